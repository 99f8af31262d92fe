//! glTF 2.0 writer: an [`Animation`] as a skinned skeleton with one animation, as a binary `.glb`
//! or as a `.gltf` JSON file with its `.bin` buffer.
//!
//! What is written (conventions.md: rig world Y-up, facing +Z; glTF is always metres):
//! - one node per rig joint, in rig order (node `i` is joint `i`), `translation` = the joint's
//!   offset in metres and no rotation (rest rotations are identity), children per hierarchy;
//! - a skin over all joints, `skeleton` = the root joint, `inverseBindMatrices` = the inverse of
//!   each joint's rest global transform (a pure translation by minus its rest position);
//! - a mesh bound to that skin so that viewers show the motion and Blender imports an armature:
//!   one octahedral bone shape (Blender's look) from each joint to each child, to the end site
//!   of a leaf, or for a leaf without end site a short continuation of its own offset; every
//!   vertex fully weighted to the joint whose rotation moves it. The mesh node is a sibling of the
//!   root joint in the scene and has no transform (the glTF rules for skinned meshes);
//! - one animation named after the take: a LINEAR rotation channel for the root and every
//!   animated joint, keys kept on the previous key's hemisphere, and a LINEAR translation channel
//!   for the root (root positions in metres), all sharing one time accessor t = n · den / num.
//!
//! Output is deterministic: identical input gives byte-identical files.
//!
//! Objects are named (nodes = joint names, animation and scene = take name, skin = rig name), so
//! importers show them (gltf-json's `names` feature).

use crate::anim::Animation;
#[cfg(doc)]
use crate::rotation::euler::make_hemisphere_continuous;
use gltf_json as json;
use json::validation::{Checked::Valid, USize64};
use nalgebra::{UnitQuaternion, Vector3};
use rayon::prelude::*;
use serde_json::Value;
use std::collections::BTreeMap;

/// Why a glTF file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum GltfWriteError {
    #[error(
        "frames {frame} and {next} fall on the same 32-bit float time ({time} s); glTF stores key \
         times as 32-bit floats, so the take is too long for its frame rate; split it or lower \
         the frame rate"
    )]
    TimePrecision {
        frame: usize,
        next: usize,
        time: f32,
    },
    #[error("the rig has {0} joints; the glTF writer supports at most 65536")]
    TooManyJoints(usize),
    #[error("the glTF file would be {0} bytes; a GLB file holds at most 4 GiB")]
    TooLarge(u64),
    #[error("serialising the glTF JSON failed: {0}")]
    Json(#[from] serde_json::Error),
}

/// The animation as a binary glTF (`.glb`): header, JSON chunk (padded with spaces), BIN chunk
/// (padded with zeros).
pub fn to_glb(anim: &Animation, name: &str) -> Result<Vec<u8>, GltfWriteError> {
    to_glb_from(anim, name, 0)
}

/// [`to_glb`] for a time window of a longer take: the animation's frame 0 is the take's frame
/// `first_frame`, so its keys stand at n · den / num for n = `first_frame` … (the viewer's
/// chunks; `Animation::window` makes the window).
pub fn to_glb_from(
    anim: &Animation,
    name: &str,
    first_frame: u64,
) -> Result<Vec<u8>, GltfWriteError> {
    let (head, chunk) = to_glb_parts(anim, name, first_frame)?;
    let mut out = Vec::with_capacity(head.len() + chunk.len());
    out.extend_from_slice(&head);
    chunk.write_to(&mut out).expect("writing to memory");
    Ok(out)
}

/// [`to_glb`] in two parts, to be written one after the other without assembling them in memory
/// (a long take's buffer is tens of megabytes): the header, the JSON chunk (padded with spaces)
/// and the BIN chunk's header; then the BIN chunk (padded with zeros; empty when there is no
/// buffer), whose rotation keys are made as it is written ([`Buffer::write_to`]).
pub fn to_glb_parts<'a>(
    anim: &'a Animation,
    name: &str,
    first_frame: u64,
) -> Result<(Vec<u8>, Buffer<'a>), GltfWriteError> {
    let (doc, mut chunk) = document(anim, name, None, first_frame)?;
    let mut json = serde_json::to_vec(&doc)?;
    pad_to_4(&mut json, b' ');
    chunk.pad();
    let total = 12
        + 8
        + json.len() as u64
        + if chunk.is_empty() {
            0
        } else {
            8 + chunk.len() as u64
        };
    if total > u64::from(u32::MAX) {
        return Err(GltfWriteError::TooLarge(total));
    }
    let mut head = Vec::with_capacity(json.len() + 28);
    head.extend_from_slice(b"glTF");
    head.extend_from_slice(&2u32.to_le_bytes());
    head.extend_from_slice(&(total as u32).to_le_bytes());
    head.extend_from_slice(&(json.len() as u32).to_le_bytes());
    head.extend_from_slice(b"JSON");
    head.extend_from_slice(&json);
    if !chunk.is_empty() {
        head.extend_from_slice(&(chunk.len() as u32).to_le_bytes());
        head.extend_from_slice(b"BIN\0");
    }
    debug_assert_eq!((head.len() + chunk.len()) as u64, total);
    Ok((head, chunk))
}

/// The animation as a `.gltf` JSON text and the bytes of its buffer, which the JSON refers to
/// as `bin_file_name` (a file name relative to the `.gltf`; percent-encoded in the URI).
pub fn to_gltf(
    anim: &Animation,
    name: &str,
    bin_file_name: &str,
) -> Result<(String, Vec<u8>), GltfWriteError> {
    let (doc, bin) = document(anim, name, Some(uri_encode(bin_file_name)), 0)?;
    let mut json = serde_json::to_string_pretty(&doc)?;
    json.push('\n');
    Ok((json, bin.to_vec()))
}

fn pad_to_4(bytes: &mut Vec<u8>, with: u8) {
    while !bytes.len().is_multiple_of(4) {
        bytes.push(with);
    }
}

/// Percent-encodes everything but RFC 3986 unreserved characters and `/`.
fn uri_encode(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~/".contains(&b) {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// The binary buffer as it is laid out, every view on a 4-byte boundary. Small views' bytes are
/// held; a rotation channel's keys (a long take's are most of the buffer: 16 bytes per joint per
/// frame) are only counted, and made when the buffer is written, a few joints at a time on every
/// core, so the whole buffer is never in memory at once.
pub struct Buffer<'a> {
    len: usize,
    parts: Vec<Part<'a>>,
}

enum Part<'a> {
    Bytes(Vec<u8>),
    /// A joint's local rotations, written as [`rotation_key_bytes`].
    Keys(&'a [UnitQuaternion<f64>]),
}

impl Part<'_> {
    /// Its length in the buffer, bytes.
    fn len(&self) -> usize {
        match self {
            Part::Bytes(bytes) => bytes.len(),
            // x, y, z, w as f32.
            Part::Keys(track) => 16 * track.len(),
        }
    }
}

impl<'a> Buffer<'a> {
    fn new() -> Buffer<'a> {
        Buffer {
            len: 0,
            parts: Vec::new(),
        }
    }

    /// Its length in bytes.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Zeros up to the next 4-byte boundary.
    fn pad(&mut self) {
        let pad = self.len.next_multiple_of(4) - self.len;
        if pad > 0 {
            self.push(Part::Bytes(vec![0; pad]));
        }
    }

    /// Appends `part`; where it starts.
    fn push(&mut self, part: Part<'a>) -> usize {
        let offset = self.len;
        self.len += part.len();
        self.parts.push(part);
        offset
    }

    /// Writes the buffer's bytes: the held ones as they are, the rotation keys made on every core
    /// a few joints at a time (so that only those are held) and written in order.
    pub fn write_to(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        let threads = rayon::current_num_threads().max(1);
        let mut parts = self.parts.iter().peekable();
        while let Some(part) = parts.next() {
            match part {
                Part::Bytes(bytes) => w.write_all(bytes)?,
                Part::Keys(first) => {
                    let mut group = vec![*first];
                    while group.len() < threads
                        && let Some(Part::Keys(next)) = parts.peek()
                    {
                        group.push(*next);
                        parts.next();
                    }
                    let keys: Vec<Vec<u8>> = group
                        .par_iter()
                        .map(|track| rotation_key_bytes(track))
                        .collect();
                    for bytes in keys {
                        w.write_all(&bytes)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// The buffer's bytes in memory.
    pub fn to_vec(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.len);
        self.write_to(&mut out).expect("writing to memory");
        out
    }

    fn view(
        &mut self,
        root: &mut json::Root,
        part: Part<'a>,
        target: Option<json::buffer::Target>,
    ) -> json::Index<json::buffer::View> {
        self.pad();
        let len = part.len();
        let offset = self.push(part);
        root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(len),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
            name: None,
        })
    }

    /// A view holding `count` elements of `type_` / `component` and an accessor over all of it.
    #[allow(clippy::too_many_arguments)]
    fn accessor(
        &mut self,
        root: &mut json::Root,
        part: Part<'a>,
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        target: Option<json::buffer::Target>,
        min_max: Option<(Value, Value)>,
    ) -> json::Index<json::Accessor> {
        let view = self.view(root, part, target);
        let (min, max) = match min_max {
            Some((min, max)) => (Some(min), Some(max)),
            None => (None, None),
        };
        root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min,
            max,
            normalized: false,
            sparse: None,
            name: None,
        })
    }
}

fn f32_bytes(values: impl IntoIterator<Item = f32>) -> Vec<u8> {
    let values = values.into_iter();
    let mut out = Vec::with_capacity(4 * values.size_hint().0);
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Per-component min and max as JSON arrays. An f32 widened to f64 is exact, and serde_json
/// writes an f64 so that it parses back to the same f64, so min/max equal the stored data
/// exactly (the validator compares them).
fn min_max<const N: usize>(items: &[[f32; N]]) -> (Value, Value) {
    let mut min = [f32::INFINITY; N];
    let mut max = [f32::NEG_INFINITY; N];
    for item in items {
        for c in 0..N {
            min[c] = min[c].min(item[c]);
            max[c] = max[c].max(item[c]);
        }
    }
    let arr = |v: [f32; N]| Value::Array(v.iter().map(|&x| Value::from(f64::from(x))).collect());
    (arr(min), arr(max))
}

/// The keys of one rotation track in glTF order x, y, z, w as little-endian `f32` bytes, each on
/// the previous key's hemisphere (sign flipped when its dot product with the previous key, as
/// written, is negative: [`make_hemisphere_continuous`]), so LINEAR interpolation takes the short
/// way.
fn rotation_key_bytes(track: &[UnitQuaternion<f64>]) -> Vec<u8> {
    let mut out = Vec::with_capacity(16 * track.len());
    let mut previous: Option<nalgebra::Vector4<f64>> = None;
    for q in track {
        let mut c = q.coords;
        if previous.is_some_and(|p| c.dot(&p) < 0.0) {
            c = -c;
        }
        previous = Some(c);
        // nalgebra stores a quaternion's coordinates as (i, j, k, w) = glTF's x, y, z, w.
        for v in [c.x, c.y, c.z, c.w] {
            out.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    out
}

/// The bone shapes of the skinned mesh, in the rest pose, metres.
struct BoneMesh {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    joints: Vec<u16>,
}

/// Blender's octahedral bone from `head` to `tail`: a square ring at 10 % of the length with a
/// half-width of 10 % of the length; 8 flat-shaded triangles, counter-clockwise seen from outside.
fn push_bone(mesh: &mut BoneMesh, joint: u16, head: Vector3<f64>, tail: Vector3<f64>) {
    let d = tail - head;
    let length = d.norm();
    if length < 1e-9 {
        return;
    }
    let axis = d / length;
    // The world axis least aligned with the bone gives a stable perpendicular.
    let helper = (0..3)
        .map(|i| Vector3::ith(i, 1.0))
        .min_by(|a: &Vector3<f64>, b| axis.dot(a).abs().total_cmp(&axis.dot(b).abs()))
        .unwrap_or_else(Vector3::x);
    let u = axis.cross(&helper).normalize();
    let v = axis.cross(&u);
    let centre = head + axis * (0.1 * length);
    let r = 0.1 * length;
    let ring = [
        centre + u * r,
        centre + v * r,
        centre - u * r,
        centre - v * r,
    ];
    for k in 0..4 {
        let (a, b) = (ring[k], ring[(k + 1) % 4]);
        for apex in [head, tail] {
            let (mut p1, mut p2) = (a, b);
            let mut n = (p1 - apex).cross(&(p2 - apex));
            // `centre` is inside the solid, so the outward normal points away from it.
            if n.dot(&((apex + p1 + p2) / 3.0 - centre)) < 0.0 {
                std::mem::swap(&mut p1, &mut p2);
                n = -n;
            }
            let n = n.normalize();
            for p in [apex, p1, p2] {
                mesh.positions.push([p.x as f32, p.y as f32, p.z as f32]);
                mesh.normals.push([n.x as f32, n.y as f32, n.z as f32]);
                mesh.joints.push(joint);
            }
        }
    }
}

fn bone_mesh(anim: &Animation, rest: &[Vector3<f64>], metres: f64) -> BoneMesh {
    let rig = anim.rig();
    let mut mesh = BoneMesh {
        positions: Vec::new(),
        normals: Vec::new(),
        joints: Vec::new(),
    };
    for (j, joint) in rig.joints().iter().enumerate() {
        let head = rest[j];
        let mut children = rig.children(j).peekable();
        let leaf = children.peek().is_none();
        for c in children {
            push_bone(&mut mesh, j as u16, head, rest[c]);
        }
        if let Some(end) = joint.end_site {
            push_bone(&mut mesh, j as u16, head, head + end * metres);
        } else if leaf {
            // No end site: continue the joint's own direction by half its offset (at least 5 cm),
            // so the leaf still shows; a lone root or a zero offset gets 10 cm straight up.
            let offset = joint.offset * metres;
            let tail = if offset.norm() > 1e-9 && joint.parent.is_some() {
                head + offset.normalize() * (0.5 * offset.norm()).max(0.05)
            } else {
                head + Vector3::y() * 0.1
            };
            push_bone(&mut mesh, j as u16, head, tail);
        }
    }
    mesh
}

/// Frame times n · den / num (n from `first_frame`) as f32, refused when two frames fall on the
/// same f32 (glTF wants strictly increasing key times).
fn key_times(anim: &Animation, first_frame: u64) -> Result<Vec<f32>, GltfWriteError> {
    let times: Vec<f32> = (0..anim.frames() as u64)
        .map(|n| anim.fps().frame_time_of(first_frame + n) as f32)
        .collect();
    strictly_increasing(&times)?;
    Ok(times)
}

fn strictly_increasing(times: &[f32]) -> Result<(), GltfWriteError> {
    match (1..times.len()).find(|&n| times[n] <= times[n - 1]) {
        Some(n) => Err(GltfWriteError::TimePrecision {
            frame: n - 1,
            next: n,
            time: times[n],
        }),
        None => Ok(()),
    }
}

/// The glTF document and its binary buffer.
fn document<'a>(
    anim: &'a Animation,
    name: &str,
    buffer_uri: Option<String>,
    first_frame: u64,
) -> Result<(json::Root, Buffer<'a>), GltfWriteError> {
    use json::accessor::{ComponentType as C, Type as T};
    use json::buffer::Target;

    let rig = anim.rig();
    let joints = rig.joints();
    if joints.len() > 65536 {
        return Err(GltfWriteError::TooManyJoints(joints.len()));
    }
    let metres = rig.units().metres_per_unit();
    let rest: Vec<Vector3<f64>> = rig.rest_positions().iter().map(|p| p * metres).collect();

    let times = key_times(anim, first_frame)?;

    let mut root = json::Root {
        asset: json::Asset {
            generator: Some(format!("imubake {}", env!("CARGO_PKG_VERSION"))),
            ..Default::default()
        },
        ..Default::default()
    };
    let mut bin = Buffer::new();

    // Joint nodes: node i is joint i.
    for (j, joint) in joints.iter().enumerate() {
        let t = joint.offset * metres;
        let children: Vec<json::Index<json::Node>> = rig
            .children(j)
            .map(|c| json::Index::new(c as u32))
            .collect();
        root.push(json::Node {
            translation: Some([t.x as f32, t.y as f32, t.z as f32]),
            children: (!children.is_empty()).then_some(children),
            name: Some(joint.name.clone()),
            ..Default::default()
        });
    }

    // Skin.
    let ibm: Vec<f32> = rest
        .iter()
        .flat_map(|p| {
            // Column-major inverse of translate(p).
            let (x, y, z) = (p.x as f32, p.y as f32, p.z as f32);
            [
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -x, -y, -z, 1.0,
            ]
        })
        .collect();
    let ibm = bin.accessor(
        &mut root,
        Part::Bytes(f32_bytes(ibm)),
        joints.len(),
        C::F32,
        T::Mat4,
        None,
        None,
    );
    let skin = root.push(json::Skin {
        inverse_bind_matrices: Some(ibm),
        joints: (0..joints.len() as u32).map(json::Index::new).collect(),
        skeleton: Some(json::Index::new(0)),
        extensions: None,
        extras: Default::default(),
        name: Some(rig.name().to_string()),
    });

    // Bone mesh.
    let mesh = bone_mesh(anim, &rest, metres);
    let count = mesh.positions.len();
    let position = bin.accessor(
        &mut root,
        Part::Bytes(f32_bytes(mesh.positions.iter().flatten().copied())),
        count,
        C::F32,
        T::Vec3,
        Some(Target::ArrayBuffer),
        Some(min_max(&mesh.positions)),
    );
    let normal = bin.accessor(
        &mut root,
        Part::Bytes(f32_bytes(mesh.normals.iter().flatten().copied())),
        count,
        C::F32,
        T::Vec3,
        Some(Target::ArrayBuffer),
        None,
    );
    let (joint_bytes, joint_type): (Vec<u8>, _) = if joints.len() <= 256 {
        (
            mesh.joints
                .iter()
                .flat_map(|&j| [j as u8, 0, 0, 0])
                .collect(),
            C::U8,
        )
    } else {
        (
            mesh.joints
                .iter()
                .flat_map(|&j| [j, 0, 0, 0])
                .flat_map(u16::to_le_bytes)
                .collect(),
            C::U16,
        )
    };
    let joint_acc = bin.accessor(
        &mut root,
        Part::Bytes(joint_bytes),
        count,
        joint_type,
        T::Vec4,
        Some(Target::ArrayBuffer),
        None,
    );
    let weights = f32_bytes((0..count).flat_map(|_| [1.0, 0.0, 0.0, 0.0]));
    let weight_acc = bin.accessor(
        &mut root,
        Part::Bytes(weights),
        count,
        C::F32,
        T::Vec4,
        Some(Target::ArrayBuffer),
        None,
    );
    // 65535 is the primitive restart value, so 16-bit indices stop below it.
    let (index_bytes, index_type): (Vec<u8>, _) = if count < 65535 {
        (
            (0..count as u16).flat_map(u16::to_le_bytes).collect(),
            C::U16,
        )
    } else {
        (
            (0..count as u32).flat_map(u32::to_le_bytes).collect(),
            C::U32,
        )
    };
    let indices = bin.accessor(
        &mut root,
        Part::Bytes(index_bytes),
        count,
        index_type,
        T::Scalar,
        Some(Target::ElementArrayBuffer),
        None,
    );
    let material = root.push(json::Material {
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            base_color_factor: json::material::PbrBaseColorFactor([0.8, 0.8, 0.8, 1.0]),
            metallic_factor: json::material::StrengthFactor(0.0),
            roughness_factor: json::material::StrengthFactor(0.6),
            ..Default::default()
        },
        name: Some("bone".to_string()),
        ..Default::default()
    });
    let mut attributes = BTreeMap::new();
    attributes.insert(Valid(json::mesh::Semantic::Positions), position);
    attributes.insert(Valid(json::mesh::Semantic::Normals), normal);
    attributes.insert(Valid(json::mesh::Semantic::Joints(0)), joint_acc);
    attributes.insert(Valid(json::mesh::Semantic::Weights(0)), weight_acc);
    let mesh_index = root.push(json::Mesh {
        primitives: vec![json::mesh::Primitive {
            attributes,
            indices: Some(indices),
            material: Some(material),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
            extensions: None,
            extras: Default::default(),
        }],
        weights: None,
        extensions: None,
        extras: Default::default(),
        name: Some(format!("{} bones", rig.name())),
    });
    let mesh_node = root.push(json::Node {
        mesh: Some(mesh_index),
        skin: Some(skin),
        name: Some(format!("{} bones", rig.name())),
        ..Default::default()
    });

    let scene = root.push(json::Scene {
        nodes: vec![json::Index::new(0), mesh_node],
        extensions: None,
        extras: Default::default(),
        name: Some(name.to_string()),
    });
    root.scene = Some(scene);

    // Animation.
    let input = {
        let (min, max) = min_max(&times.iter().map(|&t| [t]).collect::<Vec<_>>());
        bin.accessor(
            &mut root,
            Part::Bytes(f32_bytes(times.iter().copied())),
            times.len(),
            C::F32,
            T::Scalar,
            None,
            Some((min, max)),
        )
    };
    let mut channels = Vec::new();
    let mut samplers = Vec::new();
    let mut channel =
        |root: &mut json::Root, bin: &mut Buffer<'a>, node: usize, path, part: Part<'a>, type_| {
            let output = bin.accessor(root, part, times.len(), C::F32, type_, None, None);
            let sampler = json::Index::push(
                &mut samplers,
                json::animation::Sampler {
                    input,
                    interpolation: Valid(json::animation::Interpolation::Linear),
                    output,
                    extensions: None,
                    extras: Default::default(),
                },
            );
            channels.push(json::animation::Channel {
                sampler,
                target: json::animation::Target {
                    node: json::Index::new(node as u32),
                    path: Valid(path),
                    extensions: None,
                    extras: Default::default(),
                },
                extensions: None,
                extras: Default::default(),
            });
        };
    // The root's position, and the joints with an animated translation (`--in-place` hips).
    let root_track = (0, anim.root_positions());
    let moving =
        std::iter::once(root_track).chain(anim.translations().iter().map(|(j, t)| (*j, &t[..])));
    for (j, track) in moving {
        let bytes = f32_bytes(track.iter().flat_map(|p| {
            let p = p * metres;
            [p.x as f32, p.y as f32, p.z as f32]
        }));
        channel(
            &mut root,
            &mut bin,
            j,
            json::animation::Property::Translation,
            Part::Bytes(bytes),
            T::Vec3,
        );
    }
    // The joints' rotations, in joint order; their keys are made when the buffer is written.
    for j in (0..joints.len()).filter(|&j| j == 0 || anim.is_animated(j)) {
        channel(
            &mut root,
            &mut bin,
            j,
            json::animation::Property::Rotation,
            Part::Keys(anim.local(j)),
            T::Vec4,
        );
    }
    // Foot contacts as per-frame 0/1 curves on the animation's own frames (frame n at n / fps,
    // from `first_frame` when not 0), for engines and IK setups that pin feet.
    let extras = anim.contacts().map(|c| {
        let curve = |side: usize| c.iter().map(|f| u8::from(f[side])).collect::<Vec<_>>();
        let mut value = serde_json::json!({"imubake": {"contacts": {
            "fps": anim.fps().as_f64(),
            "left": curve(0),
            "right": curve(1),
        }}});
        if first_frame > 0 {
            value["imubake"]["contacts"]["first_frame"] = first_frame.into();
        }
        serde_json::value::to_raw_value(&value).expect("plain JSON")
    });
    root.push(json::Animation {
        channels,
        samplers,
        extensions: None,
        extras,
        name: Some(name.to_string()),
    });

    root.push(json::Buffer {
        byte_length: USize64::from(bin.len()),
        uri: buffer_uri,
        extensions: None,
        extras: Default::default(),
        name: None,
    });
    Ok((root, bin))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fps::Fps;
    use crate::rig::load_rig;

    /// Mixamo rig, 300 frames at 29.97: the root and a few joints spin through several turns.
    fn spinning(frames: usize) -> Animation {
        let rig = load_rig("mixamo").unwrap();
        let n = rig.len();
        let spin = ["Hips", "LeftArm", "RightForeArm", "Head"].map(|j| rig.joint_index(j).unwrap());
        let mut local = vec![Vec::with_capacity(frames); n];
        let mut roots = Vec::with_capacity(frames);
        for f in 0..frames {
            let t = f as f64 / 30.0;
            for (j, track) in local.iter_mut().enumerate() {
                let q = if spin.contains(&j) {
                    let axis =
                        nalgebra::Unit::new_normalize(Vector3::new(0.3, 1.0, 0.2 * j as f64));
                    UnitQuaternion::from_axis_angle(&axis, 3.0 * t * (1.0 + j as f64 * 0.1))
                } else {
                    UnitQuaternion::identity()
                };
                // Canonical w ≥ 0, as Euler conversions produce: the sign jumps each half turn.
                track.push(if q.w < 0.0 {
                    UnitQuaternion::new_unchecked(-q.into_inner())
                } else {
                    q
                });
            }
            roots.push(Vector3::new(0.1 * t, 1.0, 0.5 * t));
        }
        let animated = (0..n).map(|j| spin.contains(&j)).collect();
        Animation::new(rig, Fps::new(30000, 1001).unwrap(), local, animated, roots).unwrap()
    }

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    /// (JSON, BIN) chunks of a GLB, checking the container.
    fn chunks(glb: &[u8]) -> (Value, Vec<u8>) {
        assert_eq!(&glb[0..4], b"glTF");
        assert_eq!(u32_at(glb, 4), 2);
        assert_eq!(u32_at(glb, 8) as usize, glb.len());
        let json_len = u32_at(glb, 12) as usize;
        assert_eq!(&glb[16..20], b"JSON");
        assert_eq!(json_len % 4, 0);
        let json = &glb[20..20 + json_len];
        let bin_at = 20 + json_len;
        let bin_len = u32_at(glb, bin_at) as usize;
        assert_eq!(bin_len % 4, 0);
        assert_eq!(&glb[bin_at + 4..bin_at + 8], b"BIN\0");
        assert_eq!(bin_at + 8 + bin_len, glb.len());
        (
            serde_json::from_slice(json).unwrap(),
            glb[bin_at + 8..].to_vec(),
        )
    }

    fn floats(doc: &Value, bin: &[u8], accessor: usize) -> Vec<f32> {
        let acc = &doc["accessors"][accessor];
        assert_eq!(acc["componentType"], 5126);
        let view = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let start = view["byteOffset"].as_u64().unwrap() as usize;
        let len = view["byteLength"].as_u64().unwrap() as usize;
        bin[start..start + len]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    #[test]
    fn glb_container_is_well_formed_and_parses_with_gltf_json() {
        let anim = spinning(300);
        let glb = to_glb(&anim, "spin").unwrap();
        let (doc, bin) = chunks(&glb);
        let json_len = u32_at(&glb, 12) as usize;
        // JSON padding is spaces.
        let json = &glb[20..20 + json_len];
        let text_end = json.iter().rposition(|&b| b == b'}').unwrap();
        assert!(json[text_end + 1..].iter().all(|&b| b == b' '));
        assert!(json.len() - text_end - 1 < 4);
        let byte_length = doc["buffers"][0]["byteLength"].as_u64().unwrap() as usize;
        assert!(bin.len() >= byte_length && bin.len() - byte_length < 4);
        assert!(bin[byte_length..].iter().all(|&b| b == 0));
        assert!(doc["buffers"][0].get("uri").is_none());
        for view in doc["bufferViews"].as_array().unwrap() {
            assert_eq!(view["byteOffset"].as_u64().unwrap() % 4, 0, "{view}");
            assert!(view.get("byteStride").is_none());
        }
        let root = json::Root::from_slice(json).expect("gltf-json parses our JSON");
        let mut errors = Vec::new();
        json::validation::Validate::validate(&root, &root, json::Path::new, &mut |path, err| {
            errors.push(format!("{}: {err}", path()))
        });
        assert!(errors.is_empty(), "{errors:?}");
        assert_eq!(root.nodes.len(), anim.rig().len() + 1);
        assert_eq!(
            doc["asset"]["generator"],
            format!("imubake {}", env!("CARGO_PKG_VERSION"))
        );
        assert_eq!(doc["asset"]["version"], "2.0");
        assert_eq!(doc["animations"][0]["name"], "spin");
        assert_eq!(doc["nodes"][0]["name"], "Hips");
        assert_eq!(
            doc["skins"][0]["joints"].as_array().unwrap().len(),
            anim.rig().len()
        );
    }

    #[test]
    fn accessor_counts_and_time_range() {
        let anim = spinning(300);
        let (doc, bin) = chunks(&to_glb(&anim, "spin").unwrap());
        let animation = &doc["animations"][0];
        let animated = (0..anim.rig().len())
            .filter(|&j| j == 0 || anim.is_animated(j))
            .count();
        assert_eq!(
            animation["channels"].as_array().unwrap().len(),
            animated + 1
        );
        let input = animation["samplers"][0]["input"].as_u64().unwrap() as usize;
        for s in animation["samplers"].as_array().unwrap() {
            assert_eq!(
                s["input"].as_u64().unwrap() as usize,
                input,
                "one shared time accessor"
            );
            assert_eq!(s["interpolation"], "LINEAR");
            assert_eq!(
                doc["accessors"][s["output"].as_u64().unwrap() as usize]["count"],
                300
            );
        }
        let acc = &doc["accessors"][input];
        assert_eq!(acc["count"], 300);
        let times = floats(&doc, &bin, input);
        assert_eq!(times[0], 0.0);
        assert_eq!(times[299], (299.0 * 1001.0 / 30000.0) as f32);
        assert_eq!(acc["min"][0].as_f64(), Some(0.0));
        assert_eq!(acc["max"][0].as_f64(), Some(f64::from(times[299])));
        assert!(times.windows(2).all(|w| w[1] > w[0]));
        // Mesh: one count over all attributes and indices, POSITION with min/max.
        let prim = &doc["meshes"][0]["primitives"][0];
        let count =
            doc["accessors"][prim["attributes"]["POSITION"].as_u64().unwrap() as usize]["count"]
                .clone();
        for a in ["NORMAL", "JOINTS_0", "WEIGHTS_0"] {
            assert_eq!(
                doc["accessors"][prim["attributes"][a].as_u64().unwrap() as usize]["count"],
                count
            );
        }
        assert_eq!(
            doc["accessors"][prim["indices"].as_u64().unwrap() as usize]["count"],
            count
        );
        let pos = &doc["accessors"][prim["attributes"]["POSITION"].as_u64().unwrap() as usize];
        assert!(pos["min"].is_array() && pos["max"].is_array());
        let normals = floats(
            &doc,
            &bin,
            prim["attributes"]["NORMAL"].as_u64().unwrap() as usize,
        );
        for n in normals.chunks_exact(3) {
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-6);
        }
        let ibm = floats(
            &doc,
            &bin,
            doc["skins"][0]["inverseBindMatrices"].as_u64().unwrap() as usize,
        );
        assert_eq!(ibm.len(), 16 * anim.rig().len());
        let rest = anim.rig().rest_positions();
        assert_eq!(
            ibm[16 * 5 + 12..16 * 5 + 15],
            [-rest[5].x as f32, -rest[5].y as f32, -rest[5].z as f32]
        );
    }

    #[test]
    fn rotation_keys_stay_on_one_hemisphere_and_match_the_animation() {
        let anim = spinning(300);
        let (doc, bin) = chunks(&to_glb(&anim, "spin").unwrap());
        let animation = &doc["animations"][0];
        let mut flips_needed = 0;
        for ch in animation["channels"].as_array().unwrap() {
            if ch["target"]["path"] != "rotation" {
                continue;
            }
            let node = ch["target"]["node"].as_u64().unwrap() as usize;
            let sampler = &animation["samplers"][ch["sampler"].as_u64().unwrap() as usize];
            let keys = floats(&doc, &bin, sampler["output"].as_u64().unwrap() as usize);
            let keys: Vec<&[f32]> = keys.chunks_exact(4).collect();
            for (f, k) in keys.iter().enumerate() {
                let q = anim.local(node)[f];
                let dot =
                    k[0] as f64 * q.i + k[1] as f64 * q.j + k[2] as f64 * q.k + k[3] as f64 * q.w;
                assert!((dot.abs() - 1.0).abs() < 1e-6, "same rotation, either sign");
                if f > 0 {
                    let prev = keys[f - 1];
                    let d: f32 = (0..4).map(|c| prev[c] * k[c]).sum();
                    assert!(d >= 0.0, "node {node} frame {f}");
                    let source = anim.local(node)[f - 1].coords.dot(&q.coords);
                    if source < 0.0 {
                        flips_needed += 1;
                    }
                }
            }
        }
        assert!(flips_needed > 0, "the test animation exercises sign flips");
    }

    #[test]
    fn output_is_deterministic_and_gltf_matches_glb() {
        let anim = spinning(120);
        assert_eq!(
            to_glb(&anim, "a").unwrap(),
            to_glb(&anim.clone(), "a").unwrap()
        );
        let (json1, bin1) = to_gltf(&anim, "a", "a take.bin").unwrap();
        let (json2, bin2) = to_gltf(&anim, "a", "a take.bin").unwrap();
        assert_eq!((&json1, &bin1), (&json2, &bin2));
        let doc: Value = serde_json::from_str(&json1).unwrap();
        assert_eq!(doc["buffers"][0]["uri"], "a%20take.bin");
        assert_eq!(
            doc["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
            bin1.len()
        );
        let (glb_doc, glb_bin) = chunks(&to_glb(&anim, "a").unwrap());
        assert_eq!(&glb_bin[..bin1.len()], &bin1[..]);
        assert_eq!(doc["accessors"], glb_doc["accessors"]);
    }

    #[test]
    fn centimetre_rigs_are_written_in_metres() {
        let anim = spinning(30);
        let rig = anim.rig();
        let joints = rig
            .joints()
            .iter()
            .map(|j| crate::rig::Joint {
                offset: j.offset * 100.0,
                end_site: j.end_site.map(|e| e * 100.0),
                ..j.clone()
            })
            .collect();
        let cm_rig =
            crate::rig::Rig::new("mixamo", crate::rig::LengthUnit::Centimetres, joints).unwrap();
        let cm = Animation::new(
            cm_rig,
            anim.fps(),
            (0..rig.len()).map(|j| anim.local(j).to_vec()).collect(),
            (0..rig.len()).map(|j| anim.is_animated(j)).collect(),
            anim.root_positions().iter().map(|p| p * 100.0).collect(),
        )
        .unwrap();
        let (m_doc, m_bin) = chunks(&to_glb(&anim, "t").unwrap());
        let (cm_doc, cm_bin) = chunks(&to_glb(&cm, "t").unwrap());
        for (a, b) in m_doc["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .zip(cm_doc["nodes"].as_array().unwrap())
        {
            for c in 0..3 {
                let (a, b) = (
                    a["translation"][c].as_f64().unwrap_or(0.0),
                    b["translation"][c].as_f64().unwrap_or(0.0),
                );
                assert!((a - b).abs() < 1e-6, "{a} {b}");
            }
        }
        // Every float in the buffer (IBMs, mesh, times, translations, rotations) agrees.
        assert_eq!(m_bin.len(), cm_bin.len());
        for (a, b) in m_bin.chunks_exact(4).zip(cm_bin.chunks_exact(4)) {
            let (a, b) = (
                f32::from_le_bytes(a.try_into().unwrap()),
                f32::from_le_bytes(b.try_into().unwrap()),
            );
            assert!(
                (a - b).abs() < 1e-6 || a.to_bits() == b.to_bits(),
                "{a} {b}"
            );
        }
    }

    #[test]
    fn single_frame_and_too_long_takes() {
        let rig = load_rig("mixamo").unwrap();
        let n = rig.len();
        let one = Animation::new(
            rig.clone(),
            Fps::new(30, 1).unwrap(),
            vec![vec![UnitQuaternion::identity()]; n],
            vec![false; n],
            vec![Vector3::new(0.0, 1.0, 0.0)],
        )
        .unwrap();
        let (doc, _) = chunks(&to_glb(&one, "one").unwrap());
        assert_eq!(
            doc["animations"][0]["channels"].as_array().unwrap().len(),
            2
        );

        // At 100 000 fps, frames 30 000 000 and 30 000 001 (300 s) share one f32 time.
        let fps = Fps::new(100_000, 1).unwrap();
        let late = [
            fps.frame_time_of(30_000_000) as f32,
            fps.frame_time_of(30_000_001) as f32,
        ];
        assert!(matches!(
            strictly_increasing(&late),
            Err(GltfWriteError::TimePrecision { .. })
        ));
        assert!(strictly_increasing(&[0.0, 0.5, 1.0]).is_ok());
    }
}
