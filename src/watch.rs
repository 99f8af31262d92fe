//! `imubake watch`: converts an inbox's backlog, then each take as it arrives or changes, under
//! the same ledger and per-take conversion as `batch` ([`crate::batch::process_take`]).
//!
//! Takes are found with [`crate::batch::discover`] (each top-level file or session folder of the
//! inbox is one take; FIFOs, devices, symlinks out of the inbox, symlink cycles and config,
//! mapping and rig files are not, each reported once); hidden and temporary names (`.*`,
//! `*.part`, `*.tmp`, `*~`, `*.crdownload`) are ignored. A take is complete when its file
//! is closed after writing or renamed into place (file-system events), or when its size and
//! modification time (a session folder: summed over its files, the latest mtime) stay the same
//! over two looks at least [`WatchOptions::settle`] apart (500 ms by default) — and, on Linux, no
//! process still has it open for writing ([`held_for_writing`]: a writer pausing between chunks
//! through one open file is waited for, however long it pauses). Changes are noticed by
//! file-system events (`notify` through `notify-debouncer-full`, [`DEBOUNCE`]) or by polling;
//! either way the inbox is rescanned, so a missed event only delays a take.
//!
//! Each conversion runs on a worker thread while this one keeps watching the stop flag: told to
//! stop (SIGINT, SIGTERM), the watcher lets a take in progress finish for up to [`FINISH_GRACE`],
//! then abandons it ([`crate::write::abandon_writes`]: its temporary files removed, no ledger
//! line) and returns.
//!
//! A take that failed for the environment's sake — its outputs or its ledger line could not be
//! written: a read-only or full output folder, a quota, a file size limit
//! ([`crate::batch::environmental`]) — is tried again while the watcher runs, [`RETRY_FIRST`]
//! after the failure, then after twice as long each time up to [`RETRY_MAX`], each attempt told
//! on the terminal; a take whose own data or settings failed it waits, as before, for the file or
//! the settings to change.
//!
//! One watcher per output folder: [`WatchLock`] holds an exclusive lock (`flock`) on
//! `<out>/.imubake/watch.lock`, which names the holder's PID and inbox, for as long as the watch
//! runs; a second watcher on the same output stops at once with [`WatchError::AlreadyWatched`].
//! The kernel releases the lock when its process dies, however it dies, so a lock file left by a
//! killed watcher never blocks the next one. (`batch` takes no lock: its shards share a ledger on
//! purpose.)
//!
//! Everything worth telling is a `tracing` event (one `converted`/`failed` line per take with its
//! duration, [`crate::batch::TakeResult::log`]); the binary installs the subscriber.

use crate::batch::{
    Attempt, BatchTake, DiscoverOptions, Skipped, Summary, TakeJob, TakeResult, TakeStatus,
    attempt_take, discover,
};
use crate::config::PlanError;
use crate::convert::{Plan, source_sha256};
use crate::ledger::{
    FINGERPRINT_SCHEMA, Ledger, SourceStat, Status, fingerprint_schema, settings_fingerprint,
};
use crate::write::error_report::ErrorReport;
use notify::RecursiveMode;
use notify::event::{AccessKind, AccessMode, EventKind, ModifyKind, RenameMode};
use notify_debouncer_full::{DebounceEventResult, new_debouncer};
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, HashSet};
use std::fs;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tracing::{debug, error, info, warn};

/// The config file an inbox may hold.
pub const INBOX_CONFIG: &str = crate::batch::FOLDER_CONFIG;

/// How long a take in progress may go on after a stop signal before it is abandoned.
pub const FINISH_GRACE: Duration = Duration::from_secs(2);

/// The file-system event debouncer's timeout. `notify-debouncer-full` holds each event for this
/// long after it happened (it is not a quiet period: a steady writer does not postpone it), so it
/// adds straight to the close→sidecar latency, whose budget is 250 ms over `convert`. 50 ms is
/// enough to pair a rename's two halves and to fold the burst one write produces (create,
/// modifies, close-write) into one wake-up, and leaves most of the budget to the scan, the
/// `/proc` check and the conversion.
pub const DEBOUNCE: Duration = Duration::from_millis(50);

/// How long after a take failed for the environment's sake it is tried again the first time;
/// each further failure doubles the wait, up to [`RETRY_MAX`].
pub const RETRY_FIRST: Duration = Duration::from_secs(1);

/// The longest wait between two attempts at a take the environment failed.
pub const RETRY_MAX: Duration = Duration::from_secs(60);

/// The wait after the `attempts`-th failure in a row (1: [`RETRY_FIRST`]).
pub fn retry_delay(attempts: u32) -> Duration {
    let doublings = attempts.saturating_sub(1).min(16);
    (RETRY_FIRST * (1u32 << doublings)).min(RETRY_MAX)
}

/// The lock file of an output folder's watcher.
pub fn lock_path(out: &Path) -> PathBuf {
    out.join(".imubake").join("watch.lock")
}

/// What a watcher's lock file says of it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LockHolder {
    pub pid: u32,
    /// The inbox it follows (absolute when it could be made so).
    pub inbox: PathBuf,
}

/// Why a watch could not run.
#[derive(Debug, thiserror::Error)]
pub enum WatchError {
    /// Another watcher holds the output folder's lock.
    #[error("{}", already_watched(.out, .lock, .holder.as_ref()))]
    AlreadyWatched {
        out: PathBuf,
        lock: PathBuf,
        /// What the lock file says of the watcher holding it (`None`: it says nothing readable).
        holder: Option<LockHolder>,
    },
    #[error(transparent)]
    Io(#[from] io::Error),
}

fn already_watched(out: &Path, lock: &Path, holder: Option<&LockHolder>) -> String {
    let who = match holder {
        Some(h) => format!("pid {}, inbox {}", h.pid, h.inbox.display()),
        None => format!("its pid and inbox unknown: {} does not say", lock.display()),
    };
    format!(
        "{}: another `imubake watch` is following this output folder ({who}); one watcher per \
         output folder: stop that one, or give this one another --out",
        out.display()
    )
}

/// The lock that makes a watcher the only one on its output folder: an exclusive `flock` on
/// `<out>/.imubake/watch.lock` (through `File::try_lock`), held until it is dropped or the
/// process dies (the kernel releases it then, so a killed watcher's lock file blocks nothing).
/// The file holds the holder's [`LockHolder`] as JSON, for the message a second watcher gives;
/// it is never removed (removing it could let two watchers lock two different files).
#[derive(Debug)]
pub struct WatchLock {
    _file: fs::File,
}

impl WatchLock {
    /// Takes the lock of `out` for a watcher of `inbox`, or says who holds it.
    pub fn acquire(out: &Path, inbox: &Path) -> Result<WatchLock, WatchError> {
        let path = lock_path(out);
        if let Some(dir) = path.parent() {
            fs::create_dir_all(dir)?;
        }
        let mut file = fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(fs::TryLockError::WouldBlock) => {
                return Err(WatchError::AlreadyWatched {
                    out: out.to_path_buf(),
                    holder: read_holder(&path),
                    lock: path,
                });
            }
            Err(fs::TryLockError::Error(e)) => return Err(e.into()),
        }
        let holder = LockHolder {
            pid: std::process::id(),
            inbox: inbox.canonicalize().unwrap_or_else(|_| inbox.to_path_buf()),
        };
        let mut json = serde_json::to_vec(&holder).map_err(io::Error::other)?;
        json.push(b'\n');
        file.set_len(0)?;
        file.write_all(&json)?;
        Ok(WatchLock { _file: file })
    }
}

/// The holder a lock file names. The holder writes it just after taking the lock, so an empty
/// file is read again for up to a second.
fn read_holder(path: &Path) -> Option<LockHolder> {
    let deadline = Instant::now() + Duration::from_secs(1);
    loop {
        let mut text = String::new();
        let read = fs::File::open(path).and_then(|mut f| f.read_to_string(&mut text));
        if read.is_ok()
            && let Ok(holder) = serde_json::from_str::<LockHolder>(text.trim())
        {
            return Some(holder);
        }
        if Instant::now() >= deadline {
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[derive(Debug, Clone)]
pub struct WatchOptions {
    pub inbox: PathBuf,
    pub out: PathBuf,
    /// Poll every this often instead of waiting for file-system events.
    pub poll: Option<Duration>,
    /// Convert the backlog and return.
    pub once: bool,
    /// A change of settings reconverts takes converted under other settings.
    pub reconvert: bool,
    /// How long a take's size and mtime must stay the same before it counts as complete (a file
    /// closed after writing or renamed into place, where the platform reports it, is complete at
    /// once). On Linux a file some process still has open for writing is never complete, so this
    /// need not outlast a writer's pauses; elsewhere it must.
    pub settle: Duration,
    /// The config file to follow (`--config`, else `<inbox>/imubake.yaml`).
    pub config: PathBuf,
    /// Follow symlinks whose targets are outside the inbox.
    pub follow_symlinks: bool,
}

impl WatchOptions {
    pub fn new(inbox: PathBuf, out: PathBuf, config: Option<PathBuf>) -> WatchOptions {
        let config = config.unwrap_or_else(|| inbox.join(INBOX_CONFIG));
        WatchOptions {
            inbox,
            out,
            poll: None,
            once: false,
            reconvert: false,
            settle: Duration::from_millis(500),
            config,
            follow_symlinks: false,
        }
    }
}

/// Whether a file or folder name is hidden or temporary (a download or copy in progress).
pub fn is_temporary_name(name: &str) -> bool {
    name.starts_with('.')
        || name.ends_with(".part")
        || name.ends_with(".tmp")
        || name.ends_with('~')
        || name.ends_with(".crdownload")
}

/// Whether a session folder holds a temporary name (not hidden: hidden entries are ignored).
fn has_temporary_entry(dir: &Path) -> bool {
    let Ok(entries) = fs::read_dir(dir) else {
        return false;
    };
    entries.filter_map(Result::ok).any(|e| {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') {
            return false;
        }
        is_temporary_name(&name) || (e.path().is_dir() && has_temporary_entry(&e.path()))
    })
}

/// A config file's identity: absent, or its size and mtime.
fn config_stat(path: &Path) -> Option<SourceStat> {
    SourceStat::of(path).ok()
}

/// Which of `candidates` (canonical paths; a folder stands for every file under it) some process
/// has open for writing: on Linux, the `/proc/<pid>/fd/*` links that point at or under a
/// candidate, with `O_WRONLY` or `O_RDWR` in `/proc/<pid>/fdinfo/<fd>`'s `flags`. Only processes
/// whose `/proc` entries we may read are seen (our user's, or all as root); writers on other
/// machines (network shares) are not. Elsewhere: none. One pass over `/proc` for all candidates.
pub fn held_for_writing(candidates: &[PathBuf]) -> HashSet<PathBuf> {
    let mut held = HashSet::new();
    if candidates.is_empty() || !cfg!(target_os = "linux") {
        return held;
    }
    let wanted: HashSet<&Path> = candidates.iter().map(PathBuf::as_path).collect();
    let Ok(procs) = fs::read_dir("/proc") else {
        return held;
    };
    for proc in procs.filter_map(Result::ok) {
        let pid = proc.file_name();
        if !pid.to_string_lossy().bytes().all(|b| b.is_ascii_digit()) {
            continue;
        }
        let Ok(fds) = fs::read_dir(proc.path().join("fd")) else {
            continue;
        };
        for fd in fds.filter_map(Result::ok) {
            let Ok(target) = fs::read_link(fd.path()) else {
                continue;
            };
            let Some(hit) = target.ancestors().find(|a| wanted.contains(a)) else {
                continue;
            };
            if held.contains(hit) {
                continue;
            }
            let info = proc.path().join("fdinfo").join(fd.file_name());
            let writing = fs::read_to_string(info)
                .ok()
                .and_then(|text| fdinfo_flags(&text))
                .is_some_and(|flags| flags & 0o3 != 0);
            if writing {
                held.insert(hit.to_path_buf());
            }
        }
    }
    held
}

/// The `flags:` field (octal) of a `/proc/<pid>/fdinfo/<fd>`.
fn fdinfo_flags(text: &str) -> Option<u32> {
    let line = text.lines().find(|l| l.starts_with("flags:"))?;
    u32::from_str_radix(line["flags:".len()..].trim(), 8).ok()
}

/// A take seen changing.
#[derive(Debug, Clone, Copy)]
struct Pending {
    /// The stat last seen, and since when.
    stat: SourceStat,
    since: Instant,
    /// Settled, but still being written (open for writing, a temporary file inside): looked at
    /// again on the next event or poll rather than at a settle deadline.
    busy: bool,
}

/// A take the environment failed: tried again at `at` unless it changes first.
#[derive(Debug, Clone, Copy)]
struct Retry {
    /// The take's stat when it failed.
    stat: SourceStat,
    /// Failures in a row.
    attempts: u32,
    at: Instant,
}

/// A plan and its fingerprint.
type Resolved = (Arc<Plan>, String);

/// The stat of each file a plan read (mapping, rig, subject, …): a change resolves it again.
type FileStats = Vec<(PathBuf, Option<SourceStat>)>;

fn file_stats(plan: &Plan) -> FileStats {
    plan.files()
        .into_iter()
        .map(|f| (f.to_path_buf(), config_stat(f)))
        .collect()
}

/// Whether a file of `stats` changed since they were taken.
fn files_changed(stats: &FileStats) -> bool {
    stats.iter().any(|(path, stat)| config_stat(path) != *stat)
}

/// A subfolder config's stat when last loaded, the stats of the files its plan read, and its
/// last good plan and fingerprint.
type FolderSettings = (Option<SourceStat>, FileStats, Option<Resolved>);

/// The follower of one inbox.
struct Watch<'a> {
    opts: &'a WatchOptions,
    load_plan: &'a dyn Fn(Option<&Path>) -> Result<Plan, PlanError>,
    plan: Arc<Plan>,
    fingerprint: String,
    config_seen: Option<SourceStat>,
    /// The files the inbox's plan read, as they were when it was resolved.
    files_seen: FileStats,
    /// Shared with the conversion's worker thread.
    ledger: Arc<Ledger>,
    /// Takes handled at this size, mtime and ctime.
    done: HashMap<String, SourceStat>,
    /// Takes seen changing.
    pending: HashMap<String, Pending>,
    last_discover_error: Option<String>,
    /// Entries passed over by discovery and already reported (each is reported once while it
    /// stays).
    reported: HashSet<Skipped>,
    /// A subfolder's own `imubake.yaml`: its stat when loaded, and its settings and fingerprint
    /// (the last good ones when it became bad).
    folder_settings: HashMap<PathBuf, FolderSettings>,
    /// Files (or folders) reported closed after writing or renamed into place since the last
    /// scan.
    closed: HashSet<PathBuf>,
    /// A take was abandoned after a stop signal: the watch is over.
    abandoned: bool,
    /// Each take's latest outcome in this run, which the summary counts ([`Outcomes`]).
    outcomes: Outcomes,
    /// Takes the environment failed, waiting to be tried again.
    retries: HashMap<String, Retry>,
}

/// Each take's latest outcome in a watch run: a take that failed and then converted (its
/// settings fixed, the file rewritten) counts as converted, one that converted and then failed
/// as failed, and a take converted or failed before is not made "skipped" by a later look that
/// found it current. The summary counts each take once.
#[derive(Debug, Default)]
struct Outcomes(HashMap<String, TakeStatus>);

impl Outcomes {
    fn record(&mut self, take: &str, status: TakeStatus) {
        let earlier = self.0.get(take).copied();
        let keep_earlier = status == TakeStatus::Skipped
            && matches!(earlier, Some(TakeStatus::Converted | TakeStatus::Failed));
        if !keep_earlier {
            self.0.insert(take.to_string(), status);
        }
    }

    fn summary(&self) -> Summary {
        let mut s = Summary::default();
        for status in self.0.values() {
            match status {
                TakeStatus::Converted => s.converted += 1,
                TakeStatus::Failed => s.failed += 1,
                TakeStatus::Skipped => s.skipped += 1,
                TakeStatus::Abandoned => s.abandoned += 1,
            }
        }
        s
    }
}

/// The take's line on the terminal ([`TakeResult::log`]); a failed take's also gives its error
/// report's hint, what to do about it, when the report has one.
fn log_result(result: &TakeResult, out: &Path) {
    let hint = match (&result.status, &result.error_report) {
        (TakeStatus::Failed, Some(report)) => fs::read(out.join(report))
            .ok()
            .and_then(|bytes| serde_json::from_slice::<ErrorReport>(&bytes).ok())
            .and_then(|report| report.hint),
        _ => None,
    };
    let Some(hint) = hint else {
        result.log();
        return;
    };
    error!(
        source = result.source.as_str(),
        duration_ms = u64::try_from(result.duration.as_millis()).unwrap_or(u64::MAX),
        error_report = result.error_report.as_deref().unwrap_or(""),
        reason = result.reason.as_deref().unwrap_or(""),
        hint = hint.as_str(),
        "failed"
    );
}

impl Watch<'_> {
    fn config_arg(&self) -> Option<&Path> {
        self.opts
            .config
            .is_file()
            .then_some(self.opts.config.as_path())
    }

    /// Resolves the plan again when the config file or a file the plan read changed; a bad
    /// config is reported and the last good plan stays.
    fn refresh_config(&mut self) {
        let stat = config_stat(&self.opts.config);
        if stat == self.config_seen && !files_changed(&self.files_seen) {
            return;
        }
        self.config_seen = stat;
        match (self.load_plan)(self.config_arg()) {
            Ok(plan) => {
                self.files_seen = file_stats(&plan);
                let fingerprint = settings_fingerprint(&plan);
                if fingerprint != self.fingerprint {
                    info!(
                        config = %self.opts.config.display(),
                        "settings changed; takes that failed are retried, {}",
                        if self.opts.reconvert {
                            "and converted takes are reconverted"
                        } else {
                            "new takes use them (--reconvert to redo converted ones)"
                        }
                    );
                    self.plan = Arc::new(plan);
                    self.fingerprint = fingerprint;
                    if self.opts.reconvert {
                        self.done.clear();
                    }
                }
            }
            Err(e) => error!(
                config = %self.opts.config.display(),
                "{e} (keeping the last good settings)"
            ),
        }
    }

    fn takes(&mut self) -> Vec<BatchTake> {
        let options = DiscoverOptions {
            exclude: Some(&self.opts.out),
            follow_symlinks: self.opts.follow_symlinks,
        };
        match discover(std::slice::from_ref(&self.opts.inbox), options) {
            Ok(found) => {
                self.last_discover_error = None;
                let now: HashSet<Skipped> = found.skipped.into_iter().collect();
                for skipped in now.difference(&self.reported) {
                    let path = skipped.path.display();
                    if skipped.reason.is_warning() {
                        warn!(path = %path, "{}", skipped.reason);
                    } else {
                        debug!(path = %path, "{}", skipped.reason);
                    }
                }
                self.reported = now;
                let config = self.opts.config.canonicalize().ok();
                found
                    .takes
                    .into_iter()
                    .filter(|t| {
                        let temp = Path::new(&t.rel)
                            .components()
                            .any(|c| is_temporary_name(&c.as_os_str().to_string_lossy()));
                        // --config inside the inbox, even while it does not parse.
                        let is_config = config.is_some()
                            && t.path.canonicalize().ok().as_ref() == config.as_ref();
                        !temp && !is_config
                    })
                    .collect()
            }
            Err(e) => {
                let msg = e.to_string();
                if self.last_discover_error.as_ref() != Some(&msg) {
                    error!(inbox = %self.opts.inbox.display(), "{msg}");
                }
                self.last_discover_error = Some(msg);
                Vec::new()
            }
        }
    }

    /// The nearest subfolder `imubake.yaml` between the take and the inbox, if any.
    fn folder_config(&self, take: &BatchTake) -> Option<PathBuf> {
        let mut dir = take.path.parent()?;
        while dir != self.opts.inbox && dir.starts_with(&self.opts.inbox) {
            let config = dir.join(INBOX_CONFIG);
            if config.is_file() {
                return Some(config);
            }
            dir = dir.parent()?;
        }
        None
    }

    /// The plan and fingerprint for a take: a subfolder's own `imubake.yaml` (resolved again when
    /// it or a file its plan read changes; a bad one is reported and its last good plan stays,
    /// else the inbox's), else the inbox's.
    fn settings_for(&mut self, take: &BatchTake) -> Resolved {
        let Some(config) = self.folder_config(take) else {
            return (Arc::clone(&self.plan), self.fingerprint.clone());
        };
        let stat = config_stat(&config);
        let entry = self
            .folder_settings
            .entry(config.clone())
            .or_insert((None, Vec::new(), None));
        if entry.0 != stat || entry.2.is_none() && stat.is_none() || files_changed(&entry.1) {
            entry.0 = stat;
            match (self.load_plan)(Some(&config)) {
                Ok(plan) => {
                    entry.1 = file_stats(&plan);
                    let fingerprint = settings_fingerprint(&plan);
                    entry.2 = Some((Arc::new(plan), fingerprint));
                }
                Err(e) => error!(
                    config = %config.display(),
                    "{e} (keeping the last good settings for this folder)"
                ),
            }
        }
        entry
            .2
            .clone()
            .unwrap_or_else(|| (Arc::clone(&self.plan), self.fingerprint.clone()))
    }

    /// Whether the take was converted from this content, under whatever settings (without
    /// `--reconvert`, a change of settings leaves converted takes alone) of this fingerprint
    /// schema (a ledger line of an older schema converts again). `force_hash`: the source was
    /// seen written, so its hash decides whatever its size and times say.
    fn current_under_its_own_settings(
        &self,
        take: &BatchTake,
        stat: SourceStat,
        fingerprint: &str,
        force_hash: bool,
    ) -> bool {
        self.ledger.latest(&take.rel).is_some_and(|e| {
            let own_settings =
                !self.opts.reconvert && fingerprint_schema(&e.settings) == FINGERPRINT_SCHEMA;
            let fingerprint = if own_settings {
                &e.settings
            } else {
                fingerprint
            };
            e.status == Status::Converted
                && self
                    .ledger
                    .is_current(&take.rel, stat, fingerprint, force_hash, || {
                        source_sha256(&take.path)
                    })
                    .is_ok_and(|f| f.is_current())
        })
    }

    /// Whether the take's last conversion failed under other settings than its own now (a
    /// capture dropped before its `imubake.yaml`): it is tried again.
    fn failed_under_other_settings(&mut self, take: &BatchTake) -> bool {
        let failed_with = match self.ledger.latest(&take.rel) {
            Some(e) if e.status == Status::Failed => e.settings.clone(),
            _ => return false,
        };
        failed_with != self.settings_for(take).1
    }

    fn convert(&mut self, take: &BatchTake, stat: SourceStat, force_hash: bool, stop: &AtomicBool) {
        self.pending.remove(&take.rel);
        self.done.insert(take.rel.clone(), stat);
        let (plan, fingerprint) = self.settings_for(take);
        let retry = self.retries.remove(&take.rel);
        if self.current_under_its_own_settings(take, stat, &fingerprint, force_hash) {
            self.outcomes.record(&take.rel, TakeStatus::Skipped);
            return;
        }
        let again = retry.is_some();
        let Some(Attempt {
            result,
            environment,
        }) = self.convert_on_worker(take, plan, fingerprint, again, stop)
        else {
            return;
        };
        match environment {
            Some(kind) => {
                let attempts = retry.map_or(1, |r| r.attempts + 1);
                let wait = retry_delay(attempts);
                self.retries.insert(
                    take.rel.clone(),
                    Retry {
                        stat,
                        attempts,
                        at: Instant::now() + wait,
                    },
                );
                warn!(
                    source = result.source.as_str(),
                    duration_ms = u64::try_from(result.duration.as_millis()).unwrap_or(u64::MAX),
                    attempt = attempts,
                    retry_in_s = wait.as_secs(),
                    error_kind = ?kind,
                    error_report = result.error_report.as_deref().unwrap_or(""),
                    reason = result.reason.as_deref().unwrap_or(""),
                    "cannot write the take's outputs or its ledger line; retrying"
                );
            }
            None => {
                log_result(&result, &self.opts.out);
                if let Some(retry) = retry {
                    info!(
                        source = result.source.as_str(),
                        attempts = retry.attempts + 1,
                        "written after retrying"
                    );
                }
            }
        }
        self.outcomes.record(&take.rel, result.status);
        if result.status != TakeStatus::Skipped {
            match Ledger::load(&self.opts.out) {
                Ok(ledger) => self.ledger = Arc::new(ledger),
                Err(e) => error!(
                    ledger = %self.ledger.path().display(),
                    "cannot reload the ledger: {e}"
                ),
            }
        }
    }

    /// Converts a take on a worker thread while watching `stop`: after a stop signal the take
    /// may finish within [`FINISH_GRACE`], else its writes are abandoned and `None` returned.
    fn convert_on_worker(
        &mut self,
        take: &BatchTake,
        plan: Arc<Plan>,
        fingerprint: String,
        retry: bool,
        stop: &AtomicBool,
    ) -> Option<Attempt> {
        let (tx, rx) = mpsc::channel();
        let ledger = Arc::clone(&self.ledger);
        let (owned_take, out) = (take.clone(), self.opts.out.clone());
        let spawned = std::thread::Builder::new()
            .name(format!("convert {}", take.rel))
            .spawn(move || {
                let job = TakeJob {
                    out_root: &out,
                    plan: &plan,
                    fingerprint: &fingerprint,
                    ledger: &ledger,
                };
                let _ = tx.send(attempt_take(&owned_take, &job, retry));
            });
        if let Err(e) = spawned {
            error!(
                source = take.rel.as_str(),
                "cannot start a conversion thread: {e}"
            );
            return None;
        }
        let mut stopped_at: Option<Instant> = None;
        loop {
            match rx.recv_timeout(Duration::from_millis(20)) {
                Ok(result) => return Some(result),
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    error!(
                        source = take.rel.as_str(),
                        "the conversion thread ended without a result"
                    );
                    return None;
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {}
            }
            if stop.load(Ordering::SeqCst) {
                let at = *stopped_at.get_or_insert_with(Instant::now);
                if at.elapsed() >= FINISH_GRACE {
                    let removed = crate::write::abandon_writes();
                    let result = TakeResult::new(take.rel.clone(), TakeStatus::Abandoned);
                    result.log();
                    debug!(
                        source = take.rel.as_str(),
                        "removed {} temporary file(s)",
                        removed.len()
                    );
                    self.outcomes.record(&take.rel, TakeStatus::Abandoned);
                    self.abandoned = true;
                    return None;
                }
            }
        }
    }

    /// One look at the inbox: converts the takes that are complete (`wait_for_settle` false: all
    /// of them at once, for `--once`).
    fn scan(&mut self, stop: &AtomicBool, wait_for_settle: bool) {
        self.refresh_config();
        let takes = self.takes();
        let now = Instant::now();
        let live: HashSet<&str> = takes.iter().map(|t| t.rel.as_str()).collect();
        self.pending.retain(|rel, _| live.contains(rel.as_str()));
        self.done.retain(|rel, _| live.contains(rel.as_str()));
        self.retries.retain(|rel, _| live.contains(rel.as_str()));
        // Settled or closed: complete unless some process still has them open for writing.
        let mut candidates: Vec<(&BatchTake, SourceStat, PathBuf, bool)> = Vec::new();
        for take in &takes {
            if stop.load(Ordering::SeqCst) || self.abandoned {
                return;
            }
            let Ok(stat) = SourceStat::of(&take.path) else {
                // Gone or unreadable for now: no retry stays due (nor a settle pending) for a
                // take that cannot be looked at; the next scan that can sees it afresh.
                self.retries.remove(&take.rel);
                self.pending.remove(&take.rel);
                continue;
            };
            // Written (an event) or changed since this watcher handled it: its hash decides.
            let written = self.closed.contains(&take.path);
            // The environment failed it: tried again when due, unless it changed since.
            if let Some(retry) = self.retries.get(&take.rel) {
                if retry.stat == stat && !written {
                    if Instant::now() >= retry.at {
                        self.convert(take, stat, false, stop);
                    }
                    continue;
                }
                self.retries.remove(&take.rel);
            }
            let seen = self.done.get(&take.rel).copied();
            if seen == Some(stat) && !written && !self.failed_under_other_settings(take) {
                continue;
            }
            let force_hash = written || seen.is_some();
            if !wait_for_settle
                || !self.pending.contains_key(&take.rel) && {
                    let fingerprint = self.settings_for(take).1;
                    self.current_under_its_own_settings(take, stat, &fingerprint, force_hash)
                }
            {
                self.convert(take, stat, force_hash, stop);
                continue;
            }
            let closed = self.closed.remove(&take.path);
            let pending = match self.pending.get_mut(&take.rel) {
                Some(p) if p.stat == stat => p,
                _ => {
                    let fresh = Pending {
                        stat,
                        since: now,
                        busy: false,
                    };
                    self.pending.insert(take.rel.clone(), fresh);
                    self.pending.get_mut(&take.rel).expect("just inserted")
                }
            };
            if !closed && now.duration_since(pending.since) < self.opts.settle {
                continue;
            }
            if take.path.is_dir() && has_temporary_entry(&take.path) {
                pending.busy = true;
                continue;
            }
            let canonical = take
                .path
                .canonicalize()
                .unwrap_or_else(|_| take.path.clone());
            candidates.push((take, stat, canonical, force_hash));
        }
        self.closed.clear();
        let paths: Vec<PathBuf> = candidates.iter().map(|(_, _, p, _)| p.clone()).collect();
        let held = held_for_writing(&paths);
        for (take, stat, canonical, force_hash) in candidates {
            if stop.load(Ordering::SeqCst) || self.abandoned {
                return;
            }
            if held.contains(&canonical) {
                if let Some(p) = self.pending.get_mut(&take.rel) {
                    p.busy = true;
                }
                continue;
            }
            self.convert(take, stat, force_hash, stop);
        }
    }

    /// When the next take the environment failed is due to be tried again.
    fn next_retry(&self) -> Option<Instant> {
        self.retries.values().map(|r| r.at).min()
    }

    /// When the next pending take settles (not counting the busy ones).
    fn next_settle(&self) -> Option<Instant> {
        self.pending
            .values()
            .filter(|p| !p.busy)
            .map(|p| p.since + self.opts.settle)
            .min()
    }
}

/// The paths a debounced event reports complete: closed after writing (Linux close-write), or
/// renamed into place. The debouncer gives a rename it could pair (inotify's cookies; elsewhere
/// file ids) as `Both` `[from, to]`, a move in from outside the inbox as `To`, and a rename some
/// platform cannot tell apart as `Any` (into place when the path exists). It keeps close-write
/// events (it drops only the modifications and repeated creates that follow a create, and keeps
/// the last event of each kind per path), and when a take is written under a temporary name and
/// renamed into place within one [`DEBOUNCE`] it moves the temporary name's events, close-write
/// included, to the final name and reports that as created rather than renamed: the close-write
/// still marks it complete.
fn completed_paths(event: &notify::Event) -> Vec<PathBuf> {
    match event.kind {
        EventKind::Access(AccessKind::Close(AccessMode::Write))
        | EventKind::Modify(ModifyKind::Name(RenameMode::To)) => event.paths.clone(),
        EventKind::Modify(ModifyKind::Name(RenameMode::Both)) => {
            event.paths.last().cloned().into_iter().collect()
        }
        EventKind::Modify(ModifyKind::Name(RenameMode::Any)) => {
            event.paths.iter().filter(|p| p.exists()).cloned().collect()
        }
        _ => Vec::new(),
    }
}

/// Whether an event is a change to look at. Opening, reading and closing a file unwritten
/// (inotify's `IN_OPEN`, which `notify` watches) and an access-time update are not: the scan
/// itself opens every take (discovery sniffs its format, the ledger hashes it), so waking on
/// them would rescan forever, each scan's reads waking the next.
fn is_change(event: &notify::Event) -> bool {
    use notify::event::MetadataKind;
    match event.kind {
        EventKind::Access(AccessKind::Close(AccessMode::Write)) => true,
        EventKind::Access(_) => false,
        EventKind::Modify(ModifyKind::Metadata(MetadataKind::AccessTime)) => false,
        _ => true,
    }
}

/// What the debouncer tells the loop: something changed, and these paths are complete.
type Wake = Vec<PathBuf>;

/// The wake a batch of debounced events gives: none when nothing in it changed anything.
fn wake_of(res: DebounceEventResult) -> Option<Wake> {
    match res {
        Ok(events) => events
            .iter()
            .any(|e| is_change(e))
            .then(|| events.iter().flat_map(|e| completed_paths(e)).collect()),
        Err(errors) => {
            // Dropped events and the like: the rescan this wake causes finds the takes.
            for e in errors {
                warn!("file-system events: {e}");
            }
            Some(Vec::new())
        }
    }
}

/// Converts the inbox's backlog, then (unless `once`) follows it until `stop` is set, finishing
/// the take in progress. `load_plan` resolves the plan of a config file (or none); it is
/// called again whenever the config file changes. Returns what was converted, failed and skipped,
/// each take counted once, by its latest outcome ([`Outcomes`]). The output folder's
/// [`WatchLock`] is held throughout (`--once` too); when another watcher holds it, returns
/// [`WatchError::AlreadyWatched`] before doing anything else.
pub fn run(
    opts: &WatchOptions,
    load_plan: &dyn Fn(Option<&Path>) -> Result<Plan, PlanError>,
    stop: &AtomicBool,
) -> Result<Summary, WatchError> {
    fs::create_dir_all(&opts.out)?;
    let _lock = WatchLock::acquire(&opts.out, &opts.inbox)?;
    let config_seen = config_stat(&opts.config);
    let config_arg = opts.config.is_file().then_some(opts.config.as_path());
    let plan = load_plan(config_arg).map_err(io::Error::other)?;
    let ledger = Ledger::load(&opts.out)?;
    ledger.report_older_schema();
    let mut watch = Watch {
        opts,
        load_plan,
        fingerprint: settings_fingerprint(&plan),
        files_seen: file_stats(&plan),
        plan: Arc::new(plan),
        config_seen,
        ledger: Arc::new(ledger),
        done: HashMap::new(),
        pending: HashMap::new(),
        last_discover_error: None,
        reported: HashSet::new(),
        folder_settings: HashMap::new(),
        closed: Default::default(),
        abandoned: false,
        outcomes: Outcomes::default(),
        retries: HashMap::new(),
    };
    if opts.once {
        watch.scan(stop, false);
        return Ok(watch.outcomes.summary());
    }

    // File-system events only wake the loop early; the scan decides. With --poll there is no
    // watcher: the loop rescans every poll interval itself (a PollWatcher would walk and stat the
    // inbox on its own clock, then the scan would do it again, and its events would arrive a
    // debounce later, eating into the poll + 600 ms budget).
    let (tx, rx) = mpsc::channel::<Wake>();
    let debouncer = if opts.poll.is_none() {
        let tx = tx.clone();
        let mut debouncer = new_debouncer(DEBOUNCE, None, move |res: DebounceEventResult| {
            if let Some(wake) = wake_of(res) {
                let _ = tx.send(wake);
            }
        })
        .map_err(io::Error::other)?;
        debouncer
            .watch(&opts.inbox, RecursiveMode::Recursive)
            .map_err(io::Error::other)?;
        if opts.config.parent() != Some(opts.inbox.as_path())
            && let Some(dir) = opts.config.parent().filter(|d| d.is_dir())
        {
            let _ = debouncer.watch(dir, RecursiveMode::NonRecursive);
        }
        Some(debouncer)
    } else {
        None
    };
    info!(
        inbox = %opts.inbox.display(),
        "watching ({}); Ctrl-C to stop",
        match opts.poll {
            Some(p) => format!("polling every {} ms", p.as_millis()),
            None => "file-system events".into(),
        }
    );
    // The backlog: current takes are done at once, the others once they are settled.
    watch.scan(stop, true);
    while !stop.load(Ordering::SeqCst) && !watch.abandoned {
        // Until the next poll (events: a fallback rescan) or the next take to settle or to try
        // again, if sooner.
        let until_settle = watch
            .next_settle()
            .into_iter()
            .chain(watch.next_retry())
            .min()
            .map(|at| at.saturating_duration_since(Instant::now()));
        let wait = opts
            .poll
            .unwrap_or(Duration::from_secs(2))
            .min(until_settle.unwrap_or(Duration::MAX))
            .max(Duration::from_millis(10));
        let deadline = Instant::now() + wait;
        while !stop.load(Ordering::SeqCst) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            // Events: the debouncer has already gathered the burst; rescan now.
            if let Ok(first) = rx.recv_timeout(left.min(Duration::from_millis(50))) {
                watch
                    .closed
                    .extend(std::iter::once(first).chain(rx.try_iter()).flatten());
                break;
            }
        }
        if stop.load(Ordering::SeqCst) {
            break;
        }
        watch.scan(stop, true);
    }
    drop(tx);
    if let Some(debouncer) = debouncer {
        debouncer.stop();
    }
    Ok(watch.outcomes.summary())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// The paths the real debouncer reports complete, until `quiet` passes without one.
    fn drain(rx: &mpsc::Receiver<Wake>, quiet: Duration) -> HashSet<PathBuf> {
        let mut paths = HashSet::new();
        while let Ok(wake) = rx.recv_timeout(quiet) {
            paths.extend(wake);
        }
        paths
    }

    /// Through `notify-debouncer-full`, a close-write and a rename into place still mark the take
    /// complete, however the debouncer stitches the rename; a file still open for writing does
    /// not.
    #[test]
    #[cfg(target_os = "linux")]
    fn the_debouncer_keeps_close_write_and_renames_into_place() {
        let dir = tempfile::tempdir().unwrap();
        let (inbox, elsewhere) = (dir.path().join("in"), dir.path().join("elsewhere"));
        fs::create_dir_all(&inbox).unwrap();
        fs::create_dir_all(&elsewhere).unwrap();
        let (tx, rx) = mpsc::channel::<Wake>();
        let mut debouncer = new_debouncer(DEBOUNCE, None, move |res: DebounceEventResult| {
            if let Some(wake) = wake_of(res) {
                let _ = tx.send(wake);
            }
        })
        .unwrap();
        debouncer.watch(&inbox, RecursiveMode::Recursive).unwrap();
        let quiet = Duration::from_millis(400);

        // Written through one handle and closed.
        let mut f = fs::File::create(inbox.join("closed.log")).unwrap();
        f.write_all(b"time_s\n").unwrap();
        drop(f);
        // Written under a temporary name and renamed into place at once (the debouncer moves the
        // create and the close-write to the final name).
        fs::write(inbox.join(".quick.log.tmp"), b"x").unwrap();
        fs::rename(inbox.join(".quick.log.tmp"), inbox.join("quick.log")).unwrap();
        // Open for writing: only its creation is seen.
        let mut open = fs::File::create(inbox.join("open.log")).unwrap();
        open.write_all(b"time_s\n").unwrap();
        let seen = drain(&rx, quiet);
        for name in ["closed.log", "quick.log"] {
            assert!(seen.contains(&inbox.join(name)), "{name}: {seen:?}");
        }
        assert!(!seen.contains(&inbox.join("open.log")), "{seen:?}");

        // A temporary file closed long before its rename: the rename pairs up as [from, to].
        fs::write(inbox.join("slow.log.part"), b"x").unwrap();
        drain(&rx, quiet);
        fs::rename(inbox.join("slow.log.part"), inbox.join("slow.log")).unwrap();
        // Moved in from outside the inbox; and the open file closed at last.
        fs::write(elsewhere.join("moved.log"), b"x").unwrap();
        fs::rename(elsewhere.join("moved.log"), inbox.join("moved.log")).unwrap();
        drop(open);
        let seen = drain(&rx, quiet);
        for name in ["slow.log", "moved.log", "open.log"] {
            assert!(seen.contains(&inbox.join(name)), "{name}: {seen:?}");
        }

        // Reading the takes (as every scan does) wakes nothing: no rescan feeds the next.
        for name in [
            "closed.log",
            "quick.log",
            "slow.log",
            "moved.log",
            "open.log",
        ] {
            let mut text = String::new();
            fs::File::open(inbox.join(name))
                .unwrap()
                .read_to_string(&mut text)
                .unwrap();
        }
        let _ = fs::read_dir(&inbox).unwrap().count();
        assert!(
            rx.recv_timeout(quiet).is_err(),
            "reading the inbox woke the loop"
        );
        debouncer.stop();
    }

    #[test]
    fn each_take_counts_once_by_its_latest_outcome() {
        use TakeStatus::{Abandoned, Converted, Failed, Skipped};
        let mut o = Outcomes::default();
        // Failed, then converted once its settings were fixed.
        o.record("fixed.log", Failed);
        o.record("fixed.log", Converted);
        // Converted, then failed when rewritten badly.
        o.record("broken.log", Converted);
        o.record("broken.log", Failed);
        // Failed twice (retried under new settings).
        o.record("junk.log", Failed);
        o.record("junk.log", Failed);
        // Converted, then found current again: still converted in this run.
        o.record("touched.log", Converted);
        o.record("touched.log", Skipped);
        // Current at start, then rewritten and converted.
        o.record("old.log", Skipped);
        o.record("old.log", Converted);
        o.record("current.log", Skipped);
        o.record("current.log", Skipped);
        o.record("cut.log", Converted);
        o.record("cut.log", Abandoned);
        assert_eq!(
            o.summary(),
            Summary {
                converted: 3,
                failed: 2,
                abandoned: 1,
                skipped: 1,
            }
        );
    }

    #[test]
    fn retries_wait_one_second_doubling_to_a_minute() {
        let waits: Vec<u64> = (1..=9).map(|n| retry_delay(n).as_secs()).collect();
        assert_eq!(waits, [1, 2, 4, 8, 16, 32, 60, 60, 60]);
        assert_eq!(retry_delay(u32::MAX), RETRY_MAX);
    }

    /// A second lock on one output folder is refused and names the holder (`flock` locks belong
    /// to open files, so a second open in this process is refused as another process would
    /// be); dropped, the lock is free again and its file names the new holder.
    #[test]
    fn one_lock_per_output_folder() {
        let dir = tempfile::tempdir().unwrap();
        let (out, inbox) = (dir.path().join("out"), dir.path().join("in"));
        fs::create_dir_all(&inbox).unwrap();
        let first = WatchLock::acquire(&out, &inbox).unwrap();
        let holder = LockHolder {
            pid: std::process::id(),
            inbox: inbox.canonicalize().unwrap(),
        };
        match WatchLock::acquire(&out, Path::new("elsewhere")) {
            Err(e @ WatchError::AlreadyWatched { .. }) => {
                let WatchError::AlreadyWatched { holder: seen, .. } = &e else {
                    unreachable!()
                };
                assert_eq!(seen.as_ref(), Some(&holder));
                let text = e.to_string();
                assert!(text.contains(&format!("pid {}", holder.pid)), "{text}");
                assert!(text.contains(&holder.inbox.display().to_string()), "{text}");
            }
            other => panic!("{other:?}"),
        }
        drop(first);
        let _again = WatchLock::acquire(&out, dir.path()).unwrap();
        let text = fs::read_to_string(lock_path(&out)).unwrap();
        let now: LockHolder = serde_json::from_str(text.trim()).unwrap();
        assert_eq!(now.inbox, dir.path().canonicalize().unwrap());
    }

    #[test]
    fn fdinfo_flags_are_octal() {
        let text = "pos:\t0\nflags:\t0100001\nmnt_id:\t25\n";
        assert_eq!(fdinfo_flags(text), Some(0o100001));
        assert_eq!(fdinfo_flags("pos:\t0\n"), None);
    }

    #[test]
    #[cfg(target_os = "linux")]
    fn a_file_open_for_writing_is_held_and_a_reader_does_not_hold_it() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        let (file, other) = (root.join("take.log"), root.join("other.log"));
        fs::write(&other, b"x").unwrap();
        let mut writer = fs::File::create(&file).unwrap();
        writer.write_all(b"time_s").unwrap();
        let _reader = fs::File::open(&other).unwrap();
        let held = held_for_writing(&[file.clone(), other.clone()]);
        assert!(held.contains(&file) && !held.contains(&other), "{held:?}");
        // A folder is held when a file under it is.
        assert!(held_for_writing(std::slice::from_ref(&root)).contains(&root));
        drop(writer);
        assert!(held_for_writing(&[file, other, root]).is_empty());
    }
}
