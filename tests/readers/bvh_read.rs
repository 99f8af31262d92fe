//! The BVH reader on the real files of ../shared/data/bvh and on hand-written fixtures. Expected
//! values come from the file text itself (a plain whitespace split of chosen lines, in the test)
//! or from the numbers written in the fixtures, and rotations from explicit matrices.

use crate::common;

use imubake::bvh::{self, Bvh, Channel};
use imubake::rig::LengthUnit;
use imubake::rotation::EulerOrder;
use imubake::write::{
    self,
    bvh::{Angles, BvhMotion},
};
use nalgebra::{Matrix3, Vector3};

/// The lines of a file as text, line ends removed (LF or CRLF).
fn text_lines(bytes: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(bytes)
        .split('\n')
        .map(|l| l.trim_end_matches('\r').to_string())
        .collect()
}

/// The numbers on a line, by whitespace split.
fn numbers(line: &str) -> Vec<f64> {
    line.split_whitespace()
        .map(|t| t.parse::<f64>().unwrap())
        .collect()
}

/// The index of the first line whose trimmed text is `text`.
fn find_line(lines: &[String], text: &str) -> usize {
    lines
        .iter()
        .position(|l| l.trim() == text)
        .unwrap_or_else(|| panic!("no line `{text}`"))
}

/// The OFFSET written right after `header` (e.g. `JOINT LeftLeg`).
fn offset_after(lines: &[String], header: &str) -> Vector3<f64> {
    let start = find_line(lines, header);
    let line = lines[start..]
        .iter()
        .find(|l| l.trim_start().starts_with("OFFSET"))
        .unwrap();
    let v = numbers(line.trim_start().trim_start_matches("OFFSET"));
    Vector3::new(v[0], v[1], v[2])
}

fn rx(deg: f64) -> Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}
fn ry(deg: f64) -> Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}
fn rz(deg: f64) -> Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}
fn r_axis(axis: usize, deg: f64) -> Matrix3<f64> {
    [rx, ry, rz][axis](deg)
}

struct Expect {
    file: &'static str,
    joints: usize,
    end_sites: usize,
    frames: usize,
    frame_time: f64,
    channels: usize,
    root: &'static str,
    order: EulerOrder,
    /// A joint whose OFFSET is checked against the text.
    joint: &'static str,
}

const FILES: [Expect; 5] = [
    Expect {
        file: "bvh/cmu_01_01.bvh",
        joints: 31,
        end_sites: 7,
        frames: 2752,
        frame_time: 0.0083333,
        channels: 6 + 30 * 3,
        root: "Hips",
        order: EulerOrder::ZYX,
        joint: "LeftLeg",
    },
    Expect {
        file: "bvh/pymo_walk.bvh",
        joints: 23,
        end_sites: 7,
        frames: 1064,
        frame_time: 0.008333,
        channels: 6 + 22 * 3,
        root: "Hips",
        order: EulerOrder::XYZ,
        joint: "LeftForeArm",
    },
    Expect {
        file: "bvh/mixamo_rig_freebvh.bvh",
        joints: 55,
        end_sites: 15,
        frames: 69,
        frame_time: 0.0333333,
        channels: 6 + 54 * 3,
        root: "mixamorig:Hips",
        order: EulerOrder::ZYX,
        joint: "mixamorig:Spine1",
    },
    Expect {
        file: "bvh/mocapbank_crlf.bvh",
        joints: 19,
        end_sites: 5,
        frames: 455,
        frame_time: 0.033333,
        channels: 6 + 18 * 3,
        root: "Hips",
        order: EulerOrder::ZXY,
        joint: "LeftElbow",
    },
    Expect {
        file: "bvh/pfnn_hierarchy.bvh",
        joints: 31,
        end_sites: 7,
        frames: 60,
        frame_time: 0.0333333,
        channels: 6 + 30 * 3,
        root: "Hips",
        order: EulerOrder::ZYX,
        joint: "LeftUpLeg",
    },
];

#[test]
fn real_files_match_their_text() {
    for e in &FILES {
        let Some(path) = common::shared(e.file) else {
            return;
        };
        let bytes = std::fs::read(&path).unwrap();
        let bvh = bvh::parse(&bytes).unwrap_or_else(|err| panic!("{}: {err}", e.file));
        let lines = text_lines(&bytes);

        assert_eq!(bvh.joints().len(), e.joints, "{}", e.file);
        assert_eq!(
            bvh.joints().iter().filter(|j| j.end_site.is_some()).count(),
            e.end_sites,
            "{}",
            e.file
        );
        // Cross-check the counts against the text too.
        let text_joints = lines
            .iter()
            .filter(|l| {
                let t = l.trim_start();
                t.starts_with("JOINT") || t.starts_with("ROOT")
            })
            .count();
        assert_eq!(text_joints, e.joints, "{}", e.file);
        assert_eq!(bvh.frame_count(), e.frames, "{}", e.file);
        assert_eq!(bvh.frame_time_s(), e.frame_time, "{}", e.file);
        assert_eq!(bvh.channel_count(), e.channels, "{}", e.file);
        assert_eq!(bvh.values().len(), e.frames * e.channels);
        assert_eq!(bvh.joints()[0].name, e.root);
        assert_eq!(bvh.joints()[0].parent, None);
        assert_eq!(bvh.joints()[0].channels.len(), 6);
        for (i, j) in bvh.joints().iter().enumerate() {
            assert!(j.parent.is_none_or(|p| p < i), "{}: parents first", e.file);
            assert_eq!(j.rotation_order(), e.order, "{} {}", e.file, j.name);
        }

        // Root OFFSET and one joint's OFFSET, read from the text.
        assert_eq!(
            bvh.joints()[0].offset,
            offset_after(&lines, &format!("ROOT {}", e.root))
        );
        let j = bvh.joint_index(e.joint).unwrap();
        assert_eq!(
            bvh.joints()[j].offset,
            offset_after(&lines, &format!("JOINT {}", e.joint))
        );

        // Motion lines: the first, the last and one in between, split by hand.
        let motion = find_line(&lines, "MOTION");
        assert!(lines[motion + 1].starts_with("Frames:"));
        assert!(lines[motion + 2].starts_with("Frame Time:"));
        for f in [0, e.frames / 2, e.frames - 1] {
            let expected = numbers(&lines[motion + 3 + f]);
            assert_eq!(expected.len(), e.channels);
            assert_eq!(bvh.frame(f), &expected[..], "{} frame {f}", e.file);
            // The root's position channels replace its OFFSET.
            let t = bvh.joint_translations(f);
            assert_eq!(t[0], Vector3::new(expected[0], expected[1], expected[2]));
            assert_eq!(t[j], bvh.joints()[j].offset);
            // Local rotations: the channels in file order as explicit matrices.
            let q = bvh.local_rotations(f);
            for (k, joint) in bvh.joints().iter().enumerate() {
                let start = bvh.channel_start(k);
                let mut m = Matrix3::identity();
                for (c, channel) in joint.channels.iter().enumerate() {
                    if channel.is_rotation() {
                        m *= r_axis(channel.axis(), expected[start + c]);
                    }
                }
                let got = q[k].to_rotation_matrix().into_inner();
                assert!(
                    (got - m).abs().max() < 1e-12,
                    "{} frame {f} joint {}",
                    e.file,
                    joint.name
                );
            }
        }

        let rig = bvh.to_rig(e.file, LengthUnit::Centimetres).unwrap();
        assert_eq!(rig.len(), e.joints);
        assert_eq!(rig.joints()[j].order, e.order);
        assert_eq!(rig.joints()[j].offset, bvh.joints()[j].offset);
        assert_eq!(rig.units(), LengthUnit::Centimetres);
    }
}

#[test]
fn cmu_root_rotation_by_hand() {
    let Some(path) = common::shared("bvh/cmu_01_01.bvh") else {
        return;
    };
    let bvh = bvh::parse(&std::fs::read(path).unwrap()).unwrap();
    // Line 188 (frame 0) starts `9.3722 17.8693 -17.3198 0 0 0`, lines 4-5 of the file:
    // `OFFSET 0.00000 0.00000 0.00000`, `CHANNELS 6 Xposition Yposition Zposition Zrotation
    // Yrotation Xrotation`.
    assert_eq!(
        &bvh.frame(0)[..6],
        &[9.3722, 17.8693, -17.3198, 0.0, 0.0, 0.0]
    );
    assert_eq!(
        bvh.joints()[0].channels,
        vec![
            Channel::Xposition,
            Channel::Yposition,
            Channel::Zposition,
            Channel::Zrotation,
            Channel::Yrotation,
            Channel::Xrotation
        ]
    );
    // `JOINT LeftUpLeg` `OFFSET 1.36306 -1.79463 0.83929` under LHipJoint (offset 0) under Hips.
    let up = bvh.joint_index("LeftUpLeg").unwrap();
    assert_eq!(
        bvh.joints()[up].offset,
        Vector3::new(1.36306, -1.79463, 0.83929)
    );
    assert_eq!(
        bvh.joints()[bvh.joints()[up].parent.unwrap()].name,
        "LHipJoint"
    );
    // `End Site` of LeftToeBase: `OFFSET 0.00000 -0.00000 1.18966`.
    let toe = bvh.joint_index("LeftToeBase").unwrap();
    assert_eq!(
        bvh.joints()[toe].end_site,
        Some(Vector3::new(0.0, 0.0, 1.18966))
    );
}

#[test]
fn tolerant_fixture_by_hand() {
    let bvh: Bvh =
        bvh::parse(&std::fs::read(common::fixture("bvh/tolerant.bvh")).unwrap()).unwrap();
    let names: Vec<&str> = bvh.joints().iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["Pelvis", "Spine", "Prop", "Left_Leg"]);
    assert_eq!(bvh.joints()[2].parent, Some(1));
    assert_eq!(bvh.joints()[3].parent, Some(0));
    assert_eq!(bvh.frame_count(), 2);
    assert_eq!(bvh.frame_time_s(), 0.0083333);
    assert_eq!(bvh.channel_count(), 18);
    // Two End Sites in Prop: the first is kept. Spine has one after its child joint.
    assert_eq!(bvh.joints()[2].end_site, Some(Vector3::new(2.0, 0.0, 0.0)));
    assert_eq!(bvh.joints()[1].end_site, Some(Vector3::new(0.0, 4.0, 0.0)));
    assert_eq!(bvh.joints()[3].rotation_order(), EulerOrder::YXZ);
    assert_eq!(bvh.joints()[2].rotation_order(), EulerOrder::XYZ);

    // Frame 1: every rotation is zero except Prop (Yrotation 90) and Left_Leg (Y -30, X 10), so
    // positions add up by hand: Pelvis (-1.5, 89, 2); Spine + (0, 10, -1.5); Prop's position
    // channels (5, 0, 0) replace its offset; Left_Leg + (8, -5, 0).
    let p = bvh.world_positions(1);
    let expected = [
        Vector3::new(-1.5, 89.0, 2.0),
        Vector3::new(-1.5, 99.0, 0.5),
        Vector3::new(3.5, 99.0, 0.5),
        Vector3::new(6.5, 84.0, 2.0),
    ];
    for (got, want) in p.iter().zip(&expected) {
        assert!((got - want).norm() < 1e-12, "{got} vs {want}");
    }

    // Frame 0: Pelvis Rz(10)·Rx(20)·Ry(30); Spine Rz(-5)·Rx(0)·Ry(5); Prop translated by its
    // position channels (6, 1, 0).
    let r0 = rz(10.0) * rx(20.0) * ry(30.0);
    let r1 = rz(-5.0) * rx(0.0) * ry(5.0);
    let pelvis = Vector3::new(1.5, 91.0, -2.0);
    let spine = pelvis + r0 * Vector3::new(0.0, 10.0, -1.5);
    let prop = spine + r0 * r1 * Vector3::new(6.0, 1.0, 0.0);
    let leg = pelvis + r0 * Vector3::new(8.0, -5.0, 0.0);
    let p = bvh.world_positions(0);
    for (got, want) in p.iter().zip(&[pelvis, spine, prop, leg]) {
        assert!((got - want).norm() < 1e-12, "{got} vs {want}");
    }
    let q = bvh.local_rotations(0);
    let leg_m = ry(0.0) * rx(0.0) * rz(45.0);
    assert!((q[3].to_rotation_matrix().into_inner() - leg_m).abs().max() < 1e-12);
}

#[test]
fn zero_frames_fixture() {
    let bvh = bvh::parse(&std::fs::read(common::fixture("bvh/zero_frames.bvh")).unwrap()).unwrap();
    assert_eq!(bvh.frame_count(), 0);
    assert_eq!(bvh.frame_time_s(), 0.04);
    assert_eq!(bvh.joints().len(), 1);
    assert_eq!(bvh.joints()[0].end_site, Some(Vector3::new(0.0, 0.2, 0.0)));
    let rig = bvh.to_rig("z", LengthUnit::Metres).unwrap();
    assert_eq!(rig.joints()[0].order, EulerOrder::ZXY);
}

/// Cuts the tolerant fixture in structural ways; each must fail on the right line with a message
/// saying what was expected.
#[test]
fn structural_errors() {
    let good =
        String::from_utf8(std::fs::read(common::fixture("bvh/tolerant.bvh")).unwrap()).unwrap();
    let lines: Vec<&str> = good.lines().collect();
    let with = |line: usize, replacement: Option<&str>| -> String {
        let mut out: Vec<&str> = lines.clone();
        match replacement {
            Some(r) => out[line - 1] = r,
            None => {
                out.remove(line - 1);
            }
        }
        out.join("\n") + "\n"
    };
    let cases: [(String, usize, &str); 9] = [
        // Line 7 is Spine's `{`.
        (with(7, None), 7, "expected `{`"),
        // A missing `}` of Prop (line 22): every later `}` closes one level too low, so MOTION
        // comes while the root is still open.
        (
            with(22, None),
            37,
            "expected `}` closing joint `Pelvis` (opened at line 3)",
        ),
        // An extra `}` after the root.
        (
            good.replace("}\nMOTION", "}\n}\nMOTION"),
            38,
            "unbalanced `}`",
        ),
        (
            with(9, Some("\t\tCHANNELS 3 Zrotation Xrotation")),
            9,
            "expected 3 channels",
        ),
        (
            with(9, Some("\t\tCHANNELS 3 Zrotation Xrotation Wrotation")),
            9,
            "channel name",
        ),
        (
            with(8, Some("\t\tOFFSET 0.0 1e999 -1.5")),
            8,
            "finite number",
        ),
        (
            with(41, Some("1.5 91 -2 10 20 30 -5 0 5 90 0 0 6 1 0 0 0")),
            41,
            "expected 18 values",
        ),
        (
            with(43, Some("-1.5 89 2 0 0 0 0 0 0 0 90 0 5 0 NaN -30 10 0")),
            43,
            "finite number",
        ),
        (
            with(40, Some("Frame Time: -0.1")),
            40,
            "positive frame time",
        ),
    ];
    for (text, line, expected) in cases {
        let err = bvh::parse(text.as_bytes()).expect_err(expected);
        eprintln!("{err}");
        assert_eq!(err.line, line, "{err}");
        assert!(
            err.message.contains(expected),
            "`{err}` should say `{expected}`"
        );
    }
    // More frames than announced, fewer, and an absurd count.
    let err = bvh::parse(good.replace("Frames:\t2", "Frames:\t1").as_bytes()).unwrap_err();
    assert_eq!(err.line, 43, "{err}");
    let err = bvh::parse(good.replace("Frames:\t2", "Frames:\t3").as_bytes()).unwrap_err();
    assert!(err.message.contains("expected 3 frames"), "{err}");
    let err = bvh::parse(
        good.replace("Frames:\t2", "Frames: 1000000000000")
            .as_bytes(),
    )
    .unwrap_err();
    assert_eq!(err.line, 39, "{err}");
}

/// `Frames: 100000000` (the limit) with one motion line neither allocates for the claim nor
/// panics: it fails for missing frames.
#[test]
fn huge_frame_claim_does_not_allocate() {
    let text = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n}\nMOTION\nFrames: 100000000\nFrame Time: 0.01\n1 2 3\n";
    let err = bvh::parse(text.as_bytes()).unwrap_err();
    assert!(err.message.contains("expected 100000000 frames"), "{err}");
    // Without channels nothing can be checked, so the claim stands but nothing is stored.
    let text =
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n}\nMOTION\nFrames: 100000000\nFrame Time: 0.01\n";
    let bvh = bvh::parse(text.as_bytes()).unwrap();
    assert_eq!(bvh.frame_count(), 100_000_000);
    assert!(bvh.values().is_empty());
    assert!(bvh.frame(99_999_999).is_empty());
}

/// 3,000 nested joints (the written file indents each level, so it grows quadratically): neither
/// the reader nor the writer recurses, so nothing overflows.
#[test]
fn deep_nesting() {
    let depth = 3_000;
    let mut text = String::from("HIERARCHY\n");
    for i in 0..depth {
        text.push_str(if i == 0 { "ROOT j0\n{\n" } else { "" });
        if i > 0 {
            text.push_str(&format!("JOINT j{i}\n{{\n"));
        }
        text.push_str("OFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n");
    }
    text.push_str("End Site\n{\nOFFSET 0 1 0\n}\n");
    text.push_str(&"}\n".repeat(depth));
    text.push_str("MOTION\nFrames: 1\nFrame Time: 0.1\n");
    text.push_str(&"0 0 0 ".repeat(depth));
    text.push('\n');
    let bvh = bvh::parse(text.as_bytes()).unwrap();
    assert_eq!(bvh.joints().len(), depth);
    assert_eq!(bvh.joints()[depth - 1].parent, Some(depth - 2));
    let p = bvh.world_positions(0);
    assert_eq!(p[depth - 1], Vector3::new(0.0, depth as f64, 0.0));

    let rig = bvh.to_rig("deep", LengthUnit::Metres).unwrap();
    let roots = vec![Vector3::new(0.0, 1.0, 0.0)];
    let angles = vec![vec![[0.0; 3]]; depth];
    let mut out = Vec::new();
    write::bvh::write_bvh(
        &mut out,
        &BvhMotion {
            rig: &rig,
            fps: imubake::fps::Fps::new(10, 1).unwrap(),
            root_positions: &roots,
            euler_deg: Angles::Degrees(&angles),
            translations: &[],
        },
    )
    .unwrap();
    assert_eq!(bvh::parse(&out).unwrap().joints().len(), depth);

    // Unclosed: the error names the innermost open joint.
    let cut = text.split("}\n}\n}\nMOTION").next().unwrap();
    let err = bvh::parse(cut.as_bytes()).unwrap_err();
    assert!(err.message.contains("expected `}` closing joint"), "{err}");
}
