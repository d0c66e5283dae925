//! Value parsers for numeric options: negative numbers parse wherever they make sense,
//! and a value outside an option's range is a range error ("must be between ..."), not
//! a parse error. clap prints the message after the option's name.

use std::fmt::Display;
use std::str::FromStr;

fn number<T: FromStr>(s: &str, what: &str) -> Result<T, String> {
    s.trim()
        .parse::<T>()
        .map_err(|_| format!("expected {what}, got \"{s}\""))
}

fn finite(s: &str) -> Result<f32, String> {
    let v: f32 = number(s, "a number")?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("must be a finite number, got \"{s}\""))
    }
}

/// Any finite number (angles, offsets).
pub(crate) fn any_f32(s: &str) -> Result<f32, String> {
    finite(s)
}

/// A finite number greater than 0 (radii, scales, frame rates).
pub(crate) fn positive_f32(s: &str) -> Result<f32, String> {
    let v = finite(s)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("must be greater than 0, got {v}"))
    }
}

/// A number in [0, 1] (opacities, colour components).
pub(crate) fn unit_f32(s: &str) -> Result<f32, String> {
    let v = finite(s)?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("must be between 0 and 1, got {v}"))
    }
}

/// A size `WxH` (`1920x1080`), each side 1..=16384.
pub(crate) fn size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WIDTHxHEIGHT such as 1920x1080, got \"{s}\""))?;
    let side = int_in(1u32, verisplat::core::camera::MAX_IMAGE_SIDE);
    Ok((side(w)?, side(h)?))
}

/// A lens for generated cameras (`--lens`): `verisplat::core::camera::LensSpec`'s forms.
pub(crate) fn lens(s: &str) -> Result<verisplat::core::camera::LensSpec, String> {
    s.parse()
}

/// A field of view in degrees, strictly between 0 and 180.
pub(crate) fn fov_deg(s: &str) -> Result<f32, String> {
    let v = finite(s)?;
    if v > 0.0 && v < 180.0 {
        Ok(v)
    } else {
        Err(format!(
            "must be between 0 and 180 degrees (exclusive), got {v}"
        ))
    }
}

/// An elevation in degrees, strictly between -90 and 90 (at the poles the view
/// direction is parallel to the up axis and the camera's roll is undefined).
pub(crate) fn elevation_deg(s: &str) -> Result<f32, String> {
    let v = finite(s)?;
    if v > -90.0 && v < 90.0 {
        Ok(v)
    } else {
        Err(format!(
            "must be between -90 and 90 degrees (exclusive), got {v}"
        ))
    }
}

/// A whole number in `lo..=hi`, with a range error for any other whole number
/// (negative ones included).
pub(crate) fn int_in<T>(lo: T, hi: T) -> impl Fn(&str) -> Result<T, String> + Clone
where
    T: TryFrom<i128> + TryInto<i128> + Copy + Display + Send + Sync + 'static,
{
    // Every unsigned bound up to 64 bits fits an i128.
    let bounds = (
        lo.try_into().unwrap_or(i128::MIN),
        hi.try_into().unwrap_or(i128::MAX),
    );
    move |s: &str| {
        let v: i128 = number(s, "a whole number")?;
        if v < bounds.0 || v > bounds.1 {
            return Err(format!("must be between {lo} and {hi}, got {v}"));
        }
        T::try_from(v).map_err(|_| format!("must be between {lo} and {hi}, got {v}"))
    }
}

fn list(s: &str, n: usize, names: &str) -> Result<Vec<f32>, String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != n {
        return Err(format!("expected {names} ({n} numbers), got \"{s}\""));
    }
    parts
        .iter()
        .map(|p| {
            finite(p).map_err(|_| format!("expected {names} ({n} finite numbers), got \"{s}\""))
        })
        .collect()
}

/// `X,Y,Z`: three finite numbers.
pub(crate) fn vec3(s: &str) -> Result<[f32; 3], String> {
    let v = list(s, 3, "X,Y,Z")?;
    Ok([v[0], v[1], v[2]])
}

/// `EX,EY,EZ,TX,TY,TZ,UX,UY,UZ`: an eye, a target and an up direction (`--look-at`); the
/// eye not at the target, the up not zero nor along the line of sight.
pub(crate) fn look_at(s: &str) -> Result<[f32; 9], String> {
    let v = list(s, 9, "EX,EY,EZ,TX,TY,TZ,UX,UY,UZ (eye, target, up)")?;
    let eye = glam::Vec3::new(v[0], v[1], v[2]);
    let target = glam::Vec3::new(v[3], v[4], v[5]);
    let up = glam::Vec3::new(v[6], v[7], v[8]);
    if (target - eye).length() <= 1e-6 * eye.length().max(1.0) {
        return Err(format!(
            "the eye and the target are the same point in \"{s}\""
        ));
    }
    if up.length() == 0.0 {
        return Err(format!("the up direction is 0,0,0 in \"{s}\""));
    }
    if (target - eye).normalize().cross(up.normalize()).length() < 1e-4 {
        return Err(format!(
            "the up direction lies along the line of sight in \"{s}\"; give an up across it"
        ));
    }
    let mut out = [0f32; 9];
    out.copy_from_slice(&v[..9]);
    Ok(out)
}

/// `NEAR,FAR`: two different finite numbers.
pub(crate) fn depth_range(s: &str) -> Result<[f32; 2], String> {
    let v = list(s, 2, "NEAR,FAR")?;
    if v[0] == v[1] {
        return Err(format!("NEAR and FAR must differ, got \"{s}\""));
    }
    Ok([v[0], v[1]])
}

/// `R,G,B` in [0, 1], or `black` / `white`.
pub(crate) fn background(s: &str) -> Result<[f32; 3], String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "black" => return Ok([0.0; 3]),
        "white" => return Ok([1.0; 3]),
        _ => {}
    }
    let v = list(s, 3, "R,G,B")?;
    if let Some(c) = v.iter().find(|c| !(0.0..=1.0).contains(*c)) {
        return Err(format!(
            "colour components must be between 0 and 1 (linear), got {c} in \"{s}\""
        ));
    }
    Ok([v[0], v[1], v[2]])
}

/// `T0,T1`: two finite times (either order; equal only for one time).
pub(crate) fn time_range(s: &str) -> Result<[f32; 2], String> {
    let v = list(s, 2, "T0,T1")?;
    Ok([v[0], v[1]])
}

/// `PX,PY,PZ,NX,NY,NZ`: a plane's point and normal (six finite numbers, a nonzero normal).
pub(crate) fn plane(s: &str) -> Result<[f32; 6], String> {
    let v = list(s, 6, "PX,PY,PZ,NX,NY,NZ")?;
    if v[3] == 0.0 && v[4] == 0.0 && v[5] == 0.0 {
        return Err(format!(
            "the normal NX,NY,NZ must not be 0,0,0, got \"{s}\""
        ));
    }
    Ok([v[0], v[1], v[2], v[3], v[4], v[5]])
}

/// A colour-map range: `LO,HI` (LO below HI) or `auto` (`None`).
pub(crate) fn colour_range(s: &str) -> Result<Option<[f32; 2]>, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(None);
    }
    let v = list(s, 2, "LO,HI or auto")?;
    if v[0] >= v[1] {
        return Err(format!("LO must be below HI, got \"{s}\""));
    }
    Ok(Some([v[0], v[1]]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_values_parse_and_ranges_are_range_errors() {
        assert_eq!(any_f32("-90").unwrap(), -90.0);
        assert_eq!(vec3("-0.1,0,2e1").unwrap(), [-0.1, 0.0, 20.0]);
        assert_eq!(elevation_deg("-10").unwrap(), -10.0);
        assert!(positive_f32("-1").unwrap_err().contains("greater than 0"));
        assert!(positive_f32("0").unwrap_err().contains("greater than 0"));
        assert!(positive_f32("abc")
            .unwrap_err()
            .contains("expected a number"));
        assert!(positive_f32("inf").unwrap_err().contains("finite"));
        assert!(unit_f32("1.5").unwrap_err().contains("between 0 and 1"));
        assert!(fov_deg("180").unwrap_err().contains("between 0 and 180"));
        assert!(elevation_deg("90")
            .unwrap_err()
            .contains("between -90 and 90"));
        let threads = int_in(0usize, 64);
        assert_eq!(threads("4").unwrap(), 4);
        assert!(threads("-1").unwrap_err().contains("between 0 and 64"));
        assert!(threads("1000").unwrap_err().contains("between 0 and 64"));
        assert!(threads("1.5").unwrap_err().contains("whole number"));
        assert!(background("2,0,0").unwrap_err().contains("between 0 and 1"));
        assert_eq!(background("white").unwrap(), [1.0; 3]);
        assert!(depth_range("1,1").unwrap_err().contains("differ"));
        assert!(vec3("1,2").unwrap_err().contains("X,Y,Z"));
    }

    #[test]
    fn sizes_parse_with_their_limits() {
        assert_eq!(size("1920x1080").unwrap(), (1920, 1080));
        assert_eq!(size("64X48").unwrap(), (64, 48));
        assert!(size("1920").unwrap_err().contains("WIDTHxHEIGHT"));
        assert!(size("0x10").unwrap_err().contains("between 1 and"));
        assert!(size("100000x10").unwrap_err().contains("between 1 and"));
    }
}
