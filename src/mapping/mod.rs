//! Sensor-to-bone mappings (README, "Mappings"): which sensor drives which bone, how it is
//! mounted, and the calibration window. Paper 002's Listing-2 format is accepted as a legacy mode.

mod axes;
mod legacy;
mod suggest;

pub use axes::{parse_axis, parse_mount_axes};
pub use legacy::{EulerSource, LegacyChannel, LegacyMapping, LegacyTarget};
pub use suggest::{nearest_bones, unknown_bone_message};

use crate::rig::Rig;
use crate::world::World;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::de::{self, MapAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};

/// How a sensor sits on its bone: `q_bone_sensor`.
#[derive(Debug, Clone, PartialEq)]
pub enum Mount {
    /// Known: the sensor's orientation in its bone's frame.
    Fixed(UnitQuaternion<f64>),
    /// Solved from the calibration window.
    Calibrate,
}

/// The pose the subject holds during calibration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PoseRef {
    Rest,
    Named(String),
    /// Frame N of a BVH rig's motion.
    BvhFrame(usize),
}

impl PoseRef {
    fn parse(s: &str) -> Result<PoseRef, String> {
        if s == "rest" {
            return Ok(PoseRef::Rest);
        }
        if let Some(n) = s.strip_prefix("frame:") {
            return n
                .trim()
                .parse()
                .map(PoseRef::BvhFrame)
                .map_err(|_| format!("`{s}`: expected frame:N with N a frame number"));
        }
        if s.is_empty() {
            return Err("empty pose name".into());
        }
        Ok(PoseRef::Named(s.to_string()))
    }

    pub fn label(&self) -> String {
        match self {
            PoseRef::Rest => "rest".into(),
            PoseRef::Named(n) => n.clone(),
            PoseRef::BvhFrame(n) => format!("frame:{n}"),
        }
    }
}

/// A window of the take in which the subject holds `pose`, and optionally a second one: the turn
/// of each bone between the two poses gives the heading of sensors that have none of their own
/// (fused without a magnetometer), as SlimeVR's mounting reset does.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationWindow {
    pub pose: PoseRef,
    pub start_s: f64,
    pub duration_s: f64,
    pub second: Option<SecondPose>,
}

/// The second calibration pose (`calibration.second`), held after the first.
#[derive(Debug, Clone, PartialEq)]
pub struct SecondPose {
    pub pose: PoseRef,
    pub start_s: f64,
    pub duration_s: f64,
}

impl CalibrationWindow {
    /// The same poses held again from `start_s` (a recalibration): every start moves by the
    /// same amount.
    pub fn starting_at(&self, start_s: f64) -> CalibrationWindow {
        let shift = start_s - self.start_s;
        CalibrationWindow {
            pose: self.pose.clone(),
            start_s,
            duration_s: self.duration_s,
            second: self.second.as_ref().map(|p| SecondPose {
                pose: p.pose.clone(),
                start_s: p.start_s + shift,
                duration_s: p.duration_s,
            }),
        }
    }

    /// Where the last pose ends, seconds.
    pub fn end_s(&self) -> f64 {
        match &self.second {
            Some(s) => (s.start_s + s.duration_s).max(self.start_s + self.duration_s),
            None => self.start_s + self.duration_s,
        }
    }
}

impl Default for CalibrationWindow {
    fn default() -> Self {
        CalibrationWindow {
            pose: PoseRef::Rest,
            start_s: 0.0,
            duration_s: 1.0,
            second: None,
        }
    }
}

/// One sensor's entry.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorMapping {
    pub sensor: String,
    pub bone: String,
    pub mount: Mount,
    /// The sensor axis that points where the body faces during calibration (sensor frame).
    pub forward: Option<Vector3<f64>>,
}

/// Where the subject's heading comes from (the mapping's `heading`, `--heading`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HeadingPolicy {
    /// From the take (a declared `forward`, a known mount, a second pose, walking); a take whose
    /// heading is unsure is refused ([`crate::pipeline::calibrate`]).
    #[default]
    Estimate,
    /// The sensors' own north is kept as the subject's facing, deliberately: for hardware whose
    /// north is the subject's (a suit calibrated facing a known way) or when the axes of the turns
    /// do not matter.
    Sensors,
}

impl std::str::FromStr for HeadingPolicy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "estimate" => Ok(HeadingPolicy::Estimate),
            "sensors" => Ok(HeadingPolicy::Sensors),
            _ => Err(format!(
                "`{s}`: expected `estimate` (from the take; refused when unsure) or `sensors` (keep the sensors' north)"
            )),
        }
    }
}

impl HeadingPolicy {
    pub fn label(self) -> &'static str {
        match self {
            HeadingPolicy::Estimate => "estimate",
            HeadingPolicy::Sensors => "sensors",
        }
    }
}

/// A quaternion-mode mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct Mapping {
    pub rig: Option<String>,
    pub world: Option<World>,
    /// Where the heading comes from.
    pub heading: HeadingPolicy,
    pub calibration: Option<CalibrationWindow>,
    /// In file order.
    pub sensors: Vec<SensorMapping>,
}

/// What a mapping file holds.
#[derive(Debug, Clone, PartialEq)]
pub enum MappingFile {
    Quaternion(Mapping),
    /// Paper 002's Listing 2 (signed Euler channel copy).
    Legacy(LegacyMapping),
}

/// A mapping problem, naming the file and the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {}{message}", .file.display(), key_prefix(.key))]
pub struct MappingError {
    pub file: PathBuf,
    /// Dotted path of the offending key, e.g. `sensors.N1_0.mount`; empty for the whole file.
    pub key: String,
    pub message: String,
}

fn key_prefix(key: &str) -> String {
    if key.is_empty() {
        String::new()
    } else {
        format!("`{key}`: ")
    }
}

impl MappingError {
    pub fn new(file: &Path, key: impl Into<String>, message: impl Into<String>) -> Self {
        MappingError {
            file: file.to_path_buf(),
            key: key.into(),
            message: message.into(),
        }
    }
}

/// A JSON object's entries in file order (repeated keys are refused before, by
/// [`first_repeated_sensor`]).
#[derive(Debug)]
struct OrderedMap<V>(Vec<(String, V)>);

impl<'de, V: Deserialize<'de>> Deserialize<'de> for OrderedMap<V> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct V_<V>(std::marker::PhantomData<V>);
        impl<'de, V: Deserialize<'de>> Visitor<'de> for V_<V> {
            type Value = OrderedMap<V>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut out: Vec<(String, V)> = Vec::new();
                while let Some(key) = map.next_key::<String>()? {
                    let value = map.next_value()?;
                    out.push((key, value));
                }
                Ok(OrderedMap(out))
            }
        }
        deserializer.deserialize_map(V_(std::marker::PhantomData))
    }
}

/// The first sensor id that appears twice under `sensors`, if any (serde_json would silently keep
/// the last one).
fn first_repeated_sensor(text: &str) -> Option<String> {
    struct FirstRepeat(Option<String>);
    impl<'de> Deserialize<'de> for FirstRepeat {
        fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
            struct V;
            impl<'de> Visitor<'de> for V {
                type Value = FirstRepeat;
                fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                    f.write_str("an object")
                }
                fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<FirstRepeat, A::Error> {
                    let mut seen = std::collections::HashSet::new();
                    let mut repeat = None;
                    while let Some(key) = map.next_key::<String>()? {
                        map.next_value::<de::IgnoredAny>()?;
                        if !seen.insert(key.clone()) && repeat.is_none() {
                            repeat = Some(key);
                        }
                    }
                    Ok(FirstRepeat(repeat))
                }
            }
            deserializer.deserialize_map(V)
        }
    }
    #[derive(Deserialize)]
    struct Top {
        sensors: FirstRepeat,
    }
    serde_json::from_str::<Top>(text).ok()?.sensors.0
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMapping {
    #[serde(default)]
    rig: Option<String>,
    #[serde(default)]
    world: Option<String>,
    #[serde(default)]
    calibration: Option<RawCalibration>,
    #[serde(default)]
    heading: Option<String>,
    /// Free text for people (why the heading is kept, which suit); not read.
    #[serde(default, rename = "comment")]
    _comment: Option<String>,
    sensors: OrderedMap<RawSensor>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCalibration {
    #[serde(default = "default_pose")]
    pose: String,
    #[serde(default)]
    start_s: f64,
    #[serde(default = "default_duration")]
    duration_s: f64,
    #[serde(default)]
    second: Option<RawSecondPose>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSecondPose {
    pose: String,
    start_s: f64,
    #[serde(default = "default_duration")]
    duration_s: f64,
}

/// A pose window's fields checked; `key` is `calibration` or `calibration.second`.
fn pose_window(
    file: &Path,
    key: &str,
    pose: &str,
    start_s: f64,
    duration_s: f64,
) -> Result<(PoseRef, f64, f64), MappingError> {
    let pose =
        PoseRef::parse(pose).map_err(|e| MappingError::new(file, format!("{key}.pose"), e))?;
    if !(start_s.is_finite() && start_s >= 0.0) {
        return Err(MappingError::new(
            file,
            format!("{key}.start_s"),
            "expected seconds ≥ 0",
        ));
    }
    if !(duration_s.is_finite() && duration_s >= 0.0) {
        return Err(MappingError::new(
            file,
            format!("{key}.duration_s"),
            "expected seconds ≥ 0",
        ));
    }
    Ok((pose, start_s, duration_s))
}

fn default_pose() -> String {
    "rest".into()
}

fn default_duration() -> f64 {
    1.0
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSensor {
    bone: String,
    #[serde(default = "default_mount")]
    mount: serde_json::Value,
    #[serde(default)]
    forward: Option<String>,
}

fn default_mount() -> serde_json::Value {
    serde_json::Value::String("calibrate".into())
}

fn parse_mount(value: &serde_json::Value) -> Result<Mount, String> {
    match value {
        serde_json::Value::String(s) if s == "calibrate" => Ok(Mount::Calibrate),
        serde_json::Value::String(s) => parse_mount_axes(s).map(Mount::Fixed),
        serde_json::Value::Array(items) if items.len() == 4 => {
            let v: Option<Vec<f64>> = items.iter().map(|i| i.as_f64()).collect();
            let v = v.ok_or("a quaternion mount needs four numbers [w, x, y, z]")?;
            let q = Quaternion::new(v[0], v[1], v[2], v[3]);
            let n = q.norm();
            if !n.is_finite() || (n - 1.0).abs() > 0.01 {
                return Err(format!(
                    "quaternion [w, x, y, z] = {v:?} has length {n:.4}; expected a unit quaternion"
                ));
            }
            Ok(Mount::Fixed(UnitQuaternion::from_quaternion(q)))
        }
        _ => Err(
            "expected \"calibrate\", an axis string such as \"+y-x+z\", or a quaternion [w, x, y, z]"
                .into(),
        ),
    }
}

impl crate::diagnostic::Diagnostic for MappingError {
    fn file(&self) -> Option<&Path> {
        Some(&self.file)
    }

    fn hint(&self) -> Option<&'static str> {
        Some("check the mapping file (README, Mappings)")
    }
}

/// What a mapping looks like, for errors that have to say what to write.
const SHAPE_EXAMPLE: &str = r#"{"rig": "mixamo", "sensors": {"pelvis": {"bone": "Hips"}, "left_thigh": {"bone": "LeftUpLeg"}}}"#;

/// What to do with a mapping that maps nothing.
fn what_to_write() -> String {
    format!(
        "map each sensor id of the take to a bone of the rig, e.g. {SHAPE_EXAMPLE} \
         (full examples: mappings/*.json, such as mappings/paper000_16imu_mixamo.json; \
         every key: the reference's Mappings page)"
    )
}

/// Parses a mapping file's text (JSON). `file` names it in errors.
pub fn parse_mapping(text: &str, file: &Path) -> Result<MappingFile, MappingError> {
    if text.trim().is_empty() {
        return Err(MappingError::new(
            file,
            "",
            format!("the file is empty; {}", what_to_write()),
        ));
    }
    let value: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| MappingError::new(file, "", format!("not valid JSON: {e}")))?;
    if legacy::looks_like(&value) {
        return legacy::parse(&value, file).map(MappingFile::Legacy);
    }
    if let Some(id) = first_repeated_sensor(text) {
        return Err(MappingError::new(
            file,
            format!("sensors.{id}"),
            format!("sensor `{id}` is mapped twice; map each sensor once"),
        ));
    }
    let raw: RawMapping = serde_json::from_str(text).map_err(|e| {
        MappingError::new(
            file,
            "",
            format!("{e}; expected {{\"rig\", \"world\", \"calibration\", \"heading\", \"comment\", \"sensors\": {{id: {{\"bone\", \"mount\", \"forward\"}}}}}}"),
        )
    })?;
    let world = match raw.world {
        None => None,
        Some(w) => Some(
            w.parse::<World>()
                .map_err(|e| MappingError::new(file, "world", e.to_string()))?,
        ),
    };
    let calibration = match raw.calibration {
        None => None,
        Some(c) => {
            let (pose, start_s, duration_s) =
                pose_window(file, "calibration", &c.pose, c.start_s, c.duration_s)?;
            let second = match c.second {
                None => None,
                Some(s) => {
                    let (pose, start_s2, duration_s2) =
                        pose_window(file, "calibration.second", &s.pose, s.start_s, s.duration_s)?;
                    if start_s2 < start_s + duration_s {
                        return Err(MappingError::new(
                            file,
                            "calibration.second.start_s",
                            format!(
                                "the second pose starts at {start_s2} s, before the first ends ({} s)",
                                start_s + duration_s
                            ),
                        ));
                    }
                    Some(SecondPose {
                        pose,
                        start_s: start_s2,
                        duration_s: duration_s2,
                    })
                }
            };
            Some(CalibrationWindow {
                pose,
                start_s,
                duration_s,
                second,
            })
        }
    };
    let mut sensors = Vec::new();
    for (id, s) in raw.sensors.0 {
        let mount = parse_mount(&s.mount)
            .map_err(|e| MappingError::new(file, format!("sensors.{id}.mount"), e))?;
        let forward = match &s.forward {
            None => None,
            Some(f) => Some(
                parse_axis(f)
                    .map_err(|e| MappingError::new(file, format!("sensors.{id}.forward"), e))?,
            ),
        };
        if let Some((other, _)) = sensors
            .iter()
            .map(|m: &SensorMapping| (&m.sensor, &m.bone))
            .find(|(_, bone)| **bone == s.bone)
        {
            return Err(MappingError::new(
                file,
                format!("sensors.{id}.bone"),
                format!(
                    "bone `{}` is already driven by sensor `{other}`; one sensor per bone",
                    s.bone
                ),
            ));
        }
        sensors.push(SensorMapping {
            sensor: id,
            bone: s.bone,
            mount,
            forward,
        });
    }
    if sensors.is_empty() {
        return Err(MappingError::new(
            file,
            "sensors",
            format!("no sensors mapped; {}", what_to_write()),
        ));
    }
    let heading = match &raw.heading {
        None => HeadingPolicy::Estimate,
        Some(h) => h
            .parse()
            .map_err(|e: String| MappingError::new(file, "heading", e))?,
    };
    Ok(MappingFile::Quaternion(Mapping {
        rig: raw.rig,
        world,
        heading,
        calibration,
        sensors,
    }))
}

/// Reads and parses a mapping file.
pub fn load_mapping(path: &Path) -> Result<MappingFile, MappingError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| MappingError::new(path, "", format!("cannot read: {e}")))?;
    parse_mapping(&text, path)
}

/// A mapping checked against a rig: bone indices resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedSensor {
    pub sensor: String,
    pub bone: usize,
    pub mount: Mount,
    pub forward: Option<Vector3<f64>>,
    /// The sensor's heading is its own, not north (fused without a magnetometer): calibration
    /// aligns it ([`crate::pipeline::calibrate`]). Set by the sources stage.
    pub own_heading: bool,
}

impl Mapping {
    /// Resolves bone names on `rig`; unknown bones are errors naming the key.
    pub fn resolve(&self, rig: &Rig, file: &Path) -> Result<Vec<ResolvedSensor>, MappingError> {
        self.sensors
            .iter()
            .map(|s| {
                let bone = rig.joint_index(&s.bone).ok_or_else(|| {
                    MappingError::new(
                        file,
                        format!("sensors.{}.bone", s.sensor),
                        unknown_bone_message(rig, &s.bone),
                    )
                })?;
                Ok(ResolvedSensor {
                    sensor: s.sensor.clone(),
                    bone,
                    mount: s.mount.clone(),
                    forward: s.forward,
                    own_heading: false,
                })
            })
            .collect()
    }

    /// The default mapping for a rig whose bones are named like the take's sensors: each sensor
    /// drives its namesake, mounts calibrated in the rest pose over the first second.
    pub fn by_name(rig: &Rig, sensor_ids: &[&str]) -> Option<Mapping> {
        let sensors: Vec<SensorMapping> = sensor_ids
            .iter()
            .filter(|id| rig.joint_index(id).is_some())
            .map(|id| SensorMapping {
                sensor: id.to_string(),
                bone: rig.joints()[rig.joint_index(id).expect("filtered")]
                    .name
                    .clone(),
                mount: Mount::Calibrate,
                forward: None,
            })
            .collect();
        (!sensors.is_empty()).then(|| Mapping {
            rig: Some(rig.name().to_string()),
            world: None,
            heading: HeadingPolicy::Estimate,
            calibration: Some(CalibrationWindow::default()),
            sensors,
        })
    }
}

/// The resolved mapping as recorded in the sidecar.
#[derive(Debug, Clone, Serialize)]
pub struct MappingRecord {
    pub file: Option<String>,
    pub rig: String,
    pub world: World,
    pub calibration: Option<CalibrationRecord>,
    pub sensors: Vec<SensorRecord>,
    /// Paper 002's Listing-2 targets, in legacy mode (`sensors` is then empty).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub legacy: Option<Vec<LegacyTargetRecord>>,
}

/// One Listing-2 target as recorded in the sidecar.
#[derive(Debug, Clone, Serialize)]
pub struct LegacyTargetRecord {
    pub sou: String,
    /// 1 or 2.
    pub mpu: u8,
    /// The node MPU`mpu` measures: `<sou>_0` or `<sou>_1`.
    pub node: String,
    pub bone: String,
    /// Blender Euler X, Y, Z channels as signed angles, e.g. `-pitch1`.
    #[serde(rename = "X")]
    pub x: String,
    #[serde(rename = "Y")]
    pub y: String,
    #[serde(rename = "Z")]
    pub z: String,
    /// The Table-1 parent whose absolute angles were subtracted from `node`'s; `null` when
    /// `node`'s angles were used as read.
    pub relative_to: Option<String>,
}

impl LegacyTargetRecord {
    pub fn new(target: &LegacyTarget, relative_to: Option<String>) -> Self {
        let channel = |c: &LegacyChannel| {
            format!(
                "{}{}{}",
                if c.sign < 0.0 { '-' } else { '+' },
                ["yaw", "pitch", "roll"][c.source.angle],
                c.source.mpu
            )
        };
        LegacyTargetRecord {
            sou: target.sou.clone(),
            mpu: target.mpu,
            node: target.node.clone(),
            bone: target.target.clone(),
            x: channel(&target.channels[0]),
            y: channel(&target.channels[1]),
            z: channel(&target.channels[2]),
            relative_to,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct CalibrationRecord {
    pub pose: String,
    pub start_s: f64,
    pub duration_s: f64,
    /// The second pose, when there is one: `{pose, start_s, duration_s}`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub second: Option<serde_json::Value>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SensorRecord {
    pub sensor: String,
    pub bone: String,
    /// `"calibrate"` or `"fixed"`: where the mount came from.
    pub mount_source: &'static str,
    /// q_bone_sensor used, [w, x, y, z].
    pub mount: [f64; 4],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub forward: Option<[f64; 3]>,
    /// Where the sensor's orientation came from: `device` or `fused`.
    pub orientation: &'static str,
    /// The world its orientation was in (a fused one is `enu`).
    pub world: World,
    /// For a sensor without a heading of its own (fused 6D): how calibration aligned it
    /// (`mount`, `forward`, `second-pose`, `hinge`), or `none`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heading_aligned_by: Option<&'static str>,
    /// A `calibrate` mount on a knee's or an elbow's segment, turned about the segment's long
    /// axis so that the hinge flexes about the pose's left–right: the turn, degrees
    /// (anticlockwise seen from above: a left leg turned out, a right leg turned in), and the
    /// hinge axis's uncertainty, degrees.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mount_turned_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mount_turn_uncertainty_deg: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<MappingFile, MappingError> {
        parse_mapping(text, Path::new("m.json"))
    }

    #[test]
    fn the_issue_example_parses() {
        let text = r#"{
          "rig": "mixamo",
          "world": "enu",
          "calibration": {"pose": "rest", "start_s": 0.0, "duration_s": 1.0},
          "sensors": {
            "pelvis": {"bone": "Hips", "mount": "calibrate", "forward": "+x"},
            "N1_0":   {"bone": "RightArm", "mount": "+y-x+z"},
            "s7":     {"bone": "LeftLeg", "mount": [0.7071, 0, 0.7071, 0]}
          }
        }"#;
        let MappingFile::Quaternion(m) = parse(text).unwrap() else {
            panic!("expected a quaternion mapping")
        };
        assert_eq!(m.world, Some(World::Enu));
        assert_eq!(m.sensors.len(), 3);
        assert_eq!(m.sensors[0].sensor, "pelvis");
        assert_eq!(m.sensors[0].mount, Mount::Calibrate);
        assert_eq!(m.sensors[0].forward, Some(Vector3::x()));
        // "+y-x+z": sensor x = bone +y, sensor y = bone -x, sensor z = bone +z: 90° about z.
        let Mount::Fixed(q) = m.sensors[1].mount else {
            panic!()
        };
        assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-12);
        assert!((q * Vector3::y() + Vector3::x()).norm() < 1e-12);
        let Mount::Fixed(q) = m.sensors[2].mount else {
            panic!()
        };
        // 90° about y: x → -z.
        assert!((q * Vector3::x() + Vector3::z()).norm() < 1e-4);
    }

    #[test]
    fn errors_name_file_and_key() {
        let twice = r#"{"sensors": {"a": {"bone": "Hips"}, "a": {"bone": "Spine"}}}"#;
        let e = parse(twice).unwrap_err().to_string();
        assert!(
            e.contains("m.json") && e.contains("`sensors.a`") && e.contains("`a` is mapped twice"),
            "{e}"
        );
        let same_bone = r#"{"sensors": {"a": {"bone": "Hips"}, "b": {"bone": "Hips"}}}"#;
        let e = parse(same_bone).unwrap_err().to_string();
        assert!(
            e.contains("`sensors.b.bone`") && e.contains("already driven by sensor `a`"),
            "{e}"
        );
        let bad_mount = r#"{"sensors": {"a": {"bone": "Hips", "mount": "+x+x+z"}}}"#;
        let e = parse(bad_mount).unwrap_err().to_string();
        assert!(e.contains("`sensors.a.mount`"), "{e}");
        let left = r#"{"sensors": {"a": {"bone": "Hips", "mount": "+x+y-z"}}}"#;
        let e = parse(left).unwrap_err().to_string();
        assert!(e.contains("left-handed"), "{e}");
        let bad_q = r#"{"sensors": {"a": {"bone": "Hips", "mount": [1, 1, 0, 0]}}}"#;
        assert!(
            parse(bad_q)
                .unwrap_err()
                .to_string()
                .contains("unit quaternion")
        );
        let bad_world = r#"{"world": "xyz", "sensors": {"a": {"bone": "Hips"}}}"#;
        assert!(
            parse(bad_world)
                .unwrap_err()
                .to_string()
                .contains("`world`")
        );
        let typo = r#"{"sensors": {"a": {"bone": "Hips", "mout": "calibrate"}}}"#;
        assert!(parse(typo).unwrap_err().to_string().contains("mout"));
        let rig = crate::rig::load_rig("mixamo").unwrap();
        let MappingFile::Quaternion(m) = parse(r#"{"sensors": {"a": {"bone": "Tail"}}}"#).unwrap()
        else {
            panic!()
        };
        let e = m
            .resolve(&rig, Path::new("m.json"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`sensors.a.bone`") && e.contains("unknown bone `Tail`"),
            "{e}"
        );
    }

    /// A bone named with the wrong case is suggested, and the error lists the rig's bones.
    #[test]
    fn an_unknown_bone_suggests_the_nearest_and_lists_the_rig() {
        let rig = crate::rig::load_rig("mixamo").unwrap();
        let text = r#"{"sensors": {"hips": {"bone": "Hips"}, "fa": {"bone": "LeftForearm"}}}"#;
        let MappingFile::Quaternion(m) = parse(text).unwrap() else {
            panic!()
        };
        let e = m
            .resolve(&rig, Path::new("m.json"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(
                "m.json: `sensors.fa.bone`: unknown bone `LeftForearm` in rig `mixamo`; \
                 did you mean `LeftForeArm`? The rig's 22 bones: Hips, Spine, Spine1, Spine2, \
                 Neck, Head, LeftShoulder, LeftArm, LeftForeArm, LeftHand,"
            ),
            "{e}"
        );
        assert!(e.ends_with("RightFoot, RightToeBase"), "{e}");
    }

    /// An empty file, or one that maps no sensor, says what to write.
    #[test]
    fn an_empty_mapping_says_what_to_write() {
        for text in ["", "  \n", r#"{"rig": "mixamo", "sensors": {}}"#] {
            let e = parse(text).unwrap_err().to_string();
            let what = if text.trim().is_empty() {
                "m.json: the file is empty; "
            } else {
                "m.json: `sensors`: no sensors mapped; "
            };
            assert!(e.starts_with(what), "{e}");
            assert!(
                e.contains("map each sensor id of the take to a bone of the rig, e.g. {")
                    && e.contains("mappings/paper000_16imu_mixamo.json"),
                "{e}"
            );
            // The example given is itself a mapping that parses.
            let example = &e[e.find('{').unwrap()..=e.rfind('}').unwrap()];
            assert!(
                matches!(parse(example), Ok(MappingFile::Quaternion(_))),
                "{example}"
            );
        }
    }
}
