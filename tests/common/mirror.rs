//! Files of public repositories fetched as snapshots (never copied into this one): read from the
//! git directories under `IMUBAKE_MIRROR`, by default `/work/.mirror` (`owner+name/repo`). CI
//! machines have no network to fetch them, so a test skips a file that is absent, saying so.

use std::path::PathBuf;
use std::process::Command;

fn root() -> PathBuf {
    std::env::var_os("IMUBAKE_MIRROR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/work/.mirror"))
}

/// The file at `commit:path` of `repo`'s fetched snapshot, or `None` (with the reason printed)
/// when it is absent.
pub fn fetched(repo: &str, commit: &str, path: &str) -> Option<Vec<u8>> {
    let dir = root().join(repo.replace('/', "+")).join("repo");
    let out = Command::new("git")
        .arg("-C")
        .arg(&dir)
        .args(["show", &format!("{commit}:{path}")])
        .output()
        .ok()?;
    if !out.status.success() {
        eprintln!(
            "SKIPPED {repo}@{commit}:{path}: not fetched here ({})",
            String::from_utf8_lossy(&out.stderr).trim()
        );
        return None;
    }
    Some(out.stdout)
}
