//! The conversion pipeline: a take and a mapping onto a rig → an [`Animation`] on a frame grid.
//!
//! [`run`] is its stage list, each stage a function of its own module given what the stages
//! before made and its options:
//! 1. [`sources`]: the mapped sensors' orientation tracks (the device's, or fused);
//! 2. [`calibrate`]: heading and mounts from the calibration window (and each recalibration);
//! 3. [`bone_world`]: `q_world_bone = H ⊗ C ⊗ q_world_sensor ⊗ q_bone_sensor⁻¹`, with `C`
//!    taking the sensors' world into the rig world ([`crate::world::World::to_rig`]);
//! 4. [`smoothing`] at each sensor's own rate, 5. [`resample`] onto the frame grid (slerp; held
//!    outside each sensor's range), per sensor on rayon's pool;
//! 6. [`relative`]: local rotations `q_world_parent⁻¹ ⊗ q_world_bone`;
//! 7. [`root`]: the root position; `--trim` cuts the frame range;
//! 8. [`foot_lock`]: each planted foot held where it stands (two-bone IK on the legs).
//!
//! In causal mode the same stages run as the stream's incremental cores ([`stream`]). Euler
//! angles (with the discontinuity filter) are made by the BVH writer from the animation's
//! quaternions ([`crate::rotation::euler`]).

pub mod bone_world;
pub mod calibrate;
mod error;
pub mod foot_lock;
pub mod hinge_axis;
pub mod legacy;
mod options;
pub(crate) mod parallel;
pub mod record;
pub mod relative;
pub mod resample;
pub mod root;
pub mod smoothing;
pub mod sources;
pub mod stream;

pub use error::{PipelineError, RecalibrateError};
pub use options::{PipelineOptions, Trim};

use crate::anim::{Animation, AnimationBuilder, Pose};
use crate::mapping::{CalibrationWindow, HeadingPolicy, Mapping, MappingRecord, ResolvedSensor};
use crate::rig::Rig;
use crate::take::Take;
use crate::take::{ImuSample, Track};
use crate::world::World;
use calibrate::Calibration;
use nalgebra::UnitQuaternion;
use parallel::parallel_map_with;
use record::PipelineRecord;
use resample::FrameGrid;
use root::RootMode;
use smoothing::smooth_track;
use sources::{Sources, TakeInput};
use std::path::Path;
use tracing::debug_span;

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
/// stage 1 instead of copied, so a long take's samples are never held twice. With what the
/// sidecar says of the run (`mapping_file`: `None` for sensors matched to bones by name).
pub fn run_owned(
    mut take: Take,
    rig: &Rig,
    mapping: &Mapping,
    mapping_file: Option<&Path>,
    options: &PipelineOptions,
) -> Result<Recorded, PipelineError> {
    let named = mapping_file.unwrap_or(Path::new("(sensors matched to bones by name)"));
    let converted = run_on(TakeInput::Owned(&mut take), rig, mapping, named, options)?;
    let policy = options.heading_policy(mapping);
    Ok(Recorded {
        mapping: record::mapping_record(&converted, rig, mapping, mapping_file),
        pipeline: PipelineRecord {
            fusion: record::fusion_record(&converted, options.fusion.is_some(), None),
            ..record::pipeline_record(
                options,
                Some((&converted.calibration, policy)),
                converted.first_frame,
                record::Mode::Orientations,
                converted.root_mode,
            )
        },
        converted,
    })
}

/// A run of the pipeline with the sidecar's records of it.
#[derive(Debug, Clone)]
pub struct Recorded {
    pub converted: Converted,
    pub mapping: MappingRecord,
    pub pipeline: PipelineRecord,
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
    let (file, w) = (mapping_file.display().to_string(), &mut Vec::new());
    let (times, policy) = (TakeTimes::of(input.take()), options.heading_policy(mapping));
    let resolved = mapping.resolve(rig, mapping_file)?;
    let feet_readings = feet_readings(input.take(), rig, &resolved, options.root);
    let (world, sources, window) = stage(debug_span!("sources"), || {
        sources_and_window(input, rig, mapping, resolved, options, w)
    })?;
    let (calibration, later) = stage(debug_span!("calibrate"), || {
        calibrations(rig, &sources, window.as_ref(), times, policy, &file, w)
    })?;
    let bone_tracks = stage(debug_span!("bone world"), || {
        bone_world::bone_world_recalibrated(sources.tracks, &calibration, &later)
    });
    let grid = frame_grid(rig, &sources.sensors, &bone_tracks, options, w)?;
    let on_grid = stage(debug_span!("smooth and resample"), || {
        smooth_and_resample(rig, &sources.sensors, bone_tracks, &grid, options, w)
    });
    let held = calibrate::held_pose(rig, window.as_ref());
    let local = stage(debug_span!("local rotations"), || {
        local_rotations(rig, on_grid, &grid, options, &held)
    });
    let (animation, root_mode, contacts) = stage(debug_span!("root"), || {
        let frame_times_s: Vec<f64> = grid.times_s().collect();
        let pivots = feet_pivots(feet_readings, rig, &sources.sensors, &calibration, &held)
            .map(|r| r.map(|(times, a)| root::zupt::on_frames(&times, &a, &frame_times_s)));
        root_stage(rig, local.local, &local.animated, options, &held, &pivots)
    })?;
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
        unsmoothed: local.unsmoothed,
        warnings: std::mem::take(w),
    })
}

/// What stage 2 needs of the take, seconds, taken before stage 1 may consume it: its last
/// time and a live session's recalibration times.
struct TakeTimes {
    last_s: f64,
    recalibrations_s: Vec<f64>,
}

impl TakeTimes {
    fn of(take: &Take) -> TakeTimes {
        TakeTimes {
            last_s: take.last_time_s(),
            recalibrations_s: take.recalibrations_s().to_vec(),
        }
    }
}

/// Runs one stage inside its `tracing` span (`IMUBAKE_LOG=imubake=debug` prints each one's
/// wall time; `cargo bench --bench convert` reads them).
fn stage<R>(span: tracing::Span, f: impl FnOnce() -> R) -> R {
    let _entered = span.entered();
    f()
}

/// Stage 2: the calibration from the window, and a live session's recalibrations — the same
/// pose held again, each solved on its own window and applying from the window's end. Each is
/// refused when its heading is unsure under `policy` ([`Calibration::check_heading`]).
fn calibrations(
    rig: &Rig,
    sources: &Sources,
    window: Option<&CalibrationWindow>,
    take: TakeTimes,
    policy: HeadingPolicy,
    file: &str,
    warnings: &mut Vec<String>,
) -> Result<(Calibration, Vec<(f64, Calibration)>), PipelineError> {
    let (take_last_s, recalibrations_s) = (take.last_s, take.recalibrations_s);
    let calibration =
        calibrate::calibrate(rig, sources, window, take_last_s, policy, file, warnings)?;
    calibration.check_heading(&sources.sensors, policy, file)?;
    let mut later = Vec::new();
    for t in recalibrations_s {
        let Some(again) = window.map(|w| w.starting_at(t)) else {
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
            sources,
            Some(&again),
            take_last_s,
            policy,
            file,
            warnings,
        )?;
        c.check_heading(&sources.sensors, policy, file)?;
        later.push((again.end_s(), c));
    }
    Ok((calibration, later))
}

/// The frame grid over the tracks (to the last sample of any), with `--trim`; the rate checked
/// against the sensors' and their long gaps reported. Both modes' one check.
fn frame_grid(
    rig: &Rig,
    sensors: &[ResolvedSensor],
    tracks: &[Track<UnitQuaternion<f64>>],
    options: &PipelineOptions,
    warnings: &mut Vec<String>,
) -> Result<FrameGrid, PipelineError> {
    let t_last = tracks.iter().map(|t| t.last_time_s()).fold(0.0, f64::max);
    let grid = FrameGrid::new(options.fps, t_last, options.trim)?;
    let times: Vec<&[f64]> = tracks.iter().map(|t| t.times_s()).collect();
    resample::check_frame_rate(&grid, options.force, &times, rig.len(), warnings)?;
    let names: Vec<&str> = sensors.iter().map(|s| s.sensor.as_str()).collect();
    warnings.extend(resample::long_gaps(&names, &times, &grid));
    Ok(grid)
}

/// Each sensed bone's world rotations on the frame grid, and (`keep_unsmoothed`) before
/// smoothing: `[joint]`, `None` for a joint no sensor drives.
struct OnGrid {
    smoothed: Vec<Option<Vec<UnitQuaternion<f64>>>>,
    raw: Option<Vec<Option<Vec<UnitQuaternion<f64>>>>>,
}

/// Stages 4 and 5: smoothing at each sensor's own rate (`smoothing` explains why), then
/// resampling onto the frame grid; per sensor, independent, so on rayon's pool, each worker
/// reusing its scratch memory.
fn smooth_and_resample(
    rig: &Rig,
    sensors: &[ResolvedSensor],
    bone_tracks: Vec<Track<UnitQuaternion<f64>>>,
    grid: &FrameGrid,
    options: &PipelineOptions,
    warnings: &mut Vec<String>,
) -> OnGrid {
    let items = sensors.iter().zip(bone_tracks).collect();
    let per_sensor = parallel_map_with(items, |scratch, (s, track)| {
        let raw = options
            .keep_unsmoothed
            .then(|| resample::resample(&track, grid));
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
    let mut smoothed = vec![None; rig.len()];
    let mut raw_tracks = options.keep_unsmoothed.then(|| vec![None; rig.len()]);
    let mut not_smoothed: Vec<(String, String)> = Vec::new();
    for (bone, on_grid, raw, unsmoothed) in per_sensor {
        smoothed[bone] = Some(on_grid);
        if let (Some(all), Some(raw)) = (&mut raw_tracks, raw) {
            all[bone] = Some(raw);
        }
        not_smoothed.extend(unsmoothed);
    }
    warnings.extend(smoothing::not_smoothed_warnings(&not_smoothed));
    OnGrid {
        smoothed,
        raw: raw_tracks,
    }
}

/// Stage 6's output: `local[joint][frame]`, which joints a sensor drives, and the local
/// rotations before smoothing when kept.
struct Local {
    local: Vec<Vec<UnitQuaternion<f64>>>,
    animated: Vec<bool>,
    unsmoothed: Option<Vec<Vec<UnitQuaternion<f64>>>>,
}

/// Stage 6: local rotations (joints without a sensor as `--unsensed` says, from the held pose).
fn local_rotations(
    rig: &Rig,
    on_grid: OnGrid,
    grid: &FrameGrid,
    options: &PipelineOptions,
    held: &[UnitQuaternion<f64>],
) -> Local {
    let animated: Vec<bool> = on_grid.smoothed.iter().map(Option::is_some).collect();
    let local = relative::to_local(rig, on_grid.smoothed, grid.frames, options.unsensed, held);
    let unsmoothed = on_grid
        .raw
        .map(|raw| relative::to_local(rig, raw, grid.frames, options.unsensed, held));
    Local {
        local,
        animated,
        unsmoothed,
    }
}

/// The raw readings (gyro, specific force) of the sensors the mapping puts on the feet
/// (`resolved`), `[left, right]`, with the sensor's name: what the root stage's zero-velocity cue
/// ([`root::zupt`]) reads, taken before stage 1, which may consume the take. None in the root
/// modes that have no contacts.
fn feet_readings(
    take: &Take,
    rig: &Rig,
    resolved: &[ResolvedSensor],
    mode: RootMode,
) -> [Option<(String, Track<ImuSample>)>; 2] {
    let feet = root::foot_joints(rig).filter(|_| matches!(mode, RootMode::Feet | RootMode::Auto));
    let Some(feet) = feet else {
        return [None, None];
    };
    feet.map(|foot| {
        let sensor = resolved.iter().find(|s| s.bone == foot)?;
        let readings = take.sensor(&sensor.sensor)?.inertial()?;
        Some((sensor.sensor.clone(), readings.clone()))
    })
}

/// The feet's own cue ([`root::zupt::Shoe::pivot_acceleration_m_s2`]) from their readings: each
/// reading's time and how fast the foot's least-moving point accelerates, m/s², about the foot's
/// points ([`root::foot_points_from_sensor_m`], turned into the sensor's frame by its calibrated
/// mount, `q_bone_sensor⁻¹`).
fn feet_pivots(
    readings: [Option<(String, Track<ImuSample>)>; 2],
    rig: &Rig,
    sensors: &[ResolvedSensor],
    calibration: &Calibration,
    held: &[UnitQuaternion<f64>],
) -> [Option<(Vec<f64>, Vec<f64>)>; 2] {
    let points = root::foot_points_from_sensor_m(rig, held);
    [0, 1].map(|side| {
        let (name, track) = readings[side].as_ref()?;
        let i = sensors.iter().position(|s| &s.sensor == name)?;
        let mount = calibration.mounts.get(i)?;
        let in_sensor: Vec<_> = points.as_ref()?[side]
            .iter()
            .map(|p| mount.inverse() * p)
            .collect();
        let shoe = root::zupt::Shoe::default();
        let a = shoe.pivot_acceleration_m_s2(track.times_s(), track.values(), &in_sensor);
        Some((track.times_s().to_vec(), a))
    })
}

/// Stages 7 and 8: the root position (the mode resolved), the planted feet held where they stand
/// (`feet` mode with `--foot-lock`), and the animation with the feet's contacts.
fn root_stage(
    rig: &Rig,
    local: Vec<Vec<UnitQuaternion<f64>>>,
    animated: &[bool],
    options: &PipelineOptions,
    held: &[UnitQuaternion<f64>],
    pivots: &root::FeetPivots,
) -> Result<(Animation, RootMode, Option<root::Contacts>), PipelineError> {
    let root_mode = root::resolve(options.root, rig, animated);
    let root::RootMotion {
        positions: roots,
        contacts,
        slips,
    } = root::root_positions(
        rig,
        root_mode,
        &local,
        options.fps.frame_time_s(),
        held,
        pivots,
    );
    let mut local = local;
    if let Some(c) = contacts.as_ref().filter(|_| options.foot_lock) {
        stage(debug_span!("foot lock"), || {
            foot_lock::lock_feet(
                rig,
                &mut local,
                &roots,
                &c.per_frame,
                &slips,
                options.fps.frame_time_s(),
            )
        });
    }
    let moving = relative::moving(rig, animated, options.unsensed, held);
    let mut animation = Animation::new(rig.clone(), options.fps, local, moving, roots)?
        .standing_in(rig.extent_in(held));
    if let Some(c) = &contacts {
        animation = animation.with_contacts(c.per_frame.clone())?;
    }
    Ok((animation, root_mode, contacts))
}

/// Stage 1 for both modes: the devices' world (the settings', else the mapping's, else the
/// take's), the mapped sensors' (`resolved`) tracks, and the calibration window.
fn sources_and_window(
    input: TakeInput,
    rig: &Rig,
    mapping: &Mapping,
    resolved: Vec<ResolvedSensor>,
    options: &PipelineOptions,
    warnings: &mut Vec<String>,
) -> Result<(World, Sources, Option<CalibrationWindow>), PipelineError> {
    let world = options
        .world
        .or(mapping.world)
        .unwrap_or(input.take().source().world);
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
        mapping.resolve(rig, mapping_file)?,
        options,
        &mut warnings,
    )?;
    let grid = frame_grid(
        rig,
        &sources.sensors,
        &sources.tracks,
        options,
        &mut warnings,
    )?;

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
            slip: [nalgebra::Vector3::zeros(); 2],
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
    let policy = options.heading_policy(mapping);
    calibration.check_heading(&sources.sensors, policy, &file)?;
    let root_mode = stream.root_mode();
    let subject_height_m = stream.root_subject_height_m();
    drop(stream);
    let held = calibrate::held_pose(rig, window.as_ref());
    let moving = relative::moving(rig, &animated, options.unsensed, &held);
    let animation = animation
        .finish(grid.first, grid.frames, moving)?
        .standing_in(rig.extent_in(&held));
    let kept = feet
        .get(grid.first..(grid.first + grid.frames).min(feet.len()))
        .unwrap_or(&[]);
    let contacts =
        (root_mode == RootMode::Feet).then(|| root::Contacts::from_frames(kept, subject_height_m));
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
