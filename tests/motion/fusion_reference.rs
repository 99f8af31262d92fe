//! imubake's fusion cores against independent implementations, sample by sample, on a real IMU
//! log (../shared/data/imu/vqf_imu_data.npz, 4000 samples at 285.7 Hz): VQF (through `vqf-rs`)
//! against PyPI `vqf`, the authors' own C++ (online, float64); Madgwick and Mahony, with and
//! without the magnetometer, against PyPI `ahrs` with the same start, gains and frame. The
//! references are computed at test time by tests/python/fusion_reference.py.

use crate::common;

use imubake::fusion::Ahrs;
use imubake::fusion::madgwick::Madgwick;
use imubake::fusion::mahony::Mahony;
use imubake::fusion::nwu_to_enu;
use imubake::fusion::vqf::{Vqf, VqfParams};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;
use std::process::Command;

/// A JSON array of number arrays.
fn rows(v: &Value) -> Vec<Vec<f64>> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|r| {
            r.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        })
        .collect()
}

fn vectors(v: &Value) -> Vec<Vector3<f64>> {
    rows(v)
        .iter()
        .map(|r| Vector3::new(r[0], r[1], r[2]))
        .collect()
}

fn quats(v: &Value) -> Vec<Quaternion<f64>> {
    rows(v)
        .iter()
        .map(|r| Quaternion::new(r[0], r[1], r[2], r[3]))
        .collect()
}

/// The largest difference of any component, signs aligned (q and −q are one rotation).
fn worst(ours: &[Quaternion<f64>], theirs: &[Quaternion<f64>]) -> f64 {
    ours.iter()
        .zip(theirs)
        .map(|(a, b)| {
            let b = if a.dot(b) < 0.0 { -b } else { *b };
            (a - b).coords.abs().max()
        })
        .fold(0.0, f64::max)
}

fn reference() -> Option<Value> {
    let npz = common::shared("imu/vqf_imu_data.npz")?;
    let python = common::python()?;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("reference.json");
    let status = Command::new(python)
        .arg(common::repo_file("tests/python/fusion_reference.py"))
        .arg(&npz)
        .arg(&out)
        .arg("4000")
        .status()
        .unwrap();
    assert!(status.success(), "fusion_reference.py failed");
    Some(serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap())
}

#[test]
fn cores_match_independent_implementations_sample_by_sample() {
    let Some(r) = reference() else {
        return;
    };
    let ts = r["sample_time_s"].as_f64().unwrap();
    let (gyr, acc, mag) = (vectors(&r["gyr"]), vectors(&r["acc"]), vectors(&r["mag"]));
    let n = gyr.len();

    // VQF, 6D and 9D outputs of one run, and its bias estimate.
    let mut vqf = Vqf::new(&VqfParams::default(), ts, true);
    let mut vqf6 = Vqf::new(&VqfParams::default(), ts, false);
    let (mut q9, mut q6, mut bias) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..n {
        vqf.update(&gyr[i], &acc[i], Some(&mag[i]), ts);
        vqf6.update(&gyr[i], &acc[i], None, ts);
        q9.push(vqf.orientation().into_inner());
        q6.push(vqf6.orientation().into_inner());
        bias.push(vqf.gyro_bias().unwrap());
    }
    let vqf9 = worst(&q9, &quats(&r["vqf_quat9d"]));
    let vqf6w = worst(&q6, &quats(&r["vqf_quat6d"]));
    let bias_worst = bias
        .iter()
        .zip(vectors(&r["vqf_bias"]))
        .map(|(a, b)| (a - b).abs().max())
        .fold(0.0, f64::max);
    eprintln!("VQF 9D {vqf9:e}, 6D {vqf6w:e}, bias {bias_worst:e} rad/s");
    assert!(
        vqf9 < 1e-9 && vqf6w < 1e-9,
        "VQF differs: 9D {vqf9:e}, 6D {vqf6w:e}"
    );
    assert!(
        bias_worst < 1e-12,
        "VQF bias differs by {bias_worst:e} rad/s"
    );

    // Madgwick (textbook NWU) and Mahony (ENU), from the same start, one update per later sample.
    let q0: Vec<f64> = r["q0_enu"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let q0 = UnitQuaternion::new_normalize(Quaternion::new(q0[0], q0[1], q0[2], q0[3]));
    let beta = r["beta"].as_f64().unwrap();
    let (kp, ki) = (r["kp"].as_f64().unwrap(), r["ki"].as_f64().unwrap());
    for nine_d in [true, false] {
        let m = |i: usize| nine_d.then_some(&mag[i]);
        let mut madgwick = Madgwick::new(beta, q0);
        let mut mahony = Mahony::new(kp, ki, q0);
        let (mut mw, mut mh) = (vec![madgwick.q_nwu().into_inner()], vec![q0.into_inner()]);
        for i in 1..n {
            madgwick.update(&gyr[i], &acc[i], m(i), ts);
            mahony.update(&gyr[i], &acc[i], m(i), ts);
            mw.push(madgwick.q_nwu().into_inner());
            mh.push(mahony.orientation().into_inner());
            // What the core hands out is ENU: the NWU state turned by 90° about up.
            let enu = madgwick.orientation();
            assert!(enu.angle_to(&(nwu_to_enu() * madgwick.q_nwu())) < 1e-12);
        }
        let d = if nine_d { "9d" } else { "6d" };
        let w_madgwick = worst(&mw, &quats(&r[format!("madgwick_{d}_nwu").as_str()]));
        let w_mahony = worst(&mh, &quats(&r[format!("mahony_{d}_enu").as_str()]));
        eprintln!("Madgwick {d} {w_madgwick:e}, Mahony {d} {w_mahony:e}");
        assert!(w_madgwick < 1e-6, "Madgwick {d} differs by {w_madgwick:e}");
        assert!(w_mahony < 1e-6, "Mahony {d} differs by {w_mahony:e}");
    }
}
