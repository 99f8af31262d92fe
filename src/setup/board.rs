//! What `imubake setup` knows of a suit, fed sample by sample: each sensor's latest readings and
//! their norms, its rate and gaps, how fast it turns (the one turning fastest "lights up"), which
//! bone it sits on, and the calibrations taken from the stream: the gyro bias (hold still), the
//! held pose and the bow that gives the heading source. Pure: no clock but the samples' own
//! (stream time, seconds), no threads; [`super::Setup`] shares it with the page.
//!
//! Units: gyro rad/s in, °/s shown; specific force m/s²; the field in the log's unit (µT by the
//! conventions); quaternions `[w, x, y, z]`, `q_enu_sensor` (a source's own world is turned to
//! ENU before the board: [`super::Setup::sample`]).

use crate::fusion::stream::StreamFuser;
use crate::intrinsics::gyro_bias::{BiasWindow, GyroBias, gyro_bias};
use crate::intrinsics::magnetometer::{MagCalibration, MagFit, calibrate_magnetometer, coverage};
use crate::take::{ImuSample, StreamValue, Track};
use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};

/// A sensor turning faster than this, °/s (its turn rate low-passed over [`ACTIVITY_TAU_S`]),
/// is moving; the fastest of those is lit.
pub const LIT_DPS: f64 = 30.0;
/// The turn rate's low-pass time constant, seconds: short enough to light within 0.2 s of a
/// wave, long enough that one noisy sample does not.
pub const ACTIVITY_TAU_S: f64 = 0.1;
/// A specific force whose norm is off g by more than this fraction: the sensor accelerates.
pub const ACC_DISTURBED: f64 = 0.1;
/// A field whose norm is off its usual value by more than this fraction: disturbed (the usual
/// value: the magnetometer fit's field when the sensor has one, else the norm's slow mean).
pub const MAG_DISTURBED: f64 = 0.1;
/// A gap: a step between samples longer than this many times the sensor's usual one.
pub const GAP_FACTOR: f64 = 3.0;
/// Sensors a board keeps (a stream naming more is refused past it: bounded memory).
pub const MAX_SENSORS: usize = 256;
/// Samples a capture keeps per sensor (60 s at 500 Hz), and of all sensors together: bounded
/// memory whatever the stream does (about 50 MB at most).
pub const MAX_CAPTURE_SAMPLES: usize = 30_000;
pub const MAX_CAPTURE_TOTAL: usize = 600_000;
/// Readings the live coverage of a magnetometer capture looks at per sensor (spread evenly).
const COVERAGE_SAMPLES: usize = 400;
/// Standard gravity, m/s².
const G: f64 = 9.80665;

/// One sensor's live state.
struct Sensor {
    id: String,
    last_s: f64,
    samples: u64,
    /// The usual step between samples (low-passed), seconds.
    step_s: Option<f64>,
    gaps: u64,
    gyr: Option<Vector3<f64>>,
    acc: Option<Vector3<f64>>,
    mag: Option<Vector3<f64>>,
    q: Option<UnitQuaternion<f64>>,
    /// The turn rate, low-passed, rad/s.
    activity: f64,
    /// The field's norm, low-passed slowly (its usual value).
    mag_norm: Option<f64>,
    /// Raw readings fused as they come (online VQF, [`StreamFuser`]): the "filtered" view.
    fuser: Option<StreamFuser>,
    /// The fused orientation, `q_enu_sensor`.
    fused: Option<UnitQuaternion<f64>>,
    /// Why the readings cannot be fused (units), once.
    fusion_error: Option<String>,
}

impl Sensor {
    fn new(id: &str, t_s: f64) -> Sensor {
        Sensor {
            id: id.to_string(),
            last_s: t_s,
            samples: 0,
            step_s: None,
            gaps: 0,
            gyr: None,
            acc: None,
            mag: None,
            q: None,
            activity: 0.0,
            mag_norm: None,
            fuser: None,
            fused: None,
            fusion_error: None,
        }
    }

    fn push(&mut self, t_s: f64, value: StreamValue) {
        let dt = t_s - self.last_s;
        let mut rate = None;
        if self.samples > 0 && dt > 0.0 {
            match self.step_s {
                Some(step) if dt > GAP_FACTOR * step => self.gaps += 1,
                Some(step) => self.step_s = Some(step + 0.05 * (dt - step)),
                None => self.step_s = Some(dt),
            }
        }
        match value {
            StreamValue::Raw { imu, mag } => {
                rate = Some(imu.gyro_rad_s.norm());
                self.gyr = Some(imu.gyro_rad_s);
                self.acc = Some(imu.accel_m_s2);
                if let Some(n) = mag.map(|m| m.norm()).filter(|n| n.is_finite()) {
                    self.mag_norm = Some(self.mag_norm.map_or(n, |u| u + 0.01 * (n - u)));
                }
                self.mag = mag;
                self.fuse(t_s, imu, mag);
            }
            value => {
                if let Some(q) = value.orientation() {
                    if let Some(prev) = self.q
                        && dt > 0.0
                    {
                        rate = Some(prev.angle_to(&q) / dt);
                    }
                    self.q = Some(q);
                }
            }
        }
        // A reading that is not a number (the stream's cleaning drops them; a board does not
        // count on it) leaves the low-passed values as they were.
        if let Some(rate) = rate.filter(|r| r.is_finite()) {
            let step = if self.samples == 0 || dt <= 0.0 {
                1.0
            } else {
                (dt / ACTIVITY_TAU_S).min(1.0)
            };
            self.activity += step * (rate - self.activity);
        }
        self.samples += 1;
        self.last_s = self.last_s.max(t_s);
    }

    /// The reading through the sensor's online filter (readings whose time does not rise are
    /// left out of it).
    fn fuse(&mut self, t_s: f64, imu: ImuSample, mag: Option<Vector3<f64>>) {
        let finite = |v: &Vector3<f64>| v.iter().all(|x| x.is_finite());
        if self.fusion_error.is_some()
            || (self.samples > 0 && t_s <= self.last_s)
            || !finite(&imu.gyro_rad_s)
            || !finite(&imu.accel_m_s2)
            || mag.as_ref().is_some_and(|m| !finite(m))
        {
            return;
        }
        let fuser = self
            .fuser
            .get_or_insert_with(|| StreamFuser::new(&self.id, &crate::fusion::Fusion::default()));
        let mut out = Vec::new();
        match fuser.push(t_s, imu, mag, &mut out) {
            Ok(()) => {
                if let Some((_, q)) = out.last() {
                    self.fused = Some(*q);
                }
            }
            Err(e) => {
                self.fusion_error = Some(e.to_string());
                self.fuser = None;
            }
        }
    }
}

/// What a capture is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CaptureKind {
    /// Hold every sensor still: each one's gyro bias.
    GyroBias,
    /// Hold the calibration pose: every sensor still, each one's gravity.
    Pose,
    /// Then hold a second pose (the mapping's `calibration.second`): the turn of each bone
    /// between the two gives the heading of sensors without a magnetometer.
    SecondPose,
    /// From the pose, bow forward and come back: the pelvis sensor's forward axis.
    Bow,
    /// Turn every sensor through all directions: each magnetometer's hard and soft iron.
    Magnetometer,
}

/// A capture under way: from `start_s` (stream time) for `seconds`, each sensor's raw samples.
#[derive(Debug, Clone)]
struct Capture {
    kind: CaptureKind,
    start_s: f64,
    seconds: f64,
    samples: HashMap<usize, CaptureSamples>,
    /// Samples kept, of all sensors.
    total: usize,
}

/// One sensor's readings in a capture.
#[derive(Debug, Clone, Default)]
struct CaptureSamples {
    /// The raw readings' times and readings (a sensor that sends raw readings).
    times: Vec<f64>,
    imu: Vec<ImuSample>,
    mag: Vec<Vector3<f64>>,
    /// Each sample's up in the sensor frame: the specific force's direction, or `q⁻¹·z` from an
    /// orientation.
    up: Vec<Vector3<f64>>,
    /// From orientations: the first, and the largest angle from it (how much the sensor moved).
    first_q: Option<UnitQuaternion<f64>>,
    turned: f64,
    last_s: Option<f64>,
}

/// One sensor's result of a gyro-bias capture.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BiasResult {
    pub sensor: String,
    /// `Err`: why this sensor has none (it moved, too few samples).
    pub bias: Result<GyroBias, String>,
}

/// One sensor's result of a magnetometer capture.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MagResult {
    pub sensor: String,
    /// `Err`: why this sensor has none (not turned enough, too little coverage).
    pub fit: Result<MagCalibration, String>,
}

/// The pose capture's result: each sensor's up in its own frame (the mean direction of its
/// specific force, or of `q⁻¹·z` from its orientations).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PoseResult {
    pub start_s: f64,
    pub seconds: f64,
    /// Sensors that moved during the hold (raw: a gyro spread above 2 °/s SD; orientations: more
    /// than 2° from the first), by id.
    pub moved: Vec<String>,
    #[serde(skip)]
    up: HashMap<String, Vector3<f64>>,
}

/// The bow's result: the forward axis found for the sensor on the pelvis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BowResult {
    pub sensor: String,
    /// The sensor axis nearest the body's forward (`+x` … `-z`), as the mapping's `forward`.
    pub forward: String,
    /// The angle between that axis and the forward found, degrees.
    pub off_axis_deg: f64,
    /// How deep the bow was, degrees.
    pub bow_deg: f64,
}

/// A command from the page.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum Command {
    /// Put `sensor` on `bone` (a bone driven by another sensor is given to this one).
    Assign {
        sensor: String,
        bone: String,
    },
    Unassign {
        sensor: String,
    },
    /// Start a capture of `seconds` after `countdown_s`.
    Capture {
        kind: CaptureKind,
        seconds: f64,
        #[serde(default)]
        countdown_s: f64,
    },
    /// The subject's height, metres.
    Height {
        m: f64,
    },
    /// A segment's length, metres, by body part (`left_thigh`, `right_forearm`: the subject
    /// file's keys); `null` forgets it.
    Segment {
        part: String,
        m: Option<f64>,
    },
    /// The rig pose held during calibration (`rest` or one of the rig's named poses).
    Pose {
        name: String,
    },
    /// The rig pose held second (`null`: none).
    SecondPose {
        name: Option<String>,
    },
    /// Write the files.
    Save,
}

/// A joint of the character the page draws: its name, parent and place in the rig's rest pose
/// (metres, rig world Y up).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FigureJoint {
    pub name: String,
    pub parent: Option<usize>,
    pub position_m: [f64; 3],
    /// Where the bone ends when the joint has no child (its End Site), metres.
    pub end_m: Option<[f64; 3]>,
}

impl FigureJoint {
    /// The rig's joints at rest.
    pub fn of(rig: &crate::rig::Rig) -> Vec<FigureJoint> {
        let unit = rig.units().metres_per_unit();
        let at = rig.rest_positions();
        rig.joints()
            .iter()
            .zip(&at)
            .map(|(j, p)| FigureJoint {
                name: j.name.clone(),
                parent: j.parent,
                position_m: (p * unit).into(),
                end_m: j.end_site.map(|e| ((p + e) * unit).into()),
            })
            .collect()
    }
}

/// The board: every sensor, the assignments, the calibrations.
pub struct Board {
    figure: Vec<FigureJoint>,
    bones: Vec<String>,
    poses: Vec<String>,
    sensors: Vec<Sensor>,
    index: HashMap<String, usize>,
    /// Sensor id → bone.
    assigned: BTreeMap<String, String>,
    now_s: f64,
    capture: Option<Capture>,
    bias: Vec<BiasResult>,
    mag: Vec<MagResult>,
    pose: Option<PoseResult>,
    second: Option<PoseResult>,
    bow: Option<Result<BowResult, String>>,
    pose_name: String,
    second_name: Option<String>,
    /// The pelvis sensor's fused heading when the pose was held, radians (the follow camera's
    /// reference).
    pelvis_heading_at_pose: Option<f64>,
    height_m: Option<f64>,
    /// Body part → length, metres.
    segments: BTreeMap<String, f64>,
    /// Sensors past [`MAX_SENSORS`], refused.
    refused: u64,
    /// The last command's error or news, for the page.
    pub message: Option<String>,
}

impl std::fmt::Debug for Board {
    // The sensors' filters are not Debug; what a board holds, in short.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Board")
            .field("sensors", &self.sensors.len())
            .field("assigned", &self.assigned)
            .field("now_s", &self.now_s)
            .finish_non_exhaustive()
    }
}

/// Bow deeper than this, degrees, for the forward to count.
pub const MIN_BOW_DEG: f64 = 15.0;

impl Board {
    /// A board for `rig`: its joints drawn at rest, its named poses (a BVH rig's frames,
    /// `frame:N`, left out of the page's list).
    pub fn of_rig(rig: &crate::rig::Rig) -> Board {
        let poses = rig
            .pose_names()
            .into_iter()
            .filter(|p| !p.starts_with("frame:"))
            .collect();
        Board::new(FigureJoint::of(rig), poses)
    }

    /// A board for a rig drawn as `figure` (its joints, whose names are the bones) with the
    /// named poses `poses`.
    pub fn new(figure: Vec<FigureJoint>, poses: Vec<String>) -> Board {
        Board {
            bones: figure.iter().map(|j| j.name.clone()).collect(),
            figure,
            poses,
            sensors: Vec::new(),
            index: HashMap::new(),
            assigned: BTreeMap::new(),
            now_s: f64::NEG_INFINITY,
            capture: None,
            bias: Vec::new(),
            mag: Vec::new(),
            pose: None,
            second: None,
            bow: None,
            pose_name: "rest".into(),
            second_name: None,
            pelvis_heading_at_pose: None,
            height_m: None,
            segments: BTreeMap::new(),
            refused: 0,
            message: None,
        }
    }

    /// One sample of sensor `id` at `t_s` (stream time).
    pub fn sample(&mut self, id: &str, t_s: f64, value: StreamValue) {
        if !t_s.is_finite() {
            return;
        }
        let k = match self.index.get(id) {
            Some(&k) => k,
            None if self.sensors.len() < MAX_SENSORS => {
                self.sensors.push(Sensor::new(id, t_s));
                self.index.insert(id.to_string(), self.sensors.len() - 1);
                self.sensors.len() - 1
            }
            None => {
                self.refused += 1;
                return;
            }
        };
        self.sensors[k].push(t_s, value);
        self.now_s = self.now_s.max(t_s);
        if let Some(c) = &mut self.capture
            && t_s >= c.start_s
            && t_s <= c.start_s + c.seconds
            && c.total < MAX_CAPTURE_TOTAL
        {
            let kept = c.samples.entry(k).or_default();
            if kept.up.len() < MAX_CAPTURE_SAMPLES && kept.last_s.is_none_or(|l| t_s > l) {
                kept.last_s = Some(t_s);
                match value {
                    StreamValue::Raw { imu, mag } => {
                        kept.times.push(t_s);
                        kept.imu.push(imu);
                        kept.up.extend(imu.accel_m_s2.try_normalize(1e-9));
                        if c.kind == CaptureKind::Magnetometer
                            && let Some(m) = mag
                        {
                            kept.mag.push(m);
                        }
                    }
                    value => {
                        if let Some(q) = value.orientation() {
                            kept.up.push(q.inverse() * Vector3::z());
                            let first = *kept.first_q.get_or_insert(q);
                            kept.turned = kept.turned.max(first.angle_to(&q));
                        }
                    }
                }
                c.total += 1;
            }
        }
        if self
            .capture
            .as_ref()
            .is_some_and(|c| self.now_s > c.start_s + c.seconds)
        {
            let c = self.capture.take().expect("a capture");
            self.finish(c);
        }
    }

    /// The sensor that is lit: the fastest turning above [`LIT_DPS`].
    pub fn lit(&self) -> Option<&str> {
        self.sensors
            .iter()
            .filter(|s| s.activity.to_degrees() > LIT_DPS)
            .max_by(|a, b| a.activity.total_cmp(&b.activity))
            .map(|s| s.id.as_str())
    }

    /// Carries out a command from the page.
    pub fn command(&mut self, command: Command) -> Result<(), String> {
        match command {
            Command::Assign { sensor, bone } => {
                if !self.index.contains_key(&sensor) {
                    return Err(format!("no sensor `{sensor}` in the stream"));
                }
                if !self.bones.contains(&bone) {
                    return Err(format!("the rig has no bone `{bone}`"));
                }
                self.assigned.retain(|_, b| *b != bone);
                self.assigned.insert(sensor, bone);
            }
            Command::Unassign { sensor } => {
                self.assigned.remove(&sensor);
            }
            Command::Capture {
                kind,
                seconds,
                countdown_s,
            } => {
                if !(seconds.is_finite() && (0.5..=60.0).contains(&seconds)) {
                    return Err("a capture lasts 0.5 to 60 s".into());
                }
                if !(countdown_s.is_finite() && (0.0..=30.0).contains(&countdown_s)) {
                    return Err("a countdown is 0 to 30 s".into());
                }
                if !self.now_s.is_finite() {
                    return Err("no samples yet".into());
                }
                if kind == CaptureKind::Bow && self.pose.is_none() {
                    return Err("hold the pose first: the bow is measured from it".into());
                }
                if kind == CaptureKind::SecondPose {
                    if self.pose.is_none() {
                        return Err("hold the first pose first".into());
                    }
                    if self.second_name.is_none() {
                        return Err("choose the second pose first".into());
                    }
                }
                self.capture = Some(Capture {
                    kind,
                    start_s: self.now_s + countdown_s,
                    seconds,
                    samples: HashMap::new(),
                    total: 0,
                });
            }
            Command::Segment { part, m } => {
                use crate::rig::anatomy::Part;
                if !Part::all().iter().any(|p| p.key() == part) {
                    return Err(format!(
                        "no body part `{part}`; expected one of {}",
                        Part::all()
                            .iter()
                            .map(|p| p.key())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ));
                }
                match m {
                    None => {
                        self.segments.remove(&part);
                    }
                    Some(m) if m.is_finite() && (0.02..=1.5).contains(&m) => {
                        self.segments.insert(part, m);
                    }
                    Some(m) => return Err(format!("a segment of {m} m? expected 0.02 to 1.5 m")),
                }
            }
            Command::Height { m } => {
                if !(m.is_finite() && (0.5..=2.6).contains(&m)) {
                    return Err(format!("a height of {m} m? expected 0.5 to 2.6 m"));
                }
                self.height_m = Some(m);
            }
            Command::Pose { name } => {
                self.check_pose(&name)?;
                if self.second_name.as_ref() == Some(&name) {
                    return Err(format!("`{name}` is already the second pose"));
                }
                self.pose_name = name;
            }
            Command::SecondPose { name } => {
                if let Some(name) = &name {
                    self.check_pose(name)?;
                    if *name == self.pose_name {
                        return Err(format!("`{name}` is already the first pose"));
                    }
                }
                self.second_name = name;
                self.second = None;
            }
            Command::Save => return Err("save is the session's, not the board's".into()),
        }
        Ok(())
    }

    fn check_pose(&self, name: &str) -> Result<(), String> {
        if name != "rest" && !self.poses.iter().any(|p| p == name) {
            return Err(format!(
                "the rig has no pose `{name}` (it has rest{})",
                self.poses
                    .iter()
                    .filter(|p| *p != "rest")
                    .map(|p| format!(", {p}"))
                    .collect::<String>()
            ));
        }
        Ok(())
    }

    /// The sensor on the rig's first bone (the pelvis).
    fn pelvis_sensor(&self) -> Option<&str> {
        let root = self.bones.first()?;
        self.assigned
            .iter()
            .find(|(_, b)| *b == root)
            .map(|(s, _)| s.as_str())
    }

    /// The fused heading of `sensor`'s x axis, radians from north toward east.
    fn heading(&self, sensor: &str) -> Option<f64> {
        self.sensors[*self.index.get(sensor)?].fused.map(heading_of)
    }

    fn finish(&mut self, c: Capture) {
        match c.kind {
            CaptureKind::GyroBias => {
                self.bias = self
                    .sensors
                    .iter()
                    .enumerate()
                    .filter(|(_, s)| s.gyr.is_some())
                    .map(|(k, s)| BiasResult {
                        sensor: s.id.clone(),
                        bias: match c.samples.get(&k) {
                            Some(kept) if !kept.times.is_empty() => {
                                Track::new(kept.times.clone(), kept.imu.clone())
                                    .map_err(|e| e.to_string())
                                    .and_then(|track| {
                                        gyro_bias(
                                            &s.id,
                                            &track,
                                            &BiasWindow::Given {
                                                start_s: c.start_s,
                                                end_s: c.start_s + c.seconds,
                                            },
                                        )
                                        .map_err(|e| e.to_string())
                                    })
                            }
                            _ => Err("no samples during the capture".into()),
                        },
                    })
                    .collect();
            }
            CaptureKind::Pose | CaptureKind::SecondPose => {
                let mut moved = Vec::new();
                let mut up = HashMap::new();
                for (k, s) in self.sensors.iter().enumerate() {
                    let Some(kept) = c.samples.get(&k) else {
                        continue;
                    };
                    // Moved: raw readings turning with a spread above 2 °/s; orientations
                    // turning more than 2° from the first.
                    let v = &kept.imu;
                    let moved_here = if v.is_empty() {
                        kept.turned.to_degrees() > 2.0
                    } else {
                        let n = v.len() as f64;
                        let mean = v.iter().map(|x| x.gyro_rad_s).sum::<Vector3<f64>>() / n;
                        let spread = v
                            .iter()
                            .map(|x| (x.gyro_rad_s - mean).norm_squared())
                            .sum::<f64>()
                            / n;
                        spread.sqrt().to_degrees() > 2.0
                    };
                    if moved_here {
                        moved.push(s.id.clone());
                    }
                    let mean_up = kept.up.iter().sum::<Vector3<f64>>();
                    if let Some(u) = mean_up.try_normalize(1e-9) {
                        up.insert(s.id.clone(), u);
                    }
                }
                let held = PoseResult {
                    start_s: c.start_s,
                    seconds: c.seconds,
                    moved,
                    up,
                };
                if c.kind == CaptureKind::SecondPose {
                    self.second = Some(held);
                } else {
                    self.pose = Some(held);
                    // The bow and the second pose are measured from this one.
                    self.bow = None;
                    self.second = None;
                    self.pelvis_heading_at_pose =
                        self.pelvis_sensor().and_then(|s| self.heading(s));
                }
            }
            CaptureKind::Bow => self.bow = Some(self.bow_result(&c)),
            CaptureKind::Magnetometer => {
                self.mag = self
                    .sensors
                    .iter()
                    .enumerate()
                    .filter(|(_, s)| s.mag.is_some())
                    .map(|(k, s)| MagResult {
                        sensor: s.id.clone(),
                        fit: calibrate_magnetometer(
                            &s.id,
                            c.samples.get(&k).map_or(&[][..], |kept| &kept.mag),
                            MagFit::Ellipsoid,
                        )
                        .map_err(|e| e.to_string()),
                    })
                    .collect();
            }
        }
    }

    /// The forward axis of the sensor on the pelvis (the rig's first bone), from the bow.
    ///
    /// With `u₀` the sensor's up in the pose (the mean direction of its specific force, or of
    /// `q⁻¹·z` for a sensor that sends orientations; sensor frame) and `u₁` its up at the bow's
    /// deepest, the sensor turned about the body's right-left axis: `r = u₀ × u₁`
    /// (normalised) is the body's right in the sensor frame (a forward bow tips gravity toward
    /// the sensor's back), and forward is `f = u₀ × r`.
    fn bow_result(&self, c: &Capture) -> Result<BowResult, String> {
        let pose = self.pose.as_ref().ok_or("no pose held")?;
        let root = self.bones.first().ok_or("the rig has no bones")?;
        let sensor = self
            .pelvis_sensor()
            .map(str::to_string)
            .ok_or_else(|| format!("no sensor on `{root}` (the pelvis): put one there first"))?;
        let u0 = *pose
            .up
            .get(&sensor)
            .ok_or_else(|| format!("`{sensor}` had no readings in the pose"))?;
        let k = self.index[&sensor];
        let ups = &c
            .samples
            .get(&k)
            .ok_or_else(|| format!("`{sensor}` had no readings during the bow"))?
            .up;
        // The deepest: the up (averaged over 5 samples) furthest from u₀.
        let mut deepest: Option<(f64, Vector3<f64>)> = None;
        for w in ups.windows(5) {
            let Some(u) = w.iter().sum::<Vector3<f64>>().try_normalize(1e-9) else {
                continue;
            };
            let angle = u0.angle(&u);
            if deepest.is_none_or(|(d, _)| angle > d) {
                deepest = Some((angle, u));
            }
        }
        let (angle, u1) = deepest.ok_or("too few readings during the bow")?;
        let bow_deg = angle.to_degrees();
        if bow_deg < MIN_BOW_DEG {
            return Err(format!(
                "the pelvis turned {bow_deg:.0}°: bow deeper (at least {MIN_BOW_DEG:.0}°)"
            ));
        }
        let right = u0.cross(&u1).normalize();
        let forward = u0.cross(&right).normalize();
        let (axis, off) = nearest_axis(&forward);
        Ok(BowResult {
            sensor,
            forward: axis,
            off_axis_deg: off.to_degrees(),
            bow_deg,
        })
    }

    /// The state for the page, as JSON.
    pub fn snapshot(&self) -> Snapshot<'_> {
        let now = self.now_s;
        Snapshot {
            now_s: now.is_finite().then_some(now),
            lit: self.lit(),
            figure: &self.figure,
            poses: &self.poses,
            pose: &self.pose_name,
            sensors: self
                .sensors
                .iter()
                .map(|s| {
                    let v = |x: Option<Vector3<f64>>| x.map(<[f64; 3]>::from);
                    let unit = |x: Option<Vector3<f64>>| {
                        x.and_then(|x| x.try_normalize(1e-12)).map(<[f64; 3]>::from)
                    };
                    let acc_norm = s.acc.map(|a| a.norm());
                    let mag_norm = s.mag.map(|m| m.norm());
                    SensorView {
                        id: &s.id,
                        bone: self.assigned.get(&s.id).map(String::as_str),
                        rate_hz: s.step_s.map(|d| 1.0 / d),
                        samples: s.samples,
                        gaps: s.gaps,
                        silent_s: (now - s.last_s).max(0.0),
                        turn_dps: s.activity.to_degrees(),
                        gyr_dps: s.gyr.map(|g| <[f64; 3]>::from(g.map(f64::to_degrees))),
                        gyr_norm_dps: s.gyr.map(|g| g.norm().to_degrees()),
                        acc: v(s.acc),
                        acc_norm,
                        acc_unit: unit(s.acc),
                        mag: v(s.mag),
                        mag_norm,
                        mag_unit: unit(s.mag),
                        q: s.q.map(|q| [q.w, q.i, q.j, q.k]),
                        fused: s.fused.map(|q| [q.w, q.i, q.j, q.k]),
                        fused_tilt_deg: s
                            .fused
                            .map(|q| (q * Vector3::z()).z.clamp(-1.0, 1.0).acos().to_degrees()),
                        fused_heading_deg: s.fused.map(|q| heading_of(q).to_degrees()),
                        fusion_error: s.fusion_error.as_deref(),
                        mag_coverage_pct: self.capture.as_ref().and_then(|c| {
                            let kept = c.samples.get(&self.index[&s.id])?;
                            (c.kind == CaptureKind::Magnetometer && kept.mag.len() >= 2)
                                .then(|| live_coverage(&kept.mag))
                        }),
                        accelerating: acc_norm.is_some_and(|n| (n / G - 1.0).abs() > ACC_DISTURBED),
                        // Against the fit's field when there is one (a raw norm changes
                        // as a sensor with hard iron turns), else the norm's slow mean.
                        magnetic_disturbance: match (
                            s.mag,
                            self.mag_fits().find(|(id, _)| *id == s.id),
                            s.mag_norm,
                        ) {
                            (Some(m), Some((_, fit)), _) if fit.field_norm > 0.0 => {
                                (fit.correct(&m).norm() / fit.field_norm - 1.0).abs()
                                    > MAG_DISTURBED
                            }
                            (Some(m), None, Some(u)) if u > 0.0 => {
                                (m.norm() / u - 1.0).abs() > MAG_DISTURBED
                            }
                            _ => false,
                        },
                    }
                })
                .collect(),
            capture: self.capture.as_ref().map(|c| CaptureView {
                kind: c.kind,
                starts_in_s: (c.start_s - now).max(0.0),
                left_s: (c.start_s + c.seconds - now.max(c.start_s)).max(0.0),
            }),
            bias: &self.bias,
            mag: &self.mag,
            pose_held: self.pose.as_ref(),
            second_pose: self.second_name.as_deref(),
            second_held: self.second.as_ref(),
            pelvis_turn_deg: match (self.pelvis_heading_at_pose, self.pelvis_sensor()) {
                (Some(at_pose), Some(s)) => self.heading(s).map(|h| {
                    let d = (h - at_pose).to_degrees();
                    d - 360.0 * (d / 360.0).round()
                }),
                _ => None,
            },
            bow: self.bow.as_ref().map(|b| match b {
                Ok(b) => BowView::Found(b),
                Err(e) => BowView::Failed { error: e },
            }),
            height_m: self.height_m,
            segments: &self.segments,
            refused_sensors: self.refused,
            message: self.message.as_deref(),
        }
    }

    /// Sensor id → bone, as assigned.
    pub fn assigned(&self) -> &BTreeMap<String, String> {
        &self.assigned
    }

    pub fn height_m(&self) -> Option<f64> {
        self.height_m
    }

    pub fn pose_name(&self) -> &str {
        &self.pose_name
    }

    /// Body part → length, metres.
    pub fn segments(&self) -> &BTreeMap<String, f64> {
        &self.segments
    }

    /// The magnetometer fits found, by sensor.
    pub fn mag_fits(&self) -> impl Iterator<Item = (&str, &MagCalibration)> {
        self.mag
            .iter()
            .filter_map(|m| m.fit.as_ref().ok().map(|f| (m.sensor.as_str(), f)))
    }

    /// The biases found, by sensor.
    pub fn biases(&self) -> impl Iterator<Item = (&str, &GyroBias)> {
        self.bias
            .iter()
            .filter_map(|b| b.bias.as_ref().ok().map(|g| (b.sensor.as_str(), g)))
    }

    /// The forward found by the bow: (sensor, axis).
    pub fn forward(&self) -> Option<(&str, &str)> {
        match &self.bow {
            Some(Ok(b)) => Some((&b.sensor, &b.forward)),
            _ => None,
        }
    }

    /// The pose held, if any.
    pub fn pose_held(&self) -> Option<&PoseResult> {
        self.pose.as_ref()
    }

    /// The second pose's name and hold, when both are there.
    pub fn second_held(&self) -> Option<(&str, &PoseResult)> {
        Some((self.second_name.as_deref()?, self.second.as_ref()?))
    }
}

/// How much of the sphere of directions a magnetometer capture has reached so far, % (as the fit
/// will judge it, [`coverage`]): the readings about their min-max centre, at most
/// [`COVERAGE_SAMPLES`] of them spread evenly over the capture.
fn live_coverage(mag: &[Vector3<f64>]) -> f64 {
    let (mut lo, mut hi) = (mag[0], mag[0]);
    for m in mag {
        lo = lo.inf(m);
        hi = hi.sup(m);
    }
    let mid = (lo + hi) / 2.0;
    let step = mag.len().div_ceil(COVERAGE_SAMPLES);
    coverage(
        mag.iter()
            .step_by(step)
            .filter_map(|m| (m - mid).try_normalize(1e-12)),
    )
}

/// The heading of the x axis of `q_enu_sensor`, radians from north toward east.
fn heading_of(q: UnitQuaternion<f64>) -> f64 {
    let x = q * Vector3::x();
    x.x.atan2(x.y)
}

/// The signed axis nearest `v` (unit), and the angle to it, radians.
fn nearest_axis(v: &Vector3<f64>) -> (String, f64) {
    let (k, c) = (0..3)
        .map(|k| (k, v[k]))
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .expect("three axes");
    let name = format!("{}{}", if c < 0.0 { '-' } else { '+' }, ['x', 'y', 'z'][k]);
    (name, c.abs().clamp(-1.0, 1.0).acos())
}

/// The page's view of the board (JSON).
#[derive(Debug, Serialize)]
pub struct Snapshot<'a> {
    pub now_s: Option<f64>,
    pub lit: Option<&'a str>,
    pub figure: &'a [FigureJoint],
    pub poses: &'a [String],
    pub pose: &'a str,
    pub sensors: Vec<SensorView<'a>>,
    pub capture: Option<CaptureView>,
    pub bias: &'a [BiasResult],
    pub mag: &'a [MagResult],
    pub pose_held: Option<&'a PoseResult>,
    /// The second pose chosen, and its hold.
    pub second_pose: Option<&'a str>,
    pub second_held: Option<&'a PoseResult>,
    /// How far the pelvis sensor has turned about the vertical since the pose, degrees (toward
    /// east positive; `None` before the pose or without a fused pelvis sensor): the follow
    /// camera turns with it.
    pub pelvis_turn_deg: Option<f64>,
    pub bow: Option<BowView<'a>>,
    pub height_m: Option<f64>,
    pub segments: &'a BTreeMap<String, f64>,
    pub refused_sensors: u64,
    pub message: Option<&'a str>,
}

#[derive(Debug, Serialize)]
pub struct SensorView<'a> {
    pub id: &'a str,
    pub bone: Option<&'a str>,
    pub rate_hz: Option<f64>,
    pub samples: u64,
    pub gaps: u64,
    pub silent_s: f64,
    /// The turn rate, low-passed, °/s.
    pub turn_dps: f64,
    pub gyr_dps: Option<[f64; 3]>,
    pub gyr_norm_dps: Option<f64>,
    pub acc: Option<[f64; 3]>,
    pub acc_norm: Option<f64>,
    pub acc_unit: Option<[f64; 3]>,
    pub mag: Option<[f64; 3]>,
    pub mag_norm: Option<f64>,
    pub mag_unit: Option<[f64; 3]>,
    /// `[w, x, y, z]`, `q_enu_sensor`, for sources that send orientations.
    pub q: Option<[f64; 4]>,
    /// Raw readings fused (online VQF): `[w, x, y, z]`, `q_enu_sensor`; the angle of the
    /// sensor's z from up and the heading of its x (from north toward east), degrees.
    pub fused: Option<[f64; 4]>,
    pub fused_tilt_deg: Option<f64>,
    pub fused_heading_deg: Option<f64>,
    pub fusion_error: Option<&'a str>,
    /// During a magnetometer capture: the share of directions reached so far, %.
    pub mag_coverage_pct: Option<f64>,
    pub accelerating: bool,
    pub magnetic_disturbance: bool,
}

#[derive(Debug, Serialize)]
pub struct CaptureView {
    pub kind: CaptureKind,
    pub starts_in_s: f64,
    pub left_s: f64,
}

#[derive(Debug, Serialize)]
#[serde(untagged)]
pub enum BowView<'a> {
    Found(&'a BowResult),
    Failed { error: &'a str },
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn raw(gyr: Vector3<f64>, acc: Vector3<f64>) -> StreamValue {
        StreamValue::Raw {
            imu: ImuSample {
                gyro_rad_s: gyr,
                accel_m_s2: acc,
            },
            mag: Some(Vector3::new(20.0, 0.0, -40.0)),
        }
    }

    pub(crate) fn joints(names: &[&str]) -> Vec<FigureJoint> {
        names
            .iter()
            .enumerate()
            .map(|(i, n)| FigureJoint {
                name: n.to_string(),
                parent: i.checked_sub(1),
                position_m: [0.0, i as f64 * 0.1, 0.0],
                end_m: None,
            })
            .collect()
    }

    /// A step of the bow tests: a command, or sensor `p`'s sample at `t` bowed `bow_rad`.
    pub(crate) enum BowStep {
        Command(Command),
        Sample { t: f64, bow_rad: f64 },
    }

    /// The bow tests' protocol at 100 Hz: sensor `p` on `Hips` at t = 0, the pose held still for
    /// 1 s (1.2 s of samples), then a forward bow of 30°·sin(π·i/200) over sample i of 250 (down
    /// and back up over 2 s, the deepest at 1 s) inside a 2 s capture.
    pub(crate) fn pose_then_bow() -> Vec<BowStep> {
        let capture = |kind, seconds| {
            BowStep::Command(Command::Capture {
                kind,
                seconds,
                countdown_s: 0.0,
            })
        };
        let mut steps = vec![
            BowStep::Sample {
                t: 0.0,
                bow_rad: 0.0,
            },
            BowStep::Command(Command::Assign {
                sensor: "p".into(),
                bone: "Hips".into(),
            }),
            capture(CaptureKind::Pose, 1.0),
        ];
        let mut t = 0.0;
        for _ in 0..120 {
            t += 0.01;
            steps.push(BowStep::Sample { t, bow_rad: 0.0 });
        }
        steps.push(capture(CaptureKind::Bow, 2.0));
        for i in 0..250 {
            t += 0.01;
            let bow_rad = 30f64.to_radians() * (std::f64::consts::PI * i as f64 / 200.0).sin();
            steps.push(BowStep::Sample { t, bow_rad });
        }
        steps
    }

    fn board() -> Board {
        Board::new(
            joints(&["Hips", "Spine", "LeftArm"]),
            vec!["rest".into(), "tpose".into()],
        )
    }

    #[test]
    fn the_sensor_that_turns_lights_up_and_the_still_ones_do_not() {
        let mut b = board();
        let still = raw(Vector3::new(0.001, 0.0, 0.0), Vector3::new(0.0, 0.0, G));
        // 100 Hz: s1 still, s2 turns at 90 °/s from t = 1 s.
        for i in 0..200 {
            let t = i as f64 / 100.0;
            b.sample("s1", t, still);
            let w = if t >= 1.0 { 90f64.to_radians() } else { 0.0 };
            b.sample(
                "s2",
                t,
                raw(Vector3::new(0.0, 0.0, w), Vector3::new(0.0, 0.0, G)),
            );
            if (t - 0.99).abs() < 1e-9 {
                assert_eq!(b.lit(), None);
            }
            // Low-passed over 0.1 s: 30 °/s of 90 is passed after 0.1·ln(3/2) ≈ 0.04 s.
            if (t - 1.06).abs() < 1e-9 {
                assert_eq!(b.lit(), Some("s2"));
            }
        }
        let snap = b.snapshot();
        assert_eq!(snap.sensors.len(), 2);
        assert!((snap.sensors[0].rate_hz.unwrap() - 100.0).abs() < 1e-6);
        assert_eq!(snap.sensors[0].acc_norm, Some(G));
        assert_eq!(snap.sensors[0].acc_unit, Some([0.0, 0.0, 1.0]));
    }

    #[test]
    fn a_sensor_that_sends_orientations_lights_up_by_their_turn() {
        // Orientations at 100 Hz: `q` turns at 60 °/s about y from t = 1 s, `r` stays; the
        // angle between consecutive quaternions over their step is the turn rate.
        let mut b = board();
        for i in 0..150 {
            let t = i as f64 / 100.0;
            let angle = (t - 1.0).max(0.0) * 60f64.to_radians();
            let turned = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), angle);
            b.sample("q", t, StreamValue::Quaternion(turned));
            b.sample("r", t, StreamValue::Quaternion(UnitQuaternion::identity()));
        }
        assert_eq!(b.lit(), Some("q"));
        let snap = b.snapshot();
        assert!(
            (snap.sensors[0].turn_dps - 60.0).abs() < 0.5,
            "{}",
            snap.sensors[0].turn_dps
        );
        assert_eq!(snap.sensors[1].turn_dps, 0.0);
        assert!(snap.sensors[0].q.is_some() && snap.sensors[0].fused.is_none());
    }

    #[test]
    fn a_suit_that_sends_orientations_bows_to_the_same_forward() {
        // The pelvis sensor of the raw test, sending `q_enu_sensor` instead: 180° about z (its
        // −y the body's forward, north), then a forward bow of 30°: a turn about the world's −x
        // (the trunk tips north), taken before the mount.
        let mut b = board();
        let q0 = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI);
        for step in pose_then_bow() {
            match step {
                BowStep::Command(c) => b.command(c).unwrap(),
                BowStep::Sample { t, bow_rad } => {
                    let bow = UnitQuaternion::from_axis_angle(&-Vector3::x_axis(), bow_rad);
                    b.sample("p", t, StreamValue::Quaternion(bow * q0));
                }
            }
        }
        assert!(b.pose_held().unwrap().moved.is_empty());
        assert_eq!(b.forward(), Some(("p", "-y")));
    }

    #[test]
    fn a_gap_is_counted() {
        let mut b = board();
        let still = raw(Vector3::zeros(), Vector3::new(0.0, 0.0, G));
        for t in [0.0, 0.01, 0.02, 0.03, 0.2, 0.21] {
            b.sample("s", t, still);
        }
        assert_eq!(b.snapshot().sensors[0].gaps, 1);
    }

    #[test]
    fn a_bone_has_one_sensor_and_unknown_names_are_refused() {
        let mut b = board();
        let still = raw(Vector3::zeros(), Vector3::new(0.0, 0.0, G));
        b.sample("a", 0.0, still);
        b.sample("b", 0.0, still);
        let assign = |s: &str, bone: &str| Command::Assign {
            sensor: s.into(),
            bone: bone.into(),
        };
        b.command(assign("a", "Hips")).unwrap();
        b.command(assign("b", "Hips")).unwrap();
        assert_eq!(b.assigned().len(), 1);
        assert_eq!(b.assigned()["b"], "Hips");
        assert!(b.command(assign("c", "Hips")).is_err());
        assert!(b.command(assign("a", "Tail")).is_err());
        assert!(b.command(Command::Height { m: f64::NAN }).is_err());
        assert!(
            b.command(Command::Pose {
                name: "apose".into()
            })
            .is_err()
        );
    }

    #[test]
    fn the_gyro_bias_capture_is_each_sensors_mean_and_a_moving_one_is_refused() {
        let mut b = board();
        let bias = Vector3::new(0.5f64, -0.25, 1.0).map(f64::to_radians);
        let g = Vector3::new(0.0, 0.0, G);
        b.sample("still", 0.0, raw(bias, g));
        b.sample("moving", 0.0, raw(Vector3::zeros(), g));
        b.command(Command::Capture {
            kind: CaptureKind::GyroBias,
            seconds: 2.0,
            countdown_s: 1.0,
        })
        .unwrap();
        for i in 1..=400 {
            let t = i as f64 / 100.0;
            // ± 0.2 °/s alternating: the mean is the bias to rounding.
            let noise = Vector3::repeat(if i % 2 == 0 { 0.2f64 } else { -0.2 }.to_radians());
            b.sample("still", t, raw(bias + noise, g));
            let w = 40f64.to_radians() * (t * 3.0).sin();
            b.sample("moving", t, raw(Vector3::new(w, 0.0, 0.0), g));
        }
        let found: Vec<_> = b.biases().collect();
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].0, "still");
        for k in 0..3 {
            assert!((found[0].1.bias_rad_s[k] - bias[k]).abs() < 0.01f64.to_radians());
        }
        // 1 s countdown, 2 s: samples from t = 1 to 3 s.
        assert_eq!(found[0].1.window_s, [1.0, 3.0]);
        let snap = b.snapshot();
        assert!(snap.capture.is_none());
        assert!(
            snap.bias
                .iter()
                .any(|r| r.sensor == "moving" && r.bias.is_err())
        );
    }

    #[test]
    fn a_still_tilted_sensor_is_fused_to_its_tilt() {
        // Turned 30° about x: its z is 30° from up; the field (0, 20, −40) µT in ENU gives its
        // x's heading: x stays along east, 90° from north.
        let mut b = board();
        let turn = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 30f64.to_radians());
        let (g, m) = (Vector3::new(0.0, 0.0, G), Vector3::new(0.0, 20.0, -40.0));
        for i in 0..1000 {
            b.sample(
                "s",
                i as f64 / 100.0,
                StreamValue::Raw {
                    imu: ImuSample {
                        gyro_rad_s: Vector3::zeros(),
                        accel_m_s2: turn.inverse() * g,
                    },
                    mag: Some(turn.inverse() * m),
                },
            );
        }
        let snap = b.snapshot();
        let s = &snap.sensors[0];
        assert!(
            (s.fused_tilt_deg.unwrap() - 30.0).abs() < 0.1,
            "{:?}",
            s.fused_tilt_deg
        );
        assert!(
            (s.fused_heading_deg.unwrap() - 90.0).abs() < 0.5,
            "{:?}",
            s.fused_heading_deg
        );
        assert_eq!(s.fusion_error, None);
    }

    #[test]
    fn a_magnetometer_turned_everywhere_gets_its_hard_and_soft_iron() {
        // A field of 50 read through x = S·m + h, S symmetric (det 1.05), h = (12, −7, 30),
        // the sensor turned over a spiral of directions for 20 s at 100 Hz.
        let mut b = board();
        let h = Vector3::new(12.0, -7.0, 30.0);
        let soft = nalgebra::Matrix3::new(1.1, 0.05, 0.0, 0.05, 0.95, 0.02, 0.0, 0.02, 1.0);
        b.sample("s", 0.0, raw(Vector3::zeros(), Vector3::new(0.0, 0.0, G)));
        b.command(Command::Capture {
            kind: CaptureKind::Magnetometer,
            seconds: 20.0,
            countdown_s: 0.0,
        })
        .unwrap();
        let n = 2000;
        let mut seen = Vec::new();
        for i in 1..=n {
            // A Fibonacci spiral over the sphere: each direction of the field in the sensor.
            let z = 1.0 - 2.0 * (i as f64 - 0.5) / n as f64;
            let phi = std::f64::consts::PI * (3.0 - 5f64.sqrt()) * i as f64;
            let d = Vector3::new(
                (1.0 - z * z).sqrt() * phi.cos(),
                (1.0 - z * z).sqrt() * phi.sin(),
                z,
            );
            let value = StreamValue::Raw {
                imu: ImuSample {
                    gyro_rad_s: Vector3::zeros(),
                    accel_m_s2: Vector3::new(0.0, 0.0, G),
                },
                mag: Some(soft * (d * 50.0) + h),
            };
            b.sample("s", i as f64 / 100.0, value);
            if i % 500 == 0 {
                seen.push(b.snapshot().sensors[0].mag_coverage_pct.unwrap());
            }
        }
        // Judged about the readings' min-max centre, as the fit's own check does: a cap of the
        // sphere reads wide while its centre is off; the whole sphere reads whole.
        assert!(*seen.last().unwrap() > 90.0, "{seen:?}");
        // One more sample past the end closes the capture.
        b.sample("s", 20.5, raw(Vector3::zeros(), Vector3::new(0.0, 0.0, G)));
        let fits: Vec<_> = b.mag_fits().collect();
        assert_eq!(fits.len(), 1, "{:?}", b.snapshot().mag);
        let fit = fits[0].1;
        for k in 0..3 {
            assert!(
                (fit.hard_iron[k] - h[k]).abs() < 0.01,
                "{:?}",
                fit.hard_iron
            );
        }
        // W·S is a pure scale: the corrected field's directions are the field's.
        let ws = fit.matrix() * soft;
        let scale = ws[(0, 0)];
        assert!(
            (ws - nalgebra::Matrix3::identity() * scale).norm() < 1e-6,
            "{ws}"
        );
        assert!(fit.coverage_pct > 95.0);
    }

    #[test]
    fn the_follow_camera_turns_with_the_pelvis_since_the_pose() {
        // The pelvis sensor lies flat (z up), its x north. After the pose it turns clockwise
        // seen from above by 90° (−90° about z, 1 s at −90 °/s): its x then points east, a
        // heading of +90° from north toward east.
        let mut b = board();
        let (g, m) = (Vector3::new(0.0, 0.0, G), Vector3::new(0.0, 20.0, -40.0));
        let reading = |q: UnitQuaternion<f64>, w: f64| StreamValue::Raw {
            imu: ImuSample {
                gyro_rad_s: Vector3::new(0.0, 0.0, w),
                accel_m_s2: q.inverse() * g,
            },
            mag: Some(q.inverse() * m),
        };
        let mut t = 0.0;
        b.sample("p", t, reading(UnitQuaternion::identity(), 0.0));
        b.command(Command::Assign {
            sensor: "p".into(),
            bone: "Hips".into(),
        })
        .unwrap();
        b.command(Command::Capture {
            kind: CaptureKind::Pose,
            seconds: 1.0,
            countdown_s: 2.0,
        })
        .unwrap();
        for _ in 0..400 {
            t += 0.01;
            b.sample("p", t, reading(UnitQuaternion::identity(), 0.0));
        }
        assert!(b.snapshot().pelvis_turn_deg.unwrap().abs() < 0.5);
        let rate = -90f64.to_radians();
        for i in 1..=200 {
            t += 0.01;
            let angle = rate * (i.min(100) as f64 * 0.01);
            let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle);
            b.sample("p", t, reading(q, if i <= 100 { rate } else { 0.0 }));
        }
        let turn = b.snapshot().pelvis_turn_deg.unwrap();
        assert!((turn - 90.0).abs() < 1.0, "{turn}");
    }

    #[test]
    fn a_segment_is_a_body_part_of_a_plausible_length() {
        let mut b = board();
        let seg = |part: &str, m: Option<f64>| Command::Segment {
            part: part.into(),
            m,
        };
        b.command(seg("left_thigh", Some(0.42))).unwrap();
        assert!(b.command(seg("left_tail", Some(0.42))).is_err());
        assert!(b.command(seg("left_shank", Some(3.0))).is_err());
        assert!(b.command(seg("left_shank", Some(f64::INFINITY))).is_err());
        assert_eq!(b.segments().len(), 1);
        b.command(seg("left_thigh", None)).unwrap();
        assert!(b.segments().is_empty());
    }

    proptest::proptest! {
        /// Whatever the stream sends (any times and values, NaN and infinities included) and in
        /// any order with whatever commands, the board neither panics nor grows past its bounds.
        #[test]
        fn any_samples_and_commands_leave_the_board_whole(
            steps in proptest::collection::vec(
                (0u8..6, -1e3f64..1e3, proptest::prelude::any::<[f64; 9]>(), 0u8..5),
                1..300,
            )
        ) {
            let mut b = board();
            for (sensor, t, v, what) in steps {
                let id = format!("s{sensor}");
                let value = StreamValue::Raw {
                    imu: ImuSample {
                        gyro_rad_s: Vector3::new(v[0], v[1], v[2]),
                        accel_m_s2: Vector3::new(v[3], v[4], v[5]),
                    },
                    mag: Some(Vector3::new(v[6], v[7], v[8])),
                };
                b.sample(&id, t, value);
                let command = match what {
                    0 => Command::Capture { kind: CaptureKind::GyroBias, seconds: 0.5, countdown_s: 0.0 },
                    1 => Command::Capture { kind: CaptureKind::Magnetometer, seconds: 0.5, countdown_s: 0.0 },
                    2 => Command::Capture { kind: CaptureKind::Pose, seconds: 0.5, countdown_s: 0.0 },
                    3 => Command::Capture { kind: CaptureKind::Bow, seconds: 0.5, countdown_s: 0.0 },
                    _ => Command::Assign { sensor: id.clone(), bone: "Hips".into() },
                };
                let _ = b.command(command);
                let snapshot = serde_json::to_string(&b.snapshot()).unwrap();
                proptest::prop_assert!(snapshot.len() < 1 << 20);
            }
            // Whatever came before, a sensor that turns at 90 °/s for 0.5 s of its own time
            // lights up (no value it was fed stays in its low-passed turn rate).
            for i in 1..=50 {
                let t = 2e3 + i as f64 / 100.0;
                b.sample("s0", t, raw(Vector3::new(90f64.to_radians(), 0.0, 0.0), Vector3::new(0.0, 0.0, G)));
                for k in 1..6 {
                    b.sample(&format!("s{k}"), t, raw(Vector3::zeros(), Vector3::new(0.0, 0.0, G)));
                }
            }
            proptest::prop_assert_eq!(b.lit(), Some("s0"));
        }
    }

    #[test]
    fn the_bow_gives_the_pelvis_sensors_forward_axis() {
        // The pelvis sensor is mounted with its -y axis forward and its +z up: in the sensor
        // frame the body's forward is -y. A forward bow of 30° tips gravity toward the
        // sensor's back (+y): specific force (0, sin 30°, cos 30°)·g.
        let mut b = board();
        let up = Vector3::new(0.0, 0.0, G);
        b.sample("p", 0.0, raw(Vector3::zeros(), up));
        // Not before the pose: the bow is measured from it.
        let bow = Command::Capture {
            kind: CaptureKind::Bow,
            seconds: 2.0,
            countdown_s: 0.0,
        };
        assert!(b.command(bow).unwrap_err().contains("pose first"));
        for step in pose_then_bow() {
            match step {
                BowStep::Command(c) => b.command(c).unwrap(),
                BowStep::Sample { t, bow_rad } => {
                    let a = Vector3::new(0.0, bow_rad.sin(), bow_rad.cos()) * G;
                    b.sample("p", t, raw(Vector3::zeros(), a));
                }
            }
        }
        assert!(b.pose_held().unwrap().moved.is_empty());
        assert_eq!(b.forward(), Some(("p", "-y")));
        let Some(BowView::Found(found)) = b.snapshot().bow else {
            panic!("no bow");
        };
        assert!((found.bow_deg - 30.0).abs() < 0.5, "{}", found.bow_deg);
        assert!(found.off_axis_deg < 1e-6);
    }
}
