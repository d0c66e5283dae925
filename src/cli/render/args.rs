//! The arguments of `verisplat render` ([`RenderArgs`], with the field renders' own
//! [`FieldArgs`]) and the check of the options `--cpu` cannot honour.

use crate::cli::common::{CameraArgs, FilterArgs, GpuArgs, KernelArg, PathArgs, SceneArg};
use crate::cli::values;
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;
use verisplat::app::sequence::FrameSelection;
use verisplat::cpu::field::MAX_FIELD_SAMPLES;
use verisplat::io::output;

#[derive(Args)]
#[command(after_help = "Examples:
  verisplat render scene.ply -o view.png
  verisplat render scene.ply --orbit 120 -o orbit/frame_{:05}.exr
  verisplat render model_dir/ --cameras cameras.json --camera 0,8,16 -o renders/{name}.png
  verisplat render scene.spz --cameras path.json --frames 100..200 -o out/ --format exr
  verisplat render scene.ply --orbit 120 -o orbit/f_%04d.png --skip-existing   # resume
  verisplat render scene.ply --cameras path.json -o turn.mp4 --fps 24   # a video (ffmpeg)
  verisplat render scene.ply --orbit 1200 -o orbit/ --shard slurm   # a task of sbatch --array=0-7
  verisplat render scene.ply --orbit 1200 -o orbit/ --verify        # after the array: all there?
  verisplat render scene.ply --orbit 48 --width 320 --height 240 --export-colmap data/   # a data set to train on
  verisplat render moving.ply --time 0.5 --mode field-slice --slice-plane 0,0,0,0,0,1 -o t05.png
  verisplat render moving.ply --time-range 0,1 --time-frames 30 --mode field-max -o anim/frame_%04d.png

A time-varying scene (t_mean, t_scale per Gaussian, what `fit --time-column` writes) is
rendered at a time: --time T, or --time-range T0,T1 for an animation; without either it is
refused (there is no default time).")]
pub(crate) struct RenderArgs {
    #[command(flatten)]
    pub(crate) scene: SceneArg,
    #[command(flatten)]
    pub(crate) view: CameraArgs,
    #[command(flatten)]
    pub(crate) path: PathArgs,
    /// Output: a file (.png or .exr), a pattern with {} / {:05} / %05d / ##### (frame
    /// number) or {name} (camera name), e.g. out/frame_{:05}.exr, or a directory (out/
    /// gives out/frame_00000.png, ...) [default: render.png for one frame,
    /// render/frame_{:05}.png for several]; or a video, out.mp4 (H.264), out.webm (VP9)
    /// or out.gif, encoded by the system ffmpeg at --fps (default 30) and --quality.
    #[arg(short, long, value_name = "OUT")]
    pub(crate) output: Option<PathBuf>,
    /// What to write: rgb, rgba, alpha, depth, rgb+depth, features, normal, median-depth,
    /// field-slice, field-integral or field-max [default: rgb for PNG, rgb+depth (R, G, B,
    /// A, Z) for EXR]. rgba: PNG with a transparent background (straight colour; EXR as
    /// rgb). Depth PNGs are colour-mapped for looking at. features: the scene's feature
    /// channels blended like colour over 0, as EXR (feat.0 ... feat.K-1, A, Z) or .npy (H x
    /// W x K float32). normal: each Gaussian's shortest axis facing the camera, blended
    /// like colour and normalised (EXR: N.x, N.y, N.z, A; PNG: 0.5 + 0.5 n, black where
    /// nothing is hit; --normal-space). median-depth: the depth where the transmittance
    /// first reaches 0.5 (EXR: Z, +inf where it never does; PNG colour-mapped as depth).
    /// field-*: the fitted field itself (the sum over Gaussians `fit` models) on the
    /// --slice-plane, integrated along each ray, or its maximum along each ray; EXR and
    /// .npy as features, PNG the --channel through a colour map (or --shader).
    #[arg(long, value_name = "MODE")]
    pub(crate) mode: Option<output::RenderMode>,
    /// The space --mode normal writes normals in: camera (the renderer's: x right, y down,
    /// z the direction of view; a surface facing the camera is (0, 0, -1)) or world
    /// [default: camera].
    #[arg(long, value_name = "SPACE")]
    pub(crate) normal_space: Option<verisplat::core::model::surface::NormalSpace>,
    /// Feature channels for the scene's Gaussians: an N x K NumPy array (float32 or
    /// float16, N the scene's Gaussian count, K 1..64), replacing any feat_* of the file.
    #[arg(long, value_name = "FILE.npy")]
    pub(crate) features: Option<PathBuf>,
    /// Neural shader: a per-pixel MLP (safetensors with a verisplat_mlp description; README
    /// "Neural shader") applied to the blended feature channels (and optionally the view
    /// direction and alpha). The colour written is alpha * MLP + (1 - alpha) * background.
    #[arg(long, value_name = "FILE.safetensors")]
    pub(crate) shader: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) field: Box<FieldArgs>,
    /// Frames of the path to render, numbered in the whole path (before --camera): 7,
    /// 0,3,7, 100..200 (end exclusive), 100..=199, 100.. or ..50. File names keep the
    /// frame's number, so split runs give the files of one run.
    #[arg(long, value_name = "SPEC")]
    pub(crate) frames: Option<FrameSelection>,
    /// A time-varying scene (t_mean, t_scale per Gaussian: `fit --time-column`) at time T:
    /// each Gaussian's opacity times exp(-((T - t_mean) / t_scale)^2 / 2) (0 beyond 4
    /// temporal scales), in every mode. Such a scene needs --time or --time-range.
    #[arg(long, value_name = "T", value_parser = values::any_f32, allow_hyphen_values = true, conflicts_with = "time_range")]
    pub(crate) time: Option<f32>,
    /// An animation of a time-varying scene: frame k of N at time T0 + (T1 - T0) k / (N - 1),
    /// N the path's frames (--orbit N, a camera file) or, for one camera, --time-frames N.
    #[arg(long, value_name = "T0,T1", value_parser = values::time_range, allow_hyphen_values = true)]
    pub(crate) time_range: Option<[f32; 2]>,
    /// --time-range from one camera: N frames of it, one per time.
    #[arg(long, value_name = "N", value_parser = values::int_in(1usize, 1_000_000), requires = "time_range")]
    pub(crate) time_frames: Option<usize>,
    /// Resume: skip frames whose files exist (write only the missing files of a frame).
    #[arg(long, conflicts_with = "overwrite")]
    pub(crate) skip_existing: bool,
    /// Render shard I of N (0-based) of the selected frames, a contiguous block of them, so
    /// N processes together render each frame once; `slurm` reads SLURM_ARRAY_TASK_ID,
    /// SLURM_ARRAY_TASK_COUNT and SLURM_ARRAY_TASK_MIN (a task of sbatch --array).
    #[arg(long, value_name = "I/N|slurm")]
    pub(crate) shard: Option<String>,
    /// Render nothing: check that every file of the selected frames (of the shard, with
    /// --shard) exists, decodes and has its camera's size; list the others and fail if any.
    #[arg(long, conflicts_with_all = ["overwrite", "skip_existing", "export_cameras"])]
    pub(crate) verify: bool,
    /// Spread the frames over several Vulkan devices of this machine, one renderer each:
    /// `all` (every usable device of the default device's type) or a list of indices or
    /// names, `0,1,3` (a device named twice gets two renderers).
    #[arg(long, value_name = "all|N,N,..", conflicts_with_all = ["cpu", "device"])]
    pub(crate) devices: Option<String>,
    /// Replace output files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// Image format of a directory output (-o out/): png or exr [default: png].
    #[arg(long, value_name = "EXT", value_parser = ["png", "exr"])]
    pub(crate) format: Option<String>,
    /// Video output (-o out.mp4, .webm): the codec's constant-quality factor (CRF),
    /// lower is better and larger: H.264 0-51 [default: 18], VP9 0-63 [default: 24]. A
    /// GIF has none (refused): its quality is a 256-colour palette made from the clip.
    #[arg(long, value_name = "CRF", value_parser = values::int_in(0u32, 63))]
    pub(crate) quality: Option<u32>,
    /// Write 16-bit PNG (colour and alpha) instead of 8-bit.
    #[arg(long)]
    pub(crate) png16: bool,
    /// Write EXR R, G, B, A as 16-bit half floats instead of 32-bit floats (Z stays
    /// 32-bit).
    #[arg(long)]
    pub(crate) exr_half: bool,
    /// Keep the background in EXR R, G, B (the reference's image, as PNG shows it). By
    /// default EXR colour is premultiplied over transparent black, ready to composite.
    #[arg(long)]
    pub(crate) exr_background: bool,
    /// Also write the rendered cameras (after --camera and resizing) as an INRIA
    /// cameras.json, with the lens of each camera that is not a pinhole, which --cameras
    /// reads back.
    #[arg(long, value_name = "FILE.json")]
    pub(crate) export_cameras: Option<PathBuf>,
    /// Instead of -o: write the selected frames as a COLMAP data set in DIR, for training
    /// (or testing a trainer) on a known scene: DIR/images/NAME.png as rendered (colour
    /// over --background), DIR/sparse/0/{cameras,images,points3D}.txt with the cameras
    /// (PINHOLE, or OPENCV, FULL_OPENCV, OPENCV_FISHEYE for those lenses; COLMAP has no
    /// orthographic or equirectangular model) and every Nth Gaussian centre and its DC
    /// colour as the points (N chosen so that at most 100,000 are written; said).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["output", "verify", "shard", "devices", "mode", "skip_existing", "export_cameras"])]
    pub(crate) export_colmap: Option<PathBuf>,
    /// Depth range NEAR,FAR of colour-mapped depth PNGs (default: each frame's 1st-99th
    /// percentile; fix it for a steady video).
    #[arg(long, value_name = "NEAR,FAR", value_parser = values::depth_range, allow_hyphen_values = true)]
    pub(crate) depth_range: Option<[f32; 2]>,
    /// Background colour, linear R,G,B in [0, 1] (or "black" / "white").
    #[arg(long, value_name = "R,G,B", default_value = "0,0,0", value_parser = values::background, allow_hyphen_values = true)]
    pub(crate) background: [f32; 3],
    #[command(flatten)]
    pub(crate) filter: FilterArgs,
    /// Multiply every Gaussian's scales by M before projecting (the reference rasterizer's
    /// scaling_modifier; < 1 shrinks the splats, > 1 grows them).
    #[arg(long, value_name = "M", default_value_t = 1.0, value_parser = values::positive_f32)]
    pub(crate) scale_modifier: f32,
    // Boxed: keeps the Render variant of main's Command enum small.
    #[command(flatten)]
    pub(crate) transform: Box<crate::cli::transform::TransformArgs>,
    /// Opacity compensation for scenes trained with antialiasing (mip) settings:
    /// opacity * sqrt(max(2.5e-5, det_before / det_after)) of the 0.3 dilation. On by
    /// default when the file records antialiased training (SPZ flag, SOG meta.json).
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
    /// Print the time of each pipeline stage: GPU timestamps, or with --cpu the wall
    /// clock of the CPU reference's phases (the mean over the frames of a path).
    #[arg(long)]
    pub(crate) timings: bool,
    /// Threads that encode and write images while the next frame renders (0: encode on
    /// the rendering thread; at most 64).
    #[arg(long, value_name = "N", default_value_t = verisplat::app::sequence::default_encode_threads(), value_parser = values::int_in(0usize, 64))]
    pub(crate) encode_threads: usize,
    /// Frames of a path in flight on the device: 2 records and submits frame n+1 before
    /// frame n is read back and encoded (two sets of per-frame buffers); 1 renders one
    /// frame at a time. The files are the same either way [default: 2].
    #[arg(long, value_name = "N", value_parser = values::int_in(1usize, 2))]
    pub(crate) frames_in_flight: Option<usize>,
    /// Compact device copy of the scene: SH coefficients, axis scales and rotations as fp16
    /// (centres and opacities stay f32): 16 bytes per Gaussian fewer, plus 2 per SH float
    /// (112 in all at SH degree 3). Not exact: frames carry fp16's rounding of those values.
    #[arg(long)]
    pub(crate) compact: bool,
    /// No progress display (the summary is still printed).
    #[arg(long, short)]
    pub(crate) quiet: bool,
    #[command(flatten)]
    pub(crate) gpu: GpuArgs,
}

/// A colour-map range: fixed, or `None` for auto.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ColourRange(pub(crate) Option<[f32; 2]>);

fn colour_range(s: &str) -> Result<ColourRange, String> {
    values::colour_range(s).map(ColourRange)
}

/// The options of the field renders.
#[derive(Args)]
pub(crate) struct FieldArgs {
    /// field-slice: the plane, a point PX,PY,PZ on it and its normal NX,NY,NZ (each pixel
    /// shows the field where its ray meets the plane; empty where it does not).
    #[arg(long, value_name = "PX,PY,PZ,NX,NY,NZ", value_parser = values::plane, allow_hyphen_values = true)]
    pub(crate) slice_plane: Option<[f32; 6]>,
    /// field-max: samples along each ray's chord through the field's box (1 to 256)
    /// [default: 128].
    #[arg(long, value_name = "S", value_parser = values::int_in(1u32, MAX_FIELD_SAMPLES))]
    pub(crate) max_samples: Option<u32>,
    /// Field render PNG: the channel shown through the colour map [default: 0].
    #[arg(long, value_name = "C")]
    pub(crate) channel: Option<usize>,
    /// Field render PNG: the colour map's range LO,HI (values beyond it get the end
    /// colours) or auto (the 1st to 99th percentile of the channel in the first frame,
    /// printed) [default: auto].
    #[arg(long, value_name = "LO,HI|auto", value_parser = colour_range, allow_hyphen_values = true)]
    pub(crate) range: Option<ColourRange>,
    /// Field render PNG: add a colour bar under the image, labelled with the range's ends
    /// and the channel's name (and --units).
    #[arg(long)]
    pub(crate) colorbar: bool,
    /// The channel's name on the colour bar [default: feat_C].
    #[arg(long, value_name = "NAME")]
    pub(crate) channel_name: Option<String>,
    /// The channel's units on the colour bar (e.g. V/m).
    #[arg(long, value_name = "UNITS")]
    pub(crate) units: Option<String>,
    /// field-slice, field-integral: channels I,Q are one complex field (what `fit --complex`
    /// writes): two channels are appended, its magnitude |I + iQ| (K) and phase (K + 1),
    /// and the PNG shows the magnitude unless --channel says otherwise.
    #[arg(long, value_name = "I,Q", value_parser = crate::cli::fit::channel_pair)]
    pub(crate) complex: Option<(usize, usize)>,
}

/// Refuses Vulkan-only options with `--cpu`.
pub(super) fn check_cpu_options(args: &RenderArgs) -> Result<()> {
    let g = &args.gpu;
    let gpu_only = [
        ("--device", g.device.is_some()),
        ("--memory-limit", g.memory_limit.is_some()),
        ("--validate", g.validate),
        ("--frames-in-flight", args.frames_in_flight.is_some()),
        ("--compact", args.compact),
    ];
    if let Some((flag, _)) = gpu_only.iter().find(|(_, set)| *set) {
        bail!("{flag} applies to the Vulkan pipeline; --cpu renders with the CPU reference");
    }
    Ok(())
}
