//! Output preparation, after the stages: what a writer needs that the animation does not hold as
//! such. BVH stores Euler angles, so each joint's local rotations become angles in its channel
//! order with the discontinuity filter ([`crate::rotation::euler::filter_track_degrees`], Blender's
//! `compatible_eul`); glTF keeps the quaternions (its writer keeps each key on the previous key's
//! hemisphere). `convert` leaves the angles to the BVH writer, which makes them a group of frames
//! at a time as it writes ([`crate::write::bvh::Angles::Rotations`]); [`euler_degrees`] makes a
//! whole take's at once, the same to the bit.

use crate::anim::Animation;
use crate::rotation::euler::filter_track_degrees;
use rayon::prelude::*;

/// Euler angles in degrees, `[joint][frame]`, each joint in its own channel order, with the
/// discontinuity filter applied.
pub fn euler_degrees(animation: &Animation) -> Vec<Vec<[f64; 3]>> {
    // Joints are independent: one per core at a time.
    animation
        .rig()
        .joints()
        .par_iter()
        .enumerate()
        .map(|(j, joint)| filter_track_degrees(animation.local(j), joint.order))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::load_rig;
    use nalgebra::{UnitQuaternion, Vector3};

    #[test]
    fn a_turn_through_180_degrees_stays_continuous() {
        let rig = load_rig("mixamo").unwrap();
        let frames = 40;
        // The hips turn about +Y from 0° to 390°: past ±180° the angles keep counting.
        let local: Vec<Vec<UnitQuaternion<f64>>> = (0..rig.len())
            .map(|j| {
                (0..frames)
                    .map(|f| {
                        let deg = if j == 0 { f as f64 * 10.0 } else { 0.0 };
                        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), deg.to_radians())
                    })
                    .collect()
            })
            .collect();
        let animated = (0..rig.len()).map(|j| j == 0).collect();
        let roots = vec![rig.joints()[0].offset; frames];
        let fps = "30".parse().unwrap();
        let anim = Animation::new(rig, fps, local, animated, roots).unwrap();
        let euler = euler_degrees(&anim);
        // mixamo's order is ZYX: the Y angle is the middle channel.
        for (f, angles) in euler[0].iter().enumerate() {
            assert!(
                (angles[1] - f as f64 * 10.0).abs() < 1e-6,
                "frame {f}: {angles:?}"
            );
        }
    }
}
