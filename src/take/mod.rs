//! The take: one capture's per-sensor tracks on one clock, plus everything that was dropped or
//! repaired on the way in (conventions.md, "Time and frames", "Takes and names").

mod builder;
mod dropped;
mod format;
mod samples;
mod sequence;
mod stream;
mod track;

pub use builder::{BuildError, ClockUnit, ContactSample, SensorIdx, TakeBuilder};
pub use dropped::DroppedLines;
pub use format::InputFormat;
pub use samples::{ImuSample, YawPitchRollDeg};
pub use sequence::LOOKAHEAD_ROWS;
pub use stream::{DEFAULT_REORDER_S, MAX_STREAM_SENSORS, StreamSample, StreamValue, TakeStream};
pub use track::{Track, TrackError};

use crate::world::World;
use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;
use std::path::PathBuf;

/// Where a take came from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SourceInfo {
    #[serde(serialize_with = "serialize_path_lossy")]
    pub path: PathBuf,
    pub format: InputFormat,
    /// The world the sensors' orientations are expressed in.
    pub world: World,
    /// The source's own timestamp of t = 0 (device uptime, µs counter, wall time), with its unit,
    /// so the take can be synced with other recordings.
    pub start_timestamp: String,
}

fn serialize_path_lossy<S: serde::Serializer>(
    path: &std::path::Path,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.serialize_str(&path.to_string_lossy())
}

/// A line of the source that was dropped or repaired, and why.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct LineReport {
    /// File of a multi-file take (relative to the take's folder); absent for single-file takes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// 1-based line number in that file.
    pub line: u64,
    pub reason: String,
    /// The raw line, cut short to [`LineReport::TEXT_LIMIT`] characters.
    pub text: String,
}

impl LineReport {
    pub const TEXT_LIMIT: usize = 80;

    pub fn new(file: Option<&str>, line: u64, reason: impl Into<String>, raw: &[u8]) -> Self {
        LineReport {
            file: file.map(str::to_string),
            line,
            reason: reason.into(),
            text: cut_text(raw),
        }
    }

    /// `file:line` (or `line N`) for messages.
    pub fn location(&self) -> String {
        match &self.file {
            Some(file) => format!("{file}:{}", self.line),
            None => format!("line {}", self.line),
        }
    }
}

/// Lossy UTF-8, control characters made visible, cut to `TEXT_LIMIT` characters.
pub(crate) fn cut_text(raw: &[u8]) -> String {
    let text = String::from_utf8_lossy(raw);
    let mut out: String = text
        .chars()
        .take(LineReport::TEXT_LIMIT)
        .map(|c| if c.is_control() { '\u{FFFD}' } else { c })
        .collect();
    if text.chars().nth(LineReport::TEXT_LIMIT).is_some() {
        out.push('…');
    }
    out
}

/// Orientation samples as the source gave them.
#[derive(Debug, Clone, PartialEq)]
pub enum OrientationTrack {
    /// `q_world_sensor`, unit, w first.
    Quaternion(Track<UnitQuaternion<f64>>),
    /// Yaw, pitch, roll in degrees, intrinsic Z-Y-X (SOU logs; kept verbatim for the paper's
    /// Euler-channel legacy mode).
    YawPitchRollDeg(Track<YawPitchRollDeg>),
}

impl OrientationTrack {
    pub fn times_s(&self) -> &[f64] {
        match self {
            OrientationTrack::Quaternion(t) => t.times_s(),
            OrientationTrack::YawPitchRollDeg(t) => t.times_s(),
        }
    }

    /// The orientations as unit quaternions `q_world_sensor`.
    pub fn to_quaternions(&self) -> Track<UnitQuaternion<f64>> {
        match self {
            OrientationTrack::Quaternion(t) => t.clone(),
            OrientationTrack::YawPitchRollDeg(t) => t.map(|ypr| ypr.to_quaternion()),
        }
    }

    /// [`Self::to_quaternions`] without a copy of quaternion tracks.
    pub fn into_quaternions(self) -> Track<UnitQuaternion<f64>> {
        match self {
            OrientationTrack::Quaternion(t) => t,
            OrientationTrack::YawPitchRollDeg(t) => t.map(|ypr| ypr.to_quaternion()),
        }
    }

    fn shift_times(&mut self, offset_s: f64) {
        match self {
            OrientationTrack::Quaternion(t) => t.shift_times(offset_s),
            OrientationTrack::YawPitchRollDeg(t) => t.shift_times(offset_s),
        }
    }

    fn keep_from(self, start_s: f64) -> Option<Self> {
        match self {
            OrientationTrack::Quaternion(t) => {
                t.keep_from(start_s).map(OrientationTrack::Quaternion)
            }
            OrientationTrack::YawPitchRollDeg(t) => {
                t.keep_from(start_s).map(OrientationTrack::YawPitchRollDeg)
            }
        }
    }
}

/// One sensor's streams. At least one stream is present (the builder guarantees it).
#[derive(Debug, Clone, PartialEq)]
pub struct Sensor {
    id: String,
    orientation: Option<OrientationTrack>,
    inertial: Option<Track<ImuSample>>,
    /// Magnetic field, µT where the source said so, else the source's own unit.
    magnetometer: Option<Track<Vector3<f64>>>,
}

impl Sensor {
    pub fn id(&self) -> &str {
        &self.id
    }
    pub fn orientation(&self) -> Option<&OrientationTrack> {
        self.orientation.as_ref()
    }
    pub fn inertial(&self) -> Option<&Track<ImuSample>> {
        self.inertial.as_ref()
    }
    pub fn magnetometer(&self) -> Option<&Track<Vector3<f64>>> {
        self.magnetometer.as_ref()
    }

    /// The stream that stands for the sensor in summaries: orientation, else inertial, else
    /// magnetometer.
    pub fn primary_times_s(&self) -> &[f64] {
        if let Some(o) = &self.orientation {
            o.times_s()
        } else if let Some(i) = &self.inertial {
            i.times_s()
        } else if let Some(m) = &self.magnetometer {
            m.times_s()
        } else {
            unreachable!("a Sensor always has a stream")
        }
    }

    fn streams_first_last(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        let o = self.orientation.as_ref().map(|o| o.times_s());
        let i = self.inertial.as_ref().map(|t| t.times_s());
        let m = self.magnetometer.as_ref().map(|t| t.times_s());
        [o, i, m]
            .into_iter()
            .flatten()
            .map(|t| (t[0], t[t.len() - 1]))
    }

    pub fn first_time_s(&self) -> f64 {
        self.streams_first_last()
            .map(|(f, _)| f)
            .fold(f64::INFINITY, f64::min)
    }

    pub fn last_time_s(&self) -> f64 {
        self.streams_first_last()
            .map(|(_, l)| l)
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// A capture read into memory: sensors on one clock, t = 0 at the earliest kept sample.
///
/// Built only by [`TakeBuilder`], which guarantees at least one sensor and the zero point.
#[derive(Debug, Clone, PartialEq)]
pub struct Take {
    source: SourceInfo,
    sensors: Vec<Sensor>,
    dropped_lines: Vec<LineReport>,
    repaired_lines: Vec<LineReport>,
    warnings: Vec<String>,
    /// When a live session was recalibrated (`# calibrate t=…` lines), seconds, ascending.
    recalibrations_s: Vec<f64>,
    /// The foot contacts the capture system found itself (Xsens MVN's), when the file has them.
    vendor_contacts: Option<VendorContacts>,
}

/// A capture system's own foot contacts: at each time (seconds, the take's clock), whether the
/// left and right foot are planted.
#[derive(Debug, Clone, PartialEq)]
pub struct VendorContacts {
    /// Whose: `xsens`.
    pub vendor: &'static str,
    pub times_s: Vec<f64>,
    pub planted: Vec<[bool; 2]>,
}

impl VendorContacts {
    /// Planted at `t_s`: the latest sample at or before it (the first before the first).
    pub fn at(&self, t_s: f64) -> [bool; 2] {
        let i = self.times_s.partition_point(|&t| t <= t_s + 1e-9);
        self.planted[i
            .saturating_sub(1)
            .min(self.planted.len().saturating_sub(1))]
    }
}

impl Take {
    /// When a live session recording this take was recalibrated: the mapping's calibration
    /// pose held again from each of these times (seconds, ascending).
    pub fn recalibrations_s(&self) -> &[f64] {
        &self.recalibrations_s
    }
    pub fn source(&self) -> &SourceInfo {
        &self.source
    }
    /// The capture system's own foot contacts, when the file has them.
    pub fn vendor_contacts(&self) -> Option<&VendorContacts> {
        self.vendor_contacts.as_ref()
    }
    /// Sensors in the order they first appear in the source.
    pub fn sensors(&self) -> &[Sensor] {
        &self.sensors
    }
    pub fn sensor(&self, id: &str) -> Option<&Sensor> {
        self.sensors.iter().find(|s| s.id == id)
    }
    pub fn dropped_lines(&self) -> &[LineReport] {
        &self.dropped_lines
    }
    pub fn repaired_lines(&self) -> &[LineReport] {
        &self.repaired_lines
    }
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }
    /// Time of the latest sample of any sensor (seconds since t = 0).
    pub fn last_time_s(&self) -> f64 {
        self.sensors
            .iter()
            .map(Sensor::last_time_s)
            .fold(0.0, f64::max)
    }
    /// Moves a sensor's orientation track out of the take (for a pipeline that owns the take
    /// and needs no copy); the sensor keeps its other streams.
    pub(crate) fn remove_orientation(&mut self, id: &str) -> Option<OrientationTrack> {
        self.sensors
            .iter_mut()
            .find(|s| s.id == id)
            .and_then(|s| s.orientation.take())
    }

    pub fn total_samples(&self) -> usize {
        self.sensors.iter().map(|s| s.primary_times_s().len()).sum()
    }
}
