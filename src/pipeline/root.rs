//! Root position per frame. `fixed`: the root held at its rest position (feet on the ground in
//! the rest pose); foot-rooted modes come later.

use crate::rig::Rig;
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RootMode {
    /// Hips held at rest height and place.
    #[default]
    Fixed,
}

impl RootMode {
    pub fn label(self) -> &'static str {
        match self {
            RootMode::Fixed => "fixed",
        }
    }
}

/// Stage 7, root: the root position at every frame (rig units), given every joint's local
/// rotations (`local[joint][frame]`) and the world rotations of the sensed bones
/// (`world[joint]`, `None` for joints without a sensor) — what foot-rooted modes will need.
pub fn root_positions(
    rig: &Rig,
    mode: RootMode,
    local: &[Vec<UnitQuaternion<f64>>],
    world: &[Option<Vec<UnitQuaternion<f64>>>],
) -> Vec<Vector3<f64>> {
    let frames = local.first().map_or(0, Vec::len);
    let _ = world;
    match mode {
        RootMode::Fixed => vec![rig.joints()[0].offset; frames],
    }
}
