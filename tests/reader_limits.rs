//! Issue 43, "no stream or file can stall or swamp imubake": a piped input is judged by its
//! first bytes and read with its lines' length checked as it goes, and a BVH frame line is
//! refused at its first value past the hierarchy's channels, never held whole.
//!
//! Each case runs in a child process (the `imubake` binary, or this test binary re-run on one
//! entry point for the BVH reader alone) and measures the child's peak resident memory as the
//! kernel counts it: `ru_maxrss` of the `rusage` that `wait4` gives for that one child. The
//! inputs are hundreds of megabytes, so reading them whole (what the readers did before) shows
//! as hundreds of megabytes resident; the bounds are far below that and far above the binary's
//! own few megabytes.

mod common;

use std::io::{self, Read, Write};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

const MIB: u64 = 1 << 20;

/// The peak resident memory a reader may reach on any of these inputs.
const PEAK_BOUND_KIB: u64 = 100 * 1024;

/// The line-length limit of the text readers (`imubake::read::lines::MAX_LINE_BYTES`), written
/// out here so that a change of the limit is a decision, not a drift.
const LINE_LIMIT: u64 = 1 << 20;

/// What a child did.
struct Run {
    /// The exit code, or `None` when a signal ended it.
    code: Option<i32>,
    signal: Option<i32>,
    stdout: String,
    stderr: String,
    /// Peak resident memory, KiB (`ru_maxrss`).
    peak_kib: u64,
    /// Bytes the child's stdin accepted before it was closed (all of them, or fewer when the
    /// child stopped reading and exited).
    fed: u64,
}

impl Run {
    fn describe(&self) -> String {
        format!(
            "exit {:?} signal {:?}, peak {} KiB, {} bytes fed\nstdout: {}\nstderr: {}",
            self.code, self.signal, self.peak_kib, self.fed, self.stdout, self.stderr
        )
    }
}

/// `chunk` written `times` times.
#[derive(Clone)]
struct Segment {
    chunk: Vec<u8>,
    times: u64,
}

/// Runs `cmd` with `feed` written to its stdin by a thread of its own (a child that exits early
/// closes the pipe: the write fails with `BrokenPipe`, which is what a bounded reader should
/// cause, and ends the feeding), reaps it with `wait4` for its own `rusage`, and kills it if it
/// has not finished within `limit`.
fn run_fed(cmd: &mut Command, feed: Vec<Segment>, limit: Duration) -> Run {
    let mut child = cmd
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn the child");
    let mut stdin = child.stdin.take().expect("stdin");
    let writer = std::thread::spawn(move || {
        let mut fed = 0u64;
        for segment in &feed {
            for _ in 0..segment.times {
                let mut rest = &segment.chunk[..];
                while !rest.is_empty() {
                    match stdin.write(rest) {
                        Ok(n) => {
                            fed += n as u64;
                            rest = &rest[n..];
                        }
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => return fed,
                        Err(e) => panic!("writing the child's stdin: {e}"),
                    }
                }
            }
        }
        fed
    });
    finish(child, limit, Some(writer))
}

/// Runs `cmd` without input.
fn run(cmd: &mut Command, limit: Duration) -> Run {
    let child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn the child");
    finish(child, limit, None)
}

fn finish(mut child: Child, limit: Duration, writer: Option<std::thread::JoinHandle<u64>>) -> Run {
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut text = Vec::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_end(&mut text);
            }
            String::from_utf8_lossy(&text).into_owned()
        })
    };
    let stdout = drain(
        child
            .stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let stderr = drain(
        child
            .stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let pid = child.id() as libc::pid_t;
    let (done_tx, done_rx) = mpsc::channel::<()>();
    let watchdog = std::thread::spawn(move || {
        if done_rx.recv_timeout(limit) == Err(mpsc::RecvTimeoutError::Timeout) {
            // SAFETY: a signal to the child, which is not reaped before `done` is sent.
            unsafe { libc::kill(pid, libc::SIGKILL) };
            return true;
        }
        false
    });
    let mut status: libc::c_int = 0;
    // SAFETY: `wait4` fills the zeroed `rusage` and the status it is given and keeps neither.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
        if r == pid {
            break;
        }
        let e = io::Error::last_os_error();
        assert_eq!(e.kind(), io::ErrorKind::Interrupted, "wait4: {e}");
    }
    let _ = done_tx.send(());
    let killed = watchdog.join().unwrap_or(false);
    let fed = writer.map_or(0, |w| w.join().expect("the writer thread"));
    let run = Run {
        code: libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status)),
        signal: libc::WIFSIGNALED(status).then(|| libc::WTERMSIG(status)),
        stdout: stdout.join().unwrap_or_default(),
        stderr: stderr.join().unwrap_or_default(),
        peak_kib: usage.ru_maxrss as u64,
        fed,
    };
    assert!(
        !killed,
        "the child did not finish in {limit:?}: {}",
        run.describe()
    );
    run
}

fn imubake() -> Command {
    Command::new(common::imubake_bin())
}

// ------------------------------------------------------------------ piped input

/// `imubake <command> /dev/stdin` fed `segments`, for `inspect` and for `convert` (onto mixamo,
/// into a scratch folder): each must exit 1 with `message` in its error, its peak RSS under
/// [`PEAK_BOUND_KIB`], having taken less than `fed_below` bytes from the pipe.
fn refused_on_stdin_by_both(segments: &[Segment], message: &str, fed_below: u64) {
    for command in ["inspect", "convert"] {
        let out = tempfile::tempdir().unwrap();
        let mut cmd = imubake();
        cmd.args([command, "/dev/stdin"]);
        if command == "convert" {
            cmd.args(["--rig", "mixamo", "--out"]).arg(out.path());
        }
        let run = run_fed(&mut cmd, segments.to_vec(), Duration::from_secs(300));
        eprintln!("{command}: {}", run.describe());
        assert_eq!(run.code, Some(1), "{command}: {}", run.describe());
        assert!(
            run.stderr.contains(message),
            "{command}: {}",
            run.describe()
        );
        assert!(
            run.peak_kib < PEAK_BOUND_KIB,
            "{command}: {}",
            run.describe()
        );
        assert!(run.fed < fed_below, "{command}: {}", run.describe());
    }
}

/// 300 MB of the byte `a` on stdin: no capture format starts like that, which the first few
/// KiB tell. The child must answer from them, never holding the rest, and stop reading: the
/// pipe takes at most a few MiB before it closes.
#[test]
fn an_unknown_format_on_stdin_is_refused_after_its_first_bytes() {
    let junk = Segment {
        chunk: vec![b'a'; MIB as usize],
        times: 300,
    };
    refused_on_stdin_by_both(&[junk], "unknown capture format", 16 * MIB);
}

/// An imubake CSV header, then one 300 MB line without a newline: the header decides the
/// format, and the second line is refused once it passes the 1 MiB limit, by number.
#[test]
fn a_huge_line_after_a_csv_header_on_stdin_is_refused_at_the_limit() {
    let segments = [
        Segment {
            chunk: b"time_s,sensor,qw,qx,qy,qz\n".to_vec(),
            times: 1,
        },
        Segment {
            chunk: vec![b'1'; MIB as usize],
            times: 300,
        },
    ];
    let message = format!("line 2: the line is longer than {LINE_LIMIT} bytes");
    refused_on_stdin_by_both(&segments, &message, 32 * MIB);
}

/// A valid take still reads from a pipe: 2000 rows of one sensor at 100 Hz, 40 bytes a row;
/// `inspect --json` counts them and their interval (10 ms, by construction).
#[test]
fn a_valid_capture_still_reads_from_stdin() {
    let mut text = b"time_s,sensor,qw,qx,qy,qz\n".to_vec();
    for i in 0..2000 {
        text.extend_from_slice(format!("{:.2},pelvis,1,0,0,0\n", i as f64 / 100.0).as_bytes());
    }
    let run = run_fed(
        imubake().args(["inspect", "/dev/stdin", "--json"]),
        vec![Segment {
            chunk: text,
            times: 1,
        }],
        Duration::from_secs(120),
    );
    assert_eq!(run.code, Some(0), "{}", run.describe());
    let json: serde_json::Value = serde_json::from_str(&run.stdout).expect("JSON");
    let pelvis = &json["sensors"]["pelvis"];
    assert_eq!(pelvis["samples"], 2000, "{json}");
    let mean = pelvis["mean_dt_ms"].as_f64().unwrap();
    assert!((mean - 10.0).abs() < 1e-6, "{json}");
    assert_eq!(json["source"]["format"], "imubake-csv", "{json}");
}

// ------------------------------------------------------------------ BVH frame lines

/// A valid hierarchy of 9 channels (the root's 6, one joint's 3), `Frames: 1`, then one frame
/// line of `values` values `0.0 ` (4 bytes each) and a newline: line [`FRAME_LINE`].
fn write_bvh(path: &Path, values: u64) {
    let head = "HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\tJOINT Spine\n\t{\n\t\tOFFSET 0 10 0\n\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n\t}\n}\nMOTION\nFrames: 1\nFrame Time: 0.0333333\n";
    let mut file = io::BufWriter::new(std::fs::File::create(path).unwrap());
    file.write_all(head.as_bytes()).unwrap();
    let chunk = "0.0 ".repeat(1 << 16);
    let mut left = values;
    while left > 0 {
        let n = left.min(1 << 16);
        file.write_all(&chunk.as_bytes()[..(n * 4) as usize])
            .unwrap();
        left -= n;
    }
    file.write_all(b"\n").unwrap();
    file.flush().unwrap();
}

/// The frame line's number in [`write_bvh`]'s file.
const FRAME_LINE: u64 = 15;

/// 50 million values (200 MB) on one frame line of a 9-channel hierarchy, read by the library's
/// BVH reader alone (this test binary re-run on [`bvh_reader_child_entry`]): refused at value 10
/// with the line and the count, the line never held.
#[test]
fn a_bvh_frame_line_with_too_many_values_is_refused_without_holding_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long_line.bvh");
    write_bvh(&path, 50_000_000);
    let run = run(
        Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "bvh_reader_child_entry",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD_BVH, &path),
        Duration::from_secs(300),
    );
    eprintln!("{}", run.describe());
    assert_eq!(run.code, Some(0), "{}", run.describe());
    let line = run
        .stdout
        .lines()
        .find_map(|l| l.split_once("bvh error: ").map(|(_, e)| e))
        .unwrap_or_else(|| panic!("no error from the reader: {}", run.describe()));
    assert!(
        line.starts_with(&format!("line {FRAME_LINE}: ")),
        "{}",
        run.describe()
    );
    assert!(line.contains("expected 9 values"), "{}", run.describe());
    assert!(run.peak_kib < PEAK_BOUND_KIB, "{}", run.describe());
}

/// The name of the variable that makes [`bvh_reader_child_entry`] read a file.
const CHILD_BVH: &str = "IMUBAKE_READER_LIMITS_BVH";

/// Not a test of its own: the child process of
/// [`a_bvh_frame_line_with_too_many_values_is_refused_without_holding_it`], which runs this
/// binary on this entry with [`CHILD_BVH`] set. It reads the file with the library's BVH reader
/// and prints the outcome for the parent to judge; run without the variable it does nothing.
#[test]
fn bvh_reader_child_entry() {
    let Some(path) = std::env::var_os(CHILD_BVH) else {
        return;
    };
    let file = std::fs::File::open(&path).expect("open the BVH");
    match imubake::bvh::read(file) {
        Ok(bvh) => println!("bvh read: {} frames", bvh.frame_count()),
        Err(e) => println!("bvh error: {e}"),
    }
}

/// The same file through `imubake convert`: the same error, by line and count, exit 1, and the
/// same bound: `convert` hashes a BVH take as the reader reads it, never holding the file (before,
/// 50 million tokens took it to 985 MB; reading the file whole to hash it, 204 MB).
#[test]
fn convert_refuses_a_bvh_frame_line_with_too_many_values() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long_line.bvh");
    write_bvh(&path, 50_000_000);
    let run = run(
        imubake()
            .arg("convert")
            .arg(&path)
            .args(["--rig", "mixamo", "--out"])
            .arg(dir.path().join("out")),
        Duration::from_secs(300),
    );
    eprintln!("{}", run.describe());
    assert_eq!(run.code, Some(1), "{}", run.describe());
    assert!(
        run.stderr.contains(&format!("line {FRAME_LINE}: ")),
        "{}",
        run.describe()
    );
    assert!(
        run.stderr.contains("expected 9 values"),
        "{}",
        run.describe()
    );
    assert!(run.peak_kib < PEAK_BOUND_KIB, "{}", run.describe());
}
