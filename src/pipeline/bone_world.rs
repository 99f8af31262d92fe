//! Stage 3, bone world: each sensor's track turned into its bone's world orientation,
//! `q_world_bone = H ⊗ q_rig_sensor ⊗ q_bone_sensor⁻¹` (heading `H` and mount `q_bone_sensor` from
//! [`super::calibrate`]), on the sensor's own sample times.

use super::calibrate::Calibration;
use crate::take::Track;
use nalgebra::UnitQuaternion;

/// The bone world tracks, one per sensor track (in the order of `calibration.mounts`).
pub fn bone_world(
    tracks: Vec<Track<UnitQuaternion<f64>>>,
    calibration: &Calibration,
) -> Vec<Track<UnitQuaternion<f64>>> {
    let heading = calibration.heading;
    tracks
        .into_iter()
        .zip(&calibration.mounts)
        .map(|(t, mount)| {
            let inv = mount.inverse();
            t.map_in_place(|q| heading * q * inv)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::calibrate::HeadingSource;
    use nalgebra::Vector3;

    #[test]
    fn heading_and_mount_by_hand() {
        let about = |axis: Vector3<f64>, deg: f64| {
            UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg.to_radians())
        };
        // A sensor mounted turned 90° about the bone's x, a heading of 30° about +Y.
        let mount = about(Vector3::x(), 90.0);
        let heading = about(Vector3::y(), 30.0);
        let bone = about(Vector3::z(), 40.0);
        // What the sensor reads when the bone is at `bone` (rig world, before heading).
        let sensor = heading.inverse() * bone * mount;
        let track = Track::new(vec![0.0], vec![sensor]).unwrap();
        let calibration = Calibration {
            heading,
            heading_source: HeadingSource::None,
            mounts: vec![mount],
            warnings: vec![],
        };
        let out = bone_world(vec![track], &calibration);
        assert!(out[0].values()[0].angle_to(&bone) < 1e-12);
    }
}
