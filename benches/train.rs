//! Training speed and memory: `verisplat train`'s loop ([`verisplat::train::run::train`]) on a
//! COLMAP data set made from a shared scene (rendered from orbit cameras by the CPU
//! reference; every 4th Gaussian centre as points3D), reporting iterations per second,
//! the Gaussians at the end and the device bytes per Gaussian at the peak: first with the
//! state on the device (the default), then with the host optimiser (each iteration uploads
//! the Gaussians and reads their gradients back), so the two are measured side by side.
//! `VERISPLAT_TRAIN_BENCH=device` (or `host`) runs one of them.
//!
//! `cargo bench --bench train` runs PLAYBOT LOD3 (31k Gaussians) at 320x240 for 500
//! iterations (densification from 100 every 100); under `cargo test` (no `--bench`
//! argument) LOD6 at 40x30 for 20 iterations, as a smoke test.

use verisplat::core::camera::orbit::{orbit, OrbitParams};
use verisplat::gpu::{ContextOptions, GpuContext};
use verisplat::render::backward::differentiable::DiffRasterizer;
use verisplat::train::{data, loss::GpuLoss, model::Settings, run};

fn main() {
    let full = std::env::args().any(|a| a == "--bench");
    let shared = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    let (file, w, h, iterations) = if full {
        ("playbot_lod3_31k_sh2.ply", 320, 240, 500)
    } else {
        ("playbot_lod6_1873_sh2.ply", 40, 30, 20)
    };
    let scene = verisplat::io::scene::load_with_format(&shared.join(file))
        .expect("a shared scene")
        .0;
    let cams = orbit(
        &scene.positions,
        &OrbitParams {
            frames: 24,
            width: w,
            height: h,
            elevation_deg: 15.0,
            ..Default::default()
        },
    )
    .expect("orbit cameras");
    let dir = tempfile::tempdir().expect("a temporary directory");
    let set = dir.path().join("data");
    data::write_rendered_dataset(&set, &scene, &cams, None, 4, false).expect("the data set");
    let dataset = data::load_colmap(&set, data::Resolution(1), true).expect("the data set");
    let ctx = GpuContext::new(&ContextOptions::default()).expect("a Vulkan device");
    let device = ctx.info().name.clone();
    let mut loss = GpuLoss::new(&ctx).expect("loss pipelines");
    let mut rast = DiffRasterizer::new(ctx).expect("rasterizer");
    let mut opts = run::TrainOptions {
        settings: Settings {
            iterations,
            densify_from_iter: 100,
            ..Settings::default()
        },
        ..Default::default()
    };
    let which = std::env::var("VERISPLAT_TRAIN_BENCH").unwrap_or_default();
    for host in [false, true] {
        if (which == "device" && host) || (which == "host" && !host) {
            continue;
        }
        opts.host_optimizer = host;
        let report = run::train(
            &dataset,
            &dir.path().join(if host { "model-host" } else { "model" }),
            &opts,
            &mut rast,
            &mut loss,
            &mut |_| {},
            &mut |_| {},
        )
        .expect("training");
        let peak = report.device_bytes_peak;
        let last = report
            .evaluations
            .last()
            .expect("the last iteration's evaluation");
        println!(
            "train ({}): {file} ({} Gaussians as {} points), {} views of {w}x{h}, {device}: {iterations} iterations at {:.1} it/s; {} Gaussians at the end; peak device memory {:.1} MB ({:.0} bytes per Gaussian at the end, loss buffers {:.1} MB); held-out PSNR {:.2} dB",
            if report.on_device { "state on the device" } else { "host optimiser" },
            scene.len(),
            dataset.points.as_ref().map_or(0, |p| p.len()),
            dataset.train.len(),
            report.iterations_per_second,
            report.gaussians,
            peak as f64 / 1e6,
            peak as f64 / report.gaussians.max(1) as f64,
            loss.device_bytes() as f64 / 1e6,
            last.psnr
        );
        println!(
            "  device ms per iteration: {}",
            report
                .stage_ms
                .iter()
                .map(|(n, ms)| format!("{n} {ms:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
}
