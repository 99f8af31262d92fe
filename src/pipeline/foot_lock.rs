//! Stage 8, foot lock (`--foot-lock`): a planted foot stays where it stands.
//!
//! The root stage ([`super::root`]) moves the hips so that the foot carrying the body holds
//! still; but where each foot is relative to the hips comes from its leg's sensors, so a foot
//! planted while the other carries (standing, double support) moves with whatever moves the feet
//! relative to each other — the sensors' noise, and the subject's own slips. CMU 01_01's standing
//! feet travel about 0.02 h per contact more than the source's that way, which an animator sees
//! as sliding. The root stage measures, each frame, how far the point each foot pivots on (the
//! lowest of its points a frame before: heel, sole or toes) moved over the ground
//! ([`super::root::RootFrame::slip`]). Over each contact `[s, e]` the foot is moved back by what
//! its pivot slipped since the contact began, horizontally (rig units):
//!
//! ```text
//! c(s) = 0,   c(t) = c(t − 1) − slip(t)   for s < t ≤ e
//! ```
//!
//! so its pivot stays where it landed while the foot still rolls over its heel or toes as
//! measured; after the contact the last correction fades out linearly over [`FADE_S`], so
//! nothing jumps when the foot lifts (and a contact that starts before it has faded starts from
//! what is left instead of nil, so nothing jumps when it lands again either). Heights stay the
//! root stage's (each foot on its surface).
//!
//! The foot is moved by turning its leg — two-bone inverse kinematics, per frame, with `H`, `K`,
//! `A` the hip (thigh joint), knee (shank joint) and ankle (foot joint), `a = |K − H|`,
//! `b = |A − K|`, the target `T = A + c` and `d = |T − H|` (kept within `[|a − b|, a + b]` by
//! [`REACH`], so a target out of reach straightens the leg towards it):
//! 1. the knee bends by `α = θ − θ'` about `n = (K − H) × (A − K)` (the plane the leg bends in
//!    stays), `θ` the knee's angle now and `θ' = acos((a² + b² − d²) / 2ab)` the one that puts
//!    the ankle `d` from the hip (law of cosines);
//! 2. the whole leg swings about the hip by the shortest rotation taking the hip-to-ankle
//!    direction onto `T − H`;
//! 3. the foot (and the toes below it) keeps its world rotation, which its sensor measured.
//!
//! Joints between the thigh and the shank or between the shank and the foot (roll bones) turn
//! with the segment they belong to. The price: wherever the subject's feet did slip, or a rigid
//! sole rocks from heel to toes, the thighs and shanks turn away from what their sensors measured
//! — on CMU 01_01 with 0.5° of noise 0.91–1.14° RMS instead of 0.42–0.43°
//! (`closed_loop::the_foot_lock_turns_only_the_legs`), up to 3.3° without noise, as its source's
//! feet slip up to 0.03 h over a long stance — which is why the lock is asked for
//! (`--foot-lock`), not done by default. The correction needs only the frames before it, so a
//! stream (`live`, `--causal`) locks each pose as it comes ([`FootLockCore`], from the stream's
//! root core's contacts and slips), the same way.

use crate::rig::Rig;
use crate::rig::anatomy::{Anatomy, Limb, Side};
use nalgebra::{Unit, UnitQuaternion, Vector3};
use rayon::prelude::*;

/// After a contact its last correction fades out over this long, s.
pub const FADE_S: f64 = 0.1;
/// The hip-to-target distance is kept this far inside the leg's reach (a fraction of the
/// shorter segment), so the knee's angle stays away from the straight and folded singularities.
pub const REACH: f64 = 1e-3;

/// A leg's joints: the thigh (hip), the shank (knee), the foot (ankle), and the joints between.
#[derive(Debug, Clone)]
struct Leg {
    thigh: usize,
    shank: usize,
    foot: usize,
    /// Joints strictly between the thigh and the shank (they swing with the thigh).
    upper: Vec<usize>,
    /// Joints strictly between the shank and the foot (they turn with the shank).
    lower: Vec<usize>,
}

impl Leg {
    /// The leg of `side`, when the rig's anatomy finds its thigh, shank and foot, each below the
    /// one before.
    fn of(rig: &Rig, anatomy: &Anatomy, side: Side) -> Option<Leg> {
        let thigh = anatomy.limb(side, Limb::Thigh)?;
        let shank = anatomy.limb(side, Limb::Shank)?;
        let foot = anatomy.limb(side, Limb::Foot)?;
        let upper = between(rig, thigh, shank)?;
        let lower = between(rig, shank, foot)?;
        Some(Leg {
            thigh,
            shank,
            foot,
            upper,
            lower,
        })
    }
}

/// The joints strictly between `top` and `bottom` (top first) when `top` is an ancestor of
/// `bottom`.
fn between(rig: &Rig, top: usize, bottom: usize) -> Option<Vec<usize>> {
    let mut chain = Vec::new();
    let mut j = rig.joints()[bottom].parent?;
    while j != top {
        chain.push(j);
        j = rig.joints()[j].parent?;
    }
    chain.reverse();
    Some(chain)
}

/// Per frame, how far to move the foot (horizontally, rig units) so that the point it pivots on
/// holds still over each contact: inside a contact the slips since its first frame taken back,
/// `c(t) = c(t − 1) − slip(t)` from `c(s) = 0`; after it the last correction fades out linearly
/// over `fade` frames (a contact that starts before it has faded starts from what is left, so the
/// foot does not jump). `planted` and `slip` per frame.
fn corrections(planted: &[bool], slip: &[Vector3<f64>], fade: usize) -> Vec<Vector3<f64>> {
    let mut foot = Correction::default();
    planted
        .iter()
        .zip(slip)
        .map(|(&planted, &slip)| foot.next(planted, slip, fade))
        .collect()
}

/// [`corrections`] one frame at a time: each needs only the frames before it, so a stream locks
/// its feet as it goes.
#[derive(Debug, Clone, Copy, Default)]
struct Correction {
    /// The correction at the frame before (nil before the first).
    last: Vector3<f64>,
    /// The foot was planted at the frame before.
    was_planted: bool,
    /// After a contact: the frames since it ended and its last correction, while that fades.
    fading: Option<(usize, Vector3<f64>)>,
}

impl Correction {
    /// The correction at the next frame, where the foot is `planted` or not and its pivot
    /// slipped `slip` since the frame before.
    fn next(&mut self, planted: bool, slip: Vector3<f64>, fade: usize) -> Vector3<f64> {
        let c = if planted {
            // A contact's first frame starts from where the foot is put now (nil, or what is left
            // of the last contact's correction while it fades): its pivot stays where it landed.
            let c = if self.was_planted {
                self.last - slip
            } else {
                self.last
            };
            self.fading = Some((0, c));
            c
        } else {
            match self.fading {
                Some((k, last)) if k < fade => {
                    self.fading = Some((k + 1, last));
                    last * (1.0 - (k + 1) as f64 / (fade + 1) as f64)
                }
                _ => {
                    self.fading = None;
                    Vector3::zeros()
                }
            }
        };
        self.last = c;
        self.was_planted = planted;
        c
    }
}

/// The rotation taking direction `from` onto `to` by the shortest arc (identity when either is
/// nil or they are opposite — a leg never needs half a turn).
fn swing(from: &Vector3<f64>, to: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::rotation_between(from, to).unwrap_or_else(UnitQuaternion::identity)
}

/// Two-bone IK on one leg at one frame: the world rotations of the thigh, the joints between,
/// the shank and the foot after putting the ankle at `target` (see the module). `world` and
/// `positions` are the frame's forward kinematics.
fn reach(
    leg: &Leg,
    world: &mut [UnitQuaternion<f64>],
    positions: &[Vector3<f64>],
    target: Vector3<f64>,
) {
    let (hip, knee, ankle) = (
        positions[leg.thigh],
        positions[leg.shank],
        positions[leg.foot],
    );
    let (a, b) = ((knee - hip).norm(), (ankle - knee).norm());
    if a <= 0.0 || b <= 0.0 {
        return;
    }
    let margin = REACH * a.min(b);
    let d = (target - hip)
        .norm()
        .clamp((a - b).abs() + margin, a + b - margin);
    let cos_angle =
        |u: Vector3<f64>, v: Vector3<f64>| (u.dot(&v) / (u.norm() * v.norm())).clamp(-1.0, 1.0);
    let theta = cos_angle(hip - knee, ankle - knee).acos();
    let wanted = ((a * a + b * b - d * d) / (2.0 * a * b))
        .clamp(-1.0, 1.0)
        .acos();
    // The knee bends in the plane it bends in now; a straight leg has none, and stays straight
    // (it only swings).
    let bend = Unit::try_new((knee - hip).cross(&(ankle - knee)), 1e-12 * a * b)
        .map_or_else(UnitQuaternion::identity, |n| {
            UnitQuaternion::from_axis_angle(&n, theta - wanted)
        });
    let bent_ankle = knee + bend * (ankle - knee);
    let turn = swing(&(bent_ankle - hip), &(target - hip));
    // The foot and the joints below it keep their world rotations: left as they are.
    for &j in std::iter::once(&leg.thigh).chain(&leg.upper) {
        world[j] = turn * world[j];
    }
    for &j in std::iter::once(&leg.shank).chain(&leg.lower) {
        world[j] = turn * bend * world[j];
    }
}

/// One frame's new local rotations: (joint, rotation).
type Changes = Vec<(usize, UnitQuaternion<f64>)>;

/// A rig's legs for the lock, and the joints whose local rotations it changes on each: the legs'
/// down to the feet (the toes' parents keep their world rotations, so theirs do not change).
#[derive(Debug, Clone)]
struct Legs {
    legs: [Option<Leg>; 2],
    changed: [Vec<usize>; 2],
}

impl Legs {
    /// `None` when the rig's anatomy finds neither leg.
    fn of(rig: &Rig) -> Option<Legs> {
        let anatomy = Anatomy::of(rig);
        let legs = Side::BOTH.map(|side| Leg::of(rig, &anatomy, side));
        if legs.iter().all(Option::is_none) {
            return None;
        }
        let changed = legs.each_ref().map(|leg| {
            leg.as_ref().map_or_else(Vec::new, |l| {
                let mut joints = vec![l.thigh];
                joints.extend(&l.upper);
                joints.push(l.shank);
                joints.extend(&l.lower);
                joints.push(l.foot);
                joints
            })
        });
        Some(Legs { legs, changed })
    }

    /// One frame: into `out`, the new local rotations that put each foot `shifts` (rig units)
    /// from where the pose `local` with its root at `root` has it; nothing for a foot not moved.
    /// `world` and `positions`: scratch for the frame's forward kinematics.
    fn lock(
        &self,
        rig: &Rig,
        (local, root): (&[UnitQuaternion<f64>], Vector3<f64>),
        shifts: [Vector3<f64>; 2],
        (world, positions): (&mut Vec<UnitQuaternion<f64>>, &mut Vec<Vector3<f64>>),
        out: &mut Changes,
    ) {
        out.clear();
        let moved = |s: usize| self.legs[s].is_some() && shifts[s] != Vector3::zeros();
        if !moved(0) && !moved(1) {
            return;
        }
        rig.world_pose_into(local, root, world, positions);
        for (s, leg) in self.legs.iter().enumerate() {
            let Some(leg) = leg.as_ref().filter(|_| moved(s)) else {
                continue;
            };
            reach(leg, world, positions, positions[leg.foot] + shifts[s]);
            // Back to local rotations: q_local = q_world_parent⁻¹ q_world.
            out.extend(self.changed[s].iter().map(|&j| {
                let q = match rig.joints()[j].parent {
                    Some(p) => world[p].inverse() * world[j],
                    None => world[j],
                };
                (j, q)
            }));
        }
    }
}

/// The fade after a contact in frames, [`FADE_S`] at `frame_time_s`.
fn fade_frames(frame_time_s: f64) -> usize {
    (FADE_S / frame_time_s).round().max(0.0) as usize
}

/// Stage 8 over a whole take: `local[joint][frame]` with each planted foot held where it stands
/// over its contact (see the module). `roots`: the root position per frame (rig units);
/// `contacts`: per frame, left and right planted; `slips`: per frame, how far each foot's pivot
/// moved over the ground since the frame before (the root stage's
/// [`super::root::RootFrame::slip`]); `frame_time_s`: the frames' spacing. A rig whose legs the
/// anatomy does not find is left as it is.
pub fn lock_feet(
    rig: &Rig,
    local: &mut [Vec<UnitQuaternion<f64>>],
    roots: &[Vector3<f64>],
    contacts: &[[bool; 2]],
    slips: &[[Vector3<f64>; 2]],
    frame_time_s: f64,
) {
    let frames = roots.len().min(contacts.len()).min(slips.len());
    let Some(legs) = Legs::of(rig).filter(|_| frames > 0) else {
        return;
    };
    let fade = fade_frames(frame_time_s);
    let shifts = [0, 1].map(|side| {
        let planted: Vec<bool> = contacts[..frames].iter().map(|c| c[side]).collect();
        let slip: Vec<Vector3<f64>> = slips[..frames].iter().map(|s| s[side]).collect();
        corrections(&planted, &slip, fade)
    });
    // In blocks of frames, each block's frames on the pool: what a block changes is held at once,
    // not a whole take's.
    const BLOCK: usize = 4096;
    for start in (0..frames).step_by(BLOCK) {
        let block: Vec<(usize, Changes)> = (start..(start + BLOCK).min(frames))
            .into_par_iter()
            .filter_map(|t| {
                let shift = [shifts[0][t], shifts[1][t]];
                if shift == [Vector3::zeros(); 2] {
                    return None;
                }
                let pose: Vec<UnitQuaternion<f64>> = local.iter().map(|track| track[t]).collect();
                let mut changes = Vec::new();
                let scratch = (&mut Vec::new(), &mut Vec::new());
                legs.lock(rig, (&pose, roots[t]), shift, scratch, &mut changes);
                Some((t, changes))
            })
            .collect();
        for (t, joints) in block {
            for (j, q) in joints {
                local[j][t] = q;
            }
        }
    }
}

/// Stage 8 frame after frame, for a stream ([`super::stream`]): each pose's planted feet held
/// where they stand as the poses come, by the same corrections as a whole take's (each needs
/// only the frames before it) and the same inverse kinematics. The contacts are the root core's
/// per frame, as the stream reports them (a whole take's leave out those shorter than
/// [`super::root::MIN_FRAMES`], which a stream cannot know yet: a contact of one frame holds
/// the foot one frame).
#[derive(Debug, Clone)]
pub struct FootLockCore {
    legs: Legs,
    fade: usize,
    feet: [Correction; 2],
    // Per-frame buffers (a stream allocates nothing per frame).
    world: Vec<UnitQuaternion<f64>>,
    positions: Vec<Vector3<f64>>,
    changes: Changes,
}

impl FootLockCore {
    /// The lock for `rig`'s legs at frames `frame_time_s` apart; `None` when the rig's anatomy
    /// finds neither leg.
    pub fn new(rig: &Rig, frame_time_s: f64) -> Option<FootLockCore> {
        Some(FootLockCore {
            legs: Legs::of(rig)?,
            fade: fade_frames(frame_time_s),
            feet: [Correction::default(); 2],
            world: Vec::new(),
            positions: Vec::new(),
            changes: Vec::new(),
        })
    }

    /// The next pose: its local rotations `local` (changed in place), its root `root` (rig
    /// units), each foot `planted` or not and how far its pivot slipped over the ground since the
    /// pose before (the root core's [`super::root::RootFrame`]).
    pub fn push(
        &mut self,
        rig: &Rig,
        local: &mut [UnitQuaternion<f64>],
        root: Vector3<f64>,
        planted: [bool; 2],
        slip: [Vector3<f64>; 2],
    ) {
        let fade = self.fade;
        let shifts = [0, 1].map(|f| self.feet[f].next(planted[f], slip[f], fade));
        let scratch = (&mut self.world, &mut self.positions);
        self.legs
            .lock(rig, (local, root), shifts, scratch, &mut self.changes);
        for &(j, q) in &self.changes {
            local[j] = q;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::load_rig;
    use proptest::prelude::*;

    /// The foot and the joints below it (toes), which keep their world rotations.
    fn below(rig: &Rig, leg: &Leg) -> Vec<usize> {
        // Parents come before their children in a rig, so one pass finds the subtree.
        let mut below = vec![leg.foot];
        for (i, j) in rig.joints().iter().enumerate().skip(leg.foot + 1) {
            if j.parent.is_some_and(|p| below.contains(&p)) {
                below.push(i);
            }
        }
        below
    }

    fn locals_of(rig: &Rig, world: &[UnitQuaternion<f64>]) -> Vec<UnitQuaternion<f64>> {
        rig.joints()
            .iter()
            .enumerate()
            .map(|(i, j)| j.parent.map_or(world[i], |p| world[p].inverse() * world[i]))
            .collect()
    }

    /// The mixamo rig's left leg in a pose: thigh flexed by `hip_deg` about x, knee bent by
    /// `knee_deg`, foot pitched by `foot_deg` and turned 10° about y.
    fn bent_leg(
        hip_deg: f64,
        knee_deg: f64,
        foot_deg: f64,
    ) -> (Rig, Leg, Vec<UnitQuaternion<f64>>) {
        let rig = load_rig("mixamo").unwrap();
        let leg = Leg::of(&rig, &Anatomy::of(&rig), Side::Left).unwrap();
        let mut local = vec![UnitQuaternion::identity(); rig.len()];
        let x = |deg: f64| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), deg.to_radians());
        local[leg.thigh] = x(-hip_deg);
        local[leg.shank] = x(knee_deg);
        local[leg.foot] =
            x(foot_deg) * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 10f64.to_radians());
        (rig, leg, local)
    }

    /// What [`shifted`] returns: the target, the world rotations before, the positions and world
    /// rotations after.
    type Shifted = (
        Vector3<f64>,
        Vec<UnitQuaternion<f64>>,
        Vec<Vector3<f64>>,
        Vec<UnitQuaternion<f64>>,
    );

    /// Puts the left ankle `shift` from where it is: the new locals, and the forward kinematics
    /// before and after.
    fn shifted(
        rig: &Rig,
        leg: &Leg,
        local: &[UnitQuaternion<f64>],
        shift: Vector3<f64>,
    ) -> Shifted {
        let root = rig.joints()[0].offset;
        let (mut world, positions) = rig.world_pose(local, root);
        let before = world.clone();
        let target = positions[leg.foot] + shift;
        reach(leg, &mut world, &positions, target);
        let (after_world, after_positions) = rig.world_pose(&locals_of(rig, &world), root);
        assert!(
            after_world
                .iter()
                .zip(&world)
                .all(|(a, b)| a.angle_to(b) < 1e-9)
        );
        (target, before, after_positions, after_world)
    }

    /// A target within reach: the ankle is put on it; the knee's angle is the law of cosines'
    /// for the hip-to-target distance, by hand; the foot and toes keep their world rotations;
    /// the hips and the other leg do not move.
    #[test]
    fn the_ankle_reaches_its_target_and_the_foot_keeps_its_turn() {
        let (rig, leg, local) = bent_leg(25.0, 40.0, -15.0);
        let (_, positions) = rig.world_pose(&local, rig.joints()[0].offset);
        let a = (positions[leg.shank] - positions[leg.thigh]).norm();
        let b = (positions[leg.foot] - positions[leg.shank]).norm();
        let shift = Vector3::new(0.03, -0.01, -0.02) * (a + b);
        let (target, before, after, after_world) = shifted(&rig, &leg, &local, shift);
        assert!((after[leg.foot] - target).norm() < 1e-9 * (a + b));
        let d = (target - positions[leg.thigh]).norm();
        let knee =
            (after[leg.thigh] - after[leg.shank]).angle(&(after[leg.foot] - after[leg.shank]));
        let by_hand = ((a * a + b * b - d * d) / (2.0 * a * b)).acos();
        assert!((knee - by_hand).abs() < 1e-9, "{knee} vs {by_hand}");
        for &j in &below(&rig, &leg) {
            assert!(
                after_world[j].angle_to(&before[j]) < 1e-9,
                "{}",
                rig.joints()[j].name
            );
        }
        let right = Leg::of(&rig, &Anatomy::of(&rig), Side::Right).unwrap();
        for j in [0, right.thigh, right.shank, right.foot] {
            assert!((after[j] - positions[j]).norm() < 1e-12);
            assert!(after_world[j].angle_to(&before[j]) < 1e-12);
        }
    }

    /// A contact over frames 4–7 of 14, two frames of fade: nil at its first frame, then the
    /// slips since taken back (by hand: −1, −1 − 2, −1 − 2 − 4 along x), then 2/3 and 1/3 of the
    /// last; nothing before it, nor after the fade.
    #[test]
    fn a_contact_takes_back_its_slips_and_fades_after() {
        let planted: Vec<bool> = (0..14).map(|t| (4..=7).contains(&t)).collect();
        let slip: Vec<Vector3<f64>> = (0..14)
            .map(|t| {
                Vector3::new(
                    if (5..=7).contains(&t) {
                        f64::from(1 << (t - 5))
                    } else {
                        9.0
                    },
                    0.0,
                    0.0,
                )
            })
            .collect();
        let c = corrections(&planted, &slip, 2);
        let x: Vec<f64> = c.iter().map(|v| v.x).collect();
        let expected = [
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            -1.0,
            -3.0,
            -7.0,
            -7.0 * 2.0 / 3.0,
            -7.0 / 3.0,
            0.0,
            0.0,
            0.0,
            0.0,
        ];
        for (t, (got, want)) in x.iter().zip(expected).enumerate() {
            assert!((got - want).abs() < 1e-12, "frame {t}: {got} vs {want}");
        }
        // A second contact from frame 10, while the first's correction still fades (three frames
        // of fade: −7 · 3/4 at frame 8, −7 · 2/4 at 9): it starts from what is left at frame 9,
        // −7/2, and takes its slips back (−9 at frame 11).
        let again: Vec<bool> = (0..14).map(|t| (4..=7).contains(&t) || t >= 10).collect();
        let c = corrections(&again, &slip, 3);
        assert!((c[9].x + 7.0 / 2.0).abs() < 1e-12, "{}", c[9].x);
        assert!((c[10].x + 7.0 / 2.0).abs() < 1e-12, "{}", c[10].x);
        assert!((c[11].x + 7.0 / 2.0 + 9.0).abs() < 1e-12, "{}", c[11].x);
    }

    /// A planted foot on a jittering leg, the slips its pivot would have (here the ankle's own
    /// motion: the foot keeps its turn, so every point of it moves alike): over its contact the
    /// ankle stays where it was at the contact's first frame horizontally, at its own height; the
    /// foot's world rotation never changes; frames beyond the fade and the other leg are
    /// untouched.
    #[test]
    fn a_planted_foot_holds_still_through_the_legs_jitter() {
        let (rig, leg, rest) = bent_leg(10.0, 20.0, -5.0);
        let frames = 40;
        let dt = 1.0 / 60.0;
        let mut local: Vec<Vec<UnitQuaternion<f64>>> =
            rest.iter().map(|&q| vec![q; frames]).collect();
        #[allow(clippy::needless_range_loop)] // t is the frame, for both legs' tracks
        for t in 0..frames {
            let jitter = |k: f64| {
                UnitQuaternion::from_scaled_axis(
                    Vector3::new((t as f64 * k).sin(), (t as f64 * 1.7 * k).cos(), 0.3)
                        * 0.5f64.to_radians(),
                )
            };
            local[leg.thigh][t] = jitter(1.3) * local[leg.thigh][t];
            local[leg.shank][t] = jitter(2.9) * local[leg.shank][t];
        }
        let roots = vec![rig.joints()[0].offset; frames];
        let contacts: Vec<[bool; 2]> = (0..frames)
            .map(|t| [(10..30).contains(&t), false])
            .collect();
        let before = local.clone();
        let fk = |local: &[Vec<UnitQuaternion<f64>>], t: usize| {
            let pose: Vec<UnitQuaternion<f64>> = local.iter().map(|track| track[t]).collect();
            rig.world_pose(&pose, roots[t])
        };
        let was: Vec<Vector3<f64>> = (0..frames).map(|t| fk(&before, t).1[leg.foot]).collect();
        let slips: Vec<[Vector3<f64>; 2]> = (0..frames)
            .map(|t| {
                let d = if t == 0 {
                    Vector3::zeros()
                } else {
                    was[t] - was[t - 1]
                };
                [Vector3::new(d.x, 0.0, d.z), Vector3::zeros()]
            })
            .collect();
        lock_feet(&rig, &mut local, &roots, &contacts, &slips, dt);
        let landed = was[10];
        let spread = was[10..30]
            .iter()
            .map(|p| (p.xz() - landed.xz()).norm())
            .fold(0.0, f64::max);
        assert!(spread > 1e-3, "the jitter moves the ankle: {spread}");
        let fade = (FADE_S / dt).round() as usize;
        for t in 0..frames {
            let (w0, p0) = fk(&before, t);
            let (w1, p1) = fk(&local, t);
            for &j in &below(&rig, &leg) {
                assert!(w1[j].angle_to(&w0[j]) < 1e-9, "frame {t}");
            }
            if (10..30).contains(&t) {
                assert!((p1[leg.foot].xz() - landed.xz()).norm() < 1e-9, "frame {t}");
                assert!((p1[leg.foot].y - p0[leg.foot].y).abs() < 1e-9, "frame {t}");
            }
            if t + fade < 10 || t > 29 + fade {
                assert!(
                    local.iter().zip(&before).all(|(a, b)| a[t] == b[t]),
                    "frame {t}"
                );
            }
            assert!(local.iter().zip(&before).enumerate().all(|(j, (a, b))| {
                below(&rig, &leg).contains(&j) || j == leg.thigh || j == leg.shank || a[t] == b[t]
            }));
        }
    }

    /// A stream's lock ([`FootLockCore`], pose after pose) turns the legs exactly as a whole
    /// take's ([`lock_feet`]) for the same contacts and slips: here both legs jitter, each foot
    /// with contacts of its own (one with a gap of one frame) and slips of
    /// 1 mm along x and 2 mm along z a frame.
    #[test]
    fn a_stream_locks_as_a_whole_take_does() {
        let (rig, _, rest) = bent_leg(10.0, 20.0, -5.0);
        let anatomy = Anatomy::of(&rig);
        let legs = Side::BOTH.map(|side| Leg::of(&rig, &anatomy, side).unwrap());
        let frames = 50;
        let dt = 1.0 / 60.0;
        let mut local: Vec<Vec<UnitQuaternion<f64>>> =
            rest.iter().map(|&q| vec![q; frames]).collect();
        for (k, leg) in legs.iter().enumerate() {
            for (t, q) in local[leg.shank].iter_mut().enumerate() {
                let angle = ((t + 7 * k) as f64 * 0.9).sin() * 2f64.to_radians();
                *q = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), angle) * *q;
            }
        }
        let roots: Vec<Vector3<f64>> = (0..frames)
            .map(|t| rig.joints()[0].offset + Vector3::new(0.01 * t as f64, 0.0, 0.0))
            .collect();
        let contacts: Vec<[bool; 2]> = (0..frames)
            .map(|t| [(5..20).contains(&t) && t != 12, (15..40).contains(&t)])
            .collect();
        let slips = vec![[Vector3::new(1e-3, 0.0, 2e-3); 2]; frames];
        let mut whole = local.clone();
        lock_feet(&rig, &mut whole, &roots, &contacts, &slips, dt);
        let mut core = FootLockCore::new(&rig, dt).unwrap();
        let mut changed = 0;
        for t in 0..frames {
            let mut pose: Vec<UnitQuaternion<f64>> = local.iter().map(|track| track[t]).collect();
            core.push(&rig, &mut pose, roots[t], contacts[t], slips[t]);
            for (j, q) in pose.iter().enumerate() {
                assert!(q.angle_to(&whole[j][t]) < 1e-12, "joint {j}, frame {t}");
                changed += usize::from(q.angle_to(&local[j][t]) > 1e-9);
            }
        }
        assert!(changed > 100, "{changed} rotations changed");
    }

    proptest! {
        /// Any pose of the leg and any target: the rotations stay finite and the ankle never ends
        /// farther from the target than it was; within reach (a margin from straight and folded)
        /// it is on it.
        #[test]
        fn reaching_never_moves_the_ankle_away(
            hip in -60.0f64..60.0, knee in 0.0f64..120.0, foot in -40.0f64..40.0,
            sx in -0.5f64..0.5, sy in -0.5f64..0.5, sz in -0.5f64..0.5,
        ) {
            let (rig, leg, local) = bent_leg(hip, knee, foot);
            let (_, positions) = rig.world_pose(&local, rig.joints()[0].offset);
            let a = (positions[leg.shank] - positions[leg.thigh]).norm();
            let b = (positions[leg.foot] - positions[leg.shank]).norm();
            let shift = Vector3::new(sx, sy, sz) * (a + b);
            let (target, _, after, after_world) = shifted(&rig, &leg, &local, shift);
            prop_assert!(after_world.iter().all(|q| q.coords.iter().all(|c| c.is_finite())));
            let gap = (after[leg.foot] - target).norm();
            prop_assert!(gap <= shift.norm() + 1e-9 * (a + b));
            let d = (target - positions[leg.thigh]).norm();
            let margin = 2.0 * REACH * a.min(b);
            // A straight leg has no plane to bend in: only a bent one reaches every target.
            if knee > 1.0 && d > (a - b).abs() + margin && d < a + b - margin {
                prop_assert!(gap < 1e-9 * (a + b), "{gap}");
            }
        }
    }
}
