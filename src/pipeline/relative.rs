//! World rotations on the frame grid → local rotations: q_local = q_world_parent⁻¹ ⊗ q_world_bone.
//!
//! Joints without a sensor ([`Unsensed`]):
//! - `interpolate` (the default): a chain of unsensed joints `u_1 … u_k` between a sensed joint
//!   `A` and its nearest sensed descendant `D` (the spine between the hips and the chest, the
//!   neck) shares the rotation between them, `R = q_world_A⁻¹ ⊗ q_world_D`: each `u_i` turns by
//!   the fraction `f_i` of it, `q_local_i = exp(f_i · log R)` (a slerp from the identity), as a
//!   chain that bends evenly along its length would: the segment `u_i` turns (from `u_i` to the
//!   next joint, or `D`, rest length `ℓ_i`) points along the bend's tangent at its middle, so
//!   `Σ_{j≤i} f_j = (Σ_{j<i} ℓ_j + ℓ_i / 2) / Σ ℓ`; `D` keeps the rest of the rotation, so the
//!   chain bends smoothly and `D` is exactly where its sensor says (two equal segments: ¼, ½, and
//!   ¼ left for `D`). An unsensed joint without a sensed descendant (a head with no sensor) keeps its
//!   rest rotation; where branches meet, the first sensed descendant in the rig's order decides.
//! - `rest`: every unsensed joint keeps its rest (identity) local rotation, so its world rotation
//!   is its parent's and the whole bend between two sensors happens at the lower one.

use crate::rig::Rig;
use nalgebra::UnitQuaternion;
use serde::{Deserialize, Serialize};

/// What joints without a sensor do (`--unsensed`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Unsensed {
    /// Share the rotation between the sensed joints around them.
    #[default]
    Interpolate,
    /// Keep the rest rotation.
    Rest,
}

impl Unsensed {
    pub fn label(self) -> &'static str {
        match self {
            Unsensed::Interpolate => "interpolate",
            Unsensed::Rest => "rest",
        }
    }
}

impl std::str::FromStr for Unsensed {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "interpolate" => Ok(Unsensed::Interpolate),
            "rest" => Ok(Unsensed::Rest),
            _ => Err(format!("unknown `{s}`; expected interpolate or rest")),
        }
    }
}

/// An unsensed joint between two sensed ones: the sensed ancestor, the sensed descendant and the
/// fraction of the rotation between them that this joint takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Between {
    pub ancestor: usize,
    pub descendant: usize,
    pub fraction: f64,
}

/// For each joint, how it turns when it has no sensor: `Some` for the joints of a chain between
/// two sensed joints (under [`Unsensed::Interpolate`]), `None` to keep the rest rotation.
pub fn plan(rig: &Rig, sensed: &[bool], mode: Unsensed) -> Vec<Option<Between>> {
    let n = rig.len();
    let mut out = vec![None; n];
    if mode == Unsensed::Rest {
        return out;
    }
    let joints = rig.joints();
    // Sensed joints in the rig's (parents-first) order: each claims the unsensed chain above it.
    for d in (0..n).filter(|&j| sensed[j]) {
        let mut chain = Vec::new();
        let mut j = joints[d].parent;
        while let Some(u) = j {
            if sensed[u] {
                break;
            }
            chain.push(u);
            j = joints[u].parent;
        }
        let Some(a) = j else { continue };
        if chain.is_empty() || chain.iter().any(|u| out[*u].is_some()) {
            continue;
        }
        chain.reverse(); // u_1 (below A) … u_k (above D)
        // A chain that bends evenly along its length: each segment points along the bend's
        // tangent at its middle, so u_i turns by the change of that tangent between its segment
        // and the one before (the segment u_i turns runs from u_i to the next joint, or D), and
        // D keeps the rest — the turn from its segment's middle to its end.
        let lengths: Vec<f64> = chain
            .iter()
            .skip(1)
            .chain(std::iter::once(&d))
            .map(|&j| joints[j].offset.norm())
            .collect();
        let total: f64 = lengths.iter().sum();
        let mut before = 0.0; // the arc length before segment i
        let mut previous = 0.0; // the tangent's share at the previous segment's middle
        for (i, &u) in chain.iter().enumerate() {
            let middle = if total > 0.0 {
                (before + lengths[i] / 2.0) / total
            } else {
                (i as f64 + 0.5) / lengths.len() as f64
            };
            before += lengths[i];
            let fraction = middle - previous;
            previous = middle;
            out[u] = Some(Between {
                ancestor: a,
                descendant: d,
                fraction,
            });
        }
    }
    out
}

/// Which joints move: the sensed ones, and (under [`Unsensed::Interpolate`]) the unsensed ones
/// between two sensed joints, which share the bend between them.
pub fn moving(rig: &Rig, sensed: &[bool], mode: Unsensed) -> Vec<bool> {
    plan(rig, sensed, mode)
        .iter()
        .zip(sensed)
        .map(|(between, sensed)| *sensed || between.is_some())
        .collect()
}

/// `world[j]`: the world rotation track of joint j when a sensor drives it. Returns `local[j][frame]`.
pub fn to_local(
    rig: &Rig,
    world: &[Option<Vec<UnitQuaternion<f64>>>],
    frames: usize,
    unsensed: Unsensed,
) -> Vec<Vec<UnitQuaternion<f64>>> {
    let n = rig.len();
    let sensed: Vec<bool> = world.iter().map(Option::is_some).collect();
    let between = plan(rig, &sensed, unsensed);
    let mut local = vec![vec![UnitQuaternion::identity(); frames]; n];
    let mut frame_world = vec![UnitQuaternion::identity(); n];
    let mut frame_local = vec![UnitQuaternion::identity(); n];
    for f in 0..frames {
        frame_to_local(
            rig,
            |j| world[j].as_ref().map(|track| track[f]),
            &between,
            &mut frame_world,
            &mut frame_local,
        );
        for (j, q) in frame_local.iter().enumerate() {
            local[j][f] = *q;
        }
    }
    local
}

/// The incremental core: one frame's local rotations (`local`, one per joint) from the world
/// rotations of the joints a sensor drives (`world(j)`); `frame_world` is scratch (one per joint).
/// A joint without a sensor turns as `between` says ([`plan`]), else keeps its rest rotation.
pub fn frame_to_local(
    rig: &Rig,
    world: impl Fn(usize) -> Option<UnitQuaternion<f64>>,
    between: &[Option<Between>],
    frame_world: &mut [UnitQuaternion<f64>],
    local: &mut [UnitQuaternion<f64>],
) {
    for (j, joint) in rig.joints().iter().enumerate() {
        let parent_world = joint.parent.map(|p| frame_world[p]);
        frame_world[j] = match (world(j), parent_world) {
            (Some(w), Some(pw)) => {
                local[j] = pw.inverse() * w;
                w
            }
            (Some(w), None) => {
                local[j] = w;
                w
            }
            (None, pw) => {
                let pw = pw.unwrap_or_else(UnitQuaternion::identity);
                // Between two sensed joints: its share of the rotation between them (when both
                // have a value this frame; a stream's stale sensor leaves it at rest).
                local[j] = between
                    .get(j)
                    .copied()
                    .flatten()
                    .and_then(|b| {
                        let d = world(b.descendant)?;
                        let r = frame_world[b.ancestor].inverse() * d;
                        Some(UnitQuaternion::from_scaled_axis(
                            r.scaled_axis() * b.fraction,
                        ))
                    })
                    .unwrap_or_else(UnitQuaternion::identity);
                pw * local[j]
            }
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::load_rig;
    use nalgebra::Vector3;

    #[test]
    fn locals_recompose_to_worlds_and_unmapped_joints_stay_at_rest() {
        let rig = load_rig("mixamo").unwrap();
        let hips = rig.joint_index("Hips").unwrap();
        let spine = rig.joint_index("Spine").unwrap();
        let arm = rig.joint_index("LeftArm").unwrap();
        let mut world = vec![None; rig.len()];
        let h = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.7);
        let a = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -1.2);
        world[hips] = Some(vec![h; 2]);
        world[arm] = Some(vec![a; 2]);
        let local = to_local(&rig, &world, 2, Unsensed::Rest);
        assert!(local[hips][1].angle_to(&h) < 1e-12);
        assert!(
            local[spine][0].angle() < 1e-12,
            "unmapped spine keeps its rest rotation"
        );
        // LeftArm's parents (LeftShoulder, Spine2, Spine1, Spine) are unmapped: its world is
        // hips ⊗ local, so local = h⁻¹ ⊗ a.
        assert!(local[arm][0].angle_to(&(h.inverse() * a)) < 1e-12);
        let recomposed = rig.world_rotations(&local.iter().map(|t| t[0]).collect::<Vec<_>>());
        assert!(recomposed[arm].angle_to(&a) < 1e-12);
    }

    /// Hips and Spine2 sensed, Spine and Spine1 between them: a 60° bend about x shares by the
    /// segments Spine and Spine1 turn (Spine → Spine1, Spine1 → Spine2) and the one ending at
    /// Spine2, which lands exactly where its sensor says; the neck above (no sensed descendant)
    /// stays at rest.
    #[test]
    fn a_chain_between_two_sensors_shares_the_bend() {
        let rig = load_rig("mixamo").unwrap();
        let idx = |n: &str| rig.joint_index(n).unwrap();
        let mut world = vec![None; rig.len()];
        let h = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.4);
        let bend = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 60f64.to_radians());
        world[idx("Hips")] = Some(vec![h]);
        world[idx("Spine2")] = Some(vec![h * bend]);
        let local = to_local(&rig, &world, 1, Unsensed::Interpolate);
        // Two equal segments (Spine → Spine1 → Spine2, 0.12 m each): ¼, ½ and ¼ of the bend.
        for (n, share) in ["Spine", "Spine1", "Spine2"].iter().zip([0.25, 0.5, 0.25]) {
            let angle = local[idx(n)][0].angle().to_degrees();
            assert!((angle - 60.0 * share).abs() < 1e-9, "{n}: {angle}");
        }
        let worlds = rig.world_rotations(&local.iter().map(|t| t[0]).collect::<Vec<_>>());
        assert!(worlds[idx("Spine2")].angle_to(&(h * bend)) < 1e-12);
        assert!(local[idx("Neck")][0].angle() < 1e-12);
        let sensed: Vec<bool> = world.iter().map(Option::is_some).collect();
        let p = plan(&rig, &sensed, Unsensed::Interpolate);
        assert_eq!(p[idx("Spine")].unwrap().descendant, idx("Spine2"));
        assert!(p[idx("Neck")].is_none() && p[idx("Spine2")].is_none());
        assert!(
            plan(&rig, &sensed, Unsensed::Rest)
                .iter()
                .all(Option::is_none)
        );
    }
}
