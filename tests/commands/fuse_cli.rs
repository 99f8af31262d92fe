//! `imubake fuse` and `convert` on raw readings, as a user reads them: which algorithm fused each
//! sensor, what it found, the error it expects of itself and the warning above 2° (issue 51).
//! The readings are simulated from the shared pymo walk (`simulate --raw`).

use crate::common;

use common::{imubake_bin, run, shared};
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// `simulate --raw` of the shared pymo walk's 16 sensors at 100 Hz into `dir/name` (`args`: the
/// frames, the pose, the jitter).
fn simulate_raw(dir: &Path, name: &str, args: &[&str]) -> Option<std::path::PathBuf> {
    let bvh = shared("bvh/pymo_walk.bvh")?;
    let raw = dir.join(name);
    run(Command::new(imubake_bin())
        .arg("simulate")
        .arg(&bvh)
        .arg("--mapping")
        .arg(common::fixture("mappings/pymo_16imu.json"))
        .args(["--rate", "100", "--raw"])
        .args(args)
        .arg("--output")
        .arg(&raw));
    Some(raw)
}

/// 16 sensors of the pymo walk's first 5 s after a 1 s pose, 100 Hz, with `jitter_ms` of
/// timing jitter.
fn raw_take(dir: &Path, jitter_ms: f64) -> Option<std::path::PathBuf> {
    let jitter = jitter_ms.to_string();
    simulate_raw(
        dir,
        &format!("raw_{jitter_ms}.csv"),
        &[
            "--frames",
            "0:599",
            "--hold-s",
            "1",
            "--seed",
            "1",
            "--jitter-ms",
            &jitter,
        ],
    )
}

fn fuse_json(raw: &Path, fusion: &str, dir: &Path) -> (Value, String) {
    let out = run(Command::new(imubake_bin())
        .arg("fuse")
        .arg(raw)
        .arg("-o")
        .arg(dir.join("fused.csv"))
        .args(["--fusion", fusion, "--json"]));
    (
        serde_json::from_slice(&out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

/// `fuse` names the algorithm per sensor (JSON and one line each on stderr); the offline
/// fusion gives the rest it found (the 1 s pose), no disturbed seconds (the field is clean) and
/// an expected error, and warns of exactly the sensors whose expected error passes 2° — none on
/// evenly spaced samples, those it says on samples 4 ms off their period; online VQF has no
/// estimate.
#[test]
fn fuse_names_the_algorithm_and_its_expected_error_per_sensor() {
    let dir = tempfile::tempdir().unwrap();
    let (Some(even), Some(jittered)) = (raw_take(dir.path(), 0.0), raw_take(dir.path(), 4.0))
    else {
        return;
    };
    for raw in [&even, &jittered] {
        let (json, stderr) = fuse_json(raw, "offline", dir.path());
        let sensors = json["sensors"].as_object().unwrap();
        assert_eq!(sensors.len(), 16);
        for (id, s) in sensors {
            assert_eq!(s["algorithm"], "offline", "{id}");
            assert_eq!(s["variant"], "9d", "{id}");
            let rest = s["rest_s"].as_f64().unwrap();
            assert!((0.8..=1.2).contains(&rest), "{id}: rest {rest} s");
            assert_eq!(s["disturbed_s"], serde_json::json!(0.0), "{id}");
            assert!(!s["disturbed_s"].to_string().starts_with('-'), "{id}");
            let expected = s["expected_error_deg"].as_f64().unwrap();
            assert!(expected > 0.0 && expected.is_finite(), "{id}: {expected}");
            let warned = stderr.contains(&format!("sensor `{id}`: the offline fusion expects"));
            assert_eq!(warned, expected > 2.0, "{id}: {expected}° — {stderr}");
            if raw == &even {
                assert!(expected < 2.0, "{id}: {expected}°");
            }
        }
        let (vqf, _) = fuse_json(raw, "vqf", dir.path());
        for (id, s) in vqf["sensors"].as_object().unwrap() {
            assert_eq!(s["algorithm"], "vqf", "{id}");
            assert!(s.get("expected_error_deg").is_none(), "{id}");
        }
    }
    // Without --json, one line per sensor on stderr.
    let out = run(Command::new(imubake_bin())
        .arg("fuse")
        .arg(&even)
        .arg("-o")
        .arg(dir.path().join("fused.csv")));
    let stderr = String::from_utf8(out.stderr).unwrap();
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("offline 9d, rest "))
        .collect();
    assert_eq!(lines.len(), 16, "{stderr}");
    assert!(
        lines.iter().all(|l| l.contains("°/s, expected error ")),
        "{stderr}"
    );
}

/// A take that starts mid-walk (no pose, no rest anywhere) fuses: the unit check's "stillest"
/// samples of a swinging thigh read 1.5 g, which is no reason to call them g.
#[test]
fn a_take_that_never_rests_is_not_taken_for_the_wrong_units() {
    let dir = tempfile::tempdir().unwrap();
    let Some(raw) = simulate_raw(
        dir.path(),
        "walking.csv",
        &["--frames", "100:700", "--hold-s", "0", "--blend-s", "0"],
    ) else {
        return;
    };
    let (json, _) = fuse_json(&raw, "offline", dir.path());
    let sensors = json["sensors"].as_object().unwrap();
    assert_eq!(sensors.len(), 16);
    assert!(sensors.values().all(|s| s["rest_s"] == 0.0), "{json}");
}

/// `convert` says which algorithms fused how many sensors, and its sidecar has each sensor's.
#[test]
fn convert_says_which_algorithms_fused_the_take() {
    let dir = tempfile::tempdir().unwrap();
    let Some(raw) = raw_take(dir.path(), 0.0) else {
        return;
    };
    let out_dir = dir.path().join("out");
    let convert = |extra: &[&str]| {
        run(Command::new(imubake_bin())
            .arg("convert")
            .arg(&raw)
            .arg("--mapping")
            .arg(common::fixture("mappings/pymo_16imu.json"))
            .arg("-o")
            .arg(&out_dir)
            .args(["--format", "bvh"])
            .args(extra))
    };
    let sidecar: Value = serde_json::from_slice(&convert(&["--json"]).stdout).unwrap();
    let sidecar = if sidecar.is_array() {
        &sidecar[0]
    } else {
        &sidecar
    };
    let fusion = &sidecar["pipeline"]["fusion"];
    assert_eq!(fusion["method"], "offline");
    for (id, s) in fusion["sensors"].as_object().unwrap() {
        assert_eq!(s["algorithm"], "offline", "{id}");
        assert!(s["expected_error_deg"].as_f64().unwrap() < 2.0, "{id}");
    }
    let out = convert(&[]);
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.contains("; fused offline 9d ×16)"), "{stdout}");
}
