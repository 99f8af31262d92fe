//! The viewer's inputs never panic or hang: the files it opens (a BVH, a GLB, a sidecar) mutated
//! byte by byte, and whatever a client sends the server as a request (answered with one
//! well-formed response, heads near the limits with the status the limits give).

use imubake::view::{ServeOptions, Server, ViewTake};
use proptest::prelude::*;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

/// A small converted take: a two-joint BVH, a GLB of it, and a sidecar naming both.
const BVH: &str = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition \
    Zposition Zrotation Xrotation Yrotation\n JOINT LeftFoot\n {\n  OFFSET 0.1 -0.9 0\n  CHANNELS \
    3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 0 0.1\n  }\n }\n}\nMOTION\n\
    Frames: 4\nFrame Time: 0.0333333\n0 1 0 0 0 0 0 0 0\n0.1 1 0 10 0 0 5 0 0\n\
    0.2 1 0 20 0 0 10 0 0\n0.3 1 0 30 0 0 15 0 0\n";

fn sidecar(frames: usize) -> String {
    serde_json::json!({
        "fps": {"num": 30, "den": 1}, "frames": frames, "rig": {"units": "m"},
        "mapping": {"sensors": [{"sensor": "s", "bone": "Hips", "mount": [1.0, 0.0, 0.0, 0.0]}]},
        "contacts": {"left": [[0, 2]], "right": [], "airborne": []},
        "outputs": [{"format": "bvh", "path": "t.bvh"}, {"format": "glb", "path": "t.glb"}],
        "source": {"path": "t.csv"}
    })
    .to_string()
}

fn glb() -> Vec<u8> {
    let bvh = imubake::bvh::parse(BVH.as_bytes()).unwrap();
    let fps = imubake::fps::Fps::new(30, 1).unwrap();
    let anim = imubake::anim::Animation::from_bvh(&bvh, "t", imubake::rig::LengthUnit::Metres, fps)
        .unwrap();
    imubake::write::gltf::to_glb(&anim, "t").unwrap()
}

/// Opens `path` and makes every chunk: an error is fine, a panic is not.
fn open_and_cut(path: &Path) {
    if let Ok(take) = ViewTake::open(path, 0.05) {
        assert!(take.frames >= 1);
        for k in 0..take.chunks() {
            let _ = take.chunk_glb(k).expect("a chunk below chunks()");
        }
        assert!(take.chunk_glb(take.chunks()).is_none());
        let _ = serde_json::to_vec(&take.json()).unwrap();
    }
}

fn mutate(mut bytes: Vec<u8>, edits: &[(prop::sample::Index, u8, u8)]) -> Vec<u8> {
    for (at, value, kind) in edits {
        if bytes.is_empty() {
            bytes.push(*value);
            continue;
        }
        let i = at.index(bytes.len());
        match kind % 3 {
            0 => bytes[i] = *value,
            1 => {
                bytes.remove(i);
            }
            _ => bytes.insert(i, *value),
        }
    }
    bytes
}

fn edits() -> impl Strategy<Value = Vec<(prop::sample::Index, u8, u8)>> {
    proptest::collection::vec(
        (any::<prop::sample::Index>(), any::<u8>(), any::<u8>()),
        1..8,
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn mutated_files_never_panic(which in 0usize..3, edits in edits()) {
        let dir = tempfile::tempdir().unwrap();
        let files: [(&str, Vec<u8>); 3] = [
            ("t.bvh", BVH.as_bytes().to_vec()),
            ("t.glb", glb()),
            ("t.imubake.json", sidecar(4).into_bytes()),
        ];
        for (name, bytes) in &files {
            std::fs::write(dir.path().join(name), bytes).unwrap();
        }
        let (name, bytes) = &files[which];
        let path = dir.path().join(name);
        std::fs::write(&path, mutate(bytes.clone(), &edits)).unwrap();
        open_and_cut(&path);
    }

    #[test]
    fn arbitrary_bytes_as_a_take_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512), ext in 0usize..3) {
        let dir = tempfile::tempdir().unwrap();
        let path: PathBuf = dir.path().join(["a.bvh", "a.glb", "a.imubake.json"][ext]);
        std::fs::write(&path, &bytes).unwrap();
        open_and_cut(&path);
    }
}

/// One server for the request properties: the small take, on loopback.
fn server() -> &'static str {
    static URL: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    URL.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap().keep();
        std::fs::write(dir.join("t.bvh"), BVH).unwrap();
        std::fs::write(dir.join("t.glb"), glb()).unwrap();
        std::fs::write(dir.join("t.imubake.json"), sidecar(4)).unwrap();
        let take = ViewTake::open(&dir.join("t.imubake.json"), 0.05).unwrap();
        let server = Server::bind(
            take,
            &ServeOptions {
                listen: "127.0.0.1:0".parse().unwrap(),
            },
            None,
        )
        .unwrap();
        let authority = server.addr().to_string();
        let stop = Arc::new(AtomicBool::new(false));
        std::thread::spawn(move || server.run(&stop));
        authority
    })
}

/// Sends `request` as it is and reads the answer (the server may also just close).
fn exchange(request: &[u8]) -> Vec<u8> {
    let mut s = TcpStream::connect(server()).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let _ = s.write_all(request);
    let _ = s.shutdown(std::net::Shutdown::Write);
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    out
}

fn status(answer: &[u8]) -> Option<u16> {
    let text = std::str::from_utf8(answer.get(..12)?).ok()?;
    text.strip_prefix("HTTP/1.1 ")?.get(..3)?.parse().ok()
}

/// An answer is nothing (closed) or one well-formed HTTP/1.1 response: a status line, headers,
/// and a body of its `Content-Length`. Its status, if any.
fn well_formed(answer: &[u8]) -> Result<Option<u16>, String> {
    if answer.is_empty() {
        return Ok(None);
    }
    let mut headers = [httparse::EMPTY_HEADER; 32];
    let mut response = httparse::Response::new(&mut headers);
    let at = match response.parse(answer) {
        Ok(httparse::Status::Complete(at)) => at,
        other => return Err(format!("{other:?}: {:?}", String::from_utf8_lossy(answer))),
    };
    if response.version != Some(1) {
        return Err(format!(
            "not HTTP/1.1: {:?}",
            String::from_utf8_lossy(answer)
        ));
    }
    let length = response
        .headers
        .iter()
        .find(|h| h.name.eq_ignore_ascii_case("Content-Length"))
        .and_then(|h| std::str::from_utf8(h.value).ok()?.parse::<usize>().ok())
        .ok_or("no Content-Length")?;
    if answer.len() - at != length {
        return Err(format!(
            "{} body bytes, Content-Length {length}",
            answer.len() - at
        ));
    }
    Ok(response.code)
}

/// A head with a request line of `line` bytes and, after `Host`, header lines of `lines`
/// bytes (line ends excluded), and the status the limits give it: 414 when the request line
/// is over 8192 bytes; else 431 when a header line is over 8192 bytes, there are over 100 of
/// them (`Host` counted) or they total over 65 536 bytes with their line ends; else 200.
fn head_near_the_limits(host: &str, line: usize, lines: &[usize]) -> (Vec<u8>, u16) {
    let mut head = format!("GET /?{} HTTP/1.1\r\n", "a".repeat(line - 15));
    let host_line = format!("Host: {host}");
    let mut total = host_line.len() + 2;
    head.push_str(&host_line);
    head.push_str("\r\n");
    for (i, &n) in lines.iter().enumerate() {
        let name = format!("X-{i}: ");
        head.push_str(&name);
        head.push_str(&"p".repeat(n - name.len()));
        head.push_str("\r\n");
        total += n + 2;
    }
    head.push_str("\r\n");
    let want = if line > 8192 {
        414
    } else if lines.iter().any(|&n| n > 8192) || lines.len() + 1 > 100 || total > 65536 {
        431
    } else {
        200
    };
    (head.into_bytes(), want)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Any target: the server answers (404 unless it is one of its paths), and keeps serving.
    #[test]
    fn any_request_target_gets_an_answer(target in "[ -~]{0,80}") {
        let host = server();
        let request = format!("GET {target} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n");
        let answer = exchange(request.as_bytes());
        if let Some(code) = status(&answer) {
            let own = ["/", "/index.html", "/take.json", "/viewer.js", "/viewer.css", "/chunk/0.glb", "/chunk/1.glb"];
            let path = target.split(['?', '#']).next().unwrap_or("");
            prop_assert!(code == 200 && (own.contains(&path) || path.starts_with("/vendor/three/")) || code >= 400, "{target:?}: {code}");
        }
        let again = exchange(format!("GET /take.json HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n").as_bytes());
        prop_assert_eq!(status(&again), Some(200));
    }

    /// Arbitrary bytes as a request: no crash, the answer nothing or one well-formed HTTP/1.1
    /// response, and the server keeps serving.
    #[test]
    fn arbitrary_request_bytes_never_stop_the_server(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let answer = exchange(&bytes);
        prop_assert!(well_formed(&answer).is_ok(), "{:?}", well_formed(&answer));
        let host = server();
        let again = exchange(format!("GET / HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n").as_bytes());
        prop_assert_eq!(status(&again), Some(200));
    }

    /// Heads around the limits (request lines of 15 to 8400 bytes, up to 105 header lines
    /// of up to 8300 bytes): the answer is a well-formed response with the status the limits
    /// give (414, 431, else 200), and the server keeps serving.
    #[test]
    fn heads_near_the_limits_get_the_limits_answer(
        line in prop_oneof![15usize..200, 8180usize..8210, 8210usize..8400],
        lines in proptest::collection::vec(prop_oneof![4 => 10usize..64, 1 => 7000usize..8300], 0..105),
    ) {
        let host = server();
        let (head, want) = head_near_the_limits(host, line, &lines);
        let answer = exchange(&head);
        prop_assert_eq!(well_formed(&answer), Ok(Some(want)));
        let again = exchange(format!("GET / HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n").as_bytes());
        prop_assert_eq!(status(&again), Some(200));
    }
}
