//! One tab's connection: its WebSocket, camera and settings. It parses and checks what
//! the page sends, puts frame requests in the tab's slot for the render worker, writes
//! the worker's frames (JPEG previews, PNG at rest), answers the rest directly.

use super::paths::{export_path, sample_path};
use super::protocol::{
    binary_message, camera_from_entry, camera_to_entry, ClientMessage, FrameHeader, KeyframeIn,
    PathFormat, Quality, ServerMessage, ShotHeader,
};
use super::queue::{FrameJob, Outgoing, Shared, ShotJob};
use super::source::{ShotFormat, ViewFrame, ViewSettings};
use crate::camera::Camera;
use std::io::ErrorKind;
use std::net::TcpStream;
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tungstenite::{Message, WebSocket};

/// The blend of a preview frame should take about this long (ms).
const PREVIEW_BLEND_MS: f64 = 25.0;
/// Previews are never smaller than this many pixels.
const MIN_PREVIEW_PIXELS: f64 = 60_000.0;

/// One tab: its camera, settings and the WebSocket.
pub(super) struct Session<'s, 'a> {
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
    /// Pixels of this tab's previews: lowered while their blend takes longer than
    /// [`PREVIEW_BLEND_MS`] (a slow renderer, `--cpu`), raised back up to
    /// [`ServerConfig::preview_pixels`](super::queue::ServerConfig::preview_pixels).
    preview_pixels: f64,
}

impl<'s, 'a> Session<'s, 'a> {
    pub(super) fn new(
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
            preview_pixels: shared.config.preview_pixels as f64,
        }
    }

    pub(super) fn run(&mut self) {
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

    /// Scales the preview size so that the blend of a preview, the stage whose time
    /// grows with the pixels, takes about [`PREVIEW_BLEND_MS`] (between
    /// [`MIN_PREVIEW_PIXELS`] and the configured size); the per-Gaussian stages do not
    /// shrink with the frame, so they are left out. Damped so the size does not swing.
    fn adapt_preview(&mut self, frame: &ViewFrame) {
        let pixels = frame.width as f64 * frame.height as f64;
        let max = self.shared.config.preview_pixels as f64;
        self.preview_pixels =
            next_preview_budget(self.preview_pixels, pixels, frame.timings.blend, max);
    }

    /// Writes what the worker finished for this client; false when the socket is gone.
    fn deliver(&mut self) -> bool {
        while let Ok(out) = self.rx.try_recv() {
            let sent = match out {
                Outgoing::Frame { job, result } => {
                    let message = match result {
                        Ok(frame) => {
                            if job.quality == Quality::Preview {
                                self.adapt_preview(&frame);
                            }
                            self.encode_frame(&job, &frame)
                        }
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
            timings: frame.timings.clone(),
            gaussians: frame.gaussians,
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
            Quality::Preview => cap_pixels(&capped, self.preview_pixels as u32),
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

pub(super) fn error_text(message: &str, seq: Option<u64>) -> String {
    serde_json::to_string(&ServerMessage::Error {
        message: message.to_string(),
        seq,
    })
    .unwrap_or_default()
}

/// The preview budget after a preview of `pixels` whose blend took `blend_ms`.
fn next_preview_budget(budget: f64, pixels: f64, blend_ms: f64, max: f64) -> f64 {
    if !(blend_ms > 0.0 && pixels > 0.0) {
        return budget;
    }
    let ratio = (PREVIEW_BLEND_MS / blend_ms).clamp(0.25, 4.0).sqrt();
    let target = pixels * ratio;
    // A fast frame smaller than the budget (a small canvas) keeps the budget.
    let next = if ratio >= 1.0 {
        budget.max(target)
    } else {
        target
    };
    next.clamp(MIN_PREVIEW_PIXELS.min(max), max)
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
    fn preview_budget_follows_the_blend_time() {
        let max = 250_000.0;
        // Slow blends shrink it (damped), down to the floor.
        let b = next_preview_budget(max, max, 4.0 * PREVIEW_BLEND_MS, max);
        assert_eq!(b, max / 2.0);
        assert_eq!(next_preview_budget(b, b, 1e6, max), b / 2.0);
        assert_eq!(
            next_preview_budget(b / 2.0, b / 2.0, 1e6, max),
            MIN_PREVIEW_PIXELS
        );
        // Fast ones grow it back up to the configured size.
        assert_eq!(
            next_preview_budget(100_000.0, 100_000.0, 1.0, max),
            200_000.0
        );
        assert_eq!(next_preview_budget(200_000.0, 200_000.0, 1.0, max), max);
        // A small canvas rendered fast keeps the budget; no timing keeps it too.
        assert_eq!(next_preview_budget(max, 10_000.0, 1.0, max), max);
        assert_eq!(next_preview_budget(123.0, 10_000.0, 0.0, max), 123.0);
    }

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
}
