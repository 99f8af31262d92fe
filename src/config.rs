//! The YAML settings file shared by `convert --config` and `watch` (README, "Configuration").
//! Flags override it; paths in it are relative to the file's folder.
//!
//! ```yaml
//! mapping: mappings/paper002_sou12_mixamo.json
//! rig: mixamo            # a built-in rig or a rig file
//! fps: 29.97             # or 30000/1001
//! formats: [bvh, glb]    # bvh, glb, gltf
//! units: m               # BVH length unit: m or cm
//! trim: "2.5:60"         # seconds, either side optional
//! root: fixed
//! input_format: sou      # skip detection
//! skip_lines: 0
//! skip_seconds: 0
//! world: ned             # override the format's world
//! smoothing: butterworth:order=4,cutoff=14   # or none, gaussian:sigma=0.02, fft, fft:cutoff=8
//! # or with per-bone overrides:
//! # smoothing: {method: "butterworth:cutoff=4", bones: {LeftHand: none, Head: "gaussian:sigma=0.05"}}
//! ```

use crate::convert::{ConvertSettings, OutputFormat};
use crate::fps::Fps;
use crate::pipeline::Trim;
use crate::pipeline::root::RootMode;
use crate::read::InputFormat;
use crate::rig::LengthUnit;
use crate::smooth::Smoothing;
use crate::world::World;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Config {
    pub mapping: Option<PathBuf>,
    pub rig: Option<String>,
    pub fps: Option<Fps>,
    pub formats: Option<Vec<OutputFormat>>,
    pub units: Option<LengthUnit>,
    pub trim: Option<String>,
    pub root: Option<RootMode>,
    pub input_format: Option<String>,
    pub skip_lines: Option<u64>,
    pub skip_seconds: Option<f64>,
    pub world: Option<World>,
    pub smoothing: Option<SmoothingEntry>,
}

/// `smoothing:` in the config: a method string, or a method with per-bone overrides.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum SmoothingEntry {
    Method(String),
    WithBones {
        method: String,
        #[serde(default)]
        bones: BTreeMap<String, String>,
    },
}

impl SmoothingEntry {
    pub fn to_smoothing(&self) -> Result<Smoothing, String> {
        match self {
            SmoothingEntry::Method(m) => Ok(Smoothing {
                method: m.parse()?,
                bones: BTreeMap::new(),
            }),
            SmoothingEntry::WithBones { method, bones } => {
                let mut parsed = BTreeMap::new();
                for (bone, m) in bones {
                    parsed.insert(
                        bone.clone(),
                        m.parse().map_err(|e| format!("bone `{bone}`: {e}"))?,
                    );
                }
                Ok(Smoothing {
                    method: method.parse()?,
                    bones: parsed,
                })
            }
        }
    }
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
        config.validate().map_err(err)?;
        Ok(config)
    }

    /// Parses and checks a config's text (paths in it stay as written).
    pub fn parse(text: &str) -> Result<Config, String> {
        let config: Config = if text.trim().is_empty() {
            Config::default()
        } else {
            serde_yaml::from_str(text).map_err(|e| format!("{e}; see README, \"Configuration\""))?
        };
        config.validate()?;
        Ok(config)
    }

    fn validate(&self) -> Result<(), String> {
        if let Some(t) = &self.trim {
            t.parse::<Trim>().map_err(|e| format!("`trim`: {e}"))?;
        }
        if let Some(f) = &self.input_format {
            f.parse::<InputFormat>()
                .map_err(|e| format!("`input_format`: {e}"))?;
        }
        if self
            .skip_seconds
            .is_some_and(|s| !(s.is_finite() && s >= 0.0))
        {
            return Err("`skip_seconds`: expected seconds ≥ 0".into());
        }
        if let Some(s) = &self.smoothing {
            s.to_smoothing().map_err(|e| format!("`smoothing`: {e}"))?;
        }
        if self.formats.as_ref().is_some_and(Vec::is_empty) {
            return Err("`formats`: name at least one of bvh, glb, gltf".into());
        }
        Ok(())
    }

    /// Settings from this file over the defaults.
    pub fn to_settings(&self) -> ConvertSettings {
        let mut s = ConvertSettings {
            mapping: self.mapping.clone(),
            rig: self.rig.clone(),
            ..ConvertSettings::default()
        };
        if let Some(fps) = self.fps {
            s.pipeline.fps = fps;
        }
        if let Some(f) = &self.formats {
            s.formats = f.clone();
        }
        if let Some(u) = self.units {
            s.units = u;
        }
        s.pipeline.trim = self.trim.as_ref().and_then(|t| t.parse().ok());
        if let Some(r) = self.root {
            s.pipeline.root = r;
        }
        s.read.format = self.input_format.as_ref().and_then(|f| f.parse().ok());
        s.read.skip_lines = self.skip_lines.unwrap_or(0);
        s.read.skip_seconds = self.skip_seconds.unwrap_or(0.0);
        s.read.world = self.world;
        s.world_from = self.world.map(|_| crate::world::WorldFrom::Config);
        if let Some(smoothing) = self.smoothing.as_ref().and_then(|e| e.to_smoothing().ok()) {
            s.pipeline.smoothing = smoothing;
        }
        s
    }
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
        let s = c.to_settings();
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
        let s = Config::load(&path).unwrap().to_settings();
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
}
