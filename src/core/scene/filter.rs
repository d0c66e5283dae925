//! Selection filters applied to a scene before it is rendered or converted: the
//! scale-filter slider of the Kaolin notebook as `--max-scale`, `--min-opacity`, an
//! axis-aligned `--crop` box, and `--sh-degree` to drop SH bands.
//!
//! Filters never rewrite the input file: they produce a new [`Scene`] holding the kept
//! Gaussians in their original order, so a render of a filtered scene equals the render
//! of a file that was filtered beforehand.

use super::{sigmoid, Scene};

/// Which Gaussians to keep and how many SH bands to use.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneFilter {
    /// Drop Gaussians whose largest axis scale (`exp(log_scale)`, world units) is above this.
    pub max_scale: Option<f32>,
    /// Drop Gaussians whose opacity (`sigmoid(logit)`) is below this.
    pub min_opacity: Option<f32>,
    /// Keep only Gaussians whose centre lies in this box (inclusive), `[min, max]`.
    pub crop: Option<[[f32; 3]; 2]>,
    /// Render or write with at most this SH degree (bands above it are dropped).
    pub sh_degree: Option<u32>,
}

impl SceneFilter {
    /// True when the filter keeps every Gaussian and every band of `scene`.
    pub fn is_identity_for(&self, scene: &Scene) -> bool {
        self.max_scale.is_none()
            && self.min_opacity.is_none()
            && self.crop.is_none()
            && self.sh_degree.map_or(true, |d| d >= scene.sh_degree)
    }

    /// Checks the parameters themselves (finite, ordered box, degree 0..=3).
    pub fn validate(&self) -> Result<(), String> {
        if let Some(s) = self.max_scale {
            if !(s.is_finite() && s > 0.0) {
                return Err(format!("--max-scale must be a positive number, got {s}"));
            }
        }
        if let Some(o) = self.min_opacity {
            if !(0.0..=1.0).contains(&o) {
                return Err(format!("--min-opacity must be in [0, 1], got {o}"));
            }
        }
        if let Some([lo, hi]) = self.crop {
            for a in 0..3 {
                if !(lo[a].is_finite() && hi[a].is_finite() && lo[a] <= hi[a]) {
                    return Err(format!(
                        "--crop needs finite bounds with min <= max on every axis, got {lo:?}..{hi:?}"
                    ));
                }
            }
        }
        if let Some(d) = self.sh_degree {
            if d > 3 {
                return Err(format!("--sh-degree must be 0..3, got {d}"));
            }
        }
        Ok(())
    }

    /// True when Gaussian `i` of `scene` passes the selection filters.
    pub fn keeps(&self, scene: &Scene, i: usize) -> bool {
        if let Some(max) = self.max_scale {
            let s = scene.log_scales[i];
            let largest = s[0].max(s[1]).max(s[2]).exp();
            // A Gaussian with a NaN scale is dropped too.
            if largest.is_nan() || largest > max {
                return false;
            }
        }
        if let Some(min) = self.min_opacity {
            let opacity = sigmoid(scene.opacity_logits[i]);
            if opacity.is_nan() || opacity < min {
                return false;
            }
        }
        if let Some([lo, hi]) = self.crop {
            let p = scene.positions[i];
            if !(0..3).all(|a| p[a] >= lo[a] && p[a] <= hi[a]) {
                return false;
            }
        }
        true
    }

    /// Returns the filtered scene: kept Gaussians in their original order, SH truncated
    /// to `sh_degree` when it is lower than the scene's.
    pub fn apply(&self, scene: &Scene) -> Scene {
        let degree = self
            .sh_degree
            .map_or(scene.sh_degree, |d| d.min(scene.sh_degree));
        let keep: Vec<usize> = (0..scene.len()).filter(|&i| self.keeps(scene, i)).collect();
        scene.select(&keep, degree)
    }
}

/// Parses a crop box written `xmin,ymin,zmin,xmax,ymax,zmax`.
pub fn parse_crop(text: &str) -> Result<[[f32; 3]; 2], String> {
    let vals: Result<Vec<f32>, _> = text.split(',').map(|v| v.trim().parse::<f32>()).collect();
    match vals {
        Ok(v) if v.len() == 6 => Ok([[v[0], v[1], v[2]], [v[3], v[4], v[5]]]),
        _ => Err(format!(
            "expected six numbers xmin,ymin,zmin,xmax,ymax,zmax, got \"{text}\""
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> Scene {
        let mut s = Scene::empty(1);
        for i in 0..4 {
            s.positions.push([i as f32, 0.0, 0.0]);
            s.log_scales.push([(0.1 * (i + 1) as f32).ln(), -5.0, -5.0]);
            s.rotations.push([1.0, 0.0, 0.0, 0.0]);
            s.opacity_logits.push(i as f32 - 1.5);
            s.sh.extend((0..12).map(|k| (i * 100 + k) as f32));
        }
        s
    }

    #[test]
    fn max_scale_and_opacity_and_crop_select_exactly() {
        let s = scene();
        let f = SceneFilter {
            max_scale: Some(0.25),
            ..Default::default()
        };
        assert_eq!(
            f.apply(&s).positions,
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
        );
        let f = SceneFilter {
            min_opacity: Some(0.5),
            ..Default::default()
        };
        assert_eq!(
            f.apply(&s).positions,
            vec![[2.0, 0.0, 0.0], [3.0, 0.0, 0.0]]
        );
        let f = SceneFilter {
            crop: Some([[0.5, -1.0, -1.0], [2.0, 1.0, 1.0]]),
            ..Default::default()
        };
        assert_eq!(
            f.apply(&s).positions,
            vec![[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
        );
    }

    #[test]
    fn sh_truncation_keeps_the_low_bands() {
        let s = scene();
        let f = SceneFilter {
            sh_degree: Some(0),
            ..Default::default()
        };
        let out = f.apply(&s);
        assert_eq!(out.sh_degree, 0);
        assert_eq!(
            out.sh,
            vec![0., 1., 2., 100., 101., 102., 200., 201., 202., 300., 301., 302.]
        );
        assert!(out.check_consistent().is_ok());
        assert!(SceneFilter::default().is_identity_for(&s));
        assert_eq!(SceneFilter::default().apply(&s), s);
    }

    #[test]
    fn parameters_are_checked() {
        assert!(parse_crop("0,0,0,1,1,1").is_ok());
        assert!(parse_crop("0,0,0,1,1").is_err());
        let bad = SceneFilter {
            crop: Some([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]]),
            ..Default::default()
        };
        assert!(bad.validate().is_err());
        let bad = SceneFilter {
            min_opacity: Some(1.5),
            ..Default::default()
        };
        assert!(bad.validate().is_err());
    }
}
