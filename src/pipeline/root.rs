//! Root position per frame. `fixed`: the root held at its rest position (feet on the ground in
//! the rest pose); foot-rooted modes come later.

use crate::rig::Rig;
use nalgebra::Vector3;
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

/// Root positions for `frames` frames (rig units).
pub fn root_positions(rig: &Rig, mode: RootMode, frames: usize) -> Vec<Vector3<f64>> {
    match mode {
        RootMode::Fixed => vec![rig.joints()[0].offset; frames],
    }
}
