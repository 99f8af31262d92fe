//! Motion on one skeleton onto another rig: any suit's BVH (SlimeVR, Rokoko, Noitom Axis,
//! mocopi, CMU) on a game rig, and Xsens's own segments ([`mvnx_animation`]) as a skeleton of
//! their own. A source is a [`SourceMotion`] (a BVH's forward kinematics, or an animation's).
//!
//! Each mapped source joint s drives one target bone j (same anatomical part,
//! [`crate::rig::names`], or a bone map). With S_s(t) the source joint's world rotation (the
//! BVH's forward kinematics, rig world: Y up) and R_s its world rotation in the reference pose
//! (the BVH's rest — every channel zero — or frame N), the change since the reference is
//!
//! ```text
//! D_s(t) = S_s(t) ⊗ R_s⁻¹
//! ```
//!
//! and the target bone turns by the same change from its own rest: W_j(t) = D_s(t) ⊗ W_j(rest),
//! with W_j(rest) = 1 (a rig's rest rotations are the identity). A target bone without a source
//! keeps its rest rotation relative to its parent (W_j = W_parent). Local rotations follow:
//! L_j = W_parent(j)⁻¹ ⊗ W_j.
//!
//! The root position is the source root's, scaled by the ratio of hip heights, k = h_target /
//! h_source (h: the root's rest height above the rest pose's lowest point, end sites included),
//! on the target's floor: p(t) = k · p_s(t) + (0, floor_target, 0). The source's floor is taken
//! as its world's y = 0 (BVH's convention, and Blender's import).
//!
//! Frames are resampled to the output rate: frame n at n / fps reads the source at t · fps_source,
//! between two frames by slerp (rotations) and linear interpolation (the root).

use crate::anim::{Animation, AnimationError};
use crate::bvh::Bvh;
use crate::fps::Fps;
use crate::rig::Rig;
use crate::rotation::quat::slerp_shortest;
use nalgebra::{UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// The source pose the changes are measured from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Reference {
    /// The BVH's rest pose: every channel zero.
    #[default]
    Rest,
    /// A frame of the take (0-based).
    Frame(usize),
}

impl FromStr for Reference {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "rest" => Ok(Reference::Rest),
            other => other
                .strip_prefix("frame:")
                .and_then(|n| n.parse().ok())
                .map(Reference::Frame)
                .ok_or_else(|| format!("`{s}`: expected `rest` or `frame:N` (0-based)")),
        }
    }
}

impl std::fmt::Display for Reference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Reference::Rest => f.write_str("rest"),
            Reference::Frame(n) => write!(f, "frame:{n}"),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RetargetError {
    #[error(
        "no bone of the rig `{rig}` has the anatomical part of a joint of the BVH ({joints}); give a bone map (--bone-map)"
    )]
    NothingMapped { rig: String, joints: String },
    #[error("the reference frame {frame} is past the take's last frame {last}")]
    ReferenceFrame { frame: usize, last: usize },
    #[error("the BVH has no frames")]
    NoFrames,
    #[error("MVNX segments: {0}")]
    Segments(String),
    #[error("{path}: {reason}")]
    BoneMap { path: PathBuf, reason: String },
    #[error(transparent)]
    Animation(#[from] AnimationError),
}

/// `(source joint, target joint)` pairs from a bone map file: `{"bones": {"<source joint>":
/// "<target bone, or a canonical part such as LeftArm>"}}` (a flat object works too), the
/// Blender add-on's format. Every source joint and target bone must exist.
pub fn load_bone_map(
    path: &Path,
    source: &[&str],
    target: &[&str],
) -> Result<Vec<(usize, usize)>, RetargetError> {
    let fail = |reason: String| RetargetError::BoneMap {
        path: path.to_path_buf(),
        reason,
    };
    let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| fail(format!("not JSON: {e}")))?;
    let bones = value.get("bones").unwrap_or(&value);
    let bones = bones
        .as_object()
        .ok_or_else(|| fail(r#"expected {"bones": {"source joint": "target bone", …}}"#.into()))?;
    let parts = crate::rig::names::match_joints(target.iter().copied());
    let mut pairs = Vec::with_capacity(bones.len());
    for (s, t) in bones {
        let t = t
            .as_str()
            .ok_or_else(|| fail(format!("the target of `{s}` is not a bone name")))?;
        let si = source.iter().position(|n| n == s).ok_or_else(|| {
            fail(format!(
                "source joint `{s}` is not in the BVH (it has: {})",
                source.join(", ")
            ))
        })?;
        let ti = target
            .iter()
            .position(|n| *n == t)
            .or_else(|| parts.iter().find(|(p, _)| *p == t).map(|(_, i)| *i))
            .ok_or_else(|| fail(format!("target bone `{t}` is not in the rig")))?;
        if pairs.iter().any(|&(_, other)| other == ti) {
            return Err(fail(format!("two source joints drive `{}`", target[ti])));
        }
        pairs.push((si, ti));
    }
    Ok(pairs)
}

/// A skeleton's motion, as retargeting reads it: each joint's world rotation per frame (rig
/// world axes: Y up), the root's position, the hips' rest height above the rest pose's lowest
/// point (in the source's units) and the rate.
#[derive(Debug, Clone)]
pub struct SourceMotion {
    pub names: Vec<String>,
    pub fps: Fps,
    /// `world[frame][joint]`: q_world_joint.
    pub world: Vec<Vec<UnitQuaternion<f64>>>,
    /// The root joint's position per frame, source units; the floor is y = 0.
    pub roots: Vec<Vector3<f64>>,
    pub hip_height: f64,
}

impl SourceMotion {
    /// A BVH file's motion (its forward kinematics), at `fps` (its `Frame Time`'s rate).
    pub fn of_bvh(bvh: &Bvh, fps: Fps) -> SourceMotion {
        let (rest, lowest) = rest_heights(bvh);
        let mut world = Vec::with_capacity(bvh.frame_count());
        let mut roots = Vec::with_capacity(bvh.frame_count());
        for n in 0..bvh.frame_count() {
            let translations = bvh.joint_translations(n);
            world.push(
                bvh.forward_kinematics(&bvh.local_rotations(n), &translations)
                    .1,
            );
            roots.push(translations[0]);
        }
        SourceMotion {
            names: bvh.joints().iter().map(|j| j.name.clone()).collect(),
            fps,
            world,
            roots,
            hip_height: rest.first().map_or(0.0, |r| r.y) - lowest,
        }
    }

    /// An animation's motion on its own rig.
    pub fn of_animation(anim: &Animation) -> SourceMotion {
        let rig = anim.rig();
        SourceMotion {
            names: rig.joints().iter().map(|j| j.name.clone()).collect(),
            fps: anim.fps(),
            world: (0..anim.frames())
                .map(|n| rig.world_rotations(&anim.pose_at(n)))
                .collect(),
            roots: anim.root_positions().to_vec(),
            hip_height: rig.root_height(),
        }
    }
}

/// The pairs by anatomical part ([`crate::rig::names::auto_map`]); an error when there are none.
pub fn auto_pairs(source: &[&str], target: &Rig) -> Result<Vec<(usize, usize)>, RetargetError> {
    let pairs = crate::rig::names::auto_map(
        source.iter().copied(),
        target.joints().iter().map(|j| j.name.as_str()),
    );
    if pairs.is_empty() {
        return Err(RetargetError::NothingMapped {
            rig: target.name().to_string(),
            joints: source.join(", "),
        });
    }
    Ok(pairs)
}

/// Each joint's rest position (every channel zero; the root at its OFFSET), file units, and the
/// lowest point of the rest pose (end sites included).
fn rest_heights(bvh: &Bvh) -> (Vec<Vector3<f64>>, f64) {
    let mut pos: Vec<Vector3<f64>> = Vec::with_capacity(bvh.joints().len());
    let mut lowest = f64::INFINITY;
    for j in bvh.joints() {
        let p = j.parent.map_or(Vector3::zeros(), |p| pos[p]) + j.offset;
        lowest = lowest.min(p.y);
        if let Some(end) = j.end_site {
            lowest = lowest.min(p.y + end.y);
        }
        pos.push(p);
    }
    (pos, lowest)
}

/// The source's motion on `target` at `fps` (see the module documentation).
pub fn retarget(
    source: &SourceMotion,
    target: &Rig,
    pairs: &[(usize, usize)],
    reference: Reference,
    fps: Fps,
) -> Result<Animation, RetargetError> {
    let frames = source.world.len();
    if frames == 0 || source.roots.len() != frames {
        return Err(RetargetError::NoFrames);
    }
    let joints = source.names.len();
    let reference_rot: Vec<UnitQuaternion<f64>> = match reference {
        Reference::Rest => vec![UnitQuaternion::identity(); joints],
        Reference::Frame(n) if n < frames => source.world[n].clone(),
        Reference::Frame(n) => {
            return Err(RetargetError::ReferenceFrame {
                frame: n,
                last: frames - 1,
            });
        }
    };
    // Each frame's changes since the reference, of the mapped joints.
    let change: Vec<Vec<UnitQuaternion<f64>>> = source
        .world
        .iter()
        .map(|w| {
            pairs
                .iter()
                .map(|&(s, _)| w[s] * reference_rot[s].inverse())
                .collect()
        })
        .collect();

    let h_target = target.root_height();
    let k = if source.hip_height > 1e-9 && h_target > 0.0 {
        h_target / source.hip_height
    } else {
        1.0
    };
    let floor = target.joints()[0].offset.y - h_target;
    let duration = source.fps.frame_time_of(frames as u64 - 1);
    let out_frames = fps.frame_count(duration) as usize;
    let bones = target.joints();
    let mut source_of = vec![None; bones.len()];
    for (i, &(_, t)) in pairs.iter().enumerate() {
        source_of[t] = Some(i);
    }
    let mut local = vec![Vec::with_capacity(out_frames); bones.len()];
    let mut root_positions = Vec::with_capacity(out_frames);
    let mut w = vec![UnitQuaternion::identity(); bones.len()];
    for n in 0..out_frames {
        // Where frame n falls in the source: between frames i and i + 1, a of the way.
        let u = fps.frame_time_of(n as u64) * source.fps.as_f64();
        let i = (u.floor().max(0.0) as usize).min(frames - 1);
        let i1 = (i + 1).min(frames - 1);
        let a = if i1 > i {
            (u - i as f64).clamp(0.0, 1.0)
        } else {
            0.0
        };
        for (j, bone) in bones.iter().enumerate() {
            let parent = bone.parent.map_or(UnitQuaternion::identity(), |p| w[p]);
            w[j] = match source_of[j] {
                Some(m) => slerp_shortest(&change[i][m], &change[i1][m], a),
                None => parent,
            };
            local[j].push(parent.inverse() * w[j]);
        }
        let p = source.roots[i].lerp(&source.roots[i1], a) * k;
        root_positions.push(Vector3::new(p.x, p.y + floor, p.z));
    }
    let animated = (0..bones.len()).map(|j| source_of[j].is_some()).collect();
    Ok(Animation::new(
        target.clone(),
        fps,
        local,
        animated,
        root_positions,
    )?)
}

/// MVN's 23 body segments and each one's parent: the skeleton an MVNX file's segments form.
const MVN_SKELETON: [(&str, Option<&str>); 23] = [
    ("Pelvis", None),
    ("L5", Some("Pelvis")),
    ("L3", Some("L5")),
    ("T12", Some("L3")),
    ("T8", Some("T12")),
    ("Neck", Some("T8")),
    ("Head", Some("Neck")),
    ("RightShoulder", Some("T8")),
    ("RightUpperArm", Some("RightShoulder")),
    ("RightForeArm", Some("RightUpperArm")),
    ("RightHand", Some("RightForeArm")),
    ("LeftShoulder", Some("T8")),
    ("LeftUpperArm", Some("LeftShoulder")),
    ("LeftForeArm", Some("LeftUpperArm")),
    ("LeftHand", Some("LeftForeArm")),
    ("RightUpperLeg", Some("Pelvis")),
    ("RightLowerLeg", Some("RightUpperLeg")),
    ("RightFoot", Some("RightLowerLeg")),
    ("RightToe", Some("RightFoot")),
    ("LeftUpperLeg", Some("Pelvis")),
    ("LeftLowerLeg", Some("LeftUpperLeg")),
    ("LeftFoot", Some("LeftLowerLeg")),
    ("LeftToe", Some("LeftFoot")),
];

/// Xsens's own segment kinematics (`convert --mvnx-segments`) as an animation at `fps` on a rig
/// built from the file: MVN's segments as joints (their parents MVN's), each offset the segment's
/// place in the `identity` frame less its parent's, turned into the rig world by
/// A = q_rig_nwu ([`crate::world::World::Nwu`]). In that frame every segment's axes are the
/// global ones, so a segment's orientation q (MVN: segment → global) is the rig bone's
///
/// ```text
/// W = A ⊗ q ⊗ A⁻¹      (the rest pose is the identity, as for every rig)
/// ```
///
/// and the root is the pelvis at A · p. Frames are resampled by slerp (orientations) and linear
/// interpolation (the pelvis). Segments that are not MVN's body segments (props) are left out,
/// with a warning.
pub fn mvnx_animation(
    segments: &crate::read::xsens_mvnx::Segments,
    fps: Fps,
) -> Result<(Animation, Vec<String>), RetargetError> {
    let fail = |reason: String| RetargetError::Segments(reason);
    let a = crate::world::World::Nwu.to_rig();
    let mut warnings = Vec::new();
    // Kept segments: (index in the file, index of the parent among the kept).
    let mut kept: Vec<(usize, Option<usize>)> = Vec::new();
    for (i, label) in segments.labels.iter().enumerate() {
        let Some((_, parent)) = MVN_SKELETON.iter().find(|(name, _)| name == label) else {
            warnings.push(format!(
                "segment `{label}` is not one of MVN's body segments: left out"
            ));
            continue;
        };
        let parent = match parent {
            None => None,
            Some(p) => Some(
                kept.iter()
                    .position(|&(k, _)| segments.labels[k] == *p)
                    .ok_or_else(|| {
                        fail(format!("segment `{label}` comes before its parent `{p}`"))
                    })?,
            ),
        };
        if parent.is_none() && !kept.is_empty() {
            return Err(fail(format!("a second root segment `{label}`")));
        }
        kept.push((i, parent));
    }
    if kept.first().is_none_or(|&(_, p)| p.is_some()) {
        return Err(fail("the file has no `Pelvis` segment first".into()));
    }
    let joints = kept
        .iter()
        .map(|&(i, parent)| crate::rig::Joint {
            name: segments.labels[i].clone(),
            parent,
            offset: a * match parent {
                None => segments.rest[i],
                Some(p) => segments.rest[i] - segments.rest[kept[p].0],
            },
            order: crate::rotation::EulerOrder::ZXY,
            end_site: None,
        })
        .collect();
    let rig = Rig::new("xsens-mvn", crate::rig::LengthUnit::Metres, joints)
        .map_err(|e| fail(e.to_string()))?;

    let times = &segments.times_s;
    let last = *times.last().ok_or(RetargetError::NoFrames)?;
    let out_frames = fps.frame_count(last) as usize;
    let mut local = vec![Vec::with_capacity(out_frames); kept.len()];
    let mut roots = Vec::with_capacity(out_frames);
    let mut w = vec![UnitQuaternion::identity(); kept.len()];
    for n in 0..out_frames {
        let t = fps.frame_time_of(n as u64);
        let i = times.partition_point(|&x| x <= t).saturating_sub(1);
        let i1 = (i + 1).min(times.len() - 1);
        let s = if i1 > i {
            ((t - times[i]) / (times[i1] - times[i])).clamp(0.0, 1.0)
        } else {
            0.0
        };
        for (j, &(k, parent)) in kept.iter().enumerate() {
            let q = slerp_shortest(
                &segments.orientations[i][k],
                &segments.orientations[i1][k],
                s,
            );
            w[j] = a * q * a.inverse();
            let parent = parent.map_or(UnitQuaternion::identity(), |p| w[p]);
            local[j].push(parent.inverse() * w[j]);
        }
        let pelvis = kept[0].0;
        let p = segments.positions[i][pelvis].lerp(&segments.positions[i1][pelvis], s);
        roots.push(a * p);
    }
    let animated = vec![true; kept.len()];
    let animation = Animation::new(rig, fps, local, animated, roots)?;
    Ok((animation, warnings))
}
