//! The differentiable model: Gaussians as a training loop holds them (gsplat's
//! conventions), the gradients of a frame's pixels that a loss hands back, and the
//! gradients per Gaussian that the backward passes return.
//!
//! Both backward passes use these types: the CPU reference ([`crate::cpu::backward`], in
//! f64) and the Vulkan pipeline ([`crate::render::GpuRenderer::backward`], in f32).

use super::{sh_coeffs_for_degree, ActivatedScene};

/// The colour model of the Gaussians.
#[derive(Clone, Debug, PartialEq)]
pub enum ColorParams<T> {
    /// SH coefficients of `degree` (0..=3), `(degree + 1)^2` per channel, coefficient-major
    /// with the colour channel innermost (`coeffs[(i * K + k) * 3 + c]`, gsplat's `[N, K, 3]`).
    /// Colour = max(SH + 0.5, 0) per channel, as the reference.
    Sh {
        /// SH degree stored (and evaluated, unless the options lower it).
        degree: u32,
        /// The coefficients.
        coeffs: Vec<T>,
    },
    /// `channels` values per Gaussian blended as they are (gsplat's `colors [N, D]` without
    /// `sh_degree`: no offset, no clamp), e.g. N-D features.
    Direct {
        /// Channels per Gaussian.
        channels: usize,
        /// The values, Gaussian-major.
        values: Vec<T>,
    },
}

/// Gaussians with the parameters a gradient is taken with respect to (gsplat's
/// conventions): centres, quaternions `(w, x, y, z)` of any non-zero length (normalised
/// inside), linear axis scales, opacities in [0, 1] and colours.
#[derive(Clone, Debug, PartialEq)]
pub struct SplatParams<T> {
    /// World-space centres.
    pub means: Vec<[T; 3]>,
    /// Rotations `(w, x, y, z)`, unnormalised.
    pub quats: Vec<[T; 4]>,
    /// Axis scales (linear, not log).
    pub scales: Vec<[T; 3]>,
    /// Opacities (activated, in [0, 1]).
    pub opacities: Vec<T>,
    /// Colours.
    pub colors: ColorParams<T>,
}

impl<T: Copy> SplatParams<T> {
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }
    /// True when there are no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }
    /// Channels each pixel receives (3 for SH colours).
    pub fn channels(&self) -> usize {
        match &self.colors {
            ColorParams::Sh { .. } => 3,
            ColorParams::Direct { channels, .. } => *channels,
        }
    }
    /// Colour values per Gaussian.
    pub fn color_stride(&self) -> usize {
        match &self.colors {
            ColorParams::Sh { degree, .. } => sh_coeffs_for_degree(*degree) * 3,
            ColorParams::Direct { channels, .. } => *channels,
        }
    }
    /// The colour values (SH coefficients or direct values).
    pub fn color_values(&self) -> &[T] {
        match &self.colors {
            ColorParams::Sh { coeffs, .. } => coeffs,
            ColorParams::Direct { values, .. } => values,
        }
    }
}

impl SplatParams<f32> {
    /// Checks lengths and values: every array holds one entry per Gaussian, every value is
    /// finite, scales are positive, opacities in [0, 1], quaternions non-zero, the SH degree
    /// 0..=3. The message names the array.
    pub fn validate(&self) -> Result<(), String> {
        let n = self.len();
        let lens = [
            ("quats", self.quats.len()),
            ("scales", self.scales.len()),
            ("opacities", self.opacities.len()),
        ];
        for (name, len) in lens {
            if len != n {
                return Err(format!("{name} has {len} entries for {n} means"));
            }
        }
        if let ColorParams::Sh { degree, .. } = self.colors {
            if degree > 3 {
                return Err(format!("the SH degree must be 0..3, got {degree}"));
            }
        }
        if let ColorParams::Direct { channels, .. } = self.colors {
            if channels == 0 {
                return Err("colors must have at least one channel".into());
            }
        }
        let stride = self.color_stride();
        if self.color_values().len() != n * stride {
            return Err(format!(
                "colors has {} values for {n} Gaussians of {stride}",
                self.color_values().len()
            ));
        }
        let finite = |name: &str, v: &mut dyn Iterator<Item = f32>| -> Result<(), String> {
            match v.enumerate().find(|(_, x)| !x.is_finite()) {
                Some((i, x)) => Err(format!("{name} holds {x} (value {i}); all must be finite")),
                None => Ok(()),
            }
        };
        finite("means", &mut self.means.iter().flatten().copied())?;
        finite("quats", &mut self.quats.iter().flatten().copied())?;
        finite("scales", &mut self.scales.iter().flatten().copied())?;
        finite("opacities", &mut self.opacities.iter().copied())?;
        finite("colors", &mut self.color_values().iter().copied())?;
        if let Some((i, s)) = self
            .scales
            .iter()
            .enumerate()
            .find(|(_, s)| s.iter().any(|&v| v <= 0.0))
        {
            return Err(format!(
                "scales of Gaussian {i} are {s:?}; scales are linear and must be positive"
            ));
        }
        if let Some((i, o)) = self
            .opacities
            .iter()
            .enumerate()
            .find(|(_, o)| !(0.0..=1.0).contains(*o))
        {
            return Err(format!(
                "opacity of Gaussian {i} is {o}; opacities are activated and must be in [0, 1]"
            ));
        }
        if let Some(i) = self
            .quats
            .iter()
            .position(|q| q.iter().map(|v| v * v).sum::<f32>() == 0.0)
        {
            return Err(format!("the quaternion of Gaussian {i} is zero"));
        }
        Ok(())
    }

    /// The same parameters in f64 (for the reference backward).
    pub fn to_f64(&self) -> SplatParams<f64> {
        let f = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
        SplatParams {
            means: self.means.iter().map(|m| m.map(f64::from)).collect(),
            quats: self.quats.iter().map(|m| m.map(f64::from)).collect(),
            scales: self.scales.iter().map(|m| m.map(f64::from)).collect(),
            opacities: f(&self.opacities),
            colors: match &self.colors {
                ColorParams::Sh { degree, coeffs } => ColorParams::Sh {
                    degree: *degree,
                    coeffs: f(coeffs),
                },
                ColorParams::Direct { channels, values } => ColorParams::Direct {
                    channels: *channels,
                    values: f(values),
                },
            },
        }
    }

    /// The scene the renderers draw: quaternions normalised, SH as they are; direct colour
    /// channels become the scene's feature channels (with SH degree 0 and zero
    /// coefficients for its colour).
    pub fn to_activated(&self) -> ActivatedScene {
        let rotations = self
            .quats
            .iter()
            .map(|q| {
                let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
                q.map(|v| v / n)
            })
            .collect();
        let (sh_degree, sh, feature_count, features) = match &self.colors {
            ColorParams::Sh { degree, coeffs } => (*degree, coeffs.clone(), 0, Vec::new()),
            ColorParams::Direct { channels, values } => {
                (0, vec![0.0; self.len() * 3], *channels, values.clone())
            }
        };
        ActivatedScene {
            sh_degree,
            positions: self.means.clone(),
            scales: self.scales.clone(),
            rotations,
            opacities: self.opacities.clone(),
            sh,
            feature_count,
            features,
        }
    }
}

/// What a loss hands back for one frame: its gradient with respect to each output pixel.
/// An empty vector stands for zeros.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PixelGrads<T> {
    /// dL/d(colour), `width * height * channels`, pixel-major (the colour includes the
    /// background, as the frame does).
    pub color: Vec<T>,
    /// dL/d(alpha), `width * height` (alpha = 1 - final transmittance).
    pub alpha: Vec<T>,
    /// dL/d(depth), `width * height`: the alpha-normalised depth the frame holds
    /// (sum of depth * weight / alpha; 0 where alpha is 0).
    pub depth: Vec<T>,
}

/// Gradients per Gaussian, in the layout of [`SplatParams`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplatGrads<T> {
    /// dL/d(means).
    pub means: Vec<[T; 3]>,
    /// dL/d(quats), with respect to the unnormalised quaternions given.
    pub quats: Vec<[T; 4]>,
    /// dL/d(scales) (linear).
    pub scales: Vec<[T; 3]>,
    /// dL/d(opacities).
    pub opacities: Vec<T>,
    /// dL/d(colour values): SH coefficients or direct values, in their layout.
    pub colors: Vec<T>,
    /// dL/d(2D means) in pixels (gsplat's `means2d.grad`).
    pub means2d: Vec<[T; 2]>,
    /// Sum over pixels of |dL/d(2D mean)| per axis (gsplat's `absgrad`), for densification.
    pub absgrad: Vec<[T; 2]>,
    /// The gradients of the projected quantities (gsplat's `v_conics`, `v_colors`,
    /// `v_depths`): dL/d(conic A, B, C), dL/d(the view's SH colour r, g, b: SH frames
    /// only, 0 for direct values), dL/d(view-space depth) and dL/d(the opacity blended:
    /// the compensated one when antialiased). The reference fills
    /// them always; the device when asked ([`crate::render::GpuRenderer::set_screen_grads`]),
    /// else zeros. A camera's gradient is the chain rule from them.
    pub screen: Vec<[T; 8]>,
}

impl<T: Copy + Default> SplatGrads<T> {
    /// Zero gradients for `n` Gaussians with `stride` colour values each.
    pub fn zeros(n: usize, stride: usize) -> Self {
        let z = T::default();
        SplatGrads {
            means: vec![[z; 3]; n],
            quats: vec![[z; 4]; n],
            scales: vec![[z; 3]; n],
            opacities: vec![z; n],
            colors: vec![z; n * stride],
            means2d: vec![[z; 2]; n],
            absgrad: vec![[z; 2]; n],
            screen: vec![[z; 8]; n],
        }
    }
}

/// Parameter groups of [`SplatGrads`], for comparisons group by group.
pub const GRAD_GROUPS: [&str; 8] = [
    "means",
    "quats",
    "scales",
    "opacities",
    "colors",
    "means2d",
    "absgrad",
    "screen",
];

impl<T: Copy + Into<f64>> SplatGrads<T> {
    /// The values of group `name` (one of [`GRAD_GROUPS`]) as f64.
    pub fn group(&self, name: &str) -> Vec<f64> {
        fn flat<T: Copy + Into<f64>, const K: usize>(v: &[[T; K]]) -> Vec<f64> {
            v.iter().flatten().map(|&x| x.into()).collect()
        }
        match name {
            "means" => flat(&self.means),
            "quats" => flat(&self.quats),
            "scales" => flat(&self.scales),
            "opacities" => self.opacities.iter().map(|&x| x.into()).collect(),
            "colors" => self.colors.iter().map(|&x| x.into()).collect(),
            "means2d" => flat(&self.means2d),
            "absgrad" => flat(&self.absgrad),
            "screen" => flat(&self.screen),
            _ => Vec::new(),
        }
    }
}

/// Relative L2 error `|a - b| / |b|` (0 when both are zero; infinite when only `b` is).
pub fn relative_l2(a: &[f64], b: &[f64]) -> f64 {
    let diff: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    let norm: f64 = b.iter().map(|y| y * y).sum();
    if norm == 0.0 {
        return if diff == 0.0 { 0.0 } else { f64::INFINITY };
    }
    (diff / norm).sqrt()
}
