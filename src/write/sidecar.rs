//! The sidecar `<stem>.imubake.json` (conventions.md): exactly what was done to a take. Its
//! field names are a contract read by the Blender add-on and scripts.

use crate::fps::Fps;
use crate::inspect::SensorSummaries;
use crate::mapping::MappingRecord;
use crate::take::LineReport;
use serde::Serialize;

#[derive(Debug, Clone, Serialize)]
pub struct Sidecar {
    pub imubake_version: &'static str,
    pub source: SourceRecord,
    pub fps: Fps,
    pub frames: usize,
    /// (frames − 1) / fps.
    pub duration_s: f64,
    pub rig: RigRecord,
    pub mapping: MappingRecord,
    pub pipeline: PipelineRecord,
    /// Foot contacts and airborne stretches as frame intervals `[start, end]` (inclusive), in
    /// `feet` root mode; `null` otherwise.
    pub contacts: Option<crate::pipeline::root::Contacts>,
    /// The capture system's own foot contacts (Xsens MVN's `footContacts`), on the same frames,
    /// for comparison with `contacts`; absent when the source has none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vendor_contacts: Option<VendorContactsRecord>,
    pub outputs: Vec<OutputRecord>,
    pub sensors: SensorSummaries,
    pub dropped_lines: Vec<LineReport>,
    pub repaired_lines: Vec<LineReport>,
    pub warnings: Vec<String>,
}

/// A capture system's own foot contacts as frame intervals `[start, end]` (inclusive) of the
/// written animation: a foot is planted at frame n when the system said so at its latest sample
/// at or before frame n's time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VendorContactsRecord {
    /// Whose: `xsens`.
    pub vendor: &'static str,
    pub left: Vec<[usize; 2]>,
    pub right: Vec<[usize; 2]>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SourceRecord {
    pub path: String,
    pub sha256: String,
    pub format: crate::take::InputFormat,
    /// The world the sensors were read in (the mapping's `world` when it overrides the format's).
    pub world: crate::world::World,
    /// Where the world came from: `flag`, `config`, `mapping` or `format`.
    pub world_from: crate::world::WorldFrom,
    pub start_timestamp: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct RigRecord {
    pub name: String,
    /// Length unit of the written BVH (glTF is always metres).
    pub units: &'static str,
    pub bones: usize,
    /// The subject the rig was scaled to (`--subject`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub subject: Option<SubjectRecord>,
}

/// A subject file: where, its content's hash, its measurements and the standing height they gave.
#[derive(Debug, Clone, Serialize)]
pub struct SubjectRecord {
    pub path: String,
    pub sha256: String,
    #[serde(flatten)]
    pub subject: crate::rig::subject::Subject,
    pub standing_height_m: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct PipelineRecord {
    /// `null` when no sensor was fused.
    pub fusion: Option<FusionRecord>,
    pub smoothing: Option<serde_json::Value>,
    pub root: &'static str,
    /// What joints without a sensor did: `interpolate` or `rest`.
    pub unsensed: &'static str,
    pub heading: &'static str,
    /// The sensor whose forward axis or mount gave the heading.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heading_sensor: Option<String>,
    /// Heading applied about +Y, degrees.
    pub heading_deg: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trim: Option<TrimRecord>,
    /// `"quaternion"`, or `"legacy-euler"` for paper 002's Listing-2 mappings.
    pub mode: &'static str,
    /// Causal mode: the take ran through the stream's stages.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub causal: bool,
    /// Frame 0 is the rig's rest pose and the take starts at frame 1 (`--bind-frame`).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub bind_frame: bool,
    /// The rig's first joint is a `root` at floor level carrying the hips' horizontal motion
    /// (`--in-place`); the hips below it keep their horizontal place.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub in_place: bool,
}

/// How raw readings were fused: the filter with every parameter (`method`, then its own keys, and
/// `six_d` when the magnetometer was left out), whether it was asked for (`--fusion`, the config)
/// or the default for sensors with raw readings only, and per fused sensor what it came to.
#[derive(Debug, Clone, Serialize)]
pub struct FusionRecord {
    #[serde(flatten)]
    pub fusion: crate::fusion::Fusion,
    /// `settings` (`--fusion`, the config's `fusion`) or `default`.
    pub chosen_by: &'static str,
    /// The sensor calibration file applied before fusion (`--sensor-calibration`); each sensor's
    /// `corrections` say which of its kinds ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor_calibration: Option<FileRecord>,
    pub sensors: std::collections::BTreeMap<String, crate::fusion::FusionStats>,
}

/// A file by path and content.
#[derive(Debug, Clone, Serialize)]
pub struct FileRecord {
    pub path: String,
    pub sha256: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct TrimRecord {
    pub start_s: f64,
    pub end_s: Option<f64>,
    /// Frame of the untrimmed grid that became frame 0.
    pub first_frame: usize,
}

#[derive(Debug, Clone, Serialize)]
pub struct OutputRecord {
    pub format: &'static str,
    pub path: String,
}
