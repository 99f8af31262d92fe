//! The sidecar `<stem>.imubake.json` (conventions.md): exactly what was done to a take. Its
//! field names are a contract read by the Blender add-on and scripts.

use crate::fps::Fps;
use crate::inspect::SensorSummaries;
use crate::mapping::HeadingPolicy;
use crate::mapping::MappingRecord;
use crate::mapping::{CalibrationRecord, Mapping, Mount, SensorRecord};
use crate::pipeline::calibrate::Calibration;
use crate::pipeline::sources::Origin;
use crate::pipeline::{self, PipelineOptions, root::RootMode};
use crate::rig::Rig;
use crate::take::{DroppedLines, LineReport};
use serde::Serialize;
use std::path::Path;

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
    /// The first [`DroppedLines::KEEP`] dropped lines, whole ([`Sidecar::bound_dropped`]).
    pub dropped_lines: Vec<LineReport>,
    /// Every dropped line, listed or not.
    pub dropped_lines_total: u64,
    /// The dropped lines past those listed, counted by reason; absent when all are listed.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub dropped_lines_omitted: Vec<OmittedRecord>,
    pub repaired_lines: Vec<LineReport>,
    pub warnings: Vec<String>,
}

/// Dropped lines of one reason past those listed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OmittedRecord {
    pub reason: String,
    pub lines: u64,
}

impl Sidecar {
    /// A take's dropped lines as the sidecar holds them: the first [`DroppedLines::KEEP`] whole,
    /// the rest counted by reason (a source of a million garbage lines gives a sidecar of
    /// kilobytes, not of a hundred megabytes); with the total.
    pub fn bound_dropped(all: Vec<LineReport>) -> (Vec<LineReport>, u64, Vec<OmittedRecord>) {
        let total = all.len() as u64;
        if all.len() <= DroppedLines::KEEP {
            return (all, total, Vec::new());
        }
        let mut bounded = DroppedLines::default();
        for r in all {
            bounded.push(r);
        }
        let omitted = bounded
            .omitted_by_reason()
            .iter()
            .map(|(reason, lines)| OmittedRecord {
                reason: reason.clone(),
                lines: *lines,
            })
            .collect();
        (bounded.reports().to_vec(), total, omitted)
    }
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
    /// The heading's estimated uncertainty, degrees; `null` when it is unknown
    /// (`crate::pipeline::calibrate`'s module docs give the estimates).
    pub heading_uncertainty_deg: Option<f64>,
    /// `estimate` (from the take, refused when unsure) or `sensors` (the sensors' north kept
    /// deliberately).
    pub heading_policy: &'static str,
    /// Every source's look at the heading and whether it agreed with the others (those that
    /// did are combined into `heading_deg`); empty without any.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub heading_looks: Vec<HeadingLookRecord>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trim: Option<TrimRecord>,
    /// `"quaternion"`, or `"legacy-euler"` for paper 002's Listing-2 mappings.
    pub mode: Mode,
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

/// How a take becomes an animation (the sidecar's `pipeline.mode`): one module of `convert/`
/// each, in the order `convert::Plan::mode_for` chooses them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// A BVH take: its motion retargeted onto the rig (`convert/bvh_retarget.rs`).
    BvhRetarget,
    /// `--mvnx-segments`: Xsens's own segment kinematics (`convert/mvnx_segments.rs`).
    MvnxSegments,
    /// Paper 002's Euler-channel mode, for a Listing-2 mapping (`convert/euler.rs`).
    Euler,
    /// Sensor orientations through the quaternion pipeline (`convert/orientations.rs`).
    Orientations,
}

impl Mode {
    /// Every mode, in the order `convert::Plan::mode_for` tries them.
    pub const ALL: [Mode; 4] = [
        Mode::BvhRetarget,
        Mode::MvnxSegments,
        Mode::Euler,
        Mode::Orientations,
    ];

    /// The sidecar's `pipeline.mode`.
    pub fn label(self) -> &'static str {
        match self {
            Mode::BvhRetarget => "bvh-retarget",
            Mode::MvnxSegments => "mvnx-segments",
            Mode::Euler => "legacy-euler",
            Mode::Orientations => "quaternion",
        }
    }
}

impl Serialize for Mode {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.label())
    }
}

/// The sidecar's `mapping` for the quaternion pipeline: each sensor's bone, mount and source.
pub fn mapping_record(
    converted: &pipeline::Converted,
    rig: &Rig,
    mapping: &Mapping,
    file: Option<&Path>,
) -> MappingRecord {
    MappingRecord {
        file: file.map(|f| f.to_string_lossy().into_owned()),
        rig: rig.name().to_string(),
        world: converted.world,
        calibration: converted.window.as_ref().map(|w| CalibrationRecord {
            pose: w.pose.label(),
            start_s: w.start_s,
            duration_s: w.duration_s,
            second: w.second.as_ref().map(|p| {
                serde_json::json!({"pose": p.pose.label(), "start_s": p.start_s, "duration_s": p.duration_s})
            }),
        }),
        sensors: converted
            .sensors
            .iter()
            .zip(&converted.calibration.mounts)
            .zip(converted.origins.iter().zip(&converted.calibration.alignment))
            .map(|((s, q), (origin, alignment))| SensorRecord {
                sensor: s.sensor.clone(),
                bone: rig.joints()[s.bone].name.clone(),
                mount_source: match s.mount {
                    Mount::Calibrate => "calibrate",
                    Mount::Fixed(_) => "fixed",
                },
                mount: [q.w, q.i, q.j, q.k],
                forward: mapping
                    .sensors
                    .iter()
                    .find(|m| m.sensor == s.sensor)
                    .and_then(|m| m.forward)
                    .map(|v| [v.x, v.y, v.z]),
                orientation: match origin {
                    Origin::Device { .. } => "device",
                    Origin::Fused(_) => "fused",
                },
                world: origin.world(),
                heading_aligned_by: alignment.label(),
            })
            .collect(),
        legacy: None,
    }
}

/// The sidecar's `pipeline.fusion`: `None` when no sensor was fused. `chosen`: the settings
/// asked for the filter (else the default ran); `sensor_calibration`: the file of corrections.
pub fn fusion_record(
    converted: &pipeline::Converted,
    chosen: bool,
    sensor_calibration: Option<FileRecord>,
) -> Option<FusionRecord> {
    let fusion = converted.fusion.clone()?;
    let sensors = converted
        .sensors
        .iter()
        .zip(&converted.origins)
        .filter_map(|(s, origin)| match origin {
            Origin::Fused(stats) => Some((s.sensor.clone(), stats.clone())),
            Origin::Device { .. } => None,
        })
        .collect();
    Some(FusionRecord {
        fusion,
        chosen_by: if chosen { "settings" } else { "default" },
        sensor_calibration,
        sensors,
    })
}

/// One source's look at the heading, in the sidecar.
#[derive(Debug, Clone, Serialize)]
pub struct HeadingLookRecord {
    pub source: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor: Option<String>,
    pub heading_deg: f64,
    pub uncertainty_deg: f64,
    pub agrees: bool,
}

/// The sidecar's `pipeline`: what was done, in which mode.
/// `heading`: the calibration's, `None` for modes without one (the sidecar says `none`).
pub fn pipeline_record(
    options: &PipelineOptions,
    heading: Option<(&Calibration, HeadingPolicy)>,
    first_frame: usize,
    mode: Mode,
    root: RootMode,
) -> PipelineRecord {
    PipelineRecord {
        fusion: None,
        smoothing: Some(serde_json::to_value(&options.smoothing).expect("serialisable")),
        root: root.label(),
        unsensed: if mode == Mode::Euler {
            "rest"
        } else {
            options.unsensed.label()
        },
        heading: heading.map_or("none", |(c, _)| c.heading_source.label()),
        heading_sensor: heading.and_then(|(c, _)| c.heading_source.sensor().map(str::to_string)),
        heading_deg: heading.map_or(0.0, |(c, _)| c.heading.scaled_axis().y.to_degrees()),
        heading_uncertainty_deg: heading
            .map(|(c, _)| c.heading_uncertainty_deg)
            .filter(|u| u.is_finite()),
        heading_policy: heading.map_or("none", |(_, p)| p.label()),
        heading_looks: heading.map_or_else(Vec::new, |(c, _)| {
            c.heading_looks
                .iter()
                .map(|l| HeadingLookRecord {
                    source: l.source.label(),
                    sensor: l.source.sensor().map(str::to_string),
                    heading_deg: l.heading_deg,
                    uncertainty_deg: l.uncertainty_deg,
                    agrees: l.agrees,
                })
                .collect()
        }),
        trim: options.trim.map(|t| TrimRecord {
            start_s: t.start_s,
            end_s: (t.end_s < f64::MAX).then_some(t.end_s),
            first_frame,
        }),
        mode,
        causal: options.causal,
        bind_frame: false,
        in_place: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dropped_lines_past_the_first_thousand_are_counted_by_reason() {
        let few: Vec<LineReport> = (1..=3)
            .map(|i| LineReport::new(None, i, "bad", b"x"))
            .collect();
        let (listed, total, omitted) = Sidecar::bound_dropped(few.clone());
        assert_eq!((listed, total, omitted), (few, 3, Vec::new()));
        let many: Vec<LineReport> = (1..=1500)
            .map(|i| {
                let reason = if i % 3 == 0 {
                    "time out of sequence: x"
                } else {
                    "garbage"
                };
                LineReport::new(None, i, reason, b"x")
            })
            .collect();
        let (listed, total, omitted) = Sidecar::bound_dropped(many);
        assert_eq!(listed.len(), 1000);
        assert_eq!(listed[999].line, 1000);
        assert_eq!(total, 1500);
        // Lines 1001..=1500: 167 multiples of 3 (1002, …, 1500), 333 others; 1001 comes first.
        let record = |reason: &str, lines| OmittedRecord {
            reason: reason.into(),
            lines,
        };
        assert_eq!(
            omitted,
            [record("garbage", 333), record("time out of sequence", 167)]
        );
    }
}
