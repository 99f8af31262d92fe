//! Two angle tables compared as paper 000 compared its IMU system with optical capture: the two
//! synchronised, optionally the mean offset removed, then RMSE and Pearson's r per angle.
//!
//! # Synchronising
//! The lag `L` (seconds) pairs `a(t)` with `b(t + L)`: an event at time `t` in `a` happens at
//! `t + L` in `b`.
//! - `xcorr` (the default): both series of the sync angle linearly resampled onto a grid at
//!   `a`'s median sample period `Δ`; `L = kΔ` maximises Pearson's r over the overlap, among
//!   `|L| ≤ max_lag` with an overlap of at least half the shorter series; refined by a parabola
//!   through the r of `k − 1, k, k + 1`.
//! - `spike`: `L = t_b − t_a`, each the time of the steepest change of the sync angle (the
//!   largest `|Δangle / Δt|` between neighbouring samples) — paper 000's clap, which spikes the
//!   elbow and shoulder angles.
//! - `none`: `L = 0`.
//!
//! The sync angle is the one named, else the angle in both tables with the largest variance in
//! `a`.
//!
//! # Statistics
//! At each time `t` of `a` with `t + L` inside `b`, `b(t + L)` by linear interpolation (each
//! series unwrapped first, so a signed angle crossing ±180° interpolates the short way); pairs
//! with a NaN are left out. With `d = b − a` wrapped into (−180°, 180°]: `offset = mean d`,
//! `RMSE = √(mean (d − offset)²)` when the offset is removed (as the paper did), else
//! `√(mean d²)`; `r = Σ(a−ā)(b−b̄) / √(Σ(a−ā)² Σ(b−b̄)²)` (undefined for a constant series).

use super::{AnalysisError, AngleTable};

/// How to synchronise the two tables.
#[derive(Debug, Clone, PartialEq)]
pub enum Sync {
    None,
    CrossCorrelation,
    Spike,
}

impl std::str::FromStr for Sync {
    type Err = String;
    fn from_str(s: &str) -> Result<Sync, String> {
        match s {
            "none" => Ok(Sync::None),
            "xcorr" => Ok(Sync::CrossCorrelation),
            "spike" => Ok(Sync::Spike),
            _ => Err(format!("unknown `{s}`; expected xcorr, spike or none")),
        }
    }
}

impl Sync {
    pub fn label(&self) -> &'static str {
        match self {
            Sync::None => "none",
            Sync::CrossCorrelation => "xcorr",
            Sync::Spike => "spike",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct CompareOptions {
    pub sync: Sync,
    /// The angle to synchronise on; `None`: the one varying most in `a`.
    pub sync_angle: Option<String>,
    /// The largest lag `xcorr` considers, seconds.
    pub max_lag_s: f64,
    /// Remove the mean offset `b − a` before the RMSE.
    pub remove_offset: bool,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            sync: Sync::CrossCorrelation,
            sync_angle: None,
            max_lag_s: 10.0,
            remove_offset: false,
        }
    }
}

/// One angle's statistics.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AngleStats {
    pub angle: String,
    /// Pairs compared.
    pub n: usize,
    pub rmse_deg: f64,
    /// Pearson's r; `None` when either series is constant over the pairs.
    pub r: Option<f64>,
    /// Mean of `b − a`, degrees (removed from the RMSE when asked).
    pub offset_deg: f64,
}

/// The result: the lag found and each common angle's statistics, in `a`'s order.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Comparison {
    pub sync: &'static str,
    pub sync_angle: Option<String>,
    /// `b(t + lag_s)` pairs with `a(t)`.
    pub lag_s: f64,
    /// Pearson's r of the sync angle at the lag (cross-correlation).
    pub sync_r: Option<f64>,
    pub offset_removed: bool,
    pub angles: Vec<AngleStats>,
}

/// A series unwrapped: a step of more than 180° between neighbours is taken the short way.
fn unwrap(values: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(values.len());
    let mut shift = 0.0;
    let mut last: Option<f64> = None;
    for &v in values {
        if v.is_finite() {
            if let Some(prev) = last {
                let step = v + shift - prev;
                shift -= 360.0 * (step / 360.0).round();
            }
            last = Some(v + shift);
            out.push(v + shift);
        } else {
            out.push(f64::NAN);
        }
    }
    out
}

/// `values` (at `times`) at time `t` by linear interpolation; `None` outside.
fn sample(times: &[f64], values: &[f64], t: f64) -> Option<f64> {
    let (first, last) = (times[0], times[times.len() - 1]);
    if !(first..=last).contains(&t) {
        return None;
    }
    let i = times.partition_point(|&x| x <= t);
    if i == 0 || i >= times.len() {
        // t is the last time (or the only one).
        return Some(values[times.len() - 1]).filter(|v| v.is_finite());
    }
    let (t0, t1) = (times[i - 1], times[i]);
    let w = (t - t0) / (t1 - t0);
    let v = values[i - 1] + w * (values[i] - values[i - 1]);
    v.is_finite().then_some(v)
}

/// Pearson's r of paired values; `None` for fewer than 2 pairs or a constant series.
pub fn pearson(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len().min(b.len());
    if n < 2 {
        return None;
    }
    let ma = a[..n].iter().sum::<f64>() / n as f64;
    let mb = b[..n].iter().sum::<f64>() / n as f64;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a[..n].iter().zip(&b[..n]) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    let denom = (saa * sbb).sqrt();
    (denom > 1e-12 * (1.0 + saa.max(sbb))).then(|| (sab / denom).clamp(-1.0, 1.0))
}

fn median_period(times: &[f64]) -> Option<f64> {
    let mut d: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    Some(d[d.len() / 2])
}

/// The series on the grid `t0 + iΔ`, `i = 0 ..`, over its span (NaN where it has none).
fn on_grid(times: &[f64], values: &[f64], t0: f64, dt: f64) -> Vec<f64> {
    let n = ((times[times.len() - 1] - t0) / dt).floor() as usize + 1;
    (0..n)
        .map(|i| sample(times, values, t0 + i as f64 * dt).unwrap_or(f64::NAN))
        .collect()
}

/// Pearson's r of `a[i]` with `b[i + k]` over the pairs where both are finite; with the count.
fn r_at_lag(a: &[f64], b: &[f64], k: i64) -> (Option<f64>, usize) {
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    for (i, &x) in a.iter().enumerate() {
        let j = i as i64 + k;
        if j < 0 || j as usize >= b.len() {
            continue;
        }
        let y = b[j as usize];
        if x.is_finite() && y.is_finite() {
            xs.push(x);
            ys.push(y);
        }
    }
    (pearson(&xs, &ys), xs.len())
}

fn cross_correlation(
    ta: &[f64],
    a: &[f64],
    tb: &[f64],
    b: &[f64],
    max_lag_s: f64,
) -> Result<(f64, f64), AnalysisError> {
    let dt = median_period(ta)
        .or_else(|| median_period(tb))
        .ok_or_else(|| AnalysisError::Sync("both tables have a single row".into()))?;
    // Both on grids with the same period, b's starting at a's t0 + m·Δ: then lag k·Δ pairs
    // ga[i] with gb[i + k − m].
    let t0 = ta[0];
    let m = ((tb[0] - t0) / dt).ceil() as i64;
    let ga = on_grid(ta, a, t0, dt);
    let gb = on_grid(tb, b, t0 + m as f64 * dt, dt);
    let shorter = ga.len().min(gb.len());
    let need = (shorter / 2).max(3);
    let k_max = (max_lag_s / dt).floor() as i64;
    let mut best: Option<(i64, f64)> = None;
    let mut rs = std::collections::HashMap::new();
    for k in -k_max..=k_max {
        let (r, n) = r_at_lag(&ga, &gb, k - m);
        if let (Some(r), true) = (r, n >= need) {
            rs.insert(k, r);
            if best.is_none_or(|(_, b)| r > b) {
                best = Some((k, r));
            }
        }
    }
    let (k, r) = best.ok_or_else(|| {
        AnalysisError::Sync(format!(
            "no lag within ±{max_lag_s} s overlaps half of the shorter series with a varying sync angle"
        ))
    })?;
    let delta = match (rs.get(&(k - 1)), rs.get(&(k + 1))) {
        (Some(&r0), Some(&r2)) => {
            let curvature = r0 - 2.0 * r + r2;
            if curvature < 0.0 {
                (0.5 * (r0 - r2) / curvature).clamp(-0.5, 0.5)
            } else {
                0.0
            }
        }
        _ => 0.0,
    };
    Ok(((k as f64 + delta) * dt, r))
}

/// The time of the steepest change.
fn spike_time(times: &[f64], values: &[f64]) -> Option<f64> {
    let mut best: Option<(f64, f64)> = None;
    for i in 1..times.len() {
        let (v0, v1) = (values[i - 1], values[i]);
        if !(v0.is_finite() && v1.is_finite()) {
            continue;
        }
        let rate = ((v1 - v0) / (times[i] - times[i - 1])).abs();
        if best.is_none_or(|(_, r)| rate > r) {
            best = Some((0.5 * (times[i - 1] + times[i]), rate));
        }
    }
    best.map(|(t, _)| t)
}

fn variance(values: &[f64]) -> f64 {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.len() < 2 {
        return 0.0;
    }
    let mean = finite.iter().sum::<f64>() / finite.len() as f64;
    finite.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / finite.len() as f64
}

/// Compares `b` with `a` (module docs).
pub fn compare(
    a: &AngleTable,
    b: &AngleTable,
    options: &CompareOptions,
) -> Result<Comparison, AnalysisError> {
    let common: Vec<&String> = a.names().iter().filter(|n| b.column(n).is_some()).collect();
    if common.is_empty() {
        return Err(AnalysisError::NothingInCommon {
            a: a.names().join(", "),
            b: b.names().join(", "),
        });
    }
    let series = |t: &AngleTable, n: &str| unwrap(t.column(n).expect("a common angle"));
    let sync_angle = match (&options.sync, &options.sync_angle) {
        (Sync::None, _) => None,
        (_, Some(n)) => {
            if !common.contains(&n) {
                return Err(AnalysisError::UnknownAngle(n.clone()));
            }
            Some(n.clone())
        }
        (_, None) => common
            .iter()
            .map(|n| (n, variance(&series(a, n))))
            .max_by(|x, y| x.1.total_cmp(&y.1))
            .map(|(n, _)| (*n).clone()),
    };
    let (lag_s, sync_r) = match (&options.sync, &sync_angle) {
        (Sync::CrossCorrelation, Some(n)) => {
            let (lag, r) = cross_correlation(
                a.time_s(),
                &series(a, n),
                b.time_s(),
                &series(b, n),
                options.max_lag_s,
            )?;
            (lag, Some(r))
        }
        (Sync::Spike, Some(n)) => {
            let ta = spike_time(a.time_s(), &series(a, n));
            let tb = spike_time(b.time_s(), &series(b, n));
            match ta.zip(tb) {
                Some((ta, tb)) => (tb - ta, None),
                None => {
                    return Err(AnalysisError::Sync(format!(
                        "`{n}`: too few values to find a spike"
                    )));
                }
            }
        }
        _ => (0.0, None),
    };
    let mut angles = Vec::new();
    for n in common {
        let (va, vb) = (series(a, n), series(b, n));
        let (mut xs, mut ys) = (Vec::new(), Vec::new());
        for (t, x) in a.time_s().iter().zip(&va) {
            if let (true, Some(y)) = (x.is_finite(), sample(b.time_s(), &vb, t + lag_s)) {
                xs.push(*x);
                ys.push(y);
            }
        }
        let diffs: Vec<f64> = xs
            .iter()
            .zip(&ys)
            .map(|(x, y)| (y - x) - 360.0 * ((y - x) / 360.0).round())
            .collect();
        let count = diffs.len().max(1) as f64;
        let offset = diffs.iter().sum::<f64>() / count;
        let removed = if options.remove_offset { offset } else { 0.0 };
        let rmse = (diffs.iter().map(|d| (d - removed).powi(2)).sum::<f64>() / count).sqrt();
        angles.push(AngleStats {
            angle: n.clone(),
            n: diffs.len(),
            rmse_deg: if diffs.is_empty() { f64::NAN } else { rmse },
            r: pearson(&xs, &ys),
            offset_deg: offset,
        });
    }
    Ok(Comparison {
        sync: options.sync.label(),
        sync_angle,
        lag_s,
        sync_r,
        offset_removed: options.remove_offset,
        angles,
    })
}

impl Comparison {
    /// The statistics in the layout of paper 000's Table 1: a row per joint and quantity, RMSE
    /// and r for the left and the right side; other angles after, a row each.
    pub fn table(&self) -> String {
        use super::angles::{COMPONENTS, JOINTS};
        use std::fmt::Write as _;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "sync: {}{}; lag: b at a + {:.4} s{}{}",
            self.sync,
            self.sync_angle
                .as_ref()
                .map(|n| format!(" on {n}"))
                .unwrap_or_default(),
            self.lag_s,
            self.sync_r
                .map(|r| format!(" (r = {r:.4})"))
                .unwrap_or_default(),
            if self.offset_removed {
                "; mean offset removed"
            } else {
                ""
            }
        );
        let find = |name: &str| self.angles.iter().find(|s| s.angle == name);
        let cell = |s: Option<&AngleStats>| match s {
            Some(s) => format!(
                "{:>9.2} {:>7}",
                s.rmse_deg,
                s.r.map_or("–".to_string(), |r| format!("{r:.3}"))
            ),
            None => format!("{:>9} {:>7}", "", ""),
        };
        let _ = writeln!(
            out,
            "{:<20} {:>9} {:>7} {:>9} {:>7}",
            "joint", "left RMSE", "left r", "right RMSE", "right r"
        );
        let mut shown = std::collections::HashSet::new();
        for joint in JOINTS {
            for quantity in std::iter::once("").chain(COMPONENTS) {
                let suffix = if quantity.is_empty() {
                    String::new()
                } else {
                    format!("_{quantity}")
                };
                let left = find(&format!("left_{joint}{suffix}"));
                let right = find(&format!("right_{joint}{suffix}"));
                if left.is_none() && right.is_none() {
                    continue;
                }
                shown.extend(left.iter().chain(right.iter()).map(|s| s.angle.clone()));
                let label = if quantity.is_empty() {
                    format!("{joint} (γ)")
                } else {
                    format!("{joint} {quantity}")
                };
                let _ = writeln!(out, "{label:<20} {} {}", cell(left), cell(right));
            }
        }
        for s in self.angles.iter().filter(|s| !shown.contains(&s.angle)) {
            let _ = writeln!(out, "{:<20} {}", s.angle, cell(Some(s)));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(times: Vec<f64>, name: &str, values: Vec<f64>) -> AngleTable {
        AngleTable::new(vec![name.into()], times, vec![values]).unwrap()
    }

    /// A 0.5 Hz sine sampled at 60 Hz, and the same 0.37 s later sampled at 100 Hz: the lag
    /// comes back to well under a sample, and at it the two agree.
    #[test]
    fn cross_correlation_finds_a_lag_between_different_rates() {
        let f = |t: f64| 40.0 * (std::f64::consts::PI * t).sin() + 10.0 * (2.3 * t).cos();
        let ta: Vec<f64> = (0..600).map(|i| i as f64 / 60.0).collect();
        let tb: Vec<f64> = (0..1200).map(|i| i as f64 / 100.0).collect();
        let a = table(ta.clone(), "k", ta.iter().map(|&t| f(t)).collect());
        let b = table(tb.clone(), "k", tb.iter().map(|&t| f(t - 0.37)).collect());
        let c = compare(&a, &b, &CompareOptions::default()).unwrap();
        assert!((c.lag_s - 0.37).abs() < 0.004, "{}", c.lag_s);
        assert!(c.angles[0].rmse_deg < 0.5 && c.angles[0].r.unwrap() > 0.999);
        let spike = CompareOptions {
            sync: Sync::Spike,
            ..Default::default()
        };
        // A clap: a step in the middle of each.
        let step = |t: f64, at: f64| if t < at { 0.0 } else { 30.0 };
        let a = table(ta.clone(), "k", ta.iter().map(|&t| step(t, 4.0)).collect());
        let b = table(tb.clone(), "k", tb.iter().map(|&t| step(t, 5.5)).collect());
        let c = compare(&a, &b, &spike).unwrap();
        assert!((c.lag_s - 1.5).abs() < 0.02, "{}", c.lag_s);
    }

    #[test]
    fn offsets_wraps_and_missing_values() {
        let t: Vec<f64> = (0..5).map(f64::from).collect();
        let a = table(t.clone(), "r", vec![170.0, 175.0, 179.0, -178.0, f64::NAN]);
        let b = table(t, "r", vec![172.0, 177.0, -179.0, -176.0, 3.0]);
        let none = CompareOptions {
            sync: Sync::None,
            ..Default::default()
        };
        let c = compare(&a, &b, &none).unwrap();
        assert_eq!(c.angles[0].n, 4);
        assert!((c.angles[0].rmse_deg - 2.0).abs() < 1e-9);
        assert!((c.angles[0].offset_deg - 2.0).abs() < 1e-9);
        let c = compare(
            &a,
            &b,
            &CompareOptions {
                remove_offset: true,
                ..none
            },
        )
        .unwrap();
        assert!(c.angles[0].rmse_deg < 1e-9);
        assert!((c.angles[0].r.unwrap() - 1.0).abs() < 1e-9);
    }
}
