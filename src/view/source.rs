//! The renderer behind the viewer: one frame for a camera and the page's settings.
//!
//! The server only knows [`FrameSource`]; [`GpuSource`] renders with the Vulkan
//! pipeline, reading back RGBA8 for colour frames (the image stays on the GPU and is
//! packed there) and float planes only where a mode or a screenshot needs them.

use crate::camera::Camera;
use crate::render::{FrameStats, StageTimings};

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
}

/// Screenshot formats: written by the same code as `vksplat render`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShotFormat {
    /// 8-bit PNG of the current mode.
    Png,
    /// EXR with R, G, B, A and Z.
    Exr,
}

/// What the server asks of a renderer. Errors are messages for the page.
pub trait FrameSource: Send {
    /// Renders `cam` (its size is the frame's) with `settings`.
    fn render(&mut self, cam: &Camera, settings: &ViewSettings) -> anyhow::Result<ViewFrame>;
    /// Renders `cam` at full quality and encodes it as a file of `format`, as
    /// `vksplat render` would write it with the flags matching `settings`.
    fn screenshot(
        &mut self,
        cam: &Camera,
        settings: &ViewSettings,
        format: ShotFormat,
    ) -> anyhow::Result<Vec<u8>>;
}
