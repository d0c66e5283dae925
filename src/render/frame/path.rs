//! Camera paths on the device with frames in flight: [`GpuPath`] is the
//! [`FrameSource`] that `crate::app::sequence::run_pipelined` drives. With two frames in
//! flight, frame `n + 1` is recorded and submitted before frame `n` is waited for, read
//! back and handed to the encoders, so the device renders while the CPU reads back.

use crate::core::camera::Camera;
use crate::core::frame::{FramePixels, FrameSource};
use crate::core::model::RenderOptions;
use crate::render::forward::shade::GpuShader;
use crate::render::{FrameRequest, Readback};
use crate::render::{FrameStats, GpuFeatures, GpuRenderer, GpuScene};
use crate::render::{StageTimings, Ticket, MAX_FRAMES_IN_FLIGHT};
use std::collections::VecDeque;

/// Called with each finished frame's timings and counts.
type FrameHook<'a> = Box<dyn FnMut(&StageTimings, &FrameStats) + 'a>;

/// Renders the frames of a path with up to `frames_in_flight` frames in flight: colour,
/// alpha and depth ([`GpuRenderer::render`]), or with features
/// ([`FrameRequest::features`], [`FrameRequest::shaded`]), or only the colour as 8-bit
/// RGBA packed on the device ([`GpuPath::rgb8`]). Each frame's files equal those of the
/// frame rendered on its own.
pub struct GpuPath<'a> {
    renderer: &'a mut GpuRenderer,
    scene: &'a GpuScene,
    features: Option<(&'a GpuFeatures, Option<&'a GpuShader>)>,
    opts: RenderOptions,
    depth: usize,
    readback: Readback,
    tickets: VecDeque<Ticket<'a>>,
    on_frame: Option<FrameHook<'a>>,
}

impl<'a> GpuPath<'a> {
    /// Frames of `scene` rendered with `opts`, up to `frames_in_flight` (1 or 2) in
    /// flight: the frames a `crate::app::sequence::run_pipelined` with the same
    /// [`crate::app::sequence::RunOptions::frames_in_flight`] submits.
    pub fn new(
        renderer: &'a mut GpuRenderer,
        scene: &'a GpuScene,
        opts: &RenderOptions,
        frames_in_flight: usize,
    ) -> Self {
        GpuPath {
            renderer,
            scene,
            features: None,
            opts: opts.clone(),
            depth: frames_in_flight.clamp(1, MAX_FRAMES_IN_FLIGHT),
            readback: Readback::Float,
            tickets: VecDeque::new(),
            on_frame: None,
        }
    }

    /// Blends `features` too (and shades them with `shader` when given).
    pub fn with_features(
        mut self,
        features: &'a GpuFeatures,
        shader: Option<&'a GpuShader>,
    ) -> Self {
        self.features = Some((features, shader));
        self
    }

    /// With `on`, the frames read back only their colour, packed to 8-bit RGBA on the
    /// device ([`Readback::Rgba8`], [`FramePixels::Rgba8`]): for runs whose every output
    /// is 8-bit colour (`crate::app::sequence::reads_rgb8_only`). Not with features.
    pub fn rgb8(mut self, on: bool) -> Self {
        self.readback = if on { Readback::Rgba8 } else { Readback::Float };
        self
    }

    /// Calls `hook` with each frame's timings and counts as the frame is finished.
    pub fn on_frame(mut self, hook: impl FnMut(&StageTimings, &FrameStats) + 'a) -> Self {
        self.on_frame = Some(Box::new(hook));
        self
    }

    /// The renderer.
    pub fn renderer(&self) -> &GpuRenderer {
        self.renderer
    }
}

impl FrameSource for GpuPath<'_> {
    fn submit(&mut self, cam: &Camera) -> anyhow::Result<()> {
        if self.tickets.len() >= self.depth {
            anyhow::bail!(
                "{} frame(s) are in flight already; finish one first",
                self.tickets.len()
            );
        }
        let mut request = FrameRequest::new(self.scene, cam, &self.opts).readback(self.readback);
        if let Some((f, shader)) = self.features {
            request = request.features(f).shader(shader);
        }
        let ticket = self.renderer.submit(&request)?;
        self.tickets.push_back(ticket);
        Ok(())
    }

    fn finish(&mut self) -> anyhow::Result<FramePixels> {
        let ticket = self
            .tickets
            .pop_front()
            .ok_or_else(|| anyhow::anyhow!("no frame is in flight"))?;
        let rendered = self.renderer.finish(ticket)?;
        let frame = match self.readback {
            Readback::Rgba8 => FramePixels::Rgba8(rendered.into_rgba8()?),
            _ => FramePixels::Float(rendered.into_frame()?),
        };
        if let Some(hook) = &mut self.on_frame {
            hook(self.renderer.timings(), self.renderer.stats());
        }
        Ok(frame)
    }

    fn discard(&mut self) {
        while let Some(t) = self.tickets.pop_front() {
            // Waiting can only fail with a lost device, which the next call reports.
            let _ = self.renderer.discard(t);
        }
    }
}

impl Drop for GpuPath<'_> {
    fn drop(&mut self) {
        self.discard();
    }
}
