//! `imubake::rotation::euler` against Blender's `mathutils` (Blender 5.0.1).
//!
//! The expectations come from `tests/fixtures/euler/compat_<ORDER>.json`, written by
//! `tests/python/make_euler_fixtures.py` with `mathutils` (`Quaternion.to_euler(order)`,
//! `Quaternion.to_euler(order, previous)`, `Euler.to_quaternion()`); this test only reads the
//! JSON and never runs Python. See the script's header for the file layout.
//!
//! Angle layout: every triple in the fixtures is already in imubake's application order
//! (`angles[k]` about `order.axes()[k]`); the script converted Blender's per-axis storage
//! (`euler.x, .y, .z` of mode `order.blender_name()`) with `angles[k] = euler[axes[k]]`.
//!
//! # Tolerances, and why
//!
//! `mathutils` stores and computes in `f32`; imubake in `f64`. The script rounds every input to
//! `f32` before giving it to `mathutils`, and this test recovers those exact `f32` values
//! (`as f32 as f64`), so both sides start from the same numbers. What remains is `mathutils`'
//! own `f32` arithmetic:
//! - its rotation matrix is rounded to `f32` (≤ 6e-8 per entry) and `hypotf`/`atan2f` add an
//!   ulp, so a well-conditioned angle is off by a few 1e-7 rad: [`BASE`] = 2e-6 rad;
//! - the returned angles are `f32`: half an ulp is 4.8e-7 at 10 rad, and Blender's 2π is
//!   `2·float(π)`, 1.7e-7 too large, once per turn unwound: [`REL`] = 1e-7 × |angle|;
//! - near gimbal lock the first and last angles are `atan2` of matrix entries of size
//!   `cy = |cos(middle)|`, so their `f32` error grows like 1e-7 / cy (1e-3 rad at 89.99°):
//!   [`NOISE_OVER_CY`] = 1e-6 / cy, only for those two angles and only outside Blender's
//!   gimbal-lock branch (inside it the first angle is exactly 0 and the last is well-conditioned).
//!
//! The smallest tolerance therefore is 2e-6 rad, not 1e-9: that is the honest resolution of a
//! float32 reference. The largest errors actually seen are printed with `--nocapture`.
//!
//! Two `f32`/`f64` effects can make the *choice* differ rather than the value, and are handled
//! explicitly:
//! - Blender's gimbal-lock test `cy > 3.75e-5` is evaluated on an `f32` matrix: within ~1e-7 of
//!   the threshold the two sides may take different branches (`threshold_band` cases with
//!   |cy − 3.75e-5| < 1e-6); there only the rotation is compared, within the branch's own error
//!   (≤ 2·cy) plus the `f32` noise. The trajectories keep out of [0.5, 2] × 3.75e-5 (asserted
//!   by the script).
//! - Two candidates exactly equally close to `previous` (an angle difference of exactly ±π, or
//!   equal sums) are a tie that `f32` rounding may break differently. A mismatch is accepted as
//!   such a tie only if both answers are the same rotation and equally close to `previous`
//!   (within 1e-5); ties are counted, and none is allowed on the smooth trajectories.

use imubake::rotation::EulerOrder;
use imubake::rotation::euler::{
    GIMBAL_LOCK_EPSILON, angle_between, compatible, filter_track, from_quaternion,
    from_quaternion_blender, to_quaternion,
};
use nalgebra::{Quaternion, UnitQuaternion};
use serde::Deserialize;
use std::f64::consts::{PI, TAU};

const BASE: f64 = 2e-6;
const REL: f64 = 1e-7;
const NOISE_OVER_CY: f64 = 1e-6;
/// Two answers within this L1 distance of each other's closeness to `previous` are a tie.
const TIE: f64 = 1e-5;

#[derive(Deserialize)]
struct Fixture {
    order: String,
    blender_order: String,
    gimbal_lock_epsilon: f64,
    trajectories: Vec<Trajectory>,
    singles: Vec<Single>,
    compat_pairs: Vec<CompatPair>,
    boundary_pairs: Vec<CompatPair>,
    threshold_band: Vec<BandCase>,
    to_quaternion: Vec<ToQuat>,
}

#[derive(Deserialize)]
struct Trajectory {
    name: String,
    quats: Vec<[f64; 4]>,
    principal: Vec<[f64; 3]>,
    chain: Vec<[f64; 3]>,
}

#[derive(Deserialize)]
struct Single {
    quat: [f64; 4],
    to_euler: [f64; 3],
    principal: [f64; 3],
}

#[derive(Deserialize)]
struct CompatPair {
    quat: [f64; 4],
    previous: [f64; 3],
    expected: [f64; 3],
}

#[derive(Deserialize)]
struct BandCase {
    quat: [f64; 4],
    cy: f64,
    principal: [f64; 3],
}

#[derive(Deserialize)]
struct ToQuat {
    angles: [f64; 3],
    quat: [f64; 4],
}

fn load(order: EulerOrder) -> Fixture {
    let path = format!(
        "{}/tests/fixtures/euler/compat_{}.json",
        env!("CARGO_MANIFEST_DIR"),
        order.name()
    );
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let fixture: Fixture = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"));
    assert_eq!(fixture.order, order.name());
    assert_eq!(fixture.blender_order, order.blender_name());
    assert_eq!(fixture.gimbal_lock_epsilon, GIMBAL_LOCK_EPSILON);
    fixture
}

/// The exact float32 value the script gave mathutils.
fn f32_exact(v: f64) -> f64 {
    v as f32 as f64
}

fn quat(v: &[f64; 4]) -> UnitQuaternion<f64> {
    let [w, x, y, z] = v.map(f32_exact);
    UnitQuaternion::new_normalize(Quaternion::new(w, x, y, z))
}

fn angles32(v: &[f64; 3]) -> [f64; 3] {
    v.map(f32_exact)
}

/// |cos(middle angle)| of `q` in f64.
fn cy_of(q: &UnitQuaternion<f64>, order: EulerOrder) -> f64 {
    from_quaternion(q, order)[1].cos().abs()
}

/// Tolerance for angle `k` (0, 1, 2 in application order) of an answer of size `expected`.
fn tolerance(k: usize, cy: f64, expected: f64) -> f64 {
    let mut tol = BASE + REL * expected.abs();
    if k != 1 && cy > GIMBAL_LOCK_EPSILON {
        tol += NOISE_OVER_CY / cy;
    }
    tol
}

/// Difference wrapped to [-π, π] (for principal angles, where π and −π are the same value).
fn wrapped(d: f64) -> f64 {
    d - TAU * (d / TAU).round()
}

fn l1(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).abs()).sum()
}

/// Largest |difference| / tolerance seen, for the report.
#[derive(Default)]
struct Worst {
    ratio: f64,
    what: String,
}

impl Worst {
    fn see(&mut self, ratio: f64, what: impl FnOnce() -> String) {
        if ratio > self.ratio {
            self.ratio = ratio;
            self.what = what();
        }
    }
}

/// Compares two triples angle by angle; returns the worst |diff|/tol, or None when some angle is
/// out of tolerance.
fn compare(ours: &[f64; 3], want: &[f64; 3], cy: f64, wrap: bool) -> Option<f64> {
    let mut worst: f64 = 0.0;
    for k in 0..3 {
        let d = ours[k] - want[k];
        let d = if wrap { wrapped(d) } else { d };
        let ratio = d.abs() / tolerance(k, cy, want[k]);
        if ratio.is_nan() || ratio > 1.0 {
            return None;
        }
        worst = worst.max(ratio);
    }
    Some(worst)
}

/// Same rotation, within the f32 noise of the reference near gimbal lock.
fn same_rotation(a: &[f64; 3], b: &[f64; 3], order: EulerOrder, cy: f64) -> bool {
    let err = angle_between(&to_quaternion(*a, order), &to_quaternion(*b, order));
    err < 1e-5 + 2.0 * NOISE_OVER_CY / cy.max(GIMBAL_LOCK_EPSILON)
}

#[test]
fn to_quaternion_matches_mathutils() {
    let mut worst: f64 = 0.0;
    for order in EulerOrder::ALL {
        let fixture = load(order);
        assert!(!fixture.to_quaternion.is_empty());
        for case in &fixture.to_quaternion {
            let q = to_quaternion(angles32(&case.angles), order);
            let want = case.quat.map(f32_exact);
            let got = [q.w, q.i, q.j, q.k];
            // mathutils computes in double and rounds the result to f32 (≤ 6e-8 per component).
            // The sign must match too: both are the product of the half-angle quaternions.
            for k in 0..4 {
                let d = (got[k] - want[k]).abs();
                worst = worst.max(d);
                assert!(
                    d < 2e-7,
                    "{order} {:?}: {got:?} vs mathutils {want:?}",
                    case.angles
                );
            }
        }
    }
    eprintln!("to_quaternion: worst component difference {worst:.2e}");
}

#[test]
fn principal_matches_mathutils() {
    let mut worst = Worst::default();
    let mut frames = 0;
    let mut locked = 0;
    for order in EulerOrder::ALL {
        let fixture = load(order);
        let cases = fixture
            .trajectories
            .iter()
            .flat_map(|t| t.quats.iter().zip(&t.principal))
            .chain(fixture.singles.iter().map(|s| (&s.quat, &s.principal)));
        for (qv, want) in cases {
            let q = quat(qv);
            let ours = from_quaternion(&q, order);
            let want = angles32(want);
            let cy = cy_of(&q, order);
            frames += 1;
            if cy <= GIMBAL_LOCK_EPSILON {
                locked += 1;
                assert_eq!(ours[0], 0.0);
            }
            assert!(
                (-PI / 2.0..=PI / 2.0).contains(&ours[1]),
                "{order} {ours:?}"
            );
            let ratio = compare(&ours, &want, cy, true).unwrap_or_else(|| {
                panic!("{order} quat {qv:?} (cy {cy:.3e}): ours {ours:?}, mathutils {want:?}")
            });
            worst.see(ratio, || format!("{order} {qv:?} cy={cy:.2e}"));
        }
    }
    assert!(
        locked >= 6,
        "every order has an exact gimbal-lock frame ({locked})"
    );
    eprintln!(
        "principal: {frames} frames ({locked} gimbal locked), worst diff/tol {:.3} at {}",
        worst.ratio, worst.what
    );
}

#[test]
fn blender_choice_matches_mathutils_to_euler() {
    let mut second = 0;
    let mut ties = 0;
    for order in EulerOrder::ALL {
        let fixture = load(order);
        for single in &fixture.singles {
            let q = quat(&single.quat);
            let ours = from_quaternion_blender(&q, order);
            let want = angles32(&single.to_euler);
            if want[1].abs() > PI / 2.0 + 1e-6 {
                second += 1;
            }
            let cy = cy_of(&q, order);
            if compare(&ours, &want, cy, true).is_none() {
                // Equal sums of |angles|: a tie that float32 may break the other way.
                let tie = (l1(&ours, &[0.0; 3]) - l1(&want, &[0.0; 3])).abs() < TIE
                    && same_rotation(&ours, &want, order, cy);
                assert!(
                    tie,
                    "{order} {:?}: ours {ours:?}, mathutils {want:?}",
                    single.quat
                );
                ties += 1;
            }
        }
    }
    // The fixtures must exercise the case where Blender's choice is not the principal one.
    assert!(
        second > 10,
        "only {second} singles where mathutils picks the second solution"
    );
    assert!(ties <= 1, "{ties} ties");
    eprintln!("to_euler (Blender's choice): {second} second-solution cases, {ties} ties");
}

#[test]
fn threshold_band_matches_mathutils() {
    let mut compared_angles = 0;
    let mut compared_rotations = 0;
    for order in EulerOrder::ALL {
        let fixture = load(order);
        for case in &fixture.threshold_band {
            let q = quat(&case.quat);
            let cy = cy_of(&q, order);
            // The script's cy (f64, from the same f32 quaternion) and ours agree.
            assert!(
                (cy - case.cy).abs() < 1e-12 + 1e-9 * cy,
                "{cy} vs {}",
                case.cy
            );
            let ours = from_quaternion(&q, order);
            let want = angles32(&case.principal);
            if (cy - GIMBAL_LOCK_EPSILON).abs() < 1e-6 {
                // Branch choice is decided by f32 rounding: compare rotations only. Each branch is
                // within 2·cy of the true rotation; mathutils adds its f32 noise.
                let err = angle_between(&to_quaternion(ours, order), &to_quaternion(want, order));
                assert!(
                    err < 4.0 * cy + 2.0 * NOISE_OVER_CY / cy,
                    "{order} cy={cy:e}: {ours:?} vs {want:?} ({err})"
                );
                compared_rotations += 1;
            } else {
                assert!(
                    compare(&ours, &want, cy, true).is_some(),
                    "{order} cy={cy:e}: ours {ours:?}, mathutils {want:?}"
                );
                compared_angles += 1;
            }
        }
    }
    assert!(compared_angles > 100 && compared_rotations > 0);
    eprintln!("threshold band: {compared_angles} by angle, {compared_rotations} by rotation");
}

/// Blender's discontinuity filter, one frame at a time, fed with Blender's own previous output.
#[test]
fn compatible_matches_mathutils_frame_by_frame() {
    let mut worst = Worst::default();
    let mut frames = 0;
    for order in EulerOrder::ALL {
        let fixture = load(order);
        for t in &fixture.trajectories {
            for n in 1..t.quats.len() {
                let q = quat(&t.quats[n]);
                let previous = angles32(&t.chain[n - 1]);
                let want = angles32(&t.chain[n]);
                let ours = compatible(&q, order, previous);
                let cy = cy_of(&q, order);
                let ratio = compare(&ours, &want, cy, false).unwrap_or_else(|| {
                    panic!(
                        "{order} {} frame {n} (cy {cy:.3e}): previous {previous:?}, ours {ours:?}, \
                         mathutils {want:?}",
                        t.name
                    )
                });
                worst.see(ratio, || {
                    format!("{order} {} frame {n} cy={cy:.2e}", t.name)
                });
                frames += 1;
            }
        }
    }
    eprintln!(
        "compatible (trajectories): {frames} frames, worst diff/tol {:.3} at {}",
        worst.ratio, worst.what
    );
}

/// The whole filter: frame 0 principal, then compatible with our own previous output.
#[test]
fn filter_track_matches_mathutils_chain() {
    let mut worst = Worst::default();
    let mut spins = 0;
    for order in EulerOrder::ALL {
        let fixture = load(order);
        for t in &fixture.trajectories {
            let track: Vec<_> = t.quats.iter().map(quat).collect();
            let ours = filter_track(&track, order);
            assert_eq!(ours.len(), t.chain.len());
            for (n, (got, want)) in ours.iter().zip(&t.chain).enumerate() {
                let want = angles32(want);
                let cy = cy_of(&track[n], order);
                let ratio = compare(got, &want, cy, false).unwrap_or_else(|| {
                    panic!(
                        "{order} {} frame {n}: ours {got:?}, mathutils {want:?}",
                        t.name
                    )
                });
                worst.see(ratio, || {
                    format!("{order} {} frame {n} cy={cy:.2e}", t.name)
                });
            }
            let largest = t.chain.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
            if largest > TAU {
                spins += 1;
            }
        }
    }
    // The chains must unwind beyond one turn somewhere (long spins), or the test proves little.
    assert!(spins >= 6, "only {spins} trajectories wind beyond 2π");
    eprintln!(
        "filter_track: {spins} trajectories beyond 2π, worst diff/tol {:.3} at {}",
        worst.ratio, worst.what
    );
}

/// Random quaternions with far-away `previous` angles (up to ±12 rad): wrapping by several
/// turns, second-solution choices and Blender's pi flip in general position.
#[test]
fn compatible_matches_mathutils_far_previous() {
    let mut worst = Worst::default();
    let mut ties = 0;
    let mut cases = 0;
    for order in EulerOrder::ALL {
        let fixture = load(order);
        for pair in &fixture.compat_pairs {
            let q = quat(&pair.quat);
            let previous = angles32(&pair.previous);
            let want = angles32(&pair.expected);
            let ours = compatible(&q, order, previous);
            let cy = cy_of(&q, order);
            cases += 1;
            match compare(&ours, &want, cy, false) {
                Some(ratio) => worst.see(ratio, || format!("{order} {:?}", pair.quat)),
                None => {
                    let tie = (l1(&ours, &previous) - l1(&want, &previous)).abs() < TIE
                        && same_rotation(&ours, &want, order, cy);
                    assert!(
                        tie,
                        "{order} quat {:?} previous {previous:?}: ours {ours:?}, mathutils {want:?}",
                        pair.quat
                    );
                    ties += 1;
                }
            }
        }
    }
    assert!(ties * 100 <= cases, "{ties} ties in {cases} cases");
    eprintln!(
        "compatible (far previous): {cases} cases, {ties} ties, worst diff/tol {:.3} at {}",
        worst.ratio, worst.what
    );
}

/// Exact ties (`boundary_pairs`), where f32 and f64 rounding legitimately decide differently:
/// - a half turn about an axis with `previous` at 0 lies exactly π from both +π and −π. Blender's
///   `compatible_eul` runs in f32 with `pi_thresh = float(π)` (> π), so its "pi flip" turns the
///   angle into the other sign there; in f64 no flip fires;
/// - the identity with `previous` = ±float(π/2) on every axis: (0, 0, 0) and (±π, ±π, ±π) are
///   equally far in f32 (Blender keeps the first), while in f64 float(π/2) is 4e-8 above π/2 and
///   the second is closer by 1.3e-7.
///
/// Every mismatch must be such a tie (same rotation, equally close to `previous` within 1e-5);
/// the count is reported.
#[test]
fn compatible_at_exact_ties_is_equally_close() {
    let mut ties = 0;
    let mut cases = 0;
    for order in EulerOrder::ALL {
        let fixture = load(order);
        assert!(!fixture.boundary_pairs.is_empty());
        for pair in &fixture.boundary_pairs {
            let q = quat(&pair.quat);
            let previous = angles32(&pair.previous);
            let want = angles32(&pair.expected);
            let ours = compatible(&q, order, previous);
            let cy = cy_of(&q, order);
            cases += 1;
            if compare(&ours, &want, cy, false).is_none() {
                let tie = (l1(&ours, &previous) - l1(&want, &previous)).abs() < TIE
                    && same_rotation(&ours, &want, order, cy);
                assert!(
                    tie,
                    "{order} quat {:?} previous {previous:?}: ours {ours:?}, mathutils {want:?}",
                    pair.quat
                );
                ties += 1;
            }
        }
    }
    eprintln!(
        "exact ties: {cases} cases, {ties} resolved differently from mathutils (f32 vs f64 at exact ties)"
    );
}
