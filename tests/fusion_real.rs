//! Fusion on real bodies: the x-IMU3 lower body (`../shared/data/fullbody/xio_lower_body_7imu/`)
//! from its raw files against the devices' own orientation (`Quaternion.csv`, the x-IMU3's AHRS).

mod common;

use imubake::fusion::{Fusion, fuse};
use imubake::read::{ReadOptions, read_take};
use imubake::take::OrientationTrack;
use imubake::world::World;
use nalgebra::{UnitQuaternion, Vector3};

/// The angle between the vertical as two orientations see it in the sensor frame: the
/// inclination error, whatever the heading.
fn inclination_deg(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    let (ua, ub) = (a.inverse() * Vector3::z(), b.inverse() * Vector3::z());
    ua.dot(&ub).clamp(-1.0, 1.0).acos().to_degrees()
}

#[test]
fn x_imu3_lower_body_inclination_agrees_with_the_devices_own() {
    let Some(session) = common::shared("fullbody/xio_lower_body_7imu") else {
        return;
    };
    let take = read_take(&session, &ReadOptions::default()).unwrap();
    assert_eq!(take.source().world, World::Nwu);
    // NWU and ENU share the vertical: the device's q_nwu_sensor and our q_enu_sensor see the same
    // up (z) in the sensor frame.
    for spec in ["vqf", "madgwick", "mahony", "vqf:6d"] {
        let fusion: Fusion = spec.parse().unwrap();
        let mut worst = (0.0f64, String::new());
        for sensor in take.sensors() {
            let fused = fuse(
                sensor.id(),
                sensor.inertial().unwrap(),
                sensor.magnetometer(),
                &fusion,
            )
            .unwrap();
            let Some(OrientationTrack::Quaternion(device)) = sensor.orientation() else {
                panic!("{}: no Quaternion.csv", sensor.id());
            };
            // The first second is the filters' start (VQF and the device both converge).
            let errors: Vec<f64> = fused
                .track
                .iter()
                .filter(|(t, _)| *t >= 1.0 && *t <= device.last_time_s())
                .map(|(t, q)| inclination_deg(q, &device.sample_at(t)))
                .collect();
            let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
            eprintln!(
                "{spec:>9} {:>16}: inclination RMS {rms:.2}° over {} samples",
                sensor.id(),
                errors.len()
            );
            if rms > worst.0 {
                worst = (rms, sensor.id().to_string());
            }
        }
        // The bar for the default; the others are printed for the notes.
        if spec == "vqf" {
            assert!(
                worst.0 <= 3.0,
                "{spec}: {} off by {:.2}° RMS",
                worst.1,
                worst.0
            );
        }
    }
}
