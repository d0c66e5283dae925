//! The CPU reference of the differentiable rasterizer, in f64: a forward pass with exactly
//! the reference's rules ([`forward`], the same stages and decisions as [`super::render`])
//! and its backward pass ([`backward`]): from the gradient of a loss with respect to each
//! output pixel (colour, alpha, depth) to the gradient with respect to every Gaussian's
//! centre, quaternion, scale, opacity and colour (SH coefficients or direct channels).
//! A pinhole camera projects by the EWA rule; every other lens by the unscented
//! transform, differentiated through its sigma points (`lens.rs`); a panorama that wraps
//! around draws each Gaussian at the copy nearest each tile, as the renderers do.
//!
//! It is the yardstick of the Vulkan backward pass and is itself checked against central
//! finite differences of [`forward`] (tests in `tests/all/train/gradients.rs`). Derivatives are
//! those of the function the forward computes, piece by piece: where alpha is clamped at
//! the rules' clamp (0.99; gsplat's 0.999), where a colour is clamped at 0, and where the view direction is clamped to the
//! guard band, the clamped quantity has zero derivative (as gsplat; the original CUDA
//! backward ignores the 0.99 clamp). Culling, tile rectangles, the 1/255 skip and the
//! 1e-4 stop are decisions, constant under a small change of the parameters.
//!
//! Pixel (i, j) is evaluated at (i, j); the 2D mean is in those pixel units, so
//! [`SplatGrads::means2d`] is gsplat's `means2d.grad` with the reference's half-pixel
//! convention.

use crate::core::camera::lens::{Intrinsics, Lens};
use crate::core::camera::Camera;
use crate::core::model::grad::{ColorParams, PixelGrads, SplatGrads, SplatParams};
use crate::core::model::{
    sh_coeffs_for_degree, RenderOptions, Rules, SplatKernel, ALPHA_MIN, COV2D_DILATION, TILE_SIZE,
};
use glam::{DMat3, DVec3};
use rayon::prelude::*;

mod lens;
mod shaded;

pub use shaded::{backward_shaded, forward_shaded, MlpParams};

/// A frame of the f64 reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Image64 {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Channels per pixel.
    pub channels: usize,
    /// Colour (with the background), `width * height * channels`, pixel-major.
    pub color: Vec<f64>,
    /// 1 - final transmittance per pixel.
    pub alpha: Vec<f64>,
    /// Alpha-normalised depth per pixel (0 where alpha is 0).
    pub depth: Vec<f64>,
}

/// The camera in f64.
struct Cam64 {
    r: DMat3,
    t: DVec3,
    pos: DVec3,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    /// The guard band ([`Rules::clamp_limits`]).
    lim: [f64; 4],
    rules: Rules,
    size: (u32, u32),
    tiles: (u32, u32),
    lens: Lens,
    k: Intrinsics,
    /// Whether the image wraps around ([`Lens::wraps`]).
    wraps: bool,
}

impl Cam64 {
    fn new(cam: &Camera, rules: Rules) -> Self {
        let r = cam.rotation.as_dmat3();
        let t = cam.translation.as_dvec3();
        let (fx, fy) = (cam.fx as f64, cam.fy as f64);
        let (w, h) = (cam.width as f64, cam.height as f64);
        let (cx, cy) = (cam.cx as f64, cam.cy as f64);
        Cam64 {
            r,
            t,
            pos: -(r.transpose() * t),
            fx,
            fy,
            cx,
            cy,
            lim: rules.clamp_limits(w, h, fx, fy, cx, cy),
            rules,
            size: (cam.width, cam.height),
            tiles: cam.tile_grid(),
            lens: cam.lens.clone(),
            k: cam.intrinsics(),
            wraps: cam.lens.wraps(),
        }
    }
}

/// One projected Gaussian.
#[derive(Clone, Debug)]
struct Proj {
    mean2d: [f64; 2],
    conic: [f64; 3],
    depth: f64,
    opacity: f64,
    color: Vec<f64>,
    rect_min: [u32; 2],
    rect_max: [u32; 2],
}

/// Checks the background's length and the camera.
fn check(p: &SplatParams<f64>, cam: &Camera, background: &[f64]) -> Result<(), String> {
    if background.len() != p.channels() {
        return Err(format!(
            "the background has {} channels for colours of {}",
            background.len(),
            p.channels()
        ));
    }
    cam.validate().map_err(|e| e.to_string())
}

fn normalized(q: [f64; 4]) -> [f64; 4] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    q.map(|v| v / n)
}

/// SH basis values `Y_k(dir)` for `k < (degree + 1)^2`, with the reference's signs and
/// constants (`model::sh::eval_sh`).
pub fn sh_basis(degree: u32, d: DVec3) -> [f64; 16] {
    use crate::core::model::sh::{SH_C0, SH_C1, SH_C2, SH_C3};
    let (c0, c1) = (SH_C0 as f64, SH_C1 as f64);
    let c2 = SH_C2.map(f64::from);
    let c3 = SH_C3.map(f64::from);
    let (x, y, z) = (d.x, d.y, d.z);
    let mut b = [0.0; 16];
    b[0] = c0;
    if degree > 0 {
        b[1] = -c1 * y;
        b[2] = c1 * z;
        b[3] = -c1 * x;
    }
    if degree > 1 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        b[4] = c2[0] * x * y;
        b[5] = c2[1] * y * z;
        b[6] = c2[2] * (2.0 * zz - xx - yy);
        b[7] = c2[3] * x * z;
        b[8] = c2[4] * (xx - yy);
        if degree > 2 {
            b[9] = c3[0] * y * (3.0 * xx - yy);
            b[10] = c3[1] * x * y * z;
            b[11] = c3[2] * y * (4.0 * zz - xx - yy);
            b[12] = c3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
            b[13] = c3[4] * x * (4.0 * zz - xx - yy);
            b[14] = c3[5] * z * (xx - yy);
            b[15] = c3[6] * x * (xx - 3.0 * yy);
        }
    }
    b
}

/// Gradients `dY_k/d(dir)` of [`sh_basis`] (the direction taken as free, not unit).
pub fn sh_basis_grad(degree: u32, d: DVec3) -> [DVec3; 16] {
    use crate::core::model::sh::{SH_C1, SH_C2, SH_C3};
    let c1 = SH_C1 as f64;
    let c2 = SH_C2.map(f64::from);
    let c3 = SH_C3.map(f64::from);
    let (x, y, z) = (d.x, d.y, d.z);
    let mut g = [DVec3::ZERO; 16];
    if degree > 0 {
        g[1] = DVec3::new(0.0, -c1, 0.0);
        g[2] = DVec3::new(0.0, 0.0, c1);
        g[3] = DVec3::new(-c1, 0.0, 0.0);
    }
    if degree > 1 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        g[4] = c2[0] * DVec3::new(y, x, 0.0);
        g[5] = c2[1] * DVec3::new(0.0, z, y);
        g[6] = c2[2] * DVec3::new(-2.0 * x, -2.0 * y, 4.0 * z);
        g[7] = c2[3] * DVec3::new(z, 0.0, x);
        g[8] = c2[4] * DVec3::new(2.0 * x, -2.0 * y, 0.0);
        if degree > 2 {
            g[9] = c3[0] * DVec3::new(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0);
            g[10] = c3[1] * DVec3::new(y * z, x * z, x * y);
            g[11] = c3[2] * DVec3::new(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z);
            g[12] = c3[3] * DVec3::new(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy);
            g[13] = c3[4] * DVec3::new(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z);
            g[14] = c3[5] * DVec3::new(2.0 * x * z, -2.0 * y * z, xx - yy);
            g[15] = c3[6] * DVec3::new(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0);
        }
    }
    g
}

/// The active SH degree and the stored coefficients per channel.
fn sh_degrees(p: &SplatParams<f64>, opts: &RenderOptions) -> (u32, usize) {
    match &p.colors {
        ColorParams::Sh { degree, .. } => (
            opts.active_sh_degree(*degree),
            sh_coeffs_for_degree(*degree),
        ),
        ColorParams::Direct { .. } => (0, 0),
    }
}

/// Whether Gaussian `i` passes the options' filters (as `RenderOptions::keeps`).
fn keeps(p: &SplatParams<f64>, i: usize, opts: &RenderOptions) -> bool {
    if let Some(max) = opts.max_scale {
        let s = p.scales[i];
        let largest = s[0].max(s[1]).max(s[2]);
        if largest.is_nan() || largest > max as f64 {
            return false;
        }
    }
    if let Some(min) = opts.min_opacity {
        let o = p.opacities[i];
        if o.is_nan() || o < min as f64 {
            return false;
        }
    }
    true
}

/// The 3D covariance's factor `M = R S` (so `Sigma = M M^T`) of Gaussian `i`.
fn cov_factor(p: &SplatParams<f64>, i: usize, opts: &RenderOptions) -> (DMat3, [f64; 4], DVec3) {
    let q = normalized(p.quats[i]);
    let m = opts.scale_modifier as f64;
    let s = DVec3::from(p.scales[i]) * m;
    (
        crate::core::quat::quat_to_dmat3(q) * DMat3::from_diagonal(s),
        q,
        s,
    )
}

/// Rows of `T = J W` and the clamped `tx`, `ty` for the view-space centre `v`.
fn jacobian_rows(v: DVec3, cam: &Cam64) -> (DVec3, DVec3, f64, f64) {
    let z = v.z;
    let tx = (v.x / z).clamp(-cam.lim[0], cam.lim[1]) * z;
    let ty = (v.y / z).clamp(-cam.lim[2], cam.lim[3]) * z;
    let j0 = DVec3::new(cam.fx / z, 0.0, -(cam.fx * tx) / (z * z));
    let j1 = DVec3::new(0.0, cam.fy / z, -(cam.fy * ty) / (z * z));
    let w_t = cam.r.transpose();
    (w_t * j0, w_t * j1, tx, ty)
}

/// Gaussian `i`'s 2D mean (pixel `(i, j)` at `(i, j)`), its 2D covariance `[xx, xy, yy]`
/// before the dilation, and its depth; `None` where it is nearer than the near plane or
/// (through a lens) culled. A pinhole projects by the EWA rule with the guard band, every
/// other lens by the unscented transform ([`lens`]).
fn screen(
    p: &SplatParams<f64>,
    i: usize,
    cam: &Cam64,
    opts: &RenderOptions,
) -> Option<([f64; 2], [f64; 3], f64)> {
    let mean = DVec3::from(p.means[i]);
    let v = cam.r * mean + cam.t;
    let (m, _, _) = cov_factor(p, i, opts);
    if !cam.lens.is_pinhole() {
        let depth = lens::depth(&cam.lens, v);
        if !cam.rules.in_front(depth, opts.near() as f64) {
            return None;
        }
        let (mean2d, cov) = lens::project(&cam.lens, &cam.k, v, cam.r * m)?;
        return Some((mean2d, cov, depth));
    }
    if !cam.rules.in_front(v.z, opts.near() as f64) {
        return None;
    }
    let cov3d = m * m.transpose();
    let (t0, t1, _, _) = jacobian_rows(v, cam);
    let cov = [t0.dot(cov3d * t0), t0.dot(cov3d * t1), t1.dot(cov3d * t1)];
    let mean2d = [
        cam.fx * v.x / v.z + cam.cx - 0.5,
        cam.fy * v.y / v.z + cam.cy - 0.5,
    ];
    Some((mean2d, cov, v.z))
}

fn project(p: &SplatParams<f64>, i: usize, cam: &Cam64, opts: &RenderOptions) -> Option<Proj> {
    if !keeps(p, i, opts) {
        return None;
    }
    let mean = DVec3::from(p.means[i]);
    let (mean2d, [a, b, c], depth) = screen(p, i, cam, opts)?;
    let dil = COV2D_DILATION as f64;
    let (a, c) = (a + dil, c + dil);
    let det = a * c - b * b;
    if !cam.rules.keeps_det(det) {
        return None;
    }
    let conic = [c / det, -b / det, a / det];
    let opacity = if opts.antialiased {
        p.opacities[i] * compensation(a, b, c, cam.rules).0
    } else {
        p.opacities[i]
    };
    let e = if cam.wraps {
        // An image that wraps around: the rectangle in the tiles of three turns side by
        // side, at most one turn wide (as `cpu::preprocess_one`).
        cam.rules
            .wrapped_extent([a, b, c], det, opacity, mean2d, cam.size, cam.tiles)?
    } else {
        cam.rules
            .extent([a, b, c], det, opacity, mean2d, cam.size, cam.tiles)?
    };
    let color = match &p.colors {
        ColorParams::Sh { coeffs, .. } => {
            let (active, k) = sh_degrees(p, opts);
            let dir = (mean - cam.pos).normalize();
            let basis = sh_basis(active, dir);
            let sh = &coeffs[i * k * 3..(i + 1) * k * 3];
            (0..3)
                .map(|ch| {
                    let raw: f64 = (0..sh_coeffs_for_degree(active))
                        .map(|j| sh[j * 3 + ch] * basis[j])
                        .sum();
                    (raw + 0.5).max(0.0)
                })
                .collect()
        }
        ColorParams::Direct { channels, values } => {
            values[i * channels..(i + 1) * channels].to_vec()
        }
    };
    Some(Proj {
        mean2d,
        conic,
        depth,
        opacity,
        color,
        rect_min: e.rect_min,
        rect_max: e.rect_max,
    })
}

/// Each tile's Gaussians front to back (by depth, then index: the reference's stable sort).
fn tile_lists(projs: &[Option<Proj>], cam: &Cam64) -> Vec<Vec<u32>> {
    let (tx, ty) = cam.tiles;
    let mut lists: Vec<Vec<(f64, u32)>> = vec![Vec::new(); (tx * ty) as usize];
    for (i, pr) in projs.iter().enumerate() {
        if let Some(pr) = pr {
            for y in pr.rect_min[1]..pr.rect_max[1] {
                for x in pr.rect_min[0]..pr.rect_max[0] {
                    let x = if cam.wraps { x % tx } else { x };
                    lists[(y * tx + x) as usize].push((pr.depth, i as u32));
                }
            }
        }
    }
    lists
        .into_iter()
        .map(|mut l| {
            l.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            l.into_iter().map(|(_, i)| i).collect()
        })
        .collect()
}

/// One Gaussian composited into a pixel.
struct Step {
    id: u32,
    alpha: f64,
    /// Alpha before the clamp.
    unclamped: f64,
    /// Transmittance before this Gaussian.
    t: f64,
    power: f64,
    dx: f64,
    dy: f64,
}

/// The reference's compositing loop at pixel `(px, py)` over `ids` front to back: the
/// Gaussians added and the final transmittance. In an image that wraps around, `wrap` is
/// the pixel's tile's middle column and the image's width: each Gaussian is drawn at the
/// copy of its centre (moved by whole turns) nearest that middle, as
/// `cpu::wrapped_for_tile`.
fn composite(
    projs: &[Option<Proj>],
    ids: &[u32],
    (px, py): (f64, f64),
    wrap: Option<(f64, f64)>,
    kernel: SplatKernel,
    rules: Rules,
) -> (Vec<Step>, f64) {
    let mut t = 1.0;
    let mut steps = Vec::new();
    for &id in ids {
        let g = projs[id as usize]
            .as_ref()
            .expect("listed Gaussians are projected");
        let mx = match wrap {
            Some((middle, w)) => g.mean2d[0] + ((middle - g.mean2d[0]) / w + 0.5).floor() * w,
            None => g.mean2d[0],
        };
        let dx = mx - px;
        let dy = g.mean2d[1] - py;
        let [ca, cb, cc] = g.conic;
        let power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy;
        if power > 0.0 {
            continue;
        }
        let unclamped = match kernel {
            SplatKernel::Gaussian => g.opacity * power.exp(),
            SplatKernel::Power => g.opacity * (1.0 - (-2.0 * power) / 9.0).max(0.0),
        };
        let alpha = unclamped.min(rules.alpha_max() as f64);
        if alpha < ALPHA_MIN as f64 {
            continue;
        }
        let test_t = t * (1.0 - alpha);
        if rules.stops(test_t) {
            break;
        }
        steps.push(Step {
            id,
            alpha,
            unclamped,
            t,
            power,
            dx,
            dy,
        });
        t = test_t;
    }
    (steps, t)
}

/// Projection and per-tile lists of a frame.
struct Raster {
    cam: Cam64,
    projs: Vec<Option<Proj>>,
    lists: Vec<Vec<u32>>,
}

fn rasterize(p: &SplatParams<f64>, cam: &Camera, opts: &RenderOptions) -> Raster {
    let cam = Cam64::new(cam, opts.rules);
    let projs: Vec<Option<Proj>> = (0..p.len())
        .into_par_iter()
        .map(|i| project(p, i, &cam, opts))
        .collect();
    let lists = tile_lists(&projs, &cam);
    Raster { cam, projs, lists }
}

impl Raster {
    fn pixel_list(&self, x: u32, y: u32) -> &[u32] {
        let tile = (y / TILE_SIZE) * self.cam.tiles.0 + x / TILE_SIZE;
        &self.lists[tile as usize]
    }

    fn proj(&self, id: u32) -> &Proj {
        self.projs[id as usize]
            .as_ref()
            .expect("listed Gaussians are projected")
    }

    /// Pixel `(x, y)` composited: the Gaussians added, the final transmittance and the
    /// sum of depth * weight.
    fn pixel(&self, x: usize, y: usize, kernel: SplatKernel) -> (Vec<Step>, f64, f64) {
        let list = self.pixel_list(x as u32, y as u32);
        let wrap = self.cam.wraps.then(|| {
            let middle = (x as u32 / TILE_SIZE * TILE_SIZE + TILE_SIZE / 2) as f64;
            (middle, self.cam.size.0 as f64)
        });
        let pixel = (x as f64, y as f64);
        let (steps, t) = composite(&self.projs, list, pixel, wrap, kernel, self.cam.rules);
        let dacc = steps
            .iter()
            .map(|s| self.proj(s.id).depth * s.alpha * s.t)
            .sum();
        (steps, t, dacc)
    }
}

/// Renders a frame with the reference rules in f64: colour (with `background`, one value
/// per channel), alpha and alpha-normalised depth.
pub fn forward(
    p: &SplatParams<f64>,
    cam: &Camera,
    opts: &RenderOptions,
    background: &[f64],
) -> Result<Image64, String> {
    check(p, cam, background)?;
    let r = rasterize(p, cam, opts);
    let (w, h) = (cam.width as usize, cam.height as usize);
    let d = p.channels();
    let mut img = Image64 {
        width: cam.width,
        height: cam.height,
        channels: d,
        color: vec![0.0; w * h * d],
        alpha: vec![0.0; w * h],
        depth: vec![0.0; w * h],
    };
    let rows: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut color = vec![0.0; w * d];
            let mut alpha = vec![0.0; w];
            let mut depth = vec![0.0; w];
            for x in 0..w {
                let (steps, t, dacc) = r.pixel(x, y, opts.kernel);
                for s in &steps {
                    let g = r.proj(s.id);
                    let wgt = s.alpha * s.t;
                    for ch in 0..d {
                        color[x * d + ch] += g.color[ch] * wgt;
                    }
                }
                for ch in 0..d {
                    color[x * d + ch] += t * background[ch];
                }
                let a = 1.0 - t;
                alpha[x] = a;
                depth[x] = if a > 0.0 { dacc / a } else { 0.0 };
            }
            (color, alpha, depth)
        })
        .collect();
    for (y, (c, a, dp)) in rows.into_iter().enumerate() {
        img.color[y * w * d..(y + 1) * w * d].copy_from_slice(&c);
        img.alpha[y * w..(y + 1) * w].copy_from_slice(&a);
        img.depth[y * w..(y + 1) * w].copy_from_slice(&dp);
    }
    Ok(img)
}

/// Gradients of one Gaussian's projected quantities, summed over the pixels.
#[derive(Clone, Debug, Default)]
struct ProjGrad {
    mean2d: [f64; 2],
    absgrad: [f64; 2],
    conic: [f64; 3],
    opacity: f64,
    depth: f64,
    color: Vec<f64>,
}

fn pixel_grad(g: &PixelGrads<f64>, idx: usize, d: usize) -> (Vec<f64>, f64, f64) {
    let color = if g.color.is_empty() {
        vec![0.0; d]
    } else {
        g.color[idx * d..(idx + 1) * d].to_vec()
    };
    let at = |v: &Vec<f64>| if v.is_empty() { 0.0 } else { v[idx] };
    (color, at(&g.alpha), at(&g.depth))
}

/// The backward pass of [`forward`]: dL/d(every parameter) from dL/d(every output pixel).
pub fn backward(
    p: &SplatParams<f64>,
    cam: &Camera,
    opts: &RenderOptions,
    background: &[f64],
    grads: &PixelGrads<f64>,
) -> Result<SplatGrads<f64>, String> {
    check(p, cam, background)?;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let d = p.channels();
    let lens = [
        ("colour", grads.color.len(), w * h * d),
        ("alpha", grads.alpha.len(), w * h),
        ("depth", grads.depth.len(), w * h),
    ];
    for (name, len, want) in lens {
        if len != 0 && len != want {
            return Err(format!(
                "the {name} gradient has {len} values for a {w}x{h} frame of {d} channels (want {want})"
            ));
        }
    }
    let r = rasterize(p, cam, opts);
    let n = p.len();
    // Per row, the per-Gaussian sums of that row's pixels; rows are merged in order.
    let rows: Vec<Vec<(u32, ProjGrad)>> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut acc: std::collections::BTreeMap<u32, ProjGrad> = Default::default();
            for x in 0..w {
                let idx = y * w + x;
                let (gc, ga, gd) = pixel_grad(grads, idx, d);
                let (steps, t_final, dacc) = r.pixel(x, y, opts.kernel);
                let a = 1.0 - t_final;
                // depth = dacc / a: its gradient reaches dacc and alpha.
                let (g_dacc, g_alpha) = if a > 0.0 {
                    (gd / a, ga - gd * (dacc / a) / a)
                } else {
                    (0.0, ga)
                };
                let mut behind: Vec<f64> = background.iter().map(|b| t_final * b).collect();
                let mut behind_depth = 0.0;
                for s in steps.iter().rev() {
                    let g = r.proj(s.id);
                    let e = acc.entry(s.id).or_insert_with(|| ProjGrad {
                        color: vec![0.0; d],
                        ..Default::default()
                    });
                    let wgt = s.alpha * s.t;
                    let one_minus = 1.0 - s.alpha;
                    let mut g_a = 0.0;
                    for ch in 0..d {
                        e.color[ch] += gc[ch] * wgt;
                        g_a += gc[ch] * (g.color[ch] * s.t - behind[ch] / one_minus);
                        behind[ch] += g.color[ch] * wgt;
                    }
                    e.depth += g_dacc * wgt;
                    g_a += g_dacc * (g.depth * s.t - behind_depth / one_minus);
                    behind_depth += g.depth * wgt;
                    g_a += g_alpha * t_final / one_minus;
                    if s.unclamped < opts.rules.alpha_max() as f64 {
                        let (da_do, da_dpower) = match opts.kernel {
                            SplatKernel::Gaussian => (s.power.exp(), s.unclamped),
                            SplatKernel::Power => {
                                (1.0 + 2.0 * s.power / 9.0, g.opacity * 2.0 / 9.0)
                            }
                        };
                        e.opacity += g_a * da_do;
                        let gp = g_a * da_dpower;
                        let [ca, cb, cc] = g.conic;
                        let gmx = gp * -(ca * s.dx + cb * s.dy);
                        let gmy = gp * -(cc * s.dy + cb * s.dx);
                        e.mean2d[0] += gmx;
                        e.mean2d[1] += gmy;
                        e.absgrad[0] += gmx.abs();
                        e.absgrad[1] += gmy.abs();
                        e.conic[0] += gp * -0.5 * s.dx * s.dx;
                        e.conic[1] += gp * -s.dx * s.dy;
                        e.conic[2] += gp * -0.5 * s.dy * s.dy;
                    }
                }
            }
            acc.into_iter().collect()
        })
        .collect();
    let mut per: Vec<Option<ProjGrad>> = vec![None; n];
    for row in rows {
        for (id, g) in row {
            let e = per[id as usize].get_or_insert_with(|| ProjGrad {
                color: vec![0.0; d],
                ..Default::default()
            });
            for k in 0..2 {
                e.mean2d[k] += g.mean2d[k];
                e.absgrad[k] += g.absgrad[k];
            }
            for k in 0..3 {
                e.conic[k] += g.conic[k];
            }
            e.opacity += g.opacity;
            e.depth += g.depth;
            for ch in 0..d {
                e.color[ch] += g.color[ch];
            }
        }
    }
    let stride = p.color_stride();
    let mut out = SplatGrads::zeros(n, stride);
    for (i, g) in per.iter().enumerate() {
        if let Some(g) = g {
            project_backward(p, i, &r.cam, opts, g, &mut out);
        }
    }
    Ok(out)
}

/// The antialiased opacity compensation `sqrt(max(r, floor))` (the rules' floor), `r =
/// det(cov2d) / det(cov2d + dilation)`, of the dilated 2D covariance `(a, b; b, c)`, and
/// its derivatives with respect to a, b and c (0 where the ratio is clamped).
fn compensation(a: f64, b: f64, c: f64, rules: Rules) -> (f64, [f64; 3]) {
    let dil = COV2D_DILATION as f64;
    let det = a * c - b * b;
    let det0 = (a - dil) * (c - dil) - b * b;
    let r = det0 / det;
    let min = rules.antialias_min_ratio() as f64;
    if r <= min {
        return (min.sqrt(), [0.0; 3]);
    }
    let comp = r.sqrt();
    // dr/dx = (det0' det - det0 det') / det^2; dcomp/dr = 1 / (2 comp).
    let k = 0.5 / comp / (det * det);
    let ga = k * ((c - dil) * det - det0 * c);
    let gc = k * ((a - dil) * det - det0 * a);
    let gb = k * (-2.0 * b * det + det0 * 2.0 * b);
    (comp, [ga, gb, gc])
}

/// Chain rule through the preprocess of Gaussian `i`: from its projected quantities'
/// gradients to its parameters'.
fn project_backward(
    p: &SplatParams<f64>,
    i: usize,
    cam: &Cam64,
    opts: &RenderOptions,
    g: &ProjGrad,
    out: &mut SplatGrads<f64>,
) {
    out.means2d[i] = g.mean2d;
    out.absgrad[i] = g.absgrad;
    out.opacities[i] = g.opacity;
    let rgb = match p.colors {
        ColorParams::Sh { .. } => [g.color[0], g.color[1], g.color[2]],
        ColorParams::Direct { .. } => [0.0; 3],
    };
    let [ca, cb, cc] = g.conic;
    out.screen[i] = [ca, cb, cc, rgb[0], rgb[1], rgb[2], g.depth, g.opacity];
    let mean = DVec3::from(p.means[i]);
    let v = cam.r * mean + cam.t;
    let (m, q, s) = cov_factor(p, i, opts);
    let (_, [a, b, c], _) = screen(p, i, cam, opts).expect("a listed Gaussian is projected");
    let dil = COV2D_DILATION as f64;
    let (a, c) = (a + dil, c + dil);
    let det = a * c - b * b;
    let det2 = det * det;
    // conic (A, B, C) = (c, -b, a) / det.
    let [ga_, gb_, gc_] = g.conic;
    let mut g_a = ga_ * (-c * c / det2) + gb_ * (b * c / det2) + gc_ * (1.0 / det - a * c / det2);
    let mut g_c = ga_ * (1.0 / det - a * c / det2) + gb_ * (b * a / det2) + gc_ * (-a * a / det2);
    let mut g_b = ga_ * (2.0 * b * c / det2)
        + gb_ * (-1.0 / det - 2.0 * b * b / det2)
        + gc_ * (2.0 * a * b / det2);
    if opts.antialiased {
        // The blended opacity is opacity * comp(a, b, c).
        let (comp, [da, db, dc]) = compensation(a, b, c, cam.rules);
        out.opacities[i] = g.opacity * comp;
        let g_comp = g.opacity * p.opacities[i];
        g_a += g_comp * da;
        g_b += g_comp * db;
        g_c += g_comp * dc;
    }
    let (g_v, g_m) = if cam.lens.is_pinhole() {
        pinhole_backward(v, m, cam, g, [g_a, g_b, g_c])
    } else {
        // Through the lens: camera-space axes W M, so dL/dM = W^T dL/d(W M).
        let (g_v, g_axes) = lens::project_backward(
            &cam.lens,
            &cam.k,
            v,
            cam.r * m,
            g.mean2d,
            [g_a, g_b, g_c],
            g.depth,
        );
        (g_v, cam.r.transpose() * g_axes)
    };
    let mut g_mean = cam.r.transpose() * g_v;
    let rot = crate::core::quat::quat_to_dmat3(q);
    let modifier = opts.scale_modifier as f64;
    let g_scale: [f64; 3] = std::array::from_fn(|k| rot.col(k).dot(g_m.col(k)) * modifier);
    let g_rot = DMat3::from_cols(g_m.col(0) * s.x, g_m.col(1) * s.y, g_m.col(2) * s.z);
    // R[row][col] = g_rot.col(col)[row].
    let gr = |row: usize, col: usize| g_rot.col(col)[row];
    let [qr, qx, qy, qz] = q;
    let gq = [
        2.0 * (qz * (gr(1, 0) - gr(0, 1))
            + qy * (gr(0, 2) - gr(2, 0))
            + qx * (gr(2, 1) - gr(1, 2))),
        2.0 * (qy * (gr(1, 0) + gr(0, 1))
            + qz * (gr(2, 0) + gr(0, 2))
            + qr * (gr(2, 1) - gr(1, 2))
            - 2.0 * qx * (gr(1, 1) + gr(2, 2))),
        2.0 * (qx * (gr(1, 0) + gr(0, 1))
            + qr * (gr(0, 2) - gr(2, 0))
            + qz * (gr(2, 1) + gr(1, 2))
            - 2.0 * qy * (gr(0, 0) + gr(2, 2))),
        2.0 * (qr * (gr(1, 0) - gr(0, 1))
            + qx * (gr(2, 0) + gr(0, 2))
            + qy * (gr(2, 1) + gr(1, 2))
            - 2.0 * qz * (gr(0, 0) + gr(1, 1))),
    ];
    // Normalisation: q_hat = q / |q|.
    let raw = p.quats[i];
    let norm = (raw[0] * raw[0] + raw[1] * raw[1] + raw[2] * raw[2] + raw[3] * raw[3]).sqrt();
    let dot = gq[0] * q[0] + gq[1] * q[1] + gq[2] * q[2] + gq[3] * q[3];
    out.quats[i] = [0, 1, 2, 3].map(|k| (gq[k] - q[k] * dot) / norm);
    out.scales[i] = g_scale;
    // Colours.
    let stride = p.color_stride();
    match &p.colors {
        ColorParams::Direct { .. } => {
            out.colors[i * stride..(i + 1) * stride].copy_from_slice(&g.color);
        }
        ColorParams::Sh { coeffs, .. } => {
            let (active, k) = sh_degrees(p, opts);
            let u = mean - cam.pos;
            let len = u.length();
            let dir = u / len;
            let basis = sh_basis(active, dir);
            let basis_grad = sh_basis_grad(active, dir);
            let sh = &coeffs[i * k * 3..(i + 1) * k * 3];
            let used = sh_coeffs_for_degree(active);
            let mut g_dir = DVec3::ZERO;
            for ch in 0..3 {
                let raw: f64 = (0..used).map(|j| sh[j * 3 + ch] * basis[j]).sum();
                // colour = max(raw + 0.5, 0).
                if raw + 0.5 < 0.0 {
                    continue;
                }
                let gch = g.color[ch];
                for j in 0..used {
                    out.colors[i * stride + j * 3 + ch] = basis[j] * gch;
                    g_dir += basis_grad[j] * (sh[j * 3 + ch] * gch);
                }
            }
            // dir = u / |u|.
            g_mean += (g_dir - dir * dir.dot(g_dir)) / len;
        }
    }
    out.means[i] = g_mean.to_array();
}

/// The pinhole's EWA projection backward (with the guard band's clamp): from the
/// gradients of the 2D mean, depth and 2D covariance `[a, b, c]` of the Gaussian with
/// view-space centre `v` and covariance factor `m`, to `dL/dv` (view space) and `dL/dM`.
fn pinhole_backward(
    v: DVec3,
    m: DMat3,
    cam: &Cam64,
    g: &ProjGrad,
    [g_a, g_b, g_c]: [f64; 3],
) -> (DVec3, DMat3) {
    let z = v.z;
    let cov3d = m * m.transpose();
    let (t0, t1, tx, ty) = jacobian_rows(v, cam);
    // a = t0' S t0, b = t0' S t1, c = t1' S t1.
    let g_cov = DMat3::from_cols(
        g_a * t0 * t0.x + g_b * t0 * t1.x + g_c * t1 * t1.x,
        g_a * t0 * t0.y + g_b * t0 * t1.y + g_c * t1 * t1.y,
        g_a * t0 * t0.z + g_b * t0 * t1.z + g_c * t1 * t1.z,
    );
    let g_t0 = 2.0 * g_a * (cov3d * t0) + g_b * (cov3d * t1);
    let g_t1 = 2.0 * g_c * (cov3d * t1) + g_b * (cov3d * t0);
    // t_k = W^T j_k.
    let g_j0 = cam.r * g_t0;
    let g_j1 = cam.r * g_t1;
    let (fx, fy) = (cam.fx, cam.fy);
    let mut g_v = DVec3::ZERO;
    g_v.z += g_j0.x * (-fx / (z * z)) + g_j0.z * (2.0 * fx * tx / (z * z * z));
    g_v.z += g_j1.y * (-fy / (z * z)) + g_j1.z * (2.0 * fy * ty / (z * z * z));
    let g_tx = g_j0.z * (-fx / (z * z));
    let g_ty = g_j1.z * (-fy / (z * z));
    // tx = clamp(x / z, -lim, lim) z: x passes where unclamped, z carries the bound where clamped.
    let (ux, uy) = (v.x / z, v.y / z);
    if ux >= -cam.lim[0] && ux <= cam.lim[1] {
        g_v.x += g_tx;
    } else {
        g_v.z += g_tx * tx / z;
    }
    if uy >= -cam.lim[2] && uy <= cam.lim[3] {
        g_v.y += g_ty;
    } else {
        g_v.z += g_ty * ty / z;
    }
    // mean2d = f * v.xy / z + c - 0.5; depth = z.
    g_v.x += g.mean2d[0] * fx / z;
    g_v.y += g.mean2d[1] * fy / z;
    g_v.z -= (g.mean2d[0] * fx * v.x + g.mean2d[1] * fy * v.y) / (z * z);
    g_v.z += g.depth;
    // Sigma = M M^T.
    (g_v, (g_cov + g_cov.transpose()) * m)
}
