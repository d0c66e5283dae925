//! `vksplat info`: a scene's size, bounds and parameter statistics.

use super::common::{load_scene, SceneArg};
use anyhow::Result;
use vksplat::scene;

pub(crate) fn fmt3(v: [f32; 3]) -> String {
    format!("({:.4}, {:.4}, {:.4})", v[0], v[1], v[2])
}

pub(crate) fn info(arg: &SceneArg) -> Result<()> {
    let (scene, name, format) = match arg.scene.as_deref() {
        Some(path) if !arg.demo => {
            let file = scene::resolve_scene_path_at(path, arg.iteration)?;
            let (scene, format) = scene::load_with_format(&file)?;
            let name = file.display().to_string();
            (scene, name, Some(format))
        }
        _ => {
            let (scene, name) = load_scene(arg)?;
            (scene, name, None)
        }
    };
    let s = vksplat::stats::scene_stats(&scene);
    println!("scene       {name}");
    if let Some(format) = format {
        println!("format      {format}");
        if scene.antialiased {
            println!("antialiased yes: the file records antialiased training (rendered with the compensation by default)");
        }
    }
    println!("gaussians   {}", s.count);
    println!(
        "sh degree   {} ({} coefficients per channel)",
        s.sh_degree,
        scene.sh_coeffs()
    );
    if let Some((lo, hi)) = s.bounds {
        println!("bounds      min {}  max {}", fmt3(lo), fmt3(hi));
    }
    println!(
        "bulk        centre {} (per-axis median), radius {:.4} (95% of centres within), 2-98% box {} .. {}",
        fmt3(s.bulk.centre.into()),
        s.bulk.radius,
        fmt3(s.bulk.lo.into()),
        fmt3(s.bulk.hi.into())
    );
    println!();
    println!(
        "{:<28} {:>12} {:>12} {:>12} {:>12}",
        "quantity", "min", "max", "mean", "std"
    );
    for (label, v) in [
        ("scale (exp, all axes)", s.scale),
        ("max scale per Gaussian", s.max_scale),
        ("log scale (stored)", s.log_scale),
        ("opacity (sigmoid)", s.opacity),
        ("opacity logit (stored)", s.opacity_logit),
    ] {
        println!(
            "{label:<28} {:>12.6} {:>12.6} {:>12.6} {:>12.6}",
            v.min, v.max, v.mean, v.std
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
    Ok(())
}

/// Prints a log-binned histogram as text bars with the share a threshold at each bin
/// edge keeps (below the bin's end for `upper`, from the bin's start otherwise).
pub(crate) fn print_histogram(title: &str, h: &vksplat::stats::Histogram, upper: bool) {
    println!();
    println!("{title}");
    if h.counts.is_empty() {
        println!("  (no positive values)");
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
        println!(
            "  [{:>9}, {:>9})  {c:>10}  kept {:>6.2} %  {bar}",
            format!("{:.3e}", h.edges[i]),
            format!("{:.3e}", h.edges[i + 1]),
            100.0 * kept as f64 / total,
        );
    }
    if h.outside > 0 {
        println!("  zero, negative or not finite: {}", h.outside);
    }
}
