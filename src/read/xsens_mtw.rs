//! Xsens MTw `.txt` exports (MT Manager; the files OpenSim's OpenSense reads): one file is a take,
//! and a folder of such files (one per sensor, one recording) is one take.
//!
//! MT Manager 4.x:
//!
//! ```text
//! // Start Time: Unknown
//! // Update Rate: 100.0Hz
//! // Filter Profile: human (46.1)
//! PacketCounter<TAB>SampleTimeFine<TAB>...<TAB>Acc_X<TAB>Acc_Y<TAB>Acc_Z<TAB>Mat[1][1]<TAB>Mat[2][1]<TAB>Mat[3][1]<TAB>Mat[1][2]...Mat[3][3]
//! 00472<TAB><TAB>...<TAB>0.492747<TAB>-5.241669<TAB>-8.223521<TAB>0.856410<TAB>-0.513606<TAB>...
//! ```
//!
//! MT Manager 2019.2 and later (no update rate; the columns are those ticked for the export):
//!
//! ```text
//! // General information:
//! //  MT Manager version: 2019.2.0
//! //  XDA version: 2019.2.0 build 3853 rev 94535 built on 2019-09-09
//! // Device information:
//! //  DeviceId: 00B40DE4
//! ...
//! // Coordinate system: ENU
//! PacketCounter<TAB>SampleTimeFine<TAB>Year<TAB>...<TAB>UTC_Valid<TAB>Acc_X<TAB>...<TAB>Quat_q0<TAB>Quat_q1<TAB>Quat_q2<TAB>Quat_q3
//! 03027<TAB>4294967046<TAB><TAB>...<TAB>0.051234<TAB>...<TAB>1.000000<TAB>0.000000<TAB>0.000000<TAB>0.000000
//! ```
//!
//! - `//` lines are header comments. The first other line is the column row: tab-separated (`,`
//!   or `;` also accepted when the row has no tab), names matched case-insensitively in any
//!   order. Many columns (UTC, SampleTimeFine, ...) are often empty; the unused ones are ignored.
//! - Time, from the first of these the file has:
//!   - a `// Update Rate: 100.0Hz` line: `PacketCounter`, a 16-bit counter that wraps at 65536,
//!     counted at that rate: `ClockUnit::Counter { name: "PacketCounter", rate_hz }`. A gap of
//!     more than half a wrap (327 s at 100 Hz) cannot be told from a step back.
//!   - a `SampleTimeFine` on the first data row: the sensor's clock in ticks of 100 µs (10 kHz),
//!     a 32-bit counter that wraps at 2³² (4.97 days): `ClockUnit::Counter { name:
//!     "SampleTimeFine", rate_hz: 10000 }`. The sensors of one Awinda recording share it.
//!   - `--rate HZ`: PacketCounter at that rate.
//!   - none: an error naming the missing `// Update Rate:` line and SampleTimeFine column (or
//!     the first data row, where MT Manager left SampleTimeFine empty), with what to do.
//!
//!   Either counter is unwrapped (each row placed at the nearest unwrapped value to the previous
//!   row's; the files of a folder, which must all have the same clock, are placed within half a
//!   wrap of the earliest-starting file).
//! - Orientation, the first present of: `Quat_q0..Quat_q3` (q_GS, w first), the rotation matrix
//!   `Mat[r][c]`, or `Roll, Pitch, Yaw` (degrees; Xsens' "XYZ earth-fixed" sequence, which is
//!   R = Rz(yaw)·Ry(pitch)·Rx(roll), stored verbatim with `push_yaw_pitch_roll`).
//! - `Acc_X..Z` (m/s²) with `Gyr_X..Z` (rad/s, MT Manager's unit) become an inertial stream,
//!   `Mag_X..Z` (a.u.) a magnetometer stream; `Acc` alone is not used (the files OpenSense ships
//!   have no gyroscope columns).
//! - Sensor id: the file name after its last `_`, without extension
//!   (`MT_012005D6_009-001_00B421EF.txt` → `00B421EF`).
//! - World: ENU, Xsens' default local earth frame (`--world` overrides).
//!
//! # What `Mat[r][c]` means
//!
//! Xsens' MTw user manual (section 11.7.3, "Rotation Matrix Orientation Output Mode", also the
//! MTi/MTx manual MT0100P 4.3.3) defines the rotation matrix output as R_GS, "the unit vectors of
//! S are found in the columns of the matrix, so column 1 is X_S expressed in G", with
//! x_G = R_GS · x_S, and R_GS = [a d g; b e h; c f i] = [R11 R12 R13; R21 R22 R23; R31 R32 R33],
//! output in the order a, b, c, d, ..., i: column-major. MT Manager's column names say the same:
//! `Mat[1][1] Mat[2][1] Mat[3][1] Mat[1][2] ...` is R11, R21, R31, R12, ... So `Mat[r][c]` is row r,
//! column c of R_GS, the matrix that rotates sensor-frame vectors into the world frame: exactly
//! q_world_sensor, with no transpose. OpenSim's `XsensDataReader.cpp` (opensim-core,
//! OpenSim/Common) reads the nine values the same way, outer loop over columns, inner over rows
//! (`imu_matrix[mrow][mcol] = value[k++]`), and uses the result as the sensor orientation. The data
//! agree: in the OpenSense example files the static accelerometer reading (specific force, +g
//! upward), rotated by this matrix, points along world +z (tested in tests/readers/vendor_readers.rs).
//! The columns are looked up by name, so a file with another column order reads the same.
//!
//! Rows with the wrong number of fields, an empty or bad counter (PacketCounter, or SampleTimeFine
//! when it gives the times), or an unusable value in a used column (empty, NaN, a zero
//! quaternion, a matrix that is not a rotation) are dropped and reported. `--skip-lines N` drops data rows whose line number is at most N in each file.

use super::clock::{WrappingClock, parse_counter};
use super::lines::{LineReader, number_problem, parse_f64, split_fields};
use super::{
    HeaderCheck, InputFormat, PerSensorFolder, ReadError, ReadOptions, column_group,
    read_single_file, warn_if_denormalised,
};
use crate::take::{
    BuildError, ClockUnit, ImuSample, SensorIdx, Take, TakeBuilder, YawPitchRollDeg,
};
use crate::world::World;
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use std::fs;
use std::io::Read;
use std::path::Path;

/// `PacketCounter` wraps at 2¹⁶.
pub const PACKET_COUNTER_MODULUS: u64 = 1 << 16;

/// `SampleTimeFine` wraps at 2³².
pub const SAMPLE_TIME_FINE_MODULUS: u64 = 1 << 32;

/// `SampleTimeFine` counts ticks of this clock: 10 kHz, 100 µs a tick (Xsens' MTi user manual
/// MT0605P, 4.12.3: "a 0.1 ms resolution 4 byte time stamp"; Movella DOT's is 1 MHz instead).
pub const SAMPLE_TIME_FINE_HZ: f64 = 10_000.0;

/// At most this many columns are looked at.
const MAX_COLUMNS: usize = 160;

/// Header comment lines read before giving up on finding the column row.
const MAX_HEADER_LINES: u64 = 1000;

/// Largest deviation of RᵀR from the identity accepted for a rotation matrix.
const ORTHONORMAL_TOLERANCE: f64 = 0.01;

const EXPECTED_HEADER: &str = "a tab-separated column row with PacketCounter and Quat_q0..Quat_q3, \
     Mat[1][1]..Mat[3][3] or Roll,Pitch,Yaw (or Acc_X..Z with Gyr_X..Z), and times: SampleTimeFine or a \
     `// Update Rate: <n>Hz` header line, as MT Manager exports";

/// Sensor id of an MTw file: the file name after its last `_`, without extension.
pub fn sensor_id(path: &Path) -> String {
    let stem = path
        .file_stem()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    match stem.rsplit('_').next() {
        Some(id) if !id.is_empty() => id.to_string(),
        _ if !stem.is_empty() => stem,
        _ => "mtw".to_string(),
    }
}

fn separator(line: &[u8]) -> u8 {
    if line.contains(&b'\t') {
        b'\t'
    } else if line.contains(&b',') {
        b','
    } else {
        b';'
    }
}

fn names_of(line: &[u8], sep: u8) -> Vec<String> {
    line.split(|&b| b == sep)
        .map(|f| String::from_utf8_lossy(f.trim_ascii()).to_ascii_lowercase())
        .collect()
}

fn is_comment(line: &[u8]) -> bool {
    line.trim_ascii_start().starts_with(b"//")
}

/// The rate of a `// Update Rate: 100.0Hz` line; `Some(None)` when the line names the rate but it
/// does not parse, `None` for other lines.
fn update_rate(comment: &[u8]) -> Option<Option<f64>> {
    let text = String::from_utf8_lossy(comment);
    let text = text.trim_start().trim_start_matches('/').trim();
    let (key, value) = text.split_once(':')?;
    if !key.trim().eq_ignore_ascii_case("update rate") {
        return None;
    }
    let value = value.trim();
    let value = value
        .strip_suffix("Hz")
        .or_else(|| value.strip_suffix("hz"))
        .or_else(|| value.strip_suffix("HZ"))
        .unwrap_or(value);
    Some(parse_f64(value.as_bytes()).filter(|r| *r > 0.0))
}

/// True when the first lines are an MT Manager export: a `// Update Rate:` comment, or a column
/// row with `PacketCounter` and Xsens orientation columns (or tab-separated).
pub fn looks_like(head: &[u8]) -> bool {
    let mut reader = LineReader::over(head);
    let mut seen = 0;
    while let Ok(Some((_, line))) = reader.next_line() {
        seen += 1;
        if seen > 64 {
            break;
        }
        if line.trim_ascii().is_empty() {
            continue;
        }
        if is_comment(line) {
            if update_rate(line).is_some() {
                return true;
            }
            continue;
        }
        let sep = separator(line);
        let names = names_of(line, sep);
        let has = |n: &str| names.iter().any(|x| x == n);
        return has("packetcounter")
            && (sep == b'\t' || has("mat[1][1]") || has("quat_q0") || has("roll"));
    }
    false
}

/// How a file gives orientation.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Orientation {
    Quaternion([usize; 4]),
    /// Column of `Mat[r][c]` at `[r-1][c-1]`.
    Matrix([[usize; 3]; 3]),
    RollPitchYaw([usize; 3]),
}

/// Column positions resolved from the column row.
#[derive(Debug, Clone, PartialEq)]
struct Layout {
    sep: u8,
    columns: usize,
    counter: usize,
    sample_time_fine: Option<usize>,
    orientation: Option<Orientation>,
    inertial: Option<([usize; 3], [usize; 3])>,
    mag: Option<[usize; 3]>,
}

/// Header comments and column row of one file.
#[derive(Debug, Clone, PartialEq)]
struct Header {
    /// The `// Update Rate:` line's rate, when there is one.
    rate_hz: Option<f64>,
    layout: Layout,
    /// The column row's line.
    line: u64,
}

/// What gives a file's rows their times.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Clock {
    /// `PacketCounter` (16 bits) at the header's `// Update Rate:`, or at `--rate`.
    Packets { rate_hz: f64 },
    /// `SampleTimeFine` (32 bits, 10 kHz ticks), when the header names no update rate.
    Fine,
}

impl Clock {
    fn name(self) -> &'static str {
        match self {
            Clock::Packets { .. } => "PacketCounter",
            Clock::Fine => "SampleTimeFine",
        }
    }

    fn modulus(self) -> u64 {
        match self {
            Clock::Packets { .. } => PACKET_COUNTER_MODULUS,
            Clock::Fine => SAMPLE_TIME_FINE_MODULUS,
        }
    }

    fn unit(self) -> ClockUnit {
        ClockUnit::Counter {
            name: self.name().to_string(),
            rate_hz: match self {
                Clock::Packets { rate_hz } => rate_hz,
                Clock::Fine => SAMPLE_TIME_FINE_HZ,
            },
        }
    }

    /// The column of the counter, `None` for a `Fine` clock in a file without SampleTimeFine.
    fn column(self, layout: &Layout) -> Option<usize> {
        match self {
            Clock::Packets { .. } => Some(layout.counter),
            Clock::Fine => layout.sample_time_fine,
        }
    }

    /// The counter's value in a row's field (below the modulus), or why it has none.
    fn value(self, field: &[u8]) -> Result<u64, String> {
        match parse_counter(field) {
            Ok(c) if c < self.modulus() => Ok(c),
            Ok(_) => Err(match self {
                Clock::Packets { .. } => {
                    "PacketCounter is larger than a 16-bit counter (0-65535)".to_string()
                }
                Clock::Fine => {
                    "SampleTimeFine is larger than a 32-bit counter (0-4294967295)".to_string()
                }
            }),
            Err(problem) => Err(format!("{} {problem}", self.name())),
        }
    }

    /// Whether two files' clocks are one take's.
    fn same(self, other: Clock) -> bool {
        match (self, other) {
            (Clock::Packets { rate_hz: a }, Clock::Packets { rate_hz: b }) => same_rate(a, b),
            (Clock::Fine, Clock::Fine) => true,
            _ => false,
        }
    }

    fn describe(self) -> String {
        match self {
            Clock::Packets { rate_hz } => format!("PacketCounter at {rate_hz} Hz"),
            Clock::Fine => "SampleTimeFine (no `// Update Rate:` line)".to_string(),
        }
    }
}

const MAT_NAMES: [[&str; 3]; 3] = [
    ["Mat[1][1]", "Mat[1][2]", "Mat[1][3]"],
    ["Mat[2][1]", "Mat[2][2]", "Mat[2][3]"],
    ["Mat[3][1]", "Mat[3][2]", "Mat[3][3]"],
];

impl Layout {
    fn from_header(line: &[u8], path: &Path, line_no: u64) -> Result<Layout, ReadError> {
        let sep = separator(line);
        let names = names_of(line, sep);
        let check = HeaderCheck::new(path, line_no, "column row", EXPECTED_HEADER);
        check.column_count(names.len(), MAX_COLUMNS)?;
        let find = |name: &str| {
            let lower = name.to_ascii_lowercase();
            names.iter().position(|n| *n == lower)
        };
        let mut missing: Vec<String> = Vec::new();
        let mut group = |wanted: &[&str]| column_group(find, wanted, &mut missing);
        let quat = group(&["Quat_q0", "Quat_q1", "Quat_q2", "Quat_q3"]);
        let mat = group(&MAT_NAMES.concat());
        let rpy = group(&["Roll", "Pitch", "Yaw"]);
        let acc = group(&["Acc_X", "Acc_Y", "Acc_Z"]);
        let gyr = group(&["Gyr_X", "Gyr_Y", "Gyr_Z"]);
        let mag = group(&["Mag_X", "Mag_Y", "Mag_Z"]);
        let three = |v: Vec<usize>| <[usize; 3]>::try_from(v).ok();
        let counter = check.required(find("PacketCounter"), "PacketCounter")?;
        let sample_time_fine = find("SampleTimeFine");
        check.complete(&missing)?;
        let orientation = if let Some(q) = quat.and_then(|v| <[usize; 4]>::try_from(v).ok()) {
            Some(Orientation::Quaternion(q))
        } else if let Some(m) = mat {
            // `group` returns the columns in MAT_NAMES order: row-major [r][c].
            let at = |r: usize, c: usize| m.get(r * 3 + c).copied().unwrap_or(0);
            Some(Orientation::Matrix([
                [at(0, 0), at(0, 1), at(0, 2)],
                [at(1, 0), at(1, 1), at(1, 2)],
                [at(2, 0), at(2, 1), at(2, 2)],
            ]))
        } else {
            rpy.and_then(three).map(Orientation::RollPitchYaw)
        };
        let inertial = match (acc.and_then(three), gyr.and_then(three)) {
            (Some(a), Some(g)) => Some((a, g)),
            _ => None,
        };
        if orientation.is_none() && inertial.is_none() {
            return Err(ReadError::line(
                path,
                line_no,
                format!("column row has no orientation columns; expected {EXPECTED_HEADER}"),
            ));
        }
        Ok(Layout {
            sep,
            columns: names.len(),
            counter,
            sample_time_fine,
            orientation,
            inertial,
            mag: mag.and_then(three),
        })
    }
}

/// Reads the header comments and the column row.
fn read_header<R: Read>(lines: &mut LineReader<R>, path: &Path) -> Result<Header, ReadError> {
    let mut rate = None;
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        if line.trim_ascii().is_empty() {
            continue;
        }
        if is_comment(line) {
            match update_rate(line) {
                Some(Some(r)) => rate = Some(r),
                Some(None) => {
                    return Err(ReadError::line(
                        path,
                        line_no,
                        "the update rate is not a positive number; expected e.g. `// Update Rate: 100.0Hz`",
                    ));
                }
                None => {}
            }
            if line_no >= MAX_HEADER_LINES {
                break;
            }
            continue;
        }
        let layout = Layout::from_header(line, path, line_no)?;
        return Ok(Header {
            rate_hz: rate,
            layout,
            line: line_no,
        });
    }
    Err(ReadError::format(
        path,
        format!("no column row found; expected {EXPECTED_HEADER}"),
    ))
}

/// Lines read ahead for the first data row of a file without an update rate.
const LOOKAHEAD_LINES: usize = 1000;

/// Lines read ahead of the rows (their numbers and text), to be read as rows in turn.
type Ahead = Vec<(u64, Vec<u8>)>;

/// A file's header and the clock of its rows; when the header names no rate, the lines up to
/// the first data row are read ahead (returned, for the caller to read as rows first):
/// - the header's `// Update Rate:` line: PacketCounter at that rate (MT Manager 4.x, and the
///   files OpenSense ships);
/// - else SampleTimeFine, when the first data row has one (MT Manager 2019.2 and later write no
///   update rate);
/// - else PacketCounter at `rate_hz` (`--rate`), when given;
/// - else an error naming the missing line and columns.
fn header_and_clock<R: Read>(
    lines: &mut LineReader<R>,
    path: &Path,
    rate_hz: Option<f64>,
) -> Result<(Header, Clock, Ahead), ReadError> {
    let header = read_header(lines, path)?;
    if let Some(rate_hz) = header.rate_hz {
        return Ok((header, Clock::Packets { rate_hz }, Vec::new()));
    }
    let layout = &header.layout;
    let mut ahead = Vec::new();
    let mut first = None;
    while ahead.len() < LOOKAHEAD_LINES
        && let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))?
    {
        ahead.push((line_no, line.to_vec()));
        let mut f = [&b""[..]; MAX_COLUMNS];
        let n = split_fields(line, layout.sep, &mut f);
        if !line.trim_ascii().is_empty() && field_count_ok(layout, &f, n) {
            first = layout
                .sample_time_fine
                .map(|column| (line_no, Clock::Fine.value(f[column])));
            break;
        }
    }
    let (line, problem) = match (layout.sample_time_fine, first) {
        (None, _) => (
            header.line,
            "no `// Update Rate: <n>Hz` line in the header and no SampleTimeFine column"
                .to_string(),
        ),
        // No data row to judge by: the rows are dropped one by one, each with its reason.
        (Some(_), None) | (Some(_), Some((_, Ok(_)))) => {
            return Ok((header, Clock::Fine, ahead));
        }
        (Some(_), Some((line_no, Err(problem)))) => (
            line_no,
            format!(
                "no `// Update Rate: <n>Hz` line in the header, and on this first data row \
                 {problem}"
            ),
        ),
    };
    if let Some(rate_hz) = rate_hz {
        return Ok((header, Clock::Packets { rate_hz }, ahead));
    }
    Err(ReadError::line(
        path,
        line,
        format!(
            "{problem}: PacketCounter alone gives no times (MT Manager 2019.2 and later export no \
             update rate). Hint: export again with SampleTimeFine among the exported data, or give \
             the update rate with --rate <HZ>"
        ),
    ))
}

/// Reads an MTw file or a folder of MTw files (one take).
pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    let meta = fs::metadata(path).map_err(|e| ReadError::io(path, e))?;
    if !meta.is_dir() {
        return read_single_file(path, options, read_from);
    }
    let folder = PerSensorFolder::open(
        path,
        looks_like,
        "Xsens MTw",
        &format!("files with {EXPECTED_HEADER}"),
        sensor_id,
    )?;
    // First pass: the clock (one for the take) and each file's first counter value.
    let mut take_clock: Option<(Clock, String)> = None;
    let firsts = folder.first_values(|f, file, name| {
        let mut lines = LineReader::new(f);
        let (header, clock, ahead) = header_and_clock(&mut lines, file, options.rate_hz)?;
        match &take_clock {
            None => take_clock = Some((clock, name.to_string())),
            Some((other, first)) if !other.same(clock) => {
                return Err(ReadError::format(
                    file,
                    format!(
                        "times from {} differ from `{first}`'s, {}; expected the files of one \
                         recording. Hint: read the files one by one",
                        clock.describe(),
                        other.describe()
                    ),
                ));
            }
            Some(_) => {}
        }
        first_counter(ahead, &mut lines, &header.layout, clock, file)
    })?;
    let take_clock = take_clock.map_or(Clock::Packets { rate_hz: 1.0 }, |c| c.0);
    let mut clock = WrappingClock::anchored_at_earliest(take_clock.modulus(), &firsts);
    let world = options.world.unwrap_or(World::Enu);
    let mut take = TakeBuilder::new(path, InputFormat::XsensMtw, world, take_clock.unit());
    folder.read_into(&mut take, &mut clock, |take, clock, f, file| {
        read_file_with(take, clock, f, file, take_clock, options)
    })?;
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

fn same_rate(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

/// The first parseable counter of `clock` after the column row (the lines read ahead first).
fn first_counter<R: Read>(
    ahead: Ahead,
    lines: &mut LineReader<R>,
    layout: &Layout,
    clock: Clock,
    path: &Path,
) -> Result<Option<u64>, ReadError> {
    let Some(column) = clock.column(layout) else {
        return Ok(None);
    };
    let first_of = |line: &[u8]| {
        let mut f = [&b""[..]; MAX_COLUMNS];
        let n = split_fields(line, layout.sep, &mut f);
        if field_count_ok(layout, &f, n) {
            clock.value(f[column]).ok()
        } else {
            None
        }
    };
    if let Some(c) = ahead.iter().find_map(|(_, line)| first_of(line)) {
        return Ok(Some(c));
    }
    while let Some((_, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        if let Some(c) = first_of(line) {
            return Ok(Some(c));
        }
    }
    Ok(None)
}

/// Reads one MTw file as a take; `path` names it in reports and gives the sensor id.
pub fn read_from(reader: impl Read, path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    let mut lines = LineReader::new(reader);
    let (header, clock, ahead) = header_and_clock(&mut lines, path, options.rate_hz)?;
    let world = options.world.unwrap_or(World::Enu);
    let mut take = TakeBuilder::new(path, InputFormat::XsensMtw, world, clock.unit());
    let mut counter = WrappingClock::new(clock.modulus());
    Rows::new(&mut take, &header.layout, clock, path, options.skip_lines).read(
        ahead,
        &mut lines,
        &mut take,
        &mut counter,
    )?;
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

/// Parses one MTw file into `take`, whose clock counts PacketCounter at `rate_hz` (the caller
/// sets the file name for reports with [`TakeBuilder::set_file`]). The sensor id comes from
/// `path`'s file name; `clock` carries the take's unwrapped counter from file to file. A file
/// with another update rate, or none, is an error.
pub fn read_file_into(
    take: &mut TakeBuilder,
    clock: &mut WrappingClock,
    reader: impl Read,
    path: &Path,
    rate_hz: f64,
    skip_lines: u64,
) -> Result<(), ReadError> {
    let options = ReadOptions {
        skip_lines,
        ..ReadOptions::default()
    };
    read_file_with(
        take,
        clock,
        reader,
        path,
        Clock::Packets { rate_hz },
        &options,
    )
}

/// [`read_file_into`] for a take whose times come from `expected`: a file whose clock is
/// another is an error.
fn read_file_with(
    take: &mut TakeBuilder,
    clock: &mut WrappingClock,
    reader: impl Read,
    path: &Path,
    expected: Clock,
    options: &ReadOptions,
) -> Result<(), ReadError> {
    let mut lines = LineReader::new(reader);
    let (header, file_clock, ahead) = header_and_clock(&mut lines, path, options.rate_hz)?;
    if !file_clock.same(expected) {
        let detail = match (file_clock, expected) {
            (Clock::Packets { rate_hz: a }, Clock::Packets { rate_hz: b }) => {
                format!("update rate {a} Hz differs from the take's {b} Hz")
            }
            _ => format!(
                "times from {} differ from the take's, {}",
                file_clock.describe(),
                expected.describe()
            ),
        };
        return Err(ReadError::format(
            path,
            format!("{detail}; expected the files of one recording"),
        ));
    }
    Rows::new(take, &header.layout, expected, path, options.skip_lines)
        .read(ahead, &mut lines, take, clock)
}

fn field_count_ok(layout: &Layout, f: &[&[u8]; MAX_COLUMNS], n: usize) -> bool {
    // A trailing separator on data rows only is tolerated.
    n == layout.columns
        || (n == layout.columns + 1 && f.get(n - 1).is_some_and(|x| x.trim_ascii().is_empty()))
}

/// What reading a file's rows needs, row after row.
struct Rows<'a> {
    layout: &'a Layout,
    clock: Clock,
    sensor: SensorIdx,
    worst_norm_error: f64,
    skip_lines: u64,
    path: &'a Path,
}

impl<'a> Rows<'a> {
    /// The rows of `path` (its sensor named in `take`), timed by `clock`.
    fn new(
        take: &mut TakeBuilder,
        layout: &'a Layout,
        clock: Clock,
        path: &'a Path,
        skip_lines: u64,
    ) -> Self {
        Rows {
            layout,
            clock,
            sensor: take.sensor(&sensor_id(path)),
            worst_norm_error: 0.0,
            skip_lines,
            path,
        }
    }

    /// Reads the rows: the lines read ahead, then the rest of `lines`.
    fn read<R: Read>(
        mut self,
        ahead: Ahead,
        lines: &mut LineReader<R>,
        take: &mut TakeBuilder,
        counter: &mut WrappingClock,
    ) -> Result<(), ReadError> {
        counter.start_file();
        for (line_no, line) in &ahead {
            self.row(take, counter, *line_no, line)?;
        }
        while let Some((line_no, line)) = lines
            .next_line()
            .map_err(|e| ReadError::lines(self.path, e))?
        {
            self.row(take, counter, line_no, line)?;
        }
        let file = self
            .path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned());
        warn_if_denormalised(
            take,
            self.worst_norm_error,
            Some(file.as_deref().unwrap_or_default()),
        );
        Ok(())
    }

    fn row(
        &mut self,
        take: &mut TakeBuilder,
        counter: &mut WrappingClock,
        line_no: u64,
        line: &[u8],
    ) -> Result<(), ReadError> {
        let layout = self.layout;
        if line.trim_ascii().is_empty() {
            return Ok(());
        }
        if line_no <= self.skip_lines {
            take.drop_line(line_no, "skipped by --skip-lines", line);
            return Ok(());
        }
        let mut f = [&b""[..]; MAX_COLUMNS];
        let n = split_fields(line, layout.sep, &mut f);
        if !field_count_ok(layout, &f, n) {
            let sep = match layout.sep {
                b'\t' => "tab",
                b',' => "comma",
                _ => "semicolon",
            };
            take.drop_line(
                line_no,
                format!(
                    "expected {} {sep}-separated fields as in the column row, found {n}",
                    layout.columns
                ),
                line,
            );
            return Ok(());
        }
        let Some(column) = self.clock.column(layout) else {
            take.drop_line(line_no, "no SampleTimeFine column", line);
            return Ok(());
        };
        let value = match self.clock.value(f[column]) {
            Ok(v) => v,
            Err(problem) => {
                take.drop_line(line_no, problem, line);
                return Ok(());
            }
        };
        let t = counter.unwrap(value) as f64;
        match parse_values(layout, &f) {
            Ok(values) => push_values(
                take,
                self.sensor,
                t,
                values,
                line_no,
                line,
                &mut self.worst_norm_error,
            )
            .map_err(|e| ReadError::take(self.path, e)),
            Err(problem) => {
                take.drop_line(line_no, problem, line);
                Ok(())
            }
        }
    }
}

enum OrientationValue {
    Quaternion(UnitQuaternion<f64>, f64),
    RollPitchYaw(YawPitchRollDeg),
}

struct Values {
    orientation: Option<OrientationValue>,
    imu: Option<ImuSample>,
    mag: Option<Vector3<f64>>,
}

/// Converts R_GS (`Mat[r][c]` at `[r-1][c-1]`) to q_world_sensor; `None` unless it is a rotation.
pub fn rotation_matrix_to_quaternion(m: [[f64; 3]; 3]) -> Option<UnitQuaternion<f64>> {
    let r = Matrix3::from_fn(|i, j| m[i][j]);
    let error = (r.transpose() * r - Matrix3::identity()).abs().max();
    if !error.is_finite() || error > ORTHONORMAL_TOLERANCE || r.determinant() <= 0.0 {
        return None;
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let q = q.into_inner();
    let norm = q.norm();
    (norm.is_finite() && norm > 1e-9).then(|| UnitQuaternion::new_unchecked(q / norm))
}

fn parse_values(layout: &Layout, f: &[&[u8]; MAX_COLUMNS]) -> Result<Values, String> {
    let num = |i: usize, name: &str| {
        let field = f.get(i).copied().unwrap_or(b"");
        parse_f64(field).ok_or_else(|| format!("{name} {}", number_problem(field)))
    };
    let vec3 = |c: [usize; 3], names: [&str; 3]| -> Result<Vector3<f64>, String> {
        Ok(Vector3::new(
            num(c[0], names[0])?,
            num(c[1], names[1])?,
            num(c[2], names[2])?,
        ))
    };
    let orientation = match layout.orientation {
        None => None,
        Some(Orientation::Quaternion(c)) => {
            let q = Quaternion::new(
                num(c[0], "Quat_q0")?,
                num(c[1], "Quat_q1")?,
                num(c[2], "Quat_q2")?,
                num(c[3], "Quat_q3")?,
            );
            let norm = q.norm();
            if !norm.is_finite() || norm < 1e-9 {
                return Err(
                    "quaternion is zero; expected a unit quaternion Quat_q0..Quat_q3".into(),
                );
            }
            Some(OrientationValue::Quaternion(
                UnitQuaternion::new_unchecked(q / norm),
                norm,
            ))
        }
        Some(Orientation::Matrix(cols)) => {
            let mut m = [[0.0; 3]; 3];
            for (r, row) in m.iter_mut().enumerate() {
                for (c, value) in row.iter_mut().enumerate() {
                    *value = num(cols[r][c], MAT_NAMES[r][c])?;
                }
            }
            let q = rotation_matrix_to_quaternion(m).ok_or_else(|| {
                format!(
                    "Mat[1][1]..Mat[3][3] is not a rotation matrix (columns not orthonormal within \
                     {ORTHONORMAL_TOLERANCE}, or a reflection)"
                )
            })?;
            Some(OrientationValue::Quaternion(q, 1.0))
        }
        Some(Orientation::RollPitchYaw(c)) => {
            Some(OrientationValue::RollPitchYaw(YawPitchRollDeg {
                roll: num(c[0], "Roll")?,
                pitch: num(c[1], "Pitch")?,
                yaw: num(c[2], "Yaw")?,
            }))
        }
    };
    let imu = match layout.inertial {
        Some((a, g)) => Some(ImuSample {
            accel_m_s2: vec3(a, ["Acc_X", "Acc_Y", "Acc_Z"])?,
            gyro_rad_s: vec3(g, ["Gyr_X", "Gyr_Y", "Gyr_Z"])?,
        }),
        None => None,
    };
    let mag = layout
        .mag
        .map(|m| vec3(m, ["Mag_X", "Mag_Y", "Mag_Z"]))
        .transpose()?;
    Ok(Values {
        orientation,
        imu,
        mag,
    })
}

fn push_values(
    take: &mut TakeBuilder,
    sensor: SensorIdx,
    t: f64,
    values: Values,
    line_no: u64,
    raw: &[u8],
    worst_norm_error: &mut f64,
) -> Result<(), BuildError> {
    match values.orientation {
        Some(OrientationValue::Quaternion(q, norm)) => {
            *worst_norm_error = worst_norm_error.max((norm - 1.0).abs());
            take.push_quaternion(sensor, t, q, line_no, raw)?;
        }
        Some(OrientationValue::RollPitchYaw(ypr)) => {
            take.push_yaw_pitch_roll(sensor, t, ypr, line_no, raw)?;
        }
        None => {}
    }
    if let Some(imu) = values.imu {
        take.push_inertial(sensor, t, imu, line_no, raw)?;
    }
    if let Some(mag) = values.mag {
        take.push_magnetometer(sensor, t, mag, line_no, raw)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::take::OrientationTrack;
    use proptest::prelude::*;

    const HEAD: &str = "// Start Time: Unknown\r\n// Update Rate: 100.0Hz\r\n// Filter Profile: human (46.1)\r\n\
        PacketCounter\tSampleTimeFine\tAcc_X\tAcc_Y\tAcc_Z\tMat[1][1]\tMat[2][1]\tMat[3][1]\tMat[1][2]\tMat[2][2]\tMat[3][2]\tMat[1][3]\tMat[2][3]\tMat[3][3]\r\n";

    /// A row with a 90° rotation about z: R = [0 -1 0; 1 0 0; 0 0 1], written column-major.
    fn row(counter: &str) -> String {
        format!("{counter}\t\t0\t0\t9.8\t0\t1\t0\t-1\t0\t0\t0\t0\t1\r\n")
    }

    fn read_str(name: &str, text: &str) -> Result<Take, ReadError> {
        read_from(text.as_bytes(), Path::new(name), &ReadOptions::default())
    }

    fn quats(take: &Take, id: &str) -> Vec<(f64, UnitQuaternion<f64>)> {
        let Some(OrientationTrack::Quaternion(t)) = take.sensor(id).unwrap().orientation() else {
            panic!("no quaternion track");
        };
        t.iter().map(|(time, q)| (time, *q)).collect()
    }

    #[test]
    fn matrix_is_r_gs_in_column_major_order() {
        let text = format!("{HEAD}{}{}", row("00472"), row("00473"));
        let take = read_str("MT_012005D6_009-001_00B421EF.txt", &text).unwrap();
        assert_eq!(take.source().world, World::Enu);
        assert_eq!(take.source().start_timestamp, "PacketCounter 472 at 100 Hz");
        let q = quats(&take, "00B421EF");
        assert_eq!(q.len(), 2);
        assert!((q[1].0 - 0.01).abs() < 1e-12);
        // sensor x maps to world y: column 1 of R_GS is (Mat[1][1], Mat[2][1], Mat[3][1]) = (0, 1, 0)
        let x = q[0].1 * Vector3::x();
        assert!((x - Vector3::y()).norm() < 1e-12, "{x}");
        let expected =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        assert!(q[0].1.angle_to(&expected) < 1e-9);
    }

    #[test]
    fn rotation_matrix_conversion_covers_all_branches() {
        for axis in [Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis()] {
            for angle in [0.0, 0.3, 2.0, std::f64::consts::PI, -3.0] {
                let q = UnitQuaternion::from_axis_angle(&axis, angle);
                let r = q.to_rotation_matrix().into_inner();
                let m = [
                    [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
                    [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
                    [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
                ];
                let back = rotation_matrix_to_quaternion(m).unwrap();
                assert!(back.angle_to(&q) < 1e-9, "{axis:?} {angle}");
            }
        }
        assert!(rotation_matrix_to_quaternion([[0.0; 3]; 3]).is_none());
        assert!(
            rotation_matrix_to_quaternion([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
                .is_none()
        );
        assert!(
            rotation_matrix_to_quaternion([[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
                .is_none()
        );
    }

    #[test]
    fn counter_wrap_and_bad_rows() {
        let text = format!(
            "{HEAD}{}{}{}{}{}{}{}{}{}{}",
            row("65534"),
            row("65535"),
            row("00001"), // one packet lost across the wrap
            row("00000"), // late row: sorted into place
            row("00001"), // repeat
            "00002\t\t0\t0\t9.8\t0\t1\t0\r\n",
            "00003\t\t0\t0\t9.8\t0\t0\t0\t0\t0\t0\t0\t0\t0\r\n",
            "\t\t0\t0\t9.8\t0\t1\t0\t-1\t0\t0\t0\t0\t1\r\n",
            "00004\t\t0\t0\t9.8\t0\t1\tnan\t-1\t0\t0\t0\t0\t1\r\n",
            "70000\t\t0\t0\t9.8\t0\t1\t0\t-1\t0\t0\t0\t0\t1\r\n",
        );
        let take = read_str("a_S1.txt", &text).unwrap();
        let times: Vec<f64> = quats(&take, "S1").iter().map(|s| s.0).collect();
        assert_eq!(times.len(), 4);
        for (t, e) in times.iter().zip([0.0, 0.01, 0.02, 0.03]) {
            assert!((t - e).abs() < 1e-9, "{times:?}");
        }
        let reasons: Vec<(u64, String)> = take
            .dropped_lines()
            .iter()
            .map(|d| (d.line, d.reason.clone()))
            .collect();
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == 9 && r.contains("repeats")),
            "{reasons:?}"
        );
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == 10 && r.contains("found 8"))
        );
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == 11 && r.contains("not a rotation"))
        );
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == 12 && r == "PacketCounter is empty")
        );
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == 13 && r == "Mat[3][1] is NaN")
        );
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == 14 && r.contains("16-bit"))
        );
        assert_eq!(reasons.len(), 6);
        assert!(take.repaired_lines().iter().any(|r| r.line == 8));
    }

    #[test]
    fn quaternion_euler_inertial_and_comma_columns() {
        let text = "// Update Rate: 50Hz\nPacketCounter,Quat_q0,Quat_q1,Quat_q2,Quat_q3,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z,Mag_X,Mag_Y,Mag_Z,Roll,Pitch,Yaw\n\
                    1,0,0,0,2,0,0,9.8,0.1,0.2,0.3,1,2,3,0,0,180\n";
        let take = read_str("x_Q.txt", text).unwrap();
        let s = take.sensor("Q").unwrap();
        let q = quats(&take, "Q")[0].1;
        assert_eq!([q.w, q.i, q.j, q.k], [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(
            s.inertial().unwrap().values()[0].gyro_rad_s,
            Vector3::new(0.1, 0.2, 0.3)
        );
        assert_eq!(
            s.magnetometer().unwrap().values()[0],
            Vector3::new(1.0, 2.0, 3.0)
        );
        assert!(take.warnings().iter().any(|w| w.contains("deviate")));
        let text = "// Update Rate: 60Hz\nPacketCounter\tRoll\tPitch\tYaw\t\n7\t10\t20\t30\t\n";
        let take = read_str("x_E.txt", text).unwrap();
        let Some(OrientationTrack::YawPitchRollDeg(t)) = take.sensor("E").unwrap().orientation()
        else {
            panic!("expected yaw/pitch/roll");
        };
        assert_eq!(
            t.values()[0],
            YawPitchRollDeg {
                yaw: 30.0,
                pitch: 20.0,
                roll: 10.0
            }
        );
    }

    #[test]
    fn header_errors() {
        let e = read_str("a_b.txt", "PacketCounter\tMat[1][1]\n").unwrap_err();
        assert!(e.to_string().contains("Mat[2][1]"), "{e}");
        let e = read_str(
            "a_b.txt",
            "PacketCounter\tQuat_q0\tQuat_q1\tQuat_q2\tQuat_q3\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("Update Rate"), "{e}");
        let e = read_str("a_b.txt", "// Update Rate: fast\nPacketCounter\n").unwrap_err();
        assert!(e.to_string().contains("line 1"), "{e}");
        let e = read_str("a_b.txt", "// Update Rate: 100Hz\nCounter\tQuat_q0\n").unwrap_err();
        assert!(e.to_string().contains("no PacketCounter"), "{e}");
        let e = read_str(
            "a_b.txt",
            "// Update Rate: 100Hz\nPacketCounter\tAcc_X\tAcc_Y\tAcc_Z\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("no orientation"), "{e}");
        let e = read_str("a_b.txt", "// Update Rate: 100Hz\n").unwrap_err();
        assert!(e.to_string().contains("no column row"), "{e}");
    }

    #[test]
    fn folder_files_share_one_counter_clock() {
        // File B starts after A's counter wrapped; B is read first (sorted by name) but the clock is
        // anchored at A's start.
        let a = format!("{HEAD}{}{}", row("65530"), row("65535"));
        let b = format!("{HEAD}{}{}", row("00002"), row("00003"));
        let mut take = TakeBuilder::new(
            "dir",
            InputFormat::XsensMtw,
            World::Enu,
            ClockUnit::Counter {
                name: "PacketCounter".into(),
                rate_hz: 100.0,
            },
        );
        let mut clock = WrappingClock::anchored_at_earliest(PACKET_COUNTER_MODULUS, &[2, 65530]);
        take.set_file(Some("x_B.txt".into()));
        read_file_into(
            &mut take,
            &mut clock,
            b.as_bytes(),
            Path::new("x_B.txt"),
            100.0,
            0,
        )
        .unwrap();
        take.set_file(Some("x_A.txt".into()));
        read_file_into(
            &mut take,
            &mut clock,
            a.as_bytes(),
            Path::new("x_A.txt"),
            100.0,
            0,
        )
        .unwrap();
        let e = read_file_into(
            &mut take,
            &mut clock,
            a.as_bytes(),
            Path::new("x_C.txt"),
            60.0,
            0,
        )
        .unwrap_err();
        assert!(e.to_string().contains("differs"), "{e}");
        let take = take.finish(0.0).unwrap();
        assert_eq!(
            take.source().start_timestamp,
            "PacketCounter 65530 at 100 Hz"
        );
        let b_times: Vec<f64> = quats(&take, "B").iter().map(|s| s.0).collect();
        assert!((b_times[0] - 0.08).abs() < 1e-9, "{b_times:?}");
    }

    /// Without an update rate the clock is judged by the first data row; the lines read ahead
    /// for it (a damaged row, a blank line) are read as rows after, the damaged one reported.
    /// A folder's files must agree on their clock.
    #[test]
    fn rows_read_ahead_for_the_clock_are_read_and_reported() {
        let text = "// Coordinate system: ENU\nPacketCounter\tSampleTimeFine\tQuat_q0\tQuat_q1\tQuat_q2\tQuat_q3\n\
                    00001\t100\t1\t0\n\n00002\t200\t1\t0\t0\t0\n00003\t300\t1\t0\t0\t0\n";
        let take = read_str("a_S.txt", text).unwrap();
        let times: Vec<f64> = quats(&take, "S").iter().map(|s| s.0).collect();
        assert_eq!(times.len(), 2);
        assert!((times[1] - 0.01).abs() < 1e-12, "{times:?}");
        assert_eq!(
            take.source().start_timestamp,
            "SampleTimeFine 200 at 10000 Hz"
        );
        let dropped: Vec<(u64, &str)> = take
            .dropped_lines()
            .iter()
            .map(|d| (d.line, d.reason.as_str()))
            .collect();
        assert_eq!(
            dropped,
            [(
                3,
                "expected 6 tab-separated fields as in the column row, found 4"
            )]
        );

        let mut take =
            TakeBuilder::new("dir", InputFormat::XsensMtw, World::Enu, Clock::Fine.unit());
        let mut clock = WrappingClock::new(SAMPLE_TIME_FINE_MODULUS);
        let e = read_file_with(
            &mut take,
            &mut clock,
            HEAD.as_bytes(),
            Path::new("x_B.txt"),
            Clock::Fine,
            &ReadOptions::default(),
        )
        .unwrap_err();
        assert!(
            e.to_string().contains(
                "times from PacketCounter at 100 Hz differ from the take's, SampleTimeFine"
            ),
            "{e}"
        );
    }

    #[test]
    fn detection_and_ids() {
        assert!(looks_like(HEAD.as_bytes()));
        assert!(looks_like(b"PacketCounter\tAcc_X\n"));
        assert!(!looks_like(
            b"PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z\n"
        ));
        assert!(!looks_like(b"1000,N0,1,2,3,4,5,6\n"));
        assert_eq!(
            sensor_id(Path::new("MT_012005D6_009-001_00B421EF.txt")),
            "00B421EF"
        );
        assert_eq!(sensor_id(Path::new("pelvis.txt")), "pelvis");
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_do_not_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
            let _ = read_from(&bytes[..], Path::new("p_S.txt"), &ReadOptions::default());
            let _ = looks_like(&bytes);
        }

        #[test]
        fn mutated_fixture_does_not_panic(
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..16),
            cut in any::<prop::sample::Index>(),
        ) {
            let mut bytes = format!("{HEAD}{}{}{}", row("65535"), row("00000"), row("00001")).into_bytes();
            for (at, b) in edits {
                let i = at.index(bytes.len());
                bytes[i] = b;
            }
            bytes.truncate(cut.index(bytes.len() + 1));
            let _ = read_from(&bytes[..], Path::new("p_S.txt"), &ReadOptions::default());
        }
    }
}
