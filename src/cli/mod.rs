//! Command-line interface: one module per subcommand.

mod angles;
mod batch;
mod calibrate_sensors;
mod compare;
mod convert;
mod fuse;
mod inspect;
mod live;
mod setup;
mod simulate;
mod view;
mod watch;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use imubake::config::Config;
use imubake::read::{InputFormat, ReadOptions};
use imubake::world::{World, WorldFrom};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

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
    /// Convert captures into keyframed BVH and glTF on a rig, with a JSON sidecar.
    Convert(convert::ConvertArgs),
    /// Find each sensor's gyro bias and gain, accelerometer and magnetometer corrections from a
    /// calibration take, into a file `convert --sensor-calibration` applies.
    CalibrateSensors(calibrate_sensors::CalibrateSensorsArgs),
    /// Convert many takes in parallel (files, folders, globs), skipping those already current.
    Batch(batch::BatchArgs),
    /// Fuse raw gyroscope, accelerometer (and magnetometer) readings into orientations (CSV).
    Fuse(fuse::FuseArgs),
    /// Summarise a capture: time frame, nodes, sample rates, gaps, dropped lines.
    Inspect(inspect::InspectArgs),
    /// Simulate the capture a mapping's sensors would record from BVH motion (tests, samples).
    Simulate(simulate::SimulateArgs),
    /// Convert an inbox's backlog, then each take as it arrives or changes.
    Watch(watch::WatchArgs),
    /// Sensors to a moving character in real time: serial, UDP, TCP in; VMC out; recorded.
    Live(live::LiveArgs),
    /// Joint angles per frame (paper 000): between segments, and flexion, abduction, rotation.
    Angles(angles::AnglesArgs),
    /// RMSE and Pearson's r per joint angle of two takes after synchronising them (paper 000's
    /// Table 1).
    Compare(compare::CompareArgs),
    /// A take in the browser: the character in 3D, play, scrub, sensors' axes, foot contacts.
    View(view::ViewArgs),
    /// Bring up a suit in the browser: every sensor live, lit when moved, put on a bone, its
    /// gyro bias and the pose calibrated; saves the mapping, subject and sensor calibration.
    Setup(setup::SetupArgs),
}

/// Flags shared by every command that reads captures.
#[derive(Debug, Args, Clone)]
pub struct ReadArgs {
    /// Read as this format instead of detecting it from content.
    #[arg(long, value_name = "FORMAT", value_parser = input_format_parser())]
    input_format: Option<InputFormat>,
    /// Drop the first N lines of the log (fixed-length cleaning).
    #[arg(long, value_name = "N")]
    skip_lines: Option<u64>,
    /// Drop samples in the first S seconds; t = 0 moves to the earliest kept sample.
    #[arg(long, value_name = "S", value_parser = parse_seconds)]
    skip_seconds: Option<f64>,
    /// The sensors' world frame, overriding the format's (enu, ned, nwu, opensim, rig).
    #[arg(long, value_name = "WORLD")]
    world: Option<World>,
    /// Samples per second of recordings without timestamps (WitMotion without time packets; an
    /// Xsens MTw export with neither `// Update Rate:` nor SampleTimeFine)
    #[arg(long, value_name = "HZ", value_parser = parse_rate_hz)]
    rate: Option<f64>,
    /// Read captures through this packet layout (a YAML file: how a home-made device's frames
    /// are delimited and what each field is; docs, "Packet layouts")
    #[arg(long, value_name = "FILE.yaml")]
    layout: Option<std::path::PathBuf>,
}

impl ReadArgs {
    /// The read options these flags give alone (`inspect`).
    pub fn options(&self) -> ReadOptions {
        self.layer().to_settings(WorldFrom::Flag).read
    }

    /// These flags as a settings layer.
    pub fn layer(&self) -> Config {
        Config {
            input_format: self.input_format,
            skip_lines: self.skip_lines,
            skip_seconds: self.skip_seconds,
            world: self.world,
            rate_hz: self.rate,
            layout: self.layout.clone(),
            ..Config::default()
        }
    }
}

/// `--input-format`'s values, from [`InputFormat::ALL`]: `-h` lists their names, `--help` each
/// with what it reads, and a wrong one is refused with the list.
fn input_format_parser() -> impl clap::builder::TypedValueParser<Value = InputFormat> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new(
        InputFormat::ALL.map(|f| PossibleValue::new(f.name()).help(f.description())),
    )
    .map(|name| {
        name.parse::<InputFormat>()
            .expect("every possible value is a format's name")
    })
}

fn parse_rate_hz(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a rate in Hz above 0")),
    }
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a number of seconds ≥ 0")),
    }
}

/// A flag set by SIGINT or SIGTERM.
pub fn stop_on_signals() -> anyhow::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop))
            .context("cannot install the signal handlers")?;
    }
    Ok(stop)
}

/// `--out` must be a folder (created if missing), not an existing file.
pub fn check_out_folder(out: &std::path::Path) -> Result<(), String> {
    if out.exists() && !out.is_dir() {
        return Err(format!(
            "--out {}: is a file; expected a folder (created if missing)",
            out.display()
        ));
    }
    Ok(())
}

pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Convert(args) => convert::run(args),
        Command::Batch(args) => batch::run(args),
        Command::CalibrateSensors(args) => calibrate_sensors::run(args),
        Command::Fuse(args) => fuse::run(args),
        Command::Inspect(args) => inspect::run(args),
        Command::Simulate(args) => simulate::run(args),
        Command::Watch(args) => watch::run(args),
        Command::Live(args) => live::run(args),
        Command::Angles(args) => angles::run(args),
        Command::Compare(args) => compare::run(args),
        Command::View(args) => view::run(args),
        Command::Setup(args) => setup::run(args),
    }
}
