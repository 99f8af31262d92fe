//! Benchmark: the fusion cores per sample on one core, VQF's own C++ (PyPI `vqf`, batch mode)
//! timed on the same readings, and `convert` of the 60-minute, 16-sensor, 100 Hz raw log against
//! its orientation twin.
//!
//! Targets: Madgwick 9D ≤ 150 ns per sample; online VQF no slower per sample than VQF's C++; the
//! raw log converts in at most twice the time of its twin (issue 13); the offline fusion costs at
//! most 3× online VQF per sample (issue 14).
//!
//!   cargo bench --bench fusion
//!   IMUBAKE_BENCH_MINUTES=5 cargo bench --bench fusion

mod common;

use common::{PAPER000_SENSORS, minutes_from_env, write_log, write_raw_log};
use imubake::convert::{ConvertSettings, convert};
use imubake::fusion::Fusion;
use nalgebra::{UnitQuaternion, Vector3};
use std::hint::black_box;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

const SAMPLES: usize = 1_000_000;
const RATE_HZ: f64 = 100.0;

/// Readings of a sensor tumbling about a slowly wandering axis, with a little noise: gyro
/// (rad/s), specific force (m/s²), field (µT), sensor frame.
fn readings() -> Vec<[f64; 9]> {
    let dt = 1.0 / RATE_HZ;
    let mut q = UnitQuaternion::identity();
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    (0..SAMPLES)
        .map(|i| {
            let t = i as f64 * dt;
            let w = Vector3::new((0.7 * t).sin(), (0.3 * t).cos(), 0.5 * (0.11 * t).sin()) * 2.0;
            q *= UnitQuaternion::from_scaled_axis(w * dt);
            let a = q.inverse() * Vector3::new(0.0, 0.0, 9.81);
            let m = q.inverse() * Vector3::new(0.0, 20.0, -40.0);
            [
                w.x + 0.01 * noise(),
                w.y + 0.01 * noise(),
                w.z + 0.01 * noise(),
                a.x + 0.1 * noise(),
                a.y + 0.1 * noise(),
                a.z + 0.1 * noise(),
                m.x + 0.5 * noise(),
                m.y + 0.5 * noise(),
                m.z + 0.5 * noise(),
            ]
        })
        .collect()
}

/// Nanoseconds per sample of a filter's `update` (best of 3 passes over the readings).
fn per_sample_ns(spec: &str, data: &[[f64; 9]]) -> f64 {
    let fusion: Fusion = spec.parse().expect("filter");
    let nine_d = !fusion.six_d;
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let mut core = fusion.core(UnitQuaternion::identity(), 1.0 / RATE_HZ, nine_d);
        let start = Instant::now();
        for r in data {
            let gyr = Vector3::new(r[0], r[1], r[2]);
            let acc = Vector3::new(r[3], r[4], r[5]);
            let mag = Vector3::new(r[6], r[7], r[8]);
            core.update(&gyr, &acc, nine_d.then_some(&mag), 1.0 / RATE_HZ);
        }
        black_box(core.orientation());
        best = best.min(start.elapsed().as_secs_f64());
    }
    best * 1e9 / data.len() as f64
}

/// VQF's C++ through PyPI `vqf` (`VQF.updateBatch`, 9D and 6D) on the same readings, ns per
/// sample, best of 3; `None` when no Python with `vqf` is found (IMUBAKE_PYTHON, or the test
/// cache's venv).
fn vqf_cpp_ns(data: &[[f64; 9]], dir: &Path) -> Option<(f64, f64)> {
    let python = std::env::var_os("IMUBAKE_PYTHON")
        .map(std::path::PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .map(|h| Path::new(&h).join(".cache/imubake-test/venv/bin/python"))
        })
        .filter(|p| p.exists())?;
    let raw = dir.join("readings.f64");
    let bytes: Vec<u8> = data
        .iter()
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    std::fs::write(&raw, bytes).ok()?;
    let script = format!(
        "import numpy as np, time\nfrom vqf import VQF\n\
         d = np.fromfile('{}', dtype='<f8').reshape(-1, 9)\n\
         g, a, m = (np.ascontiguousarray(d[:, i:i + 3]) for i in (0, 3, 6))\n\
         def best(f):\n    t = []\n    for _ in range(3):\n        s = time.perf_counter(); f(); t.append(time.perf_counter() - s)\n    return min(t) * 1e9 / len(d)\n\
         print(best(lambda: VQF({dt}).updateBatch(g, a, m)), best(lambda: VQF({dt}).updateBatch(g, a)))\n",
        raw.display(),
        dt = 1.0 / RATE_HZ
    );
    let out = Command::new(python).args(["-c", &script]).output().ok()?;
    if !out.status.success() {
        eprintln!("PyPI vqf: {}", String::from_utf8_lossy(&out.stderr));
        return None;
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut v = text.split_whitespace().filter_map(|x| x.parse().ok());
    Some((v.next()?, v.next()?))
}

/// Nanoseconds per sample of `fusion::fuse` over the readings as one sensor's track (the whole
/// path a conversion takes: steps, the filter, the track out), best of 3.
fn fuse_ns(spec: &str, data: &[[f64; 9]]) -> f64 {
    use imubake::take::{ImuSample, Track};
    let times: Vec<f64> = (0..data.len()).map(|i| i as f64 / RATE_HZ).collect();
    let inertial = Track::new(
        times.clone(),
        data.iter()
            .map(|r| ImuSample {
                gyro_rad_s: Vector3::new(r[0], r[1], r[2]),
                accel_m_s2: Vector3::new(r[3], r[4], r[5]),
            })
            .collect(),
    )
    .expect("track");
    let mag = Track::new(
        times,
        data.iter()
            .map(|r| Vector3::new(r[6], r[7], r[8]))
            .collect(),
    )
    .expect("track");
    let fusion: Fusion = spec.parse().expect("filter");
    (0..3)
        .map(|_| {
            let start = Instant::now();
            black_box(imubake::fusion::fuse("s", &inertial, Some(&mag), &fusion).expect("fuse"));
            start.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
        * 1e9
        / data.len() as f64
}

fn main() {
    let data = readings();
    let dir = tempfile::tempdir().expect("temp dir");
    println!("per sample, one core, {SAMPLES} samples at {RATE_HZ} Hz (best of 3):");
    let mut results = Vec::new();
    for spec in [
        "vqf",
        "vqf:6d",
        "madgwick",
        "madgwick:6d",
        "mahony",
        "mahony:6d",
        "trust",
        "gyro",
    ] {
        let ns = per_sample_ns(spec, &data);
        println!("  {spec:<12} {ns:>7.1} ns");
        results.push((spec, ns));
    }
    let ns = |spec: &str| {
        results
            .iter()
            .find(|(s, _)| *s == spec)
            .map(|r| r.1)
            .unwrap()
    };
    let madgwick_ok = ns("madgwick") <= 150.0;
    println!("Madgwick 9D: {:.1} ns (target ≤ 150 ns)", ns("madgwick"));
    let (online, offline) = (fuse_ns("vqf", &data), fuse_ns("offline", &data));
    let offline_ok = offline <= 3.0 * online;
    println!(
        "whole track through fuse(): online VQF {online:.1} ns, offline {offline:.1} ns per sample = {:.2}× (target ≤ 3×)",
        offline / online
    );
    let vqf_ok = match vqf_cpp_ns(&data, dir.path()) {
        Some((nine, six)) => {
            println!(
                "VQF's C++ (PyPI vqf, updateBatch): 9D {nine:.1} ns, 6D {six:.1} ns; imubake's default \
                 (vqf-rs) 9D {:.1} ns, 6D {:.1} ns (target: no slower)",
                ns("vqf"),
                ns("vqf:6d")
            );
            ns("vqf") <= nine && ns("vqf:6d") <= six
        }
        None => {
            println!("VQF's C++: not measured (no Python with PyPI vqf)");
            false
        }
    };

    // The 60-minute raw log and its orientation twin through convert.
    let minutes = minutes_from_env();
    let (twin, raw) = (dir.path().join("twin.csv"), dir.path().join("raw.csv"));
    let twin_mb = write_log(&twin, minutes, &PAPER000_SENSORS).expect("twin") as f64 / 1e6;
    let raw_mb = write_raw_log(&raw, minutes, &PAPER000_SENSORS).expect("raw") as f64 / 1e6;
    let mapping = Path::new(env!("CARGO_MANIFEST_DIR")).join("mappings/paper000_16imu_mixamo.json");
    let mut settings = ConvertSettings {
        mapping: Some(mapping),
        ..ConvertSettings::default()
    };
    settings.pipeline.fps = "60".parse().expect("fps");
    // The synthetic log spins every sensor from its first sample: no body gives a heading.
    settings.pipeline.heading = Some(imubake::mapping::HeadingPolicy::Sensors);
    let time = |input: &Path, fusion: Option<&str>| {
        let out = dir.path().join("out");
        let mut settings = settings.clone();
        settings.pipeline.fusion = fusion.map(|f| f.parse().expect("filter"));
        let plan = imubake::convert::Plan::resolve(settings).expect("a plan");
        (0..2)
            .map(|_| {
                let start = Instant::now();
                convert(input, &out, &plan).expect("convert");
                start.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let twin_s = time(&twin, None);
    let (raw_s, raw_online_s) = (time(&raw, None), time(&raw, Some("vqf")));
    println!(
        "convert {minutes} min × 16 sensors at 100 Hz: orientation twin ({twin_mb:.0} MB) {twin_s:.2} s; \
         raw readings ({raw_mb:.0} MB) with the offline default {raw_s:.2} s = {:.2}×, with online \
         VQF {raw_online_s:.2} s = {:.2}× (target ≤ 2×)",
        raw_s / twin_s,
        raw_online_s / twin_s
    );
    let ok = madgwick_ok && vqf_ok && offline_ok && raw_s <= 2.0 * twin_s;
    println!("{}", if ok { "targets met" } else { "TARGETS MISSED" });
}
