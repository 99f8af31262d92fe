//! `imubake convert` end to end, its outputs checked in their real consumers.
//!
//! Two takes, the bundled SOU sample (samples/sou_wave.log, 12 nodes, debug text and corrupted
//! lines) and a short simulated full-body walk (`simulate` of ../shared/data/bvh/pymo_walk.bvh
//! through paper 000's 16-sensor layout), are converted at 24, 29.97, 60 and 120 fps into BVH,
//! GLB and .gltf + .bin. Then:
//! - Blender 5.0.1 imports every BVH (scene rate = the sidecar's rational, one key per frame on
//!   every F-curve) and every GLB and .gltf (one armature with the rig's bones, an action);
//! - the Khronos glTF-Validator reports no error and no warning on any GLB or .gltf;
//! - `bvh_anim`, another BVH reader, reads every BVH with the right frame count;
//! - every sidecar holds the contract fields of conventions.md, with a frame count computed here
//!   from the capture (floor(t_last · fps) + 1, t_last from `inspect --json`) and a SHA-256
//!   computed here over the input;
//! - Blender's BVH import and its GLB import of the walk at 60 fps put the bones at the same
//!   places: both files carry the same motion.
//!
//! Then `--units cm`, and the command's behaviour: name clashes, `--json`, mapping errors,
//! unmapped sensors, `--trim`, `--rig` without a mapping, a missing input, determinism.
//!
//! Blender runs are few and batched (two for all 24 files); the conversions are shared by the
//! tests through a fixture built once, under Cargo's per-target temporary folder.

use crate::common;

use common::{
    blender_import_bvh, blender_import_gltf, gltf_validate, imubake_bin, node_modules, python,
    repo_file, shared, vec3,
};
use imubake::rig::load_rig;
use serde_json::Value;
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The rates converted at: as given to `--fps`, and the rational it means (conventions.md).
const RATES: [(&str, u64, u64); 4] = [
    ("24", 24, 1),
    ("29.97", 30000, 1001),
    ("60", 60, 1),
    ("120", 120, 1),
];

const SOU: &str = "samples/sou_wave.log";
const SOU_MAPPING: &str = "samples/sou_wave.mapping.json";
const WALK_MAPPING: &str = "mappings/paper000_16imu_mixamo.json";

/// Walk frames (at 60 fps) whose bone positions Blender's BVH and GLB imports must agree on:
/// the first, and frames in the motion (it starts after the 2 s hold and 1 s blend).
const WALK_60_FRAMES: [u64; 6] = [0, 190, 215, 240, 265, 299];
const SANITY_BONES: [&str; 6] = [
    "Hips",
    "Head",
    "LeftHand",
    "RightForeArm",
    "LeftFoot",
    "RightLeg",
];

fn imubake(args: &[&str]) -> Output {
    Command::new(imubake_bin())
        .args(args)
        .output()
        .expect("imubake runs")
}

fn utf8(path: &Path) -> &str {
    path.to_str().expect("a UTF-8 path")
}

/// `imubake convert <inputs> [--mapping <mapping>] --out <out> <extra>`.
fn convert(inputs: &[&Path], mapping: Option<&Path>, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["convert"];
    args.extend(inputs.iter().map(|p| utf8(p)));
    if let Some(m) = mapping {
        args.extend(["--mapping", utf8(m)]);
    }
    args.extend(["--out", utf8(out)]);
    args.extend(extra);
    imubake(&args)
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Asserts success; the output.
fn ok(out: Output) -> Output {
    assert!(
        out.status.success(),
        "{:?}\nstdout: {}\nstderr: {}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        stderr(&out)
    );
    out
}

fn read_json(path: &Path) -> Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn sha256_hex(path: &Path) -> String {
    Sha256::digest(std::fs::read(path).unwrap())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn sorted(mut names: Vec<&str>) -> Vec<&str> {
    names.sort_unstable();
    names
}

/// A capture and what `inspect --json` and its mapping file say about it.
struct Take {
    name: &'static str,
    input: PathBuf,
    mapping: PathBuf,
    stem: &'static str,
    inspect: Value,
    /// Latest sample of any mapped sensor, seconds on the take's clock.
    t_last_s: f64,
    /// sensor → bone, from the mapping file.
    bones: BTreeMap<String, String>,
}

impl Take {
    fn new(name: &'static str, input: PathBuf, mapping: PathBuf, stem: &'static str) -> Take {
        let inspect: Value =
            serde_json::from_slice(&ok(imubake(&["inspect", utf8(&input), "--json"])).stdout)
                .unwrap();
        let bones: BTreeMap<String, String> = read_json(&mapping)["sensors"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(s, m)| (s.clone(), m["bone"].as_str().unwrap().to_string()))
            .collect();
        let t_last_s = inspect["sensors"]
            .as_object()
            .unwrap()
            .iter()
            .filter(|(id, _)| bones.contains_key(*id))
            .map(|(_, s)| s["last_s"].as_f64().unwrap())
            .fold(f64::NEG_INFINITY, f64::max);
        Take {
            name,
            input,
            mapping,
            stem,
            inspect,
            t_last_s,
            bones,
        }
    }

    /// floor(t_last · fps) + 1, refusing a t_last so close to a frame that rounding decides.
    fn expected_frames(&self, num: u64, den: u64) -> u64 {
        let last = self.t_last_s * num as f64 / den as f64;
        assert!(
            (last - last.round()).abs() > 1e-6,
            "{}: t_last {} s is on a frame at {num}/{den}; pick another take",
            self.name,
            self.t_last_s
        );
        last.floor() as u64 + 1
    }
}

/// One `convert` run of a take at a rate, with all three formats.
struct Conversion {
    take: usize,
    rate: (&'static str, u64, u64),
    dir: PathBuf,
    sidecar: Value,
    frames: u64,
}

impl Conversion {
    fn file(&self, fixture: &Fixture, ext: &str) -> PathBuf {
        self.dir
            .join(format!("{}.{ext}", fixture.takes[self.take].stem))
    }

    fn label(&self, fixture: &Fixture) -> String {
        format!("{} at {}", fixture.takes[self.take].name, self.rate.0)
    }
}

struct Fixture {
    takes: Vec<Take>,
    conversions: Vec<Conversion>,
}

impl Fixture {
    fn walk_60(&self) -> Option<&Conversion> {
        self.conversions
            .iter()
            .find(|c| self.takes[c.take].name == "walk" && c.rate.0 == "60")
    }

    fn files(&self, ext: &str) -> Vec<PathBuf> {
        self.conversions.iter().map(|c| c.file(self, ext)).collect()
    }
}

/// A fresh folder under Cargo's temporary folder for this test target.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("convert_outputs")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn convert_into(take: &Take, dir: &Path, extra: &[&str]) -> Value {
    let out = ok(convert(&[&take.input], Some(&take.mapping), dir, extra));
    // Only the line counting the dropped lines (the SOU sample has debug text), and at 60 and
    // 120 fps the warning that the SOU sample's 26 Hz is less than half the frame rate.
    let text = stderr(&out);
    let messages: Vec<&str> = text
        .lines()
        .filter(|l| !(l.starts_with("note: ") && l.contains(" dropped ")))
        .filter(|l| !l.contains("is more than twice the fastest mapped sensor's rate"))
        .collect();
    assert!(
        messages.is_empty(),
        "{}: unexpected messages: {text}",
        take.name
    );
    read_json(&dir.join(format!("{}.imubake.json", take.stem)))
}

/// The shared conversions: the SOU sample, and (when ../shared/data is there) the simulated
/// walk, each at every rate of [`RATES`].
fn fixture() -> &'static Fixture {
    static FIXTURE: OnceLock<Fixture> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        let root = scratch("matrix");
        let mut takes = vec![Take::new(
            "sou",
            repo_file(SOU),
            repo_file(SOU_MAPPING),
            "sou_wave",
        )];
        if let Some(motion) = shared("bvh/pymo_walk.bvh") {
            let capture = root.join("walk.csv");
            // 2 s of the walk (frames 0..=240 at 120 fps) after the 2 s hold and 1 s blend.
            ok(imubake(&[
                "simulate",
                utf8(&motion),
                "--mapping",
                utf8(&repo_file(WALK_MAPPING)),
                "--bone-map",
                "Spine2=Spine",
                "--frames",
                "0:240",
                "--seed",
                "1",
                "--output",
                utf8(&capture),
            ]));
            takes.push(Take::new("walk", capture, repo_file(WALK_MAPPING), "walk"));
        }
        let mut conversions = Vec::new();
        for (t, take) in takes.iter().enumerate() {
            for rate in RATES {
                let dir = root.join(format!("{}_{}", take.name, rate.0));
                let sidecar =
                    convert_into(take, &dir, &["--fps", rate.0, "--format", "bvh,glb,gltf"]);
                conversions.push(Conversion {
                    take: t,
                    rate,
                    dir,
                    sidecar,
                    frames: take.expected_frames(rate.1, rate.2),
                });
            }
        }
        Fixture { takes, conversions }
    })
}

#[test]
fn sidecars_hold_the_contract_and_describe_the_files() {
    let fx = fixture();
    let rig = load_rig("mixamo").unwrap();
    for c in &fx.conversions {
        let take = &fx.takes[c.take];
        let s = &c.sidecar;
        let label = c.label(fx);
        let (_, num, den) = c.rate;
        eprintln!(
            "{label}: t_last {} s, frames {} (expected {}), duration {} s",
            take.t_last_s, s["frames"], c.frames, s["duration_s"]
        );

        assert_eq!(s["imubake_version"], env!("CARGO_PKG_VERSION"), "{label}");
        // source
        let src = &s["source"];
        assert_eq!(src["path"], take.input.to_str().unwrap(), "{label}");
        assert_eq!(src["sha256"], sha256_hex(&take.input), "{label}");
        for key in ["format", "world", "start_timestamp"] {
            assert!(src[key].is_string(), "{label}: source.{key}: {src}");
            assert_eq!(
                src[key], take.inspect["source"][key],
                "{label}: source.{key}"
            );
        }
        // fps, frames, duration
        assert_eq!(s["fps"]["num"].as_u64(), Some(num), "{label}");
        assert_eq!(s["fps"]["den"].as_u64(), Some(den), "{label}");
        let float = s["fps"]["float"].as_f64().unwrap();
        assert!(
            (float - num as f64 / den as f64).abs() < 1e-9,
            "{label}: {float}"
        );
        assert_eq!(s["frames"].as_u64(), Some(c.frames), "{label}");
        let duration = s["duration_s"].as_f64().unwrap();
        let expected = (c.frames - 1) as f64 * den as f64 / num as f64;
        assert!(
            (duration - expected).abs() < 1e-9,
            "{label}: {duration} vs {expected}"
        );
        // inspect's time frame is the same t_last (every sensor of both takes is mapped)
        let time_frame = take.inspect["time_frame_s"].as_f64().unwrap();
        assert!((time_frame - take.t_last_s).abs() < 1e-9, "{label}");
        // rig
        assert_eq!(s["rig"]["name"], "mixamo", "{label}");
        assert_eq!(s["rig"]["units"], "m", "{label}");
        assert_eq!(
            s["rig"]["bones"].as_u64(),
            Some(rig.len() as u64),
            "{label}"
        );
        // mapping: the resolved one, every sensor of the file on its bone
        let mapping = &s["mapping"];
        assert_eq!(mapping["file"], take.mapping.to_str().unwrap(), "{label}");
        let resolved: BTreeMap<String, String> = mapping["sensors"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| {
                (
                    m["sensor"].as_str().unwrap().to_string(),
                    m["bone"].as_str().unwrap().to_string(),
                )
            })
            .collect();
        assert_eq!(resolved, take.bones, "{label}");
        // pipeline
        for key in ["fusion", "smoothing", "root", "heading"] {
            assert!(
                s["pipeline"].get(key).is_some(),
                "{label}: pipeline.{key}: {}",
                s["pipeline"]
            );
        }
        assert!(s["pipeline"].get("trim").is_none(), "{label}");
        // sensors and dropped lines: what inspect reports for the same capture
        let sensors = s["sensors"].as_object().unwrap();
        let inspected = take.inspect["sensors"].as_object().unwrap();
        assert_eq!(
            sensors.keys().collect::<BTreeSet<_>>(),
            inspected.keys().collect::<BTreeSet<_>>(),
            "{label}"
        );
        for (id, summary) in sensors {
            assert_eq!(summary["samples"], inspected[id]["samples"], "{label} {id}");
            assert!(summary["gaps"].is_array(), "{label} {id}");
        }
        assert_eq!(s["dropped_lines"], take.inspect["dropped_lines"], "{label}");
        // No warning, but the documented one for a frame rate above twice the fastest sensor's
        // (the SOU sample's nodes log at about 26 Hz, so at 60 and 120 fps).
        let fastest_hz = inspected
            .values()
            .filter_map(|v| v["mean_dt_ms"].as_f64())
            .map(|ms| 1000.0 / ms)
            .fold(0.0, f64::max);
        let warnings = s["warnings"].as_array().unwrap();
        if num as f64 / den as f64 > 2.0 * fastest_hz {
            assert_eq!(warnings.len(), 1, "{label}: {warnings:?}");
            assert!(
                warnings[0]
                    .as_str()
                    .unwrap()
                    .contains("is more than twice the fastest mapped sensor's rate"),
                "{label}: {warnings:?}"
            );
        } else {
            assert!(warnings.is_empty(), "{label}: {warnings:?}");
        }

        // outputs: listed, present, and nothing else in the folder (no temporary file left)
        let listed: Vec<(&str, &str)> = s["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| (o["format"].as_str().unwrap(), o["path"].as_str().unwrap()))
            .collect();
        let stem = take.stem;
        let (bvh, glb, gltf) = (
            format!("{stem}.bvh"),
            format!("{stem}.glb"),
            format!("{stem}.gltf"),
        );
        assert_eq!(
            listed,
            [
                ("bvh", bvh.as_str()),
                ("glb", glb.as_str()),
                ("gltf", gltf.as_str())
            ],
            "{label}"
        );
        // The .gltf's buffer, as it names it.
        let gltf_json = read_json(&c.dir.join(&gltf));
        let bin = gltf_json["buffers"][0]["uri"].as_str().unwrap().to_string();
        assert_eq!(bin, format!("{stem}.bin"), "{label}");
        let present: BTreeSet<String> = std::fs::read_dir(&c.dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        let expected: BTreeSet<String> =
            [bvh, glb, gltf, bin, format!("{stem}.imubake.json")].into();
        assert_eq!(present, expected, "{label}");
        for name in &present {
            assert!(
                !(name.starts_with('.') && name.ends_with(".tmp")),
                "{label}: {name} left behind"
            );
            assert!(
                std::fs::metadata(c.dir.join(name)).unwrap().len() > 0,
                "{label}: {name} is empty"
            );
        }
    }
}

#[test]
fn bvh_anim_reads_every_bvh() {
    let fx = fixture();
    let rig = load_rig("mixamo").unwrap();
    for c in &fx.conversions {
        let label = c.label(fx);
        let bytes = std::fs::read(c.file(fx, "bvh")).unwrap();
        let theirs = bvh_anim::from_bytes(&bytes[..]).unwrap_or_else(|e| panic!("{label}: {e}"));
        assert_eq!(theirs.num_frames() as u64, c.frames, "{label}");
        assert_eq!(theirs.joints().count(), rig.len(), "{label}");
        let (_, num, den) = c.rate;
        let ft = theirs.frame_time().as_secs_f64();
        // bvh_anim keeps the frame time as a Duration (whole nanoseconds).
        assert!((ft - den as f64 / num as f64).abs() < 2e-9, "{label}: {ft}");
        // Our own reader agrees.
        let ours = imubake::bvh::parse(&bytes).unwrap();
        assert_eq!(ours.frame_count() as u64, c.frames, "{label}");
    }
}

#[test]
fn validator_finds_no_error_or_warning_in_any_gltf() {
    let Some(modules) = node_modules() else {
        return;
    };
    let fx = fixture();
    let mut files = fx.files("glb");
    files.extend(fx.files("gltf"));
    let reports = gltf_validate(&files, &modules);
    for (file, report) in files.iter().zip(&reports) {
        eprintln!(
            "{}: errors {} warnings {} infos {} hints {}",
            file.strip_prefix(env!("CARGO_TARGET_TMPDIR"))
                .unwrap_or(file)
                .display(),
            report["errors"],
            report["warnings"],
            report["infos"],
            report["hints"]
        );
        assert_eq!(
            (report["errors"].as_u64(), report["warnings"].as_u64()),
            (Some(0), Some(0)),
            "{}: {report:#}",
            file.display()
        );
    }
}

#[test]
fn blender_imports_every_output_and_bvh_and_glb_carry_the_same_motion() {
    let Some(py) = python() else {
        return;
    };
    let fx = fixture();
    let rig = load_rig("mixamo").unwrap();
    let bone_names = sorted(rig.joints().iter().map(|j| j.name.as_str()).collect());

    // BVH: one Blender run for all files; poses at the walk frames checked below (Blender
    // frame = our frame + 1).
    let pose_frames: Vec<u64> = WALK_60_FRAMES.iter().map(|n| n + 1).collect();
    let bvh_files = fx.files("bvh");
    let bvh_report = blender_import_bvh(&py, &bvh_files, Some(&pose_frames));
    assert_eq!(bvh_report["blender"], "5.0.1");
    let imports = bvh_report["files"].as_array().unwrap();
    assert_eq!(imports.len(), fx.conversions.len());
    for (c, file) in fx.conversions.iter().zip(imports) {
        let label = c.label(fx);
        let (_, num, den) = c.rate;
        let rate = num as f64 / den as f64;
        let fps = file["fps"].as_f64().unwrap();
        let fps_base = file["fps_base"].as_f64().unwrap();
        let keys: BTreeSet<u64> = file["fcurves"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f["keys"].as_u64().unwrap())
            .collect();
        eprintln!(
            "{label}: Blender BVH fps {fps}, fps_base {fps_base:.11}, rate {:.9}; {} F-curves with {keys:?} keys, frames {}..{}",
            fps / fps_base,
            file["fcurves"].as_array().unwrap().len(),
            file["frame_start"],
            file["frame_end"]
        );
        // The sidecar's rational, which the fixture checked against the rate asked for.
        assert_eq!(c.sidecar["fps"]["num"].as_u64(), Some(num));
        assert_eq!(c.sidecar["fps"]["den"].as_u64(), Some(den));
        assert_eq!(fps, rate.round(), "{label}");
        // fps_base is a single-precision property: 1.001 is stored as 1.00100004673.
        assert!(
            (fps_base - fps * den as f64 / num as f64).abs() < 1e-6,
            "{label}: fps_base {fps_base}"
        );
        assert!(((fps / fps_base) / rate - 1.0).abs() < 1e-6, "{label}");
        assert_eq!(
            sorted(common::strings(&file["bones"])),
            bone_names,
            "{label}"
        );
        // The root's location and rotation, every other joint's rotation.
        assert_eq!(
            file["fcurves"].as_array().unwrap().len(),
            3 + 3 * rig.len(),
            "{label}"
        );
        let frames = c.sidecar["frames"].as_u64().unwrap();
        assert_eq!(frames, c.frames, "{label}");
        for curve in file["fcurves"].as_array().unwrap() {
            assert_eq!(curve["keys"].as_u64(), Some(frames), "{label}: {curve}");
            assert_eq!(curve["first"].as_f64(), Some(1.0), "{label}: {curve}");
            assert_eq!(
                curve["last"].as_f64(),
                Some(frames as f64),
                "{label}: {curve}"
            );
        }
        assert_eq!(file["frame_start"].as_u64(), Some(1), "{label}");
        // update_scene_duration only ever extends the factory scene (frames 1..250) to one past
        // the last key.
        assert_eq!(
            file["frame_end"].as_u64(),
            Some((frames + 1).max(250)),
            "{label}"
        );
    }

    // GLB and .gltf: one Blender run for all files, heads of a few bones at the walk frames'
    // key times (as written, f32).
    let times: Vec<f64> = WALK_60_FRAMES
        .iter()
        .map(|&n| f64::from((n as f64 / 60.0) as f32))
        .collect();
    let query = serde_json::json!({"bones": SANITY_BONES, "times": times});
    let mut gltf_files = fx.files("glb");
    gltf_files.extend(fx.files("gltf"));
    let gltf_reports = blender_import_gltf(&py, &gltf_files, &query);
    for (k, (file, report)) in gltf_files.iter().zip(&gltf_reports).enumerate() {
        let c = &fx.conversions[k % fx.conversions.len()];
        let label = format!(
            "{} ({})",
            c.label(fx),
            file.extension().unwrap().to_string_lossy()
        );
        eprintln!(
            "{label}: Blender glTF: {} armature(s), {} bones, action {}, frame range {}",
            report["armatures"],
            report["bones"].as_array().map_or(0, Vec::len),
            report["action"],
            report["frame_range"]
        );
        assert_eq!(report["blender"], "5.0.1");
        assert_eq!(report["armatures"], 1, "{label}: {report}");
        assert_eq!(
            sorted(common::strings(&report["bones"])),
            bone_names,
            "{label}"
        );
        let stem = fx.takes[c.take].stem;
        assert_eq!(
            report["action"].as_str().map(|a| a.contains(stem)),
            Some(true),
            "{label}: {report}"
        );
        // The action spans the take: its last key at duration_s in the importer's frames.
        let per_second = report["frames_per_second"].as_f64().unwrap();
        let duration = c.sidecar["duration_s"].as_f64().unwrap();
        let range = &report["frame_range"];
        assert!(range[0].as_f64().unwrap().abs() < 1e-4, "{label}: {range}");
        assert!(
            (range[1].as_f64().unwrap() - f64::from(duration as f32) * per_second).abs() < 1e-3,
            "{label}: {range} vs {duration} s"
        );
    }

    // Motion: the walk at 60 fps, BVH import vs GLB import (and .gltf import), both through
    // Blender's own axis conversion.
    let Some(walk) = fx.walk_60() else {
        return;
    };
    let k = fx
        .conversions
        .iter()
        .position(|c| std::ptr::eq(c, walk))
        .unwrap();
    let bvh_frames = imports[k]["frames"].as_array().unwrap();
    let glb = &gltf_reports[k]["heads"];
    let gltf = &gltf_reports[fx.conversions.len() + k]["heads"];
    let mut worst = 0.0f64;
    let mut spread = 0.0f64;
    for (i, &n) in WALK_60_FRAMES.iter().enumerate() {
        assert_eq!(bvh_frames[i]["frame"].as_u64(), Some(n + 1));
        for bone in SANITY_BONES {
            let from_bvh = vec3(&bvh_frames[i]["bones"][bone]["head"]);
            let from_glb = vec3(&glb[i]["bones"][bone]);
            let from_gltf = vec3(&gltf[i]["bones"][bone]);
            let err = (from_bvh - from_glb).norm();
            worst = worst.max(err);
            assert!(
                err < 1e-4,
                "walk frame {n} {bone}: BVH {from_bvh:?}, GLB {from_glb:?}: {err} m"
            );
            assert!((from_gltf - from_glb).norm() < 1e-6, "frame {n} {bone}");
            spread = spread.max((from_glb - vec3(&glb[0]["bones"][bone])).norm());
        }
    }
    eprintln!(
        "walk at 60 fps: largest BVH/GLB head difference {worst:.3e} m over {} bones x {} frames; bones move up to {spread:.3} m",
        SANITY_BONES.len(),
        WALK_60_FRAMES.len()
    );
    // The frames compared are not all one pose.
    assert!(spread > 0.05, "{spread}");
}

/// Converts the SOU sample at 30 fps with `extra` flags into a fresh folder.
fn convert_sou(name: &str, extra: &[&str]) -> (PathBuf, Value) {
    let take = Take::new("sou", repo_file(SOU), repo_file(SOU_MAPPING), "sou_wave");
    let dir = scratch(name);
    let sidecar = convert_into(&take, &dir, extra);
    (dir, sidecar)
}

#[test]
fn units_cm_scales_the_bvh_lengths_only() {
    let formats = ["--format", "bvh,glb,gltf"];
    let (m_dir, m) = convert_sou("units_m", &[&formats[..], &["--units", "m"][..]].concat());
    let (cm_dir, cm) = convert_sou("units_cm", &[&formats[..], &["--units", "cm"][..]].concat());
    assert_eq!(m["rig"]["units"], "m");
    assert_eq!(cm["rig"]["units"], "cm");
    assert_eq!(m["frames"], cm["frames"]);

    let parse = |dir: &Path| {
        imubake::bvh::parse(&std::fs::read(dir.join("sou_wave.bvh")).unwrap()).unwrap()
    };
    let (a, b) = (parse(&m_dir), parse(&cm_dir));
    assert_eq!(a.joints().len(), b.joints().len());
    assert_eq!(a.frame_count(), b.frame_count());
    // Written with 6 decimals: 100 × (a metre value rounded to 1e-6) is within 5e-5 cm of the
    // centimetre value rounded to 1e-6.
    let tol = 1e-4;
    for (ja, jb) in a.joints().iter().zip(b.joints()) {
        assert_eq!(ja.name, jb.name);
        assert_eq!(ja.channels, jb.channels);
        assert!((ja.offset * 100.0 - jb.offset).norm() < tol, "{}", ja.name);
        match (ja.end_site, jb.end_site) {
            (Some(ea), Some(eb)) => assert!((ea * 100.0 - eb).norm() < tol, "{}", ja.name),
            (None, None) => {}
            _ => panic!("{}: end sites differ", ja.name),
        }
    }
    let mut positions = 0;
    for f in 0..a.frame_count() {
        for (j, joint) in a.joints().iter().enumerate() {
            let (va, vb) = (a.joint_values(f, j), b.joint_values(f, j));
            for ((channel, x), y) in joint.channels.iter().zip(va).zip(vb) {
                if channel.is_position() {
                    positions += 1;
                    assert!(
                        (x * 100.0 - y).abs() < tol,
                        "frame {f} {}: {x} m vs {y} cm",
                        joint.name
                    );
                } else {
                    assert_eq!(x, y, "frame {f} {} {}", joint.name, channel.name());
                }
            }
        }
    }
    assert_eq!(
        positions,
        3 * a.frame_count(),
        "the root's position channels"
    );
    // The root stands at hip height: metres, then centimetres.
    let root_y = b.joint_values(0, 0)[1];
    assert!((50.0..150.0).contains(&root_y), "root height {root_y} cm");

    // glTF is metres whatever --units says.
    for file in ["sou_wave.glb", "sou_wave.gltf", "sou_wave.bin"] {
        assert!(
            std::fs::read(m_dir.join(file)).unwrap() == std::fs::read(cm_dir.join(file)).unwrap(),
            "{file} differs between --units m and cm"
        );
    }
}

#[test]
fn two_inputs_with_the_same_stem_are_a_usage_error() {
    let dir = scratch("same_stem");
    let (a, b) = (dir.join("a/sou_wave.log"), dir.join("b/sou_wave.log"));
    for p in [&a, &b] {
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::copy(repo_file(SOU), p).unwrap();
    }
    let out_dir = dir.join("out");
    let out = convert(&[&a, &b], Some(&repo_file(SOU_MAPPING)), &out_dir, &[]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains(a.to_str().unwrap()) && err.contains(b.to_str().unwrap()),
        "{err}"
    );
    assert!(
        !out_dir.join("sou_wave.imubake.json").exists(),
        "nothing is converted"
    );
}

#[test]
fn json_prints_exactly_the_sidecars_written() {
    let dir = scratch("json");
    let (sou, mapping) = (repo_file(SOU), repo_file(SOU_MAPPING));
    let out = ok(convert(&[&sou], Some(&mapping), &dir, &["--json"]));
    let printed: Value = serde_json::from_slice(&out.stdout).unwrap();
    let written = std::fs::read(dir.join("sou_wave.imubake.json")).unwrap();
    assert_eq!(printed, serde_json::from_slice::<Value>(&written).unwrap());
    assert_eq!(out.stdout, written, "the same text, too");

    // Several inputs: an array, one sidecar per input in order.
    let other = dir.join("other.log");
    std::fs::copy(repo_file(SOU), &other).unwrap();
    let out = ok(convert(&[&sou, &other], Some(&mapping), &dir, &["--json"]));
    let printed: Value = serde_json::from_slice(&out.stdout).unwrap();
    let expected = Value::Array(
        ["sou_wave", "other"]
            .iter()
            .map(|stem| read_json(&dir.join(format!("{stem}.imubake.json"))))
            .collect(),
    );
    assert_eq!(printed, expected);
}

/// Converts the SOU sample into `dir`/out with a mapping file written from `text` and `extra`
/// flags; the mapping's path and the output.
fn convert_with_mapping(dir: &Path, name: &str, text: &str, extra: &[&str]) -> (PathBuf, Output) {
    let mapping = dir.join(name);
    std::fs::write(&mapping, text).unwrap();
    let out = convert(&[&repo_file(SOU)], Some(&mapping), &dir.join("out"), extra);
    (mapping, out)
}

#[test]
fn mapping_errors_name_the_file_and_the_key() {
    let dir = scratch("mapping_errors");
    let cases = [
        (
            "unknown_bone.json",
            r#"{"rig": "mixamo", "world": "ned", "sensors": {"N0_0": {"bone": "Tail"}}}"#,
            &["`sensors.N0_0.bone`", "unknown bone `Tail`"][..],
        ),
        (
            "twice.json",
            r#"{"rig": "mixamo", "world": "ned", "sensors": {"N0_0": {"bone": "Hips"}, "N0_1": {"bone": "Spine"}, "N0_0": {"bone": "Head"}}}"#,
            &["`N0_0` is mapped twice"][..],
        ),
        (
            "bad_mount.json",
            r#"{"rig": "mixamo", "world": "ned", "sensors": {"N0_0": {"bone": "Hips", "mount": "+x+x+z"}}}"#,
            &["`sensors.N0_0.mount`"][..],
        ),
        (
            "calibration.json",
            r#"{"rig": "mixamo", "world": "ned", "calibration": {"pose": "rest", "start_s": 30, "duration_s": 1}, "sensors": {"N0_0": {"bone": "Hips"}}}"#,
            &["`calibration`", "outside the take"][..],
        ),
    ];
    for (name, text, needles) in cases {
        let (mapping, out) = convert_with_mapping(&dir, name, text, &[]);
        let err = stderr(&out);
        eprintln!("{name}: {err}");
        assert_eq!(out.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains(mapping.to_str().unwrap()), "{name}: {err}");
        for needle in needles {
            assert!(err.contains(needle), "{name}: no {needle} in {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
    }
    assert!(!dir.join("out/sou_wave.imubake.json").exists());
}

#[test]
fn a_sensor_missing_from_the_mapping_is_a_sidecar_warning() {
    let dir = scratch("unmapped");
    let mut mapping = read_json(&repo_file(SOU_MAPPING));
    mapping["sensors"].as_object_mut().unwrap().remove("N5_1");
    let (_, out) = convert_with_mapping(&dir, "no_head.json", &mapping.to_string(), &[]);
    let out = ok(out);
    let sidecar = read_json(&dir.join("out/sou_wave.imubake.json"));
    let warnings: Vec<&str> = common::strings(&sidecar["warnings"]);
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("N5_1") && w.contains("not in the mapping")),
        "{warnings:?}"
    );
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(stderr(&out).contains("N5_1"), "also said on stderr");
    assert_eq!(sidecar["mapping"]["sensors"].as_array().unwrap().len(), 11);
}

#[test]
fn frames_end_at_the_last_sample_of_a_mapped_sensor() {
    // N1_0 and N1_1 end at 19.966 s, the take at 19.998 s (N0_0): 1198 frames at 60 fps, not
    // 1200; t = 0 stays at the take's earliest sample.
    let dir = scratch("mapped_end");
    // An arm alone gives no heading: the sensors' north is kept (issue 47).
    let text = r#"{"rig": "mixamo", "world": "ned", "heading": "sensors",
        "calibration": {"pose": "rest", "start_s": 0.5, "duration_s": 2.0},
        "sensors": {"N1_0": {"bone": "RightArm"}, "N1_1": {"bone": "RightForeArm"}}}"#;
    let (mapping, out) = convert_with_mapping(&dir, "arm.json", text, &["--fps", "60"]);
    ok(out);
    let take = Take::new("arm", repo_file(SOU), mapping, "sou_wave");
    let expected = take.expected_frames(60, 1);
    let whole = take.inspect["time_frame_s"].as_f64().unwrap();
    assert_ne!(
        expected,
        (whole * 60.0).floor() as u64 + 1,
        "the test needs a shorter sensor"
    );
    let sidecar = read_json(&dir.join("out/sou_wave.imubake.json"));
    eprintln!(
        "t_last of the mapped sensors {} s: {expected} frames",
        take.t_last_s
    );
    assert_eq!(sidecar["frames"].as_u64(), Some(expected));
    assert_eq!(
        sidecar["source"]["start_timestamp"],
        take.inspect["source"]["start_timestamp"]
    );
}

#[test]
fn trim_2_to_5_at_30_fps_keeps_91_frames_and_is_recorded() {
    let (dir, sidecar) = convert_sou(
        "trim",
        &["--fps", "30", "--trim", "2:5", "--format", "bvh,glb"],
    );
    assert_eq!(sidecar["frames"], 91);
    assert!((sidecar["duration_s"].as_f64().unwrap() - 3.0).abs() < 1e-9);
    let trim = &sidecar["pipeline"]["trim"];
    assert_eq!(trim["start_s"].as_f64(), Some(2.0), "{trim}");
    assert_eq!(trim["end_s"].as_f64(), Some(5.0), "{trim}");
    assert_eq!(trim["first_frame"].as_u64(), Some(60), "{trim}");
    let bvh = imubake::bvh::parse(&std::fs::read(dir.join("sou_wave.bvh")).unwrap()).unwrap();
    assert_eq!(bvh.frame_count(), 91);
}

#[test]
fn rig_sou12_without_a_mapping_matches_sensors_to_bones_by_name() {
    let dir = scratch("sou12");
    // Sensors matched by name declare no heading: the sensors' north, deliberately.
    let out = ok(convert(
        &[&repo_file(SOU)],
        None,
        &dir,
        &["--rig", "sou12", "--heading", "sensors"],
    ));
    let sidecar = read_json(&dir.join("sou_wave.imubake.json"));
    assert_eq!(sidecar["rig"]["name"], "sou12");
    assert_eq!(sidecar["rig"]["bones"], 12);
    assert!(sidecar["mapping"]["file"].is_null());
    let sensors = sidecar["mapping"]["sensors"].as_array().unwrap();
    assert_eq!(sensors.len(), 12, "{}", stderr(&out));
    for s in sensors {
        assert_eq!(s["sensor"], s["bone"], "{s}");
    }
    // 19.998 s at the default 30 fps.
    assert_eq!(sidecar["frames"], 600);
    assert_eq!(sidecar["warnings"], serde_json::json!([]));
    for file in ["sou_wave.bvh", "sou_wave.glb"] {
        assert!(dir.join(file).is_file(), "{file}");
    }
}

#[test]
fn a_missing_input_fails_naming_it() {
    let dir = scratch("missing");
    let input = dir.join("no such take.log");
    let mapping = repo_file(SOU_MAPPING);
    let out = convert(&[&input], Some(&mapping), &dir.join("out"), &["--json"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains(input.to_str().unwrap()), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    // --json: no sidecar to print, and nothing that is not JSON either.
    assert!(
        out.stdout.is_empty(),
        "stdout: {:?}",
        String::from_utf8_lossy(&out.stdout)
    );
}

#[test]
fn converting_twice_gives_identical_files() {
    let flags = ["--fps", "29.97", "--format", "bvh,glb,gltf"];
    let (a, _) = convert_sou("twice_a", &flags);
    let (b, _) = convert_sou("twice_b", &flags);
    for ext in ["bvh", "glb", "gltf", "bin", "imubake.json"] {
        let file = format!("sou_wave.{ext}");
        let (x, y) = (
            std::fs::read(a.join(&file)).unwrap(),
            std::fs::read(b.join(&file)).unwrap(),
        );
        assert!(x == y, "{file} differs between two conversions");
    }
}

#[test]
fn each_format_is_written_and_listed_once() {
    let (dir, sidecar) = convert_sou("formats_twice", &["--format", "bvh,glb,bvh"]);
    let outputs: Vec<&Value> = sidecar["outputs"].as_array().unwrap().iter().collect();
    assert_eq!(
        outputs,
        [
            &serde_json::json!({"format": "bvh", "path": "sou_wave.bvh"}),
            &serde_json::json!({"format": "glb", "path": "sou_wave.glb"}),
        ]
    );
    assert!(dir.join("sou_wave.glb").is_file());
}

#[test]
fn a_failed_reconversion_leaves_no_stale_sidecar() {
    let (dir, first) = convert_sou("reconvert", &["--fps", "30", "--format", "bvh,glb"]);
    assert_eq!(first["frames"], 600);
    // The GLB cannot be written this time: a folder stands at its path.
    std::fs::remove_file(dir.join("sou_wave.glb")).unwrap();
    std::fs::create_dir(dir.join("sou_wave.glb")).unwrap();
    let (sou, mapping) = (repo_file(SOU), repo_file(SOU_MAPPING));
    let out = convert(
        &[&sou],
        Some(&mapping),
        &dir,
        &["--fps", "60", "--format", "bvh,glb"],
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("sou_wave.glb"), "{err}");
    // The 30 fps sidecar must not stay claiming a complete take (conventions.md: the sidecar's
    // appearance means the take is complete), and the BVH rewritten at 60 fps before the failure
    // is removed with it: a failed conversion leaves nothing of the take.
    assert!(
        !dir.join("sou_wave.imubake.json").exists(),
        "a stale sidecar describes other outputs"
    );
    assert!(
        !dir.join("sou_wave.bvh").exists(),
        "half a take is left after a failure"
    );
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(!names.iter().any(|n| n.ends_with(".tmp")), "{names:?}");
}
