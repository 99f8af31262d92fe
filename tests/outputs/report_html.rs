//! The `convert --report` HTML report (src/report.rs), read back as a browser and a person would:
//! tests/python/check_report.py parses the document (html.parser, every <svg> with ElementTree)
//! and maps the drawn curves back to data units, so these tests check that the charts show the
//! data, that text is escaped, and that a 60-minute take stays small.

use crate::common;

use imubake::inspect::{SensorSummaries, SensorSummary};
use imubake::rotation::EulerOrder;
use imubake::write::report::{
    AFTER_STROKE, AXIS_COLOURS, BEFORE_STROKE, BoneSeries, PLOT_WIDTH_PX, ReportInput,
    decimate_min_max, render_report,
};
use serde_json::{Value, json};
use std::f64::consts::TAU;
use std::path::Path;
use std::process::Command;

/// check_report.py's description of the report at `path` (see its docstring).
fn check_report(py: &Path, path: &Path, spec: &Value) -> Value {
    let out = Command::new(py)
        .arg(common::repo_file("tests/python/check_report.py"))
        .arg(path)
        .arg(spec.to_string())
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", py.display()));
    assert!(
        out.status.success(),
        "check_report.py failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("check_report.py prints JSON")
}

/// A deterministic noise in [-1, 1).
fn noise(i: usize, salt: u64) -> f64 {
    let mut x = (i as u64 ^ salt.wrapping_mul(0x9E37_79B9_7F4A_7C15)).wrapping_add(0x2545_F491);
    x ^= x >> 33;
    x = x.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    x ^= x >> 33;
    (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

fn times(frames: usize, fps: f64) -> Vec<f64> {
    (0..frames).map(|i| i as f64 / fps).collect()
}

/// The stroke (colour, width, opacity) of a curve of `axis` (0 = x) before or after smoothing.
fn stroke(axis: usize, after: bool) -> (&'static str, f64, f64) {
    let (w, a) = if after { AFTER_STROKE } else { BEFORE_STROKE };
    (AXIS_COLOURS[axis], w as f64, a)
}

/// The curve of a chart drawn with `stroke`.
fn curve<'a>(chart: &'a Value, stroke: (&str, f64, f64)) -> &'a Value {
    let found: Vec<&Value> = chart["curves"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| {
            c["stroke"] == stroke.0
                && c["width"].as_f64() == Some(stroke.1)
                && c["opacity"].as_f64() == Some(stroke.2)
        })
        .collect();
    assert_eq!(found.len(), 1, "one curve {stroke:?} in {}", chart["bone"]);
    found[0]
}

fn sensors() -> SensorSummaries {
    let regular = |n: usize, dt: f64| (0..n).map(|i| i as f64 * dt).collect::<Vec<f64>>();
    let mut gappy = regular(500, 0.01);
    gappy.extend((0..200).map(|i| 5.8 + i as f64 * 0.01)); // a 0.81 s gap
    SensorSummaries(vec![
        (
            "pelvis".into(),
            SensorSummary::from_times(&regular(6000, 0.01)),
        ),
        ("thigh_l".into(), SensorSummary::from_times(&gappy)),
        ("s<3>&\"x\"".into(), SensorSummary::from_times(&[1.0])),
        (
            "shank_r".into(),
            SensorSummary::from_times(&regular(3000, 0.02)),
        ),
    ])
}

const SINE: (f64, f64, f64, f64) = (30.0, 0.25, 0.3, 5.0); // amplitude °, Hz, phase rad, offset °

#[test]
fn report_shows_the_data_and_escapes_text() {
    let Some(py) = common::python() else { return };
    // 60 s at 60 fps: 3600 frames, more than two per pixel column, so the curves are decimated.
    let t = times(3600, 60.0);
    let (amp, freq, phase, offset) = SINE;
    let sine: Vec<[f64; 3]> = t
        .iter()
        .map(|&t| {
            let a = TAU * freq * t + phase;
            [offset + amp * a.sin(), 10.0 * a.cos(), -20.0]
        })
        .collect();
    let noisy: Vec<[f64; 3]> = sine
        .iter()
        .enumerate()
        .map(|(i, a)| [a[0] + 8.0 * noise(i, 1), a[1] + 3.0 * noise(i, 2), a[2]])
        .collect();
    let walk: Vec<[f64; 3]> = t
        .iter()
        .map(|&t| [40.0 * (0.1 * t).sin(), -60.0 + t, 15.0 * (0.7 * t).cos()])
        .collect();
    let mut spiky = walk.clone();
    spiky[1234][1] = 170.0;
    let bones = vec![
        BoneSeries {
            bone: "Sine".into(),
            order: EulerOrder::ZYX,
            times_s: t.clone(),
            before_deg: noisy,
            after_deg: sine,
        },
        BoneSeries {
            bone: "Left<Arm> & \"Hand\" 'x'".into(),
            order: EulerOrder::XZY,
            times_s: t.clone(),
            before_deg: spiky,
            after_deg: walk,
        },
    ];
    let sensors = sensors();
    let warnings = vec![
        "sensor `<script>&\"` is in the data but not in the mapping".to_string(),
        "no calibration window: mounts solved from the first second, assumed rest pose".to_string(),
        "a 'quoted' & <b>bold</b> </li></ul> warning".to_string(),
    ];
    let input = ReportInput {
        take: "walk <take> & co",
        source: "/data/\"quoted\"/walk&run<1>.csv",
        fps: "60".into(),
        smoothing: "butterworth order 4, cutoff 6 Hz".into(),
        bones,
        sensors: &sensors,
        warnings: &warnings,
        dropped_lines: 7,
        fusion: Vec::new(),
    };
    let html = render_report(&input);
    assert_eq!(html, render_report(&input), "deterministic");
    assert!(
        html.contains("&lt;script&gt;&amp;&quot;"),
        "escaped warning"
    );
    assert!(!html.contains("<script"), "no script tag");
    assert!(!html.contains("<b>"), "no markup from warnings");

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("walk.report.html");
    std::fs::write(&path, &html).unwrap();
    let spec = json!({"sine": {"bone": "Sine", "amp": amp, "freq": freq, "phase": phase,
        "offset": offset}});
    let r = check_report(&py, &path, &spec);

    assert_eq!(r["doctype"], json!(["DOCTYPE html"]));
    assert_eq!(r["title"], "imubake report: walk <take> & co");
    for tag in ["script", "img", "link", "iframe", "object", "embed", "b"] {
        assert!(
            r["start_tags"].get(tag).is_none(),
            "a <{tag}>: {}",
            r["start_tags"]
        );
    }
    assert_eq!(r["external"], json!([]));
    assert_eq!(r["header"]["Take"], "walk <take> & co");
    assert_eq!(r["header"]["Source"], "/data/\"quoted\"/walk&run<1>.csv");
    assert_eq!(r["header"]["Frame rate"], "60");
    assert_eq!(r["header"]["Smoothing"], "butterworth order 4, cutoff 6 Hz");
    assert_eq!(r["warnings"], json!(warnings), "every warning, as text");
    assert!(r["dropped"].as_array().unwrap().iter().all(|d| d == "7"));
    assert!(!r["dropped"].as_array().unwrap().is_empty());

    // One table row per sensor.
    let rows = r["sensor_rows"].as_array().unwrap();
    assert_eq!(rows.len(), sensors.0.len());
    for (row, (id, s)) in rows.iter().zip(&sensors.0) {
        assert_eq!(row[0], id.as_str());
        assert_eq!(row[1], s.samples.to_string().as_str());
    }
    assert_eq!(rows[0][2], "10.00"); // mean interval, ms
    assert_eq!(rows[1][7], "1 (longest 0.810 s)");
    assert_eq!(rows[2][2], "–"); // one sample: no interval

    // One chart per bone, named and labelled with the axis letters of its order.
    let charts = r["charts"].as_array().unwrap();
    assert_eq!(charts.len(), input.bones.len());
    for (chart, bone) in charts.iter().zip(&input.bones) {
        assert_eq!(chart["bone"], bone.bone.as_str());
        assert_eq!(chart["order"], bone.order.name());
        assert_eq!(chart["svg_count"], 1);
        assert_eq!(chart["curves"].as_array().unwrap().len(), 6);
        assert_eq!(chart["legend_lines"].as_array().unwrap().len(), 6);
        let texts = common::strings(&chart["texts"]);
        for letter in bone.order.name().chars() {
            for what in ["before", "after"] {
                assert!(
                    texts.contains(&format!("{letter} {what}").as_str()),
                    "{texts:?}"
                );
            }
        }
        for axis in bone.order.axes() {
            for after in [false, true] {
                let c = curve(chart, stroke(axis, after));
                let n = c["points"].as_u64().unwrap();
                assert!(n > 100 && n <= 2 * PLOT_WIDTH_PX as u64, "{n} points");
                assert!(c["t_min"].as_f64().unwrap().abs() < 0.1);
                assert!((c["t_max"].as_f64().unwrap() - 3599.0 / 60.0).abs() < 0.2);
            }
        }
    }

    // The Sine bone's Z channel (its first, ZYX) after smoothing is the sine, point for point.
    let z_after = curve(&charts[0], stroke(2, true));
    let corr = z_after["sine_corr"].as_f64().unwrap();
    let rms = z_after["sine_rms"].as_f64().unwrap();
    assert!(corr > 0.99, "correlation {corr}");
    assert!(rms < 1.0, "RMS {rms}°");
    assert!((z_after["v_max"].as_f64().unwrap() - (offset + amp)).abs() < 1.0);
    assert!((z_after["v_min"].as_f64().unwrap() - (offset - amp)).abs() < 1.0);
    // The other curves are not that sine.
    for axis in [0, 1] {
        let c = curve(&charts[0], stroke(axis, true));
        assert!(c["sine_corr"].as_f64().unwrap().abs() < 0.9, "{c}");
    }
    // Before smoothing it is noisy: further from the sine than after.
    let z_before = curve(&charts[0], stroke(2, false));
    assert!(
        z_before["sine_rms"].as_f64().unwrap() > 2.0 * rms,
        "{z_before}"
    );
    assert!(z_before["v_max"].as_f64().unwrap() > offset + amp + 4.0);

    // The second bone's single-frame spike (its Z channel, second in XZY) is drawn before
    // smoothing and not after.
    let z_before = curve(&charts[1], stroke(2, false));
    let z_after = curve(&charts[1], stroke(2, true));
    let v_max = z_before["v_max"].as_f64().unwrap();
    assert!((v_max - 170.0).abs() < 1.5, "spike drawn to {v_max}°");
    assert!(z_after["v_max"].as_f64().unwrap() < 10.0);
}

#[test]
fn decimation_bounds_points_and_keeps_a_spike() {
    let t = times(216_000, 60.0);
    let mut v: Vec<f64> = t.iter().map(|t| 20.0 * (0.3 * t).sin()).collect();
    v[98_765] = 123.0;
    v[98_766] = 0.0;
    let d = decimate_min_max(&t, &v, PLOT_WIDTH_PX as usize);
    assert!(
        d.len() <= 2000 && d.len() <= 2 * PLOT_WIDTH_PX as usize,
        "{}",
        d.len()
    );
    assert!(d.len() > PLOT_WIDTH_PX as usize);
    assert!(d.contains(&(t[98_765], 123.0)), "the spike is kept");
    assert!(d.windows(2).all(|w| w[0].0 < w[1].0), "time order");
    // Every kept point is a sample.
    assert!(d.iter().all(|&(tt, vv)| {
        let i = (tt * 60.0).round() as usize;
        t[i] == tt && v[i] == vv
    }));
}

/// A 60-minute, 22-bone take at 60 fps: the report stays small, every curve is decimated to at
/// most two points per pixel column, and a single-frame spike is still drawn.
#[test]
fn long_take_stays_small() {
    let Some(py) = common::python() else { return };
    let frames = 216_000;
    let t = times(frames, 60.0);
    let bones: Vec<BoneSeries> = (0..22)
        .map(|b| {
            let after: Vec<[f64; 3]> = t
                .iter()
                .map(|&t| {
                    let f = 0.05 + 0.01 * b as f64;
                    [
                        40.0 * (TAU * f * t).sin(),
                        -30.0 + 20.0 * (TAU * 0.3 * f * t).cos(),
                        10.0 * (TAU * 2.0 * f * t).sin(),
                    ]
                })
                .collect();
            let mut before: Vec<[f64; 3]> = after
                .iter()
                .enumerate()
                .map(|(i, a)| {
                    [
                        a[0] + 5.0 * noise(i, 3 * b),
                        a[1] + 5.0 * noise(i, 3 * b + 1),
                        a[2] + 5.0 * noise(i, 3 * b + 2),
                    ]
                })
                .collect();
            if b == 7 {
                before[150_001][0] = 175.0;
            }
            BoneSeries {
                bone: format!("mixamorig:Bone{b:02}"),
                order: EulerOrder::ZYX,
                times_s: t.clone(),
                before_deg: before,
                after_deg: after,
            }
        })
        .collect();
    let sensors = sensors();
    let warnings = vec!["a warning".to_string()];
    let input = ReportInput {
        take: "long",
        source: "long.csv",
        fps: "60".into(),
        smoothing: "butterworth order 4, cutoff 6 Hz".into(),
        bones,
        sensors: &sensors,
        warnings: &warnings,
        dropped_lines: 0,
        fusion: Vec::new(),
    };
    let html = render_report(&input);
    eprintln!("60-minute 22-bone report: {} bytes", html.len());
    assert!(html.len() < 3_000_000, "{} bytes", html.len());

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long.report.html");
    std::fs::write(&path, &html).unwrap();
    let r = check_report(&py, &path, &json!({}));
    let charts = r["charts"].as_array().unwrap();
    assert_eq!(charts.len(), 22);
    for chart in charts {
        let curves = chart["curves"].as_array().unwrap();
        assert_eq!(curves.len(), 6);
        for c in curves {
            let n = c["points"].as_u64().unwrap();
            assert!(n <= 2 * PLOT_WIDTH_PX as u64 && n <= 2000, "{n} points");
            assert!(n > PLOT_WIDTH_PX as u64, "{n} points");
        }
    }
    let spiky = &charts[7];
    assert_eq!(spiky["bone"], "mixamorig:Bone07");
    let v_max = curve(spiky, stroke(2, false))["v_max"].as_f64().unwrap();
    assert!((v_max - 175.0).abs() < 1.5, "spike drawn to {v_max}°");
    let v_max = curve(spiky, stroke(2, true))["v_max"].as_f64().unwrap();
    assert!(v_max < 41.0, "after smoothing: {v_max}°");
}
