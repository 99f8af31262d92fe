//! Collects rows as readers parse them and turns them into a [`Take`].
//!
//! Readers push samples in file order with their line numbers. Rows that arrive earlier than the
//! previous row of the same stream are kept aside and sorted into place at the end (reported as
//! repaired); rows repeating a time are dropped, the first kept (reported as dropped); a row more
//! than [`CLOCK_RESET_S`] earlier than its predecessor is a clock reset and fails the take.

use super::{
    ImuSample, LineReport, OrientationTrack, Sensor, SourceInfo, Take, Track, YawPitchRollDeg,
};
use crate::read::InputFormat;
use crate::world::World;
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::path::PathBuf;

/// A step back in time larger than this (seconds) is a clock reset, not a late row.
pub const CLOCK_RESET_S: f64 = 1.0;

const REPEATED_TIME: &str =
    "repeats the time of an earlier sample of the same sensor; the first is kept";
const OUT_OF_ORDER: &str = "earlier than the previous sample of the same sensor; sorted into place";

/// The unit of a source's raw time values.
#[derive(Debug, Clone, PartialEq)]
pub enum ClockUnit {
    Seconds,
    Milliseconds,
    Microseconds,
    /// A sample counter at a fixed rate, e.g. Xsens `PacketCounter` at the header's update rate.
    Counter {
        name: String,
        rate_hz: f64,
    },
}

impl ClockUnit {
    pub fn seconds_per_unit(&self) -> f64 {
        match self {
            ClockUnit::Seconds => 1.0,
            ClockUnit::Milliseconds => 1e-3,
            ClockUnit::Microseconds => 1e-6,
            ClockUnit::Counter { rate_hz, .. } => 1.0 / rate_hz,
        }
    }

    /// The original timestamp of t = 0, with its unit (sidecar `source.start_timestamp`).
    pub fn describe(&self, raw: f64) -> String {
        // Re-zeroing after --skip-seconds adds float noise far below any clock's resolution.
        let raw = (raw * 1e6).round() / 1e6;
        match self {
            ClockUnit::Seconds => format!("{raw} s"),
            ClockUnit::Milliseconds => format!("{raw} ms"),
            ClockUnit::Microseconds => format!("{raw} us"),
            ClockUnit::Counter { name, rate_hz } => format!("{name} {raw} at {rate_hz} Hz"),
        }
    }
}

/// Index of a sensor inside a [`TakeBuilder`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SensorIdx(usize);

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BuildError {
    #[error(
        "{location}: time goes back by {back_s:.3} s for sensor `{sensor}` (from {previous} to {time} in the file's time unit): \
         the clock was reset. Expected times that keep increasing; split the log at this line, or trim it with --skip-lines"
    )]
    ClockReset {
        location: String,
        sensor: String,
        previous: f64,
        time: f64,
        back_s: f64,
    },
    #[error("no samples in the take{}", first_drop_hint(.dropped))]
    Empty { dropped: Vec<LineReport> },
}

fn first_drop_hint(dropped: &[LineReport]) -> String {
    match dropped.first() {
        None => String::new(),
        Some(first) => format!(
            ": all {} data lines were dropped, the first at {} ({}: \"{}\")",
            dropped.len(),
            first.location(),
            first.reason,
            first.text
        ),
    }
}

struct Late<T> {
    raw_time: f64,
    value: T,
    report: LineReport,
}

struct Stream<T> {
    raw_times: Vec<f64>,
    values: Vec<T>,
    late: Vec<Late<T>>,
}

impl<T> Default for Stream<T> {
    fn default() -> Self {
        Stream {
            raw_times: Vec::new(),
            values: Vec::new(),
            late: Vec::new(),
        }
    }
}

enum Pushed {
    Appended,
    Duplicate,
    Late,
}

impl<T> Stream<T> {
    fn push(
        &mut self,
        raw_time: f64,
        value: T,
        reset_units: f64,
        report: impl FnOnce() -> LineReport,
    ) -> Result<Pushed, (f64, LineReport)> {
        match self.raw_times.last() {
            Some(&last) if raw_time <= last => {
                if raw_time == last {
                    return Ok(Pushed::Duplicate);
                }
                if last - raw_time > reset_units {
                    return Err((last, report()));
                }
                self.late.push(Late {
                    raw_time,
                    value,
                    report: report(),
                });
                Ok(Pushed::Late)
            }
            _ => {
                self.raw_times.push(raw_time);
                self.values.push(value);
                Ok(Pushed::Appended)
            }
        }
    }

    fn first_raw(&self) -> Option<f64> {
        let main = self.raw_times.first().copied();
        let late = self.late.iter().map(|l| l.raw_time).reduce(f64::min);
        match (main, late) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Merges late rows into place; returns the track on the take's clock.
    fn finish(
        mut self,
        raw_start: f64,
        seconds_per_unit: f64,
        dropped: &mut Vec<LineReport>,
        repaired: &mut Vec<LineReport>,
    ) -> Option<Track<T>> {
        if !self.late.is_empty() {
            // Stable: late rows with equal times stay in line order, so the first is kept.
            self.late.sort_by(|a, b| a.raw_time.total_cmp(&b.raw_time));
            let n = self.raw_times.len() + self.late.len();
            let mut times = Vec::with_capacity(n);
            let mut values = Vec::with_capacity(n);
            let mut main = self.raw_times.into_iter().zip(self.values).peekable();
            for late in self.late {
                while let Some((t, _)) = main.peek() {
                    if *t <= late.raw_time {
                        let (t, v) = main.next().expect("peeked");
                        times.push(t);
                        values.push(v);
                    } else {
                        break;
                    }
                }
                if times.last() == Some(&late.raw_time) {
                    dropped.push(LineReport {
                        reason: REPEATED_TIME.to_string(),
                        ..late.report
                    });
                } else {
                    repaired.push(LineReport {
                        reason: OUT_OF_ORDER.to_string(),
                        ..late.report
                    });
                    times.push(late.raw_time);
                    values.push(late.value);
                }
            }
            for (t, v) in main {
                times.push(t);
                values.push(v);
            }
            self.raw_times = times;
            self.values = values;
        }
        for t in &mut self.raw_times {
            *t = (*t - raw_start) * seconds_per_unit;
        }
        // Distinct raw times can collapse only if they differ by less than f64 resolution after
        // scaling, which no real clock produces; Track::new would reject it rather than lie.
        Track::new(self.raw_times, self.values).ok()
    }
}

struct SensorStreams {
    id: String,
    orientation_q: Stream<UnitQuaternion<f64>>,
    orientation_ypr: Stream<YawPitchRollDeg>,
    inertial: Stream<ImuSample>,
    magnetometer: Stream<Vector3<f64>>,
}

/// Builds a [`Take`] from rows pushed in file order.
pub struct TakeBuilder {
    path: PathBuf,
    format: InputFormat,
    world: World,
    clock: ClockUnit,
    reset_units: f64,
    current_file: Option<String>,
    sensors: Vec<SensorStreams>,
    by_id: HashMap<String, SensorIdx>,
    dropped: Vec<LineReport>,
    repaired: Vec<LineReport>,
    warnings: Vec<String>,
}

impl TakeBuilder {
    pub fn new(
        path: impl Into<PathBuf>,
        format: InputFormat,
        world: World,
        clock: ClockUnit,
    ) -> Self {
        let reset_units = CLOCK_RESET_S / clock.seconds_per_unit();
        TakeBuilder {
            path: path.into(),
            format,
            world,
            clock,
            reset_units,
            current_file: None,
            sensors: Vec::new(),
            by_id: HashMap::new(),
            dropped: Vec::new(),
            repaired: Vec::new(),
            warnings: Vec::new(),
        }
    }

    pub fn set_world(&mut self, world: World) {
        self.world = world;
    }

    /// Names the file that following line numbers refer to (multi-file takes).
    pub fn set_file(&mut self, file: Option<String>) {
        self.current_file = file;
    }

    pub fn current_file(&self) -> Option<&str> {
        self.current_file.as_deref()
    }

    pub fn sensor(&mut self, id: &str) -> SensorIdx {
        if let Some(&idx) = self.by_id.get(id) {
            return idx;
        }
        let idx = SensorIdx(self.sensors.len());
        self.sensors.push(SensorStreams {
            id: id.to_string(),
            orientation_q: Stream::default(),
            orientation_ypr: Stream::default(),
            inertial: Stream::default(),
            magnetometer: Stream::default(),
        });
        self.by_id.insert(id.to_string(), idx);
        idx
    }

    pub fn sensor_count(&self) -> usize {
        self.sensors.len()
    }

    /// Reserves room for `additional` more samples in every orientation stream (readers that can
    /// estimate their row count use it to avoid growth spikes on large logs).
    pub fn reserve_orientation(&mut self, additional: usize) {
        for s in &mut self.sensors {
            s.orientation_q.raw_times.reserve(additional);
            s.orientation_q.values.reserve(additional);
        }
    }

    pub fn drop_line(&mut self, line: u64, reason: impl Into<String>, raw: &[u8]) {
        let report = LineReport::new(self.current_file.as_deref(), line, reason, raw);
        self.dropped.push(report);
    }

    pub fn repair_line(&mut self, line: u64, reason: impl Into<String>, raw: &[u8]) {
        let report = LineReport::new(self.current_file.as_deref(), line, reason, raw);
        self.repaired.push(report);
    }

    pub fn warn(&mut self, warning: impl Into<String>) {
        self.warnings.push(warning.into());
    }

    pub fn dropped_count(&self) -> usize {
        self.dropped.len()
    }

    pub fn push_quaternion(
        &mut self,
        sensor: SensorIdx,
        raw_time: f64,
        q: UnitQuaternion<f64>,
        line: u64,
        raw: &[u8],
    ) -> Result<(), BuildError> {
        self.push_with(sensor, raw_time, q, line, raw, |s| &mut s.orientation_q)
    }

    pub fn push_yaw_pitch_roll(
        &mut self,
        sensor: SensorIdx,
        raw_time: f64,
        ypr: YawPitchRollDeg,
        line: u64,
        raw: &[u8],
    ) -> Result<(), BuildError> {
        self.push_with(sensor, raw_time, ypr, line, raw, |s| &mut s.orientation_ypr)
    }

    pub fn push_inertial(
        &mut self,
        sensor: SensorIdx,
        raw_time: f64,
        sample: ImuSample,
        line: u64,
        raw: &[u8],
    ) -> Result<(), BuildError> {
        self.push_with(sensor, raw_time, sample, line, raw, |s| &mut s.inertial)
    }

    pub fn push_magnetometer(
        &mut self,
        sensor: SensorIdx,
        raw_time: f64,
        field: Vector3<f64>,
        line: u64,
        raw: &[u8],
    ) -> Result<(), BuildError> {
        self.push_with(sensor, raw_time, field, line, raw, |s| &mut s.magnetometer)
    }

    fn push_with<T>(
        &mut self,
        sensor: SensorIdx,
        raw_time: f64,
        value: T,
        line: u64,
        raw: &[u8],
        stream: impl FnOnce(&mut SensorStreams) -> &mut Stream<T>,
    ) -> Result<(), BuildError> {
        let file = self.current_file.as_deref();
        let sensor_streams = &mut self.sensors[sensor.0];
        let id = &sensor_streams.id;
        let make_report = || LineReport::new(file, line, String::new(), raw);
        let id_for_reason = id.clone();
        match stream(sensor_streams).push(raw_time, value, self.reset_units, make_report) {
            Ok(Pushed::Appended) | Ok(Pushed::Late) => Ok(()),
            Ok(Pushed::Duplicate) => {
                let report = LineReport::new(file, line, REPEATED_TIME, raw);
                // A row carrying several sensors (a SOU line) is reported once.
                if self.dropped.last() != Some(&report) {
                    self.dropped.push(report);
                }
                Ok(())
            }
            Err((previous, report)) => Err(BuildError::ClockReset {
                location: report.location(),
                sensor: id_for_reason,
                previous,
                time: raw_time,
                back_s: (previous - raw_time) * self.clock.seconds_per_unit(),
            }),
        }
    }

    /// Finishes the take: merges late rows, re-zeroes the clock at the earliest sample, and drops
    /// samples before `skip_seconds` (then re-zeroes at the earliest kept one).
    pub fn finish(self, skip_seconds: f64) -> Result<Take, BuildError> {
        let TakeBuilder {
            path,
            format,
            world,
            clock,
            sensors,
            mut dropped,
            mut repaired,
            mut warnings,
            ..
        } = self;
        let raw_start = sensors
            .iter()
            .flat_map(|s| {
                [
                    s.orientation_q.first_raw(),
                    s.orientation_ypr.first_raw(),
                    s.inertial.first_raw(),
                    s.magnetometer.first_raw(),
                ]
            })
            .flatten()
            .reduce(f64::min);
        let Some(mut raw_start) = raw_start else {
            return Err(BuildError::Empty { dropped });
        };
        let spu = clock.seconds_per_unit();
        let mut out = Vec::with_capacity(sensors.len());
        for s in sensors {
            let id = s.id;
            let q = s
                .orientation_q
                .finish(raw_start, spu, &mut dropped, &mut repaired);
            let ypr = s
                .orientation_ypr
                .finish(raw_start, spu, &mut dropped, &mut repaired);
            let orientation = match (q, ypr) {
                (Some(q), Some(_)) => {
                    warnings.push(format!(
                        "sensor `{id}` has both quaternion and yaw/pitch/roll columns; the quaternions are used"
                    ));
                    Some(OrientationTrack::Quaternion(q))
                }
                (Some(q), None) => Some(OrientationTrack::Quaternion(q)),
                (None, Some(e)) => Some(OrientationTrack::YawPitchRollDeg(e)),
                (None, None) => None,
            };
            let inertial = s
                .inertial
                .finish(raw_start, spu, &mut dropped, &mut repaired);
            let magnetometer = s
                .magnetometer
                .finish(raw_start, spu, &mut dropped, &mut repaired);
            if orientation.is_some() || inertial.is_some() || magnetometer.is_some() {
                out.push(Sensor {
                    id,
                    orientation,
                    inertial,
                    magnetometer,
                });
            }
        }
        // Stable sorts keep a line's reports in the order they were made; a row carrying several
        // sensors is reported once.
        for reports in [&mut dropped, &mut repaired] {
            reports.sort_by(|a, b| (&a.file, a.line).cmp(&(&b.file, b.line)));
            reports.dedup();
        }

        if skip_seconds > 0.0 {
            let before: usize = out.iter().map(|s| s.primary_times_s().len()).sum();
            out = out
                .into_iter()
                .filter_map(|s| s.keep_from(skip_seconds))
                .collect();
            let after: usize = out.iter().map(|s| s.primary_times_s().len()).sum();
            warnings.push(format!(
                "--skip-seconds {skip_seconds}: {} samples before {skip_seconds} s skipped",
                before - after
            ));
            let new_zero = out
                .iter()
                .map(Sensor::first_time_s)
                .fold(f64::INFINITY, f64::min);
            if new_zero.is_finite() {
                for s in &mut out {
                    s.shift_times(new_zero);
                }
                raw_start += new_zero / spu;
            }
        }
        if out.is_empty() {
            return Err(BuildError::Empty { dropped });
        }
        Ok(Take {
            source: SourceInfo {
                path,
                format,
                world,
                start_timestamp: clock.describe(raw_start),
            },
            sensors: out,
            dropped_lines: dropped,
            repaired_lines: repaired,
            warnings,
        })
    }
}

impl Sensor {
    fn keep_from(self, start_s: f64) -> Option<Sensor> {
        let Sensor {
            id,
            orientation,
            inertial,
            magnetometer,
        } = self;
        let orientation = orientation.and_then(|o| o.keep_from(start_s));
        let inertial = inertial.and_then(|t| t.keep_from(start_s));
        let magnetometer = magnetometer.and_then(|t| t.keep_from(start_s));
        if orientation.is_none() && inertial.is_none() && magnetometer.is_none() {
            return None;
        }
        Some(Sensor {
            id,
            orientation,
            inertial,
            magnetometer,
        })
    }

    fn shift_times(&mut self, offset_s: f64) {
        if let Some(o) = &mut self.orientation {
            o.shift_times(offset_s);
        }
        if let Some(t) = &mut self.inertial {
            t.shift_times(offset_s);
        }
        if let Some(t) = &mut self.magnetometer {
            t.shift_times(offset_s);
        }
    }
}
