//! Gyro bias from a stretch of stillness: `b = (1/N) Σ ω_i` over the stretch's samples (a still
//! sensor turns at 0, so its mean reading is the bias), with the per-axis standard deviation of
//! the readings and of the mean (`σ/√N`) as its quality.

use super::IntrinsicsError;
use super::still::{Still, StillOptions, still_stretches};
use crate::take::{ImuSample, Track};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// A gyro bias and what it was read from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GyroBias {
    /// Subtracted from every reading, rad/s, sensor frame.
    pub bias_rad_s: [f64; 3],
    /// The stretch it was read over, s on the calibration take's clock.
    pub window_s: [f64; 2],
    pub samples: usize,
    /// The readings' standard deviation per axis over the stretch, °/s (the gyro's noise).
    pub noise_dps: [f64; 3],
    /// The standard deviation of the mean per axis, °/s (how well the bias is known).
    pub uncertainty_dps: [f64; 3],
}

impl GyroBias {
    pub fn vector(&self) -> Vector3<f64> {
        Vector3::from(self.bias_rad_s)
    }
}

/// Where to read the bias: a given window, or the first stretch of stillness found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BiasWindow {
    /// The first stretch of stillness ([`still_stretches`]).
    FirstStill(StillOptions),
    /// Between these times, s (the user says the sensor was still there).
    Given { start_s: f64, end_s: f64 },
}

/// The mean reading over the samples of `range`.
pub fn bias_over(inertial: &Track<ImuSample>, range: std::ops::Range<usize>) -> GyroBias {
    let values = &inertial.values()[range.clone()];
    let n = values.len() as f64;
    let mean = values.iter().map(|s| s.gyro_rad_s).sum::<Vector3<f64>>() / n;
    let var = values
        .iter()
        .map(|s| (s.gyro_rad_s - mean).component_mul(&(s.gyro_rad_s - mean)))
        .sum::<Vector3<f64>>()
        / (n - 1.0).max(1.0);
    let noise = var.map(|v| v.sqrt().to_degrees());
    let times = inertial.times_s();
    GyroBias {
        bias_rad_s: mean.into(),
        window_s: [times[range.start], times[range.end - 1]],
        samples: values.len(),
        noise_dps: noise.into(),
        uncertainty_dps: (noise / n.sqrt()).into(),
    }
}

/// The gyro bias of `sensor` over `window`. Errors: no stretch of stillness, or a given window
/// with fewer than 10 samples or in which the sensor moved.
pub fn gyro_bias(
    sensor: &str,
    inertial: &Track<ImuSample>,
    window: &BiasWindow,
) -> Result<GyroBias, IntrinsicsError> {
    match *window {
        BiasWindow::FirstStill(options) => {
            let found: Vec<Still> = still_stretches(inertial, &options);
            let first = found.first().ok_or_else(|| IntrinsicsError::NeverStill {
                sensor: sensor.to_string(),
                min_s: options.min_s,
            })?;
            Ok(bias_over(inertial, first.samples.clone()))
        }
        BiasWindow::Given { start_s, end_s } => {
            let times = inertial.times_s();
            let start = times.partition_point(|t| *t < start_s);
            let end = times.partition_point(|t| *t <= end_s);
            if end < start + 10 {
                return Err(IntrinsicsError::TooFew {
                    sensor: sensor.to_string(),
                    what: format!("readings between {start_s} s and {end_s} s for the gyro bias"),
                    found: end.saturating_sub(start),
                    needed: 10,
                    record: "give a window in which the sensor lay still for a few seconds",
                });
            }
            let bias = bias_over(inertial, start..end);
            // A window in which the sensor turned is not rest: its spread gives it away.
            let worst = bias.noise_dps.iter().copied().fold(0.0, f64::max);
            if worst > 2.0 {
                return Err(IntrinsicsError::Moved {
                    sensor: sensor.to_string(),
                    start_s,
                    end_s,
                    spread_dps: worst,
                });
            }
            Ok(bias)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bias_is_the_mean_over_the_first_stillness() {
        // 4 s still reading b ± a square wave of 0.1 °/s, then turning.
        let b = Vector3::new(0.01, -0.02, 0.005);
        let samples: Vec<ImuSample> = (0..600)
            .map(|i| ImuSample {
                gyro_rad_s: if i < 400 {
                    b + Vector3::repeat(if i % 2 == 0 { 0.1f64 } else { -0.1 }.to_radians())
                } else {
                    Vector3::new(1.0, 0.0, 0.0)
                },
                accel_m_s2: Vector3::new(0.0, 0.0, 9.81),
            })
            .collect();
        let track = Track::new((0..600).map(|i| i as f64 / 100.0).collect(), samples).unwrap();
        let g = gyro_bias(
            "s",
            &track,
            &BiasWindow::FirstStill(StillOptions::default()),
        )
        .unwrap();
        // The window's half-width of motion is cut; the square wave averages to 0 over an even
        // count, and the estimate is within 0.1 °/s / √N of b whatever the count.
        assert!(
            (g.vector() - b).amax() < 0.1f64.to_radians() / 20.0,
            "{g:?}"
        );
        assert!((g.noise_dps[0] - 0.1).abs() < 0.01, "{g:?}");
        let given = gyro_bias(
            "s",
            &track,
            &BiasWindow::Given {
                start_s: 0.0,
                end_s: 1.99,
            },
        )
        .unwrap();
        assert_eq!(given.samples, 200);
        assert!((given.vector() - b).amax() < 1e-12);
        let moved = gyro_bias(
            "s",
            &track,
            &BiasWindow::Given {
                start_s: 3.0,
                end_s: 5.0,
            },
        )
        .unwrap_err()
        .to_string();
        assert!(
            moved.contains("sensor `s`") && moved.contains("moved"),
            "{moved}"
        );
    }
}
