//! The original 3DGS training loss, `L = (1 - lambda) L1 + lambda (1 - SSIM)` with
//! `lambda = 0.2` (`train.py`: `(1.0 - opt.lambda_dssim) * Ll1 + opt.lambda_dssim * (1.0 -
//! ssim(image, gt_image))`), and its gradient with respect to the rendered image: on the
//! CPU in f64 ([`loss_reference`], the reference) and on the device ([`GpuLoss`]), whose
//! per-pixel gradient feeds the backward pass without leaving the device.
//!
//! L1 is the mean of `|x - y|` over every pixel and channel (its derivative at `x == y`
//! is 0, as torch's); SSIM is [`crate::io::metrics::ssim`] (11x11 Gaussian window, sigma 1.5,
//! zero padding, the mean over pixels and channels), differentiated as
//! [`crate::io::metrics::ssim_with_gradient`] documents.
//!
//! The device runs seven passes, each a dispatch with its barrier: the five quantities SSIM
//! compares (`ssim_prepare`), the window along x and y (`ssim_filter`), SSIM and its
//! derivatives per pixel (`ssim_map`), the window again (the adjoint), the gradient
//! (`ssim_grad`); the sums of |x - y| and SSIM are added in a fixed order
//! (`loss_reduce`), so the loss and its gradient are the same bits run after run, and only
//! the sums (|x - y|, SSIM, (x - y)^2: 16 bytes) are read back. On CPU devices the window
//! reads its source through texel views (the same bits; llvmpipe runs a storage-buffer load
//! in the tap loop as a scalar loop per lane).
//!
//! Masks ([`loss_reference_masked`], [`GpuLoss::stage_target_masked`]): the loss of a
//! masked view is the loss of the render with its masked pixels replaced by the photo's,
//! L1 and SSIM averaged over the kept pixels only (SSIM's windows still reach across the
//! mask's edge, where they see the photo); its gradient is zero at every masked pixel. On
//! the device a masked pixel's target has w = 1 (0 where kept, as without a mask).

mod photos;

use photos::{PendingTarget, PhotoStore};

use crate::core::shader_interface::{
    CountsPush, ImageRowsPush, LossGradPush, RecordLayout, SizePush,
};
use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::sync::{barrier, barrier_uses, Access};
use crate::gpu::{
    BufferSlice, BufferView, ComputePipeline, GpuBuffer, GpuContext, GpuError, GpuResult,
    MemoryKind,
};
use crate::train::appearance::device::AffinePasses;
use crate::train::shaders::bindings;

/// The original's weight of the D-SSIM term (`lambda_dssim`).
pub const LAMBDA_DSSIM: f32 = 0.2;

/// A loss and its parts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossValue {
    /// `(1 - lambda) l1 + lambda (1 - ssim)`.
    pub total: f64,
    /// Mean absolute error.
    pub l1: f64,
    /// Mean SSIM.
    pub ssim: f64,
    /// Mean squared error (of the render as it is, not clamped).
    pub mse: f64,
}

impl LossValue {
    fn of(l1: f64, ssim: f64, mse: f64, lambda: f64) -> Self {
        LossValue {
            total: (1.0 - lambda) * l1 + lambda * (1.0 - ssim),
            l1,
            ssim,
            mse,
        }
    }

    /// PSNR in dB of [`Self::mse`] (peak 1).
    pub fn psnr(&self) -> f64 {
        -10.0 * self.mse.max(1e-30).log10()
    }
}

/// The loss of `image` against `target` (`H x W x C`, pixel-major) and its gradient with
/// respect to `image`, in f64.
pub fn loss_reference(
    image: &[f64],
    target: &[f64],
    width: usize,
    height: usize,
    channels: usize,
    lambda: f64,
) -> (LossValue, Vec<f64>) {
    loss_reference_masked(image, target, None, width, height, channels, lambda)
}

/// [`loss_reference`] with the pixels where `keep` is false masked (`keep` one flag per
/// pixel): the loss of the image whose masked pixels are the target's, L1, SSIM and the
/// squared error averaged over the kept pixels (and channels), the gradient zero at the
/// masked pixels. `None` (or every pixel kept) is [`loss_reference`].
pub fn loss_reference_masked(
    image: &[f64],
    target: &[f64],
    keep: Option<&[bool]>,
    width: usize,
    height: usize,
    channels: usize,
    lambda: f64,
) -> (LossValue, Vec<f64>) {
    let kept = |i: usize| keep.map_or(true, |k| k[i / channels]);
    let replaced: Vec<f64>;
    let image = match keep {
        None => image,
        Some(_) => {
            replaced = (0..image.len())
                .map(|i| if kept(i) { image[i] } else { target[i] })
                .collect();
            &replaced
        }
    };
    let weights: Option<Vec<f64>> =
        keep.map(|k| k.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect());
    let n = match keep {
        None => image.len(),
        Some(k) => k.iter().filter(|&&b| b).count() * channels,
    }
    .max(1) as f64;
    let (ssim, g_ssim) = crate::io::metrics::ssim_with_gradient_weighted(
        image,
        target,
        width,
        height,
        channels,
        weights.as_deref(),
    );
    let l1 = image
        .iter()
        .zip(target)
        .map(|(a, b)| (a - b).abs())
        .sum::<f64>()
        / n;
    let mse = image
        .iter()
        .zip(target)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        / n;
    let grad = image
        .iter()
        .zip(target)
        .zip(&g_ssim)
        .enumerate()
        .map(|(i, ((a, b), gs))| {
            if !kept(i) {
                return 0.0;
            }
            let d = a - b;
            let sign = if d > 0.0 {
                1.0
            } else if d < 0.0 {
                -1.0
            } else {
                0.0
            };
            (1.0 - lambda) * sign / n - lambda * gs
        })
        .collect();
    (LossValue::of(l1, ssim, mse, lambda), grad)
}

/// Values a `loss_reduce` workgroup sums.
const REDUCE_SPAN: u64 = crate::gpu::shader_set::REDUCE_SPAN as u64;
/// Invocations per workgroup of the per-pixel passes.
const PIXEL_GROUP: u64 = crate::gpu::shader_set::LOSS_WG as u64;
/// Pixels one `ssim_filter` invocation filters, consecutive along its axis.
const FILTER_RUN: u64 = crate::gpu::shader_set::SSIM_FILTER_RUN as u64;

/// The buffers of one loss evaluation: the rendered image and the target (vec4 per pixel,
/// rgb), and the gradient written (vec4 per pixel, rgb; w 0).
pub struct LossBuffers<'a> {
    /// The rendered image.
    pub image: BufferSlice<'a>,
    /// The target image.
    pub target: BufferSlice<'a>,
    /// Out: dL/d(image).
    pub grad: BufferSlice<'a>,
}

/// The loss on the device: its pipelines and work buffers (grown as images need).
pub struct GpuLoss {
    prepare: ComputePipeline,
    filter: ComputePipeline,
    /// The window reading its source through texel views (CPU devices).
    filter_texel: Option<ComputePipeline>,
    /// RGBA32F views of the two plane buffers (`work`'s first two) for `filter_texel`;
    /// before `work`, so they are dropped first.
    views: Option<[BufferView; 2]>,
    map: ComputePipeline,
    grad: ComputePipeline,
    reduce: ComputePipeline,
    work: Option<(u64, [GpuBuffer; 5])>,
    io: Option<(u64, [GpuBuffer; 3])>,
    /// The next target as the loss reads it (a vec4 per pixel), written by the host into
    /// this upload buffer by [`Self::stage_target`] and copied to the device-local target
    /// by the submission that computes the loss (no submission of its own); kept from
    /// iteration to iteration.
    target_staging: Option<GpuBuffer>,
    /// The target staged and not yet copied, and where from.
    target_pending: Option<PendingTarget>,
    /// The training photos kept on the device ([`Self::keep_photos`]).
    photos: Option<PhotoStore>,
    /// The kept pixels of the staged target (all of them without a mask).
    target_kept: u64,
    /// Where [`Self::record_image`]'s submission copies its sums, so that
    /// [`Self::read_value`] needs no submission of its own.
    sums_readback: Option<GpuBuffer>,
    /// The work buffer the last loss left its sums in, its kept pixels' count and lambda, and
    /// whether its submission also copied them to `sums_readback`.
    last: Option<(ash::vk::Buffer, u64, f32, bool)>,
    /// The affine appearance's passes ([`Self::record_image_affine`]), built at its first
    /// use.
    affine: Option<AffinePasses>,
}

/// A pass's writes before the next one's reads (through buffers or texel views).
fn after_pass(ctx: &GpuContext, cmd: ash::vk::CommandBuffer) {
    barrier_uses(
        ctx,
        cmd,
        &[Access::ComputeWrite],
        &[Access::ComputeRead, Access::ComputeSampledRead],
    );
}

fn pixel_groups(ctx: &GpuContext, pixels: u64) -> GpuResult<[u32; 3]> {
    crate::gpu::limits::dispatch_groups(ctx.info(), "the loss", pixels.div_ceil(PIXEL_GROUP).max(1))
}

fn buffer(ctx: &GpuContext, name: &str, bytes: u64) -> GpuResult<GpuBuffer> {
    crate::gpu::limits::check_binding(
        ctx.info(),
        &format!("the {name}"),
        bytes,
        "use smaller images",
    )?;
    GpuBuffer::new(ctx, name, bytes.max(16), MemoryKind::Device)
}

impl GpuLoss {
    /// Builds the pipelines; on CPU devices the window reads through texel views.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        Self::with_texel_fetch(
            ctx,
            ctx.info().device_type == ash::vk::PhysicalDeviceType::CPU,
        )
    }

    /// [`Self::new`] with the window's texel-view reads on or off (both give the same
    /// bits; the view is faster on llvmpipe).
    pub fn with_texel_fetch(ctx: &GpuContext, texel: bool) -> GpuResult<Self> {
        let s = BindingKind::StorageBuffer;
        let build = |name: &str, kinds: &[BindingKind], push: &RecordLayout| {
            ComputePipeline::from_embedded(ctx, name, &[], kinds, push)
        };
        use bindings::{loss_reduce, ssim_filter, ssim_grad, ssim_map, ssim_prepare};
        Ok(GpuLoss {
            prepare: build(
                "ssim_prepare",
                &by_binding([
                    (ssim_prepare::IMAGE, s),
                    (ssim_prepare::TARGET, s),
                    (ssim_prepare::PLANES, s),
                ])?,
                &SizePush::LAYOUT,
            )?,
            filter: ComputePipeline::from_embedded(
                ctx,
                "ssim_filter",
                &[("TEXEL_FETCH", "0".into())],
                &by_binding([(ssim_filter::SRC, s), (ssim_filter::DST, s)])?,
                &ImageRowsPush::LAYOUT,
            )?,
            filter_texel: if texel {
                Some(ComputePipeline::from_embedded(
                    ctx,
                    "ssim_filter",
                    &[("TEXEL_FETCH", "1".into())],
                    &by_binding([
                        (ssim_filter::SRC, BindingKind::UniformTexelBuffer),
                        (ssim_filter::DST, s),
                    ])?,
                    &ImageRowsPush::LAYOUT,
                )?)
            } else {
                None
            },
            views: None,
            map: build(
                "ssim_map",
                &by_binding([
                    (ssim_map::MOMENTS, s),
                    (ssim_map::IMAGE, s),
                    (ssim_map::TARGET, s),
                    (ssim_map::MAPS, s),
                    (ssim_map::SUMS, s),
                ])?,
                &SizePush::LAYOUT,
            )?,
            grad: build(
                "ssim_grad",
                &by_binding([
                    (ssim_grad::FILTERED, s),
                    (ssim_grad::IMAGE, s),
                    (ssim_grad::TARGET, s),
                    (ssim_grad::GRAD, s),
                ])?,
                &LossGradPush::LAYOUT,
            )?,
            reduce: build(
                "loss_reduce",
                &by_binding([(loss_reduce::VALUES, s), (loss_reduce::SUMS, s)])?,
                &CountsPush::LAYOUT,
            )?,
            work: None,
            io: None,
            target_staging: None,
            target_pending: None,
            photos: None,
            target_kept: 0,
            sums_readback: None,
            last: None,
            affine: None,
        })
    }

    /// Device bytes of the work buffers (the appearance's too).
    pub fn device_bytes(&self) -> u64 {
        let work = self
            .work
            .as_ref()
            .map_or(0, |(_, b)| b.iter().map(|b| b.size()).sum());
        let io = self
            .io
            .as_ref()
            .map_or(0, |(_, b)| b.iter().map(|b| b.size()).sum());
        let affine = self.affine.as_ref().map_or(0, AffinePasses::device_bytes);
        work + io + affine
    }

    fn ensure_work(&mut self, ctx: &GpuContext, pixels: u64) -> GpuResult<()> {
        if self.work.as_ref().is_some_and(|(p, _)| *p >= pixels) {
            return Ok(());
        }
        self.views = None;
        self.work = None;
        let sums = pixels.div_ceil(REDUCE_SPAN).max(1);
        self.work = Some((
            pixels,
            [
                buffer(ctx, "loss planes", pixels * 5 * 16)?,
                buffer(ctx, "loss filtered planes", pixels * 5 * 16)?,
                buffer(ctx, "loss per-pixel sums", pixels * 16)?,
                buffer(ctx, "loss partial sums", sums * 16)?,
                buffer(ctx, "loss partial sums (2)", sums * 16)?,
            ],
        ));
        // Texel views where the device addresses that many texels (else the buffers).
        let texels = pixels * 5;
        if self.filter_texel.is_some() && texels <= u64::from(ctx.info().max_texel_buffer_elements)
        {
            let (_, [planes, filtered, ..]) = self.work.as_ref().expect("made above");
            let view = |b: &GpuBuffer| {
                BufferView::new(ctx, b, ash::vk::Format::R32G32B32A32_SFLOAT, 0, texels * 16)
            };
            self.views = Some([view(planes)?, view(filtered)?]);
        }
        Ok(())
    }

    /// Records the loss of `bufs.image` against `bufs.target` (`width x height`) and its
    /// gradient into `bufs.grad`; the two sums (|x - y| and SSIM over every pixel and
    /// channel) end in the returned buffer's first 8 bytes. The caller orders the inputs'
    /// writes before and the outputs' reads after.
    pub fn record(
        &mut self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        bufs: &LossBuffers,
        width: u32,
        height: u32,
        lambda: f32,
    ) -> GpuResult<&GpuBuffer> {
        let pixels = u64::from(width) * u64::from(height);
        self.record_kept(ctx, cmd, bufs, (width, height), pixels, lambda)
    }

    /// [`Self::record`] of a target whose masked pixels (w 1) are not counted: the means
    /// are over `kept` pixels.
    fn record_kept(
        &mut self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        bufs: &LossBuffers,
        (width, height): (u32, u32),
        kept: u64,
        lambda: f32,
    ) -> GpuResult<&GpuBuffer> {
        let pixels = u64::from(width) * u64::from(height);
        if pixels == 0 {
            return Err(GpuError::InvalidArgument(
                "an empty image has no loss".into(),
            ));
        }
        for (name, b) in [
            ("image", &bufs.image),
            ("target", &bufs.target),
            ("gradient", &bufs.grad),
        ] {
            if b.size < pixels * 16 {
                return Err(GpuError::InvalidArgument(format!(
                    "the {name} buffer holds {} bytes, a {width}x{height} image needs {}",
                    b.size,
                    pixels * 16
                )));
            }
        }
        self.ensure_work(ctx, pixels)?;
        let (_, [planes, filtered, sums, _, _]) = self.work.as_ref().expect("made above");
        let groups = pixel_groups(ctx, pixels)?;
        let size = SizePush {
            size: [width, height, 0, 0],
        };
        let taps64 = crate::io::metrics::ssim_taps();
        let mut taps = [[0f32; 4]; 3];
        for (k, t) in taps64.iter().enumerate() {
            taps[k / 4][k % 4] = *t as f32;
        }
        self.prepare.dispatch(
            ctx,
            cmd,
            &[bufs.image, bufs.target, planes.whole()],
            bytemuck::bytes_of(&size),
            groups,
        )?;
        after_pass(ctx, cmd);
        // The window over the planes, then over the derivative maps: x, then y.
        // The view of a plane buffer, when the window reads through views.
        let view_of = |b: &GpuBuffer| -> Option<ash::vk::BufferView> {
            let views = self.views.as_ref()?;
            let i = if std::ptr::eq(b, planes) { 0 } else { 1 };
            Some(views[i].handle())
        };
        // The window's invocations: runs of FILTER_RUN pixels along x, then along y.
        let (w, h) = (u64::from(width), u64::from(height));
        let filter_groups = [
            pixel_groups(ctx, w.div_ceil(FILTER_RUN) * h)?,
            pixel_groups(ctx, h.div_ceil(FILTER_RUN) * w)?,
        ];
        let filter = |cmd, src: &GpuBuffer, dst: &GpuBuffer, vecs: u32| -> GpuResult<()> {
            for (axis, (a, b)) in [(0u32, (src, dst)), (1u32, (dst, src))] {
                let groups = filter_groups[axis as usize];
                let push = ImageRowsPush {
                    size: [width, height, vecs, axis],
                    rows: taps,
                };
                match (&self.filter_texel, view_of(a)) {
                    (Some(pipeline), Some(view)) => pipeline.dispatch_resources(
                        ctx,
                        cmd,
                        &[Resource::TexelBuffer(view), Resource::Buffer(b.whole())],
                        bytemuck::bytes_of(&push),
                        groups,
                    )?,
                    _ => self.filter.dispatch(
                        ctx,
                        cmd,
                        &[a.whole(), b.whole()],
                        bytemuck::bytes_of(&push),
                        groups,
                    )?,
                }
                after_pass(ctx, cmd);
            }
            Ok(())
        };
        // planes -> filtered (x) -> planes (y): the moments end in `planes`.
        filter(cmd, planes, filtered, 5)?;
        self.map.dispatch(
            ctx,
            cmd,
            &[
                planes.whole(),
                bufs.image,
                bufs.target,
                filtered.whole(),
                sums.whole(),
            ],
            bytemuck::bytes_of(&size),
            groups,
        )?;
        after_pass(ctx, cmd);
        // filtered (the maps) -> planes (x) -> filtered (y).
        filter(cmd, filtered, planes, 3)?;
        let n = (kept.max(1) * 3) as f32;
        let push = LossGradPush {
            size: size.size,
            scale: [(1.0 - lambda) / n, lambda / n, 0.0, 0.0],
        };
        self.grad.dispatch(
            ctx,
            cmd,
            &[filtered.whole(), bufs.image, bufs.target, bufs.grad],
            bytemuck::bytes_of(&push),
            groups,
        )?;
        self.record_sums(ctx, cmd, pixels)
    }

    /// The per-pixel sums added up, 4096 to one per pass, into one vec4 of the buffer
    /// returned; each pass's writes before the next one's reads.
    fn record_sums(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        pixels: u64,
    ) -> GpuResult<&GpuBuffer> {
        let (_, [_, _, sums, part_a, part_b]) = self.work.as_ref().expect("made by record");
        let mut count = pixels;
        let mut src = sums;
        let mut dst = part_a;
        loop {
            let out = count.div_ceil(REDUCE_SPAN);
            // One row of workgroups (the shader reads gl_WorkGroupID.x only).
            crate::gpu::limits::check_dispatch(
                ctx.info(),
                "the loss's reduction",
                [out as u32, 1, 1],
            )?;
            self.reduce.dispatch(
                ctx,
                cmd,
                &[src.whole(), dst.whole()],
                bytemuck::bytes_of(&CountsPush {
                    counts: [count as u32, 0, 0, 0],
                }),
                [out as u32, 1, 1],
            )?;
            after_pass(ctx, cmd);
            if out == 1 {
                return Ok(dst);
            }
            count = out;
            src = dst;
            dst = if std::ptr::eq(dst, part_a) {
                part_b
            } else {
                part_a
            };
        }
    }

    fn ensure_io(&mut self, ctx: &GpuContext, pixels: u64) -> GpuResult<()> {
        if !self.io.as_ref().is_some_and(|(p, _)| *p >= pixels) {
            self.io = None;
            self.io = Some((
                pixels,
                [
                    buffer(ctx, "loss image", pixels * 16)?,
                    buffer(ctx, "loss target", pixels * 16)?,
                    buffer(ctx, "loss gradient", pixels * 16)?,
                ],
            ));
        }
        Ok(())
    }

    /// Stages the target image (RGB, pixel-major) of the next [`Self::record_image`] (or
    /// [`Self::compute`]): written as vec4s straight into a kept upload buffer; the
    /// submission that computes the loss copies it to the device first. (Each iteration
    /// had allocated a staging buffer, converted into a vector, copied that and waited for
    /// a submission of its own.)
    pub fn stage_target(&mut self, ctx: &GpuContext, target: &[[f32; 3]]) -> GpuResult<()> {
        self.stage_target_masked(ctx, target, None)
    }

    /// [`Self::stage_target`] with the pixels where `keep` (one flag per pixel) is false
    /// masked: they add nothing to the loss and get no gradient; the means are over the
    /// kept pixels. `None`: every pixel kept.
    pub fn stage_target_masked(
        &mut self,
        ctx: &GpuContext,
        target: &[[f32; 3]],
        keep: Option<&[bool]>,
    ) -> GpuResult<()> {
        let pixels = target.len() as u64;
        if keep.is_some_and(|k| k.len() != target.len()) {
            return Err(GpuError::InvalidArgument(format!(
                "the mask has {} pixels, the target {pixels}",
                keep.map_or(0, <[bool]>::len)
            )));
        }
        self.ensure_io(ctx, pixels)?;
        let bytes = pixels * 16;
        if !self
            .target_staging
            .as_ref()
            .is_some_and(|b| b.size() >= bytes)
        {
            self.target_staging = None;
            self.target_staging = Some(GpuBuffer::new(
                ctx,
                "loss target (staging)",
                bytes.max(16),
                crate::gpu::MemoryKind::Upload,
            )?);
        }
        let staging = self.target_staging.as_mut().expect("made above");
        staging.write_mapped_with(bytes, |dst| {
            let dst: &mut [[f32; 4]] = bytemuck::cast_slice_mut(dst);
            for (d, c) in dst.iter_mut().zip(target) {
                *d = [c[0], c[1], c[2], 0.0];
            }
            if let Some(keep) = keep {
                for (d, k) in dst.iter_mut().zip(keep) {
                    d[3] = if *k { 0.0 } else { 1.0 };
                }
            }
        })?;
        self.target_pending = Some(PendingTarget::Staged {
            bytes,
            keep_at: None,
        });
        self.target_kept = keep.map_or(pixels, |k| k.iter().filter(|&&b| b).count() as u64);
        Ok(())
    }

    /// Records the loss of a rendered colour image (RGBA32F, `width x height`, a copy
    /// source: a frame rendered with [`crate::render::Readback::Counters`]) against the target staged
    /// by [`Self::stage_target`], its gradient into `grad` (a vec4 per pixel: rgb, alpha
    /// 0). After the submission, [`Self::read_value`] reads the loss.
    #[allow(clippy::too_many_arguments)]
    pub fn record_image(
        &mut self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        image: &crate::gpu::GpuImage,
        grad: BufferSlice,
        width: u32,
        height: u32,
        lambda: f32,
    ) -> GpuResult<()> {
        self.record_image_with(ctx, cmd, image, grad, (width, height), lambda, None)
    }

    /// [`Self::record_image`] of the photo's affine appearance `rows` (row r of `[A | b]`,
    /// [`crate::train::appearance`]): the loss is that of `A c + b` (c the rendered pixel,
    /// background included), `grad` ends as the render's gradient (`A^T` times the
    /// loss's) and, after the submission, [`Self::read_affine_grads`] reads the
    /// transform's.
    #[allow(clippy::too_many_arguments)]
    pub fn record_image_affine(
        &mut self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        image: &crate::gpu::GpuImage,
        grad: BufferSlice,
        width: u32,
        height: u32,
        lambda: f32,
        rows: &[[f32; 4]; 3],
    ) -> GpuResult<()> {
        self.ensure_affine(ctx)?;
        self.record_image_with(ctx, cmd, image, grad, (width, height), lambda, Some(rows))
    }

    /// Builds the appearance's passes the first time a photo's transform is recorded.
    fn ensure_affine(&mut self, ctx: &GpuContext) -> GpuResult<()> {
        if self.affine.is_none() {
            self.affine = Some(AffinePasses::new(ctx)?);
        }
        Ok(())
    }

    /// The affine appearance's 12 gradients (row r of `[A | b]` at `4 r..4 r + 4`) of the
    /// last [`Self::record_image_affine`] (or [`Self::compute_affine`]), once its
    /// submission has finished.
    pub fn read_affine_grads(&self) -> GpuResult<[f64; 12]> {
        self.affine
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("no appearance was recorded".into()))?
            .read_grads()
    }

    /// [`Self::record_image`], through the appearance's passes with `rows`.
    #[allow(clippy::too_many_arguments)]
    fn record_image_with(
        &mut self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        image: &crate::gpu::GpuImage,
        grad: BufferSlice,
        (width, height): (u32, u32),
        lambda: f32,
        rows: Option<&[[f32; 4]; 3]>,
    ) -> GpuResult<()> {
        let pixels = u64::from(width) * u64::from(height);
        if image.size() != (width, height) {
            return Err(GpuError::InvalidArgument(format!(
                "the image is {}x{}, the loss {width}x{height}",
                image.size().0,
                image.size().1
            )));
        }
        if !self.io.as_ref().is_some_and(|(p, _)| *p >= pixels) {
            return Err(GpuError::InvalidArgument(
                "no target staged for this image size (stage_target)".into(),
            ));
        }
        let io = self.io.take().expect("checked above");
        let mut affine = self.affine.take();
        let result = (|| {
            let [img, tgt, _] = &io.1;
            image.copy_to_buffer(ctx, cmd, img, 0);
            self.record_target_copy(ctx, cmd, tgt);
            barrier(ctx, cmd, Access::TransferWrite, Access::ComputeRead);
            let passes = match (rows, affine.as_mut()) {
                (Some(rows), Some(passes)) => {
                    passes.ensure(ctx, pixels)?;
                    passes.record_apply(ctx, cmd, img.whole(), (width, height), rows)?;
                    Some((passes, rows))
                }
                _ => None,
            };
            let bufs = LossBuffers {
                image: match &passes {
                    Some((p, _)) => p.corrected()?,
                    None => img.whole(),
                },
                target: tgt.whole(),
                grad,
            };
            let kept = self.target_kept;
            let sums = self
                .record_kept(ctx, cmd, &bufs, (width, height), kept, lambda)?
                .handle();
            if let Some((p, rows)) = passes {
                p.record_grad(ctx, cmd, img.whole(), grad, (width, height), rows)?;
            }
            // The sums to host-visible memory in this submission (16 bytes).
            if self.sums_readback.is_none() {
                self.sums_readback = Some(GpuBuffer::new(
                    ctx,
                    "loss sums (read-back)",
                    16,
                    crate::gpu::MemoryKind::Readback,
                )?);
            }
            let readback = self.sums_readback.as_ref().expect("made above");
            barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
            let region = [ash::vk::BufferCopy::default().size(16)];
            // SAFETY: both buffers are alive; the sums are the first 16 bytes of theirs.
            unsafe {
                ctx.device()
                    .cmd_copy_buffer(cmd, sums, readback.handle(), &region)
            };
            barrier(ctx, cmd, Access::TransferWrite, Access::HostRead);
            self.last = Some((sums, kept, lambda, true));
            Ok(())
        })();
        self.io = Some(io);
        self.affine = affine;
        result
    }

    /// The loss of the last [`Self::record_image`] (or [`Self::compute`]), once its
    /// submission has finished.
    pub fn read_value(&self, ctx: &GpuContext) -> GpuResult<LossValue> {
        let (handle, kept, lambda, copied) = self
            .last
            .ok_or_else(|| GpuError::InvalidArgument("no loss was recorded".into()))?;
        let (_, work) = self
            .work
            .as_ref()
            .ok_or_else(|| GpuError::Internal("no loss work buffers".into()))?;
        let b = work
            .iter()
            .find(|b| b.handle() == handle)
            .ok_or_else(|| GpuError::Internal("the loss sums buffer is gone".into()))?;
        let sums: Vec<[f32; 4]> = match (&self.sums_readback, copied) {
            // Copied by the submission that computed them (record_image).
            (Some(r), true) => bytemuck::pod_collect_to_vec(r.mapped_range(0, 16)?),
            _ => b.read(ctx, 1)?,
        };
        let n = (kept.max(1) * 3) as f64;
        Ok(LossValue::of(
            sums[0][0] as f64 / n,
            sums[0][1] as f64 / n,
            sums[0][2] as f64 / n,
            lambda as f64,
        ))
    }

    /// The loss of `image` against `target` (`width x height`, RGB, pixel-major; only the
    /// first three channels of each pixel are read) and its gradient, through the device:
    /// uploads both, runs [`Self::record`], reads back the gradient (`width * height * 3`)
    /// and the two sums.
    pub fn compute(
        &mut self,
        ctx: &GpuContext,
        image: &[[f32; 3]],
        target: &[[f32; 3]],
        width: u32,
        height: u32,
        lambda: f32,
    ) -> GpuResult<(LossValue, Vec<[f32; 3]>)> {
        self.compute_masked(ctx, image, target, None, width, height, lambda)
    }

    /// [`Self::compute`] with the pixels where `keep` is false masked
    /// ([`Self::stage_target_masked`]).
    #[allow(clippy::too_many_arguments)]
    pub fn compute_masked(
        &mut self,
        ctx: &GpuContext,
        image: &[[f32; 3]],
        target: &[[f32; 3]],
        keep: Option<&[bool]>,
        width: u32,
        height: u32,
        lambda: f32,
    ) -> GpuResult<(LossValue, Vec<[f32; 3]>)> {
        self.compute_with(ctx, image, target, keep, (width, height), lambda, None)
            .map(|(value, grad, _)| (value, grad))
    }

    /// [`Self::compute_masked`] through the affine appearance `rows` (row r of `[A | b]`,
    /// as [`Self::record_image_affine`]): the loss of `A image + b`, the gradient with
    /// respect to `image` (`A^T` times the loss's) and the transform's 12 gradients.
    #[allow(clippy::too_many_arguments)]
    pub fn compute_affine(
        &mut self,
        ctx: &GpuContext,
        image: &[[f32; 3]],
        target: &[[f32; 3]],
        keep: Option<&[bool]>,
        width: u32,
        height: u32,
        lambda: f32,
        rows: &[[f32; 4]; 3],
    ) -> GpuResult<(LossValue, Vec<[f32; 3]>, [f64; 12])> {
        self.ensure_affine(ctx)?;
        let (value, grad, affine) = self.compute_with(
            ctx,
            image,
            target,
            keep,
            (width, height),
            lambda,
            Some(rows),
        )?;
        Ok((value, grad, affine.expect("the passes ran")))
    }

    /// [`Self::compute_masked`], through the appearance's passes with `rows`.
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn compute_with(
        &mut self,
        ctx: &GpuContext,
        image: &[[f32; 3]],
        target: &[[f32; 3]],
        keep: Option<&[bool]>,
        (width, height): (u32, u32),
        lambda: f32,
        rows: Option<&[[f32; 4]; 3]>,
    ) -> GpuResult<(LossValue, Vec<[f32; 3]>, Option<[f64; 12]>)> {
        let pixels = u64::from(width) * u64::from(height);
        if image.len() as u64 != pixels || target.len() as u64 != pixels {
            return Err(GpuError::InvalidArgument(format!(
                "the image has {} pixels and the target {}, a {width}x{height} image {pixels}",
                image.len(),
                target.len()
            )));
        }
        self.stage_target_masked(ctx, target, keep)?;
        let kept = self.target_kept;
        let io = self.io.take().expect("made by stage_target");
        // The passes, taken while the closure borrows `self` (put back below).
        let mut affine = if rows.is_some() {
            self.affine.take()
        } else {
            None
        };
        let result = (|| {
            let [img, tgt, grad] = &io.1;
            let wide: Vec<[f32; 4]> = image.iter().map(|c| [c[0], c[1], c[2], 0.0]).collect();
            img.upload(ctx, &wide)?;
            if let Some(p) = affine.as_mut() {
                p.ensure(ctx, pixels)?;
            }
            let mut sums = None;
            ctx.submit_and_wait("loss", |cmd| {
                self.record_target_copy(ctx, cmd, tgt);
                barrier(ctx, cmd, Access::Any, Access::Any);
                let passes = affine.as_mut().zip(rows);
                if let Some((p, rows)) = &passes {
                    p.record_apply(ctx, cmd, img.whole(), (width, height), rows)?;
                }
                let bufs = LossBuffers {
                    image: match &passes {
                        Some((p, _)) => p.corrected()?,
                        None => img.whole(),
                    },
                    target: tgt.whole(),
                    grad: grad.whole(),
                };
                sums = Some(
                    self.record_kept(ctx, cmd, &bufs, (width, height), kept, lambda)?
                        .handle(),
                );
                if let Some((p, rows)) = passes {
                    p.record_grad(ctx, cmd, img.whole(), grad.whole(), (width, height), rows)?;
                }
                barrier(ctx, cmd, Access::ComputeWrite, Access::Any);
                Ok(())
            })?;
            self.last = sums.map(|h| (h, kept, lambda, false));
            let value = self.read_value(ctx)?;
            let g: Vec<[f32; 4]> = grad.read(ctx, pixels as usize)?;
            let affine_grads = match &affine {
                Some(p) => Some(p.read_grads()?),
                None => None,
            };
            Ok((
                value,
                g.iter().map(|v| [v[0], v[1], v[2]]).collect(),
                affine_grads,
            ))
        })();
        self.io = Some(io);
        if affine.is_some() {
            self.affine = affine;
        }
        result
    }
}
