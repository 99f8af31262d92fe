//! What the quaternion pipeline did to a take, as the sidecar says it (`pipeline` and
//! `mapping`; conventions.md): made by the pipeline itself ([`super::run_owned`]) so the modes
//! above hand the writers one finished value.

use crate::mapping::HeadingPolicy;
use crate::mapping::MappingRecord;
use crate::mapping::{CalibrationRecord, Mapping, Mount, SensorRecord};
use crate::pipeline::calibrate::Calibration;
use crate::pipeline::sources::Origin;
use crate::pipeline::{self, PipelineOptions, root::RootMode};
use crate::rig::Rig;
use serde::Serialize;
use std::path::Path;

#[derive(Debug, Clone, Serialize)]
pub struct PipelineRecord {
    /// `null` when no sensor was fused.
    pub fusion: Option<FusionRecord>,
    pub smoothing: Option<serde_json::Value>,
    pub root: &'static str,
    /// The planted feet were held where they stood (`--foot-lock` in `feet` mode:
    /// [`crate::pipeline::foot_lock`]).
    pub foot_lock: bool,
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
    /// Causal mode: the stream time (s) from which `heading_deg` was in force, when the hinges
    /// refined the heading as the take went on (the frames before turned with the one before).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heading_from_s: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trim: Option<TrimRecord>,
    /// `"quaternion"`, or `"legacy-euler"` for paper 002's Listing-2 mappings.
    pub mode: Mode,
    /// A BVH take's reference pose (`--bvh-reference`: `match:N`, `frame:N`, `rest`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bvh_reference: Option<String>,
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
            .zip(&converted.calibration.mount_turns)
            .map(|(((s, q), (origin, alignment)), turn)| SensorRecord {
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
                mount_turned_deg: turn.map(|t| t.deg),
                mount_turn_uncertainty_deg: turn.map(|t| t.uncertainty_deg),
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
        foot_lock: options.foot_lock && root == RootMode::Feet && mode == Mode::Orientations,
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
        heading_from_s: heading.and_then(|(c, _)| c.heading_from_s),
        trim: options.trim.map(|t| TrimRecord {
            start_s: t.start_s,
            end_s: (t.end_s < f64::MAX).then_some(t.end_s),
            first_frame,
        }),
        mode,
        bvh_reference: None,
        causal: options.causal,
        bind_frame: false,
        in_place: false,
    }
}
