//! What a backward pass differentiates ([`BackwardRequest`]) and what one read back returns
//! ([`Gradients`]): the one request the backward takes, read back
//! ([`crate::render::GpuRenderer::backward`]) or recorded on the device
//! ([`crate::render::GpuRenderer::device_backward`]), as the forward's
//! [`crate::render::FrameRequest`] is rendered or submitted.

use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::model::grad::{PixelGrads, SplatGrads};
use crate::render::backward::DeviceFeatures;
use crate::render::forward::shade::GpuShader;
use crate::render::{ForwardHandle, GpuScene};

/// A backward pass of the renderer's last frame: the frame's handle and the scene it
/// rendered, and the pixels' gradients: from the host ([`Self::new`]: the frame as it was
/// returned, whose alpha and depth turn a depth gradient into the sums the pass walks,
/// and dL/d(each pixel); read back by [`crate::render::GpuRenderer::backward`]) or
/// recorded on the device by the caller ([`Self::recorded`], for
/// [`crate::render::GpuRenderer::device_backward`]). By default of a frame of SH colour,
/// or, with [`Self::features`], of one that blended feature channels, or, with
/// [`Self::shaded`] (on the device: [`Self::shaded_on_device`]), one whose features a
/// neural shader turned into its colour.
#[derive(Clone, Copy)]
pub struct BackwardRequest<'a> {
    /// The frame's handle ([`crate::render::Rendered::forward`]).
    pub forward: &'a ForwardHandle,
    /// The uploaded scene the frame rendered.
    pub scene: &'a GpuScene,
    /// The frame as the renderer returned it and dL/d(each pixel): `color` has 3 channels
    /// per pixel (or the feature channels of a features frame), `alpha` and `depth` one;
    /// an empty plane has no gradient. `None`: the caller records them on the device.
    pub pixels: Option<(&'a Frame, &'a PixelGrads<f32>)>,
    /// The Gaussians' blended feature values and their channels per Gaussian (at most 16),
    /// Gaussian-major; `None` for SH colour.
    pub features: Option<(&'a [f32], usize)>,
    /// The neural shader that shaded the features, the frame's camera and background.
    pub shader: Option<(&'a GpuShader, &'a Camera, [f32; 3])>,
    /// A pass recorded on the device: the feature values on the device and the neural
    /// shader that shaded them.
    pub device_features: Option<DeviceFeatures<'a>>,
}

impl<'a> BackwardRequest<'a> {
    /// The backward pass of a frame of SH colour, with the pixels' gradients from the host.
    pub fn new(
        forward: &'a ForwardHandle,
        scene: &'a GpuScene,
        frame: &'a Frame,
        grads: &'a PixelGrads<f32>,
    ) -> Self {
        BackwardRequest {
            pixels: Some((frame, grads)),
            ..Self::recorded(forward, scene)
        }
    }

    /// The backward pass of a frame of SH colour whose pixels' gradients the caller
    /// records on the device ([`crate::render::GpuRenderer::device_backward`]).
    pub fn recorded(forward: &'a ForwardHandle, scene: &'a GpuScene) -> Self {
        BackwardRequest {
            forward,
            scene,
            pixels: None,
            features: None,
            shader: None,
            device_features: None,
        }
    }

    /// Of a frame whose feature channels (values on the device) a neural shader turned
    /// into its colour ([`DeviceFeatures`]), in a pass recorded on the device.
    pub fn shaded_on_device(self, features: DeviceFeatures<'a>) -> Self {
        BackwardRequest {
            device_features: Some(features),
            ..self
        }
    }

    /// Of a frame that blended `k` feature channels per Gaussian (`values`, Gaussian-major)
    /// instead of its SH colour, with no background: `grads.color` holds `k` channels per
    /// pixel, and the returned `colors` are dL/d(feature values), `k` per Gaussian.
    pub fn features(self, values: &'a [f32], k: usize) -> Self {
        BackwardRequest {
            features: Some((values, k)),
            ..self
        }
    }

    /// Of a frame whose `k` feature channels (`values`) `shader` turned into its colour
    /// from `cam` over `background` (the options' background): `grads.color` is dL/d(the
    /// shaded colour, 3 channels); the network's gradients come back too.
    pub fn shaded(
        self,
        values: &'a [f32],
        k: usize,
        shader: &'a GpuShader,
        cam: &'a Camera,
        background: [f32; 3],
    ) -> Self {
        BackwardRequest {
            features: Some((values, k)),
            shader: Some((shader, cam, background)),
            ..self
        }
    }
}

/// What a backward pass returns.
#[derive(Clone, Debug)]
pub struct Gradients {
    /// The Gaussians' gradients in the layout of the uploaded scene: `quats` with respect
    /// to the normalised quaternions it holds, `colors` with respect to its SH
    /// coefficients (or feature values), `means2d` and `absgrad` in pixels.
    pub splats: SplatGrads<f32>,
    /// A shaded frame's network gradients, in the float layout of its weights
    /// ([`crate::fields::mlp::Mlp::gpu_words`] after the header: per layer the weights,
    /// row-major `outputs x inputs`, then the biases); `None` for other frames.
    pub shader: Option<Vec<f32>>,
}
