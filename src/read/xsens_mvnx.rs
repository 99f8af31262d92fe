//! Xsens MVN's MVNX export (XML, namespace `http://www.xsens.com/mvn/mvnx`, version 4), read as
//! it streams (`quick-xml`): a long take runs to gigabytes and is never held whole.
//!
//! ```text
//! <mvnx version="4"><subject frameRate="60" configuration="FullBody" …>
//!   <segments><segment label="Pelvis" id="1">…</segment>…</segments>
//!   <sensors><sensor label="Pelvis"/><sensor label="T8"/>…</sensors>
//!   <footContactDefinition><contactDefinition label="LeftFoot_Heel" index="0"/>…
//!   <frames …>
//!     <frame type="identity"|"tpose"|"tpose-isb" …>  (calibration: segments only, skipped)
//!     <frame time="17" index="1" tc="…" ms="1542082631859" type="normal">
//!       <orientation>w x y z …</orientation> … <footContacts>1 0 1 0</footContacts> …
//!       <sensorOrientation>w x y z …</sensorOrientation> …
//! ```
//!
//! - The sensors are the `<sensors>` list (each named after its segment: `Pelvis`, `T8`,
//!   `RightUpperArm`, …); each normal frame's `sensorOrientation` holds one w-first quaternion
//!   per sensor in that order: q_global_sensor.
//! - The world is MVN's global frame: x north (forward at MVN's calibration), y west, z up —
//!   `nwu`.
//! - Time: frame `index` / `frameRate` (the index keeps the original frame number, so a dropped
//!   frame leaves its gap), else `time` (milliseconds from the first frame).
//! - `footContacts` (LeftFoot_Heel, LeftFoot_Toe, RightFoot_Heel, RightFoot_Toe, 0 or 1) are kept
//!   as the take's vendor contacts: a foot is planted when its heel or toe is.
//! - Not read: segment kinematics, joint angles, `sensorFreeAcceleration` (global, gravity
//!   removed: not what an accelerometer measures) and `sensorMagneticField` (arbitrary units).
//!
//! A frame whose `sensorOrientation` is missing, short or holds a bad number is dropped and
//! reported with its line; a zero quaternion drops that sensor's sample. Malformed XML fails
//! with its line.

use super::{InputFormat, ReadError, ReadOptions, read_single_file, unit_quaternion};
use crate::take::{ClockUnit, ContactSample, LineReport, SensorIdx, Take, TakeBuilder};
use crate::world::World;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use quick_xml::events::{BytesStart, Event};
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// The namespace every MVNX element is in.
pub const NAMESPACE: &str = "http://www.xsens.com/mvn/mvnx";

/// True when the first bytes are an MVNX document: an `<mvnx` root element (after the XML
/// declaration and comments) or the MVNX namespace.
pub fn looks_like(head: &[u8]) -> bool {
    let text = String::from_utf8_lossy(head);
    text.contains("<mvnx") && (text.contains(NAMESPACE) || text.trim_start().starts_with("<?xml"))
}

pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    read_single_file(path, options, read_from)
}

/// A `BufRead` that counts the newlines the parser has consumed: the line of each event.
struct Counting<B> {
    inner: B,
    newlines: u64,
}

impl<B: BufRead> Read for Counting<B> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.newlines += memchr::memchr_iter(b'\n', &buf[..n]).count() as u64;
        Ok(n)
    }
}

impl<B: BufRead> BufRead for Counting<B> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        self.inner.fill_buf()
    }
    fn consume(&mut self, amt: usize) {
        if let Ok(buf) = self.inner.fill_buf() {
            let amt = amt.min(buf.len());
            self.newlines += memchr::memchr_iter(b'\n', &buf[..amt]).count() as u64;
        }
        self.inner.consume(amt);
    }
}

/// Which element's text the scanner is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Field {
    None,
    Orientation,
    Position,
    SensorOrientation,
    FootContacts,
}

/// What the document says before its frames.
#[derive(Debug, Default)]
pub(crate) struct Header {
    pub frame_rate: Option<f64>,
    /// `<sensors>` labels, in order.
    pub sensors: Vec<String>,
    /// `<segments>` labels, in order.
    pub segments: Vec<String>,
}

/// One `<frame>` as written: its attributes and the texts of the elements read.
#[derive(Debug, Default)]
pub(crate) struct RawFrame {
    /// `normal`, or a calibration frame's type (`identity`, `tpose`, `tpose-isb`).
    pub kind: String,
    pub line: u64,
    pub index: Option<f64>,
    pub time_ms: Option<f64>,
    /// The start tag, for reports.
    pub tag: String,
    pub orientation: Option<Vec<u8>>,
    pub position: Option<Vec<u8>>,
    pub sensor_orientation: Option<Vec<u8>>,
    pub contacts: Option<Vec<u8>>,
}

impl RawFrame {
    /// The frame's time, seconds: `index / frameRate`, else `time` (ms).
    pub fn time_s(&self, frame_rate: Option<f64>) -> Option<f64> {
        match (self.index, frame_rate, self.time_ms) {
            (Some(i), Some(rate), _) => Some(i / rate),
            (_, _, Some(ms)) => Some(ms / 1000.0),
            _ => None,
        }
    }
}

fn attribute(e: &BytesStart<'_>, name: &str) -> Option<String> {
    e.attributes()
        .flatten()
        .find(|a| a.key.local_name().into_inner() == name)
        .map(|a| a.value.to_string())
}

/// Whitespace-separated finite numbers; `None` if any is not one.
pub(crate) fn numbers(text: &[u8]) -> Option<Vec<f64>> {
    text.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| {
            fast_float2::parse::<f64, _>(t)
                .ok()
                .filter(|v| v.is_finite())
        })
        .collect()
}

/// Streams an MVNX document: `on_frame` hears each frame as it ends (the header complete by
/// then); `segments` says whether segment data (`orientation`, `position`) is kept. Malformed XML,
/// a root that is not `mvnx` and a repeated or empty sensor label are errors with their line.
pub(crate) fn scan(
    reader: impl Read,
    path: &Path,
    segments: bool,
    mut on_frame: impl FnMut(&Header, RawFrame) -> Result<(), ReadError>,
) -> Result<Header, ReadError> {
    let mut xml = quick_xml::Reader::from_reader(Counting {
        inner: BufReader::with_capacity(1 << 16, reader),
        newlines: 0,
    });
    xml.config_mut().trim_text(true);
    let mut buf = Vec::new();
    let mut header = Header::default();
    let mut in_sensors = false;
    let mut in_segments = false;
    let mut seen_root = false;
    let mut field = Field::None;
    let mut frame: Option<RawFrame> = None;
    let line_of = |xml: &quick_xml::Reader<Counting<BufReader<_>>>| xml.get_ref().newlines + 1;
    loop {
        let event = xml.read_event_into(&mut buf).map_err(|e| {
            ReadError::line(path, line_of(&xml), format!("not well-formed XML: {e}"))
        })?;
        let line = line_of(&xml);
        match event {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let empty = matches!(event, Event::Empty(_));
                let in_frame = frame.is_some();
                match e.local_name().into_inner() {
                    "mvnx" => seen_root = true,
                    _ if !seen_root => {
                        return Err(ReadError::line(
                            path,
                            line,
                            "not an MVNX document: the root element is not `mvnx`",
                        ));
                    }
                    "subject" => {
                        header.frame_rate = attribute(e, "frameRate")
                            .and_then(|v| v.trim().parse::<f64>().ok())
                            .filter(|v| v.is_finite() && *v > 0.0);
                    }
                    "sensors" if !empty => in_sensors = true,
                    "segments" if !empty => in_segments = true,
                    "sensor" if in_sensors => {
                        let label = attribute(e, "label").unwrap_or_default();
                        if label.is_empty() || header.sensors.contains(&label) {
                            return Err(ReadError::line(
                                path,
                                line,
                                format!("a sensor without a label, or a repeated one (`{label}`)"),
                            ));
                        }
                        header.sensors.push(label);
                    }
                    "segment" if in_segments => {
                        header
                            .segments
                            .push(attribute(e, "label").unwrap_or_default());
                    }
                    "frame" if !empty => {
                        frame = Some(RawFrame {
                            kind: attribute(e, "type").unwrap_or_default(),
                            line,
                            index: attribute(e, "index").and_then(|v| v.trim().parse().ok()),
                            time_ms: attribute(e, "time").and_then(|v| v.trim().parse().ok()),
                            tag: format!("<{}>", AsRef::<str>::as_ref(e)),
                            ..RawFrame::default()
                        });
                    }
                    "orientation" if in_frame && segments => field = Field::Orientation,
                    "position" if in_frame && segments => field = Field::Position,
                    "sensorOrientation" if in_frame => field = Field::SensorOrientation,
                    "footContacts" if in_frame => field = Field::FootContacts,
                    _ => {}
                }
            }
            Event::Text(ref t) => {
                if let Some(f) = &mut frame {
                    let text = || Some(AsRef::<str>::as_ref(t).as_bytes().to_vec());
                    match field {
                        Field::Orientation => f.orientation = text(),
                        Field::Position => f.position = text(),
                        Field::SensorOrientation => f.sensor_orientation = text(),
                        Field::FootContacts => f.contacts = text(),
                        Field::None => {}
                    }
                }
            }
            Event::End(ref e) => match e.local_name().into_inner() {
                "sensors" => in_sensors = false,
                "segments" => in_segments = false,
                "orientation" | "position" | "sensorOrientation" | "footContacts" => {
                    field = Field::None
                }
                "frame" => {
                    if let Some(f) = frame.take() {
                        on_frame(&header, f)?;
                    }
                }
                _ => {}
            },
            Event::Eof => break,
            _ => {}
        }
        buf.clear();
    }
    if !seen_root {
        return Err(ReadError::format(
            path,
            "not an MVNX document (no `mvnx` element)",
        ));
    }
    Ok(header)
}

/// Reads an MVNX document from any reader; `path` names it in reports.
pub fn read_from(reader: impl Read, path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    let world = options.world.unwrap_or(World::Nwu);
    let mut take = TakeBuilder::new(path, InputFormat::XsensMvnx, world, ClockUnit::Seconds);
    let mut sensors: Vec<SensorIdx> = Vec::new();
    let mut normal_frames = 0u64;
    let mut contacts: Vec<ContactSample> = Vec::new();
    let header = scan(reader, path, false, |header, f| {
        if sensors.len() != header.sensors.len() {
            sensors = header.sensors.iter().map(|l| take.sensor(l)).collect();
        }
        if f.kind == "normal" {
            normal_frames += 1;
            frame_done(
                path,
                &mut take,
                &f,
                header.frame_rate,
                &sensors,
                &mut contacts,
            )?;
        }
        Ok(())
    })?;
    if header.sensors.is_empty() {
        return Err(ReadError::format(
            path,
            "the MVNX file lists no sensors (`<sensors>`): nothing to animate from",
        ));
    }
    if normal_frames == 0 {
        return Err(ReadError::format(
            path,
            "the MVNX file has no normal frames",
        ));
    }
    take.set_vendor_contacts("xsens", contacts);
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

/// One normal frame into the take.
fn frame_done(
    path: &Path,
    take: &mut TakeBuilder,
    f: &RawFrame,
    frame_rate: Option<f64>,
    sensors: &[SensorIdx],
    contacts: &mut Vec<ContactSample>,
) -> Result<(), ReadError> {
    let raw = f.tag.as_bytes();
    let Some(t) = f.time_s(frame_rate) else {
        take.drop_line(f.line, "a frame with neither `index` nor `time`", raw);
        return Ok(());
    };
    let Some(values) = f.sensor_orientation.as_deref() else {
        take.drop_line(f.line, "a frame without `sensorOrientation`", raw);
        return Ok(());
    };
    let Some(values) = numbers(values) else {
        take.drop_line(
            f.line,
            "`sensorOrientation` holds a value that is not a number",
            raw,
        );
        return Ok(());
    };
    if values.len() != 4 * sensors.len() {
        take.drop_line(
            f.line,
            format!(
                "`sensorOrientation` has {} values; {} sensors need {}",
                values.len(),
                sensors.len(),
                4 * sensors.len()
            ),
            raw,
        );
        return Ok(());
    }
    for (q, &sensor) in values.chunks_exact(4).zip(sensors) {
        match unit_quaternion(Quaternion::new(q[0], q[1], q[2], q[3])) {
            Some((q, _)) => take
                .push_quaternion(sensor, t, q, f.line, raw)
                .map_err(|e| ReadError::take(path, e))?,
            None => take.drop_line(f.line, "a zero quaternion in `sensorOrientation`", raw),
        }
    }
    if let Some(c) = f.contacts.as_deref().and_then(numbers)
        && c.len() == 4
    {
        contacts.push((t, [c[0] > 0.5 || c[1] > 0.5, c[2] > 0.5 || c[3] > 0.5]));
    }
    Ok(())
}

/// Xsens's own segment kinematics (`convert --mvnx-segments`), in MVN's global frame (`nwu`,
/// metres): the segments in order, where each stands in the `identity` calibration frame (every
/// segment's axes those of the global frame: x forward, y left, z up), and per normal frame each
/// segment's orientation q_global_segment (w first in the file) and position.
#[derive(Debug, Clone)]
pub struct Segments {
    pub labels: Vec<String>,
    /// Positions in the `identity` frame: the rest layout.
    pub rest: Vec<Vector3<f64>>,
    /// Seconds from the first kept frame.
    pub times_s: Vec<f64>,
    /// `orientations[frame][segment]`.
    pub orientations: Vec<Vec<UnitQuaternion<f64>>>,
    pub positions: Vec<Vec<Vector3<f64>>>,
    /// Frames dropped, with their lines.
    pub dropped: Vec<LineReport>,
    /// Xsens's foot contacts at `times_s`.
    pub contacts: Vec<ContactSample>,
}

/// A kept frame's time, orientations, positions and contacts.
type SegmentFrame = (
    f64,
    Vec<UnitQuaternion<f64>>,
    Vec<Vector3<f64>>,
    Option<[bool; 2]>,
);

/// Reads the segment kinematics of an MVNX file. A normal frame whose `orientation` or
/// `position` is missing, has the wrong count or a zero quaternion is dropped with its line; no
/// `identity` frame, or no frame kept, is an error.
pub fn read_segments(path: &Path) -> Result<Segments, ReadError> {
    let file = std::fs::File::open(path).map_err(|e| ReadError::io(path, e))?;
    let mut rest: Option<Vec<Vector3<f64>>> = None;
    let mut kept: Vec<SegmentFrame> = Vec::new();
    let mut dropped = Vec::new();
    let vectors = |text: Option<&[u8]>, n: usize| -> Result<Vec<Vector3<f64>>, String> {
        let v =
            numbers(text.ok_or("no `position`")?).ok_or("a `position` value is not a number")?;
        if v.len() != 3 * n {
            return Err(format!(
                "`position` has {} values; {n} segments need {}",
                v.len(),
                3 * n
            ));
        }
        Ok(v.chunks_exact(3)
            .map(|p| Vector3::new(p[0], p[1], p[2]))
            .collect())
    };
    let header = scan(file, path, true, |header, f| {
        let n = header.segments.len();
        if f.kind == "identity" {
            rest = vectors(f.position.as_deref(), n).ok();
            return Ok(());
        }
        if f.kind != "normal" {
            return Ok(());
        }
        let frame = (|| -> Result<_, String> {
            let t = f
                .time_s(header.frame_rate)
                .ok_or("a frame with neither `index` nor `time`")?;
            let q = numbers(f.orientation.as_deref().ok_or("no `orientation`")?)
                .ok_or("an `orientation` value is not a number")?;
            if q.len() != 4 * n {
                return Err(format!(
                    "`orientation` has {} values; {n} segments need {}",
                    q.len(),
                    4 * n
                ));
            }
            let q = q
                .chunks_exact(4)
                .map(|q| unit_quaternion(Quaternion::new(q[0], q[1], q[2], q[3])).map(|u| u.0))
                .collect::<Option<Vec<_>>>()
                .ok_or("a zero quaternion in `orientation`")?;
            let p = vectors(f.position.as_deref(), n)?;
            let feet = f
                .contacts
                .as_deref()
                .and_then(numbers)
                .filter(|c| c.len() == 4)
                .map(|c| [c[0] + c[1] > 0.0, c[2] + c[3] > 0.0]);
            Ok((t, q, p, feet))
        })();
        match frame {
            Ok(frame) => {
                // Frames in time order; a repeated time keeps the first.
                if kept.last().is_none_or(|last| frame.0 > last.0) {
                    kept.push(frame);
                } else {
                    dropped.push(LineReport::new(
                        None,
                        f.line,
                        "a frame at or before the one before it",
                        f.tag.as_bytes(),
                    ));
                }
            }
            Err(reason) => dropped.push(LineReport::new(None, f.line, reason, f.tag.as_bytes())),
        }
        Ok(())
    })?;
    let rest = rest.ok_or_else(|| {
        ReadError::format(
            path,
            "no `identity` calibration frame with every segment's position: the segments' layout is unknown",
        )
    })?;
    let t0 = kept.first().map(|k| k.0).ok_or_else(|| {
        ReadError::format(
            path,
            "no normal frame with every segment's orientation and position",
        )
    })?;
    let mut segments = Segments {
        labels: header.segments,
        rest,
        times_s: Vec::with_capacity(kept.len()),
        orientations: Vec::with_capacity(kept.len()),
        positions: Vec::with_capacity(kept.len()),
        dropped,
        contacts: Vec::new(),
    };
    for (t, q, p, feet) in kept {
        segments.times_s.push(t - t0);
        segments.orientations.push(q);
        segments.positions.push(p);
        if let Some(feet) = feet {
            segments.contacts.push((t - t0, feet));
        }
    }
    Ok(segments)
}
