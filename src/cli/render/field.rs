//! `render --mode field-slice | field-integral | field-max`: the fitted field itself
//! (`verisplat::cpu::field` has the formulas), on the GPU (`render::field`) or with `--cpu`
//! the f64 reference; EXR and `.npy` hold the channels, a PNG one channel through the
//! turbo colour map (or the `--shader`), optionally with a labelled colour bar.

use super::args::RenderArgs;
use super::time::Animation;
use crate::cli::common::fail_on_validation_messages;
use anyhow::{bail, Result};
use std::path::Path;
use verisplat::app::sequence::{FramePlan, RunOptions, Summary};
use verisplat::core::camera::Camera;
use verisplat::core::console::note;
use verisplat::core::frame::Frame;
use verisplat::cpu::field::{FieldGaussians, FieldMode};
use verisplat::cpu::SplatKernel;
use verisplat::io::output::{self, RenderMode};

/// `field-slice` etc., for messages.
pub(crate) fn mode_name(mode: Option<RenderMode>) -> &'static str {
    match mode {
        Some(RenderMode::FieldSlice) => "field-slice",
        Some(RenderMode::FieldIntegral) => "field-integral",
        Some(RenderMode::FieldMax) => "field-max",
        _ => "",
    }
}

/// Whether the output is a PNG (the default, a `.png` name, or a folder with `--format
/// png`).
pub(crate) fn writes_png(args: &RenderArgs) -> bool {
    let Some(out) = &args.output else {
        return true;
    };
    match Path::new(out).extension() {
        Some(e) => e.eq_ignore_ascii_case("png"),
        None => args.format.as_deref().unwrap_or("png") == "png",
    }
}

/// Refuses field options without a field mode, options the mode ignores, and render
/// options that do not apply to the field.
pub(crate) fn check_options(args: &RenderArgs, mode: Option<RenderMode>) -> Result<()> {
    let f = &args.field;
    let png_only = [
        ("--channel", f.channel.is_some()),
        ("--range", f.range.is_some()),
        ("--colorbar", f.colorbar),
        ("--channel-name", f.channel_name.is_some()),
        ("--units", f.units.is_some()),
    ];
    let Some(mode) = mode else {
        let field_only = [
            ("--slice-plane", f.slice_plane.is_some()),
            ("--max-samples", f.max_samples.is_some()),
            ("--complex", f.complex.is_some()),
        ];
        if let Some((flag, _)) = field_only.iter().chain(&png_only).find(|(_, set)| *set) {
            bail!("{flag} applies to the field renders (--mode field-slice, field-integral or field-max)");
        }
        return Ok(());
    };
    let name = mode_name(Some(mode));
    if mode == RenderMode::FieldSlice && f.slice_plane.is_none() {
        bail!("--mode field-slice needs the plane: --slice-plane PX,PY,PZ,NX,NY,NZ (a point on it and its normal, e.g. --slice-plane 0,0,0,0,0,1 for z = 0)");
    }
    if mode != RenderMode::FieldSlice && f.slice_plane.is_some() {
        bail!("--slice-plane applies to --mode field-slice, not {name}");
    }
    if f.complex.is_some() && args.shader.is_some() {
        bail!("--complex colour-maps the magnitude; a --shader takes the channels themselves, so give one or the other");
    }
    if mode == RenderMode::FieldMax && f.complex.is_some() {
        bail!("--complex applies to field-slice and field-integral: the maximum of |f| along a ray needs the complex sum at every sample, which field-max does not keep (it takes each channel's maximum)");
    }
    if mode != RenderMode::FieldMax && f.max_samples.is_some() {
        bail!("--max-samples applies to --mode field-max, not {name}");
    }
    if !writes_png(args) {
        if let Some((flag, _)) = png_only.iter().find(|(_, set)| *set) {
            bail!("{flag} sets the colour map of a field render's PNG; EXR and .npy outputs hold every channel as it is");
        }
    }
    if (f.channel_name.is_some() || f.units.is_some()) && !f.colorbar {
        bail!("--channel-name and --units label the colour bar; add --colorbar");
    }
    for (flag, label) in [("--channel-name", &f.channel_name), ("--units", &f.units)] {
        let Some(label) = label else { continue };
        if let Some(c) = verisplat::io::font::undrawable(label) {
            bail!(
                "{flag} \"{label}\": the colour bar's font cannot draw '{c}' (U+{:04X}); it draws printable ASCII and {}",
                u32::from(c),
                verisplat::io::font::SYMBOLS
            );
        }
    }
    let ignored = [
        ("--scale-modifier", args.scale_modifier != 1.0),
        ("--antialiased", args.antialiased),
        ("--compact", args.compact),
        ("--exr-background", args.exr_background),
        ("--frames-in-flight", args.frames_in_flight.is_some()),
    ];
    if let Some((flag, _)) = ignored.iter().find(|(_, set)| *set) {
        bail!("{flag} does not apply to --mode {name}: the field is the fitted sum over the Gaussians as they are");
    }
    Ok(())
}

/// Renders `frames` of the field of `scene` (or with `animation`, of each frame's scene at
/// its time) under `mode` and writes them.
#[allow(clippy::too_many_arguments)]
pub(crate) fn render(
    args: &RenderArgs,
    scene: &verisplat::core::model::ActivatedScene,
    animation: Option<&Animation>,
    kernel: SplatKernel,
    mode: RenderMode,
    frames: &[FramePlan],
    run_opts: &RunOptions,
    shader: Option<&verisplat::fields::mlp::Mlp>,
) -> Result<(Summary, String)> {
    let f = &args.field;
    let field_mode = match mode {
        RenderMode::FieldSlice => {
            let p = f.slice_plane.unwrap_or([0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
            FieldMode::Slice {
                point: [p[0], p[1], p[2]],
                normal: [p[3], p[4], p[5]],
            }
        }
        RenderMode::FieldIntegral => FieldMode::Integral,
        _ => FieldMode::Max {
            samples: f.max_samples.unwrap_or(128),
        },
    };
    let g = FieldGaussians::new(scene, kernel);
    if let Some((i, q)) = f.complex {
        if i.max(q) >= g.k {
            bail!(
                "--complex {i},{q} names a channel the scene does not have (it has {}: 0 to {})",
                g.k,
                g.k - 1
            );
        }
    }
    // With --complex the frame has two more channels: |f| (K) and its phase (K + 1).
    let channels = g.k + if f.complex.is_some() { 2 } else { 0 };
    let channel = f
        .channel
        .unwrap_or(if f.complex.is_some() { g.k } else { 0 });
    if channel >= channels {
        bail!(
            "--channel {channel} is not a channel of the scene, which has {channels} (0 to {})",
            channels - 1
        );
    }
    let colours = Colours {
        png: writes_png(args),
        channel,
        range: f.range.and_then(|r| r.0),
        background: args.background,
        bar: f.colorbar.then(|| {
            let name = f
                .channel_name
                .clone()
                .unwrap_or_else(|| format!("feat_{channel}"));
            match &f.units {
                Some(u) => format!("{name} ({u})"),
                None => name,
            }
        }),
        bar_noted: false,
        shader,
        complex: f.complex,
    };
    let mut colours = colours;
    if let Some(anim) = animation {
        // Each frame the field at its time: the CPU reference, or uploaded to the device.
        let ctx = if args.cpu {
            None
        } else {
            Some(args.gpu.context()?)
        };
        let mut renderer = verisplat::render::field::FieldRenderer::new(kernel);
        let summary = verisplat::app::sequence::run_each(
            frames,
            &mut |p| {
                let g = FieldGaussians::new(&anim.scene(p.index), kernel);
                let frame = match &ctx {
                    None => verisplat::cpu::field::render_field(&g, &p.camera, &field_mode),
                    Some(ctx) => {
                        let gpu_field = verisplat::render::field::GpuField::new(ctx, &g)?;
                        renderer.render(ctx, &gpu_field, &p.camera, &field_mode)?
                    }
                };
                colours.apply(&p.camera, frame)
            },
            run_opts,
        )?;
        return Ok(match &ctx {
            None => (summary, "on the CPU (the f64 field reference)".into()),
            Some(ctx) => {
                fail_on_validation_messages(ctx)?;
                (summary, format!("on {}", ctx.info().name))
            }
        });
    }
    if args.cpu {
        let summary = verisplat::app::sequence::run(
            frames,
            &mut |cam| {
                colours.apply(
                    cam,
                    verisplat::cpu::field::render_field(&g, cam, &field_mode),
                )
            },
            run_opts,
        )?;
        return Ok((summary, "on the CPU (the f64 field reference)".into()));
    }
    let ctx = args.gpu.context()?;
    let gpu_field = verisplat::render::field::GpuField::new(&ctx, &g)?;
    let mut renderer = verisplat::render::field::FieldRenderer::new(kernel);
    let summary = verisplat::app::sequence::run(
        frames,
        &mut |cam| {
            let frame = renderer.render(&ctx, &gpu_field, cam, &field_mode)?;
            colours.apply(cam, frame)
        },
        run_opts,
    )?;
    fail_on_validation_messages(&ctx)?;
    Ok((summary, format!("on {}", ctx.info().name)))
}

/// How a field frame becomes a PNG's colour.
struct Colours<'a> {
    png: bool,
    channel: usize,
    /// Fixed, or set from the first frame (auto).
    range: Option<[f32; 2]>,
    background: [f32; 3],
    /// The colour bar's centre label, when there is a bar.
    bar: Option<String>,
    /// Whether a label too wide for the bar was noted.
    bar_noted: bool,
    shader: Option<&'a verisplat::fields::mlp::Mlp>,
    /// `--complex I,Q`: magnitude and phase appended.
    complex: Option<(usize, usize)>,
}

impl Colours<'_> {
    fn apply(&mut self, cam: &Camera, mut frame: Frame) -> Result<Frame> {
        if let Some((i, q)) = self.complex {
            verisplat::cpu::field::append_magnitude_phase(&mut frame, i, q);
        }
        if !self.png {
            return Ok(frame);
        }
        let k = frame.feature_count;
        if let Some(mlp) = self.shader {
            let features: Vec<f32> = frame
                .features
                .iter()
                .map(|v| if v.is_nan() { 0.0 } else { *v })
                .collect();
            frame.color = verisplat::fields::mlp::shade(
                mlp,
                cam,
                &features,
                k,
                &frame.alpha,
                self.background,
            );
            return Ok(frame);
        }
        let range = match self.range {
            Some(r) => r,
            None => {
                let r = output::field_auto_range(&frame, self.channel).unwrap_or([0.0, 1.0]);
                note!(
                    "colour map range {} to {} (auto: the 1st to 99th percentile of channel {} in the first frame; --range LO,HI fixes it)",
                    r[0],
                    r[1],
                    self.channel
                );
                self.range = Some(r);
                r
            }
        };
        frame.color = output::field_colormap(&frame, self.channel, range, self.background);
        if let Some(label) = &self.bar {
            let (w, h) = (frame.width as usize, frame.height as usize);
            let lo = verisplat::io::diff_image::label_number(f64::from(range[0]));
            let hi = verisplat::io::diff_image::label_number(f64::from(range[1]));
            let drawn = verisplat::io::diff_image::append_colour_bar(
                &mut frame.color,
                w,
                h,
                [&lo, label, &hi],
            );
            if !drawn && !self.bar_noted {
                note!(
                    "the colour bar's label \"{label}\" does not fit the {w}-pixel-wide image and is left out; render it wider (--width)"
                );
                self.bar_noted = true;
            }
            frame.height += verisplat::io::diff_image::BAR_HEIGHT;
            let n = frame.color.len();
            frame.alpha.resize(n, 1.0);
            frame.depth.resize(n, 0.0);
            frame.features.clear();
            frame.feature_count = 0;
        }
        Ok(frame)
    }
}
