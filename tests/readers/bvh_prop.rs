//! Property tests: the reader never panics (arbitrary bytes, token soups, mutations of a valid
//! file), and write → parse keeps hierarchy, offsets and angles for random rigs and motions.

use crate::common;

use imubake::bvh;
use imubake::fps::Fps;
use imubake::rig::{Joint, LengthUnit, Rig};
use imubake::rotation::EulerOrder;
use imubake::write::{
    self,
    bvh::{Angles, BvhMotion},
};
use nalgebra::{UnitQuaternion, Vector3};
use proptest::prelude::*;

fn valid_file() -> Vec<u8> {
    std::fs::read(common::fixture("bvh/tolerant.bvh")).unwrap()
}

/// Pieces of BVH syntax, to reach deep parser states more often than random bytes do.
fn token() -> impl Strategy<Value = &'static str> {
    prop::sample::select(vec![
        "HIERARCHY",
        "ROOT",
        "JOINT",
        "End",
        "Site",
        "{",
        "}",
        "OFFSET",
        "CHANNELS",
        "MOTION",
        "Frames:",
        "Frame",
        "Time:",
        "Xposition",
        "Yposition",
        "Zposition",
        "Xrotation",
        "Yrotation",
        "Zrotation",
        "0",
        "1",
        "3",
        "6",
        "7",
        "-1",
        ".5",
        "1e308",
        "1e999",
        "nan",
        "inf",
        "99999999999999999999",
        "a",
        "\n",
        "\r\n",
        "\r",
        "\t",
        " ",
    ])
}

#[derive(Debug, Clone)]
enum Mutation {
    Delete(usize, usize),
    Insert(usize, Vec<u8>),
    Replace(usize, u8),
    Truncate(usize),
    DuplicateLine(usize),
    SwapLines(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 1usize..20).prop_map(|(p, n)| Mutation::Delete(p, n)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(p, b)| Mutation::Insert(p, b)),
        (
            any::<usize>(),
            prop::sample::select(b"{} \n\r\t0-.e9:aXZnEM".to_vec())
        )
            .prop_map(|(p, b)| Mutation::Replace(p, b)),
        any::<usize>().prop_map(Mutation::Truncate),
        any::<usize>().prop_map(Mutation::DuplicateLine),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    let len = bytes.len().max(1);
    match m {
        Mutation::Delete(p, n) => {
            let start = p % len;
            let end = (start + n).min(bytes.len());
            if start < end {
                bytes.drain(start..end);
            }
        }
        Mutation::Insert(p, b) => {
            let at = p % (bytes.len() + 1);
            bytes.splice(at..at, b.iter().copied());
        }
        Mutation::Replace(p, b) => {
            if !bytes.is_empty() {
                let at = p % bytes.len();
                bytes[at] = *b;
            }
        }
        Mutation::Truncate(p) => bytes.truncate(p % len),
        Mutation::DuplicateLine(p) | Mutation::SwapLines(p, _) => {
            let mut lines: Vec<Vec<u8>> =
                bytes.split(|&b| b == b'\n').map(<[u8]>::to_vec).collect();
            let i = p % lines.len();
            match m {
                Mutation::SwapLines(_, q) => {
                    let j = q % lines.len();
                    lines.swap(i, j);
                }
                _ => {
                    let line = lines[i].clone();
                    lines.insert(i, line);
                }
            }
            *bytes = lines.join(&b'\n');
        }
    }
}

/// Calls everything a caller might call on a parsed file; none of it may panic.
fn exercise(bytes: &[u8]) {
    if let Ok(b) = bvh::parse(bytes) {
        assert_eq!(b.values().len(), b.frame_count() * b.channel_count());
        assert!(b.frame_time_s() > 0.0 && b.frame_time_s().is_finite());
        for (i, j) in b.joints().iter().enumerate() {
            assert!(j.parent.is_none_or(|p| p < i));
            assert_eq!(j.parent.is_none(), i == 0);
            let _ = j.rotation_order();
        }
        if b.channel_count() > 0 {
            for f in [0, b.frame_count().saturating_sub(1)] {
                if f < b.frame_count() {
                    let _ = b.local_rotations(f);
                    let _ = b.joint_translations(f);
                    let _ = b.world_positions(f);
                }
            }
        }
        let _ = b.to_rig("fuzz", LengthUnit::Centimetres);
    } else if let Err(e) = bvh::parse(bytes) {
        assert!(e.line >= 1);
        assert!(!e.message.is_empty());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..2048)) {
        exercise(&bytes);
    }

    #[test]
    fn token_soup_never_panics(tokens in prop::collection::vec(token(), 0..200)) {
        let text = tokens.join(" ");
        exercise(text.as_bytes());
    }

    #[test]
    fn mutations_of_a_valid_file_never_panic(mutations in prop::collection::vec(mutation(), 1..6)) {
        let mut bytes = valid_file();
        for m in &mutations {
            apply(&mut bytes, m);
        }
        exercise(&bytes);
    }
}

/// A random rig and motion. `dfs` keeps joints in depth-first order (each parent is on the
/// path from the root to the previous joint), as a parsed file's are; otherwise any earlier
/// joint may be the parent.
#[derive(Debug, Clone)]
struct Case {
    rig: Rig,
    roots: Vec<Vector3<f64>>,
    angles: Vec<Vec<[f64; 3]>>,
    fps: Fps,
}

fn case(dfs: bool) -> impl Strategy<Value = Case> {
    (1usize..9, 0usize..6).prop_flat_map(move |(joints, frames)| {
        let parents = prop::collection::vec(any::<usize>(), joints);
        let offsets = prop::collection::vec(prop::array::uniform3(-2.0f64..2.0), joints);
        let end_sites = prop::collection::vec(
            prop::option::of(prop::array::uniform3(-1.0f64..1.0)),
            joints,
        );
        let orders = prop::collection::vec(prop::sample::select(EulerOrder::ALL.to_vec()), joints);
        let roots = prop::collection::vec(prop::array::uniform3(-10.0f64..10.0), frames);
        let angles = prop::collection::vec(
            prop::collection::vec(prop::array::uniform3(-180.0f64..180.0), frames),
            joints,
        );
        let fps = (1u64..100_000, 1u64..2000).prop_filter_map("rate", |(n, d)| Fps::new(n, d));
        let units = prop::sample::select(vec![LengthUnit::Metres, LengthUnit::Centimetres]);
        (
            parents, offsets, end_sites, orders, roots, angles, fps, units,
        )
            .prop_map(
                move |(parents, offsets, end_sites, orders, roots, angles, fps, units)| {
                    let mut path: Vec<usize> = Vec::new(); // root → previous joint
                    let mut js = Vec::new();
                    for i in 0..parents.len() {
                        let parent = if i == 0 {
                            None
                        } else if dfs {
                            let depth = parents[i] % path.len();
                            path.truncate(depth + 1);
                            Some(path[depth])
                        } else {
                            Some(parents[i] % i)
                        };
                        path.push(i);
                        js.push(Joint {
                            name: format!("j{i}"),
                            parent,
                            offset: Vector3::from(offsets[i]),
                            order: orders[i],
                            end_site: end_sites[i].map(Vector3::from),
                        });
                    }
                    Case {
                        rig: Rig::new("random", units, js).unwrap(),
                        roots: roots.into_iter().map(Vector3::from).collect(),
                        angles,
                        fps,
                    }
                },
            )
    })
}

fn write(c: &Case) -> Vec<u8> {
    let mut out = Vec::new();
    write::bvh::write_bvh(
        &mut out,
        &BvhMotion {
            rig: &c.rig,
            fps: c.fps,
            root_positions: &c.roots,
            euler_deg: Angles::Degrees(&c.angles),
            translations: &[],
        },
    )
    .unwrap();
    out
}

fn compose(order: EulerOrder, a: [f64; 3]) -> UnitQuaternion<f64> {
    order
        .axes()
        .iter()
        .zip(a)
        .fold(UnitQuaternion::identity(), |q, (&axis, deg)| {
            q * UnitQuaternion::from_axis_angle(&Vector3::ith_axis(axis), deg.to_radians())
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn write_then_parse_keeps_everything(c in case(true)) {
        let bytes = write(&c);
        prop_assert!(!bytes.contains(&b'\r'));
        prop_assert_eq!(&bytes, &write(&c), "deterministic");
        let back = bvh::parse(&bytes).unwrap();
        let frames = c.roots.len();
        prop_assert_eq!(back.frame_count(), frames);
        prop_assert_eq!(back.frame_time_s(), c.fps.frame_time_s());
        prop_assert_eq!(back.joints().len(), c.rig.len());
        for (j, (ours, read)) in c.rig.joints().iter().zip(back.joints()).enumerate() {
            prop_assert_eq!(&ours.name, &read.name);
            prop_assert_eq!(ours.parent, read.parent);
            prop_assert!((ours.offset - read.offset).norm() < 1e-6);
            prop_assert_eq!(read.rotation_order(), ours.order);
            prop_assert_eq!(read.channels.len(), if j == 0 { 6 } else { 3 });
            match ours.end_site {
                Some(e) => prop_assert!((e - read.end_site.unwrap()).norm() < 1e-6),
                None => {
                    let leaf = c.rig.children(j).next().is_none();
                    prop_assert_eq!(read.end_site.is_some(), leaf);
                    if let Some(e) = read.end_site {
                        prop_assert!(e.norm() > 0.0, "a synthesized End Site has length");
                    }
                }
            }
        }
        for f in 0..frames {
            prop_assert!((back.joint_translations(f)[0] - c.roots[f]).norm() < 1e-6);
            let local = back.local_rotations(f);
            for (j, joint) in c.rig.joints().iter().enumerate() {
                let values = back.joint_values(f, j);
                let rot = &values[values.len() - 3..];
                for (r, a) in rot.iter().zip(c.angles[j][f]) {
                    prop_assert!((r - a).abs() <= 5e-7 + 1e-12);
                }
                let expected = compose(joint.order, c.angles[j][f]);
                prop_assert!(local[j].angle_to(&expected) < 1e-6);
            }
        }
    }

    /// Rigs not in depth-first order are written depth first; matched by name, nothing changes.
    #[test]
    fn any_joint_order_round_trips_by_name(c in case(false)) {
        let back = bvh::parse(&write(&c)).unwrap();
        prop_assert_eq!(back.joints().len(), c.rig.len());
        for (j, joint) in c.rig.joints().iter().enumerate() {
            let k = back.joint_index(&joint.name).unwrap();
            let read = &back.joints()[k];
            let parent_name = joint.parent.map(|p| c.rig.joints()[p].name.clone());
            let read_parent = read.parent.map(|p| back.joints()[p].name.clone());
            prop_assert_eq!(parent_name, read_parent);
            prop_assert!((joint.offset - read.offset).norm() < 1e-6);
            for f in 0..c.roots.len() {
                let values = back.joint_values(f, k);
                let rot = &values[values.len() - 3..];
                for (r, a) in rot.iter().zip(c.angles[j][f]) {
                    prop_assert!((r - a).abs() <= 5e-7 + 1e-12);
                }
            }
        }
    }
}
