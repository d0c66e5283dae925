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
//! `cameras.json` reader, settings by
//! [`ViewSettings::validate`](super::source::ViewSettings::validate)); what is refused is
//! answered with an `error` message to that client. A render error or a renderer panic
//! is sent to the tab that asked.
//!
//! Nothing polls; every thread blocks until it has something to do:
//!
//! * The accept loop blocks in `accept`. [`Stopper::stop`] sets the stop flag and
//!   connects to the listener, which wakes it; it then shuts the reading side of every
//!   open connection, which ends their blocked reads (each tab is sent a close
//!   message), and wakes the worker.
//! * A connection's thread reads the request head with blocking reads until a
//!   deadline, then serves a file or hands the socket to its tab (`session`: a reader
//!   on that thread, a writer on another, and a channel from the worker and the reader
//!   to the writer).
//! * The render worker waits on a condition variable: for work, or until the next
//!   rest frame is due (its time-out is that moment, not a polling interval).

use super::http::{loopback_host, read_head, refuse, respond, websocket_handshake, HeadError};
use super::page;
use super::preview::PreviewLimits;
use super::protocol::{Quality, ServerMessage};
pub use super::queue::ServerConfig;
use super::queue::{FrameJob, Outgoing, Queue, Shared, ShotJob};
use super::session;
use super::source::ViewSource;
use crate::core::camera::Camera;
use std::collections::BTreeMap;
use std::io::ErrorKind;
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// What the server serves: the `hello` every tab gets and the scene's cameras.
pub struct ServedScene {
    /// Sent on connecting.
    pub hello: super::protocol::Hello,
    /// The scene's cameras, in `hello`'s order (`select_camera` indexes them).
    pub cameras: Vec<Camera>,
}

/// A bound listener; [`Server::run`] serves until a [`Stopper`] stops it.
pub struct Server {
    listener: TcpListener,
    config: ServerConfig,
    stop: Arc<AtomicBool>,
}

/// Stops a [`Server`] from any thread (and before it runs): see [`Stopper::stop`].
#[derive(Clone, Debug)]
pub struct Stopper {
    stop: Arc<AtomicBool>,
    /// The listener's address (a loopback one where it listens on all).
    addr: SocketAddr,
}

impl Stopper {
    /// Makes [`Server::run`] close every connection and return: sets the stop flag,
    /// then connects to the listener to wake its blocking `accept`. (Should that
    /// connection fail, the next one to come in wakes it.)
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = TcpStream::connect_timeout(&self.addr, Duration::from_secs(1));
    }
}

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
        Ok(Server {
            listener,
            config,
            stop: Arc::new(AtomicBool::new(false)),
        })
    }

    /// The address bound (with the port chosen for port 0).
    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.listener.local_addr()
    }

    /// What stops [`Server::run`].
    pub fn stopper(&self) -> std::io::Result<Stopper> {
        let mut addr = self.listener.local_addr()?;
        if addr.ip().is_unspecified() {
            addr.set_ip(match addr {
                SocketAddr::V4(_) => Ipv4Addr::LOCALHOST.into(),
                SocketAddr::V6(_) => Ipv6Addr::LOCALHOST.into(),
            });
        }
        Ok(Stopper {
            stop: Arc::clone(&self.stop),
            addr,
        })
    }

    /// Serves until a [`Stopper`] stops it, then closes every connection and returns.
    pub fn run(self, source: Box<dyn ViewSource>, scene: ServedScene) -> anyhow::Result<()> {
        let sh_degree = scene.hello.sh_degree;
        let gaussians = u32::try_from(scene.hello.gaussians).unwrap_or(u32::MAX);
        let preview_limits = PreviewLimits::new(
            gaussians,
            source.preview_subset(),
            self.config.preview_pixels,
        );
        let hello_text = serde_json::to_string(&ServerMessage::Hello(Box::new(scene.hello)))?;
        let shared = Shared {
            config: self.config,
            hello_text,
            cameras: scene.cameras,
            sh_degree,
            preview_limits,
            stop: self.stop,
            loopback: self.listener.local_addr()?.ip().is_loopback(),
            connections: Mutex::new(BTreeMap::new()),
            queue: Mutex::new(Queue::default()),
            wake: Condvar::new(),
        };
        std::thread::scope(|s| {
            let shared = &shared;
            let worker = s.spawn(move || render_worker(source, shared));
            let mut last_id = 0u64;
            while !shared.stopping() {
                let stream = match self.listener.accept() {
                    Ok((stream, _)) => stream,
                    Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                    // Out of file descriptors and the like: wait rather than spin.
                    Err(_) => {
                        std::thread::sleep(Duration::from_millis(100));
                        continue;
                    }
                };
                if shared.stopping() {
                    break;
                }
                // Kept to end its reads on stop.
                let Ok(handle) = stream.try_clone() else {
                    continue;
                };
                {
                    let mut open = shared.connections();
                    // Connections beyond the bound are closed at once (a client that
                    // opens sockets in a loop cannot exhaust the threads).
                    if open.len() >= MAX_CONNECTIONS {
                        continue;
                    }
                    last_id += 1;
                    open.insert(last_id, handle);
                }
                let id = last_id;
                let _ = s.spawn(move || {
                    serve_connection(stream, shared);
                    shared.connections().remove(&id);
                });
            }
            shared.shut_connections();
            {
                // Under the lock: the worker checks the flag under it before it waits.
                let _queue = shared.queue();
                shared.wake.notify_all();
            }
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
                let now = Instant::now();
                let next_rest = start_rests(&mut q, now);
                if let Some(found) = next_job(&mut q) {
                    break found;
                }
                q = match next_rest {
                    Some(due) => {
                        let wait = shared.wake.wait_timeout(q, due - now);
                        wait.unwrap_or_else(|p| p.into_inner()).0
                    }
                    None => shared.wake.wait(q).unwrap_or_else(|p| p.into_inner()),
                };
            }
        };
        let message = match job {
            Job::Frame(job) => {
                let result = guarded(|| match job.quality {
                    Quality::Preview => {
                        source.render_preview(&job.camera, &job.settings, job.gaussians)
                    }
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

/// Puts each tab's rest frame that is due in its frame slot (it replaces the preview
/// there: the same view); returns when the next one is due.
fn start_rests(q: &mut Queue, now: Instant) -> Option<Instant> {
    let mut next: Option<Instant> = None;
    for p in q.clients.values_mut() {
        match p.rest.take() {
            Some((due, job)) if due <= now => p.frame = Some(job),
            Some((due, job)) => {
                next = Some(next.map_or(due, |n| n.min(due)));
                p.rest = Some((due, job));
            }
            None => {}
        }
    }
    next
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
            crate::core::console::error_sentence(&e)
        )),
        Err(_) => Err(
            "the renderer failed unexpectedly (a bug; the message is in the server's log)".into(),
        ),
    }
}

/// One TCP connection: a file of the page, or the upgrade to a WebSocket.
fn serve_connection(mut stream: TcpStream, shared: &Shared) {
    if stream.set_write_timeout(Some(WRITE_TIMEOUT)).is_err() {
        return;
    }
    let _ = stream.set_nodelay(true);
    let (req, bytes, head_len) = match read_head(&mut stream) {
        Ok(head) => head,
        Err(HeadError::Gone) => return,
        Err(HeadError::Refused { status, reason }) => {
            refuse(&mut stream, status, &reason);
            return;
        }
    };
    let path = req.path.split('?').next().unwrap_or("");
    // The handshake's own checks (Host, Origin, the number of tabs) answer in
    // tungstenite's callback.
    if path == "/ws" && websocket_handshake(&req) {
        session::serve(stream, bytes, head_len, shared);
        return;
    }
    if shared.loopback && !loopback_host(req.header("Host")) {
        refuse(
            &mut stream,
            "403 Forbidden",
            "the viewer answers only to localhost names",
        );
        return;
    }
    if req.method != "GET" {
        refuse(&mut stream, "405 Method Not Allowed", "only GET");
        return;
    }
    if path == "/ws" {
        refuse(
            &mut stream,
            "400 Bad Request",
            "expected a WebSocket upgrade (GET with Upgrade: websocket, Connection: Upgrade, Sec-WebSocket-Version: 13 and a Sec-WebSocket-Key)",
        );
        return;
    }
    match page::file(path) {
        Some((content_type, body)) => respond(&mut stream, "200 OK", content_type, body),
        None => refuse(&mut stream, "404 Not Found", "not found"),
    }
}
