//! The layers of ARCHITECTURE.md hold: a module imports (`use crate::…`, `crate::…` paths in
//! code, outside tests and comments) only modules of lower layers — never a higher one, nor
//! another of its own layer, so there can be no import loop. Submodules belong to their
//! top-level module's layer.

use std::collections::BTreeMap;
use std::path::Path;

/// Top-level modules by layer, lowest first (ARCHITECTURE.md, "Layers").
const LAYERS: [&[&str]; 11] = [
    &["fps", "world", "rotation", "diagnostic", "smooth"],
    &["take"],
    &["read", "bvh", "inspect", "fusion"],
    &["rig", "intrinsics"],
    &["mapping", "anim"],
    &["pipeline", "analysis", "retarget"],
    &["write"],
    &["convert", "simulate", "setup"],
    &["config", "ledger", "view"],
    &["batch", "live"],
    &["watch"],
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

/// The code of a source file: test modules cut off, comments dropped.
fn code(text: &str) -> String {
    let text = text.split("#[cfg(test)]").next().unwrap_or("");
    text.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Every source file under `src/`: its path relative to `src/` and its text.
fn source_files() -> Vec<(String, String)> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    let mut stack = vec![src.clone()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            let rel = path
                .strip_prefix(&src)
                .unwrap()
                .to_string_lossy()
                .into_owned();
            files.push((rel, std::fs::read_to_string(&path).unwrap()));
        }
    }
    files
}

#[test]
fn lower_layers_never_import_higher_ones() {
    let path_re = regex::Regex::new(r"crate::([a-z_]+)").unwrap();
    let mut modules = BTreeMap::new();
    let mut violations = Vec::new();
    for (rel, text) in source_files() {
        let top = rel.split(['/', '.']).next().unwrap().to_string();
        if ["lib", "main", "cli"].contains(&top.as_str()) {
            continue;
        }
        let own = layer_of(&top).unwrap_or_else(|| {
            panic!("src/{rel}: module `{top}` is in no layer of ARCHITECTURE.md")
        });
        modules.insert(top.clone(), own);
        for cap in path_re.captures_iter(&code(&text)) {
            let used = &cap[1];
            let Some(theirs) = layer_of(used) else {
                panic!("src/{rel}: uses `crate::{used}`, which is in no layer");
            };
            // Only strictly lower layers (or the module itself): no loops, even in a layer.
            if used != top && theirs >= own {
                violations.push(format!(
                    "src/{rel} (layer {own}) uses crate::{used} (layer {theirs})"
                ));
            }
        }
    }
    // Every layer's modules exist (the table names no module that is gone).
    for module in LAYERS.iter().flat_map(|l| l.iter()) {
        assert!(
            modules.contains_key(*module),
            "no module `{module}` in src/"
        );
    }
    assert!(violations.is_empty(), "{violations:#?}");
}

/// The calls that open a mapping, rig, subject, sensor calibration or bone map file by its path
/// (their definitions aside): only `convert/plan.rs` makes them, once per command, and the
/// command line for commands of its own (`simulate`, `inspect`, `calibrate-sensors`).
fn file_loads(code: &str) -> Vec<String> {
    let re = regex::Regex::new(
        r"\b(load_mapping|load_rig|load_bone_map)\s*\(|\b(Subject|SensorCalibration|BoneMap)::load\s*\(",
    )
    .unwrap();
    code.lines()
        .filter(|l| {
            let t = l.trim_start();
            !t.starts_with("pub fn ") && !t.starts_with("fn ") && re.is_match(l)
        })
        .map(|l| l.trim().to_string())
        .collect()
}

#[test]
fn only_the_plan_opens_the_files_settings_name() {
    // The scanner sees a load, and passes a definition.
    assert_eq!(file_loads("    let m = load_mapping(path)?;").len(), 1);
    assert_eq!(file_loads("let s = Subject::load(p)?;").len(), 1);
    assert!(file_loads("pub fn load_rig(name: &str) -> Result<Rig, E> {").is_empty());
    let mut violations = Vec::new();
    for (rel, text) in source_files() {
        if rel == "convert/plan.rs" || rel.starts_with("cli/") || rel == "main.rs" {
            continue;
        }
        for call in file_loads(&code(&text)) {
            violations.push(format!("src/{rel}: {call}"));
        }
    }
    assert!(violations.is_empty(), "{violations:#?}");
}
