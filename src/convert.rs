//! One take from capture to outputs: read → pipeline → Euler filter → BVH / glTF → sidecar
//! (written last, so its appearance means the take is complete).

use crate::anim::Animation;
use crate::bvh::{BvhMotion, write_bvh_in};
use crate::inspect::SensorSummaries;
use crate::mapping::{
    CalibrationRecord, LegacyMapping, LegacyTargetRecord, Mapping, MappingError, MappingFile,
    MappingRecord, Mount, SensorRecord, load_mapping,
};
use crate::pipeline::calibrate::HeadingSource;
use crate::pipeline::legacy::LegacyAnimation;
use crate::pipeline::{self, Converted, PipelineError, PipelineOptions};
use crate::read::{
    ReadError, ReadOptions, check_text, is_stream, read_stream, read_take, read_take_from_bytes,
    sniff,
};
use crate::report::{BoneSeries, ReportInput, render_report};
use crate::rig::file::RigLoadError;
use crate::rig::{LengthUnit, Rig, load_rig};
use crate::rotation::euler::filter_track;
use crate::take::{LineReport, Take};
use crate::world::{World, WorldFrom};
use crate::write::gltf::{GltfWriteError, to_glb, to_gltf};
use crate::write::sidecar::{
    OutputRecord, PipelineRecord, RigRecord, Sidecar, SourceRecord, TrimRecord,
};
use crate::write::{remove_take_outputs, write_atomic};
use nalgebra::UnitQuaternion;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::io::{self, Read};
use std::path::{Path, PathBuf};

/// An output file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputFormat {
    Bvh,
    Glb,
    /// `.gltf` JSON with a `.bin` buffer beside it.
    Gltf,
}

impl OutputFormat {
    pub fn name(self) -> &'static str {
        match self {
            OutputFormat::Bvh => "bvh",
            OutputFormat::Glb => "glb",
            OutputFormat::Gltf => "gltf",
        }
    }
}

impl std::str::FromStr for OutputFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "bvh" => Ok(OutputFormat::Bvh),
            "glb" => Ok(OutputFormat::Glb),
            "gltf" => Ok(OutputFormat::Gltf),
            _ => Err(format!(
                "unknown output format `{s}`; expected bvh, glb or gltf"
            )),
        }
    }
}

/// Everything a conversion needs besides the input and the output folder.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvertSettings {
    pub read: ReadOptions,
    /// A mapping file; without one, sensors drive the rig's bones of the same name.
    pub mapping: Option<PathBuf>,
    /// A built-in rig name or a rig file; default: the mapping's `rig`, else `mixamo`.
    pub rig: Option<String>,
    pub pipeline: PipelineOptions,
    pub formats: Vec<OutputFormat>,
    /// Length unit of the BVH output (glTF is always metres).
    pub units: LengthUnit,
    /// Also write `<stem>.report.html`.
    pub report: bool,
    /// Where `read.world` came from (`--world` or the config file), when it is set.
    pub world_from: Option<WorldFrom>,
}

impl Default for ConvertSettings {
    fn default() -> Self {
        ConvertSettings {
            read: ReadOptions::default(),
            mapping: None,
            rig: None,
            pipeline: PipelineOptions::default(),
            formats: vec![OutputFormat::Bvh, OutputFormat::Glb],
            units: LengthUnit::Metres,
            report: false,
            world_from: None,
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
    #[error("{}: cannot write: {source}", .path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("{}: {source}", .path.display())]
    Gltf {
        path: PathBuf,
        #[source]
        source: GltfWriteError,
    },
}

/// The name outputs of `input` are written under: the file name without its extension, or the
/// folder name of a session folder.
pub fn take_stem(input: &Path) -> String {
    let name = if input.is_dir() {
        input.file_name()
    } else {
        input.file_stem()
    };
    name.map(|n| n.to_string_lossy().into_owned())
        .filter(|n| !n.is_empty() && n != "." && n != "..")
        .unwrap_or_else(|| "take".to_string())
}

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

/// The mapping to use and the file it came from (for messages and the sidecar).
fn resolve_mapping(
    input: &Path,
    take: &Take,
    settings: &ConvertSettings,
    file_mapping: Option<(Mapping, PathBuf)>,
) -> Result<(Mapping, Option<PathBuf>, Rig), ConvertError> {
    let rig_name = settings
        .rig
        .clone()
        .or_else(|| file_mapping.as_ref().and_then(|(m, _)| m.rig.clone()))
        .unwrap_or_else(|| "mixamo".to_string());
    let rig = load_rig(&rig_name)?;
    match file_mapping {
        Some((m, path)) => Ok((m, Some(path), rig)),
        None => {
            let ids: Vec<&str> = take.sensors().iter().map(|s| s.id()).collect();
            let mapping = Mapping::by_name(&rig, &ids).ok_or_else(|| ConvertError::NoMapping {
                input: input.to_path_buf(),
                rig: rig_name.clone(),
                sensors: ids.join(", "),
            })?;
            Ok((mapping, None, rig))
        }
    }
}

/// Euler angles in degrees, `[joint][frame]`, each joint in its own channel order, with the
/// discontinuity filter applied.
pub fn euler_degrees(animation: &Animation) -> Vec<Vec<[f64; 3]>> {
    animation
        .rig()
        .joints()
        .iter()
        .enumerate()
        .map(|(j, joint)| {
            filter_track(animation.local(j), joint.order)
                .into_iter()
                .map(|a| a.map(f64::to_degrees))
                .collect()
        })
        .collect()
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
    /// Takes the take, so its samples are freed here.
    fn of(take: Take, pipeline_warnings: &[String]) -> TakeFacts {
        let mut warnings = take.warnings().to_vec();
        warnings.extend(pipeline_warnings.iter().cloned());
        TakeFacts {
            sensor_summaries: SensorSummaries::of(&take),
            warnings,
            dropped_lines: take.dropped_lines().to_vec(),
            repaired_lines: take.repaired_lines().to_vec(),
        }
    }
}

/// Each animated bone's Euler angles before (`unsmoothed`, when kept) and after smoothing.
fn report_bones(
    animation: &Animation,
    unsmoothed: Option<&[Vec<UnitQuaternion<f64>>]>,
    euler_after: &[Vec<[f64; 3]>],
) -> Vec<BoneSeries> {
    let fps = animation.fps();
    let times: Vec<f64> = (0..animation.frames() as u64)
        .map(|n| fps.frame_time_of(n))
        .collect();
    animation
        .rig()
        .joints()
        .iter()
        .enumerate()
        .filter(|(j, _)| animation.is_animated(*j))
        .map(|(j, joint)| BoneSeries {
            bone: joint.name.clone(),
            order: joint.order,
            times_s: times.clone(),
            before_deg: match unsmoothed {
                Some(raw) => filter_track(&raw[j], joint.order)
                    .into_iter()
                    .map(|a| a.map(f64::to_degrees))
                    .collect(),
                None => euler_after[j].clone(),
            },
            after_deg: euler_after[j].clone(),
        })
        .collect()
}

/// What a conversion wrote.
#[derive(Debug, Clone)]
pub struct ConvertOutcome {
    pub sidecar: Sidecar,
    pub sidecar_path: PathBuf,
}

fn mapping_record(
    converted: &Converted,
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
        }),
        sensors: converted
            .sensors
            .iter()
            .zip(&converted.calibration.mounts)
            .map(|(s, q)| SensorRecord {
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
            })
            .collect(),
        legacy: None,
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Reads the take and the SHA-256 of its source. A file or folder is hashed on the second core
/// while the first parses it, once a file has passed the text check (so a huge binary file is
/// refused without being read); a stream (FIFO, process substitution) is read once into memory,
/// then hashed and parsed.
fn read_and_hash(input: &Path, options: &ReadOptions) -> Result<(Take, String), ReadError> {
    if is_stream(input) {
        let bytes = read_stream(input)?;
        let sha256 = hex(&Sha256::digest(&bytes));
        return Ok((read_take_from_bytes(&bytes, input, options)?, sha256));
    }
    if input.is_file() {
        check_text(input, &sniff(input)?)?;
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
        if matches!(e, ConvertError::Write { .. } | ConvertError::Gltf { .. }) {
            remove_take_outputs(out_dir, &take_stem(input));
        }
    })
}

fn convert_unclean(
    input: &Path,
    out_dir: &Path,
    settings: &ConvertSettings,
) -> Result<ConvertOutcome, ConvertError> {
    let (take, sha256) = read_and_hash(input, &settings.read)?;
    let file_mapping = match &settings.mapping {
        Some(path) => match load_mapping(path)? {
            MappingFile::Quaternion(m) => Some((m, path.clone())),
            MappingFile::Legacy(m) => {
                return convert_legacy(input, out_dir, settings, take, sha256, &m, path);
            }
        },
        None => None,
    };
    let (mapping, mapping_path, rig) = resolve_mapping(input, &take, settings, file_mapping)?;
    let mapping_name = mapping_path
        .clone()
        .unwrap_or_else(|| PathBuf::from("(sensors matched to bones by name)"));
    let mut pipeline_options = settings.pipeline.clone();
    pipeline_options.keep_unsmoothed |= settings.report;
    let (world, world_from) = resolve_world(&take, settings, mapping.world);
    pipeline_options.world = Some(world);
    let converted = pipeline::run(&take, &rig, &mapping, &mapping_name, &pipeline_options)
        .map_err(|source| ConvertError::Pipeline {
            input: input.to_path_buf(),
            source,
        })?;
    // What the sidecar needs of the take; the samples themselves are no longer needed, so a long
    // take's memory is freed before the outputs are built.
    let source_format = take.source().format;
    let start_timestamp = take.source().start_timestamp.clone();
    let TakeFacts {
        sensor_summaries,
        warnings,
        dropped_lines,
        repaired_lines,
    } = TakeFacts::of(take, &converted.warnings);
    let animation = &converted.animation;

    let stem = take_stem(input);
    let euler = euler_degrees(animation);
    let mut outputs = write_outputs(out_dir, &stem, animation, Some(&euler), settings)?;
    if settings.report {
        let path = out_dir.join(format!("{stem}.report.html"));
        let bones = report_bones(animation, converted.unsmoothed.as_deref(), &euler);
        let html = render_report(&ReportInput {
            take: &stem,
            source: &input.to_string_lossy(),
            fps: animation.fps().to_string(),
            smoothing: settings.pipeline.smoothing.describe(),
            bones,
            sensors: &sensor_summaries,
            warnings: &warnings,
            dropped_lines: dropped_lines.len(),
        });
        write_atomic(&path, |w| w.write_all(html.as_bytes())).map_err(write_err(&path))?;
        outputs.push(OutputRecord {
            format: "report",
            path: format!("{stem}.report.html"),
        });
    }

    let h = converted.calibration.heading;
    let sidecar = Sidecar {
        imubake_version: env!("CARGO_PKG_VERSION"),
        source: SourceRecord {
            path: input.to_string_lossy().into_owned(),
            sha256,
            format: source_format,
            world: converted.world,
            world_from,
            start_timestamp,
        },
        fps: animation.fps(),
        frames: animation.frames(),
        duration_s: animation.duration_s(),
        rig: RigRecord {
            name: rig.name().to_string(),
            units: settings.units.name(),
            bones: rig.len(),
        },
        mapping: mapping_record(&converted, &rig, &mapping, mapping_path.as_deref()),
        pipeline: pipeline_record(
            settings,
            &converted.calibration.heading_source,
            h.scaled_axis().y.to_degrees(),
            converted.first_frame,
            "quaternion",
        ),
        outputs,
        sensors: sensor_summaries,
        dropped_lines,
        repaired_lines,
        warnings,
    };
    write_sidecar(out_dir, &stem, sidecar)
}

/// The sidecar's `pipeline`: what was done, in which mode.
fn pipeline_record(
    settings: &ConvertSettings,
    heading: &HeadingSource,
    heading_deg: f64,
    first_frame: usize,
    mode: &'static str,
) -> PipelineRecord {
    PipelineRecord {
        fusion: None,
        smoothing: Some(serde_json::to_value(&settings.pipeline.smoothing).expect("serialisable")),
        root: settings.pipeline.root.label(),
        heading: heading.label(),
        heading_sensor: heading.sensor().map(str::to_string),
        heading_deg,
        trim: settings.pipeline.trim.map(|t| TrimRecord {
            start_s: t.start_s,
            end_s: (t.end_s < f64::MAX).then_some(t.end_s),
            first_frame,
        }),
        mode,
    }
}

fn write_err(path: &Path) -> impl FnOnce(io::Error) -> ConvertError {
    let path = path.to_path_buf();
    move |source| ConvertError::Write { path, source }
}

/// Writes the requested formats of `animation` as `<out_dir>/<stem>.*`. The BVH gets `euler_deg`
/// (`[joint][frame]`, degrees, each joint's order) when given, else [`euler_degrees`].
fn write_outputs(
    out_dir: &Path,
    stem: &str,
    animation: &Animation,
    euler_deg: Option<&[Vec<[f64; 3]>]>,
    settings: &ConvertSettings,
) -> Result<Vec<OutputRecord>, ConvertError> {
    std::fs::create_dir_all(out_dir).map_err(|source| ConvertError::Write {
        path: out_dir.to_path_buf(),
        source,
    })?;
    // A sidecar left by an earlier conversion would claim a complete take while its outputs are
    // being replaced, and after a failure: it goes before any output is touched.
    let old_sidecar = out_dir.join(format!("{stem}.imubake.json"));
    if let Err(e) = std::fs::remove_file(&old_sidecar)
        && e.kind() != io::ErrorKind::NotFound
    {
        return Err(write_err(&old_sidecar)(e));
    }
    let mut outputs = Vec::new();
    for format in &settings.formats {
        match format {
            OutputFormat::Bvh => {
                let path = out_dir.join(format!("{stem}.bvh"));
                let filtered;
                let euler_deg = match euler_deg {
                    Some(e) => e,
                    None => {
                        filtered = euler_degrees(animation);
                        &filtered
                    }
                };
                let motion = BvhMotion {
                    rig: animation.rig(),
                    fps: animation.fps(),
                    root_positions: animation.root_positions(),
                    euler_deg,
                };
                write_atomic(&path, |w| write_bvh_in(w, &motion, settings.units))
                    .map_err(write_err(&path))?;
                outputs.push(OutputRecord {
                    format: "bvh",
                    path: format!("{stem}.bvh"),
                });
            }
            OutputFormat::Glb => {
                let path = out_dir.join(format!("{stem}.glb"));
                let bytes = to_glb(animation, stem).map_err(|source| ConvertError::Gltf {
                    path: path.clone(),
                    source,
                })?;
                write_atomic(&path, |w| w.write_all(&bytes)).map_err(write_err(&path))?;
                outputs.push(OutputRecord {
                    format: "glb",
                    path: format!("{stem}.glb"),
                });
            }
            OutputFormat::Gltf => {
                let path = out_dir.join(format!("{stem}.gltf"));
                let bin_name = format!("{stem}.bin");
                let bin_path = out_dir.join(&bin_name);
                let (json, bin) =
                    to_gltf(animation, stem, &bin_name).map_err(|source| ConvertError::Gltf {
                        path: path.clone(),
                        source,
                    })?;
                // The buffer first, so a .gltf never points at a missing .bin.
                write_atomic(&bin_path, |w| w.write_all(&bin)).map_err(write_err(&bin_path))?;
                write_atomic(&path, |w| w.write_all(json.as_bytes())).map_err(write_err(&path))?;
                outputs.push(OutputRecord {
                    format: "gltf",
                    path: format!("{stem}.gltf"),
                });
            }
        }
    }

    Ok(outputs)
}

/// Writes the sidecar last: its appearance means the take is complete.
fn write_sidecar(
    out_dir: &Path,
    stem: &str,
    sidecar: Sidecar,
) -> Result<ConvertOutcome, ConvertError> {
    let sidecar_path = out_dir.join(format!("{stem}.imubake.json"));
    let json = serde_json::to_vec_pretty(&sidecar).expect("the sidecar serialises");
    write_atomic(&sidecar_path, |w| {
        w.write_all(&json)?;
        w.write_all(b"\n")
    })
    .map_err(write_err(&sidecar_path))?;
    Ok(ConvertOutcome {
        sidecar,
        sidecar_path,
    })
}

/// Paper 002's pipeline for a Listing-2 mapping ([`pipeline::legacy`]): the signed yaw/pitch/roll
/// channel copy onto `--rig` (default `mixamo`), parents from Table 1 (the `sou12` rig), every
/// joint written with BVH channels `Zrotation Yrotation Xrotation` (Blender's `XYZ` mode), the
/// root fixed at rest. Sidecar: `pipeline.mode = "legacy-euler"`, `pipeline.heading = "none"`,
/// `mapping.legacy` lists each target.
fn convert_legacy(
    input: &Path,
    out_dir: &Path,
    settings: &ConvertSettings,
    take: Take,
    sha256: String,
    mapping: &LegacyMapping,
    mapping_path: &Path,
) -> Result<ConvertOutcome, ConvertError> {
    let rig = load_rig(settings.rig.as_deref().unwrap_or("mixamo"))?;
    let table1 = load_rig("sou12")?;
    let legacy: LegacyAnimation = pipeline::legacy::run(
        &take,
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
    // What the sidecar needs of the take; its samples are freed before the outputs are built.
    let (world, world_from) = resolve_world(&take, settings, None);
    let source = SourceRecord {
        path: input.to_string_lossy().into_owned(),
        sha256,
        format: take.source().format,
        world,
        world_from,
        start_timestamp: take.source().start_timestamp.clone(),
    };
    let TakeFacts {
        sensor_summaries,
        warnings,
        dropped_lines,
        repaired_lines,
    } = TakeFacts::of(take, &legacy.warnings);
    let animation = &legacy.animation;
    let stem = take_stem(input);
    let outputs = write_outputs(out_dir, &stem, animation, Some(&legacy.euler_deg), settings)?;
    let out_rig = animation.rig();
    let world = source.world;
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
        },
        mapping: MappingRecord {
            file: Some(mapping_path.to_string_lossy().into_owned()),
            rig: out_rig.name().to_string(),
            world,
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
        ),
        outputs,
        sensors: sensor_summaries,
        dropped_lines,
        repaired_lines,
        warnings,
    };
    write_sidecar(out_dir, &stem, sidecar)
}
