//! Helpers shared by integration tests: locating `../shared/data` and external tools.
//!
//! Locally a test whose data or tool is missing skips with a message; under `CI=true` it fails,
//! so a broken install never turns into a green run.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

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

/// The test venv's Python (set up by scripts/test.sh; `IMUBAKE_PYTHON` overrides).
pub fn python() -> Option<PathBuf> {
    let path = std::env::var_os("IMUBAKE_PYTHON")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .map(|h| PathBuf::from(h).join(".cache/imubake-test/venv/bin/python"))
        })?;
    if path.is_file() {
        Some(path)
    } else {
        missing(&format!(
            "test Python {} (run scripts/test.sh)",
            path.display()
        ))
    }
}

/// The compiled `imubake` binary.
pub fn imubake_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_imubake"))
}
