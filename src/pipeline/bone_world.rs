//! Stage 3, bone world: each sensor's track turned into its bone's world orientation,
//! `q_world_bone = H ⊗ A_i ⊗ q_rig_sensor ⊗ q_bone_sensor⁻¹` (heading `H`, alignment `A_i` of a
//! sensor without a heading of its own, mount `q_bone_sensor`: [`super::calibrate`]), on the
//! sensor's own sample times.

use super::calibrate::Calibration;
use crate::take::Track;
use nalgebra::UnitQuaternion;

/// The bone world tracks, one per sensor track (in the order of `calibration.mounts`).
pub fn bone_world(
    tracks: Vec<Track<UnitQuaternion<f64>>>,
    calibration: &Calibration,
) -> Vec<Track<UnitQuaternion<f64>>> {
    // Each track on its own: spread over the cores.
    super::parallel::parallel_map(tracks.into_iter().enumerate().collect(), |(i, t)| {
        let world_side = calibration.heading * calibration.align[i];
        let inv = calibration.mounts[i].inverse();
        t.map_in_place(|q| world_side * q * inv)
    })
}

/// [`bone_world`] for a take recalibrated live: `later` holds each recalibration's time from
/// which it applies (its window's end, ascending) and its calibration; before the first of
/// them, `calibration` applies.
pub fn bone_world_recalibrated(
    tracks: Vec<Track<UnitQuaternion<f64>>>,
    calibration: &Calibration,
    later: &[(f64, Calibration)],
) -> Vec<Track<UnitQuaternion<f64>>> {
    if later.is_empty() {
        return bone_world(tracks, calibration);
    }
    tracks
        .into_iter()
        .enumerate()
        .map(|(i, t)| {
            let values = t
                .times_s()
                .iter()
                .zip(t.values())
                .map(|(time, q)| {
                    let c = later
                        .iter()
                        .rev()
                        .find(|(from, _)| time >= from)
                        .map_or(calibration, |(_, c)| c);
                    c.heading * c.align[i] * q * c.mounts[i].inverse()
                })
                .collect();
            Track::new(t.times_s().to_vec(), values).expect("the same times")
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
            heading_uncertainty_deg: f64::INFINITY,
            heading_looks: Vec::new(),
            axes_uncertainty_deg: vec![0.0],
            mounts: vec![mount],
            align: vec![UnitQuaternion::identity()],
            alignment: vec![crate::pipeline::calibrate::Alignment::OwnHeading],
            mount_turns: vec![None],
            warnings: vec![],
            heading_from_s: None,
        };
        let out = bone_world(vec![track], &calibration);
        assert!(out[0].values()[0].angle_to(&bone) < 1e-12);
    }
}
