//! The pipeline's options and `--trim`'s cut of the frame range.

use super::relative;
use super::root::RootMode;
use crate::fps::Fps;
use crate::smooth::Smoothing;
use crate::world::World;

/// A cut of the frame range, in seconds on the take's clock (both ends inclusive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trim {
    pub start_s: f64,
    pub end_s: f64,
}

impl std::fmt::Display for Trim {
    /// `start:end` as given, an open end left empty.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:", self.start_s)?;
        if self.end_s < f64::MAX {
            write!(f, "{}", self.end_s)?;
        }
        Ok(())
    }
}

impl std::str::FromStr for Trim {
    type Err = String;
    /// `start:end` in seconds; either side may be empty (`:10`, `2.5:`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (a, b) = s
            .split_once(':')
            .ok_or_else(|| format!("`{s}`: expected START:END in seconds, e.g. 2.5:10"))?;
        let parse = |v: &str, default: f64| -> Result<f64, String> {
            if v.trim().is_empty() {
                return Ok(default);
            }
            match v.trim().parse::<f64>() {
                Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
                _ => Err(format!("`{v}` in `{s}` is not a number of seconds ≥ 0")),
            }
        };
        let trim = Trim {
            start_s: parse(a, 0.0)?,
            end_s: parse(b, f64::MAX)?,
        };
        if trim.end_s < trim.start_s {
            return Err(format!("`{s}`: the end is before the start"));
        }
        Ok(trim)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct PipelineOptions {
    pub fps: Fps,
    pub trim: Option<Trim>,
    pub root: RootMode,
    /// Hold each planted foot where it stands over its contact (`--foot-lock`:
    /// [`super::foot_lock`]; a whole take in `feet` mode).
    pub foot_lock: bool,
    pub smoothing: Smoothing,
    /// Also produce the local rotations without smoothing (for the report).
    pub keep_unsmoothed: bool,
    /// Allow more than [`MAX_KEYFRAMES`] keyframes.
    pub force: bool,
    /// The sensors' world when the user set it (`--world`, the config file): over the mapping's
    /// and the take's.
    pub world: Option<World>,
    /// Causal mode: the take runs through the stream's incremental cores ([`stream`]), as a live
    /// capture would: smoothing causal, no heading from the hinges (it reads the minute after calibration).
    pub causal: bool,
    /// The sensors' sample rate, when known: causal smoothing's grid uses it instead of the rate
    /// of each sensor's first samples.
    pub sensor_rate_hz: Option<f64>,
    /// Fusion asked for (`--fusion`): every sensor with raw readings is fused with it, even when
    /// the device gave an orientation. `None`: device orientations where there are some, the
    /// default filter for sensors with raw readings only.
    pub fusion: Option<crate::fusion::Fusion>,
    /// What joints without a sensor do (`--unsensed`).
    pub unsensed: relative::Unsensed,
    /// Corrections of raw readings before fusion, per sensor id (`--sensor-calibration`).
    pub sensor_calibration: Option<std::sync::Arc<crate::intrinsics::SensorCalibration>>,
    /// Where the heading comes from when the user set it (`--heading`, the config file): over
    /// the mapping's.
    pub heading: Option<crate::mapping::HeadingPolicy>,
}

impl PipelineOptions {
    /// Where the heading comes from: `--heading` (or the config's) over the mapping's.
    pub fn heading_policy(
        &self,
        mapping: &crate::mapping::Mapping,
    ) -> crate::mapping::HeadingPolicy {
        self.heading.unwrap_or(mapping.heading)
    }
}

impl Default for PipelineOptions {
    fn default() -> Self {
        PipelineOptions {
            fps: Fps::new(30, 1).expect("30 fps"),
            trim: None,
            root: RootMode::Auto,
            foot_lock: false,
            smoothing: Smoothing::default(),
            keep_unsmoothed: false,
            force: false,
            world: None,
            causal: false,
            sensor_rate_hz: None,
            fusion: None,
            unsensed: relative::Unsensed::Interpolate,
            sensor_calibration: None,
            heading: None,
        }
    }
}
