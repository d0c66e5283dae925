//! `verisplat eval`: renders the cameras of a trained model and compares each render with
//! the ground-truth photo of the same name, as the original 3DGS `render.py` +
//! `metrics.py` do: PSNR, SSIM and LDR-FLIP per image and on average.

use super::common::{
    fail_on_validation_messages, load_scene, model_cameras, GpuArgs, KernelArg, SceneArg,
};
use super::compare::{csv_cell, db, db_csv};
use super::eval_photo::render_size;
use anyhow::{bail, Context, Result};
use clap::Args;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use verisplat::app::shard::Shard;
use verisplat::core::camera::Camera;
use verisplat::core::console::{note, outln};
use verisplat::io;

use verisplat::io::color_fit;
use verisplat::io::image_file::{self, Planes};
use verisplat::io::metrics;
use verisplat::io::output;
use verisplat::render::GpuRenderer;
use verisplat::render::{FrameRequest, Rendered};
use verisplat::train::masks;

/// Every `LLFF_HOLD`-th camera (in image-name order, from the first) is a test camera when
/// the data set names no split: the original code's `llffhold`.
pub(crate) const LLFF_HOLD: usize = 8;

#[derive(Args)]
#[command(after_help = "\
Photos are found by the camera's img_name in DIR, with any of the extensions .png, .jpg, \
.jpeg, .webp, .exr, .npy (lower or upper case). Cameras are taken in image-name order, as \
the trainer sorts them; --split test keeps cameras 0, 8, 16, ... of that order (the \
llffhold rule), train the others, unless DIR/../sparse/0/test.txt lists the test images. \
A photo with alpha is composited over --background. A photo smaller than the camera by \
one factor on both sides (images downscaled for training) is compared with a render at \
its size. Renders are clamped to [0, 1] and quantised to 8 bits as render.py saves them \
(--float keeps the float values). SSIM: 11x11 Gaussian window, sigma 1.5, zero padding, \
as the original utils/loss_utils.py; FLIP: NVIDIA's LDR-FLIP, mean over the image, with \
the values as sRGB-encoded display values. PSNR of identical images is \"inf\" in the \
table and the CSV and null in the JSON.

With --shard I/N (or slurm, in a task of a Slurm job array) a process evaluates a \
contiguous block of the split's cameras and writes DIR/report.shard-I-of-N.json and .csv; \
`eval --merge DIR` then checks that every shard is there once and writes DIR/report.json \
and report.csv, the files one process writes.

Examples:
  verisplat eval model/ --images dataset/images --split test
  verisplat eval scene.ply --cameras cameras.json --images photos/ -o eval_report/
  verisplat eval model/ --images dataset/images -o rep/ --shard slurm   # sbatch --array=0-7
  verisplat eval --merge rep/")]
pub(crate) struct EvalArgs {
    /// Scene: INRIA .ply, compressed .ply, .splat, .spz or SOG (detected from the content),
    /// or a trained model directory (uses point_cloud/iteration_<largest>/).
    #[arg(required_unless_present_any = ["demo", "merge"])]
    pub(crate) scene: Option<PathBuf>,
    /// Use the built-in demo scene (PLAYBOT, 1,873 Gaussians, CC BY 4.0).
    #[arg(long, conflicts_with = "scene")]
    pub(crate) demo: bool,
    /// Iteration of a trained model directory: point_cloud/iteration_N (default: the largest).
    #[arg(long, value_name = "N", conflicts_with = "demo")]
    pub(crate) iteration: Option<u64>,
    #[command(flatten)]
    pub(crate) spz: super::common::SpzAxesArg,
    /// Camera file (INRIA cameras.json, COLMAP model, or a model directory) [default: the
    /// model directory's cameras.json].
    #[arg(long, value_name = "FILE")]
    pub(crate) cameras: Option<PathBuf>,
    /// Folder of the ground-truth photos, named after the cameras.
    #[arg(long, value_name = "DIR", required_unless_present = "merge")]
    pub(crate) images: Option<PathBuf>,
    /// Scale the photos as `train -r` did: 1, 2, 4 or 8 divide the size, another number
    /// is a width in pixels [default: the model directory's cfg_args resolution; without
    /// one, photos larger than their camera by one factor are scaled to its size].
    #[arg(short = 'r', long, value_name = "N")]
    pub(crate) resolution: Option<u32>,
    /// Which cameras to evaluate: test (every 8th, or the data set's test.txt), train (the
    /// others) or all.
    #[arg(long, value_name = "SPLIT", default_value = "test", value_parser = ["test", "train", "all"])]
    pub(crate) split: String,
    /// Leave out cameras without a photo (with a note) instead of stopping.
    #[arg(long)]
    pub(crate) skip_missing: bool,
    /// Report directory: report.json and report.csv (with --shard, report.shard-I-of-N.*)
    /// [default: eval_report; with --merge, the first DIR].
    #[arg(short, long, value_name = "DIR")]
    pub(crate) output: Option<PathBuf>,
    /// Evaluate shard I of N (0-based) of the split's cameras, a contiguous block; `slurm`
    /// reads SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT and SLURM_ARRAY_TASK_MIN.
    #[arg(long, value_name = "I/N|slurm")]
    pub(crate) shard: Option<String>,
    /// Merge the shard reports (report.shard-I-of-N.json) found in DIRs (or given as
    /// files) into one report, after checking that they are the shards of one evaluation,
    /// each present once.
    #[arg(long, value_name = "DIR", num_args = 1.., conflicts_with_all = ["scene", "demo", "cameras", "images", "shard", "cpu", "resolution"])]
    pub(crate) merge: Vec<PathBuf>,
    /// Replace report files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// Do nothing when the report files (of this shard) exist: re-running a job array
    /// whose tasks were killed finishes only what is missing.
    #[arg(long, conflicts_with = "overwrite")]
    pub(crate) skip_existing: bool,
    /// Background colour, linear R,G,B in [0, 1] (or "black" / "white"); photos with
    /// alpha are composited over it too.
    #[arg(long, value_name = "R,G,B", default_value = "0,0,0", value_parser = super::values::background, allow_hyphen_values = true)]
    pub(crate) background: [f32; 3],
    /// Compare the float render (clamped to [0, 1]) instead of its 8-bit quantisation.
    #[arg(long)]
    pub(crate) float: bool,
    /// Pixels per degree of visual angle for FLIP [default: 67.02, FLIP's own: 0.7 m from
    /// a 0.7 m wide 3840-pixel display].
    #[arg(long, value_name = "PPD")]
    pub(crate) ppd: Option<f64>,
    /// Opacity compensation for scenes trained with antialiasing (see `render --help`).
    #[arg(long)]
    pub(crate) antialiased: bool,
    /// Render without the compensation even when the file records antialiased training.
    #[arg(long, conflicts_with = "antialiased")]
    pub(crate) no_antialiased: bool,
    #[command(flatten)]
    pub(crate) kernel: KernelArg,
    /// Render with the CPU reference renderer instead of the Vulkan pipeline.
    #[arg(long)]
    pub(crate) cpu: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub(crate) quiet: bool,
    #[command(flatten)]
    pub(crate) gpu: GpuArgs,
}

/// One evaluated image, as the reports hold it.
#[derive(Serialize, Deserialize)]
struct ImageRecord {
    frame: usize,
    camera: String,
    photo: String,
    width: u32,
    height: u32,
    #[serde(deserialize_with = "null_is_infinite")]
    psnr: f64,
    /// PSNR after the render's best affine colour fit to the photo (`io::color_fit`).
    #[serde(default = "not_measured", deserialize_with = "null_is_infinite")]
    psnr_cc: f64,
    ssim: f64,
    flip: f64,
    /// Scored over the pixels its mask keeps only.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    masked: bool,
    /// Scored inside the fisheye's image circle only (`train::masks::image_circle`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    image_circle: bool,
}

#[derive(Serialize, Deserialize)]
struct Means {
    #[serde(deserialize_with = "null_is_infinite")]
    psnr: f64,
    #[serde(default = "not_measured", deserialize_with = "null_is_infinite")]
    psnr_cc: f64,
    ssim: f64,
    flip: f64,
}

/// Which shard of a split evaluation a report is.
#[derive(Serialize, Deserialize, Clone, Copy)]
struct ShardRecord {
    index: usize,
    count: usize,
}

#[derive(Serialize, Deserialize)]
struct EvalReport {
    scene: String,
    cameras: String,
    images: String,
    split: String,
    split_rule: String,
    renderer: String,
    quantized: bool,
    ppd: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    shard: Option<ShardRecord>,
    results: Vec<ImageRecord>,
    skipped: Vec<String>,
    mean: Option<Means>,
}

/// A PSNR read back from a report: JSON has no infinity, so identical images' "inf" is
/// written as null.
fn null_is_infinite<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// A report written before the colour-corrected PSNR: not measured.
fn not_measured() -> f64 {
    f64::NAN
}

/// The means of `results`, summed in their order (a merged report sums as one run does).
fn means(results: &[ImageRecord]) -> Option<Means> {
    if results.is_empty() {
        return None;
    }
    let n = results.len() as f64;
    Some(Means {
        psnr: results.iter().map(|r| r.psnr).sum::<f64>() / n,
        psnr_cc: results.iter().map(|r| r.psnr_cc).sum::<f64>() / n,
        ssim: results.iter().map(|r| r.ssim).sum::<f64>() / n,
        flip: results.iter().map(|r| r.flip).sum::<f64>() / n,
    })
}

/// The report's CSV: one row per image, then the means.
fn report_csv(report: &EvalReport) -> String {
    let mut csv = String::from("frame,camera,photo,width,height,psnr,ssim,flip,psnr_cc\n");
    for r in &report.results {
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{}\n",
            r.frame,
            csv_cell(&r.camera),
            csv_cell(&r.photo),
            r.width,
            r.height,
            db_csv(r.psnr),
            r.ssim,
            r.flip,
            db_csv(r.psnr_cc)
        ));
    }
    if let Some(mean) = &report.mean {
        csv.push_str(&format!(
            "mean,,,,,{},{},{},{}\n",
            db_csv(mean.psnr),
            mean.ssim,
            mean.flip,
            db_csv(mean.psnr_cc)
        ));
    }
    csv
}

/// The report files in `dir`: `report.json` and `report.csv`, or a shard's.
fn report_files(dir: &Path, shard: Option<Shard>) -> [PathBuf; 2] {
    ["report.json", "report.csv"].map(|f| {
        let file = dir.join(f);
        match shard {
            Some(s) => s.file_name(&file),
            None => file,
        }
    })
}

/// Refuses to start when a report file exists and --overwrite was not given.
fn check_report_files(files: &[PathBuf], overwrite: bool) -> Result<()> {
    if let Some(p) = files.iter().find(|p| !overwrite && p.exists()) {
        return Err(output::OutputError::Exists(p.clone()).into());
    }
    Ok(())
}

/// Writes `report` as JSON and CSV to `files` (each atomically), creating their folder.
fn write_report(report: &EvalReport, files: &[PathBuf; 2], overwrite: bool) -> Result<()> {
    let dir = files[0].parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the report directory", dir.display()))?;
    output::write_bytes_atomically(
        &files[0],
        overwrite,
        serde_json::to_string_pretty(report)?.as_bytes(),
    )?;
    output::write_bytes_atomically(&files[1], overwrite, report_csv(report).as_bytes())?;
    Ok(())
}

/// The mean line of the table printed on stdout.
fn print_mean(count: usize, mean: &Means) {
    outln!(
        "{:>5}  {:<24} {:>9} {:>9} {:>9.5} {:>9.5}",
        "",
        format!("mean of {count}"),
        db(mean.psnr),
        db(mean.psnr_cc),
        mean.ssim,
        mean.flip
    );
}

/// Photo file extensions tried after a camera's name, in order.
const PHOTO_EXTENSIONS: [&str; 9] = [
    "png", "jpg", "jpeg", "webp", "exr", "npy", "PNG", "JPG", "JPEG",
];

/// The photo of camera `name` in `dir`: `dir/name` when the name has an extension and
/// that file exists, else `dir/<name or its stem>.<ext>`. `Err` lists what was tried.
fn find_photo(dir: &Path, name: &str) -> std::result::Result<PathBuf, String> {
    let direct = dir.join(name);
    let has_ext = Path::new(name)
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| image_file::EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
    if has_ext && direct.is_file() {
        return Ok(direct);
    }
    let stem = if has_ext {
        Path::new(name)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| name.to_string())
    } else {
        name.to_string()
    };
    for ext in PHOTO_EXTENSIONS {
        let p = dir.join(format!("{stem}.{ext}"));
        if p.is_file() {
            return Ok(p);
        }
    }
    Err(format!(
        "{}.{{{}}}",
        dir.join(&stem).display(),
        PHOTO_EXTENSIONS[..6].join(",")
    ))
}

/// A photo as `H x W x 3` colour in [0, 1]: grey is spread to RGB, and alpha composites
/// the colour over `background`.
fn photo_rgb(p: &Planes, path: &Path, background: [f32; 3]) -> Result<Vec<f32>> {
    let rgb = if let Some(v) = p.interleave(&["R", "G", "B"]) {
        v
    } else if let Some(y) = p.channel("Y") {
        y.values.iter().flat_map(|&v| [v, v, v]).collect()
    } else {
        bail!(
            "{}: has no colour channels (R, G, B or grey); its channels are {}",
            path.display(),
            p.names().join(", ")
        );
    };
    let mut rgb: Vec<f32> = rgb.into_iter().map(|v| v.clamp(0.0, 1.0)).collect();
    if let Some(a) = p.channel("A") {
        for (px, &a) in rgb.chunks_mut(3).zip(&a.values) {
            let a = a.clamp(0.0, 1.0);
            for (c, bg) in px.iter_mut().zip(background) {
                *c = *c * a + bg * (1.0 - a);
            }
        }
    }
    Ok(rgb)
}

/// The test image names of `images/../sparse/0/test.txt`, when the data set has one.
fn test_list(images: &Path) -> Option<(PathBuf, Vec<String>)> {
    let file = images.parent()?.join("sparse").join("0").join("test.txt");
    let text = std::fs::read_to_string(&file).ok()?;
    let names = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .map(str::to_string)
        .collect();
    Some((file, names))
}

/// A name without a photo extension, so `IMG_1.JPG` in a list matches camera `IMG_1`.
fn stem(name: &str) -> &str {
    match name.rsplit_once('.') {
        Some((s, e)) if image_file::EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()) => s,
        _ => name,
    }
}

/// The cameras of `split`, with their indices in the camera file, in image-name order,
/// and a sentence saying which rule chose them.
fn split_cameras(cams: Vec<Camera>, split: &str, images: &Path) -> (Vec<(usize, Camera)>, String) {
    let mut ordered: Vec<(usize, Camera)> = cams.into_iter().enumerate().collect();
    // The trainer sorts its cameras by image name before holding out test views.
    ordered.sort_by(|a, b| a.1.name.cmp(&b.1.name));
    if split == "all" {
        return (ordered, "all cameras".into());
    }
    let want_test = split == "test";
    let list = test_list(images);
    let rule = match &list {
        Some((file, _)) => format!("the test images listed in {}", file.display()),
        None => {
            format!("every {LLFF_HOLD}th camera in image-name order is a test camera (llffhold)")
        }
    };
    let chosen = ordered
        .into_iter()
        .enumerate()
        .filter(|(k, (_, c))| {
            let is_test = match &list {
                Some((_, names)) => names.iter().any(|n| stem(n) == stem(&c.name)),
                None => k % LLFF_HOLD == 0,
            };
            is_test == want_test
        })
        .map(|(_, c)| c)
        .collect();
    (chosen, rule)
}

pub(crate) fn eval(args: &EvalArgs) -> Result<()> {
    if !args.merge.is_empty() {
        return merge(args);
    }
    let scene_arg = SceneArg {
        scene: args.scene.clone(),
        demo: args.demo,
        iteration: args.iteration,
        spz: args.spz,
    };
    let shard = super::common::shard(args.shard.as_deref())?;
    let (ppd, images) = checked_ppd_and_images(args)?;
    let out_dir = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from("eval_report"));
    let files = report_files(&out_dir, shard);
    if args.skip_existing && files.iter().all(|f| f.exists()) {
        note!("{} exists; nothing to evaluate", files[0].display());
        return Ok(());
    }
    check_report_files(&files, args.overwrite)?;
    let cameras_file = cameras_file(args, &scene_arg)?;
    let (scene, name) = load_scene(&scene_arg)?;
    super::common::refuse_time_varying(&scene, &name, "eval")?;
    let (cams, rule) = split_and_shard_cameras(args, &cameras_file, images, shard)?;
    let (jobs, skipped) = match_photos(args, cams, images)?;
    // A shard may have no cameras (more shards than cameras) or none with a photo; its
    // empty report still tells the merge that it ran.
    if jobs.is_empty() && shard.is_none() {
        bail!(
            "no camera of the {} split has a photo in {}",
            args.split,
            images.display()
        );
    }
    let antialiased = args.antialiased || (scene.antialiased && !args.no_antialiased);
    let opts = verisplat::cpu::RenderOptions {
        background: args.background,
        antialiased,
        kernel: args.kernel.resolve(&scene, &name),
        rules: args.kernel.resolve_rules(&scene, &name),
        reproducible: args.kernel.reproducible,
        ..Default::default()
    };
    let act = scene.activated();
    let mut gpu = if args.cpu || jobs.is_empty() {
        None
    } else {
        let renderer = GpuRenderer::new(args.gpu.context()?)?;
        let uploaded = renderer.upload(&act)?;
        Some((renderer, uploaded))
    };
    let renderer_name = match &gpu {
        Some((r, _)) => format!("GPU pipeline on {}", r.ctx().info().name),
        None => "CPU reference renderer".into(),
    };
    let measure = Measure {
        args,
        prep: super::eval_photo::PhotoPrep::new(args.resolution, scene_arg.scene.as_deref())?,
        frame_masks: match images.parent() {
            Some(dir) => super::eval_mask::FrameMasks::read(dir)?,
            None => None,
        },
        ppd,
        scene: &act,
        opts: &opts,
    };
    let results = measure.all(&mut gpu, &jobs)?;
    if let Some((r, _)) = &gpu {
        fail_on_validation_messages(r.ctx())?;
    }
    let mean = means(&results);
    if let Some(mean) = &mean {
        print_mean(results.len(), mean);
    }
    let circled = results.iter().filter(|r| r.image_circle).count();
    if circled > 0 {
        outln!("scored only the pixels inside the image circle of {circled} fisheye photo(s) (past its field of view the lens images nothing)");
    }
    let masked = results.iter().filter(|r| r.masked).count();
    if masked > 0 {
        outln!("scored only the unmasked pixels of {masked} photo(s) (their masks in the masks folder beside {}, or their frames' mask_path)", images.display());
    }
    let report = EvalReport {
        scene: name.clone(),
        cameras: cameras_file.display().to_string(),
        images: images.display().to_string(),
        split: args.split.clone(),
        split_rule: rule,
        renderer: renderer_name.clone(),
        quantized: !args.float,
        ppd,
        shard: shard.map(|s| ShardRecord {
            index: s.index,
            count: s.count,
        }),
        results,
        skipped,
        mean,
    };
    // Written only now, so a run stopped by a bad photo leaves nothing behind.
    write_report(&report, &files, args.overwrite)?;
    note!(
        "evaluated {} image(s) of {name} ({renderer_name}){}; report in {}",
        report.results.len(),
        if report.skipped.is_empty() {
            String::new()
        } else {
            format!(
                ", {} camera(s) without a photo skipped",
                report.skipped.len()
            )
        },
        files[0].display()
    );
    Ok(())
}

/// `--ppd` (checked, or FLIP's default) and the folder of photos (`--images`, checked).
fn checked_ppd_and_images(args: &EvalArgs) -> Result<(f64, &Path)> {
    let ppd = args.ppd.unwrap_or_else(metrics::flip_default_ppd);
    if !(ppd.is_finite() && ppd > 0.0) {
        bail!("--ppd {ppd} must be a positive number");
    }
    let Some(images) = args.images.as_deref() else {
        bail!("eval needs the folder of ground-truth photos: pass --images DIR");
    };
    if !images.is_dir() {
        bail!("{}: is not a folder of photos (--images)", images.display());
    }
    Ok((ppd, images))
}

/// The cameras of the photos: `--cameras`, or the model directory's cameras.json.
fn cameras_file(args: &EvalArgs, scene_arg: &SceneArg) -> Result<PathBuf> {
    Ok(match &args.cameras {
        Some(f) => f.clone(),
        None => match model_cameras(scene_arg) {
            Some(f) => f,
            None => bail!("eval needs the cameras of the photos: pass --cameras FILE (a cameras.json, a COLMAP model or a model directory), or a trained model directory holding cameras.json"),
        },
    })
}

/// The cameras of `--split` in `cameras_file` (announced, with the rule that chose them),
/// or a shard's block of them; and the rule.
fn split_and_shard_cameras(
    args: &EvalArgs,
    cameras_file: &Path,
    images: &Path,
    shard: Option<Shard>,
) -> Result<(Vec<(usize, Camera)>, String)> {
    let (all, format) =
        io::camera::load_camera_file(cameras_file, &io::camera::PathTiming::default())?;
    let total = all.len();
    let (cams, rule) = split_cameras(all, &args.split, images);
    if cams.is_empty() {
        bail!(
            "{}: the {} split is empty ({total} camera(s); {rule})",
            cameras_file.display(),
            args.split
        );
    }
    note!(
        "{} split: {} of {total} camera(s) of {} ({format}); {rule}",
        args.split,
        cams.len(),
        cameras_file.display()
    );
    // The block of a shard is chosen before photos are matched, so it does not depend on
    // which photos exist.
    let cams = match shard {
        Some(s) => {
            let all = cams.len();
            let mine = s.take(cams);
            note!("{s}: {} of the {all} camera(s)", mine.len());
            mine
        }
        None => cams,
    };
    Ok((cams, rule))
}

/// A camera to evaluate: its index in the camera file, the camera and its photo.
type Job = (usize, Camera, PathBuf);

/// Matches every camera with its photo before rendering anything: the cameras with one,
/// and the names of those without (skipped with `--skip-missing`, else an error).
fn match_photos(
    args: &EvalArgs,
    cams: Vec<(usize, Camera)>,
    images: &Path,
) -> Result<(Vec<Job>, Vec<String>)> {
    let mut jobs = Vec::new();
    let mut skipped = Vec::new();
    for (k, cam) in cams {
        match find_photo(images, &cam.name) {
            Ok(photo) => jobs.push((k, cam, photo)),
            Err(tried) if args.skip_missing => {
                note!("note: camera {k} (\"{}\") has no photo ({tried}); skipped", cam.name);
                skipped.push(cam.name.clone());
            }
            Err(tried) => bail!(
                "camera {k} (\"{}\") has no photo: looked for {tried} (--skip-missing leaves such cameras out)",
                cam.name
            ),
        }
    }
    Ok((jobs, skipped))
}

/// The device renderer and the scene uploaded to it (`None`: the CPU reference renders).
type Gpu = Option<(GpuRenderer, verisplat::render::GpuScene)>;

/// What each image is rendered and measured with.
struct Measure<'a> {
    args: &'a EvalArgs,
    prep: super::eval_photo::PhotoPrep,
    /// The masks the data set's transforms files name (`mask_path`), read once.
    frame_masks: Option<super::eval_mask::FrameMasks>,
    ppd: f64,
    scene: &'a verisplat::core::model::ActivatedScene,
    opts: &'a verisplat::cpu::RenderOptions,
}

impl Measure<'_> {
    /// Renders and measures every camera against its photo, printing the table's rows
    /// under a progress bar.
    fn all(&self, gpu: &mut Gpu, jobs: &[Job]) -> Result<Vec<ImageRecord>> {
        let bar = if self.args.quiet {
            indicatif::ProgressBar::hidden()
        } else {
            let bar = indicatif::ProgressBar::new(jobs.len() as u64);
            bar.set_style(
                indicatif::ProgressStyle::with_template(
                    "{bar:40.cyan/blue} {pos}/{len} images  ETA {eta}  {msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            bar
        };
        outln!(
            "{:>5}  {:<24} {:>9} {:>9} {:>9} {:>9}  {:>9}",
            "frame",
            "camera",
            "PSNR dB",
            "PSNR cc",
            "SSIM",
            "FLIP",
            "size"
        );
        let mut results = Vec::new();
        for (k, cam, photo_path) in jobs {
            bar.set_message(cam.name.clone());
            let record = self.image(gpu, *k, cam, photo_path)?;
            bar.suspend(|| {
                outln!(
                    "{:>5}  {:<24} {:>9} {:>9} {:>9.5} {:>9.5}  {:>9}",
                    record.frame,
                    record.camera,
                    db(record.psnr),
                    db(record.psnr_cc),
                    record.ssim,
                    record.flip,
                    format!("{}x{}", record.width, record.height)
                )
            });
            results.push(record);
            bar.inc(1);
        }
        bar.finish_and_clear();
        Ok(results)
    }

    /// Camera `k` rendered at its photo's size and measured against it.
    fn image(
        &self,
        gpu: &mut Gpu,
        k: usize,
        cam: &Camera,
        photo_path: &Path,
    ) -> Result<ImageRecord> {
        let args = self.args;
        let photo = image_file::read_image(photo_path)?;
        let truth = photo_rgb(&photo, photo_path, args.background)?;
        let (truth, pw, ph) = self.prep.prepare(cam, truth, (photo.width, photo.height));
        let keep = super::eval_mask::photo_mask(
            &self.prep,
            self.frame_masks.as_ref(),
            cam,
            photo_path,
            (photo.width, photo.height),
        )?;
        let (w, h) = render_size(cam.width, cam.height, pw, ph).ok_or_else(|| {
            anyhow::anyhow!(
                "camera {k} (\"{}\") is {}x{} but its photo {} is {}x{}{}; a photo may only be smaller by one factor on both sides (images downscaled for training; -r scales photos as train -r did)",
                cam.name,
                cam.width,
                cam.height,
                photo_path.display(),
                photo.width,
                photo.height,
                if (pw, ph) == (photo.width, photo.height) {
                    String::new()
                } else {
                    format!(" ({pw}x{ph} as prepared)")
                }
            )
        })?;
        let cam = cam.with_resolution(w, h)?;
        cam.validate()?;
        let frame = match gpu.as_mut() {
            Some((r, s)) => r
                .render(&FrameRequest::new(s, &cam, self.opts))
                .and_then(Rendered::into_frame)?,
            None => verisplat::cpu::render(self.scene, &cam, self.opts),
        };
        let render: Vec<f32> = metrics::clamped_color(&frame)
            .into_iter()
            .map(|v| {
                if args.float {
                    v
                } else {
                    output::to_u8(v) as f32 / 255.0
                }
            })
            .collect();
        let (wu, hu) = (w as usize, h as usize);
        let masked = keep.is_some();
        // A fisheye's pixels past its field of view are not scored, as they are not
        // trained on: its lens images no ray there (the photo's black border).
        let circle = masks::image_circle(&cam);
        let image_circle = circle.is_some();
        let keep = match (keep.filter(|k| k.len() == wu * hu), circle) {
            (Some(k), Some(c)) => Some(k.iter().zip(&c).map(|(a, b)| *a && *b).collect()),
            (k, c) => k.or(c),
        };
        let (psnr, ssim, flip) = match keep.as_deref() {
            Some(k) => masks::masked_metrics(&truth, &render, (wu, hu), k, self.ppd),
            None => (
                metrics::psnr(&truth, &render, 1.0),
                metrics::ssim(&truth, &render, wu, hu, 3),
                metrics::flip(&truth, &render, wu, hu, self.ppd),
            ),
        };
        let corrected = color_fit::affine_color_corrected(&truth, &render, keep.as_deref());
        let psnr_cc = masks::masked_psnr(&truth, &corrected, keep.as_deref());
        Ok(ImageRecord {
            frame: k,
            camera: cam.name.clone(),
            photo: photo_path.display().to_string(),
            width: w,
            height: h,
            psnr,
            psnr_cc,
            ssim,
            flip,
            masked,
            image_circle,
        })
    }
}

/// `eval --merge DIR...`: the shard reports of one split evaluation as one report.
fn merge(args: &EvalArgs) -> Result<()> {
    let out_dir = args.output.clone().unwrap_or_else(|| args.merge[0].clone());
    let files = report_files(&out_dir, None);
    check_report_files(&files, args.overwrite)?;
    // The shard reports: files given, or report.shard-I-of-N.json in folders given.
    let mut found: Vec<(Shard, PathBuf)> = Vec::new();
    for given in &args.merge {
        let candidates: Vec<PathBuf> = if given.is_dir() {
            let entries = std::fs::read_dir(given)
                .with_context(|| format!("{}: cannot list the folder", given.display()))?;
            entries.flatten().map(|e| e.path()).collect()
        } else if given.is_file() {
            vec![given.clone()]
        } else {
            bail!("{}: no such folder or file (--merge)", given.display());
        };
        for path in candidates {
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
            let tag = name
                .as_deref()
                .and_then(|n| n.strip_prefix("report."))
                .and_then(|n| n.strip_suffix(".json"));
            if let Some(shard) = tag.and_then(Shard::parse_tag) {
                found.push((shard, path));
            }
        }
    }
    let Some(count) = found.first().map(|(s, _)| s.count) else {
        bail!(
            "no shard reports (report.shard-I-of-N.json) in {}",
            args.merge
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    };
    if let Some((s, p)) = found.iter().find(|(s, _)| s.count != count) {
        bail!(
            "{}: is {s} but {} is a shard of {count}: reports of different splits",
            p.display(),
            found[0].1.display()
        );
    }
    found.sort_by_key(|(s, _)| s.index);
    if let Some(w) = found.windows(2).find(|w| w[0].0.index == w[1].0.index) {
        bail!(
            "{} and {}: both are {}; merge the reports of one run",
            w[0].1.display(),
            w[1].1.display(),
            w[0].0
        );
    }
    let missing: Vec<String> = (0..count)
        .filter(|i| !found.iter().any(|(s, _)| s.index == *i))
        .map(|i| i.to_string())
        .collect();
    if !missing.is_empty() {
        bail!(
            "{} of {count} shard report(s) missing: shard(s) {} (run them, e.g. the same array with only those task ids)",
            missing.len(),
            missing.join(", ")
        );
    }
    let mut merged: Option<EvalReport> = None;
    for (shard, path) in &found {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the shard report", path.display()))?;
        let part: EvalReport = serde_json::from_str(&text)
            .with_context(|| format!("{}: is not an eval report", path.display()))?;
        match part.shard {
            Some(r) if (r.index, r.count) == (shard.index, shard.count) => {}
            _ => bail!(
                "{}: its content is not {shard} (renamed?); merge the files eval wrote",
                path.display()
            ),
        }
        let Some(whole) = merged.as_mut() else {
            merged = Some(part);
            continue;
        };
        let differs = [
            ("scene", &whole.scene, &part.scene),
            ("cameras", &whole.cameras, &part.cameras),
            ("images", &whole.images, &part.images),
            ("split", &whole.split, &part.split),
        ]
        .into_iter()
        .find(|(_, a, b)| a != b)
        .map(|(what, a, b)| format!("{what} {a:?} vs {b:?}"))
        .or_else(|| {
            (whole.quantized != part.quantized || whole.ppd != part.ppd)
                .then(|| "quantisation or --ppd".to_string())
        });
        if let Some(d) = differs {
            bail!(
                "{}: is not a shard of the same evaluation as {} ({d})",
                path.display(),
                found[0].1.display()
            );
        }
        // Shards on different devices: the report names each device. A shard with no
        // image rendered nothing: it names no renderer.
        if whole.results.is_empty() {
            whole.renderer = part.renderer.clone();
        } else if !part.results.is_empty()
            && !whole.renderer.split("; ").any(|r| r == part.renderer)
        {
            whole.renderer = format!("{}; {}", whole.renderer, part.renderer);
        }
        whole.results.extend(part.results);
        whole.skipped.extend(part.skipped);
    }
    let Some(mut report) = merged else {
        bail!("no shard reports to merge");
    };
    if report.results.is_empty() {
        bail!(
            "no camera of the {} split had a photo in {} (every shard report is empty)",
            report.split,
            report.images
        );
    }
    report.shard = None;
    report.mean = means(&report.results);
    if let Some(mean) = &report.mean {
        print_mean(report.results.len(), mean);
    }
    write_report(&report, &files, args.overwrite)?;
    note!(
        "merged {count} shard report(s): {} image(s) of {}; report in {}",
        report.results.len(),
        report.scene,
        files[0].display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn downscaled_photos_render_at_their_size_other_sizes_are_refused() {
        assert_eq!(render_size(1600, 1064, 1600, 1064), Some((1600, 1064)));
        assert_eq!(render_size(1600, 1064, 800, 532), Some((800, 532)));
        assert_eq!(render_size(1600, 1064, 400, 266), Some((400, 266)));
        // Rational factor 2/3, and a side rounded to whole pixels (1297 / 2 = 648.5).
        assert_eq!(render_size(1200, 900, 800, 600), Some((800, 600)));
        assert_eq!(render_size(1297, 840, 648, 420), Some((648, 420)));
        // Larger, different aspect ratio, or only one side smaller.
        assert_eq!(render_size(800, 600, 1600, 1200), None);
        assert_eq!(render_size(800, 600, 400, 400), None);
        assert_eq!(render_size(800, 600, 800, 300), None);
    }

    #[test]
    fn llffhold_takes_every_eighth_camera_in_name_order() {
        let cam = |n: &str| {
            let mut c = verisplat::core::camera::default_camera(&[[0.0; 3]], 8, 8);
            c.name = n.into();
            c
        };
        // File order: test cameras first (as the trainer writes cameras.json), then train.
        let names: Vec<String> = (0..20).map(|i| format!("img_{i:03}")).collect();
        let mut file: Vec<Camera> = [0, 8, 16].iter().map(|&i| cam(&names[i])).collect();
        file.extend((0..20).filter(|i| i % 8 != 0).map(|i| cam(&names[i])));
        let none = Path::new("/nonexistent/images");
        let (test, rule) = split_cameras(file.clone(), "test", none);
        let got: Vec<&str> = test.iter().map(|(_, c)| c.name.as_str()).collect();
        assert_eq!(got, ["img_000", "img_008", "img_016"], "{rule}");
        assert_eq!(test.iter().map(|(k, _)| *k).collect::<Vec<_>>(), [0, 1, 2]);
        let (train, _) = split_cameras(file.clone(), "train", none);
        assert_eq!(train.len(), 17);
        assert!(train.iter().all(|(_, c)| !got.contains(&c.name.as_str())));
        assert_eq!(split_cameras(file, "all", none).0.len(), 20);
    }

    #[test]
    fn a_data_sets_test_txt_is_an_explicit_split() {
        let dir = tempfile::tempdir().unwrap();
        let images = dir.path().join("images");
        std::fs::create_dir_all(dir.path().join("sparse/0")).unwrap();
        std::fs::write(
            dir.path().join("sparse/0/test.txt"),
            "img_3.JPG\nimg_5.png\n",
        )
        .unwrap();
        let cams: Vec<Camera> = (0..9)
            .map(|i| {
                let mut c = verisplat::core::camera::default_camera(&[[0.0; 3]], 8, 8);
                c.name = format!("img_{i}");
                c
            })
            .collect();
        let (test, rule) = split_cameras(cams.clone(), "test", &images);
        let names: Vec<&str> = test.iter().map(|(_, c)| c.name.as_str()).collect();
        assert_eq!(names, ["img_3", "img_5"]);
        assert!(rule.contains("test.txt"), "{rule}");
        assert_eq!(split_cameras(cams, "train", &images).0.len(), 7);
    }

    #[test]
    fn photos_are_found_by_name_with_any_extension() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("a.png"), b"").unwrap();
        std::fs::write(dir.path().join("b.JPG"), b"").unwrap();
        std::fs::write(dir.path().join("c.exr"), b"").unwrap();
        assert!(find_photo(dir.path(), "a").unwrap().ends_with("a.png"));
        assert!(find_photo(dir.path(), "b").unwrap().ends_with("b.JPG"));
        assert!(find_photo(dir.path(), "b.JPG").unwrap().ends_with("b.JPG"));
        // A COLMAP-style name with an extension also finds a converted photo.
        assert!(find_photo(dir.path(), "c.jpg").unwrap().ends_with("c.exr"));
        let e = find_photo(dir.path(), "d").unwrap_err();
        assert!(e.contains("d.{png,jpg,jpeg,webp,exr,npy}"), "{e}");
    }
}
