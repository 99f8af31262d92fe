//! Butterworth low-pass filtering in second-order sections, reproducing SciPy.
//!
//! * [`design_lowpass_sos`] is `scipy.signal.butter(order, cutoff_hz, fs=sample_rate_hz,
//!   output='sos')`: the analog prototype's poles (`buttap`), the frequency pre-warping
//!   `warped = 4 tan(π Wn / 2)` with `Wn = cutoff / (fs / 2)` that `iirfilter` does, the
//!   low-pass scaling (`lp2lp_zpk`), the bilinear transform at `fs = 2` (`bilinear_zpk`) and
//!   the `'nearest'` pole–zero pairing of `zpk2sos`, so the coefficients themselves (not only
//!   the cascade's response) match SciPy's, section by section.
//! * [`sosfilt`] is `scipy.signal.sosfilt(sos, x)`: causal, transposed direct form II, zero
//!   initial state ([`sosfilt_with_state`] takes and returns the state, as `zi=` does).
//! * [`sosfilt_zi`] is `scipy.signal.sosfilt_zi(sos)`: the state of a unit-step steady state.
//! * [`sosfiltfilt`] is `scipy.signal.sosfiltfilt(sos, x)` with its defaults: odd extension by
//!   `padlen = 3 (2 len(sos) + 1 − min(#(b2 == 0), #(a2 == 0)))` samples at each end, a forward
//!   pass started from `zi · ext[0]` (the first sample of the *extended* series, as SciPy does,
//!   which is `2 x[0] − x[padlen]`), a backward pass started from `zi · y[-1]` (the last
//!   forward output), and the padding cut off again. Zero phase, squared magnitude response.
//!
//! Units: frequencies in hertz (cycles per second) and sample rates in samples per second; the
//! series are uniformly sampled and indexed by sample, so no timestamps are involved.
//!
//! Non-finite samples: [`sosfilt`] propagates them (every later output is affected, as in
//! SciPy); [`sosfiltfilt`] refuses them with [`FilterError::NonFinite`], because they would
//! poison the whole output. Finite series whose magnitude approaches `f64::MAX` may overflow in
//! the odd extension (`2 x[0] − x[k]`); signals in physical units are many orders away.

use realfft::num_complex::Complex64;

/// One second-order section, `[b0, b1, b2, a0, a1, a2]` with `a0 == 1`, as in SciPy.
pub type Sos = [f64; 6];

/// Largest filter order accepted by [`design_lowpass_sos`].
pub const MAX_ORDER: usize = 10;

/// Why a filter could not be designed or applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FilterError {
    /// The order is 0 or above [`MAX_ORDER`].
    #[error("Butterworth order {0} is outside 1..={MAX_ORDER}")]
    InvalidOrder(usize),
    /// The sample rate is not finite and positive.
    #[error("sample rate {0} Hz must be finite and positive")]
    InvalidSampleRate(f64),
    /// The cutoff is not strictly between 0 and the Nyquist frequency.
    #[error(
        "cutoff {cutoff_hz} Hz must lie strictly between 0 and {nyquist_hz} Hz (half the sample rate)"
    )]
    InvalidCutoff {
        /// The requested cutoff, Hz.
        cutoff_hz: f64,
        /// Half the sample rate, Hz.
        nyquist_hz: f64,
    },
    /// The series is too short for zero-phase filtering: SciPy's `sosfiltfilt` needs more
    /// samples than its padding length. `needed` is the minimum length (padlen + 1).
    #[error(
        "series of {got} samples is too short for zero-phase filtering (needs at least {needed})"
    )]
    TooShort {
        /// Minimum number of samples (padlen + 1).
        needed: usize,
        /// Number of samples given.
        got: usize,
    },
    /// A sample is NaN or infinite.
    #[error("sample {index} is not finite")]
    NonFinite {
        /// Index of the first non-finite sample.
        index: usize,
    },
    /// The second-order sections cannot be used (no sections, `a0 != 1`, non-finite
    /// coefficients, or a section whose steady state does not exist).
    #[error("invalid second-order sections: {0}")]
    InvalidSos(&'static str),
}

/// A Butterworth low-pass and its zero-phase application, for callers that keep settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ButterworthOptions {
    /// Filter order, 1..=[`MAX_ORDER`]. Applied forward and backward, the attenuation is doubled.
    pub order: usize,
    /// Cutoff (−3 dB of the single pass), Hz.
    pub cutoff_hz: f64,
}

impl Default for ButterworthOptions {
    /// Third order at 5 Hz, the setting of the IMU gait literature (paper 000).
    fn default() -> Self {
        Self {
            order: 3,
            cutoff_hz: 5.0,
        }
    }
}

/// `scipy.signal.butter(order, cutoff_hz, fs=sample_rate_hz, output='sos')`.
///
/// Returns `(order + 1) / 2` sections; the overall gain sits in the first section's numerator.
pub fn design_lowpass_sos(
    order: usize,
    cutoff_hz: f64,
    sample_rate_hz: f64,
) -> Result<Vec<Sos>, FilterError> {
    if order == 0 || order > MAX_ORDER {
        return Err(FilterError::InvalidOrder(order));
    }
    if !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0) {
        return Err(FilterError::InvalidSampleRate(sample_rate_hz));
    }
    // iirfilter: Wn = Wn / (fs/2), then digital design at fs = 2 with pre-warping.
    let wn = cutoff_hz / (sample_rate_hz / 2.0);
    if !(wn > 0.0 && wn < 1.0) {
        return Err(FilterError::InvalidCutoff {
            cutoff_hz,
            nyquist_hz: sample_rate_hz / 2.0,
        });
    }
    let fs = 2.0_f64;
    let warped = 2.0 * fs * (std::f64::consts::PI * wn / fs).tan();

    // buttap: p = -exp(1j * pi * m / (2N)), m = -N+1, -N+3, ..., N-1; no zeros; k = 1.
    let n = order;
    let poles: Vec<Complex64> = (0..n)
        .map(|i| {
            let m = -(n as f64) + 1.0 + 2.0 * i as f64;
            let theta = std::f64::consts::PI * m / (2 * n) as f64;
            Complex64::new(-theta.cos(), -theta.sin())
        })
        .collect();

    // lp2lp_zpk: p *= wo, k *= wo ** degree (degree = N, no zeros).
    let poles: Vec<Complex64> = poles
        .iter()
        .map(|p| Complex64::new(warped * p.re, warped * p.im))
        .collect();
    let k = warped.powf(n as f64);

    // bilinear_zpk at fs = 2: p_z = (fs2 + p) / (fs2 - p); N zeros at -1;
    // k_z = k * real(prod(fs2 - z) / prod(fs2 - p)).
    let fs2 = 2.0 * fs;
    let p_z: Vec<Complex64> = poles
        .iter()
        .map(|p| {
            npy_div(
                Complex64::new(fs2 + p.re, p.im),
                Complex64::new(fs2 - p.re, -p.im),
            )
        })
        .collect();
    let z_z = vec![Complex64::new(-1.0, 0.0); n];
    let mut prod = Complex64::new(fs2 - poles[0].re, -poles[0].im);
    for p in &poles[1..] {
        prod = npy_mul(prod, Complex64::new(fs2 - p.re, -p.im));
    }
    let k_z = k * npy_div(Complex64::new(1.0, 0.0), prod).re;

    zpk2sos_nearest(z_z, p_z, k_z)
}

/// `scipy.signal.sosfilt(sos, x)`: causal filtering from a zero state.
///
/// Each section's `a0` (index 3) is taken to be 1, as SciPy's kernel does (SciPy rejects other
/// values; [`sosfiltfilt`] and [`sosfilt_zi`] do too). Non-finite samples propagate.
pub fn sosfilt(sos: &[Sos], x: &[f64]) -> Vec<f64> {
    let mut state = vec![[0.0; 2]; sos.len()];
    sosfilt_with_state(sos, x, &mut state)
}

/// `scipy.signal.sosfilt(sos, x, zi=state)`: causal filtering from `state` (one `[f64; 2]` per
/// section), which is updated to the final state. If `state` has the wrong length it is
/// resized (missing sections start from zero).
pub fn sosfilt_with_state(sos: &[Sos], x: &[f64], state: &mut Vec<[f64; 2]>) -> Vec<f64> {
    state.resize(sos.len(), [0.0; 2]);
    x.iter()
        .map(|&sample| sosfilt_step(sos, sample, state))
        .collect()
}

/// One sample through the cascade (transposed direct form II), updating `state` (one `[f64; 2]`
/// per section): the incremental core of [`sosfilt_with_state`].
#[inline]
pub fn sosfilt_step(sos: &[Sos], sample: f64, state: &mut [[f64; 2]]) -> f64 {
    let mut cur = sample;
    for (s, z) in sos.iter().zip(state.iter_mut()) {
        let new = s[0] * cur + z[0];
        z[0] = s[1] * cur - s[4] * new + z[1];
        z[1] = s[2] * cur - s[5] * new;
        cur = new;
    }
    cur
}

/// `scipy.signal.sosfilt_zi(sos)`: the per-section state of the steady state of a unit step,
/// so that `sosfilt_with_state(sos, x, zi · x[0])` starts without a transient.
pub fn sosfilt_zi(sos: &[Sos]) -> Result<Vec<[f64; 2]>, FilterError> {
    validate_sos(sos)?;
    let mut zi = Vec::with_capacity(sos.len());
    let mut scale = 1.0;
    for s in sos {
        let (b, a) = ([s[0], s[1], s[2]], [s[3], s[4], s[5]]);
        let z = lfilter_zi_2(b, a).ok_or(FilterError::InvalidSos(
            "a section has a pole at z = 1 (no steady state)",
        ))?;
        zi.push([scale * z[0], scale * z[1]]);
        scale *= ((b[0] + b[1]) + b[2]) / ((a[0] + a[1]) + a[2]);
    }
    Ok(zi)
}

/// The padding length `sosfiltfilt` uses with its defaults for these sections.
pub fn sosfiltfilt_padlen(sos: &[Sos]) -> usize {
    let zeros_b2 = sos.iter().filter(|s| s[2] == 0.0).count();
    let zeros_a2 = sos.iter().filter(|s| s[5] == 0.0).count();
    let ntaps = 2 * sos.len() + 1 - zeros_b2.min(zeros_a2);
    3 * ntaps
}

/// `scipy.signal.sosfiltfilt(sos, x)` with its defaults (padtype `'odd'`, default padlen).
///
/// An empty series gives an empty output; a series of 1..=padlen samples gives
/// [`FilterError::TooShort`] (the caller decides the fallback); a non-finite sample gives
/// [`FilterError::NonFinite`].
pub fn sosfiltfilt(sos: &[Sos], x: &[f64]) -> Result<Vec<f64>, FilterError> {
    let mut y: Vec<[f64; 1]> = x.iter().map(|&v| [v]).collect();
    sosfiltfilt_lanes(sos, &mut y, &mut Vec::new()).map_err(|(_, e)| e)?;
    Ok(y.into_iter().map(|[v]| v).collect())
}

/// [`sosfiltfilt`] of `N` series of one length at once, interleaved (`x[n][lane]`), in place.
/// Each lane goes through the same operations in the same order as [`sosfiltfilt`] alone, so
/// its result is the same to the bit; what changes is speed: a filter's recurrence waits on
/// itself sample after sample, and `N` independent ones fill that wait (a quaternion's four
/// components are filtered together). `work` is scratch for the padding at both ends (callers
/// filtering many tracks keep one).
///
/// On an error `x` is unchanged; a non-finite sample is reported for the first lane that has
/// one (with that lane), as filtering the lanes one after another would.
pub fn sosfiltfilt_lanes<const N: usize>(
    sos: &[Sos],
    x: &mut [[f64; N]],
    work: &mut Vec<[f64; N]>,
) -> Result<(), (usize, FilterError)> {
    if x.is_empty() {
        return Ok(());
    }
    let zi = sosfilt_zi(sos).map_err(|e| (0, e))?;
    let edge = sosfiltfilt_padlen(sos);
    if x.len() <= edge {
        let e = FilterError::TooShort {
            needed: edge + 1,
            got: x.len(),
        };
        return Err((0, e));
    }
    // One pass when every sample is finite (the usual case); the lanes one by one otherwise.
    if !x.iter().all(|v| v.iter().all(|c| c.is_finite())) {
        for lane in 0..N {
            if let Some(index) = x.iter().position(|v| !v[lane].is_finite()) {
                return Err((lane, FilterError::NonFinite { index }));
            }
        }
    }
    // The padded series is `before ++ x ++ after`, filtered where it lies: `x` in place, the
    // short extensions in `work`, with the state running on across them as along one array.
    odd_ext_ends(x, edge, work);
    let (before, after) = work.split_at_mut(edge);

    // Forward over the whole padded series.
    let mut state = lane_state(&zi, before[0]);
    for v in before
        .iter_mut()
        .chain(x.iter_mut())
        .chain(after.iter_mut())
    {
        *v = sosfilt_step_lanes(sos, *v, &mut state);
    }
    // Backward from its end; the extension before `x` would only be filtered to be dropped.
    let mut state = lane_state(&zi, after[edge - 1]);
    for v in after.iter_mut().rev().chain(x.iter_mut().rev()) {
        *v = sosfilt_step_lanes(sos, *v, &mut state);
    }
    Ok(())
}

/// The steady state `zi · x0` of each section, per lane: `[z0, z1]` of every lane (the state
/// [`sosfilt_step_lanes`] takes).
pub fn lane_state<const N: usize>(zi: &[[f64; 2]], x0: [f64; N]) -> Vec<[[f64; N]; 2]> {
    zi.iter()
        .map(|z| [x0.map(|v| z[0] * v), x0.map(|v| z[1] * v)])
        .collect()
}

/// [`sosfilt_step`] on `N` lanes: the same expressions, lane by lane (so each lane's output is
/// [`sosfilt_step`]'s to the bit).
#[inline]
pub fn sosfilt_step_lanes<const N: usize>(
    sos: &[Sos],
    sample: [f64; N],
    state: &mut [[[f64; N]; 2]],
) -> [f64; N] {
    let mut cur = sample;
    for (s, [z0, z1]) in sos.iter().zip(state.iter_mut()) {
        for l in 0..N {
            let new = s[0] * cur[l] + z0[l];
            z0[l] = s[1] * cur[l] - s[4] * new + z1[l];
            z1[l] = s[2] * cur[l] - s[5] * new;
            cur[l] = new;
        }
    }
    cur
}

/// The two ends `scipy.signal._arraytools.odd_ext(x, n)` adds, per lane, into `ends`: the `n`
/// samples before `x`, then the `n` after it; requires `1 <= n <= x.len() - 1`.
fn odd_ext_ends<const N: usize>(x: &[[f64; N]], n: usize, ends: &mut Vec<[f64; N]>) {
    let len = x.len();
    ends.clear();
    ends.reserve(2 * n);
    let (first, last) = (x[0], x[len - 1]);
    let reflect =
        |edge: [f64; N], v: [f64; N]| -> [f64; N] { std::array::from_fn(|l| 2.0 * edge[l] - v[l]) };
    ends.extend((1..=n).rev().map(|i| reflect(first, x[i])));
    ends.extend((1..=n).map(|i| reflect(last, x[len - 1 - i])));
}

fn validate_sos(sos: &[Sos]) -> Result<(), FilterError> {
    if sos.is_empty() {
        return Err(FilterError::InvalidSos("no sections"));
    }
    if sos.iter().any(|s| s[3] != 1.0) {
        return Err(FilterError::InvalidSos("sos[:, 3] should be all ones"));
    }
    if sos.iter().flatten().any(|c| !c.is_finite()) {
        return Err(FilterError::InvalidSos("non-finite coefficient"));
    }
    Ok(())
}

/// `scipy.signal.lfilter_zi(b, a)` for one section with `a[0] == 1`: solves
/// `(I - A) zi = B` with `I - A = [[1 + a1, -1], [a2, 1]]`, `B = b[1:] - a[1:] b0`, by LU with
/// partial pivoting as LAPACK's `dgesv` does. `None` when the matrix is singular.
fn lfilter_zi_2(b: [f64; 3], a: [f64; 3]) -> Option<[f64; 2]> {
    let mut m = [[1.0 + a[1], -1.0], [a[2], 1.0]];
    let mut rhs = [b[1] - a[1] * b[0], b[2] - a[2] * b[0]];
    if m[1][0].abs() > m[0][0].abs() {
        m.swap(0, 1);
        rhs.swap(0, 1);
    }
    if m[0][0] == 0.0 {
        return None;
    }
    let l = m[1][0] * (1.0 / m[0][0]);
    let u11 = m[1][1] - l * m[0][1];
    if u11 == 0.0 || !u11.is_finite() {
        return None;
    }
    let y1 = rhs[1] - l * rhs[0];
    let x1 = y1 / u11;
    let x0 = (rhs[0] - x1 * m[0][1]) / m[0][0];
    Some([x0, x1])
}

/// NumPy's complex multiplication.
fn npy_mul(a: Complex64, b: Complex64) -> Complex64 {
    Complex64::new(a.re * b.re - a.im * b.im, a.re * b.im + a.im * b.re)
}

/// NumPy's complex division (Smith's method), so results match bit for bit where possible.
fn npy_div(a: Complex64, b: Complex64) -> Complex64 {
    let (br_abs, bi_abs) = (b.re.abs(), b.im.abs());
    if br_abs >= bi_abs {
        if br_abs == 0.0 && bi_abs == 0.0 {
            return Complex64::new(a.re / br_abs, a.im / br_abs);
        }
        let rat = b.im / b.re;
        let scl = 1.0 / (b.re + b.im * rat);
        Complex64::new((a.re + a.im * rat) * scl, (a.im - a.re * rat) * scl)
    } else {
        let rat = b.re / b.im;
        let scl = 1.0 / (b.im + b.re * rat);
        Complex64::new((a.re * rat + a.im) * scl, (a.im * rat - a.re) * scl)
    }
}

fn is_real(z: Complex64) -> bool {
    z.im == 0.0
}

/// `scipy.signal._filter_design._cplxreal`: complex values with positive imaginary part (one
/// per conjugate pair, averaged with its partner), sorted by real part then |imag|, followed by
/// the real values, sorted. Values without a partner are kept as they are (SciPy raises).
fn cplxreal(mut z: Vec<Complex64>) -> Vec<Complex64> {
    if z.is_empty() {
        return z;
    }
    let tol = 100.0 * f64::EPSILON;
    z.sort_by(|a, b| {
        a.re.total_cmp(&b.re)
            .then(a.im.abs().total_cmp(&b.im.abs()))
    });
    let (reals, complexes): (Vec<Complex64>, Vec<Complex64>) =
        z.into_iter().partition(|v| v.im.abs() <= tol * v.norm());
    let zr: Vec<Complex64> = reals.iter().map(|v| Complex64::new(v.re, 0.0)).collect();
    if complexes.is_empty() {
        return zr;
    }
    let mut zp: Vec<Complex64> = complexes.iter().copied().filter(|v| v.im > 0.0).collect();
    let mut zn: Vec<Complex64> = complexes.iter().copied().filter(|v| v.im < 0.0).collect();
    // Runs of (approximately) the same real part are sorted by |imag|.
    let mut start = 0;
    while start < zp.len() {
        let mut stop = start + 1;
        while stop < zp.len() && zp[stop].re - zp[stop - 1].re <= tol * zp[stop - 1].norm() {
            stop += 1;
        }
        if stop - start > 1 {
            zp[start..stop].sort_by(|a, b| a.im.abs().total_cmp(&b.im.abs()));
            let end = stop.min(zn.len());
            if start < end {
                zn[start..end].sort_by(|a, b| a.im.abs().total_cmp(&b.im.abs()));
            }
        }
        start = stop;
    }
    let mut out: Vec<Complex64> = zp
        .iter()
        .zip(zn.iter())
        .map(|(p, n)| {
            let s = Complex64::new(p.re + n.re, p.im - n.im);
            Complex64::new(s.re / 2.0, s.im / 2.0)
        })
        .collect();
    // Unpaired leftovers (not produced by Butterworth designs) are kept rather than dropped.
    out.extend(zp.iter().skip(zn.len()).copied());
    out.extend(zn.iter().skip(zp.len()).map(|v| v.conj()));
    out.extend(zr);
    out
}

#[derive(Clone, Copy, PartialEq)]
enum Which {
    Real,
    Complex,
    Any,
}

/// `_nearest_real_complex_idx`: index of the element of `fro` nearest to `to` (of the kind
/// asked for); ties go to the earlier element, as NumPy's small-array sort is stable.
fn nearest_idx(fro: &[Complex64], to: Complex64, which: Which) -> Option<usize> {
    let mut order: Vec<usize> = (0..fro.len()).collect();
    order.sort_by(|&i, &j| (fro[i] - to).norm().total_cmp(&(fro[j] - to).norm()));
    order.into_iter().find(|&i| match which {
        Which::Any => true,
        Which::Real => is_real(fro[i]),
        Which::Complex => !is_real(fro[i]),
    })
}

/// `np.argmin(np.abs(1 - np.abs(p)))`: the pole closest to the unit circle.
fn idx_worst(p: &[Complex64], among: impl Iterator<Item = usize>) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for i in among {
        let d = (1.0 - p[i].norm()).abs();
        if best.is_none_or(|(_, bd)| d < bd) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| i)
}

/// `np.poly(roots)` (real part; the roots given are real or a conjugate pair).
fn poly(roots: &[Complex64]) -> Vec<f64> {
    let mut a = vec![Complex64::new(1.0, 0.0)];
    for &r in roots {
        let neg = Complex64::new(-r.re, -r.im);
        let mut next = vec![Complex64::new(0.0, 0.0); a.len() + 1];
        for (i, &c) in a.iter().enumerate() {
            next[i] += c;
            next[i + 1] += npy_mul(c, neg);
        }
        a = next;
    }
    a.iter().map(|c| c.re).collect()
}

/// `_single_zpksos(z, p, 1)`.
fn single_zpksos(z: &[Complex64], p: &[Complex64]) -> Sos {
    let mut sos = [0.0; 6];
    let b = poly(z);
    let a = poly(p);
    sos[3 - b.len()..3].copy_from_slice(&b);
    sos[6 - a.len()..6].copy_from_slice(&a);
    sos
}

/// `scipy.signal.zpk2sos(z, p, k)` with the default digital pairing `'nearest'`.
fn zpk2sos_nearest(
    mut z: Vec<Complex64>,
    mut p: Vec<Complex64>,
    k: f64,
) -> Result<Vec<Sos>, FilterError> {
    if z.is_empty() && p.is_empty() {
        return Ok(vec![[k, 0.0, 0.0, 1.0, 0.0, 0.0]]);
    }
    let zero = Complex64::new(0.0, 0.0);
    while p.len() < z.len() {
        p.push(zero);
    }
    while z.len() < p.len() {
        z.push(zero);
    }
    let n_sections = p.len().div_ceil(2);
    if p.len() % 2 == 1 {
        p.push(zero);
        z.push(zero);
    }
    let mut z = cplxreal(z);
    let mut p = cplxreal(p);
    let broken = FilterError::InvalidSos("pole/zero pairing failed");

    let mut sos = vec![[0.0; 6]; n_sections];
    for si in (0..n_sections).rev() {
        let p1_idx = idx_worst(&p, 0..p.len()).ok_or(broken.clone())?;
        let p1 = p.remove(p1_idx);
        let n_real_p = p.iter().filter(|v| is_real(**v)).count();
        let n_real_z = z.iter().filter(|v| is_real(**v)).count();

        if is_real(p1) && n_real_p == 0 {
            // Special case (1): last remaining real pole.
            let z1_idx = nearest_idx(&z, p1, Which::Real).ok_or(broken.clone())?;
            let z1 = z.remove(z1_idx);
            sos[si] = single_zpksos(&[z1, zero], &[p1, zero]);
        } else if p.len() + 1 == z.len() && !is_real(p1) && n_real_p == 1 && n_real_z == 1 {
            // Special case (2): one real pole and one real zero left; pair with a complex zero.
            let z1_idx = nearest_idx(&z, p1, Which::Complex).ok_or(broken.clone())?;
            let z1 = z.remove(z1_idx);
            sos[si] = single_zpksos(&[z1, z1.conj()], &[p1, p1.conj()]);
        } else {
            let p2 = if is_real(p1) {
                let real_idx: Vec<usize> = (0..p.len()).filter(|&i| is_real(p[i])).collect();
                let p2_idx = idx_worst(&p, real_idx.into_iter()).ok_or(broken.clone())?;
                p.remove(p2_idx)
            } else {
                p1.conj()
            };
            if z.is_empty() {
                sos[si] = single_zpksos(&[], &[p1, p2]);
            } else {
                let z1_idx = nearest_idx(&z, p1, Which::Any).ok_or(broken.clone())?;
                let z1 = z.remove(z1_idx);
                if !is_real(z1) {
                    sos[si] = single_zpksos(&[z1, z1.conj()], &[p1, p2]);
                } else if !z.is_empty() {
                    let z2_idx = nearest_idx(&z, p1, Which::Real).ok_or(broken.clone())?;
                    let z2 = z.remove(z2_idx);
                    sos[si] = single_zpksos(&[z1, z2], &[p1, p2]);
                } else {
                    sos[si] = single_zpksos(&[z1], &[p1, p2]);
                }
            }
        }
    }
    if !(p.is_empty() && z.is_empty()) {
        return Err(broken);
    }
    for c in &mut sos[0][..3] {
        *c *= k;
    }
    Ok(sos)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn rejects_bad_designs() {
        assert_eq!(
            design_lowpass_sos(0, 5.0, 100.0),
            Err(FilterError::InvalidOrder(0))
        );
        assert_eq!(
            design_lowpass_sos(11, 5.0, 100.0),
            Err(FilterError::InvalidOrder(11))
        );
        for cutoff in [0.0, -1.0, 50.0, 60.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                design_lowpass_sos(3, cutoff, 100.0),
                Err(FilterError::InvalidCutoff { .. })
            ));
        }
        for rate in [0.0, -100.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                design_lowpass_sos(3, 5.0, rate),
                Err(FilterError::InvalidSampleRate(_))
            ));
        }
    }

    #[test]
    fn first_order_matches_closed_form() {
        // butter(1, Wn): b = [g, g, 0], a = [1, -(1 - t) / (1 + t), 0], t = tan(pi Wn / 2),
        // g = t / (1 + t).
        let sos = design_lowpass_sos(1, 10.0, 100.0).unwrap();
        let t = (std::f64::consts::PI * 0.2 / 2.0).tan();
        let expected = [
            t / (1.0 + t),
            t / (1.0 + t),
            0.0,
            1.0,
            -(1.0 - t) / (1.0 + t),
            0.0,
        ];
        assert_eq!(sos.len(), 1);
        for (a, b) in sos[0].iter().zip(expected) {
            assert!((a - b).abs() < 1e-15, "{sos:?}");
        }
    }

    #[test]
    fn unit_dc_gain() {
        for order in 1..=MAX_ORDER {
            for cutoff in [0.5, 5.0, 24.0, 49.0] {
                let sos = design_lowpass_sos(order, cutoff, 100.0).unwrap();
                let gain: f64 = sos
                    .iter()
                    .map(|s| (s[0] + s[1] + s[2]) / (s[3] + s[4] + s[5]))
                    .product();
                assert!(
                    (gain - 1.0).abs() < 1e-9,
                    "order {order} cutoff {cutoff}: {gain}"
                );
            }
        }
    }

    #[test]
    fn dc_passes_unchanged() {
        let x = vec![3.25; 400];
        let sos = design_lowpass_sos(4, 6.0, 100.0).unwrap();
        let y = sosfiltfilt(&sos, &x).unwrap();
        assert!(y.iter().all(|v| (v - 3.25).abs() < 1e-12), "{y:?}");
        // The causal filter starts from rest: DC passes once the transient has died out.
        let y = sosfilt(&sos, &x);
        assert!(y[250..].iter().all(|v| (v - 3.25).abs() < 1e-12));
        // ... and at once from the steady state.
        let zi = sosfilt_zi(&sos).unwrap();
        let mut state = zi.iter().map(|z| [z[0] * 3.25, z[1] * 3.25]).collect();
        let y = sosfilt_with_state(&sos, &x, &mut state);
        assert!(y.iter().all(|v| (v - 3.25).abs() < 1e-12));
    }

    #[test]
    fn nyquist_alternation_is_removed() {
        let x: Vec<f64> = (0..400)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let sos = design_lowpass_sos(4, 10.0, 100.0).unwrap();
        let y = sosfiltfilt(&sos, &x).unwrap();
        // Butterworth has its zeros at Nyquist: once the edge transients (from the odd
        // extension) have died out, nothing is left (scipy: 3.2e-7 at sample 60, 4.8e-11 at 100).
        assert!(
            y[150..250].iter().all(|v| v.abs() < 1e-12),
            "{:?}",
            &y[150..160]
        );
        let y = sosfilt(&sos, &x);
        assert!(y[150..].iter().all(|v| v.abs() < 1e-12));
    }

    #[test]
    fn lanes_are_each_the_single_series_filter_to_the_bit() {
        // Four unrelated series (different shapes and scales) filtered in lockstep, against each
        // filtered alone by the scalar step (`sosfilt_step`, the incremental core) around a
        // hand-made odd extension, for every order.
        let n = 700;
        let series: [Vec<f64>; 4] = [
            (0..n).map(|i| (i as f64 * 0.037).sin()).collect(),
            (0..n)
                .map(|i| ((i * 7919) % 613) as f64 / 613.0 - 0.5)
                .collect(),
            (0..n)
                .map(|i| 1e3 * (i as f64 * 0.01).cos() + i as f64)
                .collect(),
            (0..n)
                .map(|i| if i % 50 < 25 { 1e-7 } else { -3e-7 })
                .collect(),
        ];
        for order in 1..=MAX_ORDER {
            let sos = design_lowpass_sos(order, 7.5, 100.0).unwrap();
            let mut lanes: Vec<[f64; 4]> =
                (0..n).map(|i| series.each_ref().map(|s| s[i])).collect();
            sosfiltfilt_lanes(&sos, &mut lanes, &mut Vec::new()).unwrap();
            let zi = sosfilt_zi(&sos).unwrap();
            let edge = sosfiltfilt_padlen(&sos);
            for (l, x) in series.iter().enumerate() {
                let mut ext: Vec<f64> = (1..=edge).rev().map(|i| 2.0 * x[0] - x[i]).collect();
                ext.extend_from_slice(x);
                ext.extend((1..=edge).map(|i| 2.0 * x[n - 1] - x[n - 1 - i]));
                let mut state: Vec<[f64; 2]> =
                    zi.iter().map(|z| [z[0] * ext[0], z[1] * ext[0]]).collect();
                let forward: Vec<f64> = ext
                    .iter()
                    .map(|&v| sosfilt_step(&sos, v, &mut state))
                    .collect();
                let y0 = forward[forward.len() - 1];
                let mut state: Vec<[f64; 2]> = zi.iter().map(|z| [z[0] * y0, z[1] * y0]).collect();
                let mut backward: Vec<f64> = forward
                    .iter()
                    .rev()
                    .map(|&v| sosfilt_step(&sos, v, &mut state))
                    .collect();
                backward.reverse();
                for i in 0..n {
                    assert_eq!(
                        lanes[i][l].to_bits(),
                        backward[edge + i].to_bits(),
                        "order {order}, lane {l}, sample {i}"
                    );
                }
                assert_eq!(sosfiltfilt(&sos, x).unwrap(), &backward[edge..edge + n]);
            }
        }
        // A non-finite sample is reported for the first lane that has one; nothing is changed.
        let sos = design_lowpass_sos(2, 5.0, 100.0).unwrap();
        let mut lanes = vec![[0.5; 3]; 40];
        lanes[30][2] = f64::NAN;
        lanes[9][1] = f64::INFINITY;
        let before = lanes.clone();
        assert_eq!(
            sosfiltfilt_lanes(&sos, &mut lanes, &mut Vec::new()),
            Err((1, FilterError::NonFinite { index: 9 }))
        );
        assert_eq!(format!("{lanes:?}"), format!("{before:?}"));
    }

    #[test]
    fn short_and_odd_series() {
        let sos = design_lowpass_sos(3, 5.0, 100.0).unwrap();
        let padlen = sosfiltfilt_padlen(&sos);
        assert_eq!(padlen, 12);
        assert_eq!(sosfiltfilt(&sos, &[]), Ok(vec![]));
        for len in 1..=padlen {
            assert_eq!(
                sosfiltfilt(&sos, &vec![1.0; len]),
                Err(FilterError::TooShort {
                    needed: padlen + 1,
                    got: len
                })
            );
        }
        assert_eq!(
            sosfiltfilt(&sos, &vec![1.0; padlen + 1]).unwrap().len(),
            padlen + 1
        );
        let mut x = vec![0.5; 50];
        x[7] = f64::NAN;
        assert_eq!(
            sosfiltfilt(&sos, &x),
            Err(FilterError::NonFinite { index: 7 })
        );
        assert!(sosfilt(&sos, &[]).is_empty());
        assert!(matches!(
            sosfiltfilt(&[], &x),
            Err(FilterError::InvalidSos(_))
        ));
        let mut bad = sos.clone();
        bad[0][3] = 2.0;
        assert!(matches!(sosfilt_zi(&bad), Err(FilterError::InvalidSos(_))));
        // An integrator has no steady state.
        let integrator = [[1.0, 0.0, 0.0, 1.0, -1.0, 0.0]];
        assert!(matches!(
            sosfilt_zi(&integrator),
            Err(FilterError::InvalidSos(_))
        ));
    }

    proptest! {
        #[test]
        fn never_panics_or_yields_nan(
            x in proptest::collection::vec(-1e6f64..1e6, 0..200),
            order in 0usize..12,
            cutoff in -5.0f64..60.0,
        ) {
            let rate = 100.0;
            match design_lowpass_sos(order, cutoff, rate) {
                Ok(sos) => {
                    let y = sosfilt(&sos, &x);
                    prop_assert_eq!(y.len(), x.len());
                    prop_assert!(y.iter().all(|v| v.is_finite()));
                    match sosfiltfilt(&sos, &x) {
                        Ok(y) => {
                            prop_assert_eq!(y.len(), x.len());
                            prop_assert!(y.iter().all(|v| v.is_finite()));
                        }
                        Err(FilterError::TooShort { needed, got }) => {
                            prop_assert_eq!(got, x.len());
                            prop_assert!(got < needed);
                        }
                        Err(e) => prop_assert!(false, "unexpected {e}"),
                    }
                }
                Err(_) => prop_assert!(order == 0 || order > MAX_ORDER || !(cutoff > 0.0 && cutoff < rate / 2.0)),
            }
        }
    }
}
