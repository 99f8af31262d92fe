//! A table of angle series on one clock: what `imubake angles` writes and `imubake compare` reads.
//!
//! CSV: a header `frame,time_s,<angle>,...` (`frame` optional; any other column is an angle,
//! degrees), one row per frame; a value that could not be computed is `nan` (or empty). JSON:
//! `{"units": "degrees", "time_s": [...], "angles": {"<angle>": [...]}}` with `null` for NaN.

use super::AnalysisError;
use std::fmt::Write as _;
use std::path::Path;

/// Angle series (degrees) at strictly increasing, finite times (seconds).
///
/// Invariants (checked by [`AngleTable::new`]): at least one row; every column as long as the
/// times; unique names.
#[derive(Debug, Clone, PartialEq)]
pub struct AngleTable {
    names: Vec<String>,
    time_s: Vec<f64>,
    /// `columns[angle][row]`.
    columns: Vec<Vec<f64>>,
}

impl AngleTable {
    pub fn new(
        names: Vec<String>,
        time_s: Vec<f64>,
        columns: Vec<Vec<f64>>,
    ) -> Result<AngleTable, String> {
        if time_s.is_empty() {
            return Err("no rows".into());
        }
        if names.len() != columns.len() {
            return Err(format!(
                "{} names for {} columns",
                names.len(),
                columns.len()
            ));
        }
        if let Some(i) = (0..time_s.len())
            .find(|&i| !time_s[i].is_finite() || (i > 0 && time_s[i] <= time_s[i - 1]))
        {
            return Err(format!(
                "row {}: time {} s is not finite or not after the previous row's",
                i + 1,
                time_s[i]
            ));
        }
        if let Some((n, _)) = names
            .iter()
            .zip(&columns)
            .find(|(_, c)| c.len() != time_s.len())
        {
            return Err(format!("column `{n}` is not as long as the times"));
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(n) = names.iter().find(|n| !seen.insert(n.as_str())) {
            return Err(format!("column `{n}` appears twice"));
        }
        Ok(AngleTable {
            names,
            time_s,
            columns,
        })
    }

    pub fn names(&self) -> &[String] {
        &self.names
    }

    pub fn time_s(&self) -> &[f64] {
        &self.time_s
    }

    /// The series of angle `name`, if the table has it.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }

    pub fn rows(&self) -> usize {
        self.time_s.len()
    }

    /// CSV with a `frame` column (the row index) and six decimals.
    pub fn to_csv(&self) -> String {
        let mut out = String::from("frame,time_s");
        for n in &self.names {
            out.push(',');
            out.push_str(n);
        }
        out.push('\n');
        for (i, t) in self.time_s.iter().enumerate() {
            let _ = write!(out, "{i},{t:.6}");
            for c in &self.columns {
                if c[i].is_finite() {
                    let _ = write!(out, ",{:.6}", c[i]);
                } else {
                    out.push_str(",nan");
                }
            }
            out.push('\n');
        }
        out
    }

    pub fn to_json(&self) -> serde_json::Value {
        let finite = |v: &f64| v.is_finite().then_some(*v);
        let angles: serde_json::Map<String, serde_json::Value> = self
            .names
            .iter()
            .zip(&self.columns)
            .map(|(n, c)| {
                (
                    n.clone(),
                    serde_json::json!(c.iter().map(finite).collect::<Vec<_>>()),
                )
            })
            .collect();
        serde_json::json!({"units": "degrees", "time_s": self.time_s, "angles": angles})
    }

    /// Reads a CSV table (module docs). Errors name the file and line.
    pub fn read_csv(path: &Path) -> Result<AngleTable, AnalysisError> {
        let text = std::fs::read_to_string(path).map_err(|source| AnalysisError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        AngleTable::parse_csv(&text, path)
    }

    pub fn parse_csv(text: &str, path: &Path) -> Result<AngleTable, AnalysisError> {
        let err = |line: usize, reason: String| AnalysisError::Table {
            path: path.to_path_buf(),
            line,
            reason,
        };
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim_end_matches('\r')))
            .filter(|(_, l)| !l.trim().is_empty());
        let (_, header) = lines.next().ok_or_else(|| {
            err(
                1,
                "empty file: expected a header `time_s,<angle>,...`".into(),
            )
        })?;
        let fields: Vec<&str> = header.split(',').map(str::trim).collect();
        let time = fields
            .iter()
            .position(|f| *f == "time_s")
            .ok_or_else(|| err(1, "the header has no `time_s` column".into()))?;
        let angle_cols: Vec<usize> = (0..fields.len())
            .filter(|&i| i != time && fields[i] != "frame")
            .collect();
        let names: Vec<String> = angle_cols.iter().map(|&i| fields[i].to_string()).collect();
        let mut time_s = Vec::new();
        let mut columns = vec![Vec::new(); names.len()];
        let mut last_line = 1;
        for (n, line) in lines {
            last_line = n;
            let values: Vec<&str> = line.split(',').map(str::trim).collect();
            if values.len() != fields.len() {
                return Err(err(
                    n,
                    format!("{} fields; the header has {}", values.len(), fields.len()),
                ));
            }
            let t: f64 = values[time]
                .parse()
                .ok()
                .filter(|t: &f64| t.is_finite())
                .ok_or_else(|| err(n, format!("time `{}` is not a number", values[time])))?;
            if time_s.last().is_some_and(|&last| t <= last) {
                return Err(err(
                    n,
                    format!("time {t} s is not after the previous row's"),
                ));
            }
            time_s.push(t);
            for (c, &i) in angle_cols.iter().enumerate() {
                let v = values[i];
                let x = if v.is_empty() || v.eq_ignore_ascii_case("nan") {
                    f64::NAN
                } else {
                    v.parse::<f64>()
                        .ok()
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| err(n, format!("`{}`: `{v}` is not a number", names[c])))?
                };
                columns[c].push(x);
            }
        }
        AngleTable::new(names, time_s, columns).map_err(|reason| err(last_line, reason))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips_and_bad_lines_are_named() {
        let t = AngleTable::new(
            vec!["left_knee".into(), "x".into()],
            vec![0.0, 0.5],
            vec![vec![1.5, f64::NAN], vec![-2.0, 3.25]],
        )
        .unwrap();
        let back = AngleTable::parse_csv(&t.to_csv(), Path::new("a.csv")).unwrap();
        assert_eq!(back.names(), t.names());
        assert_eq!(back.column("x").unwrap(), &[-2.0, 3.25]);
        assert!(back.column("left_knee").unwrap()[1].is_nan());
        let e = AngleTable::parse_csv("time_s,a\n0,1\n0,2\n", Path::new("a.csv"))
            .unwrap_err()
            .to_string();
        assert_eq!(e, "a.csv: line 3: time 0 s is not after the previous row's");
        let e = AngleTable::parse_csv("time_s,a\n0,1\n1,x\n", Path::new("a.csv"))
            .unwrap_err()
            .to_string();
        assert_eq!(e, "a.csv: line 3: `a`: `x` is not a number");
        let e = AngleTable::parse_csv("t,a\n", Path::new("a.csv"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 1: the header has no `time_s`"), "{e}");
        let e = AngleTable::parse_csv("time_s,a\n", Path::new("a.csv"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("no rows"), "{e}");
    }
}
