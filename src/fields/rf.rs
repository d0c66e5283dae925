//! Synthetic radio-frequency fields on a dense grid (`verisplat gen --rf`), so the fitting
//! flow (`verisplat fit`) can be tried without measured data.
//!
//! Lengths are in wavelengths (lambda = 1, wavenumber k = 2 pi). A grid of `n` points per
//! axis samples its bounds like `numpy.linspace(min, max, n)` on each axis (the first and
//! last points lie on the bounds); value `c` of point `(i, j, l)` is
//! `data[((i * n + j) * n + l) * C + c]`, so the array is `X x Y x Z x C` in C order. Both
//! fields clamp the distance to a source at lambda / 4, which keeps them finite at the
//! source. Each field has four channels:
//!
//! - `dipole`: a half-wave dipole along z at the origin, bounds -2..2 on every axis. Far
//!   field `E(r, theta) = |cos(pi/2 cos theta) / sin theta| / r` (0 on the axis, its limit),
//!   phase `-k r`. Channels: magnitude (normalised to a maximum of 1), cos(phase),
//!   sin(phase), and the vertical polarisation fraction `sin^2 theta` (the field points
//!   along theta-hat, whose z component is `-sin theta`).
//! - `two-ray`: an isotropic transmitter 1 wavelength above a perfectly reflecting ground
//!   plane z = 0 (reflection coefficient -1), bounds x, y in -3..3 and z in 0..3. The field
//!   is the direct ray `exp(-i k r1) / r1` plus the image ray `-exp(-i k r2) / r2`.
//!   Channels: magnitude of the sum (normalised to a maximum of 1), cos and sin of its
//!   phase, and the direct ray's magnitude `1 / r1` (normalised to a maximum of 1).
//!
//! And one time-varying field, [`MovingSource`] (`moving-source`): a Gaussian blob whose
//! centre moves along x as time goes from 0 to 1, sampled on the grid at several times and
//! written as samples `N x 5` (x, y, z, t, magnitude) for `fit` in space and time.

use std::f64::consts::{FRAC_PI_2, TAU};

/// A synthetic field `verisplat gen --rf` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RfField {
    /// A half-wave dipole's radiation pattern.
    Dipole,
    /// A transmitter above a ground plane: direct and reflected rays interfere.
    TwoRay,
}

impl RfField {
    /// The name `--rf` takes.
    pub fn name(self) -> &'static str {
        match self {
            RfField::Dipole => "dipole",
            RfField::TwoRay => "two-ray",
        }
    }

    /// The grid's extent: `[xmin, ymin, zmin, xmax, ymax, zmax]` in wavelengths.
    pub fn bounds(self) -> [f32; 6] {
        match self {
            RfField::Dipole => [-2.0, -2.0, -2.0, 2.0, 2.0, 2.0],
            RfField::TwoRay => [-3.0, -3.0, 0.0, 3.0, 3.0, 3.0],
        }
    }

    /// The names of the four channels, in order.
    pub fn channels(self) -> [&'static str; 4] {
        match self {
            RfField::Dipole => ["magnitude", "cos_phase", "sin_phase", "vertical_fraction"],
            RfField::TwoRay => ["magnitude", "cos_phase", "sin_phase", "direct_magnitude"],
        }
    }

    /// The unnormalised channels at `p`: [magnitude, cos phase, sin phase, fourth channel].
    pub fn raw(self, p: [f64; 3]) -> [f64; 4] {
        let k = TAU;
        let clamp = 0.25;
        match self {
            RfField::Dipole => {
                let r_true = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                let r = r_true.max(clamp);
                let (cos_t, sin_t) = if r_true > 0.0 {
                    let c = (p[2] / r_true).clamp(-1.0, 1.0);
                    (c, (1.0 - c * c).max(0.0).sqrt())
                } else {
                    (0.0, 1.0)
                };
                let pattern = if sin_t < 1e-9 {
                    0.0
                } else {
                    ((FRAC_PI_2 * cos_t).cos() / sin_t).abs()
                };
                let phase = -k * r;
                [pattern / r, phase.cos(), phase.sin(), sin_t * sin_t]
            }
            RfField::TwoRay => {
                let height = 1.0;
                let dist = |z0: f64| {
                    let dz = p[2] - z0;
                    (p[0] * p[0] + p[1] * p[1] + dz * dz).sqrt().max(clamp)
                };
                let r1 = dist(height);
                let r2 = dist(-height);
                let re = (-k * r1).cos() / r1 - (-k * r2).cos() / r2;
                let im = (-k * r1).sin() / r1 - (-k * r2).sin() / r2;
                let mag = (re * re + im * im).sqrt();
                let (c, s) = if mag > 0.0 {
                    (re / mag, im / mag)
                } else {
                    (1.0, 0.0)
                };
                [mag, c, s, 1.0 / r1]
            }
        }
    }
}

impl std::fmt::Display for RfField {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for RfField {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "dipole" => Ok(RfField::Dipole),
            "two-ray" | "tworay" | "two_ray" => Ok(RfField::TwoRay),
            other => Err(format!("unknown RF field {other:?}; use dipole or two-ray")),
        }
    }
}

/// What `gen --rf` writes: a field on a grid, or the moving source's samples in time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RfData {
    /// A static field on a dense grid.
    Grid(RfField),
    /// [`MovingSource`], sampled in space and time.
    MovingSource,
}

impl RfData {
    /// The name `--rf` takes.
    pub fn name(self) -> &'static str {
        match self {
            RfData::Grid(f) => f.name(),
            RfData::MovingSource => "moving-source",
        }
    }
}

impl std::fmt::Display for RfData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for RfData {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "moving-source" | "moving_source" | "movingsource" => Ok(RfData::MovingSource),
            other => other.parse().map(RfData::Grid).map_err(|_| {
                format!("unknown RF field {other:?}; use dipole, two-ray or moving-source")
            }),
        }
    }
}

/// A time-varying field (`gen --rf moving-source`): a Gaussian blob of amplitude 1 and
/// width [`MovingSource::SIGMA`] whose centre moves in a straight line at constant speed,
/// `c(t) = (-1 + 2 t, 0, 0)` for `t` in 0..1, over the box -2..2 on every axis (lengths in
/// wavelengths). One channel, the magnitude `exp(-|x - c(t)|^2 / (2 sigma^2))`. The tests
/// compare the field fitted to its samples with it at several times.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MovingSource;

impl MovingSource {
    /// The blob's width (standard deviation).
    pub const SIGMA: f64 = 0.5;
    /// The box, `[xmin, ymin, zmin, xmax, ymax, zmax]`.
    pub const BOUNDS: [f32; 6] = [-2.0, -2.0, -2.0, 2.0, 2.0, 2.0];
    /// The times sampled run from the first to the second.
    pub const TIMES: [f32; 2] = [0.0, 1.0];
    /// The columns of its samples.
    pub const COLUMNS: [&'static str; 5] = ["x", "y", "z", "t", "magnitude"];
    /// The column of the time.
    pub const TIME_COLUMN: usize = 3;

    /// The centre at time `t`.
    pub fn centre(t: f64) -> [f64; 3] {
        [-1.0 + 2.0 * t, 0.0, 0.0]
    }

    /// The magnitude at `p` at time `t`.
    pub fn magnitude(p: [f64; 3], t: f64) -> f64 {
        let c = Self::centre(t);
        let r2: f64 = (0..3).map(|a| (p[a] - c[a]).powi(2)).sum();
        (-0.5 * r2 / (Self::SIGMA * Self::SIGMA)).exp()
    }

    /// Samples on an `n^3` grid over [`Self::BOUNDS`] at `times` equally spaced times over
    /// [`Self::TIMES`] (both ends included): rows `x, y, z, t, magnitude`, time-major.
    pub fn samples(n: usize, times: usize) -> Vec<f32> {
        let b = Self::BOUNDS;
        let mut rows = Vec::with_capacity(n * n * n * times * 5);
        for f in 0..times {
            let t = grid_coordinate(Self::TIMES[0], Self::TIMES[1], f, times);
            for i in 0..n {
                for j in 0..n {
                    for l in 0..n {
                        let p = [
                            grid_coordinate(b[0], b[3], i, n),
                            grid_coordinate(b[1], b[4], j, n),
                            grid_coordinate(b[2], b[5], l, n),
                        ];
                        let v = Self::magnitude(p.map(f64::from), f64::from(t));
                        rows.extend_from_slice(&[p[0], p[1], p[2], t, v as f32]);
                    }
                }
            }
        }
        rows
    }

    /// The sidecar of its `.npy` samples: bounds, time range, columns and the time's column
    /// (which `fit` reads as `--time-column`).
    pub fn sidecar_json(n: usize, times: usize) -> String {
        let value = serde_json::json!({
            "field": "moving-source",
            "bounds": Self::BOUNDS,
            "time_range": Self::TIMES,
            "shape": [n * n * n * times, Self::COLUMNS.len()],
            "columns": Self::COLUMNS,
            "time_column": Self::TIME_COLUMN,
            "centre": "(-1 + 2 t, 0, 0)",
            "sigma": Self::SIGMA,
            "wavelength": 1.0,
            "grid": "numpy.linspace(min, max, n) on each axis and over time; rows time-major",
        });
        serde_json::to_string_pretty(&value).unwrap_or_default() + "\n"
    }
}

/// The coordinate of point `i` of `n` spanning `[lo, hi]` (`numpy.linspace`; the middle
/// when `n == 1`).
pub fn grid_coordinate(lo: f32, hi: f32, i: usize, n: usize) -> f32 {
    if n <= 1 {
        0.5 * (lo + hi)
    } else {
        let t = i as f64 / (n - 1) as f64;
        (f64::from(lo) + t * (f64::from(hi) - f64::from(lo))) as f32
    }
}

/// A field sampled on an `n x n x n` grid: `n^3 * 4` values, `X x Y x Z x C` in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct RfGrid {
    /// Which field.
    pub field: RfField,
    /// Points per axis.
    pub size: usize,
    /// The grid's extent, `[xmin, ymin, zmin, xmax, ymax, zmax]`.
    pub bounds: [f32; 6],
    /// The values, `[size, size, size, 4]` in C order.
    pub data: Vec<f32>,
}

impl RfGrid {
    /// The array's shape.
    pub fn shape(&self) -> [usize; 4] {
        [self.size, self.size, self.size, 4]
    }
}

/// Samples `field` on an `n^3` grid over its bounds (normalising the magnitude channels).
pub fn generate(field: RfField, n: usize) -> RfGrid {
    let b = field.bounds();
    let mut raw = Vec::with_capacity(n * n * n);
    for i in 0..n {
        for j in 0..n {
            for l in 0..n {
                let p = [
                    f64::from(grid_coordinate(b[0], b[3], i, n)),
                    f64::from(grid_coordinate(b[1], b[4], j, n)),
                    f64::from(grid_coordinate(b[2], b[5], l, n)),
                ];
                raw.push(field.raw(p));
            }
        }
    }
    let max = |c: usize| raw.iter().map(|v| v[c]).fold(0.0f64, f64::max);
    let norm_mag = max(0).max(1e-30);
    let norm_fourth = match field {
        RfField::Dipole => 1.0,
        RfField::TwoRay => max(3).max(1e-30),
    };
    let data = raw
        .iter()
        .flat_map(|v| {
            [
                (v[0] / norm_mag) as f32,
                v[1] as f32,
                v[2] as f32,
                (v[3] / norm_fourth) as f32,
            ]
        })
        .collect();
    RfGrid {
        field,
        size: n,
        bounds: b,
        data,
    }
}

/// The sidecar JSON `gen --rf` writes beside `OUT.npy` (as `OUT.npy.json`) and `fit`
/// reads when `--bounds` is not given.
pub fn sidecar_path(npy: &std::path::Path) -> std::path::PathBuf {
    let mut name = npy.as_os_str().to_owned();
    name.push(".json");
    std::path::PathBuf::from(name)
}

/// The sidecar's text: the field, its bounds, its shape and its channel names.
pub fn sidecar_json(grid: &RfGrid) -> String {
    let value = serde_json::json!({
        "field": grid.field.name(),
        "bounds": grid.bounds,
        "shape": grid.shape(),
        "channels": grid.field.channels(),
        "wavelength": 1.0,
        "grid": "numpy.linspace(min, max, n) on each axis, X x Y x Z x C in C order",
    });
    serde_json::to_string_pretty(&value).unwrap_or_default() + "\n"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dipole_pattern_peaks_at_broadside_and_vanishes_on_the_axis() {
        let g = generate(RfField::Dipole, 17);
        assert_eq!(g.data.len(), 17 * 17 * 17 * 4);
        let at = |i: usize, j: usize, l: usize| &g.data[((i * 17 + j) * 17 + l) * 4..][..4];
        // Centre (clamped r), the z axis and a broadside point at the same distance.
        let axis = at(8, 8, 16);
        let side = at(16, 8, 8);
        assert!(
            axis[0].abs() < 1e-6,
            "no radiation along the dipole: {axis:?}"
        );
        assert!(side[0] > 0.05, "{side:?}");
        assert!((side[3] - 1.0).abs() < 1e-6, "broadside is vertical");
        let max = g.data.chunks(4).map(|v| v[0]).fold(0.0f32, f32::max);
        assert!((max - 1.0).abs() < 1e-6);
        // Phase -k r at r = 2 (a whole number of wavelengths): cos 1, sin 0.
        assert!(
            (side[1] - 1.0).abs() < 1e-5 && side[2].abs() < 1e-5,
            "{side:?}"
        );
        assert!(g.data.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn two_ray_vanishes_on_the_ground_plane() {
        let g = generate(RfField::TwoRay, 9);
        for (p, v) in g.data.chunks(4).enumerate() {
            let l = p % 9;
            if l == 0 {
                // z = 0: both rays have the same length and cancel (reflection -1).
                assert!(v[0] < 1e-6, "{v:?}");
            }
            assert!((v[1] * v[1] + v[2] * v[2] - 1.0).abs() < 1e-5);
        }
        let max = g.data.chunks(4).map(|v| v[3]).fold(0.0f32, f32::max);
        assert!((max - 1.0).abs() < 1e-6);
    }

    #[test]
    fn moving_source_samples_follow_the_centre() {
        let rows = MovingSource::samples(5, 3);
        assert_eq!(rows.len(), 125 * 3 * 5);
        // The peak of each time's samples sits at its centre: x = -1, 0, 1 (grid points).
        for f in 0..3 {
            let block = &rows[f * 125 * 5..(f + 1) * 125 * 5];
            let best = block
                .chunks(5)
                .max_by(|a, b| a[4].total_cmp(&b[4]))
                .unwrap();
            assert_eq!(best[3], f as f32 * 0.5);
            assert_eq!(&best[..3], &[-1.0 + f as f32, 0.0, 0.0]);
            assert!((best[4] - 1.0).abs() < 1e-6);
        }
        assert_eq!("moving-source".parse::<RfData>(), Ok(RfData::MovingSource));
        assert_eq!(
            "dipole".parse::<RfData>(),
            Ok(RfData::Grid(RfField::Dipole))
        );
        assert!("x".parse::<RfData>().unwrap_err().contains("moving-source"));
    }

    #[test]
    fn linspace_coordinates() {
        assert_eq!(grid_coordinate(-2.0, 2.0, 0, 5), -2.0);
        assert_eq!(grid_coordinate(-2.0, 2.0, 4, 5), 2.0);
        assert_eq!(grid_coordinate(-2.0, 2.0, 2, 5), 0.0);
        assert_eq!(grid_coordinate(1.0, 3.0, 0, 1), 2.0);
    }
}
