//! The orientations mode: sensors' orientations (from the device, or fused) through the
//! quaternion pipeline ([`pipeline::run_owned`]), with the plan's mapping, or with the sensors
//! driving the rig's bones named like them.

use super::error::ConvertError;
use super::plan::{Plan, PlanMapping};
use crate::mapping::Mapping;
use crate::pipeline;
use crate::pipeline::record::FileRecord;
use crate::take::Take;
use crate::world::{World, WorldFrom};
use crate::write::take::Conversion;
use std::path::Path;

/// The take through the quaternion pipeline onto the plan's rig.
pub(super) fn convert(input: &Path, take: Take, plan: &Plan) -> Result<Conversion, ConvertError> {
    // Sensors matched to bones by name carry no world of their own.
    let mapping_world = match plan.mapping() {
        PlanMapping::Quaternion(m) => m.value.world,
        PlanMapping::ByName | PlanMapping::Euler(_) => None,
    };
    let (world, world_from) = resolve_world(&take, plan, mapping_world);
    let by_name;
    let (mapping, file) = match plan.mapping() {
        PlanMapping::Quaternion(m) => (&m.value, Some(m.path.as_path())),
        PlanMapping::ByName => {
            let ids: Vec<&str> = take.sensors().iter().map(|s| s.id()).collect();
            by_name =
                Mapping::by_name(plan.rig(), &ids).ok_or_else(|| ConvertError::NoMapping {
                    input: input.to_path_buf(),
                    rig: plan
                        .settings()
                        .rig
                        .clone()
                        .unwrap_or_else(|| "mixamo".into()),
                    sensors: ids.join(", "),
                })?;
            (&by_name, None)
        }
        PlanMapping::Euler(_) => unreachable!("a Listing-2 mapping converts in the Euler mode"),
    };
    let mut options = plan.pipeline().clone();
    options.world = Some(world);
    let mut recorded =
        pipeline::run_owned(take, plan.rig(), mapping, file, &options).map_err(|source| {
            ConvertError::Pipeline {
                input: input.to_path_buf(),
                source,
            }
        })?;
    if let Some(fusion) = &mut recorded.pipeline.fusion {
        fusion.sensor_calibration = plan.sensor_calibration().map(|c| FileRecord {
            path: c.path.display().to_string(),
            sha256: c.sha256.clone(),
        });
    }
    let converted = recorded.converted;
    Ok(Conversion {
        euler_deg: None,
        mapping: recorded.mapping,
        pipeline: recorded.pipeline,
        contacts: converted.contacts,
        world: (converted.world, world_from),
        vendor_contacts: None,
        unsmoothed: converted.unsmoothed,
        warnings: converted.warnings,
        animation: converted.animation,
    })
}

/// The world of a take's sensors and where it came from: `--world` or the config file's (which
/// the reader already applied), else the mapping's, else the format's own.
pub(super) fn resolve_world(
    take: &Take,
    plan: &Plan,
    mapping_world: Option<World>,
) -> (World, WorldFrom) {
    let settings = plan.settings();
    match (settings.read.world, mapping_world) {
        (Some(w), _) => (w, settings.world_from.unwrap_or(WorldFrom::Flag)),
        (None, Some(w)) => (w, WorldFrom::Mapping),
        (None, None) => (take.source().world, WorldFrom::Format),
    }
}
