//! Movella/Xsens DOT CSV exports: a folder with one CSV per sensor (one take), or one such file.
//!
//! ```text
//! sep=,
//! DeviceTag:,zdt
//! OutputRate:,60Hz
//! StartTime: ,2021-08-20_20:21:13_829 GMT+8
//! © Xsens Technologies B. V. 2005-2021
//!
//! PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z,FreeAcc_X,FreeAcc_Y,FreeAcc_Z,Status
//! 1,3343444552,0.411830,-0.431467,-0.561427,-0.573619,0.016456,0.019243,-0.046306,0
//! ```
//!
//! - Metadata lines (anything before the header row) are read past; the header row is the first
//!   line with a `SampleTimeFine` field. Column names are matched case-insensitively, in any order.
//! - Time: `SampleTimeFine`, the sensor's 1 MHz clock (µs), a 32-bit counter that wraps at 2³²
//!   (about 71.6 minutes). It is unwrapped within a file (each row is placed at the nearest
//!   unwrapped value to the previous row's, so a wrap and small out-of-order steps both come out
//!   right), and the files of a folder are put on one clock: each file's first value is placed
//!   within half a wrap of the take's anchor, the earliest-starting file, so a file that started
//!   after another file's wrap lands after it, not 71 minutes earlier. `ClockUnit::Microseconds`;
//!   the sidecar start timestamp is the unwrapped counter of t = 0.
//! - Orientation: `Quat_W,Quat_X,Quat_Y,Quat_Z` (q_world_sensor in Xsens' local earth frame, ENU),
//!   normalised; else `Euler_X,Euler_Y,Euler_Z` = roll, pitch, yaw in degrees. The DOT user manual
//!   defines them as the Z-Y-X (aerospace) sequence, R = Rz(yaw)·Ry(pitch)·Rx(roll), so they are
//!   stored verbatim with `push_yaw_pitch_roll` (yaw = Euler_Z). Quaternions win when both exist.
//! - Raw data when exported: `Acc_X..Z` (m/s²) with `Gyr_X..Z` (°/s, converted to rad/s) become an
//!   inertial stream, `Mag_X..Z` (a.u.) a magnetometer stream. `PacketCounter`, `FreeAcc_*`,
//!   `Status` and other columns are not used.
//! - Sensor id: the file name before the first `_` (`LFemur_20210820_….csv` → `LFemur`).
//! - World: ENU (`--world` overrides).
//!
//! Footer: some exports end with the copyright text glued onto the last data row without a
//! newline (`…,0© Xsens Technologies B. V. 2005-2021`). The text from `©` on is removed, the row's
//! data is kept, and the line is reported as repaired ("vendor footer text removed"). A footer on a
//! line of its own (starting with `©`) after the header is vendor text, not data, and is ignored
//! like the metadata lines. Any other data row that cannot be used is dropped and reported.
//! `--skip-lines N` drops data rows whose line number is at most N in each file.

use super::clock::{WrappingClock, parse_counter};
use super::lines::{LineReader, number_problem, parse_f64, split_fields};
use super::{
    HeaderCheck, InputFormat, PerSensorFolder, ReadError, ReadOptions, column_group,
    read_single_file, unit_quaternion, warn_if_denormalised,
};
use crate::take::{ClockUnit, ImuSample, SensorIdx, Take, TakeBuilder, YawPitchRollDeg};
use crate::world::World;
use nalgebra::{Quaternion, Vector3};
use std::fs;
use std::io::Read;
use std::path::Path;

/// `SampleTimeFine` wraps at 2³² µs.
pub const SAMPLE_TIME_FINE_MODULUS: u64 = 1 << 32;

/// At most this many columns are looked at.
const MAX_COLUMNS: usize = 64;

/// Metadata lines read before giving up on finding the header row.
const MAX_METADATA_LINES: u64 = 1000;

const EXPECTED_HEADER: &str = "a header row with SampleTimeFine and Quat_W,Quat_X,Quat_Y,Quat_Z or \
     Euler_X,Euler_Y,Euler_Z (or Acc_X..Z with Gyr_X..Z), e.g. \
     `PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z,FreeAcc_X,FreeAcc_Y,FreeAcc_Z,Status`";

/// Sensor id of a DOT file: the file name before the first `_` (else the stem).
pub fn sensor_id(path: &Path) -> String {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let stem = path
        .file_stem()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    match name.split('_').next() {
        Some(id) if !id.is_empty() && name.contains('_') => id.to_string(),
        _ if !stem.is_empty() => stem,
        _ => "dot".to_string(),
    }
}

/// Column positions resolved from the header row.
#[derive(Debug, Clone, PartialEq)]
struct Layout {
    columns: usize,
    time: usize,
    quat: Option<[usize; 4]>,
    euler: Option<[usize; 3]>,
    acc: Option<[usize; 3]>,
    gyr: Option<[usize; 3]>,
    mag: Option<[usize; 3]>,
}

fn fields_of(line: &[u8]) -> Vec<String> {
    line.split(|&b| b == b',')
        .map(|f| String::from_utf8_lossy(f.trim_ascii()).to_ascii_lowercase())
        .collect()
}

impl Layout {
    fn from_header(line: &[u8], path: &Path, line_no: u64) -> Result<Layout, ReadError> {
        let names = fields_of(line);
        let check = HeaderCheck::new(path, line_no, "header", EXPECTED_HEADER);
        check.column_count(names.len(), MAX_COLUMNS)?;
        let find = |name: &str| names.iter().position(|n| n == name);
        let group =
            |wanted: &[&str], missing: &mut Vec<String>| column_group(find, wanted, missing);
        let three = |v: Vec<usize>| -> Option<[usize; 3]> { v.try_into().ok() };
        let mut missing = Vec::new();
        let time = find("sampletimefine");
        let quat = group(&["quat_w", "quat_x", "quat_y", "quat_z"], &mut missing)
            .and_then(|v| <[usize; 4]>::try_from(v).ok());
        let euler = group(&["euler_x", "euler_y", "euler_z"], &mut missing).and_then(three);
        let acc = group(&["acc_x", "acc_y", "acc_z"], &mut missing).and_then(three);
        let gyr = group(&["gyr_x", "gyr_y", "gyr_z"], &mut missing).and_then(three);
        let mag = group(&["mag_x", "mag_y", "mag_z"], &mut missing).and_then(three);
        let time = check.required(time, "SampleTimeFine")?;
        let missing: Vec<String> = missing.iter().map(|m| xsens_case(m)).collect();
        check.complete(&missing)?;
        let inertial = acc.is_some() && gyr.is_some();
        if quat.is_none() && euler.is_none() && !inertial {
            return Err(ReadError::line(
                path,
                line_no,
                format!("header has no orientation columns; expected {EXPECTED_HEADER}"),
            ));
        }
        Ok(Layout {
            columns: names.len(),
            time,
            quat,
            euler: if quat.is_some() { None } else { euler },
            acc: acc.filter(|_| inertial),
            gyr: gyr.filter(|_| inertial),
            mag: mag.filter(|_| inertial || quat.is_some() || euler.is_some()),
        })
    }
}

/// `quat_w` → `Quat_W`, for messages.
fn xsens_case(name: &str) -> String {
    name.split('_')
        .map(|part| {
            let mut c = part.chars();
            match c.next() {
                Some(f) if part.len() == 1 => f.to_ascii_uppercase().to_string(),
                Some(f) => f.to_ascii_uppercase().to_string() + c.as_str(),
                None => String::new(),
            }
        })
        .collect::<Vec<_>>()
        .join("_")
}

fn is_header(line: &[u8]) -> bool {
    line.contains(&b',')
        && line
            .split(|&b| b == b',')
            .any(|f| f.trim_ascii().eq_ignore_ascii_case(b"SampleTimeFine"))
}

/// True when the first lines hold a DOT header row (comma-separated, `SampleTimeFine` and
/// quaternion, Euler or raw inertial columns).
pub fn looks_like(head: &[u8]) -> bool {
    let mut reader = LineReader::over(head);
    let mut seen = 0;
    while let Ok(Some((_, line))) = reader.next_line() {
        if is_header(line) {
            let names = fields_of(line);
            let has = |n: &str| names.iter().any(|x| x == n);
            return has("quat_w") || has("euler_x") || (has("acc_x") && has("gyr_x"));
        }
        seen += 1;
        if seen > 64 {
            break;
        }
    }
    false
}

/// Position of a vendor footer glued onto a line: the `©` sign (UTF-8 or Latin-1).
fn footer_start(line: &[u8]) -> Option<usize> {
    line.iter().position(|&b| b == 0xA9).map(|i| {
        if i > 0 && line.get(i - 1) == Some(&0xC2) {
            i - 1
        } else {
            i
        }
    })
}

/// Reads a DOT file, or a folder of DOT files (one take).
pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    let meta = fs::metadata(path).map_err(|e| ReadError::io(path, e))?;
    if !meta.is_dir() {
        return read_single_file(path, options, read_from);
    }
    let folder = PerSensorFolder::open(
        path,
        looks_like,
        "Movella DOT CSV",
        &format!("one CSV per sensor with {EXPECTED_HEADER}"),
        sensor_id,
    )?;
    let mut clock = folder.anchored_clock(SAMPLE_TIME_FINE_MODULUS, |f, file, _| {
        first_sample_time(f, file)
    })?;
    let world = options.world.unwrap_or(World::Enu);
    let mut take = TakeBuilder::new(path, InputFormat::XsensDot, world, ClockUnit::Microseconds);
    folder.read_into(&mut take, &mut clock, |take, clock, f, file| {
        read_file_into(take, clock, f, file, options.skip_lines)
    })?;
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

/// The first parseable `SampleTimeFine` of a file (for anchoring a folder's clock).
fn first_sample_time(reader: impl Read, path: &Path) -> Result<Option<u64>, ReadError> {
    let mut lines = LineReader::new(reader);
    let mut layout = None;
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        match &layout {
            None if is_header(line) => layout = Some(Layout::from_header(line, path, line_no)?),
            None => {}
            Some(layout) => {
                let line = &line[..footer_start(line).unwrap_or(line.len())];
                let mut f = [&b""[..]; MAX_COLUMNS];
                let n = split_fields(line, b',', &mut f);
                if n == layout.columns
                    && let Ok(t) = parse_counter(f[layout.time])
                    && t < SAMPLE_TIME_FINE_MODULUS
                {
                    return Ok(Some(t));
                }
            }
        }
    }
    Ok(None)
}

/// Reads one DOT file as a take; `path` names it in reports and gives the sensor id.
pub fn read_from(reader: impl Read, path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    let world = options.world.unwrap_or(World::Enu);
    let mut take = TakeBuilder::new(path, InputFormat::XsensDot, world, ClockUnit::Microseconds);
    let mut clock = WrappingClock::new(SAMPLE_TIME_FINE_MODULUS);
    read_file_into(&mut take, &mut clock, reader, path, options.skip_lines)?;
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

/// Parses one DOT file into `take` (the caller sets the file name for reports with
/// [`TakeBuilder::set_file`]). The sensor id comes from `path`'s file name; `clock` carries the
/// take's unwrapped `SampleTimeFine` from file to file.
pub fn read_file_into(
    take: &mut TakeBuilder,
    clock: &mut WrappingClock,
    reader: impl Read,
    path: &Path,
    skip_lines: u64,
) -> Result<(), ReadError> {
    let mut lines = LineReader::new(reader);
    let mut layout = None;
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        if is_header(line) {
            layout = Some(Layout::from_header(line, path, line_no)?);
            break;
        }
        if line_no >= MAX_METADATA_LINES {
            break;
        }
    }
    let Some(layout) = layout else {
        return Err(ReadError::format(
            path,
            format!("no header row found; expected metadata lines, then {EXPECTED_HEADER}"),
        ));
    };
    let sensor = take.sensor(&sensor_id(path));
    clock.start_file();
    let mut worst_norm_error: f64 = 0.0;
    while let Some((line_no, raw)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        let trimmed = raw.trim_ascii();
        if trimmed.is_empty() {
            continue;
        }
        let footer = footer_start(raw);
        if footer.is_some_and(|i| raw[..i].trim_ascii().is_empty()) {
            // The copyright footer on a line of its own: vendor text, not data.
            continue;
        }
        if line_no <= skip_lines {
            take.drop_line(line_no, "skipped by --skip-lines", raw);
            continue;
        }
        let line = &raw[..footer.unwrap_or(raw.len())];
        match parse_row(&layout, line) {
            Ok(row) => {
                let t = clock.unwrap(row.time) as f64;
                if let Some(reason) = row.problem {
                    take.drop_line(line_no, reason, raw);
                    continue;
                }
                push_row(take, sensor, t, &row, line_no, raw, &mut worst_norm_error)
                    .map_err(|e| ReadError::take(path, e))?;
                if footer.is_some() {
                    take.repair_line(line_no, "vendor footer text removed", raw);
                }
            }
            Err(reason) => take.drop_line(line_no, reason, raw),
        }
    }
    let file = path.file_name().map(|n| n.to_string_lossy().into_owned());
    warn_if_denormalised(
        take,
        worst_norm_error,
        Some(file.as_deref().unwrap_or_default()),
    );
    Ok(())
}

/// A parsed data row. `problem` is set when the time is usable but the values are not: the time
/// still advances the unwrapping clock.
struct Row {
    time: u64,
    problem: Option<String>,
    quat: Option<Quaternion<f64>>,
    euler: Option<[f64; 3]>,
    imu: Option<ImuSample>,
    mag: Option<Vector3<f64>>,
}

fn parse_row(layout: &Layout, line: &[u8]) -> Result<Row, String> {
    let mut f = [&b""[..]; MAX_COLUMNS];
    let n = split_fields(line, b',', &mut f);
    if n != layout.columns {
        return Err(format!(
            "expected {} comma-separated fields as in the header, found {n}",
            layout.columns
        ));
    }
    let time = match parse_counter(f[layout.time]) {
        Ok(t) if t < SAMPLE_TIME_FINE_MODULUS => t,
        Ok(_) => return Err("SampleTimeFine is larger than a 32-bit counter".to_string()),
        Err(problem) => return Err(format!("SampleTimeFine {problem}")),
    };
    let mut row = Row {
        time,
        problem: None,
        quat: None,
        euler: None,
        imu: None,
        mag: None,
    };
    let values = (|| -> Result<(), String> {
        let num = |i: usize, name: &str| {
            parse_f64(f[i]).ok_or_else(|| format!("{name} {}", number_problem(f[i])))
        };
        let vec3 = |c: [usize; 3], names: [&str; 3]| -> Result<Vector3<f64>, String> {
            Ok(Vector3::new(
                num(c[0], names[0])?,
                num(c[1], names[1])?,
                num(c[2], names[2])?,
            ))
        };
        if let Some(c) = layout.quat {
            let q = Quaternion::new(
                num(c[0], "Quat_W")?,
                num(c[1], "Quat_X")?,
                num(c[2], "Quat_Y")?,
                num(c[3], "Quat_Z")?,
            );
            row.quat = Some(q);
        }
        if let Some(c) = layout.euler {
            let e = vec3(c, ["Euler_X", "Euler_Y", "Euler_Z"])?;
            row.euler = Some([e.x, e.y, e.z]);
        }
        if let (Some(a), Some(g)) = (layout.acc, layout.gyr) {
            row.imu = Some(ImuSample {
                gyro_rad_s: vec3(g, ["Gyr_X", "Gyr_Y", "Gyr_Z"])? * std::f64::consts::PI / 180.0,
                accel_m_s2: vec3(a, ["Acc_X", "Acc_Y", "Acc_Z"])?,
            });
        }
        if let Some(m) = layout.mag {
            row.mag = Some(vec3(m, ["Mag_X", "Mag_Y", "Mag_Z"])?);
        }
        Ok(())
    })();
    if let Err(problem) = values {
        row.problem = Some(problem);
    } else if row.quat.is_some_and(|q| unit_quaternion(q).is_none()) {
        row.problem =
            Some("quaternion is zero; expected a unit quaternion Quat_W..Quat_Z".to_string());
    }
    Ok(row)
}

fn push_row(
    take: &mut TakeBuilder,
    sensor: SensorIdx,
    t: f64,
    row: &Row,
    line_no: u64,
    raw: &[u8],
    worst_norm_error: &mut f64,
) -> Result<(), crate::take::BuildError> {
    if let Some((q, norm)) = row.quat.and_then(unit_quaternion) {
        *worst_norm_error = worst_norm_error.max((norm - 1.0).abs());
        take.push_quaternion(sensor, t, q, line_no, raw)?;
    }
    if let Some([roll, pitch, yaw]) = row.euler {
        take.push_yaw_pitch_roll(
            sensor,
            t,
            YawPitchRollDeg { yaw, pitch, roll },
            line_no,
            raw,
        )?;
    }
    if let Some(imu) = row.imu {
        take.push_inertial(sensor, t, imu, line_no, raw)?;
    }
    if let Some(mag) = row.mag {
        take.push_magnetometer(sensor, t, mag, line_no, raw)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::take::OrientationTrack;
    use proptest::prelude::*;

    const META: &str = "sep=,\nDeviceTag:,zdt\nOutputRate:,60Hz\nStartTime: ,2021-08-20_20:21:13_829 GMT+8\n\u{a9} Xsens Technologies B. V. 2005-2021\n\n";
    const HEADER: &str = "PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z,FreeAcc_X,FreeAcc_Y,FreeAcc_Z,Status\n";

    fn file(rows: &str) -> String {
        format!("{META}{HEADER}{rows}")
    }

    fn read_str(name: &str, text: &str) -> Result<Take, ReadError> {
        read_from(text.as_bytes(), Path::new(name), &ReadOptions::default())
    }

    fn quats(take: &Take, id: &str) -> Vec<(f64, [f64; 4])> {
        let Some(OrientationTrack::Quaternion(t)) = take.sensor(id).unwrap().orientation() else {
            panic!("no quaternion track");
        };
        t.iter()
            .map(|(time, q)| (time, [q.w, q.i, q.j, q.k]))
            .collect()
    }

    #[test]
    fn reads_a_file_and_names_the_sensor() {
        let text = file(
            "1,1000,1,0,0,0,0,0,0,0\n2,17667,0,2,0,0,0,0,0,0\n3,34334,0.5,0.5,0.5,0.5,0,0,0,0\n",
        );
        let take = read_str("dir/LFemur_20210820_202113_831.csv", &text).unwrap();
        assert_eq!(take.source().world, World::Enu);
        assert_eq!(take.source().start_timestamp, "1000 us");
        let q = quats(&take, "LFemur");
        assert_eq!(q.len(), 3);
        assert!((q[1].0 - 0.016667).abs() < 1e-12);
        assert_eq!(q[1].1, [0.0, 1.0, 0.0, 0.0]);
        assert!((q[2].0 - 0.033334).abs() < 1e-12);
        assert!(take.dropped_lines().is_empty() && take.repaired_lines().is_empty());
        assert_eq!(sensor_id(Path::new("Pelvis.csv")), "Pelvis");
        assert_eq!(sensor_id(Path::new("_x.csv")), "_x");
    }

    #[test]
    fn bad_rows_crlf_and_glued_footer() {
        let text = file(
            "1,1000,1,0,0,0,0,0,0,0\r\n\
             2,3000,1,0,0,0,0,0,0,0\r\n\
             3,2000,1,0,0,0,0,0,0,0\r\n\
             4,3000,1,0,0,0,0,0,0,0\r\n\
             5,4000,NaN,0,0,0,0,0,0,0\r\n\
             6,5000,1,0,0\r\n\
             7,6000,0,0,0,0,0,0,0,0\r\n\
             8,x,1,0,0,0,0,0,0,0\r\n\
             9,7000,1,0,0,0,0,0,0,0\u{a9} Xsens Technologies B. V. 2005-2021",
        )
        .replace('\n', "\r\n")
        .replace("\r\r\n", "\r\n");
        let take = read_str("S_1.csv", &text).unwrap();
        let times: Vec<f64> = quats(&take, "S").iter().map(|s| s.0).collect();
        assert_eq!(times, vec![0.0, 0.001, 0.002, 0.006]);
        let reasons: Vec<(u64, String)> = take
            .dropped_lines()
            .iter()
            .map(|d| (d.line, d.reason.clone()))
            .collect();
        let first = 8; // metadata 6 lines, header line 7
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == first + 3 && r.contains("repeats"))
        );
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == first + 4 && r == "Quat_W is NaN")
        );
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == first + 5 && r.contains("found 5"))
        );
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == first + 6 && r.contains("zero"))
        );
        assert!(
            reasons
                .iter()
                .any(|(l, r)| *l == first + 7 && r.contains("SampleTimeFine is not a whole"))
        );
        assert_eq!(reasons.len(), 5, "{reasons:?}");
        let repaired: Vec<(u64, &str)> = take
            .repaired_lines()
            .iter()
            .map(|r| (r.line, r.reason.as_str()))
            .collect();
        assert!(
            repaired.contains(&(first + 8, "vendor footer text removed")),
            "{repaired:?}"
        );
        assert!(repaired.iter().any(|(l, _)| *l == first + 2)); // out of order, sorted in
    }

    #[test]
    fn footer_on_its_own_line_is_ignored_and_skip_lines() {
        let text = file(
            "1,1000,1,0,0,0,0,0,0,0\n2,2000,1,0,0,0,0,0,0,0\n\u{a9} Xsens Technologies B. V. 2005-2021\n",
        );
        let take = read_str("S_1.csv", &text).unwrap();
        assert!(take.dropped_lines().is_empty());
        let options = ReadOptions {
            skip_lines: 8,
            ..ReadOptions::default()
        };
        let take = read_from(text.as_bytes(), Path::new("S_1.csv"), &options).unwrap();
        assert_eq!(take.dropped_lines().len(), 1);
        assert_eq!(take.source().start_timestamp, "2000 us");
    }

    #[test]
    fn counter_wrap_within_a_file() {
        let text = file(
            "1,4294960000,1,0,0,0,0,0,0,0\n2,4294966667,1,0,0,0,0,0,0,0\n3,6038,1,0,0,0,0,0,0,0\n4,22705,1,0,0,0,0,0,0,0\n",
        );
        let take = read_str("S_1.csv", &text).unwrap();
        let times: Vec<f64> = quats(&take, "S").iter().map(|s| s.0).collect();
        let expected = [
            0.0,
            6667.0,
            6038.0 + 4294967296.0 - 4294960000.0,
            22705.0 + 7296.0,
        ];
        for (t, e) in times.iter().zip(expected) {
            assert!((t - e * 1e-6).abs() < 1e-9, "{times:?}");
        }
    }

    #[test]
    fn euler_and_raw_columns() {
        let text = format!(
            "{META}PacketCounter,SampleTimeFine,Euler_X,Euler_Y,Euler_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z,Mag_X,Mag_Y,Mag_Z,Status\n\
             1,100,10,20,30,0,0,9.8,180,0,0,1,2,3,0\n"
        );
        let take = read_str("E_1.csv", &text).unwrap();
        let s = take.sensor("E").unwrap();
        let Some(OrientationTrack::YawPitchRollDeg(t)) = s.orientation() else {
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
        let imu = s.inertial().unwrap().values()[0];
        assert!((imu.gyro_rad_s.x - std::f64::consts::PI).abs() < 1e-12);
        assert_eq!(imu.accel_m_s2.z, 9.8);
        assert_eq!(
            s.magnetometer().unwrap().values()[0],
            Vector3::new(1.0, 2.0, 3.0)
        );
    }

    #[test]
    fn header_errors() {
        let e = read_str("S_1.csv", &format!("{META}PacketCounter,Quat_W\n")).unwrap_err();
        assert!(e.to_string().contains("no header row"), "{e}");
        let e = read_str("S_1.csv", &format!("{META}SampleTimeFine,Quat_W,Quat_X\n")).unwrap_err();
        assert!(e.to_string().contains("Quat_Y, Quat_Z"), "{e}");
        assert!(e.to_string().contains("line 7"), "{e}");
        let e = read_str("S_1.csv", &format!("{META}SampleTimeFine,FreeAcc_X\n")).unwrap_err();
        assert!(e.to_string().contains("no orientation"), "{e}");
        let e = read_str("S_1.csv", &file("")).unwrap_err();
        assert!(e.to_string().contains("no samples"), "{e}");
    }

    #[test]
    fn detection() {
        assert!(looks_like(file("").as_bytes()));
        assert!(!looks_like(b"PacketCounter\tSampleTimeFine\tQuat_q0\n"));
        assert!(!looks_like(b"time_s,sensor,qw,qx,qy,qz\n"));
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_do_not_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
            let _ = read_from(&bytes[..], Path::new("P_1.csv"), &ReadOptions::default());
            let _ = looks_like(&bytes);
        }

        #[test]
        fn mutated_fixture_does_not_panic(
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..16),
            cut in any::<prop::sample::Index>(),
        ) {
            let mut bytes = file(
                "1,4294967000,1,0,0,0,0,0,0,0\n2,100,0.5,0.5,0.5,0.5,0,0,0,0\n3,16767,1,0,0,0,0,0,0,0\u{a9} X"
            ).into_bytes();
            for (at, b) in edits {
                let i = at.index(bytes.len());
                bytes[i] = b;
            }
            bytes.truncate(cut.index(bytes.len() + 1));
            let mut take = TakeBuilder::new("p", InputFormat::XsensDot, World::Enu, ClockUnit::Microseconds);
            let mut clock = WrappingClock::new(SAMPLE_TIME_FINE_MODULUS);
            take.set_file(Some("P_1.csv".into()));
            let _ = read_file_into(&mut take, &mut clock, &bytes[..], Path::new("P_1.csv"), 0);
            let _ = read_file_into(&mut take, &mut clock, &bytes[..], Path::new("Q_1.csv"), 0);
            let _ = take.finish(0.0);
        }
    }
}
