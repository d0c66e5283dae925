//! Blend stage (`glsl/render/forward/blend.comp`): one 16x16 workgroup per tile, writing colour+alpha and
//! depth storage images.

use crate::core::model::SplatKernel;
use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuImage, GpuResult};
use crate::render::shaders::bindings::blend as slot;
use ash::vk;

/// Shared memory of the shared kernel per pixel of a tile: one staged Gaussian's mean and
/// opacity, conic and colour (three vec4s, `glsl/render/forward/blend.comp`).
const SHARED_KERNEL_BYTES_PER_PIXEL: u32 = 48;

/// Which blend kernel to build. Both composite with the same per-pixel arithmetic.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlendKernel {
    /// One invocation per pixel; the tile's Gaussians are fetched into shared memory in
    /// batches of 256 and the workgroup stops when every pixel is finished. For GPUs.
    Shared,
    /// One invocation per `strip` pixels of a row, reading Gaussians through texel-buffer
    /// fetches (no shared memory, no barriers); an invocation stops when its pixels are
    /// finished. For CPU implementations such as lavapipe, where loop-indexed buffer and
    /// shared-memory loads become per-lane scalar loops but texel fetches do not.
    Texel {
        /// Pixels per invocation: 1, 2, 4, 8 or 16.
        strip: u32,
    },
}

/// Supported strip lengths of [`BlendKernel::Texel`] (a strip never crosses an 8-pixel bin;
/// each has a module compiled at build time).
pub use crate::gpu::shader_set::STRIPS;

impl BlendKernel {
    /// The kernel for a device: [`BlendKernel::Shared`] on GPUs, texel fetches with two
    /// pixels per invocation on CPU devices (fastest on lavapipe, see BENCHMARKS.md) and
    /// on GPUs whose workgroups cannot hold a 16x16 tile (fewer than 256 invocations or
    /// 12 KiB of shared memory: the texel kernel's 8x8 bins need 32 invocations and no
    /// shared memory). `VERISPLAT_BLEND` (`shared`, `texel` or `texel:N`) overrides.
    pub fn for_device(ctx: &GpuContext) -> BlendKernel {
        if let Some(k) =
            crate::core::former_name::env_var("VERISPLAT_BLEND").and_then(|v| v.parse().ok())
        {
            return k;
        }
        let info = ctx.info();
        if info.device_type == vk::PhysicalDeviceType::CPU || !BlendKernel::Shared.fits(info) {
            BlendKernel::Texel { strip: 2 }
        } else {
            BlendKernel::Shared
        }
    }

    /// Whether the device's workgroups can hold the kernel: a 16x16 tile for the shared
    /// kernel (256 invocations, 12 KiB of shared memory), 16 / strip x 16 invocations for
    /// a texel kernel.
    pub fn fits(self, info: &crate::gpu::DeviceInfo) -> bool {
        let tile = crate::core::rules::TILE_SIZE * crate::core::rules::TILE_SIZE;
        match self {
            BlendKernel::Shared => {
                info.max_workgroup_invocations >= tile
                    && info.max_shared_memory >= SHARED_KERNEL_BYTES_PER_PIXEL * tile + 4
            }
            BlendKernel::Texel { strip } => info.max_workgroup_invocations >= tile / strip,
        }
    }

    /// The kernel the reproducible mode blends with in place of this one: the one-pixel
    /// texel kernel in place of the longer strips where the device's workgroups hold it.
    /// lavapipe computes a strip's later pixels with different roundings in rare pixels
    /// (a few in 100,000 colour values differ by an ulp; not understood yet), which the
    /// one-pixel strip does not (docs/reproducibility.md).
    pub fn reproducible(self, info: &crate::gpu::DeviceInfo) -> BlendKernel {
        let one = BlendKernel::Texel { strip: 1 };
        match self {
            BlendKernel::Texel { strip } if strip > 1 && one.fits(info) => one,
            other => other,
        }
    }

    /// Every supported kernel (for tests and benchmarks).
    pub fn all() -> Vec<BlendKernel> {
        std::iter::once(BlendKernel::Shared)
            .chain(STRIPS.iter().map(|&strip| BlendKernel::Texel { strip }))
            .collect()
    }

    /// Side of the pixel bins the pairs are keyed by: the reference's 16x16 tiles for the
    /// shared kernel (one list per workgroup); 8x8 quarters for the texel kernel, whose
    /// invocations each read their own list, so shorter lists per pixel block pay for the
    /// extra pairs (measured on lavapipe: see BENCHMARKS.md).
    pub fn bin_size(self) -> u32 {
        match self {
            BlendKernel::Shared => 16,
            BlendKernel::Texel { .. } => 8,
        }
    }

    /// Whether the kernel reads the splats and values through texel views (CPU devices).
    pub fn texel(self) -> bool {
        matches!(self, BlendKernel::Texel { .. })
    }

    fn strip(self) -> u32 {
        match self {
            BlendKernel::Shared => 1,
            BlendKernel::Texel { strip } => strip,
        }
    }
}

/// The kernel as `VERISPLAT_BLEND` names it: `shared` or `texel:N`.
impl std::fmt::Display for BlendKernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BlendKernel::Shared => write!(f, "shared"),
            BlendKernel::Texel { strip } => write!(f, "texel:{strip}"),
        }
    }
}

impl std::str::FromStr for BlendKernel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "shared" => Ok(BlendKernel::Shared),
            "texel" => Ok(BlendKernel::Texel { strip: 1 }),
            other => other
                .strip_prefix("texel:")
                .and_then(|n| n.parse::<u32>().ok())
                .filter(|n| STRIPS.contains(n))
                .map(|strip| BlendKernel::Texel { strip })
                .ok_or_else(|| format!("unknown blend kernel {other:?}; use shared, texel or texel:N (N in {STRIPS:?})")),
        }
    }
}

/// The blends' alpha formula: the splat kernel and the arithmetic (the reproducible
/// mode's portable exp and unfused operations, [`crate::core::model::RenderOptions::reproducible`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Falloff {
    /// The splat kernel (`SPLAT_KERNEL`, a variant each).
    pub kernel: SplatKernel,
    /// The reproducible mode (`REPRODUCIBLE`, a specialization constant).
    pub reproducible: bool,
}

impl From<SplatKernel> for Falloff {
    fn from(kernel: SplatKernel) -> Self {
        Falloff {
            kernel,
            reproducible: false,
        }
    }
}

impl Falloff {
    /// The falloff a frame with `opts` blends with.
    pub fn of(opts: &crate::core::model::RenderOptions) -> Self {
        Falloff {
            kernel: opts.kernel,
            reproducible: opts.reproducible,
        }
    }

    /// Its pipelines' slot: the kernel's shader id, plus 2 when reproducible.
    pub fn index(self) -> usize {
        self.kernel.shader_id() as usize + 2 * usize::from(self.reproducible)
    }

    /// The specialization constant a blend pipeline is built with.
    pub fn specialization(self) -> [(u32, u32); 1] {
        [(
            crate::gpu::shader_set::REPRODUCIBLE_SPEC,
            u32::from(self.reproducible),
        )]
    }
}

/// The blend pipeline, for one [`BlendKernel`] and one alpha falloff ([`SplatKernel`],
/// compiled in as `SPLAT_KERNEL`).
pub struct Blend {
    pipeline: ComputePipeline,
    kernel: BlendKernel,
    falloff: Falloff,
    save_last: bool,
}

/// Resources the stage reads and writes.
pub struct BlendBindings<'a> {
    /// FrameParams.
    pub params: BufferSlice<'a>,
    /// Splats.
    pub splats: BufferSlice<'a>,
    /// Sorted values (Gaussian indices).
    pub values: BufferSlice<'a>,
    /// Texel view of `splats` (R32G32B32A32_SFLOAT), for the texel kernel.
    pub splat_texels: Option<vk::BufferView>,
    /// Texel view of `values` (R32_UINT), for the texel kernel.
    pub value_texels: Option<vk::BufferView>,
    /// Tile ranges.
    pub ranges: BufferSlice<'a>,
    /// rgba32f colour + alpha image (written, GENERAL layout).
    pub color: &'a GpuImage,
    /// r32f depth image (written, GENERAL layout).
    pub depth: &'a GpuImage,
    /// Counters (loop lengths reported).
    pub counters: BufferSlice<'a>,
    /// Resume each pixel from the state a previous chunk left in the images.
    pub resume: bool,
    /// Write the final pixels (else the state for the next chunk).
    pub last: bool,
    /// One u32 per pixel: one past the sorted-pair index of its last composited Gaussian
    /// (0: none); bound by (and only by) a pipeline built with `save_last`. It starts at
    /// the first pixel row of `first_tile_row`.
    pub last_contributor: Option<BufferSlice<'a>>,
    /// The first tile row of the dispatch (0 but for a frame saved in bands).
    pub first_tile_row: u32,
}

impl Blend {
    /// Compiles the shader for `kernel` with `falloff`; `save_last` also writes each
    /// pixel's last contributor (`SAVE_LAST`, for a backward pass).
    pub fn new(
        ctx: &GpuContext,
        kernel: BlendKernel,
        falloff: Falloff,
        save_last: bool,
    ) -> GpuResult<Self> {
        use BindingKind::{StorageBuffer as B, StorageImage as I, UniformTexelBuffer as T};
        if !STRIPS.contains(&kernel.strip()) {
            return Err(crate::gpu::GpuError::InvalidArgument(format!(
                "blend strip {} is not one of {STRIPS:?}",
                kernel.strip()
            )));
        }
        let defines = [
            ("STRIP", kernel.strip().to_string()),
            ("TEXEL_FETCH", u32::from(kernel.texel()).to_string()),
            ("SPLAT_KERNEL", format!("{}u", falloff.kernel.shader_id())),
            ("SAVE_LAST", u32::from(save_last).to_string()),
        ];
        let read = if kernel.texel() { T } else { B };
        let mut bindings = by_binding([
            (slot::PARAMS, B),
            (slot::SPLATS, read),
            (slot::VALUES, read),
            (slot::RANGES, B),
            (slot::COLOR, I),
            (slot::DEPTH, I),
            (slot::COUNTERS, B),
            (slot::LAST, B),
        ])?
        .to_vec();
        if !save_last {
            bindings.truncate(slot::LAST as usize);
        }
        let pipeline = ComputePipeline::from_embedded_specialized(
            ctx,
            "blend",
            &defines,
            &bindings,
            &crate::render::forward::types::BlendPush::LAYOUT,
            &falloff.specialization(),
        )?;
        Ok(Blend {
            pipeline,
            kernel,
            falloff,
            save_last,
        })
    }

    /// The kernel in use.
    pub fn kernel(&self) -> BlendKernel {
        self.kernel
    }

    /// The alpha falloff compiled in.
    pub fn falloff(&self) -> Falloff {
        self.falloff
    }

    /// Whether the kernel reads texel-buffer views of the splats and values.
    pub fn needs_texel_views(&self) -> bool {
        self.kernel.texel()
    }

    /// Records one workgroup per tile of `tiles` (columns, rows from `b.first_tile_row`;
    /// the tile grid is at most 1024x1024).
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &BlendBindings,
        tiles: (u32, u32),
    ) -> GpuResult<()> {
        let (splats, values) = match (self.kernel, b.splat_texels, b.value_texels) {
            (BlendKernel::Shared, _, _) => (Resource::Buffer(b.splats), Resource::Buffer(b.values)),
            (_, Some(s), Some(v)) => (Resource::TexelBuffer(s), Resource::TexelBuffer(v)),
            _ => {
                return Err(crate::gpu::GpuError::Internal(
                    "the texel blend kernel needs texel views of the splats and values".into(),
                ))
            }
        };
        // The last-contributor buffer is bound exactly when the pipeline writes it.
        let last = match (self.save_last, b.last_contributor) {
            (true, Some(l)) => l,
            // Any buffer: the slot is cut off below for a pipeline without it.
            (false, None) => b.counters,
            _ => {
                return Err(crate::gpu::GpuError::Internal(
                    "the last-contributor buffer must be bound exactly when the blend saves it"
                        .into(),
                ))
            }
        };
        let all = by_binding([
            (slot::PARAMS, Resource::Buffer(b.params)),
            (slot::SPLATS, splats),
            (slot::VALUES, values),
            (slot::RANGES, Resource::Buffer(b.ranges)),
            (
                slot::COLOR,
                Resource::Image {
                    view: b.color.view(),
                    layout: vk::ImageLayout::GENERAL,
                },
            ),
            (
                slot::DEPTH,
                Resource::Image {
                    view: b.depth.view(),
                    layout: vk::ImageLayout::GENERAL,
                },
            ),
            (slot::COUNTERS, Resource::Buffer(b.counters)),
            (slot::LAST, Resource::Buffer(last)),
        ])?;
        let resources = if self.save_last {
            &all[..]
        } else {
            &all[..slot::LAST as usize]
        };
        self.pipeline.dispatch_resources(
            ctx,
            cmd,
            resources,
            bytemuck::bytes_of(&crate::render::forward::types::BlendPush {
                resume: u32::from(b.resume),
                last: u32::from(b.last),
                first_tile_row: b.first_tile_row,
                pad: 0,
            }),
            [tiles.0, tiles.1, 1],
        )
    }
}
