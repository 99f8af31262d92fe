//! The bone-along-X twin of a BVH: every joint's frame turned so that its bone (towards its
//! first child, else its End Site) lies along its +X, as Maya and MotionBuilder export skeletons
//! with joint orients baked. The twin moves exactly as the original in the world (every joint at
//! the same place at every frame) but its zero pose is no standing pose: a test of everything that
//! must read the calibration pose, not the zero pose.
//!
//! With `C_j` the turn of joint j's frame (+X onto the bone), the twin's offsets, End Sites and
//! local rotations are
//!
//! ```text
//! o'_j = C_p⁻¹ · o_j      e'_j = C_j⁻¹ · e_j      L'_j = C_p⁻¹ ⊗ L_j ⊗ C_j
//! ```
//!
//! (`p` the parent; the root's parent frame is the world, `C_p = I`), so its world rotations are
//! `W'_j = W_j ⊗ C_j` and its joints' positions `W'_p · o'_j = W_p · o_j` are the original's.
//! Written with only the root's position channels and `Zrotation Yrotation Xrotation` for every
//! joint (nalgebra's `euler_angles`: `R = Rz(yaw) Ry(pitch) Rx(roll)`).

use imubake::bvh::Bvh;
use nalgebra::{UnitQuaternion, Vector3};
use std::fmt::Write;

/// The twin of `bvh` as BVH text (frames `frames`, all when `None`).
pub fn bone_along_x(bvh: &Bvh, frames: Option<std::ops::Range<usize>>) -> String {
    let joints = bvh.joints();
    let turn: Vec<UnitQuaternion<f64>> = (0..joints.len())
        .map(|j| {
            let bone = joints
                .iter()
                .position(|c| c.parent == Some(j))
                .map(|c| joints[c].offset)
                .or(joints[j].end_site)
                .filter(|d| d.norm() > 1e-9);
            match bone {
                None => UnitQuaternion::identity(),
                Some(d) => {
                    UnitQuaternion::rotation_between(&Vector3::x(), &d).unwrap_or_else(|| {
                        // The bone along −X: half a turn about +Z.
                        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI)
                    })
                }
            }
        })
        .collect();
    let parent_turn = |j: usize| {
        joints[j]
            .parent
            .map_or(UnitQuaternion::identity(), |p| turn[p])
    };
    let mut text = String::from("HIERARCHY\n");
    let v = |p: &Vector3<f64>| format!("{:.9} {:.9} {:.9}", p.x, p.y, p.z);
    let mut open: Vec<usize> = Vec::new();
    for (j, joint) in joints.iter().enumerate() {
        while open.last().is_some_and(|&o| Some(o) != joint.parent) {
            open.pop();
            writeln!(text, "{}}}", "  ".repeat(open.len())).unwrap();
        }
        let pad = "  ".repeat(open.len());
        let kind = if joint.parent.is_none() {
            "ROOT"
        } else {
            "JOINT"
        };
        writeln!(text, "{pad}{kind} {}\n{pad}{{", joint.name).unwrap();
        let offset = if joint.parent.is_none() {
            joint.offset
        } else {
            parent_turn(j).inverse() * joint.offset
        };
        writeln!(text, "{pad}  OFFSET {}", v(&offset)).unwrap();
        let channels = if joint.parent.is_none() {
            "6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"
        } else {
            "3 Zrotation Yrotation Xrotation"
        };
        writeln!(text, "{pad}  CHANNELS {channels}").unwrap();
        if let Some(e) = joint.end_site {
            let e = turn[j].inverse() * e;
            writeln!(
                text,
                "{pad}  End Site\n{pad}  {{\n{pad}    OFFSET {}\n{pad}  }}",
                v(&e)
            )
            .unwrap();
        }
        open.push(j);
    }
    while open.pop().is_some() {
        writeln!(text, "{}}}", "  ".repeat(open.len())).unwrap();
    }
    let range = frames.unwrap_or(0..bvh.frame_count());
    writeln!(
        text,
        "MOTION\nFrames: {}\nFrame Time: {:.9}",
        range.len(),
        bvh.frame_time_s()
    )
    .unwrap();
    for n in range {
        let local = bvh.local_rotations(n);
        let root = bvh.joint_translations(n)[0];
        let mut line = v(&root);
        for j in 0..joints.len() {
            let l = parent_turn(j).inverse() * local[j] * turn[j];
            let (roll, pitch, yaw) = l.euler_angles();
            write!(
                line,
                " {:.9} {:.9} {:.9}",
                yaw.to_degrees(),
                pitch.to_degrees(),
                roll.to_degrees()
            )
            .unwrap();
        }
        text.push_str(&line);
        text.push('\n');
    }
    text
}
