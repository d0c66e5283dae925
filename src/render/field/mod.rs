//! Field stage (`glsl/render/field/field.comp`): renders of the fitted field itself (slice, line
//! integral, maximum along the ray; [`crate::cpu::field`] is the reference and has every
//! formula). No projection, sort or blend: one dispatch per group of four channels, each
//! 16x8 workgroup summing the Gaussians whose support can reach its tile.

use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::model::field::{FieldGaussians, FieldMode, MAX_FIELD_SAMPLES};
use crate::core::shader_interface::FieldPush;
pub use crate::core::shader_interface::{FieldGaussian, FieldParams};
use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{ComputePipeline, GpuBuffer, GpuContext, GpuError, GpuResult, MemoryKind};
use crate::render::shaders::bindings::field as slot;

use crate::gpu::shader_set::{PIXEL_WG_X as SIDE, PIXEL_WG_Y as ROWS};

/// Gaussians per pass of a slice or an integral on a device with llvmpipe's loop limit
/// (an invocation whose loops run 65,535 iterations in all is ended before it writes): an
/// invocation loops at most 5 times per chunk of 128 (the chunk loop and the workgroup
/// scan's) and once per Gaussian, 34,048 in all. The passes add up; a maximum cannot be
/// split (each pixel keeps its samples' sums), so it is one pass, refused when a pixel
/// was not written.
const LOOP_LIMITED_PASS: u32 = 32_768;

/// What the output is filled with before a frame: a NaN no arithmetic makes (the shader
/// writes `0x7fc00000` for empty), so a pixel still holding it was never written.
const UNWRITTEN: u32 = 0xFFFF_FFFF;

const _: () = assert!(std::mem::size_of::<FieldParams>() == 176);

const _: () = assert!(std::mem::size_of::<FieldGaussian>() == 48);

/// A field on the device: the Gaussians and their `o_i feat_i` in groups of four.
pub struct GpuField {
    gaussians: GpuBuffer,
    features: GpuBuffer,
    count: u32,
    k: usize,
    groups: u32,
    cutoff: f32,
    bounds: [f64; 6],
}

impl GpuField {
    /// Uploads `g`.
    pub fn new(ctx: &GpuContext, g: &FieldGaussians) -> GpuResult<Self> {
        if g.k == 0 {
            return Err(GpuError::Input(
                "a field render needs feature channels".into(),
            ));
        }
        let groups = g.k.div_ceil(4);
        let records: Vec<FieldGaussian> = (0..g.len().max(1))
            .map(|i| {
                if i >= g.len() {
                    return FieldGaussian::default();
                }
                let m = g.means[i];
                let a = g.inv_cov[i].map(|v| v as f32);
                FieldGaussian {
                    mean_radius: [m[0] as f32, m[1] as f32, m[2] as f32, g.radius[i] as f32],
                    a0: [a[0], a[1], a[2], a[3]],
                    a1: [a[4], a[5], 0.0, 0.0],
                }
            })
            .collect();
        let mut feats = vec![0f32; g.len().max(1) * groups * 4];
        for i in 0..g.len() {
            for c in 0..g.k {
                feats[i * groups * 4 + c] = g.weights[i * g.k + c] as f32;
            }
        }
        let gaussians = GpuBuffer::new(
            ctx,
            "field gaussians",
            std::mem::size_of_val(records.as_slice()) as u64,
            MemoryKind::Device,
        )?;
        gaussians.upload(ctx, &records)?;
        let features = GpuBuffer::new(
            ctx,
            "field features",
            (feats.len() * 4) as u64,
            MemoryKind::Device,
        )?;
        features.upload(ctx, &feats)?;
        Ok(GpuField {
            gaussians,
            features,
            count: g.len() as u32,
            k: g.k,
            groups: groups as u32,
            cutoff: crate::core::model::field::field_cutoff(g.kernel) as f32,
            bounds: g.bounds,
        })
    }
}

/// The field pipelines of one kernel (one per mode, built when first used). Each frame
/// allocates its parameter and output buffers (a field render is one submission, waited
/// for).
pub struct FieldRenderer {
    kernel: crate::core::model::SplatKernel,
    pipelines: [Option<ComputePipeline>; 3],
}

impl FieldRenderer {
    /// A renderer for fields with `kernel`'s falloff.
    pub fn new(kernel: crate::core::model::SplatKernel) -> Self {
        FieldRenderer {
            kernel,
            pipelines: [None, None, None],
        }
    }

    fn pipeline(&mut self, ctx: &GpuContext, mode: u32) -> GpuResult<&ComputePipeline> {
        let slot_ref = &mut self.pipelines[mode as usize];
        if slot_ref.is_none() {
            use BindingKind::StorageBuffer as B;
            let defines = [
                ("FIELD_MODE", mode.to_string()),
                ("SPLAT_KERNEL", format!("{}u", self.kernel.shader_id())),
            ];
            *slot_ref = Some(ComputePipeline::from_embedded(
                ctx,
                "field",
                &defines,
                &by_binding([
                    (slot::PARAMS, B),
                    (slot::GAUSSIANS, B),
                    (slot::FEATURES, B),
                    (slot::OUTPUT, B),
                ])?,
                &FieldPush::LAYOUT,
            )?);
        }
        slot_ref
            .as_ref()
            .ok_or_else(|| GpuError::Internal("the field pipeline was just built".into()))
    }

    /// Renders `field` from `cam` under `mode`: as [`crate::cpu::field::render_field`]
    /// (the frame's features hold the channels, NaN where empty; alpha 1 where there is a
    /// value).
    pub fn render(
        &mut self,
        ctx: &GpuContext,
        field: &GpuField,
        cam: &Camera,
        mode: &FieldMode,
    ) -> GpuResult<Frame> {
        let samples = match *mode {
            FieldMode::Max { samples } if !(1..=MAX_FIELD_SAMPLES).contains(&samples) => {
                return Err(GpuError::Input(format!(
                    "a field maximum takes 1 to {MAX_FIELD_SAMPLES} samples along the ray, not {samples}"
                )))
            }
            FieldMode::Max { samples } => samples,
            _ => 0,
        };
        let (plane_point, plane_normal) = match *mode {
            FieldMode::Slice { point, normal } => {
                let len = normal.iter().map(|v| v * v).sum::<f32>().sqrt();
                (
                    [point[0], point[1], point[2], 0.0],
                    [normal[0] / len, normal[1] / len, normal[2] / len, 0.0],
                )
            }
            _ => ([0.0; 4], [0.0; 4]),
        };
        let r = cam.rotation.transpose().to_cols_array_2d(); // rows of R
        let t = cam.translation;
        let o = cam.position();
        let b = field.bounds.map(|v| v as f32);
        let params = FieldParams {
            size: [cam.width, cam.height, field.count, field.groups],
            mode: [samples, 0, 0, 0],
            w2c: [
                [r[0][0], r[0][1], r[0][2], t.x],
                [r[1][0], r[1][1], r[1][2], t.y],
                [r[2][0], r[2][1], r[2][2], t.z],
            ],
            origin: [o.x, o.y, o.z, field.cutoff],
            focal: [cam.fx, cam.fy, cam.cx, cam.cy],
            plane_point,
            plane_normal,
            bounds_min: [b[0], b[1], b[2], 0.0],
            bounds_max: [b[3], b[4], b[5], 0.0],
        };
        let pixels = cam.width as usize * cam.height as usize;
        let params_buf = GpuBuffer::new(ctx, "field params", 176, MemoryKind::Device)?;
        params_buf.upload(ctx, std::slice::from_ref(&params))?;
        let out_bytes = (pixels * field.groups as usize * 16) as u64;
        let out = GpuBuffer::new(ctx, "field output", out_bytes, MemoryKind::Device)?;
        let pass = match mode {
            FieldMode::Max { .. } => field.count.max(1),
            _ if ctx.info().loop_limited() => LOOP_LIMITED_PASS,
            _ => field.count.max(1),
        };
        let pipeline = self.pipeline(ctx, mode.shader_id())?;
        ctx.submit_and_wait("field render", |cmd| {
            out.fill(ctx, cmd, 0, ash::vk::WHOLE_SIZE, UNWRITTEN);
            barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);
            let mut first = 0;
            loop {
                if first > 0 {
                    // The next pass adds to what the last one wrote.
                    barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
                }
                for group in 0..field.groups {
                    let push = FieldPush {
                        group,
                        first,
                        count: pass.min(field.count - first),
                        accumulate: u32::from(first > 0),
                    };
                    pipeline.dispatch_resources(
                        ctx,
                        cmd,
                        &by_binding([
                            (slot::PARAMS, Resource::Buffer(params_buf.whole())),
                            (slot::GAUSSIANS, Resource::Buffer(field.gaussians.whole())),
                            (slot::FEATURES, Resource::Buffer(field.features.whole())),
                            (slot::OUTPUT, Resource::Buffer(out.whole())),
                        ])?,
                        bytemuck::bytes_of(&push),
                        [cam.width.div_ceil(SIDE), cam.height.div_ceil(ROWS), 1],
                    )?;
                }
                first += pass;
                if first >= field.count {
                    break;
                }
            }
            Ok(())
        })?;
        let planes: Vec<[f32; 4]> = out.read(ctx, pixels * field.groups as usize)?;
        if let Some(p) = planes.iter().position(|v| v[0].to_bits() == UNWRITTEN) {
            let p = p % pixels;
            return Err(GpuError::Input(format!(
                "pixel ({}, {}) of this field render was not computed: {} ends a shader invocation whose loops run past 65,535 iterations (a field maximum is one pass over every Gaussian its ray meets, and each adds into the samples it covers); use fewer --max-samples, fewer Gaussians, or the CPU reference (--cpu)",
                p % cam.width as usize,
                p / cam.width as usize,
                ctx.info().name
            )));
        }
        let k = field.k;
        let mut features = vec![0f32; pixels * k];
        for (p, px) in features.chunks_exact_mut(k).enumerate() {
            for (c, v) in px.iter_mut().enumerate() {
                *v = planes[(c / 4) * pixels + p][c % 4];
            }
        }
        Ok(crate::core::model::field::frame_from_channels(
            cam.width, cam.height, k, features,
        ))
    }
}
