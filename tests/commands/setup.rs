//! `imubake setup` as a user drives it, in Debian's Chromium (headless, playwright-core:
//! `tests/browser/setup.mjs`), against a replayed raw stream of 16 simulated sensors that move
//! one at a time (`tests/python/setup_stream.py`, numpy and scipy): the page lights each moving
//! sensor, the driver puts it on the bone the simulation says moves then (it is never told the
//! sensor), runs the gyro-bias and magnetometer captures, holds the pose, bows, enters a height
//! and a segment and saves. The saved files are
//! checked against the simulation's truth, then drive `live --record` and `convert`.

use crate::common;
use crate::viewer::{browser, serve};
use crate::viewer_server::upgrade_at;
use common::{imubake_bin, python, repo_file, run};
use imubake::intrinsics::SensorCalibration;
use imubake::mapping::{MappingFile, load_mapping};
use imubake::rig::subject::Subject;
use serde_json::Value;
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Command, Stdio};

#[test]
fn a_suit_is_set_up_in_the_browser_and_its_files_convert_a_take() {
    let (Some(py), Some(modules)) = (python(), browser()) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let stream = dir.path().join("stream.csv");
    let truth_path = dir.path().join("truth.json");
    run(Command::new(&py)
        .arg(repo_file("tests/python/setup_stream.py"))
        .arg(&stream)
        .arg(&truth_path)
        .arg("3"));
    let truth: Value = serde_json::from_slice(&std::fs::read(&truth_path).unwrap()).unwrap();
    let out = dir.path().join("suit");

    // The browser first (its start under load can outlast the stream's 3 s still lead-in, and the
    // replay runs in real time from the server's start), then the server, whose URL goes to the
    // waiting driver.
    let shot = dir.path().join("setup.png");
    let mut driver = Command::new("node")
        .arg(repo_file("tests/browser/setup.mjs"))
        .arg("-")
        .arg(&truth_path)
        .arg(&shot)
        .env("IMUBAKE_NODE_MODULES", &modules)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut page = BufReader::new(driver.stdout.take().unwrap());
    let mut ready = String::new();
    page.read_line(&mut ready).unwrap();
    assert_eq!(
        ready.trim(),
        "ready",
        "the driver did not start its browser"
    );
    let mut cmd = Command::new(imubake_bin());
    cmd.arg("setup")
        .arg("--source")
        .arg(format!("file:{}", stream.display()))
        .arg("--out")
        .arg(&out);
    let served = serve(cmd, true);
    {
        let mut stdin = driver.stdin.take().unwrap();
        writeln!(stdin, "{}", served.url).unwrap();
    }
    // While the page loads (the server ends with its stream): the board's socket takes its
    // page's origin only (its commands change the files).
    let host = served.authority().to_string();
    for origin in [None, Some("http://evil.example"), Some("null")] {
        let (code, _) = upgrade_at(&host, "/setup", &host, origin);
        assert_eq!(code, 403, "Origin {origin:?}");
    }
    let mut report = String::new();
    page.read_to_string(&mut report).unwrap();
    assert!(driver.wait().unwrap().success(), "{report}");
    let page: Value = serde_json::from_str(&report).unwrap();
    assert_eq!(page["console"], Value::Array(vec![]), "{page}");
    assert_eq!(page["failed"], Value::Array(vec![]));
    assert_eq!(page["errors"], Value::Array(vec![]));

    // Each slot lit the sensor that moved, within 0.5 s of stream time.
    let moves = truth["moves"].as_array().unwrap();
    let slots = page["slots"].as_array().unwrap();
    assert_eq!(slots.len(), 16);
    for (slot, mv) in slots.iter().zip(moves) {
        assert_eq!(slot["lit"], mv["sensor"], "{slot} {mv}");
        let late = slot["seen_at_s"].as_f64().unwrap() - mv["start_s"].as_f64().unwrap();
        assert!((0.0..=0.5).contains(&late), "lit {late:.2} s after {mv}");
    }
    println!(
        "lit after (s): {:?}",
        slots
            .iter()
            .zip(moves)
            .map(|(s, m)| s["seen_at_s"].as_f64().unwrap() - m["start_s"].as_f64().unwrap())
            .collect::<Vec<_>>()
    );

    // The saved files, read by the loaders convert uses, against the truth.
    let MappingFile::Quaternion(mapping) = load_mapping(&out.join("mapping.json")).unwrap() else {
        panic!("not a quaternion mapping");
    };
    let sensors = truth["sensors"].as_object().unwrap();
    assert_eq!(mapping.sensors.len(), 16);
    for s in &mapping.sensors {
        assert_eq!(sensors[&s.sensor]["bone"], s.bone.as_str(), "{}", s.sensor);
        let pelvis = s.sensor == truth["pelvis"];
        let forward = truth["forward"].as_str().unwrap();
        assert_eq!(
            s.forward,
            pelvis.then(|| imubake::mapping::parse_axis(forward).unwrap()),
            "{}",
            s.sensor
        );
    }
    let calibration = SensorCalibration::load(&out.join("sensor_calibration.yaml")).unwrap();
    assert_eq!(calibration.sensors.len(), 16);
    let mut worst = 0.0f64;
    for (id, s) in &calibration.sensors {
        let found = s.gyro_bias.as_ref().unwrap().bias_rad_s;
        let simulated = &sensors[id]["bias_rad_s"];
        for (k, b) in found.iter().enumerate() {
            worst = worst.max((b - simulated[k].as_f64().unwrap()).abs().to_degrees());
        }
    }
    println!("gyro bias: worst axis {worst:.4} °/s off the simulated");
    assert!(worst <= 0.05, "{worst} °/s");
    // Each magnetometer's hard iron, from the tumble.
    let mut worst = 0.0f64;
    for (id, s) in &calibration.sensors {
        let fit = s
            .magnetometer
            .as_ref()
            .unwrap_or_else(|| panic!("{id}: no fit"));
        let simulated = &sensors[id]["hard_iron"];
        for (k, h) in fit.hard_iron.iter().enumerate() {
            worst = worst.max((h - simulated[k].as_f64().unwrap()).abs());
        }
    }
    println!("hard iron: worst axis {worst:.3} µT off the simulated (field 44.7 µT)");
    assert!(worst <= 0.5, "{worst} µT");
    let subject = Subject::load(&out.join("subject.yaml")).unwrap();
    assert_eq!(subject.height_m, Some(1.72));
    assert_eq!(subject.segments["left_thigh"], 0.45);

    // The command the page printed records a take (the stream replayed 10× faster, VMC off);
    // convert reads it with the saved files.
    let message = page["message"].as_str().unwrap();
    let printed = message.lines().last().unwrap();
    assert!(printed.starts_with("imubake live "), "{message}");
    let mut args: Vec<String> = printed
        .split_whitespace()
        .skip(2)
        .map(|w| {
            if w.starts_with("file:") {
                format!("{}@10", w.rsplit_once('@').map_or(w, |(p, _)| p))
            } else {
                w.to_string()
            }
        })
        .collect();
    args.extend(["--vmc", "off", "--listen", "off"].map(String::from));
    run(Command::new(imubake_bin()).arg("live").args(&args));
    let takes = out.join("takes");
    let recorded: Vec<_> = std::fs::read_dir(&takes)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(recorded.len(), 1, "{recorded:?}");
    let converted = dir.path().join("converted");
    let flag = |name: &str| {
        let at = args.iter().position(|a| a == name).unwrap();
        args[at + 1].clone()
    };
    run(Command::new(imubake_bin())
        .arg("convert")
        .arg(&recorded[0])
        .args(["--rig", &flag("--rig")])
        .args(["--mapping", &flag("--mapping")])
        .args(["--subject", &flag("--subject")])
        .args(["--sensor-calibration", &flag("--sensor-calibration")])
        .arg("-o")
        .arg(&converted));
    let sidecar: Vec<_> = std::fs::read_dir(&converted)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".json"))
        .collect();
    assert_eq!(sidecar.len(), 1, "{sidecar:?}");
    let sidecar: Value = serde_json::from_slice(&std::fs::read(&sidecar[0]).unwrap()).unwrap();
    assert!(
        sidecar["frames"].as_u64().is_some_and(|n| n > 100),
        "{sidecar}"
    );
    assert_eq!(sidecar["sensors"].as_object().unwrap().len(), 16);
    // The heading comes from the forward the bow found, and the simulated body faces north
    // (its pelvis sensor's -y along +y of ENU): the declared forward's heading is 0°.
    let pipeline = &sidecar["pipeline"];
    assert_eq!(pipeline["heading"], "declared-forward", "{pipeline}");
    assert_eq!(pipeline["heading_sensor"], truth["pelvis"]);
    let declared = pipeline["heading_looks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["source"] == "declared-forward")
        .unwrap();
    println!("declared forward: heading {} °", declared["heading_deg"]);
    assert!(
        declared["heading_deg"].as_f64().unwrap().abs() < 2.0,
        "{declared}"
    );
}
