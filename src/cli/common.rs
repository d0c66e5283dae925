//! Arguments and helpers shared by several subcommands: the scene, the camera and
//! resolution, the camera path, the GPU device and the upload filters.

use super::values;
use anyhow::{bail, Result};
use clap::Args;
use std::path::{Path, PathBuf};
use verisplat::core::camera;
use verisplat::core::camera::Camera;
use verisplat::core::scene::filter::SceneFilter;
use verisplat::core::scene::Scene;
use verisplat::cpu::{Rules, SplatKernel};
use verisplat::gpu::{ContextOptions, GpuContext};
use verisplat::io;
use verisplat::io::camera::CameraFormat;
use verisplat::io::scene::spz::SpzAxes;

/// Where the camera comes from and at which resolution.
#[derive(Args, Clone)]
pub(crate) struct CameraArgs {
    /// Camera file: INRIA cameras.json (or a trained model directory holding one), a COLMAP
    /// sparse model (folder, or cameras/images .txt/.bin), a nerfstudio camera_path.json, a
    /// transforms.json (nerfstudio, instant-ngp, NeRF-synthetic) or a verisplat keyframe
    /// JSON (see docs/cameras.md); the format is detected from the content.
    #[arg(long, value_name = "FILE")]
    pub(crate) cameras: Option<PathBuf>,
    /// Cameras to use: all, an index, a list 0,3,7, a range 10..20 (end exclusive),
    /// 10..=20 or 10.., or img_names (a number that is a camera's name, 0002, picks
    /// that camera; #2 is always index 2) [default: all].
    #[arg(long, value_name = "SPEC")]
    pub(crate) camera: Option<String>,
    /// Output width in pixels (alone: keeps the aspect ratio).
    #[arg(long, value_name = "W", value_parser = values::int_in(1u32, camera::MAX_IMAGE_SIDE))]
    pub(crate) width: Option<u32>,
    /// Output height in pixels (alone: keeps the aspect ratio).
    #[arg(long, value_name = "H", value_parser = values::int_in(1u32, camera::MAX_IMAGE_SIDE))]
    pub(crate) height: Option<u32>,
    /// Scale the camera's resolution (focal lengths scale with it).
    #[arg(long, value_name = "S", value_parser = values::positive_f32, conflicts_with_all = ["width", "height"])]
    pub(crate) scale: Option<f32>,
}

#[derive(Args, Clone)]
pub(crate) struct SceneArg {
    /// Scene: INRIA .ply, compressed .ply, .splat, .spz, SOG (.sog, or a directory with
    /// meta.json) or glTF (.glb, .gltf: KHR_gaussian_splatting), detected from the content;
    /// or a trained model directory (uses point_cloud/iteration_<largest>/).
    #[arg(required_unless_present = "demo")]
    pub(crate) scene: Option<PathBuf>,
    /// Use the built-in demo scene (PLAYBOT, 1,873 Gaussians, CC BY 4.0).
    #[arg(long, conflicts_with = "scene")]
    pub(crate) demo: bool,
    /// Iteration of a trained model directory: point_cloud/iteration_N (default: the largest).
    #[arg(long, value_name = "N", conflicts_with = "demo")]
    pub(crate) iteration: Option<u64>,
    #[command(flatten)]
    pub(crate) spz: SpzAxesArg,
}

/// `--spz-axes`: the frame an SPZ scene file is in (a file does not say).
#[derive(Args, Clone, Copy, Debug, Default)]
pub(crate) struct SpzAxesArg {
    /// Axes of an SPZ scene: spec (the SPZ spec's RUB, converted to PLY axes: Niantic's
    /// spz library, Scaniverse, verisplat) or raw (PLY axes as they are: PlayCanvas
    /// splat-transform). A file read in the wrong one is upside down and mirrored front
    /// to back (turned 180 degrees about x).
    #[arg(long = "spz-axes", value_name = "spec|raw", default_value_t = SpzAxes::Spec)]
    pub(crate) axes: SpzAxes,
}

#[derive(Args)]
pub(crate) struct GpuArgs {
    /// Vulkan device: index or part of its name (default: discrete, then integrated,
    /// then CPU; also VERISPLAT_DEVICE).
    #[arg(long, value_name = "N|NAME")]
    pub(crate) device: Option<String>,
    /// Enable the Khronos validation layer (also VERISPLAT_VALIDATE=1); any message it
    /// prints makes the command fail.
    #[arg(long)]
    pub(crate) validate: bool,
    /// Print the chosen device and memory use.
    #[arg(short, long)]
    pub(crate) verbose: bool,
    /// Device memory the renderer may use, in bytes (K/M/G suffixes; also
    /// VERISPLAT_MEMORY_LIMIT); default: the device-local heap.
    #[arg(long, value_name = "BYTES", value_parser = verisplat::gpu::context::parse_bytes)]
    pub(crate) memory_limit: Option<u64>,
}

impl GpuArgs {
    /// The Vulkan context these flags ask for.
    pub(crate) fn context(&self) -> Result<GpuContext> {
        self.context_on(self.device.as_deref())
    }

    /// The Vulkan context of `device` (index or name), with these flags' other settings.
    pub(crate) fn context_on(&self, device: Option<&str>) -> Result<GpuContext> {
        Ok(GpuContext::new(&ContextOptions {
            device: device.map(str::to_string),
            validation: self.validate,
            memory_limit: self.memory_limit,
            ..Default::default()
        })?)
    }
}

/// The shard `--shard` names (`I/N` or `slurm`, read from the environment), if given;
/// a bad value or `slurm` outside a job array is one sentence.
pub(crate) fn shard(spec: Option<&str>) -> Result<Option<verisplat::app::shard::Shard>> {
    let Some(spec) = spec else {
        return Ok(None);
    };
    let spec: verisplat::app::shard::ShardSpec = spec.parse().map_err(anyhow::Error::msg)?;
    Ok(Some(
        spec.resolve(|k| std::env::var(k).ok())
            .map_err(anyhow::Error::msg)?,
    ))
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

/// Camera paths generated or interpolated by verisplat.
#[derive(Args, Clone)]
pub(crate) struct PathArgs {
    /// Render a turntable orbit of FRAMES frames around the scene's bulk (world up -y).
    #[arg(long, value_name = "FRAMES", conflicts_with = "cameras", value_parser = values::int_in(1usize, camera::MAX_PATH_FRAMES))]
    pub(crate) orbit: Option<usize>,
    /// Orbit centre X,Y,Z (default: the centre of the scene's robust bounding box; also
    /// spelled --orbit-center).
    #[arg(long, visible_alias = "orbit-center", value_name = "X,Y,Z", value_parser = values::vec3, allow_hyphen_values = true, requires = "orbit")]
    pub(crate) orbit_centre: Option<[f32; 3]>,
    /// Orbit radius (default: far enough for the bulk to fit the view).
    #[arg(long, value_name = "R", value_parser = values::positive_f32, requires = "orbit")]
    pub(crate) orbit_radius: Option<f32>,
    /// Orbit elevation above the horizon, degrees (-90..90, exclusive; negative looks up).
    #[arg(long, value_name = "DEG", default_value_t = 20.0, value_parser = values::elevation_deg, requires = "orbit")]
    pub(crate) orbit_elevation: f32,
    /// Orbit start angle, degrees (0: the default camera's view, from -z).
    #[arg(long, value_name = "DEG", default_value_t = 0.0, value_parser = values::any_f32, requires = "orbit")]
    pub(crate) orbit_start: f32,
    /// World up axis of the orbit X,Y,Z [default: a trained model's cameras' up (and
    /// their centre of view as --orbit-centre), else 0,-1,0 (INRIA/COLMAP scenes)].
    #[arg(long, value_name = "X,Y,Z", value_parser = values::vec3, allow_hyphen_values = true, requires = "orbit")]
    pub(crate) orbit_up: Option<[f32; 3]>,
    /// One camera at the eye EX,EY,EZ looking at the target TX,TY,TZ, with UX,UY,UZ the
    /// world's up (the image's up is the up made perpendicular to the line of sight),
    /// e.g. --look-at 4,0,0,0,0,0,0,0,1 (from +x towards the origin, z up); --width,
    /// --height and --vfov as for the default camera.
    #[arg(long, value_name = "EX,EY,EZ,TX,TY,TZ,UX,UY,UZ", value_parser = values::look_at, allow_hyphen_values = true, conflicts_with_all = ["cameras", "orbit", "camera"])]
    pub(crate) look_at: Option<[f32; 9]>,
    /// Vertical field of view of generated cameras (orbit, --look-at, default camera),
    /// degrees [default: 50]. Camera files bring their own intrinsics.
    #[arg(long, value_name = "DEG", value_parser = values::fov_deg)]
    pub(crate) vfov: Option<f32>,
    /// Lens of generated cameras (orbit, --look-at, default camera): pinhole,
    /// fisheye[:fov=DEG] (default 180, filling the shorter side), equirect[:lon=A..B,lat=C..D]
    /// (degrees; the whole sphere by default; default size 1280 wide, the window's
    /// longitudes:latitudes ratio, 2:1 for the whole sphere) or ortho[:width=W] (world units across;
    /// default: what --vfov shows at the scene's centre). Every lens is drawn on the GPU
    /// and by the CPU reference (--cpu) alike; field renders (--mode field-*) draw the
    /// pinhole only. docs/cameras.md, "Lenses".
    #[arg(long, value_name = "LENS", value_parser = values::lens)]
    pub(crate) lens: Option<camera::LensSpec>,
    /// Frames per second of a keyframe path (default: the file's); with `render -o
    /// out.mp4` (.webm, .gif) also the video's frame rate, for any path (default: a
    /// keyframe path's own, else 30).
    #[arg(long, value_name = "FPS", value_parser = values::positive_f32)]
    pub(crate) fps: Option<f32>,
    /// Total frames of a keyframe path (default: from its fps and duration).
    #[arg(long, value_name = "N", value_parser = values::int_in(1usize, camera::MAX_PATH_FRAMES))]
    pub(crate) path_frames: Option<usize>,
}

/// The alpha falloff (`--kernel`) and the rasterizer's rules (`--rules`).
#[derive(Args, Clone, Default)]
pub(crate) struct KernelArg {
    /// Alpha falloff of the splats: gaussian (the reference: opacity * exp(-d2/2)) or power
    /// (opacity * max(0, 1 - d2/9), ending at 3 sigma), d2 the squared Mahalanobis distance
    /// [default: the kernel the scene file records, else gaussian].
    #[arg(long, value_name = "gaussian|power")]
    pub(crate) kernel: Option<SplatKernel>,
    /// The rasterizer's rules: original (the 3DGS rasterizer's) or gsplat (near plane 0.01,
    /// alpha clamp 0.999, a per-axis 3.33-sigma screen box; for scenes trained with gsplat)
    /// [default: the rules the scene file records, else original].
    #[arg(long, value_name = "original|gsplat")]
    pub(crate) rules: Option<Rules>,
    /// Render the CPU reference's bits on the GPU: the blends use the reference's own exp
    /// (from +, -, x) and unfused arithmetic. Exact on lavapipe for pinhole cameras; costs
    /// blend time (docs/reproducibility.md).
    #[arg(long)]
    pub(crate) reproducible: bool,
}

impl KernelArg {
    /// The kernel to render `scene` with: `--kernel`, else the one the file records (with a
    /// note when that is not the default).
    pub(crate) fn resolve(&self, scene: &Scene, name: &str) -> SplatKernel {
        if let Some(k) = self.kernel {
            return k;
        }
        if scene.kernel != SplatKernel::Gaussian {
            verisplat::core::console::note!(
                "note: {name} records the {} kernel; rendering with it (--kernel gaussian overrides)",
                scene.kernel
            );
        }
        scene.kernel
    }

    /// The rules to render `scene` with: `--rules`, else the ones the file records (with a
    /// note when those are not the default).
    pub(crate) fn resolve_rules(&self, scene: &Scene, name: &str) -> Rules {
        if let Some(r) = self.rules {
            return r;
        }
        if scene.rules != Rules::Original {
            verisplat::core::console::note!(
                "note: {name} records that it was trained with {}'s rules; rendering with them (--rules original overrides)",
                scene.rules
            );
        }
        scene.rules
    }
}

/// Which Gaussians to keep (applied after loading; the input file is not changed).
#[derive(Args)]
pub(crate) struct FilterArgs {
    /// Keep at most this SH degree (0..3; higher bands are dropped).
    #[arg(long, value_name = "D", value_parser = values::int_in(0u32, 3))]
    pub(crate) sh_degree: Option<u32>,
    /// Drop Gaussians whose largest scale (world units, after exp) is above S.
    #[arg(long, value_name = "S", value_parser = values::positive_f32)]
    pub(crate) max_scale: Option<f32>,
    /// Drop Gaussians whose opacity (after the sigmoid) is below O (0..1).
    #[arg(long, value_name = "O", value_parser = values::unit_f32)]
    pub(crate) min_opacity: Option<f32>,
    /// Keep only Gaussians whose centre is inside the box XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX.
    #[arg(long, value_name = "BOX", value_parser = verisplat::core::scene::filter::parse_crop, allow_hyphen_values = true)]
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

pub(crate) fn load_scene(arg: &SceneArg) -> Result<(Scene, String)> {
    if arg.demo {
        return Ok((
            verisplat::io::demo::demo_scene(),
            "built-in demo scene (PLAYBOT)".into(),
        ));
    }
    let Some(path) = arg.scene.as_deref() else {
        bail!("no scene given; pass a .ply file, a model directory or --demo");
    };
    let loaded = io::scene::resolve_scene_path_at(path, arg.iteration).and_then(|resolved| {
        let (scene, _) = io::scene::detect::load_with_axes(&resolved, arg.spz.axes)?;
        Ok((scene, resolved))
    });
    match loaded {
        Ok((scene, resolved)) => Ok((scene, resolved.display().to_string())),
        // A camera file where the scene belongs: every command says what `info` says. (A
        // model directory also holds cameras, but its scene's error is the one to show.)
        Err(e) if path.is_file() => match verisplat::io::camera::detect_camera_format(path) {
            Ok(format) => bail!(
                "{} is a camera file ({format}), not a scene: give a scene and pass this file with --cameras {}",
                path.display(),
                path.display()
            ),
            Err(_) => Err(e.into()),
        },
        Err(e) => Err(e.into()),
    }
}

/// Refuses a time-varying scene (`t_mean`, `t_scale`) in a command that renders it
/// without a time: only `render` takes `--time`.
pub(crate) fn refuse_time_varying(scene: &Scene, name: &str, command: &str) -> Result<()> {
    if let Some((lo, hi)) = scene.time_range() {
        bail!(
            "{name} is time-varying (its Gaussians' temporal means run from {lo} to {hi}), which `verisplat {command}` does not render; use `verisplat render --time T` (or --time-range T0,T1)"
        );
    }
    Ok(())
}

/// The `cameras.json` of a trained model directory given as the scene (one with a
/// `point_cloud/` folder), for commands given no camera option; prints a one-line note
/// saying which cameras are used, or that the model has none and the default camera is.
pub(crate) fn model_cameras(scene: &SceneArg) -> Option<PathBuf> {
    let dir = model_dir(scene)?;
    let file = dir.join("cameras.json");
    if file.is_file() {
        verisplat::core::console::note!(
            "note: using the model's cameras, {} (--cameras or --orbit choose others)",
            file.display()
        );
        Some(file)
    } else {
        verisplat::core::console::note!(
            "note: model directory {} has no cameras.json; using the default camera",
            dir.display()
        );
        None
    }
}

/// The scene argument when it is a trained model directory (one with `point_cloud/`).
fn model_dir(scene: &SceneArg) -> Option<&Path> {
    let dir = scene.scene.as_deref().filter(|_| !scene.demo)?;
    dir.join("point_cloud").is_dir().then_some(dir)
}

/// The orbit's up and centre: `--orbit-up` and `--orbit-centre`, else, for a trained
/// model directory with a `cameras.json`, what its cameras say ([`camera::up_and_centre_of`],
/// with a note), else -y and the scene's robust centre.
fn orbit_frame(p: &PathArgs, scene_arg: &SceneArg) -> Result<(glam::Vec3, Option<glam::Vec3>)> {
    let given_up = p.orbit_up.map(glam::Vec3::from);
    let given_centre = p.orbit_centre.map(glam::Vec3::from);
    let file = model_dir(scene_arg)
        .map(|d| d.join("cameras.json"))
        .filter(|f| f.is_file());
    let (Some(file), true) = (file, given_up.is_none() || given_centre.is_none()) else {
        return Ok((given_up.unwrap_or(glam::Vec3::NEG_Y), given_centre));
    };
    let (cams, _) = io::camera::load_camera_file(&file, &Default::default())?;
    let (up, centre) = camera::up_and_centre_of(&cams);
    let mut took = Vec::new();
    if let (None, Some(u)) = (given_up, up) {
        took.push(format!("up {:.3},{:.3},{:.3}", u.x, u.y, u.z));
    }
    if let (None, Some(c)) = (given_centre, centre) {
        took.push(format!("centre {:.3},{:.3},{:.3}", c.x, c.y, c.z));
    }
    if !took.is_empty() {
        verisplat::core::console::note!(
            "note: the orbit's {} from the model's {} ({}; --orbit-up and --orbit-centre choose others)",
            took.join(" and "),
            super::plural(cams.len(), "camera"),
            file.display()
        );
    }
    Ok((
        given_up.or(up).unwrap_or(glam::Vec3::NEG_Y),
        given_centre.or(centre),
    ))
}

/// Checks, before any work starts, that `path` can be written: an existing file is
/// refused without `overwrite`, missing folders are created, and the folder must accept a
/// new file (so an unwritable destination is reported now, not after minutes of work).
pub(crate) fn check_output_file(path: &Path, overwrite: bool) -> Result<()> {
    if !overwrite && path.exists() {
        return Err(verisplat::io::output::OutputError::Exists(path.to_path_buf()).into());
    }
    if path.is_dir() {
        bail!("{}: is a directory; give a file name", path.display());
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    check_output_dir(&dir)
}

/// Creates `dir` if missing and checks that a file can be created in it.
pub(crate) fn check_output_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir)
        .map_err(|e| anyhow::anyhow!("{}: cannot create the output folder: {e}", dir.display()))?;
    let probe = dir.join(format!(".verisplat-probe.{}.tmp", std::process::id()));
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .map_err(|e| anyhow::anyhow!("{}: cannot write in this folder: {e}", dir.display()))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// The cameras a command uses: the selected cameras of the path with their frame numbers
/// (positions in the whole path, the numbers file names carry), at the requested
/// resolution.
pub(crate) struct CameraPath {
    /// Selected cameras and their frame numbers, in selection order.
    pub(crate) cameras: Vec<(usize, Camera)>,
    /// Frames in the whole path, before `--camera`.
    pub(crate) len: usize,
    /// Where the cameras come from, for messages: "the default camera",
    /// "cams.json (INRIA cameras.json, 24 cameras)", "an orbit of 120 frames".
    pub(crate) source: String,
}

/// Refuses a `--lens` other than the pinhole where only pinhole cameras work so far (both
/// renderers and the viewer draw every lens; field renders do not yet): `why` says so,
/// after the lens.
pub(crate) fn refuse_lens(p: &PathArgs, why: &str) -> Result<()> {
    match &p.lens {
        Some(spec) if *spec != camera::LensSpec::Pinhole => {
            bail!("--lens {}: {why}", spec.lens().name())
        }
        _ => Ok(()),
    }
}

/// [`refuse_lens`]'s reason for a command that draws: `what` draws pinhole cameras only.
pub(crate) fn draws_pinholes_only(what: &str) -> String {
    format!("{what} draws pinhole cameras only so far; `render` draws every lens")
}

/// Gives a generated pinhole camera the lens of `spec` (`--lens`), its focal lengths made
/// from the pinhole's and the distance to the scene's `centre`.
fn with_lens(cam: &mut Camera, spec: &camera::LensSpec, centre: glam::Vec3) {
    let distance = f64::from((cam.position() - centre).length()).max(1e-6);
    let (lens, fx, fy, cx, cy) = spec.apply(cam.width, cam.height, f64::from(cam.fy), distance);
    cam.lens = lens;
    (cam.fx, cam.fy) = (fx as f32, fy as f32);
    (cam.cx, cam.cy) = (cx as f32, cy as f32);
}

/// The cameras of a camera file for [`camera_path`]: refuses --lens and --vfov, which set
/// generated cameras only, and `sampling` (the flags that set a keyframe path's sampling)
/// for files that are not keyframe paths.
fn file_cameras(
    path: &Path,
    p: &PathArgs,
    sampling: Option<&str>,
) -> Result<(Vec<Camera>, PathBuf, String)> {
    if p.lens.is_some() {
        bail!(
            "--lens sets the lens of generated cameras (--orbit, --look-at, the default camera); {} brings its own",
            path.display()
        );
    }
    if p.vfov.is_some() {
        bail!(
            "--vfov sets the field of view of generated cameras (--orbit, the default camera); {} brings its own intrinsics",
            path.display()
        );
    }
    let timing = io::camera::PathTiming {
        frames: p.path_frames,
        fps: p.fps,
    };
    let (cams, format) = io::camera::load_camera_file(path, &timing)?;
    if let (Some(flags), true) = (sampling, format != CameraFormat::Keyframes) {
        bail!(
            "{flags} set the sampling of a keyframe path; {} is a {format} file, whose cameras are used as they are",
            path.display()
        );
    }
    let source = format!(
        "{} ({format}, {})",
        path.display(),
        super::plural(cams.len(), "camera")
    );
    Ok((cams, path.to_path_buf(), source))
}

/// Builds the camera path of `--orbit`, `--cameras`, a model directory's own
/// cameras.json ([`model_cameras`]) or the default camera, applies `--camera` and the
/// resolution options, and refuses options the source ignores.
pub(crate) fn camera_path(
    view: &CameraArgs,
    p: &PathArgs,
    scene_arg: &SceneArg,
    scene: &Scene,
) -> Result<CameraPath> {
    let camera_file = match (&view.cameras, p.orbit.or(p.look_at.map(|_| 0))) {
        (Some(file), _) => Some(file.clone()),
        (None, None) => model_cameras(scene_arg),
        (None, Some(_)) => None,
    };
    let sampling = p.fps.is_some() || p.path_frames.is_some();
    let sampling_flags = match (p.fps.is_some(), p.path_frames.is_some()) {
        (true, true) => "--fps and --path-frames",
        (true, false) => "--fps",
        _ => "--path-frames",
    };
    let vfov = p.vfov.unwrap_or(camera::DEFAULT_VFOV_DEG);
    // Generated cameras are made at the requested size (square pixels whatever the
    // aspect; an equirectangular window's default is its angles' ratio, 2:1 for the whole
    // sphere); camera files are rescaled.
    let size = p
        .lens
        .as_ref()
        .map_or((1280, 720), camera::LensSpec::default_size);
    let (width, height) = camera::resized_dims(size, view.width, view.height, view.scale)?;
    let generated = camera_file.is_none();
    let (all, label, source): (Vec<Camera>, PathBuf, String) = if let Some(frames) = p.orbit {
        if sampling {
            bail!("{sampling_flags} set the sampling of a keyframe path (--cameras KEYFRAMES.json); an orbit's frame count is --orbit FRAMES");
        }
        let (up, centre) = orbit_frame(p, scene_arg)?;
        let params = camera::OrbitParams {
            frames,
            centre,
            radius: p.orbit_radius,
            elevation_deg: p.orbit_elevation,
            up,
            start_deg: p.orbit_start,
            vfov_deg: vfov,
            width,
            height,
        };
        (
            camera::orbit(&scene.positions, &params)?,
            PathBuf::from("--orbit"),
            format!("an orbit of {}", super::plural(frames, "frame")),
        )
    } else if let Some(path) = &camera_file {
        file_cameras(path, p, sampling.then_some(sampling_flags))?
    } else if let Some(l) = p.look_at {
        if sampling {
            bail!("{sampling_flags} set the sampling of a keyframe path; --look-at is one camera");
        }
        let v = |i: usize| glam::Vec3::new(l[i], l[i + 1], l[i + 2]);
        let cam = Camera::look_at(
            "look_at",
            width,
            height,
            vfov.to_radians(),
            v(0),
            v(3),
            v(6),
        );
        (
            vec![cam],
            PathBuf::from("--look-at"),
            "the --look-at camera".into(),
        )
    } else {
        if sampling {
            bail!("{sampling_flags} set the sampling of a keyframe path; pass it with --cameras KEYFRAMES.json");
        }
        // Frame 0 of the default orbit is the default camera (with --vfov applied).
        let params = camera::OrbitParams {
            frames: 1,
            vfov_deg: vfov,
            width,
            height,
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
    let (chosen, source): (Vec<usize>, String) = match &view.camera {
        Some(spec) => {
            let chosen = camera::select_camera_indices(&all, spec, &label)?;
            let how = camera::describe_selection(&all, spec, &chosen);
            (chosen, format!("{source}, {how}"))
        }
        None => ((0..all.len()).collect(), source),
    };
    let centre = p
        .lens
        .as_ref()
        .map(|_| camera::bulk_bounds(&scene.positions).box_centre());
    let cameras = chosen
        .into_iter()
        .map(|i| {
            Ok(if generated {
                let mut cam = all[i].clone();
                if let (Some(spec), Some(centre)) = (&p.lens, centre) {
                    with_lens(&mut cam, spec, centre);
                }
                (i, cam)
            } else {
                (i, all[i].resized(view.width, view.height, view.scale)?)
            })
        })
        .collect::<Result<Vec<_>>>()?;
    for (_, c) in &cameras {
        c.validate()?;
    }
    Ok(CameraPath {
        cameras,
        len: all.len(),
        source,
    })
}
