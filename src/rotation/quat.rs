//! Quaternion helpers shared by the Euler filter, smoothing and the glTF writer.
//!
//! Quaternions are Hamilton, w first, unit length (`conventions.md`). `q` and `-q` are the same
//! rotation; the helpers here never change the rotation a quaternion stands for.

use nalgebra::{Quaternion, UnitQuaternion};

/// The rotation about one coordinate axis (0 = x, 1 = y, 2 = z) by `angle` radians
/// (right-handed: positive angles turn y towards z about x, z towards x about y, x towards y
/// about z). The result has `w = cos(angle / 2)`, so angles beyond ±π give `w < 0`.
///
/// An axis index above 2 is taken as z; callers pass `EulerOrder::axes()` entries.
pub fn axis_rotation(axis: usize, angle: f64) -> UnitQuaternion<f64> {
    let (s, c) = (0.5 * angle).sin_cos();
    let q = match axis {
        0 => Quaternion::new(c, s, 0.0, 0.0),
        1 => Quaternion::new(c, 0.0, s, 0.0),
        _ => Quaternion::new(c, 0.0, 0.0, s),
    };
    UnitQuaternion::new_unchecked(q)
}

/// The angle, in radians in [0, π], of the rotation that takes `a` to `b` (the geodesic
/// distance on SO(3); the sign of either quaternion does not matter).
///
/// Computed as `2·atan2(|v|, |w|)` of `a⁻¹ ⊗ b`, which stays accurate for tiny angles (unlike
/// `2·acos(|w|)`, whose resolution near 0 is only about 1e-8 rad).
pub fn angle_between(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    let d = a.quaternion().conjugate() * b.quaternion();
    2.0 * d.imag().norm().atan2(d.w.abs())
}

/// Flips the sign of quaternions so that each has a non-negative dot product with the one before
/// it (after that one was fixed). The first quaternion is left as it is. The rotations do not
/// change; only the representation becomes continuous on the 4-D sphere, which glTF linear/slerp
/// interpolation and component-wise smoothing need.
pub fn make_hemisphere_continuous(track: &mut [UnitQuaternion<f64>]) {
    for n in 1..track.len() {
        if track[n].coords.dot(&track[n - 1].coords) < 0.0 {
            track[n] = UnitQuaternion::new_unchecked(-track[n].into_inner());
        }
    }
}

/// Spherical linear interpolation along the shorter arc; `u` in [0, 1]. Unlike nalgebra's
/// `slerp` it never panics (rotations 180° apart take a well-defined path).
pub fn slerp_shortest(
    a: &UnitQuaternion<f64>,
    b: &UnitQuaternion<f64>,
    u: f64,
) -> UnitQuaternion<f64> {
    let qa = a.into_inner();
    let mut qb = b.into_inner();
    let mut dot = qa.dot(&qb);
    if dot < 0.0 {
        qb = -qb;
        dot = -dot;
    }
    let q: Quaternion<f64> = if dot > 0.9995 {
        // Nearly equal: normalised linear interpolation is exact to ~1e-7 rad and stable.
        qa * (1.0 - u) + qb * u
    } else {
        let theta = dot.min(1.0).acos();
        let s = theta.sin();
        qa * (((1.0 - u) * theta).sin() / s) + qb * ((u * theta).sin() / s)
    };
    UnitQuaternion::from_quaternion(q)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use proptest::prelude::*;

    fn quat_strategy() -> impl Strategy<Value = UnitQuaternion<f64>> {
        (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0)
            .prop_filter("non-degenerate", |(w, x, y, z)| {
                w * w + x * x + y * y + z * z > 1e-3
            })
            .prop_map(|(w, x, y, z)| UnitQuaternion::new_normalize(Quaternion::new(w, x, y, z)))
    }

    #[test]
    fn axis_rotation_turns_the_right_way() {
        let x = Vector3::x();
        let y = Vector3::y();
        let z = Vector3::z();
        let r = std::f64::consts::FRAC_PI_2;
        assert!((axis_rotation(0, r) * y - z).norm() < 1e-15);
        assert!((axis_rotation(1, r) * z - x).norm() < 1e-15);
        assert!((axis_rotation(2, r) * x - y).norm() < 1e-15);
    }

    #[test]
    fn angle_between_known_values() {
        let a = axis_rotation(2, 0.3);
        let b = axis_rotation(2, 0.3 + 1e-12);
        assert!((angle_between(&a, &b) - 1e-12).abs() < 1e-15);
        // The sign of a quaternion does not matter.
        let nb = UnitQuaternion::new_unchecked(-b.into_inner());
        assert!((angle_between(&a, &nb) - 1e-12).abs() < 1e-15);
        let c = axis_rotation(0, 3.0);
        assert!((angle_between(&UnitQuaternion::identity(), &c) - 3.0).abs() < 1e-14);
        // 3.5 rad about an axis is 2π − 3.5 the other way round.
        let d = axis_rotation(1, 3.5);
        let expected = 2.0 * std::f64::consts::PI - 3.5;
        assert!((angle_between(&UnitQuaternion::identity(), &d) - expected).abs() < 1e-14);
    }

    #[test]
    fn hemisphere_on_empty_and_single() {
        let mut empty: Vec<UnitQuaternion<f64>> = Vec::new();
        make_hemisphere_continuous(&mut empty);
        let q = UnitQuaternion::new_unchecked(Quaternion::new(-0.6, 0.8, 0.0, 0.0));
        let mut one = vec![q];
        make_hemisphere_continuous(&mut one);
        assert_eq!(one[0], q, "the first key keeps its sign");
    }

    proptest! {
        #[test]
        fn hemisphere_continuity_never_changes_the_rotation(
            track in prop::collection::vec((quat_strategy(), any::<bool>()), 0..40)
        ) {
            let original: Vec<UnitQuaternion<f64>> = track
                .iter()
                .map(|(q, flip)| if *flip { UnitQuaternion::new_unchecked(-q.into_inner()) } else { *q })
                .collect();
            let mut fixed = original.clone();
            make_hemisphere_continuous(&mut fixed);
            for (n, (a, b)) in original.iter().zip(&fixed).enumerate() {
                // Same rotation: identical or exactly negated, never anything else.
                let same = a.coords == b.coords;
                let negated = a.coords == -b.coords;
                prop_assert!(same || negated, "frame {n} changed");
                prop_assert!(angle_between(a, b) < 1e-7);
                if n == 0 {
                    prop_assert!(same);
                } else {
                    prop_assert!(b.coords.dot(&fixed[n - 1].coords) >= 0.0);
                }
            }
        }

        #[test]
        fn angle_between_is_symmetric_and_bounded(a in quat_strategy(), b in quat_strategy()) {
            let ab = angle_between(&a, &b);
            let ba = angle_between(&b, &a);
            prop_assert!((0.0..=std::f64::consts::PI + 1e-12).contains(&ab));
            prop_assert!((ab - ba).abs() < 1e-12);
            // Agrees with nalgebra's own (acos based) angle where that one is well-conditioned.
            let reference = a.angle_to(&b);
            let reference = reference.min(2.0 * std::f64::consts::PI - reference);
            if reference > 1e-3 && reference < std::f64::consts::PI - 1e-3 {
                prop_assert!((ab - reference).abs() < 1e-9);
            }
        }
    }
}
