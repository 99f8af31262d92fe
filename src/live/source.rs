//! Where a live session's lines come from: `serial:`, `udp:`, `tcp:`, `stdin`, `file:`. Each
//! source runs on a thread of its own and sends what it receives, split into lines, to the
//! session over one bounded channel.

use super::LiveError;
use crate::read::layout::Layout;
use std::io::Read;
use std::net::{IpAddr, SocketAddr, TcpStream, UdpSocket};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::time::{Duration, Instant};

/// The longest line kept (bytes); a longer one is dropped and counted.
pub const MAX_LINE: usize = 64 * 1024;

/// What a serial, UDP or TCP source's bytes are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Packets {
    /// Lines of text (imubake CSV, SOU, …).
    Lines,
    /// WitMotion's binary packets (`:witmotion`).
    WitMotion,
    /// Frames of the session's `--layout` (`:layout`).
    Layout,
}

impl Packets {
    fn suffix(self) -> &'static str {
        match self {
            Packets::Lines => "",
            Packets::WitMotion => ":witmotion",
            Packets::Layout => ":layout",
        }
    }
}

/// A source as given on the command line.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceSpec {
    /// `serial:/dev/ttyUSB0[@115200][:witmotion|:layout]`.
    Serial {
        path: PathBuf,
        baud: u32,
        packets: Packets,
    },
    /// `udp:[BIND_ADDR:]PORT[:witmotion|:layout]` (the address defaults to 127.0.0.1): lines in
    /// datagrams, WitMotion packets, or a layout's frames.
    Udp { bind: SocketAddr, packets: Packets },
    /// `tcp:HOST:PORT[:witmotion|:layout]`: a client that connects, and reconnects.
    Tcp { addr: String, packets: Packets },
    /// `stdin`.
    Stdin,
    /// `file:PATH[@SPEED]`: a capture replayed at its own pace × SPEED (default 1).
    File { path: PathBuf, speed: f64 },
}

impl std::fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SourceSpec::Serial {
                path,
                baud,
                packets,
            } => write!(f, "serial:{}@{baud}{}", path.display(), packets.suffix()),
            SourceSpec::Udp { bind, packets } => write!(f, "udp:{bind}{}", packets.suffix()),
            SourceSpec::Tcp { addr, packets } => write!(f, "tcp:{addr}{}", packets.suffix()),
            SourceSpec::Stdin => write!(f, "stdin"),
            SourceSpec::File { path, speed } => write!(f, "file:{}@{speed}", path.display()),
        }
    }
}

/// `text@N` → (text, N) when N parses; else (text, None).
fn at_suffix(s: &str) -> (&str, Option<&str>) {
    match s.rsplit_once('@') {
        Some((a, b)) if !b.is_empty() && b.chars().all(|c| c.is_ascii_digit() || c == '.') => {
            (a, Some(b))
        }
        _ => (s, None),
    }
}

impl std::str::FromStr for SourceSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<SourceSpec, String> {
        let usage = "expected serial:PATH[@BAUD][:witmotion|:layout], udp:[ADDR:]PORT[:witmotion|:layout], tcp:HOST:PORT[:witmotion|:layout], stdin or file:PATH[@SPEED]";
        if s == "stdin" || s == "-" {
            return Ok(SourceSpec::Stdin);
        }
        let (kind, rest) = s.split_once(':').ok_or_else(|| format!("`{s}`: {usage}"))?;
        let (rest, packets) = match [Packets::WitMotion, Packets::Layout]
            .into_iter()
            .find_map(|p| rest.strip_suffix(p.suffix()).map(|r| (r, p)))
        {
            Some((r, p)) if matches!(kind, "serial" | "udp" | "tcp") => (r, p),
            Some((_, p)) => {
                return Err(format!(
                    "`{s}`: `{}` applies to serial, udp and tcp sources",
                    p.suffix()
                ));
            }
            None => (rest, Packets::Lines),
        };
        match kind {
            "serial" => {
                let (path, baud) = at_suffix(rest);
                let baud = match baud {
                    None => 115_200,
                    Some(b) => b
                        .parse()
                        .ok()
                        .filter(|b| *b > 0)
                        .ok_or_else(|| format!("`{s}`: `{b}` is not a baud rate"))?,
                };
                if path.is_empty() {
                    return Err(format!("`{s}`: no port; {usage}"));
                }
                Ok(SourceSpec::Serial {
                    path: path.into(),
                    baud,
                    packets,
                })
            }
            "udp" => {
                let bind = match rest.parse::<u16>() {
                    Ok(port) => SocketAddr::new(IpAddr::from([127, 0, 0, 1]), port),
                    Err(_) => rest
                        .parse()
                        .map_err(|_| format!("`{s}`: `{rest}` is not ADDR:PORT or PORT"))?,
                };
                Ok(SourceSpec::Udp { bind, packets })
            }
            "tcp" => {
                if !rest.contains(':') {
                    return Err(format!("`{s}`: expected tcp:HOST:PORT"));
                }
                Ok(SourceSpec::Tcp {
                    addr: rest.into(),
                    packets,
                })
            }
            "file" => {
                let (path, speed) = at_suffix(rest);
                let speed = match speed {
                    None => 1.0,
                    Some(v) => v
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite() && *v > 0.0)
                        .ok_or_else(|| format!("`{s}`: `{v}` is not a speed above 0"))?,
                };
                if path.is_empty() {
                    return Err(format!("`{s}`: no file; {usage}"));
                }
                Ok(SourceSpec::File {
                    path: path.into(),
                    speed,
                })
            }
            _ => Err(format!("`{s}`: {usage}")),
        }
    }
}

/// What a source thread tells the session.
#[derive(Debug)]
pub enum Event {
    /// Complete lines (without their endings), received together at `at`.
    Lines {
        source: usize,
        lines: Vec<Vec<u8>>,
        at: Instant,
    },
    /// Something worth a line on the terminal (a reconnection, a datagram refused).
    Notice { source: usize, text: String },
    /// The source has ended (a file or stdin at its end); `None` when it ended cleanly.
    Closed {
        source: usize,
        error: Option<String>,
    },
    /// A calibration was asked for (a key, or VMC's `/VMC/Ext/Set/Calib/Exec`).
    Calibrate { from: String },
}

/// Bytes → lines, keeping the partial line between reads; a line longer than [`MAX_LINE`] is
/// dropped (counted in `too_long`).
#[derive(Debug, Default)]
pub struct LineSplitter {
    partial: Vec<u8>,
    skipping: bool,
    pub too_long: u64,
}

impl LineSplitter {
    /// Splits `bytes` onto the pending partial line; complete lines go to `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Vec<u8>>) {
        for piece in bytes.split_inclusive(|&b| b == b'\n') {
            let complete = piece.last() == Some(&b'\n');
            let body = if complete {
                &piece[..piece.len() - 1]
            } else {
                piece
            };
            if !self.skipping {
                if self.partial.len() + body.len() > MAX_LINE {
                    self.partial.clear();
                    self.skipping = true;
                    self.too_long += 1;
                } else {
                    self.partial.extend_from_slice(body);
                }
            }
            if complete {
                if !self.skipping {
                    let mut line = std::mem::take(&mut self.partial);
                    if line.last() == Some(&b'\r') {
                        line.pop();
                    }
                    out.push(line);
                }
                self.skipping = false;
            }
        }
    }

    /// The last line, when the stream ends without a line ending.
    pub fn finish(&mut self, out: &mut Vec<Vec<u8>>) {
        if !self.skipping && !self.partial.is_empty() {
            let mut line = std::mem::take(&mut self.partial);
            if line.last() == Some(&b'\r') {
                line.pop();
            }
            out.push(line);
        }
        self.skipping = false;
    }
}

/// Which senders a network source accepts (`--allow ADDR[/PREFIX],…`); empty: any.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Allow(pub Vec<(IpAddr, u8)>);

impl std::str::FromStr for Allow {
    type Err = String;
    fn from_str(s: &str) -> Result<Allow, String> {
        let mut out = Vec::new();
        for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let (addr, prefix) = match item.split_once('/') {
                Some((a, p)) => (a, Some(p)),
                None => (item, None),
            };
            let addr: IpAddr = addr
                .parse()
                .map_err(|_| format!("`{item}`: not an IP address"))?;
            let max = if addr.is_ipv4() { 32 } else { 128 };
            let prefix = match prefix {
                None => max,
                Some(p) => p
                    .parse::<u8>()
                    .ok()
                    .filter(|p| *p <= max)
                    .ok_or_else(|| format!("`{item}`: prefix beyond /{max}"))?,
            };
            out.push((addr, prefix));
        }
        Ok(Allow(out))
    }
}

impl Allow {
    pub fn admits(&self, ip: IpAddr) -> bool {
        if self.0.is_empty() {
            return true;
        }
        let bits = |ip: IpAddr| -> (u128, u8) {
            match ip {
                IpAddr::V4(v) => (u32::from(v) as u128, 32),
                IpAddr::V6(v) => match v.to_ipv4_mapped() {
                    Some(v4) => (u32::from(v4) as u128, 32),
                    None => (u128::from(v), 128),
                },
            }
        };
        let (x, width) = bits(ip);
        self.0.iter().any(|&(net, prefix)| {
            let (n, w) = bits(net);
            if w != width {
                return false;
            }
            let shift = (width - prefix.min(width)) as u32;
            let mask = if shift >= 128 { 0 } else { u128::MAX << shift };
            (x & mask) == (n & mask)
        })
    }
}

/// Counters a source thread keeps for the status line.
#[derive(Debug, Default)]
pub struct SourceCounters {
    /// Datagrams or lines the session could not keep up with (dropped at the channel).
    pub overflowed: AtomicU64,
    /// Datagrams refused by `--allow`.
    pub refused: AtomicU64,
    /// Lines longer than [`MAX_LINE`].
    pub too_long: AtomicU64,
    /// Datagrams the system dropped before they were read, its receive buffer full (Linux: the
    /// socket's `drops` in `/proc/net/udp`; 0 elsewhere, where it cannot be known).
    pub lost_datagrams: AtomicU64,
}

/// What every source thread has: its index, where to send, when to stop.
#[derive(Clone)]
pub struct Link {
    pub source: usize,
    pub tx: SyncSender<Event>,
    pub stop: Arc<AtomicBool>,
    pub counters: Arc<SourceCounters>,
}

impl Link {
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// Moves the splitter's count of over-long lines into the session's counters as they come
    /// (the session's summary must not wait for the source's end).
    fn count_too_long(&self, split: &mut LineSplitter) {
        if split.too_long > 0 {
            self.counters
                .too_long
                .fetch_add(std::mem::take(&mut split.too_long), Ordering::Relaxed);
        }
    }

    /// Sends lines, waiting when the session is behind (streams whose sender can wait).
    fn send(&self, lines: Vec<Vec<u8>>) -> bool {
        if lines.is_empty() {
            return true;
        }
        self.tx
            .send(Event::Lines {
                source: self.source,
                lines,
                at: Instant::now(),
            })
            .is_ok()
    }

    /// Sends lines without waiting: a burst the session cannot keep up with is dropped and
    /// counted, so memory stays bounded (datagrams).
    fn offer(&self, lines: Vec<Vec<u8>>) -> bool {
        if lines.is_empty() {
            return true;
        }
        let n = lines.len() as u64;
        match self.tx.try_send(Event::Lines {
            source: self.source,
            lines,
            at: Instant::now(),
        }) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) => {
                self.counters.overflowed.fetch_add(n, Ordering::Relaxed);
                true
            }
            Err(TrySendError::Disconnected(_)) => false,
        }
    }

    fn notice(&self, text: String) {
        let _ = self.tx.send(Event::Notice {
            source: self.source,
            text,
        });
    }

    fn closed(&self, error: Option<String>) {
        let _ = self.tx.send(Event::Closed {
            source: self.source,
            error,
        });
    }
}

/// Starts the thread of one source. Errors that stop it before it starts (a file that cannot
/// be opened, a port already bound) come back at once.
pub fn start(
    spec: &SourceSpec,
    link: Link,
    allow: Allow,
    layout: Option<Arc<Layout>>,
) -> Result<std::thread::JoinHandle<()>, LiveError> {
    let name = spec.to_string();
    let io = |source: std::io::Error| LiveError::Source {
        source_name: name.clone(),
        source,
    };
    let handle = match spec.clone() {
        SourceSpec::File { path, speed } => {
            let file = std::fs::File::open(&path).map_err(io)?;
            std::thread::spawn(move || replay(file, speed, &link))
        }
        SourceSpec::Stdin => std::thread::spawn(move || {
            let stdin = std::io::stdin();
            read_stream(stdin.lock(), &link);
        }),
        SourceSpec::Udp { bind, packets } => {
            let socket = udp_socket(bind).map_err(io)?;
            let framing = Framing::new(packets, &format!("udp{}", bind.port()), layout)
                .map_err(|e| io(std::io::Error::other(e)))?;
            std::thread::spawn(move || udp(socket, &link, &allow, framing))
        }
        SourceSpec::Tcp { addr, packets } => {
            let framing =
                Framing::new(packets, "tcp", layout).map_err(|e| io(std::io::Error::other(e)))?;
            std::thread::spawn(move || tcp(&addr, &link, &allow, framing))
        }
        SourceSpec::Serial {
            path,
            baud,
            packets,
        } => {
            // A device's lines carry the port's name (`ttyUSB0`) as their sensor when its
            // packets name none.
            let sensor = path
                .file_name()
                .map_or_else(|| "serial".into(), |n| n.to_string_lossy().into_owned());
            let framing =
                Framing::new(packets, &sensor, layout).map_err(|e| io(std::io::Error::other(e)))?;
            std::thread::spawn(move || serial(&path, baud, framing, &link))
        }
    };
    Ok(handle)
}

/// How reading a source ended.
enum Pumped {
    /// The session stopped.
    Stopped,
    /// The stream's end (0 bytes read).
    Ended,
    /// A read failed.
    Lost(std::io::Error),
}

/// A read error that only means "nothing yet" (a timeout) or "try again".
fn transient(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::WouldBlock
            | std::io::ErrorKind::TimedOut
            | std::io::ErrorKind::Interrupted
    )
}

/// How a source's bytes become lines: split at line ends, or WitMotion packets or a layout's
/// frames decoded into imubake CSV lines ([`crate::read::witmotion::CsvLines`],
/// [`crate::read::layout::CsvLines`]).
enum Framing {
    Lines(LineSplitter),
    WitMotion {
        lines: Box<crate::read::witmotion::CsvLines>,
        started: Instant,
        /// Bad checksums already said.
        said: u64,
    },
    Layout {
        lines: Box<crate::read::layout::CsvLines>,
        started: Instant,
        /// Dropped frames already said.
        said: u64,
    },
}

impl Framing {
    /// `sensor`: the id a device's lines carry when its packets name none; `layout`: the
    /// session's `--layout`, which a `:layout` source needs.
    fn new(packets: Packets, sensor: &str, layout: Option<Arc<Layout>>) -> Result<Framing, String> {
        Ok(match packets {
            Packets::Lines => Framing::Lines(LineSplitter::default()),
            Packets::WitMotion => Framing::WitMotion {
                lines: Box::new(crate::read::witmotion::CsvLines::new(sensor)),
                started: Instant::now(),
                said: 0,
            },
            Packets::Layout => Framing::Layout {
                lines: Box::new(crate::read::layout::CsvLines::new(
                    layout.ok_or("a `:layout` source needs --layout FILE")?,
                    sensor,
                )),
                started: Instant::now(),
                said: 0,
            },
        })
    }

    fn push(&mut self, bytes: &[u8], out: &mut Vec<Vec<u8>>, link: &Link) {
        match self {
            Framing::Lines(split) => {
                split.push(bytes, out);
                link.count_too_long(split);
            }
            Framing::WitMotion {
                lines,
                started,
                said,
            } => {
                lines.push(bytes, started.elapsed().as_secs_f64(), out);
                say_growing(link, lines.bad_checksums(), said, |n| {
                    format!("{n} WitMotion packets with a bad checksum dropped")
                });
            }
            Framing::Layout {
                lines,
                started,
                said,
            } => {
                lines.push(bytes, started.elapsed().as_secs_f64(), out);
                say_growing(link, lines.dropped(), said, |n| {
                    format!(
                        "{n} frames of the layout dropped (bad, repeated or without an orientation)"
                    )
                });
            }
        }
    }

    /// A new connection of the same source: a line or packet half received before it is gone;
    /// a WitMotion stream keeps its header and clock.
    fn restart(&mut self) {
        match self {
            Framing::Lines(split) => *split = LineSplitter::default(),
            Framing::WitMotion { lines, .. } => lines.restart(),
            Framing::Layout { lines, .. } => lines.restart(),
        }
    }

    fn finish(&mut self, out: &mut Vec<Vec<u8>>, link: &Link) {
        match self {
            Framing::Lines(split) => {
                split.finish(out);
                link.count_too_long(split);
            }
            Framing::WitMotion { lines, started, .. } => {
                lines.finish(started.elapsed().as_secs_f64(), out)
            }
            Framing::Layout { lines, started, .. } => {
                lines.finish(started.elapsed().as_secs_f64(), out)
            }
        }
    }
}

/// A count of dropped packets said as a notice when it first grows, then once per 100 more
/// (`said`: the count last said).
fn say_growing(link: &Link, count: u64, said: &mut u64, text: impl FnOnce(u64) -> String) {
    if count > *said && (*said == 0 || count >= *said + 100) {
        link.notice(text(count));
        *said = count;
    }
}

/// Reads until the end, a failure or the session's stop, sending complete lines as they come
/// (and the last, unfinished one at the end: the parsers judge it).
fn pump(reader: &mut impl Read, link: &Link, framing: &mut Framing) -> Pumped {
    let mut buf = vec![0u8; 64 * 1024];
    let how = loop {
        if link.stopped() {
            break Pumped::Stopped;
        }
        match reader.read(&mut buf) {
            Ok(0) => break Pumped::Ended,
            Ok(n) => {
                let mut lines = Vec::new();
                framing.push(&buf[..n], &mut lines, link);
                if !link.send(lines) {
                    break Pumped::Stopped;
                }
            }
            Err(e) if transient(&e) => {}
            Err(e) => break Pumped::Lost(e),
        }
    };
    let mut lines = Vec::new();
    framing.finish(&mut lines, link);
    link.send(lines);
    how
}

/// A byte stream until its end (or the session's stop).
fn read_stream(mut reader: impl Read, link: &Link) {
    match pump(
        &mut reader,
        link,
        &mut Framing::Lines(LineSplitter::default()),
    ) {
        Pumped::Stopped => {}
        Pumped::Ended => link.closed(None),
        Pumped::Lost(e) => link.closed(Some(e.to_string())),
    }
}

/// A device or a server, opened and read, and opened again with a backoff (up to 5 s) whenever
/// it goes away, until the session stops. `again` and `back` are the words for both (a TCP
/// source reconnects, a serial port is reopened).
fn reopening<R: Read>(
    link: &Link,
    mut open: impl FnMut() -> std::io::Result<R>,
    again: &str,
    back: &str,
    mut framing: Framing,
) {
    let mut delay = Duration::from_millis(200);
    let mut down = false;
    while !link.stopped() {
        let mut reader = match open() {
            Ok(r) => r,
            Err(e) => {
                if !down {
                    link.notice(format!("cannot open ({e}); retrying"));
                    down = true;
                }
                delay = back_off(delay, link);
                continue;
            }
        };
        link.notice(back.into());
        down = true;
        delay = Duration::from_millis(200);
        framing.restart();
        match pump(&mut reader, link, &mut framing) {
            Pumped::Stopped => return,
            Pumped::Ended => link.notice(format!("closed; {again}")),
            Pumped::Lost(e) => link.notice(format!("lost ({e}); {again}")),
        }
    }
}

/// A capture replayed at its own pace × `speed`: each data line is sent when its time (since the
/// first data line's) has come. Times are read by the session's own parsers and judged by its
/// clock rules ([`super::clock::SourceClock`]), so a damaged or far-future time is not waited
/// for and a restarted clock paces on from where it was; lines are split as a stream's are
/// (at most [`MAX_LINE`] bytes, longer ones counted in `too_long`), never held whole.
fn replay(mut reader: impl Read, speed: f64, link: &Link) {
    let mut clock = super::clock::SourceClock::new(super::clock::DEFAULT_HORIZON_S);
    let mut framing = Framing::Lines(LineSplitter::default());
    let mut buf = vec![0u8; 64 * 1024];
    let mut lines = Vec::new();
    let mut judged = Vec::new();
    let start = Instant::now();
    let mut first: Option<f64> = None;
    loop {
        if link.stopped() {
            return;
        }
        let n = match reader.read(&mut buf) {
            Ok(0) => {
                framing.finish(&mut lines, link);
                0
            }
            Ok(n) => {
                framing.push(&buf[..n], &mut lines, link);
                n
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => {
                link.closed(Some(e.to_string()));
                return;
            }
        };
        for line in lines.drain(..) {
            clock.push(line, &mut judged);
        }
        if n == 0 {
            clock.finish(&mut judged);
        }
        for j in judged.drain(..) {
            let (line, t_s) = match j {
                super::clock::Judged::Take { line, t_s } => (line, t_s),
                // The session judges the same lines the same way and reports them.
                super::clock::Judged::Drop { line, .. } => (line, None),
                super::clock::Judged::Notice(_) => continue,
            };
            if let Some(t) = t_s {
                let t0 = *first.get_or_insert(t);
                let due = Duration::try_from_secs_f64((t - t0) / speed).unwrap_or(Duration::ZERO);
                // Slept in slices, so a stop is seen within 100 ms.
                while let Some(wait) = due.checked_sub(start.elapsed()) {
                    if link.stopped() {
                        return;
                    }
                    if wait.is_zero() {
                        break;
                    }
                    std::thread::sleep(wait.min(Duration::from_millis(100)));
                }
            }
            if !link.send(vec![line]) {
                return;
            }
        }
        if n == 0 {
            break;
        }
    }
    link.closed(None);
}

/// The receive buffer asked for (bytes). Datagrams wait there while this thread is off its core;
/// the system's default (~200 KiB) holds ~256 small datagrams as the kernel counts them (~830
/// bytes each), 0.16 s of a 16-sensor suit sending a datagram per reading at 100 Hz, and less
/// when a recording is replayed faster. Linux grants at most `net.core.rmem_max` (commonly 4 MiB).
pub const UDP_RECEIVE_BUFFER: usize = 4 << 20;

/// A bound datagram socket with a large receive buffer and a 100 ms read timeout (so the thread
/// sees the session stop).
fn udp_socket(bind: SocketAddr) -> std::io::Result<UdpSocket> {
    use socket2::{Domain, Protocol, Socket, Type};
    let socket = Socket::new(Domain::for_address(bind), Type::DGRAM, Some(Protocol::UDP))?;
    // Best effort: a smaller buffer than asked for still works.
    let _ = socket.set_recv_buffer_size(UDP_RECEIVE_BUFFER);
    socket.bind(&bind.into())?;
    let socket = UdpSocket::from(socket);
    socket.set_read_timeout(Some(Duration::from_millis(100)))?;
    Ok(socket)
}

/// The datagrams the system has dropped for this socket since it was opened: the `drops` column
/// of its row (found by the socket's inode) in `/proc/net/udp` or `/proc/net/udp6`. `None` off
/// Linux or when the row cannot be read.
#[cfg(target_os = "linux")]
fn kernel_drops(socket: &UdpSocket) -> Option<u64> {
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::MetadataExt;
    let inode = std::fs::metadata(format!("/proc/self/fd/{}", socket.as_raw_fd()))
        .ok()?
        .ino();
    ["/proc/net/udp", "/proc/net/udp6"]
        .iter()
        .find_map(|table| {
            let text = std::fs::read_to_string(table).ok()?;
            drops_of(&text, inode)
        })
}

#[cfg(not(target_os = "linux"))]
fn kernel_drops(_socket: &UdpSocket) -> Option<u64> {
    None
}

/// The `drops` (last) column of the row whose `inode` (tenth) column is `inode`, in the text of
/// `/proc/net/udp` (a header line, then one row per socket).
#[cfg_attr(not(target_os = "linux"), allow(dead_code))]
fn drops_of(table: &str, inode: u64) -> Option<u64> {
    table.lines().skip(1).find_map(|row| {
        let columns: Vec<&str> = row.split_whitespace().collect();
        // sl local rem st tx:rx tr:when retrnsmt uid timeout inode ref pointer drops
        if columns.len() < 13 || columns[9].parse::<u64>().ok()? != inode {
            return None;
        }
        columns.last()?.parse().ok()
    })
}

fn udp(socket: UdpSocket, link: &Link, allow: &Allow, mut framing: Framing) {
    let mut buf = vec![0u8; 65_536];
    let mut drops_read = Instant::now();
    let read_drops = || {
        if let Some(n) = kernel_drops(&socket) {
            link.counters.lost_datagrams.store(n, Ordering::Relaxed);
        }
    };
    while !link.stopped() {
        // Twice a second is enough for the status line; the last count is read on the way out.
        if drops_read.elapsed() >= Duration::from_millis(500) {
            read_drops();
            drops_read = Instant::now();
        }
        match socket.recv_from(&mut buf) {
            Ok((n, from)) => {
                if !allow.admits(from.ip()) {
                    link.counters.refused.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                // A datagram holds whole lines (WitMotion packets may run on into the next).
                let mut lines = Vec::new();
                framing.push(&buf[..n], &mut lines, link);
                if let Framing::Lines(_) = framing {
                    framing.finish(&mut lines, link);
                }
                if !link.offer(lines) {
                    break;
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) => {}
            Err(e) => {
                link.notice(format!("receive failed: {e}"));
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
    read_drops();
}

/// Waits `delay` unless the session stops first; the next delay (doubling, at most 5 s).
fn back_off(delay: Duration, link: &Link) -> Duration {
    let until = Instant::now() + delay;
    while Instant::now() < until && !link.stopped() {
        std::thread::sleep(Duration::from_millis(50));
    }
    (delay * 2).min(Duration::from_secs(5))
}

fn tcp(addr: &str, link: &Link, allow: &Allow, framing: Framing) {
    let open = || {
        let a = std::net::ToSocketAddrs::to_socket_addrs(addr)?
            .next()
            .ok_or_else(|| std::io::Error::other("no such address"))?;
        if !allow.admits(a.ip()) {
            return Err(std::io::Error::other("refused by --allow"));
        }
        let stream = TcpStream::connect_timeout(&a, Duration::from_secs(2))?;
        stream.set_read_timeout(Some(Duration::from_millis(100)))?;
        Ok(stream)
    };
    reopening(link, open, "reconnecting", "connected", framing);
}

fn serial(path: &std::path::Path, baud: u32, framing: Framing, link: &Link) {
    // A port with a timeout says "no data yet" as TimedOut; 0 bytes is its end (the device
    // gone, a pty whose other side closed).
    let open = || {
        serialport::new(path.to_string_lossy(), baud)
            .timeout(Duration::from_millis(100))
            .open()
            .map_err(std::io::Error::from)
    };
    reopening(link, open, "reopening", "opened", framing);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two rows as Linux 6 prints them (a socket bound to 127.0.0.1:54539 whose buffer held 256
    /// datagrams of 3 000 sent, and another): the drops of the one asked for.
    #[test]
    fn drops_are_read_from_the_sockets_row() {
        let table = "   sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode ref pointer drops            \n 3358: 0100007F:D50B 00000000:0000 07 00000000:00034000 00:00000000 00000000     0        0 6096 2 00000000a6bb308c 2744       \n14196: 00000000:BF61 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 6097 2 00000000c8413e5c 0          \n";
        assert_eq!(drops_of(table, 6096), Some(2744));
        assert_eq!(drops_of(table, 6097), Some(0));
        assert_eq!(drops_of(table, 3358), None);
        assert_eq!(drops_of("", 6096), None);
        assert_eq!(drops_of("header\n 1: short row 6096\n", 6096), None);
    }

    /// The system's own count, read back: datagrams sent to a socket nobody reads overflow its
    /// buffer, and what is then read plus what the system says it dropped is what was sent.
    #[cfg(target_os = "linux")]
    #[test]
    fn the_systems_drops_and_the_datagrams_read_add_up_to_those_sent() {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket.set_nonblocking(true).unwrap();
        let sender = UdpSocket::bind("127.0.0.1:0").unwrap();
        let to = socket.local_addr().unwrap();
        let sent = 20_000;
        for _ in 0..sent {
            sender.send_to(&[b'x'; 60], to).unwrap();
        }
        let mut buf = [0u8; 128];
        let mut read = 0;
        while socket.recv_from(&mut buf).is_ok() {
            read += 1;
        }
        let dropped = kernel_drops(&socket).expect("the socket's row in /proc/net/udp");
        assert!(dropped > 0, "a default buffer holds 20 000 datagrams?");
        assert_eq!(read + dropped, sent);
    }

    /// A `udp:` source's buffer is the one asked for, within what the system allows.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_udp_source_asks_for_a_large_receive_buffer() {
        let socket = udp_socket("127.0.0.1:0".parse().unwrap()).unwrap();
        let max: usize = std::fs::read_to_string("/proc/sys/net/core/rmem_max")
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        // Linux doubles the size asked for (its bookkeeping) and reports the double.
        let got = socket2::SockRef::from(&socket).recv_buffer_size().unwrap();
        assert_eq!(got, 2 * UDP_RECEIVE_BUFFER.min(max), "rmem_max {max}");
    }

    #[test]
    fn specs_parse_and_bad_ones_say_why() {
        let udp = |bind: &str, packets| SourceSpec::Udp {
            bind: bind.parse().unwrap(),
            packets,
        };
        let serial = |path: &str, baud, packets| SourceSpec::Serial {
            path: path.into(),
            baud,
            packets,
        };
        for (spec, expected) in [
            (
                "serial:/dev/ttyUSB0",
                serial("/dev/ttyUSB0", 115_200, Packets::Lines),
            ),
            (
                "serial:/dev/ttyACM1@9600",
                serial("/dev/ttyACM1", 9600, Packets::Lines),
            ),
            (
                "serial:/dev/ttyUSB0@115200:witmotion",
                serial("/dev/ttyUSB0", 115_200, Packets::WitMotion),
            ),
            (
                "udp:9001:witmotion",
                udp("127.0.0.1:9001", Packets::WitMotion),
            ),
            ("udp:9000", udp("127.0.0.1:9000", Packets::Lines)),
            ("udp:0.0.0.0:9000", udp("0.0.0.0:9000", Packets::Lines)),
            ("udp:9000:layout", udp("127.0.0.1:9000", Packets::Layout)),
            (
                "file:take@user.log@2.5",
                SourceSpec::File {
                    path: "take@user.log".into(),
                    speed: 2.5,
                },
            ),
            (
                "tcp:host:9:layout",
                SourceSpec::Tcp {
                    addr: "host:9".into(),
                    packets: Packets::Layout,
                },
            ),
        ] {
            assert_eq!(spec.parse::<SourceSpec>().unwrap(), expected, "{spec}");
        }
        for bad in [
            "serial:",
            "udp:x",
            "tcp:host",
            "file:a@0",
            "nope:1",
            "x",
            "file:a:witmotion",
            "serial::witmotion",
        ] {
            assert!(bad.parse::<SourceSpec>().is_err(), "{bad}");
        }
        assert_eq!(
            "serial:/dev/ttyACM0@921600:layout"
                .parse::<SourceSpec>()
                .unwrap()
                .to_string(),
            "serial:/dev/ttyACM0@921600:layout"
        );
        assert!(
            "file:take.bin:layout"
                .parse::<SourceSpec>()
                .unwrap_err()
                .contains("`:layout` applies to serial, udp and tcp")
        );
    }

    #[test]
    fn lines_split_across_reads_and_long_lines_are_dropped() {
        let mut s = LineSplitter::default();
        let mut out = Vec::new();
        s.push(b"ab", &mut out);
        s.push(b"c\r\nde\nf", &mut out);
        assert_eq!(out, vec![b"abc".to_vec(), b"de".to_vec()]);
        let long = vec![b'x'; MAX_LINE + 1];
        s.push(&long, &mut out);
        s.push(b"\nok\n", &mut out);
        assert_eq!(out.last().unwrap(), b"ok");
        assert_eq!(s.too_long, 1);
        s.push(b"tail", &mut out);
        s.finish(&mut out);
        assert_eq!(out.last().unwrap(), b"tail");
    }

    #[test]
    fn allow_lists_match_prefixes() {
        let a: Allow = "192.168.1.0/24, 10.0.0.7".parse().unwrap();
        assert!(a.admits("192.168.1.77".parse().unwrap()));
        assert!(!a.admits("192.168.2.1".parse().unwrap()));
        assert!(a.admits("10.0.0.7".parse().unwrap()));
        assert!(!a.admits("10.0.0.8".parse().unwrap()));
        assert!(a.admits("::ffff:10.0.0.7".parse().unwrap()));
        assert!(Allow::default().admits("8.8.8.8".parse().unwrap()));
        assert!("10.0.0.0/33".parse::<Allow>().is_err());
        let zero: Allow = "0.0.0.0/0".parse().unwrap();
        assert!(zero.admits("1.2.3.4".parse().unwrap()));
    }
}
