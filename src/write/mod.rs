//! Writers: one module per output format, the [`Output`] kinds a conversion chooses from, and
//! the atomic file writing they share (conventions.md, "Takes and names": hidden temporary file
//! in the same folder, renamed into place).

pub mod bvh;
pub mod decimal;
pub mod error_report;
pub mod gltf;
pub mod godot;
pub mod orientation_csv;
pub mod report;
pub mod sidecar;
pub mod take;
pub mod transforms;

use crate::anim::Animation;
use crate::rig::LengthUnit;
use serde::{Deserialize, Serialize};
use sidecar::OutputRecord;

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The temporary files being written in this process, and whether the process has abandoned its
/// writes (it was told to stop and a conversion did not finish in time).
struct Temps {
    abandoned: bool,
    paths: Vec<PathBuf>,
}

static TEMPS: Mutex<Temps> = Mutex::new(Temps {
    abandoned: false,
    paths: Vec::new(),
});

fn temps() -> std::sync::MutexGuard<'static, Temps> {
    TEMPS.lock().unwrap_or_else(|e| e.into_inner())
}

/// The error of a write refused because the process abandoned its writes.
pub fn abandoned_error() -> io::Error {
    io::Error::new(
        io::ErrorKind::Interrupted,
        "stopped before the take finished; nothing of it was kept",
    )
}

/// Abandons this process's writes, for a process about to exit in the middle of a conversion:
/// every temporary file being written is removed, and from now on no temporary file is created
/// and none is renamed into place ([`write_atomic`] fails), and [`unless_abandoned`] refuses.
/// Returns the temporary files removed. Creation and rename happen under the same lock, so
/// nothing of an unfinished take appears after this returns.
pub fn abandon_writes() -> Vec<PathBuf> {
    let mut temps = temps();
    temps.abandoned = true;
    let paths = std::mem::take(&mut temps.paths);
    for p in &paths {
        let _ = fs::remove_file(p);
    }
    paths
}

/// Whether [`abandon_writes`] was called.
pub fn writes_abandoned() -> bool {
    temps().abandoned
}

/// Runs `f` (a ledger append, say) unless the writes were abandoned, holding the lock so that
/// an abandonment waits for it to finish.
pub fn unless_abandoned<T>(f: impl FnOnce() -> io::Result<T>) -> io::Result<T> {
    let temps = temps();
    if temps.abandoned {
        return Err(abandoned_error());
    }
    let result = f();
    drop(temps);
    result
}

/// An animation file format (`--format`, config `formats`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputFormat {
    Bvh,
    Glb,
    /// `.gltf` JSON with a `.bin` buffer beside it.
    Gltf,
}

impl OutputFormat {
    pub fn name(self) -> &'static str {
        match self {
            OutputFormat::Bvh => "bvh",
            OutputFormat::Glb => "glb",
            OutputFormat::Gltf => "gltf",
        }
    }
}

impl std::str::FromStr for OutputFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "bvh" => Ok(OutputFormat::Bvh),
            "glb" => Ok(OutputFormat::Glb),
            "gltf" => Ok(OutputFormat::Gltf),
            _ => Err(format!(
                "unknown output format `{s}`; expected bvh, glb or gltf"
            )),
        }
    }
}

/// A game engine whose import settings are written beside each take's glTF outputs
/// (`--engine`, config `engine`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// Godot 3: `<file>.import` beside each `.glb`/`.gltf` ([`godot`]).
    Godot,
}

impl Engine {
    pub fn name(self) -> &'static str {
        match self {
            Engine::Godot => "godot",
        }
    }
}

impl std::str::FromStr for Engine {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "godot" => Ok(Engine::Godot),
            _ => Err(format!("unknown engine `{s}`; expected godot")),
        }
    }
}

/// One output of a take (the sidecar, written last by its writer, is not one of them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    Animation(OutputFormat),
    /// `<stem>.report.html` ([`report`]).
    Report,
}

/// Everything the writers are given of a converted take.
pub struct TakeOutputs<'a> {
    pub stem: &'a str,
    pub animation: &'a Animation,
    /// BVH channel values, `[joint][frame]` degrees in each joint's order, continuous
    /// ([`crate::rotation::euler::filter_track_degrees`]), when made already (paper 002's channel copy); else the
    /// BVH writer makes them from the animation's rotations as it writes.
    pub euler_deg: Option<&'a [Vec<[f64; 3]>]>,
    /// Length unit of the BVH (glTF is always metres).
    pub units: LengthUnit,
    /// The report's content, when a report is wanted.
    pub report: Option<report::ReportInput<'a>>,
}

/// Why an output could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{}: cannot write: {source}", .path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("{}: {source}", .path.display())]
    Gltf {
        path: PathBuf,
        #[source]
        source: gltf::GltfWriteError,
    },
}

fn write_error(path: &Path) -> impl FnOnce(io::Error) -> OutputError {
    let path = path.to_path_buf();
    move |source| OutputError::Write { path, source }
}

impl Output {
    /// Writes this output of the take into `dir` (atomically), and says what it wrote.
    pub fn write(self, dir: &Path, take: &TakeOutputs) -> Result<OutputRecord, OutputError> {
        let stem = take.stem;
        let record = |format: &'static str, ext: &str| OutputRecord {
            format,
            path: format!("{stem}.{ext}"),
        };
        let gltf_error = |path: &Path| {
            let path = path.to_path_buf();
            move |source| OutputError::Gltf { path, source }
        };
        match self {
            Output::Animation(OutputFormat::Bvh) => {
                let path = dir.join(format!("{stem}.bvh"));
                let anim = take.animation;
                let motion = bvh::BvhMotion {
                    rig: anim.rig(),
                    fps: anim.fps(),
                    root_positions: anim.root_positions(),
                    euler_deg: match take.euler_deg {
                        Some(degrees) => bvh::Angles::Degrees(degrees),
                        None => bvh::Angles::Rotations(anim.locals()),
                    },
                    translations: anim.translations(),
                };
                write_atomic(&path, |w| bvh::write_bvh_in(w, &motion, take.units))
                    .map_err(write_error(&path))?;
                Ok(record("bvh", "bvh"))
            }
            Output::Animation(OutputFormat::Glb) => {
                let path = dir.join(format!("{stem}.glb"));
                let (head, chunk) =
                    gltf::to_glb_parts(take.animation, stem, 0).map_err(gltf_error(&path))?;
                write_atomic(&path, |w| {
                    w.write_all(&head)?;
                    chunk.write_to(w)
                })
                .map_err(write_error(&path))?;
                Ok(record("glb", "glb"))
            }
            Output::Animation(OutputFormat::Gltf) => {
                let path = dir.join(format!("{stem}.gltf"));
                let bin_name = format!("{stem}.bin");
                let bin_path = dir.join(&bin_name);
                let (json, bin) =
                    gltf::to_gltf(take.animation, stem, &bin_name).map_err(gltf_error(&path))?;
                // The buffer first, so a .gltf never points at a missing .bin.
                write_atomic(&bin_path, |w| w.write_all(&bin)).map_err(write_error(&bin_path))?;
                write_atomic(&path, |w| w.write_all(json.as_bytes()))
                    .map_err(write_error(&path))?;
                Ok(record("gltf", "gltf"))
            }
            Output::Report => {
                let path = dir.join(format!("{stem}.report.html"));
                let html = take
                    .report
                    .as_ref()
                    .map(report::render_report)
                    .unwrap_or_default();
                write_atomic(&path, |w| w.write_all(html.as_bytes()))
                    .map_err(write_error(&path))?;
                Ok(record("report", "report.html"))
            }
        }
    }
}

/// The extensions a take's outputs may have, the sidecar first (removed first: without it a take
/// is not complete).
pub const OUTPUT_SUFFIXES: [&str; 8] = [
    ".imubake.json",
    ".bvh",
    ".glb",
    ".gltf",
    ".bin",
    ".report.html",
    ".glb.import",
    ".gltf.import",
];

/// Removes every output of take `stem` in `dir`, the sidecar first; missing files are fine.
pub fn remove_take_outputs(dir: &Path, stem: &str) {
    for suffix in OUTPUT_SUFFIXES {
        let _ = fs::remove_file(dir.join(format!("{stem}{suffix}")));
    }
}

/// The hidden temporary name for `path`: `<dir>/.<file name>.tmp`.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp"))
}

/// Writes a file atomically: readers see either the old file or the complete new one, never a
/// partial one. The data is flushed to disk before the rename. A device or a pipe (`-o
/// /dev/null`, a FIFO) is written straight into instead: a file renamed over it would replace it
/// — `/dev/null` a regular file for every program after.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut (dyn Write + Send)) -> io::Result<()>,
) -> io::Result<()> {
    if fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
        let mut out = io::BufWriter::new(fs::OpenOptions::new().write(true).open(path)?);
        write(&mut out)?;
        return out.flush();
    }
    let tmp = temp_path(path);
    let file = {
        let mut temps = temps();
        if temps.abandoned {
            return Err(abandoned_error());
        }
        let file = fs::File::create(&tmp)?;
        temps.paths.push(tmp.clone());
        file
    };
    let result = (|| {
        let mut out = io::BufWriter::with_capacity(1 << 20, Writeback::new(file));
        write(&mut out)?;
        let file = out.into_inner().map_err(|e| e.into_error())?.file;
        file.sync_all()?;
        let mut temps = temps();
        temps.paths.retain(|p| p != &tmp);
        if temps.abandoned {
            return Err(abandoned_error());
        }
        fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
        temps().paths.retain(|p| p != &tmp);
    }
    result
}

/// A file being written that asks the kernel to start writing each 16 MB to disk as soon as
/// it is written (Linux's `sync_file_range`), so that the `fsync` before the rename finds little
/// left to wait for: a 140 MB BVH otherwise waits ~50 ms for all of it at the end.
struct Writeback {
    file: fs::File,
    written: u64,
    started: u64,
}

impl Writeback {
    const STRIDE: u64 = 16 << 20;

    fn new(file: fs::File) -> Writeback {
        Writeback {
            file,
            written: 0,
            started: 0,
        }
    }
}

impl Write for Writeback {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.file.write(buf)?;
        self.written += n as u64;
        if self.written - self.started >= Self::STRIDE {
            start_writeback(&self.file, self.started, self.written - self.started);
            self.started = self.written;
        }
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

/// Starts writing `len` bytes at `offset` of `file` to disk, without waiting; a hint only, so a
/// failure is ignored (the `fsync` that follows reports real errors).
#[cfg(target_os = "linux")]
fn start_writeback(file: &fs::File, offset: u64, len: u64) {
    use std::os::fd::AsRawFd;
    // SAFETY: a plain system call on an open descriptor; no memory is passed.
    unsafe {
        libc::sync_file_range(
            file.as_raw_fd(),
            offset as libc::off64_t,
            len as libc::off64_t,
            libc::SYNC_FILE_RANGE_WRITE,
        );
    }
}

#[cfg(not(target_os = "linux"))]
fn start_writeback(_file: &fs::File, _offset: u64, _len: u64) {}

#[cfg(test)]
mod tests {
    use super::*;

    /// A FIFO (as `/dev/null`, not a regular file) is written into, not replaced: its read end,
    /// opened first (without blocking, so a regression fails instead of hanging), gets the
    /// bytes, and the path is still a FIFO after.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_pipe_is_written_into_not_replaced() {
        use std::io::Read;
        use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.is_ok_and(|s| s.success()), "mkfifo");
        let mut reader = fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(&fifo)
            .unwrap();
        write_atomic(&fifo, |w| w.write_all(b"hello")).unwrap();
        let mut got = [0u8; 16];
        let n = reader.read(&mut got).unwrap_or(0);
        assert_eq!(&got[..n], b"hello");
        assert!(fs::metadata(&fifo).unwrap().file_type().is_fifo());
        assert!(!temp_path(&fifo).exists());
    }

    #[test]
    fn a_large_write_starts_writeback_as_it_goes_and_lands_whole() {
        // 40 MB in odd-sized pieces: writeback is started twice (every 16 MB) on the way.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("long.bvh");
        let piece: Vec<u8> = (0..1_000_003u32).map(|i| (i % 251) as u8).collect();
        write_atomic(&path, |w| {
            for _ in 0..40 {
                w.write_all(&piece)?;
            }
            Ok(())
        })
        .unwrap();
        let back = fs::read(&path).unwrap();
        assert_eq!(back.len(), 40 * piece.len());
        assert!(back.chunks(piece.len()).all(|c| c == piece));
        assert!(!temp_path(&path).exists());
    }

    #[test]
    fn atomic_write_leaves_no_temp_file_and_cleans_up_on_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("walk.bvh");
        write_atomic(&path, |w| w.write_all(b"hello")).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"hello");
        assert!(!temp_path(&path).exists());
        assert_eq!(temp_path(&path).file_name().unwrap(), ".walk.bvh.tmp");
        let err = write_atomic(&path, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("boom"))
        });
        assert!(err.is_err());
        assert_eq!(
            fs::read(&path).unwrap(),
            b"hello",
            "the old file is untouched"
        );
        assert!(!temp_path(&path).exists());
    }
}
