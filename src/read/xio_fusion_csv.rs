//! The raw-readings CSV of x-io's Fusion library and tools: one sensor, one row per sample.
//!
//! ```text
//! Time (s),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g),Magnetometer X (uT),Magnetometer Y (uT),Magnetometer Z (uT)
//! 0,0.01644619,-0.1517251,0.1080897,0.001015204,-0.02045836,0.9970807,15.3017,0.4328527,-41.06483
//! ```
//!
//! - One sensor, id `imu` (a calibration take and a capture of the same sensor then share it).
//! - Gyroscope °/s → rad/s, accelerometer g → m/s² (g = 9.80665), magnetometer kept in µT; all
//!   in the sensor frame. The three magnetometer columns are optional.
//! - Time in seconds from the file's own zero.
//!
//! A header that is not this one is an error (its columns would be misread); data rows with the
//! wrong number of fields or a bad number are dropped and reported.

use super::lines::{LineReader, number_problem, parse_f64, split_fields};
use super::{InputFormat, ReadError, ReadOptions, read_single_file};
use crate::take::{ClockUnit, ImuSample, Take, TakeBuilder};
use crate::world::World;
use nalgebra::Vector3;
use std::io::Read;
use std::path::Path;

/// The sensor id of the one sensor in a file.
pub const SENSOR_ID: &str = "imu";

/// Standard gravity, for accelerometer columns in g.
const STANDARD_GRAVITY_M_S2: f64 = 9.80665;

/// The header's columns; the last three (the magnetometer) may be absent.
pub const HEADER: [&str; 10] = [
    "Time (s)",
    "Gyroscope X (deg/s)",
    "Gyroscope Y (deg/s)",
    "Gyroscope Z (deg/s)",
    "Accelerometer X (g)",
    "Accelerometer Y (g)",
    "Accelerometer Z (g)",
    "Magnetometer X (uT)",
    "Magnetometer Y (uT)",
    "Magnetometer Z (uT)",
];

/// The number of columns the header has (7 or 10), or `None` when it is not this format's.
fn header_columns(line: &[u8]) -> Option<usize> {
    let names: Vec<&[u8]> = line.split(|&b| b == b',').map(|f| f.trim_ascii()).collect();
    let matches = names.len() <= HEADER.len()
        && names
            .iter()
            .zip(HEADER)
            .all(|(n, e)| n.eq_ignore_ascii_case(e.as_bytes()));
    (matches && (names.len() == 7 || names.len() == 10)).then_some(names.len())
}

/// True when the first line is the Fusion CSV header.
pub fn looks_like(head: &[u8]) -> bool {
    let mut reader = LineReader::over(head);
    matches!(reader.next_line(), Ok(Some((_, line))) if header_columns(line).is_some())
}

pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    read_single_file(path, options, read_from)
}

/// Reads a Fusion CSV from any reader; `path` names it in reports.
pub fn read_from(reader: impl Read, path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    // Only raw readings: the world is that of the fusion (ENU) unless the user names one.
    let world = options.world.unwrap_or(World::Enu);
    let mut take = TakeBuilder::new(path, InputFormat::XioFusionCsv, world, ClockUnit::Seconds);
    let sensor = take.sensor(SENSOR_ID);
    let mut lines = LineReader::new(reader);
    let mut columns = None;
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        if line.trim_ascii().is_empty() {
            continue;
        }
        let Some(n_columns) = columns else {
            columns = Some(header_columns(line).ok_or_else(|| {
                ReadError::line(
                    path,
                    line_no,
                    format!(
                        "expected the x-io Fusion header `{}` (the magnetometer columns optional), found `{}`",
                        HEADER.join(","),
                        crate::take::cut_text(line)
                    ),
                )
            })?);
            continue;
        };
        if line_no <= options.skip_lines {
            take.drop_line(line_no, "skipped by --skip-lines", line);
            continue;
        }
        let mut f = [&b""[..]; 10];
        let n = split_fields(line, b',', &mut f);
        if n != n_columns {
            take.drop_line(
                line_no,
                format!("expected {n_columns} comma-separated fields as the header has, found {n}"),
                line,
            );
            continue;
        }
        let mut v = [0.0; 10];
        if let Some(i) = (0..n).find(|&i| match parse_f64(f[i]) {
            Some(x) => {
                v[i] = x;
                false
            }
            None => true,
        }) {
            take.drop_line(
                line_no,
                format!("{} {}", HEADER[i], number_problem(f[i])),
                line,
            );
            continue;
        }
        let sample = ImuSample {
            gyro_rad_s: Vector3::new(v[1], v[2], v[3]) * (std::f64::consts::PI / 180.0),
            accel_m_s2: Vector3::new(v[4], v[5], v[6]) * STANDARD_GRAVITY_M_S2,
        };
        take.push_inertial(sensor, v[0], sample, line_no, line)
            .map_err(|e| ReadError::take(path, e))?;
        if n == 10 {
            take.push_magnetometer(sensor, v[0], Vector3::new(v[7], v[8], v[9]), line_no, line)
                .map_err(|e| ReadError::take(path, e))?;
        }
    }
    if columns.is_none() {
        return Err(ReadError::format(
            path,
            format!("no header; expected `{}` and data rows", HEADER.join(",")),
        ));
    }
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn read_text(text: &str) -> Result<Take, ReadError> {
        read_from(text.as_bytes(), Path::new("f.csv"), &ReadOptions::default())
    }

    #[test]
    fn rows_become_raw_readings_in_si_units() {
        let text = format!(
            "{}\n0,90,0,-180,0,0,1,15,0.5,-41\n0.01,0,0,0,0.5,0,0,15,0.5,-41\n0.02,x,0,0,0,0,1,1,2,3\n",
            HEADER.join(",")
        );
        let take = read_text(&text).unwrap();
        assert_eq!(take.source().format, InputFormat::XioFusionCsv);
        let s = take.sensor(SENSOR_ID).unwrap();
        let i = s.inertial().unwrap();
        assert_eq!(i.len(), 2);
        let first = &i.values()[0];
        assert!((first.gyro_rad_s.x - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((first.gyro_rad_s.z + std::f64::consts::PI).abs() < 1e-12);
        assert!((first.accel_m_s2.z - 9.80665).abs() < 1e-12);
        assert!((i.values()[1].accel_m_s2.x - 4.903325).abs() < 1e-12);
        assert_eq!(
            s.magnetometer().unwrap().values()[0],
            Vector3::new(15.0, 0.5, -41.0)
        );
        assert_eq!(take.dropped_lines().len(), 1);
        assert_eq!(take.dropped_lines()[0].line, 4);
        assert!(
            take.dropped_lines()[0]
                .reason
                .contains("Gyroscope X (deg/s)")
        );
    }

    #[test]
    fn the_magnetometer_columns_are_optional_and_other_headers_are_refused() {
        let text = format!("{}\n0,0,0,0,0,0,1\n", HEADER[..7].join(","));
        let take = read_text(&text).unwrap();
        assert!(take.sensor(SENSOR_ID).unwrap().magnetometer().is_none());
        assert!(looks_like(text.as_bytes()));
        let e = read_text("Time (s),Gyro\n0,1\n").unwrap_err().to_string();
        assert!(
            e.contains("line 1") && e.contains("x-io Fusion header"),
            "{e}"
        );
        assert!(!looks_like(b"time_s,sensor,gx\n"));
    }

    proptest! {
        /// Any bytes after a valid header: an error or a take, never a panic.
        #[test]
        fn never_panics(body in proptest::collection::vec(any::<u8>(), 0..400)) {
            let mut text = HEADER.join(",").into_bytes();
            text.push(b'\n');
            text.extend(body);
            let _ = read_from(&text[..], Path::new("f.csv"), &ReadOptions::default());
        }
    }
}
