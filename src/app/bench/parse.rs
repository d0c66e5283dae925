//! Parsers of the benchmark's command-line values: resolutions and Gaussian counts.

/// Parses a resolution: `720p`, `1080p`, `1440p`, `4k` or `WxH`.
pub fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "720p" => Ok((1280, 720)),
        "1080p" => Ok((1920, 1080)),
        "1440p" => Ok((2560, 1440)),
        "4k" | "2160p" => Ok((3840, 2160)),
        other => {
            let (w, h) = other.split_once('x').ok_or_else(|| {
                format!("unknown resolution {s:?}; use 720p, 1080p, 1440p, 4k or WxH")
            })?;
            let parse = |v: &str| {
                v.parse::<u32>().map_err(|_| {
                    format!("unknown resolution {s:?}; use 720p, 1080p, 1440p, 4k or WxH")
                })
            };
            Ok((parse(w)?, parse(h)?))
        }
    }
}

/// Parses a Gaussian count such as `1e5`, `250000` or `2.5e5`.
pub fn parse_count(s: &str) -> Result<usize, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of Gaussians"))?;
    if !(1.0..=1e9).contains(&v) || v.fract() != 0.0 {
        return Err(format!(
            "{s:?} is not a whole number of Gaussians between 1 and 1e9"
        ));
    }
    Ok(v as usize)
}
