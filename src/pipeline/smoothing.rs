//! The smoothing stage: rotation tracks smoothed without breaking them, with the filters of
//! [`crate::smooth`]: quaternions are made sign-continuous,
//! filtered per component and renormalised; Euler angles are filtered as (cos, sin) pairs and
//! turned back with atan2 (paper 002, 6.5), so 359° and 0° never average to 180°.
//!
//! Filters need uniform sampling, and sensors sample irregularly: a sensor's track is first
//! slerped onto a uniform grid at its own mean rate ([`uniform`]), smoothed there — at the sensor
//! rate, where averaging has the most samples to work with — and then resampled onto the frame
//! grid by the pipeline.

use crate::rotation::make_hemisphere_continuous;
use crate::smooth::Method;
use crate::smooth::butterworth::{design_lowpass_sos, sosfilt_with_state, sosfilt_zi, sosfiltfilt};
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
            let sos = design_lowpass_sos(*order, *cutoff_hz, rate_hz)
                .map_err(|e| Unsmoothed(format!("{method} at {rate_hz:.1} Hz: {e}")))?;
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
    if *method == Method::None {
        return Ok(());
    }
    make_hemisphere_continuous(values);
    let mut components = Vec::with_capacity(4);
    for c in 0..4 {
        let series: Vec<f64> = values.iter().map(|q| q.coords[c]).collect();
        components.push(smooth_series(&series, rate_hz, method)?);
    }
    let smoothed = |n: usize, input: &UnitQuaternion<f64>| {
        // nalgebra stores quaternions as (x, y, z, w).
        let f = Quaternion::new(
            components[3][n],
            components[0][n],
            components[1][n],
            components[2][n],
        );
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
    // smallest |dot| of neighbours (angle = 2·acos|dot|).
    let mut min_dot_in: f64 = 1.0;
    let mut min_dot_out: f64 = 1.0;
    let mut previous = None;
    for (n, input) in values.iter().enumerate() {
        let out = smoothed(n, input);
        if let Some((prev_in, prev_out)) = previous {
            min_dot_in = min_dot_in.min(input.coords.dot(&prev_in).abs());
            min_dot_out = min_dot_out.min(out.coords.dot(&prev_out).abs());
        }
        previous = Some((input.coords, out.coords));
    }
    let (step_in, step_out) = (
        2.0 * min_dot_in.min(1.0).acos(),
        2.0 * min_dot_out.min(1.0).acos(),
    );
    if step_out > step_in + MAX_ADDED_STEP_RAD {
        return Err(Unsmoothed(format!(
            "{method} would turn by up to {:.1}° between samples where the input turns by at most {:.1}°",
            step_out.to_degrees(),
            step_in.to_degrees()
        )));
    }
    for (n, q) in values.iter_mut().enumerate() {
        *q = smoothed(n, q);
    }
    Ok(())
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
/// of samples). `None` for a single sample.
pub fn uniform(track: &Track<UnitQuaternion<f64>>) -> Option<(f64, Track<UnitQuaternion<f64>>)> {
    let n = track.len();
    if n < 2 {
        return None;
    }
    let (first, last) = (track.first_time_s(), track.last_time_s());
    let step = (last - first) / (n - 1) as f64;
    let times: Vec<f64> = (0..n).map(|k| first + step * k as f64).collect();
    let values = track.resample_at(times.iter().copied());
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
/// and the reason when it cannot be smoothed.
pub fn smooth_track(
    track: Track<UnitQuaternion<f64>>,
    method: &Method,
) -> (Track<UnitQuaternion<f64>>, Option<Unsmoothed>) {
    if *method == Method::None {
        return (track, None);
    }
    let Some((rate, grid)) = uniform(&track) else {
        return (
            track,
            Some(Unsmoothed("a single sample cannot be smoothed".into())),
        );
    };
    drop(track);
    let (times, mut values) = grid.into_parts();
    let unsmoothed = smooth_quaternions_in_place(&mut values, rate, method).err();
    let track = Track::new(times, values).expect("the uniform grid's times are valid");
    (track, unsmoothed)
}
