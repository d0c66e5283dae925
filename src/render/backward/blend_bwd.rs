//! Blend backward stage (`glsl/render/backward/blend_bwd.comp`): one workgroup per bin walks the bin's
//! sorted pairs back to front with the forward's saved per-pixel state and writes, per
//! pair, the bin's summed gradient with respect to the pair's Gaussian (2D mean, conic,
//! opacity, colour, depth, |2D mean|), plus the largest |sum| per field.

use crate::core::shader_interface::CountsPush;
use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::shader_set::{
    GRAD_FIELDS, GRAD_SPEC_BATCH, GRAD_SPEC_MAX_SUBGROUPS, GRAD_SPEC_ROWS_SUBGROUP,
    MAX_FEATURE_GROUPS,
};
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuError, GpuResult};
use crate::render::forward::blend::Falloff;
use crate::render::shaders::bindings::blend_bwd as slot;
use ash::vk;

/// The blend-backward pipeline for one bin size, layout and kernel.
pub struct BlendBwd {
    pipeline: ComputePipeline,
    bin: u32,
    rows: bool,
}

/// What the blend backward binds: the forward's frame (`splats` and `values` are buffers,
/// or texel views for the row layout), the pixels' gradients and the pass's outputs.
#[derive(Clone, Copy)]
pub struct BlendBwdBindings<'a> {
    /// The frame's parameters.
    pub params: BufferSlice<'a>,
    /// The frame's splats.
    pub splats: Resource<'a>,
    /// The sorted pairs' Gaussian indices.
    pub values: Resource<'a>,
    /// Each bin's range of pairs.
    pub ranges: BufferSlice<'a>,
    /// Each pixel's last contributor and final transmittance.
    pub last: BufferSlice<'a>,
    /// dL/d(colour, alpha) per pixel.
    pub grad_color: BufferSlice<'a>,
    /// dL/d depth per pixel.
    pub grad_depth: BufferSlice<'a>,
    /// Out: each pair's gradient fields.
    pub pair_grads: BufferSlice<'a>,
    /// Out: each field's largest magnitude.
    pub maxima: BufferSlice<'a>,
    /// The Gaussians' feature values (groups of four).
    pub features: BufferSlice<'a>,
    /// dL/d feature channel per pixel.
    pub grad_features: BufferSlice<'a>,
}

/// One dispatch of a split pass ([`crate::render::frame::bands`]): the pairs `[lo, hi)` whose sums it
/// writes, the bin rows `[first, end)` it runs, and the first pixel row of the per-pixel
/// bindings.
#[derive(Clone, Copy, Debug)]
pub struct BlendBwdBand {
    /// Pairs `[lo, hi)`.
    pub pairs: (u32, u32),
    /// Bin rows `[first, end)`.
    pub bin_rows: (u32, u32),
    /// The pixel row the per-pixel bindings start at.
    pub first_row: u32,
}

impl BlendBwd {
    /// Whether `ctx` runs the row layout for `bin`-pixel bins: one invocation per row of
    /// an 8-pixel bin, reading through texel views (`texel_views`: the frame has them).
    /// CPU devices. Its workgroup (8 invocations) is one subgroup where the device's
    /// smallest subgroup has 8 lanes or more; otherwise (lavapipe at 4 lanes) the rows'
    /// sums go through shared memory in the order llvmpipe's subgroup sum adds them, so
    /// the gradients are the same bits at every width.
    pub fn rows_for(_ctx: &GpuContext, bin: u32, texel_views: bool) -> bool {
        bin == 8 && texel_views
    }

    /// Builds the pipeline for `bin`-pixel bins (8 or 16) and `falloff`: with `rows`, the
    /// row layout ([`Self::rows_for`]); otherwise one invocation per pixel, whose shared
    /// memory holds one partial sum per subgroup, pair of a batch and field (the device's
    /// smallest subgroup size decides how many subgroups a workgroup can have).
    pub fn new(
        ctx: &GpuContext,
        bin: u32,
        rows: bool,
        falloff: Falloff,
        feature_groups: u32,
    ) -> GpuResult<Self> {
        if feature_groups > MAX_FEATURE_GROUPS {
            return Err(GpuError::InvalidArgument(format!(
                "the backward pass differentiates at most {} feature channels, not {}",
                4 * MAX_FEATURE_GROUPS,
                4 * feature_groups
            )));
        }
        if !matches!(bin, 8 | 16) || (rows && bin != 8) {
            return Err(GpuError::InvalidArgument(format!(
                "the blend backward runs on 8- or 16-pixel bins (rows: 8), not {bin}"
            )));
        }
        let info = ctx.info();
        let strip = if rows { bin } else { 1 };
        let invocations = bin * bin / strip;
        let max_subgroups = invocations.div_ceil(info.min_subgroup_size.max(1));
        let fields = GRAD_FIELDS + 4 * feature_groups;
        // Shared memory of the per-pixel layout: per staged pair its splat (13 floats) and
        // one partial sum per subgroup and field; the max of each field, the last pair.
        let shared = |batch: u32| 4 * (batch * 13 + batch * max_subgroups * fields + 1 + fields);
        let batch = [16, 8, 4, 2]
            .into_iter()
            .find(|&b| shared(b) <= info.max_shared_memory);
        let batch = match (rows, batch) {
            (true, _) => 0,
            (false, Some(b)) => b,
            (false, None) => {
                return Err(GpuError::DeviceLimit {
                    limit: "maxComputeSharedMemorySize",
                    needed: u64::from(shared(2)),
                    max: u64::from(info.max_shared_memory),
                    message: format!(
                        "the blend backward of {bin}-pixel bins needs {} bytes of shared memory \
                         for {max_subgroups} subgroups and {fields} gradient fields",
                        shared(2)
                    ),
                })
            }
        };
        let storage = BindingKind::StorageBuffer;
        let pairs = if rows {
            BindingKind::UniformTexelBuffer
        } else {
            storage
        };
        let pipeline = ComputePipeline::from_embedded_specialized(
            ctx,
            "blend_bwd",
            &[
                ("BIN", format!("{bin}u")),
                ("STRIP", strip.to_string()),
                ("SPLAT_KERNEL", format!("{}u", falloff.kernel.shader_id())),
                ("FEATURE_GROUPS", feature_groups.to_string()),
                (
                    "CANONICAL_SUM",
                    u32::from(!rows && info.subgroup_shuffle).to_string(),
                ),
            ],
            &by_binding([
                (slot::PARAMS, storage),
                (slot::SPLATS, pairs),
                (slot::VALUES, pairs),
                (slot::RANGES, storage),
                (slot::LAST, storage),
                (slot::GRAD_COLOR, storage),
                (slot::GRAD_DEPTH, storage),
                (slot::PAIR_GRADS, storage),
                (slot::MAXIMA, storage),
                (slot::FEATURES, storage),
                (slot::GRAD_FEATURES, storage),
            ])?,
            &CountsPush::LAYOUT,
            &if rows {
                vec![
                    (
                        GRAD_SPEC_ROWS_SUBGROUP,
                        u32::from(info.min_subgroup_size >= bin),
                    ),
                    falloff.specialization()[0],
                ]
            } else {
                vec![
                    (GRAD_SPEC_MAX_SUBGROUPS, max_subgroups),
                    (GRAD_SPEC_BATCH, batch),
                    falloff.specialization()[0],
                ]
            },
        )?;
        Ok(BlendBwd {
            pipeline,
            bin,
            rows,
        })
    }

    /// Bin side in pixels.
    pub fn bin(&self) -> u32 {
        self.bin
    }

    /// Whether this is the row layout (splats and values bound as texel views).
    pub fn rows(&self) -> bool {
        self.rows
    }

    /// Records the dispatch over the bins of `bins_x` columns and `band`'s rows, writing
    /// the sums of `band`'s pairs ([`crate::render::frame::bands`]): `pair_grads` holds the band's pairs
    /// from its first, and the per-pixel bindings start at its first pixel row.
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        bins_x: u32,
        band: BlendBwdBand,
        b: &BlendBwdBindings,
    ) -> GpuResult<()> {
        let bins = (bins_x, band.bin_rows.1 - band.bin_rows.0);
        if bins.1 == 0 {
            return Ok(());
        }
        let BlendBwdBindings {
            params,
            splats,
            values,
            ranges,
            last,
            grad_color,
            grad_depth,
            pair_grads,
            maxima,
            features,
            grad_features,
        } = *b;
        let buffers = by_binding([
            (slot::PARAMS, Resource::Buffer(params)),
            (slot::SPLATS, splats),
            (slot::VALUES, values),
            (slot::RANGES, Resource::Buffer(ranges)),
            (slot::LAST, Resource::Buffer(last)),
            (slot::GRAD_COLOR, Resource::Buffer(grad_color)),
            (slot::GRAD_DEPTH, Resource::Buffer(grad_depth)),
            (slot::PAIR_GRADS, Resource::Buffer(pair_grads)),
            (slot::MAXIMA, Resource::Buffer(maxima)),
            (slot::FEATURES, Resource::Buffer(features)),
            (slot::GRAD_FEATURES, Resource::Buffer(grad_features)),
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
        let push = CountsPush {
            counts: [band.pairs.0, band.pairs.1, band.bin_rows.0, band.first_row],
        };
        self.pipeline.dispatch_resources(
            ctx,
            cmd,
            &buffers,
            bytemuck::bytes_of(&push),
            [bins.0, bins.1, 1],
        )
    }
}
