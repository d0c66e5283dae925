//! Video output through the system `ffmpeg`: frames are streamed to it as raw 8-bit RGB
//! (the values an 8-bit RGB PNG of the frame holds) and it encodes them to MP4 (H.264,
//! yuv420p, `+faststart`), WebM (VP9) or GIF (a palette made from the whole clip).
//!
//! The video is written to a temporary file beside the output (the name
//! [`crate::core::fsutil`] gives temporaries, so a later run removes one that a killed run
//! left) and renamed into place only when ffmpeg succeeds; on any failure, or when the
//! writer is dropped unfinished (an error, Ctrl-C), ffmpeg is stopped and the temporary
//! file removed. ffmpeg runs in its own process group, so a Ctrl-C at the terminal reaches
//! only verisplat, which stops it.

use crate::core::frame::FramePixels;
use crate::core::fsutil;
use crate::io::output::{rgb8_into, to_u8, OutputError};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::{Arc, Mutex};

/// What to install when ffmpeg is missing.
pub const INSTALL_HINT: &str = "install it (sudo apt install ffmpeg, or tools/setup.sh)";

/// Video containers and their codecs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VideoFormat {
    /// MP4 with H.264 (libx264), yuv420p, the index at the front (`+faststart`).
    Mp4,
    /// WebM with VP9 (libvpx-vp9), yuv420p, constant quality.
    Webm,
    /// Animated GIF, one 256-colour palette made from every frame (looping).
    Gif,
}

impl VideoFormat {
    /// The format a file name's extension names (`.mp4`, `.webm`, `.gif`, any case).
    pub fn from_path(path: &Path) -> Option<VideoFormat> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "mp4" => Some(VideoFormat::Mp4),
            "webm" => Some(VideoFormat::Webm),
            "gif" => Some(VideoFormat::Gif),
            _ => None,
        }
    }

    /// ffmpeg's encoder for the format.
    pub fn encoder(self) -> &'static str {
        match self {
            VideoFormat::Mp4 => "libx264",
            VideoFormat::Webm => "libvpx-vp9",
            VideoFormat::Gif => "gif",
        }
    }

    /// ffmpeg's name of the container (`-f`).
    fn muxer(self) -> &'static str {
        match self {
            VideoFormat::Mp4 => "mp4",
            VideoFormat::Webm => "webm",
            VideoFormat::Gif => "gif",
        }
    }

    /// The codec's constant-quality (CRF) range and the default (`None` for GIF, which
    /// has none).
    pub fn crf_range(self) -> Option<(u32, u32, u32)> {
        match self {
            // x264: 0 lossless .. 51; 18 is close to visually lossless.
            VideoFormat::Mp4 => Some((0, 51, 18)),
            // libvpx-vp9: 0 .. 63 (0 is not lossless without -lossless 1).
            VideoFormat::Webm => Some((0, 63, 24)),
            VideoFormat::Gif => None,
        }
    }

    /// A description for messages: "H.264 MP4", "VP9 WebM", "GIF".
    pub fn describe(self) -> &'static str {
        match self {
            VideoFormat::Mp4 => "H.264 MP4",
            VideoFormat::Webm => "VP9 WebM",
            VideoFormat::Gif => "GIF",
        }
    }

    /// [`describe`](Self::describe) with its article, as a sentence needs it: "an H.264
    /// MP4", "a VP9 WebM", "a GIF".
    pub fn with_article(self) -> String {
        let article = match self {
            VideoFormat::Mp4 => "an",
            VideoFormat::Webm | VideoFormat::Gif => "a",
        };
        format!("{article} {}", self.describe())
    }
}

/// How a video is encoded.
#[derive(Clone, Debug, PartialEq)]
pub struct VideoOptions {
    /// The container and codec.
    pub format: VideoFormat,
    /// Frames per second.
    pub fps: f64,
    /// The codec's CRF (lower is better); `None`: the format's default. Ignored for GIF.
    pub crf: Option<u32>,
    /// The colour of the pixel row or column added to an MP4 of odd size (H.264 in
    /// yuv420p needs even sizes): the render's background, linear RGB as in the frame.
    pub pad_colour: [f32; 3],
    /// Replace an existing output.
    pub overwrite: bool,
}

/// The `ffmpeg` found on `PATH` (a file that is executable), or `None`.
pub fn find_ffmpeg() -> Option<PathBuf> {
    find_on_path("ffmpeg")
}

/// An executable named `name` in a folder of `PATH`.
fn find_on_path(name: &str) -> Option<PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .filter(|d| !d.as_os_str().is_empty())
        .map(|d| d.join(name))
        .find(|p| {
            std::fs::metadata(p).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
        })
}

/// Checks that `ffmpeg` is on `PATH` and has the format's encoder; the ffmpeg to run, or
/// one sentence saying what is missing (naming `output`) and what to install.
pub fn check_ffmpeg(output: &Path, format: VideoFormat) -> Result<PathBuf, String> {
    let Some(ffmpeg) = find_ffmpeg() else {
        return Err(format!(
            "{}: writing {} needs ffmpeg, which is not on the PATH; {INSTALL_HINT}",
            output.display(),
            format.with_article()
        ));
    };
    let listed = Command::new(&ffmpeg)
        .args(["-hide_banner", "-nostdin", "-encoders"])
        .stdin(Stdio::null())
        .stderr(Stdio::null())
        .output()
        .map_err(|e| format!("{}: cannot run {}: {e}", output.display(), ffmpeg.display()))?;
    let text = String::from_utf8_lossy(&listed.stdout);
    let has = text
        .lines()
        .any(|l| l.split_whitespace().nth(1) == Some(format.encoder()));
    if !has {
        return Err(format!(
            "{}: {} has no {} encoder, which {} needs; install Debian's or Ubuntu's ffmpeg (sudo apt install ffmpeg, or tools/setup.sh)",
            output.display(),
            ffmpeg.display(),
            format.encoder(),
            format.with_article()
        ));
    }
    Ok(ffmpeg)
}

/// `fps` as ffmpeg reads a frame rate: an integer, or a fraction to 1/1000.
fn rate(fps: f64) -> String {
    if fps.fract() == 0.0 {
        format!("{}", fps as u64)
    } else {
        format!("{}/1000", (fps * 1000.0).round() as u64)
    }
}

/// `#rrggbb` of a linear colour quantised as the frame's pixels are.
fn hex(c: [f32; 3]) -> String {
    let [r, g, b] = c.map(to_u8);
    format!("0x{r:02x}{g:02x}{b:02x}")
}

/// The ffmpeg arguments that encode raw RGB frames of `width x height` from stdin to `tmp`.
fn ffmpeg_args(opts: &VideoOptions, width: u32, height: u32, tmp: &Path) -> Vec<String> {
    let mut a: Vec<String> = [
        "-hide_banner",
        "-nostdin",
        "-loglevel",
        "error",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-video_size",
    ]
    .map(String::from)
    .to_vec();
    a.push(format!("{width}x{height}"));
    a.extend([
        "-framerate".into(),
        rate(opts.fps),
        "-i".into(),
        "pipe:0".into(),
    ]);
    let crf = |f: VideoFormat| {
        let (_, _, default) = f.crf_range().unwrap_or((0, 0, 0));
        opts.crf.unwrap_or(default).to_string()
    };
    // RGB to BT.709 YUV, tagged as such, so players and decoders convert it back alike.
    let yuv = "scale=out_color_matrix=bt709:out_range=tv,format=yuv420p";
    let tags = [
        "-colorspace",
        "bt709",
        "-color_primaries",
        "bt709",
        "-color_trc",
        "bt709",
        "-color_range",
        "tv",
    ];
    match opts.format {
        VideoFormat::Mp4 => {
            let filter = if width % 2 == 1 || height % 2 == 1 {
                format!(
                    "pad=width=ceil(iw/2)*2:height=ceil(ih/2)*2:x=0:y=0:color={},{yuv}",
                    hex(opts.pad_colour)
                )
            } else {
                yuv.to_string()
            };
            a.extend(["-vf".into(), filter]);
            a.extend(["-c:v", "libx264", "-preset", "medium", "-crf"].map(String::from));
            a.push(crf(VideoFormat::Mp4));
            a.extend(tags.map(String::from));
            a.extend(["-movflags", "+faststart"].map(String::from));
        }
        VideoFormat::Webm => {
            a.extend(["-vf".into(), yuv.into()]);
            a.extend(["-c:v", "libvpx-vp9", "-b:v", "0", "-crf"].map(String::from));
            a.push(crf(VideoFormat::Webm));
            a.extend(["-deadline", "good", "-cpu-used", "2", "-row-mt", "1"].map(String::from));
            a.extend(tags.map(String::from));
        }
        VideoFormat::Gif => {
            a.extend(
                [
                    "-filter_complex",
                    "split[a][b];[a]palettegen=stats_mode=full[p];[b][p]paletteuse=dither=sierra2_4a",
                    "-loop",
                    "0",
                ]
                .map(String::from),
            );
        }
    }
    a.extend(["-f".into(), opts.format.muxer().into()]);
    a.push(tmp.to_string_lossy().into_owned());
    a
}

/// The last lines ffmpeg wrote to stderr (kept by a thread that reads them all).
type StderrTail = Arc<Mutex<Vec<u8>>>;

/// The last lines of `bytes`, at most 8 and 1500 characters, on one line.
fn tail(bytes: &[u8]) -> String {
    let text = String::from_utf8_lossy(bytes);
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    let joined = lines[lines.len().saturating_sub(8)..].join(" | ");
    let skip = joined.chars().count().saturating_sub(1500);
    joined.chars().skip(skip).collect()
}

/// A video being written: ffmpeg running, reading frames on its stdin.
#[derive(Debug)]
struct Encoding {
    child: Child,
    stdin: Option<ChildStdin>,
    stderr: StderrTail,
    reader: Option<std::thread::JoinHandle<()>>,
    tmp: PathBuf,
    frames: usize,
    rgb: Vec<u8>,
}

impl Encoding {
    /// Stops ffmpeg (killed, reaped) and removes the temporary file.
    fn abort(&mut self) {
        self.stdin = None;
        let _ = self.child.kill();
        let _ = self.child.wait();
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
        let _ = std::fs::remove_file(&self.tmp);
    }

    /// Closes stdin and waits for ffmpeg; its error, with the tail of its stderr.
    fn wait(&mut self) -> Result<(), String> {
        self.stdin = None;
        let status = self
            .child
            .wait()
            .map_err(|e| format!("waiting for ffmpeg: {e}"))?;
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
        if status.success() {
            return Ok(());
        }
        let err = self.stderr.lock().unwrap_or_else(|e| e.into_inner());
        Err(format!("ffmpeg failed ({status}): {}", tail(&err)))
    }
}

/// Writes one video: [`VideoWriter::start`] starts ffmpeg, [`VideoWriter::write`] hands
/// it each frame in order, [`VideoWriter::finish`] waits for it and renames the file into
/// place. Dropped (or [`VideoWriter::abort`]ed) before `finish`, it stops ffmpeg and
/// removes the temporary file. Shared between threads by reference (`&self` methods).
#[derive(Debug)]
pub struct VideoWriter {
    path: PathBuf,
    opts: VideoOptions,
    width: u32,
    height: u32,
    state: Mutex<Option<Encoding>>,
}

impl VideoWriter {
    /// Starts `ffmpeg` writing `path` (through a temporary file beside it) from frames of
    /// `width x height`. Refuses an existing `path` unless [`VideoOptions::overwrite`].
    pub fn start(
        ffmpeg: &Path,
        path: &Path,
        width: u32,
        height: u32,
        opts: &VideoOptions,
    ) -> Result<VideoWriter, OutputError> {
        if !opts.overwrite && path.exists() {
            return Err(OutputError::Exists(path.to_path_buf()));
        }
        let tmp = fsutil::temporary_path(path);
        let mut cmd = Command::new(ffmpeg);
        cmd.args(ffmpeg_args(opts, width, height, &tmp))
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        {
            use std::os::unix::process::CommandExt;
            // Its own process group: Ctrl-C at the terminal stops verisplat, which stops it.
            cmd.process_group(0);
        }
        let mut child = cmd.spawn().map_err(|e| OutputError::Encode {
            path: path.to_path_buf(),
            message: format!("cannot run {}: {e}", ffmpeg.display()),
        })?;
        let stdin = child.stdin.take();
        let stderr: StderrTail = Arc::default();
        let reader = child.stderr.take().map(|mut pipe| {
            let keep = Arc::clone(&stderr);
            std::thread::spawn(move || {
                let mut buf = [0u8; 4096];
                while let Ok(n) = pipe.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                    let mut k = keep.lock().unwrap_or_else(|e| e.into_inner());
                    k.extend_from_slice(&buf[..n]);
                    let excess = k.len().saturating_sub(16 * 1024);
                    k.drain(..excess);
                }
            })
        });
        Ok(VideoWriter {
            path: path.to_path_buf(),
            opts: opts.clone(),
            width,
            height,
            state: Mutex::new(Some(Encoding {
                child,
                stdin,
                stderr,
                reader,
                tmp,
                frames: 0,
                rgb: Vec::new(),
            })),
        })
    }

    /// The output file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// An encoding error of this video.
    fn error(&self, message: String) -> OutputError {
        OutputError::Encode {
            path: self.path.clone(),
            message,
        }
    }

    /// Hands ffmpeg the next frame, as 8-bit RGB (the colour an 8-bit PNG of it holds:
    /// [`rgb8_into`], from floats or from the device's packed pixels alike).
    /// On an error ffmpeg is stopped and the temporary file removed.
    pub fn write(&self, frame: &FramePixels) -> Result<(), OutputError> {
        let mut guard = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let Some(enc) = guard.as_mut() else {
            return Err(self.error("the video is already finished or stopped".into()));
        };
        let (width, height) = frame.size();
        if (width, height) != (self.width, self.height) {
            let message = format!(
                "frame {} is {width}x{height}, the video {}x{}; a video's frames have one size",
                enc.frames, self.width, self.height
            );
            enc.abort();
            *guard = None;
            return Err(self.error(message));
        }
        rgb8_into(frame, &mut enc.rgb);
        let written = match enc.stdin.as_mut() {
            Some(stdin) => stdin.write_all(&enc.rgb),
            None => Err(std::io::ErrorKind::BrokenPipe.into()),
        };
        if let Err(e) = written {
            // ffmpeg stopped reading: its own error says why.
            let message = match enc.wait() {
                Err(m) => m,
                Ok(()) => format!("ffmpeg stopped reading frames: {e}"),
            };
            enc.abort();
            *guard = None;
            return Err(self.error(message));
        }
        enc.frames += 1;
        Ok(())
    }

    /// Frames handed to ffmpeg so far.
    pub fn frames(&self) -> usize {
        self.state
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .as_ref()
            .map_or(0, |e| e.frames)
    }

    /// Ends the video: waits for ffmpeg, then renames the temporary file into place
    /// (refusing an output that appeared meanwhile unless overwriting). On an error
    /// (ffmpeg's, with the tail of its stderr) the temporary file is removed.
    pub fn finish(&self) -> Result<(), OutputError> {
        let mut guard = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let Some(mut enc) = guard.take() else {
            return Err(self.error("the video is already finished or stopped".into()));
        };
        if enc.frames == 0 {
            enc.abort();
            return Err(self.error("no frames were rendered".into()));
        }
        if let Err(m) = enc.wait() {
            enc.abort();
            return Err(self.error(m));
        }
        let io = |source| OutputError::Io {
            path: self.path.clone(),
            source,
        };
        let result = (|| {
            std::fs::File::open(&enc.tmp)
                .and_then(|f| f.sync_all())
                .map_err(io)?;
            if !self.opts.overwrite && self.path.exists() {
                return Err(OutputError::Exists(self.path.clone()));
            }
            std::fs::rename(&enc.tmp, &self.path).map_err(io)
        })();
        if result.is_err() {
            let _ = std::fs::remove_file(&enc.tmp);
        }
        result
    }

    /// Stops ffmpeg and removes the temporary file (an interrupted or failed render).
    pub fn abort(&self) {
        let mut guard = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(mut enc) = guard.take() {
            enc.abort();
        }
    }
}

impl Drop for VideoWriter {
    fn drop(&mut self) {
        self.abort();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_come_from_the_extension() {
        assert_eq!(
            VideoFormat::from_path(Path::new("a/b.MP4")),
            Some(VideoFormat::Mp4)
        );
        assert_eq!(
            VideoFormat::from_path(Path::new("b.webm")),
            Some(VideoFormat::Webm)
        );
        assert_eq!(
            VideoFormat::from_path(Path::new("b.gif")),
            Some(VideoFormat::Gif)
        );
        for other in ["b.png", "b.exr", "mp4", "out/"] {
            assert_eq!(VideoFormat::from_path(Path::new(other)), None, "{other}");
        }
    }

    #[test]
    fn messages_put_the_right_article_before_each_format() {
        assert_eq!(VideoFormat::Mp4.with_article(), "an H.264 MP4");
        assert_eq!(VideoFormat::Webm.with_article(), "a VP9 WebM");
        assert_eq!(VideoFormat::Gif.with_article(), "a GIF");
    }

    #[test]
    fn arguments_pad_odd_mp4_sizes_and_name_the_codec() {
        let opts = VideoOptions {
            format: VideoFormat::Mp4,
            fps: 29.97,
            crf: None,
            pad_colour: [1.0, 0.0, 0.0],
            overwrite: false,
        };
        let args = ffmpeg_args(&opts, 65, 48, Path::new("t.tmp")).join(" ");
        assert!(args.contains("-framerate 29970/1000"), "{args}");
        assert!(args.contains("color=0xff0000"), "{args}");
        assert!(args.contains("-crf 18"), "{args}");
        assert!(args.contains("+faststart"), "{args}");
        assert!(args.ends_with("-f mp4 t.tmp"), "{args}");
        let even = ffmpeg_args(&opts, 64, 48, Path::new("t.tmp")).join(" ");
        assert!(!even.contains("pad="), "{even}");
        let webm = VideoOptions {
            format: VideoFormat::Webm,
            fps: 30.0,
            crf: Some(40),
            ..opts.clone()
        };
        let args = ffmpeg_args(&webm, 65, 49, Path::new("t.tmp")).join(" ");
        assert!(
            args.contains("libvpx-vp9") && args.contains("-crf 40"),
            "{args}"
        );
        assert!(args.contains("-framerate 30 "), "{args}");
        assert!(!args.contains("pad="), "{args}");
        let gif = VideoOptions {
            format: VideoFormat::Gif,
            ..opts
        };
        let args = ffmpeg_args(&gif, 65, 49, Path::new("t.tmp")).join(" ");
        assert!(
            args.contains("palettegen") && !args.contains("-crf"),
            "{args}"
        );
    }

    #[test]
    fn stderr_tails_keep_the_last_lines() {
        let text: String = (0..20).map(|i| format!("line {i}\n")).collect();
        assert_eq!(
            tail(text.as_bytes()),
            "line 12 | line 13 | line 14 | line 15 | line 16 | line 17 | line 18 | line 19"
        );
    }
}
