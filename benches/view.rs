//! Benchmark: how long a converted 60-minute take takes to open in `imubake view` — from starting
//! the command to the page having what it draws first: the server's URL printed, `/take.json`
//! and the first chunk (`/chunk/0.glb`, 60 s) received over HTTP. The take is the convert
//! benchmark's log (16 sensors at 100 Hz) converted onto mixamo at 60 fps (BVH + GLB + sidecar);
//! the viewer opens its sidecar. The browser's own start and WebGL set-up are not counted.
//!
//! Target (issue 20): under 2 s, median of 5 runs.
//!
//!   cargo bench --bench view
//!   IMUBAKE_BENCH_MINUTES=5 cargo bench --bench view

mod common;

use common::{PAPER000_SENSORS, median, minutes_from_env, write_log};
use imubake::convert::{ConvertSettings, convert};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

fn get(authority: &str, target: &str) -> usize {
    let mut s = TcpStream::connect(authority).expect("connect");
    write!(
        s,
        "GET {target} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n\r\n"
    )
    .expect("request");
    let mut body = Vec::new();
    s.read_to_end(&mut body).expect("response");
    assert!(body.starts_with(b"HTTP/1.1 200"), "{target}");
    body.len()
}

fn main() {
    let minutes = minutes_from_env();
    let dir = tempfile::tempdir().expect("temp dir");
    let input = dir.path().join("long.csv");
    write_log(&input, minutes, &PAPER000_SENSORS).expect("write the log");
    let mapping = Path::new(env!("CARGO_MANIFEST_DIR")).join("mappings/paper000_16imu_mixamo.json");
    let mut settings = ConvertSettings {
        mapping: Some(mapping),
        ..ConvertSettings::default()
    };
    settings.pipeline.fps = "60".parse().expect("fps");
    // The synthetic log spins every sensor from its first sample: no body gives a heading.
    settings.pipeline.heading = Some(imubake::mapping::HeadingPolicy::Sensors);
    let out = dir.path().join("out");
    let plan = imubake::convert::Plan::resolve(settings).expect("a plan");
    let outcome = convert(&input, &out, &plan).expect("convert");
    let bvh_mb = std::fs::metadata(out.join("long.bvh")).map_or(0, |m| m.len()) as f64 / 1e6;
    println!(
        "take: {minutes} min, {} frames at 60 fps on mixamo, BVH {bvh_mb:.0} MB",
        outcome.sidecar.frames
    );

    let mut runs = Vec::new();
    for _ in 0..5 {
        let start = Instant::now();
        let mut child = Command::new(env!("CARGO_BIN_EXE_imubake"))
            .arg("view")
            .arg(&outcome.sidecar_path)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("imubake view");
        let mut line = String::new();
        BufReader::new(child.stdout.take().expect("stdout"))
            .read_line(&mut line)
            .expect("its URL");
        let listening = start.elapsed().as_secs_f64();
        let url = line
            .split_whitespace()
            .find(|w| w.starts_with("http://"))
            .expect("a URL");
        let authority = url.trim_start_matches("http://").trim_end_matches('/');
        get(authority, "/take.json");
        let glb = get(authority, "/chunk/0.glb");
        let opened = start.elapsed().as_secs_f64();
        let _ = child.kill();
        let _ = child.wait();
        println!(
            "open: listening after {listening:.3} s, take.json and the first chunk ({:.1} MB) after {opened:.3} s",
            glb as f64 / 1e6
        );
        runs.push(opened);
    }
    let median = median(runs);
    println!("open a {minutes}-minute take: median of 5 {median:.3} s (target < 2 s)");
    println!(
        "{}",
        if median < 2.0 {
            "targets met"
        } else {
            "TARGETS MISSED"
        }
    );
}
