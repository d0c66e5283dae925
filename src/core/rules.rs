//! The reference rasterizer's constants (`shared/docs/reference-semantics.md`), defined
//! once: the CPU reference uses them from here, and `build.rs` passes them to every shader
//! as `#define`s (see `gpu::shader_set::shared_defines`). Std only: build.rs includes it.
//! Also the one limit the two renderers of the fitted field share
//! ([`MAX_FIELD_SAMPLES`]).

/// Tile side in pixels.
pub const TILE_SIZE: u32 = 16;
/// Gaussians whose view depth is at or below this are culled.
pub const NEAR_PLANE: f32 = 0.2;
/// Added to the diagonal of every 2D covariance (the reference's low-pass filter).
pub const COV2D_DILATION: f32 = 0.3;
/// Lower bound of the antialiasing compensation's determinant ratio (the reference's).
pub const ANTIALIAS_MIN_RATIO: f32 = 0.000025;
/// Upper clamp of a Gaussian's alpha at a pixel.
pub const ALPHA_MAX: f32 = 0.99;
/// Contributions with alpha below this are skipped.
pub const ALPHA_MIN: f32 = 1.0 / 255.0;
/// A pixel is finished before its transmittance would drop below this.
pub const T_MIN: f32 = 0.0001;

/// gsplat's rules (`--rules gsplat`, `model::Rules`): its default near plane ...
pub const GSPLAT_NEAR_PLANE: f32 = 0.01;
/// ... its alpha clamp ...
pub const GSPLAT_ALPHA_MAX: f32 = 0.999;
/// ... and the most sigmas its screen box extends along each axis.
pub const GSPLAT_EXTEND: f32 = 3.33;

/// Most samples along a ray of a field-maximum render (`glsl/render/field/field.comp` keeps one
/// accumulator per sample; the CPU reference, `cpu::field`, takes the same range).
pub const MAX_FIELD_SAMPLES: u32 = 256;
