//! The BVH reader: tolerant of layout, strict about structure, never panics.

use super::{Bvh, BvhError, BvhJoint, Channel};
use nalgebra::Vector3;
use std::io::{BufRead, BufReader, Read};

/// The largest `Frames:` count accepted (about 9.6 days at 120 Hz). Larger counts are refused
/// before anything is read; the values themselves are only ever stored as they are read.
pub const MAX_FRAMES: u64 = 100_000_000;

/// The longest line the reader accepts, in bytes without its line end: 1 MiB, over a hundred
/// times the frame line of a thousand-joint rig. A longer line is refused once its first
/// `MAX_LINE_BYTES + 1` bytes are read, so no line is ever held whole past the limit.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// A line as read: its 1-based number, its text (at most `MAX_LINE_BYTES + 1` bytes), and
/// whether it was cut there, being longer than [`MAX_LINE_BYTES`].
struct Line<'a> {
    n: usize,
    text: &'a [u8],
    cut: bool,
}

impl<'a> Line<'a> {
    /// The whole line, or an error naming it and the limit when it was cut.
    fn whole(self) -> Result<(usize, &'a [u8]), BvhError> {
        if self.cut {
            return Err(too_long(self.n));
        }
        Ok((self.n, self.text))
    }
}

fn too_long(n: usize) -> BvhError {
    error(
        n,
        format!(
            "the line is longer than {MAX_LINE_BYTES} bytes, the longest line the BVH reader \
             accepts; expected a BVH file with one frame per line"
        ),
    )
}

/// Splits input into lines, numbered from 1, as it reads; `\n`, `\r\n` and a lone `\r` all end
/// a line. A line is held in one buffer, never past [`MAX_LINE_BYTES`]` + 1` bytes.
struct Lines<R> {
    reader: R,
    buf: Vec<u8>,
    line: usize,
    /// The last line ended with `\r`: a `\n` right after belongs to it.
    pending_cr: bool,
    /// Bytes consumed so far.
    consumed: u64,
}

impl<R: BufRead> Lines<R> {
    fn new(reader: R) -> Lines<R> {
        Lines {
            reader,
            buf: Vec::new(),
            line: 0,
            pending_cr: false,
            consumed: 0,
        }
    }

    /// The number of the last line returned (at least 1), for errors at the end of the input.
    fn last_line(&self) -> usize {
        self.line.max(1)
    }

    fn consume(&mut self, n: usize) {
        self.reader.consume(n);
        self.consumed += n as u64;
    }

    /// The next line; a UTF-8 byte order mark at the start of line 1 is removed.
    fn next_line(&mut self) -> Result<Option<Line<'_>>, BvhError> {
        self.buf.clear();
        let mut started = false;
        let mut cut = false;
        loop {
            let available = match self.reader.fill_buf() {
                Ok(bytes) => bytes,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(error(self.line + 1, format!("cannot read: {e}"))),
            };
            if available.is_empty() {
                self.pending_cr = false;
                if !started {
                    return Ok(None);
                }
                break;
            }
            let skip = usize::from(self.pending_cr && available[0] == b'\n');
            self.pending_cr = false;
            let rest = &available[skip..];
            let room = MAX_LINE_BYTES + 1 - self.buf.len();
            match memchr::memchr2(b'\n', b'\r', rest) {
                Some(i) if i < room => {
                    self.buf.extend_from_slice(&rest[..i]);
                    self.pending_cr = rest[i] == b'\r';
                    self.consume(skip + i + 1);
                    break;
                }
                found => {
                    // No line end within reach: keep what fits, and stop at the limit.
                    let take = found.unwrap_or(rest.len()).min(room);
                    self.buf.extend_from_slice(&rest[..take]);
                    started |= take > 0;
                    self.consume(skip + take);
                    if self.buf.len() > MAX_LINE_BYTES {
                        cut = true;
                        break;
                    }
                }
            }
        }
        self.line += 1;
        let mut text = &self.buf[..];
        if self.line == 1 {
            text = text.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(text);
        }
        Ok(Some(Line {
            n: self.line,
            text,
            cut,
        }))
    }
}

fn tokens(line: &[u8]) -> Vec<&[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
        .collect()
}

fn show(token: &[u8]) -> String {
    const MAX: usize = 40;
    let text = String::from_utf8_lossy(token);
    if text.chars().count() > MAX {
        format!("{}…", text.chars().take(MAX).collect::<String>())
    } else {
        text.into_owned()
    }
}

fn error(line: usize, message: impl Into<String>) -> BvhError {
    BvhError {
        line,
        message: message.into(),
    }
}

fn is(token: &[u8], keyword: &str) -> bool {
    token.eq_ignore_ascii_case(keyword.as_bytes())
}

/// A finite number, or `None`.
fn number(token: &[u8]) -> Option<f64> {
    let text = std::str::from_utf8(token).ok()?;
    // Rust accepts "inf", "nan" and "infinity"; overflowing exponents give infinities.
    text.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// What the hierarchy parser expects next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expect {
    Hierarchy,
    Root,
    /// `{` after ROOT, JOINT (the joint's index) or End Site (`None`).
    OpenBrace(Option<usize>),
    /// Inside a joint's braces.
    JointBody,
    /// Inside an End Site's braces.
    EndSiteBody,
    /// After the root's closing brace.
    Motion,
}

/// An open `{`.
struct Open {
    /// The joint, or `None` for an End Site (whose joint is the enclosing one).
    joint: Option<usize>,
    line: usize,
    offset_seen: bool,
    channels_seen: bool,
    /// A child JOINT or End Site has been opened: OFFSET and CHANNELS must come before.
    child_seen: bool,
}

fn describe(expect: Expect, joints: &[BvhJoint], stack: &[Open]) -> String {
    let opened = |o: &Open| match o.joint {
        Some(j) => format!("joint `{}` (opened at line {})", joints[j].name, o.line),
        None => format!("End Site (opened at line {})", o.line),
    };
    match expect {
        Expect::Hierarchy => "expected `HIERARCHY`".into(),
        Expect::Root => "expected `ROOT <name>`".into(),
        Expect::OpenBrace(Some(j)) => {
            format!("expected `{{` after JOINT/ROOT `{}`", joints[j].name)
        }
        Expect::OpenBrace(None) => "expected `{` after End Site".into(),
        Expect::JointBody | Expect::EndSiteBody => match stack.last() {
            Some(o) => format!("expected `}}` closing {}", opened(o)),
            None => "expected `}`".into(),
        },
        Expect::Motion => "expected `MOTION`".into(),
    }
}

/// Reads a BVH file from its bytes. See the module documentation for what is tolerated and what
/// is refused.
pub fn parse(bytes: &[u8]) -> Result<Bvh, BvhError> {
    read_lines(Lines::new(bytes), Some(bytes.len() as u64))
}

/// Reads a BVH file from a reader as it goes (buffered here): no line is held past
/// [`MAX_LINE_BYTES`], and a frame line is judged as it is split, so a file of any size costs
/// the reader no more than its frames' values. Errors as [`parse`]'s; one that fails to read
/// names the line it was reading.
pub fn read(reader: impl Read) -> Result<Bvh, BvhError> {
    read_lines(Lines::new(BufReader::with_capacity(1 << 16, reader)), None)
}

/// `size_hint`: the input's length when known, which bounds what is reserved for the values.
fn read_lines<R: BufRead>(mut lines: Lines<R>, size_hint: Option<u64>) -> Result<Bvh, BvhError> {
    let joints = parse_hierarchy(&mut lines)?;

    let mut channel_start = Vec::with_capacity(joints.len());
    let mut channel_count = 0usize;
    for j in &joints {
        channel_start.push(channel_count);
        channel_count += j.channels.len();
    }

    let (frame_count, frame_time_s, values) = parse_motion(&mut lines, channel_count, size_hint)?;
    Ok(Bvh {
        joints,
        channel_start,
        channel_count,
        frame_time_s,
        frame_count,
        values,
    })
}

/// Parses up to and including the `MOTION` line.
fn parse_hierarchy<R: BufRead>(lines: &mut Lines<R>) -> Result<Vec<BvhJoint>, BvhError> {
    let mut joints: Vec<BvhJoint> = Vec::new();
    let mut stack: Vec<Open> = Vec::new();
    let mut expect = Expect::Hierarchy;

    while let Some(line) = lines.next_line()? {
        let (n, line) = line.whole()?;
        let toks = tokens(line);
        let mut i = 0;
        while i < toks.len() {
            let tok = toks[i];
            i += 1;
            match expect {
                Expect::Hierarchy => {
                    if !is(tok, "HIERARCHY") {
                        return Err(error(
                            n,
                            format!("expected `HIERARCHY`, found `{}`", show(tok)),
                        ));
                    }
                    expect = Expect::Root;
                }
                Expect::Root => {
                    if !is(tok, "ROOT") {
                        return Err(error(
                            n,
                            format!("expected `ROOT <name>`, found `{}`", show(tok)),
                        ));
                    }
                    let name = joint_name(&toks, &mut i)
                        .ok_or_else(|| error(n, "expected a joint name after `ROOT`"))?;
                    joints.push(BvhJoint {
                        name,
                        parent: None,
                        offset: Vector3::zeros(),
                        channels: Vec::new(),
                        end_site: None,
                    });
                    expect = Expect::OpenBrace(Some(0));
                }
                Expect::OpenBrace(joint) => {
                    if tok != b"{" {
                        return Err(error(
                            n,
                            format!(
                                "{}, found `{}`",
                                describe(expect, &joints, &stack),
                                show(tok)
                            ),
                        ));
                    }
                    stack.push(Open {
                        joint,
                        line: n,
                        offset_seen: false,
                        channels_seen: false,
                        child_seen: false,
                    });
                    expect = if joint.is_some() {
                        Expect::JointBody
                    } else {
                        Expect::EndSiteBody
                    };
                }
                Expect::JointBody => {
                    let Some(open) = stack.last_mut() else {
                        return Err(error(n, "internal: no open joint"));
                    };
                    let Some(j) = open.joint else {
                        return Err(error(n, "internal: End Site in joint state"));
                    };
                    if is(tok, "OFFSET") {
                        if open.offset_seen {
                            return Err(error(
                                n,
                                format!("joint `{}` has a second OFFSET", joints[j].name),
                            ));
                        }
                        if open.child_seen {
                            return Err(error(
                                n,
                                format!(
                                    "OFFSET of joint `{}` must come before its children",
                                    joints[j].name
                                ),
                            ));
                        }
                        joints[j].offset = offset(&toks, &mut i, n)?;
                        open.offset_seen = true;
                    } else if is(tok, "CHANNELS") {
                        if open.channels_seen {
                            return Err(error(
                                n,
                                format!("joint `{}` has a second CHANNELS line", joints[j].name),
                            ));
                        }
                        if open.child_seen {
                            return Err(error(
                                n,
                                format!(
                                    "CHANNELS of joint `{}` must come before its children",
                                    joints[j].name
                                ),
                            ));
                        }
                        joints[j].channels = channels(&toks, &mut i, n)?;
                        open.channels_seen = true;
                    } else if is(tok, "JOINT") {
                        if !open.offset_seen {
                            return Err(error(
                                n,
                                format!(
                                    "expected OFFSET of joint `{}` before its child JOINT",
                                    joints[j].name
                                ),
                            ));
                        }
                        open.child_seen = true;
                        let name = joint_name(&toks, &mut i)
                            .ok_or_else(|| error(n, "expected a joint name after `JOINT`"))?;
                        joints.push(BvhJoint {
                            name,
                            parent: Some(j),
                            offset: Vector3::zeros(),
                            channels: Vec::new(),
                            end_site: None,
                        });
                        expect = Expect::OpenBrace(Some(joints.len() - 1));
                    } else if is(tok, "End") {
                        if !toks.get(i).is_some_and(|t| is(t, "Site")) {
                            return Err(error(n, "expected `Site` after `End`"));
                        }
                        if !open.offset_seen {
                            return Err(error(
                                n,
                                format!(
                                    "expected OFFSET of joint `{}` before its End Site",
                                    joints[j].name
                                ),
                            ));
                        }
                        open.child_seen = true;
                        // Anything after `End Site` up to a `{` is ignored (Blender does the same).
                        i += 1;
                        while i < toks.len() && toks[i] != b"{" {
                            i += 1;
                        }
                        expect = Expect::OpenBrace(None);
                    } else if tok == b"}" {
                        if !open.offset_seen {
                            return Err(error(
                                n,
                                format!(
                                    "expected OFFSET in joint `{}` before `}}`",
                                    joints[j].name
                                ),
                            ));
                        }
                        stack.pop();
                        expect = match stack.last() {
                            None => Expect::Motion,
                            Some(_) => Expect::JointBody,
                        };
                    } else if is(tok, "MOTION") {
                        let open_line = open.line;
                        return Err(error(
                            n,
                            format!(
                                "expected `}}` closing joint `{}` (opened at line {open_line}) before MOTION: a `}}` is missing",
                                joints[j].name
                            ),
                        ));
                    } else {
                        return Err(error(
                            n,
                            format!(
                                "expected OFFSET, CHANNELS, JOINT, End Site or `}}` in joint `{}`, found `{}`",
                                joints[j].name,
                                show(tok)
                            ),
                        ));
                    }
                }
                Expect::EndSiteBody => {
                    let Some(open) = stack.last_mut() else {
                        return Err(error(n, "internal: no open End Site"));
                    };
                    if is(tok, "OFFSET") {
                        if open.offset_seen {
                            return Err(error(n, "End Site has a second OFFSET"));
                        }
                        let v = offset(&toks, &mut i, n)?;
                        open.offset_seen = true;
                        // The End Site belongs to the joint that encloses it; keep the first.
                        let owner = stack.iter().rev().find_map(|o| o.joint);
                        if let Some(j) = owner
                            && joints[j].end_site.is_none()
                        {
                            joints[j].end_site = Some(v);
                        }
                    } else if is(tok, "CHANNELS") && toks.get(i).is_some_and(|t| t == b"0") {
                        i += 1; // `CHANNELS 0` in an End Site says nothing.
                    } else if tok == b"}" {
                        if !open.offset_seen {
                            return Err(error(n, "expected OFFSET in End Site before `}`"));
                        }
                        stack.pop();
                        expect = Expect::JointBody;
                    } else {
                        return Err(error(
                            n,
                            format!("expected OFFSET or `}}` in End Site, found `{}`", show(tok)),
                        ));
                    }
                }
                Expect::Motion => {
                    if is(tok, "MOTION") {
                        if let Some(extra) = toks.get(i) {
                            return Err(error(
                                n,
                                format!("expected nothing after `MOTION`, found `{}`", show(extra)),
                            ));
                        }
                        return Ok(joints);
                    }
                    if is(tok, "ROOT") {
                        return Err(error(
                            n,
                            "expected `MOTION`: files with a second ROOT are not supported",
                        ));
                    }
                    if tok == b"}" {
                        return Err(error(
                            n,
                            "unbalanced `}`: the root joint is already closed; expected `MOTION`",
                        ));
                    }
                    return Err(error(
                        n,
                        format!("expected `MOTION`, found `{}`", show(tok)),
                    ));
                }
            }
        }
    }
    Err(error(
        lines.last_line(),
        format!(
            "unexpected end of file: {}",
            describe(expect, &joints, &stack)
        ),
    ))
}

/// The name after ROOT/JOINT: the rest of the line up to a `{`, words joined with `_`.
fn joint_name(toks: &[&[u8]], i: &mut usize) -> Option<String> {
    let mut words = Vec::new();
    while *i < toks.len() && toks[*i] != b"{" {
        words.push(String::from_utf8_lossy(toks[*i]).into_owned());
        *i += 1;
    }
    if words.is_empty() {
        None
    } else {
        Some(words.join("_"))
    }
}

fn offset(toks: &[&[u8]], i: &mut usize, n: usize) -> Result<Vector3<f64>, BvhError> {
    let mut v = Vector3::zeros();
    for (axis, name) in ["x", "y", "z"].iter().enumerate() {
        let Some(tok) = toks.get(*i) else {
            return Err(error(
                n,
                format!("expected 3 numbers after OFFSET, found {axis}"),
            ));
        };
        v[axis] = number(tok).ok_or_else(|| {
            error(
                n,
                format!(
                    "expected a finite number for OFFSET {name}, found `{}`",
                    show(tok)
                ),
            )
        })?;
        *i += 1;
    }
    Ok(v)
}

fn channels(toks: &[&[u8]], i: &mut usize, n: usize) -> Result<Vec<Channel>, BvhError> {
    let Some(count_tok) = toks.get(*i) else {
        return Err(error(n, "expected the number of channels after CHANNELS"));
    };
    *i += 1;
    let count: usize = std::str::from_utf8(count_tok)
        .ok()
        .and_then(|t| t.parse().ok())
        .filter(|&c| c <= 6)
        .ok_or_else(|| {
            error(
                n,
                format!(
                    "expected a channel count from 0 to 6 after CHANNELS, found `{}`",
                    show(count_tok)
                ),
            )
        })?;
    let listed = &toks[*i..];
    if listed.len() != count {
        return Err(error(
            n,
            format!(
                "CHANNELS says {count} channels but lists {}; expected {count} channels",
                listed.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(count);
    for tok in listed {
        let c = Channel::from_name(tok).ok_or_else(|| {
            error(
                n,
                format!(
                    "expected a channel name (Xposition ... Zrotation), found `{}`",
                    show(tok)
                ),
            )
        })?;
        if out.contains(&c) {
            return Err(error(n, format!("channel {c} is listed twice")));
        }
        out.push(c);
    }
    *i = toks.len();
    Ok(out)
}

/// The next line with something on it: its number and its words joined.
fn next_nonblank<R: BufRead>(lines: &mut Lines<R>) -> Result<Option<(usize, Vec<u8>)>, BvhError> {
    while let Some(line) = lines.next_line()? {
        let (n, line) = line.whole()?;
        let toks = tokens(line);
        if !toks.is_empty() {
            return Ok(Some((n, toks.concat())));
        }
    }
    Ok(None)
}

/// Strips an ASCII-case-insensitive prefix.
fn strip_prefix_ci<'a>(text: &'a [u8], prefix: &str) -> Option<&'a [u8]> {
    let p = prefix.as_bytes();
    (text.len() >= p.len() && text[..p.len()].eq_ignore_ascii_case(p)).then(|| &text[p.len()..])
}

/// `Frames: N`, `Frame Time: t`, then the frame lines.
fn parse_motion<R: BufRead>(
    lines: &mut Lines<R>,
    channel_count: usize,
    size_hint: Option<u64>,
) -> Result<(usize, f64, Vec<f64>), BvhError> {
    // `Frames: 12`, `Frames:\t12`, `Frames:12`, `Frames 12`: join the words and read past the
    // keyword and an optional colon.
    let Some((n, joined)) = next_nonblank(lines)? else {
        return Err(error(
            lines.last_line(),
            "unexpected end of file: expected `Frames: <count>`",
        ));
    };
    let frames_text = strip_prefix_ci(&joined, "frames")
        .map(|r| r.strip_prefix(b":").unwrap_or(r))
        .ok_or_else(|| {
            error(
                n,
                format!("expected `Frames: <count>`, found `{}`", show(&joined)),
            )
        })?;
    let frame_count: u64 = std::str::from_utf8(frames_text)
        .ok()
        .filter(|t| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit()))
        .and_then(|t| t.parse().ok())
        .ok_or_else(|| {
            error(
                n,
                format!(
                    "expected a whole number of frames after `Frames:`, found `{}`",
                    show(frames_text)
                ),
            )
        })?;
    if frame_count > MAX_FRAMES {
        return Err(error(
            n,
            format!("Frames: {frame_count} is more than the {MAX_FRAMES} frames accepted"),
        ));
    }
    let frame_count = frame_count as usize;

    let Some((n, joined)) = next_nonblank(lines)? else {
        return Err(error(
            lines.last_line(),
            "unexpected end of file: expected `Frame Time: <seconds>`",
        ));
    };
    let time_text = strip_prefix_ci(&joined, "frametime")
        .map(|r| r.strip_prefix(b":").unwrap_or(r))
        .ok_or_else(|| {
            error(
                n,
                format!(
                    "expected `Frame Time: <seconds>`, found `{}`",
                    show(&joined)
                ),
            )
        })?;
    let frame_time_s = number(time_text).filter(|&t| t > 0.0).ok_or_else(|| {
        error(
            n,
            format!(
                "expected a positive frame time in seconds after `Frame Time:`, found `{}`",
                show(time_text)
            ),
        )
    })?;

    // Reserve only what the remaining bytes could hold (each value takes at least 2 bytes), or
    // at most a million values when the length is not known; more grow as they are read.
    let claimed = frame_count.saturating_mul(channel_count);
    let room = match size_hint {
        Some(len) => {
            usize::try_from(len.saturating_sub(lines.consumed) / 2 + 1).unwrap_or(usize::MAX)
        }
        None => 1 << 20,
    };
    let mut values = Vec::with_capacity(claimed.min(room));
    let mut frames_read = 0usize;
    while let Some(Line { n, text, cut }) = lines.next_line()? {
        // Split as read: values up to the channel count are stored, the rest only counted.
        let mut toks = text
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty());
        let Some(first) = toks.next() else {
            if cut {
                return Err(too_long(n));
            }
            continue;
        };
        if channel_count == 0 || frames_read == frame_count {
            return Err(error(
                n,
                if channel_count == 0 {
                    "expected empty frame lines: the hierarchy has no channels".to_string()
                } else {
                    format!(
                        "expected the end of the file after {frame_count} frames (`Frames: {frame_count}`), found more motion data"
                    )
                },
            ));
        }
        let mut count = 0usize;
        let mut bad: Option<(usize, String)> = None;
        for tok in std::iter::once(first).chain(toks) {
            count += 1;
            if count > channel_count {
                continue;
            }
            match number(tok) {
                Some(v) => values.push(v),
                None => {
                    if bad.is_none() {
                        bad = Some((count, show(tok)));
                    }
                }
            }
        }
        let expected = format!(
            "expected {channel_count} values (one per channel of the hierarchy) on frame {frames_read}"
        );
        if cut {
            // Only the first MAX_LINE_BYTES + 1 bytes of the line were read.
            return Err(error(
                n,
                if count > channel_count {
                    format!(
                        "{expected}, found at least {count} in its first {} bytes (a line longer \
                         than {MAX_LINE_BYTES} bytes, the longest the BVH reader accepts)",
                        MAX_LINE_BYTES + 1
                    )
                } else {
                    too_long(n).message
                },
            ));
        }
        if count != channel_count {
            return Err(error(n, format!("{expected}, found {count}")));
        }
        if let Some((k, tok)) = bad {
            return Err(error(
                n,
                format!(
                    "expected a finite number for value {k} of frame {frames_read}, found `{tok}`"
                ),
            ));
        }
        frames_read += 1;
    }
    if channel_count > 0 && frames_read != frame_count {
        return Err(error(
            lines.last_line(),
            format!(
                "unexpected end of file: expected {frame_count} frames (`Frames: {frame_count}`), found {frames_read}"
            ),
        ));
    }
    Ok((frame_count, frame_time_s, values))
}
