//! Offline fusion: a whole take at once, so each orientation uses the samples after it as well as
//! those before (as Xsens' "HD reprocessing" does). Built on VQF's offline idea (Laidig & Seel
//! 2023) and changed where the measurements said so:
//!
//! 1. **Gyro bias from rest.** Where the take holds rest (VQF's detector: gyro and accelerometer
//!    steady for 1.5 s; 0.4 s for the pose that opens a take; a gyro biased beyond VQF's 2 °/s
//!    found still by the readings that see turns — [`rest_segments`]), each stretch's mean gyro is
//!    the bias there, and between stretches the
//!    two nearest are carried forward and backward with an uncertainty that grows with time and
//!    merged by inverse variance ([`bias_from_rest`]). VQF's online estimate in motion leans on the
//!    accelerometer, which a body that keeps accelerating misleads (the final estimates on a
//!    simulated walk: 0.03–0.13 °/s off with it, 0.01–0.10 from rest). A take without rest gets
//!    VQF's own estimate, run forward and backward and merged by covariance ([`vqf_passes`]).
//! 2. **Strapdown.** The bias-corrected gyro is integrated, `q₃ᵢ = q₃ᵢ₋₁ ⊗ exp((ωᵢ − bᵢ) Δtᵢ)`: an
//!    almost inertial frame that only drifts by the bias left over.
//! 3. **Inclination from a long two-sided average.** The specific force is taken into that frame,
//!    `aᴵ = q₃ ⊗ a`, and low-passed forward and backward (second-order Butterworth, time constant
//!    `tau_acc`, default 10 s; VQF's online 3 s). In an inertial frame the mean of a body's
//!    acceleration over a window is its change of velocity over the window's length, so over a
//!    long symmetric window only gravity is left: a person walking a loop at 1.7 m/s has ~1.5 m/s²
//!    of centripetal acceleration for seconds, which a 3 s one-sided filter takes for ~3° of tilt.
//!    But the strapdown frame is only almost inertial: where uneven sample times leave a random
//!    walk `q` of unknown rotation ([`timing_wander`]), a window `τ` lets `q·τ/3` of it through
//!    while each change of the body's velocity leaves a tilt `V/(g·τ)` for about `τ`
//!    ([`BODY_SPEED`]); the window is the one that balances them ([`inclination_window`]) when
//!    that is shorter than `tau_acc`.
//!    Each sample is then turned so its averaged specific force points up (`q₆`).
//! 4. **Heading, smoothed.** The field's heading in that frame, `zᵢ = atan2(mᴱₓ, mᴱᵧ)`, measures
//!    the heading offset `δ` up to the magnetometer's own errors, which are small at rest and
//!    large in motion (calibration that depends on orientation, fields that are not uniform) and
//!    unbounded in a disturbance — found with hindsight: a field whose norm or dip is off the
//!    take's median by more than 10 % or 10° ([`DISTURBED_NORM`], [`DISTURBED_DIP_DEG`]) is left
//!    out, however long. `δ` drifts at a rate `β` (the bias left over about the vertical, prior
//!    variance the bias's own) plus a random walk (`drift` °/√s, and what uneven sample times
//!    leave unknown of fast turns, [`timing_unknown`]), seen through those measurements — σ =
//!    `rest_deg` at rest, `motion_deg` in motion — and `[δ, β]` is estimated by a Kalman filter
//!    forward and a Rauch–Tung–Striebel pass backward ([`smooth_heading`]): the heading leans on
//!    the field where the field is trustworthy and on the gyro between. `q₉ = R_z(δ) ⊗ q₆`.
//!
//! Measured on BROAD and on simulated bodies (docs, "Accuracy"); every step is in this file.

use crate::smooth::butterworth::{design_lowpass_sos, lane_state, sosfilt_step_lanes, sosfilt_zi};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use vqf_rs::{Params, VQF};

/// One step of the take: readings (sensor frame) and the time since the previous step.
#[derive(Debug, Clone, Copy)]
pub struct Step {
    pub gyr: Vector3<f64>,
    pub acc: Vector3<f64>,
    pub mag: Option<Vector3<f64>>,
    pub dt: f64,
}

/// The offline fusion's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OfflineParams {
    /// Time constant of the two-sided inclination average, seconds.
    pub tau_acc: f64,
    /// VQF's own accelerometer time constant in the bias passes, seconds.
    pub pass_tau_acc: f64,
    /// VQF's heading time constant in the bias passes, seconds.
    pub tau_mag: f64,
    /// The magnetometer's heading error at rest, degrees (σ).
    pub rest_deg: f64,
    /// Its heading error in motion, degrees (σ).
    pub motion_deg: f64,
    /// How fast the heading offset may wander, °/√s.
    pub drift: f64,
}

impl Default for OfflineParams {
    fn default() -> Self {
        OfflineParams {
            tau_acc: 10.0,
            pass_tau_acc: 3.0,
            tau_mag: 9.0,
            rest_deg: 2.0,
            motion_deg: 20.0,
            drift: 0.02,
        }
    }
}

/// What the offline fusion gives, one entry per step.
#[derive(Debug, Clone)]
pub struct OfflineResult {
    /// `q_enu_sensor` (9D), or with an arbitrary heading (6D).
    pub orientation: Vec<UnitQuaternion<f64>>,
    /// The merged gyro bias, rad/s.
    pub bias: Vec<Vector3<f64>>,
    pub rest: Vec<bool>,
    pub magnetic_disturbance: Vec<bool>,
    /// What the fusion expects its own error to be ([`ExpectedError`]).
    pub expected: ExpectedError,
}

/// The offline fusion's own estimate of its error, from what the take gave it — a model, not a
/// measurement: RMS over the take, degrees.
///
/// - **Tilt**: the bias left over (σ_b, the mean standard deviation of each step's bias per
///   axis: a stretch of rest's mean, `σ/√N`, carried with its wander; or VQF's covariance
///   without rest) turns the strapdown frame by `σ_b·t`, and uneven sample times add a random
///   walk `q` ([`timing_wander`]); the two-sided average of `T = min(τ, the take's
///   length)` sees both through its window: `tilt² = (σ_b·T)² + q·T/3`.
/// - **Heading** with a magnetometer: the smoother's own posterior variance, averaged over the
///   take (it grows through a disturbance and with `q`); without one, nothing corrects it after
///   the first sample: the mean of `(σ_b·t)² + q·t` over the take, `(σ_b·L)²/3 + q·L/2`.
///
/// It leaves out what it cannot see: the body's acceleration that the average does not cancel,
/// and a magnetometer's errors in motion beyond the smoother's model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExpectedError {
    pub tilt_deg: f64,
    pub heading_deg: f64,
}

impl ExpectedError {
    /// `√(tilt² + heading²)`, degrees.
    pub fn total_deg(&self) -> f64 {
        self.tilt_deg.hypot(self.heading_deg)
    }
}

/// Standard gravity, m/s².
const G: f64 = 9.80665;
/// How much a body part's velocity changes over a few seconds, m/s (a limb's swing, a step's
/// start): what a two-sided average of the specific force over `τ` leaves of it is `V/τ`, a
/// tilt of `V/(g·τ)`.
const BODY_SPEED: f64 = 1.0;

/// A VQF for the bias passes.
fn vqf(params: &OfflineParams, ts: f64) -> VQF {
    let p = Params {
        tau_acc: params.pass_tau_acc,
        tau_mag: params.tau_mag,
        ..Params::default()
    };
    VQF::new(ts, None, None, Some(p))
}

/// Rest as VQF detects it (its thresholds): the gyro and the accelerometer within 2 °/s and
/// 0.5 m/s² of their own low-passed values (first order, τ = 0.5 s), the low-passed gyro under
/// 2 °/s on every axis, for at least 1.5 s — or [`OPENING_S`] for the take's first stretch: a
/// pose held before the motion, however briefly, is the take's best look at the bias and at
/// gravity (VQF's 1.5 s found none in a 0.5–1.5 s pose, and the bias then came from VQF's passes
/// in motion: 3.8° of error since the pose on a 5 s take with a 2 °/s bias, 0.56° with it; see
/// `scripts/fusion_matrix.py`). The stretches of rest, as step ranges.
///
/// VQF's last test also refuses a still sensor whose gyro is biased by more than 2 °/s (a
/// cheap gyro's bias reaches that), and then no rest is found and no bias learned from it. So a
/// stretch steady but turning at up to [`BIASED_REST_DPS`] is rest too when the turn is not
/// real: the specific force and, with a magnetometer, the field keep their directions in the
/// sensor's frame over it (within [`REST_TURN_DEG`] between its first and its last
/// [`REST_ENDS_S`]) where the gyro says it turned at least twice as far. Without a magnetometer
/// a turn about the vertical cannot be told from bias: the gyro's part about it must pass VQF's
/// test.
pub fn rest_segments(steps: &[Step]) -> Vec<std::ops::Range<usize>> {
    let vqf = steady_stretches(steps, 2.0);
    let mut segments: Vec<std::ops::Range<usize>> = Vec::with_capacity(vqf.len());
    // A stretch steady at a biased gyro's rate, whose turn nothing else sees, replaces the VQF
    // rest inside it; one whose turn is real leaves that rest as VQF found it.
    let biased: Vec<_> = steady_stretches(steps, BIASED_REST_DPS)
        .into_iter()
        .filter(|r| turn_is_bias(&steps[r.clone()]))
        .collect();
    for r in vqf {
        if !biased.iter().any(|b| b.start <= r.start && r.end <= b.end) {
            segments.push(r);
        }
    }
    segments.extend(biased);
    segments.sort_by_key(|r| r.start);
    segments
}

/// The stretches in which the gyro and the accelerometer are within 2 °/s and 0.5 m/s² of their
/// own low-passed values (first order, τ = 0.5 s) and the low-passed gyro under `gyro_dps` on
/// every axis, at least 1.5 s long ([`OPENING_S`] for the take's first).
fn steady_stretches(steps: &[Step], gyro_dps: f64) -> Vec<std::ops::Range<usize>> {
    const TAU_S: f64 = 0.5;
    const MIN_S: f64 = 1.5;
    let (gyr_th, acc_th) = (2f64.to_radians(), 0.5);
    let lp_th = gyro_dps.to_radians();
    let Some(first) = steps.first() else {
        return Vec::new();
    };
    let (mut gyr_lp, mut acc_lp) = (first.gyr, first.acc);
    let mut segments = Vec::new();
    let (mut start, mut still_s) = (0, 0.0);
    let mut close = |range: std::ops::Range<usize>, still_s: f64| {
        if still_s >= MIN_S || (range.start == 0 && still_s >= OPENING_S) {
            segments.push(range);
        }
    };
    for (i, s) in steps.iter().enumerate() {
        let alpha = s.dt / (TAU_S + s.dt);
        gyr_lp += (s.gyr - gyr_lp) * alpha;
        acc_lp += (s.acc - acc_lp) * alpha;
        let still = (s.gyr - gyr_lp).norm() < gyr_th
            && (s.acc - acc_lp).norm() < acc_th
            && gyr_lp.amax() < lp_th;
        if still {
            if still_s == 0.0 {
                start = i;
            }
            still_s += s.dt;
        } else {
            close(start..i, still_s);
            still_s = 0.0;
        }
    }
    close(start..steps.len(), still_s);
    segments
}

/// A take that opens still for this long opens at rest (the pose held before a take, which
/// animators keep short), s: its mean gyro is the bias, its specific force gravity.
pub const OPENING_S: f64 = 0.4;
/// The fastest steady turn that may still be a biased gyro at rest, °/s: a consumer MEMS gyro's
/// zero-rate offset is specified up to ±20 °/s (InvenSense MPU-6050; ±10 °/s for ST's
/// LSM6DS3), and a simulated bias of 2 °/s SD per axis passes 6 °/s on one sensor in eight of a
/// 16-sensor suit — which VQF's bias estimate, clipped at 2 °/s, cannot follow (24° on that
/// shank since the pose).
pub const BIASED_REST_DPS: f64 = 20.0;
/// The most the specific force (and the field) may turn over such a stretch, degrees …
pub const REST_TURN_DEG: f64 = 0.5;
/// … between the means over its first and its last this long, s.
pub const REST_ENDS_S: f64 = 0.3;

/// Whether a steady stretch's turn, as its gyro tells it, is the gyro's bias: the readings that
/// see the turn — the specific force, the field if there is one — keep their directions while
/// the mean gyro integrates to at least twice [`REST_TURN_DEG`] over the stretch.
fn turn_is_bias(stretch: &[Step]) -> bool {
    let Some(last) = stretch.len().checked_sub(1) else {
        return false;
    };
    let duration: f64 = stretch[1..].iter().map(|s| s.dt).sum();
    let mean_gyr = stretch.iter().map(|s| s.gyr).sum::<Vector3<f64>>() / stretch.len() as f64;
    let turn = REST_TURN_DEG.to_radians();
    if mean_gyr.norm() * duration < 2.0 * turn {
        return false;
    }
    let ends = stretch
        .iter()
        .scan(0.0, |t, s| {
            *t += s.dt;
            Some(*t)
        })
        .take_while(|&t| t <= REST_ENDS_S)
        .count()
        .clamp(1, stretch.len() / 2 + 1);
    let mean = |range: std::ops::Range<usize>, f: &dyn Fn(&Step) -> Option<Vector3<f64>>| {
        let values: Option<Vec<Vector3<f64>>> = stretch[range].iter().map(f).collect();
        values.map(|v| v.iter().sum::<Vector3<f64>>() / v.len() as f64)
    };
    let kept = |f: &dyn Fn(&Step) -> Option<Vector3<f64>>| match (
        mean(0..ends, f),
        mean(last + 1 - ends..last + 1, f),
    ) {
        (Some(a), Some(b)) => a.angle(&b) < turn,
        _ => false,
    };
    // Without a field, nothing sees a turn about the vertical: the gyro's part about it must pass
    // VQF's own test.
    let about_vertical = || {
        let up = stretch.iter().map(|s| s.acc).sum::<Vector3<f64>>();
        up.try_normalize(1e-9)
            .is_some_and(|up| mean_gyr.dot(&up).abs() < 2f64.to_radians())
    };
    let field = stretch.iter().all(|s| s.mag.is_some());
    kept(&|s| Some(s.acc))
        && if field {
            kept(&|s| s.mag)
        } else {
            about_vertical()
        }
}

/// How fast the bias may wander away from what rest showed: its uncertainty grows to 0.05 °/s
/// in 100 s (VQF's bias forgetting time), as a variance per second, (rad/s)²/s.
const BIAS_WANDER: f64 =
    0.05 * 0.05 * (std::f64::consts::PI / 180.0) * (std::f64::consts::PI / 180.0) / 100.0;
/// The smallest uncertainty of a stretch's mean gyro, rad/s.
const BIAS_FLOOR: f64 = 0.005 * std::f64::consts::PI / 180.0;

/// The gyro bias at every step from the stretches of rest: each stretch's mean gyro (its variance
/// that of a mean, at least [`BIAS_FLOOR`]²), carried forward and backward with a variance that
/// grows by [`BIAS_WANDER`] per second, the two merged by their inverse variances; inside a
/// stretch, its mean.
pub fn bias_from_rest(steps: &[Step], segments: &[std::ops::Range<usize>]) -> Vec<Vector3<f64>> {
    bias_and_variance_from_rest(steps, segments).0
}

/// [`bias_from_rest`] and the variance of each step's bias per axis, (rad/s)²: a stretch's, or
/// the merged `(1/v₁ + 1/v₂)⁻¹` between two.
fn bias_and_variance_from_rest(
    steps: &[Step],
    segments: &[std::ops::Range<usize>],
) -> (Vec<Vector3<f64>>, Vec<f64>) {
    let n = steps.len();
    let mut time = Vec::with_capacity(n);
    let mut t = 0.0;
    for s in steps {
        t += s.dt;
        time.push(t);
    }
    let stats: Vec<(Vector3<f64>, f64)> = segments
        .iter()
        .map(|r| {
            let count = r.len() as f64;
            let mean = steps[r.clone()].iter().map(|s| s.gyr).sum::<Vector3<f64>>() / count;
            let var = steps[r.clone()]
                .iter()
                .map(|s| (s.gyr - mean).norm_squared() / 3.0)
                .sum::<f64>()
                / count.max(2.0);
            (mean, (var / count).max(BIAS_FLOOR * BIAS_FLOOR))
        })
        .collect();
    let mut bias = vec![Vector3::zeros(); n];
    let mut variance = vec![0.0; n];
    let mut next = 0; // the first segment that ends after step i
    for i in 0..n {
        while next < segments.len() && segments[next].end <= i {
            next += 1;
        }
        if next < segments.len() && segments[next].contains(&i) {
            (bias[i], variance[i]) = stats[next];
            continue;
        }
        let before = next.checked_sub(1).map(|k| {
            let end = time[segments[k].end - 1];
            (stats[k].0, stats[k].1 + BIAS_WANDER * (time[i] - end))
        });
        let after = (next < segments.len()).then(|| {
            let start = time[segments[next].start];
            (
                stats[next].0,
                stats[next].1 + BIAS_WANDER * (start - time[i]),
            )
        });
        (bias[i], variance[i]) = match (before, after) {
            (Some((b1, v1)), Some((b2, v2))) => (
                (b1 / v1 + b2 / v2) / (1.0 / v1 + 1.0 / v2),
                1.0 / (1.0 / v1 + 1.0 / v2),
            ),
            (Some((b, v)), None) | (None, Some((b, v))) => (b, v),
            (None, None) => (Vector3::zeros(), 0.0),
        };
    }
    (bias, variance)
}

fn matrix(m: &vqf_rs::Matrix<3, 3>) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| m.0[r][c])
}

/// The bias for a take without rest: VQF forward and backward (time reversed, gyro negated), its
/// estimates at rest and in motion merged at each step by their covariances,
/// `b = (P₁⁻¹ + P₂⁻¹)⁻¹ (P₁⁻¹ b₁ − P₂⁻¹ b₂)` (the backward pass sees `−b`), computed with one
/// inverse as `b = P₂ S⁻¹ b₁ − P₁ S⁻¹ b₂`, `S = P₁ + P₂` (`(P₁⁻¹ + P₂⁻¹)⁻¹ = P₂ S⁻¹ P₁ = P₁ S⁻¹ P₂`);
/// rest where either pass found it. The passes leave the magnetometer out (the bias comes from
/// the gyro and the accelerometer), and run on blocks of steps averaged down to about 25 Hz
/// ([`PASS_PERIOD_S`]): the bias changes over minutes, and the passes are most of the offline
/// fusion's cost.
fn vqf_passes(
    steps: &[Step],
    ts: f64,
    params: &OfflineParams,
) -> (Vec<Vector3<f64>>, Vec<f64>, Vec<bool>) {
    let k = ((PASS_PERIOD_S / ts).round() as usize).max(1);
    // A block's mean readings and its length (the blocks are read twice, not stored).
    let block = |c: &[Step]| {
        let m = c.len() as f64;
        let gyr = c.iter().map(|s| s.gyr).sum::<Vector3<f64>>() / m;
        let acc = c.iter().map(|s| s.acc).sum::<Vector3<f64>>() / m;
        (gyr, acc, c.iter().map(|s| s.dt).sum::<f64>())
    };
    let n = steps.len().div_ceil(k);
    let ts = ts * k as f64;
    let arr = |v: &Vector3<f64>| [v.x, v.y, v.z];
    let mut filter = vqf(params, ts);
    let mut forward = Vec::with_capacity(n);
    let mut rest = Vec::with_capacity(n);
    for c in steps.chunks(k) {
        let (gyr, acc, dt) = block(c);
        filter.update_gyr_with_ts(arr(&gyr), dt);
        filter.update_acc(arr(&acc));
        forward.push((
            matrix(&filter.state().bias_p),
            Vector3::from(filter.state().bias),
        ));
        rest.push(filter.rest_detected());
    }
    let mut filter = vqf(params, ts);
    let mut bias = vec![Vector3::zeros(); n];
    let mut variance = vec![0.0; n];
    // VQF keeps its bias covariance in (0.01 °/s)².
    let p_unit = (0.01f64).to_radians().powi(2);
    // Backward, the step from block i + 1 to block i spans the later block's interval.
    let mut later_dt = None;
    for (i, c) in steps.chunks(k).enumerate().rev() {
        let (gyr, acc, dt) = block(c);
        filter.update_gyr_with_ts(arr(&-gyr), later_dt.unwrap_or(dt));
        later_dt = Some(dt);
        filter.update_acc(arr(&acc));
        let (p1, b1) = forward[i];
        let p2 = matrix(&filter.state().bias_p);
        let b2 = Vector3::from(filter.state().bias);
        if let Some(s_inv) = (p1 + p2).try_inverse() {
            bias[i] = p2 * (s_inv * b1) - p1 * (s_inv * b2);
            variance[i] = (p1 * s_inv * p2).trace() / 3.0 * p_unit;
        }
        rest[i] |= filter.rest_detected();
    }
    // Back to one value per step.
    let per_step = |v: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
        v.iter()
            .flat_map(|b| std::iter::repeat_n(*b, k))
            .take(steps.len())
            .collect()
    };
    let rest = rest
        .iter()
        .flat_map(|r| std::iter::repeat_n(*r, k))
        .take(steps.len())
        .collect();
    let variance = variance
        .iter()
        .flat_map(|v| std::iter::repeat_n(*v, k))
        .take(steps.len())
        .collect();
    (per_step(&bias), variance, rest)
}

/// The bias passes' sampling period, seconds (about 25 Hz). Measured with the passes forced on
/// BROAD's three trials (their rest set aside) and on a simulated walk without rest: 25 Hz and
/// 50 Hz agree within 0.003° of RMS error, 10 Hz loses 0.005–0.04°; on the x-io lower-body take
/// (50 Hz, forced too) 25 Hz keeps pelvis, thighs and shanks within 0.002° of what the take's
/// rest gives (the feet within 0.3–0.65°, as at 50 Hz), where passes at the full 50 Hz put one
/// shank 6.6° off.
const PASS_PERIOD_S: f64 = 0.04;

/// Fuses `steps` (sampled every `ts` seconds nominally) offline; `nine_d` uses the magnetometer.
pub fn fuse_offline(
    steps: &[Step],
    ts: f64,
    nine_d: bool,
    params: &OfflineParams,
) -> OfflineResult {
    let n = steps.len();
    // 1. The gyro bias: from the stretches of rest where there are some; else from VQF's passes.
    let segments = rest_segments(steps);
    let (bias, bias_variance, rest) = if segments.is_empty() {
        vqf_passes(steps, ts, params)
    } else {
        let mut rest = vec![false; n];
        for r in &segments {
            rest[r.clone()].fill(true);
        }
        let (bias, variance) = bias_and_variance_from_rest(steps, &segments);
        (bias, variance, rest)
    };

    let duration: f64 = steps.iter().skip(1).map(|s| s.dt).sum();
    let wander = timing_wander(steps, duration, ts);
    let bias_var = bias_variance.iter().sum::<f64>() / n.max(1) as f64;
    let tau_acc = inclination_window(params.tau_acc, wander, duration);
    let window = tau_acc.min(duration);
    let tilt_var = bias_var * window * window + wander * window / 3.0;

    // 2. Strapdown integration.
    let mut q3 = Vec::with_capacity(n);
    let mut q = UnitQuaternion::identity();
    for (s, b) in steps.iter().zip(&bias) {
        q *= UnitQuaternion::from_scaled_axis((s.gyr - b) * s.dt);
        q3.push(q);
    }

    // 3. Inclination: the specific force in that frame, averaged both ways.
    let acc_inertial: Vec<Vector3<f64>> = q3.iter().zip(steps).map(|(q, s)| q * s.acc).collect();
    // A take that starts (ends) at rest starts (ends) the average at gravity as rest showed it.
    let rest_mean = |r: &std::ops::Range<usize>| {
        acc_inertial[r.clone()].iter().sum::<Vector3<f64>>() / r.len() as f64
    };
    let at_start = segments.first().filter(|r| r.start == 0).map(rest_mean);
    let at_end = segments.last().filter(|r| r.end == n).map(rest_mean);
    let mut averaged = acc_inertial;
    lowpass_both_ways(&mut averaged, tau_acc, ts, at_start, at_end);
    let mut correction = UnitQuaternion::identity();
    // q₆ in place of q₃; in 9D, each field in that frame measured beside it (the correction is
    // one long chain of dependent steps, which leaves the core room for the field's own work).
    let mut fields: Vec<Option<Field>> = Vec::with_capacity(if nine_d { n } else { 0 });
    let mut q6 = q3;
    for ((q, a), s) in q6.iter_mut().zip(&averaged).zip(steps) {
        *q = {
            let up = (correction * a)
                .try_normalize(1e-12)
                .unwrap_or_else(Vector3::z);
            // The smallest turn taking `up` to +z.
            let w = ((up.z + 1.0) / 2.0).max(0.0).sqrt();
            let step = if w > 1e-6 {
                UnitQuaternion::new_normalize(Quaternion::new(
                    w,
                    0.5 * up.y / w,
                    -0.5 * up.x / w,
                    0.0,
                ))
            } else {
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
            };
            correction = step * correction;
            correction * *q
        };
        if nine_d {
            fields.push(s.mag.and_then(|m| Field::of(*q * m)));
        }
    }
    drop(averaged);
    if !nine_d {
        let heading_var = bias_var * duration * duration / 3.0 + wander * duration / 2.0;
        return OfflineResult {
            orientation: q6,
            bias,
            rest,
            magnetic_disturbance: vec![false; n],
            expected: ExpectedError {
                tilt_deg: tilt_var.sqrt().to_degrees(),
                heading_deg: heading_var.sqrt().to_degrees(),
            },
        };
    }

    // 4. Heading offset, filtered forward and smoothed backward, from the samples whose field
    // is the take's own (disturbances found with hindsight).
    let disturbed = disturbances(&fields);
    let (rest_var, motion_var) = (
        params.rest_deg.to_radians().powi(2),
        params.motion_deg.to_radians().powi(2),
    );
    let measurement = |i: usize| {
        let f = fields[i].as_ref().filter(|_| !disturbed[i])?;
        Some((f.heading, if rest[i] { rest_var } else { motion_var }))
    };
    let drift = params.drift.to_radians().powi(2);
    // The bias left over turns the heading at a rate: its vertical part, one axis's variance.
    let (delta, delta_var) = smooth_heading(steps, ts, measurement, drift, bias_var);
    let heading_var = delta_var.iter().sum::<f64>() / n.max(1) as f64;
    drop(fields);
    // q₉ in place of q₆.
    let mut orientation = q6;
    for (q, d) in orientation.iter_mut().zip(&delta) {
        *q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), *d) * *q;
    }
    OfflineResult {
        orientation,
        bias,
        rest,
        magnetic_disturbance: disturbed,
        expected: ExpectedError {
            tilt_deg: tilt_var.sqrt().to_degrees(),
            heading_deg: heading_var.sqrt().to_degrees(),
        },
    }
}

/// The field in the inclination-corrected frame, as the heading step uses it.
struct Field {
    /// `atan2(mₓ, m_y)`: the field's heading, radians.
    heading: f64,
    norm: f64,
    /// `asin(m_z / |m|)`, radians.
    dip: f64,
}

impl Field {
    /// `None` for a field with no horizontal part (no heading).
    fn of(m: Vector3<f64>) -> Option<Field> {
        (m.x != 0.0 || m.y != 0.0).then(|| {
            let norm = m.norm();
            Field {
                heading: m.x.atan2(m.y),
                norm,
                dip: (m.z / norm).asin(),
            }
        })
    }
}

/// The relative change of the field's norm, and the change of its dip, beyond which a sample's
/// field is not the take's own (VQF's thresholds for the same test).
pub const DISTURBED_NORM: f64 = 0.1;
pub const DISTURBED_DIP_DEG: f64 = 10.0;

/// The samples whose field (inclination-corrected frame) is not the take's own: norm or dip off
/// the take's median by more than [`DISTURBED_NORM`] or [`DISTURBED_DIP_DEG`]. Seen over the
/// whole take, a disturbance is bounded from both ends, and no reference has to be accepted
/// first (VQF online holds every field for disturbed until it has turned for about 5 s).
fn disturbances(fields: &[Option<Field>]) -> Vec<bool> {
    let norms: Vec<f64> = fields.iter().flatten().map(|f| f.norm).collect();
    if norms.is_empty() {
        return vec![false; fields.len()];
    }
    let norm = super::median(norms);
    let dip = super::median(fields.iter().flatten().map(|f| f.dip).collect());
    fields
        .iter()
        .map(|f| {
            f.as_ref().is_some_and(|f| {
                (f.norm - norm).abs() > DISTURBED_NORM * norm
                    || (f.dip - dip).abs() > DISTURBED_DIP_DEG.to_radians()
            })
        })
        .collect()
}

/// Each component low-passed forward and backward (second-order Butterworth with VQF's relation
/// between time constant and cutoff, `f_c = √2 / (2π τ)`). A slow filter's start matters for
/// seconds: each pass starts in the steady state of `start` / `end` when the take begins / ends at
/// rest (the mean specific force over that stretch: gravity), else of the mean of its first `τ`
/// seconds — never of one sample, which in motion is anything (VQF's offline filter averages its
/// first samples too). A take too short for the filter is averaged whole.
fn lowpass_both_ways(
    x: &mut [Vector3<f64>],
    tau: f64,
    ts: f64,
    start: Option<Vector3<f64>>,
    end: Option<Vector3<f64>>,
) {
    let fs = 1.0 / ts;
    let cutoff = std::f64::consts::SQRT_2 / (2.0 * std::f64::consts::PI * tau);
    let sos = design_lowpass_sos(2, cutoff.min(0.45 * fs), fs).ok();
    let zi = sos.as_ref().and_then(|sos| sosfilt_zi(sos).ok());
    let (Some(sos), Some(zi)) = (sos, zi) else {
        let mean = x.iter().sum::<Vector3<f64>>() / x.len().max(1) as f64;
        x.fill(mean);
        return;
    };
    let n = x.len();
    let window = ((tau / ts).round() as usize).clamp(1, n.max(1));
    // In place, the three axes side by side (the same arithmetic per axis as one at a time,
    // faster: three independent recurrences): the take's arrays are large, and fresh ones cost
    // page faults.
    let mean = |range: std::ops::Range<usize>, x: &[Vector3<f64>]| -> [f64; 3] {
        std::array::from_fn(|k| {
            x[range.clone()].iter().map(|v| v[k]).sum::<f64>() / range.len() as f64
        })
    };
    let first = start.map_or_else(|| mean(0..window, x), |v| v.into());
    let mut state = lane_state(&zi, first);
    for v in x.iter_mut() {
        *v = sosfilt_step_lanes(&sos, (*v).into(), &mut state).into();
    }
    let last = end.map_or_else(|| mean(n - window..n, x), |v| v.into());
    let mut state = lane_state(&zi, last);
    for v in x.iter_mut().rev() {
        *v = sosfilt_step_lanes(&sos, (*v).into(), &mut state).into();
    }
}

/// The angle `a` wrapped into (−π, π].
fn wrap(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let shifted = a + PI;
    // `rem_euclid` is `fmod` (a software loop here) plus a turn when negative; within a turn of
    // zero `fmod` returns its argument exactly, so that case needs no call (same bits).
    let turned = if shifted.abs() < TAU {
        if shifted < 0.0 {
            shifted + TAU
        } else {
            shifted
        }
    } else {
        shifted.rem_euclid(TAU)
    };
    let w = turned - PI;
    if w == -std::f64::consts::PI {
        std::f64::consts::PI
    } else {
        w
    }
}

/// The inclination average's time constant, seconds: `tau_acc` (the longest), shortened where
/// the strapdown frame wanders (`wander`, rad²/s, [`timing_wander`]) to the window that balances
/// the wander it lets through against the body's acceleration it leaves.
///
/// A window `τ` lets `q·τ/3` rad² of the wander through (the mean square of a random walk's
/// departure from its own centred mean). A velocity change `V` ([`BODY_SPEED`]) leaves a tilt of
/// `V/(g·τ)` for about `τ` seconds; the take has at least one (the move out of the opening pose)
/// and one per `tau_acc` in a longer take, so over `L = min(duration, tau_acc)` its mean square
/// is `(V/(g·τ))² · τ/L` for `τ < L`. The sum is least at `τ = (V/g)·√(3/(q·L))`; where that is
/// not under `L` the change covers the whole window, `(V/(g·τ))² + q·τ/3`, least at
/// `τ = ∛(6 (V/g)²/q)`.
fn inclination_window(tau_acc: f64, wander: f64, duration: f64) -> f64 {
    if wander <= 0.0 {
        return tau_acc;
    }
    let v = BODY_SPEED / G;
    let between_changes = duration.min(tau_acc);
    let within = v * (3.0 / (wander * between_changes)).sqrt();
    let tau = if within < between_changes {
        within
    } else {
        (6.0 * v * v / wander).cbrt()
    };
    tau.min(tau_acc)
}

/// What the samples' timing leaves unknown of the rotation into `step` from `prev`, rad²: a gyro
/// reads its rate over its own sampling period `T` before each sample, so where the samples'
/// spacing `Δt` differs from it the rotation between them is partly unknown — about
/// `|ωᵢ − ωᵢ₋₁| · |Δt − T|` (the rate across the gap or overlap lies anywhere between its
/// neighbours', and a late sample lengthens one interval and shortens the next, so the two
/// steps' unknowns add). On noise-free simulated readings with 1 ms of jitter, strapdown alone
/// drifted 2.3–3.9° in 20 s of CMU 01_01 where this predicts 2.7–4.8° (half of it, 1.3–2.4°,
/// with the rate's change halved). Zero for evenly spaced samples.
fn timing_unknown(prev: &Step, step: &Step, ts: f64) -> f64 {
    let off = step.dt - ts;
    // (Most takes are evenly spaced: no need to look at the rates.)
    if off == 0.0 {
        return 0.0;
    }
    (step.gyr - prev.gyr).norm_squared() * off * off
}

/// The take's [`timing_unknown`] steps as the rate of a random walk, rad²/s: their sum over the
/// take's length (`duration`, seconds).
fn timing_wander(steps: &[Step], duration: f64, ts: f64) -> f64 {
    if duration <= 0.0 {
        return 0.0;
    }
    steps
        .windows(2)
        .map(|w| timing_unknown(&w[0], &w[1], ts))
        .sum::<f64>()
        / duration
}

/// A symmetric 2 × 2 covariance `[[a, c], [c, e]]` of `[δ, β]`.
#[derive(Debug, Clone, Copy)]
struct Cov2 {
    a: f64,
    c: f64,
    e: f64,
}

impl Cov2 {
    /// `F P Fᵀ` for `F = [[1, Δt], [0, 1]]`.
    fn predicted(self, dt: f64) -> Cov2 {
        Cov2 {
            a: self.a + dt * (2.0 * self.c + dt * self.e),
            c: self.c + dt * self.e,
            e: self.e,
        }
    }

    /// The RTS gain `C = P Fᵀ (P⁻)⁻¹` into a step `dt` later whose predicted covariance is
    /// `next`; where the rate is known exactly (`rate_var` = 0: its row and column stay 0) the
    /// pseudo-inverse, `1/P⁻₁₁` — the scalar walk's gain; 0 where nothing is uncertain.
    fn gain(self, dt: f64, next: Cov2) -> [[f64; 2]; 2] {
        // P Fᵀ = [[a + c Δt, c], [c + e Δt, e]].
        let pf = [
            [self.a + self.c * dt, self.c],
            [self.c + self.e * dt, self.e],
        ];
        let det = next.a * next.e - next.c * next.c;
        let inv = if next.e > 0.0 && det > 0.0 {
            [[next.e / det, -next.c / det], [-next.c / det, next.a / det]]
        } else if next.a > 0.0 {
            [[1.0 / next.a, 0.0], [0.0, 0.0]]
        } else {
            [[0.0; 2]; 2]
        };
        std::array::from_fn(|r| {
            std::array::from_fn(|k| pf[r][0] * inv[0][k] + pf[r][1] * inv[1][k])
        })
    }
}

/// The heading offset `δ` over the steps, seen through angle measurements with variances
/// (`measurement(i)`: step i's, if it has one), estimated with the rate `β` it drifts at by what
/// is left of the gyro bias about the vertical: `δᵢ = δᵢ₋₁ + β·Δtᵢ + wᵢ`, `β` constant with prior
/// `N(0, rate_var)` (rad/s)² and `w` a random walk (`drift · Δt` and each step's
/// [`timing_unknown`], `ts` the sampling period). A Kalman filter forward on `x = [δ, β]`
/// (`F = [[1, Δt], [0, 1]]`, innovations wrapped), a Rauch–Tung–Striebel pass backward,
/// `xₛ,ᵢ = xᵢ + Cᵢ (xₛ,ᵢ₊₁ − F xᵢ)`, `Pₛ,ᵢ = Pᵢ + Cᵢ (Pₛ,ᵢ₊₁ − P⁻ᵢ₊₁) Cᵢᵀ`, `Cᵢ = Pᵢ Fᵀ (P⁻ᵢ₊₁)⁻¹`.
/// With `rate_var` = 0 it is the scalar walk. A rate matters where the bias came from motion:
/// a take without rest leaves ~0.3 °/s, 6° in 20 s, which the field at 20° per sample in motion
/// pins down over the take where a walk of 0.02 °/√s would not follow it. Before the first
/// measurement the estimate is its value; without any, 0. Returns the smoothed `δ` and its
/// variance (without measurements, 0).
fn smooth_heading(
    steps: &[Step],
    ts: f64,
    measurement: impl Fn(usize) -> Option<(f64, f64)>,
    drift: f64,
    rate_var: f64,
) -> (Vec<f64>, Vec<f64>) {
    let n = steps.len();
    let Some(first) = (0..n).find_map(&measurement) else {
        return (vec![0.0; n], vec![0.0; n]);
    };
    let (mut delta, mut rate) = (first.0, 0.0);
    let mut p = Cov2 {
        a: first.1,
        c: 0.0,
        e: rate_var,
    };
    // Per step: the filtered state and covariance, and the covariance predicted into it.
    let mut filtered = Vec::with_capacity(n);
    let mut predicted = Vec::with_capacity(n);
    for (i, step) in steps.iter().enumerate() {
        if i > 0 {
            delta = wrap(delta + rate * step.dt);
            p = p.predicted(step.dt);
            p.a += drift * step.dt + timing_unknown(&steps[i - 1], step, ts);
        }
        predicted.push(p);
        if let Some((z, r)) = measurement(i) {
            // K = P Hᵀ / (H P Hᵀ + r), H = [1, 0]; P ← P − K H P.
            let (k1, k2) = (p.a / (p.a + r), p.c / (p.a + r));
            let innovation = wrap(z - delta);
            delta = wrap(delta + k1 * innovation);
            rate += k2 * innovation;
            p = Cov2 {
                a: p.a - k1 * p.a,
                c: p.c - k1 * p.c,
                e: p.e - k2 * p.c,
            };
        }
        filtered.push(([delta, rate], p));
    }
    let mut smoothed = vec![0.0; n];
    let mut variance = vec![0.0; n];
    let ([mut ds, mut bs], mut ps) = filtered[n - 1];
    (smoothed[n - 1], variance[n - 1]) = (ds, ps.a);
    for i in (0..n - 1).rev() {
        let ([d, b], pf) = filtered[i];
        let dt = steps[i + 1].dt;
        let next = predicted[i + 1];
        let g = pf.gain(dt, next);
        // xₛ = x + C (xₛ₊₁ − F x), Pₛ = P + C (Pₛ₊₁ − P⁻₊₁) Cᵀ.
        let ahead = [wrap(ds - (d + b * dt)), bs - b];
        ds = wrap(d + g[0][0] * ahead[0] + g[0][1] * ahead[1]);
        bs = b + g[1][0] * ahead[0] + g[1][1] * ahead[1];
        let m = [
            [ps.a - next.a, ps.c - next.c],
            [ps.c - next.c, ps.e - next.e],
        ];
        let gm = |r: usize, k: usize| g[r][0] * m[0][k] + g[r][1] * m[1][k];
        let gmg = |r: usize, k: usize| gm(r, 0) * g[k][0] + gm(r, 1) * g[k][1];
        ps = Cov2 {
            a: pf.a + gmg(0, 0),
            c: pf.c + gmg(0, 1),
            e: pf.e + gmg(1, 1),
        };
        (smoothed[i], variance[i]) = (ds, ps.a);
    }
    (smoothed, variance)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_is_the_remainder_formula_to_the_bit() {
        use std::f64::consts::{PI, TAU};
        let reference = |a: f64| {
            let w = (a + PI).rem_euclid(TAU) - PI;
            if w == -PI { PI } else { w }
        };
        let mut x = 0.377_777_f64;
        let mut values = vec![
            0.0,
            -0.0,
            PI,
            -PI,
            TAU,
            -TAU,
            3.0 * PI,
            -3.0 * PI,
            1e300,
            f64::NAN,
        ];
        for i in 0..100_000 {
            x = (x * 3.987_654_321 + 0.271_828).fract();
            values.push((2.0 * x - 1.0) * [0.5, 4.0, 7.0, 12.0, 1e4][i % 5]);
        }
        for a in values {
            assert_eq!(wrap(a).to_bits(), reference(a).to_bits(), "{a}");
        }
    }

    #[test]
    fn lowpass_lanes_are_each_axis_alone_to_the_bit() {
        // The per-axis passes (the filter's definition) against the three axes side by side.
        let (tau, ts) = (2.0, 0.01);
        let x: Vec<Vector3<f64>> = (0..3000)
            .map(|i| {
                let t = i as f64 * ts;
                Vector3::new(
                    (3.1 * t).sin(),
                    9.81 + (0.7 * t).cos(),
                    ((i * 7919) % 101) as f64 * 0.01,
                )
            })
            .collect();
        for (start, end) in [
            (None, None),
            (
                Some(Vector3::new(0.1, 9.8, -0.2)),
                Some(Vector3::z() * 9.81),
            ),
        ] {
            let mut lanes = x.clone();
            lowpass_both_ways(&mut lanes, tau, ts, start, end);
            let fs = 1.0 / ts;
            let cutoff = std::f64::consts::SQRT_2 / (2.0 * std::f64::consts::PI * tau);
            let sos = design_lowpass_sos(2, cutoff.min(0.45 * fs), fs).unwrap();
            let zi = sosfilt_zi(&sos).unwrap();
            let (n, window) = (x.len(), (tau / ts).round() as usize);
            let mut axes = x.clone();
            for k in 0..3 {
                let mean = |r: std::ops::Range<usize>, x: &[Vector3<f64>]| {
                    x[r.clone()].iter().map(|v| v[k]).sum::<f64>() / r.len() as f64
                };
                let first = start.map_or_else(|| mean(0..window, &axes), |v| v[k]);
                let mut state: Vec<[f64; 2]> =
                    zi.iter().map(|z| [z[0] * first, z[1] * first]).collect();
                for v in axes.iter_mut() {
                    v[k] = crate::smooth::butterworth::sosfilt_step(&sos, v[k], &mut state);
                }
                let last = end.map_or_else(|| mean(n - window..n, &axes), |v| v[k]);
                let mut state: Vec<[f64; 2]> =
                    zi.iter().map(|z| [z[0] * last, z[1] * last]).collect();
                for v in axes.iter_mut().rev() {
                    v[k] = crate::smooth::butterworth::sosfilt_step(&sos, v[k], &mut state);
                }
            }
            for (a, b) in lanes.iter().zip(&axes) {
                for k in 0..3 {
                    assert_eq!(a[k].to_bits(), b[k].to_bits());
                }
            }
        }
    }

    /// `n` steps of a still sensor without a field, 100 Hz.
    fn still_steps(n: usize) -> Vec<Step> {
        vec![
            Step {
                gyr: Vector3::zeros(),
                acc: Vector3::z(),
                mag: None,
                dt: 0.01
            };
            n
        ]
    }

    #[test]
    fn the_smoother_follows_the_trustworthy_measurements() {
        // δ is 0.3 rad throughout; the measurements are exact at rest (first and last 100
        // steps) and off by ±0.5 rad in motion: the smoothed heading stays near 0.3.
        let steps = still_steps(1000);
        let m: Vec<Option<(f64, f64)>> = (0..1000)
            .map(|i| {
                if !(100..900).contains(&i) {
                    Some((0.3, 2f64.to_radians().powi(2)))
                } else {
                    let off = if i % 2 == 0 { 0.5 } else { -0.5 };
                    Some((0.3 + off, 20f64.to_radians().powi(2)))
                }
            })
            .collect();
        let (d, _) = smooth_heading(&steps, 0.01, |i| m[i], 0.02f64.to_radians().powi(2), 0.0);
        assert!(
            d.iter().all(|x| (x - 0.3).abs() < 0.01),
            "{:?}",
            &d[495..505]
        );
        // Angles wrap: measurements either side of ±π give a heading near π.
        let m: Vec<Option<(f64, f64)>> = (0..1000)
            .map(|i| Some((if i % 2 == 0 { 3.1 } else { -3.1 }, 0.01)))
            .collect();
        let (d, _) = smooth_heading(&steps, 0.01, |i| m[i], 1e-6, 0.0);
        assert!(d.iter().all(|x| x.abs() > 3.0), "{:?}", &d[..4]);
    }

    /// A heading drifting at 0.5 °/s for 20 s (what a bias left over by 0.5 °/s about the
    /// vertical does), seen at 100 Hz through a field 20° off either way in turn (σ in motion).
    /// As a walk of 0.02 °/√s alone the smoother holds nearly one value, and a flat line misses
    /// a ramp of 10° by `10/√12` = 2.9° RMS; with the rate (prior 0.3 °/s) it follows the ramp.
    #[test]
    fn the_smoother_follows_a_heading_that_drifts_at_a_rate() {
        let steps = still_steps(2000);
        let truth = |i: usize| (0.5 * i as f64 * 0.01).to_radians();
        let r = 20f64.to_radians().powi(2);
        let m: Vec<Option<(f64, f64)>> = (0..2000)
            .map(|i| {
                let off = if i % 2 == 0 { 20.0 } else { -20.0 };
                Some((truth(i) + f64::to_radians(off), r))
            })
            .collect();
        let drift = 0.02f64.to_radians().powi(2);
        let rms = |d: &[f64]| {
            let sum: f64 = d
                .iter()
                .enumerate()
                .map(|(i, x)| (x - truth(i)).powi(2))
                .sum();
            (sum / d.len() as f64).sqrt().to_degrees()
        };
        let (walk, _) = smooth_heading(&steps, 0.01, |i| m[i], drift, 0.0);
        let (rate, _) = smooth_heading(&steps, 0.01, |i| m[i], drift, 0.3f64.to_radians().powi(2));
        assert!(rms(&walk) > 2.5, "{}", rms(&walk));
        assert!(rms(&rate) < 0.5, "{}", rms(&rate));
    }

    /// The smoothed variance against the scalar Riccati equation's steady state: a walk of `Q`
    /// per step seen with variance `r` at every step filters to `P = (−Q + √(Q² + 4Qr)) / 2`,
    /// predicted `P⁻ = P + Q`, and smooths to `Pₛ = (P − C²P⁻) / (1 − C²)`, `C = P / P⁻` (the RTS
    /// recursion at its fixed point); at the last step the smoothed variance is the filtered one.
    /// Without measurements there is nothing to be unsure of: 0.
    #[test]
    fn the_smoothers_variance_is_the_riccati_steady_state() {
        let steps = still_steps(4000);
        let (q, r) = (1e-4, 0.05);
        let (_, var) = smooth_heading(&steps, 0.01, |_| Some((0.0, r)), q, 0.0);
        let step_q = q * 0.01;
        let p = (-step_q + (step_q * step_q + 4.0 * step_q * r).sqrt()) / 2.0;
        let p_pred = p + step_q;
        let c = p / p_pred;
        let smoothed = (p - c * c * p_pred) / (1.0 - c * c);
        assert!(
            (var[2000] / smoothed - 1.0).abs() < 1e-6,
            "{} vs {smoothed}",
            var[2000]
        );
        assert!((var[3999] / p - 1.0).abs() < 1e-6, "{} vs {p}", var[3999]);
        assert!(var[3999] > var[2000]);
        let (_, none) = smooth_heading(&steps, 0.01, |_| None, q, 0.0);
        assert!(none.iter().all(|v| *v == 0.0));
        // One step 5 ms late while the rate changes by 2 rad/s leaves (2 · 0.005)² rad²
        // unknown there: without measurements after it, the last variance is the steady one
        // plus that and the walk of the late 5 ms.
        let mut late = steps.clone();
        late[3990].dt = 0.015;
        late[3990].gyr = Vector3::new(2.0, 0.0, 0.0);
        let (_, var) = smooth_heading(&late, 0.01, |i| (i < 3990).then_some((0.0, r)), q, 0.0);
        let unknown = (2.0f64 * 0.005).powi(2);
        let by_hand = p + 10.0 * step_q + 0.005 * q + unknown;
        assert!(
            (var[3999] / by_hand - 1.0).abs() < 1e-6,
            "{} vs {by_hand}",
            var[3999]
        );
    }

    #[test]
    fn rest_is_found_in_stretches_and_pins_the_bias_between_them() {
        // A gyro with a bias of 0.01 rad/s on x, then 0.02 (it warmed up): 2 s still, 3 s of
        // turning about z at 1 rad/s, 4 s still, 1 s turning, 0.5 s still at the end (too
        // short to count).
        let step = |bias: f64, turning: bool| Step {
            gyr: Vector3::new(bias, 0.0, if turning { 1.0 } else { 0.0 }),
            acc: Vector3::new(0.0, 0.0, 9.80665),
            mag: None,
            dt: 0.01,
        };
        let steps: Vec<Step> = [
            (200, 0.01, false),
            (300, 0.015, true),
            (400, 0.02, false),
            (100, 0.02, true),
            (50, 0.02, false),
        ]
        .iter()
        .flat_map(|&(n, b, turning)| std::iter::repeat_n(step(b, turning), n))
        .collect();
        let segments = rest_segments(&steps);
        assert_eq!(segments.len(), 2, "{segments:?}");
        // The first stretch is still from its first sample; after turning, the detector's
        // low-pass takes ~1.7 s to settle. Each ends where the turning starts.
        assert_eq!((segments[0].start, segments[0].end), (0, 200));
        assert!(
            segments[1].start > 600 && segments[1].start < 720 && segments[1].end == 900,
            "{segments:?}"
        );
        let bias = bias_from_rest(&steps, &segments);
        assert!((bias[100].x - 0.01).abs() < 1e-9);
        // Between two stretches the estimate lies between their biases, nearer the nearer one.
        assert!(bias[300].x > 0.01 && bias[300].x < 0.015, "{}", bias[300].x);
        assert!(bias[480].x > 0.015 && bias[480].x < 0.02, "{}", bias[480].x);
        // After the last stretch, its bias is carried on.
        assert!((bias[960].x - 0.02).abs() < 1e-9, "{}", bias[960].x);
    }

    /// A take opening with a pose held 0.5 s (VQF's 1.5 s finds no rest in it) learns its bias
    /// and gravity there; a stretch that still so briefly later in the take does not count.
    #[test]
    fn a_brief_opening_pose_is_rest() {
        let step = |turning: bool| Step {
            gyr: Vector3::new(0.01, 0.0, if turning { 1.0 } else { 0.0 }),
            acc: Vector3::new(0.0, 0.0, 9.80665),
            mag: None,
            dt: 0.01,
        };
        let steps: Vec<Step> = [(50, false), (300, true), (50, false), (300, true)]
            .iter()
            .flat_map(|&(n, turning)| std::iter::repeat_n(step(turning), n))
            .collect();
        assert_eq!(rest_segments(&steps), vec![0..50]);
        let segments = rest_segments(&steps);
        assert!((bias_from_rest(&steps, &segments)[600].x - 0.01).abs() < 1e-12);
        // Shorter than OPENING_S it is not rest.
        assert!(rest_segments(&steps[20..]).is_empty());
    }

    /// Rest, then a real turn about x that speeds up smoothly to 3 °/s over 1 s and holds it for
    /// 1 s (the specific force turns): steady throughout, under the biased gyro's rate, but the
    /// turn is real — the rest before it stays as VQF finds it.
    #[test]
    fn a_slow_real_turn_after_rest_leaves_the_rest() {
        let rate = |i: usize| 3f64.to_radians() * ((i as f64 - 200.0) / 100.0).clamp(0.0, 1.0);
        let mut angle = 0.0;
        let steps: Vec<Step> = (0..400)
            .map(|i| {
                angle += rate(i) * 0.01;
                let turned = UnitQuaternion::from_scaled_axis(Vector3::x() * angle).inverse();
                Step {
                    gyr: Vector3::x() * rate(i),
                    acc: turned * Vector3::new(0.0, 0.0, 9.80665),
                    mag: None,
                    dt: 0.01,
                }
            })
            .collect();
        // The biased test's stretch covers it all, and is refused.
        let steady = steady_stretches(&steps, BIASED_REST_DPS);
        assert_eq!(steady, vec![0..400]);
        assert!(!turn_is_bias(&steps));
        let segments = rest_segments(&steps);
        assert_eq!(segments.len(), 1, "{segments:?}");
        assert_eq!(segments[0].start, 0);
        assert!(
            segments[0].end > 200 && segments[0].end < 320,
            "{segments:?}"
        );
    }

    /// A still sensor whose gyro is biased 3 °/s or 15 °/s about x (more than VQF's 2 °/s test
    /// allows) is at rest: its specific force and field keep their directions while the gyro
    /// says it turned 6° (30°). A sensor really turning at that rate about x is not (its specific
    /// force turns), nor about z without a magnetometer (nothing else sees a turn about the
    /// vertical); nor one biased beyond [`BIASED_REST_DPS`].
    #[test]
    fn a_biased_gyro_at_rest_is_told_from_a_slow_turn() {
        for rate_dps in [3.0, 15.0, 25.0] {
            let rate = f64::to_radians(rate_dps);
            let field = Vector3::new(0.0, 20.0, -40.0);
            let take = |axis: Vector3<f64>, real: bool, mag: bool| -> Vec<Step> {
                (0..200)
                    .map(|i| {
                        let turned = UnitQuaternion::from_scaled_axis(
                            axis * if real { rate * i as f64 * 0.01 } else { 0.0 },
                        )
                        .inverse();
                        Step {
                            gyr: axis * rate,
                            acc: turned * Vector3::new(0.0, 0.0, 9.80665),
                            mag: mag.then(|| turned * field),
                            dt: 0.01,
                        }
                    })
                    .collect()
            };
            // Biased, still: rest from the first sample (the whole take is its opening).
            let biased = take(Vector3::x(), false, true);
            if rate_dps > BIASED_REST_DPS {
                assert!(rest_segments(&biased).is_empty());
                continue;
            }
            assert_eq!(rest_segments(&biased), vec![0..200]);
            let bias = bias_from_rest(&biased, &rest_segments(&biased));
            assert!((bias[0].x - rate).abs() < 1e-12);
            assert_eq!(
                rest_segments(&take(Vector3::x(), false, false)),
                vec![0..200]
            );
            // Turning about x: the specific force turns with it.
            assert!(rest_segments(&take(Vector3::x(), true, true)).is_empty());
            // Turning about z: the field turns (with a magnetometer); without one, not rest either.
            assert!(rest_segments(&take(Vector3::z(), true, true)).is_empty());
            assert!(rest_segments(&take(Vector3::z(), false, false)).is_empty());
        }
    }

    /// Hand calculation: evenly spaced samples leave nothing unknown; samples 2 ms off a 10 ms
    /// period while the rate changes by 1 rad/s per sample leave 2 mrad per step, and over 1 s
    /// of such steps (100 of them, the first has no predecessor) a random walk of
    /// 100 · (2e-3)² rad² per second.
    #[test]
    fn uneven_samples_of_a_changing_rate_wander() {
        let step = |i: usize, dt: f64| Step {
            gyr: Vector3::new(i as f64, 0.0, 0.0),
            acc: Vector3::z(),
            mag: None,
            dt,
        };
        let even: Vec<Step> = (0..101).map(|i| step(i, 0.01)).collect();
        assert_eq!(timing_wander(&even, 1.0, 0.01), 0.0);
        let uneven: Vec<Step> = (0..101)
            .map(|i| step(i, if i % 2 == 0 { 0.012 } else { 0.008 }))
            .collect();
        let wander = timing_wander(&uneven, 1.0, 0.01);
        assert!((wander - 100.0 * 4e-6 / 1.0).abs() < 1e-12, "{wander}");
    }

    /// Hand calculation (V/g = 1/9.80665 = 0.10197 s): with `q` = 1.2e-4 rad²/s a 20 s take
    /// balances over 10 s, `0.10197·√(3/(1.2e-4·10))` = 5.099 s, and so does a 10 s one; a 5 s
    /// take over its 5 s, 7.21 s — not under 5, so the cube root, `∛(6·0.10197²/1.2e-4)` =
    /// 8.041 s; a steadier frame keeps 10 s, and even samples (`q` = 0) always do.
    #[test]
    fn the_inclination_window_balances_wander_against_velocity_changes() {
        let close = |a: f64, b: f64| (a - b).abs() < 2e-3;
        assert!(close(inclination_window(10.0, 1.2e-4, 20.0), 5.099));
        assert!(close(inclination_window(10.0, 1.2e-4, 10.0), 5.099));
        assert!(close(inclination_window(10.0, 1.2e-4, 5.0), 8.041));
        assert_eq!(inclination_window(10.0, 1e-6, 20.0), 10.0);
        assert_eq!(inclination_window(10.0, 0.0, 20.0), 10.0);
    }

    #[test]
    fn a_disturbance_is_found_with_hindsight_and_left_out() {
        // A still sensor facing north; from 4 s to 6 s a magnet adds 40 µT along east: the field's
        // norm changes by a quarter, and online VQF has not accepted a reference field yet.
        let field = Vector3::new(0.0, 20.0, -40.0);
        let steps: Vec<Step> = (0..1000)
            .map(|i| {
                let t = i as f64 * 0.01;
                let extra = if (4.0..6.0).contains(&t) {
                    Vector3::new(40.0, 0.0, 0.0)
                } else {
                    Vector3::zeros()
                };
                Step {
                    gyr: Vector3::zeros(),
                    acc: Vector3::new(0.0, 0.0, 9.81),
                    mag: Some(field + extra),
                    dt: 0.01,
                }
            })
            .collect();
        let out = fuse_offline(&steps, 0.01, true, &OfflineParams::default());
        assert!(out.magnetic_disturbance[500] && !out.magnetic_disturbance[300]);
        // Through the disturbance the heading rests on the gyro alone: the fusion expects more
        // error of its heading than with the field there throughout.
        let clean: Vec<Step> = steps
            .iter()
            .map(|s| Step {
                mag: Some(field),
                ..*s
            })
            .collect();
        let clean = fuse_offline(&clean, 0.01, true, &OfflineParams::default());
        assert!(
            out.expected.heading_deg > 1.05 * clean.expected.heading_deg,
            "{:?} vs {:?}",
            out.expected,
            clean.expected
        );
        let worst = out
            .orientation
            .iter()
            .map(|q| q.angle().to_degrees())
            .fold(0.0, f64::max);
        assert!(worst < 0.01, "heading pulled by {worst:.3}°");
    }

    #[test]
    fn a_still_tilted_sensor_comes_out_tilted_and_facing_its_field() {
        // A sensor turned 30° about x then 50° about the vertical, still for 20 s at 100 Hz.
        let truth = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 50f64.to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 30f64.to_radians());
        let acc = truth.inverse() * Vector3::new(0.0, 0.0, 9.81);
        let mag = truth.inverse() * Vector3::new(0.0, 20.0, -40.0);
        let steps = vec![
            Step {
                gyr: Vector3::zeros(),
                acc,
                mag: Some(mag),
                dt: 0.01
            };
            2000
        ];
        let out = fuse_offline(&steps, 0.01, true, &OfflineParams::default());
        for q in [out.orientation[0], out.orientation[1999]] {
            assert!(
                q.angle_to(&truth).to_degrees() < 0.01,
                "{}",
                q.angle_to(&truth).to_degrees()
            );
        }
        assert!(out.rest[1000]);
    }
}
