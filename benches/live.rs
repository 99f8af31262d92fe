//! A live session under load (issue 18): 16 sensors at 100 Hz arriving over UDP on loopback
//! (one datagram per sample tick, 16 rows), poses at 60 fps sent as VMC to a local receiver.
//!
//! Measured by the session itself: from the arrival of the datagram holding the sample that
//! completes frame n (the source thread's receive) to frame n's bundle being sent; and the
//! process's CPU time (getrusage: the session, its source thread and the sender here) over the
//! wall time. `IMUBAKE_BENCH_SECONDS` sets the length (default 30 s).
//!
//! Targets: median ≤ 2 ms, p99 ≤ 5 ms; CPU ≤ 10 % of one core. Run twice: the session alone, and
//! with `imubake setup`'s board fed by the same session and its page connected (a WebSocket
//! client reading the board ten times a second, as the page does): issue 55's "the live
//! benchmark's targets hold with the page connected".

mod common;

use common::{Cpu, PAPER000_SENSORS, RATE_HZ};
use imubake::convert::ConvertSettings;
use imubake::live::{LiveSettings, Report};
use std::net::UdpSocket;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

fn main() {
    let seconds: f64 = std::env::var("IMUBAKE_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(30.0);
    session(seconds, false);
    session(seconds, true);
}

/// The setup page: a board on the session's samples, served, with a WebSocket client reading it.
fn setup_page(stop: &Arc<AtomicBool>) -> (Arc<imubake::setup::Setup>, Arc<AtomicU64>) {
    use imubake::setup::board::Board;
    use imubake::view::{ServeOptions, Server, ViewTake};
    let rig = imubake::rig::builtin_rig("mixamo").unwrap().unwrap();
    let setup = Arc::new(imubake::setup::Setup::new(
        Board::of_rig(&rig),
        std::env::temp_dir().join("imubake-bench-setup"),
        rig.clone(),
        "mixamo".into(),
        Vec::new(),
    ));
    let server = Server::bind(
        ViewTake::live(rig, "60".parse().unwrap(), Vec::new()),
        &ServeOptions {
            listen: "127.0.0.1:0".parse().unwrap(),
        },
        None,
    )
    .unwrap()
    .with_setup(Arc::clone(&setup));
    let addr = server.addr();
    let serving = Arc::clone(stop);
    std::thread::spawn(move || server.run(&serving));
    let boards = Arc::new(AtomicU64::new(0));
    let counting = Arc::clone(&boards);
    let reading = Arc::clone(stop);
    std::thread::spawn(move || {
        let request = tungstenite::http::Request::builder()
            .uri(format!("ws://{addr}/setup"))
            .header("Host", addr.to_string())
            .header("Origin", format!("http://{addr}"))
            .header("Connection", "Upgrade")
            .header("Upgrade", "websocket")
            .header("Sec-WebSocket-Version", "13")
            .header(
                "Sec-WebSocket-Key",
                tungstenite::handshake::client::generate_key(),
            )
            .body(())
            .unwrap();
        let (mut socket, _) = tungstenite::connect(request).expect("the setup socket");
        while !reading.load(Ordering::Relaxed) {
            if socket.read().is_err() {
                return;
            }
            counting.fetch_add(1, Ordering::Relaxed);
        }
    });
    (setup, boards)
}

fn session(seconds: f64, with_page: bool) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let port = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    // The VMC receiver: drains the bundles and counts them.
    let receiver = UdpSocket::bind("127.0.0.1:0").unwrap();
    let vmc = receiver.local_addr().unwrap();
    receiver
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let received = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let counting = Arc::clone(&received);
    std::thread::spawn(move || {
        let mut buf = vec![0u8; 65_536];
        loop {
            if receiver.recv(&mut buf).is_ok() {
                counting.fetch_add(1, Ordering::Relaxed);
            }
        }
    });
    let mut convert = ConvertSettings {
        mapping: Some(root.join("mappings/paper000_16imu_mixamo.json")),
        ..Default::default()
    };
    convert.pipeline.fps = "60".parse().unwrap();
    convert.pipeline.causal = true;
    let stop = Arc::new(AtomicBool::new(false));
    let page = with_page.then(|| setup_page(&stop));
    let settings = LiveSettings {
        sources: vec![format!("udp:{port}").parse().unwrap()],
        plan: std::sync::Arc::new(imubake::convert::Plan::resolve(convert).unwrap()),
        vmc: Some(vmc),
        listen: None,
        record: None,
        allow: Default::default(),
        clock: None,
        keys: false,
        preview: None,
        setup: page.as_ref().map(|(s, _)| Arc::clone(s)),
        time_horizon_s: imubake::live::clock::DEFAULT_HORIZON_S,
    };
    let stopper = Arc::clone(&stop);
    // The sensors: a header, then every 10 ms one datagram of 16 rows, in real time.
    let sender = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(300));
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        let target = format!("127.0.0.1:{port}");
        socket
            .send_to(b"time_s,sensor,qw,qx,qy,qz", &target)
            .unwrap();
        let start = Instant::now();
        let ticks = (seconds * RATE_HZ as f64) as usize;
        let mut datagram = String::with_capacity(2048);
        for i in 0..ticks {
            let due = Duration::from_secs_f64(i as f64 / RATE_HZ as f64);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
            datagram.clear();
            for (s, name) in PAPER000_SENSORS.iter().enumerate() {
                let t = i as f64 / RATE_HZ as f64;
                let angle = 0.01 * i as f64 + s as f64;
                let (half_sin, half_cos) = (angle / 2.0).sin_cos();
                datagram.push_str(&format!(
                    "{t:.4},{name},{half_cos:.6},{:.6},0.000000,{:.6}\n",
                    0.6 * half_sin,
                    0.8 * half_sin
                ));
            }
            socket.send_to(datagram.as_bytes(), &target).unwrap();
        }
        std::thread::sleep(Duration::from_millis(300));
        stopper.store(true, Ordering::Relaxed);
    });
    let (cpu0, wall0) = (Cpu::now(), Instant::now());
    let summary = imubake::live::run(&settings, stop, |r| {
        if let Report::Notice(n) = r {
            eprintln!("{n}");
        }
    })
    .expect("the session");
    let (cpu, wall) = (
        Cpu::now().since(cpu0).total_s(),
        wall0.elapsed().as_secs_f64(),
    );
    sender.join().unwrap();
    let (median, p99) = summary.latency_ms.expect("frames went out");
    if let Some((_, boards)) = &page {
        println!(
            "with the setup page connected: {} boards received over its WebSocket",
            boards.load(Ordering::Relaxed)
        );
    }
    println!(
        "{seconds} s of 16 sensors at {RATE_HZ} Hz over UDP: {} lines, {} frames at 60 fps, {} bundles received, {} lines overflowed",
        summary.lines,
        summary.frames,
        received.load(Ordering::Relaxed),
        summary.overflowed
    );
    println!(
        "latency arrival → bundle sent: median {median:.3} ms, p99 {p99:.3} ms (targets 2 and 5 ms); \
         CPU {:.1} % of one core ({cpu:.2} s over {wall:.1} s; target 10 %)",
        100.0 * cpu / wall
    );
}
