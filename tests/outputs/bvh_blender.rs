//! Real Blender (5.0.1 as the `bpy` module in the test venv) imports BVH files we wrote, at 24,
//! 30000/1001, 60 and 120 fps, with `update_scene_fps` and `update_scene_duration`; the script
//! tests/python/blender_import_bvh.py reports the scene rate, bones, keys, and each bone's world
//! head and rotation at every keyed frame. Skips locally when the venv is missing (fails under
//! CI=true).
//!
//! Head positions are axis-convention free: Blender's importer (axis_forward '-Z', axis_up 'Y')
//! maps a BVH point (x, y, z) to Blender (x, -z, y). Bone rotations are compared relative to
//! frame 0, which cancels Blender's bone-along-Y rest orientation: B(f)·B(0)ᵀ = C·R(f)·R(0)ᵀ·Cᵀ.

use crate::common;

use imubake::fps::Fps;
use imubake::rig::{Joint, LengthUnit, Rig};
use imubake::rotation::EulerOrder;
use imubake::write::{
    self,
    bvh::{Angles, BvhMotion},
};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde_json::Value;

/// More than Blender's default scene length (250), so that `update_scene_duration` has to act.
const FRAMES: usize = 260;

fn rig() -> Rig {
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
        "blender_test",
        LengthUnit::Metres,
        vec![
            j("Hips", None, [0.0, 1.0, 0.0], EulerOrder::ZXY, None),
            j("Spine", Some(0), [0.0, 0.3, 0.0], EulerOrder::XYZ, None),
            // Head: no end site in the rig, so the writer invents one.
            j("Head", Some(1), [0.0, 0.25, 0.02], EulerOrder::ZYX, None),
            j(
                "LeftArm",
                Some(1),
                [0.2, 0.2, 0.0],
                EulerOrder::YZX,
                Some([0.3, 0.0, 0.0]),
            ),
        ],
    )
    .unwrap()
}

/// A known motion: every angle a different sinusoid of the frame, the root walking along -Z.
fn motion(rig: &Rig) -> (Vec<Vector3<f64>>, Vec<Vec<[f64; 3]>>) {
    let roots = (0..FRAMES)
        .map(|f| {
            let t = f as f64;
            Vector3::new(0.05 * t, 1.0 + 0.02 * (0.7 * t).sin(), -0.1 * t)
        })
        .collect();
    let angles = (0..rig.len())
        .map(|j| {
            (0..FRAMES)
                .map(|f| {
                    let t = f as f64 + 2.0 * j as f64;
                    [
                        40.0 * (0.4 * t).sin(),
                        25.0 * (0.3 * t + 1.0).cos(),
                        -35.0 * (0.25 * t).sin(),
                    ]
                })
                .collect()
        })
        .collect();
    (roots, angles)
}

/// Local rotations from the angles by the conventions (application order, intrinsic).
fn local_rotations(rig: &Rig, angles: &[Vec<[f64; 3]>], frame: usize) -> Vec<UnitQuaternion<f64>> {
    rig.joints()
        .iter()
        .zip(angles)
        .map(|(joint, a)| {
            joint.order.axes().iter().zip(a[frame]).fold(
                UnitQuaternion::identity(),
                |q, (&axis, deg)| {
                    q * UnitQuaternion::from_axis_angle(&Vector3::ith_axis(axis), deg.to_radians())
                },
            )
        })
        .collect()
}

/// BVH (Y-up) → Blender (Z-up) as the importer's default axis conversion does.
fn to_blender() -> Matrix3<f64> {
    Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0)
}

fn mat3(v: &Value) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| v[r][c].as_f64().unwrap())
}

#[test]
fn blender_imports_our_bvh() {
    let Some(python) = common::python() else {
        return;
    };
    let rig = rig();
    let (roots, angles) = motion(&rig);
    let rates = [(24u64, 1u64), (30000, 1001), (60, 1), (120, 1)];
    let dir = tempfile::tempdir().unwrap();
    let mut paths = Vec::new();
    for (num, den) in rates {
        let path = dir.path().join(format!("take_{num}_{den}.bvh"));
        let file = std::fs::File::create(&path).unwrap();
        write::bvh::write_bvh(
            file,
            &BvhMotion {
                rig: &rig,
                fps: Fps::new(num, den).unwrap(),
                root_positions: &roots,
                euler_deg: Angles::Degrees(&angles),
                translations: &[],
            },
        )
        .unwrap();
        paths.push(path);
    }
    let report = common::blender_import_bvh(&python, &paths, None);
    eprintln!("Blender {}", report["blender"]);

    // Our forward kinematics of the motion, in BVH world axes.
    let c = to_blender();
    let heads: Vec<Vec<Vector3<f64>>> = (0..FRAMES)
        .map(|f| rig.world_positions(&local_rotations(&rig, &angles, f), roots[f]))
        .collect();
    let world_rots: Vec<Vec<Matrix3<f64>>> = (0..FRAMES)
        .map(|f| {
            rig.world_rotations(&local_rotations(&rig, &angles, f))
                .iter()
                .map(|q| q.to_rotation_matrix().into_inner())
                .collect()
        })
        .collect();

    for ((num, den), file) in rates.iter().zip(report["files"].as_array().unwrap()) {
        let fps = file["fps"].as_f64().unwrap();
        let fps_base = file["fps_base"].as_f64().unwrap();
        let rate = *num as f64 / *den as f64;
        eprintln!(
            "{num}/{den}: Blender fps {fps}, fps_base {fps_base:.9}, rate {:.9}",
            fps / fps_base
        );
        assert_eq!(fps, rate.round(), "{num}/{den}");
        // fps_base is a single-precision property: 1.001 is stored as 1.00100004673.
        assert!(
            (fps_base - fps * *den as f64 / *num as f64).abs() < 1e-6,
            "{num}/{den}: fps_base {fps_base}"
        );
        assert!(((fps / fps_base) / rate - 1.0).abs() < 1e-6, "{num}/{den}");
        assert_eq!(file["frame_start"].as_i64(), Some(1));
        // The importer sets frame_end = frame_start + frame count (one past the last key) and
        // only ever extends the scene.
        assert_eq!(
            file["frame_end"].as_i64(),
            Some(FRAMES as i64 + 1),
            "{num}/{den}"
        );

        let bones: Vec<&str> = common::strings(&file["bones"]);
        assert_eq!(bones, ["Hips", "Spine", "Head", "LeftArm"]);
        // Hips: location and rotation_euler (3 + 3); the others rotation_euler (3 each).
        let curves = file["fcurves"].as_array().unwrap();
        assert_eq!(curves.len(), 6 + 3 * 3, "{num}/{den}");
        for curve in curves {
            assert_eq!(curve["keys"].as_u64(), Some(FRAMES as u64), "{curve}");
            // Our frame n is Blender frame n + 1.
            assert_eq!(curve["first"].as_f64(), Some(1.0), "{curve}");
            assert_eq!(curve["last"].as_f64(), Some(FRAMES as f64), "{curve}");
        }

        let frames = file["frames"].as_array().unwrap();
        assert_eq!(frames.len(), FRAMES);
        let base: Vec<Matrix3<f64>> = bones
            .iter()
            .map(|b| mat3(&frames[0]["bones"][b]["matrix"]))
            .collect();
        for (f, frame) in frames.iter().enumerate() {
            assert_eq!(frame["frame"].as_u64(), Some(f as u64 + 1));
            for (j, name) in bones.iter().enumerate() {
                let head = common::vec3(&frame["bones"][name]["head"]);
                let expected = c * heads[f][j];
                assert!(
                    (head - expected).norm() < 1e-5,
                    "{num}/{den} frame {f} {name}: Blender {head} vs ours {expected}"
                );

                let b = mat3(&frame["bones"][name]["matrix"]);
                let blender_rel = b * base[j].transpose();
                let ours_rel = c * world_rots[f][j] * world_rots[0][j].transpose() * c.transpose();
                assert!(
                    (blender_rel - ours_rel).abs().max() < 1e-5,
                    "{num}/{den} frame {f} {name}: rotation relative to frame 0 differs"
                );
            }
        }
    }
}
