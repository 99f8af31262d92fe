//! The settings of a conversion as the command line and the config file give them: paths not
//! yet read (a [`super::Plan`] reads them once), options, and which layer gave each.

use crate::pipeline::PipelineOptions;
use crate::read::ReadOptions;
use crate::rig::LengthUnit;
use crate::world::WorldFrom;
pub use crate::write::{Engine, Output, OutputFormat};
use std::path::PathBuf;

/// Which settings layer gave a value.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Layer {
    /// Not given: the default.
    #[default]
    Default,
    /// The config file (`imubake.yaml`, `--config`).
    Config,
    /// A flag on the command line.
    Flag,
}

impl Layer {
    /// The layer of a value given (or not) by the flags, else by the config file.
    pub fn of(flag: bool, config: bool) -> Layer {
        match (flag, config) {
            (true, _) => Layer::Flag,
            (false, true) => Layer::Config,
            (false, false) => Layer::Default,
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            Layer::Default => "default",
            Layer::Config => "config",
            Layer::Flag => "flag",
        }
    }
}

/// Where each of the settings that name a file, or change a command's defaults, came from
/// (`world`'s is [`ConvertSettings::world_from`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Given {
    pub fps: Layer,
    pub mapping: Layer,
    pub rig: Layer,
    pub subject: Layer,
    pub sensor_calibration: Layer,
    pub bone_map: Layer,
}

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
    /// A game engine whose import settings are written beside the glTF outputs (`--engine`).
    pub engine: Option<Engine>,
    /// Where `read.world` came from (`--world` or the config file), when it is set.
    pub world_from: Option<WorldFrom>,
    /// A BVH take: which of its joints drive which bones (the Blender add-on's bone-map JSON);
    /// default: by anatomical part.
    pub bone_map: Option<PathBuf>,
    /// A BVH take: the pose its joints' changes are measured from.
    pub bvh_reference: crate::retarget::Reference,
    /// An MVNX take: Xsens's own segment orientations and positions instead of its sensors.
    pub mvnx_segments: bool,
    /// Which layer gave the settings that are files or change a command's defaults.
    pub given: Given,
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
            engine: None,
            world_from: None,
            bone_map: None,
            bvh_reference: crate::retarget::Reference::default(),
            mvnx_segments: false,
            given: Given::default(),
        }
    }
}
