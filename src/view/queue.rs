//! What the viewer's threads share: the server's tunables, the served scene, and per
//! tab the slots the render worker takes its work from and the channel to the tab.
//!
//! The accept loop and the render worker ([`server`](super::server)) and each tab's
//! [`session`](super::session) depend on this module, not on each other.

use super::protocol::Quality;
use super::source::{ShotFormat, ViewFrame, ViewSettings};
use crate::camera::Camera;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{mpsc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

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
pub(super) struct Shared<'a> {
    pub(super) config: ServerConfig,
    pub(super) hello_text: String,
    pub(super) cameras: Vec<Camera>,
    pub(super) sh_degree: u32,
    pub(super) stop: &'a AtomicBool,
    /// Bound to a loopback address: requests must name a loopback host.
    pub(super) loopback: bool,
    /// Open TCP connections (each has a thread).
    pub(super) connections: AtomicUsize,
    pub(super) queue: Mutex<Queue>,
    pub(super) wake: Condvar,
}

impl Shared<'_> {
    pub(super) fn queue(&self) -> MutexGuard<'_, Queue> {
        // A panic while holding the lock leaves plain data; keep serving.
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(super) fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
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
    /// The newest screenshot request.
    pub(super) shot: Option<ShotJob>,
    /// A frame was rendered and is not yet written to the socket.
    pub(super) frame_in_flight: bool,
    /// To the client's connection thread.
    pub(super) tx: mpsc::Sender<Outgoing>,
}

#[derive(Clone)]
pub(super) struct FrameJob {
    pub(super) seq: u64,
    pub(super) camera: Camera,
    pub(super) settings: ViewSettings,
    pub(super) quality: Quality,
}

pub(super) struct ShotJob {
    pub(super) seq: u64,
    pub(super) camera: Camera,
    pub(super) settings: ViewSettings,
    pub(super) format: ShotFormat,
}

/// From the worker to a connection thread.
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
}
