//! A BVH take onto another rig: the motion of any suit's BVH (SlimeVR, Rokoko, Noitom Axis,
//! mocopi, CMU) on a game rig.
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

/// The pairs by anatomical part ([`crate::rig::names::auto_map`]); an error when there are none.
pub fn auto_pairs(bvh: &Bvh, target: &Rig) -> Result<Vec<(usize, usize)>, RetargetError> {
    let pairs = crate::rig::names::auto_map(
        bvh.joints().iter().map(|j| j.name.as_str()),
        target.joints().iter().map(|j| j.name.as_str()),
    );
    if pairs.is_empty() {
        return Err(RetargetError::NothingMapped {
            rig: target.name().to_string(),
            joints: bvh
                .joints()
                .iter()
                .map(|j| j.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
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

/// The root scale k = h_target / h_source (1 when the source's hips are not above its lowest
/// point).
pub fn hip_scale(bvh: &Bvh, target: &Rig) -> f64 {
    let (rest, lowest) = rest_heights(bvh);
    let h_source = rest[0].y - lowest;
    let h_target = target.root_height();
    if h_source > 1e-9 && h_target > 0.0 {
        h_target / h_source
    } else {
        1.0
    }
}

/// The BVH's motion on `target` at `fps` (see the module documentation). `source_fps` is the
/// BVH's rate.
pub fn retarget(
    bvh: &Bvh,
    source_fps: Fps,
    target: &Rig,
    pairs: &[(usize, usize)],
    reference: Reference,
    fps: Fps,
) -> Result<Animation, RetargetError> {
    let frames = bvh.frame_count();
    if frames == 0 {
        return Err(RetargetError::NoFrames);
    }
    // Each source frame's world rotations of the mapped joints, as changes since the reference.
    let world = |n: usize| {
        bvh.forward_kinematics(&bvh.local_rotations(n), &bvh.joint_translations(n))
            .1
    };
    let reference_rot: Vec<UnitQuaternion<f64>> = match reference {
        Reference::Rest => vec![UnitQuaternion::identity(); bvh.joints().len()],
        Reference::Frame(n) if n < frames => world(n),
        Reference::Frame(n) => {
            return Err(RetargetError::ReferenceFrame {
                frame: n,
                last: frames - 1,
            });
        }
    };
    let mut change: Vec<Vec<UnitQuaternion<f64>>> = Vec::with_capacity(frames);
    let mut roots: Vec<Vector3<f64>> = Vec::with_capacity(frames);
    for n in 0..frames {
        let w = world(n);
        change.push(
            pairs
                .iter()
                .map(|&(s, _)| w[s] * reference_rot[s].inverse())
                .collect(),
        );
        roots.push(bvh.joint_translations(n)[0]);
    }

    let k = hip_scale(bvh, target);
    let floor = target.joints()[0].offset.y - target.root_height();
    let duration = source_fps.frame_time_of(frames as u64 - 1);
    let out_frames = fps.frame_count(duration) as usize;
    let joints = target.joints();
    let mut source_of = vec![None; joints.len()];
    for (i, &(_, t)) in pairs.iter().enumerate() {
        source_of[t] = Some(i);
    }
    let mut local = vec![Vec::with_capacity(out_frames); joints.len()];
    let mut root_positions = Vec::with_capacity(out_frames);
    let mut w = vec![UnitQuaternion::identity(); joints.len()];
    for n in 0..out_frames {
        // Where frame n falls in the source: between frames i and i + 1, a of the way.
        let u = fps.frame_time_of(n as u64) * source_fps.as_f64();
        let i = (u.floor().max(0.0) as usize).min(frames - 1);
        let a = if i + 1 < frames {
            (u - i as f64).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let j1 = (i + 1).min(frames - 1);
        for (j, joint) in joints.iter().enumerate() {
            let parent = joint.parent.map_or(UnitQuaternion::identity(), |p| w[p]);
            w[j] = match source_of[j] {
                Some(m) => change[i][m].slerp(&change[j1][m], a),
                None => parent,
            };
            local[j].push(parent.inverse() * w[j]);
        }
        let p = roots[i].lerp(&roots[j1], a) * k;
        root_positions.push(Vector3::new(p.x, p.y + floor, p.z));
    }
    let animated = (0..joints.len()).map(|j| source_of[j].is_some()).collect();
    Ok(Animation::new(
        target.clone(),
        fps,
        local,
        animated,
        root_positions,
    )?)
}
