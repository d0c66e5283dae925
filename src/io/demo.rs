//! The built-in demo scene, which `render` and `view` show when given no scene.

/// The built-in demo scene (PLAYBOT LOD6, CC BY 4.0, see `assets/README.md`).
pub const DEMO_SCENE_PLY: &[u8] = include_bytes!("../../assets/playbot_lod6_1873_sh2.ply");

/// Loads the built-in demo scene.
pub fn demo_scene() -> crate::core::scene::Scene {
    crate::io::scene::ply::parse(
        DEMO_SCENE_PLY,
        std::path::Path::new("<built-in demo scene>"),
    )
    .expect("the embedded demo scene is a valid PLY")
}
