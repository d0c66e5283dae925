//! The viewer's server: plain HTTP/1.1 for the three files of the page, a WebSocket per
//! tab, and one render worker.
//!
//! Latest wins. Each tab has one pending-frame slot that new camera and settings
//! messages overwrite, and at most one frame in flight: the worker renders a tab's next
//! frame only after its previous one was written to the socket, so a slow tab or a fast
//! mouse never builds a queue. The worker serves tabs round-robin. While the camera moves
//! the page marks its requests interactive: those frames are rendered smaller and sent as
//! JPEG; when the page says the camera rests (or [`ServerConfig::rest_delay`] after the
//! last interactive request) the same view follows at full size as lossless PNG.
//!
//! Nothing a client sends can stop the server or other clients: every message is parsed
//! into [`ClientMessage`] and checked (cameras by the `cameras.json` reader, settings by
//! [`ViewSettings::validate`]); what is refused is answered with an `error` message to
//! that client. A render error or a renderer panic is sent to the tab that asked.

use super::page;
use super::protocol::{
    binary_message, camera_from_entry, camera_to_entry, ClientMessage, FrameHeader, KeyframeIn,
    PathFormat, Quality, ServerMessage, ShotHeader, StageMs,
};
use super::source::{FrameSource, ShotFormat, ViewFrame, ViewSettings};
use crate::camera::{keyframes, nerfstudio, Camera, PathTiming};
use std::collections::BTreeMap;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{mpsc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tungstenite::protocol::{Role, WebSocketConfig};
use tungstenite::{Message, WebSocket};

/// Tunables of the server.
#[derive(Clone, Debug)]
pub struct ServerConfig {
    /// Largest rendered frame (`--max-resolution`); larger canvases keep their aspect
    /// ratio and are scaled down.
    pub max_resolution: (u32, u32),
    /// Pixels of an interactive (preview) frame at most.
    pub preview_pixels: u32,
    /// After this long without a new interactive request the view is rendered at full
    /// quality, even if the page never says it rests.
    pub rest_delay: Duration,
    /// WebSocket clients at once; more are refused with HTTP 503.
    pub max_clients: usize,
    /// Messages a client may send per second; more are dropped with one error.
    pub max_messages_per_s: u32,
    /// JPEG quality of preview frames (1-100).
    pub jpeg_quality: u8,
}

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            max_resolution: (1920, 1080),
            preview_pixels: 250_000,
            rest_delay: Duration::from_millis(200),
            max_clients: 16,
            max_messages_per_s: 400,
            jpeg_quality: 80,
        }
    }
}

/// What the server serves: the `hello` every tab gets and the scene's cameras.
pub struct ServedScene {
    /// Sent on connecting.
    pub hello: super::protocol::Hello,
    /// The scene's cameras, in `hello`'s order (`select_camera` indexes them).
    pub cameras: Vec<Camera>,
}

/// A bound listener; [`Server::run`] serves until the stop flag is set.
pub struct Server {
    listener: TcpListener,
    config: ServerConfig,
}

/// How long a connection may take to send its HTTP request head.
const HEAD_TIMEOUT: Duration = Duration::from_secs(5);
/// Longest HTTP request head read.
const MAX_HEAD: usize = 16 * 1024;
/// How often blocked loops look at the stop flag.
const POLL: Duration = Duration::from_millis(10);
/// Longest WebSocket message a client may send (a long keyframe list fits).
const MAX_MESSAGE: usize = 4 << 20;
/// TCP connections at once (page files, WebSockets, and those still sending a request).
const MAX_CONNECTIONS: usize = 64;
/// A write to a client that does not read for this long ends its connection.
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

impl Server {
    /// Binds `addr` (port 0 picks a free port); the error names the address.
    pub fn bind(addr: SocketAddr, config: ServerConfig) -> anyhow::Result<Server> {
        let listener = TcpListener::bind(addr).map_err(|e| {
            if e.kind() == ErrorKind::AddrInUse {
                anyhow::anyhow!(
                    "port {} on {} is in use by another program; pick another with --port (--port 0 picks a free one)",
                    addr.port(),
                    addr.ip()
                )
            } else {
                anyhow::anyhow!("cannot listen on {addr}: {e}")
            }
        })?;
        listener.set_nonblocking(true)?;
        Ok(Server { listener, config })
    }

    /// The address bound (with the port chosen for port 0).
    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.listener.local_addr()
    }

    /// Serves until `stop` is set, then closes every connection and returns.
    pub fn run(
        self,
        source: Box<dyn FrameSource>,
        scene: ServedScene,
        stop: &AtomicBool,
    ) -> anyhow::Result<()> {
        let sh_degree = scene.hello.sh_degree;
        let hello_text = serde_json::to_string(&ServerMessage::Hello(Box::new(scene.hello)))?;
        let shared = Shared {
            config: self.config,
            hello_text,
            cameras: scene.cameras,
            sh_degree,
            stop,
            loopback: self.listener.local_addr()?.ip().is_loopback(),
            connections: AtomicUsize::new(0),
            queue: Mutex::new(Queue::default()),
            wake: Condvar::new(),
        };
        std::thread::scope(|s| {
            let shared = &shared;
            let worker = s.spawn(move || render_worker(source, shared));
            while !stop.load(Ordering::Relaxed) {
                match self.listener.accept() {
                    Ok((stream, _)) => {
                        // Connections beyond the bound are closed at once (a client that
                        // opens sockets in a loop cannot exhaust the threads).
                        if shared.connections.fetch_add(1, Ordering::Relaxed) >= MAX_CONNECTIONS {
                            shared.connections.fetch_sub(1, Ordering::Relaxed);
                            drop(stream);
                            continue;
                        }
                        let _ = s.spawn(move || {
                            serve_connection(stream, shared);
                            shared.connections.fetch_sub(1, Ordering::Relaxed);
                        });
                    }
                    Err(e) if e.kind() == ErrorKind::WouldBlock => std::thread::sleep(POLL),
                    Err(e) if e.kind() == ErrorKind::Interrupted => {}
                    // Out of file descriptors and the like: wait rather than spin.
                    Err(_) => std::thread::sleep(Duration::from_millis(100)),
                }
            }
            shared.wake.notify_all();
            let _ = worker.join();
        });
        Ok(())
    }
}

/// State shared by the accept loop, the connections and the worker.
struct Shared<'a> {
    config: ServerConfig,
    hello_text: String,
    cameras: Vec<Camera>,
    sh_degree: u32,
    stop: &'a AtomicBool,
    /// Bound to a loopback address: requests must name a loopback host.
    loopback: bool,
    /// Open TCP connections (each has a thread).
    connections: AtomicUsize,
    queue: Mutex<Queue>,
    wake: Condvar,
}

impl Shared<'_> {
    fn queue(&self) -> MutexGuard<'_, Queue> {
        // A panic while holding the lock leaves plain data; keep serving.
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// Work waiting for the worker, per client.
#[derive(Default)]
struct Queue {
    clients: BTreeMap<u64, Pending>,
    next_id: u64,
    last_served: u64,
}

/// One client's slots.
struct Pending {
    /// The newest frame request (overwritten by newer ones).
    frame: Option<FrameJob>,
    /// The newest screenshot request.
    shot: Option<ShotJob>,
    /// A frame was rendered and is not yet written to the socket.
    frame_in_flight: bool,
    /// To the client's connection thread.
    tx: mpsc::Sender<Outgoing>,
}

#[derive(Clone)]
struct FrameJob {
    seq: u64,
    camera: Camera,
    settings: ViewSettings,
    quality: Quality,
}

struct ShotJob {
    seq: u64,
    camera: Camera,
    settings: ViewSettings,
    format: ShotFormat,
}

/// From the worker to a connection thread.
enum Outgoing {
    // Boxed: a frame's header and camera are much larger than a screenshot's.
    Frame {
        job: Box<FrameJob>,
        result: Result<ViewFrame, String>,
    },
    Shot {
        seq: u64,
        format: ShotFormat,
        result: Result<Vec<u8>, String>,
    },
}

enum Job {
    Frame(FrameJob),
    Shot(ShotJob),
}

/// Renders requests round-robin over the clients until the server stops.
fn render_worker(mut source: Box<dyn FrameSource>, shared: &Shared) {
    loop {
        let (job, tx) = {
            let mut q = shared.queue();
            loop {
                if shared.stopping() {
                    return;
                }
                if let Some(found) = next_job(&mut q) {
                    break found;
                }
                q = shared
                    .wake
                    .wait_timeout(q, Duration::from_millis(100))
                    .unwrap_or_else(|p| p.into_inner())
                    .0;
            }
        };
        let message = match job {
            Job::Frame(job) => {
                let result = guarded(|| source.render(&job.camera, &job.settings));
                Outgoing::Frame {
                    job: Box::new(job),
                    result,
                }
            }
            Job::Shot(job) => {
                let result = guarded(|| source.screenshot(&job.camera, &job.settings, job.format));
                Outgoing::Shot {
                    seq: job.seq,
                    format: job.format,
                    result,
                }
            }
        };
        // A client that left meanwhile drops its receiver; nothing to do.
        let _ = tx.send(message);
    }
}

/// The next client after the last served one with work, and its job.
fn next_job(q: &mut Queue) -> Option<(Job, mpsc::Sender<Outgoing>)> {
    let after = q.last_served;
    let ids: Vec<u64> = q
        .clients
        .range(after + 1..)
        .chain(q.clients.range(..=after))
        .filter(|(_, p)| p.shot.is_some() || (p.frame.is_some() && !p.frame_in_flight))
        .map(|(id, _)| *id)
        .take(1)
        .collect();
    let id = *ids.first()?;
    let p = q.clients.get_mut(&id)?;
    let job = if let Some(shot) = p.shot.take() {
        Job::Shot(shot)
    } else {
        p.frame_in_flight = true;
        Job::Frame(p.frame.take()?)
    };
    let tx = p.tx.clone();
    q.last_served = id;
    Some((job, tx))
}

/// Runs a render call; a panic in the renderer becomes an error for the client.
fn guarded<T>(f: impl FnOnce() -> anyhow::Result<T>) -> Result<T, String> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(format!("render failed: {}", error_sentence(&e))),
        Err(_) => Err(
            "the renderer failed unexpectedly (a bug; the message is in the server's log)".into(),
        ),
    }
}

fn error_sentence(e: &anyhow::Error) -> String {
    let mut s = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !s.contains(&c) {
            s.push_str(": ");
            s.push_str(&c);
        }
    }
    s
}

/// A parsed HTTP request head.
struct Request {
    method: String,
    path: String,
    headers: Vec<(String, String)>,
}

impl Request {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
}

/// Reads the request head; returns it and any bytes read past it.
fn read_head(stream: &mut TcpStream) -> Option<(Request, Vec<u8>)> {
    let deadline = Instant::now() + HEAD_TIMEOUT;
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    let end = loop {
        if let Some(i) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            break i + 4;
        }
        if buf.len() > MAX_HEAD || Instant::now() > deadline {
            return None;
        }
        match stream.read(&mut chunk) {
            Ok(0) => return None,
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(_) => return None,
        }
    };
    let text = std::str::from_utf8(&buf[..end]).ok()?;
    let mut lines = text.split("\r\n");
    let mut first = lines.next()?.split(' ');
    let method = first.next()?.to_string();
    let path = first.next()?.to_string();
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(n, v)| (n.trim().to_string(), v.trim().to_string()))
        .collect();
    Some((
        Request {
            method,
            path,
            headers,
        },
        buf[end..].to_vec(),
    ))
}

fn respond(stream: &mut TcpStream, status: &str, content_type: &str, body: &[u8]) {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        body.len()
    );
    let _ = stream
        .write_all(head.as_bytes())
        .and_then(|()| stream.write_all(body))
        .and_then(|()| stream.flush());
}

/// One TCP connection: a file of the page, or the upgrade to a WebSocket.
fn serve_connection(mut stream: TcpStream, shared: &Shared) {
    // The listener is non-blocking; accepted sockets must not be.
    if stream.set_nonblocking(false).is_err()
        || stream.set_read_timeout(Some(POLL)).is_err()
        || stream.set_write_timeout(Some(WRITE_TIMEOUT)).is_err()
    {
        return;
    }
    let _ = stream.set_nodelay(true);
    let Some((req, rest)) = read_head(&mut stream) else {
        return;
    };
    if shared.loopback && !loopback_host(&req) {
        respond(
            &mut stream,
            "403 Forbidden",
            "text/plain",
            b"the viewer answers only to localhost names\n",
        );
        return;
    }
    if req.method != "GET" {
        respond(
            &mut stream,
            "405 Method Not Allowed",
            "text/plain",
            b"only GET\n",
        );
        return;
    }
    let path = req.path.split('?').next().unwrap_or("");
    if path == "/ws" {
        upgrade(stream, &req, rest, shared);
        return;
    }
    match page::file(path) {
        Some((content_type, body)) => respond(&mut stream, "200 OK", content_type, body),
        None => respond(&mut stream, "404 Not Found", "text/plain", b"not found\n"),
    }
}

/// The Host header names a loopback address (`localhost`, `127.x.y.z`, `[::1]`, any
/// port). A server on loopback refuses other names, so a web page whose domain was
/// re-pointed at 127.0.0.1 (DNS rebinding) cannot reach it.
fn loopback_host(req: &Request) -> bool {
    let Some(host) = req.header("Host") else {
        return false;
    };
    let name = match host.strip_prefix('[') {
        Some(v6) => v6.split(']').next().unwrap_or(""),
        None => host.rsplit_once(':').map_or(host, |(n, _)| n),
    };
    name.eq_ignore_ascii_case("localhost")
        || name
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// Origin `http://host:port` must name the Host the page was loaded from: another site
/// open in the same browser may not drive the viewer.
fn same_origin(req: &Request) -> bool {
    match (req.header("Origin"), req.header("Host")) {
        (None, _) => true,
        (Some(origin), Some(host)) => origin
            .strip_prefix("http://")
            .is_some_and(|o| o.eq_ignore_ascii_case(host)),
        (Some(_), None) => false,
    }
}

fn upgrade(mut stream: TcpStream, req: &Request, rest: Vec<u8>, shared: &Shared) {
    let is_upgrade = req
        .header("Upgrade")
        .is_some_and(|u| u.eq_ignore_ascii_case("websocket"));
    let Some(key) = req.header("Sec-WebSocket-Key").filter(|_| is_upgrade) else {
        respond(
            &mut stream,
            "400 Bad Request",
            "text/plain",
            b"expected a WebSocket upgrade\n",
        );
        return;
    };
    if !same_origin(req) {
        respond(
            &mut stream,
            "403 Forbidden",
            "text/plain",
            b"the WebSocket must come from the viewer's own page\n",
        );
        return;
    }
    let (tx, rx) = mpsc::channel();
    let id = {
        let mut q = shared.queue();
        if q.clients.len() >= shared.config.max_clients {
            drop(q);
            respond(
                &mut stream,
                "503 Service Unavailable",
                "text/plain",
                b"too many viewer tabs are open\n",
            );
            return;
        }
        q.next_id += 1;
        let id = q.next_id;
        q.clients.insert(
            id,
            Pending {
                frame: None,
                shot: None,
                frame_in_flight: false,
                tx,
            },
        );
        id
    };
    let accept = tungstenite::handshake::derive_accept_key(key.as_bytes());
    let head = format!(
        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: {accept}\r\n\r\n"
    );
    if stream.write_all(head.as_bytes()).is_ok() {
        let config = WebSocketConfig::default()
            .max_message_size(Some(MAX_MESSAGE))
            .max_frame_size(Some(MAX_MESSAGE));
        let ws = WebSocket::from_partially_read(stream, rest, Role::Server, Some(config));
        let mut session = Session::new(id, ws, rx, shared);
        session.run();
    }
    shared.queue().clients.remove(&id);
    shared.wake.notify_all();
}

/// One tab: its camera, settings and the WebSocket.
struct Session<'s, 'a> {
    id: u64,
    ws: WebSocket<TcpStream>,
    rx: mpsc::Receiver<Outgoing>,
    shared: &'s Shared<'a>,
    /// The last frame request, for `rest`, `settings` and the rest timer.
    last: Option<FrameJob>,
    settings: ViewSettings,
    /// When the last interactive request came (a full frame follows after the delay).
    moving_since: Option<Instant>,
    window_start: Instant,
    window_count: u32,
    window_warned: bool,
}

impl<'s, 'a> Session<'s, 'a> {
    fn new(
        id: u64,
        ws: WebSocket<TcpStream>,
        rx: mpsc::Receiver<Outgoing>,
        shared: &'s Shared<'a>,
    ) -> Self {
        Session {
            id,
            ws,
            rx,
            shared,
            last: None,
            settings: ViewSettings::default(),
            moving_since: None,
            window_start: Instant::now(),
            window_count: 0,
            window_warned: false,
        }
    }

    fn run(&mut self) {
        if self
            .ws
            .send(Message::text(self.shared.hello_text.clone()))
            .is_err()
        {
            return;
        }
        loop {
            if self.shared.stopping() {
                let _ = self.ws.close(None);
                let _ = self.ws.flush();
                return;
            }
            match self.ws.read() {
                Ok(Message::Text(text)) => {
                    if self.admit() {
                        self.handle(text.as_str());
                    }
                }
                Ok(Message::Binary(_)) => {
                    if self.admit() {
                        self.send_error("binary messages are not understood; send JSON text", None);
                    }
                }
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
                Err(tungstenite::Error::Capacity(e)) => {
                    // The connection cannot resynchronise after an oversized frame.
                    self.send_error(&format!("message refused: {e}; closing"), None);
                    let _ = self.ws.close(None);
                    let _ = self.ws.flush();
                    return;
                }
                Err(_) => return,
            }
            if !self.deliver() {
                return;
            }
            self.rest_timer();
        }
    }

    /// Counts a message against the rate limit; false drops it (one error per second).
    fn admit(&mut self) -> bool {
        if self.window_start.elapsed() >= Duration::from_secs(1) {
            self.window_start = Instant::now();
            self.window_count = 0;
            self.window_warned = false;
        }
        self.window_count += 1;
        if self.window_count <= self.shared.config.max_messages_per_s {
            return true;
        }
        if !self.window_warned {
            self.window_warned = true;
            let limit = self.shared.config.max_messages_per_s;
            self.send_error(
                &format!("too many messages: more than {limit} in one second; the rest of this second's messages are dropped"),
                None,
            );
        }
        false
    }

    /// Writes what the worker finished for this client; false when the socket is gone.
    fn deliver(&mut self) -> bool {
        while let Ok(out) = self.rx.try_recv() {
            let sent = match out {
                Outgoing::Frame { job, result } => {
                    let message = match result {
                        Ok(frame) => self.encode_frame(&job, &frame),
                        Err(e) => Err(e),
                    };
                    let sent = match message {
                        Ok(bytes) => self.ws.send(Message::binary(bytes)),
                        Err(e) => self.ws.send(Message::text(error_text(&e, Some(job.seq)))),
                    };
                    if let Some(p) = self.shared.queue().clients.get_mut(&self.id) {
                        p.frame_in_flight = false;
                    }
                    self.shared.wake.notify_all();
                    sent
                }
                Outgoing::Shot {
                    seq,
                    format,
                    result,
                } => match result {
                    Ok(bytes) => {
                        let header = ShotHeader {
                            kind: "screenshot",
                            seq,
                            format,
                            filename: format!(
                                "vksplat_{}.{}",
                                unix_seconds(),
                                match format {
                                    ShotFormat::Png => "png",
                                    ShotFormat::Exr => "exr",
                                }
                            ),
                        };
                        self.ws
                            .send(Message::binary(binary_message(&header, &bytes)))
                    }
                    Err(e) => self.ws.send(Message::text(error_text(&e, Some(seq)))),
                },
            };
            if sent.is_err() {
                return false;
            }
        }
        true
    }

    /// JPEG for previews, PNG for full frames, behind the frame header.
    fn encode_frame(&self, job: &FrameJob, frame: &ViewFrame) -> Result<Vec<u8>, String> {
        use image::ImageEncoder;
        let start = Instant::now();
        let (w, h) = (frame.width, frame.height);
        if frame.rgba8.len() != w as usize * h as usize * 4 {
            return Err(format!(
                "the renderer returned {} bytes for a {w}x{h} frame",
                frame.rgba8.len()
            ));
        }
        let rgb: Vec<u8> = frame
            .rgba8
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        let mut bytes = Vec::new();
        let (encoding, result) = match job.quality {
            Quality::Preview => (
                "jpeg",
                image::codecs::jpeg::JpegEncoder::new_with_quality(
                    &mut bytes,
                    self.shared.config.jpeg_quality,
                )
                .write_image(&rgb, w, h, image::ExtendedColorType::Rgb8),
            ),
            Quality::Full => (
                "png",
                image::codecs::png::PngEncoder::new_with_quality(
                    &mut bytes,
                    image::codecs::png::CompressionType::Fast,
                    image::codecs::png::FilterType::Adaptive,
                )
                .write_image(&rgb, w, h, image::ExtendedColorType::Rgb8),
            ),
        };
        result.map_err(|e| format!("encoding the frame failed: {e}"))?;
        let header = FrameHeader {
            kind: "frame",
            seq: job.seq,
            width: w,
            height: h,
            quality: job.quality,
            encoding,
            timings: StageMs::from(&frame.timings),
            visible: frame.stats.visible,
            pairs: frame.stats.pairs,
            wall_ms: frame.wall_ms,
            encode_ms: start.elapsed().as_secs_f64() * 1e3,
        };
        Ok(binary_message(&header, &bytes))
    }

    /// A full frame of the last view once the camera stopped moving.
    fn rest_timer(&mut self) {
        let due = self
            .moving_since
            .is_some_and(|t| t.elapsed() >= self.shared.config.rest_delay);
        if due {
            self.moving_since = None;
            if let Some(job) = self.last.clone() {
                self.submit_frame(FrameJob {
                    quality: Quality::Full,
                    ..job
                });
            }
        }
    }

    fn send_error(&mut self, message: &str, seq: Option<u64>) {
        let _ = self.ws.send(Message::text(error_text(message, seq)));
    }

    fn handle(&mut self, text: &str) {
        let message: ClientMessage = match serde_json::from_str(text) {
            Ok(m) => m,
            Err(e) => {
                // Say which request failed when its seq can be read.
                let seq = serde_json::from_str::<serde_json::Value>(text)
                    .ok()
                    .and_then(|v| v["seq"].as_u64());
                self.send_error(&format!("message not understood: {e}"), seq);
                return;
            }
        };
        let (seq, result) = match message {
            ClientMessage::View {
                seq,
                camera,
                settings,
                interactive,
            } => (seq, self.view(seq, &camera, settings, interactive)),
            ClientMessage::Settings { seq, settings } => (seq, self.new_settings(seq, settings)),
            ClientMessage::Rest { seq } => (seq, self.rest(seq)),
            ClientMessage::SelectCamera {
                seq,
                index,
                width,
                height,
            } => (seq, self.select_camera(seq, index, width, height)),
            ClientMessage::Screenshot {
                seq,
                format,
                camera,
                settings,
            } => (seq, self.screenshot(seq, format, camera, settings)),
            ClientMessage::ExportKeyframes {
                seq,
                format,
                fps,
                keyframes,
            } => (seq, self.export(seq, format, fps, &keyframes)),
            ClientMessage::SampleKeyframes {
                seq,
                fps,
                keyframes,
            } => (seq, self.sample(seq, fps, &keyframes)),
        };
        if let Err(e) = result {
            self.send_error(&e, Some(seq));
        }
    }

    fn checked_settings(&self, settings: Option<ViewSettings>) -> Result<ViewSettings, String> {
        let settings = settings.unwrap_or_else(|| self.settings.clone());
        settings
            .validate(self.shared.sh_degree)
            .map_err(|e| format!("settings refused: {e}"))?;
        Ok(settings)
    }

    fn view(
        &mut self,
        seq: u64,
        camera: &serde_json::Value,
        settings: Option<ViewSettings>,
        interactive: bool,
    ) -> Result<(), String> {
        let camera = camera_from_entry(camera).map_err(|e| format!("camera refused: {e}"))?;
        let settings = self.checked_settings(settings)?;
        self.settings = settings.clone();
        self.moving_since = interactive.then(Instant::now);
        self.submit_frame(FrameJob {
            seq,
            camera,
            settings,
            quality: if interactive {
                Quality::Preview
            } else {
                Quality::Full
            },
        });
        Ok(())
    }

    fn new_settings(&mut self, seq: u64, settings: ViewSettings) -> Result<(), String> {
        let settings = self.checked_settings(Some(settings))?;
        self.settings = settings.clone();
        if let Some(job) = self.last.clone() {
            self.moving_since = None;
            self.submit_frame(FrameJob {
                seq,
                settings,
                quality: Quality::Full,
                ..job
            });
        }
        Ok(())
    }

    fn rest(&mut self, seq: u64) -> Result<(), String> {
        self.moving_since = None;
        let job = self
            .last
            .clone()
            .ok_or("rest before any view: send a view message first")?;
        self.submit_frame(FrameJob {
            seq,
            quality: Quality::Full,
            ..job
        });
        Ok(())
    }

    fn select_camera(
        &mut self,
        seq: u64,
        index: usize,
        width: Option<u32>,
        height: Option<u32>,
    ) -> Result<(), String> {
        let cams = &self.shared.cameras;
        let cam = cams.get(index).ok_or_else(|| {
            format!(
                "camera {index} does not exist; the scene has {} (0..{})",
                camera_count(cams.len()),
                cams.len()
            )
        })?;
        let cam = cam
            .resized(width, height, None)
            .and_then(|c| c.validate().map(|()| c))
            .map_err(|e| format!("camera {index} at that size: {e}"))?;
        let entry = camera_to_entry(&cam, index)?;
        let reply = ServerMessage::Camera {
            seq,
            index,
            camera: entry,
        };
        let text = serde_json::to_string(&reply).map_err(|e| e.to_string())?;
        let _ = self.ws.send(Message::text(text));
        self.moving_since = None;
        let settings = self.settings.clone();
        self.submit_frame(FrameJob {
            seq,
            camera: cam,
            settings,
            quality: Quality::Full,
        });
        Ok(())
    }

    fn screenshot(
        &mut self,
        seq: u64,
        format: ShotFormat,
        camera: Option<serde_json::Value>,
        settings: Option<ViewSettings>,
    ) -> Result<(), String> {
        let camera = match camera {
            Some(entry) => camera_from_entry(&entry).map_err(|e| format!("camera refused: {e}"))?,
            None => self
                .last
                .as_ref()
                .map(|j| j.camera.clone())
                .ok_or("screenshot before any view: send a view message or a camera")?,
        };
        let settings = self.checked_settings(settings)?;
        let mut q = self.shared.queue();
        if let Some(p) = q.clients.get_mut(&self.id) {
            p.shot = Some(ShotJob {
                seq,
                camera,
                settings,
                format,
            });
        }
        drop(q);
        self.shared.wake.notify_all();
        Ok(())
    }

    fn export(
        &mut self,
        seq: u64,
        format: PathFormat,
        fps: f32,
        keyframes: &[KeyframeIn],
    ) -> Result<(), String> {
        let (text, cameras) = export_path(format, fps, keyframes)?;
        let entries = cameras
            .iter()
            .enumerate()
            .map(|(i, c)| camera_to_entry(c, i))
            .collect::<Result<Vec<_>, _>>()?;
        let reply = ServerMessage::Export {
            seq,
            format,
            filename: match format {
                PathFormat::Vksplat => "keyframes.json".into(),
                PathFormat::Nerfstudio => "camera_path.json".into(),
            },
            text,
            cameras: entries,
        };
        let text = serde_json::to_string(&reply).map_err(|e| e.to_string())?;
        let _ = self.ws.send(Message::text(text));
        Ok(())
    }

    fn sample(&mut self, seq: u64, fps: f32, keyframes: &[KeyframeIn]) -> Result<(), String> {
        let frames = sample_path(fps, keyframes)?;
        let cameras = frames
            .iter()
            .enumerate()
            .map(|(i, c)| camera_to_entry(c, i))
            .collect::<Result<Vec<_>, _>>()?;
        let reply = ServerMessage::Path {
            seq,
            fps: fps as f64,
            cameras,
        };
        let text = serde_json::to_string(&reply).map_err(|e| e.to_string())?;
        let _ = self.ws.send(Message::text(text));
        Ok(())
    }

    /// Puts a frame request in this client's slot (replacing an older one): its size
    /// capped by `--max-resolution`, previews scaled down further.
    fn submit_frame(&mut self, job: FrameJob) {
        self.last = Some(FrameJob {
            quality: Quality::Full,
            ..job.clone()
        });
        let config = &self.shared.config;
        let capped = cap_resolution(&job.camera, config.max_resolution);
        let camera = match job.quality {
            Quality::Full => capped,
            Quality::Preview => cap_pixels(&capped, config.preview_pixels),
        };
        let mut q = self.shared.queue();
        if let Some(p) = q.clients.get_mut(&self.id) {
            p.frame = Some(FrameJob { camera, ..job });
        }
        drop(q);
        self.shared.wake.notify_all();
    }
}

/// `1 camera`, `3 cameras`.
fn camera_count(n: usize) -> String {
    if n == 1 {
        "1 camera".into()
    } else {
        format!("{n} cameras")
    }
}

fn unix_seconds() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

fn error_text(message: &str, seq: Option<u64>) -> String {
    serde_json::to_string(&ServerMessage::Error {
        message: message.to_string(),
        seq,
    })
    .unwrap_or_default()
}

/// `cam` scaled down (aspect kept, intrinsics scaled) to fit `max` (width, height).
pub fn cap_resolution(cam: &Camera, max: (u32, u32)) -> Camera {
    if cam.width <= max.0 && cam.height <= max.1 {
        return cam.clone();
    }
    let s = (max.0 as f64 / cam.width as f64).min(max.1 as f64 / cam.height as f64);
    resize_by(cam, s)
}

/// `cam` scaled down to at most `pixels` pixels.
pub fn cap_pixels(cam: &Camera, pixels: u32) -> Camera {
    let have = cam.width as f64 * cam.height as f64;
    if have <= pixels as f64 {
        return cam.clone();
    }
    resize_by(cam, (pixels as f64 / have).sqrt())
}

fn resize_by(cam: &Camera, s: f64) -> Camera {
    let side = |v: u32| ((v as f64 * s).floor() as u32).max(1);
    cam.with_resolution(side(cam.width), side(cam.height))
        .unwrap_or_else(|_| cam.clone())
}

/// The file of an exported path and its keyframes' cameras as `render --cameras` reads
/// them back from it.
pub fn export_path(
    format: PathFormat,
    fps: f32,
    keyframes: &[KeyframeIn],
) -> Result<(String, Vec<Camera>), String> {
    let (text, path) = keyframe_path(fps, keyframes)?;
    let at_keys: Vec<Camera> = path
        .keyframes()
        .iter()
        .enumerate()
        .map(|(i, k)| path.sample(k.time, format!("keyframe_{i}")))
        .collect();
    match format {
        PathFormat::Vksplat => Ok((text, at_keys)),
        PathFormat::Nerfstudio => {
            let frames = path
                .cameras(&PathTiming::default())
                .map_err(|e| format!("cannot sample the path: {e}"))?;
            let text = nerfstudio::to_camera_path_json(&frames, path.fps)
                .map_err(|e| format!("cannot export the camera path: {e}"))?;
            Ok((text, at_keys))
        }
    }
}

/// Most frames a path preview sends to the page.
pub const MAX_PREVIEW_FRAMES: usize = 10_000;

/// The frames of the keyframe path, as `render --cameras keyframes.json` renders them.
pub fn sample_path(fps: f32, keyframes: &[KeyframeIn]) -> Result<Vec<Camera>, String> {
    let (_, path) = keyframe_path(fps, keyframes)?;
    let frames = path
        .cameras(&PathTiming::default())
        .map_err(|e| format!("cannot sample the path: {e}"))?;
    if frames.len() > MAX_PREVIEW_FRAMES {
        return Err(format!(
            "the path has {} frames; a preview shows at most {MAX_PREVIEW_FRAMES} (lower Frames/s)",
            frames.len()
        ));
    }
    Ok(frames)
}

/// The keyframe file of the page's keyframes and the path it reads back as.
fn keyframe_path(
    fps: f32,
    keyframes: &[KeyframeIn],
) -> Result<(String, keyframes::KeyframePath), String> {
    if keyframes.is_empty() {
        return Err("no keyframes to export: add the current camera with \"Add\" first".into());
    }
    let mut cams = Vec::with_capacity(keyframes.len());
    let mut times = Vec::with_capacity(keyframes.len());
    for (i, k) in keyframes.iter().enumerate() {
        let c = camera_from_entry(&k.camera).map_err(|e| format!("keyframe {i}: {e}"))?;
        cams.push(c);
        times.push(k.time);
    }
    let text = keyframes::keyframes_to_json(&cams, &times, fps)
        .map_err(|e| format!("cannot export the keyframes: {e}"))?;
    let name = Path::new("keyframes.json");
    let path = keyframes::KeyframePath::parse(&text, name)
        .map_err(|e| format!("the exported keyframes do not read back: {e}"))?;
    Ok((text, path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caps_keep_the_aspect_ratio() {
        let cam = crate::camera::default_camera(&[[0.0; 3]], 4000, 2000);
        let c = cap_resolution(&cam, (1920, 1080));
        assert_eq!((c.width, c.height), (1920, 960));
        assert!((c.fx / cam.fx - 0.48).abs() < 1e-6);
        let p = cap_pixels(&c, 250_000);
        assert!(p.width * p.height <= 250_000, "{}x{}", p.width, p.height);
        assert_eq!(p.width / p.height, 2);
        let small = crate::camera::default_camera(&[[0.0; 3]], 64, 48);
        assert_eq!(cap_resolution(&small, (1920, 1080)), small);
    }

    #[test]
    fn origin_must_match_host() {
        let req = |origin: Option<&str>| Request {
            method: "GET".into(),
            path: "/ws".into(),
            headers: [("Host", Some("127.0.0.1:8080")), ("Origin", origin)]
                .into_iter()
                .filter_map(|(n, v)| v.map(|v| (n.to_string(), v.to_string())))
                .collect(),
        };
        assert!(same_origin(&req(None)));
        assert!(same_origin(&req(Some("http://127.0.0.1:8080"))));
        assert!(!same_origin(&req(Some("http://evil.example"))));
        let host = |h: &str| Request {
            method: "GET".into(),
            path: "/".into(),
            headers: vec![("Host".into(), h.into())],
        };
        for ok in [
            "127.0.0.1:8080",
            "localhost:1",
            "LOCALHOST",
            "[::1]:9000",
            "127.3.2.1",
        ] {
            assert!(loopback_host(&host(ok)), "{ok}");
        }
        for bad in ["evil.example:8080", "10.0.0.1:8080", "[fe80::1]:80", ""] {
            assert!(!loopback_host(&host(bad)), "{bad}");
        }
    }
}
