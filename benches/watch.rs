//! Benchmark: `imubake watch` latency, from a take's close (or rename into place) to its sidecar
//! in place, against `imubake convert` of the same file. One-minute takes (16 sensors at 100 Hz,
//! paper 000's mapping, default settings), the release binary watching a temp inbox.
//!
//! Targets (issue 6), medians: events, at most 250 ms more than `convert`; `--poll 200`, at most
//! the poll interval plus 600 ms.
//!
//!   cargo bench --bench watch
//!   IMUBAKE_BENCH_TAKES=20 cargo bench --bench watch
//!
//! Each take is written to a hidden temporary name and renamed into place, or (the "close" rows)
//! written through one handle under its final name and closed; the output folder is polled every
//! 5 ms.

mod common;

use common::{PAPER000_SENSORS, write_log};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_imubake");

fn mapping() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("mappings/paper000_16imu_mixamo.json")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

fn stop(mut child: Child) {
    let _ = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    let _ = child.wait();
}

#[derive(Clone, Copy)]
enum Drop {
    Rename,
    Close,
}

/// Milliseconds from each take's rename or close to its sidecar, one take at a time.
fn latencies(dir: &Path, data: &[u8], poll: Option<u64>, how: Drop, takes: usize) -> Vec<f64> {
    let tag = match (poll, how) {
        (None, Drop::Rename) => "ev-rename",
        (None, Drop::Close) => "ev-close",
        (Some(_), Drop::Rename) => "poll-rename",
        (Some(_), Drop::Close) => "poll-close",
    };
    let (inbox, out) = (
        dir.join(format!("in-{tag}")),
        dir.join(format!("out-{tag}")),
    );
    std::fs::create_dir_all(&inbox).expect("inbox");
    let mut cmd = Command::new(BIN);
    cmd.arg("watch")
        .arg(&inbox)
        .arg("--out")
        .arg(&out)
        .arg("--mapping")
        .arg(mapping())
        // The synthetic log spins every sensor from its first sample: no body gives a heading.
        .args(["--heading", "sensors"]);
    if let Some(ms) = poll {
        cmd.args(["--poll", &ms.to_string()]);
    }
    let child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn imubake watch");
    std::thread::sleep(Duration::from_millis(500));
    let mut ms = Vec::new();
    for i in 0..takes {
        let name = format!("take{i:02}.csv");
        let closed = match how {
            Drop::Rename => {
                let tmp = inbox.join(format!(".{name}.tmp"));
                std::fs::write(&tmp, data).expect("write");
                std::fs::rename(&tmp, inbox.join(&name)).expect("rename");
                Instant::now()
            }
            Drop::Close => {
                let mut f = std::fs::File::create(inbox.join(&name)).expect("create");
                for chunk in data.chunks(1 << 20) {
                    f.write_all(chunk).expect("write");
                }
                drop(f);
                Instant::now()
            }
        };
        let sidecar = out.join(format!("take{i:02}.imubake.json"));
        let deadline = closed + Duration::from_secs(20);
        while !sidecar.exists() {
            assert!(Instant::now() < deadline, "{tag}: no sidecar within 20 s");
            std::thread::sleep(Duration::from_millis(5));
        }
        ms.push(closed.elapsed().as_secs_f64() * 1000.0);
        // Quiet between takes, as between real ones (and so takes do not queue).
        std::thread::sleep(Duration::from_millis(300));
    }
    stop(child);
    ms
}

fn main() {
    let takes: usize = std::env::var("IMUBAKE_BENCH_TAKES")
        .ok()
        .and_then(|t| t.parse().ok())
        .unwrap_or(10);
    let dir = tempfile::tempdir().expect("temp dir");
    let source = dir.path().join("take.csv");
    let bytes = write_log(&source, 1, &PAPER000_SENSORS).expect("write the log");
    let data = std::fs::read(&source).expect("read the log");
    println!(
        "{takes} one-minute takes (16 sensors at 100 Hz, {:.1} MB) → BVH + GLB + sidecar, medians",
        bytes as f64 / 1e6
    );

    let mut convert = Vec::new();
    for i in 0..takes {
        let out = dir.path().join(format!("convert{i}"));
        let start = Instant::now();
        let status = Command::new(BIN)
            .arg("convert")
            .arg(&source)
            .arg("--out")
            .arg(&out)
            .arg("--mapping")
            .arg(mapping())
            .args(["--heading", "sensors"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .expect("run imubake convert");
        assert!(status.success(), "imubake convert failed");
        convert.push(start.elapsed().as_secs_f64() * 1000.0);
    }
    let convert = median(convert);
    println!("imubake convert (whole process):          {convert:7.1} ms");

    let poll = 200u64;
    for (label, mode, how, target) in [
        (
            "events, renamed into place",
            None,
            Drop::Rename,
            convert + 250.0,
        ),
        (
            "events, written and closed",
            None,
            Drop::Close,
            convert + 250.0,
        ),
        (
            "--poll 200, renamed into place",
            Some(poll),
            Drop::Rename,
            poll as f64 + 600.0,
        ),
        (
            "--poll 200, written and closed",
            Some(poll),
            Drop::Close,
            poll as f64 + 600.0,
        ),
    ] {
        let all = latencies(dir.path(), &data, mode, how, takes);
        let med = median(all.clone());
        let max = all.iter().copied().fold(0.0, f64::max);
        println!(
            "watch, {label:<31} {med:7.1} ms (max {max:.1}; target ≤ {target:.0} ms){}",
            if med <= target { "" } else { "  ABOVE TARGET" }
        );
    }
}
