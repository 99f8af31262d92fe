//! `convert` on an 8 GB sparse file of NUL bytes is refused by its content after reading at most
//! 1 MiB of it (issue 10), counted with the kernel's own tally of bytes this process read
//! (`/proc/self/io`, `rchar`). This file holds only this test, so no other test's reads count.

#![cfg(target_os = "linux")]

use imubake::convert::{ConvertSettings, Plan, convert};
use std::sync::mpsc;
use std::time::Duration;

fn bytes_read_by_this_process() -> u64 {
    let io = std::fs::read_to_string("/proc/self/io").expect("/proc/self/io");
    io.lines()
        .find_map(|l| l.strip_prefix("rchar:"))
        .and_then(|v| v.trim().parse().ok())
        .expect("rchar in /proc/self/io")
}

#[test]
fn an_8_gb_nul_file_is_refused_after_at_most_1_mib() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("zeros.csv");
    let file = std::fs::File::create(&input).unwrap();
    file.set_len(8 << 30).unwrap();
    drop(file);
    let out = dir.path().join("out");
    let before = bytes_read_by_this_process();
    // Guarded against a hang: the conversion runs on a thread, and the test gives up on it.
    let (tx, rx) = mpsc::channel();
    let job = input.clone();
    std::thread::spawn(move || {
        let plan = Plan::resolve(ConvertSettings::default()).unwrap();
        let result = convert(&job, &out, &plan);
        let _ = tx.send(result.map(|_| ()).map_err(|e| e.to_string()));
    });
    let result = rx
        .recv_timeout(Duration::from_secs(120))
        .expect("convert did not return within 120 s: it is reading the whole file");
    let read = bytes_read_by_this_process() - before;
    let err = result.expect_err("a file of NUL bytes is not a capture");
    assert!(err.contains("looks binary"), "{err}");
    assert!(read <= 1 << 20, "read {read} bytes of the file");
}
