//! `imubake inspect <input> [--json]`: a capture's summary; or a rig's anatomy, when the input
//! is a rig (a built-in name, a `.yaml`/`.json` rig file, or a BVH file's skeleton).

use super::ReadArgs;
use clap::Args;
use imubake::inspect::Inspection;
use imubake::read::read_take;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct InspectArgs {
    /// A capture file or session folder; or a rig (a built-in name such as `mixamo`, a rig file,
    /// or a `.bvh`): then the body parts found in it, and how.
    input: PathBuf,
    /// Print the summary as JSON (sidecar field names) instead of text.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    read: ReadArgs,
}

/// Dropped and repaired lines listed in the text report; `--json` lists them all.
const LINES_SHOWN: usize = 10;

/// Whether the input names a rig rather than a capture.
fn is_rig(input: &std::path::Path) -> bool {
    let ext = input
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("yaml" | "yml" | "bvh") => true,
        // A JSON rig has `joints`; a JSON capture (none is read yet) would not.
        Some("json") => std::fs::read_to_string(input).is_ok_and(|t| t.contains("\"joints\"")),
        None => {
            !input.exists()
                && imubake::rig::file::BUILTIN
                    .iter()
                    .any(|(n, _)| input == std::path::Path::new(n))
        }
        _ => false,
    }
}

fn run_rig(args: &InspectArgs) -> anyhow::Result<ExitCode> {
    let rig = imubake::rig::load_rig(&args.input.to_string_lossy())?;
    let anatomy = imubake::rig::anatomy::Anatomy::of(&rig);
    let mut stdout = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut stdout, &anatomy.to_json())?;
        writeln!(stdout)?;
    } else {
        writeln!(
            stdout,
            "rig {} ({} joints): body parts",
            rig.name(),
            rig.len()
        )?;
        for line in anatomy.describe() {
            writeln!(stdout, "  {line}")?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

pub fn run(args: InspectArgs) -> anyhow::Result<ExitCode> {
    if is_rig(&args.input) {
        return run_rig(&args);
    }
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
