//! A command's settings resolved once into a [`Plan`]: every file they name (mapping, rig,
//! subject, sensor calibration, bone map) read here and only here, hashed as it is read, and
//! parsed; the rig scaled to the subject; the pipeline's options complete. The layers below take
//! what they need from the plan and never open those files again, so a batch of a thousand takes
//! reads its mapping once, and what the ledger fingerprints is exactly what was converted with.
//!
//! `batch` and `watch` resolve a plan per config file; `watch` resolves it again when the config
//! or a file the plan read changes ([`Plan::files`]).

use super::error::ConvertError;
use super::hash::hex;
use super::settings::{ConvertSettings, Layer, OutputFormat};
use crate::intrinsics::{IntrinsicsError, SensorCalibration};
use crate::mapping::{LegacyMapping, Mapping, MappingError, MappingFile, parse_mapping};
use crate::pipeline::PipelineOptions;
pub use crate::pipeline::record::Mode;
use crate::read::ReadOptions;
use crate::retarget::BoneMap;
use crate::rig::file::RigLoadError;
use crate::rig::subject::Subject;
use crate::rig::{Rig, builtin_rig, rig_from_bytes};
use crate::write::transforms::OutputTransform;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A file the plan read: its value, its path and the SHA-256 of the bytes parsed.
#[derive(Debug, Clone)]
pub struct Loaded<T> {
    pub value: T,
    pub path: PathBuf,
    pub sha256: String,
}

/// The mapping of a plan.
#[derive(Debug, Clone)]
pub enum PlanMapping {
    /// None given: sensors drive the rig's bones named like them.
    ByName,
    Quaternion(Loaded<Mapping>),
    /// Paper 002's Listing 2.
    Euler(Loaded<LegacyMapping>),
}

/// Where the rig came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RigFrom {
    /// `--rig` or the config file's `rig`.
    Settings(Layer),
    /// The mapping's `rig`.
    Mapping,
    /// Neither: `mixamo`.
    Default,
}

/// A command's settings with every file they name read, hashed and parsed, once.
#[derive(Debug, Clone)]
pub struct Plan {
    settings: ConvertSettings,
    mapping: PlanMapping,
    /// `--rig`, else the mapping's, else `mixamo`; scaled to the subject.
    rig: Rig,
    rig_from: RigFrom,
    /// A rig file (`None` for a built-in rig): its path and SHA-256.
    rig_file: Option<(PathBuf, String)>,
    /// Paper 002's Table 1 (the `sou12` rig), for the Euler mode's parents.
    table1: Option<Rig>,
    subject: Option<Loaded<Subject>>,
    sensor_calibration: Option<Loaded<Arc<SensorCalibration>>>,
    bone_map: Option<Loaded<BoneMap>>,
    /// The settings' pipeline options with the sensor calibration in place and the unsmoothed
    /// rotations kept when the report is asked for.
    pipeline: PipelineOptions,
    /// The packet layout file (`--layout`), checked: its path and SHA-256.
    layout: Option<(PathBuf, String)>,
}

/// A file's bytes and their SHA-256.
fn read_hashed(path: &Path) -> std::io::Result<(Vec<u8>, String)> {
    let bytes = std::fs::read(path)?;
    let sha256 = hex(&Sha256::digest(&bytes));
    Ok((bytes, sha256))
}

/// A file's text and its SHA-256; `what` fails with the reason.
fn read_text<E>(path: &Path, fail: impl Fn(String) -> E) -> Result<(String, String), E> {
    let (bytes, sha256) = read_hashed(path).map_err(|e| fail(format!("cannot read: {e}")))?;
    let text = String::from_utf8(bytes)
        .map_err(|_| fail("cannot read: stream did not contain valid UTF-8".to_string()))?;
    Ok((text, sha256))
}

impl Plan {
    /// Reads every file `settings` names and resolves the rig. Errors name the file at fault.
    pub fn resolve(settings: ConvertSettings) -> Result<Plan, ConvertError> {
        if let Some(engine) = settings.engine
            && !settings
                .formats
                .iter()
                .any(|f| matches!(f, OutputFormat::Glb | OutputFormat::Gltf))
        {
            return Err(ConvertError::EngineWithoutGltf(engine));
        }
        let layout = match &settings.read.layout {
            None => None,
            Some(path) => {
                let error = |message: String| crate::read::layout::LayoutError {
                    path: path.clone(),
                    message,
                };
                let (text, sha256) = read_text(path, error)?;
                crate::read::layout::Layout::parse(&text).map_err(error)?;
                Some((path.clone(), sha256))
            }
        };
        let mapping = match &settings.mapping {
            None => PlanMapping::ByName,
            Some(path) => {
                let (text, sha256) = read_text(path, |m| MappingError::new(path, "", m))
                    .map_err(ConvertError::from)?;
                match parse_mapping(&text, path)? {
                    MappingFile::Quaternion(value) => PlanMapping::Quaternion(Loaded {
                        value,
                        path: path.clone(),
                        sha256,
                    }),
                    MappingFile::Legacy(value) => PlanMapping::Euler(Loaded {
                        value,
                        path: path.clone(),
                        sha256,
                    }),
                }
            }
        };
        let subject = match &settings.subject {
            None => None,
            Some(path) => {
                let (text, sha256) =
                    read_text(path, |message| crate::rig::subject::SubjectError {
                        path: path.clone(),
                        message,
                    })?;
                Some(Loaded {
                    value: Subject::parse(&text, path)?,
                    path: path.clone(),
                    sha256,
                })
            }
        };
        let sensor_calibration = match &settings.sensor_calibration {
            None => None,
            Some(path) => {
                let fail = |message: String| IntrinsicsError::File {
                    path: path.clone(),
                    message,
                };
                let (text, sha256) = read_text(path, fail)?;
                Some(Loaded {
                    value: Arc::new(SensorCalibration::parse(&text).map_err(fail)?),
                    path: path.clone(),
                    sha256,
                })
            }
        };
        let bone_map = match &settings.bone_map {
            None => None,
            Some(path) => {
                let (text, sha256) = read_text(path, |reason| {
                    ConvertError::BoneMapFile(crate::retarget::RetargetError::BoneMap {
                        path: path.clone(),
                        reason,
                    })
                })?;
                Some(Loaded {
                    value: BoneMap::parse(&text, path).map_err(ConvertError::BoneMapFile)?,
                    path: path.clone(),
                    sha256,
                })
            }
        };
        let mapping_rig = match &mapping {
            PlanMapping::Quaternion(m) => m.value.rig.as_deref(),
            PlanMapping::ByName | PlanMapping::Euler(_) => None,
        };
        let (name, rig_from) = match (&settings.rig, mapping_rig) {
            (Some(name), _) => (name.as_str(), RigFrom::Settings(settings.given.rig)),
            (None, Some(name)) => (name, RigFrom::Mapping),
            (None, None) => ("mixamo", RigFrom::Default),
        };
        let (rig, rig_file) = load_rig_hashed(name)?;
        let rig = match &subject {
            Some(s) => {
                // Its height is the calibration pose's: the rig's zero pose need not stand.
                let pose = calibration_pose_on(&mapping, &rig);
                s.value.apply(&rig, pose.as_deref(), &s.path)?
            }
            None => rig,
        };
        let table1 = match mapping {
            PlanMapping::Euler(_) => Some(builtin_rig("sou12").expect("a built-in rig")?),
            _ => None,
        };
        let mut pipeline = settings.pipeline.clone();
        pipeline.keep_unsmoothed |= settings.report;
        pipeline.sensor_calibration = sensor_calibration.as_ref().map(|c| Arc::clone(&c.value));
        Ok(Plan {
            settings,
            mapping,
            rig,
            rig_from,
            rig_file,
            table1,
            subject,
            sensor_calibration,
            bone_map,
            pipeline,
            layout,
        })
    }

    /// The mode a take converts in: a BVH file is retargeted, `--mvnx-segments` reads Xsens's
    /// segments, a Listing-2 mapping runs paper 002's Euler mode, anything else the sensors'
    /// orientations.
    pub fn mode_for(&self, input: &Path) -> Mode {
        if is_bvh_take(input, &self.settings.read) {
            Mode::BvhRetarget
        } else if self.settings.mvnx_segments {
            Mode::MvnxSegments
        } else if matches!(self.mapping, PlanMapping::Euler(_)) {
            Mode::Euler
        } else {
            Mode::Orientations
        }
    }

    pub fn settings(&self) -> &ConvertSettings {
        &self.settings
    }

    /// The packet layout file read through (`--layout`): its path and SHA-256.
    pub fn layout(&self) -> Option<(&Path, &str)> {
        self.layout.as_ref().map(|(p, s)| (p.as_path(), s.as_str()))
    }

    /// The local rotations of the pose the subject calibrates in (the mapping's
    /// `calibration.pose` on the plan's rig), `None` for the rest pose or without one: the
    /// standing reference joint angles are measured from.
    pub fn calibration_pose(&self) -> Option<Vec<nalgebra::UnitQuaternion<f64>>> {
        calibration_pose_on(&self.mapping, self.rig())
    }

    /// The output transforms asked for, in the order they apply.
    pub fn transforms(&self) -> Vec<OutputTransform> {
        let mut list = Vec::new();
        if self.settings.in_place {
            list.push(OutputTransform::InPlace);
        }
        if self.settings.bind_frame {
            list.push(OutputTransform::BindFrame);
        }
        list
    }

    pub fn read_options(&self) -> &ReadOptions {
        &self.settings.read
    }

    pub fn mapping(&self) -> &PlanMapping {
        &self.mapping
    }

    /// The rig every take goes onto, scaled to the subject.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    pub fn rig_from(&self) -> RigFrom {
        self.rig_from
    }

    /// `--rig` or the config file named the rig (an MVNX take's segments are retargeted only
    /// then, or with a bone map).
    pub fn rig_given(&self) -> bool {
        matches!(self.rig_from, RigFrom::Settings(_))
    }

    /// The SHA-256 of the rig file, `None` for a built-in rig.
    pub fn rig_sha256(&self) -> Option<&str> {
        self.rig_file.as_ref().map(|(_, sha)| sha.as_str())
    }

    /// Paper 002's Table 1 rig, in the Euler mode.
    pub fn table1(&self) -> Option<&Rig> {
        self.table1.as_ref()
    }

    pub fn subject(&self) -> Option<&Loaded<Subject>> {
        self.subject.as_ref()
    }

    pub fn sensor_calibration(&self) -> Option<&Loaded<Arc<SensorCalibration>>> {
        self.sensor_calibration.as_ref()
    }

    pub fn bone_map(&self) -> Option<&Loaded<BoneMap>> {
        self.bone_map.as_ref()
    }

    /// The pipeline's options, complete (sensor calibration loaded, unsmoothed rotations kept
    /// for the report).
    pub fn pipeline(&self) -> &PipelineOptions {
        &self.pipeline
    }

    /// Every file the plan read; `watch` resolves the plan again when one changes.
    pub fn files(&self) -> Vec<&Path> {
        let mapping = match &self.mapping {
            PlanMapping::ByName => None,
            PlanMapping::Quaternion(m) => Some(m.path.as_path()),
            PlanMapping::Euler(m) => Some(m.path.as_path()),
        };
        // The rig file, whether `--rig` or the mapping named it.
        let rig = self.rig_file.as_ref().map(|(path, _)| path.as_path());
        mapping
            .into_iter()
            .chain(rig)
            .chain(self.subject.as_ref().map(|s| s.path.as_path()))
            .chain(self.sensor_calibration.as_ref().map(|c| c.path.as_path()))
            .chain(self.bone_map.as_ref().map(|b| b.path.as_path()))
            .collect()
    }

    /// What a stream runs on: the rig, the quaternion mapping and its path, and the pipeline's
    /// options.
    pub fn stream(&self) -> Result<(&Rig, &Mapping, &Path, &PipelineOptions), ConvertError> {
        match &self.mapping {
            PlanMapping::Quaternion(m) => Ok((&self.rig, &m.value, &m.path, &self.pipeline)),
            PlanMapping::Euler(m) => Err(ConvertError::LegacyStream(m.path.clone())),
            PlanMapping::ByName => Err(ConvertError::NoStreamMapping),
        }
    }
}

/// A rig by built-in name or from a file (read once; its path and SHA-256), as
/// [`crate::rig::load_rig`] does.
fn load_rig_hashed(name_or_path: &str) -> Result<(Rig, Option<(PathBuf, String)>), RigLoadError> {
    if let Some(rig) = builtin_rig(name_or_path) {
        return Ok((rig?, None));
    }
    let path = Path::new(name_or_path);
    if !path.exists() {
        return Err(RigLoadError::Unknown(name_or_path.to_string()));
    }
    let (bytes, sha256) = read_hashed(path).map_err(|source| RigLoadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok((
        rig_from_bytes(path, bytes)?,
        Some((path.to_path_buf(), sha256)),
    ))
}

/// Is `input` a BVH take (`--input-format bvh`, else a file whose content is BVH)?
fn is_bvh_take(input: &Path, read: &ReadOptions) -> bool {
    match read.format {
        Some(format) => format == crate::take::InputFormat::Bvh,
        None => {
            input.is_file()
                && crate::read::detect_format(input)
                    .is_ok_and(|f| f == crate::take::InputFormat::Bvh)
        }
    }
}

/// The local rotations of `mapping`'s calibration pose on `rig` ([`Plan::calibration_pose`]).
fn calibration_pose_on(
    mapping: &PlanMapping,
    rig: &Rig,
) -> Option<Vec<nalgebra::UnitQuaternion<f64>>> {
    let PlanMapping::Quaternion(m) = mapping else {
        return None;
    };
    let pose = &m.value.calibration.as_ref()?.pose;
    rig.pose(&pose.label()).map(|p| p.local)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn repo(p: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
    }

    #[test]
    fn each_input_gets_its_mode() {
        let dir = tempfile::tempdir().unwrap();
        let bvh = dir.path().join("a.bvh");
        std::fs::write(
            &bvh,
            "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n \
             End Site\n {\n  OFFSET 0 1 0\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.5\n0 0 0\n",
        )
        .unwrap();
        let log = repo("samples/sou_wave.log");
        let quaternion = Plan::resolve(ConvertSettings {
            mapping: Some(repo("samples/sou_wave.mapping.json")),
            ..ConvertSettings::default()
        })
        .unwrap();
        assert_eq!(quaternion.mode_for(&log), Mode::Orientations);
        assert_eq!(quaternion.mode_for(&bvh), Mode::BvhRetarget);
        assert_eq!(quaternion.rig_from(), RigFrom::Mapping);
        let euler = Plan::resolve(ConvertSettings {
            mapping: Some(repo("samples/sou_wave.legacy.json")),
            ..ConvertSettings::default()
        })
        .unwrap();
        assert_eq!(euler.mode_for(&log), Mode::Euler);
        assert_eq!(euler.table1().map(|r| r.name()), Some("sou12"));
        assert!(matches!(euler.stream(), Err(ConvertError::LegacyStream(_))));
        let segments = Plan::resolve(ConvertSettings {
            mvnx_segments: true,
            ..ConvertSettings::default()
        })
        .unwrap();
        assert_eq!(segments.mode_for(&log), Mode::MvnxSegments);
        assert_eq!(segments.rig_from(), RigFrom::Default);
        assert_eq!(segments.rig().name(), "mixamo");
        assert!(matches!(
            segments.stream(),
            Err(ConvertError::NoStreamMapping)
        ));
        let labels: Vec<&str> = Mode::ALL.iter().map(|m| m.label()).collect();
        assert_eq!(
            labels,
            [
                "bvh-retarget",
                "mvnx-segments",
                "legacy-euler",
                "quaternion"
            ]
        );
    }

    #[test]
    fn every_file_is_read_once_hashed_and_named_in_errors() {
        let dir = tempfile::tempdir().unwrap();
        let mapping = dir.path().join("m.json");
        let text = std::fs::read(repo("samples/sou_wave.mapping.json")).unwrap();
        std::fs::write(&mapping, &text).unwrap();
        let subject = dir.path().join("s.yaml");
        std::fs::write(&subject, "height_m: 1.62\n").unwrap();
        let plan = Plan::resolve(ConvertSettings {
            mapping: Some(mapping.clone()),
            subject: Some(subject.clone()),
            rig: Some("mixamo".into()),
            ..ConvertSettings::default()
        })
        .unwrap();
        // The SHA-256 of the bytes read, by sha2 over the file as written here.
        let PlanMapping::Quaternion(m) = plan.mapping() else {
            panic!("a quaternion mapping")
        };
        assert_eq!(m.sha256, hex(&Sha256::digest(&text)));
        assert_eq!(plan.files(), [mapping.as_path(), subject.as_path()]);
        // Scaled to 1.62 m standing (the subject's height), from mixamo's own.
        let h = plan.rig().standing_height() * plan.rig().units().metres_per_unit();
        assert!((h - 1.62).abs() < 1e-6, "{h}");
        assert_eq!(plan.rig_from(), RigFrom::Settings(Layer::Default));
        // A rig file the mapping names is read, hashed and watched like the others.
        let rig_file = dir.path().join("r.yaml");
        let rig_text = std::fs::read(repo("rigs/mixamo.yaml")).unwrap();
        std::fs::write(&rig_file, &rig_text).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(text.contains(r#""rig": "mixamo""#));
        let named = text.replace(
            r#""rig": "mixamo""#,
            &format!("\"rig\": {:?}", rig_file.display().to_string()),
        );
        let mapping_naming_rig = dir.path().join("n.json");
        std::fs::write(&mapping_naming_rig, named).unwrap();
        let by_mapping = Plan::resolve(ConvertSettings {
            mapping: Some(mapping_naming_rig.clone()),
            ..ConvertSettings::default()
        })
        .unwrap();
        assert_eq!(by_mapping.rig_from(), RigFrom::Mapping);
        assert_eq!(
            by_mapping.rig_sha256(),
            Some(hex(&Sha256::digest(&rig_text)).as_str())
        );
        assert_eq!(
            by_mapping.files(),
            [mapping_naming_rig.as_path(), rig_file.as_path()]
        );
        // A file that is not what it should be fails the plan, naming the file.
        std::fs::write(&subject, "height: 1.62\n").unwrap();
        let e = Plan::resolve(plan.settings().clone())
            .unwrap_err()
            .to_string();
        assert!(e.contains("s.yaml"), "{e}");
        std::fs::remove_file(&mapping).unwrap();
        let e = Plan::resolve(plan.settings().clone())
            .unwrap_err()
            .to_string();
        assert!(e.contains("m.json") && e.contains("cannot read"), "{e}");
    }
}
