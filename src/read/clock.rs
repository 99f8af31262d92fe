//! Device counters that wrap (Xsens DOT `SampleTimeFine`, MTw `PacketCounter`), unwrapped onto
//! one clock for all the files of a take.

/// Unwraps a device counter that wraps at `modulus` and puts the files of one take on one clock.
///
/// Each file's first value is placed within half a wrap of the anchor (the first value seen, or
/// the one given to [`WrappingClock::anchored`]); each later value of the file within half a wrap
/// of the previous row's. Shared by the Xsens readers (DOT `SampleTimeFine`, MTw `PacketCounter`).
#[derive(Debug, Clone)]
pub struct WrappingClock {
    modulus: u64,
    anchor: Option<i64>,
    last: Option<(u64, i64)>,
}

impl WrappingClock {
    /// A clock anchored at the first value it sees.
    pub fn new(modulus: u64) -> Self {
        WrappingClock {
            modulus: modulus.max(2),
            anchor: None,
            last: None,
        }
    }

    /// A clock anchored at the earliest of the files' first values: the one every other value
    /// follows within half a wrap. All unwrapped values are then at or after it (when the files
    /// start within half a wrap of each other).
    pub fn anchored_at_earliest(modulus: u64, firsts: &[u64]) -> Self {
        let mut clock = WrappingClock::new(modulus);
        if let Some(&first) = firsts.first() {
            let m = clock.modulus;
            let earliest = firsts
                .iter()
                .copied()
                .min_by_key(|&f| circular_delta(f % m, first % m, m))
                .unwrap_or(first);
            clock.anchor = Some((earliest % m) as i64);
        }
        clock
    }

    /// Starts a new file: its first value is placed relative to the anchor.
    pub fn start_file(&mut self) {
        self.last = None;
    }

    /// The unwrapped value of `raw` (which must be below the modulus).
    pub fn unwrap(&mut self, raw: u64) -> i64 {
        let m = self.modulus;
        let raw = raw % m;
        let value = match (self.last, self.anchor) {
            (Some((last_raw, last_value)), _) => last_value + circular_delta(raw, last_raw, m),
            (None, Some(anchor)) => {
                anchor + circular_delta(raw, anchor.rem_euclid(m as i64) as u64, m)
            }
            (None, None) => {
                self.anchor = Some(raw as i64);
                raw as i64
            }
        };
        self.last = Some((raw, value));
        value
    }
}

/// `a - b` modulo `m`, in [-m/2, m/2).
fn circular_delta(a: u64, b: u64, m: u64) -> i64 {
    let m = m as i64;
    let d = (a as i64 - b as i64).rem_euclid(m);
    if d >= m / 2 { d - m } else { d }
}

/// Parses a whole non-negative number (surrounding spaces allowed).
pub(crate) fn parse_counter(field: &[u8]) -> Result<u64, &'static str> {
    let t = field.trim_ascii();
    if t.is_empty() {
        return Err("is empty");
    }
    if !t.iter().all(u8::is_ascii_digit) {
        return Err("is not a whole number");
    }
    std::str::from_utf8(t)
        .ok()
        .and_then(|s| s.parse::<u64>().ok())
        .ok_or("is too large")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circular_delta_and_unwrap() {
        assert_eq!(circular_delta(5, 3, 16), 2);
        assert_eq!(circular_delta(1, 15, 16), 2);
        assert_eq!(circular_delta(15, 1, 16), -2);
        let mut c = WrappingClock::new(16);
        let got: Vec<i64> = [12, 14, 1, 0, 3, 15, 6]
            .iter()
            .map(|&r| c.unwrap(r))
            .collect();
        assert_eq!(got, vec![12, 14, 17, 16, 19, 15, 22]);
        // a second file starting after the wrap lands after the first one's start
        c.start_file();
        assert_eq!(c.unwrap(2), 18);
        // anchored at the earliest of the files' starts
        let mut c = WrappingClock::anchored_at_earliest(16, &[2, 14, 1]);
        assert_eq!(c.unwrap(2), 18);
        c.start_file();
        assert_eq!(c.unwrap(14), 14);
        assert_eq!(parse_counter(b" 0042 "), Ok(42));
        assert!(parse_counter(b"-1").is_err());
        assert!(parse_counter(b"99999999999999999999999").is_err());
    }
}
