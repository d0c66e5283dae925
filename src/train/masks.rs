//! Masks: which pixels of a photo training counts (and `eval` scores). A mask is an image
//! beside the photos, `masks/` next to `images/` holding one file per photo with the
//! photo's stem (any extension; COLMAP's `NAME.jpg.png` too), or the `mask_path` of a
//! transforms frame (nerfstudio's key, relative to the transforms file's folder): white
//! keeps a pixel, black ignores it (grey, or the mean of R, G and B, times the alpha
//! when there is one, thresholded at 0.5). With `--alpha-mode mask` a photo's own alpha
//! below 0.5 masks too, and a fisheye camera's pixels outside its image circle are always
//! masked. A mask goes through what its photo does (undistorted, then scaled to `-r` by
//! the same area average) and is thresholded at 0.5 again at the training resolution.

use crate::core::camera::{Camera, Lens};
use std::path::{Path, PathBuf};

/// A mask's error, naming the file (the data set's loader gives it as its own).
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct MaskError {
    /// The mask, or the photo without one.
    pub path: PathBuf,
    /// What is wrong, one sentence.
    pub message: String,
}

fn data_error(path: &Path, message: impl Into<String>) -> MaskError {
    MaskError {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// What the trainer does with a photo's alpha channel (`verisplat train --alpha-mode`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AlphaMode {
    /// Dropped: the colour as stored (COLMAP data sets' default).
    Ignore,
    /// Alpha below 0.5 masks the pixel; the colour as stored elsewhere.
    Mask,
    /// The colour composited onto the training background (transforms data sets'
    /// default, as NeRF-synthetic's RGBA photos are trained).
    Background,
}

impl AlphaMode {
    /// `ignore`, `mask` or `background`.
    pub fn parse(s: &str) -> Result<AlphaMode, String> {
        match s {
            "ignore" => Ok(AlphaMode::Ignore),
            "mask" => Ok(AlphaMode::Mask),
            "background" => Ok(AlphaMode::Background),
            other => Err(format!("'{other}' is not one of ignore, mask, background")),
        }
    }

    /// The photo's colour at each pixel and, with [`AlphaMode::Mask`], which pixels its
    /// alpha keeps (1) or masks (0).
    pub(super) fn apply(
        self,
        [r, g, b, a]: &[Vec<f32>; 4],
        background: [f32; 3],
    ) -> (Vec<[f32; 3]>, Option<Vec<f32>>) {
        let colour: Vec<[f32; 3]> = match self {
            AlphaMode::Background => (0..r.len())
                .map(|p| {
                    let t = 1.0 - a[p];
                    [
                        r[p] * a[p] + background[0] * t,
                        g[p] * a[p] + background[1] * t,
                        b[p] * a[p] + background[2] * t,
                    ]
                })
                .collect(),
            _ => (0..r.len()).map(|i| [r[i], g[i], b[i]]).collect(),
        };
        let keep = (self == AlphaMode::Mask).then(|| a.iter().map(|&v| threshold(v)).collect());
        (colour, keep)
    }
}

/// 1 where `v >= 0.5` (kept), else 0.
fn threshold(v: f32) -> f32 {
    if v >= 0.5 {
        1.0
    } else {
        0.0
    }
}

/// The masks folder of the photos in `images`: `images/../masks`, when it is one.
pub fn masks_dir(images: &Path) -> Option<PathBuf> {
    let dir = images.parent()?.join("masks");
    dir.is_dir().then_some(dir)
}

/// The mask of the photo `name` (relative to its images folder) in `masks`: the file with
/// the photo's stem and any extension, or the photo's whole name plus an extension (the
/// first in name order when several match).
pub fn find_mask(masks: &Path, name: &str) -> Option<PathBuf> {
    let rel = Path::new(name);
    let folder = masks.join(rel.parent().unwrap_or(Path::new("")));
    let stem = rel.file_stem()?.to_os_string();
    let whole = rel.file_name()?.to_os_string();
    let mut found: Vec<PathBuf> = std::fs::read_dir(&folder)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .filter(|p| p.file_stem().is_some_and(|s| s == stem || s == whole))
        .collect();
    found.sort();
    found.into_iter().next()
}

/// The keep plane (1 keep, 0 masked) of the mask file `path` for a `size` photo: the
/// photo's size, or already `training` (the size `-r` scales the photo to, when given).
pub fn read_mask(
    path: &Path,
    photo: &Path,
    size: (u32, u32),
    training: Option<(u32, u32)>,
) -> Result<Vec<f32>, MaskError> {
    let planes = crate::io::image_file::read_image(path)
        .map_err(|e| data_error(path, format!("cannot be read as a mask: {e}")))?;
    let got = (planes.width, planes.height);
    if got != size && Some(got) != training {
        let scaled = match training {
            Some((w, h)) if (w, h) != size => format!(" (or {w}x{h}, its size at -r)"),
            _ => String::new(),
        };
        return Err(data_error(
            path,
            format!(
                "is a {}x{} mask, but its photo {} is {}x{}{scaled}",
                got.0,
                got.1,
                photo.display(),
                size.0,
                size.1
            ),
        ));
    }
    let channel = |n: &str| planes.channel(n).map(|c| &c.values);
    let grey: Vec<f32> = match (channel("Y"), channel("R"), channel("G"), channel("B")) {
        (Some(y), ..) => y.clone(),
        (None, Some(r), Some(g), Some(b)) => {
            (0..r.len()).map(|i| (r[i] + g[i] + b[i]) / 3.0).collect()
        }
        _ => {
            return Err(data_error(
                path,
                "cannot be read as a mask: it has no grey or colour channels",
            ))
        }
    };
    let alpha = channel("A");
    let keep: Vec<f32> = (0..grey.len())
        .map(|i| threshold(grey[i] * alpha.map_or(1.0, |a| a[i])))
        .collect();
    if got == size {
        return Ok(keep);
    }
    // A mask at the training size: to the photo's, each pixel the one it falls in, so
    // that scaling it with the photo gives it back.
    let (w, h) = (size.0 as u64, size.1 as u64);
    let (tw, th) = (got.0 as u64, got.1 as u64);
    Ok((0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) * tw / w, (i / w) * th / h);
            keep[(y.min(th - 1) * tw + x.min(tw - 1)) as usize]
        })
        .collect())
}

/// Both keep planes combined (a pixel is kept where both keep it).
pub(super) fn both(a: Option<Vec<f32>>, b: Option<Vec<f32>>) -> Option<Vec<f32>> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.iter().zip(&b).map(|(x, y)| x.min(*y)).collect()),
        (a, b) => a.or(b),
    }
}

/// Thresholds a keep plane at the training resolution.
pub(super) fn to_flags(plane: &[[f32; 3]]) -> Vec<bool> {
    plane.iter().map(|v| v[0] >= 0.5).collect()
}

/// The pixels of a fisheye `camera` inside its image circle (where a ray lands: within
/// the lens's field of view); `None` for other lenses, and when every pixel is inside.
pub fn image_circle(camera: &Camera) -> Option<Vec<bool>> {
    if !matches!(camera.lens, Lens::Fisheye { .. }) {
        return None;
    }
    let k = camera.intrinsics();
    let (w, h) = (camera.width as usize, camera.height as usize);
    let inside: Vec<bool> = (0..w * h)
        .map(|i| {
            let px = glam::DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            camera.lens.unproject(&k, px).is_some()
        })
        .collect();
    inside.iter().any(|&b| !b).then_some(inside)
}

/// The error of a photo without its mask when others have one.
pub(super) fn missing(photo: &Path, masks: &str, others: usize) -> MaskError {
    data_error(
        photo,
        format!(
            "has no mask in {masks}, but {others} other photo(s) have one; give every photo a mask, or none"
        ),
    )
}

/// PSNR (peak 1) of RGB-interleaved `test` against `reference` over the pixels `keep` keeps
/// (every pixel when `None`).
pub fn masked_psnr(reference: &[f32], test: &[f32], keep: Option<&[bool]>) -> f64 {
    let Some(keep) = keep else {
        return crate::io::metrics::psnr(reference, test, 1.0);
    };
    let kept = keep.iter().filter(|&&k| k).count().max(1);
    let squared: f64 = (0..test.len())
        .filter(|i| keep[i / 3])
        .map(|i| ((test[i] - reference[i]) as f64).powi(2))
        .sum();
    crate::io::metrics::psnr_from_mse(squared / (3 * kept) as f64, 1.0)
}

/// PSNR, SSIM and FLIP of `test` against `reference` (`H x W x 3`, `width x height`) over
/// the pixels `keep` keeps: the test image's masked pixels are the reference's (so no
/// window reaches a difference there), PSNR is of the mean squared error over the kept
/// pixels, SSIM and FLIP the means of their maps over them.
pub fn masked_metrics(
    reference: &[f32],
    test: &[f32],
    (width, height): (usize, usize),
    keep: &[bool],
    ppd: f64,
) -> (f64, f64, f64) {
    use crate::io::metrics;
    let test: Vec<f32> = (0..test.len())
        .map(|i| if keep[i / 3] { test[i] } else { reference[i] })
        .collect();
    let psnr = masked_psnr(reference, &test, Some(keep));
    let kept = keep.iter().filter(|&&k| k).count().max(1);
    let wide = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
    let weights: Vec<f64> = keep.iter().map(|&k| if k { 1.0 } else { 0.0 }).collect();
    let (ssim, _) = metrics::ssim_with_gradient_weighted(
        &wide(&test),
        &wide(reference),
        width,
        height,
        3,
        Some(&weights),
    );
    let map = metrics::flip_map(reference, &test, width, height, ppd);
    let flip = (0..map.len())
        .filter(|&i| keep[i])
        .map(|i| map[i] as f64)
        .sum::<f64>()
        / kept as f64;
    (psnr, ssim, flip)
}
