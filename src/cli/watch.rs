//! `imubake watch <inbox> --out <dir> [--config <yaml>] [--poll <ms>] [--once] [--reconvert]`.

use super::convert::SettingsArgs;
use anyhow::Context;
use clap::Args;
use imubake::watch::{self, WatchOptions};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

#[derive(Debug, Args)]
pub struct WatchArgs {
    /// The inbox: each top-level file or session folder in it is one take.
    inbox: PathBuf,
    /// Output root: each take's outputs go to <out>/<its relative folder>/<stem>.*; the ledger to
    /// <out>/.imubake/ledger.jsonl.
    #[arg(long, short)]
    out: PathBuf,
    /// Poll the inbox every MS milliseconds instead of waiting for file-system events (network
    /// shares, containers).
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(10..))]
    poll: Option<u64>,
    /// A take is complete when its size and modification time stay the same this long (or when
    /// its file is closed after writing or renamed into place, where the platform reports it);
    /// on Linux, never while a process still has it open for writing.
    #[arg(long, value_name = "MS", default_value_t = 500, value_parser = clap::value_parser!(u64).range(500..))]
    settle: u64,
    /// Convert the backlog and exit (exit code 1 if a take failed).
    #[arg(long)]
    once: bool,
    /// When the settings change (imubake.yaml edited), reconvert the takes converted before.
    #[arg(long)]
    reconvert: bool,
    /// Follow symlinks whose targets are outside the inbox (by default they are skipped with a
    /// warning).
    #[arg(long)]
    follow_symlinks: bool,
    /// Settings flags; without --config, <inbox>/imubake.yaml is the config when it exists.
    #[command(flatten)]
    settings: SettingsArgs,
}

pub fn run(args: WatchArgs) -> anyhow::Result<ExitCode> {
    if !args.inbox.is_dir() {
        tracing::error!(inbox = %args.inbox.display(), "not a folder");
        return Ok(ExitCode::from(2));
    }
    if let Err(e) = super::check_out_folder(&args.out) {
        tracing::error!("{e}");
        return Ok(ExitCode::from(2));
    }
    let user_config = args.settings.config().map(Path::to_path_buf);
    let mut opts = WatchOptions::new(args.inbox.clone(), args.out.clone(), user_config.clone());
    opts.poll = args.poll.map(Duration::from_millis);
    opts.once = args.once;
    opts.settle = Duration::from_millis(args.settle);
    opts.reconvert = args.reconvert;
    opts.follow_symlinks = args.follow_symlinks;
    let stop = super::stop_on_signals()?;
    // `--config` wins; else the inbox's imubake.yaml the watcher passes in. Flags override both.
    let load = |config: Option<&Path>| args.settings.plan_with(user_config.as_deref().or(config));
    let summary = match watch::run(&opts, &load, &stop) {
        Ok(summary) => summary,
        // Another watcher follows this output folder: say which, and stop at once.
        Err(e @ watch::WatchError::AlreadyWatched { .. }) => {
            tracing::error!("{e}");
            return Ok(ExitCode::from(1));
        }
        Err(e) => {
            return Err(e).with_context(|| format!("{}: cannot watch", args.inbox.display()));
        }
    };
    println!("{summary}");
    Ok(if args.once && summary.failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
