//! `imubake batch` on real folders: mirrored outputs, error reports, the ledger (skips, retries,
//! reconversion of changed captures), byte-identical outputs, shards, collisions.

use imubake::ledger::{Ledger, ledger_path};
use serde_json::Value;
use std::collections::BTreeSet;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

const SHARD_VARS: [&str; 7] = [
    "JOB_COMPLETION_INDEX",
    "IMUBAKE_SHARD_COUNT",
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_COUNT",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_MAX",
    "SLURM_ARRAY_TASK_STEP",
];

struct Run {
    code: i32,
    stdout: String,
    stderr: String,
}

impl Run {
    fn json(&self) -> Value {
        serde_json::from_str(&self.stdout)
            .unwrap_or_else(|e| panic!("{e}: stdout {}\nstderr {}", self.stdout, self.stderr))
    }

    fn counts(&self) -> (u64, u64, u64) {
        let j = self.json();
        (
            j["converted"].as_u64().unwrap(),
            j["failed"].as_u64().unwrap(),
            j["skipped"].as_u64().unwrap(),
        )
    }
}

fn batch_env(args: &[&str], env: &[(&str, &str)]) -> Run {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_imubake"));
    cmd.arg("batch").args(args);
    for v in SHARD_VARS.iter().chain(&["RUST_LOG", "IMUBAKE_LOG"]) {
        cmd.env_remove(v);
    }
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().expect("run imubake");
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// `batch <input> --out <out> --json`, fast settings.
fn batch(input: &Path, out: &Path, extra: &[&str]) -> Run {
    let mapping = repo("samples/sou_wave.mapping.json");
    let mut args = vec![
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--mapping",
        mapping.to_str().unwrap(),
        "--smooth",
        "none",
        "--format",
        "bvh",
        "--json",
    ];
    if !extra.contains(&"--jobs") {
        args.extend(["--jobs", "2"]);
    }
    args.extend_from_slice(extra);
    batch_env(&args, &[])
}

const GOOD: [&str; 17] = [
    "a.log",
    "b.log",
    "c.log",
    "d.log",
    "e.log",
    "walk 1.log",
    "sub/a.log",
    "sub/f.log",
    "sub/g.log",
    "sub/h.log",
    "sub/deeper/i.log",
    "sub/deeper/j.log",
    "sub/deeper/k.log",
    "other/l.log",
    "other/m.log",
    "other/n.log",
    "other/o.txt",
];
const BAD: [&str; 3] = ["garbage.log", "sub/empty.log", "other/notes.txt"];

fn sample() -> Vec<u8> {
    fs::read(repo("samples/sou_wave.log")).unwrap()
}

/// 17 good takes and 3 bad ones (binary garbage, empty, prose).
fn make_library(dir: &Path) {
    let good = sample();
    for rel in GOOD {
        let p = dir.join(rel);
        fs::create_dir_all(p.parent().unwrap()).unwrap();
        fs::write(&p, &good).unwrap();
    }
    let garbage: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    fs::write(dir.join(BAD[0]), garbage).unwrap();
    fs::write(dir.join(BAD[1]), b"").unwrap();
    fs::write(dir.join(BAD[2]), b"Remember to charge the sensors.\n").unwrap();
}

fn stem_path(rel: &str) -> String {
    let p = Path::new(rel);
    let stem = p.file_stem().unwrap().to_string_lossy();
    match p.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(d) => format!("{}/{stem}", d.display()),
        None => stem.into_owned(),
    }
}

/// Every file under `dir` (relative, `/`-separated), the ledger folder left out.
fn files(dir: &Path) -> BTreeSet<String> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeSet<String>) {
        for e in fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            if rel == ".imubake" {
                continue;
            }
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                out.insert(rel);
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(dir, dir, &mut out);
    out
}

fn expected_outputs(good: &[&str], bad: &[&str]) -> BTreeSet<String> {
    let mut set = BTreeSet::new();
    for g in good {
        set.insert(format!("{}.bvh", stem_path(g)));
        set.insert(format!("{}.imubake.json", stem_path(g)));
    }
    for b in bad {
        set.insert(format!("{}.error.json", stem_path(b)));
    }
    set
}

/// The per-take log lines of a run's stderr, as (source, outcome), sorted. Every line that names a
/// take's outcome must have the whole shape: `<UTC time>  INFO converted source="…" duration_ms=N
/// outputs=[…]` or `<UTC time> ERROR failed source="…" duration_ms=N error_report="…"
/// reason="…"`; stderr, not a terminal here, carries no colour codes (nor a progress bar).
fn take_lines(stderr: &str) -> Vec<(String, String)> {
    assert!(!stderr.contains('\x1b'), "ANSI codes on a pipe: {stderr}");
    let shape = regex::Regex::new(
        r#"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d+Z +(?:INFO (converted) source="([^"]+)" duration_ms=\d+(?: dropped_lines=\d+ repaired_lines=\d+)? outputs=\[".+"\]|ERROR (failed) source="([^"]+)" duration_ms=\d+ error_report="[^"]+\.error\.json" reason=".+")$"#,
    )
    .unwrap();
    let mut lines: Vec<(String, String)> = stderr
        .lines()
        .filter(|l| l.contains(" converted ") || l.contains(" failed "))
        .map(|line| {
            let c = shape
                .captures(line)
                .unwrap_or_else(|| panic!("a take's line of the wrong shape: {line}"));
            match c.get(1) {
                Some(status) => (c[2].to_string(), status.as_str().to_string()),
                None => (c[4].to_string(), c[3].to_string()),
            }
        })
        .collect();
    lines.sort();
    lines
}

/// (take, outcome) for each of `good` converted and `bad` failed, sorted.
fn outcomes(good: &[&str], bad: &[&str]) -> Vec<(String, String)> {
    let mut v: Vec<(String, String)> = good
        .iter()
        .map(|g| (g.to_string(), "converted".to_string()))
        .chain(bad.iter().map(|b| (b.to_string(), "failed".to_string())))
        .collect();
    v.sort();
    v
}

fn mtime(p: &Path) -> std::time::SystemTime {
    fs::metadata(p).unwrap().modified().unwrap()
}

#[test]
fn a_library_converts_skips_retries_and_reconverts_what_changed() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    let out = tmp.path().join("out");
    make_library(&input);

    // First run: every good take once, in its mirrored folder; an error report per bad one.
    let run = batch(&input, &out, &[]);
    assert_eq!(run.code, 1, "a failed take fails the run: {}", run.stderr);
    assert_eq!(run.counts(), (17, 3, 0), "{}", run.stderr);
    assert_eq!(files(&out), expected_outputs(&GOOD, &BAD));
    // One log line per take, with its duration.
    assert_eq!(
        take_lines(&run.stderr),
        outcomes(&GOOD, &BAD),
        "{}",
        run.stderr
    );
    let report: Value =
        serde_json::from_slice(&fs::read(out.join("garbage.error.json")).unwrap()).unwrap();
    assert_eq!(report["source"], "garbage.log");
    assert!(
        report["reason"].as_str().unwrap().contains("binary"),
        "{report}"
    );
    assert!(report["file"].as_str().unwrap().ends_with("garbage.log"));
    assert!(report["line"].is_null());
    assert!(report["hint"].is_string());
    let empty: Value =
        serde_json::from_slice(&fs::read(out.join("sub/empty.error.json")).unwrap()).unwrap();
    assert!(
        empty["reason"].as_str().unwrap().contains("empty"),
        "{empty}"
    );
    // No temporary files are left.
    assert!(files(&out).iter().all(|f| !f.ends_with(".tmp")));
    // The sidecar names the source and carries no conversion time.
    let sidecar = fs::read_to_string(out.join("sub/deeper/i.imubake.json")).unwrap();
    assert!(sidecar.contains("i.log"));
    assert!(!sidecar.contains("converted_at"));

    // Second run: the good takes are current (skipped, untouched); the bad ones are retried and
    // fail again, so the run still exits 1.
    let before = mtime(&out.join("a.bvh"));
    let run = batch(&input, &out, &[]);
    assert_eq!(run.counts(), (0, 3, 17), "{}", run.stderr);
    assert_eq!(run.code, 1);
    // Skipped takes are not logged (at the default level).
    assert_eq!(
        take_lines(&run.stderr),
        outcomes(&[], &BAD),
        "{}",
        run.stderr
    );
    assert_eq!(mtime(&out.join("a.bvh")), before);
    assert_eq!(files(&out), expected_outputs(&GOOD, &BAD));

    // Fixing the bad files converts them and removes their error reports.
    for b in BAD {
        fs::write(input.join(b), sample()).unwrap();
    }
    let run = batch(&input, &out, &[]);
    assert_eq!(run.counts(), (3, 0, 17), "{}", run.stderr);
    assert_eq!(run.code, 0);
    let all: Vec<&str> = GOOD.iter().chain(BAD.iter()).copied().collect();
    assert_eq!(files(&out), expected_outputs(&all, &[]));

    // Nothing changed: everything is skipped, exit 0.
    let run = batch(&input, &out, &[]);
    assert_eq!(run.counts(), (0, 0, 20), "{}", run.stderr);
    assert_eq!(run.code, 0);

    // A changed capture converts again (only that take) and replaces its outputs.
    let text = String::from_utf8(sample()).unwrap();
    let shorter: Vec<&str> = text.lines().take(text.lines().count() - 200).collect();
    fs::write(input.join("sub/f.log"), shorter.join("\n") + "\n").unwrap();
    let old_bvh = fs::read(out.join("sub/f.bvh")).unwrap();
    let untouched = mtime(&out.join("sub/g.bvh"));
    let run = batch(&input, &out, &[]);
    assert_eq!(run.counts(), (1, 0, 19), "{}", run.stderr);
    let takes = run.json()["takes"].as_array().unwrap().clone();
    let converted: Vec<&str> = takes
        .iter()
        .filter(|t| t["status"] == "converted")
        .map(|t| t["source"].as_str().unwrap())
        .collect();
    assert_eq!(converted, ["sub/f.log"]);
    assert_ne!(fs::read(out.join("sub/f.bvh")).unwrap(), old_bvh);
    assert_eq!(mtime(&out.join("sub/g.bvh")), untouched);
    assert_eq!(files(&out), expected_outputs(&all, &[]));

    // A file that turns bad loses its outputs to an error report; the ledger records it.
    fs::write(input.join("sub/g.log"), b"\0\0\0").unwrap();
    let run = batch(&input, &out, &[]);
    assert_eq!((run.code, run.counts()), (1, (0, 1, 19)), "{}", run.stderr);
    assert!(!out.join("sub/g.bvh").exists() && !out.join("sub/g.imubake.json").exists());
    assert!(out.join("sub/g.error.json").exists());
    let ledger = Ledger::load(&out).unwrap();
    assert_eq!(ledger.len(), 20);
    assert_eq!(ledger.skipped_lines(), 0);
    let g = ledger.latest("sub/g.log").unwrap();
    assert_eq!(g.status, imubake::ledger::Status::Failed);
    assert!(g.error.as_deref().unwrap().contains("binary"));

    // Different settings make every take stale.
    let run = batch(&input, &out, &["--fps", "25"]);
    assert_eq!(run.counts(), (19, 1, 0), "{}", run.stderr);
}

#[test]
fn the_same_capture_gives_byte_identical_outputs() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    fs::create_dir_all(input.join("x")).unwrap();
    fs::write(input.join("x/one.log"), sample()).unwrap();
    fs::write(input.join("x/two.log"), sample()).unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    assert_eq!(batch(&input, &a, &[]).code, 0);
    assert_eq!(batch(&input, &b, &["--jobs", "1"]).code, 0);
    let names = files(&a);
    assert_eq!(names, files(&b));
    for f in &names {
        assert_eq!(
            fs::read(a.join(f)).unwrap(),
            fs::read(b.join(f)).unwrap(),
            "{f} differs between runs"
        );
    }
    // Two copies of one capture: the same motion.
    assert_eq!(
        fs::read(a.join("x/one.bvh")).unwrap(),
        fs::read(a.join("x/two.bvh")).unwrap()
    );
}

fn list(args: &[&str], env: &[(&str, &str)]) -> (i32, Vec<String>) {
    let mut all = args.to_vec();
    all.extend(["--list", "--json"]);
    let run = batch_env(&all, env);
    if run.code != 0 {
        return (run.code, Vec::new());
    }
    let v: Vec<String> = serde_json::from_str(&run.stdout).unwrap();
    (run.code, v)
}

#[test]
fn shards_partition_the_takes_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    make_library(&input);
    let inp = input.to_str().unwrap();
    let (code, all) = list(&[inp, "--out", tmp.path().join("o").to_str().unwrap()], &[]);
    assert_eq!(code, 0);
    assert_eq!(all.len(), 20);
    let mut sorted = all.clone();
    sorted.sort();
    assert_eq!(all, sorted, "takes in relative-path order");

    // Converted for real, each shard into its own folder: the outputs partition the library.
    let mut union = BTreeSet::new();
    let mut total = 0;
    for i in 0..3 {
        let out = tmp.path().join(format!("shard{i}"));
        let run = batch(&input, &out, &["--shard", &format!("{i}/3")]);
        let (c, f, s) = run.counts();
        assert_eq!(s, 0);
        total += c + f;
        let listed = list(
            &[
                inp,
                "--out",
                out.to_str().unwrap(),
                "--shard",
                &format!("{i}/3"),
            ],
            &[],
        )
        .1;
        let expected: Vec<String> = all.iter().skip(i).step_by(3).cloned().collect();
        assert_eq!(listed, expected);
        for f in files(&out) {
            assert!(union.insert(f.clone()), "{f} in two shards");
        }
    }
    assert_eq!(total, 20);
    assert_eq!(union, expected_outputs(&GOOD, &BAD));

    // From the environment: a Kubernetes Indexed Job, a Slurm array.
    let out = tmp.path().join("o");
    let args = [inp, "--out", out.to_str().unwrap()];
    let shard1: Vec<String> = all.iter().skip(1).step_by(3).cloned().collect();
    assert_eq!(
        list(
            &args,
            &[("JOB_COMPLETION_INDEX", "1"), ("IMUBAKE_SHARD_COUNT", "3")]
        ),
        (0, shard1.clone())
    );
    assert_eq!(
        list(
            &args,
            &[
                ("SLURM_ARRAY_TASK_ID", "11"),
                ("SLURM_ARRAY_TASK_MIN", "10"),
                ("SLURM_ARRAY_TASK_COUNT", "3")
            ]
        ),
        (0, shard1.clone())
    );
    // Kubernetes gives no count: without one it is a usage error.
    assert_eq!(list(&args, &[("JOB_COMPLETION_INDEX", "1")]).0, 2);
    // --shard wins over the environment.
    let mut explicit = args.to_vec();
    explicit.extend(["--shard", "1/3"]);
    assert_eq!(
        list(
            &explicit,
            &[
                ("SLURM_ARRAY_TASK_ID", "0"),
                ("SLURM_ARRAY_TASK_COUNT", "2")
            ]
        ),
        (0, shard1)
    );
    assert_eq!(list(&[inp, "--out", "o", "--shard", "3/3"], &[]).0, 2);
}

#[test]
fn folders_globs_sessions_and_collisions() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    make_library(&input);
    // A session folder is one take.
    let session = input.join("sub/session");
    fs::create_dir_all(&session).unwrap();
    for e in fs::read_dir(repo("tests/fixtures/xio/session")).unwrap() {
        let e = e.unwrap();
        let dev = session.join(e.file_name());
        fs::create_dir_all(&dev).unwrap();
        for f in fs::read_dir(e.path()).unwrap() {
            let f = f.unwrap();
            fs::copy(f.path(), dev.join(f.file_name())).unwrap();
        }
    }
    let out = tmp.path().join("out");
    let o = out.to_str().unwrap();
    let (_, all) = list(&[input.to_str().unwrap(), "--out", o], &[]);
    assert_eq!(all.len(), 21);
    assert!(all.contains(&"sub/session".to_string()), "{all:?}");
    let (_, one) = list(&[session.to_str().unwrap(), "--out", o], &[]);
    assert_eq!(one, ["session"]);

    // Globs: relative to the folder before the first wildcard.
    let pattern = format!("{}/**/*.log", input.display());
    let (code, logs) = list(&[&pattern, "--out", o], &[]);
    assert_eq!(code, 0);
    let expected: Vec<String> = all
        .iter()
        .filter(|t| t.ends_with(".log"))
        .cloned()
        .collect();
    assert_eq!(logs, expected);
    let pattern = format!("{}/sub/?.log", input.display());
    assert_eq!(
        list(&[&pattern, "--out", o], &[]).1,
        ["a.log", "f.log", "g.log", "h.log"]
    );
    let none = format!("{}/*.nothing", input.display());
    assert_eq!(list(&[&none, "--out", o], &[]).0, 2);

    // An output folder inside the input is not an input.
    let inner = input.join("converted");
    let run = batch(&input.join("other"), &inner, &[]);
    assert_eq!(run.counts(), (4, 1, 0));
    let (_, again) = list(
        &[input.to_str().unwrap(), "--out", inner.to_str().unwrap()],
        &[],
    );
    assert_eq!(again, all);

    // Two takes that would write the same outputs: a usage error before anything runs.
    fs::write(input.join("sub/f.csv"), sample()).unwrap();
    let run = batch(&input, &out, &[]);
    assert_eq!(run.code, 2);
    assert!(
        run.stderr.lines().any(|l| l.contains(" ERROR ")
            && l.contains("sub/f.csv")
            && l.contains("sub/f.log")
            && l.contains("would both write `sub/f.*`")),
        "{}",
        run.stderr
    );
    assert!(!out.join("a.bvh").exists());
}

#[test]
fn a_torn_ledger_line_is_ignored() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    fs::create_dir_all(&input).unwrap();
    for n in ["a", "b", "c"] {
        fs::write(input.join(format!("{n}.log")), sample()).unwrap();
    }
    let out = tmp.path().join("out");
    assert_eq!(batch(&input, &out, &[]).counts(), (3, 0, 0));
    // A crash while appending: half a line.
    let mut f = fs::OpenOptions::new()
        .append(true)
        .open(ledger_path(&out))
        .unwrap();
    f.write_all(br#"{"source":"a.log","size":12,"mtime_"#)
        .unwrap();
    drop(f);
    let ledger = Ledger::load(&out).unwrap();
    assert_eq!(ledger.skipped_lines(), 1);
    assert_eq!(ledger.len(), 3);
    let run = batch(&input, &out, &[]);
    assert_eq!((run.code, run.counts()), (0, (0, 0, 3)), "{}", run.stderr);
    // Later appends start on their own line.
    fs::write(input.join("d.log"), sample()).unwrap();
    assert_eq!(batch(&input, &out, &[]).counts(), (1, 0, 3));
    let ledger = Ledger::load(&out).unwrap();
    assert_eq!((ledger.len(), ledger.skipped_lines()), (4, 1));
}

/// A folder symlink cycle (`ln -s .. in/sub/up`) is walked once, with one warning, and an
/// inbox's `imubake.yaml` and a mapping kept beside the takes are not takes.
#[test]
#[cfg(unix)]
fn a_symlink_cycle_and_settings_files_are_not_takes() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    fs::create_dir_all(input.join("sub")).unwrap();
    fs::write(input.join("a.log"), sample()).unwrap();
    fs::write(input.join("sub/b.log"), sample()).unwrap();
    std::os::unix::fs::symlink("..", input.join("sub/up")).unwrap();
    fs::write(input.join("imubake.yaml"), "smoothing: none\n").unwrap();
    fs::copy(
        repo("samples/sou_wave.mapping.json"),
        input.join("mapping.json"),
    )
    .unwrap();
    fs::copy(repo("rigs/sou12.yaml"), input.join("sub/body.yml")).unwrap();
    let out = tmp.path().join("out");
    let run = batch(&input, &out, &[]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert_eq!(run.counts(), (2, 0, 0), "{}", run.stdout);
    assert_eq!(
        files(&out),
        expected_outputs(&["a.log", "sub/b.log"], &[]),
        "no bogus failures or nested folders"
    );
    let cycle_warnings = run
        .stderr
        .lines()
        .filter(|l| l.contains(" WARN ") && l.contains("symlink cycle"))
        .count();
    assert_eq!(cycle_warnings, 1, "{}", run.stderr);
}

/// Shards run as separate processes at once, all into one output folder (as array tasks on a
/// cluster do): each appends to its own ledger file, and every line of every file is whole — one
/// `converted` line per take, none lost or torn — and an unsharded rerun reads them all and
/// converts nothing.
#[test]
fn concurrent_shards_into_one_output_lose_no_ledger_line() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    fs::create_dir_all(&input).unwrap();
    let takes: Vec<String> = (0..24).map(|n| format!("take{n:02}.log")).collect();
    for t in &takes {
        fs::write(input.join(t), sample()).unwrap();
    }
    let out = tmp.path().join("out");
    let mapping = repo("samples/sou_wave.mapping.json");
    let count = 6;
    let children: Vec<_> = (0..count)
        .map(|i| {
            let mut cmd = Command::new(env!("CARGO_BIN_EXE_imubake"));
            cmd.arg("batch")
                .arg(&input)
                .arg("--out")
                .arg(&out)
                .arg("--mapping")
                .arg(&mapping)
                .args(["--smooth", "none", "--format", "bvh", "--jobs", "1"])
                .args(["--shard", &format!("{i}/{count}")])
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::piped());
            for v in SHARD_VARS {
                cmd.env_remove(v);
            }
            cmd.spawn().expect("run imubake")
        })
        .collect();
    for child in children {
        let out = child.wait_with_output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let dir = imubake::ledger::ledger_dir(&out);
    let mut names: Vec<String> = fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    let expected: Vec<String> = (0..count)
        .map(|i| imubake::ledger::shard_ledger_name(i, count))
        .collect();
    assert_eq!(names, expected, "a file per shard, no shared one");
    let mut converted = Vec::new();
    for (i, name) in names.iter().enumerate() {
        let text = fs::read_to_string(dir.join(name)).unwrap();
        assert!(text.ends_with('\n'), "{name}: a torn last line");
        for line in text.lines() {
            let entry: imubake::ledger::LedgerEntry =
                serde_json::from_str(line).unwrap_or_else(|e| panic!("{name}: {e}: {line}"));
            assert_eq!(entry.status, imubake::ledger::Status::Converted, "{line}");
            // Shard i's takes are those at i, i + count, … in path order.
            let index = takes.iter().position(|t| *t == entry.source).unwrap();
            assert_eq!(index % count, i, "{name} holds {}", entry.source);
            converted.push(entry.source);
        }
    }
    converted.sort();
    assert_eq!(converted, takes, "one line per take, none lost");
    let ledger = Ledger::load(&out).unwrap();
    assert_eq!((ledger.len(), ledger.skipped_lines()), (takes.len(), 0));
    let run = batch(&input, &out, &[]);
    assert_eq!((run.code, run.counts()), (0, (0, 0, 24)), "{}", run.stderr);
}
