//! The real consumers the output tests rely on are installed and working: Blender 5.0.1 as the
//! `bpy` module, and the Khronos glTF-Validator. Each is checked against a real file whose
//! properties are known from its source (Fox.glb: a 24-joint skin, 3 animations).

mod common;

use common::{missing, python, shared};
use std::path::{Path, PathBuf};
use std::process::Command;

fn node_modules() -> Option<PathBuf> {
    let dir = std::env::var_os("IMUBAKE_NODE_MODULES")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .map(|h| PathBuf::from(h).join(".cache/imubake-test/node/node_modules"))
        })?;
    if dir.join("gltf-validator/package.json").is_file() {
        Some(dir)
    } else {
        missing(&format!(
            "gltf-validator in {} (run scripts/test.sh)",
            dir.display()
        ))
    }
}

#[test]
fn blender_imports_a_real_gltf_character() {
    let (Some(py), Some(fox)) = (python(), shared("gltf/Fox.glb")) else {
        return;
    };
    let script = r#"
import sys, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[1])
arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
print(bpy.app.version_string, len(arms), len(arms[0].data.bones), len(bpy.data.actions))
"#;
    let out = Command::new(py)
        .args(["-c", script])
        .arg(&fox)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let last = stdout.lines().last().unwrap_or_default();
    assert_eq!(last, "5.0.1 1 24 3", "{stdout}");
}

fn validate(file: &Path, modules: &Path) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/gltf_validate.mjs");
    let out = Command::new("node")
        .arg(script)
        .arg(file)
        .env("IMUBAKE_NODE_MODULES", modules)
        .output()
        .expect("node runs");
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "{e}: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

#[test]
fn gltf_validator_accepts_a_valid_file_and_rejects_a_broken_one() {
    let (Some(modules), Some(fox)) = (node_modules(), shared("gltf/Fox.glb")) else {
        return;
    };
    let report = validate(&fox, &modules);
    assert_eq!(
        (report["errors"].as_u64(), report["warnings"].as_u64()),
        (Some(0), Some(0)),
        "{report}"
    );

    let dir = tempfile::tempdir().unwrap();
    let broken = dir.path().join("broken.glb");
    let bytes = std::fs::read(&fox).unwrap();
    std::fs::write(&broken, &bytes[..bytes.len() / 2]).unwrap();
    let report = validate(&broken, &modules);
    assert!(report["errors"].as_u64().unwrap() > 0, "{report}");
}
