//! Accelerometer offset and scale from static positions.
//!
//! Still, an accelerometer reads gravity alone: with per-axis offset `o` and scale `s`, the
//! corrected reading `â = diag(s)·(x − o)` has norm g (9.80665 m/s²) in every position. Writing
//! `A x² + B y² + C z² + D x + E y + F z = 1` over the positions' mean readings is linear in
//! (A…F) (least squares); completing the squares, `o = (−D/2A, −E/2B, −F/2C)` and
//! `s_i² = A_i g² / K` with `K = 1 + D²/4A + E²/4B + F²/4C`. Six positions — each axis up, then
//! down — determine it well; more only help.

use super::IntrinsicsError;
use super::still::{StillOptions, still_stretches};
use crate::take::{ImuSample, Track};
use nalgebra::{DMatrix, DVector, Vector3};
use serde::{Deserialize, Serialize};

/// Standard gravity, m/s²: the norm a corrected still reading has.
pub const STANDARD_GRAVITY_M_S2: f64 = 9.80665;

/// An accelerometer's correction `â = diag(s)·(x − o)` and the fit's quality.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AccCalibration {
    /// `o`, m/s².
    pub offset_m_s2: [f64; 3],
    /// `s`, per axis.
    pub scale: [f64; 3],
    /// The still positions used.
    pub positions: usize,
    /// RMS of `|x| − g` over the positions before, and of `|â| − g` after, m/s².
    pub residual_before_m_s2: f64,
    pub residual_after_m_s2: f64,
}

impl AccCalibration {
    pub fn correct(&self, x: &Vector3<f64>) -> Vector3<f64> {
        (x - Vector3::from(self.offset_m_s2)).component_mul(&Vector3::from(self.scale))
    }
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    (sum / n.max(1) as f64).sqrt()
}

/// The offset and scale from the mean readings of still positions.
pub fn fit_positions(
    sensor: &str,
    means: &[Vector3<f64>],
) -> Result<AccCalibration, IntrinsicsError> {
    const RECORD: &str =
        "record six positions held still for 3 s each: each axis pointing up, then down";
    // Each axis up and down: some position within 45° of each.
    let mut missing = Vec::new();
    for (axis, name) in ["x", "y", "z"].iter().enumerate() {
        for (sign, word) in [(1.0, "up"), (-1.0, "down")] {
            if !means
                .iter()
                .any(|m| sign * m[axis] > m.norm() * std::f64::consts::FRAC_1_SQRT_2)
            {
                missing.push(format!("{name} {word}"));
            }
        }
    }
    if means.len() < 6 || !missing.is_empty() {
        return Err(IntrinsicsError::Positions {
            sensor: sensor.to_string(),
            found: means.len(),
            missing: missing.join(", "),
            record: RECORD,
        });
    }
    let a = DMatrix::from_fn(means.len(), 6, |r, c| {
        let m = means[r];
        if c < 3 { m[c] * m[c] } else { m[c - 3] }
    });
    let b = DVector::from_element(means.len(), 1.0);
    let x = a
        .svd(true, true)
        .solve(&b, 1e-12)
        .map_err(|_| IntrinsicsError::Implausible {
            sensor: sensor.to_string(),
            what: "the positions do not determine the accelerometer's scale".into(),
            record: RECORD,
        })?;
    let k = 1.0
        + (0..3)
            .map(|i| x[i + 3] * x[i + 3] / (4.0 * x[i]))
            .sum::<f64>();
    let offset = Vector3::from_fn(|i, _| -x[i + 3] / (2.0 * x[i]));
    let scale2 = Vector3::from_fn(|i, _| x[i] * STANDARD_GRAVITY_M_S2.powi(2) / k);
    if scale2.iter().any(|s| !(*s > 0.25 && *s < 4.0)) {
        return Err(IntrinsicsError::Implausible {
            sensor: sensor.to_string(),
            what: format!("the fitted scales² {scale2:?} are not near 1"),
            record: RECORD,
        });
    }
    let cal = AccCalibration {
        offset_m_s2: offset.into(),
        scale: scale2.map(f64::sqrt).into(),
        positions: means.len(),
        residual_before_m_s2: rms(means.iter().map(|m| m.norm() - STANDARD_GRAVITY_M_S2)),
        residual_after_m_s2: 0.0,
    };
    let after = rms(means
        .iter()
        .map(|m| cal.correct(m).norm() - STANDARD_GRAVITY_M_S2));
    Ok(AccCalibration {
        residual_after_m_s2: after,
        ..cal
    })
}

/// The offset and scale from a take's still positions ([`still_stretches`]).
pub fn calibrate_accelerometer(
    sensor: &str,
    inertial: &Track<ImuSample>,
    still: &StillOptions,
) -> Result<AccCalibration, IntrinsicsError> {
    let means: Vec<Vector3<f64>> = still_stretches(inertial, still)
        .iter()
        .map(|s| {
            let v = &inertial.values()[s.samples.clone()];
            v.iter().map(|x| x.accel_m_s2).sum::<Vector3<f64>>() / v.len() as f64
        })
        .collect();
    fit_positions(sensor, &means)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn six_positions_give_offset_and_scale() {
        let o = Vector3::new(0.2, -0.15, 0.3);
        let s = Vector3::new(1.02, 0.97, 1.01);
        let g = STANDARD_GRAVITY_M_S2;
        // Readings x = â / s + o for â = ±g along each axis, and one tilted position.
        let mut truths: Vec<Vector3<f64>> = (0..6)
            .map(|i| {
                let mut v = Vector3::zeros();
                v[i / 2] = if i % 2 == 0 { g } else { -g };
                v
            })
            .collect();
        truths.push(Vector3::new(1.0, 1.0, 1.0).normalize() * g);
        let means: Vec<_> = truths.iter().map(|a| a.component_div(&s) + o).collect();
        let cal = fit_positions("s", &means).unwrap();
        assert!(
            (Vector3::from(cal.offset_m_s2) - o).amax() < 1e-9,
            "{cal:?}"
        );
        assert!((Vector3::from(cal.scale) - s).amax() < 1e-9, "{cal:?}");
        assert!(cal.residual_after_m_s2 < 1e-9 && cal.residual_before_m_s2 > 0.1);
        // Five positions, z never down.
        let e = fit_positions("foot", &means[..5]).unwrap_err().to_string();
        assert!(e.contains("sensor `foot`") && e.contains("z down"), "{e}");
    }
}
