//! The backward benchmark (`verisplat bench --backward`): forward and backward timings of the
//! differentiable rasterizer on one camera, its report and that report's text and JSON.

use super::camera::{BenchCamera, CameraReport};
use super::{push_stage_samples, stage_reports, StageReport, Stat, JSON_SCHEMA_VERSION};
use crate::core::model::{ActivatedScene, RenderOptions};
use crate::gpu::GpuResult;
use crate::render::backward::BackwardRequest;
use crate::render::FrameRequest;
use crate::render::GpuRenderer;
use serde::Serialize;

/// Forward and backward timings of the differentiable rasterizer on one camera
/// (`verisplat bench --backward`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BackwardReport {
    /// Scene name.
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: u64,
    /// The camera that was timed.
    pub camera: CameraReport,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Device name.
    pub device: String,
    /// Driver name and version.
    pub driver: String,
    /// The alpha falloff (`gaussian` or `power`).
    pub kernel: String,
    /// Run in the reproducible mode (`--reproducible`).
    pub reproducible: bool,
    /// How per-pair gradients are summed (`deterministic`, `float-atomics`, `cas`).
    pub accumulation: String,
    /// Feature channels differentiated instead of the colour (0: the SH colour).
    pub feature_channels: usize,
    /// The neural shader the feature channels were shaded with, as its layer widths
    /// (e.g. "8-64-64-3"); its backward pass is the `shade_bwd` stage.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shader: Option<String>,
    /// Measured iterations (forward + backward each).
    pub iterations: usize,
    /// Discarded warm-up iterations.
    pub warmup: usize,
    /// Forward stages (device timestamps), in pipeline order.
    pub forward_stages: Vec<StageReport>,
    /// Forward frame, first timestamp to last, ms.
    pub forward_ms: Stat,
    /// Backward stages (device timestamps), in order.
    pub backward_stages: Vec<StageReport>,
    /// Backward pass, first timestamp to last, ms.
    pub backward_ms: Stat,
    /// Median backward over median forward.
    pub backward_over_forward: f64,
    /// Wall clock of a whole iteration (upload of the pixel gradients and read-back of the
    /// Gaussians' included), ms.
    pub iteration_wall_ms: Stat,
    /// (bin, Gaussian) pairs of the frame.
    pub pairs: u64,
    /// Device memory held at the peak (scene, frame and backward buffers), bytes.
    pub device_bytes_peak: u64,
    /// `device_bytes_peak` per Gaussian.
    pub device_bytes_per_gaussian: f64,
    /// Of which the backward pass's own buffers, bytes.
    pub backward_device_bytes: u64,
    /// The bands of pixel rows and of sorted pairs the backward pass ran in, to fit the
    /// device's storage bindings ([1, 1]: in one piece).
    pub backward_bands: [usize; 2],
}

/// Times `iterations` forward + backward passes of `scene` from `camera` (after `warmup`
/// more) with fixed pseudo-random pixel gradients (those of an L1 loss have the same
/// cost: the pass's work does not depend on the values).
#[allow(clippy::too_many_arguments)]
pub fn bench_backward(
    renderer: &mut GpuRenderer,
    scene: &ActivatedScene,
    name: &str,
    camera: &BenchCamera,
    opts: &RenderOptions,
    shader: Option<&crate::fields::mlp::Mlp>,
    iterations: usize,
    warmup: usize,
) -> GpuResult<BackwardReport> {
    use crate::core::model::grad::PixelGrads;
    let cam = &camera.camera;
    renderer.set_save_forward_state(true);
    let gpu_scene = renderer.upload(scene)?;
    // A scene with feature channels differentiates those (blended without a background).
    let k = scene.feature_count;
    let gpu_features = if k > 0 {
        Some(renderer.upload_features(scene)?)
    } else {
        None
    };
    let features = (k > 0).then_some((scene.features.as_slice(), k));
    // A shader turns the channels into colour: the pixels' gradients are the colour's.
    let gpu_shader = match (shader, &gpu_features) {
        (Some(m), Some(_)) => Some(crate::render::forward::shade::GpuShader::new(
            renderer.ctx(),
            m,
        )?),
        (Some(_), None) => {
            return Err(crate::gpu::GpuError::InvalidArgument(
                "a shader shades feature channels, and the scene has none".into(),
            ))
        }
        (None, _) => None,
    };
    let channels = if k > 0 && gpu_shader.is_none() { k } else { 3 };
    let pixels = (cam.width * cam.height) as usize;
    let mut rng = crate::core::gen::Rng(7);
    let scale = 1.0 / pixels as f32;
    let grads = PixelGrads {
        color: (0..pixels * channels)
            .map(|_| scale * rng.range(-1.0, 1.0))
            .collect(),
        alpha: (0..pixels).map(|_| scale * rng.range(-1.0, 1.0)).collect(),
        depth: Vec::new(),
    };
    let (mut fwd_samples, mut bwd_samples) = (Vec::new(), Vec::new());
    let (mut fwd, mut bwd, mut wall) = (Vec::new(), Vec::new(), Vec::new());
    let mut peak = 0u64;
    for i in 0..warmup + iterations {
        let t = std::time::Instant::now();
        match (&gpu_features, &gpu_shader, features) {
            (Some(f), Some(s), Some(values)) => {
                let rendered =
                    renderer.render(&FrameRequest::new(&gpu_scene, cam, opts).shaded(f, s))?;
                let forward = rendered.forward();
                let frame = rendered.into_frame()?;
                let (values, k) = values;
                let req = BackwardRequest::new(&forward, &gpu_scene, &frame, &grads).shaded(
                    values,
                    k,
                    s,
                    cam,
                    opts.background,
                );
                std::hint::black_box(renderer.backward(&req)?);
            }
            (Some(f), _, _) => {
                let rendered =
                    renderer.render(&FrameRequest::new(&gpu_scene, cam, opts).features(f))?;
                let forward = rendered.forward();
                let frame = rendered.into_frame()?;
                let mut req = BackwardRequest::new(&forward, &gpu_scene, &frame, &grads);
                if let Some((values, k)) = features {
                    req = req.features(values, k);
                }
                std::hint::black_box(renderer.backward(&req)?);
            }
            _ => {
                let rendered = renderer.render(&FrameRequest::new(&gpu_scene, cam, opts))?;
                let forward = rendered.forward();
                let frame = rendered.into_frame()?;
                let req = BackwardRequest::new(&forward, &gpu_scene, &frame, &grads);
                std::hint::black_box(renderer.backward(&req)?);
            }
        }
        let elapsed = t.elapsed().as_secs_f64() * 1e3;
        peak = peak.max(renderer.ctx().live_allocations().1);
        if i < warmup {
            continue;
        }
        wall.push(elapsed);
        fwd.push(renderer.timings().total);
        push_stage_samples(&mut fwd_samples, renderer.timings().stages());
        bwd.push(renderer.backward_total_ms());
        let stages = renderer.backward_timings();
        push_stage_samples(
            &mut bwd_samples,
            stages.iter().map(|(s, ms)| (s.as_str(), *ms)),
        );
    }
    renderer.set_save_forward_state(false);
    let info = renderer.ctx().info();
    let (forward_ms, backward_ms) = (Stat::of(&fwd), Stat::of(&bwd));
    Ok(BackwardReport {
        scene: name.to_string(),
        gaussians: scene.len() as u64,
        camera: camera.report(),
        width: cam.width,
        height: cam.height,
        device: info.name.clone(),
        driver: info.driver.clone(),
        kernel: opts.kernel.to_string(),
        reproducible: opts.reproducible,
        accumulation: renderer.gradient_accumulation().name().to_string(),
        feature_channels: k,
        shader: shader.map(|m| {
            let mut widths = vec![m.layers[0].inputs.to_string()];
            widths.extend(m.layers.iter().map(|l| l.outputs.to_string()));
            widths.join("-")
        }),
        iterations,
        warmup,
        forward_stages: stage_reports(fwd_samples),
        forward_ms,
        backward_stages: stage_reports(bwd_samples),
        backward_ms,
        backward_over_forward: if forward_ms.median > 0.0 {
            backward_ms.median / forward_ms.median
        } else {
            0.0
        },
        iteration_wall_ms: Stat::of(&wall),
        pairs: renderer.stats().pairs,
        device_bytes_peak: peak,
        device_bytes_per_gaussian: peak as f64 / scene.len().max(1) as f64,
        backward_device_bytes: renderer.backward_device_bytes(),
        backward_bands: {
            let (rows, pairs) = renderer.backward_bands();
            [rows, pairs]
        },
    })
}

impl BackwardReport {
    /// The report as text: both passes' stages (median and p95) and the ratio.
    pub fn to_text(&self) -> String {
        use std::fmt::Write;
        let mut t = String::new();
        let _ = writeln!(
            t,
            "{}: {} Gaussians, {}x{}, {} ({}), kernel {}{}, accumulation {}, {}, {} iterations",
            self.scene,
            self.gaussians,
            self.width,
            self.height,
            self.device,
            self.driver,
            self.kernel,
            if self.reproducible {
                " (reproducible mode)"
            } else {
                ""
            },
            self.accumulation,
            match (self.feature_channels, &self.shader) {
                (0, _) => "SH colour".to_string(),
                (k, None) => format!("{k} feature channels"),
                (k, Some(s)) => format!("{k} feature channels shaded by an MLP {s}"),
            },
            self.iterations
        );
        let _ = writeln!(t, "  {:<16} {:>10} {:>10}", "stage", "median ms", "p95 ms");
        for (pass, stages, total) in [
            ("forward", &self.forward_stages, &self.forward_ms),
            ("backward", &self.backward_stages, &self.backward_ms),
        ] {
            for s in stages {
                let _ = writeln!(
                    t,
                    "  {:<16} {:>10.2} {:>10.2}",
                    s.name, s.ms.median, s.ms.p95
                );
            }
            let _ = writeln!(
                t,
                "  {:<16} {:>10.2} {:>10.2}",
                format!("{pass} total"),
                total.median,
                total.p95
            );
        }
        let _ = writeln!(
            t,
            "  backward / forward: {:.2}x; iteration wall clock {:.1} ms (median)",
            self.backward_over_forward, self.iteration_wall_ms.median
        );
        let _ = write!(
            t,
            "  {} pairs; device memory {:.1} MB at the peak ({:.0} bytes per Gaussian), of which backward {:.1} MB",
            self.pairs,
            self.device_bytes_peak as f64 / 1e6,
            self.device_bytes_per_gaussian,
            self.backward_device_bytes as f64 / 1e6
        );
        let [rows, pairs] = self.backward_bands;
        if rows > 1 || pairs > 1 {
            let _ = write!(
                t,
                "\n  backward in {rows} bands of pixel rows and {pairs} of pairs: its buffers exceed one storage binding"
            );
        }
        t
    }
}

/// Backward reports as JSON: `{"schema_version": 1, "backward_runs": [...]}`.
pub fn backward_to_json(reports: &[BackwardReport]) -> String {
    #[derive(Serialize)]
    struct Document<'a> {
        schema_version: u32,
        backward_runs: &'a [BackwardReport],
    }
    let doc = Document {
        schema_version: JSON_SCHEMA_VERSION,
        backward_runs: reports,
    };
    serde_json::to_string_pretty(&doc).unwrap_or_default()
}
