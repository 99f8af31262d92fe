//! The `imubake` command: parses flags once, installs the log subscriber, runs a subcommand, maps
//! errors to exit codes (0 success, 1 a take failed or bad input, 2 usage error — clap exits with
//! 2 itself).

mod cli;

use clap::Parser;
use std::io::IsTerminal;
use std::process::ExitCode;
use tracing_subscriber::EnvFilter;

/// The variables that set the log level, first found wins (`IMUBAKE_LOG=debug`, or any
/// `tracing-subscriber` `EnvFilter` directive such as `imubake=debug`).
const LOG_VARS: [&str; 2] = ["IMUBAKE_LOG", "RUST_LOG"];

/// The library logs through `tracing` (`watch` and `batch`: one line per take with its duration);
/// this prints those events on stderr, one compact human-readable line each, coloured only on a
/// terminal (and not with `NO_COLOR`), at `info` unless `IMUBAKE_LOG` or `RUST_LOG` says otherwise.
/// At `debug`, each stage of a conversion is a span whose line at its end gives its wall time
/// (`time.busy`): `IMUBAKE_LOG=imubake=debug imubake convert …` is a profile per stage.
fn init_logging() {
    let mut filter = None;
    for var in LOG_VARS {
        let Ok(value) = std::env::var(var) else {
            continue;
        };
        if value.trim().is_empty() {
            continue;
        }
        match EnvFilter::try_new(&value) {
            Ok(f) => filter = Some(f),
            Err(e) => eprintln!("warning: {var}=`{value}`: {e}; logging at info"),
        }
        break;
    }
    let ansi = std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none();
    tracing_subscriber::fmt()
        .compact()
        .with_target(false)
        .with_span_events(tracing_subscriber::fmt::format::FmtSpan::CLOSE)
        .with_ansi(ansi)
        .with_writer(std::io::stderr)
        .with_env_filter(filter.unwrap_or_else(|| EnvFilter::new("info")))
        .init();
}

/// The error and its causes, each cause only when the text so far does not already say it
/// (library errors quote their source in their own message).
fn error_chain(e: &anyhow::Error) -> String {
    let mut text = e.to_string();
    for cause in e.chain().skip(1) {
        let cause = cause.to_string();
        if !text.contains(&cause) {
            text.push_str(": ");
            text.push_str(&cause);
        }
    }
    text
}

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    init_logging();
    match cli::run(args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            ExitCode::from(1)
        }
    }
}
