//! APDM Opal recordings (`.h5`, Mobility Lab 2 / Motion Studio, file format 5), read through
//! libhdf5 (`hdf5-metno`, behind the cargo feature `hdf5`):
//!
//! ```text
//! /Sensors/<id>/Accelerometer   N × 3, m/s²
//! /Sensors/<id>/Gyroscope       N × 3, rad/s
//! /Sensors/<id>/Magnetometer    N × 3, µT
//! /Sensors/<id>/Time            N, µs since the Unix epoch
//! /Sensors/<id>/Configuration   a group; attribute `Label 0`: the sensor's label
//! /Processed/<id>/Orientation   N × 4, w first (when APDM's software fused it)
//! ```
//!
//! - Sensor ids are the labels (`Label 0`, NUL padding trimmed), else the group name.
//! - Raw readings become the take's inertial and magnetometer streams (fused like any raw take);
//!   APDM's orientation, when present, is the device orientation, in `nwu` (x north, y west,
//!   z up: what public readers take APDM's earth frame to be — not confirmed by APDM's own
//!   document, which was not available).
//! - A dataset of the wrong shape, or whose length is not `Time`'s, is an error naming it; a
//!   sample with a value that is not finite is dropped and reported (its "line" is the sample's
//!   number).
//!
//! libhdf5 is C: a file is refused by its signature before libhdf5 sees it, and a crash inside
//! libhdf5 could not be caught (the property tests feed it mutated files written by libhdf5).

#[cfg(feature = "hdf5")]
use super::InputFormat;
use super::{ReadError, ReadOptions};
use crate::take::Take;
#[cfg(feature = "hdf5")]
use hdf5_metno as hdf5;
use std::path::Path;

/// The 8 bytes every HDF5 file starts with (at offset 0 for files written from scratch).
pub const SIGNATURE: &[u8; 8] = b"\x89HDF\r\n\x1a\n";

/// True when the bytes start with HDF5's signature.
pub fn looks_like(head: &[u8]) -> bool {
    head.starts_with(SIGNATURE)
}

/// Reads an APDM `.h5` file.
#[cfg(not(feature = "hdf5"))]
pub fn read(path: &Path, _options: &ReadOptions) -> Result<Take, ReadError> {
    Err(ReadError::format(
        path,
        "an HDF5 file (APDM Opal): this imubake was built without HDF5 support. Hint: build it \
         with `cargo install --path . --features hdf5` (needs libhdf5, Debian's libhdf5-dev)",
    ))
}

/// Reads an APDM `.h5` file.
#[cfg(feature = "hdf5")]
pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    use crate::take::{ClockUnit, ImuSample, TakeBuilder};
    use crate::world::World;
    use nalgebra::{Quaternion, Vector3};

    let head = super::sniff(path)?;
    if !looks_like(&head) {
        return Err(ReadError::format(
            path,
            "not an HDF5 file (no HDF5 signature)",
        ));
    }
    let fail = |what: String| ReadError::format(path, what);
    let h5 = |e: hdf5::Error| fail(format!("HDF5: {e}"));
    let file = hdf5::File::open(path).map_err(h5)?;
    let sensors = file.group("Sensors").map_err(|_| {
        fail(
            "no `/Sensors` group: not an APDM file of format 5 (formats 3 and 4 are not read)"
                .into(),
        )
    })?;
    let mut ids = sensors.member_names().map_err(h5)?;
    ids.sort();
    let world = options.world.unwrap_or(World::Nwu);
    let mut take = TakeBuilder::new(path, InputFormat::ApdmH5, world, ClockUnit::Microseconds);
    for id in ids {
        let group = sensors.group(&id).map_err(h5)?;
        let label = group
            .group("Configuration")
            .ok()
            .and_then(|c| c.attr("Label 0").ok())
            .and_then(|a| string_attribute(&a))
            .filter(|l| !l.is_empty())
            .unwrap_or_else(|| id.clone());
        let where_ = |name: &str| format!("/Sensors/{id}/{name}");
        let vectors = |name: &str| -> Result<Option<Vec<[f64; 3]>>, ReadError> {
            let Ok(ds) = group.dataset(name) else {
                return Ok(None);
            };
            let shape = ds.shape();
            if shape.len() != 2 || shape[1] != 3 {
                return Err(fail(format!(
                    "{} has shape {shape:?}; expected N × 3",
                    where_(name)
                )));
            }
            let a = ds.read_2d::<f64>().map_err(h5)?;
            Ok(Some(
                a.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect(),
            ))
        };
        let time = group
            .dataset("Time")
            .map_err(|_| fail(format!("{} is missing", where_("Time"))))?;
        if time.shape().len() != 1 {
            return Err(fail(format!(
                "{} has shape {:?}; expected N",
                where_("Time"),
                time.shape()
            )));
        }
        let time: Vec<f64> = time.read_1d::<f64>().map_err(h5)?.to_vec();
        let acc = vectors("Accelerometer")?;
        let gyro = vectors("Gyroscope")?;
        let mag = vectors("Magnetometer")?;
        let orientation = match file.dataset(&format!("Processed/{id}/Orientation")) {
            Ok(ds) => {
                let shape = ds.shape();
                if shape.len() != 2 || shape[1] != 4 {
                    return Err(fail(format!(
                        "/Processed/{id}/Orientation has shape {shape:?}; expected N × 4"
                    )));
                }
                let a = ds.read_2d::<f64>().map_err(h5)?;
                Some(
                    a.rows()
                        .into_iter()
                        .map(|r| [r[0], r[1], r[2], r[3]])
                        .collect::<Vec<_>>(),
                )
            }
            Err(_) => None,
        };
        for (name, len) in [
            ("Accelerometer", acc.as_ref().map(Vec::len)),
            ("Gyroscope", gyro.as_ref().map(Vec::len)),
            ("Magnetometer", mag.as_ref().map(Vec::len)),
            ("Orientation", orientation.as_ref().map(Vec::len)),
        ] {
            if let Some(len) = len
                && len != time.len()
            {
                return Err(fail(format!(
                    "sensor `{id}`: {name} has {len} samples, Time {}",
                    time.len()
                )));
            }
        }
        if acc.is_none() && gyro.is_none() && orientation.is_none() {
            take.warn(format!(
                "sensor `{id}` has neither readings nor an orientation: skipped"
            ));
            continue;
        }
        let sensor = take.sensor(&label);
        take.set_file(Some(format!("/Sensors/{id}")));
        for (n, &t) in time.iter().enumerate() {
            let line = n as u64 + 1;
            let raw = format!("sample {n}");
            let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
            if !t.is_finite() {
                take.drop_line(line, "a time that is not a number", raw.as_bytes());
                continue;
            }
            if let (Some(a), Some(g)) = (&acc, &gyro) {
                if finite(&a[n]) && finite(&g[n]) {
                    let sample = ImuSample {
                        gyro_rad_s: Vector3::from(g[n]),
                        accel_m_s2: Vector3::from(a[n]),
                    };
                    take.push_inertial(sensor, t, sample, line, raw.as_bytes())
                        .map_err(|e| ReadError::take(path, e))?;
                } else {
                    take.drop_line(line, "a reading that is not a number", raw.as_bytes());
                }
            }
            if let Some(m) = &mag
                && finite(&m[n])
            {
                take.push_magnetometer(sensor, t, Vector3::from(m[n]), line, raw.as_bytes())
                    .map_err(|e| ReadError::take(path, e))?;
            }
            if let Some(o) = &orientation {
                let [w, x, y, z] = o[n];
                match super::unit_quaternion(Quaternion::new(w, x, y, z)) {
                    Some((q, _)) => take
                        .push_quaternion(sensor, t, q, line, raw.as_bytes())
                        .map_err(|e| ReadError::take(path, e))?,
                    None => take.drop_line(
                        line,
                        "an orientation that is not a rotation",
                        raw.as_bytes(),
                    ),
                }
            }
        }
    }
    take.set_file(None);
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

/// A string attribute, whatever HDF5 string type it was written as; NUL padding and spaces
/// trimmed.
#[cfg(feature = "hdf5")]
fn string_attribute(a: &hdf5::Attribute) -> Option<String> {
    use hdf5::types::{FixedAscii, FixedUnicode, VarLenAscii, VarLenUnicode};
    let text = a
        .read_scalar::<VarLenUnicode>()
        .map(|s| s.as_str().to_string())
        .or_else(|_| {
            a.read_scalar::<VarLenAscii>()
                .map(|s| s.as_str().to_string())
        })
        .or_else(|_| {
            a.read_scalar::<FixedAscii<1024>>()
                .map(|s| s.as_str().to_string())
        })
        .or_else(|_| {
            a.read_scalar::<FixedUnicode<1024>>()
                .map(|s| s.as_str().to_string())
        })
        .ok()?;
    Some(
        text.trim_matches(|c: char| c == '\0' || c.is_whitespace())
            .to_string(),
    )
}
