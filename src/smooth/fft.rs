//! Frequency-domain smoothing (paper 002, sections 6.6.3 and 7.4.4), reproducing NumPy.
//!
//! The series is transformed with a real FFT; every bin whose magnitude is at least
//! `threshold × (largest magnitude)` keeps its value and every other bin is multiplied by
//! `suppress` (the paper: threshold 50 %, the rest kept at 30 %); optionally, bins above a cutoff
//! frequency are zeroed (a plain brick-wall low-pass); the inverse FFT gives a series of the same
//! length (odd and even lengths alike). With [`DcBin::Included`] this is exactly
//!
//! ```text
//! X = np.fft.rfft(x); mag = np.abs(X)
//! Y = np.where(mag >= threshold * mag.max(), X, X * suppress)
//! Y[np.fft.rfftfreq(n, 1 / fs) > cutoff] = 0          # only when a cutoff is set
//! y = np.fft.irfft(Y, n=n)
//! ```
//!
//! ## The DC bin
//!
//! [`fft_filter`] uses [`DcBin::Excluded`]: the DC bin (the series' mean times `n`) is left out
//! of "the largest magnitude" and is always kept unchanged; the threshold is relative to the
//! strongest *oscillation*. The paper's data are angles (or their cosines and sines) with a large
//! mean: with the mean included, the DC bin is usually the largest by far, so every genuine
//! motion component falls below 50 % of it and is shrunk to 30 % — the filter would flatten the
//! motion towards its mean instead of removing the weak, spread-out noise the paper describes
//! ("the actual signal should belong to the most dominating frequency levels"). Leaving DC out
//! also makes the result independent of the offset of the angle convention (adding a constant
//! to the series adds the same constant to the output). In NumPy terms, `Excluded` is
//! `Y = np.where(mag >= threshold * mag[1:].max(), X, X * suppress); Y[0] = X[0]` (for `n == 1`
//! there is nothing to threshold). [`fft_filter_with_dc`] with
//! [`DcBin::Included`] gives the literal NumPy expression above (DC competes like any bin, and is
//! suppressed if it is weak).
//!
//! The threshold is evaluated on the whole spectrum, before the cutoff zeroes anything.
//!
//! Units: `sample_rate_hz` and `cutoff_hz` in hertz; bin `k` of an `n`-sample series lies at
//! `k · fs / n` Hz (computed as NumPy's `rfftfreq` does).
//!
//! Edge cases (none panics): an empty series gives an empty output; a series containing NaN or
//! an infinity is returned unchanged (the FFT would spread it over every sample); a NaN
//! threshold suppresses every bin and a NaN cutoff zeroes none (NumPy's comparisons); a negative
//! cutoff zeroes every bin, including DC. Finite series whose sums approach `f64::MAX` may
//! overflow in the transform.

use realfft::RealFftPlanner;
use realfft::num_complex::Complex64;

/// Settings of [`fft_filter`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FftOptions {
    /// Bins with magnitude ≥ `threshold ×` the largest magnitude are kept; `None` disables the
    /// thresholding (only the cutoff, if any, applies). Default 0.5 (the paper).
    pub threshold: Option<f64>,
    /// Factor applied to the bins below the threshold (0 discards them). Default 0.3 (the paper).
    pub suppress: f64,
    /// Bins strictly above this frequency (Hz) are zeroed. Default `None`.
    pub cutoff_hz: Option<f64>,
}

/// Whether the DC bin takes part in "the largest magnitude" and in the thresholding (see the
/// module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DcBin {
    /// DC is left out of the maximum and always kept unchanged (what [`fft_filter`] does).
    #[default]
    Excluded,
    /// DC is an ordinary bin: `np.where(mag >= threshold * mag.max(), X, X * suppress)`.
    Included,
}

impl Default for FftOptions {
    fn default() -> Self {
        Self {
            threshold: Some(0.5),
            suppress: 0.3,
            cutoff_hz: None,
        }
    }
}

/// Frequency-domain filter of a uniformly sampled series (see the module documentation), with
/// the DC bin excluded from the thresholding ([`DcBin::Excluded`]).
pub fn fft_filter(x: &[f64], sample_rate_hz: f64, options: &FftOptions) -> Vec<f64> {
    fft_filter_with_dc(x, sample_rate_hz, options, DcBin::Excluded)
}

/// [`fft_filter`] with an explicit choice for the DC bin.
pub fn fft_filter_with_dc(
    x: &[f64],
    sample_rate_hz: f64,
    options: &FftOptions,
    dc: DcBin,
) -> Vec<f64> {
    let n = x.len();
    if n == 0 || x.iter().any(|v| !v.is_finite()) {
        return x.to_vec();
    }
    let mut planner = RealFftPlanner::<f64>::new();
    let forward = planner.plan_fft_forward(n);
    let inverse = planner.plan_fft_inverse(n);

    let mut input = x.to_vec();
    let mut spectrum = forward.make_output_vec();
    if forward.process(&mut input, &mut spectrum).is_err() {
        return x.to_vec();
    }

    if let Some(threshold) = options.threshold {
        let first = usize::from(dc == DcBin::Excluded);
        let max = spectrum[first..]
            .iter()
            .map(|c| c.norm())
            .fold(f64::NEG_INFINITY, f64::max);
        let limit = threshold * max;
        for c in &mut spectrum[first..] {
            // NumPy: np.where(mag >= limit, X, X * suppress); NaN compares false.
            let keep = c.norm() >= limit;
            if !keep {
                *c = Complex64::new(c.re * options.suppress, c.im * options.suppress);
            }
        }
    }

    if let Some(cutoff) = options.cutoff_hz {
        // np.fft.rfftfreq(n, d): k * (1.0 / (n * d)), with d = 1 / fs.
        let d = 1.0 / sample_rate_hz;
        let val = 1.0 / (n as f64 * d);
        for (k, c) in spectrum.iter_mut().enumerate() {
            if k as f64 * val > cutoff {
                *c = Complex64::new(0.0, 0.0);
            }
        }
    }

    // irfft ignores the imaginary parts of the DC bin and (even n) the Nyquist bin.
    spectrum[0].im = 0.0;
    if n.is_multiple_of(2) {
        spectrum[n / 2].im = 0.0;
    }
    let mut output = inverse.make_output_vec();
    if inverse.process(&mut spectrum, &mut output).is_err() {
        return x.to_vec();
    }
    let scale = 1.0 / n as f64;
    output.iter().map(|v| v * scale).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn variants() -> Vec<(FftOptions, DcBin)> {
        let base = FftOptions::default();
        vec![
            (base, DcBin::Excluded),
            (base, DcBin::Included),
            (
                FftOptions {
                    threshold: None,
                    cutoff_hz: Some(10.0),
                    ..base
                },
                DcBin::Excluded,
            ),
            (
                FftOptions {
                    threshold: Some(0.2),
                    suppress: 0.0,
                    cutoff_hz: Some(20.0),
                },
                DcBin::Included,
            ),
        ]
    }

    #[test]
    fn dc_passes_unchanged() {
        for len in [1, 2, 3, 8, 101, 256] {
            for (options, dc) in variants() {
                let y = fft_filter_with_dc(&vec![4.5; len], 100.0, &options, dc);
                assert!(
                    y.iter().all(|v| (v - 4.5).abs() < 1e-12),
                    "{len} {options:?} {dc:?}: {y:?}"
                );
            }
        }
    }

    #[test]
    fn nyquist_alternation_is_removed_by_the_cutoff() {
        for len in [64, 65] {
            let x: Vec<f64> = (0..len)
                .map(|i| 2.0 + (0.3 * i as f64).sin() + if i % 2 == 0 { 1.0 } else { -1.0 })
                .collect();
            let options = FftOptions {
                threshold: None,
                cutoff_hz: Some(20.0),
                ..FftOptions::default()
            };
            let y = fft_filter(&x, 100.0, &options);
            // Nothing above 20 Hz is left: compare with the same series without alternation.
            let smooth: Vec<f64> = (0..len).map(|i| 2.0 + (0.3 * i as f64).sin()).collect();
            let reference = fft_filter(&smooth, 100.0, &options);
            if len % 2 == 0 {
                // Even length: the alternation is exactly the Nyquist bin, which is zeroed.
                assert!(y.iter().zip(&reference).all(|(a, b)| (a - b).abs() < 1e-12));
            }
            // The mean is untouched whatever the length.
            let mean_in: f64 = x.iter().sum::<f64>() / len as f64;
            let mean_out: f64 = y.iter().sum::<f64>() / len as f64;
            assert!((mean_in - mean_out).abs() < 1e-12);
        }
    }

    #[test]
    fn dc_exclusion_keeps_the_offset_out_of_the_threshold() {
        // A dominant oscillation on a large offset: with DC excluded the oscillation is kept.
        let x: Vec<f64> = (0..100)
            .map(|i| 50.0 + (2.0 * std::f64::consts::PI * 5.0 * i as f64 / 100.0).sin())
            .collect();
        let y = fft_filter(&x, 100.0, &FftOptions::default());
        assert!(x.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-9));
        // With DC included, the oscillation is below half of DC and shrinks to 30 %.
        let y = fft_filter_with_dc(&x, 100.0, &FftOptions::default(), DcBin::Included);
        assert!(
            x.iter()
                .zip(&y)
                .all(|(a, b)| ((a - 50.0) * 0.3 - (b - 50.0)).abs() < 1e-9)
        );
    }

    #[test]
    fn non_finite_series_is_returned_unchanged() {
        let x = [1.0, f64::NAN, 3.0];
        let y = fft_filter(&x, 100.0, &FftOptions::default());
        assert_eq!(y[0], 1.0);
        assert!(y[1].is_nan());
        assert_eq!(y[2], 3.0);
        assert!(fft_filter(&[], 100.0, &FftOptions::default()).is_empty());
    }

    proptest! {
        #[test]
        fn never_panics_or_yields_nan(
            x in proptest::collection::vec(-1e6f64..1e6, 0..150),
            threshold in proptest::option::of(-0.5f64..1.5),
            suppress in -1.0f64..1.5,
            cutoff in proptest::option::of(-5.0f64..80.0),
            included: bool,
        ) {
            let options = FftOptions { threshold, suppress, cutoff_hz: cutoff };
            let dc = if included { DcBin::Included } else { DcBin::Excluded };
            let y = fft_filter_with_dc(&x, 100.0, &options, dc);
            prop_assert_eq!(y.len(), x.len());
            prop_assert!(y.iter().all(|v| v.is_finite()));
        }
    }
}
