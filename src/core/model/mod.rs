//! The splat model the renderers share: the Gaussians after the reference activations
//! ([`ActivatedScene`]), the alpha falloff ([`SplatKernel`]), the per-frame options
//! ([`RenderOptions`]), the reference's constants and its spherical harmonics ([`sh`]).
//!
//! It sits below the CPU reference ([`crate::cpu`]), the GPU pipeline ([`crate::render`])
//! and the scene files ([`crate::core::scene`]), and uses none of them, so that none of those
//! needs another for its types. `cpu` and `scene` re-export what used to live in them
//! (`cpu::RenderOptions`, `cpu::sh`, `scene::ActivatedScene`, ...).

pub mod field;
pub mod grad;
pub mod rules;
pub mod sh;
pub mod surface;
pub mod unscented;

pub use rules::{clamp_limits, Rules};

/// The reference's constants, defined once in [`crate::core::rules`] (the shaders get them from
/// there too).
pub use crate::core::rules::{
    ALPHA_MAX, ALPHA_MIN, ANTIALIAS_MIN_RATIO, COV2D_DILATION, NEAR_PLANE, TILE_SIZE, T_MIN,
};

/// Number of SH coefficients per colour channel for a degree (0..=3).
pub const fn sh_coeffs_for_degree(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// The falloff of a splat's alpha with the squared Mahalanobis distance `d2` of a pixel
/// from its 2D centre (`d2 = A dx^2 + 2 B dx dy + C dy^2` with the conic, i.e.
/// `d2 = -2 power` in the reference's terms). Chosen with `--kernel`; both kernels follow the
/// same 1/255 skip, 0.99 clamp and 1e-4 transmittance rules.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SplatKernel {
    /// `opacity * exp(-d2 / 2)`: the reference's Gaussian.
    #[default]
    Gaussian,
    /// `opacity * max(0, 1 - d2 / 9)`: the power-function kernel, whose support ends at the
    /// 3-sigma ellipse (inside the reference's radius, so its tile rectangle clips nothing).
    Power,
}

impl SplatKernel {
    /// Every kernel, in `--kernel` order.
    pub const ALL: [SplatKernel; 2] = [SplatKernel::Gaussian, SplatKernel::Power];

    /// The name `--kernel` and the PLY comment use.
    pub fn name(self) -> &'static str {
        match self {
            SplatKernel::Gaussian => "gaussian",
            SplatKernel::Power => "power",
        }
    }

    /// Alpha before the 0.99 clamp at a pixel where the reference's exponent is `power`
    /// (`power = -d2 / 2 <= 0`). The Gaussian's exp is [`crate::core::math::exp`], the
    /// same bits on every platform and the shaders' in the reproducible mode.
    pub fn falloff(self, opacity: f32, power: f32) -> f32 {
        match self {
            SplatKernel::Gaussian => opacity * crate::core::math::exp(power),
            SplatKernel::Power => {
                let d2 = -2.0 * power;
                opacity * (1.0 - d2 / 9.0).max(0.0)
            }
        }
    }

    /// Exact bound of the tile culling: a pixel at squared Mahalanobis distance `d2` can get
    /// alpha >= 1/255 only when `d2 <= bound`. Gaussian: `2 ln(255 opacity)`; power:
    /// `9 (1 - 1 / (255 opacity))`. Both with the same small conservative margin (relative
    /// 1e-3 plus 0.01) against rounding in the per-pixel evaluation; negative when the
    /// Gaussian reaches 1/255 nowhere. Mirrors `alpha_bound` in `glsl/render/forward/splat_common.glsl`.
    pub fn alpha_bound(self, opacity: f32) -> f32 {
        let exact = match self {
            SplatKernel::Gaussian => 2.0 * (255.0 * opacity).ln(),
            SplatKernel::Power => 9.0 * (1.0 - 1.0 / (255.0 * opacity)),
        };
        exact * 1.001 + 0.01
    }

    /// The value the shaders receive (`FrameParams.filters.w`, `SPLAT_KERNEL`).
    pub fn shader_id(self) -> u32 {
        match self {
            SplatKernel::Gaussian => crate::core::shader_interface::SPLAT_KERNEL_GAUSSIAN,
            SplatKernel::Power => crate::core::shader_interface::SPLAT_KERNEL_POWER,
        }
    }
}

impl std::fmt::Display for SplatKernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SplatKernel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "gaussian" => Ok(SplatKernel::Gaussian),
            "power" => Ok(SplatKernel::Power),
            other => Err(format!("unknown kernel {other:?}; use gaussian or power")),
        }
    }
}

/// Options shared by every renderer.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Colour added behind the Gaussians, weighted by the final transmittance.
    pub background: [f32; 3],
    /// Opacity compensation for scenes trained with the antialiased (mip) setting: each
    /// opacity is multiplied by `sqrt(max(2.5e-5, det_before / det_after))` of the 0.3
    /// dilation (the reference's optional `antialiasing` flag). Off by default.
    pub antialiased: bool,
    /// Every Gaussian's axis scales are multiplied by this before its covariance is built
    /// (the reference rasterizer's `scaling_modifier`, `S = modifier * scale`). 1 by default.
    pub scale_modifier: f32,
    /// Gaussians whose largest axis scale (activated, before the modifier) is above this,
    /// or NaN, are culled: the frame equals that of a scene without them
    /// (`SceneFilter::max_scale`), without re-uploading anything. `None` keeps all.
    pub max_scale: Option<f32>,
    /// Gaussians whose activated opacity is below this, or NaN, are culled
    /// (`SceneFilter::min_opacity`). `None` keeps all.
    pub min_opacity: Option<f32>,
    /// SH degree evaluated, at most the scene's. `None` evaluates the scene's own.
    pub sh_degree: Option<u32>,
    /// Alpha falloff of every splat ([`SplatKernel::Gaussian`] by default, the reference).
    pub kernel: SplatKernel,
    /// Which rasterizer's rules ([`Rules::Original`] by default).
    pub rules: Rules,
    /// Gaussians nearer than this view depth are culled; `None`: the rules' default (0.2,
    /// gsplat's 0.01). Must be positive.
    pub near_plane: Option<f32>,
    /// The reproducible mode: the blends take exp from [`crate::core::math::exp`] (the CPU
    /// reference's) and keep their arithmetic unfused, so a device renders the reference's
    /// bits where its preprocess does too (docs/reproducibility.md). Off by default: it
    /// costs blend time.
    pub reproducible: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            background: [0.0; 3],
            antialiased: false,
            scale_modifier: 1.0,
            max_scale: None,
            min_opacity: None,
            sh_degree: None,
            kernel: SplatKernel::Gaussian,
            rules: Rules::Original,
            near_plane: None,
            reproducible: false,
        }
    }
}

impl RenderOptions {
    /// The near plane in use ([`Self::near_plane`] or the rules' default).
    pub fn near(&self) -> f32 {
        self.near_plane.unwrap_or(self.rules.default_near_plane())
    }

    /// The SH degree evaluated for a scene of degree `scene_degree`.
    pub fn active_sh_degree(&self, scene_degree: u32) -> u32 {
        self.sh_degree.map_or(scene_degree, |d| d.min(scene_degree))
    }

    /// Whether Gaussian `i` passes the per-frame filters ([`Self::max_scale`],
    /// [`Self::min_opacity`]); the GPU's preprocess applies the same test.
    pub fn keeps(&self, scene: &ActivatedScene, i: usize) -> bool {
        if let Some(max) = self.max_scale {
            let s = scene.scales[i];
            let largest = s[0].max(s[1]).max(s[2]);
            // A NaN scale is dropped, as by `SceneFilter`.
            if largest.is_nan() || largest > max {
                return false;
            }
        }
        if let Some(min) = self.min_opacity {
            let opacity = scene.opacities[i];
            if opacity.is_nan() || opacity < min {
                return false;
            }
        }
        true
    }

    /// Checks the values (finite, positive modifier and scale, opacity in [0, 1]).
    pub fn validate(&self) -> Result<(), String> {
        if !(self.scale_modifier.is_finite() && self.scale_modifier > 0.0) {
            return Err(format!(
                "the scale modifier must be a positive number, got {}",
                self.scale_modifier
            ));
        }
        if let Some(m) = self.max_scale {
            if !(m.is_finite() && m > 0.0) {
                return Err(format!("the max scale must be a positive number, got {m}"));
            }
        }
        if let Some(o) = self.min_opacity {
            if !(0.0..=1.0).contains(&o) {
                return Err(format!("the min opacity must be in [0, 1], got {o}"));
            }
        }
        if let Some(n) = self.near_plane {
            // Depth keys order as unsigned bits only for positive depths.
            if !(n.is_finite() && n > 0.0) {
                return Err(format!("the near plane must be a positive number, got {n}"));
            }
        }
        if !self.background.iter().all(|c| c.is_finite()) {
            return Err(format!(
                "the background must be finite, got {:?}",
                self.background
            ));
        }
        Ok(())
    }
}

/// Gaussians after the reference activations, ready to render or upload.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ActivatedScene {
    /// SH degree, 0..=3.
    pub sh_degree: u32,
    /// World-space centres.
    pub positions: Vec<[f32; 3]>,
    /// Axis scales, `exp(log_scale)`.
    pub scales: Vec<[f32; 3]>,
    /// Normalised rotation quaternions `(w, x, y, z)`.
    pub rotations: Vec<[f32; 4]>,
    /// Opacities, `sigmoid(logit)`.
    pub opacities: Vec<f32>,
    /// SH coefficients, same layout as [`crate::core::scene::Scene::sh`].
    pub sh: Vec<f32>,
    /// Feature channels per Gaussian, as [`crate::core::scene::Scene::feature_count`].
    pub feature_count: usize,
    /// Features, same layout as [`crate::core::scene::Scene::features`].
    pub features: Vec<f32>,
}

impl ActivatedScene {
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    /// True when the scene holds no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
    /// Floats of SH per Gaussian.
    pub fn sh_stride(&self) -> usize {
        sh_coeffs_for_degree(self.sh_degree) * 3
    }

    /// The scene as a compact upload (`--compact`) holds it, back in f32: axis scales,
    /// rotations and SH coefficients rounded to the nearest fp16; centres, opacities and
    /// features unchanged. The CPU reference renders this to check compact GPU frames.
    pub fn compact_rounded(&self) -> ActivatedScene {
        let round = |x: f32| half::f16::from_f32(x).to_f32();
        ActivatedScene {
            scales: self.scales.iter().map(|s| s.map(round)).collect(),
            rotations: self.rotations.iter().map(|q| q.map(round)).collect(),
            sh: self.sh.iter().map(|&x| round(x)).collect(),
            ..self.clone()
        }
    }
}
