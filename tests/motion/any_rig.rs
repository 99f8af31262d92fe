//! Any rig (issue 47): a rig and its bone-along-X twin (`common::twin`) are the same body, so a
//! capture converted onto either gives the same joint positions at every frame, in every root
//! mode, and the same joint angles — calibration, the heading, the floor, the standing height,
//! the feet's contacts and the segments' frames all read the calibration pose, never the rig's
//! zero pose. The capture is `simulate`d from CMU
//! 01_01 (real optical motion) with unknown mounts calibrated in the take's first frame.

use crate::common;

use common::{imubake_bin, run, shared, twin};
use nalgebra::{UnitQuaternion, Vector3};
use std::path::Path;
use std::process::Command;

/// The source frames simulated: 5 s of the walk.
const FRAMES: std::ops::Range<usize> = 0..600;

const MAPPING: &str = r#"{
  "calibration": {"pose": "frame:0", "start_s": 0.0, "duration_s": 1.0},
  "sensors": {
    "pelvis": {"bone": "Hips", "mount": "calibrate", "forward": "+z"},
    "chest": {"bone": "Spine1", "mount": "calibrate"},
    "head": {"bone": "Head", "mount": "calibrate"},
    "l_upper_arm": {"bone": "LeftArm", "mount": "calibrate"},
    "l_forearm": {"bone": "LeftForeArm", "mount": "calibrate"},
    "r_upper_arm": {"bone": "RightArm", "mount": "calibrate"},
    "r_forearm": {"bone": "RightForeArm", "mount": "calibrate"},
    "l_thigh": {"bone": "LeftUpLeg", "mount": "calibrate"},
    "l_shank": {"bone": "LeftLeg", "mount": "calibrate"},
    "l_foot": {"bone": "LeftFoot", "mount": "calibrate"},
    "r_thigh": {"bone": "RightUpLeg", "mount": "calibrate"},
    "r_shank": {"bone": "RightLeg", "mount": "calibrate"},
    "r_foot": {"bone": "RightFoot", "mount": "calibrate"}
  }
}"#;

/// Every joint's position at every frame of a BVH, and the standing height of its first frame.
fn positions(path: &Path) -> (Vec<Vec<Vector3<f64>>>, f64) {
    let bvh = imubake::bvh::parse(&std::fs::read(path).unwrap()).unwrap();
    let all: Vec<_> = (0..bvh.frame_count())
        .map(|n| bvh.world_positions(n))
        .collect();
    let ys = all[0].iter().map(|p| p.y);
    let h = ys.clone().fold(f64::MIN, f64::max) - ys.fold(f64::MAX, f64::min);
    (all, h)
}

/// Two `angles --json` outputs name the same angles (at least 20) and agree within 10⁻³° at
/// every frame (`what` names the second's source in a failure).
fn same_angles(a: &serde_json::Value, b: &serde_json::Value, what: &Path) {
    let (a, b) = (
        a["angles"].as_object().unwrap(),
        b["angles"].as_object().unwrap(),
    );
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    assert!(a.len() >= 20, "{} angles", a.len());
    for (name, series) in a {
        for (x, y) in series
            .as_array()
            .unwrap()
            .iter()
            .zip(b[name].as_array().unwrap())
        {
            let (Some(x), Some(y)) = (x.as_f64(), y.as_f64()) else {
                assert_eq!(x.is_null(), y.is_null(), "{name}");
                continue;
            };
            let d = ((x - y + 180.0).rem_euclid(360.0) - 180.0).abs();
            assert!(
                d < 1e-3,
                "angles on {}: {name} {x}° vs {y}°",
                what.display()
            );
        }
    }
}

#[test]
fn the_twin_maker_keeps_every_joint_in_place_and_lays_the_zero_pose_down() {
    let Some(src) = shared("bvh/cmu_01_01.bvh") else {
        return;
    };
    let bvh = imubake::bvh::parse(&std::fs::read(&src).unwrap()).unwrap();
    let twin = imubake::bvh::parse(twin::bone_along_x(&bvh, Some(FRAMES)).as_bytes()).unwrap();
    for n in [0, 137, 599] {
        let (a, b) = (bvh.world_positions(n), twin.world_positions(n));
        for (p, q) in a.iter().zip(&b) {
            assert!((p - q).norm() < 1e-6, "frame {n}: {p} vs {q}");
        }
    }
    // Its zero pose: the left shank's bone lies along its own +X, so the leg does not hang down.
    let shin = twin.joint_index("LeftLeg").unwrap();
    let foot = twin.joint_index("LeftFoot").unwrap();
    let offset = twin.joints()[foot].offset;
    assert!(offset.y.abs() < 1e-9 && offset.z.abs() < 1e-9 && offset.x > 0.0);
    let rest: Vec<UnitQuaternion<f64>> = vec![UnitQuaternion::identity(); twin.joints().len()];
    let translations: Vec<_> = twin.joints().iter().map(|j| j.offset).collect();
    let (zero, _) = twin.forward_kinematics(&rest, &translations);
    let down = zero[foot] - zero[shin];
    assert!(
        -down.y < 0.5 * down.norm(),
        "the twin's zero pose stands: {down}"
    );
}

#[test]
fn a_rig_and_its_bone_along_x_twin_give_the_same_joint_positions() {
    let Some(src) = shared("bvh/cmu_01_01.bvh") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let bvh = imubake::bvh::parse(&std::fs::read(&src).unwrap()).unwrap();
    let original = dir.path().join("cmu.bvh");
    let mine = dir.path().join("cmu_twin.bvh");
    std::fs::copy(&src, &original).unwrap();
    std::fs::write(&mine, twin::bone_along_x(&bvh, None)).unwrap();
    let mapping = dir.path().join("mapping.json");
    std::fs::write(&mapping, MAPPING).unwrap();
    let capture = dir.path().join("take.csv");
    run(Command::new(imubake_bin())
        .arg("simulate")
        .arg(&src)
        .arg("--rig")
        .arg(&original)
        .arg("--mapping")
        .arg(&mapping)
        .arg("--output")
        .arg(&capture)
        .args(["--frames", &format!("{}:{}", FRAMES.start, FRAMES.end - 1)])
        .args(["--seed", "47", "--hold-s", "1.5"]));
    // The twin made here, and the one shipped with the shared data (made by another hand).
    let mut rigs = vec![original.clone(), mine];
    if let Some(theirs) = shared("bvh/cmu_01_01_boneaxis_x.bvh") {
        rigs.push(theirs);
    }
    // `angles`: the same joint angles on every rig, the segments' frames read in the
    // calibration pose (frame 0) and carried by their bones.
    let angles: Vec<serde_json::Value> = rigs
        .iter()
        .map(|rig| {
            let out = run(Command::new(imubake_bin())
                .arg("angles")
                .arg(&capture)
                .arg("--mapping")
                .arg(&mapping)
                .arg("--rig")
                .arg(rig)
                .args(["--fps", "60", "--json"]));
            serde_json::from_slice(&out.stdout).unwrap()
        })
        .collect();
    for (k, other) in angles.iter().enumerate().skip(1) {
        same_angles(&angles[0], other, &rigs[k]);
    }
    // Offline, and through the stream's incremental cores as `live` runs them (`--causal`); and
    // scaled to a subject a quarter taller (CMU's BVH read as a rig, in centimetres, stands
    // 0.266 m tall: 0.3325 m) with the root moved to the floor (`--in-place`): the height and the
    // floor are the calibration pose's, so the scaled rigs stand that tall in it (the sidecar's
    // `standing_height_m`) and their root joints stand on one floor.
    let subject = dir.path().join("subject.yaml");
    std::fs::write(&subject, "height_m: 0.3325\n").unwrap();
    let scaled = ["--in-place", "--subject", subject.to_str().unwrap()];
    for (root, flags) in [
        ("fixed", &[][..]),
        ("ground", &[]),
        ("feet", &[]),
        ("feet", &["--causal"]),
        ("ground", &["--causal"]),
        ("feet", &scaled),
    ] {
        let mut outs = Vec::new();
        for (k, rig) in rigs.iter().enumerate() {
            let out = dir.path().join(format!("{root}_{}_{k}", flags.len()));
            run(Command::new(imubake_bin())
                .arg("convert")
                .arg(&capture)
                .arg("--mapping")
                .arg(&mapping)
                .arg("--rig")
                .arg(rig)
                .args(["--root", root, "--fps", "60", "--format", "bvh", "--out"])
                .arg(&out)
                .args(flags));
            let sidecar: serde_json::Value =
                serde_json::from_slice(&std::fs::read(out.join("take.imubake.json")).unwrap())
                    .unwrap();
            assert_eq!(sidecar["pipeline"]["heading"], "declared-forward");
            if flags == scaled {
                let h = sidecar["rig"]["subject"]["standing_height_m"]
                    .as_f64()
                    .unwrap();
                assert!((h - 0.3325).abs() < 1e-9, "{}: {h} m", rig.display());
            }
            outs.push(positions(&out.join("take.bvh")));
        }
        let (reference, h) = &outs[0];
        for (k, (other, _)) in outs.iter().enumerate().skip(1) {
            assert_eq!(reference.len(), other.len());
            let worst = reference
                .iter()
                .zip(other)
                .flat_map(|(a, b)| a.iter().zip(b).map(|(p, q)| (p - q).norm()))
                .fold(0.0, f64::max);
            assert!(
                worst / h < 1e-4,
                "--root {root} {flags:?}, rig {}: a joint {:.2e} h away from the original rig's",
                rigs[k].display(),
                worst / h
            );
        }
    }
}

/// A BVH take and its bone-along-X twins (ours and the shared one) have the same joint angles
/// (`angles`), and retargeted onto mixamo with the default reference (`match:0`) give one output: every channel within 1e-4 (degrees, and
/// the hips' centimetres), so the same joint positions; and no joint of any shared BVH's take
/// goes more than 0.02 h below the floor. With `--bvh-reference rest` the twin's zero pose
/// (limbs along +X) is taken for a standing pose: its output is another (asserted, so that the
/// default is what makes them one).
#[test]
fn a_bvh_take_and_its_bone_along_x_twin_retarget_to_one_output() {
    let Some(src) = shared("bvh/cmu_01_01.bvh") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let bvh = imubake::bvh::parse(&std::fs::read(&src).unwrap()).unwrap();
    let mine = dir.path().join("cmu_01_01_twin.bvh");
    std::fs::write(&mine, twin::bone_along_x(&bvh, None)).unwrap();
    let mut takes = vec![src.clone(), mine];
    takes.extend(shared("bvh/cmu_01_01_boneaxis_x.bvh"));
    let convert = |take: &Path, reference: &[&str]| {
        let out = dir.path().join(format!(
            "{}{}",
            take.file_stem().unwrap().to_string_lossy(),
            reference.len()
        ));
        run(Command::new(imubake_bin())
            .arg("convert")
            .arg(take)
            .args(["--rig", "mixamo", "--format", "bvh", "--out"])
            .arg(&out)
            .args(reference));
        let stem = take.file_stem().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(out.join(format!("{stem}.bvh"))).unwrap();
        let motion: Vec<Vec<f64>> = text
            .split("MOTION")
            .nth(1)
            .unwrap()
            .lines()
            .skip(3)
            .filter(|l| !l.trim().is_empty())
            .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
            .collect();
        (motion, out.join(format!("{stem}.bvh")))
    };
    let largest = |a: &[Vec<f64>], b: &[Vec<f64>]| {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p - q).abs()))
            .fold(0.0, f64::max)
    };
    // `angles` on the take itself: the segments' frames read in frame 0's pose, as retargeting
    // reads it, so every twin measures the same angles.
    let angles = |take: &Path| -> serde_json::Value {
        serde_json::from_slice(
            &run(Command::new(imubake_bin())
                .arg("angles")
                .arg(take)
                .arg("--json"))
            .stdout,
        )
        .unwrap()
    };
    let mine_angles = angles(&src);
    for take in &takes[1..] {
        same_angles(&mine_angles, &angles(take), take);
    }
    let (original, path) = convert(&src, &[]);
    let (all, h) = positions(&path);
    let floor = all[0].iter().map(|p| p.y).fold(f64::MAX, f64::min);
    assert!(all.len() > 600);
    for take in &takes[1..] {
        let (other, _) = convert(take, &[]);
        let d = largest(&original, &other);
        assert!(d < 1e-4, "{}: a channel {d} away", take.display());
        let (rest, _) = convert(take, &["--bvh-reference", "rest"]);
        assert!(largest(&original, &rest) > 1.0, "{}", take.display());
    }
    // The floor: the rig's rest pose's lowest point, which every frame keeps above.
    let lowest = all.iter().flatten().map(|p| p.y).fold(f64::MAX, f64::min);
    assert!(lowest > floor - 0.02 * h, "{lowest} vs floor {floor}");
    for name in [
        "pymo_walk",
        "cmu_03_02_uneven_terrain",
        "mixamo_rig_freebvh",
        "mocapbank_crlf",
    ] {
        let Some(take) = shared(&format!("bvh/{name}.bvh")) else {
            continue;
        };
        let (_, path) = convert(&take, &[]);
        let (all, h) = positions(&path);
        let lowest = all.iter().flatten().map(|p| p.y).fold(f64::MAX, f64::min);
        assert!(
            lowest > floor - 0.02 * h,
            "{name}: {lowest} vs floor {floor}"
        );
    }
}

/// With `calibrate` mounts and nothing that gives the heading (no `forward`, no known mount, no
/// second pose, no legs to walk on), a take is refused with an error naming the ways out — by
/// `convert`, and by `batch` and `watch` as a failed take with the same message — and
/// `--heading sensors` converts it as before, saying so in the sidecar.
#[test]
fn an_unknown_heading_is_refused_unless_the_sensors_north_is_kept() {
    let Some(src) = shared("bvh/cmu_01_01.bvh") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("cmu.bvh");
    std::fs::copy(&src, &rig).unwrap();
    let mapping = dir.path().join("upper.json");
    std::fs::write(
        &mapping,
        r#"{"calibration": {"pose": "frame:0", "start_s": 0.0, "duration_s": 1.0},
            "sensors": {"pelvis": {"bone": "Hips"}, "chest": {"bone": "Spine1"},
                        "l_arm": {"bone": "LeftArm"}, "r_arm": {"bone": "RightArm"}}}"#,
    )
    .unwrap();
    let inbox = dir.path().join("inbox");
    std::fs::create_dir(&inbox).unwrap();
    let capture = inbox.join("upper.csv");
    run(Command::new(imubake_bin())
        .arg("simulate")
        .arg(&src)
        .arg("--rig")
        .arg(&rig)
        .arg("--mapping")
        .arg(&mapping)
        .arg("--output")
        .arg(&capture)
        .args(["--frames", "0:300", "--seed", "5"]));
    let convert = |out: &str, extra: &[&str]| {
        Command::new(imubake_bin())
            .arg("convert")
            .arg(&capture)
            .arg("--mapping")
            .arg(&mapping)
            .arg("--rig")
            .arg(&rig)
            .arg("--out")
            .arg(dir.path().join(out))
            .args(extra)
            .output()
            .unwrap()
    };
    let refused = convert("refused", &[]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{stderr}");
    for part in [
        "heading is unknown",
        "declare `forward`",
        "calibration.second",
        "--heading sensors",
    ] {
        assert!(stderr.contains(part), "{part}: {stderr}");
    }
    assert!(!dir.path().join("refused/upper.bvh").exists());
    let kept = convert("kept", &["--heading", "sensors"]);
    assert!(kept.status.success());
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("kept/upper.imubake.json")).unwrap())
            .unwrap();
    assert_eq!(sidecar["pipeline"]["heading"], "none");
    assert_eq!(sidecar["pipeline"]["heading_policy"], "sensors");
    assert!(sidecar["pipeline"]["heading_uncertainty_deg"].is_null());
    for command in ["batch", "watch"] {
        let out = dir.path().join(command);
        let mut cmd = Command::new(imubake_bin());
        cmd.arg(command)
            .arg(&inbox)
            .arg("--out")
            .arg(&out)
            .arg("--mapping")
            .arg(&mapping)
            .arg("--rig")
            .arg(&rig);
        if command == "watch" {
            cmd.arg("--once");
        }
        let _ = cmd.output().unwrap();
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("upper.error.json")).unwrap())
                .unwrap_or_else(|e| panic!("{command}: {e}"));
        let reason = report["reason"].as_str().unwrap();
        assert!(
            reason.contains("heading is unknown") && reason.contains("--heading sensors"),
            "{command}: {reason}"
        );
        assert!(!out.join("upper.bvh").exists());
    }
}
