//! The glTF writer against its real consumers: the Khronos glTF-Validator must find nothing
//! (no errors, warnings or infos) in a GLB and a .gltf + .bin, and real Blender 5.0.1 must import
//! the GLB as one armature whose bones follow forward kinematics computed here, independently of
//! the writer, from the animation's local rotations.

use crate::common;

use common::{blender_import_gltf, gltf_validate, node_modules, python};
use imubake::anim::Animation;
use imubake::fps::Fps;
use imubake::rig::{Joint, LengthUnit, Rig, load_rig};
use imubake::rotation::EulerOrder;
use imubake::write::gltf::{to_glb, to_gltf};
use nalgebra::{Unit, UnitQuaternion, Vector3};

const FRAMES: usize = 450;

/// Mixamo rig, 450 frames (15 s) at 30000/1001 fps. Six joints turn through several full turns
/// about tilted axes, with quaternions kept canonical (w ≥ 0) as Euler conversions produce them,
/// so their sign jumps every half turn and the writer's hemisphere flipping matters; the root
/// walks a curve and bobs.
fn take() -> Animation {
    let rig = load_rig("mixamo").unwrap();
    let fps = Fps::new(30000, 1001).unwrap();
    let spinning = [
        "Hips",
        "Spine1",
        "LeftArm",
        "LeftForeArm",
        "RightUpLeg",
        "Head",
    ]
    .map(|j| rig.joint_index(j).unwrap());
    let mut local = vec![Vec::with_capacity(FRAMES); rig.len()];
    let mut roots = Vec::with_capacity(FRAMES);
    for n in 0..FRAMES {
        let t = fps.frame_time_of(n as u64);
        for (j, track) in local.iter_mut().enumerate() {
            let q = match spinning.iter().position(|&s| s == j) {
                Some(k) => {
                    let axis = Unit::new_normalize(Vector3::new(
                        (k as f64).sin(),
                        1.0,
                        0.5 * (k as f64).cos(),
                    ));
                    // 0.6 to 1.6 turns per second: about 7° to 19° per frame.
                    let angle = std::f64::consts::TAU * (0.6 + 0.2 * k as f64) * t;
                    let q = UnitQuaternion::from_axis_angle(&axis, angle);
                    if q.w < 0.0 {
                        UnitQuaternion::new_unchecked(-q.into_inner())
                    } else {
                        q
                    }
                }
                None => UnitQuaternion::identity(),
            };
            track.push(q);
        }
        roots.push(Vector3::new(
            0.8 * (0.5 * t).sin(),
            1.0 + 0.05 * (4.0 * t).sin(),
            0.4 * t,
        ));
    }
    let animated = (0..rig.len()).map(|j| spinning.contains(&j)).collect();
    Animation::new(rig, fps, local, animated, roots).unwrap()
}

fn assert_clean(report: &serde_json::Value) {
    eprintln!(
        "{}: errors {} warnings {} infos {} hints {}",
        report["path"], report["errors"], report["warnings"], report["infos"], report["hints"]
    );
    let counts = ["errors", "warnings", "infos"].map(|k| report[k].as_u64());
    assert_eq!(counts, [Some(0); 3], "{report:#}");
}

#[test]
fn validator_finds_nothing_in_glb_and_gltf() {
    let Some(modules) = node_modules() else {
        return;
    };
    let anim = take();
    let dir = tempfile::tempdir().unwrap();

    let glb = dir.path().join("spin walk.glb");
    std::fs::write(&glb, to_glb(&anim, "spin walk").unwrap()).unwrap();

    // A name with a space: the buffer URI must be percent-encoded for the validator to find it.
    let (json, bin) = to_gltf(&anim, "spin walk", "spin walk.bin").unwrap();
    std::fs::write(dir.path().join("spin walk.gltf"), json).unwrap();
    std::fs::write(dir.path().join("spin walk.bin"), bin).unwrap();

    // One frame: a single key per channel.
    let rig = load_rig("mixamo").unwrap();
    let n = rig.len();
    let still = Animation::new(
        rig,
        Fps::new(24, 1).unwrap(),
        vec![vec![UnitQuaternion::identity()]; n],
        vec![false; n],
        vec![Vector3::new(0.0, 1.0, 0.0)],
    )
    .unwrap();
    let one = dir.path().join("still.glb");
    std::fs::write(&one, to_glb(&still, "still").unwrap()).unwrap();

    // 300 joints (JOINTS_0 as UNSIGNED_SHORT), a chain in centimetres without end sites, every
    // joint animated.
    let joints = (0..300usize)
        .map(|i| Joint {
            name: format!("j{i}"),
            parent: i.checked_sub(1),
            offset: if i == 0 {
                Vector3::new(0.0, 100.0, 0.0)
            } else {
                Vector3::new(0.0, 1.0, 0.5)
            },
            order: EulerOrder::ZXY,
            end_site: None,
        })
        .collect();
    let rig = Rig::new("chain", LengthUnit::Centimetres, joints).unwrap();
    let fps = Fps::new(60, 1).unwrap();
    let local = (0..300)
        .map(|j| {
            (0..40)
                .map(|n| UnitQuaternion::from_euler_angles(0.01 * j as f64, 0.3 * n as f64, 0.0))
                .collect()
        })
        .collect();
    let chain = Animation::new(
        rig,
        fps,
        local,
        vec![true; 300],
        vec![Vector3::new(0.0, 100.0, 0.0); 40],
    )
    .unwrap();
    let long = dir.path().join("chain.glb");
    std::fs::write(&long, to_glb(&chain, "chain").unwrap()).unwrap();

    let files = [glb, dir.path().join("spin walk.gltf"), one, long];
    for report in gltf_validate(&files, &modules) {
        assert_clean(&report);
    }
}

#[test]
fn blender_imports_an_armature_that_follows_forward_kinematics() {
    let Some(py) = python() else {
        return;
    };
    let anim = take();
    let rig = anim.rig();
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("spin.glb");
    std::fs::write(&glb, to_glb(&anim, "spin").unwrap()).unwrap();

    let bones = [
        "Hips",
        "Spine1",
        "Head",
        "LeftHand",
        "RightToeBase",
        "LeftFoot",
    ];
    // Frames spread over the take, including both ends and frames right after sign jumps.
    let frames: Vec<usize> = vec![0, 1, 7, 57, 123, 200, 301, 388, FRAMES - 2, FRAMES - 1];
    // The key times exactly as written (f32).
    let times: Vec<f64> = frames
        .iter()
        .map(|&n| f64::from(anim.fps().frame_time_of(n as u64) as f32))
        .collect();
    let query = serde_json::json!({"bones": bones, "times": times});
    let report = &blender_import_gltf(&py, &[&glb], &query)[0];
    eprintln!(
        "Blender {}: {} armature(s), {} bones, action {}, frame range {}, {} frames per second",
        report["blender"],
        report["armatures"],
        report["bones"].as_array().map_or(0, Vec::len),
        report["action"],
        report["frame_range"],
        report["frames_per_second"]
    );
    assert_eq!(report["blender"], "5.0.1");
    assert_eq!(report["armatures"], 1, "{report}");
    assert_eq!(report["empties"], 0, "{report}");
    // The bone mesh is deformed by that armature (a skinned mesh, not empties).
    let skinned = report["skinned_meshes"].as_array().unwrap();
    assert_eq!(skinned.len(), 1, "{report}");
    assert_eq!(skinned[0]["armature"], report["armature"], "{report}");
    let names: Vec<&str> = common::strings(&report["bones"]);
    let mut expected: Vec<&str> = rig.joints().iter().map(|j| j.name.as_str()).collect();
    let mut got = names.clone();
    expected.sort_unstable();
    got.sort_unstable();
    assert_eq!(got, expected);
    assert_eq!(
        report["action"].as_str().map(|a| a.contains("spin")),
        Some(true),
        "{report}"
    );
    // The importer puts t = 0 at frame 0 and the last key at t_last · its factor.
    let per_second = report["frames_per_second"].as_f64().unwrap();
    let range = &report["frame_range"];
    assert!(range[0].as_f64().unwrap().abs() < 1e-4, "{report}");
    let last = f64::from(anim.duration_s() as f32) * per_second;
    assert!(
        (range[1].as_f64().unwrap() - last).abs() < 1e-3,
        "{range} vs {last}"
    );

    let metres = rig.units().metres_per_unit();
    let mut worst = 0.0f64;
    for (k, &n) in frames.iter().enumerate() {
        let fk = rig.world_positions(&anim.pose_at(n), anim.root_positions()[n]);
        let sample = &report["heads"][k];
        for bone in bones {
            let j = rig.joint_index(bone).unwrap();
            let p = fk[j] * metres;
            // glTF / rig world (x, y, z) is Blender (x, -z, y).
            let expected = Vector3::new(p.x, -p.z, p.y);
            let got = common::vec3(&sample["bones"][bone]);
            let err = (got - expected).norm();
            worst = worst.max(err);
            assert!(
                err < 1e-4,
                "frame {n} bone {bone}: Blender {got:?}, forward kinematics {expected:?}, {err} m"
            );
        }
    }
    eprintln!(
        "largest head position difference over {} bones x {} frames: {worst:.3e} m",
        bones.len(),
        frames.len()
    );
}
