//! Exclusive prefix sum of u32 values, multi-level reduce-then-scan:
//! block sums -> scan of the block sums (recursively) -> scan blocks and add back.
//!
//! Sums are computed modulo 2^32: a total >= 2^32 wraps, and refusing such inputs is
//! the caller's job (the renderer bounds its counts).

pub use crate::core::shader_interface::ScanPush;
use ash::vk;

use super::shader::{by_binding, BindingKind};
use super::shader_set::bindings;
use super::sync::{barrier, Access};
use super::{
    dispatch_grid, BufferSlice, ComputePipeline, GpuBuffer, GpuContext, GpuError, GpuResult,
    Traffic,
};

pub use super::shader_set::{SCAN_BLOCK, SCAN_ITEMS, SCAN_WG};
/// Alignment of sub-ranges carved out of scratch buffers (the largest
/// minStorageBufferOffsetAlignment Vulkan allows).
pub const SCRATCH_ALIGN: u64 = 256;

/// The prefix-sum pipelines.
pub struct Scan {
    reduce: ComputePipeline,
    block: ComputePipeline,
    add: ComputePipeline,
    max_groups_x: u32,
}

impl Scan {
    /// Compiles the scan shaders and builds their pipelines.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let defines = [];
        let push = &ScanPush::LAYOUT;
        let storage = BindingKind::StorageBuffer;
        Ok(Self {
            reduce: ComputePipeline::from_embedded(
                ctx,
                "scan_reduce",
                &defines,
                &by_binding([
                    (bindings::scan_reduce::DATA_IN, storage),
                    (bindings::scan_reduce::BLOCK_SUMS, storage),
                ])?,
                push,
            )?,
            block: ComputePipeline::from_embedded(
                ctx,
                "scan_block",
                &defines,
                &by_binding([
                    (bindings::scan_block::DATA_IN, storage),
                    (bindings::scan_block::DATA_OUT, storage),
                    (bindings::scan_block::TOTALS, storage),
                ])?,
                push,
            )?,
            add: ComputePipeline::from_embedded(
                ctx,
                "scan_add",
                &defines,
                &by_binding([
                    (bindings::scan_add::DATA_IN, storage),
                    (bindings::scan_add::BLOCK_OFFSETS, storage),
                    (bindings::scan_add::DATA_OUT, storage),
                ])?,
                push,
            )?,
            max_groups_x: ctx.info().max_workgroup_count[0],
        })
    }

    /// Pretends `maxComputeWorkGroupCount[0]` is `max_x` (at most the real limit), so
    /// tests can exercise the 2D dispatch grid with small inputs.
    pub fn with_dispatch_limit(mut self, max_x: u32) -> Self {
        self.max_groups_x = self.max_groups_x.min(max_x.max(1));
        self
    }

    /// Scratch bytes needed to scan `n` elements (0 when one workgroup suffices).
    pub fn scratch_size(n: u32) -> u64 {
        if n <= SCAN_BLOCK {
            0
        } else {
            let groups = n.div_ceil(SCAN_BLOCK);
            super::align_up(u64::from(groups) * 4, SCRATCH_ALIGN) + Self::scratch_size(groups)
        }
    }

    /// The device memory a scan of `n` u32s reads and writes: one workgroup's block reads
    /// and writes each element (and the total); a larger scan reduces every block to its
    /// sum, scans the sums (recursively) and adds them back while scanning the blocks.
    pub fn traffic(n: u32) -> Traffic {
        let bytes = u64::from(n) * 4;
        if n <= SCAN_BLOCK {
            return Traffic::new(bytes, bytes + 4);
        }
        let sums = u64::from(n.div_ceil(SCAN_BLOCK)) * 4;
        let reduce = Traffic::new(bytes, sums);
        let add = Traffic::new(bytes + sums, bytes);
        reduce + Self::traffic(n.div_ceil(SCAN_BLOCK)) + add
    }

    /// Records an exclusive prefix sum of `n` u32s from `input` into `output` (which
    /// may be the same range) and writes the total to the u32 at byte `total.1` of
    /// `total.0`.
    ///
    /// Barrier contract: the caller makes earlier writes of `input` visible to compute
    /// shader reads, and orders earlier accesses of `output`, `scratch` and the total
    /// before this (compute-to-compute barrier). On return, `output` and the total
    /// have been written by compute shaders and the caller places the barrier from
    /// [`Access::ComputeWrite`] to its next use. Slice offsets must respect
    /// minStorageBufferOffsetAlignment.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        input: BufferSlice,
        output: BufferSlice,
        total: (&GpuBuffer, u64),
        scratch: BufferSlice,
        n: u32,
    ) -> GpuResult<()> {
        let bytes = u64::from(n) * 4;
        if input.size < bytes || output.size < bytes {
            return Err(GpuError::InvalidArgument(format!(
                "scan of {n} elements needs {bytes} bytes; input '{}' has {}, output '{}' has {}",
                input.buffer.name(),
                input.size,
                output.buffer.name(),
                output.size
            )));
        }
        if total.1 % 4 != 0 || total.1 + 4 > total.0.size() {
            return Err(GpuError::InvalidArgument(format!(
                "scan total offset {} is not a u32 slot inside '{}' ({} bytes)",
                total.1,
                total.0.name(),
                total.0.size()
            )));
        }
        let need = Self::scratch_size(n);
        if scratch.size < need {
            return Err(GpuError::InvalidArgument(format!(
                "scan of {n} elements needs {need} scratch bytes, '{}' slice has {}",
                scratch.buffer.name(),
                scratch.size
            )));
        }
        self.record_level(ctx, cmd, input, output, total, scratch, n)
    }

    #[allow(clippy::too_many_arguments)]
    fn record_level(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        input: BufferSlice,
        output: BufferSlice,
        total: (&GpuBuffer, u64),
        scratch: BufferSlice,
        n: u32,
    ) -> GpuResult<()> {
        if n <= SCAN_BLOCK {
            // Bind only the neighbourhood of the total slot (from an offset aligned for
            // any device) so hazard tracking sees the one word written.
            let base = total.1 / SCRATCH_ALIGN * SCRATCH_ALIGN;
            let total_slice = total.0.slice(base, total.1 + 4 - base);
            let push = ScanPush {
                n,
                write_total: 1,
                total_index: ((total.1 - base) / 4) as u32,
                pad: 0,
            };
            return self.block.dispatch(
                ctx,
                cmd,
                &by_binding([
                    (bindings::scan_block::DATA_IN, input),
                    (bindings::scan_block::DATA_OUT, output),
                    (bindings::scan_block::TOTALS, total_slice),
                ])?,
                bytemuck::bytes_of(&push),
                [1, 1, 1],
            );
        }
        let groups = n.div_ceil(SCAN_BLOCK);
        let sums_bytes = super::align_up(u64::from(groups) * 4, SCRATCH_ALIGN);
        let sums = scratch.buffer.slice(scratch.offset, u64::from(groups) * 4);
        let rest = scratch
            .buffer
            .slice(scratch.offset + sums_bytes, scratch.size - sums_bytes);
        let push = ScanPush {
            n,
            write_total: 0,
            total_index: 0,
            pad: 0,
        };
        let grid = dispatch_grid(groups, self.max_groups_x);
        let reduce = by_binding([
            (bindings::scan_reduce::DATA_IN, input),
            (bindings::scan_reduce::BLOCK_SUMS, sums),
        ])?;
        self.reduce
            .dispatch(ctx, cmd, &reduce, bytemuck::bytes_of(&push), grid)?;
        // Block sums: written above, scanned in place below.
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeReadWrite);
        self.record_level(ctx, cmd, sums, sums, total, rest, groups)?;
        // Scanned block sums are read by the add-back pass.
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeReadWrite);
        self.add.dispatch(
            ctx,
            cmd,
            &by_binding([
                (bindings::scan_add::DATA_IN, input),
                (bindings::scan_add::BLOCK_OFFSETS, sums),
                (bindings::scan_add::DATA_OUT, output),
            ])?,
            bytemuck::bytes_of(&push),
            grid,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn traffic_of_one_block_and_of_two_levels() {
        let block = u64::from(SCAN_BLOCK) * 4;
        assert_eq!(Scan::traffic(SCAN_BLOCK), Traffic::new(block, block + 4));
        // One more element: two block sums, reduced, scanned and added back.
        let n = block + 4;
        let expected = Traffic::new(n, 8) + Traffic::new(8, 12) + Traffic::new(n + 8, n);
        assert_eq!(Scan::traffic(SCAN_BLOCK + 1), expected);
    }
}
