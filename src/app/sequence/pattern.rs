//! Output name patterns: `out/frame_{:05}.png`, `%04d`, `####`, `{name}` or a directory,
//! and camera names made safe as file names.

use std::path::{Path, PathBuf};

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
}
