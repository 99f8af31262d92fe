//! Collects rows as readers parse them and turns them into a [`Take`].
//!
//! Readers push samples in file order with their line numbers; each stream of each sensor is
//! cleaned by the rules of [`super::sequence`] (late rows kept aside and sorted into place at the
//! end, reported as repaired; repeated times dropped; a jump of more than [`CLOCK_RESET_S`]
//! judged by the rows after it: a damaged timestamp dropped, a gap kept, a clock reset an error).
//!
//! So one damaged timestamp costs one sample, not the take.

use super::sequence::{Dropped, Held, Reset, Sequencer, Sink};
use super::{
    ImuSample, InputFormat, LineReport, OrientationTrack, Sensor, SourceInfo, Take, Track,
    YawPitchRollDeg,
};
use crate::world::World;
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::path::PathBuf;

/// A step back in time larger than this (seconds) is a clock reset, not a late row; a jump
/// larger than this either way is looked at with the rows that follow it.
pub const CLOCK_RESET_S: f64 = 1.0;

pub(crate) const OUT_OF_SEQUENCE: &str = "time out of sequence: more than 1 s from the previous sample of \
     the same sensor, while the samples after it continue from that one; dropped";

pub(crate) const REPEATED_TIME: &str =
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
pub struct SensorIdx(pub(crate) usize);

impl SensorIdx {
    /// The position of the sensor, in the order sensors were first named.
    pub fn index(self) -> usize {
        self.0
    }
}

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

/// What a stream did with a row besides keeping it in order.
enum Event {
    Dropped(Dropped),
    /// Earlier than the previous row: sorted into place at the end.
    Late,
}

/// One stream of one sensor: the rows kept in order, the late ones to sort into place at the
/// end, and the rules' state.
struct Stream<T> {
    raw_times: Vec<f64>,
    values: Vec<T>,
    late: Vec<Held<T>>,
    sequencer: Sequencer<T>,
}

/// A stream's storage and the builder's events, as the sequencer's sink.
struct Store<'a, T> {
    raw_times: &'a mut Vec<f64>,
    values: &'a mut Vec<T>,
    late: &'a mut Vec<Held<T>>,
    events: &'a mut Vec<Event>,
}

impl<T> Sink<T> for Store<'_, T> {
    #[inline]
    fn keep(&mut self, raw_time: f64, value: T) {
        self.raw_times.push(raw_time);
        self.values.push(value);
    }

    fn late(&mut self, row: Held<T>) {
        self.late.push(row);
        self.events.push(Event::Late);
    }

    fn dropped(&mut self, row: Dropped) {
        self.events.push(Event::Dropped(row));
    }
}

impl<T> Stream<T> {
    fn new(reset_units: f64) -> Self {
        Stream {
            raw_times: Vec::new(),
            values: Vec::new(),
            late: Vec::new(),
            sequencer: Sequencer::new(reset_units),
        }
    }

    fn parts<'a>(&'a mut self, events: &'a mut Vec<Event>) -> (&'a mut Sequencer<T>, Store<'a, T>) {
        let Stream {
            raw_times,
            values,
            late,
            sequencer,
        } = self;
        (
            sequencer,
            Store {
                raw_times,
                values,
                late,
                events,
            },
        )
    }

    /// Takes a row in file order. `report` is called only when the row must be held or reported.
    #[inline]
    fn push(
        &mut self,
        raw_time: f64,
        value: T,
        report: impl FnOnce() -> LineReport,
        events: &mut Vec<Event>,
    ) -> Result<(), Reset> {
        let (sequencer, mut store) = self.parts(events);
        sequencer.push(raw_time, value, report, &mut store)
    }

    /// Decides the rows still held at the end of the source.
    fn flush(&mut self, events: &mut Vec<Event>) -> Result<(), Reset> {
        let (sequencer, mut store) = self.parts(events);
        sequencer.flush(&mut store)
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

/// A raw time and whether the left and right foot are planted then.
pub type ContactSample = (f64, [bool; 2]);

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
    /// Scratch for what a push did besides keeping the row.
    events: Vec<Event>,
    /// Recalibrations recorded by a live session, seconds since its first sample.
    recalibrations: Vec<f64>,
    /// A capture system's own foot contacts: who, and (raw time, [left, right] planted).
    vendor_contacts: Option<(&'static str, Vec<ContactSample>)>,
}

/// Moves a stream's events into the dropped lines (late rows are reported when merged).
fn settle_events(events: &mut Vec<Event>, dropped: &mut Vec<LineReport>) {
    for event in events.drain(..) {
        let report = match event {
            Event::Dropped(dropped) => dropped_report(dropped),
            Event::Late => continue,
        };
        // A row carrying several sensors (a SOU line) is reported once.
        if dropped.last() != Some(&report) {
            dropped.push(report);
        }
    }
}

/// The line report of a dropped row, with its reason.
pub(crate) fn dropped_report(dropped: Dropped) -> LineReport {
    match dropped {
        Dropped::Duplicate(r) => LineReport {
            reason: REPEATED_TIME.to_string(),
            ..r
        },
        Dropped::OutOfSequence(r) => LineReport {
            reason: OUT_OF_SEQUENCE.to_string(),
            ..r
        },
    }
}

pub(crate) fn clock_reset(sensor: &str, r: Reset, seconds_per_unit: f64) -> BuildError {
    BuildError::ClockReset {
        location: r.report.location(),
        sensor: sensor.to_string(),
        previous: r.previous,
        time: r.time,
        back_s: (r.previous - r.time) * seconds_per_unit,
    }
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
            events: Vec::new(),
            recalibrations: Vec::new(),
            vendor_contacts: None,
        }
    }

    /// A recalibration a live session recorded (`# calibrate t=…`): the mapping's pose held
    /// again from `t_s`, seconds since the first sample.
    /// The capture system's own foot contacts, at raw times in the take's clock unit.
    pub fn set_vendor_contacts(&mut self, vendor: &'static str, samples: Vec<ContactSample>) {
        self.vendor_contacts = Some((vendor, samples));
    }

    pub fn recalibrate_at(&mut self, t_s: f64) {
        self.recalibrations.push(t_s);
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
            orientation_q: Stream::new(self.reset_units),
            orientation_ypr: Stream::new(self.reset_units),
            inertial: Stream::new(self.reset_units),
            magnetometer: Stream::new(self.reset_units),
        });
        self.by_id.insert(id.to_string(), idx);
        idx
    }

    pub fn sensor_count(&self) -> usize {
        self.sensors.len()
    }

    /// Reserves room for `additional` more samples in every stream that already holds samples
    /// (readers that can estimate their row count call it after their first rows: a growing
    /// stream of a large log would otherwise copy itself and touch fresh memory at each doubling).
    pub fn reserve(&mut self, additional: usize) {
        fn reserve<T>(stream: &mut Stream<T>, additional: usize) {
            if !stream.values.is_empty() {
                stream.raw_times.reserve(additional);
                stream.values.reserve(additional);
            }
        }
        for s in &mut self.sensors {
            reserve(&mut s.orientation_q, additional);
            reserve(&mut s.orientation_ypr, additional);
            reserve(&mut s.inertial, additional);
            reserve(&mut s.magnetometer, additional);
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
        let make_report = || LineReport::new(file, line, String::new(), raw);
        let sensor_streams = &mut self.sensors[sensor.0];
        let pushed = stream(sensor_streams).push(raw_time, value, make_report, &mut self.events);
        let id = &self.sensors[sensor.0].id;
        // Most rows make no event: no drain to set up and tear down for them.
        if !self.events.is_empty() {
            settle_events(&mut self.events, &mut self.dropped);
        }
        pushed.map_err(|r| clock_reset(id, r, self.clock.seconds_per_unit()))
    }

    /// Finishes the take: merges late rows, re-zeroes the clock at the earliest sample, and drops
    /// samples before `skip_seconds` (then re-zeroes at the earliest kept one).
    pub fn finish(self, skip_seconds: f64) -> Result<Take, BuildError> {
        let TakeBuilder {
            path,
            format,
            world,
            clock,
            mut sensors,
            mut dropped,
            mut repaired,
            mut warnings,
            mut events,
            mut recalibrations,
            vendor_contacts,
            ..
        } = self;
        // Rows still held after a jump at the end of the source.
        for s in &mut sensors {
            let flushed = s
                .orientation_q
                .flush(&mut events)
                .and_then(|()| s.orientation_ypr.flush(&mut events))
                .and_then(|()| s.inertial.flush(&mut events))
                .and_then(|()| s.magnetometer.flush(&mut events));
            settle_events(&mut events, &mut dropped);
            flushed.map_err(|r| clock_reset(&s.id, r, clock.seconds_per_unit()))?;
        }
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
                for t in &mut recalibrations {
                    *t -= new_zero;
                }
                recalibrations.retain(|t| *t >= 0.0);
            }
        }
        if out.is_empty() {
            return Err(BuildError::Empty { dropped });
        }
        // On the take's clock (t = 0 at the earliest kept sample), in time order, from t = 0.
        let vendor_contacts = vendor_contacts.and_then(|(vendor, mut samples)| {
            samples.sort_by(|a, b| a.0.total_cmp(&b.0));
            let (times_s, planted): (Vec<f64>, Vec<[bool; 2]>) = samples
                .into_iter()
                .map(|(raw, p)| ((raw - raw_start) * spu, p))
                .filter(|(t, _)| t.is_finite() && *t >= -1e-9)
                .unzip();
            (!times_s.is_empty()).then_some(crate::take::VendorContacts {
                vendor,
                times_s,
                planted,
            })
        });
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
            recalibrations_s: {
                recalibrations.sort_by(f64::total_cmp);
                recalibrations
            },
            vendor_contacts,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::take::OrientationTrack;

    /// A one-sensor take from raw times in seconds, one row per line (line n + 1).
    fn take_of(times: &[f64]) -> Result<Take, BuildError> {
        let mut b = TakeBuilder::new(
            "t.csv",
            InputFormat::ImubakeCsv,
            World::Enu,
            ClockUnit::Seconds,
        );
        let s = b.sensor("a");
        for (i, &t) in times.iter().enumerate() {
            let line = format!("{t},a");
            b.push_yaw_pitch_roll(
                s,
                t,
                YawPitchRollDeg {
                    yaw: i as f64,
                    pitch: 0.0,
                    roll: 0.0,
                },
                i as u64 + 1,
                line.as_bytes(),
            )?;
        }
        b.finish(0.0)
    }

    /// The kept samples as (absolute raw time, yaw = index of the row that carried it).
    fn kept(take: &Take) -> Vec<(f64, usize)> {
        let zero: f64 = take
            .source()
            .start_timestamp
            .trim_end_matches(" s")
            .parse()
            .unwrap();
        match take.sensors()[0].orientation() {
            Some(OrientationTrack::YawPitchRollDeg(t)) => t
                .iter()
                .map(|(time, v)| (((time + zero) * 1e6).round() / 1e6, v.yaw as usize))
                .collect(),
            _ => panic!("expected yaw/pitch/roll"),
        }
    }

    fn dropped_lines(take: &Take) -> Vec<u64> {
        take.dropped_lines().iter().map(|d| d.line).collect()
    }

    const STEADY: [f64; 12] = [
        10.0, 10.1, 10.2, 10.3, 10.4, 10.5, 10.6, 10.7, 10.8, 10.9, 11.0, 11.1,
    ];

    fn with(i: usize, t: f64) -> Vec<f64> {
        let mut v = STEADY.to_vec();
        v[i] = t;
        v
    }

    #[test]
    fn one_damaged_timestamp_costs_one_sample_forward_or_back() {
        for bad in [1000.0, 2.0, -5.0] {
            let take = take_of(&with(4, bad)).unwrap();
            assert_eq!(dropped_lines(&take), [5], "time {bad}");
            assert!(
                take.dropped_lines()[0]
                    .reason
                    .starts_with("time out of sequence")
            );
            let expected: Vec<(f64, usize)> = STEADY
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != 4)
                .map(|(i, &t)| (t, i))
                .collect();
            assert_eq!(kept(&take), expected, "time {bad}");
        }
    }

    #[test]
    fn a_damaged_first_or_last_row_is_dropped_too() {
        for (i, bad) in [(0, 5000.0), (0, 0.0), (11, 5000.0), (11, 1.0)] {
            let take = take_of(&with(i, bad)).unwrap();
            assert_eq!(dropped_lines(&take), [i as u64 + 1], "row {i} at {bad}");
            assert_eq!(kept(&take).len(), 11);
            assert!(kept(&take).iter().all(|&(_, k)| k != i));
        }
    }

    #[test]
    fn a_jump_the_following_rows_continue_is_a_gap_or_a_clock_reset() {
        // Forward by 30 s and on from there: a gap, every row kept.
        let gap: Vec<f64> = STEADY
            .iter()
            .enumerate()
            .map(|(i, &t)| if i >= 6 { t + 30.0 } else { t })
            .collect();
        let take = take_of(&gap).unwrap();
        assert!(take.dropped_lines().is_empty());
        assert_eq!(kept(&take).len(), 12);
        // Back by 5 s and on from there: the clock was reset at row 7 (line 7).
        let reset: Vec<f64> = STEADY
            .iter()
            .enumerate()
            .map(|(i, &t)| if i >= 6 { t - 5.0 } else { t })
            .collect();
        let e = take_of(&reset).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("line 7") && msg.contains("4.900 s"), "{msg}");
        // Even with only two rows after it.
        let e = take_of(&reset[..9]).unwrap_err();
        assert!(e.to_string().contains("line 7"), "{e}");
    }

    #[test]
    fn late_rows_and_repeats_after_a_damaged_row_keep_their_rules() {
        // Row 5 damaged, row 7 late by one step, row 9 repeats row 8.
        let mut times = with(4, 99.0);
        times.swap(6, 7);
        times[9] = times[8];
        let take = take_of(&times).unwrap();
        assert_eq!(dropped_lines(&take), [5, 10]);
        assert_eq!(take.repaired_lines().len(), 1);
        assert_eq!(take.repaired_lines()[0].line, 8);
    }
}
