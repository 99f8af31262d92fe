//! `imubake fuse <input> -o <file.csv> [--fusion NAME[:key=value,...]]`: raw readings in, each
//! sensor's fused orientation `q_enu_sensor` at every inertial sample out, as imubake CSV.

use super::ReadArgs;
use clap::Args;
use imubake::fusion::{Fusion, fuse_take};
use imubake::read::read_take;
use imubake::world::World;
use imubake::write::{orientation_csv, write_atomic};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct FuseArgs {
    /// A capture file or session folder with raw gyroscope and accelerometer readings.
    input: PathBuf,
    /// The CSV to write (time_s,sensor,qw,qx,qy,qz in the ENU world).
    #[arg(long, short)]
    output: PathBuf,
    /// The filter: offline[:tau_acc=10,rest=2,motion=20,drift=0.02], vqf[:tau_acc=3,tau_mag=9],
    /// madgwick[:beta=0.12], mahony[:kp=0.74,ki=0.0012], trust[:range=2000], gyro; add `6d` to
    /// leave the magnetometer out [default: offline]
    #[arg(long, value_name = "NAME[:key=value,...]")]
    fusion: Option<Fusion>,
    /// Print what each sensor's fusion came to (the sidecar's `pipeline.fusion`) as JSON.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    read: ReadArgs,
}

pub fn run(args: FuseArgs) -> anyhow::Result<ExitCode> {
    let take = read_take(&args.input, &args.read.options())?;
    let fusion = args.fusion.unwrap_or_default();
    let fused = fuse_take(&take, &fusion)?;
    if fused.is_empty() {
        eprintln!(
            "error: {}: no sensor has raw gyroscope and accelerometer readings",
            args.input.display()
        );
        return Ok(ExitCode::from(1));
    }
    for (_, f) in &fused {
        for w in &f.warnings {
            eprintln!("warning: {w}");
        }
    }
    let tracks: Vec<_> = fused
        .iter()
        .map(|(id, f)| (id.as_str(), &f.track))
        .collect();
    let comments = vec![format!("imubake fuse {}: {fusion}", args.input.display())];
    write_atomic(&args.output, |w| {
        orientation_csv::write(w, World::Enu, &comments, &tracks)
    })
    .map_err(|e| anyhow::anyhow!("{}: {e}", args.output.display()))?;
    if args.json {
        let sensors: BTreeMap<&str, _> = fused
            .iter()
            .map(|(id, f)| (id.as_str(), &f.stats))
            .collect();
        let mut stdout = std::io::stdout().lock();
        serde_json::to_writer_pretty(
            &mut stdout,
            &serde_json::json!({"fusion": fusion, "sensors": sensors}),
        )?;
        writeln!(stdout)?;
    } else {
        eprintln!(
            "{} → {} ({} sensors, {fusion})",
            args.input.display(),
            args.output.display(),
            fused.len()
        );
        let width = fused
            .iter()
            .map(|(id, _)| id.chars().count())
            .max()
            .unwrap_or(0);
        for (id, f) in &fused {
            eprintln!("  {id:width$}  {}", f.stats.describe());
        }
    }
    Ok(ExitCode::SUCCESS)
}
