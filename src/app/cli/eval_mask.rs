//! The masks of `verisplat eval`: a `masks/` folder beside the photos' folder (the layout
//! `verisplat train` reads, [`verisplat::train::masks`]) holds a mask per photo, prepared
//! as its photo is (undistorted, scaled to `-r`) and thresholded at 0.5; only the kept
//! pixels are scored.

use super::eval_photo::PhotoPrep;
use anyhow::{bail, Result};
use std::path::Path;
use verisplat::core::camera::Camera;
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
    let plane = masks::read_mask(&path, photo_path, size, None)?;
    let rgb: Vec<f32> = plane.iter().flat_map(|&v| [v; 3]).collect();
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
