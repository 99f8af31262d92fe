//! Issue 45: a skeleton's body parts do not depend on the scheme its joints are named in. Four
//! real BVH skeletons (CMU's, pymo's, a Mixamo export, CMU's Poser-named terrain walk) have their
//! part joints — the pelvis, each spine and neck joint, the head and every limb part, as
//! `imubake inspect --json` resolves them on the original — renamed into each of ten schemes
//! (Mixamo, Unity, game assets' `UpperLeg_L`, CMU, Poser/DAZ, Axis/Perception Neuron, SlimeVR,
//! Xsens MVN's BVH, Sony mocopi, Rigify); every other joint keeps its name (CMU's `LHipJoint`,
//! Poser's `rButtock` stay, as a real file would have them). Then, renamed against original:
//! - (a) `inspect --json` gives the same parts (through the renaming);
//! - (b) `angles --json` the same angle names and values (1e-9 relative, NaN where NaN);
//! - (c) `convert` of the BVH onto mixamo (retargeting pairs parts) the same output; a capture
//!   simulated from the original (sensors on its part joints) and converted with `--root feet`
//!   onto the original and onto the renamed skeleton (the same sensors on the renamed bones) the
//!   same MOTION section, the same HIERARCHY but for the names, the same contacts;
//! - (d) `imubake live` of that capture onto either skeleton, VMC received by python-osc
//!   (tests/python/vmc_receive.py), the same Unity bones with the same values per frame (1e-6).
//!
//! A spine or neck longer than a scheme's numbers on (`Spine3`, `torso_4`). Every difference is
//! collected and the test fails once, listing them all; `IMUBAKE_KEEP_RENAMED=DIR` keeps the
//! renamed files (`DIR/<scheme>/<file>.bvh`) for `imubake inspect`.

use crate::common;

use common::{imubake_bin, python, repo_file, run, shared};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// Differences the lead has accepted for now: (skeleton, scheme, check) whose failures are
/// reported but do not fail the test. Empty: every case must agree.
// KNOWN: none.
const KNOWN: &[(&str, &str, &str)] = &[];

/// The naming schemes a skeleton is renamed into.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scheme {
    Mixamo,
    Unity,
    GameAsset,
    Cmu,
    Poser,
    Axis,
    SlimeVr,
    MvnBvh,
    Mocopi,
    Rigify,
}

const SCHEMES: [Scheme; 10] = [
    Scheme::Mixamo,
    Scheme::Unity,
    Scheme::GameAsset,
    Scheme::Cmu,
    Scheme::Poser,
    Scheme::Axis,
    Scheme::SlimeVr,
    Scheme::MvnBvh,
    Scheme::Mocopi,
    Scheme::Rigify,
];

/// The limb parts' keys in `inspect --json` (after `left_`/`right_`), from the body out.
const LIMBS: [&str; 8] = [
    "clavicle",
    "upper_arm",
    "forearm",
    "hand",
    "thigh",
    "shank",
    "foot",
    "toe",
];

impl Scheme {
    fn label(self) -> &'static str {
        match self {
            Scheme::Mixamo => "mixamo",
            Scheme::Unity => "unity",
            Scheme::GameAsset => "game_asset",
            Scheme::Cmu => "cmu",
            Scheme::Poser => "poser",
            Scheme::Axis => "axis",
            Scheme::SlimeVr => "slimevr",
            Scheme::MvnBvh => "mvn_bvh",
            Scheme::Mocopi => "mocopi",
            Scheme::Rigify => "rigify",
        }
    }

    fn pelvis(self) -> String {
        match self {
            Scheme::Poser => "hip",
            Scheme::SlimeVr => "Hip",
            Scheme::Mocopi => "root",
            Scheme::Rigify => "spine",
            _ => "Hips",
        }
        .to_string()
    }

    /// The `i`th spine joint from the pelvis up (the pelvis not counted); a chain longer than the
    /// scheme's numbers on.
    fn spine(self, i: usize) -> String {
        let listed = |names: &[&str], more: &dyn Fn(usize) -> String| {
            names.get(i).map_or_else(|| more(i), |s| s.to_string())
        };
        match self {
            Scheme::Mixamo | Scheme::Axis => listed(&["Spine"], &|i| format!("Spine{i}")),
            Scheme::Unity => listed(&["Spine", "Chest", "UpperChest"], &|i| format!("Chest{i}")),
            Scheme::GameAsset => format!("Spine_{:02}", i + 1),
            Scheme::Cmu => listed(&["LowerBack", "Spine"], &|i| format!("Spine{}", i - 1)),
            Scheme::Poser => listed(&["abdomen", "chest"], &|i| format!("chest{i}")),
            Scheme::SlimeVr => listed(&["Waist", "Chest", "UpperChest"], &|i| format!("Chest{i}")),
            Scheme::MvnBvh => listed(&["Chest"], &|i| format!("Chest{}", i + 1)),
            Scheme::Mocopi => format!("torso_{}", i + 1),
            Scheme::Rigify => format!("spine.{:03}", i + 1),
        }
    }

    /// The `i`th neck joint from the thorax up.
    fn neck(self, i: usize) -> String {
        match self {
            Scheme::GameAsset => format!("Neck_{:02}", i + 1),
            Scheme::Poser if i == 0 => "neck".into(),
            Scheme::Poser => format!("neck{i}"),
            Scheme::MvnBvh if i > 0 => format!("Neck{}", i + 1),
            Scheme::Mocopi => format!("neck_{}", i + 1),
            Scheme::Rigify if i == 0 => "neck".into(),
            Scheme::Rigify => format!("neck.{i:03}"),
            _ if i == 0 => "Neck".into(),
            _ => format!("Neck{i}"),
        }
    }

    fn head(self) -> String {
        match self {
            Scheme::Poser | Scheme::Mocopi | Scheme::Rigify => "head",
            _ => "Head",
        }
        .to_string()
    }

    /// A limb part (`left`/`right`, a key of [`LIMBS`]).
    fn limb(self, side: &str, limb: &str) -> String {
        let k = LIMBS.iter().position(|&l| l == limb).unwrap();
        let left = side == "left";
        let pick = |names: [&'static str; 8]| -> &'static str { names[k] };
        let (word, l, r) = match self {
            Scheme::Mixamo | Scheme::Cmu | Scheme::Axis => {
                let w = pick([
                    "Shoulder", "Arm", "ForeArm", "Hand", "UpLeg", "Leg", "Foot", "ToeBase",
                ]);
                return format!("{}{w}", if left { "Left" } else { "Right" });
            }
            Scheme::Unity => {
                let w = pick([
                    "Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot",
                    "Toes",
                ]);
                return format!("{}{w}", if left { "Left" } else { "Right" });
            }
            Scheme::GameAsset => (
                pick([
                    "Clavicle", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot",
                    "Toes",
                ]),
                "_L",
                "_R",
            ),
            Scheme::Poser => {
                let w = pick([
                    "Collar", "Shldr", "ForeArm", "Hand", "Thigh", "Shin", "Foot", "Toe",
                ]);
                return format!("{}{w}", if left { "l" } else { "r" });
            }
            // The legs as SlimeVR's own recordings name them (`Left-Foot` is the joint below
            // the ankle: the toes); the arms in the same style.
            Scheme::SlimeVr => {
                let w = pick([
                    "Shoulder",
                    "Upper-Arm",
                    "Elbow",
                    "Wrist",
                    "Hip",
                    "Knee",
                    "Ankle",
                    "Foot",
                ]);
                return format!("{}-{w}", if left { "Left" } else { "Right" });
            }
            Scheme::MvnBvh => {
                let w = pick([
                    "Collar", "Shoulder", "Elbow", "Wrist", "Hip", "Knee", "Ankle", "Toe",
                ]);
                return format!("{}{w}", if left { "Left" } else { "Right" });
            }
            Scheme::Mocopi => {
                let w = pick([
                    "shoulder", "up_arm", "low_arm", "hand", "up_leg", "low_leg", "foot", "toes",
                ]);
                return format!("{}_{w}", if left { "l" } else { "r" });
            }
            Scheme::Rigify => (
                pick([
                    "shoulder",
                    "upper_arm",
                    "forearm",
                    "hand",
                    "thigh",
                    "shin",
                    "foot",
                    "toe",
                ]),
                ".L",
                ".R",
            ),
        };
        format!("{word}{}", if left { l } else { r })
    }
}

fn imubake() -> Command {
    Command::new(imubake_bin())
}

/// Runs `cmd`: its output, or (when it fails) the command and the first lines it printed.
fn attempt(cmd: &mut Command) -> Result<std::process::Output, String> {
    let out = cmd.output().unwrap();
    if out.status.success() {
        return Ok(out);
    }
    let args: Vec<String> = cmd
        .get_args()
        .map(|a| {
            let a = a.to_string_lossy();
            // Temporary paths are long and say nothing.
            Path::new(&*a)
                .file_name()
                .map_or(a.to_string(), |f| f.to_string_lossy().into())
        })
        .collect();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let said: Vec<&str> = stderr
        .lines()
        .filter(|l| !l.trim().is_empty())
        .take(3)
        .collect();
    Err(format!(
        "`imubake {}` failed: {}",
        args.join(" "),
        said.join(" | ")
    ))
}

fn json_of(out: &std::process::Output) -> Value {
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)))
}

/// `imubake inspect FILE --json`'s parts: part id → its joints' names.
fn parts(bvh: &Path) -> Result<BTreeMap<String, Vec<String>>, String> {
    let v = json_of(&attempt(imubake().arg("inspect").arg(bvh).arg("--json"))?);
    Ok(v["parts"]
        .as_object()
        .unwrap_or_else(|| panic!("no parts in {v}"))
        .iter()
        .map(|(id, p)| {
            let joints = p["joints"]
                .as_array()
                .unwrap()
                .iter()
                .map(|j| j.as_str().unwrap().to_string())
                .collect();
            (id.clone(), joints)
        })
        .collect())
}

/// The renaming of a skeleton's part joints into `scheme`: old name → new name.
fn renaming(parts: &BTreeMap<String, Vec<String>>, scheme: Scheme) -> BTreeMap<String, String> {
    let mut map = BTreeMap::new();
    let mut add = |old: &str, new: String| {
        let prev = map.insert(old.to_string(), new);
        assert!(prev.is_none(), "{old} is two parts");
    };
    for (id, joints) in parts {
        for (i, j) in joints.iter().enumerate() {
            let new = match id.as_str() {
                "pelvis" => scheme.pelvis(),
                "spine" => scheme.spine(i),
                "neck" => scheme.neck(i),
                "head" => scheme.head(),
                limb => {
                    let (side, key) = limb.split_once('_').unwrap();
                    scheme.limb(side, key)
                }
            };
            add(j, new);
        }
    }
    map
}

/// The BVH text with its HIERARCHY's ROOT/JOINT names renamed by `map` (others kept).
fn rename_bvh(text: &str, map: &BTreeMap<String, String>) -> String {
    let mut out = String::with_capacity(text.len());
    let mut in_motion = false;
    for line in text.split_inclusive('\n') {
        let trimmed = line.trim_start();
        if trimmed.starts_with("MOTION") {
            in_motion = true;
        }
        if !in_motion && let Some(kw) = ["ROOT", "JOINT"].iter().find(|k| trimmed.starts_with(*k)) {
            let start = line.len() - trimmed.len() + kw.len();
            let name = line[start..].trim();
            if let Some(new) = map.get(name) {
                let at = start + line[start..].find(name).unwrap();
                out.push_str(&line[..at]);
                out.push_str(new);
                out.push_str(&line[at + name.len()..]);
                continue;
            }
        }
        out.push_str(line);
    }
    out
}

/// The ROOT/JOINT names of a BVH text, in order.
fn joint_names(text: &str) -> Vec<String> {
    text.lines()
        .take_while(|l| !l.trim_start().starts_with("MOTION"))
        .filter_map(|l| {
            let t = l.trim_start();
            ["ROOT", "JOINT"]
                .iter()
                .find(|k| t.starts_with(*k))
                .map(|k| t[k.len()..].trim().to_string())
        })
        .collect()
}

/// What goes wrong, for one skeleton.
struct Findings {
    skeleton: &'static str,
    list: Vec<(String, String, String)>,
}

impl Findings {
    fn add(&mut self, scheme: Scheme, check: &str, what: String) {
        eprintln!("{} × {} [{check}]: {what}", self.skeleton, scheme.label());
        self.list
            .push((scheme.label().to_string(), check.to_string(), what));
    }

    /// Fails on every finding not in [`KNOWN`].
    fn finish(self) {
        let unknown: Vec<String> = self
            .list
            .iter()
            .filter(|(scheme, check, _)| {
                !KNOWN
                    .iter()
                    .any(|(sk, sc, ch)| *sk == self.skeleton && sc == scheme && ch == check)
            })
            .map(|(scheme, check, what)| format!("{} × {scheme} [{check}]: {what}", self.skeleton))
            .collect();
        assert!(
            unknown.is_empty(),
            "{} difference(s):\n{}",
            unknown.len(),
            unknown.join("\n")
        );
    }
}

/// `angles --json`: name → values (NaN for null).
fn angles(bvh: &Path) -> Result<BTreeMap<String, Vec<f64>>, String> {
    let v = json_of(&attempt(imubake().arg("angles").arg(bvh).arg("--json"))?);
    Ok(v["angles"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, a)| {
            let values = a
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap_or(f64::NAN))
                .collect();
            (k.clone(), values)
        })
        .collect())
}

/// The first place two angle tables differ (names, lengths, a value beyond 1e-9 relative, NaN
/// on one side only).
fn angles_differ(a: &BTreeMap<String, Vec<f64>>, b: &BTreeMap<String, Vec<f64>>) -> Option<String> {
    if a.keys().ne(b.keys()) {
        let only_a: Vec<_> = a.keys().filter(|k| !b.contains_key(*k)).collect();
        let only_b: Vec<_> = b.keys().filter(|k| !a.contains_key(*k)).collect();
        return Some(format!(
            "angle names differ: only in the original {only_a:?}, only renamed {only_b:?}"
        ));
    }
    for (name, x) in a {
        let y = &b[name];
        if x.len() != y.len() {
            return Some(format!("{name}: {} vs {} frames", x.len(), y.len()));
        }
        for (f, (p, q)) in x.iter().zip(y).enumerate() {
            let same = if p.is_nan() || q.is_nan() {
                p.is_nan() && q.is_nan()
            } else {
                (p - q).abs() <= 1e-9 * p.abs().max(q.abs()).max(1e-3)
            };
            if !same {
                return Some(format!("{name} frame {f}: {p} vs {q}"));
            }
        }
    }
    None
}

/// A mapping of 17 sensors onto the part joints (the pelvis, the thorax, the head, each limb's
/// but the toes) under `names` (the original's names → this skeleton's).
fn mapping(parts: &BTreeMap<String, Vec<String>>, names: &dyn Fn(&str) -> String) -> String {
    let mut sensors = serde_json::Map::new();
    let mut put = |sensor: &str, joint: Option<&String>, extra: Option<(&str, &str)>| {
        if let Some(j) = joint {
            let mut s = serde_json::json!({"bone": names(j), "mount": "calibrate"});
            if let Some((k, v)) = extra {
                s[k] = v.into();
            }
            sensors.insert(sensor.into(), s);
        }
    };
    put("pelvis", parts["pelvis"].first(), Some(("forward", "-z")));
    put("sternum", parts["spine"].last(), None);
    put("head", parts["head"].first(), None);
    for side in ["left", "right"] {
        for limb in &LIMBS[..7] {
            let sensor = format!("{}_{limb}", &side[..1]);
            put(&sensor, parts[&format!("{side}_{limb}")].first(), None);
        }
    }
    serde_json::json!({
        "world": "enu",
        "calibration": {"pose": "rest", "start_s": 0.0, "duration_s": 2.0},
        "sensors": sensors,
    })
    .to_string()
}

/// A BVH split at `MOTION`.
fn split_motion(text: &str) -> (&str, &str) {
    let at = text.find("MOTION").expect("a MOTION section");
    text.split_at(at)
}

/// `convert CAPTURE --mapping M --rig RIG --root feet` into `out`: the output BVH's text and the
/// sidecar's contacts.
fn convert_feet(
    capture: &Path,
    mapping: &Path,
    rig: &Path,
    out: &Path,
) -> Result<(String, Value), String> {
    attempt(
        imubake()
            .arg("convert")
            .arg(capture)
            .arg("--mapping")
            .arg(mapping)
            .arg("--rig")
            .arg(rig)
            .args(["--root", "feet", "--fps", "60", "--format", "bvh", "--out"])
            .arg(out),
    )?;
    let stem = capture.file_stem().unwrap().to_string_lossy();
    let bvh = std::fs::read_to_string(out.join(format!("{stem}.bvh"))).unwrap();
    let sidecar: Value =
        serde_json::from_slice(&std::fs::read(out.join(format!("{stem}.imubake.json"))).unwrap())
            .unwrap();
    Ok((bvh, sidecar["contacts"].clone()))
}

/// `convert BVH --rig mixamo` (retargeting) into `out`: the output BVH's text.
fn retarget(bvh: &Path, out: &Path) -> Result<String, String> {
    attempt(
        imubake()
            .arg("convert")
            .arg(bvh)
            .args(["--rig", "mixamo", "--format", "bvh", "--out"])
            .arg(out),
    )?;
    Ok(std::fs::read_to_string(out.join(bvh.file_name().unwrap())).unwrap())
}

/// The VMC receiver (tests/python/vmc_receive.py) on a free port.
struct Receiver {
    child: Child,
    port: u16,
    out: PathBuf,
}

impl Receiver {
    fn start(py: &Path, out: PathBuf) -> Receiver {
        let mut child = Command::new(py)
            .arg(repo_file("tests/python/vmc_receive.py"))
            .arg(&out)
            .args(["--idle", "1", "--max", "60"])
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.as_mut().unwrap())
            .read_line(&mut line)
            .unwrap();
        Receiver {
            child,
            port: line.trim().parse().unwrap(),
            out,
        }
    }

    /// Ends it early (the session failed: nothing will come).
    fn stop(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    fn finish(mut self) -> Value {
        assert!(self.child.wait().unwrap().success());
        serde_json::from_slice(&std::fs::read(&self.out).unwrap()).unwrap()
    }
}

/// `imubake live` replaying the capture onto `rig`, VMC to python-osc: per frame time (in
/// 1/60 s), the root's and each Unity bone's values.
type Frames = BTreeMap<i64, (Option<Vec<f64>>, BTreeMap<String, Vec<f64>>)>;

fn live(
    py: &Path,
    capture: &Path,
    mapping: &Path,
    rig: &Path,
    dir: &Path,
) -> Result<Frames, String> {
    let receiver = Receiver::start(py, dir.join("vmc.json"));
    let session = attempt(
        imubake()
            .arg("live")
            .arg("--source")
            .arg(format!("file:{}@10", capture.display()))
            .arg("--mapping")
            .arg(mapping)
            .arg("--rig")
            .arg(rig)
            .args(["--root", "feet", "--listen", "off", "--vmc"])
            .arg(format!("127.0.0.1:{}", receiver.port)),
    );
    if let Err(e) = session {
        receiver.stop();
        return Err(e);
    }
    let vmc = receiver.finish();
    let floats = |v: &Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    Ok(vmc["bundles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| {
            let t = (b["t"].as_f64().unwrap() * 60.0).round() as i64;
            let root = (!b["root"].is_null()).then(|| floats(&b["root"]));
            let bones = b["bones"]
                .as_object()
                .unwrap()
                .iter()
                .map(|(k, v)| (k.clone(), floats(v)))
                .collect();
            (t, (root, bones))
        })
        .collect())
}

/// The first place two VMC streams differ.
fn vmc_differs(a: &Frames, b: &Frames) -> Option<String> {
    let common: Vec<&i64> = a.keys().filter(|t| b.contains_key(*t)).collect();
    if common.len() + 2 < a.len().max(b.len()) || common.len() < 60 {
        return Some(format!(
            "frames: {} original, {} renamed, {} in both",
            a.len(),
            b.len(),
            common.len()
        ));
    }
    let close = |x: &[f64], y: &[f64]| {
        x.len() == y.len() && x.iter().zip(y).all(|(p, q)| (p - q).abs() <= 1e-6)
    };
    for t in common {
        let ((ra, ba), (rb, bb)) = (&a[t], &b[t]);
        if ba.keys().ne(bb.keys()) {
            let ka: BTreeSet<_> = ba.keys().collect();
            let kb: BTreeSet<_> = bb.keys().collect();
            return Some(format!(
                "frame {t}: bones only in the original {:?}, only renamed {:?}",
                ka.difference(&kb).collect::<Vec<_>>(),
                kb.difference(&ka).collect::<Vec<_>>()
            ));
        }
        match (ra, rb) {
            (Some(x), Some(y)) if close(x, y) => {}
            (None, None) => {}
            _ => return Some(format!("frame {t}: root {ra:?} vs {rb:?}")),
        }
        for (bone, x) in ba {
            if !close(x, &bb[bone]) {
                return Some(format!("frame {t}: {bone} {x:?} vs {:?}", bb[bone]));
            }
        }
    }
    None
}

/// One skeleton in every scheme (the live sessions skipped where the test Python is missing).
fn skeleton(rel: &'static str) {
    let Some(original) = shared(rel) else { return };
    let py = python();
    let name = original.file_name().unwrap().to_owned();
    let mut findings = Findings {
        skeleton: Path::new(rel).file_stem().unwrap().to_str().unwrap(),
        list: Vec::new(),
    };
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(&original).unwrap();
    let original_parts = parts(&original).unwrap();
    let original_angles = angles(&original).unwrap();
    assert!(
        original_angles.len() == 48
            && original_angles
                .values()
                .all(|a| a.iter().any(|x| x.is_finite())),
        "{rel}: {:?}",
        original_angles.keys()
    );
    let original_retarget = retarget(&original, &dir.path().join("retarget")).unwrap();

    // (c)/(d): one capture from the original, sensors on its part joints.
    let capture = dir.path().join("take.csv");
    let m = dir.path().join("mapping.json");
    std::fs::write(&m, mapping(&original_parts, &|j| j.to_string())).unwrap();
    run(imubake()
        .arg("simulate")
        .arg(&original)
        .arg("--mapping")
        .arg(&m)
        .arg("--rig")
        .arg(&original)
        .args([
            "--frames",
            "0:240",
            "--noise-deg",
            "0.5",
            "--seed",
            "3",
            "--output",
        ])
        .arg(&capture));
    let (feet_bvh, contacts) =
        convert_feet(&capture, &m, &original, &dir.path().join("feet")).unwrap();
    // What the comparisons stand on: contacts on both feet, a VMC stream of every frame with the
    // body's bones (19 without a neck or toes).
    for side in ["left", "right"] {
        assert!(
            contacts[side].as_array().is_some_and(|c| !c.is_empty()),
            "{rel}: no {side} contacts: {contacts}"
        );
    }
    let vmc = py.as_ref().map(|py| {
        let vmc = live(py, &capture, &m, &original, dir.path()).unwrap();
        let bones = vmc.values().map(|(_, b)| b.len()).min().unwrap_or(0);
        eprintln!(
            "{rel}: {} VMC frames of {bones} bones; contacts {contacts}",
            vmc.len()
        );
        assert!(
            vmc.len() >= 200 && bones >= 19,
            "{rel}: {} frames, {bones} bones",
            vmc.len()
        );
        vmc
    });

    for scheme in SCHEMES {
        let map = renaming(&original_parts, scheme);
        let renamed_text = rename_bvh(&text, &map);
        let names = joint_names(&renamed_text);
        let unique: BTreeSet<&String> = names.iter().collect();
        assert_eq!(
            unique.len(),
            names.len(),
            "{scheme:?}: names repeat: {names:?}"
        );
        let sdir = dir.path().join(scheme.label());
        std::fs::create_dir_all(&sdir).unwrap();
        let renamed = sdir.join(&name);
        std::fs::write(&renamed, &renamed_text).unwrap();
        if let Some(keep) = std::env::var_os("IMUBAKE_KEEP_RENAMED") {
            let to = PathBuf::from(keep).join(scheme.label());
            std::fs::create_dir_all(&to).unwrap();
            std::fs::write(to.join(&name), &renamed_text).unwrap();
        }
        let new_name = |j: &str| map.get(j).cloned().unwrap_or_else(|| j.to_string());

        // (a) the same parts.
        let expected: BTreeMap<String, Vec<String>> = original_parts
            .iter()
            .map(|(id, js)| (id.clone(), js.iter().map(|j| new_name(j)).collect()))
            .collect();
        match parts(&renamed) {
            Err(e) => findings.add(scheme, "inspect", e),
            Ok(got) => {
                for (id, want) in &expected {
                    let have = got.get(id).cloned().unwrap_or_default();
                    if &have != want {
                        findings.add(
                            scheme,
                            "inspect",
                            format!("{id}: {have:?}, expected {want:?}"),
                        );
                    }
                }
            }
        }

        // (b) the same angles.
        match angles(&renamed) {
            Err(e) => findings.add(scheme, "angles", e),
            Ok(a) => {
                if let Some(d) = angles_differ(&original_angles, &a) {
                    findings.add(scheme, "angles", d);
                }
            }
        }

        // (c) retargeting onto mixamo: the same output.
        match retarget(&renamed, &sdir.join("retarget")) {
            Err(e) => findings.add(scheme, "retarget", e),
            Ok(r) if r != original_retarget => {
                let (ha, ma) = split_motion(&original_retarget);
                let (hb, mb) = split_motion(&r);
                findings.add(
                    scheme,
                    "retarget",
                    format!(
                        "convert --rig mixamo differs (hierarchy {}, motion {})",
                        if ha == hb { "same" } else { "differs" },
                        if ma == mb { "same" } else { "differs" }
                    ),
                );
            }
            Ok(_) => {}
        }

        // (c) root motion from the feet: the same frames and contacts.
        let m = sdir.join("mapping.json");
        std::fs::write(&m, mapping(&original_parts, &new_name)).unwrap();
        match convert_feet(&capture, &m, &renamed, &sdir.join("feet")) {
            Err(e) => findings.add(scheme, "root feet", e),
            Ok((bvh, c)) => {
                let (h0, m0) = split_motion(&feet_bvh);
                let (h1, m1) = split_motion(&bvh);
                if m0 != m1 {
                    let line = m0
                        .lines()
                        .zip(m1.lines())
                        .position(|(a, b)| a != b)
                        .unwrap_or(0);
                    findings.add(
                        scheme,
                        "root feet",
                        format!("MOTION differs from its line {line}"),
                    );
                }
                if rename_bvh(h0, &map) != h1 {
                    findings.add(scheme, "root feet", "HIERARCHY differs".into());
                }
                if c != contacts {
                    findings.add(scheme, "root feet", format!("contacts {c} vs {contacts}"));
                }
            }
        }

        // (d) live: the same VMC stream.
        let (Some(py), Some(vmc)) = (&py, &vmc) else {
            continue;
        };
        match live(py, &capture, &m, &renamed, &sdir) {
            Err(e) => findings.add(scheme, "live", e),
            Ok(v) => {
                if let Some(d) = vmc_differs(vmc, &v) {
                    findings.add(scheme, "live", d);
                }
            }
        }
    }
    findings.finish();
}

#[test]
fn cmu_01_01_in_every_scheme() {
    skeleton("bvh/cmu_01_01.bvh");
}

#[test]
fn cmu_03_02_poser_names_in_every_scheme() {
    skeleton("bvh/cmu_03_02_uneven_terrain.bvh");
}

#[test]
fn pymo_walk_in_every_scheme() {
    skeleton("bvh/pymo_walk.bvh");
}

#[test]
fn mixamo_export_in_every_scheme() {
    skeleton("bvh/mixamo_rig_freebvh.bvh");
}
