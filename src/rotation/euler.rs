//! Euler angles: conversions to and from quaternions, and the Euler discontinuity filter.
//!
//! # Conventions
//!
//! Angles are radians and listed in **application order** (`conventions.md`): for an order `O`,
//! `angles[k]` is the angle about axis `O.axes()[k]` and the rotation is
//! `R = R_axes[0](angles[0]) · R_axes[1](angles[1]) · R_axes[2](angles[2])` (intrinsic; BVH
//! channel order). `ZXY` with `[a, b, c]` is `Rz(a)·Rx(b)·Ry(c)`, i.e. BVH
//! `Zrotation a Xrotation b Yrotation c`.
//!
//! Blender calls the same rotation mode by the reversed name ([`EulerOrder::blender_name`]) and
//! stores its angles per axis (`euler.x`, `euler.y`, `euler.z`), not in application order. For our
//! order `O` and a Blender `Euler` `e` in mode `O.blender_name()`:
//! `angles[k] == e[O.axes()[k]]` (see [`from_blender_xyz`] / [`to_blender_xyz`]).
//!
//! # The algorithm (Blender's)
//!
//! The quaternion → Euler conversion and the compatible ("discontinuity filter") choice follow
//! Blender's `source/blender/blenlib/intern/math_rotation_c.cc` (functions
//! `mat3_normalized_to_eulo2`, `mat3_normalized_to_eulO`, `compatible_eul`,
//! `mat3_normalized_to_compatible_eulO`; `mathutils.Quaternion.to_euler` calls them through
//! `quat_to_eulO` / `quat_to_compatible_eulO`), done here in `f64` instead of Blender's `f32`:
//!
//! 1. Build the rotation matrix `R` (`R[row][col]`; Blender's column-major `mat[c][r]`). With
//!    Blender's axis triple `(i, j, k)` (the letters of the Blender order, i.e. ours reversed:
//!    `i = axes()[2]`, `k = axes()[0]`) and `cy = hypot(R[i][i], R[j][i])`, the two solutions are
//!    `e1 = (atan2(R[k][j], R[k][k]), atan2(-R[k][i], cy), atan2(R[j][i], R[i][i]))` and
//!    `e2 = (atan2(-R[k][j], -R[k][k]), atan2(-R[k][i], -cy), atan2(-R[j][i], -R[i][i]))`
//!    (per axis i, j, k), negated for odd permutations. `e1` has the middle angle in [-π/2, π/2];
//!    `e2` is the same rotation as `(a + π, π − b, c + π)`. No `asin`, so no clamping is needed
//!    and nothing can become NaN for a unit quaternion.
//! 2. At gimbal lock, `cy <= GIMBAL_LOCK_EPSILON` (Blender's `EULER_HYPOT_EPSILON`, 3.75e-5),
//!    Blender sets the angle about `k` to 0 — our **first** angle, `angles[0]` — and the last one,
//!    `angles[2]` (about `i`), takes the whole rotation about the (then shared) axis:
//!    `e1 = e2 = (atan2(-R[j][k], R[j][j]), atan2(-R[k][i], cy), 0)` per axis (i, j, k).
//!    This costs at most about `2·cy` ≤ 7.5e-5 rad (0.004°) of rotation error inside that band
//!    (tested), and is what Blender shows there; outside the band the rotation error is about
//!    1e-16 / cy (≤ 3e-12 rad). Angles of exactly −π (from `atan2(-0.0, -1.0)` or a negated π)
//!    are reported as +π, and −0.0 as 0.0.
//! 3. [`compatible`]: each solution is moved by `compatible_eul` towards `previous` — every angle
//!    further than π from its previous value is shifted by the nearest multiple of 2π
//!    (`floor(d / 2π + 0.5)`), then Blender's "pi flip": an angle still more than π away while
//!    the two others are within π/2 is moved by one more turn to the other side of `previous`
//!    (in f64 this only fires when rounding leaves the corrected difference a hair beyond ±π)
//!    — and the solution with the smaller sum of absolute differences to `previous` wins, `e1`
//!    on a tie. Blender's `pi_thresh` is `float(π)`, slightly above π, so in `f32` the flip also
//!    fires for a difference of exactly π (a half turn with `previous` 0 comes out as −π there,
//!    +π here): both answers are then exactly equally close, and only such ties can differ.
//!
//! Differences from `mathutils`: everything is `f64` (Blender computes and stores `f32`); and
//! [`from_quaternion`] returns the principal solution `e1`, whereas Blender's
//! `to_euler(order)` without `euler_compat` returns whichever of `e1`, `e2` has the smaller sum of
//! absolute angles — that one is [`from_quaternion_blender`].

use super::EulerOrder;
use super::quat::axis_rotation;
use nalgebra::{Matrix3, UnitQuaternion};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

pub use super::quat::{angle_between, make_hemisphere_continuous};

/// Blender's `EULER_HYPOT_EPSILON`: below this value of `cos(middle angle)` a rotation is treated
/// as gimbal locked (first angle, `angles[0]`, set to 0). See the module documentation.
pub const GIMBAL_LOCK_EPSILON: f64 = 3.75e-5;

/// The quaternion of intrinsic Euler angles in application order:
/// `R_axes[0](angles[0]) · R_axes[1](angles[1]) · R_axes[2](angles[2])`.
///
/// The sign is that of the product of the three half-angle axis quaternions (the same sign
/// Blender's `Euler.to_quaternion()` gives), so it is not normalised to `w >= 0`.
pub fn to_quaternion(angles: [f64; 3], order: EulerOrder) -> UnitQuaternion<f64> {
    let axes = order.axes();
    let q = axis_rotation(axes[0], angles[0]).into_inner()
        * axis_rotation(axes[1], angles[1]).into_inner()
        * axis_rotation(axes[2], angles[2]).into_inner();
    // A product of unit quaternions is unit up to rounding; renormalise to keep it exactly so.
    UnitQuaternion::new_normalize(q)
}

/// The principal Euler angles (application order) of `q`: middle angle in [-π/2, π/2], first and
/// last in (-π, π]. At gimbal lock (see [`GIMBAL_LOCK_EPSILON`]) the first angle is 0 and the
/// last one carries the rotation about the shared axis.
///
/// This is Blender's first solution `eul1`; it never returns NaN for a finite quaternion.
#[inline(always)]
pub fn from_quaternion(q: &UnitQuaternion<f64>, order: EulerOrder) -> [f64; 3] {
    Solutions::of(q, order).principal()
}

/// What `mathutils.Quaternion.to_euler(blender_order)` returns (without `euler_compat`): of the
/// two solutions, the one with the smaller sum of absolute angles (the principal one on a tie).
/// Its middle angle may lie outside [-π/2, π/2]. Angles in application order.
pub fn from_quaternion_blender(q: &UnitQuaternion<f64>, order: EulerOrder) -> [f64; 3] {
    let (e1, e2) = two_solutions(q, order);
    let d1: f64 = e1.iter().map(|a| a.abs()).sum();
    let d2: f64 = e2.iter().map(|a| a.abs()).sum();
    if d1 > d2 { e2 } else { e1 }
}

/// The Euler angles of `q` (application order) closest to `previous`, as Blender's
/// `Quaternion.to_euler(order, previous)` / `mat3_normalized_to_compatible_eulO` choose them:
/// of the two solutions `(a, b, c)` and `(a + π, π − b, c + π)`, each angle shifted by multiples
/// of 2π towards `previous`, the one with the smaller sum of absolute differences.
///
/// A non-finite `previous` (which Blender would turn into garbage) gives [`from_quaternion`].
#[inline(always)]
pub fn compatible(q: &UnitQuaternion<f64>, order: EulerOrder, previous: [f64; 3]) -> [f64; 3] {
    let solutions = Solutions::of(q, order);
    let principal = solutions.principal();
    let mut e1 = principal;
    if !previous.iter().all(|v| v.is_finite()) {
        return e1;
    }
    compatible_eul(&mut e1, &previous);
    let d1 = l1_distance(&e1, &previous);
    if solutions.locked() {
        // Both solutions are e1: a tie, which e1 wins.
        return e1;
    }
    // The second solution's distance is known to within rounding from e1 alone (it is
    // (a + π, π − b, c + π), and compatible_eul leaves each angle at its circular distance): its
    // three atan2 are computed only when it may win. The margin is ~10⁶ times the rounding.
    let [a, b, c] = principal;
    let d2_estimate = circular_distance(a + PI, previous[0])
        + circular_distance(PI - b, previous[1])
        + circular_distance(c + PI, previous[2]);
    const MARGIN: f64 = 1e-9;
    if d1 + MARGIN < d2_estimate {
        return e1;
    }
    let mut e2 = solutions.second();
    compatible_eul(&mut e2, &previous);
    let d2 = l1_distance(&e2, &previous);
    if d1 > d2 { e2 } else { e1 }
}

/// The Euler discontinuity filter: frame 0 is [`from_quaternion`], every later frame is
/// [`compatible`] with the previous output. Angles may grow beyond ±π on continuous spins.
pub fn filter_track(track: &[UnitQuaternion<f64>], order: EulerOrder) -> Vec<[f64; 3]> {
    filter_track_then(track, order, |angles| angles)
}

/// [`filter_track`] in degrees (each angle through `f64::to_degrees`), as BVH writes them.
pub fn filter_track_degrees(track: &[UnitQuaternion<f64>], order: EulerOrder) -> Vec<[f64; 3]> {
    filter_track_then(track, order, |angles| angles.map(f64::to_degrees))
}

/// [`filter_track`] with each frame's angles passed through `then` as they are made (no second
/// pass over the track).
#[inline]
fn filter_track_then(
    track: &[UnitQuaternion<f64>],
    order: EulerOrder,
    then: impl Fn([f64; 3]) -> [f64; 3],
) -> Vec<[f64; 3]> {
    let mut out = Vec::with_capacity(track.len());
    TrackFilter::new(order).extend_then(track, then, &mut out);
    out
}

/// [`filter_track`] a run of frames at a time: the runs of a track fed in turn give, to the bit,
/// what the whole track gives at once (a writer that makes each block of frames' angles as it
/// writes them never holds the whole track's).
#[derive(Debug, Clone, Copy)]
pub struct TrackFilter {
    filter: EulerFilter,
    /// The last frame's angles were made by `compatible` from those before them, and equal them.
    settled: bool,
    previous_q: Option<UnitQuaternion<f64>>,
    /// The last output (after `then`).
    last: Option<[f64; 3]>,
}

impl TrackFilter {
    pub fn new(order: EulerOrder) -> TrackFilter {
        TrackFilter {
            filter: EulerFilter::new(order),
            settled: false,
            previous_q: None,
            last: None,
        }
    }

    /// Appends the next frames' angles in degrees ([`filter_track_degrees`]) to `out`.
    pub fn extend_degrees(&mut self, run: &[UnitQuaternion<f64>], out: &mut Vec<[f64; 3]>) {
        self.extend_then(run, |angles| angles.map(f64::to_degrees), out);
    }

    #[inline]
    fn extend_then(
        &mut self,
        run: &[UnitQuaternion<f64>],
        then: impl Fn([f64; 3]) -> [f64; 3],
        out: &mut Vec<[f64; 3]>,
    ) {
        // One copy of the loop per order: with the axes known when compiling, only the matrix
        // entries the angles use are computed and the axis bookkeeping folds away. The arithmetic
        // is the same, so the angles are the same to the bit.
        match self.filter.order {
            EulerOrder::XYZ => self.extend_in::<0>(run, then, out),
            EulerOrder::XZY => self.extend_in::<1>(run, then, out),
            EulerOrder::YXZ => self.extend_in::<2>(run, then, out),
            EulerOrder::YZX => self.extend_in::<3>(run, then, out),
            EulerOrder::ZXY => self.extend_in::<4>(run, then, out),
            EulerOrder::ZYX => self.extend_in::<5>(run, then, out),
        }
    }

    /// [`Self::extend_then`] for the order `EulerOrder::ALL[ORDER]`.
    ///
    /// Each frame's angles are a function of its rotation and the previous frame's angles, so
    /// once a frame gives the very angles of the frame before, every following frame with the
    /// same rotation gives them again: a joint that holds still (a rig's unsensed joints, all of a
    /// finger) costs a comparison per frame instead of an Euler conversion, to the same bits.
    fn extend_in<const ORDER: usize>(
        &mut self,
        run: &[UnitQuaternion<f64>],
        then: impl Fn([f64; 3]) -> [f64; 3],
        out: &mut Vec<[f64; 3]>,
    ) {
        // The order as a constant here (a local filter), not a field read through `self`.
        let mut filter = EulerFilter {
            order: EulerOrder::ALL[ORDER],
            previous: self.filter.previous,
        };
        let (mut settled, mut previous_q, mut last) = (self.settled, self.previous_q, self.last);
        out.reserve(run.len());
        for q in run {
            let same_rotation = previous_q.is_some_and(|p| same_bits(&p, q));
            previous_q = Some(*q);
            if settled
                && same_rotation
                && let Some(last) = last
            {
                out.push(last);
                continue;
            }
            let before = filter.previous;
            let angles = filter.next(q);
            settled = before.is_some_and(|b| b.map(f64::to_bits) == angles.map(f64::to_bits));
            let made = then(angles);
            last = Some(made);
            out.push(made);
        }
        self.filter.previous = filter.previous;
        (self.settled, self.previous_q, self.last) = (settled, previous_q, last);
    }
}

/// The two rotations are stored as the same four doubles.
#[inline(always)]
fn same_bits(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> bool {
    a.coords.map(f64::to_bits) == b.coords.map(f64::to_bits)
}

/// The incremental core of [`filter_track`]: one frame at a time.
#[derive(Debug, Clone, Copy)]
pub struct EulerFilter {
    order: EulerOrder,
    previous: Option<[f64; 3]>,
}

impl EulerFilter {
    pub fn new(order: EulerOrder) -> EulerFilter {
        EulerFilter {
            order,
            previous: None,
        }
    }

    /// The next frame's angles (radians, application order).
    #[inline(always)]
    pub fn next(&mut self, q: &UnitQuaternion<f64>) -> [f64; 3] {
        let angles = match self.previous {
            None => from_quaternion(q, self.order),
            Some(previous) => compatible(q, self.order, previous),
        };
        self.previous = Some(angles);
        angles
    }
}

/// Application-order angles from Blender's per-axis storage (`[euler.x, euler.y, euler.z]` of an
/// `Euler` in mode `order.blender_name()`).
#[inline]
pub fn from_blender_xyz(xyz: [f64; 3], order: EulerOrder) -> [f64; 3] {
    order.axes().map(|axis| xyz[axis])
}

/// Blender's per-axis storage (`[x, y, z]`, mode `order.blender_name()`) of application-order
/// angles.
pub fn to_blender_xyz(angles: [f64; 3], order: EulerOrder) -> [f64; 3] {
    let mut xyz = [0.0; 3];
    for (k, axis) in order.axes().into_iter().enumerate() {
        xyz[axis] = angles[k];
    }
    xyz
}

/// Blender's `mat3_normalized_to_eulo2`, in application order: (principal, second solution).
fn two_solutions(q: &UnitQuaternion<f64>, order: EulerOrder) -> ([f64; 3], [f64; 3]) {
    let s = Solutions::of(q, order);
    (s.principal(), s.second())
}

/// The rotation matrix entries and axes that both of Blender's solutions are computed from, so
/// that each is computed only when it is needed (three `atan2` each).
struct Solutions {
    order: EulerOrder,
    m: Matrix3<f64>,
    /// Blender's axis triple: its own order string's axes, i.e. ours reversed.
    ijk: (usize, usize, usize),
    /// `cos(middle angle)`.
    cy: f64,
}

impl Solutions {
    #[inline(always)]
    fn of(q: &UnitQuaternion<f64>, order: EulerOrder) -> Solutions {
        let m: Matrix3<f64> = q.to_rotation_matrix().into_inner();
        let axes = order.axes();
        let (i, j, k) = (axes[2], axes[1], axes[0]);
        let mut s = Solutions {
            order,
            m,
            ijk: (i, j, k),
            cy: 0.0,
        };
        s.cy = s.r(i, i).hypot(s.r(i, j));
        s
    }

    /// Blender's column-major `mat[a][b]` is `m[(b, a)]`.
    #[inline]
    fn r(&self, a: usize, b: usize) -> f64 {
        self.m[(b, a)]
    }

    /// At gimbal lock both solutions are the same.
    #[inline]
    fn locked(&self) -> bool {
        self.cy <= GIMBAL_LOCK_EPSILON
    }

    /// Blender's `eul1`.
    #[inline(always)]
    fn principal(&self) -> [f64; 3] {
        let (i, j, k) = self.ijk;
        let mut e = [0.0; 3];
        if !self.locked() {
            e[i] = self.r(j, k).atan2(self.r(k, k));
            e[j] = (-self.r(i, k)).atan2(self.cy);
            e[k] = self.r(i, j).atan2(self.r(i, i));
        } else {
            e[i] = (-self.r(k, j)).atan2(self.r(j, j));
            e[j] = (-self.r(i, k)).atan2(self.cy);
            e[k] = 0.0;
        }
        self.finish(e)
    }

    /// Blender's `eul2`: the same rotation as `(a + π, π − b, c + π)` (application order).
    #[inline(always)]
    fn second(&self) -> [f64; 3] {
        if self.locked() {
            return self.principal();
        }
        let (i, j, k) = self.ijk;
        let mut e = [0.0; 3];
        e[i] = (-self.r(j, k)).atan2(-self.r(k, k));
        e[j] = (-self.r(i, k)).atan2(-self.cy);
        e[k] = (-self.r(i, j)).atan2(-self.r(i, i));
        self.finish(e)
    }

    /// Per-axis angles → application order, negated for odd permutations (Blender's `parity`).
    #[inline(always)]
    fn finish(&self, mut e: [f64; 3]) -> [f64; 3] {
        let (i, j, _) = self.ijk;
        let parity_odd = j != (i + 1) % 3;
        for v in &mut e {
            if parity_odd {
                *v = -*v;
            }
            // atan2(-0.0, -1.0) is -π and negation turns π into -π: report +π so that the
            // principal range is (-π, π] whatever the sign of a zero; and no -0.0 in outputs.
            *v = if *v == -PI { PI } else { *v + 0.0 };
        }
        from_blender_xyz(e, self.order)
    }
}

/// The distance from `a` to the nearest angle equal to `b` modulo 2π, in [0, π]: what
/// [`compatible_eul`] leaves between an angle and the previous one, up to rounding.
#[inline]
fn circular_distance(a: f64, b: f64) -> f64 {
    // Whole turns removed by rounding (a software `fmod` costs more than the rest of the
    // estimate); off by ~1e-15 per turn, far inside the margin it is used with. Adding and
    // subtracting 1.5·2⁵² rounds to the nearest whole number in two additions where `round` is a
    // library call on baseline x86-64 (exact below 2⁵¹; at a tie either turn leaves π).
    const ROUNDER: f64 = 6_755_399_441_055_744.0;
    let d = a - b;
    let turns = d / TAU;
    let whole = if turns.abs() < 2_251_799_813_685_248.0 {
        (turns + ROUNDER) - ROUNDER
    } else {
        turns.round()
    };
    (d - TAU * whole).abs()
}

/// Blender's `compatible_eul`: shift each angle by multiples of 2π towards `old`, then the
/// "pi flip". The operation treats the three angles symmetrically, so it is the same in
/// application order as in Blender's per-axis order.
#[inline(always)]
fn compatible_eul(eul: &mut [f64; 3], old: &[f64; 3]) {
    // Blender uses `pi_thresh = float(M_PI)` and `pi_x2 = 2 * float(M_PI)` (f32); here the f64
    // π and 2π, so that exact-π differences are not flipped (see the module documentation).
    let mut deul = [0.0; 3];
    for n in 0..3 {
        deul[n] = eul[n] - old[n];
        if deul[n] > PI {
            eul[n] -= (deul[n] / TAU + 0.5).floor() * TAU;
            deul[n] = eul[n] - old[n];
        } else if deul[n] < -PI {
            eul[n] += (-deul[n] / TAU + 0.5).floor() * TAU;
            deul[n] = eul[n] - old[n];
        }
    }
    // An axis still more than 180° away while the two others are within 90°: one more turn.
    // `deul` is not updated here, so each axis is decided independently, as in Blender.
    for n in 0..3 {
        let (o1, o2) = ((n + 1) % 3, (n + 2) % 3);
        if deul[n].abs() > PI && deul[o1].abs() < FRAC_PI_2 && deul[o2].abs() < FRAC_PI_2 {
            if deul[n] > 0.0 {
                eul[n] -= TAU;
            } else {
                eul[n] += TAU;
            }
        }
    }
}

#[inline]
fn l1_distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Quaternion, Vector3};
    use proptest::prelude::*;

    const DEG: f64 = PI / 180.0;

    fn quat_strategy() -> impl Strategy<Value = UnitQuaternion<f64>> {
        (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0)
            .prop_filter("non-degenerate", |(w, x, y, z)| {
                w * w + x * x + y * y + z * z > 1e-3
            })
            .prop_map(|(w, x, y, z)| UnitQuaternion::new_normalize(Quaternion::new(w, x, y, z)))
    }

    fn order_strategy() -> impl Strategy<Value = EulerOrder> {
        prop::sample::select(EulerOrder::ALL.to_vec())
    }

    /// Independent reference: the product of axis rotation *matrices* (not quaternions).
    fn matrix_of(angles: [f64; 3], order: EulerOrder) -> Matrix3<f64> {
        let axes = order.axes();
        let one = |axis: usize, a: f64| {
            let (s, c) = a.sin_cos();
            match axis {
                0 => Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c),
                1 => Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c),
                _ => Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0),
            }
        };
        one(axes[0], angles[0]) * one(axes[1], angles[1]) * one(axes[2], angles[2])
    }

    fn rot_err(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
        angle_between(a, b)
    }

    #[test]
    fn hand_calculated_cases() {
        let x = Vector3::x();
        let y = Vector3::y();
        let z = Vector3::z();
        // ZXY (90°, 0, 0) is Rz(90°): +x → +y.
        let q = to_quaternion([90.0 * DEG, 0.0, 0.0], EulerOrder::ZXY);
        assert!((q * x - y).norm() < 1e-15);
        // ZXY (0, 90°, 0) is Rx(90°): +y → +z.
        let q = to_quaternion([0.0, 90.0 * DEG, 0.0], EulerOrder::ZXY);
        assert!((q * y - z).norm() < 1e-15);
        // ZXY (0, 0, 90°) is Ry(90°): +z → +x.
        let q = to_quaternion([0.0, 0.0, 90.0 * DEG], EulerOrder::ZXY);
        assert!((q * z - x).norm() < 1e-15);
        // ZXY (90°, 90°, 0) = Rz(90°)·Rx(90°): +y → (Rx) +z → (Rz) +z; +z → -y → +x.
        let q = to_quaternion([90.0 * DEG, 90.0 * DEG, 0.0], EulerOrder::ZXY);
        assert!((q * y - z).norm() < 1e-15);
        assert!((q * z - x).norm() < 1e-15);
        // XYZ (0, 0, 90°) then the order matters: Rx(90°)·Rz(90°) maps +x → +y → +z.
        let q = to_quaternion([90.0 * DEG, 0.0, 90.0 * DEG], EulerOrder::XYZ);
        assert!((q * x - z).norm() < 1e-15);
        // ... and ZYX (90°, 0, 90°) = Rz(90°)·Rx(90°) maps +y → +z → +z, +x → +x → +y.
        let q = to_quaternion([90.0 * DEG, 0.0, 90.0 * DEG], EulerOrder::ZYX);
        assert!((q * x - y).norm() < 1e-15);
        assert!((q * y - z).norm() < 1e-15);

        // Back: Rz(30°)·Rx(20°)·Ry(10°) recovered by ZXY.
        let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 30.0 * DEG)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 20.0 * DEG)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 10.0 * DEG);
        let e = from_quaternion(&q, EulerOrder::ZXY);
        for (got, want) in e.iter().zip([30.0 * DEG, 20.0 * DEG, 10.0 * DEG]) {
            assert!((got - want).abs() < 1e-14, "{e:?}");
        }
    }

    #[test]
    fn blender_storage_conversion() {
        // BVH `Zrotation 10 Xrotation 20 Yrotation 30` is Blender mode 'YXZ' with
        // x = 20, y = 30, z = 10.
        let ours = [10.0, 20.0, 30.0];
        assert_eq!(to_blender_xyz(ours, EulerOrder::ZXY), [20.0, 30.0, 10.0]);
        assert_eq!(from_blender_xyz([20.0, 30.0, 10.0], EulerOrder::ZXY), ours);
        for order in EulerOrder::ALL {
            assert_eq!(from_blender_xyz(to_blender_xyz(ours, order), order), ours);
        }
    }

    #[test]
    fn to_quaternion_matches_matrix_product() {
        for order in EulerOrder::ALL {
            for angles in [[0.3, -1.2, 2.9], [-3.5, 0.1, 7.0], [PI, FRAC_PI_2, -PI]] {
                let q = to_quaternion(angles, order);
                let m = matrix_of(angles, order);
                let diff = (q.to_rotation_matrix().into_inner() - m).abs().max();
                assert!(diff < 1e-14, "{order} {angles:?}: {diff}");
            }
        }
    }

    #[test]
    fn exact_gimbal_lock_round_trips() {
        for order in EulerOrder::ALL {
            for b in [FRAC_PI_2, -FRAC_PI_2] {
                for (a, c) in [(0.0, 0.0), (0.7, -0.4), (-2.5, 3.0), (PI, PI), (1.0, 1.0)] {
                    let q = to_quaternion([a, b, c], order);
                    let e = from_quaternion(&q, order);
                    assert!(e.iter().all(|v| v.is_finite()));
                    assert_eq!(e[0], 0.0, "{order}: first angle is 0 at gimbal lock");
                    assert!((e[1] - b).abs() < 1e-7, "{order} {e:?}");
                    let back = to_quaternion(e, order);
                    assert!(rot_err(&q, &back) < 1e-12, "{order} {e:?}");
                    // The compatible form also stays finite and equivalent.
                    let e = compatible(&q, order, [a + 0.1, b, c - 0.1]);
                    assert!(rot_err(&q, &to_quaternion(e, order)) < 1e-12);
                }
            }
        }
    }

    /// Inside Blender's gimbal-lock band the first angle is dropped; the rotation error is
    /// bounded by about 2·cos(middle angle).
    #[test]
    fn near_gimbal_lock_error_is_bounded() {
        for order in EulerOrder::ALL {
            for cy in [1e-12, 1e-9, 1e-6, 1e-5, 3.0e-5, 3.7e-5, 3.8e-5, 1e-4, 1e-3] {
                for sign in [1.0, -1.0] {
                    for (a, c) in [(0.3, -0.2), (2.0, 3.1), (-3.1, -3.1)] {
                        let b = sign * (FRAC_PI_2 - cy);
                        let q = to_quaternion([a, b, c], order);
                        let e = from_quaternion(&q, order);
                        let err = rot_err(&q, &to_quaternion(e, order));
                        let bound = if cy <= GIMBAL_LOCK_EPSILON {
                            2.0 * cy + 1e-12
                        } else {
                            // Exact branch: atan2 of entries of size cy, f64 noise ~1e-16.
                            1e-15 / cy + 1e-13
                        };
                        assert!(err <= bound, "{order} cy={cy} {e:?}: {err} > {bound}");
                    }
                }
            }
        }
    }

    #[test]
    fn compatible_prefers_continuity_and_spins() {
        let order = EulerOrder::ZXY;
        // 350° about z, previous 340°: keep going rather than wrapping to -10°.
        let q = to_quaternion([350.0 * DEG, 0.0, 0.0], order);
        let e = compatible(&q, order, [340.0 * DEG, 0.0, 0.0]);
        assert!((e[0] - 350.0 * DEG).abs() < 1e-12, "{e:?}");
        // Two turns and a bit.
        let e = compatible(&q, order, [700.0 * DEG, 0.0, 0.0]);
        assert!((e[0] - 710.0 * DEG).abs() < 1e-12, "{e:?}");
        let e = compatible(&q, order, [-372.0 * DEG, 0.0, 0.0]);
        assert!((e[0] + 370.0 * DEG).abs() < 1e-12, "{e:?}");
        // The second solution: previous near (a + π, π − b, c + π).
        let angles = [0.4, 1.3, -0.2];
        let q = to_quaternion(angles, order);
        let previous = [0.4 + PI, PI - 1.3, -0.2 + PI];
        let e = compatible(&q, order, previous);
        for (g, w) in e.iter().zip(previous) {
            assert!((g - w).abs() < 1e-12, "{e:?}");
        }
        // Non-finite previous values fall back to the principal solution.
        let e = compatible(&q, order, [f64::NAN, 0.0, f64::INFINITY]);
        assert_eq!(e, from_quaternion(&q, order));
    }

    #[test]
    fn compatible_eul_pi_flip() {
        // Just past the ±π boundary, the 2π correction lands inside (−π, π].
        let mut e = [-PI - 1e-9, 0.1, -0.1];
        compatible_eul(&mut e, &[0.0, 0.0, 0.0]);
        assert!((e[0] - (PI - 1e-9)).abs() < 1e-12, "{e:?}");
        // Large differences are wrapped to the nearest turn.
        let mut e = [10.0, -10.0, 0.5];
        compatible_eul(&mut e, &[0.0, 0.0, 0.0]);
        assert!((e[0] - (10.0 - 2.0 * TAU)).abs() < 1e-12, "{e:?}");
        assert!((e[1] - (-10.0 + 2.0 * TAU)).abs() < 1e-12, "{e:?}");
        assert_eq!(e[2], 0.5);
        // 19π (f64) minus 3 turns rounds to −3.1415926535897967, still beyond −π: the pi flip
        // adds one more turn because the other two angles are within 90°...
        let mut e = [19.0 * PI, 0.1, -0.1];
        compatible_eul(&mut e, &[0.0, 0.0, 0.0]);
        assert!(e[0] > 0.0 && (e[0] - PI).abs() < 1e-14, "{e:?}");
        // ... and does not when one of them is not.
        let mut e = [19.0 * PI, 0.1, -2.0];
        compatible_eul(&mut e, &[0.0, 0.0, 0.0]);
        assert!(e[0] < -PI && (e[0] + PI).abs() < 1e-14, "{e:?}");
    }

    #[test]
    fn ties_keep_the_principal_solution() {
        // Identity with previous (π/2, π/2, π/2): (0, 0, 0) and (π, π, π) are both 3π/2 away;
        // Blender keeps the first solution on a tie (`d1 > d2` picks the second only).
        for order in EulerOrder::ALL {
            let q = UnitQuaternion::identity();
            let e = compatible(&q, order, [FRAC_PI_2; 3]);
            assert_eq!(e, [0.0; 3], "{order}");
            let e = from_quaternion_blender(&q, order);
            assert_eq!(e, [0.0; 3], "{order}");
        }
    }

    #[test]
    fn half_turns_give_plus_pi() {
        for order in EulerOrder::ALL {
            for axis in 0..3 {
                let mut v = [0.0; 4];
                v[axis + 1] = 1.0;
                let q = UnitQuaternion::new_unchecked(Quaternion::new(v[0], v[1], v[2], v[3]));
                let e = from_quaternion(&q, order);
                assert!(
                    e.iter().all(|a| *a == 0.0 || *a == PI),
                    "{order} {axis}: {e:?}"
                );
                assert!(
                    e.iter().all(|a| a.is_sign_positive()),
                    "{order} {axis}: {e:?}"
                );
                assert!(rot_err(&q, &to_quaternion(e, order)) < 1e-15);
            }
        }
    }

    #[test]
    fn filter_track_empty_and_single() {
        assert!(filter_track(&[], EulerOrder::XYZ).is_empty());
        let q = to_quaternion([0.1, 0.2, 0.3], EulerOrder::YZX);
        let out = filter_track(&[q], EulerOrder::YZX);
        assert_eq!(out, vec![from_quaternion(&q, EulerOrder::YZX)]);
    }

    /// Frames held still are copied rather than converted, to exactly what converting each
    /// frame in turn gives: tracks of runs of repeated rotations — ordinary ones, half-turn
    /// flips, spins, gimbal lock, a joint that never moves — in every order; and fed to a
    /// [`TrackFilter`] in pieces, what the whole track gives.
    #[test]
    fn held_frames_give_what_frame_by_frame_conversion_gives() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for order in EulerOrder::ALL {
            for case in 0..60 {
                let mut track = Vec::new();
                let mut angle = [0.0f64; 3];
                while track.len() < 400 {
                    match case % 4 {
                        // A joint that never moves.
                        0 => angle = [0.3, -0.2, 0.1],
                        // Small steps, some across ±180°, some through the middle axis's ±90°.
                        1 => {
                            for a in &mut angle {
                                *a += (next() - 0.5) * 0.8;
                            }
                        }
                        2 => {
                            angle = [
                                next() * 12.0 - 6.0,
                                FRAC_PI_2 * (next() - 0.5).signum(),
                                next(),
                            ]
                        }
                        _ => angle = [angle[0] + 0.9, next() * 3.0 - 1.5, angle[2] - 0.7],
                    }
                    let q = to_quaternion(angle, order);
                    let run = 1 + (next() * 6.0) as usize;
                    track.extend(std::iter::repeat_n(q, run));
                }
                let mut filter = EulerFilter::new(order);
                let expected: Vec<[u64; 3]> = track
                    .iter()
                    .map(|q| filter.next(q).map(f64::to_bits))
                    .collect();
                let got: Vec<[u64; 3]> = filter_track(&track, order)
                    .iter()
                    .map(|a| a.map(f64::to_bits))
                    .collect();
                assert_eq!(got, expected, "{order} case {case}");
                // The same track fed in runs of 0 to 40 frames, as the BVH writer feeds it a
                // group of frames at a time: the whole track's angles to the bit.
                let whole: Vec<[u64; 3]> = filter_track_degrees(&track, order)
                    .iter()
                    .map(|a| a.map(f64::to_bits))
                    .collect();
                let mut runs = TrackFilter::new(order);
                let mut in_runs = Vec::new();
                let mut at = 0;
                while at < track.len() {
                    let len = ((next() * 41.0) as usize).min(track.len() - at);
                    runs.extend_degrees(&track[at..at + len], &mut in_runs);
                    at += len;
                }
                let in_runs: Vec<[u64; 3]> = in_runs.iter().map(|a| a.map(f64::to_bits)).collect();
                assert_eq!(in_runs, whole, "{order} case {case}, in runs");
            }
        }
    }

    #[test]
    fn filter_track_degrees_is_filter_track_in_degrees() {
        for order in EulerOrder::ALL {
            let track: Vec<_> = (0..200)
                .map(|n| to_quaternion([n as f64 * 0.09, 1.2 - n as f64 * 0.01, -0.4], order))
                .collect();
            let radians = filter_track(&track, order);
            let degrees = filter_track_degrees(&track, order);
            for (r, d) in radians.iter().zip(&degrees) {
                assert_eq!(r.map(|a| a.to_degrees().to_bits()), d.map(f64::to_bits));
            }
        }
    }

    #[test]
    fn filter_track_unwraps_a_long_spin() {
        for order in EulerOrder::ALL {
            // Spin 3 turns about the first-applied axis with a small constant tilt.
            let track: Vec<_> = (0..300)
                .map(|n| to_quaternion([n as f64 * 0.07, 0.3, -0.2], order))
                .collect();
            let out = filter_track(&track, order);
            for (n, e) in out.iter().enumerate() {
                assert!(
                    (e[0] - n as f64 * 0.07).abs() < 1e-9,
                    "{order} frame {n}: {e:?}"
                );
                assert!((e[1] - 0.3).abs() < 1e-9 && (e[2] + 0.2).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn circular_distance_is_the_distance_modulo_a_turn() {
        // Against fmod, far from and at half turns, at every scale the filter can reach.
        let reference = |a: f64, b: f64| {
            let r = (a - b).rem_euclid(TAU);
            r.min(TAU - r)
        };
        let mut x = 0.123_456_789_f64;
        for i in 0..200_000 {
            // A cheap generator over [-1, 1), scaled from 1e-3 to 1e6 radians.
            x = (x * 3.987_654_321 + 0.314_159).fract();
            let scale = 10f64.powi(i % 10 - 3);
            let (a, b) = ((2.0 * x - 1.0) * scale, (1.0 - 2.0 * x * x) * scale);
            let want = reference(a, b);
            let tolerance = 1e-15 * (1.0 + a.abs() + b.abs());
            assert!(
                (circular_distance(a, b) - want).abs() <= tolerance,
                "{a} {b}"
            );
        }
        for k in -7..=7 {
            let odd_half_turns = f64::from(2 * k + 1) * PI;
            assert!(
                (circular_distance(odd_half_turns, 0.0) - PI).abs() < 1e-14,
                "{k}"
            );
            assert!(circular_distance(f64::from(k) * TAU, 0.0) < 1e-14, "{k}");
        }
        assert_eq!(circular_distance(1e300, 1e300), 0.0);
        assert!(circular_distance(f64::NAN, 0.0).is_nan());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn round_trip_every_order(q in quat_strategy(), order in order_strategy()) {
            let e = from_quaternion(&q, order);
            prop_assert!((-FRAC_PI_2..=FRAC_PI_2).contains(&e[1]), "{:?}", e);
            prop_assert!(e[0].abs() <= PI && e[2].abs() <= PI);
            let back = to_quaternion(e, order);
            // Up to sign: compare rotations.
            prop_assert!(rot_err(&q, &back) < 1e-9, "{} {:?}", order, e);
            let m = matrix_of(e, order);
            prop_assert!((m - q.to_rotation_matrix().into_inner()).abs().max() < 1e-9);
            // The Blender choice is the same rotation.
            let eb = from_quaternion_blender(&q, order);
            prop_assert!(rot_err(&q, &to_quaternion(eb, order)) < 1e-9);
        }

        #[test]
        fn angles_round_trip(
            a in -PI..PI, b in -FRAC_PI_2..FRAC_PI_2, c in -PI..PI, order in order_strategy()
        ) {
            let q = to_quaternion([a, b, c], order);
            let e = from_quaternion(&q, order);
            let cy = b.cos();
            prop_assume!(cy > 1e-3);
            let tol = 1e-12 / cy;
            prop_assert!((e[0] - a).abs() < tol && (e[1] - b).abs() < tol && (e[2] - c).abs() < tol,
                "{} {:?} vs {:?}", order, e, [a, b, c]);
        }

        #[test]
        fn compatible_is_the_closest_representation(
            q in quat_strategy(),
            order in order_strategy(),
            previous in prop::array::uniform3(-20.0f64..20.0),
        ) {
            let e = compatible(&q, order, previous);
            prop_assert!(rot_err(&q, &to_quaternion(e, order)) < 1e-9);
            let best = l1_distance(&e, &previous);
            // Every representation (both families, any turns) is at least as far away.
            let e1 = from_quaternion(&q, order);
            let e2 = [e1[0] + PI, PI - e1[1], e1[2] + PI];
            for family in [e1, e2] {
                for t0 in -5..=5 {
                    for t1 in -5..=5 {
                        for t2 in -5..=5 {
                            let cand = [
                                family[0] + TAU * t0 as f64,
                                family[1] + TAU * t1 as f64,
                                family[2] + TAU * t2 as f64,
                            ];
                            prop_assert!(best <= l1_distance(&cand, &previous) + 1e-9,
                                "{:?} beats {:?} for {:?}", cand, e, previous);
                        }
                    }
                }
            }
        }

        /// Computing the second solution only when it may win changes nothing: the same answer,
        /// bit for bit, as computing both always (Blender's way), for any previous angles and
        /// for previous angles almost equally far from both solutions (the ties).
        #[test]
        fn compatible_equals_both_solutions_computed(
            q in quat_strategy(),
            order in order_strategy(),
            previous in prop::array::uniform3(-20.0f64..20.0),
            blend in 0.0f64..1.0,
            nudge in prop::array::uniform3(-1e-12f64..1e-12),
        ) {
            let both = |previous: [f64; 3]| {
                let (mut e1, mut e2) = two_solutions(&q, order);
                compatible_eul(&mut e1, &previous);
                compatible_eul(&mut e2, &previous);
                if l1_distance(&e1, &previous) > l1_distance(&e2, &previous) { e2 } else { e1 }
            };
            let bits = |e: [f64; 3]| e.map(f64::to_bits);
            prop_assert_eq!(bits(compatible(&q, order, previous)), bits(both(previous)));
            // Between the two solutions' representations nearest to each other.
            let (e1, e2) = two_solutions(&q, order);
            let tie: [f64; 3] = std::array::from_fn(|n| {
                let e2n = e1[n] + (e2[n] - e1[n] + PI).rem_euclid(TAU) - PI;
                e1[n] + blend * (e2n - e1[n]) + nudge[n]
            });
            prop_assert_eq!(bits(compatible(&q, order, tie)), bits(both(tie)));
        }

        /// Smooth input away from gimbal lock: no Euler jump larger than the rotation step times
        /// the Euler-rate bound. For intrinsic angles (a, b, c) and an angular velocity ω:
        /// |ȧ| ≤ |ω|/cos b, |ḃ| ≤ |ω|, |ċ| ≤ |ω|(1 + |tan b|) ≤ 2|ω|/cos b. Along a step of
        /// angle δ the middle angle moves by at most δ, hence the bound 2δ/cos(|b| + δ).
        #[test]
        fn filter_track_has_no_jumps(
            start in quat_strategy(),
            axis in prop::array::uniform3(-1.0f64..1.0),
            wobble in prop::array::uniform3(-1.0f64..1.0),
            speed in 0.001f64..0.2,
            order in order_strategy(),
        ) {
            let axis = Vector3::from(axis);
            prop_assume!(axis.norm() > 0.1);
            let wobble = Vector3::from(wobble);
            let mut q = start;
            let mut track = vec![q];
            for n in 0..150 {
                let w = (axis.normalize() + 0.5 * (n as f64 * 0.05).sin() * wobble) * speed;
                q *= UnitQuaternion::from_scaled_axis(w);
                track.push(q);
            }
            let out = filter_track(&track, order);
            for n in 1..track.len() {
                let step = rot_err(&track[n - 1], &track[n]);
                let b = out[n - 1][1].abs().max(out[n][1].abs());
                // Reduce b modulo the second family (π − b) to the distance from ±90°.
                let b = {
                    let r = b.rem_euclid(PI);
                    r.min(PI - r)
                };
                let margin = FRAC_PI_2 - (b + step);
                if margin < 0.05 {
                    // Near gimbal lock Euler angles legitimately move fast (or jump at lock).
                    continue;
                }
                let bound = 2.0 * step / margin.sin() + 1e-9;
                for k in 0..3 {
                    let jump = (out[n][k] - out[n - 1][k]).abs();
                    prop_assert!(jump <= bound, "{} frame {}: {:?} → {:?} (step {})",
                        order, n, out[n - 1], out[n], step);
                }
            }
        }

        #[test]
        fn filter_track_ignores_quaternion_signs(
            start in quat_strategy(),
            signs in prop::collection::vec(any::<bool>(), 40),
            order in order_strategy(),
        ) {
            let step = UnitQuaternion::from_scaled_axis(Vector3::new(0.05, -0.03, 0.08));
            let mut q = start;
            let mut track = Vec::new();
            let mut flipped = Vec::new();
            for flip in &signs {
                track.push(q);
                flipped.push(if *flip { UnitQuaternion::new_unchecked(-q.into_inner()) } else { q });
                q *= step;
            }
            let a = filter_track(&track, order);
            let b = filter_track(&flipped, order);
            for (x, y) in a.iter().zip(&b) {
                for k in 0..3 {
                    prop_assert!((x[k] - y[k]).abs() < 1e-12);
                }
            }
        }
    }

    /// A whole track turning about Y from 0° to 390° in ZYX order: past ±180° the middle
    /// channel keeps counting (was the test of `pipeline/output.rs`, whose whole-take function
    /// had no caller).
    #[test]
    fn a_track_turning_through_180_degrees_stays_continuous() {
        let track: Vec<UnitQuaternion<f64>> = (0..40)
            .map(|f| {
                UnitQuaternion::from_axis_angle(&Vector3::y_axis(), (f as f64 * 10.0).to_radians())
            })
            .collect();
        let euler = filter_track_degrees(&track, EulerOrder::ZYX);
        for (f, angles) in euler.iter().enumerate() {
            assert!(
                (angles[1] - f as f64 * 10.0).abs() < 1e-6,
                "frame {f}: {angles:?}"
            );
        }
    }
}
