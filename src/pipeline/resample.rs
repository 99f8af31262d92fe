//! Resampling rotation tracks onto the take's frame grid (conventions.md, "Time and frames"):
//! slerp between the two nearest samples, held at the first/last sample outside the track
//! ([`Track::resample_at`]).

use super::{PipelineError, Trim};
use crate::fps::Fps;
use crate::rotation::slerp_shortest;
use crate::take::Track;
use nalgebra::UnitQuaternion;
use std::collections::VecDeque;

/// `track` at the frames of `grid`.
pub fn resample(track: &Track<UnitQuaternion<f64>>, grid: &FrameGrid) -> Vec<UnitQuaternion<f64>> {
    track.resample_at(grid.times_s())
}

/// The frames an animation covers: frames `first .. first + frames` of the take's grid
/// (conventions.md: frame n at n / fps, from 0 to floor(t_last · fps)); `first` > 0 after
/// `--trim`. Its frame 0 is the grid's frame `first`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameGrid {
    pub fps: Fps,
    pub first: usize,
    pub frames: usize,
}

impl FrameGrid {
    /// Frames 0 ..= floor(t_last · fps), cut by `trim` (both ends inclusive).
    pub fn new(fps: Fps, t_last: f64, trim: Option<Trim>) -> Result<FrameGrid, PipelineError> {
        let (first, frames) = frame_range(fps, t_last, trim)?;
        Ok(FrameGrid { fps, first, frames })
    }

    /// The take-clock times of the frames, in order.
    pub fn times_s(&self) -> impl ExactSizeIterator<Item = f64> + '_ {
        (self.first..self.first + self.frames).map(|n| self.fps.frame_time_of(n as u64))
    }
}

fn frame_range(fps: Fps, t_last: f64, trim: Option<Trim>) -> Result<(usize, usize), PipelineError> {
    let total = fps.frame_count(t_last) as usize;
    let Some(trim) = trim else {
        return Ok((0, total));
    };
    let first = fps.first_frame_at_or_after(trim.start_s) as usize;
    let last = (fps
        .last_frame_at_or_before(trim.end_s.min(1e12))
        .unwrap_or(0) as usize)
        .min(total - 1);
    if first > last || first >= total {
        return Err(PipelineError::EmptyTrim {
            trim,
            end_take_s: fps.frame_time_of(total as u64 - 1),
        });
    }
    Ok((first, last - first + 1))
}

/// Frames × joints above this (about 1 GB of BVH) are refused unless `force`.
pub const MAX_KEYFRAMES: usize = 50_000_000;

/// A gap in a sensor's samples longer than this is a warning naming the frames interpolated
/// across it.
pub const LONG_GAP_S: f64 = 1.0;

/// The mean rate of a track's sample times, Hz (`None` for a single sample).
fn mean_rate_hz(times: &[f64]) -> Option<f64> {
    let n = times.len();
    (n > 1 && times[n - 1] > times[0]).then(|| (n - 1) as f64 / (times[n - 1] - times[0]))
}

/// Warns when the frame rate is more than twice the fastest mapped sensor's (the frames between
/// samples are interpolation, not data); refuses more than [`MAX_KEYFRAMES`] keyframes unless
/// `force`.
pub fn check_frame_rate(
    grid: &FrameGrid,
    force: bool,
    times: &[&[f64]],
    joints: usize,
    warnings: &mut Vec<String>,
) -> Result<(), PipelineError> {
    let FrameGrid {
        fps: rate, frames, ..
    } = *grid;
    let fastest = times
        .iter()
        .filter_map(|t| mean_rate_hz(t))
        .fold(0.0, f64::max);
    if fastest > 0.0 && rate.as_f64() > 2.0 * fastest {
        warnings.push(format!(
            "--fps {rate} is more than twice the fastest mapped sensor's rate ({fastest:.1} Hz): most \
             frames are interpolated between samples"
        ));
    }
    let cells = frames.saturating_mul(joints);
    if cells > MAX_KEYFRAMES && !force {
        return Err(PipelineError::TooManyFrames {
            fps: rate,
            frames,
            joints,
            cells,
            // About 22 bytes per keyframe of text in the BVH.
            mb: cells / 1_000_000 * 22,
            max: MAX_KEYFRAMES,
            sensor_hz: fastest,
        });
    }
    Ok(())
}

/// A warning for each stretch longer than [`LONG_GAP_S`] in which a mapped sensor has no sample,
/// naming the frames interpolated across it (frame numbers of the output, after `--trim`); gaps
/// that all sensors share are one warning.
pub fn long_gaps(sensors: &[&str], times: &[&[f64]], grid: &FrameGrid) -> Vec<String> {
    let FrameGrid { fps, first, frames } = *grid;
    // (start, end) → sensors, in order of first appearance.
    let mut gaps: Vec<((f64, f64), Vec<&str>)> = Vec::new();
    for (id, t) in sensors.iter().zip(times) {
        for w in t.windows(2).filter(|w| w[1] - w[0] > LONG_GAP_S) {
            let key = (w[0], w[1]);
            // The same stretch in another sensor (within a sample's worth) counts as one gap.
            match gaps
                .iter_mut()
                .find(|(k, _)| (k.0 - key.0).abs() < 0.1 && (k.1 - key.1).abs() < 0.1)
            {
                Some((_, ids)) => ids.push(id),
                None => gaps.push((key, vec![id])),
            }
        }
    }
    let last_frame = first + frames - 1;
    gaps.into_iter()
        .filter_map(|((start, end), ids)| {
            // Frames strictly inside the gap, on the output's numbering.
            let a = (fps.first_frame_at_or_after(start) as usize).max(first);
            let b = (fps.last_frame_at_or_before(end)? as usize).min(last_frame);
            let inside = if a > b {
                "no frame falls inside it".to_string()
            } else {
                format!(
                    "frames {}–{} are interpolated across it",
                    a - first,
                    b - first
                )
            };
            let who = if ids.len() == sensors.len() && sensors.len() > 1 {
                "all sensors".to_string()
            } else if ids.len() <= 4 {
                format!(
                    "sensor{} {}",
                    if ids.len() == 1 { "" } else { "s" },
                    ids.join(", ")
                )
            } else {
                format!("{} sensors ({}, …)", ids.len(), ids[..3].join(", "))
            };
            Some(format!(
                "a {:.1} s gap in {who} from {start:.3} s to {end:.3} s: {inside}",
                end - start
            ))
        })
        .collect()
}

/// The incremental core of resampling: each sensor's (smoothed) samples in, frames out. Frame
/// n (at n / fps) comes out once every sensor has a sample at or after its time, or has been
/// declared stale (no sample for [`FrameResampler::stale_after_s`] of stream time: it is then
/// held at its last sample, and picked up again when it returns); a sensor with no sample yet is
/// absent (`None`) once stale. The value is as [`Track::resample_at`]'s: slerp between the
/// bracketing samples, held before the first and after the last; a frame exactly on a sample
/// takes the sample.
pub struct FrameResampler {
    fps: Fps,
    /// The next frame to emit.
    next: u64,
    /// Per sensor, its samples from the one bracketing the next frame on.
    queues: Vec<VecDeque<(f64, UnitQuaternion<f64>)>>,
    /// Per sensor, the time of its latest input sample (before smoothing), for staleness.
    last_input_s: Vec<Option<f64>>,
    /// The latest time any sensor has reached.
    stream_s: f64,
    /// Sensors whose samples have ended (at the end of a take).
    ended: Vec<bool>,
    pub stale_after_s: f64,
}

/// How long a sensor may be silent before frames go on without it.
pub const DEFAULT_STALE_AFTER_S: f64 = 0.5;

impl FrameResampler {
    pub fn new(fps: Fps, sensors: usize) -> FrameResampler {
        FrameResampler {
            fps,
            next: 0,
            queues: (0..sensors).map(|_| VecDeque::new()).collect(),
            last_input_s: vec![None; sensors],
            stream_s: f64::NEG_INFINITY,
            ended: vec![false; sensors],
            stale_after_s: DEFAULT_STALE_AFTER_S,
        }
    }

    /// The next frame to come out.
    pub fn next_frame(&self) -> u64 {
        self.next
    }

    /// Notes that `sensor` delivered an input sample at `t` (stream time moves on).
    pub fn saw_input(&mut self, sensor: usize, t: f64) {
        self.last_input_s[sensor] = Some(t);
        self.stream_s = self.stream_s.max(t);
    }

    /// A (smoothed) sample of `sensor`; times increase per sensor.
    pub fn push(&mut self, sensor: usize, t: f64, q: UnitQuaternion<f64>) {
        self.queues[sensor].push_back((t, q));
    }

    /// The sensor's samples have ended: frames after its last sample hold it.
    pub fn end(&mut self, sensor: usize) {
        self.ended[sensor] = true;
    }

    /// Whether `sensor` has been silent longer than [`FrameResampler::stale_after_s`] of stream
    /// time (or has sent nothing after that long).
    pub fn is_stale(&self, sensor: usize) -> bool {
        match self.last_input_s[sensor] {
            Some(t) => self.stream_s - t > self.stale_after_s,
            None => self.stream_s > self.stale_after_s,
        }
    }

    /// Whether every sensor is ready for frame time `t`.
    fn ready(&self, t: f64) -> bool {
        (0..self.queues.len()).all(|s| {
            self.ended[s]
                || self.is_stale(s)
                || self.queues[s].back().is_some_and(|&(last, _)| last >= t)
        })
    }

    /// Emits the frames that are ready, up to `last_frame` (inclusive) when given: for each,
    /// every sensor's value (`None`: no sample yet) goes to `frame(n, values)`.
    pub fn emit(
        &mut self,
        last_frame: Option<u64>,
        values: &mut [Option<UnitQuaternion<f64>>],
        mut frame: impl FnMut(u64, &[Option<UnitQuaternion<f64>>]),
    ) {
        loop {
            if last_frame.is_some_and(|l| self.next > l) {
                return;
            }
            let t = self.fps.frame_time_of(self.next);
            if !self.ready(t) {
                return;
            }
            for (s, queue) in self.queues.iter_mut().enumerate() {
                // Drop samples no later frame needs: keep the last one at or before `t`.
                while queue.len() >= 2 && queue[1].0 <= t {
                    queue.pop_front();
                }
                // At or before the first sample, and after the last: held. A frame exactly on a
                // sample takes it as it is, whether or not the next sample has come yet.
                values[s] = match (queue.front(), queue.get(1)) {
                    (None, _) => None,
                    (Some(&(t0, q0)), Some(&(t1, q1))) if t > t0 => {
                        Some(slerp_shortest(&q0, &q1, (t - t0) / (t1 - t0)))
                    }
                    (Some(&(_, q0)), _) => Some(q0),
                };
            }
            frame(self.next, values);
            self.next += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn about_y(deg: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), deg.to_radians())
    }

    #[test]
    fn uniform_track_at_its_own_rate_is_the_identity() {
        let fps: Fps = "50".parse().unwrap();
        let times: Vec<f64> = (0..100).map(|n| fps.frame_time_of(n)).collect();
        let values: Vec<_> = (0..100).map(|n| about_y(n as f64 * 7.3)).collect();
        let track = Track::new(times, values.clone()).unwrap();
        let grid = FrameGrid {
            fps,
            first: 0,
            frames: 100,
        };
        let out = resample(&track, &grid);
        for (a, b) in out.iter().zip(&values) {
            assert!(a.angle_to(b) < 1e-12);
        }
    }

    #[test]
    fn slerp_midpoint_holds_and_shortest_arc_by_hand() {
        let track = Track::new(vec![0.1, 0.3], vec![about_y(10.0), about_y(50.0)]).unwrap();
        let grid = FrameGrid {
            fps: "10".parse().unwrap(),
            first: 0,
            frames: 5,
        };
        let out = resample(&track, &grid);
        // Frames at 0.0 (held), 0.1, 0.2 (midway: 30°), 0.3, 0.4 (held).
        let deg: Vec<f64> = out.iter().map(|q| q.angle().to_degrees()).collect();
        for (a, b) in deg.iter().zip([10.0, 10.0, 30.0, 50.0, 50.0]) {
            assert!((a - b).abs() < 1e-9, "{deg:?}");
        }
        // 170° and -170° are 20° apart through 180°.
        let m = crate::rotation::slerp_shortest(&about_y(170.0), &about_y(-170.0), 0.5);
        assert!(m.angle_to(&about_y(180.0)) < 1e-9);
        // Exactly opposite rotations do not panic.
        let q = crate::rotation::slerp_shortest(&about_y(0.0), &about_y(180.0), 0.5);
        assert!((q.angle().to_degrees() - 90.0).abs() < 1e-9);
    }
}
