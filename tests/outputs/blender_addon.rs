//! The Blender add-on's test suite (tests/blender_addon/*.py) inside real Blender: bpy 5.0.1 (the
//! test venv) and bpy 4.2 LTS (a second venv, since 4.2's animation API differs). This driver
//! makes the sample takes with the imubake binary (samples/walk.csv at 24, 29.97, 60 and 120 fps,
//! BVH + GLB + sidecar each), builds the extension zip with Blender's own extension tool
//! (scripts/build_blender_addon.py), and runs tests/blender_addon/run.py, which installs the zip
//! into a temporary BLENDER_USER_RESOURCES. Skips locally when a venv or ../shared/data is
//! missing; fails under CI=true.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

/// Makes the sample takes: `walk_24`, `walk_2997`, `walk_60`, `walk_120` on the mixamo rig, and
/// `sou_wave` (paper 002's SOU log) on the sou12 rig.
fn make_takes(dir: &Path) {
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    // The bundled walk at four rates, once with its walk on a `root` joint (`--in-place`), once
    // with the rest pose as frame 0 (`--bind-frame`).
    for (stem, fps, extra) in [
        ("walk_24", "24", None),
        ("walk_2997", "29.97", None),
        ("walk_60", "60", None),
        ("walk_120", "120", None),
        ("walk_inplace", "30", Some("--in-place")),
        ("walk_bind", "30", Some("--bind-frame")),
    ] {
        let csv = input.join(format!("{stem}.csv"));
        std::fs::copy(common::repo_file("samples/walk.csv"), &csv).unwrap();
        let out = Command::new(common::imubake_bin())
            .args(["convert", "--fps", fps, "--format", "bvh,glb", "--mapping"])
            .arg(common::repo_file("mappings/paper000_16imu_mixamo.json"))
            .args(extra)
            .arg("--out")
            .arg(dir.join("takes"))
            .arg(&csv)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "convert {stem}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let out = Command::new(common::imubake_bin())
        .args(["convert", "--fps", "30", "--format", "bvh", "--mapping"])
        .arg(common::repo_file("mappings/paper002_sou12.json"))
        .arg("--out")
        .arg(dir.join("takes"))
        .arg(common::repo_file("samples/sou_wave.log"))
        .output()
        .unwrap();
    assert!(out.status.success(), "convert sou_wave: {out:?}");
}

fn build_zip(python: &Path, dir: &Path) -> PathBuf {
    let out = Command::new(python)
        .arg(common::repo_file("scripts/build_blender_addon.py"))
        .arg(dir.join("dist"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "building the extension: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    PathBuf::from(String::from_utf8(out.stdout).unwrap().trim())
}

fn run_suite(python: Option<PathBuf>) {
    let Some(python) = python else { return };
    let Some(shared) = common::shared_data() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    make_takes(dir.path());
    let zip = build_zip(&python, dir.path());
    let out = Command::new(&python)
        .arg(common::repo_file("tests/blender_addon/run.py"))
        .arg(&zip)
        .arg(dir.path().join("takes"))
        .env("IMUBAKE_SHARED_DATA", &shared)
        .env("IMUBAKE_BIN", common::imubake_bin())
        .env("IMUBAKE_REPO", common::repo_file(""))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    // unittest's report goes to stdout; Blender's own chatter to both.
    println!("{stdout}");
    assert!(
        out.status.success(),
        "add-on tests failed in {}:\n{stdout}\n{stderr}",
        python.display()
    );
    assert!(
        stdout.contains("\nOK") && !stdout.contains("skipped"),
        "the suite did not run cleanly:\n{stdout}"
    );
}

#[test]
fn addon_suite_in_blender_5_0() {
    run_suite(common::python());
}

#[test]
fn addon_suite_in_blender_4_2() {
    run_suite(common::python_blender42());
}
