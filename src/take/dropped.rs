//! A stream's dropped-line reports, bounded: a stream can run for days and a broken device can
//! send nothing but garbage, so it keeps the first [`DroppedLines::KEEP`] reports whole (line
//! number, reason, text) and after that only counts, by reason. A file's take keeps every report
//! (its length is known); a stream's memory must not grow with its length.

use super::LineReport;

/// Reports kept whole, then counts by reason (see the module documentation).
#[derive(Debug, Clone, Default)]
pub struct DroppedLines {
    kept: Vec<LineReport>,
    /// The latest report, kept or not (a SOU line carrying two sensors is reported once).
    latest: Option<LineReport>,
    /// Reports past [`DroppedLines::KEEP`], by reason kind (at most [`DroppedLines::REASONS`]
    /// kinds; later kinds are counted under [`DroppedLines::OTHER`]).
    omitted: Vec<(String, u64)>,
}

impl DroppedLines {
    /// Reports kept whole.
    pub const KEEP: usize = 1000;
    /// Reason kinds counted apart once reports are only counted.
    pub const REASONS: usize = 32;
    /// The kind that counts the reasons past [`DroppedLines::REASONS`].
    pub const OTHER: &'static str = "other reasons";

    /// Adds a report.
    pub fn push(&mut self, report: LineReport) {
        if self.kept.len() < Self::KEEP {
            self.kept.push(report.clone());
        } else {
            self.count(reason_kind(&report.reason), 1);
        }
        self.latest = Some(report);
    }

    /// Adds a report unless it repeats the latest one (the same line, reason and text).
    pub fn push_unless_repeated(&mut self, report: LineReport) {
        if self.latest.as_ref() != Some(&report) {
            self.push(report);
        }
    }

    /// Every report taken, kept whole or counted.
    pub fn total(&self) -> u64 {
        self.kept.len() as u64 + self.omitted()
    }

    /// The reports kept whole, in the order they came.
    pub fn reports(&self) -> &[LineReport] {
        &self.kept
    }

    /// How many reports were only counted.
    pub fn omitted(&self) -> u64 {
        self.omitted.iter().map(|(_, n)| n).sum()
    }

    /// The counted reports by reason kind, in the order each kind first came.
    pub fn omitted_by_reason(&self) -> &[(String, u64)] {
        &self.omitted
    }

    pub fn is_empty(&self) -> bool {
        self.kept.is_empty()
    }

    /// Several streams' reports as one: the reports each kept whole, in line order, then counts
    /// (a part's counted reports are counted, even where their lines come before another part's
    /// kept ones).
    pub fn merged(parts: &[&DroppedLines]) -> DroppedLines {
        let mut kept: Vec<&LineReport> = parts.iter().flat_map(|p| p.kept.iter()).collect();
        kept.sort_by_key(|r| r.line);
        let mut out = DroppedLines::default();
        for r in kept {
            out.push(r.clone());
        }
        for p in parts {
            for (kind, n) in &p.omitted {
                out.count(kind, *n);
            }
        }
        out
    }

    /// Counts `n` reports of `kind` (under [`DroppedLines::OTHER`] once the kinds are full).
    fn count(&mut self, kind: &str, n: u64) {
        let known = self.omitted.iter().position(|(k, _)| k == kind);
        let at = match known {
            Some(i) => i,
            None if self.omitted.len() < Self::REASONS => {
                self.omitted.push((kind.into(), 0));
                self.omitted.len() - 1
            }
            None => match self.omitted.iter().position(|(k, _)| k == Self::OTHER) {
                Some(i) => i,
                None => {
                    self.omitted.push((Self::OTHER.into(), 0));
                    self.omitted.len() - 1
                }
            },
        };
        self.omitted[at].1 += n;
    }
}

/// A reason's kind: its words before the first `:` or `;` (the details after vary line by
/// line), at most 80 bytes.
fn reason_kind(reason: &str) -> &str {
    let end = reason.find([':', ';']).unwrap_or(reason.len());
    let mut kind = reason[..end].trim();
    if kind.len() > 80 {
        let mut cut = 80;
        while !kind.is_char_boundary(cut) {
            cut -= 1;
        }
        kind = &kind[..cut];
    }
    kind
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(line: u64, reason: &str) -> LineReport {
        LineReport::new(None, line, reason, b"x")
    }

    #[test]
    fn the_first_reports_are_kept_then_counted_by_kind() {
        let mut d = DroppedLines::default();
        let n = DroppedLines::KEEP as u64 + 2500;
        for line in 1..=n {
            let reason = if line % 2 == 0 {
                format!("time out of sequence: {line} s")
            } else {
                "does not match the SOU format".to_string()
            };
            d.push(report(line, &reason));
        }
        assert_eq!(d.total(), n);
        assert_eq!(d.reports().len(), DroppedLines::KEEP);
        assert_eq!(d.reports()[999].line, 1000);
        // Lines 1001..=3500: 1250 odd, 1250 even; the first counted is 1001 (odd).
        assert_eq!(
            d.omitted_by_reason(),
            [
                ("does not match the SOU format".to_string(), 1250),
                ("time out of sequence".to_string(), 1250)
            ]
        );
    }

    #[test]
    fn reason_kinds_are_bounded() {
        let mut d = DroppedLines::default();
        for line in 0..DroppedLines::KEEP as u64 {
            d.push(report(line, "filler"));
        }
        for k in 0..100u64 {
            d.push(report(10_000 + k, &format!("kind {k}")));
        }
        assert_eq!(d.omitted(), 100);
        assert_eq!(d.omitted_by_reason().len(), DroppedLines::REASONS + 1);
        assert_eq!(
            d.omitted_by_reason().last().unwrap(),
            &(
                DroppedLines::OTHER.to_string(),
                100 - DroppedLines::REASONS as u64
            )
        );
        let merged = DroppedLines::merged(&[&d, &d]);
        assert_eq!(merged.total(), 2 * d.total());
        assert_eq!(merged.omitted_by_reason().len(), DroppedLines::REASONS + 1);
    }

    #[test]
    fn merged_parts_list_their_reports_in_line_order() {
        let mut a = DroppedLines::default();
        let mut b = DroppedLines::default();
        for line in (1..=1200).step_by(2) {
            a.push(report(line, "odd"));
        }
        for line in (2..=1200).step_by(2) {
            b.push(report(line, "even: x"));
        }
        let m = DroppedLines::merged(&[&a, &b]);
        assert_eq!(m.total(), 1200);
        let lines: Vec<u64> = m.reports().iter().map(|r| r.line).collect();
        assert_eq!(lines, (1..=1000).collect::<Vec<u64>>());
        assert_eq!(
            m.omitted_by_reason(),
            [("odd".to_string(), 100), ("even".to_string(), 100)]
        );
    }

    #[test]
    fn a_repeated_report_is_taken_once() {
        let mut d = DroppedLines::default();
        d.push_unless_repeated(report(3, "bad"));
        d.push_unless_repeated(report(3, "bad"));
        d.push_unless_repeated(report(4, "bad"));
        assert_eq!(d.total(), 2);
    }
}
