//! The filters of `imubake::smooth` against SciPy/NumPy outputs stored in
//! `tests/fixtures/filters/*.json` (written by `tests/python/make_filter_fixtures.py`; no Python
//! at test time).
//!
//! Tolerance: `|ours − scipy| ≤ 1e-9 · max(1, |scipy|)`, i.e. absolute for values of order one
//! and relative for larger ones. Rounding errors of sums and FFTs scale with the magnitude of the
//! values involved, so a fixed absolute bound would be needlessly loose for small series and too
//! strict for an angle track in degrees around 50. Filter coefficients are compared relatively
//! (`≤ 1e-9 · |scipy| + 1e-15`): the gain of a low-cutoff sixth-order design is about 1e-13, where
//! an absolute 1e-9 would compare nothing; the 1e-15 floor covers coefficients that are exactly 0
//! in one implementation and a rounding residue in the other. Each test prints the largest
//! difference it saw (`cargo test --test motion filters_scipy -- --nocapture`).

use imubake::smooth::butterworth::{
    FilterError, Sos, design_lowpass_sos, sosfilt, sosfilt_zi, sosfiltfilt, sosfiltfilt_padlen,
};
use imubake::smooth::fft::{DcBin, FftOptions, fft_filter, fft_filter_with_dc};
use imubake::smooth::gaussian::gaussian_filter1d;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

const TOL: f64 = 1e-9;

fn load(name: &str) -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/filters")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (run tests/python/make_filter_fixtures.py)",
            path.display()
        )
    });
    serde_json::from_str(&text).unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn signals(doc: &Value) -> BTreeMap<String, Vec<f64>> {
    doc["signals"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.clone(), floats(v)))
        .collect()
}

/// Largest `|a − b| / max(1, |b|)`; panics when it exceeds [`TOL`].
fn compare_series(ours: &[f64], scipy: &[f64], what: &str) -> f64 {
    assert_eq!(ours.len(), scipy.len(), "{what}: length");
    let mut worst = 0.0_f64;
    for (i, (a, b)) in ours.iter().zip(scipy).enumerate() {
        let d = (a - b).abs() / b.abs().max(1.0);
        assert!(
            d <= TOL,
            "{what}: sample {i}: ours {a:e}, scipy {b:e}, scaled diff {d:e}"
        );
        worst = worst.max(d);
    }
    worst
}

#[test]
fn butter_sos_matches_scipy() {
    let doc = load("butter_sos.json");
    let cases = doc["cases"].as_array().unwrap();
    assert!(cases.len() >= 60);
    let (mut worst_sos, mut worst_abs, mut worst_zi) = (0.0_f64, 0.0_f64, 0.0_f64);
    for case in cases {
        let order = case["order"].as_u64().unwrap() as usize;
        let cutoff = case["cutoff_hz"].as_f64().unwrap();
        let rate = case["rate_hz"].as_f64().unwrap();
        let what = format!("butter({order}, {cutoff}, fs={rate})");
        let expected: Vec<Vec<f64>> = case["sos"].as_array().unwrap().iter().map(floats).collect();
        let sos = design_lowpass_sos(order, cutoff, rate).unwrap();
        assert_eq!(sos.len(), expected.len(), "{what}: sections");
        // Coefficient by coefficient, section by section: the pairing is scipy's, not only the
        // cascade's response.
        for (s, (ours, theirs)) in sos.iter().zip(&expected).enumerate() {
            for (c, (a, b)) in ours.iter().zip(theirs).enumerate() {
                let d = (a - b).abs();
                assert!(
                    d <= TOL * b.abs() + 1e-15,
                    "{what}: sos[{s}][{c}]: ours {a:e}, scipy {b:e}"
                );
                worst_abs = worst_abs.max(d);
                if b.abs() > 1e-12 {
                    worst_sos = worst_sos.max(d / b.abs());
                }
            }
        }
        assert_eq!(
            sosfiltfilt_padlen(&sos),
            case["padlen"].as_u64().unwrap() as usize,
            "{what}: padlen"
        );
        let zi = sosfilt_zi(&sos).unwrap();
        let expected_zi: Vec<Vec<f64>> =
            case["zi"].as_array().unwrap().iter().map(floats).collect();
        for (ours, theirs) in zi.iter().zip(&expected_zi) {
            worst_zi = worst_zi.max(compare_series(ours, theirs, &format!("{what}: zi")));
        }
    }
    eprintln!(
        "butter sos: largest relative coefficient difference {worst_sos:e} (coefficients above \
         1e-12), largest absolute {worst_abs:e}"
    );
    eprintln!("sosfilt_zi: largest scaled difference {worst_zi:e}");
}

#[test]
fn sosfilt_and_sosfiltfilt_match_scipy() {
    let doc = load("sosfilt.json");
    let signals = signals(&doc);
    let (mut worst_filt, mut worst_filtfilt) = (0.0_f64, 0.0_f64);
    let (mut too_short, mut filtered) = (0, 0);
    for case in doc["cases"].as_array().unwrap() {
        let name = case["signal"].as_str().unwrap();
        let x = &signals[name];
        let order = case["order"].as_u64().unwrap() as usize;
        let cutoff = case["cutoff_hz"].as_f64().unwrap();
        let rate = case["rate_hz"].as_f64().unwrap();
        let what = format!(
            "{name} (n = {}), butter({order}, {cutoff}, fs={rate})",
            x.len()
        );
        let sos: Vec<Sos> = design_lowpass_sos(order, cutoff, rate).unwrap();

        let y = sosfilt(&sos, x);
        worst_filt = worst_filt.max(compare_series(
            &y,
            &floats(&case["sosfilt"]),
            &format!("sosfilt {what}"),
        ));

        match (sosfiltfilt(&sos, x), case.get("too_short")) {
            (Ok(y), None) => {
                filtered += 1;
                worst_filtfilt = worst_filtfilt.max(compare_series(
                    &y,
                    &floats(&case["sosfiltfilt"]),
                    &format!("sosfiltfilt {what}"),
                ));
            }
            (Err(FilterError::TooShort { needed, got }), Some(expected)) => {
                too_short += 1;
                assert_eq!(
                    needed as u64,
                    expected["needed"].as_u64().unwrap(),
                    "{what}"
                );
                assert_eq!(got as u64, expected["got"].as_u64().unwrap(), "{what}");
            }
            (ours, theirs) => panic!("{what}: ours {ours:?}, scipy {theirs:?}"),
        }
    }
    assert!(too_short >= 6 && filtered >= 20, "{too_short} {filtered}");
    eprintln!("sosfilt: largest scaled difference {worst_filt:e}");
    eprintln!("sosfiltfilt: largest scaled difference {worst_filtfilt:e}");
}

#[test]
fn gaussian_filter1d_matches_scipy() {
    let doc = load("gaussian.json");
    let signals = signals(&doc);
    let mut worst = 0.0_f64;
    let mut longer_than_series = 0;
    for case in doc["cases"].as_array().unwrap() {
        let name = case["signal"].as_str().unwrap();
        let x = &signals[name];
        let sigma = case["sigma"].as_f64().unwrap();
        let truncate = case["truncate"].as_f64().unwrap();
        if case["radius"].as_u64().unwrap() as usize >= x.len() {
            longer_than_series += 1;
        }
        let y = gaussian_filter1d(x, sigma, truncate);
        let what = format!(
            "gaussian_filter1d({name} (n = {}), {sigma}, truncate={truncate})",
            x.len()
        );
        worst = worst.max(compare_series(&y, &floats(&case["output"]), &what));
    }
    assert!(longer_than_series >= 8, "{longer_than_series}");
    eprintln!("gaussian_filter1d: largest scaled difference {worst:e}");
}

#[test]
fn fft_filter_matches_numpy() {
    let doc = load("fft.json");
    let signals = signals(&doc);
    let mut worst = 0.0_f64;
    let mut seen = BTreeMap::new();
    for case in doc["cases"].as_array().unwrap() {
        let name = case["signal"].as_str().unwrap();
        let x = &signals[name];
        let rate = case["rate_hz"].as_f64().unwrap();
        let options = FftOptions {
            threshold: case["threshold"].as_f64(),
            suppress: case["suppress"].as_f64().unwrap(),
            cutoff_hz: case["cutoff_hz"].as_f64(),
        };
        let dc = match case["dc"].as_str().unwrap() {
            "included" => DcBin::Included,
            "excluded" => DcBin::Excluded,
            other => panic!("dc {other}"),
        };
        *seen.entry(format!("{dc:?}")).or_insert(0) += 1;
        let y = fft_filter_with_dc(x, rate, &options, dc);
        if dc == DcBin::Excluded {
            assert_eq!(y, fft_filter(x, rate, &options), "fft_filter excludes DC");
        }
        let what = format!(
            "fft_filter({name} (n = {}), {rate} Hz, {options:?}, {dc:?})",
            x.len()
        );
        worst = worst.max(compare_series(&y, &floats(&case["output"]), &what));
    }
    assert_eq!(seen.len(), 2, "{seen:?}");
    eprintln!("fft_filter: largest scaled difference {worst:e}");
}
