//! Godot imports what `--engine godot` writes (issue 52): the bundled walk converted plain,
//! `--in-place`, `--bind-frame`, at 60 fps, at 29.97 fps and as `.gltf`, each with the `.import`
//! imubake wrote, imported headless by Godot 3 (`godot3-server --export-pack`, which imports a project's
//! files and exits) and read back by tests/godot/inspect_takes.gd: the animation's length, each
//! track's keys, the skeleton's bone names and every bone's world position at the take's frame
//! times. Positions are checked against an independent forward kinematics of the GLB
//! (tests/python/glb_positions.py, numpy), names against the sidecar's `engine.bone_names`. The
//! Blender add-on's batch export (`--format glb --engine godot`) of the plain take is imported the
//! same way.

use crate::common;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

const PROJECT: &str = "config_version=4\n\n[application]\n\nconfig/name=\"imubake-godot-test\"\n";

/// The minimal export preset `--export-pack` needs: it imports every file of the project, packs
/// them and exits (`--editor --quit` does not exit in Godot 3.2).
const EXPORT_PRESETS: &str = "[preset.0]\n\nname=\"Linux/X11\"\nplatform=\"Linux/X11\"\n\
runnable=true\ncustom_features=\"\"\nexport_filter=\"all_resources\"\ninclude_filter=\"\"\n\
exclude_filter=\"\"\nexport_path=\"\"\nscript_export_mode=1\nscript_encryption_key=\"\"\n\n\
[preset.0.options]\n";

/// One conversion of the walk into its own folder of the project.
struct Variant {
    dir: &'static str,
    /// `glb` or `gltf`.
    format: &'static str,
    args: &'static [&'static str],
    /// `--engine godot`; without it Godot imports with its own defaults.
    engine: bool,
}

const VARIANTS: [Variant; 7] = [
    Variant {
        dir: "plain",
        format: "glb",
        args: &[],
        engine: true,
    },
    Variant {
        dir: "in_place",
        format: "glb",
        args: &["--in-place"],
        engine: true,
    },
    Variant {
        dir: "bind_frame",
        format: "glb",
        args: &["--bind-frame"],
        engine: true,
    },
    Variant {
        dir: "fps60",
        format: "glb",
        args: &["--fps", "60"],
        engine: true,
    },
    Variant {
        dir: "ntsc",
        format: "glb",
        args: &["--fps", "29.97"],
        engine: true,
    },
    Variant {
        dir: "gltf",
        format: "gltf",
        args: &[],
        engine: true,
    },
    Variant {
        dir: "godot_defaults",
        format: "glb",
        args: &[],
        engine: false,
    },
];

/// Node names Godot rewrites in different ways, given to the walk's joints in a copy of its GLB.
const TRICKY_NAMES: [(&str, &str); 12] = [
    ("Hips", "mixamorig:Hips"),
    ("Spine", "Spine01"),
    ("Spine1", "HTTPServer"),
    ("Spine2", "Bip01 Spine2"),
    ("Neck", "Toe2Tip"),
    ("Head", "head_100"),
    ("LeftShoulder", "L/Shoulder"),
    ("LeftArm", "ÄrmL"),
    ("RightArm", "thigh_l"),
    ("RightShoulder", "thigh.L"),
    ("RightForeArm", "a:b"),
    ("RightHand", "x-y Hand"),
];

fn run(cmd: &mut Command, what: &str) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot run: {e}"));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// Godot headless in `project`, stopped after 300 s if it hangs.
fn godot(godot: &Path, project: &Path, args: &[&str], what: &str) {
    run(
        Command::new("timeout")
            .arg("300")
            .arg(godot)
            .arg("--path")
            .arg(project)
            .args(args),
        what,
    );
}

fn frame_times(sidecar: &Value) -> Vec<f64> {
    let (num, den) = (
        sidecar["fps"]["num"].as_u64().unwrap(),
        sidecar["fps"]["den"].as_u64().unwrap(),
    );
    let frames = sidecar["frames"].as_u64().unwrap();
    (0..frames).map(|n| (n * den) as f64 / num as f64).collect()
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The largest and the median distance (metres) between Godot's bone positions and the GLB's
/// own forward kinematics, over every bone and time; `names` maps Godot's bone names back to the
/// GLB's node names.
fn position_errors(
    godot_take: &Value,
    fk: &Value,
    names: &dyn Fn(&str) -> String,
) -> (f64, f64, String) {
    let bones = common::strings(&godot_take["bones"]);
    let mut errors = Vec::new();
    let mut worst = (0.0, String::new());
    for (t, frame) in godot_take["positions"]
        .as_array()
        .unwrap()
        .iter()
        .enumerate()
    {
        for (b, bone) in bones.iter().enumerate() {
            let node = names(bone);
            let expected = common::vec3(&fk["nodes"][&node][t]);
            let e = (common::vec3(&frame[b]) - expected).norm();
            if e > worst.0 {
                worst = (e, format!("{bone} at time index {t}"));
            }
            errors.push(e);
        }
    }
    errors.sort_by(f64::total_cmp);
    (worst.0, errors[errors.len() / 2], worst.1)
}

#[test]
fn godot_imports_each_take_at_its_rate_with_the_sidecars_bone_names() {
    let Some(godot_bin) = common::godot() else {
        return;
    };
    let Some(py) = common::python() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let project = tmp.path().join("project");
    std::fs::create_dir_all(&project).unwrap();
    std::fs::write(project.join("project.godot"), PROJECT).unwrap();
    std::fs::write(project.join("export_presets.cfg"), EXPORT_PRESETS).unwrap();
    std::fs::copy(
        common::repo_file("tests/godot/inspect_takes.gd"),
        project.join("inspect_takes.gd"),
    )
    .unwrap();

    let mut sidecars = Vec::new();
    for v in &VARIANTS {
        let mut cmd = Command::new(common::imubake_bin());
        cmd.arg("convert")
            .arg(common::repo_file("samples/walk.csv"))
            .arg("--mapping")
            .arg(common::repo_file("mappings/paper000_16imu_mixamo.json"))
            .args(["--format", v.format, "--out"])
            .arg(project.join(v.dir))
            .args(v.args);
        if v.engine {
            cmd.args(["--engine", "godot"]);
        }
        run(&mut cmd, &format!("imubake convert ({})", v.dir));
        let sidecar = read_json(&project.join(v.dir).join("walk.imubake.json"));
        let import = project
            .join(v.dir)
            .join(format!("walk.{}.import", v.format));
        assert_eq!(import.is_file(), v.engine, "{}", import.display());
        sidecars.push(sidecar);
    }
    // The same take with joints renamed the ways Godot rewrites names, and imubake's import file.
    let names = tmp.path().join("names.json");
    let tricky: serde_json::Map<String, Value> = TRICKY_NAMES
        .iter()
        .map(|(from, to)| (from.to_string(), Value::from(*to)))
        .collect();
    std::fs::write(&names, Value::Object(tricky).to_string()).unwrap();
    std::fs::create_dir_all(project.join("names")).unwrap();
    run(
        Command::new(&py)
            .arg(common::repo_file("tests/python/glb_positions.py"))
            .arg("rename")
            .arg(project.join("plain/walk.glb"))
            .arg(project.join("names/walk.glb"))
            .arg(&names),
        "glb_positions.py rename",
    );
    std::fs::copy(
        project.join("plain/walk.glb.import"),
        project.join("names/walk.glb.import"),
    )
    .unwrap();

    // The add-on's batch export of the plain take, with the import file it writes.
    run(
        Command::new(&py)
            .arg(common::repo_file("blender_addon/batch_export.py"))
            .arg(project.join("plain"))
            .arg(project.join("blender"))
            .args(["--format", "glb", "--engine", "godot"]),
        "blender_addon/batch_export.py --format glb --engine godot",
    );
    assert_eq!(
        std::fs::read_to_string(project.join("blender/walk.glb.import")).unwrap(),
        std::fs::read_to_string(project.join("plain/walk.glb.import")).unwrap(),
        "the add-on writes the import file imubake writes"
    );

    let request: Vec<Value> = VARIANTS
        .iter()
        .map(|v| format!("{}/walk.{}", v.dir, v.format))
        .chain(["names/walk.glb".into(), "blender/walk.glb".into()])
        .zip(sidecars.iter().chain([&sidecars[0], &sidecars[0]]))
        .map(|(file, sidecar)| {
            serde_json::json!({"file": format!("res://{file}"), "times": frame_times(sidecar)})
        })
        .collect();
    std::fs::write(
        project.join("request.json"),
        serde_json::json!({ "takes": request }).to_string(),
    )
    .unwrap();
    godot(
        &godot_bin,
        &project,
        &["--export-pack", "Linux/X11", "imported.pck"],
        "Godot's import (--export-pack)",
    );
    godot(
        &godot_bin,
        &project,
        &["-s", "inspect_takes.gd"],
        "tests/godot/inspect_takes.gd",
    );
    let result = read_json(&project.join("result.json"));
    let godot_version = result["engine"].as_str().unwrap_or("?");
    assert!(godot_version.starts_with("3."), "{godot_version}");
    let takes = result["takes"].as_array().unwrap();

    for (i, v) in VARIANTS.iter().enumerate() {
        let (take, sidecar) = (&takes[i], &sidecars[i]);
        assert!(take["error"].is_null(), "{}: {}", v.dir, take["error"]);
        let label = format!("{} (Godot {godot_version})", v.dir);
        let frames = sidecar["frames"].as_u64().unwrap();
        let duration = sidecar["duration_s"].as_f64().unwrap();
        // The length is the last key's time, stored as a 32-bit float.
        let length = take["length"].as_f64().unwrap();
        assert!(
            (length - duration).abs() < 2e-5,
            "{label}: length {length} s, sidecar {duration} s"
        );
        assert_eq!(common::strings(&take["animations"]), ["walk"], "{label}");

        let times = tmp.path().join(format!("{}.times.json", v.dir));
        std::fs::write(&times, Value::from(frame_times(sidecar)).to_string()).unwrap();
        let fk: Value = serde_json::from_str(&run(
            Command::new(&py)
                .arg(common::repo_file("tests/python/glb_positions.py"))
                .arg("positions")
                .arg(project.join(v.dir).join(format!("walk.{}", v.format)))
                .arg(&times),
            "glb_positions.py positions",
        ))
        .unwrap();
        let keys: Vec<u64> = take["tracks"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| t["keys"].as_u64().unwrap())
            .collect();
        assert!(!keys.is_empty(), "{label}: no tracks");

        if !v.engine {
            // Godot's own defaults: re-baked at 15 fps, then thinned by the optimizer — at most
            // half the keys, and bones off the take between them (the trap the import file
            // avoids). The GLB's joints keep their names here (no renaming test).
            let at_15 = (length * 15.0).ceil() as u64 + 1;
            assert!(keys.iter().all(|&k| k <= at_15), "{label}: {keys:?}");
            assert!(at_15 < frames, "{label}");
            let same = |godot: &str| {
                let plain = sidecars[0]["engine"]["bone_names"].as_object().unwrap();
                let joint = plain.iter().find(|(_, g)| g.as_str() == Some(godot));
                joint.map(|(j, _)| j.clone()).unwrap()
            };
            let (max, median, at) = position_errors(take, &fk, &same);
            eprintln!(
                "{label}: Godot's defaults, at the take's frame times: max {:.2} mm ({at}), median {:.2} mm",
                max * 1e3,
                median * 1e3
            );
            assert!(max > 1e-3, "{label}: {max} m");
            continue;
        }
        // The sidecar's names are Godot's: one bone per joint, each named as recorded.
        let recorded = sidecar["engine"]["bone_names"].as_object().unwrap();
        let mut godot_names: Vec<&str> = common::strings(&take["bones"]);
        let mut sidecar_names: Vec<&str> = recorded.values().map(|n| n.as_str().unwrap()).collect();
        godot_names.sort();
        sidecar_names.sort();
        assert_eq!(godot_names, sidecar_names, "{label}: bone names");
        assert_eq!(
            sidecar["engine"]["import_files"],
            serde_json::json!([format!("walk.{}.import", v.format)])
        );
        let back = |godot: &str| -> String {
            recorded
                .iter()
                .find(|(_, g)| g.as_str() == Some(godot))
                .map(|(joint, _)| joint.clone())
                .unwrap_or_else(|| panic!("{label}: Godot's bone `{godot}` is in no record"))
        };
        let (max, median, at) = position_errors(take, &fk, &back);
        let whole = sidecar["fps"]["den"].as_u64() == Some(1);
        let bake = sidecar["engine"]["bake_fps"].as_u64().unwrap();
        if whole {
            assert_eq!(bake, sidecar["fps"]["num"].as_u64().unwrap(), "{label}");
            // One key per frame of the take, on the frames' times.
            assert!(
                keys.iter().all(|&k| k == frames),
                "{label}: {keys:?} keys, {frames} frames"
            );
            for t in take["tracks"].as_array().unwrap() {
                for (n, time) in t["first_times"].as_array().unwrap().iter().enumerate() {
                    let expected = n as f64 / bake as f64;
                    assert!(
                        (time.as_f64().unwrap() - expected).abs() < 1e-5,
                        "{label}: {t}"
                    );
                }
            }
            eprintln!(
                "{label}: {frames} keys per track; bones at most {:.1e} m from the GLB's own",
                max
            );
            assert!(
                max < 1e-4,
                "{label}: a bone {max} m from the GLB's own position ({at})"
            );
        } else {
            // 29.97 fps baked at 30: keys no longer on the frames; Godot interpolates between
            // its own keys, each itself interpolated between two frames.
            assert_eq!(bake, 30, "{label}");
            assert!(
                keys.iter().all(|&k| k == (length * 30.0).ceil() as u64 + 1),
                "{label}: {keys:?}"
            );
            eprintln!(
                "{label}: Godot's re-bake at 30 fps, at the take's frame times: max {:.2} mm ({at}), median {:.2} mm",
                max * 1e3,
                median * 1e3
            );
            // README, "A take into Godot": measured 17.6 mm max, 1.1 mm median (Godot 3.2.3).
            assert!(
                max < 0.025 && median < 0.002,
                "{label}: {max} m, {median} m"
            );
        }
    }

    // Blender's GLB of the plain take: one key per frame, the bones where its own keys put them,
    // named as imubake's sidecar says.
    let take = &takes[VARIANTS.len() + 1];
    let plain = &sidecars[0];
    let frames = plain["frames"].as_u64().unwrap();
    assert!(
        (take["length"].as_f64().unwrap() - plain["duration_s"].as_f64().unwrap()).abs() < 2e-5,
        "blender: {}",
        take["length"]
    );
    for t in take["tracks"].as_array().unwrap() {
        assert_eq!(t["keys"].as_u64(), Some(frames), "blender: {t}");
    }
    let times = tmp.path().join("blender.times.json");
    std::fs::write(&times, Value::from(frame_times(plain)).to_string()).unwrap();
    let fk: Value = serde_json::from_str(&run(
        Command::new(&py)
            .arg(common::repo_file("tests/python/glb_positions.py"))
            .arg("positions")
            .arg(project.join("blender/walk.glb"))
            .arg(&times),
        "glb_positions.py positions (blender)",
    ))
    .unwrap();
    let recorded = plain["engine"]["bone_names"].as_object().unwrap();
    let back = |godot: &str| {
        let joint = recorded.iter().find(|(_, g)| g.as_str() == Some(godot));
        joint
            .map(|(j, _)| j.clone())
            .unwrap_or_else(|| panic!("blender: Godot's bone `{godot}` is in no record"))
    };
    let (max, _, at) = position_errors(take, &fk, &back);
    assert!(max < 1e-4, "blender: {max} m ({at})");

    // Every name rewrite Godot makes, as imubake predicts it.
    let take = &takes[VARIANTS.len()];
    let renamed = |joint: &str| {
        TRICKY_NAMES
            .iter()
            .find(|(from, _)| *from == joint)
            .map_or(joint, |(_, to)| to)
            .to_string()
    };
    let plain = sidecars[0]["engine"]["bone_names"].as_object().unwrap();
    let nodes: Vec<String> = plain.keys().map(|j| renamed(j)).collect();
    let mut expected = imubake::write::godot::bone_names(nodes.iter().map(String::as_str));
    let mut got: Vec<String> = common::strings(&take["bones"])
        .into_iter()
        .map(str::to_string)
        .collect();
    expected.sort();
    got.sort();
    assert_eq!(got, expected, "Godot's bone names for {TRICKY_NAMES:?}");
}

#[test]
fn an_engine_without_a_gltf_output_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(common::imubake_bin())
        .arg("convert")
        .arg(common::repo_file("samples/walk.csv"))
        .arg("--mapping")
        .arg(common::repo_file("mappings/paper000_16imu_mixamo.json"))
        .args(["--format", "bvh", "--engine", "godot", "--out"])
        .arg(tmp.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--engine godot") && stderr.contains("--format glb"),
        "{stderr}"
    );
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0);
}
