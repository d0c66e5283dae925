//! Host mirrors of the records in `glsl/splat_common.glsl` (std430). The tests pin every
//! size and offset so the two sides cannot drift.

use bytemuck::{Pod, Zeroable};

/// Per-frame parameters (`FrameParams` in GLSL).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FrameParams {
    /// World-to-camera rotation row 0, `w` = translation x.
    pub w2c_row0: [f32; 4],
    /// Row 1, `w` = translation y.
    pub w2c_row1: [f32; 4],
    /// Row 2, `w` = translation z.
    pub w2c_row2: [f32; 4],
    /// Camera centre (xyz); `w` is 1 with the antialiasing opacity compensation, else 0.
    pub cam_pos: [f32; 4],
    /// fx, fy, cx, cy.
    pub focal: [f32; 4],
    /// The guard band of the 2D covariance (`model::Rules::clamp_limits`): `x/z` is clamped
    /// to `[-x, y]`, `y/z` to `[-z, w]`.
    pub limits: [f32; 4],
    /// Background rgb.
    pub background: [f32; 4],
    /// width, height, tiles_x, tiles_y.
    pub image: [u32; 4],
    /// Gaussians, active SH degree, stored SH coefficients per channel, key capacity.
    pub counts: [u32; 4],
    /// Bin size in pixels (16 or 8), bins_x, bins_y, 16 / bin size.
    pub bins: [u32; 4],
    /// Scale modifier, max scale (< 0: no limit), min opacity (< 0: no limit), and the
    /// alpha falloff (`cpu::SplatKernel::shader_id` as a float): the per-frame options of
    /// `cpu::RenderOptions`, applied by preprocess (the falloff also picks the blend
    /// pipeline).
    pub filters: [f32; 4],
    /// The rules' numbers (`model::Rules`): a centre is kept when its depth is above `x`
    /// (the near plane, or the float below gsplat's), alpha clamp, a pixel ends before its
    /// transmittance would drop below `z`, the antialiased compensation's lowest ratio.
    pub rules: [f32; 4],
    /// `Rules::shader_id` (the screen extent's rule) and three zeros.
    pub modes: [u32; 4],
}

/// One uploaded Gaussian (`Gaussian` in GLSL), activated.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuGaussian {
    /// Centre xyz, opacity in `w`.
    pub pos_opacity: [f32; 4],
    /// Axis scales (xyz).
    pub scale: [f32; 4],
    /// Unit quaternion (w, x, y, z).
    pub rotation: [f32; 4],
}

/// One Gaussian of a compact upload (`GaussianCompact` in GLSL): the centre and opacity in
/// f32, the axis scales and the rotation as fp16 pairs (`packHalf2x16` order: the first
/// value in the low half).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuGaussianCompact {
    /// Centre xyz, opacity in `w`.
    pub pos_opacity: [f32; 4],
    /// (scale x, scale y), (scale z, rotation w), (rotation x, rotation y), (rotation z, 0).
    pub shape: [u32; 4],
}

impl GpuGaussianCompact {
    /// The compact record of a Gaussian (rounding to nearest fp16, as
    /// `ActivatedScene::compact_rounded`).
    pub fn new(position: [f32; 3], opacity: f32, scale: [f32; 3], rotation: [f32; 4]) -> Self {
        let pack = |a: f32, b: f32| {
            u32::from(half::f16::from_f32(a).to_bits())
                | (u32::from(half::f16::from_f32(b).to_bits()) << 16)
        };
        let [w, x, y, z] = rotation;
        GpuGaussianCompact {
            pos_opacity: [position[0], position[1], position[2], opacity],
            shape: [
                pack(scale[0], scale[1]),
                pack(scale[2], w),
                pack(x, y),
                pack(z, 0.0),
            ],
        }
    }
}

/// A projected Gaussian (`Splat` in GLSL).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Splat {
    /// mean2d x, y, opacity, and the bound on the quadratic form (squared Mahalanobis
    /// distance) below which the splat reaches alpha 1/255 under the frame's kernel
    /// (`cpu::SplatKernel::alpha_bound`: `2 ln(255 opacity)` or `9 (1 - 1/(255 opacity))`,
    /// with margin).
    pub mean_opacity_bound: [f32; 4],
    /// Conic A, B, C and the view depth.
    pub conic_depth: [f32; 4],
    /// RGB and the radius in pixels (0 when culled).
    pub color_radius: [f32; 4],
}

/// Frame counters (`Counters` in GLSL).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Counters {
    /// Sum of tiles touched modulo 2^32 (the scan's total).
    pub scan_total: u32,
    /// Number of keys sorted: min(total, capacity).
    pub sort_count: u32,
    /// Exact sum of tiles touched, low word.
    pub touched_lo: u32,
    /// Exact sum of tiles touched, high word.
    pub touched_hi: u32,
    /// Indirect dispatch of the ranges stage.
    pub ranges_groups: [u32; 3],
    /// Gaussians touching at least one tile.
    pub visible: u32,
    /// Largest bin loop of one Gaussian, recorded when above 4096 (CPU loop limits).
    pub max_bins_loop: u32,
    /// Largest list loop of one bin in the blend, recorded when above 4096.
    pub max_list_loop: u32,
    /// Padding.
    pub pad: [u32; 2],
}

impl Counters {
    /// The exact number of (tile, Gaussian) pairs the frame needs.
    pub fn pairs(&self) -> u64 {
        (u64::from(self.touched_hi) << 32) | u64::from(self.touched_lo)
    }
}

/// Byte offset of `Counters::scan_total`.
pub const COUNTER_SCAN_TOTAL: u64 = 0;
/// Byte offset of `Counters::sort_count`.
pub const COUNTER_SORT_COUNT: u64 = 4;
/// Byte offset of `Counters::ranges_groups`.
pub const COUNTER_RANGES_GROUPS: u64 = 16;

/// Packs a tile coordinate as the shaders do (`x | y << 16`).
pub fn unpack_tile(v: u32) -> [u32; 2] {
    [v & 0xFFFF, v >> 16]
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{offset_of, size_of};

    #[test]
    fn layouts_match_the_glsl_header() {
        assert_eq!(size_of::<FrameParams>(), 208);
        assert_eq!(offset_of!(FrameParams, w2c_row0), 0);
        assert_eq!(offset_of!(FrameParams, w2c_row1), 16);
        assert_eq!(offset_of!(FrameParams, w2c_row2), 32);
        assert_eq!(offset_of!(FrameParams, cam_pos), 48);
        assert_eq!(offset_of!(FrameParams, focal), 64);
        assert_eq!(offset_of!(FrameParams, limits), 80);
        assert_eq!(offset_of!(FrameParams, background), 96);
        assert_eq!(offset_of!(FrameParams, image), 112);
        assert_eq!(offset_of!(FrameParams, counts), 128);
        assert_eq!(offset_of!(FrameParams, bins), 144);
        assert_eq!(offset_of!(FrameParams, filters), 160);
        assert_eq!(offset_of!(FrameParams, rules), 176);
        assert_eq!(offset_of!(FrameParams, modes), 192);

        assert_eq!(size_of::<GpuGaussian>(), 48);
        assert_eq!(offset_of!(GpuGaussian, pos_opacity), 0);
        assert_eq!(offset_of!(GpuGaussian, scale), 16);
        assert_eq!(offset_of!(GpuGaussian, rotation), 32);

        assert_eq!(size_of::<GpuGaussianCompact>(), 32);
        assert_eq!(offset_of!(GpuGaussianCompact, pos_opacity), 0);
        assert_eq!(offset_of!(GpuGaussianCompact, shape), 16);

        assert_eq!(size_of::<Splat>(), 48);
        assert_eq!(offset_of!(Splat, mean_opacity_bound), 0);
        assert_eq!(offset_of!(Splat, conic_depth), 16);
        assert_eq!(offset_of!(Splat, color_radius), 32);

        assert_eq!(size_of::<Counters>(), 48);
        assert_eq!(offset_of!(Counters, scan_total) as u64, COUNTER_SCAN_TOTAL);
        assert_eq!(offset_of!(Counters, sort_count) as u64, COUNTER_SORT_COUNT);
        assert_eq!(offset_of!(Counters, touched_lo), 8);
        assert_eq!(offset_of!(Counters, touched_hi), 12);
        assert_eq!(
            offset_of!(Counters, ranges_groups) as u64,
            COUNTER_RANGES_GROUPS
        );
        assert_eq!(offset_of!(Counters, visible), 28);
        assert_eq!(offset_of!(Counters, max_bins_loop), 32);
        assert_eq!(offset_of!(Counters, max_list_loop), 36);
    }

    #[test]
    fn pair_count_is_64_bit() {
        let c = Counters {
            touched_lo: 5,
            touched_hi: 2,
            ..Default::default()
        };
        assert_eq!(c.pairs(), (2u64 << 32) + 5);
    }
}

/// Push constants of `glsl/preprocess.comp` (`Window`): the Gaussians one dispatch covers.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct WindowPush {
    /// First Gaussian of the window.
    pub first: u32,
    /// Gaussians in the window.
    pub count: u32,
}

/// Push constants of `glsl/keys.comp` (`Chunk`): the depth-ordered Gaussians keyed.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct KeysPush {
    /// First Gaussian (index in depth order).
    pub first: u32,
    /// One past the last.
    pub end: u32,
    /// Scanned offset of `first`, modulo 2^32.
    pub base: u32,
}

/// Push constants of `glsl/blend.comp` (`ChunkFlags`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct BlendPush {
    /// Non-zero: resume each pixel from the images (a chunk after the first).
    pub resume: u32,
    /// Non-zero: write final pixels (the last chunk).
    pub last: u32,
}

/// Push constants of `glsl/blend_features.comp` (`ChunkFlags`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct FeatureBlendPush {
    /// Non-zero: resume each pixel from the previous chunk's state.
    pub resume: u32,
    /// Padding.
    pub pad: u32,
}

/// Push constants of `glsl/pack.comp`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct PackPush {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}
