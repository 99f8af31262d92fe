//! Lines of a capture as they arrive (a serial port, a datagram, a capture replayed), parsed by
//! the readers' own line parsers and fed to a [`TakeStream`]: the line-level cleaning of files
//! (a line that is not data is dropped and reported) then the stream's reorder buffer and
//! per-sensor rules.
//!
//! Formats: paper 002's SOU lines, and imubake CSV rows after their header line (and any
//! `# world:` comment before it).

use super::{ReadError, imubake_csv, sou};
use crate::take::{
    ClockUnit, DEFAULT_REORDER_S, LineReport, SensorIdx, StreamSample, StreamValue, TakeStream,
    YawPitchRollDeg,
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

/// A SOU line without a timestamp of its own (`N0,yaw1,pitch1,roll1,yaw2,pitch2,roll2`, as some
/// node firmware sends), stamped with `ms` as paper 002's driver stamps it on arrival; `None`
/// for any other line.
pub fn stamp_untimed_sou(line: &[u8], ms: u64) -> Option<Vec<u8>> {
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
        Some(out)
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
    dropped: Vec<LineReport>,
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
            dropped: Vec::new(),
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
    pub fn dropped_lines(&self) -> &[LineReport] {
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
                let pair = (
                    take.sensor(&format!("{id}_0")),
                    take.sensor(&format!("{id}_1")),
                );
                self.nodes.insert(id.to_string(), pair);
                pair
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
                if let Some(w) = imubake_csv::world_directive(comment) {
                    self.world =
                        w.map_err(|e| ReadError::line(&self.name, line_no, e.to_string()))?;
                }
                return Ok(());
            }
            let layout = imubake_csv::Layout::from_header(line, &self.name, line_no)?;
            self.take = Some(TakeStream::new(layout.clock.clone(), self.reorder_s));
            self.csv = Some(layout);
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
                let s = take.sensor(name);
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
