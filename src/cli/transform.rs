//! `--flip-x/y/z`, `--scale-scene`, `--rotate` and `--translate`: a scene transform applied
//! to the loaded scene before the filters, shared by `render` and `convert`.
//!
//! The steps are applied in one fixed order whatever the order on the command line:
//! flips, then the scale about the origin, then the rotations about the origin (in the
//! order given), then the translation. The values are parsed here rather than by clap so
//! that every bad value gives one sentence.

use anyhow::{anyhow, Result};
use clap::Args;
use verisplat::core::scene::transform::SceneTransform;
use verisplat::core::scene::Scene;

/// Moves, turns, mirrors or scales the scene before it is rendered or written.
#[derive(Args)]
pub(crate) struct TransformArgs {
    /// Mirror the scene's x axis (x -> -x); flips come first.
    #[arg(long, help_heading = "Scene transform")]
    pub(crate) flip_x: bool,
    /// Mirror the scene's y axis (y -> -y).
    #[arg(long, help_heading = "Scene transform")]
    pub(crate) flip_y: bool,
    /// Mirror the scene's z axis (z -> -z). --flip-y --flip-z is --rotate 1,0,0,180, which
    /// fixes an SPZ file written without its axis conversion.
    #[arg(long, help_heading = "Scene transform")]
    pub(crate) flip_z: bool,
    /// Scale the scene about the origin by S > 0 (positions and Gaussian sizes), after the
    /// flips.
    #[arg(
        long,
        value_name = "S",
        allow_hyphen_values = true,
        help_heading = "Scene transform"
    )]
    pub(crate) scale_scene: Option<String>,
    /// Rotate the scene about the origin by DEG degrees around the axis X,Y,Z (right-hand
    /// rule), after the scale; repeat to chain rotations in the order given.
    #[arg(
        long,
        value_name = "X,Y,Z,DEG",
        allow_hyphen_values = true,
        help_heading = "Scene transform"
    )]
    pub(crate) rotate: Vec<String>,
    /// Translate the scene by X,Y,Z, last. The filters (--crop) and the cameras see the
    /// transformed scene.
    #[arg(
        long,
        value_name = "X,Y,Z",
        allow_hyphen_values = true,
        help_heading = "Scene transform"
    )]
    pub(crate) translate: Option<String>,
}

impl TransformArgs {
    /// The transform the flags ask for, checked; `None` when no flag is given.
    pub(crate) fn transform(&self) -> Result<Option<SceneTransform>> {
        let flips = self.flip_x || self.flip_y || self.flip_z;
        if !flips
            && self.scale_scene.is_none()
            && self.rotate.is_empty()
            && self.translate.is_none()
        {
            return Ok(None);
        }
        let mut t = SceneTransform::flip_axes(self.flip_x, self.flip_y, self.flip_z);
        if let Some(text) = &self.scale_scene {
            let s = numbers("--scale-scene", text, "S", 1)?[0];
            t = t.then(
                &SceneTransform::scaling(s).map_err(|e| flag_error("--scale-scene", text, e))?,
            );
        }
        for text in &self.rotate {
            let v = numbers("--rotate", text, "X,Y,Z,DEG", 4)?;
            let r = SceneTransform::rotation([v[0], v[1], v[2]], v[3])
                .map_err(|e| flag_error("--rotate", text, e))?;
            t = t.then(&r);
        }
        if let Some(text) = &self.translate {
            let v = numbers("--translate", text, "X,Y,Z", 3)?;
            let tr = SceneTransform::translation([v[0], v[1], v[2]])
                .map_err(|e| flag_error("--translate", text, e))?;
            t = t.then(&tr);
        }
        Ok(Some(t))
    }
}

/// Applies `transform` (when there is one) to a loaded scene and says so on stderr.
pub(crate) fn apply(transform: Option<&SceneTransform>, scene: Scene) -> Result<Scene> {
    let Some(t) = transform else {
        return Ok(scene);
    };
    let n = scene.len();
    let out = t.apply(scene).map_err(anyhow::Error::msg)?;
    verisplat::core::console::note!("transformed: {} by {t}", super::plural(n, "Gaussian"));
    Ok(out)
}

fn flag_error(flag: &str, text: &str, e: String) -> anyhow::Error {
    anyhow!("{flag} {text}: {e}")
}

/// `count` comma-separated numbers (finiteness is checked by the transform's constructors).
fn numbers(flag: &str, text: &str, form: &str, count: usize) -> Result<Vec<f64>> {
    let v: Option<Vec<f64>> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>().ok())
        .collect();
    match v {
        Some(v) if v.len() == count => Ok(v),
        _ => Err(anyhow!(
            "{flag} expects {form} ({count} number{}), got \"{text}\"",
            if count == 1 { "" } else { "s" }
        )),
    }
}
