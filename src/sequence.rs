//! Rendering a camera path to a sequence of image files: output name patterns, frame
//! ranges, resuming, atomic writes, a progress display, and encoding on worker threads
//! that overlaps the rendering of the next frame.
//!
//! Frame `k` of a path is always written to the same file name whatever part of the path
//! a run covers, so a path split into `--frames` ranges across machines gives exactly the
//! files of one run, and `--skip-existing` resumes an interrupted run. Every file is
//! written to a temporary file and renamed, so an interrupted run never leaves a
//! truncated frame; the temporaries a killed run leaves behind are removed on the next.

use crate::camera::Camera;
use crate::frame::Frame;
use crate::fsutil;
use crate::output::{self, FileSpec, OutputOptions};
use std::collections::{HashSet, VecDeque};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A piece of an output name pattern.
#[derive(Clone, Debug, PartialEq)]
enum Piece {
    Text(String),
    /// The frame number, zero-padded to `width` digits.
    Index {
        width: usize,
    },
    /// The camera's name, with path separators and control characters replaced.
    Name,
}

/// An output file name pattern: `out/frame_{:05}.png`, `out/{name}.exr`, a directory
/// (`out/` gives `out/frame_{:05}.png`), or a plain file name for a single frame.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputPattern {
    pieces: Vec<Piece>,
}

impl OutputPattern {
    /// Parses `output`. A path that is an existing directory or ends with a separator
    /// names a directory: frames go to `frame_{:05}.<dir_extension>` inside it.
    /// Placeholders: `{}` (frame number), `{:0N}` (zero-padded to N digits), `{name}`
    /// (camera name); `{{` and `}}` are literal braces. The habits of other tools work
    /// too: `%d` / `%04d` (printf, ffmpeg; `%%` is a literal `%`) and `####` (one digit
    /// per `#`, as in Nuke and Houdini).
    pub fn parse(output: &Path, dir_extension: &str) -> Result<OutputPattern, String> {
        let text = output.to_string_lossy().into_owned();
        if names_directory(output) {
            let dir = text.trim_end_matches(['/', '\\']);
            let dir = if dir.is_empty() { "/" } else { dir };
            return Ok(OutputPattern {
                pieces: vec![
                    Piece::Text(format!("{dir}/frame_")),
                    Piece::Index { width: 5 },
                    Piece::Text(format!(".{dir_extension}")),
                ],
            });
        }
        let mut pieces = Vec::new();
        let mut lit = String::new();
        // A frame-number placeholder of `width` digits (`%0Nd` or `#...#`), after the
        // literal text before it.
        let push_index =
            |pieces: &mut Vec<Piece>, lit: &mut String, width: usize| -> Result<(), String> {
                if width > 12 {
                    return Err(format!(
                        "{text}: frame numbers are padded to at most 12 digits"
                    ));
                }
                if !lit.is_empty() {
                    pieces.push(Piece::Text(std::mem::take(lit)));
                }
                pieces.push(Piece::Index { width });
                Ok(())
            };
        let mut chars = text.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '%' if chars.peek() == Some(&'%') => {
                    chars.next();
                    lit.push('%');
                }
                '%' => {
                    let mut digits = String::new();
                    while let Some(d) = chars.peek().filter(|d| d.is_ascii_digit()) {
                        digits.push(*d);
                        chars.next();
                    }
                    if chars.next() != Some('d') {
                        return Err(format!(
                            "{text}: unknown '%' placeholder; use %d or %05d (a literal % is %%)"
                        ));
                    }
                    let width = if digits.is_empty() {
                        0
                    } else {
                        digits.parse::<usize>().unwrap_or(usize::MAX)
                    };
                    push_index(&mut pieces, &mut lit, width)?;
                }
                '#' => {
                    let mut width = 1;
                    while chars.peek() == Some(&'#') {
                        chars.next();
                        width += 1;
                    }
                    push_index(&mut pieces, &mut lit, width)?;
                }
                '{' if chars.peek() == Some(&'{') => {
                    chars.next();
                    lit.push('{');
                }
                '}' if chars.peek() == Some(&'}') => {
                    chars.next();
                    lit.push('}');
                }
                '{' => {
                    let mut spec = String::new();
                    loop {
                        match chars.next() {
                            Some('}') => break,
                            Some(c) => spec.push(c),
                            None => {
                                return Err(format!("{text}: unclosed '{{' in the output pattern"))
                            }
                        }
                    }
                    if !lit.is_empty() {
                        pieces.push(Piece::Text(std::mem::take(&mut lit)));
                    }
                    pieces.push(match spec.as_str() {
                        "" => Piece::Index { width: 0 },
                        "name" => Piece::Name,
                        s => match s.strip_prefix(':').and_then(|w| w.parse::<usize>().ok()) {
                            Some(width) if width <= 12 => Piece::Index { width },
                            _ => {
                                return Err(format!(
                                    "{text}: unknown placeholder {{{spec}}}; use {{}}, {{:05}} (zero-padded frame number) or {{name}}"
                                ))
                            }
                        },
                    });
                }
                '}' => return Err(format!("{text}: unmatched '}}' in the output pattern")),
                c => lit.push(c),
            }
        }
        if !lit.is_empty() {
            pieces.push(Piece::Text(lit));
        }
        Ok(OutputPattern { pieces })
    }

    /// True when the pattern names one file per frame (it has a placeholder).
    pub fn is_sequence(&self) -> bool {
        self.pieces.iter().any(|p| !matches!(p, Piece::Text(_)))
    }

    /// The file name of frame `index` from camera `name`.
    pub fn path(&self, index: usize, name: &str) -> PathBuf {
        let mut s = String::new();
        for p in &self.pieces {
            match p {
                Piece::Text(t) => s.push_str(t),
                Piece::Index { width } => s.push_str(&format!("{index:0width$}")),
                Piece::Name => s.push_str(&file_safe_name(name)),
            }
        }
        PathBuf::from(s)
    }
}

/// True when an output names a directory: it exists as one or ends with a separator.
pub fn names_directory(output: &Path) -> bool {
    let text = output.to_string_lossy();
    output.is_dir() || text.ends_with('/') || text.ends_with('\\')
}

/// A camera name as a file name: an image extension is dropped (COLMAP and INRIA names
/// are the photos' file names, and `front.png` should give `front.png`, not
/// `front.png.png`), and path separators, control characters and white space become `_`.
pub fn file_safe_name(name: &str) -> String {
    const IMAGE_EXTENSIONS: [&str; 9] = [
        "png", "jpg", "jpeg", "exr", "tif", "tiff", "bmp", "webp", "npy",
    ];
    let stem = match name.rsplit_once('.') {
        Some((stem, ext))
            if !stem.is_empty() && IMAGE_EXTENSIONS.iter().any(|e| e.eq_ignore_ascii_case(ext)) =>
        {
            stem
        }
        _ => name,
    };
    let safe: String = stem
        .chars()
        .map(|c| {
            if c == '/' || c == '\\' || c.is_control() || c.is_whitespace() {
                '_'
            } else {
                c
            }
        })
        .collect();
    if safe.is_empty() {
        "camera".into()
    } else {
        safe
    }
}

/// The frames of a path to render (`--frames`): frame numbers, lists and ranges in the
/// syntax of `--camera` (`7`, `0,3,7`, `100..200` end exclusive, `100..=199`, `100..`,
/// `..50`, mixed freely). Frame numbers are positions in the whole path, the numbers the
/// file names carry, whatever `--camera` selected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameSelection {
    text: String,
    /// `(start, end)` with `end` exclusive, `None` meaning the end of the path.
    items: Vec<(usize, Option<usize>)>,
}

impl std::str::FromStr for FrameSelection {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || {
            format!("\"{s}\" is not a frame selection (e.g. 7, 0,3,7, 100..200, 100..=199, 100..)")
        };
        let mut items = Vec::new();
        for item in s.split(',').map(str::trim) {
            let (start, end) = if let Ok(k) = item.parse::<usize>() {
                (k, Some(k.saturating_add(1)))
            } else {
                match crate::camera::parse_index_range(item) {
                    Some(Ok(range)) => range,
                    Some(Err(e)) => return Err(e),
                    None => return Err(bad()),
                }
            };
            if end.is_some_and(|e| e <= start) {
                return Err(format!("frame range \"{item}\" is empty"));
            }
            items.push((start, end));
        }
        Ok(FrameSelection {
            text: s.trim().to_string(),
            items,
        })
    }
}

impl FrameSelection {
    /// True when frame `k` is selected.
    pub fn contains(&self, k: usize) -> bool {
        self.items
            .iter()
            .any(|&(start, end)| k >= start && end.map_or(true, |e| k < e))
    }

    /// Checks that every item lies inside a path of `len` frames: a frame or a range
    /// reaching past the last frame is an error (as with `--camera`), not silently cut;
    /// an open range (`100..`) runs to the end.
    pub fn check(&self, len: usize) -> Result<(), String> {
        for &(start, end) in &self.items {
            if start >= len || end.is_some_and(|e| e > len) {
                let last = match end {
                    Some(e) if e == start + 1 => format!("frame {start}"),
                    Some(e) => format!("frames {start}..={}", e - 1),
                    None => format!("frames {start}.."),
                };
                return Err(format!(
                    "--frames {}: {last} reaches past the end of the path, which has {len} frame(s) ({}){}",
                    self.text,
                    crate::camera::index_span(len),
                    if start < len { format!("; use {start}.. to render to the end") } else { String::new() }
                ));
            }
        }
        Ok(())
    }
}

impl std::fmt::Display for FrameSelection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

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
            match crate::image_file::read_image(&f.path) {
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

/// How progress is shown.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ProgressStyle {
    /// A bar on a terminal (with the `cli` feature), plain lines otherwise.
    #[default]
    Auto,
    /// Plain lines (about every 10 % or 10 s).
    Lines,
    /// Nothing until the summary.
    Quiet,
}

/// Options of [`run`].
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Replace files that exist when they are written.
    pub overwrite: bool,
    /// Encoding threads; 0 encodes on the rendering thread (no overlap).
    pub encode_threads: usize,
    /// Rendered frames that may wait for a free encoder.
    pub queue_depth: usize,
    /// Progress display.
    pub progress: ProgressStyle,
    /// Resuming: a file that another process wrote while this run was going is kept and
    /// counted in [`Summary::appeared`], not an error.
    pub skip_existing: bool,
    /// Set (by a Ctrl-C / SIGTERM handler) to stop before the next frame: frames already
    /// rendered are written completely, and the summary says the run was interrupted.
    pub cancel: Option<Arc<AtomicBool>>,
    /// Frames in flight with [`run_pipelined`]: 2 submits frame `n + 1` before frame `n`
    /// is read back; 1 renders one frame at a time. [`run`] always renders one at a time.
    pub frames_in_flight: usize,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            overwrite: false,
            encode_threads: default_encode_threads(),
            queue_depth: 2,
            progress: ProgressStyle::Auto,
            skip_existing: false,
            cancel: None,
            frames_in_flight: 1,
        }
    }
}

/// Encoding threads by default: the available parallelism, at most 4.
pub fn default_encode_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .min(4)
}

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    /// Frames rendered and written.
    pub written: usize,
    /// Wall-clock seconds of the whole run.
    pub wall_s: f64,
    /// Seconds spent rendering (including the read-back).
    pub render_s: f64,
    /// Seconds spent encoding and writing, summed over threads.
    pub encode_s: f64,
    /// Files that appeared while the run was going (another process wrote them) and were
    /// kept, with [`RunOptions::skip_existing`].
    pub appeared: usize,
    /// The run stopped early because [`RunOptions::cancel`] was set.
    pub interrupted: bool,
}

impl Summary {
    /// Frames written per wall-clock second.
    pub fn frames_per_s(&self) -> f64 {
        self.written as f64 / self.wall_s.max(1e-9)
    }
}

struct Progress {
    total: usize,
    done: usize,
    start: Instant,
    last_line: Instant,
    last_decile: usize,
    bar: Option<Bar>,
    lines: bool,
}

/// The terminal progress bar (with the `cli` feature).
#[cfg(feature = "cli")]
type Bar = indicatif::ProgressBar;

/// Without the `cli` feature there is no terminal progress bar: [`ProgressStyle::Auto`]
/// prints lines.
#[cfg(not(feature = "cli"))]
enum Bar {}

#[cfg(not(feature = "cli"))]
impl Bar {
    fn set_position(&self, _: u64) {
        match *self {}
    }
    fn finish_and_clear(&self) {
        match *self {}
    }
}

/// A progress bar of `total` frames on the terminal, where the `cli` feature has one.
fn terminal_bar(total: usize) -> Option<Bar> {
    #[cfg(feature = "cli")]
    {
        let bar = indicatif::ProgressBar::new(total as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:40.cyan/blue} {pos}/{len} frames  {per_sec}  ETA {eta}  {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Some(bar)
    }
    #[cfg(not(feature = "cli"))]
    {
        let _ = total;
        None
    }
}

impl Progress {
    fn new(total: usize, style: ProgressStyle) -> Progress {
        let tty = std::io::stderr().is_terminal();
        let bar = (style == ProgressStyle::Auto && tty)
            .then(|| terminal_bar(total))
            .flatten();
        Progress {
            total,
            done: 0,
            start: Instant::now(),
            last_line: Instant::now(),
            last_decile: 0,
            lines: bar.is_none() && style != ProgressStyle::Quiet,
            bar,
        }
    }

    fn frame_done(&mut self) {
        self.done += 1;
        if let Some(bar) = &self.bar {
            bar.set_position(self.done as u64);
            return;
        }
        let decile = self.done * 10 / self.total.max(1);
        let due = decile > self.last_decile || self.last_line.elapsed() >= Duration::from_secs(10);
        if self.lines && due {
            self.last_decile = decile;
            self.last_line = Instant::now();
            let elapsed = self.start.elapsed().as_secs_f64();
            let rate = self.done as f64 / elapsed.max(1e-9);
            let eta = (self.total - self.done) as f64 / rate.max(1e-9);
            crate::note!(
                "{}/{} frames ({:.0} %), {rate:.2} frames/s, ETA {eta:.0} s",
                self.done,
                self.total,
                100.0 * self.done as f64 / self.total.max(1) as f64
            );
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// A renderer that may keep several frames in flight: [`run_pipelined`] submits frame
/// `n + 1` before it finishes frame `n`.
pub trait FrameSource {
    /// Starts rendering `cam` (recorded and submitted; not waited for).
    fn submit(&mut self, cam: &Camera) -> anyhow::Result<()>;
    /// Waits for the oldest frame submitted and not finished yet, and reads it back.
    fn finish(&mut self) -> anyhow::Result<Frame>;
    /// Drops the frames submitted and not finished (after an error stopped the run).
    fn discard(&mut self);
}

/// Renders every planned frame with `render` and writes its files. With
/// `encode_threads > 0`, frames are encoded and written on worker threads while the next
/// frame renders (at most `queue_depth` rendered frames wait). The first error stops the
/// run: frames already handed to the encoders are finished, so every file on disk is
/// complete, and the error says how many frames were written. One frame is rendered at a
/// time ([`RunOptions::frames_in_flight`] does not apply; see [`run_pipelined`]).
pub fn run(
    frames: &[FramePlan],
    render: &mut dyn FnMut(&Camera) -> anyhow::Result<Frame>,
    opts: &RunOptions,
) -> Result<Summary, SequenceError> {
    run_each(frames, &mut |p| render(&p.camera), opts)
}

/// A closure given each whole [`FramePlan`] (its number too) as a [`FrameSource`]:
/// [`render_frames`] submits the frames in order, so the `n`-th submit is `frames[n]`.
struct EachPlan<'r> {
    frames: &'r [FramePlan],
    next: usize,
    render: &'r mut dyn FnMut(&FramePlan) -> anyhow::Result<Frame>,
    done: VecDeque<Frame>,
}

impl FrameSource for EachPlan<'_> {
    fn submit(&mut self, cam: &Camera) -> anyhow::Result<()> {
        let p = self
            .frames
            .get(self.next)
            .filter(|p| p.camera.name == cam.name)
            .ok_or_else(|| anyhow::anyhow!("frames were submitted out of order"))?;
        self.next += 1;
        let frame = (self.render)(p)?;
        self.done.push_back(frame);
        Ok(())
    }

    fn finish(&mut self) -> anyhow::Result<Frame> {
        self.done
            .pop_front()
            .ok_or_else(|| anyhow::anyhow!("no frame was submitted"))
    }

    fn discard(&mut self) {
        self.done.clear();
    }
}

/// [`run`] with a renderer given the whole [`FramePlan`] of each frame, not only its
/// camera: for frames that differ by more than the camera (`render --time-range`, whose
/// frame `n` shows its own time).
pub fn run_each(
    frames: &[FramePlan],
    render: &mut dyn FnMut(&FramePlan) -> anyhow::Result<Frame>,
    opts: &RunOptions,
) -> Result<Summary, SequenceError> {
    let mut source = EachPlan {
        frames,
        next: 0,
        render,
        done: VecDeque::new(),
    };
    let opts = RunOptions {
        frames_in_flight: 1,
        ..opts.clone()
    };
    run_pipelined(frames, &mut source, &opts)
}

/// [`run`] with a renderer that keeps up to [`RunOptions::frames_in_flight`] frames in
/// flight: frame `n + 1` is submitted before frame `n` is finished (read back) and handed
/// to the encoders. Files, errors and their frame numbers are those of [`run`]: a frame
/// that fails to submit is reported after the frames before it are written.
pub fn run_pipelined(
    frames: &[FramePlan],
    source: &mut dyn FrameSource,
    opts: &RunOptions,
) -> Result<Summary, SequenceError> {
    let start = Instant::now();
    let mut progress = Progress::new(frames.len(), opts.progress);
    let mut summary = Summary::default();
    let mut failure: Option<SequenceError> = None;
    let overwrite = opts.overwrite;
    let skip_existing = opts.skip_existing;
    let write_all = |frame: &Frame, files: &[FileSpec]| -> Written {
        let t = Instant::now();
        let mut appeared = 0;
        for f in files {
            match output::write_file(frame, f, overwrite) {
                // Another process (a parallel run of the same path) wrote it meanwhile.
                Err(output::OutputError::Exists(_)) if skip_existing => appeared += 1,
                other => other?,
            }
        }
        Ok((t.elapsed().as_secs_f64(), appeared))
    };
    // Counts a frame whose files were written, or keeps the first error.
    let mut record = |written: Written,
                      summary: &mut Summary,
                      failure: &mut Option<SequenceError>| {
        match written {
            Ok((encode_s, appeared)) => {
                summary.encode_s += encode_s;
                summary.appeared += appeared;
                summary.written += 1;
                progress.frame_done();
            }
            Err(e) => {
                failure.get_or_insert(e.into());
            }
        }
    };
    let depth = opts.frames_in_flight.max(1);
    if opts.encode_threads == 0 {
        render_frames(
            frames,
            opts.cancel.as_deref(),
            depth,
            source,
            &mut summary,
            &mut failure,
            |frame, p, summary, failure| {
                record(write_all(&frame, &p.files), summary, failure);
            },
        );
    } else {
        let (job_tx, job_rx) = mpsc::sync_channel::<(Frame, Vec<FileSpec>)>(opts.queue_depth);
        let job_rx = Arc::new(Mutex::new(job_rx));
        let (done_tx, done_rx) = mpsc::channel::<Written>();
        std::thread::scope(|scope| {
            for _ in 0..opts.encode_threads {
                let job_rx = Arc::clone(&job_rx);
                let done_tx = done_tx.clone();
                let write_all = &write_all;
                scope.spawn(move || loop {
                    let job = job_rx.lock().unwrap_or_else(|e| e.into_inner()).recv();
                    let Ok((frame, files)) = job else {
                        break;
                    };
                    if done_tx.send(write_all(&frame, &files)).is_err() {
                        break;
                    }
                });
            }
            drop(done_tx);
            render_frames(
                frames,
                opts.cancel.as_deref(),
                depth,
                source,
                &mut summary,
                &mut failure,
                |frame, p, summary, failure| {
                    // A full queue blocks here until an encoder is free. The encoders only stop
                    // once the queue is closed, so the send succeeds.
                    let _ = job_tx.send((frame, p.files.clone()));
                    while let Ok(d) = done_rx.try_recv() {
                        record(d, summary, failure);
                    }
                },
            );
            drop(job_tx);
            // Let the encoders finish what they hold, so every frame handed over is complete.
            for d in done_rx.iter() {
                record(d, &mut summary, &mut failure);
            }
        });
    }
    progress.finish();
    if let Some(SequenceError::Render { written, .. }) = &mut failure {
        *written = summary.written;
    }
    summary.wall_s = start.elapsed().as_secs_f64();
    match failure {
        Some(e) => Err(e),
        None => Ok(summary),
    }
}

/// The outcome of writing one frame's files: seconds spent encoding and the files found
/// already written by another process, or the error.
type Written = Result<(f64, usize), output::OutputError>;

/// Renders `frames` in order, up to `depth` in flight, and hands each to `deliver` in
/// order, until the first render error or until `deliver` has recorded a failure.
fn render_frames(
    frames: &[FramePlan],
    cancel: Option<&AtomicBool>,
    depth: usize,
    source: &mut dyn FrameSource,
    summary: &mut Summary,
    failure: &mut Option<SequenceError>,
    mut deliver: impl FnMut(Frame, &FramePlan, &mut Summary, &mut Option<SequenceError>),
) {
    let render_error = |p: &FramePlan, e: anyhow::Error| SequenceError::Render {
        index: p.index,
        message: format!("{e:#}"),
        // Filled in once the frames handed over are written.
        written: 0,
    };
    let mut next = frames.iter();
    let mut in_flight: VecDeque<&FramePlan> = VecDeque::new();
    // A frame that failed to submit: reported once the frames before it are delivered.
    let mut submit_failure = None;
    let mut submitting = true;
    loop {
        while submitting && in_flight.len() < depth && failure.is_none() {
            if cancel.is_some_and(|c| c.load(Ordering::SeqCst)) {
                // Frames in flight are rendered already: they are finished and written.
                summary.interrupted = true;
                submitting = false;
                break;
            }
            let Some(p) = next.next() else {
                submitting = false;
                break;
            };
            let t = Instant::now();
            let submitted = source.submit(&p.camera);
            summary.render_s += t.elapsed().as_secs_f64();
            match submitted {
                Ok(()) => in_flight.push_back(p),
                Err(e) => {
                    submit_failure = Some(render_error(p, e));
                    submitting = false;
                }
            }
        }
        if failure.is_some() {
            break;
        }
        let Some(p) = in_flight.pop_front() else {
            break;
        };
        let t = Instant::now();
        let finished = source.finish();
        summary.render_s += t.elapsed().as_secs_f64();
        match finished {
            Ok(frame) => deliver(frame, p, summary, failure),
            Err(e) => {
                *failure = Some(render_error(p, e));
                break;
            }
        }
    }
    if !in_flight.is_empty() {
        source.discard();
    }
    if failure.is_none() {
        *failure = submit_failure;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_expand() {
        let p = OutputPattern::parse(Path::new("out/frame_{:05}.png"), "png").unwrap();
        assert!(p.is_sequence());
        assert_eq!(p.path(42, "x"), PathBuf::from("out/frame_00042.png"));
        let p = OutputPattern::parse(Path::new("out/{name}_{}.exr"), "png").unwrap();
        assert_eq!(p.path(7, "a/b"), PathBuf::from("out/a_b_7.exr"));
        let p = OutputPattern::parse(Path::new("x{{}}.png"), "png").unwrap();
        assert!(!p.is_sequence());
        assert_eq!(p.path(1, ""), PathBuf::from("x{}.png"));
        let p = OutputPattern::parse(Path::new("somewhere/"), "exr").unwrap();
        assert_eq!(p.path(3, ""), PathBuf::from("somewhere/frame_00003.exr"));
        let p = OutputPattern::parse(Path::new("out/f_%04d.png"), "png").unwrap();
        assert_eq!(p.path(42, "x"), PathBuf::from("out/f_0042.png"));
        let p = OutputPattern::parse(Path::new("out/f_%d_100%%.png"), "png").unwrap();
        assert_eq!(p.path(42, "x"), PathBuf::from("out/f_42_100%.png"));
        let p = OutputPattern::parse(Path::new("out/f.####.exr"), "png").unwrap();
        assert_eq!(p.path(7, "x"), PathBuf::from("out/f.0007.exr"));
        // Camera names: image extensions dropped, white space and separators replaced.
        let p = OutputPattern::parse(Path::new("r/{name}.png"), "png").unwrap();
        assert_eq!(p.path(0, "front.png"), PathBuf::from("r/front.png"));
        assert_eq!(p.path(0, "IMG 01.JPG"), PathBuf::from("r/IMG_01.png"));
        assert_eq!(p.path(0, "shot.v2"), PathBuf::from("r/shot.v2.png"));
        for bad in [
            "a{b}.png", "a{.png", "a}.png", "{:x}.png", "a%s.png", "%13d.png",
        ] {
            assert!(
                OutputPattern::parse(Path::new(bad), "png").is_err(),
                "{bad}"
            );
        }
    }

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

    #[test]
    fn frame_selections_parse_like_camera_specs() {
        let sel = |s: &str| s.parse::<FrameSelection>();
        let picked = |s: &str, n: usize| -> Vec<usize> {
            let f = sel(s).unwrap();
            (0..n).filter(|&k| f.contains(k)).collect()
        };
        assert_eq!(picked("100..103", 200), [100, 101, 102]);
        assert_eq!(picked("100..=102", 200), [100, 101, 102]);
        assert_eq!(picked("197..", 200), [197, 198, 199]);
        assert_eq!(picked("..3", 200), [0, 1, 2]);
        assert_eq!(picked("7", 200), [7]);
        assert_eq!(picked("0,3,7", 10), [0, 3, 7]);
        assert_eq!(picked("8..,1..=2", 10), [1, 2, 8, 9]);
        assert!(sel("4..").unwrap().contains(1 << 40));
        for bad in ["5..5", "a..b", "", "1,,2", "3..=", "x"] {
            assert!(sel(bad).is_err(), "{bad}");
        }
        // Inside the path: fine; reaching past its end: an error in the notation the
        // option reads, pointing at the open range.
        assert!(sel("0..10").unwrap().check(10).is_ok());
        assert!(sel("5..").unwrap().check(10).is_ok());
        let e = sel("5..20").unwrap().check(10).unwrap_err();
        assert!(
            e.contains("frames 5..=19") && e.contains("0..=9") && e.contains("use 5.."),
            "{e}"
        );
        let e = sel("12").unwrap().check(10).unwrap_err();
        assert!(e.contains("frame 12") && !e.contains("use"), "{e}");
    }
}
