//! Which rasterizer's rules a frame follows ([`Rules`], `--rules`): the original 3DGS
//! rasterizer's (the default, `shared/docs/reference-semantics.md`) or gsplat's (v1.5), so
//! that a model trained with either renders and trains here the way it did there.
//!
//! The two differ only in decisions and constants, never in the formulas between them:
//!
//! | rule | original | gsplat |
//! |---|---|---|
//! | near plane | culled at `z <= 0.2` | culled at `z < near` (0.01 by default) |
//! | guard band of the 2D covariance | `x/z` clamped to `±1.3 tan(fov/2)` | `-(cx/fx + 0.3 tan)` .. `(W - cx)/fx + 0.3 tan` |
//! | determinant | culled at `det == 0` | culled at `det <= 0` |
//! | antialiased compensation | `sqrt(max(2.5e-5, ratio))` | `sqrt(max(0, ratio))` |
//! | screen extent | a disc of radius `ceil(3 sqrt(lambda_max))`, tiles `[(p - r) / 16, (p + r + 15) / 16)` truncated | a box of `ceil(e sqrt(cov_xx))` by `ceil(e sqrt(cov_yy))`, `e = min(3.33, sqrt(2 ln(255 opacity)))`, tiles `[floor((p - r) / 16), ceil((p + r) / 16))` of the pixel-centre mean; culled when opacity < 1/255 or the box misses the image |
//! | alpha clamp | 0.99 | 0.999 |
//! | a pixel ends | before `T (1 - alpha) < 1e-4` | before `T (1 - alpha) <= 1e-4` |
//!
//! Both keep the 0.3 dilation, the 1/255 skip and the same SH colour rule. gsplat's box holds
//! every pixel where alpha >= 1/255, so under its rules no tail of a splat is cut at a tile
//! edge; the original's 3-sigma disc cuts the tails of opaque splats.

use crate::core::rules::{
    ALPHA_MAX, ALPHA_MIN, ANTIALIAS_MIN_RATIO, GSPLAT_ALPHA_MAX, GSPLAT_EXTEND, GSPLAT_NEAR_PLANE,
    NEAR_PLANE, TILE_SIZE, T_MIN,
};

/// Which rasterizer's rules a frame follows (see the module's table).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Rules {
    /// The original 3DGS rasterizer's (the default: scenes trained with the INRIA code).
    #[default]
    Original,
    /// gsplat's (v1.5): scenes trained with gsplat.
    Gsplat,
}

/// The floats both renderers' arithmetic runs in (f32 for the renderers, f64 for the
/// reference of the backward pass).
pub trait Real:
    Copy
    + PartialOrd
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
{
    /// The constant `v` in this type.
    fn of(v: f64) -> Self;
    /// `sqrt`.
    fn sqrt(self) -> Self;
    /// `ln`.
    fn ln(self) -> Self;
    /// `ceil`.
    fn ceil(self) -> Self;
    /// `floor`.
    fn floor(self) -> Self;
    /// Truncating conversion, saturating at the ends of i64.
    fn to_i64(self) -> i64;
}

macro_rules! real {
    ($t:ty) => {
        impl Real for $t {
            fn of(v: f64) -> Self {
                v as $t
            }
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            fn ln(self) -> Self {
                <$t>::ln(self)
            }
            fn ceil(self) -> Self {
                <$t>::ceil(self)
            }
            fn floor(self) -> Self {
                <$t>::floor(self)
            }
            fn to_i64(self) -> i64 {
                self as i64
            }
        }
    };
}
real!(f32);
real!(f64);

/// A Gaussian's screen extent under a rule set: its radius in pixels (per axis; the
/// original's disc has equal ones) and its tile rectangle `[min, max)`, clamped to the grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extent {
    /// Radius in pixels along x and y.
    pub radius: [i32; 2],
    /// First tile (x, y), inclusive.
    pub rect_min: [u32; 2],
    /// Last tile (x, y), exclusive.
    pub rect_max: [u32; 2],
}

impl Rules {
    /// Both rule sets, in `--rules` order.
    pub const ALL: [Rules; 2] = [Rules::Original, Rules::Gsplat];

    /// The name `--rules`, the PLY comment and the reports use.
    pub fn name(self) -> &'static str {
        match self {
            Rules::Original => "original",
            Rules::Gsplat => "gsplat",
        }
    }

    /// The near plane when none is given (0.2; gsplat's `near_plane` default 0.01).
    pub fn default_near_plane(self) -> f32 {
        match self {
            Rules::Original => NEAR_PLANE,
            Rules::Gsplat => GSPLAT_NEAR_PLANE,
        }
    }

    /// Whether a centre at view depth `z` is in front of the near plane `near`.
    pub fn in_front<T: Real>(self, z: T, near: T) -> bool {
        match self {
            Rules::Original => z > near,
            Rules::Gsplat => z >= near,
        }
    }

    /// The depth the shaders compare with `>`: `near` itself, or the float just below it
    /// for gsplat's `>=` (the same test on every f32).
    pub fn near_cull_f32(self, near: f32) -> f32 {
        match self {
            Rules::Original => near,
            Rules::Gsplat => f32::from_bits(near.to_bits() - 1), // positive: the next float down
        }
    }

    /// The upper clamp of a Gaussian's alpha at a pixel.
    pub fn alpha_max(self) -> f32 {
        match self {
            Rules::Original => ALPHA_MAX,
            Rules::Gsplat => GSPLAT_ALPHA_MAX,
        }
    }

    /// A pixel ends before a Gaussian that would leave its transmittance below this: 1e-4,
    /// or for gsplat's `<= 1e-4` the float just above it (the same test on every f32).
    pub fn t_stop(self) -> f32 {
        match self {
            Rules::Original => T_MIN,
            Rules::Gsplat => f32::from_bits(T_MIN.to_bits() + 1), // the next float up
        }
    }

    /// [`Self::t_stop`] for the f64 reference: whether a pixel at transmittance `test_t`
    /// after a Gaussian ends before it.
    pub fn stops(self, test_t: f64) -> bool {
        match self {
            Rules::Original => test_t < T_MIN as f64,
            Rules::Gsplat => test_t <= T_MIN as f64,
        }
    }

    /// Lower bound of the antialiased compensation's determinant ratio.
    pub fn antialias_min_ratio(self) -> f32 {
        match self {
            Rules::Original => ANTIALIAS_MIN_RATIO,
            Rules::Gsplat => 0.0,
        }
    }

    /// Whether a dilated 2D covariance of determinant `det` is kept.
    pub fn keeps_det<T: Real>(self, det: T) -> bool {
        match self {
            Rules::Original => det != T::of(0.0),
            Rules::Gsplat => det > T::of(0.0),
        }
    }

    /// The guard band of the 2D covariance's Jacobian, `[x_neg, x_pos, y_neg, y_pos]`:
    /// `x/z` is clamped to `[-x_neg, x_pos]` and `y/z` to `[-y_neg, y_pos]`. The original
    /// is symmetric, 1.3 tan(fov/2) with tan(fov/2) = W / (2 fx); gsplat's follows the
    /// principal point.
    pub fn clamp_limits<T: Real>(self, w: T, h: T, fx: T, fy: T, cx: T, cy: T) -> [T; 4] {
        let tan_x = w / (T::of(2.0) * fx);
        let tan_y = h / (T::of(2.0) * fy);
        match self {
            Rules::Original => {
                let (lx, ly) = (T::of(1.3) * tan_x, T::of(1.3) * tan_y);
                [lx, lx, ly, ly]
            }
            Rules::Gsplat => {
                let (bx, by) = (
                    T::of(0.3) * (T::of(0.5) * w / fx),
                    T::of(0.3) * (T::of(0.5) * h / fy),
                );
                [
                    cx / fx + bx,
                    (w - cx) / fx + bx,
                    cy / fy + by,
                    (h - cy) / fy + by,
                ]
            }
        }
    }

    /// The screen extent of a splat with dilated 2D covariance `(a, b, c)` (xx, xy, yy; det
    /// `det`), opacity `opacity` (compensated where antialiased) and centre `mean2d` (the
    /// renderers' pixel units: pixel `(i, j)` at `(i, j)`), on an image of `size` pixels
    /// and `grid` tiles; `None` when culled (an empty rectangle, and for gsplat an opacity
    /// below 1/255 or a box off the image).
    pub fn extent<T: Real>(
        self,
        cov: [T; 3],
        det: T,
        opacity: T,
        mean2d: [T; 2],
        size: (u32, u32),
        grid: (u32, u32),
    ) -> Option<Extent> {
        let tile = T::of(TILE_SIZE as f64);
        let clamp = |v: T, hi: u32| -> u32 { v.to_i64().clamp(0, hi as i64) as u32 };
        let [a, _, c] = cov;
        let e = match self {
            Rules::Original => {
                let mid = T::of(0.5) * (a + c);
                let d = mid * mid - det;
                let disc = (if d > T::of(0.1) { d } else { T::of(0.1) }).sqrt();
                let (l1, l2) = (mid + disc, mid - disc);
                let r = (T::of(3.0) * (if l1 > l2 { l1 } else { l2 }).sqrt()).ceil();
                let (rect_min, rect_max) = get_rect(mean2d, r, grid);
                Extent {
                    radius: [r.to_i64() as i32; 2],
                    rect_min,
                    rect_max,
                }
            }
            Rules::Gsplat => {
                let threshold = T::of(ALPHA_MIN as f64);
                if opacity < threshold {
                    return None;
                }
                let fit = (T::of(2.0) * (opacity / threshold).ln()).sqrt();
                let extend = if fit < T::of(GSPLAT_EXTEND as f64) {
                    fit
                } else {
                    T::of(GSPLAT_EXTEND as f64)
                };
                let (rx, ry) = ((extend * a.sqrt()).ceil(), (extend * c.sqrt()).ceil());
                if rx <= T::of(0.0) && ry <= T::of(0.0) {
                    return None;
                }
                // gsplat's pixel centres are at +0.5.
                let (px, py) = (mean2d[0] + T::of(0.5), mean2d[1] + T::of(0.5));
                let (w, h) = (T::of(size.0 as f64), T::of(size.1 as f64));
                let zero = T::of(0.0);
                if px + rx <= zero || px - rx >= w || py + ry <= zero || py - ry >= h {
                    return None;
                }
                Extent {
                    radius: [rx.to_i64() as i32, ry.to_i64() as i32],
                    rect_min: [
                        clamp(((px - rx) / tile).floor(), grid.0),
                        clamp(((py - ry) / tile).floor(), grid.1),
                    ],
                    rect_max: [
                        clamp(((px + rx) / tile).ceil(), grid.0),
                        clamp(((py + ry) / tile).ceil(), grid.1),
                    ],
                }
            }
        };
        let area = (e.rect_max[0] - e.rect_min[0]) * (e.rect_max[1] - e.rect_min[1]);
        (area != 0).then_some(e)
    }

    /// [`Self::extent`] in an image that wraps around
    /// ([`Lens::wraps`](crate::core::camera::Lens::wraps)), `size.0` pixels and `grid.0`
    /// tiles across: the rectangle in the tiles of three turns side by side, the image the
    /// middle one, at most one turn wide; tile `x` of it is the image's tile
    /// `x % grid.0`. Each turn is whole tiles, `grid.0 * 16` pixels: the middle turn's
    /// rectangle is that of the centre moved by one such turn; where the width is not
    /// whole tiles (the last tile of a turn partly empty), what the splat covers across
    /// the seam is the rectangle of its copy one image width to the left or right, in the
    /// image's tiles, so a splat across the seam reaches the first or last tile as it
    /// would across any other tile edge.
    pub fn wrapped_extent<T: Real>(
        self,
        cov: [T; 3],
        det: T,
        opacity: T,
        mean2d: [T; 2],
        size: (u32, u32),
        grid: (u32, u32),
    ) -> Option<Extent> {
        let turn = grid.0 * TILE_SIZE;
        let moved = [mean2d[0] + T::of(turn as f64), mean2d[1]];
        let turns = (3 * turn, size.1);
        let mut e = self.extent(cov, det, opacity, moved, turns, (3 * grid.0, grid.1))?;
        if size.0 != turn {
            let w = T::of(size.0 as f64);
            // The copy one width to the right is seen in the turn to the left, and the
            // copy to the left in the turn to the right.
            for (x, offset) in [(mean2d[0] + w, 0), (mean2d[0] - w, 2 * grid.0)] {
                if let Some(s) = self.extent(cov, det, opacity, [x, mean2d[1]], size, grid) {
                    e.rect_min[0] = e.rect_min[0].min(s.rect_min[0] + offset);
                    e.rect_max[0] = e.rect_max[0].max(s.rect_max[0] + offset);
                }
            }
        }
        e.rect_max[0] = e.rect_max[0].min(e.rect_min[0] + grid.0);
        Some(e)
    }

    /// The value the shaders receive (`FrameParams.modes.x`).
    pub fn shader_id(self) -> u32 {
        match self {
            Rules::Original => crate::core::shader_interface::RULES_ORIGINAL,
            Rules::Gsplat => crate::core::shader_interface::RULES_GSPLAT,
        }
    }
}

/// Tile rectangle `[min, max)` of a disc of radius `r` around `p`, clamped to the `grid`
/// (the original rasterizer's `getRect`, with C's truncating float-to-int conversion).
pub fn get_rect<T: Real>(p: [T; 2], r: T, grid: (u32, u32)) -> ([u32; 2], [u32; 2]) {
    let tile = T::of(TILE_SIZE as f64);
    let clamp = |v: T, hi: u32| -> u32 { v.to_i64().clamp(0, hi as i64) as u32 };
    let last = tile - T::of(1.0);
    (
        [
            clamp((p[0] - r) / tile, grid.0),
            clamp((p[1] - r) / tile, grid.1),
        ],
        [
            clamp((p[0] + r + last) / tile, grid.0),
            clamp((p[1] + r + last) / tile, grid.1),
        ],
    )
}

impl std::fmt::Display for Rules {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Rules {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "original" | "inria" => Ok(Rules::Original),
            "gsplat" => Ok(Rules::Gsplat),
            other => Err(format!("unknown rules {other:?}; use original or gsplat")),
        }
    }
}

/// The guard band of `rules` for `cam` ([`Rules::clamp_limits`]), as the GPU receives it.
pub fn clamp_limits(cam: &crate::core::camera::Camera, rules: Rules) -> [f32; 4] {
    let (w, h) = (cam.width as f32, cam.height as f32);
    rules.clamp_limits(w, h, cam.fx, cam.fy, cam.cx, cam.cy)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_near_and_stop_floats_make_gsplats_inclusive_tests() {
        let near = 0.01f32;
        let cull = Rules::Gsplat.near_cull_f32(near);
        assert!(near > cull && f64::from(near) - f64::from(cull) < 1e-9);
        assert!(Rules::Gsplat.in_front(near, near) && !Rules::Original.in_front(near, near));
        let stop = Rules::Gsplat.t_stop();
        assert!(T_MIN < stop && f64::from(stop) - f64::from(T_MIN) < 1e-11);
        assert!(Rules::Gsplat.stops(T_MIN as f64) && !Rules::Original.stops(T_MIN as f64));
    }

    #[test]
    fn the_original_guard_band_is_symmetric_and_gsplats_follows_the_principal_point() {
        let o = Rules::Original.clamp_limits(100.0f32, 50.0, 80.0, 80.0, 50.0, 25.0);
        let (lx, ly) = (1.3f32 * (100.0 / 160.0), 1.3f32 * (50.0 / 160.0));
        assert_eq!(o, [lx, lx, ly, ly]);
        let g = Rules::Gsplat.clamp_limits(100.0f64, 50.0, 80.0, 80.0, 20.0, 25.0);
        let tan = 100.0 / 160.0;
        assert!((g[0] - (20.0 / 80.0 + 0.3 * tan)).abs() < 1e-12);
        assert!((g[1] - (80.0 / 80.0 + 0.3 * tan)).abs() < 1e-12);
    }

    #[test]
    fn gsplats_box_is_per_axis_and_opacity_aware() {
        // cov xx 4 (sigma 2), yy 1 (sigma 1) on a 100x100 image of 7x7 tiles.
        let extent = |rules: Rules, opacity: f32, x: f32| {
            rules.extent(
                [4.0f32, 0.0, 1.0],
                4.0,
                opacity,
                [x, 40.0],
                (100, 100),
                (7, 7),
            )
        };
        // Opaque: e = 3.33 -> radii 7 and 4.
        let e = extent(Rules::Gsplat, 1.0, 40.0).unwrap();
        assert_eq!(e.radius, [7, 4]);
        // x: (40.5 - 7) / 16 = 2.09 -> 2, (40.5 + 7) / 16 = 2.97 -> 3.
        assert_eq!((e.rect_min, e.rect_max), ([2, 2], [3, 3]));
        // opacity 0.05: e = sqrt(2 ln(12.75)) = 2.26 -> radius x ceil(4.51) = 5.
        assert_eq!(extent(Rules::Gsplat, 0.05, 40.0).unwrap().radius, [5, 3]);
        assert!(extent(Rules::Gsplat, 0.003, 40.0).is_none());
        // A box that ends at the image's left edge is culled.
        assert!(extent(Rules::Gsplat, 1.0, -7.5).is_none());
        // The original's disc: radius ceil(3 * 2) = 6 on both axes.
        assert_eq!(extent(Rules::Original, 1.0, 40.0).unwrap().radius, [6, 6]);
    }
}
