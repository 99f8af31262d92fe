//! The viewer's HTTP and WebSocket server: `tiny_http` (a blocking server, one thread per
//! request) and `tungstenite` for the live WebSocket (ARCHITECTURE.md says why not an async
//! stack).
//!
//! Paths: the page's assets ([`super::assets`]), `/take.json`, `/chunk/<k>.glb` (`k` in
//! decimal digits, below the take's chunk count) and, in a live session, `/live`. Anything else
//! is 404: the server opens no file after it starts. Bound to loopback, it also refuses a
//! request whose `Host` is not the loopback address it listens on (a web page cannot reach it
//! through DNS rebinding).

use super::live::{Preview, Seen};
use super::motion::ViewTake;
use super::{ViewError, assets};
use std::collections::VecDeque;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tiny_http::{Header, Method, Request, Response};

/// Where to listen.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// `127.0.0.1:0` by default: loopback, a free port.
    pub listen: SocketAddr,
}

/// A bound server, not yet serving.
pub struct Server {
    http: tiny_http::Server,
    addr: SocketAddr,
    shared: Arc<Shared>,
}

struct Shared {
    take: ViewTake,
    take_json: Vec<u8>,
    preview: Option<Arc<Preview>>,
    /// The last chunks made, newest last.
    chunks: Mutex<VecDeque<(usize, Arc<Vec<u8>>)>>,
    /// `Host` values accepted (loopback only); `None`: any.
    hosts: Option<Vec<String>>,
    busy: AtomicUsize,
}

/// Chunks kept made (the page asks for the one it shows and the next).
const KEEP_CHUNKS: usize = 4;
/// Requests handled at once; more wait for a `503` reply.
const MAX_BUSY: usize = 64;

impl Server {
    /// Binds to `options.listen` (port 0: a free one). `preview`: a live session's poses, served
    /// on `/live`.
    pub fn bind(
        take: ViewTake,
        options: &ServeOptions,
        preview: Option<Arc<Preview>>,
    ) -> Result<Server, ViewError> {
        let http = tiny_http::Server::http(options.listen).map_err(|e| ViewError::Bind {
            addr: options.listen.to_string(),
            reason: e.to_string(),
        })?;
        let addr = http.server_addr().to_ip().ok_or_else(|| ViewError::Bind {
            addr: options.listen.to_string(),
            reason: "not an IP address".into(),
        })?;
        let hosts = addr.ip().is_loopback().then(|| {
            let port = addr.port();
            vec![
                format!("127.0.0.1:{port}"),
                format!("localhost:{port}"),
                format!("[::1]:{port}"),
            ]
        });
        let take_json = serde_json::to_vec(&take.json()).map_err(|e| ViewError::Bind {
            addr: addr.to_string(),
            reason: e.to_string(),
        })?;
        Ok(Server {
            http,
            addr,
            shared: Arc::new(Shared {
                take,
                take_json,
                preview,
                chunks: Mutex::new(VecDeque::new()),
                hosts,
                busy: AtomicUsize::new(0),
            }),
        })
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
        while !stop.load(Ordering::Relaxed) {
            let request = match self.http.recv_timeout(Duration::from_millis(100)) {
                Ok(Some(r)) => r,
                Ok(None) => continue,
                Err(_) => continue,
            };
            let shared = Arc::clone(&self.shared);
            if shared.busy.fetch_add(1, Ordering::AcqRel) >= MAX_BUSY {
                shared.busy.fetch_sub(1, Ordering::AcqRel);
                let _ = request.respond(text(503, "busy"));
                continue;
            }
            let stop = Arc::clone(stop);
            std::thread::spawn(move || {
                handle(&shared, request, &stop);
                shared.busy.fetch_sub(1, Ordering::AcqRel);
            });
        }
    }
}

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("ASCII header")
}

fn text(status: u16, body: &str) -> Response<std::io::Cursor<Vec<u8>>> {
    Response::from_data(body.as_bytes().to_vec())
        .with_status_code(status)
        .with_header(header("Content-Type", "text/plain; charset=utf-8"))
}

fn bytes(content_type: &str, body: Vec<u8>) -> Response<std::io::Cursor<Vec<u8>>> {
    // Its length, not chunked transfer: the page can tell how much is coming.
    Response::from_data(body)
        .with_chunked_threshold(usize::MAX)
        .with_header(header("Content-Type", content_type))
        .with_header(header("Cache-Control", "no-store"))
        .with_header(header("X-Content-Type-Options", "nosniff"))
}

fn request_header<'r>(request: &'r Request, name: &str) -> Option<&'r str> {
    request
        .headers()
        .iter()
        .find(|h| h.field.as_str().as_str().eq_ignore_ascii_case(name))
        .map(|h| h.value.as_str())
}

/// `/chunk/<k>.glb` → k (decimal digits only).
fn chunk_number(path: &str) -> Option<usize> {
    let k = path.strip_prefix("/chunk/")?.strip_suffix(".glb")?;
    if k.is_empty() || k.len() > 9 || !k.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    k.parse().ok()
}

fn handle(shared: &Shared, request: Request, stop: &Arc<AtomicBool>) {
    if let Some(hosts) = &shared.hosts
        && !request_header(&request, "Host").is_some_and(|h| hosts.iter().any(|a| a == h))
    {
        let _ = request.respond(text(403, "forbidden: unexpected Host"));
        return;
    }
    if !matches!(request.method(), Method::Get | Method::Head) {
        let _ = request.respond(text(405, "only GET"));
        return;
    }
    // The path without its query; nothing is decoded, so `%2f` is never a separator.
    let path = request
        .url()
        .split(['?', '#'])
        .next()
        .unwrap_or("")
        .to_string();
    if let Some(asset) = assets::find(&path) {
        let _ = request.respond(
            Response::from_data(asset.bytes.to_vec())
                .with_chunked_threshold(usize::MAX)
                .with_header(header("Content-Type", asset.content_type))
                .with_header(header("Cache-Control", "no-cache"))
                .with_header(header("X-Content-Type-Options", "nosniff")),
        );
        return;
    }
    if path == "/take.json" {
        let _ = request.respond(bytes(
            "application/json; charset=utf-8",
            shared.take_json.clone(),
        ));
        return;
    }
    if let Some(k) = chunk_number(&path) {
        match chunk(shared, k) {
            Some(Ok(glb)) => {
                let _ = request.respond(bytes("model/gltf-binary", glb.to_vec()));
            }
            Some(Err(e)) => {
                eprintln!("imubake view: {e}");
                let _ = request.respond(text(500, &e.to_string()));
            }
            None => {
                let _ = request.respond(text(404, "no such chunk"));
            }
        }
        return;
    }
    if path == "/live"
        && let Some(preview) = &shared.preview
    {
        live(request, preview, stop);
        return;
    }
    let _ = request.respond(text(404, "not found"));
}

fn chunk(shared: &Shared, k: usize) -> Option<Result<Arc<Vec<u8>>, ViewError>> {
    {
        let cache = shared.chunks.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, glb)) = cache.iter().find(|(c, _)| *c == k) {
            return Some(Ok(Arc::clone(glb)));
        }
    }
    let glb = match shared.take.chunk_glb(k)? {
        Ok(glb) => Arc::new(glb),
        Err(e) => return Some(Err(e)),
    };
    let mut cache = shared.chunks.lock().unwrap_or_else(|e| e.into_inner());
    cache.push_back((k, Arc::clone(&glb)));
    while cache.len() > KEEP_CHUNKS {
        cache.pop_front();
    }
    Some(Ok(glb))
}

/// The WebSocket of a live session: each new status and pose, until the page goes or the
/// session stops.
fn live(request: Request, preview: &Preview, stop: &Arc<AtomicBool>) {
    let is_upgrade =
        request_header(&request, "Upgrade").is_some_and(|u| u.eq_ignore_ascii_case("websocket"));
    let Some(key) = request_header(&request, "Sec-WebSocket-Key").filter(|_| is_upgrade) else {
        let _ = request.respond(text(426, "a WebSocket endpoint"));
        return;
    };
    let accept = tungstenite::handshake::derive_accept_key(key.as_bytes());
    let response = Response::empty(101)
        .with_header(header("Upgrade", "websocket"))
        .with_header(header("Connection", "Upgrade"))
        .with_header(header("Sec-WebSocket-Accept", &accept));
    let stream = request.upgrade("websocket", response);
    let mut socket =
        tungstenite::WebSocket::from_raw_socket(stream, tungstenite::protocol::Role::Server, None);
    let mut seen = Seen::default();
    while !stop.load(Ordering::Relaxed) {
        for message in preview.wait(&mut seen, Duration::from_millis(200)) {
            if socket
                .send(tungstenite::Message::text(message.to_string()))
                .is_err()
            {
                return;
            }
        }
    }
    let _ = socket.close(None);
    let _ = socket.flush();
}

#[cfg(test)]
mod tests {
    use super::chunk_number;

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
}
