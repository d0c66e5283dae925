//! `verisplat view`: serve an interactive viewer of a scene to a browser.

use super::common::{camera_path, load_scene, CameraArgs, KernelArg, PathArgs, SceneArg};
use super::{plural, values};
use anyhow::{bail, Context, Result};
use clap::Args;
use std::net::{SocketAddr, ToSocketAddrs};
use verisplat::app::view::protocol::{
    camera_to_entry, Hello, NamedCamera, ScaleHistogram, PROTOCOL_VERSION,
};
use verisplat::app::view::server::{ServedScene, Server, ServerConfig, Stopper};
use verisplat::app::view::source::ViewSource;
use verisplat::core::console::{note, outln};

#[derive(Args)]
#[command(after_help = "Examples:
  verisplat view ../shared/data/playbot_lod2_125k_sh2.ply --open
  verisplat view model_dir/                  # the model's cameras.json in the camera list
  verisplat view scene.spz --cameras cameras.json --port 9000
  verisplat view --demo --cpu --port 0       # CPU reference renderer, any free port
  ssh -L 8080:localhost:8080 gpu-box 'verisplat view scene.ply'   # then open http://localhost:8080/")]
pub(crate) struct ViewArgs {
    #[command(flatten)]
    pub(crate) scene: SceneArg,
    #[command(flatten)]
    pub(crate) view: CameraArgs,
    #[command(flatten)]
    pub(crate) path: PathArgs,
    /// TCP port of the viewer (0: any free port, printed at start).
    #[arg(long, value_name = "PORT", default_value_t = 8080)]
    pub(crate) port: u16,
    /// Address to listen on. Anything but a loopback address (127.0.0.1, ::1,
    /// localhost) makes the scene visible to the network.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1")]
    pub(crate) host: String,
    /// Open the viewer in the default browser (xdg-open).
    #[arg(long)]
    pub(crate) open: bool,
    /// Largest frame rendered, WxH: bigger browser windows are scaled down (aspect kept).
    #[arg(long, value_name = "WxH", default_value = "1920x1080", value_parser = values::size)]
    pub(crate) max_resolution: (u32, u32),
    /// Render with the CPU reference renderer instead of the Vulkan pipeline (slow; for
    /// machines without a Vulkan device).
    #[arg(long)]
    pub(crate) cpu: bool,
    /// Vulkan device index (see `vulkaninfo --summary`; default: discrete, then
    /// integrated, then CPU).
    #[arg(long, value_name = "N", conflicts_with = "cpu")]
    pub(crate) device: Option<usize>,
    /// While the camera moves, previews may draw only the most important Gaussians
    /// (opacity times the area of the largest cross-section), at most N short of the
    /// whole scene: how many, and the preview's size, are chosen from the measured stage
    /// times so previews stay fluid. The view at rest always draws all. 0 previews with
    /// the whole scene; scenes of at most 8,192 (or N) Gaussians always preview whole.
    #[arg(long, value_name = "N", default_value_t = verisplat::app::view::source::DEFAULT_PREVIEW_GAUSSIANS, conflicts_with = "cpu")]
    pub(crate) preview_gaussians: usize,
    /// Opacity compensation for scenes trained with antialiasing (as render
    /// --antialiased); on by default when the file records it.
    #[arg(long)]
    pub(crate) antialiased: bool,
    /// Render without the compensation even when the file records antialiased training.
    #[arg(long, conflicts_with = "antialiased")]
    pub(crate) no_antialiased: bool,
    #[command(flatten)]
    pub(crate) kernel: KernelArg,
}

/// The address `--host`/`--port` name (the first the name resolves to).
fn listen_address(host: &str, port: u16) -> Result<SocketAddr> {
    // `::1` and other IPv6 literals are given bare; the resolver wants them bracketed.
    let literal = host
        .parse::<std::net::IpAddr>()
        .ok()
        .map(|ip| SocketAddr::new(ip, port));
    if let Some(addr) = literal {
        return Ok(addr);
    }
    (host, port)
        .to_socket_addrs()
        .with_context(|| format!("--host {host}: not an address or a known host name"))?
        .next()
        .with_context(|| format!("--host {host}: the name resolves to no address"))
}

/// The scene, its cameras and the renderer, as the server gets them.
fn serve(args: &ViewArgs) -> Result<(Box<dyn ViewSource>, ServedScene, String)> {
    let (mut scene, name) = load_scene(&args.scene)?;
    super::common::refuse_time_varying(&scene, &name, "view")?;
    // The sources render with the scene's kernel.
    scene.kernel = args.kernel.resolve(&scene, &name);
    scene.rules = args.kernel.resolve_rules(&scene, &name);
    if scene.is_empty() {
        bail!("{name} holds no Gaussians; there is nothing to view");
    }
    let path = camera_path(&args.view, &args.path, &args.scene, &scene)?;
    let stats = verisplat::app::stats::scene_stats(&scene);
    let antialiased = args.antialiased || (scene.antialiased && !args.no_antialiased);
    if scene.antialiased && !args.antialiased && !args.no_antialiased {
        note!(
            "note: {name} records that it was trained with antialiasing; rendering with its opacity compensation (--no-antialiased turns it off)"
        );
    }
    let cameras: Vec<verisplat::core::camera::Camera> =
        path.cameras.into_iter().map(|(_, c)| c).collect();
    let named = cameras
        .iter()
        .enumerate()
        .map(|(i, c)| {
            Ok(NamedCamera {
                name: c.name.clone(),
                camera: camera_to_entry(c, i).map_err(anyhow::Error::msg)?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let initial_camera = named
        .first()
        .map(|c| c.camera.clone())
        .context("the camera path is empty")?;
    let hist = &stats.max_scale_histogram;
    let max_scale_range = match (hist.edges.first(), hist.edges.last()) {
        (Some(&lo), Some(&hi)) if lo < hi => [lo, hi],
        _ => [stats.max_scale.min.max(1e-6), stats.max_scale.max.max(1e-5)],
    };
    let (source, device): (Box<dyn ViewSource>, String) = if args.cpu {
        let src = verisplat::app::view::cpu_source::CpuSource::new(&scene, antialiased);
        let device = src.device_name();
        (Box::new(src), device)
    } else {
        let mut src = verisplat::app::view::source::GpuSource::new(
            &scene,
            args.device,
            antialiased,
            args.preview_gaussians,
        )?;
        src.set_reproducible(args.kernel.reproducible);
        if src.preview_subset() > 0 {
            note!(
                "previews while the camera moves may draw fewer of the {} Gaussians, the most important (up to {} short of all; as many as keep them fluid); the view at rest draws all (--preview-gaussians N changes the most)",
                scene.len(),
                src.preview_subset()
            );
        }
        let device = src.device_name();
        (Box::new(src), device)
    };
    let bulk = stats.bulk;
    let hello = Hello {
        version: PROTOCOL_VERSION,
        scene: name,
        gaussians: scene.len(),
        sh_degree: scene.sh_degree,
        centre: bulk.box_centre().to_array(),
        bounds_lo: bulk.lo.to_array(),
        bounds_hi: bulk.hi.to_array(),
        size: bulk.radius.max(1e-6),
        max_scale_range,
        max_scale_histogram: ScaleHistogram {
            edges: hist.edges.clone(),
            counts: hist.counts.clone(),
        },
        up: [0.0, -1.0, 0.0],
        cameras: named,
        initial_camera,
        device: device.clone(),
        max_resolution: [args.max_resolution.0, args.max_resolution.1],
        preview_pixels: ServerConfig::default().preview_pixels,
    };
    note!(
        "{} with {}; camera list: {}",
        plural(scene.len(), "Gaussian"),
        device,
        path.source
    );
    Ok((source, ServedScene { hello, cameras }, device))
}

pub(crate) fn view(args: &ViewArgs) -> Result<()> {
    let addr = listen_address(&args.host, args.port)?;
    // Bind first: a port in use is reported before the scene is loaded.
    let config = ServerConfig {
        max_resolution: args.max_resolution,
        ..Default::default()
    };
    let server = Server::bind(addr, config)?;
    let bound = server.local_addr()?;
    if !bound.ip().is_loopback() {
        note!(
            "warning: listening on {}: anyone who can reach this machine on port {} can see the scene and use its GPU; use --host 127.0.0.1 (the default) and an SSH tunnel to keep it private",
            bound.ip(),
            bound.port()
        );
    }
    let (source, scene, _device) = serve(args)?;
    let shown = if bound.ip().is_unspecified() {
        SocketAddr::new(std::net::Ipv4Addr::LOCALHOST.into(), bound.port())
    } else {
        bound
    };
    let url = format!("http://{shown}/");
    outln!("verisplat view: {url}  (Ctrl-C stops)");
    if args.open {
        open_browser(&url);
    }
    stop_on_signals(server.stopper()?)?;
    server.run(source, scene)?;
    note!("viewer stopped");
    Ok(())
}

/// Stops the server on SIGINT or SIGTERM; a second one ends the process at once (as in
/// `render`). The signal handler writes a byte to a socket pair; a thread blocked on
/// the other end calls [`Stopper::stop`] (which a signal handler may not).
fn stop_on_signals(stopper: Stopper) -> Result<()> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    use std::io::Read;
    use std::os::unix::net::UnixStream;
    // Registered first: the second signal sees the flag the first one set.
    let _ = super::render::interrupt_flag();
    let (mut signalled, wake) = UnixStream::pair()?;
    for signal in [SIGINT, SIGTERM] {
        signal_hook::low_level::pipe::register(signal, wake.try_clone()?)?;
    }
    std::thread::spawn(move || {
        if signalled.read_exact(&mut [0u8]).is_ok() {
            stopper.stop();
        }
    });
    Ok(())
}

/// Starts the desktop's browser; failing is a note (the URL is printed anyway).
fn open_browser(url: &str) {
    let child = std::process::Command::new("xdg-open")
        .arg(url)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn();
    match child {
        // Reaped in the background so it leaves no zombie.
        Ok(mut c) => {
            std::thread::spawn(move || {
                if let Ok(status) = c.wait() {
                    if !status.success() {
                        note!(
                            "note: xdg-open could not open a browser; open the URL above yourself"
                        );
                    }
                }
            });
        }
        Err(e) => note!("note: cannot run xdg-open ({e}); open the URL above yourself"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hosts_parse() {
        assert!(listen_address("127.0.0.1", 0).unwrap().ip().is_loopback());
        assert!(listen_address("::1", 8080).unwrap().ip().is_loopback());
        assert!(listen_address("no such host.invalid", 1).is_err());
    }
}
