//! BVH (Biovision Hierarchy): the document ([`Bvh`]) and its reader. The writer is
//! [`crate::write::bvh`]; a BVH hierarchy becomes a rig through [`Bvh::to_rig`] (in
//! [`crate::rig`], which builds on this module).
//!
//! # Reading ([`parse`])
//!
//! The reader takes bytes and gives a [`Bvh`]: the joints in file order (depth first, so every
//! parent comes before its children), the frame time and the motion values (frames × channels,
//! `f64`). It is tolerant of layout and strict about structure:
//!
//! - tolerated: tabs or spaces, LF, CRLF or lone CR line ends, a UTF-8 byte order mark, blank
//!   lines anywhere, `Frames:` followed by a tab, `Frames 12` or `Frames:12`, numbers without a
//!   leading zero (`.0083333`), keywords in any case, `{` on the same line as `ROOT`/`JOINT`/
//!   `End Site`, text after `End Site` (ignored, as Blender does), joints with position channels
//!   anywhere in the tree, joints without a `CHANNELS` line (no channels), `Frames: 0`, several
//!   `End Site` blocks in one joint (the first is kept as [`BvhJoint::end_site`]), joint names
//!   with spaces (joined with `_`, as Blender does).
//! - refused with a [`BvhError`] naming the 1-based line and what was expected: anything before
//!   `HIERARCHY`, unbalanced braces, a joint without `OFFSET`, `OFFSET`/`CHANNELS` after a child
//!   joint, a `CHANNELS` count that differs from the channels listed, unknown or repeated
//!   channels, a second `ROOT`, a missing or malformed `MOTION`/`Frames:`/`Frame Time:` header, a
//!   frame time that is not a positive number, a motion line whose number of values is not the
//!   number of channels of the hierarchy, more or fewer frame lines than `Frames:` says, and
//!   any number that is not finite (`nan`, `inf`, overflowing exponents).
//! - bounded: no allocation is sized by a count read in the file beyond what the input's
//!   length can hold; `Frames:` above [`MAX_FRAMES`] (100,000,000) is refused outright, and every
//!   value stored was read from the text. A line longer than [`MAX_LINE_BYTES`] (1 MiB) is
//!   refused, naming it, once that much of it is read: no line is held past the limit. A frame
//!   line's values are counted as it is split and only the first channel-count of them stored,
//!   so one with too many values is refused with its line, the count expected and the count
//!   found (at least so many, for a line past the limit) without its values piling up. Nothing
//!   recurses, so deep nesting cannot overflow the stack. No input makes [`parse`] panic
//!   (property-tested on arbitrary bytes and mutations).
//!
//! [`read`] reads from any reader as it goes, [`parse`] from bytes in memory; both are the same
//! reader.
//!
//! Position channels **replace** the joint's OFFSET component by component
//! ([`Bvh::joint_translations`]). This is Blender's reading (its importer keys
//! `position − OFFSET` as the bone's location), and for the root it is the rule of
//! conventions.md (Units): the root's position channels are its world position.
//! Rotation channels are intrinsic and composed in file order: `Zrotation Xrotation Yrotation`
//! with values z, x, y degrees is Rz(z)·Rx(x)·Ry(y) ([`Bvh::local_rotations`]).
//!
mod reader;

pub use reader::{MAX_FRAMES, MAX_LINE_BYTES, parse, read};

use crate::rotation::EulerOrder;
use nalgebra::{UnitQuaternion, Vector3};
use std::fmt;

/// One BVH channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Channel {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
}

impl Channel {
    pub const ALL: [Channel; 6] = [
        Channel::Xposition,
        Channel::Yposition,
        Channel::Zposition,
        Channel::Xrotation,
        Channel::Yrotation,
        Channel::Zrotation,
    ];

    /// The name as written in files (`Xposition`, ..., `Zrotation`).
    pub fn name(self) -> &'static str {
        match self {
            Channel::Xposition => "Xposition",
            Channel::Yposition => "Yposition",
            Channel::Zposition => "Zposition",
            Channel::Xrotation => "Xrotation",
            Channel::Yrotation => "Yrotation",
            Channel::Zrotation => "Zrotation",
        }
    }

    /// Parses a channel name, ignoring ASCII case.
    pub fn from_name(name: &[u8]) -> Option<Channel> {
        Channel::ALL
            .into_iter()
            .find(|c| c.name().as_bytes().eq_ignore_ascii_case(name))
    }

    /// The axis, 0 = x, 1 = y, 2 = z.
    pub fn axis(self) -> usize {
        match self {
            Channel::Xposition | Channel::Xrotation => 0,
            Channel::Yposition | Channel::Yrotation => 1,
            Channel::Zposition | Channel::Zrotation => 2,
        }
    }

    pub fn is_position(self) -> bool {
        matches!(
            self,
            Channel::Xposition | Channel::Yposition | Channel::Zposition
        )
    }

    pub fn is_rotation(self) -> bool {
        !self.is_position()
    }

    /// The rotation channel about `axis` (0 = x, 1 = y, 2 = z).
    pub fn rotation(axis: usize) -> Option<Channel> {
        [Channel::Xrotation, Channel::Yrotation, Channel::Zrotation]
            .get(axis)
            .copied()
    }

    /// The position channel along `axis` (0 = x, 1 = y, 2 = z).
    pub fn position(axis: usize) -> Option<Channel> {
        [Channel::Xposition, Channel::Yposition, Channel::Zposition]
            .get(axis)
            .copied()
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One joint of a BVH hierarchy, as written in the file.
#[derive(Debug, Clone, PartialEq)]
pub struct BvhJoint {
    pub name: String,
    /// Index of the parent joint in [`Bvh::joints`]; `None` for the root (index 0).
    pub parent: Option<usize>,
    /// The OFFSET line, in the file's unit.
    pub offset: Vector3<f64>,
    /// The CHANNELS line in file order (at most one of each channel).
    pub channels: Vec<Channel>,
    /// The OFFSET of the joint's (first) End Site, when it has one.
    pub end_site: Option<Vector3<f64>>,
}

impl BvhJoint {
    /// The Euler order of this joint's rotation channels, named in application order like the
    /// channel list (`Zrotation Xrotation Yrotation` → ZXY).
    ///
    /// A joint with fewer than three rotation channels has the missing axes appended in the order
    /// they take in ZXY: no rotation channels → ZXY, only `Xrotation` → XZY, `Yrotation
    /// Xrotation` → YXZ. ZXY is the order most BVH files use (CMU-style ZYX aside); since the
    /// missing angles are zero, the completed order describes the same rotations.
    pub fn rotation_order(&self) -> EulerOrder {
        let mut axes: Vec<usize> = Vec::with_capacity(3);
        for c in &self.channels {
            if c.is_rotation() && !axes.contains(&c.axis()) {
                axes.push(c.axis());
            }
        }
        for a in EulerOrder::ZXY.axes() {
            if !axes.contains(&a) {
                axes.push(a);
            }
        }
        EulerOrder::ALL
            .into_iter()
            .find(|o| o.axes()[..] == axes[..])
            .unwrap_or(EulerOrder::ZXY)
    }

    pub fn has_position_channels(&self) -> bool {
        self.channels.iter().any(|c| c.is_position())
    }

    pub fn has_rotation_channels(&self) -> bool {
        self.channels.iter().any(|c| c.is_rotation())
    }
}

/// A parse error: the 1-based line and what was expected there.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: {message}")]
pub struct BvhError {
    /// 1-based line number (the last line for errors found at the end of the input).
    pub line: usize,
    /// What was expected and what was found.
    pub message: String,
}

/// A parsed BVH file.
#[derive(Debug, Clone, PartialEq)]
pub struct Bvh {
    joints: Vec<BvhJoint>,
    /// Index of each joint's first channel within a frame.
    channel_start: Vec<usize>,
    channel_count: usize,
    frame_time_s: f64,
    frame_count: usize,
    /// frame_count × channel_count values, frame by frame (empty when there are no channels).
    values: Vec<f64>,
}

impl Bvh {
    /// Joints in file order: depth first, parents before children, the root first.
    pub fn joints(&self) -> &[BvhJoint] {
        &self.joints
    }

    /// The index of the joint named `name` (exact match).
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Number of frames (the `Frames:` line, checked against the motion lines).
    pub fn frame_count(&self) -> usize {
        self.frame_count
    }

    /// Seconds per frame (the `Frame Time:` line).
    pub fn frame_time_s(&self) -> f64 {
        self.frame_time_s
    }

    /// Channels per frame over all joints.
    pub fn channel_count(&self) -> usize {
        self.channel_count
    }

    /// Index of the first channel of `joint` within a frame's values.
    ///
    /// Panics if `joint` is out of range.
    pub fn channel_start(&self, joint: usize) -> usize {
        self.channel_start[joint]
    }

    /// All motion values, frame after frame (`frame_count() × channel_count()`).
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The values of one frame, in channel order.
    ///
    /// Panics if `frame >= frame_count()`.
    pub fn frame(&self, frame: usize) -> &[f64] {
        self.check_frame(frame);
        let c = self.channel_count;
        &self.values[frame * c..(frame + 1) * c]
    }

    /// The values of `joint`'s channels at `frame`, in the order of [`BvhJoint::channels`].
    ///
    /// Panics if `frame` or `joint` is out of range.
    pub fn joint_values(&self, frame: usize, joint: usize) -> &[f64] {
        let start = self.channel_start[joint];
        &self.frame(frame)[start..start + self.joints[joint].channels.len()]
    }

    fn check_frame(&self, frame: usize) {
        assert!(
            frame < self.frame_count,
            "BVH frame {frame} out of range: the file has {} frames",
            self.frame_count
        );
    }

    /// The local rotation of every joint at `frame`: its rotation channels composed in file order
    /// (`Zrotation Xrotation Yrotation` with values z, x, y degrees → Rz(z)·Rx(x)·Ry(y)).
    /// Joints without rotation channels get the identity.
    ///
    /// Panics if `frame >= frame_count()`.
    pub fn local_rotations(&self, frame: usize) -> Vec<UnitQuaternion<f64>> {
        let values = self.frame(frame);
        self.joints
            .iter()
            .zip(&self.channel_start)
            .map(|(joint, &start)| {
                let mut q = UnitQuaternion::identity();
                for (k, c) in joint.channels.iter().enumerate() {
                    if c.is_rotation() {
                        let axis = Vector3::ith_axis(c.axis());
                        q *= UnitQuaternion::from_axis_angle(&axis, values[start + k].to_radians());
                    }
                }
                q
            })
            .collect()
    }

    /// The translation of every joint from its parent at `frame`: its OFFSET, with each component
    /// that has a position channel replaced by that channel's value. The root's position channels
    /// therefore give its position in the world, whatever its OFFSET says (Blender's reading).
    ///
    /// Panics if `frame >= frame_count()`.
    pub fn joint_translations(&self, frame: usize) -> Vec<Vector3<f64>> {
        let values = self.frame(frame);
        self.joints
            .iter()
            .zip(&self.channel_start)
            .map(|(joint, &start)| {
                let mut t = joint.offset;
                for (k, c) in joint.channels.iter().enumerate() {
                    if c.is_position() {
                        t[c.axis()] = values[start + k];
                    }
                }
                t
            })
            .collect()
    }

    /// World positions of every joint at `frame` (forward kinematics of
    /// [`local_rotations`](Bvh::local_rotations) and [`joint_translations`](Bvh::joint_translations)),
    /// in the file's unit.
    ///
    /// Panics if `frame >= frame_count()`.
    pub fn world_positions(&self, frame: usize) -> Vec<Vector3<f64>> {
        self.forward_kinematics(
            &self.local_rotations(frame),
            &self.joint_translations(frame),
        )
        .0
    }

    /// Every joint's world position and world rotation for local rotations and translations
    /// from the parent (one per joint, in [`Bvh::joints`] order; the root's translation is its
    /// position), in the file's unit.
    pub fn forward_kinematics(
        &self,
        local: &[UnitQuaternion<f64>],
        translation: &[Vector3<f64>],
    ) -> (Vec<Vector3<f64>>, Vec<UnitQuaternion<f64>>) {
        let mut world_rot: Vec<UnitQuaternion<f64>> = Vec::with_capacity(self.joints.len());
        let mut pos: Vec<Vector3<f64>> = Vec::with_capacity(self.joints.len());
        for (i, j) in self.joints.iter().enumerate() {
            match j.parent {
                Some(p) => {
                    pos.push(pos[p] + world_rot[p] * translation[i]);
                    world_rot.push(world_rot[p] * local[i]);
                }
                None => {
                    pos.push(translation[i]);
                    world_rot.push(local[i]);
                }
            }
        }
        (pos, world_rot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = "HIERARCHY
ROOT Hips
{
\tOFFSET 1 2 3
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Arm
\t{
\t\tOFFSET 0 0 1
\t\tCHANNELS 3 Xrotation Yrotation Zrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 0 0.5
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.5
10 20 30 90 0 0 0 0 0
10 20 30 0 90 0 0 90 0
";

    fn err(text: &str) -> BvhError {
        parse(text.as_bytes()).expect_err("should fail")
    }

    #[test]
    fn small_file() {
        let bvh = parse(SMALL.as_bytes()).unwrap();
        assert_eq!(bvh.joints().len(), 2);
        assert_eq!(bvh.frame_count(), 2);
        assert_eq!(bvh.frame_time_s(), 0.5);
        assert_eq!(bvh.channel_count(), 9);
        assert_eq!(bvh.joints()[1].end_site, Some(Vector3::new(0.0, 0.0, 0.5)));
        assert_eq!(bvh.joints()[0].rotation_order(), EulerOrder::ZXY);
        assert_eq!(bvh.joints()[1].rotation_order(), EulerOrder::XYZ);
        // The root's position channels replace its OFFSET.
        let t = bvh.joint_translations(0);
        assert_eq!(t[0], Vector3::new(10.0, 20.0, 30.0));
        assert_eq!(t[1], Vector3::new(0.0, 0.0, 1.0));
        // Frame 1: root Zrot 0, Xrot 90 → Rx(90) maps +z to -y; Arm Yrot 90 is local only.
        let p = bvh.world_positions(1);
        assert!(
            (p[1] - Vector3::new(10.0, 19.0, 30.0)).norm() < 1e-12,
            "{p:?}"
        );
        // Frame 0: Rz(90) leaves +z alone.
        let p = bvh.world_positions(0);
        assert!(
            (p[1] - Vector3::new(10.0, 20.0, 31.0)).norm() < 1e-12,
            "{p:?}"
        );
    }

    #[test]
    fn rotation_order_completion() {
        let j = |channels: Vec<Channel>| BvhJoint {
            name: "j".into(),
            parent: None,
            offset: Vector3::zeros(),
            channels,
            end_site: None,
        };
        assert_eq!(j(vec![]).rotation_order(), EulerOrder::ZXY);
        assert_eq!(
            j(vec![Channel::Xposition]).rotation_order(),
            EulerOrder::ZXY
        );
        assert_eq!(
            j(vec![Channel::Xrotation]).rotation_order(),
            EulerOrder::XZY
        );
        assert_eq!(
            j(vec![Channel::Yrotation, Channel::Xrotation]).rotation_order(),
            EulerOrder::YXZ
        );
    }

    #[test]
    fn errors_name_line_and_expectation() {
        let e = err("HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 3 Xrotation Yrotation\n}\n");
        assert_eq!(e.line, 5, "{e}");
        assert!(e.message.contains("3 channels"), "{e}");

        let e = err("HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n");
        assert!(e.message.contains("`}`"), "{e}");

        let e = err("HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n}\n}\nMOTION\n");
        assert_eq!(e.line, 6, "{e}");

        let e = err("HIERARCHY\nROOT a\n{\n OFFSET 0 nan 0\n}\n");
        assert_eq!(e.line, 4, "{e}");
        assert!(e.message.contains("finite"), "{e}");

        let good_head =
            "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 2 Xrotation Yrotation\n}\nMOTION\n";
        let e = err(&format!(
            "{good_head}Frames: 2\nFrame Time: 0.1\n1 2\n1 2 3\n"
        ));
        assert_eq!(e.line, 11, "{e}");
        assert!(e.message.contains("expected 2 values"), "{e}");

        let e = err(&format!(
            "{good_head}Frames: 3\nFrame Time: 0.1\n1 2\n1 2\n"
        ));
        assert!(e.message.contains("expected 3 frames"), "{e}");

        let e = err(&format!(
            "{good_head}Frames: 1\nFrame Time: 0.1\n1 2\n1 2\n"
        ));
        assert_eq!(e.line, 11, "{e}");

        let e = err(&format!("{good_head}Frames: 1\nFrame Time: 0.1\n1 inf\n"));
        assert_eq!(e.line, 10, "{e}");

        let e = err(&format!("{good_head}Frames: 1\nFrame Time: 0\n1 2\n"));
        assert_eq!(e.line, 9, "{e}");

        let e = err(&format!(
            "{good_head}Frames: 1000000000000\nFrame Time: 0.1\n1 2\n"
        ));
        assert_eq!(e.line, 8, "{e}");

        let e = err("HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n}\nROOT b\n");
        assert!(e.message.contains("ROOT"), "{e}");

        let e = err("hello\n");
        assert_eq!(e.line, 1);
        let e = err("");
        assert_eq!(e.line, 1);
    }

    #[test]
    fn tolerant_layout() {
        let text = "\u{feff}hierarchy\r\nROOT  My Hips {\r\n\tOFFSET\t0 0 0\r\n\tCHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation\r\n\
            JOINT b\r{\rOFFSET 1 0 0\rCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\r\
            End Site name\r{\rOFFSET 1 0 0\r}\rEnd Site\r{\rOFFSET 2 0 0\r}\r}\r}\n\n\
            MOTION\nFrames:\t1\nFrame Time:\t.0083333\n\n1 2 3 4 5 6 7 8 9 10 11 12\n\n";
        let bvh = parse(text.as_bytes()).unwrap();
        assert_eq!(bvh.joints()[0].name, "My_Hips");
        assert_eq!(bvh.joints()[1].end_site, Some(Vector3::new(1.0, 0.0, 0.0)));
        assert_eq!(bvh.frame_time_s(), 0.0083333);
        assert_eq!(bvh.joint_translations(0)[1], Vector3::new(7.0, 8.0, 9.0));
        let zero = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n}\nMOTION\nFrames: 0\nFrame Time: 0.04\n";
        let bvh = parse(zero.as_bytes()).unwrap();
        assert_eq!(bvh.frame_count(), 0);
        assert!(bvh.values().is_empty());
    }

    /// A reader that hands out one byte per read, so every line end (a `\r\n` too) and the
    /// byte order mark fall across reads.
    struct ByteByByte<'a>(&'a [u8]);

    impl std::io::Read for ByteByByte<'_> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            match (self.0.split_first(), buf.first_mut()) {
                (Some((&b, rest)), Some(slot)) => {
                    *slot = b;
                    self.0 = rest;
                    Ok(1)
                }
                _ => Ok(0),
            }
        }
    }

    /// [`read`] from a reader gives what [`parse`] gives from the bytes, the lines split across
    /// reads anywhere: the documents, and the errors with their lines.
    #[test]
    fn reading_as_it_goes_is_parsing_the_bytes() {
        let tolerant = "\u{feff}hierarchy\r\nROOT a {\r\n\tOFFSET\t0 0 0\r\n\tCHANNELS 3 Zrotation Xrotation Yrotation\r\
            JOINT b\r{\rOFFSET 1 0 0\r}\r}\r\n\r\nMOTION\nFrames:\t2\nFrame Time:\t.5\n\n1 2 3\r\n4 5 6\r";
        let texts = [
            SMALL.to_string(),
            tolerant.to_string(),
            SMALL.replace("10 20 30 0 90 0 0 90 0", "10 20 30 0 90 0 0 90 0 1"),
            SMALL.replace("Frames: 2", "Frames: 3"),
            SMALL.replace("\t\tOFFSET 0 0 1", "\t\tOFFSET 0 x 1"),
            "HIERARCHY\r".to_string(),
            String::new(),
        ];
        for text in &texts {
            let whole = parse(text.as_bytes());
            let streamed = read(ByteByByte(text.as_bytes()));
            assert_eq!(streamed, whole, "{text:?}");
        }
        let bvh = read(ByteByByte(tolerant.as_bytes())).unwrap();
        assert_eq!(bvh.frame_count(), 2);
        assert_eq!(bvh.values(), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    /// A frame line with more values than channels: the count found when the line is within the
    /// limit; a line of exactly [`MAX_LINE_BYTES`] bytes is read, one byte more is refused.
    #[test]
    fn frame_lines_are_counted_and_held_to_the_limit() {
        let head = SMALL.split("10 20 30 90").next().unwrap();
        // 9 channels; the frame lines are lines 19 and 20.
        let e = err(&format!("{head}1 2 3 4 5 6 7 8 9 10\n1 2 3 4 5 6 7 8 9\n"));
        assert_eq!(e.line, 19, "{e}");
        assert!(
            e.message.ends_with(
                "expected 9 values (one per channel of the hierarchy) on frame 0, found 10"
            ),
            "{e}"
        );
        // A valid frame line padded with spaces to exactly the limit, and one byte more.
        let row = "1 2 3 4 5 6 7 8 9";
        let at_limit = format!("{row}{}", " ".repeat(MAX_LINE_BYTES - row.len()));
        let bvh = parse(format!("{head}{row}\n{at_limit}\n").as_bytes()).unwrap();
        assert_eq!(bvh.frame_count(), 2);
        let e = err(&format!("{head}{row}\n{at_limit} \n"));
        assert_eq!(e.line, 20, "{e}");
        assert!(
            e.message
                .contains(&format!("longer than {MAX_LINE_BYTES} bytes")),
            "{e}"
        );
        // Past the limit with more values than channels: how many were seen, at least.
        // `0 ` is two bytes, so the first MAX_LINE_BYTES + 1 bytes hold MAX_LINE_BYTES / 2 + 1
        // values (the last one's digit is the byte past the limit).
        let many = "0 ".repeat(MAX_LINE_BYTES);
        let e = err(&format!("{head}{many}\n"));
        assert_eq!(e.line, 19, "{e}");
        assert!(
            e.message.contains(&format!(
                "expected 9 values (one per channel of the hierarchy) on frame 0, found at least {} in its first {} bytes",
                MAX_LINE_BYTES / 2 + 1,
                MAX_LINE_BYTES + 1
            )),
            "{e}"
        );
        // A hierarchy line past the limit: refused by number.
        let name = "x".repeat(MAX_LINE_BYTES);
        let e = err(&format!("HIERARCHY\nROOT {name}\n"));
        assert_eq!(e.line, 2, "{e}");
        assert!(
            e.message
                .contains(&format!("longer than {MAX_LINE_BYTES} bytes")),
            "{e}"
        );
    }
}
