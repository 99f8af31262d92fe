//! `imubake angles <input> [--csv | --json] [-o FILE]`: paper 000's joint angles per frame of a
//! BVH file, an angle table, or a capture converted in memory with the `convert` settings.

use super::convert::SettingsArgs;
use clap::Args;
use imubake::analysis::{AngleTable, angles};
use imubake::convert::Plan;
use imubake::write::write_atomic;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct AnglesArgs {
    /// A BVH file (its own skeleton), or a capture (file or session folder) converted with the
    /// settings below as `convert` would.
    input: PathBuf,
    /// Write CSV: frame,time_s,<angle>,... in degrees (the default).
    #[arg(long, conflicts_with = "json")]
    csv: bool,
    /// Write JSON: {"units", "time_s": [...], "angles": {name: [...]}} (NaN as null).
    #[arg(long)]
    json: bool,
    /// Write to this file (atomically) instead of standard output.
    #[arg(long, short)]
    output: Option<PathBuf>,
    #[command(flatten)]
    settings: SettingsArgs,
}

/// Is `path` a BVH file (by its extension, or its first word)?
fn is_bvh(path: &Path) -> bool {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("bvh"))
    {
        return true;
    }
    let mut head = [0u8; 16];
    std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
        .is_ok_and(|n| {
            std::str::from_utf8(&head[..n]).is_ok_and(|s| s.trim_start().starts_with("HIERARCHY"))
        })
}

/// Is `path` an angle table (a CSV whose header has `time_s` and a joint angle's name)?
fn is_angle_table(path: &Path) -> bool {
    if !path.is_file() {
        return false;
    }
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    let mut header = String::new();
    let _ = std::io::BufRead::read_line(&mut std::io::BufReader::new(file), &mut header);
    let fields: Vec<&str> = header.trim().split(',').map(str::trim).collect();
    fields.contains(&"time_s")
        && fields.iter().any(|f| {
            ["left_", "right_"].iter().any(|side| {
                f.strip_prefix(side)
                    .is_some_and(|rest| angles::JOINTS.iter().any(|j| rest.starts_with(j)))
            })
        })
}

/// The plan of a command's settings, resolved the first time a capture needs it and kept for
/// the inputs after (a BVH file or an angle table needs none).
pub struct LazyPlan<'a> {
    settings: &'a SettingsArgs,
    plan: Option<Plan>,
}

impl<'a> LazyPlan<'a> {
    pub fn new(settings: &'a SettingsArgs) -> LazyPlan<'a> {
        LazyPlan {
            settings,
            plan: None,
        }
    }

    fn get(&mut self) -> anyhow::Result<&Plan> {
        if self.plan.is_none() {
            self.plan = Some(self.settings.plan()?);
        }
        Ok(self.plan.as_ref().expect("resolved above"))
    }
}

/// The angle table of an input: a BVH file's motion, an angle table as it is, else a capture
/// converted with the plan.
pub fn load(input: &Path, plan: &mut LazyPlan<'_>) -> anyhow::Result<AngleTable> {
    if is_bvh(input) {
        let bytes =
            std::fs::read(input).map_err(|e| anyhow::anyhow!("{}: {e}", input.display()))?;
        let bvh =
            imubake::bvh::parse(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", input.display()))?;
        let name = imubake::convert::take_stem(input);
        // The segments' frames read in the pose a BVH take is retargeted from (`--bvh-reference`).
        let reference = plan.get()?.settings().bvh_reference.frame();
        return angles::of_bvh(&bvh, &name, reference)
            .map_err(|e| anyhow::anyhow!("{}: {e}", input.display()));
    }
    if is_angle_table(input) {
        return Ok(AngleTable::read_csv(input)?);
    }
    let plan = plan.get()?;
    let animation = imubake::convert::animate(input, plan)?;
    angles::of_animation(&animation, plan.calibration_pose().as_deref())
        .map_err(|e| anyhow::anyhow!("{}: {e}", input.display()))
}

pub fn run(args: AnglesArgs) -> anyhow::Result<ExitCode> {
    let table = load(&args.input, &mut LazyPlan::new(&args.settings))?;
    let text = if args.json {
        let mut s = serde_json::to_string(&table.to_json())?;
        s.push('\n');
        s
    } else {
        table.to_csv()
    };
    match &args.output {
        Some(path) => {
            write_atomic(path, |w| w.write_all(text.as_bytes()))
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            eprintln!(
                "{} → {} ({} angles × {} frames)",
                args.input.display(),
                path.display(),
                table.names().len(),
                table.rows()
            );
        }
        None => std::io::stdout().lock().write_all(text.as_bytes())?,
    }
    Ok(ExitCode::SUCCESS)
}
