//! Xsens MVN's MVNX files: read as PyPI's `mvnx` parser reads them, converted like the same
//! orientations in an imubake CSV, onto `mixamo` with the shipped mapping (full and upper body),
//! imported by Blender; damaged frames dropped with their line. The takes are written by
//! `tests/python/make_mvnx.py` from the bundled walk (real Xsens takes are held out).

use crate::common;

use common::{
    blender_import_bvh, gltf_validate, imubake_bin, node_modules, python, repo_file, run,
};
use imubake::convert::{ConvertSettings, Plan, animate};
use imubake::read::{ReadOptions, read_take};
use imubake::take::OrientationTrack;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The script's takes in a temporary folder: (folder, frames).
fn fixtures(py: &Path) -> (tempfile::TempDir, usize) {
    let dir = tempfile::tempdir().unwrap();
    let out = run(Command::new(py)
        .arg(repo_file("tests/python/make_mvnx.py"))
        .arg(repo_file("samples/walk.csv"))
        .arg(dir.path()));
    let frames = String::from_utf8(out.stdout)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    (dir, frames)
}

/// Every sensor's every sample equals what PyPI `mvnx` 0.2 reads from the same file (its
/// `sensorOrientation` rows, w first, in `<sensors>` order), at t = index / frameRate; the
/// calibration frames are not samples; the format and world are Xsens's.
#[test]
fn the_reader_agrees_with_pypi_mvnx() {
    let Some(py) = python() else { return };
    let (dir, frames) = fixtures(&py);
    let path = dir.path().join("walk.mvnx");
    let script = "import json, sys, mvnx\nm = mvnx.load(sys.argv[1])\n\
        json.dump({'sensors': m.sensors, 'rate': m.frameRate, \
        'q': m.sensorOrientation.tolist(), 'feet': m.footContacts.tolist()}, sys.stdout)";
    let out = run(Command::new(&py).args(["-c", script]).arg(&path));
    let reference: Value = serde_json::from_slice(&out.stdout).unwrap();
    let take = read_take(&path, &ReadOptions::default()).unwrap();
    assert_eq!(take.source().format.name(), "xsens-mvnx");
    assert_eq!(take.source().world.name(), "nwu");
    let sensors: Vec<&str> = take.sensors().iter().map(|s| s.id()).collect();
    assert_eq!(
        serde_json::json!(sensors),
        reference["sensors"],
        "sensors in <sensors> order"
    );
    assert_eq!(reference["rate"], "60");
    let rows = reference["q"].as_array().unwrap();
    assert_eq!(rows.len(), frames);
    let mut worst: f64 = 0.0;
    for (k, sensor) in take.sensors().iter().enumerate() {
        let Some(OrientationTrack::Quaternion(track)) = sensor.orientation() else {
            panic!("{}: no quaternions", sensor.id());
        };
        assert_eq!(track.len(), frames, "{}", sensor.id());
        for (n, (t, q)) in track.iter().enumerate() {
            assert!(
                (t - n as f64 / 60.0).abs() < 1e-12,
                "{} frame {n}: t = {t}",
                sensor.id()
            );
            let r: Vec<f64> = rows[n].as_array().unwrap()[4 * k..4 * k + 4]
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            let expected = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                r[0], r[1], r[2], r[3],
            ));
            worst = worst.max(q.angle_to(&expected));
        }
    }
    eprintln!(
        "{} sensors × {frames} frames, worst {worst:.2e} rad",
        take.sensors().len()
    );
    assert!(worst < 1e-9, "{worst} rad");
    // The vendor contacts: one per frame, a foot down when its heel or toe is.
    let feet = reference["feet"].as_array().unwrap();
    let contacts = take.vendor_contacts().expect("Xsens's foot contacts");
    assert_eq!(contacts.vendor, "xsens");
    assert_eq!(contacts.planted.len(), frames);
    for (n, f) in feet.iter().enumerate() {
        let f: Vec<f64> = f
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(
            contacts.planted[n],
            [f[0] + f[1] > 0.0, f[2] + f[3] > 0.0],
            "frame {n}"
        );
    }
}

/// The paper-000 mapping with the walk's sensor names turned into Xsens's, in MVN's world.
fn xsens_named_paper000(dir: &Path) -> PathBuf {
    let names = [
        ("pelvis", "Pelvis"),
        ("sternum", "T8"),
        ("right_shoulder_blade", "RightShoulder"),
        ("right_upper_arm", "RightUpperArm"),
        ("right_forearm", "RightForeArm"),
        ("right_hand", "RightHand"),
        ("left_shoulder_blade", "LeftShoulder"),
        ("left_upper_arm", "LeftUpperArm"),
        ("left_forearm", "LeftForeArm"),
        ("left_hand", "LeftHand"),
        ("right_thigh", "RightUpperLeg"),
        ("right_shank", "RightLowerLeg"),
        ("right_foot", "RightFoot"),
        ("left_thigh", "LeftUpperLeg"),
        ("left_shank", "LeftLowerLeg"),
        ("left_foot", "LeftFoot"),
    ];
    let mut mapping: Value = serde_json::from_slice(
        &std::fs::read(repo_file("mappings/paper000_16imu_mixamo.json")).unwrap(),
    )
    .unwrap();
    let sensors = mapping["sensors"].as_object().unwrap().clone();
    let renamed: serde_json::Map<String, Value> = sensors
        .into_iter()
        .map(|(k, v)| {
            let name = names.iter().find(|(a, _)| *a == k).unwrap().1;
            (name.to_string(), v)
        })
        .collect();
    mapping["sensors"] = Value::Object(renamed);
    mapping["world"] = "nwu".into();
    let path = dir.join("xsens_paper000.json");
    std::fs::write(&path, mapping.to_string()).unwrap();
    path
}

/// The MVNX take converts to the animation its imubake-CSV twin (the same orientations in ENU,
/// the walk's names) converts to: every joint of every frame within 1e-6°.
#[test]
fn an_mvnx_take_converts_like_its_csv_twin() {
    let Some(py) = python() else { return };
    let (dir, _) = fixtures(&py);
    let settings = |mapping: PathBuf| {
        Plan::resolve(ConvertSettings {
            mapping: Some(mapping),
            ..ConvertSettings::default()
        })
        .unwrap()
    };
    let mvnx = animate(
        &dir.path().join("walk.mvnx"),
        &settings(xsens_named_paper000(dir.path())),
    )
    .unwrap();
    let csv = animate(
        &dir.path().join("walk_twin.csv"),
        &settings(repo_file("mappings/paper000_16imu_mixamo.json")),
    )
    .unwrap();
    assert_eq!(mvnx.frames(), csv.frames());
    let mut worst: f64 = 0.0;
    for j in 0..mvnx.rig().len() {
        for (a, b) in mvnx.local(j).iter().zip(csv.local(j)) {
            worst = worst.max(a.angle_to(b).to_degrees());
        }
    }
    let roots = mvnx
        .root_positions()
        .iter()
        .zip(csv.root_positions())
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    eprintln!(
        "{} frames: worst joint {worst:.2e}°, root {roots:.2e} m",
        mvnx.frames()
    );
    assert!(worst < 1e-6, "{worst}°");
    assert!(roots < 1e-6, "{roots} m");
}

/// The shipped mapping onto `mixamo`: the full-body take (17 sensors) and the upper-body one
/// (11: the legs keep their rest rotation, with a warning each) convert; Blender imports the BVH
/// with mixamo's 22 bones; the GLB passes the validator; the sidecar keeps Xsens's foot contacts
/// beside ours, on the written frames (by hand: the left foot down on 60 Hz frames n with
/// ⌊n / 45⌋ even, so on 30 fps frames 0–22, 45–67, …); `inspect` summarises the take.
#[test]
fn the_shipped_mapping_converts_full_and_upper_body_takes() {
    let (Some(py), Some(modules)) = (python(), node_modules()) else {
        return;
    };
    let (dir, frames) = fixtures(&py);
    let out = dir.path().join("out");
    for (name, sensors) in [("walk", 17usize), ("walk_upper", 11)] {
        let convert = run(Command::new(imubake_bin()).args([
            "convert",
            dir.path().join(format!("{name}.mvnx")).to_str().unwrap(),
            "--mapping",
            repo_file("mappings/xsens_mvn_mixamo.json")
                .to_str()
                .unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]));
        let stderr = String::from_utf8_lossy(&convert.stderr);
        let sidecar: Value = serde_json::from_slice(
            &std::fs::read(out.join(format!("{name}.imubake.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(sidecar["source"]["format"], "xsens-mvnx");
        assert_eq!(sidecar["source"]["world"], "nwu");
        assert_eq!(
            sidecar["mapping"]["sensors"].as_array().map(Vec::len),
            Some(sensors)
        );
        let missing = sidecar["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|w| w.as_str().unwrap().contains("is not in the take"))
            .count();
        assert_eq!(missing, 17 - sensors, "{stderr}");
        let written = sidecar["frames"].as_u64().unwrap() as usize;
        // 30 fps frames m ↔ 60 Hz frames 2m.
        let planted = |m: usize, left: bool| ((2 * m) / 45).is_multiple_of(2) == left;
        let runs = |left: bool| -> Vec<[usize; 2]> {
            let mut out: Vec<[usize; 2]> = Vec::new();
            for m in (0..written).filter(|&m| planted(m, left)) {
                match out.last_mut() {
                    Some(r) if r[1] + 1 == m => r[1] = m,
                    _ => out.push([m, m]),
                }
            }
            out
        };
        assert_eq!(sidecar["vendor_contacts"]["vendor"], "xsens");
        assert_eq!(
            sidecar["vendor_contacts"]["left"],
            serde_json::json!(runs(true))
        );
        assert_eq!(
            sidecar["vendor_contacts"]["right"],
            serde_json::json!(runs(false))
        );
        assert_eq!(
            sidecar["vendor_contacts"]["left"][0],
            serde_json::json!([0, 22])
        );
        // Ours too where the root is foot-rooted (the legs have sensors).
        assert_eq!(sidecar["contacts"]["left"].is_array(), sensors == 17);
        assert_eq!(written, (frames - 1) / 2 + 1);

        let bvh = out.join(format!("{name}.bvh"));
        let report = &blender_import_bvh(&py, &[&bvh], Some(&[1, 100]))["files"][0];
        assert_eq!(
            report["bones"].as_array().map(Vec::len),
            Some(22),
            "{report}"
        );
        let glb = out.join(format!("{name}.glb"));
        let validation = &gltf_validate(&[&glb], &modules)[0];
        assert_eq!(
            (
                validation["errors"].as_u64(),
                validation["warnings"].as_u64()
            ),
            (Some(0), Some(0)),
            "{validation}"
        );
    }
    let inspect = run(Command::new(imubake_bin())
        .args(["inspect", dir.path().join("walk.mvnx").to_str().unwrap()]));
    let text = String::from_utf8_lossy(&inspect.stdout);
    assert!(
        text.contains("Xsens MVN .mvnx export") && text.contains("Node count: 17"),
        "{text}"
    );
    assert!(
        text.contains("RightUpperLeg") && text.contains("710"),
        "{text}"
    );
}

/// A hand-written take: calibration frames are not samples; a frame without
/// `sensorOrientation`, one with a short one and one with a bad number are dropped with their
/// lines; a zero quaternion drops that sample; `time` (ms) stands in for a missing `index`.
#[test]
fn damaged_frames_are_dropped_with_their_lines() {
    let text = r#"<?xml version="1.0" encoding="UTF-8"?>
<mvnx xmlns="http://www.xsens.com/mvn/mvnx" version="4">
<subject label="s" frameRate="100" segmentCount="1" configuration="Custom">
<sensors>
<sensor label="Pelvis"/>
<sensor label="T8"/>
</sensors>
<frames>
<frame time="0" type="identity"><orientation>1 0 0 0</orientation></frame>
<frame time="0" index="0" type="normal"><sensorOrientation>1 0 0 0 0 1 0 0</sensorOrientation></frame>
<frame time="10" index="1" type="normal"><orientation>1 0 0 0</orientation></frame>
<frame time="20" index="2" type="normal"><sensorOrientation>1 0 0 0 0 1 0</sensorOrientation></frame>
<frame time="30" index="3" type="normal"><sensorOrientation>1 0 0 0 0 x 0 0</sensorOrientation></frame>
<frame time="40" index="4" type="normal"><sensorOrientation>0 0 0 0 0 0 1 0</sensorOrientation></frame>
<frame time="50" type="normal"><sensorOrientation>0.5 0.5 0.5 0.5 0 0 0 1</sensorOrientation></frame>
</frames>
</subject>
</mvnx>
"#;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("damaged.mvnx");
    std::fs::write(&path, text).unwrap();
    let take = read_take(&path, &ReadOptions::default()).unwrap();
    let dropped: Vec<(u64, &str)> = take
        .dropped_lines()
        .iter()
        .map(|d| (d.line, d.reason.as_str()))
        .collect();
    assert_eq!(dropped.len(), 4, "{dropped:?}");
    assert_eq!(dropped[0].0, 11);
    assert!(dropped[0].1.contains("without `sensorOrientation`"));
    assert_eq!(dropped[1].0, 12);
    assert!(dropped[1].1.contains("has 7 values; 2 sensors need 8"));
    assert_eq!(dropped[2].0, 13);
    assert!(dropped[2].1.contains("not a number"));
    assert_eq!(dropped[3].0, 14);
    assert!(dropped[3].1.contains("zero quaternion"));
    let times = |id: &str| -> Vec<f64> {
        match take.sensor(id).unwrap().orientation() {
            Some(OrientationTrack::Quaternion(t)) => t.iter().map(|(t, _)| t).collect(),
            _ => panic!(),
        }
    };
    // Pelvis: frames 0 and the index-less one at time 50 ms; T8 also frame 4 (at 0.04 s).
    assert_eq!(times("Pelvis"), [0.0, 0.05]);
    assert_eq!(times("T8"), [0.0, 0.04, 0.05]);
    match take.sensor("T8").unwrap().orientation() {
        Some(OrientationTrack::Quaternion(t)) => {
            let (_, q) = t.iter().next().unwrap();
            // w first: 0 1 0 0 is a half turn about x.
            assert!((q.angle() - std::f64::consts::PI).abs() < 1e-12);
            assert!((q.axis().unwrap().x.abs() - 1.0).abs() < 1e-12);
        }
        _ => panic!(),
    }
    // Not XML at all, and XML that is not MVNX: errors naming the line.
    for (bad, says) in [
        (
            "<mvnx><subject><frames><frame type=\"normal\"></mvnx>",
            "not well-formed",
        ),
        (
            "<?xml version=\"1.0\"?>\n<other><mvnx/></other>",
            "not an MVNX document",
        ),
    ] {
        std::fs::write(&path, bad).unwrap();
        let e = read_take(
            &path,
            &ReadOptions {
                format: Some(imubake::read::InputFormat::XsensMvnx),
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains(says), "{e}");
    }
}

/// `--mvnx-segments`: Xsens's own segment kinematics on a rig made from the file. Every joint of
/// the written BVH (the numpy reader's forward kinematics) stands where the MVNX puts its segment
/// (PyPI `mvnx`'s `position`, turned into the rig world: y west → +X, z up → +Y, x north → +Z)
/// within 1 mm at every 30 fps frame m (MVNX frame 2m); with `--rig mixamo` it is retargeted by
/// part (L5 → Spine, T8 → Spine2, RightUpperLeg → RightUpLeg, …) and keeps Xsens's contacts.
#[test]
fn mvnx_segments_are_xsens_own_skeleton() {
    let Some(py) = python() else { return };
    let (dir, _) = fixtures(&py);
    let mvnx = dir.path().join("walk.mvnx");
    let out = dir.path().join("segments");
    run(Command::new(imubake_bin())
        .arg("convert")
        .arg(&mvnx)
        .args(["--mvnx-segments", "--format", "bvh", "--out"])
        .arg(&out));
    let sidecar: Value =
        serde_json::from_slice(&std::fs::read(out.join("walk.imubake.json")).unwrap()).unwrap();
    assert_eq!(sidecar["pipeline"]["mode"], "mvnx-segments");
    assert_eq!(sidecar["rig"]["name"], "xsens-mvn");
    let frames = sidecar["frames"].as_u64().unwrap() as usize;
    let script = "import json, sys, mvnx\nm = mvnx.load(sys.argv[1])\n\
        json.dump({'segments': list(m.segments.values()), 'p': m.position.tolist()}, sys.stdout)";
    let reference: Value =
        serde_json::from_slice(&run(Command::new(&py).args(["-c", script]).arg(&mvnx)).stdout)
            .unwrap();
    let wanted: Vec<String> = (0..frames).map(|m| m.to_string()).collect();
    let bvh: Value = serde_json::from_slice(
        &run(Command::new(&py)
            .arg(repo_file("tests/browser/bvh_reference_positions.py"))
            .arg(out.join("walk.bvh"))
            .arg("1")
            .args(&wanted))
        .stdout,
    )
    .unwrap();
    assert_eq!(
        bvh["names"], reference["segments"],
        "joints are the segments, in order"
    );
    let mut worst: f64 = 0.0;
    for m in 0..frames {
        let row = reference["p"][2 * m].as_array().unwrap();
        for (k, joint) in bvh["frames"][m.to_string()]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
        {
            let nwu = [0, 1, 2].map(|c| row[3 * k + c].as_f64().unwrap());
            let rig = nalgebra::Vector3::new(nwu[1], nwu[2], nwu[0]);
            worst = worst.max((common::vec3(joint) - rig).norm());
        }
    }
    eprintln!("{frames} frames × 23 segments: worst {:.3} mm", worst * 1e3);
    assert!(worst < 1e-3, "{worst} m");

    let out = dir.path().join("on_mixamo");
    run(Command::new(imubake_bin())
        .arg("convert")
        .arg(&mvnx)
        .args(["--mvnx-segments", "--rig", "mixamo", "--out"])
        .arg(&out));
    let sidecar: Value =
        serde_json::from_slice(&std::fs::read(out.join("walk.imubake.json")).unwrap()).unwrap();
    let pairs = common::sidecar_pairs(&sidecar);
    for pair in [
        ("Pelvis", "Hips"),
        ("L5", "Spine"),
        ("T8", "Spine2"),
        ("RightUpperLeg", "RightUpLeg"),
        ("LeftToe", "LeftToeBase"),
    ] {
        let pair = (pair.0.to_string(), pair.1.to_string());
        assert!(pairs.contains(&pair), "{pair:?} in {pairs:?}");
    }
    assert_eq!(sidecar["rig"]["name"], "mixamo");
    assert_eq!(
        sidecar["vendor_contacts"]["left"][0],
        serde_json::json!([0, 22])
    );
}
