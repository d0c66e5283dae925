//! The surface passes (`render --mode normal` and `--mode median-depth`), shared by both
//! renderers and the writers.
//!
//! Each Gaussian's *axis* is the unit column of its rotation that belongs to its smallest
//! scale (the normal of the disc it flattens to; the first of equal smallest scales),
//! uploaded once per scene as four channels `(n, n . mean)` in world space
//! ([`surface_axes`]). Per frame, the blend flips it to face the camera
//! ([`facing_normal`]: `n . (mean - centre) <= 0`) and composites it with the colour
//! weights `w_i = alpha_i T_i` into the first three channels of a four-channel plane; the
//! fourth holds the median depth: the depth of the Gaussian whose compositing takes the
//! pixel's transmittance from above 0.5 to 0.5 or below (0 where it never gets there).
//! The GPU's `glsl/render/forward/blend_features.comp` (`SURFACE 1`) and [`crate::cpu::surface::render_surface`]
//! do exactly this; [`surface_planes`] turns the blended plane into unit normals in world
//! or camera space and the median depth.

use crate::core::camera::Camera;
use crate::core::model::ActivatedScene;
use glam::{DMat3, DVec3};

/// Channels per Gaussian and per pixel of the surface pass: the facing normal's sum
/// (3) and the median depth.
pub const SURFACE_CHANNELS: usize = 4;

/// The transmittance at which the median depth is taken (gsplat's 2DGS: 0.5).
pub const MEDIAN_TRANSMITTANCE: f32 = 0.5;

/// The space normals are written in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum NormalSpace {
    /// The renderer's camera space (OpenCV: x right, y down, z forward, the direction of
    /// view): a disc facing the camera has normal (0, 0, -1).
    #[default]
    Camera,
    /// World space, the scene's own axes.
    World,
}

impl NormalSpace {
    /// The name `--normal-space` and the Python `normal_space` take.
    pub fn name(self) -> &'static str {
        match self {
            NormalSpace::Camera => "camera",
            NormalSpace::World => "world",
        }
    }
}

impl std::str::FromStr for NormalSpace {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "camera" => Ok(NormalSpace::Camera),
            "world" => Ok(NormalSpace::World),
            _ => Err(format!("unknown normal space \"{s}\"; use camera or world")),
        }
    }
}

/// One Gaussian's axis as the surface pass uploads it: the unit column of the rotation of
/// `rotation` (`w, x, y, z`, normalised here) for the smallest of `scale` (the first of
/// equal ones), and its dot product with `mean`, computed in f64 and rounded.
pub fn surface_axis(mean: [f32; 3], scale: [f32; 3], rotation: [f32; 4]) -> [f32; 4] {
    let q = rotation.map(f64::from);
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let q = if norm > 0.0 {
        q.map(|v| v / norm)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    };
    let r: DMat3 = crate::core::quat::quat_to_dmat3(q);
    let mut axis = 0;
    for a in 1..3 {
        if scale[a] < scale[axis] {
            axis = a;
        }
    }
    let n: DVec3 = r.col(axis).normalize_or_zero();
    let d = n.dot(DVec3::from(mean.map(f64::from)));
    [n.x as f32, n.y as f32, n.z as f32, d as f32]
}

/// [`surface_axis`] of every Gaussian of `scene`, Gaussian-major.
pub fn surface_axes(scene: &ActivatedScene) -> Vec<[f32; 4]> {
    (0..scene.len())
        .map(|i| surface_axis(scene.positions[i], scene.scales[i], scene.rotations[i]))
        .collect()
}

/// The axis `axis` (`n, n . mean`) flipped to face a camera at `centre`: `-n` where
/// `n . mean - n . centre > 0` (the Gaussian's front is away from the camera), else `n`.
/// The sums are taken in this order with no fused multiply-add, as the shader's
/// `precise` arithmetic.
pub fn facing_normal(axis: [f32; 4], centre: [f32; 3]) -> [f32; 3] {
    let nc = axis[0] * centre[0] + axis[1] * centre[1] + axis[2] * centre[2];
    let facing = axis[3] - nc;
    if facing > 0.0 {
        [-axis[0], -axis[1], -axis[2]]
    } else {
        [axis[0], axis[1], axis[2]]
    }
}

/// A surface frame's planes: unit normals and median depth.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfacePlanes {
    /// Unit normal per pixel in the chosen space; 0 where alpha is 0 (or the blended
    /// normals cancel).
    pub normals: Vec<[f32; 3]>,
    /// Median depth per pixel; 0 where the transmittance never reaches 0.5.
    pub median_depth: Vec<f32>,
}

/// The planes of a blended surface plane `raw` ([`SURFACE_CHANNELS`] per pixel, the
/// renderers' [`crate::core::frame::Frame::features`]) with opacities `alpha`: each
/// pixel's normal sum normalised to unit length where alpha is above 0 (in f64), in world
/// space, or rotated into `camera`'s camera space when one is given
/// ([`NormalSpace::Camera`]).
pub fn surface_planes(raw: &[f32], alpha: &[f32], camera: Option<&Camera>) -> SurfacePlanes {
    let rotation = camera.map(|cam| cam.rotation.as_dmat3());
    let (normals, median_depth) = raw
        .chunks_exact(SURFACE_CHANNELS)
        .zip(alpha)
        .map(|(p, &a)| {
            let sum = DVec3::new(p[0].into(), p[1].into(), p[2].into());
            let n = if a > 0.0 {
                sum.normalize_or_zero()
            } else {
                DVec3::ZERO
            };
            let n = rotation.map_or(n, |r| r * n);
            ([n.x as f32, n.y as f32, n.z as f32], p[3])
        })
        .unzip();
    SurfacePlanes {
        normals,
        median_depth,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_axis_is_the_smallest_scale_column() {
        // A quarter turn about z: x -> y, y -> -x.
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let a = surface_axis([0.0, 0.0, 5.0], [0.3, 0.01, 0.2], [h, 0.0, 0.0, h]);
        assert!((a[0] + 1.0).abs() < 1e-6 && a[1].abs() < 1e-6 && a[2].abs() < 1e-6);
        assert!(a[3].abs() < 1e-6);
        let b = surface_axis([0.0, 0.0, 5.0], [0.3, 0.2, 0.01], [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(b, [0.0, 0.0, 1.0, 5.0]);
    }

    #[test]
    fn facing_flips_away_from_the_camera() {
        // Axis +z at z = 5, camera at the origin: n . (mean - c) = 5 > 0, so flipped.
        assert_eq!(
            facing_normal([0.0, 0.0, 1.0, 5.0], [0.0; 3]),
            [-0.0, -0.0, -1.0]
        );
        // Camera behind it at z = 10: kept.
        assert_eq!(
            facing_normal([0.0, 0.0, 1.0, 5.0], [0.0, 0.0, 10.0]),
            [0.0, 0.0, 1.0]
        );
    }

    #[test]
    fn names_parse_back() {
        for s in [NormalSpace::Camera, NormalSpace::World] {
            assert_eq!(s.name().parse::<NormalSpace>(), Ok(s));
        }
        assert!("view".parse::<NormalSpace>().is_err());
    }
}
