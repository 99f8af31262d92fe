//! `imubake convert <input>... --out <dir> [options]`.

use super::ReadArgs;
use anyhow::Context;
use clap::Args;
use imubake::config::{Config, PlanError};
use imubake::convert::{ConvertSettings, OutputFormat, Plan, convert, take_stem};
use imubake::fps::Fps;
use imubake::pipeline::Trim;
use imubake::rig::LengthUnit;
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct ConvertArgs {
    /// Capture files or session folders; each is one take.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Output folder (created if missing).
    #[arg(long, short)]
    out: PathBuf,
    #[command(flatten)]
    settings: SettingsArgs,
    /// Print the sidecar as JSON on stdout (an array for several inputs).
    #[arg(long)]
    json: bool,
}

/// The conversion settings flags, shared by `convert` and `batch`: `--config` and the flags that
/// override it.
#[derive(Debug, Args)]
pub struct SettingsArgs {
    /// YAML settings (the same keys as these flags); flags override it.
    #[arg(long, value_name = "YAML")]
    config: Option<PathBuf>,
    /// Sensor-to-bone mapping (JSON); default: sensors drive the bones named like them.
    #[arg(long, value_name = "JSON")]
    mapping: Option<PathBuf>,
    /// Target rig: a built-in name (mixamo, sou12) or a rig file (.yaml, .json).
    #[arg(long, value_name = "NAME|FILE")]
    rig: Option<String>,
    /// Frame rate: 24, 25, 29.97 (= 30000/1001), 30, 60, 2000/7, ... [default: 30]
    #[arg(long, value_name = "RATE")]
    fps: Option<Fps>,
    /// Output formats, comma-separated: bvh, glb, gltf [default: bvh,glb]
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    format: Option<Vec<OutputFormat>>,
    /// BVH length unit: m or cm (glTF is always metres) [default: m]
    #[arg(long, value_parser = parse_units)]
    units: Option<LengthUnit>,
    /// Keep only START:END seconds of the take (either side optional).
    #[arg(long, value_name = "START:END")]
    trim: Option<Trim>,
    /// Smoothing: none, butterworth[:order=4,cutoff=14[,causal]], gaussian[:sigma=0.02],
    /// fft[:threshold=0.5,suppress=0.3] or fft:cutoff=8 [default: butterworth:order=4,cutoff=14]
    #[arg(long, value_name = "METHOD[:key=value,...]")]
    smooth: Option<imubake::smooth::Method>,
    /// Also write <stem>.report.html: each bone's angles before and after smoothing, the sensor
    /// rates and the warnings.
    #[arg(long)]
    report: bool,
    /// Convert even when frames × joints exceed 5·10⁷ (about 1 GB of BVH; usually a mistyped
    /// --fps).
    #[arg(long)]
    force: bool,
    /// Causal mode: run the take as a live stream would (smoothing causal, no heading from the
    /// knees and elbows, which reads ahead), through the same incremental stages.
    #[arg(long)]
    causal: bool,
    /// The sensors' sample rate, Hz: causal smoothing's grid uses it instead of the rate of each
    /// sensor's first samples.
    #[arg(long, value_name = "HZ", value_parser = parse_rate)]
    sensor_rate: Option<f64>,
    /// Fuse raw gyroscope, accelerometer (and magnetometer) readings with this filter, even where
    /// the device gave an orientation: offline[:tau_acc=10,rest=2,motion=20,drift=0.02] (the
    /// whole take at once), vqf[:tau_acc=3,tau_mag=9], madgwick[:beta=0.12],
    /// mahony[:kp=0.74,ki=0.0012], trust[:range=2000], gyro; add `6d` to leave the magnetometer
    /// out [default: offline (vqf with --causal), for sensors with raw readings only]
    #[arg(long, value_name = "NAME[:key=value,...]")]
    fusion: Option<imubake::fusion::Fusion>,
    /// Where the body is: fixed (hips at rest height and place), ground (lowest point on the
    /// floor), feet (foot-rooted: the planted foot stays, the body walks), auto (feet when both
    /// legs are sensed down to the feet, ground when the thighs are, else fixed) [default: auto]
    #[arg(long, value_name = "MODE")]
    root: Option<imubake::pipeline::root::RootMode>,
    /// Feet mode: hold each planted foot where it stands over its contact, by turning its thigh
    /// and shank — no foot slides, at the cost of legs up to a few degrees off what their
    /// sensors measured where the subject's feet did slip
    #[arg(long)]
    foot_lock: bool,
    /// Scale the rig to a subject: a YAML file with `height_m` and/or `segments: {bone: metres}`
    #[arg(long, value_name = "FILE.yaml")]
    subject: Option<PathBuf>,
    /// Joints without a sensor: interpolate (a chain between two sensed joints shares the bend
    /// between them) or rest (keep the rest rotation) [default: interpolate]
    #[arg(long, value_name = "MODE")]
    unsensed: Option<imubake::pipeline::relative::Unsensed>,
    /// Where the subject's heading comes from: estimate (a sensor's declared `forward`, a known
    /// mount, a second pose or walking; a take whose heading is unsure by more than 10° fails) or
    /// sensors (keep the sensors' own north as the subject's facing, deliberately)
    /// [default: the mapping's `heading`, else estimate]
    #[arg(long, value_name = "SOURCE")]
    heading: Option<imubake::mapping::HeadingPolicy>,
    /// The rig's rest pose as frame 0 and the take from frame 1, as engines retarget from
    #[arg(long)]
    bind_frame: bool,
    /// Root motion for game engines: a new `root` joint at floor level above the hips carries
    /// their horizontal motion (the convention Unreal and Unity import)
    #[arg(long)]
    in_place: bool,
    /// Also write what this game engine's importer reads beside each .glb and .gltf: godot
    /// (Godot 3's `<file>.import`: the animation baked at the take's rate, no lossy optimizer;
    /// the bone names Godot will show go into the sidecar)
    #[arg(long, value_name = "ENGINE")]
    engine: Option<imubake::write::Engine>,
    /// Correct raw readings before fusion with this sensor calibration file (written by
    /// `imubake calibrate-sensors`): gyro bias and gain, accelerometer, magnetometer, per sensor.
    #[arg(long, value_name = "FILE.yaml")]
    sensor_calibration: Option<PathBuf>,
    /// A BVH take: which of its joints drive which bones, {"bones": {"joint": "bone or part"}}
    /// [default: by anatomical part, from the joints' names]
    #[arg(long, value_name = "FILE.json")]
    bone_map: Option<PathBuf>,
    /// A BVH take: the pose its joints' turns are measured from. match:N: frame N's pose, each
    /// bone aimed as its joint is there (any joint axes); frame:N: frame N is the rig's rest
    /// pose; rest: the BVH's zero pose is the rig's rest pose, with the same joint axes
    /// [default: match:0]
    #[arg(long, value_name = "match:N|frame:N|rest")]
    bvh_reference: Option<imubake::retarget::Reference>,
    /// An Xsens MVNX take: Xsens's own segment orientations and positions instead of its
    /// sensors, on a rig made from the file's segments (or retargeted onto --rig)
    #[arg(long)]
    mvnx_segments: bool,
    #[command(flatten)]
    read: ReadArgs,
}

fn parse_rate(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(r) if r.is_finite() && r > 0.0 => Ok(r),
        _ => Err(format!("`{s}`: expected a rate above 0 Hz")),
    }
}

fn parse_units(s: &str) -> Result<LengthUnit, String> {
    match s {
        "m" => Ok(LengthUnit::Metres),
        "cm" => Ok(LengthUnit::Centimetres),
        _ => Err(format!("`{s}`: expected m or cm")),
    }
}

impl SettingsArgs {
    /// The `--config` given, if any.
    pub fn config(&self) -> Option<&Path> {
        self.config.as_deref()
    }

    /// The settings: the config file's, with these flags over it.
    pub fn settings(&self) -> anyhow::Result<ConvertSettings> {
        self.settings_with(self.config())
    }

    /// The settings from `config` (a YAML file, or none) with these flags over it.
    pub fn settings_with(&self, config: Option<&Path>) -> anyhow::Result<ConvertSettings> {
        Ok(imubake::config::settings(self.layer(), config)?)
    }

    /// The plan of these settings: every file they name read once.
    pub fn plan(&self) -> anyhow::Result<Plan> {
        Ok(self.plan_with(self.config())?)
    }

    /// The plan of the settings from `config` (a YAML file, or none) with these flags over it.
    pub fn plan_with(&self, config: Option<&Path>) -> Result<Plan, PlanError> {
        imubake::config::plan(self.layer(), config)
    }

    /// These flags as one settings layer.
    fn layer(&self) -> Config {
        Config {
            mapping: self.mapping.clone(),
            rig: self.rig.clone(),
            fps: self.fps,
            formats: self.format.clone(),
            units: self.units,
            trim: self.trim,
            smoothing: self
                .smooth
                .clone()
                .map(|method| imubake::smooth::Smoothing {
                    method,
                    bones: Default::default(),
                }),
            report: self.report,
            force: self.force,
            causal: self.causal,
            sensor_rate_hz: self.sensor_rate,
            fusion: self.fusion.clone(),
            sensor_calibration: self.sensor_calibration.clone(),
            root: self.root,
            foot_lock: self.foot_lock,
            bind_frame: self.bind_frame,
            in_place: self.in_place,
            engine: self.engine,
            unsensed: self.unsensed,
            heading: self.heading,
            subject: self.subject.clone(),
            bone_map: self.bone_map.clone(),
            bvh_reference: self.bvh_reference,
            mvnx_segments: self.mvnx_segments,
            ..self.read.layer()
        }
    }
}

pub fn run(args: ConvertArgs) -> anyhow::Result<ExitCode> {
    if let Err(e) = super::check_out_folder(&args.out) {
        eprintln!("error: {e}");
        return Ok(ExitCode::from(2));
    }
    let mut stems: HashMap<String, &PathBuf> = HashMap::new();
    for input in &args.inputs {
        if let Some(other) = stems.insert(take_stem(input), input) {
            eprintln!(
                "error: {} and {} would both write `{}.*`: rename one, or convert them into different --out folders",
                other.display(),
                input.display(),
                take_stem(input)
            );
            return Ok(ExitCode::from(2));
        }
    }
    let plan = args.settings.plan()?;
    let mut sidecars = Vec::new();
    let mut failed = 0;
    for input in &args.inputs {
        match convert(input, &args.out, &plan) {
            Ok(outcome) => {
                for w in &outcome.sidecar.warnings {
                    eprintln!("warning: {}: {w}", input.display());
                }
                let (dropped, repaired) = (
                    outcome.sidecar.dropped_lines.len(),
                    outcome.sidecar.repaired_lines.len(),
                );
                if dropped + repaired > 0 {
                    eprintln!(
                        "note: {}: dropped {dropped} line{}, repaired {repaired}; see {}",
                        input.display(),
                        if dropped == 1 { "" } else { "s" },
                        outcome.sidecar_path.display()
                    );
                }
                if !args.json {
                    let outputs: Vec<_> = outcome
                        .sidecar
                        .outputs
                        .iter()
                        .map(|o| o.path.as_str())
                        .collect();
                    let fused = outcome
                        .sidecar
                        .pipeline
                        .fusion
                        .as_ref()
                        .filter(|f| !f.sensors.is_empty())
                        .map_or(String::new(), |f| {
                            format!(
                                "; fused {}",
                                imubake::fusion::algorithms_summary(f.sensors.values())
                            )
                        });
                    println!(
                        "{} → {} ({} frames at {} fps, {}{fused})",
                        input.display(),
                        args.out.display(),
                        outcome.sidecar.frames,
                        outcome.sidecar.fps,
                        outputs.join(", ")
                    );
                }
                sidecars.push(outcome.sidecar);
            }
            Err(e) => {
                failed += 1;
                eprintln!("error: {e}");
            }
        }
    }
    if args.json {
        let mut stdout = std::io::stdout().lock();
        // One input: its sidecar, or nothing when it failed (stdout stays valid JSON or empty).
        if args.inputs.len() == 1 {
            if let Some(s) = sidecars.first() {
                serde_json::to_writer_pretty(&mut stdout, s)?;
                writeln!(stdout).context("writing to stdout")?;
            }
        } else {
            serde_json::to_writer_pretty(&mut stdout, &sidecars)?;
            writeln!(stdout).context("writing to stdout")?;
        }
    }
    Ok(if failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
