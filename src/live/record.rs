//! `--record DIR`: everything a live session receives, appended as it arrives to
//! `DIR/.<start>.<ext>.part` and renamed to `DIR/<start>.<ext>` when the session ends, so a
//! `watch` on DIR bakes the take exactly like a file dropped there (a watch ignores dot files).
//!
//! Lines are written straight through after each batch that arrives and the file is fsynced
//! once a second, so a session killed outright loses at most the last second. A `.part` left by
//! a crash is a take too: on start it is renamed into place, with a warning.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// A recording in progress.
pub struct Recorder {
    part: PathBuf,
    done: PathBuf,
    file: BufWriter<File>,
    last_sync: Instant,
    lines: u64,
}

/// `2026-12-01T23-05-09Z`: UTC, sortable, safe in file names on every system.
pub fn stamp(time: SystemTime) -> String {
    let secs = time.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}-{:02}-{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Renames every `.NAME.part` in `dir` to `NAME` (a session that crashed); what was renamed.
pub fn recover(dir: &Path) -> io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    if !dir.is_dir() {
        return Ok(out);
    }
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(bare) = name
            .strip_prefix('.')
            .and_then(|n| n.strip_suffix(".part"))
            .filter(|n| !n.is_empty())
        else {
            continue;
        };
        if !entry.file_type()?.is_file() {
            continue;
        }
        let mut target = dir.join(bare);
        // Never over an existing take: a numbered name instead.
        let mut n = 1;
        while target.exists() {
            target = dir.join(format!("{bare}.{n}"));
            n += 1;
        }
        std::fs::rename(entry.path(), &target)?;
        out.push(target);
    }
    out.sort();
    Ok(out)
}

impl Recorder {
    /// Starts `DIR/.<stamp>.<ext>.part` (DIR created if missing).
    pub fn start(dir: &Path, stamp: &str, ext: &str) -> io::Result<Recorder> {
        std::fs::create_dir_all(dir)?;
        let mut name = format!("{stamp}.{ext}");
        let mut n = 1;
        while dir.join(&name).exists() || dir.join(format!(".{name}.part")).exists() {
            name = format!("{stamp}-{n}.{ext}");
            n += 1;
        }
        let part = dir.join(format!(".{name}.part"));
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&part)?;
        Ok(Recorder {
            part,
            done: dir.join(name),
            file: BufWriter::with_capacity(64 * 1024, file),
            last_sync: Instant::now(),
            lines: 0,
        })
    }

    /// Where the take will be when the session ends.
    pub fn path(&self) -> &Path {
        &self.done
    }

    pub fn lines(&self) -> u64 {
        self.lines
    }

    /// Appends one line (its line ending added).
    pub fn line(&mut self, line: &[u8]) -> io::Result<()> {
        self.file.write_all(line)?;
        self.file.write_all(b"\n")?;
        self.lines += 1;
        Ok(())
    }

    /// The end of a batch: what was written goes to the file, and once a second to the disk.
    pub fn batch_done(&mut self) -> io::Result<()> {
        self.file.flush()?;
        if self.last_sync.elapsed() >= Duration::from_secs(1) {
            self.file.get_ref().sync_data()?;
            self.last_sync = Instant::now();
        }
        Ok(())
    }

    /// The end of the session: flushed, synced, renamed into place. The take's path.
    pub fn finish(mut self) -> io::Result<PathBuf> {
        self.file.flush()?;
        self.file.get_ref().sync_all()?;
        std::fs::rename(&self.part, &self.done)?;
        if let Some(dir) = self.done.parent()
            && let Ok(d) = File::open(dir)
        {
            let _ = d.sync_all();
        }
        Ok(self.done)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_are_utc_civil_dates() {
        // 2026-12-01 23:05:09 UTC = 1796166309 s (date -u -d @1796166309).
        let t = UNIX_EPOCH + Duration::from_secs(1_796_166_309);
        assert_eq!(stamp(t), "2026-12-01T23-05-09Z");
        assert_eq!(stamp(UNIX_EPOCH), "1970-01-01T00-00-00Z");
        // A leap day.
        let t = UNIX_EPOCH + Duration::from_secs(951_782_400);
        assert_eq!(stamp(t), "2000-02-29T00-00-00Z");
    }

    #[test]
    fn a_recording_is_renamed_at_the_end_and_a_leftover_part_recovered() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = Recorder::start(dir.path(), "s", "csv").unwrap();
        r.line(b"time_s,sensor,qw,qx,qy,qz").unwrap();
        r.batch_done().unwrap();
        assert!(dir.path().join(".s.csv.part").is_file());
        let done = r.finish().unwrap();
        assert_eq!(done, dir.path().join("s.csv"));
        assert_eq!(
            std::fs::read(&done).unwrap(),
            b"time_s,sensor,qw,qx,qy,qz\n"
        );
        // A second session with the same stamp does not overwrite it.
        let r = Recorder::start(dir.path(), "s", "csv").unwrap();
        assert_eq!(r.path(), dir.path().join("s-1.csv"));
        drop(r); // a crash: the .part stays
        let recovered = recover(dir.path()).unwrap();
        assert_eq!(recovered, vec![dir.path().join("s-1.csv")]);
        assert!(!dir.path().join(".s-1.csv.part").exists());
    }
}
