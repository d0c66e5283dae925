//! The renderer behind the viewer: one frame for a camera and the page's settings.
//!
//! The server only knows [`ViewSource`]; [`GpuSource`] renders with the Vulkan
//! pipeline, reading back RGBA8 for colour frames (the image stays on the GPU and is
//! packed there) and float planes only where a mode or a screenshot needs them.

use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::model::{RenderOptions, SplatKernel};
use crate::core::scene::Scene;
use crate::gpu::{ContextOptions, GpuContext};
use crate::io::output::{
    depth_colormap, encode_file, plan_files, to_u8, OutputOptions, RenderMode,
};
use crate::render::{FrameRequest, Readback, Rendered};
use crate::render::{FrameStats, GpuRenderer, GpuScene, StageTimings};

/// What the page shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ViewMode {
    /// Colour over the background.
    #[default]
    Rgb,
    /// Opacity as grey.
    Alpha,
    /// Depth with the turbo map (near warm, far cold), as `render --mode depth` writes it.
    Depth,
}

/// Per-client render settings: the page's sliders. Every field maps to a `render` flag,
/// and a frame rendered with them equals `render` with those flags.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ViewSettings {
    /// Every Gaussian's scales multiplied by this (`--scale-modifier`, the reference
    /// rasterizer's `scaling_modifier`); > 0.
    pub scale_modifier: f32,
    /// Gaussians whose largest scale is above this are not drawn (`--max-scale`);
    /// `None` draws all.
    pub max_scale: Option<f32>,
    /// Gaussians with opacity below this are not drawn (`--min-opacity`); 0 draws all.
    pub min_opacity: f32,
    /// SH degree used (`--sh-degree`); `None` is the scene's own.
    pub sh_degree: Option<u32>,
    /// Background colour, linear RGB in [0, 1] (`--background`).
    pub background: [f32; 3],
    /// What is shown.
    pub mode: ViewMode,
}

impl Default for ViewSettings {
    fn default() -> Self {
        ViewSettings {
            scale_modifier: 1.0,
            max_scale: None,
            min_opacity: 0.0,
            sh_degree: None,
            background: [0.0; 3],
            mode: ViewMode::Rgb,
        }
    }
}

impl ViewSettings {
    /// Checks every value; the message names the setting and the value.
    pub fn validate(&self, scene_sh_degree: u32) -> Result<(), String> {
        if !(self.scale_modifier.is_finite() && self.scale_modifier > 0.0) {
            return Err(format!(
                "scale_modifier must be a positive number, got {}",
                self.scale_modifier
            ));
        }
        if let Some(m) = self.max_scale {
            if !(m.is_finite() && m > 0.0) {
                return Err(format!("max_scale must be a positive number, got {m}"));
            }
        }
        if !(0.0..=1.0).contains(&self.min_opacity) {
            return Err(format!(
                "min_opacity must be in [0, 1], got {}",
                self.min_opacity
            ));
        }
        if let Some(d) = self.sh_degree {
            if d > scene_sh_degree {
                return Err(format!(
                    "sh_degree must be 0..={scene_sh_degree} (the scene's degree), got {d}"
                ));
            }
        }
        if !self
            .background
            .iter()
            .all(|c| c.is_finite() && (0.0..=1.0).contains(c))
        {
            return Err(format!(
                "background must be three numbers in [0, 1], got {:?}",
                self.background
            ));
        }
        Ok(())
    }
}

/// One frame for the page: 8-bit RGBA, row-major, top row first, alpha 255.
#[derive(Clone, Debug, Default)]
pub struct ViewFrame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height * 4` bytes.
    pub rgba8: Vec<u8>,
    /// GPU time of each stage.
    pub timings: StageTimings,
    /// Visible Gaussians, tile pairs.
    pub stats: FrameStats,
    /// Wall time of the render call (submit to readback), milliseconds.
    pub wall_ms: f64,
    /// Gaussians the frame was drawn from: the scene's, or a preview's subset.
    pub gaussians: u32,
}

/// Screenshot formats: written by the same code as `verisplat render`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShotFormat {
    /// 8-bit PNG of the current mode.
    Png,
    /// EXR with R, G, B, A and Z.
    Exr,
}

/// What the viewer's server asks of a renderer. Errors are messages for the page. (Not
/// [`crate::app::sequence::FrameSource`], which feeds `render`'s pipelined frame sequences.)
pub trait ViewSource: Send {
    /// Renders `cam` (its size is the frame's) with `settings`.
    fn render(&mut self, cam: &Camera, settings: &ViewSettings) -> anyhow::Result<ViewFrame>;
    /// Renders a preview while the camera moves, drawing about `gaussians` of the
    /// scene's Gaussians, the most important ones (all of them when `gaussians` is the
    /// scene's count or more): by default the same as [`Self::render`]; a source with a
    /// preview subset draws its first `gaussians` (see [`GpuSource::set_preview`]).
    /// [`ViewFrame::gaussians`] says how many were drawn.
    fn render_preview(
        &mut self,
        cam: &Camera,
        settings: &ViewSettings,
        gaussians: u32,
    ) -> anyhow::Result<ViewFrame> {
        let _ = gaussians;
        self.render(cam, settings)
    }
    /// The most Gaussians a preview may draw short of the whole scene (the size of the
    /// preview subset); 0 when previews always draw the whole scene.
    fn preview_subset(&self) -> u32 {
        0
    }
    /// Renders `cam` at full quality and encodes it as a file of `format`, as
    /// `verisplat render` would write it with the flags matching `settings`.
    fn screenshot(
        &mut self,
        cam: &Camera,
        settings: &ViewSettings,
        format: ShotFormat,
    ) -> anyhow::Result<Vec<u8>>;
}

/// The Vulkan pipeline behind the viewer: the scene uploaded once; settings change per
/// frame (the filters, scale modifier and SH degree are read by preprocess); colour frames
/// are packed to RGBA8 on the device and only those bytes are read back.
pub struct GpuSource {
    // Dropped before the renderer, whose context frees them.
    scene: GpuScene,
    /// The most important Gaussians of the scene, most important first: a preview draws
    /// a prefix of it.
    preview: Option<GpuScene>,
    renderer: GpuRenderer,
    sh_degree: u32,
    antialiased: bool,
    /// The alpha falloff (the scene's [`Scene::kernel`]).
    kernel: SplatKernel,
    /// The rasterizer's rules (the scene's [`Scene::rules`]).
    rules: crate::core::model::Rules,
    /// The reproducible mode ([`RenderOptions::reproducible`]).
    reproducible: bool,
}

/// The most Gaussians a preview draws by default short of the whole scene (the size of
/// the preview subset uploaded beside the scene; about 32 MiB at SH degree 3). How many
/// a preview draws is chosen per tab from the measured stage times (`session`); on
/// lavapipe the per-Gaussian stages (preprocess, depth order, keys, sort) cost about
/// 0.5 to 1 ms per 1,000 Gaussians, so previews there draw a few tens of thousands.
pub const DEFAULT_PREVIEW_GAUSSIANS: usize = 131_072;

/// Scenes of at most this many Gaussians (or `--preview-gaussians`, if fewer) always
/// preview whole: fewer would not make a frame much faster.
pub const MIN_PREVIEW_GAUSSIANS: usize = 8_192;

impl GpuSource {
    /// Opens device `device` (an index; `None`: the default device), builds the pipeline
    /// and uploads `scene`, and beside it the preview subset of `preview_gaussians`
    /// ([`Self::set_preview`]; [`DEFAULT_PREVIEW_GAUSSIANS`] unless the user asks).
    pub fn new(
        scene: &Scene,
        device: Option<usize>,
        antialiased: bool,
        preview_gaussians: usize,
    ) -> anyhow::Result<GpuSource> {
        let ctx = GpuContext::new(&ContextOptions {
            device: device.map(|d| d.to_string()),
            ..Default::default()
        })?;
        Self::with_context(ctx, scene, antialiased, preview_gaussians)
    }

    /// As [`Self::new`], on an opened context.
    pub fn with_context(
        ctx: GpuContext,
        scene: &Scene,
        antialiased: bool,
        preview_gaussians: usize,
    ) -> anyhow::Result<GpuSource> {
        let renderer = GpuRenderer::new(ctx)?;
        let gpu_scene = renderer.upload(&scene.activated())?;
        let mut source = GpuSource {
            scene: gpu_scene,
            preview: None,
            renderer,
            sh_degree: scene.sh_degree,
            antialiased,
            kernel: scene.kernel,
            rules: scene.rules,
            reproducible: false,
        };
        source.set_preview(scene, preview_gaussians)?;
        Ok(source)
    }

    /// Renders in the reproducible mode ([`RenderOptions::reproducible`]) or not.
    pub fn set_reproducible(&mut self, on: bool) {
        self.reproducible = on;
    }

    /// Previews (frames while the camera moves) may draw fewer Gaussians: the `n` most
    /// important of `scene` ([`Scene::ranked_by_importance`]) are uploaded once beside
    /// the scene, most important first, and a preview draws the first of them (as many
    /// as [`ViewSource::render_preview`] asks) or the whole scene. Resting frames and
    /// screenshots always draw the whole scene. `n == 0`, and scenes of at most
    /// [`MIN_PREVIEW_GAUSSIANS`] (or `n`, if fewer), preview whole.
    pub fn set_preview(&mut self, scene: &Scene, n: usize) -> anyhow::Result<()> {
        self.preview = None;
        if n > 0 && scene.len() > MIN_PREVIEW_GAUSSIANS.min(n) {
            let ranked = scene.ranked_by_importance(n);
            let subset = scene.select(&ranked, scene.sh_degree);
            self.preview = Some(self.renderer.upload(&subset.activated())?);
        }
        Ok(())
    }

    fn render_scene(
        &mut self,
        preview: Option<u32>,
        cam: &Camera,
        settings: &ViewSettings,
    ) -> anyhow::Result<ViewFrame> {
        let opts = self.options(settings)?;
        let scene = match (&mut self.preview, preview) {
            (Some(p), Some(n)) if n < self.scene.len() => {
                p.draw_first(n.max(1));
                &*p
            }
            _ => &self.scene,
        };
        let start = std::time::Instant::now();
        let rgba8 = match settings.mode {
            ViewMode::Rgb => {
                self.renderer
                    .render(&FrameRequest::new(scene, cam, &opts).readback(Readback::Rgba8))
                    .and_then(Rendered::into_rgba8)?
                    .rgba
            }
            mode => frame_rgba8(
                &self
                    .renderer
                    .render(&FrameRequest::new(scene, cam, &opts))
                    .and_then(Rendered::into_frame)?,
                mode,
            ),
        };
        Ok(ViewFrame {
            width: cam.width,
            height: cam.height,
            rgba8,
            timings: self.renderer.timings().clone(),
            stats: self.renderer.stats().clone(),
            wall_ms: start.elapsed().as_secs_f64() * 1e3,
            gaussians: scene.len(),
        })
    }

    /// The device's name.
    pub fn device_name(&self) -> String {
        self.renderer.ctx().info().name.clone()
    }

    /// The renderer (for its context, e.g. the validation messages).
    pub fn renderer(&self) -> &GpuRenderer {
        &self.renderer
    }

    fn options(&self, s: &ViewSettings) -> anyhow::Result<RenderOptions> {
        s.validate(self.sh_degree).map_err(anyhow::Error::msg)?;
        let mut opts = render_options(s, self.antialiased, self.kernel, self.rules);
        opts.reproducible = self.reproducible;
        Ok(opts)
    }
}

/// The render options matching `settings` (what `render` builds from the same flags).
pub fn render_options(
    settings: &ViewSettings,
    antialiased: bool,
    kernel: SplatKernel,
    rules: crate::core::model::Rules,
) -> RenderOptions {
    RenderOptions {
        background: settings.background,
        antialiased,
        scale_modifier: settings.scale_modifier,
        max_scale: settings.max_scale,
        min_opacity: (settings.min_opacity > 0.0).then_some(settings.min_opacity),
        sh_degree: settings.sh_degree,
        kernel,
        rules,
        near_plane: None,
        reproducible: false,
    }
}

/// The frame of a float render in `mode`, as the PNG `render --mode` writes would show it:
/// colour, opacity as grey, or depth through the turbo map over the frame's percentiles.
pub fn frame_rgba8(frame: &Frame, mode: ViewMode) -> Vec<u8> {
    let grey = |v: f32| {
        let g = to_u8(v);
        [g, g, g, 255]
    };
    match mode {
        ViewMode::Rgb => frame
            .color
            .iter()
            .flat_map(|c| [to_u8(c[0]), to_u8(c[1]), to_u8(c[2]), 255])
            .collect(),
        ViewMode::Alpha => frame.alpha.iter().flat_map(|&a| grey(a)).collect(),
        ViewMode::Depth => depth_colormap(frame, None)
            .iter()
            .flat_map(|c| [to_u8(c[0]), to_u8(c[1]), to_u8(c[2]), 255])
            .collect(),
    }
}

/// Encodes `frame` as `verisplat render` writes it with the matching `--mode`: PNG of the
/// mode, or EXR with R, G, B, A and Z (premultiplied, the camera in the header).
pub fn encode_shot(
    frame: &Frame,
    cam: &Camera,
    settings: &ViewSettings,
    format: ShotFormat,
) -> anyhow::Result<Vec<u8>> {
    let (name, mode) = match (format, settings.mode) {
        (ShotFormat::Exr, _) => ("screenshot.exr", RenderMode::RgbDepth),
        (ShotFormat::Png, ViewMode::Rgb) => ("screenshot.png", RenderMode::Rgb),
        (ShotFormat::Png, ViewMode::Alpha) => ("screenshot.png", RenderMode::Alpha),
        (ShotFormat::Png, ViewMode::Depth) => ("screenshot.png", RenderMode::Depth),
    };
    let opts = OutputOptions {
        mode: Some(mode),
        background: settings.background,
        ..Default::default()
    };
    let files = plan_files(std::path::Path::new(name), Some(cam), &opts)?;
    let mut out = std::io::Cursor::new(Vec::new());
    encode_file(frame, &files[0], &mut out)?;
    Ok(out.into_inner())
}

impl ViewSource for GpuSource {
    fn render(&mut self, cam: &Camera, settings: &ViewSettings) -> anyhow::Result<ViewFrame> {
        self.render_scene(None, cam, settings)
    }

    fn render_preview(
        &mut self,
        cam: &Camera,
        settings: &ViewSettings,
        gaussians: u32,
    ) -> anyhow::Result<ViewFrame> {
        self.render_scene(Some(gaussians), cam, settings)
    }

    fn preview_subset(&self) -> u32 {
        self.preview.as_ref().map_or(0, GpuScene::uploaded_len)
    }

    fn screenshot(
        &mut self,
        cam: &Camera,
        settings: &ViewSettings,
        format: ShotFormat,
    ) -> anyhow::Result<Vec<u8>> {
        let opts = self.options(settings)?;
        let frame = self
            .renderer
            .render(&FrameRequest::new(&self.scene, cam, &opts))
            .and_then(Rendered::into_frame)?;
        encode_shot(&frame, cam, settings, format)
    }
}
