//! Helpers shared by integration tests: locating `../shared/data` and external tools.
//!
//! Locally a test whose data or tool is missing skips with a message; under `CI=true` it fails,
//! so a broken install never turns into a green run.
#![allow(dead_code)]

use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};
use std::process::Command;

pub mod mirror;
pub mod rescale;
pub mod reverse;
pub mod twin;

pub fn in_ci() -> bool {
    std::env::var("CI")
        .map(|v| v == "true" || v == "1")
        .unwrap_or(false)
}

/// Skips (returns `None`, printing why) locally; panics under CI.
pub fn missing<T>(what: &str) -> Option<T> {
    if in_ci() {
        panic!("CI=true but {what} is missing: the test set-up is broken");
    }
    eprintln!("SKIPPED: {what} is missing");
    None
}

/// `../shared/data` (or `IMUBAKE_SHARED_DATA`).
pub fn shared_data() -> Option<PathBuf> {
    let dir = std::env::var_os("IMUBAKE_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    if dir.join("README.md").is_file() {
        Some(dir)
    } else {
        missing(&format!("shared data folder {}", dir.display()))
    }
}

/// A file or folder under `../shared/data`.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let path = shared_data()?.join(rel);
    if path.exists() {
        Some(path)
    } else {
        missing(&format!("shared data {}", path.display()))
    }
}

/// A checked-in fixture under tests/fixtures.
pub fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(rel)
}

/// A test tool set up by scripts/test.sh under `~/.cache/imubake-test` (`rel`), or where the
/// environment variable `var` says; it is there when the file `marker` (relative to that path,
/// the path itself when empty) is.
fn test_tool(var: &str, rel: &str, marker: &str, what: &str) -> Option<PathBuf> {
    let path = std::env::var_os(var).map(PathBuf::from).or_else(|| {
        std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache/imubake-test").join(rel))
    })?;
    let marker = if marker.is_empty() {
        path.clone()
    } else {
        path.join(marker)
    };
    if marker.is_file() {
        Some(path)
    } else {
        missing(&format!("{what} {} (run scripts/test.sh)", path.display()))
    }
}

/// The test venv's Python (set up by scripts/test.sh; `IMUBAKE_PYTHON` overrides).
pub fn python() -> Option<PathBuf> {
    test_tool("IMUBAKE_PYTHON", "venv/bin/python", "", "test Python")
}

/// Python with Blender 4.2 LTS as `bpy` (a second venv set up by scripts/test.sh;
/// `IMUBAKE_PYTHON_BLENDER42` overrides): the add-on is tested in both 4.2 and 5.0.
pub fn python_blender42() -> Option<PathBuf> {
    test_tool(
        "IMUBAKE_PYTHON_BLENDER42",
        "venv-blender42/bin/python",
        "",
        "Blender 4.2 test Python",
    )
}

/// Godot 3's headless editor, `godot3-server` (Debian's package, installed by scripts/test.sh;
/// `IMUBAKE_GODOT` overrides).
pub fn godot() -> Option<PathBuf> {
    let path = std::env::var_os("IMUBAKE_GODOT")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/bin/godot3-server"));
    if path.is_file() {
        Some(path)
    } else {
        missing(&format!("Godot 3 {} (run scripts/test.sh)", path.display()))
    }
}

/// A pseudo-terminal: its master (what the test writes) and its slave's fd and path (the
/// "serial port").
pub fn openpty() -> (std::fs::File, (i32, String)) {
    let (mut m, mut s) = (0, 0);
    let mut name = [0 as libc::c_char; 128];
    let rc = unsafe {
        libc::openpty(
            &mut m,
            &mut s,
            name.as_mut_ptr(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(rc, 0);
    // Not inherited by the imubake child (it would keep the device alive after an "unplug").
    unsafe {
        libc::fcntl(m, libc::F_SETFD, libc::FD_CLOEXEC);
        libc::fcntl(s, libc::F_SETFD, libc::FD_CLOEXEC);
    }
    // Raw, as a USB-serial adapter is (no echo, no line editing) before anyone opens it.
    unsafe {
        let mut t: libc::termios = std::mem::zeroed();
        libc::tcgetattr(s, &mut t);
        libc::cfmakeraw(&mut t);
        libc::tcsetattr(s, libc::TCSANOW, &t);
    }
    let path = unsafe { std::ffi::CStr::from_ptr(name.as_ptr()) }
        .to_string_lossy()
        .into_owned();
    use std::os::fd::FromRawFd;
    (unsafe { std::fs::File::from_raw_fd(m) }, (s, path))
}

/// A UDP port on 127.0.0.1 free a moment ago (for a live source to bind).
pub fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Stops a `imubake live --record DIR` session (`child`, its stderr piped) as a user would
/// (SIGINT), checks that it exited cleanly, and returns the text of the CSV recording it left in
/// `record`.
pub fn stop_and_read_recording(child: std::process::Child, record: &Path) -> String {
    unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let recording = std::fs::read_dir(record)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "csv"))
        .expect("a recording");
    std::fs::read_to_string(&recording).unwrap()
}

/// The compiled `imubake` binary.
pub fn imubake_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_imubake"))
}

/// `imubake inspect --json <path>` (a capture's summary, or a rig's body parts), which must
/// succeed.
pub fn inspect_json(path: &Path) -> serde_json::Value {
    let out = Command::new(imubake_bin())
        .args(["inspect", "--json"])
        .arg(path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "imubake inspect {}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// A file of this crate (scripts, test scripts), by its path in the repository.
pub fn repo_file(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The `node_modules` folder holding the Khronos glTF-Validator (set up by scripts/test.sh;
/// `IMUBAKE_NODE_MODULES` overrides).
pub fn node_modules() -> Option<PathBuf> {
    test_tool(
        "IMUBAKE_NODE_MODULES",
        "node/node_modules",
        "gltf-validator/package.json",
        "gltf-validator in",
    )
}

/// A JSON array of three numbers (a position in a report).
pub fn vec3(v: &serde_json::Value) -> nalgebra::Vector3<f64> {
    let x = |i: usize| {
        v[i].as_f64()
            .unwrap_or_else(|| panic!("not three numbers: {v}"))
    };
    nalgebra::Vector3::new(x(0), x(1), x(2))
}

/// The strings of a JSON array (names in a report).
pub fn strings(v: &serde_json::Value) -> Vec<&str> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|s| s.as_str().unwrap_or_else(|| panic!("not a string: {s}")))
        .collect()
}

/// The glTF-Validator's report on each file, in order, from one Node run of
/// scripts/gltf_validate.mjs: `{"path", "validator", "errors", "warnings", "infos", "hints",
/// "messages"}`.
pub fn gltf_validate<P: AsRef<Path>>(files: &[P], modules: &Path) -> Vec<serde_json::Value> {
    let out = Command::new("node")
        .arg(repo_file("scripts/gltf_validate.mjs"))
        .args(files.iter().map(AsRef::as_ref))
        .env("IMUBAKE_NODE_MODULES", modules)
        .output()
        .expect("node runs");
    let reports: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|line| {
            serde_json::from_str(line)
                .unwrap_or_else(|e| panic!("{e}: {line}\n{}", String::from_utf8_lossy(&out.stderr)))
        })
        .collect();
    assert_eq!(
        reports.len(),
        files.len(),
        "one report per file: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    reports
}

/// Runs `py script args...`; its stdout. Panics with stdout and stderr when it fails.
pub fn run_python(py: &Path, script: &str, args: &mut dyn Iterator<Item = &OsStr>) -> String {
    let out = Command::new(py)
        .arg(repo_file(script))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", py.display()));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{script} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// Blender's own BVH import of each file, in one run of tests/python/blender_import_bvh.py
/// (see its docstring): `{"blender", "files": [...]}`. `pose_frames`: the Blender frames to
/// report bone poses at (default: every keyed frame).
pub fn blender_import_bvh<P: AsRef<Path>>(
    py: &Path,
    files: &[P],
    pose_frames: Option<&[u64]>,
) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let json_path = dir.path().join("blender_bvh.json");
    let mut args: Vec<OsString> = Vec::new();
    if let Some(frames) = pose_frames {
        let list: Vec<String> = frames.iter().map(u64::to_string).collect();
        args.push("--frames".into());
        args.push(list.join(",").into());
    }
    args.push(json_path.clone().into());
    args.extend(files.iter().map(|f| f.as_ref().as_os_str().to_owned()));
    run_python(
        py,
        "tests/python/blender_import_bvh.py",
        &mut args.iter().map(OsString::as_os_str),
    );
    serde_json::from_slice(&std::fs::read(&json_path).unwrap()).unwrap()
}

/// Blender's own glTF import of each file, in one run of tests/python/blender_import_gltf.py
/// (see its docstring): one report per file, in order. `query`: `{"bones", "times"}`.
pub fn blender_import_gltf<P: AsRef<Path>>(
    py: &Path,
    files: &[P],
    query: &serde_json::Value,
) -> Vec<serde_json::Value> {
    let query = OsString::from(query.to_string());
    let stdout = run_python(
        py,
        "tests/python/blender_import_gltf.py",
        &mut files
            .iter()
            .map(|f| f.as_ref().as_os_str())
            .chain(std::iter::once(query.as_os_str())),
    );
    let lines: Vec<&str> = stdout.lines().collect();
    assert!(lines.len() >= files.len(), "{stdout}");
    lines[lines.len() - files.len()..]
        .iter()
        .map(|line| serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}")))
        .collect()
}

/// Runs `cmd`, which must succeed (a failure shows the command and what it printed); its output.
pub fn run(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?}\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The (sensor or joint, bone) pairs a sidecar's `mapping.sensors` lists.
pub fn sidecar_pairs(sidecar: &serde_json::Value) -> Vec<(String, String)> {
    sidecar["mapping"]["sensors"]
        .as_array()
        .map(|sensors| {
            sensors
                .iter()
                .map(|s| {
                    (
                        s["sensor"].as_str().unwrap_or_default().to_string(),
                        s["bone"].as_str().unwrap_or_default().to_string(),
                    )
                })
                .collect()
        })
        .unwrap_or_default()
}

/// `imubake convert INPUT --mapping <mapping_json written into dir> --out dir/out`, which must
/// succeed; the take's sidecar.
pub fn convert_with_mapping(input: &Path, mapping_json: &str, dir: &Path) -> serde_json::Value {
    let mapping = dir.join("mapping.json");
    std::fs::write(&mapping, mapping_json).unwrap();
    let out = dir.join("out");
    run(Command::new(imubake_bin())
        .arg("convert")
        .arg(input)
        .arg("--mapping")
        .arg(&mapping)
        .arg("--out")
        .arg(&out));
    let stem = input.file_stem().unwrap().to_string_lossy();
    serde_json::from_slice(&std::fs::read(out.join(format!("{stem}.imubake.json"))).unwrap())
        .unwrap()
}

/// `format!("{v:.6}")` as the BVH writer has always written numbers: a value that rounds to
/// zero is written positive (`0.000000`, never `-0.000000`).
pub fn six_decimals(v: f64) -> String {
    let text = format!("{v:.6}");
    if text == "-0.000000" {
        "0.000000".to_string()
    } else {
        text
    }
}
