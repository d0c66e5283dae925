//! Lens distortion of the photos of a data set (COLMAP's `SIMPLE_RADIAL`, `RADIAL`,
//! `OPENCV`, `FULL_OPENCV`, `OPENCV_FISHEYE`, `SIMPLE_RADIAL_FISHEYE`, `RADIAL_FISHEYE`;
//! nerfstudio / instant-ngp `transforms.json` keys `k1..k4`, `p1`, `p2`, `camera_model`,
//! `is_fisheye`), as COLMAP and OpenCV define them. A model maps a ray's pinhole
//! coordinates `(x, y) = (X / Z, Y / Z)` to the distorted normalised coordinates whose
//! pixel is `(fx * xd + cx, fy * yd + cy)`; [`crate::train::undistort`] resamples photos
//! through it. `docs/cameras.md` lists the models and the keys.

use serde::{Deserialize, Serialize};

/// A distortion model and its coefficients.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Distortion {
    /// The model's name as the data set writes it (`OPENCV`, `OPENCV_FISHEYE`, ...), for
    /// messages and the record in the model directory.
    pub model: String,
    /// Equidistant fisheye (`theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 +
    /// k4 theta^8)`, `theta = atan(r)`) instead of Brown-Conrady.
    pub fisheye: bool,
    /// Brown-Conrady: `k1..k6` of the rational radial factor `(1 + k1 r^2 + k2 r^4 +
    /// k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)`; fisheye: `k1..k4` of the angle's
    /// polynomial (the rest zero).
    pub radial: [f64; 6],
    /// Brown-Conrady tangential `p1, p2` (zero for a fisheye).
    pub tangential: [f64; 2],
}

impl Distortion {
    /// Brown-Conrady (OpenCV) with radial `k1..k6` and tangential `p1, p2`.
    pub fn opencv(model: &str, radial: [f64; 6], tangential: [f64; 2]) -> Distortion {
        Distortion {
            model: model.into(),
            fisheye: false,
            radial,
            tangential,
        }
    }

    /// Equidistant fisheye with `k1..k4`.
    pub fn fisheye(model: &str, k: [f64; 4]) -> Distortion {
        Distortion {
            model: model.into(),
            fisheye: true,
            radial: [k[0], k[1], k[2], k[3], 0.0, 0.0],
            tangential: [0.0; 2],
        }
    }

    /// Whether this is no distortion at all: a Brown-Conrady model whose coefficients are
    /// all exactly zero (a fisheye never is, even with zero coefficients).
    pub fn is_pinhole(&self) -> bool {
        !self.fisheye
            && self.radial.iter().all(|&k| k == 0.0)
            && self.tangential.iter().all(|&p| p == 0.0)
    }

    /// Whether every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        self.radial
            .iter()
            .chain(&self.tangential)
            .all(|k| k.is_finite())
    }

    /// The distorted normalised coordinates of the ray through pinhole coordinates
    /// `(x, y)`.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        if self.fisheye {
            let r = (x * x + y * y).sqrt();
            if r < 1e-12 {
                return (x, y);
            }
            let s = equidistant(&self.radial, r.atan()) / r;
            return (x * s, y * s);
        }
        brown_conrady(&self.radial, &self.tangential, x, y)
    }

    /// The pinhole coordinates whose ray is distorted to `(xd, yd)`, found by Newton's
    /// method from `(xd, yd)` (as COLMAP's iterative undistortion); `None` where it does
    /// not converge or, for a fisheye, where the ray is at or beyond 90 degrees from the
    /// axis (no pinhole image holds it).
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        if self.fisheye {
            return self.undistort_fisheye(xd, yd);
        }
        invert_brown_conrady(&self.radial, &self.tangential, xd, yd)
    }

    /// The fisheye's inverse: the angle `theta` of `theta_d = |(xd, yd)|` by Newton's
    /// method, then `r = tan(theta)` along the same direction.
    fn undistort_fisheye(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        let td = (xd * xd + yd * yd).sqrt();
        if td < 1e-12 {
            return Some((xd, yd));
        }
        let k = &self.radial;
        let mut t = td;
        for _ in 0..100 {
            let f = equidistant(k, t) - td;
            let df = equidistant_slope(k, t);
            if !df.is_finite() || df.abs() < 1e-12 {
                return None;
            }
            let step = f / df;
            t -= step;
            if step.abs() < 1e-14 {
                break;
            }
        }
        let err = equidistant(k, t) - td;
        if !(t.is_finite() && err.abs() < 1e-9 && t > 0.0 && t < std::f64::consts::FRAC_PI_2 - 1e-6)
        {
            return None;
        }
        let s = t.tan() / td;
        Some((xd * s, yd * s))
    }
}

impl Distortion {
    /// The model's own coefficients by name, in the model's order (COLMAP's parameter
    /// order after the intrinsics: `k1, k2, p1, p2` for `OPENCV`, `k1..k4` for
    /// `OPENCV_FISHEYE`), then any other that is not zero.
    pub fn coefficients(&self) -> Vec<(&'static str, f64)> {
        let (k, p) = (&self.radial, &self.tangential);
        let all = [
            ("k1", k[0]),
            ("k2", k[1]),
            ("k3", k[2]),
            ("k4", k[3]),
            ("k5", k[4]),
            ("k6", k[5]),
            ("p1", p[0]),
            ("p2", p[1]),
        ];
        let own: &[&'static str] = match (self.fisheye, self.model.as_str()) {
            (true, "SIMPLE_RADIAL_FISHEYE") => &["k1"],
            (true, "RADIAL_FISHEYE") => &["k1", "k2"],
            (true, _) => &["k1", "k2", "k3", "k4"],
            (false, "SIMPLE_RADIAL") => &["k1"],
            (false, "RADIAL") => &["k1", "k2"],
            (false, "FULL_OPENCV") => &["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
            (false, _) => &["k1", "k2", "p1", "p2"],
        };
        let value = |name: &str| all.iter().find(|(n, _)| *n == name).map_or(0.0, |c| c.1);
        own.iter()
            .map(|&n| (n, value(n)))
            .chain(
                all.iter()
                    .filter(|(n, v)| !own.contains(n) && *v != 0.0)
                    .copied(),
            )
            .collect()
    }
}

/// `OPENCV_FISHEYE (k1 0.03, k2 -0.01, k3 0.002, k4 0)`: the model and its own coefficients.
impl std::fmt::Display for Distortion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let coefficients: Vec<String> = self
            .coefficients()
            .iter()
            .map(|(name, v)| format!("{name} {v}"))
            .collect();
        write!(f, "{} ({})", self.model, coefficients.join(", "))
    }
}

/// The equidistant fisheye's normalised radius at angle `theta` from the axis:
/// `theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)` (`k`: at least 4).
pub fn equidistant(k: &[f64], theta: f64) -> f64 {
    let t2 = theta * theta;
    theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))
}

/// d/dtheta of [`equidistant`].
pub fn equidistant_slope(k: &[f64], theta: f64) -> f64 {
    let t2 = theta * theta;
    1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + 9.0 * t2 * k[3])))
}

/// Brown-Conrady distortion of pinhole coordinates `(x, y)`: the rational radial factor of
/// `radial` (`k1..k6`) and the tangential terms of `tangential` (`p1, p2`).
pub fn brown_conrady(radial: &[f64; 6], tangential: &[f64; 2], x: f64, y: f64) -> (f64, f64) {
    let k = radial;
    let [p1, p2] = *tangential;
    let r2 = x * x + y * y;
    let num = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[2]));
    let den = 1.0 + r2 * (k[3] + r2 * (k[4] + r2 * k[5]));
    let radial = num / den;
    (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )
}

/// The pinhole coordinates that [`brown_conrady`] distorts to `(xd, yd)`, by Newton's
/// method from `(xd, yd)` (as COLMAP's iterative undistortion); `None` where it does not
/// converge.
pub fn invert_brown_conrady(
    radial: &[f64; 6],
    tangential: &[f64; 2],
    xd: f64,
    yd: f64,
) -> Option<(f64, f64)> {
    let distort = |x: f64, y: f64| brown_conrady(radial, tangential, x, y);
    let (mut x, mut y) = (xd, yd);
    for _ in 0..100 {
        let (fx, fy) = distort(x, y);
        let (ex, ey) = (fx - xd, fy - yd);
        let h = 1e-7 * (1.0 + x.abs().max(y.abs()));
        let (ax, ay) = distort(x + h, y);
        let (bx, by) = distort(x - h, y);
        let (cx, cy) = distort(x, y + h);
        let (dx, dy) = distort(x, y - h);
        let (j00, j10) = ((ax - bx) / (2.0 * h), (ay - by) / (2.0 * h));
        let (j01, j11) = ((cx - dx) / (2.0 * h), (cy - dy) / (2.0 * h));
        let det = j00 * j11 - j01 * j10;
        if !det.is_finite() || det.abs() < 1e-12 {
            return None;
        }
        let sx = (j11 * ex - j01 * ey) / det;
        let sy = (j00 * ey - j10 * ex) / det;
        x -= sx;
        y -= sy;
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        if sx.abs().max(sy.abs()) < 1e-13 * (1.0 + x.abs().max(y.abs())) {
            break;
        }
    }
    let (fx, fy) = distort(x, y);
    let err = (fx - xd).abs().max((fy - yd).abs());
    (err < 1e-9 * (1.0 + xd.abs().max(yd.abs()))).then_some((x, y))
}

/// The distortion of a COLMAP camera model given its parameters after the focal length
/// and principal point (`None`: a pinhole model, or a distorted one whose coefficients
/// are all zero), or why it cannot be handled.
pub fn from_colmap(model: &str, p: &[f64]) -> Result<Option<Distortion>, String> {
    let get = |i: usize| p.get(i).copied().unwrap_or(0.0);
    let d = match model {
        "SIMPLE_PINHOLE" | "PINHOLE" => return Ok(None),
        "SIMPLE_RADIAL" | "RADIAL" => {
            Distortion::opencv(model, [get(0), get(1), 0.0, 0.0, 0.0, 0.0], [0.0; 2])
        }
        "OPENCV" => Distortion::opencv(
            model,
            [get(0), get(1), 0.0, 0.0, 0.0, 0.0],
            [get(2), get(3)],
        ),
        "FULL_OPENCV" => Distortion::opencv(
            model,
            [get(0), get(1), get(4), get(5), get(6), get(7)],
            [get(2), get(3)],
        ),
        "OPENCV_FISHEYE" => Distortion::fisheye(model, [get(0), get(1), get(2), get(3)]),
        "SIMPLE_RADIAL_FISHEYE" | "RADIAL_FISHEYE" => {
            Distortion::fisheye(model, [get(0), get(1), 0.0, 0.0])
        }
        "FOV" if p.iter().all(|&w| w == 0.0) => return Ok(None),
        other => {
            return Err(format!(
                "the {other} model is not supported (verisplat has no lens for it); \
                 undistort the images first (`colmap image_undistorter` writes PINHOLE cameras)"
            ))
        }
    };
    if !d.is_finite() {
        return Err(format!(
            "the {model} model has a non-finite distortion parameter"
        ));
    }
    Ok((!d.is_pinhole()).then_some(d))
}

/// The distortion a nerfstudio / instant-ngp `transforms.json` frame gives through `key`
/// (the frame's value, else the file's): `camera_model` (`OPENCV` and the pinhole and
/// radial COLMAP names: Brown-Conrady with `k1, k2, k3, p1, p2`; `OPENCV_FISHEYE`:
/// `k1..k4`), or instant-ngp's `is_fisheye`. `None`: no distortion (every coefficient
/// zero or absent). A coefficient the model has no place for is refused, never dropped.
pub fn from_transforms<'a>(
    key: &dyn Fn(&str) -> Option<&'a serde_json::Value>,
) -> Result<Option<Distortion>, String> {
    let mut c = std::collections::BTreeMap::new();
    for name in ["k1", "k2", "k3", "k4", "k5", "k6", "p1", "p2"] {
        let v = match key(name) {
            None | Some(serde_json::Value::Null) => 0.0,
            Some(v) => v
                .as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("\"{name}\" is not a finite number"))?,
        };
        c.insert(name, v);
    }
    let fisheye_flag = match key("is_fisheye") {
        None | Some(serde_json::Value::Null) => false,
        Some(v) => v
            .as_bool()
            .ok_or_else(|| "\"is_fisheye\" is not true or false".to_string())?,
    };
    let model = match key("camera_model") {
        None | Some(serde_json::Value::Null) if fisheye_flag => "OPENCV_FISHEYE".to_string(),
        None | Some(serde_json::Value::Null) => "OPENCV".to_string(),
        Some(v) => v
            .as_str()
            .ok_or_else(|| "\"camera_model\" is not a string".to_string())?
            .to_string(),
    };
    let nonzero = |names: &[&'static str]| -> Option<&'static str> {
        names.iter().copied().find(|n| c[n] != 0.0)
    };
    let refuse = |n: &str, why: &str| {
        Err(format!(
            "\"{n}\" is {} but the {model} camera model {why}; it cannot be ignored",
            c[n]
        ))
    };
    // instant-ngp's f-theta lens: a model of its own, not Brown-Conrady.
    if let Some(n) = (0..5)
        .map(|i| format!("ftheta_p{i}"))
        .find(|n| key(n).and_then(|v| v.as_f64()).is_some_and(|v| v != 0.0))
    {
        return Err(format!(
            "\"{n}\" gives instant-ngp's f-theta lens, which is not supported; undistort the \
             photos to a pinhole camera first"
        ));
    }
    if let Some(n) = nonzero(&["k5", "k6"]) {
        return refuse(
            n,
            "has no such coefficient (transforms.json has k1..k4, p1, p2)",
        );
    }
    let d = match model.as_str() {
        "OPENCV" | "PINHOLE" | "SIMPLE_PINHOLE" | "SIMPLE_RADIAL" | "RADIAL" if !fisheye_flag => {
            if let Some(n) = nonzero(&["k4"]) {
                return refuse(
                    n,
                    "is undistorted with k1, k2, k3, p1, p2 only (as nerfstudio)",
                );
            }
            Distortion::opencv(
                &model,
                [c["k1"], c["k2"], c["k3"], 0.0, 0.0, 0.0],
                [c["p1"], c["p2"]],
            )
        }
        "OPENCV_FISHEYE" => {
            if let Some(n) = nonzero(&["p1", "p2"]) {
                return refuse(n, "has no tangential coefficients");
            }
            Distortion::fisheye(&model, [c["k1"], c["k2"], c["k3"], c["k4"]])
        }
        other if fisheye_flag => {
            return Err(format!(
            "\"is_fisheye\" is true but \"camera_model\" is {other}; a fisheye is OPENCV_FISHEYE"
        ))
        }
        "EQUIRECTANGULAR" => {
            return Err(
                "camera_model \"EQUIRECTANGULAR\" is a 360-degree camera, which has no pinhole \
                 image to undistort to; it can be rendered from (render --cameras \
                 transforms.json), not trained on"
                    .into(),
            )
        }
        other => {
            return Err(format!(
                "camera_model \"{other}\" is not supported (supported: OPENCV, OPENCV_FISHEYE, \
                 the pinhole models and, to render from, EQUIRECTANGULAR); undistort the photos \
                 to a pinhole camera first"
            ))
        }
    };
    Ok((!d.is_pinhole()).then_some(d))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undistort_inverts_distort() {
        let models = [
            Distortion::opencv("OPENCV", [-0.2, 0.05, 0.0, 0.0, 0.0, 0.0], [0.001, -0.002]),
            Distortion::opencv(
                "FULL_OPENCV",
                [0.1, -0.03, 0.01, 0.05, 0.0, 0.001],
                [0.0, 0.003],
            ),
            Distortion::fisheye("OPENCV_FISHEYE", [0.05, -0.01, 0.002, 0.0]),
        ];
        for d in &models {
            for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.6, 0.4), (0.01, 0.5)] {
                let (xd, yd) = d.distort(x, y);
                let (u, v) = d.undistort(xd, yd).expect("converges");
                assert!(
                    (u - x).abs() < 1e-9 && (v - y).abs() < 1e-9,
                    "{d:?}: {x},{y} -> {u},{v}"
                );
            }
        }
        // Zero coefficients: the identity; a fisheye with zero k is still equidistant.
        let zero = Distortion::opencv("OPENCV", [0.0; 6], [0.0; 2]);
        assert!(zero.is_pinhole());
        assert_eq!(zero.distort(0.3, -0.7), (0.3, -0.7));
        let f = Distortion::fisheye("OPENCV_FISHEYE", [0.0; 4]);
        assert!(!f.is_pinhole());
        let (xd, _) = f.distort(1.0, 0.0);
        assert!((xd - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert_eq!(f.undistort(2.0, 0.0), None, "beyond 90 degrees");
    }

    #[test]
    fn messages_show_each_models_own_coefficients() {
        let fisheye = from_colmap("OPENCV_FISHEYE", &[0.0; 4]).unwrap().unwrap();
        assert_eq!(
            fisheye.to_string(),
            "OPENCV_FISHEYE (k1 0, k2 0, k3 0, k4 0)"
        );
        let fisheye = from_colmap("OPENCV_FISHEYE", &[0.03, -0.01, 0.002, 0.0])
            .unwrap()
            .unwrap();
        assert_eq!(
            fisheye.to_string(),
            "OPENCV_FISHEYE (k1 0.03, k2 -0.01, k3 0.002, k4 0)"
        );
        let opencv = from_colmap("OPENCV", &[0.1, 0.0, 0.0, 0.01])
            .unwrap()
            .unwrap();
        assert_eq!(opencv.to_string(), "OPENCV (k1 0.1, k2 0, p1 0, p2 0.01)");
        let simple = from_colmap("SIMPLE_RADIAL_FISHEYE", &[0.2])
            .unwrap()
            .unwrap();
        assert_eq!(simple.to_string(), "SIMPLE_RADIAL_FISHEYE (k1 0.2)");
        let full = from_colmap("FULL_OPENCV", &[0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8])
            .unwrap()
            .unwrap();
        assert_eq!(
            full.to_string(),
            "FULL_OPENCV (k1 0.1, k2 0.2, p1 0.3, p2 0.4, k3 0.5, k4 0.6, k5 0.7, k6 0.8)"
        );
        // transforms.json's OPENCV has a k3 COLMAP's has not: shown where it is set.
        let json = serde_json::json!({"k1": 0.1, "k3": 0.05});
        let key = |k: &str| json.get(k);
        let d = from_transforms(&key).unwrap().unwrap();
        assert_eq!(d.to_string(), "OPENCV (k1 0.1, k2 0, p1 0, p2 0, k3 0.05)");
    }

    #[test]
    fn colmap_and_transforms_models_name_what_they_refuse() {
        assert_eq!(from_colmap("OPENCV", &[0.0; 4]), Ok(None));
        let d = from_colmap("OPENCV", &[0.1, 0.0, 0.0, 0.01])
            .unwrap()
            .unwrap();
        assert_eq!((d.radial[0], d.tangential), (0.1, [0.0, 0.01]));
        let e = from_colmap("THIN_PRISM_FISHEYE", &[0.0; 8]).unwrap_err();
        assert!(e.contains("THIN_PRISM_FISHEYE"), "{e}");
        assert!(from_colmap("FOV", &[0.1]).unwrap_err().contains("FOV"));
        let json: serde_json::Value = serde_json::json!({"k1": 0.1, "k4": 0.2});
        let key = |k: &str| json.get(k);
        let e = from_transforms(&key).unwrap_err();
        assert!(e.contains("\"k4\"") && e.contains("OPENCV"), "{e}");
        // A 360-degree camera has no distortion to undistort a photo by: the trainer
        // refuses it (a camera file renders from it: transforms::lens_from_transforms,
        // tested there).
        let json = serde_json::json!({"camera_model": "EQUIRECTANGULAR"});
        let key = |k: &str| json.get(k);
        let e = from_transforms(&key).unwrap_err();
        assert!(
            e.contains("EQUIRECTANGULAR") && e.contains("not trained on"),
            "{e}"
        );
        let json = serde_json::json!({"is_fisheye": true, "k1": 0.0});
        let key = |k: &str| json.get(k);
        assert!(from_transforms(&key).unwrap().unwrap().fisheye);
        let json = serde_json::json!({"k1": 0.0, "p2": 0.0});
        let key = |k: &str| json.get(k);
        assert_eq!(from_transforms(&key), Ok(None));
    }
}
