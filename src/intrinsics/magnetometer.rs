//! Magnetometer hard and soft iron.
//!
//! A magnetometer turned through every direction in a steady field `m` (|m| = F) reads
//! `x = S·m + h`: `h` the hard iron (fields of magnetised parts that turn with the sensor, plus
//! the sensor's offset), `S` the soft iron (parts that bend the field, and the axes' gains and
//! cross-talk). The readings lie on the ellipsoid `(x − h)ᵀ S⁻ᵀS⁻¹ (x − h) = F²`, and the
//! correction is
//!
//! `m̂ = W·(x − h)`, `W` symmetric with det W = 1,
//!
//! which puts them on a sphere of radius [`MagCalibration::field_norm`]. Fusion only uses the
//! field's direction, so the overall scale is left alone (det W = 1); a symmetric `W` is the one
//! correction that does not also turn the sensor's axes.
//!
//! Two fits:
//! - [`MagFit::MinMax`], paper 000's: `h = (max + min)/2` per axis, `W = I`;
//! - [`MagFit::Ellipsoid`]: Li & Griffiths (2004), as magneto 1.4 and SlimeVR's firmware do. The
//!   quadric `a x² + b y² + c z² + 2f yz + 2g xz + 2h xy + 2p x + 2q y + 2r z + d = 0`, with
//!   `v = (a, b, c, f, g, h, p, q, r, d)` and each reading's row `D = (x², y², z², 2yz, 2xz, 2xy,
//!   2x, 2y, 2z, 1)`, minimises `vᵀ(Σ DDᵀ)v` under `4J − I² = 1` (`I = a + b + c`, `J = ab + bc +
//!   ac − f² − g² − h²`), the constraint that makes it an ellipsoid. With `Σ DDᵀ` split 6 + 4
//!   (`S11, S12, S22`) the first six unknowns solve `(S11 − S12 S22⁻¹ S21) v1 = λ C v1` (`C` the
//!   constraint's matrix) for the one positive λ, and `v2 = −S22⁻¹ S21 v1`. [`EllipsoidFit`] keeps
//!   only the 10×10 `Σ DDᵀ`, so it runs on a stream of any length. Then the centre
//!   `h = −Q⁻¹u` (`Q` the quadratic part, `u = (p, q, r)`), `N = Q / (hᵀQh − d)`, and
//!   `W = √N / det(√N)^{1/3}`, `F = det(√N)^{−1/3}`.
//!
//! The fit's quality: the corrected field's norm over the take (`residual_*_pct`: the RMS of
//! `|m̂|/mean|m̂| − 1`, before with `W = I, h = 0`), and how much of the sphere of directions the
//! readings covered ([`coverage`]).

use super::IntrinsicsError;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};

/// The fit to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MagFit {
    /// Hard iron only, from the readings' extremes (paper 000).
    MinMax,
    /// Hard and soft iron (Li & Griffiths).
    Ellipsoid,
}

impl std::str::FromStr for MagFit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "ellipsoid" => Ok(MagFit::Ellipsoid),
            "min-max" => Ok(MagFit::MinMax),
            _ => Err(format!(
                "unknown magnetometer fit `{s}`; expected ellipsoid or min-max"
            )),
        }
    }
}

/// A magnetometer's correction `m̂ = W·(x − h)` and the fit's quality. Units are the log's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MagCalibration {
    pub fit: MagFit,
    /// `h`, in the log's unit.
    pub hard_iron: [f64; 3],
    /// `W`, rows; symmetric, det 1 (the identity for min-max).
    pub soft_iron_correction: [[f64; 3]; 3],
    /// The corrected field's mean norm, in the log's unit.
    pub field_norm: f64,
    /// RMS of the field norm's relative deviation before and after correction, %.
    pub residual_before_pct: f64,
    pub residual_after_pct: f64,
    /// The same over the readings the fit kept (not set aside as disturbed), %.
    pub kept_residual_before_pct: f64,
    pub kept_residual_after_pct: f64,
    /// Share of the readings set aside as disturbed, %.
    pub set_aside_pct: f64,
    /// Share of the sphere of directions the corrected readings reached ([`coverage`]), %.
    pub coverage_pct: f64,
    pub samples: usize,
}

impl MagCalibration {
    pub fn matrix(&self) -> Matrix3<f64> {
        let w = self.soft_iron_correction;
        Matrix3::from_fn(|r, c| w[r][c])
    }

    /// `W·(x − h)`.
    pub fn correct(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.matrix() * (x - Vector3::from(self.hard_iron))
    }
}

/// The streaming ellipsoid fit: `Σ DDᵀ` over the readings pushed, in a unit set by the first
/// reading's norm so the sums stay well scaled.
#[derive(Debug, Clone)]
pub struct EllipsoidFit {
    normal: SMatrix<f64, 10, 10>,
    scale: Option<f64>,
    count: usize,
}

/// What an ellipsoid fit came to: the centre, `W` and `F` (the module's formulas).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    pub center: Vector3<f64>,
    pub correction: Matrix3<f64>,
    pub field_norm: f64,
}

impl Default for EllipsoidFit {
    fn default() -> Self {
        EllipsoidFit {
            normal: SMatrix::zeros(),
            scale: None,
            count: 0,
        }
    }
}

impl EllipsoidFit {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn count(&self) -> usize {
        self.count
    }

    /// Adds one reading.
    pub fn push(&mut self, x: &Vector3<f64>) {
        if !x.iter().all(|v| v.is_finite()) {
            return;
        }
        let scale = *self
            .scale
            .get_or_insert(if x.norm() > 0.0 { 1.0 / x.norm() } else { 1.0 });
        let [x, y, z] = [x.x * scale, x.y * scale, x.z * scale];
        let d = SVector::<f64, 10>::from([
            x * x,
            y * y,
            z * z,
            2.0 * y * z,
            2.0 * x * z,
            2.0 * x * y,
            2.0 * x,
            2.0 * y,
            2.0 * z,
            1.0,
        ]);
        self.normal += d * d.transpose();
        self.count += 1;
    }

    /// The ellipsoid, or `None` when the readings do not determine one (fewer than 10, all in a
    /// plane, or a best quadric that is not an ellipsoid).
    pub fn solve(&self) -> Option<Ellipsoid> {
        let scale = self.scale?;
        if self.count < 10 {
            return None;
        }
        let s = &self.normal;
        let s11 = s.fixed_view::<6, 6>(0, 0).into_owned();
        let s12 = s.fixed_view::<6, 4>(0, 6).into_owned();
        let s22 = s.fixed_view::<4, 4>(6, 6).into_owned();
        let s22_inv = s22.try_inverse()?;
        let a = s11 - s12 * s22_inv * s12.transpose();
        // A v = λ C v with A symmetric positive (semi)definite: with A = L Lᵀ and u = Lᵀ v,
        // (L⁻¹ C L⁻ᵀ) u = (1/λ) u, symmetric; the one positive λ is the largest 1/λ. A hair of
        // ridge keeps the Cholesky factor when the readings lie exactly on an ellipsoid (λ = 0).
        let ridge = a.trace() * 1e-13;
        let l = (a + SMatrix::<f64, 6, 6>::identity() * ridge)
            .cholesky()?
            .l();
        let l_inv = l.try_inverse()?;
        let mut c = SMatrix::<f64, 6, 6>::zeros();
        for i in 0..3 {
            for j in 0..3 {
                c[(i, j)] = if i == j { -1.0 } else { 1.0 };
            }
            c[(i + 3, i + 3)] = -4.0;
        }
        let m = l_inv * c * l_inv.transpose();
        let eig = m.symmetric_eigen();
        let (best, mu) = eig
            .eigenvalues
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))?;
        if *mu <= 0.0 {
            return None;
        }
        let v1 = l_inv.transpose() * eig.eigenvectors.column(best);
        let v2 = -s22_inv * s12.transpose() * v1;
        let q = Matrix3::new(
            v1[0], v1[5], v1[4], v1[5], v1[1], v1[3], v1[4], v1[3], v1[2],
        );
        let u = Vector3::new(v2[0], v2[1], v2[2]);
        let d = v2[3];
        let center = -q.try_inverse()? * u;
        let k = center.dot(&(q * center)) - d;
        let n = q / k;
        // An ellipsoid: N positive definite (the sign of v is arbitrary; k carries it).
        let e = n.symmetric_eigen();
        if e.eigenvalues.iter().any(|l| *l <= 0.0 || !l.is_finite()) {
            return None;
        }
        let sqrt_n = e.eigenvectors
            * Matrix3::from_diagonal(&e.eigenvalues.map(f64::sqrt))
            * e.eigenvectors.transpose();
        let det = sqrt_n.determinant();
        let cube = det.cbrt();
        Some(Ellipsoid {
            center: center / scale,
            correction: sqrt_n / cube,
            field_norm: 1.0 / (cube * scale),
        })
    }
}

/// The ellipsoid fit twice more without the readings whose corrected norm is off the median by
/// more than 3 robust standard deviations (1.4826 · the median absolute deviation, at least
/// 1 %): a magnet passing by, a steel desk, leave the fit alone.
fn robust_ellipsoid(xs: &[Vector3<f64>]) -> Option<(Ellipsoid, Vec<bool>)> {
    let mut fit = EllipsoidFit::new();
    xs.iter().for_each(|x| fit.push(x));
    let mut e = fit.solve()?;
    let mut kept = vec![true; xs.len()];
    for _ in 0..2 {
        let k = inliers(xs, &e.center, &e.correction);
        let mut refit = EllipsoidFit::new();
        xs.iter()
            .zip(&k)
            .filter(|(_, k)| **k)
            .for_each(|(x, _)| refit.push(x));
        match refit.solve() {
            Some(better) => (e, kept) = (better, k),
            None => break,
        }
    }
    Some((e, kept))
}

/// The readings whose corrected norm is within 3 robust standard deviations of the median.
fn inliers(xs: &[Vector3<f64>], center: &Vector3<f64>, w: &Matrix3<f64>) -> Vec<bool> {
    let norms: Vec<f64> = xs.iter().map(|x| (w * (x - center)).norm()).collect();
    let median = crate::fusion::median(norms.clone());
    let mad = crate::fusion::median(norms.iter().map(|n| (n - median).abs()).collect());
    let limit = (3.0 * 1.4826 * mad).max(0.01 * median);
    norms.iter().map(|n| (n - median).abs() <= limit).collect()
}

/// Cell centres spread evenly over the sphere (a Fibonacci lattice).
fn sphere_cells(n: usize) -> Vec<Vector3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            Vector3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// How many of the sphere's directions readings reached, %: the share of 100 equal cells (each
/// about 23° across) that at least one of `directions` (unit vectors) falls in. A sensor turned
/// about one axis only covers a band of about 10 %, a thorough figure-of-eight dance over 60 %.
pub fn coverage(directions: impl Iterator<Item = Vector3<f64>>) -> f64 {
    let cells = sphere_cells(100);
    let mut hit = [false; 100];
    for d in directions {
        let best = cells
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.dot(&d).total_cmp(&b.1.dot(&d)))
            .map_or(0, |(i, _)| i);
        hit[best] = true;
    }
    hit.iter().filter(|h| **h).count() as f64
}

/// RMS of `|x|/mean|x| − 1` over `xs`, %.
fn norm_residual_pct(xs: &[Vector3<f64>]) -> f64 {
    let norms: Vec<f64> = xs.iter().map(|x| x.norm()).collect();
    let mean = norms.iter().sum::<f64>() / norms.len() as f64;
    let ms = norms.iter().map(|n| (n / mean - 1.0).powi(2)).sum::<f64>() / norms.len() as f64;
    100.0 * ms.sqrt()
}

/// The smallest coverage an ellipsoid fit needs, %: below it the soft iron is guessed.
pub const MIN_COVERAGE_ELLIPSOID_PCT: f64 = 30.0;
/// How far each axis must have pointed along and against the field (the cosine): within 60° for
/// the ellipsoid, whose shape carries the rest; within 25° for min-max, whose extremes are only
/// the ellipsoid's when they were reached.
const MIN_AXIS_REACH_ELLIPSOID: f64 = 0.5;
const MIN_AXIS_REACH_MIN_MAX: f64 = 0.9;

/// Calibrates `sensor`'s magnetometer from readings `xs` (a take in which it was turned through
/// every direction). Errors name the sensor and what to record: too few readings, an axis never
/// turned along and against the field, too little of the sphere covered for an ellipsoid, or a
/// fit that is not plausible (axes' gains more than 2:1 apart, a centre further than 10 field
/// norms).
pub fn calibrate_magnetometer(
    sensor: &str,
    xs: &[Vector3<f64>],
    fit: MagFit,
) -> Result<MagCalibration, IntrinsicsError> {
    const RECORD: &str = "record the sensor turned slowly through every direction (figures of eight, each face up \
                          and down), away from metal";
    let xs: Vec<Vector3<f64>> = xs
        .iter()
        .copied()
        .filter(|x| x.iter().all(|v| v.is_finite()))
        .collect();
    if xs.len() < 50 {
        return Err(IntrinsicsError::TooFew {
            sensor: sensor.to_string(),
            what: "magnetometer readings".into(),
            found: xs.len(),
            needed: 50,
            record: RECORD,
        });
    }
    let (mut lo, mut hi) = (xs[0], xs[0]);
    for x in &xs {
        lo = lo.inf(x);
        hi = hi.sup(x);
    }
    let mid = (lo + hi) / 2.0;
    // Did each axis point along and against the field? (Judged from the min-max centre, before
    // any fit, so that a sensor that never turned cannot give a wild matrix.)
    let mut reach = [[0.0f64; 2]; 3];
    let mut directions = Vec::with_capacity(xs.len());
    for x in &xs {
        let d = (x - mid).try_normalize(1e-12).unwrap_or_else(Vector3::z);
        for axis in 0..3 {
            reach[axis][0] = reach[axis][0].max(d[axis]);
            reach[axis][1] = reach[axis][1].max(-d[axis]);
        }
        directions.push(d);
    }
    let rough_coverage = coverage(directions.into_iter());
    let min_reach = match fit {
        MagFit::Ellipsoid => MIN_AXIS_REACH_ELLIPSOID,
        MagFit::MinMax => MIN_AXIS_REACH_MIN_MAX,
    };
    if let Some(axis) = (0..3).find(|a| reach[*a][0] < min_reach || reach[*a][1] < min_reach) {
        return Err(IntrinsicsError::NotTurned {
            sensor: sensor.to_string(),
            axis: ["x", "y", "z"][axis],
            coverage_pct: rough_coverage,
            record: RECORD,
        });
    }
    let (center, w, field_norm) = match fit {
        MagFit::MinMax => {
            let f = xs.iter().map(|x| (x - mid).norm()).sum::<f64>() / xs.len() as f64;
            (mid, Matrix3::identity(), f)
        }
        MagFit::Ellipsoid => {
            if rough_coverage < MIN_COVERAGE_ELLIPSOID_PCT {
                return Err(IntrinsicsError::LowCoverage {
                    sensor: sensor.to_string(),
                    coverage_pct: rough_coverage,
                    needed_pct: MIN_COVERAGE_ELLIPSOID_PCT,
                    record: RECORD,
                });
            }
            let (e, _) = robust_ellipsoid(&xs).ok_or_else(|| IntrinsicsError::Implausible {
                sensor: sensor.to_string(),
                what: "the readings do not lie on an ellipsoid".into(),
                record: RECORD,
            })?;
            let gains = e.correction.symmetric_eigen().eigenvalues;
            let (g_lo, g_hi) = (gains.min(), gains.max());
            if g_hi / g_lo > 2.0 || e.center.norm() > 10.0 * e.field_norm {
                return Err(IntrinsicsError::Implausible {
                    sensor: sensor.to_string(),
                    what: format!(
                        "the fitted axes' gains are {:.2}:1 apart and its centre {:.1} field norms out",
                        g_hi / g_lo,
                        e.center.norm() / e.field_norm
                    ),
                    record: RECORD,
                });
            }
            (e.center, e.correction, e.field_norm)
        }
    };
    let corrected: Vec<Vector3<f64>> = xs.iter().map(|x| w * (x - center)).collect();
    let kept = inliers(&xs, &center, &w);
    let only_kept = |v: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
        v.iter()
            .zip(&kept)
            .filter(|(_, k)| **k)
            .map(|(m, _)| *m)
            .collect()
    };
    let kept_corrected = only_kept(&corrected);
    let coverage_pct = coverage(corrected.iter().map(|m| m.normalize()));
    Ok(MagCalibration {
        fit,
        hard_iron: center.into(),
        soft_iron_correction: std::array::from_fn(|r| std::array::from_fn(|c| w[(r, c)])),
        field_norm,
        residual_before_pct: norm_residual_pct(&xs),
        residual_after_pct: norm_residual_pct(&corrected),
        kept_residual_before_pct: norm_residual_pct(&only_kept(&xs)),
        kept_residual_after_pct: norm_residual_pct(&kept_corrected),
        set_aside_pct: 100.0 * (1.0 - kept_corrected.len() as f64 / xs.len() as f64),
        coverage_pct,
        samples: xs.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on the sphere of radius f, distorted by `s` and moved by `h`.
    fn readings(s: &Matrix3<f64>, h: &Vector3<f64>, f: f64, n: usize) -> Vec<Vector3<f64>> {
        sphere_cells(n).iter().map(|d| s * d * f + h).collect()
    }

    #[test]
    fn an_exact_ellipsoid_is_recovered() {
        let s = Matrix3::new(1.1, 0.05, -0.02, 0.05, 0.9, 0.03, -0.02, 0.03, 1.0);
        let h = Vector3::new(12.0, -30.0, 5.0);
        let xs = readings(&s, &h, 45.0, 500);
        let cal = calibrate_magnetometer("s", &xs, MagFit::Ellipsoid).unwrap();
        assert!((Vector3::from(cal.hard_iron) - h).norm() < 1e-6, "{cal:?}");
        // W ∝ S⁻¹ with det 1; F = 45 · det(S)^{1/3}.
        let s_inv = s.try_inverse().unwrap();
        let expected = s_inv / s_inv.determinant().cbrt();
        assert!((cal.matrix() - expected).amax() < 1e-6, "{cal:?}");
        assert!((cal.field_norm - 45.0 * s.determinant().cbrt()).abs() < 1e-6);
        assert!(
            cal.residual_after_pct < 1e-6 && cal.residual_before_pct > 3.0,
            "{cal:?}"
        );
        assert!(cal.coverage_pct > 99.0);
        // Min-max finds the centre of a sphere, not of a tilted ellipsoid.
        let mm = calibrate_magnetometer(
            "s",
            &readings(&Matrix3::identity(), &h, 45.0, 500),
            MagFit::MinMax,
        )
        .unwrap();
        assert!((Vector3::from(mm.hard_iron) - h).norm() < 0.5, "{mm:?}");
    }

    #[test]
    fn a_sensor_turned_about_one_axis_is_refused() {
        // A cone about the vertical (dip 60°): x and y turn, z never points against the field.
        let xs: Vec<Vector3<f64>> = (0..400)
            .map(|i| {
                let a = i as f64 * 0.05;
                Vector3::new(20.0 * a.cos(), 20.0 * a.sin(), -35.0)
            })
            .collect();
        for fit in [MagFit::Ellipsoid, MagFit::MinMax] {
            let e = calibrate_magnetometer("wrist", &xs, fit)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("sensor `wrist`") && e.contains("every direction"),
                "{e}"
            );
        }
        let e = calibrate_magnetometer("wrist", &xs[..20], MagFit::Ellipsoid)
            .unwrap_err()
            .to_string();
        assert!(e.contains("20") && e.contains("50"), "{e}");
    }
}
