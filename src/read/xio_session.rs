//! x-io x-IMU3 session folders (x-IMU3 GUI data logger): one sub-folder per device, one take.
//!
//! ```text
//! session/
//!   Left Foot 64F0EBCE (UDP)/
//!     Quaternion.csv     Timestamp (us),W,X,Y,Z
//!     Inertial.csv       Timestamp (us),Gyroscope X (deg/s),...,Accelerometer X (g),...
//!     Magnetometer.csv   Timestamp (us),X (a.u.),Y (a.u.),Z (a.u.)
//!     Battery.csv, Rssi.csv, Temperature.csv, HighGAccelerometer.csv, Command.json  (not used)
//!   pelvis 64F0EDBF (UDP)/
//!     ...
//! ```
//!
//! - Sensor id: the device folder name without the trailing `(transport)` and serial number
//!   (`Left Foot 64F0EBCE (UDP)` → `Left Foot`). If two folders give the same id, those keep their
//!   serial number (a warning says so).
//! - Quaternion.csv: q_world_sensor, w first, in the x-IMU3's NWU earth frame (`World::Nwu`;
//!   `--world` overrides), normalised.
//! - Inertial.csv: gyroscope °/s → rad/s, accelerometer g → m/s² (g = 9.80665), sensor frame.
//! - Magnetometer.csv: kept in the device's arbitrary units.
//! - Time: `Timestamp (us)`, one µs clock shared by all devices of the session:
//!   `ClockUnit::Microseconds`.
//! - A device folder with none of the three files is a warning; an empty file is a warning; a
//!   file whose header is not the expected one is an error (its columns would be misread).
//!   A folder that itself holds Quaternion.csv or Inertial.csv is read as a one-device session.
//!
//! Data rows with the wrong number of fields, a bad number or a zero quaternion are dropped and
//! reported (file name relative to the session folder). `--skip-lines` is not applied (the files
//! have different rates, so line numbers do not mean the same time); use `--skip-seconds`.

use super::lines::{LineReader, number_problem, parse_f64, split_fields};
use super::{
    InputFormat, ReadError, ReadOptions, check_text, sniff, unit_quaternion, warn_if_denormalised,
};
use crate::take::{BuildError, ClockUnit, ImuSample, SensorIdx, Take, TakeBuilder};
use crate::world::World;
use nalgebra::{Quaternion, Vector3};
use std::collections::HashMap;
use std::fs::{self, File};
use std::io::Read;
use std::path::{Path, PathBuf};

/// Standard gravity, for accelerometer columns in g.
const STANDARD_GRAVITY_M_S2: f64 = 9.80665;

/// The x-IMU3 files imubake reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum XioFile {
    Quaternion,
    Inertial,
    Magnetometer,
}

impl XioFile {
    pub const ALL: [XioFile; 3] = [
        XioFile::Quaternion,
        XioFile::Inertial,
        XioFile::Magnetometer,
    ];

    pub fn file_name(self) -> &'static str {
        match self {
            XioFile::Quaternion => "Quaternion.csv",
            XioFile::Inertial => "Inertial.csv",
            XioFile::Magnetometer => "Magnetometer.csv",
        }
    }

    /// The header row the x-IMU3 GUI writes.
    pub fn header(self) -> &'static [&'static str] {
        match self {
            XioFile::Quaternion => &["Timestamp (us)", "W", "X", "Y", "Z"],
            XioFile::Inertial => &[
                "Timestamp (us)",
                "Gyroscope X (deg/s)",
                "Gyroscope Y (deg/s)",
                "Gyroscope Z (deg/s)",
                "Accelerometer X (g)",
                "Accelerometer Y (g)",
                "Accelerometer Z (g)",
            ],
            XioFile::Magnetometer => &["Timestamp (us)", "X (a.u.)", "Y (a.u.)", "Z (a.u.)"],
        }
    }

    fn matches_header(self, line: &[u8]) -> bool {
        let names: Vec<&[u8]> = line.split(|&b| b == b',').map(|f| f.trim_ascii()).collect();
        let expected = self.header();
        names.len() == expected.len()
            && names
                .iter()
                .zip(expected)
                .all(|(n, e)| n.eq_ignore_ascii_case(e.as_bytes()))
    }
}

/// Sensor id of a device folder: the name without the trailing `(transport)` and serial number.
pub fn device_id(folder_name: &str) -> String {
    let mut name = folder_name.trim();
    if name.ends_with(')')
        && let Some(open) = name.rfind('(')
    {
        name = name[..open].trim_end();
    }
    if let Some((rest, serial)) = name.rsplit_once(char::is_whitespace) {
        let is_serial =
            (6..=16).contains(&serial.len()) && serial.chars().all(|c| c.is_ascii_hexdigit());
        if is_serial && !rest.trim().is_empty() {
            name = rest.trim_end();
        }
    }
    if name.is_empty() {
        folder_name.trim().to_string()
    } else {
        name.to_string()
    }
}

/// The device id without the transport only (used when two devices share a name).
fn device_id_with_serial(folder_name: &str) -> String {
    let name = folder_name.trim();
    match name
        .strip_suffix(')')
        .and_then(|n| n.rfind('(').map(|i| &name[..i]))
    {
        Some(rest) if !rest.trim().is_empty() => rest.trim_end().to_string(),
        _ => name.to_string(),
    }
}

/// True when the first line is a Quaternion.csv, Inertial.csv or Magnetometer.csv header.
pub fn looks_like(head: &[u8]) -> bool {
    let mut reader = LineReader::over(head);
    match reader.next_line() {
        Ok(Some((_, line))) => XioFile::ALL.iter().any(|k| k.matches_header(line)),
        _ => false,
    }
}

/// True when `dir` holds a file of a device folder (Quaternion.csv or Inertial.csv).
pub fn is_device_folder(dir: &Path) -> bool {
    dir.join(XioFile::Quaternion.file_name()).is_file()
        || dir.join(XioFile::Inertial.file_name()).is_file()
}

/// Non-hidden sub-folders, sorted by name.
fn sub_folders(dir: &Path) -> Result<Vec<(PathBuf, String)>, ReadError> {
    let mut out = Vec::new();
    for entry in fs::read_dir(dir).map_err(|e| ReadError::io(dir, e))? {
        let entry = entry.map_err(|e| ReadError::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if !name.starts_with('.') && entry.path().is_dir() {
            out.push((entry.path(), name));
        }
    }
    out.sort();
    Ok(out)
}

/// True when the folder has at least one sub-folder holding Quaternion.csv or Inertial.csv.
pub fn looks_like_folder(path: &Path) -> bool {
    sub_folders(path)
        .map(|subs| subs.iter().any(|(dir, _)| is_device_folder(dir)))
        .unwrap_or(false)
}

/// Reads an x-IMU3 session folder (or one device folder) as one take.
pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    if !path.is_dir() {
        if !path.exists() {
            return Err(ReadError::io(
                path,
                std::io::Error::from(std::io::ErrorKind::NotFound),
            ));
        }
        return Err(ReadError::format(
            path,
            "an x-IMU3 session is a folder with one sub-folder per device (Quaternion.csv, Inertial.csv, \
             Magnetometer.csv); got a file. Hint: pass the session folder",
        ));
    }
    let world = options.world.unwrap_or(World::Nwu);
    let mut take = TakeBuilder::new(
        path,
        InputFormat::XioSession,
        world,
        ClockUnit::Microseconds,
    );
    // (device folder, its name, prefix of file names in reports)
    let devices: Vec<(PathBuf, String, String)> =
        if is_device_folder(path) && !looks_like_folder(path) {
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "device".to_string());
            vec![(path.to_path_buf(), name, String::new())]
        } else {
            sub_folders(path)?
                .into_iter()
                .map(|(dir, name)| {
                    let prefix = format!("{name}/");
                    (dir, name, prefix)
                })
                .collect()
        };
    if devices.is_empty() {
        return Err(ReadError::format(
            path,
            "no device sub-folders; expected an x-IMU3 session folder with one sub-folder per device \
             (e.g. `Left Foot 64F0EBCE (UDP)/Quaternion.csv`)",
        ));
    }
    if options.skip_lines > 0 {
        take.warn(format!(
            "--skip-lines {} is not applied to x-IMU3 sessions (their files have different rates); use --skip-seconds",
            options.skip_lines
        ));
    }
    let mut id_count: HashMap<String, usize> = HashMap::new();
    for (_, name, _) in &devices {
        *id_count.entry(device_id(name)).or_default() += 1;
    }
    let mut read_any = false;
    for (dir, name, prefix) in &devices {
        let present: Vec<XioFile> = XioFile::ALL
            .into_iter()
            .filter(|k| dir.join(k.file_name()).is_file())
            .collect();
        if present.is_empty() {
            take.warn(format!(
                "device folder `{name}` has none of Quaternion.csv, Inertial.csv, Magnetometer.csv; skipped"
            ));
            continue;
        }
        let mut id = device_id(name);
        if id_count.get(&id).copied().unwrap_or(0) > 1 {
            let with_serial = device_id_with_serial(name);
            take.warn(format!(
                "several device folders are named `{id}`; `{name}` is read as sensor `{with_serial}`"
            ));
            id = with_serial;
        }
        let sensor = take.sensor(&id);
        for kind in present {
            let file = dir.join(kind.file_name());
            let rel = format!("{prefix}{}", kind.file_name());
            take.set_file(Some(rel.clone()));
            let head = sniff(&file)?;
            if head.is_empty() {
                take.warn(format!("`{rel}` is empty; skipped"));
                continue;
            }
            check_text(&file, &head)?;
            let f = File::open(&file).map_err(|e| ReadError::io(&file, e))?;
            read_file_into(&mut take, f, &file, kind, sensor)?;
            read_any = true;
        }
    }
    take.set_file(None);
    if !read_any {
        return Err(ReadError::format(
            path,
            "no device folder has Quaternion.csv, Inertial.csv or Magnetometer.csv data; expected an x-IMU3 \
             session folder",
        ));
    }
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

/// Parses one x-IMU3 file of kind `kind` into `take` as samples of `sensor` (the caller names the
/// file for reports with [`TakeBuilder::set_file`]); `path` names it in errors.
pub fn read_file_into(
    take: &mut TakeBuilder,
    reader: impl Read,
    path: &Path,
    kind: XioFile,
    sensor: SensorIdx,
) -> Result<(), ReadError> {
    let mut lines = LineReader::new(reader);
    let expected = kind.header();
    let mut header_seen = false;
    let mut worst_norm_error: f64 = 0.0;
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        if line.trim_ascii().is_empty() {
            continue;
        }
        if !header_seen {
            if !kind.matches_header(line) {
                return Err(ReadError::line(
                    path,
                    line_no,
                    format!(
                        "expected the {} header `{}`, found `{}`. Hint: is this an x-IMU3 GUI data-logger file?",
                        kind.file_name(),
                        expected.join(","),
                        crate::take::cut_text(line)
                    ),
                ));
            }
            header_seen = true;
            continue;
        }
        let mut f = [&b""[..]; 7];
        let n = split_fields(line, b',', &mut f);
        if n != expected.len() {
            take.drop_line(
                line_no,
                format!(
                    "expected {} comma-separated fields ({}), found {n}",
                    expected.len(),
                    expected.join(",")
                ),
                line,
            );
            continue;
        }
        let mut values = [0.0; 7];
        let mut bad = None;
        for (i, (slot, field)) in values.iter_mut().zip(&f).take(n).enumerate() {
            match parse_f64(field) {
                Some(v) => *slot = v,
                None => {
                    bad = Some(i);
                    break;
                }
            }
        }
        if let Some(i) = bad {
            let name = expected.get(i).copied().unwrap_or("field");
            let field = f.get(i).copied().unwrap_or(b"");
            take.drop_line(line_no, format!("{name} {}", number_problem(field)), line);
            continue;
        }
        let [t, a, b, c, d, e, g] = values;
        let pushed: Result<(), BuildError> = match kind {
            XioFile::Quaternion => match unit_quaternion(Quaternion::new(a, b, c, d)) {
                Some((q, norm)) => {
                    worst_norm_error = worst_norm_error.max((norm - 1.0).abs());
                    take.push_quaternion(sensor, t, q, line_no, line)
                }
                None => {
                    take.drop_line(
                        line_no,
                        "quaternion is zero; expected a unit quaternion W,X,Y,Z",
                        line,
                    );
                    continue;
                }
            },
            XioFile::Inertial => {
                let sample = ImuSample {
                    gyro_rad_s: Vector3::new(a, b, c) * (std::f64::consts::PI / 180.0),
                    accel_m_s2: Vector3::new(d, e, g) * STANDARD_GRAVITY_M_S2,
                };
                take.push_inertial(sensor, t, sample, line_no, line)
            }
            XioFile::Magnetometer => {
                take.push_magnetometer(sensor, t, Vector3::new(a, b, c), line_no, line)
            }
        };
        pushed.map_err(|e| ReadError::take(path, e))?;
    }
    if !header_seen {
        return Err(ReadError::format(
            path,
            format!("no header; expected `{}` and data rows", expected.join(",")),
        ));
    }
    let file = take.current_file().unwrap_or("Quaternion.csv").to_string();
    warn_if_denormalised(take, worst_norm_error, Some(&file));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::take::OrientationTrack;
    use proptest::prelude::*;

    fn builder() -> TakeBuilder {
        TakeBuilder::new(
            "s",
            InputFormat::XioSession,
            World::Nwu,
            ClockUnit::Microseconds,
        )
    }

    fn read_one(kind: XioFile, text: &str) -> Result<Take, ReadError> {
        let mut take = builder();
        let sensor = take.sensor("dev");
        take.set_file(Some(format!("dev 12345678 (UDP)/{}", kind.file_name())));
        read_file_into(
            &mut take,
            text.as_bytes(),
            Path::new(kind.file_name()),
            kind,
            sensor,
        )?;
        take.finish(0.0)
            .map_err(|e| ReadError::take(Path::new("s"), e))
    }

    #[test]
    fn device_ids() {
        assert_eq!(device_id("Left Foot 64F0EBCE (UDP)"), "Left Foot");
        assert_eq!(device_id("pelvis 64F0EDBF (UDP)"), "pelvis");
        assert_eq!(
            device_id("Right Lower Leg 64F61B2A (USB)"),
            "Right Lower Leg"
        );
        assert_eq!(device_id("64F0EBCE (UDP)"), "64F0EBCE");
        assert_eq!(device_id("Head"), "Head");
        assert_eq!(device_id("Left Cafe"), "Left Cafe");
        assert_eq!(device_id("  (x) "), "(x)");
        assert_eq!(
            device_id_with_serial("Foot 64F0EBCE (UDP)"),
            "Foot 64F0EBCE"
        );
    }

    #[test]
    fn quaternion_rows() {
        let text = "Timestamp (us),W,X,Y,Z\r\n\
                    1000,1,0,0,0\r\n\
                    3000,0,2,0,0\r\n\
                    2000,0.5,0.5,0.5,0.5\r\n\
                    3000,1,0,0,0\r\n\
                    4000,0,0,0,0\r\n\
                    5000,nan,0,0,0\r\n\
                    6000,1,0,0\r\n\
                    7000,1,0,0,0\r\n";
        let take = read_one(XioFile::Quaternion, text).unwrap();
        let Some(OrientationTrack::Quaternion(t)) = take.sensor("dev").unwrap().orientation()
        else {
            panic!("no quaternions");
        };
        assert_eq!(t.times_s(), &[0.0, 0.001, 0.002, 0.006]);
        assert_eq!(t.values()[2].i, 1.0);
        let dropped: Vec<(u64, &str)> = take
            .dropped_lines()
            .iter()
            .map(|d| (d.line, d.reason.as_str()))
            .collect();
        assert_eq!(dropped.len(), 4, "{dropped:?}");
        assert!(dropped[0].0 == 5 && dropped[0].1.contains("repeats"));
        assert!(dropped[1].0 == 6 && dropped[1].1.contains("zero"));
        assert_eq!(dropped[2], (7, "W is NaN"));
        assert!(dropped[3].0 == 8 && dropped[3].1.contains("found 4"));
        assert!(
            take.dropped_lines()
                .iter()
                .all(|d| d.file.as_deref() == Some("dev 12345678 (UDP)/Quaternion.csv"))
        );
        assert_eq!(take.repaired_lines().len(), 1);
        assert!(take.warnings().iter().any(|w| w.contains("deviate")));
    }

    #[test]
    fn inertial_and_magnetometer_units() {
        let text = "Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)\n\
                    10,180,0,-90,0,0,1\n";
        let take = read_one(XioFile::Inertial, text).unwrap();
        let s = take.sensor("dev").unwrap().inertial().unwrap().values()[0];
        assert!((s.gyro_rad_s.x - std::f64::consts::PI).abs() < 1e-12);
        assert!((s.gyro_rad_s.z + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(s.accel_m_s2.z, 9.80665);
        let text = "Timestamp (us),X (a.u.),Y (a.u.),Z (a.u.)\n10,0.5,-1,2\n";
        let take = read_one(XioFile::Magnetometer, text).unwrap();
        let m = take.sensor("dev").unwrap().magnetometer().unwrap().values()[0];
        assert_eq!(m, Vector3::new(0.5, -1.0, 2.0));
    }

    #[test]
    fn wrong_header_is_an_error() {
        let e = read_one(
            XioFile::Quaternion,
            "Timestamp (us),X (a.u.),Y (a.u.),Z (a.u.)\n",
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("expected the Quaternion.csv header"),
            "{e}"
        );
        assert!(e.to_string().contains("line 1"), "{e}");
        let e = read_one(XioFile::Quaternion, "\n\n").unwrap_err();
        assert!(e.to_string().contains("no header"), "{e}");
    }

    #[test]
    fn detection() {
        assert!(looks_like(b"Timestamp (us),W,X,Y,Z\n1,1,0,0,0\n"));
        assert!(!looks_like(
            b"Timestamp (us),Percentage (%),Voltage (V),Charging Status\n"
        ));
        assert!(!looks_like(b""));
    }

    fn any_kind() -> impl Strategy<Value = XioFile> {
        prop_oneof![
            Just(XioFile::Quaternion),
            Just(XioFile::Inertial),
            Just(XioFile::Magnetometer)
        ]
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_do_not_panic(
            kind in any_kind(),
            bytes in proptest::collection::vec(any::<u8>(), 0..2048),
        ) {
            let mut take = builder();
            let sensor = take.sensor("dev");
            let _ = read_file_into(&mut take, &bytes[..], Path::new("f.csv"), kind, sensor);
            let _ = take.finish(0.0);
            let _ = looks_like(&bytes);
            let _ = device_id(&String::from_utf8_lossy(&bytes));
        }

        #[test]
        fn mutated_fixture_does_not_panic(
            kind in any_kind(),
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..16),
            cut in any::<prop::sample::Index>(),
        ) {
            let mut bytes = match kind {
                XioFile::Quaternion => "Timestamp (us),W,X,Y,Z\n1000,1,0,0,0\n2000,0.5,0.5,0.5,0.5\n",
                XioFile::Inertial => "Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)\n1000,1,2,3,0,0,1\n",
                XioFile::Magnetometer => "Timestamp (us),X (a.u.),Y (a.u.),Z (a.u.)\n1000,1,2,3\n",
            }.as_bytes().to_vec();
            for (at, b) in edits {
                let i = at.index(bytes.len());
                bytes[i] = b;
            }
            bytes.truncate(cut.index(bytes.len() + 1));
            let mut take = builder();
            let sensor = take.sensor("dev");
            let _ = read_file_into(&mut take, &bytes[..], Path::new("f.csv"), kind, sensor);
            let _ = take.finish(0.0);
        }
    }
}
