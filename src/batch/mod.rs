//! Many takes at once (`imubake batch`, and `watch` later): finding the takes of files, folders
//! and globs, a deterministic shard of them, and converting each one under the ledger
//! ([`crate::ledger`]): skipped when current, `<stem>.error.json` on failure, exactly one set of
//! outputs per take.

mod discover;
mod process;
mod shard;

pub use discover::{
    BatchTake, DiscoverError, DiscoverOptions, Discovery, FOLDER_CONFIG, SkipReason, Skipped,
    discover, is_session_folder, settings_file_kind, slash,
};
pub use process::{Attempt, TakeJob, attempt_take, environmental, process_take};
pub use shard::Shard;

use crate::convert::Plan;
use crate::ledger::Ledger;
use rayon::prelude::*;
use serde::Serialize;
use std::fs;
use std::io;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TakeStatus {
    Converted,
    Failed,
    Skipped,
    /// Stopped by a signal before it finished; nothing of it was kept or recorded.
    Abandoned,
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
    /// Lines of the source dropped and repaired on reading (listed in the sidecar).
    #[serde(skip_serializing_if = "is_zero")]
    pub dropped_lines: usize,
    #[serde(skip_serializing_if = "is_zero")]
    pub repaired_lines: usize,
    /// How long [`process_take`] took (the ledger check, and the conversion if there was one).
    #[serde(skip)]
    pub duration: Duration,
}

impl TakeResult {
    /// A result with nothing but its source and status.
    pub fn new(source: String, status: TakeStatus) -> TakeResult {
        TakeResult {
            source,
            status,
            outputs: Vec::new(),
            error_report: None,
            reason: None,
            warnings: Vec::new(),
            dropped_lines: 0,
            repaired_lines: 0,
            duration: Duration::ZERO,
        }
    }

    /// Logs the take (`tracing`): one line for a converted (info) or failed (error) take with its
    /// duration, and one warning line per warning of its conversion; a skipped take only at
    /// debug level.
    pub fn log(&self) {
        let source = self.source.as_str();
        let duration_ms = u64::try_from(self.duration.as_millis()).unwrap_or(u64::MAX);
        match self.status {
            // The sidecar lists the lines dropped and repaired; the log says how many.
            TakeStatus::Converted if self.dropped_lines + self.repaired_lines > 0 => {
                tracing::info!(
                    source,
                    duration_ms,
                    dropped_lines = self.dropped_lines,
                    repaired_lines = self.repaired_lines,
                    outputs = ?self.outputs,
                    "converted"
                )
            }
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
            TakeStatus::Abandoned => tracing::warn!(
                source,
                duration_ms,
                "abandoned: stopped before it finished; nothing of it was kept"
            ),
        }
        for warning in &self.warnings {
            tracing::warn!(source, "{warning}");
        }
    }
}

/// Counts of a batch run.
#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub struct Summary {
    pub converted: usize,
    pub failed: usize,
    /// Takes stopped by a signal before they finished (not in the text unless there are some).
    #[serde(skip_serializing_if = "is_zero")]
    pub abandoned: usize,
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
                TakeStatus::Abandoned => s.abandoned += 1,
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
        )?;
        if self.abandoned > 0 {
            write!(f, ", abandoned {}", self.abandoned)?;
        }
        Ok(())
    }
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Converts `takes` into `out_root` on `jobs` threads (0: one per core), calling `on_result` as
/// each take finishes (logging is the caller's: [`TakeResult::log`]). Results are in the order of
/// `takes`; once `stop` is set no take starts (those are left out of the results). A shard
/// records its takes in a ledger file of its own (shards on other machines may share the
/// output root over NFS, where appends to one file are not atomic).
pub fn run(
    takes: &[BatchTake],
    out_root: &Path,
    shard: Option<Shard>,
    plan: &Plan,
    jobs: usize,
    stop: &AtomicBool,
    on_result: &(dyn Fn(&TakeResult) + Sync),
) -> io::Result<Vec<TakeResult>> {
    fs::create_dir_all(out_root)?;
    let ledger = match shard {
        Some(s) if s.count > 1 => Ledger::load_appending_to(
            out_root,
            &crate::ledger::shard_ledger_name(s.index, s.count),
        )?,
        _ => Ledger::load(out_root)?,
    };
    ledger.report_older_schema();
    let fingerprint = crate::ledger::settings_fingerprint(plan);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .build()
        .map_err(io::Error::other)?;
    Ok(pool.install(|| {
        takes
            .par_iter()
            .with_max_len(1)
            .filter_map(|take| {
                if stop.load(Ordering::SeqCst) {
                    return None;
                }
                let job = TakeJob {
                    out_root,
                    plan,
                    fingerprint: &fingerprint,
                    ledger: &ledger,
                };
                let r = process_take(take, &job);
                on_result(&r);
                Some(r)
            })
            .collect()
    }))
}
