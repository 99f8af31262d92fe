//! `imubake simulate <motion.bvh> --mapping <json> --output <file> [options]`.

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use imubake::bvh;
use imubake::mapping::{MappingFile, load_mapping};
use imubake::rig::load_rig;
use imubake::simulate::raw::{GyroBias, RawOptions};
use imubake::simulate::{CaptureFormat, SimulateOptions, simulate};
use imubake::write::write_atomic;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Clone, Copy, ValueEnum)]
enum As {
    Csv,
    Sou,
}

#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// BVH motion to play.
    motion: PathBuf,
    /// The mapping whose sensors are simulated (a quaternion mapping).
    #[arg(long, value_name = "JSON")]
    mapping: PathBuf,
    /// The capture file to write.
    #[arg(long, short)]
    output: PathBuf,
    /// Source frames A:B (inclusive; either side optional), e.g. 1: to skip frame 0.
    #[arg(long, value_name = "A:B")]
    frames: Option<String>,
    /// Capture format: imubake CSV or a paper-002 SOU log.
    #[arg(long = "as", value_enum, default_value = "csv")]
    format: As,
    /// Sensor sampling rate, Hz.
    #[arg(long, default_value_t = 100.0)]
    rate: f64,
    /// Sampling jitter (standard deviation), milliseconds.
    #[arg(long, default_value_t = 0.5)]
    jitter_ms: f64,
    /// Orientation noise: standard deviation of each rotation-vector component, degrees.
    #[arg(long, default_value_t = 0.0)]
    noise_deg: f64,
    /// Probability that a sample is lost.
    #[arg(long, default_value_t = 0.0)]
    dropout: f64,
    /// Heading of the subject about the vertical, degrees [default: random from the seed]
    #[arg(long, allow_hyphen_values = true)]
    heading_deg: Option<f64>,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seconds the calibration pose is held before the motion.
    #[arg(long, default_value_t = 2.0)]
    hold_s: f64,
    /// Seconds of blending from the calibration pose into the first frame.
    #[arg(long, default_value_t = 1.0)]
    blend_s: f64,
    /// Target bone = source joint pairs where names differ, e.g. Spine2=Spine1.
    #[arg(long, value_name = "BONE=JOINT", value_delimiter = ',')]
    bone_map: Vec<String>,
    /// Write what was simulated (heading, mounts, timing) as JSON here.
    #[arg(long, value_name = "JSON")]
    truth: Option<PathBuf>,
    /// The mapping's rig, if the mapping does not name one [default: mixamo]
    #[arg(long)]
    rig: Option<String>,
    /// Write what the sensors would have measured instead of orientations: gyroscope (rad/s),
    /// specific force (m/s², the sensor at the midpoint of its bone) and magnetic field (µT),
    /// each in the sensor's frame.
    #[arg(long)]
    raw: bool,
    /// With --raw: gyro white noise, °/s per axis.
    #[arg(long, default_value_t = 0.3, requires = "raw")]
    gyro_noise_dps: f64,
    /// With --raw: the largest constant gyro bias, °/s (each sensor's drawn up to it, in a random
    /// direction).
    #[arg(long, default_value_t = 0.5, requires = "raw")]
    gyro_bias_dps: f64,
    /// With --raw: each sensor's constant gyro bias drawn normal on every axis with this standard
    /// deviation, °/s (instead of --gyro-bias-dps).
    #[arg(long, value_name = "SD", requires = "raw", conflicts_with = "gyro_bias_dps", value_parser = parse_sd)]
    gyro_bias_sd_dps: Option<f64>,
    /// With --raw: accelerometer white noise, m/s² per axis.
    #[arg(long, default_value_t = 0.05, requires = "raw")]
    accel_noise: f64,
    /// With --raw: magnetometer white noise, µT per axis.
    #[arg(long, default_value_t = 0.3, requires = "raw")]
    mag_noise_ut: f64,
    /// With --raw: the Earth's field strength, µT.
    #[arg(long, default_value_t = 50.0, requires = "raw")]
    field_ut: f64,
    /// With --raw: the field's dip below the horizontal, degrees.
    #[arg(
        long,
        default_value_t = 65.0,
        allow_hyphen_values = true,
        requires = "raw"
    )]
    dip_deg: f64,
    /// With --raw: leave the magnetometer out (a 6D capture).
    #[arg(long, requires = "raw")]
    no_magnetometer: bool,
    /// With --raw: a magnetic disturbance, a field along east added from START to END seconds
    /// (ramped over 0.5 s), MICROTESLA strong [default strength: 30].
    #[arg(long, value_name = "START:END[:MICROTESLA]", requires = "raw")]
    mag_disturbance: Option<imubake::simulate::raw::Disturbance>,
    /// With --raw: the BVH's length unit: m, cm, mm, in, or metres per unit [default: scaled so
    /// the rest pose is --subject-height-m tall]
    #[arg(
        long,
        value_name = "UNIT",
        requires = "raw",
        conflicts_with = "subject_height_m"
    )]
    source_units: Option<imubake::simulate::raw::SourceScale>,
    /// With --raw: give each sensor intrinsic errors to calibrate away (its own draw; the truth
    /// file lists them): `default` (20 µT hard iron, 5 % soft iron, 3 % gyro gain, 1°
    /// misalignment, 0.3 m/s² and 3 % on the accelerometer), or some of
    /// hard_iron=µT,soft_iron=…,gyro_gain=…,misalignment_deg=…,acc_offset=m/s²,acc_gain=…
    #[arg(long, value_name = "default|key=value,...", requires = "raw")]
    sensor_errors: Option<imubake::simulate::raw::ErrorSizes>,
    /// With --raw, when the BVH's unit is not given: the rest pose's height, metres.
    #[arg(long, default_value_t = 1.75, requires = "raw")]
    subject_height_m: f64,
}

fn parse_frames(s: &str) -> anyhow::Result<(usize, Option<usize>)> {
    let Some((a, b)) = s.split_once(':') else {
        bail!("--frames `{s}`: expected A:B, e.g. 1: or 10:500");
    };
    let first = if a.trim().is_empty() {
        0
    } else {
        a.trim()
            .parse()
            .context("--frames: A is not a frame number")?
    };
    let last = if b.trim().is_empty() {
        None
    } else {
        Some(
            b.trim()
                .parse()
                .context("--frames: B is not a frame number")?,
        )
    };
    Ok((first, last))
}

pub fn run(args: SimulateArgs) -> anyhow::Result<ExitCode> {
    let bytes = std::fs::read(&args.motion)
        .with_context(|| format!("{}: cannot read", args.motion.display()))?;
    let motion =
        bvh::parse(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", args.motion.display()))?;
    let mapping = match load_mapping(&args.mapping)? {
        MappingFile::Quaternion(m) => m,
        MappingFile::Legacy(_) => bail!(
            "{}: simulate needs a quaternion mapping, not the legacy paper-002 format",
            args.mapping.display()
        ),
    };
    let rig_name = args
        .rig
        .clone()
        .or_else(|| mapping.rig.clone())
        .unwrap_or_else(|| "mixamo".into());
    let rig = load_rig(&rig_name)?;
    let (first_frame, last_frame) = match &args.frames {
        Some(f) => parse_frames(f)?,
        None => (0, None),
    };
    let mut bone_map = Vec::new();
    for pair in &args.bone_map {
        let Some((bone, joint)) = pair.split_once('=') else {
            bail!("--bone-map `{pair}`: expected BONE=JOINT");
        };
        bone_map.push((bone.trim().to_string(), joint.trim().to_string()));
    }
    let options = SimulateOptions {
        first_frame,
        last_frame,
        rate_hz: args.rate,
        jitter_s: args.jitter_ms / 1000.0,
        noise_deg: args.noise_deg,
        dropout: args.dropout,
        heading_deg: args.heading_deg,
        seed: args.seed,
        hold_s: args.hold_s,
        blend_s: args.blend_s,
        format: match args.format {
            As::Csv => CaptureFormat::Csv,
            As::Sou => CaptureFormat::Sou,
        },
        bone_map,
        raw: args.raw.then(|| RawOptions {
            gyro_noise_dps: args.gyro_noise_dps,
            gyro_bias: match args.gyro_bias_sd_dps {
                Some(sd) => GyroBias::SdPerAxis(sd),
                None => GyroBias::UpTo(args.gyro_bias_dps),
            },
            accel_noise: args.accel_noise,
            mag_noise_ut: args.mag_noise_ut,
            field_ut: args.field_ut,
            dip_deg: args.dip_deg,
            magnetometer: !args.no_magnetometer,
            disturbance: args.mag_disturbance,
            source_scale: args.source_units.unwrap_or(
                imubake::simulate::raw::SourceScale::RestHeight(args.subject_height_m),
            ),
            errors: args.sensor_errors,
        }),
    };
    let simulated = simulate(&motion, &rig, &mapping, &options)?;
    write_atomic(&args.output, |w| w.write_all(simulated.text.as_bytes()))
        .with_context(|| format!("{}: cannot write", args.output.display()))?;
    if let Some(path) = &args.truth {
        let json = serde_json::to_vec_pretty(&simulated.truth)?;
        write_atomic(path, |w| w.write_all(&json))
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    eprintln!(
        "{}: {} sensors, heading {:.1}°, motion from {:.3} s",
        args.output.display(),
        simulated.truth.sensors.len(),
        simulated.truth.heading_deg,
        simulated.truth.motion_start_s
    );
    Ok(ExitCode::SUCCESS)
}

fn parse_sd(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}`: expected a standard deviation ≥ 0 °/s")),
    }
}
