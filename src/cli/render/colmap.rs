//! `render --export-colmap DIR`: the selected cameras rendered into a COLMAP data set to
//! train on.

use super::args::RenderArgs;
use crate::cli::common::fail_on_validation_messages;
use crate::cli::plural;
use anyhow::{bail, Result};
use std::path::Path;
use verisplat::core::camera::Camera;
use verisplat::core::console::outln;
use verisplat::render::GpuRenderer;
use verisplat::render::{FrameRequest, Rendered};

/// Points3D written by `--export-colmap` at most.
const EXPORT_COLMAP_POINTS: usize = 100_000;

/// `--export-colmap DIR`: the selected cameras rendered (on the device, or the CPU
/// reference with --cpu or --shader) into a COLMAP data set.
pub(super) fn export_colmap(
    args: &RenderArgs,
    dir: &Path,
    scene: &verisplat::core::scene::Scene,
    name: &str,
    cameras: &[(usize, Camera)],
    shader: Option<&verisplat::fields::mlp::Mlp>,
) -> Result<()> {
    let cams: Vec<Camera> = cameras
        .iter()
        .filter(|(k, _)| args.frames.as_ref().map_or(true, |f| f.contains(*k)))
        .map(|(_, c)| c.clone())
        .collect();
    if cams.is_empty() {
        bail!("--export-colmap: no cameras selected");
    }
    let stride = scene.len().div_ceil(EXPORT_COLMAP_POINTS).max(1);
    let opts = verisplat::cpu::RenderOptions {
        background: args.background,
        scale_modifier: args.scale_modifier,
        kernel: args.kernel.resolve(scene, name),
        rules: args.kernel.resolve_rules(scene, name),
        reproducible: args.kernel.reproducible,
        ..Default::default()
    };
    let t = std::time::Instant::now();
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(cams.len() as u64)
    };
    let act = scene.activated();
    // The device renders unless --cpu or a shader (shaded on the CPU) asks otherwise.
    let mut gpu = if args.cpu || shader.is_some() {
        None
    } else {
        let renderer = GpuRenderer::new(args.gpu.context()?)?;
        let gpu_scene = renderer.upload(&act)?;
        Some((renderer, gpu_scene))
    };
    let how = if gpu.is_some() {
        "on the device"
    } else {
        "with the CPU reference"
    };
    verisplat::train::data::write_dataset(dir, scene, &cams, stride, args.overwrite, &mut |cam| {
        bar.inc(1);
        match (&mut gpu, shader) {
            (Some((renderer, gpu_scene)), _) => renderer
                .render(&FrameRequest::new(gpu_scene, cam, &opts))
                .and_then(Rendered::into_frame)
                .map_err(|e| e.to_string()),
            (None, Some(mlp)) => {
                let mut frame = verisplat::cpu::render_features(&act, cam, &opts);
                frame.color = verisplat::fields::mlp::shade(
                    mlp,
                    cam,
                    &frame.features,
                    scene.feature_count,
                    &frame.alpha,
                    opts.background,
                );
                Ok(frame)
            }
            (None, None) => Ok(verisplat::cpu::render(&act, cam, &opts)),
        }
    })?;
    if let Some((renderer, gpu_scene)) = gpu {
        drop(gpu_scene);
        fail_on_validation_messages(renderer.ctx())?;
    }
    bar.finish_and_clear();
    outln!(
        "wrote a COLMAP data set of {name}: {} rendered {how} at {}x{} and {} ({}) in {:.2} s -> {}",
        plural(cams.len(), "image"),
        cams[0].width,
        cams[0].height,
        plural(scene.len().div_ceil(stride), "point"),
        if stride == 1 {
            "every Gaussian centre".to_string()
        } else {
            format!("one Gaussian centre in {stride}")
        },
        t.elapsed().as_secs_f64(),
        dir.display()
    );
    Ok(())
}
