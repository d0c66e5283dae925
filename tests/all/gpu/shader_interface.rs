//! The shader interface cannot drift: every variant compiled at build time is built by its
//! stage (each pipeline reflects its SPIR-V and refuses bindings or push constants the
//! host does not match, `gpu::reflect::check`), and the records the host lays out
//! (`#[repr(C)]` mirrors in `render/types.rs`, push-constant structs) have the strides and
//! member offsets the compiled shaders use.

use crate::common;

use std::mem::{offset_of, size_of};
use verisplat::cpu::SplatKernel;
use verisplat::gpu::reflect::{check, reflect, Interface};
use verisplat::gpu::scan::ScanPush;
use verisplat::gpu::shader::{
    compile_glsl, prebuilt_variants, shader_spirv, BindingKind, ComputePipeline,
};
use verisplat::gpu::shader_set::MAX_FEATURE_GROUPS;
use verisplat::gpu::sort::{
    SortConfig, SortPassPush, SortSetupPush, DEFAULT_SORT_CONFIG, SORT_CONFIG_32,
};
use verisplat::gpu::{RadixSort, Scan};
use verisplat::render::backward::blend_bwd::BlendBwd;
use verisplat::render::backward::grad_accumulate::{Accumulation, GradAccumulate};
use verisplat::render::backward::preprocess_bwd::PreprocessBwd;
use verisplat::render::backward::shade_bwd::ShadeBwd;
use verisplat::render::forward::blend::{Blend, BlendKernel};
use verisplat::render::forward::features::FeatureBlend;
use verisplat::render::forward::keys::Keys;
use verisplat::render::forward::order::Order;
use verisplat::render::forward::pack::Pack;
use verisplat::render::forward::preprocess::Preprocess;
use verisplat::render::forward::ranges::Ranges;
use verisplat::render::forward::shade::Shade;
use verisplat::render::forward::types::{GpuGaussian, GpuGaussianCompact, Splat};
use verisplat::render::Falloff;

fn interface(shader: &str, defines: &[(&str, &str)]) -> Interface {
    let defines: Vec<(&str, String)> = defines.iter().map(|&(k, v)| (k, v.to_string())).collect();
    let words = shader_spirv(shader, &defines).expect("a prebuilt variant");
    reflect(&words).expect("valid SPIR-V")
}

#[test]
fn every_stage_variant_builds_against_its_compiled_interface() {
    let r = common::gpu::renderer();
    let ctx = r.ctx();
    let mut built = 0;
    for texel in [false, true] {
        for compact in [false, true] {
            for lenses in [false, true] {
                Preprocess::new(ctx, compact, texel, lenses).expect("preprocess");
                built += 1;
            }
        }
        Keys::new(ctx, texel).expect("keys");
        Ranges::new(ctx, texel).expect("ranges");
        built += 2;
        for kernel in SplatKernel::ALL {
            for surface in [false, true] {
                // Each module also with the reproducible mode's specialization (one module).
                for falloff in falloffs(kernel) {
                    FeatureBlend::new(ctx, falloff, texel, surface).expect("feature blend");
                }
                built += 1;
            }
        }
    }
    for save_last in [false, true] {
        for kernel in SplatKernel::ALL {
            for blend in BlendKernel::all() {
                for falloff in falloffs(kernel) {
                    Blend::new(ctx, blend, falloff, save_last).expect("blend");
                }
                built += 1;
            }
        }
    }
    Order::new(ctx).expect("order");
    Scan::new(ctx).expect("scan");
    Pack::new(ctx).expect("pack");
    Shade::new(ctx).expect("shade");
    ShadeBwd::new(ctx, 140, 64).expect("shade backward and its reduce");
    // The loss's five stages, its window also through texel views.
    verisplat::train::loss::GpuLoss::with_texel_fetch(ctx, true).expect("the training loss");
    built += 1 + 3 + 1 + 1 + 2 + 5 + 1;
    // The per-photo colour transform's two passes (`train --appearance affine`).
    verisplat::train::appearance::device::AffinePasses::new(ctx).expect("the appearance passes");
    built += 2;
    // The training step's: the Gaussians' and the shader's (its norm's reduce is the
    // loss's, counted above).
    verisplat::train::device::StepPipelines::new(ctx).expect("the training step's stages");
    built += 2;
    let sorts = [
        DEFAULT_SORT_CONFIG,
        SORT_CONFIG_32,
        SortConfig {
            texel_io: true,
            ..SORT_CONFIG_32
        },
    ];
    for config in sorts {
        RadixSort::with_config(ctx, config).expect("sort");
        built += 4;
    }
    ComputePipeline::from_embedded(
        ctx,
        "count64_test",
        &[],
        &[BindingKind::StorageBuffer],
        &verisplat::core::shader_interface::NO_PUSH_CONSTANTS,
    )
    .expect("count64_test");
    built += 1;
    // The subgroup self-check every context runs.
    verisplat::gpu::subgroup::probe(ctx).expect("the subgroup probe");
    built += 1;
    built += build_backward_variants(ctx);
    // The field renders: every mode and kernel (each pipeline is built by its first frame).
    for kernel in SplatKernel::ALL {
        let mut scene = verisplat::core::scene::Scene::empty(0);
        common::push_gaussian(&mut scene, [0.0, 0.0, 3.0], 0.5, 0.5, [0.5; 3]);
        scene.set_features(1, vec![1.0]).unwrap();
        let g = verisplat::cpu::field::FieldGaussians::new(&scene.activated(), kernel);
        let field = verisplat::render::field::GpuField::new(ctx, &g).expect("field upload");
        let mut renderer = verisplat::render::field::FieldRenderer::new(kernel);
        for mode in [
            verisplat::cpu::field::FieldMode::Slice {
                point: [0.0, 0.0, 3.0],
                normal: [0.0, 0.0, 1.0],
            },
            verisplat::cpu::field::FieldMode::Integral,
            verisplat::cpu::field::FieldMode::Max { samples: 8 },
        ] {
            renderer
                .render(ctx, &field, &common::axis_camera(32.0), &mode)
                .expect("field render");
            built += 1;
        }
    }
    // Every prebuilt module was built above: none is dead weight, none unchecked.
    assert_eq!(built, prebuilt_variants().count());
    common::gpu::assert_validation_clean(&r);
}

/// Builds every backward-pass pipeline variant (both blend layouts and bin sizes, with and
/// without subgroup shuffles, every accumulation, both reads); returns how many.
/// `kernel`'s falloffs: the default mode's and the reproducible mode's (the same module,
/// specialized).
fn falloffs(kernel: SplatKernel) -> [Falloff; 2] {
    [false, true].map(|reproducible| Falloff {
        kernel,
        reproducible,
    })
}

fn build_backward_variants(ctx: &verisplat::gpu::GpuContext) -> usize {
    let mut built = 0;
    // The backward pass: both blend layouts and bin sizes (the per-pixel layout with
    // subgroup shuffles' balanced sums where the device has them, as lavapipe does, and
    // without on a context that pretends not to), every accumulation, both reads.
    let no_shuffle = verisplat::gpu::GpuContext::new(&verisplat::gpu::ContextOptions {
        validation: true,
        emulate: verisplat::gpu::emulate::Emulation::parse("no-subgroup-shuffle").unwrap(),
        ..Default::default()
    })
    .expect("a context without shuffles");
    assert!(!no_shuffle.info().subgroup_shuffle);
    if !ctx.info().subgroup_shuffle {
        eprintln!(
            "no subgroup shuffles on {}: the balanced sums are not built",
            ctx.info().name
        );
    }
    for (bin, rows) in [(8, false), (16, false), (8, true)] {
        for kernel in SplatKernel::ALL {
            for groups in 0..=MAX_FEATURE_GROUPS {
                for falloff in falloffs(kernel) {
                    BlendBwd::new(ctx, bin, rows, falloff, groups).expect("blend backward");
                }
                built += 1;
                if !rows {
                    BlendBwd::new(&no_shuffle, bin, rows, kernel.into(), groups)
                        .expect("blend backward without shuffles");
                    built += 1;
                }
            }
        }
    }
    let msgs = no_shuffle.validation_messages();
    assert!(msgs.is_empty(), "validation messages:\n{}", msgs.join("\n"));
    for mode in [
        Accumulation::Deterministic,
        Accumulation::FloatAtomics,
        Accumulation::CompareAndSwap,
    ] {
        // Float atomics need the device's feature (lavapipe has it).
        if mode != Accumulation::FloatAtomics || ctx.info().float_atomic_add {
            GradAccumulate::new(ctx, mode).expect("accumulation");
            built += 1;
        } else {
            eprintln!(
                "no float atomics on {}: that variant is not built",
                ctx.info().name
            );
            built += 1;
        }
    }
    // The deterministic sums by 64-bit atomics (above, where the device has them) and by
    // 32-bit halves with a carry (a context without them).
    if !ctx.info().int64_atomics {
        eprintln!(
            "no 64-bit atomics on {}: that variant is not built",
            ctx.info().name
        );
    }
    let ctx32 = verisplat::gpu::GpuContext::new(&verisplat::gpu::ContextOptions {
        validation: true,
        emulate: verisplat::gpu::emulate::Emulation::parse("no-int64-atomics").unwrap(),
        ..Default::default()
    })
    .expect("a second context");
    GradAccumulate::new(&ctx32, Accumulation::Deterministic).expect("32-bit accumulation");
    built += 1;
    let msgs = ctx32.validation_messages();
    assert!(msgs.is_empty(), "validation messages:\n{}", msgs.join("\n"));
    for float_sums in [false, true] {
        for lenses in [false, true] {
            PreprocessBwd::new(ctx, float_sums, lenses).expect("preprocess backward");
            built += 1;
        }
    }
    built
}

#[test]
fn a_stage_that_binds_other_kinds_than_its_shader_is_refused() {
    let r = common::gpu::renderer();
    let e = ComputePipeline::from_embedded(
        r.ctx(),
        "count64_test",
        &[],
        &[BindingKind::StorageImage],
        &verisplat::core::shader_interface::NO_PUSH_CONSTANTS,
    )
    .err()
    .expect("a storage buffer bound as an image is refused");
    assert!(e.to_string().contains("binding 0"), "{e}");
}

#[test]
fn record_strides_and_push_constants_match_the_host_structs() {
    for compact in ["0", "1"] {
        let i = interface(
            "preprocess",
            &[
                ("COMPACT_GAUSSIANS", compact),
                ("PREPROCESS_TEXEL_IO", "0"),
                ("LENSES", "1"),
            ],
        );
        let record = match compact {
            "0" => size_of::<GpuGaussian>(),
            _ => size_of::<GpuGaussianCompact>(),
        };
        // Binding 1: the Gaussian records; binding 3: the splats written.
        assert!(i.array_strides.contains(&(1, record as u32)), "{i:?}");
        assert!(
            i.array_strides.contains(&(3, size_of::<Splat>() as u32)),
            "{i:?}"
        );
    }
    let blend = interface(
        "blend",
        &[
            ("STRIP", "1"),
            ("TEXEL_FETCH", "0"),
            ("SPLAT_KERNEL", "0u"),
            ("SAVE_LAST", "0"),
        ],
    );
    assert!(
        blend
            .array_strides
            .contains(&(1, size_of::<Splat>() as u32)),
        "{blend:?}"
    );

    // The field stage: its Gaussian records (binding 1) and its four channels per record
    // and per pixel (bindings 2 and 3, vec4).
    for mode in ["0", "1", "2"] {
        let field = interface("field", &[("FIELD_MODE", mode), ("SPLAT_KERNEL", "0u")]);
        let record = size_of::<verisplat::render::field::FieldGaussian>() as u32;
        for stride in [(1, record), (2, 16), (3, 16)] {
            assert!(field.array_strides.contains(&stride), "{field:?}");
        }
    }

    let scan = interface("scan_block", &[]);
    assert_eq!(
        scan.push_offsets,
        [
            offset_of!(ScanPush, n),
            offset_of!(ScanPush, write_total),
            offset_of!(ScanPush, total_index),
            offset_of!(ScanPush, pad),
        ]
        .map(|o| o as u32)
    );
    assert_eq!(scan.push_size as usize, size_of::<ScanPush>());
    // The stages' own push-constant structs (render/types.rs).
    use verisplat::render::forward::types::{
        BlendPush, FeatureBlendPush, KeysPush, PackPush, WindowPush,
    };
    let pre = interface(
        "preprocess",
        &[
            ("COMPACT_GAUSSIANS", "0"),
            ("PREPROCESS_TEXEL_IO", "1"),
            ("LENSES", "0"),
        ],
    );
    let want = [offset_of!(WindowPush, first), offset_of!(WindowPush, count)];
    assert_eq!(pre.push_offsets, want.map(|o| o as u32));
    assert_eq!(pre.push_size as usize, size_of::<WindowPush>());
    let keys = interface("keys", &[("KEYS_TEXEL_IO", "0")]);
    let want = [
        offset_of!(KeysPush, first),
        offset_of!(KeysPush, end),
        offset_of!(KeysPush, base),
    ];
    assert_eq!(keys.push_offsets, want.map(|o| o as u32));
    assert_eq!(keys.push_size as usize, size_of::<KeysPush>());
    let want = [
        offset_of!(BlendPush, resume),
        offset_of!(BlendPush, last),
        offset_of!(BlendPush, first_tile_row),
        offset_of!(BlendPush, pad),
    ];
    assert_eq!(blend.push_offsets, want.map(|o| o as u32));
    assert_eq!(blend.push_size as usize, size_of::<BlendPush>());
    let features = interface(
        "blend_features",
        &[
            ("SPLAT_KERNEL", "0u"),
            ("TEXEL_FETCH", "1"),
            ("SURFACE", "0"),
        ],
    );
    let want = [
        offset_of!(FeatureBlendPush, resume),
        offset_of!(FeatureBlendPush, pad),
    ];
    assert_eq!(features.push_offsets, want.map(|o| o as u32));
    let pack = interface("pack", &[]);
    let want = [offset_of!(PackPush, width), offset_of!(PackPush, height)];
    assert_eq!(pack.push_offsets, want.map(|o| o as u32));
    assert_eq!(pack.push_size as usize, size_of::<PackPush>());

    let sort = [("SORT_KEY", "uint"), ("SORT_TEXEL_IO", "0")];
    let setup = interface("sort_setup", &sort);
    assert_eq!(
        setup.push_offsets,
        [
            offset_of!(SortSetupPush, host_n),
            offset_of!(SortSetupPush, count_index),
            offset_of!(SortSetupPush, max_n),
            offset_of!(SortSetupPush, max_groups_x),
        ]
        .map(|o| o as u32)
    );
    let pass = interface("sort_scatter", &sort);
    assert_eq!(
        pass.push_offsets,
        [
            offset_of!(SortPassPush, shift),
            offset_of!(SortPassPush, bits),
            offset_of!(SortPassPush, hist_stride),
            offset_of!(SortPassPush, pad),
        ]
        .map(|o| o as u32)
    );
}

#[test]
fn reflection_reads_bindings_push_constants_and_strides_and_catches_drift() {
    use BindingKind::*;
    let source = "#version 460
layout(local_size_x = 64) in;
struct S { vec4 a; vec4 b; float c; };
struct P { uint n; uint pad; vec4 v; };
layout(push_constant) uniform PBlock { P pc; };
layout(std430, binding = 0) buffer A { S items[]; };
layout(binding = 1) uniform usamplerBuffer t;
layout(binding = 2, r32ui) uniform writeonly uimageBuffer o;
layout(binding = 3, rgba32f) uniform writeonly image2D img;
void main() {
uint i = gl_GlobalInvocationID.x;
items[i].a += vec4(float(texelFetch(t, int(i)).x + pc.n)) + pc.v;
imageStore(o, int(i), uvec4(uint(items[i].c)));
imageStore(img, ivec2(i, 0), items[i].b);
}
";
    let words = compile_glsl("reflect_test", source, &[]).expect("compiles");
    let found = reflect(&words).expect("reflects");
    assert_eq!(
        found.bindings,
        vec![
            (0, StorageBuffer),
            (1, UniformTexelBuffer),
            (2, StorageTexelBuffer),
            (3, StorageImage)
        ]
    );
    assert_eq!(found.push_offsets, vec![0, 4, 16]);
    assert_eq!(found.push_size, 32);
    // std430: 36 bytes rounded up to the 16-byte alignment of the vec4 members.
    assert_eq!(found.array_strides, vec![(0, 48)]);
    let host = [
        StorageBuffer,
        UniformTexelBuffer,
        StorageTexelBuffer,
        StorageImage,
    ];
    use verisplat::core::shader_interface::{FieldLayout, RecordLayout};
    const fn field(name: &'static str, ty: &'static str, offset: usize) -> FieldLayout {
        FieldLayout { name, ty, offset }
    }
    const FIELDS: &[FieldLayout] = &[
        field("n", "uint", 0),
        field("pad", "uint", 4),
        field("v", "vec4", 16),
    ];
    const MOVED: &[FieldLayout] = &[
        field("n", "uint", 0),
        field("pad", "uint", 8),
        field("v", "vec4", 16),
    ];
    let p = RecordLayout {
        rust: "P",
        glsl: "P",
        size: 32,
        fields: FIELDS,
    };
    assert!(found.push_is_record);
    assert!(check("t", &words, &host, &p).is_ok());
    // Every kind of drift is caught.
    let wrong_kind = [
        StorageBuffer,
        StorageBuffer,
        StorageTexelBuffer,
        StorageImage,
    ];
    let e = check("t", &words, &wrong_kind, &p).unwrap_err();
    assert!(e.contains("binding 1"), "{e}");
    let e = check("t", &words, &host[..3], &p).unwrap_err();
    assert!(e.contains("binding 3"), "{e}");
    let short = RecordLayout { size: 16, ..p };
    let e = check("t", &words, &host, &short).unwrap_err();
    assert!(e.contains("32 bytes of push constants"), "{e}");
    // A member the host places elsewhere (same size).
    let e = check("t", &words, &host, &RecordLayout { fields: MOVED, ..p }).unwrap_err();
    assert!(e.contains("members are at bytes [0, 4, 16]"), "{e}");
    // A block declared member by member instead of as the record.
    let flat = source.replace(
        "struct P { uint n; uint pad; vec4 v; };\nlayout(push_constant) uniform PBlock { P pc; };",
        "layout(push_constant) uniform PBlock { uint n; uint pad; vec4 v; } pc;",
    );
    assert_ne!(flat, source);
    let flat_words = compile_glsl("reflect_flat", &flat, &[]).expect("compiles");
    let e = check("t", &flat_words, &host, &p).unwrap_err();
    assert!(e.contains("member by member"), "{e}");
    assert!(reflect(&words[..3]).is_err());
}

/// Bindings are named once, by the wing that owns the shader (`gpu::shader_set::bindings`,
/// `render::shaders::bindings`, `train::shaders::bindings`): the shaders use the names'
/// defines, never a literal index, and a stage's list must fill each slot exactly once.
#[test]
fn bindings_are_named_in_the_shaders_and_placed_once_by_the_host() {
    let glsl = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("glsl");
    let literal = regex_free_literal_binding;
    let mut shaders = 0;
    let (_, folders) = verisplat::gpu::shader_set::glsl_tree(&glsl).unwrap();
    let files = folders
        .iter()
        .flat_map(|d| std::fs::read_dir(d).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file());
    for path in files {
        let text = std::fs::read_to_string(&path).unwrap();
        for (i, line) in text.lines().enumerate() {
            assert!(
                !literal(line),
                "{}:{}: a literal binding index: {line}",
                path.display(),
                i + 1
            );
        }
        shaders += 1;
    }
    assert!(shaders >= 16, "{shaders} shader files read");
    let names = verisplat::gpu::shader::all_bindings();
    assert!(names
        .iter()
        .any(|(s, n)| *s == "preprocess" && n.contains(&"SPLATS")));
    // Each wing's table, gathered once, each shader once.
    let wings = [
        verisplat::gpu::shader_set::bindings::ALL,
        verisplat::render::shaders::bindings::ALL,
        verisplat::train::shaders::bindings::ALL,
    ];
    assert_eq!(names.len(), wings.iter().map(|w| w.len()).sum::<usize>());
    for (shader, binding_names) in wings.iter().flat_map(|w| w.iter()) {
        assert_eq!(
            names
                .iter()
                .filter(|(s, n)| s == shader && n == binding_names)
                .count(),
            1,
            "{shader}"
        );
    }
    use verisplat::gpu::shader::by_binding;
    assert_eq!(by_binding([(1, 'b'), (0, 'a')]).unwrap(), ['a', 'b']);
    assert!(by_binding([(0, 'a'), (0, 'b')])
        .unwrap_err()
        .to_string()
        .contains("twice"));
    assert!(by_binding([(0, 'a'), (2, 'b')])
        .unwrap_err()
        .to_string()
        .contains("past"));
}

/// `binding = <digits>` in a GLSL line.
fn regex_free_literal_binding(line: &str) -> bool {
    line.match_indices("binding").any(|(i, _)| {
        let rest = line[i + "binding".len()..].trim_start();
        rest.strip_prefix('=')
            .map(|r| r.trim_start().starts_with(|c: char| c.is_ascii_digit()))
            .unwrap_or(false)
    })
}

/// Every prebuilt module's workgroup size and shared memory can be read from its SPIR-V
/// (so `gpu::workgroup::check_limits` guards every pipeline), and the values are the
/// ones the sources declare for a few known kernels.
#[test]
fn every_modules_workgroup_demand_is_readable() {
    use verisplat::gpu::workgroup::demand;
    for key in prebuilt_variants() {
        let mut parts = key.split(' ');
        let shader = parts.next().expect("a shader name");
        let defines: Vec<(&str, String)> = parts
            .map(|p| {
                let (k, v) = p.split_once('=').expect("NAME=VALUE");
                (k, v.to_string())
            })
            .collect();
        let words = shader_spirv(shader, &defines).expect("prebuilt");
        let d = demand(&words, &[]).unwrap_or_else(|e| panic!("{key}: {e}"));
        assert!(d.invocations >= 1, "{key}: {d:?}");
    }
    let sort = shader_spirv(
        "sort_scatter",
        &[("SORT_KEY", "uint".into()), ("SORT_TEXEL_IO", "0".into())],
    )
    .expect("prebuilt");
    // 64 invocations, 256 digits x 16 subgroups of counters.
    let d = demand(&sort, &[(0, 64), (2, 256), (3, 16)]).expect("readable");
    assert_eq!(d.invocations, 64);
    assert!(d.shared_bytes >= 256 * 16 * 4, "{d:?}");
    let probe = shader_spirv("subgroup_probe", &[]).expect("prebuilt");
    assert_eq!(demand(&probe, &[]).expect("readable").invocations, 128);
}
