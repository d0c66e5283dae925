//! Per-photo appearance (`verisplat train --appearance affine`): each training photo has
//! its own colour transform `c' = A c + b` (A 3x3, b 3), learnt jointly with the scene and
//! applied to that photo's rendered image (the whole pixel, background included, as
//! gsplat's appearance colour transform) before the loss. Exposure, white balance and
//! tone changes between photos then go into the photos' transforms instead of into the
//! scene as floaters and tinted Gaussians.
//!
//! The loss's gradient with respect to the transformed image `g = dL/dc'` gives the
//! render's, `dL/dc = A^T g`, and the transform's, `dL/dA = sum over pixels of g c^T`,
//! `dL/db = sum of g`. The transforms are regularised towards the identity,
//! `reg (||A - I||_F^2 + ||b||^2)` per photo (its gradient `2 reg (A - I)`, `2 reg b`, is
//! added to the photo's before its step), and each photo's 12 values step with Adam (the
//! model's own, [`crate::train::model`]'s moments and conventions) on the host, once per
//! iteration that trains on the photo, from [`AppearanceSettings::from`] on: before that
//! the transforms are the identity and the scene learns alone.
//!
//! Renders, the saved PLY and every evaluation are the scene alone: no transform is
//! applied to a held-out photo (none was learnt for it) nor to a training photo that an
//! evaluation renders. The transforms are written beside each saved PLY
//! ([`APPEARANCE_FILE`], [`Appearances::to_json`]) and carried by the checkpoints.
//!
//! On the device the transform is two passes of the loss's submission
//! ([`device::AffinePasses`]); on the host the same maths in Rust ([`apply`],
//! [`backward`]).

pub mod device;

use crate::train::model::Moments;

/// The file the transforms are written to, beside each saved `point_cloud.ply`.
pub const APPEARANCE_FILE: &str = "appearance.json";

/// The `format` of [`APPEARANCE_FILE`].
pub const APPEARANCE_FORMAT: &str = "verisplat appearance";

/// The schema version of [`APPEARANCE_FILE`].
pub const APPEARANCE_VERSION: u32 = 1;

/// Adam's default learning rate of the transforms (`--appearance-lr`): gsplat's learning
/// rate of its per-photo bilateral grids, the nearest per-photo colour model it trains.
pub const DEFAULT_LR: f32 = 2e-3;

/// The default weight of the pull towards the identity (`--appearance-reg`): measured on
/// the fox at `-r 8` (BENCHMARKS.md, issue 62 item 2), 0.1 gave a little more held-out
/// PSNR, plain and colour-corrected, than 0.01 (one run each).
pub const DEFAULT_REG: f32 = 0.1;

/// The default first iteration that steps the transforms (`--appearance-from`): the
/// original's first densification, by when the scene has its coarse colours (before it,
/// the random start's colours are far from every photo's and the transforms would take
/// up what the scene has still to learn).
pub const DEFAULT_FROM: u32 = 500;

/// What each training photo learns besides the scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AppearanceMode {
    /// Nothing: every photo is the scene as rendered (the default).
    #[default]
    None,
    /// A 3x3 colour matrix and an offset per photo.
    Affine,
}

impl std::str::FromStr for AppearanceMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "none" => Ok(AppearanceMode::None),
            "affine" => Ok(AppearanceMode::Affine),
            other => Err(format!(
                "unknown appearance model {other:?}; use none or affine"
            )),
        }
    }
}

impl std::fmt::Display for AppearanceMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            AppearanceMode::None => "none",
            AppearanceMode::Affine => "affine",
        })
    }
}

/// How the per-photo appearance is learnt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AppearanceSettings {
    /// The model (`--appearance`).
    pub mode: AppearanceMode,
    /// Adam's learning rate of the transforms.
    pub lr: f32,
    /// Weight of `||A - I||_F^2 + ||b||^2` in each photo's loss.
    pub reg: f32,
    /// The first iteration whose loss sees the transform and which steps it.
    pub from: u32,
}

impl Default for AppearanceSettings {
    /// No appearance; [`DEFAULT_LR`], [`DEFAULT_REG`] and [`DEFAULT_FROM`] when one is
    /// asked for.
    fn default() -> Self {
        AppearanceSettings {
            mode: AppearanceMode::None,
            lr: DEFAULT_LR,
            reg: DEFAULT_REG,
            from: DEFAULT_FROM,
        }
    }
}

/// One photo's transform as 12 values: row r of `[A | b]` at `4 r..4 r + 4`, that is
/// `(A[r][0], A[r][1], A[r][2], b[r])` (the layout the shaders' push block takes).
pub type Affine = [f32; 12];

/// The identity transform.
pub const IDENTITY: Affine = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// `affine`'s rows as vec4s (the shaders' push block).
pub fn rows(affine: &Affine) -> [[f32; 4]; 3] {
    [0, 1, 2].map(|r| [0, 1, 2, 3].map(|k| affine[4 * r + k]))
}

/// `c' = A c + b` of every pixel of `image` (RGB), in f32.
pub fn apply(image: &[[f32; 3]], affine: &Affine) -> Vec<[f32; 3]> {
    let rows = rows(affine);
    image
        .iter()
        .map(|c| rows.map(|r| r[0] * c[0] + r[1] * c[1] + r[2] * c[2] + r[3]))
        .collect()
}

/// The backward of [`apply`]: with `grad` the loss's gradient with respect to the
/// transformed image, the gradient with respect to `image` (`A^T g` per pixel, f32) and
/// the transform's 12 gradients in [`Affine`]'s layout (`g[r] c[j]` and `g[r]` summed over
/// the pixels in order, in f64).
pub fn backward(
    image: &[[f32; 3]],
    grad: &[[f32; 3]],
    affine: &Affine,
) -> (Vec<[f32; 3]>, [f64; 12]) {
    let rows = rows(affine);
    let mut sums = [0f64; 12];
    let pixel = image
        .iter()
        .zip(grad)
        .map(|(c, g)| {
            for r in 0..3 {
                let gr = f64::from(g[r]);
                for j in 0..3 {
                    sums[4 * r + j] += gr * f64::from(c[j]);
                }
                sums[4 * r + 3] += gr;
            }
            [0, 1, 2].map(|j| rows[0][j] * g[0] + rows[1][j] * g[1] + rows[2][j] * g[2])
        })
        .collect();
    (pixel, sums)
}

/// The training photos' transforms and their optimiser.
#[derive(Clone, Debug, PartialEq)]
pub struct Appearances {
    /// The photos' names as the data set names them (its cameras' image names), in the
    /// data set's order of training views.
    pub names: Vec<String>,
    /// Each photo's transform.
    pub affines: Vec<Affine>,
    /// Adam's first moments, 12 per photo.
    m: Vec<f32>,
    /// Adam's second moments, 12 per photo.
    v: Vec<f32>,
    /// Adam steps taken per photo.
    steps: Vec<u32>,
}

impl Appearances {
    /// Identity transforms of the photos `names`, no step taken.
    pub fn identity(names: Vec<String>) -> Self {
        let n = names.len();
        Appearances {
            names,
            affines: vec![IDENTITY; n],
            m: vec![0.0; 12 * n],
            v: vec![0.0; 12 * n],
            steps: vec![0; n],
        }
    }

    /// One Adam step of photo `photo`'s transform with the loss's gradient `grads`
    /// ([`Affine`]'s layout) plus the regulariser's, `2 reg (affine - identity)`.
    pub fn step(&mut self, photo: usize, grads: &[f64; 12], settings: &AppearanceSettings) {
        let params = &mut self.affines[photo];
        let g: Vec<f32> = (0..12)
            .map(|k| {
                let pull = 2.0 * f64::from(settings.reg) * f64::from(params[k] - IDENTITY[k]);
                (grads[k] + pull) as f32
            })
            .collect();
        self.steps[photo] += 1;
        let range = 12 * photo..12 * photo + 12;
        let mut moments = Moments {
            m: self.m[range.clone()].to_vec(),
            v: self.v[range.clone()].to_vec(),
        };
        moments.step(params, &g, self.steps[photo], |_| settings.lr);
        self.m[range.clone()].copy_from_slice(&moments.m);
        self.v[range].copy_from_slice(&moments.v);
    }

    /// The checkpoint's arrays (transforms, moments) and the steps per photo.
    pub(crate) fn state(&self) -> (Vec<(String, Vec<f32>)>, Vec<u32>) {
        let flat: Vec<f32> = self.affines.iter().flatten().copied().collect();
        (
            vec![
                ("appearance_affines".to_string(), flat),
                ("appearance_m".to_string(), self.m.clone()),
                ("appearance_v".to_string(), self.v.clone()),
            ],
            self.steps.clone(),
        )
    }

    /// The state [`Self::state`] gave, of the photos `names`, taken out of a checkpoint's
    /// `arrays`; `None` when the checkpoint has none.
    pub(crate) fn from_state(
        arrays: &mut std::collections::HashMap<String, Vec<f32>>,
        steps: Option<Vec<u32>>,
        names: Vec<String>,
    ) -> Result<Option<Self>, String> {
        let Some(flat) = arrays.remove("appearance_affines") else {
            return Ok(None);
        };
        let n = flat.len() / 12;
        let mut take = |name: &str| -> Result<Vec<f32>, String> {
            let v = arrays.remove(name).ok_or(format!("has no {name}"))?;
            if v.len() != 12 * n {
                return Err(format!("{name} holds {} values, not {}", v.len(), 12 * n));
            }
            Ok(v)
        };
        let (m, v) = (take("appearance_m")?, take("appearance_v")?);
        let steps = steps.ok_or("has appearance transforms but no appearance_steps")?;
        if flat.len() != 12 * n || steps.len() != n || (!names.is_empty() && names.len() != n) {
            return Err(format!(
                "has {} appearance values and {} step counts, not 12 and 1 for each of {n} photos",
                flat.len(),
                steps.len()
            ));
        }
        Ok(Some(Appearances {
            names,
            affines: flat
                .chunks_exact(12)
                .map(|c| c.try_into().expect("12 values"))
                .collect(),
            m,
            v,
            steps,
        }))
    }

    /// [`APPEARANCE_FILE`]'s text after iteration `iteration`: the format, the schema
    /// version, the model, and per photo its name, A (rows) and b.
    pub fn to_json(&self, iteration: u32) -> String {
        let photos: Vec<serde_json::Value> = self
            .names
            .iter()
            .zip(&self.affines)
            .map(|(name, a)| {
                let r = rows(a);
                serde_json::json!({
                    "name": name,
                    "A": r.map(|row| [row[0], row[1], row[2]]),
                    "b": r.map(|row| row[3]),
                })
            })
            .collect();
        let doc = serde_json::json!({
            "format": APPEARANCE_FORMAT,
            "version": APPEARANCE_VERSION,
            "model": "affine",
            "iteration": iteration,
            "transform": "c' = A c + b, c the rendered RGB (background included), per training photo",
            "photos": photos,
        });
        serde_json::to_string_pretty(&doc).expect("plain JSON values") + "\n"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_backward_is_the_forward_s_derivative() {
        let image = [[0.2f32, 0.5, 0.9], [0.7, 0.1, 0.3]];
        let grad = [[0.3f32, -0.2, 0.5], [-0.4, 0.6, 0.1]];
        let affine: Affine = [
            1.1, 0.1, -0.2, 0.05, 0.0, 0.9, 0.3, -0.1, 0.2, -0.1, 1.2, 0.02,
        ];
        // L = sum g . apply(c): linear, so its derivatives are exact in f64.
        let loss = |img: &[[f32; 3]], a: &Affine| -> f64 {
            apply(img, a)
                .iter()
                .zip(&grad)
                .map(|(c, g)| {
                    (0..3)
                        .map(|k| f64::from(c[k]) * f64::from(g[k]))
                        .sum::<f64>()
                })
                .sum()
        };
        let (pixel, sums) = backward(&image, &grad, &affine);
        let h = 1e-2f32;
        for k in 0..12 {
            let (mut up, mut down) = (affine, affine);
            up[k] += h;
            down[k] -= h;
            let fd = (loss(&image, &up) - loss(&image, &down)) / f64::from(2.0 * h);
            assert!((fd - sums[k]).abs() < 1e-4, "{k}: {fd} vs {}", sums[k]);
        }
        for p in 0..2 {
            for j in 0..3 {
                let (mut up, mut down) = (image, image);
                up[p][j] += h;
                down[p][j] -= h;
                let fd = (loss(&up, &affine) - loss(&down, &affine)) / f64::from(2.0 * h);
                assert!((fd - f64::from(pixel[p][j])).abs() < 1e-4, "{p} {j}");
            }
        }
    }

    #[test]
    fn a_step_without_a_loss_gradient_stays_at_the_identity_and_the_state_reads_back() {
        let mut a = Appearances::identity(vec!["a.png".into(), "b.png".into()]);
        let s = AppearanceSettings {
            mode: AppearanceMode::Affine,
            ..Default::default()
        };
        a.step(1, &[0.0; 12], &s);
        assert_eq!(a.affines[1], IDENTITY);
        a.step(0, &[1.0; 12], &s);
        assert!(a.affines[0].iter().zip(IDENTITY).all(|(x, i)| *x < i));
        let (arrays, steps) = a.state();
        let mut map = arrays.into_iter().collect();
        let back = Appearances::from_state(&mut map, Some(steps), a.names.clone()).unwrap();
        assert_eq!(back, Some(a));
        assert_eq!("Affine".parse(), Ok(AppearanceMode::Affine));
        assert!("bilateral".parse::<AppearanceMode>().is_err());
    }
}
