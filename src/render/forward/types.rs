//! The records the forward stages share with their shaders, declared once in
//! [`crate::core::shader_interface`] (which writes their GLSL), and what the host does with them.
//! The tests pin every size and offset the host relies on.

pub use crate::core::shader_interface::{
    BlendPush, Counters, FeatureBlendPush, FrameParams, GpuGaussian, GpuGaussianCompact, KeysPush,
    PackPush, Splat, WindowPush,
};

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

impl Counters {
    /// The exact number of (tile, Gaussian) pairs the frame needs.
    pub fn pairs(&self) -> u64 {
        (u64::from(self.touched_hi) << 32) | u64::from(self.touched_lo)
    }
}

/// Byte offset of `Counters::scan_total`.
pub const COUNTER_SCAN_TOTAL: u64 = std::mem::offset_of!(Counters, scan_total) as u64;
/// Byte offset of `Counters::sort_count`.
pub const COUNTER_SORT_COUNT: u64 = std::mem::offset_of!(Counters, sort_count) as u64;
/// Byte offset of `Counters::ranges_groups`.
pub const COUNTER_RANGES_GROUPS: u64 = std::mem::offset_of!(Counters, ranges_groups) as u64;

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
        assert_eq!(size_of::<FrameParams>(), 272);
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
        assert_eq!(offset_of!(FrameParams, lens_a), 208);
        assert_eq!(offset_of!(FrameParams, lens_c), 256);

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
        assert_eq!(COUNTER_SCAN_TOTAL, 0);
        assert_eq!(COUNTER_SORT_COUNT, 4);
        assert_eq!(offset_of!(Counters, touched_lo), 8);
        assert_eq!(offset_of!(Counters, touched_hi), 12);
        assert_eq!(COUNTER_RANGES_GROUPS, 16);
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
