//! Real suits' BVH exports, fetched from public repositories (never copied into this one:
//! `common::mirror` reads them from the fetched snapshots and skips with a message where one is
//! absent): each retargeted onto the built-in Mixamo rig, every body part both
//! skeletons have turns in the world as its source joint did, within 2°, by an independent
//! forward kinematics of both files (`tests/real_exports/turns.py`, scipy's rotations); and no
//! part is left out (the gap issue 45 found: mocopi's pelvis and spine, MVN's joint-named arms
//! and legs, SlimeVR's `Left-Hip` thighs, all matched by no name before).

use crate::common;

use std::process::Command;

/// (suit, repository, commit, path in it, its licence, output rate = the source's).
const EXPORTS: &[(&str, &str, &str, &str, &str, &str)] = &[
    (
        "Sony mocopi",
        "SatooRu65536/mcp_persor",
        "f1cb313e884ed4f167556dc988cbc9c3ea9302f9",
        "bvh/jump.bvh",
        "MIT",
        "60",
    ),
    (
        "Sony mocopi",
        "SatooRu65536/mcp_persor",
        "f1cb313e884ed4f167556dc988cbc9c3ea9302f9",
        "bvh/chair.bvh",
        "MIT",
        "60",
    ),
    (
        "Xsens MVN (joint-named BVH)",
        "AnyBody/ammr",
        "ef387217a8c69ed97b237d6cd6eec92c77049b9f",
        "Application/MocapExamples/BVH_Xsens/BVH-files/S01_Trial02.bvh",
        "AnyBody AMMR licence (read only, not redistributed)",
        "240",
    ),
    (
        "Xsens MVN (joint-named BVH, a prop joint)",
        "AnyBody/ammr",
        "ef387217a8c69ed97b237d6cd6eec92c77049b9f",
        "Application/MocapExamples/BVH_BoxLift/BVH-files/S01_T01.bvh",
        "AnyBody AMMR licence (read only, not redistributed)",
        "60",
    ),
    (
        "Perception Neuron (Axis Neuron)",
        "AnyBody/ammr",
        "50c516f85e8082f47a3a2e6a24688884fd6c6d57",
        "Application/MocapExamples/BVH_NeuronMoCap/BVH-files/Sit-Stand3_chr00.bvh",
        "AnyBody AMMR licence (read only, not redistributed)",
        "100",
    ),
    (
        "Rokoko Studio (from video, Mixamo preset; bones along +X at rest)",
        "facebookresearch/AnimatedDrawings",
        "74ee7f0039adab0c6c6ebfcb2f9bac9c218e6747",
        "examples/bvh/rokoko/jesse_dance.bvh",
        "MIT",
        "100",
    ),
    (
        "SlimeVR server recording (2022 names, hung from the head)",
        "SlimeVR/SlimeVR-Server",
        "52fa6702936474ea1e6796942aef2fd0b0c65685",
        "BVH Recordings/BVH-Recording3.bvh",
        "MIT or Apache-2.0",
        "100",
    ),
];

/// The parts every one of these skeletons has (SlimeVR's recordings have legs and a spine only).
const LEGS: [&str; 7] = [
    "pelvis",
    "spine",
    "left_thigh",
    "left_shank",
    "left_foot",
    "right_thigh",
    "right_shank",
];

/// The body parts of `path`, also written to `into` for the Python check.
fn parts_into(path: &std::path::Path, into: &std::path::Path) -> serde_json::Value {
    let parts = common::inspect_json(path);
    std::fs::write(into, serde_json::to_vec(&parts).unwrap()).unwrap();
    parts
}

#[test]
fn real_exports_retarget_onto_mixamo_part_by_part_within_2_degrees() {
    let Some(python) = common::python() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut checked = 0;
    for (i, &(suit, repo, commit, path, licence, fps)) in EXPORTS.iter().enumerate() {
        let Some(bytes) = common::mirror::fetched(repo, commit, path) else {
            continue;
        };
        let src = dir.path().join(format!("export{i}.bvh"));
        std::fs::write(&src, bytes).unwrap();
        let what = format!("{suit}: {repo}@{commit}:{path} ({licence})");
        let out = dir.path().join(format!("out{i}"));
        let run = Command::new(common::imubake_bin())
            .arg("convert")
            .arg(&src)
            .args(["--rig", "mixamo", "--fps", fps, "--format", "bvh", "--out"])
            .arg(&out)
            .args(["--bvh-reference", "rest"])
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{what}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(
            !stderr.contains("not driven") && !stderr.contains("is no body part"),
            "{what}: a part left out: {stderr}"
        );
        let source_parts = parts_into(&src, &dir.path().join(format!("s{i}.json")));
        parts_into(
            &common::repo_file("rigs/mixamo.yaml"),
            &dir.path().join("mixamo.json"),
        );
        for part in LEGS {
            assert!(
                !source_parts["parts"][part]["joints"]
                    .as_array()
                    .unwrap()
                    .is_empty(),
                "{what}: no {part} found: {source_parts}"
            );
        }
        let output = out.join(format!("export{i}.bvh"));
        let turns = Command::new(&python)
            .arg(common::repo_file("tests/real_exports/turns.py"))
            .arg(&src)
            .arg(&output)
            .arg(dir.path().join(format!("s{i}.json")))
            .arg(dir.path().join("mixamo.json"))
            .arg("1")
            .output()
            .unwrap();
        assert!(
            turns.status.success(),
            "{what}: {}",
            String::from_utf8_lossy(&turns.stderr)
        );
        let turns: serde_json::Value = serde_json::from_slice(&turns.stdout).unwrap();
        let turns = turns.as_object().unwrap();
        for part in LEGS {
            assert!(
                turns.contains_key(part),
                "{what}: {part} not compared: {turns:?}"
            );
        }
        let mut worst = (String::new(), 0.0f64);
        for (part, deg) in turns {
            let deg = deg.as_f64().unwrap();
            assert!(deg <= 2.0, "{what}: the {part} is {deg:.2}° off its source");
            if deg >= worst.1 {
                worst = (part.clone(), deg);
            }
        }
        eprintln!(
            "{what}: {} parts, the largest difference {:.4}° ({})",
            turns.len(),
            worst.1,
            worst.0
        );
        // By default (`match:0`): each bone aimed as its source joint is in frame 0, then turning
        // as it does — the numpy check of that, and of the bones pointing as their joints do.
        let matched = dir.path().join(format!("matched{i}"));
        common::run(
            Command::new(common::imubake_bin())
                .arg("convert")
                .arg(&src)
                .args(["--rig", "mixamo", "--fps", fps, "--format", "bvh", "--out"])
                .arg(&matched),
        );
        let sidecar: serde_json::Value = serde_json::from_slice(
            &std::fs::read(matched.join(format!("export{i}.imubake.json"))).unwrap(),
        )
        .unwrap();
        let pairs: Vec<[String; 2]> = common::sidecar_pairs(&sidecar)
            .into_iter()
            .map(|(s, b)| [s, b])
            .collect();
        let pairs_file = dir.path().join(format!("pairs{i}.json"));
        std::fs::write(&pairs_file, serde_json::to_vec(&pairs).unwrap()).unwrap();
        let check = common::run(
            Command::new(&python)
                .arg(common::repo_file("tests/python/retarget_check.py"))
                .arg(&src)
                .arg(matched.join(format!("export{i}.bvh")))
                .arg(&pairs_file)
                .args(["1", "match:0"]),
        );
        let check: serde_json::Value = serde_json::from_slice(&check.stdout).unwrap();
        let (turn, aim) = (
            check["worst_deg"].as_f64().unwrap(),
            check["worst_aim_deg"].as_f64().unwrap(),
        );
        // Position channels below the root (Axis Neuron's) let the bones change length, and a
        // bone's direction to its child then moves within its joint's frame: 3.2° measured.
        let stretches = std::fs::read_to_string(&src)
            .unwrap()
            .matches("CHANNELS 6")
            .count()
            > 1;
        let aim_bound = if stretches { 5.0 } else { 0.01 };
        eprintln!("{what}, matched: worst bone {turn:.2e}°, aims {aim:.2e}°");
        assert!(turn < 0.5 && aim < aim_bound, "{what}, matched: {check}");
        checked += 1;
    }
    eprintln!("{checked} of {} real exports checked", EXPORTS.len());
}
