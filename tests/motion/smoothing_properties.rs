//! Smoothing never breaks a rotation, whatever the input: no NaN, unit quaternions, and no
//! frame-to-frame rotation step of the output larger than the input's largest step plus 1°.
//! Euler angle smoothing through (cos, sin) pairs never averages 359° and 1° to 180°.

use imubake::pipeline::smoothing::{smooth_angles_deg, smooth_quaternions};
use imubake::rotation::angle_between;
use imubake::smooth::Method;
use nalgebra::{UnitQuaternion, Vector3};
use proptest::prelude::*;

fn methods() -> Vec<Method> {
    [
        "none",
        "butterworth:order=4,cutoff=6",
        "butterworth:order=2,cutoff=1",
        "butterworth:order=3,cutoff=5,causal",
        "gaussian:sigma=0.05",
        "gaussian:sigma=0.5",
        "fft",
        "fft:cutoff=4",
        "fft:threshold=0.2,suppress=0.1,cutoff=10",
    ]
    .iter()
    .map(|m| m.parse().unwrap())
    .collect()
}

/// A random-walk track: steps are random rotations of up to `max_step_deg`, some huge.
fn track() -> impl Strategy<Value = (Vec<UnitQuaternion<f64>>, f64)> {
    (
        proptest::collection::vec((any::<[i16; 3]>(), 0.0f64..1.0), 0..300),
        prop_oneof![Just(1.0), Just(10.0), Just(60.0), Just(179.0)],
        prop_oneof![Just(30.0), Just(100.0), 5.0f64..400.0],
        any::<bool>(),
    )
        .prop_map(|(steps, max_step_deg, rate, flip_signs)| {
            let mut q = UnitQuaternion::identity();
            let mut out = Vec::with_capacity(steps.len());
            for (i, (axis, size)) in steps.into_iter().enumerate() {
                let axis = Vector3::new(axis[0] as f64, axis[1] as f64, axis[2] as f64 + 0.5);
                let step = UnitQuaternion::from_scaled_axis(
                    axis.normalize() * (size * max_step_deg).to_radians(),
                );
                q = step * q;
                // The same rotations with arbitrary quaternion signs must give the same result.
                let stored = if flip_signs && i % 3 == 1 {
                    UnitQuaternion::new_unchecked(-q.into_inner())
                } else {
                    q
                };
                out.push(stored);
            }
            (out, rate)
        })
}

fn max_step_deg(track: &[UnitQuaternion<f64>]) -> f64 {
    track
        .windows(2)
        .map(|w| angle_between(&w[0], &w[1]).to_degrees())
        .fold(0.0, f64::max)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn quaternion_smoothing_keeps_rotations((input, rate) in track()) {
        for method in methods() {
            let linear = !matches!(method, Method::Fft { .. });
            match smooth_quaternions(&input, rate, &method) {
                // Too short for the filter, or (only for wild input) smoothing would add a jump:
                // the caller keeps the input, with a warning. Never for ordinary motion with a
                // linear filter: the guard must not hide the smoothing itself.
                Err(why) => prop_assert!(
                    !(linear && input.len() >= 100 && max_step_deg(&input) <= 5.0),
                    "{method} refused an ordinary track: {why:?}"
                ),
                Ok(out) => {
                    prop_assert_eq!(out.len(), input.len());
                    for q in &out {
                        prop_assert!(q.coords.iter().all(|v| v.is_finite()), "{method}: NaN");
                        prop_assert!((q.coords.norm() - 1.0).abs() < 1e-9, "{method}: not unit");
                    }
                    let (step_in, step_out) = (max_step_deg(&input), max_step_deg(&out));
                    prop_assert!(step_out <= step_in + 1.0, "{method}: output step {step_out:.2}° > input step {step_in:.2}° + 1°");
                }
            }
        }
    }

    #[test]
    fn angle_smoothing_stays_finite_and_near_the_input(
        angles in proptest::collection::vec(-720.0f64..720.0, 0..200),
        rate in 10.0f64..200.0,
    ) {
        for method in methods() {
            if let Ok(out) = smooth_angles_deg(&angles, rate, &method) {
                prop_assert_eq!(out.len(), angles.len());
                for (a, b) in angles.iter().zip(&out) {
                    prop_assert!(b.is_finite());
                    prop_assert!((a - b).abs() <= 180.0 + 1e-9, "{method}: {a} → {b}");
                }
            }
        }
    }
}

#[test]
fn angles_across_360_average_through_zero_not_180() {
    // A yaw dithering between 359° and 1° (wrapped as the SOU logs give it): smoothing must stay
    // near 0°/360°, where naive averaging would give 180°.
    let angles: Vec<f64> = (0..200)
        .map(|i| if i % 2 == 0 { 359.0 } else { 1.0 })
        .collect();
    for method in methods() {
        let out = smooth_angles_deg(&angles, 100.0, &method).unwrap();
        for (a, b) in angles.iter().zip(&out) {
            let from_zero = b.rem_euclid(360.0);
            let from_zero = from_zero.min(360.0 - from_zero);
            assert!(from_zero <= 2.0, "{method}: {a} → {b}");
        }
    }
}

#[test]
fn short_tracks_fall_back_without_panicking() {
    let method: Method = "butterworth:order=4,cutoff=6".parse().unwrap();
    let short = vec![UnitQuaternion::identity(); 5];
    // sosfiltfilt needs more samples than its padding (27 for order 4).
    assert!(smooth_quaternions(&short, 100.0, &method).is_err());
    assert!(smooth_quaternions(&[], 100.0, &method).map_or(true, |v| v.is_empty()));
    // A low-pass at or above half the sample rate has nothing to remove: the track is unchanged.
    let too_high: Method = "butterworth:cutoff=60".parse().unwrap();
    let track: Vec<_> = (0..100)
        .map(|i| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), (i as f64 * 0.37).sin()))
        .collect();
    let out = smooth_quaternions(&track, 100.0, &too_high).unwrap();
    for (a, b) in track.iter().zip(&out) {
        assert!(angle_between(a, b) < 1e-12);
    }
}

/// When the guard refuses (smoothing would add a jump), the track is left as it came in, only
/// made sign-continuous: each sample equal to the input or its negation, on its predecessor's
/// hemisphere.
#[test]
fn a_refused_track_is_left_sign_continuous_and_otherwise_unchanged() {
    use imubake::pipeline::smoothing::smooth_quaternions_in_place;
    let method: Method = "butterworth:order=4,cutoff=6".parse().unwrap();
    let mut refused = 0;
    for step_deg in (100..=179).step_by(3) {
        // A spin of `step_deg` per sample about a wandering axis, signs scrambled.
        let input: Vec<UnitQuaternion<f64>> = (0..300)
            .map(|n| {
                let axis = Vector3::new(1.0, 0.3 * (n as f64 * 0.05).sin(), 0.2);
                let q = UnitQuaternion::from_scaled_axis(
                    axis.normalize() * (n as f64 * step_deg as f64).to_radians(),
                );
                if n % 3 == 1 {
                    UnitQuaternion::new_unchecked(-q.into_inner())
                } else {
                    q
                }
            })
            .collect();
        let mut values = input.clone();
        if smooth_quaternions_in_place(&mut values, 100.0, &method).is_ok() {
            continue;
        }
        refused += 1;
        for n in 0..input.len() {
            let (v, i) = (values[n].coords, input[n].coords);
            assert!(
                v == i || v == -i,
                "step {step_deg}° sample {n}: {v:?} is not ±{i:?}"
            );
            if n > 0 {
                assert!(
                    v.dot(&values[n - 1].coords) >= 0.0,
                    "step {step_deg}° sample {n}"
                );
            }
        }
    }
    assert!(refused > 0, "no spin was refused: the test checks nothing");
}
