//! The BVH writer: a [`Rig`], a rational frame rate, root positions and per-joint Euler angles
//! ([`BvhMotion`]) → a file that Blender, `bvh_anim` and [`crate::bvh::parse`] read back; see
//! [`write_bvh_scaled`] for the exact layout, the End Sites it adds and the checks it makes, and
//! [`write_bvh_in`] for writing another unit (`--units cm`: lengths × 100 from a metre rig).

use super::decimal::push_fixed6;
use crate::fps::Fps;
use crate::rig::{LengthUnit, Rig};
use crate::rotation::euler::TrackFilter;
use nalgebra::{UnitQuaternion, Vector3};
use rayon::prelude::*;
use std::io::{self, BufWriter, Write};

/// Motion to write: a rig, a frame rate, and per frame the root position and every joint's
/// Euler angles.
#[derive(Debug, Clone, Copy)]
pub struct BvhMotion<'a> {
    pub rig: &'a Rig,
    pub fps: Fps,
    /// The root joint's position in the world at every frame, in the rig's unit. Written as the
    /// root's position channels, which replace its OFFSET when read (the OFFSET written is the
    /// rig's rest offset of the root).
    pub root_positions: &'a [Vector3<f64>],
    /// Every joint's rotation at every frame, as Euler angles or as rotations to turn into them.
    pub euler_deg: Angles<'a>,
    /// Joints other than the root with position channels: per frame their translation from the
    /// parent (rig units), written before their rotations, replacing their OFFSET when read.
    pub translations: &'a [(usize, Vec<Vector3<f64>>)],
}

/// The joints' rotations a BVH's channels hold.
#[derive(Debug, Clone, Copy)]
pub enum Angles<'a> {
    /// `[joint][frame]`: the joint's local rotation as Euler angles in degrees, in the joint's own
    /// order (`rig.joints()[joint].order`), listed in application order, which is the BVH channel
    /// order: for ZXY, `[z, x, y]` meaning Rz(z)·Rx(x)·Ry(y).
    Degrees(&'a [Vec<[f64; 3]>]),
    /// `[joint][frame]`: local rotations, turned into those angles by the Euler discontinuity
    /// filter ([`crate::rotation::euler::filter_track_degrees`]) a group of frames at a time as
    /// the lines are written, never the whole take's angles at once.
    Rotations(&'a [Vec<UnitQuaternion<f64>>]),
}

impl Angles<'_> {
    /// Tracks, one per joint.
    fn joints(&self) -> usize {
        match self {
            Angles::Degrees(t) => t.len(),
            Angles::Rotations(t) => t.len(),
        }
    }

    /// Joint `j`'s frames.
    fn frames(&self, j: usize) -> usize {
        match self {
            Angles::Degrees(t) => t[j].len(),
            Angles::Rotations(t) => t[j].len(),
        }
    }

    /// The first frame of joint `j` with a non-finite number, if any.
    fn first_non_finite(&self, j: usize) -> Option<usize> {
        let finite = |v: &[f64]| v.iter().all(|v| v.is_finite());
        match self {
            Angles::Degrees(t) => t[j].iter().position(|a| !finite(a)),
            Angles::Rotations(t) => t[j].iter().position(|q| !finite(q.coords.as_slice())),
        }
    }
}

/// The factor that converts lengths in `from` to lengths in `to` (metres → centimetres: 100).
pub fn unit_scale(from: LengthUnit, to: LengthUnit) -> f64 {
    if from == to {
        1.0
    } else {
        from.metres_per_unit() / to.metres_per_unit()
    }
}

/// Writes `motion` as BVH in the rig's own unit. See [`write_bvh_scaled`].
pub fn write_bvh<W: Write + Send>(out: W, motion: &BvhMotion) -> io::Result<()> {
    write_bvh_scaled(out, motion, 1.0)
}

/// Writes `motion` as BVH with lengths converted from the rig's unit to `units`
/// (`--units cm` on a metre rig multiplies offsets, End Sites and root positions by 100).
pub fn write_bvh_in<W: Write + Send>(
    out: W,
    motion: &BvhMotion,
    units: LengthUnit,
) -> io::Result<()> {
    write_bvh_scaled(out, motion, unit_scale(motion.rig.units(), units))
}

fn invalid(message: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, message)
}

/// Writes `motion` as BVH with every length (offsets, End Sites, root positions) multiplied by
/// `scale`; angles are not scaled.
///
/// Layout (deterministic: identical input gives identical bytes):
///
/// ```text
/// HIERARCHY
/// ROOT Hips
/// {
/// <tab>OFFSET 0.000000 1.000000 0.000000
/// <tab>CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
/// <tab>JOINT Spine
/// <tab>{
/// <tab><tab>OFFSET ...
/// <tab><tab>CHANNELS 3 Zrotation Xrotation Yrotation
/// <tab><tab>End Site
/// <tab><tab>{
/// <tab><tab><tab>OFFSET ...
/// <tab><tab>}
/// <tab>}
/// }
/// MOTION
/// Frames: 2
/// Frame Time: 0.03336666666666667
/// 0.000000 1.000000 ...
/// ```
///
/// - Lines end with LF only; indentation is one tab per level.
/// - Rotation channels are each joint's [`order`](crate::rig::Joint::order) in application order
///   ([`EulerOrder::bvh_channels`](crate::rotation::EulerOrder::bvh_channels)); only the root has
///   position channels.
/// - Joints are written depth first, children in rig order; for a rig already in depth-first
///   order (every rig read from a BVH file) the file's joint order is the rig's.
/// - `Frame Time:` is 1/fps from the rational, written with the shortest decimal that reads back
///   as the same `f64` (30000/1001 fps → `0.03336666666666667`), so importers that set the scene
///   rate from it (Blender: fps 30, fps_base 1.001) recover the rate.
/// - Offsets and motion values are written with 6 decimals (1 µm in metres, 1e-6°).
/// - Every leaf joint gets an End Site, as every importer expects one (Blender makes a leaf
///   bone's tail from it; without one the bone gets an arbitrary 0.1-unit tail along +Y). It is
///   the rig's [`end_site`](crate::rig::Joint::end_site) when it has one; otherwise the End Site
///   continues the joint's own direction from its parent (its offset, or the nearest ancestor's
///   non-zero offset) for half that offset's length, and a leaf root gets 0.1 m along +Y. A
///   non-leaf joint gets an End Site only when the rig gives it one.
///
/// Fails with [`io::ErrorKind::InvalidInput`], before writing anything, when
/// `euler_deg.len()` is not the number of joints, when an `euler_deg[j]` does not have one entry
/// per frame (`root_positions.len()` frames), when a value is not finite, when `scale` is not a
/// positive number, or when a joint name is empty or contains whitespace or braces (no reader
/// could read it back).
pub fn write_bvh_scaled<W: Write + Send>(out: W, motion: &BvhMotion, scale: f64) -> io::Result<()> {
    let rig = motion.rig;
    let frames = motion.root_positions.len();
    validate(motion, scale)?;

    let joints = rig.joints();
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); joints.len()];
    for (i, j) in joints.iter().enumerate() {
        if let Some(p) = j.parent {
            children[p].push(i);
        }
    }

    let mut out = BufWriter::new(out);
    let mut buf = Vec::with_capacity(256);
    buf.extend_from_slice(b"HIERARCHY\n");

    // Depth-first: an explicit stack of (joint, depth, entered).
    let mut order: Vec<usize> = Vec::with_capacity(joints.len());
    let mut stack: Vec<(usize, usize, bool)> = vec![(0, 0, false)];
    while let Some((j, depth, entered)) = stack.pop() {
        let joint = &joints[j];
        if entered {
            if let Some(end) = end_site(rig, j, &children[j]) {
                indent(&mut buf, depth + 1);
                buf.extend_from_slice(b"End Site\n");
                indent(&mut buf, depth + 1);
                buf.extend_from_slice(b"{\n");
                indent(&mut buf, depth + 2);
                buf.extend_from_slice(b"OFFSET");
                push_vector(&mut buf, &(end * scale));
                buf.push(b'\n');
                indent(&mut buf, depth + 1);
                buf.extend_from_slice(b"}\n");
            }
            indent(&mut buf, depth);
            buf.extend_from_slice(b"}\n");
            out.write_all(&buf)?;
            buf.clear();
            continue;
        }
        order.push(j);
        indent(&mut buf, depth);
        buf.extend_from_slice(if j == 0 { b"ROOT " } else { b"JOINT " });
        buf.extend_from_slice(joint.name.as_bytes());
        buf.push(b'\n');
        indent(&mut buf, depth);
        buf.extend_from_slice(b"{\n");
        indent(&mut buf, depth + 1);
        buf.extend_from_slice(b"OFFSET");
        push_vector(&mut buf, &(joint.offset * scale));
        buf.push(b'\n');
        indent(&mut buf, depth + 1);
        if j == 0 || motion.translations.iter().any(|(t, _)| *t == j) {
            buf.extend_from_slice(b"CHANNELS 6 Xposition Yposition Zposition");
        } else {
            buf.extend_from_slice(b"CHANNELS 3");
        }
        for c in joint.order.bvh_channels() {
            buf.push(b' ');
            buf.extend_from_slice(c.as_bytes());
        }
        buf.push(b'\n');
        stack.push((j, depth, true));
        for &c in children[j].iter().rev() {
            stack.push((c, depth + 1, false));
        }
        out.write_all(&buf)?;
        buf.clear();
    }

    writeln!(
        buf,
        "MOTION\nFrames: {frames}\nFrame Time: {}",
        motion.fps.frame_time_s()
    )?;
    out.write_all(&buf)?;
    buf.clear();

    // The motion lines, formatted in blocks of frames on every core and written in order.
    let translations: Vec<Option<&[Vector3<f64>]>> = order
        .iter()
        .map(|&j| {
            motion
                .translations
                .iter()
                .find(|(t, _)| *t == j && j != 0)
                .map(|(_, t)| t.as_slice())
        })
        .collect();
    // `runs[j]`: joint j's angles for the group of frames from `first` on.
    let lines = |frames: std::ops::Range<usize>, runs: &[&[[f64; 3]]], first: usize| {
        let mut text = Vec::with_capacity(frames.len() * (order.len() * 30 + 32));
        // The block's angles frame by frame: each joint's run read in one sweep (reading them
        // frame by frame hops between every joint's track and waits on memory at each hop).
        // A joint whose angles hold through the block (one that never moves) has its three
        // numbers formatted once and copied into each line: `held[k]` is their text's range in
        // `held_text`.
        let width = order.len();
        let mut angles = vec![[0.0; 3]; frames.len() * width];
        let mut held: Vec<Option<std::ops::Range<usize>>> = vec![None; width];
        let mut held_text = Vec::new();
        let push_root = |text: &mut Vec<u8>, f: usize| {
            let root = motion.root_positions[f] * scale;
            push_fixed6(text, root.x);
            push_numbers(text, &[root.y, root.z]);
        };
        // So does a root that stays in place (`--root fixed`).
        let roots = &motion.root_positions[frames.clone()];
        let root_bits = |p: &Vector3<f64>| p.map(f64::to_bits);
        let root_held = roots
            .iter()
            .all(|p| root_bits(p) == root_bits(&roots[0]))
            .then(|| {
                push_root(&mut held_text, frames.start);
                0..held_text.len()
            });
        for (k, &j) in order.iter().enumerate() {
            let run = &runs[j][frames.start - first..frames.end - first];
            let first = run[0].map(f64::to_bits);
            if run.iter().all(|a| a.map(f64::to_bits) == first) {
                let start = held_text.len();
                push_numbers(&mut held_text, &run[0]);
                held[k] = Some(start..held_text.len());
                continue;
            }
            for (i, a) in run.iter().enumerate() {
                angles[i * width + k] = *a;
            }
        }
        for (i, f) in frames.enumerate() {
            // The root's position first, the line starting with its number.
            if let Some(range) = &root_held {
                text.extend_from_slice(&held_text[range.clone()]);
            } else {
                push_root(&mut text, f);
            }
            let frame_angles = &angles[i * width..(i + 1) * width];
            for ((translation, joint_angles), held) in
                translations.iter().zip(frame_angles).zip(&held)
            {
                if let Some(t) = translation {
                    push_vector(&mut text, &(t[f] * scale));
                }
                if let Some(range) = held {
                    text.extend_from_slice(&held_text[range.clone()]);
                    continue;
                }
                push_numbers(&mut text, joint_angles);
            }
            text.push(b'\n');
        }
        text
    };
    // A thread of its own writes each group of blocks while the cores format the next: the
    // copies into the file run beside the formatting instead of between its groups.
    let group = BLOCK_FRAMES * 2 * rayon::current_num_threads();
    std::thread::scope(|scope| {
        let (formatted, groups) = std::sync::mpsc::sync_channel::<Vec<Vec<u8>>>(1);
        let writer = scope.spawn(move || -> io::Result<()> {
            for blocks in groups {
                for block in blocks {
                    out.write_all(&block)?;
                }
            }
            out.flush()
        });
        // Rotations become angles a group at a time, each joint's filter running on from the
        // group before, into buffers kept from group to group.
        let mut filters: Vec<TrackFilter> =
            joints.iter().map(|j| TrackFilter::new(j.order)).collect();
        let mut made: Vec<Vec<[f64; 3]>> = vec![Vec::new(); joints.len()];
        for start in (0..frames).step_by(group) {
            let end = (start + group).min(frames);
            let runs: Vec<&[[f64; 3]]> = match motion.euler_deg {
                Angles::Degrees(tracks) => tracks.iter().map(|t| &t[start..end]).collect(),
                Angles::Rotations(tracks) => {
                    made.par_iter_mut().zip(&mut filters).zip(tracks).for_each(
                        |((out, filter), track)| {
                            out.clear();
                            filter.extend_degrees(&track[start..end], out);
                        },
                    );
                    made.iter().map(Vec::as_slice).collect()
                }
            };
            let blocks: Vec<Vec<u8>> = (start..end)
                .step_by(BLOCK_FRAMES)
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|b| lines(b..(b + BLOCK_FRAMES).min(end), &runs, start))
                .collect();
            // The writer stopped on an error, which its result reports.
            if formatted.send(blocks).is_err() {
                break;
            }
        }
        drop(formatted);
        writer
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
}

/// Frames formatted together: big enough to keep a core busy, small enough to stay in cache.
const BLOCK_FRAMES: usize = 256;

fn validate(motion: &BvhMotion, scale: f64) -> io::Result<()> {
    let rig = motion.rig;
    let frames = motion.root_positions.len();
    if !(scale.is_finite() && scale > 0.0) {
        return Err(invalid(format!(
            "BVH scale must be a positive number, got {scale}"
        )));
    }
    let angles = &motion.euler_deg;
    if angles.joints() != rig.len() {
        return Err(invalid(format!(
            "BVH motion has Euler angles for {} joints but rig `{}` has {} joints",
            angles.joints(),
            rig.name(),
            rig.len()
        )));
    }
    for (j, joint) in rig.joints().iter().enumerate() {
        if angles.frames(j) != frames {
            return Err(invalid(format!(
                "BVH motion: joint {j} `{}` has {} frames of Euler angles but there are {frames} root positions",
                joint.name,
                angles.frames(j)
            )));
        }
        if let Some(f) = angles.first_non_finite(j) {
            return Err(invalid(format!(
                "BVH motion: joint `{}` has a non-finite angle at frame {f}",
                joint.name
            )));
        }
        if joint.name.is_empty()
            || joint
                .name
                .chars()
                .any(|c| c.is_whitespace() || c == '{' || c == '}')
        {
            return Err(invalid(format!(
                "BVH joint names must be non-empty without spaces or braces: `{}`",
                joint.name
            )));
        }
    }
    for (j, t) in motion.translations {
        if *j >= rig.len()
            || t.len() != frames
            || !t.iter().all(|p| p.iter().all(|v| v.is_finite()))
        {
            return Err(invalid(format!(
                "BVH motion: joint {j}'s translations are not {frames} finite vectors of a joint of the rig"
            )));
        }
    }
    if let Some(f) = motion
        .root_positions
        .iter()
        .position(|p| !p.iter().all(|v| v.is_finite()))
    {
        return Err(invalid(format!(
            "BVH motion: root position at frame {f} is not finite"
        )));
    }
    Ok(())
}

/// The End Site written after `j`'s children, if any (see [`write_bvh_scaled`]).
fn end_site(rig: &Rig, j: usize, children: &[usize]) -> Option<Vector3<f64>> {
    let joints = rig.joints();
    if let Some(e) = joints[j].end_site {
        return Some(e);
    }
    if !children.is_empty() {
        return None;
    }
    // Continue the bone's direction: the joint's offset from its parent, or the nearest ancestor's
    // non-zero one (a zero-offset leaf sits on its parent's head). The root's offset is a
    // position, not a direction, so it is not used.
    let tiny = 1e-6 / rig.units().metres_per_unit();
    let mut k = j;
    while let Some(p) = joints[k].parent {
        let offset = joints[k].offset;
        if offset.norm() > tiny {
            return Some(offset * 0.5);
        }
        k = p;
    }
    Some(Vector3::new(0.0, 0.1 / rig.units().metres_per_unit(), 0.0))
}

fn indent(buf: &mut Vec<u8>, depth: usize) {
    for _ in 0..depth {
        buf.push(b'\t');
    }
}

/// ` x y z` (each preceded by a space), six decimals; a value that rounds to zero is written as
/// `0.000000` whatever its sign ([`push_fixed6`]).
fn push_vector(buf: &mut Vec<u8>, v: &Vector3<f64>) {
    push_numbers(buf, v.as_slice());
}

/// Each number with a space before it.
fn push_numbers(buf: &mut Vec<u8>, values: &[f64]) {
    for &x in values {
        buf.push(b' ');
        push_fixed6(buf, x);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::Joint;
    use crate::rotation::EulerOrder;
    use crate::rotation::euler::{filter_track_degrees, to_quaternion};

    /// A chain of six joints, one per Euler order.
    fn six_orders() -> Rig {
        let joints = EulerOrder::ALL
            .iter()
            .enumerate()
            .map(|(i, &order)| Joint {
                name: format!("j{i}"),
                parent: i.checked_sub(1),
                offset: Vector3::new(0.0, 0.1 * i as f64, 0.0),
                order,
                end_site: None,
            })
            .collect();
        Rig::new("six", LengthUnit::Metres, joints).unwrap()
    }

    /// Rotations written as they are made into angles, a group of frames at a time, give the
    /// very bytes of the angles made for the whole take first: 2 600 frames (groups end in the
    /// middle), spins across ±180°, passes through gimbal lock, and joints holding still for a
    /// while (the filter's settled state carried from one group to the next).
    #[test]
    fn angles_made_while_writing_match_angles_made_first() {
        let rig = six_orders();
        let frames = 2600;
        let rotations: Vec<Vec<UnitQuaternion<f64>>> = rig
            .joints()
            .iter()
            .enumerate()
            .map(|(j, joint)| {
                (0..frames)
                    .map(|f| {
                        // Held still over frames 900..1500 (and all along for the last joint).
                        let t = if (900..1500).contains(&f) || j == 5 {
                            900
                        } else {
                            f
                        } as f64;
                        let a = [
                            t * 0.031 * (j + 1) as f64,
                            (t * 0.004 + j as f64).sin() * 1.7,
                            -t * 0.017,
                        ];
                        to_quaternion(a, joint.order)
                    })
                    .collect()
            })
            .collect();
        let roots = vec![Vector3::new(0.0, 1.0, 0.0); frames];
        let degrees: Vec<Vec<[f64; 3]>> = rotations
            .iter()
            .zip(rig.joints())
            .map(|(track, joint)| filter_track_degrees(track, joint.order))
            .collect();
        let write = |angles: Angles| {
            let mut out = Vec::new();
            let motion = BvhMotion {
                rig: &rig,
                fps: "60".parse().unwrap(),
                root_positions: &roots,
                euler_deg: angles,
                translations: &[],
            };
            write_bvh(&mut out, &motion).unwrap();
            out
        };
        let made_first = write(Angles::Degrees(&degrees));
        assert!(made_first.len() > 100_000);
        assert!(write(Angles::Rotations(&rotations)) == made_first);
    }

    /// Rotations are checked before anything is written, as angles are.
    #[test]
    fn bad_rotations_are_refused_before_writing() {
        let rig = six_orders();
        let roots = vec![Vector3::zeros(); 3];
        let mut rotations = vec![vec![UnitQuaternion::identity(); 3]; rig.len()];
        rotations[2][1] =
            UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
        let short = vec![vec![UnitQuaternion::identity(); 2]; rig.len()];
        for (rotations, what) in [(&rotations, "non-finite angle"), (&short, "2 frames")] {
            let mut out = Vec::new();
            let motion = BvhMotion {
                rig: &rig,
                fps: "60".parse().unwrap(),
                root_positions: &roots,
                euler_deg: Angles::Rotations(rotations),
                translations: &[],
            };
            let err = write_bvh(&mut out, &motion).unwrap_err();
            assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
            assert!(err.to_string().contains(what), "{err}");
            assert!(out.is_empty());
        }
    }
}
