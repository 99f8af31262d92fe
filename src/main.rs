//! The `imubake` command: parses flags once, runs a subcommand, maps errors to exit codes
//! (0 success, 1 a take failed or bad input, 2 usage error — clap exits with 2 itself).

mod cli;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}
