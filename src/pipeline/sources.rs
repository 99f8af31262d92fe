//! Stage 1, sources: each mapped sensor's orientation track in the rig world,
//! `q_rig_sensor = C ⊗ q_world_sensor`, with `C` taking the sensors' world into the rig world
//! ([`World::to_rig`]). Sensors that carry raw readings only are where fusion will come in.

use super::PipelineError;
use crate::mapping::{Mapping, ResolvedSensor};
use crate::rig::Rig;
use crate::take::{Take, Track};
use crate::world::World;
use nalgebra::UnitQuaternion;

/// The sensors that drive bones, in mapping order, and their tracks (rig world).
#[derive(Debug, Clone)]
pub struct Sources {
    pub sensors: Vec<ResolvedSensor>,
    pub tracks: Vec<Track<UnitQuaternion<f64>>>,
}

/// The mapped sensors' orientation tracks in the rig world. A mapped sensor missing from the
/// take, or without orientation, is a warning (its bone keeps its rest rotation), and so is a
/// sensor of the take the mapping does not use; no usable sensor at all is an error.
pub fn orientations(
    take: &Take,
    rig: &Rig,
    mapping: &Mapping,
    resolved: Vec<ResolvedSensor>,
    world: World,
    warnings: &mut Vec<String>,
) -> Result<Sources, PipelineError> {
    let to_rig = world.to_rig();
    let mut sensors = Vec::new();
    let mut tracks = Vec::new();
    for s in resolved {
        let bone = &rig.joints()[s.bone].name;
        match take.sensor(&s.sensor).map(|t| t.orientation()) {
            None => warnings.push(format!(
                "sensor `{}` (mapped to `{bone}`) is not in the take; `{bone}` keeps its rest rotation",
                s.sensor
            )),
            Some(None) => warnings.push(format!(
                "sensor `{}` has raw readings only and fusion is not enabled; `{bone}` keeps its rest rotation",
                s.sensor
            )),
            Some(Some(o)) => {
                tracks.push(o.to_quaternions().map_in_place(|q| to_rig * q));
                sensors.push(s);
            }
        }
    }
    warnings.extend(unmapped_sensors(take, |id| {
        mapping.sensors.iter().any(|m| m.sensor == id)
    }));
    if sensors.is_empty() {
        return Err(no_sensors(
            take,
            mapping.sensors.iter().map(|s| s.sensor.as_str()),
        ));
    }
    Ok(Sources { sensors, tracks })
}

/// A warning for each sensor of the take that the mapping does not use.
pub(crate) fn unmapped_sensors(take: &Take, is_mapped: impl Fn(&str) -> bool) -> Vec<String> {
    take.sensors()
        .iter()
        .filter(|s| !is_mapped(s.id()))
        .map(|s| format!("sensor {} is not in the mapping; ignored", s.id()))
        .collect()
}

/// The error when none of the mapped sensors can drive a bone.
pub(crate) fn no_sensors<'a>(take: &Take, mapped: impl Iterator<Item = &'a str>) -> PipelineError {
    PipelineError::NoSensors {
        mapped: mapped.collect::<Vec<_>>().join(", "),
        present: take
            .sensors()
            .iter()
            .map(|s| s.id())
            .collect::<Vec<_>>()
            .join(", "),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::read::{ReadOptions, imubake_csv};
    use crate::rig::load_rig;

    #[test]
    fn tracks_are_taken_into_the_rig_world_and_strays_are_warned_about() {
        // One sensor turned 90° about ENU z (up): its x axis points north, which is the rig's
        // +Z (conventions.md), and its z axis up, the rig's +Y.
        let csv = "# world: enu\ntime_s,sensor,qw,qx,qy,qz\n0,a,0.70710678,0,0,0.70710678\n0,stray,1,0,0,0\n";
        let take = imubake_csv::read_from(
            csv.as_bytes(),
            std::path::Path::new("t.csv"),
            &ReadOptions::default(),
        )
        .unwrap();
        let rig = load_rig("mixamo").unwrap();
        let text = r#"{"sensors": {"a": {"bone": "Hips", "mount": "+x+y+z"}, "gone": {"bone": "Head", "mount": "+x+y+z"}}}"#;
        let crate::mapping::MappingFile::Quaternion(mapping) =
            crate::mapping::parse_mapping(text, std::path::Path::new("m.json")).unwrap()
        else {
            panic!("a quaternion mapping")
        };
        let resolved = mapping
            .resolve(&rig, std::path::Path::new("m.json"))
            .unwrap();
        let mut warnings = Vec::new();
        let sources =
            orientations(&take, &rig, &mapping, resolved, World::Enu, &mut warnings).unwrap();
        assert_eq!(sources.sensors.len(), 1);
        let q = sources.tracks[0].values()[0];
        let (x, z) = (nalgebra::Vector3::x(), nalgebra::Vector3::z());
        assert!((q * x - z).norm() < 1e-6, "{q:?}");
        assert!((q * z - nalgebra::Vector3::y()).norm() < 1e-6, "{q:?}");
        assert!(
            warnings
                .iter()
                .any(|w| w.contains("`gone`") && w.contains("not in the take"))
        );
        assert!(
            warnings
                .iter()
                .any(|w| w.contains("stray is not in the mapping"))
        );
    }
}
