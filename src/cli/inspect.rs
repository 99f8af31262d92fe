//! `imubake inspect <input> [--json]`.

use super::ReadArgs;
use clap::Args;
use imubake::inspect::Inspection;
use imubake::read::read_take;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct InspectArgs {
    /// A capture file or session folder.
    input: PathBuf,
    /// Print the summary as JSON (sidecar field names) instead of text.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    read: ReadArgs,
}

/// Dropped and repaired lines listed in the text report; `--json` lists them all.
const LINES_SHOWN: usize = 10;

pub fn run(args: InspectArgs) -> anyhow::Result<ExitCode> {
    let take = read_take(&args.input, &args.read.options())?;
    let inspection = Inspection::of(&take);
    let mut stdout = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut stdout, &inspection)?;
        writeln!(stdout)?;
    } else {
        write!(stdout, "{}", inspection.to_text(LINES_SHOWN))?;
    }
    Ok(ExitCode::SUCCESS)
}
