//! Orientation accuracy against optical ground truth: the BROAD trials in `../shared/data/broad/`
//! through `imubake fuse`, scored by tests/python/broad_eval.py (BROAD's metric, written there
//! independently of imubake) beside PyPI's `vqf` (online and `offlineVQF`) run by the same
//! script.

use crate::common;

use serde_json::Value;
use std::process::Command;

fn evaluate() -> Option<Value> {
    let broad = common::shared("broad")?;
    let python = common::python()?;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("broad.json");
    let status = Command::new(python)
        .arg(common::repo_file("tests/python/broad_eval.py"))
        .arg(env!("CARGO_BIN_EXE_imubake"))
        .arg(&broad)
        .arg(&out)
        .args(["offline", "vqf", "madgwick", "mahony", "trust", "gyro"])
        .status()
        .unwrap();
    assert!(status.success(), "broad_eval.py failed");
    Some(serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap())
}

fn total(trial: &Value, key: &str) -> f64 {
    trial[key]["total_rmse_deg"]
        .as_f64()
        .unwrap_or_else(|| panic!("no {key}"))
}

#[test]
fn online_vqf_to_the_hundredth_of_a_degree_and_the_offline_default_better_than_both_vqf_modes() {
    let Some(results) = evaluate() else {
        return;
    };
    let trials = results.as_object().unwrap();
    assert_eq!(trials.len(), 3, "{:?}", trials.keys());
    // The default for files (offline): a mean below 1.75° (VQF online ≈ 1.81°, offline ≈ 1.84°),
    // and on each trial within 0.15° of the better VQF mode.
    let mut sum = 0.0;
    for (name, trial) in trials {
        let offline = total(trial, "imubake offline");
        let better = total(trial, "pypi vqf online").min(total(trial, "pypi vqf offline"));
        eprintln!("{name}: imubake offline {offline:.3}°, the better VQF mode {better:.3}°");
        assert!(
            offline <= better + 0.15,
            "{name}: {offline:.3}° vs {better:.3}°"
        );
        sum += offline;
    }
    assert!(sum / 3.0 <= 1.75, "mean {:.3}°", sum / 3.0);
    for (name, trial) in trials {
        let ours = total(trial, "imubake vqf");
        let vqf = total(trial, "pypi vqf online");
        eprintln!("{name}: imubake vqf {ours:.3}°, PyPI vqf online {vqf:.3}°");
        assert!(
            (ours - vqf).abs() <= 0.02,
            "{name}: {ours:.3}° vs {vqf:.3}°"
        );
        // Madgwick and Mahony in ENU: a frame mix-up (their textbook NWU) would cost about 90°.
        for filter in ["imubake madgwick", "imubake mahony"] {
            assert!(
                total(trial, filter) < 15.0,
                "{name}: {filter} {}",
                total(trial, filter)
            );
        }
    }
    // The figures the VQF authors' package gives on these trials (the numbers): the
    // data and the metric are read as they mean.
    for (trial, expected) in [
        ("02_undisturbed_slow_rotation_B", 1.38),
        ("07_undisturbed_fast_rotation_B", 1.75),
        ("15_undisturbed_fast_translation_A", 2.31),
    ] {
        let got = total(&results[trial], "pypi vqf online");
        assert!((got - expected).abs() < 0.01, "{trial}: {got:.3}°");
    }
}
