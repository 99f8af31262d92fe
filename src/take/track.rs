//! A time series whose invariants are enforced by its constructor.

use crate::rotation::slerp_shortest;
use nalgebra::UnitQuaternion;
use std::fmt;

/// Samples at strictly increasing, finite times (seconds on the take's clock).
///
/// A `Track` is never empty and `times_s().len() == values().len()` always holds:
/// the only way to build one is [`Track::new`], which checks both.
#[derive(Clone, PartialEq)]
pub struct Track<T> {
    times_s: Vec<f64>,
    values: Vec<T>,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrackError {
    #[error("a track needs at least one sample")]
    Empty,
    #[error("{times} times but {values} values")]
    LengthMismatch { times: usize, values: usize },
    #[error("time at index {index} is not finite ({time})")]
    NonFinite { index: usize, time: f64 },
    #[error("times must strictly increase: index {index} has {time} s after {previous} s")]
    NotIncreasing {
        index: usize,
        previous: f64,
        time: f64,
    },
}

impl<T> Track<T> {
    pub fn new(times_s: Vec<f64>, values: Vec<T>) -> Result<Self, TrackError> {
        if times_s.len() != values.len() {
            return Err(TrackError::LengthMismatch {
                times: times_s.len(),
                values: values.len(),
            });
        }
        if times_s.is_empty() {
            return Err(TrackError::Empty);
        }
        for (index, &time) in times_s.iter().enumerate() {
            if !time.is_finite() {
                return Err(TrackError::NonFinite { index, time });
            }
            if index > 0 && time <= times_s[index - 1] {
                return Err(TrackError::NotIncreasing {
                    index,
                    previous: times_s[index - 1],
                    time,
                });
            }
        }
        Ok(Track { times_s, values })
    }

    pub fn times_s(&self) -> &[f64] {
        &self.times_s
    }

    pub fn values(&self) -> &[T] {
        &self.values
    }

    pub fn len(&self) -> usize {
        self.times_s.len()
    }

    /// Always false: kept for API symmetry with `len` (clippy's `len_without_is_empty`).
    pub fn is_empty(&self) -> bool {
        false
    }

    pub fn first_time_s(&self) -> f64 {
        self.times_s[0]
    }

    pub fn last_time_s(&self) -> f64 {
        self.times_s[self.times_s.len() - 1]
    }

    pub fn iter(&self) -> impl ExactSizeIterator<Item = (f64, &T)> {
        self.times_s.iter().copied().zip(self.values.iter())
    }

    /// Shifts every time by `-offset_s` (re-zeroing keeps the order, so the invariant holds).
    pub(crate) fn shift_times(&mut self, offset_s: f64) {
        for t in &mut self.times_s {
            *t -= offset_s;
        }
    }

    /// Keeps the samples at or after `start_s`; `None` when nothing is left.
    pub(crate) fn keep_from(self, start_s: f64) -> Option<Self> {
        let first = self.times_s.partition_point(|&t| t < start_s);
        if first == self.times_s.len() {
            return None;
        }
        let Track {
            mut times_s,
            mut values,
        } = self;
        times_s.drain(..first);
        values.drain(..first);
        Some(Track { times_s, values })
    }

    /// The times and values, taking the track apart.
    pub fn into_parts(self) -> (Vec<f64>, Vec<T>) {
        (self.times_s, self.values)
    }

    /// Transforms every value in place (the times, and so the invariants, are unchanged).
    pub fn map_in_place(mut self, f: impl Fn(&T) -> T) -> Track<T> {
        for v in &mut self.values {
            *v = f(v);
        }
        self
    }

    pub fn map<U>(&self, f: impl FnMut(&T) -> U) -> Track<U> {
        Track {
            times_s: self.times_s.clone(),
            values: self.values.iter().map(f).collect(),
        }
    }
}

/// Sampling a rotation track (as bevy's curve types carry their own sampling): slerp between the
/// bracketing samples, held at the first and last sample outside the track.
impl Track<UnitQuaternion<f64>> {
    /// The track's value at time `t`: slerp between the bracketing samples, held outside.
    pub fn sample_at(&self, t: f64) -> UnitQuaternion<f64> {
        let times = self.times_s();
        let values = self.values();
        match times.partition_point(|&x| x <= t) {
            0 => values[0],
            i if i == times.len() => values[i - 1],
            i => slerp_shortest(
                &values[i - 1],
                &values[i],
                (t - times[i - 1]) / (times[i] - times[i - 1]),
            ),
        }
    }

    /// The track at increasing times (slerp between the bracketing samples, held outside).
    pub fn resample_at(&self, times_s: impl IntoIterator<Item = f64>) -> Vec<UnitQuaternion<f64>> {
        let mut out = Vec::new();
        self.resample_into(times_s, &mut out);
        out
    }

    /// [`Self::resample_at`] into `out` (cleared first): memory a caller already has.
    pub fn resample_into(
        &self,
        times_s: impl IntoIterator<Item = f64>,
        out: &mut Vec<UnitQuaternion<f64>>,
    ) {
        let times = self.times_s();
        let values = self.values();
        let times_s = times_s.into_iter();
        out.clear();
        out.reserve(times_s.size_hint().0);
        // The times increase, so the bracketing sample only moves forward.
        let mut i = 0;
        for t in times_s {
            while i < times.len() && times[i] <= t {
                i += 1;
            }
            let q = if i == 0 {
                values[0]
            } else if i == times.len() {
                values[times.len() - 1]
            } else {
                let (t0, t1) = (times[i - 1], times[i]);
                slerp_shortest(&values[i - 1], &values[i], (t - t0) / (t1 - t0))
            };
            out.push(q);
        }
    }
}

impl<T> fmt::Debug for Track<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Track({} samples, {} s .. {} s)",
            self.len(),
            self.first_time_s(),
            self.last_time_s()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_empty_mismatched_nonfinite_and_unordered() {
        assert_eq!(Track::<u8>::new(vec![], vec![]), Err(TrackError::Empty));
        assert!(matches!(
            Track::new(vec![0.0], vec![1u8, 2]),
            Err(TrackError::LengthMismatch { .. })
        ));
        assert!(matches!(
            Track::new(vec![0.0, f64::NAN], vec![1u8, 2]),
            Err(TrackError::NonFinite { index: 1, .. })
        ));
        assert!(matches!(
            Track::new(vec![0.0, 0.0], vec![1u8, 2]),
            Err(TrackError::NotIncreasing { index: 1, .. })
        ));
        assert!(matches!(
            Track::new(vec![1.0, 0.5], vec![1u8, 2]),
            Err(TrackError::NotIncreasing { index: 1, .. })
        ));
    }

    #[test]
    fn keep_from_and_shift() {
        let mut t = Track::new(vec![0.0, 1.0, 2.0], vec!['a', 'b', 'c']).unwrap();
        t.shift_times(-1.0);
        assert_eq!(t.times_s(), &[1.0, 2.0, 3.0]);
        let t = t.keep_from(1.5).unwrap();
        assert_eq!(t.times_s(), &[2.0, 3.0]);
        assert_eq!(t.values(), &['b', 'c']);
        assert!(t.keep_from(3.5).is_none());
    }
}
