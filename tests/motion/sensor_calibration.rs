//! Sensor calibration (`calibrate-sensors`, issue 15) against independently made truth:
//! calibration takes with random errors drawn by tests/python/calibration_takes.py (numpy and
//! scipy), the real raw logs in ../shared/data/imu/ (the bias against numpy's mean over the same
//! stillness; the magnetometer's field norm before and after), and degenerate takes.

use crate::common;

use common::{imubake_bin, python, repo_file, run, shared};
use imubake::intrinsics::SensorCalibration;
use nalgebra::{Matrix3, Vector3};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};

fn matrix(v: &Value) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| v[r][c].as_f64().unwrap())
}

fn calibrate(input: &Path, out: &Path, args: &[&str]) -> Output {
    Command::new(imubake_bin())
        .arg("calibrate-sensors")
        .arg(input)
        .arg("--output")
        .arg(out)
        .args(args)
        .output()
        .unwrap()
}

/// Three sensors with random errors (seed 15): every solver recovers the truth within the
/// issue's tolerances — hard iron within 1 % of the field norm, the soft-iron correction within
/// 0.02 per element, the gyro gain matrix within 0.005 per element (0.5 %), the accelerometer
/// offset within 0.03 m/s² and scale within 0.3 %, the gyro bias within 0.05 °/s.
#[test]
fn solvers_recover_random_errors() {
    let Some(py) = python() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (take, truth_path, cal) = (
        dir.path().join("cal.csv"),
        dir.path().join("truth.json"),
        dir.path().join("cal.yaml"),
    );
    run(Command::new(py)
        .arg(repo_file("tests/python/calibration_takes.py"))
        .args(["random", "15", "3"])
        .arg(&take)
        .arg(&truth_path));
    let out = calibrate(&take, &cal, &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let truth: Value = serde_json::from_slice(&std::fs::read(&truth_path).unwrap()).unwrap();
    let field_norm = common::vec3(&truth["field_enu_ut"]).norm();
    let found = SensorCalibration::load(&cal).unwrap();
    assert_eq!(found.sensors.len(), 3);
    for (id, t) in truth["sensors"].as_object().unwrap() {
        let s = &found.sensors[id];
        let mag = s.magnetometer.as_ref().unwrap();
        let hard = (Vector3::from(mag.hard_iron) - common::vec3(&t["hard_iron_ut"])).norm();
        let s_inv = matrix(&t["soft_iron"]).try_inverse().unwrap();
        let soft = (mag.matrix() - s_inv / s_inv.determinant().cbrt()).amax();
        let gain = s.gyro_gain.as_ref().unwrap();
        let g = (gain.matrix() - matrix(&t["gyro_matrix"]).try_inverse().unwrap()).amax();
        let acc = s.accelerometer.as_ref().unwrap();
        let offset = (Vector3::from(acc.offset_m_s2) - common::vec3(&t["acc_offset_m_s2"])).amax();
        let scale =
            (Vector3::from(acc.scale) - common::vec3(&t["acc_gain"]).map(|k| 1.0 / k)).amax();
        let bias = (Vector3::from(s.gyro_bias.as_ref().unwrap().bias_rad_s).map(f64::to_degrees)
            - common::vec3(&t["gyro_bias_dps"]))
        .amax();
        eprintln!(
            "{id}: hard iron {:.3} % of |F|, soft iron {soft:.4}, gyro gain {g:.5} (residual {:.2} % → {:.4} %), \
             acc offset {offset:.4} m/s² scale {scale:.5}, bias {bias:.4} °/s, mag residual {:.2} % → {:.3} %",
            100.0 * hard / field_norm,
            gain.residual_before_pct,
            gain.residual_after_pct,
            mag.residual_before_pct,
            mag.residual_after_pct
        );
        assert!(
            hard < 0.01 * field_norm,
            "{id}: hard iron off by {hard:.3} µT"
        );
        assert!(soft < 0.02, "{id}: soft iron off by {soft:.4}");
        assert!(g < 0.005, "{id}: gyro gain off by {g:.5}");
        assert!(
            gain.rotations.len() == 9 && gain.condition < 10.0,
            "{gain:?}"
        );
        assert!(offset < 0.03 && scale < 0.003, "{id}: {acc:?}");
        assert!(bias < 0.05, "{id}: bias off by {bias:.4} °/s");
        assert!(
            mag.residual_after_pct < 1.0 && mag.residual_before_pct > 5.0,
            "{mag:?}"
        );
    }
    // A second run with one kind keeps the file's other kinds.
    let out = calibrate(&take, &cal, &["--kind", "gyro-bias", "--still", "0:4"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let again = SensorCalibration::load(&cal).unwrap();
    assert_eq!(
        again.sensors["s0"].kinds(),
        ["gyro-bias", "gyro-gain", "acc", "mag"]
    );
    assert_eq!(
        again.sensors["s0"].gyro_bias.as_ref().unwrap().window_s[1],
        4.0
    );
}

/// The real raw logs (no ground truth): the gyro bias found at the opening stillness is numpy's
/// mean over the same window, and the magnetometer fit lowers the field norm's spread over the
/// readings it keeps. Measured: x-io Fusion's sample 4.90 % → 1.32 % with 15.9 % set aside (its
/// field changes for a stretch mid-take), VQF's example 1.84 % → 1.64 % — both devices come
/// factory-calibrated, so there is little left to take away.
#[test]
fn real_logs_bias_and_magnetometer() {
    let (Some(xio), Some(npz), Some(py)) = (
        shared("imu/xio_fusion_sensor_data.csv"),
        shared("imu/vqf_imu_data.npz"),
        python(),
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let vqf_csv = dir.path().join("vqf.csv");
    run(Command::new(&py)
        .arg(repo_file("tests/python/vqf_npz_to_csv.py"))
        .arg(&npz)
        .arg(&vqf_csv));
    for (kind, source, take) in [("xio", &xio, &xio), ("npz", &npz, &vqf_csv)] {
        let cal = dir.path().join(format!("{kind}.yaml"));
        let out = calibrate(take, &cal, &["--kind", "gyro-bias,mag"]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let found = SensorCalibration::load(&cal).unwrap();
        let s = &found.sensors["imu"];
        let bias = s.gyro_bias.as_ref().unwrap();
        let mean = run(Command::new(&py)
            .arg(repo_file("tests/python/mean_over_window.py"))
            .arg(kind)
            .arg(source)
            .arg(format!("{:.9}", bias.window_s[0]))
            .arg(format!("{:.9}", bias.window_s[1])));
        let mean: Value = serde_json::from_slice(&mean.stdout).unwrap();
        let expected = common::vec3(&mean["mean_dps"]);
        let found_dps = Vector3::from(bias.bias_rad_s).map(f64::to_degrees);
        assert_eq!(mean["samples"].as_u64().unwrap() as usize, bias.samples);
        assert!(
            (found_dps - expected).amax() < 1e-6,
            "{found_dps} vs {expected}"
        );
        assert!(bias.window_s[1] - bias.window_s[0] > 4.0, "{bias:?}");
        let mag = s.magnetometer.as_ref().unwrap();
        eprintln!(
            "{kind}: bias {found_dps:?} °/s over {:?} s; field norm residual {:.2} % → {:.2} % ({:.2} % → {:.2} % \
             without the {:.1} % set aside), coverage {:.0} %",
            bias.window_s,
            mag.residual_before_pct,
            mag.residual_after_pct,
            mag.kept_residual_before_pct,
            mag.kept_residual_after_pct,
            mag.set_aside_pct,
            mag.coverage_pct
        );
        assert!(
            mag.kept_residual_after_pct < mag.kept_residual_before_pct,
            "{mag:?}"
        );
        assert!(mag.kept_residual_after_pct < 2.0, "{mag:?}");
        assert!(mag.set_aside_pct < 20.0, "{mag:?}");
        // Neither log turned each axis within 25° of the field both ways: min-max is refused.
        let out = calibrate(
            take,
            &dir.path().join("mm.yaml"),
            &["--kind", "mag", "--mag-fit", "min-max"],
        );
        let text = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && text.contains("never pointed along and against"),
            "{text}"
        );
    }
}

/// A raw imubake CSV of one sensor `s` at 100 Hz from a function of time.
fn synthetic(path: &Path, seconds: f64, reading: impl Fn(f64) -> [f64; 9]) {
    let mut text = String::from("time_s,sensor,gx,gy,gz,ax,ay,az,mx,my,mz\n");
    for i in 0..(seconds * 100.0) as usize {
        let t = i as f64 / 100.0;
        let v = reading(t);
        text.push_str(&format!("{t:.2},s"));
        for x in v {
            text.push_str(&format!(",{x:.6}"));
        }
        text.push('\n');
    }
    std::fs::write(path, text).unwrap();
}

/// Degenerate takes give an error that names the sensor and what to record, and no file.
#[test]
fn degenerate_takes_are_refused_with_what_to_record() {
    let dir = tempfile::tempdir().unwrap();
    type Reading = Box<dyn Fn(f64) -> [f64; 9]>;
    let cases: [(&str, f64, Reading, &str, &str); 4] = [
        // Spinning all the time: never still.
        (
            "spin",
            20.0,
            Box::new(|t: f64| {
                let a = 2.0 * t;
                [
                    0.3 * (5.0 * t).sin(),
                    0.0,
                    2.0,
                    0.0,
                    0.0,
                    9.81,
                    20.0 * a.cos(),
                    20.0 * a.sin(),
                    -40.0,
                ]
            }),
            "gyro-bias",
            "never holds still for 2 s",
        ),
        // Lying still: the magnetometer never turned.
        (
            "still",
            20.0,
            Box::new(|_| [0.0, 0.0, 0.0, 0.0, 0.0, 9.81, 20.0, 0.0, -40.0]),
            "mag",
            "turned slowly through every direction",
        ),
        // Ten readings.
        (
            "short",
            0.1,
            Box::new(|_| [0.0, 0.0, 0.0, 0.0, 0.0, 9.81, 20.0, 0.0, -40.0]),
            "mag",
            "only 10 magnetometer readings, 50 needed",
        ),
        // Still, but in one position.
        (
            "one-position",
            20.0,
            Box::new(|_| [0.0, 0.0, 0.0, 0.0, 0.0, 9.81, 20.0, 0.0, -40.0]),
            "acc",
            "1 still positions, six needed",
        ),
    ];
    for (name, seconds, reading, kind, expected) in cases {
        let take = dir.path().join(format!("{name}.csv"));
        synthetic(&take, seconds, reading);
        let cal = dir.path().join(format!("{name}.yaml"));
        let out = calibrate(&take, &cal, &["--kind", kind]);
        let text = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name}: {text}");
        assert!(
            text.contains("sensor `s`") && text.contains(expected),
            "{name}: {text}"
        );
        assert!(!cal.exists(), "{name}: a file was written");
    }
}
