//! Reading a finished frame back to the host: pixels, counters, feature planes and the
//! intermediate buffers the tests compare with the CPU reference.

use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::gpu::{BufferSlice, GpuContext, GpuError, GpuImage, GpuResult};
use crate::render::forward::types::{Counters, Splat};

use crate::render::forward::features;
use crate::render::frame::buffers::FrameSet;
use crate::render::{bin_grid, GpuScene, Rgba8Frame};

/// Intermediate buffers of a frame, read back for tests against the CPU reference.
#[derive(Clone, Debug, Default)]
pub struct Intermediates {
    /// Preprocess output per Gaussian.
    pub splats: Vec<Splat>,
    /// Packed tile rectangles per Gaussian (`x | y << 16`, min inclusive, max exclusive).
    pub rects: Vec<[u32; 2]>,
    /// Gaussian indices in depth order (culled Gaussians last).
    pub order: Vec<u32>,
    /// Exclusive prefix sum of tiles touched, in depth order.
    pub offsets: Vec<u32>,
    /// Frame counters.
    pub counters: Counters,
    /// Sorted keys: the bin (tile) ids; pairs arrive in depth order, so the keys carry no
    /// depth (of the last chunk, for a frame in chunks; so are the values, the ranges and
    /// the sort count).
    pub keys: Vec<u32>,
    /// Sorted values (Gaussian indices).
    pub values: Vec<u32>,
    /// `[start, end)` per bin.
    pub ranges: Vec<[u32; 2]>,
    /// Side of the bins in pixels (16: the reference tiles; 8: their quarters).
    pub bin_size: u32,
    /// Bins along x and y.
    pub bins: (u32, u32),
}

impl FrameSet {
    /// The `k` blended channels of the set's last features frame, pixel-major.
    pub(crate) fn read_feature_planes(
        &self,
        ctx: &GpuContext,
        k: usize,
        pixels: usize,
    ) -> GpuResult<Vec<f32>> {
        let planes = self
            .feature_planes
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("no feature image was rendered".into()))?;
        let stride = (planes.plane_bytes / 16) as usize;
        let groups = features::groups(k);
        let all: Vec<[f32; 4]> = planes.buffer.read(ctx, stride * groups)?;
        let mut out = vec![0f32; pixels * k];
        for g in 0..groups {
            let plane = &all[g * stride..g * stride + pixels];
            for (dst, src) in out.chunks_exact_mut(k).zip(plane) {
                for (c, v) in src.iter().enumerate() {
                    let ch = g * features::CHANNELS_PER_GROUP + c;
                    if ch < k {
                        dst[ch] = *v;
                    }
                }
            }
        }
        Ok(out)
    }

    /// The finished frame's colour, alpha and depth, read back as floats.
    pub(crate) fn read_frame(&self, cam: &Camera) -> GpuResult<Frame> {
        let f = self
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::Internal("no frame buffers for a finished frame".into()))?;
        let bytes = f.readback.mapped()?;
        let pixels = cam.width as usize * cam.height as usize;
        let (color_off, depth_off, _) = f.readback_offsets();
        let rgba: &[[f32; 4]] =
            bytemuck::cast_slice(&bytes[color_off as usize..color_off as usize + pixels * 16]);
        let depth: &[f32] =
            bytemuck::cast_slice(&bytes[depth_off as usize..depth_off as usize + pixels * 4]);
        // In parallel: at 4K the three copies (and the page faults of their fresh
        // allocations) took about 100 ms of one host thread on the H200 machine, 20x the
        // frame's device time (BENCHMARKS.md, 2026-11-28).
        use rayon::prelude::*;
        let (color, (alpha, depth)) = rayon::join(
            || rgba.par_iter().map(|p| [p[0], p[1], p[2]]).collect(),
            || {
                rayon::join(
                    || rgba.par_iter().map(|p| p[3]).collect(),
                    || depth.par_iter().copied().collect(),
                )
            },
        );
        Ok(Frame {
            width: cam.width,
            height: cam.height,
            color,
            alpha,
            depth,
            feature_count: 0,
            features: Vec::new(),
        })
    }

    /// The finished frame's colour, packed to 8 bits on the device.
    pub(crate) fn read_rgba8(&self, cam: &Camera) -> GpuResult<Rgba8Frame> {
        let f = self
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::Internal("no frame buffers for a finished frame".into()))?;
        let len = cam.width as usize * cam.height as usize * 4;
        let (color_off, _, _) = f.readback_offsets();
        Ok(Rgba8Frame {
            width: cam.width,
            height: cam.height,
            rgba: f.readback.mapped_range(color_off, len as u64)?.to_vec(),
        })
    }

    /// The intermediate buffers of the frame finished in this set.
    pub(crate) fn read_intermediates(
        &self,
        ctx: &GpuContext,
        scene: &GpuScene,
        cam: &Camera,
    ) -> GpuResult<Intermediates> {
        let f = self
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::Internal("no frame buffers for a finished frame".into()))?;
        let n = scene.count as usize;
        let counters = self.counters()?;
        let sorted = counters.sort_count as usize;
        let bin_size = self.bin_size;
        let (bx, by) = bin_grid(bin_size, cam.width, cam.height);
        Ok(Intermediates {
            splats: f.splats.read(ctx, n)?,
            rects: f.rects.read(ctx, n)?,
            order: f.depth_values.read(ctx, n)?,
            offsets: f.offsets.read(ctx, n)?,
            counters,
            keys: f.keys.read(ctx, sorted)?,
            values: f.values.read(ctx, sorted)?,
            ranges: f.ranges.read(ctx, (bx * by) as usize)?,
            bin_size,
            bins: (bx, by),
        })
    }
}

/// What the last finished frame left on the device that a backward pass reads, through
/// one handle: the projected Gaussians, the sorted (bin, Gaussian) pairs, each bin's range
/// of them, and the colour image whose alpha is each pixel's `1 - T_final`. Valid until
/// the renderer records its next frame. For a frame rendered in depth-ordered chunks the
/// pairs and ranges are the last chunk's ([`crate::render::FrameStats::chunks`] says how many there were).
/// With [`GpuRenderer::set_save_forward_state`](crate::render::GpuRenderer::set_save_forward_state) a frame in one piece also saves each
/// pixel's last contributor.
#[derive(Clone, Copy)]
pub struct ForwardState<'a> {
    /// One [`Splat`] per Gaussian: mean2d, opacity, conic, depth, colour, radius.
    pub splats: BufferSlice<'a>,
    /// An RGBA32F texel view of the splats (three texels each).
    pub splat_texels: ash::vk::BufferView,
    /// An R32UI texel view of the sorted pair values, on devices whose stages read through
    /// texel views (CPU devices).
    pub value_texels: Option<ash::vk::BufferView>,
    /// Sorted pair values: the Gaussian index of each (bin, Gaussian) pair, by bin and
    /// then depth; `pairs` of them.
    pub sorted_gaussians: BufferSlice<'a>,
    /// Sorted pair keys: the bin id of each pair.
    pub sorted_bins: BufferSlice<'a>,
    /// Pairs sorted.
    pub pairs: u32,
    /// `[start, end)` into the sorted pairs per bin (`uvec2`), bins row-major.
    pub ranges: BufferSlice<'a>,
    /// Side of the bins in pixels, and bins along x and y.
    pub bin_size: u32,
    /// Bins along x and y.
    pub bins: (u32, u32),
    /// RGBA32F: composited colour and alpha `1 - T_final` per pixel.
    pub color: &'a GpuImage,
    /// R32F: alpha-normalised depth per pixel.
    pub depth: &'a GpuImage,
    /// The frame's constants (`FrameParams`).
    pub params: BufferSlice<'a>,
    /// Two u32 per pixel (row-major): one past the index into the sorted pairs of the
    /// last Gaussian composited into the pixel (0 for none), and the bits of the pixel's
    /// final transmittance (f32). Only when the frame was rendered with
    /// [`GpuRenderer::set_save_forward_state`](crate::render::GpuRenderer::set_save_forward_state) and in one piece.
    pub last_contributor: Option<BufferSlice<'a>>,
    /// The blended feature channels of a features frame: one plane of vec4s per group of
    /// four channels, and the vec4s from one plane to the next.
    pub feature_planes: Option<(BufferSlice<'a>, u32)>,
}

impl FrameSet {
    /// The counters of the set's last finished frame.
    pub(crate) fn counters(&self) -> GpuResult<Counters> {
        let f = self
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::Internal("no frame buffers for a finished frame".into()))?;
        let (_, _, off) = f.readback_offsets();
        let bytes = f
            .readback
            .mapped_range(off, std::mem::size_of::<Counters>() as u64)?;
        Ok(bytemuck::pod_read_unaligned(bytes))
    }

    /// What the set's last finished frame left for a backward pass.
    pub(crate) fn forward_state(&self) -> GpuResult<ForwardState<'_>> {
        let f = self
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("no frame was rendered yet".into()))?;
        let counters = self.counters()?;
        Ok(ForwardState {
            splats: f.splats.whole(),
            splat_texels: f.splat_texels.handle(),
            value_texels: f.value_texels.as_ref().map(|v| v.handle()),
            sorted_gaussians: f.values.whole(),
            sorted_bins: f.keys.whole(),
            pairs: counters.sort_count,
            ranges: f.ranges.whole(),
            bin_size: self.bin_size,
            bins: bin_grid(self.bin_size, f.width, f.height),
            color: &f.color,
            depth: &f.depth,
            params: f.params.whole(),
            last_contributor: match self.saves_last {
                true => f.last_contributor.as_ref().map(|b| b.whole()),
                false => None,
            },
            feature_planes: self
                .feature_planes
                .as_ref()
                .map(|p| (p.buffer.whole(), (p.plane_bytes / 16) as u32)),
        })
    }
}
