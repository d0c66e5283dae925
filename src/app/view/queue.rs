//! What the viewer's threads share: the server's tunables, the served scene, the open
//! connections, and per tab the slots the render worker takes its work from and the
//! channel to the tab's writer.
//!
//! The accept loop and the render worker ([`server`](super::server)) and each tab's
//! reader and writer ([`session`](super::session)) depend on this module; the session
//! does not import the server (which hands it each WebSocket connection).

use super::preview::{PreviewLimits, PreviewPlan};
use super::protocol::Quality;
use super::source::{ShotFormat, ViewFrame, ViewSettings};
use crate::core::camera::Camera;
use std::collections::BTreeMap;
use std::net::{Shutdown, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tungstenite::protocol::CloseFrame;
use tungstenite::Bytes;

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

/// State shared by the accept loop, the connections and the worker.
pub(super) struct Shared {
    pub(super) config: ServerConfig,
    pub(super) hello_text: String,
    pub(super) cameras: Vec<Camera>,
    pub(super) sh_degree: u32,
    /// What previews may draw (the scene's Gaussians, the preview subset, the size).
    pub(super) preview_limits: PreviewLimits,
    pub(super) stop: Arc<AtomicBool>,
    /// Bound to a loopback address: requests must name a loopback host.
    pub(super) loopback: bool,
    /// Open TCP connections (each has a thread), by id: on stop the server shuts their
    /// reading side, which ends every blocked read.
    pub(super) connections: Mutex<BTreeMap<u64, TcpStream>>,
    pub(super) queue: Mutex<Queue>,
    /// Wakes the render worker: new work, a frame written, a tab gone, the stop.
    pub(super) wake: Condvar,
}

impl Shared {
    pub(super) fn queue(&self) -> MutexGuard<'_, Queue> {
        // A panic while holding the lock leaves plain data; keep serving.
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(super) fn connections(&self) -> MutexGuard<'_, BTreeMap<u64, TcpStream>> {
        self.connections.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(super) fn stopping(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }

    /// Ends every blocked read of every connection (their threads then finish); the
    /// writing side stays open, so each tab is sent a close message.
    pub(super) fn shut_connections(&self) {
        for stream in self.connections().values() {
            let _ = stream.shutdown(Shutdown::Read);
        }
    }
}

/// Work waiting for the worker, per client.
#[derive(Default)]
pub(super) struct Queue {
    pub(super) clients: BTreeMap<u64, Pending>,
    pub(super) next_id: u64,
    pub(super) last_served: u64,
}

/// One client's slots.
pub(super) struct Pending {
    /// The newest frame request (overwritten by newer ones).
    pub(super) frame: Option<FrameJob>,
    /// The full frame of the last preview's view, due when the camera has not moved for
    /// [`ServerConfig::rest_delay`]: the worker moves it to `frame` then.
    pub(super) rest: Option<(Instant, FrameJob)>,
    /// The newest screenshot request.
    pub(super) shot: Option<ShotJob>,
    /// A frame was rendered and is not yet written to the socket.
    pub(super) frame_in_flight: bool,
    /// What this tab's next preview draws ([`super::preview::next_plan`]): set by the
    /// tab's writer after each preview, read when a preview is requested.
    pub(super) preview: PreviewPlan,
    /// To the client's writer thread.
    pub(super) tx: mpsc::Sender<Outgoing>,
}

#[derive(Clone)]
pub(super) struct FrameJob {
    pub(super) seq: u64,
    pub(super) camera: Camera,
    pub(super) settings: ViewSettings,
    pub(super) quality: Quality,
    /// Gaussians a preview draws (the most important; the scene's count: all).
    pub(super) gaussians: u32,
}

pub(super) struct ShotJob {
    pub(super) seq: u64,
    pub(super) camera: Camera,
    pub(super) settings: ViewSettings,
    pub(super) format: ShotFormat,
}

/// To a tab's writer thread: from the worker (frames, screenshots) and from the tab's
/// reader (answers, and the replies to pings and closes).
pub(super) enum Outgoing {
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
    /// A JSON message.
    Text(String),
    /// The answer to a ping.
    Pong(Bytes),
    /// Send a close message (the client's own, echoed, or the server's) and end.
    Close(Option<CloseFrame>),
    /// End without a word (the connection is gone).
    End,
}
