//! What the sidecar says of how a take was converted: the mapping's sensors and mounts, the
//! pipeline's settings and outcome, the fusion, a capture system's own contacts.

use super::plan::{Mode, Plan};
use crate::mapping::{CalibrationRecord, Mapping, MappingRecord, Mount, SensorRecord};
use crate::pipeline::calibrate::HeadingSource;
use crate::pipeline::sources::Origin;
use crate::pipeline::{self, root::RootMode};
use crate::rig::Rig;
use crate::write::sidecar::{FusionRecord, PipelineRecord, TrimRecord, VendorContactsRecord};
use crate::write::take::Conversion;
use std::path::Path;

/// The sidecar's `mapping` for the quaternion pipeline: each sensor's bone, mount and source.
pub(super) fn mapping_record(
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

/// The sidecar's `pipeline.fusion`: `None` when no sensor was fused.
pub(super) fn fusion_record(plan: &Plan, converted: &pipeline::Converted) -> Option<FusionRecord> {
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
        chosen_by: if plan.pipeline().fusion.is_some() {
            "settings"
        } else {
            "default"
        },
        sensor_calibration: plan
            .sensor_calibration()
            .map(|c| crate::write::sidecar::FileRecord {
                path: c.path.display().to_string(),
                sha256: c.sha256.clone(),
            }),
        sensors,
    })
}

/// The sidecar's `pipeline`: what was done, in which mode.
pub(super) fn pipeline_record(
    plan: &Plan,
    heading: &HeadingSource,
    heading_deg: f64,
    first_frame: usize,
    mode: Mode,
    root: RootMode,
) -> PipelineRecord {
    let options = plan.pipeline();
    PipelineRecord {
        fusion: None,
        smoothing: Some(serde_json::to_value(&options.smoothing).expect("serialisable")),
        root: root.label(),
        unsensed: if mode == Mode::Euler {
            "rest"
        } else {
            options.unsensed.label()
        },
        heading: heading.label(),
        heading_sensor: heading.sensor().map(str::to_string),
        heading_deg,
        trim: options.trim.map(|t| TrimRecord {
            start_s: t.start_s,
            end_s: (t.end_s < f64::MAX).then_some(t.end_s),
            first_frame,
        }),
        mode: mode.label(),
        causal: options.causal,
        bind_frame: false,
        in_place: false,
    }
}

/// A capture system's contacts on the written frames: frame n stands at take time
/// (n − bind + first) / fps, where `first` is the grid frame `--trim` made frame 0 and `bind` is 1
/// with `--bind-frame` (whose frame 0, the rest pose, has no contact).
pub(super) fn vendor_contacts_record(
    v: &crate::take::VendorContacts,
    conversion: &Conversion,
) -> VendorContactsRecord {
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
    let runs = |side: usize| pipeline::root::runs(planted.iter().map(|p| p[side]), 1);
    VendorContactsRecord {
        vendor: v.vendor,
        left: runs(0),
        right: runs(1),
    }
}
