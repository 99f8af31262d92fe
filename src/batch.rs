//! Many takes at once (`imubake batch`, and `watch` later): finding the takes of files, folders
//! and globs, a deterministic shard of them, and converting each one under the ledger
//! ([`crate::ledger`]): skipped when current, `<stem>.error.json` on failure, exactly one set of
//! outputs per take.

use crate::convert::{ConvertSettings, convert, source_sha256, take_stem};
use crate::ledger::{Freshness, Ledger, LedgerEntry, SourceStat, Status, now_ns};
use crate::read::detect_format;
use crate::write::error_report::{ErrorReport, remove_error_report, write_error_report};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::{BTreeMap, HashSet};
use std::fs;
use std::io;
use std::path::{Component, Path, PathBuf};
use std::time::{Duration, Instant};

/// One take of a batch.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BatchTake {
    /// The file or session folder on disk.
    pub path: PathBuf,
    /// Its path relative to its input root, `/`-separated: the ledger's key and the order of
    /// sharding.
    pub rel: String,
    /// Where its outputs go, relative to the output root.
    pub out_dir: PathBuf,
    /// The name of its outputs.
    pub stem: String,
}

impl BatchTake {
    fn new(path: PathBuf, rel: &Path) -> BatchTake {
        let stem = take_stem(&path);
        BatchTake {
            rel: slash(rel),
            out_dir: rel.parent().map(Path::to_path_buf).unwrap_or_default(),
            stem,
            path,
        }
    }

    /// `<relative dir>/<stem>`: two takes with the same key would write the same outputs.
    pub fn output_key(&self) -> String {
        slash(&self.out_dir.join(&self.stem))
    }
}

fn slash(p: &Path) -> String {
    p.components()
        .filter_map(|c| match c {
            Component::Normal(s) => Some(s.to_string_lossy().into_owned()),
            _ => None,
        })
        .collect::<Vec<_>>()
        .join("/")
}

#[derive(Debug, thiserror::Error)]
pub enum DiscoverError {
    #[error("{}: no such file or folder", .0.display())]
    Missing(PathBuf),
    #[error("`{0}` matches no file or folder")]
    NoMatch(String),
    #[error("{}: cannot list: {source}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error(
        "{} and {} would both write `{key}.*`: rename one, or convert them into different --out folders",
        .first.display(), .second.display()
    )]
    Collision {
        first: PathBuf,
        second: PathBuf,
        key: String,
    },
}

/// Whether a folder is itself one take (an x-IMU3 session, a DOT or MTw export).
pub fn is_session_folder(path: &Path) -> bool {
    path.is_dir() && detect_format(path).is_ok()
}

/// The takes of `inputs`: a file is a take (relative to its folder); a session folder is a take
/// (relative to its parent); any other folder contributes its files and session sub-folders,
/// recursively, relative to itself; an input with `*`, `?` or `**` that is not an existing path is
/// a glob, its matches relative to the folder before its first wildcard (matched folders expand
/// like folder inputs). Hidden entries and `exclude` (the output folder) are skipped; a take named
/// twice counts once. Sorted by relative path; two takes with the same outputs are an error.
pub fn discover(
    inputs: &[PathBuf],
    exclude: Option<&Path>,
) -> Result<Vec<BatchTake>, DiscoverError> {
    let exclude = exclude.and_then(|p| p.canonicalize().ok());
    let mut takes = Vec::new();
    for input in inputs {
        let text = input.to_string_lossy();
        if !input.exists() && (text.contains('*') || text.contains('?')) {
            let (base, pattern) = split_glob(input);
            let mut matches = Vec::new();
            glob_walk(&base, Path::new(""), &pattern, &mut matches);
            matches.sort();
            matches.dedup();
            if matches.is_empty() {
                return Err(DiscoverError::NoMatch(text.into_owned()));
            }
            for (path, rel) in matches {
                add_entry(path, &rel, exclude.as_deref(), &mut takes)?;
            }
        } else if input.is_dir() {
            if is_session_folder(input) {
                let rel = PathBuf::from(take_stem(input));
                takes.push(BatchTake::new(input.clone(), &rel));
            } else {
                walk_folder(input, Path::new(""), exclude.as_deref(), &mut takes)?;
            }
        } else if input.exists() {
            let name = input.file_name().map(PathBuf::from).unwrap_or_default();
            takes.push(BatchTake::new(input.clone(), &name));
        } else {
            return Err(DiscoverError::Missing(input.clone()));
        }
    }
    // The same take named twice (a folder and a glob inside it) counts once.
    let mut seen = HashSet::new();
    takes.retain(|t| seen.insert(t.path.canonicalize().unwrap_or_else(|_| t.path.clone())));
    takes.sort_by(|a, b| a.rel.cmp(&b.rel));
    let mut keys: BTreeMap<String, &BatchTake> = BTreeMap::new();
    for t in &takes {
        if let Some(first) = keys.insert(t.output_key(), t) {
            return Err(DiscoverError::Collision {
                first: first.path.clone(),
                second: t.path.clone(),
                key: t.output_key(),
            });
        }
    }
    Ok(takes)
}

fn add_entry(
    path: PathBuf,
    rel: &Path,
    exclude: Option<&Path>,
    takes: &mut Vec<BatchTake>,
) -> Result<(), DiscoverError> {
    if is_excluded(&path, exclude) {
        return Ok(());
    }
    if path.is_dir() {
        if is_session_folder(&path) {
            takes.push(BatchTake::new(path, rel));
        } else {
            walk_folder(&path, rel, exclude, takes)?;
        }
    } else {
        takes.push(BatchTake::new(path, rel));
    }
    Ok(())
}

fn is_excluded(path: &Path, exclude: Option<&Path>) -> bool {
    exclude.is_some_and(|ex| path.canonicalize().is_ok_and(|p| p == ex))
}

fn visible_entries(dir: &Path) -> io::Result<Vec<PathBuf>> {
    let mut entries = Vec::new();
    for entry in fs::read_dir(dir)? {
        let entry = entry?;
        if !entry.file_name().to_string_lossy().starts_with('.') {
            entries.push(entry.path());
        }
    }
    entries.sort();
    Ok(entries)
}

fn walk_folder(
    dir: &Path,
    rel: &Path,
    exclude: Option<&Path>,
    takes: &mut Vec<BatchTake>,
) -> Result<(), DiscoverError> {
    let entries = visible_entries(dir).map_err(|source| DiscoverError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    for path in entries {
        let name = path.file_name().map(PathBuf::from).unwrap_or_default();
        add_entry(path, &rel.join(name), exclude, takes)?;
    }
    Ok(())
}

/// The folder before the first wildcard component, and the components from there on.
fn split_glob(pattern: &Path) -> (PathBuf, Vec<String>) {
    let mut base = PathBuf::new();
    let mut rest = Vec::new();
    for c in pattern.components() {
        let s = c.as_os_str().to_string_lossy();
        if rest.is_empty() && !s.contains('*') && !s.contains('?') {
            base.push(c.as_os_str());
        } else {
            rest.push(s.into_owned());
        }
    }
    if base.as_os_str().is_empty() {
        base = PathBuf::from(".");
    }
    (base, rest)
}

fn glob_walk(path: &Path, rel: &Path, pattern: &[String], out: &mut Vec<(PathBuf, PathBuf)>) {
    let Some((first, rest)) = pattern.split_first() else {
        if path.exists() {
            out.push((path.to_path_buf(), rel.to_path_buf()));
        }
        return;
    };
    let Ok(entries) = fs::read_dir(path) else {
        return;
    };
    let mut entries: Vec<(String, PathBuf)> = entries
        .filter_map(Result::ok)
        .map(|e| (e.file_name().to_string_lossy().into_owned(), e.path()))
        .collect();
    entries.sort();
    if first == "**" {
        // Zero folders, or one more folder and still `**`.
        glob_walk(path, rel, rest, out);
        for (name, sub) in entries {
            if !name.starts_with('.') && sub.is_dir() {
                glob_walk(&sub, &rel.join(&name), pattern, out);
            }
        }
        return;
    }
    for (name, sub) in entries {
        if name.starts_with('.') && !first.starts_with('.') {
            continue;
        }
        if wildcard_match(first, &name) {
            glob_walk(&sub, &rel.join(&name), rest, out);
        }
    }
}

/// `*` (any run of characters) and `?` (one character) matching of a whole name.
pub fn wildcard_match(pattern: &str, name: &str) -> bool {
    let p: Vec<char> = pattern.chars().collect();
    let n: Vec<char> = name.chars().collect();
    let (mut pi, mut ni) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while ni < n.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == n[ni]) {
            pi += 1;
            ni += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some((pi, ni));
            pi += 1;
        } else if let Some((sp, sn)) = star {
            pi = sp + 1;
            ni = sn + 1;
            star = Some((sp, sn + 1));
        } else {
            return false;
        }
    }
    p[pi..].iter().all(|&c| c == '*')
}

/// A slice of a batch: the takes whose index in relative-path order is `index` modulo `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    pub fn new(index: usize, count: usize) -> Result<Shard, String> {
        if count == 0 {
            Err("the shard count must be at least 1".into())
        } else if index >= count {
            Err(format!(
                "shard index {index} is not below the count {count} (indexes start at 0)"
            ))
        } else {
            Ok(Shard { index, count })
        }
    }

    /// The shard from the environment, and the variables it came from: a Kubernetes Indexed Job's
    /// `JOB_COMPLETION_INDEX` (Kubernetes sets no count variable: `IMUBAKE_SHARD_COUNT` gives it,
    /// e.g. the Job's `completions`), or a Slurm array's `SLURM_ARRAY_TASK_ID` with
    /// `SLURM_ARRAY_TASK_COUNT` (index = (ID − `SLURM_ARRAY_TASK_MIN`) / `SLURM_ARRAY_TASK_STEP`;
    /// `IMUBAKE_SHARD_COUNT` overrides the count). `None` when neither index is set.
    pub fn from_env(
        var: impl Fn(&str) -> Option<String>,
    ) -> Result<Option<(Shard, &'static str)>, String> {
        let num = |name: &str| -> Result<Option<usize>, String> {
            match var(name) {
                None => Ok(None),
                Some(v) if v.trim().is_empty() => Ok(None),
                Some(v) => v
                    .trim()
                    .parse()
                    .map(Some)
                    .map_err(|_| format!("{name}=`{v}` is not a whole number ≥ 0")),
            }
        };
        let override_count = num("IMUBAKE_SHARD_COUNT")?;
        if let Some(index) = num("JOB_COMPLETION_INDEX")? {
            let count = override_count.ok_or(
                "JOB_COMPLETION_INDEX is set but Kubernetes gives no count: set IMUBAKE_SHARD_COUNT \
                 to the Job's completions, or pass --shard $(JOB_COMPLETION_INDEX)/N",
            )?;
            return Ok(Some((
                Shard::new(index, count)?,
                "JOB_COMPLETION_INDEX, IMUBAKE_SHARD_COUNT",
            )));
        }
        if let Some(id) = num("SLURM_ARRAY_TASK_ID")? {
            let min = num("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let step = num("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
            let count = match override_count {
                Some(c) => c,
                None => num("SLURM_ARRAY_TASK_COUNT")?.ok_or(
                    "SLURM_ARRAY_TASK_ID is set without SLURM_ARRAY_TASK_COUNT: set \
                     IMUBAKE_SHARD_COUNT or pass --shard I/N",
                )?,
            };
            let offset = id.checked_sub(min).ok_or(format!(
                "SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"
            ))?;
            if offset % step != 0 {
                return Err(format!(
                    "SLURM_ARRAY_TASK_ID {id} is not on the array's step {step} from {min}"
                ));
            }
            return Ok(Some((
                Shard::new(offset / step, count)?,
                "SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT",
            )));
        }
        Ok(None)
    }

    /// The takes of this shard (`takes` sorted by relative path, as [`discover`] returns them).
    pub fn select(self, takes: Vec<BatchTake>) -> Vec<BatchTake> {
        let mut takes = takes;
        takes.sort_by(|a, b| a.rel.cmp(&b.rel));
        takes
            .into_iter()
            .enumerate()
            .filter(|(i, _)| i % self.count == self.index)
            .map(|(_, t)| t)
            .collect()
    }
}

impl std::str::FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("`{s}`: expected I/N, e.g. 0/4"))?;
        let parse = |v: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|_| format!("`{s}`: expected I/N with whole numbers, e.g. 0/4"))
        };
        Shard::new(parse(i)?, parse(n)?)
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TakeStatus {
    Converted,
    Failed,
    Skipped,
}

/// What happened to one take.
#[derive(Debug, Clone, Serialize)]
pub struct TakeResult {
    pub source: String,
    pub status: TakeStatus,
    /// Outputs relative to the output root (converted and skipped takes).
    pub outputs: Vec<String>,
    /// The error report, relative to the output root (failed takes).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_report: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Warnings of the conversion.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// How long [`process_take`] took (the ledger check, and the conversion if there was one).
    #[serde(skip)]
    pub duration: Duration,
}

impl TakeResult {
    /// Logs the take (`tracing`): one line for a converted (info) or failed (error) take with its
    /// duration, and one warning line per warning of its conversion; a skipped take only at
    /// debug level.
    pub fn log(&self) {
        let source = self.source.as_str();
        let duration_ms = u64::try_from(self.duration.as_millis()).unwrap_or(u64::MAX);
        match self.status {
            TakeStatus::Converted => {
                tracing::info!(source, duration_ms, outputs = ?self.outputs, "converted")
            }
            TakeStatus::Failed => tracing::error!(
                source,
                duration_ms,
                error_report = self.error_report.as_deref().unwrap_or(""),
                reason = self.reason.as_deref().unwrap_or(""),
                "failed"
            ),
            TakeStatus::Skipped => tracing::debug!(source, duration_ms, "current, skipped"),
        }
        for warning in &self.warnings {
            tracing::warn!(source, "{warning}");
        }
    }
}

/// The extensions a take's outputs may have, the sidecar first (removed first: without it a take
/// is not complete).
const OUTPUT_SUFFIXES: [&str; 6] = [
    ".imubake.json",
    ".bvh",
    ".glb",
    ".gltf",
    ".bin",
    ".report.html",
];

fn rel_output(take: &BatchTake, name: &str) -> String {
    slash(&take.out_dir.join(name))
}

fn remove_quietly(path: &Path) {
    let _ = fs::remove_file(path);
}

/// Converts one take unless the ledger says its outputs are current, appending the outcome to the
/// ledger: outputs of an earlier conversion that the new one did not write are removed, and so is
/// `<stem>.error.json`; on failure the take's outputs are removed (sidecar first) and
/// `<stem>.error.json` written.
pub fn process_take(
    take: &BatchTake,
    out_root: &Path,
    settings: &ConvertSettings,
    fingerprint: &str,
    ledger: &Ledger,
) -> TakeResult {
    let clock = Instant::now();
    let mut result = process_take_untimed(take, out_root, settings, fingerprint, ledger);
    result.duration = clock.elapsed();
    result
}

fn process_take_untimed(
    take: &BatchTake,
    out_root: &Path,
    settings: &ConvertSettings,
    fingerprint: &str,
    ledger: &Ledger,
) -> TakeResult {
    let out_dir = out_root.join(&take.out_dir);
    let stat = SourceStat::of(&take.path);
    if let Ok(stat) = stat {
        match ledger.is_current(&take.rel, stat, fingerprint, || source_sha256(&take.path)) {
            Ok(Freshness::Current) => return skipped(take, ledger),
            Ok(Freshness::CurrentTouched(entry)) => {
                let _ = ledger.append_shared(&entry);
                return skipped(take, ledger);
            }
            _ => {}
        }
    }
    let started = now_ns();
    let result = fs::create_dir_all(&out_dir)
        .map_err(|e| format!("{}: cannot create: {e}", out_dir.display()))
        .and_then(|()| {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                convert(&take.path, &out_dir, settings)
            }))
            .map_err(|panic| {
                let msg = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                format!(
                    "{}: internal error (please report): {msg}",
                    take.path.display()
                )
            })
        });
    let previous = ledger.latest(&take.rel);
    let stat = stat.ok();
    // A failed conversion and a panic both end in an error report.
    let result = match result {
        Ok(Ok(outcome)) => Ok(outcome),
        Ok(Err(error)) => Err(ErrorReport::from_convert_error(&take.rel, &error)),
        Err(message) => Err(ErrorReport::from_message(&take.rel, &message)),
    };
    match result {
        Ok(outcome) => {
            let mut outputs: Vec<String> = outcome
                .sidecar
                .outputs
                .iter()
                .map(|o| rel_output(take, &o.path))
                .collect();
            outputs.push(rel_output(take, &format!("{}.imubake.json", take.stem)));
            if let Some(prev) = previous {
                for old in prev.outputs.iter().filter(|o| !outputs.contains(o)) {
                    if prev.status == Status::Converted {
                        remove_quietly(&out_root.join(old));
                    }
                }
            }
            let mut result = TakeResult {
                source: take.rel.clone(),
                status: TakeStatus::Converted,
                outputs: outputs.clone(),
                error_report: None,
                reason: None,
                warnings: outcome.sidecar.warnings.clone(),
                duration: Duration::ZERO,
            };
            let entry = LedgerEntry {
                source: take.rel.clone(),
                size: stat.map_or(0, |s| s.size),
                mtime_ns: stat.and_then(|s| s.mtime_ns),
                sha256: outcome.sidecar.source.sha256.clone(),
                outputs,
                status: Status::Converted,
                settings: fingerprint.to_string(),
                error: None,
                converted_at_ns: started,
                imubake_version: env!("CARGO_PKG_VERSION").to_string(),
            };
            let cleanup = remove_error_report(&out_dir, &take.stem);
            if let Err(e) = cleanup.and_then(|()| ledger.append_shared(&entry)) {
                result.status = TakeStatus::Failed;
                result.reason = Some(format!(
                    "{}: converted, but cannot record it in {}: {e}",
                    take.rel,
                    ledger.path().display()
                ));
            }
            result
        }
        Err(report) => fail(
            take,
            out_root,
            &out_dir,
            report,
            stat,
            fingerprint,
            started,
            ledger,
        ),
    }
}

fn skipped(take: &BatchTake, ledger: &Ledger) -> TakeResult {
    TakeResult {
        source: take.rel.clone(),
        status: TakeStatus::Skipped,
        outputs: ledger
            .latest(&take.rel)
            .map(|e| e.outputs.clone())
            .unwrap_or_default(),
        error_report: None,
        reason: None,
        warnings: Vec::new(),
        duration: Duration::ZERO,
    }
}

#[allow(clippy::too_many_arguments)]
fn fail(
    take: &BatchTake,
    out_root: &Path,
    out_dir: &Path,
    report: ErrorReport,
    stat: Option<SourceStat>,
    fingerprint: &str,
    started: u64,
    ledger: &Ledger,
) -> TakeResult {
    // No outputs of an earlier version stay beside the error: the sidecar first.
    for suffix in OUTPUT_SUFFIXES {
        remove_quietly(&out_dir.join(format!("{}{suffix}", take.stem)));
    }
    if let Some(prev) = ledger.latest(&take.rel) {
        for old in &prev.outputs {
            if !old.ends_with(".error.json") {
                remove_quietly(&out_root.join(old));
            }
        }
    }
    let report_rel = rel_output(take, &format!("{}.error.json", take.stem));
    let mut reason = report.reason.clone();
    if let Err(e) = write_error_report(out_dir, &take.stem, &report) {
        reason.push_str(&format!(" (and cannot write {report_rel}: {e})"));
    }
    let entry = LedgerEntry {
        source: take.rel.clone(),
        size: stat.map_or(0, |s| s.size),
        mtime_ns: stat.and_then(|s| s.mtime_ns),
        sha256: source_sha256(&take.path).unwrap_or_default(),
        outputs: vec![report_rel.clone()],
        status: Status::Failed,
        settings: fingerprint.to_string(),
        error: Some(reason.clone()),
        converted_at_ns: started,
        imubake_version: env!("CARGO_PKG_VERSION").to_string(),
    };
    if let Err(e) = ledger.append_shared(&entry) {
        reason.push_str(&format!(
            " (and cannot record it in {}: {e})",
            ledger.path().display()
        ));
    }
    TakeResult {
        source: take.rel.clone(),
        status: TakeStatus::Failed,
        outputs: Vec::new(),
        error_report: Some(report_rel),
        reason: Some(reason),
        warnings: Vec::new(),
        duration: Duration::ZERO,
    }
}

/// Counts of a batch run.
#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub struct Summary {
    pub converted: usize,
    pub failed: usize,
    pub skipped: usize,
}

impl Summary {
    pub fn of(results: &[TakeResult]) -> Summary {
        let mut s = Summary::default();
        for r in results {
            match r.status {
                TakeStatus::Converted => s.converted += 1,
                TakeStatus::Failed => s.failed += 1,
                TakeStatus::Skipped => s.skipped += 1,
            }
        }
        s
    }
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "converted {}, failed {}, skipped {}",
            self.converted, self.failed, self.skipped
        )
    }
}

/// Converts `takes` into `out_root` on `jobs` threads (0: one per core), calling `on_result` as
/// each take finishes (logging is the caller's: [`TakeResult::log`]). Results are in the order of
/// `takes`.
pub fn run(
    takes: &[BatchTake],
    out_root: &Path,
    settings: &ConvertSettings,
    jobs: usize,
    on_result: &(dyn Fn(&TakeResult) + Sync),
) -> io::Result<Vec<TakeResult>> {
    fs::create_dir_all(out_root)?;
    let ledger = Ledger::load(out_root)?;
    let fingerprint = crate::ledger::settings_fingerprint(settings);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .build()
        .map_err(io::Error::other)?;
    Ok(pool.install(|| {
        takes
            .par_iter()
            .with_max_len(1)
            .map(|take| {
                let r = process_take(take, out_root, settings, &fingerprint, &ledger);
                on_result(&r);
                r
            })
            .collect()
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wildcards() {
        assert!(wildcard_match("*.log", "a.log"));
        assert!(wildcard_match("*.log", ".log"));
        assert!(!wildcard_match("*.log", "a.logs"));
        assert!(wildcard_match("a?c*", "abcdef"));
        assert!(!wildcard_match("a?c", "ac"));
        assert!(wildcard_match("*a*b*", "xxaxxbxx"));
        assert!(!wildcard_match("*a*b*", "xxbxxaxx"));
        assert!(wildcard_match("**", ""));
    }

    #[test]
    fn shards_from_the_environment() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                vars.iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| v.to_string())
            }
        };
        assert_eq!(Shard::from_env(env(&[])).unwrap(), None);
        assert!(Shard::from_env(env(&[("JOB_COMPLETION_INDEX", "2")])).is_err());
        let (s, _) = Shard::from_env(env(&[
            ("JOB_COMPLETION_INDEX", "2"),
            ("IMUBAKE_SHARD_COUNT", "4"),
        ]))
        .unwrap()
        .unwrap();
        assert_eq!(s, Shard::new(2, 4).unwrap());
        let (s, _) = Shard::from_env(env(&[
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_MIN", "5"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ]))
        .unwrap()
        .unwrap();
        assert_eq!(s, Shard::new(2, 3).unwrap());
        assert!(
            Shard::from_env(env(&[
                ("SLURM_ARRAY_TASK_ID", "3"),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ]))
            .is_err(),
            "index 3 of 3"
        );
        assert_eq!("1/3".parse::<Shard>().unwrap(), Shard::new(1, 3).unwrap());
        assert!("3/3".parse::<Shard>().is_err());
        assert!("1/0".parse::<Shard>().is_err());
        assert!("x".parse::<Shard>().is_err());
    }
}
