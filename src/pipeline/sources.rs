//! Stage 1, sources: each mapped sensor's orientation track in the rig world,
//! `q_rig_sensor = C_w ⊗ q_w_sensor`, with `C_w` taking the sensor's own world `w` into the rig
//! world ([`World::to_rig`]). A sensor's world is its own: a device orientation is in the take's
//! world (or the one the user set), a fused one in `enu` ([`crate::fusion`]).
//!
//! Which readings give a sensor's orientation: the device's own when the take has it, unless
//! fusion is asked for (`--fusion`); the fusion of its raw gyroscope, accelerometer (and
//! magnetometer) readings otherwise, with the default filter when none is asked for.

use super::PipelineError;
use super::parallel::parallel_map;
use crate::fusion::{self, Fusion, FusionStats};
use crate::intrinsics::BiasFallback;
use crate::mapping::{Mapping, ResolvedSensor};
use crate::rig::Rig;
use crate::take::{Sensor, Take, Track};
use crate::world::World;
use nalgebra::UnitQuaternion;

/// Where a sensor's orientation came from.
#[derive(Debug, Clone)]
pub enum Origin {
    /// The device's own orientation, in `world`.
    Device { world: World },
    /// Fused from raw readings (world `enu`).
    Fused(FusionStats),
}

impl Origin {
    /// The world the sensor's orientation is in.
    pub fn world(&self) -> World {
        match self {
            Origin::Device { world } => *world,
            Origin::Fused(_) => World::Enu,
        }
    }

    /// Whether the heading is the sensor's own (fused without a magnetometer): arbitrary, and
    /// to be aligned at calibration.
    pub fn heading_unknown(&self) -> bool {
        matches!(self, Origin::Fused(s) if s.variant == "6d")
    }
}

/// The sensors that drive bones, in mapping order, their tracks (rig world) and where each came
/// from.
#[derive(Debug, Clone)]
pub struct Sources {
    pub sensors: Vec<ResolvedSensor>,
    pub tracks: Vec<Track<UnitQuaternion<f64>>>,
    pub origins: Vec<Origin>,
    /// The filter, when any sensor was fused.
    pub fusion: Option<Fusion>,
}

/// What a mapped sensor's orientation will come from.
#[derive(Clone, Copy)]
enum Plan {
    Missing,
    /// The device's own orientations.
    Device,
    /// Fused from its raw readings.
    Fuse,
    /// Readings that cannot give an orientation, and why.
    Unusable(&'static str),
}

fn plan(sensor: Option<&Sensor>, fusion_asked: bool) -> Plan {
    let Some(s) = sensor else {
        return Plan::Missing;
    };
    match (s.orientation(), s.inertial()) {
        (Some(_), None) => Plan::Device,
        (Some(_), Some(_)) if !fusion_asked => Plan::Device,
        (_, Some(_)) => Plan::Fuse,
        (None, None) => Plan::Unusable(
            "has magnetometer readings only: fusion needs its gyroscope and accelerometer",
        ),
    }
}

/// The take the orientations come from: borrowed (the device tracks are copied) or owned by the
/// pipeline (they are moved out, so a long take is not held twice).
pub enum TakeInput<'a> {
    Borrowed(&'a Take),
    Owned(&'a mut Take),
}

impl TakeInput<'_> {
    pub fn take(&self) -> &Take {
        match self {
            TakeInput::Borrowed(t) => t,
            TakeInput::Owned(t) => t,
        }
    }

    /// A sensor's device orientations as quaternions.
    fn device_track(&mut self, id: &str) -> Option<Track<UnitQuaternion<f64>>> {
        match self {
            TakeInput::Borrowed(t) => t.sensor(id)?.orientation().map(|o| o.to_quaternions()),
            TakeInput::Owned(t) => t.remove_orientation(id).map(|o| o.into_quaternions()),
        }
    }
}

/// The mapped sensors' orientation tracks in the rig world. A mapped sensor missing from the
/// take, or without readings that give an orientation, is a warning (its bone keeps its rest
/// rotation), and so is a sensor of the take the mapping does not use; no usable sensor at all is
/// an error, and so are raw readings that cannot be right ([`fusion::FusionError`]). `world` is
/// the device orientations' world; `options.fusion` the filter asked for (`None`: device
/// orientations where there are some, the default filter elsewhere: offline, or online VQF in
/// causal mode).
pub fn orientations(
    mut input: TakeInput,
    rig: &Rig,
    mapping: &Mapping,
    resolved: Vec<ResolvedSensor>,
    world: World,
    options: &super::PipelineOptions,
    warnings: &mut Vec<String>,
) -> Result<Sources, PipelineError> {
    let (fusion, causal) = (options.fusion.as_ref(), options.causal);
    // A whole take gets the offline fusion by default; causal mode (a stream's view) cannot look
    // ahead, so it runs the online counterpart of whatever was asked for.
    let filter = match (fusion, causal) {
        (None, false) => Fusion::default(),
        (None, true) => Fusion::online_default(),
        (Some(f), false) => f.clone(),
        (Some(f), true) => {
            if f.is_offline() {
                warnings.push(format!(
                    "fusion `{f}` needs the whole take; causal mode fuses with `{}` instead",
                    f.online()
                ));
            }
            f.online()
        }
    };
    let mut kept = Vec::new();
    for s in resolved {
        let bone = &rig.joints()[s.bone].name;
        match plan(input.take().sensor(&s.sensor), fusion.is_some()) {
            Plan::Missing => warnings.push(format!(
                "sensor `{}` (mapped to `{bone}`) is not in the take; `{bone}` keeps its rest rotation",
                s.sensor
            )),
            Plan::Unusable(why) => warnings.push(format!(
                "sensor `{}` {why}; `{bone}` keeps its rest rotation",
                s.sensor
            )),
            plan => kept.push((s, plan)),
        }
    }
    // Device tracks first (moved out of an owned take); then fusion, the costly part, each
    // sensor's independent: spread over the cores.
    let kept: Vec<_> = kept
        .into_iter()
        .map(|(s, plan)| {
            let device = match plan {
                Plan::Device => input.device_track(&s.sensor),
                _ => None,
            };
            (s, plan, device)
        })
        .collect();
    let take = input.take();
    // Once, not per sample: the compiler does not hoist it out of the loop.
    let world_to_rig = world.to_rig();
    let results = parallel_map(kept, |(s, plan, device)| {
        let result = match (plan, device) {
            (Plan::Device, Some(track)) => Ok((
                track.map_in_place(|q| world_to_rig * q),
                Origin::Device { world },
                Vec::new(),
            )),
            (Plan::Fuse, _) => {
                let sensor = take
                    .sensor(&s.sensor)
                    .expect("planned for a sensor of the take");
                let prepared = crate::intrinsics::prepare(
                    sensor.id(),
                    sensor.inertial().expect("planned for raw readings"),
                    sensor.magnetometer(),
                    options
                        .sensor_calibration
                        .as_ref()
                        .and_then(|c| c.sensors.get(sensor.id())),
                    if filter.estimates_gyro_bias() {
                        BiasFallback::Filter
                    } else if causal {
                        BiasFallback::LeftIn
                    } else {
                        BiasFallback::OpeningStillness
                    },
                );
                // Causal mode fuses as a live stream does (the filter's period from the first
                // readings), so a take converted causally gives the frames a session of it gave.
                let mut prepared = prepared;
                if causal && !filter.estimates_gyro_bias() {
                    for c in &mut prepared.corrections {
                        if c.starts_with("gyro-bias (estimated") {
                            *c =
                                "gyro-bias left in (causal: no look ahead at an opening stillness)"
                                    .into();
                        }
                    }
                }
                let fuse = if causal {
                    fusion::stream::fuse_as_stream
                } else {
                    fusion::fuse
                };
                fuse(
                    sensor.id(),
                    &prepared.inertial,
                    prepared.magnetometer.as_deref(),
                    &filter,
                )
                .map(|mut fused| {
                    let to_rig = World::Enu.to_rig();
                    fused.stats.corrections = prepared.corrections;
                    let mut warnings = prepared.warnings;
                    warnings.extend(fused.warnings);
                    (
                        fused.track.map_in_place(|q| to_rig * q),
                        Origin::Fused(fused.stats),
                        warnings,
                    )
                })
            }
            _ => unreachable!("planned only for sensors with orientations or raw readings"),
        };
        (s, result)
    });
    let mut sources = Sources {
        sensors: Vec::new(),
        tracks: Vec::new(),
        origins: Vec::new(),
        fusion: None,
    };
    for (mut s, result) in results {
        let (track, origin, fusion_warnings) = result?;
        s.own_heading = origin.heading_unknown();
        warnings.extend(fusion_warnings);
        if matches!(origin, Origin::Fused(_)) {
            sources.fusion = Some(filter.clone());
        }
        sources.sensors.push(s);
        sources.tracks.push(track);
        sources.origins.push(origin);
    }
    warnings.extend(unmapped_sensors(take, |id| {
        mapping.sensors.iter().any(|m| m.sensor == id)
    }));
    if sources.sensors.is_empty() {
        return Err(no_sensors(
            take,
            mapping.sensors.iter().map(|s| s.sensor.as_str()),
        ));
    }
    Ok(sources)
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
        let sources = orientations(
            TakeInput::Borrowed(&take),
            &rig,
            &mapping,
            resolved,
            World::Enu,
            &crate::pipeline::PipelineOptions::default(),
            &mut warnings,
        )
        .unwrap();
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
