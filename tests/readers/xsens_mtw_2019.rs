//! Xsens MTw `.txt` exports from MT Manager 2019.2 and later, which write no `// Update Rate:`
//! line (issue 43; opensim-core issue #2812, "XSensDataReader not working with MT Manager 19.2").
//!
//! The fixtures in `tests/fixtures/xsens_mtw_2019/` are written by hand in the shape of a real
//! MT Manager 2019.2.0 export, `MT_01200454_000-000_00B40DE4.txt` of that issue (kept in
//! opensim-core as `OpenSim/Tests/shared/IMUData/Xsens/`): the same twelve comment lines
//! (`// General information: `, `//  MT Manager version: 2019.2.0 `, … `// Coordinate system:
//! ENU`, some with the trailing space MT Manager leaves), no update rate, then a tab-separated
//! column row and five-digit packet counters. `…00B41A2D.txt` has that file's column row
//! (PacketCounter, Acc, Gyr, Mag, Mat: no SampleTimeFine); `…00B41A2C.txt` and `awinda/` have
//! the column row MT Manager writes with the timestamps and quaternions ticked (PacketCounter,
//! SampleTimeFine, the date and UTC columns left empty, Acc, Gyr, Mag, Quat_q0..3, as in
//! opensim-core's MT_012005D6 test data). The numbers are made up; the times below are worked
//! out by hand from the SampleTimeFine values (10 kHz ticks: 1e-4 s each, wrapping at 2^32).

use crate::common;

use imubake::read::{ReadOptions, read_take};
use imubake::take::{OrientationTrack, Take};
use std::path::{Path, PathBuf};
use std::process::Command;

fn fixture(name: &str) -> PathBuf {
    common::fixture(&format!("xsens_mtw_2019/{name}"))
}

fn times(take: &Take, id: &str) -> Vec<f64> {
    match take.sensor(id).map(|s| s.orientation()) {
        Some(Some(OrientationTrack::Quaternion(t))) => t.iter().map(|(time, _)| time).collect(),
        other => panic!("sensor `{id}`: expected quaternions, got {other:?}"),
    }
}

fn assert_times(got: &[f64], expected: &[f64]) {
    assert_eq!(got.len(), expected.len(), "{got:?} against {expected:?}");
    for (g, e) in got.iter().zip(expected) {
        assert!((g - e).abs() < 1e-9, "{got:?} against {expected:?}");
    }
}

fn inspect(args: &[&str], input: &Path) -> std::process::Output {
    Command::new(common::imubake_bin())
        .arg("inspect")
        .arg(input)
        .args(args)
        .output()
        .expect("run imubake")
}

/// SampleTimeFine of the eight rows: 2^32 − 250, 2^32 − 150, 2^32 − 50, then (wrapped) 50, 150,
/// 350 (a packet lost: PacketCounter 03032 is missing), 450, 550. Unwrapped, each is 100 ticks
/// after the one before (200 across the lost packet), so t = (ticks since the first) × 1e-4 s:
/// 0, 0.01, 0.02, 0.03, 0.04, 0.06, 0.07, 0.08.
const TIMES: [f64; 8] = [0.0, 0.01, 0.02, 0.03, 0.04, 0.06, 0.07, 0.08];

#[test]
fn times_come_from_sample_time_fine_across_its_wrap() {
    let path = fixture("MT_01200454_000-000_00B41A2C.txt");
    let take = read_take(&path, &ReadOptions::default()).unwrap();
    assert_times(&times(&take, "00B41A2C"), &TIMES);
    assert_eq!(
        take.source().start_timestamp,
        "SampleTimeFine 4294967046 at 10000 Hz"
    );
    assert!(
        take.dropped_lines().is_empty(),
        "{:?}",
        take.dropped_lines()
    );
    // The rows' quaternions as written: row k turns 0.1·k rad about z, w first.
    let Some(OrientationTrack::Quaternion(track)) = take.sensor("00B41A2C").unwrap().orientation()
    else {
        panic!("quaternions");
    };
    let q = track.values()[1];
    assert!(
        (q.w - 0.998750).abs() < 2e-6 && (q.k - 0.049979).abs() < 2e-6,
        "{q:?}"
    );
}

/// `imubake inspect --json`: 8 samples, intervals of 10 ms and one of 20 ms (the lost packet),
/// so a mean of 80 ms / 7 = 11.428571 ms; t = 0 named by its SampleTimeFine.
#[test]
fn inspect_reports_the_rate_of_sample_time_fine() {
    let path = fixture("MT_01200454_000-000_00B41A2C.txt");
    let out = inspect(&["--json"], &path);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let s = &json["sensors"]["00B41A2C"];
    assert_eq!(s["samples"], 8, "{json}");
    let ms = |k: &str| s[k].as_f64().unwrap();
    assert!((ms("min_dt_ms") - 10.0).abs() < 1e-6, "{json}");
    assert!((ms("max_dt_ms") - 20.0).abs() < 1e-6, "{json}");
    assert!((ms("mean_dt_ms") - 80.0 / 7.0).abs() < 1e-6, "{json}");
    assert!(
        (json["time_frame_s"].as_f64().unwrap() - 0.08).abs() < 1e-9,
        "{json}"
    );
    assert_eq!(
        json["source"]["start_timestamp"],
        "SampleTimeFine 4294967046 at 10000 Hz"
    );
    assert_eq!(json["source"]["format"], "xsens-mtw");
}

/// The real 2019.2 file's columns: no update rate and no SampleTimeFine, so nothing gives the
/// packet counter a rate. The error names what is missing and what to do (not the old hint,
/// "export from MT Manager with the header comments on", which these exports have); `--rate`
/// then gives PacketCounter its rate: rows 03027..03030 at 100 Hz are 0, 0.01, 0.02, 0.03 s.
#[test]
fn packet_counter_alone_needs_a_rate() {
    let path = fixture("MT_01200454_000-000_00B41A2D.txt");
    let out = inspect(&[], &path);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(
            "line 13: no `// Update Rate: <n>Hz` line in the header and no SampleTimeFine column"
        ),
        "{err}"
    );
    assert!(err.contains("--rate"), "{err}");
    assert!(!err.contains("header comments on"), "{err}");

    let options = ReadOptions {
        rate_hz: Some(100.0),
        ..ReadOptions::default()
    };
    let take = read_take(&path, &options).unwrap();
    assert_eq!(
        take.source().start_timestamp,
        "PacketCounter 3027 at 100 Hz"
    );
    let Some(OrientationTrack::Quaternion(track)) = take.sensor("00B41A2D").unwrap().orientation()
    else {
        panic!("quaternions");
    };
    let got: Vec<f64> = track.iter().map(|(t, _)| t).collect();
    assert_times(&got, &[0.0, 0.01, 0.02, 0.03]);

    let out = inspect(&["--rate", "100", "--json"], &path);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mean = json["sensors"]["00B41A2D"]["mean_dt_ms"].as_f64().unwrap();
    assert!((mean - 10.0).abs() < 1e-6, "{json}");
}

/// MT Manager 2020.0.2 writes a SampleTimeFine column and leaves it empty (opensim-core's
/// `MT_01200312-002-000_00B474BA.txt`): refused by the first data row's line, unless `--rate`.
#[test]
fn an_empty_sample_time_fine_column_is_named_by_its_row() {
    let text = "// General information: \n//  MT Manager version: 2020.0.2 \n// Coordinate system: ENU\n\
                PacketCounter\tSampleTimeFine\tAcc_X\tAcc_Y\tAcc_Z\tQuat_q0\tQuat_q1\tQuat_q2\tQuat_q3\n\
                \n\
                01330\t\t9.1\t0.4\t-3.4\t1\t0\t0\t0\n\
                01331\t\t9.1\t0.4\t-3.4\t1\t0\t0\t0\n";
    let read = |options: &ReadOptions| {
        imubake::read::xsens_mtw::read_from(text.as_bytes(), Path::new("x_S.txt"), options)
    };
    let err = read(&ReadOptions::default()).unwrap_err().to_string();
    assert!(
        err.contains("line 6: no `// Update Rate: <n>Hz` line in the header, and on this first data row SampleTimeFine is empty"),
        "{err}"
    );
    assert!(err.contains("--rate"), "{err}");
    let options = ReadOptions {
        rate_hz: Some(40.0),
        ..ReadOptions::default()
    };
    let take = read(&options).unwrap();
    assert_times(&times(&take, "S"), &[0.0, 0.025]);
}

/// Two sensors of one Awinda recording share SampleTimeFine's clock: A's rows are at 2^32 − 250,
/// 2^32 − 150, 2^32 − 50, 50 ticks; B's at 2^32 − 50, 50, 150. On the take's clock (t = 0 at A's
/// first row) A is at 0, 0.01, 0.02, 0.03 s and B at 0.02, 0.03, 0.04 s, B's wrap after A's
/// start.
#[test]
fn a_folder_of_sensors_shares_sample_time_fine() {
    let take = read_take(&fixture("awinda"), &ReadOptions::default()).unwrap();
    assert_times(&times(&take, "00B41A2C"), &[0.0, 0.01, 0.02, 0.03]);
    assert_times(&times(&take, "00B41A2E"), &[0.02, 0.03, 0.04]);
    assert_eq!(
        take.source().start_timestamp,
        "SampleTimeFine 4294967046 at 10000 Hz"
    );
}

/// A file with the `// Update Rate:` line keeps PacketCounter at that rate even with
/// SampleTimeFine filled in: the same eight rows under a 4.x-style `// Update Rate: 50.0Hz` are
/// at the counter's steps of 20 ms, 03027..03035 with 03032 missing: 0, 0.02, 0.04, 0.06, 0.08,
/// 0.12, 0.14, 0.16 s (SampleTimeFine's would be half those), named by PacketCounter.
#[test]
fn an_update_rate_line_still_gives_the_packet_counter_its_rate() {
    let text = std::fs::read_to_string(fixture("MT_01200454_000-000_00B41A2C.txt")).unwrap();
    let text = text.replacen(
        "// Coordinate system: ENU\n",
        "// Coordinate system: ENU\n// Update Rate: 50.0Hz\n",
        1,
    );
    let take = imubake::read::xsens_mtw::read_from(
        text.as_bytes(),
        Path::new("MT_01200454_000-000_00B41A2C.txt"),
        &ReadOptions::default(),
    )
    .unwrap();
    assert_eq!(take.source().start_timestamp, "PacketCounter 3027 at 50 Hz");
    let doubled: Vec<f64> = TIMES.iter().map(|t| 2.0 * t).collect();
    assert_times(&times(&take, "00B41A2C"), &doubled);
}
