//! `imubake view` and `live --preview` in a real browser: Debian's Chromium, headless, WebGL
//! through SwiftShader, driven by playwright-core (`tests/browser/view.mjs`). What the page shows
//! is checked against the independent numpy BVH reader (`tests/blender_addon/bvh_reference.py`),
//! the sidecar and hand calculations; its chunks by the Khronos glTF-Validator; the server by raw
//! HTTP requests.

use crate::common;

use common::{gltf_validate, imubake_bin, missing, node_modules, python, repo_file, run};
use serde_json::Value;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Debian's Chromium (`IMUBAKE_CHROMIUM` overrides), with playwright-core beside the validator.
pub(crate) fn browser() -> Option<PathBuf> {
    let modules = node_modules()?;
    if !modules.join("playwright-core/package.json").is_file() {
        return missing(&format!(
            "playwright-core in {} (run scripts/test.sh)",
            modules.display()
        ));
    }
    let chromium = std::env::var_os("IMUBAKE_CHROMIUM")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/bin/chromium"));
    if chromium.is_file() {
        Some(modules)
    } else {
        missing(&format!("Chromium at {}", chromium.display()))
    }
}

/// A running server, stopped when dropped.
pub(crate) struct Served {
    child: Child,
    pub(crate) url: String,
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Served {
    /// `host:port` of the URL.
    pub(crate) fn authority(&self) -> &str {
        self.url.trim_start_matches("http://").trim_end_matches('/')
    }
}

/// Starts `cmd` and waits (up to 60 s) for a line on stdout (`view`) or stderr (`live`) holding
/// its URL.
pub(crate) fn serve(mut cmd: Command, url_on_stderr: bool) -> Served {
    cmd.stdout(Stdio::piped()).stderr(Stdio::piped());
    let mut child = cmd.spawn().unwrap();
    let (out, other): (Box<dyn Read + Send>, Box<dyn Read + Send>) = if url_on_stderr {
        (
            Box::new(child.stderr.take().unwrap()),
            Box::new(child.stdout.take().unwrap()),
        )
    } else {
        (
            Box::new(child.stdout.take().unwrap()),
            Box::new(child.stderr.take().unwrap()),
        )
    };
    // Drain the other stream so the server never blocks on a full pipe.
    std::thread::spawn(move || std::io::copy(&mut BufReader::new(other), &mut std::io::sink()));
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut lines = BufReader::new(out).lines();
        let mut sent = false;
        for line in lines.by_ref().map_while(Result::ok) {
            if !sent && let Some(at) = line.find("http://") {
                let url = line[at..].split_whitespace().next().unwrap().to_string();
                let _ = tx.send(url);
                sent = true;
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(60))
        .unwrap_or_else(|_| panic!("{cmd:?} printed no URL"));
    Served { child, url }
}

fn view(args: &[&str]) -> Served {
    let mut cmd = Command::new(imubake_bin());
    cmd.arg("view").args(args);
    serve(cmd, false)
}

/// A raw HTTP/1.1 GET (or `method`) of exactly `target` with `Host: host`: (status, body).
fn http(authority: &str, method: &str, target: &str, host: &str) -> (u16, Vec<u8>) {
    let mut s = TcpStream::connect(authority).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    write!(
        s,
        "{method} {target} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let end = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a header");
    let head = String::from_utf8_lossy(&raw[..end]);
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, raw[end + 4..].to_vec())
}

fn get(served: &Served, target: &str) -> (u16, Vec<u8>) {
    http(served.authority(), "GET", target, served.authority())
}

/// The page driven in Chromium: `tests/browser/view.mjs` with `args`.
fn drive(modules: &Path, args: &[&str]) -> Value {
    let out = run(Command::new("node")
        .arg(repo_file("tests/browser/view.mjs"))
        .args(args)
        .env("IMUBAKE_NODE_MODULES", modules));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Joint positions (metres) by the numpy reader at `frames`.
fn reference(py: &Path, bvh: &Path, metres_per_unit: f64, frames: &[usize]) -> Value {
    let out = run(Command::new(py)
        .arg(repo_file("tests/browser/bvh_reference_positions.py"))
        .arg(bvh)
        .arg(metres_per_unit.to_string())
        .args(frames.iter().map(|f| f.to_string())));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The largest distance, metres, between the page's joints and the reference's.
fn worst_distance(page: &Value, reference: &[Value]) -> f64 {
    let bones = page["bones"].as_array().unwrap();
    assert_eq!(bones.len(), reference.len());
    bones
        .iter()
        .zip(reference)
        .map(|(a, b)| (common::vec3(a) - common::vec3(b)).norm())
        .fold(0.0, f64::max)
}

/// The bundled walk converted at 29.97 fps (BVH in metres, GLB, sidecar) into `dir`.
fn walk(dir: &Path) -> PathBuf {
    run(Command::new(imubake_bin()).args([
        "convert",
        repo_file("samples/walk.csv").to_str().unwrap(),
        "--mapping",
        repo_file("mappings/paper000_16imu_mixamo.json")
            .to_str()
            .unwrap(),
        "--fps",
        "29.97",
        "--out",
        dir.to_str().unwrap(),
    ]));
    dir.join("walk.imubake.json")
}

/// RGB pixels of a PNG screenshot (8-bit RGB or RGBA), and its width.
fn pixels(path: &Path) -> (Vec<[u8; 3]>, usize) {
    let decoder = png::Decoder::new(BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.bit_depth, png::BitDepth::Eight, "{}", path.display());
    let channels = match info.color_type {
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        other => panic!("{}: {other:?}", path.display()),
    };
    buf.truncate(info.buffer_size());
    let rgb = buf
        .chunks_exact(channels)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    (rgb, info.width as usize)
}

/// The screen box of a frame's joints, grown by `margin` pixels: (x0, y0, x1, y1).
fn joint_box(frame: &Value, margin: f64) -> (f64, f64, f64, f64) {
    let mut b = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for p in frame["screen"].as_array().unwrap() {
        let (x, y) = (p[0].as_f64().unwrap(), p[1].as_f64().unwrap());
        b = (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y));
    }
    (b.0 - margin, b.1 - margin, b.2 + margin, b.3 + margin)
}

/// The walk at 29.97 fps in 4-second chunks (120 frames each, 3 chunks), opened at frame 100
/// (chunk 0) and moved to frames 250 (chunk 2) and 130 (chunk 1): no console error; every joint
/// within 1 mm of the numpy reader's forward kinematics of the BVH; the counter and time are the
/// sidecar's frame n at n · 1001 / 30000 s; the screenshots of frames 100 and 130 differ, and
/// where they differ is where the body was.
#[test]
fn the_page_shows_each_frame_where_the_bvh_puts_it() {
    let (Some(modules), Some(py)) = (browser(), python()) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let sidecar_path = walk(dir.path());
    let sidecar: Value = serde_json::from_slice(&std::fs::read(&sidecar_path).unwrap()).unwrap();
    assert_eq!(sidecar["fps"]["num"], 30000);
    assert_eq!(sidecar["fps"]["den"], 1001);
    let frames = sidecar["frames"].as_u64().unwrap() as usize;
    let served = view(&[sidecar_path.to_str().unwrap(), "--chunk-seconds", "4"]);
    assert!(
        served.url.starts_with("http://127.0.0.1:"),
        "{}",
        served.url
    );

    let shots = dir.path().join("shots");
    std::fs::create_dir(&shots).unwrap();
    let page = drive(
        &modules,
        &[
            "take",
            &served.url,
            shots.to_str().unwrap(),
            "100",
            "250",
            "130",
        ],
    );
    assert_eq!(page["console"], serde_json::json!([]), "{page:#}");
    assert_eq!(page["failed"], serde_json::json!([]), "{page:#}");

    let wanted = [100usize, 250, 130];
    let reference = reference(&py, &dir.path().join("walk.bvh"), 1.0, &wanted);
    assert_eq!(reference["count"].as_u64(), Some(frames as u64));
    for (state, n) in page["frames"].as_array().unwrap().iter().zip(wanted) {
        assert_eq!(state["errors"], serde_json::json!([]));
        assert_eq!(state["frame"].as_u64(), Some(n as u64));
        assert_eq!(state["joints"], reference["names"], "joints in rig order");
        let worst = worst_distance(
            state,
            reference["frames"][n.to_string()].as_array().unwrap(),
        );
        eprintln!("frame {n}: worst joint {:.2} µm", worst * 1e6);
        assert!(worst <= 1e-3, "frame {n}: a joint {worst} m from the BVH's");
        // By hand: frame n at n · 1001 / 30000 s; the counter counts to the last frame.
        let t = n as f64 * 1001.0 / 30000.0;
        assert_eq!(state["time_s"].as_f64(), Some(t));
        assert_eq!(
            state["counter"].as_str(),
            Some(format!("frame {n} / {}", frames - 1).as_str())
        );
        assert_eq!(
            state["time_text"].as_str(),
            Some(format!("{t:.3} s").as_str())
        );
    }

    // Where the screenshots differ: above the controls (whose counter changes too), pixels whose
    // colour changed; they must be many and lie where the body was in one frame or the other.
    let states = page["frames"].as_array().unwrap();
    let (a, width) = pixels(Path::new(states[0]["shot"].as_str().unwrap()));
    let (b, _) = pixels(Path::new(states[2]["shot"].as_str().unwrap()));
    let height = a.len() / width;
    let boxes = [joint_box(&states[0], 30.0), joint_box(&states[2], 30.0)];
    for bx in &boxes {
        // The body in view, whole.
        assert!(
            bx.0 > 0.0 && bx.1 > 0.0 && bx.2 < width as f64 && bx.3 < (height - 60) as f64,
            "{bx:?}"
        );
    }
    let inside = |x: f64, y: f64, bx: &(f64, f64, f64, f64)| {
        x >= bx.0 && x <= bx.2 && y >= bx.1 && y <= bx.3
    };
    let (mut changed, mut near_body, mut in_box) = (0usize, 0usize, [0usize; 2]);
    for y in 0..height - 60 {
        for x in 0..width {
            let i = y * width + x;
            let d: u32 = (0..3).map(|c| a[i][c].abs_diff(b[i][c]) as u32).sum();
            if d > 48 {
                changed += 1;
                let (fx, fy) = (x as f64, y as f64);
                if boxes.iter().any(|bx| inside(fx, fy, bx)) {
                    near_body += 1;
                }
                for (k, bx) in boxes.iter().enumerate() {
                    if inside(fx, fy, bx) {
                        in_box[k] += 1;
                    }
                }
            }
        }
    }
    eprintln!("{changed} pixels changed, {near_body} by the body, per frame's box {in_box:?}");
    assert!(changed > 2000, "{changed} pixels changed");
    assert!(
        near_body as f64 >= 0.98 * changed as f64,
        "{near_body} of {changed} changed pixels by the body"
    );
    assert!(in_box.iter().all(|&n| n > 500), "{in_box:?}");
}

/// Each chunk is a valid GLB (Khronos validator: 0 errors, 0 warnings) keyed at its own frames'
/// times: chunk 1 of 120-frame chunks starts at 120 · 1001 / 30000 s and ends at 240 · 1001 /
/// 30000 s; the page's description says so; no chunk past the last.
#[test]
fn chunks_are_valid_glbs_of_their_time_windows() {
    let Some(modules) = node_modules() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let sidecar_path = walk(dir.path());
    let served = view(&[sidecar_path.to_str().unwrap(), "--chunk-seconds", "4"]);
    let (status, take) = get(&served, "/take.json");
    assert_eq!(status, 200);
    let take: Value = serde_json::from_slice(&take).unwrap();
    // 4 s at 29.97 fps = 119.88 → 120 frames a chunk; 356 frames → chunks [0,120] [120,240] [240,355].
    assert_eq!(take["chunk_frames"], 120);
    assert_eq!(take["chunks"], 3);
    assert_eq!(take["frames"], 356);
    assert_eq!(take["feet"], serde_json::json!(["LeftFoot", "RightFoot"]));
    assert_eq!(take["sensors"].as_array().map(Vec::len), Some(16));
    assert!(
        take["contacts"]["left"]
            .as_array()
            .is_some_and(|l| !l.is_empty())
    );
    let mut files = Vec::new();
    for (k, (first, last)) in [(0, 120), (120, 240), (240, 355)].into_iter().enumerate() {
        let (status, glb) = get(&served, &format!("/chunk/{k}.glb"));
        assert_eq!(status, 200);
        let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
        let doc: Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
        let input = doc["animations"][0]["samplers"][0]["input"]
            .as_u64()
            .unwrap() as usize;
        let times = &doc["accessors"][input];
        assert_eq!(times["count"].as_u64(), Some(last - first + 1));
        let at = |n: u64| (n as f64 * 1001.0 / 30000.0) as f32 as f64;
        assert_eq!(times["min"][0].as_f64(), Some(at(first)), "chunk {k}");
        assert_eq!(times["max"][0].as_f64(), Some(at(last)), "chunk {k}");
        let path = dir.path().join(format!("chunk{k}.glb"));
        std::fs::write(&path, &glb).unwrap();
        files.push(path);
    }
    for report in gltf_validate(&files, &modules) {
        assert_eq!(
            (report["errors"].as_u64(), report["warnings"].as_u64()),
            (Some(0), Some(0)),
            "{report}"
        );
    }
    assert_eq!(get(&served, "/chunk/3.glb").0, 404);
}

/// A capture is converted first; then the server answers only its own paths: no path leaves
/// them (encoded dots and slashes, absolute paths, absolute-form targets), a foreign `Host` is
/// refused (DNS rebinding), only GET; and Ctrl-C stops it at once, exit 0.
#[test]
fn the_server_serves_only_the_take_and_stops_on_ctrl_c() {
    let served = view(&[
        repo_file("samples/walk.csv").to_str().unwrap(),
        "--mapping",
        repo_file("mappings/paper000_16imu_mixamo.json")
            .to_str()
            .unwrap(),
    ]);
    assert!(
        served.url.starts_with("http://127.0.0.1:"),
        "{}",
        served.url
    );
    let (status, take) = get(&served, "/take.json");
    assert_eq!(status, 200);
    let take: Value = serde_json::from_slice(&take).unwrap();
    assert_eq!(
        take["source"],
        repo_file("samples/walk.csv").display().to_string()
    );
    assert_eq!(take["chunks"], 1);
    assert_eq!(get(&served, "/").0, 200);
    assert_eq!(get(&served, "/vendor/three/three.module.min.js").0, 200);
    let cargo = std::fs::read_to_string(repo_file("Cargo.toml")).unwrap();
    let host = served.authority().to_string();
    for target in [
        "/..%2fCargo.toml",
        "/..%2f..%2f..%2fetc%2fpasswd",
        "/%2e%2e/%2e%2e/Cargo.toml",
        "/vendor/three/../../../Cargo.toml",
        "/vendor/three/..%2f..%2f..%2f..%2fCargo.toml",
        "/vendor/three/addons/..\\..\\..\\Cargo.toml",
        "/etc/passwd",
        "//etc/passwd",
        "/Cargo.toml",
        "/src/view/web/viewer.js",
        "/chunk/../Cargo.toml",
        "/chunk/0.glb/../../Cargo.toml",
        "/chunk/-1.glb",
        "/chunk/1.glb",
        "/take.json/..",
        &format!("http://{host}/etc/passwd"),
        &format!("http://{host}/..%2fCargo.toml"),
    ] {
        let (status, body) = get(&served, target);
        assert_eq!(status, 404, "{target}");
        let body = String::from_utf8_lossy(&body);
        assert!(
            !body.contains("root:") && !body.contains("[package]"),
            "{target}: {body}"
        );
        assert!(body.len() < 100 || !cargo.contains(&*body), "{target}");
    }
    for foreign in ["evil.example:80", "attacker.test", ""] {
        let (status, _) = http(served.authority(), "GET", "/take.json", foreign);
        assert_eq!(status, 403, "Host: {foreign}");
    }
    assert_eq!(
        http(
            served.authority(),
            "GET",
            "/take.json",
            &format!("localhost:{}", host.rsplit(':').next().unwrap())
        )
        .0,
        200
    );
    assert_eq!(http(served.authority(), "POST", "/take.json", &host).0, 405);
    assert_eq!(http(served.authority(), "DELETE", "/", &host).0, 405);

    let mut served = served;
    let pid = served.child.id() as libc::pid_t;
    unsafe { libc::kill(pid, libc::SIGINT) };
    let start = Instant::now();
    let status = loop {
        if let Some(status) = served.child.try_wait().unwrap() {
            break status;
        }
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "still serving 5 s after Ctrl-C"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "{status:?}");
    assert!(
        TcpStream::connect(served.authority()).is_err(),
        "the port is closed"
    );
}

/// A file that cannot be shown is an error naming it, before anything is served: no URL, a
/// non-zero exit, at once.
#[test]
fn a_bad_file_fails_before_serving() {
    let dir = tempfile::tempdir().unwrap();
    let sidecar_path = walk(dir.path());
    let bvh = std::fs::read_to_string(dir.path().join("walk.bvh")).unwrap();
    let glb = std::fs::read(dir.path().join("walk.glb")).unwrap();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("truncated.bvh", bvh.as_bytes()[..bvh.len() / 2].to_vec()),
        (
            "hierarchy-only.bvh",
            bvh.as_bytes()[..bvh.find("MOTION").unwrap()].to_vec(),
        ),
        ("noise.glb", b"not a glb at all".to_vec()),
        ("truncated.glb", glb[..glb.len() / 2].to_vec()),
        ("empty.bvh", Vec::new()),
        ("broken.imubake.json", b"{\"fps\": ".to_vec()),
        ("other.imubake.json", b"{\"hello\": 1}".to_vec()),
        ("garbage.csv", b"\x00\x01\x02 not a capture\n".to_vec()),
    ];
    let mut paths: Vec<PathBuf> = cases
        .iter()
        .map(|(name, bytes)| {
            let path = dir.path().join(name);
            std::fs::write(&path, bytes).unwrap();
            path
        })
        .collect();
    paths.push(dir.path().join("missing.bvh"));
    // A sidecar whose BVH is gone.
    std::fs::remove_file(dir.path().join("walk.bvh")).unwrap();
    paths.push(sidecar_path);
    for path in paths {
        let mut child = Command::new(imubake_bin())
            .args(["view", path.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while child.try_wait().unwrap().is_none() {
            if start.elapsed() > Duration::from_secs(30) {
                let _ = child.kill();
                panic!("{}: still running after 30 s", path.display());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let out = child.wait_with_output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{}: {stdout}", path.display());
        assert!(
            !stdout.contains("http://"),
            "{}: served: {stdout}",
            path.display()
        );
        let name = path.file_name().unwrap().to_string_lossy();
        assert!(
            stderr.contains(&*name) || stderr.contains("walk.bvh"),
            "{}: the error does not name the file: {stderr}",
            path.display()
        );
        eprintln!("{name}: {}", stderr.trim());
    }
}

/// `live --preview`: the walk replayed in real time; the page, connected over the WebSocket,
/// shows a live frame with every joint within 1 mm of the numpy reader's positions in the
/// whole-take causal conversion at that frame, and lists the sensors.
#[test]
fn the_live_preview_shows_the_session_pose() {
    let (Some(modules), Some(py)) = (browser(), python()) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let capture = repo_file("samples/walk.csv");
    let mapping = repo_file("mappings/paper000_16imu_mixamo.json");
    let mut cmd = Command::new(imubake_bin());
    cmd.args([
        "live",
        "--source",
        &format!("file:{}@1", capture.display()),
        "--mapping",
        mapping.to_str().unwrap(),
        "--vmc",
        "off",
        "--listen",
        "off",
        "--preview",
    ]);
    let served = serve(cmd, true);
    let page = drive(&modules, &["live", &served.url, "150"]);
    drop(served);
    assert_eq!(page["console"], serde_json::json!([]), "{page:#}");
    assert_eq!(page["failed"], serde_json::json!([]), "{page:#}");
    let state = &page["frames"][0];
    assert_eq!(state["errors"], serde_json::json!([]));
    let n = state["live_frame"].as_u64().unwrap() as usize;
    assert!(n >= 150, "{state}");
    let status = page["status"].as_str().unwrap();
    assert!(
        status.contains("pelvis") && status.contains("right_foot"),
        "{status}"
    );

    run(Command::new(imubake_bin()).args([
        "convert",
        capture.to_str().unwrap(),
        "--mapping",
        mapping.to_str().unwrap(),
        "--causal",
        "--fps",
        "60",
        "--format",
        "bvh",
        "--out",
        dir.path().to_str().unwrap(),
    ]));
    let reference = reference(&py, &dir.path().join("walk.bvh"), 1.0, &[n]);
    assert_eq!(state["joints"], reference["names"]);
    let worst = worst_distance(
        state,
        reference["frames"][n.to_string()].as_array().unwrap(),
    );
    eprintln!("live frame {n}: worst joint {:.2} µm", worst * 1e6);
    assert!(
        worst <= 1e-3,
        "live frame {n}: a joint {worst} m from the BVH's"
    );
}
