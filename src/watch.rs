//! `imubake watch`: converts an inbox's backlog, then each take as it arrives or changes, under
//! the same ledger and per-take conversion as `batch` ([`crate::batch::process_take`]).
//!
//! Takes are found with [`crate::batch::discover`] (each top-level file or session folder of the
//! inbox is one take); hidden and temporary names (`.*`, `*.part`, `*.tmp`, `*~`,
//! `*.crdownload`) and the inbox's `imubake.yaml` are ignored. A take is complete when its size
//! and modification time (a session folder: summed over its files, the latest mtime) stay the
//! same over two looks at least [`WatchOptions::settle`] apart; a file renamed into place is
//! complete the same way, one settle period later. Changes are noticed by file-system events
//! (`notify`) or by polling; either way the inbox is rescanned, so a missed event only delays a
//! take.

use crate::batch::{BatchTake, Summary, TakeResult, TakeStatus, discover, process_take};
use crate::convert::{ConvertSettings, source_sha256};
use crate::ledger::{Ledger, SourceStat, Status, settings_fingerprint};
use notify::Watcher;
use notify::event::{AccessKind, AccessMode, EventKind};
use std::collections::HashMap;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// The config file an inbox may hold.
pub const INBOX_CONFIG: &str = "imubake.yaml";

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
    /// How long a take's size and mtime must stay the same before it counts as complete (longer
    /// than the pauses of the slowest writer; a file closed after writing, where the platform
    /// reports it, is complete at once).
    pub settle: Duration,
    /// The config file to follow (`--config`, else `<inbox>/imubake.yaml`).
    pub config: PathBuf,
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
            settle: Duration::from_millis(2000),
            config,
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

/// The follower of one inbox.
struct Watch<'a> {
    opts: &'a WatchOptions,
    load_settings: &'a dyn Fn(Option<&Path>) -> Result<ConvertSettings, String>,
    settings: ConvertSettings,
    fingerprint: String,
    config_seen: Option<SourceStat>,
    ledger: Ledger,
    /// Takes handled at this size and mtime.
    done: HashMap<String, SourceStat>,
    /// Takes seen changing: the stat last seen and since when.
    pending: HashMap<String, (SourceStat, Instant)>,
    last_discover_error: Option<String>,
    /// Files reported closed after writing since the last scan.
    closed: std::collections::HashSet<PathBuf>,
    summary: Summary,
}

impl Watch<'_> {
    fn config_arg(&self) -> Option<&Path> {
        self.opts
            .config
            .is_file()
            .then_some(self.opts.config.as_path())
    }

    /// Reloads the settings when the config file changed; a bad config is reported and the last
    /// good settings stay.
    fn refresh_config(&mut self) {
        let stat = config_stat(&self.opts.config);
        if stat == self.config_seen {
            return;
        }
        self.config_seen = stat;
        match (self.load_settings)(self.config_arg()) {
            Ok(settings) => {
                let fingerprint = settings_fingerprint(&settings);
                if fingerprint != self.fingerprint {
                    eprintln!(
                        "{}: settings changed{}",
                        self.opts.config.display(),
                        if self.opts.reconvert {
                            "; reconverting the takes"
                        } else {
                            "; new takes use them (--reconvert to redo old ones)"
                        }
                    );
                    self.settings = settings;
                    self.fingerprint = fingerprint;
                    if self.opts.reconvert {
                        self.done.clear();
                    }
                }
            }
            Err(e) => eprintln!("error: {e} (keeping the last good settings)"),
        }
    }

    fn takes(&mut self) -> Vec<BatchTake> {
        match discover(std::slice::from_ref(&self.opts.inbox), Some(&self.opts.out)) {
            Ok(takes) => {
                self.last_discover_error = None;
                let config = self.opts.config.canonicalize().ok();
                takes
                    .into_iter()
                    .filter(|t| {
                        let temp = Path::new(&t.rel)
                            .components()
                            .any(|c| is_temporary_name(&c.as_os_str().to_string_lossy()));
                        let is_config = t.rel == INBOX_CONFIG
                            || config.is_some()
                                && t.path.canonicalize().ok().as_ref() == config.as_ref();
                        !temp && !is_config
                    })
                    .collect()
            }
            Err(e) => {
                let msg = e.to_string();
                if self.last_discover_error.as_ref() != Some(&msg) {
                    eprintln!("error: {msg}");
                }
                self.last_discover_error = Some(msg);
                Vec::new()
            }
        }
    }

    /// Whether the take was converted from this content, under whatever settings (without
    /// `--reconvert`, a change of settings leaves old takes alone).
    fn current_under_its_own_settings(&self, take: &BatchTake, stat: SourceStat) -> bool {
        self.ledger.latest(&take.rel).is_some_and(|e| {
            let fingerprint = if self.opts.reconvert {
                &self.fingerprint
            } else {
                &e.settings
            };
            e.status == Status::Converted
                && self
                    .ledger
                    .is_current(&take.rel, stat, fingerprint, || source_sha256(&take.path))
                    .is_ok_and(|f| f.is_current())
        })
    }

    fn convert(&mut self, take: &BatchTake, stat: SourceStat) {
        self.pending.remove(&take.rel);
        self.done.insert(take.rel.clone(), stat);
        if self.current_under_its_own_settings(take, stat) {
            self.summary.skipped += 1;
            return;
        }
        let started = Instant::now();
        let result = process_take(
            take,
            &self.opts.out,
            &self.settings,
            &self.fingerprint,
            &self.ledger,
        );
        log(&result, started.elapsed());
        match result.status {
            TakeStatus::Converted => self.summary.converted += 1,
            TakeStatus::Failed => self.summary.failed += 1,
            TakeStatus::Skipped => self.summary.skipped += 1,
        }
        if result.status != TakeStatus::Skipped {
            match Ledger::load(&self.opts.out) {
                Ok(ledger) => self.ledger = ledger,
                Err(e) => eprintln!("error: {}: {e}", self.ledger.path().display()),
            }
        }
    }

    /// One look at the inbox: converts the takes that are complete (`settled`: without waiting,
    /// for `--once`).
    fn scan(&mut self, stop: &AtomicBool, wait_for_settle: bool) {
        self.refresh_config();
        let takes = self.takes();
        let now = Instant::now();
        let live: std::collections::HashSet<&str> = takes.iter().map(|t| t.rel.as_str()).collect();
        self.pending.retain(|rel, _| live.contains(rel.as_str()));
        self.done.retain(|rel, _| live.contains(rel.as_str()));
        for take in &takes {
            if stop.load(Ordering::SeqCst) {
                return;
            }
            let Ok(stat) = SourceStat::of(&take.path) else {
                continue;
            };
            if self.done.get(&take.rel) == Some(&stat) {
                continue;
            }
            if !wait_for_settle
                || !self.pending.contains_key(&take.rel)
                    && self.current_under_its_own_settings(take, stat)
            {
                self.convert(take, stat);
                continue;
            }
            let closed = self.closed.remove(&take.path);
            let settled = closed
                || match self.pending.get(&take.rel) {
                    Some((seen, since)) if *seen == stat => {
                        now.duration_since(*since) >= self.opts.settle
                    }
                    _ => {
                        self.pending.insert(take.rel.clone(), (stat, now));
                        false
                    }
                };
            if settled && !(take.path.is_dir() && has_temporary_entry(&take.path)) {
                self.convert(take, stat);
            }
        }
        self.closed.clear();
    }
}

fn log(result: &TakeResult, took: Duration) {
    let secs = took.as_secs_f64();
    match result.status {
        TakeStatus::Converted => eprintln!("{}: converted in {secs:.2} s", result.source),
        TakeStatus::Failed => eprintln!(
            "{}: failed in {secs:.2} s: {}",
            result.source,
            result.reason.as_deref().unwrap_or("")
        ),
        TakeStatus::Skipped => {}
    }
    for w in &result.warnings {
        eprintln!("warning: {}: {w}", result.source);
    }
}

/// Converts the inbox's backlog, then (unless `once`) follows it until `stop` is set, finishing
/// the take in progress. `load_settings` gives the settings from a config file (or none); it is
/// called again whenever the config file changes. Returns what was converted, failed and skipped.
pub fn run(
    opts: &WatchOptions,
    load_settings: &dyn Fn(Option<&Path>) -> Result<ConvertSettings, String>,
    stop: &AtomicBool,
) -> io::Result<Summary> {
    fs::create_dir_all(&opts.out)?;
    let config_seen = config_stat(&opts.config);
    let config_arg = opts.config.is_file().then_some(opts.config.as_path());
    let settings = load_settings(config_arg).map_err(io::Error::other)?;
    let mut watch = Watch {
        opts,
        load_settings,
        fingerprint: settings_fingerprint(&settings),
        settings,
        config_seen,
        ledger: Ledger::load(&opts.out)?,
        done: HashMap::new(),
        pending: HashMap::new(),
        last_discover_error: None,
        closed: Default::default(),
        summary: Summary::default(),
    };
    if opts.once {
        watch.scan(stop, false);
        return Ok(watch.summary);
    }

    // File-system events only wake the loop early; the scan decides.
    let (tx, rx) = mpsc::channel::<Option<PathBuf>>();
    let _watcher = if opts.poll.is_none() {
        let tx = tx.clone();
        let mut w = notify::recommended_watcher(move |res: notify::Result<notify::Event>| {
            let close_write = EventKind::Access(AccessKind::Close(AccessMode::Write));
            match res {
                Ok(event) if event.kind == close_write => {
                    for path in event.paths {
                        let _ = tx.send(Some(path));
                    }
                }
                _ => {
                    let _ = tx.send(None);
                }
            }
        })
        .map_err(io::Error::other)?;
        w.watch(&opts.inbox, notify::RecursiveMode::Recursive)
            .map_err(io::Error::other)?;
        if opts.config.parent() != Some(opts.inbox.as_path())
            && let Some(dir) = opts.config.parent().filter(|d| d.is_dir())
        {
            let _ = w.watch(dir, notify::RecursiveMode::NonRecursive);
        }
        Some(w)
    } else {
        None
    };
    eprintln!(
        "watching {} ({}); Ctrl-C to stop",
        opts.inbox.display(),
        match opts.poll {
            Some(p) => format!("polling every {} ms", p.as_millis()),
            None => "file-system events".into(),
        }
    );
    // The backlog: current takes are done at once, the others once they are settled.
    watch.scan(stop, true);
    while !stop.load(Ordering::SeqCst) {
        let wait = match opts.poll {
            Some(p) => p,
            None if !watch.pending.is_empty() => opts.settle / 2,
            None => Duration::from_secs(2),
        };
        let deadline = Instant::now() + wait;
        while !stop.load(Ordering::SeqCst) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            match rx.recv_timeout(left.min(Duration::from_millis(50))) {
                // An event: rescan soon, gathering the burst that comes with it.
                Ok(first) if opts.poll.is_none() => {
                    std::thread::sleep(Duration::from_millis(50));
                    for path in std::iter::once(first).chain(rx.try_iter()).flatten() {
                        watch.closed.insert(path);
                    }
                    break;
                }
                _ => {}
            }
        }
        if stop.load(Ordering::SeqCst) {
            break;
        }
        watch.scan(stop, true);
    }
    drop(tx);
    Ok(watch.summary)
}
