//! The ledger `<out>/.imubake/ledger.jsonl`: one JSON object per line, one line per conversion
//! attempt, so that each take produces exactly one set of outputs and a rerun (`batch`, `watch`)
//! converts only what changed.
//!
//! A line records the source (its path relative to the input root, `/`-separated), its size,
//! modification time and SHA-256, the outputs (relative to the output root), the status
//! (`converted` or `failed`), a fingerprint of the settings, the error when failed and the time of
//! the conversion. Conversion times live only here, never in outputs, so outputs of the same
//! capture are byte-identical.
//!
//! Appends are atomic per line: the file is opened for appending, each line is written with one
//! `write_all` and synced. Several processes may append to the same ledger on a local file system
//! (O_APPEND); reading ignores a torn last line (a crash mid-write) and counts it.

use crate::convert::ConvertSettings;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{SystemTime, UNIX_EPOCH};

/// The ledger's path under an output root.
pub fn ledger_path(out_root: &Path) -> PathBuf {
    out_root.join(".imubake").join("ledger.jsonl")
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Converted,
    Failed,
}

/// One conversion attempt.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LedgerEntry {
    /// The source relative to its input root, `/`-separated.
    pub source: String,
    /// Bytes (a session folder: the sum over its files).
    pub size: u64,
    /// Modification time, ns since the Unix epoch (a session folder: the latest of its entries).
    pub mtime_ns: Option<u64>,
    pub sha256: String,
    /// Output files relative to the output root, `/`-separated, the sidecar last.
    pub outputs: Vec<String>,
    pub status: Status,
    /// [`settings_fingerprint`] of the settings used.
    pub settings: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// When the conversion started, ns since the Unix epoch.
    pub converted_at_ns: u64,
    #[serde(default)]
    pub imubake_version: String,
}

/// A source's size and modification time, the cheap half of "has it changed".
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SourceStat {
    pub size: u64,
    pub mtime_ns: Option<u64>,
}

impl SourceStat {
    /// A file's size and mtime; a folder's summed sizes and latest mtime (itself, its visible
    /// files and sub-folders, recursively).
    pub fn of(path: &Path) -> io::Result<SourceStat> {
        let meta = fs::metadata(path)?;
        let mut stat = SourceStat {
            size: if meta.is_dir() { 0 } else { meta.len() },
            mtime_ns: mtime_ns(&meta),
        };
        if meta.is_dir() {
            stat_dir(path, &mut stat)?;
        }
        Ok(stat)
    }
}

fn stat_dir(dir: &Path, stat: &mut SourceStat) -> io::Result<()> {
    for entry in fs::read_dir(dir)? {
        let entry = entry?;
        if entry.file_name().to_string_lossy().starts_with('.') {
            continue;
        }
        let meta = fs::metadata(entry.path())?;
        stat.mtime_ns = match (stat.mtime_ns, mtime_ns(&meta)) {
            (Some(a), Some(b)) => Some(a.max(b)),
            _ => None,
        };
        if meta.is_dir() {
            stat_dir(&entry.path(), stat)?;
        } else {
            stat.size += meta.len();
        }
    }
    Ok(())
}

fn mtime_ns(meta: &fs::Metadata) -> Option<u64> {
    let t = meta.modified().ok()?;
    u64::try_from(t.duration_since(UNIX_EPOCH).ok()?.as_nanos()).ok()
}

/// Now, ns since the Unix epoch.
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}

/// A source modified this close to (or after) its conversion may have changed again within the
/// file system's timestamp granularity without changing size or mtime ("racy git"): its hash is
/// checked.
const RACY_NS: u64 = 2_000_000_000;

/// SHA-256 (hex) of what decides a conversion's result besides the capture: the settings' debug
/// text, the imubake version, and the contents of the mapping file and of a rig file.
pub fn settings_fingerprint(settings: &ConvertSettings) -> String {
    let mut h = Sha256::new();
    h.update(env!("CARGO_PKG_VERSION").as_bytes());
    h.update([0]);
    h.update(format!("{settings:?}").as_bytes());
    let mut file = |path: &Path| {
        h.update([0]);
        match fs::read(path) {
            Ok(bytes) => h.update(&bytes),
            Err(_) => h.update(b"(unreadable)"),
        }
    };
    if let Some(m) = &settings.mapping {
        file(m);
    }
    if let Some(rig) = &settings.rig {
        let p = Path::new(rig);
        if p.is_file() {
            file(p);
        }
    }
    hex(&h.finalize())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Whether a take needs converting, and why not when it does not.
#[derive(Debug, Clone, PartialEq)]
pub enum Freshness {
    /// Converted with these settings from this content, and every output exists.
    Current,
    /// As `Current`, but the size or mtime changed with the content the same (a touched file):
    /// the entry to append so the next check is cheap again.
    CurrentTouched(LedgerEntry),
    /// Never converted, failed last time, settings or content changed, or an output is missing.
    Stale,
}

impl Freshness {
    pub fn is_current(&self) -> bool {
        !matches!(self, Freshness::Stale)
    }
}

/// The ledger of one output root: the latest entry per source, and the file to append to.
#[derive(Debug)]
pub struct Ledger {
    out_root: PathBuf,
    path: PathBuf,
    latest: HashMap<String, LedgerEntry>,
    skipped_lines: usize,
    file: Mutex<Option<File>>,
}

impl Ledger {
    /// Loads `<out_root>/.imubake/ledger.jsonl` (an empty ledger when it does not exist yet).
    /// Lines that do not parse (a torn last line after a crash) are ignored and counted.
    pub fn load(out_root: &Path) -> io::Result<Ledger> {
        let path = ledger_path(out_root);
        let mut latest = HashMap::new();
        let mut skipped_lines = 0;
        match fs::read(&path) {
            Ok(bytes) => {
                for line in bytes.split(|&b| b == b'\n') {
                    if line.iter().all(u8::is_ascii_whitespace) {
                        continue;
                    }
                    match serde_json::from_slice::<LedgerEntry>(line) {
                        Ok(entry) => {
                            latest.insert(entry.source.clone(), entry);
                        }
                        Err(_) => skipped_lines += 1,
                    }
                }
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
        Ok(Ledger {
            out_root: out_root.to_path_buf(),
            path,
            latest,
            skipped_lines,
            file: Mutex::new(None),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Lines that did not parse (a torn last line) and were ignored.
    pub fn skipped_lines(&self) -> usize {
        self.skipped_lines
    }

    /// The latest entry of `source`.
    pub fn latest(&self, source: &str) -> Option<&LedgerEntry> {
        self.latest.get(source)
    }

    pub fn len(&self) -> usize {
        self.latest.len()
    }

    pub fn is_empty(&self) -> bool {
        self.latest.is_empty()
    }

    /// Whether `source` (relative path, with `stat` now) is converted and current under
    /// `fingerprint`. Size and mtime are checked first; `hash` (the source's SHA-256) is computed
    /// only when the size is the same but the mtime differs, is unknown, or is too close to the
    /// conversion to be trusted.
    pub fn is_current(
        &self,
        source: &str,
        stat: SourceStat,
        fingerprint: &str,
        hash: impl FnOnce() -> io::Result<String>,
    ) -> io::Result<Freshness> {
        let Some(entry) = self.latest.get(source) else {
            return Ok(Freshness::Stale);
        };
        if entry.status != Status::Converted
            || entry.settings != fingerprint
            || entry.size != stat.size
            || entry.outputs.is_empty()
            || !entry
                .outputs
                .iter()
                .all(|o| self.out_root.join(o).is_file())
        {
            return Ok(Freshness::Stale);
        }
        let trusted_mtime = match (entry.mtime_ns, stat.mtime_ns) {
            (Some(then), Some(now)) => {
                then == now && then.saturating_add(RACY_NS) < entry.converted_at_ns
            }
            _ => false,
        };
        if trusted_mtime {
            return Ok(Freshness::Current);
        }
        if hash()? != entry.sha256 {
            return Ok(Freshness::Stale);
        }
        if entry.mtime_ns == stat.mtime_ns {
            Ok(Freshness::Current)
        } else {
            let mut touched = entry.clone();
            touched.mtime_ns = stat.mtime_ns;
            Ok(Freshness::CurrentTouched(touched))
        }
    }

    /// Appends `entry` as one line (one `write_all`, then fsync) and makes it the latest of its
    /// source. Safe to call from several threads.
    pub fn append(&mut self, entry: LedgerEntry) -> io::Result<()> {
        self.append_shared(&entry)?;
        self.latest.insert(entry.source.clone(), entry);
        Ok(())
    }

    /// [`Ledger::append`] through a shared reference (parallel conversions): the line is written
    /// but the in-memory view is not updated.
    pub fn append_shared(&self, entry: &LedgerEntry) -> io::Result<()> {
        let mut line = serde_json::to_vec(entry).map_err(io::Error::other)?;
        line.push(b'\n');
        let mut guard = self.file.lock().unwrap_or_else(|e| e.into_inner());
        if guard.is_none() {
            *guard = Some(self.open_for_append()?);
        }
        let file = guard.as_mut().expect("opened above");
        file.write_all(&line)?;
        file.sync_data()
    }

    fn open_for_append(&self) -> io::Result<File> {
        if let Some(dir) = self.path.parent() {
            fs::create_dir_all(dir)?;
        }
        let mut file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.path)?;
        // A torn last line (no newline) must not swallow the next entry.
        let len = file.metadata()?.len();
        if len > 0 {
            let bytes = fs::read(&self.path)?;
            if bytes.last() != Some(&b'\n') {
                file.write_all(b"\n")?;
            }
        }
        Ok(file)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(source: &str, status: Status, sha: &str) -> LedgerEntry {
        LedgerEntry {
            source: source.into(),
            size: 5,
            mtime_ns: Some(1),
            sha256: sha.into(),
            outputs: vec![format!("{source}.bvh")],
            status,
            settings: "fp".into(),
            error: None,
            converted_at_ns: 10_000_000_000,
            imubake_version: "x".into(),
        }
    }

    #[test]
    fn latest_entry_wins_and_torn_line_is_ignored() {
        let dir = tempfile::tempdir().unwrap();
        let mut ledger = Ledger::load(dir.path()).unwrap();
        assert!(ledger.is_empty());
        ledger.append(entry("a", Status::Failed, "1")).unwrap();
        ledger.append(entry("a", Status::Converted, "2")).unwrap();
        ledger.append(entry("b", Status::Converted, "3")).unwrap();
        drop(ledger);
        // A crash mid-write: half a line, no newline.
        let mut f = OpenOptions::new()
            .append(true)
            .open(ledger_path(dir.path()))
            .unwrap();
        f.write_all(br#"{"source":"c","size":"#).unwrap();
        drop(f);
        let mut ledger = Ledger::load(dir.path()).unwrap();
        assert_eq!(ledger.skipped_lines(), 1);
        assert_eq!(ledger.len(), 2);
        assert_eq!(ledger.latest("a").unwrap().sha256, "2");
        // The next append starts on a new line.
        ledger.append(entry("d", Status::Converted, "4")).unwrap();
        let ledger = Ledger::load(dir.path()).unwrap();
        assert_eq!(ledger.skipped_lines(), 1);
        assert_eq!(ledger.len(), 3);
    }

    #[test]
    fn currency_checks_size_mtime_then_hash() {
        let dir = tempfile::tempdir().unwrap();
        fs::write(dir.path().join("a.bvh"), "x").unwrap();
        let mut ledger = Ledger::load(dir.path()).unwrap();
        ledger.append(entry("a", Status::Converted, "h")).unwrap();
        let stat = SourceStat {
            size: 5,
            mtime_ns: Some(1),
        };
        let no_hash = || -> io::Result<String> { panic!("hashed") };
        assert_eq!(
            ledger.is_current("a", stat, "fp", no_hash).unwrap(),
            Freshness::Current
        );
        assert_eq!(
            ledger.is_current("a", stat, "other", no_hash).unwrap(),
            Freshness::Stale
        );
        let bigger = SourceStat { size: 6, ..stat };
        assert_eq!(
            ledger.is_current("a", bigger, "fp", no_hash).unwrap(),
            Freshness::Stale
        );
        let touched = SourceStat {
            mtime_ns: Some(2),
            ..stat
        };
        assert!(matches!(
            ledger
                .is_current("a", touched, "fp", || Ok("h".into()))
                .unwrap(),
            Freshness::CurrentTouched(e) if e.mtime_ns == Some(2)
        ));
        assert_eq!(
            ledger
                .is_current("a", touched, "fp", || Ok("new".into()))
                .unwrap(),
            Freshness::Stale
        );
        fs::remove_file(dir.path().join("a.bvh")).unwrap();
        assert_eq!(
            ledger.is_current("a", stat, "fp", no_hash).unwrap(),
            Freshness::Stale,
            "a missing output makes the take stale"
        );
        ledger.append(entry("f", Status::Failed, "h")).unwrap();
        assert_eq!(
            ledger.is_current("f", stat, "fp", no_hash).unwrap(),
            Freshness::Stale,
            "failed takes are retried"
        );
    }
}
