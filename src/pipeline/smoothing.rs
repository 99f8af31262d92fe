//! The smoothing stage: rotation tracks smoothed without breaking them, with the filters of
//! [`crate::smooth`]: quaternions are made sign-continuous,
//! filtered per component and renormalised; Euler angles are filtered as (cos, sin) pairs and
//! turned back with atan2 (paper 002, 6.5), so 359° and 0° never average to 180°.
//!
//! Filters need uniform sampling, and sensors sample irregularly: a sensor's track is first
//! slerped onto a uniform grid at its own mean rate ([`uniform`]), smoothed there — at the sensor
//! rate, where averaging has the most samples to work with — and then resampled onto the frame
//! grid by the pipeline.

use crate::rotation::slerp_shortest;
use crate::smooth::Method;
use crate::smooth::butterworth::{
    Sos, design_lowpass_sos, sosfilt_step, sosfilt_with_state, sosfilt_zi, sosfiltfilt,
    sosfiltfilt_lanes,
};
use crate::smooth::fft::{FftOptions, fft_filter};
use crate::smooth::gaussian::gaussian_filter1d;
use crate::take::Track;
use nalgebra::{Quaternion, UnitQuaternion};

/// Why a series was left unsmoothed (the caller warns and keeps the input).
#[derive(Debug, Clone, PartialEq)]
pub struct Unsmoothed(pub String);

/// Filters a series sampled uniformly at `rate_hz`.
pub fn smooth_series(x: &[f64], rate_hz: f64, method: &Method) -> Result<Vec<f64>, Unsmoothed> {
    match method {
        Method::None => Ok(x.to_vec()),
        // A low-pass at or above half the sample rate has nothing to remove: the identity (the
        // default's 14 Hz on a 26 Hz SOU log, say).
        Method::Butterworth { cutoff_hz, .. } if *cutoff_hz >= rate_hz / 2.0 => Ok(x.to_vec()),
        Method::Butterworth {
            order,
            cutoff_hz,
            causal,
        } => {
            let sos = butterworth_sos(*order, *cutoff_hz, rate_hz, method)?;
            if *causal {
                // From the steady state of the first sample, as a live filter that has been
                // running would be: from a zero state every track would start at zero.
                let Some(&first) = x.first() else {
                    return Ok(Vec::new());
                };
                let zi = sosfilt_zi(&sos).map_err(|e| Unsmoothed(format!("{method}: {e}")))?;
                let mut state: Vec<[f64; 2]> =
                    zi.iter().map(|z| [z[0] * first, z[1] * first]).collect();
                Ok(sosfilt_with_state(&sos, x, &mut state))
            } else {
                sosfiltfilt(&sos, x).map_err(|e| Unsmoothed(format!("{method}: {e}")))
            }
        }
        Method::Gaussian { sigma_s } => Ok(gaussian_filter1d(x, sigma_s * rate_hz, 4.0)),
        Method::Fft {
            threshold,
            suppress,
            cutoff_hz,
        } => {
            // The FFT sees the series as periodic; a track that ends elsewhere than it starts
            // would wrap with a jump whose ringing spreads over the whole take. Filtering the
            // series followed by its mirror image (a continuous periodic signal) avoids that.
            let mut mirrored = x.to_vec();
            mirrored.extend(x.iter().rev());
            let options = FftOptions {
                threshold: *threshold,
                suppress: *suppress,
                cutoff_hz: *cutoff_hz,
            };
            let mut y = fft_filter(&mirrored, rate_hz, &options);
            y.truncate(x.len());
            Ok(y)
        }
    }
}

/// Smooths unit quaternions sampled uniformly at `rate_hz`: sign-continuous, per component,
/// renormalised. A sample whose filtered components nearly cancel (norm below 0.1, which only a
/// wildly spinning input produces) keeps its input value rather than an arbitrary direction.
pub fn smooth_quaternions(
    track: &[UnitQuaternion<f64>],
    rate_hz: f64,
    method: &Method,
) -> Result<Vec<UnitQuaternion<f64>>, Unsmoothed> {
    let mut values = track.to_vec();
    smooth_quaternions_in_place(&mut values, rate_hz, method)?;
    Ok(values)
}

/// [`smooth_quaternions`] without copies of the track (long takes hold millions of samples). On
/// an error the values are left sign-continuous but otherwise unchanged.
pub fn smooth_quaternions_in_place(
    values: &mut [UnitQuaternion<f64>],
    rate_hz: f64,
    method: &Method,
) -> Result<(), Unsmoothed> {
    smooth_quaternions_with(values, rate_hz, method, &mut Scratch::default())
}

/// The working memory of smoothing one track, kept from track to track by a caller that
/// smooths many (a long take's track is millions of samples: fresh memory for each costs more
/// than filtering it — ~2 µs a 4 KiB page on this project's test machine, against ~0.25 µs to
/// write a page already in use).
#[derive(Debug, Default)]
pub struct Scratch {
    /// The four components as they are filtered, then the output.
    filtered: Vec<[f64; 4]>,
    /// The padded series the filter runs over.
    padded: Vec<[f64; 4]>,
    /// Tracks' memory handed back ([`Scratch::give`]), for the next track's uniform grid or the
    /// caller's frame grid.
    spare_times: Vec<Vec<f64>>,
    spare_values: Vec<Vec<UnitQuaternion<f64>>>,
}

impl Scratch {
    /// The most spare vectors of each kind kept: a track's and its uniform grid's.
    const SPARES: usize = 2;

    /// Keeps `track`'s memory for later tracks.
    pub(crate) fn give(&mut self, track: Track<UnitQuaternion<f64>>) {
        let (times, values) = track.into_parts();
        if self.spare_times.len() < Self::SPARES {
            self.spare_times.push(times);
        }
        if self.spare_values.len() < Self::SPARES {
            self.spare_values.push(values);
        }
    }

    /// A kept vector for values (empty, perhaps with room), else a new one.
    pub(crate) fn values(&mut self) -> Vec<UnitQuaternion<f64>> {
        self.spare_values.pop().unwrap_or_default()
    }

    fn times(&mut self) -> Vec<f64> {
        self.spare_times.pop().unwrap_or_default()
    }
}

/// [`smooth_quaternions_in_place`] with working memory from `scratch`.
pub fn smooth_quaternions_with(
    values: &mut [UnitQuaternion<f64>],
    rate_hz: f64,
    method: &Method,
    scratch: &mut Scratch,
) -> Result<(), Unsmoothed> {
    if *method == Method::None {
        return Ok(());
    }
    // Each sample on its predecessor's hemisphere (as `make_hemisphere_continuous`), copied as
    // it is made: nalgebra stores quaternions as (x, y, z, w), four interleaved series, filtered
    // in place.
    let filtered = &mut scratch.filtered;
    filtered.clear();
    filtered.reserve(values.len());
    let mut before: Option<UnitQuaternion<f64>> = None;
    for value in values.iter_mut() {
        if before.is_some_and(|b| value.coords.dot(&b.coords) < 0.0) {
            *value = UnitQuaternion::new_unchecked(-value.into_inner());
        }
        before = Some(*value);
        filtered.push(<[f64; 4]>::from(value.coords));
    }
    filter_lanes(filtered, rate_hz, method, &mut scratch.padded)?;
    let smoothed = |f: [f64; 4], input: &UnitQuaternion<f64>| {
        let f = Quaternion::new(f[3], f[0], f[1], f[2]);
        let norm = f.norm();
        if norm.is_finite() && norm > 0.1 {
            UnitQuaternion::new_unchecked(f / norm)
        } else {
            *input
        }
    };
    // Smoothing must never add a jump. On real motion it only shrinks steps; on a track that
    // turns by nearly 180° between samples, component averages lose their meaning, and such a
    // track is kept as it is (with the reason) rather than made worse. The largest step is the
    // smallest |dot| of neighbours (angle = 2·acos|dot|). The output takes the input's place
    // as it is made, the input the filtered components' (to be put back if the guard refuses).
    let mut min_dot_in: f64 = 1.0;
    let mut min_dot_out: f64 = 1.0;
    let mut previous = None;
    for (value, f) in values.iter_mut().zip(filtered.iter_mut()) {
        let input = *value;
        let out = smoothed(*f, &input);
        if let Some((prev_in, prev_out)) = previous {
            min_dot_in = min_dot_in.min(input.coords.dot(&prev_in).abs());
            min_dot_out = min_dot_out.min(out.coords.dot(&prev_out).abs());
        }
        previous = Some((input.coords, out.coords));
        *value = out;
        *f = input.coords.into();
    }
    let (step_in, step_out) = (
        2.0 * min_dot_in.min(1.0).acos(),
        2.0 * min_dot_out.min(1.0).acos(),
    );
    if step_out > step_in + MAX_ADDED_STEP_RAD {
        for (value, f) in values.iter_mut().zip(filtered.iter()) {
            *value = UnitQuaternion::new_unchecked(Quaternion::new(f[3], f[0], f[1], f[2]));
        }
        return Err(Unsmoothed(format!(
            "{method} would turn by up to {:.1}° between samples where the input turns by at most {:.1}°",
            step_out.to_degrees(),
            step_in.to_degrees()
        )));
    }
    Ok(())
}

/// The sections of `method`'s Butterworth low-pass at `rate_hz`, or why there are none.
fn butterworth_sos(
    order: usize,
    cutoff_hz: f64,
    rate_hz: f64,
    method: &Method,
) -> Result<Vec<Sos>, Unsmoothed> {
    design_lowpass_sos(order, cutoff_hz, rate_hz)
        .map_err(|e| Unsmoothed(format!("{method} at {rate_hz:.1} Hz: {e}")))
}

/// Filters four interleaved series sampled uniformly at `rate_hz`, in place: zero-phase
/// Butterworth (the default) on all four at once, any other method one series at a time.
fn filter_lanes(
    x: &mut [[f64; 4]],
    rate_hz: f64,
    method: &Method,
    padded: &mut Vec<[f64; 4]>,
) -> Result<(), Unsmoothed> {
    match method {
        Method::Butterworth {
            order,
            cutoff_hz,
            causal: false,
        } if *cutoff_hz < rate_hz / 2.0 => {
            let sos = butterworth_sos(*order, *cutoff_hz, rate_hz, method)?;
            sosfiltfilt_lanes(&sos, x, padded)
                .map_err(|(_, e)| Unsmoothed(format!("{method}: {e}")))
        }
        _ => {
            for lane in 0..4 {
                let series: Vec<f64> = x.iter().map(|v| v[lane]).collect();
                let y = smooth_series(&series, rate_hz, method)?;
                for (v, y) in x.iter_mut().zip(y) {
                    v[lane] = y;
                }
            }
            Ok(())
        }
    }
}

/// How much larger than the input's largest step (radians) a smoothed track's largest step may be.
const MAX_ADDED_STEP_RAD: f64 = std::f64::consts::PI / 180.0;

/// Smooths an angle series in degrees through (cos, sin) pairs; the result is unwrapped to stay
/// within 180° of the input at every sample, so continuous tracks stay continuous.
pub fn smooth_angles_deg(
    angles: &[f64],
    rate_hz: f64,
    method: &Method,
) -> Result<Vec<f64>, Unsmoothed> {
    if *method == Method::None {
        return Ok(angles.to_vec());
    }
    let cos: Vec<f64> = angles.iter().map(|a| a.to_radians().cos()).collect();
    let sin: Vec<f64> = angles.iter().map(|a| a.to_radians().sin()).collect();
    let cos = smooth_series(&cos, rate_hz, method)?;
    let sin = smooth_series(&sin, rate_hz, method)?;
    Ok(angles
        .iter()
        .zip(cos.iter().zip(&sin))
        .map(|(a, (c, s))| {
            if c.hypot(*s) < 1e-9 {
                return *a;
            }
            let smoothed = s.atan2(*c).to_degrees();
            smoothed + 360.0 * ((a - smoothed) / 360.0).round()
        })
        .collect())
}

/// A track slerped onto a uniform grid at its mean rate (same first and last time, same number
/// of samples), and that rate. `None` for a single sample.
pub fn uniform(track: &Track<UnitQuaternion<f64>>) -> Option<(f64, Track<UnitQuaternion<f64>>)> {
    uniform_with(track, &mut Scratch::default())
}

/// [`uniform`] in memory from `scratch`.
fn uniform_with(
    track: &Track<UnitQuaternion<f64>>,
    scratch: &mut Scratch,
) -> Option<(f64, Track<UnitQuaternion<f64>>)> {
    let n = track.len();
    if n < 2 {
        return None;
    }
    let (first, last) = (track.first_time_s(), track.last_time_s());
    let step = (last - first) / (n - 1) as f64;
    let mut times = scratch.times();
    times.clear();
    times.extend((0..n).map(|k| first + step * k as f64));
    let mut values = scratch.values();
    track.resample_into(times.iter().copied(), &mut values);
    Track::new(times, values).ok().map(|t| (1.0 / step, t))
}

/// The warnings for bones left unsmoothed (bone, reason): one for a reason many bones share (a
/// low sensor rate, a short take), else one per bone.
pub fn not_smoothed_warnings(not_smoothed: &[(String, String)]) -> Vec<String> {
    let Some((_, first_reason)) = not_smoothed.first() else {
        return Vec::new();
    };
    if not_smoothed.len() > 3 {
        let bones: Vec<&str> = not_smoothed.iter().map(|(b, _)| b.as_str()).collect();
        vec![format!(
            "{} bones are not smoothed ({}), e.g. because {first_reason}",
            bones.len(),
            bones.join(", ")
        )]
    } else {
        not_smoothed
            .iter()
            .map(|(bone, why)| format!("`{bone}` is not smoothed: {why}"))
            .collect()
    }
}

/// Smooths one sensor's track at its own rate; returns the uniform smoothed track, or the input
/// and the reason when it cannot be smoothed. The input's memory is kept in `scratch` for what
/// comes next.
pub fn smooth_track(
    track: Track<UnitQuaternion<f64>>,
    method: &Method,
    sensor_rate_hz: Option<f64>,
    scratch: &mut Scratch,
) -> (Track<UnitQuaternion<f64>>, Option<Unsmoothed>) {
    if *method == Method::None {
        return (track, None);
    }
    if method.is_causal() {
        return smooth_track_causally(&track, method, sensor_rate_hz);
    }
    let Some((rate, grid)) = uniform_with(&track, scratch) else {
        return (
            track,
            Some(Unsmoothed("a single sample cannot be smoothed".into())),
        );
    };
    scratch.give(track);
    let (times, mut values) = grid.into_parts();
    let unsmoothed = smooth_quaternions_with(&mut values, rate, method, scratch).err();
    let track = Track::new(times, values).expect("the uniform grid's times are valid");
    (track, unsmoothed)
}
/// A causal method runs on its incremental core ([`CausalSmoother`]), as on a stream.
fn smooth_track_causally(
    track: &Track<UnitQuaternion<f64>>,
    method: &Method,
    sensor_rate_hz: Option<f64>,
) -> (Track<UnitQuaternion<f64>>, Option<Unsmoothed>) {
    let mut smoother = CausalSmoother::new(method, sensor_rate_hz).expect("a causal method");
    let mut out = Vec::with_capacity(track.len());
    for (t, q) in track.iter() {
        smoother.push(t, *q, &mut out);
    }
    smoother.finish(&mut out);
    let why = smoother.not_smoothed().cloned().or_else(|| {
        (smoother.unsmoothed() > 0).then(|| {
            Unsmoothed(format!(
                "{} samples would have turned further than the sensor did",
                smoother.unsmoothed()
            ))
        })
    });
    let (times, values) = out.into_iter().unzip();
    let smoothed = Track::new(times, values).expect("the grid's times increase");
    (smoothed, why)
}

/// How many samples of a sensor give its grid's rate in causal smoothing (when no rate is
/// declared).
pub const RATE_SAMPLES: usize = 32;

/// The incremental core of smoothing, for one sensor: samples in, smoothed samples out, using only
/// the past. The sensor's samples are slerped onto a uniform grid whose rate comes from its first
/// [`RATE_SAMPLES`] samples (or the declared rate), then each grid sample goes through a causal
/// Butterworth filter per quaternion component (started in the steady state of the first sample,
/// sign-continuous, renormalised). The guard decides per sample, as the whole-take guard does
/// over the track: a filtered sample that would turn from the previous output by more than 1°
/// beyond the largest turn of the input over the last [`GUARD_SAMPLES`] grid samples (a lagging
/// filter may turn more than the input at the very moment the input slows) is replaced by the
/// input, and the filter restarts there (counted in [`CausalSmoother::unsmoothed`]). `none`
/// passes samples through unchanged.
pub struct CausalSmoother {
    method: Method,
    declared_rate_hz: Option<f64>,
    /// The first samples, until the grid's rate is known.
    first: Vec<(f64, UnitQuaternion<f64>)>,
    grid: Option<Grid>,
    /// The previous input sample, for slerping onto the grid.
    previous: Option<(f64, UnitQuaternion<f64>)>,
    /// Grid samples left unsmoothed by the guard.
    unsmoothed: usize,
    /// Why the sensor is not smoothed at all, if it is not.
    not_smoothed: Option<Unsmoothed>,
}

/// How many recent grid samples' turns the per-sample guard compares a filtered turn with.
pub const GUARD_SAMPLES: usize = 64;

/// The uniform grid and the filter running on it.
struct Grid {
    t0: f64,
    step: f64,
    /// The next grid sample to produce.
    next: u64,
    /// `None`: the low-pass has nothing to remove at this rate (passes grid samples unchanged).
    sos: Option<Vec<crate::smooth::butterworth::Sos>>,
    zi: Vec<[f64; 2]>,
    /// Per quaternion component (nalgebra's x, y, z, w), the filter state.
    state: [Vec<[f64; 2]>; 4],
    /// The previous grid sample in (sign-continuous) and out.
    last_in: Option<UnitQuaternion<f64>>,
    last_out: Option<UnitQuaternion<f64>>,
    /// The input's turns (radians) over the last [`GUARD_SAMPLES`] grid samples, a ring.
    recent_steps: [f64; GUARD_SAMPLES],
    steps_seen: usize,
}

impl CausalSmoother {
    /// A smoother for `method` (which must be causal: [`Method::to_causal`]); `rate_hz` the
    /// sensor's declared rate, if known.
    pub fn new(
        method: &Method,
        rate_hz: Option<f64>,
    ) -> Result<CausalSmoother, crate::smooth::NotCausal> {
        let method = method.to_causal()?;
        Ok(CausalSmoother {
            method,
            declared_rate_hz: rate_hz.filter(|r| r.is_finite() && *r > 0.0),
            first: Vec::new(),
            grid: None,
            previous: None,
            unsmoothed: 0,
            not_smoothed: None,
        })
    }

    /// Grid samples the guard left unsmoothed so far.
    pub fn unsmoothed(&self) -> usize {
        self.unsmoothed
    }

    /// Why the sensor was not smoothed at all (a single sample, a filter that cannot be made).
    pub fn not_smoothed(&self) -> Option<&Unsmoothed> {
        self.not_smoothed.as_ref()
    }

    /// Takes a sample (times increasing); appends the smoothed samples it completes to `out`.
    pub fn push(
        &mut self,
        t: f64,
        q: UnitQuaternion<f64>,
        out: &mut Vec<(f64, UnitQuaternion<f64>)>,
    ) {
        if self.method == Method::None {
            out.push((t, q));
            return;
        }
        if self.grid.is_none() {
            self.first.push((t, q));
            let rate = self
                .declared_rate_hz
                .or_else(|| (self.first.len() >= RATE_SAMPLES).then(|| mean_rate(&self.first)));
            if let Some(rate) = rate {
                self.start_grid(rate, out);
            }
            return;
        }
        self.advance(t, q, out);
    }

    /// The end of the sensor's samples: what is still held comes out.
    pub fn finish(&mut self, out: &mut Vec<(f64, UnitQuaternion<f64>)>) {
        if self.grid.is_some() || self.first.is_empty() {
            return;
        }
        if self.first.len() < 2 {
            self.not_smoothed = Some(Unsmoothed("a single sample cannot be smoothed".into()));
            out.append(&mut self.first);
            return;
        }
        let rate = mean_rate(&self.first);
        self.start_grid(rate, out);
    }

    fn start_grid(&mut self, rate_hz: f64, out: &mut Vec<(f64, UnitQuaternion<f64>)>) {
        let Method::Butterworth {
            order, cutoff_hz, ..
        } = self.method
        else {
            unreachable!("only Butterworth smooths causally")
        };
        let t0 = self.first[0].0;
        let sos = if cutoff_hz >= rate_hz / 2.0 {
            // A low-pass at or above half the rate has nothing to remove: the identity.
            None
        } else {
            match design_lowpass_sos(order, cutoff_hz, rate_hz) {
                Ok(sos) => Some(sos),
                Err(e) => {
                    self.not_smoothed = Some(Unsmoothed(format!(
                        "{} at {rate_hz:.1} Hz: {e}",
                        self.method
                    )));
                    None
                }
            }
        };
        let zi = match &sos {
            Some(sos) => sosfilt_zi(sos).unwrap_or_default(),
            None => Vec::new(),
        };
        self.grid = Some(Grid {
            t0,
            step: 1.0 / rate_hz,
            next: 0,
            sos,
            state: std::array::from_fn(|_| zi.clone()),
            zi,
            last_in: None,
            last_out: None,
            recent_steps: [0.0; GUARD_SAMPLES],
            steps_seen: 0,
        });
        let first = std::mem::take(&mut self.first);
        for (t, q) in first {
            self.advance(t, q, out);
        }
    }

    /// Produces the grid samples up to `t` (slerped between the previous sample and this one).
    fn advance(
        &mut self,
        t: f64,
        q: UnitQuaternion<f64>,
        out: &mut Vec<(f64, UnitQuaternion<f64>)>,
    ) {
        let grid = self.grid.as_mut().expect("the grid is started");
        if let Some((tp, qp)) = self.previous {
            loop {
                let tk = grid.t0 + grid.next as f64 * grid.step;
                if tk > t {
                    break;
                }
                let u = if t > tp { (tk - tp) / (t - tp) } else { 1.0 };
                let value = slerp_shortest(&qp, &q, u.clamp(0.0, 1.0));
                let (smoothed, kept) = grid.filter(value);
                self.unsmoothed += usize::from(!kept);
                out.push((tk, smoothed));
                grid.next += 1;
            }
        } else if grid.t0 == t {
            let (smoothed, kept) = grid.filter(q);
            self.unsmoothed += usize::from(!kept);
            out.push((t, smoothed));
            grid.next = 1;
        }
        self.previous = Some((t, q));
    }
}

impl Grid {
    /// Filters one grid sample; `false` when the guard kept the input instead.
    fn filter(&mut self, input: UnitQuaternion<f64>) -> (UnitQuaternion<f64>, bool) {
        // Sign-continuous with the previous input.
        let input = match self.last_in {
            Some(prev) if prev.coords.dot(&input.coords) < 0.0 => {
                UnitQuaternion::new_unchecked(-input.into_inner())
            }
            _ => input,
        };
        let Some(sos) = &self.sos else {
            self.last_in = Some(input);
            self.last_out = Some(input);
            return (input, true);
        };
        if self.last_in.is_none() {
            for (c, state) in self.state.iter_mut().enumerate() {
                for (z, zi) in state.iter_mut().zip(&self.zi) {
                    *z = [zi[0] * input.coords[c], zi[1] * input.coords[c]];
                }
            }
        }
        let mut f = [0.0; 4];
        for (c, state) in self.state.iter_mut().enumerate() {
            f[c] = sosfilt_step(sos, input.coords[c], state);
        }
        // nalgebra stores quaternions as (x, y, z, w).
        let filtered = Quaternion::new(f[3], f[0], f[1], f[2]);
        let norm = filtered.norm();
        let candidate = (norm.is_finite() && norm > 0.1)
            .then(|| UnitQuaternion::new_unchecked(filtered / norm));
        let step = |a: Option<UnitQuaternion<f64>>, b: &UnitQuaternion<f64>| {
            a.map_or(0.0, |a| 2.0 * a.coords.dot(&b.coords).abs().min(1.0).acos())
        };
        self.recent_steps[self.steps_seen % GUARD_SAMPLES] = step(self.last_in, &input);
        self.steps_seen += 1;
        let largest_in = self.recent_steps.iter().copied().fold(0.0, f64::max);
        let output = match candidate {
            Some(out) if step(self.last_out, &out) <= largest_in + MAX_ADDED_STEP_RAD => Some(out),
            _ => None,
        };
        self.last_in = Some(input);
        match output {
            Some(out) => {
                self.last_out = Some(out);
                (out, true)
            }
            None => {
                // Restart the filter in the steady state of this input.
                for (c, state) in self.state.iter_mut().enumerate() {
                    for (z, zi) in state.iter_mut().zip(&self.zi) {
                        *z = [zi[0] * input.coords[c], zi[1] * input.coords[c]];
                    }
                }
                self.last_out = Some(input);
                (input, false)
            }
        }
    }
}

/// The mean rate of samples, Hz.
fn mean_rate(samples: &[(f64, UnitQuaternion<f64>)]) -> f64 {
    let n = samples.len();
    (n - 1) as f64 / (samples[n - 1].0 - samples[0].0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A track of `n` samples at ~100 Hz with jittered times (and a 0.5 s gap in longer ones),
    /// turning about a wandering axis.
    fn wobbly_track(n: usize, seed: u64) -> Track<UnitQuaternion<f64>> {
        let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut jitter = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut t = seed as f64 * 0.37;
        let mut times = Vec::new();
        let mut values = Vec::new();
        for k in 0..n {
            t += 0.01 + 0.003 * jitter() + if k == n / 2 && n > 100 { 0.5 } else { 0.0 };
            times.push(t);
            let axis = Vector3::new(1.0, (t * 0.7).sin(), (t * 1.3).cos());
            let angle = (t * 2.1).sin() * 2.5 + 0.02 * jitter();
            values.push(UnitQuaternion::from_scaled_axis(axis.normalize() * angle));
        }
        Track::new(times, values).unwrap()
    }

    /// What the pipeline does per sensor with one `Scratch` for many tracks — smoothed, then
    /// slerped onto a frame grid in a kept vector, each track's memory handed on — gives to the bit
    /// what fresh memory gives for every track, whether the kept vectors are longer or shorter
    /// than the next track needs.
    #[test]
    fn tracks_smoothed_in_kept_memory_match_tracks_smoothed_in_fresh_memory() {
        let method = Method::default();
        let mut scratch = Scratch::default();
        for (i, n) in [3000, 700, 5000, 2, 1, 1500, 40, 4000]
            .into_iter()
            .enumerate()
        {
            let track = wobbly_track(n, i as u64 + 1);
            let frames: Vec<f64> = (0..(n * 3 / 5).max(1))
                .map(|f| track.first_time_s() + f as f64 / 60.0)
                .collect();

            let (fresh, fresh_why) =
                smooth_track(track.clone(), &method, None, &mut Scratch::default());
            let fresh_grid = fresh.resample_at(frames.iter().copied());

            let (kept, kept_why) = smooth_track(track, &method, None, &mut scratch);
            let mut grid = scratch.values();
            kept.resample_into(frames.iter().copied(), &mut grid);
            scratch.give(kept.clone());

            assert_eq!(fresh_why, kept_why, "track {i}");
            assert_eq!(fresh.times_s(), kept.times_s(), "track {i}");
            assert_eq!(fresh.values(), kept.values(), "track {i}");
            assert_eq!(fresh_grid, grid, "track {i}");
            assert!(scratch.spare_times.len() <= Scratch::SPARES);
            assert!(scratch.spare_values.len() <= Scratch::SPARES);
        }
    }
}
