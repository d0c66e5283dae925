//! The Vulkan splatting pipeline. A frame is recorded top to bottom as
//! preprocess -> order -> scan -> keys -> sort -> ranges -> blend -> readback, in one
//! command buffer with a barrier between each pair of stages and a timestamp pair around
//! each stage. The frame's recording (up to the blend) is one path for every consumer;
//! only the readback differs by what the consumer needs ([`Readback`]): float colour,
//! alpha and depth for files and checks, or 8-bit RGBA packed on the device for display
//! and 8-bit colour files.
//!
//! Sorting: the reference orders each tile's Gaussians by a stable sort of
//! `tile << 32 | depth` keys emitted in Gaussian order. Here the Gaussians are first sorted
//! by depth (stable, 32 bits, one key per Gaussian), the pairs are emitted in that order,
//! and the pair sort orders only the tile bits: the result is the same
//! `(tile, depth, index)` order with far fewer passes over the (many more) pairs. Both sorts
//! use 32-bit keys (depth bits; bin id), so each pass moves 8 bytes per element, not 12.
//!
//! The number of (tile, Gaussian) pairs is only known on the GPU. The key buffers are
//! sized from a capacity kept across frames; the keys stage drops pairs beyond it and the
//! preprocess stage counts the exact 64-bit total, so after the frame the host sees whether
//! the capacity sufficed. Only when a frame proves it too small are the buffers grown and
//! the frame recorded again; the CPU never waits in the middle of a frame.
//!
//! Frames in flight: [`GpuRenderer::submit`] records and submits a frame and returns a
//! [`Ticket`]; [`GpuRenderer::finish`] waits for it, checks its counters (recording it
//! again when it needs more), and reads it back. Each of the (at most two) frames in flight
//! has its own command buffer, fence, timestamp queries and frame buffers, so frame n+1
//! renders while frame n is read back ([`frame::path::GpuPath`] drives camera paths this way).
//! [`GpuRenderer::render`] is a submit followed by its finish.

pub mod backward;
pub mod field;
pub mod forward;
pub mod frame;
/// The render wing's shaders: their named bindings and variants (`glsl/render/`).
pub mod shaders;

use backward::grad_accumulate::Accumulation;
use backward::{BackwardRequest, BackwardState, DeviceBackward, Gradients, LastFrameState};

use forward::{blend, shade};

pub use forward::blend::Falloff;
use frame::buffers::{check_binding, FrameBuffers, FrameSet};
use frame::pipelines::FrameNeeds;
pub use frame::readback::{ForwardState, Intermediates};
use frame::schedule::Frames;
use frame::schedule::Pass;
use frame::schedule::CHUNKS_PER_SUBMIT;
pub use frame::schedule::{
    bin_grid, key_bits, tile_bits, SplitLimits, CPU_LOOP_LIMIT, SMALL_BIN_MAX_PAIRS,
};
use frame::timings::MAX_STAGES_PER_SUBMIT;
pub use frame::timings::{FrameStats, Stage, StageTimings};
pub use frame::traffic::frame_traffic;
use frame::upload::FeatureJob;
pub use frame::upload::{sh_texel_stride, GpuFeatures, GpuScene};

/// Refuses a storage binding of `bytes` that the device cannot bind (maxStorageBufferRange),
/// naming `what` it is for.
pub fn check_storage_binding(ctx: &GpuContext, what: &str, bytes: u64) -> GpuResult<()> {
    check_binding(ctx, what, bytes)
}

use crate::core::camera::Camera;
use crate::core::frame::Frame;
pub use crate::core::frame::Rgba8Frame;
use crate::core::model::{ActivatedScene, RenderOptions};
use crate::gpu::{GpuContext, GpuError, GpuResult};

/// What a frame reads back to the host after it is rendered.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Readback {
    /// Colour, alpha and depth as floats (a [`Frame`]): 20 bytes per pixel.
    #[default]
    Float,
    /// Colour packed to 8-bit RGBA on the device (alpha 255), quantised as
    /// [`crate::io::output::to_u8`]: 4 bytes per pixel. For display, and for runs whose
    /// every output is 8-bit colour (RGB PNGs, videos: [`crate::app::sequence::reads_rgb8_only`]).
    Rgba8,
    /// Nothing but the frame's counters: the colour and depth images stay on the device,
    /// ready to be copied from (the frame's [`ForwardHandle`]; training reads them there).
    Counters,
    /// [`Readback::Float`] and every intermediate buffer of the frame ([`Intermediates`]:
    /// the splats, the sorted pairs, the bin ranges), for tests and the stage checks.
    Intermediates,
}

/// The handle of a finished frame's forward state on the device ([`Rendered::forward`]),
/// which a backward pass of the frame takes ([`GpuRenderer::device_backward`],
/// [`GpuRenderer::backward`]). The renderer refuses it once it has finished another
/// frame, whose state replaced this one's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ForwardHandle {
    frame: LastFrame,
    width: u32,
    height: u32,
}

/// A finished frame as its backward pass needs to know it: the set that holds its saved
/// state, its serial (a later frame's replaces it), the alpha falloff it was drawn with
/// and whether through a lens other than the pinhole (its backward pass differentiates the
/// unscented transform). The renderer keeps its last one; a [`ForwardHandle`] carries its
/// frame's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct LastFrame {
    pub(crate) set: usize,
    pub(crate) serial: u64,
    pub(crate) falloff: Falloff,
    pub(crate) lens: bool,
}

impl ForwardHandle {
    /// The frame's width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
}

/// What a frame renders and what it reads back: the one request every kind of frame is
/// rendered from ([`GpuRenderer::render`], [`GpuRenderer::submit`]).
/// The scene, features and shader (`'a`) are borrowed by a submitted frame until it is
/// finished; the camera and options (`'c`) are copied.
#[derive(Clone, Copy)]
pub struct FrameRequest<'a, 'c> {
    /// The uploaded scene.
    pub scene: &'a GpuScene,
    /// The camera.
    pub camera: &'c Camera,
    /// The per-frame options.
    pub options: &'c RenderOptions,
    /// Feature channels blended over the same sorted lists with the colour rules
    /// (background 0), timed as the `features` stage.
    pub features: Option<&'a GpuFeatures>,
    /// A neural shader ([`crate::fields::mlp`]) that turns the feature channels into the frame's
    /// colour (`alpha * mlp(...) + (1 - alpha) * background`), as its own `shade` stage.
    pub shader: Option<&'a shade::GpuShader>,
    /// What is read back.
    pub readback: Readback,
}

impl<'a, 'c> FrameRequest<'a, 'c> {
    /// A frame of `scene` from `camera`, read back as floats.
    pub fn new(scene: &'a GpuScene, camera: &'c Camera, options: &'c RenderOptions) -> Self {
        FrameRequest {
            scene,
            camera,
            options,
            features: None,
            shader: None,
            readback: Readback::Float,
        }
    }

    /// The frame also blends `features` (read back in [`Frame::features`]).
    pub fn features(self, features: &'a GpuFeatures) -> Self {
        FrameRequest {
            features: Some(features),
            ..self
        }
    }

    /// The frame blends `features` and shades them with `shader`.
    pub fn shaded(self, features: &'a GpuFeatures, shader: &'a shade::GpuShader) -> Self {
        FrameRequest {
            features: Some(features),
            shader: Some(shader),
            ..self
        }
    }

    /// The frame's shader, if any (with [`Self::features`]).
    pub fn shader(self, shader: Option<&'a shade::GpuShader>) -> Self {
        FrameRequest { shader, ..self }
    }

    /// What the frame reads back.
    pub fn readback(self, readback: Readback) -> Self {
        FrameRequest { readback, ..self }
    }
}

/// A finished frame: what its request's [`Readback`] asked for, and the handle of its
/// state on the device, which a backward pass of it takes.
#[derive(Clone, Debug)]
pub struct Rendered {
    forward: ForwardHandle,
    output: Output,
}

/// What a finished frame read back.
#[derive(Clone, Debug)]
enum Output {
    /// [`Readback::Float`]: colour, alpha, depth (and feature channels).
    Frame(Frame),
    /// [`Readback::Rgba8`].
    Rgba8(Rgba8Frame),
    /// [`Readback::Counters`]: the frame is left on the device.
    OnDevice,
    /// [`Readback::Intermediates`]: the float frame and its intermediate buffers.
    Intermediates(Box<(Frame, Intermediates)>),
}

impl Rendered {
    fn wrong(&self, want: &str) -> GpuError {
        let got = match self.output {
            Output::Frame(_) => "Readback::Float",
            Output::Rgba8(_) => "Readback::Rgba8",
            Output::OnDevice => "Readback::Counters",
            Output::Intermediates(..) => "Readback::Intermediates",
        };
        GpuError::InvalidArgument(format!("the frame was requested with {got}, not {want}"))
    }

    /// The handle of the frame's state on the device (what a backward pass of it takes).
    pub fn forward(&self) -> ForwardHandle {
        self.forward
    }

    /// The float frame.
    pub fn into_frame(self) -> GpuResult<Frame> {
        match self.output {
            Output::Frame(f) => Ok(f),
            _ => Err(self.wrong("Readback::Float")),
        }
    }

    /// The 8-bit frame.
    pub fn into_rgba8(self) -> GpuResult<Rgba8Frame> {
        match self.output {
            Output::Rgba8(f) => Ok(f),
            _ => Err(self.wrong("Readback::Rgba8")),
        }
    }

    /// The float frame and its intermediate buffers.
    pub fn into_intermediates(self) -> GpuResult<(Frame, Intermediates)> {
        match self.output {
            Output::Intermediates(both) => Ok(*both),
            _ => Err(self.wrong("Readback::Intermediates")),
        }
    }

    /// The handle of a frame left on the device ([`Readback::Counters`]).
    pub fn into_forward(self) -> GpuResult<ForwardHandle> {
        match self.output {
            Output::OnDevice => Ok(self.forward),
            _ => Err(self.wrong("Readback::Counters")),
        }
    }
}

/// The GPU renderer: pipelines, per-frame buffers and the timestamp pool.
pub struct GpuRenderer {
    /// The frames' sets, pipelines and schedule ([`Frames`]). First, so that it drops
    /// first: a set waits for a frame still in flight before the pipelines go.
    frames: Frames,
    /// Upload scenes compact: fp16 SH, scales and rotations ([`Self::set_compact`]).
    compact: bool,
    /// The backward pass's pipelines and buffers, made by the first pass.
    backward: Option<backward::BackwardState>,
    ctx: GpuContext,
}

/// Frames one renderer keeps in flight at most ([`GpuRenderer::submit`]).
pub const MAX_FRAMES_IN_FLIGHT: usize = 2;

/// A frame submitted by [`GpuRenderer::submit`], still being rendered;
/// [`GpuRenderer::finish`] waits
/// for it and reads it back. It borrows the scene (and features) the frame reads, so they
/// outlive the work on the device.
#[must_use = "a submitted frame is read back (and its resources freed for the next) by GpuRenderer::finish"]
pub struct Ticket<'a> {
    set: usize,
    serial: u64,
    scene: &'a GpuScene,
    cam: Camera,
    opts: RenderOptions,
    readback: Readback,
    features: Option<FeatureJob<'a>>,
    /// Rendered in chunks when finished (nothing of it is in flight).
    chunked: bool,
}

impl Ticket<'_> {
    /// What recording the frame takes: the pipelines it needs; `save_last` as its set
    /// records it ([`FrameSet::saves_last`]).
    fn needs(&self, save_last: bool) -> FrameNeeds {
        FrameNeeds {
            compact: self.scene.compact,
            lens: !self.cam.lens.is_pinhole(),
            falloff: Falloff::of(&self.opts),
            features: self.features.is_some(),
            surface: matches!(self.features, Some((f, _)) if f.surface),
            shade: matches!(self.features, Some((_, Some(_)))),
            pack: self.readback == Readback::Rgba8,
            save_last,
        }
    }

    /// The camera of the frame.
    pub fn camera(&self) -> &Camera {
        &self.cam
    }
}

impl GpuRenderer {
    /// The saved state of the last finished frame ([`ForwardState`]).
    pub fn forward_state(&self) -> GpuResult<ForwardState<'_>> {
        self.frames.sets[self.frames.last.set].forward_state()
    }

    /// Uploads activated Gaussians.
    pub fn upload(&self, scene: &ActivatedScene) -> GpuResult<GpuScene> {
        self.uploader().upload(scene)
    }

    /// A scene of `count` Gaussians whose records and SH texels (degree `sh_degree`) a
    /// device pass writes ([`GpuScene::device_buffers`]) instead of an upload: training
    /// keeps its parameters on the device and writes the activated values there.
    pub fn scene_for_device_writes(&self, count: u32, sh_degree: u32) -> GpuResult<GpuScene> {
        self.uploader().scene_for_device_writes(count, sh_degree)
    }

    /// Feature channels (`k` per Gaussian, in groups of four: a buffer of a vec4 per
    /// Gaussian each) for `count` Gaussians, not filled: a device pass writes them
    /// ([`GpuFeatures::device_buffers`]), or [`Self::upload_features`] uploads them.
    pub fn features_for_device_writes(&self, count: u32, k: usize) -> GpuResult<GpuFeatures> {
        self.uploader().features_for_device_writes(count, k)
    }

    /// Uploads the scene's feature channels (four per buffer, for the feature blend).
    pub fn upload_features(&self, scene: &ActivatedScene) -> GpuResult<GpuFeatures> {
        self.uploader().upload_features(scene)
    }

    /// Uploads the surface pass's axes of `scene` ([`surface_axes`](crate::core::model::surface::surface_axes): each Gaussian's unit
    /// smallest-scale axis and its dot product with the centre, one group of four): frames
    /// blended with them ([`crate::render::FrameRequest::features`]) hold, per pixel, the
    /// blended facing normals and the median depth
    /// ([`crate::core::model::surface::surface_planes`] reads them).
    pub fn upload_surface(&self, scene: &ActivatedScene) -> GpuResult<GpuFeatures> {
        self.uploader().upload_surface(scene)
    }

    /// What an upload needs of the renderer.
    fn uploader(&self) -> frame::upload::Uploader<'_> {
        frame::upload::Uploader {
            ctx: &self.ctx,
            compact: self.compact,
            texel_io: self.frames.pipelines.texel_io(),
        }
    }

    /// Builds every pipeline on `ctx`, with the blend kernel suited to the device.
    pub fn new(ctx: GpuContext) -> GpuResult<Self> {
        let kernel = blend::BlendKernel::for_device(&ctx);
        Self::with_blend_kernel(ctx, kernel)
    }

    /// Builds every pipeline with the given blend kernel.
    pub fn with_blend_kernel(ctx: GpuContext, kernel: blend::BlendKernel) -> GpuResult<Self> {
        Ok(GpuRenderer {
            frames: Frames::new(&ctx, kernel)?,
            compact: false,
            backward: None,
            ctx,
        })
    }

    /// Splits frames as if the device's limits were `limits` (for tests; see
    /// [`SplitLimits`]).
    pub fn set_split_limits(&mut self, limits: SplitLimits) {
        self.frames.split = limits;
    }

    /// Whether the frames from now on also save each pixel's last contributor for a
    /// backward pass ([`Self::forward_state`]); off by default, so plain renders neither
    /// compute nor store it. Frames in one piece only: a frame rendered in chunks saves no
    /// last contributor.
    pub fn set_save_forward_state(&mut self, on: bool) {
        self.frames.save_forward = on;
    }

    /// Pipelines built so far (each the first time a frame needed it) and the
    /// milliseconds that took.
    pub fn pipelines_built(&self) -> (u32, f64) {
        self.frames.pipelines.built()
    }

    /// The blend kernel in use.
    pub fn blend_kernel(&self) -> blend::BlendKernel {
        self.frames.pipelines.kernel()
    }

    /// The blend kernel frames with `opts` use: [`Self::blend_kernel`], or in the
    /// reproducible mode [`blend::BlendKernel::reproducible`].
    pub fn blend_kernel_for(&self, opts: &RenderOptions) -> blend::BlendKernel {
        match opts.reproducible {
            true => self.blend_kernel().reproducible(self.ctx().info()),
            false => self.blend_kernel(),
        }
    }

    /// Destroys the pipelines and per-frame resources and returns the context (for
    /// checking that nothing is left allocated).
    pub fn into_context(self) -> GpuContext {
        self.ctx
    }

    /// The device context.
    pub fn ctx(&self) -> &GpuContext {
        &self.ctx
    }

    /// Compact mode for the scenes uploaded from now on: SH coefficients as fp16 (half the
    /// bytes of the largest per-Gaussian array: 96 instead of 192 at SH degree 3), read
    /// through an RGBA16F texel view, and 32-byte records instead of 48 (axis scales and
    /// rotation as fp16; centre and opacity stay f32), unpacked by a preprocess variant.
    /// Not exact: frames equal the exact render of [`ActivatedScene::compact_rounded`](crate::core::model::ActivatedScene::compact_rounded),
    /// which differs from the scene by fp16's rounding (BENCHMARKS.md measures the PSNR).
    pub fn set_compact(&mut self, on: bool) {
        self.compact = on;
    }

    /// The handle of the frame just finished, rendered from `cam`.
    fn forward_handle(&self, cam: &Camera) -> ForwardHandle {
        ForwardHandle {
            frame: self.frames.last,
            width: cam.width,
            height: cam.height,
        }
    }

    /// What every features frame needs before it is recorded: features uploaded for this
    /// scene and, with a shader, a shader that takes them and fits the device's loops.
    fn prepare_features(
        &mut self,
        scene: &GpuScene,
        features: &GpuFeatures,
        shader: Option<&shade::GpuShader>,
    ) -> GpuResult<()> {
        if features.count != scene.uploaded {
            return Err(GpuError::Input(format!(
                "the features were uploaded for {} Gaussians, the scene has {}",
                features.count, scene.uploaded
            )));
        }
        if let Some(shader) = shader {
            if shader.channels() != features.channels {
                return Err(GpuError::Input(format!(
                    "the shader takes {} feature channels but the scene has {}",
                    shader.channels(),
                    features.channels
                )));
            }
            if self.ctx.info().loop_limited() && shader.iterations > u64::from(CPU_LOOP_LIMIT) {
                return Err(GpuError::DeviceLimit {
                    limit: "llvmpipe's loop iterations per invocation",
                    needed: shader.iterations,
                    max: u64::from(CPU_LOOP_LIMIT),
                    message: format!(
                        "the neural shader needs {} loop iterations per pixel, but {} ends every shader invocation's loops after {CPU_LOOP_LIMIT} iterations; use narrower layers, or the CPU reference (--cpu)",
                        shader.iterations,
                        self.ctx.info().name
                    ),
                });
            }
        }
        Ok(())
    }

    /// GPU time per stage of the last frame finished.
    pub fn timings(&self) -> &StageTimings {
        &self.frames.timings
    }

    /// Counts of the last frame finished.
    pub fn stats(&self) -> &FrameStats {
        &self.frames.stats
    }

    /// Device bytes held by the per-frame buffers, of every frame in flight: with two
    /// frames in flight ([`Self::submit`]) there are two sets of them.
    pub fn frame_device_bytes(&self) -> u64 {
        self.frames
            .sets
            .iter()
            .filter_map(|s| s.frame.as_ref())
            .map(|f| f.device_bytes())
            .sum()
    }

    /// Sets of per-frame resources made so far: 1, or 2 once two frames were in flight.
    pub fn frame_sets(&self) -> usize {
        self.frames.sets.len()
    }

    /// Frames submitted and not finished yet.
    pub fn frames_in_flight(&self) -> usize {
        self.frames
            .sets
            .iter()
            .filter(|s| s.pending.is_some())
            .count()
    }

    /// Renders the frame `request` asks for: [`Self::submit`] and [`Self::finish`].
    pub fn render(&mut self, request: &FrameRequest) -> GpuResult<Rendered> {
        let ticket = self.submit(request)?;
        self.finish(ticket)
    }

    /// Records the frame `request` asks for and submits it to the device without waiting
    /// for it: the CPU can submit the next frame (up to [`MAX_FRAMES_IN_FLIGHT`] in flight,
    /// each with its own command buffer, fence, timestamps and frame buffers) while this
    /// one renders, and read it back with [`Self::finish`]. Frames may be finished in any
    /// order. The second set of per-frame resources is made the first time two frames are
    /// in flight (doubling the device memory of [`Self::frame_device_bytes`]).
    pub fn submit<'a>(&mut self, request: &FrameRequest<'a, '_>) -> GpuResult<Ticket<'a>> {
        let features = match request.features {
            Some(features) => {
                self.prepare_features(request.scene, features, request.shader)?;
                Some((features, request.shader))
            }
            None if request.shader.is_some() => {
                return Err(GpuError::InvalidArgument(
                    "a neural shader shades feature channels: the request has none".into(),
                ))
            }
            None => None,
        };
        let readback = request.readback;
        if features.is_some() && matches!(readback, Readback::Rgba8 | Readback::Intermediates) {
            return Err(GpuError::InvalidArgument(format!(
                "a frame of feature channels reads back floats or nothing, not Readback::{readback:?}"
            )));
        }
        self.frames.submit_with(
            &self.ctx,
            request.scene,
            request.camera,
            request.options,
            readback,
            features,
        )
    }

    /// Waits for a submitted frame and reads back what its request asked for: the float
    /// frame (with its feature channels when it blended features and no shader), the
    /// 8-bit frame, or, for a frame left on the device, its [`ForwardHandle`]. When the
    /// frame needed more tile/Gaussian pairs than its buffers hold, or larger bins, it is
    /// recorded again (and waited for) here. The timings and counts ([`Self::timings`],
    /// [`Self::stats`]) become this frame's.
    pub fn finish(&mut self, ticket: Ticket) -> GpuResult<Rendered> {
        self.frames.complete(&self.ctx, &ticket)?;
        let output = match ticket.readback {
            Readback::Float => {
                let mut frame = self.frames.sets[ticket.set].read_frame(&ticket.cam)?;
                if let Some((features, None)) = ticket.features {
                    let pixels = ticket.cam.width as usize * ticket.cam.height as usize;
                    frame.feature_count = features.channels;
                    frame.features = self.frames.sets[ticket.set].read_feature_planes(
                        &self.ctx,
                        features.channels,
                        pixels,
                    )?;
                }
                Output::Frame(frame)
            }
            Readback::Rgba8 => Output::Rgba8(self.frames.sets[ticket.set].read_rgba8(&ticket.cam)?),
            Readback::Counters => Output::OnDevice,
            Readback::Intermediates => Output::Intermediates(Box::new((
                self.frames.sets[ticket.set].read_frame(&ticket.cam)?,
                self.frames.sets[self.frames.last.set].read_intermediates(
                    &self.ctx,
                    ticket.scene,
                    &ticket.cam,
                )?,
            ))),
        };
        Ok(Rendered {
            forward: self.forward_handle(&ticket.cam),
            output,
        })
    }

    /// Waits for a submitted frame without reading it back, freeing its resources for the
    /// next frame (after an error stopped a path).
    pub fn discard(&mut self, ticket: Ticket) -> GpuResult<()> {
        let set = self.frames.sets.get_mut(ticket.set).ok_or_else(|| {
            GpuError::InvalidArgument("the ticket is not from this renderer".into())
        })?;
        if set.pending == Some(ticket.serial) {
            set.pending = None;
            self.ctx.wait_slot(&mut set.slot)?;
        }
        Ok(())
    }
}

/// The backward pass ([`backward`]): from the gradients of a loss with respect to the last
/// frame's pixels to the Gaussians'.
impl GpuRenderer {
    /// The backward pass of the last frame that `req` asks for ([`BackwardRequest`]). The
    /// frame must have been rendered with [`Self::set_save_forward_state`] on, in one
    /// piece, and be the renderer's last (an older handle is refused); its options
    /// (kernel, background, scale modifier, SH degree) are the backward's. A frame whose
    /// buffers exceed one storage binding is taken in bands ([`Self::backward_bands`]).
    pub fn backward(&mut self, req: &BackwardRequest) -> GpuResult<Gradients> {
        let (ctx, frame, state) = self.backward_parts()?;
        state.backward(ctx, frame, req)
    }

    /// The backward pass `req` asks for ([`BackwardRequest::recorded`]) of the frame its
    /// handle names (rendered with [`Readback::Counters`], with the forward state saved),
    /// entirely on the device, recorded by the caller in one submission with what makes
    /// the pixels' gradients and what reads the results ([`DeviceBackward`]). A frame of
    /// SH colour, or of feature channels shaded by a neural shader
    /// ([`FrameRequest::shaded`], [`BackwardRequest::shaded_on_device`]); no depth
    /// gradient. Nothing is read back. Refused when the renderer has finished another
    /// frame since.
    pub fn device_backward<'r>(
        &'r mut self,
        req: &BackwardRequest<'r>,
    ) -> GpuResult<DeviceBackward<'r>> {
        let (ctx, frame, state) = self.backward_parts()?;
        state.device_backward(ctx, frame, req)
    }

    /// The context, the last frame as a backward pass reads it, and the backward pass's
    /// state (made the first time it is asked for).
    fn backward_parts(
        &mut self,
    ) -> GpuResult<(&GpuContext, LastFrameState<'_>, &mut BackwardState)> {
        let GpuRenderer {
            ctx,
            frames,
            backward,
            ..
        } = self;
        let frame = LastFrameState {
            sets: &frames.sets,
            last: frames.last,
        };
        Ok((ctx, frame, BackwardState::get(ctx, backward)?))
    }

    /// How the backward passes add per-pair gradients into per-Gaussian sums
    /// ([`Accumulation::Deterministic`] by default).
    pub fn set_gradient_accumulation(&mut self, mode: Accumulation) -> GpuResult<()> {
        BackwardState::get(&self.ctx, &mut self.backward)?.set_accumulation(mode);
        Ok(())
    }

    /// The accumulation the backward passes use.
    pub fn gradient_accumulation(&self) -> Accumulation {
        self.backward
            .as_ref()
            .map_or_else(Accumulation::default, BackwardState::accumulation)
    }

    /// Whether the backward passes that read their gradients back also return the
    /// projected quantities' ([`crate::core::model::grad::SplatGrads::screen`], what a
    /// camera's gradient needs; off by default: it reads every Gaussian's sums back).
    pub fn set_screen_grads(&mut self, on: bool) -> GpuResult<()> {
        BackwardState::get(&self.ctx, &mut self.backward)?.set_screen(on);
        Ok(())
    }

    /// Milliseconds of each stage of the last backward pass (device timestamps), in order.
    pub fn backward_timings(&self) -> Vec<(String, f64)> {
        self.backward
            .as_ref()
            .map_or_else(Vec::new, |b| b.timings().to_vec())
    }

    /// Milliseconds of the last backward pass on the device, first timestamp to last.
    pub fn backward_total_ms(&self) -> f64 {
        self.backward.as_ref().map_or(0.0, BackwardState::total_ms)
    }

    /// How the last backward pass was split to fit the device's storage bindings: its
    /// bands of pixel rows and its bands of sorted pairs, (1, 1) for a pass in one piece
    /// ((0, 0) before the first pass).
    pub fn backward_bands(&self) -> (usize, usize) {
        self.backward.as_ref().map_or((0, 0), BackwardState::bands)
    }

    /// Device bytes the backward pass holds (its buffers, sized by the largest pass so far).
    pub fn backward_device_bytes(&self) -> u64 {
        self.backward
            .as_ref()
            .map_or(0, BackwardState::device_bytes)
    }
}
