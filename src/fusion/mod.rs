//! Orientation from raw readings: gyroscope (rad/s), accelerometer (specific force, m/s²) and
//! magnetometer (any unit), all in the sensor frame → `q_enu_sensor`, whatever a filter's
//! textbook frame.
//!
//! Each filter is an incremental core with x-io Fusion's shape, [`Ahrs::update`]`(gyr, acc, mag,
//! dt)`; [`fuse`] runs one over a sensor's whole track. Filters:
//! - [`offline`] (the default for a whole take): VQF's passes both ways, a two-sided inclination
//!   average and a smoothed heading;
//! - [`vqf`] (the default for streams): VQF, through `vqf-rs`;
//! - [`madgwick`] (β), [`mahony`] (k_P, k_I), [`trust`] (paper 000's blend), [`gyro`] (paper 004's
//!   integration only).
//!
//! Each runs 9D (with the magnetometer) or 6D (without: the heading is then arbitrary and drifts;
//! calibration aligns it).

pub mod gyro;
pub mod init;
pub mod madgwick;
pub mod mahony;
pub mod offline;
pub mod stream;
pub mod trust;
pub mod vqf;

use crate::take::{ImuSample, Track};
use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;
use std::fmt;
use std::str::FromStr;

/// What a filter rejected at its last step.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Rejected {
    /// The magnetometer was set aside (a disturbed field).
    pub magnetic: bool,
    /// The accelerometer was set aside (the body accelerating).
    pub acceleration: bool,
}

/// An attitude filter's incremental core.
pub trait Ahrs {
    /// One step: the gyroscope (rad/s), the accelerometer (m/s²) and, when there is one, the
    /// magnetometer, all in the sensor frame, `dt` seconds after the previous step.
    fn update(
        &mut self,
        gyr: &Vector3<f64>,
        acc: &Vector3<f64>,
        mag: Option<&Vector3<f64>>,
        dt: f64,
    );
    /// `q_enu_sensor`.
    fn orientation(&self) -> UnitQuaternion<f64>;
    /// The gyroscope bias the filter estimates, rad/s (subtracted from the readings).
    fn gyro_bias(&self) -> Option<Vector3<f64>> {
        None
    }
    fn rejected(&self) -> Rejected {
        Rejected::default()
    }
}

/// `q_enu_nwu`: north (NWU's x) is ENU's y, west (NWU's y) is ENU's −x.
pub fn nwu_to_enu() -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2)
}

/// A filter and its parameters (`--fusion NAME[:key=value,...]`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "method", rename_all = "lowercase")]
pub enum Filter {
    Vqf {
        tau_acc: f64,
        tau_mag: f64,
    },
    Madgwick {
        beta: f64,
    },
    Mahony {
        kp: f64,
        ki: f64,
    },
    Trust {
        /// The gyro's range, °/s.
        range_dps: f64,
    },
    Gyro,
    /// The whole take at once ([`offline`]); a stream runs online VQF instead.
    Offline {
        /// The two-sided inclination average's time constant, s.
        tau_acc: f64,
        /// The magnetometer's heading error at rest and in motion, degrees.
        rest_deg: f64,
        motion_deg: f64,
        /// How fast the heading offset may wander, °/√s.
        drift: f64,
    },
}

impl Filter {
    /// The filter's name, as `--fusion` takes it.
    pub fn name(&self) -> &'static str {
        match self {
            Filter::Vqf { .. } => "vqf",
            Filter::Madgwick { .. } => "madgwick",
            Filter::Mahony { .. } => "mahony",
            Filter::Trust { .. } => "trust",
            Filter::Gyro => "gyro",
            Filter::Offline { .. } => "offline",
        }
    }

    /// The offline filter with its default parameters.
    pub fn offline() -> Filter {
        let p = offline::OfflineParams::default();
        Filter::Offline {
            tau_acc: p.tau_acc,
            rest_deg: p.rest_deg,
            motion_deg: p.motion_deg,
            drift: p.drift,
        }
    }
}

/// The fusion settings: a filter, and whether to leave the magnetometer out (6D).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Fusion {
    #[serde(flatten)]
    pub filter: Filter,
    /// Ignore the magnetometer even when there is one.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub six_d: bool,
}

impl Default for Fusion {
    /// The default for a whole take: the offline fusion ([`offline`]).
    fn default() -> Self {
        Fusion {
            filter: Filter::offline(),
            six_d: false,
        }
    }
}

impl Fusion {
    /// The default when samples come one at a time (streams, `--causal`): online VQF.
    pub fn online_default() -> Self {
        let p = vqf::VqfParams::default();
        Fusion {
            filter: Filter::Vqf {
                tau_acc: p.tau_acc,
                tau_mag: p.tau_mag,
            },
            six_d: false,
        }
    }
}

impl fmt::Display for Fusion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.filter {
            Filter::Vqf { tau_acc, tau_mag } => {
                write!(f, "vqf:tau_acc={tau_acc},tau_mag={tau_mag}")?
            }
            Filter::Madgwick { beta } => write!(f, "madgwick:beta={beta}")?,
            Filter::Mahony { kp, ki } => write!(f, "mahony:kp={kp},ki={ki}")?,
            Filter::Trust { range_dps } => write!(f, "trust:range={range_dps}")?,
            Filter::Gyro => write!(f, "gyro")?,
            Filter::Offline {
                tau_acc,
                rest_deg,
                motion_deg,
                drift,
            } => write!(
                f,
                "offline:tau_acc={tau_acc},rest={rest_deg},motion={motion_deg},drift={drift}"
            )?,
        }
        if self.six_d {
            f.write_str(if matches!(self.filter, Filter::Gyro) {
                ":6d"
            } else {
                ",6d"
            })?;
        }
        Ok(())
    }
}

impl FromStr for Fusion {
    type Err = String;

    /// `vqf[:tau_acc=3,tau_mag=9]`, `madgwick[:beta=0.12]`, `mahony[:kp=0.74,ki=0.0012]`,
    /// `trust[:range=2000]`, `gyro`; any of them with `6d` among the options to leave the
    /// magnetometer out.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (name, args) = s.trim().split_once(':').unwrap_or((s.trim(), ""));
        let mut six_d = false;
        let mut pairs = Vec::new();
        for a in args.split(',').map(str::trim).filter(|a| !a.is_empty()) {
            if a.eq_ignore_ascii_case("6d") {
                six_d = true;
                continue;
            }
            let (k, v) = a
                .split_once('=')
                .ok_or_else(|| format!("`{s}`: `{a}` needs a value, e.g. {a}=1"))?;
            let v: f64 = v
                .trim()
                .parse()
                .ok()
                .filter(|x: &f64| x.is_finite() && *x >= 0.0)
                .ok_or_else(|| format!("`{s}`: `{a}` is not a number ≥ 0"))?;
            pairs.push((k.trim().to_ascii_lowercase(), v));
        }
        let take = |allowed: &[&str], defaults: &mut [f64]| -> Result<(), String> {
            for (k, v) in &pairs {
                match allowed.iter().position(|a| a == k) {
                    Some(i) => defaults[i] = *v,
                    None => {
                        return Err(format!(
                            "`{s}`: unknown option `{k}` for {name}; expected {} or 6d",
                            allowed.join(", ")
                        ));
                    }
                }
            }
            Ok(())
        };
        let filter = match name.to_ascii_lowercase().as_str() {
            "vqf" => {
                let d = vqf::VqfParams::default();
                let mut v = [d.tau_acc, d.tau_mag];
                take(&["tau_acc", "tau_mag"], &mut v)?;
                Filter::Vqf {
                    tau_acc: v[0],
                    tau_mag: v[1],
                }
            }
            "madgwick" => {
                let mut v = [DEFAULT_MADGWICK_BETA];
                take(&["beta"], &mut v)?;
                Filter::Madgwick { beta: v[0] }
            }
            "mahony" => {
                let mut v = [DEFAULT_MAHONY_KP, DEFAULT_MAHONY_KI];
                take(&["kp", "ki"], &mut v)?;
                Filter::Mahony { kp: v[0], ki: v[1] }
            }
            "trust" => {
                let mut v = [DEFAULT_GYRO_RANGE_DPS];
                take(&["range"], &mut v)?;
                Filter::Trust { range_dps: v[0] }
            }
            "gyro" => {
                take(&[], &mut [])?;
                Filter::Gyro
            }
            "offline" => {
                let d = offline::OfflineParams::default();
                let mut v = [d.tau_acc, d.rest_deg, d.motion_deg, d.drift];
                take(&["tau_acc", "rest", "motion", "drift"], &mut v)?;
                if v[0] <= 0.0 || v[1] <= 0.0 || v[2] <= 0.0 {
                    return Err(format!("`{s}`: tau_acc, rest and motion must be above 0"));
                }
                Filter::Offline {
                    tau_acc: v[0],
                    rest_deg: v[1],
                    motion_deg: v[2],
                    drift: v[3],
                }
            }
            _ => {
                return Err(format!(
                    "unknown fusion `{name}`; expected offline, vqf, madgwick, mahony, trust or gyro"
                ));
            }
        };
        Ok(Fusion { filter, six_d })
    }
}

/// Madgwick's β by default: BROAD's best over all its trials (its published runs).
pub const DEFAULT_MADGWICK_BETA: f64 = 0.12;
/// Mahony's gains by default: BROAD's best over all its trials.
pub const DEFAULT_MAHONY_KP: f64 = 0.74;
pub const DEFAULT_MAHONY_KI: f64 = 0.0012;
/// The trust filter's gyro range by default, °/s (common MEMS gyros' largest range).
pub const DEFAULT_GYRO_RANGE_DPS: f64 = 2000.0;

impl Fusion {
    /// Whether the filter needs the whole take (a stream runs [`Fusion::core`] instead).
    pub fn is_offline(&self) -> bool {
        matches!(self.filter, Filter::Offline { .. })
    }

    /// Whether the filter estimates the gyro bias itself (VQF, Mahony's integral term, the
    /// offline fusion's rest and passes).
    pub fn estimates_gyro_bias(&self) -> bool {
        matches!(
            self.filter,
            Filter::Vqf { .. } | Filter::Mahony { .. } | Filter::Offline { .. }
        )
    }

    /// The online setting a stream runs for this one (offline → VQF).
    pub fn online(&self) -> Fusion {
        match self.filter {
            Filter::Offline { .. } => Fusion {
                six_d: self.six_d,
                ..Fusion::online_default()
            },
            _ => self.clone(),
        }
    }

    /// The filter's core, starting from the first readings' attitude (VQF starts itself).
    pub fn core(
        &self,
        q0: UnitQuaternion<f64>,
        sample_time_s: f64,
        nine_d: bool,
    ) -> Box<dyn Ahrs + Send> {
        match self.filter {
            Filter::Vqf { tau_acc, tau_mag } => Box::new(vqf::Vqf::new(
                &vqf::VqfParams {
                    tau_acc,
                    tau_mag,
                    ..vqf::VqfParams::default()
                },
                sample_time_s,
                nine_d,
            )),
            Filter::Madgwick { beta } => Box::new(madgwick::Madgwick::new(beta, q0)),
            Filter::Mahony { kp, ki } => Box::new(mahony::Mahony::new(kp, ki, q0)),
            Filter::Trust { range_dps } => Box::new(trust::Trust::new(range_dps.to_radians(), q0)),
            Filter::Gyro => Box::new(gyro::GyroIntegration::new(q0)),
            // Sample by sample there is no future: online VQF with the passes' parameters.
            Filter::Offline { .. } => Box::new(vqf::Vqf::new(
                &vqf::VqfParams::default(),
                sample_time_s,
                nine_d,
            )),
        }
    }
}

/// Why raw readings cannot be fused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FusionError {
    #[error(
        "sensor `{sensor}`: gyroscope rates reach {max:.0} rad/s, more than any body turns (35 rad/s \
         is already 2000 °/s). Hint: the readings are probably in °/s: name the columns gx_dps, gy_dps, gz_dps"
    )]
    GyroUnits { sensor: String, max: f64 },
    #[error("sensor `{sensor}`: the accelerometer reads {norm:.2} at rest, not 9.81 m/s². {hint}")]
    AccelUnits {
        sensor: String,
        norm: f64,
        hint: &'static str,
    },
    #[error("sensor `{sensor}`: no usable accelerometer reading to start from")]
    NoStart { sensor: String },
}

/// What fusing a sensor came to, for the sidecar and the report.
#[derive(Debug, Clone, Serialize)]
pub struct FusionStats {
    /// The filter that fused this sensor (`offline`, `vqf`, …; `--fusion`'s names).
    pub algorithm: &'static str,
    /// `9d` or `6d`.
    pub variant: &'static str,
    /// The filter's last gyro bias estimate, °/s (for filters that estimate one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gyro_bias_dps: Option<[f64; 3]>,
    /// Missing samples filled in (readings interpolated at the nominal rate) over short gaps.
    pub filled_samples: usize,
    /// Share of samples in which the magnetometer was set aside as disturbed (VQF: the field's
    /// norm or dip off its accepted reference — and before a reference is accepted, which takes
    /// about 5 s of turning).
    pub magnetic_rejected: f64,
    /// Share of samples in which the accelerometer was set aside.
    pub acceleration_rejected: f64,
    /// The offline fusion: seconds of rest found (its gyro bias came from them; `0` when the
    /// take has none and the bias came from VQF's passes in motion).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rest_s: Option<f64>,
    /// The offline fusion: seconds in which the field was disturbed (left out of the heading).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub disturbed_s: Option<f64>,
    /// The offline fusion: the error it expects of itself, RMS over the take, degrees
    /// (`offline::ExpectedError`: a model from the bias's uncertainty, the samples' timing and
    /// the heading smoother's variance; above [`EXPECTED_ERROR_WARN_DEG`] a warning).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expected_error_deg: Option<f64>,
    /// The corrections of the readings before fusion (the sensor calibration file's kinds, and
    /// where the gyro bias came from).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub corrections: Vec<String>,
    /// Over time (every 0.1 s): (time s, gyro bias magnitude °/s, magnetometer set aside,
    /// accelerometer set aside), for the report.
    #[serde(skip)]
    pub series: Vec<(f64, f64, bool, bool)>,
}

impl FusionStats {
    /// One line for people: the algorithm and what it found, e.g. `offline 9d, rest 1.5 s, gyro
    /// bias (0.100, -0.200, 0.200) °/s, expected error 0.75°`.
    pub fn describe(&self) -> String {
        let mut out = format!("{} {}", self.algorithm, self.variant);
        if let Some(r) = self.rest_s {
            out += &format!(", rest {r:.1} s");
        }
        if let Some(b) = self.gyro_bias_dps {
            out += &format!(", gyro bias ({:.3}, {:.3}, {:.3}) °/s", b[0], b[1], b[2]);
        }
        if let Some(d) = self.disturbed_s.filter(|d| *d > 0.0) {
            out += &format!(", field disturbed {d:.1} s");
        }
        if let Some(e) = self.expected_error_deg {
            out += &format!(", expected error {e:.2}°");
        }
        out
    }
}

/// Which algorithms fused how many sensors, e.g. `offline 9d ×15, offline 6d ×1` (in order of
/// first appearance).
pub fn algorithms_summary<'a>(stats: impl IntoIterator<Item = &'a FusionStats>) -> String {
    let mut counts: Vec<((&str, &str), usize)> = Vec::new();
    for s in stats {
        let key = (s.algorithm, s.variant);
        match counts.iter_mut().find(|(k, _)| *k == key) {
            Some((_, n)) => *n += 1,
            None => counts.push((key, 1)),
        }
    }
    counts
        .iter()
        .map(|((a, v), n)| format!("{a} {v} ×{n}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The offline fusion's expected error above which a sensor gets a warning, degrees: beyond its
/// worst on the real BROAD trials (1.47°), with a margin for the estimate being a model.
pub const EXPECTED_ERROR_WARN_DEG: f64 = 2.0;

/// A filter's outputs at each step.
struct Run {
    orientation: Vec<UnitQuaternion<f64>>,
    bias: StepBias,
    rejected: Vec<Rejected>,
    /// The offline fusion's rest, per step.
    rest: Option<Vec<bool>>,
    /// The offline fusion's estimate of its error.
    expected: Option<offline::ExpectedError>,
}

/// The gyro bias at each step, as the filter gave it (no copy of the offline fusion's).
enum StepBias {
    /// An online core's, where it estimates one.
    Online(Vec<Option<Vector3<f64>>>),
    Offline(Vec<Vector3<f64>>),
}

impl StepBias {
    fn at(&self, k: usize) -> Option<Vector3<f64>> {
        match self {
            StepBias::Online(b) => b[k],
            StepBias::Offline(b) => Some(b[k]),
        }
    }
}

/// A sensor's fused orientation track and what it came to.
#[derive(Debug, Clone)]
pub struct Fused {
    /// `q_enu_sensor` at each inertial sample's time.
    pub track: Track<UnitQuaternion<f64>>,
    pub stats: FusionStats,
    pub warnings: Vec<String>,
}

/// The median (the upper one of an even count), in linear time.
pub(crate) fn median(mut v: Vec<f64>) -> f64 {
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Checks that readings are in the units the columns say: gyro rates no body reaches (°/s read
/// as rad/s) and an accelerometer whose norm when nearly still is not gravity's (g read as m/s²,
/// or another scale) are errors; a gyro that sits at its limit is a warning.
fn check_units(sensor: &str, inertial: &Track<ImuSample>) -> Result<Vec<String>, FusionError> {
    let mut warnings = Vec::new();
    // Each axis's largest magnitude, in one pass.
    let peaks = inertial.values().iter().fold([0.0f64; 3], |m, s| {
        std::array::from_fn(|axis| m[axis].max(s.gyro_rad_s[axis].abs()))
    });
    let max_rate = peaks[0].max(peaks[1]).max(peaks[2]);
    if max_rate > 35.0 {
        return Err(FusionError::GyroUnits {
            sensor: sensor.to_string(),
            max: max_rate,
        });
    }
    // The accelerometer's norm when the sensor is nearly still: among (up to 2000 spread)
    // samples, the tenth that turn slowest, whose specific force is mostly gravity's — a foot in
    // a fast walk reads 1.6 g on its median sample but 1 g in stance.
    let mut sampled: Vec<(f64, f64)> = inertial
        .values()
        .iter()
        .step_by((inertial.len() / 2000).max(1))
        .map(|s| (s.gyro_rad_s.norm(), s.accel_m_s2.norm()))
        .collect();
    sampled.sort_by(|a, b| a.0.total_cmp(&b.0));
    let stillest = sampled.len().div_ceil(10);
    let norm = median(sampled[..stillest].iter().map(|s| s.1).collect());
    // Wide bounds: the units differ ninefold, and a take that never rests reads well above
    // 1 g even there (a walking thigh's slowest-turning tenth is where its swing reverses,
    // 1.5 g on the pymo walk).
    if !(4.0..=30.0).contains(&norm) {
        let hint = if (0.4..=3.0).contains(&norm) {
            "Hint: the readings are probably in g: name the columns ax_g, ay_g, az_g"
        } else {
            "Hint: check the accelerometer's unit (m/s² by default, _g for g)"
        };
        return Err(FusionError::AccelUnits {
            sensor: sensor.to_string(),
            norm,
            hint,
        });
    }
    // A saturated axis: many readings at exactly the largest magnitude on that axis.
    let at_peaks = if peaks.iter().any(|&p| p > 1.0) {
        inertial.values().iter().fold([0usize; 3], |n, s| {
            std::array::from_fn(|axis| {
                let peak = peaks[axis];
                n[axis] + usize::from(peak > 1.0 && s.gyro_rad_s[axis].abs() == peak)
            })
        })
    } else {
        [0; 3]
    };
    for (axis, (&peak, &at_peak)) in peaks.iter().zip(&at_peaks).enumerate() {
        if at_peak >= 5 {
            warnings.push(format!(
                "sensor `{sensor}`: the gyroscope's {} axis sits at {:.0} °/s on {at_peak} samples: \
                 it saturated, and the orientation drifts there",
                ["x", "y", "z"][axis],
                peak.to_degrees()
            ));
        }
    }
    Ok(warnings)
}

/// Whether a magnetometer track carries a field: not all zero, not stuck at one value.
fn magnetometer_works(mag: &Track<Vector3<f64>>) -> bool {
    let first = mag.values()[0];
    first.norm() > 0.0 && mag.values().iter().any(|m| *m != first)
}

/// Gaps longer than this many missing samples are not filled (the rotation in them is unknown).
pub const MAX_FILLED_STEPS: usize = 50;

/// What [`steps_for`] did about the gap before a reading.
pub(crate) struct Gap {
    /// Readings filled in.
    pub filled: usize,
    /// A gap too long to fill (seconds): the filter carried on from before it.
    pub long_s: Option<f64>,
}

/// The filter steps one reading at `t` makes, given the one before it (`prev`): over a gap of up
/// to [`MAX_FILLED_STEPS`] missing samples at `nominal_dt`, readings interpolated linearly at the
/// nominal rate first (so the rotation over the gap follows the rates at both ends and the
/// filters' low-pass stages keep their steady rate); over a longer gap one nominal step (the
/// rotation in it is unknown); the first reading one nominal step. `step(gyr, acc, dt, real)`
/// takes each, `real` for the reading itself. Shared by whole tracks ([`fuse`]) and streams
/// ([`stream::StreamFuser`]), so both step a filter alike.
pub(crate) fn steps_for(
    prev: Option<(f64, &ImuSample)>,
    t: f64,
    s: &ImuSample,
    nominal_dt: f64,
    mut step: impl FnMut(Vector3<f64>, Vector3<f64>, f64, bool),
) -> Gap {
    let mut gap = Gap {
        filled: 0,
        long_s: None,
    };
    let Some((t_prev, prev)) = prev else {
        step(s.gyro_rad_s, s.accel_m_s2, nominal_dt, true);
        return gap;
    };
    let dt = t - t_prev;
    let count = (dt / nominal_dt).round();
    if count >= 2.0 && count <= MAX_FILLED_STEPS as f64 + 1.0 {
        let count = count as usize;
        let step_dt = dt / count as f64;
        for j in 1..count {
            let u = j as f64 / count as f64;
            step(
                prev.gyro_rad_s.lerp(&s.gyro_rad_s, u),
                prev.accel_m_s2.lerp(&s.accel_m_s2, u),
                step_dt,
                false,
            );
        }
        gap.filled = count - 1;
        step(s.gyro_rad_s, s.accel_m_s2, step_dt, true);
    } else if count >= 2.0 {
        gap.long_s = Some(dt);
        step(s.gyro_rad_s, s.accel_m_s2, nominal_dt, true);
    } else {
        step(s.gyro_rad_s, s.accel_m_s2, dt, true);
    }
    gap
}

/// The warning for a gap [`steps_for`] could not fill.
pub(crate) fn long_gap_warning(sensor: &str, dt: f64, t: f64) -> String {
    format!(
        "sensor `{sensor}`: no reading for {dt:.2} s before {t:.3} s; fusion carried on from the \
         orientation before the gap"
    )
}

/// Fuses one sensor's whole track with `fusion`: inertial samples (gyro and accelerometer at the
/// same instants) with the latest magnetometer sample at or before each (magnetometers often run
/// slower), each step's `dt` from the samples' own times; over a gap of up to
/// [`MAX_FILLED_STEPS`] missing samples (at the median period), readings interpolated linearly
/// at the nominal rate (on x-IMU3 UDP takes with dropped packets this halves the worst
/// inclination error against the device's own AHRS). The first step starts from the first
/// accelerometer (and magnetometer) reading's attitude; the orientation comes out at every
/// inertial sample.
pub fn fuse(
    sensor: &str,
    inertial: &Track<ImuSample>,
    magnetometer: Option<&Track<Vector3<f64>>>,
    fusion: &Fusion,
) -> Result<Fused, FusionError> {
    let mut warnings = check_units(sensor, inertial)?;
    let mag = magnetometer.filter(|m| {
        let works = magnetometer_works(m);
        if !works {
            warnings.push(format!(
                "sensor `{sensor}`: the magnetometer reads nothing (zero or one value throughout); \
                 fused without it (6D)"
            ));
        }
        works
    });
    let nine_d = mag.is_some() && !fusion.six_d;
    let mag = mag.filter(|_| nine_d);
    let times = inertial.times_s();
    let dts: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    let nominal_dt = if dts.is_empty() { 0.01 } else { median(dts) };
    let mut mag_index = 0;
    let mag_at = |t: f64, index: &mut usize| -> Option<Vector3<f64>> {
        let m = mag?;
        let mt = m.times_s();
        while *index + 1 < mt.len() && mt[*index + 1] <= t {
            *index += 1;
        }
        (mt[*index] <= t || *index == 0).then(|| m.values()[*index])
    };
    // The steps the filter takes: each inertial sample, after the filled-in samples of a short
    // gap before it. `real[k]`: step k is a sample of the track.
    let mut steps: Vec<offline::Step> = Vec::with_capacity(inertial.len());
    let mut real: Vec<bool> = Vec::with_capacity(inertial.len());
    let mut filled = 0usize;
    for (i, (t, s)) in inertial.iter().enumerate() {
        let m = mag_at(t, &mut mag_index);
        let prev = (i > 0).then(|| (times[i - 1], &inertial.values()[i - 1]));
        let gap = steps_for(prev, t, s, nominal_dt, |gyr, acc, dt, is_real| {
            steps.push(offline::Step {
                gyr,
                acc,
                mag: m,
                dt,
            });
            real.push(is_real);
        });
        filled += gap.filled;
        if let Some(dt) = gap.long_s {
            warnings.push(long_gap_warning(sensor, dt, t));
        }
    }
    let run = match &fusion.filter {
        Filter::Offline {
            tau_acc,
            rest_deg,
            motion_deg,
            drift,
        } => {
            let params = offline::OfflineParams {
                tau_acc: *tau_acc,
                rest_deg: *rest_deg,
                motion_deg: *motion_deg,
                drift: *drift,
                ..offline::OfflineParams::default()
            };
            let r = offline::fuse_offline(&steps, nominal_dt, nine_d, &params);
            Run {
                orientation: r.orientation,
                bias: StepBias::Offline(r.bias),
                rest: Some(r.rest),
                expected: Some(r.expected),
                rejected: r
                    .magnetic_disturbance
                    .into_iter()
                    .map(|magnetic| Rejected {
                        magnetic,
                        acceleration: false,
                    })
                    .collect(),
            }
        }
        _ => {
            let first = &inertial.values()[0];
            let q0 = init::attitude(&first.accel_m_s2, steps[0].mag.as_ref()).ok_or_else(|| {
                FusionError::NoStart {
                    sensor: sensor.to_string(),
                }
            })?;
            let mut core = fusion.core(q0, nominal_dt, nine_d);
            let n = steps.len();
            let (mut orientation, mut bias, mut rejected) = (
                Vec::with_capacity(n),
                Vec::with_capacity(n),
                Vec::with_capacity(n),
            );
            for s in &steps {
                core.update(&s.gyr, &s.acc, s.mag.as_ref(), s.dt);
                orientation.push(core.orientation());
                bias.push(core.gyro_bias());
                rejected.push(core.rejected());
            }
            Run {
                orientation,
                bias: StepBias::Online(bias),
                rejected,
                rest: None,
                expected: None,
            }
        }
    };
    // What the track's own samples came to.
    let (mut mag_rejected, mut acc_rejected) = (0usize, 0usize);
    let mut series = Vec::new();
    let mut next_series_t = f64::NEG_INFINITY;
    let mut last_bias = None;
    let kept = (0..steps.len()).filter(|k| real[*k]);
    for (k, t) in kept.clone().zip(times) {
        let rejected = run.rejected[k];
        mag_rejected += usize::from(rejected.magnetic);
        acc_rejected += usize::from(rejected.acceleration);
        last_bias = run.bias.at(k);
        if *t >= next_series_t {
            let bias = last_bias.map_or(0.0, |b| b.norm().to_degrees());
            series.push((*t, bias, rejected.magnetic, rejected.acceleration));
            next_series_t = t + 0.1;
        }
    }
    // The seconds of the steps flagged, from +0 (an empty f64 sum is −0, which JSON would print).
    let seconds_where = |flags: &mut dyn Iterator<Item = bool>| {
        steps
            .iter()
            .zip(flags)
            .filter(|(_, f)| *f)
            .fold(0.0, |sum, (s, _)| sum + s.dt)
    };
    let rest_s = run
        .rest
        .as_ref()
        .map(|rest| seconds_where(&mut rest.iter().copied()));
    // The offline fusion's own accounts (it alone has an expected error).
    let disturbed_s = run
        .expected
        .map(|_| seconds_where(&mut run.rejected.iter().map(|r| r.magnetic)));
    let expected_error_deg = run.expected.map(|e| e.total_deg());
    if let Some(e) = run
        .expected
        .filter(|e| e.total_deg() > EXPECTED_ERROR_WARN_DEG)
    {
        warnings.push(format!(
            "sensor `{sensor}`: the offline fusion expects {:.1}° of orientation error \
             (tilt {:.1}°, heading {:.1}°; rest {:.1} s{}) — above {EXPECTED_ERROR_WARN_DEG}°: \
             hold still longer before the motion, check the samples' timing, or calibrate the gyro",
            e.total_deg(),
            e.tilt_deg,
            e.heading_deg,
            rest_s.unwrap_or(0.0),
            disturbed_s
                .filter(|d| *d > 0.0)
                .map_or(String::new(), |d| format!(", field disturbed {d:.1} s")),
        ));
    }
    // Without filled-in steps, every step is a sample: the run's orientations are the track's.
    let out = if filled == 0 {
        run.orientation
    } else {
        kept.map(|k| run.orientation[k]).collect()
    };
    let n = inertial.len() as f64;
    let stats = FusionStats {
        algorithm: fusion.filter.name(),
        variant: if nine_d { "9d" } else { "6d" },
        filled_samples: filled,
        gyro_bias_dps: last_bias.map(|b| [b.x.to_degrees(), b.y.to_degrees(), b.z.to_degrees()]),
        magnetic_rejected: mag_rejected as f64 / n,
        acceleration_rejected: acc_rejected as f64 / n,
        rest_s,
        disturbed_s,
        expected_error_deg,
        corrections: Vec::new(),
        series,
    };
    let track = Track::new(times.to_vec(), out).expect("the inertial track's times");
    Ok(Fused {
        track,
        stats,
        warnings,
    })
}

/// Fuses every sensor of `take` that has raw readings, in take order, on rayon's pool (they are
/// independent).
pub fn fuse_take(
    take: &crate::take::Take,
    fusion: &Fusion,
) -> Result<Vec<(String, Fused)>, FusionError> {
    use rayon::prelude::*;
    let raw: Vec<_> = take
        .sensors()
        .iter()
        .filter_map(|s| s.inertial().map(|i| (s.id(), i, s.magnetometer())))
        .collect();
    raw.par_iter()
        .with_max_len(1)
        .map(|(id, inertial, mag)| Ok((id.to_string(), fuse(id, inertial, *mag, fusion)?)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Standard gravity, m/s².
    const G: f64 = 9.80665;

    #[test]
    fn fusion_settings_parse_and_print() {
        let f: Fusion = "madgwick:beta=0.05,6d".parse().unwrap();
        assert_eq!(f.filter, Filter::Madgwick { beta: 0.05 });
        assert!(f.six_d);
        assert_eq!(f.to_string(), "madgwick:beta=0.05,6d");
        assert_eq!("vqf".parse::<Fusion>().unwrap(), Fusion::online_default());
        assert_eq!("offline".parse::<Fusion>().unwrap(), Fusion::default());
        assert_eq!(Fusion::default().online(), Fusion::online_default());
        assert!(
            "vqf:beta=1"
                .parse::<Fusion>()
                .unwrap_err()
                .contains("unknown option `beta`")
        );
        assert!("kalman".parse::<Fusion>().is_err());
        assert_eq!(
            "mahony".parse::<Fusion>().unwrap().filter,
            Filter::Mahony {
                kp: 0.74,
                ki: 0.0012
            }
        );
        assert_eq!("gyro:6d".parse::<Fusion>().unwrap().to_string(), "gyro:6d");
    }

    /// A sensor spinning at a constant rate about its own z with the accelerometer reading gravity
    /// along z: every filter follows the spin (the heading turns, the inclination stays).
    #[test]
    fn every_filter_follows_a_spin_about_the_vertical() {
        let rate = 1.0; // rad/s
        let n = 500;
        let dt = 0.01;
        let times: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let samples = vec![
            ImuSample {
                gyro_rad_s: Vector3::new(0.0, 0.0, rate),
                accel_m_s2: Vector3::new(0.0, 0.0, G),
            };
            n
        ];
        let inertial = Track::new(times, samples).unwrap();
        for spec in ["vqf", "madgwick", "mahony", "trust", "gyro", "vqf:6d"] {
            let fusion: Fusion = spec.parse().unwrap();
            let fused = fuse("s", &inertial, None, &fusion).unwrap();
            assert_eq!(fused.stats.variant, "6d");
            let q = fused.track.values();
            // Turned by rate · (n − 1) · dt about +z between the first and last sample.
            let turn = q[0].inverse() * q[n - 1];
            let expected =
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rate * (n - 1) as f64 * dt);
            assert!(
                turn.angle_to(&expected).to_degrees() < 1.0,
                "{spec}: {:.3}°",
                turn.angle_to(&expected).to_degrees()
            );
            let up = q[n - 1] * Vector3::z();
            assert!((up - Vector3::z()).norm() < 1e-3, "{spec}: {up:?}");
        }
    }

    /// The offline fusion says how much rest its bias came from: a sensor still for its first
    /// second (a pose held before the motion) then turning, 1 s; one turning from the start, none.
    #[test]
    fn the_offline_fusion_reports_the_rest_it_found() {
        let track = |still_s: f64| {
            let times: Vec<f64> = (0..300).map(|i| i as f64 * 0.01).collect();
            let samples = times
                .iter()
                .map(|&t| ImuSample {
                    gyro_rad_s: Vector3::new(0.0, 0.0, if t < still_s { 0.0 } else { 1.0 }),
                    accel_m_s2: Vector3::new(0.0, 0.0, G),
                })
                .collect();
            Track::new(times, samples).unwrap()
        };
        let offline: Fusion = "offline".parse().unwrap();
        let rest = |still_s: f64| {
            fuse("shank", &track(still_s), None, &offline)
                .unwrap()
                .stats
                .rest_s
                .unwrap()
        };
        assert!((rest(1.0) - 1.0).abs() < 0.02, "{}", rest(1.0));
        // +0, not −0 (JSON prints the sign).
        assert!(rest(0.0) == 0.0 && rest(0.0).is_sign_positive());
    }

    /// Each fused sensor names its algorithm; the offline fusion's expected error is in the
    /// stats, and above [`EXPECTED_ERROR_WARN_DEG`] it is a warning: a 6D sensor still for 1 s,
    /// then turning about the vertical at a rate that swings by 10 rad/s between samples spaced
    /// 8, 12, 10, 8, … ms (the median period 10 ms), leaves `(10 · 0.002)²` rad² unknown on two
    /// steps in three: over the 900 steps of the turn in a 10 s take, `q` = 600 · 4·10⁻⁴ / 10 =
    /// 0.024 rad²/s. The inclination average shortens to `τ = (1 / 9.80665)·√(3 / (0.024 · 10))`
    /// = 0.3605 s and lets `q·τ/3` through; without a field nothing corrects the heading, `q·L/2`:
    /// in all `√(0.024 · (0.3605/3 + 10/2))` = 0.3506 rad = 20.09° (the bias, from the still
    /// second, adds a hundredth of a degree). Evenly spaced, the same sensor expects under a
    /// degree.
    #[test]
    fn the_offline_fusion_names_itself_and_warns_of_a_large_expected_error() {
        let track = |uneven: bool| {
            let mut t = 0.0;
            let times: Vec<f64> = (0..1001)
                .map(|i| {
                    if i > 0 {
                        t += if uneven {
                            [0.008, 0.012, 0.01][i % 3]
                        } else {
                            0.01
                        };
                    }
                    t
                })
                .collect();
            let samples = (0..1001)
                .map(|i| ImuSample {
                    gyro_rad_s: Vector3::new(
                        0.0,
                        0.0,
                        // (a little drift, or it would read as a saturated gyro)
                        match i {
                            0..100 => 0.0,
                            _ if i % 2 == 0 => 5.0 + 1e-4 * i as f64,
                            _ => -5.0 + 1e-4 * i as f64,
                        },
                    ),
                    accel_m_s2: Vector3::new(0.0, 0.0, G),
                })
                .collect();
            Track::new(times, samples).unwrap()
        };
        let offline: Fusion = "offline".parse().unwrap();
        let uneven = fuse("hand", &track(true), None, &offline).unwrap();
        assert_eq!(uneven.stats.algorithm, "offline");
        let expected = uneven.stats.expected_error_deg.unwrap();
        let q = 0.024f64;
        let tau = (1.0 / 9.80665f64) * (3.0 / (q * 10.0)).sqrt();
        let by_hand = (q * (tau / 3.0 + 10.0 / 2.0)).sqrt().to_degrees();
        assert!((expected - by_hand).abs() < 0.3, "{expected} vs {by_hand}");
        assert!(
            uneven
                .warnings
                .iter()
                .any(|w| w.contains("sensor `hand`: the offline fusion expects")),
            "{:?}",
            uneven.warnings
        );
        let even = fuse("hand", &track(false), None, &offline).unwrap();
        assert!(even.stats.expected_error_deg.unwrap() < 1.0);
        assert!(even.warnings.is_empty(), "{:?}", even.warnings);
        let vqf = fuse("hand", &track(false), None, &"vqf".parse().unwrap()).unwrap();
        assert_eq!(vqf.stats.algorithm, "vqf");
        assert_eq!(vqf.stats.expected_error_deg, None);
        // The seconds of a disturbed field: a still sensor whose field gains 40 µT along east
        // from 4 s to 6 s of 10 s.
        let times: Vec<f64> = (0..1000).map(|i| i as f64 * 0.01).collect();
        let still = vec![
            ImuSample {
                gyro_rad_s: Vector3::zeros(),
                accel_m_s2: Vector3::new(0.0, 0.0, G),
            };
            1000
        ];
        let field: Vec<Vector3<f64>> = times
            .iter()
            .map(|t| Vector3::new(if (4.0..6.0).contains(t) { 40.0 } else { 0.0 }, 20.0, -40.0))
            .collect();
        let disturbed = fuse(
            "hand",
            &Track::new(times.clone(), still).unwrap(),
            Some(&Track::new(times, field).unwrap()),
            &offline,
        )
        .unwrap();
        let seconds = disturbed.stats.disturbed_s.unwrap();
        assert!((seconds - 2.0).abs() < 0.02, "{seconds}");
    }

    #[test]
    fn a_saturated_gyro_and_a_dead_magnetometer_are_warnings() {
        // 20 samples, the gyro's x pinned at 2000 °/s on eight of them, its z at −1000 °/s on
        // six, its y reaching 1000 °/s once.
        let limit = 2000f64.to_radians();
        let samples: Vec<ImuSample> = (0..20)
            .map(|i| ImuSample {
                gyro_rad_s: Vector3::new(
                    if (5..13).contains(&i) {
                        limit
                    } else {
                        0.1 * i as f64
                    },
                    if i == 3 { limit / 2.0 } else { 0.0 },
                    if (10..16).contains(&i) {
                        -limit / 2.0
                    } else {
                        0.0
                    },
                ),
                accel_m_s2: Vector3::new(0.0, 0.0, G),
            })
            .collect();
        let times: Vec<f64> = (0..20).map(|i| i as f64 * 0.01).collect();
        let inertial = Track::new(times.clone(), samples).unwrap();
        let dead = Track::new(times, vec![Vector3::zeros(); 20]).unwrap();
        let fused = fuse("wrist", &inertial, Some(&dead), &Fusion::default()).unwrap();
        assert_eq!(fused.stats.variant, "6d");
        let text = fused.warnings.join("\n");
        assert!(
            text.contains("sensor `wrist`: the gyroscope's x axis sits at 2000 °/s on 8 samples"),
            "{text}"
        );
        assert!(
            text.contains("sensor `wrist`: the gyroscope's z axis sits at 1000 °/s on 6 samples"),
            "{text}"
        );
        assert!(!text.contains("y axis"), "{text}");
        assert!(
            text.contains("sensor `wrist`: the magnetometer reads nothing"),
            "{text}"
        );
    }

    #[test]
    fn readings_in_the_wrong_units_are_errors() {
        let track = |gyr: f64, acc: f64| {
            Track::new(
                vec![0.0, 0.01],
                vec![
                    ImuSample {
                        gyro_rad_s: Vector3::new(gyr, 0.0, 0.0),
                        accel_m_s2: Vector3::new(0.0, 0.0, acc),
                    };
                    2
                ],
            )
            .unwrap()
        };
        let f = Fusion::default();
        let error = |gyr: f64, acc: f64| {
            fuse("s", &track(gyr, acc), None, &f)
                .unwrap_err()
                .to_string()
        };
        let e = error(90.0, G);
        assert!(e.contains("gx_dps"), "{e}");
        let e = error(0.1, 1.0);
        assert!(e.contains("ax_g"), "{e}");
        assert!(fuse("s", &track(0.1, G), None, &f).is_ok());
        // A limb that never rests reads 1.5 g where it turns slowest; in g it would read 1.5.
        assert!(fuse("s", &track(0.1, 1.5 * G), None, &f).is_ok());
        let e = error(0.1, 1.5);
        assert!(e.contains("ax_g"), "{e}");
        let e = error(0.1, 100.0);
        assert!(e.contains("check the accelerometer's unit"), "{e}");
    }
}
