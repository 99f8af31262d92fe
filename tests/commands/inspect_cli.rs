//! `imubake inspect` end to end: its figures against an independent Python re-implementation of
//! paper 002's summarizer (tests/python/summarize.py, numpy), its text, and its exit codes.

use crate::common;

use common::{fixture, imubake_bin, inspect_json, python, shared};
use serde_json::Value;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn python_summary(format: &str, path: &Path) -> Option<Value> {
    let py = python()?;
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/summarize.py");
    let out = Command::new(py)
        .arg(script)
        .arg(format)
        .arg(path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(serde_json::from_slice(&out.stdout).unwrap())
}

fn close(a: &Value, b: &Value, tol: f64, what: &str) {
    match (a.as_f64(), b.as_f64()) {
        (Some(x), Some(y)) => assert!((x - y).abs() <= tol, "{what}: imubake {x} vs python {y}"),
        _ => assert_eq!(a, b, "{what}"),
    }
}

/// Compares imubake's inspection of `path` with the Python summarizer's.
fn check_against_python(format: &str, path: &Path) {
    let Some(expected) = python_summary(format, path) else {
        return;
    };
    let got = inspect_json(path);
    assert_eq!(got["source"]["format"], format);
    assert_eq!(
        got["node_count"],
        expected["node_count"],
        "{}",
        path.display()
    );
    close(
        &got["time_frame_s"],
        &expected["time_frame_s"],
        1e-9,
        "time_frame_s",
    );
    let exp_sensors = expected["sensors"].as_object().unwrap();
    let got_sensors = got["sensors"].as_object().unwrap();
    let ids = |m: &serde_json::Map<String, Value>| m.keys().cloned().collect::<BTreeSet<_>>();
    assert_eq!(ids(got_sensors), ids(exp_sensors));
    for (id, exp) in exp_sensors {
        let g = &got_sensors[id];
        assert_eq!(g["samples"], exp["samples"], "{id} samples");
        for key in ["mean_dt_ms", "min_dt_ms", "max_dt_ms"] {
            close(&g[key], &exp[key], 1e-6, &format!("{id} {key}"));
        }
        let gaps = g["gaps"].as_array().unwrap();
        let exp_gaps = exp["gaps"].as_array().unwrap();
        assert_eq!(gaps.len(), exp_gaps.len(), "{id} gaps");
        for (gap, e) in gaps.iter().zip(exp_gaps) {
            close(&gap["start_s"], &e[0], 1e-9, "gap start");
            close(&gap["end_s"], &e[1], 1e-9, "gap end");
        }
    }
    let lines = |v: &Value| -> BTreeSet<u64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|d| d.as_u64().or_else(|| d["line"].as_u64()).unwrap())
            .collect()
    };
    assert_eq!(
        lines(&got["dropped_lines"]),
        lines(&expected["dropped_lines"]),
        "dropped lines"
    );
}

#[test]
fn bundled_sou_sample_matches_python() {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/sou_wave.log");
    check_against_python("sou", &sample);
}

#[test]
fn sou_fixtures_match_python() {
    check_against_python("sou", &fixture("sou/debug_and_corrupt.log"));
    check_against_python("sou", &fixture("sou/gaps.log"));
}

#[test]
fn imubake_csv_fixture_matches_python() {
    check_against_python("imubake-csv", &fixture("csv/quaternions.csv"));
}

#[test]
fn real_vendor_exports_match_python() {
    let cases: [(&str, &str); 3] = [
        (
            "xsens-dot",
            "vendor_formats/Original_XsensDot_Data_Realtime",
        ),
        ("xsens-mtw", "vendor_formats/OpenSenseExampleIMUData"),
        ("xio-session", "fullbody/xio_lower_body_7imu"),
    ];
    for (format, rel) in cases {
        let Some(path): Option<PathBuf> = shared(rel) else {
            return;
        };
        check_against_python(format, &path);
    }
}

#[test]
fn gaps_by_hand() {
    // A: 1000, 1040, 1600 (gap of 0.56 s from 0.04 s), 1630. B: 1620, 2000 (gap of 0.38 s).
    let got = inspect_json(&fixture("sou/gaps.log"));
    let gaps = &got["sensors"]["A_0"]["gaps"];
    assert_eq!(gaps.as_array().unwrap().len(), 1);
    close(
        &gaps[0]["start_s"],
        &Value::from(0.04),
        1e-12,
        "A gap start",
    );
    close(
        &gaps[0]["duration_s"],
        &Value::from(0.56),
        1e-12,
        "A gap duration",
    );
    close(
        &got["sensors"]["B_1"]["gaps"][0]["end_s"],
        &Value::from(1.0),
        1e-12,
        "B gap end",
    );
    close(&got["time_frame_s"], &Value::from(1.0), 1e-12, "time frame");
}

#[test]
fn text_report_for_people() {
    let out = Command::new(imubake_bin())
        .arg("inspect")
        .arg(fixture("sou/debug_and_corrupt.log"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("Time frame: 0.165 seconds"), "{text}");
    assert!(text.contains("Node count: 4"), "{text}");
    assert!(text.contains("Dropped lines: 7"), "{text}");
    assert!(
        text.contains("line 9: does not match the SOU format"),
        "{text}"
    );
    assert!(text.contains("Repaired lines: 1"), "{text}");
    // N0_0: intervals 40, 60, 20, 40 ms → mean 40, min 20, max 60.
    let row = text.lines().find(|l| l.starts_with("N0_0")).unwrap();
    let cols: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(cols, ["N0_0", "5", "40.00", "20.00", "60.00", "0"]);
}

#[test]
fn exit_codes_and_messages() {
    let run = |args: &[&str]| Command::new(imubake_bin()).args(args).output().unwrap();
    let out = run(&["inspect", "no/such/file.log"]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no/such/file.log") && err.contains("cannot read"),
        "{err}"
    );

    let bin = fixture("csv/binary.bin");
    let out = run(&["inspect", bin.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("binary"));

    let reset = fixture("sou/clock_reset.log");
    let out = run(&["inspect", reset.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("line 4"));

    assert_eq!(
        run(&["inspect", "--no-such-flag", "x"]).status.code(),
        Some(2)
    );
    assert_eq!(
        run(&["inspect", "--input-format", "bogus", "x"])
            .status
            .code(),
        Some(2)
    );
    assert_eq!(
        run(&["inspect", "--skip-seconds", "-1", "x"]).status.code(),
        Some(2)
    );
    assert_eq!(run(&["frobnicate"]).status.code(), Some(2));
}

/// The shared BVH skeletons (CMU, Mixamo, Poser-named CMU, pymo) with every joint renamed `j1`,
/// `j2`, …: `inspect` finds the same body parts by shape alone as by their names.
#[test]
fn a_skeleton_stripped_of_names_resolves_by_shape_as_by_names() {
    let dir = tempfile::tempdir().unwrap();
    for file in [
        "bvh/cmu_01_01.bvh",
        "bvh/mixamo_rig_freebvh.bvh",
        "bvh/cmu_03_02_uneven_terrain.bvh",
        "bvh/pymo_walk.bvh",
    ] {
        let Some(path) = common::shared(file) else {
            return;
        };
        let text = std::fs::read_to_string(&path).unwrap();
        let (mut names, mut stripped, mut n) = (Vec::new(), String::new(), 0);
        for line in text.split_inclusive('\n') {
            let t = line.trim_start();
            match t.split_whitespace().collect::<Vec<_>>()[..] {
                [kw @ ("ROOT" | "JOINT"), name] => {
                    n += 1;
                    names.push(name.to_string());
                    let indent = &line[..line.len() - t.len()];
                    stripped.push_str(&format!("{indent}{kw} j{n}\n"));
                }
                _ => stripped.push_str(line),
            }
        }
        let renamed = dir.path().join(path.file_name().unwrap());
        std::fs::write(&renamed, stripped).unwrap();
        let parts = |p: &Path| inspect_json(p)["parts"].clone();
        let (named, shaped) = (parts(&path), parts(&renamed));
        for (part, v) in named.as_object().unwrap() {
            let by_name: Vec<&str> = v["joints"]
                .as_array()
                .unwrap()
                .iter()
                .map(|j| j.as_str().unwrap())
                .collect();
            let by_shape: Vec<&str> = shaped[part]["joints"]
                .as_array()
                .unwrap()
                .iter()
                .map(|j| names[j.as_str().unwrap()[1..].parse::<usize>().unwrap() - 1].as_str())
                .collect();
            assert_eq!(by_shape, by_name, "{file}: {part}");
        }
    }
}
