//! A backward pass recorded on the device by its caller, with what makes the pixels'
//! gradients before it and what reads its results after, in one submission.

use super::pass::BackwardPass;
use super::{BackwardClock, DeviceGrads};
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{BufferSlice, GpuContext, GpuImage, GpuResult};
use crate::render::Stage;

/// The backward pass of the last frame, resolved ([`crate::render::GpuRenderer::device_backward`])
/// and recorded by the caller in three steps, top to bottom in one command buffer:
///
/// ```text
/// ctx.submit_and_wait("training step", |cmd| {
///     let (image, grad) = pass.begin(cmd)?;      // Stage::Loss: write dL/d(rgb, alpha) into `grad`
///     record_loss(cmd, image, grad)?;
///     let grads = pass.record(cmd)?;             // the pass; then Stage::Step reads `grads`
///     record_step(cmd, grads)?;
///     pass.end(cmd)
/// })?;
/// pass.finish()?;                                // the stage times (`backward_timings`)
/// ```
pub struct DeviceBackward<'r> {
    ctx: &'r GpuContext,
    pass: BackwardPass<'r>,
    clock: &'r mut BackwardClock,
}

impl<'r> DeviceBackward<'r> {
    pub(super) fn new(
        ctx: &'r GpuContext,
        pass: BackwardPass<'r>,
        clock: &'r mut BackwardClock,
    ) -> Self {
        DeviceBackward { ctx, pass, clock }
    }

    /// The renderer's context, to record and submit with.
    pub fn ctx(&self) -> &'r GpuContext {
        self.ctx
    }

    /// Opens the pass in `cmd` and its [`Stage::Loss`]: returns the frame's colour image
    /// (RGBA32F, a copy source) and the buffer the pixels' gradients go into (dL/d rgb,
    /// dL/d alpha, a vec4 per pixel), which the caller records next.
    pub fn begin(
        &mut self,
        cmd: ash::vk::CommandBuffer,
    ) -> GpuResult<(&'r GpuImage, BufferSlice<'r>)> {
        let ctx = self.ctx;
        self.pass.open(ctx, cmd, &mut self.clock.timer);
        self.pass.clear_depth_gradients(ctx, cmd);
        self.clock.timer.begin(ctx, cmd, Stage::Loss.name())?;
        Ok(self.pass.pixel_target())
    }

    /// Closes the loss's stage, records the pass (the shader's backward pass, blend
    /// backward, accumulation, preprocess backward) and opens [`Stage::Step`]: returns the
    /// pass's results, which the caller's step reads next.
    pub fn record(&mut self, cmd: ash::vk::CommandBuffer) -> GpuResult<DeviceGrads<'r>> {
        let ctx = self.ctx;
        self.clock.timer.end(ctx, cmd)?;
        self.pass.record_stages(ctx, cmd, &mut self.clock.timer)?;
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
        self.clock.timer.begin(ctx, cmd, Stage::Step.name())?;
        Ok(self.pass.results())
    }

    /// Closes the step's stage and the pass.
    pub fn end(&mut self, cmd: ash::vk::CommandBuffer) -> GpuResult<()> {
        self.clock.timer.end(self.ctx, cmd)?;
        self.pass.close(self.ctx, cmd);
        Ok(())
    }

    /// After the submission finished: reads the pass's stage times
    /// ([`crate::render::GpuRenderer::backward_timings`]).
    pub fn finish(self) -> GpuResult<()> {
        self.clock.read(self.ctx)
    }
}
