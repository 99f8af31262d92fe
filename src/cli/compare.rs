//! `imubake compare <a> <b> [--json]`: RMSE and Pearson's r per joint angle of two takes, BVH
//! files or angle tables, after synchronising them (paper 000's Table 1).

use super::angles::{LazyPlan, load};
use super::convert::SettingsArgs;
use clap::Args;
use imubake::analysis::{CompareOptions, Sync, compare};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The reference: a BVH file, an angle table (`imubake angles` CSV) or a capture.
    a: PathBuf,
    /// The one compared with it.
    b: PathBuf,
    /// Synchronise by xcorr (cross-correlation of the sync angle), spike (its steepest change:
    /// a clap) or none [default: xcorr]
    #[arg(long, value_name = "MODE", default_value = "xcorr")]
    sync: Sync,
    /// The angle to synchronise on [default: the one varying most in <a>]
    #[arg(long, value_name = "ANGLE")]
    sync_angle: Option<String>,
    /// The largest lag xcorr considers, seconds.
    #[arg(long, value_name = "S", default_value_t = 10.0, value_parser = parse_lag)]
    max_lag: f64,
    /// Remove each angle's mean offset before the RMSE, as paper 000 did.
    #[arg(long)]
    remove_offset: bool,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
    /// Conversion settings for inputs that are captures.
    #[command(flatten)]
    settings: SettingsArgs,
}

fn parse_lag(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a number of seconds ≥ 0")),
    }
}

pub fn run(args: CompareArgs) -> anyhow::Result<ExitCode> {
    let mut plan = LazyPlan::new(&args.settings);
    let a = load(&args.a, &mut plan)?;
    let b = load(&args.b, &mut plan)?;
    let options = CompareOptions {
        sync: args.sync,
        sync_angle: args.sync_angle,
        max_lag_s: args.max_lag,
        remove_offset: args.remove_offset,
    };
    let result = compare(&a, &b, &options)?;
    let mut stdout = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut stdout, &result)?;
        writeln!(stdout)?;
    } else {
        write!(stdout, "{}", result.table())?;
    }
    Ok(ExitCode::SUCCESS)
}
