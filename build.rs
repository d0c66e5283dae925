//! Compiles every compute shader variant each wing lists (`src/gpu/shader_set.rs`,
//! `src/render/shaders.rs`, `src/train/shaders.rs`; the GLSL in `glsl/<wing>/`) to SPIR-V
//! with `glslc` (shaderc's command line, Debian package `glslc`) and embeds the modules,
//! so that no binary, test or Python extension links a GLSL compiler and start-up compiles
//! no GLSL. A GLSL error fails the build with glslc's `glsl/<wing>/<file>:<line>: error:
//! ...` message. `GLSLC` names another compiler executable.

#[path = "src/render/shaders.rs"]
#[allow(dead_code)]
mod render_shaders;
#[path = "src/core/rules.rs"]
#[allow(dead_code)]
mod rules;
#[path = "src/core/shader_interface.rs"]
#[allow(dead_code)]
mod shader_interface;
#[path = "src/gpu/shader_set.rs"]
#[allow(dead_code, unused_imports)]
mod shader_set;
#[path = "src/train/shaders.rs"]
#[allow(dead_code)]
mod train_shaders;
/// The library's path to `rules` (`crate::core::rules`), which `shader_set` names.
mod core {
    pub(crate) use super::rules;
}
/// The library's path to `shader_set` (`crate::gpu::shader_set`), which the wings name.
mod gpu {
    pub(crate) use super::shader_set;
}

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=glsl");
    println!("cargo:rerun-if-changed=src/gpu/shader_set.rs");
    println!("cargo:rerun-if-changed=src/render/shaders.rs");
    println!("cargo:rerun-if-changed=src/train/shaders.rs");
    println!("cargo:rerun-if-changed=src/core/rules.rs");
    println!("cargo:rerun-if-changed=src/core/shader_interface.rs");
    println!("cargo:rerun-if-env-changed=GLSLC");
    let root = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR"));
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR"));
    let spirv_dir = out.join("spirv");
    std::fs::create_dir_all(&spirv_dir).expect("create OUT_DIR/spirv");

    // The records, push blocks and flags the shaders include (`interface.glsl`), from
    // their one declaration in Rust.
    let interface_dir = out.join("glsl");
    std::fs::create_dir_all(&interface_dir).expect("create OUT_DIR/glsl");
    let interface = shader_interface::glsl_declarations()
        .unwrap_or_else(|e| panic!("src/core/shader_interface.rs is not std430: {e}"));
    std::fs::write(interface_dir.join("interface.glsl"), interface).expect("write interface.glsl");

    let variants: Vec<shader_set::ShaderVariant> = [
        shader_set::shader_variants(),
        render_shaders::shader_variants(),
        train_shaders::shader_variants(),
    ]
    .concat();
    let tables = [
        shader_set::bindings::ALL,
        render_shaders::bindings::ALL,
        train_shaders::bindings::ALL,
    ];
    let shared = shader_set::shared_defines(&tables);
    // Every shader by its stem (unique across the wings), and every folder, searched by
    // `#include` (the headers are named by file alone).
    let (sources, folders) =
        shader_set::glsl_tree(&root.join("glsl")).unwrap_or_else(|e| panic!("reading glsl/: {e}"));
    let mut include_dirs: Vec<PathBuf> = folders
        .iter()
        .map(|d| d.strip_prefix(&root).unwrap_or(d).to_path_buf())
        .collect();
    include_dirs.push(interface_dir.clone());
    let include: Vec<&Path> = include_dirs.iter().map(PathBuf::as_path).collect();
    let next = AtomicUsize::new(0);
    let errors = Mutex::new(Vec::new());
    let workers = std::thread::available_parallelism()
        .map_or(2, |n| n.get())
        .clamp(1, 8);
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(variant) = variants.get(i) else {
                    break;
                };
                let defines: Vec<(&str, &str)> = shared
                    .iter()
                    .chain(&variant.defines)
                    .map(|(k, v)| (k.as_str(), v.as_str()))
                    .collect();
                let Some(path) = sources.get(&variant.shader) else {
                    errors.lock().unwrap().push(format!(
                        "{}: no glsl/**/{}.comp",
                        variant.key(),
                        variant.shader
                    ));
                    continue;
                };
                let file = path
                    .strip_prefix(&root)
                    .unwrap_or(path)
                    .display()
                    .to_string();
                let output = spirv_dir.join(format!("{i:03}-{}.spv", variant.shader));
                if let Err(e) =
                    shader_set::compile_glsl_file(&root, &file, &include, &defines, &output)
                {
                    errors
                        .lock()
                        .unwrap()
                        .push(format!("{} ({file}):\n{e}", variant.key()));
                }
            });
        }
    });
    let errors = errors.into_inner().unwrap();
    if !errors.is_empty() {
        panic!("compiling the shaders failed:\n{}", errors.join("\n\n"));
    }

    let mut table = String::from(
        "/// Every shader variant's SPIR-V, compiled by build.rs, by `ShaderVariant::key`.\n\
         pub static PREBUILT: &[(&str, &[u8])] = &[\n",
    );
    for (i, variant) in variants.iter().enumerate() {
        let path = spirv_dir.join(format!("{i:03}-{}.spv", variant.shader));
        table.push_str(&format!(
            "    ({:?}, include_bytes!({:?})),\n",
            variant.key(),
            path.display().to_string()
        ));
    }
    table.push_str("];\n");
    // The defines every shader is compiled with, for run-time compiles (shader
    // development), and every wing's binding names.
    table.push_str(
        "/// The `#define`s every shader is compiled with (`shader_set::shared_defines`).\n\
         pub static SHARED_DEFINES: &[(&str, &str)] = &[\n",
    );
    for (k, v) in &shared {
        table.push_str(&format!("    ({k:?}, {v:?}),\n"));
    }
    table.push_str(
        "];\n/// Every wing's binding names by shader, in binding order.\n\
         pub static BINDINGS: &[(&str, &[&str])] = &[\n",
    );
    for (shader, names) in tables.iter().flat_map(|t| t.iter()) {
        table.push_str(&format!("    ({shader:?}, &{names:?}),\n"));
    }
    table.push_str("];\n");
    std::fs::write(out.join("prebuilt_shaders.rs"), table).expect("write prebuilt_shaders.rs");
}
