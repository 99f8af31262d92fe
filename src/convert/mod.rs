//! One take from capture to outputs, under a [`Plan`] resolved once per command:
//!
//! ```text
//! plan ── mode_for(input) ──▶ bvh_retarget │ mvnx_segments │ euler │ orientations ──▶ Conversion
//!      ──▶ write::take: output transforms (--in-place, --bind-frame), outputs, sidecar last
//! ```
//!
//! Each mode is a module of its own; every mode yields one [`Conversion`], so there is one
//! output path.

mod bvh_retarget;
mod error;
mod euler;
mod hash;
mod mvnx_segments;
mod orientations;
pub mod plan;
pub mod settings;
mod skeleton;

pub use crate::write::transforms::OutputTransform;
pub use error::ConvertError;
pub use hash::source_sha256;
pub use plan::{Mode, Plan};
pub use settings::{ConvertSettings, Given, Layer, Output, OutputFormat};

use crate::anim::Animation;
pub use crate::read::take_stem;
use crate::take::Take;
use crate::write::remove_take_outputs;
use crate::write::sidecar::{FileRecord, SourceRecord};
use crate::write::take::{
    Conversion, SubjectFile, TakeError, TakeFacts, TakeJob, WrittenTake, write_take,
};
use crate::write::transforms::apply_all;
use std::path::Path;

/// What a conversion wrote: the sidecar and where it is.
pub type ConvertOutcome = WrittenTake;

/// Converts one take into `out_dir`. A failure after the outputs were started (a full disk, say)
/// removes every output of the take, the sidecar first, so no partial take is left behind; a
/// failure before that leaves an earlier conversion's outputs as they were.
pub fn convert(input: &Path, out_dir: &Path, plan: &Plan) -> Result<ConvertOutcome, ConvertError> {
    convert_unclean(input, out_dir, plan).inspect_err(|e| {
        if matches!(e, ConvertError::Output(_)) {
            remove_take_outputs(out_dir, &take_stem(input));
        }
    })
}

fn convert_unclean(
    input: &Path,
    out_dir: &Path,
    plan: &Plan,
) -> Result<ConvertOutcome, ConvertError> {
    // All the writing needs of the plan, taken before the conversion: the settings go down
    // once, and nothing comes back up for them afterwards.
    let settings = plan.settings();
    let outputs = settings.outputs();
    let (units, smoothing, transforms) = (
        settings.units,
        plan.pipeline().smoothing.describe(),
        plan.transforms(),
    );
    let subject = plan.subject().map(|s| SubjectFile {
        path: &s.path,
        sha256: &s.sha256,
        subject: &s.value,
    });
    let mode = plan.mode_for(input);
    let (conversion, source, facts) = match mode {
        Mode::BvhRetarget => {
            let (conversion, source) = bvh_retarget::convert(input, plan)?;
            let facts = TakeFacts {
                warnings: conversion.warnings.clone(),
                ..TakeFacts::default()
            };
            (conversion, source, facts)
        }
        Mode::MvnxSegments => {
            let mvnx = mvnx_segments::convert(input, plan)?;
            let mut conversion = mvnx.conversion;
            conversion.vendor_contacts = mvnx.contacts;
            let facts = TakeFacts {
                warnings: conversion.warnings.clone(),
                dropped_lines: mvnx.dropped,
                ..TakeFacts::default()
            };
            (conversion, mvnx.source, facts)
        }
        Mode::Euler | Mode::Orientations => {
            let read_span = tracing::debug_span!("read and hash").entered();
            let (take, sha256) = hash::read_and_hash(input, plan.read_options())?;
            drop(read_span);
            // What the sidecar and the report keep of the take; the pipeline then consumes it,
            // so its samples are never held twice and are freed before the outputs are built.
            let mut facts = TakeFacts::of(&take);
            let vendor_contacts = take.vendor_contacts().cloned();
            let source_info = take.source().clone();
            let mut conversion = of_take(input, take, mode, plan)?;
            facts.warnings.extend(conversion.warnings.iter().cloned());
            conversion.vendor_contacts = vendor_contacts;
            let source = SourceRecord {
                path: input.to_string_lossy().into_owned(),
                sha256,
                format: source_info.format,
                world: conversion.world.0,
                world_from: conversion.world.1,
                start_timestamp: source_info.start_timestamp,
                layout: plan.layout().map(|(path, sha256)| FileRecord {
                    path: path.display().to_string(),
                    sha256: sha256.to_string(),
                }),
            };
            (conversion, source, facts)
        }
    };
    let job = TakeJob {
        input,
        out_dir,
        outputs: &outputs,
        units,
        smoothing,
        subject,
        source,
        facts,
        transforms,
        engine: plan.settings().engine,
    };
    write_take(job, conversion).map_err(|e| match e {
        TakeError::Output(e) => ConvertError::Output(e),
        TakeError::Transform(source) => transform_error(input, source),
    })
}

fn transform_error(input: &Path, source: crate::anim::AnimationError) -> ConvertError {
    ConvertError::Pipeline {
        input: input.to_path_buf(),
        source: source.into(),
    }
}

/// A take read into memory, converted in `mode` (the Euler mode or the orientations).
fn of_take(input: &Path, take: Take, mode: Mode, plan: &Plan) -> Result<Conversion, ConvertError> {
    match mode {
        Mode::Euler => euler::convert(input, &take, plan),
        _ => orientations::convert(input, take, plan),
    }
}

/// The animation of one take, as `convert` would write it, without writing anything (for
/// `imubake angles` and `compare` on a capture).
pub fn animate(input: &Path, plan: &Plan) -> Result<Animation, ConvertError> {
    let mode = plan.mode_for(input);
    let conversion = if mode == Mode::BvhRetarget {
        bvh_retarget::convert(input, plan)?.0
    } else {
        let take = crate::read::read_take(input, plan.read_options())?;
        of_take(input, take, mode, plan)?
    };
    apply_all(conversion, &plan.transforms())
        .map(|c| c.animation)
        .map_err(|e| transform_error(input, e))
}
