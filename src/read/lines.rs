//! Fast line splitting for text logs: large reads, CRLF accepted, 1-based line numbers.

use std::io::{self, Read};

/// Lines longer than this are not text logs (a binary file without newlines, say).
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
}

impl<R: Read> LineReader<R> {
    pub fn new(reader: R) -> Self {
        LineReader {
            reader,
            buf: vec![0; CHUNK_BYTES],
            start: 0,
            end: 0,
            eof: false,
            line_no: 0,
            bytes_consumed: 0,
        }
    }

    /// Bytes of the source consumed so far (for progress and size estimates).
    pub fn bytes_consumed(&self) -> u64 {
        self.bytes_consumed
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
        if self.buf.len() - self.end < CHUNK_BYTES / 2 {
            self.buf.resize(self.buf.len() + CHUNK_BYTES, 0);
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

/// Splits a line on `sep` into at most `N` fields; returns the number of fields found, which is
/// larger than `N` when there are more (the extra ones are not stored).
#[inline]
pub fn split_fields<'a, const N: usize>(line: &'a [u8], sep: u8, out: &mut [&'a [u8]; N]) -> usize {
    let mut count = 0;
    let mut rest = line;
    loop {
        let (field, next) = match memchr::memchr(sep, rest) {
            Some(pos) => (&rest[..pos], Some(&rest[pos + 1..])),
            None => (rest, None),
        };
        if count < N {
            out[count] = field;
        }
        count += 1;
        match next {
            Some(next) => rest = next,
            None => return count,
        }
    }
}

/// Parses a decimal number (surrounding spaces allowed); `None` for anything else, including
/// NaN and infinities, which no capture log should contain.
#[inline]
pub fn parse_f64(field: &[u8]) -> Option<f64> {
    let field = field.trim_ascii();
    let value: f64 = fast_float2::parse(field).ok()?;
    value.is_finite().then_some(value)
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
        assert_eq!(number_problem(b"NaN"), "is NaN");
        assert_eq!(number_problem(b"-inf"), "is infinite");
        assert_eq!(number_problem(b"1e999"), "overflows to infinity");
        assert_eq!(number_problem(b"abc"), "is not a number");
    }
}
