//! What can stop the pipeline.

use super::Trim;
use crate::anim::AnimationError;
use crate::fps::Fps;
use crate::mapping::MappingError;

#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Mapping(#[from] MappingError),
    /// Boxed: five strings would make every `Result` of the pipeline large.
    #[error(transparent)]
    MissingPart(Box<crate::rig::anatomy::MissingPart>),
    #[error(
        "none of the mapped sensors ({mapped}) has orientation or raw readings in the take (sensors in the take: {present}); check the mapping's sensor ids"
    )]
    NoSensors { mapped: String, present: String },
    #[error(
        "{file}: `calibration`: the window {start_s} s + {duration_s} s is outside the take, which ends at {end_s:.3} s"
    )]
    CalibrationOutside {
        file: String,
        start_s: f64,
        duration_s: f64,
        end_s: f64,
    },
    #[error("{file}: `calibration.pose`: rig `{rig}` has no pose `{pose}`; it has {known}")]
    UnknownPose {
        file: String,
        rig: String,
        pose: String,
        known: String,
    },
    #[error("{file}: {}", heading_unsure_message(.heading, *.uncertainty_deg, .sensor))]
    HeadingUnsure {
        file: String,
        /// Where the heading came from (`none` when nothing gave one).
        heading: &'static str,
        /// Degrees; infinite when unknown.
        uncertainty_deg: f64,
        /// The sensor whose bone's axes are least sure.
        sensor: String,
    },
    #[error("--trim {trim} keeps no frame of the take (frames run from 0 s to {end_take_s:.3} s)")]
    EmptyTrim { trim: Trim, end_take_s: f64 },
    #[error(
        "--fps {fps} over {frames} frames × {joints} joints is {cells} keyframes (about {mb} MB of BVH), \
         more than the {max} allowed without --force. Hint: a lower --fps (the fastest mapped sensor \
         samples at {sensor_hz:.1} Hz), or --force"
    )]
    TooManyFrames {
        fps: Fps,
        frames: usize,
        joints: usize,
        cells: usize,
        mb: usize,
        max: usize,
        sensor_hz: f64,
    },
    #[error(transparent)]
    Fusion(#[from] crate::fusion::FusionError),
    #[error("`{bone}`: {source}")]
    NotCausal {
        bone: String,
        #[source]
        source: crate::smooth::NotCausal,
    },
    #[error(transparent)]
    Animation(#[from] AnimationError),
}

/// Why a stream cannot calibrate again now ([`super::stream::PoseStream::recalibrate`]).
#[derive(Debug, thiserror::Error)]
pub enum RecalibrateError {
    #[error("the mapping has no calibration window (every mount is fixed)")]
    NoWindow,
    #[error("the first calibration is still under way")]
    FirstUnderWay,
    /// Boxed: the pipeline's error holds this one.
    #[error(transparent)]
    Window(Box<PipelineError>),
}

/// The refusal of an unsure heading, naming the ways out.
pub fn heading_unsure_message(heading: &str, uncertainty_deg: f64, sensor: &str) -> String {
    let how = if uncertainty_deg.is_finite() {
        format!("unsure by about {uncertainty_deg:.0}° (from `{heading}`)")
    } else if heading == "none" {
        "unknown: no sensor declares `forward`, no mount is known, there is no second pose and no knee or elbow flexes in the minute after calibration".to_string()
    } else {
        format!("unknown for some sensors (`{heading}`)")
    };
    format!(
        "the subject's heading is {how}, so bones would turn about wrong axes (sensor `{sensor}` is the least sure; more than {max}° is refused). \
         Ways out: declare `forward` on one sensor (the sensor axis that points where the body faces in the calibration pose, e.g. `\"forward\": \"+y\"` on the pelvis sensor); \
         hold a second calibration pose (`calibration.second`, e.g. `skiing` after `npose`); \
         or keep the sensors' own north as the subject's facing deliberately: `\"heading\": \"sensors\"` in the mapping, `heading: sensors` in the config, or `--heading sensors`",
        max = super::calibrate::MAX_HEADING_UNCERTAINTY_DEG
    )
}
