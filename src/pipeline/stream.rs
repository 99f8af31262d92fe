//! The pipeline on a stream: samples in, one [`Pose`] per frame out, as soon as it can be known.
//! Each stage runs its incremental core, in the order of [`super::run`]:
//!
//! 1. sources: `q_rig_sensor = C ⊗ q_world_sensor`;
//! 2. calibration ([`CalibrationCore`]): until the window has passed for every sensor no frame
//!    comes out (samples are kept), only [`StreamStatus::Calibrating`] with the seconds left;
//!    then the kept samples go on through the stages;
//! 3. bone world: `H ⊗ q_rig_sensor ⊗ q_bone_sensor⁻¹`;
//! 4. smoothing ([`CausalSmoother`]), causal only: Butterworth runs causal; the Gaussian and FFT
//!    filters, which look ahead, are refused;
//! 5. resampling ([`FrameResampler`]): frame n once every sensor has a sample at or after its
//!    time, or is stale (held at its last pose, and reported);
//! 6. relative rotations ([`frame_to_local`]), 7. the root, 8. with `--foot-lock` each planted
//!    foot held where it stands ([`super::foot_lock::FootLockCore`]).
//!
//! What looks ahead stays with whole takes: zero-phase filters. The heading from the hinges,
//! which a whole take reads over the minute after calibration, a stream refines as the knees and
//! elbows flex ([`CalibrationCore::refine`]): frames come out with the heading in force (the
//! sensors' north until one is sure), it changes when a surer one comes, and each change is said
//! in the warnings with its stream time.
//! The whole-take path with causal settings ([`super::run`] with `causal`) is this stream fed
//! the take's samples, so a stream and a file of the same rows give the same frames.
//!
//! Once warmed up, a frame costs no allocation: the pose handed out is reused.
//!
//! A recalibration ([`PoseStream::recalibrate`]) holds the mapping's pose again from a time `t`:
//! samples before the new window's end go on with the calibration in force (frames keep coming),
//! those from its end wait until the new calibration is solved and then go on with it — by their
//! times, not their order of arrival, so a recording converted later gives the same frames.

use super::calibrate::{Calibration, CalibrationCore};
use super::relative::frame_to_local;
use super::resample::{DEFAULT_STALE_AFTER_S, FrameResampler};
use super::root::RootCore;
use super::smoothing::CausalSmoother;
use super::{PipelineError, PipelineOptions, RecalibrateError};
use crate::anim::Pose;
use crate::fps::Fps;
use crate::fusion::stream::StreamFuser;
use crate::fusion::{Fusion, FusionError};
use crate::mapping::{CalibrationWindow, Mapping, ResolvedSensor};
use crate::rig::Rig;
use crate::take::ImuSample;
use crate::world::World;
use nalgebra::{UnitQuaternion, Vector3};
use std::path::Path;

/// What a stream is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StreamStatus {
    /// Waiting for the calibration window to pass: hold the pose for this much longer.
    Calibrating { left_s: f64 },
    /// Frames are coming out; the next is this one.
    Running { next_frame: u64 },
}

/// The pipeline's incremental cores, strung together (see the module documentation).
pub struct PoseStream {
    rig: Rig,
    fps: Fps,
    root: RootCore,
    /// Stage 8 (`--foot-lock`, feet mode).
    foot_lock: Option<super::foot_lock::FootLockCore>,
    to_rig: UnitQuaternion<f64>,
    sensors: Vec<ResolvedSensor>,
    calibration: CalibrationCore,
    mapping_file: String,
    /// Where the heading comes from ([`Calibration::check_heading`]).
    heading_policy: crate::mapping::HeadingPolicy,
    /// The calibration in force has a heading too unsure to trust (said in the warnings).
    heading_unsure: bool,
    /// Samples (sensor, time, `q_rig_sensor`) kept until the calibration is solved.
    pending: Vec<(usize, f64, UnitQuaternion<f64>)>,
    smoothers: Vec<CausalSmoother>,
    resampler: FrameResampler,
    /// The latest sample time of any sensor.
    latest_s: f64,
    warnings: Vec<String>,
    // Scratch, reused frame after frame.
    smoothed: Vec<(f64, UnitQuaternion<f64>)>,
    values: Vec<Option<UnitQuaternion<f64>>>,
    frame_world: Vec<UnitQuaternion<f64>>,
    bone_world: Vec<Option<UnitQuaternion<f64>>>,
    /// How each unsensed joint turns ([`super::relative::plan`]).
    plan: super::relative::Plan,
    pose: Pose,
    /// A recalibration under way.
    recalibration: Option<Recalibration>,
    /// Raw readings fused as they come, per sensor (created on its first raw reading).
    fusers: Vec<Option<StreamFuser>>,
    fusion: Fusion,
    corrections: Option<std::sync::Arc<crate::intrinsics::SensorCalibration>>,
    /// `q_rig_enu`: fused orientations are in ENU whatever the stream's world.
    enu_to_rig: UnitQuaternion<f64>,
    fused: Vec<(f64, UnitQuaternion<f64>)>,
}

/// A calibration being solved again while the one in force goes on.
struct Recalibration {
    core: CalibrationCore,
    /// The new window's end: samples from here on wait for the new calibration.
    end_s: f64,
    waiting: Vec<(usize, f64, UnitQuaternion<f64>)>,
}

impl PoseStream {
    /// A stream for `sensors` (resolved against `rig`, in mapping order) whose samples are in
    /// `world`, calibrated over `window`, with `options`' frame rate, smoothing (made causal) and
    /// root. `mapping_file` names the mapping in errors.
    pub fn new(
        rig: &Rig,
        sensors: Vec<ResolvedSensor>,
        window: Option<CalibrationWindow>,
        world: World,
        options: &PipelineOptions,
        mapping_file: &str,
    ) -> Result<PoseStream, PipelineError> {
        super::root::require_parts(options.root, rig)
            .map_err(|e| PipelineError::MissingPart(Box::new(e)))?;
        let mut smoothers = Vec::with_capacity(sensors.len());
        for s in &sensors {
            let bone = &rig.joints()[s.bone].name;
            let method = options.smoothing.for_bone(bone);
            let smoother =
                CausalSmoother::new(method, options.sensor_rate_hz).map_err(|source| {
                    PipelineError::NotCausal {
                        bone: bone.clone(),
                        source,
                    }
                })?;
            smoothers.push(smoother);
        }
        let held = super::calibrate::held_pose(rig, window.as_ref());
        let calibration = CalibrationCore::new(rig, sensors.clone(), window, mapping_file)?;
        let n = sensors.len();
        let mut resampler = FrameResampler::new(options.fps, n);
        resampler.stale_after_s = DEFAULT_STALE_AFTER_S;
        let joints = rig.len();
        let mut sensed = vec![false; joints];
        for s in &sensors {
            sensed[s.bone] = true;
        }
        let root_mode = super::root::resolve(options.root, rig, &sensed);
        let foot_lock = (options.foot_lock && root_mode == super::root::RootMode::Feet)
            .then(|| super::foot_lock::FootLockCore::new(rig, options.fps.frame_time_s()))
            .flatten();
        Ok(PoseStream {
            rig: rig.clone(),
            fps: options.fps,
            root: RootCore::new(rig, root_mode, options.fps.frame_time_s(), &held),
            foot_lock,
            to_rig: world.to_rig(),
            sensors,
            calibration,
            mapping_file: mapping_file.to_string(),
            heading_policy: options.heading.unwrap_or_default(),
            heading_unsure: false,
            pending: Vec::new(),
            smoothers,
            resampler,
            latest_s: f64::NEG_INFINITY,
            warnings: Vec::new(),
            smoothed: Vec::new(),
            values: vec![None; n],
            frame_world: vec![UnitQuaternion::identity(); joints],
            bone_world: vec![None; joints],
            plan: super::relative::plan(rig, &sensed, options.unsensed, &held),
            pose: Pose {
                frame: 0,
                time_s: 0.0,
                local: vec![UnitQuaternion::identity(); joints],
                root: Vector3::zeros(),
                contact: [false; 2],
                airborne: false,
            },
            recalibration: None,
            fusers: (0..n).map(|_| None).collect(),
            fusion: options
                .fusion
                .clone()
                .unwrap_or_else(Fusion::online_default),
            corrections: options.sensor_calibration.clone(),
            enu_to_rig: World::Enu.to_rig(),
            fused: Vec::new(),
        })
    }

    /// A stream for every sensor of `mapping` (resolved against `rig`), calibrated over the
    /// mapping's window, with samples in `world`.
    pub fn from_mapping(
        rig: &Rig,
        mapping: &Mapping,
        mapping_file: &Path,
        world: World,
        options: &PipelineOptions,
    ) -> Result<PoseStream, PipelineError> {
        let mut warnings = Vec::new();
        let sensors = mapping.resolve(rig, mapping_file)?;
        let window = super::calibrate::window(mapping, &sensors, &mut warnings);
        let mut stream = PoseStream::new(
            rig,
            sensors,
            window,
            world,
            options,
            &mapping_file.display().to_string(),
        )?;
        stream.warnings = warnings;
        stream.heading_policy = options.heading_policy(mapping);
        Ok(stream)
    }

    /// Whether the calibration in force has a heading too unsure to trust: the stream goes on
    /// with the sensors' own north (a live subject cannot be refused), and says so.
    pub fn heading_unsure(&self) -> bool {
        self.heading_unsure
    }

    /// After a calibration is solved: a heading unsure beyond the limit is said loudly, with the
    /// ways out, and kept in [`PoseStream::heading_unsure`].
    fn note_heading(&mut self) {
        let Some(c) = self.calibration.result() else {
            return;
        };
        match c.check_heading(&self.sensors, self.heading_policy, &self.mapping_file) {
            Ok(()) => self.heading_unsure = false,
            Err(e) => {
                self.heading_unsure = true;
                let hinges = if self.calibration.watching_hinges() {
                    " until the knees and elbows, flexing (a few steps, a squat), give a sure one"
                } else {
                    ""
                };
                self.warnings.push(format!(
                    "HEADING UNKNOWN: {e}. Streaming with the sensors' own north meanwhile{hinges}; \
                     with a second pose in the mapping (`calibration.second`), hold both poses \
                     again (`c`, or a calibration request) to fix it"
                ));
            }
        }
    }

    /// The index [`PoseStream::push`] takes for the sensor with this id, if it drives a bone.
    pub fn sensor_index(&self, id: &str) -> Option<usize> {
        self.sensors.iter().position(|s| s.sensor == id)
    }

    pub fn status(&self) -> StreamStatus {
        match self.calibration.result() {
            None => StreamStatus::Calibrating {
                left_s: self.calibration.left_s(),
            },
            Some(_) => StreamStatus::Running {
                next_frame: self.resampler.next_frame(),
            },
        }
    }

    /// The calibration, once solved.
    pub fn calibration(&self) -> Option<&Calibration> {
        self.calibration.result()
    }

    /// What the stream has had to say so far.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The sensors driving bones, in mapping order (the index [`PoseStream::push`] takes).
    pub fn sensors(&self) -> &[ResolvedSensor] {
        &self.sensors
    }

    /// The latest sample time seen.
    pub fn latest_s(&self) -> f64 {
        self.latest_s
    }

    /// A sample of sensor `sensor` (its index in [`PoseStream::sensors`]) at `t` seconds, as
    /// `q_world_sensor`; times increase per sensor. Each frame it completes goes to `on_pose`.
    pub fn push(
        &mut self,
        sensor: usize,
        t: f64,
        q_world_sensor: UnitQuaternion<f64>,
        on_pose: &mut impl FnMut(&Pose),
    ) {
        let q = self.to_rig * q_world_sensor;
        self.push_rig(sensor, t, q, on_pose);
    }

    /// Raw readings of sensor `sensor` at `t` seconds (gyroscope rad/s, accelerometer m/s², the
    /// magnetometer when the row has one, sensor frame), fused online
    /// ([`crate::fusion::stream::StreamFuser`], corrected first by the sensor calibration file
    /// when it has the sensor); the orientations go on as [`PoseStream::push`]'s, in ENU.
    pub fn push_raw(
        &mut self,
        sensor: usize,
        t: f64,
        imu: ImuSample,
        mag: Option<Vector3<f64>>,
        on_pose: &mut impl FnMut(&Pose),
    ) -> Result<(), FusionError> {
        let id = &self.sensors[sensor].sensor;
        let (imu, mag) = match self.corrections.as_ref().and_then(|c| c.sensors.get(id)) {
            Some(c) => (
                c.correct_inertial(&imu),
                mag.map(|m| c.correct_magnetometer(&m)),
            ),
            None => (imu, mag),
        };
        let fusion = &self.fusion;
        let fuser = self.fusers[sensor].get_or_insert_with(|| StreamFuser::new(id, fusion));
        let mut fused = std::mem::take(&mut self.fused);
        fused.clear();
        let result = fuser.push(t, imu, mag, &mut fused);
        self.after_fusing(sensor, &mut fused, on_pose);
        self.fused = fused;
        result
    }

    /// Orientations a fuser let out, into the stages; a sensor fused without a magnetometer has
    /// no heading of its own, which calibration then aligns.
    fn after_fusing(
        &mut self,
        sensor: usize,
        fused: &mut Vec<(f64, UnitQuaternion<f64>)>,
        on_pose: &mut impl FnMut(&Pose),
    ) {
        if fused.is_empty() {
            return;
        }
        let six_d = self.fusers[sensor].as_ref().is_some_and(|f| !f.nine_d());
        if six_d && !self.sensors[sensor].own_heading {
            self.sensors[sensor].own_heading = true;
            self.calibration.set_own_heading(sensor);
        }
        for &(t, q) in fused.iter() {
            let q = self.enu_to_rig * q;
            self.push_rig(sensor, t, q, on_pose);
        }
        fused.clear();
    }

    /// What the fusers have had to say, drained.
    pub fn take_fusion_warnings(&mut self) -> Vec<String> {
        self.fusers
            .iter_mut()
            .flatten()
            .flat_map(|f| std::mem::take(&mut f.warnings))
            .collect()
    }

    /// [`PoseStream::push`] for a sample already in the rig world (`q_rig_sensor`, stage 1 done).
    pub fn push_rig(
        &mut self,
        sensor: usize,
        t: f64,
        q: UnitQuaternion<f64>,
        on_pose: &mut impl FnMut(&Pose),
    ) {
        self.latest_s = self.latest_s.max(t);
        self.resampler.saw_input(sensor, t);
        if self.calibration.result().is_none() {
            self.calibration.push(sensor, t, q);
            self.pending.push((sensor, t, q));
            let stale: Vec<bool> = (0..self.sensors.len())
                .map(|i| self.resampler.is_stale(i))
                .collect();
            if self
                .calibration
                .try_solve(|i| stale[i], &mut self.warnings)
                .is_some()
            {
                self.replay(on_pose);
            }
            return;
        }
        if self.recalibrating(sensor, t, q, on_pose) {
            return;
        }
        self.refine_and_feed(sensor, t, q);
        self.emit(None, on_pose);
    }

    /// The hinges' look at the heading and at the 6D sensors on them
    /// ([`CalibrationCore::refine`]), said when it changes the heading or aligns a sensor, then
    /// stages 3 and 4.
    fn refine_and_feed(&mut self, sensor: usize, t: f64, q: UnitQuaternion<f64>) {
        if let Some(r) = self.calibration.refine(sensor, t, q) {
            if r.heading_taken {
                let before = if r.before_uncertainty_deg.is_finite() {
                    format!(
                        "{:.1}° (unsure by {:.1}°)",
                        r.before_deg, r.before_uncertainty_deg
                    )
                } else {
                    "the sensors' north".to_string()
                };
                self.warnings.push(format!(
                    "from {:.3} s on, the heading is {:.1}° about +Y, unsure by {:.1}°, with the knees and \
                     elbows flexing (was {before})",
                    r.at_s, r.heading_deg, r.uncertainty_deg
                ));
            }
            if !r.aligned.is_empty() {
                let names: Vec<&str> = r.aligned.iter().map(|(s, _)| s.as_str()).collect();
                let worst = r.aligned.iter().map(|(_, u)| *u).fold(0.0, f64::max);
                self.warnings.push(format!(
                    "from {:.3} s on, sensor(s) {} (no magnetometer) are aligned by their knees and elbows flexing, \
                     unsure by up to {worst:.1}°",
                    r.at_s,
                    names.join(", ")
                ));
            }
            self.note_heading();
        }
        self.feed(sensor, t, q);
    }

    /// The end of the stream: the calibration solved with what there is, every sensor's last
    /// samples smoothed, and the frames up to the latest sample's (floor(t_last · fps)) out.
    pub fn finish(&mut self, on_pose: &mut impl FnMut(&Pose)) -> Result<(), PipelineError> {
        // Fusers still warming up start with what they have.
        for sensor in 0..self.fusers.len() {
            let mut fused = Vec::new();
            if let Some(f) = self.fusers[sensor].as_mut() {
                f.finish(&mut fused)?;
            }
            self.after_fusing(sensor, &mut fused, on_pose);
        }
        if self.calibration.result().is_none() {
            self.calibration
                .finish(&self.mapping_file, &mut self.warnings)?;
            self.replay(on_pose);
        }
        if let Some(r) = &mut self.recalibration {
            // Solved with what there is; a window the stream ended before keeps the calibration
            // in force.
            if r.core
                .finish(&self.mapping_file, &mut self.warnings)
                .is_ok()
            {
                self.take_over();
            } else {
                let r = self.recalibration.take().expect("under way");
                self.warnings.push(format!(
                    "the stream ended before the recalibration's pose was held ({} s on); the calibration before it stays",
                    r.end_s
                ));
                for (sensor, t, q) in r.waiting {
                    self.feed(sensor, t, q);
                }
            }
        }
        for (i, smoother) in self.smoothers.iter_mut().enumerate() {
            self.smoothed.clear();
            smoother.finish(&mut self.smoothed);
            for &(t, q) in &self.smoothed {
                self.resampler.push(i, t, q);
            }
            self.resampler.end(i);
        }
        if self.latest_s.is_finite() {
            let last = self.fps.frame_count(self.latest_s) - 1;
            self.emit(Some(last), on_pose);
        }
        for (s, smoother) in self.sensors.iter().zip(&self.smoothers) {
            let bone = &self.rig.joints()[s.bone].name;
            if let Some(why) = smoother.not_smoothed() {
                self.warnings
                    .push(format!("`{bone}` is not smoothed: {}", why.0));
            } else if smoother.unsmoothed() > 0 {
                self.warnings.push(format!(
                    "`{bone}`: {} samples left unsmoothed (smoothing would have turned them further than the sensor did)",
                    smoother.unsmoothed()
                ));
            }
        }
        Ok(())
    }

    /// Sends the samples kept during calibration on through the stages.
    fn replay(&mut self, on_pose: &mut impl FnMut(&Pose)) {
        self.note_heading();
        let pending = std::mem::take(&mut self.pending);
        for &(sensor, t, q) in &pending {
            self.refine_and_feed(sensor, t, q);
        }
        self.emit(None, on_pose);
    }

    /// The root mode the stream runs (`auto` resolved).
    pub fn root_mode(&self) -> super::root::RootMode {
        self.root.mode()
    }

    /// The subject's height, m, the root stage's flights fall by.
    pub fn root_subject_height_m(&self) -> f64 {
        self.root.subject_height_m()
    }

    /// Holds the mapping's calibration pose(s) again from `t_s` (stream time): the seconds to hold
    /// them. Until the new window has passed, frames go on with the calibration in force.
    /// Refused when the mapping has no calibration window, or the first calibration is not
    /// done yet.
    pub fn recalibrate(&mut self, t_s: f64) -> Result<f64, RecalibrateError> {
        let Some(window) = self.calibration.window() else {
            return Err(RecalibrateError::NoWindow);
        };
        if self.calibration.result().is_none() {
            return Err(RecalibrateError::FirstUnderWay);
        }
        let window = window.starting_at(t_s);
        let end_s = window.end_s();
        let core = CalibrationCore::new(
            &self.rig,
            self.sensors.clone(),
            Some(window),
            &self.mapping_file,
        )
        .map_err(|e| RecalibrateError::Window(Box::new(e)))?;
        // Samples already in the new window's stretch (a sensor ahead of the others) cannot be
        // given to it any more; the window is measured from what comes.
        self.recalibration = Some(Recalibration {
            core,
            end_s,
            waiting: Vec::new(),
        });
        Ok(end_s - t_s)
    }

    /// A sample while a recalibration is under way (`false` when none is): one before the new
    /// window's end goes on with the calibration in force, one after waits; once the new
    /// calibration is solved, it takes over and the waiting samples go on with it.
    fn recalibrating(
        &mut self,
        sensor: usize,
        t: f64,
        q: UnitQuaternion<f64>,
        on_pose: &mut impl FnMut(&Pose),
    ) -> bool {
        let Some(r) = &mut self.recalibration else {
            return false;
        };
        r.core.push(sensor, t, q);
        if t >= r.end_s {
            r.waiting.push((sensor, t, q));
        } else {
            self.feed(sensor, t, q);
        }
        let stale: Vec<bool> = (0..self.sensors.len())
            .map(|i| self.resampler.is_stale(i))
            .collect();
        let r = self.recalibration.as_mut().expect("under way");
        if r.core.try_solve(|i| stale[i], &mut self.warnings).is_some() {
            self.take_over();
        }
        self.emit(None, on_pose);
        true
    }

    /// The new calibration takes over; the samples that waited for it go on.
    fn take_over(&mut self) {
        let r = self.recalibration.take().expect("under way");
        self.calibration = r.core;
        self.note_heading();
        for (sensor, t, q) in r.waiting {
            self.refine_and_feed(sensor, t, q);
        }
    }

    /// Stages 3 and 4 for one sample, into the resampler.
    fn feed(&mut self, sensor: usize, t: f64, q_rig: UnitQuaternion<f64>) {
        let calibration = self.calibration.result().expect("solved");
        let bone = calibration.bone_world(sensor, &q_rig);
        self.smoothed.clear();
        self.smoothers[sensor].push(t, bone, &mut self.smoothed);
        for &(ts, qs) in &self.smoothed {
            self.resampler.push(sensor, ts, qs);
        }
    }

    /// Stages 5–7: every frame that is ready (up to `last_frame`), as a pose.
    fn emit(&mut self, last_frame: Option<u64>, on_pose: &mut impl FnMut(&Pose)) {
        let PoseStream {
            rig,
            fps,
            root,
            foot_lock,
            sensors,
            resampler,
            values,
            frame_world,
            bone_world,
            plan,
            pose,
            ..
        } = self;
        resampler.emit(last_frame, values, |n, values| {
            bone_world.iter_mut().for_each(|b| *b = None);
            for (s, v) in sensors.iter().zip(values) {
                bone_world[s.bone] = *v;
            }
            frame_to_local(rig, |j| bone_world[j], plan, frame_world, &mut pose.local);
            pose.frame = n;
            pose.time_s = fps.frame_time_of(n);
            let r = root.push(&pose.local);
            if let Some(lock) = foot_lock {
                lock.push(rig, &mut pose.local, r.position, r.contact, r.slip);
            }
            pose.root = r.position;
            pose.contact = r.contact;
            pose.airborne = r.airborne;
            on_pose(pose);
        });
    }
}
