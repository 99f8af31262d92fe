//! Property tests: fusion never panics on readings a reader can hand it (finite values of any
//! size, irregular and gappy times, a magnetometer at its own rate or stuck), and what it gives
//! is either an error naming the sensor or a unit quaternion per inertial sample.

use imubake::fusion::{Fusion, fuse};
use imubake::take::{ImuSample, Track};
use nalgebra::Vector3;
use proptest::prelude::*;

fn vector(scale: f64) -> impl Strategy<Value = Vector3<f64>> {
    (-scale..scale, -scale..scale, -scale..scale).prop_map(|(x, y, z)| Vector3::new(x, y, z))
}

fn sample() -> impl Strategy<Value = ImuSample> {
    // Mostly plausible readings, sometimes absurd ones, sometimes zero.
    let gyro = prop_oneof![vector(10.0), vector(1e6), Just(Vector3::zeros())];
    let accel = prop_oneof![
        vector(10.0).prop_map(|v| v + Vector3::new(0.0, 0.0, 9.81)),
        vector(1e6),
        Just(Vector3::zeros())
    ];
    (gyro, accel).prop_map(|(gyro_rad_s, accel_m_s2)| ImuSample {
        gyro_rad_s,
        accel_m_s2,
    })
}

/// Strictly increasing times with steps from 0.1 ms to 3 s (gaps filled or not).
fn times(n: usize) -> impl Strategy<Value = Vec<f64>> {
    proptest::collection::vec(prop_oneof![1e-4..0.05f64, 0.05..3.0f64], n).prop_map(|steps| {
        steps
            .iter()
            .scan(0.0, |t, s| {
                *t += s;
                Some(*t)
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn fusion_never_panics_and_gives_unit_quaternions(
        (inertial_times, samples) in (1usize..120).prop_flat_map(|n| (times(n), proptest::collection::vec(sample(), n))),
        mag in proptest::option::of(proptest::collection::vec(vector(100.0), 1..40)),
        stuck in any::<bool>(),
        filter in prop_oneof![Just("vqf"), Just("vqf:6d"), Just("madgwick"), Just("mahony"), Just("trust"), Just("gyro")],
    ) {
        let inertial = Track::new(inertial_times.clone(), samples).unwrap();
        let mag = mag.map(|values| {
            let n = values.len();
            let values = if stuck { vec![values[0]; n] } else { values };
            let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.037).collect();
            Track::new(t, values).unwrap()
        });
        let fusion: Fusion = filter.parse().unwrap();
        match fuse("s", &inertial, mag.as_ref(), &fusion) {
            Ok(fused) => {
                prop_assert_eq!(fused.track.times_s(), &inertial_times[..]);
                for q in fused.track.values() {
                    prop_assert!(q.coords.iter().all(|c| c.is_finite()), "{:?}", q);
                    prop_assert!((q.norm() - 1.0).abs() < 1e-6);
                }
            }
            Err(e) => prop_assert!(e.to_string().contains("sensor `s`"), "{}", e),
        }
    }
}
