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
        let bias = self.gyro_bias.as_ref().map_or(Vector3::zeros(), GyroBias::vector);
        let gain = self.gyro_gain.as_ref().map_or(Matrix3::identity(), GyroGain::matrix);
        ImuSample {
            gyro_rad_s: gain * (s.gyro_rad_s - bias),
            accel_m_s2: self
                .accelerometer
                .as_ref()
                .map_or(s.accel_m_s2, |a| a.correct(&s.accel_m_s2)),
        }
    }

    /// A sensor's tracks corrected (the magnetometer's only when there is a correction for it).
    pub fn apply(
        &self,
        inertial: &Track<ImuSample>,
        magnetometer: Option<&Track<Vector3<f64>>>,
    ) -> (Track<ImuSample>, Option<Track<Vector3<f64>>>) {
        let inertial = inertial.clone().map_in_place(|s| self.correct_inertial(s));
        let magnetometer = magnetometer.map(|m| match &self.magnetometer {
            Some(cal) => m.clone().map_in_place(|x| cal.correct(x)),
            None => m.clone(),
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
            format!("{e}; expected a sensor calibration file written by `imubake calibrate-sensors`")
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
                && s.accelerometer.as_ref().is_none_or(|a| {
                    finite(&a.offset_m_s2) && a.scale.iter().all(|x| *x > 0.0)
                })
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
        assert!(SensorCalibration::parse(&bad).unwrap_err().contains("not finite"));
        assert!(SensorCalibration::parse("imubake_sensor_calibration: 2\nsensors: {}\n")
            .unwrap_err()
            .contains("version 2"));
    }
}
