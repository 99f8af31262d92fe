//! Gaussian smoothing, reproducing `scipy.ndimage.gaussian_filter1d(x, sigma, mode='reflect',
//! truncate=truncate)`.
//!
//! * The kernel has radius `int(truncate · sigma + 0.5)` samples (truncation toward zero) and
//!   weights `exp(−0.5 / sigma² · j²)` for `j = −radius..=radius`, normalised to sum 1 (the sum
//!   taken in NumPy's pairwise order).
//! * The series is extended by `'reflect'`, the half-sample symmetric extension
//!   `d c b a | a b c d | d c b a | a b c d …`, which repeats with period `2 len` when the
//!   radius exceeds the length.
//! * Each output is `w0 x[i] + Σ_{j = radius..1} w_j (x[i − j] + x[i + j])`, SciPy's order for
//!   symmetric kernels.
//!
//! Units: `sigma_samples` and the radius are in **samples**, not seconds; a caller with a
//! standard deviation in seconds multiplies it by the sample rate (Hz) first.
//!
//! Edge cases (none panics): an empty series gives an empty output; `sigma_samples` that is
//! zero, negative, NaN or infinite returns the input unchanged (SciPy would give NaN or raise);
//! a radius that rounds to 0 (including a negative or NaN `truncate`) returns the input
//! unchanged; the radius is capped at [`MAX_RADIUS`] samples (σ above about 260 000 samples at
//! the default truncation), beyond which the kernel is cut there and no longer matches SciPy.
//! Non-finite samples propagate to every output within the radius of them, as in SciPy.

/// SciPy's default truncation, in standard deviations.
pub const DEFAULT_TRUNCATE: f64 = 4.0;

/// Largest kernel radius used, in samples.
pub const MAX_RADIUS: usize = 1 << 20;

/// Settings of [`gaussian_filter1d`], for callers that keep them together.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussianOptions {
    /// Standard deviation of the kernel, samples.
    pub sigma_samples: f64,
    /// Truncation of the kernel, standard deviations (SciPy's default 4).
    pub truncate: f64,
}

impl Default for GaussianOptions {
    fn default() -> Self {
        Self {
            sigma_samples: 1.0,
            truncate: DEFAULT_TRUNCATE,
        }
    }
}

impl GaussianOptions {
    /// [`gaussian_filter1d`] with these settings.
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        gaussian_filter1d(x, self.sigma_samples, self.truncate)
    }
}

/// `scipy.ndimage.gaussian_filter1d(x, sigma_samples, mode='reflect', truncate=truncate)`.
pub fn gaussian_filter1d(x: &[f64], sigma_samples: f64, truncate: f64) -> Vec<f64> {
    let n = x.len();
    if n == 0 || !(sigma_samples.is_finite() && sigma_samples > 0.0) {
        return x.to_vec();
    }
    // Python's int() truncates toward zero; a NaN or negative value means no smoothing.
    let radius_f = (truncate * sigma_samples + 0.5).trunc();
    if radius_f.is_nan() || radius_f < 1.0 {
        return x.to_vec();
    }
    let radius = if radius_f >= MAX_RADIUS as f64 {
        MAX_RADIUS
    } else {
        radius_f as usize
    };
    let Some(w) = half_kernel(sigma_samples, radius) else {
        return x.to_vec();
    };

    if radius < n {
        // Direct form over a buffer extended by `radius` samples at each end.
        let mut ext = Vec::with_capacity(n + 2 * radius);
        ext.extend((0..radius).map(|i| x[reflect(i as isize - radius as isize, n)]));
        ext.extend_from_slice(x);
        ext.extend((0..radius).map(|i| x[reflect((n + i) as isize, n)]));
        (0..n)
            .map(|i| {
                let c = i + radius;
                let mut acc = ext[c] * w[0];
                for j in (1..=radius).rev() {
                    acc += (ext[c - j] + ext[c + j]) * w[j];
                }
                acc
            })
            .collect()
    } else {
        // The kernel is longer than a period (2n) of the reflected series: fold it onto one
        // period, so the cost is O(radius + n²) rather than O(n · radius).
        let period = 2 * n;
        let mut folded = vec![0.0; period];
        folded[0] = w[0];
        for (j, &wj) in w.iter().enumerate().skip(1) {
            folded[j % period] += wj;
            folded[(period - j % period) % period] += wj;
        }
        (0..n)
            .map(|i| {
                folded
                    .iter()
                    .enumerate()
                    .map(|(q, &wq)| wq * x[reflect((i + q) as isize, n)])
                    .sum()
            })
            .collect()
    }
}

/// Index into a series of length `n` of position `i` of its `'reflect'` extension.
fn reflect(i: isize, n: usize) -> usize {
    let period = 2 * n as isize;
    let m = i.rem_euclid(period) as usize;
    if m < n { m } else { 2 * n - 1 - m }
}

/// Weights `w[0..=radius]` of the normalised kernel (it is symmetric), as
/// `scipy.ndimage._filters._gaussian_kernel1d(sigma, 0, radius)` computes them.
fn half_kernel(sigma: f64, radius: usize) -> Option<Vec<f64>> {
    let sigma2 = sigma * sigma;
    let scale = -0.5 / sigma2;
    let phi: Vec<f64> = (0..=radius)
        .map(|j| {
            let j = j as f64;
            (scale * (j * j)).exp()
        })
        .collect();
    // phi_x.sum() over x = -radius..=radius, in NumPy's order: first element, then the
    // pairwise sum of the rest.
    let full: Vec<f64> = (0..=2 * radius).map(|k| phi[k.abs_diff(radius)]).collect();
    let total = full[0] + pairwise_sum(&full[1..]);
    if !(total.is_finite() && total > 0.0) {
        return None;
    }
    Some(phi.iter().map(|p| p / total).collect())
}

/// NumPy's `pairwise_sum_DOUBLE` (blocks of 128, unrolled by 8).
fn pairwise_sum(a: &[f64]) -> f64 {
    let n = a.len();
    if n < 8 {
        a.iter().fold(0.0, |acc, v| acc + v)
    } else if n <= 128 {
        let mut r = [0.0; 8];
        r.copy_from_slice(&a[..8]);
        let mut i = 8;
        while i < n - (n % 8) {
            for (k, rk) in r.iter_mut().enumerate() {
                *rk += a[i + k];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        while i < n {
            res += a[i];
            i += 1;
        }
        res
    } else {
        let mut n2 = n / 2;
        n2 -= n2 % 8;
        pairwise_sum(&a[..n2]) + pairwise_sum(&a[n2..])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn reflect_is_half_sample_symmetric() {
        let idx: Vec<usize> = (-8..12).map(|i| reflect(i, 4)).collect();
        assert_eq!(
            idx,
            [0, 1, 2, 3, 3, 2, 1, 0, 0, 1, 2, 3, 3, 2, 1, 0, 0, 1, 2, 3]
        );
        assert!((-5..5).all(|i| reflect(i, 1) == 0));
    }

    #[test]
    fn dc_passes_unchanged() {
        for len in [1, 2, 5, 40, 300] {
            for sigma in [0.3, 1.0, 2.5, 20.0] {
                let y = gaussian_filter1d(&vec![-7.5; len], sigma, DEFAULT_TRUNCATE);
                assert!(
                    y.iter().all(|v| (v + 7.5).abs() < 1e-12),
                    "{len} {sigma}: {y:?}"
                );
            }
        }
    }

    #[test]
    fn nyquist_alternation_is_removed() {
        let x: Vec<f64> = (0..200)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let y = gaussian_filter1d(&x, 2.0, DEFAULT_TRUNCATE);
        // The untruncated sampled Gaussian passes exp(-pi² sigma² / 2) ~ 3e-9 of Nyquist; the
        // cut at 4 sigma leaves about half the last weight, w[8] / 2 ~ 1.5e-5 (scipy gives the
        // same). The reflected ends (where the alternation breaks) are left out.
        assert!(
            y[10..190].iter().all(|v| v.abs() < 2e-5),
            "{:?}",
            &y[10..20]
        );
        let wide = gaussian_filter1d(&x, 2.0, 6.0);
        assert!(
            wide[15..185].iter().all(|v| v.abs() < 1e-8),
            "{:?}",
            &wide[15..25]
        );
    }

    #[test]
    fn degenerate_sigmas_return_the_input() {
        let x = [1.0, 4.0, -2.0, 8.0];
        for sigma in [0.0, -1.0, f64::NAN, f64::INFINITY, 0.1] {
            assert_eq!(gaussian_filter1d(&x, sigma, DEFAULT_TRUNCATE), x);
        }
        assert_eq!(gaussian_filter1d(&x, 1.0, -4.0), x);
        assert_eq!(gaussian_filter1d(&x, 1.0, f64::NAN), x);
        assert!(gaussian_filter1d(&[], 1.0, DEFAULT_TRUNCATE).is_empty());
    }

    #[test]
    fn folded_kernel_matches_direct_sum() {
        // Radius 12 > length 5: compare with a plain sum over the reflected extension.
        let x = [0.3, -1.2, 2.0, 0.7, -0.1];
        let sigma = 3.0;
        let radius = 12usize;
        let w = half_kernel(sigma, radius).unwrap();
        let y = gaussian_filter1d(&x, sigma, DEFAULT_TRUNCATE);
        for (i, yi) in y.iter().enumerate() {
            let mut acc = 0.0;
            for d in -(radius as isize)..=(radius as isize) {
                acc += w[d.unsigned_abs()] * x[reflect(i as isize + d, x.len())];
            }
            assert!((acc - yi).abs() < 1e-14);
        }
    }

    proptest! {
        #[test]
        fn never_panics_or_yields_nan(
            x in proptest::collection::vec(-1e6f64..1e6, 0..120),
            sigma in -1.0f64..40.0,
            truncate in -1.0f64..6.0,
        ) {
            let y = gaussian_filter1d(&x, sigma, truncate);
            prop_assert_eq!(y.len(), x.len());
            prop_assert!(y.iter().all(|v| v.is_finite()));
        }
    }
}
