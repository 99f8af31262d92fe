//! One take of a batch under the ledger: skipped when current, converted otherwise, with
//! `<stem>.error.json` on failure and exactly one set of outputs per take.

use super::{BatchTake, TakeResult, TakeStatus, slash};
use crate::convert::{ConvertSettings, convert, source_sha256};
use crate::ledger::{Freshness, Ledger, LedgerEntry, SourceStat, Status, now_ns};
use crate::write::error_report::{ErrorReport, remove_error_report, write_error_report};
use std::fs;
use std::path::Path;
use std::time::Instant;

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
pub fn process_take(take: &BatchTake, job: &TakeJob<'_>) -> TakeResult {
    let clock = Instant::now();
    let mut result = process_take_untimed(take, job);
    result.duration = clock.elapsed();
    result
}

/// What every take of a run shares: where outputs go, the settings and their fingerprint, the
/// ledger.
#[derive(Debug, Clone, Copy)]
pub struct TakeJob<'a> {
    pub out_root: &'a Path,
    pub settings: &'a ConvertSettings,
    pub fingerprint: &'a str,
    pub ledger: &'a Ledger,
}

fn process_take_untimed(take: &BatchTake, job: &TakeJob<'_>) -> TakeResult {
    let TakeJob {
        out_root,
        settings,
        fingerprint,
        ledger,
    } = *job;
    let out_dir = out_root.join(&take.out_dir);
    let stat = SourceStat::of(&take.path);
    if let Ok(stat) = stat {
        match ledger.is_current(&take.rel, stat, fingerprint, false, || {
            source_sha256(&take.path)
        }) {
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
    if crate::write::writes_abandoned() {
        // The process is stopping: nothing of this take is recorded (its temporary files are
        // gone; a changed take's old sidecar was removed, so it converts again next time).
        return TakeResult::new(take.rel.clone(), TakeStatus::Abandoned);
    }
    let previous = ledger.latest(&take.rel);
    let stat = stat.ok();
    // A failed conversion and a panic both end in an error report.
    let result = match result {
        Ok(Ok(outcome)) => Ok(outcome),
        Ok(Err(error)) => Err(ErrorReport::from_error(&take.rel, &error)),
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
                outputs: outputs.clone(),
                warnings: outcome.sidecar.warnings.clone(),
                dropped_lines: outcome.sidecar.dropped_lines.len(),
                repaired_lines: outcome.sidecar.repaired_lines.len(),
                ..TakeResult::new(take.rel.clone(), TakeStatus::Converted)
            };
            let entry = LedgerEntry {
                source: take.rel.clone(),
                size: stat.map_or(0, |s| s.size),
                mtime_ns: stat.and_then(|s| s.mtime_ns),
                ctime_ns: stat.and_then(|s| s.ctime_ns),
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
        Err(report) => fail(take, job, &out_dir, report, stat, started),
    }
}

fn skipped(take: &BatchTake, ledger: &Ledger) -> TakeResult {
    TakeResult {
        outputs: ledger
            .latest(&take.rel)
            .map(|e| e.outputs.clone())
            .unwrap_or_default(),
        ..TakeResult::new(take.rel.clone(), TakeStatus::Skipped)
    }
}

fn fail(
    take: &BatchTake,
    job: &TakeJob<'_>,
    out_dir: &Path,
    report: ErrorReport,
    stat: Option<SourceStat>,
    started: u64,
) -> TakeResult {
    let TakeJob {
        out_root,
        fingerprint,
        ledger,
        ..
    } = *job;
    // No outputs of an earlier version stay beside the error: the sidecar first.
    crate::write::remove_take_outputs(out_dir, &take.stem);
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
        ctime_ns: stat.and_then(|s| s.ctime_ns),
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
        error_report: Some(report_rel),
        reason: Some(reason),
        ..TakeResult::new(take.rel.clone(), TakeStatus::Failed)
    }
}
