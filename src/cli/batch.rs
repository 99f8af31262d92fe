//! `imubake batch <files|folders|globs>... --out <dir> [--jobs N] [--shard I/N] [options]`.

use super::convert::SettingsArgs;
use anyhow::Context;
use clap::Args;
use imubake::batch::{self, DiscoverOptions, Shard, Summary, TakeResult, TakeStatus};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// The exit code of a batch stopped by SIGINT or SIGTERM (the shell's 128 + SIGINT).
const INTERRUPTED: i32 = 130;
use tracing::{debug, error, info, warn};

#[derive(Debug, Args)]
pub struct BatchArgs {
    /// Capture files, folders (each file and session sub-folder in them, recursively, is a take;
    /// a session folder is one take) and globs (`*`, `?`, `**`).
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Output root: each take's outputs go to <out>/<its relative folder>/<stem>.*; the ledger to
    /// <out>/.imubake/ledger.jsonl (a shard's to ledger.shard-I-of-N.jsonl beside it).
    #[arg(long, short)]
    out: PathBuf,
    /// Conversions at once [default: one per core].
    #[arg(long, short, value_name = "N")]
    jobs: Option<usize>,
    /// Convert only the takes whose index in relative-path order is I modulo N. Default: from
    /// JOB_COMPLETION_INDEX + IMUBAKE_SHARD_COUNT (Kubernetes Indexed Job) or
    /// SLURM_ARRAY_TASK_ID + SLURM_ARRAY_TASK_COUNT (Slurm array), else all takes.
    #[arg(long, value_name = "I/N")]
    shard: Option<Shard>,
    /// List the takes of this shard (relative paths) and exit without converting.
    #[arg(long)]
    list: bool,
    /// Follow symlinks whose targets are outside the input folders (by default they are skipped
    /// with a warning).
    #[arg(long)]
    follow_symlinks: bool,
    #[command(flatten)]
    settings: SettingsArgs,
    /// Print the result as JSON on stdout: {"converted", "failed", "skipped", "shard", "takes"}.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct Report<'a> {
    #[serde(flatten)]
    summary: &'a Summary,
    shard: Option<Shard>,
    takes: &'a [TakeResult],
}

pub fn run(args: BatchArgs) -> anyhow::Result<ExitCode> {
    let shard = match args.shard {
        Some(s) => Some(s),
        None => match Shard::from_env(|k| std::env::var(k).ok()) {
            Ok(s) => s.map(|(s, from)| {
                info!(shard = %s, variables = from, "shard from the environment");
                s
            }),
            Err(e) => {
                error!("{e}");
                return Ok(ExitCode::from(2));
            }
        },
    };
    if let Err(e) = super::check_out_folder(&args.out) {
        error!("{e}");
        return Ok(ExitCode::from(2));
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create", args.out.display()))?;
    let options = DiscoverOptions {
        exclude: Some(&args.out),
        follow_symlinks: args.follow_symlinks,
    };
    let takes = match batch::discover(&args.inputs, options) {
        Ok(found) => {
            for skipped in &found.skipped {
                let path = skipped.path.display();
                if skipped.reason.is_warning() {
                    warn!(path = %path, "{}", skipped.reason);
                } else {
                    debug!(path = %path, "{}", skipped.reason);
                }
            }
            found.takes
        }
        Err(e) => {
            error!("{e}");
            return Ok(ExitCode::from(2));
        }
    };
    let total = takes.len();
    let takes = match shard {
        Some(s) => s.select(takes),
        None => takes,
    };
    if args.list {
        let mut stdout = std::io::stdout().lock();
        if args.json {
            let rels: Vec<&str> = takes.iter().map(|t| t.rel.as_str()).collect();
            serde_json::to_writer_pretty(&mut stdout, &rels)?;
            writeln!(stdout)?;
        } else {
            for t in &takes {
                writeln!(stdout, "{}", t.rel)?;
            }
        }
        return Ok(ExitCode::SUCCESS);
    }
    let plan = args.settings.plan()?;

    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(Some(takes.len() as u64), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} takes, {elapsed} (eta {eta}) {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    if let Some(s) = shard {
        bar.set_message(format!("shard {s} of {total} takes"));
    }
    // One line per converted or failed take, with its duration (and its warnings), above the bar.
    let on_result = |r: &TakeResult| {
        bar.suspend(|| r.log());
        bar.inc(1);
    };
    let jobs = args.jobs.unwrap_or(0);
    // SIGINT/SIGTERM: no new take starts; those in progress may finish within the grace period,
    // then their writes are abandoned (temporary files removed, nothing recorded) and the
    // process exits.
    let stop = super::stop_on_signals()?;
    {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            while !stop.load(Ordering::SeqCst) {
                std::thread::sleep(Duration::from_millis(20));
            }
            std::thread::sleep(imubake::watch::FINISH_GRACE);
            let removed = imubake::write::abandon_writes();
            warn!(
                "stopped: takes still converting were abandoned ({} temporary file(s) removed)",
                removed.len()
            );
            std::process::exit(INTERRUPTED);
        });
    }
    let results = batch::run(&takes, &args.out, shard, &plan, jobs, &stop, &on_result)
        .with_context(|| format!("{}: cannot run the batch", args.out.display()))?;
    bar.finish_and_clear();

    let summary = Summary::of(&results);
    let mut stdout = std::io::stdout().lock();
    if args.json {
        let report = Report {
            summary: &summary,
            shard,
            takes: &results,
        };
        serde_json::to_writer_pretty(&mut stdout, &report)?;
        writeln!(stdout).context("writing to stdout")?;
    } else {
        writeln!(stdout, "{summary}").context("writing to stdout")?;
    }
    if stop.load(Ordering::SeqCst) {
        let left = takes.len() - results.len();
        warn!("stopped by a signal; {left} take(s) not started");
        return Ok(ExitCode::from(INTERRUPTED as u8));
    }
    let failed = results.iter().any(|r| r.status == TakeStatus::Failed);
    Ok(if failed {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
