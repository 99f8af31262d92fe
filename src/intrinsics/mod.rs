//! Sensor intrinsics: corrections of a sensor's raw readings before fusion, and the solvers that
//! find them from calibration takes (`imubake calibrate-sensors`).
//!
//! Per sensor, in the order they apply to a reading:
//! - gyroscope `ω = G·(x − b)`: the bias `b` ([`gyro_bias`]) and paper 004's gain and
//!   misalignment `G` ([`gyro_gain`]);
//! - accelerometer `â = diag(s)·(x − o)` ([`accelerometer`]);
//! - magnetometer `m̂ = W·(x − h)`: hard iron `h`, soft iron `W` ([`magnetometer`]).
//!
//! Each solver is a pure function of a track; [`still`] finds the stretches of stillness they
//! read. A [`SensorCalibration`] file (YAML) holds the results per sensor id with each fit's
//! quality; [`SensorIntrinsics::apply`] corrects a sensor's tracks.

pub mod accelerometer;
pub mod gyro_bias;
pub mod gyro_gain;
pub mod magnetometer;
pub mod still;

use crate::take::{ImuSample, Track};
use accelerometer::AccCalibration;
use gyro_bias::GyroBias;
use gyro_gain::GyroGain;
use magnetometer::MagCalibration;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Why a calibration could not be found, or a calibration file not read. Each names the sensor
/// and what to record instead.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IntrinsicsError {
    #[error(
        "sensor `{sensor}`: never holds still for {min_s} s. Hint: record 5 s of the sensor lying still, \
         or give the still window (--still START:END)"
    )]
    NeverStill { sensor: String, min_s: f64 },
    #[error("sensor `{sensor}`: only {found} {what}, {needed} needed. Hint: {record}")]
    TooFew {
        sensor: String,
        what: String,
        found: usize,
        needed: usize,
        record: &'static str,
    },
    #[error(
        "sensor `{sensor}`: moved between {start_s} s and {end_s} s (its gyro readings spread {spread_dps:.1} °/s); \
         the bias needs stillness"
    )]
    Moved {
        sensor: String,
        start_s: f64,
        end_s: f64,
        spread_dps: f64,
    },
    #[error(
        "sensor `{sensor}`: its {axis} axis never pointed along and against the field (the readings cover \
         {coverage_pct:.0} % of the directions); a fit would be a guess. Hint: {record}"
    )]
    NotTurned {
        sensor: String,
        axis: &'static str,
        coverage_pct: f64,
        record: &'static str,
    },
    #[error(
        "sensor `{sensor}`: the readings cover {coverage_pct:.0} % of the directions, {needed_pct:.0} % needed for \
         the soft iron (`--mag-fit min-max` finds the hard iron alone). Hint: {record}"
    )]
    LowCoverage {
        sensor: String,
        coverage_pct: f64,
        needed_pct: f64,
        record: &'static str,
    },
    #[error(
        "sensor `{sensor}`: {found} still positions, six needed with each axis up and down (missing: {missing}). \
         Hint: {record}"
    )]
    Positions {
        sensor: String,
        found: usize,
        missing: String,
        record: &'static str,
    },
    #[error("sensor `{sensor}`: {what}. Hint: {record}")]
    Implausible {
        sensor: String,
        what: String,
        record: &'static str,
    },
    #[error("sensor `{sensor}`: has no {what} readings to calibrate")]
    NoReadings { sensor: String, what: &'static str },
    #[error("{}: {message}", .path.display())]
    File { path: PathBuf, message: String },
}

/// The corrections of one sensor, each with its fit's quality.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorIntrinsics {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro_bias: Option<GyroBias>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro_gain: Option<GyroGain>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accelerometer: Option<AccCalibration>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub magnetometer: Option<MagCalibration>,
}

impl SensorIntrinsics {
    /// The corrections it holds, by name (`gyro-bias`, `gyro-gain`, `acc`, `mag`).
    pub fn kinds(&self) -> Vec<&'static str> {
        let mut k = Vec::new();
        if self.gyro_bias.is_some() {
            k.push("gyro-bias");
        }
        if self.gyro_gain.is_some() {
            k.push("gyro-gain");
        }
        if self.accelerometer.is_some() {
            k.push("acc");
        }
        if self.magnetometer.is_some() {
            k.push("mag");
        }
        k
    }

    /// One inertial reading corrected.
    pub fn correct_inertial(&self, s: &ImuSample) -> ImuSample {
        let bias = self
            .gyro_bias
            .as_ref()
            .map_or(Vector3::zeros(), GyroBias::vector);
        let gain = self
            .gyro_gain
            .as_ref()
            .map_or(Matrix3::identity(), GyroGain::matrix);
        ImuSample {
            gyro_rad_s: gain * (s.gyro_rad_s - bias),
            accel_m_s2: self
                .accelerometer
                .as_ref()
                .map_or(s.accel_m_s2, |a| a.correct(&s.accel_m_s2)),
        }
    }

    /// One magnetometer reading corrected (hard and soft iron).
    pub fn correct_magnetometer(&self, m: &Vector3<f64>) -> Vector3<f64> {
        self.magnetometer.as_ref().map_or(*m, |cal| cal.correct(m))
    }

    /// A sensor's tracks corrected; each is borrowed as it is when nothing corrects it.
    #[allow(clippy::type_complexity)]
    pub fn apply<'a>(
        &self,
        inertial: &'a Track<ImuSample>,
        magnetometer: Option<&'a Track<Vector3<f64>>>,
    ) -> (
        Cow<'a, Track<ImuSample>>,
        Option<Cow<'a, Track<Vector3<f64>>>>,
    ) {
        let corrected =
            self.gyro_bias.is_some() || self.gyro_gain.is_some() || self.accelerometer.is_some();
        let inertial = if corrected {
            Cow::Owned(inertial.clone().map_in_place(|s| self.correct_inertial(s)))
        } else {
            Cow::Borrowed(inertial)
        };
        let magnetometer = magnetometer.map(|m| match &self.magnetometer {
            Some(cal) => Cow::Owned(m.clone().map_in_place(|x| cal.correct(x))),
            None => Cow::Borrowed(m),
        });
        (inertial, magnetometer)
    }
}

/// The version of the calibration file's layout.
pub const FILE_VERSION: u32 = 1;

/// A sensor calibration file: corrections per sensor id, and what they were found from.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorCalibration {
    /// [`FILE_VERSION`].
    pub imubake_sensor_calibration: u32,
    /// The calibration take(s) each kind was found from.
    #[serde(default)]
    pub sources: BTreeMap<String, String>,
    pub sensors: BTreeMap<String, SensorIntrinsics>,
}

impl SensorCalibration {
    pub fn new() -> Self {
        SensorCalibration {
            imubake_sensor_calibration: FILE_VERSION,
            ..Default::default()
        }
    }

    /// Reads a calibration file; errors name the file and what is wrong.
    pub fn load(path: &Path) -> Result<SensorCalibration, IntrinsicsError> {
        let err = |message: String| IntrinsicsError::File {
            path: path.to_path_buf(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
        Self::parse(&text).map_err(err)
    }

    pub fn parse(text: &str) -> Result<SensorCalibration, String> {
        let cal: SensorCalibration = serde_yaml::from_str(text).map_err(|e| {
            format!(
                "{e}; expected a sensor calibration file written by `imubake calibrate-sensors`"
            )
        })?;
        if cal.imubake_sensor_calibration != FILE_VERSION {
            return Err(format!(
                "layout version {} is not {FILE_VERSION}; write it again with this imubake's calibrate-sensors",
                cal.imubake_sensor_calibration
            ));
        }
        for (id, s) in &cal.sensors {
            let finite = |xs: &[f64]| xs.iter().all(|x| x.is_finite());
            let ok = s.gyro_bias.as_ref().is_none_or(|b| finite(&b.bias_rad_s))
                && s.gyro_gain.as_ref().is_none_or(|g| {
                    finite(g.matrix.as_flattened()) && g.matrix().determinant() > 0.0
                })
                && s.accelerometer
                    .as_ref()
                    .is_none_or(|a| finite(&a.offset_m_s2) && a.scale.iter().all(|x| *x > 0.0))
                && s.magnetometer.as_ref().is_none_or(|m| {
                    finite(&m.hard_iron)
                        && finite(m.soft_iron_correction.as_flattened())
                        && m.matrix().determinant() > 0.0
                });
            if !ok {
                return Err(format!(
                    "sensor `{id}`: a correction is not finite, or a matrix or scale is not positive"
                ));
            }
        }
        Ok(cal)
    }

    /// The file's text (YAML).
    pub fn to_yaml(&self) -> String {
        let mut text = String::from(
            "# imubake sensor calibration: gyro ω = G·(x − bias) (rad/s), accelerometer â = diag(scale)·(x − \
             offset) (m/s²),\n# magnetometer m̂ = W·(x − hard_iron) (the log's unit). Matrices by rows.\n",
        );
        text.push_str(&serde_yaml::to_string(self).expect("plain data serialises"));
        text
    }

    /// This file with `newer`'s corrections over its own (kind by kind, sensor by sensor).
    pub fn merged(mut self, newer: SensorCalibration) -> SensorCalibration {
        self.sources.extend(newer.sources);
        for (id, n) in newer.sensors {
            let s = self.sensors.entry(id).or_default();
            s.gyro_bias = n.gyro_bias.or(s.gyro_bias.take());
            s.gyro_gain = n.gyro_gain.or(s.gyro_gain.take());
            s.accelerometer = n.accelerometer.or(s.accelerometer.take());
            s.magnetometer = n.magnetometer.or(s.magnetometer.take());
        }
        self
    }
}

/// A sensor's readings made ready for fusion: the calibration file's corrections for it, then —
/// when the file gives no gyro bias and the filter does not estimate one itself (VQF, Mahony and
/// the offline fusion do; correcting twice would fight them) — the bias read over the take's
/// opening stillness (a stretch starting in its first second). `corrections` says what ran;
/// `warnings` when a bias was wanted but the take does not open still.
/// The tracks are borrowed where nothing corrects them (the default for most takes).
pub struct Prepared<'a> {
    pub inertial: Cow<'a, Track<ImuSample>>,
    pub magnetometer: Option<Cow<'a, Track<Vector3<f64>>>>,
    pub corrections: Vec<String>,
    pub warnings: Vec<String>,
}

/// Where the gyro bias comes from when the calibration file gives none.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BiasFallback {
    /// The filter estimates it itself (VQF, Mahony, the offline fusion).
    Filter,
    /// Read over the take's opening stillness.
    OpeningStillness,
    /// Left in: a causal run cannot look ahead at an opening stillness.
    LeftIn,
}

pub fn prepare<'a>(
    sensor: &str,
    inertial: &'a Track<ImuSample>,
    magnetometer: Option<&'a Track<Vector3<f64>>>,
    calibration: Option<&SensorIntrinsics>,
    fallback: BiasFallback,
) -> Prepared<'a> {
    let mut corrections: Vec<String> = calibration
        .map(|c| {
            c.kinds()
                .iter()
                .map(|k| format!("{k} (calibration file)"))
                .collect()
        })
        .unwrap_or_default();
    let mut warnings = Vec::new();
    let mut intrinsics = calibration.cloned().unwrap_or_default();
    if intrinsics.gyro_bias.is_none() {
        match fallback {
            BiasFallback::Filter => {
                corrections.push("gyro-bias (estimated by the filter)".into());
            }
            BiasFallback::LeftIn => corrections
                .push("gyro-bias left in (causal: no look ahead at an opening stillness)".into()),
            BiasFallback::OpeningStillness => {
                let opening = still::still_stretches(inertial, &still::StillOptions::default())
                    .into_iter()
                    .next()
                    .filter(|s| s.start_s <= inertial.times_s()[0] + 1.0);
                match opening {
                    Some(s) => {
                        let b = gyro_bias::bias_over(inertial, s.samples.clone());
                        corrections.push(format!(
                            "gyro-bias (opening stillness {:.2}–{:.2} s)",
                            b.window_s[0], b.window_s[1]
                        ));
                        intrinsics.gyro_bias = Some(b);
                    }
                    None => warnings.push(format!(
                        "sensor `{sensor}`: the take does not open with 2 s of stillness, and the filter does not \
                         estimate the gyro bias: it is left in (record a still start, or give a calibration file)"
                    )),
                }
            }
        }
    }
    let (inertial, magnetometer) = intrinsics.apply(inertial, magnetometer);
    Prepared {
        inertial,
        magnetometer,
        corrections,
        warnings,
    }
}

/// A kind of calibration (`--kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    GyroBias,
    GyroGain,
    Acc,
    Mag,
}

impl Kind {
    pub const ALL: [Kind; 4] = [Kind::GyroBias, Kind::GyroGain, Kind::Acc, Kind::Mag];

    pub fn name(self) -> &'static str {
        match self {
            Kind::GyroBias => "gyro-bias",
            Kind::GyroGain => "gyro-gain",
            Kind::Acc => "acc",
            Kind::Mag => "mag",
        }
    }
}

impl std::str::FromStr for Kind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Kind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                format!("unknown calibration kind `{s}`; expected gyro-bias, gyro-gain, acc or mag")
            })
    }
}

/// How to calibrate a take.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrateOptions {
    pub still: still::StillOptions,
    /// Where the gyro bias is read (default: the first stretch of stillness).
    pub bias_window: Option<(f64, f64)>,
    pub mag_fit: magnetometer::MagFit,
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        CalibrateOptions {
            still: still::StillOptions::default(),
            bias_window: None,
            mag_fit: magnetometer::MagFit::Ellipsoid,
        }
    }
}

/// What calibrating a take came to: the corrections found, a note for each rotation left out,
/// and each (sensor, kind) that failed with why.
#[derive(Debug, Clone, Default)]
pub struct Calibrated {
    pub calibration: SensorCalibration,
    pub notes: Vec<String>,
    pub failed: Vec<(String, Kind, IntrinsicsError)>,
}

/// Runs the solvers of `kinds` on every sensor of `take` that has the readings they need.
pub fn calibrate_take(
    take: &crate::take::Take,
    kinds: &[Kind],
    options: &CalibrateOptions,
) -> Calibrated {
    let mut out = Calibrated {
        calibration: SensorCalibration::new(),
        ..Default::default()
    };
    let source = take.source().path.display().to_string();
    for sensor in take.sensors() {
        let id = sensor.id();
        let mut found = SensorIntrinsics::default();
        for &kind in kinds {
            let result: Result<(), IntrinsicsError> = (|| {
                let inertial = || {
                    sensor
                        .inertial()
                        .ok_or_else(|| IntrinsicsError::NoReadings {
                            sensor: id.to_string(),
                            what: "gyroscope and accelerometer",
                        })
                };
                match kind {
                    Kind::GyroBias => {
                        let window = match options.bias_window {
                            Some((start_s, end_s)) => {
                                gyro_bias::BiasWindow::Given { start_s, end_s }
                            }
                            None => gyro_bias::BiasWindow::FirstStill(options.still),
                        };
                        found.gyro_bias = Some(gyro_bias::gyro_bias(id, inertial()?, &window)?);
                    }
                    Kind::GyroGain => {
                        found.gyro_gain = Some(gyro_gain::calibrate_gyro_gain(
                            id,
                            inertial()?,
                            &options.still,
                            &mut out.notes,
                        )?);
                    }
                    Kind::Acc => {
                        found.accelerometer = Some(accelerometer::calibrate_accelerometer(
                            id,
                            inertial()?,
                            &options.still,
                        )?);
                    }
                    Kind::Mag => {
                        let m =
                            sensor
                                .magnetometer()
                                .ok_or_else(|| IntrinsicsError::NoReadings {
                                    sensor: id.to_string(),
                                    what: "magnetometer",
                                })?;
                        found.magnetometer = Some(magnetometer::calibrate_magnetometer(
                            id,
                            m.values(),
                            options.mag_fit,
                        )?);
                    }
                }
                out.calibration
                    .sources
                    .insert(kind.name().to_string(), source.clone());
                Ok(())
            })();
            if let Err(e) = result {
                out.failed.push((id.to_string(), kind, e));
            }
        }
        if !found.kinds().is_empty() {
            out.calibration.sensors.insert(id.to_string(), found);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_round_trips_merges_and_refuses_nonsense() {
        let mut a = SensorCalibration::new();
        a.sensors.insert(
            "imu".into(),
            SensorIntrinsics {
                gyro_bias: Some(GyroBias {
                    bias_rad_s: [0.01, 0.0, -0.02],
                    window_s: [0.0, 3.0],
                    samples: 300,
                    noise_dps: [0.1; 3],
                    uncertainty_dps: [0.006; 3],
                }),
                ..Default::default()
            },
        );
        let text = a.to_yaml();
        let back = SensorCalibration::parse(&text).unwrap();
        assert_eq!(back, a);
        let mut b = SensorCalibration::new();
        b.sensors.insert(
            "imu".into(),
            SensorIntrinsics {
                accelerometer: Some(AccCalibration {
                    offset_m_s2: [0.1, 0.0, 0.0],
                    scale: [1.0, 1.01, 0.99],
                    positions: 6,
                    residual_before_m_s2: 0.1,
                    residual_after_m_s2: 0.001,
                }),
                ..Default::default()
            },
        );
        let m = a.clone().merged(b);
        assert_eq!(m.sensors["imu"].kinds(), ["gyro-bias", "acc"]);
        // A reading: bias off, then the accelerometer's offset and scale.
        let s = ImuSample {
            gyro_rad_s: Vector3::new(0.01, 0.0, -0.02),
            accel_m_s2: Vector3::new(0.1, 1.0, 1.0),
        };
        let c = m.sensors["imu"].correct_inertial(&s);
        assert_eq!(c.gyro_rad_s, Vector3::zeros());
        assert!((c.accel_m_s2 - Vector3::new(0.0, 1.01, 0.99)).norm() < 1e-12);
        let bad = text.replace("0.01", ".nan");
        assert!(
            SensorCalibration::parse(&bad)
                .unwrap_err()
                .contains("not finite")
        );
        assert!(
            SensorCalibration::parse("imubake_sensor_calibration: 2\nsensors: {}\n")
                .unwrap_err()
                .contains("version 2")
        );
    }

    /// Filters without a bias estimate of their own get the opening stillness's; the others, and
    /// a file's bias, are not corrected twice.
    #[test]
    fn the_opening_stillness_gives_the_bias_only_where_nothing_else_does() {
        let b = Vector3::new(0.02, -0.01, 0.03);
        let samples: Vec<ImuSample> = (0..500)
            .map(|i| ImuSample {
                gyro_rad_s: b + if i < 300 {
                    Vector3::zeros()
                } else {
                    Vector3::new(1.0, 0.0, 0.0)
                },
                accel_m_s2: Vector3::new(0.0, 0.0, 9.81),
            })
            .collect();
        let track = Track::new((0..500).map(|i| i as f64 / 100.0).collect(), samples).unwrap();
        let p = prepare("s", &track, None, None, BiasFallback::OpeningStillness);
        assert_eq!(p.corrections.len(), 1);
        assert!(
            p.corrections[0].starts_with("gyro-bias (opening stillness 0.00–"),
            "{:?}",
            p.corrections
        );
        assert!(p.inertial.values()[0].gyro_rad_s.norm() < 1e-12);
        assert!((p.inertial.values()[400].gyro_rad_s - Vector3::x()).norm() < 1e-12);
        let p = prepare("s", &track, None, None, BiasFallback::Filter);
        assert_eq!(p.corrections, ["gyro-bias (estimated by the filter)"]);
        assert_eq!(p.inertial.values()[0].gyro_rad_s, b);
        // Turning from the start: nothing to read the bias from, and a warning says so.
        let moving = track.clone().map_in_place(|s| ImuSample {
            gyro_rad_s: s.gyro_rad_s + Vector3::new(0.0, 1.0, 0.0),
            ..*s
        });
        let p = prepare("s", &moving, None, None, BiasFallback::OpeningStillness);
        assert!(
            p.corrections.is_empty() && p.warnings[0].contains("does not open"),
            "{:?}",
            p.warnings
        );
    }

    proptest::proptest! {
        /// Any readings (huge, tiny, constant, jumping): every solver returns a calibration or an
        /// error, never a panic.
        #[test]
        fn solvers_never_panic(
            rows in proptest::collection::vec(
                (proptest::array::uniform3(-1e6f64..1e6), proptest::array::uniform3(-1e3f64..1e3),
                 proptest::array::uniform3(-1e4f64..1e4), 0u8..4),
                1..300),
        ) {
            let mut text = String::from("time_s,sensor,gx,gy,gz,ax,ay,az,mx,my,mz\n");
            for (i, (g, a, m, hold)) in rows.iter().enumerate() {
                // Runs of repeated rows make stretches of stillness now and then.
                let (g, a, m) = if *hold == 0 { ([0.0; 3], [0.0, 0.0, 9.8], [20.0, 0.0, -40.0]) } else { (*g, *a, *m) };
                let g = g.map(|x| x * 1e-5);
                text.push_str(&format!("{},s,{},{},{},{},{},{},{},{},{}\n", i as f64 * 0.05,
                    g[0], g[1], g[2], a[0], a[1], a[2], m[0], m[1], m[2]));
            }
            let take = crate::read::imubake_csv::read_from(
                text.as_bytes(), Path::new("p.csv"), &crate::read::ReadOptions::default()).unwrap();
            let _ = calibrate_take(&take, &Kind::ALL, &CalibrateOptions::default());
        }

        /// Any text: a calibration or an error, never a panic.
        #[test]
        fn parsing_never_panics(text in "\\PC{0,300}") {
            let _ = SensorCalibration::parse(&text);
        }

        /// Mutations of a real file's text: the same.
        #[test]
        fn mutated_files_never_panic(cut in 0usize..400, insert in "\\PC{0,8}") {
            let mut cal = SensorCalibration::new();
            cal.sensors.insert("a".into(), SensorIntrinsics {
                magnetometer: Some(magnetometer::MagCalibration {
                    fit: magnetometer::MagFit::Ellipsoid,
                    hard_iron: [1.0, 2.0, 3.0],
                    soft_iron_correction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                    field_norm: 40.0,
                    residual_before_pct: 3.0,
                    residual_after_pct: 0.5,
                    kept_residual_before_pct: 3.0,
                    kept_residual_after_pct: 0.5,
                    set_aside_pct: 0.0,
                    coverage_pct: 80.0,
                    samples: 1000,
                }),
                ..Default::default()
            });
            let mut text = cal.to_yaml();
            let at = text.char_indices().map(|(i, _)| i).nth(cut % text.chars().count()).unwrap_or(0);
            text.insert_str(at, &insert);
            let _ = SensorCalibration::parse(&text);
        }
    }
}
