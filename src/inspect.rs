//! Paper 002's data summarizer (7.4.2): time frame, node count, and per node the sample count and
//! the mean/min/max interval between samples, plus gaps and what was dropped on reading.

use crate::take::{LineReport, SourceInfo, Take};
use rayon::prelude::*;
use serde::ser::SerializeMap;
use serde::{Serialize, Serializer};
use std::fmt::Write as _;

/// An interval between two samples of a sensor longer than this is a gap.
pub const GAP_THRESHOLD_S: f64 = 0.25;

/// A stretch without samples, between two consecutive samples of one sensor.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Gap {
    /// Time of the sample before the gap (take clock, seconds).
    pub start_s: f64,
    /// Time of the sample after the gap.
    pub end_s: f64,
    pub duration_s: f64,
}

/// One sensor's rate summary (the sidecar's `sensors` entry).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SensorSummary {
    pub samples: usize,
    /// Interval statistics in milliseconds; `None` for a sensor with a single sample.
    pub mean_dt_ms: Option<f64>,
    pub min_dt_ms: Option<f64>,
    pub max_dt_ms: Option<f64>,
    pub first_s: f64,
    pub last_s: f64,
    pub gaps: Vec<Gap>,
}

impl SensorSummary {
    /// Summarises sample times (strictly increasing, seconds).
    pub fn from_times(times_s: &[f64]) -> SensorSummary {
        // Four running minima and maxima, each interval to one of them in turn: with a single
        // pair every step waits for the one before (an hour's sixteen sensors took 27 ms; with
        // this and a sensor per core, 5). The least of the four is the least of all, whatever
        // the order.
        let mut least = [f64::INFINITY; 4];
        let mut most = [f64::NEG_INFINITY; 4];
        let mut gaps = Vec::new();
        for (k, pair) in times_s.windows(2).enumerate() {
            let dt = pair[1] - pair[0];
            let lane = k % 4;
            least[lane] = least[lane].min(dt);
            most[lane] = most[lane].max(dt);
            if dt > GAP_THRESHOLD_S {
                gaps.push(Gap {
                    start_s: pair[0],
                    end_s: pair[1],
                    duration_s: dt,
                });
            }
        }
        let min = least.into_iter().fold(f64::INFINITY, f64::min);
        let max = most.into_iter().fold(f64::NEG_INFINITY, f64::max);
        let n = times_s.len();
        let (first, last) = (times_s[0], times_s[n - 1]);
        let intervals = n > 1;
        SensorSummary {
            samples: n,
            // The mean interval is the span over the count of intervals (telescoping sum).
            mean_dt_ms: intervals.then(|| (last - first) / (n - 1) as f64 * 1e3),
            min_dt_ms: intervals.then_some(min * 1e3),
            max_dt_ms: intervals.then_some(max * 1e3),
            first_s: first,
            last_s: last,
            gaps,
        }
    }
}

/// Sensor summaries keyed by id, in the take's sensor order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SensorSummaries(pub Vec<(String, SensorSummary)>);

impl Serialize for SensorSummaries {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (id, summary) in &self.0 {
            map.serialize_entry(id, summary)?;
        }
        map.end()
    }
}

impl SensorSummaries {
    pub fn of(take: &Take) -> SensorSummaries {
        // One sensor per core at a time: an hour is millions of intervals.
        SensorSummaries(
            take.sensors()
                .par_iter()
                .map(|s| {
                    (
                        s.id().to_string(),
                        SensorSummary::from_times(s.primary_times_s()),
                    )
                })
                .collect(),
        )
    }
}

/// What `imubake inspect` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Inspection {
    pub source: SourceInfo,
    pub node_count: usize,
    /// From the earliest to the latest sample of any sensor, seconds.
    pub time_frame_s: f64,
    pub sensors: SensorSummaries,
    pub dropped_lines: Vec<LineReport>,
    pub repaired_lines: Vec<LineReport>,
    pub warnings: Vec<String>,
}

impl Inspection {
    pub fn of(take: &Take) -> Inspection {
        Inspection {
            source: take.source().clone(),
            node_count: take.sensors().len(),
            time_frame_s: take.last_time_s(),
            sensors: SensorSummaries::of(take),
            dropped_lines: take.dropped_lines().to_vec(),
            repaired_lines: take.repaired_lines().to_vec(),
            warnings: take.warnings().to_vec(),
        }
    }

    /// The report for people. Lists at most `max_lines` dropped and repaired lines each.
    pub fn to_text(&self, max_lines: usize) -> String {
        let mut out = String::new();
        let src = &self.source;
        let _ = writeln!(
            out,
            "{}: {} (world {}), t = 0 at source time {}",
            src.path.display(),
            src.format.description(),
            src.world,
            src.start_timestamp
        );
        let _ = writeln!(out, "Time frame: {:.3} seconds", self.time_frame_s);
        let _ = writeln!(out, "Node count: {}", self.node_count);
        let width = self
            .sensors
            .0
            .iter()
            .map(|(id, _)| id.chars().count())
            .max()
            .unwrap_or(4)
            .max(4);
        let _ = writeln!(
            out,
            "{:<width$}  {:>8}  {:>11}  {:>10}  {:>10}  {:>5}",
            "Node", "Samples", "Mean dt ms", "Min dt ms", "Max dt ms", "Gaps"
        );
        let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        for (id, s) in &self.sensors.0 {
            let _ = writeln!(
                out,
                "{:<width$}  {:>8}  {:>11}  {:>10}  {:>10}  {:>5}",
                id,
                s.samples,
                ms(s.mean_dt_ms),
                ms(s.min_dt_ms),
                ms(s.max_dt_ms),
                s.gaps.len()
            );
        }
        let gaps: Vec<_> = self
            .sensors
            .0
            .iter()
            .flat_map(|(id, s)| s.gaps.iter().map(move |g| (id, g)))
            .collect();
        if !gaps.is_empty() {
            let _ = writeln!(out, "Gaps longer than {GAP_THRESHOLD_S} s: {}", gaps.len());
            for (id, g) in gaps.iter().take(max_lines) {
                let _ = writeln!(
                    out,
                    "  {id}: {:.3} s without samples, from {:.3} s to {:.3} s",
                    g.duration_s, g.start_s, g.end_s
                );
            }
            more(&mut out, gaps.len(), max_lines);
        }
        for (title, lines) in [
            ("Dropped lines", &self.dropped_lines),
            ("Repaired lines", &self.repaired_lines),
        ] {
            if lines.is_empty() {
                continue;
            }
            let _ = writeln!(out, "{title}: {}", lines.len());
            for l in lines.iter().take(max_lines) {
                let _ = writeln!(out, "  {}: {}: \"{}\"", l.location(), l.reason, l.text);
            }
            more(&mut out, lines.len(), max_lines);
        }
        if !self.warnings.is_empty() {
            let _ = writeln!(out, "Warnings: {}", self.warnings.len());
            for w in &self.warnings {
                let _ = writeln!(out, "  {w}");
            }
        }
        out
    }
}

fn more(out: &mut String, total: usize, shown: usize) {
    if total > shown {
        let _ = writeln!(
            out,
            "  … and {} more (all of them with --json)",
            total - shown
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_by_hand() {
        // Intervals 0.1, 0.3 (a gap), 0.05 s.
        let s = SensorSummary::from_times(&[0.0, 0.1, 0.4, 0.45]);
        assert_eq!(s.samples, 4);
        assert!((s.mean_dt_ms.unwrap() - 150.0).abs() < 1e-9);
        assert!((s.min_dt_ms.unwrap() - 50.0).abs() < 1e-9);
        assert!((s.max_dt_ms.unwrap() - 300.0).abs() < 1e-9);
        assert_eq!(s.gaps.len(), 1);
        assert!((s.gaps[0].start_s - 0.1).abs() < 1e-12 && (s.gaps[0].end_s - 0.4).abs() < 1e-12);
        let one = SensorSummary::from_times(&[2.0]);
        assert_eq!((one.samples, one.mean_dt_ms, one.gaps.len()), (1, None, 0));
    }

    /// The least and greatest intervals, and the gaps in order, are those of one pass over the
    /// intervals, for every count of intervals modulo the four running extremes.
    #[test]
    fn extremes_and_gaps_as_one_pass_finds_them() {
        let mut state = 0x853c_49e6_748f_ea9bu64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for n in 2..60 {
            let mut t = 0.0;
            let times: Vec<f64> = (0..n)
                .map(|_| {
                    t += if next() < 0.1 {
                        0.3 + next()
                    } else {
                        0.001 + next() * 0.02
                    };
                    t
                })
                .collect();
            let dts: Vec<f64> = times.windows(2).map(|p| p[1] - p[0]).collect();
            let least = dts.iter().copied().fold(f64::INFINITY, f64::min);
            let most = dts.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let s = SensorSummary::from_times(&times);
            assert_eq!(s.min_dt_ms, Some(least * 1e3), "{n}");
            assert_eq!(s.max_dt_ms, Some(most * 1e3), "{n}");
            let gaps: Vec<(f64, f64)> = times
                .windows(2)
                .filter(|p| p[1] - p[0] > GAP_THRESHOLD_S)
                .map(|p| (p[0], p[1]))
                .collect();
            let found: Vec<(f64, f64)> = s.gaps.iter().map(|g| (g.start_s, g.end_s)).collect();
            assert_eq!(found, gaps, "{n}");
        }
    }
}
