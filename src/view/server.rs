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
//! into a [`ClientMessage`](super::protocol::ClientMessage) and checked (cameras by the
//! `cameras.json` reader, settings by [`ViewSettings::validate`]); what is refused is
//! answered with an `error` message to that client. A render error or a renderer panic
//! is sent to the tab that asked.

use super::http::{loopback_host, read_head, respond, same_origin, Request};
use super::page;
use super::protocol::{Quality, ServerMessage};
pub use super::queue::ServerConfig;
use super::queue::{FrameJob, Outgoing, Pending, Queue, Shared, ShotJob};
use super::session::Session;
use super::source::ViewSource;
use crate::camera::Camera;
use std::io::{ErrorKind, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{mpsc, Condvar, Mutex};
use std::time::Duration;
use tungstenite::protocol::{Role, WebSocketConfig};
use tungstenite::WebSocket;

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

/// How often blocked loops look at the stop flag.
pub(super) const POLL: Duration = Duration::from_millis(10);
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
        source: Box<dyn ViewSource>,
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

enum Job {
    Frame(FrameJob),
    Shot(ShotJob),
}

/// Renders requests round-robin over the clients until the server stops.
fn render_worker(mut source: Box<dyn ViewSource>, shared: &Shared) {
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
                let result = guarded(|| match job.quality {
                    Quality::Preview => source.render_preview(&job.camera, &job.settings),
                    Quality::Full => source.render(&job.camera, &job.settings),
                });
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
        Ok(Err(e)) => Err(format!(
            "render failed: {}",
            crate::console::error_sentence(&e)
        )),
        Err(_) => Err(
            "the renderer failed unexpectedly (a bug; the message is in the server's log)".into(),
        ),
    }
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
