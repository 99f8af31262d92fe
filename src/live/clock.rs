//! One source's clock kept sane before its lines reach the stream: the rules a file does not
//! need, because a stream cannot look at what comes next and must never wait for a time that
//! will not come.
//!
//! For each data line of one source (its time read by the readers' own parsers, [`LineClock`]),
//! on the stream's clock `t = raw + offset` (seconds):
//!
//! - **A time that is not a finite number** is a dropped line.
//! - **The first line** waits for the next data line to agree with it (within the rules below):
//!   a lone first time far from the lines after it (`1e308`, then `0.01, 0.02, …`) is dropped,
//!   not taken as the stream's start.
//! - **In step**: `latest − RESTART_S ≤ t ≤ latest + horizon` (`latest` the largest time taken
//!   so far, `RESTART_S` = 1 s, the readers' reset distance; `horizon` 10 s by default,
//!   `--time-horizon`): the line is taken. Lines a little out of order are the reorder buffer's
//!   business, not this.
//! - **A jump** (further back than `RESTART_S`, or further ahead than `horizon`): the line is held.
//!   When [`CONFIRM_LINES`] jumped lines in a row agree with each other (each in step with the
//!   one before), the source restarted its clock (an Arduino reset: `millis()` from 0) or jumped
//!   it (a clock set over the network): from then on its lines are restamped to carry on from
//!   `latest` plus one nominal step ([`RESTART_STEP_S`]), the held ones included, and the
//!   restart is said once. When a line in step comes first, the held lines were damaged
//!   timestamps: each is dropped with its reason.
//!
//! So a stream's time never leaps: no burst of frames for a gap that was not recorded, no source
//! left silent behind one time from the far future. Held lines are at most [`CONFIRM_LINES`];
//! a source whose lines keep disagreeing loses them one by one, reported.

use crate::read::stream::LineClock;

/// Jumped lines in a row that, agreeing with each other, make a clock restart.
pub const CONFIRM_LINES: usize = 5;
/// A time this far before the source's latest is a jump (the readers' reset distance for files,
/// [`crate::take::CLOCK_RESET_S`]).
pub const RESTART_S: f64 = 1.0;
/// The default for how far ahead of the source's latest a time may be and still be in step.
pub const DEFAULT_HORIZON_S: f64 = 10.0;
/// Where a restarted clock carries on from: the latest time plus this.
pub const RESTART_STEP_S: f64 = 0.01;

/// What [`SourceClock::push`] decided about a line.
#[derive(Debug, Clone, PartialEq)]
pub enum Judged {
    /// The line for the stream, restamped if its source's clock restarted; `t_s` is its time on
    /// the stream's clock (`None`: not a data line).
    Take { line: Vec<u8>, t_s: Option<f64> },
    /// A data line left out of the stream, with the reason.
    Drop { line: Vec<u8>, reason: String },
    /// Something to tell the user (a restart).
    Notice(String),
}

#[derive(Debug)]
struct HeldLine {
    line: Vec<u8>,
    /// The line's own time (seconds).
    raw_s: f64,
}

/// One source's clock rules (see the module documentation).
#[derive(Debug)]
pub struct SourceClock {
    clock: LineClock,
    horizon_s: f64,
    /// Added to each line's own time.
    offset_s: f64,
    /// The largest stream time taken so far.
    latest_s: Option<f64>,
    /// Lines waiting: the first line until one agrees with it, or a jump's lines.
    held: Vec<HeldLine>,
}

impl SourceClock {
    /// Rules with `horizon_s` seconds of look-ahead allowed (clamped to at least [`RESTART_S`]).
    pub fn new(horizon_s: f64) -> SourceClock {
        SourceClock {
            clock: LineClock::default(),
            horizon_s: if horizon_s.is_finite() {
                horizon_s.max(RESTART_S)
            } else {
                DEFAULT_HORIZON_S
            },
            offset_s: 0.0,
            latest_s: None,
            held: Vec::new(),
        }
    }

    /// Whether `t` follows `from` in step.
    fn in_step(&self, from: f64, t: f64) -> bool {
        t >= from - RESTART_S && t <= from + self.horizon_s
    }

    /// Judges one line as it arrives; what it decides (for this line and held ones) is appended
    /// to `out` in arrival order of the lines. Taken lines keep their own text (a replay paces
    /// on `t_s` and sends them as they are); [`SourceClock::judge`] restamps them.
    pub fn push(&mut self, line: Vec<u8>, out: &mut Vec<Judged>) {
        let Some(raw_s) = self.clock.time_s(&line) else {
            out.push(Judged::Take { line, t_s: None });
            return;
        };
        if !raw_s.is_finite() {
            out.push(Judged::Drop {
                line,
                reason: "time is not a finite number; dropped".into(),
            });
            return;
        }
        let t = raw_s + self.offset_s;
        let Some(latest) = self.latest_s else {
            // The first data line: taken with the first line after it that agrees.
            match self.held.last() {
                None => self.held.push(HeldLine { line, raw_s }),
                Some(first) if self.in_step(first.raw_s + self.offset_s, t) => {
                    let first = self.held.pop().expect("a held first line");
                    let first_t = first.raw_s + self.offset_s;
                    self.latest_s = Some(first_t.max(t));
                    out.push(Judged::Take {
                        line: first.line,
                        t_s: Some(first_t),
                    });
                    out.push(Judged::Take { line, t_s: Some(t) });
                }
                Some(_) => {
                    let first = self.held.pop().expect("a held first line");
                    out.push(Judged::Drop {
                        line: first.line,
                        reason: format!(
                            "the stream's first time ({:.3} s) is far from the next line's \
                             ({raw_s:.3} s); dropped",
                            first.raw_s
                        ),
                    });
                    self.held.push(HeldLine { line, raw_s });
                }
            }
            return;
        };
        if self.in_step(latest, t) {
            self.drop_held(latest, out);
            self.latest_s = Some(latest.max(t));
            out.push(Judged::Take { line, t_s: Some(t) });
            return;
        }
        // A jump: does it continue the jumped lines held before it?
        if let Some(last) = self.held.last()
            && !self.in_step(last.raw_s + self.offset_s, t)
        {
            self.drop_held(latest, out);
        }
        self.held.push(HeldLine { line, raw_s });
        if self.held.len() >= CONFIRM_LINES {
            self.restart(latest, out);
        }
    }

    /// The jumped lines held agree: the clock restarted. They and later lines carry on from
    /// `latest`.
    fn restart(&mut self, latest: f64, out: &mut Vec<Judged>) {
        let first_raw = self.held[0].raw_s;
        self.offset_s = latest + RESTART_STEP_S - first_raw;
        out.push(Judged::Notice(format!(
            "the device's clock restarted ({first_raw:.3} s after {latest:.3} s); its lines \
             carry on from {:.3} s",
            latest + RESTART_STEP_S
        )));
        let mut newest = latest;
        for held in std::mem::take(&mut self.held) {
            let t = held.raw_s + self.offset_s;
            newest = newest.max(t);
            out.push(Judged::Take {
                line: held.line,
                t_s: Some(t),
            });
        }
        self.latest_s = Some(newest);
    }

    /// The held lines were lone damaged times: each is dropped.
    fn drop_held(&mut self, latest: f64, out: &mut Vec<Judged>) {
        for held in self.held.drain(..) {
            out.push(Judged::Drop {
                line: held.line,
                reason: format!(
                    "time {:.3} s is far from the stream's ({latest:.3} s) and the lines after \
                     it do not follow it; dropped",
                    held.raw_s + self.offset_s
                ),
            });
        }
    }

    /// Restamps `line` if this source's clock restarted (lines that are taken as they come).
    fn restamped(&mut self, line: Vec<u8>, t_s: Option<f64>) -> Vec<u8> {
        match t_s {
            Some(t) if self.offset_s != 0.0 => self.clock.restamp(&line, t).unwrap_or(line),
            _ => line,
        }
    }

    /// [`SourceClock::push`], with taken lines restamped onto the stream's clock.
    pub fn judge(&mut self, line: Vec<u8>, out: &mut Vec<Judged>) {
        let from = out.len();
        self.push(line, out);
        for judged in &mut out[from..] {
            if let Judged::Take { line, t_s } = judged {
                let taken = std::mem::take(line);
                *line = self.restamped(taken, *t_s);
            }
        }
    }

    /// The source has ended: a first line alone is taken; a jump not confirmed is dropped.
    pub fn finish(&mut self, out: &mut Vec<Judged>) {
        match self.latest_s {
            None => {
                for held in self.held.drain(..) {
                    let t_s = Some(held.raw_s + self.offset_s);
                    out.push(Judged::Take {
                        line: held.line,
                        t_s,
                    });
                }
            }
            Some(latest) => self.drop_held(latest, out),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each line's fate, in order: `Some(Some(t))` taken at t, `Some(None)` taken untimed,
    /// `None` dropped; notices apart.
    type Fates = Vec<(String, Option<Option<f64>>)>;

    fn run(horizon: f64, lines: &[&str]) -> (Fates, Vec<String>) {
        let mut clock = SourceClock::new(horizon);
        let mut out = Vec::new();
        for l in lines {
            clock.judge(l.as_bytes().to_vec(), &mut out);
        }
        clock.finish(&mut out);
        let mut notices = Vec::new();
        let mut fates = Vec::new();
        for j in out {
            match j {
                Judged::Take { line, t_s } => fates.push((
                    String::from_utf8(line).unwrap(),
                    Some(t_s.map(|t| (t * 1000.0).round() / 1000.0)),
                )),
                Judged::Drop { line, .. } => fates.push((String::from_utf8(line).unwrap(), None)),
                Judged::Notice(n) => notices.push(n),
            }
        }
        (fates, notices)
    }

    /// The data lines' times (`None`: dropped).
    fn times(fates: &Fates) -> Vec<Option<f64>> {
        fates
            .iter()
            .filter(|(_, f)| !matches!(f, Some(None)))
            .map(|(_, f)| f.flatten())
            .collect()
    }

    #[test]
    fn a_lone_far_time_is_dropped_and_the_stream_goes_on() {
        let (fates, notices) = run(
            10.0,
            &[
                "time_s,sensor,qw,qx,qy,qz",
                "1.0,a,1,0,0,0",
                "1.1,a,1,0,0,0",
                "1e308,a,1,0,0,0",
                "1.2,a,1,0,0,0",
                "-1e308,a,1,0,0,0",
                "3601.3,a,1,0,0,0",
                "1.3,a,1,0,0,0",
            ],
        );
        assert_eq!(
            times(&fates),
            [Some(1.0), Some(1.1), None, Some(1.2), None, None, Some(1.3)]
        );
        assert!(notices.is_empty());
        // Taken lines keep their own text: no restart happened.
        assert_eq!(fates[4].0, "1.2,a,1,0,0,0");
    }

    #[test]
    fn a_lone_first_time_is_not_the_start() {
        let (fates, _) = run(
            10.0,
            &[
                "time_s,sensor,qw,qx,qy,qz",
                "1e23,a,1,0,0,0",
                "0.5,a,1,0,0,0",
                "0.6,a,1,0,0,0",
            ],
        );
        assert_eq!(times(&fates), [None, Some(0.5), Some(0.6)]);
    }

    #[test]
    fn five_agreeing_lines_are_a_restart_restamped_from_the_latest() {
        // The clock jumps an hour ahead, or back to near 0, and stays there.
        for jump in [3600.0, -2.0] {
            let mut lines = vec!["time_s,sensor,qw,qx,qy,qz".to_string()];
            for k in 0..10 {
                lines.push(format!("{},a,1,0,0,0", 2.0 + 0.1 * k as f64));
            }
            for k in 0..8 {
                lines.push(format!("{},a,1,0,0,0", 2.0 + jump + 0.1 * k as f64));
            }
            let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
            let (fates, notices) = run(10.0, &refs);
            assert_eq!(notices.len(), 1, "{notices:?}");
            // Nothing dropped; after 2.9 s the restarted lines carry on from 2.91 s, 0.1 s apart.
            let mut want: Vec<Option<f64>> = (0..10).map(|k| Some(2.0 + 0.1 * k as f64)).collect();
            want.extend((0..8).map(|k| Some(2.91 + 0.1 * k as f64)));
            let want: Vec<Option<f64>> = want
                .into_iter()
                .map(|t| t.map(|t| (t * 1000.0).round() / 1000.0))
                .collect();
            assert_eq!(times(&fates), want, "jump {jump}");
            // Restamped lines say their new time, six decimals: the held ones and those after.
            assert_eq!(fates[11].0, "2.910000,a,1,0,0,0", "{fates:?}");
            assert_eq!(fates.last().unwrap().0, "3.610000,a,1,0,0,0");
        }
    }

    #[test]
    fn jumped_lines_that_disagree_are_dropped_one_by_one() {
        // Garbage times, each far from the stream and from each other: never a restart.
        let mut lines = vec![
            "time_s,sensor,qw,qx,qy,qz",
            "1.0,a,1,0,0,0",
            "1.1,a,1,0,0,0",
        ];
        lines.extend([
            "1000,a,1,0,0,0",
            "5000,a,1,0,0,0",
            "-900,a,1,0,0,0",
            "77777,a,1,0,0,0",
            "123,a,1,0,0,0",
            "9e9,a,1,0,0,0",
        ]);
        lines.push("1.2,a,1,0,0,0");
        let (fates, notices) = run(10.0, &lines);
        let mut want = vec![Some(1.0), Some(1.1)];
        want.extend([None; 6]);
        want.push(Some(1.2));
        assert_eq!(times(&fates), want);
        assert!(notices.is_empty());
        // Arrival order is kept.
        let order: Vec<&str> = fates.iter().map(|f| f.0.as_str()).collect();
        assert_eq!(order, lines);
    }

    #[test]
    fn text_lines_pass_untimed_and_an_unconfirmed_jump_is_dropped_at_the_end() {
        let (fates, _) = run(
            10.0,
            &[
                "Booting v1.2",
                "time_s,sensor,qw,qx,qy,qz",
                "0.0,a,1,0,0,0",
                "0.1,a,1,0,0,0",
                "50,a,1,0,0,0",
            ],
        );
        assert_eq!(fates[0], ("Booting v1.2".into(), Some(None)));
        assert_eq!(fates[1], ("time_s,sensor,qw,qx,qy,qz".into(), Some(None)));
        assert_eq!(times(&fates), [Some(0.0), Some(0.1), None]);
    }

    #[test]
    fn a_short_horizon_makes_a_gap_a_jump() {
        let (fates, notices) = run(
            2.0,
            &[
                "time_s,sensor,qw,qx,qy,qz",
                "0.0,a,1,0,0,0",
                "0.1,a,1,0,0,0",
                "5.0,a,1,0,0,0",
                "5.1,a,1,0,0,0",
                "5.2,a,1,0,0,0",
                "5.3,a,1,0,0,0",
                "5.4,a,1,0,0,0",
            ],
        );
        assert_eq!(notices.len(), 1);
        assert_eq!(
            times(&fates),
            [
                Some(0.0),
                Some(0.1),
                Some(0.11),
                Some(0.21),
                Some(0.31),
                Some(0.41),
                Some(0.51)
            ]
        );
    }
}
