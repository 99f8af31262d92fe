//! Readers: one module per capture format, each turning a file or session folder into a
//! [`Take`]. The format is detected from content; [`ReadOptions::format`] overrides.
//!
//! Nothing is read whole before it is judged: the format is detected from a source's first
//! 8 KiB, a stream's (a FIFO, `/dev/stdin`) as a file's, so an unknown one is refused having read
//! no more; then the format's reader reads on, and every line-based reader (all but MVNX's XML)
//! holds each line to [`lines::MAX_LINE_BYTES`] (1 MiB) as it reads, refusing a longer one by
//! number without holding it. A stream is read as it comes ([`read_take`]); only WitMotion's
//! binary packets are gathered whole first.

pub mod apdm;
pub mod blocks;
pub mod clock;
pub mod imubake_csv;
pub mod layout;
pub mod lines;
pub mod opensense_sto;
pub mod sou;
pub mod stream;
pub mod witmotion;
pub mod xio_fusion_csv;
pub mod xio_session;
pub mod xsens_dot;
pub mod xsens_mtw;
pub mod xsens_mvnx;

pub use crate::take::InputFormat;
use crate::take::{BuildError, Take, TakeBuilder};
use crate::world::World;
use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};

/// How to read a take.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadOptions {
    /// Skip detection and read as this format.
    pub format: Option<InputFormat>,
    /// Drop the first N lines of a line-based single-file log (paper 002's fixed-length cleaning).
    pub skip_lines: u64,
    /// Drop samples earlier than this many seconds after the first sample; the clock is then
    /// re-zeroed at the earliest kept sample.
    pub skip_seconds: f64,
    /// Overrides the world the format declares.
    pub world: Option<World>,
    /// Samples per second of a recording without timestamps (WitMotion without time packets).
    pub rate_hz: Option<f64>,
    /// A declared packet layout (`--layout`): every capture is read through it.
    pub layout: Option<PathBuf>,
}

impl ReadOptions {
    /// The format the options impose: the layout's, else `--input-format`'s.
    pub fn forced_format(&self) -> Option<InputFormat> {
        if self.layout.is_some() {
            Some(InputFormat::Layout)
        } else {
            self.format
        }
    }
}

/// Why a take could not be read. Every message names the file, the line when there is one, what
/// was expected, and a hint.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{}: cannot read: {source}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: is empty; expected a capture log", .path.display())]
    EmptyFile { path: PathBuf },
    #[error("{}: looks binary (a NUL byte at offset {offset}); expected a text capture log", .path.display())]
    Binary { path: PathBuf, offset: usize },
    #[error("{}: line {line}: {message}", .path.display())]
    Line {
        path: PathBuf,
        line: u64,
        message: String,
    },
    #[error("{}: {message}", .path.display())]
    Format { path: PathBuf, message: String },
    #[error("{}: {source}", .path.display())]
    Take {
        path: PathBuf,
        #[source]
        source: BuildError,
    },
}

impl crate::diagnostic::Diagnostic for ReadError {
    fn file(&self) -> Option<&Path> {
        match self {
            ReadError::Io { path, .. }
            | ReadError::EmptyFile { path }
            | ReadError::Binary { path, .. }
            | ReadError::Line { path, .. }
            | ReadError::Format { path, .. }
            | ReadError::Take { path, .. } => Some(path),
        }
    }

    fn line(&self) -> Option<u64> {
        match self {
            ReadError::Line { line, .. } => Some(*line),
            _ => None,
        }
    }

    fn hint(&self) -> Option<&'static str> {
        match self {
            ReadError::Line { .. } => {
                Some("fix or delete that line, or drop the lines before it with --skip-lines")
            }
            ReadError::Io { .. } => Some("check the path and its permissions"),
            ReadError::EmptyFile { .. } | ReadError::Binary { .. } | ReadError::Format { .. } => {
                Some(
                    "is this a capture log? Name its format with --input-format, or move it out of the inputs",
                )
            }
            ReadError::Take { .. } => None,
        }
    }
}

impl ReadError {
    pub(crate) fn line(path: &Path, line: u64, message: impl Into<String>) -> Self {
        ReadError::Line {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    pub(crate) fn format(path: &Path, message: impl Into<String>) -> Self {
        ReadError::Format {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        ReadError::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn take(path: &Path, source: BuildError) -> Self {
        ReadError::Take {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn lines(path: &Path, e: lines::LineError) -> Self {
        match e {
            lines::LineError::Io(source) => ReadError::io(path, source),
            lines::LineError::TooLong { line } => ReadError::line(
                path,
                line,
                format!(
                    "the line is longer than {} bytes (1 MiB), the longest line of a text log \
                     imubake reads; expected one sample per line",
                    lines::MAX_LINE_BYTES
                ),
            ),
        }
    }
}

/// How many bytes of a file detection and the binary check look at.
const SNIFF_BYTES: usize = 8192;

/// Reads up to [`SNIFF_BYTES`] of a file.
pub(crate) fn sniff(path: &Path) -> Result<Vec<u8>, ReadError> {
    let mut file = fs::File::open(path).map_err(|e| ReadError::io(path, e))?;
    let mut head = Vec::with_capacity(SNIFF_BYTES);
    file.by_ref()
        .take(SNIFF_BYTES as u64)
        .read_to_end(&mut head)
        .map_err(|e| ReadError::io(path, e))?;
    Ok(head)
}

/// The name outputs of `input` are written under: the file name without its extension, or the
/// folder name of a session folder.
pub fn take_stem(input: &Path) -> String {
    let name = if input.is_dir() {
        input.file_name()
    } else {
        input.file_stem()
    };
    name.map(|n| n.to_string_lossy().into_owned())
        .filter(|n| !n.is_empty() && n != "." && n != "..")
        .unwrap_or_else(|| "take".to_string())
}

/// Whether bytes that start like `head` are one of the binary formats (WitMotion's packets, HDF5),
/// which the text check must let through.
pub(crate) fn is_binary_format(head: &[u8], format: Option<InputFormat>) -> bool {
    match format {
        Some(f) => matches!(
            f,
            InputFormat::WitMotion | InputFormat::ApdmH5 | InputFormat::Layout
        ),
        None => witmotion::looks_like(head) || apdm::looks_like(head),
    }
}

/// Fails on an empty file or one with NUL bytes near the start: no text capture log has them.
pub(crate) fn check_text(path: &Path, head: &[u8]) -> Result<(), ReadError> {
    if head.is_empty() {
        return Err(ReadError::EmptyFile {
            path: path.to_path_buf(),
        });
    }
    if let Some(offset) = memchr::memchr(0, head) {
        return Err(ReadError::Binary {
            path: path.to_path_buf(),
            offset,
        });
    }
    Ok(())
}

/// Detects the format of a file or folder from its content.
pub fn detect_format(path: &Path) -> Result<InputFormat, ReadError> {
    let meta = fs::metadata(path).map_err(|e| ReadError::io(path, e))?;
    if meta.is_dir() {
        return detect_folder(path);
    }
    let head = sniff(path)?;
    if witmotion::looks_like(&head) {
        return Ok(InputFormat::WitMotion);
    }
    if apdm::looks_like(&head) {
        return Ok(InputFormat::ApdmH5);
    }
    check_text(path, &head)?;
    detect_bytes(&head).ok_or_else(|| unknown_format(path))
}

fn unknown_format(path: &Path) -> ReadError {
    ReadError::format(
        path,
        "unknown capture format; expected a SOU log (`timestamp_ms,SOU_ID,yaw1,...`), an imubake CSV \
         (header with time_s|time_ms|time_us and sensor), an OpenSense .sto, a Movella DOT CSV, an \
         Xsens MTw .txt, an Xsens MVN .mvnx, an x-io Fusion CSV, a WitMotion binary stream or a \
         BVH. Hint: name the format with --input-format",
    )
}

/// Detects a single-file format from its first bytes.
pub fn detect_bytes(head: &[u8]) -> Option<InputFormat> {
    if xsens_mvnx::looks_like(head) {
        Some(InputFormat::XsensMvnx)
    } else if head.trim_ascii_start().starts_with(b"HIERARCHY") {
        Some(InputFormat::Bvh)
    } else if opensense_sto::looks_like(head) {
        Some(InputFormat::OpensenseSto)
    } else if xsens_mtw::looks_like(head) {
        Some(InputFormat::XsensMtw)
    } else if xsens_dot::looks_like(head) {
        Some(InputFormat::XsensDot)
    } else if xio_fusion_csv::looks_like(head) {
        Some(InputFormat::XioFusionCsv)
    } else if imubake_csv::looks_like(head) {
        Some(InputFormat::ImubakeCsv)
    } else if sou::looks_like(head) {
        Some(InputFormat::Sou)
    } else {
        None
    }
}

fn detect_folder(path: &Path) -> Result<InputFormat, ReadError> {
    // A session folder, or a single x-IMU3 device folder (read as a one-device session).
    if xio_session::looks_like_folder(path) || xio_session::is_device_folder(path) {
        return Ok(InputFormat::XioSession);
    }
    // One WitMotion recording per sensor.
    if visible_files(path)?
        .iter()
        .any(|f| sniff(f).is_ok_and(|head| witmotion::looks_like(&head)))
    {
        return Ok(InputFormat::WitMotion);
    }
    let entries = visible_files(path)?;
    // The first file of a folder format decides; other files (notes, stray exports) are skipped
    // by the reader with a warning.
    let mut formats = entries.iter().filter_map(|file| {
        let head = sniff(file).ok()?;
        detect_bytes(&head)
    });
    match formats.find(|f| matches!(f, InputFormat::XsensDot | InputFormat::XsensMtw)) {
        Some(f) => Ok(f),
        _ => Err(ReadError::format(
            path,
            "folder is not a capture session; expected an x-IMU3 session (one sub-folder per device with \
             Quaternion.csv or Inertial.csv), a Movella DOT export (one CSV per sensor) or Xsens MTw .txt files",
        )),
    }
}

/// The columns of a group that belongs together (`qw,qx,qy,qz`, `Acc_X,Acc_Y,Acc_Z`), looked up
/// with `find`: all of them, or `None` when the group is absent; a partly present group is `None`
/// and its absent names are added to `missing`.
pub(crate) fn column_group(
    find: impl Fn(&str) -> Option<usize>,
    wanted: &[&str],
    missing: &mut Vec<String>,
) -> Option<Vec<usize>> {
    let found: Vec<Option<usize>> = wanted.iter().map(|n| find(n)).collect();
    let present = found.iter().filter(|f| f.is_some()).count();
    if present == 0 {
        return None;
    }
    if present < wanted.len() {
        for (f, n) in found.iter().zip(wanted) {
            if f.is_none() {
                missing.push(n.to_string());
            }
        }
        return None;
    }
    Some(found.into_iter().flatten().collect())
}

/// A unit quaternion from `w, x, y, z` and the norm it had; `None` for a zero or non-finite one.
pub(crate) fn unit_quaternion(
    q: nalgebra::Quaternion<f64>,
) -> Option<(nalgebra::UnitQuaternion<f64>, f64)> {
    let norm = q.norm();
    if !norm.is_finite() || norm < 1e-9 {
        return None;
    }
    Some((nalgebra::UnitQuaternion::new_unchecked(q / norm), norm))
}

/// Quaternions are normalised on read; one warning when they were more than 1 % off unit length
/// (`file`: the file of a multi-file take, named in the warning).
pub(crate) fn warn_if_denormalised(
    take: &mut TakeBuilder,
    worst_norm_error: f64,
    file: Option<&str>,
) {
    if worst_norm_error > 0.01 {
        let what = "quaternions deviate from unit length by up to";
        take.warn(match file {
            Some(f) => format!("{f}: {what} {worst_norm_error:.3}; normalised"),
            None => format!("{what} {worst_norm_error:.3}; normalised"),
        });
    }
}

/// The checks of a header (column) row the Xsens readers share; every error names the file, the
/// line, the row (`what`: "header", "column row") and what was expected.
pub(crate) struct HeaderCheck<'a> {
    pub path: &'a Path,
    pub line: u64,
    pub what: &'a str,
    pub expected: &'a str,
}

impl<'a> HeaderCheck<'a> {
    /// The checks of the row at `line` of `path`, called `what` in messages.
    pub(crate) fn new(path: &'a Path, line: u64, what: &'a str, expected: &'a str) -> Self {
        HeaderCheck {
            path,
            line,
            what,
            expected,
        }
    }

    pub(crate) fn error(&self, problem: String) -> ReadError {
        ReadError::line(self.path, self.line, format!("{} {problem}", self.what))
    }

    /// At most `max` columns are looked at.
    pub(crate) fn column_count(&self, columns: usize, max: usize) -> Result<(), ReadError> {
        if columns > max {
            return Err(self.error(format!(
                "has {columns} columns; at most {max} are supported"
            )));
        }
        Ok(())
    }

    /// A column the format cannot do without.
    pub(crate) fn required(&self, found: Option<usize>, name: &str) -> Result<usize, ReadError> {
        found.ok_or_else(|| self.error(format!("has no {name} column; expected {}", self.expected)))
    }

    /// No column group may be partly present ([`column_group`]'s `missing`).
    pub(crate) fn complete(&self, missing: &[String]) -> Result<(), ReadError> {
        if missing.is_empty() {
            return Ok(());
        }
        Err(self.error(format!(
            "is missing column(s) {}; expected {}",
            missing.join(", "),
            self.expected
        )))
    }
}

/// A session folder's accepted files (path and name), and notes on the files passed over.
pub(crate) type TakeFiles = (Vec<(PathBuf, String)>, Vec<String>);

/// The files of a multi-file take's folder that `looks_like` accepts (name and path, sorted),
/// and a note for each file passed over; an error naming `what` when none is accepted.
pub(crate) fn take_files(
    dir: &Path,
    looks_like: fn(&[u8]) -> bool,
    what: &str,
    expected: &str,
) -> Result<TakeFiles, ReadError> {
    let mut files = Vec::new();
    let mut notes = Vec::new();
    for file in visible_files(dir)? {
        let name = file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let head = sniff(&file)?;
        if !looks_like(&head) {
            notes.push(format!("`{name}` is not {what}; ignored"));
            continue;
        }
        check_text(&file, &head)?;
        files.push((file, name));
    }
    if files.is_empty() {
        return Err(ReadError::format(
            dir,
            format!("no {what} files in the folder; expected {expected}"),
        ));
    }
    Ok((files, notes))
}

/// An error when two files of a session folder name the same sensor (`sensor_id` of each path).
pub(crate) fn one_file_per_sensor(
    dir: &Path,
    files: &[(PathBuf, String)],
    sensor_id: fn(&Path) -> String,
) -> Result<(), ReadError> {
    let mut ids: std::collections::HashMap<String, &str> = std::collections::HashMap::new();
    for (file, name) in files {
        let id = sensor_id(file);
        if let Some(other) = ids.insert(id.clone(), name) {
            return Err(ReadError::format(
                dir,
                format!(
                    "`{other}` and `{name}` both name sensor `{id}`; expected one file per sensor. \
                     Hint: move each recording's files into its own folder"
                ),
            ));
        }
    }
    Ok(())
}

/// A folder holding one file per sensor of one recording (Movella DOT, Xsens MTw): the files the
/// format accepts (the others noted), at most one per sensor.
pub(crate) struct PerSensorFolder {
    files: Vec<(PathBuf, String)>,
    notes: Vec<String>,
}

impl PerSensorFolder {
    /// The files of `dir` that `looks_like` accepts ([`take_files`]), one per sensor by
    /// `sensor_id` ([`one_file_per_sensor`]).
    pub(crate) fn open(
        dir: &Path,
        looks_like: fn(&[u8]) -> bool,
        what: &str,
        expected: &str,
        sensor_id: fn(&Path) -> String,
    ) -> Result<Self, ReadError> {
        let (files, notes) = take_files(dir, looks_like, what, expected)?;
        one_file_per_sensor(dir, &files, sensor_id)?;
        Ok(PerSensorFolder { files, notes })
    }

    /// The take's counter clock, anchored at the earliest of the files' first counter values
    /// (`first_value` of each file and its name), so every file lands at or after it.
    pub(crate) fn anchored_clock(
        &self,
        modulus: u64,
        first_value: impl FnMut(fs::File, &Path, &str) -> Result<Option<u64>, ReadError>,
    ) -> Result<clock::WrappingClock, ReadError> {
        let firsts = self.first_values(first_value)?;
        Ok(clock::WrappingClock::anchored_at_earliest(modulus, &firsts))
    }

    /// `first_value` of each file (opened, with its path and name), in reading order; the files
    /// without one are left out.
    pub(crate) fn first_values(
        &self,
        mut first_value: impl FnMut(fs::File, &Path, &str) -> Result<Option<u64>, ReadError>,
    ) -> Result<Vec<u64>, ReadError> {
        let mut firsts = Vec::new();
        for (file, name) in &self.files {
            let f = fs::File::open(file).map_err(|e| ReadError::io(file, e))?;
            if let Some(first) = first_value(f, file, name)? {
                firsts.push(first);
            }
        }
        Ok(firsts)
    }

    /// Reads every file into `take` with `read_file`, each under its own name in reports, after
    /// noting the files passed over.
    pub(crate) fn read_into(
        &self,
        take: &mut TakeBuilder,
        clock: &mut clock::WrappingClock,
        mut read_file: impl FnMut(
            &mut TakeBuilder,
            &mut clock::WrappingClock,
            fs::File,
            &Path,
        ) -> Result<(), ReadError>,
    ) -> Result<(), ReadError> {
        for note in &self.notes {
            take.warn(note.clone());
        }
        for (file, name) in &self.files {
            take.set_file(Some(name.clone()));
            let f = fs::File::open(file).map_err(|e| ReadError::io(file, e))?;
            read_file(take, clock, f, file)?;
        }
        take.set_file(None);
        Ok(())
    }
}

/// Reads a single-file take through a reader's byte-level entry, after the text checks.
pub(crate) fn read_single_file(
    path: &Path,
    options: &ReadOptions,
    read_from: fn(fs::File, &Path, &ReadOptions) -> Result<Take, ReadError>,
) -> Result<Take, ReadError> {
    check_text(path, &sniff(path)?)?;
    let file = fs::File::open(path).map_err(|e| ReadError::io(path, e))?;
    read_from(file, path, options)
}

/// Non-hidden regular files of a folder, sorted by name so reading order is stable.
pub(crate) fn visible_files(dir: &Path) -> Result<Vec<PathBuf>, ReadError> {
    let mut files = Vec::new();
    for entry in fs::read_dir(dir).map_err(|e| ReadError::io(dir, e))? {
        let entry = entry.map_err(|e| ReadError::io(dir, e))?;
        let name = entry.file_name();
        let hidden = name.to_string_lossy().starts_with('.');
        if !hidden && entry.path().is_file() {
            files.push(entry.path());
        }
    }
    files.sort();
    Ok(files)
}

/// Whether `path` is a stream to read once (a FIFO, `/dev/stdin`, a process substitution) rather
/// than a regular file or a folder, which can be opened again.
pub fn is_stream(path: &Path) -> bool {
    fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// How much of a stream read whole ([`read_stream`]) is checked for NUL bytes.
pub const STREAM_CHECK_BYTES: usize = 1 << 20;

/// Reads a stream to its end, for a caller that needs its bytes (to hash them, say), checking
/// as it reads: a NUL byte in its first [`STREAM_CHECK_BYTES`] refuses a stream that does not
/// start like a binary format (so `/dev/zero` is refused at once), and in a text stream no line
/// may pass [`lines::MAX_LINE_BYTES`]: the first that does is refused by number once the limit
/// is passed, so a stream without line ends is never read whole. (A stream that starts like
/// WitMotion's packets, HDF5 or an MVNX document is read whole as it is.) [`read_take`] reads a
/// stream without holding it.
pub fn read_stream(path: &Path) -> Result<Vec<u8>, ReadError> {
    let mut file = fs::File::open(path).map_err(|e| ReadError::io(path, e))?;
    let mut bytes = read_head(&mut file, path)?;
    let binary = is_binary_format(&bytes, None);
    if !binary {
        check_text(path, &bytes)?;
    }
    let check_lines = !binary && !xsens_mvnx::looks_like(&bytes);
    let mut lines = LineLengths::default();
    if check_lines {
        lines.scan(&bytes).map_err(|e| ReadError::lines(path, e))?;
    }
    let mut chunk = vec![0u8; 1 << 16];
    loop {
        let n = match file.read(&mut chunk) {
            Ok(0) => return Ok(bytes),
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(ReadError::io(path, e)),
        };
        let new = &chunk[..n];
        if !binary && bytes.len() < STREAM_CHECK_BYTES {
            let checked = &new[..n.min(STREAM_CHECK_BYTES - bytes.len())];
            if let Some(at) = memchr::memchr(0, checked) {
                return Err(ReadError::Binary {
                    path: path.to_path_buf(),
                    offset: bytes.len() + at,
                });
            }
        }
        if check_lines {
            lines.scan(new).map_err(|e| ReadError::lines(path, e))?;
        }
        bytes.extend_from_slice(new);
    }
}

/// The first [`SNIFF_BYTES`] of a source (fewer when it ends first), read from a stream as they
/// come.
fn read_head(source: &mut impl Read, path: &Path) -> Result<Vec<u8>, ReadError> {
    let mut head = Vec::with_capacity(SNIFF_BYTES);
    source
        .take(SNIFF_BYTES as u64)
        .read_to_end(&mut head)
        .map_err(|e| ReadError::io(path, e))?;
    Ok(head)
}

/// The length of the line being read, checked against [`lines::MAX_LINE_BYTES`] as bytes come;
/// a line is counted without its end (`\n` or `\r\n`), as the line reader counts it.
#[derive(Default)]
struct LineLengths {
    /// Lines ended so far.
    ended: u64,
    /// Bytes of the line being read so far, a `\r` at its end included.
    current: usize,
    /// The last byte seen was `\r`.
    last_cr: bool,
}

impl LineLengths {
    fn scan(&mut self, bytes: &[u8]) -> Result<(), lines::LineError> {
        let mut start = 0;
        for end in memchr::memchr_iter(b'\n', bytes).chain(std::iter::once(bytes.len())) {
            let run = end - start;
            self.current += run;
            if run > 0 {
                self.last_cr = bytes[end - 1] == b'\r';
            }
            // A `\r` at the end may be the first half of a `\r\n`, which is no part of the line.
            if self.current - usize::from(self.last_cr) > lines::MAX_LINE_BYTES {
                return Err(lines::LineError::TooLong {
                    line: self.ended + 1,
                });
            }
            if end < bytes.len() {
                self.ended += 1;
                self.current = 0;
                self.last_cr = false;
            }
            start = end + 1;
        }
        Ok(())
    }
}

/// The format of a single-file source from its first bytes: `forced`, or detected; the text
/// check for all but the binary formats.
fn format_of_head(
    head: &[u8],
    path: &Path,
    forced: Option<InputFormat>,
) -> Result<InputFormat, ReadError> {
    let format = match forced {
        Some(f) => f,
        None if witmotion::looks_like(head) => InputFormat::WitMotion,
        None if apdm::looks_like(head) => InputFormat::ApdmH5,
        None => {
            check_text(path, head)?;
            detect_bytes(head).ok_or_else(|| unknown_format(path))?
        }
    };
    if !matches!(
        format,
        InputFormat::WitMotion | InputFormat::ApdmH5 | InputFormat::Layout
    ) {
        check_text(path, head)?;
    }
    Ok(format)
}

/// Reads one take from a single file's bytes (a stream read with [`read_stream`]).
pub fn read_take_from_bytes(
    bytes: &[u8],
    path: &Path,
    options: &ReadOptions,
) -> Result<Take, ReadError> {
    let head = &bytes[..bytes.len().min(SNIFF_BYTES)];
    match format_of_head(head, path, options.forced_format())? {
        InputFormat::WitMotion => witmotion::take_of(
            &[witmotion::Recording {
                id: take_stem(path),
                bytes,
            }],
            path,
            options,
        ),
        format => read_format_from(format, bytes, path, options),
    }
}

/// Reads one take from a stream as it comes: the format from its first [`SNIFF_BYTES`] (an
/// unknown one is refused having read no more), then the reader of that format on the stream,
/// which checks each line's length as it reads ([`lines::MAX_LINE_BYTES`]). Only WitMotion's
/// binary packets are read whole first.
fn read_take_from_stream(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    let file = fs::File::open(path).map_err(|e| ReadError::io(path, e))?;
    read_take_from_source(file, path, options)
}

/// [`read_take_from_stream`] from an open source.
fn read_take_from_source(
    mut source: impl Read + Send,
    path: &Path,
    options: &ReadOptions,
) -> Result<Take, ReadError> {
    let head = read_head(&mut source, path)?;
    let format = format_of_head(&head, path, options.forced_format())?;
    read_format_from(
        format,
        std::io::Cursor::new(head).chain(source),
        path,
        options,
    )
}

/// Reads one take from a stream (a FIFO, `/dev/stdin`) as [`read_take`] does, showing every byte
/// of the stream to `observe` in order as it is read, so a caller can hash the source (the
/// sidecar's SHA-256) without holding it: what the format's reader leaves unread (after an
/// MVNX document, say) is read after it, for `observe`. It works on a regular file too.
pub fn read_stream_observed(
    path: &Path,
    options: &ReadOptions,
    observe: &mut (dyn FnMut(&[u8]) + Send),
) -> Result<Take, ReadError> {
    let file = fs::File::open(path).map_err(|e| ReadError::io(path, e))?;
    let mut source = blocks::Observed {
        inner: file,
        observe,
    };
    let take = read_take_from_source(&mut source, path, options)?;
    std::io::copy(&mut source, &mut std::io::sink()).map_err(|e| ReadError::io(path, e))?;
    Ok(take)
}

/// Reads a single-file take of a text format (or refuses the formats a stream cannot hold).
fn read_format_from(
    format: InputFormat,
    source: impl Read + Send,
    path: &Path,
    options: &ReadOptions,
) -> Result<Take, ReadError> {
    match format {
        InputFormat::Sou => sou::read_from(source, path, options),
        InputFormat::ImubakeCsv => imubake_csv::read_from(source, path, options),
        InputFormat::OpensenseSto => opensense_sto::read_from(source, path, options),
        InputFormat::XsensDot => xsens_dot::read_from(source, path, options),
        InputFormat::XsensMtw => xsens_mtw::read_from(source, path, options),
        InputFormat::XioFusionCsv => xio_fusion_csv::read_from(source, path, options),
        InputFormat::XsensMvnx => xsens_mvnx::read_from(source, path, options),
        InputFormat::XioSession => Err(ReadError::format(
            path,
            "an x-IMU3 session is a folder; a stream cannot hold one. Hint: pass the session folder",
        )),
        InputFormat::Bvh => Err(bvh_is_motion(path)),
        InputFormat::WitMotion => {
            let mut bytes = Vec::new();
            { source }
                .read_to_end(&mut bytes)
                .map_err(|e| ReadError::io(path, e))?;
            read_take_from_bytes(&bytes, path, options)
        }
        InputFormat::ApdmH5 => Err(ReadError::format(
            path,
            "an HDF5 file is read from a file, not a stream (libhdf5 opens files). Hint: save it first",
        )),
        InputFormat::Layout => layout::read_from(source, path, options),
    }
}

/// Reads one take from a file, a session folder, or a stream (FIFO, process substitution).
pub fn read_take(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    if is_stream(path) {
        return read_take_from_stream(path, options);
    }
    let format = match options.forced_format() {
        Some(f) => f,
        None => detect_format(path)?,
    };
    match format {
        InputFormat::Sou => sou::read(path, options),
        InputFormat::ImubakeCsv => imubake_csv::read(path, options),
        InputFormat::OpensenseSto => opensense_sto::read(path, options),
        InputFormat::XsensDot => xsens_dot::read(path, options),
        InputFormat::XsensMtw => xsens_mtw::read(path, options),
        InputFormat::XioSession => xio_session::read(path, options),
        InputFormat::XioFusionCsv => xio_fusion_csv::read(path, options),
        InputFormat::XsensMvnx => xsens_mvnx::read(path, options),
        InputFormat::Bvh => Err(bvh_is_motion(path)),
        InputFormat::WitMotion => witmotion::read(path, options),
        InputFormat::ApdmH5 => apdm::read(path, options),
        InputFormat::Layout => {
            if path.is_dir() {
                return Err(ReadError::format(
                    path,
                    "--layout reads one capture file, not a folder",
                ));
            }
            let file = fs::File::open(path).map_err(|e| ReadError::io(path, e))?;
            layout::read_from(file, path, options)
        }
    }
}

/// A BVH file is motion on a skeleton, not sensor readings: only `convert` takes it.
fn bvh_is_motion(path: &Path) -> ReadError {
    ReadError::format(
        path,
        "a BVH file is motion on a skeleton, not a sensor capture: `imubake convert` retargets it \
         onto the rig (`--rig`, `--bone-map`)",
    )
}

/// A live session's recalibration as it records it, `# calibrate t=SECONDS` (the text after
/// `#`): `None` for any other comment, `Err` for a malformed time.
pub(crate) fn calibrate_directive(comment: &[u8]) -> Option<Result<f64, String>> {
    let text = std::str::from_utf8(comment).ok()?.trim();
    let rest = text.strip_prefix("calibrate")?.trim();
    let value = rest.strip_prefix("t=")?.trim();
    Some(
        value
            .parse::<f64>()
            .ok()
            .filter(|t| t.is_finite() && *t >= 0.0)
            .ok_or_else(|| format!("`# calibrate t={value}`: expected seconds ≥ 0")),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A take read while observed is the take read plainly, and the observer sees every byte of
    /// the source in order.
    #[test]
    fn an_observed_stream_shows_every_byte() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("take.csv");
        let mut text = b"time_s,sensor,qw,qx,qy,qz\n".to_vec();
        for i in 0..5000 {
            text.extend_from_slice(format!("{}.{:02},a,1,0,0,0\n", i / 100, i % 100).as_bytes());
        }
        fs::write(&path, &text).unwrap();
        let mut seen = Vec::new();
        let take = read_stream_observed(&path, &ReadOptions::default(), &mut |b| {
            seen.extend_from_slice(b)
        })
        .unwrap();
        assert_eq!(take, read_take(&path, &ReadOptions::default()).unwrap());
        assert_eq!(seen, text);
    }

    /// A stream's lines are held to the limit wherever its reads split them: a line of exactly
    /// `MAX_LINE_BYTES` bytes passes, with `\n`, `\r\n` (its `\r` split from its `\n` or not) or
    /// at the end; one byte more is refused as line 2.
    #[test]
    fn stream_lines_are_checked_across_reads() {
        let max = lines::MAX_LINE_BYTES;
        for len in [max, max + 1] {
            for end in ["\n", "\r\n", ""] {
                let mut text = b"time_s,sensor,qw,qx,qy,qz\n".to_vec();
                text.extend(std::iter::repeat_n(b'1', len));
                if !end.is_empty() {
                    text.extend_from_slice(end.as_bytes());
                    text.extend_from_slice(b"0,a,1,0,0,0\n");
                }
                let header = 26;
                for split in [1, header, header + len - 1, header + len, header + len + 1] {
                    let split = split.min(text.len());
                    let mut check = LineLengths::default();
                    let result = check
                        .scan(&text[..split])
                        .and_then(|()| check.scan(&text[split..]));
                    match result {
                        Ok(()) => assert_eq!(len, max, "{len} {end:?} {split}"),
                        Err(lines::LineError::TooLong { line }) => {
                            assert_eq!((len, line), (max + 1, 2), "{end:?} {split}")
                        }
                        Err(e) => panic!("{e}"),
                    }
                }
            }
        }
    }

    #[test]
    fn two_files_of_one_sensor_are_refused() {
        let files = |names: &[&str]| -> Vec<(PathBuf, String)> {
            names
                .iter()
                .map(|n| (PathBuf::from("dot").join(n), n.to_string()))
                .collect()
        };
        let ok = files(&["LFemur_20210820.csv", "RFemur_20210820.csv"]);
        assert!(one_file_per_sensor(Path::new("dot"), &ok, xsens_dot::sensor_id).is_ok());
        // DOT names a sensor by the text before the first `_`.
        let twice = files(&["LFemur_20210820.csv", "LFemur_20210821.csv"]);
        let e = one_file_per_sensor(Path::new("dot"), &twice, xsens_dot::sensor_id).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains(
                "`LFemur_20210820.csv` and `LFemur_20210821.csv` both name sensor `LFemur`"
            ),
            "{msg}"
        );
        assert!(msg.starts_with("dot"), "{msg}");
    }
}
