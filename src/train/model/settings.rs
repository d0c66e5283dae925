//! The original's optimisation and densification settings, the MCMC strategy's, and the
//! centres' learning-rate schedule.

/// The original's optimisation and densification settings (`arguments/__init__.py`).
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Iterations in all.
    pub iterations: u32,
    /// Centre learning rate at the start and the end (times the scene extent), decayed
    /// exponentially over `position_lr_max_steps`.
    pub position_lr_init: f32,
    /// See `position_lr_init`.
    pub position_lr_final: f32,
    /// Steps of the centres' decay.
    pub position_lr_max_steps: u32,
    /// SH DC learning rate (the rest: a twentieth of it).
    pub feature_lr: f32,
    /// Opacity learning rate.
    pub opacity_lr: f32,
    /// Log-scale learning rate.
    pub scaling_lr: f32,
    /// Quaternion learning rate.
    pub rotation_lr: f32,
    /// Below `percent_dense * extent` a densified Gaussian is cloned, above it split.
    pub percent_dense: f32,
    /// Weight of D-SSIM in the loss.
    pub lambda_dssim: f32,
    /// Densify every this many iterations ...
    pub densification_interval: u32,
    /// ... from this iteration ...
    pub densify_from_iter: u32,
    /// ... until this one.
    pub densify_until_iter: u32,
    /// Average 2D-mean gradient (NDC units, as the original's) above which a Gaussian is
    /// densified.
    pub densify_grad_threshold: f32,
    /// Opacities are reset to at most 0.01 every this many iterations.
    pub opacity_reset_interval: u32,
    /// The SH degree in use rises by one every this many iterations.
    pub sh_increase_interval: u32,
    /// Learning rate of the neural shader's weights (feature splats).
    pub shader_lr: f32,
    /// Largest L2 norm of the whole gradient (all parameters, the shader's too); above it
    /// the gradient is scaled down to it. `None`: no clipping (the original's default).
    pub clip_grad: Option<f32>,
    /// The MCMC strategy (3DGS as Markov chain Monte Carlo, Kheradmand et al. 2024)
    /// instead of the original's densification; `None`: the original's.
    pub mcmc: Option<Mcmc>,
}

/// The MCMC strategy's settings (the names and defaults of `ubc-vision/3dgs-mcmc`): every
/// `densification_interval` iterations from `densify_from_iter` to `refine_until`, the
/// dead Gaussians (opacity <= 0.005) are moved onto live ones drawn by opacity and the
/// count grows by 5 % up to `cap_max`, each draw sharing its source's opacity and scale so
/// the rendered image stays the same; after every step the centres get noise shaped by
/// each Gaussian's covariance, strong where it is transparent; the loss gains
/// `opacity_reg * mean(opacity) + scale_reg * mean(scale)`. No opacity reset.
#[derive(Clone, Debug, PartialEq)]
pub struct Mcmc {
    /// The most Gaussians.
    pub cap_max: usize,
    /// Noise scale, times the centres' learning rate.
    pub noise_lr: f32,
    /// Weight of the mean opacity in the loss.
    pub opacity_reg: f32,
    /// Weight of the mean scale in the loss.
    pub scale_reg: f32,
    /// Relocation and growth stop at this iteration.
    pub refine_until: u32,
}

impl Default for Mcmc {
    fn default() -> Self {
        Mcmc {
            cap_max: 1_000_000,
            noise_lr: 5e5,
            opacity_reg: 0.01,
            scale_reg: 0.01,
            refine_until: 25_000,
        }
    }
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            iterations: 30_000,
            position_lr_init: 0.00016,
            position_lr_final: 0.0000016,
            position_lr_max_steps: 30_000,
            feature_lr: 0.0025,
            opacity_lr: 0.025,
            scaling_lr: 0.005,
            rotation_lr: 0.001,
            percent_dense: 0.01,
            lambda_dssim: 0.2,
            densification_interval: 100,
            densify_from_iter: 500,
            densify_until_iter: 15_000,
            densify_grad_threshold: 0.0002,
            opacity_reset_interval: 3000,
            sh_increase_interval: 1000,
            shader_lr: 0.001,
            clip_grad: None,
            mcmc: None,
        }
    }
}

/// The centres' learning rate at `step` (the original's `get_expon_lr_func`, no delay).
pub fn position_lr(settings: &Settings, extent: f32, step: u32) -> f32 {
    let t = (step as f32 / settings.position_lr_max_steps.max(1) as f32).clamp(0.0, 1.0);
    let (a, b) = (
        settings.position_lr_init * extent,
        settings.position_lr_final * extent,
    );
    (a.ln() * (1.0 - t) + b.ln() * t).exp()
}
