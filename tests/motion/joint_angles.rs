//! `imubake angles` and `imubake compare` (issue 17, paper 000's analysis): checked against an
//! independent numpy/scipy implementation on real BVH motion, against scipy's Pearson r, and in a
//! closed loop (a simulated capture's conversion compared with the motion it was simulated from).

use crate::common;

use common::{imubake_bin, python, repo_file, run, shared};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

/// A CSV table: header and columns.
pub(crate) fn read_table(path: &Path) -> BTreeMap<String, Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); header.len()];
    for line in lines {
        for (c, v) in cols.iter_mut().zip(line.split(',')) {
            c.push(v.parse().unwrap_or(f64::NAN));
        }
    }
    header.into_iter().zip(cols).collect()
}

/// Every angle of every frame of two real BVH files (CMU's 01_01 and pymo's walk: different
/// skeletons, rest poses and channel orders) as the checked-in numpy/scipy script computes them
/// from the same definitions (its own BVH parser and forward kinematics, scipy's Euler
/// decompositions): the same columns, within the CSV's rounding — the segments' frames read in
/// frame 0's pose (the default, as BVH takes retarget) and in the zero pose (`--bvh-reference
/// rest`).
#[test]
fn angles_match_an_independent_numpy_scipy_implementation() {
    let Some(py) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    // By default the segments' frames are read in frame 0's pose; `--bvh-reference rest` reads
    // them in the zero pose.
    for (name, reference) in [
        ("cmu_01_01", None),
        ("pymo_walk", None),
        ("cmu_01_01", Some("rest")),
        ("pymo_walk", Some("rest")),
    ] {
        let Some(bvh) = shared(&format!("bvh/{name}.bvh")) else {
            return;
        };
        let ours = dir.path().join(format!("{name}{reference:?}.csv"));
        let theirs = dir.path().join(format!("{name}{reference:?}.ref.csv"));
        run(Command::new(imubake_bin())
            .arg("angles")
            .arg(&bvh)
            .arg("--csv")
            .arg("-o")
            .arg(&ours)
            .args(reference.map(|r| ["--bvh-reference", r]).iter().flatten()));
        run(Command::new(&py)
            .arg(repo_file("tests/python/joint_angles.py"))
            .arg(&bvh)
            .arg(&theirs)
            .args(reference.is_none().then_some("0")));
        let (a, b) = (read_table(&ours), read_table(&theirs));
        assert_eq!(
            a.keys().collect::<Vec<_>>(),
            b.keys().collect::<Vec<_>>(),
            "{name}: the same angles"
        );
        assert_eq!(a.len(), 2 + 4 * 12, "{name}: all six joints on both sides");
        let mut worst = (0.0f64, String::new());
        for (col, ours) in &a {
            let theirs = &b[col];
            assert_eq!(ours.len(), theirs.len());
            for (x, y) in ours.iter().zip(theirs) {
                assert!(x.is_finite() && y.is_finite(), "{name} {col}: NaN");
                let d = (x - y) - 360.0 * ((x - y) / 360.0).round();
                if d.abs() > worst.0 {
                    worst = (d.abs(), col.clone());
                }
            }
        }
        eprintln!(
            "{name} ({reference:?}): largest difference {:.2e}° ({})",
            worst.0, worst.1
        );
        assert!(worst.0 < 2e-6, "{name}: {worst:?}");
        // Plausible motion, not only agreement: a walk bends the knees by tens of degrees.
        let knee = &a["left_knee_flexion"];
        let range = knee.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - knee.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(range > 40.0, "{name}: left knee flexion range {range:.1}°");
    }
}

/// Simulates a 16-sensor capture from CMU 01_01 onto its own skeleton (3 s of calibration pose
/// first), converts it, and compares the conversion with the source three ways: their `angles`
/// tables, the BVH files, and the capture itself (converted in memory). Cross-correlation finds
/// the 3 s the simulation put before the motion; knee and elbow flexion correlate at r ≥ 0.99
/// on both sides; and the RMSE and r of every angle are what numpy and `scipy.stats.pearsonr`
/// compute from the same tables at that lag.
#[test]
fn a_simulated_capture_compares_with_its_source() {
    let (Some(py), Some(bvh)) = (python(), shared("bvh/cmu_01_01.bvh")) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mapping = repo_file("tests/fixtures/mappings/cmu_16imu.json");
    run(Command::new(imubake_bin())
        .arg("simulate")
        .arg(&bvh)
        .arg("--mapping")
        .arg(&mapping)
        .arg("--rig")
        .arg(&bvh)
        .arg("--output")
        .arg(d.join("take.csv"))
        .arg("--truth")
        .arg(d.join("truth.json"))
        .args(["--noise-deg", "0.5", "--seed", "3"]));
    let truth: Value =
        serde_json::from_slice(&std::fs::read(d.join("truth.json")).unwrap()).unwrap();
    // The source's first frame is at the capture's motion_start_s.
    let expected_lag = truth["motion_start_s"].as_f64().unwrap()
        - truth["first_frame"].as_f64().unwrap() * truth["source_frame_time_s"].as_f64().unwrap();
    run(Command::new(imubake_bin())
        .arg("convert")
        .arg(d.join("take.csv"))
        .arg("--mapping")
        .arg(&mapping)
        .arg("--rig")
        .arg(&bvh)
        .args(["--fps", "60", "--format", "bvh", "--out"])
        .arg(d.join("out")));
    let converted = d.join("out/take.bvh");
    for (input, table) in [(&bvh, "source.csv"), (&converted, "converted.csv")] {
        run(Command::new(imubake_bin())
            .arg("angles")
            .arg(input)
            .arg("-o")
            .arg(d.join(table)));
    }
    let compare = |a: &Path, b: &Path, extra: &[&str]| -> Value {
        let out = run(Command::new(imubake_bin())
            .arg("compare")
            .arg(a)
            .arg(b)
            .arg("--json")
            .args(extra));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let stats = |c: &Value, angle: &str| -> (f64, f64) {
        let s = c["angles"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["angle"] == angle)
            .unwrap_or_else(|| panic!("{angle} missing"));
        (s["rmse_deg"].as_f64().unwrap(), s["r"].as_f64().unwrap())
    };
    let tables = compare(&d.join("source.csv"), &d.join("converted.csv"), &[]);
    let lag = tables["lag_s"].as_f64().unwrap();
    eprintln!(
        "lag {lag:.4} s (expected {expected_lag:.4} s) on {}",
        tables["sync_angle"]
    );
    assert!(
        (lag - expected_lag).abs() < 1.0 / 60.0,
        "lag {lag} vs {expected_lag}"
    );
    for angle in [
        "left_knee_flexion",
        "right_knee_flexion",
        "left_elbow_flexion",
        "right_elbow_flexion",
    ] {
        let (rmse, r) = stats(&tables, angle);
        eprintln!("{angle}: RMSE {rmse:.2}°, r {r:.4}");
        assert!(r >= 0.99, "{angle}: r {r}");
        assert!(rmse < 3.0, "{angle}: RMSE {rmse}");
    }
    // The BVH files directly give the same numbers as their tables (the tables round to 1e-6°).
    let direct = compare(&bvh, &converted, &[]);
    assert!((direct["lag_s"].as_f64().unwrap() - lag).abs() < 1e-3);
    let (rmse_t, r_t) = stats(&tables, "left_knee_flexion");
    let (rmse_d, r_d) = stats(&direct, "left_knee_flexion");
    assert!((rmse_t - rmse_d).abs() < 1e-3 && (r_t - r_d).abs() < 1e-5);
    // The capture itself, converted in memory by `compare` with the same settings (30 fps).
    let capture = compare(
        &bvh,
        &d.join("take.csv"),
        &[
            "--mapping",
            mapping.to_str().unwrap(),
            "--rig",
            bvh.to_str().unwrap(),
        ],
    );
    for angle in ["left_knee_flexion", "right_elbow_flexion"] {
        let (_, r) = stats(&capture, angle);
        assert!(r >= 0.99, "capture {angle}: r {r}");
    }
    // numpy and scipy at the lag imubake found, with and without the offset removed.
    for extra in [&[][..], &["--remove-offset"][..]] {
        let ours = compare(&d.join("source.csv"), &d.join("converted.csv"), extra);
        let lag = ours["lag_s"].as_f64().unwrap();
        let theirs: Value = serde_json::from_slice(
            &run(Command::new(&py)
                .arg(repo_file("tests/python/compare_reference.py"))
                .arg(d.join("source.csv"))
                .arg(d.join("converted.csv"))
                .arg(lag.to_string())
                .args(extra))
            .stdout,
        )
        .unwrap();
        let ours = ours["angles"].as_array().unwrap();
        assert_eq!(ours.len(), theirs.as_object().unwrap().len());
        for s in ours {
            let t = &theirs[s["angle"].as_str().unwrap()];
            assert_eq!(s["n"], t["n"], "{}", s["angle"]);
            for key in ["rmse_deg", "offset_deg"] {
                let (x, y) = (s[key].as_f64().unwrap(), t[key].as_f64().unwrap());
                assert!((x - y).abs() < 1e-9, "{} {key}: {x} vs {y}", s["angle"]);
            }
            match (s["r"].as_f64(), t["r"].as_f64()) {
                (Some(x), Some(y)) => assert!((x - y).abs() < 1e-9, "{}: r {x} vs {y}", s["angle"]),
                (x, y) => assert_eq!(x, y, "{}: r", s["angle"]),
            }
        }
    }
}

/// A table shifted by a known time: `compare` finds the shift with either sync, and the text
/// output is paper 000's Table 1 layout.
#[test]
fn compare_finds_a_known_shift_and_prints_table_1() {
    let Some(bvh) = shared("bvh/pymo_walk.bvh") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.csv");
    run(Command::new(imubake_bin())
        .arg("angles")
        .arg(&bvh)
        .arg("-o")
        .arg(&a));
    // b: the same angles 1.25 s later (the time column moved; the frame column dropped).
    let text = std::fs::read_to_string(&a).unwrap();
    let mut shifted = String::new();
    for (i, line) in text.lines().enumerate() {
        let (_, rest) = line.split_once(',').unwrap();
        if i == 0 {
            shifted.push_str(rest);
        } else {
            let (t, values) = rest.split_once(',').unwrap();
            let t: f64 = t.parse().unwrap();
            shifted.push_str(&format!("{:.6},{values}", t + 1.25));
        }
        shifted.push('\n');
    }
    let b = dir.path().join("b.csv");
    std::fs::write(&b, shifted).unwrap();
    for sync in ["xcorr", "spike"] {
        let out = run(Command::new(imubake_bin())
            .arg("compare")
            .arg(&a)
            .arg(&b)
            .args([
                "--sync",
                sync,
                "--sync-angle",
                "left_knee_flexion",
                "--json",
            ]));
        let c: Value = serde_json::from_slice(&out.stdout).unwrap();
        let lag = c["lag_s"].as_f64().unwrap();
        assert!((lag - 1.25).abs() < 1e-3, "{sync}: {lag}");
    }
    let out = run(Command::new(imubake_bin()).arg("compare").arg(&a).arg(&b));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("joint                left RMSE  left r right RMSE right r"),
        "{text}"
    );
    let knee = text
        .lines()
        .find(|l| l.starts_with("knee flexion"))
        .unwrap();
    let cells: Vec<&str> = knee.split_whitespace().collect();
    assert_eq!(cells[2..], ["0.00", "1.000", "0.00", "1.000"], "{knee}");
}

/// Bad inputs: clear errors naming the file and line, or the rig and what is missing.
#[test]
fn bad_inputs_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "frame,time_s,left_knee\n0,0.0,1\n1,0.0,2\n").unwrap();
    let out = Command::new(imubake_bin())
        .arg("compare")
        .arg(&bad)
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.csv: line 3: time 0 s is not after the previous row's"),
        "{err}"
    );
    let other = dir.path().join("other.csv");
    std::fs::write(&other, "time_s,right_elbow\n0,1\n1,2\n").unwrap();
    let good = dir.path().join("good.csv");
    std::fs::write(&good, "time_s,left_knee\n0,1\n1,2\n").unwrap();
    let out = Command::new(imubake_bin())
        .arg("compare")
        .arg(&good)
        .arg(&other)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("no angle appears in both"),
        "{err}"
    );
    // A skeleton without limbs.
    let stick = dir.path().join("stick.bvh");
    std::fs::write(
        &stick,
        "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 3 Zrotation Xrotation Yrotation\n JOINT b\n {\n  OFFSET 0 1 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0 0 0 0\n",
    )
    .unwrap();
    let out = Command::new(imubake_bin())
        .arg("angles")
        .arg(&stick)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains("cannot tell left from right")
            && err.contains("closest by name: left thigh: a, b"),
        "{err}"
    );
}
