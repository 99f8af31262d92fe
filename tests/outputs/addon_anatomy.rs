//! The Blender add-on's `names.py` resolves a skeleton's body parts exactly as imubake does
//! (`src/rig/anatomy.rs`, `src/rig/names.rs`). For every BVH in `../shared/data/bvh/` and every
//! built-in rig (`rigs/*.yaml`, written out as a BVH hierarchy), the parts `imubake inspect
//! --json` prints — pelvis, spine chain, neck chain, head and each side's limb parts, with how each
//! was found — must equal those of `names.resolve` on the same hierarchy (names, parents, rest
//! positions from the offsets, End Sites), parsed from the same file by a small Python driver.
//!
//! Each skeleton is also checked with its resolved parts renamed into other schemes (Unity,
//! `UpperLeg_L`, Poser's `lThigh`, MVN's `LeftHip`/`LeftKnee` with `LeftShoulder` the upper arm,
//! mocopi's `l_up_leg`, SlimeVR's `Left-Hip`) and with every joint renamed `j0`, `j1`, … so that
//! only the shape decides. The assertion is Rust = Python on each variant, not that a variant
//! resolves as its original. Skips locally without the test Python or ../shared/data; fails
//! under CI=true.

use crate::common;

use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Reads BVH hierarchies (paths in argv[2:]) and prints `[names.resolve(...).to_json(), ...]`.
const DRIVER: &str = r#"
import json, sys
sys.path.insert(0, sys.argv[1])
import names

def parse(path):
    joint_names, parents, offsets, ends = [], [], [], []
    stack, pending = [], None
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            tok = line.split()
            if not tok:
                continue
            k = tok[0]
            if k == "MOTION":
                break
            if k in ("ROOT", "JOINT"):
                joint = next((x for kind, x in reversed(stack) if kind == "joint"), None)
                joint_names.append(line.strip()[len(k):].strip())
                parents.append(joint)
                offsets.append((0.0, 0.0, 0.0))
                ends.append(None)
                pending = ("joint", len(joint_names) - 1)
            elif k == "End":
                pending = ("end", stack[-1][1])
            elif k == "{":
                stack.append(pending)
            elif k == "}":
                stack.pop()
            elif k == "OFFSET":
                v = tuple(float(x) for x in tok[1:4])
                kind, j = stack[-1]
                if kind == "joint":
                    offsets[j] = v
                else:
                    ends[j] = v
    rest = []
    for j, p in enumerate(parents):
        if p is None:
            rest.append(offsets[0])
        else:
            r, o = rest[p], offsets[j]
            rest.append((r[0] + o[0], r[1] + o[1], r[2] + o[2]))
    return joint_names, parents, rest, ends

out = []
for path in sys.argv[2:]:
    n, p, r, e = parse(path)
    out.append(names.resolve(n, p, r, e, skeleton=path).to_json())
print(json.dumps(out))
"#;

/// A skeleton to check: its label and its BVH file.
struct Case {
    label: String,
    bvh: PathBuf,
}

/// The BVH's hierarchy with its joints renamed (`rename[i]` for the i-th `ROOT`/`JOINT`, `None`
/// keeps it) and one frame of zero motion.
fn rewrite(text: &str, rename: &dyn Fn(usize, &str) -> Option<String>) -> String {
    let mut out = String::new();
    let mut channels = 0usize;
    let mut joint = 0usize;
    for line in text.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("MOTION") {
            break;
        }
        let keyword = ["ROOT", "JOINT"].into_iter().find(|k| {
            trimmed
                .strip_prefix(k)
                .is_some_and(|r| r.starts_with([' ', '\t']))
        });
        if let Some(k) = keyword {
            let name = trimmed[k.len()..].trim();
            let indent = &line[..line.len() - trimmed.len()];
            let new = rename(joint, name).unwrap_or_else(|| name.to_string());
            writeln!(out, "{indent}{k} {new}").unwrap();
            joint += 1;
            continue;
        }
        if let Some(rest) = trimmed.strip_prefix("CHANNELS") {
            channels += rest
                .split_whitespace()
                .next()
                .and_then(|n| n.parse::<usize>().ok())
                .unwrap_or(0);
        }
        writeln!(out, "{}", line.trim_end()).unwrap();
    }
    let zeros = vec!["0"; channels].join(" ");
    write!(out, "MOTION\nFrames: 1\nFrame Time: 0.033333\n{zeros}\n").unwrap();
    out
}

/// A built-in rig's YAML as a BVH hierarchy (offsets and End Sites as declared).
fn rig_to_bvh(yaml: &Path) -> String {
    let rig: serde_yaml::Value = serde_yaml::from_str(&std::fs::read_to_string(yaml).unwrap())
        .unwrap_or_else(|e| panic!("{}: {e}", yaml.display()));
    let joints = rig["joints"].as_sequence().expect("joints");
    let name = |j: &serde_yaml::Value| j["name"].as_str().unwrap().to_string();
    let vec3 = |v: &serde_yaml::Value| -> String {
        v.as_sequence()
            .unwrap()
            .iter()
            .map(|x| format!("{:.6}", x.as_f64().unwrap()))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut children: BTreeMap<Option<String>, Vec<usize>> = BTreeMap::new();
    for (i, j) in joints.iter().enumerate() {
        let parent = j["parent"].as_str().map(str::to_string);
        children.entry(parent).or_default().push(i);
    }
    fn write(
        out: &mut String,
        i: usize,
        depth: usize,
        joints: &[serde_yaml::Value],
        children: &BTreeMap<Option<String>, Vec<usize>>,
        name: &dyn Fn(&serde_yaml::Value) -> String,
        vec3: &dyn Fn(&serde_yaml::Value) -> String,
    ) {
        let pad = "  ".repeat(depth);
        let j = &joints[i];
        let (kw, ch) = if depth == 0 {
            (
                "ROOT",
                "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation",
            )
        } else {
            ("JOINT", "CHANNELS 3 Zrotation Yrotation Xrotation")
        };
        writeln!(out, "{pad}{kw} {}\n{pad}{{", name(j)).unwrap();
        writeln!(out, "{pad}  OFFSET {}\n{pad}  {ch}", vec3(&j["offset"])).unwrap();
        for &c in children.get(&Some(name(j))).into_iter().flatten() {
            write(out, c, depth + 1, joints, children, name, vec3);
        }
        if !j["end_site"].is_null() {
            let e = vec3(&j["end_site"]);
            writeln!(
                out,
                "{pad}  End Site\n{pad}  {{\n{pad}    OFFSET {e}\n{pad}  }}"
            )
            .unwrap();
        }
        writeln!(out, "{pad}}}").unwrap();
    }
    let mut out = String::from("HIERARCHY\n");
    for &root in children.get(&None).into_iter().flatten() {
        write(&mut out, root, 0, joints, &children, &name, &vec3);
    }
    out.push_str("MOTION\n");
    out
}

/// The name a scheme gives the `i`-th of `n` joints of a part (`pelvis`, `spine`, `neck`,
/// `head`, `left_upper_arm`, …).
fn scheme_name(scheme: &str, part: &str, i: usize, n: usize) -> String {
    let k = i + 1;
    let (side, limb) = match part.split_once('_') {
        Some((s @ ("left" | "right"), l)) => (Some(s == "left"), l),
        _ => (None, part),
    };
    match (scheme, side) {
        ("unity", None) => match part {
            "pelvis" => "Hips".into(),
            "spine" => ["Spine", "Chest", "UpperChest"]
                .get(i)
                .map_or(format!("Chest{k}"), |s| s.to_string()),
            "neck" if i == 0 => "Neck".into(),
            "neck" => format!("Neck{k}"),
            _ => "Head".into(),
        },
        ("game", None) => match part {
            "pelvis" => "Pelvis".into(),
            "spine" => format!("Spine_{k:02}"),
            "neck" => format!("Neck_{k:02}"),
            _ => "Head".into(),
        },
        ("poser", None) => match part {
            "pelvis" => "hip".into(),
            "spine" if i + 1 == n => "chest".into(),
            "spine" if i == 0 => "abdomen".into(),
            "spine" => format!("abdomen{k}"),
            "neck" if i == 0 => "neck".into(),
            "neck" => format!("neck{k}"),
            _ => "head".into(),
        },
        ("mvn", None) => match part {
            "pelvis" => "Pelvis".into(),
            "spine" if i == 0 => "Chest".into(),
            "spine" => format!("Chest{k}"),
            "neck" if i == 0 => "Neck".into(),
            "neck" => format!("Neck{k}"),
            _ => "Head".into(),
        },
        ("mocopi", None) => match part {
            "pelvis" => "root".into(),
            "spine" => format!("torso_{k}"),
            "neck" => format!("neck_{k}"),
            _ => "head".into(),
        },
        ("slimevr", None) => match part {
            "pelvis" => "Hip".into(),
            "spine" if i == 0 => "Waist".into(),
            "spine" => format!("Chest{i}"),
            "neck" if i == 0 => "Neck".into(),
            "neck" => format!("Neck{k}"),
            _ => "Head".into(),
        },
        (_, Some(left)) => {
            let (word, letter) = if left { ("Left", "l") } else { ("Right", "r") };
            let index = [
                "clavicle",
                "upper_arm",
                "forearm",
                "hand",
                "thigh",
                "shank",
                "foot",
                "toe",
            ]
            .iter()
            .position(|l| *l == limb)
            .unwrap();
            let words: [&str; 8] = match scheme {
                "unity" => [
                    "Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot",
                    "Toes",
                ],
                "game" => [
                    "Clavicle", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot",
                    "Ball",
                ],
                "poser" => [
                    "Collar", "Shldr", "ForeArm", "Hand", "Thigh", "Shin", "Foot", "Toe",
                ],
                "mvn" => [
                    "Collar", "Shoulder", "Elbow", "Wrist", "Hip", "Knee", "Ankle", "Toe",
                ],
                "mocopi" => [
                    "shoulder", "up_arm", "low_arm", "hand", "up_leg", "low_leg", "foot", "toes",
                ],
                "slimevr" => [
                    "Shoulder",
                    "Upper-Arm",
                    "Lower-Arm",
                    "Hand",
                    "Hip",
                    "Knee",
                    "Ankle",
                    "Toe",
                ],
                _ => unreachable!(),
            };
            let w = words[index];
            match scheme {
                "unity" | "mvn" => format!("{word}{w}"),
                "game" => format!("{w}_{}", letter.to_uppercase()),
                "poser" => format!("{letter}{w}"),
                "mocopi" => format!("{letter}_{w}"),
                "slimevr" => format!("{word}-{w}"),
                _ => unreachable!(),
            }
        }
        _ => unreachable!("{scheme}"),
    }
}

const SCHEMES: [&str; 6] = ["unity", "game", "poser", "mvn", "mocopi", "slimevr"];

#[test]
fn the_addon_resolves_every_skeleton_as_imubake_does() {
    let Some(python) = common::python() else {
        return;
    };
    let Some(bvh_dir) = common::shared("bvh") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // The originals: the shared BVHs and the built-in rigs.
    let mut originals: Vec<Case> = Vec::new();
    let mut files: Vec<PathBuf> = std::fs::read_dir(&bvh_dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    files.sort();
    assert!(files.len() >= 5, "too few BVHs in {}", bvh_dir.display());
    for f in files {
        let label = f.file_stem().unwrap().to_string_lossy().into_owned();
        originals.push(Case { label, bvh: f });
    }
    let mut rigs: Vec<PathBuf> = std::fs::read_dir(common::repo_file("rigs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml"))
        .collect();
    rigs.sort();
    assert!(!rigs.is_empty());
    for rig in &rigs {
        let label = format!("rig {}", rig.file_stem().unwrap().to_string_lossy());
        let bvh = dir.path().join(format!(
            "{}.bvh",
            rig.file_stem().unwrap().to_string_lossy()
        ));
        std::fs::write(&bvh, rig_to_bvh(rig)).unwrap();
        // The written hierarchy resolves as the rig itself.
        let from_rig = common::inspect_json(rig);
        let written = rewrite(&std::fs::read_to_string(&bvh).unwrap(), &|_, _| None);
        std::fs::write(&bvh, written).unwrap();
        assert_eq!(
            common::inspect_json(&bvh)["parts"],
            from_rig["parts"],
            "{label}: its BVH resolves otherwise"
        );
        originals.push(Case { label, bvh });
    }

    // The variants: the resolved parts renamed into each scheme, and every name stripped.
    let mut cases: Vec<Case> = Vec::new();
    for (n, case) in originals.into_iter().enumerate() {
        let parts = common::inspect_json(&case.bvh)["parts"].clone();
        let text = std::fs::read_to_string(&case.bvh).unwrap();
        let mut part_of: BTreeMap<String, (String, usize, usize)> = BTreeMap::new();
        for (part, v) in parts.as_object().unwrap() {
            let joints = common::strings(&v["joints"]);
            for (i, j) in joints.iter().enumerate() {
                part_of.insert(j.to_string(), (part.clone(), i, joints.len()));
            }
        }
        for scheme in SCHEMES {
            let renamed = rewrite(&text, &|_, name| {
                part_of
                    .get(name)
                    .map(|(part, i, len)| scheme_name(scheme, part, *i, *len))
            });
            let bvh = dir.path().join(format!("{n}_{scheme}.bvh"));
            std::fs::write(&bvh, renamed).unwrap();
            cases.push(Case {
                label: format!("{} as {scheme}", case.label),
                bvh,
            });
        }
        let stripped = rewrite(&text, &|i, _| Some(format!("j{i}")));
        let bvh = dir.path().join(format!("{n}_stripped.bvh"));
        std::fs::write(&bvh, stripped).unwrap();
        cases.push(Case {
            label: format!("{} without names", case.label),
            bvh,
        });
        cases.insert(0, case);
    }

    let out = common::run(
        Command::new(&python)
            .arg("-c")
            .arg(DRIVER)
            .arg(common::repo_file("blender_addon"))
            .args(cases.iter().map(|c| &c.bvh)),
    );
    assert!(
        out.status.success(),
        "the Python driver failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let python_parts: Vec<Value> = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(python_parts.len(), cases.len());
    let mut differ = Vec::new();
    let mut found_by = BTreeMap::new();
    for (case, py) in cases.iter().zip(&python_parts) {
        let rust = common::inspect_json(&case.bvh);
        if rust["parts"] != py["parts"] {
            let mut lines = vec![format!("{} ({}):", case.label, case.bvh.display())];
            for (part, r) in rust["parts"].as_object().unwrap() {
                let p = &py["parts"][part];
                if r != p {
                    lines.push(format!("  {part}: imubake {r}, names.py {p}"));
                }
            }
            differ.push(lines.join("\n"));
        }
        for v in rust["parts"].as_object().unwrap().values() {
            let how = v["found"].as_str().unwrap_or("none").to_string();
            *found_by.entry(how).or_insert(0usize) += 1;
        }
    }
    println!(
        "{} skeletons checked; parts found by: {found_by:?}",
        cases.len()
    );
    assert!(
        differ.is_empty(),
        "names.py resolves {} of {} skeletons otherwise than imubake:\n{}",
        differ.len(),
        cases.len(),
        differ.join("\n")
    );
    // Each way of finding a part was exercised.
    for how in ["named", "shape"] {
        assert!(found_by.get(how).is_some_and(|&n| n > 0), "no part {how}");
    }
}
