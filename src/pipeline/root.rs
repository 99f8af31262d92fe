//! Stage 7, root: where the body is in the scene, frame by frame.
//!
//! Modes (`--root`):
//! - `fixed`: the root held at its rest position.
//! - `ground` (paper 000 ch. IV): the root at its rest place horizontally, moved vertically so
//!   that the body's lowest point (joints and end sites) is on the floor — the rest pose's lowest
//!   point's height.
//! - `feet` (paper 003): foot-rooted. Each frame the joints' positions relative to the hips come
//!   from the frame's rotations (forward kinematics, `c_child = c_parent + R_parent · offset`).
//!   Horizontally a planted foot's contact point stays where it is, so the hips move by minus its
//!   motion relative to the hips: `H(t) = H(t−1) − Σ_f w_f (p_f(t) − p_f(t−1))`, `p_f` the point
//!   of foot f's subtree (foot, toes, end sites) that was lowest at `t − 1` (a rolling foot pivots
//!   on its heel, then its toes). Vertically each foot stands on its surface: `H_y = Σ_f w_f
//!   (L_f − y_f)`, `y_f` its lowest point relative to the hips, `L_f` the surface's height — the
//!   other foot's when the weight passes to it, unless the feet are then a step apart
//!   ([`STEP_H`]; a stair, a kerb: the body climbs, as paper 003's does), so sensor error cannot
//!   make the floor wander. A whole take reads that step where both feet stood or where the new
//!   one landed rather than when the weight passes ([`transfer`]), and eases the hips across a
//!   step down's gap (`smooth_gaps`). The contact weights `w_f` score each foot — how much
//!   higher it is than the other, how fast it moves over the ground (its motion relative to the
//!   hips plus the hips' recent velocity: nil for a planted foot whichever way the body moves —
//!   forwards, backwards, sideways), how fast it rises relative to the hips (a foot pushing off
//!   rises first), how fast it goes down over the ground (a foot on its way down has not landed:
//!   a step down) — and blend smoothly between alike feet (double support), so a switch never
//!   jumps.
//!   A whole take decides the weights over all its frames instead ([`support`]: the foot whose
//!   stillness implies the steadiest hips, a Viterbi path), since those scores read the hips'
//!   recent velocity, which follows whichever foot they chose, and so can lock onto a sliding one.
//!   Where the followed foot slid all the same, the hips' velocity leaves its course faster than
//!   friction allows and comes back: a whole take bridges it ([`slide`]).
//!   Paper 003 thresholds the foot's angular speed instead (τ = 0.28 over 3 samples), which
//!   seldom holds on real walks. Where the take has a foot sensor's raw readings, that sensor
//!   says whether the foot turns about a point that stands ([`zupt`]: SHOE's force term about
//!   each of the foot's points): a foot whose every point accelerates by more than
//!   [`UNPLANTED_M_S2`] is not reported planted, one about a nearly still point is. A foot's
//!   points are its joints, their end sites and a heel (a skeleton has none: below the ankle at
//!   the sole's height, [`HEEL_BACK`] of the foot behind it). The body leaves the ground in two
//!   ways: the legs throw the hips up faster than [`TAKEOFF_H_S`] for [`TAKEOFF_S`] (a hop's
//!   push-off), or the feet fall [`FLIGHT_H`] below the ballistic path the hips would have taken
//!   from the last frame the feet held them (the ground only pushes: a body cannot be pulled
//!   down faster than gravity, so feet that would pull it have left the ground — a run's flight,
//!   which rises too little for the first way).
//!   Airborne, the hips keep the horizontal velocity of their last stance (its mean over up to
//!   [`STANCE_S`]) and follow gravity. While they still rise the legs may be
//!   unfolding under the push-off: a foot at its surface then carries them higher and faster
//!   (the take-off velocity is the push's last, not the smoothed one at its start); on the way
//!   down the first foot to reach its surface lands. Nothing goes below the planted foot's
//!   surface (the clamp).
//! - `auto` (the default): `feet` when both legs are sensed down to the feet (the thigh and the
//!   shank of each side: the foot follows the shank when it has no sensor of its own), else
//!   `ground` when both thighs are, else `fixed`.
//!
//! Every threshold is a fraction of the subject's standing height `h` (the rest pose's lowest
//! point to its highest), since rigs come in metres or in any BVH unit; gravity too, g over the
//! subject's height in metres ([`subject_height_m`]). The stage is an
//! incremental core ([`RootCore`]): a frame's local rotations in, its root position and foot
//! contacts out, for a whole take and a stream alike.

pub mod slide;
pub mod support;
pub mod transfer;
pub mod zupt;

use crate::rig::Rig;
use crate::rig::anatomy::{Anatomy, Limb, Side};
use nalgebra::{UnitQuaternion, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RootMode {
    /// Hips held at rest height and place.
    Fixed,
    /// The lowest point on the floor, no horizontal motion.
    Ground,
    /// Foot-rooted: the planted foot stays, the body walks.
    Feet,
    /// `feet`, `ground` or `fixed`, by what the mapping senses.
    #[default]
    Auto,
}

impl RootMode {
    pub fn label(self) -> &'static str {
        match self {
            RootMode::Fixed => "fixed",
            RootMode::Ground => "ground",
            RootMode::Feet => "feet",
            RootMode::Auto => "auto",
        }
    }
}

impl std::str::FromStr for RootMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        [
            RootMode::Fixed,
            RootMode::Ground,
            RootMode::Feet,
            RootMode::Auto,
        ]
        .into_iter()
        .find(|m| m.label() == s)
        .ok_or_else(|| format!("unknown root mode `{s}`; expected fixed, ground, feet or auto"))
    }
}

/// A foot this much higher than the other scores one unit against carrying the body, × h
/// (the weights go from one foot to the other over two units).
pub const BAND_H: f64 = 0.004;
/// So does this much horizontal speed over the ground, × h / s (a planted foot has none, a
/// swinging one about twice the body's)…
pub const SPEED_H_S: f64 = 0.1;
/// … and this much rising relative to the hips, × h / s (a foot pushing off rises first).
pub const RISE_H_S: f64 = 0.1 / 6.0;
/// … and this much going down over the ground (its motion relative to the hips plus theirs),
/// × h / s: a foot still on its way down has not landed. Without it the weight passed to a foot
/// stepping down before it got there, so a step down's height was missed while a step up's
/// (whose foot cannot go further) was not, and on rough ground the body climbed
/// (`changing_ground_keeps_each_foot_on_its_own` prints it). Much less lets a walk's landing heel
/// take the weight too late.
pub const DESCENT_H_S: f64 = 0.04;
/// Feet this far apart in height when the weight passes are on different surfaces (a step),
/// × h; closer, they are on the same one.
pub const STEP_H: f64 = 0.06;
/// The planted leg throwing the hips up faster than this is a take-off, × h / s.
pub const TAKEOFF_H_S: f64 = 0.45;
/// … for this long, s.
pub const TAKEOFF_S: f64 = 0.04;
/// Standard gravity, m/s².
pub const GRAVITY_M_S2: f64 = 9.80665;
/// A subject's standing height when the rig's is not a person's, m: a rig whose standing height
/// in metres lies in [`PERSON_HEIGHT_M`] is taken to be the subject's (a body model scaled with
/// `--subject`, an actor's skeleton), else the body is taken to be this tall.
pub const ASSUMED_HEIGHT_M: f64 = 1.75;
/// The standing heights of people, children to the tallest adults, m.
pub const PERSON_HEIGHT_M: std::ops::RangeInclusive<f64> = 1.0..=2.3;
/// The feet's support falling this far below the path the body would have followed had it left
/// the ground (ballistic) is a flight, × h: the ground only pushes, so a body whose feet would
/// pull it down faster than gravity has left it (a run's flight, which rises too little for
/// [`TAKEOFF_H_S`]). Less is not a flight: a toe without a sensor stays rigid where a real one
/// bends, and a toe about 0.04 h long bent 45° at a walk's push-off hides about 0.03 h.
pub const FLIGHT_H: f64 = 0.03;
/// … only after the feet have held the body this long, s (a run's stance lasts 0.1 s or more),
/// with the hips going up no faster than [`TAKEOFF_H_S`] (or [`PUSH_OFF_MAX_H_S`]; the path
/// launched at no more than [`TAKEOFF_H_S`]): the take-off's horizontal velocity is the hips'
/// mean over the stance.
pub const STANCE_S: f64 = 0.1;
/// … × h / s, on one foot for [`STANCE_S`] since the weight last passed to it: a run's push-off
/// sampled at 30 fps or less shows the hips rising a little faster than [`TAKEOFF_H_S`] for a
/// frame, too short for [`TAKEOFF_S`] (CMU 09_01 at 30 fps, seed 5: under 1.25 ×
/// [`TAKEOFF_H_S`]). The weight passing to a foot that stands higher relative to the hips throws
/// them up faster, or as fast just after it, and is no push-off: paths launched there (even at
/// [`TAKEOFF_H_S`]) left the feet 0.03 h below them and made false flights of 9 to 33 frames —
/// CMU 05_05's dance, between 1.5 and 2 × [`TAKEOFF_H_S`], and the uneven-ground walk 03_04
/// within a stance of its transfers. 1.5 × [`TAKEOFF_H_S`].
pub const PUSH_OFF_MAX_H_S: f64 = 0.675;
/// The hips' velocity on the feet is smoothed with this time constant, s — α = 2/3 a frame at
/// 60 fps, 1/(60·ln 3) s — what a take-off or a late-found flight carries. Per frame (α = 2/3
/// at any rate) it lagged by about a frame, 42 ms at 24 fps: a run's push-off, sampled there
/// at about 0.4 h/s, launched its flights at about 0.3 and they stayed on the feet.
pub const VELOCITY_TAU_S: f64 = 0.015_170_654;
/// The heel behind the ankle, as a fraction of the foot's reach from its joint to its toes
/// (the ankle stands about a quarter of the foot's length in front of the heel).
pub const HEEL_BACK: f64 = 0.25;
/// A foot whose own sensor says that none of its points accelerates by less than this, m/s²
/// ([`zupt::Shoe::pivot_acceleration_m_s2`]), is not reported planted: at g a point gains the
/// speed of a foot not in contact in issue 49's rule (0.12 h/s, 0.2 m/s) within a frame at
/// 60 fps. The kinematic cues below read the fused orientations, and a fused foot's error at
/// heel strike and push-off lets a landing or lifting foot pass for still for a frame or two.
pub const UNPLANTED_M_S2: f64 = GRAVITY_M_S2;
/// A foot turning about a point that accelerates by less than this, m/s², is reported planted
/// (if near its surface) though it rolls and its pivot moves over the ground by up to
/// [`PIVOT_SPEED`] × [`PLANT_SPEED_H_S`] by the kinematic cues: the sensor sees the heel or the
/// toes stand where the fused orientations blur them.
pub const PIVOT_M_S2: f64 = GRAVITY_M_S2 / 2.0;
/// See [`PIVOT_M_S2`].
pub const PIVOT_SPEED: f64 = 2.0;
/// A foot whose lowest point is this close to its surface, × h …
pub const PLANT_H: f64 = 0.02;
/// … slower than this over the ground, × h / s …
pub const PLANT_SPEED_H_S: f64 = 0.3;
/// … and whose toes' tip turns about its joint slower than this, × h / s, is reported planted: a
/// foot rolling off its toes or onto its sole is not, though the point it pivots on holds still
/// (the ground-truth rule of issue 49 sees the source's rolling foot move: a real sole rolls,
/// ours pivots on a point). About 7 rad/s for a foot 0.15 h long.
pub const PLANT_ROLL_H_S: f64 = 1.0;
/// A whole take's decoded support passes from one foot to the other over this many frames on
/// each side of the switch ([`support::left_weights`]).
pub const SUPPORT_BLEND_FRAMES: usize = 1;
/// Contacts and airborne stretches shorter than this many frames are not reported.
pub const MIN_FRAMES: usize = 3;

/// A foot: its joint, and the joints of its subtree (toes), each with its end site if any.
#[derive(Debug, Clone)]
struct Foot {
    /// The joints whose positions (and end sites) make the foot's contact points.
    joints: Vec<usize>,
    /// The heel: the sole's point below the foot joint in the standing pose, [`HEEL_BACK`] of the
    /// foot's reach behind it, in the foot joint's frame — a skeleton has no heel joint, and
    /// without it a foot rolling onto its heel (the end of a backwards step, a heel pivot) pivots
    /// on its ankle, which swings.
    heel: Vector3<f64>,
    /// Which of the foot's points ([`foot_points`]) reaches farthest from its joint horizontally
    /// in the standing pose (the toes' tip): how fast it turns about the joint is the foot's roll.
    tip: usize,
}

/// The foot joints of a rig, its body parts' ([`crate::rig::anatomy`]: declared, named in any
/// common scheme — `LeftFoot`, `l_foot`, `LeftAnkle`, `lFoot`, `Foot_L` … — or by shape).
/// Returns `[left, right]`.
pub fn foot_joints(rig: &Rig) -> Option<[usize; 2]> {
    Anatomy::of(rig).feet()
}

/// [`foot_joints`] among joint names alone (a skeleton that is not a rig: a GLB's skin).
pub fn foot_names<'a>(names: impl Iterator<Item = &'a str> + Clone) -> Option<[usize; 2]> {
    Anatomy::of_names(names).feet()
}

/// Each foot's points (`foot_points`: its joints, their end sites, the heel) in the foot bone's
/// frame from where its sensor is taken to sit, in metres (`[left, right]`): what
/// [`zupt::Shoe::pivot_acceleration_m_s2`] turns about, once turned into the sensor's frame by
/// its mount. The sensor is taken at the middle of the foot bone (from its joint to its first
/// child, or its end site): on the instep, where a foot's sensor is strapped, and where `simulate
/// --raw` puts it. A real one sits a few centimetres off it; a point off by `d` reads an
/// acceleration off by about `|ω̇| d` (a hard heel strike, 100 rad/s², over 3 cm: 3 m/s², under
/// [`PIVOT_M_S2`]) — not measured on real feet. The points are the calibrated pose's
/// (`reference`), rig units scaled by the subject's height ([`subject_height_m`]). `None` for a
/// rig without feet.
pub fn foot_points_from_sensor_m(
    rig: &Rig,
    reference: &[UnitQuaternion<f64>],
) -> Option<[Vec<Vector3<f64>>; 2]> {
    let core = RootCore::new(rig, RootMode::Feet, 1.0, reference);
    let feet = core.feet.as_ref()?;
    let metres_per_unit = core.subject_height_m / core.height;
    let (mut world, mut positions) = (Vec::new(), Vec::new());
    pose_relative_to_hips(rig, reference, &mut world, &mut positions);
    Some([0, 1].map(|side| {
        let foot = &feet[side];
        let f = foot.joints[0];
        let toward = rig
            .children(f)
            .next()
            .map(|c| rig.joints()[c].offset)
            .or(rig.joints()[f].end_site)
            .unwrap_or_default();
        let sensor = toward / 2.0;
        let mut points = Vec::new();
        foot_points(rig, foot, &positions, &world, &mut points);
        points
            .iter()
            .map(|p| (world[f].inverse() * (p - positions[f]) - sensor) * metres_per_unit)
            .collect()
    }))
}

/// What a root mode needs of the rig: `feet` asked for by name needs both feet (an error naming
/// the part and the joints that came closest); `auto` takes what the rig has.
pub fn require_parts(mode: RootMode, rig: &Rig) -> Result<(), crate::rig::anatomy::MissingPart> {
    if mode != RootMode::Feet {
        return Ok(());
    }
    Anatomy::of(rig).require(
        &[
            crate::rig::anatomy::Part::Limb(Side::Left, Limb::Foot),
            crate::rig::anatomy::Part::Limb(Side::Right, Limb::Foot),
        ],
        "--root feet",
    )
}

/// The mode `auto` resolves to for `rig` when the joints `animated` carry sensors.
pub fn resolve(mode: RootMode, rig: &Rig, animated: &[bool]) -> RootMode {
    if mode != RootMode::Auto {
        return mode;
    }
    let anatomy = Anatomy::of(rig);
    if anatomy.feet().is_none() {
        return RootMode::Fixed;
    }
    let sensed = |side: Side, limb: Limb| anatomy.limb(side, limb).is_some_and(|j| animated[j]);
    if Side::BOTH
        .iter()
        .all(|&s| sensed(s, Limb::Shank) && sensed(s, Limb::Thigh))
    {
        RootMode::Feet
    } else if Side::BOTH.iter().all(|&s| sensed(s, Limb::Thigh)) {
        RootMode::Ground
    } else {
        RootMode::Fixed
    }
}

/// One frame's root position and what the feet did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RootFrame {
    pub position: Vector3<f64>,
    /// Left, right: planted.
    pub contact: [bool; 2],
    pub airborne: bool,
    /// Left, right: how far the point each foot pivots on moved over the ground (horizontally)
    /// since the frame before, rig units — what a planted foot's pivot slips ([`super::foot_lock`]
    /// takes it back).
    pub slip: [Vector3<f64>; 2],
}

/// The root stage's incremental core.
#[derive(Debug, Clone)]
pub struct RootCore {
    mode: RootMode,
    rig: Rig,
    rest_root: Vector3<f64>,
    /// The rest pose's lowest point's height (the floor), rig units.
    floor: f64,
    /// Standing height, rig units.
    height: f64,
    /// The subject's standing height, m ([`subject_height_m`]): gravity is [`GRAVITY_M_S2`] over
    /// it, in standing heights per s².
    subject_height_m: f64,
    dt: f64,
    feet: Option<[Foot; 2]>,
    state: Option<FeetState>,
    // Per-frame buffers (a stream allocates nothing per frame).
    world: Vec<UnitQuaternion<f64>>,
    positions: Vec<Vector3<f64>>,
    now: [Vec<Vector3<f64>>; 2],
}

#[derive(Debug, Clone)]
struct FeetState {
    hips: Vector3<f64>,
    /// Each foot's contact points relative to the hips at the previous frame.
    previous: [Vec<Vector3<f64>>; 2],
    /// The height of the surface each foot stands (or last stood) on.
    level: [f64; 2],
    /// Frames the hips have been rising faster than a walk's.
    rising: usize,
    /// Where the hips would be and how fast they would go (position, velocity) had the body left
    /// the ground when the feet last held it at or above that path: ballistic since.
    ballistic: Option<(Vector3<f64>, Vector3<f64>)>,
    /// That path's positions at the frames since it started, oldest first (given out on the
    /// feet).
    path: Vec<Vector3<f64>>,
    /// Frames before the last one that were found in the air only at it: their positions on the
    /// path, oldest first (see [`RootCore::revised`]).
    revised: Vec<Vector3<f64>>,
    /// The hips' positions over the last [`STANCE_S`] on the ground, oldest first; emptied in the
    /// air.
    stance: std::collections::VecDeque<Vector3<f64>>,
    /// The foot that carried most weight at the previous frame.
    dominant: usize,
    /// Frames on the ground since the weight last passed from one foot to the other (or the
    /// body landed).
    since_switch: usize,
    /// The hips' velocity over the last frames (smoothed), rig units per second.
    velocity: Vector3<f64>,
    airborne: bool,
}

/// Points of a foot's subtree (joint positions and end sites) for positions `pos` and world
/// rotations `world`.
fn foot_points(
    rig: &Rig,
    foot: &Foot,
    pos: &[Vector3<f64>],
    world: &[UnitQuaternion<f64>],
    out: &mut Vec<Vector3<f64>>,
) {
    out.clear();
    for &j in &foot.joints {
        out.push(pos[j]);
        if let Some(e) = rig.joints()[j].end_site {
            out.push(pos[j] + world[j] * e);
        }
    }
    let f = foot.joints[0];
    out.push(pos[f] + world[f] * foot.heel);
}

/// Forward kinematics with the hips at the origin into the buffers (world rotations,
/// positions); the lowest point's height (joints and end sites).
fn pose_relative_to_hips(
    rig: &Rig,
    local: &[UnitQuaternion<f64>],
    world: &mut Vec<UnitQuaternion<f64>>,
    positions: &mut Vec<Vector3<f64>>,
) -> f64 {
    rig.world_pose_into(local, Vector3::zeros(), world, positions);
    let mut low = f64::INFINITY;
    for ((j, q), p) in rig.joints().iter().zip(world.iter()).zip(positions.iter()) {
        low = low.min(p.y);
        if let Some(e) = j.end_site {
            low = low.min(p.y + (q * e).y);
        }
    }
    low
}

/// What feet mode needs of a pose: its lowest point's height relative to the hips (returned)
/// and each foot's points (into `now`). Depends on this frame alone.
fn measure_feet(
    rig: &Rig,
    feet: &[Foot; 2],
    local: &[UnitQuaternion<f64>],
    world: &mut Vec<UnitQuaternion<f64>>,
    positions: &mut Vec<Vector3<f64>>,
    now: &mut [Vec<Vector3<f64>>; 2],
) -> f64 {
    let mut body_low = pose_relative_to_hips(rig, local, world, positions);
    for (foot, out) in feet.iter().zip(now.iter_mut()) {
        foot_points(rig, foot, positions, world, out);
        body_low = body_low.min(lowest(out).1);
    }
    body_low
}

fn lowest(points: &[Vector3<f64>]) -> (usize, f64) {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| (i, p.y))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, 0.0))
}

/// How a foot's pivot — its point that was lowest in `before` — moved to `now` (both the foot's
/// points relative to the hips, a frame apart): a planted foot holds it still, so the hips moved
/// by minus this.
fn pivot_moved(before: &[Vector3<f64>], now: &[Vector3<f64>]) -> Vector3<f64> {
    let k = lowest(before).0;
    match (now.get(k), before.get(k)) {
        (Some(n), Some(b)) => n - b,
        _ => Vector3::zeros(),
    }
}

/// How fast a foot rolls, × its units / s: its toes' tip (`before`, `after`: relative to the foot
/// joint, a frame `dt` apart) turning about the joint in the foot's upright plane — a heel rising
/// at push-off, a sole coming down after a heel strike change the tip's height and its horizontal
/// reach; a foot swivelling on the spot changes neither.
fn roll_speed(before: Vector3<f64>, after: Vector3<f64>, dt: f64) -> f64 {
    let reach = |v: Vector3<f64>| v.x.hypot(v.z);
    (after.y - before.y).hypot(reach(after) - reach(before)) / dt
}

/// Smooth step from 0 at `x = −1` to 1 at `x = 1`.
fn smooth(x: f64) -> f64 {
    let u = ((x + 1.0) / 2.0).clamp(0.0, 1.0);
    u * u * (3.0 - 2.0 * u)
}

impl RootCore {
    /// A core for `rig` at `fps`, in `mode` (resolved with [`resolve`] first; `auto` acts as
    /// `feet` here). `reference`: the local rotations of the pose the subject calibrated in (the
    /// rest pose's identities without one): the floor and the standing height `h` are that pose's,
    /// with the hips at the rig's root offset, not the zero pose's, which need not stand.
    pub fn new(
        rig: &Rig,
        mode: RootMode,
        frame_time_s: f64,
        reference: &[UnitQuaternion<f64>],
    ) -> RootCore {
        let (low, high) = rig.extent_in(reference);
        let mode = if mode == RootMode::Auto {
            RootMode::Feet
        } else {
            mode
        };
        // The standing pose with the hips at the origin: each foot's heel below its joint, at
        // the height of the foot's lowest point (its sole).
        let (mut world, mut positions) = (Vec::new(), Vec::new());
        pose_relative_to_hips(rig, reference, &mut world, &mut positions);
        let feet = foot_joints(rig).map(|[l, r]| {
            let subtree = |f: usize| {
                let mut joints = vec![f];
                for (i, j) in rig.joints().iter().enumerate() {
                    if j.parent.is_some_and(|p| joints.contains(&p)) {
                        joints.push(i);
                    }
                }
                let mut foot = Foot {
                    joints,
                    heel: Vector3::zeros(),
                    tip: 0,
                };
                let mut points = Vec::new();
                foot_points(rig, &foot, &positions, &world, &mut points);
                let sole = lowest(&points).1 - positions[f].y;
                // The foot's reach: its farthest point from the joint horizontally (the toes).
                let (tip, reach) = points
                    .iter()
                    .map(|p| Vector3::new(p.x - positions[f].x, 0.0, p.z - positions[f].z))
                    .enumerate()
                    .max_by(|a, b| a.1.norm_squared().total_cmp(&b.1.norm_squared()))
                    .unwrap_or_default();
                foot.tip = tip;
                foot.heel = world[f].inverse()
                    * (Vector3::new(0.0, sole.min(0.0), 0.0) - HEEL_BACK * reach);
                foot
            };
            [subtree(l), subtree(r)]
        });
        let mode = match (mode, &feet) {
            (RootMode::Feet, None) => RootMode::Ground,
            (m, _) => m,
        };
        let height = (high - low).max(1e-9);
        let subject_height_m = subject_height_m(height * rig.units().metres_per_unit());
        RootCore {
            mode,
            rig: rig.clone(),
            rest_root: rig.joints()[0].offset,
            floor: low,
            height,
            subject_height_m,
            dt: frame_time_s,
            feet,
            state: None,
            world: Vec::with_capacity(rig.len()),
            positions: Vec::with_capacity(rig.len()),
            now: [Vec::with_capacity(16), Vec::with_capacity(16)],
        }
    }

    /// The mode it runs (`feet` falls back to `ground` on a rig without feet).
    pub fn mode(&self) -> RootMode {
        self.mode
    }

    /// The standing height `h`, rig units.
    pub fn standing_height(&self) -> f64 {
        self.height
    }

    /// Gravity in standing heights per s² (what a flight falls by).
    pub fn gravity_h_s2(&self) -> f64 {
        GRAVITY_M_S2 / self.subject_height_m
    }

    /// The subject's standing height, m, that gravity is taken over ([`subject_height_m`]).
    pub fn subject_height_m(&self) -> f64 {
        self.subject_height_m
    }

    /// After a [`push`](Self::push): the frames before it that were found in the air only at it
    /// (a flight the feet could not see until they fell behind its path), the root's positions
    /// on that path, oldest first — the last `revised().len()` frames before the one pushed. A
    /// whole take puts them there; a stream, which has sent those frames, cannot, and its body
    /// jumps onto the path at most [`FLIGHT_H`] up (and by what the feet moved it aside).
    pub fn revised(&self) -> &[Vector3<f64>] {
        self.state.as_ref().map_or(&[], |s| &s.revised)
    }

    /// The next frame, from its local rotations (one per joint).
    pub fn push(&mut self, local: &[UnitQuaternion<f64>]) -> RootFrame {
        match self.mode {
            RootMode::Fixed => RootFrame {
                position: self.rest_root,
                contact: [false; 2],
                airborne: false,
                slip: [Vector3::zeros(); 2],
            },
            RootMode::Ground => {
                let low =
                    pose_relative_to_hips(&self.rig, local, &mut self.world, &mut self.positions);
                self.step_ground(low)
            }
            RootMode::Feet | RootMode::Auto => {
                let feet = self.feet.as_ref().expect("feet mode has feet");
                let body_low = measure_feet(
                    &self.rig,
                    feet,
                    local,
                    &mut self.world,
                    &mut self.positions,
                    &mut self.now,
                );
                let now = std::mem::take(&mut self.now);
                let frame = self.step_feet(
                    body_low,
                    [&now[0], &now[1]],
                    None,
                    [None; 2],
                    Planned::default(),
                );
                self.now = now;
                frame
            }
        }
    }

    /// Ground mode's frame from the pose's lowest point relative to the hips.
    fn step_ground(&self, low: f64) -> RootFrame {
        RootFrame {
            position: Vector3::new(self.rest_root.x, self.floor - low, self.rest_root.z),
            contact: [false; 2],
            airborne: false,
            slip: [Vector3::zeros(); 2],
        }
    }

    /// Feet mode's next frame from what [`measure_feet`] found of the pose: the lowest point's
    /// height and each foot's points, relative to the hips; the left foot's share of the weight
    /// if a whole take's support path ([`support`]) decided it, else this frame's scores do.
    fn step_feet(
        &mut self,
        body_low: f64,
        now: [&[Vector3<f64>]; 2],
        left_weight: Option<f64>,
        pivot: [Option<f64>; 2],
        plan: Planned,
    ) -> RootFrame {
        let (h, gravity) = (self.height, self.gravity_h_s2());
        let low = [lowest(now[0]), lowest(now[1])];
        let tips = self
            .feet
            .as_ref()
            .map_or([0; 2], |feet| [feet[0].tip, feet[1].tip]);
        let Some(state) = self.state.as_mut() else {
            // The first frame: the body stands on the floor where the rest pose stood.
            let hips = Vector3::new(self.rest_root.x, self.floor - body_low, self.rest_root.z);
            let w_left = smooth((low[1].1 - low[0].1) / (BAND_H * h));
            let planted =
                [0, 1].map(|f| self.floor - body_low + low[f].1 <= self.floor + PLANT_H * h);
            self.state = Some(FeetState {
                hips,
                previous: now.map(<[Vector3<f64>]>::to_vec),
                level: [self.floor; 2],
                rising: 0,
                ballistic: None,
                path: Vec::new(),
                revised: Vec::new(),
                stance: std::collections::VecDeque::new(),
                dominant: usize::from(w_left < 0.5),
                since_switch: 0,
                velocity: Vector3::zeros(),
                airborne: false,
            });
            return RootFrame {
                position: hips,
                contact: planted,
                airborne: false,
                slip: [Vector3::zeros(); 2],
            };
        };
        state.revised.clear();
        let moved = [0, 1].map(|f| pivot_moved(&state.previous[f], now[f]));
        // Contact weights: the foot that is lower, slower over the ground and not rising
        // relative to the hips carries the body; when the two are alike both share it (double
        // support), smoothly. Its speed over the ground is its speed relative to the hips plus
        // the hips' own as they moved lately: a planted foot's is nil whichever way the body
        // goes (backwards, sideways), where relative to the hips it is the body's speed.
        let dt = self.dt;
        let hips = state.velocity;
        let score = |f: usize| {
            let relative = moved[f] / dt;
            let ground = Vector3::new(relative.x + hips.x, 0.0, relative.z + hips.z);
            (low[f].1 - low[0].1.min(low[1].1)) / (BAND_H * h)
                + ground.norm() / (SPEED_H_S * h)
                + relative.y.max(0.0) / (RISE_H_S * h)
                + (-(relative.y + hips.y)).max(0.0) / (DESCENT_H_S * h)
        };
        let w_left = left_weight.unwrap_or_else(|| smooth(score(1) - score(0)));
        let weights = [w_left, 1.0 - w_left];
        let before = state.hips;
        let was_airborne = state.airborne;
        // A foot still pushing off under a take-off: airborne, but not off the ground yet.
        let mut pushing = false;
        if state.airborne {
            // Ballistic: the horizontal velocity kept, gravity vertically.
            state.velocity.y -= gravity * h * dt;
            state.hips += state.velocity * dt;
            // A foot reaching its surface lands on the way down; on the way up the legs are still
            // unfolding under a push-off, and they carry the hips higher and faster.
            let f = usize::from(low[1].1 < low[0].1);
            let on_foot = state.level[f] - low[f].1;
            if on_foot >= state.hips.y {
                if state.velocity.y <= 0.0 {
                    state.airborne = false;
                    state.level[1 - f] = state.level[f];
                    state.dominant = f;
                    state.since_switch = 0;
                } else {
                    state.velocity.y += (on_foot - state.hips.y) / dt;
                    state.hips.y = on_foot;
                    pushing = true;
                }
            }
        } else {
            // Horizontally the planted feet stay where they are.
            let step = weights[0] * moved[0] + weights[1] * moved[1];
            state.hips.x -= step.x;
            state.hips.z -= step.z;
            // When the weight passes to the other foot, it stands on a surface as much higher
            // than the other's as a whole take's planned transfer read it where both feet stood
            // or where the new one landed ([`transfer`]); else as it is higher relative to the
            // hips now. The same surface unless that is a step's height (a stair, a kerb; less
            // is the sensors' error).
            let dominant = usize::from(weights[1] > weights[0]);
            if dominant != state.dominant {
                let rise = match plan.rise {
                    Some(rise) => rise,
                    None => low[dominant].1 - low[state.dominant].1,
                };
                state.level[dominant] = if rise.abs() >= STEP_H * h {
                    state.level[state.dominant] + rise
                } else {
                    state.level[state.dominant]
                };
                state.dominant = dominant;
                state.since_switch = 0;
            } else {
                state.since_switch += 1;
            }
            // Vertically each foot on its surface, weighted.
            state.hips.y =
                weights[0] * (state.level[0] - low[0].1) + weights[1] * (state.level[1] - low[1].1);
            // A push-off faster than a walk's rise, for [`TAKEOFF_S`]: airborne.
            if (state.hips.y - before.y) / dt > TAKEOFF_H_S * h && !plan.gap {
                state.rising += 1;
            } else {
                state.rising = 0;
            }
            if state.rising as f64 * dt >= TAKEOFF_S {
                state.airborne = true;
                state.rising = 0;
                if let Some(mean) = state.stance_velocity(dt) {
                    state.velocity.x = mean.x;
                    state.velocity.z = mean.z;
                }
            }
        }
        // Nothing below the planted foot's surface.
        let floor = state.level[state.dominant];
        let body = state.hips.y + body_low;
        if body < floor - 1e-12 {
            state.hips.y += floor - body;
            if state.airborne && state.velocity.y < 0.0 {
                state.airborne = false;
            }
        }
        // A planned transfer's gap is the legs easing a fall (a step down), not a flight.
        if !state.airborne && !was_airborne && !plan.gap {
            self.fall_behind_flight(before);
        }
        let frames = self.stance_frames();
        let state = self.state.as_mut().expect("set above");
        let v = (state.hips - before) / dt;
        if state.airborne {
            state.stance.clear();
        } else {
            // Smoothed ([`VELOCITY_TAU_S`]): the velocity a take-off carries.
            state.velocity += (v - state.velocity) * (1.0 - (-dt / VELOCITY_TAU_S).exp());
            state.stance.push_back(state.hips);
            if state.stance.len() > frames + 1 {
                state.stance.pop_front();
            }
        }
        // Reported contacts: a foot near its surface, nearly still over the ground and not
        // rolling. No hysteresis (it held contacts past the source's end, measured by
        // `every_gait_walks_without_sliding`): contacts shorter than [`MIN_FRAMES`] are dropped
        // instead, so that noise does not flicker them.
        // The pivots' motion over the ground: the hips' step plus their motion relative to them.
        let slip = [0, 1].map(|f| {
            let d = state.hips - before + moved[f];
            Vector3::new(d.x, 0.0, d.z)
        });
        let contact = [0, 1].map(|f| {
            let height = state.hips.y + low[f].1 - state.level[f];
            let speed = slip[f].norm() / dt;
            // A planted foot lies still on its sole: it does not roll.
            let tip = |points: &[Vector3<f64>]| {
                points.get(tips[f]).copied().unwrap_or_default() - points[0]
            };
            let roll = roll_speed(tip(&state.previous[f]), tip(now[f]), dt);
            let still = speed <= PLANT_SPEED_H_S * h && roll <= PLANT_ROLL_H_S * h;
            // The foot's own sensor ([`zupt`]): a foot none of whose points accelerates by less
            // than [`UNPLANTED_M_S2`] is not planted; one turning about a point that hardly
            // accelerates ([`PIVOT_M_S2`]) is, rolling and a little faster.
            let planted = match pivot[f] {
                None => still,
                Some(a) => {
                    (still && a <= UNPLANTED_M_S2)
                        || (a <= PIVOT_M_S2 && speed <= PIVOT_SPEED * PLANT_SPEED_H_S * h)
                }
            };
            (!state.airborne || pushing) && height <= PLANT_H * h && planted
        });
        for (previous, now) in state.previous.iter_mut().zip(now) {
            previous.clear();
            previous.extend_from_slice(now);
        }
        RootFrame {
            position: state.hips,
            contact,
            airborne: state.airborne && !pushing,
            slip,
        }
    }
}

impl FeetState {
    /// The hips' mean velocity over the stance kept (up to [`STANCE_S`]), if it has two frames:
    /// what a take-off carries horizontally, steadier than the last frames' (`velocity`), which
    /// a push-off's foot rolling disturbs.
    fn stance_velocity(&self, dt: f64) -> Option<Vector3<f64>> {
        let (first, last) = (self.stance.front()?, self.stance.back()?);
        let n = self.stance.len() - 1;
        (n > 0).then(|| (last - first) / (n as f64 * dt))
    }
}

impl RootCore {
    /// Frames in [`STANCE_S`].
    fn stance_frames(&self) -> usize {
        (STANCE_S / self.dt).round().max(1.0) as usize
    }

    /// The flight the feet cannot see, on a frame the body was on the ground before and after:
    /// where the feet put the hips this frame (`state.hips`) against the ballistic path from the
    /// last frame they held them at or above it (`before`, the hips a frame ago, starts a new
    /// one) — started only after a stance of [`STANCE_S`] with the hips going up no faster than
    /// [`TAKEOFF_H_S`] (or [`PUSH_OFF_MAX_H_S`] a stance after the weight last passed from one
    /// foot to the other), at their mean horizontal velocity over it and their vertical one no
    /// faster than [`TAKEOFF_H_S`] (a path that rises at most TAKEOFF_H_S²/2g, about 0.018 h for
    /// a person, less than [`FLIGHT_H`]). Once the feet fall [`FLIGHT_H`] below that path the
    /// body is airborne on it.
    fn fall_behind_flight(&mut self, before: Vector3<f64>) {
        let (h, dt, frames) = (self.height, self.dt, self.stance_frames());
        let gravity = self.gravity_h_s2();
        let state = self.state.as_mut().expect("feet mode has a state");
        let start = match state.ballistic {
            Some(going) => Some(going),
            None if state.stance.len() > frames
                && state.velocity.y > 0.0
                && (state.velocity.y <= TAKEOFF_H_S * h
                    || (state.velocity.y <= PUSH_OFF_MAX_H_S * h
                        && state.since_switch > frames)) =>
            {
                let mean = state.stance_velocity(dt).unwrap_or_default();
                state.path.clear();
                // No faster than a take-off's rise: a frame or two faster (too short for
                // [`TAKEOFF_S`]) is a run's push-off sampled at 30 fps or less.
                let up = state.velocity.y.min(TAKEOFF_H_S * h);
                Some((before, Vector3::new(mean.x, up, mean.z)))
            }
            None => None,
        };
        state.ballistic = start.and_then(|(mut p, mut v)| {
            v.y -= gravity * h * dt;
            p += v * dt;
            let below = p.y - state.hips.y;
            if below >= FLIGHT_H * h {
                state.hips = p;
                state.velocity = v;
                state.airborne = true;
                // The frames since the path started were in the air too.
                std::mem::swap(&mut state.revised, &mut state.path);
                None
            } else if below > 0.0 {
                state.path.push(p);
                Some((p, v))
            } else {
                None
            }
        });
    }
}

/// The subject's standing height, m, for a rig standing `rig_height_m` tall: the rig's when a
/// person's ([`PERSON_HEIGHT_M`]), else [`ASSUMED_HEIGHT_M`] (a character of another size, or a
/// BVH whose unit was guessed wrong: CMU's, in 1/0.45 inch, reads as 0.26 m).
pub fn subject_height_m(rig_height_m: f64) -> f64 {
    if PERSON_HEIGHT_M.contains(&rig_height_m) {
        rig_height_m
    } else {
        ASSUMED_HEIGHT_M
    }
}

/// Frame ranges `[start, end]` (inclusive) where `flags` holds for at least [`MIN_FRAMES`].
pub fn intervals(flags: impl Iterator<Item = bool>) -> Vec<[usize; 2]> {
    runs(flags, MIN_FRAMES)
}

/// Frame ranges `[start, end]` (inclusive) where `flags` holds for at least `min_frames`.
pub fn runs(flags: impl Iterator<Item = bool>, min_frames: usize) -> Vec<[usize; 2]> {
    let mut out = Vec::new();
    let mut start = None;
    let mut n = 0;
    for (i, f) in flags.enumerate() {
        n = i + 1;
        match (f, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                if i - s >= min_frames {
                    out.push([s, i - 1]);
                }
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start
        && n - s >= min_frames
    {
        out.push([s, n - 1]);
    }
    out
}

/// Foot contacts and airborne stretches over a take, as frame intervals (inclusive).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Contacts {
    pub left: Vec<[usize; 2]>,
    pub right: Vec<[usize; 2]>,
    pub airborne: Vec<[usize; 2]>,
    /// The standing height, m, whose gravity the flights fell by ([`subject_height_m`]).
    pub subject_height_m: f64,
    /// Per frame: left and right planted (for the glTF's contact curves).
    #[serde(skip)]
    pub per_frame: Vec<[bool; 2]>,
}

impl Contacts {
    /// The intervals of the frames' contacts, and the per-frame flags they make (runs shorter
    /// than [`MIN_FRAMES`] left out of both, so the two always agree), found by a core whose
    /// flights fell as a body `subject_height_m` tall does.
    pub fn from_frames(frames: &[RootFrame], subject_height_m: f64) -> Contacts {
        let left = intervals(frames.iter().map(|f| f.contact[0]));
        let right = intervals(frames.iter().map(|f| f.contact[1]));
        let mut per_frame = vec![[false; 2]; frames.len()];
        for (side, runs) in [&left, &right].into_iter().enumerate() {
            for [s, e] in runs {
                for flags in &mut per_frame[*s..=*e] {
                    flags[side] = true;
                }
            }
        }
        Contacts {
            left,
            right,
            airborne: intervals(frames.iter().map(|f| f.airborne)),
            subject_height_m,
            per_frame,
        }
    }
}

/// What each foot's own sensor said, frame by frame (`[left, right]`): how fast the foot's
/// least-moving point accelerates, m/s² ([`zupt::Shoe::pivot_acceleration_m_s2`]), where the
/// take has the foot sensor's raw readings; `None` where it has not.
pub type FeetPivots = [Option<Vec<f64>>; 2];

/// Stage 7's output over a whole take.
#[derive(Debug, Clone, Default)]
pub struct RootMotion {
    /// The root position per frame, rig units.
    pub positions: Vec<Vector3<f64>>,
    /// `feet` mode: the contacts.
    pub contacts: Option<Contacts>,
    /// `feet` mode: per frame, how far each foot's pivot moved over the ground since the frame
    /// before ([`RootFrame::slip`]), what stage 8 takes back; empty otherwise (kept apart from
    /// the contacts, which the writers keep: a 60-minute take's slips are about 10 MB).
    pub slips: Vec<[Vector3<f64>; 2]>,
}

/// Stage 7 over a whole take: the root position at every frame (rig units) from every joint's
/// local rotations (`local[joint][frame]`), and the contacts in `feet` mode. `mode` is resolved
/// already; `pivots`, what the feet's own sensors said (frames past its end: moving).
pub fn root_positions(
    rig: &Rig,
    mode: RootMode,
    local: &[Vec<UnitQuaternion<f64>>],
    frame_time_s: f64,
    reference: &[UnitQuaternion<f64>],
    pivots: &FeetPivots,
) -> RootMotion {
    let frames = local.first().map_or(0, Vec::len);
    let mut core = RootCore::new(rig, mode, frame_time_s, reference);
    if core.mode() == RootMode::Fixed {
        return RootMotion {
            positions: vec![rig.joints()[0].offset; frames],
            ..RootMotion::default()
        };
    }
    // What each frame's pose says (forward kinematics: the frame's own business) on every core,
    // in blocks of frames; then the core steps through the frames in order.
    let block = frames.div_ceil(4 * rayon::current_num_threads()).max(1);
    let starts: Vec<usize> = (0..frames).step_by(block).collect();
    let measured: Vec<Measured> = starts
        .into_par_iter()
        .map(|start| measure_frames(&core, local, start..(start + block).min(frames)))
        .collect();
    let (mut planned, mut gaps, mut feet_low) = (Vec::new(), Vec::new(), Vec::new());
    let left_weights = (core.mode() == RootMode::Feet).then(|| {
        let (cues, low_h) = support_cues(&measured, core.dt, core.height);
        let mut path = support::decode(&cues, core.dt, core.gravity_h_s2());
        support::without_flickers(&mut path, MIN_FRAMES);
        let transfers = transfer::plan(&low_h, &cues, &path, core.dt, core.gravity_h_s2());
        planned = planned_frames(&transfers, core.height, frames);
        gaps = transfers.iter().filter_map(eased_gap).collect();
        feet_low = low_h;
        support::left_weights(&path, SUPPORT_BLEND_FRAMES)
    });
    let mut all: Vec<RootFrame> = Vec::with_capacity(frames);
    for m in &measured {
        for (i, &low) in m.low.iter().enumerate() {
            let n = all.len();
            let left_weight = left_weights.as_ref().map(|w| w[n]);
            let pivot = pivots.each_ref().map(|s| {
                s.as_ref()
                    .map(|s| s.get(n).copied().unwrap_or(f64::INFINITY))
            });
            let f = match &m.feet {
                None => core.step_ground(low),
                Some(feet) => {
                    let plan = planned.get(n).copied().unwrap_or_default();
                    core.step_feet(low, feet.frame(i), left_weight, pivot, plan)
                }
            };
            // A flight found late: the frames since it started were in the air, on its path.
            let revised = core.revised();
            let from = all.len() - revised.len();
            for (k, p) in (from..).zip(revised) {
                all[k] = RootFrame {
                    position: *p,
                    contact: [false; 2],
                    airborne: true,
                    slip: [Vector3::zeros(); 2],
                };
            }
            all.push(f);
        }
    }
    let feet = core.mode() == RootMode::Feet;
    if feet {
        let low: Vec<f64> = measured
            .iter()
            .flat_map(|m| m.low.iter().copied())
            .collect();
        let h = core.height;
        let bounds = (LANDING_SLACK_H * h, FLIGHT_H * h, STEP_H * h);
        refit_flights(
            &mut all,
            &low,
            &feet_low,
            core.dt,
            core.gravity_h_s2() * h,
            bounds,
        );
        smooth_gaps(&mut all, &gaps, core.dt);
        let weights = left_weights.as_deref().unwrap_or_default();
        bridge_slides(&mut all, weights, core.dt, core.gravity_h_s2() * h);
    }
    RootMotion {
        positions: all.iter().map(|f| f.position).collect(),
        contacts: feet.then(|| Contacts::from_frames(&all, core.subject_height_m())),
        slips: if feet {
            all.iter().map(|f| f.slip).collect()
        } else {
            Vec::new()
        },
    }
}

/// A whole take's hips bridged across the slides of the feet they followed ([`slide`]). The
/// feet's slips over the ground move by as much as the hips' steps changed, so that the foot lock
/// ([`super::foot_lock`]) holds a planted foot where it stood; the contacts stay as reported.
fn bridge_slides(all: &mut [RootFrame], left_weight: &[f64], dt: f64, gravity: f64) {
    let before: Vec<Vector3<f64>> = all.iter().map(|f| f.position).collect();
    let airborne: Vec<bool> = all.iter().map(|f| f.airborne).collect();
    let mut hips = before.clone();
    let windows = slide::bridge(&mut hips, &airborne, left_weight, dt, gravity);
    for w in windows {
        // The step after the window too: a smoothed one ends there.
        for t in w.first..=(w.last + 1).min(all.len() - 1) {
            let d = (hips[t] - hips[t - 1]) - (before[t] - before[t - 1]);
            let frame = &mut all[t];
            for slip in &mut frame.slip {
                *slip += Vector3::new(d.x, 0.0, d.z);
            }
        }
    }
    for (frame, p) in all.iter_mut().zip(hips) {
        frame.position = p;
    }
}

/// A refitted flight's lowest point may pass this far below the lower of its take-off's and its
/// landing's surfaces, × h (the sensors' noise on the legs).
pub const LANDING_SLACK_H: f64 = 0.01;
/// A refitted flight lasts at most this long, s (a standing high jump's is about 0.6 s).
pub const MAX_FLIGHT_S: f64 = 1.0;
/// The feet's vertical velocities a flight's refit meets are taken over this long on each side,
/// s: two frames at 60 fps, one at 30 or 24 (two frames at 30 fps average a push-off's fastest
/// frame with a slower one: CMU 09_01 at 30 fps 1.67 → 1.08 %,
/// `root_motion::a_run_at_30_fps_is_refitted_from_its_last_push`).
pub const REFIT_VELOCITY_S: f64 = 1.0 / 30.0;

/// A whole take's flights refitted between the frames on the feet that bound them. The core,
/// going forwards, launches a flight at the velocity the feet gave the hips and lands it where a
/// foot reaches its surface; a take-off's last frames are its fastest and the smoothing rounds
/// them, so a flight launched too slowly lands early — while the body is still up — and one
/// launched too fast late. Seen whole, a flight is one parabola from its take-off frame `a` to a
/// landing frame `b`, both on the feet: `y(t) = y_a + v₀t − gt²/2` with `v₀ = (y_b − y_a)/T +
/// gT/2`, `T = (b − a)·dt`, where `y_b = L − l_b` is where the feet put the hips at `b` (`L` the
/// surface the core landed on, `l_b` the lowest point relative to the hips). The ground pushes
/// with a finite force, so the hips' vertical velocity is continuous where the feet leave and
/// reach it: `b` is the frame whose parabola best meets the feet's velocities on both sides —
/// minimising `(v₀ − ẏ_a)² + (v₀ − gT − ẏ_b)²`, `ẏ_a` over [`REFIT_VELOCITY_S`] before `a`,
/// `ẏ_b` over as long after `b` (both from the feet) — among those whose lowest point stays above the
/// surfaces ([`LANDING_SLACK_H`]) and rises [`FLIGHT_H`] above them at least (less is a foot
/// skimming the ground, not a flight: the early landings' continuations rise about 0.02 h).
/// Horizontally the flight keeps the core's mean velocity. Frames the core had on its feet
/// before `b` join the flight (a false landing, and the false flight that followed it); frames it
/// had in the air from `b` on stand on the feet — the lower foot, planted, carries the hips
/// horizontally too, by minus its motion relative to them (`feet_low`: each foot's lowest point
/// relative to the hips, h; carried on at the flight's velocity, the landed feet slid: CMU 01_01
/// played backwards, skate 0.0086 → 0.0005 h) — and the frames after move with the landing, so
/// the path goes on without a jump. A stream, which has sent its frames, keeps the core's
/// flights.
fn refit_flights(
    all: &mut [RootFrame],
    low: &[f64],
    feet_low: &[[f64; 2]],
    dt: f64,
    gravity: f64,
    (slack, clear, step): (f64, f64, f64),
) {
    let n = all.len();
    let flights = intervals(all.iter().map(|f| f.airborne));
    if flights.is_empty() {
        return;
    }
    // Where the lower foot would move the hips horizontally each frame, were it planted: minus
    // its motion relative to them, which is its slip over the ground less the hips' own step
    // (`RootCore::push`); a frame the core had in the air has one too. Without the feet's
    // heights, both feet's mean.
    let feet_step: Vec<Vector3<f64>> = (0..n)
        .map(|k| {
            let hips = if k == 0 {
                Vector3::zeros()
            } else {
                all[k].position - all[k - 1].position
            };
            let relative = |f: usize| all[k].slip[f] - Vector3::new(hips.x, 0.0, hips.z);
            match feet_low.get(k) {
                Some(low) => -relative(usize::from(low[1] < low[0])),
                None => -(relative(0) + relative(1)) / 2.0,
            }
        })
        .collect();
    let max = (MAX_FLIGHT_S / dt).round() as usize;
    // The frames the feet's velocities are taken over on each side ([`REFIT_VELOCITY_S`]).
    let across = ((REFIT_VELOCITY_S / dt).round() as usize).max(1);
    // Frames before `next` have `shift` applied (a landing moved everything after it).
    let mut shift = Vector3::zeros();
    let mut next = 0;
    let settle = |all: &mut [RootFrame], next: &mut usize, shift: Vector3<f64>, upto: usize| {
        while *next <= upto.min(n - 1) {
            all[*next].position += shift;
            *next += 1;
        }
    };
    let mut covered = 0; // frames before this were refitted already
    for [start, end] in flights {
        if start < covered.max(3) || end + 3 >= n {
            continue;
        }
        let (a, landed) = (start - 1, end + 1);
        settle(all, &mut next, shift, (a + max + 2).max(landed + 2));
        let ya = all[a].position.y;
        let va = (ya - all[a - across].position.y) / (across as f64 * dt);
        let take_off_level = ya + low[a];
        // On the surface the core landed on, so that the frames after go on from it, when that
        // is the one it left (within a step of it, [`STEP_H`]: a late landing's feet sink a
        // little); a flight the core landed a step away is left as it is — a hop onto a step,
        // or a surface the core lost in the air, which no refit can tell apart.
        let level = all[landed].position.y + low[landed];
        if (level - take_off_level).abs() >= step {
            continue;
        }
        let surface = take_off_level.min(level);
        let mut best: Option<(f64, usize, f64)> = None;
        for b in a + MIN_FRAMES + 1..=(a + max).min(n - 3) {
            let span = (b - a) as f64 * dt;
            let yb = level - low[b];
            let v0 = (yb - ya) / span + gravity * span / 2.0;
            let vb = (low[b] - low[b + across]) / (across as f64 * dt);
            let cost = (v0 - va).powi(2) + (v0 - gravity * span - vb).powi(2);
            if best.is_some_and(|(c, _, _)| c <= cost) {
                continue;
            }
            // The lowest point's height above the surface over the flight, lowest and highest.
            let (lowest, highest) = (a + 1..b)
                .map(|k| {
                    let t = (k - a) as f64 * dt;
                    ya + v0 * t - gravity * t * t / 2.0 + low[k] - surface
                })
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), y| {
                    (l.min(y), h.max(y))
                });
            if lowest >= -slack && highest >= clear {
                best = Some((cost, b, v0));
            }
        }
        let Some((_, b, v0)) = best else {
            continue;
        };
        // The frames the refit decides: up to the first on the feet in both.
        let mut m = b.max(landed);
        while m < n && all[m].airborne {
            m += 1;
        }
        if m + 1 >= n {
            continue;
        }
        settle(all, &mut next, shift, m);
        // Horizontally the core's flight, on average, until the landing; from there the feet.
        let carried = (all[end].position - all[a].position) / (end - a) as f64;
        let from = all[a].position;
        for k in a + 1..m {
            let t = (k - a) as f64 * dt;
            let previous = all[k - 1].position;
            let frame = &mut all[k];
            if k < b {
                frame.position.x = from.x + carried.x * (k - a) as f64;
                frame.position.z = from.z + carried.z * (k - a) as f64;
                frame.position.y = from.y + v0 * t - gravity * t * t / 2.0;
                frame.airborne = true;
                frame.contact = [false; 2];
            } else {
                frame.position.x = previous.x + feet_step[k].x;
                frame.position.z = previous.z + feet_step[k].z;
                frame.position.y = level - low[k];
                frame.airborne = false;
            }
        }
        let before_landing = all[m - 1].position;
        let landing = Vector3::new(
            before_landing.x + feet_step[m].x,
            all[m].position.y,
            before_landing.z + feet_step[m].z,
        );
        // The frames from m move with the landing: those settled already by this much, the
        // rest by the whole shift when they are.
        let moved = landing - all[m].position;
        shift += moved;
        for frame in &mut all[m..next] {
            frame.position += moved;
        }
        covered = m;
    }
    settle(all, &mut next, shift, n - 1);
}

/// What each frame of a whole take says about which foot carries the body ([`support`]), from
/// the feet's points relative to the hips: the hips' velocity each foot's pivot ([`pivot_moved`],
/// as [`RootCore::push`] moves the hips) implies, and its height above the other's, both
/// in standing heights `height`; and each foot's lowest point relative to the hips, h (what the
/// planned transfers read, [`transfer::plan`]).
fn support_cues(
    measured: &[Measured],
    dt: f64,
    height: f64,
) -> (Vec<support::SupportCues>, Vec<[f64; 2]>) {
    let (mut cues, mut low_h) = (Vec::new(), Vec::new());
    let mut previous: Option<[&[Vector3<f64>]; 2]> = None;
    for m in measured {
        let Some(feet) = &m.feet else {
            continue;
        };
        for i in 0..m.low.len() {
            let now = feet.frame(i);
            let low = now.map(|p| lowest(p).1);
            let above = [0, 1].map(|f| (low[f] - low[0].min(low[1])) / height);
            let implied = match previous {
                None => [Vector3::zeros(); 2],
                Some(before) => [0, 1].map(|f| -pivot_moved(before[f], now[f]) / (dt * height)),
            };
            cues.push(support::SupportCues { implied, above });
            low_h.push(low.map(|l| l / height));
            previous = Some(now);
        }
    }
    (cues, low_h)
}

/// What a whole take's planned transfers ([`transfer`]) say of one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Planned {
    /// The support path passes the weight here, to a surface this much higher (rig units).
    rise: Option<f64>,
    /// Within a transfer's gap or just before it, as the weights start to pass: the legs easing
    /// a fall (no flight is looked for).
    gap: bool,
}

/// The transfers as frame-by-frame instructions to the core: each switch's step, and the
/// frames of each step's gap ([`eased_gap`]).
fn planned_frames(transfers: &[transfer::Transfer], height: f64, frames: usize) -> Vec<Planned> {
    let mut out = vec![Planned::default(); frames];
    for p in transfers {
        if let Some(frame) = out.get_mut(p.switch) {
            frame.rise = Some(p.rise_h * height);
        }
        if let Some((start, b)) = eased_gap(p) {
            for frame in out.iter_mut().take(b).skip(start) {
                frame.gap = true;
            }
        }
    }
    out
}

/// The frames a transfer's gap eases the hips over, `(start, landing)`, when it steps onto
/// another surface ([`STEP_H`]): from the last frame before the path's weights start passing
/// (±[`SUPPORT_BLEND_FRAMES`] around the switch) to the landing. On the same surface the hips
/// pass from foot to foot where the feet put them, as they always did.
fn eased_gap(p: &transfer::Transfer) -> Option<(usize, usize)> {
    p.gap()
        .filter(|_| p.rise_h.abs() >= STEP_H)
        .map(|(s, b)| (s.saturating_sub(SUPPORT_BLEND_FRAMES + 1), b))
}

/// Across each step's gap ([`transfer::Found::Gap`], eased over `(g, b)`: [`eased_gap`]) the hips
/// pass from the old foot's surface to the new one's at the switch, in one frame; seen whole, they
/// follow a cubic from `g` to the landing `b`, meeting the path's heights and
/// vertical velocities at both ends (a step down is a fall eased by the legs, not a drop). Gaps
/// with a frame in the air, or starting within the one before, are left alone.
fn smooth_gaps(all: &mut [RootFrame], gaps: &[(usize, usize)], dt: f64) {
    // Frames before this were eased already: a gap that starts among them is left alone.
    let mut eased = 0;
    for &(g, b) in gaps {
        if g == 0
            || g <= eased
            || b + 1 >= all.len()
            || all[g - 1..=b + 1].iter().any(|f| f.airborne)
        {
            continue;
        }
        eased = b;
        let y = |t: usize| all[t].position.y;
        let (v0, v1) = ((y(g) - y(g - 1)) / dt, (y(b + 1) - y(b)) / dt);
        let (y0, y1, span) = (y(g), y(b), (b - g) as f64 * dt);
        for (t, frame) in all.iter_mut().enumerate().take(b).skip(g + 1) {
            let tau = (t - g) as f64 / (b - g) as f64;
            frame.position.y = transfer::hermite(y0, v0, y1, v1, span, tau);
        }
    }
}

/// A block of frames as [`measure_feet`] (feet mode) or [`pose_relative_to_hips`] (ground mode)
/// saw them: each frame's lowest point, and in feet mode each foot's points, frame after frame
/// (a foot has the same number of points in every frame).
struct Measured {
    low: Vec<f64>,
    feet: Option<FeetPoints>,
}

/// Each foot's points, frame after frame, and how many a frame has.
struct FeetPoints {
    points: [Vec<Vector3<f64>>; 2],
    per_foot: [usize; 2],
}

impl FeetPoints {
    /// Frame `i`'s points of each foot (of the frames measured together).
    fn frame(&self, i: usize) -> [&[Vector3<f64>]; 2] {
        [0, 1].map(|f| &self.points[f][i * self.per_foot[f]..(i + 1) * self.per_foot[f]])
    }
}

fn measure_frames(
    core: &RootCore,
    local: &[Vec<UnitQuaternion<f64>>],
    frames: std::ops::Range<usize>,
) -> Measured {
    let rig = &core.rig;
    let mut pose = vec![UnitQuaternion::identity(); rig.len()];
    let (mut world, mut positions) = (Vec::new(), Vec::new());
    let mut now = [Vec::new(), Vec::new()];
    let mut low = Vec::with_capacity(frames.len());
    let mut points = [Vec::new(), Vec::new()];
    let feet = core.feet.as_ref().filter(|_| core.mode == RootMode::Feet);
    for n in frames {
        for (q, track) in pose.iter_mut().zip(local) {
            *q = track[n];
        }
        match feet {
            Some(feet) => {
                low.push(measure_feet(
                    rig,
                    feet,
                    &pose,
                    &mut world,
                    &mut positions,
                    &mut now,
                ));
                for (all, foot) in points.iter_mut().zip(&now) {
                    all.extend_from_slice(foot);
                }
            }
            None => low.push(pose_relative_to_hips(
                rig,
                &pose,
                &mut world,
                &mut positions,
            )),
        }
    }
    let per_foot = [now[0].len(), now[1].len()];
    Measured {
        low,
        feet: feet.map(|_| FeetPoints { points, per_foot }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::load_rig;

    #[test]
    fn feet_are_found_by_name_and_auto_follows_the_sensors() {
        let rig = load_rig("mixamo").unwrap();
        let [l, r] = foot_joints(&rig).unwrap();
        assert_eq!(rig.joints()[l].name, "LeftFoot");
        assert_eq!(rig.joints()[r].name, "RightFoot");
        let mut animated = vec![false; rig.len()];
        assert_eq!(resolve(RootMode::Auto, &rig, &animated), RootMode::Fixed);
        for name in ["LeftUpLeg", "RightUpLeg"] {
            animated[rig.joint_index(name).unwrap()] = true;
        }
        assert_eq!(resolve(RootMode::Auto, &rig, &animated), RootMode::Ground);
        for name in ["LeftLeg", "RightLeg"] {
            animated[rig.joint_index(name).unwrap()] = true;
        }
        assert_eq!(resolve(RootMode::Auto, &rig, &animated), RootMode::Feet);
        assert_eq!(resolve(RootMode::Fixed, &rig, &animated), RootMode::Fixed);
    }

    /// A person-sized rig is the subject's size; CMU's BVH read as centimetres (25.7 units of
    /// 1/0.45 inch: 0.26 m) or a giant is not, and 1.75 m is assumed.
    #[test]
    fn gravity_is_the_subjects() {
        assert_eq!(subject_height_m(1.45), 1.45);
        assert_eq!(subject_height_m(1.0), 1.0);
        assert_eq!(subject_height_m(2.3), 2.3);
        assert_eq!(subject_height_m(0.257), 1.75);
        assert_eq!(subject_height_m(4.0), 1.75);
        let rig = load_rig("mixamo").unwrap();
        let rest = vec![UnitQuaternion::identity(); rig.len()];
        let core = RootCore::new(&rig, RootMode::Feet, 1.0 / 60.0, &rest);
        let height_m = core.standing_height() * rig.units().metres_per_unit();
        assert!((core.gravity_h_s2() - 9.80665 / height_m).abs() < 1e-12);
    }

    /// A hop (by hand): the hips rise at 1 unit/s on the feet, fly 0.2 s under g = 10 units/s²
    /// with the legs still (v₀ = gT/2 = 1), and land going down at 1 unit/s, the legs giving. A
    /// core that launched it at 0.6 units/s landed it after 5 frames and stood on the feet
    /// after; the refit finds the flight whole — airborne for the 11 frames between, on the
    /// true parabola, the frames after where the feet put them.
    #[test]
    fn a_flight_launched_too_slowly_is_refitted_between_the_feet() {
        let (dt, g, a, n) = (1.0 / 60.0, 10.0, 20usize, 60usize);
        let flight = 12; // frames from take-off to landing: 0.2 s
        // The true hips' height, and the lowest point relative to the hips (the pose's).
        let truth = |k: usize| -> f64 {
            let t = (k as f64 - a as f64) * dt;
            if k <= a {
                1.0 + t
            } else if k < a + flight {
                1.0 + t - g * t * t / 2.0
            } else {
                1.0 - (t - flight as f64 * dt)
            }
        };
        let low: Vec<f64> = (0..n)
            .map(|k| {
                if k > a && k < a + flight {
                    -truth(a)
                } else {
                    -truth(k)
                }
            })
            .collect();
        let frame = |y: f64, airborne: bool| RootFrame {
            position: Vector3::new(0.0, y, 0.0),
            contact: [!airborne; 2],
            airborne,
            slip: [Vector3::zeros(); 2],
        };
        let mut all: Vec<RootFrame> = (0..n)
            .map(|k| {
                if k <= a {
                    frame(truth(k), false)
                } else if k <= a + 5 {
                    let t = (k - a) as f64 * dt;
                    frame(truth(a) + 0.6 * t - g * t * t / 2.0, true)
                } else {
                    frame(-low[k], false)
                }
            })
            .collect();
        refit_flights(&mut all, &low, &[], dt, g, (0.01, 0.03, 0.06));
        for (k, f) in all.iter().enumerate() {
            let air = k > a && k < a + flight;
            assert_eq!(f.airborne, air, "{k}");
            assert!(
                (f.position.y - truth(k)).abs() < 1e-9,
                "{k}: {} vs {}",
                f.position.y,
                truth(k)
            );
        }
    }

    /// The same hop (by hand), moving forwards at 1 unit/s, by a core that launched it too fast
    /// and landed it 3 frames late (frame 35, not 32). The refit lands it at 32; over frames
    /// 32–34, which the core had in the air at 1 unit/s, the lower foot (the left) is planted and
    /// moves back relative to the hips at 0.5 units/s while the right swings forward at 2: the
    /// hips go on at 0.5 units/s, as they do from frame 35 on the feet, without a jump.
    #[test]
    fn a_flight_landed_early_by_the_refit_stands_on_the_lower_foot() {
        let (dt, g, a, n) = (1.0 / 60.0, 10.0, 20usize, 60usize);
        let (b, m) = (a + 12, a + 15); // the true landing, the core's
        let truth = |k: usize| -> f64 {
            let t = (k as f64 - a as f64) * dt;
            if k <= a {
                1.0 + t
            } else if k < b {
                1.0 + t - g * t * t / 2.0
            } else {
                1.0 - (t - (b - a) as f64 * dt)
            }
        };
        let low: Vec<f64> = (0..n)
            .map(|k| if k > a && k < b { -truth(a) } else { -truth(k) })
            .collect();
        // The core's horizontal path: still before the take-off, 1 unit/s in its flight, 0.5
        // on the feet after.
        let x_core = |k: usize| -> f64 {
            if k <= a {
                0.0
            } else if k < m {
                (k - a) as f64 * dt
            } else {
                (m - 1 - a) as f64 * dt + (k - m + 1) as f64 * 0.5 * dt
            }
        };
        let mut all: Vec<RootFrame> = (0..n)
            .map(|k| {
                let airborne = k > a && k < m;
                let y = if airborne {
                    let t = (k - a) as f64 * dt;
                    truth(a) + 1.4 * t - g * t * t / 2.0
                } else {
                    -low[k]
                };
                let step = if k == 0 {
                    0.0
                } else {
                    x_core(k) - x_core(k - 1)
                };
                // Each foot's slip: the hips' step plus its motion relative to them; the left
                // moves back 0.5 units/s relative to the hips from the landing on, the right
                // forward 2.
                let relative = if k >= b {
                    [-0.5 * dt, 2.0 * dt]
                } else {
                    [0.0; 2]
                };
                RootFrame {
                    position: Vector3::new(x_core(k), y, 0.0),
                    contact: [!airborne; 2],
                    airborne,
                    slip: relative.map(|r| Vector3::new(step + r, 0.0, 0.0)),
                }
            })
            .collect();
        let feet_low = vec![[-0.5, -0.4]; n]; // the left foot lower
        refit_flights(&mut all, &low, &feet_low, dt, g, (0.01, 0.03, 0.06));
        for (k, f) in all.iter().enumerate() {
            assert_eq!(f.airborne, k > a && k < b, "{k}");
            assert!(
                (f.position.y - truth(k)).abs() < 1e-9,
                "{k}: y {}",
                f.position.y
            );
            let x = if k < b {
                x_core(k)
            } else {
                (b - 1 - a) as f64 * dt + (k - b + 1) as f64 * 0.5 * dt
            };
            assert!(
                (f.position.x - x).abs() < 1e-12,
                "{k}: x {} vs {x}",
                f.position.x
            );
        }
    }

    #[test]
    fn intervals_keep_runs_of_at_least_three_frames() {
        let f = [
            true, true, false, true, true, true, false, true, true, true, true,
        ];
        assert_eq!(intervals(f.into_iter()), vec![[3, 5], [7, 10]]);
    }

    /// Standing still in the rest pose: every mode keeps the body where the rest pose stands,
    /// feet on the floor.
    #[test]
    fn standing_still_stays_put() {
        let rig = load_rig("mixamo").unwrap();
        let rest = vec![UnitQuaternion::identity(); rig.len()];
        for mode in [RootMode::Fixed, RootMode::Ground, RootMode::Feet] {
            let mut core = RootCore::new(&rig, mode, 1.0 / 60.0, &rest);
            for _ in 0..30 {
                let f = core.push(&rest);
                assert!(
                    (f.position - rig.joints()[0].offset).norm() < 1e-9,
                    "{mode:?}: {f:?}"
                );
                assert!(!f.airborne);
            }
        }
    }

    /// The rate (rad/s) at which the left foot of `rig` standing in `rest`, pitched about x (it
    /// points along z), rolls at [`PLANT_ROLL_H_S`]: its toes' tip moves at ω · its distance from
    /// the x axis through the foot joint.
    fn roll_limit_rad_s(rig: &Rig, rest: &[UnitQuaternion<f64>], dt: f64) -> f64 {
        let probe = RootCore::new(rig, RootMode::Feet, dt, rest);
        let left = probe.feet.as_ref().unwrap()[0].clone();
        let (mut world, mut positions, mut points) = (Vec::new(), Vec::new(), Vec::new());
        pose_relative_to_hips(rig, rest, &mut world, &mut positions);
        foot_points(rig, &left, &positions, &world, &mut points);
        let tip = points[left.tip] - points[0];
        PLANT_ROLL_H_S * probe.standing_height() / tip.y.hypot(tip.z)
    }

    /// A foot rolling on the point it pivots on — its toes' tip turning about its joint in the
    /// foot's upright plane at twice [`PLANT_ROLL_H_S`] — is not reported planted, though that
    /// point holds still; rolling at half of it, it is.
    #[test]
    fn a_rolling_foot_is_not_planted() {
        let rig = load_rig("mixamo").unwrap();
        let foot = Anatomy::of(&rig).limb(Side::Left, Limb::Foot).unwrap();
        let rest = vec![UnitQuaternion::identity(); rig.len()];
        let dt = 1.0 / 60.0;
        let limit = roll_limit_rad_s(&rig, &rest, dt);
        for (rate_rad_s, planted) in [(0.5 * limit, true), (2.0 * limit, false)] {
            let mut core = RootCore::new(&rig, RootMode::Feet, dt, &rest);
            for _ in 0..10 {
                assert!(core.push(&rest).contact[0]);
            }
            let mut pose = rest.clone();
            for k in 1..=6 {
                // Toes up: the foot pivots on its heel.
                pose[foot] = UnitQuaternion::from_axis_angle(
                    &Vector3::x_axis(),
                    -rate_rad_s * dt * k as f64,
                );
                let frame = core.push(&pose);
                assert!(!frame.airborne, "{rate_rad_s} rad/s, frame {k}");
                assert_eq!(
                    frame.contact[0], planted,
                    "{rate_rad_s} rad/s, frame {k}: {frame:?}"
                );
            }
        }
    }

    /// The foot's own sensor ([`zupt`]): a point the foot turns about that hardly accelerates
    /// (2 m/s², under [`PIVOT_M_S2`]) keeps it planted where the kinematic rule alone would not
    /// (the rolling foot of [`a_rolling_foot_is_not_planted`] at 1.5 × [`PLANT_ROLL_H_S`], its
    /// lowest point sliding at 0.21–0.50 h/s as the foot turns about its ankle: under
    /// [`PIVOT_SPEED`] × [`PLANT_SPEED_H_S`]; at twice the roll it slides at up to 0.67 h/s, and
    /// stays unplanted); 6 m/s² (between it and [`UNPLANTED_M_S2`]), or no sensor, leaves the
    /// rule's answer; 12 m/s² (over g) unplants even the standing frames.
    #[test]
    fn a_foot_whose_point_stands_is_planted() {
        let rig = load_rig("mixamo").unwrap();
        let foot = Anatomy::of(&rig).limb(Side::Left, Limb::Foot).unwrap();
        let rest = vec![UnitQuaternion::identity(); rig.len()];
        let dt = 1.0 / 60.0;
        let rate_rad_s = 1.5 * roll_limit_rad_s(&rig, &rest, dt);
        // Ten frames standing, then six rolling onto the heel.
        let poses: Vec<Vec<UnitQuaternion<f64>>> = (0..16)
            .map(|n| {
                let mut pose = rest.clone();
                let k = (n as usize).saturating_sub(9) as f64;
                pose[foot] =
                    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -rate_rad_s * dt * k);
                pose
            })
            .collect();
        let local: Vec<Vec<UnitQuaternion<f64>>> = (0..rig.len())
            .map(|j| poses.iter().map(|p| p[j]).collect())
            .collect();
        for (sensor, left_contact) in [
            (None, vec![[0, 9]]),
            (Some(6.0), vec![[0, 9]]),
            (Some(2.0), vec![[0, 15]]),
            (Some(12.0), vec![]),
        ] {
            let pivots = [sensor.map(|a| vec![a; 16]), None];
            let contacts =
                root_positions(&rig, RootMode::Feet, &local, dt, &rest, &pivots).contacts;
            assert_eq!(contacts.unwrap().left, left_contact, "{sensor:?} m/s²");
        }
    }

    /// The roll is the tip's turn in the foot's upright plane: ω · arm for a pitch (by hand:
    /// a tip 0.2 ahead and 0.05 below the joint, turned 0.1 rad in 0.1 s, moves 0.1 · √0.0425
    /// in 0.1 s), nil for a swivel about the vertical however fast.
    #[test]
    fn a_foot_swivelling_on_the_spot_does_not_roll() {
        let tip = Vector3::new(0.0, -0.05, 0.2);
        let pitched = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.1) * tip;
        let expected = 2.0 * (0.05f64).sin() * 0.0425f64.sqrt() / 0.1; // chord over dt
        assert!((roll_speed(tip, pitched, 0.1) - expected).abs() < 1e-12);
        let swivelled = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 1.0) * tip;
        assert!(roll_speed(tip, swivelled, 0.01).abs() < 1e-12);
    }

    /// Both knees, flexed 40°, straighten to 15° over 0.3 s (too slowly for a hop's take-off,
    /// [`TAKEOFF_H_S`]: the slow fold never flies) and then fold to 90° in `fold_s`: folded in
    /// 0.1 s the feet rise
    /// faster than a body can fall, so it has left the ground — airborne from then on, on a
    /// parabola (second differences −g·dt², horizontally still), rising first, until a foot
    /// reaches the floor. A stream jumps onto that path when it sees the flight; a whole take
    /// ([`root_positions`]) puts the frames since the flight began on it. Folded over 1 s the body
    /// sinks on its feet and never leaves them.
    #[test]
    fn legs_folding_faster_than_gravity_leave_the_ground() {
        let rig = load_rig("mixamo").unwrap();
        let anatomy = Anatomy::of(&rig);
        let knees = Side::BOTH.map(|s| anatomy.limb(s, Limb::Shank).unwrap());
        let rest = vec![UnitQuaternion::identity(); rig.len()];
        let dt = 1.0 / 60.0;
        let pose = |knee_deg: f64| {
            let mut pose = rest.clone();
            for &k in &knees {
                pose[k] =
                    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), knee_deg.to_radians());
            }
            pose
        };
        for (fold_s, flies) in [(0.1, true), (1.0, false)] {
            let mut core = RootCore::new(&rig, RootMode::Feet, dt, &rest);
            let h = core.standing_height();
            // Mixamo's rig is a person's size (metres): it falls at g over its own height.
            let height_m = h * rig.units().metres_per_unit();
            assert!((1.5..2.0).contains(&height_m), "{height_m} m");
            let g = 9.80665 / height_m;
            let mut knee = Vec::new();
            knee.extend((0..30).map(|_| 40.0));
            knee.extend((1..=18).map(|i| 40.0 - 25.0 * i as f64 / 18.0));
            let fold_from = knee.len();
            let fold = (fold_s / dt).round() as usize;
            knee.extend((1..=fold).map(|i| 15.0 + 75.0 * i as f64 / fold as f64));
            knee.extend((0..60).map(|_| 90.0));
            let frames: Vec<RootFrame> = knee.iter().map(|&k| core.push(&pose(k))).collect();
            let air: Vec<usize> = (0..frames.len()).filter(|&i| frames[i].airborne).collect();
            if !flies {
                assert!(
                    air.is_empty(),
                    "folded over {fold_s} s: airborne at {air:?}"
                );
                continue;
            }
            assert!(!air.is_empty(), "folded in {fold_s} s: never airborne");
            let (first, last) = (air[0], air[air.len() - 1]);
            assert!(first > fold_from && first <= fold_from + fold, "{air:?}");
            assert_eq!(last - first + 1, air.len(), "one flight: {air:?}");
            assert!(!frames[frames.len() - 1].airborne);
            for i in first + 1..last {
                let (a, b, c) = (
                    frames[i - 1].position,
                    frames[i].position,
                    frames[i + 1].position,
                );
                let second = (c - 2.0 * b + a) / h;
                assert!((second.y + g * dt * dt).abs() < 1e-9, "{i}: {second}");
                assert!(
                    second.x.abs() < 1e-9 && second.z.abs() < 1e-9,
                    "{i}: {second}"
                );
            }
            let peak = frames[first..=last]
                .iter()
                .map(|f| f.position.y)
                .fold(f64::MIN, f64::max);
            assert!(peak > frames[first - 1].position.y, "it rose first");
            // A whole take puts the frames the stream gave out on the feet before it saw the
            // flight on its path: the same flight from an earlier frame, one parabola throughout
            // (the stream jumped onto it), the same positions before and after. Refitted between
            // its take-off and its landing ([`refit_flights`]), it lands a frame early here: these
            // legs stop folding at once, a landing no real leg makes (it would give), so the
            // hips' velocity meets the parabola's nowhere and the refit takes the frame before.
            let local: Vec<Vec<UnitQuaternion<f64>>> = (0..rig.len())
                .map(|j| knee.iter().map(|&k| pose(k)[j]).collect())
                .collect();
            let RootMotion {
                positions,
                contacts,
                ..
            } = root_positions(&rig, RootMode::Feet, &local, dt, &rest, &[None, None]);
            let flights = contacts.unwrap().airborne;
            assert_eq!(flights.len(), 1, "{flights:?}");
            let [start, end] = flights[0];
            assert!(
                start < first && start > fold_from && (last - 1..=last).contains(&end),
                "{flights:?} vs {air:?}"
            );
            for i in start + 1..end {
                let second = (positions[i + 1] - 2.0 * positions[i] + positions[i - 1]) / h;
                assert!((second.y + g * dt * dt).abs() < 1e-9, "{i}: {second}");
            }
            for i in 0..start {
                assert!((positions[i] - frames[i].position).norm() < 1e-12, "{i}");
            }
            // From its landing the feet carry the hips, a frame before the stream's: after it
            // the frames move as the stream's did, at its heights, shifted along the ground by
            // the feet's motion over that frame (the legs still folding: a little).
            let offset = positions[last + 1] - frames[last + 1].position;
            assert!(
                offset.y.abs() < 1e-12 && offset.norm() < 0.01 * h,
                "{offset} ({h})"
            );
            for i in last + 1..frames.len() {
                let moved = positions[i] - frames[i].position;
                assert!((moved - offset).norm() < 1e-12, "{i}: {moved} vs {offset}");
            }
        }
    }
}
