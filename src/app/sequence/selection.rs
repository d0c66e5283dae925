//! Frame selections (`--frames`): frame numbers, lists and ranges of a path.

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
                match crate::core::camera::parse_index_range(item) {
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
                    crate::core::camera::index_span(len),
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

#[cfg(test)]
mod tests {
    use super::*;

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
