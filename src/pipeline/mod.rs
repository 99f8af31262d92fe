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

pub mod bone_world;
pub mod calibrate;
pub mod legacy;
pub mod relative;
pub mod resample;
pub mod root;
pub mod smoothing;
pub mod sources;
pub mod stream;

use crate::anim::{Animation, AnimationBuilder, AnimationError, Pose};
use crate::fps::Fps;
use crate::mapping::{CalibrationWindow, Mapping, MappingError, ResolvedSensor};
use crate::rig::Rig;
use crate::smooth::Smoothing;
use crate::take::Take;
use crate::world::World;
use calibrate::Calibration;
use nalgebra::UnitQuaternion;
use resample::FrameGrid;
use root::RootMode;
use smoothing::smooth_track;
use sources::{Sources, TakeInput};
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
    /// Causal mode: the take runs through the stream's incremental cores ([`stream`]), as a live
    /// capture would: smoothing causal, no heading from the direction of travel.
    pub causal: bool,
    /// The sensors' sample rate, when known: causal smoothing's grid uses it instead of the rate
    /// of each sensor's first samples.
    pub sensor_rate_hz: Option<f64>,
    /// Fusion asked for (`--fusion`): every sensor with raw readings is fused with it, even when
    /// the device gave an orientation. `None`: device orientations where there are some, the
    /// default filter for sensors with raw readings only.
    pub fusion: Option<crate::fusion::Fusion>,
    /// What joints without a sensor do (`--unsensed`).
    pub unsensed: relative::Unsensed,
    /// Corrections of raw readings before fusion, per sensor id (`--sensor-calibration`).
    pub sensor_calibration: Option<std::sync::Arc<crate::intrinsics::SensorCalibration>>,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        PipelineOptions {
            fps: Fps::new(30, 1).expect("30 fps"),
            trim: None,
            root: RootMode::Auto,
            smoothing: Smoothing::default(),
            keep_unsmoothed: false,
            force: false,
            world: None,
            causal: false,
            sensor_rate_hz: None,
            fusion: None,
            unsensed: relative::Unsensed::Interpolate,
            sensor_calibration: None,
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
    /// The device orientations' world (fused sensors are in `enu`: `origins`).
    pub world: World,
    /// Where each of `sensors` got its orientation.
    pub origins: Vec<sources::Origin>,
    /// The filter, when any sensor was fused.
    pub fusion: Option<crate::fusion::Fusion>,
    /// Frame of the take's grid that became frame 0 (non-zero after `--trim`).
    pub first_frame: usize,
    /// The root mode that ran (`auto` resolved), and the feet's contacts in `feet` mode.
    pub root_mode: RootMode,
    pub contacts: Option<root::Contacts>,
    /// `local[joint][frame]` before smoothing, when asked for (`keep_unsmoothed`).
    pub unsmoothed: Option<Vec<Vec<UnitQuaternion<f64>>>>,
    pub warnings: Vec<String>,
}

#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Mapping(#[from] MappingError),
    /// Boxed: five strings would make every `Result` of the pipeline large.
    #[error(transparent)]
    MissingPart(Box<crate::rig::anatomy::MissingPart>),
    #[error(
        "none of the mapped sensors ({mapped}) has orientation or raw readings in the take (sensors in the take: {present}); check the mapping's sensor ids"
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
    Fusion(#[from] crate::fusion::FusionError),
    #[error("`{bone}`: {reason}")]
    NotCausal { bone: String, reason: String },
    #[error(transparent)]
    Animation(#[from] AnimationError),
}

/// Maps `f` over `items` on up to as many threads as there are cores, keeping the order.
fn parallel_map<T: Send, R: Send>(items: Vec<T>, f: impl Fn(T) -> R + Sync) -> Vec<R> {
    parallel_map_with(items, |_: &mut (), item| f(item))
}

/// [`parallel_map`] where each thread keeps its own `S` (working memory, say) from item to
/// item, made with `S::default()` and dropped when its items are done.
///
/// Each thread takes the next item not yet taken when it finishes one, rather than a share
/// dealt out first: items do not cost the same (a sensor fused from its rest, another through
/// VQF's passes), and on a shared machine one thread can be held up, so a fixed share can
/// leave a core idle while the other works through the rest of its own.
fn parallel_map_with<T: Send, R: Send, S: Default>(
    items: Vec<T>,
    f: impl Fn(&mut S, T) -> R + Sync,
) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(items.len().max(1));
    if threads <= 1 {
        let mut state = S::default();
        return items.into_iter().map(|t| f(&mut state, t)).collect();
    }
    let slots: Vec<std::sync::Mutex<Option<T>>> = items
        .into_iter()
        .map(|t| std::sync::Mutex::new(Some(t)))
        .collect();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let (f, slots, next) = (&f, &slots, &next);
    let mut results: Vec<(usize, R)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(move || {
                    let mut state = S::default();
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(slot) = slots.get(i) else {
                            return done;
                        };
                        let item = slot
                            .lock()
                            .unwrap_or_else(std::sync::PoisonError::into_inner)
                            .take()
                            .expect("each item is taken once");
                        done.push((i, f(&mut state, item)));
                    }
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
    run_on(
        TakeInput::Borrowed(take),
        rig,
        mapping,
        mapping_file,
        options,
    )
}

/// [`run`] on a take the pipeline may consume: the devices' orientation tracks are moved into
/// stage 1 instead of copied, so a long take's samples are never held twice.
pub fn run_owned(
    mut take: Take,
    rig: &Rig,
    mapping: &Mapping,
    mapping_file: &Path,
    options: &PipelineOptions,
) -> Result<Converted, PipelineError> {
    run_on(
        TakeInput::Owned(&mut take),
        rig,
        mapping,
        mapping_file,
        options,
    )
}

fn run_on(
    input: TakeInput,
    rig: &Rig,
    mapping: &Mapping,
    mapping_file: &Path,
    options: &PipelineOptions,
) -> Result<Converted, PipelineError> {
    root::require_parts(options.root, rig).map_err(|e| PipelineError::MissingPart(Box::new(e)))?;
    if options.causal {
        return run_causal(input.take(), rig, mapping, mapping_file, options);
    }
    let file = mapping_file.display().to_string();
    let mut warnings = Vec::new();
    // What stage 1 may take away from an owned take.
    let take_last_s = input.take().last_time_s();
    let recalibrations_s = input.take().recalibrations_s().to_vec();
    // 1. Sources, and the calibration window they call for.
    let stage = tracing::debug_span!("sources").entered();
    let (world, sources, window) =
        sources_and_window(input, rig, mapping, mapping_file, options, &mut warnings)?;
    // 2. Calibration.
    drop(stage);
    let stage = tracing::debug_span!("calibrate").entered();
    let calibration = calibrate::calibrate(
        rig,
        &sources,
        window.as_ref(),
        take_last_s,
        &file,
        &mut warnings,
    )?;
    // A live session's recalibrations: the same pose held again, each solved on its own window
    // and applying from the window's end.
    let mut later = Vec::new();
    for &t in &recalibrations_s {
        let Some(again) = window.as_ref().map(|w| w.starting_at(t)) else {
            break;
        };
        if again.end_s() > take_last_s {
            warnings.push(format!(
                "the recalibration at {t:.3} s ends after the take; the calibration before it stays"
            ));
            continue;
        }
        let c = calibrate::calibrate(
            rig,
            &sources,
            Some(&again),
            take_last_s,
            &file,
            &mut warnings,
        )?;
        later.push((again.end_s(), c));
    }
    let Sources {
        sensors,
        tracks,
        origins,
        fusion,
    } = sources;

    // 3. Bone world orientations, on each sensor's own sample times.
    drop(stage);
    let stage = tracing::debug_span!("bone world").entered();
    let bone_tracks = bone_world::bone_world_recalibrated(tracks, &calibration, &later);

    // The frame grid, and what to say about it.
    let t_last = bone_tracks
        .iter()
        .map(|t| t.last_time_s())
        .fold(0.0, f64::max);
    let grid = FrameGrid::new(options.fps, t_last, options.trim)?;
    let times: Vec<&[f64]> = bone_tracks.iter().map(|t| t.times_s()).collect();
    resample::check_frame_rate(&grid, options.force, &times, rig.len(), &mut warnings)?;
    let names: Vec<&str> = sensors.iter().map(|s| s.sensor.as_str()).collect();
    warnings.extend(resample::long_gaps(&names, &times, &grid));

    // 4. Smoothing at each sensor's own rate (`smoothing` explains why), 5. resampling onto the
    // frame grid: per sensor, independent, so spread over the cores.
    drop(stage);
    let stage = tracing::debug_span!("smooth and resample").entered();
    let items = sensors.iter().zip(bone_tracks).collect();
    let per_sensor = parallel_map_with(items, |scratch, (s, track)| {
        let raw = options
            .keep_unsmoothed
            .then(|| resample::resample(&track, &grid));
        let bone = &rig.joints()[s.bone].name;
        let (track, unsmoothed) = smooth_track(
            track,
            options.smoothing.for_bone(bone),
            options.sensor_rate_hz,
            scratch,
        );
        // Into memory an earlier track had (the take's, most often), which then stays in use.
        let mut on_grid = scratch.values();
        track.resample_into(grid.times_s(), &mut on_grid);
        // Its room past the frames (the sensor's rate is above the frame rate) given back.
        on_grid.shrink_to_fit();
        scratch.give(track);
        (
            s.bone,
            on_grid,
            raw,
            unsmoothed.map(|why| (bone.clone(), why.0)),
        )
    });
    let mut world_tracks = vec![None; rig.len()];
    let mut raw_tracks = options.keep_unsmoothed.then(|| vec![None; rig.len()]);
    let mut not_smoothed: Vec<(String, String)> = Vec::new();
    for (bone, on_grid, raw, unsmoothed) in per_sensor {
        world_tracks[bone] = Some(on_grid);
        if let (Some(all), Some(raw)) = (&mut raw_tracks, raw) {
            all[bone] = Some(raw);
        }
        not_smoothed.extend(unsmoothed);
    }
    warnings.extend(smoothing::not_smoothed_warnings(&not_smoothed));

    // 6. Local rotations; 7. the root.
    drop(stage);
    let stage = tracing::debug_span!("local rotations").entered();
    let held = calibrate::held_pose(rig, window.as_ref());
    let animated: Vec<bool> = world_tracks.iter().map(Option::is_some).collect();
    let local = relative::to_local(rig, world_tracks, grid.frames, options.unsensed, &held);
    let unsmoothed =
        raw_tracks.map(|raw| relative::to_local(rig, raw, grid.frames, options.unsensed, &held));
    drop(stage);
    let _stage = tracing::debug_span!("root").entered();
    let root_mode = root::resolve(options.root, rig, &animated);
    let (roots, contacts) =
        root::root_positions(rig, root_mode, &local, options.fps.frame_time_s());
    let moving = relative::moving(rig, &animated, options.unsensed, &held);
    let mut animation = Animation::new(rig.clone(), options.fps, local, moving, roots)?;
    if let Some(c) = &contacts {
        animation = animation.with_contacts(c.per_frame.clone())?;
    }
    Ok(Converted {
        animation,
        sensors,
        calibration,
        window,
        world,
        origins,
        fusion,
        root_mode,
        contacts,
        first_frame: grid.first,
        unsmoothed,
        warnings,
    })
}

/// Stage 1 for both modes: the devices' world (the settings', else the mapping's, else the
/// take's), the mapped sensors' tracks, and the calibration window.
fn sources_and_window(
    input: TakeInput,
    rig: &Rig,
    mapping: &Mapping,
    mapping_file: &Path,
    options: &PipelineOptions,
    warnings: &mut Vec<String>,
) -> Result<(World, Sources, Option<CalibrationWindow>), PipelineError> {
    let world = options
        .world
        .or(mapping.world)
        .unwrap_or(input.take().source().world);
    let resolved = mapping.resolve(rig, mapping_file)?;
    let sources = sources::orientations(input, rig, mapping, resolved, world, options, warnings)?;
    let window = calibrate::window(mapping, &sources.sensors, warnings);
    Ok((world, sources, window))
}

/// Causal mode: the whole take through the stream's incremental cores ([`stream::PoseStream`]),
/// its samples in time order as a live capture would deliver them, the poses collected into the
/// animation (then cut by `--trim`).
fn run_causal(
    take: &Take,
    rig: &Rig,
    mapping: &Mapping,
    mapping_file: &Path,
    options: &PipelineOptions,
) -> Result<Converted, PipelineError> {
    let file = mapping_file.display().to_string();
    let mut warnings = Vec::new();
    let (world, sources, window) = sources_and_window(
        TakeInput::Borrowed(take),
        rig,
        mapping,
        mapping_file,
        options,
        &mut warnings,
    )?;
    let t_last = sources
        .tracks
        .iter()
        .map(|t| t.last_time_s())
        .fold(0.0, f64::max);
    let grid = FrameGrid::new(options.fps, t_last, options.trim)?;
    let times: Vec<&[f64]> = sources.tracks.iter().map(|t| t.times_s()).collect();
    resample::check_frame_rate(&grid, options.force, &times, rig.len(), &mut warnings)?;
    let names: Vec<&str> = sources.sensors.iter().map(|s| s.sensor.as_str()).collect();
    warnings.extend(resample::long_gaps(&names, &times, &grid));

    let mut stream = stream::PoseStream::new(
        rig,
        sources.sensors.clone(),
        window.clone(),
        world,
        options,
        &file,
    )?;
    let mut animation = AnimationBuilder::new(rig.clone(), options.fps);
    let mut feet: Vec<root::RootFrame> = Vec::new();
    let mut on_pose = |pose: &Pose| {
        animation.push(pose);
        feet.push(root::RootFrame {
            position: pose.root,
            contact: pose.contact,
            airborne: pose.airborne,
        });
    };
    // The sensors' samples merged in time order (ties in mapping order).
    let mut heads: std::collections::BinaryHeap<MergeHead> = sources
        .tracks
        .iter()
        .enumerate()
        .map(|(sensor, track)| MergeHead {
            t: track.first_time_s(),
            sensor,
            index: 0,
        })
        .collect();
    // A live session's recalibrations, at the point of the stream where it made them.
    let mut recalibrations = take.recalibrations_s().iter().copied().peekable();
    while let Some(head) = heads.pop() {
        while let Some(t) = recalibrations.next_if(|&t| head.t > t) {
            if let Err(why) = stream.recalibrate(t) {
                warnings.push(format!("the recalibration at {t:.3} s: {why}"));
            }
        }
        let track = &sources.tracks[head.sensor];
        stream.push_rig(
            head.sensor,
            head.t,
            track.values()[head.index],
            &mut on_pose,
        );
        if head.index + 1 < track.len() {
            heads.push(MergeHead {
                t: track.times_s()[head.index + 1],
                sensor: head.sensor,
                index: head.index + 1,
            });
        }
    }
    stream.finish(&mut on_pose)?;
    warnings.extend(stream.warnings().iter().cloned());
    let mut animated = vec![false; rig.len()];
    for s in &sources.sensors {
        animated[s.bone] = true;
    }
    let calibration = stream.calibration().cloned().expect("solved at the end");
    let root_mode = stream.root_mode();
    drop(stream);
    let held = calibrate::held_pose(rig, window.as_ref());
    let moving = relative::moving(rig, &animated, options.unsensed, &held);
    let animation = animation.finish(grid.first, grid.frames, moving)?;
    let kept = feet
        .get(grid.first..(grid.first + grid.frames).min(feet.len()))
        .unwrap_or(&[]);
    let contacts = (root_mode == RootMode::Feet).then(|| root::Contacts::from_frames(kept));
    let animation = match &contacts {
        Some(c) => animation.with_contacts(c.per_frame.clone())?,
        None => animation,
    };
    Ok(Converted {
        animation,
        sensors: sources.sensors,
        calibration,
        window,
        world,
        origins: sources.origins,
        fusion: sources.fusion,
        root_mode,
        contacts,
        first_frame: grid.first,
        unsmoothed: None,
        warnings,
    })
}

/// The next sample of one sensor, in a merge by time (the earliest on top of the heap).
struct MergeHead {
    t: f64,
    sensor: usize,
    index: usize,
}

impl PartialEq for MergeHead {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}
impl Eq for MergeHead {}
impl PartialOrd for MergeHead {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for MergeHead {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other
            .t
            .total_cmp(&self.t)
            .then(other.sensor.cmp(&self.sensor))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::{Duration, Instant};

    #[test]
    fn parallel_map_keeps_the_order_and_takes_each_item_once() {
        let calls = AtomicUsize::new(0);
        // Each thread's state counts the items it took.
        let out = parallel_map_with((0..500u64).collect(), |taken: &mut usize, x| {
            calls.fetch_add(1, Ordering::Relaxed);
            *taken += 1;
            x * x
        });
        assert_eq!(out, (0..500u64).map(|x| x * x).collect::<Vec<_>>());
        assert_eq!(calls.load(Ordering::Relaxed), 500);
        assert!(parallel_map(Vec::<u8>::new(), |x| x).is_empty());
    }

    #[test]
    fn a_slow_item_leaves_the_rest_to_the_other_threads() {
        if std::thread::available_parallelism().map_or(1, |n| n.get()) < 2 {
            return;
        }
        // The first item waits until every other item is done: with shares dealt out first,
        // its thread would own half of them and wait for itself until the deadline.
        let others_done = AtomicUsize::new(0);
        let n = 200;
        let out = parallel_map((0..n).collect(), |i: usize| {
            if i == 0 {
                let deadline = Instant::now() + Duration::from_secs(10);
                while others_done.load(Ordering::Acquire) < n - 1 {
                    if Instant::now() > deadline {
                        return false;
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
            } else {
                others_done.fetch_add(1, Ordering::Release);
            }
            true
        });
        assert!(
            out[0],
            "the other items were not taken by the other threads"
        );
        assert!(out.iter().all(|&done| done));
    }
}
