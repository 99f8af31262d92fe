//! Benchmark: `convert` end to end (read, pipeline, BVH and GLB written, sidecar) of the
//! 60-minute, 16-sensor, 100 Hz log of issue 2 onto the mixamo rig at 60 fps, with paper 000's
//! 16-sensor mapping.
//!
//! Targets (issue 3): at most 5 s, peak memory at most 1 GB.
//!
//!   cargo bench --bench convert
//!   IMUBAKE_BENCH_MINUTES=5 cargo bench --bench convert

mod common;

use common::{minutes_from_env, reset_peak, status_kib, write_log};
use imubake::convert::{ConvertSettings, convert};
use std::path::Path;
use std::time::Instant;

const SENSORS: [&str; 16] = [
    "pelvis",
    "sternum",
    "left_shoulder_blade",
    "left_upper_arm",
    "left_forearm",
    "left_hand",
    "left_thigh",
    "left_shank",
    "left_foot",
    "right_shoulder_blade",
    "right_upper_arm",
    "right_forearm",
    "right_hand",
    "right_thigh",
    "right_shank",
    "right_foot",
];

fn main() {
    let minutes = minutes_from_env();
    let dir = tempfile::tempdir().expect("temp dir");
    let input = dir.path().join("long.csv");
    let bytes = write_log(&input, minutes, &SENSORS).expect("write the log");
    let mapping = Path::new(env!("CARGO_MANIFEST_DIR")).join("mappings/paper000_16imu_mixamo.json");
    let mut settings = ConvertSettings {
        mapping: Some(mapping),
        ..ConvertSettings::default()
    };
    settings.pipeline.fps = "60".parse().expect("fps");
    println!(
        "log: {minutes} min, 16 sensors at 100 Hz, {:.1} MB; convert to BVH + GLB at 60 fps",
        bytes as f64 / 1e6
    );

    let out = dir.path().join("out");
    reset_peak();
    let base_kib = status_kib("VmRSS:").unwrap_or(0);
    let start = Instant::now();
    let outcome = convert(&input, &out, &settings).expect("convert");
    let first = start.elapsed().as_secs_f64();
    let peak_mb = (status_kib("VmHWM:").unwrap_or(0).saturating_sub(base_kib)) as f64 / 1024.0;
    let frames = outcome.sidecar.frames;
    let mut best = first;
    for _ in 0..2 {
        let start = Instant::now();
        convert(&input, &out, &settings).expect("convert");
        best = best.min(start.elapsed().as_secs_f64());
    }
    let size = |ext: &str| {
        std::fs::metadata(out.join(format!("long.{ext}"))).map_or(0, |m| m.len()) as f64 / 1e6
    };
    println!(
        "frames: {frames}; BVH {:.1} MB, GLB {:.1} MB",
        size("bvh"),
        size("glb")
    );
    println!("convert: best of 3 {best:.2} s (target ≤ 5 s)");
    println!("peak memory: {peak_mb:.0} MB above base (target ≤ 1024 MB)");
    println!(
        "{}",
        if best <= 5.0 && peak_mb <= 1024.0 {
            "targets met"
        } else {
            "TARGETS MISSED"
        }
    );
}
