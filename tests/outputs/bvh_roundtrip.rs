//! Writer round trips: real files → rig + angles → write_bvh → parse gives the same hierarchy,
//! offsets and values; re-expressing the rotations in other Euler orders keeps the rotations;
//! output layout and input validation.

use crate::common;

use imubake::bvh::{self, Bvh, Channel};
use imubake::fps::Fps;
use imubake::rig::{Joint, LengthUnit, Rig};
use imubake::rotation::EulerOrder;
use imubake::write::{
    self,
    bvh::{Angles, BvhMotion},
};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

const FILES: [&str; 5] = [
    "bvh/cmu_01_01.bvh",
    "bvh/pymo_walk.bvh",
    "bvh/mixamo_rig_freebvh.bvh",
    "bvh/mocapbank_crlf.bvh",
    "bvh/pfnn_hierarchy.bvh",
];

fn read(rel: &str) -> Option<Bvh> {
    let path = common::shared(rel)?;
    Some(bvh::parse(&std::fs::read(path).unwrap()).unwrap())
}

/// Root positions and per-joint angles taken straight from the channel values: each joint of
/// these files has exactly three rotation channels, so the angles in channel order are the
/// angles in the rig's order (`to_rig` takes the order from the channels).
fn motion_of(bvh: &Bvh) -> (Vec<Vector3<f64>>, Vec<Vec<[f64; 3]>>) {
    let frames = bvh.frame_count();
    let roots = (0..frames).map(|f| bvh.joint_translations(f)[0]).collect();
    let angles = (0..bvh.joints().len())
        .map(|j| {
            (0..frames)
                .map(|f| {
                    let values = bvh.joint_values(f, j);
                    let rot: Vec<f64> = bvh.joints()[j]
                        .channels
                        .iter()
                        .zip(values)
                        .filter(|(c, _)| c.is_rotation())
                        .map(|(_, v)| *v)
                        .collect();
                    [rot[0], rot[1], rot[2]]
                })
                .collect()
        })
        .collect();
    (roots, angles)
}

fn write(motion: &BvhMotion) -> Vec<u8> {
    let mut out = Vec::new();
    write::bvh::write_bvh(&mut out, motion).unwrap();
    out
}

fn assert_close(a: &[f64], b: &[f64], tol: f64, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - y).abs() <= tol, "{what}: value {i}: {x} vs {y}");
    }
}

#[test]
fn real_files_round_trip() {
    for rel in FILES {
        let Some(original) = read(rel) else {
            return;
        };
        let rig = original.to_rig(rel, LengthUnit::Centimetres).unwrap();
        let (roots, angles) = motion_of(&original);
        let fps = Fps::new(120, 1).unwrap();
        let bytes = write(&BvhMotion {
            rig: &rig,
            fps,
            root_positions: &roots,
            euler_deg: Angles::Degrees(&angles),
            translations: &[],
        });
        let back = bvh::parse(&bytes).unwrap_or_else(|e| panic!("{rel}: {e}"));

        assert_eq!(back.joints().len(), original.joints().len(), "{rel}");
        for (a, b) in original.joints().iter().zip(back.joints()) {
            assert_eq!(a.name, b.name, "{rel}");
            assert_eq!(a.parent, b.parent, "{rel} {}", a.name);
            assert_eq!(a.channels, b.channels, "{rel} {}", a.name);
            assert_close(a.offset.as_slice(), b.offset.as_slice(), 1e-6, &a.name);
            match (a.end_site, b.end_site) {
                (Some(x), Some(y)) => assert_close(x.as_slice(), y.as_slice(), 1e-6, &a.name),
                (None, None) => {}
                other => panic!("{rel} {}: end site {other:?}", a.name),
            }
        }
        assert_eq!(back.frame_count(), original.frame_count(), "{rel}");
        assert_eq!(back.frame_time_s(), 1.0 / 120.0);
        assert_close(back.values(), original.values(), 1e-6, rel);

        // Writing is deterministic.
        let again = write(&BvhMotion {
            rig: &rig,
            fps,
            root_positions: &roots,
            euler_deg: Angles::Degrees(&angles),
            translations: &[],
        });
        assert_eq!(bytes, again, "{rel}");
    }
}

/// Euler angles (degrees) of `q` in `order`, listed in application order, by nalgebra's
/// general extraction (Shuster & Markley), independent of the writer.
fn euler_of(q: &UnitQuaternion<f64>, order: EulerOrder) -> [f64; 3] {
    let axes = order.axes().map(Vector3::<f64>::ith_axis);
    let r: Rotation3<f64> = q.to_rotation_matrix();
    let (angles, _) = r.euler_angles_ordered(axes, false);
    angles.map(f64::to_degrees)
}

/// The CMU file's rotations (ZYX channels) rewritten with every joint in another order: the
/// re-read local rotations and world positions equal the original ones.
#[test]
fn other_euler_orders_keep_the_rotations() {
    let Some(original) = read("bvh/cmu_01_01.bvh") else {
        return;
    };
    let base = original.to_rig("cmu", LengthUnit::Centimetres).unwrap();
    let joints: Vec<Joint> = base
        .joints()
        .iter()
        .enumerate()
        .map(|(i, j)| Joint {
            order: EulerOrder::ALL[i % 6],
            ..j.clone()
        })
        .collect();
    let rig = Rig::new("cmu", LengthUnit::Centimetres, joints).unwrap();
    let frames: Vec<usize> = (0..original.frame_count()).step_by(97).collect();
    let roots: Vec<Vector3<f64>> = frames
        .iter()
        .map(|&f| original.joint_translations(f)[0])
        .collect();
    let locals: Vec<Vec<UnitQuaternion<f64>>> = frames
        .iter()
        .map(|&f| original.local_rotations(f))
        .collect();
    let angles: Vec<Vec<[f64; 3]>> = (0..rig.len())
        .map(|j| {
            locals
                .iter()
                .map(|l| euler_of(&l[j], rig.joints()[j].order))
                .collect()
        })
        .collect();
    let fps = Fps::new(30000, 1001).unwrap();
    let bytes = write(&BvhMotion {
        rig: &rig,
        fps,
        root_positions: &roots,
        euler_deg: Angles::Degrees(&angles),
        translations: &[],
    });
    let back = bvh::parse(&bytes).unwrap();
    assert_eq!(back.frame_count(), frames.len());
    for (k, &f) in frames.iter().enumerate() {
        for (j, joint) in back.joints().iter().enumerate() {
            let rot: Vec<Channel> = joint
                .channels
                .iter()
                .copied()
                .filter(|c| c.is_rotation())
                .collect();
            let expected: Vec<Channel> = rig.joints()[j]
                .order
                .axes()
                .iter()
                .map(|&a| Channel::rotation(a).unwrap())
                .collect();
            assert_eq!(rot, expected);
            let a = back.local_rotations(k)[j];
            let b = locals[k][j];
            // 6 decimals of a degree: about 1e-8 rad.
            assert!(
                a.angle_to(&b) < 1e-6,
                "frame {f} joint {}: {}",
                joint.name,
                a.angle_to(&b)
            );
        }
        let p_back = back.world_positions(k);
        let p_orig = original.world_positions(f);
        for (a, b) in p_back.iter().zip(&p_orig) {
            assert!((a - b).norm() < 1e-4, "frame {f}: {a} vs {b}");
        }
    }
}

fn small_rig(units: LengthUnit) -> Rig {
    let j =
        |name: &str, parent: Option<usize>, offset: [f64; 3], order, end_site: Option<[f64; 3]>| {
            Joint {
                name: name.into(),
                parent,
                offset: Vector3::from(offset),
                order,
                end_site: end_site.map(Vector3::from),
            }
        };
    Rig::new(
        "small",
        units,
        vec![
            j("Hips", None, [0.0, 1.0, 0.0], EulerOrder::ZXY, None),
            j("Spine", Some(0), [0.0, 0.3, 0.0], EulerOrder::XYZ, None),
            // A leaf without an end site, and one with.
            j("Head", Some(1), [0.0, 0.25, 0.02], EulerOrder::ZYX, None),
            j(
                "Hand",
                Some(1),
                [0.4, 0.0, 0.0],
                EulerOrder::YZX,
                Some([0.1, 0.0, 0.0]),
            ),
            // A zero-offset leaf: its End Site follows the parent's direction.
            j("Tip", Some(3), [0.0, 0.0, 0.0], EulerOrder::ZXY, None),
        ],
    )
    .unwrap()
}

#[test]
fn layout_end_sites_and_units() {
    let rig = small_rig(LengthUnit::Metres);
    let roots = vec![Vector3::new(0.0, 1.0, 0.0), Vector3::new(0.5, 1.25, -0.125)];
    let angles: Vec<Vec<[f64; 3]>> = (0..rig.len())
        .map(|j| vec![[0.0, 0.0, 0.0], [10.0 * j as f64, -0.0000001, 1.0 / 3.0]])
        .collect();
    let motion = BvhMotion {
        rig: &rig,
        fps: Fps::new(30000, 1001).unwrap(),
        root_positions: &roots,
        euler_deg: Angles::Degrees(&angles),
        translations: &[],
    };
    let text = String::from_utf8(write(&motion)).unwrap();
    let expected = "HIERARCHY
ROOT Hips
{
\tOFFSET 0.000000 1.000000 0.000000
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Spine
\t{
\t\tOFFSET 0.000000 0.300000 0.000000
\t\tCHANNELS 3 Xrotation Yrotation Zrotation
\t\tJOINT Head
\t\t{
\t\t\tOFFSET 0.000000 0.250000 0.020000
\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0.000000 0.125000 0.010000
\t\t\t}
\t\t}
\t\tJOINT Hand
\t\t{
\t\t\tOFFSET 0.400000 0.000000 0.000000
\t\t\tCHANNELS 3 Yrotation Zrotation Xrotation
\t\t\tJOINT Tip
\t\t\t{
\t\t\t\tOFFSET 0.000000 0.000000 0.000000
\t\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\t\tEnd Site
\t\t\t\t{
\t\t\t\t\tOFFSET 0.200000 0.000000 0.000000
\t\t\t\t}
\t\t\t}
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0.100000 0.000000 0.000000
\t\t\t}
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.03336666666666667
0.000000 1.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000
0.500000 1.250000 -0.125000 0.000000 0.000000 0.333333 10.000000 0.000000 0.333333 20.000000 0.000000 0.333333 30.000000 0.000000 0.333333 40.000000 0.000000 0.333333
";
    assert_eq!(text, expected);
    assert!(!text.contains('\r'));

    // Centimetres: lengths × 100, angles unchanged.
    let mut out = Vec::new();
    write::bvh::write_bvh_in(&mut out, &motion, LengthUnit::Centimetres).unwrap();
    let cm = bvh::parse(&out).unwrap();
    let m = bvh::parse(text.as_bytes()).unwrap();
    for (a, b) in m.joints().iter().zip(cm.joints()) {
        assert!((a.offset * 100.0 - b.offset).norm() < 1e-9);
        if let (Some(x), Some(y)) = (a.end_site, b.end_site) {
            assert!((x * 100.0 - y).norm() < 1e-9);
        }
    }
    assert_eq!(&cm.frame(1)[..3], &[50.0, 125.0, -12.5]);
    assert_eq!(&cm.frame(1)[3..], &m.frame(1)[3..]);
    assert_eq!(
        write::bvh::unit_scale(LengthUnit::Centimetres, LengthUnit::Metres),
        0.01
    );
}

#[test]
fn frame_time_digits() {
    let rig = small_rig(LengthUnit::Metres);
    for (num, den, text) in [
        (24, 1, "Frame Time: 0.041666666666666664\n"),
        (30000, 1001, "Frame Time: 0.03336666666666667\n"),
        (60, 1, "Frame Time: 0.016666666666666666\n"),
        (120, 1, "Frame Time: 0.008333333333333333\n"),
        (25, 1, "Frame Time: 0.04\n"),
    ] {
        let angles = vec![Vec::new(); rig.len()];
        let out = write(&BvhMotion {
            rig: &rig,
            fps: Fps::new(num, den).unwrap(),
            root_positions: &[],
            euler_deg: Angles::Degrees(&angles),
            translations: &[],
        });
        let s = String::from_utf8(out).unwrap();
        assert!(s.contains(text), "{s}");
        assert!(s.contains("Frames: 0\n"));
        let back = bvh::parse(s.as_bytes()).unwrap();
        assert_eq!(back.frame_time_s(), den as f64 / num as f64);
        assert_eq!(back.frame_count(), 0);
    }
}

#[test]
fn invalid_input_is_refused() {
    let rig = small_rig(LengthUnit::Metres);
    let fps = Fps::new(30, 1).unwrap();
    let roots = vec![Vector3::zeros(); 2];
    let good: Vec<Vec<[f64; 3]>> = vec![vec![[0.0; 3]; 2]; rig.len()];
    let check = |roots: &[Vector3<f64>], angles: &[Vec<[f64; 3]>], what: &str| {
        let mut out = Vec::new();
        let err = write::bvh::write_bvh(
            &mut out,
            &BvhMotion {
                rig: &rig,
                fps,
                root_positions: roots,
                euler_deg: Angles::Degrees(angles),
                translations: &[],
            },
        )
        .expect_err(what);
        assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput, "{what}");
        assert!(out.is_empty(), "{what}: nothing is written");
    };
    check(&roots, &good[..4], "one joint missing");
    check(&roots[..1], &good, "fewer root positions than frames");
    let mut short = good.clone();
    short[2].pop();
    check(&roots, &short, "one joint short of frames");
    let mut nan = good.clone();
    nan[3][1][2] = f64::NAN;
    check(&roots, &nan, "NaN angle");
    check(
        &[Vector3::zeros(), Vector3::new(0.0, f64::INFINITY, 0.0)],
        &good,
        "infinite root",
    );

    let spaced = Rig::new(
        "s",
        LengthUnit::Metres,
        vec![Joint {
            name: "Left Arm".into(),
            parent: None,
            offset: Vector3::zeros(),
            order: EulerOrder::ZXY,
            end_site: None,
        }],
    )
    .unwrap();
    let mut out = Vec::new();
    let err = write::bvh::write_bvh(
        &mut out,
        &BvhMotion {
            rig: &spaced,
            fps,
            root_positions: &[],
            euler_deg: Angles::Degrees(&[Vec::new()]),
            translations: &[],
        },
    )
    .unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
    let err = write::bvh::write_bvh_scaled(
        &mut out,
        &BvhMotion {
            rig: &rig,
            fps,
            root_positions: &roots,
            euler_deg: Angles::Degrees(&good),
            translations: &[],
        },
        0.0,
    )
    .unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
}

/// A single-joint rig: the root is a leaf and gets a 0.1 m End Site along +Y (10 in cm).
#[test]
fn leaf_root_end_site() {
    for (units, len) in [(LengthUnit::Metres, 0.1), (LengthUnit::Centimetres, 10.0)] {
        let rig = Rig::new(
            "one",
            units,
            vec![Joint {
                name: "Root".into(),
                parent: None,
                offset: Vector3::new(3.0, 4.0, 5.0),
                order: EulerOrder::ZXY,
                end_site: None,
            }],
        )
        .unwrap();
        let out = write(&BvhMotion {
            rig: &rig,
            fps: Fps::new(24, 1).unwrap(),
            root_positions: &[Vector3::zeros()],
            euler_deg: Angles::Degrees(&[vec![[1.0, 2.0, 3.0]]]),
            translations: &[],
        });
        let back = bvh::parse(&out).unwrap();
        assert!((back.joints()[0].end_site.unwrap() - Vector3::new(0.0, len, 0.0)).norm() < 1e-12);
    }
}

/// A sink that takes `room` bytes and then fails, as a full disk does.
struct FullAfter {
    room: usize,
    taken: Vec<u8>,
}

impl std::io::Write for FullAfter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.taken.len() >= self.room {
            return Err(std::io::Error::new(
                std::io::ErrorKind::StorageFull,
                "no space left",
            ));
        }
        let n = buf.len().min(self.room - self.taken.len());
        self.taken.extend_from_slice(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The motion lines are formatted on the cores while another thread writes them: a write that
/// fails partway through a long take comes back as the error (no hang, nothing after it), and
/// what was written before it is the start of the whole file.
#[test]
fn a_write_failing_partway_is_reported() {
    let rig = small_rig(LengthUnit::Metres);
    let fps = Fps::new(30, 1).unwrap();
    let frames = 20_000;
    let roots: Vec<Vector3<f64>> = (0..frames)
        .map(|f| Vector3::new(f as f64 * 1e-3, 1.0, -0.5))
        .collect();
    let angles: Vec<Vec<[f64; 3]>> = (0..rig.len())
        .map(|j| {
            (0..frames)
                .map(|f| [f as f64 * 0.01, j as f64 - 0.25, -(f as f64) * 0.003])
                .collect()
        })
        .collect();
    let motion = BvhMotion {
        rig: &rig,
        fps,
        root_positions: &roots,
        euler_deg: Angles::Degrees(&angles),
        translations: &[],
    };
    let whole = write(&motion);
    // Each motion line against the values written one by one with `format!` (a value that
    // rounds to zero is written without a sign).
    let six = |v: f64| {
        let text = format!("{v:.6}");
        if text == "-0.000000" {
            "0.000000".to_string()
        } else {
            text
        }
    };
    let text = String::from_utf8(whole.clone()).unwrap();
    let motion_lines: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with("Frame Time"))
        .skip(1)
        .collect();
    assert_eq!(motion_lines.len(), frames);
    for f in [0, 1, 255, 256, 4095, 4096, frames - 1] {
        let mut expected = vec![six(roots[f].x), six(roots[f].y), six(roots[f].z)];
        for joint_angles in &angles {
            expected.extend(joint_angles[f].iter().map(|&a| six(a)));
        }
        assert_eq!(motion_lines[f], expected.join(" "), "frame {f}");
    }
    for room in [10, whole.len() / 3, whole.len() - 1] {
        let mut sink = FullAfter {
            room,
            taken: Vec::new(),
        };
        let err = write::bvh::write_bvh(&mut sink, &motion).expect_err("the disk is full");
        assert_eq!(err.kind(), std::io::ErrorKind::StorageFull, "room {room}");
        assert_eq!(sink.taken, whole[..room], "room {room}");
    }
}

/// Joints that hold still for a while, a root that stays put for a while, and a joint with
/// position channels: the motion lines are exactly the numbers one by one with `{:.6}`, across
/// several of the writer's blocks of frames (where held runs start and end inside blocks too).
#[test]
fn held_joints_and_a_fixed_root_are_written_as_moving_ones_are() {
    let rig = small_rig(LengthUnit::Metres);
    let frames = 1500;
    let moving = |f: usize, j: usize| -> [f64; 3] {
        let t = f as f64 * 0.37 + j as f64;
        [t.sin() * 170.0, -(t * 0.5).cos() * 89.9, (t * 1e-3).tan()]
    };
    let euler: Vec<Vec<[f64; 3]>> = (0..rig.len())
        .map(|j| {
            (0..frames)
                .map(|f| match j {
                    // Never moves, at a value that is not zero.
                    1 => [12.5, -0.0, 1.0 / 3.0],
                    // Held from frame 300 to 1100, moving before and after.
                    2 if (300..1100).contains(&f) => [-45.0, 0.125, 7.0],
                    // Moves on every frame but one value of the three.
                    3 => [moving(f, j)[0], 2.0, moving(f, j)[2]],
                    // Still but for a twitch now and then: the same at both ends of a block.
                    4 if f % 97 == 50 => [1.0, 2.0, 3.5],
                    4 => [1.0, 2.0, 3.0],
                    _ => moving(f, j),
                })
                .collect()
        })
        .collect();
    let roots: Vec<Vector3<f64>> = (0..frames)
        .map(|f| {
            if f < 700 && f % 89 == 30 {
                Vector3::new(0.25, 1.5, -0.0)
            } else if f < 700 {
                Vector3::new(0.25, 1.0, -0.0)
            } else {
                Vector3::new(f as f64 * 1e-3, 1.0, 0.5)
            }
        })
        .collect();
    let translation: Vec<Vector3<f64>> = (0..frames)
        .map(|f| Vector3::new(0.0, 0.3 + if f > 900 { 0.01 } else { 0.0 }, 0.0))
        .collect();
    let translations = vec![(1, translation.clone())];
    let text = String::from_utf8(write(&BvhMotion {
        rig: &rig,
        fps: Fps::new(60, 1).unwrap(),
        root_positions: &roots,
        euler_deg: Angles::Degrees(&euler),
        translations: &translations,
    }))
    .unwrap();
    let motion: Vec<&str> = text
        .split_once("Frame Time: ")
        .unwrap()
        .1
        .lines()
        .skip(1)
        .collect();
    assert_eq!(motion.len(), frames);
    for (f, line) in motion.iter().enumerate() {
        let mut numbers: Vec<f64> = roots[f].iter().copied().collect();
        // Hierarchy order: Hips, Spine (with its position channels), Head, Hand, Tip.
        for (j, angles) in euler.iter().enumerate() {
            if j == 1 {
                numbers.extend(translation[f].iter());
            }
            numbers.extend(angles[f]);
        }
        let expected: Vec<String> = numbers.into_iter().map(common::six_decimals).collect();
        assert_eq!(*line, expected.join(" "), "frame {f}");
    }
}
