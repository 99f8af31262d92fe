//! The MVNX-segments mode (`--mvnx-segments`): Xsens's own segment kinematics as the take, on
//! the rig the file's segments make, or retargeted onto `--rig` by anatomical part (or the bone
//! map); Xsens's foot contacts in the sidecar.

use super::error::ConvertError;
use super::hash::source_sha256;
use super::plan::{Mode, Plan};
use super::skeleton::{Motion, Retargeted, retarget_onto_rig};
use crate::take::{LineReport, VendorContacts};
use crate::world::{World, WorldFrom};
use crate::write::sidecar::SourceRecord;
use crate::write::take::Conversion;
use std::path::Path;

/// An MVNX take's segments converted.
pub(super) struct Mvnx {
    pub conversion: Conversion,
    /// What the sidecar says of the source.
    pub source: SourceRecord,
    /// The frames dropped.
    pub dropped: Vec<LineReport>,
    /// Xsens's foot contacts, when the file has them.
    pub contacts: Option<VendorContacts>,
}

pub(super) fn convert(input: &Path, plan: &Plan) -> Result<Mvnx, ConvertError> {
    let sha256 = source_sha256(input).map_err(|source| ConvertError::Source {
        input: input.to_path_buf(),
        source,
    })?;
    let segments = crate::read::xsens_mvnx::read_segments(input)?;
    let (mvn, mut warnings) = crate::retarget::mvnx_animation(&segments, plan.pipeline().fps)
        .map_err(|source| ConvertError::Retarget {
            input: input.to_path_buf(),
            source,
        })?;
    let (animation, pairs) = if plan.rig_given() || plan.bone_map().is_some() {
        let source = crate::retarget::SourceMotion::of_animation(&mvn);
        let Retargeted {
            animation,
            pairs,
            warnings: more,
        } = retarget_onto_rig(input, &source, plan, crate::retarget::Reference::Rest)?;
        warnings.extend(more);
        (animation, pairs)
    } else {
        let pairs = mvn
            .rig()
            .joints()
            .iter()
            .map(|j| (j.name.clone(), j.name.clone()))
            .collect();
        (mvn, pairs)
    };
    if !segments.dropped.is_empty() {
        warnings.push(format!(
            "{} frames dropped (see dropped_lines)",
            segments.dropped.len()
        ));
    }
    let motion = Motion {
        animation,
        pairs,
        orientation: "xsens-segment",
        world: World::Nwu,
        mode: Mode::MvnxSegments,
        warnings,
    };
    // Xsens's own contacts, placed on the written frames once the output transforms ran.
    let contacts = (!segments.contacts.is_empty()).then(|| {
        let (times_s, planted) = segments.contacts.iter().copied().unzip();
        VendorContacts {
            vendor: "xsens",
            times_s,
            planted,
        }
    });
    let record = SourceRecord {
        path: input.to_string_lossy().into_owned(),
        sha256,
        format: crate::take::InputFormat::XsensMvnx,
        world: World::Nwu,
        world_from: WorldFrom::Format,
        start_timestamp: "0 s".to_string(),
        layout: None,
    };
    Ok(Mvnx {
        conversion: motion.conversion(plan),
        source: record,
        dropped: segments.dropped,
        contacts,
    })
}
