//! Paper 002's Euler-channel mode for a Listing-2 mapping ([`pipeline::legacy`]): the signed
//! yaw/pitch/roll channel copy onto the plan's rig (default `mixamo`), parents from Table 1 (the
//! `sou12` rig), every joint written with BVH channels `Zrotation Yrotation Xrotation` (Blender's
//! `XYZ` mode), the root fixed at rest (unless `--root` names another mode). Sidecar:
//! `pipeline.mode = "legacy-euler"`, `pipeline.heading = "none"`, `mapping.legacy` lists each
//! target.

use super::error::ConvertError;
use super::orientations::resolve_world;
use super::plan::{Mode, Plan, PlanMapping};
use crate::mapping::{LegacyTargetRecord, MappingRecord};
use crate::pipeline;
use crate::pipeline::record::pipeline_record;
use crate::take::Take;
use crate::write::take::Conversion;
use std::path::Path;

pub(super) fn convert(input: &Path, take: &Take, plan: &Plan) -> Result<Conversion, ConvertError> {
    let (PlanMapping::Euler(mapping), Some(table1)) = (plan.mapping(), plan.table1()) else {
        unreachable!("the Euler mode is chosen for a Listing-2 mapping, with Table 1 loaded")
    };
    let legacy = pipeline::legacy::run(
        take,
        plan.rig(),
        table1,
        &mapping.value,
        &mapping.path,
        plan.pipeline(),
    )
    .map_err(|source| ConvertError::Pipeline {
        input: input.to_path_buf(),
        source,
    })?;
    let world = resolve_world(take, plan, None);
    let out_rig = legacy.animation.rig();
    Ok(Conversion {
        mapping: MappingRecord {
            file: Some(mapping.path.to_string_lossy().into_owned()),
            rig: out_rig.name().to_string(),
            world: world.0,
            calibration: None,
            sensors: Vec::new(),
            legacy: Some(
                legacy
                    .targets
                    .iter()
                    .map(|t| LegacyTargetRecord::new(&t.target, t.parent.clone()))
                    .collect(),
            ),
        },
        pipeline: pipeline_record(
            plan.pipeline(),
            None,
            legacy.first_frame,
            Mode::Euler,
            legacy.root_mode,
        ),
        contacts: legacy.contacts,
        world,
        vendor_contacts: None,
        unsmoothed: None,
        warnings: legacy.warnings,
        euler_deg: Some(legacy.euler_deg),
        animation: legacy.animation,
    })
}
