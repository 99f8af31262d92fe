//! What can stop a conversion, with the file, line and hint a user needs.

use crate::mapping::MappingError;
use crate::pipeline::PipelineError;
use crate::read::ReadError;
use crate::rig::file::RigLoadError;
use crate::write::OutputError;
use std::path::{Path, PathBuf};

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
    /// A take's source (a BVH, an MVNX file's segments) could not be read or hashed.
    #[error("{}: {source}", .input.display())]
    Source {
        input: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {source}", .input.display())]
    Bvh {
        input: PathBuf,
        #[source]
        source: crate::bvh::BvhError,
    },
    #[error("{}: Frame Time {frame_time_s} is not a frame rate", .input.display())]
    FrameTime { input: PathBuf, frame_time_s: f64 },
    /// A take on a skeleton (a BVH, Xsens's segments) that cannot be retargeted.
    #[error("{}: {source}", .input.display())]
    Retarget {
        input: PathBuf,
        #[source]
        source: crate::retarget::RetargetError,
    },
    /// The bone map file (`--bone-map`) cannot be read.
    #[error("{}: {source}", .path.display())]
    BoneMap {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The bone map file is not a bone map.
    #[error(transparent)]
    BoneMapFile(crate::retarget::RetargetError),
    /// An engine's import settings were asked for without an output that engine imports.
    #[error(
        "--engine {}: its import settings go beside a .glb or .gltf, and none is asked for (Godot 3 imports no BVH): add --format glb",
        .0.name()
    )]
    EngineWithoutGltf(crate::write::Engine),
    /// The packet layout file (`--layout`) cannot be used.
    #[error(transparent)]
    Layout(#[from] crate::read::layout::LayoutError),
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
            ConvertError::Source { input, .. }
            | ConvertError::Bvh { input, .. }
            | ConvertError::FrameTime { input, .. }
            | ConvertError::Retarget { input, .. } => Some(input),
            ConvertError::BoneMap { path, .. } => Some(path),
            ConvertError::BoneMapFile(crate::retarget::RetargetError::BoneMap { path, .. }) => {
                Some(path)
            }
            ConvertError::BoneMapFile(_) | ConvertError::EngineWithoutGltf(_) => None,
            ConvertError::Layout(e) => Some(&e.path),
        }
    }

    fn line(&self) -> Option<u64> {
        match self {
            ConvertError::Read(e) => e.line(),
            ConvertError::Bvh { source, .. } => Some(source.line as u64),
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
            ConvertError::Retarget { .. }
            | ConvertError::BoneMap { .. }
            | ConvertError::BoneMapFile(_) => Some(
                "a skeleton's joints are matched to the rig's bones by name; --bone-map names them",
            ),
            ConvertError::Source { .. }
            | ConvertError::Bvh { .. }
            | ConvertError::FrameTime { .. } => None,
            ConvertError::EngineWithoutGltf(_) => Some("add --format glb (or gltf)"),
            ConvertError::Layout(_) => {
                Some("see docs/src/formats/layouts.md for the layout's keys")
            }
        }
    }
}
