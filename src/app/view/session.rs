//! One tab's connection: its WebSocket, camera and settings.
//!
//! Two threads serve a tab, and neither polls:
//!
//! * The reader (the connection's thread) owns the tab's state. It blocks in
//!   tungstenite's `read` (no time-out), parses and checks what the page sends, puts
//!   frame requests in the tab's slot for the render worker and queues its answers for
//!   the writer. The rest timer is the worker's: a preview request leaves a full frame
//!   due [`ServerConfig::rest_delay`](super::queue::ServerConfig::rest_delay) later.
//! * The writer is the only thread that writes to the socket once the handshake is
//!   done. It blocks on its channel and writes what arrives at once: the worker's frames
//!   (encoded here: JPEG previews, PNG at rest) and screenshots, the reader's answers,
//!   pongs and the close message.
//!
//! Both use tungstenite over the same `TcpStream` (`&TcpStream` reads and writes): the
//! reader's WebSocket only reads, the writer's only writes. tungstenite answers pings
//! and closes by itself inside `read`; those automatic writes would interleave with the
//! writer's frames, so the reader's stream ([`Reading`]) drops writes after the
//! handshake and the reader passes pings and closes on to the writer, which answers
//! them. The handshake itself is tungstenite's (`accept_hdr_with_config`): the Host and
//! Origin checks and the number of tabs are decided in its callback, which answers a
//! refusal with the HTTP error.
//!
//! The end: a client's close is echoed by the writer; a broken connection ends the
//! reader, which tells the writer to stop; a writer that cannot write shuts the socket,
//! which ends the reader's blocked read; when the server stops it shuts the reading
//! side of every socket, and each reader has its writer send a close message.

use super::http::{drain, loopback_host, refusal, same_origin, LINGER};
use super::paths::{export_path, sample_path};
use super::preview::{next_plan, PreviewCost};
use super::protocol::{
    binary_message, camera_from_entry, camera_to_entry, ClientMessage, FrameHeader, KeyframeIn,
    PathFormat, Quality, ServerMessage, ShotHeader,
};
use super::queue::{FrameJob, Outgoing, Pending, Shared, ShotJob};
use super::source::{ShotFormat, ViewFrame, ViewSettings};
use crate::core::camera::Camera;
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, TcpStream};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tungstenite::error::CapacityError;
use tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tungstenite::http::StatusCode;
use tungstenite::protocol::frame::coding::CloseCode;
use tungstenite::protocol::{CloseFrame, Role, WebSocketConfig};
use tungstenite::{Message, WebSocket};

/// Longest WebSocket message a client may send (a long keyframe list fits).
const MAX_MESSAGE: usize = 4 << 20;

/// Serves one tab on this thread and a writer thread: the WebSocket handshake on the
/// socket whose request head (`bytes[..head_len]`, any bytes past it after) was read,
/// then the tab until either side ends.
pub(super) fn serve(stream: TcpStream, bytes: Vec<u8>, head_len: usize, shared: &Shared) {
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_MESSAGE))
        .max_frame_size(Some(MAX_MESSAGE));
    let (tx, rx) = mpsc::channel();
    let mut id = None;
    let reading = Reading {
        socket: &stream,
        bytes,
        at: 0,
        head_len,
        upgraded: false,
    };
    let worker_tx = tx.clone();
    let registered = &mut id;
    // The signature is tungstenite's (its `Callback`), large error and all.
    #[allow(clippy::result_large_err)]
    let check = move |req: &Request, response: Response| -> Result<Response, ErrorResponse> {
        let header = |name: &str| req.headers().get(name).and_then(|v| v.to_str().ok());
        if shared.loopback && !loopback_host(header("Host")) {
            return Err(refusal(
                StatusCode::FORBIDDEN,
                "the viewer answers only to localhost names\n",
            ));
        }
        if !same_origin(header("Origin"), header("Host")) {
            return Err(refusal(
                StatusCode::FORBIDDEN,
                "the WebSocket must come from the viewer's own page\n",
            ));
        }
        *registered = Some(register(shared, worker_tx).ok_or_else(|| {
            refusal(
                StatusCode::SERVICE_UNAVAILABLE,
                "too many viewer tabs are open\n",
            )
        })?);
        Ok(response)
    };
    // A refusal was written by tungstenite; any other failure ends the connection.
    let ws = tungstenite::accept_hdr_with_config(reading, check, Some(config)).ok();
    if let (Some(mut ws), Some(id)) = (ws, id) {
        if stream.set_read_timeout(None).is_ok() {
            ws.get_mut().upgraded = true;
            let writer = Writer {
                ws: WebSocket::from_raw_socket(&stream, Role::Server, Some(config)),
                id,
                shared,
            };
            std::thread::scope(|s| {
                s.spawn(move || writer.run(rx));
                let last = Session::new(id, tx.clone(), shared).run(&mut ws);
                // No more work for this tab; then the writer's last message.
                unregister(shared, id);
                let _ = tx.send(last);
            });
        }
    }
    if let Some(id) = id {
        unregister(shared, id);
    }
}

/// A new tab's slots, unless [`ServerConfig::max_clients`](super::queue::ServerConfig)
/// are open.
fn register(shared: &Shared, tx: mpsc::Sender<Outgoing>) -> Option<u64> {
    let mut q = shared.queue();
    if q.clients.len() >= shared.config.max_clients {
        return None;
    }
    q.next_id += 1;
    let id = q.next_id;
    q.clients.insert(
        id,
        Pending {
            frame: None,
            rest: None,
            shot: None,
            frame_in_flight: false,
            preview: shared.preview_limits.first_plan(),
            tx,
        },
    );
    Some(id)
}

fn unregister(shared: &Shared, id: u64) {
    shared.queue().clients.remove(&id);
    shared.wake.notify_all();
}

/// The socket as the reader's WebSocket sees it. Reads give the request head the
/// server already read (for the handshake), then the bytes read past it, then the
/// socket. Writes reach the socket only until the handshake is done (its response);
/// afterwards they are dropped: they are tungstenite's automatic answers to pings and
/// closes, which the writer sends instead.
struct Reading<'s> {
    socket: &'s TcpStream,
    bytes: Vec<u8>,
    at: usize,
    head_len: usize,
    upgraded: bool,
}

impl Read for Reading<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        // The handshake reads only the head: tungstenite refuses bytes past the request.
        let end = if self.upgraded {
            self.bytes.len()
        } else {
            self.head_len
        };
        if self.at < end {
            let n = buf.len().min(end - self.at);
            buf[..n].copy_from_slice(&self.bytes[self.at..self.at + n]);
            self.at += n;
            return Ok(n);
        }
        if !self.upgraded {
            return Ok(0);
        }
        self.socket.read(buf)
    }
}

impl Write for Reading<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.upgraded {
            Ok(buf.len())
        } else {
            self.socket.write(buf)
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if self.upgraded {
            Ok(())
        } else {
            self.socket.flush()
        }
    }
}

/// A tab's writer: the only thread writing to its socket after the handshake.
struct Writer<'s> {
    ws: WebSocket<&'s TcpStream>,
    id: u64,
    shared: &'s Shared,
}

impl Writer<'_> {
    /// Writes what arrives until the reader's last message (or a failed write).
    fn run(mut self, rx: mpsc::Receiver<Outgoing>) {
        while let Ok(out) = rx.recv() {
            let sent = match out {
                Outgoing::Frame { job, result } => self.frame(&job, result),
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
                                "verisplat_{}.{}",
                                unix_seconds(),
                                match format {
                                    ShotFormat::Png => "png",
                                    ShotFormat::Exr => "exr",
                                }
                            ),
                        };
                        self.send(Message::binary(binary_message(&header, &bytes)))
                    }
                    Err(e) => self.send(Message::text(error_text(&e, Some(seq)))),
                },
                Outgoing::Text(text) => self.send(Message::text(text)),
                Outgoing::Pong(data) => self.send(Message::Pong(data)),
                Outgoing::Close(frame) => {
                    let sent = self.ws.close(frame);
                    if self.retry(sent).is_ok() {
                        // The client reads the close and closes its side; the reader
                        // sees that end.
                        let _ = self.ws.get_ref().shutdown(Shutdown::Write);
                        return;
                    }
                    break;
                }
                Outgoing::End => break,
            };
            if sent.is_err() {
                break;
            }
        }
        // Ends the reader's read where this side ended first (a write failed), and
        // closes the connection from the server's side.
        let _ = self.ws.get_ref().shutdown(Shutdown::Both);
    }

    fn send(&mut self, message: Message) -> tungstenite::Result<()> {
        let sent = self.ws.send(message);
        self.retry(sent)
    }

    /// Finishes a write a signal interrupted (tungstenite keeps what is unwritten).
    fn retry(&mut self, mut result: tungstenite::Result<()>) -> tungstenite::Result<()> {
        while matches!(&result, Err(tungstenite::Error::Io(e)) if e.kind() == ErrorKind::Interrupted)
        {
            result = self.ws.flush();
        }
        result
    }

    /// Encodes and writes a rendered frame (or its error); then the worker may render
    /// the tab's next one.
    fn frame(
        &mut self,
        job: &FrameJob,
        result: Result<ViewFrame, String>,
    ) -> tungstenite::Result<()> {
        let message = match result {
            Ok(frame) => {
                if job.quality == Quality::Preview {
                    self.adapt_preview(&frame);
                }
                encode_frame(job, &frame, self.shared.config.jpeg_quality)
            }
            Err(e) => Err(e),
        };
        let sent = match message {
            Ok(bytes) => self.send(Message::binary(bytes)),
            Err(e) => self.send(Message::text(error_text(&e, Some(job.seq)))),
        };
        if let Some(p) = self.shared.queue().clients.get_mut(&self.id) {
            p.frame_in_flight = false;
        }
        self.shared.wake.notify_all();
        sent
    }

    /// Plans the tab's next preview (Gaussians and pixels) from this one's stage times
    /// ([`next_plan`]).
    fn adapt_preview(&mut self, frame: &ViewFrame) {
        let pixels = frame.width as f64 * frame.height as f64;
        let cost = PreviewCost::of(&frame.timings);
        let limits = &self.shared.preview_limits;
        if let Some(p) = self.shared.queue().clients.get_mut(&self.id) {
            p.preview = next_plan(p.preview, f64::from(frame.gaussians), pixels, cost, limits);
        }
    }
}

/// One tab's state, kept by its reader.
struct Session<'s> {
    id: u64,
    /// To the tab's writer.
    tx: mpsc::Sender<Outgoing>,
    shared: &'s Shared,
    /// The last frame request (full quality, before the size caps), for `rest`,
    /// `settings` and screenshots without a camera.
    last: Option<FrameJob>,
    settings: ViewSettings,
    window_start: Instant,
    window_count: u32,
    window_warned: bool,
}

impl<'s> Session<'s> {
    fn new(id: u64, tx: mpsc::Sender<Outgoing>, shared: &'s Shared) -> Self {
        Session {
            id,
            tx,
            shared,
            last: None,
            settings: ViewSettings::default(),
            window_start: Instant::now(),
            window_count: 0,
            window_warned: false,
        }
    }

    /// Reads and handles the page's messages until the connection ends; returns the
    /// writer's last message.
    fn run(&mut self, ws: &mut WebSocket<Reading>) -> Outgoing {
        self.send(Outgoing::Text(self.shared.hello_text.clone()));
        loop {
            match ws.read() {
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
                Ok(Message::Ping(data)) => self.send(Outgoing::Pong(data)),
                Ok(Message::Close(frame)) => return Outgoing::Close(frame),
                Ok(_) => {}
                Err(tungstenite::Error::Io(e)) if e.kind() == ErrorKind::Interrupted => {}
                Err(tungstenite::Error::Capacity(e)) => {
                    // The connection cannot resynchronise after an oversized frame: it
                    // is closed with 1009 and why, and what the client still sends of
                    // the message is read and dropped meanwhile (closing a socket with
                    // unread bytes resets it, and the client would lose the close).
                    self.send(Outgoing::Close(Some(CloseFrame {
                        code: CloseCode::Size,
                        reason: capacity_reason(&e).into(),
                    })));
                    drain(ws.get_ref().socket, LINGER);
                    return Outgoing::End;
                }
                // The server stops: it shut the reading side of the socket.
                Err(_) if self.shared.stopping() => {
                    return Outgoing::Close(Some(CloseFrame {
                        code: CloseCode::Away,
                        reason: "the viewer server is stopping".into(),
                    }))
                }
                Err(_) => return Outgoing::End,
            }
        }
    }

    /// Queues a message for the writer (gone only when the connection is).
    fn send(&self, out: Outgoing) {
        let _ = self.tx.send(out);
    }

    fn send_text(&self, message: &ServerMessage) -> Result<(), String> {
        let text = serde_json::to_string(message).map_err(|e| e.to_string())?;
        self.send(Outgoing::Text(text));
        Ok(())
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

    fn send_error(&self, message: &str, seq: Option<u64>) {
        self.send(Outgoing::Text(error_text(message, seq)));
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
        self.submit_frame(FrameJob {
            seq,
            camera,
            settings,
            quality: if interactive {
                Quality::Preview
            } else {
                Quality::Full
            },
            gaussians: u32::MAX, // set from the tab's plan in submit_frame
        });
        Ok(())
    }

    fn new_settings(&mut self, seq: u64, settings: ViewSettings) -> Result<(), String> {
        let settings = self.checked_settings(Some(settings))?;
        self.settings = settings.clone();
        if let Some(job) = self.last.clone() {
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
        self.send_text(&ServerMessage::Camera {
            seq,
            index,
            camera: entry,
        })?;
        let settings = self.settings.clone();
        self.submit_frame(FrameJob {
            seq,
            camera: cam,
            settings,
            quality: Quality::Full,
            gaussians: u32::MAX,
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
        self.send_text(&ServerMessage::Export {
            seq,
            format,
            filename: match format {
                PathFormat::Verisplat => "keyframes.json".into(),
                PathFormat::Nerfstudio => "camera_path.json".into(),
            },
            text,
            cameras: entries,
        })
    }

    fn sample(&mut self, seq: u64, fps: f32, keyframes: &[KeyframeIn]) -> Result<(), String> {
        let frames = sample_path(fps, keyframes)?;
        let cameras = frames
            .iter()
            .enumerate()
            .map(|(i, c)| camera_to_entry(c, i))
            .collect::<Result<Vec<_>, _>>()?;
        self.send_text(&ServerMessage::Path {
            seq,
            fps: fps as f64,
            cameras,
        })
    }

    /// Puts a frame request in this client's slot (replacing an older one): its size
    /// capped by `--max-resolution`, previews scaled down further. A preview leaves the
    /// full frame of its view due after [`ServerConfig::rest_delay`]; a full frame
    /// cancels a due one.
    ///
    /// [`ServerConfig::rest_delay`]: super::queue::ServerConfig::rest_delay
    fn submit_frame(&mut self, job: FrameJob) {
        self.last = Some(FrameJob {
            quality: Quality::Full,
            ..job.clone()
        });
        let config = &self.shared.config;
        let capped = cap_resolution(&job.camera, config.max_resolution);
        let mut q = self.shared.queue();
        if let Some(p) = q.clients.get_mut(&self.id) {
            let (camera, rest) = match job.quality {
                Quality::Full => (capped, None),
                Quality::Preview => {
                    let full = FrameJob {
                        camera: capped.clone(),
                        quality: Quality::Full,
                        ..job.clone()
                    };
                    let due = Instant::now() + config.rest_delay;
                    (
                        cap_pixels(&capped, p.preview.pixels as u32),
                        Some((due, full)),
                    )
                }
            };
            let gaussians = p.preview.gaussians as u32;
            p.frame = Some(FrameJob {
                camera,
                gaussians,
                ..job
            });
            p.rest = rest;
        }
        drop(q);
        self.shared.wake.notify_all();
    }
}

/// JPEG for previews, PNG for full frames, behind the frame header.
fn encode_frame(job: &FrameJob, frame: &ViewFrame, jpeg_quality: u8) -> Result<Vec<u8>, String> {
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
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, jpeg_quality)
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
        timings: frame.timings.clone(),
        gaussians: frame.gaussians,
        visible: frame.stats.visible,
        pairs: frame.stats.pairs,
        wall_ms: frame.wall_ms,
        encode_ms: start.elapsed().as_secs_f64() * 1e3,
    };
    Ok(binary_message(&header, &bytes))
}

/// The reason of the close that refuses an oversized message (at most 123 bytes, as a
/// close frame's reason must be).
fn capacity_reason(e: &CapacityError) -> String {
    match e {
        CapacityError::MessageTooLong { size, max_size } => format!(
            "a message of {} is over the limit of {}",
            mib(*size),
            mib(*max_size)
        ),
        other => format!("message refused: {other}"),
    }
}

/// Bytes as MiB with one decimal.
fn mib(bytes: usize) -> String {
    format!("{:.1} MiB", bytes as f64 / (1 << 20) as f64)
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

pub(super) fn error_text(message: &str, seq: Option<u64>) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caps_keep_the_aspect_ratio() {
        let cam = crate::core::camera::default_camera(&[[0.0; 3]], 4000, 2000);
        let c = cap_resolution(&cam, (1920, 1080));
        assert_eq!((c.width, c.height), (1920, 960));
        assert!((c.fx / cam.fx - 0.48).abs() < 1e-6);
        let p = cap_pixels(&c, 250_000);
        assert!(p.width * p.height <= 250_000, "{}x{}", p.width, p.height);
        assert_eq!(p.width / p.height, 2);
        let small = crate::core::camera::default_camera(&[[0.0; 3]], 64, 48);
        assert_eq!(cap_resolution(&small, (1920, 1080)), small);
    }
}
