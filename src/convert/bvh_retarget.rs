//! The BVH-retarget mode: a BVH take's motion retargeted onto the plan's rig
//! ([`crate::retarget`]) at the plan's rate.

use super::error::ConvertError;
use super::hash::hex;
use super::plan::{Mode, Plan};
use super::skeleton::{Motion, Retargeted, retarget_onto_rig};
use crate::world::{World, WorldFrom};
use crate::write::sidecar::SourceRecord;
use crate::write::take::Conversion;
use sha2::{Digest, Sha256};
use std::io;
use std::path::Path;

/// The conversion, and what the sidecar says of its source.
pub(super) fn convert(
    input: &Path,
    plan: &Plan,
) -> Result<(Conversion, SourceRecord), ConvertError> {
    let io_fail = |source| ConvertError::Source {
        input: input.to_path_buf(),
        source,
    };
    // Read as it comes and hashed on the way: the file is never held whole (its lines are held
    // to the reader's limit), and the hash covers every byte, the reader's unread tail included.
    let file = std::fs::File::open(input).map_err(io_fail)?;
    let mut hasher = Sha256::new();
    let mut observe = |bytes: &[u8]| hasher.update(bytes);
    let mut source = crate::read::blocks::Observed {
        inner: std::io::BufReader::with_capacity(1 << 16, file),
        observe: &mut observe,
    };
    let bvh = crate::bvh::read(&mut source).map_err(|source| ConvertError::Bvh {
        input: input.to_path_buf(),
        source,
    })?;
    io::copy(&mut source, &mut io::sink()).map_err(io_fail)?;
    drop(source);
    let sha256 = hex(&hasher.finalize());
    let source_fps = crate::fps::Fps::from_frame_time_s(bvh.frame_time_s()).ok_or_else(|| {
        ConvertError::FrameTime {
            input: input.to_path_buf(),
            frame_time_s: bvh.frame_time_s(),
        }
    })?;
    let source = crate::retarget::SourceMotion::of_bvh(&bvh, source_fps);
    drop(bvh);
    let Retargeted {
        animation,
        pairs,
        warnings,
    } = retarget_onto_rig(input, &source, plan, plan.settings().bvh_reference)?;
    let record = SourceRecord {
        path: input.to_string_lossy().into_owned(),
        sha256,
        format: crate::take::InputFormat::Bvh,
        world: World::Rig,
        world_from: WorldFrom::Format,
        start_timestamp: "0 s".to_string(),
        layout: None,
    };
    let motion = Motion {
        animation,
        pairs,
        orientation: "bvh",
        world: World::Rig,
        mode: Mode::BvhRetarget,
        warnings,
    };
    let mut conversion = motion.conversion(plan);
    conversion.pipeline.bvh_reference = Some(plan.settings().bvh_reference.to_string());
    Ok((conversion, record))
}
