//! verisplat: a 3D Gaussian Splatting renderer on raw Vulkan compute, with an exact CPU
//! reference renderer that the GPU is checked against.

#[cfg(feature = "cli")]
pub mod bench;
pub mod camera;
pub mod console;
pub mod cpu;
pub mod diff_image;
pub mod doctor;
pub mod file_error;
pub mod fit;
pub mod font;
pub mod former_name;
pub mod frame;
pub mod fsutil;
pub mod gen;
pub mod gpu;
pub mod image_file;
pub mod metrics;
pub mod mlp;
pub mod model;
pub mod output;
pub mod quat;
pub mod render;
pub mod rf;
pub mod rules;
pub mod scene;
pub mod sequence;
pub mod shader_interface;
pub mod shard;
pub mod stats;
pub mod train;
#[cfg(feature = "viewer")]
pub mod view;

/// The built-in demo scene (PLAYBOT LOD6, CC BY 4.0, see `assets/README.md`).
pub const DEMO_SCENE_PLY: &[u8] = include_bytes!("../assets/playbot_lod6_1873_sh2.ply");

/// Loads the built-in demo scene.
pub fn demo_scene() -> scene::Scene {
    scene::ply::parse(
        DEMO_SCENE_PLY,
        std::path::Path::new("<built-in demo scene>"),
    )
    .expect("the embedded demo scene is a valid PLY")
}
