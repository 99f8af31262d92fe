//! One converted take written: each output asked for as `<out_dir>/<stem>.*`, side by side, then
//! the sidecar, last, so its appearance means the take is complete.

use super::report::{ReportInput, bone_series};
use super::sidecar::{
    EngineRecord, PipelineRecord, RigRecord, Sidecar, SourceRecord, SubjectRecord,
    VendorContactsRecord,
};
use super::transforms::{OutputTransform, apply_all};
use super::{Engine, Output, OutputError, OutputFormat, TakeOutputs, write_atomic};
use crate::anim::{Animation, AnimationError};
use crate::inspect::SensorSummaries;
use crate::mapping::MappingRecord;
use crate::pipeline::root::Contacts;
use crate::rig::LengthUnit;
use crate::rig::subject::Subject;
use crate::take::{LineReport, Take, VendorContacts};
use crate::world::{World, WorldFrom};
use nalgebra::UnitQuaternion;
use rayon::prelude::*;
use std::io;
use std::path::{Path, PathBuf};

/// A converted take, whichever mode made it: the animation, what the writers need of it, and
/// what the sidecar says of how it was made.
#[derive(Debug, Clone)]
pub struct Conversion {
    pub animation: Animation,
    /// BVH channel values when made already, paper 002's channel copy ([`TakeOutputs::euler_deg`]);
    /// else the BVH writer makes them from the animation's rotations.
    pub euler_deg: Option<Vec<Vec<[f64; 3]>>>,
    /// Local rotations before smoothing, `[joint][frame]`, for the report.
    pub unsmoothed: Option<Vec<Vec<UnitQuaternion<f64>>>>,
    pub mapping: MappingRecord,
    pub pipeline: PipelineRecord,
    /// The feet's contacts, in `feet` root mode.
    pub contacts: Option<Contacts>,
    /// The sensors' world, and where it came from.
    pub world: (World, WorldFrom),
    /// The capture system's own foot contacts, in take time (put on the written frames, after
    /// the output transforms, by [`write_take`]).
    pub vendor_contacts: Option<VendorContacts>,
    pub warnings: Vec<String>,
}

/// What the sidecar and the report keep of a take once its samples are dropped.
#[derive(Debug, Clone, Default)]
pub struct TakeFacts {
    pub sensor_summaries: SensorSummaries,
    /// The take's warnings, then the conversion's.
    pub warnings: Vec<String>,
    pub dropped_lines: Vec<LineReport>,
    pub repaired_lines: Vec<LineReport>,
}

impl TakeFacts {
    /// The take's own facts; the conversion's warnings are added after them.
    pub fn of(take: &Take) -> TakeFacts {
        TakeFacts {
            sensor_summaries: SensorSummaries::of(take),
            warnings: take.warnings().to_vec(),
            dropped_lines: take.dropped_lines().to_vec(),
            repaired_lines: take.repaired_lines().to_vec(),
        }
    }
}

/// A capture system's contacts on the written frames: frame n stands at take time
/// (n − bind + first) / fps, where `first` is the grid frame `--trim` made frame 0 and `bind` is 1
/// with `--bind-frame` (whose frame 0, the rest pose, has no contact).
fn vendor_contacts_record(v: &VendorContacts, conversion: &Conversion) -> VendorContactsRecord {
    let fps = conversion.animation.fps();
    let first = conversion
        .pipeline
        .trim
        .as_ref()
        .map_or(0, |t| t.first_frame);
    let bind = usize::from(conversion.pipeline.bind_frame);
    let planted: Vec<[bool; 2]> = (0..conversion.animation.frames())
        .map(|n| match n.checked_sub(bind) {
            Some(k) => v.at(fps.frame_time_of((k + first) as u64)),
            None => [false; 2],
        })
        .collect();
    // Every run, however short: the system's own contacts, as it gave them.
    let runs = |side: usize| crate::pipeline::root::runs(planted.iter().map(|p| p[side]), 1);
    VendorContactsRecord {
        vendor: v.vendor,
        left: runs(0),
        right: runs(1),
    }
}

/// The subject file a rig was scaled to, for the sidecar.
#[derive(Debug, Clone, Copy)]
pub struct SubjectFile<'a> {
    pub path: &'a Path,
    pub sha256: &'a str,
    pub subject: &'a Subject,
}

/// How one take is written: where, which outputs, and what the sidecar says of its source.
#[derive(Debug, Clone)]
pub struct TakeJob<'a> {
    /// The take's source, named in the report; its stem names the outputs.
    pub input: &'a Path,
    pub out_dir: &'a Path,
    /// Each output once, in order (the report last).
    pub outputs: &'a [Output],
    /// Length unit of the BVH (glTF is always metres).
    pub units: LengthUnit,
    /// The smoothing, as the report describes it.
    pub smoothing: String,
    pub subject: Option<SubjectFile<'a>>,
    pub source: SourceRecord,
    pub facts: TakeFacts,
    /// Applied to the conversion, in order, before anything is written.
    pub transforms: Vec<OutputTransform>,
    /// Whose import settings go beside the glTF outputs (`--engine`).
    pub engine: Option<Engine>,
}

/// Why a take was not written.
#[derive(Debug, thiserror::Error)]
pub enum TakeError {
    /// An output transform failed; no file was touched.
    #[error(transparent)]
    Transform(#[from] AnimationError),
    #[error(transparent)]
    Output(#[from] OutputError),
}

/// What a take's writing left: the sidecar and where it is.
#[derive(Debug, Clone)]
pub struct WrittenTake {
    pub sidecar: Sidecar,
    pub sidecar_path: PathBuf,
}

/// Writes each output of `job` as `<out_dir>/<stem>.*`, then the sidecar, last; the output
/// transforms first (their failure touches no file).
pub fn write_take(job: TakeJob<'_>, conversion: Conversion) -> Result<WrittenTake, TakeError> {
    let TakeJob {
        input,
        out_dir,
        outputs,
        units,
        smoothing,
        subject,
        source,
        facts,
        transforms,
        engine,
    } = job;
    let conversion = apply_all(conversion, &transforms)?;
    let vendor_contacts = conversion
        .vendor_contacts
        .as_ref()
        .map(|v| vendor_contacts_record(v, &conversion));
    let stem = crate::read::take_stem(input);
    std::fs::create_dir_all(out_dir).map_err(|source| OutputError::Write {
        path: out_dir.to_path_buf(),
        source,
    })?;
    // A sidecar left by an earlier conversion would claim a complete take while its outputs are
    // being replaced, and after a failure: it goes before any output is touched.
    let old_sidecar = out_dir.join(format!("{stem}.imubake.json"));
    if let Err(source) = std::fs::remove_file(&old_sidecar)
        && source.kind() != io::ErrorKind::NotFound
    {
        return Err(OutputError::Write {
            path: old_sidecar,
            source,
        }
        .into());
    }
    let TakeFacts {
        sensor_summaries,
        warnings,
        dropped_lines,
        repaired_lines,
    } = facts;
    let animation = &conversion.animation;
    let source_text = input.to_string_lossy();
    let take_outputs = TakeOutputs {
        stem: &stem,
        animation,
        euler_deg: conversion.euler_deg.as_deref(),
        units,
        report: outputs.contains(&Output::Report).then(|| ReportInput {
            take: &stem,
            source: &source_text,
            fps: animation.fps().to_string(),
            smoothing,
            bones: bone_series(
                animation,
                conversion.unsmoothed.as_deref(),
                conversion.euler_deg.as_deref(),
            ),
            sensors: &sensor_summaries,
            warnings: &warnings,
            dropped_lines: dropped_lines.len(),
            fusion: conversion
                .pipeline
                .fusion
                .as_ref()
                .map(|f| f.sensors.iter().map(|(id, s)| (id.as_str(), s)).collect())
                .unwrap_or_default(),
        }),
    };
    // Each output is its own file: written side by side (the BVH's formatting and the GLB's
    // buffer share the cores), their records kept in the settings' order.
    let written: Vec<_> = outputs
        .par_iter()
        .map(|output| {
            let _span = match output {
                Output::Animation(OutputFormat::Bvh) => tracing::debug_span!("write bvh"),
                Output::Animation(OutputFormat::Glb) => tracing::debug_span!("write glb"),
                Output::Animation(OutputFormat::Gltf) => tracing::debug_span!("write gltf"),
                Output::Report => tracing::debug_span!("write report"),
            }
            .entered();
            output.write(out_dir, &take_outputs)
        })
        .collect();
    let outputs = written.into_iter().collect::<Result<Vec<_>, _>>()?;
    drop(take_outputs);
    let engine = match engine {
        None => None,
        Some(Engine::Godot) => Some(EngineRecord::Godot(super::godot::write_imports(
            out_dir, &outputs, animation,
        )?)),
    };
    let (dropped_lines, dropped_lines_total, dropped_lines_omitted) =
        Sidecar::bound_dropped(dropped_lines);
    let out_rig = animation.rig();
    let sidecar = Sidecar {
        imubake_version: env!("CARGO_PKG_VERSION"),
        source,
        fps: animation.fps(),
        frames: animation.frames(),
        duration_s: animation.duration_s(),
        rig: RigRecord {
            name: out_rig.name().to_string(),
            units: units.name(),
            bones: out_rig.len(),
            subject: subject.map(|s| SubjectRecord {
                path: s.path.display().to_string(),
                sha256: s.sha256.to_string(),
                subject: s.subject.clone(),
                standing_height_m: animation.standing_height() * out_rig.units().metres_per_unit(),
            }),
        },
        mapping: conversion.mapping,
        pipeline: conversion.pipeline,
        contacts: conversion.contacts,
        vendor_contacts,
        outputs,
        engine,
        sensors: sensor_summaries,
        dropped_lines,
        dropped_lines_total,
        dropped_lines_omitted,
        repaired_lines,
        warnings,
    };
    let sidecar_path = out_dir.join(format!("{stem}.imubake.json"));
    let json = serde_json::to_vec_pretty(&sidecar).expect("the sidecar serialises");
    write_atomic(&sidecar_path, |w| {
        w.write_all(&json)?;
        w.write_all(b"\n")
    })
    .map_err(|source| OutputError::Write {
        path: sidecar_path.clone(),
        source,
    })?;
    Ok(WrittenTake {
        sidecar,
        sidecar_path,
    })
}
