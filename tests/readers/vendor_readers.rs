//! Vendor readers (OpenSense .sto, Movella DOT, Xsens MTw, x-IMU3 sessions) against real files in
//! ../shared/data and small checked-in fixtures. Expected values are computed here from the raw
//! text with simple, independent parsing (split lines and fields), not with the readers' code.

use crate::common;

use imubake::read::{
    InputFormat, ReadOptions, detect_bytes, detect_format, opensense_sto, read_take, xio_session,
    xsens_dot, xsens_mtw,
};
use imubake::take::{ClockUnit, OrientationTrack, Take, TakeBuilder};
use imubake::world::World;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use proptest::prelude::*;
use std::fs;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------- helpers

fn quaternions(take: &Take, id: &str) -> Vec<(f64, UnitQuaternion<f64>)> {
    let sensor = take
        .sensor(id)
        .unwrap_or_else(|| panic!("no sensor `{id}`"));
    match sensor.orientation() {
        Some(OrientationTrack::Quaternion(t)) => t.iter().map(|(time, q)| (time, *q)).collect(),
        other => panic!("sensor `{id}`: expected quaternions, got {other:?}"),
    }
}

/// Asserts `q` equals the raw `w, x, y, z` numbers divided by their norm, up to `tol`.
fn assert_quat_eq(q: &UnitQuaternion<f64>, raw: [f64; 4], tol: f64) {
    let got = [q.w, q.i, q.j, q.k];
    let norm = raw.iter().map(|x| x * x).sum::<f64>().sqrt();
    for (g, r) in got.iter().zip(raw) {
        let r = r / norm;
        assert!((g - r).abs() < tol, "quaternion {got:?} != file {raw:?}");
    }
}

fn numbers(fields: &[&str]) -> Vec<f64> {
    fields
        .iter()
        .map(|f| f.trim().parse::<f64>().unwrap())
        .collect()
}

fn sorted_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
}

fn angle_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    (a.dot(b) / (a.norm() * b.norm()))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

// ---------------------------------------------------------------- OpenSense .sto

#[test]
fn opensense_sto_real_file() {
    let Some(path) =
        common::shared("vendor_formats/opensim_models_tutorial/placement_orientations.sto")
    else {
        return;
    };
    assert_eq!(detect_format(&path).unwrap(), InputFormat::OpensenseSto);
    let take = read_take(&path, &ReadOptions::default()).unwrap();

    let text = fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let end = lines.iter().position(|l| l.trim() == "endheader").unwrap();
    let names: Vec<&str> = lines[end + 1].split('\t').skip(1).collect();
    let rows: Vec<&str> = lines[end + 2..]
        .iter()
        .copied()
        .filter(|l| !l.trim().is_empty())
        .collect();
    assert_eq!(names.len(), 8);
    assert_eq!(take.sensors().len(), names.len());
    assert_eq!(take.source().world, World::Opensim);
    assert_eq!(take.source().format, InputFormat::OpensenseSto);
    assert!(take.dropped_lines().is_empty());
    let first: Vec<&str> = rows[0].split('\t').collect();
    for (i, name) in names.iter().enumerate() {
        let q = quaternions(&take, name);
        assert_eq!(q.len(), rows.len(), "{name}");
        assert_eq!(q[0].0, 0.0);
        let raw = numbers(&first[i + 1].split(',').collect::<Vec<_>>());
        assert_quat_eq(&q[0].1, [raw[0], raw[1], raw[2], raw[3]], 1e-12);
    }
}

#[test]
fn opensense_sto_fixtures() {
    let path = common::fixture("sto/orientations.sto");
    assert_eq!(detect_format(&path).unwrap(), InputFormat::OpensenseSto);
    let take = read_take(&path, &ReadOptions::default()).unwrap();
    let pelvis = quaternions(&take, "pelvis_imu");
    let femur = quaternions(&take, "femur_r_imu");
    assert_eq!(
        pelvis.iter().map(|s| s.0).collect::<Vec<_>>(),
        vec![0.0, 0.01, 0.02]
    );
    assert_eq!(femur.len(), 2);
    let s = std::f64::consts::FRAC_1_SQRT_2;
    assert_quat_eq(&femur[0].1, [s, 0.0, s, 0.0], 1e-12);
    // line 10 has a zero quaternion for femur_r_imu only
    assert_eq!(take.dropped_lines().len(), 1);
    assert_eq!(take.dropped_lines()[0].line, 10);
    assert!(take.dropped_lines()[0].reason.contains("femur_r_imu"));

    let vec3 = common::fixture("sto/accelerations_vec3.sto");
    assert_eq!(detect_format(&vec3).unwrap(), InputFormat::OpensenseSto);
    let e = read_take(&vec3, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("accelerations_vec3.sto") && e.contains("DataType=Vec3"),
        "{e}"
    );
    assert!(e.contains("expected DataType=Quaternion"), "{e}");
}

// ---------------------------------------------------------------- Movella DOT

struct DotFile {
    id: String,
    rows: Vec<Vec<String>>,
}

/// Data rows of a DOT CSV: the lines after the `PacketCounter,...` header.
fn dot_file(path: &Path) -> DotFile {
    let text = fs::read_to_string(path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let header = lines
        .iter()
        .position(|l| l.starts_with("PacketCounter,"))
        .unwrap();
    let rows = lines[header + 1..]
        .iter()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    let name = path.file_name().unwrap().to_string_lossy();
    DotFile {
        id: name.split('_').next().unwrap().to_string(),
        rows,
    }
}

#[test]
fn xsens_dot_real_folder() {
    let Some(dir) = common::shared("vendor_formats/Original_XsensDot_Data_Realtime") else {
        return;
    };
    assert_eq!(detect_format(&dir).unwrap(), InputFormat::XsensDot);
    let take = read_take(&dir, &ReadOptions::default()).unwrap();
    let files: Vec<DotFile> = sorted_files(&dir).iter().map(|p| dot_file(p)).collect();
    assert_eq!(files.len(), 5);
    assert_eq!(take.sensors().len(), 5);
    assert_eq!(take.source().world, World::Enu);
    assert!(
        take.dropped_lines().is_empty(),
        "{:?}",
        take.dropped_lines()
    );
    assert!(take.warnings().is_empty(), "{:?}", take.warnings());
    let stf = |row: &Vec<String>| row[1].trim().parse::<u64>().unwrap();
    // The files do not wrap (checked here), so the take starts at the smallest first value.
    for f in &files {
        assert!(f.rows.windows(2).all(|w| stf(&w[1]) > stf(&w[0])));
    }
    let start = files.iter().map(|f| stf(&f.rows[0])).min().unwrap();
    assert_eq!(take.source().start_timestamp, format!("{start} us"));
    for f in &files {
        let q = quaternions(&take, &f.id);
        assert_eq!(q.len(), f.rows.len(), "{}", f.id);
        let first = stf(&f.rows[0]);
        let last = stf(f.rows.last().unwrap());
        assert!(
            (q[0].0 - (first - start) as f64 / 1e6).abs() < 1e-9,
            "{}",
            f.id
        );
        let duration = q[q.len() - 1].0 - q[0].0;
        assert!(
            (duration - (last - first) as f64 / 1e6).abs() < 1e-9,
            "{}",
            f.id
        );
        let raw = numbers(&[&f.rows[0][2], &f.rows[0][3], &f.rows[0][4], &f.rows[0][5]]);
        assert_quat_eq(&q[0].1, [raw[0], raw[1], raw[2], raw[3]], 1e-12);
    }
}

#[test]
fn xsens_dot_real_single_file() {
    let Some(dir) = common::shared("vendor_formats/Original_XsensDot_Data_Realtime") else {
        return;
    };
    let path = dir.join("LFemur_20210820_202113_831.csv");
    assert_eq!(detect_format(&path).unwrap(), InputFormat::XsensDot);
    let take = read_take(&path, &ReadOptions::default()).unwrap();
    let f = dot_file(&path);
    assert_eq!(take.sensors().len(), 1);
    assert_eq!(quaternions(&take, "LFemur").len(), f.rows.len());
    assert_eq!(
        take.source().start_timestamp,
        format!("{} us", f.rows[0][1])
    );
}

#[test]
fn xsens_dot_fixture_wraps_and_aligns_files() {
    let dir = common::fixture("dot/wrap");
    assert_eq!(detect_format(&dir).unwrap(), InputFormat::XsensDot);
    let take = read_take(&dir, &ReadOptions::default()).unwrap();
    let wrap: u64 = 1 << 32;
    // LFoot starts before the 32-bit wrap, RFoot after it: RFoot's first sample comes after
    // LFoot's first, on one clock.
    let l = dot_file(&dir.join("LFoot_20240101_000000_001.csv"));
    let r = dot_file(&dir.join("RFoot_20240101_000000_002.csv"));
    let raw = |row: &Vec<String>| {
        row[1]
            .trim_end_matches(|c: char| !c.is_ascii_digit())
            .parse::<u64>()
            .unwrap()
    };
    let l0 = raw(&l.rows[0]);
    let expected_l: Vec<f64> = l
        .rows
        .iter()
        .map(|row| {
            let v = raw(row);
            let unwrapped = if v < l0 { v + wrap } else { v };
            (unwrapped - l0) as f64 / 1e6
        })
        .collect();
    let got_l: Vec<f64> = quaternions(&take, "LFoot").iter().map(|s| s.0).collect();
    assert_eq!(got_l.len(), expected_l.len());
    for (g, e) in got_l.iter().zip(&expected_l) {
        assert!((g - e).abs() < 1e-9, "{got_l:?} vs {expected_l:?}");
    }
    let got_r = quaternions(&take, "RFoot");
    assert_eq!(got_r.len(), r.rows.len() - 1); // one NaN row
    assert!((got_r[0].0 - (raw(&r.rows[0]) + wrap - l0) as f64 / 1e6).abs() < 1e-9);
    assert_eq!(take.source().start_timestamp, format!("{l0} us"));
    // the glued footer is removed and reported; the NaN row is dropped and reported
    let repaired = take.repaired_lines();
    assert_eq!(repaired.len(), 1);
    assert_eq!(
        repaired[0].file.as_deref(),
        Some("LFoot_20240101_000000_001.csv")
    );
    assert_eq!(repaired[0].line, 16);
    assert!(repaired[0].reason.contains("footer"));
    let last = quaternions(&take, "LFoot").last().unwrap().1;
    assert_quat_eq(&last, [0.998201, 0.059964, 0.0, 0.0], 1e-12);
    let dropped = take.dropped_lines();
    assert_eq!(dropped.len(), 1);
    assert_eq!(
        dropped[0].file.as_deref(),
        Some("RFoot_20240101_000000_002.csv")
    );
    assert_eq!(dropped[0].line, 15);
    assert!(dropped[0].reason.contains("NaN"));
    assert!(take.warnings().iter().any(|w| w.contains("notes.txt")));
}

// ---------------------------------------------------------------- Xsens MTw

struct MtwFile {
    id: String,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl MtwFile {
    fn col(&self, name: &str) -> usize {
        self.header.iter().position(|h| h == name).unwrap()
    }
    fn num(&self, row: usize, name: &str) -> f64 {
        self.rows[row][self.col(name)].trim().parse().unwrap()
    }
}

fn mtw_file(path: &Path) -> MtwFile {
    let text = fs::read_to_string(path).unwrap();
    let mut lines = text
        .lines()
        .map(|l| l.trim_end_matches('\r'))
        .filter(|l| !l.starts_with("//") && !l.trim().is_empty());
    let header = lines
        .next()
        .unwrap()
        .split('\t')
        .map(str::to_string)
        .collect();
    let rows = lines
        .map(|l| l.split('\t').map(str::to_string).collect())
        .collect();
    let stem = path.file_stem().unwrap().to_string_lossy();
    MtwFile {
        id: stem.rsplit('_').next().unwrap().to_string(),
        header,
        rows,
    }
}

/// Mean of the accelerometer (sensor frame) rotated into the world by the reader's orientation,
/// over the first `n` samples of both.
fn mean_world_acc(f: &MtwFile, q: &[(f64, UnitQuaternion<f64>)], n: usize) -> Vector3<f64> {
    let mut sum = Vector3::zeros();
    for (i, (_, q)) in q.iter().take(n).enumerate() {
        let acc = Vector3::new(f.num(i, "Acc_X"), f.num(i, "Acc_Y"), f.num(i, "Acc_Z"));
        sum += q * acc;
    }
    sum / n.min(q.len()) as f64
}

#[test]
fn xsens_mtw_real_folder() {
    let Some(dir) = common::shared("vendor_formats/OpenSenseExampleIMUData") else {
        return;
    };
    assert_eq!(detect_format(&dir).unwrap(), InputFormat::XsensMtw);
    let take = read_take(&dir, &ReadOptions::default()).unwrap();
    let files: Vec<MtwFile> = sorted_files(&dir).iter().map(|p| mtw_file(p)).collect();
    assert_eq!(files.len(), 8);
    assert_eq!(take.sensors().len(), 8);
    assert_eq!(take.source().world, World::Enu);
    assert!(
        take.dropped_lines().is_empty(),
        "{:?}",
        take.dropped_lines()
    );
    let counter = |f: &MtwFile, i: usize| f.rows[i][f.col("PacketCounter")].parse::<u64>().unwrap();
    for f in &files {
        // no 16-bit wrap in these files: the counter goes up by one per row
        assert!((1..f.rows.len()).all(|i| counter(f, i) == counter(f, i - 1) + 1));
    }
    let start = files.iter().map(|f| counter(f, 0)).min().unwrap();
    assert_eq!(
        take.source().start_timestamp,
        format!("PacketCounter {start} at 100 Hz")
    );
    for f in &files {
        let q = quaternions(&take, &f.id);
        assert_eq!(q.len(), f.rows.len(), "{}", f.id);
        let n = f.rows.len() - 1;
        assert!((q[0].0 - (counter(f, 0) - start) as f64 / 100.0).abs() < 1e-9);
        let duration = q[n].0 - q[0].0;
        assert!((duration - (counter(f, n) - counter(f, 0)) as f64 / 100.0).abs() < 1e-9);
        // the first orientation's matrix is the file's Mat[r][c] (row r, column c of R_GS)
        let r = q[0].1.to_rotation_matrix();
        for row in 1..=3 {
            for col in 1..=3 {
                let raw = f.num(0, &format!("Mat[{row}][{col}]"));
                let got = r[(row - 1, col - 1)];
                assert!(
                    (got - raw).abs() < 1e-4,
                    "{} Mat[{row}][{col}]: {got} vs {raw}",
                    f.id
                );
            }
        }
    }
}

/// The physics check on the orientation convention: at rest the accelerometer measures +g upward,
/// so rotated into the world by q_world_sensor it points along ENU +z. The transposed matrix
/// (R_SG) would not.
#[test]
fn xsens_mtw_gravity_points_up_in_enu() {
    let Some(dir) = common::shared("vendor_formats/OpenSenseExampleIMUData") else {
        return;
    };
    let path = dir.join("MT_012005D6_009-001_00B421EF.txt");
    let take = read_take(&path, &ReadOptions::default()).unwrap();
    let f = mtw_file(&path);
    let q = quaternions(&take, "00B421EF");
    let up = mean_world_acc(&f, &q, 50);
    let angle = angle_deg(&up, &Vector3::z());
    assert!(angle < 10.0, "gravity is {angle:.1}° from world +z: {up}");
    assert!((up.norm() - 9.81).abs() < 0.5, "{up}");
    let transposed: Vec<_> = q.iter().map(|(t, q)| (*t, q.inverse())).collect();
    let wrong = mean_world_acc(&f, &transposed, 50);
    assert!(angle_deg(&wrong, &Vector3::z()) > 30.0, "{wrong}");
    // every sensor of the recording agrees
    for file in sorted_files(&dir) {
        let take = read_take(&file, &ReadOptions::default()).unwrap();
        let f = mtw_file(&file);
        let q = quaternions(&take, &f.id);
        let angle = angle_deg(&mean_world_acc(&f, &q, 50), &Vector3::z());
        assert!(angle < 10.0, "{}: {angle:.1}°", f.id);
    }
}

#[test]
fn xsens_mtw_fixture_wraps_and_aligns_files() {
    let dir = common::fixture("mtw/wrap");
    assert_eq!(detect_format(&dir).unwrap(), InputFormat::XsensMtw);
    let take = read_take(&dir, &ReadOptions::default()).unwrap();
    assert_eq!(
        take.source().start_timestamp,
        "PacketCounter 65534 at 100 Hz"
    );
    let a = quaternions(&take, "00B40001");
    let b = quaternions(&take, "00B40002");
    // A: 65534, 65535, (00000 has no matrix: dropped), 00001; B: 00000, 00001, 00002 after A's wrap
    let times = |q: &[(f64, UnitQuaternion<f64>)]| {
        q.iter()
            .map(|s| (s.0 * 100.0).round() as i64)
            .collect::<Vec<_>>()
    };
    assert_eq!(times(&a), vec![0, 1, 3]);
    assert_eq!(times(&b), vec![2, 3, 4]);
    let dropped = take.dropped_lines();
    assert_eq!(dropped.len(), 1);
    assert_eq!(
        dropped[0].file.as_deref(),
        Some("MT_0120_000-001_00B40001.txt")
    );
    assert_eq!(dropped[0].line, 9);
    assert!(
        dropped[0].reason.contains("Mat[1][1] is empty"),
        "{}",
        dropped[0].reason
    );
    // gravity up for both sensors, whatever their orientation
    for id in ["00B40001", "00B40002"] {
        let f = mtw_file(&dir.join(format!("MT_0120_000-001_{id}.txt")));
        let kept: Vec<usize> = (0..f.rows.len())
            .filter(|&i| !f.rows[i][f.col("Mat[1][1]")].is_empty())
            .collect();
        let q = quaternions(&take, id);
        for (k, (_, q)) in kept.iter().zip(&q) {
            let acc = Vector3::new(f.num(*k, "Acc_X"), f.num(*k, "Acc_Y"), f.num(*k, "Acc_Z"));
            assert!(angle_deg(&(q * acc), &Vector3::z()) < 1e-6, "{id} row {k}");
        }
    }
}

// ---------------------------------------------------------------- x-IMU3 session

/// Data rows of an x-IMU3 CSV (after the header line).
fn xio_rows(path: &Path) -> Vec<Vec<f64>> {
    let text = fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|f| f.parse::<f64>().unwrap()).collect())
        .collect()
}

#[test]
fn xio_real_session() {
    let Some(dir) = common::shared("fullbody/xio_lower_body_7imu") else {
        return;
    };
    assert_eq!(detect_format(&dir).unwrap(), InputFormat::XioSession);
    let take = read_take(&dir, &ReadOptions::default()).unwrap();
    assert_eq!(take.source().world, World::Nwu);
    assert_eq!(take.sensors().len(), 7);
    assert!(
        take.dropped_lines().is_empty(),
        "{:?}",
        take.dropped_lines()
    );
    let mut devices: Vec<PathBuf> = fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .collect();
    devices.sort();
    let mut start = f64::INFINITY;
    for d in &devices {
        for f in ["Quaternion.csv", "Inertial.csv", "Magnetometer.csv"] {
            start = start.min(xio_rows(&d.join(f))[0][0]);
        }
    }
    assert_eq!(take.source().start_timestamp, format!("{start} us"));
    for d in &devices {
        // `Left Foot 64F0EBCE (UDP)` → `Left Foot`: drop the last two words
        let name = d.file_name().unwrap().to_string_lossy().into_owned();
        let words: Vec<&str> = name.split(' ').collect();
        let id = words[..words.len() - 2].join(" ");
        let sensor = take
            .sensor(&id)
            .unwrap_or_else(|| panic!("no sensor `{id}`"));
        let quat_rows = xio_rows(&d.join("Quaternion.csv"));
        let q = quaternions(&take, &id);
        assert_eq!(q.len(), quat_rows.len(), "{id}");
        let r = &quat_rows[0];
        assert!((q[0].0 - (r[0] - start) / 1e6).abs() < 1e-9);
        assert_quat_eq(&q[0].1, [r[1], r[2], r[3], r[4]], 1e-12);
        let inertial_rows = xio_rows(&d.join("Inertial.csv"));
        let inertial = sensor.inertial().unwrap();
        assert_eq!(inertial.len(), inertial_rows.len(), "{id}");
        let r = &inertial_rows[0];
        let s = inertial.values()[0];
        assert!((s.gyro_rad_s.y - r[2].to_radians()).abs() < 1e-12);
        assert!((s.accel_m_s2.z - r[6] * 9.80665).abs() < 1e-12);
        let mag_rows = xio_rows(&d.join("Magnetometer.csv"));
        let mag = sensor.magnetometer().unwrap();
        assert_eq!(mag.len(), mag_rows.len(), "{id}");
        assert_eq!(
            mag.values()[0],
            Vector3::new(mag_rows[0][1], mag_rows[0][2], mag_rows[0][3])
        );
    }
}

#[test]
fn xio_fixture_session() {
    let dir = common::fixture("xio/session");
    assert_eq!(detect_format(&dir).unwrap(), InputFormat::XioSession);
    let take = read_take(&dir, &ReadOptions::default()).unwrap();
    let ids: Vec<&str> = take.sensors().iter().map(|s| s.id()).collect();
    assert_eq!(ids, vec!["Left Foot", "pelvis"]);
    assert!(
        take.warnings()
            .iter()
            .any(|w| w.contains("Spare 0000CCCC (USB)") && w.contains("none of")),
        "{:?}",
        take.warnings()
    );
    assert_eq!(take.source().start_timestamp, "990000 us");
    let foot = take.sensor("Left Foot").unwrap();
    assert_eq!(quaternions(&take, "Left Foot").len(), 3);
    let imu = foot.inertial().unwrap();
    assert_eq!(imu.len(), 3);
    assert!((imu.values()[0].gyro_rad_s.x - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert!((imu.values()[0].gyro_rad_s.z + std::f64::consts::FRAC_PI_4).abs() < 1e-12);
    assert_eq!(imu.values()[0].accel_m_s2.z, 9.80665);
    assert_eq!(foot.magnetometer().unwrap().len(), 2);
    assert_eq!(quaternions(&take, "pelvis").len(), 2);
    let dropped: Vec<(Option<&str>, u64)> = take
        .dropped_lines()
        .iter()
        .map(|d| (d.file.as_deref(), d.line))
        .collect();
    assert_eq!(
        dropped,
        vec![
            (Some("Left Foot 0000AAAA (UDP)/Quaternion.csv"), 4),
            (Some("pelvis 0000BBBB (UDP)/Quaternion.csv"), 4),
        ]
    );

    // one device folder on its own is a one-sensor session
    let device = dir.join("pelvis 0000BBBB (UDP)");
    assert_eq!(detect_format(&device).unwrap(), InputFormat::XioSession);
    let take = read_take(&device, &ReadOptions::default()).unwrap();
    assert_eq!(take.sensors().len(), 1);
    assert_eq!(
        take.dropped_lines()[0].file.as_deref(),
        Some("Quaternion.csv")
    );

    // a file is not a session
    let options = ReadOptions {
        format: Some(InputFormat::XioSession),
        ..ReadOptions::default()
    };
    let e = read_take(&device.join("Quaternion.csv"), &options)
        .unwrap_err()
        .to_string();
    assert!(e.contains("session folder"), "{e}");
}

#[test]
fn world_override_and_skip_seconds() {
    let options = ReadOptions {
        world: Some(World::Ned),
        skip_seconds: 0.015,
        ..ReadOptions::default()
    };
    let take = read_take(&common::fixture("xio/session"), &options).unwrap();
    assert_eq!(take.source().world, World::Ned);
    // the magnetometer sample at 1 005 000 µs is the first at or after 990 000 + 15 000
    assert_eq!(take.source().start_timestamp, "1005000 us");
    let take = read_take(&common::fixture("mtw/wrap"), &options).unwrap();
    assert_eq!(take.source().world, World::Ned);
    let take = read_take(&common::fixture("dot/wrap"), &options).unwrap();
    assert_eq!(take.source().world, World::Ned);
    let take = read_take(&common::fixture("sto/orientations.sto"), &options).unwrap();
    assert_eq!(take.source().world, World::Ned);
    assert_eq!(take.source().start_timestamp, "0.02 s");
}

// ---------------------------------------------------------------- property tests

fn fixture_bytes(rel: &str) -> Vec<u8> {
    fs::read(common::fixture(rel)).unwrap()
}

fn mutate(
    mut bytes: Vec<u8>,
    edits: &[(prop::sample::Index, u8, u8)],
    cut: prop::sample::Index,
) -> Vec<u8> {
    for (at, byte, op) in edits {
        if bytes.is_empty() {
            bytes.push(*byte);
            continue;
        }
        let i = at.index(bytes.len());
        match op {
            0 => bytes[i] = *byte,
            1 => bytes.insert(i, *byte),
            _ => {
                bytes.remove(i);
            }
        }
    }
    let keep = cut.index(bytes.len() + 1);
    bytes.truncate(keep);
    bytes
}

fn all_entries(bytes: &[u8]) {
    let o = ReadOptions::default();
    let _ = detect_bytes(bytes);
    let _ = opensense_sto::looks_like(bytes);
    let _ = opensense_sto::read_from(bytes, Path::new("f.sto"), &o);
    let _ = xsens_dot::looks_like(bytes);
    let _ = xsens_dot::read_from(bytes, Path::new("S_1.csv"), &o);
    let _ = xsens_mtw::looks_like(bytes);
    let _ = xsens_mtw::read_from(bytes, Path::new("MT_x_S.txt"), &o);
    let _ = xio_session::looks_like(bytes);

    let mut dot = TakeBuilder::new(
        "d",
        InputFormat::XsensDot,
        World::Enu,
        ClockUnit::Microseconds,
    );
    let mut clock = imubake::read::clock::WrappingClock::new(xsens_dot::SAMPLE_TIME_FINE_MODULUS);
    dot.set_file(Some("A_1.csv".into()));
    let _ = xsens_dot::read_file_into(&mut dot, &mut clock, bytes, Path::new("A_1.csv"), 0);
    dot.set_file(Some("B_1.csv".into()));
    let _ = xsens_dot::read_file_into(&mut dot, &mut clock, bytes, Path::new("B_1.csv"), 2);
    let _ = dot.finish(0.0);

    let counter = ClockUnit::Counter {
        name: "PacketCounter".into(),
        rate_hz: 100.0,
    };
    let mut mtw = TakeBuilder::new("m", InputFormat::XsensMtw, World::Enu, counter);
    let mut clock = imubake::read::clock::WrappingClock::new(xsens_mtw::PACKET_COUNTER_MODULUS);
    let _ = xsens_mtw::read_file_into(&mut mtw, &mut clock, bytes, Path::new("x_A.txt"), 100.0, 0);
    let _ = xsens_mtw::read_file_into(&mut mtw, &mut clock, bytes, Path::new("x_B.txt"), 100.0, 0);
    let _ = mtw.finish(0.01);

    let mut xio = TakeBuilder::new(
        "x",
        InputFormat::XioSession,
        World::Nwu,
        ClockUnit::Microseconds,
    );
    let sensor = xio.sensor("dev");
    for kind in xio_session::XioFile::ALL {
        let _ =
            xio_session::read_file_into(&mut xio, bytes, Path::new(kind.file_name()), kind, sensor);
    }
    let _ = xio.finish(0.0);
}

/// Checks the invariants a take promises, whatever the input.
fn check_take(take: &Take) {
    for s in take.sensors() {
        if let Some(o) = s.orientation() {
            let t = o.times_s();
            assert!(t.windows(2).all(|w| w[1] > w[0]));
            assert!(t.iter().all(|x| x.is_finite() && *x >= 0.0));
            for q in o.to_quaternions().values() {
                let n = Quaternion::new(q.w, q.i, q.j, q.k).norm();
                assert!((n - 1.0).abs() < 1e-9, "{n}");
            }
        }
    }
}

fn fixtures() -> impl Strategy<Value = (&'static str, usize)> {
    prop_oneof![
        Just(("sto/orientations.sto", 0)),
        Just(("dot/wrap/LFoot_20240101_000000_001.csv", 1)),
        Just(("dot/wrap/RFoot_20240101_000000_002.csv", 1)),
        Just(("mtw/wrap/MT_0120_000-001_00B40001.txt", 2)),
        Just(("mtw/wrap/MT_0120_000-001_00B40002.txt", 2)),
        Just(("xio/session/Left Foot 0000AAAA (UDP)/Quaternion.csv", 3)),
        Just(("xio/session/Left Foot 0000AAAA (UDP)/Inertial.csv", 4)),
        Just(("xio/session/Left Foot 0000AAAA (UDP)/Magnetometer.csv", 5)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn vendor_readers_never_panic_on_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
        all_entries(&bytes);
    }

    #[test]
    fn vendor_readers_never_panic_on_mutated_fixtures(
        (fixture, kind) in fixtures(),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 0..24),
        cut in any::<prop::sample::Index>(),
    ) {
        let bytes = mutate(fixture_bytes(fixture), &edits, cut);
        all_entries(&bytes);
        let o = ReadOptions::default();
        let take = match kind {
            0 => opensense_sto::read_from(&bytes[..], Path::new("f.sto"), &o).ok(),
            1 => xsens_dot::read_from(&bytes[..], Path::new("S_1.csv"), &o).ok(),
            2 => xsens_mtw::read_from(&bytes[..], Path::new("MT_x_S.txt"), &o).ok(),
            _ => {
                let k = xio_session::XioFile::ALL[kind - 3];
                let mut b = TakeBuilder::new("x", InputFormat::XioSession, World::Nwu, ClockUnit::Microseconds);
                let s = b.sensor("dev");
                xio_session::read_file_into(&mut b, &bytes[..], Path::new("f.csv"), k, s)
                    .ok()
                    .and_then(|()| b.finish(0.0).ok())
            }
        };
        if let Some(take) = take {
            check_take(&take);
        }
    }
}
