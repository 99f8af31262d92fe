//! Paper 004's gyroscope gain and axis misalignment (its eq. 6–13), from whole turns.
//!
//! Taking the sensor's x axis as the reference x and its y axis in the reference xy plane, the
//! true rate `ω` follows from the bias-free readings `x` by a lower-triangular matrix
//!
//! `ω = G·x`, `G = [[a, 0, 0], [b, c, 0], [d, e, f]]` (eq. 7).
//!
//! For a rotation about a fixed axis, `|ω| = |G x|` at every instant, and integrating, the
//! readings' integral `X = ∫ x dt` over a rotation of `k` whole turns satisfies `|G X| = 2πk`:
//!
//! `X²α + Y²β + Z²γ + 2XYδ + 2XZε + 2YZζ = (2πk)²` (eq. 10, 12),
//!
//! with `α = a² + b² + d²`, `β = c² + e²`, `γ = f²`, `δ = bc + de`, `ε = df`, `ζ = ef` (eq. 11 —
//! the paper prints `α = a² + b² + c²`, a typo: expanding eq. 9 gives `d²`, not `c²`; `GᵀG` has
//! exactly these six entries). Six or more rotations about different axes give the six unknowns
//! by least squares, and then (eq. 13, with the same correction)
//!
//! `f = √γ, d = ε/f, e = ζ/f, c = √(β − e²), b = (δ − de)/c, a = √(α − b² − d²)`.
//!
//! The rotations are found in the take: the motion between two stretches of stillness is one
//! rotation, integrated (trapezoids) from the middle of the stillness before to the middle of
//! the one after, with the bias the mean of the two stretches' readings. A rotation whose
//! readings do not keep one direction (`|X| < 0.98 ∫|x|dt`) or that is not close to a whole
//! number of turns (off by more than 0.2 turn) is left out with a note.

use super::IntrinsicsError;
use super::still::{Still, StillOptions, still_stretches};
use crate::take::{ImuSample, Track};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// One rotation of the calibration take.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rotation {
    pub start_s: f64,
    pub end_s: f64,
    /// Whole turns.
    pub turns: u32,
    /// The readings' integral's direction (sensor frame).
    pub axis: [f64; 3],
}

/// `G` and the fit's quality.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GyroGain {
    /// `G`, rows: `ω = G·(x − bias)`.
    pub matrix: [[f64; 3]; 3],
    pub rotations: Vec<Rotation>,
    /// RMS over the rotations of `|G X|/(2πk) − 1` with `G` = I, and with the fitted `G`, %.
    pub residual_before_pct: f64,
    pub residual_after_pct: f64,
    /// The least-squares system's condition number (rows scaled by `(2πk)²`): large when the
    /// axes turned about were too alike.
    pub condition: f64,
}

impl GyroGain {
    pub fn matrix(&self) -> Matrix3<f64> {
        let g = self.matrix;
        Matrix3::from_fn(|r, c| g[r][c])
    }
}

/// The largest condition number accepted: turning about x, y and z alone gives hundreds (the
/// cross terms are then seen only through the small misalignments); adding the three diagonals
/// between the axes gives under 10.
pub const MAX_CONDITION: f64 = 50.0;

/// `G` from integrated readings `X_k` and their whole turns `k` (eq. 12, 13).
pub fn fit_turns(
    sensor: &str,
    integrals: &[(Vector3<f64>, u32)],
) -> Result<(Matrix3<f64>, f64), IntrinsicsError> {
    const RECORD: &str = "record six or more rotations of whole turns, each about a different axis (x, y, z and \
                          the diagonals between them), with the sensor held still for 2 s between them";
    if integrals.len() < 6 {
        return Err(IntrinsicsError::TooFew {
            sensor: sensor.to_string(),
            what: "whole-turn rotations".into(),
            found: integrals.len(),
            needed: 6,
            record: RECORD,
        });
    }
    let rows = integrals.len();
    let a = DMatrix::from_fn(rows, 6, |r, c| {
        let (v, k) = integrals[r];
        let (x, y, z) = (v.x, v.y, v.z);
        let scale = (TAU * k as f64).powi(2);
        [x * x, y * y, z * z, 2.0 * x * y, 2.0 * x * z, 2.0 * y * z][c] / scale
    });
    let b = DVector::from_element(rows, 1.0);
    let svd = a.clone().svd(true, true);
    let (s_max, s_min) = (svd.singular_values.max(), svd.singular_values.min());
    let condition = if s_min > 0.0 {
        s_max / s_min
    } else {
        f64::INFINITY
    };
    if condition > MAX_CONDITION {
        return Err(IntrinsicsError::Implausible {
            sensor: sensor.to_string(),
            what: format!(
                "the rotations' axes are too alike to separate gain from misalignment (condition {condition:.0}, \
                 at most {MAX_CONDITION:.0})"
            ),
            record: RECORD,
        });
    }
    let p = svd.solve(&b, 1e-12).expect("U and V were computed");
    let (alpha, beta, gamma, delta, epsilon, zeta) = (p[0], p[1], p[2], p[3], p[4], p[5]);
    let implausible = || IntrinsicsError::Implausible {
        sensor: sensor.to_string(),
        what: "the rotations give no real gain matrix (eq. 13 takes the root of a negative number)"
            .into(),
        record: RECORD,
    };
    let f = gamma.sqrt();
    let d = epsilon / f;
    let e = zeta / f;
    let c = (beta - e * e).sqrt();
    let bb = (delta - d * e) / c;
    let aa = (alpha - bb * bb - d * d).sqrt();
    let g = Matrix3::new(aa, 0.0, 0.0, bb, c, 0.0, d, e, f);
    if !g.iter().all(|v| v.is_finite()) || [aa, c, f].iter().any(|x| !(0.5..2.0).contains(x)) {
        return Err(implausible());
    }
    Ok((g, condition))
}

/// RMS of `|M X|/(2πk) − 1`, %.
fn turn_residual_pct(m: &Matrix3<f64>, integrals: &[(Vector3<f64>, u32)]) -> f64 {
    let ms = integrals
        .iter()
        .map(|(v, k)| ((m * v).norm() / (TAU * *k as f64) - 1.0).powi(2))
        .sum::<f64>()
        / integrals.len() as f64;
    100.0 * ms.sqrt()
}

/// Paper 004's calibration from a take of whole-turn rotations between stretches of stillness
/// (of at least 1 s, or `still.min_s` when shorter).
/// `notes` gets a line for each rotation left out.
pub fn calibrate_gyro_gain(
    sensor: &str,
    inertial: &Track<ImuSample>,
    still: &StillOptions,
    notes: &mut Vec<String>,
) -> Result<GyroGain, IntrinsicsError> {
    let times = inertial.times_s();
    let values = inertial.values();
    // Stillness only separates rotations here: a second of it is enough (a 2 s pause is seen as
    // 1.5 s, the window's half width cut at each end).
    let options = StillOptions {
        min_s: still.min_s.min(1.0),
        ..*still
    };
    let stretches: Vec<Still> = still_stretches(inertial, &options);
    let mean_gyro = |s: &Still| {
        values[s.samples.clone()]
            .iter()
            .map(|v| v.gyro_rad_s)
            .sum::<Vector3<f64>>()
            / s.samples.len() as f64
    };
    let mut integrals = Vec::new();
    let mut rotations = Vec::new();
    for pair in stretches.windows(2) {
        let (before, after) = (&pair[0], &pair[1]);
        let bias = (mean_gyro(before) + mean_gyro(after)) / 2.0;
        let from = (before.samples.start + before.samples.end) / 2;
        let to = (after.samples.start + after.samples.end) / 2;
        let (mut integral, mut path) = (Vector3::zeros(), 0.0);
        for i in from..to {
            let dt = times[i + 1] - times[i];
            let w = (values[i].gyro_rad_s + values[i + 1].gyro_rad_s) / 2.0 - bias;
            integral += w * dt;
            path += w.norm() * dt;
        }
        let turns_exact = integral.norm() / TAU;
        let turns = turns_exact.round();
        let (start_s, end_s) = (times[before.samples.end - 1], times[after.samples.start]);
        if turns_exact < 0.5 {
            continue; // a bump between two stillnesses, not a rotation
        }
        if integral.norm() < 0.98 * path {
            notes.push(format!(
                "sensor `{sensor}`: the motion from {start_s:.2} s to {end_s:.2} s did not keep one axis; left out"
            ));
            continue;
        }
        if (turns_exact - turns).abs() > 0.2 {
            notes.push(format!(
                "sensor `{sensor}`: the rotation from {start_s:.2} s to {end_s:.2} s is {turns_exact:.2} turns, not a \
                 whole number; left out"
            ));
            continue;
        }
        integrals.push((integral, turns as u32));
        rotations.push(Rotation {
            start_s,
            end_s,
            turns: turns as u32,
            axis: integral.normalize().into(),
        });
    }
    let (g, condition) = fit_turns(sensor, &integrals)?;
    Ok(GyroGain {
        matrix: std::array::from_fn(|r| std::array::from_fn(|c| g[(r, c)])),
        residual_before_pct: turn_residual_pct(&Matrix3::identity(), &integrals),
        residual_after_pct: turn_residual_pct(&g, &integrals),
        rotations,
        condition,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn six_axes_recover_a_triangular_gain() {
        let g = Matrix3::new(1.02, 0.0, 0.0, 0.015, 0.97, 0.0, -0.01, 0.02, 1.01);
        let m = g.try_inverse().unwrap(); // readings = M ω
        let axes = [
            Vector3::x(),
            Vector3::y(),
            Vector3::z(),
            Vector3::new(1.0, 1.0, 0.0),
            Vector3::new(1.0, 0.0, 1.0),
            Vector3::new(0.0, 1.0, -1.0),
            Vector3::new(1.0, -1.0, 1.0),
        ];
        let integrals: Vec<(Vector3<f64>, u32)> = axes
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let k = 1 + i as u32 % 3;
                (m * a.normalize() * TAU * k as f64, k)
            })
            .collect();
        let (fit, condition) = fit_turns("s", &integrals).unwrap();
        assert!((fit - g).amax() < 1e-9, "{fit}");
        assert!(condition < 10.0, "{condition}");
        // x, y and z alone cannot separate the cross terms.
        let alike: Vec<_> = (0..6).map(|i| integrals[i % 3]).collect();
        let e = fit_turns("s", &alike).unwrap_err().to_string();
        assert!(e.contains("too alike") && e.contains("diagonals"), "{e}");
    }
}
