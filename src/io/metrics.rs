//! Image comparison metrics, the one place in verisplat that computes them: PSNR, error
//! statistics (largest and mean absolute error, share of 8-bit values within one step),
//! SSIM as the original 3DGS evaluation computes it, and NVIDIA's LDR-FLIP.
//!
//! Images are slices of `f32` samples, row-major with the channels of a pixel adjacent
//! (`H x W x C`, as `Frame::color` flattened, NumPy or PyTorch after a permute).
//!
//! PSNR of identical images is infinite (`f64::INFINITY`); `serde_json` writes it as
//! `null`, and the command-line tables print `inf`.

use crate::core::frame::Frame;
use rayon::prelude::*;
use serde::Serialize;

/// PSNR in dB of a mean squared error, for signals whose peak value is `peak`
/// (`10 log10(peak^2 / mse)`); infinite when `mse` is 0.
pub fn psnr_from_mse(mse: f64, peak: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        10.0 * (peak * peak / mse).log10()
    }
}

/// Mean squared difference of two equally long sample slices (0 for empty ones).
pub fn mse(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "mse of slices of different lengths");
    let se: f64 = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = x as f64 - y as f64;
            d * d
        })
        .sum();
    se / a.len().max(1) as f64
}

/// PSNR in dB of two sample slices over every sample, as the original 3DGS
/// `utils/image_utils.py psnr` computes it for `peak` 1; infinite when they are equal.
pub fn psnr(a: &[f32], b: &[f32], peak: f64) -> f64 {
    psnr_from_mse(mse(a, b), peak)
}

/// Absolute-error figures of one image plane set (colour, alpha or depth).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ErrorStats {
    /// PSNR in dB against `peak`; infinite (JSON `null`) when the values are equal.
    pub psnr: f64,
    /// Largest absolute difference of one sample.
    pub max_abs: f64,
    /// Mean absolute difference over all samples.
    pub mean_abs: f64,
    /// Share (0..=1) of pixels whose every channel, divided by `peak` and quantised to 8
    /// bits as PNGs are written ([`crate::io::output::to_u8`]), differs by at most one step
    /// (1/255).
    pub within: f64,
    /// The value PSNR and the 8-bit quantisation are relative to.
    pub peak: f64,
}

/// Error statistics of `test` against `reference`, `channels` samples per pixel, values as
/// given (clamp them first where the comparison is meant to be of displayable values).
pub fn error_stats(reference: &[f32], test: &[f32], channels: usize, peak: f64) -> ErrorStats {
    assert_eq!(reference.len(), test.len(), "planes of different sizes");
    let channels = channels.max(1);
    let q = |v: f32| crate::io::output::to_u8((v as f64 / peak) as f32) as i32;
    let (mut se, mut abs_sum, mut max_abs, mut within) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    for (r, t) in reference.chunks(channels).zip(test.chunks(channels)) {
        let mut ok = true;
        for (&x, &y) in r.iter().zip(t) {
            // Equal samples differ by nothing, equal infinities included (an EXR's Z is
            // +inf wherever nothing was hit, and inf - inf would be NaN).
            let d = if x == y {
                0.0
            } else {
                (y as f64 - x as f64).abs()
            };
            se += d * d;
            abs_sum += d;
            // NaN compares false, so a NaN difference is caught by the PSNR, not hidden here.
            max_abs = if d > max_abs || d.is_nan() {
                d
            } else {
                max_abs
            };
            ok &= (q(x) - q(y)).abs() <= 1;
        }
        within += ok as usize;
    }
    let samples = reference.len().max(1) as f64;
    let pixels = reference.len().div_ceil(channels).max(1) as f64;
    ErrorStats {
        psnr: psnr_from_mse(se / samples, peak),
        max_abs,
        mean_abs: abs_sum / samples,
        within: if reference.is_empty() {
            1.0
        } else {
            within as f64 / pixels
        },
        peak,
    }
}

/// What an image plane holds, which decides how [`plane_metrics`] compares it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlaneKind {
    /// Displayable colour (RGB, or grey): clamped to [0, 1], peak 1, with SSIM, and
    /// LDR-FLIP when it has three channels.
    Colour,
    /// Alpha: clamped to [0, 1], peak 1.
    Alpha,
    /// Any other data (depth, features): compared as given, peak the largest finite
    /// absolute value of the reference (1 when it has none).
    Data,
}

/// The figures of one plane set of two images: error statistics, and for colour SSIM and
/// LDR-FLIP.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PlaneMetrics {
    /// PSNR, error figures and 8-bit agreement.
    #[serde(flatten)]
    pub stats: ErrorStats,
    /// SSIM ([`ssim`]), for colour.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ssim: Option<f64>,
    /// Mean LDR-FLIP ([`flip`] at [`flip_default_ppd`]), for three-channel colour.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flip: Option<f64>,
}

/// Compares `test` with `reference`, `width x height x channels` samples each, by the
/// rules of `kind` (the rules of `verisplat compare A B`). Colour and alpha samples are
/// clamped to [0, 1] in place, so a caller can draw a difference map of exactly what was
/// compared (divided by the returned peak).
pub fn plane_metrics(
    reference: &mut [f32],
    test: &mut [f32],
    width: usize,
    height: usize,
    channels: usize,
    kind: PlaneKind,
) -> PlaneMetrics {
    let peak = match kind {
        PlaneKind::Colour | PlaneKind::Alpha => {
            for v in reference.iter_mut().chain(test.iter_mut()) {
                *v = v.clamp(0.0, 1.0);
            }
            1.0
        }
        PlaneKind::Data => {
            let m = reference
                .iter()
                .filter(|v| v.is_finite())
                .fold(0.0f32, |m, v| m.max(v.abs()));
            if m > 0.0 {
                m as f64
            } else {
                1.0
            }
        }
    };
    let stats = error_stats(reference, test, channels, peak);
    let colour = kind == PlaneKind::Colour;
    PlaneMetrics {
        stats,
        ssim: colour.then(|| ssim(reference, test, width, height, channels)),
        flip: (colour && channels == 3)
            .then(|| flip(reference, test, width, height, flip_default_ppd())),
    }
}

/// The metrics of a rendered frame against the reference's render of the same camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FrameComparison {
    /// Colour clamped to [0, 1] (what an 8-bit image shows), peak 1.
    pub color: ErrorStats,
    /// SSIM of the clamped colour ([`ssim`]).
    pub ssim: f64,
    /// Alpha (`1 - T`), peak 1.
    pub alpha: ErrorStats,
    /// Depth, peak the reference's largest depth (1 when it has none), compared where the
    /// reference's alpha is at least [`DEPTH_MIN_ALPHA`]; other pixels count as equal.
    pub depth: ErrorStats,
}

/// Depth is only compared where the reference's alpha reaches this: depth is normalised by
/// alpha, so at a pixel only a faint Gaussian reaches, one contribution accepted by one
/// renderer and skipped by the other at the 1/255 alpha threshold (exp rounding differs in
/// the last bit) moves the depth by the whole distance to that Gaussian, though it moves
/// the colour and alpha by at most 1/255.
pub const DEPTH_MIN_ALPHA: f32 = 0.5;

/// Colour clamped to [0, 1], flattened to `H x W x 3` samples.
pub fn clamped_color(frame: &Frame) -> Vec<f32> {
    frame
        .color
        .iter()
        .flat_map(|c| c.map(|v| v.clamp(0.0, 1.0)))
        .collect()
}

/// Compares `test` with `reference` (same size): colour, alpha and depth error statistics
/// and colour SSIM.
pub fn compare_frames(reference: &Frame, test: &Frame) -> FrameComparison {
    assert_eq!(
        (reference.width, reference.height),
        (test.width, test.height),
        "frames of different sizes"
    );
    let (rc, tc) = (clamped_color(reference), clamped_color(test));
    let peak = reference
        .depth
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .fold(0.0f32, f32::max);
    let peak = if peak > 0.0 { peak as f64 } else { 1.0 };
    // Outside the mask both sides take the reference's value, so they count as equal.
    let masked_depth: Vec<f32> = test
        .depth
        .iter()
        .zip(&reference.depth)
        .zip(&reference.alpha)
        .map(|((&t, &r), &a)| if a >= DEPTH_MIN_ALPHA { t } else { r })
        .collect();
    FrameComparison {
        color: error_stats(&rc, &tc, 3, 1.0),
        ssim: ssim(
            &rc,
            &tc,
            reference.width as usize,
            reference.height as usize,
            3,
        ),
        alpha: error_stats(&reference.alpha, &test.alpha, 1, 1.0),
        depth: error_stats(&reference.depth, &masked_depth, 1, peak),
    }
}

/// Side of the SSIM window.
pub const SSIM_WINDOW: usize = 11;
/// Standard deviation of the SSIM window's Gaussian, in pixels.
pub const SSIM_SIGMA: f64 = 1.5;
/// SSIM's `C1 = (0.01 L)^2` for data range `L = 1`.
pub const SSIM_C1: f64 = 0.01 * 0.01;
/// SSIM's `C2 = (0.03 L)^2` for data range `L = 1`.
pub const SSIM_C2: f64 = 0.03 * 0.03;

/// The normalised 1D Gaussian of the SSIM window (`SSIM_WINDOW` taps, sigma `SSIM_SIGMA`).
pub(crate) fn ssim_taps() -> [f64; SSIM_WINDOW] {
    let half = (SSIM_WINDOW / 2) as f64;
    let mut g = [0.0; SSIM_WINDOW];
    for (i, w) in g.iter_mut().enumerate() {
        let x = i as f64 - half;
        *w = (-x * x / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let sum: f64 = g.iter().sum();
    g.map(|w| w / sum)
}

/// Correlates a `width x height` plane with the separable kernel `taps` (odd length)
/// along both axes, treating everything outside the plane as `outside(nearest inside)`.
fn separable_filter(
    plane: &[f64],
    width: usize,
    height: usize,
    taps_x: &[f64],
    taps_y: &[f64],
    edge: Padding,
) -> Vec<f64> {
    let sample = |len: usize, i: isize| -> Option<usize> {
        if i >= 0 && (i as usize) < len {
            Some(i as usize)
        } else {
            match edge {
                Padding::Zero => None,
                Padding::Clamp => Some(i.clamp(0, len as isize - 1) as usize),
            }
        }
    };
    let (rx, ry) = ((taps_x.len() / 2) as isize, (taps_y.len() / 2) as isize);
    let mut rows = vec![0.0; plane.len()];
    rows.par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(y, out)| {
            let src = &plane[y * width..(y + 1) * width];
            for (x, o) in out.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (k, w) in taps_x.iter().enumerate() {
                    if let Some(i) = sample(width, x as isize + k as isize - rx) {
                        acc += w * src[i];
                    }
                }
                *o = acc;
            }
        });
    let mut out = vec![0.0; plane.len()];
    out.par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(y, o)| {
            for (k, w) in taps_y.iter().enumerate() {
                if let Some(j) = sample(height, y as isize + k as isize - ry) {
                    let src = &rows[j * width..(j + 1) * width];
                    for (v, s) in o.iter_mut().zip(src) {
                        *v += w * s;
                    }
                }
            }
        });
    out
}

/// What a filter reads outside the image.
#[derive(Clone, Copy, PartialEq)]
enum Padding {
    /// Zeros (PyTorch `conv2d` with `padding`).
    Zero,
    /// The nearest edge pixel (NumPy `pad(mode="edge")`).
    Clamp,
}

/// Mean SSIM of `test` against `reference` (`H x W x C` samples, data range 1), exactly as
/// the original 3DGS `utils/loss_utils.py ssim` evaluates it: an 11x11 Gaussian window of
/// sigma 1.5, `C1 = 0.01^2`, `C2 = 0.03^2`, each channel filtered on its own with zero
/// padding to the same size (so the window near the border sees zeros, which lowers the
/// border's SSIM a little compared with scikit-image's cropped variant), and the SSIM map
/// averaged over every pixel and channel. Computed in `f64`.
pub fn ssim(reference: &[f32], test: &[f32], width: usize, height: usize, channels: usize) -> f64 {
    assert_eq!(reference.len(), test.len(), "images of different sizes");
    assert_eq!(reference.len(), width * height * channels, "size mismatch");
    if reference.is_empty() {
        return 1.0;
    }
    let taps = ssim_taps();
    let filter = |p: &[f64]| separable_filter(p, width, height, &taps, &taps, Padding::Zero);
    let mut total = 0.0;
    for c in 0..channels {
        let x: Vec<f64> = reference
            .iter()
            .skip(c)
            .step_by(channels)
            .map(|&v| v as f64)
            .collect();
        let y: Vec<f64> = test
            .iter()
            .skip(c)
            .step_by(channels)
            .map(|&v| v as f64)
            .collect();
        let mu_x = filter(&x);
        let mu_y = filter(&y);
        let xx = filter(&x.iter().map(|v| v * v).collect::<Vec<_>>());
        let yy = filter(&y.iter().map(|v| v * v).collect::<Vec<_>>());
        let xy = filter(&x.iter().zip(&y).map(|(a, b)| a * b).collect::<Vec<_>>());
        total += (0..x.len())
            .map(|i| {
                let (mx, my) = (mu_x[i], mu_y[i]);
                let sxx = xx[i] - mx * mx;
                let syy = yy[i] - my * my;
                let sxy = xy[i] - mx * my;
                ((2.0 * mx * my + SSIM_C1) * (2.0 * sxy + SSIM_C2))
                    / ((mx * mx + my * my + SSIM_C1) * (sxx + syy + SSIM_C2))
            })
            .sum::<f64>();
    }
    total / reference.len() as f64
}

/// [`ssim`] of `image` against `target` and its gradient with respect to `image` (what a
/// trainer differentiates: the original's `ssim(rendered, gt)`), in `f64`. With the local
/// moments `mx = E[x]`, `Exx = E[x^2]`, `Exy = E[xy]` (the Gaussian window, zero padding),
/// `S = A1 A2 / (B1 B2)`, `A1 = 2 mx my + C1`, `A2 = 2 (Exy - mx my) + C2`,
/// `B1 = mx^2 + my^2 + C1`, `B2 = (Exx - mx^2) + (Eyy - my^2) + C2`; the window is
/// symmetric, so the adjoint of each filtering is the same filtering and
/// `dS/dx(p) = F[dS/dmx](p) + 2 x(p) F[dS/dExx](p) + y(p) F[dS/dExy](p)`, over `n` values.
pub fn ssim_with_gradient(
    image: &[f64],
    target: &[f64],
    width: usize,
    height: usize,
    channels: usize,
) -> (f64, Vec<f64>) {
    ssim_with_gradient_weighted(image, target, width, height, channels, None)
}

/// [`ssim_with_gradient`] of the weighted mean of the SSIM map (`weights` one per pixel,
/// the same for every channel; `None`: all 1): `sum w S / (channels sum w)`, and its
/// gradient with respect to `image`.
pub fn ssim_with_gradient_weighted(
    image: &[f64],
    target: &[f64],
    width: usize,
    height: usize,
    channels: usize,
    weights: Option<&[f64]>,
) -> (f64, Vec<f64>) {
    assert_eq!(image.len(), target.len(), "images of different sizes");
    assert_eq!(image.len(), width * height * channels, "size mismatch");
    let n = match weights {
        None => image.len() as f64,
        Some(w) => w.iter().sum::<f64>() * channels as f64,
    };
    if image.is_empty() || n == 0.0 {
        return (1.0, vec![0.0; image.len()]);
    }
    let weight = |i: usize| weights.map_or(1.0, |w| w[i]);
    let taps = ssim_taps();
    let filter = |p: &[f64]| separable_filter(p, width, height, &taps, &taps, Padding::Zero);
    let mut total = 0.0;
    let mut grad = vec![0.0; image.len()];
    for c in 0..channels {
        let plane =
            |v: &[f64]| -> Vec<f64> { v.iter().skip(c).step_by(channels).copied().collect() };
        let (x, y) = (plane(image), plane(target));
        let mu_x = filter(&x);
        let mu_y = filter(&y);
        let xx = filter(&x.iter().map(|v| v * v).collect::<Vec<_>>());
        let yy = filter(&y.iter().map(|v| v * v).collect::<Vec<_>>());
        let xy = filter(&x.iter().zip(&y).map(|(a, b)| a * b).collect::<Vec<_>>());
        let pixels = x.len();
        let (mut g_m, mut g_xx, mut g_xy) =
            (vec![0.0; pixels], vec![0.0; pixels], vec![0.0; pixels]);
        for i in 0..pixels {
            let (mx, my) = (mu_x[i], mu_y[i]);
            let a1 = 2.0 * mx * my + SSIM_C1;
            let a2 = 2.0 * (xy[i] - mx * my) + SSIM_C2;
            let b1 = mx * mx + my * my + SSIM_C1;
            let b2 = (xx[i] - mx * mx) + (yy[i] - my * my) + SSIM_C2;
            let s = a1 * a2 / (b1 * b2);
            let wi = weight(i);
            total += wi * s;
            g_m[i] = wi
                * (2.0 * my * a2 / (b1 * b2) - 2.0 * mx * s / b1 + 2.0 * mx * s / b2
                    - 2.0 * my * a1 / (b1 * b2));
            g_xx[i] = wi * (-s / b2);
            g_xy[i] = wi * (2.0 * a1 / (b1 * b2));
        }
        let (f_m, f_xx, f_xy) = (filter(&g_m), filter(&g_xx), filter(&g_xy));
        for i in 0..pixels {
            grad[i * channels + c] = (f_m[i] + 2.0 * x[i] * f_xx[i] + y[i] * f_xy[i]) / n;
        }
    }
    (total / n, grad)
}

/// FLIP's default observer: 0.7 m from a 0.7 m wide display of 3840 pixels, about 67.02
/// pixels per degree of visual angle (the `flip` tool's default, computed as it does).
pub fn flip_default_ppd() -> f64 {
    (0.7f32 * (3840.0f32 / 0.7f32) * (std::f32::consts::PI / 180.0)) as f64
}

/// sRGB (linear, D65) to CIE XYZ, the exact rational form FLIP uses.
const RGB_TO_XYZ: [[f64; 3]; 3] = [
    [
        10135552.0 / 24577794.0,
        8788810.0 / 24577794.0,
        4435075.0 / 24577794.0,
    ],
    [
        2613072.0 / 12288897.0,
        8788810.0 / 12288897.0,
        887015.0 / 12288897.0,
    ],
    [
        1425312.0 / 73733382.0,
        8788810.0 / 73733382.0,
        70074185.0 / 73733382.0,
    ],
];

/// CIE XYZ to linear sRGB, the inverse of [`RGB_TO_XYZ`].
const XYZ_TO_RGB: [[f64; 3]; 3] = [
    [3.241003275, -1.537398934, -0.498615861],
    [-0.969224334, 1.875930071, 0.041554224],
    [0.055639423, -0.204011202, 1.057148933],
];

fn mat3(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

/// The reference white: XYZ of linear RGB (1, 1, 1).
fn white() -> [f64; 3] {
    mat3(&RGB_TO_XYZ, [1.0; 3])
}

/// The sRGB transfer function, encoded to linear.
fn srgb_to_linear(v: f64) -> f64 {
    if v > 0.04045 {
        ((v + 0.055) / 1.055).powf(2.4)
    } else {
        v / 12.92
    }
}

/// Linear RGB to YCxCz, the linearised opponent space FLIP filters in.
fn linear_to_ycxcz(rgb: [f64; 3]) -> [f64; 3] {
    let w = white();
    let xyz = mat3(&RGB_TO_XYZ, rgb);
    let [x, y, z] = [xyz[0] / w[0], xyz[1] / w[1], xyz[2] / w[2]];
    [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
}

/// YCxCz back to linear RGB.
fn ycxcz_to_linear(c: [f64; 3]) -> [f64; 3] {
    let w = white();
    let y = (c[0] + 16.0) / 116.0;
    let x = y + c[1] / 500.0;
    let z = y - c[2] / 200.0;
    mat3(&XYZ_TO_RGB, [x * w[0], y * w[1], z * w[2]])
}

/// Linear RGB to CIE L*a*b* followed by FLIP's Hunt adjustment (a*, b* scaled by L*/100).
fn linear_to_hunt_lab(rgb: [f64; 3]) -> [f64; 3] {
    let w = white();
    let xyz = mat3(&RGB_TO_XYZ, rgb);
    let delta: f64 = 6.0 / 29.0;
    let f = |t: f64| {
        if t > delta.powi(3) {
            t.cbrt()
        } else {
            t / (3.0 * delta * delta) + 4.0 / 29.0
        }
    };
    let [fx, fy, fz] = [f(xyz[0] / w[0]), f(xyz[1] / w[1]), f(xyz[2] / w[2])];
    let l = 116.0 * fy - 16.0;
    let (a, b) = (500.0 * (fx - fy), 200.0 * (fy - fz));
    [l, 0.01 * l * a, 0.01 * l * b]
}

/// HyAB distance: |dL| + Euclidean distance of (a, b).
fn hyab(p: [f64; 3], q: [f64; 3]) -> f64 {
    (p[0] - q[0]).abs() + ((p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

/// `exp(-pi^2 d^2 / b)` sampled at `radius` pixels either side of 0 (`d` in degrees).
fn csf_gaussian(b: f64, radius: usize, ppd: f64) -> Vec<f64> {
    use std::f64::consts::PI;
    (0..=2 * radius)
        .map(|i| {
            let d = (i as f64 - radius as f64) / ppd;
            (-PI * PI * d * d / b).exp()
        })
        .collect()
}

/// The FLIP spatial filters of the three YCxCz channels: each CSF is a sum of one or two
/// 2D Gaussians, `(a1, b1, a2, b2)`; `a2 = 0` leaves a single Gaussian.
const CSF: [[f64; 4]; 3] = [
    [1.0, 0.0047, 0.0, 1e-5],
    [1.0, 0.0053, 0.0, 1e-5],
    [34.1, 0.04, 13.5, 0.025],
];

/// Filters one channel with the 2D CSF `a1 G(b1) + a2 G(b2)` normalised to unit sum,
/// evaluated as separable passes (each term is a product of two 1D Gaussians) with the
/// image edge repeated outside.
fn csf_filter(plane: &[f64], width: usize, height: usize, csf: [f64; 4], ppd: f64) -> Vec<f64> {
    let max_b = CSF.iter().flat_map(|c| [c[1], c[3]]).fold(0.0f64, f64::max);
    let radius =
        (3.0 * (max_b / (2.0 * std::f64::consts::PI.powi(2))).sqrt() * ppd).ceil() as usize;
    let [a1, b1, a2, b2] = csf;
    // The 2D term k * g(x) g(y) with g = exp(-pi^2 x^2 / b), k = a sqrt(pi / b): split it
    // as sqrt(k) g(x) times sqrt(k) g(y), then normalise by the 2D kernel's total.
    let terms: Vec<Vec<f64>> = [(a1, b1), (a2, b2)]
        .into_iter()
        .filter(|&(a, _)| a != 0.0)
        .map(|(a, b)| {
            let k = (a * (std::f64::consts::PI / b).sqrt()).sqrt();
            csf_gaussian(b, radius, ppd)
                .into_iter()
                .map(|v| v * k)
                .collect()
        })
        .collect();
    let total: f64 = terms.iter().map(|t| t.iter().sum::<f64>().powi(2)).sum();
    let mut out = vec![0.0; plane.len()];
    for t in &terms {
        let f = separable_filter(plane, width, height, t, t, Padding::Clamp);
        for (o, v) in out.iter_mut().zip(f) {
            *o += v / total;
        }
    }
    out
}

/// FLIP's edge and point detectors along x (transpose for y): the first and second
/// derivative of a Gaussian of standard deviation `0.5 * 0.082 * ppd` pixels (half the
/// peak-to-trough width of human edge detection), positive weights normalised to sum to 1
/// and negative ones to -1. Returned as (derivative taps along x, Gaussian taps along y),
/// whose product is the normalised 2D kernel.
fn feature_taps(ppd: f64, point: bool) -> (Vec<f64>, Vec<f64>) {
    let sd = 0.5 * 0.082 * ppd;
    let radius = (3.0 * sd).ceil() as isize;
    let g = |x: f64| (-x * x / (2.0 * sd * sd)).exp();
    let xs: Vec<f64> = (-radius..=radius).map(|x| x as f64).collect();
    let gauss: Vec<f64> = xs.iter().map(|&x| g(x)).collect();
    let deriv: Vec<f64> = xs
        .iter()
        .map(|&x| {
            if point {
                (x * x / (sd * sd) - 1.0) * g(x)
            } else {
                -x * g(x)
            }
        })
        .collect();
    // In 2D the kernel is deriv(x) gauss(y); its positive (negative) part sums to the 1D
    // positive (negative) sum times the sum of `gauss`.
    let gsum: f64 = gauss.iter().sum();
    let pos: f64 = deriv.iter().filter(|v| **v > 0.0).sum::<f64>() * gsum;
    let neg: f64 = -deriv.iter().filter(|v| **v < 0.0).sum::<f64>() * gsum;
    let deriv = deriv
        .into_iter()
        .map(|v| if v > 0.0 { v / pos } else { v / neg })
        .collect();
    (deriv, gauss)
}

/// Per-pixel LDR-FLIP error (0..=1) of `test` against `reference`, both `H x W x 3`
/// sRGB-encoded colour (display values, as 8-bit images hold them; clamped to [0, 1]),
/// at `ppd` pixels per degree ([`flip_default_ppd`] is the tool's default).
///
/// Implemented from the FLIP paper (Andersson et al., "FLIP: A Difference Evaluator for
/// Alternating Images", HPG 2020): both images go to YCxCz and are filtered with the
/// achromatic, red-green and blue-yellow contrast sensitivity functions, clamped to the
/// linear RGB cube, compared in Hunt-adjusted L*a*b* with the HyAB distance raised to 0.7
/// and remapped so that 95 % of the range covers 40 % of the largest (green-blue)
/// distance; that colour error is raised to `1 - feature error`, where the feature error
/// is the largest difference in edge or point response of the normalised luminance,
/// `(diff / sqrt 2)^0.5`.
pub fn flip_map(
    reference: &[f32],
    test: &[f32],
    width: usize,
    height: usize,
    ppd: f64,
) -> Vec<f32> {
    assert_eq!(reference.len(), test.len(), "images of different sizes");
    assert_eq!(reference.len(), width * height * 3, "FLIP takes RGB images");
    let prepare = |img: &[f32]| -> [Vec<f64>; 3] {
        let mut planes = [
            Vec::with_capacity(width * height),
            Vec::with_capacity(width * height),
            Vec::with_capacity(width * height),
        ];
        for px in img.chunks(3) {
            let lin = [0, 1, 2].map(|c| srgb_to_linear(px[c].clamp(0.0, 1.0) as f64));
            let o = linear_to_ycxcz(lin);
            for c in 0..3 {
                planes[c].push(o[c]);
            }
        }
        planes
    };
    let (r, t) = (prepare(reference), prepare(test));
    // Colour pipeline: CSF-filtered, clamped, Hunt-adjusted L*a*b*.
    let colour = |p: &[Vec<f64>; 3]| -> Vec<[f64; 3]> {
        let f: Vec<Vec<f64>> = (0..3)
            .map(|c| csf_filter(&p[c], width, height, CSF[c], ppd))
            .collect();
        (0..width * height)
            .map(|i| {
                let rgb = ycxcz_to_linear([f[0][i], f[1][i], f[2][i]]).map(|v| v.clamp(0.0, 1.0));
                linear_to_hunt_lab(rgb)
            })
            .collect()
    };
    let (rl, tl) = (colour(&r), colour(&t));
    const QC: f64 = 0.7;
    const QF: f64 = 0.5;
    const PC: f64 = 0.4;
    const PT: f64 = 0.95;
    let cmax = hyab(
        linear_to_hunt_lab([0.0, 1.0, 0.0]),
        linear_to_hunt_lab([0.0, 0.0, 1.0]),
    )
    .powf(QC);
    let pccmax = PC * cmax;
    // Feature pipeline on the normalised luminance (Y + 16) / 116.
    let features = |p: &[Vec<f64>; 3]| -> [Vec<f64>; 2] {
        let y: Vec<f64> = p[0].iter().map(|v| (v + 16.0) / 116.0).collect();
        [false, true].map(|point| {
            let (d, g) = feature_taps(ppd, point);
            let fx = separable_filter(&y, width, height, &d, &g, Padding::Clamp);
            let fy = separable_filter(&y, width, height, &g, &d, Padding::Clamp);
            fx.iter().zip(&fy).map(|(a, b)| a.hypot(*b)).collect()
        })
    };
    let (rf, tf) = (features(&r), features(&t));
    (0..width * height)
        .map(|i| {
            let de = hyab(rl[i], tl[i]).powf(QC);
            let dc = if de < pccmax {
                PT / pccmax * de
            } else {
                PT + (de - pccmax) / (cmax - pccmax) * (1.0 - PT)
            };
            let edge = (rf[0][i] - tf[0][i]).abs();
            let point = (rf[1][i] - tf[1][i]).abs();
            let df = (edge.max(point) / std::f64::consts::SQRT_2).powf(QF);
            dc.powf(1.0 - df) as f32
        })
        .collect()
}

/// Mean LDR-FLIP error of `test` against `reference` ([`flip_map`] averaged; 0 for
/// identical images).
pub fn flip(reference: &[f32], test: &[f32], width: usize, height: usize, ppd: f64) -> f64 {
    let map = flip_map(reference, test, width, height, ppd);
    map.iter().map(|&v| v as f64).sum::<f64>() / map.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: usize = 48;
    const H: usize = 40;

    /// An `H x W x 3` image from an integer formula, as `tools/metrics_reference.py` builds it.
    fn image(f: impl Fn(usize, usize, usize) -> f32) -> Vec<f32> {
        let mut v = Vec::with_capacity(W * H * 3);
        for y in 0..H {
            for x in 0..W {
                for c in 0..3 {
                    v.push(f(x, y, c));
                }
            }
        }
        v
    }

    fn pattern() -> Vec<f32> {
        image(|x, y, c| ((x * 7 + y * 13 + c * 29) % 31) as f32 / 30.0)
    }

    /// The hand-made pairs of `tools/metrics_reference.py`.
    fn pairs() -> Vec<(&'static str, Vec<f32>, Vec<f32>)> {
        let checker = |shift: usize| {
            image(move |x, y, _| {
                if ((x + shift) / 4 + y / 4) % 2 == 1 {
                    0.8
                } else {
                    0.2
                }
            })
        };
        let gradient = image(|x, y, c| (x + 2 * y + c) as f32 / (W + 2 * H + 2) as f32);
        vec![
            (
                "pattern/offset",
                pattern(),
                pattern()
                    .iter()
                    .map(|v| (v + 0.1).clamp(0.0, 1.0))
                    .collect(),
            ),
            (
                "pattern/other",
                pattern(),
                image(|x, y, c| ((x * 3 + y * 5 + c * 11) % 17) as f32 / 16.0),
            ),
            ("checker/shifted", checker(0), checker(1)),
            (
                "gradient/inverse",
                gradient.clone(),
                gradient.iter().map(|v| 1.0 - v).collect(),
            ),
        ]
    }

    #[test]
    fn psnr_of_identical_images_is_infinite_and_written_as_null() {
        let a = pattern();
        assert_eq!(psnr(&a, &a, 1.0), f64::INFINITY);
        let s = error_stats(&a, &a, 3, 1.0);
        assert_eq!((s.max_abs, s.mean_abs, s.within), (0.0, 0.0, 1.0));
        let json = serde_json::to_value(s).unwrap();
        assert!(json["psnr"].is_null(), "{json}");
    }

    #[test]
    fn psnr_of_a_constant_offset_is_the_closed_form() {
        // Every sample off by d: MSE = d^2, PSNR = 20 log10(peak / d).
        let a = vec![0.25f32; 300];
        for (d, peak) in [(0.01f32, 1.0f64), (0.125, 1.0), (0.5, 4.0)] {
            let b: Vec<f32> = a.iter().map(|v| v + d).collect();
            let want = 20.0 * (peak / d as f64).log10();
            let got = psnr(&a, &b, peak);
            // The offset is added in f32: (0.25 + d) - 0.25 differs from d by at most an
            // ulp of 0.25 + d (3e-8), a relative error below 3e-6 in d; 1e-4 dB covers it.
            assert!((got - want).abs() < 1e-4, "d {d}: {got} vs {want}");
            let s = error_stats(&a, &b, 3, peak);
            assert!((s.psnr - want).abs() < 1e-4);
            assert!((s.max_abs - d as f64).abs() < 1e-7 && (s.mean_abs - d as f64).abs() < 1e-7);
        }
    }

    #[test]
    fn within_counts_pixels_whose_every_channel_is_within_one_8bit_step() {
        let a = vec![0.5f32; 12];
        let mut b = a.clone();
        b[0] += 1.0 / 255.0; // pixel 0: one step, still within
        b[4] += 2.0 / 255.0; // pixel 1: two steps off in green
        let s = error_stats(&a, &b, 3, 1.0);
        assert_eq!(s.within, 0.75);
        // Relative to a peak of 2, two 1/255 steps are one 8-bit step.
        assert_eq!(error_stats(&a, &b, 3, 2.0).within, 1.0);
    }

    #[test]
    fn ssim_of_identical_images_is_one() {
        for (_, a, _) in pairs() {
            assert!((ssim(&a, &a, W, H, 3) - 1.0).abs() < 1e-12);
        }
    }

    /// Pinned against `tools/metrics_reference.py` (SciPy, float64, the original 3DGS
    /// formula). Both sides compute in f64 from the same f32 inputs, so they agree to
    /// rounding; 1e-7 leaves room for summation order and the printed 9 decimals.
    #[test]
    fn ssim_matches_the_independent_implementation() {
        let want = [0.981662038, 0.088888152, 0.531962298, 0.036358582];
        for ((name, a, b), want) in pairs().into_iter().zip(want) {
            let got = ssim(&a, &b, W, H, 3);
            assert!((got - want).abs() < 1e-7, "{name}: {got:.9} vs {want:.9}");
        }
    }

    #[test]
    fn ssim_is_the_mean_over_channels() {
        let (_, a, b) = pairs().remove(1);
        let plane =
            |img: &[f32], c: usize| img.iter().skip(c).step_by(3).copied().collect::<Vec<_>>();
        let per_channel: f64 = (0..3)
            .map(|c| ssim(&plane(&a, c), &plane(&b, c), W, H, 1))
            .sum::<f64>()
            / 3.0;
        assert!((ssim(&a, &b, W, H, 3) - per_channel).abs() < 1e-12);
    }

    #[test]
    fn flip_of_identical_images_is_zero() {
        for (_, a, _) in pairs() {
            assert_eq!(flip(&a, &a, W, H, flip_default_ppd()), 0.0);
        }
    }

    /// Pinned against NVIDIA's own implementation (`flip-evaluator` 1.7, LDR, via
    /// `tools/metrics_reference.py`), at its default 67.02 pixels per degree and at 67.0.
    /// It computes in f32: where the two images' edge or point responses are equal, the
    /// f32 rounding of the responses (about 1e-7) goes through FLIP's square root of the
    /// feature difference and moves such a pixel's error by up to 1.2e-4 (checked against
    /// the same formulas written in NumPy float64, which agree with this code). The
    /// checker pair, mostly flat, differs by 1.1e-5 on the mean for that reason, the
    /// others by under 7e-7; 2e-5 bounds it.
    #[test]
    fn flip_matches_nvidia_flip() {
        assert!((flip_default_ppd() - 67.020645).abs() < 1e-5);
        let want = [
            (0.2565855, 0.2565967),
            (0.2255847, 0.2256899),
            (0.2467878, 0.2468783),
            (0.6803591, 0.6803529),
        ];
        for ((name, a, b), (at_default, at_67)) in pairs().into_iter().zip(want) {
            let got = flip(&a, &b, W, H, flip_default_ppd());
            assert!(
                (got - at_default).abs() < 2e-5,
                "{name}: {got:.7} vs {at_default:.7}"
            );
            let got = flip(&a, &b, W, H, 67.0);
            assert!(
                (got - at_67).abs() < 2e-5,
                "{name} at 67 ppd: {got:.7} vs {at_67:.7}"
            );
        }
    }

    #[test]
    fn equal_infinite_samples_count_as_equal() {
        // EXR depth is +inf where nothing was hit: identical planes compare as identical.
        let z = [1.0, f32::INFINITY, 2.5, f32::INFINITY];
        let same = error_stats(&z, &z, 1, 2.5);
        assert_eq!(same.psnr, f64::INFINITY);
        assert_eq!((same.max_abs, same.within), (0.0, 1.0));
        let mut hit = z;
        hit[1] = 2.0; // a surface where the reference has none
        let differs = error_stats(&z, &hit, 1, 2.5);
        assert!(differs.max_abs.is_infinite() && differs.within < 1.0);
    }

    #[test]
    fn frame_comparison_masks_depth_where_the_reference_is_faint() {
        let mut reference = Frame::background(4, 1, [0.2; 3]);
        reference.alpha = vec![1.0, 1.0, 0.01, 0.0];
        reference.depth = vec![2.0, 4.0, 3.0, 0.0];
        let mut test = reference.clone();
        test.depth[2] = 1.0; // faint pixel: ignored
        test.depth[3] = 5.0; // empty pixel: ignored
        let c = compare_frames(&reference, &test);
        assert_eq!(c.depth.psnr, f64::INFINITY);
        test.depth[1] = 3.0;
        let c = compare_frames(&reference, &test);
        // Peak 4, one of 4 pixels off by 1: MSE 1/4.
        assert!((c.depth.psnr - 10.0 * (16.0f64 / 0.25).log10()).abs() < 1e-9);
        assert_eq!(c.depth.max_abs, 1.0);
        assert_eq!(c.color.psnr, f64::INFINITY);
        assert!((c.ssim - 1.0).abs() < 1e-12);
    }
}
