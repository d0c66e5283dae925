//! The masks of `verisplat eval`: a `masks/` folder beside the photos' folder (the layout
//! `verisplat train` reads, [`verisplat::train::masks`]) holds a mask per photo, prepared
//! as its photo is (undistorted, scaled to `-r`; a mask larger than an already
//! downscaled photo by one factor is first area-averaged to it) and thresholded at 0.5;
//! only the kept pixels are scored.

use super::eval_photo::{render_size, PhotoPrep};
use anyhow::{bail, Result};
use std::path::Path;
use verisplat::core::camera::Camera;
use verisplat::train::data::resize;
use verisplat::train::masks;

/// The mask of the photo at `photo_path` (`size`, seen by `cam`) at the size the photo is
/// prepared to, one flag per pixel (true: scored); `None` without a masks folder.
pub(crate) fn photo_mask(
    prep: &PhotoPrep,
    cam: &Camera,
    photo_path: &Path,
    size: (u32, u32),
) -> Result<Option<Vec<bool>>> {
    let (Some(folder), Some(name)) = (photo_path.parent(), photo_path.file_name()) else {
        return Ok(None);
    };
    let Some(dir) = masks::masks_dir(folder) else {
        return Ok(None);
    };
    let Some(path) = masks::find_mask(&dir, &name.to_string_lossy()) else {
        bail!(
            "{}: has no mask in {}; with a masks folder every photo needs its mask",
            photo_path.display(),
            dir.display()
        );
    };
    // A mask may be larger than a photo downscaled for training (data/images_4 beside
    // data/masks): area-averaged down to the photo first.
    let mask_size = verisplat::io::image_file::read_image(&path)
        .map(|p| (p.width, p.height))
        .unwrap_or(size);
    let larger =
        mask_size != size && render_size(mask_size.0, mask_size.1, size.0, size.1).is_some();
    let plane = masks::read_mask(
        &path,
        photo_path,
        if larger { mask_size } else { size },
        None,
    )?;
    let mut rgb: Vec<[f32; 3]> = plane.iter().map(|&v| [v; 3]).collect();
    if larger {
        rgb = resize(&rgb, mask_size.0, mask_size.1, size.0, size.1);
    }
    let rgb: Vec<f32> = rgb.into_iter().flatten().collect();
    let (prepared, _, _) = prep.prepare(cam, rgb, size);
    let keep: Vec<bool> = prepared.chunks_exact(3).map(|c| c[0] >= 0.5).collect();
    if !keep.contains(&true) {
        bail!(
            "{}: masks every pixel of its photo (as prepared); nothing is left to score",
            path.display()
        );
    }
    Ok(Some(keep))
}
