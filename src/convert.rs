//! One take from capture to outputs: read (and hash) → mapping and rig → the pipeline (the
//! quaternion stages, or paper 002's Euler mode for Listing-2 mappings) → one [`Conversion`]
//! whatever the mode → each [`Output`] the settings ask for → the sidecar, written last, so its
//! appearance means the take is complete.

use crate::anim::Animation;
use crate::inspect::SensorSummaries;
use crate::mapping::{
    CalibrationRecord, LegacyMapping, LegacyTargetRecord, Mapping, MappingError, MappingFile,
    MappingRecord, Mount, SensorRecord, load_mapping,
};
use crate::pipeline::calibrate::HeadingSource;
use crate::pipeline::sources::Origin;
use crate::pipeline::{self, PipelineError, PipelineOptions};
use crate::read::{ReadError, ReadOptions, check_text, is_stream, read_take, sniff};
use crate::rig::file::RigLoadError;
use crate::rig::subject::Subject;
use crate::rig::{LengthUnit, Rig, load_rig};
use crate::take::{LineReport, Take};
use crate::world::{World, WorldFrom};
use crate::write::report::{ReportInput, bone_series};
use crate::write::sidecar::{
    FusionRecord, PipelineRecord, RigRecord, Sidecar, SourceRecord, TrimRecord,
};
pub use crate::write::{Output, OutputFormat};
use crate::write::{OutputError, TakeOutputs, remove_take_outputs, write_atomic};
use nalgebra::UnitQuaternion;
use rayon::prelude::*;
use sha2::{Digest, Sha256};
use std::io::{self, Read};
use std::path::{Path, PathBuf};

/// Everything a conversion needs besides the input and the output folder.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvertSettings {
    pub read: ReadOptions,
    /// A mapping file; without one, sensors drive the rig's bones of the same name.
    pub mapping: Option<PathBuf>,
    /// A built-in rig name or a rig file; default: the mapping's `rig`, else `mixamo`.
    pub rig: Option<String>,
    /// A sensor calibration file (`imubake calibrate-sensors`): corrections of raw readings
    /// before fusion.
    pub sensor_calibration: Option<PathBuf>,
    /// A subject file (`height_m`, segment lengths): the rig scaled to the subject.
    pub subject: Option<PathBuf>,
    pub pipeline: PipelineOptions,
    pub formats: Vec<OutputFormat>,
    /// Length unit of the BVH output (glTF is always metres).
    pub units: LengthUnit,
    /// Also write `<stem>.report.html`.
    pub report: bool,
    /// The rest pose as frame 0, the take from frame 1 (`--bind-frame`).
    pub bind_frame: bool,
    /// A `root` joint at floor level carries the hips' horizontal motion (`--in-place`).
    pub in_place: bool,
    /// Where `read.world` came from (`--world` or the config file), when it is set.
    pub world_from: Option<WorldFrom>,
    /// A BVH take: which of its joints drive which bones (the Blender add-on's bone-map JSON);
    /// default: by anatomical part.
    pub bone_map: Option<PathBuf>,
    /// A BVH take: the pose its joints' changes are measured from.
    pub bvh_reference: crate::retarget::Reference,
    /// An MVNX take: Xsens's own segment orientations and positions instead of its sensors.
    pub mvnx_segments: bool,
}

impl ConvertSettings {
    /// The outputs these settings ask for, in order: each format once, then the report.
    pub fn outputs(&self) -> Vec<Output> {
        let mut outputs: Vec<Output> = Vec::new();
        for f in &self.formats {
            if !outputs.contains(&Output::Animation(*f)) {
                outputs.push(Output::Animation(*f));
            }
        }
        if self.report {
            outputs.push(Output::Report);
        }
        outputs
    }
}

impl Default for ConvertSettings {
    fn default() -> Self {
        ConvertSettings {
            read: ReadOptions::default(),
            mapping: None,
            rig: None,
            sensor_calibration: None,
            subject: None,
            pipeline: PipelineOptions::default(),
            formats: vec![OutputFormat::Bvh, OutputFormat::Glb],
            units: LengthUnit::Metres,
            report: false,
            bind_frame: false,
            in_place: false,
            world_from: None,
            bone_map: None,
            bvh_reference: crate::retarget::Reference::Rest,
            mvnx_segments: false,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error(transparent)]
    Mapping(#[from] MappingError),
    #[error(transparent)]
    Rig(#[from] RigLoadError),
    #[error(transparent)]
    SensorCalibration(#[from] crate::intrinsics::IntrinsicsError),
    #[error(transparent)]
    Subject(#[from] crate::rig::subject::SubjectError),
    #[error("{}: {source}", .input.display())]
    Pipeline {
        input: PathBuf,
        #[source]
        source: PipelineError,
    },
    #[error(
        "{}: no mapping given and rig `{rig}` has no bone named like the take's sensors ({sensors}). \
         Hint: pass --mapping (see mappings/), or --rig sou12 for paper-002 SOU logs",
        .input.display()
    )]
    NoMapping {
        input: PathBuf,
        rig: String,
        sensors: String,
    },
    /// Writing an output (or the sidecar) failed: the take's outputs are removed.
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error(
        "{}: paper 002's Euler-channel mappings convert whole takes only; a stream needs a quaternion mapping (mappings/paper002_sou12.json for SOU nodes)",
        .0.display()
    )]
    LegacyStream(PathBuf),
    #[error("a stream needs --mapping (its sensors are not known in advance)")]
    NoStreamMapping,
    /// A take on a skeleton (a BVH, Xsens's segments) that cannot be read or retargeted.
    #[error("{}: {reason}", .input.display())]
    Motion { input: PathBuf, reason: String },
}

impl crate::diagnostic::Diagnostic for ConvertError {
    fn file(&self) -> Option<&Path> {
        match self {
            ConvertError::Read(e) => e.file(),
            // A mapping error's file is the mapping; the report names the take's own file.
            ConvertError::Mapping(_) => None,
            ConvertError::Rig(e) => e.file(),
            ConvertError::SensorCalibration(crate::intrinsics::IntrinsicsError::File {
                path,
                ..
            }) => Some(path),
            ConvertError::SensorCalibration(_) => None,
            ConvertError::Subject(e) => Some(&e.path),
            ConvertError::Pipeline { input, .. } | ConvertError::NoMapping { input, .. } => {
                Some(input)
            }
            ConvertError::Output(OutputError::Write { path, .. })
            | ConvertError::Output(OutputError::Gltf { path, .. }) => Some(path),
            ConvertError::LegacyStream(path) => Some(path),
            ConvertError::NoStreamMapping => None,
            ConvertError::Motion { input, .. } => Some(input),
        }
    }

    fn line(&self) -> Option<u64> {
        match self {
            ConvertError::Read(e) => e.line(),
            _ => None,
        }
    }

    fn hint(&self) -> Option<&'static str> {
        match self {
            ConvertError::Read(e) => e.hint(),
            ConvertError::Mapping(e) => e.hint(),
            ConvertError::Rig(e) => e.hint(),
            ConvertError::Pipeline { .. } | ConvertError::NoMapping { .. } => None,
            ConvertError::SensorCalibration(_) => {
                Some("write the file again with `imubake calibrate-sensors`")
            }
            ConvertError::Subject(_) => {
                Some("a subject file holds `height_m` and/or `segments: {bone: metres}`")
            }
            ConvertError::Output(_) => Some("check the output folder: free space and permissions"),
            ConvertError::LegacyStream(_) | ConvertError::NoStreamMapping => None,
            ConvertError::Motion { .. } => Some(
                "a skeleton's joints are matched to the rig's bones by name; --bone-map names them",
            ),
        }
    }
}

pub use crate::read::take_stem;

/// SHA-256 of a file, or of a folder's files (sorted relative paths and contents).
pub fn source_sha256(path: &Path) -> io::Result<String> {
    let mut hasher = Sha256::new();
    if path.is_dir() {
        let mut files = Vec::new();
        collect_files(path, path, &mut files)?;
        files.sort();
        for rel in files {
            hasher.update(rel.to_string_lossy().as_bytes());
            hasher.update([0u8]);
            hash_file(&path.join(&rel), &mut hasher)?;
        }
    } else {
        hash_file(path, &mut hasher)?;
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

fn hash_file(path: &Path, hasher: &mut Sha256) -> io::Result<()> {
    let mut file = std::fs::File::open(path)?;
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = file.read(&mut buf)?;
        if n == 0 {
            return Ok(());
        }
        hasher.update(&buf[..n]);
    }
}

fn collect_files(root: &Path, dir: &Path, out: &mut Vec<PathBuf>) -> io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let path = entry.path();
        if entry.file_name().to_string_lossy().starts_with('.') {
            continue;
        }
        if path.is_dir() {
            collect_files(root, &path, out)?;
        } else {
            out.push(path.strip_prefix(root).unwrap_or(&path).to_path_buf());
        }
    }
    Ok(())
}

/// What the sidecar and the report keep of a take once its samples are dropped.
struct TakeFacts {
    sensor_summaries: SensorSummaries,
    /// The take's warnings, then the pipeline's.
    warnings: Vec<String>,
    dropped_lines: Vec<LineReport>,
    repaired_lines: Vec<LineReport>,
}

impl TakeFacts {
    /// The take's own facts; the pipeline's warnings are added after them.
    fn of(take: &Take) -> TakeFacts {
        let warnings = take.warnings().to_vec();
        TakeFacts {
            sensor_summaries: SensorSummaries::of(take),
            warnings,
            dropped_lines: take.dropped_lines().to_vec(),
            repaired_lines: take.repaired_lines().to_vec(),
        }
    }
}

/// What a conversion wrote.
#[derive(Debug, Clone)]
pub struct ConvertOutcome {
    pub sidecar: Sidecar,
    pub sidecar_path: PathBuf,
}

fn mapping_record(
    converted: &pipeline::Converted,
    rig: &Rig,
    mapping: &Mapping,
    file: Option<&Path>,
) -> MappingRecord {
    MappingRecord {
        file: file.map(|f| f.to_string_lossy().into_owned()),
        rig: rig.name().to_string(),
        world: converted.world,
        calibration: converted.window.as_ref().map(|w| CalibrationRecord {
            pose: w.pose.label(),
            start_s: w.start_s,
            duration_s: w.duration_s,
            second: w.second.as_ref().map(|p| {
                serde_json::json!({"pose": p.pose.label(), "start_s": p.start_s, "duration_s": p.duration_s})
            }),
        }),
        sensors: converted
            .sensors
            .iter()
            .zip(&converted.calibration.mounts)
            .zip(converted.origins.iter().zip(&converted.calibration.alignment))
            .map(|((s, q), (origin, alignment))| SensorRecord {
                sensor: s.sensor.clone(),
                bone: rig.joints()[s.bone].name.clone(),
                mount_source: match s.mount {
                    Mount::Calibrate => "calibrate",
                    Mount::Fixed(_) => "fixed",
                },
                mount: [q.w, q.i, q.j, q.k],
                forward: mapping
                    .sensors
                    .iter()
                    .find(|m| m.sensor == s.sensor)
                    .and_then(|m| m.forward)
                    .map(|v| [v.x, v.y, v.z]),
                orientation: match origin {
                    Origin::Device { .. } => "device",
                    Origin::Fused(_) => "fused",
                },
                world: origin.world(),
                heading_aligned_by: alignment.label(),
            })
            .collect(),
        legacy: None,
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Reads the take and the SHA-256 of its source. An imubake CSV is hashed as it is read; another
/// file or a folder is hashed on a second core while it is parsed, once a file has passed the
/// text check (so a huge binary file is refused without being read); a stream (FIFO, process
/// substitution) is read once into memory, then hashed and parsed.
fn read_and_hash(input: &Path, options: &ReadOptions) -> Result<(Take, String), ReadError> {
    if is_stream(input) {
        // Read as it arrives, hashed on the way: the format is judged from the first 8 KiB and
        // each line is held to the readers' limit, so a pipe of garbage is refused early.
        let mut hasher = Sha256::new();
        let take =
            crate::read::read_stream_observed(input, options, &mut |bytes| hasher.update(bytes))?;
        return Ok((take, hex(&hasher.finalize())));
    }
    if input.is_file() {
        let head = sniff(input)?;
        if !crate::read::is_binary_format(&head, options.format) {
            check_text(input, &head)?;
        }
        let format = match options.format {
            Some(f) => f,
            None => crate::read::detect_format(input)?,
        };
        if format == crate::read::InputFormat::ImubakeCsv {
            // Hashed by the reader's own reading thread, block by block, in one pass.
            let mut hasher = Sha256::new();
            let take = crate::read::imubake_csv::read_observed(input, options, &mut |bytes| {
                hasher.update(bytes)
            })?;
            return Ok((take, hex(&hasher.finalize())));
        }
    }
    let (take, sha256) = std::thread::scope(|scope| {
        let hasher = scope.spawn(|| source_sha256(input));
        let take = read_take(input, options);
        let sha = hasher
            .join()
            .unwrap_or_else(|_| Err(io::Error::other("hashing thread panicked")));
        (take, sha)
    });
    let take = take?;
    let sha256 = sha256.map_err(|e| ReadError::Io {
        path: input.to_path_buf(),
        source: e,
    })?;
    Ok((take, sha256))
}

/// The world of a take's sensors and where it came from: `--world` or the config file's
/// (`settings.read.world`, which the reader already applied), else the mapping's, else the
/// format's own.
fn resolve_world(
    take: &Take,
    settings: &ConvertSettings,
    mapping_world: Option<World>,
) -> (World, WorldFrom) {
    match (settings.read.world, mapping_world) {
        (Some(w), _) => (w, settings.world_from.unwrap_or(WorldFrom::Flag)),
        (None, Some(w)) => (w, WorldFrom::Mapping),
        (None, None) => (take.source().world, WorldFrom::Format),
    }
}

/// Converts one take into `out_dir`. A failure after the outputs were started (a full disk, say)
/// removes every output of the take, the sidecar first, so no partial take is left behind; a
/// failure before that leaves an earlier conversion's outputs as they were.
pub fn convert(
    input: &Path,
    out_dir: &Path,
    settings: &ConvertSettings,
) -> Result<ConvertOutcome, ConvertError> {
    convert_unclean(input, out_dir, settings).inspect_err(|e| {
        if matches!(e, ConvertError::Output(_)) {
            remove_take_outputs(out_dir, &take_stem(input));
        }
    })
}

fn convert_unclean(
    input: &Path,
    out_dir: &Path,
    settings: &ConvertSettings,
) -> Result<ConvertOutcome, ConvertError> {
    // The subject file, read once: it scales the rig, and the sidecar records it.
    let subject = match &settings.subject {
        Some(path) => Some(Subject::load(path)?),
        None => None,
    };
    let subject = subject.as_ref();
    if is_bvh_take(input, &settings.read) {
        let (conversion, source) = bvh_conversion(input, settings, subject)?;
        let facts = TakeFacts {
            sensor_summaries: SensorSummaries(Vec::new()),
            warnings: conversion.warnings.clone(),
            dropped_lines: Vec::new(),
            repaired_lines: Vec::new(),
        };
        return write_take(input, out_dir, settings, subject, source, facts, conversion);
    }
    if settings.mvnx_segments {
        let (conversion, source, dropped_lines) =
            mvnx_segments_conversion(input, settings, subject)?;
        let facts = TakeFacts {
            sensor_summaries: SensorSummaries(Vec::new()),
            warnings: conversion.warnings.clone(),
            dropped_lines,
            repaired_lines: Vec::new(),
        };
        return write_take(input, out_dir, settings, subject, source, facts, conversion);
    }
    let read_span = tracing::debug_span!("read and hash").entered();
    let (take, sha256) = read_and_hash(input, &settings.read)?;
    drop(read_span);
    // What the sidecar and the report keep of the take; the pipeline then consumes it, so its
    // samples are never held twice and are freed before the outputs are built.
    let mut facts = TakeFacts::of(&take);
    let vendor_contacts = take.vendor_contacts().cloned();
    let source_info = take.source().clone();
    let mut conversion = conversion(input, take, settings, subject)?;
    facts.warnings.extend(conversion.warnings.iter().cloned());
    conversion.vendor_contacts = vendor_contacts
        .as_ref()
        .map(|v| vendor_contacts_record(v, &conversion));
    let source = SourceRecord {
        path: input.to_string_lossy().into_owned(),
        sha256,
        format: source_info.format,
        world: conversion.world.0,
        world_from: conversion.world.1,
        start_timestamp: source_info.start_timestamp,
    };
    write_take(input, out_dir, settings, subject, source, facts, conversion)
}

/// The animation of one take, as `convert` would write it, without writing anything (for
/// `imubake angles` and `compare` on a capture).
pub fn animate(input: &Path, settings: &ConvertSettings) -> Result<Animation, ConvertError> {
    let subject = match &settings.subject {
        Some(path) => Some(Subject::load(path)?),
        None => None,
    };
    if is_bvh_take(input, &settings.read) {
        return Ok(bvh_conversion(input, settings, subject.as_ref())?
            .0
            .animation);
    }
    let take = read_take(input, &settings.read)?;
    Ok(conversion(input, take, settings, subject.as_ref())?.animation)
}

/// What a stream of `settings` runs on: the rig (scaled to the subject), the quaternion mapping
/// and its path, and the pipeline options (the sensor calibration loaded).
pub fn stream_setup(
    settings: &ConvertSettings,
) -> Result<(Rig, Mapping, PathBuf, pipeline::PipelineOptions), ConvertError> {
    let path = settings
        .mapping
        .clone()
        .ok_or(ConvertError::NoStreamMapping)?;
    let mapping = match load_mapping(&path)? {
        MappingFile::Quaternion(m) => m,
        MappingFile::Legacy(_) => return Err(ConvertError::LegacyStream(path)),
    };
    let subject = match &settings.subject {
        Some(p) => Some(Subject::load(p)?),
        None => None,
    };
    let rig = rig_for(settings, mapping.rig.as_deref(), subject.as_ref())?;
    let mut options = settings.pipeline.clone();
    if let Some(p) = &settings.sensor_calibration {
        options.sensor_calibration = Some(std::sync::Arc::new(
            crate::intrinsics::SensorCalibration::load(p)?,
        ));
    }
    Ok((rig, mapping, path, options))
}

/// The take converted by its mapping's mode, then `--in-place` and `--bind-frame`.
fn conversion(
    input: &Path,
    take: Take,
    settings: &ConvertSettings,
    subject: Option<&Subject>,
) -> Result<Conversion, ConvertError> {
    let conversion = match &settings.mapping {
        Some(path) => match load_mapping(path)? {
            MappingFile::Quaternion(m) => {
                quaternion_mode(input, take, settings, subject, m, Some(path))?
            }
            MappingFile::Legacy(m) => legacy_mode(input, &take, settings, subject, &m, path)?,
        },
        None => {
            // Matching sensors to bones by name needs only the names: the rig unscaled.
            let rig = rig_for(settings, None, None)?;
            let ids: Vec<&str> = take.sensors().iter().map(|s| s.id()).collect();
            let mapping = Mapping::by_name(&rig, &ids).ok_or_else(|| ConvertError::NoMapping {
                input: input.to_path_buf(),
                rig: settings.rig.clone().unwrap_or_else(|| "mixamo".into()),
                sensors: ids.join(", "),
            })?;
            quaternion_mode(input, take, settings, subject, mapping, None)?
        }
    };
    conversion.with_output_transforms(input, settings)
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

/// A BVH take retargeted onto the rig ([`crate::retarget`]) at the settings' rate, and what the
/// sidecar says of its source.
fn bvh_conversion(
    input: &Path,
    settings: &ConvertSettings,
    subject: Option<&Subject>,
) -> Result<(Conversion, SourceRecord), ConvertError> {
    let fail = |reason: String| ConvertError::Motion {
        input: input.to_path_buf(),
        reason,
    };
    // Read as it comes and hashed on the way: the file is never held whole (its lines are held
    // to the reader's limit), and the hash covers every byte, the reader's unread tail included.
    let file = std::fs::File::open(input).map_err(|e| fail(e.to_string()))?;
    let mut hasher = Sha256::new();
    let mut observe = |bytes: &[u8]| hasher.update(bytes);
    let mut source = crate::read::blocks::Observed {
        inner: std::io::BufReader::with_capacity(1 << 16, file),
        observe: &mut observe,
    };
    let bvh = crate::bvh::read(&mut source).map_err(|e| fail(e.to_string()))?;
    io::copy(&mut source, &mut io::sink()).map_err(|e| fail(e.to_string()))?;
    drop(source);
    let sha256 = hex(&hasher.finalize());
    let source_fps = crate::fps::Fps::from_frame_time_s(bvh.frame_time_s()).ok_or_else(|| {
        fail(format!(
            "Frame Time {} is not a frame rate",
            bvh.frame_time_s()
        ))
    })?;
    let source = crate::retarget::SourceMotion::of_bvh(&bvh, source_fps);
    drop(bvh);
    let Retargeted {
        animation,
        pairs,
        warnings,
    } = retarget_onto_rig(&source, settings, subject, settings.bvh_reference, &fail)?;
    let source = SourceRecord {
        path: input.to_string_lossy().into_owned(),
        sha256,
        format: crate::take::InputFormat::Bvh,
        world: World::Rig,
        world_from: WorldFrom::Format,
        start_timestamp: "0 s".to_string(),
    };
    let motion = Motion {
        animation,
        pairs,
        orientation: "bvh",
        world: World::Rig,
        mode: "bvh-retarget",
        warnings,
    };
    Ok((motion.conversion(input, settings)?, source))
}

/// `source` onto the settings' rig (scaled to the subject): its joints paired with the rig's
/// bones by `--bone-map`, else by anatomical part, then retargeted from `reference` at the
/// settings' rate. The animation, and each (joint, bone) pair by name.
fn retarget_onto_rig(
    source: &crate::retarget::SourceMotion,
    settings: &ConvertSettings,
    subject: Option<&Subject>,
    reference: crate::retarget::Reference,
    fail: &dyn Fn(String) -> ConvertError,
) -> Result<Retargeted, ConvertError> {
    let rig = rig_for(settings, None, subject)?;
    let source_names: Vec<&str> = source.names.iter().map(String::as_str).collect();
    let target_names: Vec<&str> = rig.joints().iter().map(|j| j.name.as_str()).collect();
    let pairs = match &settings.bone_map {
        Some(path) => crate::retarget::load_bone_map(path, &source_names, &rig),
        None => crate::retarget::auto_pairs(source, &rig),
    }
    .map_err(|e| fail(e.to_string()))?;
    let warnings = crate::retarget::coverage_warnings(source, &rig, &pairs);
    let animation =
        crate::retarget::retarget(source, &rig, &pairs, reference, settings.pipeline.fps)
            .map_err(|e| fail(e.to_string()))?;
    let named = pairs
        .iter()
        .map(|&(s, t)| (source_names[s].to_string(), target_names[t].to_string()))
        .collect();
    Ok(Retargeted {
        animation,
        pairs: named,
        warnings,
    })
}

/// A motion retargeted onto the rig: the animation, each (source joint, bone) pair by name, and
/// what the pairing left out ([`crate::retarget::coverage_warnings`]).
struct Retargeted {
    animation: Animation,
    pairs: Vec<(String, String)>,
    warnings: Vec<String>,
}

/// A take whose motion is already on a skeleton (a BVH, Xsens's segments), as a conversion: its
/// animation, and each source joint that drove a bone.
struct Motion {
    animation: Animation,
    /// (source joint or segment, bone).
    pairs: Vec<(String, String)>,
    /// `mapping.sensors[].orientation`: `bvh`, `xsens-segment`.
    orientation: &'static str,
    world: World,
    /// `pipeline.mode`.
    mode: &'static str,
    warnings: Vec<String>,
}

impl Motion {
    /// The conversion `write_take` writes: the sidecar's records (identity mounts, no smoothing,
    /// the root from the source), then `--in-place` and `--bind-frame`.
    fn conversion(
        self,
        input: &Path,
        settings: &ConvertSettings,
    ) -> Result<Conversion, ConvertError> {
        let Motion {
            animation,
            pairs,
            orientation,
            world,
            mode,
            mut warnings,
        } = self;
        if settings.pipeline.trim.is_some() {
            warnings.push(format!("--trim is not applied in {mode} mode"));
        }
        let sensors = pairs
            .into_iter()
            .map(|(sensor, bone)| crate::mapping::SensorRecord {
                sensor,
                bone,
                mount_source: "fixed",
                mount: [1.0, 0.0, 0.0, 0.0],
                forward: None,
                orientation,
                world,
                heading_aligned_by: None,
            })
            .collect();
        let mut pipeline = pipeline_record(
            settings,
            &HeadingSource::None,
            0.0,
            0,
            mode,
            pipeline::root::RootMode::Fixed,
        );
        pipeline.root = "source";
        pipeline.smoothing = None;
        pipeline.unsensed = "rest";
        pipeline.trim = None;
        let rig = animation.rig().name().to_string();
        let conversion = Conversion {
            euler_deg: None,
            animation,
            unsmoothed: None,
            mapping: MappingRecord {
                file: settings
                    .bone_map
                    .as_ref()
                    .map(|p| p.to_string_lossy().into_owned()),
                rig,
                world,
                calibration: None,
                sensors,
                legacy: None,
            },
            pipeline,
            contacts: None,
            world: (world, WorldFrom::Format),
            vendor_contacts: None,
            warnings,
        };
        conversion.with_output_transforms(input, settings)
    }
}

/// Xsens's own segment kinematics (`--mvnx-segments`) as the take: on the rig the file's segments
/// make, or retargeted onto `--rig` by anatomical part (or `--bone-map`); Xsens's foot contacts
/// in the sidecar.
fn mvnx_segments_conversion(
    input: &Path,
    settings: &ConvertSettings,
    subject: Option<&Subject>,
) -> Result<(Conversion, SourceRecord, Vec<LineReport>), ConvertError> {
    let fail = |reason: String| ConvertError::Motion {
        input: input.to_path_buf(),
        reason,
    };
    let sha256 = source_sha256(input).map_err(|e| fail(e.to_string()))?;
    let segments = crate::read::xsens_mvnx::read_segments(input)?;
    let (mvn, mut warnings) = crate::retarget::mvnx_animation(&segments, settings.pipeline.fps)
        .map_err(|e| fail(e.to_string()))?;
    let (animation, pairs) = if settings.rig.is_some() || settings.bone_map.is_some() {
        let source = crate::retarget::SourceMotion::of_animation(&mvn);
        let Retargeted {
            animation,
            pairs,
            warnings: more,
        } = retarget_onto_rig(
            &source,
            settings,
            subject,
            crate::retarget::Reference::Rest,
            &fail,
        )?;
        warnings.extend(more);
        (animation, pairs)
    } else {
        let pairs = mvn
            .rig()
            .joints()
            .iter()
            .map(|j| (j.name.clone(), j.name.clone()))
            .collect();
        (mvn, pairs)
    };
    if !segments.dropped.is_empty() {
        warnings.push(format!(
            "{} frames dropped (see dropped_lines)",
            segments.dropped.len()
        ));
    }
    let motion = Motion {
        animation,
        pairs,
        orientation: "xsens-segment",
        world: World::Nwu,
        mode: "mvnx-segments",
        warnings,
    };
    let mut conversion = motion.conversion(input, settings)?;
    if !segments.contacts.is_empty() {
        let (times_s, planted) = segments.contacts.iter().copied().unzip();
        conversion.vendor_contacts = Some(vendor_contacts_record(
            &crate::take::VendorContacts {
                vendor: "xsens",
                times_s,
                planted,
            },
            &conversion,
        ));
    }
    let source = SourceRecord {
        path: input.to_string_lossy().into_owned(),
        sha256,
        format: crate::take::InputFormat::XsensMvnx,
        world: World::Nwu,
        world_from: WorldFrom::Format,
        start_timestamp: "0 s".to_string(),
    };
    Ok((conversion, source, segments.dropped))
}

/// A converted take, whichever mapping mode made it: the animation, what the writers need of it,
/// and what the sidecar says of how it was made.
struct Conversion {
    animation: Animation,
    /// BVH channel values when made already, paper 002's channel copy ([`TakeOutputs::euler_deg`]);
    /// else the BVH writer makes them from the animation's rotations.
    euler_deg: Option<Vec<Vec<[f64; 3]>>>,
    /// Local rotations before smoothing, `[joint][frame]`, for the report.
    unsmoothed: Option<Vec<Vec<UnitQuaternion<f64>>>>,
    mapping: MappingRecord,
    pipeline: PipelineRecord,
    /// The feet's contacts, in `feet` root mode.
    contacts: Option<pipeline::root::Contacts>,
    /// The sensors' world, and where it came from.
    world: (World, WorldFrom),
    /// The capture system's own foot contacts on the animation's frames.
    vendor_contacts: Option<crate::write::sidecar::VendorContactsRecord>,
    warnings: Vec<String>,
}

impl Conversion {
    /// `--in-place`, then `--bind-frame`, as the settings ask.
    fn with_output_transforms(
        self,
        input: &Path,
        settings: &ConvertSettings,
    ) -> Result<Conversion, ConvertError> {
        let conversion = if settings.in_place {
            self.in_place().map_err(|source| ConvertError::Pipeline {
                input: input.to_path_buf(),
                source: source.into(),
            })?
        } else {
            self
        };
        Ok(if settings.bind_frame {
            conversion.with_bind_frame()
        } else {
            conversion
        })
    }

    /// `--in-place` ([`Animation::in_place`]): a `root` joint at floor level carries the hips'
    /// horizontal motion; the BVH channels (a zero row for the new joint in paper 002's mode)
    /// and the report's unsmoothed rotations get the new joint.
    fn in_place(mut self) -> Result<Conversion, crate::anim::AnimationError> {
        self.animation = self.animation.in_place()?;
        let frames = self.animation.frames();
        if let Some(euler_deg) = &mut self.euler_deg {
            euler_deg.insert(0, vec![[0.0; 3]; frames]);
        }
        if let Some(unsmoothed) = &mut self.unsmoothed {
            unsmoothed.insert(0, vec![UnitQuaternion::identity(); frames]);
        }
        self.pipeline.in_place = true;
        Ok(self)
    }

    /// The rest pose as frame 0, the take from frame 1 (`--bind-frame`): the animation, its BVH
    /// channels (the quaternion mode's again from the rotations, so the Euler filter runs on from
    /// the rest pose; paper 002's channels start from zeros), the report's unsmoothed rotations
    /// and the contacts move one frame on.
    fn with_bind_frame(mut self) -> Conversion {
        self.animation = self.animation.with_bind_frame();
        for track in self.euler_deg.iter_mut().flatten() {
            track.insert(0, [0.0; 3]);
        }
        if let Some(unsmoothed) = &mut self.unsmoothed {
            for track in unsmoothed {
                track.insert(0, UnitQuaternion::identity());
            }
        }
        if let Some(c) = &mut self.contacts {
            for r in c.left.iter_mut().chain(&mut c.right).chain(&mut c.airborne) {
                *r = [r[0] + 1, r[1] + 1];
            }
            c.per_frame.insert(0, [false; 2]);
        }
        self.pipeline.bind_frame = true;
        self
    }
}

/// A capture system's contacts on the written frames: frame n stands at take time
/// (n − bind + first) / fps, where `first` is the grid frame `--trim` made frame 0 and `bind` is 1
/// with `--bind-frame` (whose frame 0, the rest pose, has no contact).
fn vendor_contacts_record(
    v: &crate::take::VendorContacts,
    conversion: &Conversion,
) -> crate::write::sidecar::VendorContactsRecord {
    let fps = conversion.animation.fps();
    let first = conversion
        .pipeline
        .trim
        .as_ref()
        .map_or(0, |t| t.first_frame);
    let bind = usize::from(conversion.pipeline.bind_frame);
    let planted: Vec<[bool; 2]> = (0..conversion.animation.frames())
        .map(|n| match n.checked_sub(bind) {
            Some(k) => v.at(fps.frame_time_of((k + first) as u64)),
            None => [false; 2],
        })
        .collect();
    // Every run, however short: the system's own contacts, as it gave them.
    let runs = |side: usize| pipeline::root::runs(planted.iter().map(|p| p[side]), 1);
    crate::write::sidecar::VendorContactsRecord {
        vendor: v.vendor,
        left: runs(0),
        right: runs(1),
    }
}

/// The rig: `--rig`, else the mapping's, else `mixamo`, scaled to `subject` (read from
/// `settings.subject`) when there is one.
fn rig_for(
    settings: &ConvertSettings,
    mapping_rig: Option<&str>,
    subject: Option<&Subject>,
) -> Result<Rig, ConvertError> {
    let name = settings.rig.as_deref().or(mapping_rig).unwrap_or("mixamo");
    let rig = load_rig(name)?;
    match (subject, &settings.subject) {
        (Some(subject), Some(path)) => Ok(subject.apply(&rig, path)?),
        _ => Ok(rig),
    }
}

/// The quaternion pipeline ([`pipeline::run`]) with a quaternion mapping (`file`: where it came
/// from; `None` when the sensors drive the bones named like them).
fn quaternion_mode(
    input: &Path,
    take: Take,
    settings: &ConvertSettings,
    subject: Option<&Subject>,
    mapping: Mapping,
    file: Option<&Path>,
) -> Result<Conversion, ConvertError> {
    let rig = rig_for(settings, mapping.rig.as_deref(), subject)?;
    let mapping_name = file.map_or_else(
        || PathBuf::from("(sensors matched to bones by name)"),
        Path::to_path_buf,
    );
    let mut options = settings.pipeline.clone();
    options.keep_unsmoothed |= settings.report;
    if let Some(path) = &settings.sensor_calibration {
        options.sensor_calibration = Some(std::sync::Arc::new(
            crate::intrinsics::SensorCalibration::load(path)?,
        ));
    }
    let (world, world_from) = resolve_world(&take, settings, mapping.world);
    options.world = Some(world);
    let converted =
        pipeline::run_owned(take, &rig, &mapping, &mapping_name, &options).map_err(|source| {
            ConvertError::Pipeline {
                input: input.to_path_buf(),
                source,
            }
        })?;
    let heading = &converted.calibration;
    Ok(Conversion {
        euler_deg: None,
        mapping: mapping_record(&converted, &rig, &mapping, file),
        pipeline: PipelineRecord {
            fusion: fusion_record(settings, &converted),
            ..pipeline_record(
                settings,
                &heading.heading_source,
                heading.heading.scaled_axis().y.to_degrees(),
                converted.first_frame,
                "quaternion",
                converted.root_mode,
            )
        },
        contacts: converted.contacts,
        world: (converted.world, world_from),
        vendor_contacts: None,
        unsmoothed: converted.unsmoothed,
        warnings: converted.warnings,
        animation: converted.animation,
    })
}

/// Paper 002's pipeline for a Listing-2 mapping ([`pipeline::legacy`]): the signed yaw/pitch/roll
/// channel copy onto `--rig` (default `mixamo`), parents from Table 1 (the `sou12` rig), every
/// joint written with BVH channels `Zrotation Yrotation Xrotation` (Blender's `XYZ` mode), the
/// root fixed at rest (unless `--root` names another mode). Sidecar: `pipeline.mode = "legacy-euler"`, `pipeline.heading = "none"`,
/// `mapping.legacy` lists each target.
fn legacy_mode(
    input: &Path,
    take: &Take,
    settings: &ConvertSettings,
    subject: Option<&Subject>,
    mapping: &LegacyMapping,
    mapping_path: &Path,
) -> Result<Conversion, ConvertError> {
    let rig = rig_for(settings, None, subject)?;
    let table1 = load_rig("sou12")?;
    let legacy = pipeline::legacy::run(
        take,
        &rig,
        &table1,
        mapping,
        mapping_path,
        &settings.pipeline,
    )
    .map_err(|source| ConvertError::Pipeline {
        input: input.to_path_buf(),
        source,
    })?;
    let world = resolve_world(take, settings, None);
    let out_rig = legacy.animation.rig();
    Ok(Conversion {
        mapping: MappingRecord {
            file: Some(mapping_path.to_string_lossy().into_owned()),
            rig: out_rig.name().to_string(),
            world: world.0,
            calibration: None,
            sensors: Vec::new(),
            legacy: Some(
                legacy
                    .targets
                    .iter()
                    .map(|t| LegacyTargetRecord::new(&t.target, t.parent.clone()))
                    .collect(),
            ),
        },
        pipeline: pipeline_record(
            settings,
            &HeadingSource::None,
            0.0,
            legacy.first_frame,
            "legacy-euler",
            legacy.root_mode,
        ),
        contacts: legacy.contacts,
        world,
        vendor_contacts: None,
        unsmoothed: None,
        warnings: legacy.warnings,
        euler_deg: Some(legacy.euler_deg),
        animation: legacy.animation,
    })
}

/// The sidecar's `pipeline.fusion`: `None` when no sensor was fused.
fn fusion_record(
    settings: &ConvertSettings,
    converted: &pipeline::Converted,
) -> Option<FusionRecord> {
    let fusion = converted.fusion.clone()?;
    let sensors = converted
        .sensors
        .iter()
        .zip(&converted.origins)
        .filter_map(|(s, origin)| match origin {
            Origin::Fused(stats) => Some((s.sensor.clone(), stats.clone())),
            Origin::Device { .. } => None,
        })
        .collect();
    Some(FusionRecord {
        fusion,
        chosen_by: if settings.pipeline.fusion.is_some() {
            "settings"
        } else {
            "default"
        },
        sensor_calibration: settings.sensor_calibration.as_ref().map(|path| {
            crate::write::sidecar::FileRecord {
                path: path.display().to_string(),
                sha256: source_sha256(path).unwrap_or_else(|_| "(unreadable)".into()),
            }
        }),
        sensors,
    })
}

/// The sidecar's `pipeline`: what was done, in which mode.
fn pipeline_record(
    settings: &ConvertSettings,
    heading: &HeadingSource,
    heading_deg: f64,
    first_frame: usize,
    mode: &'static str,
    root: pipeline::root::RootMode,
) -> PipelineRecord {
    PipelineRecord {
        fusion: None,
        smoothing: Some(serde_json::to_value(&settings.pipeline.smoothing).expect("serialisable")),
        root: root.label(),
        unsensed: if mode == "legacy-euler" {
            "rest"
        } else {
            settings.pipeline.unsensed.label()
        },
        heading: heading.label(),
        heading_sensor: heading.sensor().map(str::to_string),
        heading_deg,
        trim: settings.pipeline.trim.map(|t| TrimRecord {
            start_s: t.start_s,
            end_s: (t.end_s < f64::MAX).then_some(t.end_s),
            first_frame,
        }),
        mode,
        causal: settings.pipeline.causal,
        bind_frame: false,
        in_place: false,
    }
}

/// Writes each output the settings ask for as `<out_dir>/<stem>.*`, then the sidecar, last.
fn write_take(
    input: &Path,
    out_dir: &Path,
    settings: &ConvertSettings,
    subject: Option<&Subject>,
    source: SourceRecord,
    facts: TakeFacts,
    conversion: Conversion,
) -> Result<ConvertOutcome, ConvertError> {
    let stem = take_stem(input);
    std::fs::create_dir_all(out_dir).map_err(|source| OutputError::Write {
        path: out_dir.to_path_buf(),
        source,
    })?;
    // A sidecar left by an earlier conversion would claim a complete take while its outputs are
    // being replaced, and after a failure: it goes before any output is touched.
    let old_sidecar = out_dir.join(format!("{stem}.imubake.json"));
    if let Err(source) = std::fs::remove_file(&old_sidecar)
        && source.kind() != io::ErrorKind::NotFound
    {
        return Err(OutputError::Write {
            path: old_sidecar,
            source,
        }
        .into());
    }
    let TakeFacts {
        sensor_summaries,
        warnings,
        dropped_lines,
        repaired_lines,
    } = facts;
    let animation = &conversion.animation;
    let source_text = input.to_string_lossy();
    let take_outputs = TakeOutputs {
        stem: &stem,
        animation,
        euler_deg: conversion.euler_deg.as_deref(),
        units: settings.units,
        report: settings.report.then(|| ReportInput {
            take: &stem,
            source: &source_text,
            fps: animation.fps().to_string(),
            smoothing: settings.pipeline.smoothing.describe(),
            bones: bone_series(
                animation,
                conversion.unsmoothed.as_deref(),
                conversion.euler_deg.as_deref(),
            ),
            sensors: &sensor_summaries,
            warnings: &warnings,
            dropped_lines: dropped_lines.len(),
            fusion: conversion
                .pipeline
                .fusion
                .as_ref()
                .map(|f| f.sensors.iter().map(|(id, s)| (id.as_str(), s)).collect())
                .unwrap_or_default(),
        }),
    };
    // Each output is its own file: written side by side (the BVH's formatting and the GLB's
    // buffer share the cores), their records kept in the settings' order.
    let written: Vec<_> = settings
        .outputs()
        .into_par_iter()
        .map(|output| {
            let _span = match output {
                Output::Animation(OutputFormat::Bvh) => tracing::debug_span!("write bvh"),
                Output::Animation(OutputFormat::Glb) => tracing::debug_span!("write glb"),
                Output::Animation(OutputFormat::Gltf) => tracing::debug_span!("write gltf"),
                Output::Report => tracing::debug_span!("write report"),
            }
            .entered();
            output.write(out_dir, &take_outputs)
        })
        .collect();
    let outputs = written.into_iter().collect::<Result<Vec<_>, _>>()?;
    drop(take_outputs);
    let (dropped_lines, dropped_lines_total, dropped_lines_omitted) =
        Sidecar::bound_dropped(dropped_lines);
    let out_rig = animation.rig();
    let sidecar = Sidecar {
        imubake_version: env!("CARGO_PKG_VERSION"),
        source,
        fps: animation.fps(),
        frames: animation.frames(),
        duration_s: animation.duration_s(),
        rig: RigRecord {
            name: out_rig.name().to_string(),
            units: settings.units.name(),
            bones: out_rig.len(),
            subject: settings
                .subject
                .as_ref()
                .zip(subject)
                .map(|(path, subject)| crate::write::sidecar::SubjectRecord {
                    path: path.display().to_string(),
                    sha256: source_sha256(path).unwrap_or_else(|_| "(unreadable)".into()),
                    subject: subject.clone(),
                    standing_height_m: out_rig.standing_height()
                        * out_rig.units().metres_per_unit(),
                }),
        },
        mapping: conversion.mapping,
        pipeline: conversion.pipeline,
        contacts: conversion.contacts,
        vendor_contacts: conversion.vendor_contacts,
        outputs,
        sensors: sensor_summaries,
        dropped_lines,
        dropped_lines_total,
        dropped_lines_omitted,
        repaired_lines,
        warnings,
    };
    let sidecar_path = out_dir.join(format!("{stem}.imubake.json"));
    let json = serde_json::to_vec_pretty(&sidecar).expect("the sidecar serialises");
    write_atomic(&sidecar_path, |w| {
        w.write_all(&json)?;
        w.write_all(b"\n")
    })
    .map_err(|source| OutputError::Write {
        path: sidecar_path.clone(),
        source,
    })?;
    Ok(ConvertOutcome {
        sidecar,
        sidecar_path,
    })
}
