//! Training data sets made here: a shared scene (PLAYBOT LOD6, CC BY 4.0) rendered from
//! orbit cameras into a COLMAP data set (PNG photos, text model with every other Gaussian
//! centre as points3D), for the tests of `train` and of what reads its models.

use crate::common;
use std::path::Path;
use verisplat::core::camera::orbit::{orbit, OrbitParams};

/// Writes the data set into `dir`: `views` photos of `w x h` and the COLMAP model.
pub fn make_dataset(dir: &Path, views: usize, w: u32, h: u32) {
    make_dataset_with(dir, views, w, h, None);
}

/// [`make_dataset`] whose photos are feature splats shaded by `shader` (the scene given
/// seeded feature channels of the count the shader takes).
pub fn make_dataset_with(
    dir: &Path,
    views: usize,
    w: u32,
    h: u32,
    shader: Option<&verisplat::fields::mlp::Mlp>,
) {
    let mut scene = verisplat::io::scene::load_with_format(
        &common::shared_data().join("playbot_lod6_1873_sh2.ply"),
    )
    .expect("the shared scene")
    .0;
    if let Some(mlp) = shader {
        let k = mlp.feature_channels();
        let mut rng = common::Rng(77);
        scene.feature_count = k;
        scene.features = (0..scene.len() * k).map(|_| rng.range(-1.0, 1.0)).collect();
    }
    let cams: Vec<_> = orbit(
        &scene.positions,
        &OrbitParams {
            frames: views,
            width: w,
            height: h,
            elevation_deg: 15.0,
            ..Default::default()
        },
    )
    .unwrap()
    .into_iter()
    .enumerate()
    .map(|(i, mut c)| {
        c.name = format!("view_{i:03}.png");
        c
    })
    .collect();
    verisplat::train::data::write_rendered_dataset(dir, &scene, &cams, shader, 2, false).unwrap();
}
