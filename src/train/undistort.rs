//! Undistorting photos to pinhole cameras at load time (`verisplat train`, and `verisplat eval`
//! on the photos of a model trained from them): each pixel of the pinhole image is a ray
//! whose distorted position in the photo ([`Distortion::distort`]) is sampled
//! bilinearly. The pinhole camera keeps the photo's focal lengths (so the centre keeps its
//! sharpness) and is cropped to the largest axis-aligned rectangle whose every pixel
//! lies inside the photo (as OpenCV's `getOptimalNewCameraMatrix` with `alpha = 0`, then
//! its valid region). The trainer records each [`Undistortion`] in the model directory's
//! `undistortion.json` ([`UNDISTORTION_FILE`]), which `eval` applies to the same photos.

use crate::core::camera::distortion::Distortion;
use crate::core::camera::{Camera, MAX_IMAGE_SIDE};
use serde::{Deserialize, Serialize};

/// The file of a model directory recording how its photos were undistorted.
pub const UNDISTORTION_FILE: &str = "undistortion.json";

/// A pinhole camera's size and intrinsics (pixel centres at `+0.5`, as [`Camera`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

impl Intrinsics {
    /// The intrinsics of `cam`.
    pub fn of(cam: &Camera) -> Intrinsics {
        Intrinsics {
            width: cam.width,
            height: cam.height,
            fx: f64::from(cam.fx),
            fy: f64::from(cam.fy),
            cx: f64::from(cam.cx),
            cy: f64::from(cam.cy),
        }
    }
}

/// How one photo is undistorted: the photo's camera and lens, and the pinhole camera it
/// becomes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Undistortion {
    /// The image's name (as the model's `cameras.json` names it: without extension).
    pub name: String,
    /// The photo's size and intrinsics, as the data set gives them.
    pub photo: Intrinsics,
    /// Its lens.
    pub distortion: Distortion,
    /// The undistorted pinhole camera (at the photo's scale, before `-r`).
    pub pinhole: Intrinsics,
}

/// The contents of `undistortion.json`.
#[derive(Serialize, Deserialize)]
struct Record {
    about: String,
    images: Vec<Undistortion>,
}

/// The largest rectangle of pinhole coordinates inside the photo: the pinhole
/// coordinates of its border (the outermost pixel centres) give the inner bounds on each
/// side. `None` where a side has no usable border point.
fn inner_rectangle(photo: &Intrinsics, d: &Distortion) -> Option<[f64; 4]> {
    let (w, h) = (f64::from(photo.width), f64::from(photo.height));
    let norm = |u: f64, v: f64| d.undistort((u - photo.cx) / photo.fx, (v - photo.cy) / photo.fy);
    let (lo_u, hi_u, lo_v, hi_v) = (0.5, w - 0.5, 0.5, h - 0.5);
    let steps = |n: u32| (0..=n.max(2)).map(move |i| i as f64 / n.max(2) as f64);
    let along_v =
        |u: f64| steps(photo.height).filter_map(move |t| norm(u, lo_v + t * (hi_v - lo_v)));
    let along_u =
        |v: f64| steps(photo.width).filter_map(move |t| norm(lo_u + t * (hi_u - lo_u), v));
    let max = |it: &mut dyn Iterator<Item = f64>| it.fold(f64::NEG_INFINITY, f64::max);
    let min = |it: &mut dyn Iterator<Item = f64>| it.fold(f64::INFINITY, f64::min);
    let x0 = max(&mut along_v(lo_u).map(|p| p.0));
    let x1 = min(&mut along_v(hi_u).map(|p| p.0));
    let y0 = max(&mut along_u(lo_v).map(|p| p.1));
    let y1 = min(&mut along_u(hi_v).map(|p| p.1));
    let r = [x0, x1, y0, y1];
    (r.iter().all(|v| v.is_finite()) && x1 > x0 && y1 > y0).then_some(r)
}

impl Undistortion {
    /// Plans the undistortion of the photo of `cam` (its size and intrinsics) through
    /// `distortion`: the pinhole camera with the photo's focal lengths, cropped to the
    /// inner rectangle and shrunk a pixel at a time until every border pixel's ray lands
    /// inside the photo. `Err` says why no pinhole image fits.
    pub fn plan(cam: &Camera, distortion: &Distortion) -> Result<Undistortion, String> {
        let photo = Intrinsics::of(cam);
        let fail = || {
            format!(
                "its {distortion} lens distortion leaves no pinhole image inside the {}x{} photo",
                photo.width, photo.height
            )
        };
        let [x0, x1, y0, y1] = inner_rectangle(&photo, distortion).ok_or_else(fail)?;
        let (wf, hf) = ((x1 - x0) * photo.fx, (y1 - y0) * photo.fy);
        if !(wf >= 1.0 && hf >= 1.0) {
            return Err(fail());
        }
        let (mut w, mut h) = (wf.floor() as u32, hf.floor() as u32);
        // The floor's leftover split evenly on both sides.
        let mut cx = -x0 * photo.fx - (wf - f64::from(w)) / 2.0;
        let mut cy = -y0 * photo.fy - (hf - f64::from(h)) / 2.0;
        loop {
            let pinhole = Intrinsics {
                width: w,
                height: h,
                fx: photo.fx,
                fy: photo.fy,
                cx,
                cy,
            };
            let u = Undistortion {
                name: cam.name.clone(),
                photo,
                distortion: distortion.clone(),
                pinhole,
            };
            if u.border_inside() {
                if w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE {
                    return Err(format!(
                        "its undistorted pinhole image would be {w}x{h}, larger than {MAX_IMAGE_SIDE} pixels a side"
                    ));
                }
                return Ok(u);
            }
            if w <= 2 || h <= 2 {
                return Err(fail());
            }
            (w, h, cx, cy) = (w - 2, h - 2, cx - 1.0, cy - 1.0);
        }
    }

    /// The photo position (pixel-index coordinates: pixel `i` at `i`) of pinhole pixel
    /// `(i, j)`'s ray.
    fn source(&self, i: u32, j: u32) -> (f64, f64) {
        let (p, q) = (&self.pinhole, &self.photo);
        let x = (f64::from(i) + 0.5 - p.cx) / p.fx;
        let y = (f64::from(j) + 0.5 - p.cy) / p.fy;
        let (xd, yd) = self.distortion.distort(x, y);
        (q.fx * xd + q.cx - 0.5, q.fy * yd + q.cy - 0.5)
    }

    /// Whether every border pixel of the pinhole image samples inside the photo (within
    /// half a pixel of its outermost pixel centres, where bilinear sampling clamps).
    fn border_inside(&self) -> bool {
        let (w, h) = (self.pinhole.width, self.pinhole.height);
        let inside = |(u, v): (f64, f64)| {
            u >= -0.5
                && v >= -0.5
                && u <= f64::from(self.photo.width) - 0.5
                && v <= f64::from(self.photo.height) - 0.5
        };
        (0..w).all(|i| inside(self.source(i, 0)) && inside(self.source(i, h - 1)))
            && (0..h).all(|j| inside(self.source(0, j)) && inside(self.source(w - 1, j)))
    }

    /// `cam` as the pinhole camera of this undistortion (same pose and name).
    pub fn camera(&self, cam: &Camera) -> Camera {
        let p = &self.pinhole;
        Camera {
            width: p.width,
            height: p.height,
            fx: p.fx as f32,
            fy: p.fy as f32,
            cx: p.cx as f32,
            cy: p.cy as f32,
            ..cam.clone()
        }
    }

    /// The undistorted image of `photo` (the photo's size, pixel-major): each pinhole
    /// pixel bilinearly sampled at its ray's position in the photo. Rows in parallel.
    pub fn apply(&self, photo: &[[f32; 3]]) -> Vec<[f32; 3]> {
        use rayon::prelude::*;
        let (sw, sh) = (self.photo.width as usize, self.photo.height as usize);
        assert_eq!(photo.len(), sw * sh, "the photo's size is the plan's");
        let w = self.pinhole.width as usize;
        let mut out = vec![[0f32; 3]; w * self.pinhole.height as usize];
        out.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            for (i, px) in row.iter_mut().enumerate() {
                let (u, v) = self.source(i as u32, j as u32);
                let u = u.clamp(0.0, (sw - 1) as f64);
                let v = v.clamp(0.0, (sh - 1) as f64);
                let (i0, j0) = (u.floor() as usize, v.floor() as usize);
                let (i1, j1) = ((i0 + 1).min(sw - 1), (j0 + 1).min(sh - 1));
                let (a, b) = ((u - i0 as f64) as f32, (v - j0 as f64) as f32);
                let at = |x: usize, y: usize| photo[y * sw + x];
                let (p00, p10, p01, p11) = (at(i0, j0), at(i1, j0), at(i0, j1), at(i1, j1));
                for c in 0..3 {
                    let top = p00[c] + (p10[c] - p00[c]) * a;
                    let bottom = p01[c] + (p11[c] - p01[c]) * a;
                    px[c] = top + (bottom - top) * b;
                }
            }
        });
        out
    }
}

/// `undistortion.json`: the undistortions of a model's photos, as [`read`] reads them.
pub fn to_json(images: &[Undistortion]) -> String {
    let record = Record {
        about: "How verisplat train undistorted these photos to the pinhole cameras of \
                cameras.json (before any -r scaling); verisplat eval applies the same to the photos."
            .into(),
        images: images.to_vec(),
    };
    serde_json::to_string_pretty(&record).unwrap_or_default()
}

/// The undistortions recorded in `path` (an `undistortion.json`).
pub fn read(path: &std::path::Path) -> Result<Vec<Undistortion>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read: {e}"))?;
    let record: Record = serde_json::from_str(&text)
        .map_err(|e| format!("is not a verisplat undistortion record: {e}"))?;
    Ok(record.images)
}
