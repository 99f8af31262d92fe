//! `imubake calibrate-sensors <raw log> --output <yaml> [--kind gyro-bias|gyro-gain|acc|mag]`:
//! each sensor's intrinsics from a calibration take, with each fit's quality, into a calibration
//! file that `convert --sensor-calibration` applies. An existing file keeps the kinds not found
//! this time.

use super::ReadArgs;
use clap::Args;
use imubake::intrinsics::magnetometer::MagFit;
use imubake::intrinsics::{CalibrateOptions, Kind, SensorCalibration, calibrate_take};
use imubake::read::read_take;
use imubake::write::write_atomic;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct CalibrateSensorsArgs {
    /// A calibration take with raw readings: the sensor lying still (gyro-bias), turned through
    /// every direction (mag), held in six positions (acc), turned whole turns about six or more
    /// axes with stillness between (gyro-gain).
    input: PathBuf,
    /// The calibration file to write (YAML); when it exists, the kinds found now replace its
    /// own and the others stay.
    #[arg(long, short)]
    output: PathBuf,
    /// What to calibrate (repeat, or comma-separate): gyro-bias, gyro-gain, acc, mag
    /// [default: every kind the take allows; the others are listed with why]
    #[arg(long, value_delimiter = ',', value_parser = parse_kind)]
    kind: Vec<Kind>,
    /// The magnetometer fit: ellipsoid (hard and soft iron) or min-max (hard iron only).
    #[arg(long, default_value = "ellipsoid", value_parser = parse_mag_fit)]
    mag_fit: MagFit,
    /// Where the sensor lay still, for the gyro bias, as START:END seconds [default: the first
    /// stretch of stillness found].
    #[arg(long, value_name = "START:END", value_parser = parse_window)]
    still: Option<(f64, f64)>,
    /// The shortest stretch of stillness, seconds.
    #[arg(long, default_value_t = 2.0, value_name = "S")]
    still_min_s: f64,
    #[command(flatten)]
    read: ReadArgs,
}

fn parse_kind(s: &str) -> Result<Kind, String> {
    s.parse()
}

fn parse_mag_fit(s: &str) -> Result<MagFit, String> {
    s.parse()
}

fn parse_window(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}`: expected START:END in seconds, e.g. 0:5"))?;
    let num = |x: &str| {
        x.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
    };
    match (num(a), num(b)) {
        (Some(a), Some(b)) if b > a => Ok((a, b)),
        _ => Err(format!(
            "`{s}`: expected START:END in seconds with END after START"
        )),
    }
}

pub fn run(args: CalibrateSensorsArgs) -> anyhow::Result<ExitCode> {
    let take = read_take(&args.input, &args.read.options())?;
    for d in take.dropped_lines() {
        let file = d
            .file
            .as_deref()
            .map(|f| format!("{f}: "))
            .unwrap_or_default();
        eprintln!("warning: {file}line {}: {} (dropped)", d.line, d.reason);
    }
    let explicit = !args.kind.is_empty();
    let kinds = if explicit {
        args.kind.clone()
    } else {
        Kind::ALL.to_vec()
    };
    let options = CalibrateOptions {
        still: imubake::intrinsics::still::StillOptions {
            min_s: args.still_min_s,
            ..Default::default()
        },
        bias_window: args.still,
        mag_fit: args.mag_fit,
    };
    let result = calibrate_take(&take, &kinds, &options);
    for n in &result.notes {
        eprintln!("note: {n}");
    }
    for (_, kind, e) in &result.failed {
        if explicit {
            eprintln!("error: {e}");
        } else {
            eprintln!("{}: not calibrated: {e}", kind.name());
        }
    }
    if result.calibration.sensors.is_empty() {
        eprintln!(
            "error: {}: nothing could be calibrated",
            args.input.display()
        );
        return Ok(ExitCode::from(1));
    }
    let merged = if args.output.exists() {
        SensorCalibration::load(&args.output)?.merged(result.calibration.clone())
    } else {
        result.calibration.clone()
    };
    let text = merged.to_yaml();
    write_atomic(&args.output, |w| w.write_all(text.as_bytes()))
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.output.display()))?;
    for (id, s) in &result.calibration.sensors {
        let mut parts = Vec::new();
        if let Some(b) = &s.gyro_bias {
            let dps = b.bias_rad_s.map(f64::to_degrees);
            parts.push(format!(
                "gyro bias ({:.3}, {:.3}, {:.3}) °/s over {:.1}–{:.1} s",
                dps[0], dps[1], dps[2], b.window_s[0], b.window_s[1]
            ));
        }
        if let Some(g) = &s.gyro_gain {
            parts.push(format!(
                "gyro gain from {} rotations, turn residual {:.2} % → {:.3} %",
                g.rotations.len(),
                g.residual_before_pct,
                g.residual_after_pct
            ));
        }
        if let Some(a) = &s.accelerometer {
            parts.push(format!(
                "accelerometer from {} positions, |a| − g {:.3} → {:.4} m/s² RMS",
                a.positions, a.residual_before_m_s2, a.residual_after_m_s2
            ));
        }
        if let Some(m) = &s.magnetometer {
            parts.push(format!(
                "magnetometer ({:?}) field norm residual {:.2} % → {:.2} % ({:.2} % → {:.2} % without the {:.1} % \
                 set aside as disturbed), {:.0} % of directions",
                m.fit,
                m.residual_before_pct,
                m.residual_after_pct,
                m.kept_residual_before_pct,
                m.kept_residual_after_pct,
                m.set_aside_pct,
                m.coverage_pct
            ));
        }
        eprintln!("{id}: {}", parts.join("; "));
    }
    eprintln!("→ {}", args.output.display());
    Ok(if explicit && !result.failed.is_empty() {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
