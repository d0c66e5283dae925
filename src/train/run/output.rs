//! The model directory as the original writes it: `input.ply` (the starting points),
//! `cameras.json`, `cfg_args`, `point_cloud/iteration_N/point_cloud.ply` (and the
//! shader of feature splats and the photos' appearance transforms beside it), and the
//! checkpoints (`chkpntN.safetensors`).

use super::{Job, Run, TrainError};
use crate::core::camera::Camera;
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` (its directory made first) and records it in `written`.
pub(super) fn write(
    path: &Path,
    bytes: &[u8],
    overwrite: bool,
    written: &mut Vec<PathBuf>,
) -> Result<(), TrainError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)
            .map_err(|e| TrainError::Other(format!("{}: cannot create: {e}", dir.display())))?;
    }
    crate::core::fsutil::write_bytes_atomically(path, overwrite, bytes)?;
    written.push(path.to_path_buf());
    Ok(())
}

/// The image's name without its extension (the original's `image_name`).
fn stem(name: &str) -> &str {
    name.rsplit_once('.').map_or(name, |(s, _)| s)
}

/// The points as the original's `input.ply` (x y z nx ny nz red green blue).
pub(super) fn points_ply(points: &[crate::io::camera::colmap::Point3D]) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        points.len()
    )
    .into_bytes();
    for p in points {
        for v in p.position {
            out.extend((v as f32).to_le_bytes());
        }
        out.extend([0u8; 12]);
        out.extend(p.color);
    }
    out
}

/// `cameras.json` (the test cameras, then the training ones, the original's order, at the
/// photos' own size, each with its lens), `cfg_args` (the original's arguments, as its
/// readers parse them), when a photo's lens is not the pinhole `lenses.json` (trained
/// through the lens or undistorted, [`crate::train::data::Dataset::lens_record`]) and, when
/// photos were undistorted, `undistortion.json` (how, for `verisplat eval`).
pub(super) fn write_cameras_and_cfg(
    job: &Job,
    written: &mut Vec<PathBuf>,
) -> Result<(), TrainError> {
    let (data, out, opts, overwrite) = (job.data, job.out, job.opts, job.overwrite);
    // cameras.json: the test cameras, then the training ones (the original's order), at
    // the photos' own size.
    let all: Vec<(usize, Camera)> = data
        .test
        .iter()
        .chain(&data.train)
        .enumerate()
        .map(|(i, v)| {
            let mut c = v.camera.clone();
            c.name = stem(&c.name).to_string();
            (i, c)
        })
        .collect();
    let json =
        crate::io::camera::inria::to_json(&all).map_err(|e| TrainError::Other(e.to_string()))?;
    write(
        &out.join("cameras.json"),
        json.as_bytes(),
        overwrite,
        written,
    )?;
    let cfg = format!(
        "Namespace(sh_degree={}, source_path='{}', model_path='{}', images='images', resolution={}, white_background={}, data_device='cuda', eval={})",
        opts.sh_degree,
        data.source.display(),
        out.display(),
        opts.resolution.map_or(-1, i64::from),
        if opts.white_background { "True" } else { "False" },
        if data.test.is_empty() { "False" } else { "True" },
    );
    write(&out.join("cfg_args"), cfg.as_bytes(), overwrite, written)?;
    if let Some(record) = data.lens_record() {
        let path = out.join(crate::train::data::LENS_FILE);
        write(&path, record.as_bytes(), overwrite, written)?;
    }
    if !data.undistorted.is_empty() {
        let named: Vec<_> = data
            .undistorted
            .iter()
            .map(|u| crate::train::undistort::Undistortion {
                name: stem(&u.name).to_string(),
                ..u.clone()
            })
            .collect();
        let json = crate::train::undistort::to_json(&named);
        let path = out.join(crate::train::undistort::UNDISTORTION_FILE);
        write(&path, json.as_bytes(), overwrite, written)?;
    }
    Ok(())
}

impl Run<'_> {
    /// Writes the checkpoint after iteration `it` (replacing one there with `overwrite`)
    /// and returns its path.
    pub(super) fn checkpoint(
        &mut self,
        job: &Job,
        it: u32,
        overwrite: bool,
    ) -> Result<PathBuf, TrainError> {
        let c = crate::train::checkpoint::Checkpoint {
            iteration: it,
            rng: self.rng.0,
            order: self.order.to_vec(),
            model: self.model.clone(),
            fingerprint: job.fingerprint.clone(),
            appearance: self.appearance.clone(),
        };
        let path = job.out.join(format!("chkpnt{it}.safetensors"));
        write(&path, &c.to_bytes(), overwrite, &mut self.written).map(|()| path)
    }

    /// Saves the model after iteration `it` (`point_cloud.ply`, and `shader.safetensors`
    /// of feature splats) and notes it.
    pub(super) fn save(
        &mut self,
        job: &Job,
        it: u32,
        note: &mut dyn FnMut(String),
    ) -> Result<(), TrainError> {
        let (model, overwrite) = (&self.model, job.overwrite);
        let path = job
            .out
            .join("point_cloud")
            .join(format!("iteration_{it}"))
            .join("point_cloud.ply");
        let bytes = match &model.mip_filters {
            None => crate::io::scene::ply::to_bytes(
                &model.scene,
                crate::io::scene::ply::PlyEncoding::BinaryLittleEndian,
            ),
            Some(filters) => {
                // The scene the renders saw: the filter folded into scales and opacities,
                // and a header comment that says so.
                let mut scene = model.scene.clone();
                crate::train::model::mip::fold(&mut scene, filters);
                crate::io::scene::ply::to_bytes(
                    &scene,
                    crate::io::scene::ply::PlyEncoding::BinaryLittleEndian,
                )
            }
        };
        write(&path, &bytes, overwrite, &mut self.written)?;
        if let Some(mlp) = &model.shader {
            let shader_path = path.with_file_name("shader.safetensors");
            write(
                &shader_path,
                &mlp.to_safetensors(),
                overwrite,
                &mut self.written,
            )?;
        }
        if let Some(a) = &self.appearance {
            let json = a.to_json(it);
            let app_path = path.with_file_name(crate::train::appearance::APPEARANCE_FILE);
            write(&app_path, json.as_bytes(), overwrite, &mut self.written)?;
        }
        note(format!(
            "[ITER {it}] saved {} ({} Gaussians)",
            path.display(),
            model.len()
        ));
        Ok(())
    }
}
