//! The backward pass's device buffers: one struct, each buffer made or grown (never shrunk)
//! to what a pass's shape needs ([`BackwardBuffers::ensure`]; the neural shader's with
//! [`BackwardBuffers::ensure_shader`]).

use super::preprocess_bwd::GAUSSIAN_GRAD_BYTES;
use super::shade_bwd::ShadeBwd;
use super::{pixels_bytes, PassShape};
use crate::gpu::{GpuBuffer, GpuContext, GpuResult, MemoryKind};
use crate::render::forward::shade::GpuShader;
use crate::render::frame::buffers::check_binding;

/// Every buffer of the backward pass (`None` until a pass needs it).
#[derive(Default)]
pub(super) struct BackwardBuffers {
    /// dL/d(colour, alpha) per pixel (vec4).
    pub(super) grad_color: Option<GpuBuffer>,
    /// dL/d depth per pixel.
    pub(super) grad_depth: Option<GpuBuffer>,
    /// Each pair's gradient fields, summed over its bin: one buffer per pair band
    /// ([`crate::render::frame::bands`]).
    pub(super) pair_grads: Vec<GpuBuffer>,
    /// Each field's largest magnitude (the fixed-point scale).
    pub(super) maxima: Option<GpuBuffer>,
    /// Each Gaussian's sums, 64-bit fixed point (or float).
    pub(super) acc: Option<GpuBuffer>,
    /// Each Gaussian's [`crate::core::shader_interface::GaussianGrad`].
    pub(super) grads: Option<GpuBuffer>,
    /// dL/d SH coefficient, in the SH texels' layout.
    pub(super) sh_grads: Option<GpuBuffer>,
    /// The Gaussians' feature values (groups of four).
    pub(super) features: Option<GpuBuffer>,
    /// dL/d feature channel per pixel (groups of four).
    pub(super) grad_features: Option<GpuBuffer>,
    /// dL/d feature channel per Gaussian (groups of four).
    pub(super) feature_grads: Option<GpuBuffer>,
    /// The shader's pass: the frame's colour and alpha per pixel.
    pub(super) alpha: Option<GpuBuffer>,
    /// The shader's pass: each workgroup's activations.
    pub(super) scratch: Option<GpuBuffer>,
    /// The shader's pass: partial sums of the parameters' gradients.
    pub(super) partials: Option<GpuBuffer>,
    /// The shader's parameters' gradients.
    pub(super) mlp_grads: Option<GpuBuffer>,
}

/// A device buffer of at least `bytes`, made or grown (never shrunk) as needed, and
/// refused when one binding cannot hold it.
fn ensure<'a>(
    ctx: &GpuContext,
    slot: &'a mut Option<GpuBuffer>,
    name: &str,
    bytes: u64,
) -> GpuResult<&'a GpuBuffer> {
    check_binding(ctx, name, bytes.max(16))?;
    ensure_banded(ctx, slot, name, bytes)
}

/// [`ensure`] for a buffer bound in bands ([`crate::render::frame::bands`] checked them).
fn ensure_banded<'a>(
    ctx: &GpuContext,
    slot: &'a mut Option<GpuBuffer>,
    name: &str,
    bytes: u64,
) -> GpuResult<&'a GpuBuffer> {
    let bytes = bytes.max(16);
    if !matches!(slot, Some(b) if b.size() >= bytes) {
        *slot = None;
        *slot = Some(GpuBuffer::new(ctx, name, bytes, MemoryKind::Device)?);
    }
    Ok(slot.as_ref().expect("made above"))
}

impl BackwardBuffers {
    /// Makes or grows the buffers every pass of `shape` binds.
    pub(super) fn ensure(&mut self, ctx: &GpuContext, shape: &PassShape) -> GpuResult<()> {
        let PassShape {
            n,
            fields: f,
            sh_floats,
            pixels,
            groups,
            bands,
            ..
        } = *shape;
        let g16 = u64::from(groups) * 16;
        let colour = pixels_bytes(pixels as usize, 16);
        let depth = pixels_bytes(pixels as usize, 4);
        // Per pixel, bound in pixel bands.
        for (slot, name, bytes) in [
            (&mut self.grad_color, "pixel colour gradients", colour),
            (&mut self.grad_depth, "pixel depth gradients", depth),
            (
                &mut self.grad_features,
                "pixel feature gradients",
                pixels * g16,
            ),
        ] {
            ensure_banded(ctx, slot, name, bytes)?;
        }
        // Per pair, one buffer per pair band.
        let pair_bands = bands.pair_bands();
        self.pair_grads.truncate(pair_bands.len());
        for (j, &(lo, hi)) in pair_bands.iter().enumerate() {
            let bytes = ((hi - lo) * f * 4).max(16);
            if self.pair_grads.get(j).is_some_and(|b| b.size() >= bytes) {
                continue;
            }
            // Freed before the new one is made, so peak memory is not doubled.
            self.pair_grads.truncate(j);
            let name = format!("pair gradients (band {j})");
            let buffer = GpuBuffer::new(ctx, &name, bytes, MemoryKind::Device)?;
            self.pair_grads.push(buffer);
        }
        for (slot, name, bytes) in [
            (&mut self.maxima, "gradient maxima", f * 4),
            (&mut self.acc, "gradient sums", n * f * 8),
            (
                &mut self.grads,
                "Gaussian gradients",
                n * GAUSSIAN_GRAD_BYTES,
            ),
            (&mut self.sh_grads, "SH gradients", n * sh_floats * 4),
            (&mut self.feature_grads, "feature gradients", n * g16),
            (&mut self.features, "feature values", n * g16),
        ] {
            ensure(ctx, slot, name, bytes)?;
        }
        Ok(())
    }

    /// Makes or grows the buffers the backward pass of `shader` over `pixels` binds.
    pub(super) fn ensure_shader(
        &mut self,
        ctx: &GpuContext,
        shader: &GpuShader,
        pixels: u64,
    ) -> GpuResult<()> {
        for (slot, name, bytes) in [
            (&mut self.alpha, "pixel colour and alpha", pixels * 16),
            (
                &mut self.scratch,
                "shader activations",
                ShadeBwd::scratch_bytes(shader, pixels),
            ),
            (
                &mut self.partials,
                "shader gradient partial sums",
                ShadeBwd::partial_bytes(shader, pixels),
            ),
            (
                &mut self.mlp_grads,
                "shader gradients",
                u64::from(shader.params) * 4,
            ),
        ] {
            ensure(ctx, slot, name, bytes)?;
        }
        Ok(())
    }

    /// Bytes of device memory they hold.
    pub(super) fn device_bytes(&self) -> u64 {
        let pairs: u64 = self.pair_grads.iter().map(|b| b.size()).sum();
        pairs
            + [
                &self.grad_color,
                &self.grad_depth,
                &self.maxima,
                &self.acc,
                &self.grads,
                &self.sh_grads,
                &self.features,
                &self.grad_features,
                &self.feature_grads,
                &self.alpha,
                &self.scratch,
                &self.partials,
                &self.mlp_grads,
            ]
            .iter()
            .map(|b| b.as_ref().map_or(0, |b| b.size()))
            .sum::<u64>()
    }
}
