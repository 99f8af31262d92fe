//! Fast line splitting for text logs: large reads, CRLF accepted, 1-based line numbers.

use std::io::{self, Read};

/// The longest line of a text log, in bytes without its line end: 1 MiB. Longer lines are not
/// text logs (a binary file without newlines, say). Every line-based reader (all but MVNX's
/// XML) holds its lines to it, from files and streams alike, as it reads: a longer line is
/// refused by number once the limit is passed, never read whole.
pub const MAX_LINE_BYTES: usize = 1 << 20;

const CHUNK_BYTES: usize = 1 << 20;

#[derive(Debug, thiserror::Error)]
pub enum LineError {
    #[error(
        "line {line} is longer than {MAX_LINE_BYTES} bytes; expected a text log with one sample per line"
    )]
    TooLong { line: u64 },
    #[error(transparent)]
    Io(#[from] io::Error),
}

/// Yields the lines of a reader without the line terminator (`\n` or `\r\n`).
pub struct LineReader<R> {
    reader: R,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    eof: bool,
    line_no: u64,
    bytes_consumed: u64,
    /// How much the buffer grows by when it runs low.
    chunk: usize,
}

impl<R: Read> LineReader<R> {
    pub fn new(reader: R) -> Self {
        Self::with_chunk(reader, CHUNK_BYTES)
    }

    fn with_chunk(reader: R, chunk: usize) -> Self {
        LineReader {
            reader,
            buf: Vec::new(),
            start: 0,
            end: 0,
            eof: false,
            line_no: 0,
            bytes_consumed: 0,
            chunk,
        }
    }

    /// Bytes of the source consumed so far (for progress and size estimates).
    pub fn bytes_consumed(&self) -> u64 {
        self.bytes_consumed
    }

    /// The source and the bytes read from it but not yet returned as lines, for a reader that
    /// goes on in another way ([`super::blocks`]).
    pub fn into_pending(self) -> (R, Vec<u8>) {
        let pending = self.buf[self.start..self.end].to_vec();
        (self.reader, pending)
    }

    /// The next line and its 1-based number; a UTF-8 byte-order mark on line 1 is removed.
    pub fn next_line(&mut self) -> Result<Option<(u64, &[u8])>, LineError> {
        loop {
            if let Some(pos) = memchr::memchr(b'\n', &self.buf[self.start..self.end]) {
                let line_start = self.start;
                let line_end = self.start + pos;
                self.start = line_end + 1;
                return Ok(Some(self.emit(line_start, line_end)));
            }
            if self.eof {
                if self.start < self.end {
                    let (line_start, line_end) = (self.start, self.end);
                    self.start = self.end;
                    return Ok(Some(self.emit(line_start, line_end)));
                }
                return Ok(None);
            }
            self.refill()?;
        }
    }

    fn emit(&mut self, line_start: usize, mut line_end: usize) -> (u64, &[u8]) {
        self.bytes_consumed += (self.start - line_start) as u64;
        self.line_no += 1;
        if line_end > line_start && self.buf[line_end - 1] == b'\r' {
            line_end -= 1;
        }
        let mut line = &self.buf[line_start..line_end];
        if self.line_no == 1 {
            line = line.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(line);
        }
        (self.line_no, line)
    }

    fn refill(&mut self) -> Result<(), LineError> {
        let pending = self.end - self.start;
        if pending >= MAX_LINE_BYTES {
            return Err(LineError::TooLong {
                line: self.line_no + 1,
            });
        }
        self.buf.copy_within(self.start..self.end, 0);
        self.start = 0;
        self.end = pending;
        if self.buf.len() - self.end < self.chunk / 2 {
            self.buf.resize(self.buf.len() + self.chunk, 0);
        }
        loop {
            match self.reader.read(&mut self.buf[self.end..]) {
                Ok(0) => {
                    self.eof = true;
                    return Ok(());
                }
                Ok(n) => {
                    self.end += n;
                    return Ok(());
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e.into()),
            }
        }
    }
}

impl<'a> LineReader<&'a [u8]> {
    /// The lines of bytes already in memory (a file's head, sniffed for its format): the buffer
    /// is sized to them, where a file's reader starts with a 1 MiB one — zeroing that for each
    /// format tried made sniffing a folder of takes cost more than reading their heads.
    pub fn over(bytes: &'a [u8]) -> Self {
        Self::with_chunk(bytes, bytes.len() + 1)
    }
}

/// Splits a line on `sep` into at most `N` fields; returns the number of fields found, which is
/// larger than `N` when there are more (the extra ones are not stored).
#[inline]
pub fn split_fields<'a, const N: usize>(line: &'a [u8], sep: u8, out: &mut [&'a [u8]; N]) -> usize {
    let mut count = 0;
    let mut start = 0;
    for pos in memchr::memchr_iter(sep, line) {
        if count < N {
            out[count] = &line[start..pos];
        }
        count += 1;
        start = pos + 1;
    }
    if count < N {
        out[count] = &line[start..];
    }
    count + 1
}

/// Parses a decimal number (surrounding spaces allowed); `None` for anything else, including
/// NaN and infinities, which no capture log should contain.
#[inline]
pub fn parse_f64(field: &[u8]) -> Option<f64> {
    let field = field.trim_ascii();
    if let Some(v) = parse_plain_decimal(field) {
        return Some(v);
    }
    let value: f64 = fast_float2::parse(field).ok()?;
    value.is_finite().then_some(value)
}

/// Powers of ten that are exact doubles.
const EXACT_POWERS_OF_TEN: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// The common case of a log's numbers, `[-]digits[.digits]` with at most 19 digits, read
/// exactly: the digits as an integer `m` and `k` decimals give `m / 10^k`, and when `m ≤ 2⁵³`
/// and `k ≤ 22` both are exact doubles, so the one division rounds correctly — the same double
/// any correct parser gives (Clinger's fast path). `None` for anything else, which the full
/// parser then reads.
#[inline]
fn parse_plain_decimal(field: &[u8]) -> Option<f64> {
    plain_decimal_prefix(field, 0).and_then(|(v, end)| (end == field.len()).then_some(v))
}

/// [`parse_plain_decimal`]'s number at the start of `bytes[start..]`, and where it ends: a row
/// reader checks that a delimiter follows, and so reads a row in one pass. `None` where the
/// plain form does not apply (not a digit after the sign, `1.` or more than 19 digits, …).
#[inline]
pub fn plain_decimal_prefix(bytes: &[u8], start: usize) -> Option<(f64, usize)> {
    let negative = bytes.get(start)? == &b'-';
    let digits_start = start + usize::from(negative);
    let (whole_end, mut mantissa) = digit_run(bytes, digits_start, 0);
    let whole = whole_end - digits_start;
    let mut i = whole_end;
    let mut decimals = 0;
    if bytes.get(i) == Some(&b'.') {
        (i, mantissa) = digit_run(bytes, i + 1, mantissa);
        decimals = i - whole_end - 1;
        // Digits on both sides of the point (`1.` and `.5` are the full parser's to judge).
        if whole == 0 || decimals == 0 {
            return None;
        }
    }
    if whole == 0 || whole + decimals > 19 || mantissa > 1 << 53 || decimals > 22 {
        return None;
    }
    let value = mantissa as f64 / EXACT_POWERS_OF_TEN[decimals];
    Some((if negative { -value } else { value }, i))
}

/// The digits of `bytes` from `start` on, appended to `mantissa`'s: where they end, and the
/// mantissa (wrapping; the caller bounds the digit count).
#[inline]
fn digit_run(bytes: &[u8], start: usize, mut mantissa: u64) -> (usize, u64) {
    let mut i = start;
    while let Some(&b) = bytes.get(i) {
        let d = b.wrapping_sub(b'0');
        if d > 9 {
            break;
        }
        mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d));
        i += 1;
    }
    (i, mantissa)
}

/// Explains why a field is not a finite number, for line reports.
pub fn number_problem(field: &[u8]) -> &'static str {
    let t = field.trim_ascii().to_ascii_lowercase();
    if t.is_empty() {
        "is empty"
    } else if t.contains(&b'n') && (t.ends_with(b"nan") || t.starts_with(b"nan")) {
        "is NaN"
    } else if t.ends_with(b"inf") || t.ends_with(b"infinity") {
        "is infinite"
    } else if fast_float2::parse::<f64, _>(&t).is_ok() {
        "overflows to infinity"
    } else {
        "is not a number"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn collect(data: &[u8]) -> Vec<(u64, Vec<u8>)> {
        let mut r = LineReader::new(data);
        let mut out = vec![];
        while let Some((n, l)) = r.next_line().unwrap() {
            out.push((n, l.to_vec()));
        }
        out
    }

    #[test]
    fn splits_lf_crlf_bom_and_last_line_without_newline() {
        let lines = collect(b"\xEF\xBB\xBFa,b\r\n\r\nc\nd");
        assert_eq!(
            lines,
            vec![
                (1, b"a,b".to_vec()),
                (2, b"".to_vec()),
                (3, b"c".to_vec()),
                (4, b"d".to_vec())
            ]
        );
        assert!(collect(b"").is_empty());
    }

    #[test]
    fn lines_across_chunk_boundaries() {
        let line = "x".repeat(1000);
        let text: String = (0..3000).map(|i| format!("{i},{line}\n")).collect();
        let lines = collect(text.as_bytes());
        assert_eq!(lines.len(), 3000);
        assert_eq!(lines[2999].1, format!("2999,{line}").into_bytes());
    }

    #[test]
    fn too_long_line_is_an_error_not_a_hang() {
        let data = vec![b'a'; MAX_LINE_BYTES + 10];
        let mut r = LineReader::new(&data[..]);
        assert!(matches!(r.next_line(), Err(LineError::TooLong { line: 1 })));
    }

    /// The plain-decimal fast path gives the very double the full parser gives, for numbers as
    /// logs write them and for the limits of the fast path (2⁵³, 19 digits, 22 decimals).
    #[test]
    fn the_fast_path_agrees_with_the_full_parser() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut fields: Vec<String> = vec![
            "9007199254740992".into(),
            "9007199254740993".into(),
            "0.9007199254740993".into(),
            "1234567890123456789".into(),
            "12345678901234567890".into(),
            "0.0000000000000000000001".into(),
            "0.00000000000000000000001".into(),
            "-0".into(),
            "00012.5000".into(),
        ];
        for _ in 0..200_000 {
            let digits = 1 + next() % 19;
            let text: String = (0..digits)
                .map(|_| char::from(b'0' + (next() % 10) as u8))
                .collect();
            let point = next() % (digits + 1);
            let mut field = if point == 0 || point == digits {
                text
            } else {
                format!("{}.{}", &text[..point as usize], &text[point as usize..])
            };
            if next() % 2 == 0 {
                field.insert(0, '-');
            }
            fields.push(field);
        }
        for field in fields {
            let full: Option<f64> = fast_float2::parse(field.as_bytes()).ok();
            assert_eq!(
                parse_f64(field.as_bytes()).map(f64::to_bits),
                full.map(f64::to_bits),
                "{field}"
            );
            // In a row, with more bytes after it: the same number, and it ends where the field
            // does.
            let row = format!("{field},0.25,pelvis");
            if let Some((value, end)) = plain_decimal_prefix(row.as_bytes(), 0) {
                assert_eq!(Some(value.to_bits()), full.map(f64::to_bits), "{row}");
                assert_eq!(end, field.len(), "{row}");
            }
        }
    }

    #[test]
    fn fields_and_numbers() {
        let mut f = [&b""[..]; 3];
        assert_eq!(split_fields(b"1,2,3,4", b',', &mut f), 4);
        assert_eq!(f, [&b"1"[..], b"2", b"3"]);
        assert_eq!(split_fields(b"", b',', &mut f), 1);
        assert_eq!(parse_f64(b" -12.5 "), Some(-12.5));
        assert_eq!(parse_f64(b"nan"), None);
        assert_eq!(parse_f64(b"1e999"), None);
        assert_eq!(parse_f64(b"1.2.3"), None);
        assert_eq!(
            parse_f64(b"-0.000000").map(f64::to_bits),
            Some((-0.0f64).to_bits())
        );
        assert_eq!(parse_f64(b"1."), Some(1.0));
        assert_eq!(parse_f64(b".5"), Some(0.5));
        assert_eq!(parse_f64(b"+2.25"), Some(2.25));
        assert_eq!(parse_f64(b"-"), None);
        assert_eq!(parse_f64(b"1-2"), None);
        assert_eq!(number_problem(b"NaN"), "is NaN");
        assert_eq!(number_problem(b"-inf"), "is infinite");
        assert_eq!(number_problem(b"1e999"), "overflows to infinity");
        assert_eq!(number_problem(b"abc"), "is not a number");
    }
}
