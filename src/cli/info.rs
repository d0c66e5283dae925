//! `verisplat info`: a scene's size, bounds and parameter statistics (or what a camera
//! file holds), as text or JSON.

use super::common::{load_scene, SceneArg};
use super::plural;
use anyhow::Result;
use clap::Args;
use serde_json::json;
use verisplat::core::console::outln;
use verisplat::core::scene;
use verisplat::io;

#[derive(Args)]
#[command(after_help = "Examples:
  verisplat info scene.ply
  verisplat info model_dir/ --json > stats.json
  verisplat info cameras.json")]
pub(crate) struct InfoArgs {
    #[command(flatten)]
    pub(crate) scene: SceneArg,
    /// Print the statistics as JSON (for scripts) instead of text.
    #[arg(long)]
    pub(crate) json: bool,
    /// Feature channels to attach first: an N x K NumPy array (as `render --features`).
    #[arg(long, value_name = "FILE.npy")]
    pub(crate) features: Option<std::path::PathBuf>,
}

pub(crate) fn fmt3(v: [f32; 3]) -> String {
    format!("({:.4}, {:.4}, {:.4})", v[0], v[1], v[2])
}

pub(crate) fn info(args: &InfoArgs) -> Result<()> {
    let arg = &args.scene;
    let (scene, name, format) = match arg.scene.as_deref() {
        Some(path) if !arg.demo => match io::scene::resolve_scene_path_at(path, arg.iteration)
            .and_then(|file| {
                Ok((
                    io::scene::detect::load_with_axes(&file, arg.spz.axes)?,
                    file,
                ))
            }) {
            Ok(((scene, format), file)) => (scene, file.display().to_string(), Some(format)),
            // A camera file given where a scene belongs: say what it holds.
            Err(e) => match verisplat::io::camera::detect_camera_format(path) {
                Ok(_) => return camera_file_info(path, args.json),
                Err(_) => return Err(e.into()),
            },
        },
        _ => {
            let (scene, name) = load_scene(arg)?;
            (scene, name, None)
        }
    };
    let mut scene = scene;
    if let Some(file) = &args.features {
        scene::features::attach_npy(&mut scene, file)?;
    }
    if args.json {
        return print_json(&scene, &name, format.map(|f| f.to_string()));
    }
    let s = verisplat::app::stats::scene_stats(&scene);
    outln!("scene       {name}");
    if let Some(format) = format {
        outln!("format      {format}");
        if matches!(format, io::scene::SceneFormat::Spz { .. }) {
            outln!("axes        read in {}", arg.spz.axes.describe());
        }
        if scene.antialiased {
            outln!("antialiased yes: the file records antialiased training (rendered with the compensation by default)");
        }
    }
    if scene.kernel == verisplat::cpu::SplatKernel::Gaussian {
        outln!("kernel      gaussian");
    } else {
        outln!(
            "kernel      {}: the file records it (rendered with it by default; --kernel overrides)",
            scene.kernel
        );
    }
    if scene.mip_filter {
        outln!("mip filter  3d: Mip-Splatting's 3D filter is folded into the scales and opacities (train --mip-filter)");
    }
    if scene.rules != verisplat::cpu::Rules::Original {
        outln!(
            "rules       {}: the file records that it was trained with them (rendered with them by default; --rules overrides)",
            scene.rules
        );
    }
    outln!("gaussians   {}", s.count);
    outln!(
        "sh degree   {} ({} per channel)",
        s.sh_degree,
        plural(scene.sh_coeffs(), "coefficient")
    );
    if scene.feature_count > 0 {
        outln!(
            "features    {} per Gaussian",
            plural(scene.feature_count, "channel")
        );
    }
    if let Some((lo, hi)) = scene.time_range() {
        let (slo, shi) = time_scales(&scene);
        outln!(
            "time        temporal means {lo} .. {hi}, temporal scales {slo} .. {shi} (render with --time T or --time-range T0,T1)"
        );
    }
    if let Some((lo, hi)) = s.bounds {
        outln!("bounds      min {}  max {}", fmt3(lo), fmt3(hi));
    }
    outln!(
        "bulk        median {}, radius {:.4} (95% of centres within the median's), 2-98% box {} .. {} centred at {} (where the default camera and --orbit look)",
        fmt3(s.bulk.centre.into()),
        s.bulk.radius,
        fmt3(s.bulk.lo.into()),
        fmt3(s.bulk.hi.into()),
        fmt3(s.bulk.box_centre().into())
    );
    outln!();
    outln!(
        "{:<28} {:>12} {:>12} {:>12} {:>12}",
        "quantity",
        "min",
        "max",
        "mean",
        "std"
    );
    for (label, v) in [
        ("scale (exp, all axes)", s.scale),
        ("max scale per Gaussian", s.max_scale),
        ("log scale (stored)", s.log_scale),
        ("opacity (sigmoid)", s.opacity),
        ("opacity logit (stored)", s.opacity_logit),
    ] {
        outln!(
            "{label:<28} {:>12.6} {:>12.6} {:>12.6} {:>12.6}",
            v.min,
            v.max,
            v.mean,
            v.std
        );
    }
    print_histogram(
        "largest scale per Gaussian (world units); 'kept' = share kept by --max-scale <bin end>",
        &s.max_scale_histogram,
        true,
    );
    print_histogram(
        "opacity (after the sigmoid); 'kept' = share kept by --min-opacity <bin start>",
        &s.opacity_histogram,
        false,
    );
    if scene.feature_count > 0 {
        outln!();
        outln!(
            "{:<28} {:>12} {:>12} {:>12}",
            "feature channel",
            "min",
            "mean",
            "max"
        );
        for (k, [min, mean, max]) in scene::features::channel_stats(&scene).iter().enumerate() {
            outln!(
                "{:<28} {min:>12.6} {mean:>12.6} {max:>12.6}",
                format!("feat_{k}")
            );
        }
    }
    Ok(())
}

/// Prints a log-binned histogram as text bars with the share a threshold at each bin
/// edge keeps (below the bin's end for `upper`, from the bin's start otherwise).
pub(crate) fn print_histogram(title: &str, h: &verisplat::app::stats::Histogram, upper: bool) {
    outln!();
    outln!("{title}");
    if h.counts.is_empty() {
        outln!("  (no positive values)");
        return;
    }
    let peak = h.counts.iter().copied().max().unwrap_or(1).max(1);
    let total = h.total.max(1) as f64;
    let mut below = 0usize;
    let above_all: usize = h.counts.iter().sum();
    for (i, &c) in h.counts.iter().enumerate() {
        let kept = if upper { below + c } else { above_all - below };
        below += c;
        let bar = "#".repeat((c * 40).div_ceil(peak));
        outln!(
            "  [{:>9}, {:>9})  {c:>10}  kept {:>6.2} %  {bar}",
            format!("{:.3e}", h.edges[i]),
            format!("{:.3e}", h.edges[i + 1]),
            100.0 * kept as f64 / total,
        );
    }
    if h.outside > 0 {
        outln!("  zero, negative or not finite: {}", h.outside);
    }
}

/// What a camera file holds: its format, the number of cameras, their resolutions and
/// the first names.
fn camera_file_info(path: &std::path::Path, json: bool) -> Result<()> {
    let (cams, format) = verisplat::io::camera::load_camera_file(
        path,
        &verisplat::io::camera::PathTiming::default(),
    )?;
    let mut sizes: Vec<(u32, u32)> = cams.iter().map(|c| (c.width, c.height)).collect();
    sizes.sort_unstable();
    sizes.dedup();
    let names: Vec<&str> = cams.iter().take(5).map(|c| c.name.as_str()).collect();
    let lenses: Vec<String> = cams.iter().map(|c| lens_model(&c.lens)).collect();
    // Each model once, in the order of first appearance, with its count.
    let mut models: Vec<(&str, usize)> = Vec::new();
    for l in &lenses {
        match models.iter_mut().find(|(m, _)| m == l) {
            Some((_, n)) => *n += 1,
            None => models.push((l, 1)),
        }
    }
    if json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "path": path.display().to_string(),
                "kind": "cameras",
                "format": format.to_string(),
                "cameras": cams.len(),
                "resolutions": sizes.iter().map(|(w, h)| [w, h]).collect::<Vec<_>>(),
                "names": cams.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(),
                "lenses": lenses,
            }))?
        );
        return Ok(());
    }
    outln!(
        "{} is a camera file, not a scene: render a scene with --cameras {}",
        path.display(),
        path.display()
    );
    outln!("format      {format}");
    outln!("cameras     {}", cams.len());
    outln!(
        "resolution  {}",
        sizes
            .iter()
            .map(|(w, h)| format!("{w}x{h}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    outln!(
        "lens        {}",
        models
            .iter()
            .map(|(m, n)| if models.len() == 1 {
                m.to_string()
            } else {
                format!("{m} ({n})")
            })
            .collect::<Vec<_>>()
            .join(", ")
    );
    outln!(
        "names       {}{}",
        names.join(", "),
        if cams.len() > names.len() {
            ", ..."
        } else {
            ""
        }
    );
    Ok(())
}

/// A camera's lens as `info` names it: `pinhole`, `distorted (OPENCV)` or `distorted
/// (FULL_OPENCV)` (the COLMAP model that holds its coefficients), `fisheye` (with its field
/// of view when it stops short of 360 degrees), `orthographic`, `equirectangular` (with
/// its window when it is not the whole sphere).
fn lens_model(lens: &verisplat::core::camera::Lens) -> String {
    use verisplat::core::camera::Lens;
    // Degrees to 4 decimals, without trailing zeros.
    let deg = |r: f64| ((r.to_degrees() * 1e4).round() / 1e4 + 0.0).to_string();
    match lens {
        Lens::RadialTangential { radial, .. } if radial[2..].iter().all(|&k| k == 0.0) => {
            "distorted (OPENCV)".into()
        }
        Lens::RadialTangential { .. } => "distorted (FULL_OPENCV)".into(),
        Lens::Fisheye { max_theta, .. } if *max_theta < std::f64::consts::PI => {
            format!("fisheye ({} degrees)", deg(2.0 * max_theta))
        }
        Lens::Equirectangular {
            longitude,
            latitude,
        } if *lens != Lens::FULL_SPHERE => format!(
            "equirectangular (longitude {}..{}, latitude {}..{} degrees)",
            deg(longitude[0]),
            deg(longitude[1]),
            deg(latitude[0]),
            deg(latitude[1])
        ),
        other => other.name().into(),
    }
}

/// The statistics as one JSON object (`schema_version` 1).
fn print_json(scene: &scene::Scene, name: &str, format: Option<String>) -> Result<()> {
    let s = verisplat::app::stats::scene_stats(scene);
    let summary = |v: verisplat::app::stats::Summary| json!({"min": v.min, "max": v.max, "mean": v.mean, "std": v.std});
    let histogram = |h: &verisplat::app::stats::Histogram| json!({"edges": h.edges, "counts": h.counts, "outside": h.outside, "total": h.total});
    let v3 = |v: glam::Vec3| [v.x, v.y, v.z];
    let value = json!({
        "schema_version": 1,
        "scene": name,
        "format": format,
        "antialiased": scene.antialiased,
        "kernel": scene.kernel.name(),
        "rules": scene.rules.name(),
        "mip_filter": scene.mip_filter,
        "feature_channels": scene.feature_count,
        "time": scene.time_range().map(|(lo, hi)| {
            let (slo, shi) = time_scales(scene);
            json!({"t_mean": [lo, hi], "t_scale": [slo, shi]})
        }),
        "features": scene::features::channel_stats(scene)
            .iter()
            .map(|[min, mean, max]| json!({"min": min, "max": max, "mean": mean}))
            .collect::<Vec<_>>(),
        "gaussians": s.count,
        "sh_degree": s.sh_degree,
        "bounds": s.bounds.map(|(lo, hi)| json!({"min": lo, "max": hi})),
        "bulk": {
            "median": v3(s.bulk.centre),
            "radius_95": s.bulk.radius,
            "box_2_98": {"min": v3(s.bulk.lo), "max": v3(s.bulk.hi), "centre": v3(s.bulk.box_centre())},
        },
        "scale": summary(s.scale),
        "max_scale": summary(s.max_scale),
        "log_scale": summary(s.log_scale),
        "opacity": summary(s.opacity),
        "opacity_logit": summary(s.opacity_logit),
        "max_scale_histogram": histogram(&s.max_scale_histogram),
        "opacity_histogram": histogram(&s.opacity_histogram),
    });
    outln!("{}", serde_json::to_string_pretty(&value)?);
    Ok(())
}

/// The smallest and largest temporal scale (`exp(t_scale)`) of a time-varying scene.
fn time_scales(scene: &scene::Scene) -> (f32, f32) {
    scene
        .time
        .iter()
        .flatten()
        .fold((f32::INFINITY, 0f32), |(a, b), v| {
            (a.min(v[1].exp()), b.max(v[1].exp()))
        })
}
