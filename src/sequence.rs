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
use crate::output::{self, FileSpec, OutputOptions};
use std::collections::HashSet;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
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
    /// (camera name); `{{` and `}}` are literal braces.
    pub fn parse(output: &Path, dir_extension: &str) -> Result<OutputPattern, String> {
        let text = output.to_string_lossy().into_owned();
        let is_dir = output.is_dir() || text.ends_with('/') || text.ends_with('\\');
        if is_dir {
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
        let mut chars = text.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
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
                Piece::Name => s.extend(name.chars().map(|c| {
                    if c == '/' || c == '\\' || c.is_control() {
                        '_'
                    } else {
                        c
                    }
                })),
            }
        }
        PathBuf::from(s)
    }
}

/// A range of frame numbers, `start..end` (end exclusive, `None` = to the end).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRange {
    /// First frame.
    pub start: usize,
    /// One past the last frame, or `None` for the end of the path.
    pub end: Option<usize>,
}

impl std::str::FromStr for FrameRange {
    type Err = String;
    /// `100..200` (end exclusive), `100..=199`, `100..`, `..200`, or one frame `7`.
    fn from_str(s: &str) -> Result<Self, String> {
        let num = |t: &str| -> Result<usize, String> {
            t.trim().parse::<usize>().map_err(|_| {
                format!("\"{s}\" is not a frame range (e.g. 100..200, 100..=199, 100.., 7)")
            })
        };
        let range = if let Some((a, b)) = s.split_once("..=") {
            FrameRange {
                start: if a.trim().is_empty() { 0 } else { num(a)? },
                end: Some(num(b)? + 1),
            }
        } else if let Some((a, b)) = s.split_once("..") {
            FrameRange {
                start: if a.trim().is_empty() { 0 } else { num(a)? },
                end: if b.trim().is_empty() {
                    None
                } else {
                    Some(num(b)?)
                },
            }
        } else {
            let k = num(s)?;
            FrameRange {
                start: k,
                end: Some(k + 1),
            }
        };
        if range.end.is_some_and(|e| e <= range.start) {
            return Err(format!("frame range \"{s}\" is empty"));
        }
        Ok(range)
    }
}

impl FrameRange {
    /// True when frame `k` is in the range.
    pub fn contains(&self, k: usize) -> bool {
        k >= self.start && self.end.map_or(true, |e| k < e)
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
/// in `range` are planned. Checks that no two frames share a file and applies
/// `existing`; creates missing output directories and removes temporaries left by an
/// interrupted run.
pub fn plan(
    cameras: &[(usize, Camera)],
    pattern: &OutputPattern,
    range: Option<FrameRange>,
    opts: &OutputOptions,
    existing: Existing,
) -> Result<Plan, SequenceError> {
    if cameras.len() > 1 && !pattern.is_sequence() {
        return Err(SequenceError::Invalid(format!(
            "{} cameras but the output names one file; pick one with --camera N, or write a sequence with a pattern such as out/frame_{{:05}}.png, out/{{name}}.png or a directory",
            cameras.len()
        )));
    }
    let mut frames = Vec::new();
    let mut seen = HashSet::new();
    for (k, cam) in cameras {
        if !range.map_or(true, |r| r.contains(*k)) {
            continue;
        }
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
            "no frames to render: the path has {} camera(s) and the frame range selects none of them",
            cameras.len()
        )));
    }
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

/// Removes `.<name>.<pid>.tmp` files (see [`output::write_atomically`]) of planned outputs
/// whose writer process is gone.
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
            let Some(rest) = file.strip_prefix('.').and_then(|r| r.strip_suffix(".tmp")) else {
                continue;
            };
            let Some((name, pid)) = rest.rsplit_once('.') else {
                continue;
            };
            let Ok(pid) = pid.parse::<u32>() else {
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
    /// A bar on a terminal, plain lines otherwise.
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
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            overwrite: false,
            encode_threads: default_encode_threads(),
            queue_depth: 2,
            progress: ProgressStyle::Auto,
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
    bar: Option<indicatif::ProgressBar>,
    lines: bool,
}

impl Progress {
    fn new(total: usize, style: ProgressStyle) -> Progress {
        let tty = std::io::stderr().is_terminal();
        let bar = (style == ProgressStyle::Auto && tty).then(|| {
            let bar = indicatif::ProgressBar::new(total as u64);
            bar.set_style(
                indicatif::ProgressStyle::with_template(
                    "{bar:40.cyan/blue} {pos}/{len} frames  {per_sec}  ETA {eta}  {msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            bar
        });
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
            eprintln!(
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

/// Renders every planned frame with `render` and writes its files. With
/// `encode_threads > 0`, frames are encoded and written on worker threads while the next
/// frame renders (at most `queue_depth` rendered frames wait). The first error stops the
/// run: frames already handed to the encoders are finished, so every file on disk is
/// complete, and the error says how many frames were written.
pub fn run(
    frames: &[FramePlan],
    render: &mut dyn FnMut(&Camera) -> anyhow::Result<Frame>,
    opts: &RunOptions,
) -> Result<Summary, SequenceError> {
    let start = Instant::now();
    let mut progress = Progress::new(frames.len(), opts.progress);
    let mut summary = Summary::default();
    let mut failure: Option<SequenceError> = None;
    let overwrite = opts.overwrite;
    let write_all = |frame: &Frame, files: &[FileSpec]| -> Written {
        let t = Instant::now();
        for f in files {
            output::write_file(frame, f, overwrite)?;
        }
        Ok(t.elapsed().as_secs_f64())
    };
    // Counts a frame whose files were written, or keeps the first error.
    let mut record = |written: Written,
                      summary: &mut Summary,
                      failure: &mut Option<SequenceError>| {
        match written {
            Ok(encode_s) => {
                summary.encode_s += encode_s;
                summary.written += 1;
                progress.frame_done();
            }
            Err(e) => {
                failure.get_or_insert(e.into());
            }
        }
    };
    if opts.encode_threads == 0 {
        render_frames(
            frames,
            render,
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
                render,
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

/// The outcome of writing one frame's files: seconds spent encoding, or the error.
type Written = Result<f64, output::OutputError>;

/// Renders `frames` in order and hands each to `deliver`, until the first render error or
/// until `deliver` has recorded a failure.
fn render_frames(
    frames: &[FramePlan],
    render: &mut dyn FnMut(&Camera) -> anyhow::Result<Frame>,
    summary: &mut Summary,
    failure: &mut Option<SequenceError>,
    mut deliver: impl FnMut(Frame, &FramePlan, &mut Summary, &mut Option<SequenceError>),
) {
    for p in frames {
        if failure.is_some() {
            return;
        }
        let t = Instant::now();
        match render(&p.camera) {
            Ok(frame) => {
                summary.render_s += t.elapsed().as_secs_f64();
                deliver(frame, p, summary, failure);
            }
            Err(e) => {
                *failure = Some(SequenceError::Render {
                    index: p.index,
                    message: format!("{e:#}"),
                    // Filled in once the frames handed over are written.
                    written: 0,
                });
            }
        }
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
        for bad in ["a{b}.png", "a{.png", "a}.png", "{:x}.png"] {
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
    fn frame_ranges_parse() {
        let r = |s: &str| s.parse::<FrameRange>();
        assert_eq!(
            r("100..200").unwrap(),
            FrameRange {
                start: 100,
                end: Some(200)
            }
        );
        assert_eq!(
            r("100..=199").unwrap(),
            FrameRange {
                start: 100,
                end: Some(200)
            }
        );
        assert_eq!(
            r("5..").unwrap(),
            FrameRange {
                start: 5,
                end: None
            }
        );
        assert_eq!(
            r("..3").unwrap(),
            FrameRange {
                start: 0,
                end: Some(3)
            }
        );
        assert_eq!(
            r("7").unwrap(),
            FrameRange {
                start: 7,
                end: Some(8)
            }
        );
        assert!(r("5..5").is_err());
        assert!(r("a..b").is_err());
        assert!(r("").is_err());
        assert!(r("4..").unwrap().contains(1 << 40));
    }
}
