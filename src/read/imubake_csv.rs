//! imubake's own CSV (README, "imubake CSV"): a header row, then one row per sensor sample.
//!
//! Columns (any order, names case-insensitive):
//! - time: exactly one of `time_s`, `time_ms`, `time_us`;
//! - `sensor`;
//! - orientation `qw,qx,qy,qz` (q_world_sensor, normalised on read) or `yaw,pitch,roll` (degrees,
//!   intrinsic Z-Y-X; `_deg` suffix accepted), and/or raw `gx,gy,gz,ax,ay,az[,mx,my,mz]` with
//!   optional unit suffixes (gyro `_rad_s` (default) or `_dps`; accelerometer `_m_s2` (default) or
//!   `_g`; magnetometer `_ut` (default), `_nt`, `_gauss`, or `_au` kept as is).
//!
//! Lines starting with `#` are comments; `# world: ned` before the header declares the world
//! (default `enu`). Blank lines are ignored.

use super::blocks::{BlockError, Observed, SpareVecs, lines_of, parse_in_blocks};
use super::lines::{LineReader, number_problem, parse_f64, plain_decimal_prefix, split_fields};
use super::{InputFormat, ReadError, ReadOptions, check_text, sniff, warn_if_denormalised};
use crate::take::{ClockUnit, ImuSample, SensorIdx, Take, TakeBuilder, YawPitchRollDeg};
use crate::world::World;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::convert::Infallible;
use std::fs::File;
use std::io::Read;
use std::path::Path;

/// Standard gravity, for accelerometer columns in g.
pub const STANDARD_GRAVITY_M_S2: f64 = 9.80665;

/// At most this many columns are looked at.
const MAX_COLUMNS: usize = 32;

const EXPECTED_COLUMNS: &str = "a time column (time_s, time_ms or time_us), `sensor`, and \
     qw,qx,qy,qz or yaw,pitch,roll or gx,gy,gz,ax,ay,az[,mx,my,mz]";

/// Column positions resolved from the header.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Layout {
    columns: usize,
    time: usize,
    pub(crate) clock: ClockUnit,
    sensor: usize,
    quaternion: Option<[usize; 4]>,
    ypr: Option<[usize; 3]>,
    gyro: Option<([usize; 3], f64)>,
    accel: Option<([usize; 3], f64)>,
    mag: Option<([usize; 3], f64)>,
    ignored: Vec<String>,
    /// What each column holds, for reading a row in one pass ([`plain_row`]).
    roles: Vec<Role>,
}

/// What a column holds for the row reader.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Role {
    /// A number the row's values are made of.
    Number,
    Sensor,
    /// Not read (an ignored column, or gyro columns without accelerometer ones).
    Skipped,
}

fn split_unit(name: &str) -> (&str, &str) {
    match name.find('_') {
        Some(i) => (&name[..i], &name[i + 1..]),
        None => (name, ""),
    }
}

fn gyro_scale(unit: &str) -> Option<f64> {
    match unit {
        "" | "rad_s" | "rads" | "radps" => Some(1.0),
        "dps" | "deg_s" | "degs" => Some(std::f64::consts::PI / 180.0),
        _ => None,
    }
}

fn accel_scale(unit: &str) -> Option<f64> {
    match unit {
        "" | "m_s2" | "ms2" | "mps2" => Some(1.0),
        "g" => Some(STANDARD_GRAVITY_M_S2),
        _ => None,
    }
}

fn mag_scale(unit: &str) -> Option<f64> {
    match unit {
        "" | "ut" | "au" => Some(1.0),
        "nt" => Some(1e-3),
        "gauss" | "ga" => Some(100.0),
        "mgauss" | "mga" => Some(0.1),
        _ => None,
    }
}

impl Layout {
    /// The index of the time column.
    pub(crate) fn time_column(&self) -> usize {
        self.time
    }

    pub(crate) fn from_header(header: &[u8], path: &Path, line: u64) -> Result<Layout, ReadError> {
        let text = std::str::from_utf8(header).map_err(|_| {
            ReadError::line(
                path,
                line,
                "header is not UTF-8 text; expected column names",
            )
        })?;
        let names: Vec<String> = text
            .split(',')
            .map(|n| n.trim().to_ascii_lowercase())
            .collect();
        if names.len() > MAX_COLUMNS {
            return Err(ReadError::line(
                path,
                line,
                format!(
                    "header has {} columns; at most {MAX_COLUMNS} are supported",
                    names.len()
                ),
            ));
        }
        let mut time = None;
        let mut sensor = None;
        let mut q = [None; 4];
        let mut ypr = [None; 3];
        let mut gyro = [None; 3];
        let mut accel = [None; 3];
        let mut mag = [None; 3];
        let mut ignored = Vec::new();
        let set = |slot: &mut Option<(usize, f64)>, i: usize, scale: f64, name: &str| {
            if slot.is_some() {
                return Err(ReadError::line(
                    path,
                    line,
                    format!("column `{name}` appears twice in the header"),
                ));
            }
            *slot = Some((i, scale));
            Ok(())
        };
        let mut time_slot: Option<(usize, f64)> = None;
        let mut sensor_slot: Option<(usize, f64)> = None;
        for (i, name) in names.iter().enumerate() {
            let (base, unit) = split_unit(name);
            let axis = |b: &str| match b.as_bytes().get(1) {
                Some(b'x') => Some(0),
                Some(b'y') => Some(1),
                Some(b'z') => Some(2),
                _ => None,
            };
            match (name.as_str(), base) {
                ("time_s" | "time_ms" | "time_us", _) => {
                    if time_slot.is_some() {
                        return Err(ReadError::line(
                            path,
                            line,
                            "header has more than one time column; expected one of time_s, time_ms, time_us",
                        ));
                    }
                    time_slot = Some((i, 0.0));
                    time = Some(match name.as_str() {
                        "time_s" => ClockUnit::Seconds,
                        "time_ms" => ClockUnit::Milliseconds,
                        _ => ClockUnit::Microseconds,
                    });
                }
                ("sensor", _) => set(&mut sensor_slot, i, 1.0, name)?,
                ("qw", _) => set(&mut q[0], i, 1.0, name)?,
                ("qx", _) => set(&mut q[1], i, 1.0, name)?,
                ("qy", _) => set(&mut q[2], i, 1.0, name)?,
                ("qz", _) => set(&mut q[3], i, 1.0, name)?,
                (_, "yaw" | "pitch" | "roll") if unit.is_empty() || unit == "deg" => {
                    let k = match base {
                        "yaw" => 0,
                        "pitch" => 1,
                        _ => 2,
                    };
                    set(&mut ypr[k], i, 1.0, name)?
                }
                (_, "gx" | "gy" | "gz") if gyro_scale(unit).is_some() => set(
                    &mut gyro[axis(base).unwrap_or(0)],
                    i,
                    gyro_scale(unit).unwrap_or(1.0),
                    name,
                )?,
                (_, "ax" | "ay" | "az") if accel_scale(unit).is_some() => set(
                    &mut accel[axis(base).unwrap_or(0)],
                    i,
                    accel_scale(unit).unwrap_or(1.0),
                    name,
                )?,
                (_, "mx" | "my" | "mz") if mag_scale(unit).is_some() => set(
                    &mut mag[axis(base).unwrap_or(0)],
                    i,
                    mag_scale(unit).unwrap_or(1.0),
                    name,
                )?,
                _ => ignored.push(name.clone()),
            }
        }
        sensor = sensor.or(sensor_slot.map(|s| s.0));
        let mut missing = Vec::new();
        if time.is_none() {
            missing.push("time_s|time_ms|time_us".to_string());
        }
        if sensor.is_none() {
            missing.push("sensor".to_string());
        }
        let group = |slots: &[Option<(usize, f64)>], names: &[&str], missing: &mut Vec<String>| {
            let present = slots.iter().filter(|s| s.is_some()).count();
            if present == 0 {
                None
            } else if present < slots.len() {
                for (slot, n) in slots.iter().zip(names) {
                    if slot.is_none() {
                        missing.push(n.to_string());
                    }
                }
                None
            } else {
                Some(
                    slots
                        .iter()
                        .map(|s| s.expect("all present"))
                        .collect::<Vec<_>>(),
                )
            }
        };
        let quaternion = group(&q, &["qw", "qx", "qy", "qz"], &mut missing)
            .map(|v| [v[0].0, v[1].0, v[2].0, v[3].0]);
        let ypr =
            group(&ypr, &["yaw", "pitch", "roll"], &mut missing).map(|v| [v[0].0, v[1].0, v[2].0]);
        let triple = |v: Vec<(usize, f64)>| ([v[0].0, v[1].0, v[2].0], v[0].1);
        let gyro = group(&gyro, &["gx", "gy", "gz"], &mut missing).map(triple);
        let accel = group(&accel, &["ax", "ay", "az"], &mut missing).map(triple);
        let mag = group(&mag, &["mx", "my", "mz"], &mut missing).map(triple);
        if gyro.is_some() != accel.is_some() {
            missing.push(
                if gyro.is_some() {
                    "ax,ay,az"
                } else {
                    "gx,gy,gz"
                }
                .to_string(),
            );
        }
        if quaternion.is_none() && ypr.is_none() && gyro.is_none() && missing.is_empty() {
            missing.push("qw,qx,qy,qz or yaw,pitch,roll or gx,gy,gz,ax,ay,az".to_string());
        }
        if !missing.is_empty() {
            return Err(ReadError::line(
                path,
                line,
                format!(
                    "header is missing column(s) {}; expected {EXPECTED_COLUMNS}",
                    missing.join(", ")
                ),
            ));
        }
        let (Some(time), Some(sensor), Some(clock)) = (time_slot.map(|t| t.0), sensor, time) else {
            unreachable!("missing columns were reported above");
        };
        let mut layout = Layout {
            columns: names.len(),
            time,
            clock,
            sensor,
            quaternion,
            ypr,
            gyro: gyro.filter(|_| accel.is_some()),
            accel,
            mag: mag.filter(|_| gyro.is_some()),
            ignored,
            roles: Vec::new(),
        };
        layout.roles = layout.roles();
        Ok(layout)
    }

    /// The quaternion's columns when a row holds nothing else but its time and sensor: every row
    /// is then a [`Packed::Quaternion`], which a plain row can go to directly
    /// ([`plain_quaternion_row`]).
    fn quaternion_only(&self) -> Option<[usize; 4]> {
        // A magnetometer without a gyro is read by neither path (`mag` is `None` then); a header
        // with only one of the gyro and the accelerometer is refused. Wider rows than
        // `parse_row` reads in one pass are left to it.
        match self {
            Layout {
                columns: ..=FEW_COLUMNS,
                quaternion: Some(columns),
                ypr: None,
                gyro: None,
                mag: None,
                ..
            } => Some(*columns),
            _ => None,
        }
    }

    /// The columns [`parse_row`] reads numbers from (the time, and those `row_values` asks
    /// for: found by asking it), the sensor's, and the rest.
    fn roles(&self) -> Vec<Role> {
        let mut roles = vec![Role::Skipped; self.columns];
        roles[self.sensor] = Role::Sensor;
        let read = std::cell::RefCell::new(vec![self.time]);
        let Ok(_) = row_values(self, |column| {
            read.borrow_mut().push(column);
            Ok::<f64, Infallible>(0.0)
        });
        for column in read.into_inner() {
            roles[column] = Role::Number;
        }
        roles
    }
}

/// True when the first non-comment line is an imubake CSV header.
pub fn looks_like(head: &[u8]) -> bool {
    let mut reader = LineReader::over(head);
    while let Ok(Some((_, line))) = reader.next_line() {
        let t = line.trim_ascii();
        if t.is_empty() || t.starts_with(b"#") {
            continue;
        }
        let lower = t.to_ascii_lowercase();
        let has = |name: &[u8]| lower.split(|&b| b == b',').any(|f| f.trim_ascii() == name);
        return (has(b"time_s") || has(b"time_ms") || has(b"time_us")) && has(b"sensor");
    }
    false
}

pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    read_observed(path, options, &mut |_| {})
}

/// [`read`], showing every byte of the file to `observe` in order as it is read (the caller's
/// SHA-256 of the source, without a second pass over the file).
pub fn read_observed(
    path: &Path,
    options: &ReadOptions,
    observe: &mut (dyn FnMut(&[u8]) + Send),
) -> Result<Take, ReadError> {
    check_text(path, &sniff(path)?)?;
    let file = File::open(path).map_err(|e| ReadError::io(path, e))?;
    let size_hint = file.metadata().map(|m| m.len()).unwrap_or(0);
    let source = Observed {
        inner: file,
        observe,
    };
    read_sized(source, size_hint, path, options)
}

/// Reads an imubake CSV from any reader; `path` names it in reports.
pub fn read_from(
    reader: impl Read + Send,
    path: &Path,
    options: &ReadOptions,
) -> Result<Take, ReadError> {
    read_sized(reader, 0, path, options)
}

/// Looks a sensor id up; the previous row's successor is tried first, as sensors usually take
/// turns. Past [`SensorTable::SCAN`] ids (a file naming thousands of garbage ids) a hash index
/// answers instead of a scan, so a lookup never costs a pass over every id.
struct SensorTable<T> {
    ids: Vec<(Box<[u8]>, T)>,
    next_guess: usize,
    /// Id → position in `ids`, once there are more than [`SensorTable::SCAN`].
    index: Option<std::collections::HashMap<Box<[u8]>, usize>>,
}

impl<T: Copy> SensorTable<T> {
    /// Ids looked up by a scan; a body's sensors are far fewer.
    const SCAN: usize = 64;

    fn new() -> Self {
        SensorTable {
            ids: Vec::new(),
            next_guess: 0,
            index: None,
        }
    }

    #[inline]
    fn find(&mut self, id: &[u8]) -> Option<T> {
        let n = self.ids.len();
        if n == 0 {
            return None;
        }
        let guess = self.next_guess % n;
        if *self.ids[guess].0 == *id {
            self.next_guess = guess + 1;
            return Some(self.ids[guess].1);
        }
        let pos = match &self.index {
            Some(index) => *index.get(id)?,
            None => self.ids.iter().position(|(k, _)| **k == *id)?,
        };
        self.next_guess = pos + 1;
        Some(self.ids[pos].1)
    }

    fn insert(&mut self, id: &[u8], value: T) {
        self.ids.push((id.into(), value));
        if let Some(index) = &mut self.index {
            index.insert(id.into(), self.ids.len() - 1);
        } else if self.ids.len() > Self::SCAN {
            self.index = Some(
                self.ids
                    .iter()
                    .enumerate()
                    .map(|(i, (k, _))| (k.clone(), i))
                    .collect(),
            );
        }
    }
}

/// Rows read before the per-sensor capacity is estimated from the file size.
const ROWS_BEFORE_RESERVE: u64 = 4096;

/// A line of a block as a worker parsed it; `line` counts from the block's first line, `span`
/// is the line's bytes in the block (for reports).
enum Item {
    Row {
        line: u32,
        span: (u32, u32),
        /// Index into the block's sensor ids.
        sensor: u32,
        values: Packed,
    },
    Dropped {
        line: u32,
        span: (u32, u32),
        reason: String,
    },
    /// A `#` line: a directive or a comment, decided when merged.
    Comment { line: u32, span: (u32, u32) },
}

/// A row's [`Values`] as they travel from a worker to the merge: blocks of items go through
/// memory, so the common rows (a quaternion only; raw readings only) are kept small and unboxed,
/// and any other row is boxed.
enum Packed {
    Quaternion {
        time: f64,
        q: UnitQuaternion<f64>,
        norm: f64,
    },
    Raw {
        time: f64,
        imu: ImuSample,
        mag: Option<Vector3<f64>>,
    },
    Other(Box<Values>),
}

impl From<Values> for Packed {
    fn from(values: Values) -> Packed {
        match values {
            Values {
                time,
                quaternion: Some((q, norm)),
                ypr: None,
                imu: None,
                mag: None,
            } => Packed::Quaternion { time, q, norm },
            Values {
                time,
                quaternion: None,
                ypr: None,
                imu: Some(imu),
                mag,
            } => Packed::Raw { time, imu, mag },
            values => Packed::Other(Box::new(values)),
        }
    }
}

impl From<Packed> for Values {
    fn from(packed: Packed) -> Values {
        match packed {
            Packed::Quaternion { time, q, norm } => Values {
                time,
                quaternion: Some((q, norm)),
                ypr: None,
                imu: None,
                mag: None,
            },
            Packed::Raw { time, imu, mag } => Values {
                time,
                quaternion: None,
                ypr: None,
                imu: Some(imu),
                mag,
            },
            Packed::Other(values) => *values,
        }
    }
}

/// The blocks' item lists go round like their buffers, and from one read to the next: emptied
/// by the merge, refilled by a worker (a raw log's list is over a megabyte, and fresh memory
/// costs page faults). Those of two reads at once on 2 cores; a list grown past 4 MiB (a block
/// of very short lines) is not kept.
static SPARE_ITEMS: SpareVecs<Item> = SpareVecs::new(16, 4 << 20);

/// A block's lines, parsed.
struct ParsedBlock {
    items: Vec<Item>,
    /// The sensor ids named in the block, in order of first appearance.
    ids: Vec<Box<[u8]>>,
}

/// Parses a block of whole lines (on any thread): everything about each line that does not
/// depend on the lines before it.
/// `items` is an emptied list from an earlier block, if there is one (its memory is reused).
fn parse_block(layout: &Layout, block: &[u8], mut items: Vec<Item>) -> (ParsedBlock, u64) {
    items.clear();
    items.reserve(block.len() / 40);
    let mut ids: SensorTable<u32> = SensorTable::new();
    let mut sensor_of = |id: &[u8]| {
        ids.find(id).unwrap_or_else(|| {
            let next = ids.ids.len() as u32;
            ids.insert(id, next);
            next
        })
    };
    let quaternion_only = layout.quaternion_only();
    let mut lines = 0;
    for (index, line) in lines_of(block) {
        lines += 1;
        let start = line.as_ptr() as usize - block.as_ptr() as usize;
        let span = (start as u32, (start + line.len()) as u32);
        let line_index = index as u32;
        if let Some(columns) = quaternion_only
            && let Some((id, values)) = plain_quaternion_row(layout, columns, line)
        {
            items.push(Item::Row {
                line: line_index,
                span,
                sensor: sensor_of(id),
                values,
            });
            continue;
        }
        if line.trim_ascii().starts_with(b"#") {
            items.push(Item::Comment {
                line: line_index,
                span,
            });
            continue;
        }
        match parse_row(layout, line) {
            Ok(None) => {}
            Err(reason) => items.push(Item::Dropped {
                line: line_index,
                span,
                reason,
            }),
            Ok(Some(Row { id, values })) => items.push(Item::Row {
                line: line_index,
                span,
                sensor: sensor_of(id),
                values: values.into(),
            }),
        }
    }
    let ids = ids.ids.into_iter().map(|(id, _)| id).collect();
    (ParsedBlock { items, ids }, lines)
}

/// A block's sensor id, once looked up in the take.
#[derive(Clone, Copy)]
enum Known {
    Unknown,
    Sensor(SensorIdx),
    NotUtf8,
}

fn read_sized(
    reader: impl Read + Send,
    size_hint: u64,
    path: &Path,
    options: &ReadOptions,
) -> Result<Take, ReadError> {
    let mut lines = LineReader::new(reader);
    let mut world = World::Enu;
    let mut layout = None;
    let mut header_line = 0;
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        let t = line.trim_ascii();
        if line_no <= options.skip_lines || t.is_empty() {
            continue;
        }
        if let Some(comment) = t.strip_prefix(b"#") {
            if let Some(w) = world_directive(comment) {
                world = w.map_err(|e| ReadError::line(path, line_no, e.to_string()))?;
            }
            continue;
        }
        layout = Some(Layout::from_header(line, path, line_no)?);
        header_line = line_no;
        break;
    }
    let Some(layout) = layout else {
        return Err(ReadError::format(
            path,
            format!("no header row found; expected {EXPECTED_COLUMNS}"),
        ));
    };
    let world = options.world.unwrap_or(world);
    let mut take = TakeBuilder::new(path, InputFormat::ImubakeCsv, world, layout.clock.clone());
    for name in &layout.ignored {
        take.warn(format!(
            "line {header_line}: column `{name}` is not an imubake CSV column; ignored"
        ));
    }
    // The data lines: parsed in blocks on every core, merged here in file order, so the take's
    // cleaning rules and line reports are exactly those of a line-by-line read. (The header
    // comes after --skip-lines, so no data line is skipped.)
    let mut bytes_before = lines.bytes_consumed();
    let (reader, pending) = lines.into_pending();
    let mut sensors: SensorTable<SensorIdx> = SensorTable::new();
    let mut rows: u64 = 0;
    let mut reserved = size_hint == 0;
    let mut worst_norm_error: f64 = 0.0;
    let merge = |first_line: u64, block: &[u8], mut parsed: ParsedBlock| -> Result<(), ReadError> {
        let mut known = vec![Known::Unknown; parsed.ids.len()];
        let raw = |(start, end): (u32, u32)| &block[start as usize..end as usize];
        for item in parsed.items.drain(..) {
            match item {
                Item::Comment { line, span } => {
                    let text = raw(span);
                    let comment = text.trim_ascii().strip_prefix(b"#").unwrap_or_default();
                    match super::calibrate_directive(comment) {
                        Some(Ok(t)) => take.recalibrate_at(t),
                        Some(Err(reason)) => {
                            take.drop_line(first_line + u64::from(line), reason, text)
                        }
                        None => {}
                    }
                }
                Item::Dropped { line, span, reason } => {
                    take.drop_line(first_line + u64::from(line), reason, raw(span))
                }
                Item::Row {
                    line,
                    span,
                    sensor,
                    values,
                } => {
                    let line_no = first_line + u64::from(line);
                    let text = raw(span);
                    let slot = &mut known[sensor as usize];
                    if let Known::Unknown = slot {
                        let id = &parsed.ids[sensor as usize];
                        *slot = match sensors.find(id) {
                            Some(s) => Known::Sensor(s),
                            None => match std::str::from_utf8(id) {
                                Ok(name) => {
                                    let idx = take.sensor(name);
                                    sensors.insert(id, idx);
                                    Known::Sensor(idx)
                                }
                                Err(_) => Known::NotUtf8,
                            },
                        };
                    }
                    let sensor = match *slot {
                        Known::Sensor(s) => s,
                        _ => {
                            take.drop_line(line_no, "sensor is not UTF-8 text", text);
                            continue;
                        }
                    };
                    let Values {
                        time,
                        quaternion,
                        ypr,
                        imu,
                        mag,
                    } = values.into();
                    let q = quaternion.map(|(q, norm)| {
                        worst_norm_error = worst_norm_error.max((norm - 1.0).abs());
                        q
                    });
                    let push = |r: Result<(), _>| r.map_err(|e| ReadError::take(path, e));
                    if let Some(q) = q {
                        push(take.push_quaternion(sensor, time, q, line_no, text))?;
                    }
                    if let Some(ypr) = ypr {
                        push(take.push_yaw_pitch_roll(sensor, time, ypr, line_no, text))?;
                    }
                    if let Some(imu) = imu {
                        push(take.push_inertial(sensor, time, imu, line_no, text))?;
                    }
                    if let Some(mag) = mag {
                        push(take.push_magnetometer(sensor, time, mag, line_no, text))?;
                    }
                    rows += 1;
                    if !reserved && rows == ROWS_BEFORE_RESERVE {
                        reserved = true;
                        let consumed = bytes_before + u64::from(span.1) + 1;
                        let bytes_per_row = consumed as f64 / line_no as f64;
                        let expected_rows = size_hint as f64 / bytes_per_row;
                        let per_sensor = expected_rows / take.sensor_count() as f64 * 1.02;
                        take.reserve(per_sensor as usize);
                    }
                }
            }
        }
        bytes_before += block.len() as u64;
        SPARE_ITEMS.give([parsed.items]);
        Ok(())
    };
    parse_in_blocks(
        reader,
        pending,
        header_line + 1,
        |block| parse_block(&layout, block, SPARE_ITEMS.take().unwrap_or_default()),
        merge,
    )
    .map_err(|e| match e {
        BlockError::Lines(e) => ReadError::lines(path, e),
        BlockError::Merge(e) => e,
    })?;
    warn_if_denormalised(&mut take, worst_norm_error, None);
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

/// One data row: its sensor id and values.
pub(crate) struct Row<'a> {
    /// The sensor id as written (trimmed, never empty).
    pub id: &'a [u8],
    pub values: Values,
}

/// A data row's values.
pub(crate) struct Values {
    pub time: f64,
    /// The quaternion normalised, and the norm it had.
    pub quaternion: Option<(UnitQuaternion<f64>, f64)>,
    pub ypr: Option<YawPitchRollDeg>,
    pub imu: Option<ImuSample>,
    pub mag: Option<Vector3<f64>>,
}

/// Parses a data row; `Ok(None)` for a blank or comment line, `Err` with the reason to drop it.
#[inline]
pub(crate) fn parse_row<'a>(layout: &Layout, line: &'a [u8]) -> Result<Option<Row<'a>>, String> {
    // The fields' slots are set up for every row: as few as the layout needs.
    if layout.columns <= FEW_COLUMNS {
        parse_row_in::<FEW_COLUMNS>(layout, line)
    } else {
        parse_row_in::<MAX_COLUMNS>(layout, line)
    }
}

/// Enough fields for quaternions, or raw readings with their time and sensor.
const FEW_COLUMNS: usize = 12;

#[inline]
fn parse_row_in<'a, const N: usize>(
    layout: &Layout,
    line: &'a [u8],
) -> Result<Option<Row<'a>>, String> {
    if N == FEW_COLUMNS
        && let Some((id, numbers)) = plain_row(layout, line)
    {
        let Ok((q, ypr, imu, mag)) = row_values(layout, |i| Ok::<f64, Infallible>(numbers[i]));
        return row(id, numbers[layout.time], q, ypr, imu, mag).map(Some);
    }
    let first = line.iter().find(|b| !b.is_ascii_whitespace());
    match first {
        None | Some(b'#') => return Ok(None),
        _ => {}
    }
    let mut fields = [&b""[..]; N];
    let n = split_fields(line, b',', &mut fields);
    if n != layout.columns {
        return Err(format!(
            "expected {} comma-separated fields as in the header, found {n}",
            layout.columns
        ));
    }
    let number = |i: usize| parse_f64(fields[i]).ok_or(i);
    let time = number(layout.time).map_err(|i| format!("time {}", number_problem(fields[i])))?;
    let id = fields[layout.sensor].trim_ascii();
    if id.is_empty() {
        return Err("sensor is empty".into());
    }
    let (q, ypr, imu, mag) = row_values(layout, number).map_err(|i: usize| {
        format!(
            "column {} {}",
            column_name(layout, i),
            number_problem(fields[i])
        )
    })?;
    row(id, time, q, ypr, imu, mag).map(Some)
}

/// A row whose fields are all written plainly — every number read as
/// [`plain_decimal_prefix`] reads it, the sensor id without spaces around it — read in one pass
/// over the line instead of split first: the rows of a long log. `None` for any other line
/// (blank, a comment, spaces, exponents, a wrong field count, …), which the general reader
/// then reads; where this reads a row, the general reader reads the same numbers and id.
/// The numbers are at their column's index.
#[inline]
fn plain_row<'a>(layout: &Layout, line: &'a [u8]) -> Option<(&'a [u8], [f64; FEW_COLUMNS])> {
    // A first byte that is a space or `#` may make a blank or comment line.
    if line
        .first()
        .is_none_or(|&b| b == b'#' || b.is_ascii_whitespace())
    {
        return None;
    }
    let mut numbers = [0.0; FEW_COLUMNS];
    let mut id: &[u8] = b"";
    let mut at = 0;
    let last = layout.roles.len().checked_sub(1)?;
    for (column, role) in layout.roles.iter().enumerate() {
        let end = match role {
            Role::Number => {
                let (value, end) = plain_decimal_prefix(line, at)?;
                *numbers.get_mut(column)? = value;
                end
            }
            Role::Sensor | Role::Skipped => {
                let end = line[at..]
                    .iter()
                    .position(|&b| b == b',')
                    .map_or(line.len(), |p| at + p);
                if *role == Role::Sensor {
                    id = &line[at..end];
                    let (first, last) = (id.first()?, id.last()?);
                    if first.is_ascii_whitespace() || last.is_ascii_whitespace() {
                        return None;
                    }
                }
                end
            }
        };
        if column == last {
            return (end == line.len()).then_some((id, numbers));
        }
        if line.get(end) != Some(&b',') {
            return None;
        }
        at = end + 1;
    }
    None
}

/// What [`parse_row`] makes of a plain row of a quaternion-only layout (`columns`: the
/// quaternion's), as a block keeps it, without the general row's optional parts made and moved
/// around (~15 ns of a row's ~90): the same numbers and [`normalised`] as [`row`]. `None` where
/// `parse_row` must decide: not a plain row, or a zero quaternion (dropped, with its reason).
#[inline]
fn plain_quaternion_row<'a>(
    layout: &Layout,
    columns: [usize; 4],
    line: &'a [u8],
) -> Option<(&'a [u8], Packed)> {
    let (id, numbers) = plain_row(layout, line)?;
    let [w, x, y, z] = columns.map(|c| numbers[c]);
    let (q, norm) = normalised(Quaternion::new(w, x, y, z))?;
    let time = numbers[layout.time];
    Some((id, Packed::Quaternion { time, q, norm }))
}

/// A row's values (but the time) from its number columns, in the general reader's order, so
/// the first bad column is the one reported.
#[allow(clippy::type_complexity)]
#[inline]
fn row_values<E>(
    layout: &Layout,
    number: impl Fn(usize) -> Result<f64, E>,
) -> Result<
    (
        Option<Quaternion<f64>>,
        Option<YawPitchRollDeg>,
        Option<ImuSample>,
        Option<Vector3<f64>>,
    ),
    E,
> {
    let mut q = None;
    if let Some(c) = layout.quaternion {
        q = Some(Quaternion::new(
            number(c[0])?,
            number(c[1])?,
            number(c[2])?,
            number(c[3])?,
        ));
    }
    let mut ypr = None;
    if let Some(c) = layout.ypr {
        ypr = Some(YawPitchRollDeg {
            yaw: number(c[0])?,
            pitch: number(c[1])?,
            roll: number(c[2])?,
        });
    }
    let vec3 = |(c, scale): ([usize; 3], f64)| -> Result<Vector3<f64>, E> {
        Ok(Vector3::new(number(c[0])?, number(c[1])?, number(c[2])?) * scale)
    };
    let mut imu = None;
    if let (Some(g), Some(a)) = (layout.gyro, layout.accel) {
        imu = Some(ImuSample {
            gyro_rad_s: vec3(g)?,
            accel_m_s2: vec3(a)?,
        });
    }
    let mag = layout.mag.map(vec3).transpose()?;
    Ok((q, ypr, imu, mag))
}

/// The row, its quaternion normalised (with the norm it had).
#[inline]
fn row(
    id: &[u8],
    time: f64,
    q: Option<Quaternion<f64>>,
    ypr: Option<YawPitchRollDeg>,
    imu: Option<ImuSample>,
    mag: Option<Vector3<f64>>,
) -> Result<Row<'_>, String> {
    let quaternion = match q {
        Some(q) => Some(normalised(q).ok_or_else(|| {
            "quaternion is zero; expected a unit quaternion qw,qx,qy,qz".to_string()
        })?),
        None => None,
    };
    Ok(Row {
        id,
        values: Values {
            time,
            quaternion,
            ypr,
            imu,
            mag,
        },
    })
}

/// A row's quaternion normalised, and the norm it had; `None` for a zero quaternion.
#[inline]
fn normalised(q: Quaternion<f64>) -> Option<(UnitQuaternion<f64>, f64)> {
    let norm = q.norm();
    if norm < 1e-9 {
        return None;
    }
    Some((UnitQuaternion::new_unchecked(q / norm), norm))
}

fn column_name(layout: &Layout, index: usize) -> String {
    let named: [(&str, Option<&[usize]>); 5] = [
        ("qw,qx,qy,qz", layout.quaternion.as_ref().map(|c| &c[..])),
        ("yaw,pitch,roll", layout.ypr.as_ref().map(|c| &c[..])),
        ("gx,gy,gz", layout.gyro.as_ref().map(|c| &c.0[..])),
        ("ax,ay,az", layout.accel.as_ref().map(|c| &c.0[..])),
        ("mx,my,mz", layout.mag.as_ref().map(|c| &c.0[..])),
    ];
    for (names, cols) in named {
        if let Some(k) = cols.and_then(|c| c.iter().position(|&c| c == index)) {
            return names.split(',').nth(k).unwrap_or(names).to_string();
        }
    }
    format!("{}", index + 1)
}

/// Parses `world: ned` / `world = ned` in a comment; `None` when the comment is something else.
pub(crate) fn world_directive(comment: &[u8]) -> Option<Result<World, crate::world::UnknownWorld>> {
    let text = std::str::from_utf8(comment).ok()?.trim();
    let rest = text.strip_prefix("world")?.trim_start();
    let value = rest.strip_prefix(':').or_else(|| rest.strip_prefix('='))?;
    Some(value.trim().parse())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sensor_table_finds_every_id_by_scan_and_by_index() {
        let mut table = SensorTable::new();
        let id = |k: u32| format!("sensor{k}").into_bytes();
        for k in 0..1000u32 {
            assert_eq!(table.find(&id(k)), None);
            table.insert(&id(k), k);
            // Past SCAN ids the index answers; every earlier id is still found.
            for j in [0, k / 2, k] {
                assert_eq!(table.find(&id(j)), Some(j), "{j} of {k}");
            }
        }
        assert!(table.index.is_some());
        assert_eq!(table.find(b"sensor1000"), None);
    }
    use proptest::prelude::*;

    /// A row's outcome as text (Debug prints every double so it reads back to the same bits).
    fn outcome(r: Result<Option<Row<'_>>, String>) -> String {
        match r {
            Ok(None) => "skipped".into(),
            Err(e) => format!("dropped: {e}"),
            Ok(Some(Row { id, values: v })) => format!(
                "{id:?} {:?} {:?} {:?} {:?} {:?}",
                v.time,
                v.quaternion.map(|(q, n)| (q.coords, n)),
                v.ypr.map(|y| (y.yaw, y.pitch, y.roll)),
                v.imu.map(|i| (i.gyro_rad_s, i.accel_m_s2)),
                v.mag
            ),
        }
    }

    const HEADERS: [&str; 5] = [
        "time_s,sensor,qw,qx,qy,qz",
        "sensor,qx,qy,time_ms,qz,qw,note",
        "time_s,sensor,gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g,mx,my,mz",
        "time_us,yaw,pitch,roll,sensor",
        "time_s,sensor,mx,my,mz,qw,qx,qy,qz",
    ];

    /// Lines made of the pieces that matter to a row reader: plain and not-so-plain numbers,
    /// ids, spaces, commas, comment marks.
    fn line() -> impl Strategy<Value = String> {
        let piece = prop_oneof![
            4 => (-99_999i64..99_999, 0u32..8).prop_map(|(m, k)| {
                let s = format!("{}", m.unsigned_abs());
                let k = k as usize;
                let digits = if s.len() <= k { format!("{}{s}", "0".repeat(k + 1 - s.len())) } else { s };
                let (w, f) = digits.split_at(digits.len() - k);
                let sign = if m < 0 { "-" } else { "" };
                if f.is_empty() { format!("{sign}{w}") } else { format!("{sign}{w}.{f}") }
            }),
            1 => Just("pelvis".to_string()),
            1 => Just(",".to_string()),
            1 => prop::sample::select(vec![
                " ", "#", "-", ".", "e5", "1e-3", "nan", "inf", "\t", "12345678901234567890",
                "0.00000000000000000000001", "9007199254740993", "x y", "",
            ]).prop_map(str::to_string),
        ];
        prop::collection::vec(piece, 0..14).prop_map(|p| p.join(""))
    }

    /// Rows as they are mostly written, with one piece perhaps changed.
    fn near_plain_line(columns: usize) -> impl Strategy<Value = String> {
        (
            prop::collection::vec(-2.0f64..2.0, columns),
            0..columns,
            prop::sample::select(vec!["", " ", "pelvis", "1e2", "-", "1.", ".5", "#"]),
            any::<bool>(),
        )
            .prop_map(|(values, at, other, change)| {
                let fields: Vec<String> = values
                    .iter()
                    .enumerate()
                    .map(|(i, v)| match (change && i == at, i % 3) {
                        (true, _) => other.to_string(),
                        (false, 0) => format!("{v:.4}"),
                        (false, 1) => format!("{v:.6}"),
                        _ => format!("{v}"),
                    })
                    .collect();
                fields.join(",")
            })
    }

    fn check(header: &str, line: &str) -> Result<(), TestCaseError> {
        let layout = Layout::from_header(header.as_bytes(), Path::new("t.csv"), 1).unwrap();
        let bytes = line.as_bytes();
        // The general reader alone (it has no one-pass path at this many slots) is the reference.
        let general = outcome(parse_row_in::<MAX_COLUMNS>(&layout, bytes));
        let read = outcome(parse_row(&layout, bytes));
        prop_assert_eq!(read, general, "{} / {:?}", header, line);
        Ok(())
    }

    /// A quaternion row as a block keeps it, to the bit.
    fn quaternion_bits(values: &Packed) -> Option<(u64, [u64; 4], u64)> {
        match values {
            Packed::Quaternion { time, q, norm } => Some((
                time.to_bits(),
                [q.w, q.i, q.j, q.k].map(f64::to_bits),
                norm.to_bits(),
            )),
            _ => None,
        }
    }

    /// Where the direct quaternion row reads a line, the general reader reads the same id and
    /// values; returns whether it read it.
    fn check_direct(header: &str, line: &str) -> Result<bool, TestCaseError> {
        let layout = Layout::from_header(header.as_bytes(), Path::new("t.csv"), 1).unwrap();
        let Some(columns) = layout.quaternion_only() else {
            return Ok(false);
        };
        let Some((id, direct)) = plain_quaternion_row(&layout, columns, line.as_bytes()) else {
            return Ok(false);
        };
        let general = parse_row_in::<MAX_COLUMNS>(&layout, line.as_bytes());
        let Ok(Some(Row {
            id: general_id,
            values,
        })) = general
        else {
            return Err(TestCaseError::fail(format!(
                "{header} / {line:?}: read directly, but the general reader gives {}",
                outcome(general)
            )));
        };
        prop_assert_eq!(id, general_id);
        let general = Packed::from(values);
        prop_assert!(quaternion_bits(&general).is_some());
        prop_assert_eq!(
            quaternion_bits(&direct),
            quaternion_bits(&general),
            "{}",
            line
        );
        Ok(true)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]
        /// Both one-pass readers: the plain row and the direct quaternion row.
        #[test]
        fn the_one_pass_row_reads_what_the_general_reader_reads(
            header in prop::sample::select(HEADERS.to_vec()),
            line in line(),
        ) {
            check(header, &line)?;
            check_direct(header, &line)?;
        }

        #[test]
        fn near_plain_rows_too(
            (header, line) in prop::sample::select(HEADERS.to_vec()).prop_flat_map(|h| {
                (Just(h), near_plain_line(h.split(',').count()))
            }),
        ) {
            check(header, &line)?;
            check_direct(header, &line)?;
        }
    }

    #[test]
    fn quaternion_only_layouts_read_plain_rows_directly() {
        // A magnetometer without a gyro is not read; yaw, pitch and roll beside a quaternion are;
        // past 12 columns the general reader reads every row.
        let only: Vec<bool> = HEADERS
            .iter()
            .chain(&[
                "time_s,sensor,qw,qx,qy,qz,yaw,pitch,roll",
                "time_s,sensor,qw,qx,qy,qz,a,b,c,d,e,f",
                "time_s,sensor,qw,qx,qy,qz,a,b,c,d,e,f,g",
            ])
            .map(|h| {
                let layout = Layout::from_header(h.as_bytes(), Path::new("t.csv"), 1).unwrap();
                layout.quaternion_only().is_some()
            })
            .collect();
        assert_eq!(only, [true, true, false, false, true, false, true, false]);
        for line in [
            "62.4942,right_shank,0.854667,-0.311506,0,1",
            "0.0001,s,-1,0,0,0",
            "3,x,2,0,0,0",
        ] {
            assert!(matches!(check_direct(HEADERS[0], line), Ok(true)), "{line}");
        }
        // Not plain, or a zero quaternion (which the general reader drops with its reason):
        // left to the general reader.
        for line in [
            "1,a,0,0,0,0",
            "1,a,1e0,0,0,0",
            " 1,a,1,0,0,0",
            "#1,a,1,0,0,0",
            "",
        ] {
            assert!(
                matches!(check_direct(HEADERS[0], line), Ok(false)),
                "{line}"
            );
        }
        let layout = Layout::from_header(HEADERS[0].as_bytes(), Path::new("t.csv"), 1).unwrap();
        assert!(parse_row(&layout, b"1,a,0,0,0,0").is_err());
    }

    #[test]
    fn plain_rows_take_the_one_pass_path_and_others_do_not() {
        let layout = Layout::from_header(HEADERS[0].as_bytes(), Path::new("t.csv"), 1).unwrap();
        let (id, numbers) =
            plain_row(&layout, b"62.4942,right_shank,0.854667,-0.311506,0,1").unwrap();
        assert_eq!(id, b"right_shank");
        assert_eq!(numbers[..6], [62.4942, 0.0, 0.854667, -0.311506, 0.0, 1.0]);
        for other in [
            " 1,a,1,0,0,0",
            "1,a ,1,0,0,0",
            "1,a,1,0,0,0,",
            "1,a,1,0,0",
            "1,a,1e0,0,0,0",
            "#1,a,1,0,0,0",
            "1,,1,0,0,0",
            "1.,a,1,0,0,0",
        ] {
            assert!(plain_row(&layout, other.as_bytes()).is_none(), "{other}");
        }
    }
}
