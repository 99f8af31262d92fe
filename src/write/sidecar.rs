//! The sidecar `<stem>.imubake.json` (conventions.md): exactly what was done to a take. Its
//! field names are a contract read by the Blender add-on and scripts.

use crate::fps::Fps;
use crate::inspect::SensorSummaries;
use crate::mapping::MappingRecord;
pub use crate::pipeline::record::{
    FileRecord, FusionRecord, HeadingLookRecord, Mode, PipelineRecord, TrimRecord,
};
use crate::take::{DroppedLines, LineReport};
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
    /// What `--engine` wrote beside the outputs for the engine's importer; absent without it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub engine: Option<EngineRecord>,
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
    /// The packet layout the capture was read through (`--layout`): its path and SHA-256.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub layout: Option<FileRecord>,
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

/// An engine's import files and what its importer will make of the take, tagged by `name`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "name", rename_all = "lowercase")]
pub enum EngineRecord {
    Godot(super::godot::GodotRecord),
}

#[derive(Debug, Clone, Serialize)]
pub struct OutputRecord {
    pub format: &'static str,
    pub path: String,
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
