//! Recording a frame's command buffer: one short function per phase, read top to bottom
//! as preprocess -> order -> scan -> keys -> sort -> ranges -> blend -> readback.

use super::types::{self, Counters, FrameParams};
use crate::camera::Camera;
use crate::cpu::{RenderOptions, SplatKernel};
use crate::gpu::shader::Resource;
use crate::gpu::sync::{barrier, barrier_uses, Access};
use crate::gpu::{Count, GpuError, GpuResult};
use ash::vk;

use super::{
    bin_grid, blend, features, keys, preprocess, tile_bits, FeatureJob, FrameSet, GpuRenderer,
    GpuScene, Pass, Readback,
};

impl GpuRenderer {
    /// Records the frame into set `set`'s command buffer and submits it; waits for it
    /// when `wait`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn record_and_submit(
        &mut self,
        set: usize,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        readback: Readback,
        features: Option<FeatureJob>,
        wait: bool,
        pass: Pass,
    ) -> GpuResult<()> {
        let window = self.preprocess_window();
        let Self {
            preprocess,
            compact_preprocess,
            order,
            scan,
            keys,
            sort,
            ranges,
            blend,
            power_blend,
            feature_blends,
            shade,
            pack,
            sets,
            ctx,
            ..
        } = self;
        let FrameSet {
            slot,
            timer,
            frame,
            feature_planes,
            bin_size,
            ..
        } = sets
            .get_mut(set)
            .ok_or_else(|| GpuError::InvalidArgument(format!("no frame set {set}")))?;
        let feature_job = match features {
            Some((feat, _)) => Some((
                feat,
                feature_blends[opts.kernel.shader_id() as usize]
                    .as_ref()
                    .ok_or_else(|| {
                        GpuError::InvalidArgument("the feature blend pipeline is missing".into())
                    })?,
            )),
            None => None,
        };
        let preprocess = match (scene.compact, compact_preprocess.as_ref()) {
            (false, _) => &*preprocess,
            (true, Some(p)) => p,
            (true, None) => {
                return Err(GpuError::InvalidArgument(
                    "the compact preprocess pipeline is missing".into(),
                ))
            }
        };
        let blend = match (opts.kernel, power_blend.as_ref()) {
            (SplatKernel::Gaussian, _) => &*blend,
            (SplatKernel::Power, Some(b)) => b,
            (SplatKernel::Power, None) => {
                return Err(GpuError::InvalidArgument(
                    "the power-kernel blend pipeline is missing".into(),
                ))
            }
        };
        let f = frame
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("frame buffers missing".into()))?;
        let (tiles_x, tiles_y) = cam.tile_grid();
        let bin_size = *bin_size;
        let (bins_x, bins_y) = bin_grid(bin_size, cam.width, cam.height);
        let pos = cam.position();
        let r = cam.rotation;
        let t = cam.translation;
        let params = FrameParams {
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
            tan_fov: [cam.tan_half_fov_x(), cam.tan_half_fov_y(), 0.0, 0.0],
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
                f.capacity,
            ],
            bins: [bin_size, bins_x, bins_y, 16 / bin_size],
            filters: [
                opts.scale_modifier,
                opts.max_scale.unwrap_or(-1.0),
                opts.min_opacity.unwrap_or(-1.0),
                opts.kernel.shader_id() as f32,
            ],
        };
        let n = scene.count;
        let pair_bits = 0..tile_bits(bins_x * bins_y);
        let whole = [keys::Chunk::whole(n)];
        let (chunks, first_chunks, last_chunks) = match pass {
            Pass::Whole => (&whole[..], true, true),
            Pass::Front => (&[][..], true, false),
            Pass::Chunks {
                chunks,
                first,
                last,
            } => (chunks, first, last),
        };
        let front = !matches!(pass, Pass::Chunks { .. });
        let record = |cmd| {
            let device = ctx.device();
            timer.reset(ctx, cmd);
            if !front {
                // Everything the previous submission of this frame wrote (the scan, the
                // images, the counters) -> this one; its reads -> this one's writes.
                barrier(ctx, cmd, Access::Any, Access::Any);
            } else {
                // SAFETY: cmd is recording; the buffers are alive and large enough.
                unsafe {
                    device.cmd_update_buffer(
                        cmd,
                        f.params.handle(),
                        0,
                        bytemuck::bytes_of(&params),
                    );
                    device.cmd_fill_buffer(cmd, f.counters.handle(), 0, vk::WHOLE_SIZE, 0);
                    device.cmd_fill_buffer(cmd, f.ranges.handle(), 0, vk::WHOLE_SIZE, 0);
                }
                f.color.transition_to_general(ctx, cmd);
                f.depth.transition_to_general(ctx, cmd);
                // Params, counters and ranges: from the clears to the shaders that use them.
                barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);

                timer.stage(ctx, cmd, "preprocess", |cmd| {
                    preprocess.record(
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
                            texels: if preprocess.texel_io() {
                                Some(f.preprocess_texels(scene)?)
                            } else {
                                None
                            },
                        },
                        n,
                        window,
                    )
                })?;
                // The depth sort opens with its own barrier from compute writes (its contract).
                timer.stage(ctx, cmd, "order", |cmd| {
                    order.record(
                        ctx,
                        cmd,
                        sort,
                        &f.params,
                        &f.depth_keys,
                        &f.depth_values,
                        &f.sort_scratch,
                        f.depth_sort_texels().as_ref(),
                        f.touched.whole(),
                        f.offsets.whole(),
                        (n, f.gaussians.max(1)),
                    )
                })?;
                // Tiles touched in depth order -> scan; depth order and counters -> keys.
                barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);

                timer.stage(ctx, cmd, "scan", |cmd| {
                    scan.record(
                        ctx,
                        cmd,
                        f.offsets.slice(0, u64::from(n) * 4),
                        f.offsets.slice(0, u64::from(n) * 4),
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
            }
            if let Pass::Front = pass {
                // The counters and the scanned offsets -> copies for the host.
                barrier(ctx, cmd, Access::ComputeReadWrite, Access::TransferRead);
                let planning = f.chunk_offsets.as_ref().ok_or_else(|| {
                    GpuError::InvalidArgument("the chunk planning buffer is missing".into())
                })?;
                let (_, _, counters_off) = f.readback_offsets();
                let counters = [vk::BufferCopy::default()
                    .dst_offset(counters_off)
                    .size(std::mem::size_of::<Counters>() as u64)];
                let offsets = [vk::BufferCopy::default().size(planning.size())];
                // SAFETY: the buffers are alive and the regions are inside them (the
                // planning buffer holds one offset per Gaussian, as the offsets buffer).
                unsafe {
                    device.cmd_copy_buffer(
                        cmd,
                        f.counters.handle(),
                        f.readback.handle(),
                        &counters,
                    );
                    device.cmd_copy_buffer(cmd, f.offsets.handle(), planning.handle(), &offsets);
                }
                barrier(ctx, cmd, Access::TransferWrite, Access::HostRead);
                return Ok(());
            }
            for (c, &chunk) in chunks.iter().enumerate() {
                let resume = !(first_chunks && c == 0);
                if resume {
                    if c > 0 {
                        // The previous chunk's uses of the keys, values, ranges, counters
                        // and images -> this chunk's clears and writes.
                        barrier(ctx, cmd, Access::Any, Access::Any);
                    }
                    f.ranges.fill(ctx, cmd, 0, vk::WHOLE_SIZE, 0);
                    // Cleared ranges -> the ranges stage.
                    barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);
                }
                timer.stage(ctx, cmd, "keys", |cmd| {
                    keys.record(
                        ctx,
                        cmd,
                        &keys::KeysBindings {
                            params: f.params.whole(),
                            splat_texels: f.splat_texels.handle(),
                            counters: f.counters.whole(),
                            io: f.keys_io(keys.texel_io())?,
                        },
                        chunk,
                    )
                })?;
                // The sort opens with its own barrier from compute writes (its contract).
                // Pairs arrive in depth order: only the tile bits remain to be sorted.
                timer.stage(ctx, cmd, "sort", |cmd| {
                    let count = Count::Device {
                        buffer: &f.counters,
                        offset: types::COUNTER_SORT_COUNT,
                        max_n: f.capacity,
                    };
                    let (k, v, s) = (&f.keys, &f.values, &f.sort_scratch);
                    let texels = f.pair_sort_texels();
                    sort.record_views(ctx, cmd, k, v, s, count, pair_bits.clone(), texels.as_ref())
                })?;
                // Sorted keys -> ranges (storage or texel reads); the ranges dispatch
                // arguments (written by keys) -> indirect read.
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

                timer.stage(ctx, cmd, "ranges", |cmd| {
                    let sorted_keys = match (ranges.texel_io(), f.sort_views.as_ref()) {
                        (true, Some(v)) => Resource::TexelBuffer(v.keys.handle()),
                        _ => Resource::Buffer(f.keys.whole()),
                    };
                    ranges.record(
                        ctx,
                        cmd,
                        sorted_keys,
                        f.ranges.whole(),
                        f.counters.whole(),
                        f.counters.slice(types::COUNTER_RANGES_GROUPS, 12),
                    )
                })?;
                // Ranges, sorted values and splats -> blend and feature blend (storage reads,
                // or texel fetches in the texel kernels); counters -> their loop-length atomics.
                barrier_uses(
                    ctx,
                    cmd,
                    &[Access::ComputeWrite],
                    &[Access::ComputeReadWrite, Access::ComputeSampledRead],
                );

                if let Some((feat, pipeline)) = &feature_job {
                    // Before the colour blend: a resumed chunk reads the pixels' transmittance
                    // as the previous chunk left it in the colour image.
                    timer.stage(ctx, cmd, "features", |cmd| {
                        let planes = feature_planes.as_ref().ok_or_else(|| {
                            GpuError::InvalidArgument("the feature images are missing".into())
                        })?;
                        for (g, input) in feat.groups.iter().enumerate() {
                            let output = planes
                                .buffer
                                .slice(g as u64 * planes.plane_bytes, planes.pixel_bytes);
                            let texels = match (&f.splat_texels, &f.value_texels, feat.views.get(g))
                            {
                                (s, Some(v), Some(fv)) if pipeline.texel() => {
                                    Some([s.handle(), v.handle(), fv.handle()])
                                }
                                _ => None,
                            };
                            pipeline.record(
                                ctx,
                                cmd,
                                &features::FeatureBindings {
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
                                (cam.width, cam.height),
                            )?;
                        }
                        Ok(())
                    })?;
                    // Its colour-image reads and loop-length atomics -> the blend's.
                    barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
                }

                timer.stage(ctx, cmd, "blend", |cmd| {
                    blend.record(
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
                            last: last_chunks && c + 1 == chunks.len(),
                        },
                        (tiles_x, tiles_y),
                    )
                })?;
            }
            if !last_chunks {
                return Ok(());
            }
            if feature_job.is_some() {
                if let Some(shader) = features.and_then(|(_, s)| s) {
                    let (planes, pipeline) = match (feature_planes.as_ref(), shade.as_ref()) {
                        (Some(p), Some(s)) => (p, s),
                        _ => {
                            return Err(GpuError::InvalidArgument(
                                "the neural shader's pipeline or images are missing".into(),
                            ))
                        }
                    };
                    // The feature blend's writes (and the blend's colour image) -> reads.
                    barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
                    timer.stage(ctx, cmd, "shade", |cmd| {
                        pipeline.record(
                            ctx,
                            cmd,
                            shader,
                            planes.buffer.whole(),
                            (planes.plane_bytes / 16) as u32,
                            &f.color,
                            cam,
                            opts.background,
                        )
                    })?;
                }
            }
            // Only what the consumer needs leaves the device. Float: the images are the
            // copy sources. Rgba8: the colour image is packed by a compute pass (timed
            // with the readback) and only the packed buffer is copied.
            timer.stage(ctx, cmd, "readback", |cmd| {
                let (color_off, depth_off, counters_off) = f.readback_offsets();
                match (readback, f.packed.as_ref()) {
                    (Readback::Float, _) => {
                        // Images -> copy sources; counters (written by compute) -> copy.
                        f.color.transition_for_copy(ctx, cmd);
                        f.depth.transition_for_copy(ctx, cmd);
                        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
                        f.color.copy_to_buffer(ctx, cmd, &f.readback, color_off);
                        f.depth.copy_to_buffer(ctx, cmd, &f.readback, depth_off);
                    }
                    (Readback::Rgba8, Some(packed)) => {
                        // The blend's image writes -> the pack's image reads.
                        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
                        pack.record(ctx, cmd, &f.color, packed.whole(), (f.width, f.height))?;
                        // Packed pixels and counters (written by compute) -> copy.
                        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
                        let region = [vk::BufferCopy::default()
                            .src_offset(0)
                            .dst_offset(color_off)
                            .size(packed.size())];
                        // SAFETY: both buffers are alive; the readback holds 16 bytes per
                        // pixel at color_off, the packed buffer 4.
                        unsafe {
                            device.cmd_copy_buffer(
                                cmd,
                                packed.handle(),
                                f.readback.handle(),
                                &region,
                            )
                        };
                    }
                    (Readback::Rgba8, None) => {
                        return Err(GpuError::InvalidArgument(
                            "the packed frame buffer is missing".into(),
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
            })?;
            barrier(ctx, cmd, Access::TransferWrite, Access::HostRead);
            Ok(())
        };
        if wait {
            ctx.submit_slot(slot, record)
        } else {
            ctx.submit_slot_nowait(slot, record)
        }
    }
}
