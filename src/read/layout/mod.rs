//! Declared packet layouts (`--layout FILE`): a YAML file says how a home-made device's frames
//! are delimited and what each field is, and any capture in that layout reads as a take
//! (docs/src/formats/layouts.md). Two frame kinds:
//!
//! - `text`: one frame per line, fields split by `separator` (any run of whitespace by default),
//!   each `decimal` or a hexadecimal IEEE-754 float32 (`hex_f32_be`: the bytes as written,
//!   `3F800000` = 1.0; `hex_f32_le`: the bytes in little-endian order, `0000803F` = 1.0);
//! - `binary`: `start` bytes, the fields in order (integers `u8`…`i64` and floats `f32`/`f64`,
//!   `le` or `be`), then an optional checksum (`sum8`, `xor8`, `crc16-ccitt` — CRC-16/CCITT-FALSE:
//!   polynomial 0x1021, initial 0xFFFF — over the bytes after `start`, or over the whole frame
//!   with `over: frame`).
//!
//! Each field is `as` one of: `sensor`, `time` (unit in `time.unit`), `type` (which entry of
//! `types` names the `values` that follow), `valid` (0: the frame is a repeat and is dropped),
//! `length` (the bytes after it up to the checksum: checked), `skip`, the quaternion `qw qx qy qz`,
//! the Euler angles `yaw pitch roll` (about z, y, x; `euler.order` and `euler.unit`), the raw
//! `gx gy gz` (`gyro.unit`), `ax ay az` (`accel.unit`) and `mx my mz` (`mag.unit`), each times its
//! optional `scale`. Errors in the file name its key.
//!
//! A frame that does not decode (a bad checksum, a length that disagrees, an unknown type, a
//! token that is not a number) is dropped and reported with its line, or for a binary stream its
//! byte offset; the binary decoder then looks for the next start from the byte after the bad
//! frame's start.

mod csv_lines;
mod frames;

pub use csv_lines::CsvLines;
pub use frames::{Decoded, Decoder, Frame};

use super::{InputFormat, ReadError, ReadOptions};
use crate::take::{ClockUnit, ImuSample, Take, TakeBuilder};
use crate::world::World;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Standard gravity, m/s² per g.
const G: f64 = 9.80665;

/// What a field (or a `types` entry's value) is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Meaning {
    Sensor,
    Time,
    Type,
    Valid,
    Length,
    Values,
    Skip,
    Qw,
    Qx,
    Qy,
    Qz,
    Yaw,
    Pitch,
    Roll,
    Gx,
    Gy,
    Gz,
    Ax,
    Ay,
    Az,
    Mx,
    My,
    Mz,
}

impl Meaning {
    /// A measured value (what `types` may name).
    fn is_value(self) -> bool {
        !matches!(
            self,
            Meaning::Sensor
                | Meaning::Time
                | Meaning::Type
                | Meaning::Valid
                | Meaning::Length
                | Meaning::Values
        )
    }
}

/// How a field is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Encoding {
    /// Text: an ASCII decimal number (`-12`, `0.5`, `1e-3`).
    Decimal,
    /// Text: eight hexadecimal digits, an IEEE-754 float32's bytes in big-endian order.
    HexF32Be,
    /// Text: eight hexadecimal digits, an IEEE-754 float32's bytes in little-endian order.
    HexF32Le,
    U8,
    I8,
    U16le,
    U16be,
    I16le,
    I16be,
    U32le,
    U32be,
    I32le,
    I32be,
    U64le,
    U64be,
    I64le,
    I64be,
    F32le,
    F32be,
    F64le,
    F64be,
}

impl Encoding {
    fn is_text(self) -> bool {
        matches!(
            self,
            Encoding::Decimal | Encoding::HexF32Be | Encoding::HexF32Le
        )
    }

    /// Bytes of a binary field.
    fn size(self) -> usize {
        use Encoding::*;
        match self {
            Decimal | HexF32Be | HexF32Le => 0,
            U8 | I8 => 1,
            U16le | U16be | I16le | I16be => 2,
            U32le | U32be | I32le | I32be | F32le | F32be => 4,
            U64le | U64be | I64le | I64be | F64le | F64be => 8,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameKind {
    Text,
    Binary,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ChecksumKind {
    None,
    /// The bytes' sum modulo 256, one byte.
    Sum8,
    /// The bytes XORed, one byte.
    Xor8,
    /// CRC-16/CCITT-FALSE (0x1021, initial 0xFFFF), two bytes.
    Crc16Ccitt,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Over {
    /// The bytes after `start` up to the checksum.
    #[default]
    Payload,
    /// The whole frame up to the checksum, `start` included.
    Frame,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Endian {
    #[default]
    Le,
    Be,
}

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checksum {
    pub kind: ChecksumKind,
    #[serde(default)]
    pub over: Over,
    /// The byte order of a two-byte checksum.
    #[serde(default)]
    pub endian: Endian,
}

impl Checksum {
    fn size(&self) -> usize {
        match self.kind {
            ChecksumKind::None => 0,
            ChecksumKind::Sum8 | ChecksumKind::Xor8 => 1,
            ChecksumKind::Crc16Ccitt => 2,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Field {
    #[serde(rename = "as")]
    pub meaning: Meaning,
    pub encoding: Encoding,
    /// The decoded number times this (counts to the unit declared for its kind).
    #[serde(default)]
    pub scale: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TimeUnit {
    S,
    Ms,
    Us,
    Ns,
}

impl TimeUnit {
    fn seconds(self) -> f64 {
        match self {
            TimeUnit::S => 1.0,
            TimeUnit::Ms => 1e-3,
            TimeUnit::Us => 1e-6,
            TimeUnit::Ns => 1e-9,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeSpec {
    pub unit: TimeUnit,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AngleUnit {
    Deg,
    Rad,
}

/// Euler angles: yaw about z, pitch about y, roll about x, composed in `order` (`zyx`:
/// R = Rz(yaw) · Ry(pitch) · Rx(roll)).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EulerSpec {
    pub order: String,
    pub unit: AngleUnit,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GyroUnit {
    Dps,
    RadS,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AccelUnit {
    G,
    MS2,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MagUnit {
    /// Microtesla.
    Ut,
    /// Counts of no stated unit (the fusion normalises the field).
    Raw,
}

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Unit<U> {
    pub unit: U,
}

/// A layout file as written (serde checks each key's type and name).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct LayoutFile {
    layout: u32,
    #[serde(default)]
    name: Option<String>,
    frame: FrameKind,
    #[serde(default)]
    separator: Option<String>,
    #[serde(default)]
    start: Vec<u8>,
    #[serde(default)]
    checksum: Option<Checksum>,
    fields: Vec<Field>,
    #[serde(default)]
    types: BTreeMap<i64, Vec<Meaning>>,
    #[serde(default)]
    time: Option<TimeSpec>,
    #[serde(default)]
    euler: Option<EulerSpec>,
    #[serde(default)]
    gyro: Option<Unit<GyroUnit>>,
    #[serde(default)]
    accel: Option<Unit<AccelUnit>>,
    #[serde(default)]
    mag: Option<Unit<MagUnit>>,
    #[serde(default)]
    world: Option<World>,
}

/// A checked layout: every rule below holds, so the decoder never re-checks.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    pub name: Option<String>,
    pub frame: FrameKind,
    /// Text frames: the separator (`None`: runs of whitespace).
    pub separator: Option<String>,
    pub start: Vec<u8>,
    pub checksum: Option<Checksum>,
    pub fields: Vec<Field>,
    pub types: BTreeMap<i64, Vec<Meaning>>,
    pub time_unit: Option<TimeUnit>,
    /// The Euler composition, axes as indices 0 = x, 1 = y, 2 = z, in order; the unit's radians.
    euler: Option<([usize; 3], f64)>,
    gyro_rad_s: f64,
    accel_m_s2: f64,
    /// The units the layout declares (the live stream's CSV columns keep them).
    pub gyro_unit: Option<GyroUnit>,
    pub accel_unit: Option<AccelUnit>,
    pub world: World,
    /// The longest binary frame, bytes (start and checksum included).
    pub max_frame: usize,
}

/// Why a layout file cannot be used: its path, the key, and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {message}", .path.display())]
pub struct LayoutError {
    pub path: PathBuf,
    pub message: String,
}

/// The gyroscope's and accelerometer's values: one reading, as imubake's inertial sample is.
const INERTIAL: [Meaning; 6] = [
    Meaning::Gx,
    Meaning::Gy,
    Meaning::Gz,
    Meaning::Ax,
    Meaning::Ay,
    Meaning::Az,
];

/// Each group of values that is one reading: all or none of them in a list of meanings.
const GROUPS: [(&str, &[Meaning]); 4] = [
    (
        "quaternion",
        &[Meaning::Qw, Meaning::Qx, Meaning::Qy, Meaning::Qz],
    ),
    ("euler", &[Meaning::Yaw, Meaning::Pitch, Meaning::Roll]),
    ("gyroscope and accelerometer", &INERTIAL),
    ("magnetometer", &[Meaning::Mx, Meaning::My, Meaning::Mz]),
];

impl Layout {
    /// Reads and checks a layout file.
    pub fn load(path: &Path) -> Result<Layout, LayoutError> {
        let text = std::fs::read_to_string(path).map_err(|e| LayoutError {
            path: path.to_path_buf(),
            message: format!("cannot read: {e}"),
        })?;
        Layout::parse(&text).map_err(|message| LayoutError {
            path: path.to_path_buf(),
            message,
        })
    }

    /// Parses and checks a layout's text; an error names the key.
    pub fn parse(text: &str) -> Result<Layout, String> {
        let file: LayoutFile = serde_yaml::from_str(text).map_err(|e| e.to_string())?;
        if file.layout != 1 {
            return Err(format!(
                "layout: version {} is not known (this imubake reads layout: 1)",
                file.layout
            ));
        }
        let text_frames = file.frame == FrameKind::Text;
        if text_frames {
            if !file.start.is_empty() || file.checksum.is_some() {
                return Err("start, checksum: only binary frames have them".into());
            }
        } else {
            if file.separator.is_some() {
                return Err("separator: only text frames have one".into());
            }
            if file.start.is_empty() {
                return Err("start: a binary frame needs its start bytes".into());
            }
        }
        if file.separator.as_deref() == Some("") {
            return Err("separator: empty (leave it out to split at whitespace)".into());
        }
        if file.fields.is_empty() {
            return Err("fields: none".into());
        }
        let mut seen = Vec::new();
        for (i, f) in file.fields.iter().enumerate() {
            if f.encoding.is_text() != text_frames {
                return Err(format!(
                    "fields[{i}].encoding: {:?} is not a {} encoding",
                    f.encoding,
                    if text_frames { "text" } else { "binary" }
                ));
            }
            if let Some(s) = f.scale
                && !(s.is_finite() && s != 0.0)
            {
                return Err(format!(
                    "fields[{i}].scale: {s} is not a finite, non-zero number"
                ));
            }
            if f.meaning != Meaning::Skip && seen.contains(&f.meaning) {
                return Err(format!("fields[{i}].as: {:?} twice", f.meaning));
            }
            if f.meaning == Meaning::Values && i + 1 != file.fields.len() {
                return Err(format!("fields[{i}]: `values` must be the last field"));
            }
            if f.meaning == Meaning::Length && text_frames {
                return Err(format!("fields[{i}]: a text frame has no length field"));
            }
            seen.push(f.meaning);
        }
        let has_type = seen.contains(&Meaning::Type);
        let has_values = seen.contains(&Meaning::Values);
        if has_values != has_type || has_type == file.types.is_empty() {
            return Err(
                "types: a `type` field, a last `values` field and `types` go together".into(),
            );
        }
        let mut lists: Vec<(String, Vec<Meaning>)> = vec![("fields".into(), seen.clone())];
        for (t, list) in &file.types {
            if let Some(m) = list.iter().find(|m| !m.is_value()) {
                return Err(format!("types.{t}: {m:?} is not a value"));
            }
            if list.is_empty() {
                return Err(format!("types.{t}: no values"));
            }
            lists.push((format!("types.{t}"), list.clone()));
        }
        let mut any_reading = false;
        for (key, list) in &lists {
            for (group, members) in GROUPS {
                let n = members.iter().filter(|m| list.contains(m)).count();
                if n != 0 && n != members.len() {
                    return Err(format!(
                        "{key}: the {group} needs all of {members:?}, or none"
                    ));
                }
                any_reading |= n > 0;
            }
        }
        if !any_reading {
            return Err(
                "fields: no reading (a quaternion, Euler angles, or gyroscope and accelerometer)"
                    .into(),
            );
        }
        let uses = |m: Meaning| lists.iter().any(|(_, l)| l.contains(&m));
        let euler = match (&file.euler, uses(Meaning::Yaw)) {
            (None, true) => return Err("euler: the angles need their order and unit".into()),
            (Some(_), false) | (None, false) => None,
            (Some(e), true) => {
                let axes: Vec<usize> = e
                    .order
                    .chars()
                    .map(|c| match c {
                        'x' => Some(0),
                        'y' => Some(1),
                        'z' => Some(2),
                        _ => None,
                    })
                    .collect::<Option<_>>()
                    .ok_or_else(|| format!("euler.order: `{}` is not three of x, y, z", e.order))?;
                let mut sorted = axes.clone();
                sorted.sort_unstable();
                if sorted != [0, 1, 2] {
                    return Err(format!(
                        "euler.order: `{}` must name each of x, y, z once",
                        e.order
                    ));
                }
                let unit = match e.unit {
                    AngleUnit::Deg => std::f64::consts::PI / 180.0,
                    AngleUnit::Rad => 1.0,
                };
                Some(([axes[0], axes[1], axes[2]], unit))
            }
        };
        let gyro_rad_s = match (file.gyro, uses(Meaning::Gx)) {
            (None, true) => return Err("gyro: the rates need their unit (dps or rad_s)".into()),
            (
                Some(Unit {
                    unit: GyroUnit::Dps,
                }),
                _,
            ) => std::f64::consts::PI / 180.0,
            _ => 1.0,
        };
        let accel_m_s2 = match (file.accel, uses(Meaning::Ax)) {
            (None, true) => {
                return Err("accel: the accelerations need their unit (g or m_s2)".into());
            }
            (Some(Unit { unit: AccelUnit::G }), _) => G,
            _ => 1.0,
        };
        if file.mag.is_none() && uses(Meaning::Mx) {
            return Err("mag: the field needs its unit (ut or raw)".into());
        }
        let time_unit = match (file.time, seen.contains(&Meaning::Time)) {
            (None, true) => {
                return Err("time: the time field needs its unit (s, ms, us, ns)".into());
            }
            (Some(_), false) => return Err("time: given, but no field is the time".into()),
            (t, _) => t.map(|t| t.unit),
        };
        // The longest frame, and each field's width fixed (binary).
        let max_frame = if text_frames {
            0
        } else {
            let fixed: usize = file
                .fields
                .iter()
                .filter(|f| f.meaning != Meaning::Values)
                .map(|f| f.encoding.size())
                .sum();
            let values_size = file
                .fields
                .last()
                .filter(|f| f.meaning == Meaning::Values)
                .map_or(0, |f| f.encoding.size());
            let most = file.types.values().map(Vec::len).max().unwrap_or(0);
            let checksum = file.checksum.as_ref().map_or(0, Checksum::size);
            file.start.len() + fixed + most * values_size + checksum
        };
        if max_frame > frames::MAX_FRAME_BYTES {
            return Err(format!(
                "fields: a frame of {max_frame} bytes is longer than {} bytes",
                frames::MAX_FRAME_BYTES
            ));
        }
        Ok(Layout {
            name: file.name,
            frame: file.frame,
            separator: file.separator,
            start: file.start,
            checksum: file.checksum.filter(|c| c.kind != ChecksumKind::None),
            fields: file.fields,
            types: file.types,
            time_unit,
            euler,
            gyro_rad_s,
            accel_m_s2,
            gyro_unit: file.gyro.map(|g| g.unit),
            accel_unit: file.accel.map(|a| a.unit),
            world: file.world.unwrap_or(World::Enu),
            max_frame,
        })
    }

    /// A frame's orientation: its quaternion (normalised), or its Euler angles composed;
    /// `None` when it has neither, `Some(None)` when the quaternion is zero or not finite.
    fn orientation(&self, f: &Frame) -> Option<Option<UnitQuaternion<f64>>> {
        if let (Some(w), Some(x), Some(y), Some(z)) = (
            f.get(Meaning::Qw),
            f.get(Meaning::Qx),
            f.get(Meaning::Qy),
            f.get(Meaning::Qz),
        ) {
            let q = Quaternion::new(w, x, y, z);
            let n = q.norm();
            return Some((n.is_finite() && n > 1e-9).then(|| UnitQuaternion::from_quaternion(q)));
        }
        let (axes, unit) = self.euler?;
        let angles = [
            f.get(Meaning::Roll)?,
            f.get(Meaning::Pitch)?,
            f.get(Meaning::Yaw)?,
        ];
        let mut q = UnitQuaternion::identity();
        for axis in axes {
            let a = Vector3::ith_axis(axis);
            q *= UnitQuaternion::from_axis_angle(&a, angles[axis] * unit);
        }
        Some(angles.iter().all(|a| a.is_finite()).then_some(q))
    }
}

/// One capture file read through a layout: its bytes, the sensor id when no field gives one.
pub fn take_of(
    bytes: &[u8],
    path: &Path,
    layout: &Layout,
    options: &ReadOptions,
) -> Result<Take, ReadError> {
    let world = options.world.unwrap_or(layout.world);
    let mut take = TakeBuilder::new(path, InputFormat::Layout, world, ClockUnit::Seconds);
    let mut decoder = Decoder::new();
    let mut decoded = Decoded::default();
    decoder.push(layout, bytes, &mut decoded);
    decoder.finish(layout, &mut decoded);
    let stem = super::take_stem(path);
    let rate = match (layout.time_unit, options.rate_hz) {
        (Some(_), _) => None,
        (None, Some(rate)) => Some(rate),
        (None, None) => {
            return Err(ReadError::format(
                path,
                "the layout has no time field; give the frame rate with --rate HZ",
            ));
        }
    };
    let binary = layout.frame == FrameKind::Binary;
    let place = |line: u64, offset: u64| if binary { offset + 1 } else { line };
    for bad in &decoded.bad {
        let raw = if binary {
            format!("frame at byte offset {}", bad.offset)
        } else {
            String::from_utf8_lossy(&bad.raw).into_owned()
        };
        let reason = if binary {
            format!("{} (byte offset {})", bad.reason, bad.offset)
        } else {
            bad.reason.clone()
        };
        take.drop_line(place(bad.line, bad.offset), reason, raw.as_bytes());
    }
    if decoded.skipped_bytes > 0 {
        take.warn(format!(
            "{} bytes outside frames skipped (the first at byte offset {})",
            decoded.skipped_bytes,
            decoded.first_skipped_offset.unwrap_or(0)
        ));
    }
    // Without a time field, a sensor's k-th frame of a type is at k / rate.
    let mut counts: BTreeMap<(String, Option<i64>), u64> = BTreeMap::new();
    for f in &decoded.frames {
        let line = place(f.line, f.offset);
        let raw = if binary {
            format!("frame at byte offset {}", f.offset)
        } else {
            String::from_utf8_lossy(&f.raw).into_owned()
        };
        if f.get(Meaning::Valid) == Some(0.0) {
            take.drop_line(
                line,
                "the new-data flag is 0 (a repeated reading)",
                raw.as_bytes(),
            );
            continue;
        }
        let id = match f.get(Meaning::Sensor) {
            Some(s) => format_id(s),
            None => stem.clone(),
        };
        let t = match rate {
            Some(rate) => {
                let k = counts.entry((id.clone(), f.kind)).or_insert(0);
                let t = *k as f64 / rate;
                *k += 1;
                t
            }
            None => {
                let unit = layout.time_unit.map_or(1.0, TimeUnit::seconds);
                f.get(Meaning::Time).unwrap_or(f64::NAN) * unit
            }
        };
        if !t.is_finite() {
            take.drop_line(line, "the time is not a finite number", raw.as_bytes());
            continue;
        }
        let sensor = take.sensor(&id);
        match layout.orientation(f) {
            Some(Some(q)) => take
                .push_quaternion(sensor, t, q, line, raw.as_bytes())
                .map_err(|e| ReadError::take(path, e))?,
            Some(None) => {
                take.drop_line(
                    line,
                    "the orientation is zero or not finite",
                    raw.as_bytes(),
                );
                continue;
            }
            None => {}
        }
        let v = |a: Meaning, b: Meaning, c: Meaning| {
            Some(Vector3::new(f.get(a)?, f.get(b)?, f.get(c)?))
        };
        if let (Some(g), Some(a)) = (
            v(Meaning::Gx, Meaning::Gy, Meaning::Gz),
            v(Meaning::Ax, Meaning::Ay, Meaning::Az),
        ) {
            let sample = ImuSample {
                gyro_rad_s: g * layout.gyro_rad_s,
                accel_m_s2: a * layout.accel_m_s2,
            };
            take.push_inertial(sensor, t, sample, line, raw.as_bytes())
                .map_err(|e| ReadError::take(path, e))?;
        }
        if let Some(m) = v(Meaning::Mx, Meaning::My, Meaning::Mz) {
            take.push_magnetometer(sensor, t, m, line, raw.as_bytes())
                .map_err(|e| ReadError::take(path, e))?;
        }
    }
    if decoded.frames.is_empty() {
        return Err(ReadError::format(
            path,
            format!(
                "no frame of the layout found ({} dropped); check the layout against the device's output",
                decoded.bad.len()
            ),
        ));
    }
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

/// A sensor number as an id: an integer without a fraction, else its decimal text.
fn format_id(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v}")
    }
}

/// Reads one capture file (or stream) through `options.layout`.
pub fn read_from(
    mut source: impl std::io::Read,
    path: &Path,
    options: &ReadOptions,
) -> Result<Take, ReadError> {
    let layout_path = options.layout.as_deref().ok_or_else(|| {
        ReadError::format(
            path,
            "--input-format layout needs the layout: --layout FILE.yaml",
        )
    })?;
    let layout = Layout::load(layout_path).map_err(|e| ReadError::format(path, e.to_string()))?;
    let mut bytes = Vec::new();
    source
        .read_to_end(&mut bytes)
        .map_err(|e| ReadError::io(path, e))?;
    take_of(&bytes, path, &layout, options)
}

#[cfg(test)]
mod tests;
