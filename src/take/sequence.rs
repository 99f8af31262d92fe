//! The cleaning rules for one stream of one sensor, for rows in arrival order (file order, or
//! the order a stream releases them): a row in order is kept; a row earlier than the previous one
//! is late (the file builder sorts it into place; a stream drops it); a row repeating a time is
//! dropped (the first kept); a row more than [`CLOCK_RESET_S`](super::builder::CLOCK_RESET_S)
//! from the previous one is held until up to [`LOOKAHEAD_ROWS`] more rows have come: when most of
//! them continue from the previous row its timestamp was damaged and it is dropped; when they
//! continue from it, a jump forward is a gap and a jump back a clock reset (an error). When the
//! rows after such a jump continue from it and the only row before it is the stream's first, the
//! first is the one dropped — so the first row is kept only once a row after it confirms it.
//!
//! Files ([`super::TakeBuilder`]) and streams ([`super::TakeStream`]) share this, so both clean
//! the same way.

use super::LineReport;

/// How many rows of a stream after a jump decide whether the jump was one damaged timestamp.
pub const LOOKAHEAD_ROWS: usize = 8;

/// A row held with its report.
pub(crate) struct Held<T> {
    pub raw_time: f64,
    pub value: T,
    pub report: LineReport,
}

/// A row the rules drop.
pub(crate) enum Dropped {
    /// A repeated time (the first is kept).
    Duplicate(LineReport),
    /// A time far from both neighbours.
    OutOfSequence(LineReport),
}

/// A backward jump that the following rows continue: the clock was reset.
pub(crate) struct Reset {
    pub previous: f64,
    pub time: f64,
    pub report: LineReport,
}

/// Where a [`Sequencer`]'s decisions go.
pub(crate) trait Sink<T> {
    /// A row kept, in order.
    fn keep(&mut self, raw_time: f64, value: T);
    /// A row earlier than the previous kept row (within the reset distance).
    fn late(&mut self, row: Held<T>);
    fn dropped(&mut self, row: Dropped);
}

/// A row far from the previous one, and the rows after it that decide what it is.
struct Suspect<T> {
    row: Held<T>,
    following: Vec<Held<T>>,
}

/// The rules' state for one stream of one sensor.
pub(crate) struct Sequencer<T> {
    /// A jump larger than this (in the source's time unit) is looked at with the rows after it.
    reset_units: f64,
    /// The time of the last row kept (or of the first, while it waits to be confirmed).
    last: Option<f64>,
    /// Rows kept so far, the first included.
    kept: usize,
    late_seen: bool,
    /// The first row, until a row after it confirms it.
    first: Option<Held<T>>,
    suspect: Option<Suspect<T>>,
}

impl<T> Sequencer<T> {
    pub fn new(reset_units: f64) -> Self {
        Sequencer {
            reset_units,
            last: None,
            kept: 0,
            late_seen: false,
            first: None,
            suspect: None,
        }
    }

    /// Takes a row in arrival order. `report` is called only when the row must be held or
    /// reported.
    pub fn push(
        &mut self,
        raw_time: f64,
        value: T,
        report: impl FnOnce() -> LineReport,
        sink: &mut impl Sink<T>,
    ) -> Result<(), Reset> {
        if let Some(suspect) = &mut self.suspect {
            suspect.following.push(Held {
                raw_time,
                value,
                report: report(),
            });
            if suspect.following.len() >= LOOKAHEAD_ROWS {
                self.resolve(sink)?;
            }
            return Ok(());
        }
        let Some(last) = self.last else {
            self.first = Some(Held {
                raw_time,
                value,
                report: report(),
            });
            self.last = Some(raw_time);
            self.kept = 1;
            return Ok(());
        };
        if raw_time > last && raw_time - last <= self.reset_units {
            // The hot path: the next sample in order.
            self.confirm_first(sink);
            sink.keep(raw_time, value);
            self.last = Some(raw_time);
            self.kept += 1;
        } else if raw_time == last {
            sink.dropped(Dropped::Duplicate(report()));
        } else if (raw_time - last).abs() > self.reset_units {
            self.suspect = Some(Suspect {
                row: Held {
                    raw_time,
                    value,
                    report: report(),
                },
                following: Vec::new(),
            });
        } else {
            self.late_seen = true;
            sink.late(Held {
                raw_time,
                value,
                report: report(),
            });
        }
        Ok(())
    }

    fn confirm_first(&mut self, sink: &mut impl Sink<T>) {
        if let Some(first) = self.first.take() {
            sink.keep(first.raw_time, first.value);
        }
    }

    /// Decides what the suspect row is, then takes the rows held after it in order (which may
    /// hold a new suspect).
    fn resolve(&mut self, sink: &mut impl Sink<T>) -> Result<(), Reset> {
        let Some(Suspect { row, following }) = self.suspect.take() else {
            return Ok(());
        };
        let last = self.last.expect("a suspect follows a kept row");
        let near_previous = following
            .iter()
            .filter(|f| (f.raw_time - last).abs() < (f.raw_time - row.raw_time).abs())
            .count();
        if following.is_empty() || 2 * near_previous > following.len() {
            // The rows after it continue from the previous row (or there are none).
            sink.dropped(Dropped::OutOfSequence(row.report));
        } else if self.kept == 1 && !self.late_seen && self.first.is_some() {
            // The rows after it continue from it, and the only row before it is the stream's
            // first: that one was out of sequence.
            if let Some(first) = self.first.take() {
                sink.dropped(Dropped::OutOfSequence(first.report));
            }
            self.last = Some(row.raw_time);
            self.first = Some(row);
        } else if row.raw_time > last {
            // A gap: the sensor was silent, then went on.
            self.confirm_first(sink);
            sink.keep(row.raw_time, row.value);
            self.last = Some(row.raw_time);
            self.kept += 1;
        } else {
            return Err(Reset {
                previous: last,
                time: row.raw_time,
                report: row.report,
            });
        }
        for f in following {
            let Held {
                raw_time,
                value,
                report,
            } = f;
            self.push(raw_time, value, || report, sink)?;
        }
        Ok(())
    }

    /// Decides what is still held at the end of the source.
    pub fn flush(&mut self, sink: &mut impl Sink<T>) -> Result<(), Reset> {
        while self.suspect.is_some() {
            self.resolve(sink)?;
        }
        self.confirm_first(sink);
        Ok(())
    }
}
