//! The CPU reference renderer: the reference 3DGS forward pass, stage by stage, in f32.
//!
//! It is written for clarity and is the yardstick the GPU pipeline is held to. Each stage
//! is a public function so the GPU stages can be compared against its intermediate values:
//! [`preprocess`] -> [`tile_keys`] -> [`sort_pairs`] -> [`tile_ranges`] -> [`blend`].
//! The rules are those of `shared/docs/reference-semantics.md`.

pub mod backward;
pub mod field;
pub mod surface;

use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::model::ActivatedScene;
// The model's types, constants and SH, re-exported where they used to live.
pub use crate::core::model::sh;
pub use crate::core::model::{
    clamp_limits, RenderOptions, Rules, SplatKernel, ALPHA_MAX, ALPHA_MIN, ANTIALIAS_MIN_RATIO,
    COV2D_DILATION, NEAR_PLANE, TILE_SIZE, T_MIN,
};
pub use crate::core::quat::quat_to_mat3;
use glam::{Mat3, Vec3};
use rayon::prelude::*;

/// Per-Gaussian output of [`preprocess`]. A culled Gaussian has `radius == 0` and
/// touches no tile.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Projected {
    /// Projected centre in pixel coordinates (pixel `(i, j)` is evaluated at `(i, j)`).
    pub mean2d: [f32; 2],
    /// View-space depth `z` (through a fisheye or equirectangular lens, the distance from
    /// the camera: what the Gaussians are sorted by, and what the depth output blends).
    pub depth: f32,
    /// Inverse 2D covariance `(A, B, C)`: `power = -0.5 (A dx^2 + C dy^2) - B dx dy`.
    pub conic: [f32; 3],
    /// Activated opacity.
    pub opacity: f32,
    /// RGB from SH.
    pub color: [f32; 3],
    /// Screen-space radius in pixels, the larger of the two axes' under gsplat's rules (0
    /// when culled).
    pub radius: i32,
    /// First tile (x, y) touched, inclusive.
    pub rect_min: [u32; 2],
    /// Last tile (x, y) touched, exclusive.
    pub rect_max: [u32; 2],
}

impl Projected {
    /// Number of tiles in the Gaussian's tile rectangle (0 when culled).
    pub fn tiles_touched(&self) -> u32 {
        if self.radius <= 0 {
            return 0;
        }
        (self.rect_max[0] - self.rect_min[0]) * (self.rect_max[1] - self.rect_min[1])
    }
}

/// 3D covariance `R S S^T R^T` (symmetric, full matrix).
pub fn covariance_3d(scale: [f32; 3], rotation: [f32; 4]) -> Mat3 {
    let m = quat_to_mat3(rotation) * Mat3::from_diagonal(Vec3::from(scale));
    m * m.transpose()
}

/// 2D covariance `(a, b, c)` = xx, xy, yy of `J W Sigma W^T J^T`, before the dilation.
/// `view` is the view-space centre; `x/z` and `y/z` are clamped to the guard band of
/// `rules` (the original's 1.3 tan(fov/2)).
pub fn covariance_2d(view: Vec3, cov3d: Mat3, cam: &Camera, rules: Rules) -> [f32; 3] {
    let [xn, xp, yn, yp] = clamp_limits(cam, rules);
    let z = view.z;
    let tx = (view.x / z).clamp(-xn, xp) * z;
    let ty = (view.y / z).clamp(-yn, yp) * z;
    // Rows of J (the third row is zero).
    let j0 = Vec3::new(cam.fx / z, 0.0, -(cam.fx * tx) / (z * z));
    let j1 = Vec3::new(0.0, cam.fy / z, -(cam.fy * ty) / (z * z));
    // Rows of T = J W.
    let w_t = cam.rotation.transpose();
    let t0 = w_t * j0;
    let t1 = w_t * j1;
    let s0 = cov3d * t0;
    let s1 = cov3d * t1;
    [t0.dot(s0), t0.dot(s1), t1.dot(s1)]
}

/// The reference's preprocess for one Gaussian, with the options' filters, scale
/// modifier, SH degree and antialiasing compensation.
pub fn preprocess_one(
    scene: &ActivatedScene,
    i: usize,
    cam: &Camera,
    opts: &RenderOptions,
) -> Projected {
    let culled = Projected::default();
    if !opts.keeps(scene, i) {
        return culled;
    }
    let mean = Vec3::from(scene.positions[i]);
    let view = cam.rotation * mean + cam.translation;
    let rules = opts.rules;
    let m = opts.scale_modifier;
    let s = scene.scales[i];
    let scale = [m * s[0], m * s[1], m * s[2]];
    let (cov2d, mean2d, depth) = if cam.lens.is_pinhole() {
        if !rules.in_front(view.z, opts.near()) {
            return culled;
        }
        let cov3d = covariance_3d(scale, scene.rotations[i]);
        let inv_z = 1.0 / view.z;
        let mean2d = [
            cam.fx * view.x * inv_z + cam.cx - 0.5,
            cam.fy * view.y * inv_z + cam.cy - 0.5,
        ];
        (covariance_2d(view, cov3d, cam, rules), mean2d, view.z)
    } else {
        match through_lens(view, scale, scene.rotations[i], cam, opts) {
            Some(p) => p,
            None => return culled,
        }
    };
    let [a, b, c] = cov2d;
    let det_before = a * c - b * b;
    let (a, c) = (a + COV2D_DILATION, c + COV2D_DILATION);
    let det = a * c - b * b;
    if !rules.keeps_det(det) {
        return culled;
    }
    let opacity = if opts.antialiased {
        scene.opacities[i] * (det_before / det).max(rules.antialias_min_ratio()).sqrt()
    } else {
        scene.opacities[i]
    };
    let det_inv = 1.0 / det;
    let conic = [c * det_inv, -b * det_inv, a * det_inv];
    let size = (cam.width, cam.height);
    let grid = cam.tile_grid();
    let e = if cam.lens.wraps() {
        // An image that wraps around: the rectangle in the tiles of three turns side by
        // side (the image the middle one); the keys take each tile back to the image, and
        // the blend draws the copy of the splat nearest the tile.
        rules.wrapped_extent([a, b, c], det, opacity, mean2d, size, grid)
    } else {
        rules.extent([a, b, c], det, opacity, mean2d, size, grid)
    };
    let Some(e) = e else {
        return culled;
    };
    let dir = (mean - cam.position()).normalize();
    let stride = scene.sh_stride();
    let color = sh::eval_sh(
        opts.active_sh_degree(scene.sh_degree),
        &scene.sh[i * stride..(i + 1) * stride],
        dir,
    );
    Projected {
        mean2d,
        depth,
        conic,
        opacity,
        color,
        radius: e.radius[0].max(e.radius[1]),
        rect_min: e.rect_min,
        rect_max: e.rect_max,
    }
}

/// The 2D covariance (before the dilation), centre (pixel `(i, j)` at `(i, j)`) and depth
/// of a Gaussian seen through a lens other than the pinhole, by the unscented transform
/// ([`crate::core::model::unscented`]), or `None` when it is culled: nearer than the near
/// plane (along the axis for the distorted and orthographic lenses, as the distance from
/// the camera for the fisheye and equirectangular ones, which see behind their image
/// plane), or not imaged. The depth sorted by is that same `z` or distance.
fn through_lens(
    view: Vec3,
    scale: [f32; 3],
    rotation: [f32; 4],
    cam: &Camera,
    opts: &RenderOptions,
) -> Option<([f32; 3], [f32; 2], f32)> {
    use crate::core::camera::Lens;
    use crate::core::model::unscented;
    let depth = match cam.lens {
        Lens::Fisheye { .. } | Lens::Equirectangular { .. } => view.length(),
        _ => view.z,
    };
    if !opts.rules.in_front(depth, opts.near()) {
        return None;
    }
    let axes =
        (cam.rotation * quat_to_mat3(rotation) * Mat3::from_diagonal(Vec3::from(scale))).as_dmat3();
    let params = unscented::UnscentedParams::default();
    let p =
        unscented::project(&cam.lens, &cam.intrinsics(), view.as_dvec3(), axes, &params).ok()?;
    let cov = p.cov.as_mat2();
    let mean2d = [p.mean.x as f32 - 0.5, p.mean.y as f32 - 0.5];
    Some(([cov.x_axis.x, cov.y_axis.x, cov.y_axis.y], mean2d, depth))
}

/// Tile rectangle `[min, max)` of a disc of radius `radius` around `p`, clamped to the grid
/// (the reference's `getRect`, with C's truncating float-to-int conversion).
pub fn tile_rect(p: [f32; 2], radius: f32, grid: (u32, u32)) -> ([u32; 2], [u32; 2]) {
    crate::core::model::rules::get_rect(p, radius, grid)
}

/// Preprocesses every Gaussian (in parallel), as [`preprocess_one`].
pub fn preprocess(scene: &ActivatedScene, cam: &Camera, opts: &RenderOptions) -> Vec<Projected> {
    (0..scene.len())
        .into_par_iter()
        .map(|i| preprocess_one(scene, i, cam, opts))
        .collect()
}

/// Mirror of `tile_receives` in `glsl/render/forward/splat_common.glsl`: whether any pixel of the
/// `size`-pixel bin `tile` can get alpha >= 1/255 from a splat with this centre, conic
/// and opacity under `kernel` (with the GPU's small conservative margin, see
/// [`SplatKernel::alpha_bound`]). The GPU drops pairs for which this is false; they
/// contribute nothing, so the image is unchanged. The reference renderer itself keeps every
/// pair of the rectangle; tests use this to compare membership.
pub fn tile_receives(
    mean2d: [f32; 2],
    conic: [f32; 3],
    opacity: f32,
    kernel: SplatKernel,
    tile: [u32; 2],
    size: u32,
) -> bool {
    let bound = kernel.alpha_bound(opacity);
    let t = size as f32;
    let lo = [
        tile[0] as f32 * t - mean2d[0],
        tile[1] as f32 * t - mean2d[1],
    ];
    let hi = [lo[0] + t - 1.0, lo[1] + t - 1.0];
    if lo[0] <= 0.0 && hi[0] >= 0.0 && lo[1] <= 0.0 && hi[1] >= 0.0 {
        return bound >= 0.0;
    }
    let [a, b, c] = conic;
    let edge = |e: f32, lo: f32, hi: f32, a: f32, b: f32, c: f32| {
        let d = (-b * e / c).clamp(lo, hi);
        a * e * e + 2.0 * b * e * d + c * d * d
    };
    let m = edge(lo[0], lo[1], hi[1], a, b, c)
        .min(edge(hi[0], lo[1], hi[1], a, b, c))
        .min(edge(lo[1], lo[0], hi[0], c, b, a))
        .min(edge(hi[1], lo[0], hi[0], c, b, a));
    m <= bound
}

/// Largest alpha (before the 0.99 clamp) Gaussian `g` reaches at any pixel of the
/// `size`-pixel bin `tile` under `kernel`, evaluated pixel by pixel with the blend's formula.
pub fn max_alpha_in_tile(
    g: &Projected,
    kernel: SplatKernel,
    tile: [u32; 2],
    size: u32,
    width: u32,
    height: u32,
) -> f32 {
    let mut best = 0.0f32;
    for y in tile[1] * size..((tile[1] + 1) * size).min(height) {
        for x in tile[0] * size..((tile[0] + 1) * size).min(width) {
            let dx = g.mean2d[0] - x as f32;
            let dy = g.mean2d[1] - y as f32;
            let power = -0.5 * (g.conic[0] * dx * dx + g.conic[2] * dy * dy) - g.conic[1] * dx * dy;
            if power <= 0.0 {
                best = best.max(kernel.falloff(g.opacity, power));
            }
        }
    }
    best
}

/// Sort key of a (tile, Gaussian) pair: tile id in the high 32 bits, the depth's float
/// bits in the low 32 (depth > 0, so the bits order like the floats).
pub fn tile_key(tile_id: u32, depth: f32) -> u64 {
    ((tile_id as u64) << 32) | depth.to_bits() as u64
}

/// One key and value per (Gaussian, touched tile), emitted in Gaussian index order and,
/// within a Gaussian, row by row over its tile rectangle.
pub fn tile_keys(projected: &[Projected], cam: &Camera) -> (Vec<u64>, Vec<u32>) {
    let (tiles_x, _) = cam.tile_grid();
    // A wrapping image's rectangles are in the tiles of three turns ([`preprocess_one`]).
    let wraps = cam.lens.wraps();
    let total: usize = projected.iter().map(|p| p.tiles_touched() as usize).sum();
    let mut keys = Vec::with_capacity(total);
    let mut values = Vec::with_capacity(total);
    for (i, p) in projected.iter().enumerate() {
        if p.tiles_touched() == 0 {
            continue;
        }
        for y in p.rect_min[1]..p.rect_max[1] {
            for x in p.rect_min[0]..p.rect_max[0] {
                let x = if wraps { x % tiles_x } else { x };
                keys.push(tile_key(y * tiles_x + x, p.depth));
                values.push(i as u32);
            }
        }
    }
    (keys, values)
}

/// Stable sort of the pairs by key, so equal keys keep Gaussian index order.
pub fn sort_pairs(keys: &[u64], values: &[u32]) -> (Vec<u64>, Vec<u32>) {
    let mut pairs: Vec<(u64, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
    pairs.par_sort_by_key(|p| p.0);
    pairs.into_iter().unzip()
}

/// `[start, end)` of each tile's run in the sorted keys.
pub fn tile_ranges(sorted_keys: &[u64], num_tiles: usize) -> Vec<[u32; 2]> {
    let mut ranges = vec![[0u32; 2]; num_tiles];
    for (i, &k) in sorted_keys.iter().enumerate() {
        let tile = (k >> 32) as usize;
        if i == 0 || (sorted_keys[i - 1] >> 32) as usize != tile {
            ranges[tile][0] = i as u32;
        }
        if i + 1 == sorted_keys.len() || (sorted_keys[i + 1] >> 32) as usize != tile {
            ranges[tile][1] = i as u32 + 1;
        }
    }
    ranges
}

/// Result of compositing one pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelResult {
    /// Accumulated colour, without the background.
    pub color: [f32; 3],
    /// Final transmittance.
    pub transmittance: f32,
    /// Sum of `depth * alpha * T`.
    pub weighted_depth: f32,
    /// Gaussians evaluated, up to and including the one that finished the pixel.
    pub evaluated: u32,
}

/// Composites the Gaussians `ids` (front to back) at pixel `(px, py)` with the reference
/// rules and the alpha falloff of `kernel`.
pub fn blend_pixel(
    projected: &[Projected],
    ids: &[u32],
    px: f32,
    py: f32,
    kernel: SplatKernel,
    rules: Rules,
) -> PixelResult {
    let mut color = [0.0f32; 3];
    let mut r = blend_pixel_with(projected, ids, px, py, kernel, rules, |id, w| {
        for (c, gc) in color.iter_mut().zip(projected[id as usize].color) {
            *c += gc * w;
        }
    });
    r.color = color;
    r
}

/// The reference's per-pixel compositing loop: for every Gaussian of `ids` (front to back)
/// that the rules add to pixel `(px, py)`, calls `add(id, alpha * T)` with its weight, and
/// returns the transmittance and weighted depth (`color` zero: the caller accumulates what
/// it blends). [`blend_pixel`] blends colour with it and [`blend_features_pixel`] feature
/// channels, so both follow exactly the same alpha, skip and stop rules.
pub fn blend_pixel_with(
    projected: &[Projected],
    ids: &[u32],
    px: f32,
    py: f32,
    kernel: SplatKernel,
    rules: Rules,
    mut add: impl FnMut(u32, f32),
) -> PixelResult {
    blend_pixel_steps(projected, ids, px, py, kernel, rules, |id, w, _| add(id, w))
}

/// The alpha that pixel `(px, py)` gets from `g` under the reference's rules (the falloff
/// of `kernel`, capped at `alpha_max`), or `None` where the splat adds nothing there (a
/// positive power, or alpha below 1/255): the per-pair test of [`blend_pixel_steps`].
#[inline]
pub fn pixel_alpha(
    g: &Projected,
    px: f32,
    py: f32,
    kernel: SplatKernel,
    alpha_max: f32,
) -> Option<f32> {
    let dx = g.mean2d[0] - px;
    let dy = g.mean2d[1] - py;
    let [ca, cb, cc] = g.conic;
    let power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy;
    if power > 0.0 {
        return None;
    }
    let alpha = alpha_max.min(kernel.falloff(g.opacity, power));
    (alpha >= ALPHA_MIN).then_some(alpha)
}

/// [`blend_pixel_with`], calling `add(id, alpha * T, T')` with the transmittance `T'`
/// after each Gaussian added too (the surface pass's median depth reads it).
pub fn blend_pixel_steps(
    projected: &[Projected],
    ids: &[u32],
    px: f32,
    py: f32,
    kernel: SplatKernel,
    rules: Rules,
    mut add: impl FnMut(u32, f32, f32),
) -> PixelResult {
    let (alpha_max, t_stop) = (rules.alpha_max(), rules.t_stop());
    let mut t = 1.0f32;
    let mut depth = 0.0f32;
    let mut evaluated = 0u32;
    for &id in ids {
        evaluated += 1;
        let g = &projected[id as usize];
        let Some(alpha) = pixel_alpha(g, px, py, kernel, alpha_max) else {
            continue;
        };
        let test_t = t * (1.0 - alpha);
        if test_t < t_stop {
            break;
        }
        let w = alpha * t;
        add(id, w, test_t);
        depth += g.depth * w;
        t = test_t;
    }
    PixelResult {
        color: [0.0; 3],
        transmittance: t,
        weighted_depth: depth,
        evaluated,
    }
}

/// Composites the `k` feature channels of the Gaussians `ids` at pixel `(px, py)` into
/// `out` (`k` floats, zeroed first) with the colour rules and no background.
#[allow(clippy::too_many_arguments)]
pub fn blend_features_pixel(
    projected: &[Projected],
    ids: &[u32],
    px: f32,
    py: f32,
    kernel: SplatKernel,
    rules: Rules,
    features: &[f32],
    k: usize,
    out: &mut [f32],
) {
    out.fill(0.0);
    blend_pixel_with(projected, ids, px, py, kernel, rules, |id, w| {
        let f = &features[id as usize * k..(id as usize + 1) * k];
        for (o, v) in out.iter_mut().zip(f) {
            *o += v * w;
        }
    });
}

/// Blends the `k` feature channels per Gaussian (`features`, Gaussian-major) of every
/// tile front to back, with exactly the colour rules (same alpha, transmittance, skip and
/// stop; background 0): `width * height * k` floats, pixel-major, row by row.
#[allow(clippy::too_many_arguments)]
pub fn blend_features(
    projected: &[Projected],
    sorted_values: &[u32],
    ranges: &[[u32; 2]],
    cam: &Camera,
    kernel: SplatKernel,
    rules: Rules,
    features: &[f32],
    k: usize,
) -> Vec<f32> {
    let (tiles_x, _) = cam.tile_grid();
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut out = vec![0f32; w * h * k];
    if k == 0 {
        return out;
    }
    let wraps = cam.lens.wraps();
    out.par_chunks_mut(w * k).enumerate().for_each(|(y, row)| {
        // One tile's pixels of the row at a time: its list (a wrapping image's moved
        // splats and their features) is made once for them.
        let tile_row = (y as u32 / TILE_SIZE) * tiles_x;
        for (tx, pixels) in row.chunks_mut(TILE_SIZE as usize * k).enumerate() {
            let [start, end] = ranges[(tile_row + tx as u32) as usize];
            let ids = &sorted_values[start as usize..end as usize];
            let x0 = tx as u32 * TILE_SIZE;
            let moved = wraps.then(|| {
                let (moved, local) = wrapped_for_tile(projected, ids, x0, cam.width);
                (moved, local, ids_features(ids, features, k))
            });
            let (projected, ids, features) = match &moved {
                Some((p, i, f)) => (&p[..], &i[..], &f[..]),
                None => (projected, ids, features),
            };
            for (i, px) in pixels.chunks_exact_mut(k).enumerate() {
                let x = (x0 + i as u32) as f32;
                blend_features_pixel(projected, ids, x, y as f32, kernel, rules, features, k, px);
            }
        }
    });
    out
}

/// The `k` feature channels of each of `ids`, in that order.
fn ids_features(ids: &[u32], features: &[f32], k: usize) -> Vec<f32> {
    ids.iter()
        .flat_map(|&id| &features[id as usize * k..(id as usize + 1) * k])
        .copied()
        .collect()
}

/// Renders a frame with the scene's feature channels ([`blend_features`] into
/// [`Frame::features`]) on the CPU.
pub fn render_features(scene: &ActivatedScene, cam: &Camera, opts: &RenderOptions) -> Frame {
    render_features_timed(scene, cam, opts).0
}

/// A wrapping image's ([`Lens::wraps`](crate::core::camera::Lens::wraps)) splats of the
/// tile starting at pixel column `x0`, each with its centre moved by whole turns (the
/// image's width) to the copy nearest the tile's middle, and their ids in that list; as
/// `glsl/render/forward/splat_common.glsl`'s `wrapped_mean`.
pub fn wrapped_for_tile(
    projected: &[Projected],
    ids: &[u32],
    x0: u32,
    width: u32,
) -> (Vec<Projected>, Vec<u32>) {
    let moved = ids
        .iter()
        .map(|&id| wrapped_copy(projected[id as usize], x0, width))
        .collect();
    (moved, (0..ids.len() as u32).collect())
}

/// `p` with its centre moved by whole turns (the wrapping image's `width`) to the copy
/// nearest the middle of the tile starting at pixel column `x0` ([`wrapped_for_tile`]).
pub fn wrapped_copy(mut p: Projected, x0: u32, width: u32) -> Projected {
    let middle = (x0 + TILE_SIZE / 2) as f32;
    let w = width as f32;
    let turns = ((middle - p.mean2d[0]) / w + 0.5).floor();
    p.mean2d[0] += turns * w;
    p
}

/// Blends every tile (in parallel) into a frame, with the alpha falloff of `kernel`.
pub fn blend(
    projected: &[Projected],
    sorted_values: &[u32],
    ranges: &[[u32; 2]],
    cam: &Camera,
    background: [f32; 3],
    kernel: SplatKernel,
    rules: Rules,
) -> Frame {
    let (tiles_x, tiles_y) = cam.tile_grid();
    let (w, h) = (cam.width, cam.height);
    let wraps = cam.lens.wraps();
    let tiles: Vec<Vec<(usize, PixelResult)>> = (0..tiles_x * tiles_y)
        .into_par_iter()
        .map(|tile| {
            let [start, end] = ranges[tile as usize];
            let ids = &sorted_values[start as usize..end as usize];
            let (tx, ty) = (tile % tiles_x, tile / tiles_x);
            let moved = wraps.then(|| wrapped_for_tile(projected, ids, tx * TILE_SIZE, w));
            let (projected, ids) = match &moved {
                Some((p, i)) => (&p[..], &i[..]),
                None => (projected, ids),
            };
            let mut out = Vec::with_capacity((TILE_SIZE * TILE_SIZE) as usize);
            for y in ty * TILE_SIZE..((ty + 1) * TILE_SIZE).min(h) {
                for x in tx * TILE_SIZE..((tx + 1) * TILE_SIZE).min(w) {
                    let r = blend_pixel(projected, ids, x as f32, y as f32, kernel, rules);
                    out.push((y as usize * w as usize + x as usize, r));
                }
            }
            out
        })
        .collect();
    let mut frame = Frame::background(w, h, background);
    for (idx, r) in tiles.into_iter().flatten() {
        let t = r.transmittance;
        frame.color[idx] = [
            r.color[0] + t * background[0],
            r.color[1] + t * background[1],
            r.color[2] + t * background[2],
        ];
        let alpha = 1.0 - t;
        frame.alpha[idx] = alpha;
        frame.depth[idx] = if alpha > 0.0 {
            r.weighted_depth / alpha
        } else {
            0.0
        };
    }
    frame
}

/// Renders a frame on the CPU with the reference semantics.
pub fn render(scene: &ActivatedScene, cam: &Camera, opts: &RenderOptions) -> Frame {
    render_timed(scene, cam, opts).0
}

/// Wall-clock time of each phase of a CPU render, in milliseconds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CpuTimings {
    /// [`preprocess`].
    pub preprocess: f64,
    /// [`tile_keys`].
    pub keys: f64,
    /// [`sort_pairs`].
    pub sort: f64,
    /// [`tile_ranges`].
    pub ranges: f64,
    /// [`blend`].
    pub blend: f64,
    /// [`blend_features`] (0 unless the render blended feature channels).
    pub features: f64,
    /// The whole render.
    pub total: f64,
    /// Number of (tile, Gaussian) pairs.
    pub pairs: u64,
}

impl CpuTimings {
    /// The phases in order with their names; `features` only when the render blended
    /// feature channels.
    pub fn stages(&self) -> Vec<(&'static str, f64)> {
        let mut stages = vec![
            ("preprocess", self.preprocess),
            ("keys", self.keys),
            ("sort", self.sort),
            ("ranges", self.ranges),
            ("blend", self.blend),
        ];
        if self.features > 0.0 {
            stages.push(("features", self.features));
        }
        stages
    }
}

/// [`render`], timing each phase.
pub fn render_timed(
    scene: &ActivatedScene,
    cam: &Camera,
    opts: &RenderOptions,
) -> (Frame, CpuTimings) {
    render_timed_with(scene, cam, opts, false)
}

/// [`render_features`], timing each phase (the feature blend as `features`).
pub fn render_features_timed(
    scene: &ActivatedScene,
    cam: &Camera,
    opts: &RenderOptions,
) -> (Frame, CpuTimings) {
    render_timed_with(scene, cam, opts, true)
}

fn render_timed_with(
    scene: &ActivatedScene,
    cam: &Camera,
    opts: &RenderOptions,
    features: bool,
) -> (Frame, CpuTimings) {
    let start = std::time::Instant::now();
    let mut t = CpuTimings::default();
    let mut lap = std::time::Instant::now();
    let mut take = |slot: &mut f64| {
        *slot = lap.elapsed().as_secs_f64() * 1e3;
        lap = std::time::Instant::now();
    };
    let projected = preprocess(scene, cam, opts);
    take(&mut t.preprocess);
    let (keys, values) = tile_keys(&projected, cam);
    take(&mut t.keys);
    let (sorted_keys, sorted_values) = sort_pairs(&keys, &values);
    take(&mut t.sort);
    let (tx, ty) = cam.tile_grid();
    let ranges = tile_ranges(&sorted_keys, (tx * ty) as usize);
    take(&mut t.ranges);
    let mut frame = blend(
        &projected,
        &sorted_values,
        &ranges,
        cam,
        opts.background,
        opts.kernel,
        opts.rules,
    );
    take(&mut t.blend);
    if features {
        frame.features = blend_features(
            &projected,
            &sorted_values,
            &ranges,
            cam,
            opts.kernel,
            opts.rules,
            &scene.features,
            scene.feature_count,
        );
        frame.feature_count = scene.feature_count;
        take(&mut t.features);
    }
    t.total = start.elapsed().as_secs_f64() * 1e3;
    t.pairs = sorted_keys.len() as u64;
    (frame, t)
}

/// Pixel-Gaussian evaluations a front-to-back blend performs: for every pixel, the
/// Gaussians of its list up to and including the one that finishes it (all of them when it
/// never finishes). `list(x, y)` gives pixel (x, y)'s Gaussians in blend order.
pub fn count_evaluations<'a>(
    projected: &[Projected],
    cam: &Camera,
    kernel: SplatKernel,
    rules: Rules,
    list: impl Fn(u32, u32) -> &'a [u32] + Sync,
) -> u64 {
    (0..cam.height)
        .into_par_iter()
        .map(|y| {
            (0..cam.width)
                .map(|x| {
                    let (px, py) = (x as f32, y as f32);
                    u64::from(blend_pixel(projected, list(x, y), px, py, kernel, rules).evaluated)
                })
                .sum::<u64>()
        })
        .sum()
}
