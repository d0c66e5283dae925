//! Duplicate-per-tile keys stage (`glsl/render/forward/keys.comp`): one thread per Gaussian, in depth
//! order, writes its (tile | depth, index) pairs at its scanned offset; or the Gaussians
//! of one chunk of the depth order, relative to the chunk's first offset.

use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::{dispatch_grid, BufferSlice, ComputePipeline, GpuContext, GpuResult};
use crate::render::shaders::bindings::keys as slot;
use ash::vk;

/// Invocations per workgroup (matches `local_size_x`).
pub const WORKGROUP: u32 = crate::gpu::shader_set::LINEAR_WG;

/// The key-duplication pipeline.
pub struct Keys {
    pipeline: ComputePipeline,
    texel_io: bool,
}

/// Buffers the stage reads and writes.
pub struct KeysBindings<'a> {
    /// FrameParams.
    pub params: BufferSlice<'a>,
    /// Texel view of the splats (R32G32B32A32_SFLOAT, 3 texels per splat).
    pub splat_texels: vk::BufferView,
    /// Counters (sort count and ranges dispatch written).
    pub counters: BufferSlice<'a>,
    /// The per-Gaussian arrays read and the pairs written: storage buffers, or (for the
    /// texel-I/O pipeline) texel views.
    pub io: KeysIo<'a>,
}

/// What the keys stage reads per Gaussian and writes per pair, as bound: storage-buffer
/// slices, or texel views (R32G32_UINT for the rectangles, R32_UINT for the rest).
pub struct KeysIo<'a> {
    /// Packed tile rectangles.
    pub rects: Resource<'a>,
    /// Exclusive prefix sum of tiles touched, in depth order.
    pub offsets: Resource<'a>,
    /// Keys: the bin (tile) id of each pair, 32 bits (written).
    pub keys: Resource<'a>,
    /// Values, Gaussian indices (written).
    pub values: Resource<'a>,
    /// Gaussian indices in depth order.
    pub depth_order: Resource<'a>,
    /// Receiving bins of small tile rectangles, from preprocess (global index).
    pub bin_masks: Resource<'a>,
}

impl Keys {
    /// Compiles the shader and builds the pipeline: reading and writing storage buffers,
    /// or (`texel_io`, for CPU devices) texel views.
    pub fn new(ctx: &GpuContext, texel_io: bool) -> GpuResult<Self> {
        use BindingKind::*;
        let (read, write) = if texel_io {
            (UniformTexelBuffer, StorageTexelBuffer)
        } else {
            (StorageBuffer, StorageBuffer)
        };
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "keys",
            &[("KEYS_TEXEL_IO", u32::from(texel_io).to_string())],
            &by_binding([
                (slot::PARAMS, StorageBuffer),
                (slot::SPLAT_TEXELS, UniformTexelBuffer),
                (slot::RECTS, read),
                (slot::OFFSETS, read),
                (slot::KEYS, write),
                (slot::VALUES, write),
                (slot::COUNTERS, StorageBuffer),
                (slot::DEPTH_ORDER, read),
                (slot::BIN_MASKS, read),
            ])?,
            &crate::render::forward::types::KeysPush::LAYOUT,
        )?;
        Ok(Keys { pipeline, texel_io })
    }

    /// Whether the pipeline reads and writes texel views.
    pub fn texel_io(&self) -> bool {
        self.texel_io
    }

    /// Records the dispatch for the depth-ordered Gaussians `chunk.first..chunk.end` (at
    /// least one workgroup, so the counters are always written).
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &KeysBindings,
        chunk: Chunk,
    ) -> GpuResult<()> {
        let groups = dispatch_grid(
            (chunk.end - chunk.first).div_ceil(WORKGROUP).max(1),
            ctx.info().max_workgroup_count[0],
        );
        let push = crate::render::forward::types::KeysPush {
            first: chunk.first,
            end: chunk.end,
            base: chunk.base,
        };
        self.pipeline.dispatch_resources(
            ctx,
            cmd,
            &by_binding([
                (slot::PARAMS, Resource::Buffer(b.params)),
                (slot::SPLAT_TEXELS, Resource::TexelBuffer(b.splat_texels)),
                (slot::RECTS, b.io.rects),
                (slot::OFFSETS, b.io.offsets),
                (slot::KEYS, b.io.keys),
                (slot::VALUES, b.io.values),
                (slot::COUNTERS, Resource::Buffer(b.counters)),
                (slot::DEPTH_ORDER, b.io.depth_order),
                (slot::BIN_MASKS, b.io.bin_masks),
            ])?,
            bytemuck::bytes_of(&push),
            groups,
        )
    }
}

/// Consecutive Gaussians of the depth order keyed together: `first..end`, whose pairs
/// start at scanned offset `base` (mod 2^32). A frame in one piece is `(0, n, 0)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Chunk {
    /// First Gaussian (index in depth order).
    pub first: u32,
    /// One past the last.
    pub end: u32,
    /// Scanned offset of `first`, modulo 2^32.
    pub base: u32,
    /// Pairs of the chunk.
    pub pairs: u64,
}

impl Chunk {
    /// All `n` Gaussians in one piece.
    pub fn whole(n: u32) -> Chunk {
        Chunk {
            first: 0,
            end: n,
            base: 0,
            pairs: 0,
        }
    }
}

/// Splits the visible Gaussians of the depth order into consecutive chunks of at most
/// `limit` pairs each (a single Gaussian with more pairs makes a chunk of its own).
/// `offsets` is the exclusive scan of tiles touched in depth order modulo 2^32 (one entry
/// per visible Gaussian) and `total` the exact pair count; the 64-bit offsets are
/// recovered from the wraps (each Gaussian touches fewer than 2^32 tiles). No visible
/// Gaussian: one empty chunk, so the frame is still blended.
pub fn plan_chunks(offsets: &[u32], total: u64, limit: u64) -> Vec<Chunk> {
    let mut exact = Vec::with_capacity(offsets.len() + 1);
    let (mut high, mut last) = (0u64, 0u32);
    for &o in offsets {
        if o < last {
            high += 1 << 32;
        }
        last = o;
        exact.push(high | u64::from(o));
    }
    exact.push(total);
    let n = offsets.len();
    let mut chunks = Vec::new();
    let mut first = 0usize;
    while first < n {
        let start = exact[first];
        // The last end whose pairs fit, but at least one Gaussian.
        let fit = exact[first + 1..].partition_point(|&e| e - start <= limit);
        let end = first + fit.max(1);
        chunks.push(Chunk {
            first: first as u32,
            end: end as u32,
            base: start as u32,
            pairs: exact[end] - start,
        });
        first = end;
    }
    if chunks.is_empty() {
        chunks.push(Chunk::default());
    }
    chunks
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_cover_the_order_within_the_limit() {
        // Tiles touched 3, 5, 1, 7, 2: offsets 0, 3, 8, 9, 16, total 18.
        let runs = |chunks: Vec<Chunk>| -> Vec<(u32, u32, u32, u64)> {
            chunks
                .iter()
                .map(|c| (c.first, c.end, c.base, c.pairs))
                .collect()
        };
        assert_eq!(
            runs(plan_chunks(&[0, 3, 8, 9, 16], 18, 8)),
            vec![(0, 2, 0, 8), (2, 4, 8, 8), (4, 5, 16, 2)]
        );
        // A Gaussian of 12 pairs, over the limit, makes a chunk of its own.
        assert_eq!(
            runs(plan_chunks(&[0, 3, 15], 16, 8)),
            vec![(0, 1, 0, 3), (1, 2, 3, 12), (2, 3, 15, 1)]
        );
    }

    #[test]
    fn chunk_offsets_past_2_pow_32_are_exact() {
        // Three Gaussians of 2^31 + 1 pairs each: the scan wraps after the second.
        let big = (1u64 << 31) + 1;
        let offsets = [0u32, big as u32, (2 * big) as u32];
        let chunks = plan_chunks(&offsets, 3 * big, big);
        assert_eq!(chunks.len(), 3);
        for (i, c) in chunks.iter().enumerate() {
            assert_eq!((c.first, c.end, c.pairs), (i as u32, i as u32 + 1, big));
            assert_eq!(c.base, (i as u64 * big) as u32);
        }
        assert_eq!(plan_chunks(&[], 0, 10), vec![Chunk::default()]);
    }
}
