//! Picking cameras out of a loaded list: one by index or name ([`select_camera`]), or
//! several with a selection spec ([`select_cameras`]).

use super::{Camera, CameraError};
use std::path::Path;

/// Picks one camera by list index (`"3"`, or `"#3"`, which is always an index) or by
/// name, as [`select_cameras`] matches names (exactly, or failing that the file stem);
/// a number that is also a camera's name (`"0002"`) picks that camera.
pub fn select_camera(cams: &[Camera], which: &str, path: &Path) -> Result<Camera, CameraError> {
    if let Some(c) = named_number(cams, which) {
        return Ok(c.clone());
    }
    if let Some(i) = explicit_index(which).or_else(|| which.parse::<usize>().ok()) {
        return cams.get(i).cloned().ok_or_else(|| CameraError::NotFound {
            path: path.to_path_buf(),
            message: format!(
                "camera index {i} is out of range; there {} ({})",
                count_cameras(cams.len()),
                index_span(cams.len())
            ),
        });
    }
    by_name(cams, which, path).cloned()
}

/// Picks cameras by a selection spec: `all`, an index (`3`), a comma-separated list
/// (`0,3,7`), end-exclusive ranges (`10..20`, `10..`, `..5`), inclusive ranges
/// (`10..=20`) and names, mixed freely (`0,5..8,IMG_0042.jpg`). Cameras come back in the
/// order the spec names them; an item that parses as an index or range is one, anything
/// else is a name, except that a number which is also a camera's name (`0002` of photos
/// named `0002.jpg`) picks that camera; `#N` is always index N. A name matches a
/// camera's name exactly or, failing that, its file stem (`IMG_0042` matches
/// `IMG_0042.jpg`, for COLMAP names).
pub fn select_cameras(
    cams: &[Camera],
    spec: &str,
    path: &Path,
) -> Result<Vec<Camera>, CameraError> {
    Ok(select_camera_indices(cams, spec, path)?
        .into_iter()
        .map(|i| cams[i].clone())
        .collect())
}

/// The positions in `cams` of the cameras [`select_cameras`] picks, in the same order.
pub fn select_camera_indices(
    cams: &[Camera],
    spec: &str,
    path: &Path,
) -> Result<Vec<usize>, CameraError> {
    let not_found = |message: String| CameraError::NotFound {
        path: path.to_path_buf(),
        message,
    };
    let spec = spec.trim();
    if spec.is_empty() {
        return Err(not_found(
            "the camera selection is empty; give `all`, indices (0,3,7), ranges (10..20, 10..=20) or names".into(),
        ));
    }
    if spec.eq_ignore_ascii_case("all") {
        if cams.is_empty() {
            return Err(not_found("has no cameras".into()));
        }
        return Ok((0..cams.len()).collect());
    }
    let mut picked = Vec::new();
    for item in spec.split(',').map(str::trim) {
        if item.is_empty() {
            return Err(not_found(format!(
                "camera selection \"{spec}\" has an empty item (two commas in a row or a trailing comma)"
            )));
        }
        if let Some(c) = named_number(cams, item) {
            picked.extend(cams.iter().position(|k| std::ptr::eq(k, c)));
        } else if let Some(i) = explicit_index(item).or_else(|| item.parse::<usize>().ok()) {
            index(cams, i, path)?;
            picked.push(i);
        } else if let Some(range) = parse_index_range(item) {
            let (start, end) = range.map_err(not_found)?;
            let end = end.unwrap_or(cams.len());
            if start >= end {
                return Err(not_found(format!(
                    "camera range \"{item}\" is empty (start {start}, end {end} exclusive)"
                )));
            }
            if end > cams.len() {
                return Err(not_found(format!(
                    "camera range \"{item}\" reaches past the last camera; there {} ({}){}",
                    count_cameras(cams.len()),
                    index_span(cams.len()),
                    if start < cams.len() {
                        format!("; use {start}.. to go to the end")
                    } else {
                        String::new()
                    }
                )));
            }
            picked.extend(start..end);
        } else {
            let found = by_name(cams, item, path)?;
            picked.extend(cams.iter().position(|c| std::ptr::eq(c, found)));
        }
    }
    Ok(picked)
}

/// `#N`: index N, whatever the cameras are named.
fn explicit_index(item: &str) -> Option<usize> {
    item.strip_prefix('#')?.trim().parse().ok()
}

/// The camera a number names (`0002` of a camera named `0002` or `0002.jpg`): such a
/// name wins over the index the number would be.
fn named_number<'a>(cams: &'a [Camera], item: &str) -> Option<&'a Camera> {
    item.parse::<usize>().ok()?;
    by_name(cams, item, Path::new("")).ok()
}

/// How `--camera SPEC` was read, for a summary: the cameras picked at `indices` by name
/// and index (up to four), or their count.
pub fn describe_selection(cams: &[Camera], spec: &str, indices: &[usize]) -> String {
    if indices.len() > 4 {
        return format!("--camera {spec}: {} cameras", indices.len());
    }
    let picked: Vec<String> = indices
        .iter()
        .map(|&i| format!("\"{}\" (index {i})", cams[i].name))
        .collect();
    format!("--camera {spec}: {}", picked.join(", "))
}

fn index<'a>(cams: &'a [Camera], i: usize, path: &Path) -> Result<&'a Camera, CameraError> {
    cams.get(i).ok_or_else(|| CameraError::NotFound {
        path: path.to_path_buf(),
        message: format!(
            "camera index {i} is out of range; there {} ({})",
            count_cameras(cams.len()),
            index_span(cams.len())
        ),
    })
}

/// The valid indices of a list of `len` items in the notation `--camera` and `--frames`
/// read back (`0..=23` for 24 items).
pub fn index_span(len: usize) -> String {
    match len {
        0 => "none".into(),
        1 => "only 0".into(),
        n => format!("0..={}", n - 1),
    }
}

/// "is 1 camera", "are 8 cameras".
fn count_cameras(n: usize) -> String {
    if n == 1 {
        "is 1 camera".into()
    } else {
        format!("are {n} cameras")
    }
}

/// `Some(Ok((start, end)))` for `a..b`, `a..=b`, `a..` and `..b` (end exclusive, `None`
/// meaning the end of the list); `Some(Err)` for a range with a bad bound; `None` when the
/// item is no range at all (a name).
pub fn parse_index_range(item: &str) -> Option<Result<(usize, Option<usize>), String>> {
    let (lo, hi, inclusive) = if let Some((lo, hi)) = item.split_once("..=") {
        (lo, hi, true)
    } else {
        let (lo, hi) = item.split_once("..")?;
        (lo, hi, false)
    };
    let bound = |s: &str| -> Option<Option<usize>> {
        let s = s.trim();
        if s.is_empty() {
            Some(None)
        } else {
            s.parse::<usize>().ok().map(Some)
        }
    };
    // Something like `shot..final` is a name, not a malformed range.
    let (lo, hi) = (bound(lo)?, bound(hi)?);
    let start = lo.unwrap_or(0);
    let end = match (hi, inclusive) {
        (None, true) => return Some(Err(format!("range \"{item}\" needs an end after ..="))),
        (None, false) => None,
        (Some(h), true) => Some(h.saturating_add(1)),
        (Some(h), false) => Some(h),
    };
    Some(Ok((start, end)))
}

fn by_name<'a>(cams: &'a [Camera], name: &str, path: &Path) -> Result<&'a Camera, CameraError> {
    if let Some(c) = cams.iter().find(|c| c.name == name) {
        return Ok(c);
    }
    let stem_matches: Vec<&Camera> = cams
        .iter()
        .filter(|c| Path::new(&c.name).file_stem().and_then(|s| s.to_str()) == Some(name))
        .collect();
    match stem_matches.as_slice() {
        [one] => Ok(one),
        [] => {
            let names: Vec<&str> = cams.iter().take(5).map(|c| c.name.as_str()).collect();
            Err(CameraError::NotFound {
                path: path.to_path_buf(),
                message: format!(
                    "has no camera named \"{name}\" (names include {}{})",
                    names.join(", "),
                    if cams.len() > 5 { ", ..." } else { "" }
                ),
            })
        }
        many => Err(CameraError::NotFound {
            path: path.to_path_buf(),
            message: format!(
                "camera name \"{name}\" is ambiguous: it is the stem of {} names ({}, ...); give the full name",
                many.len(),
                many.iter().take(3).map(|c| c.name.as_str()).collect::<Vec<_>>().join(", ")
            ),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Vec3};

    fn cams(n: usize) -> Vec<Camera> {
        (0..n)
            .map(|i| Camera {
                name: format!("IMG_{i:04}.jpg"),
                width: 8,
                height: 8,
                fx: 8.0,
                fy: 8.0,
                cx: 4.0,
                cy: 4.0,
                rotation: Mat3::IDENTITY,
                translation: Vec3::new(i as f32, 0.0, 0.0),
                lens: crate::core::camera::Lens::Pinhole,
            })
            .collect()
    }

    fn names(spec: &str, n: usize) -> Result<Vec<usize>, String> {
        let all = cams(n);
        select_cameras(&all, spec, Path::new("cams"))
            .map(|v| v.iter().map(|c| c.translation.x as usize).collect())
            .map_err(|e| e.to_string())
    }

    #[test]
    fn selection_specs() {
        assert_eq!(names("all", 4).unwrap(), vec![0, 1, 2, 3]);
        assert_eq!(names(" ALL ", 2).unwrap(), vec![0, 1]);
        assert_eq!(names("3", 5).unwrap(), vec![3]);
        assert_eq!(names("0,3,7", 8).unwrap(), vec![0, 3, 7]);
        assert_eq!(names("2..5", 8).unwrap(), vec![2, 3, 4]);
        assert_eq!(names("2..=5", 8).unwrap(), vec![2, 3, 4, 5]);
        assert_eq!(names("6..", 8).unwrap(), vec![6, 7]);
        assert_eq!(names("..2", 8).unwrap(), vec![0, 1]);
        assert_eq!(names("0..8", 8).unwrap(), (0..8).collect::<Vec<_>>());
        assert_eq!(
            names("7, 1..3, IMG_0005.jpg, IMG_0000", 8).unwrap(),
            vec![7, 1, 2, 5, 0]
        );
    }

    #[test]
    fn selection_errors() {
        let e = names("8", 8).unwrap_err();
        assert!(
            e.contains("index 8 is out of range") && e.contains("8 cameras"),
            "{e}"
        );
        // Ranges past the end are errors in the notation the option reads, as with --frames.
        let e = names("5..9", 8).unwrap_err();
        assert!(
            e.contains("\"5..9\" reaches past the last camera")
                && e.contains("0..=7")
                && e.contains("use 5.."),
            "{e}"
        );
        let e = names("5..=8", 8).unwrap_err();
        assert!(e.contains("reaches past"), "{e}");
        let e = names("5..5", 8).unwrap_err();
        assert!(e.contains("is empty"), "{e}");
        let e = names("6..2", 8).unwrap_err();
        assert!(e.contains("is empty"), "{e}");
        let e = names("3..=", 8).unwrap_err();
        assert!(e.contains("needs an end"), "{e}");
        let e = names("nope", 8).unwrap_err();
        assert!(
            e.contains("no camera named \"nope\"") && e.contains("IMG_0000.jpg"),
            "{e}"
        );
        let e = names("1,,2", 8).unwrap_err();
        assert!(e.contains("empty item"), "{e}");
        let e = names("", 8).unwrap_err();
        assert!(e.contains("empty"), "{e}");
        let e = names("all", 0).unwrap_err();
        assert!(e.contains("no cameras"), "{e}");
        let e = names("..", 0).unwrap_err();
        assert!(e.contains("is empty"), "{e}");
    }

    #[test]
    fn a_number_that_is_a_name_picks_that_camera() {
        let mut all = cams(12);
        for (i, c) in all.iter_mut().enumerate() {
            c.name = format!("{:04}.jpg", i + 1);
        }
        // "0002" is the photo 0002.jpg (index 1), not index 2; "#2" is index 2; a number
        // that names no camera is an index.
        let pick = |spec: &str| {
            select_camera_indices(&all, spec, Path::new("c")).map_err(|e| e.to_string())
        };
        assert_eq!(pick("0002").unwrap(), vec![1]);
        assert_eq!(pick("0002.jpg").unwrap(), vec![1]);
        assert_eq!(pick("#2").unwrap(), vec![2]);
        assert_eq!(pick("2").unwrap(), vec![2]);
        assert_eq!(pick("0012,#0,3").unwrap(), vec![11, 0, 3]);
        assert!(pick("#12").unwrap_err().contains("out of range"));
        assert_eq!(
            select_camera(&all, "0002", Path::new("c")).unwrap().name,
            "0002.jpg"
        );
        assert_eq!(
            select_camera(&all, "#2", Path::new("c")).unwrap().name,
            "0003.jpg"
        );
        // A name by its stem, as in a list; one that names no camera is refused.
        let mut named = all.clone();
        named[4].name = "IMG_7.jpg".into();
        assert_eq!(
            select_camera(&named, "IMG_7", Path::new("c")).unwrap().name,
            "IMG_7.jpg"
        );
        let e = select_camera(&named, "IMG_8", Path::new("c")).unwrap_err();
        assert!(
            e.to_string().contains("has no camera named \"IMG_8\""),
            "{e}"
        );
        assert_eq!(
            describe_selection(&all, "0002", &pick("0002").unwrap()),
            "--camera 0002: \"0002.jpg\" (index 1)"
        );
    }

    #[test]
    fn ambiguous_stem_is_an_error() {
        let mut all = cams(2);
        all[0].name = "a.jpg".into();
        all[1].name = "a.png".into();
        let e = select_cameras(&all, "a", Path::new("c"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("ambiguous"), "{e}");
        assert_eq!(
            select_cameras(&all, "a.png", Path::new("c")).unwrap()[0].name,
            "a.png"
        );
    }
}
