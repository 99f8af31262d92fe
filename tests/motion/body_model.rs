//! The body model (issue 17): a subject file scales the rig.

use crate::common;

use common::{imubake_bin, repo_file};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};

/// The bundled walk onto mixamo scaled by `subject`, `--root root`, as BVH into `out`.
fn convert_walk(subject: &Path, root: &str, out: &Path) -> Output {
    Command::new(imubake_bin())
        .arg("convert")
        .arg(repo_file("samples/walk.csv"))
        .arg("--mapping")
        .arg(repo_file("mappings/paper000_16imu_mixamo.json"))
        .arg("--subject")
        .arg(subject)
        .args(["--format", "bvh", "--root", root, "--out"])
        .arg(out)
        .output()
        .unwrap()
}

/// `--subject` with `height_m` (and one segment): the written BVH's rest pose is the subject's
/// height (its hierarchy read back by `bvh_anim`, an independent parser), the thigh the given
/// length, and the sidecar records the file; a bad value is an error naming the key.
#[test]
fn a_subject_scales_the_rig() {
    let dir = tempfile::tempdir().unwrap();
    let subject = dir.path().join("subject.yaml");
    std::fs::write(&subject, "height_m: 1.6\nsegments:\n  LeftUpLeg: 0.4\n").unwrap();
    let convert = |out: &Path| convert_walk(&subject, "fixed", out);
    let out = dir.path().join("out");
    let run = convert(&out);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    // The written BVH read back by an independent numpy FK script: its rest extent and the
    // thigh (LeftUpLeg → LeftLeg, the same at every frame).
    let Some(py) = common::python() else {
        return;
    };
    let fk = Command::new(py)
        .arg(repo_file("tests/python/bvh_positions.py"))
        .arg(out.join("walk.bvh"))
        .arg("LeftUpLeg,LeftLeg")
        .output()
        .unwrap();
    assert!(
        fk.status.success(),
        "{}",
        String::from_utf8_lossy(&fk.stderr)
    );
    let fk: Value = serde_json::from_slice(&fk.stdout).unwrap();
    let (hip, knee) = (
        common::vec3(&fk["joints"]["LeftUpLeg"][10]),
        common::vec3(&fk["joints"]["LeftLeg"][10]),
    );
    let thigh = (knee - hip).norm();
    assert!((thigh - 0.4).abs() < 1e-5, "thigh {thigh}");
    let extent = fk["rest_highest"].as_f64().unwrap() - fk["rest_lowest"].as_f64().unwrap();
    // The height scales everything first; the thigh is then set, which moves the feet only.
    let sidecar: Value =
        serde_json::from_slice(&std::fs::read(out.join("walk.imubake.json")).unwrap()).unwrap();
    let record = &sidecar["rig"]["subject"];
    assert_eq!(record["height_m"], 1.6);
    assert_eq!(record["segments"]["LeftUpLeg"], 0.4);
    let standing = record["standing_height_m"].as_f64().unwrap();
    assert!((extent - standing).abs() < 1e-5, "{extent} vs {standing}");
    // The height scaled everything (1.6 m), then the left thigh was set: a longer one would lower
    // the lowest point, a shorter one leaves the right foot lowest.
    let mixamo = imubake::rig::load_rig("mixamo").unwrap();
    let mixamo_thigh = mixamo.joints()[mixamo.joint_index("LeftLeg").unwrap()]
        .offset
        .norm();
    let expected = 1.6 + (0.4 - mixamo_thigh * 1.6 / mixamo.standing_height()).max(0.0);
    assert!(
        (standing - expected).abs() < 1e-9,
        "{standing} vs {expected}"
    );
    assert_eq!(record["sha256"].as_str().unwrap().len(), 64);

    std::fs::write(&subject, "height_m: 0\n").unwrap();
    let bad = convert(&dir.path().join("bad"));
    let message = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success());
    assert!(
        message.contains("subject.yaml") && message.contains("`height_m`"),
        "{message}"
    );
}

/// The subject's height is the one the flights fall by (`contacts.subject_height_m`, issue 49):
/// the bundled walk, `--root feet`, onto mixamo scaled to 1.2 m (a child) and 1.9 m, is judged
/// at that height (the calibration pose's, within 0.02 m of the subject file's); scaled to 0.7 m,
/// no person's, at the assumed 1.75 m.
#[test]
fn a_subject_sets_the_flights_gravity() {
    let dir = tempfile::tempdir().unwrap();
    for (height_m, judged_m) in [(1.2, 1.2), (1.9, 1.9), (0.7, 1.75)] {
        let subject = dir.path().join(format!("subject_{height_m}.yaml"));
        std::fs::write(&subject, format!("height_m: {height_m}\n")).unwrap();
        let out = dir.path().join(format!("out_{height_m}"));
        let run = convert_walk(&subject, "feet", &out);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let sidecar: Value =
            serde_json::from_slice(&std::fs::read(out.join("walk.imubake.json")).unwrap()).unwrap();
        let said = sidecar["contacts"]["subject_height_m"].as_f64().unwrap();
        assert!(
            (said - judged_m).abs() < 0.02,
            "subject {height_m} m: flights judged at {said} m"
        );
    }
}
