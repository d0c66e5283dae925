//! Camera lenses: the exact map from a point in camera space (OpenCV axes: x right, y
//! down, z forward) to its pixel, and back from a pixel to the ray through it, for every
//! lens verisplat knows. One place for every consumer: the renderers' projection of
//! Gaussians through a lens, the photos a data set trains on, and the camera files that
//! name a model.
//!
//! | lens | pixel of a camera-space point `(x, y, z)` |
//! |---|---|
//! | [`Lens::Pinhole`] | `(fx x / z + cx, fy y / z + cy)`, `z > 0` |
//! | [`Lens::RadialTangential`] | the pinhole coordinates `(x / z, y / z)` distorted by Brown-Conrady (COLMAP `SIMPLE_RADIAL`, `RADIAL`, `OPENCV`, `FULL_OPENCV`), `z > 0` |
//! | [`Lens::Fisheye`] | equidistant: at angle `theta` from the axis, radius `theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)` (COLMAP `OPENCV_FISHEYE`, `SIMPLE_RADIAL_FISHEYE`, `RADIAL_FISHEYE`), `theta <=` half the field of view, which may pass 90 degrees |
//! | [`Lens::Orthographic`] | `(fx x + cx, fy y + cy)`: `fx`, `fy` in pixels per world unit, `z > 0` |
//! | [`Lens::Equirectangular`] | longitude `atan2(x, z)` and latitude `atan2(-y, hypot(x, z))` spread linearly over a window of the sphere (the whole sphere by default; a window may cross the seam behind the camera) |
//!
//! The inverse of a distorted lens is found by Newton's method, as COLMAP undistorts; a
//! pixel with no ray (outside a fisheye's image circle, outside the equirectangular
//! window) has none.

use super::distortion::{
    brown_conrady, equidistant, equidistant_slope, invert_brown_conrady, Distortion,
};
use glam::{DVec2, DVec3};
use std::f64::consts::{FRAC_PI_2, PI};

/// A lens: how a camera maps rays to pixels, beside its focal lengths and principal point
/// ([`Intrinsics`]).
///
/// In a `cameras.json` entry (`inria`) a lens is an object tagged by its
/// [`name`](Lens::name) (`{"kind": "fisheye", "k": [...], "max_theta": ...}`), unknown keys
/// refused.
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Lens {
    /// The ideal pinhole.
    Pinhole,
    /// A pinhole with Brown-Conrady distortion: radial `k1..k6` (the rational factor
    /// `(1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)`) and tangential
    /// `p1, p2`, as COLMAP's and OpenCV's `OPENCV` and `FULL_OPENCV` models.
    #[serde(rename = "distorted")]
    RadialTangential {
        /// `k1..k6`.
        radial: [f64; 6],
        /// `p1, p2`.
        tangential: [f64; 2],
    },
    /// The equidistant fisheye (`OPENCV_FISHEYE`): a ray at angle `theta` from the axis
    /// lands at normalised radius `theta (1 + k1 theta^2 + ... + k4 theta^8)`.
    Fisheye {
        /// `k1..k4`.
        k: [f64; 4],
        /// Half the field of view, in radians: rays further from the axis are not imaged
        /// (at most `PI`; a 190-degree lens has 95 degrees).
        max_theta: f64,
    },
    /// Orthographic: parallel rays along the axis; `fx`, `fy` are pixels per world unit.
    Orthographic,
    /// Equirectangular: longitude (around the camera's y axis, 0 straight ahead, positive
    /// to the right) across the width and latitude (0 at the horizon, positive up) down
    /// the height, each over a window in radians.
    Equirectangular {
        /// Longitudes of the left and right image edges (`[-PI, PI]`: the whole circle).
        longitude: [f64; 2],
        /// Latitudes of the top and bottom image edges (`[PI / 2, -PI / 2]`: pole to
        /// pole).
        latitude: [f64; 2],
    },
}

/// A camera's focal lengths and principal point in pixels, and its image size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal length along x, in pixels (orthographic: pixels per world unit).
    pub fx: f64,
    /// Focal length along y.
    pub fy: f64,
    /// Principal point x, in pixels.
    pub cx: f64,
    /// Principal point y, in pixels.
    pub cy: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

/// A ray in camera space: every point `origin + t * direction`, `t > 0`, lands on the
/// pixel it was cast through. `direction` has unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Where the ray starts: the centre of projection, or for an orthographic lens the
    /// point of the plane `z = 0` under the pixel.
    pub origin: DVec3,
    /// The unit direction.
    pub direction: DVec3,
}

impl Lens {
    /// The whole sphere as an equirectangular image.
    pub const FULL_SPHERE: Lens = Lens::Equirectangular {
        longitude: [-PI, PI],
        latitude: [FRAC_PI_2, -FRAC_PI_2],
    };

    /// The lens of a data set's or camera file's distortion model.
    pub fn from_distortion(d: &Distortion) -> Lens {
        if d.fisheye {
            let k = [d.radial[0], d.radial[1], d.radial[2], d.radial[3]];
            Lens::Fisheye {
                k,
                max_theta: fisheye_max_theta(&k),
            }
        } else if d.is_pinhole() {
            Lens::Pinhole
        } else {
            Lens::RadialTangential {
                radial: d.radial,
                tangential: d.tangential,
            }
        }
    }

    /// The lens's kind in words, for messages: `pinhole`, `distorted`, `fisheye`,
    /// `orthographic` or `equirectangular`.
    pub fn name(&self) -> &'static str {
        match self {
            Lens::Pinhole => "pinhole",
            Lens::RadialTangential { .. } => "distorted",
            Lens::Fisheye { .. } => "fisheye",
            Lens::Orthographic => "orthographic",
            Lens::Equirectangular { .. } => "equirectangular",
        }
    }

    /// Why the lens's parameters cannot be used, if they cannot: a coefficient that is
    /// not finite, a fisheye's field of view outside `(0, 360]` degrees, or an
    /// equirectangular window that is empty, wider than a turn, or past a pole.
    pub fn check(&self) -> Result<(), String> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        match self {
            Lens::Pinhole | Lens::Orthographic => Ok(()),
            Lens::RadialTangential { radial, tangential } => {
                if finite(radial) && finite(tangential) {
                    Ok(())
                } else {
                    Err("a distortion coefficient is not finite".into())
                }
            }
            Lens::Fisheye { k, max_theta } => {
                if !finite(k) {
                    Err("a fisheye coefficient is not finite".into())
                } else if !(*max_theta > 0.0 && *max_theta <= PI) {
                    Err(format!(
                        "a fisheye's field of view must be above 0 and at most 360 degrees, not {}",
                        2.0 * max_theta.to_degrees()
                    ))
                } else {
                    Ok(())
                }
            }
            Lens::Equirectangular {
                longitude,
                latitude,
            } => {
                let span = (longitude[1] - longitude[0]).abs();
                let poles = latitude.iter().all(|l| l.abs() <= FRAC_PI_2 + 1e-12);
                if !(finite(longitude) && finite(latitude)) {
                    Err("an equirectangular window is not finite".into())
                } else if span == 0.0 || span > 2.0 * PI + 1e-12 {
                    Err(format!(
                        "an equirectangular window spans {} degrees of longitude; it must be above 0 and at most 360",
                        span.to_degrees()
                    ))
                } else if latitude[0] == latitude[1] || !poles {
                    Err(format!(
                        "an equirectangular window's latitudes ({} and {} degrees) must differ and lie within 90 degrees of the horizon",
                        latitude[0].to_degrees(),
                        latitude[1].to_degrees()
                    ))
                } else {
                    Ok(())
                }
            }
        }
    }

    /// The lens as the shaders take it (`FrameParams`): its `LENS_*` constant, its
    /// coefficients `lens_a`, `lens_b`, and for a distorted lens the squared radius of
    /// its fold ([`radial_fold`]; `f32::MAX` for none), in f32.
    pub fn shader_params(&self) -> (u32, [f32; 4], [f32; 4], f32) {
        use crate::core::shader_interface as si;
        let f = |v: &[f64]| -> [f32; 4] {
            std::array::from_fn(|i| v.get(i).map_or(0.0, |x| *x as f32))
        };
        match self {
            Lens::Pinhole => (si::LENS_PINHOLE, [0.0; 4], [0.0; 4], 0.0),
            Lens::RadialTangential { radial, tangential } => (
                si::LENS_RADIAL_TANGENTIAL,
                f(&radial[..4]),
                f(&[radial[4], radial[5], tangential[0], tangential[1]]),
                radial_fold(radial, f64::INFINITY).map_or(f32::MAX, |r| (r * r) as f32),
            ),
            Lens::Fisheye { k, max_theta } => (si::LENS_FISHEYE, f(k), f(&[*max_theta]), 0.0),
            Lens::Orthographic => (si::LENS_ORTHOGRAPHIC, [0.0; 4], [0.0; 4], 0.0),
            Lens::Equirectangular {
                longitude,
                latitude,
            } => (
                si::LENS_EQUIRECTANGULAR,
                f(&[longitude[0], longitude[1], latitude[0], latitude[1]]),
                [0.0; 4],
                0.0,
            ),
        }
    }

    /// Whether an image through this lens wraps around: a full turn of longitude, whose
    /// left edge continues its right one. The renderers then draw a Gaussian across the
    /// seam on both sides, at any width
    /// ([`Rules::wrapped_extent`](crate::core::model::Rules::wrapped_extent)).
    pub fn wraps(&self) -> bool {
        match self {
            Lens::Equirectangular { longitude, .. } => {
                (longitude[1] - longitude[0]).abs() == 2.0 * PI
            }
            _ => false,
        }
    }

    /// Whether this is the ideal pinhole (the renderers' EWA projection applies).
    pub fn is_pinhole(&self) -> bool {
        matches!(self, Lens::Pinhole)
    }

    /// The pixel of camera-space point `p`, or `None` where the lens does not image it
    /// (behind the camera, beyond a fisheye's field of view, at the centre of projection).
    /// A point the lens images outside the picture has its pixel outside the image, as a
    /// pinhole's; an equirectangular window's longitude is taken on the turn nearest the
    /// window's middle.
    pub fn project(&self, k: &Intrinsics, p: DVec3) -> Option<DVec2> {
        let pixel = |u: f64, v: f64| DVec2::new(k.fx * u + k.cx, k.fy * v + k.cy);
        match self {
            Lens::Pinhole => (p.z > 0.0).then(|| pixel(p.x / p.z, p.y / p.z)),
            Lens::RadialTangential { radial, tangential } => {
                if p.z <= 0.0 {
                    return None;
                }
                let (x, y) = (p.x / p.z, p.y / p.z);
                if radial_fold(radial, x.hypot(y)).is_some() {
                    return None;
                }
                let (u, v) = brown_conrady(radial, tangential, x, y);
                Some(pixel(u, v))
            }
            Lens::Fisheye { k: c, max_theta } => {
                let r = p.x.hypot(p.y);
                let theta = r.atan2(p.z);
                if theta > *max_theta || p.length_squared() == 0.0 {
                    return None;
                }
                if r == 0.0 {
                    return Some(pixel(0.0, 0.0));
                }
                let s = equidistant(c, theta) / r;
                Some(pixel(p.x * s, p.y * s))
            }
            Lens::Orthographic => (p.z > 0.0).then(|| pixel(p.x, p.y)),
            Lens::Equirectangular {
                longitude,
                latitude,
            } => {
                if p.length_squared() == 0.0 {
                    return None;
                }
                // The longitude's turn nearest the window's middle, so that a window across
                // the seam behind the camera is continuous.
                let middle = 0.5 * (longitude[0] + longitude[1]);
                let lon = middle + wrap_angle(p.x.atan2(p.z) - middle);
                let lat = (-p.y).atan2(p.x.hypot(p.z));
                let u = (lon - longitude[0]) / (longitude[1] - longitude[0]);
                let v = (lat - latitude[0]) / (latitude[1] - latitude[0]);
                Some(DVec2::new(u * k.width as f64, v * k.height as f64))
            }
        }
    }

    /// The Jacobian of [`Self::project`] at `p`: the derivatives of the pixel along x, y
    /// and z of the camera-space point (the columns), where the lens images `p`; for the
    /// backward pass through the unscented transform's sigma points.
    pub fn jacobian(&self, k: &Intrinsics, p: DVec3) -> Option<[DVec2; 3]> {
        self.project(k, p)?;
        let f = DVec2::new(k.fx, k.fy);
        let cols = |d: [[f64; 3]; 2]| -> [DVec2; 3] {
            std::array::from_fn(|i| DVec2::new(d[0][i], d[1][i]))
        };
        Some(match self {
            Lens::Pinhole | Lens::RadialTangential { .. } => {
                let (x, y, z) = (p.x / p.z, p.y / p.z, p.z);
                // d(x / z, y / z) / d(x, y, z).
                let dn = [[1.0 / z, 0.0, -x / z], [0.0, 1.0 / z, -y / z]];
                let m = match self {
                    Lens::RadialTangential { radial, tangential } => {
                        brown_conrady_jacobian(radial, tangential, x, y)
                    }
                    _ => [[1.0, 0.0], [0.0, 1.0]],
                };
                let mut d = [[0.0; 3]; 2];
                for (r, row) in d.iter_mut().enumerate() {
                    for (c, v) in row.iter_mut().enumerate() {
                        *v = f[r] * (m[r][0] * dn[0][c] + m[r][1] * dn[1][c]);
                    }
                }
                cols(d)
            }
            Lens::Orthographic => cols([[k.fx, 0.0, 0.0], [0.0, k.fy, 0.0]]),
            Lens::Fisheye { k: c, .. } => {
                let r = p.x.hypot(p.y);
                if r == 0.0 {
                    // On the axis: theta = r / z to first order, and g'(0) = 1.
                    let z = p.z;
                    return Some(cols([[k.fx / z, 0.0, 0.0], [0.0, k.fy / z, 0.0]]));
                }
                let rho2 = r * r + p.z * p.z;
                let theta = r.atan2(p.z);
                let g = equidistant(c, theta);
                let dg = equidistant_slope(c, theta);
                // theta's derivatives along x, y, z; then s = g / r's.
                let dtheta = [p.z * p.x / (r * rho2), p.z * p.y / (r * rho2), -r / rho2];
                let dr = [p.x / r, p.y / r, 0.0];
                let s = g / r;
                let ds: [f64; 3] =
                    std::array::from_fn(|i| (dg * dtheta[i] * r - g * dr[i]) / (r * r));
                // pixel = f (x s, y s) + c.
                let mut d = [[0.0; 3]; 2];
                for (row, (q, fq)) in [(p.x, k.fx), (p.y, k.fy)].into_iter().enumerate() {
                    for (i, v) in d[row].iter_mut().enumerate() {
                        let own = if i == row { s } else { 0.0 };
                        *v = fq * (own + q * ds[i]);
                    }
                }
                cols(d)
            }
            Lens::Equirectangular {
                longitude,
                latitude,
            } => {
                let xz = p.x * p.x + p.z * p.z;
                let h = xz.sqrt();
                let l2 = p.y * p.y + xz;
                let dlon = [p.z / xz, 0.0, -p.x / xz];
                // lat = atan2(-y, h): d/dy = -h / l2, d/dh = y / l2, dh = (x, z) / h.
                let dlat = [p.y / l2 * p.x / h, -h / l2, p.y / l2 * p.z / h];
                let su = k.width as f64 / (longitude[1] - longitude[0]);
                let sv = k.height as f64 / (latitude[1] - latitude[0]);
                cols([dlon.map(|v| su * v), dlat.map(|v| sv * v)])
            }
        })
    }

    /// The ray through pixel position `px` (pixel centres at `i + 0.5`), or `None` where
    /// no ray lands there (outside a fisheye's image circle, past the poles or half a
    /// turn from the middle of an equirectangular window, or where the distortion cannot
    /// be inverted).
    pub fn unproject(&self, k: &Intrinsics, px: DVec2) -> Option<Ray> {
        let u = (px.x - k.cx) / k.fx;
        let v = (px.y - k.cy) / k.fy;
        let through = |d: DVec3| Ray {
            origin: DVec3::ZERO,
            direction: d.normalize(),
        };
        match self {
            Lens::Pinhole => Some(through(DVec3::new(u, v, 1.0))),
            Lens::RadialTangential { radial, tangential } => {
                let (x, y) = invert_brown_conrady(radial, tangential, u, v)?;
                Some(through(DVec3::new(x, y, 1.0)))
            }
            Lens::Fisheye { k: c, max_theta } => {
                let rd = u.hypot(v);
                if rd == 0.0 {
                    return Some(through(DVec3::Z));
                }
                let theta = invert_equidistant(c, rd, *max_theta)?;
                let s = theta.sin() / rd;
                Some(Ray {
                    origin: DVec3::ZERO,
                    direction: DVec3::new(u * s, v * s, theta.cos()),
                })
            }
            Lens::Orthographic => Some(Ray {
                origin: DVec3::new(u, v, 0.0),
                direction: DVec3::Z,
            }),
            Lens::Equirectangular {
                longitude,
                latitude,
            } => {
                let a = px.x / k.width as f64;
                let b = px.y / k.height as f64;
                let lon = longitude[0] + a * (longitude[1] - longitude[0]);
                let lat = latitude[0] + b * (latitude[1] - latitude[0]);
                if lat.abs() > FRAC_PI_2 || (lon - 0.5 * (longitude[0] + longitude[1])).abs() > PI {
                    return None;
                }
                Some(Ray {
                    origin: DVec3::ZERO,
                    direction: DVec3::new(lat.cos() * lon.sin(), -lat.sin(), lat.cos() * lon.cos()),
                })
            }
        }
    }
}

/// A lens for generated cameras (orbits, `--look-at`, the default camera), as the
/// command line's `--lens` names it:
///
/// - `pinhole` (the default);
/// - `fisheye[:fov=DEG]`: the equidistant fisheye without distortion, its field of view
///   (default 180, at most 360) filling the image's shorter side;
/// - `equirect[:lon=A..B][,lat=C..D]`: a window of longitudes (default -180..180) and
///   latitudes (default 90..-90, top to bottom) in degrees; the whole sphere by default;
/// - `ortho[:width=W]`: orthographic, `W` world units across the image (default: what
///   the pinhole of `--vfov` shows across at the distance of the scene's centre).
#[derive(Clone, Debug, PartialEq)]
pub enum LensSpec {
    /// The pinhole of `--vfov`.
    Pinhole,
    /// An equidistant fisheye with this full field of view, in degrees.
    Fisheye {
        /// The full field of view across the shorter side, degrees.
        fov_deg: f64,
    },
    /// An equirectangular window, in degrees.
    Equirect {
        /// Left and right edges' longitudes.
        lon_deg: [f64; 2],
        /// Top and bottom edges' latitudes.
        lat_deg: [f64; 2],
    },
    /// Orthographic, with the world units across the image if given.
    Ortho {
        /// World units across the image's width.
        width: Option<f64>,
    },
}

impl std::str::FromStr for LensSpec {
    type Err = String;

    fn from_str(text: &str) -> Result<LensSpec, String> {
        let (kind, rest) = text.split_once(':').unwrap_or((text, ""));
        let mut options = std::collections::BTreeMap::new();
        for part in rest.split(',').filter(|p| !p.is_empty()) {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| format!("'{part}' in --lens {text} is not KEY=VALUE"))?;
            options.insert(k.trim().to_string(), v.trim().to_string());
        }
        let number = |v: &str| -> Result<f64, String> {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("'{v}' in --lens {text} is not a number"))
        };
        let range = |v: &str| -> Result<[f64; 2], String> {
            let (a, b) = v
                .split_once("..")
                .ok_or_else(|| format!("'{v}' in --lens {text} is not a range A..B"))?;
            Ok([number(a)?, number(b)?])
        };
        let allow = |keys: &[&str]| -> Result<(), String> {
            match options.keys().find(|k| !keys.contains(&k.as_str())) {
                Some(k) if keys.is_empty() => {
                    Err(format!("--lens {kind} takes no options ('{k}')"))
                }
                Some(k) => Err(format!(
                    "--lens {kind} has no option '{k}' (it takes {})",
                    keys.join(", ")
                )),
                None => Ok(()),
            }
        };
        let spec = match kind {
            "pinhole" => {
                allow(&[])?;
                LensSpec::Pinhole
            }
            "fisheye" => {
                allow(&["fov"])?;
                let fov_deg = options.get("fov").map_or(Ok(180.0), |v| number(v))?;
                if !(fov_deg > 0.0 && fov_deg <= 360.0) {
                    return Err(format!(
                        "--lens {text}: a fisheye's field of view must be above 0 and at most 360 degrees"
                    ));
                }
                LensSpec::Fisheye { fov_deg }
            }
            "equirect" | "equirectangular" => {
                allow(&["lon", "lat"])?;
                let lon_deg = options.get("lon").map_or(Ok([-180.0, 180.0]), |v| range(v))?;
                let lat_deg = options.get("lat").map_or(Ok([90.0, -90.0]), |v| range(v))?;
                LensSpec::Equirect { lon_deg, lat_deg }
            }
            "ortho" | "orthographic" => {
                allow(&["width"])?;
                let width = options.get("width").map(|v| number(v)).transpose()?;
                if width.is_some_and(|w| w <= 0.0) {
                    return Err(format!("--lens {text}: the width must be positive"));
                }
                LensSpec::Ortho { width }
            }
            other => {
                return Err(format!(
                    "--lens '{other}' is not a lens (pinhole, fisheye[:fov=DEG], equirect[:lon=A..B,lat=C..D], ortho[:width=W])"
                ))
            }
        };
        spec.lens()
            .check()
            .map_err(|e| format!("--lens {text}: {e}"))?;
        Ok(spec)
    }
}

impl LensSpec {
    /// The lens, focal lengths and principal point it gives a `width` x `height` camera
    /// whose pinhole would have focal length `f` (pixels), `distance` from what it looks
    /// at: `(lens, fx, fy, cx, cy)`.
    pub fn apply(
        &self,
        width: u32,
        height: u32,
        f: f64,
        distance: f64,
    ) -> (Lens, f64, f64, f64, f64) {
        let (cx, cy) = (width as f64 / 2.0, height as f64 / 2.0);
        let lens = self.lens();
        let (fx, fy) = match self {
            LensSpec::Pinhole | LensSpec::Equirect { .. } => (f, f),
            LensSpec::Fisheye { fov_deg } => {
                let fx = width.min(height) as f64 / 2.0 / (fov_deg / 2.0).to_radians();
                (fx, fx)
            }
            LensSpec::Ortho { width: units } => {
                // What the pinhole shows across at `distance`: width / f units.
                let across = units.unwrap_or(width as f64 * distance / f);
                let fx = width as f64 / across;
                (fx, fx)
            }
        };
        (lens, fx, fy, cx, cy)
    }

    /// The size of a generated camera through this lens when neither side is given:
    /// 1280 pixels across, and 720 high but for an equirectangular window, whose pixels
    /// are square in angle (width : height = its longitudes : its latitudes, so 1280x640
    /// for the whole sphere). One side given, the other follows the same ratio.
    pub fn default_size(&self) -> (u32, u32) {
        match self {
            LensSpec::Equirect { lon_deg, lat_deg } => {
                let ratio = (lat_deg[1] - lat_deg[0]).abs() / (lon_deg[1] - lon_deg[0]).abs();
                (1280, ((1280.0 * ratio).round() as u32).max(1))
            }
            _ => (1280, 720),
        }
    }

    /// The lens itself.
    pub fn lens(&self) -> Lens {
        match self {
            LensSpec::Pinhole => Lens::Pinhole,
            LensSpec::Fisheye { fov_deg } => Lens::Fisheye {
                k: [0.0; 4],
                max_theta: (fov_deg / 2.0).to_radians(),
            },
            LensSpec::Equirect { lon_deg, lat_deg } => Lens::Equirectangular {
                longitude: lon_deg.map(f64::to_radians),
                latitude: lat_deg.map(f64::to_radians),
            },
            LensSpec::Ortho { .. } => Lens::Orthographic,
        }
    }
}

/// `a` turned into `(-PI, PI]`.
/// The Jacobian of [`brown_conrady`] at `(x, y)`: rows the distorted x and y, columns
/// the derivatives along x and y.
pub fn brown_conrady_jacobian(
    radial: &[f64; 6],
    tangential: &[f64; 2],
    x: f64,
    y: f64,
) -> [[f64; 2]; 2] {
    let k = radial;
    let [p1, p2] = *tangential;
    let q = x * x + y * y;
    let n = 1.0 + q * (k[0] + q * (k[1] + q * k[2]));
    let d = 1.0 + q * (k[3] + q * (k[4] + q * k[5]));
    let dn = k[0] + q * (2.0 * k[1] + q * 3.0 * k[2]);
    let dd = k[3] + q * (2.0 * k[4] + q * 3.0 * k[5]);
    let r = n / d;
    // dR / d(r^2).
    let dr = (dn * d - n * dd) / (d * d);
    [
        [
            r + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x,
            2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y,
        ],
        [
            2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y,
            r + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x,
        ],
    ]
}

/// Where Brown-Conrady's radial factor folds the image back: the first radius `r` (of
/// the pinhole coordinates `(x / z, y / z)`), on a grid of `1 / 64` out to `r = 64`
/// (89 degrees), at or below `up_to` where `r R(r^2)` stops growing or the rational
/// factor's denominator stops being positive; `None` where there is none. A lens images
/// no point at or past its fold (the polynomial sends those points back inside the
/// picture, where the real lens does not put them): points further out than the lens
/// sees. The grid makes the CPU's test of one point (scan to its radius) and the GPU's
/// (compare with the fold found once) the same test.
pub fn radial_fold(radial: &[f64; 6], up_to: f64) -> Option<f64> {
    const STEP: f64 = 1.0 / 64.0;
    const STEPS: u32 = 64 * 64;
    let k = radial;
    (1..=STEPS)
        .map(|i| i as f64 * STEP)
        .take_while(|&r| r <= up_to)
        .find(|&r| {
            let q = r * r;
            let n = 1.0 + q * (k[0] + q * (k[1] + q * k[2]));
            let d = 1.0 + q * (k[3] + q * (k[4] + q * k[5]));
            let dn = k[0] + q * (2.0 * k[1] + q * 3.0 * k[2]);
            let dd = k[3] + q * (2.0 * k[4] + q * 3.0 * k[5]);
            // d/dr (r n / d) = (n d + 2 q (n' d - n d')) / d^2: the sign of its numerator.
            d <= 0.0 || n * d + 2.0 * q * (dn * d - n * dd) <= 0.0
        })
}

fn wrap_angle(a: f64) -> f64 {
    let t = a.rem_euclid(2.0 * PI);
    if t > PI {
        t - 2.0 * PI
    } else {
        t
    }
}

/// The largest angle (at most `PI`) up to which the fisheye's radius grows with the angle:
/// past it two rays would share a pixel, so the lens images no ray beyond it.
pub fn fisheye_max_theta(k: &[f64; 4]) -> f64 {
    const STEPS: usize = 4096;
    let mut last = 0.0;
    for i in 1..=STEPS {
        let theta = PI * i as f64 / STEPS as f64;
        if equidistant_slope(k, theta) <= 0.0 {
            return last;
        }
        last = theta;
    }
    PI
}

/// The angle whose equidistant radius is `rd`, by Newton's method from `rd`, within
/// `[0, max_theta]`.
fn invert_equidistant(k: &[f64; 4], rd: f64, max_theta: f64) -> Option<f64> {
    let mut t = rd.min(max_theta);
    for _ in 0..100 {
        let step = (equidistant(k, t) - rd) / equidistant_slope(k, t);
        if !step.is_finite() {
            return None;
        }
        t = (t - step).clamp(0.0, max_theta);
        if step.abs() < 1e-15 * (1.0 + t) {
            break;
        }
    }
    ((equidistant(k, t) - rd).abs() <= 1e-10 * (1.0 + rd)).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equirectangular_windows_default_to_square_angles() {
        let size = |s: &str| s.parse::<LensSpec>().unwrap().default_size();
        assert_eq!(size("equirect"), (1280, 640));
        assert_eq!(size("equirect:lon=-90..90,lat=45..-45"), (1280, 640));
        assert_eq!(size("equirect:lon=0..120,lat=40..-40"), (1280, 853));
        assert_eq!(size("fisheye"), (1280, 720));
        assert_eq!(size("pinhole"), (1280, 720));
    }

    const K: Intrinsics = Intrinsics {
        fx: 300.0,
        fy: 310.0,
        cx: 322.5,
        cy: 238.0,
        width: 640,
        height: 480,
    };

    fn lenses() -> Vec<Lens> {
        vec![
            Lens::Pinhole,
            Lens::RadialTangential {
                radial: [-0.28, 0.07, 0.0, 0.0, 0.0, 0.0],
                tangential: [0.001, -0.0005],
            },
            Lens::RadialTangential {
                radial: [0.1, -0.02, 0.003, 0.05, -0.01, 0.001],
                tangential: [0.0, 0.0],
            },
            Lens::Fisheye {
                k: [0.02, -0.005, 0.001, 0.0],
                max_theta: 95f64.to_radians(),
            },
            Lens::Orthographic,
            Lens::FULL_SPHERE,
            Lens::Equirectangular {
                longitude: [-1.0, 0.5],
                latitude: [0.6, -0.4],
            },
        ]
    }

    /// Every pixel of a grid over the image goes to a ray and back to itself.
    #[test]
    fn every_lens_maps_a_pixel_to_a_ray_and_back() {
        for lens in lenses() {
            let mut checked = 0;
            for j in 0..=24 {
                for i in 0..=32 {
                    let px = DVec2::new(i as f64 * 20.0, j as f64 * 20.0);
                    let Some(ray) = lens.unproject(&K, px) else {
                        continue;
                    };
                    assert!((ray.direction.length() - 1.0).abs() < 1e-12, "{lens:?}");
                    for t in [0.5, 3.0] {
                        let back = lens
                            .project(&K, ray.origin + t * ray.direction)
                            .unwrap_or_else(|| panic!("{lens:?}: {px} has no pixel"));
                        let mut d = back - px;
                        if lens == Lens::FULL_SPHERE {
                            // Both edges are the seam behind the camera.
                            d.x = d.x.abs().min((d.x.abs() - K.width as f64).abs());
                        }
                        assert!(d.length() < 1e-6, "{lens:?}: {px} -> {back}");
                    }
                    checked += 1;
                }
            }
            // A fisheye's corners lie outside its image circle; every other pixel has a ray.
            assert!(checked > 700, "{lens:?}: {checked} pixels");
        }
    }

    #[test]
    fn the_pinhole_is_the_renderers_projection() {
        let p = DVec3::new(0.3, -0.2, 2.5);
        let px = Lens::Pinhole.project(&K, p).unwrap();
        assert_eq!(
            px,
            DVec2::new(300.0 * 0.3 / 2.5 + 322.5, 310.0 * -0.2 / 2.5 + 238.0)
        );
        assert_eq!(Lens::Pinhole.project(&K, DVec3::new(0.0, 0.0, -1.0)), None);
    }

    #[test]
    fn a_fisheye_images_rays_beyond_90_degrees_and_no_further_than_its_field() {
        let lens = Lens::Fisheye {
            k: [0.0; 4],
            max_theta: 95f64.to_radians(),
        };
        // 93 degrees from the axis, behind the image plane: radius fx * theta.
        let theta = 93f64.to_radians();
        let p = DVec3::new(theta.sin(), 0.0, theta.cos());
        let px = lens.project(&K, p).unwrap();
        assert!((px.x - (K.cx + K.fx * theta)).abs() < 1e-9 && (px.y - K.cy).abs() < 1e-9);
        let beyond = 96f64.to_radians();
        assert_eq!(
            lens.project(&K, DVec3::new(beyond.sin(), 0.0, beyond.cos())),
            None
        );
        // The distortion model's undistortion stops at 90 degrees; the lens does not.
        let ray = lens.unproject(&K, px).unwrap();
        assert!(ray.direction.z < 0.0);
    }

    #[test]
    fn a_fisheye_stops_where_its_radius_stops_growing() {
        // theta (1 - 0.2 theta^2): the slope 1 - 0.6 theta^2 reaches 0 at theta = 1.29.
        let limit = fisheye_max_theta(&[-0.2, 0.0, 0.0, 0.0]);
        assert!((limit - (1.0f64 / 0.6).sqrt()).abs() < 1e-3, "{limit}");
        assert_eq!(fisheye_max_theta(&[0.0; 4]), PI);
    }

    #[test]
    fn the_equirectangular_axes() {
        let k = Intrinsics {
            width: 2048,
            height: 1024,
            ..K
        };
        let at = |d: DVec3| Lens::FULL_SPHERE.project(&k, d).unwrap();
        assert_eq!(at(DVec3::Z), DVec2::new(1024.0, 512.0)); // ahead: the centre
        assert_eq!(at(DVec3::X), DVec2::new(1536.0, 512.0)); // right: three quarters
        assert_eq!(at(-DVec3::X), DVec2::new(512.0, 512.0)); // left: one quarter
        assert_eq!(at(DVec3::new(0.0, -1.0, 0.0)).y, 0.0); // up: the top row
        assert_eq!(at(DVec3::new(0.0, 1.0, 0.0)).y, 1024.0); // down: the bottom row
                                                             // Behind: the seam, at both edges' longitude (atan2 gives +PI: the right edge).
        assert_eq!(at(DVec3::new(0.0, 0.0, -1.0)), DVec2::new(2048.0, 512.0));
    }

    #[test]
    fn an_equirectangular_window_may_cross_the_seam() {
        // 120 degrees of longitude centred behind the camera.
        let lens = Lens::Equirectangular {
            longitude: [2.0 * PI / 3.0, 4.0 * PI / 3.0],
            latitude: [0.5, -0.5],
        };
        let k = Intrinsics {
            width: 1200,
            height: 600,
            ..K
        };
        let behind = lens.project(&k, DVec3::new(0.0, 0.0, -1.0)).unwrap();
        assert!(
            (behind - DVec2::new(600.0, 300.0)).length() < 1e-9,
            "{behind}"
        );
        // Just left and right of the seam: either side of the middle column.
        let left = lens.project(&k, DVec3::new(-0.01, 0.0, -1.0)).unwrap();
        let right = lens.project(&k, DVec3::new(0.01, 0.0, -1.0)).unwrap();
        assert!(left.x > 600.0 && right.x < 600.0, "{left} {right}");
        // Ahead is half a turn from the middle: outside the picture, on its edge's turn.
        assert!(lens.project(&k, DVec3::Z).unwrap().x.abs() > 1200.0 - 1e-6);
    }

    #[test]
    fn a_distorted_lens_is_the_distortion_models_map() {
        let d = Distortion::opencv(
            "OPENCV",
            [-0.28, 0.07, 0.0, 0.0, 0.0, 0.0],
            [0.001, -0.0005],
        );
        let lens = Lens::from_distortion(&d);
        let p = DVec3::new(0.4, -0.3, 1.6);
        let (xd, yd) = d.distort(0.25, -0.1875);
        let px = lens.project(&K, p).unwrap();
        assert_eq!(px, DVec2::new(K.fx * xd + K.cx, K.fy * yd + K.cy));
        let f = Distortion::fisheye("OPENCV_FISHEYE", [0.01, 0.0, 0.0, 0.0]);
        assert!(
            matches!(Lens::from_distortion(&f), Lens::Fisheye { max_theta, .. } if max_theta == PI)
        );
        let none = Distortion::opencv("OPENCV", [0.0; 6], [0.0; 2]);
        assert_eq!(Lens::from_distortion(&none), Lens::Pinhole);
    }

    #[test]
    fn a_distorted_lens_images_nothing_past_its_fold() {
        // r (1 - 0.25 r^2) grows until r = sqrt(4 / 3) = 1.1547, the grid's 74 / 64.
        let radial = [-0.25, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(radial_fold(&radial, f64::INFINITY), Some(74.0 / 64.0));
        assert_eq!(radial_fold(&radial, 1.15), None);
        let lens = Lens::RadialTangential {
            radial,
            tangential: [0.0; 2],
        };
        assert!(lens.project(&K, DVec3::new(1.15, 0.0, 1.0)).is_some());
        // Past the fold the polynomial would put this point on the axis.
        let far = DVec3::new(2.0, 0.0, 1.0);
        assert!((brown_conrady(&radial, &[0.0; 2], 2.0, 0.0).0 - 0.0).abs() < 1e-12);
        assert_eq!(lens.project(&K, far), None);
        // A rational factor whose denominator reaches zero folds there; a monotonic one
        // never.
        assert_eq!(
            radial_fold(&[0.0, 0.0, 0.0, -1.0, 0.0, 0.0], f64::INFINITY),
            Some(1.0)
        );
        assert_eq!(
            radial_fold(&[0.1, 0.01, 0.0, 0.0, 0.0, 0.0], f64::INFINITY),
            None
        );
    }

    #[test]
    fn every_lens_jacobian_is_its_maps_derivative() {
        let lenses = [
            Lens::Pinhole,
            Lens::RadialTangential {
                radial: [-0.2, 0.05, -0.01, 0.02, 0.001, 0.0],
                tangential: [0.002, -0.001],
            },
            Lens::Fisheye {
                k: [0.05, -0.01, 0.002, 0.0005],
                max_theta: 1.7,
            },
            Lens::Orthographic,
            Lens::FULL_SPHERE,
        ];
        let points = [
            DVec3::new(0.3, -0.2, 2.0),
            DVec3::new(-0.7, 0.4, 1.1),
            DVec3::new(1.5, 0.9, 0.4),
            DVec3::new(0.8, -0.3, -0.5),
            DVec3::new(0.0, 0.0, 3.0),
        ];
        let h = 1e-6;
        for lens in &lenses {
            for p in points {
                let Some(j) = lens.jacobian(&K, p) else {
                    assert!(lens.project(&K, p).is_none(), "{lens:?} {p}");
                    continue;
                };
                for (i, col) in j.iter().enumerate() {
                    let mut e = DVec3::ZERO;
                    e[i] = h;
                    let (Some(a), Some(b)) = (lens.project(&K, p + e), lens.project(&K, p - e))
                    else {
                        continue;
                    };
                    let fd = (a - b) / (2.0 * h);
                    let err = (fd - *col).length();
                    assert!(
                        err <= 1e-5 * fd.length().max(1.0),
                        "{lens:?} at {p}, column {i}: {col} vs {fd}"
                    );
                }
            }
        }
    }

    #[test]
    fn lens_specs_parse_and_refuse_by_name() {
        let parse = |t: &str| t.parse::<LensSpec>();
        assert_eq!(parse("pinhole"), Ok(LensSpec::Pinhole));
        assert_eq!(parse("fisheye"), Ok(LensSpec::Fisheye { fov_deg: 180.0 }));
        assert_eq!(
            parse("fisheye:fov=190"),
            Ok(LensSpec::Fisheye { fov_deg: 190.0 })
        );
        assert_eq!(
            parse("equirect:lon=-90..90,lat=45..-45"),
            Ok(LensSpec::Equirect {
                lon_deg: [-90.0, 90.0],
                lat_deg: [45.0, -45.0]
            })
        );
        assert_eq!(
            parse("ortho:width=3.5"),
            Ok(LensSpec::Ortho { width: Some(3.5) })
        );
        for (bad, says) in [
            ("fishy", "not a lens"),
            ("fisheye:fov=400", "at most 360"),
            ("fisheye:fov=wide", "not a number"),
            ("fisheye:zoom=2", "no option 'zoom'"),
            ("equirect:lat=100..-90", "latitudes"),
            ("equirect:lon=0", "not a range"),
            ("ortho:width=-1", "positive"),
            ("pinhole:fov=3", "takes no options"),
        ] {
            let e = parse(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
        // A 180-degree fisheye fills the shorter side: 90 degrees at 240 px from the centre.
        let (lens, fx, _, cx, _) = LensSpec::Fisheye { fov_deg: 180.0 }.apply(640, 480, 500.0, 3.0);
        assert!(matches!(lens, Lens::Fisheye { .. }));
        assert!((fx * FRAC_PI_2 - 240.0).abs() < 1e-9 && cx == 320.0);
        // Orthographic by default shows what the pinhole shows at the distance.
        let (_, fx, ..) = LensSpec::Ortho { width: None }.apply(640, 480, 500.0, 4.0);
        assert!((640.0 / fx - 640.0 * 4.0 / 500.0).abs() < 1e-9);
    }

    #[test]
    fn an_orthographic_ray_is_parallel_to_the_axis() {
        let ray = Lens::Orthographic
            .unproject(&K, DVec2::new(622.5, 238.0))
            .unwrap();
        assert_eq!(ray.direction, DVec3::Z);
        assert_eq!(ray.origin, DVec3::new(1.0, 0.0, 0.0));
        assert_eq!(
            Lens::Orthographic.project(&K, DVec3::new(1.0, 0.0, 9.0)),
            Some(DVec2::new(622.5, 238.0))
        );
    }
}
