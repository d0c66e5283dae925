// The train wing's shaders (`glsl/train/`): the loss (SSIM's passes and the fixed-order
// sum), the per-photo colour transforms (`appearance_*`) and the optimiser steps, each shader's named bindings and every variant.
//
// Compiled into the library (`crate::train::shaders`) and into the build script (a
// `#[path]` module of `build.rs`), which compiles the variants: `std` only.

use crate::gpu::shader_set::{bit, shader_bindings, variant, ShaderVariant};

shader_bindings! {
    ssim_prepare { IMAGE, TARGET, PLANES }
    ssim_filter { SRC, DST }
    ssim_map { MOMENTS, IMAGE, TARGET, MAPS, SUMS }
    ssim_grad { FILTERED, IMAGE, TARGET, GRAD }
    loss_reduce { VALUES, SUMS }
    appearance_apply { IMAGE, CORRECTED }
    appearance_grad { IMAGE, GRAD, PARTIALS }
    train_step { STATE, M, V, GRADS, SH_GRADS, SPLATS, STATS, GAUSSIANS, SH, FEATURE_GRADS, FEATURES, FEAT0, FEAT1, FEAT2, FEAT3, NORMS, NORM_TOTAL }
    train_mlp_step { STATE, M, V, GRADS, WORDS, NORMS, NORM_TOTAL }
}

/// Every variant the train wing's passes are built with.
pub fn shader_variants() -> Vec<ShaderVariant> {
    let mut out: Vec<ShaderVariant> = [
        "ssim_prepare",
        "ssim_map",
        "ssim_grad",
        "loss_reduce",
        "appearance_apply",
        "appearance_grad",
        "train_step",
        "train_mlp_step",
    ]
    .into_iter()
    .map(|shader| variant(shader, &[]))
    .collect();
    // The loss's window: through buffers, or texel views (CPU devices).
    for texel in [false, true] {
        out.push(variant("ssim_filter", &[("TEXEL_FETCH", bit(texel))]));
    }
    out
}
