//! Arguments and helpers shared by several subcommands: the scene, the camera and
//! resolution, the camera path, the GPU device and the upload filters.

use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;
use vksplat::camera::{self, Camera};
use vksplat::gpu::{ContextOptions, GpuContext};
use vksplat::scene::filter::SceneFilter;
use vksplat::scene::{self, Scene};

/// Where the camera comes from and at which resolution.
#[derive(Args)]
pub(crate) struct CameraArgs {
    /// Camera file: INRIA cameras.json, a COLMAP sparse model (folder, or cameras/images
    /// .txt/.bin), a nerfstudio camera_path.json or a vksplat keyframe JSON (see
    /// docs/cameras.md); the format is detected from the content.
    #[arg(long, value_name = "FILE")]
    pub(crate) cameras: Option<PathBuf>,
    /// Cameras of the path: all, an index, a list 0,3,7, a range 10..20 (end
    /// exclusive) or 10..=20, or img_names [default: all; a single output file needs
    /// exactly one].
    #[arg(long, value_name = "SPEC")]
    pub(crate) camera: Option<String>,
    /// Output width in pixels (alone: keeps the aspect ratio).
    #[arg(long)]
    pub(crate) width: Option<u32>,
    /// Output height in pixels (alone: keeps the aspect ratio).
    #[arg(long)]
    pub(crate) height: Option<u32>,
    /// Scale the camera's resolution (focal lengths scale with it).
    #[arg(long, conflicts_with_all = ["width", "height"])]
    pub(crate) scale: Option<f32>,
}

#[derive(Args)]
pub(crate) struct SceneArg {
    /// Scene: an INRIA .ply, or a trained model directory (uses point_cloud/iteration_<largest>/).
    #[arg(required_unless_present = "demo")]
    pub(crate) scene: Option<PathBuf>,
    /// Use the built-in demo scene (PLAYBOT, 1,873 Gaussians, CC BY 4.0).
    #[arg(long, conflicts_with = "scene")]
    pub(crate) demo: bool,
    /// Iteration of a trained model directory: point_cloud/iteration_N (default: the largest).
    #[arg(long, value_name = "N", conflicts_with = "demo")]
    pub(crate) iteration: Option<u64>,
}

#[derive(Args)]
pub(crate) struct GpuArgs {
    /// Vulkan device: index or part of its name (default: discrete, then integrated,
    /// then CPU; also VKSPLAT_DEVICE).
    #[arg(long, value_name = "N|NAME")]
    pub(crate) device: Option<String>,
    /// Enable the Khronos validation layer (also VKSPLAT_VALIDATE=1); any message it
    /// prints makes the command fail.
    #[arg(long)]
    pub(crate) validate: bool,
    /// Print the chosen device and memory use.
    #[arg(short, long)]
    pub(crate) verbose: bool,
    /// Device memory the renderer may use, in bytes (K/M/G suffixes; also
    /// VKSPLAT_MEMORY_LIMIT); default: the device-local heap.
    #[arg(long, value_name = "BYTES", value_parser = vksplat::gpu::context::parse_bytes)]
    pub(crate) memory_limit: Option<u64>,
}

impl GpuArgs {
    /// The Vulkan context these flags ask for.
    pub(crate) fn context(&self) -> Result<GpuContext> {
        Ok(GpuContext::new(&ContextOptions {
            device: self.device.clone(),
            validation: self.validate,
            memory_limit: self.memory_limit,
        })?)
    }
}

/// Fails when the validation layer (if enabled) reported anything; the messages were
/// printed as they came.
pub(crate) fn fail_on_validation_messages(ctx: &GpuContext) -> Result<()> {
    let messages = ctx.validation_messages();
    if !messages.is_empty() {
        bail!(
            "the Vulkan validation layer reported {} message(s) (printed above)",
            messages.len()
        );
    }
    Ok(())
}

/// Camera paths generated or interpolated by vksplat.
#[derive(Args)]
pub(crate) struct PathArgs {
    /// Render a turntable orbit of FRAMES frames around the scene's bulk (world up -y).
    #[arg(long, value_name = "FRAMES", conflicts_with = "cameras")]
    pub(crate) orbit: Option<usize>,
    /// Orbit centre X,Y,Z (default: the per-axis median of the Gaussians).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, requires = "orbit")]
    pub(crate) orbit_centre: Option<[f32; 3]>,
    /// Orbit radius (default: far enough for the bulk to fit the view).
    #[arg(long, value_name = "R", requires = "orbit")]
    pub(crate) orbit_radius: Option<f32>,
    /// Orbit elevation above the horizon, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 20.0, requires = "orbit")]
    pub(crate) orbit_elevation: f32,
    /// Orbit start angle, degrees (0: the default camera's view, from -z).
    #[arg(long, value_name = "DEG", default_value_t = 0.0, requires = "orbit")]
    pub(crate) orbit_start: f32,
    /// World up axis of the orbit X,Y,Z (INRIA/COLMAP scenes: 0,-1,0).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, default_value = "0,-1,0", requires = "orbit")]
    pub(crate) orbit_up: [f32; 3],
    /// Vertical field of view of generated cameras (orbit, default camera), degrees.
    #[arg(long, value_name = "DEG", default_value_t = camera::DEFAULT_VFOV_DEG)]
    pub(crate) vfov: f32,
    /// Frames per second of a keyframe path (default: the file's).
    #[arg(long, value_name = "FPS")]
    pub(crate) fps: Option<f32>,
    /// Total frames of a keyframe path (default: from its fps and duration).
    #[arg(long, value_name = "N")]
    pub(crate) path_frames: Option<usize>,
}

/// Which Gaussians to render (applied on upload; the file is not changed).
#[derive(Args)]
pub(crate) struct FilterArgs {
    /// Render with at most this SH degree (0..3).
    #[arg(long, value_name = "D", value_parser = clap::value_parser!(u32).range(0..=3))]
    pub(crate) sh_degree: Option<u32>,
    /// Drop Gaussians whose largest scale (world units, after exp) is above S.
    #[arg(long, value_name = "S")]
    pub(crate) max_scale: Option<f32>,
    /// Drop Gaussians whose opacity (after the sigmoid) is below O.
    #[arg(long, value_name = "O")]
    pub(crate) min_opacity: Option<f32>,
    /// Keep only Gaussians whose centre is inside the box XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX.
    #[arg(long, value_name = "BOX", value_parser = vksplat::scene::filter::parse_crop, allow_hyphen_values = true)]
    pub(crate) crop: Option<[[f32; 3]; 2]>,
}

impl FilterArgs {
    pub(crate) fn filter(&self) -> Result<SceneFilter> {
        let f = SceneFilter {
            max_scale: self.max_scale,
            min_opacity: self.min_opacity,
            crop: self.crop,
            sh_degree: self.sh_degree,
        };
        f.validate().map_err(anyhow::Error::msg)?;
        Ok(f)
    }
}

pub(crate) fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected X,Y,Z (three numbers), got \"{s}\""))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!(
            "expected X,Y,Z (three finite numbers), got \"{s}\""
        )),
    }
}

pub(crate) fn parse_depth_range(s: &str) -> Result<[f32; 2], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected NEAR,FAR, got \"{s}\""))?;
    match v[..] {
        [n, f] if n.is_finite() && f.is_finite() && n != f => Ok([n, f]),
        _ => Err(format!(
            "expected NEAR,FAR (two different finite numbers), got \"{s}\""
        )),
    }
}

pub(crate) fn parse_background(s: &str) -> Result<[f32; 3], String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "black" => return Ok([0.0; 3]),
        "white" => return Ok([1.0; 3]),
        _ => {}
    }
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("expected R,G,B (three numbers), got \"{s}\""));
    }
    let mut out = [0f32; 3];
    for (o, p) in out.iter_mut().zip(parts) {
        *o = p
            .trim()
            .parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("\"{p}\" is not a finite number"))?;
    }
    Ok(out)
}

pub(crate) fn load_scene(arg: &SceneArg) -> Result<(Scene, String)> {
    if arg.demo {
        return Ok((
            vksplat::demo_scene(),
            "built-in demo scene (PLAYBOT)".into(),
        ));
    }
    let Some(path) = arg.scene.as_deref() else {
        bail!("no scene given; pass a .ply file, a model directory or --demo");
    };
    let resolved = scene::resolve_scene_path_at(path, arg.iteration)?;
    Ok((scene::load(&resolved)?, resolved.display().to_string()))
}

/// The `cameras.json` of a trained model directory given as the scene (one with a
/// `point_cloud/` folder), for commands given no camera option; prints a one-line note
/// saying which cameras are used, or that the model has none and the default camera is.
pub(crate) fn model_cameras(scene: &SceneArg) -> Option<PathBuf> {
    let dir = scene.scene.as_deref().filter(|_| !scene.demo)?;
    if !dir.join("point_cloud").is_dir() {
        return None;
    }
    let file = dir.join("cameras.json");
    if file.is_file() {
        eprintln!(
            "note: using the model's cameras, {} (--cameras or --orbit choose others)",
            file.display()
        );
        Some(file)
    } else {
        eprintln!(
            "note: model directory {} has no cameras.json; using the default camera",
            dir.display()
        );
        None
    }
}

/// The cameras of the path with their frame numbers, at the requested resolution.
/// Also returns a description of the source for the summary. Without `--cameras` or
/// `--orbit`, a trained model directory's own cameras.json is used ([`model_cameras`]),
/// else the default camera.
pub(crate) fn camera_path(
    view: &CameraArgs,
    p: &PathArgs,
    scene_arg: &SceneArg,
    scene: &Scene,
) -> Result<(Vec<(usize, Camera)>, String)> {
    let cameras = match (&view.cameras, p.orbit) {
        (Some(file), _) => Some(file.clone()),
        (None, None) => model_cameras(scene_arg),
        (None, Some(_)) => None,
    };
    let (all, label, source): (Vec<Camera>, PathBuf, String) = if let Some(frames) = p.orbit {
        let params = camera::OrbitParams {
            frames,
            centre: p.orbit_centre.map(glam::Vec3::from),
            radius: p.orbit_radius,
            elevation_deg: p.orbit_elevation,
            up: glam::Vec3::from(p.orbit_up),
            start_deg: p.orbit_start,
            vfov_deg: p.vfov,
            ..Default::default()
        };
        (
            camera::orbit(&scene.positions, &params)?,
            PathBuf::from("--orbit"),
            format!("an orbit of {frames} frames"),
        )
    } else if let Some(path) = &cameras {
        let timing = camera::PathTiming {
            frames: p.path_frames,
            fps: p.fps,
        };
        let (cams, format) = camera::load_camera_file(path, &timing)?;
        let source = format!("{} ({format}, {} cameras)", path.display(), cams.len());
        (cams, path.clone(), source)
    } else {
        let params = camera::OrbitParams {
            frames: 1,
            vfov_deg: p.vfov,
            ..Default::default()
        };
        let mut cams = camera::orbit(&scene.positions, &params)?;
        cams[0].name = "default".into();
        (
            cams,
            PathBuf::from("<default camera>"),
            "the default camera".into(),
        )
    };
    let chosen: Vec<usize> = match &view.camera {
        Some(spec) => camera::select_camera_indices(&all, spec, &label)?,
        // A single output file with several cameras is refused by the plan, naming
        // --camera and patterns.
        None => (0..all.len()).collect(),
    };
    let cams = chosen
        .into_iter()
        .map(|i| Ok((i, all[i].resized(view.width, view.height, view.scale)?)))
        .collect::<Result<Vec<_>>>()?;
    Ok((cams, source))
}
