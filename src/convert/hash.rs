//! The SHA-256 of a take's source (the sidecar's and the ledger's), computed as the take is read.

use crate::read::{ReadError, ReadOptions, check_text, is_stream, read_take, sniff};
use crate::take::Take;
use sha2::{Digest, Sha256};
use std::io::{self, Read};
use std::path::{Path, PathBuf};

/// SHA-256 of a file, or of a folder's files (sorted relative paths and contents).
pub fn source_sha256(path: &Path) -> io::Result<String> {
    let mut hasher = Sha256::new();
    if path.is_dir() {
        let mut files = Vec::new();
        collect_files(path, path, &mut files)?;
        files.sort();
        for rel in files {
            hasher.update(rel.to_string_lossy().as_bytes());
            hasher.update([0u8]);
            hash_file(&path.join(&rel), &mut hasher)?;
        }
    } else {
        hash_file(path, &mut hasher)?;
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

fn hash_file(path: &Path, hasher: &mut Sha256) -> io::Result<()> {
    let mut file = std::fs::File::open(path)?;
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = file.read(&mut buf)?;
        if n == 0 {
            return Ok(());
        }
        hasher.update(&buf[..n]);
    }
}

fn collect_files(root: &Path, dir: &Path, out: &mut Vec<PathBuf>) -> io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let path = entry.path();
        if entry.file_name().to_string_lossy().starts_with('.') {
            continue;
        }
        if path.is_dir() {
            collect_files(root, &path, out)?;
        } else {
            out.push(path.strip_prefix(root).unwrap_or(&path).to_path_buf());
        }
    }
    Ok(())
}

pub(crate) fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Reads the take and the SHA-256 of its source. An imubake CSV is hashed as it is read; another
/// file or a folder is hashed on a second core while it is parsed, once a file has passed the
/// text check (so a huge binary file is refused without being read); a stream (FIFO, process
/// substitution) is read once into memory, then hashed and parsed.
pub(super) fn read_and_hash(
    input: &Path,
    options: &ReadOptions,
) -> Result<(Take, String), ReadError> {
    if is_stream(input) {
        // Read as it arrives, hashed on the way: the format is judged from the first 8 KiB and
        // each line is held to the readers' limit, so a pipe of garbage is refused early.
        let mut hasher = Sha256::new();
        let take =
            crate::read::read_stream_observed(input, options, &mut |bytes| hasher.update(bytes))?;
        return Ok((take, hex(&hasher.finalize())));
    }
    if input.is_file() {
        let head = sniff(input)?;
        if !crate::read::is_binary_format(&head, options.forced_format()) {
            check_text(input, &head)?;
        }
        let format = match options.forced_format() {
            Some(f) => f,
            None => crate::read::detect_format(input)?,
        };
        if format == crate::read::InputFormat::ImubakeCsv {
            // Hashed by the reader's own reading thread, block by block, in one pass.
            let mut hasher = Sha256::new();
            let take = crate::read::imubake_csv::read_observed(input, options, &mut |bytes| {
                hasher.update(bytes)
            })?;
            return Ok((take, hex(&hasher.finalize())));
        }
    }
    let (take, sha256) = std::thread::scope(|scope| {
        let hasher = scope.spawn(|| source_sha256(input));
        let take = read_take(input, options);
        let sha = hasher
            .join()
            .unwrap_or_else(|_| Err(io::Error::other("hashing thread panicked")));
        (take, sha)
    });
    let take = take?;
    let sha256 = sha256.map_err(|e| ReadError::Io {
        path: input.to_path_buf(),
        source: e,
    })?;
    Ok((take, sha256))
}
