//! Barriers expressed as "this memory goes from use X to use Y", mapped to
//! synchronization2 stage/access flags in one place.

use ash::vk;

use super::GpuContext;

/// One way a command uses memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    /// Read by a compute shader (storage buffer).
    ComputeRead,
    /// Read by a compute shader through a sampled/texel-buffer descriptor (`texelFetch`).
    ComputeSampledRead,
    /// Written by a compute shader.
    ComputeWrite,
    /// Read and written by a compute shader.
    ComputeReadWrite,
    /// Source of a copy.
    TransferRead,
    /// Destination of a copy or fill.
    TransferWrite,
    /// Read by the host after a fence wait.
    HostRead,
    /// Written by the host before submission.
    HostWrite,
    /// Read as VkDispatchIndirectCommand by vkCmdDispatchIndirect.
    IndirectRead,
    /// Anything (used around one-shot set-up copies, never per frame).
    Any,
}

impl Access {
    /// The sync2 stage and access masks of this use.
    pub fn flags(self) -> (vk::PipelineStageFlags2, vk::AccessFlags2) {
        use vk::AccessFlags2 as A;
        use vk::PipelineStageFlags2 as S;
        match self {
            Access::ComputeRead => (S::COMPUTE_SHADER, A::SHADER_STORAGE_READ),
            Access::ComputeSampledRead => (S::COMPUTE_SHADER, A::SHADER_SAMPLED_READ),
            Access::ComputeWrite => (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
            Access::ComputeReadWrite => (
                S::COMPUTE_SHADER,
                A::SHADER_STORAGE_READ | A::SHADER_STORAGE_WRITE,
            ),
            Access::TransferRead => (S::ALL_TRANSFER, A::TRANSFER_READ),
            Access::TransferWrite => (S::ALL_TRANSFER, A::TRANSFER_WRITE),
            Access::HostRead => (S::HOST, A::HOST_READ),
            Access::HostWrite => (S::HOST, A::HOST_WRITE),
            Access::IndirectRead => (S::DRAW_INDIRECT, A::INDIRECT_COMMAND_READ),
            Access::Any => (S::ALL_COMMANDS, A::MEMORY_READ | A::MEMORY_WRITE),
        }
    }
}

fn combine(uses: &[Access]) -> (vk::PipelineStageFlags2, vk::AccessFlags2) {
    uses.iter().fold(
        (vk::PipelineStageFlags2::NONE, vk::AccessFlags2::NONE),
        |(s, a), u| {
            let (us, ua) = u.flags();
            (s | us, a | ua)
        },
    )
}

/// Global memory barrier: all memory goes from uses `from` to uses `to`.
pub fn barrier_uses(ctx: &GpuContext, cmd: vk::CommandBuffer, from: &[Access], to: &[Access]) {
    let (src_stage, src_access) = combine(from);
    let (dst_stage, dst_access) = combine(to);
    let barriers = [vk::MemoryBarrier2::default()
        .src_stage_mask(src_stage)
        .src_access_mask(src_access)
        .dst_stage_mask(dst_stage)
        .dst_access_mask(dst_access)];
    let dep = vk::DependencyInfo::default().memory_barriers(&barriers);
    // SAFETY: cmd is in the recording state (caller contract); the info is valid.
    unsafe { ctx.device().cmd_pipeline_barrier2(cmd, &dep) };
}

/// Global memory barrier for a single use on each side.
pub fn barrier(ctx: &GpuContext, cmd: vk::CommandBuffer, from: Access, to: Access) {
    barrier_uses(ctx, cmd, &[from], &[to]);
}
