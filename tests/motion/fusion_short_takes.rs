//! Issue 51: the offline fusion on the takes animators record — short, dynamic, a brief still
//! pose first — against PyPI `vqf`'s offline mode on the same readings, by
//! scripts/fusion_matrix.py (simulated raw readings, the truth they were simulated from, PyPI's
//! `offlineVQF`, each fusion converted onto the source skeleton and scored against it with
//! scipy; written independently of imubake's fusion). CI runs its quick and ranking cells; the
//! whole matrix's figures are in docs/src/accuracy.md.

use crate::common;

use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// The matrix script on `cells` with `seeds`: its JSON (`cells`, `summary`).
fn matrix(cells: &str, seeds: &str) -> Option<Value> {
    let (data, python) = (common::shared_data()?, common::python()?);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("matrix.json");
    common::run(
        Command::new(python)
            .arg(common::repo_file("scripts/fusion_matrix.py"))
            .args(["--cells", cells, "--seeds", seeds, "--bin"])
            .arg(env!("CARGO_BIN_EXE_imubake"))
            .arg("--data")
            .arg(Path::new(&data))
            .arg("--out")
            .arg(&out),
    );
    Some(serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap())
}

fn score(cell: &Value, key: &str, k: usize) -> f64 {
    cell[key][k].as_f64().unwrap()
}

/// Through the body (each mapped bone's world rotation since the calibration pose against the
/// source's, mean of the bones' RMS), at most PyPI offline VQF's + 0.05° and below imubake's
/// online VQF; per sensor, the error's change since the pose at most PyPI offline's + 0.05° and
/// the absolute error at most PyPI offline's + 0.1°.
fn assert_cell(cell: &Value) {
    let label = format!(
        "{} (pose {} s, bias SD {} °/s, {} Hz, jitter {} ms)",
        cell["take"].as_str().unwrap(),
        cell["rest_s"],
        cell["bias_sd_dps"],
        cell["rate_hz"],
        cell["jitter_ms"]
    );
    let [abs, since, body] = [0, 1, 2].map(|k| score(cell, "offline", k));
    let [p_abs, p_since, p_body] = [0, 1, 2].map(|k| score(cell, "pypi_offline", k));
    let v_body = score(cell, "vqf", 2);
    eprintln!(
        "{label}: body {body:.2}° (PyPI offline {p_body:.2}°, imubake vqf {v_body:.2}°, the \
         pipeline's floor {:.2}°); per sensor {abs:.2}° / {since:.2}° since the pose (PyPI \
         {p_abs:.2}° / {p_since:.2}°); expected {:.2}°",
        score(cell, "truth", 2),
        cell["expected_deg"].as_f64().unwrap()
    );
    assert!(body <= p_body + 0.05, "{label}: {body:.3}° vs {p_body:.3}°");
    assert!(body < v_body, "{label}: {body:.3}° vs {v_body:.3}°");
    assert!(
        since <= p_since + 0.05,
        "{label}: {since:.3}° vs {p_since:.3}°"
    );
    assert!(abs <= p_abs + 0.1, "{label}: {abs:.3}° vs {p_abs:.3}°");
}

/// The quick cells (CMU 01_01's first 10 s after a 1.5 s pose, gyro bias SD 0.5 °/s per axis,
/// 100 Hz, 1 ms jitter; the pymo walk's first 5 s after a 0.5 s pose, bias SD 2 °/s, 60 Hz),
/// seeds 1–3. Measured 2026-12-06 through the body: 1.06° and 0.55° (PyPI offline 2.28° and
/// 8.76°, imubake vqf 2.42° and 8.33°; the pipeline's own floor, the truth converted, 0.17° and
/// 0.26°).
#[test]
fn short_takes_with_a_brief_pose_fuse_at_least_as_well_as_vqf_offline() {
    let Some(result) = matrix("quick", "1,2,3") else {
        return;
    };
    let cells = result["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 2);
    cells.iter().for_each(assert_cell);
}

/// The offline fusion's expected error (`expected_error_deg`, a model from the bias's
/// uncertainty, the samples' timing and the heading smoother's variance) ranks twelve short
/// cells' measured errors — with and without jitter, brief and long poses, 60 and 200 Hz — with
/// Spearman's ρ ≥ 0.7 (scipy), through the body and per sensor since the pose; in each cell the
/// default is below imubake's online VQF through the body. (The bound against PyPI offline is
/// the quick cells' and the whole matrix's.) Measured 2026-12-06 (seed 1): ρ 0.90 and 0.94.
#[test]
fn the_expected_error_ranks_the_measured_errors() {
    let Some(result) = matrix("ranking", "1") else {
        return;
    };
    let cells = result["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 12);
    for cell in cells {
        let (body, v_body) = (score(cell, "offline", 2), score(cell, "vqf", 2));
        eprintln!(
            "{}: body {body:.2}° (PyPI offline {:.2}°, imubake vqf {v_body:.2}°), expected {:.2}°",
            cell["take"],
            score(cell, "pypi_offline", 2),
            cell["expected_deg"]
        );
        assert!(
            body < v_body,
            "{}: {body:.3}° vs {v_body:.3}°",
            cell["take"]
        );
    }
    let summary = &result["summary"];
    for key in ["spearman_expected_vs_body", "spearman_expected_vs_since"] {
        let rho = summary[key].as_f64().unwrap();
        eprintln!("{key}: {rho:.2}");
        assert!(rho >= 0.7, "{key}: {rho:.3}");
    }
}

/// Takes that never rest (`--cells norest`: each source from its first sample, no pose, 100 Hz,
/// bias SD 0, 0.5 and 2 °/s; seed 1), per sensor against the truth: on average below PyPI
/// offline, and in each cell within its + 0.05° except the two still open in issue 51 (CMU 01_01
/// 10 s with a bias: the tilt a 10 s average leaves over a 10 s take). The heading's rate keeps
/// the 20 s takes with a bias ahead (before it, 2.48° and 9.84° against 2.10° and 7.32°).
/// Measured 2026-12-06 (seed 1): 2.70° against 3.51° on average; the 20 s cells 1.32° and 5.20°
/// against 2.12° and 7.77°.
#[test]
fn takes_that_never_rest_fuse_better_than_vqf_offline_on_average() {
    let Some(result) = matrix("norest", "1") else {
        return;
    };
    let cells = result["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 12);
    let (mut ours, mut pypi) = (0.0, 0.0);
    for cell in cells {
        let (take, bias) = (
            cell["take"].as_str().unwrap(),
            cell["bias_sd_dps"].as_f64().unwrap(),
        );
        let (abs, p_abs) = (score(cell, "offline", 0), score(cell, "pypi_offline", 0));
        eprintln!("{take} (no pose, bias SD {bias} °/s): {abs:.2}° (PyPI offline {p_abs:.2}°)");
        (ours, pypi) = (ours + abs, pypi + p_abs);
        if take == "CMU 01_01 10 s" && bias > 0.0 {
            continue;
        }
        assert!(
            abs <= p_abs + 0.05,
            "{take}, bias {bias}: {abs:.3}° vs {p_abs:.3}°"
        );
    }
    let n = cells.len() as f64;
    eprintln!("mean: {:.2}° (PyPI offline {:.2}°)", ours / n, pypi / n);
    assert!(ours < pypi, "{ours:.3} vs {pypi:.3}");
}
