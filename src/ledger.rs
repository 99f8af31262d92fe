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
//! `write_all` and synced. Several processes may append to the same file on a local file system
//! (O_APPEND); reading ignores a torn last line (a crash mid-write) and counts it.
//!
//! Shared storage (NFS) makes no append atomic across machines, so a shard of a batch appends to
//! a file of its own, `ledger.shard-I-of-N.jsonl` beside `ledger.jsonl` (the file of unsharded
//! runs and `watch`), and every reader reads them all: within a file the later line wins, across
//! files the later recorded one (`recorded_at_ns`, else `converted_at_ns`; a tie goes to the file
//! whose name sorts last). Ledgers of one file, written before shards had their own, read as
//! before.

use crate::convert::Plan;
use crate::convert::plan::PlanMapping;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{SystemTime, UNIX_EPOCH};

/// The ledger's folder under an output root.
pub fn ledger_dir(out_root: &Path) -> PathBuf {
    out_root.join(".imubake")
}

/// The ledger file of unsharded runs and `watch` under an output root.
pub fn ledger_path(out_root: &Path) -> PathBuf {
    ledger_dir(out_root).join("ledger.jsonl")
}

/// The ledger file shard `index` of `count` appends to: its own, so that shards on several
/// machines never append to one file.
pub fn shard_ledger_name(index: usize, count: usize) -> String {
    format!("ledger.shard-{index}-of-{count}.jsonl")
}

/// Whether a file name in the ledger's folder is a ledger file (`ledger.jsonl`,
/// `ledger.shard-I-of-N.jsonl`).
fn is_ledger_file(name: &str) -> bool {
    name == "ledger.jsonl" || (name.starts_with("ledger.shard-") && name.ends_with(".jsonl"))
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
    /// Inode change time, ns since the Unix epoch (a session folder: the latest of its entries);
    /// absent in lines written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ctime_ns: Option<u64>,
    /// When the conversion started, ns since the Unix epoch.
    pub converted_at_ns: u64,
    /// When the line was appended, ns since the Unix epoch (set by [`Ledger::append_shared`]):
    /// what orders entries of one source across ledger files. Absent in lines written before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recorded_at_ns: Option<u64>,
    #[serde(default)]
    pub imubake_version: String,
}

/// A source's size, modification time and inode change time, the cheap half of "has it
/// changed". The ctime catches a rewrite whose mtime was put back (`touch -d`, `cp -p`): no tool
/// can set it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SourceStat {
    pub size: u64,
    pub mtime_ns: Option<u64>,
    pub ctime_ns: Option<u64>,
}

impl SourceStat {
    /// A file's size and mtime; a folder's summed sizes and latest mtime (itself, its visible
    /// files and sub-folders, recursively).
    pub fn of(path: &Path) -> io::Result<SourceStat> {
        let meta = fs::metadata(path)?;
        let mut stat = SourceStat {
            size: if meta.is_dir() { 0 } else { meta.len() },
            mtime_ns: mtime_ns(&meta),
            ctime_ns: ctime_ns(&meta),
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
        let latest = |a: Option<u64>, b: Option<u64>| match (a, b) {
            (Some(a), Some(b)) => Some(a.max(b)),
            _ => None,
        };
        stat.mtime_ns = latest(stat.mtime_ns, mtime_ns(&meta));
        stat.ctime_ns = latest(stat.ctime_ns, ctime_ns(&meta));
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

fn ctime_ns(meta: &fs::Metadata) -> Option<u64> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let secs = u64::try_from(meta.ctime()).ok()?;
        let nanos = u64::try_from(meta.ctime_nsec()).ok()?;
        secs.checked_mul(1_000_000_000)?.checked_add(nanos)
    }
    #[cfg(not(unix))]
    {
        let _ = meta;
        None
    }
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

/// The version of what a settings fingerprint means. Bump it when a change of imubake makes the
/// same settings produce different outputs (a new default, a changed stage, a fixed bug in a
/// writer): every ledger entry under an older schema then reconverts once, with one log line
/// saying why. Adding a setting whose default keeps today's outputs needs no bump (add it to
/// [`FingerprintInput`] only with a value that leaves the fingerprint of its default unchanged,
/// or bump).
///
/// Schema 0 was a hash of the settings' `Debug` text and the crate version (any release
/// reconverted everything); 1 is [`FingerprintInput`]; 2: causal Butterworth smoothing runs on
/// the stream's core (its grid's rate from each sensor's first samples); 3: raw readings are
/// fused (takes that failed for want of orientations convert now) and the sidecar records each
/// sensor's origin and world; 4: filters that do not estimate the gyro bias (madgwick, trust,
/// gyro) get it from the take's opening stillness; 5: the root mode `auto` is the default (the
/// body walks when both legs are sensed); 6: joints between two sensed ones share the bend
/// (`unsensed: interpolate`, the default); 7: a take whose heading is unsure is refused unless
/// the mapping or `--heading` keeps the sensors' north (takes that converted fail, or convert
/// with their heading declared); 8: a BVH take is retargeted by matching its first frame's pose
/// (`--bvh-reference match:0`, was the zero pose).
pub const FINGERPRINT_SCHEMA: u32 = 8;

/// What decides a conversion's outputs besides the capture, in a stable serialisation: field
/// names and values, not Rust's `Debug` text; the mapping and rig files by content, not by path.
#[derive(Serialize)]
struct FingerprintInput<'a> {
    input_format: Option<&'static str>,
    skip_lines: u64,
    skip_seconds: f64,
    world: Option<crate::world::World>,
    /// SHA-256 of the mapping file's content.
    mapping: Option<String>,
    /// A built-in rig's name, or `file:` and the SHA-256 of a rig file's content.
    rig: Option<String>,
    fps: [u64; 2],
    trim: Option<[Option<f64>; 2]>,
    root: &'a str,
    smoothing: serde_json::Value,
    formats: Vec<&'static str>,
    units: &'static str,
    report: bool,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    causal: bool,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    bind_frame: bool,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    in_place: bool,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    foot_lock: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    engine: Option<&'static str>,
    unsensed: &'static str,
    /// `--heading` / the config's, when set (the mapping's is in its hash).
    #[serde(skip_serializing_if = "Option::is_none")]
    heading: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    sensor_rate_hz: Option<f64>,
    /// The fusion asked for, as its settings text (every parameter).
    #[serde(skip_serializing_if = "Option::is_none")]
    fusion: Option<String>,
    /// SHA-256 of the sensor calibration file's content.
    #[serde(skip_serializing_if = "Option::is_none")]
    sensor_calibration: Option<String>,
    /// SHA-256 of the subject file's content.
    #[serde(skip_serializing_if = "Option::is_none")]
    subject: Option<String>,
    /// SHA-256 of a BVH take's bone map.
    #[serde(skip_serializing_if = "Option::is_none")]
    bone_map: Option<String>,
    /// A BVH take's reference pose, when not the default (`match:0`).
    #[serde(skip_serializing_if = "Option::is_none")]
    bvh_reference: Option<String>,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    mvnx_segments: bool,
    /// `--rate` of recordings without timestamps.
    #[serde(skip_serializing_if = "Option::is_none")]
    rate_hz: Option<f64>,
    /// SHA-256 of the packet layout file's content.
    #[serde(skip_serializing_if = "Option::is_none")]
    layout: Option<String>,
}

/// `<schema>:<SHA-256 of the settings' stable serialisation>`: the plan's settings, each file
/// it read by the SHA-256 of the bytes it parsed.
pub fn settings_fingerprint(plan: &Plan) -> String {
    let settings = plan.settings();
    let p = &settings.pipeline;
    let mapping = match plan.mapping() {
        PlanMapping::ByName => None,
        PlanMapping::Quaternion(m) => Some(m.sha256.clone()),
        PlanMapping::Euler(m) => Some(m.sha256.clone()),
    };
    let input = FingerprintInput {
        input_format: settings.read.format.map(|f| f.name()),
        skip_lines: settings.read.skip_lines,
        skip_seconds: settings.read.skip_seconds,
        world: settings.read.world,
        mapping,
        rig: settings.rig.as_ref().map(|rig| match plan.rig_sha256() {
            Some(sha) => format!("file:{sha}"),
            None => rig.clone(),
        }),
        fps: [p.fps.num(), p.fps.den()],
        trim: p
            .trim
            .map(|t| [Some(t.start_s), (t.end_s < f64::MAX).then_some(t.end_s)]),
        root: p.root.label(),
        smoothing: serde_json::to_value(&p.smoothing).unwrap_or_default(),
        formats: settings.formats.iter().map(|f| f.name()).collect(),
        units: settings.units.name(),
        report: settings.report,
        causal: p.causal,
        bind_frame: settings.bind_frame,
        in_place: settings.in_place,
        foot_lock: p.foot_lock,
        engine: settings.engine.map(|e| e.name()),
        unsensed: p.unsensed.label(),
        heading: p.heading.map(|h| h.label()),
        sensor_rate_hz: p.sensor_rate_hz,
        fusion: p.fusion.as_ref().map(|f| f.to_string()),
        sensor_calibration: plan.sensor_calibration().map(|c| c.sha256.clone()),
        subject: plan.subject().map(|s| s.sha256.clone()),
        bone_map: plan.bone_map().map(|b| b.sha256.clone()),
        bvh_reference: (settings.bvh_reference != crate::retarget::Reference::default())
            .then(|| settings.bvh_reference.to_string()),
        mvnx_segments: settings.mvnx_segments,
        rate_hz: settings.read.rate_hz,
        layout: plan.layout().map(|(_, sha)| sha.to_string()),
    };
    let json = serde_json::to_vec(&input).expect("the fingerprint input serialises");
    format!("{FINGERPRINT_SCHEMA}:{}", hex(&Sha256::digest(&json)))
}

/// The schema a fingerprint was written under (0: before schemas, a bare SHA-256).
pub fn fingerprint_schema(fingerprint: &str) -> u32 {
    fingerprint
        .split_once(':')
        .and_then(|(schema, _)| schema.parse().ok())
        .unwrap_or(0)
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
    CurrentTouched(Box<LedgerEntry>),
    /// Never converted, failed last time, settings or content changed, or an output is missing.
    Stale,
}

impl Freshness {
    pub fn is_current(&self) -> bool {
        !matches!(self, Freshness::Stale)
    }
}

/// The ledger of one output root: the latest entry per source over all its files, and the file
/// this process appends to.
#[derive(Debug)]
pub struct Ledger {
    out_root: PathBuf,
    path: PathBuf,
    latest: HashMap<String, LedgerEntry>,
    skipped_lines: usize,
    file: Mutex<Option<File>>,
}

impl Ledger {
    /// Loads every ledger file of `out_root` (an empty ledger when there is none yet), to append
    /// to `ledger.jsonl`. Lines that do not parse (a torn last line after a crash) are ignored
    /// and counted.
    pub fn load(out_root: &Path) -> io::Result<Ledger> {
        Ledger::load_appending_to(out_root, "ledger.jsonl")
    }

    /// [`Ledger::load`], to append to the file `own` of the ledger's folder (a shard's:
    /// [`shard_ledger_name`]).
    pub fn load_appending_to(out_root: &Path, own: &str) -> io::Result<Ledger> {
        let dir = ledger_dir(out_root);
        let mut names: Vec<String> = match fs::read_dir(&dir) {
            Ok(entries) => entries
                .filter_map(|e| e.ok())
                .filter_map(|e| e.file_name().into_string().ok())
                .filter(|n| is_ledger_file(n))
                .collect(),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Vec::new(),
            Err(e) => return Err(e),
        };
        names.sort();
        let mut latest: HashMap<String, LedgerEntry> = HashMap::new();
        let mut skipped_lines = 0;
        for name in &names {
            let bytes = match fs::read(dir.join(name)) {
                Ok(bytes) => bytes,
                // Removed between the listing and the read: nothing of it to know.
                Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
                Err(e) => return Err(e),
            };
            // Within a file, the later line wins.
            let mut of_file: HashMap<String, LedgerEntry> = HashMap::new();
            for line in bytes.split(|&b| b == b'\n') {
                if line.iter().all(u8::is_ascii_whitespace) {
                    continue;
                }
                match serde_json::from_slice::<LedgerEntry>(line) {
                    Ok(entry) => {
                        of_file.insert(entry.source.clone(), entry);
                    }
                    Err(_) => skipped_lines += 1,
                }
            }
            // Across files, the later recorded; a tie to the file read last.
            let recorded = |e: &LedgerEntry| e.recorded_at_ns.unwrap_or(e.converted_at_ns);
            for (source, entry) in of_file {
                match latest.get(&source) {
                    Some(held) if recorded(held) > recorded(&entry) => {}
                    _ => {
                        latest.insert(source, entry);
                    }
                }
            }
        }
        Ok(Ledger {
            out_root: out_root.to_path_buf(),
            path: dir.join(own),
            latest,
            skipped_lines,
            file: Mutex::new(None),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// How many sources' latest entries were written under an older fingerprint schema (they
    /// convert again once).
    pub fn older_schema_count(&self) -> usize {
        self.latest
            .values()
            .filter(|e| fingerprint_schema(&e.settings) < FINGERPRINT_SCHEMA)
            .count()
    }

    /// Logs one line when entries of an older fingerprint schema are about to convert again.
    pub fn report_older_schema(&self) {
        let older = self.older_schema_count();
        if older > 0 {
            tracing::info!(
                ledger = %self.path.display(),
                "{older} take(s) were converted by an earlier imubake whose settings fingerprint \
                 meant something else (schema < {FINGERPRINT_SCHEMA}); they convert again once"
            );
        }
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
    /// only when the size is the same but the mtime or ctime differs, is unknown, or is too close
    /// to the conversion to be trusted — or when `force_hash` says the source was seen written.
    pub fn is_current(
        &self,
        source: &str,
        stat: SourceStat,
        fingerprint: &str,
        force_hash: bool,
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
        // A ctime recorded then must be the same now (lines written before it was recorded
        // have none).
        let same_ctime = entry.ctime_ns.is_none() || entry.ctime_ns == stat.ctime_ns;
        let trusted_mtime = match (entry.mtime_ns, stat.mtime_ns) {
            (Some(then), Some(now)) => {
                then == now && same_ctime && then.saturating_add(RACY_NS) < entry.converted_at_ns
            }
            _ => false,
        };
        let trusted_mtime = trusted_mtime && !force_hash;
        if trusted_mtime {
            return Ok(Freshness::Current);
        }
        if hash()? != entry.sha256 {
            return Ok(Freshness::Stale);
        }
        if entry.mtime_ns == stat.mtime_ns && entry.ctime_ns == stat.ctime_ns {
            Ok(Freshness::Current)
        } else {
            let mut touched = entry.clone();
            touched.mtime_ns = stat.mtime_ns;
            touched.ctime_ns = stat.ctime_ns;
            Ok(Freshness::CurrentTouched(Box::new(touched)))
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
        let recorded = LedgerEntry {
            recorded_at_ns: Some(now_ns()),
            ..entry.clone()
        };
        let mut line = serde_json::to_vec(&recorded).map_err(io::Error::other)?;
        line.push(b'\n');
        let mut guard = self.file.lock().unwrap_or_else(|e| e.into_inner());
        if guard.is_none() {
            *guard = Some(self.open_for_append()?);
        }
        let file = guard.as_mut().expect("opened above");
        // A process abandoning an unfinished take records nothing of it.
        let written = crate::write::unless_abandoned(|| {
            file.write_all(&line)?;
            file.sync_data()
        });
        if written.is_err() {
            // Part of the line may be written: the next append opens the file again, which
            // ends that fragment with a newline (a torn line, ignored when read).
            *guard = None;
        }
        written
    }

    /// Opens the file for appending (kept for the appends that follow) unless it is open
    /// already: whether a line could be recorded, asked before work whose line it is.
    pub fn ready_to_append(&self) -> io::Result<()> {
        let mut guard = self.file.lock().unwrap_or_else(|e| e.into_inner());
        if guard.is_none() {
            *guard = Some(self.open_for_append()?);
        }
        Ok(())
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
    use crate::convert::ConvertSettings;

    fn entry(source: &str, status: Status, sha: &str) -> LedgerEntry {
        LedgerEntry {
            source: source.into(),
            size: 5,
            mtime_ns: Some(1),
            ctime_ns: Some(1),
            sha256: sha.into(),
            outputs: vec![format!("{source}.bvh")],
            status,
            settings: "fp".into(),
            error: None,
            converted_at_ns: 10_000_000_000,
            recorded_at_ns: None,
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

    /// Lines written straight into a ledger file (as other processes or older versions left them).
    fn write_lines(dir: &Path, name: &str, entries: &[LedgerEntry]) {
        fs::create_dir_all(ledger_dir(dir)).unwrap();
        let text: String = entries
            .iter()
            .map(|e| serde_json::to_string(e).unwrap() + "\n")
            .collect();
        fs::write(ledger_dir(dir).join(name), text).unwrap();
    }

    #[test]
    fn every_shards_file_is_read_and_the_later_recorded_entry_wins() {
        let dir = tempfile::tempdir().unwrap();
        let at = |mut e: LedgerEntry, converted: u64, recorded: Option<u64>| {
            e.converted_at_ns = converted;
            e.recorded_at_ns = recorded;
            e
        };
        // A single-file ledger of before shards had files: within it the later line wins, even
        // with an earlier time (a clock put back).
        write_lines(
            dir.path(),
            "ledger.jsonl",
            &[
                at(entry("a", Status::Failed, "a1"), 50, None),
                at(entry("a", Status::Converted, "a2"), 40, None),
                at(entry("b", Status::Converted, "b1"), 50, None),
                at(entry("c", Status::Converted, "c1"), 50, None),
            ],
        );
        write_lines(
            dir.path(),
            &shard_ledger_name(1, 4),
            &[
                // Recorded after ledger.jsonl's b: wins.
                at(entry("b", Status::Converted, "b2"), 45, Some(60)),
                // Recorded before ledger.jsonl's c: loses.
                at(entry("c", Status::Converted, "c0"), 30, Some(35)),
                at(entry("d", Status::Converted, "d1"), 30, Some(35)),
            ],
        );
        write_lines(
            dir.path(),
            "other.jsonl",
            &[entry("e", Status::Converted, "x")],
        );
        let ledger = Ledger::load(dir.path()).unwrap();
        let sha = |s: &str| ledger.latest(s).map(|e| e.sha256.as_str());
        assert_eq!(
            [sha("a"), sha("b"), sha("c"), sha("d"), sha("e")],
            [Some("a2"), Some("b2"), Some("c1"), Some("d1"), None]
        );
        // A shard appends to its own file only, each line with the time it was recorded.
        let mut shard = Ledger::load_appending_to(dir.path(), &shard_ledger_name(2, 4)).unwrap();
        let before = now_ns();
        shard.append(entry("c", Status::Failed, "c2")).unwrap();
        let own = fs::read_to_string(ledger_dir(dir.path()).join(shard_ledger_name(2, 4))).unwrap();
        let line: LedgerEntry = serde_json::from_str(own.trim()).unwrap();
        assert!(line.recorded_at_ns.unwrap() >= before);
        assert_eq!(
            Ledger::load(dir.path())
                .unwrap()
                .latest("c")
                .unwrap()
                .sha256,
            "c2"
        );
        assert_eq!(
            fs::read_dir(ledger_dir(dir.path())).unwrap().count(),
            4,
            "ledger.jsonl, two shards' files, other.jsonl"
        );
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
            ctime_ns: Some(1),
        };
        let no_hash = || -> io::Result<String> { panic!("hashed") };
        assert_eq!(
            ledger.is_current("a", stat, "fp", false, no_hash).unwrap(),
            Freshness::Current
        );
        assert_eq!(
            ledger
                .is_current("a", stat, "other", false, no_hash)
                .unwrap(),
            Freshness::Stale
        );
        let bigger = SourceStat { size: 6, ..stat };
        assert_eq!(
            ledger
                .is_current("a", bigger, "fp", false, no_hash)
                .unwrap(),
            Freshness::Stale
        );
        let touched = SourceStat {
            mtime_ns: Some(2),
            ..stat
        };
        assert!(matches!(
            ledger
                .is_current("a", touched, "fp", false, || Ok("h".into()))
                .unwrap(),
            Freshness::CurrentTouched(e) if e.mtime_ns == Some(2)
        ));
        assert_eq!(
            ledger
                .is_current("a", touched, "fp", false, || Ok("new".into()))
                .unwrap(),
            Freshness::Stale
        );
        // The same mtime with a new ctime (a rewrite whose mtime was put back), or a look forced
        // by a write event: the hash decides.
        let rewritten = SourceStat {
            ctime_ns: Some(7),
            ..stat
        };
        assert_eq!(
            ledger
                .is_current("a", rewritten, "fp", false, || Ok("new".into()))
                .unwrap(),
            Freshness::Stale
        );
        assert!(matches!(
            ledger
                .is_current("a", rewritten, "fp", false, || Ok("h".into()))
                .unwrap(),
            Freshness::CurrentTouched(e) if e.ctime_ns == Some(7)
        ));
        assert_eq!(
            ledger
                .is_current("a", stat, "fp", true, || Ok("new".into()))
                .unwrap(),
            Freshness::Stale
        );
        fs::remove_file(dir.path().join("a.bvh")).unwrap();
        assert_eq!(
            ledger.is_current("a", stat, "fp", false, no_hash).unwrap(),
            Freshness::Stale,
            "a missing output makes the take stale"
        );
        ledger.append(entry("f", Status::Failed, "h")).unwrap();
        assert_eq!(
            ledger.is_current("f", stat, "fp", false, no_hash).unwrap(),
            Freshness::Stale,
            "failed takes are retried"
        );
    }

    #[test]
    fn fingerprints_are_stable_and_say_their_schema() {
        let fingerprint = |settings: &ConvertSettings| {
            settings_fingerprint(&Plan::resolve(settings.clone()).unwrap())
        };
        let dir = tempfile::tempdir().unwrap();
        let mapping_text = include_str!("../samples/sou_wave.mapping.json");
        let mapping = dir.path().join("m.json");
        fs::write(&mapping, mapping_text).unwrap();
        let settings = ConvertSettings {
            mapping: Some(mapping.clone()),
            ..ConvertSettings::default()
        };
        let fp = fingerprint(&settings);
        assert_eq!(fingerprint_schema(&fp), FINGERPRINT_SCHEMA);
        assert_eq!(fp, fingerprint(&settings.clone()));
        // The mapping counts by content, not by path.
        let moved = dir.path().join("moved.json");
        fs::write(&moved, mapping_text).unwrap();
        let elsewhere = ConvertSettings {
            mapping: Some(moved),
            ..settings.clone()
        };
        assert_eq!(fp, fingerprint(&elsewhere));
        fs::write(&mapping, format!("{mapping_text}\n")).unwrap();
        assert_ne!(fp, fingerprint(&settings));
        let mut other = settings.clone();
        other.pipeline.fps = "60".parse().unwrap();
        assert_ne!(fingerprint(&other), fingerprint(&settings));
        // An engine's import files are outputs too: asking for them converts again.
        let mut godot = settings.clone();
        godot.engine = Some(crate::write::Engine::Godot);
        assert_ne!(fingerprint(&godot), fingerprint(&settings));
        // Fusion asked for, and each of its parameters, change the outputs.
        let mut fused = settings.clone();
        fused.pipeline.fusion = Some("vqf".parse().unwrap());
        let mut tuned = settings.clone();
        tuned.pipeline.fusion = Some("vqf:tau_acc=2".parse().unwrap());
        let fps = [&settings, &fused, &tuned].map(fingerprint);
        assert!(fps[0] != fps[1] && fps[1] != fps[2] && fps[0] != fps[2]);
        // A sensor calibration file counts by content.
        let cal = dir.path().join("sensors.yaml");
        fs::write(&cal, "imubake_sensor_calibration: 1\nsensors: {}\n").unwrap();
        let calibrated = ConvertSettings {
            sensor_calibration: Some(cal.clone()),
            ..settings.clone()
        };
        let before = fingerprint(&calibrated);
        assert_ne!(before, fingerprint(&settings));
        fs::write(
            &cal,
            "imubake_sensor_calibration: 1\nsensors: {}\n# edited\n",
        )
        .unwrap();
        assert_ne!(before, fingerprint(&calibrated));
        // Fingerprints written before schemas were bare SHA-256s.
        assert_eq!(fingerprint_schema(&"ab".repeat(32)), 0);
    }
}
