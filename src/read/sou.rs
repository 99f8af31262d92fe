//! Paper 002's SOU logs (Table 4): `timestamp_ms,SOU_ID,yaw1,pitch1,roll1,yaw2,pitch2,roll2`.
//!
//! Each line carries two nodes, `<SOU_ID>_0` and `<SOU_ID>_1`, as yaw/pitch/roll in degrees
//! (intrinsic Z-Y-X, world NED, Madgwick output). A line that does not match the paper's pattern
//! `^[0-9]+,[a-zA-Z0-9]+(,[ \-0-9\.]+){6}$`, or whose numbers do not parse to finite values, is
//! dropped and reported — only that line, not everything before it as the paper did.

use super::lines::{LineReader, parse_f64, split_fields};
use super::{InputFormat, ReadError, ReadOptions, read_single_file};
use crate::take::{ClockUnit, Take, TakeBuilder, YawPitchRollDeg};
use crate::world::World;
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

const FIELD_NAMES: [&str; 8] = [
    "timestamp_ms",
    "SOU_ID",
    "yaw1",
    "pitch1",
    "roll1",
    "yaw2",
    "pitch2",
    "roll2",
];

/// Why a line does not match the SOU format, or `None` when it does (the paper's regex).
pub fn format_problem(line: &[u8]) -> Option<String> {
    let mut fields = [&b""[..]; 8];
    let n = split_fields(line, b',', &mut fields);
    if n != 8 {
        return Some(format!(
            "does not match the SOU format: {n} comma-separated fields, expected 8"
        ));
    }
    if fields[0].is_empty() || !fields[0].iter().all(u8::is_ascii_digit) {
        return Some("does not match the SOU format: timestamp_ms is not a whole number".into());
    }
    if fields[1].is_empty() || !fields[1].iter().all(u8::is_ascii_alphanumeric) {
        return Some("does not match the SOU format: SOU_ID is not letters and digits".into());
    }
    for (i, field) in fields.iter().enumerate().skip(2) {
        let allowed = |b: &u8| matches!(b, b' ' | b'-' | b'.' | b'0'..=b'9');
        if field.is_empty() || !field.iter().all(allowed) {
            return Some(format!(
                "does not match the SOU format: {} is not a number",
                FIELD_NAMES[i]
            ));
        }
    }
    None
}

/// True when the first lines look like a SOU log (debug text before the data is allowed).
pub fn looks_like(head: &[u8]) -> bool {
    let mut reader = LineReader::over(head);
    let mut matching = 0;
    let mut seen = 0;
    while let Ok(Some((_, line))) = reader.next_line() {
        seen += 1;
        if format_problem(line).is_none() {
            matching += 1;
        }
        if matching >= 2 || seen > 64 {
            break;
        }
    }
    matching >= 1
}

/// Parses a SOU line: its timestamp (ms), SOU id and the six angles (yaw1, pitch1, roll1, yaw2,
/// pitch2, roll2, degrees); `Err` with the reason to drop it.
pub fn parse_line(line: &[u8]) -> Result<(u64, &str, [f64; 6]), String> {
    if let Some(problem) = format_problem(line) {
        return Err(problem);
    }
    let mut f = [&b""[..]; 8];
    split_fields(line, b',', &mut f);
    let timestamp = std::str::from_utf8(f[0])
        .ok()
        .and_then(|s| s.parse::<u64>().ok())
        .ok_or("timestamp_ms does not fit in 64 bits")?;
    let mut angles = [0.0; 6];
    for (i, angle) in angles.iter_mut().enumerate() {
        *angle = parse_f64(f[i + 2])
            .ok_or_else(|| format!("{} is not a finite number", FIELD_NAMES[i + 2]))?;
    }
    // The pattern admits only ASCII letters and digits here.
    let sou_id = std::str::from_utf8(f[1]).map_err(|_| "SOU_ID is not text")?;
    Ok((timestamp, sou_id, angles))
}

pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    read_single_file(path, options, read_from)
}

/// Reads a SOU log from any reader; `path` names it in reports.
pub fn read_from(reader: impl Read, path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    let world = options.world.unwrap_or(World::Ned);
    let mut take = TakeBuilder::new(path, InputFormat::Sou, world, ClockUnit::Milliseconds);
    let mut lines = LineReader::new(reader);
    // SOU_ID → (node _0, node _1)
    let mut nodes = HashMap::new();
    while let Some((line_no, line)) = lines.next_line().map_err(|e| ReadError::lines(path, e))? {
        if line_no <= options.skip_lines {
            take.drop_line(line_no, "skipped by --skip-lines", line);
            continue;
        }
        if line.trim_ascii().is_empty() {
            continue;
        }
        // A live session's recording of a recalibration (any other line is the paper's to drop).
        if let Some(Ok(t)) = line
            .trim_ascii()
            .strip_prefix(b"#")
            .and_then(super::calibrate_directive)
        {
            take.recalibrate_at(t);
            continue;
        }
        let (timestamp, sou_id, angles) = match parse_line(line) {
            Ok(row) => row,
            Err(problem) => {
                take.drop_line(line_no, problem, line);
                continue;
            }
        };
        let (n0, n1) = match nodes.get(sou_id) {
            Some(&pair) => pair,
            None => {
                let pair = (
                    take.sensor(&format!("{sou_id}_0")),
                    take.sensor(&format!("{sou_id}_1")),
                );
                nodes.insert(sou_id.to_string(), pair);
                pair
            }
        };
        let t = timestamp as f64;
        let ypr = |a: &[f64]| YawPitchRollDeg {
            yaw: a[0],
            pitch: a[1],
            roll: a[2],
        };
        take.push_yaw_pitch_roll(n0, t, ypr(&angles[0..3]), line_no, line)
            .map_err(|e| ReadError::take(path, e))?;
        take.push_yaw_pitch_roll(n1, t, ypr(&angles[3..6]), line_no, line)
            .map_err(|e| ReadError::take(path, e))?;
    }
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}
