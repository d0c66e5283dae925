//! The affine appearance on the device: two passes recorded into the loss's submission
//! ([`crate::train::loss::GpuLoss::record_image_affine`]). `appearance_apply` writes the
//! transformed image (`A c + b`) into a buffer of its own, which the loss reads;
//! `appearance_grad`, after the loss's gradient, turns the pixels' gradients into the
//! render's (`A^T g`, in place) and writes per-workgroup partial sums of the transform's
//! 12 gradients (a fixed-shape tree in shared memory, so the same bits at every subgroup
//! size); the submission copies them to host-visible memory and [`AffinePasses::read_grads`]
//! adds them in f64, in workgroup order.

use crate::core::shader_interface::ImageRowsPush;
use crate::gpu::shader::{by_binding, BindingKind};
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{BufferSlice, ComputePipeline, GpuBuffer, GpuContext, GpuError, GpuResult};
use crate::train::shaders::bindings;

/// Pixels one `appearance_grad` workgroup sums.
const SPAN: u64 = crate::gpu::shader_set::APPEARANCE_SPAN as u64;
/// Invocations per workgroup of `appearance_apply` (`loss_common.glsl`'s).
const PIXEL_GROUP: u64 = crate::gpu::shader_set::LOSS_WG as u64;

/// The two passes and their buffers (grown as images need).
pub struct AffinePasses {
    apply: ComputePipeline,
    grad: ComputePipeline,
    /// Pixels the buffers hold, the transformed image, the partial sums (3 vec4s per
    /// workgroup) and their host-visible copy.
    bufs: Option<(u64, [GpuBuffer; 3])>,
    /// Workgroups of the last gradient pass recorded (whose partials the read-back holds
    /// once its submission has finished).
    groups: Option<u64>,
}

/// The push block of a `width x height` image and the transform's rows.
fn push(width: u32, height: u32, rows: &[[f32; 4]; 3]) -> ImageRowsPush {
    ImageRowsPush {
        size: [width, height, 0, 0],
        rows: *rows,
    }
}

impl AffinePasses {
    /// Builds the pipelines.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let s = BindingKind::StorageBuffer;
        use bindings::{appearance_apply as ap, appearance_grad as gr};
        Ok(AffinePasses {
            apply: ComputePipeline::from_embedded(
                ctx,
                "appearance_apply",
                &[],
                &by_binding([(ap::IMAGE, s), (ap::CORRECTED, s)])?,
                &ImageRowsPush::LAYOUT,
            )?,
            grad: ComputePipeline::from_embedded(
                ctx,
                "appearance_grad",
                &[],
                &by_binding([(gr::IMAGE, s), (gr::GRAD, s), (gr::PARTIALS, s)])?,
                &ImageRowsPush::LAYOUT,
            )?,
            bufs: None,
            groups: None,
        })
    }

    /// Makes the buffers hold a `pixels` image.
    pub(crate) fn ensure(&mut self, ctx: &GpuContext, pixels: u64) -> GpuResult<()> {
        if self.bufs.as_ref().is_some_and(|(p, _)| *p >= pixels) {
            return Ok(());
        }
        self.bufs = None;
        let groups = pixels.div_ceil(SPAN).max(1);
        crate::gpu::limits::check_binding(
            ctx.info(),
            "the appearance's transformed image",
            pixels * 16,
            "use smaller images",
        )?;
        use crate::gpu::MemoryKind;
        self.bufs = Some((
            pixels,
            [
                GpuBuffer::new(
                    ctx,
                    "appearance image",
                    (pixels * 16).max(16),
                    MemoryKind::Device,
                )?,
                GpuBuffer::new(ctx, "appearance partials", groups * 48, MemoryKind::Device)?,
                GpuBuffer::new(
                    ctx,
                    "appearance partials (read-back)",
                    groups * 48,
                    MemoryKind::Readback,
                )?,
            ],
        ));
        Ok(())
    }

    /// Device bytes of the buffers (the read-back copy too).
    pub fn device_bytes(&self) -> u64 {
        self.bufs
            .as_ref()
            .map_or(0, |(_, b)| b.iter().map(GpuBuffer::size).sum())
    }

    fn buffers(&self) -> GpuResult<&[GpuBuffer; 3]> {
        self.bufs
            .as_ref()
            .map(|(_, b)| b)
            .ok_or_else(|| GpuError::Internal("the appearance's buffers were not made".into()))
    }

    /// The transformed image of the last [`Self::record_apply`] (a vec4 per pixel).
    pub(crate) fn corrected(&self) -> GpuResult<BufferSlice<'_>> {
        Ok(self.buffers()?[0].whole())
    }

    /// Records `A c + b` of `image` (a vec4 per pixel, `width x height`) into
    /// [`Self::corrected`] (alpha kept), and the barrier before the loss reads it.
    pub(crate) fn record_apply(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        image: BufferSlice,
        (width, height): (u32, u32),
        rows: &[[f32; 4]; 3],
    ) -> GpuResult<()> {
        let pixels = u64::from(width) * u64::from(height);
        let groups = crate::gpu::limits::dispatch_groups(
            ctx.info(),
            "the appearance",
            pixels.div_ceil(PIXEL_GROUP).max(1),
        )?;
        self.apply.dispatch(
            ctx,
            cmd,
            &[image, self.corrected()?],
            bytemuck::bytes_of(&push(width, height, rows)),
            groups,
        )?;
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
        Ok(())
    }

    /// Records the backward: `grad` (the loss's, a vec4 per pixel) becomes `A^T grad` in
    /// place, the transform's gradients' partial sums go to the read-back buffer; the
    /// gradient is visible to the compute passes after it and the partials to the host.
    pub(crate) fn record_grad(
        &mut self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        image: BufferSlice,
        grad: BufferSlice,
        (width, height): (u32, u32),
        rows: &[[f32; 4]; 3],
    ) -> GpuResult<()> {
        let pixels = u64::from(width) * u64::from(height);
        let groups = pixels.div_ceil(SPAN).max(1);
        crate::gpu::limits::check_dispatch(
            ctx.info(),
            "the appearance's gradient",
            [groups as u32, 1, 1],
        )?;
        let [_, partials, readback] = self.buffers()?;
        self.grad.dispatch(
            ctx,
            cmd,
            &[image, grad, partials.whole()],
            bytemuck::bytes_of(&push(width, height, rows)),
            [groups as u32, 1, 1],
        )?;
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeReadWrite);
        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
        let region = [ash::vk::BufferCopy::default().size(groups * 48)];
        // SAFETY: both buffers are alive and hold `groups` partials (made by `ensure`).
        unsafe {
            ctx.device()
                .cmd_copy_buffer(cmd, partials.handle(), readback.handle(), &region)
        };
        barrier(ctx, cmd, Access::TransferWrite, Access::HostRead);
        self.groups = Some(groups);
        Ok(())
    }

    /// The transform's 12 gradients of the last [`Self::record_grad`] (row r of `[A | b]`
    /// at `4 r..4 r + 4`), once its submission has finished: the workgroups' partials
    /// added in f64, in order.
    pub fn read_grads(&self) -> GpuResult<[f64; 12]> {
        let groups = self.groups.ok_or_else(|| {
            GpuError::InvalidArgument("no appearance gradient was recorded".into())
        })?;
        let [_, _, readback] = self.buffers()?;
        let partials: Vec<[f32; 4]> =
            bytemuck::pod_collect_to_vec(readback.mapped_range(0, groups * 48)?);
        let mut sums = [0f64; 12];
        for group in partials.chunks_exact(3) {
            for (r, row) in group.iter().enumerate() {
                for (k, v) in row.iter().enumerate() {
                    sums[4 * r + k] += f64::from(*v);
                }
            }
        }
        Ok(sums)
    }
}
