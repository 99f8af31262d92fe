//! Benchmark: reading a 60-minute, 16-sensor, 100 Hz imubake CSV of quaternions
//! (`time_s` with 4 decimals, quaternions with 6; ≈5.8 M rows, ≈298 MB), parsed in blocks on
//! every core and merged in file order (`read::blocks`).
//!
//! Targets: at least 600 MB/s on this machine's cores (issue 23; issue 2 asked 150 MB/s on one)
//! and peak memory at most 64 bytes per sample above the process's base (issue 2). Peak memory is the kernel's high-water mark of
//! resident memory (VmHWM, reset through /proc/self/clear_refs before the read).
//!
//!   cargo bench --bench read_csv                     # the full 60-minute log
//!   IMUBAKE_BENCH_MINUTES=5 cargo bench --bench read_csv

mod common;

use common::{HostProbe, RATE_HZ, median, minutes_from_env, reset_peak, status_kib, write_log};
use imubake::read::{ReadOptions, read_take};
use std::time::Instant;

const SENSORS: [&str; 16] = [
    "s00", "s01", "s02", "s03", "s04", "s05", "s06", "s07", "s08", "s09", "s10", "s11", "s12",
    "s13", "s14", "s15",
];

fn main() {
    let minutes = minutes_from_env();
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bench.csv");
    let bytes = write_log(&path, minutes, &SENSORS).expect("write the log");
    let rows = minutes * 60 * RATE_HZ * SENSORS.len();
    println!(
        "log: {minutes} min, {} sensors at {RATE_HZ} Hz = {rows} rows, {:.1} MB",
        SENSORS.len(),
        bytes as f64 / 1e6
    );
    let options = ReadOptions::default();

    // Peak memory of one read, measured first so earlier runs' freed pages do not hide it.
    reset_peak();
    let base_kib = status_kib("VmRSS:").unwrap_or(0);
    let take = read_take(&path, &options).expect("read");
    let peak_kib = status_kib("VmHWM:").unwrap_or(0);
    let samples = take.total_samples();
    assert_eq!(samples, rows, "every row is a sample");
    drop(take);
    let per_sample = (peak_kib.saturating_sub(base_kib) * 1024) as f64 / samples as f64;

    // After the memory's read, so that the probe's threads and pages do not change the peak.
    println!("before: {}", HostProbe::measure());
    let mut times = Vec::new();
    for _ in 0..5 {
        let start = Instant::now();
        let take = read_take(&path, &options).expect("read");
        times.push(start.elapsed().as_secs_f64());
        assert_eq!(take.total_samples(), rows);
    }
    let median = median(times);
    let mb_s = bytes as f64 / 1e6 / median;
    println!(
        "read on {} core(s): median of 5 {median:.3} s = {mb_s:.0} MB/s (target ≥ 600 MB/s)",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!("peak memory: {per_sample:.1} bytes/sample above base (target ≤ 64)");
    println!("after: {}", HostProbe::measure());
    let ok = mb_s >= 600.0 && per_sample <= 64.0;
    println!("{}", if ok { "targets met" } else { "TARGETS MISSED" });
}
