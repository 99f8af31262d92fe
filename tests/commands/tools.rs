//! The real consumers the output tests rely on are installed and working: Blender 5.0.1 as the
//! `bpy` module, and the Khronos glTF-Validator. Each is checked against a real file whose
//! properties are known from its source (Fox.glb: a 24-joint skin, 3 animations).

use crate::common;

use common::{blender_import_gltf, gltf_validate, node_modules, python, shared};

#[test]
fn blender_imports_a_real_gltf_character() {
    let (Some(py), Some(fox)) = (python(), shared("gltf/Fox.glb")) else {
        return;
    };
    let query = serde_json::json!({"bones": [], "times": []});
    let report = &blender_import_gltf(&py, &[&fox], &query)[0];
    assert_eq!(report["blender"], "5.0.1", "{report}");
    assert_eq!(report["armatures"], 1, "{report}");
    assert_eq!(
        report["bones"].as_array().map(Vec::len),
        Some(24),
        "{report}"
    );
    assert_eq!(
        report["actions"].as_array().map(Vec::len),
        Some(3),
        "{report}"
    );
}

#[test]
fn gltf_validator_accepts_a_valid_file_and_rejects_a_broken_one() {
    let (Some(modules), Some(fox)) = (node_modules(), shared("gltf/Fox.glb")) else {
        return;
    };
    let report = &gltf_validate(&[&fox], &modules)[0];
    assert_eq!(
        (report["errors"].as_u64(), report["warnings"].as_u64()),
        (Some(0), Some(0)),
        "{report}"
    );

    let dir = tempfile::tempdir().unwrap();
    let broken = dir.path().join("broken.glb");
    let bytes = std::fs::read(&fox).unwrap();
    std::fs::write(&broken, &bytes[..bytes.len() / 2]).unwrap();
    let report = &gltf_validate(&[&broken], &modules)[0];
    assert!(report["errors"].as_u64().unwrap() > 0, "{report}");
}
