//! Links the GLSL compiler.
//!
//! The `shaderc` crate (feature `prefer-static-linking`) links Debian's
//! `libshaderc_combined.a`, which on Debian does not contain glslang or
//! SPIRV-Tools. Those come from the static archives of `glslang-dev` and
//! `spirv-tools`, linked here in dependency order (see
//! `../shared/docs/toolchain.md`). Set `VKSPLAT_NO_SYSTEM_GLSLANG=1` to skip this
//! when shaderc is built from source or found elsewhere.

fn main() {
    println!("cargo:rerun-if-env-changed=VKSPLAT_NO_SYSTEM_GLSLANG");
    println!("cargo:rerun-if-changed=build.rs");
    if std::env::var_os("VKSPLAT_NO_SYSTEM_GLSLANG").is_some() {
        return;
    }
    let arch = std::env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    let triplet = match arch.as_str() {
        "x86_64" => "x86_64-linux-gnu",
        "aarch64" => "aarch64-linux-gnu",
        other => {
            println!("cargo:warning=vksplat: no Debian library path known for {other}");
            return;
        }
    };
    println!("cargo:rustc-link-search=native=/usr/lib/{triplet}");
    for lib in [
        "glslang",
        "MachineIndependent",
        "GenericCodeGen",
        "OSDependent",
        "OGLCompiler",
        "HLSL",
        "SPIRV",
        "SPIRV-Tools-opt",
        "SPIRV-Tools",
        "glslang-default-resource-limits",
    ] {
        println!("cargo:rustc-link-lib=static={lib}");
    }
    println!("cargo:rustc-link-lib=dylib=stdc++");
}
