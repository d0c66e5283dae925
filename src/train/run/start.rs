//! The start of a run: the Gaussians the original starts from (the data set's points
//! or random ones around the cameras, written as `input.ply`), their feature channels,
//! or the state of a checkpoint to resume.

use super::output::{points_ply, write};
use super::{Job, Run, StageSums, TrainError};
use crate::core::gen::Rng;
use crate::train::appearance::{AppearanceMode, Appearances};
use crate::train::checkpoint::Checkpoint;
use crate::train::model::{random_points, Model};
use std::path::PathBuf;

impl Run<'_> {
    /// The loop's state before its first iteration.
    pub(super) fn start(job: &Job, note: &mut dyn FnMut(String)) -> Result<Self, TrainError> {
        let opts = job.opts;
        let mut rng = Rng(opts.seed);
        let mut written = Vec::new();
        let mut model = initial_model(job, &mut rng, &mut written, note)?;
        model.scene.kernel = opts.kernel;
        model.scene.rules = opts.rules;
        if let Some(mlp) = &opts.shader {
            model = model.with_features(mlp.clone(), &mut rng);
        }
        let mut run = Run {
            model,
            rng,
            order: Vec::new(),
            first: 1,
            dev: None,
            written,
            evaluations: Vec::new(),
            peak: 0,
            stage_sums: StageSums::default(),
            appearance: match opts.appearance.mode {
                AppearanceMode::None => None,
                AppearanceMode::Affine => Some(Appearances::identity(
                    job.data
                        .train
                        .iter()
                        .map(|v| v.camera.name.clone())
                        .collect(),
                )),
            },
        };
        if let Some(c) = &opts.resume {
            run.resume(job, c, note)?;
        }
        if opts.mip_filter {
            if opts.settings.mcmc.is_some() {
                return Err(TrainError::Other(
                    "--mip-filter and --strategy mcmc are not combined: the MCMC strategy's relocation shares opacities and scales that the filter changes; train with one of them".into(),
                ));
            }
            // A checkpoint keeps the filter it was stepping with; a new run computes it.
            if run.model.mip_filters.as_ref().map(Vec::len) != Some(run.model.len()) {
                run.model.mip_filters = Some(job.mip_filters(&run.model.scene.positions));
            }
        }
        Ok(run)
    }

    /// Takes the state of checkpoint `c` (of this data set and these settings, before
    /// the last iteration).
    fn resume(
        &mut self,
        job: &Job,
        c: &Checkpoint,
        note: &mut dyn FnMut(String),
    ) -> Result<(), TrainError> {
        let s = &job.opts.settings;
        if c.fingerprint != job.fingerprint {
            return Err(TrainError::Other(
                "the checkpoint belongs to another data set or other settings; resume with the ones it was written with".into(),
            ));
        }
        if c.iteration >= s.iterations {
            return Err(TrainError::Other(format!(
                "the checkpoint is at iteration {}, not before --iterations {}",
                c.iteration, s.iterations
            )));
        }
        self.model = c.model.clone();
        if self.appearance.is_some() {
            let mut a = c.appearance.clone().ok_or_else(|| {
                TrainError::Other(
                    "the checkpoint has no appearance transforms; resume with the settings it was written with".into(),
                )
            })?;
            let names: Vec<String> = job
                .data
                .train
                .iter()
                .map(|v| v.camera.name.clone())
                .collect();
            if a.affines.len() != names.len() {
                return Err(TrainError::Other(format!(
                    "the checkpoint has appearance transforms of {} photos, the data set {} training photos",
                    a.affines.len(),
                    names.len()
                )));
            }
            a.names = names;
            self.appearance = Some(a);
        }
        self.rng = Rng(c.rng);
        self.order = c.order.clone();
        self.first = c.iteration + 1;
        note(format!(
            "resuming after iteration {} ({} Gaussians)",
            c.iteration,
            self.model.len()
        ));
        Ok(())
    }
}

/// The original's start: points3D, or random points around the cameras' centre (the
/// original's `points3d.ply` of a data set without points); either is written as
/// `input.ply`.
fn initial_model(
    job: &Job,
    rng: &mut Rng,
    written: &mut Vec<PathBuf>,
    note: &mut dyn FnMut(String),
) -> Result<Model, TrainError> {
    let (data, opts) = (job.data, job.opts);
    let random;
    let points = match &data.points {
        Some(points) => points,
        None => {
            let (centre, half) = data.random_box.unwrap_or_else(|| {
                let (mean, extent) = crate::train::data::cameras_centre_and_extent(&data.train);
                (mean.to_array(), extent)
            });
            note(format!(
                "{} has no points: starting from {} random Gaussians in the cube of half side {half:.3} around ({:.3}, {:.3}, {:.3})",
                data.source.display(),
                opts.random_points,
                centre[0],
                centre[1],
                centre[2]
            ));
            random = random_points(opts.random_points, centre, half, rng);
            &random
        }
    };
    write(
        &job.out.join("input.ply"),
        &points_ply(points),
        job.overwrite,
        written,
    )?;
    Ok(Model::from_points(points, opts.sh_degree))
}
