//! `imubake watch` on real folders: the backlog with `--once`, captures written slowly while the
//! watcher runs (events and polling), a watcher killed mid-run and restarted, one log line per
//! take.

use serde_json::Value;
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

fn sample() -> Vec<u8> {
    fs::read(repo("samples/sou_wave.log")).unwrap()
}

fn fast_args() -> Vec<String> {
    [
        "--smooth",
        "none",
        "--format",
        "bvh",
        "--mapping",
        repo("samples/sou_wave.mapping.json").to_str().unwrap(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn watch_cmd(inbox: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_imubake"));
    cmd.arg("watch")
        .arg(inbox)
        .arg("--out")
        .arg(out)
        .args(fast_args())
        .args(extra)
        .env_remove("RUST_LOG")
        .env_remove("IMUBAKE_LOG");
    cmd
}

fn spawn(inbox: &Path, out: &Path, extra: &[&str]) -> Child {
    watch_cmd(inbox, out, extra)
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("spawn imubake watch")
}

/// The CPU time (user + system, seconds) a process has used so far, from `/proc/<pid>/stat`
/// (fields 14 and 15, in clock ticks; `getconf CLK_TCK` per second).
fn cpu_seconds(pid: u32) -> f64 {
    let stat = fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    // The command name (field 2) is in parentheses and may hold spaces: count after it.
    let fields: Vec<&str> = stat[stat.rfind(')').unwrap() + 2..].split(' ').collect();
    let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
    let tck = Command::new("getconf").arg("CLK_TCK").output().unwrap();
    let per_second: f64 = String::from_utf8_lossy(&tck.stdout).trim().parse().unwrap();
    ticks / per_second
}

/// SIGINT, then the exit code (within 10 s).
fn interrupt(mut child: Child) -> i32 {
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status.code().unwrap_or(-1);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("the watcher did not stop within 10 s of SIGINT");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Ledger lines per source, as (status, sha256).
fn ledger(out: &Path) -> BTreeMap<String, Vec<(String, String)>> {
    let mut map: BTreeMap<String, Vec<(String, String)>> = BTreeMap::new();
    let Ok(text) = fs::read_to_string(out.join(".imubake/ledger.jsonl")) else {
        return map;
    };
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let v: Value = serde_json::from_str(line).unwrap();
        map.entry(v["source"].as_str().unwrap().to_string())
            .or_default()
            .push((
                v["status"].as_str().unwrap().to_string(),
                v["sha256"].as_str().unwrap().to_string(),
            ));
    }
    map
}

/// The visible files of a folder (not recursive).
fn visible(dir: &Path) -> Vec<String> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut names: Vec<String> = entries
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with('.'))
        .collect();
    names.sort();
    names
}

/// No visible temporary file, and every sidecar parses.
fn assert_consistent(out: &Path) {
    for name in visible(out) {
        assert!(!name.ends_with(".tmp"), "visible temp file {name}");
        if name.ends_with(".imubake.json") {
            let text = fs::read_to_string(out.join(&name)).unwrap();
            serde_json::from_str::<Value>(&text)
                .unwrap_or_else(|e| panic!("{name} does not parse: {e}"));
        }
    }
}

fn sidecar_sha(out: &Path, stem: &str) -> String {
    let text = fs::read_to_string(out.join(format!("{stem}.imubake.json"))).unwrap();
    let v: Value = serde_json::from_str(&text).unwrap();
    v["source"]["sha256"].as_str().unwrap().to_string()
}

#[test]
fn once_converts_the_backlog_then_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    for name in ["a.log", "b.log", "c.log"] {
        fs::write(inbox.join(name), sample()).unwrap();
    }
    let garbage: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    fs::write(inbox.join("bad.log"), garbage).unwrap();
    // Ignored: hidden and temporary names.
    fs::write(inbox.join(".hidden.log"), sample()).unwrap();
    fs::write(inbox.join("d.log.part"), sample()).unwrap();
    fs::write(inbox.join("e.log.tmp"), sample()).unwrap();

    let run = watch_cmd(&inbox, &out, &["--once"]).output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert_eq!(run.status.code(), Some(1), "a take failed: {stdout}");
    assert!(stdout.contains("converted 3, failed 1"), "{stdout}");
    assert_eq!(
        visible(&out),
        [
            "a.bvh",
            "a.imubake.json",
            "b.bvh",
            "b.imubake.json",
            "bad.error.json",
            "c.bvh",
            "c.imubake.json"
        ]
    );
    assert_consistent(&out);
    let bvh_mtime = fs::metadata(out.join("a.bvh")).unwrap().modified().unwrap();

    let run = watch_cmd(&inbox, &out, &["--once"]).output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("converted 0, failed 1, skipped 3"),
        "{stdout}"
    );
    assert_eq!(
        fs::metadata(out.join("a.bvh")).unwrap().modified().unwrap(),
        bvh_mtime
    );
    let ledger = ledger(&out);
    for name in ["a.log", "b.log", "c.log"] {
        assert_eq!(ledger[name].len(), 1, "{name}: {:?}", ledger[name]);
    }

    // Fixing the bad capture converts it and removes its error report.
    fs::write(inbox.join("bad.log"), sample()).unwrap();
    let run = watch_cmd(&inbox, &out, &["--once"]).output().unwrap();
    assert_eq!(run.status.code(), Some(0));
    assert!(out.join("bad.imubake.json").is_file());
    assert!(!out.join("bad.error.json").exists());
    assert!(
        inbox.join("bad.log").is_file(),
        "sources are never modified"
    );
}

/// Writes a capture in three chunks through one handle over ~2 s while the watcher runs: it is
/// converted exactly once, from the whole file, and nothing partial is ever visible.
fn slow_write(extra: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    let child = spawn(&inbox, &out, extra);
    std::thread::sleep(Duration::from_millis(500));

    let data = sample();
    let written = Arc::new(AtomicBool::new(false));
    let writer = {
        let (path, data, written) = (inbox.join("slow.log"), data.clone(), Arc::clone(&written));
        std::thread::spawn(move || {
            let mut f = fs::File::create(path).unwrap();
            let third = data.len() / 3;
            for (i, chunk) in [&data[..third], &data[third..2 * third], &data[2 * third..]]
                .into_iter()
                .enumerate()
            {
                if i > 0 {
                    std::thread::sleep(Duration::from_millis(900));
                }
                f.write_all(chunk).unwrap();
                f.flush().unwrap();
            }
            written.store(true, Ordering::SeqCst);
            drop(f);
        })
    };
    let deadline = Instant::now() + Duration::from_secs(15);
    while !out.join("slow.imubake.json").is_file() {
        assert_consistent(&out);
        assert!(Instant::now() < deadline, "no sidecar within 15 s");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(
        written.load(Ordering::SeqCst),
        "converted before the capture was complete"
    );
    writer.join().unwrap();
    // Long enough for a second conversion to show.
    std::thread::sleep(Duration::from_millis(1500));
    assert_consistent(&out);
    assert_eq!(sidecar_sha(&out, "slow"), sha256_hex(&data));
    let ledger = ledger(&out);
    assert_eq!(ledger["slow.log"].len(), 1, "{:?}", ledger["slow.log"]);
    assert_eq!(interrupt(child), 0);
    assert_eq!(fs::read(inbox.join("slow.log")).unwrap(), data);
}

#[test]
fn a_slowly_written_capture_converts_once_when_complete() {
    slow_write(&[]);
}

#[test]
fn polling_converts_a_slowly_written_capture_once() {
    slow_write(&["--poll", "200"]);
}

#[test]
fn a_killed_watcher_restarts_without_duplicates_or_misses() {
    killed_and_restarted(&["--settle", "500"]);
}

#[test]
fn a_killed_polling_watcher_restarts_without_duplicates_or_misses() {
    killed_and_restarted(&["--settle", "500", "--poll", "200"]);
}

fn killed_and_restarted(extra: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    let names: Vec<String> = (0..8).map(|i| format!("take{i}.log")).collect();
    for name in &names {
        fs::write(inbox.join(name), sample()).unwrap();
    }
    let mut child = spawn(&inbox, &out, extra);
    let deadline = Instant::now() + Duration::from_secs(15);
    while !visible(&out).iter().any(|n| n.ends_with(".imubake.json")) {
        assert!(Instant::now() < deadline, "nothing converted within 15 s");
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let sidecars = |out: &Path| {
        visible(out)
            .iter()
            .filter(|n| n.ends_with(".imubake.json"))
            .count()
    };
    assert!(sidecars(&out) < names.len(), "killed after the last take");

    let child = spawn(&inbox, &out, extra);
    let deadline = Instant::now() + Duration::from_secs(15);
    while sidecars(&out) < names.len() {
        assert!(Instant::now() < deadline, "takes missed after the restart");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(1000));
    assert_eq!(interrupt(child), 0);
    assert_consistent(&out);
    assert_eq!(visible(&out).len(), 2 * names.len(), "{:?}", visible(&out));
    let ledger = ledger(&out);
    let sha = sha256_hex(&sample());
    for name in &names {
        assert_eq!(
            ledger[name],
            [("converted".to_string(), sha.clone())],
            "{name}: one conversion"
        );
    }
}

/// Every visible GLB's header length equals its size and every visible sidecar parses (a reader
/// must never see a partial output). `seen` holds the files already checked, by (name, size,
/// mtime), so each is read once.
fn assert_no_partial_outputs(
    out: &Path,
    seen: &mut std::collections::HashSet<(String, u64, u128)>,
) {
    use std::io::Read;
    for name in visible(out) {
        assert!(!name.ends_with(".tmp"), "visible temp file {name}");
        let glb = name.ends_with(".glb");
        if !glb && !name.ends_with(".imubake.json") {
            continue;
        }
        // Opened first, then measured through the handle: outputs are replaced by rename.
        let Ok(mut file) = fs::File::open(out.join(&name)) else {
            continue; // removed since the listing
        };
        let meta = file.metadata().unwrap();
        let mtime = meta
            .modified()
            .unwrap()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos();
        if !seen.insert((name.clone(), meta.len(), mtime)) {
            continue;
        }
        if glb {
            let mut header = [0u8; 12];
            file.read_exact(&mut header)
                .unwrap_or_else(|e| panic!("{name}: no GLB header ({} bytes): {e}", meta.len()));
            assert_eq!(&header[..4], b"glTF", "{name}");
            let length = u32::from_le_bytes(header[8..12].try_into().unwrap()) as u64;
            assert_eq!(length, meta.len(), "{name}: header length vs size");
        } else {
            let mut text = String::new();
            file.read_to_string(&mut text).unwrap();
            serde_json::from_str::<Value>(&text)
                .unwrap_or_else(|e| panic!("{name} does not parse: {e}"));
        }
    }
}

/// 300 captures dropped at once, 10 % corrupt: one set of outputs per good one, one error report
/// per bad one, and nothing partial ever visible.
fn drop_300(extra: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_imubake"));
    cmd.arg("watch")
        .arg(&inbox)
        .arg("--out")
        .arg(&out)
        .args(["--smooth", "none", "--format", "bvh,glb", "--mapping"])
        .arg(repo("samples/sou_wave.mapping.json"))
        .args(extra);
    let mut child = Running::spawn(cmd.stdout(Stdio::null()).stderr(Stdio::null()));
    std::thread::sleep(Duration::from_millis(500));

    let data = sample();
    let (good, bad): (Vec<String>, Vec<String>) = (
        (0..270).map(|i| format!("good{i:03}")).collect(),
        (0..30).map(|i| format!("bad{i:02}")).collect(),
    );
    let started = Instant::now();
    let writer = {
        let (inbox, good, bad) = (inbox.clone(), good.clone(), bad.clone());
        std::thread::spawn(move || {
            for (i, stem) in good.iter().enumerate() {
                fs::write(inbox.join(format!("{stem}.log")), &data).unwrap();
                if i % 9 == 8 {
                    let stem = &bad[i / 9];
                    let garbage: Vec<u8> = (0..4096u32 + 97 * i as u32)
                        .map(|j| ((j ^ i as u32).wrapping_mul(2654435761) >> 13) as u8)
                        .collect();
                    fs::write(inbox.join(format!("{stem}.log")), garbage).unwrap();
                }
            }
        })
    };

    let mut seen = std::collections::HashSet::new();
    let count = |suffix: &str| visible(&out).iter().filter(|n| n.ends_with(suffix)).count();
    let deadline = Instant::now() + Duration::from_secs(60);
    while count(".imubake.json") < good.len() || count(".error.json") < bad.len() {
        assert_no_partial_outputs(&out, &mut seen);
        assert!(
            Instant::now() < deadline,
            "after 60 s: {} sidecars, {} error reports",
            count(".imubake.json"),
            count(".error.json")
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    writer.join().unwrap();
    eprintln!(
        "300 captures ({}): all converted or reported in {:.1} s",
        if extra.is_empty() { "events" } else { "--poll" },
        started.elapsed().as_secs_f64()
    );
    // Long enough for a second conversion to show; and with nothing left to do the watcher
    // idles (its own reads of the inbox once woke it into rescanning without end).
    let cpu_before = cpu_seconds(child.id());
    std::thread::sleep(Duration::from_millis(2000));
    let busy = cpu_seconds(child.id()) - cpu_before;
    eprintln!("idle watcher: {busy:.2} s of CPU in 2 s");
    assert!(
        busy < 0.25,
        "an idle watcher used {busy:.2} s of CPU in 2 s (at most 0.25 s)"
    );
    assert_no_partial_outputs(&out, &mut seen);
    assert_eq!(interrupt(child.take()), 0);

    let mut expected: Vec<String> = good
        .iter()
        .flat_map(|s| {
            ["bvh", "glb", "imubake.json"]
                .iter()
                .map(move |ext| format!("{s}.{ext}"))
        })
        .chain(bad.iter().map(|s| format!("{s}.error.json")))
        .collect();
    expected.sort();
    assert_eq!(visible(&out), expected);
    let hidden: Vec<String> = fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n != ".imubake")
        .collect();
    assert!(hidden.is_empty(), "temporary files left: {hidden:?}");
    let ledger = ledger(&out);
    let sha = sha256_hex(&sample());
    for stem in &good {
        let name = format!("{stem}.log");
        assert_eq!(
            ledger[&name],
            [("converted".to_string(), sha.clone())],
            "{name}: one conversion"
        );
        assert_eq!(sidecar_sha(&out, stem), sha);
    }
    for stem in &bad {
        let name = format!("{stem}.log");
        assert!(
            ledger[&name].iter().all(|(status, _)| status == "failed"),
            "{name}: {:?}",
            ledger[&name]
        );
    }
    assert_eq!(ledger.len(), 300);
}

#[test]
fn three_hundred_captures_dropped_at_once() {
    drop_300(&[]);
}

#[test]
fn polling_three_hundred_captures_dropped_at_once() {
    drop_300(&["--poll", "200"]);
}

/// A subfolder may hold its own `imubake.yaml`: its takes use it, the others the inbox's.
#[test]
fn a_subfolder_config_applies_to_its_takes() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("inbox"), dir.path().join("out"));
    fs::create_dir_all(inbox.join("glb_only")).unwrap();
    let mapping = repo("samples/sou_wave.mapping.json");
    let config = |formats: &str| {
        format!(
            "mapping: {}\nsmoothing: none\nformats: [{formats}]\n",
            mapping.display()
        )
    };
    fs::write(inbox.join("imubake.yaml"), config("bvh")).unwrap();
    fs::write(inbox.join("glb_only/imubake.yaml"), config("glb")).unwrap();
    fs::write(inbox.join("top.log"), sample()).unwrap();
    fs::write(inbox.join("glb_only/sub.log"), sample()).unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_imubake"))
        .arg("watch")
        .arg(&inbox)
        .arg("--out")
        .arg(&out)
        .arg("--once")
        .status()
        .unwrap();
    assert!(status.success());
    assert!(out.join("top.bvh").is_file() && !out.join("top.glb").exists());
    assert!(out.join("glb_only/sub.glb").is_file() && !out.join("glb_only/sub.bvh").exists());
    // The configs themselves are not takes.
    assert!(
        !out.join("imubake.error.json").exists()
            && !out.join("glb_only/imubake.error.json").exists()
    );
}

/// Waits up to `secs` for `path` to exist.
fn wait_for(path: &Path, secs: u64) -> bool {
    wait_until(secs, || path.exists())
}

/// Whether `done` holds within `secs`, polled every 20 ms.
fn wait_until(secs: u64, done: impl Fn() -> bool) -> bool {
    let deadline = Instant::now() + Duration::from_secs(secs);
    while Instant::now() < deadline {
        if done() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

/// An edited inbox config is reloaded while the watcher runs: a bad edit keeps the last good
/// settings, and with `--reconvert` a good edit converts the old takes again under it.
#[test]
fn an_edited_config_is_reloaded_and_a_bad_one_keeps_the_last_good() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("inbox"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    let mapping = repo("samples/sou_wave.mapping.json");
    let config = |formats: &str| {
        format!(
            "mapping: {}\nsmoothing: none\nformats: [{formats}]\n",
            mapping.display()
        )
    };
    fs::write(inbox.join("imubake.yaml"), config("bvh")).unwrap();
    fs::write(inbox.join("take.log"), sample()).unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_imubake"))
        .arg("watch")
        .arg(&inbox)
        .arg("--out")
        .arg(&out)
        .args(["--poll", "100", "--reconvert"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    assert!(
        wait_for(&out.join("take.imubake.json"), 20),
        "the backlog take converts"
    );
    assert!(out.join("take.bvh").is_file() && !out.join("take.glb").exists());
    // A bad edit: reported, the last good settings stay (a new take still gets a BVH).
    fs::write(inbox.join("imubake.yaml"), "formats: [png]\n").unwrap();
    std::thread::sleep(Duration::from_millis(400));
    fs::write(inbox.join("second.log"), sample()).unwrap();
    assert!(
        wait_for(&out.join("second.imubake.json"), 20),
        "a new take converts under the last good settings"
    );
    assert!(out.join("second.bvh").is_file() && !out.join("second.glb").exists());
    // A good edit with --reconvert: the old takes are converted again, now as GLB only.
    fs::write(inbox.join("imubake.yaml"), config("glb")).unwrap();
    assert!(
        wait_for(&out.join("take.glb"), 20),
        "the old take is reconverted under the new settings"
    );
    assert!(wait_for(&out.join("second.glb"), 20));
    assert_eq!(interrupt(child), 0);
    // Outputs the new settings no longer write are removed.
    assert!(!out.join("take.bvh").exists(), "a stale BVH is left");
}

/// One per-take log line: `converted` or `failed`, the take, its duration in ms.
#[derive(Debug, Clone, PartialEq, Eq)]
struct TakeLine {
    status: String,
    source: String,
    duration_ms: u64,
}

/// The per-take lines of a run's stderr. Every line that names a take's outcome must have the
/// whole shape: `<UTC time>  INFO converted source="…" duration_ms=N [dropped_lines=N
/// repaired_lines=N] outputs=[…]` or
/// `<UTC time> ERROR failed source="…" duration_ms=N error_report="…" reason="…" [hint="…"]`;
/// and stderr, not a terminal here, carries no colour codes.
fn take_lines(stderr: &str) -> Vec<TakeLine> {
    assert!(!stderr.contains('\x1b'), "ANSI codes on a pipe: {stderr}");
    let shape = regex::Regex::new(
        r#"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d+Z +(?:INFO (converted) source="([^"]+)" duration_ms=(\d+)(?: dropped_lines=\d+ repaired_lines=\d+)? outputs=\[".+"\]|ERROR (failed) source="([^"]+)" duration_ms=(\d+) error_report="[^"]+\.error\.json" reason=".+?"(?: hint=".+")?)$"#,
    )
    .unwrap();
    let mut lines = Vec::new();
    for line in stderr.lines() {
        if !line.contains(" converted ") && !line.contains(" failed ") {
            continue;
        }
        let c = shape
            .captures(line)
            .unwrap_or_else(|| panic!("a take's line of the wrong shape: {line}"));
        let (status, source, ms) = match c.get(1) {
            Some(status) => (status, &c[2], &c[3]),
            None => (c.get(4).unwrap(), &c[5], &c[6]),
        };
        lines.push(TakeLine {
            status: status.as_str().to_string(),
            source: source.to_string(),
            duration_ms: ms.parse().unwrap(),
        });
    }
    lines
}

/// Exactly one line per take, with its outcome, over a run: the backlog and takes that arrive
/// while the watcher runs (renamed into place, written and closed). `IMUBAKE_LOG=warn` leaves only
/// the failures.
#[test]
fn a_watch_run_logs_one_line_per_take_with_its_duration() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    fs::write(inbox.join("backlog.log"), sample()).unwrap();
    fs::write(inbox.join("bad.log"), b"\0\0\0 not a capture").unwrap();
    let log = dir.path().join("stderr.txt");
    let child = watch_cmd(&inbox, &out, &[])
        .stdout(Stdio::null())
        .stderr(fs::File::create(&log).unwrap())
        .spawn()
        .expect("spawn imubake watch");
    assert!(
        wait_for(&out.join("backlog.imubake.json"), 15),
        "the backlog"
    );
    assert!(wait_for(&out.join("bad.error.json"), 15));
    // Renamed into place from a hidden temporary name; written and closed under its own name.
    fs::write(inbox.join(".renamed.log.tmp"), sample()).unwrap();
    fs::rename(inbox.join(".renamed.log.tmp"), inbox.join("renamed.log")).unwrap();
    let mut f = fs::File::create(inbox.join("closed.log")).unwrap();
    f.write_all(&sample()).unwrap();
    drop(f);
    assert!(wait_for(&out.join("renamed.imubake.json"), 15));
    assert!(wait_for(&out.join("closed.imubake.json"), 15));
    // Long enough for a second line to show.
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(interrupt(child), 0);

    let stderr = fs::read_to_string(&log).unwrap();
    assert!(
        stderr
            .lines()
            .next()
            .is_some_and(|l| l.contains("INFO watching (file-system events)")),
        "{stderr}"
    );
    let mut lines = take_lines(&stderr);
    lines.sort_by(|a, b| a.source.cmp(&b.source));
    let outcomes: Vec<(&str, &str)> = lines
        .iter()
        .map(|l| (l.source.as_str(), l.status.as_str()))
        .collect();
    assert_eq!(
        outcomes,
        [
            ("backlog.log", "converted"),
            ("bad.log", "failed"),
            ("closed.log", "converted"),
            ("renamed.log", "converted"),
        ],
        "{stderr}"
    );
    // A conversion of this sample takes some milliseconds, never minutes.
    for l in &lines {
        assert!(l.duration_ms < 60_000, "{l:?}");
    }
    assert!(
        lines
            .iter()
            .filter(|l| l.status == "converted")
            .all(|l| l.duration_ms > 0),
        "{stderr}"
    );
    assert_eq!(
        stderr.lines().filter(|l| !l.contains(" WARN ")).count(),
        lines.len() + 1,
        "only the start line (and warnings) besides the takes' lines: {stderr}"
    );

    // At warn level only the failure is told; the counts still go to stdout.
    fs::write(inbox.join("another.log"), sample()).unwrap();
    let run = watch_cmd(&inbox, &out, &["--once"])
        .env("IMUBAKE_LOG", "warn")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("converted 1, failed 1, skipped 3"),
        "{stdout}"
    );
    let stderr = String::from_utf8_lossy(&run.stderr);
    let lines = take_lines(&stderr);
    assert_eq!(lines.len(), 1, "{stderr}");
    assert_eq!(
        (lines[0].source.as_str(), lines[0].status.as_str()),
        ("bad.log", "failed")
    );
}

/// `imubake watch <inbox> --out <out> <args>`, with nothing else (no mapping).
fn bare_watch(inbox: &Path, out: &Path, args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_imubake"));
    cmd.arg("watch")
        .arg(inbox)
        .arg("--out")
        .arg(out)
        .args(args)
        .env_remove("RUST_LOG")
        .env_remove("IMUBAKE_LOG");
    cmd
}

/// SIGTERM, then the exit code (within `secs`).
fn terminate(mut child: Child, secs: u64) -> i32 {
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status.code().unwrap_or(-1);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("the watcher did not stop within {secs} s of SIGTERM");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The issue's reproduction: a symlink to /dev/zero and a FIFO in the inbox, then a good take:
/// the good take converts, each bad entry is warned about once, and SIGTERM stops the watcher.
#[cfg(unix)]
fn special_files_do_not_stall(extra: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    let log = dir.path().join("stderr.txt");
    let child = watch_cmd(&inbox, &out, extra)
        .stdout(Stdio::null())
        .stderr(fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(800));
    std::os::unix::fs::symlink("/dev/zero", inbox.join("z.log")).unwrap();
    assert!(
        Command::new("mkfifo")
            .arg(inbox.join("p.log"))
            .status()
            .unwrap()
            .success()
    );
    std::thread::sleep(Duration::from_millis(2000));
    fs::write(inbox.join("g2.log"), sample()).unwrap();
    assert!(
        wait_for(&out.join("g2.imubake.json"), 20),
        "a good take after a FIFO and /dev/zero converts"
    );
    // Several rescans later, still one warning each.
    std::thread::sleep(Duration::from_millis(2500));
    assert_eq!(terminate(child, 10), 0);
    let stderr = fs::read_to_string(&log).unwrap();
    let warned = |name: &str| {
        stderr
            .lines()
            .filter(|l| l.contains(" WARN ") && l.contains(name))
            .count()
    };
    assert_eq!(warned("p.log"), 1, "{stderr}");
    assert_eq!(warned("z.log"), 1, "{stderr}");
    assert!(stderr.contains("is a FIFO, not a regular file"), "{stderr}");
    assert!(stderr.contains("symlink to something outside"), "{stderr}");
    assert_eq!(visible(&out), ["g2.bvh", "g2.imubake.json"]);

    // --once and batch finish too.
    let run = watch_cmd(&inbox, &out, &["--once"]).output().unwrap();
    assert_eq!(run.status.code(), Some(0));
    let run = Command::new(env!("CARGO_BIN_EXE_imubake"))
        .arg("batch")
        .arg(&inbox)
        .arg("--out")
        .arg(dir.path().join("batch_out"))
        .args(fast_args())
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(0));
}

#[test]
#[cfg(unix)]
fn a_fifo_and_dev_zero_in_the_inbox_do_not_stall_the_watcher() {
    special_files_do_not_stall(&[]);
}

#[test]
#[cfg(unix)]
fn a_fifo_and_dev_zero_in_a_polled_inbox_do_not_stall_the_watcher() {
    special_files_do_not_stall(&["--poll", "200"]);
}

/// A symlink to a file outside the inbox is not followed: nothing of the target reaches an
/// output or the log (the target is a log whose debug line would be reported if it were read).
/// With --follow-symlinks it is read, which shows the check would catch a leak.
#[test]
#[cfg(unix)]
fn a_symlink_out_of_the_inbox_is_never_read() {
    const SECRET: &str = "SECRET-4d1f9c-outside-the-inbox";
    let dir = tempfile::tempdir().unwrap();
    let (inbox, outside) = (dir.path().join("in"), dir.path().join("outside"));
    fs::create_dir_all(&inbox).unwrap();
    fs::create_dir_all(&outside).unwrap();
    let mut secret = format!("{SECRET}\n").into_bytes();
    secret.extend(sample());
    fs::write(outside.join("private.log"), &secret).unwrap();
    std::os::unix::fs::symlink(outside.join("private.log"), inbox.join("leak.log")).unwrap();
    fs::write(inbox.join("good.log"), sample()).unwrap();

    let leaked = |out: &Path, stderr: &str| -> bool {
        fn walk(dir: &Path, found: &mut bool) {
            for e in fs::read_dir(dir).into_iter().flatten().flatten() {
                let p = e.path();
                if p.is_dir() {
                    walk(&p, found);
                } else if fs::read(&p).is_ok_and(|b| String::from_utf8_lossy(&b).contains(SECRET)) {
                    *found = true;
                }
            }
        }
        let mut found = stderr.contains(SECRET);
        walk(out, &mut found);
        found
    };
    let out = dir.path().join("out");
    let run = watch_cmd(&inbox, &out, &["--once"]).output().unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    assert!(!leaked(&out, &stderr), "{stderr}");
    assert!(
        stderr.contains("leak.log") && stderr.contains("outside"),
        "{stderr}"
    );
    assert_eq!(visible(&out), ["good.bvh", "good.imubake.json"]);

    let batch_out = dir.path().join("batch_out");
    let run = Command::new(env!("CARGO_BIN_EXE_imubake"))
        .arg("batch")
        .arg(&inbox)
        .arg("--out")
        .arg(&batch_out)
        .args(fast_args())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    assert!(!leaked(&batch_out, &stderr), "{stderr}");

    let followed = dir.path().join("followed");
    let run = watch_cmd(&inbox, &followed, &["--once", "--follow-symlinks"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    assert!(
        leaked(&followed, &stderr),
        "--follow-symlinks reads the target"
    );
}

/// A long take that cannot finish within the 2 s grace after SIGTERM is abandoned: the watcher
/// exits 0, no temporary file is left, no ledger line and no output of the take exist. (Two
/// minutes of the walk sample smoothed with a 40 s Gaussian: tens of seconds of work in a file
/// of 13 MB.)
#[test]
fn sigterm_during_a_long_take_abandons_it() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    let walk = fs::read_to_string(repo("samples/walk.csv")).unwrap();
    let mut long = std::io::BufWriter::new(fs::File::create(inbox.join("long.csv")).unwrap());
    writeln!(long, "time_s,sensor,qw,qx,qy,qz").unwrap();
    for k in 0..10 {
        for line in walk.lines().filter(|l| !l.starts_with(['#', 't'])) {
            let (t, rest) = line.split_once(',').unwrap();
            let t: f64 = t.parse().unwrap();
            writeln!(long, "{:.6},{rest}", t + 12.0 * k as f64).unwrap();
        }
    }
    drop(long);
    let log = dir.path().join("stderr.txt");
    let mapping = repo("mappings/paper000_16imu_mixamo.json");
    let started = Instant::now();
    let args = [
        "--mapping",
        mapping.to_str().unwrap(),
        "--smooth",
        "gaussian:sigma=40",
    ];
    let child = bare_watch(&inbox, &out, &args)
        .stdout(Stdio::null())
        .stderr(fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    // The backlog take settles (500 ms) and its conversion starts.
    std::thread::sleep(Duration::from_millis(1500));
    let code = terminate(child, 10);
    let took = started.elapsed();
    let stderr = fs::read_to_string(&log).unwrap();
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.contains("abandoned"), "{stderr}");
    assert!(took < Duration::from_secs(8), "stopped after {took:?}");
    let left: Vec<String> = fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != ".imubake")
        .collect();
    assert!(left.is_empty(), "left in the output folder: {left:?}");
    assert!(
        ledger(&out).is_empty(),
        "no ledger line for an abandoned take"
    );
}

/// A capture dropped before the inbox's `imubake.yaml` fails for want of a mapping; when the
/// config arrives, it is tried again.
#[test]
fn a_take_that_failed_for_lack_of_settings_is_retried_when_they_arrive() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    fs::write(inbox.join("early.log"), sample()).unwrap();
    let child = bare_watch(&inbox, &out, &["--poll", "100", "--format", "bvh"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    assert!(wait_for(&out.join("early.error.json"), 20));
    let report = fs::read_to_string(out.join("early.error.json")).unwrap();
    assert!(report.contains("no mapping given"), "{report}");
    fs::write(
        inbox.join("imubake.yaml"),
        format!(
            "mapping: {}\n",
            repo("samples/sou_wave.mapping.json").display()
        ),
    )
    .unwrap();
    assert!(
        wait_for(&out.join("early.imubake.json"), 20),
        "the failed take is retried under the new settings"
    );
    assert!(!out.join("early.error.json").exists());
    assert_eq!(interrupt(child), 0);
}

/// The plan is resolved again when a file it read changes, not only its config: a take that
/// failed under a mapping naming a bone the rig lacks converts once the mapping file is fixed,
/// the config untouched.
#[test]
fn a_take_is_retried_when_the_mapping_its_config_names_is_fixed() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    let good = fs::read_to_string(repo("samples/sou_wave.mapping.json")).unwrap();
    let bad = good.replacen("\"bone\": \"Hips\"", "\"bone\": \"Tail\"", 1);
    assert_ne!(good, bad);
    let mapping = dir.path().join("m.json");
    fs::write(&mapping, &bad).unwrap();
    fs::write(
        inbox.join("imubake.yaml"),
        format!("mapping: {}\n", mapping.display()),
    )
    .unwrap();
    fs::write(inbox.join("take.log"), sample()).unwrap();
    let child = bare_watch(&inbox, &out, &["--poll", "100", "--format", "bvh"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    assert!(wait_for(&out.join("take.error.json"), 20));
    let report = fs::read_to_string(out.join("take.error.json")).unwrap();
    assert!(report.contains("Tail"), "{report}");
    fs::write(&mapping, &good).unwrap();
    assert!(
        wait_for(&out.join("take.imubake.json"), 20),
        "the failed take is retried under the fixed mapping"
    );
    // The outputs are written, then the earlier error report removed, then the ledger line.
    let report = out.join("take.error.json");
    assert!(wait_until(5, || !report.exists()), "the error report stays");
    assert_eq!(interrupt(child), 0);
}

/// A capture rewritten with the same size and its modification time put back, within 2 s of its
/// conversion: converted again (events: the close-write; polling: the ctime changed).
fn same_size_rewrite(extra: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    let take = inbox.join("take.log");
    fs::write(&take, sample()).unwrap();
    let mtime = fs::metadata(&take).unwrap().modified().unwrap();
    let child = spawn(&inbox, &out, extra);
    assert!(wait_for(&out.join("take.imubake.json"), 20));
    let first = sidecar_sha(&out, "take");
    // One digit of the first data line changed: same size.
    let text = String::from_utf8(sample()).unwrap();
    let at = text
        .find("5234872,N0,90.38")
        .expect("the sample's first data line");
    let mut edited = text.into_bytes();
    edited[at + "5234872,N0,90.3".len()] = b'9';
    {
        let mut f = fs::OpenOptions::new().write(true).open(&take).unwrap();
        f.write_all(&edited).unwrap();
        f.set_modified(mtime).unwrap();
    }
    assert_eq!(fs::metadata(&take).unwrap().modified().unwrap(), mtime);
    let deadline = Instant::now() + Duration::from_secs(20);
    while sidecar_sha(&out, "take") == first {
        assert!(Instant::now() < deadline, "the rewrite was not converted");
        std::thread::sleep(Duration::from_millis(50));
        while !out.join("take.imubake.json").exists() {
            std::thread::sleep(Duration::from_millis(10));
        }
    }
    assert_eq!(sidecar_sha(&out, "take"), sha256_hex(&edited));
    assert_eq!(interrupt(child), 0);
}

#[test]
fn a_same_size_rewrite_with_its_mtime_restored_is_converted_again() {
    same_size_rewrite(&[]);
}

#[test]
fn a_polled_same_size_rewrite_with_its_mtime_restored_is_converted_again() {
    same_size_rewrite(&["--poll", "200"]);
}

/// A ledger written before settings fingerprints had a schema (a bare SHA-256): each take converts
/// again once, with one log line saying why, and not again after that.
#[test]
fn an_older_ledger_reconverts_each_take_once() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    for name in ["a.log", "b.log"] {
        fs::write(inbox.join(name), sample()).unwrap();
    }
    let run = watch_cmd(&inbox, &out, &["--once"]).output().unwrap();
    assert!(run.status.success());
    // Rewrite the ledger as the previous release wrote it: fingerprints without a schema.
    let path = out.join(".imubake/ledger.jsonl");
    let old: String = fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| {
            let mut v: Value = serde_json::from_str(l).unwrap();
            v["settings"] = Value::from("ab".repeat(32));
            v.as_object_mut().unwrap().remove("ctime_ns");
            format!("{v}\n")
        })
        .collect();
    fs::write(&path, old).unwrap();
    let run = watch_cmd(&inbox, &out, &["--once"]).output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stdout.contains("converted 2, failed 0, skipped 0"),
        "{stdout}"
    );
    assert_eq!(
        stderr
            .lines()
            .filter(|l| l.contains("converted by an earlier imubake"))
            .count(),
        1,
        "{stderr}"
    );
    assert!(stderr.contains("2 take(s)"), "{stderr}");
    let run = watch_cmd(&inbox, &out, &["--once"]).output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("converted 0, failed 0, skipped 2"),
        "{stdout}"
    );
    let ledger = ledger(&out);
    assert_eq!(ledger["a.log"].len(), 2, "{:?}", ledger["a.log"]);
}

/// The README's `watch` example, run as written (with `--once` added so it ends) in a folder
/// holding `inbox/walk.csv` (the bundled walk) and the mapping it names: the walk converts. The
/// same command without its `--mapping` fails, and the failed take's terminal line carries the
/// hint its `.error.json` gives.
#[test]
fn the_readme_watch_example_converts_the_bundled_walk() {
    let readme = fs::read_to_string(repo("README.md")).unwrap();
    let example: Vec<&str> = readme
        .lines()
        .find(|l| l.starts_with("imubake watch inbox"))
        .expect("README has an `imubake watch inbox …` example")
        .split_whitespace()
        .collect();
    let dir = tempfile::tempdir().unwrap();
    fs::create_dir_all(dir.path().join("inbox")).unwrap();
    fs::copy(repo("samples/walk.csv"), dir.path().join("inbox/walk.csv")).unwrap();
    // The files the example names, at the same relative paths.
    for arg in &example {
        if arg.ends_with(".json") || arg.ends_with(".yaml") {
            let to = dir.path().join(arg);
            fs::create_dir_all(to.parent().unwrap()).unwrap();
            fs::copy(repo(arg), &to).unwrap();
        }
    }
    let out_arg = example
        .iter()
        .position(|a| *a == "--out" || *a == "-o")
        .map(|i| example[i + 1])
        .expect("the example gives --out");
    let run = Command::new(env!("CARGO_BIN_EXE_imubake"))
        .args(&example[1..])
        .arg("--once")
        .current_dir(dir.path())
        .env_remove("RUST_LOG")
        .env_remove("IMUBAKE_LOG")
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr),
    );
    assert!(run.status.success(), "{example:?}: {stdout}{stderr}");
    assert_eq!(
        stdout.trim(),
        "converted 1, failed 0, skipped 0",
        "{stderr}"
    );
    let out = dir.path().join(out_arg);
    for name in ["walk.bvh", "walk.glb", "walk.imubake.json"] {
        assert!(out.join(name).is_file(), "{name}: {:?}", visible(&out));
    }
    let sidecar: Value =
        serde_json::from_str(&fs::read_to_string(out.join("walk.imubake.json")).unwrap()).unwrap();
    assert_eq!(sidecar["mapping"]["rig"], "mixamo");
    assert_eq!(sidecar["mapping"]["sensors"].as_array().unwrap().len(), 16);

    // Without the mapping (the example as it once was): the take fails, and its line says what
    // to do, as its error report does.
    let mut bare = example[1..].to_vec();
    let at = bare.iter().position(|a| *a == "--mapping").unwrap();
    bare.drain(at..at + 2);
    let at = bare.iter().position(|a| *a == out_arg).unwrap();
    bare[at] = "bare-out";
    let run = Command::new(env!("CARGO_BIN_EXE_imubake"))
        .args(&bare)
        .arg("--once")
        .current_dir(dir.path())
        .env_remove("RUST_LOG")
        .env_remove("IMUBAKE_LOG")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert_eq!(
        String::from_utf8_lossy(&run.stdout).trim(),
        "converted 0, failed 1, skipped 0"
    );
    let report: Value = serde_json::from_str(
        &fs::read_to_string(dir.path().join("bare-out/walk.error.json")).unwrap(),
    )
    .unwrap();
    let hint = report["hint"].as_str().expect("the report has a hint");
    assert!(hint.contains("--mapping"), "{hint}");
    let lines: Vec<&str> = stderr.lines().filter(|l| l.contains(" failed ")).collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(
        lines[0].contains(r#"source="walk.csv""#)
            && lines[0].ends_with(&format!(r#" hint="{hint}""#)),
        "{stderr}"
    );
    assert_eq!(take_lines(&stderr).len(), 1);
}

/// The summary counts each take once, by its latest outcome: a take that failed for want of a
/// mapping and converted once the inbox's config arrived, and a take that failed and converted
/// once rewritten, count as converted; a take that failed twice counts as one failure.
#[test]
fn a_take_that_converted_after_failing_counts_as_converted() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    fs::write(inbox.join("early.log"), sample()).unwrap();
    fs::write(inbox.join("bad.log"), b"\0\0\0 not a capture yet").unwrap();
    fs::write(inbox.join("junk.log"), b"\0\0\0 never a capture").unwrap();
    let stdout = dir.path().join("stdout.txt");
    let child = bare_watch(&inbox, &out, &["--poll", "100", "--format", "bvh"])
        .stdout(fs::File::create(&stdout).unwrap())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    for stem in ["early", "bad", "junk"] {
        assert!(
            wait_for(&out.join(format!("{stem}.error.json")), 20),
            "{stem}"
        );
    }
    // The settings arrive: early converts; bad and junk are tried again and fail again.
    fs::write(
        inbox.join("imubake.yaml"),
        format!(
            "mapping: {}\nsmoothing: none\n",
            repo("samples/sou_wave.mapping.json").display()
        ),
    )
    .unwrap();
    assert!(wait_for(&out.join("early.imubake.json"), 20));
    let deadline = Instant::now() + Duration::from_secs(20);
    while ledger(&out).get("junk.log").map_or(0, Vec::len) < 2
        || ledger(&out).get("bad.log").map_or(0, Vec::len) < 2
    {
        assert!(Instant::now() < deadline, "not retried: {:?}", ledger(&out));
        std::thread::sleep(Duration::from_millis(50));
    }
    // bad.log rewritten as a capture: it converts.
    fs::write(inbox.join("bad.log"), sample()).unwrap();
    assert!(wait_for(&out.join("bad.imubake.json"), 20));
    assert_eq!(interrupt(child), 0);
    let statuses: BTreeMap<String, Vec<String>> = ledger(&out)
        .into_iter()
        .map(|(k, v)| (k, v.into_iter().map(|(status, _)| status).collect()))
        .collect();
    assert_eq!(
        statuses,
        BTreeMap::from([
            (
                "bad.log".into(),
                vec!["failed".into(), "failed".into(), "converted".into()]
            ),
            (
                "early.log".into(),
                vec!["failed".into(), "converted".into()]
            ),
            ("junk.log".into(), vec!["failed".into(), "failed".into()]),
        ]),
    );
    assert_eq!(
        fs::read_to_string(&stdout).unwrap().trim(),
        "converted 2, failed 1, skipped 0"
    );
}

// ── Issue 44: the environment's failures retried, one watcher per output folder ─────────────────

/// A watcher that is killed if the test fails before it is stopped (a panicking test would
/// otherwise leave it running).
struct Running(Option<Child>);

impl Running {
    fn spawn(cmd: &mut Command) -> Running {
        Running(Some(cmd.spawn().expect("spawn imubake watch")))
    }

    fn child(&mut self) -> &mut Child {
        self.0.as_mut().expect("still held")
    }

    fn id(&self) -> u32 {
        self.0.as_ref().expect("still held").id()
    }

    /// The child, to stop it (`interrupt`): no longer killed on drop.
    fn take(&mut self) -> Child {
        self.0.take().expect("still held")
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        if let Some(mut child) = self.0.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// The bundled walk's first second (16 sensors, 30 frames at 30 fps): a quick take whose BVH
/// (22 KB) and GLB (46 KB) are both larger than 16 KiB.
fn short_walk() -> Vec<u8> {
    static SHORT: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    SHORT
        .get_or_init(|| {
            let text = fs::read_to_string(repo("samples/walk.csv")).unwrap();
            let mut out = String::new();
            for line in text.lines() {
                let time = line.split(',').next().and_then(|t| t.parse::<f64>().ok());
                if time.is_none_or(|t| t < 1.0) {
                    out.push_str(line);
                    out.push('\n');
                }
            }
            out.into_bytes()
        })
        .clone()
}

/// `imubake watch <inbox> --out <out>` for the walk (its mapping; BVH, GLB and sidecar), stdout
/// dropped, stderr piped (a file would be held to the child's file size limit too).
fn walk_watch(inbox: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_imubake"));
    cmd.arg("watch")
        .arg(inbox)
        .arg("--out")
        .arg(out)
        .arg("--mapping")
        .arg(repo("mappings/paper000_16imu_mixamo.json"))
        .args(extra)
        .env_remove("RUST_LOG")
        .env_remove("IMUBAKE_LOG")
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    cmd
}

/// A child's stderr, gathered line by line on a thread as it comes.
#[derive(Clone)]
struct Stderr(Arc<std::sync::Mutex<String>>);

impl Stderr {
    fn of(child: &mut Child) -> Stderr {
        let pipe = child.stderr.take().expect("stderr piped");
        let text = Arc::new(std::sync::Mutex::new(String::new()));
        let sink = Arc::clone(&text);
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in std::io::BufReader::new(pipe).lines() {
                let Ok(line) = line else { break };
                let mut text = sink.lock().unwrap();
                text.push_str(&line);
                text.push('\n');
            }
        });
        Stderr(text)
    }

    fn text(&self) -> String {
        self.0.lock().unwrap().clone()
    }

    /// The lines holding every one of `parts`.
    fn lines_with(&self, parts: &[&str]) -> Vec<String> {
        self.text()
            .lines()
            .filter(|l| parts.iter().all(|p| l.contains(p)))
            .map(str::to_string)
            .collect()
    }

    /// Waits up to `secs` for `n` lines holding every one of `parts`.
    fn wait_lines(&self, parts: &[&str], n: usize, secs: u64) -> Vec<String> {
        let deadline = Instant::now() + Duration::from_secs(secs);
        loop {
            let lines = self.lines_with(parts);
            if lines.len() >= n {
                return lines;
            }
            assert!(
                Instant::now() < deadline,
                "no {n} line(s) with {parts:?} within {secs} s:\n{}",
                self.text()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// Waits up to `secs` for `path` to exist; how long it took.
fn time_until(path: &Path, secs: u64) -> Duration {
    let start = Instant::now();
    assert!(
        wait_for(path, secs),
        "{} did not appear within {secs} s",
        path.display()
    );
    start.elapsed()
}

/// Waits up to `secs` for the ledger statuses of `source` to be `expected` (the ledger line is
/// written after the sidecar); panics with what they are past that.
fn wait_statuses(out: &Path, source: &str, expected: &[&str], secs: u64) {
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        // Complete lines only: one may be half written as it is read.
        let text = fs::read_to_string(out.join(".imubake/ledger.jsonl")).unwrap_or_default();
        let complete = text.rfind('\n').map_or("", |end| &text[..end]);
        let now: Vec<String> = complete
            .lines()
            .filter_map(|l| serde_json::from_str::<Value>(l).ok())
            .filter(|v| v["source"].as_str() == Some(source))
            .filter_map(|v| v["status"].as_str().map(str::to_string))
            .collect();
        if now == expected {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{source}: ledger statuses {now:?}, not {expected:?}, within {secs} s"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Ledger lines of `source`, by status, in order.
fn statuses(out: &Path, source: &str) -> Vec<String> {
    ledger(out)
        .remove(source)
        .unwrap_or_default()
        .into_iter()
        .map(|(status, _)| status)
        .collect()
}

fn chmod(path: &Path, mode: u32) {
    use std::os::unix::fs::PermissionsExt;
    fs::set_permissions(path, fs::Permissions::from_mode(mode)).unwrap();
}

/// Makes a folder's permissions bind the watcher `cmd` will start. These tests run as root (the
/// project's CI runs in a root container), and root writes through a missing write permission;
/// read-only bind mounts need privileges a container may lack. So as root the watcher runs as
/// `nobody` (uid and gid 65534; std drops the supplementary groups when root sets a uid) and
/// `root` (the test's folder) is given to it; a `chmod` then binds the watcher as it binds any
/// user. As any other user the watcher runs as that user, whom `chmod` binds already. The binary
/// and the repository's mapping must be readable by `nobody` (they are: 0755 and 0644).
fn unprivileged(cmd: &mut Command, root: &Path) {
    use std::os::unix::process::CommandExt;
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return;
    }
    fn give(path: &Path) {
        std::os::unix::fs::chown(path, Some(65534), Some(65534)).unwrap();
        if path.is_dir() {
            for entry in fs::read_dir(path).unwrap() {
                give(&entry.unwrap().path());
            }
        }
    }
    give(root);
    cmd.uid(65534).gid(65534);
}

/// A take whose output folder is read-only (`chmod 0555` on the subfolder its outputs go to,
/// binding the watcher as described at [`unprivileged`]) fails for the environment's sake: the
/// terminal says it is retried, with the error's kind, again and again (1 s, then 2 s, …) while
/// the ledger records the failure once. Made writable again, the take converts at the next
/// attempt, without a restart, exactly once, with all its outputs and no error report.
#[test]
fn a_read_only_output_folder_is_retried_until_writable_then_converts_once() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(inbox.join("day1")).unwrap();
    fs::create_dir_all(out.join("day1")).unwrap();
    fs::write(inbox.join("day1/walk.csv"), short_walk()).unwrap();
    let mut cmd = walk_watch(&inbox, &out, &[]);
    unprivileged(&mut cmd, dir.path());
    chmod(&out.join("day1"), 0o555);
    let mut child = Running::spawn(&mut cmd);
    let stderr = Stderr::of(child.child());

    let retrying = ["retrying", r#"source="day1/walk.csv""#];
    let lines = stderr.wait_lines(&retrying, 3, 30);
    for (i, line) in lines.iter().take(3).enumerate() {
        assert!(
            line.contains(&format!("attempt={}", i + 1))
                && line.contains(&format!("retry_in_s={}", 1 << i))
                && line.contains("error_kind=PermissionDenied"),
            "{line}"
        );
    }
    assert!(visible(&out.join("day1")).is_empty(), "nothing written yet");
    assert_eq!(
        statuses(&out, "day1/walk.csv"),
        ["failed"],
        "one ledger line for the failure, however many attempts"
    );

    chmod(&out.join("day1"), 0o755);
    let took = time_until(&out.join("day1/walk.imubake.json"), 30);
    eprintln!("writable again → converted in {} ms", took.as_millis());
    // The third failure waits 4 s before the next attempt; 30 s is only a bound for a slow host.
    assert!(
        child.child().try_wait().unwrap().is_none(),
        "the same watcher, still running"
    );
    wait_statuses(&out, "day1/walk.csv", &["failed", "converted"], 30);
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(interrupt(child.take()), 0);

    assert_eq!(
        visible(&out.join("day1")),
        ["walk.bvh", "walk.glb", "walk.imubake.json"]
    );
    assert_consistent(&out.join("day1"));
    assert_eq!(statuses(&out, "day1/walk.csv"), ["failed", "converted"]);
    let text = stderr.text();
    let converted: Vec<TakeLine> = take_lines(&text)
        .into_iter()
        .filter(|l| l.status == "converted")
        .collect();
    assert_eq!(converted.len(), 1, "{text}");
    assert_eq!(
        stderr
            .lines_with(&["written after retrying", "day1/walk.csv"])
            .len(),
        1,
        "{text}"
    );
}

/// Sets the file size limit of process `pid` (`RLIMIT_FSIZE`, soft; the hard one unlimited).
fn set_file_size_limit(pid: Option<u32>, bytes: u64) {
    let limit = libc::rlimit {
        rlim_cur: bytes,
        rlim_max: libc::RLIM_INFINITY,
    };
    // SAFETY: prlimit reads `limit` and writes nothing (a null old limit).
    let rc = unsafe {
        libc::prlimit(
            pid.map_or(0, |p| p as libc::pid_t),
            libc::RLIMIT_FSIZE,
            &limit,
            std::ptr::null_mut(),
        )
    };
    assert_eq!(rc, 0, "prlimit: {}", std::io::Error::last_os_error());
}

/// A full disk, simulated by a file size limit: the watcher starts with `RLIMIT_FSIZE` at 16 KiB
/// and `SIGXFSZ` ignored (set between fork and exec), so writing the take's 22 KB BVH or 46 KB
/// GLB fails with `EFBIG` as a full disk fails with `ENOSPC` — both are the environment's. The
/// terminal says the take is retried; the `.error.json` (small enough) and one ledger line record
/// the failure. The limit is then lifted while the watcher runs (`prlimit` on its pid): the take
/// converts at the next attempt, once, without a restart.
#[test]
fn a_full_disk_is_retried_until_there_is_room_then_converts_once() {
    use std::os::unix::process::CommandExt;
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    fs::write(inbox.join("walk.csv"), short_walk()).unwrap();
    let mut cmd = walk_watch(&inbox, &out, &[]);
    // SAFETY: between fork and exec only async-signal-safe calls (signal, setrlimit).
    unsafe {
        cmd.pre_exec(|| {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let limit = libc::rlimit {
                rlim_cur: 16 << 10,
                rlim_max: libc::RLIM_INFINITY,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let mut child = Running::spawn(&mut cmd);
    let stderr = Stderr::of(child.child());

    let lines = stderr.wait_lines(&["retrying", r#"source="walk.csv""#], 2, 30);
    assert!(
        lines[0].contains("attempt=1")
            && lines[0].contains("error_kind=FileTooLarge")
            && lines[1].contains("attempt=2"),
        "{lines:?}"
    );
    let report: Value =
        serde_json::from_str(&fs::read_to_string(out.join("walk.error.json")).unwrap()).unwrap();
    assert!(
        report["reason"]
            .as_str()
            .is_some_and(|r| r.contains("cannot write")),
        "{report}"
    );
    assert_eq!(
        visible(&out),
        ["walk.error.json"],
        "nothing partial beside it"
    );
    assert_eq!(statuses(&out, "walk.csv"), ["failed"]);

    set_file_size_limit(Some(child.id()), libc::RLIM_INFINITY);
    let took = time_until(&out.join("walk.imubake.json"), 30);
    eprintln!("room again → converted in {} ms", took.as_millis());
    assert!(child.child().try_wait().unwrap().is_none(), "no restart");
    wait_statuses(&out, "walk.csv", &["failed", "converted"], 30);
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(interrupt(child.take()), 0);
    assert_eq!(visible(&out), ["walk.bvh", "walk.glb", "walk.imubake.json"]);
    assert_consistent(&out);
    assert_eq!(statuses(&out, "walk.csv"), ["failed", "converted"]);
}

/// With the ledger not writable (`chmod 0444` on `ledger.jsonl`, binding the watcher as described
/// at [`unprivileged`]), a take that converts cannot be recorded: its outputs are removed, its
/// `.error.json` says why (the ledger named), the terminal says it is retried; once the ledger is
/// writable again the take converts and is recorded once, and the error report goes.
#[test]
fn an_unwritable_ledger_is_told_in_the_error_report_and_retried() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    fs::create_dir_all(&out).unwrap();
    fs::write(inbox.join("first.csv"), short_walk()).unwrap();
    let mut cmd = walk_watch(&inbox, &out, &[]);
    unprivileged(&mut cmd, dir.path());
    let mut child = Running::spawn(&mut cmd);
    let stderr = Stderr::of(child.child());
    // The backlog converted and recorded (the sidecar comes before the ledger line).
    let deadline = Instant::now() + Duration::from_secs(30);
    while statuses(&out, "first.csv").is_empty() {
        assert!(Instant::now() < deadline, "the backlog: {}", stderr.text());
        std::thread::sleep(Duration::from_millis(20));
    }

    let ledger_file = out.join(".imubake/ledger.jsonl");
    chmod(&ledger_file, 0o444);
    fs::write(inbox.join(".second.csv.tmp"), short_walk()).unwrap();
    fs::rename(inbox.join(".second.csv.tmp"), inbox.join("second.csv")).unwrap();
    // Not converted while the ledger is read-only: no output ever appears, over two attempts.
    let deadline = Instant::now() + Duration::from_secs(60);
    let retrying = ["retrying", r#"source="second.csv""#];
    while stderr.lines_with(&retrying).len() < 2 {
        for name in ["second.bvh", "second.glb", "second.imubake.json"] {
            assert!(
                !out.join(name).exists(),
                "{name} appears without a ledger line"
            );
        }
        assert!(Instant::now() < deadline, "two attempts: {}", stderr.text());
        std::thread::sleep(Duration::from_millis(5));
    }
    let lines = stderr.lines_with(&retrying);
    assert!(
        lines[0].contains("error_kind=PermissionDenied")
            && lines[0].contains("ledger.jsonl")
            && lines[0].contains("attempt=1")
            && lines[1].contains("attempt=2"),
        "{lines:?}"
    );
    // Each attempt writes the report again (removing the old one first): read it once it is there.
    assert!(wait_for(&out.join("second.error.json"), 30));
    let report: Value =
        serde_json::from_str(&fs::read_to_string(out.join("second.error.json")).unwrap()).unwrap();
    let reason = report["reason"].as_str().unwrap();
    assert!(
        reason.contains("not converted")
            && reason.contains("cannot record it in")
            && reason.contains("ledger.jsonl"),
        "{reason}"
    );
    assert!(report["hint"].as_str().is_some(), "{report}");
    for name in ["second.bvh", "second.glb", "second.imubake.json"] {
        assert!(
            !out.join(name).exists(),
            "{name} appears without a ledger line"
        );
    }
    assert!(statuses(&out, "second.csv").is_empty());

    chmod(&ledger_file, 0o644);
    let took = time_until(&out.join("second.imubake.json"), 30);
    eprintln!(
        "ledger writable again → converted in {} ms",
        took.as_millis()
    );
    assert!(child.child().try_wait().unwrap().is_none(), "no restart");
    wait_statuses(&out, "second.csv", &["converted"], 30);
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(interrupt(child.take()), 0);
    assert!(!out.join("second.error.json").exists());
    assert_eq!(statuses(&out, "second.csv"), ["converted"]);
    assert_eq!(statuses(&out, "first.csv"), ["converted"]);
    for name in ["second.bvh", "second.glb", "second.imubake.json"] {
        assert!(out.join(name).is_file(), "{name}");
    }
}

/// The PID and inbox a lock file names.
fn lock_holder(out: &Path) -> Option<(u32, PathBuf)> {
    let text = fs::read_to_string(out.join(".imubake/watch.lock")).ok()?;
    let v: Value = serde_json::from_str(text.trim()).ok()?;
    Some((
        u32::try_from(v["pid"].as_u64()?).ok()?,
        PathBuf::from(v["inbox"].as_str()?),
    ))
}

/// Waits up to `secs` for a child's exit code; kills it and panics past that.
fn exit_within(child: &mut Child, secs: u64, what: &str) -> i32 {
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status.code().unwrap_or(-1);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("{what}: still running after {secs} s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The issue's two watchers: a second watcher on the same output folder (the same inbox, or
/// another) exits at once, non-zero, naming the first's PID and inbox; the first alone converts
/// 100 takes dropped at once, each exactly once (100 ledger lines, all converted) with its BVH,
/// GLB and sidecar.
#[test]
fn a_second_watcher_on_one_output_exits_and_the_first_converts_each_take_once() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    let other_inbox = dir.path().join("other");
    fs::create_dir_all(&inbox).unwrap();
    fs::create_dir_all(&other_inbox).unwrap();
    let mut first = Running::spawn(&mut walk_watch(&inbox, &out, &[]));
    let first_log = Stderr::of(first.child());
    first_log.wait_lines(&["watching"], 1, 30);
    let canonical_inbox = inbox.canonicalize().unwrap();

    for second_inbox in [&inbox, &other_inbox] {
        let mut second = Running::spawn(&mut walk_watch(second_inbox, &out, &[]));
        let second_log = Stderr::of(second.child());
        let code = exit_within(second.child(), 30, "the second watcher");
        assert_ne!(code, 0);
        // Its stderr is read on a thread: wait for the line rather than for a while.
        let pid = format!("pid {}", first.id());
        let inbox_named = format!("inbox {}", canonical_inbox.display());
        second_log.wait_lines(&[&pid, &inbox_named], 1, 30);
        let text = second_log.text();
        assert!(!text.contains("watching"), "{text}");
    }
    assert_eq!(
        lock_holder(&out),
        Some((first.id(), canonical_inbox.clone()))
    );

    let takes: Vec<String> = (0..100).map(|i| format!("t{i:03}")).collect();
    for stem in &takes {
        let tmp = inbox.join(format!(".{stem}.csv.tmp"));
        fs::write(&tmp, short_walk()).unwrap();
        fs::rename(&tmp, inbox.join(format!("{stem}.csv"))).unwrap();
    }
    let deadline = Instant::now() + Duration::from_secs(180);
    for stem in &takes {
        let left = deadline.saturating_duration_since(Instant::now());
        assert!(
            wait_for(
                &out.join(format!("{stem}.imubake.json")),
                left.as_secs().max(1)
            ),
            "{stem} within 180 s"
        );
    }
    for stem in &takes {
        wait_statuses(&out, &format!("{stem}.csv"), &["converted"], 60);
    }
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(interrupt(first.take()), 0);

    let text = fs::read_to_string(out.join(".imubake/ledger.jsonl")).unwrap();
    assert_eq!(text.lines().count(), 100, "one ledger line per take");
    let ledger = ledger(&out);
    assert_eq!(ledger.len(), 100);
    for stem in &takes {
        let lines = &ledger[&format!("{stem}.csv")];
        assert_eq!(lines.len(), 1, "{stem}: {lines:?}");
        assert_eq!(lines[0].0, "converted", "{stem}");
        for ext in ["bvh", "glb", "imubake.json"] {
            assert!(out.join(format!("{stem}.{ext}")).is_file(), "{stem}.{ext}");
        }
    }
    assert_eq!(
        visible(&out).len(),
        300,
        "nothing else: {:?}",
        visible(&out)
    );
    assert_consistent(&out);
}

/// A watcher killed with SIGKILL leaves its lock file behind, naming it; the kernel released
/// the lock with the process, so the next watcher on that output takes it (the file then names
/// the new one) and converts.
#[test]
fn a_killed_watchers_lock_is_taken_by_the_next_watcher() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(&inbox).unwrap();
    let mut killed = Running::spawn(&mut walk_watch(&inbox, &out, &[]));
    Stderr::of(killed.child()).wait_lines(&["watching"], 1, 30);
    let canonical_inbox = inbox.canonicalize().unwrap();
    assert_eq!(
        lock_holder(&out),
        Some((killed.id(), canonical_inbox.clone()))
    );
    let mut killed = killed.take();
    killed.kill().unwrap(); // SIGKILL
    killed.wait().unwrap();
    assert!(out.join(".imubake/watch.lock").is_file(), "left behind");

    let mut next = Running::spawn(&mut walk_watch(&inbox, &out, &[]));
    let log = Stderr::of(next.child());
    log.wait_lines(&["watching"], 1, 30);
    assert_eq!(lock_holder(&out), Some((next.id(), canonical_inbox)));
    fs::write(inbox.join("walk.csv"), short_walk()).unwrap();
    assert!(
        wait_for(&out.join("walk.imubake.json"), 30),
        "{}",
        log.text()
    );
    // The ledger line is written after the sidecar.
    wait_statuses(&out, "walk.csv", &["converted"], 30);
    assert_eq!(interrupt(next.take()), 0);
}

/// A file standing where a take's output folder goes (works as any user, root included) is the
/// environment's failure too: retried, and converted once the file is moved away.
#[test]
fn a_file_in_place_of_the_output_folder_is_retried_until_moved() {
    let dir = tempfile::tempdir().unwrap();
    let (inbox, out) = (dir.path().join("in"), dir.path().join("out"));
    fs::create_dir_all(inbox.join("day3")).unwrap();
    fs::create_dir_all(&out).unwrap();
    fs::write(out.join("day3"), b"in the way").unwrap();
    fs::write(inbox.join("day3/walk.csv"), short_walk()).unwrap();
    let mut child = Running::spawn(&mut walk_watch(&inbox, &out, &[]));
    let stderr = Stderr::of(child.child());
    let lines = stderr.wait_lines(&["retrying", r#"source="day3/walk.csv""#], 1, 30);
    assert!(lines[0].contains("error_kind=AlreadyExists"), "{lines:?}");
    fs::remove_file(out.join("day3")).unwrap();
    let took = time_until(&out.join("day3/walk.imubake.json"), 30);
    eprintln!("moved away → converted in {} ms", took.as_millis());
    assert!(child.child().try_wait().unwrap().is_none(), "no restart");
    wait_statuses(&out, "day3/walk.csv", &["failed", "converted"], 30);
    assert_eq!(interrupt(child.take()), 0);
    assert_eq!(
        visible(&out.join("day3")),
        ["walk.bvh", "walk.glb", "walk.imubake.json"]
    );
    assert_eq!(statuses(&out, "day3/walk.csv"), ["failed", "converted"]);
}
