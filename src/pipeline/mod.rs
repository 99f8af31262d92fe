//! The conversion pipeline: a take and a mapping onto a rig → an [`Animation`] on a frame grid.
//!
//! Stages, each a small module with a pure function:
//! 1. [`calibrate`]: heading and mounts from the calibration window;
//! 2. bone world orientation `q_world_bone = H ⊗ C ⊗ q_world_sensor ⊗ q_bone_sensor⁻¹`, with `C`
//!    taking the sensors' world into the rig world ([`crate::world::World::to_rig`]);
//! 3. [`resample`] onto the frame grid (slerp; held outside each sensor's range);
//! 4. [`relative`]: local rotations `q_world_parent⁻¹ ⊗ q_world_bone`;
//! 5. [`root`]: the root position; `--trim` cuts the frame range.
//!
//! Euler angles (with the discontinuity filter) are made by the BVH writer's caller from the
//! animation's quaternions ([`crate::rotation::euler`]).

pub mod calibrate;
pub mod legacy;
pub mod relative;
pub mod resample;
pub mod root;

use crate::anim::{Animation, AnimationError};
use crate::fps::Fps;
use crate::mapping::{CalibrationWindow, Mapping, MappingError, Mount, ResolvedSensor};
use crate::rig::Rig;
use crate::smooth::Smoothing;
use crate::smooth::tracks::smooth_track;
use crate::take::{Take, Track};
use crate::world::World;
use calibrate::{Calibration, mean_rotation};
use nalgebra::UnitQuaternion;
use root::RootMode;
use std::path::Path;

/// A cut of the frame range, in seconds on the take's clock (both ends inclusive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trim {
    pub start_s: f64,
    pub end_s: f64,
}

impl std::fmt::Display for Trim {
    /// `start:end` as given, an open end left empty.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:", self.start_s)?;
        if self.end_s < f64::MAX {
            write!(f, "{}", self.end_s)?;
        }
        Ok(())
    }
}

impl std::str::FromStr for Trim {
    type Err = String;
    /// `start:end` in seconds; either side may be empty (`:10`, `2.5:`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (a, b) = s
            .split_once(':')
            .ok_or_else(|| format!("`{s}`: expected START:END in seconds, e.g. 2.5:10"))?;
        let parse = |v: &str, default: f64| -> Result<f64, String> {
            if v.trim().is_empty() {
                return Ok(default);
            }
            match v.trim().parse::<f64>() {
                Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
                _ => Err(format!("`{v}` in `{s}` is not a number of seconds ≥ 0")),
            }
        };
        let trim = Trim {
            start_s: parse(a, 0.0)?,
            end_s: parse(b, f64::MAX)?,
        };
        if trim.end_s < trim.start_s {
            return Err(format!("`{s}`: the end is before the start"));
        }
        Ok(trim)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct PipelineOptions {
    pub fps: Fps,
    pub trim: Option<Trim>,
    pub root: RootMode,
    pub smoothing: Smoothing,
    /// Also produce the local rotations without smoothing (for the report).
    pub keep_unsmoothed: bool,
    /// Allow more than [`MAX_KEYFRAMES`] keyframes.
    pub force: bool,
    /// The sensors' world when the user set it (`--world`, the config file): over the mapping's
    /// and the take's.
    pub world: Option<World>,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        PipelineOptions {
            fps: Fps::new(30, 1).expect("30 fps"),
            trim: None,
            root: RootMode::Fixed,
            smoothing: Smoothing::default(),
            keep_unsmoothed: false,
            force: false,
            world: None,
        }
    }
}

/// What the pipeline produced, and how.
#[derive(Debug, Clone)]
pub struct Converted {
    pub animation: Animation,
    /// The sensors that drove bones, in mapping order (mounts in `calibration.mounts`).
    pub sensors: Vec<ResolvedSensor>,
    pub calibration: Calibration,
    /// The calibration window used, if any.
    pub window: Option<CalibrationWindow>,
    pub world: World,
    /// Frame of the take's grid that became frame 0 (non-zero after `--trim`).
    pub first_frame: usize,
    /// `local[joint][frame]` before smoothing, when asked for (`keep_unsmoothed`).
    pub unsmoothed: Option<Vec<Vec<UnitQuaternion<f64>>>>,
    pub warnings: Vec<String>,
}

#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Mapping(#[from] MappingError),
    #[error(
        "none of the mapped sensors ({mapped}) has orientation data in the take (sensors in the take: {present}); check the mapping's sensor ids"
    )]
    NoSensors { mapped: String, present: String },
    #[error(
        "{file}: `calibration`: the window {start_s} s + {duration_s} s is outside the take, which ends at {end_s:.3} s"
    )]
    CalibrationOutside {
        file: String,
        start_s: f64,
        duration_s: f64,
        end_s: f64,
    },
    #[error("{file}: `calibration.pose`: rig `{rig}` has no pose `{pose}`; it has {known}")]
    UnknownPose {
        file: String,
        rig: String,
        pose: String,
        known: String,
    },
    #[error("--trim {trim} keeps no frame of the take (frames run from 0 s to {end_take_s:.3} s)")]
    EmptyTrim { trim: Trim, end_take_s: f64 },
    #[error(
        "--fps {fps} over {frames} frames × {joints} joints is {cells} keyframes (about {mb} MB of BVH), \
         more than the {max} allowed without --force. Hint: a lower --fps (the fastest mapped sensor \
         samples at {sensor_hz:.1} Hz), or --force"
    )]
    TooManyFrames {
        fps: Fps,
        frames: usize,
        joints: usize,
        cells: usize,
        mb: usize,
        max: usize,
        sensor_hz: f64,
    },
    #[error(transparent)]
    Animation(#[from] AnimationError),
}

/// The mean orientation of a track over [start, start + duration]; the value interpolated at the
/// window's middle when no sample falls inside.
fn held_over(
    track: &Track<UnitQuaternion<f64>>,
    window: &CalibrationWindow,
) -> UnitQuaternion<f64> {
    let end = window.start_s + window.duration_s;
    let inside: Vec<UnitQuaternion<f64>> = track
        .iter()
        .filter(|(t, _)| *t >= window.start_s && *t <= end)
        .map(|(_, q)| *q)
        .collect();
    if inside.is_empty() {
        return resample::sample_at(track, window.start_s + window.duration_s / 2.0);
    }
    mean_rotation(&inside)
}

/// A sensor turning further than this from its mean during the calibration window is reported.
const MOVED_DURING_CALIBRATION_DEG: f64 = 5.0;

/// How long after the calibration window the walk is read for the heading from travel.
const TRAVEL_WINDOW_S: f64 = 4.0;

/// A joint whose own offset and whose child (or end site) both point down at rest: a knee-like
/// joint (the thigh → shank link of a leg), for the heading from travel.
fn is_shank(rig: &Rig, joint: usize) -> bool {
    let down = |v: &nalgebra::Vector3<f64>| v.norm() > 0.0 && -v.y > 0.8 * v.norm();
    let j = &rig.joints()[joint];
    let below = rig
        .children(joint)
        .map(|c| rig.joints()[c].offset)
        .chain(j.end_site);
    j.parent.is_some() && down(&j.offset) && below.into_iter().any(|v| down(&v))
}

/// For every mapped thigh–shank pair, both sensors' rotations since calibration (rig world) at
/// the shank's samples in the seconds after the window.
fn knee_samples(
    rig: &Rig,
    sensors: &[ResolvedSensor],
    tracks: &[Track<UnitQuaternion<f64>>],
    held: &[UnitQuaternion<f64>],
    window: &CalibrationWindow,
) -> Vec<Vec<(UnitQuaternion<f64>, UnitQuaternion<f64>)>> {
    let start = window.start_s + window.duration_s;
    let end = start + TRAVEL_WINDOW_S;
    let mut legs = Vec::new();
    for (s, shank) in sensors.iter().enumerate() {
        let Some(parent) = rig.joints()[shank.bone].parent else {
            continue;
        };
        let Some(t) = sensors.iter().position(|o| o.bone == parent) else {
            continue;
        };
        if !is_shank(rig, shank.bone) {
            continue;
        }
        let leg = tracks[s]
            .iter()
            .filter(|(time, _)| *time > start && *time <= end)
            .map(|(time, q)| {
                let thigh = resample::sample_at(&tracks[t], time);
                (thigh * held[t].inverse(), q * held[s].inverse())
            })
            .collect();
        legs.push(leg);
    }
    legs
}

/// A warning for each sensor of the take that the mapping does not use.
pub(crate) fn unmapped_sensors(take: &Take, is_mapped: impl Fn(&str) -> bool) -> Vec<String> {
    take.sensors()
        .iter()
        .filter(|s| !is_mapped(s.id()))
        .map(|s| format!("sensor {} is not in the mapping; ignored", s.id()))
        .collect()
}

/// The error when none of the mapped sensors can drive a bone.
pub(crate) fn no_sensors<'a>(take: &Take, mapped: impl Iterator<Item = &'a str>) -> PipelineError {
    PipelineError::NoSensors {
        mapped: mapped.collect::<Vec<_>>().join(", "),
        present: take
            .sensors()
            .iter()
            .map(|s| s.id())
            .collect::<Vec<_>>()
            .join(", "),
    }
}

/// The frames of the grid kept, `(first, count)`: frames 0 ..= floor(t_last · fps), cut by
/// `trim` (both ends inclusive).
pub(crate) fn frame_range(
    fps: Fps,
    t_last: f64,
    trim: Option<Trim>,
) -> Result<(usize, usize), PipelineError> {
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
/// `options.force`.
fn check_frame_rate(
    options: &PipelineOptions,
    times: &[&[f64]],
    frames: usize,
    joints: usize,
    warnings: &mut Vec<String>,
) -> Result<(), PipelineError> {
    let fastest = times
        .iter()
        .filter_map(|t| mean_rate_hz(t))
        .fold(0.0, f64::max);
    let fps = options.fps.as_f64();
    if fastest > 0.0 && fps > 2.0 * fastest {
        warnings.push(format!(
            "--fps {} is more than twice the fastest mapped sensor's rate ({fastest:.1} Hz): most \
             frames are interpolated between samples",
            options.fps
        ));
    }
    let cells = frames.saturating_mul(joints);
    if cells > MAX_KEYFRAMES && !options.force {
        return Err(PipelineError::TooManyFrames {
            fps: options.fps,
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
fn long_gaps(
    sensors: &[&str],
    times: &[&[f64]],
    fps: Fps,
    first: usize,
    frames: usize,
) -> Vec<String> {
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

/// Maps `f` over `items` on up to as many threads as there are cores, keeping the order.
fn parallel_map<T: Send, R: Send>(items: Vec<T>, f: impl Fn(T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(items.len().max(1));
    if threads <= 1 {
        return items.into_iter().map(f).collect();
    }
    let mut chunks: Vec<Vec<(usize, T)>> = (0..threads).map(|_| Vec::new()).collect();
    for (i, item) in items.into_iter().enumerate() {
        chunks[i % threads].push((i, item));
    }
    let f = &f;
    let mut results: Vec<(usize, R)> = std::thread::scope(|scope| {
        let handles: Vec<_> = chunks
            .into_iter()
            .map(|chunk| {
                scope.spawn(move || {
                    chunk
                        .into_iter()
                        .map(|(i, t)| (i, f(t)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| {
                h.join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })
            .collect()
    });
    results.sort_by_key(|(i, _)| *i);
    results.into_iter().map(|(_, r)| r).collect()
}

/// Runs the pipeline. `mapping_file` names the mapping in errors.
pub fn run(
    take: &Take,
    rig: &Rig,
    mapping: &Mapping,
    mapping_file: &Path,
    options: &PipelineOptions,
) -> Result<Converted, PipelineError> {
    let file = mapping_file.display().to_string();
    let mut warnings = Vec::new();
    let world = options
        .world
        .or(mapping.world)
        .unwrap_or(take.source().world);
    let to_rig = world.to_rig();
    let resolved = mapping.resolve(rig, mapping_file)?;

    let mut sensors = Vec::new();
    let mut tracks = Vec::new();
    for s in resolved {
        let bone = &rig.joints()[s.bone].name;
        match take.sensor(&s.sensor).map(|t| t.orientation()) {
            None => warnings.push(format!(
                "sensor `{}` (mapped to `{bone}`) is not in the take; `{bone}` keeps its rest rotation",
                s.sensor
            )),
            Some(None) => warnings.push(format!(
                "sensor `{}` has raw readings only and fusion is not enabled; `{bone}` keeps its rest rotation",
                s.sensor
            )),
            Some(Some(o)) => {
                tracks.push(o.to_quaternions().map_in_place(|q| to_rig * q));
                sensors.push(s);
            }
        }
    }
    warnings.extend(unmapped_sensors(take, |id| {
        mapping.sensors.iter().any(|m| m.sensor == id)
    }));
    if sensors.is_empty() {
        return Err(no_sensors(
            take,
            mapping.sensors.iter().map(|s| s.sensor.as_str()),
        ));
    }

    // 1. Calibration.
    let needs_window = sensors.iter().any(|s| s.mount == Mount::Calibrate);
    let window = match (&mapping.calibration, needs_window) {
        (Some(w), _) => Some(w.clone()),
        (None, true) => {
            let w = CalibrationWindow::default();
            warnings.push(format!(
                "the mapping has `calibrate` mounts but no `calibration`; assuming the subject holds the rig's rest pose for the first {} s",
                w.duration_s
            ));
            Some(w)
        }
        (None, false) => None,
    };
    let calibration = match &window {
        Some(w) => {
            let end_s = take.last_time_s();
            if w.start_s > end_s {
                return Err(PipelineError::CalibrationOutside {
                    file,
                    start_s: w.start_s,
                    duration_s: w.duration_s,
                    end_s,
                });
            }
            let pose = rig
                .pose(&w.pose.label())
                .ok_or_else(|| PipelineError::UnknownPose {
                    file: file.clone(),
                    rig: rig.name().to_string(),
                    pose: w.pose.label(),
                    known: rig.pose_names().join(", "),
                })?;
            let pose_world_all = rig.world_rotations(&pose.local);
            let pose_world: Vec<_> = sensors.iter().map(|s| pose_world_all[s.bone]).collect();
            let held: Vec<_> = tracks.iter().map(|t| held_over(t, w)).collect();
            for ((s, track), mean) in sensors.iter().zip(&tracks).zip(&held) {
                let moved = track
                    .iter()
                    .filter(|(t, _)| *t >= w.start_s && *t <= w.start_s + w.duration_s)
                    .map(|(_, q)| crate::rotation::angle_between(q, mean))
                    .fold(0.0, f64::max)
                    .to_degrees();
                if moved > MOVED_DURING_CALIBRATION_DEG {
                    warnings.push(format!(
                        "sensor `{}` moved by up to {moved:.1}° during the calibration window ({} s to {} s); its mount may be off: check the mapping's `calibration`",
                        s.sensor,
                        w.start_s,
                        w.start_s + w.duration_s
                    ));
                }
            }
            let travel =
                calibrate::heading_from_knees(&knee_samples(rig, &sensors, &tracks, &held, w));
            calibrate::solve(&sensors, &held, &pose_world, travel)
        }
        None => Calibration {
            heading: UnitQuaternion::identity(),
            heading_source: calibrate::HeadingSource::None,
            mounts: sensors
                .iter()
                .map(|s| match s.mount {
                    Mount::Fixed(q) => q,
                    Mount::Calibrate => UnitQuaternion::identity(),
                })
                .collect(),
            warnings: Vec::new(),
        },
    };
    warnings.extend(calibration.warnings.iter().cloned());

    // 2. Bone world orientations on each sensor's own sample times.
    let heading = calibration.heading;
    let bone_tracks: Vec<Track<UnitQuaternion<f64>>> = tracks
        .into_iter()
        .zip(&calibration.mounts)
        .map(|(t, mount)| {
            let inv = mount.inverse();
            t.map_in_place(|q| heading * q * inv)
        })
        .collect();

    // 3. The frame grid, trimmed, and resampling.
    let t_last = bone_tracks
        .iter()
        .map(|t| t.last_time_s())
        .fold(0.0, f64::max);
    let (first, frames) = frame_range(options.fps, t_last, options.trim)?;
    let times: Vec<&[f64]> = bone_tracks.iter().map(|t| t.times_s()).collect();
    check_frame_rate(options, &times, frames, rig.len(), &mut warnings)?;
    let names: Vec<&str> = sensors.iter().map(|s| s.sensor.as_str()).collect();
    warnings.extend(long_gaps(&names, &times, options.fps, first, frames));
    // Per sensor (independent, so spread over the cores): 3b. smoothing at the sensor's own rate
    // (smooth::tracks explains why), then resampling onto the frame grid.
    let per_sensor = parallel_map(sensors.iter().zip(bone_tracks).collect(), |(s, track)| {
        let raw = options
            .keep_unsmoothed
            .then(|| resample::resample(&track, options.fps, first, frames));
        let bone = &rig.joints()[s.bone].name;
        let (track, unsmoothed) = smooth_track(track, options.smoothing.for_bone(bone));
        let grid = resample::resample(&track, options.fps, first, frames);
        (
            s.bone,
            grid,
            raw,
            unsmoothed.map(|why| (bone.clone(), why.0)),
        )
    });
    let mut world_tracks = vec![None; rig.len()];
    let mut raw_tracks = options.keep_unsmoothed.then(|| vec![None; rig.len()]);
    let mut not_smoothed: Vec<(String, String)> = Vec::new();
    for (bone, grid, raw, unsmoothed) in per_sensor {
        world_tracks[bone] = Some(grid);
        if let (Some(all), Some(raw)) = (&mut raw_tracks, raw) {
            all[bone] = Some(raw);
        }
        not_smoothed.extend(unsmoothed);
    }

    // One warning for a reason many bones share (a low sensor rate, a short take).
    if let Some((_, first_reason)) = not_smoothed.first() {
        if not_smoothed.len() > 3 {
            let bones: Vec<&str> = not_smoothed.iter().map(|(b, _)| b.as_str()).collect();
            warnings.push(format!(
                "{} bones are not smoothed ({}), e.g. because {first_reason}",
                bones.len(),
                bones.join(", ")
            ));
        } else {
            for (bone, why) in &not_smoothed {
                warnings.push(format!("`{bone}` is not smoothed: {why}"));
            }
        }
    }

    // 4. Local rotations; 5. root.
    let local = relative::to_local(rig, &world_tracks, frames);
    let unsmoothed = raw_tracks.map(|raw| relative::to_local(rig, &raw, frames));
    let animated = world_tracks.iter().map(Option::is_some).collect();
    drop(world_tracks);
    let roots = root::root_positions(rig, options.root, frames);
    let animation = Animation::new(rig.clone(), options.fps, local, animated, roots)?;
    Ok(Converted {
        animation,
        sensors,
        calibration,
        window,
        world,
        first_frame: first,
        unsmoothed,
        warnings,
    })
}
