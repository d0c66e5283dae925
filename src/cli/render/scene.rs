//! The scene `verisplat render` draws: loaded with its feature channels, checked against the
//! render mode and `--shader`, transformed and filtered, shown at `--time` (or animated
//! over `--time-range`), and the render options it implies.

use super::args::RenderArgs;
use super::field;
use super::time::{time_choice, Animation, TimeChoice};
use crate::cli::common::{load_scene, CameraPath};
use crate::cli::plural;
use anyhow::{bail, Result};
use verisplat::core::console::note;
use verisplat::core::scene::Scene;
use verisplat::io::output::{self, RenderMode};

/// The loaded scene and what the options ask of it.
pub(super) struct Loaded {
    /// Transformed and filtered; still time-varying when it is.
    pub(super) scene: Scene,
    /// Its name, for messages.
    pub(super) name: String,
    /// How `--time` / `--time-range` apply.
    pub(super) time: TimeChoice,
    /// A field mode (`--mode field-*`), if one renders.
    pub(super) field_mode: Option<RenderMode>,
    /// `--mode features`: the feature channels are written.
    pub(super) render_features: bool,
    /// `--shader`: the neural shader colouring the feature channels.
    pub(super) shader: Option<verisplat::fields::mlp::Mlp>,
}

/// Loads the scene (with `--features`), checks the mode, time and shader options against
/// it, and applies `--transform` and the filters.
pub(super) fn load(args: &RenderArgs) -> Result<Loaded> {
    let filter = args.filter.filter()?;
    let transform = args.transform.transform()?;
    let (mut scene, name) = load_scene(&args.scene)?;
    if let Some(file) = &args.features {
        verisplat::core::scene::features::attach_npy(&mut scene, file)?;
    }
    let time = time_choice(args, &scene, &name)?;
    let field_mode = args.mode.filter(|m| m.is_field());
    field::check_options(args, field_mode)?;
    if field_mode.is_some() && scene.feature_count == 0 {
        bail!("--mode {} renders the fitted field, its feature channels, but {name} has none; fit one with `verisplat fit` or give channels with --features FILE.npy", field::mode_name(field_mode));
    }
    let render_features = args.mode == Some(output::RenderMode::Features);
    if render_features && scene.feature_count == 0 {
        bail!("--mode features needs feature channels, but {name} has none; give them as feat_* PLY properties or with --features FILE.npy");
    }
    let shader = load_shader(args, &scene, &name, render_features, field_mode)?;
    let scene = crate::cli::transform::apply(transform.as_ref(), scene)?;
    let total = scene.len();
    let scene = if filter.is_identity_for(&scene) {
        scene
    } else {
        let kept = filter.apply(&scene);
        note!(
            "filters keep {} of {total} Gaussians (SH degree {})",
            kept.len(),
            kept.sh_degree
        );
        kept
    };
    Ok(Loaded {
        scene,
        name,
        time,
        field_mode,
        render_features,
        shader,
    })
}

/// `--shader`, checked against the mode, the output and the scene's feature channels.
fn load_shader(
    args: &RenderArgs,
    scene: &Scene,
    name: &str,
    render_features: bool,
    field_mode: Option<RenderMode>,
) -> Result<Option<verisplat::fields::mlp::Mlp>> {
    Ok(match &args.shader {
        Some(path) => {
            if render_features {
                bail!("--shader writes the shaded colour and --mode features the feature channels; choose one");
            }
            if let Some(mode) = args.mode.filter(|m| m.is_surface()) {
                let name = if mode == RenderMode::Normal {
                    "normal"
                } else {
                    "median-depth"
                };
                bail!("--shader writes the shaded colour and --mode {name} the surface pass; choose one");
            }
            if field_mode.is_some() && !field::writes_png(args) {
                bail!("--shader colours a field render's PNG; EXR and .npy outputs hold the channels themselves");
            }
            let mlp = verisplat::fields::mlp::Mlp::load(path)?;
            mlp.check_channels(scene.feature_count)
                .map_err(|e| anyhow::anyhow!("{}: {e} ({name})", path.display()))?;
            Some(mlp)
        }
        None => None,
    })
}

/// The scene as `time` shows it: itself, at one time, or (`--time-range`) itself with the
/// animation over `path`'s frames.
pub(super) fn at_time(
    args: &RenderArgs,
    time: TimeChoice,
    scene: Scene,
    path: &mut CameraPath,
) -> Result<(Scene, Option<Animation>)> {
    let mut animation = None;
    let scene = match time {
        TimeChoice::Static => scene,
        TimeChoice::At(t) => {
            let at = scene.at_time(t);
            note!(
                "at time {t}: {} of {} contribute (within 4 temporal scales)",
                at.len(),
                plural(scene.len(), "Gaussian")
            );
            at
        }
        TimeChoice::Range(range) => {
            animation = Some(Animation::new(args, range, path, scene.clone())?);
            scene
        }
    };
    Ok((scene, animation))
}

/// The render options: background, antialiasing (the scene's own, noted, unless
/// `--no-antialiased`), scale modifier and kernel.
pub(super) fn render_options(
    args: &RenderArgs,
    scene: &Scene,
    name: &str,
) -> verisplat::cpu::RenderOptions {
    let antialiased = args.antialiased || (scene.antialiased && !args.no_antialiased);
    if scene.antialiased && !args.antialiased && !args.no_antialiased {
        note!(
            "note: {name} records that it was trained with antialiasing; rendering with its opacity compensation (--no-antialiased turns it off)"
        );
    }
    verisplat::cpu::RenderOptions {
        background: args.background,
        antialiased,
        scale_modifier: args.scale_modifier,
        kernel: args.kernel.resolve(scene, name),
        rules: args.kernel.resolve_rules(scene, name),
        reproducible: args.kernel.reproducible,
        ..Default::default()
    }
}
