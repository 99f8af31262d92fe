//! What the viewer shows: a take's description (`take.json`) and its motion, cut into GLB
//! chunks of a fixed number of frames.
//!
//! Chunk `k` holds frames `k·F ..= min((k+1)·F, frames − 1)` (F = frames per chunk), keyed at
//! the take's own times n · den / num, so each is a valid GLB of its time window and the page
//! plays frame `n` from chunk `min(⌊n / F⌋, chunks − 1)`; consecutive chunks share their
//! boundary frame.

use super::ViewError;
use crate::anim::Animation;
use crate::bvh::Bvh;
use crate::fps::Fps;
use crate::rig::{LengthUnit, Rig};
use nalgebra::UnitQuaternion;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The most joints a take's rig may have to be shown: the glTF writer's limit (its chunks are
/// GLBs). A take past it is refused when it is opened and when a server is bound to it, before
/// anything is served.
pub const MAX_JOINTS: usize = 65536;

/// A take as the viewer serves it.
#[derive(Debug)]
pub struct ViewTake {
    /// Shown as the page's title.
    pub name: String,
    /// Where it came from (shown under the title).
    pub source: String,
    pub fps: Fps,
    pub frames: usize,
    pub motion: Motion,
    /// Frames per chunk (F above).
    pub chunk_frames: usize,
    /// The sensors and the bones they sit on (the sidecar's mapping), for their axes.
    pub sensors: Vec<SensorAxes>,
    /// Foot contacts and airborne stretches, frame intervals (the sidecar's `contacts`).
    pub contacts: Option<ContactIntervals>,
    /// A live session: one chunk with the rig at rest, poses over the WebSocket.
    pub live: bool,
    /// The rig's joints in order (the GLB's skin joints).
    pub joints: Vec<String>,
    /// The left and right foot joints, when the rig has them by name (the contacts' discs).
    pub feet: Option<[String; 2]>,
}

/// Where a take's motion comes from.
#[derive(Debug)]
pub enum Motion {
    /// An animation in memory (the rig at rest for a live session).
    Animation(Box<Animation>),
    /// A BVH file, parsed: chunks are made from its frames as they are asked for.
    Bvh { bvh: Bvh, units: LengthUnit },
    /// A GLB served as it is, in one chunk (a GLB without its BVH cannot be cut).
    Glb(Vec<u8>),
}

/// A sensor's axes on its bone: q_bone_sensor `[w, x, y, z]` (the sidecar's `mount`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorAxes {
    pub sensor: String,
    pub bone: String,
    pub mount: [f64; 4],
}

/// The sidecar's `contacts`: inclusive frame intervals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ContactIntervals {
    pub left: Vec<[usize; 2]>,
    pub right: Vec<[usize; 2]>,
    #[serde(default)]
    pub airborne: Vec<[usize; 2]>,
}

/// What of a sidecar the viewer reads.
#[derive(Deserialize)]
struct Sidecar {
    fps: Fps,
    frames: usize,
    rig: SidecarRig,
    mapping: SidecarMapping,
    contacts: Option<ContactIntervals>,
    outputs: Vec<SidecarOutput>,
    source: SidecarSource,
}

#[derive(Deserialize)]
struct SidecarRig {
    units: LengthUnit,
}

#[derive(Deserialize)]
struct SidecarMapping {
    sensors: Vec<SensorAxes>,
}

#[derive(Deserialize)]
struct SidecarOutput {
    format: String,
    path: String,
}

#[derive(Deserialize)]
struct SidecarSource {
    path: String,
}

/// The description the page reads from `/take.json`.
#[derive(Serialize)]
pub struct TakeJson<'a> {
    pub name: &'a str,
    pub source: &'a str,
    pub fps: Fps,
    pub frames: usize,
    pub chunk_frames: usize,
    pub chunks: usize,
    pub sensors: &'a [SensorAxes],
    pub contacts: &'a Option<ContactIntervals>,
    pub joints: &'a [String],
    pub feet: &'a Option<[String; 2]>,
    pub live: bool,
    pub imubake_version: &'static str,
}

/// Sidecars are `<stem>.imubake.json`.
const SIDECAR_SUFFIX: &str = ".imubake.json";

fn is_sidecar(path: &Path) -> bool {
    path.file_name()
        .is_some_and(|n| n.to_string_lossy().ends_with(SIDECAR_SUFFIX))
}

fn has_extension(path: &Path, ext: &str) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case(ext))
}

/// Is `path` something [`ViewTake::open`] reads (a sidecar, a `.bvh` or a `.glb`)? Anything
/// else is a capture, converted first.
pub fn is_converted(path: &Path) -> bool {
    is_sidecar(path) || has_extension(path, "bvh") || has_extension(path, "glb")
}

impl ViewTake {
    /// A converted take: its sidecar (whose BVH output is shown, else its GLB), a `.bvh` or a
    /// `.glb` (with the sidecar beside it that names it, when there is one). `chunk_s` is the
    /// chunks' length in seconds.
    pub fn open(path: &Path, chunk_s: f64) -> Result<ViewTake, ViewError> {
        if is_sidecar(path) {
            let sidecar = read_sidecar(path)?;
            let dir = path.parent().unwrap_or(Path::new("."));
            let output = |format: &str| {
                sidecar
                    .outputs
                    .iter()
                    .find(|o| o.format == format)
                    .map(|o| dir.join(&o.path))
            };
            let motion_path = output("bvh").or_else(|| output("glb")).ok_or_else(|| {
                ViewError::input(path, "the sidecar lists neither a BVH nor a GLB output")
            })?;
            return ViewTake::from_file(&motion_path, Some((path.to_path_buf(), sidecar)), chunk_s);
        }
        ViewTake::from_file(path, sidecar_beside(path), chunk_s)
    }

    fn from_file(
        path: &Path,
        sidecar: Option<(PathBuf, Sidecar)>,
        chunk_s: f64,
    ) -> Result<ViewTake, ViewError> {
        let name = crate::convert::take_stem(path);
        let bytes = std::fs::read(path).map_err(|e| ViewError::input(path, e))?;
        let (motion, fps, frames, (joints, feet)) = if has_extension(path, "glb") {
            let (fps, frames, joints) =
                glb_timing(&bytes).map_err(|e| ViewError::input(path, e))?;
            check_joints(path, joints.len())?;
            let feet = foot_names(&joints);
            (Motion::Glb(bytes), fps, frames, (joints, feet))
        } else {
            let bvh = crate::bvh::parse(&bytes).map_err(|e| ViewError::input(path, e))?;
            drop(bytes);
            check_joints(path, bvh.joints().len())?;
            let units = match &sidecar {
                Some((_, s)) => s.rig.units,
                None => guess_units(&bvh),
            };
            let fps = match &sidecar {
                Some((_, s)) => s.fps,
                None => Fps::from_frame_time_s(bvh.frame_time_s())
                    .ok_or_else(|| ViewError::input(path, "its Frame Time is not a frame rate"))?,
            };
            let frames = bvh.frame_count();
            if frames == 0 {
                return Err(ViewError::input(path, "the file has no frames"));
            }
            // The skeleton must make a rig (unique names) before anything is served.
            let rig = bvh
                .to_rig(&name, units)
                .map_err(|e| ViewError::input(path, e))?;
            (Motion::Bvh { bvh, units }, fps, frames, skeleton(&rig))
        };
        let (sensors, contacts, source) = match sidecar {
            Some((sidecar_path, s)) => {
                if s.frames != frames {
                    return Err(ViewError::input(
                        path,
                        format!(
                            "has {frames} frames, but its sidecar {} says {}",
                            sidecar_path.display(),
                            s.frames
                        ),
                    ));
                }
                (s.mapping.sensors, s.contacts, s.source.path)
            }
            None => (Vec::new(), None, path.display().to_string()),
        };
        Ok(ViewTake {
            name,
            source,
            fps,
            frames,
            motion,
            chunk_frames: chunk_frames(fps, chunk_s),
            sensors,
            contacts,
            live: false,
            joints,
            feet,
        })
    }

    /// A live session's page: the rig at rest (one frame), the mapping's sensors.
    pub fn live(rig: Rig, fps: Fps, sensors: Vec<SensorAxes>) -> ViewTake {
        let n = rig.len();
        let (joints, feet) = skeleton(&rig);
        let root = rig.joints()[0].offset;
        let rest = Animation::new(
            rig,
            fps,
            vec![vec![UnitQuaternion::identity()]; n],
            vec![true; n],
            vec![root],
        )
        .expect("a rig's rest pose is a valid one-frame animation");
        ViewTake {
            name: "live".into(),
            source: "imubake live".into(),
            fps,
            frames: 1,
            motion: Motion::Animation(Box::new(rest)),
            chunk_frames: 1,
            sensors,
            contacts: None,
            live: true,
            joints,
            feet,
        }
    }

    /// How many chunks the take is cut into.
    pub fn chunks(&self) -> usize {
        match self.motion {
            Motion::Glb(_) => 1,
            _ => (self.frames - 1).div_ceil(self.chunk_frames).max(1),
        }
    }

    /// The frames of chunk `k`, inclusive; `None` past the last chunk.
    pub fn chunk_window(&self, k: usize) -> Option<(usize, usize)> {
        if k >= self.chunks() {
            return None;
        }
        if let Motion::Glb(_) = self.motion {
            return Some((0, self.frames - 1));
        }
        let start = k * self.chunk_frames;
        Some((start, (start + self.chunk_frames).min(self.frames - 1)))
    }

    /// Chunk `k` as a GLB; `None` past the last chunk.
    pub fn chunk_glb(&self, k: usize) -> Option<Result<Vec<u8>, ViewError>> {
        let (start, end) = self.chunk_window(k)?;
        let fail = |reason: String| ViewError::Chunk { chunk: k, reason };
        let window = match &self.motion {
            Motion::Glb(bytes) => return Some(Ok(bytes.clone())),
            Motion::Animation(anim) => anim
                .window(start, end)
                .ok_or_else(|| fail("outside the take".into())),
            Motion::Bvh { bvh, units } => {
                Animation::from_bvh_window(bvh, &self.name, *units, self.fps, start..=end)
                    .map_err(|e| fail(e.to_string()))
            }
        };
        Some(window.and_then(|w| {
            crate::write::gltf::to_glb_from(&w, &self.name, start as u64)
                .map_err(|e| fail(e.to_string()))
        }))
    }

    /// `/take.json`.
    pub fn json(&self) -> TakeJson<'_> {
        TakeJson {
            name: &self.name,
            source: &self.source,
            fps: self.fps,
            frames: self.frames,
            chunk_frames: self.chunk_frames,
            chunks: self.chunks(),
            sensors: &self.sensors,
            contacts: &self.contacts,
            joints: &self.joints,
            feet: &self.feet,
            live: self.live,
            imubake_version: env!("CARGO_PKG_VERSION"),
        }
    }
}

/// At most [`MAX_JOINTS`] joints.
fn check_joints(path: &Path, joints: usize) -> Result<(), ViewError> {
    if joints > MAX_JOINTS {
        return Err(ViewError::input(
            path,
            format!(
                "its rig has {joints} joints; imubake view shows at most {MAX_JOINTS} (the glTF \
                 writer's limit)"
            ),
        ));
    }
    Ok(())
}

/// A rig's joint names and feet.
fn skeleton(rig: &Rig) -> (Vec<String>, Option<[String; 2]>) {
    let joints: Vec<String> = rig.joints().iter().map(|j| j.name.clone()).collect();
    let feet = crate::pipeline::root::foot_joints(rig)
        .map(|[l, r]| [joints[l].clone(), joints[r].clone()]);
    (joints, feet)
}

/// Frames per chunk: `chunk_s` seconds at `fps`, at least one.
fn chunk_frames(fps: Fps, chunk_s: f64) -> usize {
    ((chunk_s * fps.as_f64()).round() as usize).max(1)
}

fn read_sidecar(path: &Path) -> Result<Sidecar, ViewError> {
    let text = std::fs::read(path).map_err(|e| ViewError::input(path, e))?;
    serde_json::from_slice(&text)
        .map_err(|e| ViewError::input(path, format!("not an imubake sidecar ({e})")))
}

/// The sidecar beside a `.bvh` or `.glb` that lists it as an output, if any.
fn sidecar_beside(path: &Path) -> Option<(PathBuf, Sidecar)> {
    let dir = path.parent()?;
    let stem = path.file_stem()?.to_string_lossy();
    let file = path.file_name()?.to_string_lossy();
    let sidecar_path = dir.join(format!("{stem}{SIDECAR_SUFFIX}"));
    let sidecar = read_sidecar(&sidecar_path).ok()?;
    sidecar
        .outputs
        .iter()
        .any(|o| o.path == file)
        .then_some((sidecar_path, sidecar))
}

/// A BVH without a sidecar: centimetres when its rest pose is taller than 3 units (no body is 3 m
/// tall, every body is taller than 3 cm), else metres.
fn guess_units(bvh: &Bvh) -> LengthUnit {
    // The zero pose's joints (offsets summed down the tree): its largest span along any axis, as
    // a zero pose need not stand.
    let mut rest: Vec<nalgebra::Vector3<f64>> = Vec::with_capacity(bvh.joints().len());
    for j in bvh.joints() {
        let parent = j.parent.map_or(nalgebra::Vector3::zeros(), |p| rest[p]);
        rest.push(parent + j.offset);
    }
    let span = (0..3)
        .map(|axis| {
            let along = rest.iter().map(|p| p[axis]);
            along.clone().fold(f64::NEG_INFINITY, f64::max) - along.fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max);
    if span > 3.0 {
        LengthUnit::Centimetres
    } else {
        LengthUnit::Metres
    }
}

/// A GLB's frame rate and frame count, from its first animation's first sampler's key times,
/// and its first skin's joint names (checked to be a GLB whose JSON is glTF first).
fn glb_timing(bytes: &[u8]) -> Result<(Fps, usize, Vec<String>), String> {
    let word = |at: usize| -> Option<u32> {
        Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?))
    };
    if bytes.get(..4) != Some(b"glTF") || word(4) != Some(2) {
        return Err("not a binary glTF 2.0 file (no `glTF` version 2 header)".into());
    }
    if word(8).map(|n| n as usize) != Some(bytes.len()) {
        return Err("its header's length is not the file's (truncated?)".into());
    }
    let json_len = word(12).ok_or("no JSON chunk")? as usize;
    if word(16) != Some(0x4E4F_534A) {
        return Err("its first chunk is not JSON".into());
    }
    let json = bytes
        .get(20..20 + json_len)
        .ok_or("its JSON chunk runs past the end of the file")?;
    let root = gltf_json::Root::from_slice(json).map_err(|e| format!("its JSON: {e}"))?;
    let sampler = root
        .animations
        .first()
        .and_then(|a| a.samplers.first())
        .ok_or("it has no animation")?;
    let input = root
        .accessors
        .get(sampler.input.value())
        .ok_or("its animation's key times are missing")?;
    let frames = input.count.0 as usize;
    let last = input
        .max
        .as_ref()
        .and_then(|m| m.get(0).and_then(|v| v.as_f64()).or_else(|| m.as_f64()))
        .ok_or("its key times have no max")?;
    let first = input
        .min
        .as_ref()
        .and_then(|m| m.get(0).and_then(|v| v.as_f64()).or_else(|| m.as_f64()))
        .ok_or("its key times have no min")?;
    let fps = if frames > 1 {
        Fps::from_frame_time_s((last - first) / (frames - 1) as f64)
    } else {
        Fps::new(30, 1)
    }
    .ok_or("its key times are not a frame rate")?;
    let skin = root
        .skins
        .first()
        .ok_or("it has no skin (no skeleton to show)")?;
    let joints = skin
        .joints
        .iter()
        .map(|j| {
            root.nodes
                .get(j.value())
                .and_then(|n| n.name.clone())
                .unwrap_or_default()
        })
        .collect();
    Ok((fps, frames.max(1), joints))
}

/// The feet among joint names, as [`crate::pipeline::root::foot_joints`] finds them on a rig.
fn foot_names(joints: &[String]) -> Option<[String; 2]> {
    crate::pipeline::root::foot_names(joints.iter().map(String::as_str))
        .map(|[l, r]| [joints[l].clone(), joints[r].clone()])
}
