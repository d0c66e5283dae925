//! An independent check of the picture through every lens (issue 49, item 7): the CPU
//! reference renders a scene of small Gaussians through a lens, and the same renderer's
//! pinhole path renders the scene as a high-resolution cube map (six 90-degree faces,
//! EWA) that this file resamples through the lens's map. The resampling spells every lens
//! out again with its own formulas (`Lens::project` and `Lens::unproject` are not called):
//! each lens pixel's ray, by Newton's method for the fisheye's polynomial and for
//! Brown-Conrady, looked up in its cube face with bilinear interpolation. Nothing else is
//! composited: the faces carry the same background as the lens render.
//!
//! The scenes: Gaussians on a Fibonacci sphere of 1,440 directions around the camera
//! (every direction, so a fisheye's image past 90 degrees and every part of the
//! equirectangular image are covered), 4 to 9 units away, opaque (0.9), in distinct
//! colours, each 0.8 degrees across one standard deviation: 2.2 to 2.3 pixels in the lens
//! images (2.7 to 2.9 pixels a degree at their centres), 9 pixels or more on the cube
//! faces (`FACE` = 1,280 pixels across 90 degrees, 4 times the lens images' resolution at
//! their centres), so the faces' bilinear interpolation is close to exact. Each scene
//! leaves out the directions within 3 degrees of where a lens is documented to draw
//! otherwise (`Gap`): the fisheyes' image circle (a Gaussian there is drawn whole or
//! culled whole, where the circle would cut it) and the equirectangular seam behind the
//! camera (a Gaussian across it is cut, or drawn on both sides only where the image
//! wraps).
//!
//! The orthographic lens has parallel rays, which no cube map holds. Its reference is a
//! pinhole 100,000 units behind it with a field of view of a few thousandths of a degree,
//! at 4 times the resolution: a near-parallel projection whose scale differs from the
//! orthographic one by the scene's depth over that distance (2e-5), sampled where it sees
//! each orthographic ray's point at the middle of the scene's depth. Its scene is a slab of
//! Gaussians in front of the camera.
//!
//! What separates a render from its reference is the linearisation in each (EWA on the
//! faces; the unscented transform in the lens, whose sigma points lie a sixth of a
//! standard deviation from the mean with gsplat's `alpha = 0.1`, so close to a
//! linearisation too), which misplaces the image of a Gaussian seen far off a pinhole's
//! axis (the side of the Brown-Conrady lens, 60 to 63 degrees from the axis; a face's
//! corners, 55 degrees), and the 0.3 square pixel low-pass that the renderers add to every
//! splat in their own image's pixels. Measured on the CPU reference (2026-11-29; also in
//! BENCHMARKS.md, "2026-11-29: lens resampling check"), PSNR in dB of the colour, and the
//! thresholds:
//!
//! | model | lens image | PSNR | threshold | half a pixel right |
//! |---|---|--:|--:|--:|
//! | fisheye 190, equidistant | 512x512 | 47.0 | 45 | 35.3 |
//! | fisheye 190, k1..k4 | 512x512 | 46.8 | 45 | 35.2 |
//! | OPENCV (k1, k2, p1, p2) | 512x384 | 42.1 | 40 | 36.4 |
//! | equirectangular, whole sphere | 1024x512 | 40.2 | 37 | |
//! | the same, within 75 degrees of the horizon | | 45.9 | 43.5 | 35.8 |
//! | equirectangular, window | 512x256 | 45.9 | 44 | 34.6 |
//! | orthographic | 384x320 | 47.0 | 45 | 35.5 |
//!
//! The poles of the whole-sphere image score least: near a pole a Gaussian's true image
//! wraps across many longitudes, which no 2D Gaussian draws; the rows within 15 degrees of
//! the poles take the image from 45.9 dB to 40.2.
//!
//! Each check can fail: every map that is wrong, and a pinhole render of the same
//! intrinsics in the lens's place, must score 3 dB or more under the threshold (over the
//! rows within 75 degrees of the horizon for the whole sphere). Mirrored left to right,
//! or the pinhole, scores 15.7 to 17.2 dB, under what the background alone scores (17.8 to
//! 19.2); half a pixel to the right, 34.6 to 36.4 (the last column above); a 190-degree
//! fisheye taken for 180 degrees 16.9; its k1..k4 dropped 18.3; Brown-Conrady's p1 and
//! p2 swapped 27.7.
//!
//! `cargo test --test all -- reference::lens_resample --nocapture` prints the table.

use crate::common::{push_gaussian, Rng};
use glam::{DVec3, Mat3, Vec3};
use std::f64::consts::PI;
use verisplat::core::camera::{Camera, Lens};
use verisplat::core::frame::Frame;
use verisplat::core::scene::Scene;
use verisplat::cpu::{self, RenderOptions};

/// The colour behind every Gaussian, in the lens renders and the cube faces alike.
const BACKGROUND: [f32; 3] = [0.05, 0.1, 0.15];
/// Pixels across a cube face's 90 degrees (each face is rendered with one more pixel on
/// every side, so bilinear interpolation never needs a neighbouring face).
const FACE: u32 = 1280;
/// One standard deviation of every Gaussian of the sphere scenes, as an angle.
const SIGMA_DEG: f64 = 0.8;
/// Half the fisheyes' field of view: 190 degrees.
const FISHEYE_HALF_DEG: f64 = 95.0;

fn render(s: &Scene, cam: &Camera) -> Frame {
    let opts = RenderOptions {
        background: BACKGROUND,
        ..RenderOptions::default()
    };
    cpu::render(&s.activated(), cam, &opts)
}

/// A camera at the origin looking along +z (identity pose).
fn camera(name: &str, lens: Lens, size: (u32, u32), f: (f32, f32), c: (f32, f32)) -> Camera {
    Camera {
        name: name.into(),
        width: size.0,
        height: size.1,
        fx: f.0,
        fy: f.1,
        cx: c.0,
        cy: c.1,
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
        lens,
    }
}

/// Distinct colours: random, one channel bright.
fn colour(rng: &mut Rng) -> [f32; 3] {
    let mut c = [
        rng.range(0.1, 0.7),
        rng.range(0.1, 0.7),
        rng.range(0.1, 0.7),
    ];
    c[(rng.next_u32() % 3) as usize] = rng.range(0.8, 1.0);
    c
}

/// The directions a sphere scene leaves out (3 degrees either side).
#[derive(Clone, Copy, PartialEq)]
enum Gap {
    /// The fisheyes' image circle, `FISHEYE_HALF_DEG` from the axis.
    FisheyeCircle,
    /// The equirectangular seam: longitude 180 degrees, behind the camera.
    Seam,
}

/// A sphere scene (see the module's documentation).
fn sphere_scene(gap: Gap) -> Scene {
    let n = 1440;
    let golden = PI * (3.0 - 5f64.sqrt());
    let tilt = glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.7, 0.4, 0.2);
    let mut rng = Rng(497);
    let mut s = Scene::empty(0);
    for k in 0..n {
        // A Fibonacci sphere about a tilted axis, so that neither the camera's axis nor
        // the poles hold a point of its own pattern.
        let a = 1.0 - (2.0 * k as f64 + 1.0) / n as f64;
        let b = (1.0 - a * a).sqrt();
        let phi = k as f64 * golden;
        let d = tilt * DVec3::new(b * phi.cos(), b * phi.sin(), a);
        let distance = rng.range(4.0, 9.0) as f64;
        let rgb = colour(&mut rng);
        let margin = 3.0;
        let skip = match gap {
            Gap::FisheyeCircle => (d.z.acos().to_degrees() - FISHEYE_HALF_DEG).abs() < margin,
            Gap::Seam => d.x.atan2(d.z).to_degrees().abs() > 180.0 - margin,
        };
        if !skip {
            let scale = distance * SIGMA_DEG.to_radians().tan();
            push_gaussian(
                &mut s,
                (d * distance).as_vec3().into(),
                scale as f32,
                0.9,
                rgb,
            );
        }
    }
    s
}

/// A cube map: six 90-degree pinhole renders from the origin, each `FACE + 2` pixels
/// across, the axes (right, down, forward) of each.
struct CubeMap {
    faces: Vec<([DVec3; 3], Frame)>,
}

impl CubeMap {
    fn render(s: &Scene) -> CubeMap {
        let axes = [
            [DVec3::X, DVec3::Y, DVec3::Z],
            [DVec3::NEG_X, DVec3::Y, DVec3::NEG_Z],
            [DVec3::NEG_Z, DVec3::Y, DVec3::X],
            [DVec3::Z, DVec3::Y, DVec3::NEG_X],
            [DVec3::X, DVec3::NEG_Z, DVec3::Y],
            [DVec3::X, DVec3::Z, DVec3::NEG_Y],
        ];
        let faces = axes
            .iter()
            .map(|&[r, d, f]| {
                assert!((r.cross(d) - f).length() < 1e-12, "a right-handed face");
                let half = FACE as f32 / 2.0;
                let mut cam = camera(
                    "face",
                    Lens::Pinhole,
                    (FACE + 2, FACE + 2),
                    (half, half),
                    (half + 1.0, half + 1.0),
                );
                cam.rotation = Mat3::from_cols(r.as_vec3(), d.as_vec3(), f.as_vec3()).transpose();
                ([r, d, f], render(s, &cam))
            })
            .collect();
        CubeMap { faces }
    }

    /// The colour the cube map holds along direction `dir`: the face whose axis is
    /// nearest, bilinear between its pixel centres.
    fn sample(&self, dir: DVec3) -> [f32; 3] {
        let (axes, frame) = self
            .faces
            .iter()
            .max_by(|a, b| a.0[2].dot(dir).total_cmp(&b.0[2].dot(dir)))
            .unwrap();
        let z = axes[2].dot(dir);
        let half = FACE as f64 / 2.0;
        // Continuous pixel position, less the half pixel of the pixel centres.
        let x = half * axes[0].dot(dir) / z + half + 1.0 - 0.5;
        let y = half * axes[1].dot(dir) / z + half + 1.0 - 0.5;
        bilinear(frame, x, y)
    }
}

/// `frame`'s colour at `(x, y)` in pixel-centre coordinates (pixel `(i, j)` at `(i, j)`),
/// clamped to the frame.
fn bilinear(frame: &Frame, x: f64, y: f64) -> [f32; 3] {
    let max_x = frame.width as f64 - 1.0;
    let max_y = frame.height as f64 - 1.0;
    let (x, y) = (x.clamp(0.0, max_x), y.clamp(0.0, max_y));
    let (x0, y0) = (x.floor().min(max_x - 1.0), y.floor().min(max_y - 1.0));
    let (tx, ty) = ((x - x0) as f32, (y - y0) as f32);
    let at = |i: f64, j: f64| frame.color[frame.index(i as u32, j as u32)];
    let (a, b, c, d) = (
        at(x0, y0),
        at(x0 + 1.0, y0),
        at(x0, y0 + 1.0),
        at(x0 + 1.0, y0 + 1.0),
    );
    std::array::from_fn(|k| {
        let top = a[k] + tx * (b[k] - a[k]);
        let bottom = c[k] + tx * (d[k] - c[k]);
        top + ty * (bottom - top)
    })
}

/// The fisheye's polynomial `theta (1 + k1 theta^2 + ... + k4 theta^8)` and its slope.
fn fisheye_radius(k: &[f64; 4], theta: f64) -> (f64, f64) {
    let t2 = theta * theta;
    let r = theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))));
    let slope = 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
    (r, slope)
}

/// The angle from the axis whose fisheye radius is `rd`, by Newton's method, if it is at
/// most `max_theta`.
fn fisheye_theta(k: &[f64; 4], max_theta: f64, rd: f64) -> Option<f64> {
    if rd > fisheye_radius(k, max_theta).0 {
        return None;
    }
    let mut theta = rd;
    for _ in 0..50 {
        let (r, slope) = fisheye_radius(k, theta);
        theta -= (r - rd) / slope;
    }
    assert!(
        (fisheye_radius(k, theta).0 - rd).abs() < 1e-12,
        "Newton converges"
    );
    (theta <= max_theta).then_some(theta)
}

/// The fisheye's ray through normalised image position `(u, v)`.
fn fisheye_ray(k: &[f64; 4], max_theta: f64, u: f64, v: f64) -> Option<DVec3> {
    let rd = u.hypot(v);
    if rd == 0.0 {
        return Some(DVec3::Z);
    }
    let theta = fisheye_theta(k, max_theta, rd)?;
    let s = theta.sin() / rd;
    Some(DVec3::new(u * s, v * s, theta.cos()))
}

/// OpenCV's Brown-Conrady distortion (`OPENCV`: `k1, k2, p1, p2`) of pinhole coordinates.
fn opencv(c: &[f64; 4], x: f64, y: f64) -> DVec3 {
    let [k1, k2, p1, p2] = *c;
    let r2 = x * x + y * y;
    let radial = 1.0 + k1 * r2 + k2 * r2 * r2;
    DVec3::new(
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        0.0,
    )
}

/// The ray whose distorted pinhole coordinates are `(u, v)`: Newton's method on the 2x2
/// system, its Jacobian by central differences.
fn opencv_ray(c: &[f64; 4], u: f64, v: f64) -> Option<DVec3> {
    let target = DVec3::new(u, v, 0.0);
    let (mut x, mut y) = (u, v);
    let h = 1e-6;
    for _ in 0..50 {
        let e = opencv(c, x, y) - target;
        let dx = (opencv(c, x + h, y) - opencv(c, x - h, y)) / (2.0 * h);
        let dy = (opencv(c, x, y + h) - opencv(c, x, y - h)) / (2.0 * h);
        let det = dx.x * dy.y - dy.x * dx.y;
        x -= (dy.y * e.x - dy.x * e.y) / det;
        y -= (dx.x * e.y - dx.y * e.x) / det;
    }
    let residual = (opencv(c, x, y) - target).length();
    assert!(
        residual < 1e-10,
        "Newton converges at ({u}, {v}): {residual}"
    );
    Some(DVec3::new(x, y, 1.0).normalize())
}

/// The equirectangular window's ray through image position `(a, b)` (fractions of the
/// width and height).
fn equirect_ray(longitude: [f64; 2], latitude: [f64; 2], a: f64, b: f64) -> Option<DVec3> {
    let lon = longitude[0] + a * (longitude[1] - longitude[0]);
    let lat = latitude[0] + b * (latitude[1] - latitude[0]);
    Some(DVec3::new(
        lat.cos() * lon.sin(),
        -lat.sin(),
        lat.cos() * lon.cos(),
    ))
}

/// A lens pixel's ray: from a continuous image position to what the reference looks up
/// (a camera-space direction; for the orthographic lens, the ray's origin), `None` where
/// the lens images nothing.
type RayFn<'a> = dyn Fn(f64, f64) -> Option<DVec3> + 'a;

/// A [`RayFn`] of a model's own.
type RayMap = Box<RayFn<'static>>;

/// A lens model under test.
struct Model {
    name: &'static str,
    cam: Camera,
    /// The lens's rays, written out here.
    ray: RayMap,
    /// Fine errors of the map, each named, that the check must catch.
    wrong: Vec<(&'static str, RayMap)>,
    /// The least PSNR the render must score against its resampling (measured minus a
    /// margin), and over the rows between fractions `rows` of the height if given.
    min_psnr: f64,
    rows: Option<((f64, f64), f64)>,
    /// A pinhole camera in the lens's place.
    pinhole: Camera,
}

impl Model {
    fn new(name: &'static str, cam: Camera, ray: RayMap, min_psnr: f64) -> Model {
        let pinhole = Camera {
            lens: Lens::Pinhole,
            ..cam.clone()
        };
        Model {
            name,
            cam,
            ray,
            wrong: Vec::new(),
            min_psnr,
            rows: None,
            pinhole,
        }
    }
}

fn fisheye_model(name: &'static str, k: [f64; 4], size: u32, min_psnr: f64) -> Model {
    let max_theta = FISHEYE_HALF_DEG.to_radians();
    let half = size as f64 / 2.0;
    let f = half / fisheye_radius(&k, max_theta).0;
    let cam = camera(
        name,
        Lens::Fisheye { k, max_theta },
        (size, size),
        (f as f32, f as f32),
        (half as f32, half as f32),
    );
    // The same image read with another polynomial and field of view.
    let read = move |k: [f64; 4], max_theta: f64| -> RayMap {
        let f = half / fisheye_radius(&k, max_theta).0;
        Box::new(move |x, y| fisheye_ray(&k, max_theta, (x - half) / f, (y - half) / f))
    };
    let mut m = Model::new(name, cam, read(k, max_theta), min_psnr);
    if k == [0.0; 4] {
        m.wrong
            .push(("taken for 180 degrees", read(k, 90f64.to_radians())));
    } else {
        m.wrong.push(("k1..k4 dropped", read([0.0; 4], max_theta)));
    }
    m
}

fn opencv_model(min_psnr: f64) -> Model {
    let c = [-0.12, 0.03, 0.002, -0.001];
    let (fx, fy, cx, cy) = (160.0, 164.0, 258.6, 188.4);
    let cam = camera(
        "opencv",
        Lens::RadialTangential {
            radial: [c[0], c[1], 0.0, 0.0, 0.0, 0.0],
            tangential: [c[2], c[3]],
        },
        (512, 384),
        (fx, fy),
        (cx, cy),
    );
    let read = move |c: [f64; 4]| -> RayMap {
        Box::new(move |x, y| {
            opencv_ray(&c, (x - cx as f64) / fx as f64, (y - cy as f64) / fy as f64)
        })
    };
    let mut m = Model::new("OPENCV (k1, k2, p1, p2)", cam, read(c), min_psnr);
    m.wrong
        .push(("p1, p2 swapped", read([c[0], c[1], c[3], c[2]])));
    m
}

fn equirect_model(
    name: &'static str,
    size: (u32, u32),
    lon_deg: [f64; 2],
    lat_deg: [f64; 2],
    min_psnr: f64,
) -> Model {
    let longitude = lon_deg.map(f64::to_radians);
    let latitude = lat_deg.map(f64::to_radians);
    let per_radian = (size.0 as f64 / (longitude[1] - longitude[0])) as f32;
    let (w, h) = (size.0 as f64, size.1 as f64);
    let lens = Lens::Equirectangular {
        longitude,
        latitude,
    };
    let centre = (size.0 as f32 / 2.0, size.1 as f32 / 2.0);
    let cam = camera(name, lens, size, (per_radian, per_radian), centre);
    let ray = Box::new(move |x, y| equirect_ray(longitude, latitude, x / w, y / h));
    Model::new(name, cam, ray, min_psnr)
}

/// The image `ray` sees in `lookup`, at every pixel centre of a `width x height` image;
/// the background where there is no ray.
fn resample(
    width: u32,
    height: u32,
    ray: &RayFn<'_>,
    lookup: &dyn Fn(DVec3) -> [f32; 3],
) -> Vec<[f32; 3]> {
    (0..height)
        .flat_map(|j| (0..width).map(move |i| (i as f64 + 0.5, j as f64 + 0.5)))
        .map(|(x, y)| ray(x, y).map_or(BACKGROUND, lookup))
        .collect()
}

/// PSNR in dB of `a` against `b`, colour in [0, 1].
fn psnr(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    let sum: f64 = a
        .iter()
        .zip(b)
        .flat_map(|(p, q)| (0..3).map(move |k| (p[k] as f64 - q[k] as f64).powi(2)))
        .sum();
    let mse = sum / (3 * a.len()) as f64;
    -10.0 * mse.log10()
}

/// One model's scores against its resampling (dB).
struct Scores {
    /// The lens render.
    psnr: f64,
    /// The lens render over the rows of `Model::rows`.
    rows: Option<f64>,
    /// The background alone, over the rows of `Model::rows` where given (as the next).
    blank: f64,
    /// A pinhole render of the same intrinsics.
    pinhole: f64,
    /// The lens render against the resampling through each wrong map: mirrored left to
    /// right, half a pixel to the right, then the model's own.
    wrong: Vec<(&'static str, f64)>,
}

fn score(m: &Model, s: &Scene, lookup: &dyn Fn(DVec3) -> [f32; 3]) -> Scores {
    let (w, h) = (m.cam.width, m.cam.height);
    let truth = resample(w, h, &m.ray, lookup);
    let frame = render(s, &m.cam);
    let mirrored = |x: f64, y: f64| (m.ray)(x, y).map(|d| DVec3::new(-d.x, d.y, d.z));
    let shifted = |x: f64, y: f64| (m.ray)(x + 0.5, y);
    let wrong_maps: Vec<(&'static str, &RayFn<'_>)> = [
        ("mirrored", &mirrored as &RayFn<'_>),
        ("half a pixel right", &shifted),
    ]
    .into_iter()
    .chain(m.wrong.iter().map(|(name, ray)| (*name, ray.as_ref())))
    .collect();
    // The wrong maps are scored over the pixels of the strictest check: the rows of
    // `Model::rows` where given.
    let r = match m.rows {
        Some(((top, bottom), _)) => {
            (h as f64 * top) as usize * w as usize..(h as f64 * bottom) as usize * w as usize
        }
        None => 0..truth.len(),
    };
    let within = |img: &[[f32; 3]]| psnr(&img[r.clone()], &truth[r.clone()]);
    let wrong = wrong_maps
        .into_iter()
        .map(|(name, ray)| {
            (
                name,
                psnr(
                    &frame.color[r.clone()],
                    &resample(w, h, ray, lookup)[r.clone()],
                ),
            )
        })
        .collect();
    Scores {
        psnr: psnr(&frame.color, &truth),
        rows: m.rows.map(|_| within(&frame.color)),
        blank: within(&vec![BACKGROUND; truth.len()]),
        pinhole: within(&render(s, &m.pinhole).color),
        wrong,
    }
}

/// The orthographic lens and its scene, and its reference: the far, narrow pinhole's
/// render and where it sees each orthographic ray (see the module's documentation).
fn orthographic(min_psnr: f64) -> (Model, Scene, impl Fn(DVec3) -> [f32; 3]) {
    let (w, h, f) = (384u32, 320u32, 96.0f32);
    let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
    let mut rng = Rng(4977);
    let mut s = Scene::empty(0);
    let (near, far) = (3.0, 7.0);
    for _ in 0..480 {
        let x = rng.range(-0.55, 0.55) * w as f32 / f;
        let y = rng.range(-0.55, 0.55) * h as f32 / f;
        let z = rng.range(near, far);
        let rgb = colour(&mut rng);
        push_gaussian(&mut s, [x, y, z], 2.2 / f, 0.9, rgb);
    }
    let cam = camera("orthographic", Lens::Orthographic, (w, h), (f, f), (cx, cy));
    // The orthographic ray through (x, y) is the line (u, v, z) for every z > 0.
    let ray = Box::new(move |x: f64, y: f64| {
        Some(DVec3::new(
            (x - cx as f64) / f as f64,
            (y - cy as f64) / f as f64,
            0.0,
        ))
    });
    let mut m = Model::new("orthographic", cam, ray, min_psnr);
    let middle = 0.5 * (near + far) as f64;
    m.pinhole.fx = f * middle as f32;
    m.pinhole.fy = f * middle as f32;
    let (distance, scale) = (1e5f64, 4.0);
    let pf = scale * f as f64 * (middle + distance);
    let mut far_cam = camera(
        "far pinhole",
        Lens::Pinhole,
        (w * scale as u32, h * scale as u32),
        (pf as f32, pf as f32),
        (cx * scale as f32, cy * scale as f32),
    );
    far_cam.translation = Vec3::new(0.0, 0.0, distance as f32);
    let far_frame = render(&s, &far_cam);
    // The far pinhole sees the ray's point at the middle depth at pf u / (middle +
    // distance) + cx', less the half pixel of the pixel centres.
    let (fcx, fcy) = (far_cam.cx as f64, far_cam.cy as f64);
    let lookup = move |o: DVec3| {
        let x = pf * o.x / (middle + distance) + fcx - 0.5;
        let y = pf * o.y / (middle + distance) + fcy - 0.5;
        bilinear(&far_frame, x, y)
    };
    (m, s, lookup)
}

/// Every model's scores, with the reference's face size: the fisheyes over the scene
/// without the fisheye's image circle, the other lenses through a cube over the scene
/// without the seam, the orthographic lens through its far pinhole.
fn measure() -> Vec<(Model, (u32, u32), Scores)> {
    let mut out = Vec::new();
    let mut through_cube = |gap: Gap, models: Vec<Model>| {
        let scene = sphere_scene(gap);
        let cube = CubeMap::render(&scene);
        for m in models {
            let scores = score(&m, &scene, &|d| cube.sample(d));
            out.push((m, (FACE + 2, FACE + 2), scores));
        }
    };
    through_cube(
        Gap::FisheyeCircle,
        vec![
            fisheye_model("fisheye 190, equidistant", [0.0; 4], 512, 45.0),
            fisheye_model(
                "fisheye 190, k1..k4",
                [-0.03, 0.004, -0.0005, 0.00003],
                512,
                45.0,
            ),
        ],
    );
    let mut sphere = equirect_model(
        "equirectangular, whole sphere",
        (1024, 512),
        [-180.0, 180.0],
        [90.0, -90.0],
        37.0,
    );
    sphere.rows = Some(((1.0 / 12.0, 11.0 / 12.0), 43.5));
    let window = equirect_model(
        "equirectangular, window",
        (512, 256),
        [-70.0, 110.0],
        [55.0, -35.0],
        44.0,
    );
    through_cube(Gap::Seam, vec![opencv_model(40.0), sphere, window]);
    let (m, s, lookup) = orthographic(45.0);
    let scores = score(&m, &s, &lookup);
    let size = (m.cam.width * 4, m.cam.height * 4);
    out.push((m, size, scores));
    out
}

/// The table of BENCHMARKS.md.
fn table(rows: &[(Model, (u32, u32), Scores)]) -> String {
    let mut t = String::from(
        "| model | lens image | reference image | PSNR (dB) | background only | pinhole render | wrong maps |\n|---|---|---|---|---|---|---|\n",
    );
    for (m, (rw, rh), s) in rows {
        let wrong: Vec<String> = s.wrong.iter().map(|(n, p)| format!("{n} {p:.1}")).collect();
        let psnr = match s.rows {
            Some(r) => format!("{:.1} ({r:.1} within 75 degrees of the horizon)", s.psnr),
            None => format!("{:.1}", s.psnr),
        };
        t += &format!(
            "| {} | {}x{} | {rw}x{rh} | {psnr} | {:.1} | {:.1} | {} |\n",
            m.name,
            m.cam.width,
            m.cam.height,
            s.blank,
            s.pinhole,
            wrong.join(", ")
        );
    }
    t
}

#[test]
fn every_lens_matches_a_cube_map_resampled_through_its_own_map() {
    let start = std::time::Instant::now();
    let rows = measure();
    eprintln!("{}{:.1} s", table(&rows), start.elapsed().as_secs_f64());
    for (m, _, s) in &rows {
        assert!(s.psnr >= m.min_psnr, "{}: {:.1} dB", m.name, s.psnr);
        if let (Some((_, min)), Some(p)) = (m.rows, s.rows) {
            assert!(p >= min, "{}, the rows: {p:.1} dB", m.name);
        }
        // The check can fail: a pinhole in the lens's place, and every wrong map, score
        // well under the threshold.
        let strictest = m.rows.map_or(m.min_psnr, |(_, min)| min);
        let pinhole = ("pinhole render", s.pinhole);
        for (what, p) in s.wrong.iter().chain([&pinhole]) {
            assert!(*p < strictest - 3.0, "{}, {what}: {p:.1} dB", m.name);
        }
    }
}
