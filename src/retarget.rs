//! Motion on one skeleton onto another rig: any suit's BVH (SlimeVR, Rokoko, Noitom Axis,
//! mocopi, CMU) on a game rig, and Xsens's own segments ([`mvnx_animation`]) as a skeleton of
//! their own. A source is a [`SourceMotion`] (a BVH's forward kinematics, or an animation's).
//!
//! Each mapped source joint s drives one target bone j (the same body part of both skeletons'
//! [`crate::rig::anatomy`], chains paired by their place along them, or a bone map). With S_s(t) the source joint's world rotation (the
//! BVH's forward kinematics, rig world: Y up) and R_s its world rotation in the reference (frame
//! N, or the zero pose — every channel zero — where R_s = 1), the change since the reference is
//!
//! ```text
//! D_s(t) = S_s(t) ⊗ R_s⁻¹
//! ```
//!
//! and the target bone turns by the same change from the bone's reference, W_j(t) = D_s(t) ⊗ M_j:
//! by default ([`Reference::Match`]) M_j aims bone j from its rest as joint s is aimed in frame N
//! ([`matched_pose`]: from joint positions alone, so the source's joint axes and zero pose play
//! no part); with [`Reference::Frame`] and [`Reference::Rest`], M_j = 1 (the reference is taken
//! for the rig's rest pose, whose rotations are the identity). A target bone without a source
//! keeps its rest rotation relative to its parent (W_j = W_parent). Local rotations follow:
//! L_j = W_parent(j)⁻¹ ⊗ W_j.
//!
//! The root position is the source root's, scaled by the ratio of hip heights, k = h_target /
//! h_source, and stood on the target's floor: p(t) = k · (p_s(t) − (0, floor_source, 0)) +
//! (0, floor_target, 0). Both hip heights are read in one standing frame — the reference frame
//! (`match:N`, `frame:N`), else the first — as the root's height above that frame's lowest
//! point (end sites included): the source's in its own pose, the target's in the pose it takes
//! there, so that the target's feet stand on its floor in that frame whatever the two skeletons'
//! proportions. Never in a zero pose, which need not stand (a skeleton whose bones lie along +X,
//! a root below its feet), nor from the source world's y = 0. The target's floor is its rest
//! pose's lowest point, and no frame goes below it: where the pose's lowest point (joints and end
//! sites) would, the root rises by the difference.
//!
//! Frames are resampled to the output rate: frame n at n / fps reads the source at t · fps_source,
//! between two frames by slerp (rotations) and linear interpolation (the root).

use crate::anim::{Animation, AnimationError};
use crate::bvh::Bvh;
use crate::fps::Fps;
use crate::rig::Rig;
use crate::rig::anatomy::{self, Anatomy, Part, Skeleton};
use crate::rotation::quat::slerp_shortest;
use nalgebra::{UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// The source pose the changes are measured from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reference {
    /// The BVH's zero pose (every channel zero) taken as the target's rest: right when the
    /// source's zero pose is the target's rest pose with the same joint axes.
    Rest,
    /// Frame N taken as the target's rest: for a take that starts in the target's rest pose.
    Frame(usize),
    /// Frame N matched (the default, frame 0): each target bone aimed as its source joint is
    /// in that frame — the zero pose and the joints' axes play no part, so a skeleton and its
    /// twin with other joint axes (bones along +X) give one output.
    Match(usize),
}

impl Default for Reference {
    fn default() -> Reference {
        Reference::Match(0)
    }
}

impl Reference {
    /// The frame whose pose is the reference; `None` for the zero pose.
    pub fn frame(self) -> Option<usize> {
        match self {
            Reference::Rest => None,
            Reference::Frame(n) | Reference::Match(n) => Some(n),
        }
    }
}

impl FromStr for Reference {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let frame = |prefix: &str| s.trim().strip_prefix(prefix).and_then(|n| n.parse().ok());
        match s.trim() {
            "rest" => Ok(Reference::Rest),
            _ => frame("frame:")
                .map(Reference::Frame)
                .or_else(|| frame("match:").map(Reference::Match))
                .ok_or_else(|| {
                    format!("`{s}`: expected `match:N`, `frame:N` (N 0-based) or `rest`")
                }),
        }
    }
}

impl std::fmt::Display for Reference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Reference::Rest => f.write_str("rest"),
            Reference::Frame(n) => write!(f, "frame:{n}"),
            Reference::Match(n) => write!(f, "match:{n}"),
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

/// A bone map file as read: `{"bones": {"<source joint>": "<target bone, or a canonical part
/// such as LeftArm>"}}` (a flat object works too), the Blender add-on's format. Its names are
/// checked against a source and a rig by [`BoneMap::pairs`].
#[derive(Debug, Clone, PartialEq)]
pub struct BoneMap {
    /// The file, named in errors.
    pub path: PathBuf,
    /// (source joint, target bone or part), in the file's order.
    pub names: Vec<(String, String)>,
}

impl BoneMap {
    /// Parses a bone map's text (reading the file is the caller's: `convert::Plan` reads and
    /// hashes it once).
    pub fn parse(text: &str, path: &Path) -> Result<BoneMap, RetargetError> {
        let fail = |reason: String| RetargetError::BoneMap {
            path: path.to_path_buf(),
            reason,
        };
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| fail(format!("not JSON: {e}")))?;
        let bones = value.get("bones").unwrap_or(&value);
        let bones = bones.as_object().ok_or_else(|| {
            fail(r#"expected {"bones": {"source joint": "target bone", …}}"#.into())
        })?;
        let names = bones
            .iter()
            .map(|(s, t)| {
                t.as_str()
                    .map(|t| (s.clone(), t.to_string()))
                    .ok_or_else(|| fail(format!("the target of `{s}` is not a bone name")))
            })
            .collect::<Result<_, _>>()?;
        Ok(BoneMap {
            path: path.to_path_buf(),
            names,
        })
    }

    /// `(source joint, target joint)` index pairs: every source joint and target bone must
    /// exist, and no bone is driven twice.
    pub fn pairs(
        &self,
        source: &[&str],
        target_rig: &Rig,
    ) -> Result<Vec<(usize, usize)>, RetargetError> {
        let target: Vec<&str> = target_rig
            .joints()
            .iter()
            .map(|j| j.name.as_str())
            .collect();
        let fail = |reason: String| RetargetError::BoneMap {
            path: self.path.clone(),
            reason,
        };
        let parts = Anatomy::of(target_rig).mixamo_slots();
        let mut pairs = Vec::with_capacity(self.names.len());
        for (s, t) in &self.names {
            let si = source.iter().position(|n| n == s).ok_or_else(|| {
                fail(format!(
                    "source joint `{s}` is not in the BVH (it has: {})",
                    source.join(", ")
                ))
            })?;
            let ti = target
                .iter()
                .position(|n| n == t)
                .or_else(|| parts.iter().find(|(p, _)| p == t).map(|(_, i)| *i))
                .ok_or_else(|| fail(format!("target bone `{t}` is not in the rig")))?;
            if pairs.iter().any(|&(_, other)| other == ti) {
                return Err(fail(format!("two source joints drive `{}`", target[ti])));
            }
            pairs.push((si, ti));
        }
        Ok(pairs)
    }
}

/// A skeleton's motion, as retargeting reads it: each joint's world rotation per frame (rig
/// world axes: Y up), the root's position, the hips' rest height above the rest pose's lowest
/// point (in the source's units) and the rate.
#[derive(Debug, Clone)]
pub struct SourceMotion {
    pub names: Vec<String>,
    /// Each joint's parent (before it).
    pub parents: Vec<Option<usize>>,
    /// Each joint's rest position and End Site (source units, rig world axes).
    pub rest: Vec<Vector3<f64>>,
    pub end_sites: Vec<Option<Vector3<f64>>>,
    pub fps: Fps,
    /// `world[frame][joint]`: q_world_joint.
    pub world: Vec<Vec<UnitQuaternion<f64>>>,
    /// The root joint's position per frame, source units (the floor where a standing frame's
    /// lowest point is: [`SourceMotion::standing`]).
    pub roots: Vec<Vector3<f64>>,
}

impl SourceMotion {
    /// A BVH file's motion (its forward kinematics), at `fps` (its `Frame Time`'s rate).
    pub fn of_bvh(bvh: &Bvh, fps: Fps) -> SourceMotion {
        let rest = rest_positions(bvh);
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
            parents: bvh.joints().iter().map(|j| j.parent).collect(),
            rest,
            end_sites: bvh.joints().iter().map(|j| j.end_site).collect(),
            fps,
            world,
            roots,
        }
    }

    /// An animation's motion on its own rig.
    pub fn of_animation(anim: &Animation) -> SourceMotion {
        let rig = anim.rig();
        SourceMotion {
            names: rig.joints().iter().map(|j| j.name.clone()).collect(),
            parents: rig.joints().iter().map(|j| j.parent).collect(),
            rest: rig.rest_positions(),
            end_sites: rig.joints().iter().map(|j| j.end_site).collect(),
            fps: anim.fps(),
            world: (0..anim.frames())
                .map(|n| rig.world_rotations(&anim.pose_at(n)))
                .collect(),
            roots: anim.root_positions().to_vec(),
        }
    }
}

impl SourceMotion {
    /// Frame `n`'s joint positions and End Sites (world, source units).
    pub fn positions(&self, n: usize) -> (Vec<Vector3<f64>>, Vec<Option<Vector3<f64>>>) {
        let world = &self.world[n];
        let mut pos: Vec<Vector3<f64>> = Vec::with_capacity(self.names.len());
        for (j, parent) in self.parents.iter().enumerate() {
            pos.push(match parent {
                Some(p) => pos[*p] + world[*p] * (self.rest[j] - self.rest[*p]),
                None => self.roots[n],
            });
        }
        let ends = (0..pos.len())
            .map(|j| self.end_sites[j].map(|e| pos[j] + world[j] * e))
            .collect();
        (pos, ends)
    }

    /// Frame `n`'s lowest point (joints and End Sites) and the root's height above it, source
    /// units: the floor and the hip height of a standing frame.
    pub fn standing(&self, n: usize) -> (f64, f64) {
        let (pos, ends) = self.positions(n);
        let low = pos
            .iter()
            .chain(ends.iter().flatten())
            .map(|p| p.y)
            .fold(f64::INFINITY, f64::min);
        (low, self.roots[n].y - low)
    }

    /// The source skeleton's anatomy.
    pub fn anatomy(&self) -> Anatomy {
        Anatomy::resolve(&Skeleton {
            name: "the source",
            names: self.names.iter().map(String::as_str).collect(),
            parents: self.parents.clone(),
            rest: self.rest.clone(),
            end_sites: self.end_sites.clone(),
            declared: Default::default(),
        })
    }

    /// Each joint's largest turn relative to its parent away from its first frame's, degrees:
    /// how much it moves of its own (a joint held at one angle does not move).
    fn own_turn_deg(&self) -> Vec<f64> {
        let n = self.names.len();
        let local = |w: &[UnitQuaternion<f64>], j: usize| match self.parents[j] {
            Some(p) => w[p].inverse() * w[j],
            None => w[j],
        };
        let Some(first) = self.world.first() else {
            return vec![0.0; n];
        };
        let base: Vec<UnitQuaternion<f64>> = (0..n).map(|j| local(first, j)).collect();
        let mut most = vec![0.0f64; n];
        for w in &self.world {
            for j in 0..n {
                most[j] = most[j].max(base[j].angle_to(&local(w, j)).to_degrees());
            }
        }
        most
    }
}

/// Moving joints that are no body part named one by one in the warnings; the rest are counted.
pub const MAX_JOINT_WARNINGS: usize = 20;

/// A joint turning less than this (degrees, relative to its parent) over a take does not move.
pub const MOVES_DEG: f64 = 1.0;

/// The pairs by body part ([`anatomy::pairs`]); an error when there are none.
pub fn auto_pairs(
    source: &SourceMotion,
    target: &Rig,
) -> Result<Vec<(usize, usize)>, RetargetError> {
    let pairs = anatomy::pairs(&source.anatomy(), &Anatomy::of(target));
    if pairs.is_empty() {
        return Err(RetargetError::NothingMapped {
            rig: target.name().to_string(),
            joints: source.names.join(", "),
        });
    }
    Ok(pairs)
}

/// What the pairs leave out, as warnings naming both sides: a source joint that moves (turns
/// more than [`MOVES_DEG`] relative to its parent over the take) and is no body part — not a
/// part, not a joint between parts (the world turns of the parts below carry it), not below a
/// hand, a foot or the head (fingers, toes' tips, eyes), not a rig's helper (`ik_*`, twist, roll,
/// pole, corrective) —, and a target part left undriven though the source has it.
pub fn coverage_warnings(
    source: &SourceMotion,
    target: &Rig,
    pairs: &[(usize, usize)],
) -> Vec<String> {
    let src = source.anatomy();
    let tgt = Anatomy::of(target);
    let n = source.names.len();
    let mut warnings = Vec::new();
    let mut is_part = vec![false; n];
    for part in Part::all() {
        for j in src.joints(part) {
            is_part[j] = true;
        }
    }
    for &(s, _) in pairs {
        is_part[s] = true;
    }
    let mut is_end = vec![false; n];
    let ends = [Part::Head]
        .into_iter()
        .chain(anatomy::Side::BOTH.into_iter().flat_map(|s| {
            [
                Part::Limb(s, anatomy::Limb::Hand),
                Part::Limb(s, anatomy::Limb::Foot),
            ]
        }));
    for part in ends {
        for j in src.joints(part) {
            is_end[j] = true;
        }
    }
    // One pass up (a part below: carried) and one down (below an end: a detail; the nearest
    // part above), so a skeleton of any size costs two walks.
    let mut part_below = vec![false; n];
    for j in (0..n).rev() {
        if let Some(p) = src.parent(j) {
            part_below[p] |= is_part[j] || part_below[j];
        }
    }
    let mut detail = vec![false; n];
    let mut near: Vec<Option<usize>> = vec![None; n];
    for j in 0..n {
        if let Some(p) = src.parent(j) {
            detail[j] = detail[p] || is_end[p];
            near[j] = if is_part[p] { Some(p) } else { near[p] };
        }
    }
    let helper = |name: &str| {
        let bare = name
            .rsplit([':', '|'])
            .next()
            .unwrap_or(name)
            .to_ascii_lowercase();
        let words: Vec<&str> = bare.split(['_', '.', '-', ' ']).collect();
        words.first().is_some_and(|w| *w == "ik")
            || ["twist", "roll", "pole", "corrective", "helper"]
                .iter()
                .any(|h| bare.contains(h))
    };
    let turn = source.own_turn_deg();
    let mut unnamed = 0;
    for (j, name) in source.names.iter().enumerate() {
        if is_part[j] || part_below[j] || detail[j] || turn[j] <= MOVES_DEG || helper(name) {
            continue;
        }
        // A skeleton of thousands of such joints gets a line for each of the first few.
        unnamed += 1;
        if unnamed > MAX_JOINT_WARNINGS {
            continue;
        }
        let near = near[j]
            .and_then(|a| src.part_of(a))
            .map_or(String::new(), |p| format!(" (below the {})", p.label()));
        warnings.push(format!(
            "source joint `{name}`{near} turns up to {:.0}° but is no body part: no bone of `{}` follows it",
            turn[j],
            target.name()
        ));
    }
    if unnamed > MAX_JOINT_WARNINGS {
        warnings.push(format!(
            "… and {} more source joints that move and are no body part",
            unnamed - MAX_JOINT_WARNINGS
        ));
    }
    let driven_tgt: Vec<bool> = {
        let mut d = vec![false; target.len()];
        for &(_, t) in pairs {
            d[t] = true;
        }
        d
    };
    for part in Part::all() {
        let t = tgt.joints(part);
        let s = src.joints(part);
        if t.is_empty() || s.is_empty() || t.iter().any(|&j| driven_tgt[j]) {
            continue;
        }
        let tn: Vec<&str> = t
            .iter()
            .map(|&j| target.joints()[j].name.as_str())
            .collect();
        let sn: Vec<&str> = s.iter().map(|&j| source.names[j].as_str()).collect();
        warnings.push(format!(
            "the {} of `{}` ({}) is not driven, though the source has it ({})",
            part.label(),
            target.name(),
            tn.join(", "),
            sn.join(", ")
        ));
    }
    warnings
}

/// Each joint's rest position (every channel zero; the root at its OFFSET), file units.
fn rest_positions(bvh: &Bvh) -> Vec<Vector3<f64>> {
    let mut pos: Vec<Vector3<f64>> = Vec::with_capacity(bvh.joints().len());
    for j in bvh.joints() {
        pos.push(j.parent.map_or(Vector3::zeros(), |p| pos[p]) + j.offset);
    }
    pos
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
    if let Some(n) = reference.frame().filter(|&n| n >= frames) {
        return Err(RetargetError::ReferenceFrame {
            frame: n,
            last: frames - 1,
        });
    }
    // Each pair's D_s(t) ⊗ M_j: the change since the reference, onto the bone's reference.
    let (reference_rot, matched) = match reference {
        Reference::Rest => (vec![UnitQuaternion::identity(); joints], None),
        Reference::Frame(n) => (source.world[n].clone(), None),
        Reference::Match(n) => (
            source.world[n].clone(),
            Some(matched_pose(source, n, target, pairs)),
        ),
    };
    let change: Vec<Vec<UnitQuaternion<f64>>> = source
        .world
        .iter()
        .map(|w| {
            pairs
                .iter()
                .enumerate()
                .map(|(m, &(s, _))| {
                    let d = w[s] * reference_rot[s].inverse();
                    matched.as_ref().map_or(d, |aim| d * aim[m])
                })
                .collect()
        })
        .collect();
    let standing = reference.frame().unwrap_or(0);
    let bones = target.joints();
    let mut source_of = vec![None; bones.len()];
    for (i, &(_, t)) in pairs.iter().enumerate() {
        source_of[t] = Some(i);
    }
    // The target in the standing frame's pose: its hips' height above its lowest point there.
    let mut w = vec![UnitQuaternion::identity(); bones.len()];
    let mut standing_local = vec![UnitQuaternion::identity(); bones.len()];
    target_pose(
        target,
        &source_of,
        |m| change[standing][m],
        &mut w,
        &mut standing_local,
    );
    let (low_target, _) = target.extent_in(&standing_local);
    let h_target = bones[0].offset.y - low_target;
    let (floor_source, hip_height) = source.standing(standing);
    let k = if hip_height > 1e-9 && h_target > 0.0 {
        h_target / hip_height
    } else {
        1.0
    };
    // The target's floor is its rest pose's.
    let floor = bones[0].offset.y - target.root_height();
    let duration = source.fps.frame_time_of(frames as u64 - 1);
    let out_frames = fps.frame_count(duration) as usize;
    let mut local = vec![Vec::with_capacity(out_frames); bones.len()];
    let mut root_positions = Vec::with_capacity(out_frames);
    let mut pose = vec![UnitQuaternion::identity(); bones.len()];
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
        target_pose(
            target,
            &source_of,
            |m| slerp_shortest(&change[i][m], &change[i1][m], a),
            &mut w,
            &mut pose,
        );
        for (track, q) in local.iter_mut().zip(&pose) {
            track.push(*q);
        }
        let p = source.roots[i].lerp(&source.roots[i1], a);
        let p = Vector3::new(p.x, p.y - floor_source, p.z) * k;
        // Never below the floor: a source's own markers dip under its ground, and the target's
        // limbs, of other proportions, reach lower; the hips rise by what would go under.
        let (low, _) = target.extent_in(&pose);
        let under = floor - (p.y + floor + low - bones[0].offset.y);
        root_positions.push(Vector3::new(p.x, p.y + floor + under.max(0.0), p.z));
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

/// `M_j` of each pair (s, j) for [`Reference::Match`]: the world rotation that aims target bone j,
/// from its rest, as source joint s is aimed in frame `n`. A joint's aim is where its nearest
/// paired descendants are (`u_k = p_s'(n) − p_s(n)` in the source, `t_k` the same in the target's
/// rest), else where its children and End Site are (their mean direction); with two or more
/// directions apart M_j is the rotation that best turns the t̂_k onto the û_k (Kabsch, by SVD),
/// with one (or all along one line) the shortest turn of their mean t̂ onto their mean û (no
/// twist about the bone, which positions cannot tell). A
/// bone with no aim on either side keeps its rest turn relative to its nearest paired ancestor.
/// Only joint positions in frame n enter, so a skeleton's joint axes do not.
fn matched_pose(
    source: &SourceMotion,
    n: usize,
    target: &Rig,
    pairs: &[(usize, usize)],
) -> Vec<UnitQuaternion<f64>> {
    let (src_pos, src_ends) = source.positions(n);
    let tgt_pos = target.rest_positions();
    let bones = target.joints();
    let mut pair_of = vec![None; bones.len()];
    for (m, &(_, j)) in pairs.iter().enumerate() {
        pair_of[j] = Some(m);
    }
    // Each target bone's nearest paired descendants, through unpaired bones.
    let mut nearest: Vec<Vec<usize>> = vec![Vec::new(); bones.len()];
    for j in (0..bones.len()).rev() {
        if let Some(p) = bones[j].parent {
            let below = if pair_of[j].is_some() {
                vec![j]
            } else {
                nearest[j].clone()
            };
            nearest[p].extend(below);
        }
    }
    let unit = |v: Vector3<f64>| (v.norm() > 1e-9).then(|| v.normalize());
    let mut aims = vec![None; pairs.len()];
    for (m, &(s, j)) in pairs.iter().enumerate() {
        let mut dirs: Vec<(Vector3<f64>, Vector3<f64>)> = nearest[j]
            .iter()
            .filter_map(|&d| {
                let (s_d, _) = pairs[pair_of[d]?];
                Some((
                    unit(tgt_pos[d] - tgt_pos[j])?,
                    unit(src_pos[s_d] - src_pos[s])?,
                ))
            })
            .collect();
        if dirs.is_empty() {
            let mean = |vs: Vec<Vector3<f64>>| unit(vs.into_iter().filter_map(unit).sum());
            let t_children = (0..bones.len())
                .filter(|&c| bones[c].parent == Some(j))
                .map(|c| tgt_pos[c] - tgt_pos[j])
                .chain(bones[j].end_site)
                .collect();
            let s_children = (0..source.names.len())
                .filter(|&c| source.parents[c] == Some(s))
                .map(|c| src_pos[c] - src_pos[s])
                .chain(src_ends[s].map(|e| e - src_pos[s]))
                .collect();
            if let (Some(t), Some(u)) = (mean(t_children), mean(s_children)) {
                dirs.push((t, u));
            }
        }
        aims[m] = aim(&dirs);
    }
    // Bones without an aim: their nearest paired ancestor's, else the rest.
    let mut resolved = vec![UnitQuaternion::identity(); bones.len()];
    for (j, bone) in bones.iter().enumerate() {
        let inherited = bone
            .parent
            .map_or(UnitQuaternion::identity(), |p| resolved[p]);
        resolved[j] = pair_of[j].and_then(|m| aims[m]).unwrap_or(inherited);
    }
    pairs.iter().map(|&(_, j)| resolved[j]).collect()
}

/// The rotation that best turns each `t` onto its `u` (unit vectors): Kabsch when they span a
/// plane, else the shortest turn of their mean direction (of the first, should they cancel);
/// `None` without any.
fn aim(dirs: &[(Vector3<f64>, Vector3<f64>)]) -> Option<UnitQuaternion<f64>> {
    let &(t0, u0) = dirs.first()?;
    let (t_sum, u_sum) = dirs
        .iter()
        .fold((Vector3::zeros(), Vector3::zeros()), |(a, b), (t, u)| {
            (a + t, b + u)
        });
    let t = t_sum.try_normalize(1e-6).unwrap_or(t0);
    let u = u_sum.try_normalize(1e-6).unwrap_or(u0);
    let shortest = UnitQuaternion::rotation_between(&t, &u).unwrap_or_else(|| {
        // Opposite: half a turn about any axis across them.
        let across = t.cross(&Vector3::x()).try_normalize(1e-6);
        let axis = across.unwrap_or_else(|| t.cross(&Vector3::y()).normalize());
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(axis), std::f64::consts::PI)
    });
    let h: nalgebra::Matrix3<f64> = dirs.iter().map(|(t, u)| u * t.transpose()).sum();
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Some(shortest);
    };
    let sv = svd.singular_values;
    // One direction, or all along one line on either side: the plane, and so the twist about
    // the line, is not known.
    if sv.iter().filter(|&&x| x > 1e-3 * sv.max()).count() < 2 {
        return Some(shortest);
    }
    let d = (u * v_t).determinant().signum();
    let r = u * nalgebra::Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t;
    Some(UnitQuaternion::from_matrix(&r))
}

/// The target's pose: each bone with a source (`source_of[j]`, an index of the pairs) turned to
/// `driven(m)` in the world, the others keeping their rest rotation relative to their parent
/// (`world` is scratch, one per bone); the local rotations into `local`.
fn target_pose(
    target: &Rig,
    source_of: &[Option<usize>],
    driven: impl Fn(usize) -> UnitQuaternion<f64>,
    world: &mut [UnitQuaternion<f64>],
    local: &mut [UnitQuaternion<f64>],
) {
    for (j, bone) in target.joints().iter().enumerate() {
        let parent = bone.parent.map_or(UnitQuaternion::identity(), |p| world[p]);
        world[j] = source_of[j].map_or(parent, &driven);
        local[j] = parent.inverse() * world[j];
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The aim of known directions turned by a known rotation is that rotation: three directions
    /// (a plane and more, by SVD), two, and one (the shortest turn, so no twist about it).
    #[test]
    fn the_aim_of_turned_directions_is_the_turn() {
        let turn = UnitQuaternion::from_euler_angles(0.3, -1.1, 2.0);
        let t = [
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(1.0, 0.2, 0.0).normalize(),
            Vector3::new(-1.0, 0.2, 0.1).normalize(),
        ];
        for n in [3, 2] {
            let dirs: Vec<_> = t[..n].iter().map(|t| (*t, turn * t)).collect();
            let got = aim(&dirs).unwrap();
            assert!(got.angle_to(&turn) < 1e-9, "{n}: {}", got.angle_to(&turn));
        }
        let one = aim(&[(t[0], turn * t[0])]).unwrap();
        assert!((one * t[0] - turn * t[0]).norm() < 1e-9);
        let swing = UnitQuaternion::rotation_between(&t[0], &(turn * t[0])).unwrap();
        assert!(one.angle_to(&swing) < 1e-9);
        assert!(aim(&[]).is_none());
    }

    /// Mixamo's rig as a source whose `Spine1` turns 30° after the first frame (a part: no
    /// warning), then with a leaf `Tail` that is no part and turns 30° too (a warning naming it);
    /// a bone map leaving the left thigh out leaves the target's undriven (a warning naming both).
    #[test]
    fn moving_joints_that_are_no_part_and_undriven_parts_are_warned_of() {
        let rig = crate::rig::load_rig("mixamo").unwrap();
        let mut source = SourceMotion {
            names: rig.joints().iter().map(|j| j.name.clone()).collect(),
            parents: rig.joints().iter().map(|j| j.parent).collect(),
            rest: rig.rest_positions(),
            end_sites: rig.joints().iter().map(|j| j.end_site).collect(),
            fps: Fps::new(30, 1).unwrap(),
            world: Vec::new(),
            roots: Vec::new(),
        };
        let spine1 = rig.joint_index("Spine1").unwrap();
        let spine2 = rig.joint_index("Spine2").unwrap();
        let turn = UnitQuaternion::from_euler_angles(30f64.to_radians(), 0.0, 0.0);
        for f in 0..3 {
            let mut local = vec![UnitQuaternion::identity(); rig.len()];
            if f > 0 {
                local[spine1] = turn;
            }
            source.world.push(rig.world_rotations(&local));
            source.roots.push(Vector3::zeros());
        }
        // Named as a part, Spine1 is on the spine: no warning.
        let pairs = auto_pairs(&source, &rig).unwrap();
        assert!(coverage_warnings(&source, &rig, &pairs).is_empty());
        // A leaf that is no part and moves: the head's sibling `Tail` below the spine's top.
        source.names.push("Tail".into());
        source.parents.push(Some(spine2));
        source
            .rest
            .push(source.rest[spine2] + Vector3::new(0.0, 0.0, -0.2));
        source.end_sites.push(None);
        for (f, w) in source.world.iter_mut().enumerate() {
            let t = if f > 0 {
                turn
            } else {
                UnitQuaternion::identity()
            };
            w.push(w[spine2] * t);
        }
        let pairs = auto_pairs(&source, &rig).unwrap();
        let w = coverage_warnings(&source, &rig, &pairs);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("`Tail` (below the spine) turns up to 30°"),
            "{w:?}"
        );
        // A bone map that leaves the left thigh out.
        let thigh = rig.joint_index("LeftUpLeg").unwrap();
        let pairs: Vec<(usize, usize)> = pairs.into_iter().filter(|&(_, t)| t != thigh).collect();
        let w = coverage_warnings(&source, &rig, &pairs);
        assert!(
            w.iter().any(|m| m
                == "the left thigh of `mixamo` (LeftUpLeg) is not driven, though the source has it (LeftUpLeg)"),
            "{w:?}"
        );
    }
}
