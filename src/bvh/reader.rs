//! The BVH reader: tolerant of layout, strict about structure, never panics.

use super::{Bvh, BvhError, BvhJoint, Channel};
use nalgebra::Vector3;

/// The largest `Frames:` count accepted (about 9.6 days at 120 Hz). Larger counts are refused
/// before anything is read; the values themselves are only ever stored as they are read.
pub const MAX_FRAMES: u64 = 100_000_000;

/// Splits input into lines, numbered from 1; `\n`, `\r\n` and a lone `\r` all end a line.
struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Lines<'a> {
    fn new(bytes: &'a [u8]) -> Lines<'a> {
        let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        Lines {
            bytes,
            pos: 0,
            line: 0,
        }
    }

    /// The number of the last line returned (at least 1), for errors at the end of the input.
    fn last_line(&self) -> usize {
        self.line.max(1)
    }

    fn remaining_bytes(&self) -> usize {
        self.bytes.len() - self.pos
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = (usize, &'a [u8]);

    fn next(&mut self) -> Option<Self::Item> {
        if self.pos >= self.bytes.len() {
            return None;
        }
        let rest = &self.bytes[self.pos..];
        self.line += 1;
        match memchr::memchr2(b'\n', b'\r', rest) {
            Some(i) => {
                let crlf = rest[i] == b'\r' && rest.get(i + 1) == Some(&b'\n');
                self.pos += i + if crlf { 2 } else { 1 };
                Some((self.line, &rest[..i]))
            }
            None => {
                self.pos = self.bytes.len();
                Some((self.line, rest))
            }
        }
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

/// Reads a BVH file. See the module documentation for what is tolerated and what is refused.
pub fn parse(bytes: &[u8]) -> Result<Bvh, BvhError> {
    let mut lines = Lines::new(bytes);
    let joints = parse_hierarchy(&mut lines)?;

    let mut channel_start = Vec::with_capacity(joints.len());
    let mut channel_count = 0usize;
    for j in &joints {
        channel_start.push(channel_count);
        channel_count += j.channels.len();
    }

    let (frame_count, frame_time_s, values) = parse_motion(&mut lines, channel_count)?;
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
fn parse_hierarchy(lines: &mut Lines<'_>) -> Result<Vec<BvhJoint>, BvhError> {
    let mut joints: Vec<BvhJoint> = Vec::new();
    let mut stack: Vec<Open> = Vec::new();
    let mut expect = Expect::Hierarchy;

    for (n, line) in lines.by_ref() {
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

/// The next line with something on it.
fn next_nonblank<'a>(lines: &mut Lines<'a>) -> Option<(usize, Vec<&'a [u8]>)> {
    for (n, line) in lines.by_ref() {
        let toks = tokens(line);
        if !toks.is_empty() {
            return Some((n, toks));
        }
    }
    None
}

/// Strips an ASCII-case-insensitive prefix.
fn strip_prefix_ci<'a>(text: &'a [u8], prefix: &str) -> Option<&'a [u8]> {
    let p = prefix.as_bytes();
    (text.len() >= p.len() && text[..p.len()].eq_ignore_ascii_case(p)).then(|| &text[p.len()..])
}

/// `Frames: N`, `Frame Time: t`, then the frame lines.
fn parse_motion(
    lines: &mut Lines<'_>,
    channel_count: usize,
) -> Result<(usize, f64, Vec<f64>), BvhError> {
    // `Frames: 12`, `Frames:\t12`, `Frames:12`, `Frames 12`: join the words and read past the
    // keyword and an optional colon.
    let Some((n, toks)) = next_nonblank(lines) else {
        return Err(error(
            lines.last_line(),
            "unexpected end of file: expected `Frames: <count>`",
        ));
    };
    let joined = toks.concat();
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

    let Some((n, toks)) = next_nonblank(lines) else {
        return Err(error(
            lines.last_line(),
            "unexpected end of file: expected `Frame Time: <seconds>`",
        ));
    };
    let joined = toks.concat();
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

    // Reserve only what the remaining bytes could hold (each value takes at least 2 bytes).
    let claimed = frame_count.saturating_mul(channel_count);
    let mut values = Vec::with_capacity(claimed.min(lines.remaining_bytes() / 2 + 1));
    let mut frames_read = 0usize;
    for (n, line) in lines.by_ref() {
        let toks = tokens(line);
        if toks.is_empty() {
            continue;
        }
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
        if toks.len() != channel_count {
            return Err(error(
                n,
                format!(
                    "expected {channel_count} values (one per channel of the hierarchy) on frame {frames_read}, found {}",
                    toks.len()
                ),
            ));
        }
        for (k, tok) in toks.iter().enumerate() {
            let v = number(tok).ok_or_else(|| {
                error(
                    n,
                    format!(
                        "expected a finite number for value {} of frame {frames_read}, found `{}`",
                        k + 1,
                        show(tok)
                    ),
                )
            })?;
            values.push(v);
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
