//! One take of a batch under the ledger: skipped when current, converted otherwise, with
//! `<stem>.error.json` on failure and exactly one set of outputs per take.
//!
//! A failure is the take's own (its data, its settings: it fails the same way until the file or
//! the settings change) or the environment's: an I/O error writing the take's outputs or its
//! ledger line ([`environmental`]: permissions, a read-only or full file system, a quota, a file
//! size limit, …), which may pass on its own; [`attempt_take`] says which, so that `watch` can
//! try the take again.

use super::{BatchTake, TakeResult, TakeStatus, slash};
use crate::convert::{ConvertError, Plan, convert, source_sha256};
use crate::ledger::{Freshness, Ledger, LedgerEntry, SourceStat, Status, now_ns};
use crate::write::OutputError;
use crate::write::error_report::{ErrorReport, remove_error_report, write_error_report};
use std::fs;
use std::io;
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
    attempt_take(take, job, false).result
}

/// What [`attempt_take`] did, and whether a failure was the environment's.
#[derive(Debug)]
pub struct Attempt {
    pub result: TakeResult,
    /// The kind of the I/O error that failed the take's outputs or its ledger line, when the
    /// failure was the environment's ([`environmental`]) rather than the take's own.
    pub environment: Option<io::ErrorKind>,
}

/// [`process_take`], saying whether a failure was the environment's. `retry`: this attempt
/// follows an environmental failure of the same take, so a failure the take's latest ledger line
/// already records (same source content, settings and error) is not appended again — a watcher
/// retrying for an hour writes one line, not one per attempt.
pub fn attempt_take(take: &BatchTake, job: &TakeJob<'_>, retry: bool) -> Attempt {
    let clock = Instant::now();
    let mut attempt = process_take_untimed(take, job, retry);
    attempt.result.duration = clock.elapsed();
    attempt
}

/// Whether an I/O error writing outputs or the ledger is the environment's, likely to pass when
/// a person or the system frees space or fixes permissions: `EACCES`/`EPERM`, `EROFS`,
/// `ENOSPC`, `EDQUOT`, `EFBIG` (a file size limit), `ENOTDIR`/`EISDIR`/`ENOENT` (a folder
/// replaced or removed), `EBUSY`, `ESTALE`, `ETIMEDOUT`, `ENOMEM`, `EIO`, `EMFILE`/`ENFILE`,
/// `ENOLCK`. Told by the error's kind and OS code, never its text. Not the error of a write
/// refused because the process is stopping (`Interrupted`).
pub fn environmental(error: &io::Error) -> bool {
    use io::ErrorKind::*;
    matches!(
        error.kind(),
        PermissionDenied
            | ReadOnlyFilesystem
            | StorageFull
            | QuotaExceeded
            | FileTooLarge
            | NotADirectory
            | IsADirectory
            | NotFound
            | ResourceBusy
            | StaleNetworkFileHandle
            | TimedOut
            | OutOfMemory
    ) || error
        .raw_os_error()
        .is_some_and(|code| [libc::EIO, libc::EMFILE, libc::ENFILE, libc::ENOLCK].contains(&code))
}

/// The environmental I/O error of a failed conversion, if that is what failed it: writing an
/// output or the sidecar (a glTF too large or too long for its format is the take's own).
fn environmental_kind(error: &ConvertError) -> Option<io::ErrorKind> {
    match error {
        ConvertError::Output(OutputError::Write { source, .. }) if environmental(source) => {
            Some(source.kind())
        }
        _ => None,
    }
}

/// What every take of a run shares: where outputs go, the plan and its fingerprint, the ledger.
#[derive(Debug, Clone, Copy)]
pub struct TakeJob<'a> {
    pub out_root: &'a Path,
    pub plan: &'a Plan,
    pub fingerprint: &'a str,
    pub ledger: &'a Ledger,
}

fn process_take_untimed(take: &BatchTake, job: &TakeJob<'_>, retry: bool) -> Attempt {
    let TakeJob {
        out_root,
        plan,
        fingerprint,
        ledger,
    } = *job;
    let out_dir = out_root.join(&take.out_dir);
    let stat = SourceStat::of(&take.path);
    if let Ok(stat) = stat {
        match ledger.is_current(&take.rel, stat, fingerprint, false, || {
            source_sha256(&take.path)
        }) {
            Ok(Freshness::Current) => return take_own(skipped(take, ledger)),
            Ok(Freshness::CurrentTouched(entry)) => {
                let _ = ledger.append_shared(&entry);
                return take_own(skipped(take, ledger));
            }
            _ => {}
        }
    }
    let started = now_ns();
    // A take whose ledger line cannot be written is not converted: its outputs would not stay.
    if let Err(e) = ledger.ready_to_append() {
        let report = ErrorReport {
            hint: Some(LEDGER_HINT.to_string()),
            ..ErrorReport::from_message(
                &take.rel,
                &format!(
                    "{}: not converted: cannot record it in {}: {e}",
                    take.rel,
                    ledger.path().display()
                ),
            )
        };
        let failure = Failure {
            report,
            stat: stat.ok(),
            started,
            environment: environmental(&e).then(|| e.kind()),
            record_in_ledger: false,
            retry,
        };
        return fail(take, job, &out_dir, failure);
    }
    // The environment's error, when it is what failed the conversion.
    let mut environment = None;
    let result = fs::create_dir_all(&out_dir)
        .map_err(|e| {
            // `AlreadyExists`: a file stands where the take's folder goes.
            let replaced = e.kind() == io::ErrorKind::AlreadyExists;
            environment = (replaced || environmental(&e)).then(|| e.kind());
            format!("{}: cannot create: {e}", out_dir.display())
        })
        .and_then(|()| {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                convert(&take.path, &out_dir, plan)
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
        return take_own(TakeResult::new(take.rel.clone(), TakeStatus::Abandoned));
    }
    let previous = ledger.latest(&take.rel);
    let stat = stat.ok();
    // A failed conversion and a panic both end in an error report.
    let result = match result {
        Ok(Ok(outcome)) => Ok(outcome),
        Ok(Err(error)) => {
            environment = environmental_kind(&error);
            Err(ErrorReport::from_error(&take.rel, &error))
        }
        Err(message) => Err(ErrorReport::from_message(&take.rel, &message)),
    };
    let failure = |report, environment, record_in_ledger| {
        fail(
            take,
            job,
            &out_dir,
            Failure {
                report,
                stat,
                started,
                environment,
                record_in_ledger,
                retry,
            },
        )
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
            let result = TakeResult {
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
                recorded_at_ns: None,
                imubake_version: env!("CARGO_PKG_VERSION").to_string(),
            };
            // The error report of an earlier failure goes first, then the ledger line.
            let recorded = match remove_error_report(&out_dir, &take.stem) {
                Err(e) => Err((e, "remove its earlier error report".to_string(), true)),
                Ok(()) => ledger.append_shared(&entry).map_err(|e| {
                    let what = format!("record it in {}", ledger.path().display());
                    (e, what, false)
                }),
            };
            if let Err((e, what, ledger_writable)) = recorded {
                if crate::write::writes_abandoned() {
                    return take_own(TakeResult::new(take.rel.clone(), TakeStatus::Abandoned));
                }
                // Unrecorded, the take is not converted: its outputs go (a rerun converts it
                // again) and the error report says why, since the ledger may not.
                let report = ErrorReport {
                    hint: Some(LEDGER_HINT.to_string()),
                    ..ErrorReport::from_message(
                        &take.rel,
                        &format!("{}: converted, but cannot {what}: {e}", take.rel),
                    )
                };
                let environment = environmental(&e).then(|| e.kind());
                return failure(report, environment, ledger_writable);
            }
            take_own(result)
        }
        Err(report) => failure(report, environment, true),
    }
}

/// The hint of a take whose ledger line cannot be written.
const LEDGER_HINT: &str = "check that the output folder and its .imubake/ledger.jsonl are writable and the disk is not full";

/// A result that is the take's own (not an environmental failure).
fn take_own(result: TakeResult) -> Attempt {
    Attempt {
        result,
        environment: None,
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

/// A failed take: why, and what to record of it.
struct Failure {
    report: ErrorReport,
    stat: Option<SourceStat>,
    started: u64,
    /// The environment's error kind, when it failed the take.
    environment: Option<io::ErrorKind>,
    /// Append a ledger line (not when appending is what failed).
    record_in_ledger: bool,
    /// A retry after an environmental failure ([`attempt_take`]).
    retry: bool,
}

fn fail(take: &BatchTake, job: &TakeJob<'_>, out_dir: &Path, failure: Failure) -> Attempt {
    let TakeJob {
        out_root,
        fingerprint,
        ledger,
        ..
    } = *job;
    let Failure {
        report,
        stat,
        started,
        mut environment,
        record_in_ledger,
        retry,
    } = failure;
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
        recorded_at_ns: None,
        imubake_version: env!("CARGO_PKG_VERSION").to_string(),
    };
    let recorded_already = retry
        && ledger.latest(&take.rel).is_some_and(|prev| {
            prev.status == Status::Failed
                && prev.error == entry.error
                && prev.sha256 == entry.sha256
                && prev.settings == entry.settings
        });
    if record_in_ledger
        && !recorded_already
        && let Err(e) = ledger.append_shared(&entry)
    {
        reason.push_str(&format!(
            " (and cannot record it in {}: {e})",
            ledger.path().display()
        ));
        // A failure only the terminal tells is the environment's until it is recorded.
        if environment.is_none() && environmental(&e) {
            environment = Some(e.kind());
        }
    }
    Attempt {
        result: TakeResult {
            error_report: Some(report_rel),
            reason: Some(reason),
            ..TakeResult::new(take.rel.clone(), TakeStatus::Failed)
        },
        environment,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The environment's errors are told by their OS code; a take's own and a stop are not.
    #[test]
    fn environmental_errors_are_told_by_their_code() {
        for code in [
            libc::EACCES,
            libc::EPERM,
            libc::EROFS,
            libc::ENOSPC,
            libc::EDQUOT,
            libc::EFBIG,
            libc::ENOTDIR,
            libc::EIO,
            libc::EMFILE,
        ] {
            let e = io::Error::from_raw_os_error(code);
            assert!(environmental(&e), "{code}: {e}");
        }
        for code in [libc::EINVAL, libc::EEXIST, libc::ENAMETOOLONG, libc::EINTR] {
            let e = io::Error::from_raw_os_error(code);
            assert!(!environmental(&e), "{code}: {e}");
        }
        assert!(!environmental(&crate::write::abandoned_error()));
        // A glTF too long for its format is the take's own, a full disk writing it is not.
        let too_large = ConvertError::Output(OutputError::Gltf {
            path: "a.glb".into(),
            source: crate::write::gltf::GltfWriteError::TooLarge(5 << 30),
        });
        assert_eq!(environmental_kind(&too_large), None);
        let full = ConvertError::Output(OutputError::Write {
            path: "a.glb".into(),
            source: io::Error::from_raw_os_error(libc::ENOSPC),
        });
        assert_eq!(environmental_kind(&full), Some(io::ErrorKind::StorageFull));
    }
}
