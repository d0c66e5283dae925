//! The masks of `verisplat eval`: a `masks/` folder beside the photos' folder (the layout
//! `verisplat train` reads, [`verisplat::train::masks`]) holds a mask per photo, prepared
//! as its photo is (undistorted, scaled to `-r`; a mask larger than an already
//! downscaled photo by one factor is first area-averaged to it) and thresholded at 0.5;
//! only the kept pixels are scored. Without a masks folder, a transforms file of the data
//! set (the photos' folder's parent) may name the photo's mask in its frame's
//! `mask_path`, as `verisplat train` reads it.

use super::eval_photo::{render_size, PhotoPrep};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use verisplat::core::camera::Camera;
use verisplat::io::camera::transforms::frame_photo;
use verisplat::train::data::resize;
use verisplat::train::masks;

/// The mask of the photo at `photo_path` (`size`, seen by `cam`) at the size the photo is
/// prepared to, one flag per pixel (true: scored): from the masks folder beside the
/// photo's, else from `frame_masks`; `None` without either.
pub(crate) fn photo_mask(
    prep: &PhotoPrep,
    frame_masks: Option<&FrameMasks>,
    cam: &Camera,
    photo_path: &Path,
    size: (u32, u32),
) -> Result<Option<Vec<bool>>> {
    let (Some(folder), Some(name)) = (photo_path.parent(), photo_path.file_name()) else {
        return Ok(None);
    };
    let path = match masks::masks_dir(folder) {
        Some(dir) => match masks::find_mask(&dir, &name.to_string_lossy()) {
            Some(path) => path,
            None => bail!(
                "{}: has no mask in {}; with a masks folder every photo needs its mask",
                photo_path.display(),
                dir.display()
            ),
        },
        None => match frame_masks {
            Some(m) => m.mask_of(photo_path)?,
            None => return Ok(None),
        },
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

/// The transforms files whose frames may give a photo's `mask_path`.
const TRANSFORMS_FILES: [&str; 3] = [
    "transforms.json",
    "transforms_train.json",
    "transforms_test.json",
];

/// The masks a data set's transforms files name in their frames' `mask_path` (relative to
/// the data set's folder), by the photo at each frame's `file_path`; read once per run.
pub(crate) struct FrameMasks {
    /// The file whose frames hold the masks, for the error of a photo without one.
    file: PathBuf,
    /// (the photo, canonical; its mask).
    by_photo: Vec<(PathBuf, PathBuf)>,
}

impl FrameMasks {
    /// The frame masks of the data set in `dir` (the parent of the photos' folder); `None`
    /// when no frame of its transforms files has a `mask_path`.
    pub(crate) fn read(dir: &Path) -> Result<Option<FrameMasks>> {
        let mut found: Option<FrameMasks> = None;
        for file in TRANSFORMS_FILES.map(|f| dir.join(f)) {
            if !file.is_file() {
                continue;
            }
            let text = std::fs::read_to_string(&file)
                .with_context(|| format!("{}: cannot be read", file.display()))?;
            let doc: serde_json::Value = serde_json::from_str(&text)
                .with_context(|| format!("{}: is not a JSON transforms file", file.display()))?;
            for frame in doc["frames"].as_array().into_iter().flatten() {
                let Some(mask) = frame.get("mask_path") else {
                    continue;
                };
                let Some(mask) = mask.as_str() else {
                    bail!("{}: a frame's mask_path is not a string", file.display());
                };
                let rel = frame["file_path"].as_str().unwrap_or_default();
                let found = found.get_or_insert_with(|| FrameMasks {
                    file: file.clone(),
                    by_photo: Vec::new(),
                });
                // A frame whose photo is not there names no photo eval can score.
                if let Ok(photo) = std::fs::canonicalize(frame_photo(dir, rel)) {
                    found.by_photo.push((photo, dir.join(mask)));
                }
            }
        }
        Ok(found)
    }

    /// The mask of the photo at `photo_path`: an error naming the photo when its frame has
    /// none while others have one.
    fn mask_of(&self, photo_path: &Path) -> Result<PathBuf> {
        let photo = std::fs::canonicalize(photo_path)
            .with_context(|| format!("{}: cannot be read", photo_path.display()))?;
        match self.by_photo.iter().find(|(p, _)| *p == photo) {
            Some((_, mask)) => Ok(mask.clone()),
            None => bail!(
                "{}: has no mask_path in {}, whose other frames have one; give every photo a mask, or none",
                photo_path.display(),
                self.file.display()
            ),
        }
    }
}
