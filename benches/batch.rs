//! Benchmark: `batch` throughput on a library of one-minute takes (16 sensors at 100 Hz, paper
//! 000's mapping, onto mixamo at 60 fps, BVH + GLB + sidecar, default settings) with one job and
//! with the default `--jobs` (one per core), and the rerun that skips everything (ledger).
//!
//! Target (issue 23): 200 one-minute takes at least 40 takes/s with the default `--jobs`. (Issue
//! 6 asked 2 jobs to be 1.6× one job; since issue 23 one conversion already parses, smooths and
//! writes on every core, so a second job has little left to add, and that ratio is only shown.)
//!
//!   cargo bench --bench batch
//!   IMUBAKE_BENCH_TAKES=40 cargo bench --bench batch
//!
//! The takes are hard links of one generated log (distinct names, so distinct takes and outputs;
//! the disk holds one copy), each read, hashed and converted in full.

mod common;

use common::{HostProbe, PAPER000_SENSORS, write_log};
use imubake::batch::{DiscoverOptions, Summary, discover, run};
use imubake::convert::ConvertSettings;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

fn main() {
    let takes: usize = std::env::var("IMUBAKE_BENCH_TAKES")
        .ok()
        .and_then(|t| t.parse().ok())
        .unwrap_or(200);
    let dir = tempfile::tempdir().expect("temp dir");
    let input = dir.path().join("in");
    std::fs::create_dir_all(input.join("day2")).expect("input folder");
    let first = input.join("take000.csv");
    let bytes = write_log(&first, 1, &PAPER000_SENSORS).expect("write the log");
    for i in 1..takes {
        // Half the library in a sub-folder, as a studio's would be.
        let sub = if i % 2 == 0 { "" } else { "day2/" };
        std::fs::hard_link(&first, input.join(format!("{sub}take{i:03}.csv"))).expect("link");
    }
    let mapping = Path::new(env!("CARGO_MANIFEST_DIR")).join("mappings/paper000_16imu_mixamo.json");
    let mut settings = ConvertSettings {
        mapping: Some(mapping),
        ..ConvertSettings::default()
    };
    settings.pipeline.fps = "60".parse().expect("fps");
    // The synthetic log spins every sensor from its first sample: no body gives a heading.
    settings.pipeline.heading = Some(imubake::mapping::HeadingPolicy::Sensors);
    let plan = imubake::convert::Plan::resolve(settings).expect("a plan");
    let library = discover(std::slice::from_ref(&input), DiscoverOptions::default())
        .expect("discover")
        .takes;
    assert_eq!(library.len(), takes);
    println!(
        "{takes} one-minute takes (16 sensors at 100 Hz, {:.1} MB each) → BVH + GLB at 60 fps",
        bytes as f64 / 1e6
    );

    println!("before: {}", HostProbe::measure());
    let never_stop = AtomicBool::new(false);
    let batch = |out: &Path, jobs: usize| {
        run(&library, out, None, &plan, jobs, &never_stop, &|_| {}).expect("batch")
    };
    let mut throughput = Vec::new();
    // 0 is the default: one job per core.
    for jobs in [1, 0] {
        let out = dir.path().join(format!("out{jobs}"));
        let start = Instant::now();
        let results = batch(&out, jobs);
        let secs = start.elapsed().as_secs_f64();
        let summary = Summary::of(&results);
        assert_eq!(summary.converted, takes, "{summary}");
        let rate = takes as f64 / secs;
        println!(
            "{}: {secs:.2} s, {rate:.2} takes/s ({:.1} ms per take)",
            if jobs == 1 {
                "1 job".to_string()
            } else {
                format!(
                    "default --jobs ({})",
                    std::thread::available_parallelism().map_or(1, |n| n.get())
                )
            },
            1000.0 * secs / takes as f64
        );
        throughput.push(rate);
        if jobs == 0 {
            let start = Instant::now();
            let results = batch(&out, jobs);
            let summary = Summary::of(&results);
            assert_eq!(summary.skipped, takes, "{summary}");
            println!(
                "rerun, everything current (ledger): {:.3} s",
                start.elapsed().as_secs_f64()
            );
        }
        std::fs::remove_dir_all(&out).expect("clean up");
    }
    println!(
        "default --jobs / 1 job: {:.2}×",
        throughput[1] / throughput[0]
    );
    println!("after: {}", HostProbe::measure());
    let ok = throughput[1] >= 40.0;
    println!(
        "default --jobs: {:.1} takes/s (target ≥ 40): {}",
        throughput[1],
        if ok { "target met" } else { "TARGET MISSED" }
    );
}
