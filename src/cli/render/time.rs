//! Time-varying scenes: how `--time` and `--time-range` apply ([`TimeChoice`]) and the
//! animation of `--time-range` ([`Animation`]).

use super::args::RenderArgs;
use crate::cli::plural;
use anyhow::{bail, Result};

/// How `--time` and `--time-range` apply to the scene.
pub(super) enum TimeChoice {
    /// A static scene.
    Static,
    /// One time (`--time`).
    At(f32),
    /// An animation (`--time-range T0,T1`).
    Range([f32; 2]),
}

/// Checks `--time` / `--time-range` against the scene: a time-varying scene needs one, a
/// static one takes neither.
pub(super) fn time_choice(
    args: &RenderArgs,
    scene: &verisplat::core::scene::Scene,
    name: &str,
) -> Result<TimeChoice> {
    let flag = if args.time.is_some() {
        "--time"
    } else {
        "--time-range"
    };
    match (scene.time_range(), args.time, args.time_range) {
        (None, None, None) => Ok(TimeChoice::Static),
        (None, _, _) if scene.time.is_some() => Ok(TimeChoice::Static), // time-varying but empty
        (None, _, _) => bail!(
            "{flag} applies to a time-varying scene (t_mean, t_scale per Gaussian, as `verisplat fit --time-column` writes), but {name} is static; drop {flag}"
        ),
        (Some((lo, hi)), None, None) => bail!(
            "{name} is time-varying (its Gaussians' temporal means run from {lo} to {hi}); render it at a time with --time T, or as an animation with --time-range {lo},{hi} --time-frames N"
        ),
        (Some(_), Some(t), _) => Ok(TimeChoice::At(t)),
        (Some(_), None, Some(r)) => Ok(TimeChoice::Range(r)),
    }
}

/// `--time-range`: the time-varying scene (transformed and filtered) and the time of each
/// frame of the path; frame `k` of `n` shows the scene at `t0 + (t1 - t0) k / (n - 1)`.
pub(crate) struct Animation {
    scene: verisplat::core::scene::Scene,
    range: [f32; 2],
    frames: usize,
}

impl Animation {
    /// The animation over `path`'s frames, or over `--time-frames N` copies of its one
    /// camera (which then become the path).
    pub(super) fn new(
        args: &RenderArgs,
        range: [f32; 2],
        path: &mut crate::cli::common::CameraPath,
        scene: verisplat::core::scene::Scene,
    ) -> Result<Animation> {
        let frames = match (args.time_frames, path.cameras.len()) {
            (Some(n), 1) => {
                let cam = path.cameras[0].1.clone();
                path.cameras = (0..n).map(|k| (k, cam.clone())).collect();
                path.len = n;
                path.source = format!("{} at {}", path.source, plural(n, "time"));
                n
            }
            (Some(n), m) if path.len != n || m != path.len => bail!(
                "--time-frames {n} repeats one camera, but the path has {}; drop --time-frames to spread --time-range over the path's frames",
                plural(path.len, "frame")
            ),
            (_, 1) if path.len == 1 => bail!(
                "--time-range {},{} from one camera needs the number of frames: --time-frames N",
                range[0],
                range[1]
            ),
            _ => path.len,
        };
        if args.frames_in_flight.is_some() {
            bail!("--frames-in-flight does not apply to --time-range: each frame uploads the scene at its time and renders on its own");
        }
        Ok(Animation {
            scene,
            range,
            frames,
        })
    }

    /// The time of frame `index`.
    pub(crate) fn time(&self, index: usize) -> f32 {
        if self.frames <= 1 {
            return self.range[0];
        }
        let f = index as f64 / (self.frames - 1) as f64;
        (f64::from(self.range[0]) + f * (f64::from(self.range[1]) - f64::from(self.range[0])))
            as f32
    }

    /// The scene as frame `index` shows it ([`verisplat::core::scene::Scene::at_time`]), activated.
    pub(crate) fn scene(&self, index: usize) -> verisplat::core::scene::ActivatedScene {
        self.scene.at_time(self.time(index)).activated()
    }
}
