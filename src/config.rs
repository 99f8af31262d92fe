//! Settings, parsed once, the ripgrep way: a [`Config`] is a layer of settings, every field
//! optional and already of its own type (a YAML file deserialises straight into one, and so do
//! the command-line flags); layers are stacked with [`Config::over`] — flags over the config
//! file — and turned into [`ConvertSettings`] by [`Config::to_settings`]. The YAML file is the one
//! `convert --config` and `watch` read (README, "Configuration"); paths in it are relative to its
//! folder.
//!
//! ```yaml
//! mapping: mappings/paper002_sou12_mixamo.json
//! rig: mixamo            # a built-in rig or a rig file
//! fps: 29.97             # or 30000/1001
//! formats: [bvh, glb]    # bvh, glb, gltf
//! units: m               # BVH length unit: m or cm
//! trim: "2.5:60"         # seconds, either side optional
//! root: fixed
//! foot_lock: false       # feet mode: hold each planted foot where it stands (turns the legs)
//! input_format: sou      # skip detection
//! skip_lines: 0
//! skip_seconds: 0
//! rate_hz: 200           # recordings without timestamps (WitMotion without time packets)
//! layout: device.yaml    # a home-made device's packet layout; relative to this file
//! world: ned             # override the format's world
//! causal: false          # run the take as a live stream would (causal smoothing, no look-ahead)
//! bind_frame: false      # the rest pose as frame 0, the take from frame 1
//! in_place: false        # a root joint at floor level carries the hips' horizontal motion
//! engine: godot          # also write what the engine's importer reads beside each glb/gltf
//! unsensed: interpolate  # joints between two sensors share the bend; or rest
//! heading: estimate      # from the take, refused when unsure; or sensors (keep their north)
//! sensor_rate_hz: 100    # the sensors' rate, for causal smoothing (else from their first samples)
//! fusion: offline        # fuse raw readings even where the device gave orientations; or
//!                        # madgwick:beta=0.1, mahony, trust, gyro, vqf:6d (no magnetometer)
//! sensor_calibration: sensors.yaml   # calibrate-sensors' file; relative to this one
//! subject: subject.yaml  # height_m and/or segment lengths: the rig scaled to the subject
//! bone_map: bones.json   # a BVH take: which joint drives which bone (default: by part)
//! bvh_reference: match:0 # a BVH take: its frame 0's pose matched; or frame:N, rest
//! mvnx_segments: false   # an MVNX take: Xsens's own segment kinematics instead of its sensors
//! smoothing: butterworth:order=4,cutoff=14   # or none, gaussian:sigma=0.02, fft, fft:cutoff=8
//! # or with per-bone overrides:
//! # smoothing: {method: "butterworth:cutoff=4", bones: {LeftHand: none, Head: "gaussian:sigma=0.05"}}
//! ```

use crate::convert::{ConvertSettings, Given, Layer, OutputFormat};
use crate::fps::Fps;
use crate::pipeline::Trim;
use crate::pipeline::root::RootMode;
use crate::rig::LengthUnit;
use crate::smooth::Smoothing;
use crate::take::InputFormat;
use crate::world::{World, WorldFrom};
use serde::{Deserialize, Deserializer};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One layer of settings: a config file, or the flags given. `None` (and `false`) leave a
/// setting to the layer below.
#[derive(Debug, Clone, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Config {
    pub mapping: Option<PathBuf>,
    pub rig: Option<String>,
    pub fps: Option<Fps>,
    #[serde(default, deserialize_with = "formats")]
    pub formats: Option<Vec<OutputFormat>>,
    pub units: Option<LengthUnit>,
    #[serde(default, deserialize_with = "trim")]
    pub trim: Option<Trim>,
    pub root: Option<RootMode>,
    /// Feet mode: hold each planted foot where it stands (a flag: `--foot-lock`).
    #[serde(default)]
    pub foot_lock: bool,
    #[serde(default, deserialize_with = "input_format")]
    pub input_format: Option<InputFormat>,
    pub skip_lines: Option<u64>,
    #[serde(default, deserialize_with = "skip_seconds")]
    pub skip_seconds: Option<f64>,
    /// Samples per second of recordings without timestamps (WitMotion without time packets).
    #[serde(default, deserialize_with = "rate_hz")]
    pub rate_hz: Option<f64>,
    pub world: Option<World>,
    /// A packet layout file, relative to the config file.
    pub layout: Option<PathBuf>,
    #[serde(default, deserialize_with = "smoothing")]
    pub smoothing: Option<Smoothing>,
    /// Also write the report (a flag: `true` in any layer asks for it).
    #[serde(default)]
    pub report: bool,
    /// Allow absurd frame counts (a flag).
    #[serde(default)]
    pub force: bool,
    /// Causal mode: the take runs through the stream's cores (a flag).
    #[serde(default)]
    pub causal: bool,
    /// The rest pose as frame 0, the take from frame 1 (a flag).
    #[serde(default)]
    pub bind_frame: bool,
    /// A `root` joint at floor level carries the hips' horizontal motion (a flag).
    #[serde(default)]
    pub in_place: bool,
    /// A game engine whose import settings are written beside the glTF outputs.
    #[serde(default, deserialize_with = "engine")]
    pub engine: Option<crate::write::Engine>,
    /// What joints without a sensor do: interpolate (default) or rest.
    pub unsensed: Option<crate::pipeline::relative::Unsensed>,
    /// Where the heading comes from: estimate (the mapping's default) or sensors.
    pub heading: Option<crate::mapping::HeadingPolicy>,
    /// The sensors' sample rate, Hz, for causal smoothing's grid.
    #[serde(default, deserialize_with = "sensor_rate")]
    pub sensor_rate_hz: Option<f64>,
    /// Fusion of raw readings, for every sensor that has them.
    #[serde(default, deserialize_with = "fusion")]
    pub fusion: Option<crate::fusion::Fusion>,
    /// A sensor calibration file (`imubake calibrate-sensors`) applied before fusion.
    pub sensor_calibration: Option<PathBuf>,
    /// A subject file (`height_m`, segment lengths) the rig is scaled to.
    pub subject: Option<PathBuf>,
    /// A BVH take's bone map (source joint → bone), relative to the config file.
    pub bone_map: Option<PathBuf>,
    /// A BVH take's reference pose: `rest` or `frame:N`.
    #[serde(default, deserialize_with = "bvh_reference")]
    pub bvh_reference: Option<crate::retarget::Reference>,
    /// An MVNX take: Xsens's segment kinematics instead of its sensors (a flag).
    #[serde(default)]
    pub mvnx_segments: bool,
}

fn bvh_reference<'de, D: Deserializer<'de>>(
    d: D,
) -> Result<Option<crate::retarget::Reference>, D::Error> {
    parsed(d, "bvh_reference")
}

fn engine<'de, D: Deserializer<'de>>(d: D) -> Result<Option<crate::write::Engine>, D::Error> {
    parsed(d, "engine")
}

fn fusion<'de, D: Deserializer<'de>>(d: D) -> Result<Option<crate::fusion::Fusion>, D::Error> {
    parsed(d, "fusion")
}

/// A key's value parsed with `FromStr`, its error naming the key.
fn parsed<'de, D: Deserializer<'de>, T: std::str::FromStr<Err = String>>(
    d: D,
    key: &str,
) -> Result<Option<T>, D::Error> {
    let text = Option::<String>::deserialize(d)?;
    text.map(|t| t.parse().map_err(|e| format!("`{key}`: {e}")))
        .transpose()
        .map_err(serde::de::Error::custom)
}

fn trim<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Trim>, D::Error> {
    parsed(d, "trim")
}

fn input_format<'de, D: Deserializer<'de>>(d: D) -> Result<Option<InputFormat>, D::Error> {
    parsed(d, "input_format")
}

fn skip_seconds<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    match Option::<f64>::deserialize(d)? {
        Some(s) if !(s.is_finite() && s >= 0.0) => Err(serde::de::Error::custom(
            "`skip_seconds`: expected seconds ≥ 0",
        )),
        s => Ok(s),
    }
}

fn rate_hz<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    match Option::<f64>::deserialize(d)? {
        Some(r) if !(r.is_finite() && r > 0.0) => Err(serde::de::Error::custom(
            "`rate_hz`: expected a rate above 0 Hz",
        )),
        r => Ok(r),
    }
}

fn sensor_rate<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    match Option::<f64>::deserialize(d)? {
        Some(r) if !(r.is_finite() && r > 0.0) => Err(serde::de::Error::custom(
            "`sensor_rate_hz`: expected a rate above 0 Hz",
        )),
        r => Ok(r),
    }
}

fn formats<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<OutputFormat>>, D::Error> {
    match Option::<Vec<OutputFormat>>::deserialize(d)? {
        Some(f) if f.is_empty() => Err(serde::de::Error::custom(
            "`formats`: name at least one of bvh, glb, gltf",
        )),
        f => Ok(f),
    }
}

/// `smoothing:` in a config file: a method string, or a method with per-bone overrides.
#[derive(Deserialize)]
#[serde(untagged)]
enum SmoothingEntry {
    Method(String),
    WithBones {
        method: String,
        #[serde(default)]
        bones: BTreeMap<String, String>,
    },
}

fn smoothing<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Smoothing>, D::Error> {
    let Some(entry) = Option::<SmoothingEntry>::deserialize(d)? else {
        return Ok(None);
    };
    let parse = || -> Result<Smoothing, String> {
        match entry {
            SmoothingEntry::Method(m) => Ok(Smoothing {
                method: m.parse()?,
                bones: BTreeMap::new(),
            }),
            SmoothingEntry::WithBones { method, bones } => {
                let mut parsed = BTreeMap::new();
                for (bone, m) in bones {
                    let method = m.parse().map_err(|e| format!("bone `{bone}`: {e}"))?;
                    parsed.insert(bone, method);
                }
                Ok(Smoothing {
                    method: method.parse()?,
                    bones: parsed,
                })
            }
        }
    };
    parse()
        .map(Some)
        .map_err(|e| serde::de::Error::custom(format!("`smoothing`: {e}")))
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {message}", .path.display())]
pub struct ConfigError {
    pub path: PathBuf,
    pub message: String,
}

impl Config {
    /// Reads a config file; relative paths in it become relative to its folder.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let err = |message: String| ConfigError {
            path: path.to_path_buf(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
        let mut config = Config::parse(&text).map_err(err)?;
        let base = path.parent().unwrap_or(Path::new(""));
        if let Some(m) = config.mapping.as_ref().filter(|m| m.is_relative()) {
            config.mapping = Some(base.join(m));
        }
        if let Some(c) = config
            .sensor_calibration
            .as_ref()
            .filter(|c| c.is_relative())
        {
            config.sensor_calibration = Some(base.join(c));
        }
        if let Some(b) = config.bone_map.as_ref().filter(|b| b.is_relative()) {
            config.bone_map = Some(base.join(b));
        }
        if let Some(l) = config.layout.as_ref().filter(|l| l.is_relative()) {
            config.layout = Some(base.join(l));
        }
        if let Some(r) = &config.rig {
            let p = Path::new(r);
            let is_file = r.ends_with(".yaml")
                || r.ends_with(".yml")
                || r.ends_with(".json")
                || r.ends_with(".bvh");
            if is_file && p.is_relative() {
                config.rig = Some(base.join(p).to_string_lossy().into_owned());
            }
        }
        Ok(config)
    }

    /// Parses a config's text into its types (paths in it stay as written); an error names the
    /// key.
    pub fn parse(text: &str) -> Result<Config, String> {
        if text.trim().is_empty() {
            return Ok(Config::default());
        }
        serde_yaml::from_str(text).map_err(|e| format!("{e}; see README, \"Configuration\""))
    }

    /// This layer over `below`: each setting this one gives wins; the flags `report` and `force`
    /// are on when either layer turns them on.
    pub fn over(self, below: Config) -> Config {
        Config {
            mapping: self.mapping.or(below.mapping),
            rig: self.rig.or(below.rig),
            fps: self.fps.or(below.fps),
            formats: self.formats.or(below.formats),
            units: self.units.or(below.units),
            trim: self.trim.or(below.trim),
            root: self.root.or(below.root),
            foot_lock: self.foot_lock || below.foot_lock,
            input_format: self.input_format.or(below.input_format),
            skip_lines: self.skip_lines.or(below.skip_lines),
            skip_seconds: self.skip_seconds.or(below.skip_seconds),
            rate_hz: self.rate_hz.or(below.rate_hz),
            world: self.world.or(below.world),
            layout: self.layout.or(below.layout),
            smoothing: self.smoothing.or(below.smoothing),
            report: self.report || below.report,
            force: self.force || below.force,
            causal: self.causal || below.causal,
            bind_frame: self.bind_frame || below.bind_frame,
            in_place: self.in_place || below.in_place,
            engine: self.engine.or(below.engine),
            unsensed: self.unsensed.or(below.unsensed),
            heading: self.heading.or(below.heading),
            sensor_rate_hz: self.sensor_rate_hz.or(below.sensor_rate_hz),
            fusion: self.fusion.or(below.fusion),
            sensor_calibration: self.sensor_calibration.or(below.sensor_calibration),
            subject: self.subject.or(below.subject),
            bone_map: self.bone_map.or(below.bone_map),
            bvh_reference: self.bvh_reference.or(below.bvh_reference),
            mvnx_segments: self.mvnx_segments || below.mvnx_segments,
        }
    }

    /// Settings from this layer over the defaults. `world_from` says which layer gave `world`
    /// (recorded in the sidecar), when one did.
    pub fn to_settings(&self, world_from: WorldFrom) -> ConvertSettings {
        let mut s = ConvertSettings {
            mapping: self.mapping.clone(),
            rig: self.rig.clone(),
            sensor_calibration: self.sensor_calibration.clone(),
            subject: self.subject.clone(),
            bone_map: self.bone_map.clone(),
            bvh_reference: self.bvh_reference.unwrap_or_default(),
            mvnx_segments: self.mvnx_segments,
            ..ConvertSettings::default()
        };
        if let Some(fps) = self.fps {
            s.pipeline.fps = fps;
        }
        if let Some(f) = &self.formats {
            // Each format once (`--format bvh,glb,bvh`), in the order first given.
            s.formats.clear();
            for format in f {
                if !s.formats.contains(format) {
                    s.formats.push(*format);
                }
            }
        }
        if let Some(u) = self.units {
            s.units = u;
        }
        s.pipeline.trim = self.trim;
        if let Some(r) = self.root {
            s.pipeline.root = r;
        }
        s.pipeline.foot_lock = self.foot_lock;
        if let Some(smoothing) = &self.smoothing {
            s.pipeline.smoothing = smoothing.clone();
        }
        s.pipeline.force = self.force;
        s.pipeline.causal = self.causal;
        s.bind_frame = self.bind_frame;
        s.in_place = self.in_place;
        s.engine = self.engine;
        if let Some(u) = self.unsensed {
            s.pipeline.unsensed = u;
        }
        s.pipeline.heading = self.heading;
        s.pipeline.sensor_rate_hz = self.sensor_rate_hz;
        s.pipeline.fusion = self.fusion.clone();
        s.read.format = self.input_format;
        s.read.skip_lines = self.skip_lines.unwrap_or(0);
        s.read.skip_seconds = self.skip_seconds.unwrap_or(0.0);
        s.read.world = self.world;
        s.read.rate_hz = self.rate_hz;
        s.read.layout = self.layout.clone();
        s.world_from = self.world.map(|_| world_from);
        s.report = self.report;
        s
    }
}

/// The settings of `flags` (a layer made from the command line) over the config file at
/// `config`, if any: the one place the two meet.
pub fn settings(flags: Config, config: Option<&Path>) -> Result<ConvertSettings, ConfigError> {
    let file = match config {
        Some(path) => Config::load(path)?,
        None => Config::default(),
    };
    let world_from = if flags.world.is_some() {
        WorldFrom::Flag
    } else {
        WorldFrom::Config
    };
    let layer = |flag: bool, config: bool| Layer::of(flag, config);
    let given = Given {
        fps: layer(flags.fps.is_some(), file.fps.is_some()),
        mapping: layer(flags.mapping.is_some(), file.mapping.is_some()),
        rig: layer(flags.rig.is_some(), file.rig.is_some()),
        subject: layer(flags.subject.is_some(), file.subject.is_some()),
        sensor_calibration: layer(
            flags.sensor_calibration.is_some(),
            file.sensor_calibration.is_some(),
        ),
        bone_map: layer(flags.bone_map.is_some(), file.bone_map.is_some()),
    };
    Ok(ConvertSettings {
        given,
        ..flags.over(file).to_settings(world_from)
    })
}

/// Why a plan could not be made: the config file, or a file the settings name.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Resolve(#[from] crate::convert::ConvertError),
}

/// The plan of [`settings`]: every file the settings name read once
/// ([`crate::convert::Plan::resolve`]).
pub fn plan(flags: Config, config: Option<&Path>) -> Result<crate::convert::Plan, PlanError> {
    Ok(crate::convert::Plan::resolve(settings(flags, config)?)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loads_resolves_relative_paths_and_rejects_typos() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("imubake.yaml");
        std::fs::write(
            &path,
            "mapping: m.json\nfps: 29.97\nformats: [bvh, gltf]\nunits: cm\ntrim: \"1:2\"\nworld: ned\n",
        )
        .unwrap();
        let c = Config::load(&path).unwrap();
        assert_eq!(c.mapping, Some(dir.path().join("m.json")));
        let s = c.to_settings(WorldFrom::Config);
        assert_eq!((s.pipeline.fps.num(), s.pipeline.fps.den()), (30000, 1001));
        assert_eq!(s.formats, vec![OutputFormat::Bvh, OutputFormat::Gltf]);
        assert_eq!(s.units, LengthUnit::Centimetres);
        assert_eq!(
            s.pipeline.trim,
            Some(Trim {
                start_s: 1.0,
                end_s: 2.0
            })
        );
        assert_eq!(s.read.world, Some(World::Ned));
        std::fs::write(&path, "fsp: 30\n").unwrap();
        let e = Config::load(&path).unwrap_err().to_string();
        assert!(e.contains("imubake.yaml") && e.contains("fsp"), "{e}");
        std::fs::write(
            &path,
            "smoothing: {method: \"gaussian:sigma=0.05\", bones: {LeftHand: none}}\n",
        )
        .unwrap();
        let s = Config::load(&path).unwrap().to_settings(WorldFrom::Config);
        assert_eq!(
            s.pipeline.smoothing.for_bone("Hips"),
            &crate::smooth::Method::Gaussian { sigma_s: 0.05 }
        );
        assert_eq!(
            s.pipeline.smoothing.for_bone("mixamorig:LeftHand"),
            &crate::smooth::Method::None
        );
        std::fs::write(&path, "smoothing: median\n").unwrap();
        assert!(
            Config::load(&path)
                .unwrap_err()
                .to_string()
                .contains("`smoothing`")
        );
        std::fs::write(&path, "trim: \"5:1\"\n").unwrap();
        assert!(
            Config::load(&path)
                .unwrap_err()
                .to_string()
                .contains("`trim`")
        );
    }

    #[test]
    fn flags_are_one_layer_over_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.yaml");
        std::fs::write(&path, "fps: 24\nunits: cm\nworld: ned\nsmoothing: none\n").unwrap();
        let flags = Config {
            fps: Some("60".parse().unwrap()),
            world: Some(World::Enu),
            report: true,
            ..Config::default()
        };
        let s = settings(flags, Some(&path)).unwrap();
        assert_eq!(s.pipeline.fps, "60".parse().unwrap(), "the flag wins");
        assert_eq!(s.units, LengthUnit::Centimetres, "the file fills in");
        assert!(s.pipeline.smoothing.is_none());
        assert_eq!(
            (s.read.world, s.world_from),
            (Some(World::Enu), Some(WorldFrom::Flag))
        );
        assert!(s.report);
        let s = settings(Config::default(), Some(&path)).unwrap();
        assert_eq!(s.world_from, Some(WorldFrom::Config));
        let s = settings(Config::default(), None).unwrap();
        assert_eq!(s, ConvertSettings::default());
    }

    #[test]
    fn the_sensor_calibration_is_relative_to_the_config() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("imubake.yaml");
        std::fs::write(&path, "sensor_calibration: cal/sensors.yaml\n").unwrap();
        let s = settings(Config::default(), Some(&path)).unwrap();
        assert_eq!(
            s.sensor_calibration,
            Some(dir.path().join("cal/sensors.yaml"))
        );
        let flag = Config {
            sensor_calibration: Some("other.yaml".into()),
            ..Config::default()
        };
        let s = settings(flag, Some(&path)).unwrap();
        assert_eq!(
            s.sensor_calibration,
            Some(std::path::PathBuf::from("other.yaml"))
        );
        std::fs::write(&path, "layout: layouts/suit.yaml\n").unwrap();
        let s = settings(Config::default(), Some(&path)).unwrap();
        assert_eq!(s.read.layout, Some(dir.path().join("layouts/suit.yaml")));
    }

    #[test]
    fn the_engine_is_a_setting() {
        let c = Config::parse("engine: Godot\n").unwrap();
        assert_eq!(
            c.to_settings(WorldFrom::Config).engine,
            Some(crate::write::Engine::Godot)
        );
        let e = Config::parse("engine: unity\n").unwrap_err();
        assert!(
            e.contains("`engine`") && e.contains("unknown engine `unity`"),
            "{e}"
        );
        assert_eq!(
            Config::default().to_settings(WorldFrom::Config).engine,
            None
        );
    }

    #[test]
    fn fusion_is_a_setting_with_its_parameters() {
        let c = Config::parse("fusion: madgwick:beta=0.05,6d\n").unwrap();
        let s = c.to_settings(WorldFrom::Config);
        let f = s.pipeline.fusion.unwrap();
        assert_eq!(f.to_string(), "madgwick:beta=0.05,6d");
        let e = Config::parse("fusion: kalman\n").unwrap_err();
        assert!(
            e.contains("`fusion`") && e.contains("unknown fusion `kalman`"),
            "{e}"
        );
        // The flag's layer wins over the file's.
        let flags = Config {
            fusion: Some("vqf".parse().unwrap()),
            ..Config::default()
        };
        assert_eq!(
            flags.over(c).fusion.unwrap().to_string(),
            "vqf:tau_acc=3,tau_mag=9"
        );
    }
}
