//! The SOU reader on hand-written logs: debug text at the top, corrupted lines in the middle,
//! late and repeated rows, CRLF, clock resets. Expected values are worked out by hand from the
//! fixture text (see the comments).

use crate::common;

use common::fixture;
use imubake::read::{InputFormat, ReadError, ReadOptions, detect_format, read_take, sou};
use imubake::take::{OrientationTrack, Take, YawPitchRollDeg};
use imubake::world::World;

fn read(rel: &str, options: &ReadOptions) -> Result<Take, ReadError> {
    read_take(&fixture(rel), options)
}

fn ypr(take: &Take, id: &str) -> (Vec<f64>, Vec<YawPitchRollDeg>) {
    match take.sensor(id).unwrap().orientation().unwrap() {
        OrientationTrack::YawPitchRollDeg(t) => (t.times_s().to_vec(), t.values().to_vec()),
        other => panic!("expected yaw/pitch/roll, got {other:?}"),
    }
}

#[test]
fn debug_text_and_corrupted_lines_are_dropped_one_by_one() {
    let path = fixture("sou/debug_and_corrupt.log");
    assert_eq!(detect_format(&path).unwrap(), InputFormat::Sou);
    let take = read("sou/debug_and_corrupt.log", &ReadOptions::default()).unwrap();
    assert_eq!(take.source().world, World::Ned);
    assert_eq!(take.source().start_timestamp, "1000 ms");
    let ids: Vec<_> = take.sensors().iter().map(|s| s.id()).collect();
    assert_eq!(ids, ["N0_0", "N0_1", "N1_0", "N1_1"]);

    // Lines 1, 2 (debug), 7 (6 fields), 8 (nan), 9 (garbage), 13 (repeats 1120 of N0),
    // 16 ("1--2" passes the paper's regex but is no number).
    let dropped: Vec<u64> = take.dropped_lines().iter().map(|d| d.line).collect();
    assert_eq!(dropped, [1, 2, 7, 8, 9, 13, 16]);
    let reason = |line| {
        &take
            .dropped_lines()
            .iter()
            .find(|d| d.line == line)
            .unwrap()
            .reason
    };
    assert!(
        reason(7).contains("6 comma-separated fields, expected 8"),
        "{}",
        reason(7)
    );
    assert!(reason(8).contains("yaw1"), "{}", reason(8));
    assert!(reason(13).contains("repeats the time"), "{}", reason(13));
    assert!(
        reason(16).contains("yaw1 is not a finite number"),
        "{}",
        reason(16)
    );
    assert_eq!(
        take.dropped_lines()[0].text,
        "[    1.234] usb 1-1.3: new full-speed USB device"
    );
    // Line 12 (1100 after 1120) is sorted into place.
    let repaired: Vec<u64> = take.repaired_lines().iter().map(|d| d.line).collect();
    assert_eq!(repaired, [12]);

    let (t, v) = ypr(&take, "N0_0");
    let expect_t = [0.0, 0.040, 0.100, 0.120, 0.160];
    assert_eq!(t.len(), 5);
    for (a, b) in t.iter().zip(expect_t) {
        assert!((a - b).abs() < 1e-12, "{t:?}");
    }
    let yaws: Vec<f64> = v.iter().map(|a| a.yaw).collect();
    assert_eq!(
        yaws,
        [10.0, 11.0, 12.5, 13.0, 14.0],
        "first of the repeated rows is kept"
    );
    let (t1, v1) = ypr(&take, "N1_1");
    assert_eq!(
        t1.len(),
        5,
        "1005, 1045, 1085, 1125, 1165 (line 16 at 1160 is bad): {t1:?}"
    );
    assert_eq!(
        v1[0],
        YawPitchRollDeg {
            yaw: 0.5,
            pitch: -89.5,
            roll: -179.5
        }
    );
    let (_, v10) = ypr(&take, "N1_0");
    assert_eq!(
        v10[0],
        YawPitchRollDeg {
            yaw: 350.5,
            pitch: -10.25,
            roll: 179.0
        }
    );
    assert!((take.last_time_s() - 0.165).abs() < 1e-12);
}

#[test]
fn crlf_and_missing_final_newline() {
    let take = read("sou/crlf_no_final_newline.log", &ReadOptions::default()).unwrap();
    let (t, _) = ypr(&take, "N0_0");
    assert_eq!(t.len(), 3);
    assert!((t[2] - 0.076).abs() < 1e-12);
    assert_eq!(take.dropped_lines().len(), 1);
    assert_eq!(take.dropped_lines()[0].line, 3);
}

#[test]
fn clock_reset_is_a_clear_error_naming_file_and_line() {
    let err = read("sou/clock_reset.log", &ReadOptions::default()).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("clock_reset.log"), "{msg}");
    assert!(msg.contains("line 4"), "{msg}");
    assert!(msg.contains("2.576 s"), "{msg}");
    assert!(msg.contains("clock was reset"), "{msg}");
}

#[test]
fn skip_lines_and_skip_seconds() {
    let options = ReadOptions {
        skip_lines: 5,
        ..ReadOptions::default()
    };
    let take = read("sou/debug_and_corrupt.log", &options).unwrap();
    // Lines 1-5 skipped: N0 starts at 1120 (line 11), N1 at 1045 (line 6).
    assert_eq!(take.source().start_timestamp, "1045 ms");
    let skipped = take
        .dropped_lines()
        .iter()
        .filter(|d| d.reason == "skipped by --skip-lines")
        .count();
    assert_eq!(skipped, 5);
    let (t, _) = ypr(&take, "N1_0");
    assert_eq!(t[0], 0.0);

    let options = ReadOptions {
        skip_seconds: 0.1,
        ..ReadOptions::default()
    };
    let take = read("sou/debug_and_corrupt.log", &options).unwrap();
    // Samples at or after 1100 ms are kept; the new zero is 1100 ms (N0 at line 12).
    assert_eq!(take.source().start_timestamp, "1100 ms");
    let (t, v) = ypr(&take, "N0_0");
    assert_eq!(v[0].yaw, 12.5);
    assert_eq!(t[0], 0.0);
    assert!((t[1] - 0.020).abs() < 1e-12);
    assert!(take.warnings().iter().any(|w| w.contains("--skip-seconds")));
}

#[test]
fn world_override() {
    let options = ReadOptions {
        world: Some(World::Enu),
        ..ReadOptions::default()
    };
    let take = read("sou/debug_and_corrupt.log", &options).unwrap();
    assert_eq!(take.source().world, World::Enu);
}

#[test]
fn a_log_with_no_valid_line_is_an_empty_take() {
    let err = sou::read_from(
        &b"hello\nworld\n"[..],
        std::path::Path::new("x.log"),
        &ReadOptions::default(),
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("x.log") && msg.contains("no samples"), "{msg}");
    assert!(msg.contains("line 1"), "{msg}");
}
