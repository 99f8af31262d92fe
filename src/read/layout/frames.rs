//! A layout's frames from bytes as they come (a file at once, or a port's reads): text lines or
//! binary frames found by their start bytes, each field decoded to a number. Memory is bounded:
//! a text line longer than [`MAX_LINE_BYTES`] is dropped as it arrives, and a binary frame is at
//! most [`MAX_FRAME_BYTES`] (the layout's longest, checked when it is loaded).

use super::{ChecksumKind, Encoding, Endian, FrameKind, Layout, Meaning, Over};

/// The longest binary frame a layout may declare, bytes.
pub const MAX_FRAME_BYTES: usize = 4096;
/// The longest text line, bytes (as every text reader: [`crate::read::lines::MAX_LINE_BYTES`]).
pub const MAX_LINE_BYTES: usize = crate::read::lines::MAX_LINE_BYTES;

/// One decoded frame: where it was, its fields' numbers (scaled), and its `type`.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// 1-based line of a text frame (0 for binary frames).
    pub line: u64,
    /// Byte offset of the frame's first byte in the stream.
    pub offset: u64,
    /// A text frame's line (binary frames keep none).
    pub raw: Vec<u8>,
    pub kind: Option<i64>,
    values: Vec<(Meaning, f64)>,
}

impl Frame {
    /// The value of a meaning, when the frame has it.
    pub fn get(&self, m: Meaning) -> Option<f64> {
        self.values.iter().find(|(k, _)| *k == m).map(|(_, v)| *v)
    }
}

/// A frame that did not decode: where, why, and a text frame's line.
#[derive(Debug, Clone, PartialEq)]
pub struct BadFrame {
    pub line: u64,
    pub offset: u64,
    pub reason: String,
    pub raw: Vec<u8>,
}

/// What a decoder made of the bytes so far (drained by the caller as it likes).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Decoded {
    pub frames: Vec<Frame>,
    pub bad: Vec<BadFrame>,
    /// Binary: bytes before a start sequence that belong to no frame.
    pub skipped_bytes: u64,
    pub first_skipped_offset: Option<u64>,
}

/// An incremental decoder of a layout's stream (the layout is given to each call).
#[derive(Debug, Default)]
pub struct Decoder {
    buf: Vec<u8>,
    /// The stream offset of `buf[0]`.
    buf_offset: u64,
    /// Lines completed so far (text).
    line: u64,
    /// Text: the rest of an over-long line is being dropped.
    discarding: bool,
}

impl Decoder {
    pub fn new() -> Decoder {
        Decoder::default()
    }

    /// Bytes held for a frame or line not complete yet.
    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// Feeds bytes; complete frames (and bad ones) go to `out`.
    pub fn push(&mut self, layout: &Layout, bytes: &[u8], out: &mut Decoded) {
        self.buf.extend_from_slice(bytes);
        match layout.frame {
            FrameKind::Text => self.text(layout, out, false),
            FrameKind::Binary => self.binary(layout, out, false),
        }
    }

    /// The stream's end: a last line without its newline is a frame; an incomplete binary frame
    /// is a bad one.
    pub fn finish(&mut self, layout: &Layout, out: &mut Decoded) {
        match layout.frame {
            FrameKind::Text => self.text(layout, out, true),
            FrameKind::Binary => self.binary(layout, out, true),
        }
    }

    fn text(&mut self, layout: &Layout, out: &mut Decoded, end: bool) {
        let mut pos = 0;
        // `pos` passes the end only after a last line without its newline.
        while pos <= self.buf.len() {
            let newline = memchr::memchr(b'\n', &self.buf[pos..]).map(|i| pos + i);
            let Some(stop) = newline.or((end && pos < self.buf.len()).then_some(self.buf.len()))
            else {
                break;
            };
            self.line += 1;
            let offset = self.buf_offset + pos as u64;
            if std::mem::take(&mut self.discarding) {
                pos = stop + 1;
                continue;
            }
            let mut line = &self.buf[pos..stop];
            if line.last() == Some(&b'\r') {
                line = &line[..line.len() - 1];
            }
            if !line.iter().all(u8::is_ascii_whitespace) {
                match decode_text(layout, line) {
                    Ok((kind, values)) => out.frames.push(Frame {
                        line: self.line,
                        offset,
                        raw: line.to_vec(),
                        kind,
                        values,
                    }),
                    Err(reason) => out.bad.push(BadFrame {
                        line: self.line,
                        offset,
                        reason,
                        raw: line.to_vec(),
                    }),
                }
            }
            pos = stop + 1;
        }
        let pos = pos.min(self.buf.len());
        self.buf.drain(..pos);
        self.buf_offset += pos as u64;
        if self.buf.len() > MAX_LINE_BYTES {
            // Reported once, at the line it starts; the rest of it is dropped as it arrives.
            out.bad.push(BadFrame {
                line: self.line + 1,
                offset: self.buf_offset,
                reason: format!("a line longer than {MAX_LINE_BYTES} bytes"),
                raw: self.buf[..64].to_vec(),
            });
            self.buf_offset += self.buf.len() as u64;
            self.buf.clear();
            self.discarding = true;
        }
    }

    fn binary(&mut self, layout: &Layout, out: &mut Decoded, end: bool) {
        let start = &layout.start;
        let mut pos = 0;
        loop {
            let found = memchr::memmem::find(&self.buf[pos..], start).map(|i| pos + i);
            let Some(at) = found else {
                // Keep what could still begin a start sequence.
                let keep = if end { 0 } else { start.len() - 1 };
                let upto = self.buf.len().saturating_sub(keep).max(pos);
                self.skip(out, pos, upto);
                pos = upto;
                break;
            };
            self.skip(out, pos, at);
            match decode_binary(layout, &self.buf[at..]) {
                Binary::Frame(size, kind, values) => {
                    out.frames.push(Frame {
                        line: 0,
                        offset: self.buf_offset + at as u64,
                        raw: Vec::new(),
                        kind,
                        values,
                    });
                    pos = at + size;
                }
                Binary::Bad(reason) => {
                    out.bad.push(BadFrame {
                        line: 0,
                        offset: self.buf_offset + at as u64,
                        reason,
                        raw: Vec::new(),
                    });
                    // The next start may lie inside this frame.
                    pos = at + 1;
                }
                Binary::Incomplete => {
                    if end {
                        out.bad.push(BadFrame {
                            line: 0,
                            offset: self.buf_offset + at as u64,
                            reason: "an incomplete frame at the end".into(),
                            raw: Vec::new(),
                        });
                        pos = self.buf.len();
                    } else {
                        pos = at;
                    }
                    break;
                }
            }
        }
        self.buf.drain(..pos);
        self.buf_offset += pos as u64;
    }

    fn skip(&self, out: &mut Decoded, from: usize, to: usize) {
        if to > from {
            out.skipped_bytes += (to - from) as u64;
            out.first_skipped_offset
                .get_or_insert(self.buf_offset + from as u64);
        }
    }
}

/// A text frame's fields: its type and its values, or why not.
type Values = (Option<i64>, Vec<(Meaning, f64)>);

fn decode_text(layout: &Layout, line: &[u8]) -> Result<Values, String> {
    let text = std::str::from_utf8(line).map_err(|_| "not UTF-8 text".to_string())?;
    let tokens: Vec<&str> = match &layout.separator {
        Some(sep) => text.split(sep.as_str()).map(str::trim).collect(),
        None => text.split_whitespace().collect(),
    };
    let mut values = Vec::new();
    let mut kind = None;
    let mut next = 0;
    for (i, field) in layout.fields.iter().enumerate() {
        if field.meaning == Meaning::Values {
            let meanings = values_of(layout, kind)?;
            let rest = &tokens[next.min(tokens.len())..];
            if rest.len() != meanings.len() {
                return Err(format!(
                    "{} values for type {}, expected {}",
                    rest.len(),
                    kind.unwrap_or_default(),
                    meanings.len()
                ));
            }
            for (m, token) in meanings.iter().zip(rest) {
                let v = text_number(field.encoding, token)
                    .map_err(|e| format!("value `{token}`: {e}"))?;
                values.push((*m, v * field.scale.unwrap_or(1.0)));
            }
            next = tokens.len();
            break;
        }
        let token = tokens
            .get(next)
            .ok_or_else(|| format!("{} fields, expected {}", tokens.len(), layout.fields.len()))?;
        next += 1;
        let v = text_number(field.encoding, token)
            .map_err(|e| format!("field {} (`{token}`): {e}", i + 1))?;
        if field.meaning == Meaning::Type {
            kind = Some(type_of(layout, v)?);
        }
        values.push((field.meaning, v * field.scale.unwrap_or(1.0)));
    }
    if next < tokens.len() {
        return Err(format!(
            "{} fields, expected {}",
            tokens.len(),
            layout.fields.len()
        ));
    }
    Ok((kind, values))
}

/// The meanings a frame of type `kind` gives its values.
fn values_of(layout: &Layout, kind: Option<i64>) -> Result<&[Meaning], String> {
    let kind = kind.ok_or("no type before the values")?;
    layout
        .types
        .get(&kind)
        .map(Vec::as_slice)
        .ok_or_else(|| format!("unknown type {kind}"))
}

fn type_of(layout: &Layout, v: f64) -> Result<i64, String> {
    let t = v as i64;
    if t as f64 != v || !layout.types.contains_key(&t) {
        return Err(format!("unknown type {v}"));
    }
    Ok(t)
}

fn text_number(encoding: Encoding, token: &str) -> Result<f64, String> {
    match encoding {
        Encoding::Decimal => token
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| "not a decimal number".to_string()),
        Encoding::HexF32Be | Encoding::HexF32Le => {
            let hex = token
                .strip_prefix("0x")
                .or_else(|| token.strip_prefix("0X"))
                .unwrap_or(token);
            if hex.len() != 8 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
                return Err("not eight hexadecimal digits".into());
            }
            let bits = u32::from_str_radix(hex, 16).map_err(|e| e.to_string())?;
            let bits = if encoding == Encoding::HexF32Le {
                bits.swap_bytes()
            } else {
                bits
            };
            Ok(f64::from(f32::from_bits(bits)))
        }
        _ => Err("a binary encoding in a text frame".into()),
    }
}

enum Binary {
    /// Its size in bytes, its type, its values.
    Frame(usize, Option<i64>, Vec<(Meaning, f64)>),
    Bad(String),
    /// More bytes are needed.
    Incomplete,
}

/// The frame at the start of `bytes` (which begin with the start sequence).
fn decode_binary(layout: &Layout, bytes: &[u8]) -> Binary {
    let mut at = layout.start.len();
    let mut values = Vec::new();
    let mut kind = None;
    let mut length: Option<(f64, usize)> = None;
    for field in &layout.fields {
        let count = if field.meaning == Meaning::Values {
            match values_of(layout, kind) {
                Ok(m) => m.len(),
                Err(e) => return Binary::Bad(e),
            }
        } else {
            1
        };
        for k in 0..count {
            let size = field.encoding.size();
            let Some(field_bytes) = bytes.get(at..at + size) else {
                return Binary::Incomplete;
            };
            let v = binary_number(field.encoding, field_bytes);
            at += size;
            let meaning = if field.meaning == Meaning::Values {
                values_of(layout, kind)
                    .map(|m| m[k])
                    .unwrap_or(Meaning::Skip)
            } else {
                field.meaning
            };
            match meaning {
                Meaning::Type => match type_of(layout, v) {
                    Ok(t) => kind = Some(t),
                    Err(e) => return Binary::Bad(e),
                },
                Meaning::Length => length = Some((v, at)),
                _ => {}
            }
            values.push((meaning, v * field.scale.unwrap_or(1.0)));
        }
    }
    if let Some((declared, after)) = length
        && declared != (at - after) as f64
    {
        return Binary::Bad(format!(
            "the length field says {declared} bytes, the layout {}",
            at - after
        ));
    }
    if let Some(c) = &layout.checksum {
        let size = c.size();
        let Some(stored) = bytes.get(at..at + size) else {
            return Binary::Incomplete;
        };
        let from = match c.over {
            Over::Payload => layout.start.len(),
            Over::Frame => 0,
        };
        let covered = &bytes[from..at];
        let (computed, stored) = match c.kind {
            ChecksumKind::None => (0, 0),
            ChecksumKind::Sum8 => (
                u32::from(covered.iter().fold(0u8, |s, b| s.wrapping_add(*b))),
                u32::from(stored[0]),
            ),
            ChecksumKind::Xor8 => (
                u32::from(covered.iter().fold(0u8, |s, b| s ^ b)),
                u32::from(stored[0]),
            ),
            ChecksumKind::Crc16Ccitt => {
                let crc = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);
                let word = [stored[0], stored[1]];
                let stored = match c.endian {
                    Endian::Le => u16::from_le_bytes(word),
                    Endian::Be => u16::from_be_bytes(word),
                };
                (u32::from(crc.checksum(covered)), u32::from(stored))
            }
        };
        if computed != stored {
            return Binary::Bad(format!(
                "bad checksum: {stored:#x} stored, {computed:#x} computed"
            ));
        }
        at += size;
    }
    Binary::Frame(at, kind, values)
}

fn binary_number(encoding: Encoding, b: &[u8]) -> f64 {
    use Encoding::*;
    let a2 = || [b[0], b[1]];
    let a4 = || [b[0], b[1], b[2], b[3]];
    let a8 = || [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
    match encoding {
        U8 => f64::from(b[0]),
        I8 => f64::from(b[0] as i8),
        U16le => f64::from(u16::from_le_bytes(a2())),
        U16be => f64::from(u16::from_be_bytes(a2())),
        I16le => f64::from(i16::from_le_bytes(a2())),
        I16be => f64::from(i16::from_be_bytes(a2())),
        U32le => f64::from(u32::from_le_bytes(a4())),
        U32be => f64::from(u32::from_be_bytes(a4())),
        I32le => f64::from(i32::from_le_bytes(a4())),
        I32be => f64::from(i32::from_be_bytes(a4())),
        U64le => u64::from_le_bytes(a8()) as f64,
        U64be => u64::from_be_bytes(a8()) as f64,
        I64le => i64::from_le_bytes(a8()) as f64,
        I64be => i64::from_be_bytes(a8()) as f64,
        F32le => f64::from(f32::from_le_bytes(a4())),
        F32be => f64::from(f32::from_be_bytes(a4())),
        F64le => f64::from_le_bytes(a8()),
        F64be => f64::from_be_bytes(a8()),
        Decimal | HexF32Be | HexF32Le => f64::NAN,
    }
}
