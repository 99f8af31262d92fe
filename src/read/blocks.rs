//! A line-based text parsed on every core: the source is cut into blocks at line boundaries, the
//! blocks are parsed in parallel, and their results are merged strictly in file order on the
//! calling thread, so whatever the merge decides (a take's cleaning rules, dropped-line reports
//! with their line numbers) is decided exactly as a line-by-line reader would.
//!
//! Three kinds of work overlap: one thread reads blocks (the source may be an [`Observed`] reader,
//! which shows each read to the hasher of the sidecar's SHA-256), workers parse them, the caller
//! merges them. At
//! most [`IN_FLIGHT_PER_WORKER`] blocks per worker exist at once, so memory stays bounded however
//! slow the merge is. Lines are those of [`LineReader`](super::lines::LineReader): split at `\n`,
//! a `\r` before it removed, a last line without a newline kept, none longer than
//! [`MAX_LINE_BYTES`].

use super::lines::{LineError, MAX_LINE_BYTES};
use std::collections::BTreeMap;
use std::io::{self, Read};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};

/// Bytes read per block (the last line is carried into the next block).
pub const BLOCK_BYTES: usize = 1 << 19;

/// Vectors kept from one read for the next: at most `most` of them, none over `largest_bytes`
/// (a pathological block's long list is let go). A batch or an inbox reads take after take, and
/// each read's buffers and lists (megabytes) would otherwise be fresh memory every time, zeroed
/// and faulted in 4 KiB at a time: reading a one-minute log took ~23 ms of CPU with fresh
/// buffers and ~18 ms with kept ones, and faulted 2 800 pages instead of 720.
pub(crate) struct SpareVecs<E> {
    kept: Mutex<Vec<Vec<E>>>,
    most: usize,
    largest_bytes: usize,
}

impl<E> SpareVecs<E> {
    pub(crate) const fn new(most: usize, largest_bytes: usize) -> SpareVecs<E> {
        SpareVecs {
            kept: Mutex::new(Vec::new()),
            most,
            largest_bytes,
        }
    }

    /// A kept vector (with whatever it held), if there is one.
    pub(crate) fn take(&self) -> Option<Vec<E>> {
        self.lock().pop()
    }

    /// Keeps those of `spares` small enough while fewer than `most` are kept; drops the rest.
    pub(crate) fn give(&self, spares: impl IntoIterator<Item = Vec<E>>) {
        let mut kept = self.lock();
        for spare in spares {
            if kept.len() >= self.most {
                return;
            }
            if spare.capacity().saturating_mul(size_of::<E>()) <= self.largest_bytes {
                kept.push(spare);
            }
        }
    }

    /// A panic elsewhere while the list was held leaves it whole (pushes and pops only).
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Vec<E>>> {
        self.kept.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A new block buffer's length: a block and the half-read's room the reader keeps after it.
const BUFFER_BYTES: usize = BLOCK_BYTES + BLOCK_BYTES / 2;

/// Block buffers kept between reads: all of two reads' at once (a batch's two jobs) on up to 4
/// cores; one grown past twice its size by a long line is not kept (32 MiB at most in all).
static BUFFERS: SpareVecs<u8> = SpareVecs::new(32, 2 * BLOCK_BYTES);

/// Blocks in flight (read, being parsed, or waiting to be merged) per worker.
const IN_FLIGHT_PER_WORKER: usize = 4;

/// The lines of a block: `(index within the block, line)`, without terminators.
pub fn lines_of(block: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    let mut rest = block;
    let mut index = 0;
    std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        let (mut line, next) = match memchr::memchr(b'\n', rest) {
            Some(pos) => (&rest[..pos], &rest[pos + 1..]),
            None => (rest, &rest[rest.len()..]),
        };
        rest = next;
        if let [head @ .., b'\r'] = line {
            line = head;
        }
        index += 1;
        Some((index - 1, line))
    })
}

/// A reader that shows every byte read through it to `observe`, in order.
pub struct Observed<'a, R> {
    pub inner: R,
    pub observe: &'a mut (dyn FnMut(&[u8]) + Send),
}

impl<R: Read> Read for Observed<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        (self.observe)(&buf[..n]);
        Ok(n)
    }
}

/// A block read from the source: its bytes (whole lines, `bytes[..len]`; the buffer may be
/// longer) and its place in the file.
struct Block {
    seq: usize,
    bytes: Vec<u8>,
    len: usize,
}

impl Block {
    fn text(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

/// What went wrong reading the source, at which block.
enum ReadFailure {
    Io(io::Error),
    /// The line after the blocks sent is longer than [`MAX_LINE_BYTES`].
    TooLong,
}

/// Parses `source` (whose first `first_line - 1` lines were already consumed; `pending` holds
/// bytes already read from it) in blocks: `parse(block)` on any thread gives each block's result
/// and its number of lines; `merge(first_line_number, block, result)` takes them in file order.
///
/// The first error of `merge` stops the reading and is returned; an I/O error or an over-long
/// line is returned as a [`LineError`] after the blocks before it were merged.
pub fn parse_in_blocks<R, P, E>(
    source: R,
    pending: Vec<u8>,
    first_line: u64,
    parse: impl Fn(&[u8]) -> (P, u64) + Sync,
    mut merge: impl FnMut(u64, &[u8], P) -> Result<(), E>,
) -> Result<(), BlockError<E>>
where
    R: Read + Send,
    P: Send,
{
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get());
    let in_flight = workers * IN_FLIGHT_PER_WORKER;
    // Buffers go round: the reader takes one to fill, the merge gives it back. Holding one is
    // the permit to read a block.
    let (free_tx, free_rx) = sync_channel::<Vec<u8>>(in_flight);
    for _ in 0..in_flight {
        let buffer = BUFFERS.take().unwrap_or_else(|| vec![0; BUFFER_BYTES]);
        free_tx
            .send(buffer)
            .expect("the channel has room for every buffer");
    }
    // As many block slots as buffers: the reader can never wait on a full block channel, so
    // when the merge stops early (and nobody takes blocks any more) it still runs out of
    // buffers and returns rather than blocking the scope's join.
    let (block_tx, block_rx) = sync_channel::<Block>(in_flight);
    let block_rx = Arc::new(Mutex::new(block_rx));
    let (done_tx, done_rx) = sync_channel::<(Block, P, u64)>(in_flight);

    std::thread::scope(|scope| {
        // The reader hands the free buffers' channel back, for the buffers to be kept.
        let reader = scope.spawn(move || {
            let read = read_blocks(source, pending, &free_rx, block_tx);
            (read, free_rx)
        });
        for _ in 0..workers {
            let block_rx = Arc::clone(&block_rx);
            let done_tx = done_tx.clone();
            let parse = &parse;
            scope.spawn(move || {
                loop {
                    // The lock is held only while taking a block.
                    let next = block_rx.lock().unwrap_or_else(|e| e.into_inner()).recv();
                    let Ok(block) = next else { return };
                    let (parsed, lines) = parse(block.text());
                    if done_tx.send((block, parsed, lines)).is_err() {
                        return;
                    }
                }
            });
        }
        drop(done_tx);
        let merged = merge_in_order(done_rx, &free_tx, first_line, &mut merge);
        // Whatever the merge ended with, the reader and the workers stop: without buffers to
        // fill and with nobody to hand parsed blocks to, each returns.
        drop(free_tx);
        let (read, free_rx) = reader
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        BUFFERS.give(free_rx.try_iter());
        match (merged, read) {
            (Err(MergeEnd::Merge(e)), _) => Err(BlockError::Merge(e)),
            (Ok(_), Ok(_)) => Ok(()),
            (Ok(next_line), Err(failure)) | (Err(MergeEnd::Gap(next_line)), Err(failure)) => {
                Err(BlockError::Lines(match failure {
                    ReadFailure::Io(e) => LineError::Io(e),
                    ReadFailure::TooLong => LineError::TooLong { line: next_line },
                }))
            }
            (Err(MergeEnd::Gap(_)), Ok(_)) => {
                unreachable!("blocks are missing only after a failure")
            }
        }
    })
}

/// Why [`parse_in_blocks`] failed.
#[derive(Debug)]
pub enum BlockError<E> {
    Lines(LineError),
    Merge(E),
}

enum MergeEnd<E> {
    Merge(E),
    /// The blocks stopped before the one expected next (the reader failed): the line it starts.
    Gap(u64),
}

/// Merges parsed blocks in sequence order; returns the number of the line after the last merged.
fn merge_in_order<P, E>(
    done_rx: Receiver<(Block, P, u64)>,
    free_tx: &SyncSender<Vec<u8>>,
    first_line: u64,
    merge: &mut impl FnMut(u64, &[u8], P) -> Result<(), E>,
) -> Result<u64, MergeEnd<E>> {
    let mut waiting: BTreeMap<usize, (Block, P, u64)> = BTreeMap::new();
    let mut next_seq = 0;
    let mut line = first_line;
    for done in done_rx {
        waiting.insert(done.0.seq, done);
        while let Some((block, parsed, lines)) = waiting.remove(&next_seq) {
            merge(line, block.text(), parsed).map_err(MergeEnd::Merge)?;
            line += lines;
            next_seq += 1;
            // The reader may have stopped; then the buffer is simply dropped.
            let _ = free_tx.try_send(block.bytes);
        }
    }
    if waiting.is_empty() {
        Ok(line)
    } else {
        Err(MergeEnd::Gap(line))
    }
}

/// Lines in a block: its newlines, and one more when it does not end with one.
pub fn count_lines(block: &[u8]) -> u64 {
    let newlines = memchr::memchr_iter(b'\n', block).count() as u64;
    newlines + u64::from(block.last().is_some_and(|&b| b != b'\n'))
}

/// Reads whole-line blocks into free buffers and hands them to the workers, until the end of the
/// source, a failure, or no more buffers (the merge stopped).
///
/// A buffer keeps its length (its bytes stay initialised) as it goes round, and a block's
/// `len` says how much of it is the block: reading into it then needs no zeroing first, which
/// `read_to_end` would do for every block of a reader that only has `read`.
fn read_blocks<R: Read>(
    mut source: R,
    mut carry: Vec<u8>,
    free_rx: &Receiver<Vec<u8>>,
    block_tx: SyncSender<Block>,
) -> Result<(), ReadFailure> {
    const READ_BYTES: usize = BLOCK_BYTES / 2;
    let mut seq = 0;
    let mut eof = false;
    while !eof {
        let Ok(mut bytes) = free_rx.recv() else {
            return Ok(());
        };
        let mut used = carry.len();
        if bytes.len() < used + READ_BYTES {
            bytes.resize(used + READ_BYTES, 0);
        }
        bytes[..used].copy_from_slice(&carry);
        carry.clear();
        // Where the line being read starts: after the last newline so far.
        let mut line_start = memchr::memrchr(b'\n', &bytes[..used]).map_or(0, |p| p + 1);
        let cut = loop {
            if used >= BLOCK_BYTES && line_start > 0 {
                break line_start;
            }
            if bytes.len() < used + READ_BYTES {
                bytes.resize(used + READ_BYTES, 0);
            }
            let start = used;
            let n = match read_some(&mut source, &mut bytes[start..start + READ_BYTES]) {
                Ok(n) => n,
                Err(e) => {
                    send_whole_lines(bytes, line_start, &mut seq, &block_tx);
                    return Err(ReadFailure::Io(e));
                }
            };
            if n == 0 {
                eof = true;
                break used;
            }
            used += n;
            let new = &bytes[start..used];
            // Every line is measured as it grows: the one being read ends in the new bytes or
            // goes on past them.
            let grown_to = memchr::memchr(b'\n', new).map_or(n, |p| p);
            if start - line_start + grown_to > MAX_LINE_BYTES {
                send_whole_lines(bytes, line_start, &mut seq, &block_tx);
                return Err(ReadFailure::TooLong);
            }
            if let Some(p) = memchr::memrchr(b'\n', new) {
                line_start = start + p + 1;
            }
        };
        carry.extend_from_slice(&bytes[cut..used]);
        if cut == 0 {
            continue;
        }
        let block = Block {
            seq,
            bytes,
            len: cut,
        };
        if block_tx.send(block).is_err() {
            return Ok(());
        }
        seq += 1;
    }
    Ok(())
}

/// One `read` into `buf`, again when interrupted: the bytes read, 0 at the end of the source.
fn read_some(source: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    loop {
        match source.read(buf) {
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            read => return read,
        }
    }
}

/// Sends the lines before a failure (the first `len` bytes of `bytes`), so that they are merged
/// and the failure's line number is known.
fn send_whole_lines(bytes: Vec<u8>, len: usize, seq: &mut usize, block_tx: &SyncSender<Block>) {
    if len > 0
        && block_tx
            .send(Block {
                seq: *seq,
                bytes,
                len,
            })
            .is_ok()
    {
        *seq += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::read::lines::LineReader;

    /// Every line with its number, through the blocks, as `LineReader` numbers them.
    fn through_blocks(data: &[u8], split: usize) -> Result<Vec<(u64, Vec<u8>)>, String> {
        let mut out = Vec::new();
        let mut seen = Vec::new();
        let (head, tail) = data.split_at(split);
        let mut observe = |b: &[u8]| seen.extend_from_slice(b);
        let source = Observed {
            inner: tail,
            observe: &mut observe,
        };
        parse_in_blocks(
            source,
            head.to_vec(),
            1,
            |block| {
                let lines: Vec<Vec<u8>> = lines_of(block).map(|(_, l)| l.to_vec()).collect();
                let n = lines.len() as u64;
                (lines, n)
            },
            |first, _, lines: Vec<Vec<u8>>| -> Result<(), String> {
                for (i, l) in lines.into_iter().enumerate() {
                    out.push((first + i as u64, l));
                }
                Ok(())
            },
        )
        .map_err(|e| match e {
            BlockError::Lines(e) => e.to_string(),
            BlockError::Merge(e) => e,
        })?;
        assert_eq!(seen, tail, "the observer sees every byte read, in order");
        Ok(out)
    }

    fn line_reader(data: &[u8]) -> Result<Vec<(u64, Vec<u8>)>, String> {
        let mut r = LineReader::new(data);
        let mut out = vec![];
        while let Some((n, l)) = r.next_line().map_err(|e| e.to_string())? {
            out.push((n, l.to_vec()));
        }
        Ok(out)
    }

    #[test]
    fn the_same_lines_and_numbers_as_the_line_reader() {
        let mut text = Vec::new();
        for i in 0..200_000 {
            match i % 7 {
                0 => text.extend_from_slice(b"\r\n"),
                1 => text.extend_from_slice(format!("{i},a,1.5\r\n").as_bytes()),
                _ => text
                    .extend_from_slice(format!("{i},sensor,{}\n", "x".repeat(i % 50)).as_bytes()),
            }
        }
        text.extend_from_slice(b"last line without a newline");
        for split in [0, 1, 17, 100_000] {
            assert_eq!(through_blocks(&text, split), line_reader(&text));
        }
        assert_eq!(through_blocks(b"", 0), Ok(vec![]));
        assert_eq!(through_blocks(b"\n\n", 0), line_reader(b"\n\n"));
    }

    #[test]
    fn spare_vectors_are_kept_up_to_a_count_and_a_size() {
        let spares: SpareVecs<u32> = SpareVecs::new(3, 400);
        assert!(spares.take().is_none());
        // 100 u32 are 400 bytes: kept; 101 are not.
        spares.give([Vec::with_capacity(100), Vec::with_capacity(101)]);
        let kept = spares.take().expect("the small one is kept");
        assert!(kept.capacity() >= 100 && kept.capacity() * 4 <= 400);
        assert!(spares.take().is_none(), "the large one is let go");
        spares.give((0..5).map(|i| vec![i]));
        let mut back: Vec<Vec<u32>> = std::iter::from_fn(|| spares.take()).collect();
        back.sort();
        assert_eq!(back, vec![vec![0], vec![1], vec![2]], "three at most");
    }

    #[test]
    fn buffers_kept_from_earlier_reads_give_the_same_lines() {
        // Reads one after another and at once, long lines and short, so that each takes
        // buffers the others left full of their own bytes (blocks end where a line ends,
        // never where a buffer's earlier content did).
        let texts: Vec<Vec<u8>> = (0..6)
            .map(|k| {
                let mut text = Vec::new();
                for i in 0..(40_000 + 17_000 * k) {
                    let width = (i * (k + 3)) % (20 + 900 * (k % 2));
                    text.extend_from_slice(format!("{k},{i},{}\n", "y".repeat(width)).as_bytes());
                }
                if k % 3 == 0 {
                    text.extend_from_slice(b"no newline at the end");
                }
                text
            })
            .collect();
        for _ in 0..2 {
            for text in &texts {
                assert_eq!(through_blocks(text, 3), line_reader(text));
            }
            std::thread::scope(|scope| {
                for text in &texts {
                    scope.spawn(move || assert_eq!(through_blocks(text, 0), line_reader(text)));
                }
            });
        }
    }

    #[test]
    fn a_line_longer_than_the_limit_is_an_error_with_its_number() {
        let lines_before = 600_000;
        for (length, fails) in [(MAX_LINE_BYTES, false), (MAX_LINE_BYTES + 1, true)] {
            let mut text = b"a\nb\n".repeat(lines_before / 2);
            text.extend(std::iter::repeat_n(b'x', length));
            text.extend_from_slice(b"\nafter\n");
            match through_blocks(&text, 0) {
                Ok(lines) => {
                    assert!(!fails, "a line of {length} bytes is refused");
                    assert_eq!(lines.len(), lines_before + 2);
                    assert_eq!(lines[lines_before].1.len(), length);
                }
                Err(e) => {
                    assert!(fails, "a line of {length} bytes is accepted: {e}");
                    let expected = format!("line {} is longer than", lines_before + 1);
                    assert!(e.starts_with(&expected), "{e}");
                }
            }
        }
    }

    /// A source that hands out a few bytes at a time (from 1 to over a block), is interrupted
    /// now and then, and fails for good after `fail_at` bytes if asked to.
    struct Trickle<'a> {
        data: &'a [u8],
        at: usize,
        state: u64,
        fail_at: Option<usize>,
    }

    impl Read for Trickle<'_> {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            self.state ^= self.state << 13;
            self.state ^= self.state >> 7;
            self.state ^= self.state << 17;
            if self.state.is_multiple_of(5) {
                return Err(io::ErrorKind::Interrupted.into());
            }
            let end = self.fail_at.unwrap_or(self.data.len()).min(self.data.len());
            if self.at == end && self.fail_at.is_some() {
                return Err(io::Error::other("the disk went away"));
            }
            let want = match self.state % 3 {
                0 => 1 + (self.state >> 8) as usize % 16,
                1 => 1 + (self.state >> 8) as usize % 4096,
                _ => 1 + (self.state >> 8) as usize % (BLOCK_BYTES * 2),
            };
            let n = want.min(buf.len()).min(end - self.at);
            buf[..n].copy_from_slice(&self.data[self.at..self.at + n]);
            self.at += n;
            Ok(n)
        }
    }

    /// Short reads, interrupted reads and a failure part way: the lines are those a line
    /// reader gives, and a failure merges every whole line before it, then reports the error.
    #[test]
    fn short_interrupted_and_failing_reads() {
        let text: Vec<u8> = (0..120_000)
            .flat_map(|i| format!("{i},s{},{}\n", i % 16, "7".repeat(i % 40)).into_bytes())
            .collect();
        for (seed, fail_at) in [
            (1, None),
            (2, None),
            (3, Some(0)),
            (4, Some(5)),
            (5, Some(BLOCK_BYTES - 3)),
            (6, Some(text.len() / 2)),
            (7, Some(text.len() - 1)),
        ] {
            let source = Trickle {
                data: &text,
                at: 0,
                state: 0x9e37_79b9_7f4a_7c15 ^ seed,
                fail_at,
            };
            let mut merged = Vec::new();
            let result = parse_in_blocks(
                source,
                Vec::new(),
                1,
                |block| {
                    let lines: Vec<Vec<u8>> = lines_of(block).map(|(_, l)| l.to_vec()).collect();
                    let n = lines.len() as u64;
                    (lines, n)
                },
                |first, _, lines: Vec<Vec<u8>>| -> Result<(), ()> {
                    for (i, l) in lines.into_iter().enumerate() {
                        merged.push((first + i as u64, l));
                    }
                    Ok(())
                },
            );
            match fail_at {
                None => {
                    assert!(result.is_ok(), "seed {seed}");
                    assert_eq!(Ok(merged), line_reader(&text), "seed {seed}");
                }
                Some(at) => {
                    assert!(
                        matches!(&result, Err(BlockError::Lines(LineError::Io(e))) if e.to_string() == "the disk went away"),
                        "seed {seed}: {result:?}"
                    );
                    let whole = memchr::memrchr(b'\n', &text[..at]).map_or(0, |p| p + 1);
                    assert_eq!(Ok(merged), line_reader(&text[..whole]), "seed {seed}");
                }
            }
        }
    }

    #[test]
    fn a_merge_error_stops_everything() {
        let text = b"1\n".repeat(2_000_000);
        let mut merged = 0;
        let result = parse_in_blocks(
            &text[..],
            Vec::new(),
            1,
            |block| ((), count_lines(block)),
            |first, _, ()| {
                merged += 1;
                if first > 100_000 { Err(first) } else { Ok(()) }
            },
        );
        assert!(matches!(result, Err(BlockError::Merge(line)) if line > 100_000));
        assert!(
            merged < 20,
            "stopped soon after the error ({merged} blocks)"
        );
    }
}
