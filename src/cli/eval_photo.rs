//! The ground-truth photos of `verisplat eval`, prepared as `verisplat train` prepared them:
//! undistorted to the pinhole cameras the model's `undistortion.json` records, then
//! area-averaged down to the training resolution (`-r`, or the model's `cfg_args`), so
//! that eval compares with the photos the model was trained and tested on.

use anyhow::Result;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use verisplat::core::camera::Camera;
use verisplat::core::console::note;
use verisplat::train::data::{resize, Resolution};
use verisplat::train::undistort::{self, Undistortion};

/// How each photo is prepared before it is compared.
pub(crate) struct PhotoPrep {
    /// The `-r` of the photos (given, or the model's `cfg_args`), if any.
    resolution: Option<u32>,
    /// Whether `resolution` was given (`-r`), not read from `cfg_args`.
    given: bool,
    /// The undistortion of each distorted camera, by image name without extension.
    undistortions: HashMap<String, Undistortion>,
}

/// The model directory of a scene argument: the directory itself, or the one holding
/// `point_cloud/iteration_N/point_cloud.ply`.
fn model_dir(scene: Option<&Path>) -> Option<PathBuf> {
    let scene = scene?;
    if scene.join("point_cloud").is_dir() {
        return Some(scene.to_path_buf());
    }
    let dir = scene.ancestors().nth(3)?;
    (scene.is_file() && dir.join("point_cloud").is_dir() && dir.join("cfg_args").is_file())
        .then(|| dir.to_path_buf())
}

/// The `resolution=N` of a `cfg_args` (`None`: absent, or the original's -1, "not given").
fn cfg_resolution(text: &str) -> Option<u32> {
    let rest = text.split("resolution=").nth(1)?;
    let value: String = rest
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '-')
        .collect();
    value
        .parse::<i64>()
        .ok()
        .filter(|&r| r > 0)
        .map(|r| r as u32)
}

/// A name without its photo extension (`0001.jpg` and `0001` are one image).
fn stem(name: &str) -> &str {
    match name.rsplit_once('.') {
        Some((s, e))
            if verisplat::io::image_file::EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()) =>
        {
            s
        }
        _ => name,
    }
}

impl PhotoPrep {
    /// What `eval` of `scene` does to the photos: `-r` (`resolution`) or the model
    /// directory's `cfg_args` resolution, and its `undistortion.json`.
    pub(crate) fn new(resolution: Option<u32>, scene: Option<&Path>) -> Result<PhotoPrep> {
        let dir = model_dir(scene);
        let mut prep = PhotoPrep {
            resolution,
            given: resolution.is_some(),
            undistortions: HashMap::new(),
        };
        let Some(dir) = dir else {
            return Ok(prep);
        };
        let cfg = dir.join("cfg_args");
        if prep.resolution.is_none() {
            if let Ok(text) = std::fs::read_to_string(&cfg) {
                prep.resolution = cfg_resolution(&text);
                if let Some(r) = prep.resolution {
                    note!(
                        "note: photos are scaled as the model was trained (-r {r}, from {}; -r overrides)",
                        cfg.display()
                    );
                }
            }
        }
        let file = dir.join(undistort::UNDISTORTION_FILE);
        if file.is_file() {
            let list =
                undistort::read(&file).map_err(|m| anyhow::anyhow!("{}: {m}", file.display()))?;
            note!(
                "note: photos of {} distorted camera(s) are undistorted as {} records",
                list.len(),
                file.display()
            );
            prep.undistortions = list
                .into_iter()
                .map(|u| (stem(&u.name).to_string(), u))
                .collect();
        }
        Ok(prep)
    }

    /// Photo `rgb` (`w x h`, interleaved RGB) of camera `cam`, prepared:
    /// undistorted when the model records the camera's lens, the camera is a pinhole and
    /// the photo has the size it was taken at; then scaled with the trainer's area average
    /// to the given `-r`, or,
    /// unless it already has the camera's size (photos scaled beforehand, `images_4/`),
    /// to the model's `-r` or, without one, down to the camera's size when that is
    /// smaller by one factor on both sides. Returns the image and its size.
    pub(crate) fn prepare(
        &self,
        cam: &Camera,
        rgb: Vec<f32>,
        (w, h): (u32, u32),
    ) -> (Vec<f32>, u32, u32) {
        let mut px: Vec<[f32; 3]> = rgb.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let (mut w, mut h) = (w, h);
        // A camera that carries its lens (a distorted COLMAP model) is rendered through
        // it, so its photo stays as taken.
        let undistortion = Some(cam)
            .filter(|c| c.lens.is_pinhole())
            .and_then(|c| self.undistortions.get(stem(&c.name)));
        if let Some(u) = undistortion {
            if (w, h) == (u.photo.width, u.photo.height) {
                px = u.apply(&px);
                (w, h) = (u.pinhole.width, u.pinhole.height);
            }
        }
        let (tw, th) = match self.resolution {
            _ if (w, h) == (cam.width, cam.height) && !self.given => (w, h),
            Some(r) => Resolution(r).size(w, h),
            None => render_size(w, h, cam.width, cam.height).unwrap_or((w, h)),
        };
        if (tw, th) != (w, h) {
            px = resize(&px, w, h, tw, th);
            (w, h) = (tw, th);
        }
        (px.into_iter().flatten().collect(), w, h)
    }
}

/// The resolution to render a camera at for a photo of `(pw, ph)`: the camera's own, or
/// the photo's when it is smaller by one factor on both sides, up to the rounding of each
/// side to whole pixels (`|pw * ch - ph * cw| <= (cw + ch) / 2`).
pub(crate) fn render_size(cw: u32, ch: u32, pw: u32, ph: u32) -> Option<(u32, u32)> {
    if (pw, ph) == (cw, ch) {
        return Some((cw, ch));
    }
    let (cw64, ch64, pw64, ph64) = (cw as u64, ch as u64, pw as u64, ph as u64);
    let uniform = 2 * (pw64 * ch64).abs_diff(ph64 * cw64) <= cw64 + ch64;
    (pw <= cw && ph <= ch && pw > 0 && ph > 0 && uniform).then_some((pw, ph))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cfg_args_resolution_is_read_and_minus_one_is_none() {
        let cfg = "Namespace(sh_degree=3, source_path='d', model_path='m', images='images', resolution=8, white_background=False)";
        assert_eq!(cfg_resolution(cfg), Some(8));
        assert_eq!(cfg_resolution("Namespace(resolution=-1, eval=True)"), None);
        assert_eq!(cfg_resolution("Namespace(resolution=1600)"), Some(1600));
        assert_eq!(cfg_resolution("Namespace(eval=True)"), None);
    }

    #[test]
    fn photos_are_scaled_as_trained_unless_already_at_the_cameras_size() {
        let mut cam = verisplat::core::camera::default_camera(&[[0.0; 3]], 10, 8);
        cam.name = "a".into();
        let prep = |r: Option<u32>, given: bool| PhotoPrep {
            resolution: r,
            given,
            undistortions: HashMap::new(),
        };
        let size = |p: &PhotoPrep, w: u32, h: u32| {
            let (img, w, h) = p.prepare(&cam, vec![0.5; (w * h * 3) as usize], (w, h));
            assert_eq!(img.len(), (w * h * 3) as usize);
            (w, h)
        };
        // The model's -r 4: full photos are scaled, photos of the camera's size kept.
        assert_eq!(size(&prep(Some(4), false), 40, 32), (10, 8));
        assert_eq!(size(&prep(Some(4), false), 10, 8), (10, 8));
        // A given -r applies as given; without any, down to the camera's size.
        assert_eq!(size(&prep(Some(2), true), 40, 32), (20, 16));
        assert_eq!(size(&prep(None, false), 40, 32), (10, 8));
        assert_eq!(size(&prep(None, false), 40, 20), (40, 20));
    }
}
