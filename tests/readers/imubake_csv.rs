//! The imubake CSV reader on hand-written fixtures; expected values worked out by hand.

use crate::common;

use common::fixture;
use imubake::read::{InputFormat, ReadError, ReadOptions, detect_format, read_take};
use imubake::take::{OrientationTrack, Take};
use imubake::world::World;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::f64::consts::PI;

fn read(rel: &str) -> Result<Take, ReadError> {
    read_take(&fixture(rel), &ReadOptions::default())
}

fn quats(take: &Take, id: &str) -> (Vec<f64>, Vec<UnitQuaternion<f64>>) {
    match take.sensor(id).unwrap().orientation().unwrap() {
        OrientationTrack::Quaternion(t) => (t.times_s().to_vec(), t.values().to_vec()),
        other => panic!("expected quaternions, got {other:?}"),
    }
}

#[test]
fn quaternions_with_comments_world_directive_and_bad_rows() {
    assert_eq!(
        detect_format(&fixture("csv/quaternions.csv")).unwrap(),
        InputFormat::ImubakeCsv
    );
    let take = read("csv/quaternions.csv").unwrap();
    assert_eq!(take.source().world, World::Ned);
    assert_eq!(take.source().start_timestamp, "100 ms");
    let (t, q) = quats(&take, "hips");
    assert_eq!(t.len(), 4);
    for (a, b) in t.iter().zip([0.0, 0.01, 0.02, 0.03]) {
        assert!((a - b).abs() < 1e-12, "{t:?}");
    }
    // 120 ms (line 9, late) holds (0,1,0,0); 130 ms keeps line 8's (0.5,0.5,0.5,0.5).
    assert_eq!(q[2].into_inner(), Quaternion::new(0.0, 1.0, 0.0, 0.0));
    assert_eq!(q[3].into_inner(), Quaternion::new(0.5, 0.5, 0.5, 0.5));
    let (th, qh) = quats(&take, "head");
    assert_eq!(th.len(), 3);
    assert!((th[2] - 0.08).abs() < 1e-12);
    // (2,0,0,0) normalised to identity.
    assert_eq!(qh[1].into_inner(), Quaternion::new(1.0, 0.0, 0.0, 0.0));
    assert!((qh[0].into_inner().norm() - 1.0).abs() < 1e-15);

    let dropped: Vec<(u64, &str)> = take
        .dropped_lines()
        .iter()
        .map(|d| (d.line, d.reason.as_str()))
        .collect();
    assert_eq!(dropped.len(), 5, "{dropped:?}");
    assert_eq!(dropped[0].0, 10);
    assert!(dropped[0].1.contains("repeats the time"));
    assert_eq!(dropped[1], (11, "column qw is NaN"));
    assert_eq!(dropped[2].0, 12);
    assert!(dropped[2].1.contains("quaternion is zero"));
    assert_eq!(
        dropped[3],
        (
            13,
            "expected 6 comma-separated fields as in the header, found 5"
        )
    );
    assert_eq!(dropped[4], (14, "sensor is empty"));
    assert_eq!(take.repaired_lines().len(), 1);
    assert_eq!(take.repaired_lines()[0].line, 9);
    assert!(
        take.warnings().iter().any(|w| w.contains("unit length")),
        "{:?}",
        take.warnings()
    );
}

#[test]
fn raw_columns_with_unit_suffixes_convert_to_si() {
    let take = read("csv/raw_units.csv").unwrap();
    assert_eq!(take.source().start_timestamp, "917419171 us");
    let foot = take.sensor("foot").unwrap();
    assert!(foot.orientation().is_none());
    let imu = foot.inertial().unwrap();
    assert_eq!(imu.len(), 2);
    let s = imu.values()[0];
    assert!((s.gyro_rad_s - Vector3::new(PI / 2.0, 0.0, -PI)).norm() < 1e-12);
    assert!((s.accel_m_s2 - Vector3::new(0.0, 0.0, 9.80665)).norm() < 1e-12);
    let s = imu.values()[1];
    assert!((s.gyro_rad_s - Vector3::new(0.0, PI / 4.0, 0.0)).norm() < 1e-12);
    assert!((s.accel_m_s2 - Vector3::new(4.903325, 0.0, 4.903325)).norm() < 1e-12);
    assert!((imu.times_s()[1] - 0.020035).abs() < 1e-12);
    let mag = foot.magnetometer().unwrap();
    assert_eq!(mag.values()[0], Vector3::new(20.0, 0.0, -40.0));
    let shank = take.sensor("shank").unwrap();
    assert!((shank.inertial().unwrap().times_s()[0] - 0.040035).abs() < 1e-12);
    assert!(take.warnings().iter().any(|w| w.contains("temperature")));
}

#[test]
fn yaw_pitch_roll_and_crlf() {
    let take = read("csv/euler_crlf.csv").unwrap();
    assert_eq!(take.source().start_timestamp, "0.5 s");
    let o = take.sensor("arm").unwrap().orientation().unwrap();
    let OrientationTrack::YawPitchRollDeg(t) = o else {
        panic!("expected yaw/pitch/roll")
    };
    assert_eq!(t.len(), 3);
    assert_eq!(t.values()[1].pitch, 45.0);
    // Roll 90° maps sensor y to world z.
    let q = o.to_quaternions().values()[2];
    assert!((q * Vector3::y() - Vector3::z()).norm() < 1e-12);
}

#[test]
fn missing_columns_name_file_line_and_what_was_expected() {
    let msg = read("csv/missing_columns.csv").unwrap_err().to_string();
    assert!(msg.contains("missing_columns.csv: line 1"), "{msg}");
    assert!(msg.contains("qy, qz"), "{msg}");
    assert!(msg.contains("expected a time column"), "{msg}");
}

#[test]
fn non_utf8_fields_drop_only_their_lines() {
    let take = read("csv/not_utf8.csv").unwrap();
    assert_eq!(
        take.sensor("a")
            .unwrap()
            .orientation()
            .unwrap()
            .times_s()
            .len(),
        2
    );
    let dropped: Vec<(u64, &str)> = take
        .dropped_lines()
        .iter()
        .map(|d| (d.line, d.reason.as_str()))
        .collect();
    assert_eq!(
        dropped,
        [(4, "time is not a number"), (5, "sensor is not UTF-8 text")]
    );
    assert!(take.dropped_lines()[0].text.contains('\u{FFFD}'));
}

#[test]
fn empty_binary_and_header_only_inputs() {
    let msg = read("csv/empty.csv").unwrap_err().to_string();
    assert!(
        msg.contains("empty.csv") && msg.contains("is empty"),
        "{msg}"
    );
    let msg = read("csv/binary.bin").unwrap_err().to_string();
    assert!(
        msg.contains("binary.bin") && msg.contains("binary"),
        "{msg}"
    );
    let forced = ReadOptions {
        format: Some(InputFormat::ImubakeCsv),
        ..ReadOptions::default()
    };
    let msg = read_take(&fixture("csv/binary.bin"), &forced)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("binary"), "{msg}");
    let msg = read("csv/header_only.csv").unwrap_err().to_string();
    assert!(
        msg.contains("header_only.csv") && msg.contains("no samples"),
        "{msg}"
    );
    let msg = read("csv/does_not_exist.csv").unwrap_err().to_string();
    assert!(
        msg.contains("does_not_exist.csv") && msg.contains("cannot read"),
        "{msg}"
    );
}

/// A log much longer than the reader's blocks (parsed on every core, merged in file order), with
/// damage spread through it: every report names the line where the damage was written, with its
/// reason and text, in line order; late rows are sorted into place; a recalibration comment deep
/// in the file is kept. The expected lines are those the generator wrote the damage on.
#[test]
fn damage_far_into_a_long_log_is_reported_at_its_own_lines() {
    use std::fmt::Write as _;
    let mut text = String::from("# world: enu\ntime_s,sensor,qw,qx,qy,qz\n");
    let mut line = 2u64;
    let (mut dropped, mut repaired) = (Vec::new(), Vec::new());
    let mut calibrate_at = None;
    let rows = 120_000;
    for i in 0..rows {
        for sensor in ["hips", "head"] {
            line += 1;
            let t = i as f64 * 0.01;
            let row = match i {
                _ if i % 9_973 == 5 && sensor == "head" => {
                    dropped.push((line, "column qx is not a number"));
                    format!("{t:.4},{sensor},1,x,0,0")
                }
                _ if i % 15_013 == 7 && sensor == "hips" => {
                    dropped.push((line, "expected 6 comma-separated fields"));
                    format!("{t:.4},{sensor},1,0,0")
                }
                _ if i % 20_011 == 3 && sensor == "hips" => {
                    // Written after the next row's time: late, sorted into place.
                    repaired.push((line, "earlier than the previous sample"));
                    format!("{:.4},{sensor},1,0,0,0", t - 0.015)
                }
                _ if i % 25_013 == 11 && sensor == "head" => {
                    dropped.push((line, "repeats the time of an earlier sample"));
                    format!("{:.4},{sensor},1,0,0,0", t - 0.01)
                }
                _ => format!("{t:.4},{sensor},1,0,0,0"),
            };
            text.push_str(&row);
            text.push('\n');
        }
        if i == 70_000 {
            line += 1;
            calibrate_at = Some(line);
            let _ = writeln!(text, "# calibrate t=700.5");
        }
    }
    assert!(
        text.len() > 8 * imubake::read::blocks::BLOCK_BYTES,
        "spans many blocks"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long.csv");
    std::fs::write(&path, &text).unwrap();
    let take = read_take(&path, &ReadOptions::default()).unwrap();
    assert!(calibrate_at.is_some());
    assert_eq!(take.recalibrations_s(), &[700.5]);
    let check = |reports: &[imubake::take::LineReport], expected: &[(u64, &str)]| {
        let got: Vec<u64> = reports.iter().map(|r| r.line).collect();
        let want: Vec<u64> = expected.iter().map(|e| e.0).collect();
        assert_eq!(got, want);
        for (r, (line, reason)) in reports.iter().zip(expected) {
            assert!(r.reason.starts_with(reason), "line {line}: {}", r.reason);
            let written = text.lines().nth(*line as usize - 1).unwrap();
            assert_eq!(r.text, written, "line {line}");
        }
    };
    dropped.sort();
    check(take.dropped_lines(), &dropped);
    check(take.repaired_lines(), &repaired);
    let (t, _) = quats(&take, "hips");
    assert!(t.windows(2).all(|w| w[0] < w[1]), "sorted into place");
    let damaged_hips = dropped
        .iter()
        .filter(|d| d.1.starts_with("expected"))
        .count();
    assert_eq!(t.len(), rows - damaged_hips);
}
