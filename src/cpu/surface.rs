//! The CPU reference of the surface pass ([`crate::core::model::surface`]): the colour
//! blend's per-pixel loop with each Gaussian's facing normal in place of its colour, and
//! the median depth taken where the transmittance crosses 0.5; as
//! `glsl/render/forward/blend_features.comp` with `SURFACE 1`.

use super::{
    blend, blend_pixel_steps, preprocess, sort_pairs, tile_keys, tile_ranges, wrapped_for_tile,
    Projected,
};
use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::model::surface::{
    facing_normal, surface_axes, MEDIAN_TRANSMITTANCE, SURFACE_CHANNELS,
};
use crate::core::model::{ActivatedScene, RenderOptions, Rules, SplatKernel, TILE_SIZE};
use rayon::prelude::*;

/// Renders `scene` from `cam` with the surface pass: the colour frame, with
/// [`Frame::features`] holding per pixel the blended facing normals (world space, not
/// normalised) and the median depth ([`SURFACE_CHANNELS`] channels).
pub fn render_surface(scene: &ActivatedScene, cam: &Camera, opts: &RenderOptions) -> Frame {
    let projected = preprocess(scene, cam, opts);
    let (keys, values) = tile_keys(&projected, cam);
    let (sorted_keys, sorted_values) = sort_pairs(&keys, &values);
    let (tx, ty) = cam.tile_grid();
    let ranges = tile_ranges(&sorted_keys, (tx * ty) as usize);
    let mut frame = blend(
        &projected,
        &sorted_values,
        &ranges,
        cam,
        opts.background,
        opts.kernel,
        opts.rules,
    );
    let centre = cam.position().to_array();
    let normals: Vec<[f32; 3]> = surface_axes(scene)
        .into_iter()
        .map(|axis| facing_normal(axis, centre))
        .collect();
    frame.features = blend_surface(
        &projected,
        &sorted_values,
        &ranges,
        cam,
        opts.kernel,
        opts.rules,
        &normals,
    );
    frame.feature_count = SURFACE_CHANNELS;
    frame
}

/// One pixel of the surface pass: the facing normals of `ids` (front to back) weighted as
/// colour, and the depth of the Gaussian that takes the transmittance from above 0.5 to
/// 0.5 or below (0 when none does).
#[allow(clippy::too_many_arguments)]
pub fn surface_pixel(
    projected: &[Projected],
    ids: &[u32],
    px: f32,
    py: f32,
    kernel: SplatKernel,
    rules: Rules,
    normals: &[[f32; 3]],
) -> [f32; 4] {
    let mut out = [0f32; 4];
    let mut t_before = 1.0f32;
    blend_pixel_steps(projected, ids, px, py, kernel, rules, |id, w, t_after| {
        let n = normals[id as usize];
        for (o, v) in out.iter_mut().zip(n) {
            *o += v * w;
        }
        if t_before > MEDIAN_TRANSMITTANCE && t_after <= MEDIAN_TRANSMITTANCE {
            out[3] = projected[id as usize].depth;
        }
        t_before = t_after;
    });
    out
}

/// [`surface_pixel`] of every pixel: `width * height * 4` floats, pixel-major.
fn blend_surface(
    projected: &[Projected],
    sorted_values: &[u32],
    ranges: &[[u32; 2]],
    cam: &Camera,
    kernel: SplatKernel,
    rules: Rules,
    normals: &[[f32; 3]],
) -> Vec<f32> {
    let k = SURFACE_CHANNELS;
    let (tiles_x, _) = cam.tile_grid();
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut out = vec![0f32; w * h * k];
    let wraps = cam.lens.wraps();
    out.par_chunks_mut(w * k).enumerate().for_each(|(y, row)| {
        let tile_row = (y as u32 / TILE_SIZE) * tiles_x;
        for (tx, pixels) in row.chunks_mut(TILE_SIZE as usize * k).enumerate() {
            let [start, end] = ranges[(tile_row + tx as u32) as usize];
            let ids = &sorted_values[start as usize..end as usize];
            let x0 = tx as u32 * TILE_SIZE;
            // A wrapping image's tile draws moved copies, listed by local ids.
            let moved = wraps.then(|| {
                let (moved, local) = wrapped_for_tile(projected, ids, x0, cam.width);
                let local_normals: Vec<[f32; 3]> =
                    ids.iter().map(|&id| normals[id as usize]).collect();
                (moved, local, local_normals)
            });
            let (projected, ids, normals) = match &moved {
                Some((p, i, n)) => (&p[..], &i[..], &n[..]),
                None => (projected, ids, normals),
            };
            for (i, px) in pixels.chunks_exact_mut(k).enumerate() {
                let x = (x0 + i as u32) as f32;
                let v = surface_pixel(projected, ids, x, y as f32, kernel, rules, normals);
                px.copy_from_slice(&v);
            }
        }
    });
    out
}
