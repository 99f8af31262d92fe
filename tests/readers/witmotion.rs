//! WitMotion's binary protocol: recordings written by `tests/python/make_witmotion.py` from known
//! values (the expected decoding computed there from the int16 words, with the protocol's scales
//! and scipy for the Z-Y-X angles), read as a session folder, without time packets (`--rate`),
//! with a broken checksum, and live over UDP (`udp:PORT:witmotion`) into a recording.

use crate::common;

use common::{convert_with_mapping, imubake_bin, python, repo_file, run};
use imubake::read::{ReadOptions, read_take};
use imubake::take::OrientationTrack;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

fn fixtures(py: &Path) -> (tempfile::TempDir, Value) {
    let dir = tempfile::tempdir().unwrap();
    run(Command::new(py)
        .arg(repo_file("tests/python/make_witmotion.py"))
        .arg(dir.path()));
    let expected =
        serde_json::from_slice(&std::fs::read(dir.path().join("expected.json")).unwrap()).unwrap();
    (dir, expected)
}

fn quaternion(v: &Value) -> UnitQuaternion<f64> {
    let q: Vec<f64> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

fn vector(v: &Value) -> Vector3<f64> {
    common::vec3(v)
}

/// Every sensor's orientation, angular velocity, acceleration and magnetic field equal the
/// script's decoding (times from the time packets, 10 ms apart; orientation from the quaternion
/// packet, w first), within float rounding; the sample whose 0x52 packet has a broken checksum
/// has no angular velocity, and the warning names that packet's byte offset.
#[test]
fn a_session_folder_reads_as_encoded() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let take = read_take(&dir.path().join("session"), &ReadOptions::default()).unwrap();
    assert_eq!(take.source().format.name(), "witmotion");
    assert_eq!(take.source().world.name(), "enu");
    let bad = expected["bad_offset"].as_u64().unwrap();
    assert!(
        take.warnings()
            .iter()
            .any(|w| w.contains("left_shank") && w.contains(&format!("byte offset {bad}"))),
        "{:?}",
        take.warnings()
    );
    let mut worst_q: f64 = 0.0;
    let mut worst_v: f64 = 0.0;
    for id in ["left_thigh", "left_shank"] {
        let samples = expected[id].as_array().unwrap();
        let sensor = take.sensor(id).unwrap();
        let Some(OrientationTrack::Quaternion(track)) = sensor.orientation() else {
            panic!("{id}: no orientation");
        };
        assert_eq!(track.len(), samples.len());
        for ((t, q), e) in track.iter().zip(samples) {
            assert!((t - e["t"].as_f64().unwrap()).abs() < 1e-9, "{id}: t {t}");
            worst_q = worst_q.max(q.angle_to(&quaternion(&e["q"])));
        }
        let inertial = sensor.inertial().unwrap();
        let with_gyro: Vec<&Value> = samples
            .iter()
            .filter(|e| e["gyro_rad_s"].is_array())
            .collect();
        assert_eq!(inertial.len(), with_gyro.len(), "{id}");
        for ((_, s), e) in inertial.iter().zip(with_gyro) {
            worst_v = worst_v
                .max((s.gyro_rad_s - vector(&e["gyro_rad_s"])).norm())
                .max((s.accel_m_s2 - vector(&e["accel_m_s2"])).norm());
        }
        let mag = sensor.magnetometer().unwrap();
        for ((_, m), e) in mag.iter().zip(samples) {
            assert_eq!(*m, vector(&e["mag"]), "{id}: raw magnetometer counts");
        }
    }
    assert_eq!(
        take.sensor("left_shank").unwrap().inertial().unwrap().len(),
        199
    );
    eprintln!("worst quaternion {worst_q:.2e} rad, worst gyro/accel {worst_v:.2e}");
    assert!(worst_q < 1e-9 && worst_v < 1e-12, "{worst_q} {worst_v}");
}

/// Without time packets the rate must be given; with `--rate 100` sample k is at k / 100 s, and
/// angle-only samples are the Z-Y-X attitude scipy computes.
#[test]
fn untimed_recordings_need_a_rate() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let path = dir.path().join("notime/imu.bin");
    let e = read_take(&path, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("--rate") && e.contains("imu.bin"), "{e}");
    let take = read_take(
        &path,
        &ReadOptions {
            rate_hz: Some(100.0),
            ..Default::default()
        },
    )
    .unwrap();
    let Some(OrientationTrack::Quaternion(track)) = take.sensor("imu").unwrap().orientation()
    else {
        panic!("no orientation");
    };
    let samples = expected["imu"].as_array().unwrap();
    let mut worst: f64 = 0.0;
    for (k, ((t, q), e)) in track.iter().zip(samples).enumerate() {
        assert!((t - k as f64 / 100.0).abs() < 1e-12);
        worst = worst.max(q.angle_to(&quaternion(&e["q"])));
    }
    assert_eq!(track.len(), 200);
    assert!(worst < 1e-9, "{worst} rad");
    // The CLI says the same, exit non-zero.
    let out = Command::new(imubake_bin())
        .args(["inspect", path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--rate HZ"));
}

/// `live --source udp:PORT:witmotion`: the thigh's recording sent in datagrams of 5 packets
/// becomes imubake CSV lines in the session's recording whose quaternions are the script's
/// (sensor id `udp<PORT>`), the chip clock from 0.
#[test]
fn a_live_witmotion_stream_is_recorded_as_decoded() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let port = common::free_udp_port();
    let sensor = format!("udp{port}");
    let mapping = dir.path().join("mapping.json");
    std::fs::write(
        &mapping,
        format!(r#"{{"rig": "mixamo", "world": "enu", "sensors": {{"{sensor}": {{"bone": "LeftUpLeg", "mount": "calibrate"}}}}}}"#),
    )
    .unwrap();
    let record = dir.path().join("takes");
    let child = Command::new(imubake_bin())
        .args([
            "live",
            "--source",
            &format!("udp:{port}:witmotion"),
            "--mapping",
        ])
        .arg(&mapping)
        .args(["--vmc", "off", "--listen", "off", "--record"])
        .arg(&record)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let bytes = std::fs::read(dir.path().join("session/left_thigh.bin")).unwrap();
    let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    for chunk in bytes.chunks(55) {
        socket.send_to(chunk, ("127.0.0.1", port)).unwrap();
        std::thread::sleep(Duration::from_micros(300));
    }
    std::thread::sleep(Duration::from_millis(500));
    let text = common::stop_and_read_recording(child, &record);
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    assert_eq!(
        lines.next(),
        Some("time_s,sensor,qw,qx,qy,qz,gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let samples = expected["left_thigh"].as_array().unwrap();
    // Every sample but the last (the stream never ends: the last waits for its successor).
    assert!(rows.len() >= samples.len() - 1, "{} rows", rows.len());
    let mut worst: f64 = 0.0;
    for (row, e) in rows.iter().zip(samples) {
        assert_eq!(row[1], sensor);
        let t: f64 = row[0].parse().unwrap();
        assert!((t - e["t"].as_f64().unwrap()).abs() < 1e-6, "{row:?}");
        let q: Vec<f64> = row[2..6].iter().map(|v| v.parse().unwrap()).collect();
        let q = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
        worst = worst.max(q.angle_to(&quaternion(&e["q"])));
    }
    eprintln!("{} rows recorded, worst {worst:.2e} rad", rows.len());
    assert!(worst < 1e-8, "{worst}");
}

/// A WitMotion session converts onto mixamo with a mapping, like any capture.
#[test]
fn a_witmotion_session_converts() {
    let Some(py) = python() else { return };
    let (dir, _) = fixtures(&py);
    let sidecar = convert_with_mapping(
        &dir.path().join("session"),
        r#"{"rig": "mixamo", "world": "enu", "sensors": {
            "left_thigh": {"bone": "LeftUpLeg", "mount": "calibrate"},
            "left_shank": {"bone": "LeftLeg", "mount": "calibrate"}}}"#,
        dir.path(),
    );
    assert_eq!(sidecar["source"]["format"], "witmotion");
    assert_eq!(sidecar["frames"], 60, "1.99 s at 30 fps");
    assert!(
        sidecar["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("bad checksum")),
        "{sidecar}"
    );
}
