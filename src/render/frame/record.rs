//! Recording a frame's command buffer. `FrameRecorder::record` reads top to bottom as
//! the pipeline: clear -> preprocess -> order -> scan -> (per chunk: keys -> sort ->
//! ranges -> features -> blend) -> shade -> readback, one short function per phase, each
//! stage inside its timestamp pair ([`Stage`]) and each barrier saying what it orders.

use crate::core::camera::Camera;
use crate::core::model::RenderOptions;
use crate::gpu::limits::storage_binding_bytes;
use crate::gpu::shader::Resource;
use crate::gpu::sort::SortJob;
use crate::gpu::sync::{barrier, barrier_uses, Access};
use crate::gpu::{Count, GpuContext, GpuError, GpuResult, GpuTimer};
use crate::render::forward::features::FeatureBindings;
use crate::render::forward::order::OrderBindings;
use crate::render::forward::pack::PackBindings;
use crate::render::forward::ranges::RangesBindings;
use crate::render::forward::shade::GpuShader;
use crate::render::forward::shade::ShadeBindings;
use crate::render::forward::types::{self, Counters, FrameParams};
use crate::render::forward::{blend, keys, preprocess};
use crate::render::frame::bands;
use crate::render::frame::buffers::FeaturePlanes;
use crate::render::frame::buffers::LAST_CONTRIBUTOR;
use crate::render::frame::pipelines::{FramePipelines, Pipelines};
use crate::render::{
    bin_grid, tile_bits, FrameBuffers, FrameSet, GpuFeatures, GpuScene, Pass, Readback, Stage,
    Ticket,
};
use ash::vk;

/// Builds the pipelines the ticket's frame needs, records `pass` of it into its set's
/// command buffer (`set`, the ticket's) and submits it; waits for it when `wait`.
/// `window`: Gaussians per preprocess dispatch.
pub(crate) fn record_and_submit(
    ctx: &GpuContext,
    pipelines: &mut Pipelines,
    set: &mut FrameSet,
    window: u32,
    (t, wait, pass): (&Ticket, bool, Pass),
) -> GpuResult<()> {
    let needs = t.needs(set.saves_last);
    pipelines.prepare(ctx, needs)?;
    let FrameSet {
        slot,
        timer,
        frame,
        feature_planes,
        bin_size,
        ..
    } = set;
    let f = frame
        .as_ref()
        .ok_or_else(|| GpuError::Internal("the frame buffers were not made".into()))?;
    let mut recorder = FrameRecorder {
        ctx,
        timer,
        buffers: f,
        pipelines: pipelines.frame(needs)?,
        scene: t.scene,
        cam: &t.cam,
        opts: &t.opts,
        readback: t.readback,
        features: t.features.map(|(features, _)| features),
        shader: t.features.and_then(|(_, shader)| shader),
        feature_planes: feature_planes.as_ref(),
        params: frame_params(t.scene, &t.cam, &t.opts, f.capacity, *bin_size),
        bin_size: *bin_size,
        window,
        save_last: needs.save_last,
    };
    let record = |cmd| recorder.record(cmd, pass);
    if wait {
        ctx.submit_slot(slot, record)
    } else {
        ctx.submit_slot_nowait(slot, record)
    }
}

/// The frame constants every stage reads (`FrameParams` in `glsl/render/forward/splat_common.glsl`).
fn frame_params(
    scene: &GpuScene,
    cam: &Camera,
    opts: &RenderOptions,
    capacity: u32,
    bin_size: u32,
) -> FrameParams {
    let (tiles_x, tiles_y) = cam.tile_grid();
    let (bins_x, bins_y) = bin_grid(bin_size, cam.width, cam.height);
    let pos = cam.position();
    let r = cam.rotation;
    let t = cam.translation;
    let (lens, lens_a, lens_b, fold) = cam.lens.shader_params();
    let unscented = crate::core::model::unscented::UnscentedParams::default();
    FrameParams {
        w2c_row0: [r.x_axis.x, r.y_axis.x, r.z_axis.x, t.x],
        w2c_row1: [r.x_axis.y, r.y_axis.y, r.z_axis.y, t.y],
        w2c_row2: [r.x_axis.z, r.y_axis.z, r.z_axis.z, t.z],
        cam_pos: [
            pos.x,
            pos.y,
            pos.z,
            if opts.antialiased { 1.0 } else { 0.0 },
        ],
        focal: [cam.fx, cam.fy, cam.cx, cam.cy],
        limits: crate::core::model::clamp_limits(cam, opts.rules),
        background: [
            opts.background[0],
            opts.background[1],
            opts.background[2],
            0.0,
        ],
        image: [cam.width, cam.height, tiles_x, tiles_y],
        counts: [
            scene.count,
            opts.active_sh_degree(scene.sh_degree),
            scene.sh_coeffs,
            capacity,
        ],
        bins: [bin_size, bins_x, bins_y, 16 / bin_size],
        filters: [
            opts.scale_modifier,
            opts.max_scale.unwrap_or(-1.0),
            opts.min_opacity.unwrap_or(-1.0),
            opts.kernel.shader_id() as f32,
        ],
        rules: [
            opts.rules.near_cull_f32(opts.near()),
            opts.rules.alpha_max(),
            opts.rules.t_stop(),
            opts.rules.antialias_min_ratio(),
        ],
        modes: [opts.rules.shader_id(), lens, u32::from(cam.lens.wraps()), 0],
        lens_a,
        lens_b,
        unscented: unscented.weights().map(|w| w as f32),
        lens_c: [unscented.in_image_margin as f32, fold, 0.0, 0.0],
    }
}

/// Everything one submission of a frame records with.
struct FrameRecorder<'a> {
    ctx: &'a GpuContext,
    timer: &'a mut GpuTimer,
    buffers: &'a FrameBuffers,
    pipelines: FramePipelines<'a>,
    scene: &'a GpuScene,
    cam: &'a Camera,
    opts: &'a RenderOptions,
    readback: Readback,
    /// Feature channels blended chunk by chunk before the colour.
    features: Option<&'a GpuFeatures>,
    /// The neural shader run on the blended features after the last chunk.
    shader: Option<&'a GpuShader>,
    feature_planes: Option<&'a FeaturePlanes>,
    params: FrameParams,
    bin_size: u32,
    /// Gaussians per preprocess window.
    window: u32,
    /// The blend writes each pixel's last contributor.
    save_last: bool,
}

impl FrameRecorder<'_> {
    /// Records `pass`: the whole frame; or its front, whose offsets the host reads to plan
    /// chunks; or a batch of chunks (with the frame's end after the last one).
    fn record(&mut self, cmd: vk::CommandBuffer, pass: Pass) -> GpuResult<()> {
        self.timer.reset(self.ctx, cmd);
        match pass {
            Pass::Whole => {
                self.clear(cmd);
                self.front(cmd)?;
                self.chunk(cmd, keys::Chunk::whole(self.scene.count), false, true)?;
                self.end(cmd)
            }
            Pass::Front => {
                self.clear(cmd);
                self.front(cmd)?;
                self.copy_for_planning(cmd)
            }
            Pass::Chunks {
                chunks,
                first,
                last,
            } => {
                // Everything the previous submission of this frame wrote (the scan, the
                // images, the counters) -> this one; its reads -> this one's writes.
                barrier(self.ctx, cmd, Access::Any, Access::Any);
                for (c, &chunk) in chunks.iter().enumerate() {
                    if c > 0 {
                        // The previous chunk's uses of the keys, values, ranges, counters
                        // and images -> this chunk's clears and writes.
                        barrier(self.ctx, cmd, Access::Any, Access::Any);
                    }
                    let resume = !(first && c == 0);
                    self.chunk(cmd, chunk, resume, last && c + 1 == chunks.len())?;
                }
                if last {
                    self.end(cmd)
                } else {
                    Ok(())
                }
            }
        }
    }

    /// Frame constants in, counters and bin ranges zeroed, images to GENERAL.
    fn clear(&self, cmd: vk::CommandBuffer) {
        let (ctx, f) = (self.ctx, self.buffers);
        let device = ctx.device();
        // SAFETY: cmd is recording; the buffers are alive and large enough.
        unsafe {
            device.cmd_update_buffer(cmd, f.params.handle(), 0, bytemuck::bytes_of(&self.params));
            device.cmd_fill_buffer(cmd, f.counters.handle(), 0, vk::WHOLE_SIZE, 0);
            device.cmd_fill_buffer(cmd, f.ranges.handle(), 0, vk::WHOLE_SIZE, 0);
        }
        f.color.transition_to_general(ctx, cmd);
        f.depth.transition_to_general(ctx, cmd);
        // Params, counters and ranges: from the clears to the shaders that use them.
        barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);
    }

    /// Per Gaussian: preprocess, the depth order and the scan of tiles touched.
    fn front(&mut self, cmd: vk::CommandBuffer) -> GpuResult<()> {
        let (ctx, f, p, scene) = (self.ctx, self.buffers, self.pipelines, self.scene);
        let n = scene.count;
        let window = self.window;
        self.timer
            .stage(ctx, cmd, Stage::Preprocess.name(), |cmd| {
                let texels = match p.preprocess.texel_io() {
                    true => Some(f.preprocess_texels(scene)?),
                    false => None,
                };
                p.preprocess.record(
                    ctx,
                    cmd,
                    &preprocess::PreprocessBindings {
                        params: f.params.whole(),
                        gaussians: scene.gaussians.whole(),
                        sh_texels: scene.sh_texels.handle(),
                        splats: f.splats.whole(),
                        rects: f.rects.whole(),
                        depth_keys: f.depth_keys.whole(),
                        counters: f.counters.whole(),
                        depth_values: f.depth_values.whole(),
                        bin_masks: f.bin_masks.whole(),
                        touched: f.touched.whole(),
                        texels,
                    },
                    n,
                    window,
                )
            })?;
        // The depth sort opens with its own barrier from compute writes (its contract).
        self.timer.stage(ctx, cmd, Stage::Order.name(), |cmd| {
            let texels = f.depth_sort_texels();
            let bindings = OrderBindings {
                params: &f.params,
                depth_keys: &f.depth_keys,
                depth_values: &f.depth_values,
                scratch: &f.sort_scratch,
                texels: texels.as_ref(),
                touched: f.touched.whole(),
                touched_in_order: f.offsets.whole(),
            };
            p.order
                .record(ctx, cmd, p.sort, &bindings, (n, f.gaussians.max(1)))
        })?;
        // Tiles touched in depth order -> scan; depth order and counters -> keys.
        barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
        self.timer.stage(ctx, cmd, Stage::Scan.name(), |cmd| {
            let offsets = f.offsets.slice(0, u64::from(n) * 4);
            p.scan.record(
                ctx,
                cmd,
                offsets,
                offsets,
                (&f.counters, types::COUNTER_SCAN_TOTAL),
                f.scan_scratch.whole(),
                n,
            )
        })?;
        // Offsets and the scan total -> keys; the splats (preprocess) -> its texel reads.
        barrier_uses(
            ctx,
            cmd,
            &[Access::ComputeWrite],
            &[Access::ComputeReadWrite, Access::ComputeSampledRead],
        );
        Ok(())
    }

    /// The counters and the scanned offsets to host-visible memory, for chunk planning.
    fn copy_for_planning(&self, cmd: vk::CommandBuffer) -> GpuResult<()> {
        let (ctx, f) = (self.ctx, self.buffers);
        barrier(ctx, cmd, Access::ComputeReadWrite, Access::TransferRead);
        let planning = f
            .chunk_offsets
            .as_ref()
            .ok_or_else(|| GpuError::Internal("the chunk planning buffer was not made".into()))?;
        let (_, _, counters_off) = f.readback_offsets();
        let counters = [vk::BufferCopy::default()
            .dst_offset(counters_off)
            .size(std::mem::size_of::<Counters>() as u64)];
        let offsets = [vk::BufferCopy::default().size(planning.size())];
        // SAFETY: the buffers are alive and the regions are inside them (the planning
        // buffer holds one offset per Gaussian, as the offsets buffer).
        unsafe {
            let device = ctx.device();
            device.cmd_copy_buffer(cmd, f.counters.handle(), f.readback.handle(), &counters);
            device.cmd_copy_buffer(cmd, f.offsets.handle(), planning.handle(), &offsets);
        }
        barrier(ctx, cmd, Access::TransferWrite, Access::HostRead);
        Ok(())
    }

    /// One depth-ordered chunk of pairs: keys, sort, ranges, features, blend. `resume`:
    /// the pixels continue from a previous chunk; `last`: the blend writes final pixels.
    fn chunk(
        &mut self,
        cmd: vk::CommandBuffer,
        chunk: keys::Chunk,
        resume: bool,
        last: bool,
    ) -> GpuResult<()> {
        let (ctx, f, p) = (self.ctx, self.buffers, self.pipelines);
        if resume {
            f.ranges.fill(ctx, cmd, 0, vk::WHOLE_SIZE, 0);
            // Cleared ranges -> the ranges stage.
            barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);
        }
        self.timer.stage(ctx, cmd, Stage::Keys.name(), |cmd| {
            p.keys.record(
                ctx,
                cmd,
                &keys::KeysBindings {
                    params: f.params.whole(),
                    splat_texels: f.splat_texels.handle(),
                    counters: f.counters.whole(),
                    io: f.keys_io(p.keys.texel_io())?,
                },
                chunk,
            )
        })?;
        // The sort opens with its own barrier from compute writes (its contract).
        // Pairs arrive in depth order: only the bin bits remain to be sorted.
        let (bins_x, bins_y) = bin_grid(self.bin_size, self.cam.width, self.cam.height);
        self.timer.stage(ctx, cmd, Stage::Sort.name(), |cmd| {
            let count = Count::Device {
                buffer: &f.counters,
                offset: types::COUNTER_SORT_COUNT,
                max_n: f.capacity,
            };
            let texels = f.pair_sort_texels();
            let bits = tile_bits(bins_x * bins_y);
            let job = SortJob::new(&f.keys, &f.values, &f.sort_scratch, count, bits)
                .texels(texels.as_ref());
            p.sort.record(ctx, cmd, &job)
        })?;
        // Sorted keys -> ranges (storage or texel reads); the ranges dispatch arguments
        // (written by keys) -> indirect read.
        barrier_uses(
            ctx,
            cmd,
            &[Access::ComputeWrite],
            &[
                Access::ComputeRead,
                Access::ComputeSampledRead,
                Access::IndirectRead,
            ],
        );
        self.timer.stage(ctx, cmd, Stage::Ranges.name(), |cmd| {
            let sorted_keys = match (p.ranges.texel_io(), f.sort_views.as_ref()) {
                (true, Some(v)) => Resource::TexelBuffer(v.keys.handle()),
                _ => Resource::Buffer(f.keys.whole()),
            };
            let bindings = RangesBindings {
                sorted_keys,
                ranges: f.ranges.whole(),
                counters: f.counters.whole(),
                args: f.counters.slice(types::COUNTER_RANGES_GROUPS, 12),
            };
            p.ranges.record(ctx, cmd, &bindings)
        })?;
        // Ranges, sorted values and splats -> blend and feature blend (storage reads, or
        // texel fetches in the texel kernels); counters -> their loop-length atomics.
        barrier_uses(
            ctx,
            cmd,
            &[Access::ComputeWrite],
            &[Access::ComputeReadWrite, Access::ComputeSampledRead],
        );
        if self.features.is_some() {
            self.blend_features(cmd, resume)?;
            // Its colour-image reads and loop-length atomics -> the blend's.
            barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
        }
        let tiles = self.cam.tile_grid();
        let last_contributor = match (self.save_last, f.last_contributor.as_ref()) {
            (false, _) => None,
            (true, Some(buffer)) => Some(buffer.whole()),
            (true, None) => {
                return Err(GpuError::Internal(
                    "the last-contributor buffer was not made".into(),
                ))
            }
        };
        // Last contributors that exceed one storage binding are saved in bands of rows
        // (multiples of 64, so of the 16-pixel tiles), one dispatch each.
        let (width, height) = (self.cam.width, self.cam.height);
        let row_bands = match last_contributor {
            Some(_) => bands::pixel_bands(
                storage_binding_bytes(ctx.info()),
                (width, height),
                (LAST_CONTRIBUTOR, 8),
            )?,
            None => vec![(0, height)],
        };
        let tile = crate::core::rules::TILE_SIZE;
        self.timer.stage(ctx, cmd, Stage::Blend.name(), |cmd| {
            for &(y0, y1) in &row_bands {
                let rows = bands::bin_rows((y0, y1), height, tile, tiles.1);
                let row_bytes = u64::from(width) * 8;
                let last_contributor =
                    last_contributor.map(|s| bands::band_rows(s, (y0, y1), row_bytes));
                p.blend.record(
                    ctx,
                    cmd,
                    &blend::BlendBindings {
                        params: f.params.whole(),
                        splats: f.splats.whole(),
                        values: f.values.whole(),
                        splat_texels: Some(f.splat_texels.handle()),
                        value_texels: f.value_texels.as_ref().map(|v| v.handle()),
                        ranges: f.ranges.whole(),
                        color: &f.color,
                        depth: &f.depth,
                        counters: f.counters.whole(),
                        resume,
                        last,
                        last_contributor,
                        first_tile_row: rows.0,
                    },
                    (tiles.0, rows.1 - rows.0),
                )?;
            }
            Ok(())
        })
    }

    /// The chunk's feature channels, before its colour blend: a resumed chunk reads the
    /// pixels' transmittance as the previous chunk left it in the colour image.
    fn blend_features(&mut self, cmd: vk::CommandBuffer, resume: bool) -> GpuResult<()> {
        let (ctx, f) = (self.ctx, self.buffers);
        let (features, pipeline, planes) = match (
            self.features,
            self.pipelines.feature_blend,
            self.feature_planes,
        ) {
            (Some(features), Some(pipeline), Some(planes)) => (features, pipeline, planes),
            _ => {
                return Err(GpuError::Internal(
                    "a features frame without its pipeline or images".into(),
                ))
            }
        };
        let size = (self.cam.width, self.cam.height);
        self.timer.stage(ctx, cmd, Stage::Features.name(), |cmd| {
            for (g, input) in features.groups.iter().enumerate() {
                let output = planes
                    .buffer
                    .slice(g as u64 * planes.plane_bytes, planes.pixel_bytes);
                let texels = match (&f.value_texels, features.views.get(g)) {
                    (Some(v), Some(fv)) if pipeline.texel() => {
                        Some([f.splat_texels.handle(), v.handle(), fv.handle()])
                    }
                    _ => None,
                };
                pipeline.record(
                    ctx,
                    cmd,
                    &FeatureBindings {
                        params: f.params.whole(),
                        splats: f.splats.whole(),
                        values: f.values.whole(),
                        ranges: f.ranges.whole(),
                        features: input.whole(),
                        output,
                        counters: f.counters.whole(),
                        texels,
                        color: &f.color,
                        resume,
                    },
                    size,
                )?;
            }
            Ok(())
        })
    }

    /// After the last chunk: the neural shader (when the frame has one), then the readback.
    fn end(&mut self, cmd: vk::CommandBuffer) -> GpuResult<()> {
        if let (Some(shader), Some(_)) = (self.shader, self.features) {
            self.shade(cmd, shader)?;
        }
        self.read_back(cmd)?;
        barrier(self.ctx, cmd, Access::TransferWrite, Access::HostRead);
        Ok(())
    }

    /// The neural shader over the blended feature planes, into the colour image.
    fn shade(&mut self, cmd: vk::CommandBuffer, shader: &GpuShader) -> GpuResult<()> {
        let (ctx, f, cam) = (self.ctx, self.buffers, self.cam);
        let (planes, pipeline) = match (self.feature_planes, self.pipelines.shade) {
            (Some(planes), Some(pipeline)) => (planes, pipeline),
            _ => {
                return Err(GpuError::Internal(
                    "a shaded frame without the shader's pipeline or images".into(),
                ))
            }
        };
        // The feature blend's writes (and the blend's colour image) -> reads.
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
        let background = self.opts.background;
        self.timer.stage(ctx, cmd, Stage::Shade.name(), |cmd| {
            let bindings = ShadeBindings {
                features: planes.buffer.whole(),
                plane_stride: (planes.plane_bytes / 16) as u32,
                color: &f.color,
            };
            pipeline.record(ctx, cmd, shader, &bindings, cam, background)
        })
    }

    /// Only what the consumer needs leaves the device. Float: the images are the copy
    /// sources. Rgba8: the colour image is packed by a compute pass (timed with the
    /// readback) and only the packed buffer is copied. The counters always follow.
    fn read_back(&mut self, cmd: vk::CommandBuffer) -> GpuResult<()> {
        let (ctx, f, p, readback) = (self.ctx, self.buffers, self.pipelines, self.readback);
        self.timer.stage(ctx, cmd, Stage::Readback.name(), |cmd| {
            let device = ctx.device();
            let (color_off, depth_off, counters_off) = f.readback_offsets();
            match (readback, f.packed.as_ref(), p.pack) {
                (Readback::Float | Readback::Intermediates, _, _) => {
                    // Images -> copy sources; counters (written by compute) -> copy.
                    f.color.transition_for_copy(ctx, cmd);
                    f.depth.transition_for_copy(ctx, cmd);
                    barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
                    f.color.copy_to_buffer(ctx, cmd, &f.readback, color_off);
                    f.depth.copy_to_buffer(ctx, cmd, &f.readback, depth_off);
                }
                (Readback::Rgba8, Some(packed), Some(pack)) => {
                    // The blend's image writes -> the pack's image reads.
                    barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
                    let bindings = PackBindings {
                        color: &f.color,
                        packed: packed.whole(),
                    };
                    pack.record(ctx, cmd, &bindings, (f.width, f.height))?;
                    // Packed pixels and counters (written by compute) -> copy.
                    barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
                    let region = [vk::BufferCopy::default()
                        .src_offset(0)
                        .dst_offset(color_off)
                        .size(packed.size())];
                    // SAFETY: both buffers are alive; the readback holds 16 bytes per
                    // pixel at color_off, the packed buffer 4.
                    unsafe {
                        device.cmd_copy_buffer(cmd, packed.handle(), f.readback.handle(), &region)
                    };
                }
                (Readback::Counters, _, _) => {
                    // The images stay, as copy sources for the consumer's own passes.
                    f.color.transition_for_copy(ctx, cmd);
                    f.depth.transition_for_copy(ctx, cmd);
                    barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
                }
                (Readback::Rgba8, _, _) => {
                    return Err(GpuError::Internal(
                        "an RGBA8 frame without its packed buffer or pipeline".into(),
                    ))
                }
            }
            let region = [vk::BufferCopy::default()
                .src_offset(0)
                .dst_offset(counters_off)
                .size(std::mem::size_of::<Counters>() as u64)];
            // SAFETY: both buffers are alive and the region is inside them.
            unsafe {
                device.cmd_copy_buffer(cmd, f.counters.handle(), f.readback.handle(), &region)
            };
            Ok(())
        })
    }
}
