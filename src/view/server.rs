//! The viewer's HTTP and WebSocket server, by hand: std's `TcpListener`, a thread per
//! connection, `httparse` for the request's head, answers written here, and `tungstenite` on an
//! upgraded `/live` connection (ARCHITECTURE.md says why not an async stack or a server crate).
//!
//! Paths: the page's assets ([`super::assets`]), `/take.json`, `/chunk/<k>.glb` (`k` in
//! decimal digits, below the take's chunk count), in a live session `/live`, and in `imubake
//! setup` its page at `/` (the viewer's at `/index.html`) and its board's socket `/setup` (the
//! page's commands come back over it, so the same `Origin` check guards them). Anything else
//! is 404: the server opens no file after it starts. Against DNS rebinding (a web page reaching
//! it under a name of its own), it refuses (403) a request whose `Host` is not, bound to
//! loopback, `127.0.0.1`, `localhost`, `[::1]` or the address it listens on, and, bound
//! elsewhere, an IP address (`[…]` for IPv6) or `localhost`; always with the server's port
//! (omitted only on port 80), names in any case. Only GET and HEAD; every answer closes its
//! connection.
//!
//! What a client can hold:
//! - **Its head**, read as it comes and never held past its limits and one read
//!   ([`READ_CHUNK`]): the request line at most [`MAX_REQUEST_LINE`] bytes (else 414), at most
//!   [`MAX_HEADERS`] header lines of at most [`MAX_HEADER_LINE`] bytes each and
//!   [`MAX_HEADER_BYTES`] together, line ends included (else 431); all of it within
//!   [`HEAD_DEADLINE`] of the connection (else 408, or closed if nothing came).
//! - **A thread**: at most [`MAX_CONNECTIONS`] page connections at once. One more closes the
//!   oldest still sending its head or lingering after its answer (so idle, slow or non-reading
//!   sockets never lock the page out); with none such, it is answered 503.
//! - **An answer's write**: in pieces of at most [`WRITE_PIECE`] bytes, the whole of it within
//!   [`WRITE_BASE`] plus a second for each [`WRITE_RATE`] bytes of it (10 s for the page's
//!   assets and `take.json`), then a linger of at most [`LINGER`]: a client that never reads
//!   holds its connection no longer.
//! - **A `/live` socket**: at most [`MAX_LIVE`], counted apart from page connections (more are
//!   503, and the page still loads), each upgraded only from the page's own origin: `Origin`
//!   must be `http://` and the request's own `Host` (checked against loopback when bound there),
//!   else 403, so that another site open in the browser cannot read the session.

use super::live::{Preview, Seen};
use super::motion::{MAX_JOINTS, ViewTake};
use super::{ViewError, assets};
use crate::setup::Setup;
use std::collections::{BTreeMap, VecDeque};
use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The request line's limit, bytes, its line end excluded (past it: 414).
pub const MAX_REQUEST_LINE: usize = 8 * 1024;
/// A header line's limit, bytes, its line end excluded (past it: 431).
pub const MAX_HEADER_LINE: usize = 8 * 1024;
/// Header lines in a request (past it: 431).
pub const MAX_HEADERS: usize = 100;
/// All header lines together, line ends included, bytes (past it: 431).
pub const MAX_HEADER_BYTES: usize = 64 * 1024;
/// The whole head must arrive within this of the connection (else 408).
pub const HEAD_DEADLINE: Duration = Duration::from_secs(10);
/// Page connections at once (a thread each).
pub const MAX_CONNECTIONS: usize = 64;
/// `/live` WebSockets at once, apart from page connections.
pub const MAX_LIVE: usize = 16;
/// One read of a head: a client holds at most its limits and this.
pub const READ_CHUNK: usize = 8 * 1024;
/// A write that moves nothing for this long ends the connection.
const WRITE_STALL: Duration = Duration::from_secs(30);
/// An answer is written in pieces of at most this, bytes, the deadline checked before each.
pub const WRITE_PIECE: usize = 16 << 10;
/// An answer must be written within this, plus a second for each [`WRITE_RATE`] bytes of it (a
/// client reading slowly, or not at all, cannot hold a thread for ever).
pub const WRITE_BASE: Duration = Duration::from_secs(10);
/// The slowest reader an answer waits for past [`WRITE_BASE`], bytes a second.
pub const WRITE_RATE: usize = 64 << 10;
/// After an answer, what the client still sends is read and dropped for at most this, so that
/// closing with unread bytes does not reset the connection before the client reads the answer.
/// A lingering connection is closed early to make room for a new one.
pub const LINGER: Duration = Duration::from_secs(2);
/// How often the setup page gets the board.
const SETUP_PERIOD: Duration = Duration::from_millis(100);
/// Chunks kept made (the page asks for the one it shows and the next).
const KEEP_CHUNKS: usize = 4;

/// Where to listen.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// `127.0.0.1:0` by default: loopback, a free port.
    pub listen: SocketAddr,
}

/// A bound server, not yet serving.
pub struct Server {
    listener: TcpListener,
    addr: SocketAddr,
    shared: Arc<Shared>,
}

struct Shared {
    take: ViewTake,
    take_json: Arc<Vec<u8>>,
    preview: Option<Arc<Preview>>,
    /// `imubake setup`'s board: `/` is its page, `/setup` its WebSocket.
    setup: Option<Arc<Setup>>,
    /// The last chunks made, newest last.
    chunks: Mutex<VecDeque<(usize, Arc<Vec<u8>>)>>,
    /// `Host` values accepted, lower case (bound to loopback); `None`: an IP address or
    /// `localhost` with [`Shared::port`].
    hosts: Option<Vec<String>>,
    /// The port listened on.
    port: u16,
    /// Page connections open.
    connections: AtomicUsize,
    /// `/live` sockets open.
    live: AtomicUsize,
    /// Connections still sending their head, oldest first: the ones closed to make room.
    waiting: Mutex<BTreeMap<u64, TcpStream>>,
}

impl Server {
    /// Binds to `options.listen` (port 0: a free one). `preview`: a live session's poses, served
    /// on `/live`. A take the page cannot be given (more than [`MAX_JOINTS`] joints) is an
    /// error here, before anything is served.
    pub fn bind(
        take: ViewTake,
        options: &ServeOptions,
        preview: Option<Arc<Preview>>,
    ) -> Result<Server, ViewError> {
        if take.joints.len() > MAX_JOINTS {
            return Err(ViewError::TooManyJoints {
                joints: take.joints.len(),
            });
        }
        let fail = |e: io::Error| ViewError::Bind {
            addr: options.listen.to_string(),
            reason: e.to_string(),
        };
        let listener = TcpListener::bind(options.listen).map_err(fail)?;
        let addr = listener.local_addr().map_err(fail)?;
        // Accepted without blocking, so that `run` sees its stop flag.
        listener.set_nonblocking(true).map_err(fail)?;
        let hosts = addr.ip().is_loopback().then(|| {
            let port = addr.port();
            let mut hosts = vec![
                format!("127.0.0.1:{port}"),
                format!("localhost:{port}"),
                format!("[::1]:{port}"),
            ];
            // `SocketAddr` shows an IPv6 address bracketed, as a `Host` has it.
            let bound = addr.to_string();
            if !hosts.contains(&bound) {
                hosts.push(bound);
            }
            if port == 80 {
                let bare: Vec<String> = hosts
                    .iter()
                    .filter_map(|h| h.strip_suffix(":80").map(str::to_string))
                    .collect();
                hosts.extend(bare);
            }
            hosts
        });
        let take_json = serde_json::to_vec(&take.json()).map_err(|e| ViewError::Bind {
            addr: addr.to_string(),
            reason: e.to_string(),
        })?;
        Ok(Server {
            listener,
            addr,
            shared: Arc::new(Shared {
                take,
                take_json: Arc::new(take_json),
                preview,
                setup: None,
                chunks: Mutex::new(VecDeque::new()),
                hosts,
                port: addr.port(),
                connections: AtomicUsize::new(0),
                live: AtomicUsize::new(0),
                waiting: Mutex::new(BTreeMap::new()),
            }),
        })
    }

    /// Serves `imubake setup`'s page at `/` and its board on the `/setup` WebSocket (the
    /// viewer's page stays at `/index.html`).
    pub fn with_setup(mut self, setup: Arc<Setup>) -> Server {
        Arc::get_mut(&mut self.shared)
            .expect("not serving yet: the only handle")
            .setup = Some(setup);
        self
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The page's URL.
    pub fn url(&self) -> String {
        let host = if self.addr.ip().is_unspecified() {
            "127.0.0.1".to_string()
        } else if self.addr.is_ipv6() {
            format!("[{}]", self.addr.ip())
        } else {
            self.addr.ip().to_string()
        };
        format!("http://{host}:{}/", self.addr.port())
    }

    /// Serves until `stop` is set.
    pub fn run(self, stop: &Arc<AtomicBool>) {
        let mut id = 0u64;
        while !stop.load(Ordering::Relaxed) {
            match self.listener.accept() {
                Ok((stream, _)) => {
                    id += 1;
                    admit(&self.shared, stream, id, stop);
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    wait_for_connection(&self.listener)
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                // Out of file descriptors, or a connection gone before it was accepted.
                Err(_) => std::thread::sleep(Duration::from_millis(10)),
            }
        }
    }
}

/// Waits up to 100 ms for a connection to accept.
#[cfg(unix)]
fn wait_for_connection(listener: &TcpListener) {
    use std::os::fd::AsRawFd;
    let mut fd = libc::pollfd {
        fd: listener.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: one pollfd, valid for the call, holding the listener's open descriptor.
    unsafe { libc::poll(&mut fd, 1, 100) };
}

#[cfg(not(unix))]
fn wait_for_connection(_: &TcpListener) {
    std::thread::sleep(Duration::from_millis(10));
}

/// A page connection's place in the count, given back when dropped (or on its way to `/live`).
struct PageSlot<'a>(Option<&'a AtomicUsize>);

impl PageSlot<'_> {
    fn release(&mut self) {
        if let Some(count) = self.0.take() {
            count.fetch_sub(1, Ordering::AcqRel);
        }
    }
}

impl Drop for PageSlot<'_> {
    fn drop(&mut self) {
        self.release();
    }
}

/// A thread for a new connection, room made for it if need be, or a 503.
fn admit(shared: &Arc<Shared>, stream: TcpStream, id: u64, stop: &Arc<AtomicBool>) {
    // Accepted sockets inherit non-blocking mode on some systems.
    if stream.set_nonblocking(false).is_err() {
        return;
    }
    let open = shared.connections.load(Ordering::Acquire);
    // The evicted connection's thread leaves at once (its socket shut): the count stays near
    // MAX_CONNECTIONS, never past twice it.
    if open >= MAX_CONNECTIONS && (open >= 2 * MAX_CONNECTIONS || !evict_oldest(shared)) {
        // The answer fits the new socket's buffer: written without waiting, then closed.
        let mut stream = stream;
        let _ = stream.set_nonblocking(true);
        let _ = stream.write_all(&answer_bytes(&Reply::text(503, "busy"), true));
        return;
    }
    shared.connections.fetch_add(1, Ordering::AcqRel);
    let (mine, stop) = (Arc::clone(shared), Arc::clone(stop));
    let spawned = std::thread::Builder::new()
        .name("imubake-view".into())
        .spawn(move || {
            let mut slot = PageSlot(Some(&mine.connections));
            connection(&mine, stream, id, &stop, &mut slot);
        });
    if spawned.is_err() {
        shared.connections.fetch_sub(1, Ordering::AcqRel);
    }
}

/// Closes the connection that has been sending its head longest; false when none is.
fn evict_oldest(shared: &Shared) -> bool {
    let oldest = lock(&shared.waiting).pop_first();
    match oldest {
        Some((_, stream)) => {
            let _ = stream.shutdown(Shutdown::Both);
            true
        }
        None => false,
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// One connection: its head, then its answer (or the live socket).
fn connection(
    shared: &Shared,
    mut stream: TcpStream,
    id: u64,
    stop: &AtomicBool,
    slot: &mut PageSlot<'_>,
) {
    let deadline = Instant::now() + HEAD_DEADLINE;
    if let Ok(handle) = stream.try_clone() {
        lock(&shared.waiting).insert(id, handle);
    }
    let head = read_head(&mut stream, deadline);
    lock(&shared.waiting).remove(&id);
    let _ = stream.set_nodelay(true);
    let head = match head {
        Ok(head) => head,
        Err(HeadError::Closed) => return,
        Err(HeadError::Refused(status)) => {
            answer(shared, id, stream, &Reply::refusal(status), true);
            return;
        }
    };
    match route(shared, &head) {
        Route::Reply(reply) => answer(shared, id, stream, &reply, head.method != "HEAD"),
        Route::Live(feed) => live(shared, id, feed, stream, head, stop, slot),
    }
}

/// A request's head.
#[derive(Debug, Clone, PartialEq)]
struct Head {
    method: String,
    target: String,
    headers: Vec<(String, String)>,
    /// What came after it in the same reads.
    rest: Vec<u8>,
}

impl Head {
    /// The first header named `name` (any case); a value that is not UTF-8 has U+FFFD in it.
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    fn count(&self, name: &str) -> usize {
        self.headers
            .iter()
            .filter(|(n, _)| n.eq_ignore_ascii_case(name))
            .count()
    }
}

#[derive(Debug, Clone, PartialEq)]
enum HeadError {
    /// Closed, or silent until the deadline, before a byte came: no answer.
    Closed,
    /// Answered with this status.
    Refused(u16),
}

/// Reads a head as it comes, within `deadline`.
fn read_head(stream: &mut TcpStream, deadline: Instant) -> Result<Head, HeadError> {
    let mut scanner = HeadScanner::default();
    let mut buf = [0u8; READ_CHUNK];
    // Silent until the deadline: closed without a word (a browser's spare connection); part of
    // a head: 408.
    let late = |s: &HeadScanner| {
        if s.buf.is_empty() {
            HeadError::Closed
        } else {
            HeadError::Refused(408)
        }
    };
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(late(&scanner));
        }
        stream
            .set_read_timeout(Some(left))
            .map_err(|_| HeadError::Closed)?;
        let n = match stream.read(&mut buf) {
            // The client stopped sending before its head's end.
            Ok(0) if scanner.buf.is_empty() => return Err(HeadError::Closed),
            Ok(0) => return Err(HeadError::Refused(400)),
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                return Err(late(&scanner));
            }
            Err(_) => return Err(HeadError::Closed),
        };
        match scanner.push(&buf[..n]) {
            Scan::More => {}
            Scan::Refused(status) => return Err(HeadError::Refused(status)),
            Scan::Head(len) => return scanner.parse(len),
        }
    }
}

/// A head being read: its lines checked against the limits as they come, so that no more than
/// the limits and the last read are ever held, and the answer is the same however the bytes
/// are split into reads.
#[derive(Debug, Default)]
struct HeadScanner {
    buf: Vec<u8>,
    /// Where the line being read starts.
    line_start: usize,
    /// The request line is whole.
    request_line: bool,
    headers: usize,
    /// The header lines' bytes, line ends included.
    header_bytes: usize,
}

#[derive(Debug, PartialEq)]
enum Scan {
    More,
    /// The head is the first this many bytes.
    Head(usize),
    Refused(u16),
}

impl HeadScanner {
    fn push(&mut self, data: &[u8]) -> Scan {
        let mut at = self.buf.len();
        self.buf.extend_from_slice(data);
        while let Some(i) = memchr::memchr(b'\n', &self.buf[at..]) {
            let end = at + i;
            let line = &self.buf[self.line_start..end];
            let len = line.len() - usize::from(line.last() == Some(&b'\r'));
            if !self.request_line {
                if len > MAX_REQUEST_LINE {
                    return Scan::Refused(414);
                }
                if len == 0 {
                    return Scan::Refused(400);
                }
                self.request_line = true;
            } else if len == 0 {
                return Scan::Head(end + 1);
            } else {
                self.headers += 1;
                self.header_bytes += end + 1 - self.line_start;
                if len > MAX_HEADER_LINE
                    || self.headers > MAX_HEADERS
                    || self.header_bytes > MAX_HEADER_BYTES
                {
                    return Scan::Refused(431);
                }
            }
            self.line_start = end + 1;
            at = end + 1;
        }
        // The line still coming: refused as soon as it is sure to be over a limit (its end may
        // add a CR that does not count, and adds a LF that does).
        let partial = self.buf.len() - self.line_start;
        if !self.request_line {
            if partial > MAX_REQUEST_LINE + 1 {
                return Scan::Refused(414);
            }
        } else if partial > MAX_HEADER_LINE + 1
            || (partial >= 2 && self.header_bytes + partial + 1 > MAX_HEADER_BYTES)
        {
            return Scan::Refused(431);
        }
        Scan::More
    }

    /// The head, the first `len` bytes, parsed.
    fn parse(self, len: usize) -> Result<Head, HeadError> {
        let mut headers = [httparse::EMPTY_HEADER; MAX_HEADERS];
        let mut request = httparse::Request::new(&mut headers);
        match request.parse(&self.buf[..len]) {
            Ok(httparse::Status::Complete(n)) if n == len => {}
            Err(httparse::Error::TooManyHeaders) => return Err(HeadError::Refused(431)),
            _ => return Err(HeadError::Refused(400)),
        }
        Ok(Head {
            method: request.method.unwrap_or_default().to_string(),
            target: request.path.unwrap_or_default().to_string(),
            headers: request
                .headers
                .iter()
                .map(|h| {
                    (
                        h.name.to_string(),
                        String::from_utf8_lossy(h.value).into_owned(),
                    )
                })
                .collect(),
            rest: self.buf[len..].to_vec(),
        })
    }
}

/// An answer.
struct Reply {
    status: u16,
    content_type: &'static str,
    cache: &'static str,
    body: Body,
}

enum Body {
    Static(&'static [u8]),
    Shared(Arc<Vec<u8>>),
    Text(String),
}

impl Body {
    fn bytes(&self) -> &[u8] {
        match self {
            Body::Static(b) => b,
            Body::Shared(b) => b,
            Body::Text(t) => t.as_bytes(),
        }
    }
}

impl Reply {
    fn text(status: u16, text: &str) -> Reply {
        Reply {
            status,
            content_type: "text/plain; charset=utf-8",
            cache: "no-store",
            body: Body::Text(format!("{text}\n")),
        }
    }

    /// The answer to a head refused as it was read.
    fn refusal(status: u16) -> Reply {
        let text = match status {
            414 => format!("the request line is longer than {MAX_REQUEST_LINE} bytes"),
            431 => format!(
                "the request's headers are past their limits: {MAX_HEADERS} lines of at most \
                 {MAX_HEADER_LINE} bytes, {MAX_HEADER_BYTES} bytes in all"
            ),
            408 => format!(
                "the request's head did not arrive within {} s",
                HEAD_DEADLINE.as_secs()
            ),
            _ => "not an HTTP/1.1 request".into(),
        };
        Reply::text(status, &text)
    }

    /// A body whose length the page can see coming (no chunked transfer).
    fn bytes(content_type: &'static str, cache: &'static str, body: Body) -> Reply {
        Reply {
            status: 200,
            content_type,
            cache,
            body,
        }
    }
}

fn reason(status: u16) -> &'static str {
    match status {
        101 => "Switching Protocols",
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        414 => "URI Too Long",
        426 => "Upgrade Required",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "",
    }
}

/// The status line and headers of `reply`.
fn reply_head(reply: &Reply) -> String {
    let mut head = format!(
        "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: {}\r\n\
         X-Content-Type-Options: nosniff\r\n",
        reply.status,
        reason(reply.status),
        reply.content_type,
        reply.body.bytes().len(),
        reply.cache
    );
    if reply.status == 405 {
        head.push_str("Allow: GET, HEAD\r\n");
    }
    head.push_str("Connection: close\r\n\r\n");
    head
}

/// `reply` as bytes, its body too when `with_body`.
fn answer_bytes(reply: &Reply, with_body: bool) -> Vec<u8> {
    let mut out = reply_head(reply).into_bytes();
    if with_body {
        out.extend_from_slice(reply.body.bytes());
    }
    out
}

/// Sends `reply` (its body unless a HEAD asked) and closes the connection (connection `id`).
fn answer(shared: &Shared, id: u64, mut stream: TcpStream, reply: &Reply, with_body: bool) {
    if send(&mut stream, reply, with_body).is_ok() {
        linger(shared, id, stream);
    }
}

/// The time allowed to write an answer of `len` bytes.
fn write_deadline(len: usize) -> Duration {
    WRITE_BASE + Duration::from_secs((len / WRITE_RATE) as u64)
}

fn send(stream: &mut TcpStream, reply: &Reply, with_body: bool) -> io::Result<()> {
    let body = if with_body { reply.body.bytes() } else { &[] };
    let mut out = reply_head(reply).into_bytes();
    let deadline = Instant::now() + write_deadline(out.len() + body.len());
    // The head with the first piece of the body, in one write.
    let first = body.len().min(WRITE_PIECE);
    out.extend_from_slice(&body[..first]);
    write_within(stream, &out, deadline)?;
    write_within(stream, &body[first..], deadline)
}

/// Writes `bytes` in pieces of at most [`WRITE_PIECE`], each write waiting no later than
/// `deadline` (nor longer than [`WRITE_STALL`]).
fn write_within(stream: &mut TcpStream, mut bytes: &[u8], deadline: Instant) -> io::Result<()> {
    while !bytes.is_empty() {
        let left = deadline
            .saturating_duration_since(Instant::now())
            .min(WRITE_STALL);
        if left.is_zero() {
            return Err(io::ErrorKind::TimedOut.into());
        }
        stream.set_write_timeout(Some(left))?;
        match stream.write(&bytes[..bytes.len().min(WRITE_PIECE)]) {
            Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
            Ok(n) => bytes = &bytes[n..],
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Closes after an answer: the write side at once, then what the client still sends read and
/// dropped until it closes too or [`LINGER`] passes, or a new connection needs the room.
fn linger(shared: &Shared, id: u64, mut stream: TcpStream) {
    let _ = stream.shutdown(Shutdown::Write);
    if let Ok(handle) = stream.try_clone() {
        lock(&shared.waiting).insert(id, handle);
    }
    let deadline = Instant::now() + LINGER;
    let mut sink = [0u8; READ_CHUNK];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() || stream.set_read_timeout(Some(left)).is_err() {
            break;
        }
        match stream.read(&mut sink) {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
    }
    lock(&shared.waiting).remove(&id);
}

enum Route<'a> {
    Reply(Reply),
    Live(Feed<'a>),
}

/// What a WebSocket carries.
#[derive(Clone, Copy)]
enum Feed<'a> {
    /// A live session's poses and status (`/live`).
    Preview(&'a Preview),
    /// The setup board, and the page's commands back (`/setup`).
    Setup(&'a Setup),
}

/// `/chunk/<k>.glb` → k (decimal digits only).
fn chunk_number(path: &str) -> Option<usize> {
    let k = path.strip_prefix("/chunk/")?.strip_suffix(".glb")?;
    if k.is_empty() || k.len() > 9 || !k.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    k.parse().ok()
}

fn route<'a>(shared: &'a Shared, head: &Head) -> Route<'a> {
    if head.count("Host") > 1 {
        return Route::Reply(Reply::text(400, "more than one Host"));
    }
    if !host_allowed(shared, head.header("Host")) {
        return Route::Reply(Reply::text(403, "forbidden: unexpected Host"));
    }
    if !matches!(head.method.as_str(), "GET" | "HEAD") {
        return Route::Reply(Reply::text(405, "only GET"));
    }
    // The path without its query; nothing is decoded, so `%2f` is never a separator.
    let path = head.target.split(['?', '#']).next().unwrap_or("");
    let path = match (path, &shared.setup) {
        ("/", Some(_)) => "/setup.html",
        _ => path,
    };
    if let Some(asset) = assets::find(path) {
        return Route::Reply(Reply::bytes(
            asset.content_type,
            "no-cache",
            Body::Static(asset.bytes),
        ));
    }
    if path == "/take.json" {
        return Route::Reply(Reply::bytes(
            "application/json; charset=utf-8",
            "no-store",
            Body::Shared(Arc::clone(&shared.take_json)),
        ));
    }
    if let Some(k) = chunk_number(path) {
        return Route::Reply(match chunk(shared, k) {
            Some(Ok(glb)) => Reply::bytes("model/gltf-binary", "no-store", Body::Shared(glb)),
            Some(Err(e)) => {
                eprintln!("imubake view: {e}");
                Reply::text(500, &e.to_string())
            }
            None => Reply::text(404, "no such chunk"),
        });
    }
    if path == "/live"
        && let Some(preview) = &shared.preview
    {
        return Route::Live(Feed::Preview(preview));
    }
    if path == "/setup"
        && let Some(setup) = &shared.setup
    {
        return Route::Live(Feed::Setup(setup));
    }
    Route::Reply(Reply::text(404, "not found"))
}

fn chunk(shared: &Shared, k: usize) -> Option<Result<Arc<Vec<u8>>, ViewError>> {
    {
        let cache = lock(&shared.chunks);
        if let Some((_, glb)) = cache.iter().find(|(c, _)| *c == k) {
            return Some(Ok(Arc::clone(glb)));
        }
    }
    let glb = match shared.take.chunk_glb(k)? {
        Ok(glb) => Arc::new(glb),
        Err(e) => return Some(Err(e)),
    };
    let mut cache = lock(&shared.chunks);
    cache.push_back((k, Arc::clone(&glb)));
    while cache.len() > KEEP_CHUNKS {
        cache.pop_front();
    }
    Some(Ok(glb))
}

/// Is `host` one the page may be asked under (see the module's documentation)?
fn host_allowed(shared: &Shared, host: Option<&str>) -> bool {
    let Some(host) = host else {
        return false;
    };
    if let Some(hosts) = &shared.hosts {
        return hosts.iter().any(|a| a.eq_ignore_ascii_case(host));
    }
    // `name:port`, or `name` alone on port 80; a bracketed IPv6 address has colons of its own.
    let (name, port) = match host.rsplit_once(':') {
        Some((name, port)) if !port.contains(']') => (name, Some(port)),
        _ => (host, None),
    };
    let port_ok = match port {
        Some(port) => {
            !port.is_empty()
                && port.bytes().all(|b| b.is_ascii_digit())
                && port.parse::<u16>().ok() == Some(shared.port)
        }
        None => shared.port == 80,
    };
    let name_ok = match name.strip_prefix('[').and_then(|n| n.strip_suffix(']')) {
        Some(v6) => v6.parse::<std::net::Ipv6Addr>().is_ok(),
        None => {
            name.parse::<std::net::Ipv4Addr>().is_ok() || name.eq_ignore_ascii_case("localhost")
        }
    };
    port_ok && name_ok
}

/// Is `origin` the page's own, `http://` and `host`? (Hosts compare in any case.)
fn same_origin(origin: Option<&str>, host: Option<&str>) -> bool {
    match (origin, host) {
        (Some(origin), Some(host)) if !host.is_empty() => origin
            .strip_prefix("http://")
            .is_some_and(|o| o.eq_ignore_ascii_case(host)),
        _ => false,
    }
}

/// Gives a `/live` place back when dropped.
struct LiveSlot<'a>(&'a AtomicUsize);

impl Drop for LiveSlot<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

/// The WebSocket of a live session (each new status and pose) or of a setup (the board, and the
/// page's commands), until the page goes or the session stops.
fn live(
    shared: &Shared,
    id: u64,
    feed: Feed<'_>,
    mut stream: TcpStream,
    head: Head,
    stop: &AtomicBool,
    slot: &mut PageSlot<'_>,
) {
    let with_body = head.method != "HEAD";
    let is_upgrade = head
        .header("Upgrade")
        .is_some_and(|u| u.eq_ignore_ascii_case("websocket"));
    let Some(key) = head.header("Sec-WebSocket-Key").filter(|_| is_upgrade) else {
        answer(
            shared,
            id,
            stream,
            &Reply::text(426, "a WebSocket endpoint"),
            with_body,
        );
        return;
    };
    if !same_origin(head.header("Origin"), head.header("Host")) {
        answer(
            shared,
            id,
            stream,
            &Reply::text(403, "forbidden: an Origin other than the page's"),
            with_body,
        );
        return;
    }
    if shared.live.fetch_add(1, Ordering::AcqRel) >= MAX_LIVE {
        shared.live.fetch_sub(1, Ordering::AcqRel);
        answer(
            shared,
            id,
            stream,
            &Reply::text(503, &format!("{MAX_LIVE} live connections already")),
            with_body,
        );
        return;
    }
    let _live = LiveSlot(&shared.live);
    // From here it counts among the live sockets, not the page's connections.
    slot.release();
    let accept = tungstenite::handshake::derive_accept_key(key.as_bytes());
    let switching = format!(
        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Accept: {accept}\r\n\r\n"
    );
    if stream.set_write_timeout(Some(WRITE_STALL)).is_err()
        || stream.write_all(switching.as_bytes()).is_err()
    {
        return;
    }
    // The page sends pings, its close and (the setup page) short commands: small frames,
    // small buffers.
    let config = tungstenite::protocol::WebSocketConfig::default()
        .read_buffer_size(4096)
        .write_buffer_size(0)
        .max_message_size(Some(64 << 10))
        .max_frame_size(Some(64 << 10));
    let mut socket = tungstenite::WebSocket::from_partially_read(
        stream,
        head.rest,
        tungstenite::protocol::Role::Server,
        Some(config),
    );
    let mut seen = Seen::default();
    while !stop.load(Ordering::Relaxed) {
        match feed {
            Feed::Preview(preview) => {
                for message in preview.wait(&mut seen, Duration::from_millis(200)) {
                    if socket
                        .send(tungstenite::Message::text(message.to_string()))
                        .is_err()
                    {
                        return;
                    }
                }
                if !still_open(&mut socket, &mut |_| {}) {
                    return;
                }
            }
            Feed::Setup(setup) => {
                // The board ten times a second; the page's commands between, each answered by
                // the next board at once.
                if socket
                    .send(tungstenite::Message::text(setup.snapshot_json()))
                    .is_err()
                {
                    return;
                }
                let until = Instant::now() + SETUP_PERIOD;
                let mut commanded = false;
                while !commanded && Instant::now() < until {
                    if !still_open(&mut socket, &mut |text| {
                        setup.command_json(text);
                        commanded = true;
                    }) {
                        return;
                    }
                    if !commanded {
                        std::thread::sleep(Duration::from_millis(10));
                    }
                }
            }
        }
    }
    let _ = socket.close(None);
    let _ = socket.flush();
}

/// Reads what the page sent (pings, its close) without waiting; false once it has gone.
/// Text messages go to `on_text` (the setup page's commands).
fn still_open(
    socket: &mut tungstenite::WebSocket<TcpStream>,
    on_text: &mut dyn FnMut(&str),
) -> bool {
    if socket.get_mut().set_nonblocking(true).is_err() {
        return false;
    }
    let mut open = true;
    // A page flooding frames still gets its poses.
    for _ in 0..64 {
        match socket.read() {
            Ok(tungstenite::Message::Close(_)) => {
                open = false;
                break;
            }
            Ok(tungstenite::Message::Text(text)) => on_text(text.as_str()),
            Ok(_) => {}
            Err(tungstenite::Error::Io(e)) if e.kind() == io::ErrorKind::WouldBlock => break,
            Err(_) => {
                open = false;
                break;
            }
        }
    }
    if socket.get_mut().set_nonblocking(false).is_err() {
        return false;
    }
    if !open {
        // The reply to its close.
        let _ = socket.flush();
    }
    open
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn only_decimal_chunk_numbers_name_a_chunk() {
        assert_eq!(chunk_number("/chunk/0.glb"), Some(0));
        assert_eq!(chunk_number("/chunk/12.glb"), Some(12));
        for bad in [
            "/chunk/.glb",
            "/chunk/-1.glb",
            "/chunk/+1.glb",
            "/chunk/1.glb/",
            "/chunk/..%2f1.glb",
            "/chunk/1.GLB",
            "/chunk/9999999999.glb",
            "/chunk/1",
        ] {
            assert_eq!(chunk_number(bad), None, "{bad}");
        }
    }

    /// What the server makes of `bytes` fed in reads ending at `cuts`, each at most `chunk`
    /// bytes, then the end of the stream: the head, or its refusal; and the most it held.
    fn outcome(bytes: &[u8], cuts: &[usize], chunk: usize) -> (Result<Head, HeadError>, usize) {
        let mut scanner = HeadScanner::default();
        let mut held = 0;
        let mut from = 0;
        for to in cuts.iter().copied().chain(std::iter::once(bytes.len())) {
            if to < from {
                continue;
            }
            for piece in bytes[from..to].chunks(chunk) {
                let scan = scanner.push(piece);
                held = held.max(scanner.buf.len());
                match scan {
                    Scan::More => {}
                    Scan::Refused(status) => return (Err(HeadError::Refused(status)), held),
                    Scan::Head(len) => return (scanner.parse(len), held),
                }
            }
            from = to;
        }
        let end = if scanner.buf.is_empty() {
            HeadError::Closed
        } else {
            HeadError::Refused(400)
        };
        (Err(end), held)
    }

    /// Bytes that look like a head now and then: request lines, header lines, line ends and
    /// noise, some of them about as long as a limit.
    fn head_bytes() -> impl Strategy<Value = Vec<u8>> {
        let near = |limit: usize| (limit - 20)..(limit + 20);
        let part = prop_oneof![
            Just(b"GET / HTTP/1.1\r\n".to_vec()),
            Just(b"HEAD /take.json HTTP/1.0\n".to_vec()),
            Just(b"Host: 127.0.0.1:80\r\n".to_vec()),
            Just(b"\r\n".to_vec()),
            Just(b"\n".to_vec()),
            Just(b"\r".to_vec()),
            Just(b": ".to_vec()),
            proptest::collection::vec(any::<u8>(), 0..40),
            near(MAX_REQUEST_LINE).prop_map(|n| format!(
                "GET /{} HTTP/1.1\r\n",
                "a".repeat(n - 15)
            )
            .into_bytes()),
            near(MAX_HEADER_LINE)
                .prop_map(|n| format!("X-L: {}\r\n", "v".repeat(n - 5)).into_bytes()),
            (1usize..120).prop_map(|n| b"X-A: b\r\n".repeat(n)),
            (
                prop_oneof![0usize..100, near(MAX_REQUEST_LINE), near(MAX_HEADER_BYTES)],
                any::<u8>()
            )
                .prop_map(|(n, b)| vec![b; n]),
        ];
        proptest::collection::vec(part, 0..12).prop_map(|p| p.concat())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(1000))]

        /// Any bytes, read in pieces of any size up to [`READ_CHUNK`]: no panic; the answer
        /// they would get in one read; never more held than the limits and one read; a
        /// refusal is 400, 408, 414 or 431, and its answer a well-formed HTTP/1.1 response with
        /// that status; a head that is accepted is within the limits.
        #[test]
        fn any_bytes_in_any_reads_get_one_answer(
            bytes in head_bytes(),
            cuts in proptest::collection::vec(any::<prop::sample::Index>(), 0..8),
        ) {
            let mut cuts: Vec<usize> = cuts.iter().map(|i| i.index(bytes.len() + 1)).collect();
            cuts.sort_unstable();
            // The same head (what follows it depends on the reads), or the same refusal.
            let without_rest = |r: Result<Head, HeadError>| r.map(|h| Head { rest: Vec::new(), ..h });
            let (whole, _) = outcome(&bytes, &[], usize::MAX);
            let (split, held) = outcome(&bytes, &cuts, READ_CHUNK);
            prop_assert_eq!(without_rest(whole), without_rest(split.clone()));
            prop_assert!(held <= MAX_REQUEST_LINE + 2 + MAX_HEADER_BYTES + 2 + READ_CHUNK, "{held}");
            match split {
                Ok(head) => {
                    prop_assert!(head.headers.len() <= MAX_HEADERS);
                    prop_assert!(head.target.len() <= MAX_REQUEST_LINE);
                }
                Err(HeadError::Closed) => prop_assert!(bytes.is_empty()),
                Err(HeadError::Refused(status)) => {
                    prop_assert!([400, 408, 414, 431].contains(&status));
                    let answer = answer_bytes(&Reply::refusal(status), true);
                    let mut headers = [httparse::EMPTY_HEADER; 16];
                    let mut response = httparse::Response::new(&mut headers);
                    let parsed = response.parse(&answer);
                    prop_assert!(matches!(parsed, Ok(httparse::Status::Complete(_))), "{parsed:?}");
                    prop_assert_eq!(response.code, Some(status));
                    prop_assert_eq!(response.version, Some(1));
                    let length: usize = response
                        .headers
                        .iter()
                        .find(|h| h.name == "Content-Length")
                        .map(|h| std::str::from_utf8(h.value).unwrap().parse().unwrap())
                        .unwrap();
                    let Ok(httparse::Status::Complete(at)) = parsed else { unreachable!() };
                    prop_assert_eq!(answer.len() - at, length);
                }
            }
        }
    }

    #[test]
    fn a_head_is_parsed_with_what_follows_it() {
        let bytes = b"GET /take.json?x=1 HTTP/1.1\r\nHost: a\r\nOrigin: http://a\r\n\r\nxyz";
        let (head, _) = outcome(bytes, &[3, 20, 21], READ_CHUNK);
        let head = head.unwrap();
        assert_eq!(head.method, "GET");
        assert_eq!(head.target, "/take.json?x=1");
        assert_eq!(head.header("origin"), Some("http://a"));
        assert_eq!(head.rest, b"xyz");
        assert!(same_origin(head.header("Origin"), head.header("Host")));
        assert!(!same_origin(Some("http://a"), Some("")));
        assert!(!same_origin(None, Some("a")));
        assert!(same_origin(Some("http://A:80"), Some("a:80")));
        assert!(!same_origin(Some("https://a"), Some("a")));
    }
}
