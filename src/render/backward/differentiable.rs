//! Differentiable rendering on the device, for training loops: [`DiffRasterizer`] renders
//! Gaussians given as a trainer holds them ([`SplatParams`], gsplat's conventions) and
//! returns the gradients of a loss with respect to them. The Python package's
//! `verisplat.torch.rasterization` is built on it. With a neural shader
//! ([`DiffRasterizer::set_shader`]) the Gaussians' direct values are feature channels that
//! the shader turns into colour, and the backward pass also returns the shader's gradients.

use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::model::grad::{ColorParams, PixelGrads, SplatGrads, SplatParams};
use crate::core::model::RenderOptions;
use crate::fields::mlp::{Mlp, MlpParams};
use crate::gpu::{GpuContext, GpuError, GpuResult};
use crate::render::backward::BackwardRequest;
use crate::render::forward::shade::GpuShader;
use crate::render::forward::types::Splat;
use crate::render::{ForwardHandle, FrameRequest};
use crate::render::{GpuRenderer, GpuScene};

pub use crate::render::backward::grad_accumulate::Accumulation;

/// `frame`'s blended feature channels over `background` (`c + (1 - alpha) * bg`, what the
/// device's colour path does): direct values are blended as feature channels, whatever
/// their count, so that they are never clamped (the CPU reference's and gsplat's rule).
fn over_background(frame: &mut Frame, background: [f32; 3]) {
    if background == [0.0; 3] || frame.feature_count != 3 {
        return;
    }
    for (px, a) in frame.features.chunks_exact_mut(3).zip(&frame.alpha) {
        for (c, bg) in px.iter_mut().zip(background) {
            *c += (1.0 - a) * bg;
        }
    }
}

/// The pixel gradients of blended feature channels from those of the same channels over
/// `background` ([`over_background`]): d/d(alpha) gains `-sum(dL/dc * bg)`.
fn behind_background<'a>(
    grads: &'a PixelGrads<f32>,
    features: Option<(&[f32], usize)>,
    background: [f32; 3],
) -> std::borrow::Cow<'a, PixelGrads<f32>> {
    // Only 3 channels are blended over a background (`DiffRasterizer::forward`).
    if features.map(|(_, k)| k) != Some(3) || background == [0.0; 3] || grads.color.is_empty() {
        return std::borrow::Cow::Borrowed(grads);
    }
    let pixels = grads.color.len() / 3;
    let mut alpha = if grads.alpha.is_empty() {
        vec![0.0; pixels]
    } else {
        grads.alpha.clone()
    };
    for (a, c) in alpha.iter_mut().zip(grads.color.chunks_exact(3)) {
        *a -= c.iter().zip(background).map(|(g, bg)| g * bg).sum::<f32>();
    }
    std::borrow::Cow::Owned(PixelGrads {
        alpha,
        ..grads.clone()
    })
}

/// The last forward pass: what its backward pass needs.
struct Forward {
    token: u64,
    /// The frame's state on the device.
    handle: ForwardHandle,
    frame: Frame,
    scene: GpuScene,
}

/// The direct values of `params`, blended as feature channels (any number of them, RGB
/// too: never clamped), or None for SH coefficients.
fn as_features(params: &SplatParams<f32>) -> Option<(&[f32], usize)> {
    match &params.colors {
        ColorParams::Direct { channels, values } => Some((values.as_slice(), *channels)),
        ColorParams::Sh { .. } => None,
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

    /// Shades the frames with `mlp` (a neural shader, [`crate::fields::mlp`]) from now on, or not
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
            if channels > max {
                return Err(GpuError::InvalidArgument(format!(
                    "colours of {channels} direct channels: the device differentiates at most \
                     {max}; use the CPU reference"
                )));
            }
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
        let activated = params.to_activated();
        let scene = self.renderer.upload(&activated)?;
        let (rendered, features) = if let Some((_, gpu)) = &self.shader {
            let features = self.renderer.upload_features(&activated)?;
            let rendered = self
                .renderer
                .render(&FrameRequest::new(&scene, cam, opts).shaded(&features, gpu))?;
            (rendered, Some(features))
        } else if let Some((_, channels)) = as_features(params) {
            if opts.background != [0.0; 3] && channels != 3 {
                return Err(GpuError::InvalidArgument(format!(
                    "{channels} feature channels are blended without a background on the device"
                )));
            }
            let features = self.renderer.upload_features(&activated)?;
            let bare = RenderOptions {
                background: [0.0; 3],
                ..opts.clone()
            };
            let rendered = self
                .renderer
                .render(&FrameRequest::new(&scene, cam, &bare).features(&features))?;
            (rendered, Some(features))
        } else {
            (
                self.renderer
                    .render(&FrameRequest::new(&scene, cam, opts))?,
                None,
            )
        };
        let handle = rendered.forward();
        let frame = rendered.into_frame()?;
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
            handle,
            frame: frame.clone(),
            scene,
        });
        let mut frame = frame;
        if self.shader.is_none() {
            over_background(&mut frame, opts.background);
        }
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
        let features = as_features(params);
        let (mut g, mlp_grads) = match (&self.shader, features) {
            (Some((mlp, gpu)), Some(features)) => {
                let (values, k) = features;
                let req = BackwardRequest::new(&last.handle, &last.scene, &last.frame, grads)
                    .shaded(values, k, gpu, cam, opts.background);
                let g = self.renderer.backward(&req)?;
                let flat = g.shader.unwrap_or_default();
                let m = MlpParams::from_flat(mlp, &flat).map_err(GpuError::Internal)?;
                (g.splats, Some(m))
            }
            _ => {
                let grads = behind_background(grads, features, opts.background);
                let mut req = BackwardRequest::new(&last.handle, &last.scene, &last.frame, &grads);
                if let Some((values, k)) = features {
                    req = req.features(values, k);
                }
                (self.renderer.backward(&req)?.splats, None)
            }
        };
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
