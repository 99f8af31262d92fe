//! A take that arrives row by row (live capture): rows pass a bounded reorder buffer, then the
//! cleaning rules of files ([`super::sequence`]), and come out as samples on the take's clock as
//! soon as they are certain.
//!
//! - **Reorder buffer**: a row is held until the newest row received is more than the buffer's
//!   length (250 ms of stream time by default) later than it; rows are released in time order. A
//!   row older than the last row released can no longer be put in place: it is dropped and
//!   reported. Rows shuffled by less than the buffer's length therefore come out exactly as a
//!   file of the same rows would be read.
//! - **t = 0** is the first sample released (the earliest of the first buffer's worth), as a file's
//!   is its earliest sample; its raw time is [`TakeStream::start_timestamp`].
//! - **Order**: each sensor's samples come out in time order; a sensor's first sample comes out
//!   with its second (the rules keep a first row only once a row after it confirms it).
//! - **Cleaning**: each sensor's stream goes through the same rules as a file's (repeated times
//!   dropped, a damaged timestamp judged by the rows after it); a clock reset stops the stream
//!   with an error.
//!
//! Nothing is allocated per row once the buffer has grown to its working size; a row's text is
//! kept (cut to [`LineReport::TEXT_LIMIT`] bytes) only in case it must be reported.

use super::builder::{BuildError, CLOCK_RESET_S, ClockUnit, clock_reset, dropped_report};
use super::sequence::{Dropped, Held, Sequencer, Sink};
use super::{DroppedLines, ImuSample, LineReport, SensorIdx, YawPitchRollDeg};
use nalgebra::{UnitQuaternion, Vector3};
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

/// The default length of the reorder buffer, seconds of stream time.
pub const DEFAULT_REORDER_S: f64 = 0.25;

/// One sample as a stream carries it: an orientation, or raw readings to fuse.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StreamValue {
    /// `q_world_sensor`.
    Quaternion(UnitQuaternion<f64>),
    /// Yaw, pitch, roll in degrees, intrinsic Z-Y-X (SOU nodes).
    YawPitchRoll(YawPitchRollDeg),
    /// Gyroscope and accelerometer readings, and the magnetometer's when the row has one.
    Raw {
        imu: ImuSample,
        mag: Option<Vector3<f64>>,
    },
}

impl StreamValue {
    /// The orientation as a quaternion `q_world_sensor`; `None` for raw readings.
    pub fn orientation(self) -> Option<UnitQuaternion<f64>> {
        match self {
            StreamValue::Quaternion(q) => Some(q),
            StreamValue::YawPitchRoll(ypr) => Some(ypr.to_quaternion()),
            StreamValue::Raw { .. } => None,
        }
    }
}

/// A sample released by the stream, on the take's clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamSample {
    pub sensor: SensorIdx,
    /// Seconds since t = 0.
    pub t_s: f64,
    pub value: StreamValue,
}

/// A row's text, kept without allocating, for the report should it be dropped.
#[derive(Clone, Copy)]
struct RowText {
    bytes: [u8; LineReport::TEXT_LIMIT],
    len: u8,
}

impl RowText {
    fn new(raw: &[u8]) -> RowText {
        let mut bytes = [0u8; LineReport::TEXT_LIMIT];
        let len = raw.len().min(LineReport::TEXT_LIMIT);
        bytes[..len].copy_from_slice(&raw[..len]);
        RowText {
            bytes,
            len: len as u8,
        }
    }

    fn report(&self, line: u64, reason: &str) -> LineReport {
        LineReport::new(None, line, reason, &self.bytes[..self.len as usize])
    }
}

/// A row in the reorder buffer.
struct Pending {
    raw_time: f64,
    /// Arrival order, to release rows of equal times as they came.
    seq: u64,
    sensor: SensorIdx,
    value: StreamValue,
    line: u64,
    text: RowText,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    /// Reversed: the heap's top is the earliest row (then the first to arrive).
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .raw_time
            .total_cmp(&self.raw_time)
            .then(other.seq.cmp(&self.seq))
    }
}

const TOO_LATE: &str = "arrived after later samples had been released (the reorder buffer is \
     shorter than this row's delay); dropped";
const LATE_IN_SENSOR: &str = "earlier than the previous sample of the same sensor; dropped";
const NOT_FINITE: &str = "time is not a finite number; dropped";

/// Distinct sensor ids a stream keeps state for: a body has tens of sensors, so a stream naming
/// more is sending garbage ids, and each would cost its own rules' state.
pub const MAX_STREAM_SENSORS: usize = 1024;

/// The released samples of one push, and what was dropped.
struct Out<'a> {
    zero: f64,
    seconds_per_unit: f64,
    sensor: SensorIdx,
    samples: &'a mut Vec<StreamSample>,
    dropped: &'a mut DroppedLines,
}

impl Sink<StreamValue> for Out<'_> {
    #[inline]
    fn keep(&mut self, raw_time: f64, value: StreamValue) {
        self.samples.push(StreamSample {
            sensor: self.sensor,
            t_s: (raw_time - self.zero) * self.seconds_per_unit,
            value,
        });
    }

    fn late(&mut self, row: Held<StreamValue>) {
        self.dropped.push(LineReport {
            reason: LATE_IN_SENSOR.to_string(),
            ..row.report
        });
    }

    fn dropped(&mut self, row: Dropped) {
        // A row carrying several sensors (a SOU line) is reported once.
        self.dropped.push_unless_repeated(dropped_report(row));
    }
}

/// A take arriving row by row (see the module documentation).
pub struct TakeStream {
    clock: ClockUnit,
    seconds_per_unit: f64,
    reorder_units: f64,
    reset_units: f64,
    buffer: BinaryHeap<Pending>,
    seq: u64,
    /// The newest raw time received.
    newest: Option<f64>,
    /// The raw time of the last row released.
    released: Option<f64>,
    /// The raw time of t = 0.
    zero: Option<f64>,
    ids: Vec<String>,
    by_id: HashMap<String, SensorIdx>,
    sequencers: Vec<Sequencer<StreamValue>>,
    dropped: DroppedLines,
}

impl TakeStream {
    /// A stream whose raw times are in `clock`'s unit, with a reorder buffer of `reorder_s`
    /// seconds.
    pub fn new(clock: ClockUnit, reorder_s: f64) -> TakeStream {
        let seconds_per_unit = clock.seconds_per_unit();
        TakeStream {
            reorder_units: reorder_s.max(0.0) / seconds_per_unit,
            reset_units: CLOCK_RESET_S / seconds_per_unit,
            seconds_per_unit,
            clock,
            buffer: BinaryHeap::new(),
            seq: 0,
            newest: None,
            released: None,
            zero: None,
            ids: Vec::new(),
            by_id: HashMap::new(),
            sequencers: Vec::new(),
            dropped: DroppedLines::default(),
        }
    }

    /// The index of sensor `id`, added on first use; `None` once [`MAX_STREAM_SENSORS`] ids
    /// are known and `id` is not one of them (the caller drops its line,
    /// [`TakeStream::too_many_sensors`]).
    pub fn sensor(&mut self, id: &str) -> Option<SensorIdx> {
        if let Some(&idx) = self.by_id.get(id) {
            return Some(idx);
        }
        if self.ids.len() >= MAX_STREAM_SENSORS {
            return None;
        }
        let idx = SensorIdx(self.ids.len());
        self.ids.push(id.to_string());
        self.by_id.insert(id.to_string(), idx);
        self.sequencers.push(Sequencer::new(self.reset_units));
        Some(idx)
    }

    /// Reports a line dropped because its sensor id would be one too many.
    pub fn too_many_sensors(&mut self, line: u64, raw: &[u8]) {
        self.dropped.push(LineReport::new(
            None,
            line,
            format!(
                "a new sensor id past the stream's {MAX_STREAM_SENSORS} (garbage ids?); dropped"
            ),
            raw,
        ));
    }

    /// The sensors' ids, by index.
    pub fn sensor_ids(&self) -> &[String] {
        &self.ids
    }

    /// The source's own time of t = 0 (once the first sample is released).
    pub fn start_timestamp(&self) -> Option<String> {
        self.zero.map(|z| self.clock.describe(z))
    }

    /// Every line dropped so far (the first reports whole, then counts).
    pub fn dropped_lines(&self) -> &DroppedLines {
        &self.dropped
    }

    /// Takes a row as it arrives; the samples it lets out (in time order) are appended to
    /// `out`. `line` numbers the row in reports, `raw` is its text.
    pub fn push(
        &mut self,
        sensor: SensorIdx,
        raw_time: f64,
        value: StreamValue,
        line: u64,
        raw: &[u8],
        out: &mut Vec<StreamSample>,
    ) -> Result<(), BuildError> {
        if !raw_time.is_finite() {
            self.dropped
                .push(RowText::new(raw).report(line, NOT_FINITE));
            return Ok(());
        }
        if self.released.is_some_and(|r| raw_time < r) {
            self.dropped.push(RowText::new(raw).report(line, TOO_LATE));
            return Ok(());
        }
        self.newest = Some(self.newest.map_or(raw_time, |n| n.max(raw_time)));
        self.seq += 1;
        self.buffer.push(Pending {
            raw_time,
            seq: self.seq,
            sensor,
            value,
            line,
            text: RowText::new(raw),
        });
        let horizon = self.newest.unwrap_or(raw_time) - self.reorder_units;
        self.release(Some(horizon), out)
    }

    /// Releases every row at or before `horizon` (all of them for `None`).
    fn release(
        &mut self,
        horizon: Option<f64>,
        out: &mut Vec<StreamSample>,
    ) -> Result<(), BuildError> {
        while let Some(top) = self.buffer.peek() {
            if horizon.is_some_and(|h| top.raw_time > h) {
                break;
            }
            let row = self.buffer.pop().expect("peeked");
            self.released = Some(row.raw_time);
            let zero = *self.zero.get_or_insert(row.raw_time);
            let mut sink = Out {
                zero,
                seconds_per_unit: self.seconds_per_unit,
                sensor: row.sensor,
                samples: out,
                dropped: &mut self.dropped,
            };
            let (line, text) = (row.line, row.text);
            self.sequencers[row.sensor.0]
                .push(row.raw_time, row.value, || text.report(line, ""), &mut sink)
                .map_err(|r| clock_reset(&self.ids[row.sensor.0], r, self.seconds_per_unit))?;
        }
        Ok(())
    }

    /// The end of the stream: every row still held is released and decided.
    pub fn finish(&mut self, out: &mut Vec<StreamSample>) -> Result<(), BuildError> {
        self.release(None, out)?;
        let Some(zero) = self.zero else {
            return Ok(());
        };
        for (i, sequencer) in self.sequencers.iter_mut().enumerate() {
            let mut sink = Out {
                zero,
                seconds_per_unit: self.seconds_per_unit,
                sensor: SensorIdx(i),
                samples: out,
                dropped: &mut self.dropped,
            };
            sequencer
                .flush(&mut sink)
                .map_err(|r| clock_reset(&self.ids[i], r, self.seconds_per_unit))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn q(deg: f64) -> StreamValue {
        StreamValue::Quaternion(UnitQuaternion::from_axis_angle(
            &Vector3::z_axis(),
            deg.to_radians(),
        ))
    }

    /// (sensor, time, angle) of each sample, angles recovered from the quaternions.
    fn summary(stream: &TakeStream, samples: &[StreamSample]) -> Vec<(String, f64, f64)> {
        samples
            .iter()
            .map(|s| {
                let angle = s.value.orientation().unwrap().angle().to_degrees();
                (
                    stream.sensor_ids()[s.sensor.index()].clone(),
                    (s.t_s * 1e6).round() / 1e6,
                    (angle * 1e6).round() / 1e6,
                )
            })
            .collect()
    }

    #[test]
    fn rows_shuffled_within_the_buffer_come_out_in_order() {
        let mut stream = TakeStream::new(ClockUnit::Seconds, 0.25);
        let (a, b) = (stream.sensor("a").unwrap(), stream.sensor("b").unwrap());
        let mut out = Vec::new();
        // 10 Hz per sensor from t = 5 s; rows arrive up to 0.1 s out of order.
        let rows = [
            (a, 5.1, 1.0),
            (b, 5.05, 2.0),
            (a, 5.0, 3.0),
            (b, 5.15, 4.0),
            (a, 5.2, 5.0),
            (b, 5.25, 6.0),
            (a, 5.4, 7.0),
            (a, 5.3, 8.0),
            (b, 5.35, 9.0),
        ];
        for (i, (s, t, deg)) in rows.iter().enumerate() {
            stream
                .push(*s, *t, q(*deg), i as u64 + 1, b"row", &mut out)
                .unwrap();
        }
        // Nothing later than the newest minus 250 ms has come out yet.
        assert!(out.iter().all(|s| s.t_s <= 0.4 - 0.25 + 1e-9), "{out:?}");
        stream.finish(&mut out).unwrap();
        let got = summary(&stream, &out);
        // Each sensor's samples in time order (a sensor's first waits for its second).
        for id in ["a", "b"] {
            let times: Vec<f64> = got.iter().filter(|g| g.0 == id).map(|g| g.1).collect();
            assert!(times.windows(2).all(|w| w[0] < w[1]), "{got:?}");
        }
        assert_eq!(got.len(), 9);
        assert_eq!(got[0], ("a".into(), 0.0, 3.0));
        let a_angles: Vec<f64> = got.iter().filter(|g| g.0 == "a").map(|g| g.2).collect();
        assert_eq!(a_angles, [3.0, 1.0, 5.0, 8.0, 7.0]);
        assert_eq!(stream.start_timestamp().as_deref(), Some("5 s"));
        assert!(stream.dropped_lines().is_empty());
    }

    #[test]
    fn too_late_repeated_and_damaged_rows_are_dropped_and_reported() {
        let mut stream = TakeStream::new(ClockUnit::Seconds, 0.1);
        let a = stream.sensor("a").unwrap();
        let mut out = Vec::new();
        let mut line = 0;
        let mut push = |stream: &mut TakeStream, t: f64, out: &mut Vec<StreamSample>| {
            line += 1;
            stream
                .push(a, t, q(t), line, format!("{t},a").as_bytes(), out)
                .unwrap();
        };
        for k in 0..20 {
            push(&mut stream, k as f64 / 20.0, &mut out);
        }
        push(&mut stream, 0.3, &mut out); // 0.65 s late: released long ago
        push(&mut stream, 0.95, &mut out); // repeats a time still in the buffer
        push(&mut stream, 500.0, &mut out); // damaged
        for k in 20..40 {
            push(&mut stream, k as f64 / 20.0, &mut out);
        }
        stream.finish(&mut out).unwrap();
        let lines: Vec<(u64, &str)> = stream
            .dropped_lines()
            .reports()
            .iter()
            .map(|d| (d.line, d.reason.split(':').next().unwrap()))
            .collect();
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert_eq!(lines[0].0, 21);
        assert!(lines[0].1.starts_with("arrived after later samples"));
        assert_eq!(lines[1].0, 22);
        assert!(lines[1].1.starts_with("repeats the time"));
        assert_eq!(lines[2], (23, "time out of sequence"));
        assert_eq!(out.len(), 40);
    }
}
