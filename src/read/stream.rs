//! Lines of a capture as they arrive (a serial port, a datagram, a capture replayed), parsed by
//! the readers' own line parsers and fed to a [`TakeStream`]: the line-level cleaning of files
//! (a line that is not data is dropped and reported) then the stream's reorder buffer and
//! per-sensor rules.
//!
//! Formats: paper 002's SOU lines, and imubake CSV rows after their header line (and any
//! `# world:` comment before it). A CSV stream's lines before its header (a device's boot
//! messages, a `# world:` naming no world) are dropped lines with their reason, never the end of
//! the stream. Memory does not grow with the stream: at most
//! [`MAX_STREAM_SENSORS`](crate::take::MAX_STREAM_SENSORS) sensor ids (a line naming one more is
//! dropped), and dropped-line reports bounded ([`DroppedLines`]).

use super::{ReadError, imubake_csv, sou};
use crate::take::{
    ClockUnit, DEFAULT_REORDER_S, DroppedLines, LineReport, SensorIdx, StreamSample, StreamValue,
    TakeStream, YawPitchRollDeg,
};
use crate::world::World;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The line formats a stream can carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineFormat {
    Sou,
    ImubakeCsv,
}

impl LineFormat {
    /// The format a line shows, if it shows one: a SOU data line, or an imubake CSV header.
    /// Anything else (a SOU log's debug text, a CSV's `# world:` comment) says nothing yet.
    pub fn recognise(line: &[u8]) -> Option<LineFormat> {
        let t = line.trim_ascii();
        if t.is_empty() || t.starts_with(b"#") {
            return None;
        }
        if sou::format_problem(t).is_none() {
            return Some(LineFormat::Sou);
        }
        imubake_csv::Layout::from_header(t, Path::new(""), 0)
            .is_ok()
            .then_some(LineFormat::ImubakeCsv)
    }
}

/// What a CSV stream's recording holds for a line that came before the header: the line as it
/// came when a file's reader takes it there (blank, a comment, a `# world:` naming a world), else
/// the line behind `# dropped before the header: `, so that the recording reads as an imubake CSV
/// and still shows every byte that came.
pub fn recorded_before_header(line: &[u8]) -> std::borrow::Cow<'_, [u8]> {
    let t = line.trim_ascii();
    let fine = t.is_empty()
        || t.strip_prefix(b"#")
            .is_some_and(|c| !matches!(imubake_csv::world_directive(c), Some(Err(_))));
    if fine {
        return line.into();
    }
    let mut out = b"# dropped before the header: ".to_vec();
    out.extend_from_slice(line);
    out.into()
}

/// A SOU line without a timestamp of its own (`N0,yaw1,pitch1,roll1,yaw2,pitch2,roll2`, as some
/// node firmware sends), stamped with `ms` as paper 002's driver stamps it on arrival; `None`
/// for any other line.
fn stamp_untimed_sou(line: &[u8], ms: u64) -> Option<Vec<u8>> {
    let t = line.trim_ascii();
    if t.is_empty() || t[0].is_ascii_digit() {
        return None;
    }
    let mut stamped = format!("{ms},").into_bytes();
    stamped.extend_from_slice(t);
    sou::format_problem(&stamped).is_none().then_some(stamped)
}

/// Each data line's time, read by the same parsers as [`LineStream`] (for pacing a replayed
/// capture), and data lines restamped with another time (a live session's host clock).
#[derive(Debug, Default)]
pub struct LineClock {
    format: Option<LineFormat>,
    csv: Option<imubake_csv::Layout>,
}

impl LineClock {
    /// The line's time in seconds (the capture's clock), if it is a data line.
    pub fn time_s(&mut self, line: &[u8]) -> Option<f64> {
        self.see(line)?;
        match self.format? {
            LineFormat::Sou => sou::parse_line(line)
                .ok()
                .map(|(ms, _, _)| ms as f64 / 1000.0),
            LineFormat::ImubakeCsv => {
                let layout = self.csv.as_ref()?;
                let row = imubake_csv::parse_row(layout, line).ok()??;
                Some(row.values.time * layout.clock.seconds_per_unit())
            }
        }
    }

    /// The line with its time replaced by `t_s` seconds (in the line's own unit: whole
    /// milliseconds for SOU), if it is a data line.
    pub fn restamp(&mut self, line: &[u8], t_s: f64) -> Option<Vec<u8>> {
        self.time_s(line)?;
        let (column, value) = match self.format? {
            LineFormat::Sou => (0, format!("{}", (t_s * 1000.0).round() as u64)),
            LineFormat::ImubakeCsv => {
                let layout = self.csv.as_ref()?;
                let unit = layout.clock.seconds_per_unit();
                (layout.time_column(), format!("{:.6}", t_s / unit))
            }
        };
        Some(with_field(line, column, &value))
    }

    /// The data line's time column and the seconds of one tick of the time written there: a
    /// millisecond for SOU, a millionth of a CSV's unit (the six decimals `restamp` writes).
    fn time_column(&self) -> Option<(usize, f64)> {
        match self.format? {
            LineFormat::Sou => Some((0, 1e-3)),
            LineFormat::ImubakeCsv => {
                let layout = self.csv.as_ref()?;
                Some((layout.time_column(), layout.clock.seconds_per_unit() * 1e-6))
            }
        }
    }

    /// A data line's sensor id, as written.
    fn sensor<'l>(&mut self, line: &'l [u8]) -> Option<&'l [u8]> {
        self.see(line)?;
        match self.format? {
            LineFormat::Sou => sou::parse_line(line).ok().map(|(_, id, _)| id.as_bytes()),
            LineFormat::ImubakeCsv => {
                let row = imubake_csv::parse_row(self.csv.as_ref()?, line).ok()??;
                Some(row.id)
            }
        }
    }

    /// Learns the format and a CSV's header; `None` for a line that is not data.
    fn see(&mut self, line: &[u8]) -> Option<()> {
        if self.format.is_none() {
            self.format = Some(LineFormat::recognise(line)?);
        }
        if self.format == Some(LineFormat::ImubakeCsv) && self.csv.is_none() {
            let t = line.trim_ascii();
            if !t.starts_with(b"#") {
                self.csv = imubake_csv::Layout::from_header(t, Path::new(""), 0).ok();
            }
            return None;
        }
        Some(())
    }
}

/// A capture arriving line by line (see the module documentation).
pub struct LineStream {
    format: LineFormat,
    /// Names the stream in reports (a port, an address, a file).
    name: PathBuf,
    reorder_s: f64,
    /// Once the clock unit is known (at once for SOU, at the header for CSV).
    take: Option<TakeStream>,
    world: World,
    csv: Option<imubake_csv::Layout>,
    /// SOU id → its two nodes.
    nodes: HashMap<String, (SensorIdx, SensorIdx)>,
    /// CSV sensor id → its index.
    ids: HashMap<Vec<u8>, SensorIdx>,
    dropped: DroppedLines,
}

impl LineStream {
    /// A stream of `format` lines; `name` names it in reports; rows are reordered within
    /// `reorder_s` seconds ([`DEFAULT_REORDER_S`] by default).
    pub fn new(format: LineFormat, name: impl Into<PathBuf>, reorder_s: Option<f64>) -> Self {
        let reorder_s = reorder_s.unwrap_or(DEFAULT_REORDER_S);
        let (take, world) = match format {
            LineFormat::Sou => (
                Some(TakeStream::new(ClockUnit::Milliseconds, reorder_s)),
                World::Ned,
            ),
            LineFormat::ImubakeCsv => (None, World::Enu),
        };
        LineStream {
            format,
            name: name.into(),
            reorder_s,
            take,
            world,
            csv: None,
            nodes: HashMap::new(),
            ids: HashMap::new(),
            dropped: DroppedLines::default(),
        }
    }

    /// The sensors' world, as the format declares it (a CSV's `# world:` comment, else ENU;
    /// NED for SOU).
    pub fn world(&self) -> World {
        self.world
    }

    /// The stream of samples, once the format's clock is known.
    pub fn take(&self) -> Option<&TakeStream> {
        self.take.as_ref()
    }

    /// Lines dropped by the line parsers (the stream's own are in [`TakeStream::dropped_lines`]).
    pub fn dropped_lines(&self) -> &DroppedLines {
        &self.dropped
    }

    fn drop_line(&mut self, line_no: u64, reason: impl Into<String>, line: &[u8]) {
        self.dropped
            .push(LineReport::new(None, line_no, reason, line));
    }

    /// One line (without its line ending); the samples it lets out are appended to `out`.
    pub fn push_line(
        &mut self,
        line_no: u64,
        line: &[u8],
        out: &mut Vec<StreamSample>,
    ) -> Result<(), ReadError> {
        if line.trim_ascii().is_empty() {
            return Ok(());
        }
        match self.format {
            LineFormat::Sou => self.push_sou(line_no, line, out),
            LineFormat::ImubakeCsv => self.push_csv(line_no, line, out),
        }
    }

    fn push_sou(
        &mut self,
        line_no: u64,
        line: &[u8],
        out: &mut Vec<StreamSample>,
    ) -> Result<(), ReadError> {
        let (timestamp, id, angles) = match sou::parse_line(line) {
            Ok(row) => row,
            Err(problem) => {
                self.drop_line(line_no, problem, line);
                return Ok(());
            }
        };
        let take = self.take.as_mut().expect("a SOU stream's clock is known");
        let (n0, n1) = match self.nodes.get(id) {
            Some(&pair) => pair,
            None => {
                let (Some(n0), Some(n1)) = (
                    take.sensor(&format!("{id}_0")),
                    take.sensor(&format!("{id}_1")),
                ) else {
                    take.too_many_sensors(line_no, line);
                    return Ok(());
                };
                self.nodes.insert(id.to_string(), (n0, n1));
                (n0, n1)
            }
        };
        let ypr = |a: &[f64]| {
            StreamValue::YawPitchRoll(YawPitchRollDeg {
                yaw: a[0],
                pitch: a[1],
                roll: a[2],
            })
        };
        let t = timestamp as f64;
        let name = &self.name;
        let stream_error = |e| ReadError::take(name, e);
        take.push(n0, t, ypr(&angles[..3]), line_no, line, out)
            .map_err(stream_error)?;
        take.push(n1, t, ypr(&angles[3..]), line_no, line, out)
            .map_err(stream_error)
    }

    fn push_csv(
        &mut self,
        line_no: u64,
        line: &[u8],
        out: &mut Vec<StreamSample>,
    ) -> Result<(), ReadError> {
        let Some(layout) = &self.csv else {
            let t = line.trim_ascii();
            if let Some(comment) = t.strip_prefix(b"#") {
                match imubake_csv::world_directive(comment) {
                    Some(Ok(w)) => self.world = w,
                    Some(Err(e)) => self.drop_line(
                        line_no,
                        format!("before the CSV header: {e}; the world stays {}", self.world),
                        line,
                    ),
                    None => {}
                }
                return Ok(());
            }
            match imubake_csv::Layout::from_header(line, &self.name, line_no) {
                Ok(layout) => {
                    self.take = Some(TakeStream::new(layout.clock.clone(), self.reorder_s));
                    self.csv = Some(layout);
                }
                Err(_) => self.drop_line(
                    line_no,
                    "before the CSV header (a device's message?): not a header; dropped",
                    line,
                ),
            }
            return Ok(());
        };
        let row = match imubake_csv::parse_row(layout, line) {
            Ok(Some(row)) => row,
            Ok(None) => return Ok(()),
            Err(reason) => {
                self.drop_line(line_no, reason, line);
                return Ok(());
            }
        };
        let value = match (row.values.quaternion, row.values.ypr, row.values.imu) {
            (Some((q, _)), _, _) => StreamValue::Quaternion(q),
            (None, Some(ypr), _) => StreamValue::YawPitchRoll(ypr),
            // Raw readings, fused by the pose stream.
            (None, None, Some(imu)) => StreamValue::Raw {
                imu,
                mag: row.values.mag,
            },
            (None, None, None) => return Ok(()),
        };
        let take = self.take.as_mut().expect("the header set the clock");
        let sensor = match self.ids.get(row.id) {
            Some(&s) => s,
            None => {
                let Ok(name) = std::str::from_utf8(row.id) else {
                    self.dropped.push(LineReport::new(
                        None,
                        line_no,
                        "sensor is not UTF-8 text",
                        line,
                    ));
                    return Ok(());
                };
                let Some(s) = take.sensor(name) else {
                    take.too_many_sensors(line_no, line);
                    return Ok(());
                };
                self.ids.insert(row.id.to_vec(), s);
                s
            }
        };
        take.push(sensor, row.values.time, value, line_no, line, out)
            .map_err(|e| ReadError::take(&self.name, e))
    }

    /// The end of the stream: every row still held comes out.
    pub fn finish(&mut self, out: &mut Vec<StreamSample>) -> Result<(), ReadError> {
        match &mut self.take {
            Some(take) => take.finish(out).map_err(|e| ReadError::take(&self.name, e)),
            None => Ok(()),
        }
    }

    /// The name reports give the stream.
    pub fn name(&self) -> &Path {
        &self.name
    }
}

/// `line` with comma-separated field `column` replaced by `value`.
fn with_field(line: &[u8], column: usize, value: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(line.len() + 8);
    for (i, field) in line.split(|&b| b == b',').enumerate() {
        if i > 0 {
            out.push(b',');
        }
        if i == column {
            out.extend_from_slice(value.as_bytes());
        } else {
            out.extend_from_slice(field);
        }
    }
    out
}

/// Sensors whose last host stamp is kept; a stream naming more is not one body's sensors, and
/// the ones past this are stamped as the clock says.
const MAX_STAMPED_SENSORS: usize = 1024;

/// Data lines stamped with the host's clock on arrival, each sensor's stamps strictly rising.
///
/// One sensor's two samples cannot share a time, but the host can give them one: lines that
/// arrive in one read share their arrival, and SOU's stamps are whole milliseconds. The stream
/// keeps the first of a repeated time and drops the second, so a stamp not later than the
/// sensor's last becomes its last plus one tick (1 ms for SOU, 10⁻⁶ of a CSV's unit).
#[derive(Debug, Default)]
pub struct HostStamps {
    clock: LineClock,
    /// Each sensor's last stamp, in ticks of its line's time column.
    last: HashMap<Vec<u8>, u64>,
}

impl HostStamps {
    /// A data line stamped `t_s` seconds (the host's clock since the session started): an
    /// untimed SOU line given the time paper 002's driver would give it, any other data line's
    /// time replaced; `None` for a line that is not data.
    pub fn stamp(&mut self, line: &[u8], t_s: f64) -> Option<Vec<u8>> {
        match stamp_untimed_sou(line, 0) {
            Some(untimed) => self.restamp(&untimed, t_s),
            None => self.restamp(line, t_s),
        }
    }

    /// An untimed SOU line stamped as [`HostStamps::stamp`] stamps it; `None` for any other
    /// line (those keep their own clock).
    pub fn stamp_untimed(&mut self, line: &[u8], t_s: f64) -> Option<Vec<u8>> {
        let untimed = stamp_untimed_sou(line, 0)?;
        Some(self.restamp(&untimed, t_s).unwrap_or(untimed))
    }

    fn restamp(&mut self, line: &[u8], t_s: f64) -> Option<Vec<u8>> {
        let sensor = self.clock.sensor(line)?;
        let (column, tick_s) = self.clock.time_column()?;
        let mut ticks = (t_s.max(0.0) / tick_s).round() as u64;
        let room = self.last.len() < MAX_STAMPED_SENSORS;
        match self.last.get_mut(sensor) {
            Some(last) => {
                ticks = ticks.max(last.saturating_add(1));
                *last = ticks;
            }
            None if room => {
                self.last.insert(sensor.to_vec(), ticks);
            }
            None => {}
        }
        let value = match self.clock.format {
            Some(LineFormat::Sou) => ticks.to_string(),
            _ => format!("{}.{:06}", ticks / 1_000_000, ticks % 1_000_000),
        };
        Some(with_field(line, column, &value))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_before_a_header_are_recorded_as_a_file_reader_takes_them() {
        for kept in ["", "# a note", "# world: ned", "#world=nwu"] {
            assert_eq!(&*recorded_before_header(kept.as_bytes()), kept.as_bytes());
        }
        assert_eq!(
            &*recorded_before_header(b"Booting v1.2"),
            b"# dropped before the header: Booting v1.2"
        );
        assert_eq!(
            &*recorded_before_header(b"# world: mars"),
            b"# dropped before the header: # world: mars"
        );
    }

    #[test]
    fn formats_are_recognised_and_lines_restamped() {
        assert_eq!(LineFormat::recognise(b"Initializing I2C devices..."), None);
        assert_eq!(
            LineFormat::recognise(b"1042,N1,1.0,2.0,3.0,4.0,5.0,6.0"),
            Some(LineFormat::Sou)
        );
        assert_eq!(LineFormat::recognise(b"# world: ned"), None);
        assert_eq!(
            LineFormat::recognise(b"time_s,sensor,qw,qx,qy,qz"),
            Some(LineFormat::ImubakeCsv)
        );
        let mut sou = LineClock::default();
        assert_eq!(sou.time_s(b"debug text"), None);
        assert_eq!(sou.time_s(b"1042,N1,1.0,2.0,3.0,4.0,5.0,6.0"), Some(1.042));
        assert_eq!(
            sou.restamp(b"1042,N1,1.0,2.0,3.0,4.0,5.0,6.0", 2.5)
                .unwrap(),
            b"2500,N1,1.0,2.0,3.0,4.0,5.0,6.0"
        );
        let mut csv = LineClock::default();
        assert_eq!(csv.time_s(b"time_ms,sensor,qw,qx,qy,qz"), None);
        assert_eq!(csv.time_s(b"250,a,1,0,0,0"), Some(0.25));
        assert_eq!(
            csv.restamp(b"250,a,1,0,0,0", 1.5).unwrap(),
            b"1500.000000,a,1,0,0,0"
        );
        assert_eq!(csv.restamp(b"# a comment", 1.5), None);
        assert_eq!(
            stamp_untimed_sou(b"N1,1.0,2.0,3.0,4.0,5.0,6.0", 1042).unwrap(),
            b"1042,N1,1.0,2.0,3.0,4.0,5.0,6.0"
        );
        assert_eq!(
            stamp_untimed_sou(b"1042,N1,1.0,2.0,3.0,4.0,5.0,6.0", 7),
            None
        );
        assert_eq!(
            stamp_untimed_sou(b"Calibrating gyro... keep still", 7),
            None
        );
    }

    #[test]
    fn host_stamps_rise_for_each_sensor() {
        // Lines in turn through one source's stamps: (line, host clock in seconds, stamped).
        let expect = |cases: &[(&str, f64, &str)]| {
            let mut stamps = HostStamps::default();
            for &(line, t, stamped) in cases {
                let got = stamps.stamp(line.as_bytes(), t);
                let got = got.map(|g| String::from_utf8(g).unwrap());
                let want = (!stamped.is_empty()).then(|| stamped.to_string());
                assert_eq!(got, want, "{line} at {t}");
            }
            stamps
        };
        // Two lines of N1 in one millisecond: the second a millisecond later; N2 beside them
        // keeps the clock's time; a later clock passes the bumped stamp by; text is not stamped.
        let mut sou = expect(&[
            ("N1,1,2,3,4,5,6", 0.0104, "10,N1,1,2,3,4,5,6"),
            ("N1,1,2,3,4,5,6", 0.0096, "11,N1,1,2,3,4,5,6"),
            ("N2,1,2,3,4,5,6", 0.0096, "10,N2,1,2,3,4,5,6"),
            ("999,N1,1,2,3,4,5,6", 0.011, "12,N1,1,2,3,4,5,6"),
            ("N1,1,2,3,4,5,6", 0.020, "20,N1,1,2,3,4,5,6"),
            ("Calibrating gyro... keep still", 0.03, ""),
        ]);
        // Only untimed lines take the host's clock when the source's clock is kept.
        assert_eq!(sou.stamp_untimed(b"999,N1,1,2,3,4,5,6", 0.03), None);
        assert_eq!(
            sou.stamp_untimed(b"N1,1,2,3,4,5,6", 0.02).unwrap(),
            b"21,N1,1,2,3,4,5,6"
        );
        // A CSV in ms: six decimals of a millisecond, so a nanosecond tick.
        expect(&[
            ("time_ms,sensor,qw,qx,qy,qz", 0.0, ""),
            ("5,a,1,0,0,0", 1.5, "1500.000000,a,1,0,0,0"),
            ("6,a,1,0,0,0", 1.5, "1500.000001,a,1,0,0,0"),
            ("6,b,1,0,0,0", 1.5, "1500.000000,b,1,0,0,0"),
            ("7,a,1,0,0,0", 1.6, "1600.000000,a,1,0,0,0"),
        ]);
        // In seconds, a microsecond tick.
        expect(&[
            ("time_s,sensor,qw,qx,qy,qz", 0.0, ""),
            ("0.1,a,1,0,0,0", 2.25, "2.250000,a,1,0,0,0"),
            ("0.2,a,1,0,0,0", 2.25, "2.250001,a,1,0,0,0"),
        ]);
    }
}
