//! What the two skeleton modes share (a BVH's motion, Xsens's segments): the motion paired with
//! the plan's rig and retargeted, and the conversion the sidecar records for it.

use super::error::ConvertError;
use super::plan::{Mode, Plan};
use crate::anim::Animation;
use crate::mapping::{MappingRecord, SensorRecord};
use crate::pipeline::record::pipeline_record;
use crate::pipeline::root::RootMode;
use crate::retarget::{Reference, SourceMotion};
use crate::world::{World, WorldFrom};
use crate::write::take::Conversion;
use std::path::Path;

/// A motion retargeted onto the rig: the animation, each (source joint, bone) pair by name, and
/// what the pairing left out ([`crate::retarget::coverage_warnings`]).
pub(super) struct Retargeted {
    pub animation: Animation,
    pub pairs: Vec<(String, String)>,
    pub warnings: Vec<String>,
}

/// `source` onto the plan's rig: its joints paired with the rig's bones by the bone map, else
/// by anatomical part, then retargeted from `reference` at the plan's rate.
pub(super) fn retarget_onto_rig(
    input: &Path,
    source: &SourceMotion,
    plan: &Plan,
    reference: Reference,
) -> Result<Retargeted, ConvertError> {
    let fail = |source| ConvertError::Retarget {
        input: input.to_path_buf(),
        source,
    };
    let rig = plan.rig();
    let source_names: Vec<&str> = source.names.iter().map(String::as_str).collect();
    let target_names: Vec<&str> = rig.joints().iter().map(|j| j.name.as_str()).collect();
    let pairs = match plan.bone_map() {
        Some(map) => map.value.pairs(&source_names, rig),
        None => crate::retarget::auto_pairs(source, rig),
    }
    .map_err(fail)?;
    let warnings = crate::retarget::coverage_warnings(source, rig, &pairs);
    let animation = crate::retarget::retarget(source, rig, &pairs, reference, plan.pipeline().fps)
        .map_err(fail)?;
    let named = pairs
        .iter()
        .map(|&(s, t)| (source_names[s].to_string(), target_names[t].to_string()))
        .collect();
    Ok(Retargeted {
        animation,
        pairs: named,
        warnings,
    })
}

/// A take whose motion is already on a skeleton, as a conversion: its animation, and each
/// source joint that drove a bone.
pub(super) struct Motion {
    pub animation: Animation,
    /// (source joint or segment, bone).
    pub pairs: Vec<(String, String)>,
    /// `mapping.sensors[].orientation`: `bvh`, `xsens-segment`.
    pub orientation: &'static str,
    pub world: World,
    pub mode: Mode,
    pub warnings: Vec<String>,
}

impl Motion {
    /// The sidecar's records of the motion: identity mounts, no smoothing, the root from the
    /// source.
    pub(super) fn conversion(self, plan: &Plan) -> Conversion {
        let Motion {
            animation,
            pairs,
            orientation,
            world,
            mode,
            mut warnings,
        } = self;
        if plan.pipeline().trim.is_some() {
            warnings.push(format!("--trim is not applied in {} mode", mode.label()));
        }
        let sensors = pairs
            .into_iter()
            .map(|(sensor, bone)| SensorRecord {
                sensor,
                bone,
                mount_source: "fixed",
                mount: [1.0, 0.0, 0.0, 0.0],
                forward: None,
                orientation,
                world,
                heading_aligned_by: None,
                mount_turned_deg: None,
                mount_turn_uncertainty_deg: None,
            })
            .collect();
        let mut pipeline = pipeline_record(plan.pipeline(), None, 0, mode, RootMode::Fixed);
        pipeline.root = "source";
        pipeline.smoothing = None;
        pipeline.unsensed = "rest";
        pipeline.trim = None;
        let rig = animation.rig().name().to_string();
        Conversion {
            euler_deg: None,
            animation,
            unsmoothed: None,
            mapping: MappingRecord {
                file: plan
                    .bone_map()
                    .map(|m| m.path.to_string_lossy().into_owned()),
                rig,
                world,
                calibration: None,
                sensors,
                legacy: None,
            },
            pipeline,
            contacts: None,
            world: (world, WorldFrom::Format),
            vendor_contacts: None,
            warnings,
        }
    }
}
