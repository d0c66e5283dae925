//! COLMAP sparse models (`cameras` + `images`, text or binary, as COLMAP's
//! `read_write_model.py` reads them). COLMAP poses are world-to-camera in OpenCV axes
//! (`R = qvec2rotmat(qvec)`, `t = tvec`), exactly our [`Camera`] convention, and its
//! principal point uses the same pixel convention as ours (pixel centres at `+0.5`), so
//! `cx`, `cy` are kept as written. Images come back sorted by name, as the 3DGS
//! loaders sort them. Each camera carries the lens of its model ([`Camera::lens`]):
//! `SIMPLE_PINHOLE`, `PINHOLE` (and a distorted model whose coefficients are all zero) are
//! the pinhole; `SIMPLE_RADIAL`, `RADIAL`, `OPENCV`, `FULL_OPENCV` are
//! [`Lens::RadialTangential`]; `OPENCV_FISHEYE`, `SIMPLE_RADIAL_FISHEYE`, `RADIAL_FISHEYE`
//! are [`Lens::Fisheye`]. The models verisplat has no lens for (`FOV` with a non-zero
//! `omega`, the thin-prism fisheyes) are refused by name. The trainer reads the same models
//! as pinhole cameras with their distortion ([`load_colmap_model_distorted`]) and
//! undistorts their photos.

use super::distortion::{self, Distortion};
use super::{quat_wxyz_to_mat, Camera, CameraError, CameraFormat, Lens, MAX_IMAGE_SIDE};
use crate::core::file_error::FileError;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A COLMAP camera model: name, id in binary files, and parameter count.
struct Model {
    id: i32,
    name: &'static str,
    params: usize,
}

const MODELS: &[Model] = &[
    Model {
        id: 0,
        name: "SIMPLE_PINHOLE",
        params: 3,
    },
    Model {
        id: 1,
        name: "PINHOLE",
        params: 4,
    },
    Model {
        id: 2,
        name: "SIMPLE_RADIAL",
        params: 4,
    },
    Model {
        id: 3,
        name: "RADIAL",
        params: 5,
    },
    Model {
        id: 4,
        name: "OPENCV",
        params: 8,
    },
    Model {
        id: 5,
        name: "OPENCV_FISHEYE",
        params: 8,
    },
    Model {
        id: 6,
        name: "FULL_OPENCV",
        params: 12,
    },
    Model {
        id: 7,
        name: "FOV",
        params: 5,
    },
    Model {
        id: 8,
        name: "SIMPLE_RADIAL_FISHEYE",
        params: 4,
    },
    Model {
        id: 9,
        name: "RADIAL_FISHEYE",
        params: 5,
    },
    Model {
        id: 10,
        name: "THIN_PRISM_FISHEYE",
        params: 12,
    },
    Model {
        id: 11,
        name: "RAD_TAN_THIN_PRISM_FISHEYE",
        params: 16,
    },
];

/// A camera (its pinhole part) and its lens distortion (`None`: none).
pub type LensCamera = (Camera, Option<Distortion>);

/// Intrinsics of one COLMAP camera: the pinhole part and the lens distortion.
#[derive(Clone, Debug)]
struct Intrinsics {
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    distortion: Option<Distortion>,
}

/// One registered image: pose (world-to-camera) and the camera it was taken with.
struct Image {
    id: u64,
    name: String,
    qvec: [f64; 4],
    tvec: [f64; 3],
    camera_id: u64,
}

fn invalid(path: &Path, message: String) -> CameraError {
    CameraError::File(FileError::Invalid {
        path: path.to_path_buf(),
        message,
    })
}

/// Finds the model files under `dir` (itself, `sparse/0`, or `sparse`): the directory
/// holding them and whether they are binary or text (binary wins when both exist, as in
/// the 3DGS loader).
pub fn find_model(dir: &Path) -> Result<(PathBuf, CameraFormat), CameraError> {
    for sub in [
        dir.to_path_buf(),
        dir.join("sparse").join("0"),
        dir.join("sparse"),
    ] {
        for (ext, format) in [
            ("bin", CameraFormat::ColmapBinary),
            ("txt", CameraFormat::ColmapText),
        ] {
            if sub.join(format!("cameras.{ext}")).is_file()
                && sub.join(format!("images.{ext}")).is_file()
            {
                return Ok((sub, format));
            }
        }
    }
    Err(CameraError::NotFound {
        path: dir.to_path_buf(),
        message:
            "is not a COLMAP sparse model: found no cameras.bin + images.bin or cameras.txt + \
                  images.txt in it, in sparse/0/ or in sparse/"
                .into(),
    })
}

/// Loads every registered image of the COLMAP model under `dir` as a camera, sorted by
/// name, each with the lens of its camera model.
pub fn load_colmap_model(dir: &Path) -> Result<(Vec<Camera>, CameraFormat), CameraError> {
    let (cams, format) = load_model(dir, false)?;
    Ok((cams.into_iter().map(|(c, _)| c).collect(), format))
}

/// The cameras of [`load_colmap_model`] as the trainer wants them: each camera's pinhole
/// part ([`Lens::Pinhole`]) with its distortion (`None`: none), for the photos to be
/// undistorted.
pub fn load_colmap_model_distorted(
    dir: &Path,
) -> Result<(Vec<LensCamera>, CameraFormat), CameraError> {
    load_model(dir, true)
}

fn load_model(dir: &Path, distorted: bool) -> Result<(Vec<LensCamera>, CameraFormat), CameraError> {
    let (model_dir, format) = find_model(dir)?;
    let ext = if format == CameraFormat::ColmapBinary {
        "bin"
    } else {
        "txt"
    };
    let cameras_path = model_dir.join(format!("cameras.{ext}"));
    let images_path = model_dir.join(format!("images.{ext}"));
    let read = |p: &Path| {
        std::fs::read(p).map_err(|source| {
            CameraError::File(FileError::Io {
                path: p.to_path_buf(),
                source,
            })
        })
    };
    let (cams_bytes, images_bytes) = (read(&cameras_path)?, read(&images_path)?);
    let cams = if format == CameraFormat::ColmapBinary {
        parse_binary(
            &cams_bytes,
            &cameras_path,
            &images_bytes,
            &images_path,
            distorted,
        )?
    } else {
        let text = |b: Vec<u8>, p: &Path| {
            String::from_utf8(b).map_err(|_| invalid(p, "is not UTF-8 text".into()))
        };
        parse_text(
            &text(cams_bytes, &cameras_path)?,
            &cameras_path,
            &text(images_bytes, &images_path)?,
            &images_path,
            distorted,
        )?
    };
    Ok((cams, format))
}

/// Parses `cameras.txt` and `images.txt` held in memory (the paths name them in errors).
pub fn parse_colmap_text(
    cameras_txt: &str,
    cameras_path: &Path,
    images_txt: &str,
    images_path: &Path,
) -> Result<Vec<Camera>, CameraError> {
    let cams = parse_text(cameras_txt, cameras_path, images_txt, images_path, false)?;
    Ok(cams.into_iter().map(|(c, _)| c).collect())
}

/// [`parse_colmap_text`]; when `distorted`, each camera is its pinhole part with its
/// distortion beside it, else it carries its lens.
fn parse_text(
    cameras_txt: &str,
    cameras_path: &Path,
    images_txt: &str,
    images_path: &Path,
    distorted: bool,
) -> Result<Vec<LensCamera>, CameraError> {
    let mut intrinsics = HashMap::new();
    for (n, line) in cameras_txt.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |what: String| invalid(cameras_path, format!("line {}: {what}", n + 1));
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 4 {
            return Err(bad(format!(
                "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got \"{line}\""
            )));
        }
        let id: u64 = f[0].parse().map_err(|_| {
            bad(format!(
                "camera id \"{}\" is not a non-negative integer",
                f[0]
            ))
        })?;
        let model = MODELS.iter().find(|m| m.name == f[1]).ok_or_else(|| {
            bad(format!(
                "camera {id} has unknown camera model \"{}\" (known: {})",
                f[1],
                MODELS.iter().map(|m| m.name).collect::<Vec<_>>().join(", ")
            ))
        })?;
        let dim = |s: &str, what: &str| {
            s.parse::<u64>().map_err(|_| {
                bad(format!(
                    "camera {id}: {what} \"{s}\" is not a positive integer"
                ))
            })
        };
        let (width, height) = (dim(f[2], "width")?, dim(f[3], "height")?);
        let params = f[4..]
            .iter()
            .map(|s| {
                s.parse::<f64>()
                    .map_err(|_| bad(format!("camera {id}: parameter \"{s}\" is not a number")))
            })
            .collect::<Result<Vec<f64>, _>>()?;
        if params.len() != model.params {
            return Err(bad(format!(
                "camera {id}: model {} takes {} parameters, the line has {}",
                model.name,
                model.params,
                params.len()
            )));
        }
        let k = intrinsics_of(id, model, width, height, &params)
            .map_err(|m| invalid(cameras_path, m))?;
        if intrinsics.insert(id, k).is_some() {
            return Err(bad(format!("camera id {id} appears twice")));
        }
    }

    let mut images = Vec::new();
    let mut lines = images_txt.lines().enumerate();
    while let Some((n, line)) = lines.next() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |what: String| invalid(images_path, format!("line {}: {what}", n + 1));
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 10 {
            return Err(bad(format!(
                "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got \"{line}\""
            )));
        }
        let int = |s: &str, what: &str| {
            s.parse::<u64>()
                .map_err(|_| bad(format!("{what} \"{s}\" is not a non-negative integer")))
        };
        let mut num = [0f64; 7];
        for (v, s) in num.iter_mut().zip(&f[1..8]) {
            *v = s
                .parse()
                .map_err(|_| bad(format!("pose value \"{s}\" is not a number")))?;
        }
        images.push(Image {
            id: int(f[0], "image id")?,
            qvec: [num[0], num[1], num[2], num[3]],
            tvec: [num[4], num[5], num[6]],
            camera_id: int(f[8], "camera id")?,
            name: f[9..].join(" "),
        });
        // Every image line is followed by its 2D points line (possibly empty): skip it.
        lines.next();
    }
    assemble(images, &intrinsics, images_path, distorted)
}

/// Parses `cameras.bin` and `images.bin` held in memory (the paths name them in errors).
/// Counts are checked against the bytes that remain, so a truncated or lying file gives
/// an error, never a huge allocation or a panic.
pub fn parse_colmap_binary(
    cameras_bin: &[u8],
    cameras_path: &Path,
    images_bin: &[u8],
    images_path: &Path,
) -> Result<Vec<Camera>, CameraError> {
    let cams = parse_binary(cameras_bin, cameras_path, images_bin, images_path, false)?;
    Ok(cams.into_iter().map(|(c, _)| c).collect())
}

/// [`parse_colmap_binary`]; `distorted` as in [`parse_text`].
fn parse_binary(
    cameras_bin: &[u8],
    cameras_path: &Path,
    images_bin: &[u8],
    images_path: &Path,
    distorted: bool,
) -> Result<Vec<LensCamera>, CameraError> {
    let mut r = Reader::new(cameras_bin, cameras_path);
    // camera_id i32, model_id i32, width u64, height u64, then the parameters.
    let count = r.count("cameras", 24)?;
    let mut intrinsics = HashMap::new();
    for _ in 0..count {
        let id = r.u32("camera id")? as u64;
        let model_id = r.u32("model id")? as i32;
        let model = MODELS.iter().find(|m| m.id == model_id).ok_or_else(|| {
            invalid(
                cameras_path,
                format!("camera {id} has unknown camera model id {model_id} (known: 0..=11)"),
            )
        })?;
        let width = r.u64("width")?;
        let height = r.u64("height")?;
        let mut params = Vec::with_capacity(model.params);
        for _ in 0..model.params {
            params.push(r.f64("camera parameter")?);
        }
        let k = intrinsics_of(id, model, width, height, &params)
            .map_err(|m| invalid(cameras_path, m))?;
        if intrinsics.insert(id, k).is_some() {
            return Err(invalid(
                cameras_path,
                format!("camera id {id} appears twice"),
            ));
        }
    }
    r.finish()?;

    let mut r = Reader::new(images_bin, images_path);
    // image_id, qvec, tvec, camera_id, at least a NUL name terminator, num_points2D.
    let count = r.count("images", 4 + 7 * 8 + 4 + 1 + 8)?;
    let mut images = Vec::with_capacity(count);
    for _ in 0..count {
        let id = r.u32("image id")? as u64;
        let mut v = [0f64; 7];
        for x in &mut v {
            *x = r.f64("image pose")?;
        }
        let camera_id = r.u32("camera id")? as u64;
        let name = r.cstring("image name")?;
        let points = r.u64("number of 2D points")?;
        let bytes = points
            .checked_mul(24)
            .filter(|&b| b <= r.remaining() as u64)
            .ok_or_else(|| {
                invalid(
                    images_path,
                    format!(
                        "image {id} (\"{name}\") claims {points} 2D points ({} bytes) but only {} bytes remain: the file is truncated or corrupt",
                        points as u128 * 24,
                        r.remaining()
                    ),
                )
            })?;
        r.skip(bytes as usize);
        images.push(Image {
            id,
            name,
            qvec: [v[0], v[1], v[2], v[3]],
            tvec: [v[4], v[5], v[6]],
            camera_id,
        });
    }
    r.finish()?;
    assemble(images, &intrinsics, images_path, distorted)
}

/// Intrinsics of a COLMAP camera with its distortion, or why they cannot be used: a model
/// [`distortion::from_colmap`] has no lens for, or unusable values.
fn intrinsics_of(
    id: u64,
    model: &Model,
    width: u64,
    height: u64,
    p: &[f64],
) -> Result<Intrinsics, String> {
    let (focal, principal, coefficients): ([f64; 2], [f64; 2], &[f64]) = match model.name {
        "SIMPLE_PINHOLE"
        | "SIMPLE_RADIAL"
        | "RADIAL"
        | "SIMPLE_RADIAL_FISHEYE"
        | "RADIAL_FISHEYE" => ([p[0], p[0]], [p[1], p[2]], &p[3..]),
        _ => ([p[0], p[1]], [p[2], p[3]], &p[4..]),
    };
    let distortion = distortion::from_colmap(model.name, coefficients)
        .map_err(|m| format!("camera {id}: {m}"))?;
    let max = MAX_IMAGE_SIDE as u64;
    if width == 0 || height == 0 || width > max || height > max {
        return Err(format!(
            "camera {id}: resolution {width}x{height} is not usable; each side must be between 1 and {max} pixels"
        ));
    }
    let (width, height) = (width as u32, height as u32);
    if !(focal.iter().all(|f| f.is_finite() && *f > 0.0) && principal.iter().all(|c| c.is_finite()))
    {
        return Err(format!(
            "camera {id} has non-finite or non-positive intrinsics (focal {focal:?}, principal point {principal:?})"
        ));
    }
    Ok(Intrinsics {
        width,
        height,
        fx: focal[0],
        fy: focal[1],
        cx: principal[0],
        cy: principal[1],
        distortion,
    })
}

/// Cameras of the registered images, sorted by name (then id): with their lens, or when
/// `distorted` as pinhole cameras with their distortion beside them.
fn assemble(
    mut images: Vec<Image>,
    intrinsics: &HashMap<u64, Intrinsics>,
    images_path: &Path,
    distorted: bool,
) -> Result<Vec<LensCamera>, CameraError> {
    images.sort_by(|a, b| a.name.cmp(&b.name).then(a.id.cmp(&b.id)));
    let mut cams = Vec::with_capacity(images.len());
    for im in images {
        let bad = |what: String| {
            invalid(
                images_path,
                format!("image {} (\"{}\"): {what}", im.id, im.name),
            )
        };
        let k = intrinsics.get(&im.camera_id).ok_or_else(|| {
            bad(format!(
                "refers to camera {}, which the cameras file does not have",
                im.camera_id
            ))
        })?;
        let rotation = quat_wxyz_to_mat(im.qvec).ok_or_else(|| {
            bad(format!(
                "quaternion {:?} has zero length or is not finite",
                im.qvec
            ))
        })?;
        let t = glam::DVec3::from_array(im.tvec);
        if !t.is_finite() {
            return Err(bad(format!("translation {:?} is not finite", im.tvec)));
        }
        let cam = Camera {
            name: im.name.clone(),
            width: k.width,
            height: k.height,
            fx: k.fx as f32,
            fy: k.fy as f32,
            cx: k.cx as f32,
            cy: k.cy as f32,
            rotation: rotation.as_mat3(),
            translation: t.as_vec3(),
            lens: match (&k.distortion, distorted) {
                (Some(d), false) => Lens::from_distortion(d),
                _ => Lens::Pinhole,
            },
        };
        cam.validate().map_err(|e| bad(e.to_string()))?;
        cams.push((cam, k.distortion.clone().filter(|_| distorted)));
    }
    Ok(cams)
}

/// Little-endian reader over a COLMAP binary file; every read names what it wanted.
struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    fn new(data: &'a [u8], path: &'a Path) -> Self {
        Reader { data, pos: 0, path }
    }

    fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], CameraError> {
        if self.remaining() < n {
            return Err(invalid(
                self.path,
                format!(
                    "truncated: needs {n} bytes for the {what} at byte {} but the file has {} bytes",
                    self.pos,
                    self.data.len()
                ),
            ));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn skip(&mut self, n: usize) {
        self.pos = (self.pos + n).min(self.data.len());
    }

    fn u32(&mut self, what: &str) -> Result<u32, CameraError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&mut self, what: &str) -> Result<u64, CameraError> {
        let mut a = [0u8; 8];
        a.copy_from_slice(self.take(8, what)?);
        Ok(u64::from_le_bytes(a))
    }

    fn f64(&mut self, what: &str) -> Result<f64, CameraError> {
        Ok(f64::from_bits(self.u64(what)?))
    }

    /// A u64 record count, refused when the remaining bytes cannot hold that many
    /// records of at least `min_record` bytes each.
    fn count(&mut self, what: &str, min_record: usize) -> Result<usize, CameraError> {
        let n = self.u64(&format!("number of {what}"))?;
        let fits = (self.remaining() / min_record) as u64;
        if n > fits {
            return Err(invalid(
                self.path,
                format!(
                    "claims {n} {what} but only {} bytes follow (room for at most {fits}): the file is truncated or not a COLMAP model",
                    self.remaining()
                ),
            ));
        }
        Ok(n as usize)
    }

    fn cstring(&mut self, what: &str) -> Result<String, CameraError> {
        let rest = &self.data[self.pos..];
        let end = rest.iter().position(|&b| b == 0).ok_or_else(|| {
            invalid(
                self.path,
                format!(
                    "truncated: the {what} at byte {} has no terminating NUL",
                    self.pos
                ),
            )
        })?;
        let s = String::from_utf8_lossy(&rest[..end]).into_owned();
        self.pos += end + 1;
        Ok(s)
    }

    fn finish(&self) -> Result<(), CameraError> {
        if self.remaining() != 0 {
            return Err(invalid(
                self.path,
                format!(
                    "has {} unexpected bytes after the last record (at byte {}): not a COLMAP model or corrupt",
                    self.remaining(),
                    self.pos
                ),
            ));
        }
        Ok(())
    }
}

/// A point of a COLMAP model's `points3D`: position and colour (0-255).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point3D {
    /// World position.
    pub position: [f64; 3],
    /// RGB.
    pub color: [u8; 3],
}

/// The `points3D` of the COLMAP model under `dir` (text or binary, beside the cameras
/// [`find_model`] finds); `None` when the model has no points file.
pub fn load_colmap_points(dir: &Path) -> Result<Option<Vec<Point3D>>, CameraError> {
    let (model_dir, format) = find_model(dir)?;
    let binary = format == CameraFormat::ColmapBinary;
    let path = model_dir.join(if binary {
        "points3D.bin"
    } else {
        "points3D.txt"
    });
    if !path.is_file() {
        return Ok(None);
    }
    let bytes = std::fs::read(&path).map_err(|source| {
        CameraError::File(FileError::Io {
            path: path.clone(),
            source,
        })
    })?;
    let points = if binary {
        parse_points_binary(&bytes, &path)?
    } else {
        let text =
            String::from_utf8(bytes).map_err(|_| invalid(&path, "is not UTF-8 text".into()))?;
        parse_points_text(&text, &path)?
    };
    Ok(Some(points))
}

/// Parses `points3D.txt`: `POINT3D_ID X Y Z R G B ERROR TRACK[]` per line.
pub fn parse_points_text(text: &str, path: &Path) -> Result<Vec<Point3D>, CameraError> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        let bad = |what: &str| invalid(path, format!("line {}: {what}", n + 1));
        if f.len() < 8 {
            return Err(bad("a point needs ID X Y Z R G B ERROR"));
        }
        let num = |s: &str| -> Result<f64, CameraError> {
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| bad(&format!("{s:?} is not a finite number")))
        };
        let byte = |s: &str| -> Result<u8, CameraError> {
            s.parse::<u8>()
                .map_err(|_| bad(&format!("{s:?} is not a colour value 0-255")))
        };
        out.push(Point3D {
            position: [num(f[1])?, num(f[2])?, num(f[3])?],
            color: [byte(f[4])?, byte(f[5])?, byte(f[6])?],
        });
    }
    Ok(out)
}

/// Parses `points3D.bin` (COLMAP's `write_points3D_binary`).
pub fn parse_points_binary(bytes: &[u8], path: &Path) -> Result<Vec<Point3D>, CameraError> {
    let short = || invalid(path, "ends early: the file is truncated".into());
    let mut at = 0usize;
    let mut take = |n: usize| -> Result<&[u8], CameraError> {
        let s = bytes.get(at..at + n).ok_or_else(short)?;
        at += n;
        Ok(s)
    };
    let u64_of = |b: &[u8]| u64::from_le_bytes(b.try_into().expect("8 bytes"));
    let f64_of = |b: &[u8]| f64::from_le_bytes(b.try_into().expect("8 bytes"));
    let count = u64_of(take(8)?);
    if count > (bytes.len() / 43) as u64 {
        return Err(invalid(
            path,
            format!("says it holds {count} points, more than its size allows"),
        ));
    }
    let mut out = Vec::with_capacity(count as usize);
    for _ in 0..count {
        let _id = take(8)?;
        let p = [f64_of(take(8)?), f64_of(take(8)?), f64_of(take(8)?)];
        let c = take(3)?;
        let _error = take(8)?;
        let track = u64_of(take(8)?);
        let track_bytes = usize::try_from(track)
            .ok()
            .and_then(|t| t.checked_mul(8))
            .ok_or_else(short)?;
        take(track_bytes)?;
        if p.iter().any(|v| !v.is_finite()) {
            return Err(invalid(path, "holds a point that is not finite".into()));
        }
        out.push(Point3D {
            position: p,
            color: [c[0], c[1], c[2]],
        });
    }
    Ok(out)
}

/// The COLMAP camera model that holds `cam`'s lens, and the model's parameters: `PINHOLE`
/// (`fx, fy, cx, cy`), `OPENCV` (`..., k1, k2, p1, p2`) for a Brown-Conrady lens with
/// radial `k1`, `k2` only, `FULL_OPENCV` (`..., k1, k2, p1, p2, k3, k4, k5, k6`) for the
/// others, `OPENCV_FISHEYE` (`..., k1, k2, k3, k4`) for a fisheye (COLMAP has no field of
/// view: read back, it images every ray its polynomial can). COLMAP has no orthographic or
/// equirectangular model: those are refused, naming the camera.
pub fn colmap_model(cam: &Camera) -> Result<(&'static str, Vec<f64>), String> {
    let mut p: Vec<f64> = [cam.fx, cam.fy, cam.cx, cam.cy]
        .iter()
        .map(|&v| f64::from(v))
        .collect();
    let name = match &cam.lens {
        Lens::Pinhole => "PINHOLE",
        Lens::RadialTangential { radial, tangential } => {
            p.extend([radial[0], radial[1], tangential[0], tangential[1]]);
            if radial[2..].iter().all(|&k| k == 0.0) {
                "OPENCV"
            } else {
                p.extend(&radial[2..]);
                "FULL_OPENCV"
            }
        }
        Lens::Fisheye { k, .. } => {
            p.extend(k);
            "OPENCV_FISHEYE"
        }
        other => {
            return Err(format!(
                "camera \"{}\" has an {} lens, which COLMAP has no camera model for (it has \
                 PINHOLE, OPENCV, FULL_OPENCV and OPENCV_FISHEYE)",
                cam.name,
                other.name()
            ))
        }
    };
    Ok((name, p))
}

/// A COLMAP text model of `cameras` (one camera each, of the model [`colmap_model`] gives
/// its lens; images named by the cameras' names) and `points`: `cameras.txt`,
/// `images.txt`, `points3D.txt`, what [`load_colmap_model`] and [`load_colmap_points`] read
/// back. A lens COLMAP has no model for is refused.
pub fn to_text_model(
    cameras: &[Camera],
    points: &[Point3D],
) -> Result<[(String, String); 3], CameraError> {
    use std::fmt::Write;
    let mut cams = String::from("# Camera list: CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    let mut images = String::from(
        "# Image list: IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME, then POINTS2D[]\n",
    );
    for (i, c) in cameras.iter().enumerate() {
        let (model, params) = colmap_model(c).map_err(CameraError::BadParameter)?;
        let _ = write!(cams, "{} {model} {} {}", i + 1, c.width, c.height);
        for (j, v) in params.into_iter().enumerate() {
            // The intrinsics are the camera's f32 values, written as such.
            if j < 4 {
                let _ = write!(cams, " {}", v as f32);
            } else {
                let _ = write!(cams, " {v}");
            }
        }
        cams.push('\n');
        let q = glam::DQuat::from_mat3(&c.rotation.as_dmat3()).normalize();
        let t = c.translation;
        let _ = writeln!(
            images,
            "{} {} {} {} {} {} {} {} {} {}\n",
            i + 1,
            q.w,
            q.x,
            q.y,
            q.z,
            t.x,
            t.y,
            t.z,
            i + 1,
            c.name
        );
    }
    let mut pts = String::from("# 3D point list: POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[]\n");
    for (i, p) in points.iter().enumerate() {
        let _ = writeln!(
            pts,
            "{} {} {} {} {} {} {} 0",
            i + 1,
            p.position[0],
            p.position[1],
            p.position[2],
            p.color[0],
            p.color[1],
            p.color[2]
        );
    }
    Ok([
        ("cameras.txt".into(), cams),
        ("images.txt".into(), images),
        ("points3D.txt".into(), pts),
    ])
}
