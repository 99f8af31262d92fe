//! Stretches of stillness: where a sensor lies still long enough to read its gyro bias, or its
//! accelerometer in one position.
//!
//! A sample is still when, over the [`StillOptions::window_s`] around it, every gyro axis's
//! standard deviation is under `gyro_std_dps` and every accelerometer axis's under
//! `acc_std_m_s2`, and the mean rate is under `gyro_mean_dps` (a slow, steady turn has a small
//! deviation too; no MEMS gyro's bias is that large). Still samples in a row lasting at least
//! `min_s` make a stretch. The deviations, not the magnitudes, decide, so an uncalibrated gyro
//! with a large bias still finds its rest.

use crate::take::{ImuSample, Track};
use serde::Serialize;
use std::ops::Range;

/// The thresholds of stillness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StillOptions {
    /// The window each sample's deviations are taken over, s.
    pub window_s: f64,
    /// The largest standard deviation of a gyro axis over the window, °/s (MEMS gyro noise is
    /// about 0.1 °/s at 100 Hz).
    pub gyro_std_dps: f64,
    /// The largest standard deviation of an accelerometer axis, m/s² (noise about 0.03).
    pub acc_std_m_s2: f64,
    /// The largest mean rate over the window, °/s.
    pub gyro_mean_dps: f64,
    /// The shortest stretch, s.
    pub min_s: f64,
}

impl Default for StillOptions {
    fn default() -> Self {
        StillOptions {
            window_s: 0.5,
            gyro_std_dps: 0.6,
            acc_std_m_s2: 0.15,
            gyro_mean_dps: 5.0,
            min_s: 2.0,
        }
    }
}

/// A stretch of stillness: sample indices and their times, s.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Still {
    #[serde(skip)]
    pub samples: Range<usize>,
    pub start_s: f64,
    pub end_s: f64,
}

/// The stretches of stillness of a track, in time order.
pub fn still_stretches(inertial: &Track<ImuSample>, options: &StillOptions) -> Vec<Still> {
    let times = inertial.times_s();
    let values = inertial.values();
    let n = values.len();
    // Prefix sums of each channel and its square, for O(1) window statistics.
    let mut sum = vec![[0.0f64; 6]; n + 1];
    let mut sq = vec![[0.0f64; 6]; n + 1];
    for (i, s) in values.iter().enumerate() {
        let g = s.gyro_rad_s.map(f64::to_degrees);
        let ch = [
            g.x,
            g.y,
            g.z,
            s.accel_m_s2.x,
            s.accel_m_s2.y,
            s.accel_m_s2.z,
        ];
        for c in 0..6 {
            sum[i + 1][c] = sum[i][c] + ch[c];
            sq[i + 1][c] = sq[i][c] + ch[c] * ch[c];
        }
    }
    let half = options.window_s / 2.0;
    let (mut lo, mut hi) = (0usize, 0usize);
    let mut still = vec![false; n];
    for i in 0..n {
        while times[lo] < times[i] - half {
            lo += 1;
        }
        while hi < n && times[hi] <= times[i] + half {
            hi += 1;
        }
        let count = (hi - lo) as f64;
        if count < 3.0 {
            continue;
        }
        let mut ok = true;
        let mut mean_rate2 = 0.0;
        for c in 0..6 {
            let mean = (sum[hi][c] - sum[lo][c]) / count;
            let var = ((sq[hi][c] - sq[lo][c]) / count - mean * mean).max(0.0);
            let limit = if c < 3 {
                mean_rate2 += mean * mean;
                options.gyro_std_dps
            } else {
                options.acc_std_m_s2
            };
            ok &= var.sqrt() < limit;
        }
        still[i] = ok && mean_rate2.sqrt() < options.gyro_mean_dps;
    }
    let mut out = Vec::new();
    let mut i = 0;
    while i < n {
        if !still[i] {
            i += 1;
            continue;
        }
        let start = i;
        while i < n && still[i] {
            i += 1;
        }
        if times[i - 1] - times[start] >= options.min_s {
            out.push(Still {
                samples: start..i,
                start_s: times[start],
                end_s: times[i - 1],
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// 10 s at 100 Hz: still with a 3 °/s bias for 3 s, a steady 20 °/s turn about the vertical
    /// for 3 s, shaken for 1 s, still for 3 s.
    #[test]
    fn finds_rest_despite_a_bias_and_not_in_a_steady_turn() {
        let bias = Vector3::new(3f64.to_radians(), 0.0, 0.0);
        let samples: Vec<ImuSample> = (0..1000)
            .map(|i| {
                let t = i as f64 / 100.0;
                let wobble = 0.02 * ((i * 7919) % 13) as f64 / 13.0; // small noise
                let (gyr, acc) = if !(3.0..7.0).contains(&t) {
                    (bias, Vector3::new(wobble, 0.0, 9.81))
                } else if t < 6.0 {
                    (
                        bias + Vector3::new(0.0, 0.0, 20f64.to_radians()),
                        Vector3::new(0.0, 0.0, 9.81),
                    )
                } else {
                    let s = (t * 40.0).sin();
                    (
                        bias + Vector3::new(s, 0.0, 0.0),
                        Vector3::new(3.0 * s, 0.0, 9.81),
                    )
                };
                ImuSample {
                    gyro_rad_s: gyr,
                    accel_m_s2: acc,
                }
            })
            .collect();
        let times = (0..1000).map(|i| i as f64 / 100.0).collect();
        let track = Track::new(times, samples).unwrap();
        let found = still_stretches(&track, &StillOptions::default());
        assert_eq!(found.len(), 2, "{found:?}");
        // The window reaches 0.25 s into the motion on each side.
        assert!(
            found[0].start_s == 0.0 && (found[0].end_s - 2.75).abs() < 0.02,
            "{found:?}"
        );
        assert!(
            (found[1].start_s - 7.25).abs() < 0.02 && found[1].end_s == 9.99,
            "{found:?}"
        );
    }
}
