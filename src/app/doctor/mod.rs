//! `verisplat doctor`: a self-check of a few seconds on a Vulkan device, each building block
//! against its CPU reference (subgroups, the demo scene's render, the radix sort, the
//! prefix sum, the backward pass), so a new GPU or driver is trusted only after it has
//! shown the same answers as the CPU. [`report`] turns a bundle run's results into one
//! markdown report.

pub mod bits;
pub mod report;

use crate::render::{FrameRequest, Readback, Rendered};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use glam::Vec3;
use serde::Serialize;

use crate::core::camera::orbit::{orbit, OrbitParams};
use crate::core::camera::Camera;
use crate::core::gen::Rng;
use crate::core::model::grad::{relative_l2, PixelGrads, GRAD_GROUPS};
use crate::cpu::RenderOptions;
use crate::gpu::buffer::{BufferView, GpuBuffer, MemoryKind};
use crate::gpu::scan::Scan;
use crate::gpu::sort::{
    Count, RadixSort, SortConfig, SortJob, SortTexels, DEFAULT_SORT_CONFIG, SORT_CONFIG_32,
};
use crate::gpu::subgroup::{self, SubgroupVerdict};
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{ContextOptions, GpuContext, GpuResult};
use crate::render::backward::differentiable::DiffRasterizer;
use crate::render::forward::blend::BlendKernel;
use crate::render::GpuRenderer;

/// Smallest PSNR (dB) of the demo scene's GPU colour and alpha against the CPU's (the
/// `compare` command's default gate).
pub const MIN_PSNR_DB: f64 = 55.0;
/// Smallest share of pixels whose 8-bit colour and alpha are within 1/255 (`compare`'s).
pub const MIN_WITHIN: f64 = 0.999;
/// Largest relative L2 error of a gradient group, GPU against the f64 CPU backward
/// (`tests/all/train/gradients.rs` explains the margin: f32 sums reach ~1e-5).
pub const MAX_GRAD_REL_L2: f64 = 1e-3;
/// Keys of each sort check.
pub const SORT_KEYS: usize = 100_000;
/// Elements of the prefix-sum check (past a multiple of the scan's block on purpose).
pub const SCAN_ELEMENTS: usize = (1 << 20) + 3;
/// Size of the demo scene's renders (small: lavapipe renders it in a fraction of a second).
pub const RENDER_SIZE: (u32, u32) = (320, 240);

/// One check's outcome.
#[derive(Clone, Debug, Serialize)]
pub struct Check {
    /// Short name: `subgroups`, `render`, `sort64`, `sort32`, `scan`, `backward`,
    /// `validation`.
    pub name: String,
    /// What was checked.
    pub what: String,
    /// The figure measured, in words (e.g. `colour 62.10 dB, ...`).
    pub figure: String,
    /// The figure in one number where there is one (lowest PSNR, mismatches, worst error).
    pub value: Option<f64>,
    /// What the figure must be to pass.
    pub threshold: String,
    /// Whether it passed.
    pub passed: bool,
    /// Something worth knowing that does not fail the check (a misreported subgroup size).
    pub warning: Option<String>,
    /// The rest of a failure's message when it has several lines (compiler output).
    pub detail: Option<String>,
    /// What the check learnt beside its figure (the render check: whether the device
    /// reproduces the CPU reference bit for bit, [`bits::BitReport`]).
    pub note: Option<String>,
    /// Wall-clock seconds the check took.
    pub seconds: f64,
}

/// The self-check of one device.
#[derive(Clone, Debug, Serialize)]
pub struct DeviceRun {
    /// Index of the device (`--device N`).
    pub device_index: usize,
    /// Device name.
    pub device: String,
    /// Driver name and info.
    pub driver: String,
    /// Subgroup size the kernels use (measured).
    pub subgroup_size: u32,
    /// Subgroup size the driver reports.
    pub reported_subgroup_size: u32,
    /// Whether the validation layer watched the checks.
    pub validation: bool,
    /// The checks, in the order they ran.
    pub checks: Vec<Check>,
    /// Every check passed.
    pub passed: bool,
}

impl DeviceRun {
    /// The final verdict line.
    pub fn verdict(&self) -> String {
        let failed: Vec<&str> = self
            .checks
            .iter()
            .filter(|c| !c.passed)
            .map(|c| c.name.as_str())
            .collect();
        if failed.is_empty() {
            format!(
                "doctor: all {} checks passed on {}",
                self.checks.len(),
                self.device
            )
        } else {
            format!(
                "doctor: {} of {} checks FAILED on {}: {}",
                failed.len(),
                self.checks.len(),
                self.device,
                failed.join(", ")
            )
        }
    }
}

impl Check {
    /// One line: name, figure, threshold, PASS or FAIL (and a WARN line when there is one).
    pub fn lines(&self) -> Vec<String> {
        let mut lines = vec![format!(
            "  {:<10} {} ({}; {:.1} s)  {}",
            self.name,
            self.figure,
            self.threshold,
            self.seconds,
            if self.passed { "PASS" } else { "FAIL" }
        )];
        if let Some(w) = &self.warning {
            lines.push(format!("  {:<10} WARN: {w}", self.name));
        }
        if let Some(n) = &self.note {
            lines.push(format!("  {:<10} {n}", self.name));
        }
        if let Some(d) = &self.detail {
            lines.extend(d.lines().map(|l| format!("      {l}")));
        }
        lines
    }
}

/// What a check function returns: figure, value, passed, warning, note.
struct Outcome {
    figure: String,
    value: Option<f64>,
    passed: bool,
    warning: Option<String>,
    note: Option<String>,
}

impl Outcome {
    fn new(figure: String, value: Option<f64>, passed: bool) -> Self {
        Outcome {
            figure,
            value,
            passed,
            warning: None,
            note: None,
        }
    }
}

/// Runs one check, timing it, turning an error into a failure and failing it when the
/// validation layer spoke while it ran.
fn run_check(
    name: &str,
    what: &str,
    threshold: &str,
    log: Option<&Arc<Mutex<Vec<String>>>>,
    f: impl FnOnce() -> Result<Outcome, String>,
) -> Check {
    let count = |log: Option<&Arc<Mutex<Vec<String>>>>| {
        log.and_then(|l| l.lock().ok().map(|m| m.len()))
            .unwrap_or(0)
    };
    let before = count(log);
    let t0 = Instant::now();
    let mut detail = None;
    let mut outcome = f().unwrap_or_else(|e| {
        // The check's line keeps the first line; the rest (compiler output) follows it.
        let (first, rest) = e.split_once('\n').unwrap_or((&e, ""));
        if !rest.trim().is_empty() {
            detail = Some(rest.trim_end().to_string());
        }
        Outcome::new(format!("error: {first}"), None, false)
    });
    let new_messages = count(log) - before;
    if new_messages > 0 {
        outcome.passed = false;
        outcome.figure = format!(
            "{}; {new_messages} validation message(s) (printed above)",
            outcome.figure
        );
    }
    Check {
        name: name.to_string(),
        what: what.to_string(),
        figure: outcome.figure,
        value: outcome.value,
        threshold: threshold.to_string(),
        passed: outcome.passed,
        warning: outcome.warning,
        detail,
        note: outcome.note,
        seconds: t0.elapsed().as_secs_f64(),
    }
}

/// The checks [`self_check`] runs, in order (`validation` only with the layer on).
pub const CHECKS: [&str; 7] = [
    "subgroups",
    "sort64",
    "sort32",
    "scan",
    "render",
    "backward",
    "validation",
];

/// The self-check of device `index` (every check, a few seconds on lavapipe).
/// `validation` turns the Khronos validation layer on (`VERISPLAT_VALIDATE=1` does too):
/// any message it prints fails the check that caused it. `on_check` sees each check as it
/// finishes (to print progress). `only`, when given, names the checks to run (of
/// [`CHECKS`]; `subgroups` always runs, as the device opens).
pub fn self_check(
    index: usize,
    validation: bool,
    only: Option<&[String]>,
    mut on_check: impl FnMut(&Check),
) -> DeviceRun {
    let wanted = |name: &str| only.map_or(true, |o| o.iter().any(|n| n == name));
    let mut checks = Checks {
        done: Vec::new(),
        on_check: &mut on_check,
    };
    let opened = GpuContext::new(&ContextOptions {
        device: Some(index.to_string()),
        validation,
        ..Default::default()
    });
    let ctx = match opened {
        Ok(ctx) => ctx,
        Err(e) => return unopened(index, validation, e, checks),
    };
    let info = ctx.info().clone();
    let validation = ctx.validation_enabled();
    let log = validation.then(|| ctx.validation_log());
    let log = log.as_ref();

    primitive_checks(&ctx, &wanted, log, &mut checks);
    renderer_checks(ctx, &wanted, log, &mut checks);
    if let Some(log) = log {
        // Everything is destroyed by now: messages at teardown (leaks) count too.
        let total = log.lock().map(|m| m.len()).unwrap_or(0);
        let c = run_check(
            "validation",
            "messages of the Khronos validation layer during the checks and teardown",
            "none",
            None,
            || {
                Ok(Outcome::new(
                    format!("{total} message(s)"),
                    Some(total as f64),
                    total == 0,
                ))
            },
        );
        checks.push(c);
    }
    let checks = checks.done;
    let passed = checks.iter().all(|c| c.passed);
    DeviceRun {
        device_index: info.index,
        device: info.name.clone(),
        driver: info.driver.clone(),
        subgroup_size: info.subgroup_size,
        reported_subgroup_size: info.reported_subgroup_size,
        validation,
        checks,
        passed,
    }
}

/// The checks of one device run so far, each shown to `on_check` as it finishes.
struct Checks<'a> {
    done: Vec<Check>,
    on_check: &'a mut dyn FnMut(&Check),
}

impl Checks<'_> {
    fn push(&mut self, c: Check) {
        (self.on_check)(&c);
        self.done.push(c);
    }
}

/// The run of a device that could not be opened: its one failed check.
fn unopened(
    index: usize,
    validation: bool,
    e: crate::gpu::GpuError,
    mut checks: Checks,
) -> DeviceRun {
    let c = run_check(
        "subgroups",
        "open the device (the subgroup probe runs as it opens)",
        "the device opens and its subgroups are consistent",
        None,
        || Err(format!("the device could not be opened: {e}")),
    );
    checks.push(c);
    DeviceRun {
        device_index: index,
        device: format!("device #{index}"),
        driver: String::new(),
        subgroup_size: 0,
        reported_subgroup_size: 0,
        validation,
        checks: checks.done,
        passed: false,
    }
}

/// The checks of the compute primitives on `ctx`: subgroups, the two radix sorts and the
/// scan (those `wanted`).
fn primitive_checks(
    ctx: &GpuContext,
    wanted: &dyn Fn(&str) -> bool,
    log: Option<&Arc<Mutex<Vec<String>>>>,
    checks: &mut Checks,
) {
    checks.push(run_check(
        "subgroups",
        "the subgroup size the lanes run at against the driver's",
        "readings consistent (a misreported size is followed)",
        log,
        || check_subgroups(ctx),
    ));
    if wanted("sort64") {
        checks.push(run_check(
            "sort64",
            &format!("radix sort of {SORT_KEYS} random 64-bit keys vs a CPU stable sort"),
            "exact",
            log,
            || check_sort(ctx, DEFAULT_SORT_CONFIG, 64, 1),
        ));
    }
    let texel = BlendKernel::for_device(ctx).texel();
    if wanted("sort32") {
        checks.push(run_check(
            "sort32",
            &format!(
                "radix sort of {SORT_KEYS} random 32-bit keys{} (the renderer's) vs a CPU \
                 stable sort",
                if texel { " through texel views" } else { "" }
            ),
            "exact",
            log,
            || {
                let config = SortConfig {
                    texel_io: texel,
                    ..SORT_CONFIG_32
                };
                check_sort(ctx, config, 32, 2)
            },
        ));
    }
    if wanted("scan") {
        checks.push(run_check(
            "scan",
            &format!("exclusive prefix sum of {SCAN_ELEMENTS} u32s vs a CPU scan"),
            "exact",
            log,
            || check_scan(ctx),
        ));
    }
}

/// The checks of the renderer built on `ctx` (which it takes, and drops with everything
/// else before returning): the forward render and the backward pass (those `wanted`).
fn renderer_checks(
    ctx: GpuContext,
    wanted: &dyn Fn(&str) -> bool,
    log: Option<&Arc<Mutex<Vec<String>>>>,
    checks: &mut Checks,
) {
    let renderer = match GpuRenderer::new(ctx) {
        _ if !wanted("render") && !wanted("backward") => None,
        Ok(r) => Some(r),
        Err(e) => {
            let message = format!("the renderer's pipelines could not be built: {e}");
            for name in ["render", "backward"].into_iter().filter(|n| wanted(n)) {
                let m = message.clone();
                let c = run_check(name, "build the renderer", "builds", log, || Err(m));
                checks.push(c);
            }
            None
        }
    };
    if let Some(mut renderer) = renderer {
        let (w, h) = RENDER_SIZE;
        if wanted("render") {
            checks.push(run_check(
                "render",
                &format!("the demo scene at {w}x{h} from 2 cameras, GPU vs the CPU reference"),
                &format!(
                    "colour and alpha >= {MIN_PSNR_DB} dB, >= {:.1} % within 1/255",
                    MIN_WITHIN * 100.0
                ),
                log,
                || check_render(&mut renderer),
            ));
        }
        let mut rast = DiffRasterizer::with_renderer(renderer);
        if wanted("backward") {
            checks.push(run_check(
                "backward",
                "backward pass of 60 random Gaussians (SH 2) at 72x56, GPU vs the f64 CPU backward",
                &format!("relative L2 <= {MAX_GRAD_REL_L2:.0e} per parameter group"),
                log,
                || check_backward(&mut rast),
            ));
        }
        drop(rast);
    }
}

fn check_subgroups(ctx: &GpuContext) -> Result<Outcome, String> {
    let p = subgroup::probe(ctx).map_err(|e| e.to_string())?;
    let readings = format!(
        "gl_SubgroupSize {}, ballot of every lane {}, subgroup sum of ones {}, {} subgroups \
         of {} invocations",
        p.told.0,
        p.ballot.0,
        p.summed.0,
        p.num_subgroups,
        subgroup::PROBE_INVOCATIONS
    );
    Ok(match p.verdict() {
        Ok(SubgroupVerdict::Consistent) => Outcome::new(
            format!("{} lanes ({readings})", p.told.0),
            Some(f64::from(p.told.0)),
            true,
        ),
        Ok(SubgroupVerdict::Misreported { reported, runs }) => Outcome {
            figure: format!("{runs} lanes measured ({readings})"),
            value: Some(f64::from(runs)),
            passed: true,
            warning: Some(format!(
                "the driver reports {reported} lanes per subgroup but {runs} run together; \
                 verisplat follows the measured {runs}"
            )),
            note: None,
        },
        Err(e) => Outcome::new(format!("inconsistent: {e}"), None, false),
    })
}

fn gpu<T>(r: GpuResult<T>) -> Result<T, String> {
    r.map_err(|e| e.to_string())
}

/// Sorts [`SORT_KEYS`] random keys of `key_bits` with `config` and compares keys and
/// values with a CPU stable sort.
fn check_sort(
    ctx: &GpuContext,
    config: SortConfig,
    key_bits: u32,
    seed: u64,
) -> Result<Outcome, String> {
    let sort = gpu(RadixSort::with_config(ctx, config))?;
    let words = sort.config().key_words as usize;
    let n = SORT_KEYS;
    let mut rng = Rng(0xd0c7 + seed);
    let keys: Vec<u64> = (0..n)
        .map(|_| {
            let k = rng.next_u64();
            if words == 1 {
                k & 0xffff_ffff
            } else {
                k
            }
        })
        .collect();
    let packed: Vec<u32> = keys
        .iter()
        .flat_map(|&k| [k as u32, (k >> 32) as u32].into_iter().take(words))
        .collect();
    let values: Vec<u32> = (0..n as u32).collect();
    let key_buf = gpu(GpuBuffer::from_slice(ctx, "doctor sort keys", &packed))?;
    let value_buf = gpu(GpuBuffer::from_slice(ctx, "doctor sort values", &values))?;
    let scratch = gpu(GpuBuffer::new(
        ctx,
        "doctor sort scratch",
        sort.scratch_size_for(n as u32),
        MemoryKind::Device,
    ))?;
    let view = |b: &GpuBuffer, (offset, size): (u64, u64)| {
        BufferView::new(ctx, b, ash::vk::Format::R32_UINT, offset, size.max(4))
    };
    let views = if sort.config().texel_io {
        let [k, v] = RadixSort::scratch_pair_ranges(&sort.config(), n as u32);
        Some([
            gpu(view(&key_buf, (0, key_buf.size())))?,
            gpu(view(&value_buf, (0, value_buf.size())))?,
            gpu(view(&scratch, k))?,
            gpu(view(&scratch, v))?,
        ])
    } else {
        None
    };
    let texels = views.as_ref().map(|[k, v, sk, sv]| SortTexels {
        keys: k.handle(),
        values: v.handle(),
        scratch_keys: sk.handle(),
        scratch_values: sv.handle(),
    });
    gpu(ctx.submit_and_wait("doctor sort", |cmd| {
        let job = SortJob::new(
            &key_buf,
            &value_buf,
            &scratch,
            Count::Host(n as u32),
            key_bits,
        )
        .texels(texels.as_ref());
        sort.record(ctx, cmd, &job)?;
        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
        Ok(())
    }))?;
    let got_keys: Vec<u32> = gpu(key_buf.read(ctx, n * words))?;
    let got_values: Vec<u32> = gpu(value_buf.read(ctx, n))?;
    let mut expected: Vec<(u64, u32)> = keys.iter().copied().zip(0u32..).collect();
    expected.sort_by_key(|&(k, _)| k);
    let mut mismatches = 0usize;
    let mut first = None;
    for (i, &(k, v)) in expected.iter().enumerate() {
        let got = got_keys[i * words..(i + 1) * words]
            .iter()
            .rev()
            .fold(0u64, |acc, &w| (acc << 32) | u64::from(w));
        if got != k || got_values[i] != v {
            mismatches += 1;
            first.get_or_insert(i);
        }
    }
    let figure = match first {
        None => format!("{n} keys in order, values stable: 0 mismatches"),
        Some(i) => format!("{mismatches} of {n} elements misplaced (first at {i})"),
    };
    Ok(Outcome::new(
        figure,
        Some(mismatches as f64),
        mismatches == 0,
    ))
}

fn check_scan(ctx: &GpuContext) -> Result<Outcome, String> {
    let scan = gpu(Scan::new(ctx))?;
    let n = SCAN_ELEMENTS;
    let mut rng = Rng(0x5ca7);
    // Small values keep the total below 2^32.
    let data: Vec<u32> = (0..n).map(|_| rng.next_u32() % 200).collect();
    let input = gpu(GpuBuffer::from_slice(ctx, "doctor scan input", &data))?;
    let output = gpu(GpuBuffer::new(
        ctx,
        "doctor scan output",
        4 * n as u64,
        MemoryKind::Device,
    ))?;
    let total = gpu(GpuBuffer::from_slice(ctx, "doctor scan total", &[0u32; 4]))?;
    let scratch = gpu(GpuBuffer::new(
        ctx,
        "doctor scan scratch",
        Scan::scratch_size(n as u32),
        MemoryKind::Device,
    ))?;
    gpu(ctx.submit_and_wait("doctor scan", |cmd| {
        scan.record(
            ctx,
            cmd,
            input.whole(),
            output.whole(),
            (&total, 0),
            scratch.whole(),
            n as u32,
        )?;
        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
        Ok(())
    }))?;
    let got: Vec<u32> = gpu(output.read(ctx, n))?;
    let got_total = gpu(total.read::<u32>(ctx, 1))?[0];
    let mut sum = 0u32;
    let mut mismatches = 0usize;
    for (g, &x) in got.iter().zip(&data) {
        mismatches += usize::from(*g != sum);
        sum = sum.wrapping_add(x);
    }
    let total_ok = got_total == sum;
    let figure = format!(
        "{mismatches} of {n} prefix sums wrong, total {}",
        if total_ok { "right" } else { "WRONG" }
    );
    Ok(Outcome::new(
        figure,
        Some(mismatches as f64),
        mismatches == 0 && total_ok,
    ))
}

fn check_render(renderer: &mut GpuRenderer) -> Result<Outcome, String> {
    let scene = crate::io::demo::demo_scene();
    let (width, height) = RENDER_SIZE;
    let cams = orbit(
        &scene.positions,
        &OrbitParams {
            frames: 2,
            width,
            height,
            ..Default::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let act = scene.activated();
    let opts = RenderOptions::default();
    let gpu_scene = gpu(renderer.upload(&act))?;
    let (mut colour, mut alpha, mut within) = (f64::INFINITY, f64::INFINITY, 1.0f64);
    // The default mode's bits and the reproducible mode's (`--reproducible`), against
    // the same reference frames.
    let (mut bits, mut repro) = (bits::BitReport::default(), bits::BitReport::default());
    let repro_opts = RenderOptions {
        reproducible: true,
        ..opts
    };
    for cam in &cams {
        let reference = crate::cpu::render(&act, cam, &opts);
        let projected = crate::cpu::preprocess(&act, cam, &opts);
        let mut render = |o: &RenderOptions, report: &mut bits::BitReport| {
            let request = FrameRequest::new(&gpu_scene, cam, o).readback(Readback::Intermediates);
            let (frame, stages) = gpu(renderer
                .render(&request)
                .and_then(Rendered::into_intermediates))?;
            report.add_preprocess(&projected, &stages);
            report.add_frame(&reference, &frame);
            Ok::<_, String>(frame)
        };
        render(&repro_opts, &mut repro)?;
        let frame = render(&opts, &mut bits)?;
        let m = crate::io::metrics::compare_frames(&reference, &frame);
        // NaN (a frame of NaNs) must fail: `min` would drop it.
        let worst = |a: f64, b: f64| if b.is_nan() || b < a { b } else { a };
        colour = worst(colour, m.color.psnr);
        alpha = worst(alpha, m.alpha.psnr);
        within = worst(within, m.color.within.min(m.alpha.within));
    }
    let passed = colour >= MIN_PSNR_DB && alpha >= MIN_PSNR_DB && within >= MIN_WITHIN;
    let db = |v: f64| {
        if v.is_infinite() {
            "inf".to_string()
        } else {
            format!("{v:.2}")
        }
    };
    let mut outcome = Outcome::new(
        format!(
            "lowest colour {} dB, alpha {} dB, {:.3} % within 1/255",
            db(colour),
            db(alpha),
            within * 100.0
        ),
        Some(colour.min(alpha)),
        passed,
    );
    outcome.note = Some(format!(
        "{}; with --reproducible: {}",
        bits.sentence(),
        repro.verdict()
    ));
    Ok(outcome)
}

fn backward_camera() -> Camera {
    Camera::look_at(
        "doctor-backward",
        72,
        56,
        0.9,
        Vec3::new(0.4, -0.3, -3.0),
        Vec3::ZERO,
        Vec3::new(0.0, -1.0, 0.0),
    )
}

fn check_backward(rast: &mut DiffRasterizer) -> Result<Outcome, String> {
    let cam = backward_camera();
    let p = crate::core::gen::random_splat_params(60, 0xbac0, Some(2), 3);
    let opts = RenderOptions {
        background: [0.2, 0.4, 0.1],
        ..Default::default()
    };
    let px = (cam.width * cam.height) as usize;
    let mut rng = Rng(0x9a7d);
    let grads = PixelGrads {
        color: (0..px * 3)
            .map(|_| f64::from(rng.range(-1.0, 1.0)))
            .collect::<Vec<f64>>(),
        alpha: (0..px).map(|_| f64::from(rng.range(-1.0, 1.0))).collect(),
        depth: (0..px)
            .map(|_| 0.3 * f64::from(rng.range(-1.0, 1.0)))
            .collect(),
    };
    let to_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let grads32 = PixelGrads {
        color: to_f32(&grads.color),
        alpha: to_f32(&grads.alpha),
        depth: to_f32(&grads.depth),
    };
    // The projected quantities' gradients too (what a camera's gradient is made of).
    gpu(rast.renderer().set_screen_grads(true))?;
    let (_, token) = gpu(rast.forward(&p, &cam, &opts))?;
    let device = gpu(rast.backward(&p, &cam, &opts, token, &grads32))?;
    let bg: Vec<f64> = opts.background.iter().map(|&b| f64::from(b)).collect();
    let reference = crate::cpu::backward::backward(&p.to_f64(), &cam, &opts, &bg, &grads)
        .map_err(|e| e.to_string())?;
    let mut worst = ("", 0.0f64);
    for group in GRAD_GROUPS {
        let err = relative_l2(&device.group(group), &reference.group(group));
        if err.is_nan() || err > worst.1 || worst.0.is_empty() {
            worst = (group, err);
        }
    }
    Ok(Outcome::new(
        format!(
            "worst group {}: relative L2 {:.2e} ({} groups)",
            worst.0,
            worst.1,
            GRAD_GROUPS.len()
        ),
        Some(worst.1),
        worst.1 <= MAX_GRAD_REL_L2,
    ))
}
