//! Benchmark: a live stream — 16 sensors at 100 Hz (paper 000's mapping onto mixamo), imubake CSV
//! rows pushed one at a time through the line parser, the reorder buffer, the cleaning rules and
//! the pipeline's incremental cores (causal Butterworth smoothing), poses out at 60 fps.
//!
//! Targets (issue 12): per frame at most 100 µs of processing (the rows that arrive during a frame
//! included), and no allocation per frame once warmed up (a counting allocator).
//!
//!   cargo bench --bench stream
//!   IMUBAKE_BENCH_MINUTES=1 cargo bench --bench stream
//!   IMUBAKE_BENCH_FOOT_LOCK=1 cargo bench --bench stream   # with `--foot-lock`

mod common;

use common::{PAPER000_SENSORS, RATE_HZ};
use imubake::anim::Pose;
use imubake::mapping::{MappingFile, load_mapping};
use imubake::pipeline::PipelineOptions;
use imubake::pipeline::stream::PoseStream;
use imubake::read::stream::{LineFormat, LineStream};
use imubake::rig::load_rig;
use imubake::world::World;
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// The system allocator, counting allocations.
struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn main() {
    let minutes: usize = std::env::var("IMUBAKE_BENCH_MINUTES")
        .ok()
        .and_then(|m| m.parse().ok())
        .unwrap_or(2);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mapping_path = root.join("mappings/paper000_16imu_mixamo.json");
    let MappingFile::Quaternion(mapping) = load_mapping(&mapping_path).expect("mapping") else {
        panic!("a quaternion mapping");
    };
    let rig = load_rig("mixamo").expect("rig");
    // With `IMUBAKE_BENCH_FOOT_LOCK=1`, stage 8 too (`--foot-lock`: the planted feet held by IK).
    let foot_lock = std::env::var("IMUBAKE_BENCH_FOOT_LOCK").is_ok_and(|v| v == "1");
    let options = PipelineOptions {
        fps: "60".parse().expect("fps"),
        causal: true,
        foot_lock,
        ..PipelineOptions::default()
    };
    // The rows, made before the clock starts (the synthetic log of benches/common, in memory).
    let frames_in = minutes * 60 * RATE_HZ;
    let mut rows: Vec<Vec<u8>> = Vec::with_capacity(frames_in * PAPER000_SENSORS.len());
    for i in 0..frames_in {
        for (s, name) in PAPER000_SENSORS.iter().enumerate() {
            let t = i as f64 / RATE_HZ as f64 + s as f64 * 0.0003;
            let angle = 0.01 * i as f64 + s as f64;
            let (half_sin, half_cos) = (angle / 2.0).sin_cos();
            rows.push(
                format!(
                    "{t:.4},{name},{half_cos:.6},{:.6},0.000000,{:.6}",
                    0.6 * half_sin,
                    0.8 * half_sin
                )
                .into_bytes(),
            );
        }
    }
    let mut lines = LineStream::new(LineFormat::ImubakeCsv, "bench", None);
    let mut samples = Vec::with_capacity(64);
    lines
        .push_line(1, b"time_s,sensor,qw,qx,qy,qz", &mut samples)
        .expect("header");
    let mut poses = PoseStream::from_mapping(&rig, &mapping, &mapping_path, World::Enu, &options)
        .expect("stream");
    // Take-stream sensor index → pose-stream sensor index, filled as sensors appear.
    let mut index: Vec<Option<usize>> = Vec::with_capacity(64);
    let mut frames: u64 = 0;
    let mut checksum = 0.0;
    let warm_up_rows = 10 * RATE_HZ * PAPER000_SENSORS.len(); // 10 s
    let (mut warm_frames, mut warm_allocs) = (0, 0);
    let start = Instant::now();
    let mut warm_start = start;
    for (n, row) in rows.iter().enumerate() {
        if n == warm_up_rows {
            warm_frames = frames;
            warm_allocs = ALLOCATIONS.load(Ordering::Relaxed);
            warm_start = Instant::now();
        }
        lines
            .push_line(n as u64 + 2, row, &mut samples)
            .expect("row");
        let ids = lines.take().expect("the header is in").sensor_ids();
        for s in samples.drain(..) {
            let k = s.sensor.index();
            if k >= index.len() {
                index.resize(k + 1, None);
            }
            let i = *index[k].get_or_insert_with(|| poses.sensor_index(&ids[k]).expect("mapped"));
            poses.push(
                i,
                s.t_s,
                s.value.orientation().expect("quaternion rows"),
                &mut |p: &Pose| {
                    frames += 1;
                    checksum += p.local[3].w;
                },
            );
        }
    }
    let streaming = warm_start.elapsed();
    let allocations = ALLOCATIONS.load(Ordering::Relaxed) - warm_allocs;
    let streamed_frames = frames - warm_frames;
    lines.finish(&mut samples).expect("finish");
    let per_frame_us = streaming.as_secs_f64() * 1e6 / streamed_frames as f64;
    println!(
        "{minutes} min of 16 sensors at 100 Hz ({} rows), poses at 60 fps{}: {frames} frames in {:.2} s",
        rows.len(),
        if foot_lock { ", --foot-lock" } else { "" },
        start.elapsed().as_secs_f64()
    );
    println!(
        "after a 10 s warm-up: {streamed_frames} frames, {per_frame_us:.1} µs per frame (target ≤ 100 µs), \
         {allocations} allocations = {:.3} per frame (target 0) [checksum {checksum:.3}]",
        allocations as f64 / streamed_frames as f64
    );
}
