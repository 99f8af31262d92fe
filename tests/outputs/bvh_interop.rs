//! Interop: the `bvh_anim` crate (another reader, test-only) reads what `write_bvh` writes with
//! the same joint names, offsets, frame count, frame time and values.

use crate::common;

use imubake::bvh;
use imubake::fps::Fps;
use imubake::rig::{Joint, LengthUnit, Rig};
use imubake::rotation::EulerOrder;
use imubake::write::{
    self,
    bvh::{Angles, BvhMotion},
};
use nalgebra::Vector3;

fn check_with_bvh_anim(bytes: &[u8], ours: &bvh::Bvh) {
    let theirs = bvh_anim::from_bytes(bytes).unwrap_or_else(|e| panic!("bvh_anim: {e}"));
    let names: Vec<String> = theirs
        .joints()
        .map(|j| j.data().name().to_string())
        .collect();
    // bvh_anim's hierarchy tokenizer splits on `:` as well as whitespace, so it reads
    // `mixamorig:Hips` as `mixamorig`: compare what it can represent.
    let ours_names: Vec<String> = ours
        .joints()
        .iter()
        .map(|j| j.name.split(':').next().unwrap_or_default().to_string())
        .collect();
    assert_eq!(names, ours_names);
    assert_eq!(theirs.num_frames(), ours.frame_count());
    assert_eq!(theirs.num_channels(), ours.channel_count());
    let ft = theirs.frame_time().as_secs_f64();
    assert!(
        (ft - ours.frame_time_s()).abs() < 1e-9,
        "{ft} vs {}",
        ours.frame_time_s()
    );
    for (j, (a, b)) in theirs.joints().zip(ours.joints()).enumerate() {
        let o = a.data().offset();
        let theirs_offset = Vector3::new(o.x as f64, o.y as f64, o.z as f64);
        assert!(
            (theirs_offset - b.offset).norm() < 1e-4 * (1.0 + b.offset.norm()),
            "joint {j}"
        );
        assert_eq!(a.data().channels().len(), b.channels.len());
        for (c, ours_c) in a.data().channels().iter().zip(&b.channels) {
            assert_eq!(c.channel_type().as_str(), ours_c.name());
        }
    }
    // Values as f32.
    for (f, frame) in theirs.frames().enumerate() {
        let values = frame.as_slice();
        for (k, (x, y)) in values.iter().zip(ours.frame(f)).enumerate() {
            assert!(
                (*x as f64 - y).abs() <= 1e-5 * (1.0 + y.abs()),
                "frame {f} value {k}"
            );
        }
    }
}

#[test]
fn bvh_anim_reads_our_small_rig() {
    let j = |name: &str, parent: Option<usize>, offset: [f64; 3], order| Joint {
        name: name.into(),
        parent,
        offset: Vector3::from(offset),
        order,
        end_site: None,
    };
    let rig = Rig::new(
        "small",
        LengthUnit::Metres,
        vec![
            j("Hips", None, [0.0, 1.0, 0.0], EulerOrder::ZXY),
            j("Spine", Some(0), [0.0, 0.3, 0.0], EulerOrder::XYZ),
            j("Head", Some(1), [0.0, 0.25, 0.02], EulerOrder::ZYX),
            j("LeftArm", Some(1), [0.2, 0.2, 0.0], EulerOrder::YZX),
        ],
    )
    .unwrap();
    let frames = 7;
    let roots: Vec<Vector3<f64>> = (0..frames)
        .map(|f| Vector3::new(0.1 * f as f64, 1.0, -0.05 * f as f64))
        .collect();
    let angles: Vec<Vec<[f64; 3]>> = (0..rig.len())
        .map(|j| {
            (0..frames)
                .map(|f| {
                    let t = f as f64 + j as f64;
                    [
                        30.0 * (0.3 * t).sin(),
                        -20.0 * (0.2 * t).cos(),
                        45.0 * (0.1 * t).sin(),
                    ]
                })
                .collect()
        })
        .collect();
    let mut out = Vec::new();
    write::bvh::write_bvh(
        &mut out,
        &BvhMotion {
            rig: &rig,
            fps: Fps::new(30000, 1001).unwrap(),
            root_positions: &roots,
            euler_deg: Angles::Degrees(&angles),
            translations: &[],
        },
    )
    .unwrap();
    let ours = bvh::parse(&out).unwrap();
    assert_eq!(ours.frame_count(), frames);
    check_with_bvh_anim(&out, &ours);
}

#[test]
fn bvh_anim_reads_our_rewrite_of_real_files() {
    for rel in [
        "bvh/cmu_01_01.bvh",
        "bvh/mixamo_rig_freebvh.bvh",
        "bvh/mocapbank_crlf.bvh",
    ] {
        let Some(path) = common::shared(rel) else {
            return;
        };
        let original = bvh::parse(&std::fs::read(path).unwrap()).unwrap();
        let rig = original.to_rig(rel, LengthUnit::Centimetres).unwrap();
        let frames = original.frame_count().min(200);
        let roots: Vec<Vector3<f64>> = (0..frames)
            .map(|f| original.joint_translations(f)[0])
            .collect();
        // Every joint of these files has three rotation channels, last in its channel list.
        let angles: Vec<Vec<[f64; 3]>> = (0..rig.len())
            .map(|j| {
                (0..frames)
                    .map(|f| {
                        let v = original.joint_values(f, j);
                        [v[v.len() - 3], v[v.len() - 2], v[v.len() - 1]]
                    })
                    .collect()
            })
            .collect();
        let mut out = Vec::new();
        write::bvh::write_bvh(
            &mut out,
            &BvhMotion {
                rig: &rig,
                fps: Fps::new(120, 1).unwrap(),
                root_positions: &roots,
                euler_deg: Angles::Degrees(&angles),
                translations: &[],
            },
        )
        .unwrap();
        let ours = bvh::parse(&out).unwrap();
        assert_eq!(ours.frame_count(), frames);
        check_with_bvh_anim(&out, &ours);
    }
}
