//! World rotations on the frame grid → local rotations: q_local = q_world_parent⁻¹ ⊗ q_world_bone.
//! A joint without a sensor keeps its rest (identity) local rotation, so its world rotation is its
//! parent's and its children are relative to it.

use crate::rig::Rig;
use nalgebra::UnitQuaternion;

/// `world[j]`: the world rotation track of joint j when a sensor drives it. Returns `local[j][frame]`.
pub fn to_local(
    rig: &Rig,
    world: &[Option<Vec<UnitQuaternion<f64>>>],
    frames: usize,
) -> Vec<Vec<UnitQuaternion<f64>>> {
    let n = rig.len();
    let mut local = vec![vec![UnitQuaternion::identity(); frames]; n];
    let mut frame_world = vec![UnitQuaternion::identity(); n];
    let mut frame_local = vec![UnitQuaternion::identity(); n];
    for f in 0..frames {
        frame_to_local(
            rig,
            |j| world[j].as_ref().map(|track| track[f]),
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
/// A joint without a sensor keeps its rest (identity) rotation.
pub fn frame_to_local(
    rig: &Rig,
    world: impl Fn(usize) -> Option<UnitQuaternion<f64>>,
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
                local[j] = UnitQuaternion::identity();
                pw.unwrap_or_else(UnitQuaternion::identity)
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
        let local = to_local(&rig, &world, 2);
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
}
