//! Benchmark: reading a 60-minute, 16-sensor, 100 Hz imubake CSV of quaternions
//! (`time_s` with 4 decimals, quaternions with 6; ≈5.8 M rows, ≈285 MB) on one core.
//!
//! Targets (issue 2): at least 150 MB/s (≤ 2 s for the whole log) and peak memory at most
//! 64 bytes per sample above the process's base. Peak memory is the kernel's high-water mark of
//! resident memory (VmHWM, reset through /proc/self/clear_refs before the read).
//!
//!   cargo bench --bench read_csv                     # the full 60-minute log
//!   IMUBAKE_BENCH_MINUTES=5 cargo bench --bench read_csv

use imubake::read::{ReadOptions, read_take};
use std::io::{BufWriter, Write};
use std::time::Instant;

const SENSORS: usize = 16;
const RATE_HZ: usize = 100;

fn write_log(path: &std::path::Path, minutes: usize) -> std::io::Result<u64> {
    let mut out = BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    writeln!(out, "time_s,sensor,qw,qx,qy,qz")?;
    let frames = minutes * 60 * RATE_HZ;
    for i in 0..frames {
        for s in 0..SENSORS {
            // Sensors sample asynchronously: each is offset by 0.3 ms.
            let t = i as f64 / RATE_HZ as f64 + s as f64 * 0.0003;
            let angle = 0.01 * i as f64 + s as f64;
            let (half_sin, half_cos) = (angle / 2.0).sin_cos();
            let axis = [0.6, 0.0, 0.8];
            writeln!(
                out,
                "{t:.4},s{s:02},{:.6},{:.6},{:.6},{:.6}",
                half_cos,
                axis[0] * half_sin,
                axis[1] * half_sin,
                axis[2] * half_sin
            )?;
        }
    }
    out.flush()?;
    Ok(std::fs::metadata(path)?.len())
}

fn status_kib(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(field))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn main() {
    let minutes: usize = std::env::var("IMUBAKE_BENCH_MINUTES")
        .ok()
        .and_then(|m| m.parse().ok())
        .unwrap_or(60);
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bench.csv");
    let bytes = write_log(&path, minutes).expect("write the log");
    let rows = minutes * 60 * RATE_HZ * SENSORS;
    println!(
        "log: {minutes} min, {SENSORS} sensors at {RATE_HZ} Hz = {rows} rows, {:.1} MB",
        bytes as f64 / 1e6
    );
    let options = ReadOptions::default();

    // Peak memory of one read, measured first so earlier runs' freed pages do not hide it.
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    let base_kib = status_kib("VmRSS:").unwrap_or(0);
    let take = read_take(&path, &options).expect("read");
    let peak_kib = status_kib("VmHWM:").unwrap_or(0);
    let samples = take.total_samples();
    assert_eq!(samples, rows, "every row is a sample");
    drop(take);
    let per_sample = (peak_kib.saturating_sub(base_kib) * 1024) as f64 / samples as f64;

    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let start = Instant::now();
        let take = read_take(&path, &options).expect("read");
        let secs = start.elapsed().as_secs_f64();
        assert_eq!(take.total_samples(), rows);
        best = best.min(secs);
    }
    let mb_s = bytes as f64 / 1e6 / best;
    println!("read: best of 3 {best:.3} s = {mb_s:.0} MB/s (target ≥ 150 MB/s)");
    println!("peak memory: {per_sample:.1} bytes/sample above base (target ≤ 64)");
    let ok = mb_s >= 150.0 && per_sample <= 64.0;
    println!("{}", if ok { "targets met" } else { "TARGETS MISSED" });
}
