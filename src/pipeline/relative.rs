//! World rotations on the frame grid → local rotations: q_local = q_world_parent⁻¹ ⊗ q_world_bone.
//!
//! Joints without a sensor ([`Unsensed`]):
//! - `interpolate` (the default): a chain of unsensed joints `u_1 … u_k` between a sensed joint
//!   `A` and its nearest sensed descendant `D` (the spine between the hips and the chest, the
//!   neck) shares the rotation between them, `R = q_world_A⁻¹ ⊗ q_world_D`: each `u_i` turns by
//!   the fraction `f_i` of it, `q_local_i = exp(f_i · log R)` (a slerp from the identity), as a
//!   chain that bends evenly along its length would: the segment `u_i` turns (from `u_i` to the
//!   next joint, or `D`, rest length `ℓ_i`) points along the bend's tangent at its middle, so
//!   `Σ_{j≤i} f_j = (Σ_{j<i} ℓ_j + ℓ_i / 2) / Σ ℓ`; `D` keeps the rest of the rotation, so the
//!   chain bends smoothly and `D` is exactly where its sensor says (two equal segments: ¼, ½, and
//!   ¼ left for `D`). A limb's root is not such a chain: unsensed joints of the limb's own before
//!   a sensed upper arm (a clavicle) share [`CLAVICLE_SHARE`] of its turn in all, before a sensed
//!   thigh (a hip offset bone) none, the pelvis being rigid ([`limb_root_share`]). An unsensed
//!   joint without a sensed descendant (a head with no sensor) keeps its held rotation (below);
//!   where branches meet, the first sensed descendant in the rig's order decides.
//! - `rest`: every unsensed joint keeps its held local rotation, so the whole change of the bend
//!   between two sensors happens at the lower one.
//!
//! The held rotation `h_j` of an unsensed joint is its local rotation in the pose the subject held
//! at calibration (identity for the rest pose; a BVH rig's `frame:N` may bend the spine), since
//! that is the one moment the sensors say how the body stood. Between two sensors the chain then
//! shares the change from that pose: with `H = h_1 ⊗ … ⊗ h_k ⊗ h_D` the pose's rotation from `A`
//! to `D`, the change `M = R ⊗ H⁻¹` (in `A`'s frame) and `P_i = h_1 ⊗ … ⊗ h_i` the pose's rotation
//! from `A` to `u_i`, `q_local_i = exp(f_i · log(P_{i−1}⁻¹ ⊗ M ⊗ P_{i−1})) ⊗ h_i`: each joint turns
//! by its share of `M` about the same axis of the body, seen in its parent's frame, so the
//! product down the chain is `exp(F_k · log M) ⊗ P_k` whatever the joints' own frames are (a rig
//! and its bone-along-X twin bend alike). `D` keeps the remainder, so at calibration (`R = H`)
//! every joint is exactly in the pose; with the rest pose held (`h = 1`) this is
//! `exp(f_i · log R)`.

use crate::rig::Rig;
use crate::rig::anatomy::{Anatomy, Limb, Side};

/// The share of an upper arm's turn (relative to the chest) its unsensed clavicle takes: most of
/// an arm's swing is at the shoulder joint, the shoulder girdle following by about a tenth to a
/// fifth (shoulder rhythm), where a chain bending evenly along its length would give the clavicle
/// half — lifting the shoulder, and the hand with it, by about a tenth of the body's height when
/// the arms come down from a T-pose.
pub const CLAVICLE_SHARE: f64 = 0.15;
use nalgebra::UnitQuaternion;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// What joints without a sensor do (`--unsensed`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Unsensed {
    /// Share the rotation between the sensed joints around them.
    #[default]
    Interpolate,
    /// Keep the rest rotation.
    Rest,
}

impl Unsensed {
    pub fn label(self) -> &'static str {
        match self {
            Unsensed::Interpolate => "interpolate",
            Unsensed::Rest => "rest",
        }
    }
}

impl std::str::FromStr for Unsensed {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "interpolate" => Ok(Unsensed::Interpolate),
            "rest" => Ok(Unsensed::Rest),
            _ => Err(format!("unknown `{s}`; expected interpolate or rest")),
        }
    }
}

/// An unsensed joint between two sensed ones: the sensed ancestor, the sensed descendant, the
/// fraction of the change between them that this joint takes, and the pose held at calibration
/// (`held`: this joint's local rotation in it; `span_held_inverse`: `H⁻¹`, the inverse of that
/// pose's rotation from the ancestor to the descendant).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Between {
    pub ancestor: usize,
    pub descendant: usize,
    pub fraction: f64,
    pub held: UnitQuaternion<f64>,
    pub span_held_inverse: UnitQuaternion<f64>,
    /// `P_{i−1}`: the held pose's rotation from the ancestor to this joint's parent.
    pub parent_held: UnitQuaternion<f64>,
}

/// How each joint turns when it has no sensor: its share of the bend between two sensed joints
/// (`between`, under [`Unsensed::Interpolate`]), else its rotation in the held pose (`held`).
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    pub between: Vec<Option<Between>>,
    pub held: Vec<UnitQuaternion<f64>>,
}

/// The plan for `rig` with the joints `sensed` driven by sensors, `held` the local rotations of
/// the pose held at calibration (one per joint; identities for the rest pose).
pub fn plan(rig: &Rig, sensed: &[bool], mode: Unsensed, held: &[UnitQuaternion<f64>]) -> Plan {
    let n = rig.len();
    debug_assert_eq!(held.len(), n);
    let mut out = vec![None; n];
    let held_world = rig.world_rotations(held);
    let done = |out| Plan {
        between: out,
        held: held.to_vec(),
    };
    if mode == Unsensed::Rest {
        return done(out);
    }
    let joints = rig.joints();
    let anatomy = Anatomy::of(rig);
    // Sensed joints in the rig's (parents-first) order: each claims the unsensed chain above it.
    for d in (0..n).filter(|&j| sensed[j]) {
        let mut chain = Vec::new();
        let mut j = joints[d].parent;
        while let Some(u) = j {
            if sensed[u] {
                break;
            }
            chain.push(u);
            j = joints[u].parent;
        }
        let Some(a) = j else { continue };
        if chain.is_empty() || chain.iter().any(|u| out[*u].is_some()) {
            continue;
        }
        chain.reverse(); // u_1 (below A) … u_k (above D)
        // A chain that bends evenly along its length: each segment points along the bend's
        // tangent at its middle, so u_i turns by the change of that tangent between its segment
        // and the one before (the segment u_i turns runs from u_i to the next joint, or D), and
        // D keeps the rest — the turn from its segment's middle to its end.
        let lengths: Vec<f64> = chain
            .iter()
            .skip(1)
            .chain(std::iter::once(&d))
            .map(|&j| joints[j].offset.norm())
            .collect();
        let total: f64 = lengths.iter().sum();
        let root_share = limb_root_share(&anatomy, &chain, d);
        let chain_share = if total > 0.0 {
            (total - lengths[lengths.len() - 1] / 2.0) / total
        } else {
            1.0 - 0.5 / lengths.len() as f64
        };
        let mut before = 0.0; // the arc length before segment i
        let mut previous = 0.0; // the tangent's share at the previous segment's middle
        for (i, &u) in chain.iter().enumerate() {
            let middle = if total > 0.0 {
                (before + lengths[i] / 2.0) / total
            } else {
                (i as f64 + 0.5) / lengths.len() as f64
            };
            before += lengths[i];
            let fraction = match root_share {
                // A limb's root takes its fixed share, spread as the bend would spread it.
                Some(share) if chain_share > 0.0 => (middle - previous) * share / chain_share,
                _ => middle - previous,
            };
            previous = middle;
            out[u] = Some(Between {
                ancestor: a,
                descendant: d,
                fraction,
                held: held[u],
                span_held_inverse: held_world[d].inverse() * held_world[a],
                parent_held: held_world[a].inverse()
                    * joints[u].parent.map_or(held_world[a], |p| held_world[p]),
            });
        }
    }
    done(out)
}

/// How much of a limb's turn relative to the trunk the unsensed joints at its root take, when
/// they are the limb's own (no spine, neck or pelvis joint among them): a clavicle
/// ([`CLAVICLE_SHARE`]) before a sensed upper arm, nothing before a sensed thigh (a skeleton's
/// hip offset bone, CMU's `LHipJoint`, is part of the rigid pelvis). `None` elsewhere: the chain
/// bends evenly.
fn limb_root_share(anatomy: &Anatomy, chain: &[usize], descendant: usize) -> Option<f64> {
    let trunk = |j: &usize| {
        anatomy.spine().contains(j)
            || anatomy.neck().contains(j)
            || anatomy.pelvis() == Some(*j)
            || anatomy.thorax() == Some(*j)
    };
    if chain.iter().any(trunk) {
        return None;
    }
    Side::BOTH.into_iter().find_map(|side| {
        if anatomy.limb(side, Limb::Thigh) == Some(descendant) {
            Some(0.0)
        } else if anatomy.limb(side, Limb::UpperArm) == Some(descendant) {
            Some(CLAVICLE_SHARE)
        } else {
            None
        }
    })
}

/// Which joints the animation keys: the sensed ones, (under [`Unsensed::Interpolate`]) the
/// unsensed ones between two sensed joints, which share the bend between them, and those held
/// away from their rest rotation (`held`: the pose held at calibration). The others stay at rest.
pub fn moving(
    rig: &Rig,
    sensed: &[bool],
    mode: Unsensed,
    held: &[UnitQuaternion<f64>],
) -> Vec<bool> {
    let plan = plan(rig, sensed, mode, held);
    plan.between
        .iter()
        .zip(sensed)
        .zip(&plan.held)
        .map(|((between, sensed), held)| *sensed || between.is_some() || held.angle() > 1e-12)
        .collect()
}

/// `world[j]`: the world rotation track of joint j when a sensor drives it (`frames` long);
/// `held`: the local rotations of the pose held at calibration. Returns `local[j][frame]`.
///
/// A sensed joint's local track is written over its world track: each run of frames is read
/// before it is written, and the memory is already the process's (a fresh track would be faulted
/// in page by page: ~2 µs a page here, 27 000 pages for an hour's sixteen sensors).
pub fn to_local(
    rig: &Rig,
    world: Vec<Option<Vec<UnitQuaternion<f64>>>>,
    frames: usize,
    unsensed: Unsensed,
    held: &[UnitQuaternion<f64>],
) -> Vec<Vec<UnitQuaternion<f64>>> {
    let n = rig.len();
    let sensed: Vec<bool> = world.iter().map(Option::is_some).collect();
    let plan = plan(rig, &sensed, unsensed, held);
    // The others allocated (and first touched) on every core too.
    let mut local: Vec<Vec<UnitQuaternion<f64>>> = world
        .into_par_iter()
        .map(|track| match track {
            Some(track) => {
                assert_eq!(track.len(), frames, "a world track has one value per frame");
                track
            }
            None => vec![UnitQuaternion::identity(); frames],
        })
        .collect();
    // Frames are independent: blocks of them on every core, each writing its own slice of every
    // joint's track.
    let block = frames.div_ceil(4 * rayon::current_num_threads()).max(1);
    let mut blocks: Vec<Vec<&mut [UnitQuaternion<f64>]>> = (0..frames.div_ceil(block))
        .map(|_| Vec::with_capacity(n))
        .collect();
    for track in &mut local {
        for (b, piece) in track.chunks_mut(block).enumerate() {
            blocks[b].push(piece);
        }
    }
    blocks.into_par_iter().for_each(|mut pieces| {
        let mut frame_world = vec![UnitQuaternion::identity(); n];
        let len = pieces.first().map_or(0, |p| p.len());
        // A few frames at a time, each joint's run read and written in one sweep: going
        // frame by frame hops between every joint's track and waits on memory at each hop.
        let mut worlds = vec![UnitQuaternion::identity(); SWEEP * n];
        let mut locals = vec![UnitQuaternion::identity(); SWEEP * n];
        for start in (0..len).step_by(SWEEP) {
            let count = SWEEP.min(len - start);
            for (j, piece) in pieces.iter().enumerate() {
                if sensed[j] {
                    for (i, q) in piece[start..start + count].iter().enumerate() {
                        worlds[i * n + j] = *q;
                    }
                }
            }
            for i in 0..count {
                frame_to_local(
                    rig,
                    |j| sensed[j].then(|| worlds[i * n + j]),
                    &plan,
                    &mut frame_world,
                    &mut locals[i * n..(i + 1) * n],
                );
            }
            for (j, piece) in pieces.iter_mut().enumerate() {
                for (i, q) in piece[start..start + count].iter_mut().enumerate() {
                    *q = locals[i * n + j];
                }
            }
        }
    });
    local
}

/// Frames [`to_local`] turns from world to local rotations together (a few kB per joint).
const SWEEP: usize = 64;

/// The incremental core: one frame's local rotations (`local`, one per joint) from the world
/// rotations of the joints a sensor drives (`world(j)`); `frame_world` is scratch (one per joint).
/// A joint without a sensor turns as the [`Plan`] says.
pub fn frame_to_local(
    rig: &Rig,
    world: impl Fn(usize) -> Option<UnitQuaternion<f64>>,
    plan: &Plan,
    frame_world: &mut [UnitQuaternion<f64>],
    local: &mut [UnitQuaternion<f64>],
) {
    for (j, joint) in rig.joints().iter().enumerate() {
        let parent_world = joint.parent.map(|p| frame_world[p]);
        frame_world[j] = match (world(j), parent_world) {
            (Some(w), Some(pw)) => {
                local[j] = pw.inverse() * w;
                w
            }
            (Some(w), None) => {
                local[j] = w;
                w
            }
            (None, pw) => {
                let pw = pw.unwrap_or_else(UnitQuaternion::identity);
                // Between two sensed joints: its share of the change between them since the
                // held pose (when both have a value this frame; a stream's stale sensor leaves
                // it as held).
                local[j] = plan
                    .between
                    .get(j)
                    .copied()
                    .flatten()
                    .and_then(|b| {
                        let d = world(b.descendant)?;
                        let change = frame_world[b.ancestor].inverse() * d * b.span_held_inverse;
                        let seen = b.parent_held.inverse() * change * b.parent_held;
                        Some(
                            UnitQuaternion::from_scaled_axis(seen.scaled_axis() * b.fraction)
                                * b.held,
                        )
                    })
                    .unwrap_or(plan.held[j]);
                pw * local[j]
            }
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::load_rig;
    use nalgebra::Vector3;

    #[test]
    fn locals_recompose_to_worlds_and_unmapped_joints_stay_at_rest() {
        let rig = load_rig("mixamo").unwrap();
        let hips = rig.joint_index("Hips").unwrap();
        let spine = rig.joint_index("Spine").unwrap();
        let arm = rig.joint_index("LeftArm").unwrap();
        let mut world = vec![None; rig.len()];
        let h = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.7);
        let a = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -1.2);
        world[hips] = Some(vec![h; 2]);
        world[arm] = Some(vec![a; 2]);
        let rest = vec![UnitQuaternion::identity(); rig.len()];
        let local = to_local(&rig, world.clone(), 2, Unsensed::Rest, &rest);
        assert!(local[hips][1].angle_to(&h) < 1e-12);
        assert!(
            local[spine][0].angle() < 1e-12,
            "unmapped spine keeps its rest rotation"
        );
        // LeftArm's parents (LeftShoulder, Spine2, Spine1, Spine) are unmapped: its world is
        // hips ⊗ local, so local = h⁻¹ ⊗ a.
        assert!(local[arm][0].angle_to(&(h.inverse() * a)) < 1e-12);
        let recomposed = rig.world_rotations(&local.iter().map(|t| t[0]).collect::<Vec<_>>());
        assert!(recomposed[arm].angle_to(&a) < 1e-12);
    }

    /// Written over the world tracks, run by run on every core: each frame's local rotations are
    /// those the per-frame core computes from untouched copies (to the bit), and they recompose to
    /// every sensor's world rotation. Over 1 000 frames, so that blocks and their runs of
    /// [`SWEEP`] frames end in the middle.
    #[test]
    fn locals_written_over_the_world_tracks_match_the_per_frame_core() {
        let rig = load_rig("mixamo").unwrap();
        let idx = |n: &str| rig.joint_index(n).unwrap();
        let frames = 1000;
        let mut world = vec![None; rig.len()];
        let sensed = [
            "Hips",
            "Spine2",
            "LeftArm",
            "LeftForeArm",
            "RightUpLeg",
            "Head",
        ];
        for (s, name) in sensed.iter().enumerate() {
            let track = (0..frames)
                .map(|f| {
                    let t = f as f64 * 0.01 + s as f64;
                    let axis = Vector3::new((t * 1.7).sin(), 1.0, (t * 0.3 + s as f64).cos());
                    UnitQuaternion::from_scaled_axis(axis.normalize() * (t * 2.3).sin() * 2.0)
                })
                .collect::<Vec<_>>();
            world[idx(name)] = Some(track);
        }
        let held = vec![UnitQuaternion::identity(); rig.len()];
        for mode in [Unsensed::Interpolate, Unsensed::Rest] {
            let local = to_local(&rig, world.clone(), frames, mode, &held);
            let flags: Vec<bool> = world.iter().map(Option::is_some).collect();
            let plan = plan(&rig, &flags, mode, &held);
            let mut frame_world = vec![UnitQuaternion::identity(); rig.len()];
            let mut expected = vec![UnitQuaternion::identity(); rig.len()];
            for f in 0..frames {
                let at = |j: usize| world[j].as_ref().map(|t| t[f]);
                frame_to_local(&rig, at, &plan, &mut frame_world, &mut expected);
                let got: Vec<_> = local.iter().map(|t| t[f]).collect();
                assert_eq!(got, expected, "{mode:?} frame {f}");
                let worlds = rig.world_rotations(&got);
                for name in sensed {
                    let want = world[idx(name)].as_ref().unwrap()[f];
                    assert!(
                        worlds[idx(name)].angle_to(&want) < 1e-12,
                        "{name} frame {f}"
                    );
                }
            }
        }
    }

    /// A limb's root is not a bending chain: an unsensed clavicle takes CLAVICLE_SHARE of the
    /// upper arm's turn (an evenly bending chain would give it half), a hip offset bone none
    /// (the pelvis is rigid), and the sensed bones still land where their sensors say.
    #[test]
    fn a_clavicle_takes_a_small_share_and_a_hip_offset_none() {
        let text = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/mixamo.yaml"),
        )
        .unwrap()
        .replace(
            "  - {name: LeftUpLeg, parent: Hips, offset: [0.095, -0.0725, 0.0]}",
            "  - {name: LHipJoint, parent: Hips, offset: [0.05, -0.04, 0.0]}\n  - {name: LeftUpLeg, parent: LHipJoint, offset: [0.045, -0.0325, 0.0]}",
        );
        let rig =
            crate::rig::file::parse_rig(&text, std::path::Path::new("hip_offset.yaml")).unwrap();
        let idx = |n: &str| rig.joint_index(n).unwrap();
        let z = |deg: f64| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), deg.to_radians());
        let mut world = vec![None; rig.len()];
        for name in ["Hips", "Spine2"] {
            world[idx(name)] = Some(vec![UnitQuaternion::identity()]);
        }
        // The arm comes down from the T-pose, the thigh swings out.
        world[idx("LeftArm")] = Some(vec![z(-80.0)]);
        world[idx("LeftUpLeg")] = Some(vec![z(30.0)]);
        let rest = vec![UnitQuaternion::identity(); rig.len()];
        let local = to_local(&rig, world.clone(), 1, Unsensed::Interpolate, &rest);
        let clavicle = local[idx("LeftShoulder")][0].angle().to_degrees();
        assert!(
            (clavicle - 80.0 * CLAVICLE_SHARE).abs() < 1e-9,
            "{clavicle}"
        );
        assert!(local[idx("LHipJoint")][0].angle() < 1e-12);
        let worlds = rig.world_rotations(&local.iter().map(|t| t[0]).collect::<Vec<_>>());
        assert!(worlds[idx("LeftArm")].angle_to(&z(-80.0)) < 1e-12);
        assert!(worlds[idx("LeftUpLeg")].angle_to(&z(30.0)) < 1e-12);
    }

    /// Hips and Spine2 sensed, Spine and Spine1 between them: a 60° bend about x shares by the
    /// segments Spine and Spine1 turn (Spine → Spine1, Spine1 → Spine2) and the one ending at
    /// Spine2, which lands exactly where its sensor says; the neck above (no sensed descendant)
    /// stays at rest.
    #[test]
    fn a_chain_between_two_sensors_shares_the_bend() {
        let rig = load_rig("mixamo").unwrap();
        let idx = |n: &str| rig.joint_index(n).unwrap();
        let mut world = vec![None; rig.len()];
        let h = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.4);
        let bend = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 60f64.to_radians());
        world[idx("Hips")] = Some(vec![h]);
        world[idx("Spine2")] = Some(vec![h * bend]);
        let rest = vec![UnitQuaternion::identity(); rig.len()];
        let local = to_local(&rig, world.clone(), 1, Unsensed::Interpolate, &rest);
        // Two equal segments (Spine → Spine1 → Spine2, 0.12 m each): ¼, ½ and ¼ of the bend.
        for (n, share) in ["Spine", "Spine1", "Spine2"].iter().zip([0.25, 0.5, 0.25]) {
            let angle = local[idx(n)][0].angle().to_degrees();
            assert!((angle - 60.0 * share).abs() < 1e-9, "{n}: {angle}");
        }
        let worlds = rig.world_rotations(&local.iter().map(|t| t[0]).collect::<Vec<_>>());
        assert!(worlds[idx("Spine2")].angle_to(&(h * bend)) < 1e-12);
        assert!(local[idx("Neck")][0].angle() < 1e-12);
        let sensed: Vec<bool> = world.iter().map(Option::is_some).collect();
        let p = plan(&rig, &sensed, Unsensed::Interpolate, &rest).between;
        assert_eq!(p[idx("Spine")].unwrap().descendant, idx("Spine2"));
        assert!(p[idx("Neck")].is_none() && p[idx("Spine2")].is_none());
        assert!(
            plan(&rig, &sensed, Unsensed::Rest, &rest)
                .between
                .iter()
                .all(Option::is_none)
        );
    }

    /// The subject held a pose with the spine bent (Spine 20° and Spine1 10° about x, the neck
    /// 15°): while the sensors read that pose every unsensed joint is exactly in it, under either
    /// mode; a further 40° between the hips and the chest is shared ¼ ½ ¼ on top of it, and the
    /// chest lands where its sensor says.
    #[test]
    fn unsensed_joints_start_from_the_pose_held_at_calibration() {
        let rig = load_rig("mixamo").unwrap();
        let idx = |n: &str| rig.joint_index(n).unwrap();
        let x = |deg: f64| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), deg.to_radians());
        let mut held = vec![UnitQuaternion::identity(); rig.len()];
        held[idx("Spine")] = x(20.0);
        held[idx("Spine1")] = x(10.0);
        held[idx("Neck")] = x(15.0);
        let held_world = rig.world_rotations(&held);
        let h = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.4);
        let chest_in_pose = h * held_world[idx("Spine2")];
        let mut world = vec![None; rig.len()];
        world[idx("Hips")] = Some(vec![h, h]);
        // Frame 0: the pose; frame 1: the chest bent 40° further (about the pose's chest x axis).
        world[idx("Spine2")] = Some(vec![chest_in_pose, h * x(70.0)]);
        for mode in [Unsensed::Interpolate, Unsensed::Rest] {
            let local = to_local(&rig, world.clone(), 2, mode, &held);
            for n in ["Spine", "Spine1", "Spine2", "Neck", "Head"] {
                let expected = if n == "Spine2" {
                    UnitQuaternion::identity()
                } else {
                    held[idx(n)]
                };
                assert!(local[idx(n)][0].angle_to(&expected) < 1e-12, "{mode:?} {n}");
            }
            assert!(local[idx("Neck")][1].angle_to(&held[idx("Neck")]) < 1e-12);
        }
        let local = to_local(&rig, world.clone(), 2, Unsensed::Interpolate, &held);
        for (n, bend) in [
            ("Spine", 20.0 + 10.0),
            ("Spine1", 10.0 + 20.0),
            ("Spine2", 10.0),
        ] {
            let angle = local[idx(n)][1].angle().to_degrees();
            assert!((angle - bend).abs() < 1e-9, "{n}: {angle}");
        }
        let worlds = rig.world_rotations(&local.iter().map(|t| t[1]).collect::<Vec<_>>());
        assert!(worlds[idx("Spine2")].angle_to(&(h * x(70.0))) < 1e-12);
        // Under `rest` the whole 40° is the chest's own.
        let local = to_local(&rig, world.clone(), 2, Unsensed::Rest, &held);
        assert!((local[idx("Spine2")][1].angle().to_degrees() - 40.0).abs() < 1e-9);
    }
}
