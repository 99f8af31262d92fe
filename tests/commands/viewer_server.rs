//! The viewer's server under hostile clients (issue 44): request lines and headers past their
//! limits refused (414, 431) with the server's peak memory bounded, the limits exact, a slow or
//! idle connection closed at the head's deadline, a flood of idle connections never locking the
//! page out, `/live` sockets capped apart from page requests, upgrades only from the page's own
//! origin, and a rig too large to show refused before anything is served.
//!
//! Memory is the `view` child's peak resident set (`VmHWM` in `/proc/<pid>/status`); the other
//! cases run the library's server in this process.

use crate::common;

use common::imubake_bin;
use imubake::view::{Preview, ServeOptions, Server, ViewTake};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A two-joint BVH, four frames: a take that starts at once.
const BVH: &str = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition \
    Zposition Zrotation Xrotation Yrotation\n JOINT LeftFoot\n {\n  OFFSET 0.1 -0.9 0\n  CHANNELS \
    3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 0 0.1\n  }\n }\n}\nMOTION\n\
    Frames: 4\nFrame Time: 0.0333333\n0 1 0 0 0 0 0 0 0\n0.1 1 0 10 0 0 5 0 0\n\
    0.2 1 0 20 0 0 10 0 0\n0.3 1 0 30 0 0 15 0 0\n";

const MB: usize = 1 << 20;

/// A running `imubake view`, killed when dropped.
struct Served {
    child: Child,
    authority: String,
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Served {
    /// The child's peak resident set so far, bytes.
    fn peak_rss(&self) -> usize {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).unwrap();
        let kib: usize = status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().strip_suffix("kB"))
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or_else(|| panic!("no VmHWM in {status}"));
        kib * 1024
    }
}

/// `imubake view <path>`, once its URL is printed.
fn view(path: &Path) -> Served {
    let mut child = Command::new(imubake_bin())
        .arg("view")
        .arg(path)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let line = lines.next().expect("a line").unwrap();
    let url = &line[line
        .find("http://")
        .unwrap_or_else(|| panic!("no URL: {line}"))..];
    let authority = url["http://".len()..]
        .split('/')
        .next()
        .unwrap()
        .to_string();
    // Keep draining stdout so the child never blocks on it.
    std::thread::spawn(move || lines.for_each(drop));
    Served { child, authority }
}

fn tiny_take(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("tiny.bvh");
    std::fs::write(&path, BVH).unwrap();
    path
}

/// The status of an answer (`HTTP/1.1 NNN ...`), if it has one.
fn status(answer: &[u8]) -> Option<u16> {
    let text = std::str::from_utf8(answer.get(..12)?).ok()?;
    text.strip_prefix("HTTP/1.1 ")?.get(..3)?.parse().ok()
}

/// Reads what the server sends until it closes (or 30 s pass), at most 1 MiB.
fn read_answer(stream: &mut TcpStream) -> Vec<u8> {
    stream
        .set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    let mut answer = Vec::new();
    let mut buf = [0u8; 16 << 10];
    while answer.len() < MB {
        match stream.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => answer.extend_from_slice(&buf[..n]),
        }
    }
    answer
}

/// Sends `head`, then `filler` repeated to `total` bytes in all, then `tail`, from a thread that
/// stops quietly when the server closes, while this one reads the answer. The answer and the
/// bytes sent.
fn stream_request(
    authority: &str,
    head: &[u8],
    filler: &[u8],
    total: usize,
    tail: &[u8],
) -> (Vec<u8>, usize) {
    let mut stream = TcpStream::connect(authority).unwrap();
    let mut writer = stream.try_clone().unwrap();
    let head = head.to_vec();
    let tail = tail.to_vec();
    let unit = filler.len();
    let piece = filler.repeat((64 << 10) / unit + 1);
    let (done, finished) = std::sync::mpsc::channel();
    let sender = std::thread::spawn(move || {
        let send = |w: &mut TcpStream, bytes: &[u8], sent: &mut usize| {
            let ok = w.write_all(bytes).is_ok();
            *sent += if ok { bytes.len() } else { 0 };
            ok
        };
        let mut sent = 0;
        let mut ok = send(&mut writer, &head, &mut sent);
        while ok {
            // Whole fillers only, so that none is cut.
            let room = total.saturating_sub(sent + tail.len());
            let n = piece.len().min(room / unit * unit);
            if n == 0 {
                ok = send(&mut writer, &tail, &mut sent);
                break;
            }
            ok = send(&mut writer, &piece[..n], &mut sent);
        }
        if ok {
            let _ = writer.shutdown(Shutdown::Write);
        }
        let _ = done.send(sent);
    });
    let answer = read_answer(&mut stream);
    // The sender goes on until it has sent everything or the server closes; a server that does
    // neither within 30 s is cut off.
    let sent = finished
        .recv_timeout(Duration::from_secs(30))
        .unwrap_or_else(|_| {
            let _ = stream.shutdown(Shutdown::Both);
            finished.recv().unwrap()
        });
    sender.join().unwrap();
    (answer, sent)
}

/// A raw request of `bytes` (the write side then shut): the answer.
fn exchange(authority: &str, bytes: &[u8]) -> Vec<u8> {
    let mut stream = TcpStream::connect(authority).unwrap();
    let _ = stream.write_all(bytes);
    let _ = stream.shutdown(Shutdown::Write);
    read_answer(&mut stream)
}

fn get(authority: &str, target: &str) -> Option<u16> {
    status(&exchange(
        authority,
        format!("GET {target} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n\r\n")
            .as_bytes(),
    ))
}

/// What is sent (a head, a filler repeated, a tail) and the status it must get.
type Oversized = (
    &'static str,
    &'static [u8],
    &'static [u8],
    &'static [u8],
    u16,
);

/// Request lines and headers of 50 MB, streamed (with and without line ends): each refused with
/// its status (414 for the request line, 431 for headers) while the `view` child's peak resident
/// set stays under 100 MB and within 16 MB of what it was before; the server still serves.
#[test]
fn oversized_request_lines_and_headers_are_refused_in_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let take = tiny_take(dir.path());
    let cases: [Oversized; 4] = [
        (
            "a 50 MB request line, no line end",
            b"GET /",
            b"a",
            b"",
            414,
        ),
        (
            "a 50 MB request line, then a head",
            b"GET /?",
            b"a",
            b" HTTP/1.1\r\nHost: x\r\n\r\n",
            414,
        ),
        (
            "one 50 MB header",
            b"GET / HTTP/1.1\r\nHost: x\r\nX-Big: ",
            b"a",
            b"\r\n\r\n",
            431,
        ),
        (
            "3.7 M headers of 14 bytes (50 MB)",
            b"GET / HTTP/1.1\r\nHost: x\r\n",
            b"X-h: 1234567\r\n",
            b"\r\n",
            431,
        ),
    ];
    let mut failed = Vec::new();
    for (what, head, filler, tail, want) in cases {
        let served = view(&take);
        assert_eq!(get(&served.authority, "/"), Some(200), "{what}: before");
        let before = served.peak_rss();
        let start = Instant::now();
        let (answer, sent) = stream_request(&served.authority, head, filler, 50_000_000, tail);
        let peak = served.peak_rss();
        eprintln!(
            "{what}: {} after {:.1} MB sent in {:.1} s; peak RSS {:.1} MB (before {:.1} MB)",
            String::from_utf8_lossy(&answer[..answer.len().min(40)])
                .lines()
                .next()
                .unwrap_or("no answer"),
            sent as f64 / 1e6,
            start.elapsed().as_secs_f64(),
            peak as f64 / 1e6,
            before as f64 / 1e6
        );
        // Every case measured before any fails.
        if status(&answer) != Some(want) {
            failed.push(format!("{what}: not {want}"));
        }
        if peak >= 100_000_000 || peak - before >= 16 * MB {
            failed.push(format!("{what}: peak RSS {peak} bytes, {before} before"));
        }
        if get(&served.authority, "/") != Some(200) {
            failed.push(format!("{what}: not serving after"));
        }
    }
    assert!(failed.is_empty(), "{failed:#?}");
}

/// A server of the tiny take in this process (`preview`: a live session's), on `listen`; stopped
/// when the flag is dropped.
struct InProcess {
    authority: String,
    stop: Arc<AtomicBool>,
    _dir: tempfile::TempDir,
}

impl Drop for InProcess {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn in_process(listen: &str, preview: Option<Arc<Preview>>) -> InProcess {
    let dir = tempfile::tempdir().unwrap();
    let take = match &preview {
        Some(_) => ViewTake::live(
            imubake::rig::load_rig("mixamo").unwrap(),
            imubake::fps::Fps::new(60, 1).unwrap(),
            Vec::new(),
        ),
        None => ViewTake::open(&tiny_take(dir.path()), 1.0).unwrap(),
    };
    let server = Server::bind(
        take,
        &ServeOptions {
            listen: listen.parse().unwrap(),
        },
        preview,
    )
    .unwrap();
    let authority = format!("127.0.0.1:{}", server.addr().port());
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    std::thread::spawn(move || server.run(&flag));
    InProcess {
        authority,
        stop,
        _dir: dir,
    }
}

/// `GET /?…` whose request line (CRLF excluded) is `n` bytes.
fn request_line(n: usize) -> String {
    let fixed = "GET /? HTTP/1.1".len();
    format!("GET /?{} HTTP/1.1", "a".repeat(n - fixed))
}

/// Header lines (CRLF excluded) holding `Host` then pads, which with their CRLFs total `n` bytes.
fn headers_totalling(host: &str, n: usize) -> Vec<String> {
    let host_line = format!("Host: {host}");
    let mut left = n - host_line.len() - 2;
    let mut lines = vec![host_line];
    let count = left.div_ceil(8000);
    for i in 0..count {
        let bytes = left / (count - i);
        lines.push(format!("X-Pad-{i:02}: {}", "p".repeat(bytes - 2 - 10)));
        left -= bytes;
    }
    lines
}

fn request(line: &str, headers: &[String]) -> Vec<u8> {
    let mut out = format!("{line}\r\n");
    for h in headers {
        out.push_str(h);
        out.push_str("\r\n");
    }
    out.push_str("\r\n");
    out.into_bytes()
}

/// The limits, at their edges: a request line of 8192 bytes is served and one of 8193 is 414; a
/// header line of 8192 bytes is served and one of 8193 is 431; 100 header lines are served and
/// 101 are 431; header lines totalling 65 536 bytes with their line ends are served and 65 537
/// are 431.
#[test]
fn the_limits_are_exact() {
    let server = in_process("127.0.0.1:0", None);
    let host = server.authority.as_str();
    let host_line = format!("Host: {host}");
    let answer = |line: &str, headers: &[String]| status(&exchange(host, &request(line, headers)));
    assert_eq!(
        answer(&request_line(8192), std::slice::from_ref(&host_line)),
        Some(200)
    );
    assert_eq!(
        answer(&request_line(8193), std::slice::from_ref(&host_line)),
        Some(414)
    );

    let pad = |n: usize| format!("X-Pad: {}", "p".repeat(n - "X-Pad: ".len()));
    assert_eq!(
        answer("GET / HTTP/1.1", &[host_line.clone(), pad(8192)]),
        Some(200)
    );
    assert_eq!(
        answer("GET / HTTP/1.1", &[host_line.clone(), pad(8193)]),
        Some(431)
    );

    let many = |n: usize| -> Vec<String> {
        std::iter::once(host_line.clone())
            .chain((1..n).map(|i| format!("X-H{i}: {i}")))
            .collect()
    };
    assert_eq!(answer("GET / HTTP/1.1", &many(100)), Some(200));
    assert_eq!(answer("GET / HTTP/1.1", &many(101)), Some(431));

    for (total, want) in [(65536, 200), (65537, 431)] {
        let headers = headers_totalling(host, total);
        let sum: usize = headers.iter().map(|h| h.len() + 2).sum();
        assert_eq!(sum, total);
        assert!(headers.iter().all(|h| h.len() <= 8192) && headers.len() <= 100);
        assert_eq!(answer("GET / HTTP/1.1", &headers), Some(want), "{total}");
    }
}

/// The answers are plain HTTP/1.1 written by hand: a GET's head says the body's type and
/// length, no caching of the take, `nosniff` and `Connection: close`; a HEAD gets the same head
/// and no body; two `Host`s are 400; a POST is 405 with `Allow`.
#[test]
fn the_answers_are_plain_http() {
    let server = in_process("127.0.0.1:0", None);
    let host = server.authority.as_str();
    let ask = |method: &str, extra: &str| {
        exchange(
            host,
            format!("{method} /take.json HTTP/1.1\r\nHost: {host}\r\n{extra}\r\n").as_bytes(),
        )
    };
    let split = |answer: &[u8]| -> (String, Vec<u8>) {
        let end = answer
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .expect("a head");
        (
            String::from_utf8_lossy(&answer[..end]).to_ascii_lowercase(),
            answer[end + 4..].to_vec(),
        )
    };
    let (head, body) = split(&ask("GET", ""));
    assert!(head.starts_with("http/1.1 200 ok\r\n"), "{head}");
    let take: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(take["frames"], 4);
    for line in [
        "content-type: application/json; charset=utf-8".to_string(),
        format!("content-length: {}", body.len()),
        "cache-control: no-store".into(),
        "x-content-type-options: nosniff".into(),
        "connection: close".into(),
    ] {
        assert!(head.lines().any(|l| l == line), "no {line:?} in {head}");
    }
    let (head_only, nothing) = split(&ask("HEAD", ""));
    assert_eq!(head_only, head);
    assert!(nothing.is_empty());
    assert_eq!(status(&ask("GET", &format!("Host: {host}\r\n"))), Some(400));
    let (refused, _) = split(&ask("POST", ""));
    assert!(refused.starts_with("http/1.1 405 "), "{refused}");
    assert!(
        refused.lines().any(|l| l == "allow: get, head"),
        "{refused}"
    );
}

/// A client that sends nothing, and one that sends a header every half second and never ends
/// its head, are both closed at the head's deadline (10 s, from 9 s to 20 s on a loaded machine;
/// the slow one answered 408, the idle one 408 or nothing); meanwhile the page is served.
#[test]
fn a_slow_or_idle_connection_is_closed_at_the_heads_deadline() {
    let server = in_process("127.0.0.1:0", None);
    let host = server.authority.clone();
    let start = Instant::now();
    let mut idle = TcpStream::connect(&host).unwrap();
    let mut slow = TcpStream::connect(&host).unwrap();
    slow.write_all(format!("GET / HTTP/1.1\r\nHost: {host}\r\n").as_bytes())
        .unwrap();
    let mut dribble = slow.try_clone().unwrap();
    std::thread::spawn(move || {
        for i in 0.. {
            std::thread::sleep(Duration::from_millis(500));
            if dribble
                .write_all(format!("X-Slow-{i}: 1\r\n").as_bytes())
                .is_err()
            {
                break;
            }
        }
    });
    assert_eq!(get(&host, "/"), Some(200));
    for (what, stream) in [("idle", &mut idle), ("slow", &mut slow)] {
        stream
            .set_read_timeout(Some(Duration::from_secs(20)))
            .unwrap();
        let mut answer = Vec::new();
        let closed = stream.read_to_end(&mut answer);
        let after = start.elapsed();
        eprintln!(
            "{what}: closed after {:.2} s: {:?}",
            after.as_secs_f64(),
            status(&answer)
        );
        assert!(
            closed.is_ok() || after < Duration::from_secs(19),
            "{what}: still open after {after:?}"
        );
        assert!(
            after <= Duration::from_secs(20),
            "{what}: closed after {after:?}"
        );
        assert!(
            after >= Duration::from_secs(9),
            "{what}: closed after {after:?}"
        );
        let expected = if what == "slow" {
            status(&answer) == Some(408)
        } else {
            answer.is_empty() || status(&answer) == Some(408)
        };
        assert!(expected, "{what}: {}", String::from_utf8_lossy(&answer));
    }
}

/// 300 connections open and silent: the page and `take.json` are still served at once (within
/// 10 s on a loaded machine).
#[test]
fn a_flood_of_idle_connections_leaves_the_page_served() {
    let server = in_process("127.0.0.1:0", None);
    let host = server.authority.as_str();
    let idle: Vec<TcpStream> = (0..300)
        .map(|_| TcpStream::connect(host).unwrap())
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    let start = Instant::now();
    assert_eq!(get(host, "/"), Some(200));
    assert_eq!(get(host, "/take.json"), Some(200));
    assert!(
        start.elapsed() < Duration::from_secs(10),
        "{:?}",
        start.elapsed()
    );
    drop(idle);
}

/// 64 clients that each ask for `take.json` or a chunk and never read the answer nor close:
/// a new request for the page is still answered 200 (at once: it does not wait out their
/// linger), within 15 s.
#[test]
fn clients_that_never_read_leave_the_page_served() {
    let server = in_process("127.0.0.1:0", None);
    let host = server.authority.as_str();
    let stuck: Vec<TcpStream> = (0..64)
        .map(|i| {
            let mut s = TcpStream::connect(host).unwrap();
            let target = if i % 2 == 0 {
                "/take.json"
            } else {
                "/chunk/0.glb"
            };
            write!(s, "GET {target} HTTP/1.1\r\nHost: {host}\r\n\r\n").unwrap();
            s
        })
        .collect();
    // Their heads read and their answers written (the write side is never shut, nor read).
    std::thread::sleep(Duration::from_millis(500));
    let start = Instant::now();
    assert_eq!(get(host, "/"), Some(200), "with 64 non-reading clients");
    assert!(
        start.elapsed() <= Duration::from_secs(15),
        "{:?}",
        start.elapsed()
    );
    drop(stuck);
}

/// A raw GET of `/` with `Host: host_header`, sent to `authority`: the status.
fn get_as(authority: &str, host_header: &str) -> Option<u16> {
    status(&exchange(
        authority,
        format!("GET / HTTP/1.1\r\nHost: {host_header}\r\nConnection: close\r\n\r\n").as_bytes(),
    ))
}

/// Bound to every interface, only a `Host` that is an IP address or `localhost` with the
/// server's port is served (DNS rebinding): `evil.com:PORT` (even with its own `Origin`), an
/// IP with another port, and no port are 403; `127.0.0.1`, `192.168.1.20`, `[::1]` and
/// `LocalHost` with the port are 200.
#[test]
fn bound_everywhere_only_an_ip_or_localhost_host_is_served() {
    let server = in_process("0.0.0.0:0", None);
    let authority = server.authority.as_str();
    let port: u16 = authority.rsplit(':').next().unwrap().parse().unwrap();
    let other = port.wrapping_add(1).max(1);
    let evil = exchange(
        authority,
        format!(
            "GET / HTTP/1.1\r\nHost: evil.com:{port}\r\nOrigin: http://evil.com:{port}\r\n\r\n"
        )
        .as_bytes(),
    );
    assert_eq!(status(&evil), Some(403));
    for (host, code) in [
        (format!("evil.com:{port}"), 403),
        (format!("127.0.0.1.evil.com:{port}"), 403),
        (format!("127.0.0.1:{other}"), 403),
        ("127.0.0.1".to_string(), 403),
        (format!("[::1]x:{port}"), 403),
        (format!("127.0.0.1:{port}"), 200),
        (format!("192.168.1.20:{port}"), 200),
        (format!("[::1]:{port}"), 200),
        (format!("LocalHost:{port}"), 200),
    ] {
        assert_eq!(get_as(authority, &host), Some(code), "Host: {host}");
    }
}

/// Bound to loopback, `Host` names compare in any case, and the address bound (127.0.0.2
/// here) is accepted as well as 127.0.0.1; another loopback address is not.
#[test]
fn bound_to_loopback_the_bound_address_and_any_case_are_served() {
    let server = in_process("127.0.0.2:0", None);
    let port = server.authority.rsplit(':').next().unwrap();
    let authority = format!("127.0.0.2:{port}");
    for (host, code) in [
        (format!("127.0.0.2:{port}"), 200),
        (format!("127.0.0.1:{port}"), 200),
        (format!("LOCALHOST:{port}"), 200),
        (format!("127.0.0.3:{port}"), 403),
        (format!("evil.com:{port}"), 403),
    ] {
        assert_eq!(get_as(&authority, &host), Some(code), "Host: {host}");
    }
}

/// A WebSocket upgrade of `/live` with `Host: host` and `origin`: the status and the stream
/// (only the answer's head read from it).
fn upgrade(authority: &str, host: &str, origin: Option<&str>) -> (u16, TcpStream) {
    upgrade_at(authority, "/live", host, origin)
}

/// A WebSocket upgrade of `path` (`/live`, `/setup`), as [`upgrade`].
pub(crate) fn upgrade_at(
    authority: &str,
    path: &str,
    host: &str,
    origin: Option<&str>,
) -> (u16, TcpStream) {
    let mut stream = TcpStream::connect(authority).unwrap();
    let origin = origin.map_or(String::new(), |o| format!("Origin: {o}\r\n"));
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n{origin}\r\n"
    )
    .unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let mut head = Vec::new();
    let mut byte = [0u8];
    while !head.ends_with(b"\r\n\r\n") {
        match stream.read(&mut byte) {
            Ok(1) => head.push(byte[0]),
            _ => break,
        }
    }
    let code = status(&head).unwrap_or_else(|| panic!("{}", String::from_utf8_lossy(&head)));
    if code == 101 {
        assert!(
            String::from_utf8_lossy(&head).contains("s3pPLMBiTxaQ9kYGzzhZRbK+xOo="),
            "the accept key"
        );
    }
    (code, stream)
}

/// A live preview with 64 `/live` upgrades from its own page: 16 are accepted (101) and kept,
/// the others refused (503); the page and `take.json` are still served; the 16 receive the
/// session's status; once they close, a new upgrade is accepted within 10 s.
#[test]
fn sixty_four_live_sockets_leave_the_page_served() {
    let preview = Preview::new(1.0);
    let server = in_process("127.0.0.1:0", Some(Arc::clone(&preview)));
    let host = server.authority.clone();
    let origin = format!("http://{host}");
    let mut accepted = Vec::new();
    let mut refused = 0;
    for _ in 0..64 {
        match upgrade(&host, &host, Some(&origin)) {
            (101, s) => accepted.push(s),
            (503, _) => refused += 1,
            (other, _) => panic!("an upgrade answered {other}"),
        }
    }
    assert_eq!(get(&host, "/"), Some(200), "the page with 64 sockets open");
    assert_eq!(get(&host, "/take.json"), Some(200));
    assert_eq!((accepted.len(), refused), (16, 48));

    preview.status("running", None, 1, &[]);
    for stream in accepted.drain(..) {
        let mut socket = tungstenite::WebSocket::from_raw_socket(
            stream,
            tungstenite::protocol::Role::Client,
            None,
        );
        let message = socket.read().unwrap();
        let json: serde_json::Value = serde_json::from_str(message.to_text().unwrap()).unwrap();
        assert_eq!(json["type"], "status");
        let _ = socket.close(None);
        let _ = socket.flush();
    }
    let start = Instant::now();
    loop {
        match upgrade(&host, &host, Some(&origin)).0 {
            101 => break,
            503 if start.elapsed() < Duration::from_secs(10) => {
                std::thread::sleep(Duration::from_millis(50))
            }
            other => panic!("after the sockets closed: {other} at {:?}", start.elapsed()),
        }
    }
}

/// An upgrade is accepted only from the page's own origin, `http://` and the request's `Host`:
/// a foreign site, `null`, another loopback name, `https` and no `Origin` at all are 403. On
/// every interface (a LAN `--listen`), the origin of the `Host` the page was asked under is
/// accepted.
#[test]
fn an_upgrade_from_a_foreign_origin_is_refused() {
    let preview = Preview::new(1.0);
    let server = in_process("127.0.0.1:0", Some(Arc::clone(&preview)));
    let host = server.authority.clone();
    let port = host.rsplit(':').next().unwrap();
    let localhost = format!("localhost:{port}");
    assert_eq!(upgrade(&host, &host, Some("http://evil.example")).0, 403);
    assert_eq!(upgrade(&host, &host, Some("null")).0, 403);
    assert_eq!(
        upgrade(&host, &host, Some(&format!("https://{host}"))).0,
        403
    );
    assert_eq!(
        upgrade(&host, &host, Some(&format!("http://{localhost}"))).0,
        403
    );
    assert_eq!(upgrade(&host, &host, None).0, 403);
    assert_eq!(
        upgrade(&host, &host, Some(&format!("http://{host}"))).0,
        101
    );
    assert_eq!(
        upgrade(&host, &localhost, Some(&format!("http://{localhost}"))).0,
        101
    );

    let lan = in_process("0.0.0.0:0", Some(preview));
    let lan_host = format!("192.168.1.20:{}", lan.authority.rsplit(':').next().unwrap());
    assert_eq!(
        upgrade(
            &lan.authority,
            &lan_host,
            Some(&format!("http://{lan_host}"))
        )
        .0,
        101
    );
    assert_eq!(
        upgrade(&lan.authority, &lan_host, Some("http://evil.example")).0,
        403
    );
}

/// A BVH of `joints` joints: a root and its children, each with an end site, one frame.
fn star_bvh(joints: usize) -> String {
    let mut s = String::from(
        "HIERARCHY\nROOT Hips\n{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition Zposition \
         Zrotation Xrotation Yrotation\n",
    );
    for i in 1..joints {
        s.push_str(&format!(
            " JOINT J{i}\n {{\n  OFFSET 0 0.01 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  \
             End Site\n  {{\n   OFFSET 0 0.01 0\n  }}\n }}\n"
        ));
    }
    s.push_str("}\nMOTION\nFrames: 1\nFrame Time: 0.0333333\n0 1 0 0 0 0");
    s.push_str(&" 0 0 0".repeat(joints - 1));
    s.push('\n');
    s
}

/// `view` of a rig of 100 001 joints fails before serving: no URL, a non-zero exit, the file and
/// the limit (65 536 joints, the GLB chunks') in its message.
#[test]
fn a_rig_too_large_to_show_fails_before_serving() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.bvh");
    std::fs::write(&path, star_bvh(100_001)).unwrap();
    let mut child = Command::new(imubake_bin())
        .arg("view")
        .arg(&path)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let start = Instant::now();
    let mut stdout = String::new();
    let exit = loop {
        while let Ok(line) = rx.try_recv() {
            stdout.push_str(&line);
            stdout.push('\n');
        }
        if stdout.contains("http://") || start.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("still running after {:?}: {stdout}", start.elapsed());
        }
        if let Some(exit) = child.try_wait().unwrap() {
            break exit;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    for line in rx.iter() {
        stdout.push_str(&line);
        stdout.push('\n');
    }
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    eprintln!("{:.1} s: {}", start.elapsed().as_secs_f64(), stderr.trim());
    assert!(!exit.success(), "{exit:?}");
    assert!(!stdout.contains("http://"), "served: {stdout}");
    for needed in ["huge.bvh", "100001", "65536"] {
        assert!(stderr.contains(needed), "no {needed:?} in: {stderr}");
    }
}
