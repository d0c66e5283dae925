//! Blend backward stage (`glsl/blend_bwd.comp`): one workgroup per bin walks the bin's
//! sorted pairs back to front with the forward's saved per-pixel state and writes, per
//! pair, the bin's summed gradient with respect to the pair's Gaussian (2D mean, conic,
//! opacity, colour, depth, |2D mean|), plus the largest |sum| per field.

use crate::gpu::shader::{by_binding, BindingKind};
use crate::gpu::shader_set::bindings::blend_bwd as slot;
use crate::gpu::shader_set::{GRAD_FIELDS, GRAD_SPEC_MAX_SUBGROUPS};
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuError, GpuResult};
use crate::model::SplatKernel;
use ash::vk;

/// Pairs the shader stages in shared memory at a time (`BATCH` in the shader).
const BATCH: u32 = 16;

/// The blend-backward pipeline for one bin size and kernel.
pub struct BlendBwd {
    pipeline: ComputePipeline,
    bin: u32,
}

impl BlendBwd {
    /// Builds the pipeline for `bin`-pixel bins (8 or 16) and `kernel`. Its shared memory
    /// holds one partial sum per subgroup, pair of a batch and field: the device's
    /// smallest subgroup size decides how many subgroups a workgroup can have.
    pub fn new(ctx: &GpuContext, bin: u32, kernel: SplatKernel) -> GpuResult<Self> {
        if bin != 8 && bin != 16 {
            return Err(GpuError::InvalidArgument(format!(
                "the blend backward runs on 8- or 16-pixel bins, not {bin}"
            )));
        }
        let info = ctx.info();
        let invocations = bin * bin;
        let max_subgroups = invocations.div_ceil(info.min_subgroup_size.max(1));
        let shared = 4 * (BATCH * 12 + BATCH * max_subgroups * GRAD_FIELDS + 1 + GRAD_FIELDS);
        if shared > info.max_shared_memory {
            return Err(GpuError::DeviceLimit {
                limit: "maxComputeSharedMemorySize",
                needed: u64::from(shared),
                max: u64::from(info.max_shared_memory),
                message: format!(
                    "the blend backward of {bin}-pixel bins needs {shared} bytes of shared memory \
                     for {max_subgroups} subgroups"
                ),
            });
        }
        let storage = BindingKind::StorageBuffer;
        let pipeline = ComputePipeline::from_embedded_specialized(
            ctx,
            "blend_bwd",
            &[
                ("BIN", format!("{bin}u")),
                ("SPLAT_KERNEL", format!("{}u", kernel.shader_id())),
            ],
            &by_binding([
                (slot::PARAMS, storage),
                (slot::SPLATS, storage),
                (slot::VALUES, storage),
                (slot::RANGES, storage),
                (slot::LAST, storage),
                (slot::GRAD_COLOR, storage),
                (slot::GRAD_DEPTH, storage),
                (slot::PAIR_GRADS, storage),
                (slot::MAXIMA, storage),
            ])?,
            0,
            invocations,
            &[(GRAD_SPEC_MAX_SUBGROUPS, max_subgroups)],
        )?;
        Ok(BlendBwd { pipeline, bin })
    }

    /// Bin side in pixels.
    pub fn bin(&self) -> u32 {
        self.bin
    }

    /// Records the dispatch over the `bins` grid.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        bins: (u32, u32),
        params: BufferSlice,
        splats: BufferSlice,
        values: BufferSlice,
        ranges: BufferSlice,
        last: BufferSlice,
        grad_color: BufferSlice,
        grad_depth: BufferSlice,
        pair_grads: BufferSlice,
        maxima: BufferSlice,
    ) -> GpuResult<()> {
        let buffers = by_binding([
            (slot::PARAMS, params),
            (slot::SPLATS, splats),
            (slot::VALUES, values),
            (slot::RANGES, ranges),
            (slot::LAST, last),
            (slot::GRAD_COLOR, grad_color),
            (slot::GRAD_DEPTH, grad_depth),
            (slot::PAIR_GRADS, pair_grads),
            (slot::MAXIMA, maxima),
        ])?;
        let max = ctx.info().max_workgroup_count;
        if bins.0 > max[0] || bins.1 > max[1] {
            return Err(GpuError::DeviceLimit {
                limit: "maxComputeWorkGroupCount",
                needed: u64::from(bins.0.max(bins.1)),
                max: u64::from(max[0].min(max[1])),
                message: format!("{}x{} bins exceed the dispatch limits", bins.0, bins.1),
            });
        }
        self.pipeline
            .dispatch(ctx, cmd, &buffers, &[], [bins.0, bins.1, 1])
    }
}
