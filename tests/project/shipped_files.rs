//! Every shipped rig, mapping and sample is valid: mappings parse and resolve on their rig, with
//! the sensor counts of the papers' layouts; samples convert.

use imubake::mapping::{MappingFile, load_mapping};
use imubake::rig::load_rig;
use std::path::Path;

#[test]
fn shipped_mappings_resolve_on_their_rigs() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("mappings");
    // Sensor counts from the papers: 000 has 16 IMUs, 002 12 nodes, 003 13, 004 15.
    let expected = [
        ("paper000_16imu_mixamo.json", 16),
        ("paper002_sou12_mixamo.json", 12),
        ("paper002_sou12.json", 12),
        ("paper003_13imu_mixamo.json", 13),
        ("paper004_15imu_mixamo.json", 15),
    ];
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            continue; // mappings/blender/: the Blender add-on's bone maps, tested there
        }
        let MappingFile::Quaternion(m) = load_mapping(&path).unwrap() else {
            panic!("{}: expected a quaternion mapping", path.display());
        };
        let rig = load_rig(m.rig.as_deref().unwrap_or("mixamo")).unwrap();
        let resolved = m.resolve(&rig, &path).unwrap();
        let name = path.file_name().unwrap().to_str().unwrap();
        if let Some((_, n)) = expected.iter().find(|(f, _)| *f == name) {
            assert_eq!(resolved.len(), *n, "{name}");
            seen += 1;
        }
        // A calibration pose the rig defines.
        if let Some(c) = &m.calibration {
            assert!(
                rig.pose(&c.pose.label()).is_some(),
                "{name}: pose {}",
                c.pose.label()
            );
        }
    }
    assert_eq!(seen, expected.len());
}

#[test]
fn builtin_rigs_are_sound() {
    let mixamo = load_rig("mixamo").unwrap();
    assert_eq!(mixamo.len(), 22);
    // A 1.75 m adult: the top of the head (Head's end site) at 1.75 m, the toes just above 0.
    let rest = mixamo.rest_positions();
    let head = mixamo.joint_index("Head").unwrap();
    let top = rest[head].y + mixamo.joints()[head].end_site.unwrap().y;
    let lowest = rest.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
    assert!((top - 1.75).abs() < 1e-9, "head top at {top}");
    assert!(lowest > 0.0 && lowest < 0.1, "lowest joint at {lowest}");
    // Left is +X: the left hand is at positive x.
    assert!(rest[mixamo.joint_index("LeftHand").unwrap()].x > 0.5);
    // npose: arms straight down.
    let npose = mixamo.world_rotations(&mixamo.pose("npose").unwrap().local);
    let arm = mixamo.joint_index("LeftArm").unwrap();
    let dir = npose[arm] * nalgebra::Vector3::x();
    assert!((dir - -nalgebra::Vector3::y()).norm() < 1e-12, "{dir}");
    let sou = load_rig("sou12").unwrap();
    assert_eq!(sou.len(), 12);
    // Table 1 of paper 002.
    let parent = |n: &str| {
        sou.joints()[sou.joint_index(n).unwrap()]
            .parent
            .map(|p| sou.joints()[p].name.clone())
    };
    for (node, p) in [
        ("N0_1", "N0_0"),
        ("N1_0", "N0_1"),
        ("N2_0", "N0_1"),
        ("N3_0", "N0_0"),
        ("N4_0", "N0_0"),
        ("N5_0", "N0_1"),
        ("N5_1", "N5_0"),
    ] {
        assert_eq!(parent(node).as_deref(), Some(p), "{node}");
    }
    assert_eq!(parent("N0_0"), None);
}
