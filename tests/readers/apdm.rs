//! APDM Opal `.h5` (the cargo feature `hdf5`): files written by h5py from known values
//! (`tests/python/make_apdm.py`) read back exactly; wrong shapes and lengths are errors naming
//! the dataset; a file that is not HDF5 is refused by its signature; a take converts; and
//! property tests write mutated files with libhdf5 (values, shapes, attributes) that the reader
//! must answer without a panic.
#![cfg(feature = "hdf5")]

use crate::common;

use common::{convert_with_mapping, python, repo_file, run};
use hdf5_metno as hdf5;
use imubake::read::{InputFormat, ReadOptions, read_take};
use imubake::take::OrientationTrack;
use nalgebra::{Quaternion, UnitQuaternion};
use proptest::prelude::*;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

fn fixtures(py: &Path) -> (tempfile::TempDir, Value) {
    let dir = tempfile::tempdir().unwrap();
    run(Command::new(py)
        .arg(repo_file("tests/python/make_apdm.py"))
        .arg(dir.path()));
    let expected =
        serde_json::from_slice(&std::fs::read(dir.path().join("expected.json")).unwrap()).unwrap();
    (dir, expected)
}

/// Every sensor under its label (a NUL-padded fixed string, a variable-length one, none: the
/// group's name), every sample's time (µs → s from the first), readings in SI units and APDM's
/// orientation, w first, as h5py wrote them.
#[test]
fn an_opal_file_reads_as_written() {
    let Some(py) = python() else { return };
    let (dir, expected) = fixtures(&py);
    let take = read_take(&dir.path().join("opal.h5"), &ReadOptions::default()).unwrap();
    assert_eq!(take.source().format, InputFormat::ApdmH5);
    assert_eq!(take.source().world.name(), "nwu");
    let mut ids: Vec<&str> = take.sensors().iter().map(|s| s.id()).collect();
    ids.sort();
    assert_eq!(ids, ["999", "left_shank", "left_thigh"]);
    let mut worst: f64 = 0.0;
    for id in ids {
        let e = &expected[id];
        let sensor = take.sensor(id).unwrap();
        let inertial = sensor.inertial().unwrap();
        let times = e["t"].as_array().unwrap();
        assert_eq!(inertial.len(), times.len(), "{id}");
        for (n, (t, s)) in inertial.iter().enumerate() {
            assert!(
                (t - times[n].as_f64().unwrap()).abs() < 1e-9,
                "{id} {n}: {t}"
            );
            worst = worst
                .max((s.accel_m_s2 - common::vec3(&e["acc"][n])).norm())
                .max((s.gyro_rad_s - common::vec3(&e["gyro"][n])).norm());
        }
        let mag = sensor.magnetometer().unwrap();
        for (n, (_, m)) in mag.iter().enumerate() {
            worst = worst.max((m - common::vec3(&e["mag"][n])).norm());
        }
        match (sensor.orientation(), e["q"].as_array()) {
            (Some(OrientationTrack::Quaternion(track)), Some(qs)) => {
                for ((_, q), r) in track.iter().zip(qs) {
                    let r: Vec<f64> = r
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|v| v.as_f64().unwrap())
                        .collect();
                    let r =
                        UnitQuaternion::from_quaternion(Quaternion::new(r[0], r[1], r[2], r[3]));
                    worst = worst.max(q.angle_to(&r));
                }
            }
            (None, None) => {}
            (o, q) => panic!("{id}: orientation {o:?} against {q:?}"),
        }
    }
    eprintln!("worst difference {worst:.2e}");
    assert!(worst < 1e-12, "{worst}");
}

/// A dataset of the wrong shape, or of another length than `Time`, is an error naming it; a file
/// that is not HDF5 is refused before libhdf5 opens it.
#[test]
fn bad_files_say_what_is_wrong() {
    let Some(py) = python() else { return };
    let (dir, _) = fixtures(&py);
    let error = |name: &str| {
        read_take(
            &dir.path().join(name),
            &ReadOptions {
                format: Some(InputFormat::ApdmH5),
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string()
    };
    let e = error("bad_shape.h5");
    assert!(
        e.contains("/Sensors/XI-1/Gyroscope") && e.contains("[256, 2]"),
        "{e}"
    );
    let e = error("short.h5");
    assert!(e.contains("Magnetometer has 255 samples, Time 256"), "{e}");
    std::fs::write(dir.path().join("fake.h5"), b"not hdf5 at all").unwrap();
    let e = error("fake.h5");
    assert!(e.contains("not an HDF5 file"), "{e}");
}

/// A take of APDM readings (and APDM's orientation for the thigh) converts onto mixamo. One leg
/// of a synthetic fixture gives no sure heading (issue 47): the sensors' north is kept.
#[test]
fn an_opal_take_converts() {
    let Some(py) = python() else { return };
    let (dir, _) = fixtures(&py);
    let sidecar = convert_with_mapping(
        &dir.path().join("opal.h5"),
        r#"{"rig": "mixamo", "world": "nwu", "heading": "sensors", "sensors": {
            "left_thigh": {"bone": "LeftUpLeg", "mount": "calibrate"},
            "left_shank": {"bone": "LeftLeg", "mount": "calibrate"}}}"#,
        dir.path(),
    );
    assert_eq!(sidecar["source"]["format"], "apdm-h5");
    let sensors = sidecar["mapping"]["sensors"].as_array().unwrap();
    let origin = |id: &str| {
        sensors
            .iter()
            .find(|s| s["sensor"] == id)
            .map(|s| s["orientation"].clone())
            .unwrap()
    };
    assert_eq!(origin("left_thigh"), "device");
    assert_eq!(origin("left_shank"), "fused");
}

/// One sensor group with datasets of the given shapes and values, and a label attribute.
fn write_file(
    path: &Path,
    rows: usize,
    cols: [usize; 4],
    value: f64,
    label: &[u8],
) -> hdf5::Result<()> {
    let f = hdf5::File::create(path)?;
    let g = f.create_group("Sensors")?.create_group("XI-7")?;
    let time: Vec<u64> = (0..rows as u64).map(|k| 1_000_000 + k * 7812).collect();
    g.new_dataset_builder().with_data(&time).create("Time")?;
    for (name, c) in ["Accelerometer", "Gyroscope", "Magnetometer"]
        .iter()
        .zip(cols)
    {
        g.new_dataset::<f64>()
            .shape((rows, c))
            .create(*name)?
            .write_raw(&vec![value; rows * c])?;
    }
    f.create_group("Processed")?
        .create_group("XI-7")?
        .new_dataset::<f64>()
        .shape((rows, cols[3]))
        .create("Orientation")?
        .write_raw(&vec![value; rows * cols[3]])?;
    let c = g.create_group("Configuration")?;
    let text =
        hdf5::types::VarLenUnicode::from_str(&String::from_utf8_lossy(label)).unwrap_or_default();
    c.new_attr::<hdf5::types::VarLenUnicode>()
        .create("Label 0")?
        .write_scalar(&text)?;
    Ok(())
}

use std::str::FromStr;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(60))]

    /// Mutated datasets (shapes, values — NaN, infinities, huge), labels (any bytes): a take or
    /// an error, never a panic; a take's tracks keep their invariants.
    #[test]
    fn mutated_opal_files_never_panic(
        rows in 0usize..40,
        cols in proptest::array::uniform4(0usize..6),
        value in prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(1e300), -10.0f64..10.0],
        label in proptest::collection::vec(any::<u8>(), 0..40),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.h5");
        if write_file(&path, rows, cols, value, &label).is_ok()
            && let Ok(take) = read_take(&path, &ReadOptions::default())
        {
            for s in take.sensors() {
                let times = s.primary_times_s();
                prop_assert!(times.windows(2).all(|w| w[0] < w[1]));
            }
        }
        // The same bytes, damaged: a file cut short, and bytes flipped after the signature.
        let bytes = std::fs::read(&path).unwrap_or_default();
        if bytes.len() > 16 {
            std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
            let _ = read_take(&path, &ReadOptions::default());
        }
    }
}
