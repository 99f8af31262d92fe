//! Command-line interface: one module per subcommand.

mod inspect;

use clap::{Args, Parser, Subcommand};
use imubake::read::{InputFormat, ReadOptions};
use imubake::world::World;
use std::process::ExitCode;

#[derive(Debug, Parser)]
#[command(
    name = "imubake",
    version,
    about = "Body-worn IMU captures in, clean animation out"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Summarise a capture: time frame, nodes, sample rates, gaps, dropped lines.
    Inspect(inspect::InspectArgs),
}

/// Flags shared by every command that reads captures.
#[derive(Debug, Args, Clone)]
pub struct ReadArgs {
    /// Read as this format instead of detecting it from content.
    #[arg(long, value_name = "FORMAT", value_parser = parse_format)]
    input_format: Option<InputFormat>,
    /// Drop the first N lines of the log (fixed-length cleaning).
    #[arg(long, value_name = "N", default_value_t = 0)]
    skip_lines: u64,
    /// Drop samples in the first S seconds; t = 0 moves to the earliest kept sample.
    #[arg(long, value_name = "S", default_value_t = 0.0, value_parser = parse_seconds)]
    skip_seconds: f64,
    /// The sensors' world frame, overriding the format's (enu, ned, nwu, opensim).
    #[arg(long, value_name = "WORLD")]
    world: Option<World>,
}

impl ReadArgs {
    pub fn options(&self) -> ReadOptions {
        ReadOptions {
            format: self.input_format,
            skip_lines: self.skip_lines,
            skip_seconds: self.skip_seconds,
            world: self.world,
        }
    }
}

fn parse_format(s: &str) -> Result<InputFormat, String> {
    s.parse()
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a number of seconds ≥ 0")),
    }
}

pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Inspect(args) => inspect::run(args),
    }
}
