//! Paper 002's own pipeline, for its Listing-2 mappings (`pipeline.mode = "legacy-euler"`): yaw,
//! pitch and roll copied into Euler channels, as the paper keyed them into Blender.
//!
//! Stages, each a pure function below:
//! 1. **Angles as read** ([`node_angles`]): a SOU node's yaw/pitch/roll in degrees, verbatim. A
//!    quaternion take read with a legacy mapping gets them from `q_world_sensor` in the take's own
//!    world: intrinsic Z-Y-X angles ([`euler::from_quaternion`] with [`EulerOrder::ZYX`], yaw and
//!    roll in (−180°, 180°], pitch in [−90°, 90°]); the world is not changed.
//! 2. **Absolute → relative** (section 6.4, Listing 1, equations 14–16;
//!    [`subtract_last_value`]): per angle, child − parent, with the parents of Table 1 (the
//!    `sou12` rig's hierarchy); `N0_0` is the anchor and stays absolute. The parent's value is
//!    taken at each of the child's own timestamps by Listing 1's "last value" linear scan: the
//!    parent's most recent sample at or before the child's time (a parent row with the same
//!    timestamp counts, which makes the nodes of one SOU line subtract row by row as in
//!    equations 14–16). Before the parent's first sample its first sample is used (Listing 1
//!    would have no last value there; conventions.md holds sensors at their first sample).
//!    The parent's *absolute* angles are subtracted (Listing 1 records a node's value as a parent
//!    before subtracting its own parent), so a chain is never subtracted twice.
//! 3. **Signed channel copy** ([`copy_channel`]): each target bone's Blender X, Y, Z channel is
//!    `sign × angle` of the named relative angle (`yaw1` … of MPU1 = node `<SOU>_0`, `yaw2` … of
//!    MPU2 = node `<SOU>_1`).
//! 4. **Timestamps → frames** (equations 12–13: frame = t / δt, δt = 1000 / r ms): the paper keys
//!    sample k at the fractional frame t_k · fps; we evaluate the straight line between the two
//!    keys bracketing each frame of our grid (frame n at n / fps, frames 0 ..= ⌊t_last · fps⌋,
//!    t_last the latest sample of a mapped node; a node is held at its first/last sample outside
//!    its own range), **circularly** ([`resample_circular`]): from the earlier sample `a` towards
//!    the later `b` along the shorter way round, `a + wrap(b − a) · u` with `wrap` into
//!    (−180°, 180°]. That is linear interpolation of the unwrapped angle, so 359° and 1° give 0°
//!    (360°) half way, never 180°. Section 6.5's (cos, sin) averaging followed by `atan2` points
//!    the same way at the middle of a step and slightly differently elsewhere (it is to this what
//!    nlerp is to slerp); we interpolate the angle itself so that it moves at a constant rate
//!    between samples.
//! 5. **Euler discontinuity filter** (section 6.8; [`unwrap_filter`]) per channel, as Blender's
//!    Graph Editor filter treats a single channel: a frame at 180° or more from the previous frame
//!    is moved by whole turns towards it. The first frame keeps its value (a relative yaw of
//!    −358° stays −358°, the same rotation as 2°).
//!
//! Bones without a target keep their rest rotation; the root stays at its rest position.
//!
//! # Channel order
//!
//! The paper keyed Blender's `XYZ` Euler rotation mode, which is R = Rz(Z)·Ry(Y)·Rx(X) (Blender
//! names a mode by the order its rotations act on a vector, the reverse of our application-order
//! names; conventions.md). In BVH channel (application) order that is
//! `Zrotation Yrotation Xrotation`, our [`EulerOrder::ZYX`] with angles `[Z, Y, X]`, which is
//! what [`LegacyAnimation::euler_deg`] holds and what every joint of the output rig is set to. The
//! X, Y, Z axes are the axes of the joint frames of our rigs (BVH: at rest parallel to the Y-up
//! rig world), not the bone-roll frames of the Mixamo armature the paper keyed in Blender.
//!
//! What Blender 5.0.1's BVH importer does with such a file (its source,
//! `io_anim_bvh/import_bvh.py`, checked by `tests/outputs/legacy_mode.rs` with real Blender): it builds
//! each bone's rotation as `Euler(values, 'XYZ')` — R = Rz·Ry·Rx, exactly our reading — and
//! stores `B⁻¹·R·B` on the pose bone, B being the bone's rest orientation in the (still Y-up)
//! armature before the axis conversion, re-expressed as Euler angles in the pose bone's
//! rotation mode. With `rotate_mode='XYZ'` that mode is Blender `XYZ` and a bone whose rest is
//! the identity (it points along +Y with roll 0: Spine2, Neck, Head of the mixamo rig) stores
//! exactly the paper's X, Y, Z. With the default `rotate_mode='NATIVE'` the importer sets the
//! mode to the channel string *un*-reversed (`'ZYX'`, R = Rx·Ry·Rz), so the same rotation shows
//! other numbers there. Bones pointing elsewhere store the same rotation in their own bone axes:
//! along −Y (Hips, whose tail is the mean of its children, and the legs; B = Rz(180°)) as
//! `(−X, −Y, Z)` in `XYZ` mode; along ±X (arms) as a different triple. In every case the
//! rotation relative to rest in Blender's armature space,
//! `bone.matrix_local · matrix_basis · bone.matrix_localᵀ`, is C·R·Cᵀ, C the importer's Y-up →
//! Z-up axis conversion ((x, y, z) → (x, −z, y)), and posed bones are C·W·Cᵀ times their rest,
//! W the world rotation down the chain.

use super::resample::{FrameGrid, check_frame_rate, long_gaps};
use super::smoothing::smooth_angles_deg;
use super::sources::{no_sensors, unmapped_sensors};
use super::{PipelineError, PipelineOptions};
use crate::anim::Animation;
use crate::fps::Fps;
use crate::mapping::{LegacyChannel, LegacyMapping, LegacyTarget, MappingError};
use crate::rig::Rig;
use crate::rotation::euler;
use crate::rotation::{EulerOrder, wrap_deg};
use crate::take::{OrientationTrack, Take, Track};
use nalgebra::UnitQuaternion;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Yaw, pitch, roll in degrees (index 0, 1, 2 as [`crate::mapping::EulerSource::angle`]).
pub type Angles = [f64; 3];

/// The channel order every joint is written with: Blender's `XYZ` mode (see the module docs).
pub const LEGACY_ORDER: EulerOrder = EulerOrder::ZYX;

/// A node's yaw, pitch, roll in degrees at its own sample times (stage 1).
pub fn node_angles(track: &OrientationTrack) -> Track<Angles> {
    match track {
        OrientationTrack::YawPitchRollDeg(t) => t.map(|a| [a.yaw, a.pitch, a.roll]),
        OrientationTrack::Quaternion(t) => {
            t.map(|q| euler::from_quaternion(q, EulerOrder::ZYX).map(f64::to_degrees))
        }
    }
}

/// Stage 2: `child − parent` per angle at the child's timestamps, the parent's value being its
/// most recent sample at or before each of them (Listing 1's linear scan; the parent's first
/// sample before its range).
pub fn subtract_last_value(child: &Track<Angles>, parent: &Track<Angles>) -> Track<Angles> {
    let parent_times = parent.times_s();
    let parent_values = parent.values();
    // Number of parent samples at or before the current child time; only moves forward.
    let mut seen = 0;
    let values = child
        .iter()
        .map(|(t, c)| {
            while seen < parent_times.len() && parent_times[seen] <= t {
                seen += 1;
            }
            let p = parent_values[seen.saturating_sub(1)];
            [c[0] - p[0], c[1] - p[1], c[2] - p[2]]
        })
        .collect();
    Track::new(child.times_s().to_vec(), values).expect("the child's own times")
}

/// Stage 3: one Blender channel, `sign × angle` of a node's relative angles.
pub fn copy_channel(channel: &LegacyChannel, relative: &Track<Angles>) -> Track<f64> {
    let angle = channel.source.angle;
    relative.map(|a| channel.sign * a[angle])
}

/// Stage 4: a channel (degrees) at frames `first .. first + frames` of `fps`, interpolated along
/// the shorter way round between the samples bracketing each frame time; held at the first/last
/// sample outside the track.
pub fn resample_circular(track: &Track<f64>, fps: Fps, first: usize, frames: usize) -> Vec<f64> {
    let times = track.times_s();
    let values = track.values();
    let mut out = Vec::with_capacity(frames);
    // Number of samples at or before the frame time; frame times increase, so it only grows.
    let mut i = 0;
    for n in first..first + frames {
        let t = fps.frame_time_of(n as u64);
        while i < times.len() && times[i] <= t {
            i += 1;
        }
        let v = if i == 0 {
            values[0]
        } else if i == times.len() {
            values[i - 1]
        } else {
            let (t0, t1) = (times[i - 1], times[i]);
            let a = values[i - 1];
            a + wrap_deg(values[i] - a) * ((t - t0) / (t1 - t0))
        };
        out.push(v);
    }
    out
}

/// Stage 5: Blender's Euler discontinuity filter on one channel (degrees): every value 180° or
/// more away from the (already filtered) previous one is moved by whole turns until it is less
/// than 180° away. Blender shifts one turn at a time; the count is computed here, so huge values
/// cannot stall it.
pub fn unwrap_filter(values: &mut [f64]) {
    for k in 1..values.len() {
        let d = values[k - 1] - values[k];
        if d >= 180.0 {
            values[k] += 360.0 * (((d - 180.0) / 360.0).floor() + 1.0);
        } else if d <= -180.0 {
            values[k] -= 360.0 * (((-d - 180.0) / 360.0).floor() + 1.0);
        }
    }
}

/// A mapping target resolved on the output rig.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedTarget {
    pub target: LegacyTarget,
    /// Joint index in the output rig.
    pub bone: usize,
    /// The Table-1 parent subtracted from `target.node` (`None` for the anchor, a node outside
    /// Table 1, or a parent missing from the take).
    pub parent: Option<String>,
}

/// What the legacy pipeline produced.
#[derive(Debug, Clone)]
pub struct LegacyAnimation {
    /// The output rig (every joint's order [`LEGACY_ORDER`]) with each bone's rotation as a
    /// quaternion, for the glTF writer.
    pub animation: Animation,
    /// `euler_deg[joint][frame]`: `[Z, Y, X]` degrees, the BVH channel values (order
    /// [`LEGACY_ORDER`]); zeros for bones without a target.
    pub euler_deg: Vec<Vec<[f64; 3]>>,
    /// The targets that drove bones, in mapping order.
    pub targets: Vec<ResolvedTarget>,
    /// Frame of the take's grid that became frame 0 (non-zero after `--trim`).
    pub first_frame: usize,
    /// The root mode that ran (`auto` resolved), and the contacts in `feet` mode.
    pub root_mode: super::root::RootMode,
    pub contacts: Option<super::root::Contacts>,
    pub warnings: Vec<String>,
}

/// `rig` with every joint's channel order set to [`LEGACY_ORDER`].
fn with_legacy_order(rig: &Rig) -> Rig {
    if rig.joints().iter().all(|j| j.order == LEGACY_ORDER) {
        return rig.clone();
    }
    let joints = rig
        .joints()
        .iter()
        .cloned()
        .map(|mut j| {
            j.order = LEGACY_ORDER;
            j
        })
        .collect();
    Rig::new(rig.name(), rig.units(), joints).expect("a valid rig with other channel orders")
}

/// The node a channel reads: `<SOU>_0` for MPU1, `<SOU>_1` for MPU2.
fn source_node(target: &LegacyTarget, channel: &LegacyChannel) -> String {
    format!("{}_{}", target.sou, channel.source.mpu - 1)
}

/// Runs the legacy pipeline: `mapping` onto `rig`, parents from `table1` (the `sou12` rig).
/// `mapping_file` names the mapping in errors.
pub fn run(
    take: &Take,
    rig: &Rig,
    table1: &Rig,
    mapping: &LegacyMapping,
    mapping_file: &Path,
    options: &PipelineOptions,
) -> Result<LegacyAnimation, PipelineError> {
    let rig = with_legacy_order(rig);
    let mut warnings = Vec::new();

    // Resolve bones; an unknown bone is an error naming the mapping key.
    let mut resolved = Vec::new();
    for t in &mapping.targets {
        let bone = rig.joint_index(&t.target).ok_or_else(|| {
            MappingError::new(
                mapping_file,
                format!("{}.MPU{}.target", t.sou, t.mpu),
                format!("unknown bone `{}` in rig `{}`", t.target, rig.name()),
            )
        })?;
        resolved.push((t, bone));
    }

    // Stage 1 and 2 for every node a channel reads.
    let absolute = |node: &str| take.sensor(node).and_then(|s| s.orientation());
    let mut quaternion_nodes = BTreeSet::new();
    let mut relative: BTreeMap<String, (Track<Angles>, Option<String>)> = BTreeMap::new();
    let mut targets = Vec::new();
    let mut channels: Vec<(usize, [Track<f64>; 3])> = Vec::new();
    for (t, bone) in resolved {
        let nodes: BTreeSet<String> = t.channels.iter().map(|c| source_node(t, c)).collect();
        let missing: Vec<&String> = nodes.iter().filter(|n| absolute(n).is_none()).collect();
        if !missing.is_empty() {
            let list = missing.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>();
            let what = match take.sensor(missing[0]) {
                Some(_) => "has no orientation data",
                None => "is not in the take",
            };
            warnings.push(format!(
                "node {} (mapped to `{}`) {what}; `{}` keeps its rest rotation",
                list.join(", "),
                t.target,
                t.target
            ));
            continue;
        }
        for node in &nodes {
            if relative.contains_key(node) {
                continue;
            }
            let track = absolute(node).expect("checked above");
            if matches!(track, OrientationTrack::Quaternion(_)) {
                quaternion_nodes.insert(node.clone());
            }
            let own = node_angles(track);
            let parent = match table1.joint_index(node) {
                None => {
                    warnings.push(format!(
                        "node `{node}` is not in paper 002's Table 1 (rig `{}`); its angles are used as read (absolute)",
                        table1.name()
                    ));
                    None
                }
                Some(j) => table1.joints()[j]
                    .parent
                    .map(|p| table1.joints()[p].name.clone()),
            };
            let entry = match parent.as_deref().map(|p| (p, absolute(p))) {
                None => (own, None),
                Some((p, Some(parent_track))) => (
                    subtract_last_value(&own, &node_angles(parent_track)),
                    Some(p.to_string()),
                ),
                Some((p, None)) => {
                    warnings.push(format!(
                        "node `{node}`'s Table-1 parent `{p}` has no orientation data in the take; `{node}` keeps its absolute angles"
                    ));
                    (own, None)
                }
            };
            relative.insert(node.clone(), entry);
        }
        // Stage 3.
        let copy = |k: usize| {
            let c = &t.channels[k];
            copy_channel(c, &relative[&source_node(t, c)].0)
        };
        channels.push((bone, [copy(0), copy(1), copy(2)]));
        targets.push(ResolvedTarget {
            target: t.clone(),
            bone,
            parent: relative[&t.node].1.clone(),
        });
    }
    if !quaternion_nodes.is_empty() {
        warnings.push(format!(
            "legacy mode: node(s) {} carry quaternions; their yaw/pitch/roll are the intrinsic Z-Y-X Euler angles of q_world_sensor in the take's world ({})",
            quaternion_nodes.into_iter().collect::<Vec<_>>().join(", "),
            take.source().world
        ));
    }
    let used: BTreeSet<&str> = relative
        .iter()
        .flat_map(|(n, (_, p))| std::iter::once(n.as_str()).chain(p.as_deref()))
        .collect();
    warnings.extend(unmapped_sensors(take, |id| used.contains(id)));
    if channels.is_empty() {
        return Err(no_sensors(
            take,
            mapping.targets.iter().map(|t| t.node.as_str()),
        ));
    }

    // Stage 4: the frame grid over the mapped nodes.
    let t_last = relative
        .values()
        .map(|(t, _)| t.last_time_s())
        .fold(0.0, f64::max);
    let grid = FrameGrid::new(options.fps, t_last, options.trim)?;
    let FrameGrid { first, frames, .. } = grid;
    let times: Vec<&[f64]> = relative.values().map(|(t, _)| t.times_s()).collect();
    check_frame_rate(&grid, options.force, &times, rig.len(), &mut warnings)?;
    let names: Vec<&str> = relative.keys().map(String::as_str).collect();
    warnings.extend(long_gaps(&names, &times, &grid));

    let mut not_smoothed: Vec<String> = Vec::new();
    let mut euler_deg = vec![vec![[0.0; 3]; frames]; rig.len()];
    let mut local = vec![vec![UnitQuaternion::identity(); frames]; rig.len()];
    let mut animated = vec![false; rig.len()];
    for (bone, xyz) in &channels {
        // Stages 4 and 5 per channel.
        // Smoothing on the frame grid, through (cos, sin) pairs (paper 002, 6.5).
        let method = options.smoothing.for_bone(&rig.joints()[*bone].name);
        let [x, y, z] = xyz.each_ref().map(|c| {
            let mut v = resample_circular(c, options.fps, first, frames);
            unwrap_filter(&mut v);
            match smooth_angles_deg(&v, options.fps.as_f64(), method) {
                Ok(smoothed) => smoothed,
                Err(why) => {
                    not_smoothed.push(why.0);
                    v
                }
            }
        });
        for f in 0..frames {
            let zyx = [z[f], y[f], x[f]];
            euler_deg[*bone][f] = zyx;
            local[*bone][f] = euler::to_quaternion(zyx.map(f64::to_radians), LEGACY_ORDER);
        }
        animated[*bone] = true;
    }
    if let Some(why) = not_smoothed.first() {
        warnings.push(format!(
            "{} channels are not smoothed, e.g. because {why}",
            not_smoothed.len()
        ));
    }
    // Paper 002's mode keeps its root fixed unless another mode is asked for by name.
    let root_mode = match options.root {
        super::root::RootMode::Auto => super::root::RootMode::Fixed,
        mode => mode,
    };
    let super::root::RootMotion {
        positions: roots,
        contacts,
        ..
    } = super::root::root_positions(
        &rig,
        root_mode,
        &local,
        options.fps.frame_time_s(),
        &vec![nalgebra::UnitQuaternion::identity(); rig.len()],
        &[None, None],
    );
    let mut animation = Animation::new(rig, options.fps, local, animated, roots)?;
    if let Some(c) = &contacts {
        animation = animation.with_contacts(c.per_frame.clone())?;
    }
    Ok(LegacyAnimation {
        animation,
        root_mode,
        contacts,
        euler_deg,
        targets,
        first_frame: first,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mapping::EulerSource;
    use crate::rig::load_rig;

    fn track<T>(times: &[f64], values: Vec<T>) -> Track<T> {
        Track::new(times.to_vec(), values).unwrap()
    }

    #[test]
    fn subtraction_uses_the_parents_last_value_on_asynchronous_times() {
        let parent = track(
            &[0.010, 0.040, 0.080],
            vec![[10.0, 1.0, -1.0], [20.0, 2.0, -2.0], [30.0, 3.0, -3.0]],
        );
        // Before the parent's first sample, at one of its times, between two, after its last.
        let child = track(
            &[0.000, 0.040, 0.079, 0.200],
            vec![
                [15.0, 5.0, 5.0],
                [25.0, 5.0, 5.0],
                [35.0, 5.0, 5.0],
                [45.0, 5.0, 5.0],
            ],
        );
        let rel = subtract_last_value(&child, &parent);
        assert_eq!(rel.times_s(), child.times_s());
        assert_eq!(
            rel.values(),
            &[
                [5.0, 4.0, 6.0],  // held first parent sample
                [5.0, 3.0, 7.0],  // same timestamp counts (equations 14–16)
                [15.0, 3.0, 7.0], // 0.079 < 0.080: still the 0.040 sample
                [15.0, 2.0, 8.0], // after the parent's last sample
            ]
        );
        // No wrapping: 1° − 359° stays −358° (the filter makes later frames continuous).
        let p = track(&[0.0], vec![[359.0, 0.0, 0.0]]);
        let c = track(&[0.0], vec![[1.0, 0.0, 0.0]]);
        assert_eq!(subtract_last_value(&c, &p).values()[0][0], -358.0);
    }

    #[test]
    fn circular_resampling_never_averages_359_and_1_to_180() {
        let fps = Fps::new(10, 1).unwrap();
        // Samples at 0.0 s (359°), 0.2 s (1°), 0.4 s (3°): frames at 0.0, 0.1, ..., 0.5 s.
        let t = track(&[0.0, 0.2, 0.4], vec![359.0, 1.0, 3.0]);
        let v = resample_circular(&t, fps, 0, 6);
        let expected = [359.0, 360.0, 1.0, 2.0, 3.0, 3.0];
        for (a, b) in v.iter().zip(expected) {
            assert!((a - b).abs() < 1e-9, "{v:?}");
        }
        // Downwards across the wrap, and a frame before the first sample is held.
        let t = track(&[0.1, 0.3], vec![2.0, 358.0]);
        let v = resample_circular(&t, fps, 0, 4);
        let expected = [2.0, 2.0, 0.0, 358.0];
        for (a, b) in v.iter().zip(expected) {
            assert!((a - b).abs() < 1e-9, "{v:?}");
        }
        // A first frame past 0 (trim).
        assert_eq!(resample_circular(&t, fps, 3, 1), vec![358.0]);
        assert_eq!(wrap_deg(180.0), 180.0);
        assert_eq!(wrap_deg(-180.0), 180.0);
        assert_eq!(wrap_deg(-181.0), 179.0);
        assert_eq!(wrap_deg(720.5), 0.5);
    }

    #[test]
    fn the_filter_unwraps_each_channel_towards_the_previous_frame() {
        let mut v = vec![350.0, 359.0, 2.0, 5.0, 364.0, -170.0, 170.0];
        unwrap_filter(&mut v);
        assert_eq!(v, vec![350.0, 359.0, 362.0, 365.0, 364.0, 190.0, 170.0]);
        // The first value is kept; several turns at once.
        let mut v = vec![-358.0, 1083.0];
        unwrap_filter(&mut v);
        assert_eq!(v, vec![-358.0, -357.0]);
        // Exactly 180° away moves to the other side, as Blender's `>= M_PI` test does.
        let mut v = vec![0.0, -180.0, 100.0];
        unwrap_filter(&mut v);
        assert_eq!(v, vec![0.0, 180.0, 100.0]);
        let mut empty: Vec<f64> = vec![];
        unwrap_filter(&mut empty);
    }

    #[test]
    fn channel_copy_applies_the_sign_to_the_named_angle() {
        let rel = track(&[0.0, 0.5], vec![[10.0, 20.0, 30.0], [-1.0, -2.0, -3.0]]);
        let minus_pitch = LegacyChannel {
            sign: -1.0,
            source: EulerSource { angle: 1, mpu: 2 },
        };
        let plus_roll = LegacyChannel {
            sign: 1.0,
            source: EulerSource { angle: 2, mpu: 2 },
        };
        assert_eq!(copy_channel(&minus_pitch, &rel).values(), &[-20.0, 2.0]);
        assert_eq!(copy_channel(&plus_roll, &rel).values(), &[30.0, -3.0]);
        assert_eq!(copy_channel(&plus_roll, &rel).times_s(), rel.times_s());
    }

    #[test]
    fn quaternion_tracks_give_intrinsic_zyx_degrees() {
        let ypr = crate::take::YawPitchRollDeg {
            yaw: 120.0,
            pitch: -30.0,
            roll: 45.0,
        };
        let q = OrientationTrack::Quaternion(track(&[0.0], vec![ypr.to_quaternion()]));
        let a = node_angles(&q).values()[0];
        for (got, want) in a.iter().zip([120.0, -30.0, 45.0]) {
            assert!((got - want).abs() < 1e-9, "{a:?}");
        }
        let e = OrientationTrack::YawPitchRollDeg(track(&[0.0], vec![ypr]));
        assert_eq!(node_angles(&e).values()[0], [120.0, -30.0, 45.0]);
    }

    #[test]
    fn a_take_runs_end_to_end_with_table_1_parents() {
        use crate::read::{ReadOptions, sou};
        let log = "1000,N0,90,0,0,100,5,0\n\
                   1020,N1,95,0,-10,97,0,-30\n\
                   1040,N0,90,0,0,110,5,0\n\
                   1060,N1,95,0,-10,97,0,-30\n";
        let take =
            sou::read_from(log.as_bytes(), Path::new("t.log"), &ReadOptions::default()).unwrap();
        let text = r#"{"N0": {"MPU2": {"target": "Spine2", "X": "-pitch2", "Y": "-yaw2", "Z": "+roll2"}},
                       "N1": {"MPU1": {"target": "RightArm", "X": "-pitch1", "Y": "-yaw1", "Z": "+roll1"},
                              "MPU2": {"target": "RightForeArm", "X": "+pitch2", "Y": "+yaw2", "Z": "+roll2"}}}"#;
        let crate::mapping::MappingFile::Legacy(mapping) =
            crate::mapping::parse_mapping(text, Path::new("l.json")).unwrap()
        else {
            panic!("a Listing-2 mapping")
        };
        let rig = load_rig("mixamo").unwrap();
        let table1 = load_rig("sou12").unwrap();
        // No smoothing: the test checks the paper's channel copy exactly.
        let options = PipelineOptions {
            fps: Fps::new(50, 1).unwrap(),
            smoothing: crate::smooth::Smoothing::none(),
            ..PipelineOptions::default()
        };
        let out = run(
            &take,
            &rig,
            &table1,
            &mapping,
            Path::new("l.json"),
            &options,
        )
        .unwrap();
        // Samples from 0 to 60 ms: frames 0, 20, 40, 60 ms.
        assert_eq!(out.animation.frames(), 4);
        let spine2 = rig.joint_index("Spine2").unwrap();
        let arm = rig.joint_index("RightArm").unwrap();
        let fore = rig.joint_index("RightForeArm").unwrap();
        // N0_1 − N0_0: yaw 10 then 20 (at 40 ms); frame 1 (20 ms) half way: 15. Y = −yaw.
        assert!((out.euler_deg[spine2][1][1] + 15.0).abs() < 1e-9);
        // N1_0 − N0_1 (last value at 20 ms: the 0 ms row): yaw 95 − 100 = −5, pitch 0 − 5 = −5,
        // roll −10; [Z, Y, X] = [+roll, −yaw, −pitch].
        assert_eq!(out.euler_deg[arm][1], [-10.0, 5.0, 5.0]);
        // At 60 ms the last N0 row (40 ms) counts: yaw 95 − 110 = −15; at 40 ms half way.
        assert_eq!(out.euler_deg[arm][3], [-10.0, 15.0, 5.0]);
        assert!((out.euler_deg[arm][2][1] - 10.0).abs() < 1e-9);
        // N1_1 − N1_0, same rows: yaw 2, roll −20.
        assert_eq!(out.euler_deg[fore][2], [-20.0, 2.0, 0.0]);
        // Frame 0 is before N1's first row: held.
        assert_eq!(out.euler_deg[fore][0], [-20.0, 2.0, 0.0]);
        let parents: Vec<_> = out.targets.iter().map(|t| t.parent.as_deref()).collect();
        assert_eq!(parents, [Some("N0_0"), Some("N0_1"), Some("N1_0")]);
        // The quaternion is R = Rz(Z)·Ry(Y)·Rx(X).
        let q = out.animation.local(arm)[1];
        let r = |axis: nalgebra::Unit<nalgebra::Vector3<f64>>, deg: f64| {
            UnitQuaternion::from_axis_angle(&axis, deg.to_radians())
        };
        let want = r(nalgebra::Vector3::z_axis(), -10.0)
            * r(nalgebra::Vector3::y_axis(), 5.0)
            * r(nalgebra::Vector3::x_axis(), 5.0);
        assert!(q.angle_to(&want) < 1e-12);
        assert!(!out.animation.is_animated(rig.joint_index("Hips").unwrap()));
        // N0_0 is read as Spine2's parent: every sensor of the take is used.
        assert!(out.warnings.is_empty(), "{:?}", out.warnings);
    }
}
