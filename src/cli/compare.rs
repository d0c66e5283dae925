//! `verisplat compare`: a scene's GPU renders against the CPU reference renderer, frame by
//! frame, or two images against each other. The figures come from `verisplat::io::metrics`;
//! the command adds diff heat maps, `report.json` + `report.csv`, a table, and an exit
//! status CI can gate on.

use super::common::{
    camera_path, fail_on_validation_messages, load_scene, CameraArgs, GpuArgs, KernelArg, PathArgs,
    SceneArg,
};
use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use serde::Serialize;
use std::path::{Path, PathBuf};
use verisplat::app::sequence::FrameSelection;
use verisplat::core::console::{note, outln};
use verisplat::io::diff_image;
use verisplat::io::image_file::{self, Planes};
use verisplat::io::metrics::{self, ErrorStats, PlaneKind};
use verisplat::io::output::{self, ImageFormat};
use verisplat::render::forward::blend::BlendKernel;
use verisplat::render::GpuRenderer;
use verisplat::render::{FrameRequest, Rendered};

/// Test-only knob: `VERISPLAT_TEST_PERTURB_RED=D` adds `D` to the red channel of every GPU
/// frame before it is compared, standing in for a broken blend so the tests can check that
/// `compare` fails. Read by this command only; not meant for users.
pub(crate) const PERTURB_RED_ENV: &str = "VERISPLAT_TEST_PERTURB_RED";

/// Report directory of a scene comparison when `-o` is not given.
const DEFAULT_REPORT_DIR: &str = "compare_report";

#[derive(Args)]
#[command(after_help = "\
One path is a scene: each selected camera is rendered on the GPU and with the CPU \
reference renderer and compared. Two paths are images, A the reference and B the test. \
Colour and alpha are compared clamped to [0, 1] (peak 1); depth is compared where the \
reference's alpha is at least 0.5, with the reference's largest depth as the peak. \
PSNR of identical planes is infinite: \"inf\" in the table and the CSV, null in the JSON. \
Exit status: 0 when every frame's colour and alpha meet --min-psnr and --min-within, 1 \
when one does not (the failing frames are named) or on an error.

Examples:
  verisplat compare scene.ply --cameras cameras.json -o report/
  verisplat compare scene.ply --orbit 8 --width 640 --blend-kernel texel:4
  verisplat compare reference.exr test.npy --diff diff.png")]
pub(crate) struct CompareArgs {
    /// A scene (or trained model directory), or two images A B: PNG (8/16-bit), JPEG,
    /// WebP, OpenEXR (channels R, G, B, A, Z by name) or NumPy .npy (H x W x C or H x W,
    /// float16/32/64).
    #[arg(value_name = "SCENE | A B", num_args = 1..=2, required_unless_present = "demo")]
    pub(crate) inputs: Vec<PathBuf>,
    /// Compare renders of the built-in demo scene.
    #[arg(long, conflicts_with = "inputs")]
    pub(crate) demo: bool,
    /// Iteration of a trained model directory: point_cloud/iteration_N (default: the largest).
    #[arg(long, value_name = "N")]
    pub(crate) iteration: Option<u64>,
    #[command(flatten)]
    pub(crate) spz: super::common::SpzAxesArg,
    #[command(flatten)]
    pub(crate) view: CameraArgs,
    #[command(flatten)]
    pub(crate) path: PathArgs,
    /// Frames of the camera path to compare: 100..200 (end exclusive), 100..=199, 100..,
    /// ..50 or 7.
    #[arg(long, value_name = "RANGE")]
    pub(crate) frames: Option<FrameSelection>,
    /// Report directory: report.json, report.csv and diff_<frame>.png per frame [scenes:
    /// compare_report; images: none].
    #[arg(short, long, value_name = "DIR")]
    pub(crate) output: Option<PathBuf>,
    /// Replace report files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// Images: write the diff heat map to this PNG.
    #[arg(long, value_name = "OUT.png")]
    pub(crate) diff: Option<PathBuf>,
    /// Images: compare only these channels, e.g. R,G,B (default: all; both images must
    /// have the same ones).
    #[arg(long, value_name = "LIST")]
    pub(crate) channels: Option<String>,
    /// Smallest PSNR (dB) of colour and alpha a frame must reach.
    #[arg(long, value_name = "DB", default_value_t = 55.0)]
    pub(crate) min_psnr: f64,
    /// Smallest share (percent) of pixels whose 8-bit colour (and alpha) is within 1/255.
    #[arg(long, value_name = "PERCENT", default_value_t = 99.9)]
    pub(crate) min_within: f64,
    /// Heat map magnification: an absolute error of 1/F is drawn dark red.
    #[arg(long, value_name = "F", default_value_t = 10.0)]
    pub(crate) magnify: f32,
    /// GPU blend kernel to check: shared, texel or texel:N (default: the device's).
    #[arg(long, value_name = "KERNEL")]
    pub(crate) blend_kernel: Option<BlendKernel>,
    /// Background colour, linear R,G,B in [0, 1] (or "black" / "white").
    #[arg(long, value_name = "R,G,B", default_value = "0,0,0", value_parser = super::values::background, allow_hyphen_values = true)]
    pub(crate) background: [f32; 3],
    /// Multiply every Gaussian's scales by M before projecting (the reference rasterizer's
    /// scaling_modifier; < 1 shrinks the splats, > 1 grows them).
    #[arg(long, value_name = "M", default_value_t = 1.0, value_parser = super::values::positive_f32)]
    pub(crate) scale_modifier: f32,
    /// Opacity compensation for scenes trained with antialiasing (see `render --help`).
    #[arg(long)]
    pub(crate) antialiased: bool,
    /// Render without the compensation even when the file records antialiased training.
    #[arg(long, conflicts_with = "antialiased")]
    pub(crate) no_antialiased: bool,
    #[command(flatten)]
    pub(crate) kernel: KernelArg,
    #[command(flatten)]
    pub(crate) gpu: GpuArgs,
}

/// Thresholds a compared frame must meet.
#[derive(Clone, Copy, Serialize)]
struct Gate {
    min_psnr: f64,
    /// Percent (the statistics' `within` is a share from 0 to 1).
    #[serde(rename = "min_within_percent")]
    min_within: f64,
}

impl Gate {
    /// Why `stats` of `plane` fails the gate, if it does.
    fn check(&self, plane: &str, stats: &ErrorStats, why: &mut Vec<String>) {
        if stats.psnr.is_nan() || stats.psnr < self.min_psnr {
            why.push(format!(
                "{plane} PSNR {} dB < {}",
                db(stats.psnr),
                self.min_psnr
            ));
        }
        if stats.within * 100.0 < self.min_within {
            why.push(format!(
                "{plane} within 1/255 {:.3} % < {}",
                stats.within * 100.0,
                self.min_within
            ));
        }
    }
}

/// PSNR for text: `inf` for identical planes.
pub(crate) fn db(v: f64) -> String {
    if v.is_infinite() && v > 0.0 {
        "inf".into()
    } else {
        format!("{v:.2}")
    }
}

pub(crate) fn compare(args: &CompareArgs) -> Result<()> {
    if !(args.min_within >= 0.0 && args.min_within <= 100.0) {
        bail!(
            "--min-within {} must be a percentage from 0 to 100",
            args.min_within
        );
    }
    if !(args.magnify.is_finite() && args.magnify > 0.0) {
        bail!("--magnify {} must be a positive number", args.magnify);
    }
    let gate = Gate {
        min_psnr: args.min_psnr,
        min_within: args.min_within,
    };
    match args.inputs.as_slice() {
        [a, b] => compare_images(args, gate, a, b),
        _ => compare_renders(args, gate),
    }
}

/// One compared frame of a scene, as the reports hold it.
#[derive(Serialize)]
struct FrameRecord {
    frame: usize,
    camera: String,
    width: u32,
    height: u32,
    color: ErrorStats,
    ssim: f64,
    /// Mean LDR-FLIP of the colour (0: identical).
    flip: f64,
    alpha: ErrorStats,
    depth: ErrorStats,
    /// Colour, alpha and depth values whose bits differ from the reference's (0, 0, 0:
    /// the same frame bit for bit; docs/reproducibility.md).
    differing_values: [usize; 3],
    diff: String,
    pass: bool,
    failures: Vec<String>,
}

#[derive(Serialize)]
struct RenderReport {
    scene: String,
    reference: String,
    test: String,
    blend_kernel: String,
    /// The alpha falloff both renderers used (`--kernel`).
    kernel: String,
    thresholds: Gate,
    magnify: f32,
    frames: Vec<FrameRecord>,
    failed_frames: Vec<usize>,
    pass: bool,
}

fn kernel_name(k: BlendKernel) -> String {
    match k {
        BlendKernel::Shared => "shared".into(),
        BlendKernel::Texel { strip } => format!("texel:{strip}"),
    }
}

/// Refuses to start when a report file exists and `--overwrite` is not given.
fn check_free(paths: &[PathBuf], overwrite: bool) -> Result<()> {
    if let Some(p) = paths.iter().find(|p| !overwrite && p.exists()) {
        return Err(output::OutputError::Exists(p.clone()).into());
    }
    Ok(())
}

fn write_text(path: &Path, overwrite: bool, text: &str) -> Result<()> {
    output::write_bytes_atomically(path, overwrite, text.as_bytes())?;
    Ok(())
}

fn compare_renders(args: &CompareArgs, gate: Gate) -> Result<()> {
    if args.diff.is_some() || args.channels.is_some() {
        bail!("--diff and --channels apply to comparing two images; a scene's diff images go to the report directory (-o)");
    }
    let perturb = perturb_red()?;
    let scene_arg = SceneArg {
        scene: args.inputs.first().cloned(),
        demo: args.demo,
        iteration: args.iteration,
        spz: args.spz,
    };
    let (scene, name) = load_scene(&scene_arg)?;
    super::common::refuse_time_varying(&scene, &name, "compare")?;
    let (source, cams) = compared_cameras(args, &scene_arg, &scene)?;
    let dir = report_dir(args, &cams)?;

    let antialiased = args.antialiased || (scene.antialiased && !args.no_antialiased);
    let opts = verisplat::cpu::RenderOptions {
        background: args.background,
        antialiased,
        scale_modifier: args.scale_modifier,
        kernel: args.kernel.resolve(&scene, &name),
        rules: args.kernel.resolve_rules(&scene, &name),
        reproducible: args.kernel.reproducible,
        ..Default::default()
    };
    let ctx = args.gpu.context()?;
    let kernel = args
        .blend_kernel
        .unwrap_or_else(|| BlendKernel::for_device(&ctx));
    let mut renderer = GpuRenderer::with_blend_kernel(ctx, kernel)?;
    let device = renderer.ctx().info().name.clone();
    if args.gpu.verbose {
        note!("device: {}", renderer.ctx().info());
    }
    let act = scene.activated();
    let gpu_scene = renderer.upload(&act)?;

    outln!(
        "{:>5}  {:<16} {:>9} {:>8} {:>8} {:>9} {:>8} {:>9} {:>9} {:>9}  result",
        "frame",
        "camera",
        "colour dB",
        "SSIM",
        "FLIP",
        "within %",
        "max err",
        "alpha dB",
        "alpha %",
        "depth dB"
    );
    let check = FrameComparison {
        args,
        gate,
        scene: &act,
        gpu_scene: &gpu_scene,
        opts: &opts,
        perturb,
        dir: &dir,
    };
    let mut records = Vec::new();
    for (k, cam) in &cams {
        records.push(check.frame(&mut renderer, *k, cam)?);
    }
    fail_on_validation_messages(renderer.ctx())?;

    let failed: Vec<usize> = records
        .iter()
        .filter(|r| !r.pass)
        .map(|r| r.frame)
        .collect();
    let report = RenderReport {
        scene: name.clone(),
        reference: "CPU reference renderer".into(),
        test: format!("GPU pipeline on {device}"),
        blend_kernel: kernel_name(renderer.blend_kernel_for(&opts)),
        kernel: opts.kernel.to_string(),
        thresholds: gate,
        magnify: args.magnify,
        pass: failed.is_empty(),
        failed_frames: failed.clone(),
        frames: records,
    };
    write_text(
        &dir.join("report.json"),
        args.overwrite,
        &serde_json::to_string_pretty(&report)?,
    )?;
    write_text(
        &dir.join("report.csv"),
        args.overwrite,
        &render_csv(&report.frames),
    )?;
    summarise_renders(&report, &name, &source, &device, &dir)
}

/// The test-only shift of the GPU frames' red channel ([`PERTURB_RED_ENV`]; 0 when unset),
/// announced.
fn perturb_red() -> Result<f32> {
    Ok(match std::env::var(PERTURB_RED_ENV) {
        Ok(v) => {
            let d: f32 = v
                .trim()
                .parse()
                .map_err(|_| anyhow!("{PERTURB_RED_ENV}={v:?} is not a number"))?;
            note!(
                "note: {PERTURB_RED_ENV}={d} shifts the GPU frames' red channel (a test-only knob)"
            );
            d
        }
        Err(_) => 0.0,
    })
}

/// The cameras of the path that `--frames` selects (checked), and where they come from.
fn compared_cameras(
    args: &CompareArgs,
    scene_arg: &SceneArg,
    scene: &verisplat::core::scene::Scene,
) -> Result<(String, Vec<(usize, verisplat::core::camera::Camera)>)> {
    let path = camera_path(&args.view, &args.path, scene_arg, scene)?;
    if let Some(frames) = &args.frames {
        frames.check(path.len).map_err(anyhow::Error::msg)?;
    }
    let source = path.source;
    let cams: Vec<_> = path
        .cameras
        .into_iter()
        .filter(|(k, _)| args.frames.as_ref().map_or(true, |r| r.contains(*k)))
        .collect();
    if cams.is_empty() {
        bail!("no frames to compare: --frames selects none of the cameras of {source}");
    }
    for (_, c) in &cams {
        c.validate()?;
    }
    Ok((source, cams))
}

/// The diff image of frame `k` in the report directory.
fn diff_name(k: usize) -> String {
    format!("diff_{k:05}.png")
}

/// The report directory (`-o`, or the default), created once none of the files the
/// comparison of `cams` writes there is in the way.
fn report_dir(
    args: &CompareArgs,
    cams: &[(usize, verisplat::core::camera::Camera)],
) -> Result<PathBuf> {
    let dir = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(DEFAULT_REPORT_DIR));
    let mut files = vec![dir.join("report.json"), dir.join("report.csv")];
    files.extend(cams.iter().map(|(k, _)| dir.join(diff_name(*k))));
    check_free(&files, args.overwrite)?;
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("{}: cannot create the report directory", dir.display()))?;
    Ok(dir)
}

/// What each frame of a scene comparison is rendered, compared and written with.
struct FrameComparison<'a> {
    args: &'a CompareArgs,
    gate: Gate,
    scene: &'a verisplat::core::model::ActivatedScene,
    gpu_scene: &'a verisplat::render::GpuScene,
    opts: &'a verisplat::cpu::RenderOptions,
    /// Added to the GPU frame's red channel (the test-only knob).
    perturb: f32,
    /// The report directory, where the diff image goes.
    dir: &'a Path,
}

impl FrameComparison<'_> {
    /// Frame `k` rendered by both renderers and compared: its diff image written, its row
    /// of the table printed, its record.
    fn frame(
        &self,
        renderer: &mut GpuRenderer,
        k: usize,
        cam: &verisplat::core::camera::Camera,
    ) -> Result<FrameRecord> {
        let (args, gate, opts) = (self.args, self.gate, self.opts);
        let mut gpu = renderer
            .render(&FrameRequest::new(self.gpu_scene, cam, opts))
            .and_then(Rendered::into_frame)?;
        if self.perturb != 0.0 {
            for c in &mut gpu.color {
                c[0] += self.perturb;
            }
        }
        let cpu = verisplat::cpu::render(self.scene, cam, opts);
        let m = metrics::compare_frames(&cpu, &gpu);
        let (reference, test) = (metrics::clamped_color(&cpu), metrics::clamped_color(&gpu));
        let flip = metrics::flip(
            &reference,
            &test,
            cam.width as usize,
            cam.height as usize,
            metrics::flip_default_ppd(),
        );
        let error = diff_image::per_pixel_max_abs(&reference, &test, 3);
        let heat = diff_image::heatmap(cam.width, cam.height, &error, args.magnify);
        output::write_frame(
            &heat,
            &self.dir.join(diff_name(k)),
            ImageFormat::Png8,
            args.overwrite,
        )?;
        let mut failures = Vec::new();
        gate.check("colour", &m.color, &mut failures);
        gate.check("alpha", &m.alpha, &mut failures);
        outln!(
            "{k:>5}  {:<16} {:>9} {:>8.5} {:>8.5} {:>9.3} {:>8.5} {:>9} {:>9.3} {:>9}  {}",
            short(&cam.name, 16),
            db(m.color.psnr),
            m.ssim,
            flip,
            m.color.within * 100.0,
            m.color.max_abs,
            db(m.alpha.psnr),
            m.alpha.within * 100.0,
            db(m.depth.psnr),
            if failures.is_empty() { "ok" } else { "FAIL" }
        );
        Ok(FrameRecord {
            frame: k,
            camera: cam.name.clone(),
            width: cam.width,
            height: cam.height,
            color: m.color,
            ssim: m.ssim,
            flip,
            alpha: m.alpha,
            depth: m.depth,
            differing_values: cpu.differing_values(&gpu),
            diff: diff_name(k),
            pass: failures.is_empty(),
            failures,
        })
    }
}

/// The closing line of a scene comparison (lowest PSNRs and shares, pass or fail), and
/// the error naming the frames that fail.
fn summarise_renders(
    report: &RenderReport,
    name: &str,
    source: &str,
    device: &str,
    dir: &Path,
) -> Result<()> {
    let (gate, failed) = (report.thresholds, &report.failed_frames);
    let min =
        |f: &dyn Fn(&FrameRecord) -> f64| report.frames.iter().map(f).fold(f64::INFINITY, f64::min);
    let differing: usize = report
        .frames
        .iter()
        .map(|r| r.differing_values.iter().sum::<usize>())
        .sum();
    let values: usize = report
        .frames
        .iter()
        .map(|r| 5 * r.width as usize * r.height as usize)
        .sum();
    let bits = match differing {
        0 => "every value the reference's bits".to_string(),
        n => format!("{n} of {values} values differ from the reference's bits"),
    };
    outln!(
        "{} frame(s) of {name} from {source}: GPU ({device}, blend kernel {}) vs CPU reference: lowest colour PSNR {} dB, lowest alpha PSNR {} dB, lowest within 1/255 {:.3} %; {bits}; {}; report in {}",
        report.frames.len(),
        report.blend_kernel,
        db(min(&|r| r.color.psnr)),
        db(min(&|r| r.alpha.psnr)),
        min(&|r| r.color.within.min(r.alpha.within)) * 100.0,
        if failed.is_empty() {
            format!("all pass (--min-psnr {}, --min-within {} %)", gate.min_psnr, gate.min_within)
        } else {
            format!("{} fail", failed.len())
        },
        dir.display()
    );
    if !failed.is_empty() {
        let names: Vec<String> = report
            .frames
            .iter()
            .filter(|r| !r.pass)
            .map(|r| {
                format!(
                    "frame {} (\"{}\": {})",
                    r.frame,
                    r.camera,
                    r.failures.join(", ")
                )
            })
            .collect();
        bail!(
            "{} of {} frame(s) fail --min-psnr {} / --min-within {} %: {}",
            failed.len(),
            report.frames.len(),
            gate.min_psnr,
            gate.min_within,
            names.join("; ")
        );
    }
    Ok(())
}

/// At most `n` characters of `s` for the table.
fn short(s: &str, n: usize) -> String {
    if s.chars().count() <= n {
        s.to_string()
    } else {
        let head: String = s.chars().take(n - 1).collect();
        format!("{head}~")
    }
}

/// A CSV cell: quoted when it holds a comma, quote or line break.
pub(crate) fn csv_cell(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The CSV columns of one plane's statistics.
fn stats_cells(s: &ErrorStats) -> String {
    format!(
        "{},{},{},{}",
        db_csv(s.psnr),
        s.max_abs,
        s.mean_abs,
        s.within
    )
}

/// PSNR for CSV: full precision, `inf` for identical planes.
pub(crate) fn db_csv(v: f64) -> String {
    if v.is_infinite() && v > 0.0 {
        "inf".into()
    } else {
        v.to_string()
    }
}

fn render_csv(frames: &[FrameRecord]) -> String {
    let mut s = String::from(
        "frame,camera,width,height,color_psnr,color_max_abs,color_mean_abs,color_within,ssim,flip,alpha_psnr,alpha_max_abs,alpha_mean_abs,alpha_within,depth_psnr,depth_max_abs,depth_mean_abs,depth_within,depth_peak,color_differing,alpha_differing,depth_differing,diff,pass\n",
    );
    for r in frames {
        let [dc, da, dd] = r.differing_values;
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            r.frame,
            csv_cell(&r.camera),
            r.width,
            r.height,
            stats_cells(&r.color),
            r.ssim,
            r.flip,
            stats_cells(&r.alpha),
            stats_cells(&r.depth),
            r.depth.peak,
            dc,
            da,
            dd,
            csv_cell(&r.diff),
            r.pass
        ));
    }
    s
}

/// One compared channel group of two images.
#[derive(Serialize)]
struct GroupRecord {
    group: String,
    channels: Vec<String>,
    #[serde(flatten)]
    stats: ErrorStats,
    #[serde(skip_serializing_if = "Option::is_none")]
    ssim: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    flip: Option<f64>,
}

#[derive(Serialize)]
struct ImageReport {
    reference: String,
    test: String,
    width: u32,
    height: u32,
    thresholds: Gate,
    groups: Vec<GroupRecord>,
    pass: bool,
    failures: Vec<String>,
}

/// The channels to compare: `--channels`, or every channel when both images have the
/// same ones (two single-channel images are compared whatever their names).
fn choose_channels(
    args: &CompareArgs,
    a: &Path,
    pa: &Planes,
    b: &Path,
    pb: &Planes,
) -> Result<Vec<String>> {
    if let Some(list) = &args.channels {
        let names: Vec<String> = list
            .split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect();
        if names.is_empty() {
            bail!("--channels {list:?} names no channel");
        }
        for (path, p) in [(a, pa), (b, pb)] {
            if let Some(missing) = names.iter().find(|n| p.channel(n).is_none()) {
                bail!(
                    "{}: has no channel {missing:?}; its channels are {}",
                    path.display(),
                    p.names().join(", ")
                );
            }
        }
        return Ok(names);
    }
    let (na, nb) = (pa.names(), pb.names());
    let mut sa = na.clone();
    let mut sb = nb.clone();
    sa.sort_unstable();
    sb.sort_unstable();
    if sa == sb || (na.len() == 1 && nb.len() == 1) {
        return Ok(na.iter().map(|s| s.to_string()).collect());
    }
    bail!(
        "the images have different channels: {} has {} and {} has {}; compare common ones with --channels (e.g. --channels R,G,B)",
        a.display(),
        na.join(", "),
        b.display(),
        nb.join(", ")
    )
}

fn compare_images(args: &CompareArgs, gate: Gate, a: &Path, b: &Path) -> Result<()> {
    refuse_scene_options(args)?;
    let (pa, pb) = read_pair(a, b)?;
    let names = choose_channels(args, a, &pa, b, &pb)?;
    let groups = channel_groups(&names);
    let mut failures = Vec::new();
    let (records, diff) = measure_groups(gate, &pa, &pb, &groups, &mut failures);
    print_groups(&records);
    if let (Some(path), Some((ra, rb, c))) = (&args.diff, &diff) {
        let error = diff_image::per_pixel_max_abs(ra, rb, *c);
        let heat = diff_image::heatmap(pa.width, pa.height, &error, args.magnify);
        output::write_frame(&heat, path, ImageFormat::Png8, args.overwrite)?;
    }
    let report = ImageReport {
        reference: a.display().to_string(),
        test: b.display().to_string(),
        width: pa.width,
        height: pa.height,
        thresholds: gate,
        groups: records,
        pass: failures.is_empty(),
        failures: failures.clone(),
    };
    if let Some(dir) = &args.output {
        write_image_report(args, dir, &report)?;
    }
    outln!(
        "{} vs {} ({}x{}): {}",
        a.display(),
        b.display(),
        pa.width,
        pa.height,
        if failures.is_empty() {
            format!(
                "pass (--min-psnr {}, --min-within {} %)",
                gate.min_psnr, gate.min_within
            )
        } else {
            "FAIL".into()
        }
    );
    if !failures.is_empty() {
        bail!(
            "{} does not match {} within --min-psnr {} / --min-within {} %: {}",
            b.display(),
            a.display(),
            gate.min_psnr,
            gate.min_within,
            failures.join(", ")
        );
    }
    Ok(())
}

/// Refuses the options of a scene comparison when two images are compared.
fn refuse_scene_options(args: &CompareArgs) -> Result<()> {
    let v = &args.view;
    let scene_only = args.iteration.is_some()
        || args.frames.is_some()
        || args.blend_kernel.is_some()
        || v.cameras.is_some()
        || v.camera.is_some()
        || v.width.is_some()
        || v.height.is_some()
        || v.scale.is_some()
        || args.scale_modifier != 1.0
        || args.kernel.kernel.is_some()
        || args.kernel.rules.is_some()
        || args.path.orbit.is_some();
    if scene_only {
        bail!("camera, resolution, --iteration, --frames, --blend-kernel, --kernel, --rules and --scale-modifier options apply to comparing a scene's renders, not two images");
    }
    Ok(())
}

/// The two images, which must have the same size.
fn read_pair(a: &Path, b: &Path) -> Result<(Planes, Planes)> {
    let pa = image_file::read_image(a)?;
    let pb = image_file::read_image(b)?;
    if (pa.width, pa.height) != (pb.width, pb.height) {
        bail!(
            "the images differ in size: {} is {}x{} and {} is {}x{}",
            a.display(),
            pa.width,
            pa.height,
            b.display(),
            pb.width,
            pb.height
        );
    }
    Ok((pa, pb))
}

/// The compared channels in groups: colour (`R,G,B` or `Y`), alpha (`A`), depth (`Z`),
/// then every other channel on its own.
fn channel_groups(names: &[String]) -> Vec<(String, Vec<String>)> {
    let mut left: Vec<String> = names.to_vec();
    let mut groups: Vec<(String, Vec<String>)> = Vec::new();
    let mut group = |label: &str, members: &[&str], left: &mut Vec<String>| {
        if members.iter().all(|m| left.iter().any(|l| l == m)) {
            left.retain(|l| !members.contains(&l.as_str()));
            groups.push((
                label.into(),
                members.iter().map(|s| s.to_string()).collect(),
            ));
        }
    };
    group("color", &["R", "G", "B"], &mut left);
    group("color", &["Y"], &mut left);
    group("alpha", &["A"], &mut left);
    group("depth", &["Z"], &mut left);
    for rest in left.clone() {
        group(&rest, &[rest.as_str()], &mut left);
    }
    groups
}

/// The planes of a diff image: both images' channels of one group, scaled by its peak,
/// and their number.
type DiffPlanes = (Vec<f32>, Vec<f32>, usize);

/// Each group's metrics (the colour and alpha groups checked against `gate`, failures
/// added to `failures`), and the planes of the diff image: the colour group's, else the
/// first group's.
fn measure_groups(
    gate: Gate,
    pa: &Planes,
    pb: &Planes,
    groups: &[(String, Vec<String>)],
    failures: &mut Vec<String>,
) -> (Vec<GroupRecord>, Option<DiffPlanes>) {
    // Two single-channel images with different names compare their only channels.
    let b_name = |n: &str| -> String {
        if pb.channel(n).is_none() && pb.channels.len() == 1 {
            pb.channels[0].name.clone()
        } else {
            n.to_string()
        }
    };
    let take = |p: &Planes, ns: &[String]| -> Vec<f32> {
        let refs: Vec<&str> = ns.iter().map(String::as_str).collect();
        p.interleave(&refs).unwrap_or_default()
    };
    let (w, h) = (pa.width as usize, pa.height as usize);
    let mut records = Vec::new();
    let mut diff: Option<DiffPlanes> = None;
    for (label, members) in groups {
        let bm: Vec<String> = members.iter().map(|m| b_name(m)).collect();
        let (mut ra, mut rb) = (take(pa, members), take(pb, &bm));
        let kind = match label.as_str() {
            "color" => PlaneKind::Colour,
            "alpha" => PlaneKind::Alpha,
            _ => PlaneKind::Data,
        };
        let m = metrics::plane_metrics(&mut ra, &mut rb, w, h, members.len(), kind);
        let (stats, peak) = (m.stats, m.stats.peak);
        if kind != PlaneKind::Data {
            let plane = if label == "color" { "colour" } else { label };
            gate.check(plane, &stats, failures);
        }
        if diff.is_none() || (label == "color") {
            let scale = 1.0 / peak as f32;
            diff = Some((
                ra.iter().map(|v| v * scale).collect(),
                rb.iter().map(|v| v * scale).collect(),
                members.len(),
            ));
        }
        records.push(GroupRecord {
            group: label.clone(),
            channels: members.clone(),
            stats,
            ssim: m.ssim,
            flip: m.flip,
        });
    }
    (records, diff)
}

/// The table of the groups' metrics on stdout.
fn print_groups(records: &[GroupRecord]) {
    outln!(
        "{:<8} {:<10} {:>9} {:>10} {:>10} {:>9} {:>8} {:>8}",
        "plane",
        "channels",
        "PSNR dB",
        "max err",
        "mean err",
        "within %",
        "SSIM",
        "FLIP"
    );
    for r in records {
        let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.5}"));
        outln!(
            "{:<8} {:<10} {:>9} {:>10.6} {:>10.6} {:>9.3} {:>8} {:>8}",
            r.group,
            r.channels.join(","),
            db(r.stats.psnr),
            r.stats.max_abs,
            r.stats.mean_abs,
            r.stats.within * 100.0,
            opt(r.ssim),
            opt(r.flip)
        );
    }
}

/// Writes the report of two images to `dir` (`-o`): report.json and report.csv.
fn write_image_report(args: &CompareArgs, dir: &Path, report: &ImageReport) -> Result<()> {
    let files = [dir.join("report.json"), dir.join("report.csv")];
    check_free(&files, args.overwrite)?;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the report directory", dir.display()))?;
    write_text(
        &files[0],
        args.overwrite,
        &serde_json::to_string_pretty(report)?,
    )?;
    let mut csv = String::from("plane,channels,psnr,max_abs,mean_abs,within,peak,ssim,flip\n");
    for r in &report.groups {
        let opt = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{}\n",
            csv_cell(&r.group),
            csv_cell(&r.channels.join(" ")),
            db_csv(r.stats.psnr),
            r.stats.max_abs,
            r.stats.mean_abs,
            r.stats.within,
            r.stats.peak,
            opt(r.ssim),
            opt(r.flip)
        ));
    }
    write_text(&files[1], args.overwrite, &csv)?;
    Ok(())
}
