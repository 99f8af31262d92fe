//! OpenSense orientation `.sto` files (OpenSim's `IMUPlacer` / `IMUInverseKinematics` input).
//!
//! ```text
//! DataRate=100.000000
//! DataType=Quaternion
//! version=3
//! OpenSimVersion=4.1
//! endheader
//! time<TAB>torso_imu<TAB>pelvis_imu ...
//! 0<TAB>0.5105,0.4570,-0.6688,0.2882<TAB>...
//! ```
//!
//! - Header lines run up to the line `endheader`. `key=value` lines are read for `DataType`
//!   (must be `Quaternion`: OpenSim writes `Vec3`, `double`, ... tables in the same container,
//!   which hold no orientations, and those are refused with a clear error) and `DataRate`; other
//!   header lines (a table name, `version`, `nRows`, ...) are ignored. A missing `DataType` is a
//!   warning and the columns are read as quaternions.
//! - Then the column row: `time`, then one column per sensor. Sensor ids are the column names.
//! - Each data row: the time in seconds, then per sensor a `w,x,y,z` quaternion, the orientation
//!   of the sensor in OpenSim ground (`World::Opensim`, y up), normalised on read.
//!
//! A row with the wrong number of tab-separated fields or a bad time is dropped. A bad cell (not
//! four numbers, NaN, a zero quaternion) skips only that sensor's sample: the other sensors of
//! the row are kept and the line is reported as dropped, the reason naming the column(s).
//! `--skip-lines N` drops data rows whose line number is at most N; header lines are always read.

use super::lines::{LineReader, number_problem, parse_f64};
use super::{
    InputFormat, ReadError, ReadOptions, read_single_file, unit_quaternion, warn_if_denormalised,
};
use crate::take::{ClockUnit, SensorIdx, Take, TakeBuilder};
use crate::world::World;
use nalgebra::{Quaternion, UnitQuaternion};
use std::io::Read;
use std::path::Path;

/// Header lines read before giving up on finding `endheader`.
const MAX_HEADER_LINES: u64 = 10_000;

/// True when the first lines hold an OpenSim `endheader` line.
pub fn looks_like(head: &[u8]) -> bool {
    let mut reader = LineReader::over(head);
    let mut seen = 0;
    while let Ok(Some((_, line))) = reader.next_line() {
        if line.trim_ascii().eq_ignore_ascii_case(b"endheader") {
            return true;
        }
        seen += 1;
        if seen > 200 {
            break;
        }
    }
    false
}

pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    read_single_file(path, options, read_from)
}

/// Parses one `w,x,y,z` cell.
fn parse_cell(cell: &[u8]) -> Result<(UnitQuaternion<f64>, f64), String> {
    let parts: Vec<&[u8]> = cell.split(|&b| b == b',').collect();
    if parts.len() != 4 {
        return Err(format!(
            "expected a quaternion w,x,y,z (4 comma-separated numbers), found {} field(s)",
            parts.len()
        ));
    }
    let mut v = [0.0; 4];
    for (i, (slot, part)) in v.iter_mut().zip(&parts).enumerate() {
        match parse_f64(part) {
            Some(x) => *slot = x,
            None => {
                let name = ["w", "x", "y", "z"].get(i).copied().unwrap_or("?");
                return Err(format!("{name} {}", number_problem(part)));
            }
        }
    }
    unit_quaternion(Quaternion::new(v[0], v[1], v[2], v[3]))
        .ok_or_else(|| "quaternion is zero; expected a unit quaternion w,x,y,z".to_string())
}

/// Reads an OpenSense orientation `.sto` from any reader; `path` names it in reports.
pub fn read_from(reader: impl Read, path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    let mut lines = LineReader::new(reader);
    let mut data_type: Option<String> = None;
    let mut data_rate: Option<String> = None;
    let mut end_line = None;
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        let t = line.trim_ascii();
        if t.eq_ignore_ascii_case(b"endheader") {
            end_line = Some(line_no);
            break;
        }
        if line_no >= MAX_HEADER_LINES {
            break;
        }
        let text = String::from_utf8_lossy(t);
        if let Some((key, value)) = text.split_once('=') {
            let key = key.trim();
            if key.eq_ignore_ascii_case("DataType") {
                data_type = Some(value.trim().to_string());
            } else if key.eq_ignore_ascii_case("DataRate") {
                data_rate = Some(value.trim().to_string());
            }
        }
    }
    let Some(end_line) = end_line else {
        return Err(ReadError::format(
            path,
            "no `endheader` line; expected an OpenSim .sto header (DataRate=..., DataType=Quaternion, ...) \
             ending in a line `endheader`. Hint: is this an OpenSense orientation file?",
        ));
    };
    match &data_type {
        Some(t) if t.eq_ignore_ascii_case("Quaternion") => {}
        Some(t) => {
            return Err(ReadError::format(
                path,
                format!(
                    "DataType={t}: this .sto holds `{t}` columns, not sensor orientations; expected \
                     DataType=Quaternion (an OpenSense orientation file with one w,x,y,z column per IMU). \
                     Hint: use the orientations file that OpenSense writes from the IMU data \
                     (e.g. `*_orientations.sto`)"
                ),
            ));
        }
        None => {}
    }

    // The column row.
    let mut columns: Option<(u64, Vec<String>)> = None;
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        if line.trim_ascii().is_empty() {
            continue;
        }
        let names: Vec<String> = line
            .split(|&b| b == b'\t')
            .map(|f| String::from_utf8_lossy(f.trim_ascii()).into_owned())
            .collect();
        if !names
            .first()
            .is_some_and(|n| n.eq_ignore_ascii_case("time"))
        {
            return Err(ReadError::line(
                path,
                line_no,
                "expected the column row `time<TAB><sensor>...` after `endheader`. \
                 Hint: OpenSense orientation files are tab-separated",
            ));
        }
        columns = Some((line_no, names));
        break;
    }
    let Some((columns_line, names)) = columns else {
        return Err(ReadError::line(
            path,
            end_line,
            "no column row after `endheader`; expected `time<TAB><sensor>...` and data rows",
        ));
    };
    let sensor_names = names.get(1..).unwrap_or(&[]);
    if sensor_names.is_empty() {
        return Err(ReadError::line(
            path,
            columns_line,
            "the column row has only `time`; expected one quaternion column per sensor",
        ));
    }
    for (i, name) in sensor_names.iter().enumerate() {
        if name.is_empty() {
            return Err(ReadError::line(
                path,
                columns_line,
                format!("column {} has no name; expected a sensor name", i + 2),
            ));
        }
        if sensor_names[..i].contains(name) {
            return Err(ReadError::line(
                path,
                columns_line,
                format!("column `{name}` appears twice; expected one column per sensor"),
            ));
        }
    }

    let world = options.world.unwrap_or(World::Opensim);
    let mut take = TakeBuilder::new(path, InputFormat::OpensenseSto, world, ClockUnit::Seconds);
    if data_type.is_none() {
        take.warn("the .sto header has no DataType=; columns read as w,x,y,z quaternions");
    }
    if let Some(rate) = &data_rate
        && parse_f64(rate.as_bytes()).is_none_or(|r| r <= 0.0)
    {
        take.warn(format!(
            "header DataRate={rate} is not a positive number; the row times are used"
        ));
    }
    let sensors: Vec<SensorIdx> = sensor_names.iter().map(|n| take.sensor(n)).collect();
    let expected = names.len();
    let mut worst_norm_error: f64 = 0.0;
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        if line.trim_ascii().is_empty() {
            continue;
        }
        if line_no <= options.skip_lines {
            take.drop_line(line_no, "skipped by --skip-lines", line);
            continue;
        }
        let fields: Vec<&[u8]> = line.split(|&b| b == b'\t').collect();
        if fields.len() != expected {
            take.drop_line(
                line_no,
                format!(
                    "expected {expected} tab-separated fields (time and one w,x,y,z per sensor) as in the \
                     column row, found {}",
                    fields.len()
                ),
                line,
            );
            continue;
        }
        let Some(time) = parse_f64(fields[0]) else {
            take.drop_line(line_no, format!("time {}", number_problem(fields[0])), line);
            continue;
        };
        let mut problems = Vec::new();
        for ((cell, &sensor), name) in fields[1..].iter().zip(&sensors).zip(sensor_names) {
            match parse_cell(cell) {
                Ok((q, norm)) => {
                    worst_norm_error = worst_norm_error.max((norm - 1.0).abs());
                    take.push_quaternion(sensor, time, q, line_no, line)
                        .map_err(|e| ReadError::take(path, e))?;
                }
                Err(problem) => problems.push(format!("column `{name}`: {problem}")),
            }
        }
        if !problems.is_empty() {
            let scope = if problems.len() == sensors.len() {
                "no sample of this line is used"
            } else {
                "only those sensors' samples are skipped"
            };
            take.drop_line(line_no, format!("{}; {scope}", problems.join("; ")), line);
        }
    }
    warn_if_denormalised(&mut take, worst_norm_error, None);
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::take::OrientationTrack;
    use proptest::prelude::*;

    const HEADER: &str =
        "DataRate=100.000000\nDataType=Quaternion\nversion=3\nOpenSimVersion=4.1\nendheader\n";

    fn read_str(text: &str) -> Result<Take, ReadError> {
        read_from(text.as_bytes(), Path::new("t.sto"), &ReadOptions::default())
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
    fn reads_columns_rows_and_normalises() {
        let text = format!(
            "{HEADER}time\ta_imu\tb_imu\n0\t1,0,0,0\t0,2,0,0\n0.01\t0.5,0.5,0.5,0.5\t0,0,0,1\n"
        );
        let take = read_str(&text).unwrap();
        assert_eq!(take.source().world, World::Opensim);
        assert_eq!(take.sensors().len(), 2);
        assert_eq!(
            quats(&take, "a_imu"),
            vec![(0.0, [1.0, 0.0, 0.0, 0.0]), (0.01, [0.5; 4])]
        );
        assert_eq!(quats(&take, "b_imu")[0], (0.0, [0.0, 1.0, 0.0, 0.0]));
        assert!(take.dropped_lines().is_empty());
        assert!(take.warnings().iter().any(|w| w.contains("deviate")));
    }

    #[test]
    fn crlf_name_line_and_world_override() {
        let text = "orientations\r\nDataType=Quaternion\r\nendheader\r\ntime\ts\r\n1.5\t1,0,0,0\r\n2\t1,0,0,0\r\n";
        let options = ReadOptions {
            world: Some(World::Enu),
            ..ReadOptions::default()
        };
        let take = read_from(text.as_bytes(), Path::new("t.sto"), &options).unwrap();
        assert_eq!(take.source().world, World::Enu);
        assert_eq!(take.source().start_timestamp, "1.5 s");
        assert_eq!(quats(&take, "s").len(), 2);
    }

    #[test]
    fn bad_rows_are_reported() {
        let text = format!(
            "{HEADER}time\ta\tb\n\
             0\t1,0,0,0\t1,0,0,0\n\
             0.02\t1,0,0,0\t1,0,0,0\n\
             0.01\t1,0,0,0\t1,0,0,0\n\
             0.02\t0,1,0,0\t0,1,0,0\n\
             nan\t1,0,0,0\t1,0,0,0\n\
             0.03\t1,0,0,0\n\
             0.04\t0,0,0,0\t1,0,0,0\n\
             0.05\t1,0,NaN,0\t1,0,0\n"
        );
        let take = read_str(&text).unwrap();
        // line 9 (0.01) is out of order: sorted into place for both sensors (one report).
        assert!(!take.repaired_lines().is_empty());
        assert!(take.repaired_lines().iter().all(|r| r.line == 9));
        let dropped: Vec<(u64, &str)> = take
            .dropped_lines()
            .iter()
            .map(|d| (d.line, d.reason.as_str()))
            .collect();
        assert!(
            dropped
                .iter()
                .any(|(l, r)| *l == 10 && r.contains("repeats"))
        );
        assert!(
            dropped
                .iter()
                .any(|(l, r)| *l == 11 && r.contains("time is NaN"))
        );
        assert!(
            dropped
                .iter()
                .any(|(l, r)| *l == 12 && r.contains("expected 3 tab-separated"))
        );
        assert!(
            dropped
                .iter()
                .any(|(l, r)| *l == 13 && r.contains("column `a`: quaternion is zero"))
        );
        assert!(
            dropped
                .iter()
                .any(|(l, r)| *l == 14 && r.contains("no sample of this line"))
        );
        // the good cell of line 13 is kept
        let b: Vec<f64> = quats(&take, "b").iter().map(|s| s.0).collect();
        assert_eq!(b, vec![0.0, 0.01, 0.02, 0.04]);
        let a: Vec<f64> = quats(&take, "a").iter().map(|s| s.0).collect();
        assert_eq!(a, vec![0.0, 0.01, 0.02]);
    }

    #[test]
    fn other_data_types_and_broken_headers_are_clear_errors() {
        let e = read_str("DataType=Vec3\nendheader\ntime\ta\n0\t1,2,3\n").unwrap_err();
        assert!(e.to_string().contains("DataType=Vec3"), "{e}");
        assert!(
            e.to_string().contains("expected DataType=Quaternion"),
            "{e}"
        );
        let e = read_str("time\ta\n0\t1,0,0,0\n").unwrap_err();
        assert!(e.to_string().contains("endheader"), "{e}");
        let e = read_str(&format!("{HEADER}t\ta\n")).unwrap_err();
        assert!(e.to_string().contains("line 6"), "{e}");
        let e = read_str(&format!("{HEADER}time\n0\n")).unwrap_err();
        assert!(e.to_string().contains("only `time`"), "{e}");
        let e = read_str(&format!("{HEADER}time\ta\ta\n")).unwrap_err();
        assert!(e.to_string().contains("twice"), "{e}");
        let e = read_str(&format!("{HEADER}time\ta\n0\t0,0,0,0\n")).unwrap_err();
        assert!(e.to_string().contains("no samples"), "{e}");
        // no DataType: a warning, still read
        let take = read_str("endheader\ntime\ta\n0\t1,0,0,0\n").unwrap();
        assert!(take.warnings().iter().any(|w| w.contains("DataType")));
    }

    #[test]
    fn skip_lines_applies_to_data_rows_only() {
        let text = format!("{HEADER}time\ta\n0\t1,0,0,0\n1\t1,0,0,0\n2\t1,0,0,0\n");
        let options = ReadOptions {
            skip_lines: 8,
            ..ReadOptions::default()
        };
        let take = read_from(text.as_bytes(), Path::new("t.sto"), &options).unwrap();
        assert_eq!(take.dropped_lines().len(), 2);
        assert_eq!(quats(&take, "a").len(), 1);
        assert_eq!(take.source().start_timestamp, "2 s");
    }

    #[test]
    fn detection() {
        assert!(looks_like(HEADER.as_bytes()));
        assert!(looks_like(b"name\r\nEndHeader\r\n"));
        assert!(!looks_like(b"time_s,sensor,qw,qx,qy,qz\n"));
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_do_not_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
            let _ = read_from(&bytes[..], Path::new("p.sto"), &ReadOptions::default());
            let _ = looks_like(&bytes);
        }

        #[test]
        fn mutated_fixture_does_not_panic(
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..16),
            cut in any::<prop::sample::Index>(),
        ) {
            let mut bytes = format!(
                "{HEADER}time\ta\tb\n0\t1,0,0,0\t0,1,0,0\n0.01\t0.9,0.1,0,0\t0,0.7,0.7,0\n"
            ).into_bytes();
            for (at, b) in edits {
                let i = at.index(bytes.len());
                bytes[i] = b;
            }
            bytes.truncate(cut.index(bytes.len() + 1));
            let _ = read_from(&bytes[..], Path::new("p.sto"), &ReadOptions::default());
        }
    }
}
