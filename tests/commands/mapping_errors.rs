//! What `imubake convert` tells a user whose mapping is wrong, as the terminal shows it: a bone
//! named with the wrong case gets the rig's bone it meant and the list of the rig's bones; an
//! empty mapping file gets what to write.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// `imubake convert samples/walk.csv --mapping <mapping>`: exit code and stderr.
fn convert_walk(dir: &Path, mapping: &Path) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_imubake"))
        .arg("convert")
        .arg(repo("samples/walk.csv"))
        .arg("--mapping")
        .arg(mapping)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The shipped walk mapping with `LeftForeArm` written `LeftForearm`: the error names the key, the
/// bone it meant, and every bone of `rigs/mixamo.yaml` in the file's order.
#[test]
fn a_bone_with_the_wrong_case_gets_did_you_mean_and_the_bone_list() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(repo("mappings/paper000_16imu_mixamo.json")).unwrap();
    assert_eq!(text.matches("\"LeftForeArm\"").count(), 1);
    let mapping = dir.path().join("typo.json");
    std::fs::write(&mapping, text.replace("\"LeftForeArm\"", "\"LeftForearm\"")).unwrap();
    let (code, stderr) = convert_walk(dir.path(), &mapping);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains(
            "`sensors.left_forearm.bone`: unknown bone `LeftForearm` in rig `mixamo`; \
             did you mean `LeftForeArm`?"
        ),
        "{stderr}"
    );
    // The bones, read from the rig file itself.
    let rig = std::fs::read_to_string(repo("rigs/mixamo.yaml")).unwrap();
    let names = regex::Regex::new(r"(?m)^  - \{name: (\w+),").unwrap();
    let bones: Vec<&str> = names
        .captures_iter(&rig)
        .map(|c| c.get(1).unwrap().as_str())
        .collect();
    assert!(bones.len() >= 20 && bones[0] == "Hips", "{bones:?}");
    let list = format!("The rig's {} bones: {}", bones.len(), bones.join(", "));
    assert!(stderr.contains(&list), "{list}\n{stderr}");
    assert!(!dir.path().join("out/walk.bvh").exists());
}

/// An empty mapping file: the error says the file is empty and what a mapping looks like, and
/// points to the shipped examples.
#[test]
fn an_empty_mapping_file_says_what_to_write() {
    let dir = tempfile::tempdir().unwrap();
    let mapping = dir.path().join("empty.json");
    std::fs::write(&mapping, "").unwrap();
    let (code, stderr) = convert_walk(dir.path(), &mapping);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("empty.json: the file is empty; "),
        "{stderr}"
    );
    assert!(
        stderr.contains(r#"e.g. {"rig": "mixamo", "sensors": {"pelvis": {"bone": "Hips"}"#)
            && stderr.contains("mappings/paper000_16imu_mixamo.json"),
        "{stderr}"
    );
}
