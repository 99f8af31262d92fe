//! Pose calibration: the heading that turns the subject to face +Z, and the mounts
//! (`q_bone_sensor`) of sensors marked `calibrate`, from a window in which the subject holds a
//! known pose.
//!
//! With `H` the heading (a rotation about +Y) and sensor orientations already taken into the rig
//! world (`C ⊗ q_world_sensor`), a bone's world orientation is
//! `q_world_bone = H ⊗ q_rig_sensor ⊗ q_bone_sensor⁻¹`. A `calibrate` mount makes every bone equal
//! its pose orientation over the window: `q_bone_sensor = q_world_bone(pose)⁻¹ ⊗ H ⊗ mean q_rig_sensor`.
//!
//! A static pose cannot tell the subject's heading apart from unknown mounts, so the heading comes
//! from what can tell it: each sensor whose forward axis is declared (that axis points where the
//! body faces), each sensor whose mount is known (its bone's pose orientation says where the body
//! faces), a second pose (each bone's turn between the poses, seen through its sensor), and the
//! hinges: knees and elbows flexing at any time in the minute after calibration — a walk, a hop,
//! a squat, a wave — each about its own axis, left–right in a standing pose (see
//! [`heading_from_hinges`]). Every look that is there is combined into one heading by its
//! uncertainty, a look that disagrees with the others left out ([`combine_looks`]); without any,
//! none (the sensors' own heading is kept: north → +Z).
//!
//! Every source comes with an estimated uncertainty `u` (degrees, about one standard deviation),
//! and so does each sensor's alignment below. A heading that is off turns every calibrated bone's
//! turns about wrong axes (a rotation since calibration is conjugated by the error, which scores
//! "since calibration" cannot see), so [`Calibration::axes_uncertainty_deg`] above
//! [`MAX_HEADING_UNCERTAINTY_DEG`] is refused by the pipeline unless the mapping keeps the
//! sensors' north deliberately (`heading: sensors`). The estimates:
//! - declared forward: `u = FORWARD_AXIS_DEG / f` (how well a strapped sensor's axis follows the
//!   body's facing, divided by `f`, the horizontal fraction of the axis during the pose);
//! - known mount: `u = KNOWN_MOUNT_DEG / f` (`f` of the bone's facing seen through the sensor);
//! - second pose: per sensor `KNOWN_MOUNT_DEG / f` with `f` the smaller horizontal fraction of the
//!   two turn axes; over several sensors the circular spread of their estimates `δ` over `√n`,
//!   never below the best single one;
//! - hinges: `max(KNEE_AXIS_DEG, δ / √n)`, `δ` the circular spread of each hinge's flexion axes
//!   about its own mean (weighted by angle, pooled over the hinges), `n` one independent look per
//!   hinge per second in which it flexed; without a knee or an elbow on both sides, at least
//!   `ONE_LEG_DEG` with a knee, else `ONE_ARM_DEG` (a leg or an arm turned out turns its hinge's
//!   axis, which the other side's mirror turn cancels in their mean).
//!
//! A pose held other than as declared — a leg turned out, an arm turned in — turns the `calibrate`
//! mounts of that limb about its long axis, which no joint position shows but every hip and knee
//! turn then reads about wrong axes. Each hinge's own axis (its flexed samples' mean, where it stood
//! at calibration) says how its two segments stood: with `u` the direction up a segment in the
//! pose, each mount is taken from the pose turned by `T = R(u, ψ)`, `ψ` the angle about `u` from the
//! pose's left (+X) to the hinge's axis turned by `H`, both seen across `u` ([`hinge_turns`]):
//! `q_bone_sensor = (T ⊗ P)⁻¹ ⊗ H ⊗ held`. Its uncertainty is the hinge's: the circular spread of
//! its axes over √(seconds flexed), at least [`HINGE_AXIS_DEG`].
//!
//! Sensors without a heading of their own (fused without a magnetometer, "6D") each sit in a world
//! turned about the vertical by an unknown `A_i⁻¹`, which a mount cannot absorb: it would turn
//! every rotation axis of the bone about the vertical. Each such sensor is aligned on its own,
//! `q_world_bone = H ⊗ A_i ⊗ q_rig_sensor ⊗ q_bone_sensor⁻¹`, with `Y_i = H ⊗ A_i` (about +Y):
//! - a known mount: `Y_i` is the turn about +Y closest to `P_i ⊗ q_bone_sensor ⊗ held_i⁻¹`
//!   ([`twist_about_y`]): the bone faces the pose's way;
//! - a declared forward axis: `Y_i` turns `held_i ⊗ forward` to +Z;
//! - a second pose (`calibration.second`): between the poses the bone turns by
//!   `D_b = P2_i ⊗ P1_i⁻¹` and the sensor by `D_s = held2_i ⊗ held_i⁻¹` (both world-frame turns), so
//!   `D_b = Y_i ⊗ D_s ⊗ Y_i⁻¹`: `Y_i` turns the horizontal part of `D_s`'s axis onto `D_b`'s. It
//!   needs every such bone to turn about a non-vertical axis between the poses — the `skiing` pose
//!   after `npose` turns every segment about the subject's left–right axis;
//! - a knee or an elbow ([`SixDHinge`]): the turn `D` from the outer sensor's world into the inner
//!   one's ([`super::hinge_axis`]); with a partner that has north, `Y = H ⊗ D` (outer) or
//!   `H ⊗ D⁻¹` (inner); of two 6D sensors, the hinge's flexion folded in the inner sensor's world
//!   (the outer's turned into it by `D`) faces it as [`heading_from_hinges`] faces a shared world:
//!   `Y` for the inner, `Y ⊗ D` for the outer. Unsure by `√(u_a² + u_D²)`: the hinge axis's
//!   uncertainty over its horizontal fraction and `D`'s from the fit's curvature
//!   ([`super::hinge_axis::HingeFit::delta_uncertainty_deg`]); taken only within
//!   [`MAX_HEADING_UNCERTAINTY_DEG`].

use super::PipelineError;
use super::sources::Sources;
use crate::mapping::{CalibrationWindow, HeadingPolicy, Mapping, Mount, PoseRef, ResolvedSensor};
use crate::rig::Rig;
use crate::take::Track;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// Where the heading came from (sidecar `pipeline.heading`).
#[derive(Debug, Clone, PartialEq)]
pub enum HeadingSource {
    DeclaredForward {
        sensor: String,
    },
    KnownMount {
        sensor: String,
    },
    /// The bones' turns between two calibration poses, seen through their sensors.
    SecondPose,
    /// Knees and elbows flexing after calibration: their hinge axes point to the subject's left
    /// and right.
    Hinges,
    /// No sensor has a heading of its own: each was aligned to the pose on its own.
    Aligned,
    None,
}

impl HeadingSource {
    pub fn label(&self) -> &'static str {
        match self {
            HeadingSource::DeclaredForward { .. } => "declared-forward",
            HeadingSource::KnownMount { .. } => "mounts",
            HeadingSource::SecondPose => "second-pose",
            HeadingSource::Hinges => "hinges",
            HeadingSource::Aligned => "per-sensor",
            HeadingSource::None => "none",
        }
    }

    /// The sensor the heading came from, if one did.
    pub fn sensor(&self) -> Option<&str> {
        match self {
            HeadingSource::DeclaredForward { sensor } | HeadingSource::KnownMount { sensor } => {
                Some(sensor)
            }
            HeadingSource::SecondPose
            | HeadingSource::Hinges
            | HeadingSource::Aligned
            | HeadingSource::None => None,
        }
    }
}

/// How a sensor without a heading of its own was aligned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Alignment {
    /// Its heading is north (a device orientation, or fused with a magnetometer).
    OwnHeading,
    Mount,
    Forward,
    SecondPose,
    /// By its knee's or elbow's flexion ([`SixDHinge`]).
    Hinge,
    /// Could not be aligned: its bone turns about a wrong vertical axis.
    None,
}

impl Alignment {
    /// For the sidecar (`None` for sensors that needed no alignment).
    pub fn label(self) -> Option<&'static str> {
        match self {
            Alignment::OwnHeading => None,
            Alignment::Mount => Some("mount"),
            Alignment::Forward => Some("forward"),
            Alignment::SecondPose => Some("second-pose"),
            Alignment::Hinge => Some("hinge"),
            Alignment::None => Some("none"),
        }
    }
}

/// The result of calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// Rotation about +Y applied to every sensor (rig world).
    pub heading: UnitQuaternion<f64>,
    pub heading_source: HeadingSource,
    /// The heading's estimated uncertainty, degrees (module docs); infinite when it is unknown.
    pub heading_uncertainty_deg: f64,
    /// Every source's look at the heading, and whether it agreed ([`combine_looks`]).
    pub heading_looks: Vec<HeadingLook>,
    /// Per mapped sensor: how far about the vertical its bone's turn axes may be off, degrees —
    /// the heading's uncertainty for a `calibrate` mount on a sensor with north, its alignment's
    /// for a sensor without (infinite when unaligned), 0 for a known mount with north.
    pub axes_uncertainty_deg: Vec<f64>,
    /// `q_bone_sensor` per mapped sensor, in mapping order.
    pub mounts: Vec<UnitQuaternion<f64>>,
    /// `A_i` per mapped sensor: the turn about +Y that aligns a sensor without a heading of its
    /// own (identity for the others).
    pub align: Vec<UnitQuaternion<f64>>,
    pub alignment: Vec<Alignment>,
    /// Per mapped sensor: the turn about its segment's long axis that its `calibrate` mount
    /// took from its knee's or elbow's axis ([`MountTurn`]), if any.
    pub mount_turns: Vec<Option<MountTurn>>,
    pub warnings: Vec<String>,
    /// A stream's heading refined as the hinges flexed ([`CalibrationCore::refine`]): the stream
    /// time (s) from which this heading is in force; frames before it turned with the one before.
    /// `None`: from the calibration on.
    pub heading_from_s: Option<f64>,
}

impl Calibration {
    /// `Err` when a bone's axes are less sure than [`MAX_HEADING_UNCERTAINTY_DEG`] and `policy`
    /// does not keep the sensors' north deliberately.
    pub fn check_heading(
        &self,
        sensors: &[ResolvedSensor],
        policy: HeadingPolicy,
        mapping_file: &str,
    ) -> Result<(), PipelineError> {
        match self.least_sure(sensors) {
            Some((sensor, u)) if policy == HeadingPolicy::Estimate && too_unsure(u) => {
                Err(PipelineError::HeadingUnsure {
                    file: mapping_file.to_string(),
                    heading: self.heading_source.label(),
                    uncertainty_deg: u,
                    sensor: sensor.to_string(),
                })
            }
            _ => Ok(()),
        }
    }

    /// The sensor whose bone's axes are least sure, and how unsure (degrees); `None` without
    /// sensors.
    pub fn least_sure<'a>(&self, sensors: &'a [ResolvedSensor]) -> Option<(&'a str, f64)> {
        sensors
            .iter()
            .zip(&self.axes_uncertainty_deg)
            .map(|(s, u)| (s.sensor.as_str(), *u))
            .reduce(|a, b| if b.1 > a.1 { b } else { a })
    }

    /// `q_world_bone = H ⊗ A_i ⊗ q_rig_sensor ⊗ q_bone_sensor⁻¹` for sensor `i`.
    pub fn bone_world(&self, i: usize, q_rig_sensor: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        self.heading * self.align[i] * q_rig_sensor * self.mounts[i].inverse()
    }
}

/// The calibration window: the mapping's, or — when a mount is to be calibrated and the mapping
/// gives none — the rig's rest pose over the first second, with a warning. `None` when every
/// mount is known and the mapping names no window.
pub fn window(
    mapping: &Mapping,
    sensors: &[ResolvedSensor],
    warnings: &mut Vec<String>,
) -> Option<CalibrationWindow> {
    let needs_window = sensors.iter().any(|s| s.mount == Mount::Calibrate);
    match (&mapping.calibration, needs_window) {
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
    }
}

/// Stage 2, pose calibration: over the window, each sensor's mean orientation (a sensor that
/// turns by more than [`MOVED_DURING_CALIBRATION_DEG`] in it is warned about), the heading from
/// the hinges over the minute after it, then [`solve`]. Without a window, mounts are the known ones
/// and the heading is kept. `take_end_s` is the take's last sample time; `policy` how an unsure
/// heading is taken; `mapping_file` names the mapping in errors.
pub fn calibrate(
    rig: &Rig,
    sources: &Sources,
    window: Option<&CalibrationWindow>,
    take_end_s: f64,
    policy: HeadingPolicy,
    mapping_file: &str,
    warnings: &mut Vec<String>,
) -> Result<Calibration, PipelineError> {
    let Sources {
        sensors, tracks, ..
    } = sources;
    let Some(w) = window else {
        let calibration = without_window(sensors);
        warnings.extend(calibration.warnings.iter().cloned());
        return Ok(calibration);
    };
    check_window(w, take_end_s, mapping_file)?;
    let first = Held {
        held: held_poses(sensors, tracks, w.start_s, w.duration_s, warnings),
        pose_world: pose_world(rig, sensors, &w.pose, mapping_file)?,
    };
    let second = match &w.second {
        None => None,
        Some(p) => Some(Held {
            held: held_poses(sensors, tracks, p.start_s, p.duration_s, warnings),
            pose_world: pose_world(rig, sensors, &p.pose, mapping_file)?,
        }),
    };
    let pose_local = held_pose(rig, Some(w));
    let after = |usable| hinges_after(rig, &pose_local, sensors, tracks, w, usable);
    let hinges = heading_from_hinges(&since_calibration(after(true), &first.held));
    let six_d: Vec<SixDHinge> = after(false)
        .into_iter()
        .filter_map(|(pair, samples)| {
            six_d_hinge(pair, &samples.into_iter().collect(), &first.held)
        })
        .collect();
    let calibration = solve_aligning(sensors, &first, second.as_ref(), hinges, &six_d, policy);
    warnings.extend(calibration.warnings.iter().cloned());
    Ok(calibration)
}

/// Without a window: the known mounts (identity for the others), the sensors' own heading.
/// Sensors without a heading of their own cannot be aligned without a pose.
fn without_window(sensors: &[ResolvedSensor]) -> Calibration {
    let alignment: Vec<Alignment> = sensors
        .iter()
        .map(|s| {
            if s.own_heading {
                Alignment::None
            } else {
                Alignment::OwnHeading
            }
        })
        .collect();
    Calibration {
        heading: UnitQuaternion::identity(),
        heading_source: HeadingSource::None,
        heading_uncertainty_deg: f64::INFINITY,
        heading_looks: Vec::new(),
        // Every mount is known (a `calibrate` one would have made a window): a sensor with north
        // has its bone's axes right; one without is unaligned.
        axes_uncertainty_deg: sensors
            .iter()
            .map(|s| if s.own_heading { f64::INFINITY } else { 0.0 })
            .collect(),
        mounts: sensors
            .iter()
            .map(|s| match s.mount {
                Mount::Fixed(q) => q,
                Mount::Calibrate => UnitQuaternion::identity(),
            })
            .collect(),
        align: vec![UnitQuaternion::identity(); sensors.len()],
        mount_turns: vec![None; sensors.len()],
        warnings: unaligned_warning(sensors, &alignment, false)
            .into_iter()
            .collect(),
        alignment,
        heading_from_s: None,
    }
}

fn check_window(
    w: &CalibrationWindow,
    take_end_s: f64,
    mapping_file: &str,
) -> Result<(), PipelineError> {
    let late = std::iter::once((w.start_s, w.duration_s))
        .chain(w.second.as_ref().map(|s| (s.start_s, s.duration_s)))
        .find(|(start, _)| *start > take_end_s);
    if let Some((start_s, duration_s)) = late {
        return Err(PipelineError::CalibrationOutside {
            file: mapping_file.to_string(),
            start_s,
            duration_s,
            end_s: take_end_s,
        });
    }
    Ok(())
}

/// The local rotation of every joint in the pose held at calibration (the first window's; the
/// rest pose's identities without a window, or for a pose the rig does not know — calibration
/// itself refuses that one): where joints without a sensor start from ([`super::relative`]).
pub fn held_pose(rig: &Rig, window: Option<&CalibrationWindow>) -> Vec<UnitQuaternion<f64>> {
    window
        .and_then(|w| rig.pose(&w.pose.label()))
        .map(|p| p.local)
        .unwrap_or_else(|| vec![UnitQuaternion::identity(); rig.len()])
}

/// Each sensor's bone's world orientation in `pose`.
fn pose_world(
    rig: &Rig,
    sensors: &[ResolvedSensor],
    pose: &PoseRef,
    mapping_file: &str,
) -> Result<Vec<UnitQuaternion<f64>>, PipelineError> {
    let found = rig
        .pose(&pose.label())
        .ok_or_else(|| PipelineError::UnknownPose {
            file: mapping_file.to_string(),
            rig: rig.name().to_string(),
            pose: pose.label(),
            known: rig.pose_names().join(", "),
        })?;
    let pose_world_all = rig.world_rotations(&found.local);
    Ok(sensors.iter().map(|s| pose_world_all[s.bone]).collect())
}

/// A pose as held: each sensor's mean orientation over its window (rig world) and its bone's
/// world orientation in the pose.
pub struct Held {
    pub held: Vec<UnitQuaternion<f64>>,
    pub pose_world: Vec<UnitQuaternion<f64>>,
}

/// Each sensor's mean orientation over [start, start + duration] ([`held_over`]), warning about
/// the sensors that turn by more than [`MOVED_DURING_CALIBRATION_DEG`] in it.
fn held_poses(
    sensors: &[ResolvedSensor],
    tracks: &[Track<UnitQuaternion<f64>>],
    start_s: f64,
    duration_s: f64,
    warnings: &mut Vec<String>,
) -> Vec<UnitQuaternion<f64>> {
    let end_s = start_s + duration_s;
    let held: Vec<_> = tracks
        .iter()
        .map(|t| held_over(t, start_s, duration_s))
        .collect();
    for ((s, track), mean) in sensors.iter().zip(tracks).zip(&held) {
        let moved = track
            .iter()
            .filter(|(t, _)| *t >= start_s && *t <= end_s)
            .map(|(_, q)| crate::rotation::angle_between(q, mean))
            .fold(0.0, f64::max)
            .to_degrees();
        if moved > MOVED_DURING_CALIBRATION_DEG {
            warnings.push(format!(
                "sensor `{}` moved by up to {moved:.1}° during the calibration window ({start_s} s to {end_s} s); its mount may be off: check the mapping's `calibration`",
                s.sensor,
            ));
        }
    }
    held
}

/// The incremental core of stage 2, for streams: each sensor's samples (rig world) are kept until
/// the calibration window has passed for every sensor — a sample after its end, or the sensor
/// declared stale — then the stage solves as [`calibrate`] does, from the same samples (the last
/// one before the window, those in it, the first after it), but without the hinges, whose seconds
/// after the window have not come yet: from a declared forward axis, known mounts or a second pose
/// (one less sure than [`MAX_HEADING_UNCERTAINTY_DEG`] keeps the sensors' north, as under
/// `heading: sensors`). Before that, [`CalibrationCore::left_s`] says how long the pose is to be
/// held. After it, [`CalibrationCore::refine`] folds the hinges' flexion as it comes (for
/// [`HINGE_SEARCH_S`]) and solves again with it once a second, taking the heading it gives when
/// that is surer ([`REFINED_WHEN`]).
pub struct CalibrationCore {
    window: Option<CalibrationWindow>,
    sensors: Vec<ResolvedSensor>,
    pose_world: Vec<UnitQuaternion<f64>>,
    second_pose_world: Vec<UnitQuaternion<f64>>,
    samples: Vec<Vec<(f64, UnitQuaternion<f64>)>>,
    passed: Vec<bool>,
    latest_s: f64,
    result: Option<Calibration>,
    /// The knees and elbows the rig and the mapping have ([`hinge_pairs`]).
    pairs: Vec<HingePair>,
    /// After the window: the hinges being watched for the heading.
    watch: Option<HingeWatch>,
}

/// A hinge's sample: the time (s) and the inner and the outer sensor's orientations (rig world).
type HingeSample = (f64, UnitQuaternion<f64>, UnitQuaternion<f64>);

/// A stream's hinges after calibration ([`CalibrationCore::refine`]).
struct HingeWatch {
    /// The poses as held, to solve again with.
    first: Held,
    /// The surest the pose's own sources could make the heading, degrees (infinite without).
    without_hinges_deg: f64,
    second: Option<Held>,
    /// The usable pairs, each with its flexion so far.
    hinges: Vec<(HingePair, HingeFlexion)>,
    /// The pairs with a 6D sensor, each with its samples so far (at most one per
    /// [`SIX_D_SAMPLE_S`]): [`six_d_hinge`] needs the turn between the worlds before it can fold
    /// the flexion, so it reads them again at each look.
    six_d: Vec<(HingePair, SixDSamples)>,
    /// What the stream took last: the hinges' heading and the 6D hinges (solved again with both).
    taken_look: Option<HingeLook>,
    taken_six_d: Vec<SixDHinge>,
    /// Each sensor's latest sample (time, rig world): the inner segment's, read at the outer's.
    latest: Vec<Option<(f64, UnitQuaternion<f64>)>>,
    /// Hinge samples count in (from_s, until_s].
    from_s: f64,
    until_s: f64,
    next_look_s: f64,
}

/// A stream takes the heading the hinges give when it is surer than the one in force: unsure
/// before ([`MAX_HEADING_UNCERTAINTY_DEG`]) and sure now, or this fraction of the uncertainty
/// before or less — a few steps as the flexion piles up, not a turn every second.
pub const REFINED_WHEN: f64 = 0.8;

/// A stream pairs an outer segment's sample with the inner one's latest when that is at most this
/// old, seconds (a sample period down to 10 Hz; a sensor gone quiet is not read as a still
/// joint).
pub const HINGE_PAIR_S: f64 = 0.1;

/// A stream solves again with the hinges this often, seconds of stream time.
pub const HINGE_LOOK_EVERY_S: f64 = 1.0;

/// A stream keeps a 6D hinge's samples at most this often, seconds (125 Hz, so that a 100 Hz
/// sensor's jittered samples all count: at most 7500 over [`HINGE_SEARCH_S`], whatever the
/// sensors' rate).
pub const SIX_D_SAMPLE_S: f64 = 0.008;

/// A heading unsure by `now` degrees is surer than one by `before` ([`REFINED_WHEN`]).
fn surer(before: f64, now: f64) -> bool {
    !too_unsure(now) && (too_unsure(before) || now <= REFINED_WHEN * before)
}

/// The heading a stream took from the hinges ([`CalibrationCore::refine`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Refined {
    /// Stream time, s.
    pub at_s: f64,
    /// The turn about +Y before and now, degrees.
    pub before_deg: f64,
    pub heading_deg: f64,
    /// The uncertainty before (infinite when unknown) and now, degrees.
    pub before_uncertainty_deg: f64,
    pub uncertainty_deg: f64,
    /// Whether the heading is the hinges' now (else only sensors were aligned).
    pub heading_taken: bool,
    /// The sensors without a heading of their own that their knees or elbows aligned now (or
    /// aligned surer), each with its alignment's uncertainty, degrees.
    pub aligned: Vec<(String, f64)>,
}

impl CalibrationCore {
    pub fn new(
        rig: &Rig,
        sensors: Vec<ResolvedSensor>,
        window: Option<CalibrationWindow>,
        mapping_file: &str,
    ) -> Result<CalibrationCore, PipelineError> {
        let first_pose_world = match &window {
            Some(w) => pose_world(rig, &sensors, &w.pose, mapping_file)?,
            None => Vec::new(),
        };
        let second_pose_world = match window.as_ref().and_then(|w| w.second.as_ref()) {
            Some(p) => pose_world(rig, &sensors, &p.pose, mapping_file)?,
            None => Vec::new(),
        };
        let n = sensors.len();
        let result = window.is_none().then(|| without_window(&sensors));
        let pairs = match &window {
            Some(w) => hinge_pairs(rig, &held_pose(rig, Some(w)), &sensors),
            None => Vec::new(),
        };
        Ok(CalibrationCore {
            window,
            sensors,
            pose_world: first_pose_world,
            second_pose_world,
            samples: vec![Vec::new(); n],
            passed: vec![false; n],
            latest_s: f64::NEG_INFINITY,
            result,
            pairs,
            watch: None,
        })
    }

    /// The calibration, once solved.
    pub fn result(&self) -> Option<&Calibration> {
        self.result.as_ref()
    }

    /// Sensor `i` turns out to have no heading of its own (fused without a magnetometer): the
    /// calibration aligns it, as [`calibrate`] does such sensors.
    pub fn set_own_heading(&mut self, i: usize) {
        self.sensors[i].own_heading = true;
    }

    /// Whether the hinges are watched for a surer heading ([`CalibrationCore::refine`]).
    pub fn watching_hinges(&self) -> bool {
        self.watch.is_some()
    }

    /// The calibration window, if there is one.
    pub fn window(&self) -> Option<&CalibrationWindow> {
        self.window.as_ref()
    }

    /// Seconds of stream time until the window (the second pose's, if any) ends (0 once it has).
    pub fn left_s(&self) -> f64 {
        match &self.window {
            Some(w) => (w.end_s() - self.latest_s.max(0.0)).max(0.0),
            None => 0.0,
        }
    }

    /// A sample of sensor `i` (in mapping order), rig world; times increase per sensor.
    pub fn push(&mut self, i: usize, t: f64, q: UnitQuaternion<f64>) {
        self.latest_s = self.latest_s.max(t);
        let Some(w) = &self.window else {
            return;
        };
        if self.result.is_some() || self.passed[i] {
            return;
        }
        let samples = &mut self.samples[i];
        if t < w.start_s {
            // Only the last sample before the window matters (to interpolate in an empty one).
            samples.clear();
        }
        samples.push((t, q));
        if t > w.end_s() {
            self.passed[i] = true;
        }
    }

    /// Solves once every sensor has passed the window or is `stale`; `Some` once solved.
    pub fn try_solve(
        &mut self,
        stale: impl Fn(usize) -> bool,
        warnings: &mut Vec<String>,
    ) -> Option<&Calibration> {
        if self.result.is_none() && (0..self.sensors.len()).all(|i| self.passed[i] || stale(i)) {
            self.solve_now(warnings);
        }
        self.result.as_ref()
    }

    /// Solves with what there is (at the end of a take): an error when the window starts after
    /// every sample.
    pub fn finish(
        &mut self,
        mapping_file: &str,
        warnings: &mut Vec<String>,
    ) -> Result<&Calibration, PipelineError> {
        if self.result.is_none() {
            if let Some(w) = &self.window {
                check_window(w, self.latest_s, mapping_file)?;
            }
            self.solve_now(warnings);
        }
        Ok(self.result.as_ref().expect("solved"))
    }

    fn solve_now(&mut self, warnings: &mut Vec<String>) {
        let Some(w) = self.window.clone() else {
            return;
        };
        let tracks: Vec<Track<UnitQuaternion<f64>>> = self
            .samples
            .iter()
            .map(|s| {
                let (times, values): (Vec<f64>, Vec<UnitQuaternion<f64>>) = if s.is_empty() {
                    // A sensor silent through the window: it cannot be calibrated.
                    (vec![w.start_s], vec![UnitQuaternion::identity()])
                } else {
                    s.iter().copied().unzip()
                };
                Track::new(times, values).expect("a sensor's samples increase")
            })
            .collect();
        for (s, samples) in self.sensors.iter().zip(&self.samples) {
            if samples.is_empty() {
                warnings.push(format!(
                    "sensor `{}` sent nothing during the calibration window; its mount is unknown",
                    s.sensor
                ));
            }
        }
        let first = Held {
            held: held_poses(&self.sensors, &tracks, w.start_s, w.duration_s, warnings),
            pose_world: self.pose_world.clone(),
        };
        let second = w.second.as_ref().map(|p| Held {
            held: held_poses(&self.sensors, &tracks, p.start_s, p.duration_s, warnings),
            pose_world: self.second_pose_world.clone(),
        });
        // A live subject cannot be refused: an unsure heading keeps the sensors' north, and the
        // stream says so (`PoseStream::heading_unsure`), whatever the policy.
        let calibration = solve(
            &self.sensors,
            &first,
            second.as_ref(),
            None,
            HeadingPolicy::Sensors,
        );
        warnings.extend(calibration.warnings.iter().cloned());
        self.samples = Vec::new();
        self.result = Some(calibration);
        let hinges: Vec<(HingePair, HingeFlexion)> = self
            .pairs
            .iter()
            .filter(|p| p.usable(&self.sensors))
            .map(|p| (*p, HingeFlexion::new(*p)))
            .collect();
        let six_d: Vec<_> = self
            .pairs
            .iter()
            .filter(|p| !p.usable(&self.sensors))
            .map(|p| (*p, SixDSamples::default()))
            .collect();
        if !hinges.is_empty() || !six_d.is_empty() {
            self.watch = Some(HingeWatch {
                // Every look, agreeing or not, kept or not: the surest they could combine to.
                without_hinges_deg: self.result.as_ref().map_or(f64::INFINITY, |c| {
                    combined_uncertainty_deg(c.heading_looks.iter().map(|l| l.uncertainty_deg))
                }),
                first,
                second,
                hinges,
                six_d,
                taken_look: None,
                taken_six_d: Vec::new(),
                latest: vec![None; self.sensors.len()],
                from_s: w.end_s(),
                until_s: w.end_s() + HINGE_SEARCH_S,
                next_look_s: w.end_s() + HINGE_LOOK_EVERY_S,
            });
        }
    }

    /// After the calibration is solved, a sample of sensor `i` at `t` (rig world; times
    /// increasing per sensor): folded into the hinges whose outer segment it drives (the inner
    /// segment read at its latest sample, at most [`HINGE_PAIR_S`] old), and once a
    /// [`HINGE_LOOK_EVERY_S`] the calibration solved again with the hinges' heading — which
    /// replaces the one in force when it is surer ([`REFINED_WHEN`]): then `Some`, and
    /// [`Calibration::heading_from_s`] is `t` — and with the 6D hinges read again
    /// ([`six_d_hinge`]): `Some` too when they align a sensor surer than it was (aligned where it
    /// was not, or [`REFINED_WHEN`] as unsure). Past [`HINGE_SEARCH_S`] after the window, as in a
    /// whole take, the hinges are not watched any more.
    pub fn refine(&mut self, i: usize, t: f64, q: UnitQuaternion<f64>) -> Option<Refined> {
        let watch = self.watch.as_mut()?;
        if t > watch.until_s {
            self.watch = None;
            return None;
        }
        watch.latest[i] = Some((t, q));
        if t <= watch.from_s {
            return None;
        }
        let held = &watch.first.held;
        for (pair, flexion) in watch.hinges.iter_mut().filter(|(p, _)| p.outer == i) {
            // An inner sensor gone quiet says nothing of the joint now.
            if let Some((_, inner)) =
                watch.latest[pair.inner].filter(|(ti, _)| t - ti <= HINGE_PAIR_S)
            {
                flexion.push(
                    t,
                    &(inner * held[pair.inner].inverse()),
                    &(q * held[i].inverse()),
                );
            }
        }
        for (pair, samples) in watch.six_d.iter_mut().filter(|(p, _)| p.outer == i) {
            let due = samples
                .samples
                .last()
                .is_none_or(|(last, _, _)| t - last >= SIX_D_SAMPLE_S);
            if let Some((_, inner)) =
                watch.latest[pair.inner].filter(|(ti, _)| due && t - ti <= HINGE_PAIR_S)
            {
                samples.push((t, inner, q));
            }
        }
        if t < watch.next_look_s {
            return None;
        }
        watch.next_look_s = t + HINGE_LOOK_EVERY_S;
        let current = self.result.as_ref().expect("watched once solved");
        let look = heading_from_flexion(watch.hinges.iter().map(|(_, f)| f));
        // What the look can promise combined with the pose's own sources (when it agrees): solved
        // again for the heading only when that is surer, so a stream whose heading is as sure as
        // it gets does not allocate once a second (solving is never surer than this: a look that
        // disagrees leaves one source out).
        let heading_due = look.is_some_and(|look| {
            let promised =
                combined_uncertainty_deg([watch.without_hinges_deg, look.uncertainty_deg]);
            surer(current.heading_uncertainty_deg, promised)
        });
        // The 6D hinges are read again at each look, and solved with when one promises a sensor
        // a surer alignment than it has (aligned where it was not, or REFINED_WHEN as unsure).
        let six_d: Vec<SixDHinge> = watch
            .six_d
            .iter()
            .filter_map(|(pair, samples)| six_d_hinge(*pair, samples, held))
            .collect();
        let north = (current.heading, current.heading_uncertainty_deg);
        let align_due = six_d.iter().any(|h| {
            [h.pair.inner, h.pair.outer].into_iter().any(|k| {
                self.sensors[k].own_heading
                    && h.align(k, &self.sensors, north)
                        .is_some_and(|(_, u)| surer(current.axes_uncertainty_deg[k], u))
            })
        });
        if !heading_due && !align_due {
            return None;
        }
        let solve_with = |look: Option<HingeLook>, six_d: &[SixDHinge]| {
            solve_aligning(
                &self.sensors,
                &watch.first,
                watch.second.as_ref(),
                look,
                six_d,
                HeadingPolicy::Sensors,
            )
        };
        let six_d = if align_due {
            six_d
        } else {
            watch.taken_six_d.clone()
        };
        let hinges = if heading_due { look } else { watch.taken_look };
        let candidate = solve_with(hinges, &six_d);
        let before = current.heading_uncertainty_deg;
        let heading_taken = heading_due && surer(before, candidate.heading_uncertainty_deg);
        // A heading not surer is not taken, even with a sensor aligned better now.
        let candidate = if heading_due && !heading_taken {
            solve_with(watch.taken_look, &six_d)
        } else {
            candidate
        };
        let now = candidate.heading_uncertainty_deg;
        let aligned: Vec<(String, f64)> = self
            .sensors
            .iter()
            .enumerate()
            .filter(|(k, s)| {
                s.own_heading
                    && candidate.alignment[*k] == Alignment::Hinge
                    && surer(
                        current.axes_uncertainty_deg[*k],
                        candidate.axes_uncertainty_deg[*k],
                    )
            })
            .map(|(k, s)| (s.sensor.clone(), candidate.axes_uncertainty_deg[k]))
            .collect();
        if !heading_taken && aligned.is_empty() {
            return None;
        }
        let refined = Refined {
            at_s: t,
            before_deg: current.heading.scaled_axis().y.to_degrees(),
            heading_deg: candidate.heading.scaled_axis().y.to_degrees(),
            before_uncertainty_deg: before,
            uncertainty_deg: now,
            heading_taken,
            aligned,
        };
        if heading_taken {
            watch.taken_look = hinges;
        }
        if !refined.aligned.is_empty() {
            watch.taken_six_d = six_d;
        }
        let heading_from_s = if heading_taken {
            Some(t)
        } else {
            current.heading_from_s
        };
        self.result = Some(Calibration {
            heading_from_s,
            ..candidate
        });
        Some(refined)
    }
}

/// The mean orientation of a track over [start, start + duration]; the value interpolated at the
/// window's middle when no sample falls inside.
fn held_over(
    track: &Track<UnitQuaternion<f64>>,
    start_s: f64,
    duration_s: f64,
) -> UnitQuaternion<f64> {
    let end = start_s + duration_s;
    let inside: Vec<UnitQuaternion<f64>> = track
        .iter()
        .filter(|(t, _)| *t >= start_s && *t <= end)
        .map(|(_, q)| *q)
        .collect();
    if inside.is_empty() {
        return track.sample_at(start_s + duration_s / 2.0);
    }
    mean_rotation(&inside)
}

/// A heading (or a sensor's alignment) less sure than this is refused (module docs), degrees.
pub const MAX_HEADING_UNCERTAINTY_DEG: f64 = 10.0;
/// How well a strapped sensor's declared `forward` axis follows the body's facing, degrees.
pub const FORWARD_AXIS_DEG: f64 = 5.0;
/// How well a known mount (a sensor fixed in a housing) is known, degrees.
pub const KNOWN_MOUNT_DEG: f64 = 3.0;
/// How close the knee's flexion axis is to the body's left–right axis, degrees.
pub const KNEE_AXIS_DEG: f64 = 3.0;
/// How far one leg's knee axis may turn from the body's left–right axis by the leg turning out
/// (toe-out and hip rotation in gait, about 5–10°), degrees: what one leg alone cannot cancel.
pub const ONE_LEG_DEG: f64 = 8.0;
/// The same for one arm: a relaxed arm hangs turned in, so its elbow flexes the hand forward and
/// towards the midline, well off the left–right axis (24° for CMU 01_01's right elbow held in its
/// frame 1): one elbow alone cannot give a sure heading.
pub const ONE_ARM_DEG: f64 = 30.0;

/// A sensor turning further than this from its mean during the calibration window is reported.
pub const MOVED_DURING_CALIBRATION_DEG: f64 = 5.0;

/// How far past the calibration window the hinges are read for the heading, seconds: a take
/// need not start moving at once (a subject standing a while, then hopping or waving).
pub const HINGE_SEARCH_S: f64 = 60.0;

/// A hinge sample counts towards the heading when the joint has flexed this far since
/// calibration (about a horizontal axis), degrees: below it, sensor noise and the joint's other
/// small turns would dominate its axis.
pub const FLEXED_DEG: f64 = 10.0;

/// The least time a hinge must spend flexed to give an axis, seconds (a stray twitch does not).
pub const MIN_FLEXED_S: f64 = 0.5;

/// A limb segment hanging down in the calibration pose, as a hinge's axis needs to mean
/// left–right: in the pose's world (`pose_positions`, the joints' positions with the pose held),
/// the joint is above the segment's joint below it (or its end site) and the segment points mostly
/// down. Read in the pose, not in the rig's zero pose, which need not stand. `Some`: the unit
/// direction down the segment (pose world).
fn stands_down(
    rig: &Rig,
    pose_positions: &[Vector3<f64>],
    pose_world: &[UnitQuaternion<f64>],
    joint: usize,
) -> Option<Vector3<f64>> {
    let j = &rig.joints()[joint];
    j.parent?;
    let below = rig
        .children(joint)
        .map(|c| pose_positions[c])
        .chain(
            j.end_site
                .map(|e| pose_positions[joint] + pose_world[joint] * e),
        )
        .next()?;
    let v = below - pose_positions[joint];
    (v.norm() > 0.0 && -v.y > 0.8 * v.norm()).then(|| v.normalize())
}

/// One hinge joint's samples for the heading (a knee: thigh and shank; an elbow: upper arm and
/// forearm): at each of the outer segment's samples in the [`HINGE_SEARCH_S`] after the window,
/// the time (s) and the inner and the outer segment's rotations since calibration (rig world).
#[derive(Debug, Clone)]
pub struct HingeSamples {
    pub pair: HingePair,
    pub samples: Vec<(f64, UnitQuaternion<f64>, UnitQuaternion<f64>)>,
}

/// A knee or an elbow whose two segments both carry a sensor and hang down in the calibration
/// pose: the sensors (indices in mapping order) on its inner segment (thigh, upper arm) and its
/// outer one (shank, forearm), and the unit directions down each segment in the pose (pose
/// world: the long axes a turn-out turns the segments about, [`solve`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HingePair {
    pub side: crate::rig::anatomy::Side,
    /// +1 for a knee (it flexes about the subject's left: the foot swings back), −1 for an
    /// elbow (about the right: the hand comes forward).
    pub flexes_about_left: f64,
    pub inner: usize,
    pub outer: usize,
    pub inner_down: Vector3<f64>,
    pub outer_down: Vector3<f64>,
}

/// Every mapped knee and elbow whose segments hang down in the calibration pose (`pose_local`,
/// the pose's local rotations). Whether both sensors have a heading of their own is left to the
/// caller ([`HingePair::usable`]): a stream learns it only as fusion starts.
fn hinge_pairs(
    rig: &Rig,
    pose_local: &[UnitQuaternion<f64>],
    sensors: &[ResolvedSensor],
) -> Vec<HingePair> {
    use crate::rig::anatomy::{Anatomy, Limb, Side};
    let anatomy = Anatomy::of(rig);
    let pose_world = rig.world_rotations(pose_local);
    let pose_positions = rig.world_positions(pose_local, Vector3::zeros());
    let sensor_of = |bone: usize| sensors.iter().position(|s| s.bone == bone);
    let mut pairs = Vec::new();
    for side in Side::BOTH {
        for (inner, outer, sign) in [
            (Limb::Thigh, Limb::Shank, 1.0),
            (Limb::UpperArm, Limb::Forearm, -1.0),
        ] {
            let (Some(inner), Some(outer)) = (anatomy.limb(side, inner), anatomy.limb(side, outer))
            else {
                continue;
            };
            let (Some(i), Some(o)) = (sensor_of(inner), sensor_of(outer)) else {
                continue;
            };
            if let (Some(inner_down), Some(outer_down)) = (
                stands_down(rig, &pose_positions, &pose_world, inner),
                stands_down(rig, &pose_positions, &pose_world, outer),
            ) {
                pairs.push(HingePair {
                    side,
                    flexes_about_left: sign,
                    inner: i,
                    outer: o,
                    inner_down,
                    outer_down,
                });
            }
        }
    }
    pairs
}

impl HingePair {
    /// Both segments' sensors share the world's north (one fused without a magnetometer sits in
    /// a world of its own, about which the pair's relative turn says nothing of the body).
    fn usable(&self, sensors: &[ResolvedSensor]) -> bool {
        !sensors[self.inner].own_heading && !sensors[self.outer].own_heading
    }
}

/// Every hinge ([`hinge_pairs`]) that is [`HingePair::usable`] or not, as `usable` says, with its
/// samples over the [`HINGE_SEARCH_S`] after the window: at each of the outer sensor's, the inner
/// one's read at that time ([`HingeSample`]).
fn hinges_after(
    rig: &Rig,
    pose_local: &[UnitQuaternion<f64>],
    sensors: &[ResolvedSensor],
    tracks: &[Track<UnitQuaternion<f64>>],
    window: &CalibrationWindow,
    usable: bool,
) -> Vec<(HingePair, Vec<HingeSample>)> {
    let (start, end) = (window.end_s(), window.end_s() + HINGE_SEARCH_S);
    hinge_pairs(rig, pose_local, sensors)
        .into_iter()
        .filter(|p| p.usable(sensors) == usable)
        .map(|p| {
            let samples = tracks[p.outer]
                .iter()
                .filter(|(t, _)| *t > start && *t <= end)
                .map(|(t, q)| (t, tracks[p.inner].sample_at(t), *q))
                .collect();
            (p, samples)
        })
        .collect()
}

/// Usable hinges' samples ([`hinges_after`]) as [`HingeSamples`]: each segment's rotation since
/// calibration (`held`, the poses as held).
fn since_calibration(
    hinges: Vec<(HingePair, Vec<HingeSample>)>,
    held: &[UnitQuaternion<f64>],
) -> Vec<HingeSamples> {
    hinges
        .into_iter()
        .map(|(pair, samples)| {
            let (i, o) = (pair.inner, pair.outer);
            let samples = samples
                .into_iter()
                .map(|(t, inner, outer)| (t, inner * held[i].inverse(), outer * held[o].inverse()))
                .collect();
            HingeSamples { pair, samples }
        })
        .collect()
}

/// A knee or an elbow with a sensor without a heading of its own ("6D") on one or both segments:
/// the turn between the two sensors' worlds ([`super::hinge_axis`]) and, when the hinge flexed
/// for [`MIN_FLEXED_S`], the turn `Y` about +Y that faces the inner sensor's world to +Z with the
/// hinge's axis to the subject's left (as [`heading_from_hinges`] does a shared world's), unsure
/// by its axis's uncertainty (over the axis's horizontal fraction) and `D`'s, combined as
/// independent (`√(u_a² + u_D²)`), degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SixDHinge {
    pub pair: HingePair,
    pub outer_to_inner: UnitQuaternion<f64>,
    /// How far off `D` may be, degrees ([`super::hinge_axis::HingeFit::delta_uncertainty_deg`],
    /// one independent look per second the samples span).
    pub outer_to_inner_deg: f64,
    pub facing: Option<(UnitQuaternion<f64>, f64)>,
}

impl SixDHinge {
    /// `Y_k` for sensor `k` (`q_world_bone = Y_k ⊗ q_rig_sensor ⊗ q_bone_sensor⁻¹`) and its
    /// uncertainty, if `k` is on this hinge: a sensor whose partner keeps the world's north is
    /// turned into that world and the heading `H` applied to it (`north`: `H` and its
    /// uncertainty, infinite when unknown), `H ⊗ D` (outer) or `H ⊗ D⁻¹` (inner); of two 6D
    /// sensors, by the hinge's facing `Y`: `Y` (inner) or `Y ⊗ D` (outer).
    fn align(
        &self,
        k: usize,
        sensors: &[ResolvedSensor],
        (h, u): (UnitQuaternion<f64>, f64),
    ) -> Option<(UnitQuaternion<f64>, f64)> {
        let (inner, outer) = (self.pair.inner, self.pair.outer);
        let d = self.outer_to_inner;
        // A turn between the worlds or a facing less sure than a heading may be aligns nothing
        // (the sensor is warned about); turned into its partner's world, a sensor is as sure as
        // the partner's heading too, whatever that is (`heading: sensors` keeps an unknown one).
        if too_unsure(self.outer_to_inner_deg) {
            return None;
        }
        let facing = || self.facing.filter(|(_, u)| !too_unsure(*u));
        let north = u.hypot(self.outer_to_inner_deg);
        if k == inner {
            if sensors[outer].own_heading {
                facing()
            } else {
                Some((h * d.inverse(), north))
            }
        } else if k == outer {
            if sensors[inner].own_heading {
                facing().map(|(y, u)| (y * d, u))
            } else {
                Some((h * d, north))
            }
        } else {
            None
        }
    }
}

/// The least horizontal fraction of a hinge's fitted axis at calibration for a 6D sensor to be
/// aligned by it (the axis within 30° of horizontal).
pub const HINGE_HORIZONTAL: f64 = 0.866;

/// Two candidate turns between a hinge's worlds whose residuals differ by more than this, degrees,
/// are told apart by them ([`six_d_hinge`]).
pub const HINGE_RESIDUAL_APART_DEG: f64 = 1.0;

/// A 6D hinge's samples after the window (time, inner, outer: rig world, each in its own) and
/// their [`HingeFit`](super::hinge_axis::HingeFit) sums, folded as they come (a stream reads the
/// samples again at each look, the sums not).
#[derive(Debug, Clone, Default)]
struct SixDSamples {
    fit: super::hinge_axis::HingeFit,
    samples: Vec<HingeSample>,
}

impl SixDSamples {
    fn push(&mut self, sample: HingeSample) {
        self.fit.push(&sample.1, &sample.2);
        self.samples.push(sample);
    }
}

impl FromIterator<HingeSample> for SixDSamples {
    fn from_iter<I: IntoIterator<Item = HingeSample>>(samples: I) -> SixDSamples {
        let mut folded = SixDSamples::default();
        for sample in samples {
            folded.push(sample);
        }
        folded
    }
}

/// A hinge with a 6D sensor from its samples after the window and the poses as held: the turn
/// between its sensors' worlds, then its flexion folded in the inner sensor's world with the
/// outer one's turned into it ([`SixDHinge`]). `None` without samples, or when the axis fitted is
/// over 30° from horizontal at calibration ([`HINGE_HORIZONTAL`]).
fn six_d_hinge(
    pair: HingePair,
    hinge: &SixDSamples,
    held: &[UnitQuaternion<f64>],
) -> Option<SixDHinge> {
    let (i, o) = (pair.inner, pair.outer);
    let (fit, samples) = (&hinge.fit, &hinge.samples);
    let fitted = fit.solve()?;
    // A segment hanging down flexes about a horizontal axis; one that turns about a
    // steeper one is not this hinge's flexion (a forearm twisting, say).
    let horizontal = horizontal_fraction(&(held[i] * fitted.inner));
    if horizontal < HINGE_HORIZONTAL {
        return None;
    }
    let fitted = fitted.outer_to_inner;
    // A hinge's axis that stays horizontal fits a half turn about the vertical as well:
    // the outer segment turned round, its hinge flexing the other way as much as the inner
    // segment swings — a knee that bends backwards. Of the two: the one a single axis
    // explains better, when the other is clearly worse (an axis that tilts tells them
    // apart); else the one whose hinge bends least the wrong way from the pose (Σ of the
    // squared turns against its mean axis).
    let half_turn = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI);
    let sign = pair.flexes_about_left;
    let fold = |d: UnitQuaternion<f64>| {
        let (held_i, held_o) = (held[i].inverse(), held[o].inverse() * d.inverse());
        let turns = samples
            .iter()
            .map(move |(t, inner, outer)| (*t, inner * held_i, d * outer * held_o));
        let mut flexion = HingeFlexion::new(pair);
        for (t, inner, outer) in turns.clone() {
            flexion.push(t, &inner, &outer);
        }
        let look = heading_from_flexion([&flexion])?;
        let axis = *look.axes.iter().flatten().next()?;
        let backwards: f64 = turns
            .map(|(_, inner, outer)| {
                let v = (inner.inverse() * outer).scaled_axis() * sign;
                v.dot(&axis.left).min(0.0).powi(2)
            })
            .sum();
        Some((
            (fit.residual_deg_at(&d), backwards),
            d,
            (look.heading, axis.uncertainty_deg / horizontal),
        ))
    };
    let span_s = match (samples.first(), samples.last()) {
        (Some(first), Some(last)) => last.0 - first.0,
        _ => 0.0,
    };
    let candidates = [fitted, half_turn * fitted].map(fold);
    let chosen = candidates.iter().flatten().min_by(|a, b| {
        let ((ra, ba), (rb, bb)) = (a.0, b.0);
        if (ra - rb).abs() > HINGE_RESIDUAL_APART_DEG {
            ra.total_cmp(&rb)
        } else {
            ba.total_cmp(&bb)
        }
    });
    let (d, facing) = match chosen {
        Some((_, d, facing)) => (*d, Some(*facing)),
        None => (fitted, None),
    };
    let outer_to_inner_deg = fit.delta_uncertainty_deg(&d, span_s);
    Some(SixDHinge {
        pair,
        outer_to_inner: d,
        outer_to_inner_deg,
        facing: facing.map(|(y, u)| (y, u.hypot(outer_to_inner_deg))),
    })
}

/// Sign-aligned mean of unit quaternions (accurate for the small spread of a held pose).
pub fn mean_rotation(samples: &[UnitQuaternion<f64>]) -> UnitQuaternion<f64> {
    let first = samples[0].into_inner();
    let mut sum = Quaternion::new(0.0, 0.0, 0.0, 0.0);
    for q in samples {
        let q = q.into_inner();
        sum += if q.dot(&first) < 0.0 { -q } else { q };
    }
    UnitQuaternion::from_quaternion(sum)
}

/// The rotation about +Y that turns horizontal direction `d` (rig world) to +Z, or `None` when
/// `d` is too close to vertical to have a heading.
pub fn heading_towards_plus_z(d: &Vector3<f64>) -> Option<UnitQuaternion<f64>> {
    let horizontal = (d.x * d.x + d.z * d.z).sqrt();
    if horizontal < 0.25 * d.norm() {
        return None;
    }
    let psi = d.x.atan2(d.z);
    Some(UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -psi))
}

/// The heading from the hinges, and its uncertainty in degrees (module docs). A knee flexes about
/// the subject's left axis and an elbow about the right, whatever the mounts. The outer segment's
/// turn relative to the inner one, `Δ_inner⁻¹ ⊗ Δ_outer` (both world-frame rotations since
/// calibration), is the joint's turn about its own axis as the axis stood at calibration —
/// whichever way the body has turned since — so each flexed sample's rotation vector (horizontal
/// part, at least [`FLEXED_DEG`]) points along the hinge's axis in the calibration pose; forward
/// = left × up. Each hinge's mean axis counts once: with both sides, a leg or arm turned out
/// (toe-out, hip or shoulder rotation) turns its axis one way and the other side's the mirror
/// way, which their mean cancels. `None` when no hinge flexes for [`MIN_FLEXED_S`].
pub fn heading_from_hinges(hinges: &[HingeSamples]) -> Option<HingeLook> {
    let folded: Vec<HingeFlexion> = hinges
        .iter()
        .map(|h| {
            let mut f = HingeFlexion::new(h.pair);
            for (t, inner, outer) in &h.samples {
                f.push(*t, inner, outer);
            }
            f
        })
        .collect();
    heading_from_flexion(&folded)
}

/// One hinge's flexion folded sample by sample — all [`heading_from_hinges`] needs of its
/// samples, so a stream keeps a few numbers per hinge, not the samples.
#[derive(Debug, Clone)]
pub struct HingeFlexion {
    pair: HingePair,
    /// Σ of the flexed samples' horizontal rotation vectors (radians, towards the left).
    sum: Vector3<f64>,
    /// Σ of their lengths.
    lengths: f64,
    flexed: usize,
    samples: usize,
    first_s: f64,
    last_s: f64,
    /// Whole seconds in which it flexed (samples come in time order, so a change of second
    /// is a new one).
    seconds: usize,
    last_second: Option<i64>,
}

impl HingeFlexion {
    pub fn new(pair: HingePair) -> HingeFlexion {
        HingeFlexion {
            pair,
            sum: Vector3::zeros(),
            lengths: 0.0,
            flexed: 0,
            samples: 0,
            first_s: f64::NAN,
            last_s: f64::NAN,
            seconds: 0,
            last_second: None,
        }
    }

    /// The sample at `t_s` (times increasing): the inner and the outer segment's rotations since
    /// calibration (rig world).
    pub fn push(&mut self, t_s: f64, inner: &UnitQuaternion<f64>, outer: &UnitQuaternion<f64>) {
        if self.samples == 0 {
            self.first_s = t_s;
        }
        self.samples += 1;
        self.last_s = t_s;
        let v = (inner.inverse() * outer).scaled_axis();
        let v = Vector3::new(v.x, 0.0, v.z) * self.pair.flexes_about_left;
        if v.norm() < FLEXED_DEG.to_radians() {
            return;
        }
        self.sum += v;
        self.lengths += v.norm();
        self.flexed += 1;
        let second = t_s.floor() as i64;
        if self.last_second != Some(second) {
            self.seconds += 1;
            self.last_second = Some(second);
        }
    }

    /// The time it spent flexed, seconds: its share of flexed samples over the time they span.
    fn flexed_s(&self) -> f64 {
        if self.samples > 1 {
            (self.last_s - self.first_s) * self.flexed as f64 / (self.samples - 1) as f64
        } else {
            0.0
        }
    }
}

/// What the hinges say: the heading and its uncertainty (degrees), and each hinge's own axis
/// ([`HingeAxis`]; `[knee, elbow] × [left, right]`, fixed so that a stream looking once a second
/// does not allocate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HingeLook {
    pub heading: UnitQuaternion<f64>,
    pub uncertainty_deg: f64,
    pub axes: [Option<HingeAxis>; 4],
}

impl HingeLook {
    /// A heading alone, no hinge's own axis (tests).
    #[cfg(test)]
    pub fn heading_only(heading: UnitQuaternion<f64>, uncertainty_deg: f64) -> HingeLook {
        HingeLook {
            heading,
            uncertainty_deg,
            axes: [None; 4],
        }
    }
}

/// One hinge's axis where it stood at calibration: the mean of its flexed samples' horizontal
/// rotation vectors (rig world before the heading, towards the subject's left for a knee and an
/// elbow alike), and how sure (degrees): its samples' circular spread over √(seconds flexed),
/// never below [`HINGE_AXIS_DEG`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HingeAxis {
    pub pair: HingePair,
    pub left: Vector3<f64>,
    pub uncertainty_deg: f64,
}

/// The least uncertainty of one hinge's own axis, degrees: how far sensor noise and the skin's
/// give over a minute of flexion may still leave it.
pub const HINGE_AXIS_DEG: f64 = 1.0;

/// [`heading_from_hinges`] from the hinges' folded flexion.
pub fn heading_from_flexion<'a>(
    hinges: impl IntoIterator<Item = &'a HingeFlexion>,
) -> Option<HingeLook> {
    let mut left = Vector3::zeros();
    // Each hinge's axes' spread about its own mean (squared, radians), weighted by its samples.
    let (mut spread_sq, mut count, mut looks) = (0.0, 0usize, 0.0);
    let mut axes = [None; 4];
    for hinge in hinges {
        let n = hinge.flexed;
        if n == 0 || hinge.flexed_s() < MIN_FLEXED_S || hinge.sum.norm() == 0.0 {
            continue;
        }
        // The weighted mean resultant length R gives the circular spread sqrt(-2 ln R).
        let resultant = (hinge.sum.norm() / hinge.lengths).clamp(1e-12, 1.0);
        let hinge_spread_sq = -2.0 * resultant.ln();
        spread_sq += hinge_spread_sq * n as f64;
        count += n;
        let axis = hinge.sum.normalize();
        left += axis;
        // One independent look per hinge per second flexed in (about a stride).
        let seconds = hinge.seconds.max(1) as f64;
        looks += hinge.seconds as f64;
        let pair = hinge.pair;
        let kind = usize::from(pair.flexes_about_left < 0.0);
        let side = usize::from(pair.side == crate::rig::anatomy::Side::Right);
        axes[2 * kind + side] = Some(HingeAxis {
            pair,
            left: axis,
            uncertainty_deg: (hinge_spread_sq.sqrt().to_degrees() / seconds.sqrt())
                .max(HINGE_AXIS_DEG),
        });
    }
    if count == 0 {
        return None;
    }
    let heading = heading_towards_plus_z(&left.normalize().cross(&Vector3::y()))?;
    let spread_deg = (spread_sq / count as f64).sqrt().to_degrees();
    // A kind of hinge seen on both sides cancels its turn-out; else a lone knee bounds it at
    // ONE_LEG_DEG, lone elbows at ONE_ARM_DEG.
    let seen = |kind: usize, side: usize| axes[2 * kind + side].is_some();
    let one_side = if (0..2).any(|kind| seen(kind, 0) && seen(kind, 1)) {
        0.0
    } else if seen(0, 0) || seen(0, 1) {
        ONE_LEG_DEG
    } else {
        ONE_ARM_DEG
    };
    let uncertainty = KNEE_AXIS_DEG
        .max(spread_deg / looks.max(1.0).sqrt())
        .max(one_side);
    tracing::debug!(
        spread_deg,
        looks,
        hinges = axes.iter().flatten().count(),
        uncertainty,
        "the heading from the hinges"
    );
    Some(HingeLook {
        heading,
        uncertainty_deg: uncertainty,
        axes,
    })
}

/// The horizontal fraction of `d` (1 when horizontal, 0 when vertical).
fn horizontal_fraction(d: &Vector3<f64>) -> f64 {
    let n = d.norm();
    if n == 0.0 {
        0.0
    } else {
        (d.x * d.x + d.z * d.z).sqrt() / n
    }
}

/// What sensor `i`'s turn between the two poses says: the sensor's and its bone's turns
/// (rotation vectors, world frame) and, when both turn about horizontal enough axes, the turn about
/// +Y taking the first onto the second ([`yaw_between`]) with its uncertainty, `KNOWN_MOUNT_DEG`
/// over the smaller horizontal fraction of the two axes.
struct SecondPoseLook {
    sensor_turn: Vector3<f64>,
    bone_turn: Vector3<f64>,
    yaw: Option<(UnitQuaternion<f64>, f64)>,
}

fn second_pose_look(first: &Held, second: &Held, i: usize) -> SecondPoseLook {
    let turn = |a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>| (b * a.inverse()).scaled_axis();
    let sensor_turn = turn(&first.held[i], &second.held[i]);
    let bone_turn = turn(&first.pose_world[i], &second.pose_world[i]);
    let yaw = yaw_between(&sensor_turn, &bone_turn).map(|y| {
        let f = horizontal_fraction(&sensor_turn).min(horizontal_fraction(&bone_turn));
        (y, KNOWN_MOUNT_DEG / f)
    });
    SecondPoseLook {
        sensor_turn,
        bone_turn,
        yaw,
    }
}

/// The heading from a second pose: for each sensor with a heading of its own whose bone turns
/// about a horizontal enough axis between the poses, the turn about +Y taking the sensor's turn
/// onto the bone's ([`yaw_between`]); their circular mean, and its uncertainty (module docs).
fn heading_from_second_pose(
    sensors: &[ResolvedSensor],
    first: &Held,
    second: &Held,
) -> Option<(UnitQuaternion<f64>, f64)> {
    let looks: Vec<(f64, f64)> = sensors
        .iter()
        .enumerate()
        .filter(|(_, s)| !s.own_heading)
        .filter_map(|(i, _)| second_pose_look(first, second, i).yaw)
        .map(|(y, u)| (y.scaled_axis().y, u))
        .collect();
    let best = looks.iter().map(|l| l.1).fold(f64::INFINITY, f64::min);
    let (sin, cos) = looks
        .iter()
        .fold((0.0, 0.0), |(s, c), (a, _)| (s + a.sin(), c + a.cos()));
    if looks.is_empty() {
        return None;
    }
    let n = looks.len() as f64;
    let resultant = ((sin * sin + cos * cos).sqrt() / n).clamp(1e-12, 1.0);
    let spread_deg = (-2.0 * resultant.ln()).sqrt().to_degrees();
    let heading = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), sin.atan2(cos));
    Some((heading, best.max(spread_deg / n.sqrt())))
}

/// One source's look at the heading (sidecar `pipeline.heading_looks`): where it came from, the
/// turn about +Y it gives (degrees), its uncertainty (degrees) and whether it agreed with the
/// others ([`combine_looks`]).
#[derive(Debug, Clone, PartialEq)]
pub struct HeadingLook {
    pub source: HeadingSource,
    pub heading_deg: f64,
    pub uncertainty_deg: f64,
    pub agrees: bool,
}

impl HeadingLook {
    fn new(source: HeadingSource, heading: &UnitQuaternion<f64>, uncertainty_deg: f64) -> Self {
        HeadingLook {
            source,
            heading_deg: heading.scaled_axis().y.to_degrees(),
            uncertainty_deg,
            agrees: true,
        }
    }
}

/// One heading from every look, each weighed by its uncertainty: the circular mean with weights
/// `1/u²`. A look further from it than three of its own uncertainties disagrees: it is left out
/// (and warned about) and the mean taken again without it; should every look disagree, the
/// surest alone decides. The result: the heading, the source of the first agreeing look (`looks`
/// come in the order declared forward, known mounts, second pose, hinges: the sidecar's
/// `heading` names what the subject set up, when it agreed), and the uncertainty of the mean,
/// `(Σ 1/u²)^(−½)` over the agreeing looks. `None` without looks.
fn combine_looks(
    looks: &mut [HeadingLook],
    warnings: &mut Vec<String>,
) -> Option<(UnitQuaternion<f64>, HeadingSource, f64)> {
    let mean = |looks: &[HeadingLook]| -> Option<f64> {
        let (sin, cos) = looks
            .iter()
            .filter(|l| l.agrees)
            .fold((0.0, 0.0), |(s, c), l| {
                let (w, a) = (l.uncertainty_deg.powi(-2), l.heading_deg.to_radians());
                (s + w * a.sin(), c + w * a.cos())
            });
        (sin != 0.0 || cos != 0.0).then(|| sin.atan2(cos).to_degrees())
    };
    let first = mean(looks)?;
    for l in looks.iter_mut() {
        l.agrees =
            crate::rotation::wrap_deg(l.heading_deg - first).abs() <= 3.0 * l.uncertainty_deg;
    }
    if !looks.iter().any(|l| l.agrees) {
        let surest = looks
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.uncertainty_deg.total_cmp(&b.1.uncertainty_deg))
            .map(|(i, _)| i)?;
        looks[surest].agrees = true;
    }
    let heading_deg = mean(looks)?;
    for l in looks.iter().filter(|l| !l.agrees) {
        warnings.push(format!(
            "the heading from {}{} ({:.1}°, ±{:.1}°) disagrees with the others ({:.1}°) by more than three times its uncertainty: left out",
            l.source.label(),
            l.source
                .sensor()
                .map_or(String::new(), |s| format!(" (sensor `{s}`)")),
            l.heading_deg,
            l.uncertainty_deg,
            heading_deg
        ));
    }
    let agreeing = looks.iter().filter(|l| l.agrees);
    let first = agreeing.clone().next()?;
    let uncertainty = combined_uncertainty_deg(agreeing.map(|l| l.uncertainty_deg));
    Some((
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), heading_deg.to_radians()),
        first.source.clone(),
        uncertainty,
    ))
}

/// The uncertainty of looks combined by their weights `1/u²`: `(Σ 1/u²)^(−½)`, degrees (an
/// infinite one weighs nothing; infinite without any).
fn combined_uncertainty_deg(uncertainties_deg: impl IntoIterator<Item = f64>) -> f64 {
    uncertainties_deg
        .into_iter()
        .map(|u| u.powi(-2))
        .sum::<f64>()
        .powf(-0.5)
}

/// Less sure than [`MAX_HEADING_UNCERTAINTY_DEG`] (or unknown), degrees.
fn too_unsure(uncertainty_deg: f64) -> bool {
    uncertainty_deg.is_nan() || uncertainty_deg > MAX_HEADING_UNCERTAINTY_DEG
}

/// Solves heading, alignments and mounts.
///
/// `first.held[i]`: sensor i's mean orientation over the window, in the rig world (`C ⊗ q`);
/// `first.pose_world[i]`: its bone's world orientation in the calibration pose; `second`: the
/// same for the second pose, if any. `hinges`: the heading from the knees and elbows
/// ([`heading_from_hinges`]), used when neither a declared forward axis nor a known mount gives
/// one. Only sensors with a heading of their own give the heading `H`; the others are aligned
/// one by one (module docs). Under `policy` [`HeadingPolicy::Sensors`] a combination less sure
/// than [`MAX_HEADING_UNCERTAINTY_DEG`] is not applied: the sensors' own north is kept, as when
/// nothing gives the heading, and a warning says so (under `estimate` the pipeline refuses it).
pub fn solve(
    sensors: &[ResolvedSensor],
    first: &Held,
    second: Option<&Held>,
    hinges: Option<HingeLook>,
    policy: HeadingPolicy,
) -> Calibration {
    solve_aligning(sensors, first, second, hinges, &[], policy)
}

/// [`solve`], with the knees and elbows that sensors without a heading of their own drive
/// ([`six_d_hinge`]) to align those sensors by, after a known mount, a declared forward axis and
/// a second pose.
pub fn solve_aligning(
    sensors: &[ResolvedSensor],
    first: &Held,
    second: Option<&Held>,
    hinges: Option<HingeLook>,
    six_d: &[SixDHinge],
    policy: HeadingPolicy,
) -> Calibration {
    let (held, pose_world) = (&first.held, &first.pose_world);
    let mut warnings = Vec::new();
    let mut looks = Vec::new();
    // 1. Each declared forward axis.
    for (i, s) in sensors.iter().enumerate() {
        let Some(axis) = s.forward.filter(|_| !s.own_heading) else {
            continue;
        };
        let facing = held[i] * axis;
        match heading_towards_plus_z(&facing) {
            Some(h) => looks.push(HeadingLook::new(
                HeadingSource::DeclaredForward {
                    sensor: s.sensor.clone(),
                },
                &h,
                FORWARD_AXIS_DEG / horizontal_fraction(&facing),
            )),
            None => warnings.push(format!(
                "sensor `{}`: its forward axis points almost vertically during calibration; it cannot give the heading",
                s.sensor
            )),
        }
    }
    // 2. Each known mount: the bone's forward (+Z in the pose) seen through the sensor.
    for (i, s) in sensors.iter().enumerate() {
        let Mount::Fixed(mount) = s.mount else {
            continue;
        };
        if s.own_heading {
            continue;
        }
        let bone_world_unturned = held[i] * mount.inverse();
        let facing = bone_world_unturned * (pose_world[i].inverse() * Vector3::z());
        if let Some(h) = heading_towards_plus_z(&facing) {
            looks.push(HeadingLook::new(
                HeadingSource::KnownMount {
                    sensor: s.sensor.clone(),
                },
                &h,
                KNOWN_MOUNT_DEG / horizontal_fraction(&facing),
            ));
        }
    }
    // 3. A second pose, 4. the hinges.
    if let Some((h, u)) = second.and_then(|p| heading_from_second_pose(sensors, first, p)) {
        looks.push(HeadingLook::new(HeadingSource::SecondPose, &h, u));
    }
    if let Some(look) = &hinges {
        looks.push(HeadingLook::new(
            HeadingSource::Hinges,
            &look.heading,
            look.uncertainty_deg,
        ));
    }
    let combined = match combine_looks(&mut looks, &mut warnings) {
        // Kept deliberately, the sensors' north is not traded for a heading this unsure.
        Some((_, source, u)) if policy == HeadingPolicy::Sensors && too_unsure(u) => {
            warnings.push(format!(
                "the heading from `{}` is unsure by {u:.1}° (more than {MAX_HEADING_UNCERTAINTY_DEG}°): \
                 the sensors' own north is kept",
                source.label()
            ));
            for l in &mut looks {
                l.agrees = false;
            }
            None
        }
        c => c,
    };
    let (heading, heading_source, heading_uncertainty_deg) = combined.unwrap_or((
        UnitQuaternion::identity(),
        HeadingSource::None,
        f64::INFINITY,
    ));

    // 5. Sensors without a heading of their own, each aligned by Y_i = H ⊗ A_i.
    let mut align = vec![UnitQuaternion::identity(); sensors.len()];
    let mut alignment = vec![Alignment::OwnHeading; sensors.len()];
    let mut aligned_within = vec![f64::INFINITY; sensors.len()];
    for (i, s) in sensors.iter().enumerate().filter(|(_, s)| s.own_heading) {
        let by_mount = match s.mount {
            Mount::Fixed(mount) => {
                let y = twist_about_y(&(pose_world[i] * mount * held[i].inverse()));
                let facing = held[i] * mount.inverse() * (pose_world[i].inverse() * Vector3::z());
                Some((y, KNOWN_MOUNT_DEG / horizontal_fraction(&facing)))
            }
            Mount::Calibrate => None,
        };
        let by_forward = || {
            s.forward.and_then(|axis| {
                let facing = held[i] * axis;
                heading_towards_plus_z(&facing)
                    .map(|y| (y, FORWARD_AXIS_DEG / horizontal_fraction(&facing)))
            })
        };
        let mut by_second_pose = || {
            second.and_then(|p| {
                let look = second_pose_look(first, p, i);
                if look.yaw.is_none() {
                    warnings.push(format!(
                        "sensor `{}`: between the two calibration poses it turned {:.0}° and its bone \
                         should turn {:.0}°, about axes too close to vertical (or too little) to align its heading",
                        s.sensor,
                        look.sensor_turn.norm().to_degrees(),
                        look.bone_turn.norm().to_degrees(),
                    ));
                }
                look.yaw
            })
        };
        let by_hinge = || {
            six_d
                .iter()
                .find_map(|h| h.align(i, sensors, (heading, heading_uncertainty_deg)))
        };
        let (y, how) = if let Some(y) = by_mount {
            (Some(y), Alignment::Mount)
        } else if let Some(y) = by_forward() {
            (Some(y), Alignment::Forward)
        } else if let Some(y) = by_second_pose() {
            (Some(y), Alignment::SecondPose)
        } else if let Some(y) = by_hinge() {
            (Some(y), Alignment::Hinge)
        } else {
            (None, Alignment::None)
        };
        if let Some((y, u)) = y {
            align[i] = heading.inverse() * y;
            aligned_within[i] = u;
        }
        alignment[i] = how;
    }
    warnings.extend(unaligned_warning(sensors, &alignment, second.is_some()));
    let all_aligned = heading_source == HeadingSource::None
        && sensors.iter().all(|s| s.own_heading)
        && alignment.iter().any(|a| *a != Alignment::None);
    let (heading_source, heading_uncertainty_deg) = if all_aligned {
        let worst = aligned_within.iter().copied().fold(0.0, f64::max);
        (HeadingSource::Aligned, worst)
    } else {
        (heading_source, heading_uncertainty_deg)
    };
    // 6. The segments of the knees and elbows, each turned about its long axis by its hinge.
    let mount_turns = match &hinges {
        Some(look) if heading_source != HeadingSource::None => {
            hinge_turns(sensors, look, &heading, &mut warnings)
        }
        _ => vec![None; sensors.len()],
    };
    let axes_uncertainty_deg = sensors
        .iter()
        .zip(aligned_within.iter().zip(&mount_turns))
        .map(
            |(s, (within, turn))| match (s.own_heading, &s.mount, turn) {
                (true, _, _) => *within,
                (false, Mount::Calibrate, Some(turn)) => turn.uncertainty_deg,
                (false, Mount::Calibrate, None) => heading_uncertainty_deg,
                (false, Mount::Fixed(_), _) => 0.0,
            },
        )
        .collect();
    let mounts = sensors
        .iter()
        .enumerate()
        .map(|(i, s)| match s.mount {
            Mount::Fixed(q) => q,
            Mount::Calibrate => {
                let pose = match &mount_turns[i] {
                    Some(turn) => turn.turn * pose_world[i],
                    None => pose_world[i],
                };
                pose.inverse() * heading * align[i] * held[i]
            }
        })
        .collect();
    Calibration {
        heading,
        heading_source,
        heading_uncertainty_deg,
        heading_looks: looks,
        axes_uncertainty_deg,
        mounts,
        align,
        alignment,
        mount_turns,
        warnings,
        heading_from_s: None,
    }
}

/// How far a hinge's axis may stand from the pose's left before the pose held is taken to be
/// another than the one declared rather than a segment turned in or out, degrees.
pub const MAX_MOUNT_TURN_DEG: f64 = 45.0;

/// A `calibrate` mount's turn from its hinge: the segment stood in the pose turned about its
/// long axis by `deg` (anticlockwise seen from above: the right-hand rule about the direction up
/// the segment; a left leg turned out, a right leg turned in), so its mount is
/// `(T ⊗ P)⁻¹ ⊗ H ⊗ A ⊗ held` with `T` that turn (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountTurn {
    pub turn: UnitQuaternion<f64>,
    pub deg: f64,
    /// Its hinge axis's uncertainty ([`HingeAxis`]), degrees.
    pub uncertainty_deg: f64,
}

/// The turns of the `calibrate` mounts on the hinges' segments (sensors with the world's north,
/// as the hinges' are): each segment turned about the direction up it, `u` (pose world), by the
/// angle from the pose's left (+X, facing +Z) to its hinge's axis turned by the heading, `H ⊗ a`,
/// both seen across `u`: `atan2(u · (x⊥ × a⊥), x⊥ · a⊥)`. A hinge less sure than
/// [`MAX_HEADING_UNCERTAINTY_DEG`] turns nothing; one further than [`MAX_MOUNT_TURN_DEG`] is
/// warned about and turns nothing.
fn hinge_turns(
    sensors: &[ResolvedSensor],
    look: &HingeLook,
    heading: &UnitQuaternion<f64>,
    warnings: &mut Vec<String>,
) -> Vec<Option<MountTurn>> {
    let across = |d: &Vector3<f64>, v: Vector3<f64>| v - d * d.dot(&v);
    let mut turns = vec![None; sensors.len()];
    for axis in look.axes.iter().flatten() {
        if too_unsure(axis.uncertainty_deg) {
            continue;
        }
        let pair = &axis.pair;
        let a = heading * axis.left;
        for (i, d) in [(pair.inner, pair.inner_down), (pair.outer, pair.outer_down)] {
            let s = &sensors[i];
            if s.mount != Mount::Calibrate || s.own_heading {
                continue;
            }
            // Up the segment, so that a turn reads as seen from above.
            let up = -d;
            let (x, a) = (across(&up, Vector3::x()), across(&up, a));
            let deg = up.dot(&x.cross(&a)).atan2(x.dot(&a)).to_degrees();
            if deg.abs() > MAX_MOUNT_TURN_DEG {
                warnings.push(format!(
                    "sensor `{}`: its {} flexes about an axis {deg:.0}° from the pose's left–right; \
                     was the pose held the one declared? Its mount is taken from the pose as declared",
                    s.sensor,
                    if pair.flexes_about_left > 0.0 { "knee" } else { "elbow" },
                ));
                continue;
            }
            turns[i] = Some(MountTurn {
                turn: UnitQuaternion::from_axis_angle(
                    &nalgebra::Unit::new_normalize(up),
                    deg.to_radians(),
                ),
                deg,
                uncertainty_deg: axis.uncertainty_deg,
            });
        }
    }
    turns
}

/// The warning for sensors without a heading of their own that could not be aligned.
fn unaligned_warning(
    sensors: &[ResolvedSensor],
    alignment: &[Alignment],
    had_second_pose: bool,
) -> Option<String> {
    let unaligned: Vec<&str> = sensors
        .iter()
        .zip(alignment)
        .filter(|(_, a)| **a == Alignment::None)
        .map(|(s, _)| s.sensor.as_str())
        .collect();
    if unaligned.is_empty() {
        return None;
    }
    let how = if had_second_pose {
        "give their mounts or a `forward` axis in the mapping, or hold a second pose in which their bones turn about a horizontal axis"
    } else {
        "give their mounts or a `forward` axis in the mapping, or a second calibration pose (`calibration.second`, e.g. `skiing` after `npose`); \
         a thigh, shank, upper arm or forearm is aligned by its knee or elbow flexing after calibration, when both segments hang down in the pose"
    };
    Some(format!(
        "sensor(s) {} have no magnetometer (6D): their heading is their own and could not be aligned, \
         so their bones turn about wrong axes; {how}",
        unaligned.join(", ")
    ))
}

/// The rotation about +Y closest to `q` (the twist of its swing–twist split about +Y).
pub fn twist_about_y(q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    let (w, y) = (q.w, q.j);
    if w.abs() < 1e-12 && y.abs() < 1e-12 {
        // A half turn about a horizontal axis: no twist to speak of.
        return UnitQuaternion::identity();
    }
    UnitQuaternion::from_quaternion(Quaternion::new(w, 0.0, y, 0.0))
}

/// The turn about +Y taking rotation vector `sensor`'s horizontal direction onto `bone`'s: `None`
/// when either turns by less than 10°, or about an axis within 30° of vertical.
fn yaw_between(sensor: &Vector3<f64>, bone: &Vector3<f64>) -> Option<UnitQuaternion<f64>> {
    let usable = |v: &Vector3<f64>| {
        let horizontal = (v.x * v.x + v.z * v.z).sqrt();
        v.norm().to_degrees() >= 10.0 && horizontal >= 0.5 * v.norm()
    };
    if !usable(sensor) || !usable(bone) {
        return None;
    }
    let psi = bone.x.atan2(bone.z) - sensor.x.atan2(sensor.z);
    Some(UnitQuaternion::from_axis_angle(&Vector3::y_axis(), psi))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::anatomy::Side;

    fn rot(axis: Vector3<f64>, deg: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg.to_radians())
    }

    fn sensor(mount: Mount, forward: Option<Vector3<f64>>) -> ResolvedSensor {
        ResolvedSensor {
            sensor: "s".into(),
            bone: 0,
            mount,
            forward,
            own_heading: false,
        }
    }

    fn held(held: UnitQuaternion<f64>, pose: UnitQuaternion<f64>) -> Held {
        Held {
            held: vec![held],
            pose_world: vec![pose],
        }
    }

    /// One elbow's hinges give a heading unsure by 24°: under `heading: sensors` the sensors'
    /// north is kept (heading identity, no source, no look agreeing, a warning); under `estimate`
    /// the look is applied and the pipeline refuses the take.
    #[test]
    fn an_unsure_heading_keeps_the_sensors_north_under_heading_sensors() {
        let hinges = Some(HingeLook::heading_only(rot(Vector3::y(), 40.0), 24.0));
        let s = [sensor(Mount::Calibrate, None)];
        let first = self::held(UnitQuaternion::identity(), UnitQuaternion::identity());
        let kept = solve(&s, &first, None, hinges, HeadingPolicy::Sensors);
        assert_eq!(kept.heading, UnitQuaternion::identity());
        assert_eq!(kept.heading_source, HeadingSource::None);
        assert!(kept.heading_uncertainty_deg.is_infinite());
        assert_eq!(kept.heading_looks.len(), 1);
        assert!(!kept.heading_looks[0].agrees);
        assert!(
            kept.warnings
                .iter()
                .any(|w| w.contains("unsure by 24.0°") && w.contains("sensors' own north")),
            "{:?}",
            kept.warnings
        );
        assert!(
            kept.check_heading(&s, HeadingPolicy::Sensors, "m.json")
                .is_ok()
        );
        let applied = solve(&s, &first, None, hinges, HeadingPolicy::Estimate);
        assert!((applied.heading.angle_to(&rot(Vector3::y(), 40.0))).abs() < 1e-12);
        assert_eq!(applied.heading_source, HeadingSource::Hinges);
        assert!(
            applied
                .check_heading(&s, HeadingPolicy::Estimate, "m.json")
                .is_err()
        );
        // A sure look (3°) is applied under either policy.
        let sure = solve(
            &s,
            &first,
            None,
            Some(HingeLook::heading_only(rot(Vector3::y(), 40.0), 3.0)),
            HeadingPolicy::Sensors,
        );
        assert_eq!(sure.heading_source, HeadingSource::Hinges);
    }

    #[test]
    fn declared_forward_turns_the_subject_to_face_plus_z() {
        // The subject faces +X (rig world, before heading); the sensor's +y axis points forward.
        let held = rot(Vector3::z(), -90.0); // maps sensor +y to +x
        assert!((held * Vector3::y() - Vector3::x()).norm() < 1e-12);
        let cal = solve(
            &[sensor(Mount::Calibrate, Some(Vector3::y()))],
            &self::held(held, UnitQuaternion::identity()),
            None,
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.heading_source.label(), "declared-forward");
        assert!((cal.heading * Vector3::x() - Vector3::z()).norm() < 1e-12);
        // The bone equals its pose (identity) after heading and mount.
        let bone = cal.heading * held * cal.mounts[0].inverse();
        assert!(bone.angle() < 1e-12);
    }

    #[test]
    fn known_mount_gives_heading_and_none_otherwise() {
        // Bone faces -X (turned 90° about Y from the pose, which is identity); sensor mounted
        // with identity: held = bone orientation.
        let held = rot(Vector3::y(), -90.0);
        assert!((held * Vector3::z() + Vector3::x()).norm() < 1e-12);
        let cal = solve(
            &[sensor(Mount::Fixed(UnitQuaternion::identity()), None)],
            &self::held(held, UnitQuaternion::identity()),
            None,
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.heading_source.label(), "mounts");
        assert!((cal.heading * (-Vector3::x()) - Vector3::z()).norm() < 1e-12);
        let cal = solve(
            &[sensor(Mount::Calibrate, None)],
            &self::held(held, UnitQuaternion::identity()),
            None,
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.heading_source, HeadingSource::None);
        assert!(cal.heading.angle() < 1e-12);
    }

    fn hinge(
        side: Side,
        sign: f64,
        samples: Vec<(f64, UnitQuaternion<f64>, UnitQuaternion<f64>)>,
    ) -> HingeSamples {
        HingeSamples {
            pair: HingePair {
                side,
                flexes_about_left: sign,
                inner: 0,
                outer: 1,
                inner_down: -Vector3::y(),
                outer_down: -Vector3::y(),
            },
            samples,
        }
    }

    /// The heading and its uncertainty from the hinges' samples.
    fn hinges_heading(hinges: &[HingeSamples]) -> Option<(UnitQuaternion<f64>, f64)> {
        heading_from_hinges(hinges).map(|l| (l.heading, l.uncertainty_deg))
    }

    #[test]
    fn knees_bending_about_plus_x_mean_facing_plus_z() {
        // A subject facing +Z: left is +X, and knee flexion turns the shank about +X (the foot
        // swings back). Turn the whole scene by 30° about +Y: the heading must undo it.
        let turn = rot(Vector3::y(), 30.0);
        let leg: Vec<_> = (0..50)
            .map(|i| {
                let thigh =
                    turn * rot(Vector3::x(), -20.0 * (i as f64 * 0.2).sin()) * turn.inverse();
                let flex =
                    turn * rot(Vector3::x(), 30.0 + 20.0 * (i as f64 * 0.2).sin()) * turn.inverse();
                (i as f64 * 0.08, thigh, flex * thigh)
            })
            .collect();
        let knee = |side, samples| hinge(side, 1.0, samples);
        let (h, u) = hinges_heading(&[knee(Side::Left, leg.clone())]).unwrap();
        assert!((h * turn * Vector3::z() - Vector3::z()).norm() < 1e-9);
        // Straight knees: no heading.
        let still = vec![(0.0, UnitQuaternion::identity(), rot(Vector3::x(), 2.0)); 10];
        assert!(hinges_heading(&[knee(Side::Left, still)]).is_none());
        // One leg alone: it may be turned out.
        assert!((u - ONE_LEG_DEG).abs() < 1e-9, "{u}");
        // Both legs turned out by 12°, mirror-wise (toe-out): their bisector still faces +Z,
        // and each leg's axis holds still, so only the knee axis's own spread is left.
        let turned = |deg: f64| {
            let out = rot(Vector3::y(), deg);
            leg.iter()
                .map(|(t, a, b)| (*t, out * a * out.inverse(), out * b * out.inverse()))
                .collect::<Vec<_>>()
        };
        let (h, u) = hinges_heading(&[
            knee(Side::Left, turned(12.0)),
            knee(Side::Right, turned(-12.0)),
        ])
        .unwrap();
        assert!((h * turn * Vector3::z() - Vector3::z()).norm() < 1e-9);
        assert!((u - KNEE_AXIS_DEG).abs() < 1e-9, "{u}");
        // A knee whose axis wobbles ±30° through the stride: the spread over √(legs × seconds).
        let wobbly: Vec<_> = leg
            .iter()
            .enumerate()
            .map(|(i, (t, a, b))| {
                let w = rot(Vector3::y(), if i % 2 == 0 { 30.0 } else { -30.0 });
                (*t, w * a * w.inverse(), w * b * w.inverse())
            })
            .collect();
        let (_, u) =
            hinges_heading(&[knee(Side::Left, wobbly.clone()), knee(Side::Right, wobbly)]).unwrap();
        assert!(u > KNEE_AXIS_DEG && u < 30.0, "{u}");
    }

    /// Knees flexing in a subject whose legs stood turned out by 15° in a pose declared with them
    /// straight: each leg's `calibrate` mounts turn about the leg by its knee's axis (left +15°,
    /// right −15°), so every segment's world rotation is the true one through the flexion (within
    /// 0.01°); with the heading alone (no hinge's own axis) the legs are 15° off.
    #[test]
    fn legs_turned_out_in_the_pose_turn_their_mounts() {
        let turn = rot(Vector3::y(), 70.0);
        let out = [rot(Vector3::y(), 15.0), rot(Vector3::y(), -15.0)];
        let mounts = [
            rot(Vector3::new(1.0, 2.0, 3.0), 70.0),
            rot(Vector3::new(-2.0, 1.0, 0.5), 120.0),
            rot(Vector3::new(0.3, -1.0, 2.0), 40.0),
            rot(Vector3::new(1.0, 1.0, -1.0), 160.0),
        ];
        // Sensor 2·leg is the thigh, 2·leg + 1 the shank: their bones at time t (facing +Z).
        let bone = |i: usize, t: f64| {
            let hip = rot(Vector3::x(), -25.0 * (3.0 * t).sin());
            let knee = rot(Vector3::x(), 30.0 * (1.0 - (3.0 * t).cos()));
            out[i / 2] * if i.is_multiple_of(2) { hip } else { hip * knee }
        };
        let reading = |i: usize, t: f64| turn * bone(i, t) * mounts[i];
        let held: Vec<_> = (0..4).map(|i| reading(i, 0.0)).collect();
        let pair = |leg: usize| HingePair {
            side: if leg == 0 { Side::Left } else { Side::Right },
            flexes_about_left: 1.0,
            inner: 2 * leg,
            outer: 2 * leg + 1,
            inner_down: -Vector3::y(),
            outer_down: -Vector3::y(),
        };
        let hinges: Vec<HingeSamples> = (0..2)
            .map(|leg| HingeSamples {
                pair: pair(leg),
                samples: (1..300)
                    .map(|k| {
                        let t = k as f64 * 0.01;
                        let since = |i: usize| reading(i, t) * held[i].inverse();
                        (t, since(2 * leg), since(2 * leg + 1))
                    })
                    .collect(),
            })
            .collect();
        let look = heading_from_hinges(&hinges).unwrap();
        let sensors: Vec<ResolvedSensor> = (0..4).map(|_| sensor(Mount::Calibrate, None)).collect();
        let first = Held {
            held: held.clone(),
            pose_world: vec![UnitQuaternion::identity(); 4],
        };
        let worst_deg = |c: &Calibration| {
            (0..4)
                .flat_map(|i| (0..30).map(move |k| (i, k as f64 * 0.1)))
                .map(|(i, t)| {
                    c.bone_world(i, &reading(i, t))
                        .angle_to(&bone(i, t))
                        .to_degrees()
                })
                .fold(0.0, f64::max)
        };
        let c = solve(&sensors, &first, None, Some(look), HeadingPolicy::Estimate);
        assert!((c.heading * turn).angle().to_degrees() < 0.01, "{c:?}");
        for (i, want) in [15.0, 15.0, -15.0, -15.0].into_iter().enumerate() {
            let t = c.mount_turns[i].expect("turned");
            assert!((t.deg - want).abs() < 0.01, "{i}: {t:?}");
            assert!((t.uncertainty_deg - HINGE_AXIS_DEG).abs() < 1e-9, "{t:?}");
            assert_eq!(c.axes_uncertainty_deg[i], t.uncertainty_deg);
        }
        assert!(worst_deg(&c) < 0.01, "{}", worst_deg(&c));
        let heading_only = HingeLook::heading_only(look.heading, look.uncertainty_deg);
        let c = solve(
            &sensors,
            &first,
            None,
            Some(heading_only),
            HeadingPolicy::Estimate,
        );
        assert!(c.mount_turns.iter().all(Option::is_none));
        assert!(worst_deg(&c) > 14.9, "{}", worst_deg(&c));
        // A pose far from the one declared (the knee's axis 60° off): warned, not turned.
        let mut far = look;
        far.axes[0].as_mut().unwrap().left = rot(Vector3::y(), 60.0) * look.axes[0].unwrap().left;
        let c = solve(&sensors, &first, None, Some(far), HeadingPolicy::Estimate);
        assert!(c.mount_turns[0].is_none() && c.mount_turns[2].is_some());
        assert!(
            c.warnings
                .iter()
                .any(|w| w.contains("was the pose held the one declared"))
        );
    }

    /// The mixamo rig, `calibrate` sensors on its thighs and shanks (left, then right; each with
    /// a heading of its own or not), and a window holding its rest pose (legs down) for 1 s.
    fn mixamo_legs(own_heading: bool) -> (Rig, Vec<ResolvedSensor>, CalibrationWindow) {
        let rig = crate::rig::load_rig("mixamo").unwrap();
        let sensors = ["LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg"]
            .iter()
            .map(|b| ResolvedSensor {
                sensor: b.to_string(),
                bone: rig.joint_index(b).unwrap(),
                mount: Mount::Calibrate,
                forward: None,
                own_heading,
            })
            .collect();
        let window = CalibrationWindow {
            pose: PoseRef::Rest,
            start_s: 0.0,
            duration_s: 1.0,
            second: None,
        };
        (rig, sensors, window)
    }

    /// Four leg sensors without a heading of their own, each in a world turned by its own yaw,
    /// on the mixamo rig held in its rest pose (legs down): the knees' flexion aligns each one
    /// (`hinge`), and every segment's world rotation is the true one through a walk that turns.
    #[test]
    fn six_d_legs_are_aligned_by_their_knees() {
        let (rig, sensors, window) = mixamo_legs(true);
        let mounts = [
            rot(Vector3::new(1.0, 2.0, 3.0), 70.0),
            rot(Vector3::new(-2.0, 1.0, 0.5), 120.0),
            rot(Vector3::new(0.3, -1.0, 2.0), 40.0),
            rot(Vector3::new(1.0, 1.0, -1.0), 160.0),
        ];
        let worlds = [10.0, -100.0, 170.0, 45.0].map(|deg| rot(Vector3::y(), deg));
        let pose_world = rig.world_rotations(&held_pose(&rig, Some(&window)));
        // The subject faces +Z; from 1.5 s it walks, turning 15°/s.
        let bone = |i: usize, t: f64| {
            let m = (t - 1.5).max(0.0);
            let phase = if i < 2 { 0.0 } else { std::f64::consts::PI };
            let body = rot(Vector3::y(), 15.0 * m);
            let hip = rot(Vector3::x(), -25.0 * (3.0 * m + phase).sin());
            let knee = rot(Vector3::x(), 30.0 * (1.0 - (3.0 * m).cos()));
            let local = if i.is_multiple_of(2) { hip } else { hip * knee };
            body * local * pose_world[sensors[i].bone]
        };
        let reading = |i: usize, t: f64| worlds[i] * bone(i, t) * mounts[i];
        let times: Vec<f64> = (0..1500).map(|k| k as f64 * 0.01).collect();
        let tracks: Vec<Track<UnitQuaternion<f64>>> = (0..4)
            .map(|i| {
                Track::new(
                    times.clone(),
                    times.iter().map(|t| reading(i, *t)).collect(),
                )
                .unwrap()
            })
            .collect();
        let mut warnings = Vec::new();
        let first = Held {
            held: held_poses(&sensors, &tracks, 0.0, 1.0, &mut warnings),
            pose_world: sensors.iter().map(|s| pose_world[s.bone]).collect(),
        };
        let pose_local = held_pose(&rig, Some(&window));
        let six_d: Vec<SixDHinge> =
            hinges_after(&rig, &pose_local, &sensors, &tracks, &window, false)
                .into_iter()
                .filter_map(|(pair, samples)| {
                    six_d_hinge(pair, &samples.into_iter().collect(), &first.held)
                })
                .collect();
        assert_eq!(six_d.len(), 2, "{six_d:?}");
        let c = solve_aligning(&sensors, &first, None, None, &six_d, HeadingPolicy::Sensors);
        assert!(c.alignment.iter().all(|a| *a == Alignment::Hinge), "{c:?}");
        for i in 0..4 {
            for t in [2.0, 5.0, 9.0, 14.0] {
                let off = c
                    .bone_world(i, &reading(i, t))
                    .angle_to(&bone(i, t))
                    .to_degrees();
                assert!(off < 0.01, "{i} at {t}: {off}°");
            }
        }
    }

    /// Every source's look is weighed by its uncertainty; one that disagrees by more than three
    /// of its own uncertainties is left out and warned about; should all disagree, the surest
    /// decides; angles wrap.
    #[test]
    fn heading_looks_combine_by_their_uncertainty() {
        let look = |source: HeadingSource, deg: f64, u: f64| HeadingLook {
            source,
            heading_deg: deg,
            uncertainty_deg: u,
            agrees: true,
        };
        let declared = |deg| {
            look(
                HeadingSource::DeclaredForward {
                    sensor: "pelvis".into(),
                },
                deg,
                FORWARD_AXIS_DEG,
            )
        };
        let deg = |h: &UnitQuaternion<f64>| h.scaled_axis().y.to_degrees();
        let mut warnings = Vec::new();
        // 30° ± 5° and 32° ± 3°: (30/25 + 32/9) / (1/25 + 1/9), ± (1/25 + 1/9)^−½.
        let mut looks = vec![declared(30.0), look(HeadingSource::Hinges, 32.0, 3.0)];
        let (h, source, u) = combine_looks(&mut looks, &mut warnings).unwrap();
        let w = (1.0 / 25.0, 1.0 / 9.0);
        let expected = (30.0 * w.0 + 32.0 * w.1) / (w.0 + w.1);
        assert!((deg(&h) - expected).abs() < 1e-3, "{}", deg(&h));
        assert!((u - (w.0 + w.1).powf(-0.5)).abs() < 1e-12);
        assert_eq!(source.label(), "declared-forward");
        assert!(looks.iter().all(|l| l.agrees) && warnings.is_empty());
        // A forward axis 50° off the two others: left out, and said.
        let mut looks = vec![
            look(HeadingSource::SecondPose, 30.0, 3.0),
            look(HeadingSource::Hinges, 31.0, 3.0),
            declared(80.0),
        ];
        let (h, _, _) = combine_looks(&mut looks, &mut warnings).unwrap();
        assert!((deg(&h) - 30.5).abs() < 1e-3, "{}", deg(&h));
        assert_eq!(
            looks.iter().map(|l| l.agrees).collect::<Vec<_>>(),
            [true, true, false]
        );
        assert_eq!(warnings.len(), 1);
        assert!(
            warnings[0].contains("declared-forward (sensor `pelvis`)"),
            "{warnings:?}"
        );
        // Two sure looks a quarter turn apart: the first of the surest decides.
        let mut looks = vec![
            look(HeadingSource::SecondPose, 0.0, 1.0),
            look(HeadingSource::Hinges, 90.0, 1.0),
        ];
        let (h, source, _) = combine_looks(&mut looks, &mut Vec::new()).unwrap();
        assert!(deg(&h).abs() < 1e-9 && source == HeadingSource::SecondPose);
        // Across ±180°.
        let mut looks = vec![declared(179.0), declared(-179.0)];
        let (h, _, _) = combine_looks(&mut looks, &mut Vec::new()).unwrap();
        assert!((deg(&h).abs() - 180.0).abs() < 1e-6, "{}", deg(&h));
        assert!(combine_looks(&mut [], &mut Vec::new()).is_none());
    }

    /// The knee's axis is read as it stood at calibration: a subject who turns 120° on the spot
    /// while bending the knees (a squat with a turn) still faces +Z at calibration. (Read in the
    /// world of the moment, Δ_shank ⊗ Δ_thigh⁻¹, the axis would turn with the body: about 60° off.)
    #[test]
    fn the_knees_axis_is_read_where_it_stood_at_calibration() {
        let leg: Vec<_> = (0..200)
            .map(|i| {
                let t = i as f64 * 0.02;
                let body = rot(Vector3::y(), 30.0 * t);
                let flex = rot(Vector3::x(), 40.0 + 30.0 * (t * 3.0).sin());
                (t, body, body * flex)
            })
            .collect();
        let knees = [
            hinge(Side::Left, 1.0, leg.clone()),
            hinge(Side::Right, 1.0, leg),
        ];
        let (h, _) = hinges_heading(&knees).unwrap();
        assert!(h.angle().to_degrees() < 1e-6, "{}", h.angle().to_degrees());
    }

    /// Elbows flex about the subject's right: two give the heading as knees do; one alone is
    /// never sure enough (a relaxed arm hangs turned in). Still stretches before a hinge bends
    /// are passed over.
    #[test]
    fn elbows_give_the_heading_and_one_elbow_is_not_sure() {
        // Facing −X (rig world): right is forward × up = −Z, so the forearm turns about −Z as
        // it comes up in front.
        let arm: Vec<_> = (0..300)
            .map(|i| {
                let t = i as f64 * 0.02;
                // Still for 3 s, then waving.
                let angle = if t < 3.0 {
                    0.0
                } else {
                    60.0 + 40.0 * (t * 4.0).sin()
                };
                (t, UnitQuaternion::identity(), rot(-Vector3::z(), angle))
            })
            .collect();
        let elbows = [
            hinge(Side::Left, -1.0, arm.clone()),
            hinge(Side::Right, -1.0, arm.clone()),
        ];
        let (h, u) = hinges_heading(&elbows).unwrap();
        assert!((h * -Vector3::x() - Vector3::z()).norm() < 1e-9);
        assert!((u - KNEE_AXIS_DEG).abs() < 1e-9, "{u}");
        let (_, u) = hinges_heading(&elbows[..1]).unwrap();
        assert!((u - ONE_ARM_DEG).abs() < 1e-9, "{u}");
        assert!(u > MAX_HEADING_UNCERTAINTY_DEG);
        // A twitch shorter than MIN_FLEXED_S gives nothing.
        let twitch: Vec<_> = arm
            .iter()
            .map(|&(t, a, _)| {
                let bent = (1.0..1.3).contains(&t);
                (t, a, if bent { rot(-Vector3::z(), 60.0) } else { a })
            })
            .collect();
        assert!(hinges_heading(&[hinge(Side::Left, -1.0, twitch)]).is_none());
    }

    #[test]
    fn a_second_pose_gives_the_heading_of_sensors_with_north() {
        // The subject faces +X (rig world, before heading): H must turn +X to +Z. Two sensors
        // with unknown mounts on bones that turn 60° about the subject's left (−Z here, +X once
        // faced to +Z) from the first pose to the second.
        let h_true = rot(Vector3::y(), -90.0);
        let mounts = [
            rot(Vector3::new(1.0, 2.0, 3.0), 70.0),
            rot(Vector3::new(-2.0, 1.0, 0.5), 130.0),
        ];
        let pose1 = [rot(Vector3::y(), 0.0), rot(Vector3::x(), 10.0)];
        let pose2: Vec<_> = pose1.iter().map(|p| rot(Vector3::x(), 60.0) * p).collect();
        // What the sensors read (rig world before heading): H⁻¹ ⊗ P ⊗ m.
        let read = |p: &UnitQuaternion<f64>, m: &UnitQuaternion<f64>| h_true.inverse() * p * m;
        let first = Held {
            held: pose1.iter().zip(&mounts).map(|(p, m)| read(p, m)).collect(),
            pose_world: pose1.to_vec(),
        };
        let second = Held {
            held: pose2.iter().zip(&mounts).map(|(p, m)| read(p, m)).collect(),
            pose_world: pose2.clone(),
        };
        let sensors = vec![
            sensor(Mount::Calibrate, None),
            sensor(Mount::Calibrate, None),
        ];
        let cal = solve(
            &sensors,
            &first,
            Some(&second),
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.heading_source, HeadingSource::SecondPose);
        assert!(cal.heading.angle_to(&h_true) < 1e-9);
        // Both turns about a horizontal axis: the known-mount accuracy, agreeing exactly.
        assert!((cal.heading_uncertainty_deg - KNOWN_MOUNT_DEG).abs() < 1e-6);
        for (i, m) in mounts.iter().enumerate() {
            assert!(cal.mounts[i].angle_to(m) < 1e-9);
        }
        assert!(
            cal.check_heading(&sensors, HeadingPolicy::Estimate, "m.json")
                .is_ok()
        );
    }

    #[test]
    fn an_unknown_heading_is_refused_unless_the_sensors_north_is_kept() {
        let held = rot(Vector3::new(0.3, 1.0, 0.2), 50.0);
        let sensors = vec![sensor(Mount::Calibrate, None)];
        let cal = solve(
            &sensors,
            &self::held(held, UnitQuaternion::identity()),
            None,
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.heading_source, HeadingSource::None);
        assert!(cal.heading_uncertainty_deg.is_infinite());
        let e = cal
            .check_heading(&sensors, HeadingPolicy::Estimate, "m.json")
            .unwrap_err()
            .to_string();
        for way_out in [
            "`forward`",
            "calibration.second",
            "\"heading\": \"sensors\"",
            "--heading sensors",
        ] {
            assert!(e.contains(way_out), "{e}");
        }
        assert!(
            cal.check_heading(&sensors, HeadingPolicy::Sensors, "m.json")
                .is_ok()
        );
        // A declared forward axis tilted 59° from the horizontal: 5° / cos 59° = 9.7°, kept.
        let tilted = Vector3::new(0.0, 59f64.to_radians().sin(), 59f64.to_radians().cos());
        let s = vec![sensor(Mount::Calibrate, Some(tilted))];
        let cal = solve(
            &s,
            &self::held(UnitQuaternion::identity(), UnitQuaternion::identity()),
            None,
            None,
            HeadingPolicy::Estimate,
        );
        assert!((cal.heading_uncertainty_deg - 5.0 / 59f64.to_radians().cos()).abs() < 1e-9);
        assert!(
            cal.check_heading(&s, HeadingPolicy::Estimate, "m.json")
                .is_ok()
        );
        let steeper = Vector3::new(0.0, 62f64.to_radians().sin(), 62f64.to_radians().cos());
        let s = vec![sensor(Mount::Calibrate, Some(steeper))];
        let cal = solve(
            &s,
            &self::held(UnitQuaternion::identity(), UnitQuaternion::identity()),
            None,
            None,
            HeadingPolicy::Estimate,
        );
        assert!(
            cal.check_heading(&s, HeadingPolicy::Estimate, "m.json")
                .is_err()
        );
    }

    #[test]
    fn mean_of_sign_flipped_samples() {
        let a = rot(Vector3::x(), 10.0);
        let b = UnitQuaternion::new_unchecked(-rot(Vector3::x(), 20.0).into_inner());
        let m = mean_rotation(&[a, b]);
        assert!((m.angle().to_degrees() - 15.0).abs() < 1e-9);
    }

    /// A sensor without a heading of its own reads `q = Z⁻¹ ⊗ B ⊗ m` (rig world): its world is
    /// turned by an unknown `Z` about +Y. Whatever aligns it must give back the bone's true
    /// orientation `B` at another instant, where the bone turned about a horizontal axis.
    fn check_aligned(cal: &Calibration, z: UnitQuaternion<f64>, m: UnitQuaternion<f64>) {
        let later = rot(Vector3::new(1.0, 0.2, 0.3), 50.0) * rot(Vector3::z(), -20.0);
        let reads = z.inverse() * later * m;
        let bone = cal.bone_world(0, &reads);
        assert!(
            bone.angle_to(&later).to_degrees() < 1e-9,
            "{:.3}°",
            bone.angle_to(&later).to_degrees()
        );
    }

    #[test]
    fn sensors_without_heading_are_aligned_by_mount_forward_axis_or_second_pose() {
        let z = rot(Vector3::y(), 73.0);
        let m = rot(Vector3::new(0.3, -1.0, 0.5), 117.0);
        let pose1 = rot(Vector3::z(), 90.0);
        let pose2 = rot(Vector3::x(), -60.0) * pose1;
        let held1 = z.inverse() * pose1 * m;
        let held2 = z.inverse() * pose2 * m;
        let own = |mount: Mount, forward: Option<Vector3<f64>>| ResolvedSensor {
            own_heading: true,
            ..sensor(mount, forward)
        };
        // A known mount.
        let cal = solve(
            &[own(Mount::Fixed(m), None)],
            &held(held1, pose1),
            None,
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.alignment, vec![Alignment::Mount]);
        assert_eq!(cal.heading_source, HeadingSource::Aligned);
        check_aligned(&cal, z, m);
        // A forward axis: the sensor axis that the pose's +Z (the facing) is, m⁻¹ ⊗ P⁻¹ ⊗ +Z.
        let forward = m.inverse() * (pose1.inverse() * Vector3::z());
        let cal = solve(
            &[own(Mount::Calibrate, Some(forward))],
            &held(held1, pose1),
            None,
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.alignment, vec![Alignment::Forward]);
        check_aligned(&cal, z, m);
        // A second pose, the mount unknown.
        let second = held(held2, pose2);
        let cal = solve(
            &[own(Mount::Calibrate, None)],
            &held(held1, pose1),
            Some(&second),
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.alignment, vec![Alignment::SecondPose]);
        assert!(cal.warnings.is_empty(), "{:?}", cal.warnings);
        check_aligned(&cal, z, m);
        // Neither: a warning naming the sensor, and the bone's axes are off by Z.
        let cal = solve(
            &[own(Mount::Calibrate, None)],
            &held(held1, pose1),
            None,
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.alignment, vec![Alignment::None]);
        assert!(
            cal.warnings
                .iter()
                .any(|w| w.contains("`s`") || w.contains(" s have")),
            "{:?}",
            cal.warnings
        );
        // A second pose that turns the bone about the vertical cannot align it.
        let about_up = held(
            z.inverse() * rot(Vector3::y(), 40.0) * pose1 * m,
            rot(Vector3::y(), 40.0) * pose1,
        );
        let cal = solve(
            &[own(Mount::Calibrate, None)],
            &held(held1, pose1),
            Some(&about_up),
            None,
            HeadingPolicy::Estimate,
        );
        assert_eq!(cal.alignment, vec![Alignment::None]);
        assert!(
            cal.warnings
                .iter()
                .any(|w| w.contains("too close to vertical")),
            "{:?}",
            cal.warnings
        );
    }

    #[test]
    fn twist_about_y_keeps_the_turn_about_the_vertical() {
        let q = rot(Vector3::y(), 35.0) * rot(Vector3::x(), 20.0);
        let t = twist_about_y(&q);
        assert!((t.scaled_axis() - Vector3::y() * 35f64.to_radians()).norm() < 0.05);
        let pure = rot(Vector3::y(), -120.0);
        assert!(twist_about_y(&pure).angle_to(&pure) < 1e-12);
    }

    /// A stream's core on the mixamo rig, four sensors on the thighs and shanks, the rest pose held
    /// for the first second; then both knees flex (0–60°, a stride a second, half a stride apart)
    /// about the subject's left axis, which in the sensors' world points 35° about +Y from +X.
    /// Streamed at 100 Hz through `push`/`try_solve`, then `refine`: the heading turns that axis
    /// back onto +X (within 0.5°), sure by the 3° floor, from a stream time in the seconds after
    /// the window. With the right thigh silent from 1.05 s its stale sample is not read as a still
    /// thigh: only the left knee gives an axis, so one leg's bound (8°) holds.
    #[test]
    fn a_stream_refines_the_heading_as_the_knees_flex() {
        let (rig, sensors, window) = mixamo_legs(false);
        let left = rot(Vector3::y(), 35.0) * Vector3::x();
        let run = |right_thigh_until_s: f64| {
            let mut core =
                CalibrationCore::new(&rig, sensors.clone(), Some(window.clone()), "m.json")
                    .unwrap();
            let mut warnings = Vec::new();
            let mut refined = Vec::new();
            for k in 0..400 {
                let t = k as f64 / 100.0;
                for i in 0..4 {
                    if i == 2 && t > right_thigh_until_s {
                        continue;
                    }
                    let phase = if i < 2 { 0.0 } else { 0.5 };
                    let moving = (t - 1.0 - phase).max(0.0);
                    let flexion = 30.0 * (1.0 - (std::f64::consts::TAU * moving).cos());
                    let q = if i % 2 == 1 && t > 1.0 {
                        rot(left, flexion)
                    } else {
                        UnitQuaternion::identity()
                    };
                    if core.result().is_none() {
                        core.push(i, t, q);
                        core.try_solve(|_| false, &mut warnings);
                    } else if let Some(r) = core.refine(i, t, q) {
                        refined.push(r);
                    }
                }
            }
            (core.result().unwrap().clone(), refined)
        };
        let (c, refined) = run(f64::INFINITY);
        assert!(!refined.is_empty());
        let from_s = c.heading_from_s.unwrap();
        assert!(from_s > 1.0 && from_s < 4.0, "{from_s}");
        assert_eq!(c.heading_source, HeadingSource::Hinges);
        let turned = c.heading * left;
        assert!(turned.angle(&Vector3::x()).to_degrees() < 0.5, "{turned}");
        assert!(c.heading_uncertainty_deg <= 3.0 + 1e-9, "{c:?}");
        let (stale, _) = run(1.05);
        assert!(stale.heading_uncertainty_deg >= ONE_LEG_DEG, "{stale:?}");
    }
}
