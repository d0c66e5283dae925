//! Differentiable rendering on the device, for training loops: [`DiffRasterizer`] renders
//! Gaussians given as a trainer holds them ([`SplatParams`], gsplat's conventions) and
//! returns the gradients of a loss with respect to them. The Python package's
//! `vksplat.torch.rasterization` is built on it. With a neural shader
//! ([`DiffRasterizer::set_shader`]) the Gaussians' direct values are feature channels that
//! the shader turns into colour, and the backward pass also returns the shader's gradients.

use super::shade::GpuShader;
use super::types::Splat;
use super::{GpuRenderer, GpuScene};
use crate::camera::Camera;
use crate::frame::Frame;
use crate::gpu::{GpuContext, GpuError, GpuResult};
use crate::mlp::{Mlp, MlpParams};
use crate::model::grad::{ColorParams, PixelGrads, SplatGrads, SplatParams};
use crate::model::RenderOptions;

pub use super::grad_accumulate::Accumulation;

/// The parameters as the device renders them: other numbers of direct channels are
/// blended as feature channels; direct RGB colours `c` become SH degree 0
/// coefficients `(c - 0.5) / C0`, whose colour is `max(c, 0)` (to rounding): the device
/// blends every colour through its SH path, so negative direct colours clamp at 0.
fn device_params(params: &SplatParams<f32>) -> std::borrow::Cow<'_, SplatParams<f32>> {
    match &params.colors {
        ColorParams::Direct { values, channels } if *channels == 3 => {
            let c0 = crate::model::sh::SH_C0;
            std::borrow::Cow::Owned(SplatParams {
                colors: ColorParams::Sh {
                    degree: 0,
                    coeffs: values.iter().map(|c| (c - 0.5) / c0).collect(),
                },
                ..params.clone()
            })
        }
        _ => std::borrow::Cow::Borrowed(params),
    }
}

/// The last forward pass: what its backward pass needs.
struct Forward {
    token: u64,
    frame: Frame,
    scene: GpuScene,
}

/// Whether `params` are blended as feature channels: direct values, not 3 of them unless
/// a shader reads them (`shaded`).
fn as_features(params: &SplatParams<f32>, shaded: bool) -> Option<(&[f32], usize)> {
    match &params.colors {
        ColorParams::Direct { channels, values } if *channels != 3 || shaded => {
            Some((values.as_slice(), *channels))
        }
        _ => None,
    }
}

/// A renderer that keeps each frame's forward state for a backward pass.
pub struct DiffRasterizer {
    renderer: GpuRenderer,
    last: Option<Forward>,
    next_token: u64,
    shader: Option<(Mlp, GpuShader)>,
}

impl DiffRasterizer {
    /// A rasterizer on `ctx`.
    pub fn new(ctx: GpuContext) -> GpuResult<Self> {
        Ok(Self::with_renderer(GpuRenderer::new(ctx)?))
    }

    /// A rasterizer on a renderer made by the caller (e.g. with another blend kernel).
    pub fn with_renderer(mut renderer: GpuRenderer) -> Self {
        renderer.set_save_forward_state(true);
        DiffRasterizer {
            renderer,
            last: None,
            next_token: 1,
            shader: None,
        }
    }

    /// The renderer underneath (timings, device facts, accumulation mode).
    pub fn renderer(&mut self) -> &mut GpuRenderer {
        &mut self.renderer
    }

    /// Shades the frames with `mlp` (a neural shader, [`crate::mlp`]) from now on, or not
    /// (`None`). The Gaussians' direct values are then its feature channels and
    /// [`Self::backward_shaded`] returns its gradients too. A training step's new weights
    /// (a network of the same shape) are uploaded in place.
    pub fn set_shader(&mut self, mlp: Option<&Mlp>) -> GpuResult<()> {
        if self.shader.as_ref().map(|(m, _)| m) == mlp {
            return Ok(());
        }
        // The saved forward state was shaded otherwise.
        self.last = None;
        match (mlp, self.shader.as_mut()) {
            (None, _) => self.shader = None,
            (Some(m), Some((held, gpu))) if gpu.same_shape(m) => {
                gpu.update(self.renderer.ctx(), m)?;
                *held = m.clone();
            }
            (Some(m), _) => {
                self.shader = None;
                let gpu = GpuShader::new(self.renderer.ctx(), m)?;
                self.shader = Some((m.clone(), gpu));
            }
        }
        Ok(())
    }

    /// The neural shader set, if any.
    pub fn shader(&self) -> Option<&Mlp> {
        self.shader.as_ref().map(|(m, _)| m)
    }

    fn check(
        params: &SplatParams<f32>,
        cam: &Camera,
        opts: &RenderOptions,
        shader: Option<&Mlp>,
    ) -> GpuResult<()> {
        params.validate().map_err(GpuError::InvalidArgument)?;
        opts.validate().map_err(GpuError::InvalidArgument)?;
        cam.validate()
            .map_err(|e| GpuError::InvalidArgument(e.to_string()))?;
        if let Some(mlp) = shader {
            match params.colors {
                ColorParams::Direct { channels, .. } => mlp
                    .check_channels(channels)
                    .map_err(GpuError::InvalidArgument)?,
                ColorParams::Sh { .. } => {
                    return Err(GpuError::InvalidArgument(
                        "a neural shader reads direct feature values, not SH coefficients".into(),
                    ))
                }
            }
        }
        if let ColorParams::Direct { channels, .. } = params.colors {
            let max = 4 * crate::gpu::shader_set::MAX_FEATURE_GROUPS as usize;
            if channels > max && (channels != 3 || shader.is_some()) {
                return Err(GpuError::InvalidArgument(format!(
                    "colours of {channels} direct channels: the device differentiates at most \
                     {max}; use the CPU reference"
                )));
            }
        }
        if opts.antialiased {
            return Err(GpuError::InvalidArgument(
                "the backward pass does not support the antialiased opacity compensation".into(),
            ));
        }
        Ok(())
    }

    /// Renders `params` from `cam` and keeps the frame's state for [`Self::backward`].
    /// Returns the frame and a token naming this forward pass.
    pub fn forward(
        &mut self,
        params: &SplatParams<f32>,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> GpuResult<(Frame, u64)> {
        Self::check(params, cam, opts, self.shader())?;
        self.last = None;
        let shaded = self.shader.is_some();
        let activated = if shaded {
            params.to_activated()
        } else {
            device_params(params).to_activated()
        };
        let scene = self.renderer.upload(&activated)?;
        let (frame, features) = if let Some((_, gpu)) = &self.shader {
            let features = self.renderer.upload_features(&activated)?;
            let frame = self
                .renderer
                .render_shaded(&scene, &features, gpu, cam, opts)?;
            (frame, Some(features))
        } else if as_features(params, false).is_some() {
            if opts.background != [0.0; 3] {
                return Err(GpuError::InvalidArgument(
                    "feature channels are blended without a background on the device".into(),
                ));
            }
            let features = self.renderer.upload_features(&activated)?;
            let frame = self
                .renderer
                .render_features(&scene, &features, cam, opts)?;
            (frame, Some(features))
        } else {
            (self.renderer.render(&scene, cam, opts)?, None)
        };
        // The feature upload is the forward's only (the backward uploads its own values).
        drop(features);
        if self.renderer.forward_state()?.last_contributor.is_none() {
            return Err(GpuError::DeviceLimit {
                limit: "maxStorageBufferRange",
                needed: 0,
                max: 0,
                message: format!(
                    "the {}x{} frame of {} Gaussians is too large to render in one piece, \
                     which the backward pass needs; render it smaller",
                    cam.width,
                    cam.height,
                    params.len()
                ),
            });
        }
        let token = self.next_token;
        self.next_token += 1;
        self.last = Some(Forward {
            token,
            frame: frame.clone(),
            scene,
        });
        Ok((frame, token))
    }

    /// Per Gaussian, the last forward pass's projection: 2D mean, conic, opacity, colour,
    /// depth and radius (0: culled).
    pub fn projected(&self) -> GpuResult<Vec<Splat>> {
        let last = self
            .last
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("no forward pass yet".into()))?;
        let state = self.renderer.forward_state()?;
        state
            .splats
            .buffer
            .read(self.renderer.ctx(), last.scene.len() as usize)
    }

    /// The gradients of a loss with respect to `params` from its gradients with respect to
    /// the frame's pixels. `token` names the forward pass of `params`, `cam` and `opts`:
    /// when it was the last one, its saved state is used; otherwise the frame is rendered
    /// again first (same result: the forward pass is deterministic). With a shader set,
    /// use [`Self::backward_shaded`].
    pub fn backward(
        &mut self,
        params: &SplatParams<f32>,
        cam: &Camera,
        opts: &RenderOptions,
        token: u64,
        grads: &PixelGrads<f32>,
    ) -> GpuResult<SplatGrads<f32>> {
        if self.shader.is_some() {
            return Err(GpuError::InvalidArgument(
                "a neural shader is set: backward_shaded returns its gradients too".into(),
            ));
        }
        self.backward_any(params, cam, opts, token, grads)
            .map(|(g, _)| g)
    }

    /// [`Self::backward`] of a shaded frame ([`Self::set_shader`]): `grads.color` is
    /// dL/d(the shaded colour, 3 channels per pixel). Returns the Gaussians' gradients
    /// (`colors`: dL/d(feature values)) and the shader's.
    pub fn backward_shaded(
        &mut self,
        params: &SplatParams<f32>,
        cam: &Camera,
        opts: &RenderOptions,
        token: u64,
        grads: &PixelGrads<f32>,
    ) -> GpuResult<(SplatGrads<f32>, MlpParams<f32>)> {
        if self.shader.is_none() {
            return Err(GpuError::InvalidArgument(
                "no neural shader is set (set_shader)".into(),
            ));
        }
        let (g, mlp) = self.backward_any(params, cam, opts, token, grads)?;
        Ok((
            g,
            mlp.expect("a shaded backward pass returns the shader's gradients"),
        ))
    }

    fn backward_any(
        &mut self,
        params: &SplatParams<f32>,
        cam: &Camera,
        opts: &RenderOptions,
        token: u64,
        grads: &PixelGrads<f32>,
    ) -> GpuResult<(SplatGrads<f32>, Option<MlpParams<f32>>)> {
        if !matches!(&self.last, Some(l) if l.token == token) {
            self.forward(params, cam, opts)?;
        }
        let last = self.last.as_ref().expect("a forward pass just ran");
        if last.scene.len() as usize != params.len() {
            return Err(GpuError::InvalidArgument(format!(
                "the backward pass got {} Gaussians, its forward pass {}",
                params.len(),
                last.scene.len()
            )));
        }
        let features = as_features(params, self.shader.is_some());
        let (mut g, mlp_grads) = match (&self.shader, features) {
            (Some((mlp, gpu)), Some(features)) => {
                let (g, flat) = self.renderer.backward_shaded(
                    &last.scene,
                    features,
                    gpu,
                    cam,
                    opts.background,
                    &last.frame,
                    grads,
                )?;
                let m = MlpParams::from_flat(mlp, &flat).map_err(GpuError::Internal)?;
                (g, Some(m))
            }
            _ => (
                self.renderer
                    .backward_with_features(&last.scene, features, &last.frame, grads)?,
                None,
            ),
        };
        if let (ColorParams::Direct { .. }, None) = (&params.colors, features) {
            // Through SH degree 0 (`device_params`): dL/dc = dL/d sh0 / C0.
            let c0 = crate::model::sh::SH_C0;
            for v in g.colors.iter_mut() {
                *v /= c0;
            }
        }
        // The device differentiates with respect to the normalised quaternions q / |q|.
        for (gq, q) in g.quats.iter_mut().zip(&params.quats) {
            let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            let u = q.map(|v| v / norm);
            let dot: f32 = gq.iter().zip(&u).map(|(a, b)| a * b).sum();
            *gq = [0, 1, 2, 3].map(|k| (gq[k] - u[k] * dot) / norm);
        }
        Ok((g, mlp_grads))
    }
}
