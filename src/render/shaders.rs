// The render wing's shaders (`glsl/render/`): the forward stages (`forward/`), the backward
// stages (`backward/`) and the field renders (`field/`), each shader's named bindings and
// every variant its stages are built with.
//
// Compiled into the library (`crate::render::shaders`) and into the build script (a
// `#[path]` module of `build.rs`), which compiles the variants: `std` only.

use crate::gpu::shader_set::{bit, shader_bindings, variant, ShaderVariant};
use crate::gpu::shader_set::{MAX_FEATURE_GROUPS, STRIPS};

shader_bindings! {
    preprocess { PARAMS, GAUSSIANS, SH, SPLATS, RECTS, DEPTH_KEYS, COUNTERS, DEPTH_VALUES, BIN_MASKS, TOUCHED }
    order { PARAMS, DEPTH_ORDER, TOUCHED, TOUCHED_IN_ORDER }
    keys { PARAMS, SPLAT_TEXELS, RECTS, OFFSETS, KEYS, VALUES, COUNTERS, DEPTH_ORDER, BIN_MASKS }
    ranges { KEYS, RANGES, COUNTERS }
    blend { PARAMS, SPLATS, VALUES, RANGES, COLOR, DEPTH, COUNTERS, LAST }
    blend_features { PARAMS, SPLATS, VALUES, RANGES, FEATURES, OUTPUT, COUNTERS, COLOR_STATE }
    pack { COLOR, PACKED }
    shade { WORDS, FEATURES, COLOR }
    count64_test { COUNT }
    blend_bwd { PARAMS, SPLATS, VALUES, RANGES, LAST, GRAD_COLOR, GRAD_DEPTH, PAIR_GRADS, MAXIMA, FEATURES, GRAD_FEATURES }
    grad_accumulate { VALUES, PAIR_GRADS, MAXIMA, ACC }
    preprocess_bwd { PARAMS, GAUSSIANS, SH, SPLATS, MAXIMA, ACC, GRADS, SH_GRADS, FEATURE_GRADS }
    shade_bwd { WORDS, FEATURES, ALPHA, GRAD_COLOR, GRAD_FEATURES, SCRATCH, PARTIALS }
    mlp_grad_reduce { PARTIALS, GRADS }
    field { PARAMS, GAUSSIANS, FEATURES, OUTPUT }
}

/// SplatKernel::shader_id values: 0 Gaussian, 1 power.
const SPLAT_KERNELS: [&str; 2] = ["0u", "1u"];

/// Every variant the render wing's stages are built with: each boolean or enumerated
/// choice a stage is built with.
pub fn shader_variants() -> Vec<ShaderVariant> {
    let mut out: Vec<ShaderVariant> = [
        "order",
        "pack",
        "shade",
        "shade_bwd",
        "mlp_grad_reduce",
        "count64_test",
    ]
    .into_iter()
    .map(|shader| variant(shader, &[]))
    .collect();
    out.extend(forward_variants());
    out.extend(backward_variants());
    // Field renders: slice, integral, maximum (cpu::field::FieldMode::shader_id) per kernel.
    for mode in ["0", "1", "2"] {
        for kernel in SPLAT_KERNELS {
            out.push(variant(
                "field",
                &[
                    ("FIELD_MODE", mode.to_string()),
                    ("SPLAT_KERNEL", kernel.to_string()),
                ],
            ));
        }
    }
    out
}

/// The forward stages' variants: preprocess, keys, ranges and the feature blend through
/// buffers or texel views (CPU devices); the blend kernels.
fn forward_variants() -> Vec<ShaderVariant> {
    let mut out = Vec::new();
    for texel in [false, true] {
        for compact in [false, true] {
            for lenses in [false, true] {
                out.push(variant(
                    "preprocess",
                    &[
                        ("COMPACT_GAUSSIANS", bit(compact)),
                        ("PREPROCESS_TEXEL_IO", bit(texel)),
                        ("LENSES", bit(lenses)),
                    ],
                ));
            }
        }
        out.push(variant("keys", &[("KEYS_TEXEL_IO", bit(texel))]));
        out.push(variant("ranges", &[("RANGES_TEXEL_IO", bit(texel))]));
        for kernel in SPLAT_KERNELS {
            // The feature channels, or the surface pass (normals and median depth).
            for surface in [false, true] {
                out.push(variant(
                    "blend_features",
                    &[
                        ("SPLAT_KERNEL", kernel.to_string()),
                        ("TEXEL_FETCH", bit(texel)),
                        ("SURFACE", bit(surface)),
                    ],
                ));
            }
        }
    }
    // The shared kernel (one pixel per invocation, buffers) and the texel strips, each
    // also saving the last contributor (frames a backward pass reads).
    for save_last in [false, true] {
        for kernel in SPLAT_KERNELS {
            let kernels = std::iter::once((1, false)).chain(STRIPS.map(|strip| (strip, true)));
            for (strip, texel) in kernels {
                out.push(variant(
                    "blend",
                    &[
                        ("STRIP", strip.to_string()),
                        ("TEXEL_FETCH", bit(texel)),
                        ("SPLAT_KERNEL", kernel.to_string()),
                        ("SAVE_LAST", bit(save_last)),
                    ],
                ));
            }
        }
    }
    out
}

/// The backward pass's variants: the blend's per bin size (8: CPU devices, 16: GPUs) and
/// kernel; the accumulation in fixed point or (the fast mode) with float atomics, native
/// or by compare-and-swap; the preprocess's reading either.
fn backward_variants() -> Vec<ShaderVariant> {
    let mut out = Vec::new();
    // The per-pixel layout (strip 1) with subgroup shuffles' balanced tree (canonical 1) or
    // the driver's subgroup sums (0); the row layout (strip 8).
    for (bin, strip, canonical) in [
        ("8u", 1, 0),
        ("8u", 1, 1),
        ("16u", 1, 0),
        ("16u", 1, 1),
        ("8u", 8, 0),
    ] {
        for kernel in SPLAT_KERNELS {
            for groups in 0..=MAX_FEATURE_GROUPS {
                out.push(variant(
                    "blend_bwd",
                    &[
                        ("BIN", bin.to_string()),
                        ("STRIP", strip.to_string()),
                        ("SPLAT_KERNEL", kernel.to_string()),
                        ("FEATURE_GROUPS", groups.to_string()),
                        ("CANONICAL_SUM", canonical.to_string()),
                    ],
                ));
            }
        }
    }
    for (float, cas, int64) in [
        (false, false, false),
        (false, false, true),
        (true, false, false),
        (true, true, false),
    ] {
        out.push(variant(
            "grad_accumulate",
            &[
                ("FLOAT_ATOMICS", bit(float)),
                ("CAS_FALLBACK", bit(cas)),
                ("INT64_ATOMICS", bit(int64)),
            ],
        ));
    }
    for float in [false, true] {
        for lenses in [false, true] {
            out.push(variant(
                "preprocess_bwd",
                &[("FLOAT_ATOMICS", bit(float)), ("LENSES", bit(lenses))],
            ));
        }
    }
    out
}
