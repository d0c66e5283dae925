//! The renderer's pipelines, each built the first time a frame needs it: a renderer that
//! never renders features builds no feature blend, a command that only uploads builds no
//! pipeline at all, and the compact and power-kernel variants cost nothing until used.

use crate::gpu::sort::{SortConfig, SORT_CONFIG_32};
use crate::gpu::{GpuContext, GpuError, GpuResult, RadixSort, Scan};

use crate::render::forward::blend::{Blend, BlendKernel, Falloff};
use crate::render::forward::features::FeatureBlend;
use crate::render::forward::keys::Keys;
use crate::render::forward::order::Order;
use crate::render::forward::pack::Pack;
use crate::render::forward::preprocess::Preprocess;
use crate::render::forward::ranges::Ranges;
use crate::render::forward::shade::Shade;

/// What one frame records, so what it needs built.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FrameNeeds {
    /// 32-byte compact records (the compact preprocess variant).
    pub compact: bool,
    /// A lens other than the pinhole (the preprocess variant of every lens).
    pub lens: bool,
    /// The alpha falloff (a blend pipeline each).
    pub falloff: Falloff,
    /// Feature channels are blended.
    pub features: bool,
    /// The features are the surface pass's axes (the feature blend's surface variant).
    pub surface: bool,
    /// The neural shader runs.
    pub shade: bool,
    /// Colour is packed to RGBA8 on the device.
    pub pack: bool,
    /// The blend also saves each pixel's last contributor (a frame in one piece whose
    /// forward state a backward pass reads).
    pub save_last: bool,
}

impl FrameNeeds {
    /// The index of its preprocess variant.
    fn preprocess_variant(&self) -> usize {
        usize::from(self.compact) + 2 * usize::from(self.lens)
    }
}

/// Every pipeline the renderer may use, built on first use.
pub(crate) struct Pipelines {
    kernel: BlendKernel,
    /// By [`FrameNeeds::compact`] and [`FrameNeeds::lens`] (`compact + 2 lens`).
    preprocess: [Option<Preprocess>; 4],
    order: Option<Order>,
    scan: Option<Scan>,
    keys: Option<Keys>,
    sort: Option<RadixSort>,
    ranges: Option<Ranges>,
    /// By `save_last`, then [`Falloff::index`].
    blend: [[Option<Blend>; 4]; 2],
    /// By [`FrameNeeds::surface`], then [`Falloff::index`].
    feature_blend: [[Option<FeatureBlend>; 4]; 2],
    shade: Option<Shade>,
    pack: Option<Pack>,
    /// Pipelines built so far, and the milliseconds it took.
    built: (u32, f64),
}

/// The pipelines one frame records with.
#[derive(Clone, Copy)]
pub(crate) struct FramePipelines<'a> {
    pub preprocess: &'a Preprocess,
    pub order: &'a Order,
    pub scan: &'a Scan,
    pub keys: &'a Keys,
    pub sort: &'a RadixSort,
    pub ranges: &'a Ranges,
    pub blend: &'a Blend,
    pub feature_blend: Option<&'a FeatureBlend>,
    pub shade: Option<&'a Shade>,
    pub pack: Option<&'a Pack>,
}

/// Builds `slot`'s pipeline with `make` unless it is there already, counting it in
/// `built`.
fn ensure<T>(
    built: &mut (u32, f64),
    slot: &mut Option<T>,
    make: impl FnOnce() -> GpuResult<T>,
) -> GpuResult<()> {
    if slot.is_none() {
        let start = std::time::Instant::now();
        *slot = Some(make()?);
        built.0 += 1;
        built.1 += start.elapsed().as_secs_f64() * 1e3;
    }
    Ok(())
}

fn built<'a, T>(slot: &'a Option<T>, what: &str) -> GpuResult<&'a T> {
    slot.as_ref()
        .ok_or_else(|| GpuError::Internal(format!("the {what} pipeline was not built")))
}

impl Pipelines {
    /// No pipeline yet; texel I/O on every stage when the blend kernel reads texel views
    /// (CPU devices).
    pub fn new(kernel: BlendKernel) -> Self {
        Pipelines {
            kernel,
            preprocess: [None, None, None, None],
            order: None,
            scan: None,
            keys: None,
            sort: None,
            ranges: None,
            blend: Default::default(),
            feature_blend: Default::default(),
            shade: None,
            pack: None,
            built: (0, 0.0),
        }
    }

    /// Pipelines built so far and the milliseconds building them took (driver compiles
    /// included).
    pub fn built(&self) -> (u32, f64) {
        self.built
    }

    /// The blend kernel every frame uses.
    pub fn kernel(&self) -> BlendKernel {
        self.kernel
    }

    /// Whether the stages read and write texel views (CPU devices).
    pub fn texel_io(&self) -> bool {
        self.kernel.texel()
    }

    /// Builds what a frame with `needs` records and is not built yet.
    pub fn prepare(&mut self, ctx: &GpuContext, needs: FrameNeeds) -> GpuResult<()> {
        let texel = self.texel_io();
        let kernel = self.kernel;
        let (compact, lens) = (needs.compact, needs.lens);
        ensure(
            &mut self.built,
            &mut self.preprocess[needs.preprocess_variant()],
            || Preprocess::new(ctx, compact, texel, lens),
        )?;
        ensure(&mut self.built, &mut self.order, || Order::new(ctx))?;
        ensure(&mut self.built, &mut self.scan, || Scan::new(ctx))?;
        ensure(&mut self.built, &mut self.keys, || Keys::new(ctx, texel))?;
        // Texel-view I/O where the blend reads texel views too (CPU devices).
        ensure(&mut self.built, &mut self.sort, || {
            RadixSort::with_config(
                ctx,
                SortConfig {
                    texel_io: texel,
                    ..SORT_CONFIG_32
                },
            )
        })?;
        ensure(&mut self.built, &mut self.ranges, || {
            Ranges::new(ctx, texel)
        })?;
        let id = needs.falloff.index();
        let save = usize::from(needs.save_last);
        let blend = match needs.falloff.reproducible {
            true => kernel.reproducible(ctx.info()),
            false => kernel,
        };
        ensure(&mut self.built, &mut self.blend[save][id], || {
            Blend::new(ctx, blend, needs.falloff, needs.save_last)
        })?;
        if needs.features {
            let surface = needs.surface;
            ensure(
                &mut self.built,
                &mut self.feature_blend[usize::from(surface)][id],
                || FeatureBlend::new(ctx, needs.falloff, texel, surface),
            )?;
        }
        if needs.shade {
            ensure(&mut self.built, &mut self.shade, || Shade::new(ctx))?;
        }
        if needs.pack {
            ensure(&mut self.built, &mut self.pack, || Pack::new(ctx))?;
        }
        Ok(())
    }

    /// The pipelines of a frame with `needs` ([`Self::prepare`]d before).
    pub fn frame(&self, needs: FrameNeeds) -> GpuResult<FramePipelines<'_>> {
        let id = needs.falloff.index();
        Ok(FramePipelines {
            preprocess: built(&self.preprocess[needs.preprocess_variant()], "preprocess")?,
            order: built(&self.order, "depth order")?,
            scan: built(&self.scan, "scan")?,
            keys: built(&self.keys, "keys")?,
            sort: built(&self.sort, "sort")?,
            ranges: built(&self.ranges, "ranges")?,
            blend: built(&self.blend[usize::from(needs.save_last)][id], "blend")?,
            feature_blend: match needs.features {
                true => Some(built(
                    &self.feature_blend[usize::from(needs.surface)][id],
                    "feature blend",
                )?),
                false => None,
            },
            shade: match needs.shade {
                true => Some(built(&self.shade, "neural shader")?),
                false => None,
            },
            pack: match needs.pack {
                true => Some(built(&self.pack, "pack")?),
                false => None,
            },
        })
    }
}
