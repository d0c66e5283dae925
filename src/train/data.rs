//! Training data: a COLMAP data set (`images/` and `sparse/0/` text or binary; `points3D`
//! as the initial Gaussians) or a transforms one, its photos as taken with their cameras
//! carrying the lens (distorted, fisheye, equirectangular: trained through the lens), or
//! with [`LensMode::Undistort`] undistorted to pinhole cameras where the lens is distorted
//! ([`super::undistort`]), at the training resolution, the train/test split of the original `--eval` (every 8th image in name order is held
//! out: the `llffhold` rule `verisplat eval` uses) and the scene extent the learning rates
//! and densification scale with.

use super::masks::{self, AlphaMode};
use super::undistort::Undistortion;
use crate::core::camera::distortion::{self, Distortion};
use crate::core::camera::{Camera, Lens};
use crate::io::camera::colmap::{self, Point3D};
use std::path::{Path, PathBuf};

/// What the trainer does with a lens other than the pinhole (`verisplat train
/// --undistort`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LensMode {
    /// The photos as taken, each camera carrying its lens (Brown-Conrady, fisheye,
    /// equirectangular): the renders and the backward pass go through the lens. The
    /// default.
    #[default]
    Through,
    /// The photos of distorted and fisheye cameras undistorted to pinhole views at load
    /// time, cropped to the largest rectangle inside the photo ([`super::undistort`]);
    /// a lens that cannot be undistorted (equirectangular) is refused.
    Undistort,
}

impl LensMode {
    /// `through` or `undistort`, as the model directory's [`LENS_FILE`] says it.
    pub fn name(self) -> &'static str {
        match self {
            LensMode::Through => "through",
            LensMode::Undistort => "undistort",
        }
    }
}

/// The file of a model directory that records how the cameras' lenses were trained with
/// (written when a data set camera has a lens other than the pinhole).
pub const LENS_FILE: &str = "lenses.json";

/// Every `LLFF_HOLD`-th image (in name order, from the first) is a test image with `--eval`.
pub const LLFF_HOLD: usize = 8;

/// One photo and its camera.
#[derive(Clone, Debug)]
pub struct View {
    /// The camera (at the training resolution); its name is the image's file name.
    pub camera: Camera,
    /// The photo, RGB in [0, 1] as stored (8-bit values / 255), pixel-major.
    pub image: Vec<[f32; 3]>,
    /// Which pixels training counts (true) and which it ignores, one flag per pixel;
    /// `None`: every pixel ([`super::masks`]).
    pub mask: Option<Vec<bool>>,
}

/// How a data set's photos are read ([`load`]).
#[derive(Clone, Copy, Debug)]
pub struct LoadOptions {
    /// The training resolution (`-r`).
    pub resolution: Resolution,
    /// Hold out the test views (`--eval`).
    pub eval: bool,
    /// Through the lenses, or undistorted.
    pub lenses: LensMode,
    /// The training background ([`AlphaMode::Background`] composites onto it).
    pub background: [f32; 3],
    /// What is done with a photo's alpha; `None`: the format's rule of old (COLMAP drops
    /// it, a transforms data set composites it onto the background).
    pub alpha: Option<AlphaMode>,
}

impl LoadOptions {
    /// `resolution` and `eval` through the lenses, a black background, the formats' alpha.
    pub fn new(resolution: Resolution, eval: bool) -> LoadOptions {
        LoadOptions {
            resolution,
            eval,
            lenses: LensMode::Through,
            background: [0.0; 3],
            alpha: None,
        }
    }
}

/// Reads the data set at `dir`: a transforms one ([`is_transforms`]) or a COLMAP one,
/// with its masks ([`super::masks`]).
pub fn load(dir: &Path, opts: &LoadOptions) -> Result<Dataset, DataError> {
    if is_transforms(dir) {
        load_transforms_from(dir, opts)
    } else {
        load_colmap_from(dir, opts)
    }
}

/// A data set ready to train on.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// Where it was read from.
    pub source: PathBuf,
    /// Training views, in image-name order.
    pub train: Vec<View>,
    /// Held-out views (with `--eval`), in image-name order.
    pub test: Vec<View>,
    /// The COLMAP model's points, if it has any.
    pub points: Option<Vec<Point3D>>,
    /// The original's `cameras_extent`: 1.1 times the largest distance of a training
    /// camera's centre from their mean.
    pub extent: f32,
    /// Where random Gaussians start without points (centre, half side); `None`: around
    /// the cameras' centre, within the extent.
    pub random_box: Option<([f32; 3], f32)>,
    /// How the photos of distorted cameras were undistorted (by image name; none for
    /// pinhole cameras, and none through the lens), for the model directory's
    /// `undistortion.json`.
    pub undistorted: Vec<Undistortion>,
    /// What was done with the lenses.
    pub lenses: LensMode,
}

impl Dataset {
    /// Every view, the held-out ones first (the order of the model's `cameras.json`).
    pub fn views(&self) -> impl Iterator<Item = &View> {
        self.test.iter().chain(&self.train)
    }

    /// How many photos were taken through each lens other than the pinhole (by
    /// [`Lens::name`]), in name order: the lenses of the cameras trained through, and
    /// with [`LensMode::Undistort`] those the undistorted photos were taken with.
    pub fn lens_counts(&self) -> Vec<(&'static str, usize)> {
        let mut counts = std::collections::BTreeMap::new();
        let lenses = self.views().map(|v| v.camera.lens.clone()).chain(
            self.undistorted
                .iter()
                .map(|u| Lens::from_distortion(&u.distortion)),
        );
        for lens in lenses.filter(|l| !l.is_pinhole()) {
            *counts.entry(lens.name()).or_insert(0) += 1;
        }
        counts.into_iter().collect()
    }

    /// The model directory's [`LENS_FILE`]: how the lenses were trained with and the photos
    /// of each lens; `None` when every photo is a pinhole camera's.
    pub fn lens_record(&self) -> Option<String> {
        let counts = self.lens_counts();
        if counts.is_empty() {
            return None;
        }
        let about = match self.lenses {
            LensMode::Through => {
                "verisplat train trained through each camera's lens: the photos as taken, \
                 every render and its backward pass through the lens of cameras.json"
            }
            LensMode::Undistort => {
                "verisplat train --undistort undistorted the photos of distorted cameras to \
                 the pinhole cameras of cameras.json, as undistortion.json records"
            }
        };
        let record = serde_json::json!({
            "about": about,
            "lenses": self.lenses.name(),
            "photos": counts
                .iter()
                .map(|(name, n)| (name.to_string(), serde_json::json!(n)))
                .collect::<serde_json::Map<_, _>>(),
        });
        serde_json::to_string_pretty(&record).ok()
    }
}

/// An error naming the file and what is wrong with it.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct DataError {
    /// The file or directory.
    pub path: PathBuf,
    /// What is wrong, one sentence.
    pub message: String,
}

impl From<masks::MaskError> for DataError {
    fn from(e: masks::MaskError) -> DataError {
        DataError {
            path: e.path,
            message: e.message,
        }
    }
}

fn data_error(path: &Path, message: impl Into<String>) -> DataError {
    DataError {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// How the photos are scaled, as the original's `-r`: 1, 2, 4 or 8 divide the size; any
/// other value is a width in pixels (the height follows the aspect ratio).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Resolution(pub u32);

impl Resolution {
    /// The training size of a `width x height` photo.
    pub fn size(self, width: u32, height: u32) -> (u32, u32) {
        match self.0 {
            0 | 1 => (width, height),
            d @ (2 | 4 | 8) => ((width / d).max(1), (height / d).max(1)),
            w => {
                let scale = w as f64 / width as f64;
                (w, ((height as f64 * scale).round() as u32).max(1))
            }
        }
    }
}

/// The camera centre in world space.
pub fn camera_centre(c: &Camera) -> glam::Vec3 {
    -(c.rotation.transpose() * c.translation)
}

/// The mean of `views`' camera centres and the original's `cameras_extent` (1.1 times the
/// largest distance of a centre from it; at least 1e-6).
pub fn cameras_centre_and_extent(views: &[View]) -> (glam::Vec3, f32) {
    let centres: Vec<glam::Vec3> = views.iter().map(|v| camera_centre(&v.camera)).collect();
    let mean = centres.iter().copied().sum::<glam::Vec3>() / centres.len().max(1) as f32;
    let radius = centres
        .iter()
        .map(|c| c.distance(mean))
        .fold(0.0f32, f32::max);
    (mean, (radius * 1.1).max(1e-6))
}

/// A photo's R, G and B planes (a grey one's Y thrice) and its alpha (1 without one).
fn rgba_planes(
    planes: &crate::io::image_file::Planes,
    path: &Path,
) -> Result<[Vec<f32>; 4], DataError> {
    let channel = |n: &str| planes.channel(n).map(|c| c.values.clone());
    let (r, g, b) = match (channel("R"), channel("G"), channel("B"), channel("Y")) {
        (Some(r), Some(g), Some(b), _) => (r, g, b),
        (_, _, _, Some(y)) => (y.clone(), y.clone(), y),
        _ => return Err(data_error(path, "has no colour or grey channels")),
    };
    let a = channel("A").unwrap_or_else(|| vec![1.0; r.len()]);
    Ok([r, g, b, a])
}

/// Reads the COLMAP data set at `dir`: the model (`dir/sparse/0`, `dir/sparse` or `dir`),
/// the photos in `dir/images` (PNG or JPEG, the size the model says, as taken, each camera
/// with the lens of its model, scaled to `resolution`), and with `eval` holds out every
/// 8th image. [`load_colmap_with`] undistorts them instead.
pub fn load_colmap(dir: &Path, resolution: Resolution, eval: bool) -> Result<Dataset, DataError> {
    load_colmap_with(dir, resolution, eval, LensMode::Through)
}

/// [`load_colmap`] with the lenses as `lenses` says: through them, or the photos of
/// distorted camera models undistorted to pinhole cameras ([`LensMode::Undistort`]).
pub fn load_colmap_with(
    dir: &Path,
    resolution: Resolution,
    eval: bool,
    lenses: LensMode,
) -> Result<Dataset, DataError> {
    let opts = LoadOptions {
        lenses,
        ..LoadOptions::new(resolution, eval)
    };
    load_colmap_from(dir, &opts)
}

/// [`load_colmap_with`] as `opts` says, with the masks in `dir/masks` when there are.
fn load_colmap_from(dir: &Path, opts: &LoadOptions) -> Result<Dataset, DataError> {
    let LoadOptions { eval, lenses, .. } = *opts;
    let (mut cameras, _) =
        colmap::load_colmap_model_distorted(dir).map_err(|e| data_error(dir, e.to_string()))?;
    if cameras.is_empty() {
        return Err(data_error(dir, "its COLMAP model registers no images"));
    }
    cameras.sort_by(|a, b| a.0.name.cmp(&b.0.name));
    let points = colmap::load_colmap_points(dir).map_err(|e| data_error(dir, e.to_string()))?;
    if let Some(p) = &points {
        if p.is_empty() {
            return Err(data_error(
                &dir.join("sparse"),
                "the COLMAP model's points3D holds no points; add points or remove the file to start from random Gaussians",
            ));
        }
    }
    let images = dir.join("images");
    if !images.is_dir() {
        return Err(data_error(
            &images,
            "is not a directory: the photos must be in DATASET/images",
        ));
    }
    let mask_files = colmap_masks(&images, cameras.iter().map(|(c, _)| c.name.as_str()))?;
    let views: Vec<Result<(View, Option<Undistortion>), DataError>> = {
        use rayon::prelude::*;
        cameras
            .par_iter()
            .zip(&mask_files)
            .map(|((cam, d), m)| load_view(&images, cam, d.as_ref(), m.as_deref(), opts))
            .collect()
    };
    let mut train = Vec::new();
    let mut test = Vec::new();
    let mut undistorted = Vec::new();
    for (k, v) in views.into_iter().enumerate() {
        let (v, u) = v?;
        undistorted.extend(u);
        if eval && k % LLFF_HOLD == 0 {
            test.push(v);
        } else {
            train.push(v);
        }
    }
    if train.is_empty() {
        return Err(data_error(
            dir,
            "no training image is left after holding out the test images",
        ));
    }
    let extent = cameras_centre_and_extent(&train).1;
    Ok(Dataset {
        source: dir.to_path_buf(),
        train,
        test,
        points,
        extent,
        random_box: None,
        undistorted,
        lenses,
    })
}

/// The mask of each photo named by `names` in `images`: none without `images/../masks`
/// (or when no photo has one there); every photo's, or an error naming one without.
fn colmap_masks<'a>(
    images: &Path,
    names: impl Iterator<Item = &'a str>,
) -> Result<Vec<Option<PathBuf>>, DataError> {
    let names: Vec<&str> = names.collect();
    let Some(dir) = masks::masks_dir(images) else {
        return Ok(vec![None; names.len()]);
    };
    let found: Vec<Option<PathBuf>> = names.iter().map(|n| masks::find_mask(&dir, n)).collect();
    let have = found.iter().flatten().count();
    if have > 0 {
        if let Some(k) = found.iter().position(Option::is_none) {
            return Err(
                masks::missing(&images.join(names[k]), &dir.display().to_string(), have).into(),
            );
        }
    }
    Ok(found)
}

/// The photo of `cam` in `images` (masked by the file `mask`, when given) as a view at
/// the training resolution: taken through the lens of `distortion`, or with
/// [`LensMode::Undistort`] undistorted through it (with how).
fn load_view(
    images: &Path,
    cam: &Camera,
    distortion: Option<&Distortion>,
    mask: Option<&Path>,
    opts: &LoadOptions,
) -> Result<(View, Option<Undistortion>), DataError> {
    let path = images.join(&cam.name);
    let planes =
        crate::io::image_file::read_image(&path).map_err(|e| data_error(&path, e.to_string()))?;
    if (planes.width, planes.height) != (cam.width, cam.height) {
        return Err(data_error(
            &path,
            format!(
                "is {}x{}, but its camera in the COLMAP model is {}x{}",
                planes.width, planes.height, cam.width, cam.height
            ),
        ));
    }
    let alpha = opts.alpha.unwrap_or(AlphaMode::Ignore);
    match (distortion, opts.lenses) {
        (Some(d), LensMode::Through) => {
            let cam = Camera {
                lens: Lens::from_distortion(d),
                ..cam.clone()
            };
            photo_view(cam, &planes, &path, mask, None, opts, alpha)
        }
        (d, _) => photo_view(cam.clone(), &planes, &path, mask, d, opts, alpha),
    }
}

/// The view of `cam` and its photo `planes` (read from `path`): its alpha as `alpha`
/// says, masked by the file `mask` (when given), undistorted through `distortion` (when
/// given) and scaled to the training resolution.
fn photo_view(
    cam: Camera,
    planes: &crate::io::image_file::Planes,
    path: &Path,
    mask: Option<&Path>,
    distortion: Option<&Distortion>,
    opts: &LoadOptions,
    alpha: AlphaMode,
) -> Result<(View, Option<Undistortion>), DataError> {
    let rgba = rgba_planes(planes, path)?;
    let (full, alpha_keep) = alpha.apply(&rgba, opts.background);
    let size = (cam.width, cam.height);
    let training = distortion
        .is_none()
        .then(|| opts.resolution.size(size.0, size.1));
    let file_keep = mask
        .map(|m| masks::read_mask(m, path, size, training))
        .transpose()?;
    let keep = masks::both(file_keep, alpha_keep);
    let (view, how) = undistorted_view(cam, full, keep, distortion, opts.resolution, path)?;
    if view.mask.as_ref().is_some_and(|m| !m.contains(&true)) {
        return Err(data_error(
            mask.unwrap_or(path),
            "masks every pixel of its photo (at the training resolution); a photo needs a kept pixel",
        ));
    }
    Ok((view, how))
}

/// `cam` and its photo `full` undistorted through `distortion` (when given; `path` names
/// the photo in errors) and scaled to `resolution`, with how it was undistorted.
fn undistorted_view(
    cam: Camera,
    full: Vec<[f32; 3]>,
    keep: Option<Vec<f32>>,
    distortion: Option<&Distortion>,
    resolution: Resolution,
    path: &Path,
) -> Result<(View, Option<Undistortion>), DataError> {
    let keep = keep.map(|k| k.iter().map(|&v| [v; 3]).collect::<Vec<_>>());
    let Some(d) = distortion else {
        return Ok((scaled_view(cam, full, keep, resolution), None));
    };
    let plan = Undistortion::plan(&cam, d).map_err(|m| data_error(path, m))?;
    let image = plan.apply(&full);
    let keep = keep.map(|k| plan.apply(&k));
    Ok((
        scaled_view(plan.camera(&cam), image, keep, resolution),
        Some(plan),
    ))
}

/// Area-averaged downscaling of a `sw x sh` image to `dw x dh` (each output pixel the
/// mean of the input pixels it covers, partially covered ones weighted): how the trainer
/// scales photos to `-r`, and `eval` the same photos.
pub fn resize(src: &[[f32; 3]], sw: u32, sh: u32, dw: u32, dh: u32) -> Vec<[f32; 3]> {
    let axis = |s: u32, d: u32| -> Vec<Vec<(usize, f32)>> {
        let ratio = s as f64 / d as f64;
        (0..d)
            .map(|o| {
                let (a, b) = (o as f64 * ratio, (o + 1) as f64 * ratio);
                let mut taps = Vec::new();
                let mut i = a.floor() as usize;
                while (i as f64) < b && i < s as usize {
                    let w = (b.min(i as f64 + 1.0) - a.max(i as f64)).max(0.0);
                    if w > 0.0 {
                        taps.push((i, (w / ratio) as f32));
                    }
                    i += 1;
                }
                taps
            })
            .collect()
    };
    let (xs, ys) = (axis(sw, dw), axis(sh, dh));
    let mut out = vec![[0f32; 3]; (dw * dh) as usize];
    for (y, ty) in ys.iter().enumerate() {
        for (x, tx) in xs.iter().enumerate() {
            let mut acc = [0f32; 3];
            for &(j, wy) in ty {
                for &(i, wx) in tx {
                    let p = src[j * sw as usize + i];
                    for c in 0..3 {
                        acc[c] += wx * wy * p[c];
                    }
                }
            }
            out[y * dw as usize + x] = acc;
        }
    }
    out
}

/// Writes a COLMAP data set of `scene` seen by `cameras` into `dir` (what a trainer reads;
/// a way to test one on a known scene): each camera's render by the CPU reference (the
/// feature channels shaded by `shader`, when given) as `images/NAME.png` (`.png` added to
/// names without it), and a text model in `sparse/0/` whose `points3D` are every
/// `point_stride`-th Gaussian centre with its DC colour. Existing files are an error
/// unless `overwrite`.
pub fn write_rendered_dataset(
    dir: &Path,
    scene: &crate::core::scene::Scene,
    cameras: &[Camera],
    shader: Option<&crate::fields::mlp::Mlp>,
    point_stride: usize,
    overwrite: bool,
) -> Result<(), DataError> {
    if let Some(mlp) = shader {
        mlp.check_channels(scene.feature_count)
            .map_err(|m| data_error(dir, m))?;
    }
    let act = scene.activated();
    write_dataset(dir, scene, cameras, point_stride, overwrite, &mut |cam| {
        let mut frame = crate::cpu::render_features(&act, cam, &Default::default());
        if let Some(mlp) = shader {
            frame.color = crate::fields::mlp::shade(
                mlp,
                cam,
                &frame.features,
                scene.feature_count,
                &frame.alpha,
                [0.0; 3],
            );
        }
        Ok(frame)
    })
}

/// [`write_rendered_dataset`] with the frames rendered by `render` (e.g. on the device;
/// their colour is written as 8-bit PNG). `render` sees each camera with its final name.
pub fn write_dataset(
    dir: &Path,
    scene: &crate::core::scene::Scene,
    cameras: &[Camera],
    point_stride: usize,
    overwrite: bool,
    render: &mut dyn FnMut(&Camera) -> Result<crate::core::frame::Frame, String>,
) -> Result<(), DataError> {
    let images = dir.join("images");
    let sparse = dir.join("sparse").join("0");
    let mut named: Vec<Camera> = Vec::with_capacity(cameras.len());
    let mut seen = std::collections::HashSet::new();
    for cam in cameras {
        // A lens COLMAP has no model for is refused before anything is written.
        colmap::colmap_model(cam).map_err(|m| data_error(dir, m))?;
        let mut cam = cam.clone();
        if !cam.name.to_ascii_lowercase().ends_with(".png") {
            cam.name = format!("{}.png", cam.name);
        }
        if !seen.insert(cam.name.clone()) {
            return Err(data_error(
                dir,
                format!(
                    "two cameras are named {}; a COLMAP data set names each image once",
                    cam.name
                ),
            ));
        }
        let path = images.join(&cam.name);
        if path.exists() && !overwrite {
            return Err(data_error(&path, "exists (give --overwrite to replace it)"));
        }
        named.push(cam);
    }
    for d in [&images, &sparse] {
        std::fs::create_dir_all(d).map_err(|e| data_error(d, format!("cannot create: {e}")))?;
    }
    for cam in &named {
        let frame = render(cam).map_err(|m| data_error(&images.join(&cam.name), m))?;
        let path = images.join(&cam.name);
        crate::io::output::write_frame(
            &frame,
            &path,
            crate::io::output::ImageFormat::Png8,
            overwrite,
        )
        .map_err(|e| data_error(&path, e.to_string()))?;
    }
    let stride = scene.sh_stride();
    let points: Vec<Point3D> = (0..scene.len())
        .step_by(point_stride.max(1))
        .map(|i| Point3D {
            position: scene.positions[i].map(f64::from),
            color: [0, 1, 2].map(|c| {
                let v = 0.5 + crate::core::model::sh::SH_C0 * scene.sh[i * stride + c];
                (v.clamp(0.0, 1.0) * 255.0).round() as u8
            }),
        })
        .collect();
    let model =
        colmap::to_text_model(&named, &points).map_err(|e| data_error(dir, e.to_string()))?;
    for (name, text) in model {
        let path = sparse.join(name);
        crate::core::fsutil::write_bytes_atomically(&path, overwrite, text.as_bytes())
            .map_err(|e| data_error(&path, e.to_string()))?;
    }
    Ok(())
}

/// Whether `dir` is a NeRF-synthetic / nerfstudio data set (`transforms_train.json` or
/// `transforms.json`) rather than a COLMAP one.
pub fn is_transforms(dir: &Path) -> bool {
    dir.join("transforms_train.json").is_file() || dir.join("transforms.json").is_file()
}

/// Reads a NeRF-synthetic (`transforms_train.json`, `transforms_test.json`) or nerfstudio
/// (`transforms.json`) data set: cameras from `camera_angle_x` or `fl_x`/`fl_y`/`cx`/`cy`
/// and each frame's camera-to-world `transform_matrix` (OpenGL axes, turned into ours as the
/// original's `readCamerasFromTransforms`), photos at `file_path` (`.png` added when it
/// has no extension) with their alpha composited over `background`. With `eval` the test
/// file's frames are held out (NeRF-synthetic), or every 8th frame of a single
/// `transforms.json`. No points: the original starts these from random Gaussians in the
/// cube of half side 1.3 ([`Dataset::random_box`]). The photos are as taken, each camera
/// with the lens its `camera_model` and distortion keys give
/// ([`crate::io::camera::transforms::lens_from_transforms`]); [`load_transforms_with`]
/// undistorts them instead.
pub fn load_transforms(
    dir: &Path,
    resolution: Resolution,
    eval: bool,
    background: [f32; 3],
) -> Result<Dataset, DataError> {
    load_transforms_with(dir, resolution, eval, background, LensMode::Through)
}

/// [`load_transforms`] with the lenses as `lenses` says: through them, or the photos of
/// distorted frames undistorted to pinhole cameras ([`LensMode::Undistort`]; an
/// `EQUIRECTANGULAR` camera is then refused).
pub fn load_transforms_with(
    dir: &Path,
    resolution: Resolution,
    eval: bool,
    background: [f32; 3],
    lenses: LensMode,
) -> Result<Dataset, DataError> {
    let opts = LoadOptions {
        lenses,
        background,
        ..LoadOptions::new(resolution, eval)
    };
    load_transforms_from(dir, &opts)
}

/// [`load_transforms_with`] as `opts` says, with each frame's `mask_path` or the masks in
/// `masks/` beside its photo's folder.
fn load_transforms_from(dir: &Path, opts: &LoadOptions) -> Result<Dataset, DataError> {
    let LoadOptions { eval, lenses, .. } = *opts;
    let split = dir.join("transforms_train.json").is_file();
    let (train_file, test_file) = if split {
        (
            dir.join("transforms_train.json"),
            Some(dir.join("transforms_test.json")),
        )
    } else {
        (dir.join("transforms.json"), None)
    };
    let mut undistorted = Vec::new();
    let read = |file: &Path, undistorted: &mut Vec<Undistortion>| {
        read_transforms(file, dir, opts, undistorted)
    };
    let mut train = read(&train_file, &mut undistorted)?;
    let mut test = Vec::new();
    match test_file {
        Some(f) if eval => {
            if !f.is_file() {
                return Err(data_error(&f, "is missing; --eval holds out its frames"));
            }
            test = read(&f, &mut undistorted)?;
        }
        None if eval => {
            let all = std::mem::take(&mut train);
            for (k, v) in all.into_iter().enumerate() {
                if k % LLFF_HOLD == 0 {
                    test.push(v);
                } else {
                    train.push(v);
                }
            }
        }
        _ => {}
    }
    if train.is_empty() {
        return Err(data_error(&train_file, "lists no training frames"));
    }
    let extent = cameras_centre_and_extent(&train).1;
    Ok(Dataset {
        source: dir.to_path_buf(),
        train,
        test,
        points: None,
        extent,
        random_box: Some(([0.0; 3], 1.3)),
        undistorted,
        lenses,
    })
}

/// The views of the transforms file `file` of data set `dir`, their cameras with their
/// lens or, with [`LensMode::Undistort`], their photos undistorted where the lens is
/// distorted (how, appended to `undistorted`).
fn read_transforms(
    file: &Path,
    dir: &Path,
    opts: &LoadOptions,
    undistorted: &mut Vec<Undistortion>,
) -> Result<Vec<View>, DataError> {
    let text =
        std::fs::read_to_string(file).map_err(|e| data_error(file, format!("cannot read: {e}")))?;
    let doc: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| data_error(file, format!("is not JSON: {e}")))?;
    let frames = doc["frames"]
        .as_array()
        .ok_or_else(|| data_error(file, "has no \"frames\" list"))?;
    let num = |v: &serde_json::Value| v.as_f64().filter(|x| x.is_finite());
    let mut views = Vec::with_capacity(frames.len());
    // Each frame's photo and whether it has a mask.
    let mut masked: Vec<(PathBuf, bool)> = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        let bad = |m: String| data_error(file, format!("frame {i}: {m}"));
        let rel = f["file_path"]
            .as_str()
            .ok_or_else(|| bad("has no file_path".into()))?;
        let path = crate::io::camera::transforms::frame_photo(dir, rel);
        let m = f["transform_matrix"]
            .as_array()
            .filter(|rows| rows.len() >= 3)
            .ok_or_else(|| bad("has no 4x4 transform_matrix".into()))?;
        let mut c2w = [[0f64; 4]; 3];
        for (r, row) in m.iter().take(3).enumerate() {
            let row = row
                .as_array()
                .filter(|r| r.len() == 4)
                .ok_or_else(|| bad("transform_matrix rows must have 4 numbers".into()))?;
            for (c, v) in row.iter().enumerate() {
                c2w[r][c] =
                    num(v).ok_or_else(|| bad("transform_matrix holds a non-number".into()))?;
            }
        }
        let planes = crate::io::image_file::read_image(&path)
            .map_err(|e| data_error(&path, e.to_string()))?;
        let (w, h) = (planes.width, planes.height);
        // The lens: the camera's own, or (undistorting) the distortion of its photo.
        let value = |k: &str| f.get(k).or_else(|| doc.get(k));
        let (lens, distortion) = match opts.lenses {
            LensMode::Through => (
                crate::io::camera::transforms::lens_from_transforms(&value).map_err(bad)?,
                None,
            ),
            LensMode::Undistort => (
                Lens::Pinhole,
                distortion::from_transforms(&value).map_err(bad)?,
            ),
        };
        let sphere = lens == Lens::FULL_SPHERE;
        // Intrinsics: per frame, else the file's; a focal length, else the field of view
        // (nerfstudio's equirectangular camera needs neither: fx = W / 2, fy = H).
        let key = |k: &str| num(&f[k]).or_else(|| num(&doc[k]));
        let fx = match (key("fl_x"), key("camera_angle_x")) {
            (Some(fl), _) => fl,
            (None, Some(angle)) if angle > 0.0 && angle < std::f64::consts::PI => {
                w as f64 / (2.0 * (angle / 2.0).tan())
            }
            (None, None) if sphere => w as f64 / 2.0,
            _ => {
                return Err(bad(
                    "no fl_x or camera_angle_x gives the focal length".into()
                ))
            }
        };
        let fy = match key("fl_y") {
            Some(fl) => fl,
            None if sphere && key("fl_x").is_none() => h as f64,
            None => fx,
        };
        let cx = key("cx").unwrap_or(w as f64 / 2.0);
        let cy = key("cy").unwrap_or(h as f64 / 2.0);
        // OpenGL camera axes (y up, z back) to ours (y down, z forward), then invert.
        let r_c2w = glam::DMat3::from_cols(
            glam::DVec3::new(c2w[0][0], c2w[1][0], c2w[2][0]),
            -glam::DVec3::new(c2w[0][1], c2w[1][1], c2w[2][1]),
            -glam::DVec3::new(c2w[0][2], c2w[1][2], c2w[2][2]),
        );
        let centre = glam::DVec3::new(c2w[0][3], c2w[1][3], c2w[2][3]);
        let rotation = r_c2w.transpose();
        let name = std::path::Path::new(rel)
            .file_name()
            .map_or_else(|| format!("frame_{i}"), |n| n.to_string_lossy().to_string());
        let camera = Camera {
            name,
            width: w,
            height: h,
            fx: fx as f32,
            fy: fy as f32,
            cx: cx as f32,
            cy: cy as f32,
            rotation: rotation.as_mat3(),
            translation: (-(rotation * centre)).as_vec3(),
            lens,
        };
        camera
            .validate()
            .map_err(|e| bad(format!("its camera is not valid: {e}")))?;
        // A lens's coefficients hold for the size the intrinsics were given at.
        let size = (key("w"), key("h"));
        let distorted = distortion.is_some()
            || matches!(
                camera.lens,
                Lens::RadialTangential { .. } | Lens::Fisheye { .. }
            );
        if distorted && size != (None, None) && size != (Some(w as f64), Some(h as f64)) {
            return Err(bad(format!(
                "its photo {} is {w}x{h} but \"w\" and \"h\" say {}x{}; the lens \
                 distortion is given for the size the intrinsics are",
                path.display(),
                size.0.map_or("?".into(), |v| v.to_string()),
                size.1.map_or("?".into(), |v| v.to_string())
            )));
        }
        let mask = frame_mask(f, dir, &path).map_err(bad)?;
        masked.push((path.clone(), mask.is_some()));
        let alpha = opts.alpha.unwrap_or(AlphaMode::Background);
        let (view, how) = photo_view(
            camera,
            &planes,
            &path,
            mask.as_deref(),
            distortion.as_ref(),
            opts,
            alpha,
        )?;
        views.push(view);
        undistorted.extend(how);
    }
    let have = masked.iter().filter(|(_, m)| *m).count();
    if let Some((photo, _)) = masked.iter().find(|(_, m)| !m).filter(|_| have > 0) {
        return Err(masks::missing(
            photo,
            "its frame's mask_path or the masks folder beside its folder",
            have,
        )
        .into());
    }
    Ok(views)
}

/// The mask of a transforms frame `f` whose photo is `photo`: its `mask_path` (relative
/// to the data set's folder `dir`), else the photo's in `masks/` beside the photo's
/// folder, else none.
fn frame_mask(f: &serde_json::Value, dir: &Path, photo: &Path) -> Result<Option<PathBuf>, String> {
    if let Some(v) = f.get("mask_path") {
        let rel = v.as_str().ok_or("its mask_path is not a string")?;
        return Ok(Some(dir.join(rel)));
    }
    let (Some(folder), Some(name)) = (photo.parent(), photo.file_name()) else {
        return Ok(None);
    };
    Ok(masks::masks_dir(folder).and_then(|m| masks::find_mask(&m, &name.to_string_lossy())))
}

/// `camera` and its photo at `resolution`: the focal lengths and principal point scale with
/// the image (as [`Camera::with_resolution`]); a lens's coefficients are in normalised
/// coordinates (Brown-Conrady, fisheye) or angles (equirectangular), so the lens is kept.
/// The keep plane `keep` (when given) goes the photo's way, then is thresholded at 0.5;
/// a fisheye's pixels outside its image circle are masked.
fn scaled_view(
    cam: Camera,
    full: Vec<[f32; 3]>,
    keep: Option<Vec<[f32; 3]>>,
    resolution: Resolution,
) -> View {
    let (w, h) = resolution.size(cam.width, cam.height);
    let scale = |plane: Vec<[f32; 3]>| {
        if (w, h) == (cam.width, cam.height) {
            plane
        } else {
            resize(&plane, cam.width, cam.height, w, h)
        }
    };
    let image = scale(full);
    let keep = keep.map(|k| masks::to_flags(&scale(k)));
    let (sx, sy) = (w as f32 / cam.width as f32, h as f32 / cam.height as f32);
    let camera = Camera {
        width: w,
        height: h,
        fx: cam.fx * sx,
        fy: cam.fy * sy,
        cx: cam.cx * sx,
        cy: cam.cy * sy,
        ..cam
    };
    let mask = match (keep, masks::image_circle(&camera)) {
        (Some(k), Some(c)) => Some(k.iter().zip(&c).map(|(a, b)| *a && *b).collect()),
        (k, c) => k.or(c),
    };
    View {
        camera,
        image,
        mask,
    }
}
