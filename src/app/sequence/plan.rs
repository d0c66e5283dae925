//! The plan of a run: the frames to render and their files, checked for clashes, with
//! folders created, stale temporaries removed and existing files applied; and the check
//! of the files afterwards ([`verify`]).

use super::pattern::OutputPattern;
use super::selection::FrameSelection;
use crate::core::camera::Camera;
use crate::core::fsutil;
use crate::io::output::{self, FileSpec, OutputOptions};
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// One frame to render: its number in the path, its camera and its files.
#[derive(Clone, Debug)]
pub struct FramePlan {
    /// Frame number (used in file names).
    pub index: usize,
    /// The camera.
    pub camera: Camera,
    /// The files to write (all of them, or the missing ones when resuming).
    pub files: Vec<FileSpec>,
}

/// Whether every output of a run's `frames` is the frame's colour at 8 bits, which a
/// renderer may then quantise on the device and read back alone (4 bytes a pixel instead
/// of the float planes' 20): each file is an 8-bit RGB PNG ([`output::FileContent::is_rgb8`]), and
/// a frame without files (a video's) goes to the run's sink, which the video encoder's
/// 8-bit RGB is. A run with any other file (EXR, 16-bit or RGBA PNG, depth, alpha, ...)
/// reads back floats for every frame. Decided once per run, from the whole plan.
pub fn reads_rgb8_only(frames: &[FramePlan]) -> bool {
    frames
        .iter()
        .flat_map(|p| &p.files)
        .all(|f| f.content.is_rgb8())
}

/// How existing files are treated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Existing {
    /// Refuse to start when any output file exists.
    #[default]
    Refuse,
    /// Skip frames whose files all exist; write only the missing files of the others.
    Skip,
    /// Replace existing files.
    Overwrite,
}

/// The result of [`plan`]: the frames to render and what was skipped.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Frames to render, in path order.
    pub frames: Vec<FramePlan>,
    /// Frames in the range whose files all exist (with [`Existing::Skip`]).
    pub skipped: usize,
    /// Stale temporary files of an interrupted run that were removed.
    pub removed_temporaries: usize,
}

/// Errors of planning or running a sequence.
#[derive(Debug, thiserror::Error)]
pub enum SequenceError {
    /// Bad pattern, range or file clash.
    #[error("{0}")]
    Invalid(String),
    /// Writing a file failed.
    #[error(transparent)]
    Output(#[from] output::OutputError),
    /// Rendering failed; the frames before it are complete on disk.
    #[error("frame {index}: {message} ({written} frame(s) written before it are complete)")]
    Render {
        /// Frame that failed.
        index: usize,
        /// The renderer's error.
        message: String,
        /// Frames fully written by this run.
        written: usize,
    },
}

/// Plans a path: frame `k` renders `cameras[k]` into `pattern.path(k, name)`. Only frames
/// in `selection` are planned. Checks that no two frames share a file and applies
/// `existing`; creates missing output directories and removes temporaries left by an
/// interrupted run. ([`plan_frames`] then [`prepare`].)
pub fn plan(
    cameras: &[(usize, Camera)],
    pattern: &OutputPattern,
    selection: Option<&FrameSelection>,
    opts: &OutputOptions,
    existing: Existing,
) -> Result<Plan, SequenceError> {
    prepare(plan_frames(cameras, pattern, selection, opts)?, existing)
}

/// The frames of `selection` and their files, touching nothing on disk: an error when the
/// output names one file for several frames, when two frames would write the same file,
/// or when the selection is empty. A sharded render plans every shard's frames with it,
/// so shards that would write the same file are refused before any renders.
pub fn plan_frames(
    cameras: &[(usize, Camera)],
    pattern: &OutputPattern,
    selection: Option<&FrameSelection>,
    opts: &OutputOptions,
) -> Result<Vec<FramePlan>, SequenceError> {
    let chosen: Vec<&(usize, Camera)> = cameras
        .iter()
        .filter(|(k, _)| selection.map_or(true, |s| s.contains(*k)))
        .collect();
    if chosen.len() > 1 && !pattern.is_sequence() {
        return Err(SequenceError::Invalid(format!(
            "{} frames but the output names one file; pick one with --camera N or --frames N, or write a sequence with a pattern such as out/frame_{{:05}}.png, out/frame_%05d.png, out/{{name}}.png or a directory",
            chosen.len()
        )));
    }
    let mut frames = Vec::new();
    let mut seen = HashSet::new();
    for (k, cam) in chosen {
        let files = output::plan_files(&pattern.path(*k, &cam.name), Some(cam), opts)?;
        for f in &files {
            if !seen.insert(f.path.clone()) {
                return Err(SequenceError::Invalid(format!(
                    "{}: two frames would write this file; put {{}} or {{:05}} in the output pattern",
                    f.path.display()
                )));
            }
        }
        frames.push(FramePlan {
            index: *k,
            camera: cam.clone(),
            files,
        });
    }
    if frames.is_empty() {
        return Err(SequenceError::Invalid(format!(
            "no frames to render: --frames {} selects none of the {} frame(s) chosen ({})",
            selection.map_or(String::new(), |s| s.to_string()),
            cameras.len(),
            cameras
                .iter()
                .map(|(k, _)| k.to_string())
                .take(10)
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok(frames)
}

/// Readies planned frames for writing: creates their folders, removes temporaries an
/// interrupted run left of their files, and applies `existing`.
pub fn prepare(mut frames: Vec<FramePlan>, existing: Existing) -> Result<Plan, SequenceError> {
    let seen: HashSet<PathBuf> = frames
        .iter()
        .flat_map(|p| &p.files)
        .map(|f| f.path.clone())
        .collect();
    let mut dirs = HashSet::new();
    for f in frames.iter().flat_map(|p| &p.files) {
        let dir = match f.path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        dirs.insert(dir);
    }
    for d in &dirs {
        std::fs::create_dir_all(d).map_err(|source| output::OutputError::Io {
            path: d.clone(),
            source,
        })?;
    }
    let removed_temporaries = remove_stale_temporaries(&dirs, &seen);
    let mut skipped = 0;
    match existing {
        Existing::Overwrite => {}
        Existing::Refuse => {
            let present: Vec<&Path> = frames
                .iter()
                .flat_map(|p| &p.files)
                .map(|f| f.path.as_path())
                .filter(|p| p.exists())
                .collect();
            if let Some(first) = present.first() {
                return Err(SequenceError::Invalid(format!(
                    "{}: already exists ({} of the {} output files exist); pass --skip-existing to resume or --overwrite to replace them",
                    first.display(),
                    present.len(),
                    seen.len()
                )));
            }
        }
        Existing::Skip => {
            frames.retain_mut(|p| {
                p.files.retain(|f| !f.path.exists());
                if p.files.is_empty() {
                    skipped += 1;
                }
                !p.files.is_empty()
            });
        }
    }
    Ok(Plan {
        frames,
        skipped,
        removed_temporaries,
    })
}

/// A planned file that is not there as it should be: what [`verify`] reports.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// The frame's number.
    pub frame: usize,
    /// The file.
    pub path: PathBuf,
    /// Why: `missing`, or why it cannot be read.
    pub reason: String,
}

/// Checks the files of `frames` (after a run, or after the shards of a split run): each
/// must exist, decode as an image (or `.npy` array), and have its camera's size. Reads the
/// files in parallel; returns the problems in frame order.
pub fn verify(frames: &[FramePlan]) -> Vec<Problem> {
    use rayon::prelude::*;
    let files: Vec<(usize, &FileSpec, &Camera)> = frames
        .iter()
        .flat_map(|p| p.files.iter().map(move |f| (p.index, f, &p.camera)))
        .collect();
    files
        .par_iter()
        .filter_map(|&(frame, f, cam)| {
            let problem = |reason: String| Problem {
                frame,
                path: f.path.clone(),
                reason,
            };
            if !f.path.exists() {
                return Some(problem("missing".into()));
            }
            match crate::io::image_file::read_image(&f.path) {
                Err(e) => Some(problem(format!("unreadable: {e}"))),
                Ok(p) if (p.width, p.height) != (cam.width, cam.height) => Some(problem(format!(
                    "is {}x{}, the camera {}x{}",
                    p.width, p.height, cam.width, cam.height
                ))),
                Ok(_) => None,
            }
        })
        .collect()
}

/// Removes the temporary files that processes now gone left of `path` (a video, written
/// through a temporary file as images are); how many.
pub fn remove_stale_temporaries_of(path: &Path) -> usize {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    remove_stale_temporaries(&HashSet::from([dir]), &HashSet::from([path.to_path_buf()]))
}

/// Removes the temporary files of [`output::write_atomically`] (see
/// [`fsutil::temporary_owner`]) of planned outputs whose writer process is gone.
fn remove_stale_temporaries(dirs: &HashSet<PathBuf>, planned: &HashSet<PathBuf>) -> usize {
    let names: HashSet<String> = planned
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    let mut removed = 0;
    for d in dirs {
        let Ok(entries) = std::fs::read_dir(d) else {
            continue;
        };
        for e in entries.flatten() {
            let file = e.file_name().to_string_lossy().into_owned();
            let Some((name, pid)) = fsutil::temporary_owner(&file) else {
                continue;
            };
            let alive = pid == std::process::id() || process_running(pid);
            if names.contains(name) && !alive && std::fs::remove_file(e.path()).is_ok() {
                removed += 1;
            }
        }
    }
    removed
}

/// Whether process `pid` exists and has not exited (a zombie, killed but not yet reaped
/// by its parent, counts as exited). Where `/proc` is missing, every process counts as
/// running, so nothing is removed.
fn process_running(pid: u32) -> bool {
    if !Path::new("/proc/self").exists() {
        return true;
    }
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        // The state follows the parenthesised command name: "pid (comm) S ...".
        Ok(stat) => stat
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .map_or(true, |state| state != "Z" && state != "X"),
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn exited_and_zombie_processes_do_not_count_as_running() {
        assert!(process_running(std::process::id()));
        assert!(!process_running(4_000_000_000));
        // A child that exited but is not reaped yet is a zombie: its temporaries are stale.
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let pid = child.id();
        let start = std::time::Instant::now();
        while process_running(pid) && start.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(10));
        }
        assert!(!process_running(pid));
        child.wait().unwrap();
    }
}
