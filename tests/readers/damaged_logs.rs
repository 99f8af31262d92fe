//! `convert` on damaged logs and in hostile conditions (issue 10): one bad timestamp costs one
//! line, a full disk leaves nothing of the take, a stream is read once, absurd frame rates are
//! caught, the terminal hears of what was dropped, `--world` wins over the mapping, and the
//! messages say what is wrong.

use crate::common;

use common::{imubake_bin, repo_file};
use serde_json::Value;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const WALK: &str = "samples/walk.csv";
const WALK_MAPPING: &str = "mappings/paper000_16imu_mixamo.json";

fn run(args: &[&str]) -> Output {
    Command::new(imubake_bin())
        .args(args)
        .output()
        .expect("imubake runs")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `imubake convert <input> --mapping <paper 000's> --out <out> <extra>`.
fn convert_with_walk_mapping(input: &Path, out: &Path, extra: &[&str]) -> Output {
    let mapping = repo_file(WALK_MAPPING);
    let mut args = vec![
        "convert",
        s(input),
        "--mapping",
        s(&mapping),
        "--out",
        s(out),
    ];
    args.extend(extra);
    run(&args)
}

fn sidecar(out: &Path, stem: &str) -> Value {
    let text = fs::read_to_string(out.join(format!("{stem}.imubake.json"))).expect("sidecar");
    serde_json::from_str(&text).expect("sidecar parses")
}

/// The walk sample with line `line` (1-based) changed by `edit`.
fn walk_with(line: usize, edit: impl Fn(&str) -> String) -> String {
    let text = fs::read_to_string(repo_file(WALK)).unwrap();
    text.lines()
        .enumerate()
        .map(|(i, l)| {
            if i + 1 == line {
                edit(l)
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

fn visible_files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = fs::read_dir(dir)
        .map(|d| {
            d.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn one_corrupted_timestamp_costs_one_line() {
    // The reproduction: line 1004's time becomes 1000000.0.
    let tmp = tempfile::tempdir().unwrap();
    let g = tmp.path().join("g.csv");
    let text = walk_with(1004, |l| {
        let (_, rest) = l.split_once(',').unwrap();
        format!("1000000.0,{rest}")
    });
    fs::write(&g, &text).unwrap();
    let out = tmp.path().join("o");
    let o = convert_with_walk_mapping(&g, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let side = sidecar(&out, "g");
    let dropped = side["dropped_lines"].as_array().unwrap();
    assert_eq!(dropped.len(), 1, "{dropped:?}");
    assert_eq!(dropped[0]["line"], 1004);
    assert!(
        dropped[0]["reason"]
            .as_str()
            .unwrap()
            .starts_with("time out of sequence")
    );
    // The terminal hears of it, once, pointing at the sidecar.
    let err = stderr(&o);
    assert!(
        err.contains("dropped 1 line, repaired 0") && err.contains("g.imubake.json"),
        "{err}"
    );
    // And the take is the clean take's length (the bad time did not stretch it to 11 days).
    let clean = tmp.path().join("clean");
    let o = convert_with_walk_mapping(&repo_file(WALK), &clean, &[]);
    assert!(o.status.success());
    assert_eq!(side["frames"], sidecar(&clean, "walk")["frames"]);
}

#[test]
fn a_long_gap_is_a_warning_naming_its_frames() {
    // Every sample after 5 s moved 30 s later: a 30 s gap in all sensors.
    let text = fs::read_to_string(repo_file(WALK)).unwrap();
    let shifted: String = text
        .lines()
        .map(|l| match l.split_once(',') {
            Some((t, rest)) if t.parse::<f64>().is_ok_and(|t| t > 5.0) => {
                format!("{:.6},{rest}\n", t.parse::<f64>().unwrap() + 30.0)
            }
            _ => format!("{l}\n"),
        })
        .collect();
    let tmp = tempfile::tempdir().unwrap();
    let gap = tmp.path().join("gap.csv");
    fs::write(&gap, shifted).unwrap();
    let out = tmp.path().join("o");
    let o = convert_with_walk_mapping(&gap, &out, &["--fps", "10"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    let line = err
        .lines()
        .find(|l| l.contains("gap in all sensors"))
        .unwrap_or_else(|| panic!("no gap warning: {err}"));
    // The last sample before the gap is just before 5 s, the first after it just after 35 s:
    // frames 50–350 at 10 fps lie inside.
    assert!(line.contains("frames 50–350"), "{line}");
    assert!(line.starts_with("warning:"), "{line}");
}

#[test]
#[cfg(unix)]
fn a_full_disk_leaves_nothing_of_the_take() {
    use std::os::unix::process::CommandExt;
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    // An earlier conversion's outputs, to be replaced.
    let o = convert_with_walk_mapping(&repo_file(WALK), &out, &["--format", "glb,bvh"]);
    assert!(o.status.success());
    assert_eq!(
        visible_files(&out),
        ["walk.bvh", "walk.glb", "walk.imubake.json"]
    );
    // Files may grow to 200 kB: the GLB (134 kB) fits, the BVH (237 kB) does not, as on a disk
    // that fills up half-way through a take.
    let mut cmd = Command::new(imubake_bin());
    cmd.args([
        "convert",
        s(&repo_file(WALK)),
        "--mapping",
        s(&repo_file(WALK_MAPPING)),
        "--out",
        s(&out),
        "--format",
        "glb,bvh",
        "--smooth",
        "none",
    ]);
    unsafe {
        cmd.pre_exec(|| {
            // Writes past the limit fail with EFBIG instead of killing the process.
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let limit = libc::rlimit {
                rlim_cur: 200_000,
                rlim_max: 200_000,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let o = cmd.output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("walk.bvh"), "{}", stderr(&o));
    let left: Vec<String> = fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
#[cfg(unix)]
fn a_stream_is_read_once_and_converts_like_its_file() {
    let tmp = tempfile::tempdir().unwrap();
    let fifo = tmp.path().join("take.csv");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            let bytes = fs::read(repo_file(WALK)).unwrap();
            fs::write(fifo, bytes).unwrap();
        })
    };
    let (from_fifo, from_file) = (tmp.path().join("fifo"), tmp.path().join("file"));
    let o = convert_with_walk_mapping(&fifo, &from_fifo, &[]);
    writer.join().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let walk_copy = tmp.path().join("take2.csv");
    fs::copy(repo_file(WALK), &walk_copy).unwrap();
    let o = convert_with_walk_mapping(&walk_copy, &from_file, &[]);
    assert!(o.status.success());
    assert_eq!(
        fs::read(from_fifo.join("take.bvh")).unwrap(),
        fs::read(from_file.join("take2.bvh")).unwrap()
    );
    assert_eq!(
        sidecar(&from_fifo, "take")["source"]["sha256"],
        sidecar(&from_file, "take2")["source"]["sha256"]
    );
}

#[test]
#[cfg(unix)]
fn dev_zero_is_refused_by_content() {
    let o = run(&["convert", "/dev/zero", "--rig", "sou12", "--out", "/tmp"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("/dev/zero: looks binary (a NUL byte at offset 0)"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn absurd_frame_rates_are_caught() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    let walk = s(&repo_file(WALK)).to_string();
    // The walk's sensors sample at about 100 Hz: 240 fps is mostly interpolation.
    let o = convert_with_walk_mapping(&repo_file(WALK), &out, &["--fps", "240"]);
    assert!(o.status.success());
    assert!(
        stderr(&o).contains("--fps 240 is more than twice the fastest mapped sensor's rate"),
        "{}",
        stderr(&o)
    );
    // The walk twice over (24 s) at 100000 fps × 22 joints is 52 M keyframes (about 1 GB of
    // BVH): refused unless --force.
    let long = tmp.path().join("long.csv");
    let text = fs::read_to_string(&walk).unwrap();
    let mut doubled = text.clone();
    for l in text.lines() {
        if let Some((t, rest)) = l.split_once(',')
            && let Ok(t) = t.parse::<f64>()
        {
            doubled.push_str(&format!("{:.6},{rest}\n", t + 12.0));
        }
    }
    fs::write(&long, doubled).unwrap();
    let o = convert_with_walk_mapping(&long, &out, &["--fps", "100000"]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(
        err.contains("more than the 50000000 allowed without --force") && err.contains("--fps"),
        "{err}"
    );
    assert!(!out.join("long.bvh").exists());
}

/// A mapping file like paper 000's with its `world` set to `world`.
fn mapping_with_world(dir: &Path, world: &str) -> PathBuf {
    let mut m: Value =
        serde_json::from_str(&fs::read_to_string(repo_file(WALK_MAPPING)).unwrap()).unwrap();
    m["world"] = Value::from(world);
    let path = dir.join(format!("m_{world}.json"));
    fs::write(&path, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    path
}

#[test]
fn the_world_comes_from_the_flag_then_the_config_then_the_mapping_then_the_format() {
    let tmp = tempfile::tempdir().unwrap();
    let nwu = mapping_with_world(tmp.path(), "nwu");
    let walk = s(&repo_file(WALK)).to_string();
    let convert = |name: &str, extra: &[&str]| -> (Value, Vec<u8>) {
        let out = tmp.path().join(name);
        let mut args = vec!["convert", &walk, "--out", s(&out), "--smooth", "none"];
        args.extend(extra);
        let o = run(&args);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        (
            sidecar(&out, "walk"),
            fs::read(out.join("walk.bvh")).unwrap(),
        )
    };
    let (mapping, mapping_bvh) = convert("mapping", &["--mapping", s(&nwu)]);
    assert_eq!(mapping["source"]["world"], "nwu");
    assert_eq!(mapping["source"]["world_from"], "mapping");
    let (flag, flag_bvh) = convert("flag", &["--mapping", s(&nwu), "--world", "ned"]);
    assert_eq!(flag["source"]["world"], "ned");
    assert_eq!(flag["source"]["world_from"], "flag");
    assert_ne!(flag_bvh, mapping_bvh, "--world changes the motion");
    let config = tmp.path().join("c.yaml");
    fs::write(&config, "world: ned\n").unwrap();
    let (from_config, config_bvh) =
        convert("config", &["--mapping", s(&nwu), "--config", s(&config)]);
    assert_eq!(from_config["source"]["world_from"], "config");
    assert_eq!(config_bvh, flag_bvh);
    let (flag_over_config, _) = convert(
        "both",
        &[
            "--mapping",
            s(&nwu),
            "--config",
            s(&config),
            "--world",
            "enu",
        ],
    );
    assert_eq!(flag_over_config["source"]["world"], "enu");
    assert_eq!(flag_over_config["source"]["world_from"], "flag");
    // The walk's mapping without `world` → the file's own `# world: enu`.
    let plain = mapping_with_world(tmp.path(), "enu");
    let mut m: Value = serde_json::from_str(&fs::read_to_string(&plain).unwrap()).unwrap();
    m.as_object_mut().unwrap().remove("world");
    fs::write(&plain, m.to_string()).unwrap();
    let (format, _) = convert("format", &["--mapping", s(&plain)]);
    assert_eq!(format["source"]["world"], "enu");
    assert_eq!(format["source"]["world_from"], "format");
}

#[test]
fn messages_say_what_is_wrong_once() {
    let tmp = tempfile::tempdir().unwrap();
    let walk = s(&repo_file(WALK)).to_string();
    let out = tmp.path().join("o");
    let o = convert_with_walk_mapping(&repo_file(WALK), &out, &["--trim", "20:"]);
    let err = stderr(&o);
    assert!(err.contains("--trim 20: keeps no frame"), "{err}");
    assert!(!err.contains("179769"), "{err}");

    let file = tmp.path().join("a_file");
    fs::write(&file, "x").unwrap();
    let o = convert_with_walk_mapping(&repo_file(WALK), &file, &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("expected a folder"), "{}", stderr(&o));
    for (cmd, input) in [("batch", walk.as_str()), ("watch", s(tmp.path()))] {
        let o = run(&[cmd, input, "--out", s(&file)]);
        assert_eq!(o.status.code(), Some(2), "{cmd}");
        assert!(
            stderr(&o).contains("expected a folder"),
            "{cmd}: {}",
            stderr(&o)
        );
    }

    let missing = tmp.path().join("missing.csv");
    let o = run(&["inspect", s(&missing)]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert_eq!(err.matches("No such file or directory").count(), 1, "{err}");
}

/// Raw readings that cannot be right are errors naming the sensor and what is wrong, never a
/// silent wrong animation: an accelerometer without a gyro, °/s labelled rad/s, g labelled m/s².
#[test]
fn raw_readings_that_cannot_be_right_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let cases = [
        (
            "time_s,sensor,ax,ay,az\n0,Hips,0,0,9.8\n0.01,Hips,0,0,9.8\n",
            "missing column(s) gx,gy,gz",
        ),
        (
            "time_s,sensor,gx,gy,gz,ax,ay,az\n0,Hips,0,0,0,0,0,9.8\n0.01,Hips,250,0,0,0,0,9.8\n",
            "sensor `Hips`: gyroscope rates reach 250 rad/s",
        ),
        (
            "time_s,sensor,gx,gy,gz,ax,ay,az\n0,Hips,0,0,0,0,0,1\n0.01,Hips,0,0,0,0,0.01,1\n",
            "sensor `Hips`: the accelerometer reads 1.00 at rest, not 9.81 m/s². Hint: the readings are probably in g",
        ),
    ];
    for (i, (csv, expected)) in cases.iter().enumerate() {
        let input = dir.path().join(format!("raw{i}.csv"));
        fs::write(&input, csv).unwrap();
        let o = run(&["convert", s(&input), "--out", s(&out)]);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(stderr(&o).contains(expected), "{}", stderr(&o));
        assert!(!out.join(format!("raw{i}.bvh")).exists());
    }
}

/// A log with 100 000 garbage lines among its data (issue 43): the take converts, and the sidecar
/// lists the first 1000 dropped lines whole and counts the other 99 000 by reason — kilobytes,
/// not the ~10 MB a full list would take.
#[test]
fn a_flood_of_garbage_lines_gives_a_bounded_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let walk = fs::read_to_string(repo_file(WALK)).unwrap();
    let mut text = String::new();
    for (i, line) in walk.lines().enumerate() {
        text.push_str(line);
        text.push('\n');
        if i == 100 {
            for k in 0..100_000 {
                text.push_str(&format!("garbage {k}\n"));
            }
        }
    }
    let input = dir.path().join("flood.csv");
    fs::write(&input, &text).unwrap();
    let out = dir.path().join("out");
    let o = convert_with_walk_mapping(&input, &out, &["--format", "bvh"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let sc = sidecar(&out, "flood");
    let listed = sc["dropped_lines"].as_array().unwrap();
    assert_eq!(listed.len(), 1000);
    // The first listed is the first garbage line: line 102 of the file.
    assert_eq!(listed[0]["line"], 102);
    assert_eq!(listed[999]["line"], 1101);
    assert_eq!(sc["dropped_lines_total"], 100_000);
    let omitted = sc["dropped_lines_omitted"].as_array().unwrap();
    let counted: u64 = omitted.iter().map(|r| r["lines"].as_u64().unwrap()).sum();
    assert_eq!(counted, 99_000, "{omitted:?}");
    let size = fs::metadata(out.join("flood.imubake.json")).unwrap().len();
    assert!(size < 1 << 20, "a sidecar of {size} bytes");
}
