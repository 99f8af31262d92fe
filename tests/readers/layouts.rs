//! Declared packet layouts (issue 54): captures in the two shipped layouts written by
//! `tests/python/make_layout_streams.py` from known values with Python's `struct` (the data
//! matrix's hexadecimal float32 rows; the ESP32 struct with its CRC from `binascii.crc_hqx`), read
//! through `--layout`: every value as written (float32), the damaged rows and frames reported with
//! their lines and byte offsets and the rest read, and the binary capture converting like the same
//! readings given as imubake CSV.

use crate::common;

use common::{imubake_bin, python, repo_file, run};
use imubake::read::{ReadOptions, read_take};
use imubake::take::OrientationTrack;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn fixtures(py: &Path) -> (tempfile::TempDir, Value) {
    let dir = tempfile::tempdir().unwrap();
    run(Command::new(py)
        .arg(repo_file("tests/python/make_layout_streams.py"))
        .arg(dir.path()));
    let expected =
        serde_json::from_slice(&std::fs::read(dir.path().join("expected.json")).unwrap()).unwrap();
    (dir, expected)
}

fn layout(name: &str) -> PathBuf {
    repo_file(&format!("layouts/{name}"))
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn quaternion(v: &Value) -> UnitQuaternion<f64> {
    let q = numbers(v);
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

#[test]
fn the_data_matrix_reads_every_row_as_written() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let options = ReadOptions {
        layout: Some(layout("paper004_data_matrix.yaml")),
        rate_hz: Some(100.0),
        ..ReadOptions::default()
    };
    let take = read_take(&dir.path().join("matrix.txt"), &options).unwrap();
    assert_eq!(take.source().format.name(), "layout");
    let m = &expected["matrix"];
    for id in ["1", "2", "3"] {
        let Some(OrientationTrack::Quaternion(track)) = take.sensor(id).unwrap().orientation()
        else {
            panic!("{id}: no orientation");
        };
        let rows = m["quaternions"][id].as_array().unwrap();
        assert_eq!(track.len(), rows.len(), "{id}");
        for (k, ((t, q), e)) in track.iter().zip(rows).enumerate() {
            assert!((t - k as f64 / 100.0).abs() < 1e-12, "{id}: t {t}");
            // Quaternions: the float32 values normalised in f64 on both sides; Euler angles:
            // scipy's intrinsic ZYX of the same float32 angles.
            let angle = q.angle_to(&quaternion(e));
            assert!(angle < 1e-12, "{id} row {k}: {angle} rad");
        }
    }
    let reasons = |line: u64| -> Vec<&str> {
        take.dropped_lines()
            .iter()
            .filter(|r| r.line == line)
            .map(|r| r.reason.as_str())
            .collect()
    };
    for line in numbers(&m["repeats"]) {
        let r = reasons(line as u64);
        assert!(
            r.len() == 1 && r[0].contains("new-data flag is 0"),
            "line {line}: {r:?}"
        );
    }
    let bad = numbers(&m["bad_lines"]);
    assert_eq!(bad.len(), 3);
    assert!(reasons(bad[0] as u64)[0].contains("`3F80000`"));
    assert_eq!(reasons(bad[1] as u64), ["unknown type 9"]);
    assert!(reasons(bad[2] as u64)[0].contains("2 values for type 1, expected 3"));
    assert_eq!(
        take.dropped_lines().len(),
        m["repeats"].as_array().unwrap().len() + 3
    );
}

#[test]
fn the_esp32_struct_reads_every_value_and_names_each_bad_frame() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let options = ReadOptions {
        layout: Some(layout("esp32_struct.yaml")),
        ..ReadOptions::default()
    };
    let take = read_take(&dir.path().join("esp32.bin"), &options).unwrap();
    let e = &expected["esp32"];
    let frames = e["frames"].as_array().unwrap();
    for id in ["1", "2", "3"] {
        let sensor = take.sensor(id).unwrap();
        let mine: Vec<&Value> = frames
            .iter()
            .filter(|f| f["sensor"].as_u64().unwrap().to_string() == id)
            .collect();
        let Some(OrientationTrack::Quaternion(track)) = sensor.orientation() else {
            panic!("{id}: no orientation");
        };
        let inertial = sensor.inertial().unwrap();
        assert_eq!(
            (track.len(), inertial.len()),
            (mine.len(), mine.len()),
            "{id}"
        );
        for (((t, q), (_, s)), f) in track.iter().zip(inertial.iter()).zip(&mine) {
            assert!((t - f["t_us"].as_f64().unwrap() * 1e-6).abs() < 1e-12);
            assert!(q.angle_to(&quaternion(&f["q"])) < 1e-12, "{id} at {t}");
            let gyro = Vector3::from_vec(numbers(&f["gyro_dps"])) * (std::f64::consts::PI / 180.0);
            let accel = Vector3::from_vec(numbers(&f["accel_g"])) * 9.80665;
            assert!((s.gyro_rad_s - gyro).norm() < 1e-12, "{id} at {t}");
            assert!((s.accel_m_s2 - accel).norm() < 1e-12, "{id} at {t}");
        }
    }
    // Each damaged frame: dropped, named by its byte offset; nothing else is.
    let offsets: Vec<String> = take
        .dropped_lines()
        .iter()
        .map(|r| r.reason.clone())
        .collect();
    let bad = numbers(&e["bad_offsets"]);
    assert_eq!(offsets.len(), bad.len(), "{offsets:?}");
    for (reason, offset) in offsets.iter().zip(&bad) {
        assert!(
            reason.starts_with("bad checksum")
                && reason.ends_with(&format!("(byte offset {offset})")),
            "{reason}"
        );
    }
    // The junk before the first frame, and each damaged frame's 36 bytes after its first.
    let skipped = e["junk"].as_u64().unwrap() + 36 * bad.len() as u64;
    assert!(
        take.warnings().iter().any(|w| w
            == &format!("{skipped} bytes outside frames skipped (the first at byte offset 0)")),
        "{:?}",
        take.warnings()
    );
}

/// A take recorded through a layout converts as the same readings given as imubake CSV: the
/// BVHs are identical.
#[test]
fn a_layout_take_converts_like_the_same_values_as_csv() {
    let Some(py) = python() else { return };
    let (dir, _) = fixtures(&py);
    let mapping = dir.path().join("mapping.json");
    std::fs::write(
        &mapping,
        r#"{"rig": "mixamo", "heading": "sensors", "calibration": {"pose": "rest", "start_s": 0, "duration_s": 0.5},
            "sensors": {"1": {"bone": "Hips", "mount": "calibrate"},
                        "2": {"bone": "Spine1", "mount": "calibrate"},
                        "3": {"bone": "Head", "mount": "calibrate"}}}"#,
    )
    .unwrap();
    let convert = |input: &str, extra: &[&Path]| {
        let out = dir.path().join(format!("out-{input}"));
        let mut cmd = Command::new(imubake_bin());
        cmd.arg("convert")
            .arg(dir.path().join(input))
            .arg("--mapping")
            .arg(&mapping)
            .args(["--format", "bvh", "--out"])
            .arg(&out);
        for layout in extra {
            cmd.arg("--layout").arg(layout);
        }
        run(&mut cmd);
        let stem = input.split('.').next().unwrap();
        let sidecar: Value = serde_json::from_slice(
            &std::fs::read(out.join(format!("{stem}.imubake.json"))).unwrap(),
        )
        .unwrap();
        (
            std::fs::read_to_string(out.join(format!("{stem}.bvh"))).unwrap(),
            sidecar,
        )
    };
    let (binary, sidecar) = convert("esp32.bin", &[&layout("esp32_struct.yaml")]);
    let (csv, _) = convert("esp32.csv", &[]);
    assert_eq!(sidecar["source"]["format"], "layout");
    assert!(
        sidecar["source"]["layout"]["path"]
            .as_str()
            .unwrap()
            .ends_with("esp32_struct.yaml")
    );
    assert_eq!(
        sidecar["source"]["layout"]["sha256"]
            .as_str()
            .unwrap()
            .len(),
        64
    );
    assert!(binary == csv, "the BVHs differ");
}

/// `imubake live` on `source` with `layout`, recording; `feed` sends the capture; the recorded
/// CSV's header and rows.
fn live_recording(
    dir: &Path,
    source: &str,
    layout: &Path,
    feed: impl FnOnce(),
) -> (String, Vec<Vec<String>>) {
    let mapping = dir.join("live_mapping.json");
    std::fs::write(
        &mapping,
        r#"{"rig": "mixamo", "world": "enu", "heading": "sensors", "sensors": {
            "1": {"bone": "Hips", "mount": "calibrate"},
            "2": {"bone": "Spine1", "mount": "calibrate"},
            "3": {"bone": "Head", "mount": "calibrate"}}}"#,
    )
    .unwrap();
    let record = dir.join(format!("takes-{}", source.replace([':', '/'], "_")));
    let child = Command::new(imubake_bin())
        .args(["live", "--source", source, "--mapping"])
        .arg(&mapping)
        .arg("--layout")
        .arg(layout)
        .args(["--vmc", "off", "--listen", "off", "--record"])
        .arg(&record)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    feed();
    std::thread::sleep(std::time::Duration::from_millis(800));
    let text = common::stop_and_read_recording(child, &record);
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header = lines.next().unwrap().to_string();
    let rows = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    (header, rows)
}

fn row_quaternion(row: &[String]) -> UnitQuaternion<f64> {
    let q: Vec<f64> = row[2..6].iter().map(|v| v.parse().unwrap()).collect();
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// A live recording of the ESP32 capture: one row per good frame, in order, each with the
/// frame's sensor, its time from the first frame's, its quaternion (to 10⁻¹² rad: the session
/// normalises it) and its rates and accelerations exactly.
fn assert_esp32_recorded(header: &str, rows: &[Vec<String>], expected: &Value) {
    assert_eq!(
        header,
        "time_s,sensor,qw,qx,qy,qz,gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g"
    );
    let frames = expected["esp32"]["frames"].as_array().unwrap();
    assert_eq!(rows.len(), frames.len());
    let t0 = frames[0]["t_us"].as_f64().unwrap() * 1e-6;
    for (row, f) in rows.iter().zip(frames) {
        assert_eq!(row[1], f["sensor"].as_u64().unwrap().to_string());
        let t: f64 = row[0].parse().unwrap();
        assert!(
            (t - (f["t_us"].as_f64().unwrap() * 1e-6 - t0)).abs() < 1e-12,
            "{row:?}"
        );
        let angle = row_quaternion(row).angle_to(&quaternion(&f["q"]));
        assert!(angle < 1e-12, "{row:?}: {angle} rad");
        let v: Vec<f64> = row[6..12].iter().map(|v| v.parse().unwrap()).collect();
        let mut e = numbers(&f["gyro_dps"]);
        e.extend(numbers(&f["accel_g"]));
        assert_eq!(v, e);
    }
}

/// `live --source udp:PORT:layout`: the ESP32 capture sent three frames to a datagram is
/// recorded with every frame's values as written — the rates and accelerations exactly, the
/// quaternion to 10⁻¹² rad (normalised) — the damaged frames dropped, the time from the frames'
/// own clock.
#[test]
fn a_live_udp_stream_decodes_through_the_layout() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let port = common::free_udp_port();
    let bytes = std::fs::read(dir.path().join("esp32.bin")).unwrap();
    let (header, rows) = live_recording(
        dir.path(),
        &format!("udp:{port}:layout"),
        &layout("esp32_struct.yaml"),
        || {
            let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
            for chunk in bytes.chunks(3 * 37) {
                socket.send_to(chunk, ("127.0.0.1", port)).unwrap();
                std::thread::sleep(std::time::Duration::from_micros(300));
            }
        },
    );
    assert_esp32_recorded(&header, &rows, &expected);
}

/// `live --source serial:PTY:layout`: paper 004's data matrix written row by row through a
/// pseudo-terminal, as a receiver on USB serial would: every row's orientation as written, the
/// repeats and damaged rows dropped.
#[test]
fn a_live_serial_port_decodes_the_data_matrix() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let text = std::fs::read_to_string(dir.path().join("matrix.txt")).unwrap();
    let (mut master, slave) = common::openpty();
    let (header, rows) = live_recording(
        dir.path(),
        &format!("serial:{}:layout", slave.1),
        &layout("paper004_data_matrix.yaml"),
        || {
            use std::io::Write;
            for (i, line) in text.lines().enumerate() {
                master.write_all(line.as_bytes()).unwrap();
                master.write_all(b"\n").unwrap();
                if i % 30 == 0 {
                    std::thread::sleep(std::time::Duration::from_millis(2));
                }
            }
            master.flush().unwrap();
        },
    );
    unsafe { libc::close(slave.0) };
    assert_eq!(header, "time_s,sensor,qw,qx,qy,qz");
    for id in ["1", "2", "3"] {
        let mine: Vec<&Vec<String>> = rows.iter().filter(|r| r[1] == id).collect();
        let e = expected["matrix"]["quaternions"][id].as_array().unwrap();
        assert_eq!(mine.len(), e.len(), "sensor {id}");
        for (row, q) in mine.iter().zip(e) {
            let angle = row_quaternion(row).angle_to(&quaternion(q));
            assert!(angle < 1e-12, "sensor {id}: {angle} rad");
        }
    }
}

/// `live --source tcp:HOST:PORT:layout`: the ESP32 capture from a TCP server (a Wi-Fi board's
/// socket) in arbitrary 1000-byte writes: every frame recorded with its values.
#[test]
fn a_live_tcp_stream_decodes_through_the_layout() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let bytes = std::fs::read(dir.path().join("esp32.bin")).unwrap();
    let (header, rows) = live_recording(
        dir.path(),
        &format!("tcp:127.0.0.1:{port}:layout"),
        &layout("esp32_struct.yaml"),
        || {
            use std::io::Write;
            let (mut stream, _) = listener.accept().unwrap();
            for chunk in bytes.chunks(1000) {
                stream.write_all(chunk).unwrap();
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            stream.flush().unwrap();
            // Kept open until the session stops, as a device's socket is.
            std::mem::forget(stream);
        },
    );
    assert_esp32_recorded(&header, &rows, &expected);
}

/// `inspect --layout` shows what the layout makes of a capture (its sensors, the damaged frames
/// by offset); `batch --layout` converts a folder holding the capture and the layout file itself
/// (recognised and skipped, not a take).
#[test]
fn inspect_and_batch_read_through_the_layout() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let layout_file = layout("esp32_struct.yaml");
    let out = run(Command::new(imubake_bin())
        .arg("inspect")
        .arg(dir.path().join("esp32.bin"))
        .arg("--layout")
        .arg(&layout_file));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("Node count: 3"), "{text}");
    for offset in numbers(&expected["esp32"]["bad_offsets"]) {
        assert!(text.contains(&format!("(byte offset {offset})")), "{text}");
    }

    let library = dir.path().join("library");
    std::fs::create_dir_all(&library).unwrap();
    std::fs::copy(dir.path().join("esp32.bin"), library.join("suit.bin")).unwrap();
    std::fs::copy(&layout_file, library.join("suit_layout.yaml")).unwrap();
    std::fs::write(
        library.join("imubake.yaml"),
        "layout: suit_layout.yaml\nmapping: mapping.json\nformats: [bvh]\n",
    )
    .unwrap();
    std::fs::write(
        library.join("mapping.json"),
        r#"{"rig": "mixamo", "heading": "sensors", "sensors": {"1": {"bone": "Hips", "mount": "calibrate"}}}"#,
    )
    .unwrap();
    let out = run(Command::new(imubake_bin())
        .arg("batch")
        .arg(&library)
        .arg("--config")
        .arg(library.join("imubake.yaml"))
        .arg("--out")
        .arg(dir.path().join("converted"))
        .arg("--json"));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (report["converted"].as_u64(), report["failed"].as_u64()),
        (Some(1), Some(0))
    );
    let sidecar: Value = serde_json::from_slice(
        &std::fs::read(dir.path().join("converted/suit.imubake.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(sidecar["source"]["format"], "layout");
}
