//! The backward pass on the device: from the gradient of a loss with respect to each pixel
//! of the last frame (colour, alpha, depth) to the gradient with respect to each Gaussian's
//! parameters, reading the frame's saved forward state ([`crate::render::ForwardState`]): no
//! re-sort, no re-render. Three stages in one command buffer, each with its barrier and
//! timestamp pair, like the forward's:
//!
//! 1. blend backward (`blend_bwd`): per bin, back to front over its pairs, the pixels'
//!    gradients with respect to each pair's 2D mean, conic, opacity, colour and depth,
//!    summed over the bin in a fixed order into the pair's own slot;
//! 2. accumulation (`grad_accumulate`): each pair's sums added to its Gaussian's, in 64-bit
//!    fixed point by default, so the result does not depend on the order the device runs
//!    the pairs in: gradients are bit-identical run after run ([`Accumulation`]);
//! 3. preprocess backward (`preprocess_bwd`): the chain rule through projection,
//!    covariance and SH to centres, quaternions, scales, opacities and SH coefficients.
//!
//! A frame whose per-pair or per-pixel buffers exceed one storage binding runs the first
//! two stages in bands that fit ([`crate::render::frame::bands`]), bit-identical to one piece.
//!
//! A frame shaded by a neural shader starts with the shader's own backward pass
//! ([`shade_bwd`]), which turns the colour's gradients into the feature
//! channels' and the network's.
//!
//! The rules are those of the CPU reference [`crate::cpu::backward`], which the tests hold
//! this pass to.

pub mod blend_bwd;
mod buffers;
mod device;
pub mod differentiable;
pub mod grad_accumulate;
mod pass;
pub mod preprocess_bwd;
mod request;
pub mod shade_bwd;

use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::model::grad::{PixelGrads, SplatGrads};
use crate::core::model::sh_coeffs_for_degree;
use crate::gpu::shader_set::{GRAD_FIELDS, MAX_FEATURE_GROUPS};
use crate::gpu::{BufferSlice, GpuContext, GpuError, GpuResult, GpuTimer};
use crate::render::forward::shade::GpuShader;
use crate::render::frame::bands::Bands;
use crate::render::frame::buffers::FrameSet;
use crate::render::{
    check_binding, Falloff, ForwardHandle, ForwardState, GpuScene, LastFrame, Stage,
};
use blend_bwd::BlendBwd;
use buffers::BackwardBuffers;
pub use device::DeviceBackward;
use grad_accumulate::{Accumulation, GradAccumulate};
use pass::BackwardPass;
use preprocess_bwd::PreprocessBwd;
pub use request::{BackwardRequest, Gradients};
use shade_bwd::ShadeBwd;

/// What tells blend backward pipelines apart: bin size, whether it reads rows of texels,
/// the splat kernel, groups of four feature channels.
type BlendKey = (u32, bool, Falloff, u32);

/// Pipelines (built the first time a pass needs each), buffers (grown as frames need) and
/// the timer of the backward pass.
pub(crate) struct BackwardState {
    blend: Vec<(BlendKey, BlendBwd)>,
    accumulate: Vec<(Accumulation, GradAccumulate)>,
    /// By `float_sums + 2 lens` ([`PreprocessBwd::new`]).
    preprocess: [Option<PreprocessBwd>; 4],
    shade: Option<ShadeBwd>,
    /// The pass's buffers, grown to each pass's shape.
    buffers: BackwardBuffers,
    clock: BackwardClock,
    mode: Accumulation,
    /// Whether read-backs decode [`SplatGrads::screen`] from the per-Gaussian sums.
    screen: bool,
    /// The last pass's pixel bands and pair bands ([`crate::render::frame::bands`]).
    bands: (usize, usize),
}

/// The backward pass's timer and what it read after the last pass.
pub(super) struct BackwardClock {
    timer: GpuTimer,
    timings: Vec<(String, f64)>,
    /// First timestamp to last of the last pass, ms.
    span_ms: f64,
}

impl BackwardClock {
    /// Reads the finished pass's stage times.
    fn read(&mut self, ctx: &GpuContext) -> GpuResult<()> {
        self.timings = self.timer.read(ctx)?;
        self.span_ms = self.timer.span_ms(ctx)?;
        Ok(())
    }
}

impl BackwardState {
    fn new(ctx: &GpuContext) -> GpuResult<Self> {
        Ok(BackwardState {
            blend: Vec::new(),
            accumulate: Vec::new(),
            preprocess: Default::default(),
            shade: None,
            buffers: BackwardBuffers::default(),
            clock: BackwardClock {
                // The stages, the shader's backward pass, and a device pass's loss and step.
                timer: GpuTimer::new(ctx, "backward", Stage::BACKWARD.len() as u32)?,
                timings: Vec::new(),
                span_ms: 0.0,
            },
            mode: Accumulation::default(),
            screen: false,
            bands: (0, 0),
        })
    }

    pub(crate) fn device_bytes(&self) -> u64 {
        self.buffers.device_bytes()
    }
}

/// A backward pass's feature channels: the Gaussians' values and the pixels' gradients
/// (none when a shader's backward pass makes them), both in groups of four, and the
/// channel count.
type FeatureJob<'a> = (FeatureValues<'a>, Option<&'a [[f32; 4]]>, usize);

/// The Gaussians' feature values of a backward pass, in groups of four (a vec4 per group,
/// Gaussian-major): from the host (uploaded) or already on the device.
#[derive(Clone, Copy)]
enum FeatureValues<'a> {
    Host(&'a [[f32; 4]]),
    Device(crate::gpu::BufferSlice<'a>),
}

/// The Gaussians' gradients read back, and the neural shader's when it shaded the frame.
type HostGrads = (SplatGrads<f32>, Option<Vec<f32>>);

/// A backward pass's pixel gradients from the host, uploaded: dL/d(colour, alpha) as a
/// vec4 per pixel and dL/d(the depth-normalised sums) per pixel.
#[derive(Clone, Copy)]
struct HostPixels<'a> {
    color: &'a [[f32; 4]],
    depth: &'a [f32],
}

/// A backward pass's results on the device ([`GpuRenderer::device_backward`]).
#[derive(Clone, Copy)]
pub struct DeviceGrads<'a> {
    /// Per Gaussian four vec4: (dL/d centre, dL/d opacity), dL/d normalised quaternion,
    /// (dL/d scales, 0), (dL/d 2D mean in pixels, |dL/d 2D mean| summed per pixel).
    pub grads: crate::gpu::BufferSlice<'a>,
    /// dL/d SH coefficient, in the SH texels' layout (floats).
    pub sh_grads: crate::gpu::BufferSlice<'a>,
    /// The forward pass's projected Gaussians (`Splat`: radius in `color_radius.w`).
    pub splats: crate::gpu::BufferSlice<'a>,
    /// dL/d feature channel, a vec4 per group of four, Gaussian-major (feature frames).
    pub feature_grads: crate::gpu::BufferSlice<'a>,
    /// The neural shader's gradients in its words' float layout (shaded frames).
    pub mlp_grads: Option<crate::gpu::BufferSlice<'a>>,
}

/// The feature channels of a frame whose backward pass runs on the device
/// ([`GpuRenderer::device_backward`]): the Gaussians' values (a vec4 per group of four,
/// Gaussian-major), their count per Gaussian, and the neural shader that shaded them with
/// its camera and background.
#[derive(Clone, Copy)]
pub struct DeviceFeatures<'a> {
    /// The values.
    pub values: crate::gpu::BufferSlice<'a>,
    /// Channels per Gaussian.
    pub channels: usize,
    /// The shader.
    pub shader: &'a GpuShader,
    /// The frame's camera.
    pub cam: &'a Camera,
    /// The frame's background.
    pub background: [f32; 3],
}

/// The neural shader of a shaded frame, its camera and background.
#[derive(Clone, Copy)]
struct ShadeJob<'a> {
    shader: &'a GpuShader,
    cam: &'a Camera,
    background: [f32; 3],
}

/// `ceil(log2(n))` for n >= 1: the bits a count of at most `n` needs.
fn bits_for(n: u64) -> u32 {
    64 - n.max(1).saturating_sub(1).leading_zeros()
}

/// The renderer's last finished frame as a backward pass reads it: the frame sets and
/// which of them holds the frame ([`LastFrame`]: its set, serial, kernel and lens).
#[derive(Clone, Copy)]
pub(crate) struct LastFrameState<'a> {
    pub(crate) sets: &'a [FrameSet],
    pub(crate) last: LastFrame,
}

impl<'a> LastFrameState<'a> {
    fn set(&self) -> (&'a FrameSet, Falloff, bool) {
        (&self.sets[self.last.set], self.last.falloff, self.last.lens)
    }
}

impl BackwardState {
    /// The state in `slot`, made the first time it is asked for.
    pub(crate) fn get<'s>(
        ctx: &GpuContext,
        slot: &'s mut Option<BackwardState>,
    ) -> GpuResult<&'s mut BackwardState> {
        if slot.is_none() {
            *slot = Some(BackwardState::new(ctx)?);
        }
        Ok(slot.as_mut().expect("made above"))
    }

    /// Sets how the passes add per-pair gradients into per-Gaussian sums.
    pub(crate) fn set_accumulation(&mut self, mode: Accumulation) {
        self.mode = mode;
    }

    /// The accumulation the passes use.
    pub(crate) fn accumulation(&self) -> Accumulation {
        self.mode
    }

    /// Sets whether read-backs also decode [`SplatGrads::screen`].
    pub(crate) fn set_screen(&mut self, on: bool) {
        self.screen = on;
    }

    /// Milliseconds of each stage of the last pass.
    pub(crate) fn timings(&self) -> &[(String, f64)] {
        &self.clock.timings
    }

    /// Milliseconds of the last pass on the device, first timestamp to last.
    pub(crate) fn total_ms(&self) -> f64 {
        self.clock.span_ms
    }

    /// The last pass's pixel bands and pair bands.
    pub(crate) fn bands(&self) -> (usize, usize) {
        self.bands
    }

    /// The backward pass `req` asks for, of the renderer's last frame `frame`, read back
    /// ([`crate::render::GpuRenderer::backward`]).
    pub(crate) fn backward(
        &mut self,
        ctx: &GpuContext,
        frame: LastFrameState,
        req: &BackwardRequest,
    ) -> GpuResult<Gradients> {
        let Some((pixels, grads)) = req.pixels else {
            return Err(GpuError::InvalidArgument(
                "a backward pass read back takes the pixels' gradients from the host \
                 (BackwardRequest::new); one recorded on the device is device_backward's"
                    .into(),
            ));
        };
        if req.device_features.is_some() {
            return Err(GpuError::InvalidArgument(
                "feature values on the device are for a pass recorded on the device \
                 (device_backward); give the host's with BackwardRequest::features or shaded"
                    .into(),
            ));
        }
        let size = (pixels.width, pixels.height);
        check_forward(frame.last, req.forward, size)?;
        let shade = match req.shader {
            Some((shader, cam, background)) => {
                let channels = req.features.map_or(0, |(_, k)| k);
                check_shaded(ctx, shader, channels, cam, size)?;
                Some(ShadeJob {
                    shader,
                    cam,
                    background,
                })
            }
            None => None,
        };
        let (splats, shader) =
            self.backward_inner(ctx, frame, req.scene, req.features, shade, pixels, grads)?;
        Ok(Gradients {
            splats,
            shader: req.shader.map(|_| shader.unwrap_or_default()),
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn backward_inner(
        &mut self,
        ctx: &GpuContext,
        frame_state: LastFrameState,
        scene: &GpuScene,
        features: Option<(&[f32], usize)>,
        shade: Option<ShadeJob>,
        frame: &Frame,
        grads: &PixelGrads<f32>,
    ) -> GpuResult<(SplatGrads<f32>, Option<Vec<f32>>)> {
        let channels = features.map_or(3, |(_, k)| k);
        // The pixels' colour gradients: the shaded colour's 3 channels, or the blend's.
        let pixel_channels = if shade.is_some() { 3 } else { channels };
        if let Some((values, k)) = features {
            check_feature_channels(k)?;
            if values.len() != scene.count as usize * k {
                return Err(GpuError::InvalidArgument(format!(
                    "{} feature values for {} Gaussians of {k} channels",
                    values.len(),
                    scene.count
                )));
            }
        }
        check_full_precision(scene)?;
        let (w, h) = (frame.width as usize, frame.height as usize);
        let pixels = w * h;
        for (name, len, want) in [
            ("colour", grads.color.len(), pixels * pixel_channels),
            ("alpha", grads.alpha.len(), pixels),
            ("depth", grads.depth.len(), pixels),
        ] {
            if len != 0 && len != want {
                return Err(GpuError::InvalidArgument(format!(
                    "the {name} gradient has {len} values for a {w}x{h} frame (want {want})"
                )));
            }
        }
        for (name, v) in [
            ("colour", &grads.color),
            ("alpha", &grads.alpha),
            ("depth", &grads.depth),
        ] {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(GpuError::InvalidArgument(format!(
                    "the {name} gradient holds {} at value {i}; pixel gradients must be finite",
                    v[i]
                )));
            }
        }
        if frame.alpha.len() != pixels || frame.depth.len() != pixels {
            return Err(GpuError::InvalidArgument(
                "the frame given to the backward pass has no alpha or depth".into(),
            ));
        }
        // dL/d colour and dL/d alpha per pixel; the depth (D / alpha, D = sum depth * w)
        // passes dL/dD = g / alpha and -g depth / alpha to alpha.
        let mut grad_color = vec![[0f32; 4]; pixels];
        let mut grad_depth = vec![0f32; pixels];
        let groups = channels.div_ceil(4);
        let mut grad_features = vec![
            [0f32; 4];
            if features.is_some() && shade.is_none() {
                pixels * groups
            } else {
                0
            }
        ];
        for i in 0..pixels {
            let mut g = [0f32; 4];
            if !grads.color.is_empty() {
                if features.is_some() && shade.is_none() {
                    for c in 0..channels {
                        grad_features[i * groups + c / 4][c % 4] = grads.color[i * channels + c];
                    }
                } else {
                    g[..3].copy_from_slice(&grads.color[i * 3..i * 3 + 3]);
                }
            }
            if !grads.alpha.is_empty() {
                g[3] = grads.alpha[i];
            }
            if !grads.depth.is_empty() && frame.alpha[i] > 0.0 {
                let a = frame.alpha[i];
                grad_depth[i] = grads.depth[i] / a;
                g[3] -= grads.depth[i] * frame.depth[i] / a;
            }
            grad_color[i] = g;
        }
        // The Gaussians' feature values, in groups of four.
        let feature_values: Option<Vec<[f32; 4]>> = features.map(|(values, k)| {
            let mut packed = vec![[0f32; 4]; scene.count as usize * groups];
            for (i, row) in values.chunks_exact(k).enumerate() {
                for (c, v) in row.iter().enumerate() {
                    packed[i * groups + c / 4][c % 4] = *v;
                }
            }
            packed
        });
        let pixel_feature_grads = shade.is_none().then_some(&grad_features[..]);
        let feature_job = feature_values
            .as_deref()
            .map(|v| (FeatureValues::Host(v), pixel_feature_grads, channels));
        self.run_backward(
            ctx,
            frame_state,
            scene,
            (frame.width, frame.height),
            HostPixels {
                color: &grad_color,
                depth: &grad_depth,
            },
            feature_job,
            shade,
        )
    }

    /// The backward pass `req` asks for, recorded by the caller on the device
    /// ([`crate::render::GpuRenderer::device_backward`]).
    pub(crate) fn device_backward<'r>(
        &'r mut self,
        ctx: &'r GpuContext,
        frame: LastFrameState<'r>,
        req: &BackwardRequest<'r>,
    ) -> GpuResult<DeviceBackward<'r>> {
        if req.pixels.is_some() || req.features.is_some() {
            return Err(GpuError::InvalidArgument(
                "a backward pass recorded on the device takes its pixels' gradients and \
                 feature values on the device (BackwardRequest::recorded, \
                 shaded_on_device); one from the host is backward's"
                    .into(),
            ));
        }
        let (scene, features) = (req.scene, req.device_features);
        let size = req.forward.size();
        check_forward(frame.last, req.forward, size)?;
        if let Some(f) = &features {
            check_feature_channels(f.channels)?;
            check_shaded(ctx, f.shader, f.channels, f.cam, size)?;
        }
        check_full_precision(scene)?;
        let (pass, clock, _) = prepare(
            ctx,
            self,
            frame.set(),
            scene,
            size,
            None,
            features.map(|f| (FeatureValues::Device(f.values), None, f.channels)),
            features.map(|f| ShadeJob {
                shader: f.shader,
                cam: f.cam,
                background: f.background,
            }),
        )?;
        Ok(DeviceBackward::new(ctx, pass, clock))
    }

    /// A backward pass with the pixels' gradients from the host, read back.
    #[allow(clippy::too_many_arguments)]
    fn run_backward(
        &mut self,
        ctx: &GpuContext,
        frame: LastFrameState,
        scene: &GpuScene,
        size: (u32, u32),
        pixels: HostPixels,
        features: Option<FeatureJob>,
        shade: Option<ShadeJob>,
    ) -> GpuResult<HostGrads> {
        let (pass, clock, shape) = prepare(
            ctx,
            self,
            frame.set(),
            scene,
            size,
            Some(pixels),
            features,
            shade,
        )?;
        ctx.submit_and_wait("backward", |cmd| {
            pass.open(ctx, cmd, &mut clock.timer);
            pass.record_stages(ctx, cmd, &mut clock.timer)?;
            pass.close(ctx, cmd);
            Ok(())
        })?;
        clock.read(ctx)?;
        self.read_back(ctx, scene, &shape, features, shade)
    }
}

/// Refuses a compact upload: the backward pass reads full-precision Gaussians.
fn check_full_precision(scene: &GpuScene) -> GpuResult<()> {
    if scene.compact {
        return Err(GpuError::InvalidArgument(
            "the backward pass needs a full-precision upload, not a compact one".into(),
        ));
    }
    Ok(())
}

/// Refuses a forward handle that is not the renderer's last finished frame (`last`: a
/// later frame replaced its state) or is not `size`.
fn check_forward(last: LastFrame, forward: &ForwardHandle, size: (u32, u32)) -> GpuResult<()> {
    if forward.frame.serial != last.serial {
        return Err(GpuError::InvalidArgument(
            "the frame of this forward handle is no longer the renderer's last: its state \
             was replaced by a later frame's"
                .into(),
        ));
    }
    if forward.size() != size {
        return Err(GpuError::InvalidArgument(format!(
            "the forward handle's frame is {}x{}, the frame given {}x{}",
            forward.width, forward.height, size.0, size.1
        )));
    }
    Ok(())
}

/// Refuses a shaded frame's backward pass that the shader, the camera (`size` the
/// frame's) or the device's loop limit cannot run.
fn check_shaded(
    ctx: &GpuContext,
    shader: &GpuShader,
    channels: usize,
    cam: &Camera,
    size: (u32, u32),
) -> GpuResult<()> {
    if shader.channels() != channels {
        return Err(GpuError::InvalidArgument(format!(
            "the shader takes {} feature channels but the Gaussians have {channels}",
            shader.channels()
        )));
    }
    if (cam.width, cam.height) != size {
        return Err(GpuError::InvalidArgument(format!(
            "the camera is {}x{}, the frame {}x{}",
            cam.width, cam.height, size.0, size.1
        )));
    }
    if ctx.info().loop_limited()
        && shader.backward_iterations > u64::from(crate::render::CPU_LOOP_LIMIT)
    {
        return Err(GpuError::DeviceLimit {
            limit: "llvmpipe's loop iterations per invocation",
            needed: shader.backward_iterations,
            max: u64::from(crate::render::CPU_LOOP_LIMIT),
            message: format!(
                "the neural shader's backward pass needs {} loop iterations per pixel, but {} ends every shader invocation's loops after {} iterations; use narrower layers, or the CPU reference",
                shader.backward_iterations,
                ctx.info().name,
                crate::render::CPU_LOOP_LIMIT
            ),
        });
    }
    Ok(())
}

/// A pass over the last frame of `set` (rendered with `kernel`): the pipelines and buffers
/// it needs made in `st` (the pixels' gradients uploaded when the host gives them), and
/// resolved for recording, with `st`'s clock and the pass's shape.
#[allow(clippy::too_many_arguments)]
fn prepare<'a>(
    ctx: &'a GpuContext,
    st: &'a mut BackwardState,
    (set, falloff, lens): (&'a FrameSet, Falloff, bool),
    scene: &'a GpuScene,
    size: (u32, u32),
    pixels: Option<HostPixels>,
    features: Option<FeatureJob<'a>>,
    shade: Option<ShadeJob<'a>>,
) -> GpuResult<(BackwardPass<'a>, &'a mut BackwardClock, PassShape)> {
    let groups = features.map_or(0, |(_, _, k)| k.div_ceil(4)) as u32;
    let (fs, last) = saved_forward(set, size)?;
    let shape = PassShape::new(ctx, scene, size, &fs, groups)?;
    if shape.bands.pixels_split() && (pixels.is_none() || shade.is_some()) {
        // The training step's loss and the shader's backward pass bind whole frames: the
        // largest per-pixel buffer, which split the pass, is refused.
        let what = match shade {
            Some(_) => "a shaded frame's",
            None => "a training frame's",
        };
        let (name, bytes) = pixel_element(groups);
        crate::gpu::limits::check_binding(
            ctx.info(),
            &format!("{what} {name}"),
            shape.pixels * bytes,
            "use a smaller frame",
        )?;
    }
    let pipelines = st.build_pipelines(ctx, &fs, (falloff, lens), groups)?;
    st.ensure_buffers(ctx, &shape, pixels, features)?;
    let feature_planes = match shade {
        Some(job) => Some(st.ensure_shade_buffers(ctx, job, shape.pixels, &fs)?),
        None => None,
    };
    check_binding(ctx, "Gaussians", scene.gaussians.size())?;
    st.bands = (
        shape.bands.row_bands().len(),
        shape.bands.pair_bands().len(),
    );
    let (pass, clock) = BackwardPass::resolve(
        st,
        fs,
        scene,
        last,
        shape,
        pipelines,
        features,
        shade.zip(feature_planes),
    );
    Ok((pass, clock, shape))
}

/// The saved forward state of `set`'s last frame and its last contributors, refused when
/// the frame saved none or is not `size`.
fn saved_forward(
    set: &FrameSet,
    size: (u32, u32),
) -> GpuResult<(ForwardState<'_>, BufferSlice<'_>)> {
    let fs = set.forward_state()?;
    let last = fs.last_contributor.ok_or_else(|| {
        GpuError::InvalidArgument(
            "the last frame saved no forward state: render it with \
             set_save_forward_state(true), in one piece, right before the backward pass"
                .into(),
        )
    })?;
    let fb = set
        .frame
        .as_ref()
        .ok_or_else(|| GpuError::Internal("no frame buffers for a finished frame".into()))?;
    if (fb.width, fb.height) != size {
        return Err(GpuError::InvalidArgument(format!(
            "the frame given is {}x{}, the last frame rendered {}x{}",
            size.0, size.1, fb.width, fb.height
        )));
    }
    Ok((fs, last))
}

/// The sizes of one backward pass.
#[derive(Clone, Copy)]
struct PassShape {
    /// Gaussians.
    n: u64,
    /// Groups of four feature channels (0: an SH frame).
    groups: u32,
    /// vec4s of gradients per pair.
    vecs: u32,
    /// Gradient fields per pair.
    fields: u64,
    /// Bits of a bin index.
    bits: u32,
    /// Floats of SH texels per Gaussian.
    sh_floats: u64,
    /// Pixels of the frame.
    pixels: u64,
    /// Width and height of the frame.
    width: u32,
    height: u32,
    /// How the per-pair and per-pixel buffers are split to fit one binding.
    bands: Bands,
}

/// The largest per-pixel element of a pass of `groups` groups of four feature channels,
/// named: a colour gradient (vec4), or the pixel's feature gradients (a vec4 per group).
fn pixel_element(groups: u32) -> (&'static str, u64) {
    match groups {
        0 | 1 => ("pixel colour gradients", 16),
        g => ("pixel feature gradients", 16 * u64::from(g)),
    }
}

impl PassShape {
    fn new(
        ctx: &GpuContext,
        scene: &GpuScene,
        size: (u32, u32),
        fs: &ForwardState,
        groups: u32,
    ) -> GpuResult<Self> {
        let bins = fs.bins;
        let fields = u64::from(GRAD_FIELDS + 4 * groups);
        let pairs = u64::from(fs.pairs);
        let pixel = pixel_element(groups);
        let max = crate::gpu::limits::storage_binding_bytes(ctx.info());
        Ok(PassShape {
            n: scene.count as u64,
            groups,
            vecs: 3 + groups,
            fields,
            bits: bits_for(u64::from(bins.0) * u64::from(bins.1)),
            sh_floats: u64::from(crate::render::sh_texel_stride(scene.sh_degree)) * 4,
            pixels: u64::from(size.0) * u64::from(size.1),
            width: size.0,
            height: size.1,
            bands: Bands::plan(max, pairs, fields * 4, size, pixel)?,
        })
    }
}

impl BackwardState {
    /// Builds the pipelines the pass needs that no earlier pass built (`lens`: the frame
    /// was drawn through a lens other than the pinhole); returns the blend backward's key,
    /// whether it reads rows of texels, and the preprocess backward's index.
    fn build_pipelines(
        &mut self,
        ctx: &GpuContext,
        fs: &ForwardState,
        (falloff, lens): (Falloff, bool),
        groups: u32,
    ) -> GpuResult<(BlendKey, bool, usize)> {
        let float_sums = self.mode != Accumulation::Deterministic;
        // Pipelines, the first time a pass needs each.
        let rows = BlendBwd::rows_for(ctx, fs.bin_size, fs.value_texels.is_some());
        let blend_key = (fs.bin_size, rows, falloff, groups);
        if !self.blend.iter().any(|(k, _)| *k == blend_key) {
            self.blend.push((
                blend_key,
                BlendBwd::new(ctx, fs.bin_size, rows, falloff, groups)?,
            ));
        }
        if !self.accumulate.iter().any(|(m, _)| *m == self.mode) {
            if self.mode == Accumulation::FloatAtomics && !ctx.info().float_atomic_add {
                return Err(GpuError::InvalidArgument(format!(
                    "{} has no float atomic add (shaderBufferFloat32AtomicAdd); use the \
                     compare-and-swap or the deterministic accumulation",
                    ctx.info().name
                )));
            }
            self.accumulate
                .push((self.mode, GradAccumulate::new(ctx, self.mode)?));
        }
        let p = usize::from(float_sums) + 2 * usize::from(lens);
        if self.preprocess[p].is_none() {
            self.preprocess[p] = Some(PreprocessBwd::new(ctx, float_sums, lens)?);
        }
        Ok((blend_key, rows, p))
    }

    /// Makes or grows the gradient buffers for `shape` and uploads what the host gives:
    /// the pixels' gradients, the feature values and the pixels' feature gradients.
    fn ensure_buffers(
        &mut self,
        ctx: &GpuContext,
        shape: &PassShape,
        pixels: Option<HostPixels>,
        features: Option<FeatureJob>,
    ) -> GpuResult<()> {
        self.buffers.ensure(ctx, shape)?;
        let b = &self.buffers;
        if let Some(HostPixels { color, depth }) = pixels {
            b.grad_color
                .as_ref()
                .expect("made above")
                .upload(ctx, color)?;
            b.grad_depth
                .as_ref()
                .expect("made above")
                .upload(ctx, depth)?;
        }
        if let Some((FeatureValues::Host(values), _, _)) = features {
            b.features
                .as_ref()
                .expect("made above")
                .upload(ctx, values)?;
        }
        if let Some((_, Some(pixel_grads), _)) = features {
            let grad_features = b.grad_features.as_ref().expect("made above");
            grad_features.upload(ctx, pixel_grads)?;
        }
        Ok(())
    }

    /// The shader's backward pass: its pipeline, the frame's alpha in, scratch and partial
    /// sums; returns the forward's feature planes it reads.
    fn ensure_shade_buffers<'f>(
        &mut self,
        ctx: &GpuContext,
        job: ShadeJob,
        pixels: u64,
        fs: &ForwardState<'f>,
    ) -> GpuResult<(BufferSlice<'f>, u32)> {
        if !self.shade.as_ref().is_some_and(|s| s.fits(job.shader)) {
            self.shade = Some(ShadeBwd::for_shader(ctx, job.shader)?);
        }
        self.buffers.ensure_shader(ctx, job.shader, pixels)?;
        fs.feature_planes.ok_or_else(|| {
            GpuError::InvalidArgument(
                "the last frame blended no feature channels: render it with a shader (FrameRequest::shaded) \
                 right before the backward pass"
                    .into(),
            )
        })
    }

    /// Reads the pass's gradients back and lays them out as the uploaded scene.
    fn read_back(
        &self,
        ctx: &GpuContext,
        scene: &GpuScene,
        shape: &PassShape,
        features: Option<FeatureJob>,
        shade: Option<ShadeJob>,
    ) -> GpuResult<HostGrads> {
        let (groups, sh_floats) = (shape.groups, shape.sh_floats);
        let (grads, sh_grads, feature_grads) = (
            self.buffers.grads.as_ref().expect("made above"),
            self.buffers.sh_grads.as_ref().expect("made above"),
            self.buffers.feature_grads.as_ref().expect("made above"),
        );
        // Read back and lay out as the uploaded scene.
        let n = shape.n as usize;
        let raw: Vec<[f32; 16]> = grads.read(ctx, n)?;
        let sh_raw: Vec<f32> = sh_grads.read(ctx, n * sh_floats as usize)?;
        let k = match features {
            Some((_, _, channels)) => channels,
            None => sh_coeffs_for_degree(scene.sh_degree) * 3,
        };
        let mut out = SplatGrads::zeros(n, k);
        let mlp = match (shade, self.buffers.mlp_grads.as_ref()) {
            (Some(job), Some(b)) => Some(b.read(ctx, job.shader.params as usize)?),
            _ => None,
        };
        let feature_raw: Vec<[f32; 4]> = match features {
            Some(_) => feature_grads.read(ctx, n * groups as usize)?,
            None => Vec::new(),
        };
        if self.screen {
            self.read_screen(ctx, shape, features.is_none(), &mut out.screen)?;
        }
        for (i, g) in raw.iter().enumerate() {
            out.means[i] = [g[0], g[1], g[2]];
            out.opacities[i] = g[3];
            out.quats[i] = [g[4], g[5], g[6], g[7]];
            out.scales[i] = [g[8], g[9], g[10]];
            out.means2d[i] = [g[12], g[13]];
            out.absgrad[i] = [g[14], g[15]];
            if features.is_some() {
                for c in 0..k {
                    out.colors[i * k + c] = feature_raw[i * groups as usize + c / 4][c % 4];
                }
            } else {
                let src = &sh_raw[i * sh_floats as usize..i * sh_floats as usize + k];
                out.colors[i * k..(i + 1) * k].copy_from_slice(src);
            }
        }
        Ok((out, mlp))
    }
}

impl BackwardState {
    /// [`SplatGrads::screen`] from the per-Gaussian sums of the pass (as
    /// `preprocess_bwd.comp`'s `field` decodes them): conic (fields 2-4), colour (6-8, an
    /// SH frame's only), depth (9) and the blended opacity (5).
    fn read_screen(
        &self,
        ctx: &GpuContext,
        shape: &PassShape,
        sh_frame: bool,
        out: &mut [[f32; 8]],
    ) -> GpuResult<()> {
        let (maxima, acc) = (
            self.buffers.maxima.as_ref().expect("made by the pass"),
            self.buffers.acc.as_ref().expect("made by the pass"),
        );
        let fields = shape.fields as usize;
        let maxima: Vec<u32> = maxima.read(ctx, fields)?;
        let acc: Vec<[u32; 2]> = acc.read(ctx, shape.n as usize * fields)?;
        let float_sums = self.mode != Accumulation::Deterministic;
        let field = |g: usize, f: usize| -> f32 {
            let [lo, hi] = acc[g * fields + f];
            if float_sums {
                return f32::from_bits(lo);
            }
            fixed_to_f32(lo, hi, grad_shift(maxima[f], shape.bits))
        };
        let colour = |g: usize, f: usize| if sh_frame { field(g, f) } else { 0.0 };
        for (g, o) in out.iter_mut().enumerate() {
            *o = [
                field(g, 2),
                field(g, 3),
                field(g, 4),
                colour(g, 6),
                colour(g, 7),
                colour(g, 8),
                field(g, 9),
                field(g, 5),
            ];
        }
        Ok(())
    }
}

/// `grad_common.glsl`'s `grad_shift`: the scale exponent of a field whose largest
/// |partial| has the float bits `max_bits`.
fn grad_shift(max_bits: u32, bits: u32) -> i32 {
    let m = f32::from_bits(max_bits);
    // frexp's exponent: |m| < 2^e (0 for 0).
    let e = if m == 0.0 {
        0
    } else {
        ((m.to_bits() >> 23) & 0xff) as i32 - 126
    };
    (62 - bits as i32 - e).clamp(-200, 250)
}

/// `grad_common.glsl`'s `from_fixed`: the (lo, hi) two's-complement pair times 2^-s.
fn fixed_to_f32(lo: u32, hi: u32, s: i32) -> f32 {
    let v = ((u64::from(hi) << 32) | u64::from(lo)) as i64;
    (v as f64 * 2f64.powi(-s)) as f32
}

/// Refuses feature channels the backward pass cannot differentiate.
fn check_feature_channels(k: usize) -> GpuResult<()> {
    let max = 4 * MAX_FEATURE_GROUPS as usize;
    if k == 0 || k > max {
        return Err(GpuError::InvalidArgument(format!(
            "the backward pass differentiates 1 to {max} feature channels, not {k}"
        )));
    }
    Ok(())
}

pub(crate) fn pixels_bytes(count: usize, each: u64) -> u64 {
    count as u64 * each
}
