// The shader machinery every wing shares, and the `gpu` wing's own shaders: the constants
// the shaders share with the host, the binding-name macro ([`shader_bindings!`]), the
// variants of the scan, the sort and the subgroup probe (`glsl/gpu/`), and the one
// GLSL -> SPIR-V compile call (Khronos' `glslc`, shaderc's command line). The render and
// train wings list their own shaders' bindings and variants beside their code
// (`src/render/shaders.rs`, `src/train/shaders.rs`; their GLSL in `glsl/render/` and
// `glsl/train/`).
//
// These files are compiled twice: into the library and into the build script (`#[path]`
// modules of `build.rs`), which compiles every variant to SPIR-V and embeds it, so no
// binary or test links a GLSL compiler. They therefore use `std` only. Runtime
// compilation exists only for shader development (`VERISPLAT_GLSL_DIR`), through the same
// [`compile_glsl_file`].

/// Invocations of every one-dimensional kernel's workgroup (preprocess, order, keys,
/// ranges, the backward's accumulation and preprocess, the training step): the Vulkan
/// specification's guaranteed `maxComputeWorkGroupInvocations`, so they run on any device.
pub const LINEAR_WG: u32 = 128;
/// Invocations of the backward pass's per-pair and per-Gaussian kernels where the device
/// allows them ([`crate::gpu::workgroup::wide_linear_workgroup`]; else [`LINEAR_WG`]):
/// measured 20-25 % faster than 128 on lavapipe (BENCHMARKS.md).
pub const WIDE_WG: u32 = 256;
/// Specialization constant id of those kernels' workgroup size (`local_size_x_id`).
pub const WIDE_WG_SPEC: u32 = 101;
/// Pixels one invocation of the loss's SSIM window (`ssim_filter`) filters, consecutive
/// along its axis.
pub const SSIM_FILTER_RUN: u32 = 8;
/// Width of the image-grid workgroup of the per-pixel stages (`pack`, `shade`,
/// `blend_features`, the field renders): one invocation per pixel of a
/// [`PIXEL_WG_X`] x [`PIXEL_WG_Y`] block.
pub const PIXEL_WG_X: u32 = 16;
/// Height of the per-pixel stages' workgroup ([`PIXEL_WG_X`] x 8 = 128 invocations, the
/// specification's guaranteed minimum of `maxComputeWorkGroupInvocations`).
pub const PIXEL_WG_Y: u32 = 8;
/// Invocations per workgroup of the training loss's per-pixel passes (`loss_common.glsl`),
/// one per pixel, the workgroups laid out in two dimensions.
pub const LOSS_WG: u32 = 64;
/// Invocations per workgroup of the loss's fixed-order sum (`loss_reduce`).
pub const REDUCE_WG: u32 = 128;
/// Values each `loss_reduce` invocation adds, strided by [`REDUCE_WG`].
pub const REDUCE_ITEMS: u32 = 32;
/// Values one `loss_reduce` workgroup sums.
pub const REDUCE_SPAN: u32 = REDUCE_WG * REDUCE_ITEMS;
/// Invocations per workgroup of the appearance transform's gradient (`appearance_grad`):
/// a fixed-shape tree in shared memory, no subgroup operations, so that its partial sums
/// are the same bits at every subgroup size.
pub const APPEARANCE_WG: u32 = 128;
/// Pixels each `appearance_grad` invocation adds, strided by [`APPEARANCE_WG`].
pub const APPEARANCE_ITEMS: u32 = 8;
/// Pixels one `appearance_grad` workgroup sums.
pub const APPEARANCE_SPAN: u32 = APPEARANCE_WG * APPEARANCE_ITEMS;
/// Invocations per workgroup of the neural shader's gradient sum (`mlp_grad_reduce`), one
/// per parameter.
pub const MLP_REDUCE_WG: u32 = 64;
/// Invocations per scan workgroup (the specification's guaranteed minimum of
/// `maxComputeWorkGroupInvocations`).
pub const SCAN_WG: u32 = 128;
/// Consecutive elements each scan invocation handles.
pub const SCAN_ITEMS: u32 = 32;
/// Elements per scan workgroup (block).
pub const SCAN_BLOCK: u32 = SCAN_WG * SCAN_ITEMS;

/// Radix sort meta buffer: u32 index of the element count.
pub const META_N: u32 = 0;
/// Radix sort meta buffer: u32 index of the block count.
pub const META_BLOCKS: u32 = 1;
/// Radix sort meta buffer: u32 index of the indirect dispatch arguments (x, y, z).
pub const META_DISPATCH: u32 = 2;

/// Pixels per blend invocation that a texel blend kernel may be built for.
pub const STRIPS: [u32; 4] = [1, 2, 4, 8];

/// Gradient fields the blend backward writes per (bin, Gaussian) pair and the accumulation
/// sums per Gaussian: 2D mean (2), conic (3), opacity, colour (3), depth, |2D mean| (2).
pub const GRAD_FIELDS: u32 = 12;
/// Groups of four direct feature channels the backward pass differentiates at most (16
/// channels).
pub const MAX_FEATURE_GROUPS: u32 = 4;
/// Fields per pair at most: [`GRAD_FIELDS`] and four per feature group.
pub const MAX_GRAD_FIELDS: u32 = GRAD_FIELDS + 4 * MAX_FEATURE_GROUPS;
/// Specialization constant id of the blends' reproducible mode (`splat_common.glsl`'s
/// `REPRODUCIBLE`: the portable exp, unfused arithmetic; docs/reproducibility.md).
pub const REPRODUCIBLE_SPEC: u32 = 102;
/// Specialization constant id of the most subgroups a blend-backward workgroup may have.
pub const GRAD_SPEC_MAX_SUBGROUPS: u32 = 0;
/// Specialization constant id of the pairs a blend-backward workgroup stages at a time.
pub const GRAD_SPEC_BATCH: u32 = 1;
/// Specialization constant id of whether the blend backward's row layout runs its
/// workgroup as one subgroup (otherwise its rows' sums go through shared memory).
pub const GRAD_SPEC_ROWS_SUBGROUP: u32 = 2;
/// Pixels per chunk of the neural shader's backward pass (`glsl/render/backward/shade_bwd.comp`'s
/// `PIXELS`): one per invocation of its workgroup; the parameters' gradients are summed
/// over a chunk.
pub const SHADE_CHUNK_PIXELS: u32 = 64;
/// Specialization constant id of the values a pixel's neural-shader evaluation keeps
/// (every layer's inputs and the last layer's outputs), the shader backward's private array.
pub const SHADE_SPEC_ACTIVATIONS: u32 = 0;
/// Specialization constant id of the neural shader's widest layer (inputs or outputs).
pub const SHADE_SPEC_WIDEST: u32 = 1;

/// Specialization constant id of the subgroup size every shader uses in place of
/// `gl_SubgroupSize` when the driver's differs from what runs (`common.glsl`'s
/// `SUBGROUP_SIZE`; [`crate::gpu::subgroup`]); 0, the default, means `gl_SubgroupSize`.
/// Far from the stages' own ids (0-3), which every pipeline may also carry.
pub const SUBGROUP_SIZE_SPEC: u32 = 100;

pub use crate::core::rules::MAX_FIELD_SAMPLES;

/// Specialization constant ids of the radix sort's tunables (`sort_common.glsl`).
pub const SORT_SPEC_WG: u32 = 0;
/// Specialization constant id of the items each sort invocation handles.
pub const SORT_SPEC_ITEMS: u32 = 1;
/// Specialization constant id of the radix (digits per pass).
pub const SORT_SPEC_RADIX: u32 = 2;
/// Specialization constant id of the most subgroups a sort workgroup may have.
pub const SORT_SPEC_MAX_SUBGROUPS: u32 = 3;

/// A float constant as a GLSL literal that parses to the same f32 (Rust prints the
/// shortest decimal that round-trips).
fn glsl_float(x: f32) -> String {
    let text = format!("{x:?}");
    if text.contains(['.', 'e']) {
        text
    } else {
        format!("{text}.0")
    }
}

/// Named descriptor bindings, one module per shader (`glsl/<wing>/<shader>.comp`), in
/// binding order; each name is also a GLSL `#define <SHADER>_<NAME> <index>` (e.g.
/// `PREPROCESS_SPLATS`), so the shader and the Rust stage that binds it name the same
/// slot. Each wing invokes it once, for its own shaders.
macro_rules! shader_bindings {
    ($($shader:ident { $($name:ident),* $(,)? })*) => {
        /// Binding indices by shader and name.
        pub mod bindings {
            $(
                #[allow(missing_docs)]
                pub mod $shader {
                    $crate::gpu::shader_set::shader_bindings!(@index 0u32; $($name),*);
                    /// The names in binding order.
                    pub const NAMES: &[&str] = &[$(stringify!($name)),*];
                }
            )*
            /// Every shader's binding names, in binding order.
            pub const ALL: &[(&str, &[&str])] = &[$((stringify!($shader), $shader::NAMES)),*];
        }
    };
    (@index $i:expr; $name:ident $(, $rest:ident)*) => {
        pub const $name: u32 = $i;
        $crate::gpu::shader_set::shader_bindings!(@index $i + 1; $($rest),*);
    };
    (@index $i:expr;) => {};
}
pub(crate) use shader_bindings;

shader_bindings! {
    scan_reduce { DATA_IN, BLOCK_SUMS }
    scan_block { DATA_IN, DATA_OUT, TOTALS }
    scan_add { DATA_IN, BLOCK_OFFSETS, DATA_OUT }
    sort_setup { COUNT, META }
    sort_histogram { META, KEYS, HIST }
    sort_scatter { META, KEYS_IN, VALUES_IN, OFFSETS, KEYS_OUT, VALUES_OUT }
    sort_copy { META, KEYS_IN, VALUES_IN, KEYS_OUT, VALUES_OUT }
    subgroup_probe { OUT }
}

/// `items` (binding index, value) in binding order: each of the `N` slots exactly once.
pub fn by_binding<T: Copy, const N: usize>(items: [(u32, T); N]) -> Result<[T; N], String> {
    let mut out: [Option<T>; N] = [None; N];
    for (binding, value) in items {
        match out.get_mut(binding as usize) {
            Some(slot @ None) => *slot = Some(value),
            Some(Some(_)) => return Err(format!("binding {binding} is given twice")),
            None => return Err(format!("binding {binding} is past the {N} slots")),
        }
    }
    // Every slot is filled: N items, none twice, none out of range.
    Ok(out.map(|v| v.expect("each of the N slots was filled once")))
}

/// The `#define`s every shader is compiled with: the constants above, the reference's
/// rules (`crate::core::rules`), so that the host (Rust) is their one source, and the
/// binding names of every shader in `tables` (each wing's `bindings::ALL`).
pub fn shared_defines(tables: &[&[(&str, &[&str])]]) -> Vec<(String, String)> {
    use crate::core::rules;
    [
        ("TILE_SIZE", format!("{}u", rules::TILE_SIZE)),
        (
            "TILE_PIXELS",
            format!("{}u", rules::TILE_SIZE * rules::TILE_SIZE),
        ),
        // The near plane, the alpha clamp and the antialiased ratio's floor differ between
        // the rules and come per frame (FrameParams.rules).
        ("COV2D_DILATION", glsl_float(rules::COV2D_DILATION)),
        ("ALPHA_MIN", glsl_float(rules::ALPHA_MIN)),
        ("GSPLAT_EXTEND", glsl_float(rules::GSPLAT_EXTEND)),
        ("T_MIN", glsl_float(rules::T_MIN)),
        ("LINEAR_WG", format!("{LINEAR_WG}u")),
        ("PIXEL_WG_X", format!("{PIXEL_WG_X}u")),
        ("PIXEL_WG_Y", format!("{PIXEL_WG_Y}u")),
        ("LOSS_WG", format!("{LOSS_WG}u")),
        ("REDUCE_WG", format!("{REDUCE_WG}u")),
        ("REDUCE_ITEMS", format!("{REDUCE_ITEMS}u")),
        ("REDUCE_SPAN", format!("{REDUCE_SPAN}u")),
        ("MLP_REDUCE_WG", format!("{MLP_REDUCE_WG}u")),
        ("APPEARANCE_WG", format!("{APPEARANCE_WG}u")),
        ("APPEARANCE_ITEMS", format!("{APPEARANCE_ITEMS}u")),
        ("APPEARANCE_SPAN", format!("{APPEARANCE_SPAN}u")),
        ("SCAN_WG", SCAN_WG.to_string()),
        ("SCAN_ITEMS", SCAN_ITEMS.to_string()),
        ("SCAN_BLOCK", format!("{SCAN_BLOCK}u")),
        ("META_N", META_N.to_string()),
        ("META_BLOCKS", META_BLOCKS.to_string()),
        ("META_DISPATCH", META_DISPATCH.to_string()),
        ("SORT_SPEC_WG", SORT_SPEC_WG.to_string()),
        ("SORT_SPEC_ITEMS", SORT_SPEC_ITEMS.to_string()),
        ("SORT_SPEC_RADIX", SORT_SPEC_RADIX.to_string()),
        (
            "SORT_SPEC_MAX_SUBGROUPS",
            SORT_SPEC_MAX_SUBGROUPS.to_string(),
        ),
        ("GRAD_FIELDS", format!("{GRAD_FIELDS}u")),
        ("MAX_GRAD_FIELDS", format!("{MAX_GRAD_FIELDS}u")),
        (
            "GRAD_SPEC_MAX_SUBGROUPS",
            GRAD_SPEC_MAX_SUBGROUPS.to_string(),
        ),
        ("GRAD_SPEC_BATCH", GRAD_SPEC_BATCH.to_string()),
        (
            "GRAD_SPEC_ROWS_SUBGROUP",
            GRAD_SPEC_ROWS_SUBGROUP.to_string(),
        ),
        ("SHADE_SPEC_ACTIVATIONS", SHADE_SPEC_ACTIVATIONS.to_string()),
        ("SHADE_SPEC_WIDEST", SHADE_SPEC_WIDEST.to_string()),
        ("SHADE_CHUNK_PIXELS", format!("{SHADE_CHUNK_PIXELS}u")),
        ("MAX_FIELD_SAMPLES", MAX_FIELD_SAMPLES.to_string()),
        ("SUBGROUP_SIZE_SPEC", SUBGROUP_SIZE_SPEC.to_string()),
        ("WIDE_WG_SPEC", WIDE_WG_SPEC.to_string()),
        ("REPRODUCIBLE_SPEC", REPRODUCIBLE_SPEC.to_string()),
        ("SSIM_FILTER_RUN", SSIM_FILTER_RUN.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .chain(
        tables
            .iter()
            .flat_map(|table| table.iter())
            .flat_map(|(shader, names)| {
                names.iter().enumerate().map(move |(i, name)| {
                    (format!("{}_{name}", shader.to_uppercase()), i.to_string())
                })
            }),
    )
    .collect()
}

/// One compiled variant: a shader of `glsl/` and the defines that select the variant.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ShaderVariant {
    /// File stem, unique under `glsl/` (`blend` for `glsl/render/forward/blend.comp`).
    pub shader: String,
    /// `NAME=VALUE` defines, in the order given.
    pub defines: Vec<(String, String)>,
}

impl ShaderVariant {
    /// The variant's lookup key: the shader and its defines sorted by name, so that the
    /// order a caller lists them in does not matter.
    pub fn key(&self) -> String {
        variant_key(
            &self.shader,
            self.defines.iter().map(|(k, v)| (k.as_str(), v.as_str())),
        )
    }
}

/// [`ShaderVariant::key`] of `shader` with `defines`.
pub fn variant_key<'a>(
    shader: &str,
    defines: impl IntoIterator<Item = (&'a str, &'a str)>,
) -> String {
    let mut pairs: Vec<(&str, &str)> = defines.into_iter().collect();
    pairs.sort();
    let mut key = shader.to_string();
    for (k, v) in pairs {
        key.push(' ');
        key.push_str(k);
        key.push('=');
        key.push_str(v);
    }
    key
}

/// The variant of `shader` with `defines`.
pub fn variant(shader: &str, defines: &[(&str, String)]) -> ShaderVariant {
    ShaderVariant {
        shader: shader.to_string(),
        defines: defines
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect(),
    }
}

/// A boolean define's value.
pub fn bit(b: bool) -> String {
    u32::from(b).to_string()
}

/// The `gpu` wing's variants: the scan, the sort (each key width and I/O it is built
/// for) and the subgroup probe. Numeric tunables of the sort are specialization constants
/// instead, so any configuration the device allows uses these.
pub fn shader_variants() -> Vec<ShaderVariant> {
    let mut out: Vec<ShaderVariant> = ["scan_reduce", "scan_block", "scan_add", "subgroup_probe"]
        .into_iter()
        .map(|shader| variant(shader, &[]))
        .collect();
    // Sort: 64-bit keys through buffers, 32-bit keys through buffers or texel views.
    for (key, texel) in [("uvec2", false), ("uint", false), ("uint", true)] {
        for shader in ["sort_setup", "sort_histogram", "sort_scatter", "sort_copy"] {
            out.push(variant(
                shader,
                &[("SORT_KEY", key.to_string()), ("SORT_TEXEL_IO", bit(texel))],
            ));
        }
    }
    out
}

/// Compiles the compute shader `file` (which `glslc` reports as `display` in its
/// diagnostics, e.g. `glsl/render/forward/blend.comp`) to SPIR-V for Vulkan 1.3 with optimisation,
/// running `glslc` in `cwd` with `include_dirs` searched by `#include`. On failure the
/// error holds glslc's diagnostics (`glsl/<file>:<line>: error: ...`).
pub fn compile_glsl_file(
    cwd: &std::path::Path,
    display: &str,
    include_dirs: &[&std::path::Path],
    defines: &[(&str, &str)],
    output: &std::path::Path,
) -> Result<Vec<u32>, String> {
    let glslc = std::env::var_os("GLSLC").unwrap_or_else(|| "glslc".into());
    let mut cmd = std::process::Command::new(&glslc);
    cmd.current_dir(cwd)
        .arg("--target-env=vulkan1.3")
        .arg("-O")
        .arg("-fshader-stage=compute");
    for dir in include_dirs {
        cmd.arg("-I").arg(dir);
    }
    for (k, v) in defines {
        if k.contains(['\0', '=']) || v.contains('\0') {
            return Err(format!(
                "{display}: define {k:?} = {v:?} is not a valid macro"
            ));
        }
        cmd.arg(format!("-D{k}={v}"));
    }
    cmd.arg(display).arg("-o").arg(output);
    let result = cmd.output().map_err(|e| {
        format!(
            "cannot run {} (the GLSL compiler; Debian package `glslc`): {e}",
            std::path::Path::new(&glslc).display()
        )
    })?;
    if !result.status.success() {
        let mut text = String::from_utf8_lossy(&result.stderr).trim().to_string();
        if text.is_empty() {
            text = format!("glslc exited with {}", result.status);
        }
        return Err(text);
    }
    let bytes = std::fs::read(output).map_err(|e| format!("{}: {e}", output.display()))?;
    spirv_words(&bytes).ok_or_else(|| format!("{display}: glslc wrote no valid SPIR-V"))
}

/// The shaders under `root` (`glsl/`) by file stem, and every folder there (`root`
/// included), in name order: the wings keep their shaders in folders of their own, and a
/// stem names one shader across them all (two of one stem are an error).
#[allow(clippy::type_complexity)]
pub fn glsl_tree(
    root: &std::path::Path,
) -> Result<
    (
        std::collections::BTreeMap<String, std::path::PathBuf>,
        Vec<std::path::PathBuf>,
    ),
    String,
> {
    let mut shaders = std::collections::BTreeMap::new();
    let mut folders = vec![root.to_path_buf()];
    let mut i = 0;
    while let Some(dir) = folders.get(i).cloned() {
        i += 1;
        let mut entries: Vec<std::path::PathBuf> = std::fs::read_dir(&dir)
            .map_err(|e| format!("{}: {e}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        for path in entries {
            if path.is_dir() {
                folders.push(path);
            } else if path.extension().is_some_and(|x| x == "comp") {
                let stem = path
                    .file_stem()
                    .map(|s| s.to_string_lossy().to_string())
                    .unwrap_or_default();
                if let Some(other) = shaders.insert(stem.clone(), path.clone()) {
                    return Err(format!(
                        "two shaders named {stem}: {} and {}",
                        other.display(),
                        path.display()
                    ));
                }
            }
        }
    }
    Ok((shaders, folders))
}

/// The first word of every SPIR-V module.
pub const SPIRV_MAGIC: u32 = 0x0723_0203;

/// SPIR-V bytes as little-endian words, if they start with the SPIR-V magic number.
pub fn spirv_words(bytes: &[u8]) -> Option<Vec<u32>> {
    if bytes.len() < 20 || bytes.len() % 4 != 0 {
        return None;
    }
    let words: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    (words[0] == SPIRV_MAGIC).then_some(words)
}
