//! Stable LSD radix sort of (64-bit or 32-bit key, u32 value) pairs on the GPU.
//!
//! Keys are `uvec2 (lo, hi)` (8 bytes, no int64 needed) or, with
//! [`SortConfig::key_words`] = 1, one `uint` (a third fewer bytes moved per pass); only
//! the low `key_bits` bits take part, in `ceil(key_bits / radix_bits)` passes. Each pass
//! is reduce-then-scan (no spinning on other workgroups, so it runs on any device and any
//! subgroup size):
//! 1. `sort_histogram`: per-block digit counts, written digit-major;
//! 2. [`Scan`] of that table: the output offset of every (digit, block);
//! 3. `sort_scatter`: each block ranks its elements stably and scatters them. Each
//!    subgroup owns a contiguous chunk of the block, read in rows of
//!    `gl_SubgroupSize` elements; an element's rank among equal digits of its row
//!    comes from a ballot "multi-split" (one ballot per digit bit), its rank in the
//!    chunk from per-subgroup counters in shared memory, and the chunk's offset from a
//!    per-digit scan over subgroups. Only subgroup ballots/arithmetic are used, always
//!    over `gl_SubgroupSize` (tested with 8 lanes on lavapipe; written for 32/64).
//!
//! Key bit layout: digit `p` of pass `p` is bits `[p * radix_bits, (p + 1) * radix_bits)`
//! of `lo | hi << 32`, the last pass masked to `key_bits`; bits at or above `key_bits`
//! are ignored entirely (they neither order nor break ties).
//!
//! Passes ping-pong between the caller's buffers and scratch; after an odd number of
//! passes `sort_copy` moves the result back, so **the result always ends in the
//! caller's `keys` and `values` buffers**.
//!
//! The element count may live on the GPU ([`Count::Device`]): a one-invocation
//! `sort_setup` dispatch reads it and writes the indirect dispatch arguments, so the
//! CPU never waits mid-frame.

pub use crate::core::shader_interface::{SortPassPush, SortSetupPush};
use ash::vk;

use super::scan::{Scan, SCRATCH_ALIGN};
use super::shader::{by_binding, BindingKind, Resource};
use super::shader_set::bindings;
use super::shader_set::{SORT_SPEC_ITEMS, SORT_SPEC_MAX_SUBGROUPS, SORT_SPEC_RADIX, SORT_SPEC_WG};
use super::sync::{barrier, barrier_uses, Access};
use super::{
    align_up, BufferSlice, ComputePipeline, DeviceInfo, GpuBuffer, GpuContext, GpuError, GpuResult,
    GpuTimer, Traffic,
};

/// Tunables of the sort kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SortConfig {
    /// Bits per pass (digit width), 1..=8.
    pub radix_bits: u32,
    /// Invocations per workgroup (a multiple of the subgroup size, e.g. 128).
    pub workgroup_size: u32,
    /// Rows of one subgroup's chunk: elements per invocation.
    pub items_per_thread: u32,
    /// u32 words per key: 2 for 64-bit keys stored as `uvec2 (lo, hi)`, 1 for 32-bit
    /// keys stored as `uint`.
    pub key_words: u32,
    /// Read and write the keys and values through R32_UINT texel views (32-bit keys
    /// only; the caller passes the views, [`SortTexels`]). On llvmpipe texel fetches and
    /// `imageStore` are straight per-lane code where storage-buffer accesses are a
    /// guarded loop per component (`benches/tuning.rs` measures both).
    pub texel_io: bool,
}

impl SortConfig {
    /// Bytes per key.
    pub fn key_bytes(&self) -> u64 {
        u64::from(self.key_words) * 4
    }

    /// Subgroups a workgroup may have: the per-subgroup counters are sized for the
    /// smallest subgroups the device may run.
    pub fn max_subgroups(&self, info: &DeviceInfo) -> u32 {
        self.workgroup_size.div_ceil(info.min_subgroup_size.max(1))
    }

    /// Shared memory of the histogram and scatter kernels: one counter per digit and
    /// subgroup, and the workgroup scan's partials (`common.glsl`).
    pub fn shared_bytes(&self, info: &DeviceInfo) -> u32 {
        let radix = 1u32 << self.radix_bits.min(8);
        (radix * self.max_subgroups(info) + self.workgroup_size) * 4
    }

    /// This configuration, or the portable variant of it the device can run: while the
    /// counters do not fit the device's shared memory (small subgroups have many of them:
    /// 32 KiB for 128 invocations of 4 lanes) or the workgroup is larger than the device
    /// allows, half the invocations each take twice the rows (up to 128), so a block
    /// keeps its elements and the scratch layout ([`RadixSort::scratch_size_with`]) holds
    /// for the fitted configuration too. Never smaller than the device's largest subgroup.
    /// The same order of elements: only the speed differs (BENCHMARKS.md).
    pub fn fitted(self, info: &DeviceInfo) -> SortConfig {
        let mut config = self;
        let smallest = info.max_subgroup_size.max(info.subgroup_size).max(1);
        while (config.shared_bytes(info) > info.max_shared_memory
            || config.workgroup_size > info.max_workgroup_invocations)
            && config.workgroup_size / 2 >= smallest
            && config.workgroup_size % 2 == 0
            && config.items_per_thread * 2 <= 128
        {
            config.workgroup_size /= 2;
            config.items_per_thread *= 2;
        }
        config
    }
}

/// Default sort tuning, measured on lavapipe with `benches/tuning.rs`: 8-bit digits
/// halve the passes of 4-bit ones, and 32 items per invocation beat 16 (fewer blocks, a
/// smaller histogram table). 128 invocations keep the per-subgroup counters
/// (256 digits x 16 subgroups of 8 lanes) within 32 KiB of shared memory.
pub const DEFAULT_SORT_CONFIG: SortConfig = SortConfig {
    radix_bits: 8,
    workgroup_size: 128,
    items_per_thread: 32,
    key_words: 2,
    texel_io: false,
};

/// [`DEFAULT_SORT_CONFIG`] for 32-bit keys (the renderer's depth order and pair sort).
pub const SORT_CONFIG_32: SortConfig = SortConfig {
    key_words: 1,
    ..DEFAULT_SORT_CONFIG
};

/// Texel views (R32_UINT) a sort with [`SortConfig::texel_io`] reads and writes: over the
/// same bytes as the `keys` and `values` buffers passed to the record call, and over the
/// scratch's key and value ranges for the same `max_n` ([`RadixSort::scratch_pair_ranges`]).
#[derive(Clone, Copy)]
pub struct SortTexels {
    /// The caller's keys.
    pub keys: vk::BufferView,
    /// The caller's values.
    pub values: vk::BufferView,
    /// The scratch's keys.
    pub scratch_keys: vk::BufferView,
    /// The scratch's values.
    pub scratch_values: vk::BufferView,
}

/// u32 indices of the clamped element count, the number of blocks and the
/// VkDispatchIndirectCommand (x, y, z) for the per-block passes in the sort's meta words.
pub use super::shader_set::{META_BLOCKS, META_DISPATCH, META_N};
/// Bytes reserved for the meta words.
pub const META_BYTES: u64 = 32;

/// How many elements to sort.
#[derive(Clone, Copy)]
pub enum Count<'a> {
    /// Known on the host.
    Host(u32),
    /// A u32 at byte `offset` of `buffer`, written on the GPU; clamped to `max_n`,
    /// which sizes the scratch and dispatch arithmetic.
    Device {
        /// Buffer holding the count.
        buffer: &'a GpuBuffer,
        /// Byte offset (multiple of 4).
        offset: u64,
        /// Capacity (the keys/values buffers hold at least this many).
        max_n: u32,
    },
}

/// One sort to record ([`RadixSort::record`]): the buffers it sorts in place, its scratch,
/// the element count, the key bits that order, and the texel views of a texel-I/O sort.
#[derive(Clone)]
pub struct SortJob<'a> {
    /// Keys, sorted in place.
    pub keys: &'a GpuBuffer,
    /// Values, moved with their keys.
    pub values: &'a GpuBuffer,
    /// Scratch of [`RadixSort::scratch_size_with`] bytes for the count's capacity.
    pub scratch: &'a GpuBuffer,
    /// How many elements.
    pub count: Count<'a>,
    /// The key bits that order (`0..key_bits` for whole keys; a sub-range such as `32..44`
    /// for the tile id of pairs already in depth order: the sort is stable, so bits below
    /// the range keep the order they arrive in).
    pub bits: std::ops::Range<u32>,
    /// The views a sort with [`SortConfig::texel_io`] reads and writes (R32_UINT views of
    /// `keys`, `values` and the scratch's key and value ranges); `None` otherwise.
    pub texels: Option<&'a SortTexels>,
}

impl<'a> SortJob<'a> {
    /// Sorts `count` elements of `keys`/`values` by their low `key_bits` bits, through
    /// storage buffers.
    pub fn new(
        keys: &'a GpuBuffer,
        values: &'a GpuBuffer,
        scratch: &'a GpuBuffer,
        count: Count<'a>,
        key_bits: u32,
    ) -> Self {
        SortJob {
            keys,
            values,
            scratch,
            count,
            bits: 0..key_bits,
            texels: None,
        }
    }

    /// Orders by key bits `bits` only.
    pub fn bits(self, bits: std::ops::Range<u32>) -> Self {
        SortJob { bits, ..self }
    }

    /// Reads and writes through `texels` (a sort with [`SortConfig::texel_io`]).
    pub fn texels(self, texels: Option<&'a SortTexels>) -> Self {
        SortJob { texels, ..self }
    }
}

/// Byte ranges inside the sort scratch buffer.
#[derive(Clone, Copy, Debug)]
struct ScratchLayout {
    keys: (u64, u64),
    values: (u64, u64),
    hist: (u64, u64),
    offsets: (u64, u64),
    scan: (u64, u64),
    scan_total: u64,
    total: u64,
    hist_stride: u32,
}

impl ScratchLayout {
    fn new(config: &SortConfig, max_n: u32) -> Self {
        let block = config.workgroup_size * config.items_per_thread;
        let hist_stride = max_n.div_ceil(block).max(1);
        let table_len = hist_stride << config.radix_bits;
        let mut cursor = align_up(META_BYTES, SCRATCH_ALIGN);
        let mut take = |bytes: u64| {
            let range = (cursor, bytes);
            cursor = align_up(cursor + bytes.max(4), SCRATCH_ALIGN);
            range
        };
        let keys = take(u64::from(max_n) * config.key_bytes());
        let values = take(u64::from(max_n) * 4);
        let hist = take(u64::from(table_len) * 4);
        let offsets = take(u64::from(table_len) * 4);
        let scan = take(Scan::scratch_size(table_len));
        // Kept apart from the indirect arguments in the meta words.
        let scan_total = take(4).0;
        Self {
            keys,
            values,
            hist,
            offsets,
            scan,
            scan_total,
            total: cursor,
            hist_stride,
        }
    }
}

/// Between the sort's dispatches: compute writes -> the next dispatch's storage reads and
/// writes and texel fetches (of the texel-I/O variant).
fn pass_barrier(ctx: &GpuContext, cmd: vk::CommandBuffer) {
    barrier_uses(
        ctx,
        cmd,
        &[Access::ComputeWrite],
        &[Access::ComputeReadWrite, Access::ComputeSampledRead],
    );
}

/// The radix sort pipelines (plus the scan they use).
pub struct RadixSort {
    config: SortConfig,
    setup: ComputePipeline,
    histogram: ComputePipeline,
    scatter: ComputePipeline,
    copy: ComputePipeline,
    scan: Scan,
    max_groups_x: u32,
}

impl RadixSort {
    /// Builds the sort with [`DEFAULT_SORT_CONFIG`] (64-bit keys).
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        Self::with_config(ctx, DEFAULT_SORT_CONFIG)
    }

    /// Builds the sort with explicit tunables (for benchmarking), fitted to the device
    /// ([`SortConfig::fitted`]): [`Self::config`] is what runs.
    pub fn with_config(ctx: &GpuContext, config: SortConfig) -> GpuResult<Self> {
        let info = ctx.info();
        let config = config.fitted(info);
        let radix = 1u32 << config.radix_bits.min(8);
        let max_subgroups = config.max_subgroups(info);
        let shared_bytes = config.shared_bytes(info);
        if !(1..=8).contains(&config.radix_bits)
            || !(1..=2).contains(&config.key_words)
            || (config.texel_io && config.key_words != 1)
            || config.workgroup_size == 0
            || config.items_per_thread == 0
            || config.workgroup_size > info.max_workgroup_invocations
            || shared_bytes > info.max_shared_memory
            || info.subgroup_size > 128
        {
            return Err(GpuError::InvalidArgument(format!(
                "sort config {config:?} (subgroup size {}, {shared_bytes} bytes of shared \
                 memory) is outside what the kernels or the device support",
                info.subgroup_size
            )));
        }
        let key_type = if config.key_words == 1 {
            "uint"
        } else {
            "uvec2"
        };
        // The key type and the I/O path select the module; the tunables specialize it.
        let defines = [
            ("SORT_KEY", key_type.to_string()),
            ("SORT_TEXEL_IO", u32::from(config.texel_io).to_string()),
        ];
        let spec = [
            (SORT_SPEC_WG, config.workgroup_size),
            (SORT_SPEC_ITEMS, config.items_per_thread),
            (SORT_SPEC_RADIX, radix),
            (SORT_SPEC_MAX_SUBGROUPS, max_subgroups),
        ];
        // Bindings of the keys and values: texel views for reading and writing, or buffers.
        let (read, write) = if config.texel_io {
            (
                BindingKind::UniformTexelBuffer,
                BindingKind::StorageTexelBuffer,
            )
        } else {
            (BindingKind::StorageBuffer, BindingKind::StorageBuffer)
        };
        let storage = BindingKind::StorageBuffer;
        let setup_push = &SortSetupPush::LAYOUT;
        let pass_push = &SortPassPush::LAYOUT;
        Ok(Self {
            config,
            setup: ComputePipeline::from_embedded_specialized(
                ctx,
                "sort_setup",
                &defines,
                &by_binding([
                    (bindings::sort_setup::COUNT, storage),
                    (bindings::sort_setup::META, storage),
                ])?,
                setup_push,
                &spec,
            )?,
            histogram: ComputePipeline::from_embedded_specialized(
                ctx,
                "sort_histogram",
                &defines,
                &by_binding([
                    (bindings::sort_histogram::META, storage),
                    (bindings::sort_histogram::KEYS, read),
                    (bindings::sort_histogram::HIST, storage),
                ])?,
                pass_push,
                &spec,
            )?,
            scatter: ComputePipeline::from_embedded_specialized(
                ctx,
                "sort_scatter",
                &defines,
                &by_binding([
                    (bindings::sort_scatter::META, storage),
                    (bindings::sort_scatter::KEYS_IN, read),
                    (bindings::sort_scatter::VALUES_IN, read),
                    (bindings::sort_scatter::OFFSETS, storage),
                    (bindings::sort_scatter::KEYS_OUT, write),
                    (bindings::sort_scatter::VALUES_OUT, write),
                ])?,
                pass_push,
                &spec,
            )?,
            copy: ComputePipeline::from_embedded_specialized(
                ctx,
                "sort_copy",
                &defines,
                &by_binding([
                    (bindings::sort_copy::META, storage),
                    (bindings::sort_copy::KEYS_IN, read),
                    (bindings::sort_copy::VALUES_IN, read),
                    (bindings::sort_copy::KEYS_OUT, write),
                    (bindings::sort_copy::VALUES_OUT, write),
                ])?,
                &crate::core::shader_interface::NO_PUSH_CONSTANTS,
                &spec,
            )?,
            scan: Scan::new(ctx)?,
            max_groups_x: ctx.info().max_workgroup_count[0],
        })
    }

    /// Pretends `maxComputeWorkGroupCount[0]` is `max_x` (at most the real limit), so
    /// tests can exercise the 2D dispatch grid with small inputs.
    pub fn with_dispatch_limit(mut self, max_x: u32) -> Self {
        self.max_groups_x = self.max_groups_x.min(max_x.max(1));
        self.scan = self.scan.with_dispatch_limit(max_x);
        self
    }

    /// Scratch bytes the default configuration needs for up to `max_n` elements.
    pub fn scratch_size(max_n: u32) -> u64 {
        Self::scratch_size_with(&DEFAULT_SORT_CONFIG, max_n)
    }

    /// Scratch bytes `config` needs for up to `max_n` elements.
    pub fn scratch_size_with(config: &SortConfig, max_n: u32) -> u64 {
        ScratchLayout::new(config, max_n).total
    }

    /// Scratch bytes this instance's configuration needs for up to `max_n` elements.
    pub fn scratch_size_for(&self, max_n: u32) -> u64 {
        ScratchLayout::new(&self.config, max_n).total
    }

    /// Byte ranges `(offset, size)` of the keys and the values inside the scratch of a
    /// sort of up to `max_n` elements under `config` (for [`SortTexels`]' views).
    pub fn scratch_pair_ranges(config: &SortConfig, max_n: u32) -> [(u64, u64); 2] {
        let layout = ScratchLayout::new(config, max_n);
        [layout.keys, layout.values]
    }

    /// The device memory a sort of `n` pairs by `key_bits` bits reads and writes, its
    /// scratch laid out for `max_n` (the digit tables, and so their scans, are sized by
    /// it): per pass, the histogram reads the keys and writes the digit table, the scan
    /// of the table, and the scatter reads the pairs and the scanned table and writes the
    /// pairs; after an odd number of passes the copy back. The setup's few words and the
    /// meta words each block reads are left out.
    pub fn traffic(config: &SortConfig, n: u32, max_n: u32, key_bits: u32) -> Traffic {
        let passes = u64::from(key_bits.div_ceil(config.radix_bits));
        if n == 0 || passes == 0 {
            return Traffic::default();
        }
        let layout = ScratchLayout::new(config, max_n.max(n));
        let table_len = layout.hist_stride << config.radix_bits;
        let table = u64::from(table_len) * 4;
        let keys = u64::from(n) * config.key_bytes();
        let pairs = keys + u64::from(n) * 4;
        let histogram = Traffic::new(keys, table);
        let scatter = Traffic::new(pairs + table, pairs);
        let pass = histogram + Scan::traffic(table_len) + scatter;
        let copy = if passes % 2 == 1 {
            Traffic::new(pairs, pairs)
        } else {
            Traffic::default()
        };
        pass.times(passes) + copy
    }

    /// The tunables in use.
    pub fn config(&self) -> SortConfig {
        self.config
    }

    /// Records a stable sort of the job's `count` (key, value) pairs by its key bits (a
    /// range inside the 64- or 32-bit key; an empty range records nothing). `keys` holds
    /// `uvec2 (lo, hi)` per element (one `uint` for 32-bit keys), `values` one u32; both
    /// hold the sorted result afterwards. Elements past the count are not touched.
    /// `scratch` must hold
    /// [`RadixSort::scratch_size_for`]`(max_n)` bytes (max_n = the host count or the
    /// device capacity).
    ///
    /// Barrier contract:
    /// - Before: the sort opens with a barrier from compute-shader and transfer
    ///   writes (and compute/indirect reads, for reusing `scratch`) to its own uses,
    ///   so keys, values and the count written by earlier compute shaders or
    ///   copies/fills in the same queue need no extra barrier. Host writes are covered
    ///   by queue submission as usual.
    /// - After: the last writes to `keys`/`values` are compute-shader storage writes
    ///   and **the sort places no trailing barrier**: the caller records one from
    ///   [`Access::ComputeWrite`] to its next use (e.g. `ComputeRead`, `TransferRead`).
    ///   `scratch` must not be reused before such a barrier either.
    pub fn record(&self, ctx: &GpuContext, cmd: vk::CommandBuffer, job: &SortJob) -> GpuResult<()> {
        self.record_impl(ctx, cmd, job, None)
    }

    /// [`RadixSort::record`] with every dispatch wrapped in its own timer stage
    /// (`sort histogram`, `sort scan`, `sort scatter`, ... per pass), for profiling.
    pub fn record_timed(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        job: &SortJob,
        timer: &mut GpuTimer,
    ) -> GpuResult<()> {
        self.record_impl(ctx, cmd, job, Some(timer))
    }

    fn record_impl(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        job: &SortJob,
        mut timer: Option<&mut GpuTimer>,
    ) -> GpuResult<()> {
        let Some((max_n, count_slot)) = self.check_job(job)? else {
            return Ok(());
        };
        let (first_bit, end_bit) = (job.bits.start, job.bits.end);
        let key_bits = end_bit.saturating_sub(first_bit);
        let layout = ScratchLayout::new(&self.config, max_n);
        self.check_sizes(job, max_n, &layout)?;
        let views = SortViews::new(&self.config, job, max_n, &layout);
        let mut stage =
            |name: &str, body: &mut dyn FnMut(vk::CommandBuffer) -> GpuResult<()>| match timer
                .as_deref_mut()
            {
                Some(t) => t.stage(ctx, cmd, name, body),
                None => body(cmd),
            };
        self.record_setup(ctx, cmd, &views, max_n, count_slot)?;
        let passes = key_bits.div_ceil(self.config.radix_bits);
        for pass in 0..passes {
            let shift = first_bit + pass * self.config.radix_bits;
            let push = SortPassPush {
                shift,
                bits: self.config.radix_bits.min(end_bit - shift),
                hist_stride: layout.hist_stride,
                pad: 0,
            };
            let (src, dst) = if pass % 2 == 0 {
                (views.user, views.tmp)
            } else {
                (views.tmp, views.user)
            };
            self.record_pass(ctx, cmd, &mut stage, (&views, &layout), &push, (src, dst))?;
            if pass + 1 < passes || passes % 2 == 1 {
                // The scattered pairs are the next pass's (or the copy's) input.
                pass_barrier(ctx, cmd);
            }
        }
        if passes % 2 == 1 {
            stage("sort copy", &mut |cmd| {
                self.copy.dispatch_indirect_resources(
                    ctx,
                    cmd,
                    &by_binding([
                        (bindings::sort_copy::META, Resource::Buffer(views.meta)),
                        (bindings::sort_copy::KEYS_IN, views.tmp.0),
                        (bindings::sort_copy::VALUES_IN, views.tmp.1),
                        (bindings::sort_copy::KEYS_OUT, views.user.0),
                        (bindings::sort_copy::VALUES_OUT, views.user.1),
                    ])?,
                    &[],
                    views.dispatch_args,
                )
            })?;
        }
        Ok(())
    }

    /// Refuses a job this sort cannot run (texel I/O that does not match, bits outside the
    /// key, a device count outside its buffer); `None` when there is nothing to sort, else
    /// the most elements and the device count's buffer and offset, if any.
    #[allow(clippy::type_complexity)]
    fn check_job<'a>(
        &self,
        job: &SortJob<'a>,
    ) -> GpuResult<Option<(u32, Option<(&'a GpuBuffer, u64)>)>> {
        let SortJob {
            count,
            ref bits,
            texels,
            ..
        } = *job;
        if self.config.texel_io != texels.is_some() {
            return Err(GpuError::InvalidArgument(format!(
                "a sort {} texel I/O needs {} texel views",
                if self.config.texel_io {
                    "with"
                } else {
                    "without"
                },
                if self.config.texel_io { "its" } else { "no" },
            )));
        }
        let (first_bit, end_bit) = (bits.start, bits.end);
        let key_bits = end_bit.saturating_sub(first_bit);
        let width = self.config.key_words * 32;
        if end_bit > width || first_bit > end_bit {
            return Err(GpuError::InvalidArgument(format!(
                "radix sort bits {first_bit}..{end_bit} are not a range inside the {width}-bit key"
            )));
        }
        let (max_n, count_slot) = match count {
            Count::Host(n) => (n, None),
            Count::Device {
                buffer,
                offset,
                max_n,
            } => {
                if offset % 4 != 0 || offset + 4 > buffer.size() {
                    return Err(GpuError::InvalidArgument(format!(
                        "sort count offset {offset} is not a u32 slot inside '{}' ({} bytes)",
                        buffer.name(),
                        buffer.size()
                    )));
                }
                (max_n, Some((buffer, offset)))
            }
        };
        if max_n == 0 || key_bits == 0 {
            return Ok(None);
        }
        Ok(Some((max_n, count_slot)))
    }

    /// Refuses keys, values or scratch too small for `max_n` elements.
    fn check_sizes(&self, job: &SortJob, max_n: u32, layout: &ScratchLayout) -> GpuResult<()> {
        let checks = [
            (job.keys, u64::from(max_n) * self.config.key_bytes(), "keys"),
            (job.values, u64::from(max_n) * 4, "values"),
            (job.scratch, layout.total, "scratch"),
        ];
        for (buffer, need, what) in checks {
            if buffer.size() < need {
                return Err(GpuError::InvalidArgument(format!(
                    "radix sort of up to {max_n} elements needs {need} bytes of {what}, \
                     buffer '{}' has {}",
                    buffer.name(),
                    buffer.size()
                )));
            }
        }
        Ok(())
    }

    /// The entry barrier, the histogram cleared for a device count, and the setup
    /// dispatch that writes the meta words (count, groups, indirect arguments).
    fn record_setup(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        views: &SortViews,
        max_n: u32,
        count_slot: Option<(&GpuBuffer, u64)>,
    ) -> GpuResult<()> {
        // Entry barrier (see the contract above).
        barrier_uses(
            ctx,
            cmd,
            &[
                Access::ComputeReadWrite,
                Access::TransferWrite,
                Access::IndirectRead,
            ],
            &[
                Access::ComputeReadWrite,
                Access::ComputeSampledRead,
                Access::TransferWrite,
            ],
        );
        let hist = views.hist;
        if count_slot.is_some() {
            // Blocks past the device count never write their histogram column, and the
            // scan covers the whole capacity: those columns must read as zero.
            hist.buffer.fill(ctx, cmd, hist.offset, hist.size, 0);
            barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);
        }
        let setup_push = SortSetupPush {
            host_n: max_n,
            count_index: match count_slot {
                Some((_, offset)) => u32::try_from(offset / 4).map_err(|_| {
                    GpuError::InvalidArgument("sort count offset beyond 16 GiB".into())
                })?,
                None => u32::MAX,
            },
            max_n,
            max_groups_x: self.max_groups_x,
        };
        let count_binding = count_slot.map_or(views.meta, |(b, _)| b.whole());
        self.setup.dispatch(
            ctx,
            cmd,
            &by_binding([
                (bindings::sort_setup::COUNT, count_binding),
                (bindings::sort_setup::META, views.meta),
            ])?,
            bytemuck::bytes_of(&setup_push),
            [1, 1, 1],
        )?;
        // The meta words feed both shaders and the indirect dispatches.
        barrier_uses(
            ctx,
            cmd,
            &[Access::ComputeWrite],
            &[Access::ComputeRead, Access::IndirectRead],
        );
        Ok(())
    }

    /// One radix pass from `src` to `dst`: histogram, scan of the histogram, scatter,
    /// with a barrier between each (none after the scatter: the caller places it).
    fn record_pass(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        stage: &mut StageFn,
        (views, layout): (&SortViews, &ScratchLayout),
        push: &SortPassPush,
        (src, dst): (KeysAndValues, KeysAndValues),
    ) -> GpuResult<()> {
        let (meta, hist, offsets) = (views.meta, views.hist, views.offsets);
        stage("sort histogram", &mut |cmd| {
            self.histogram.dispatch_indirect_resources(
                ctx,
                cmd,
                &by_binding([
                    (bindings::sort_histogram::META, Resource::Buffer(meta)),
                    (bindings::sort_histogram::KEYS, src.0),
                    (bindings::sort_histogram::HIST, Resource::Buffer(hist)),
                ])?,
                bytemuck::bytes_of(push),
                views.dispatch_args,
            )
        })?;
        pass_barrier(ctx, cmd);
        stage("sort scan", &mut |cmd| {
            self.scan.record(
                ctx,
                cmd,
                hist,
                offsets,
                (views.scratch, layout.scan_total),
                views.scan_scratch,
                layout.hist_stride << self.config.radix_bits,
            )
        })?;
        pass_barrier(ctx, cmd);
        stage("sort scatter", &mut |cmd| {
            self.scatter.dispatch_indirect_resources(
                ctx,
                cmd,
                &by_binding([
                    (bindings::sort_scatter::META, Resource::Buffer(meta)),
                    (bindings::sort_scatter::KEYS_IN, src.0),
                    (bindings::sort_scatter::VALUES_IN, src.1),
                    (bindings::sort_scatter::OFFSETS, Resource::Buffer(offsets)),
                    (bindings::sort_scatter::KEYS_OUT, dst.0),
                    (bindings::sort_scatter::VALUES_OUT, dst.1),
                ])?,
                bytemuck::bytes_of(push),
                views.dispatch_args,
            )
        })
    }
}

/// Records one dispatch, in its own timer stage when the sort is timed.
type StageFn<'s> =
    dyn FnMut(&str, &mut dyn FnMut(vk::CommandBuffer) -> GpuResult<()>) -> GpuResult<()> + 's;

/// Keys and values as a pass binds them.
type KeysAndValues<'a> = (Resource<'a>, Resource<'a>);

/// A sort's buffers as its dispatches bind them: the scratch buffer's regions, and the
/// keys and values (the caller's and the scratch copies) as buffer slices or texel views.
struct SortViews<'a> {
    scratch: &'a GpuBuffer,
    meta: BufferSlice<'a>,
    dispatch_args: BufferSlice<'a>,
    hist: BufferSlice<'a>,
    offsets: BufferSlice<'a>,
    scan_scratch: BufferSlice<'a>,
    user: KeysAndValues<'a>,
    tmp: KeysAndValues<'a>,
}

impl<'a> SortViews<'a> {
    fn new(config: &SortConfig, job: &SortJob<'a>, max_n: u32, layout: &ScratchLayout) -> Self {
        let SortJob {
            keys,
            values,
            scratch,
            texels,
            ..
        } = *job;
        let meta = scratch.slice(0, META_BYTES);
        let dispatch_args = scratch.slice(u64::from(META_DISPATCH) * 4, 12);
        let tmp_keys = scratch.slice(layout.keys.0, layout.keys.1);
        let tmp_values = scratch.slice(layout.values.0, layout.values.1);
        let hist = scratch.slice(layout.hist.0, layout.hist.1);
        let offsets = scratch.slice(layout.offsets.0, layout.offsets.1);
        let scan_scratch = scratch.slice(layout.scan.0, layout.scan.1);
        let user_keys = keys.slice(0, u64::from(max_n) * config.key_bytes());
        let user_values = values.slice(0, u64::from(max_n) * 4);
        // The keys and values as bound: texel views, or buffer slices.
        let (user, tmp) = match texels {
            Some(t) => (
                (
                    Resource::TexelBuffer(t.keys),
                    Resource::TexelBuffer(t.values),
                ),
                (
                    Resource::TexelBuffer(t.scratch_keys),
                    Resource::TexelBuffer(t.scratch_values),
                ),
            ),
            None => (
                (Resource::Buffer(user_keys), Resource::Buffer(user_values)),
                (Resource::Buffer(tmp_keys), Resource::Buffer(tmp_values)),
            ),
        };
        SortViews {
            scratch,
            meta,
            dispatch_args,
            hist,
            offsets,
            scan_scratch,
            user,
            tmp,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn traffic_counts_each_pass_and_the_copy_back() {
        // 4096 pairs of 32-bit keys: one block, a 256-entry digit table (1 KiB), scanned
        // by one workgroup.
        let (keys, pairs, table) = (16384, 32768, 1024);
        let one_pass = RadixSort::traffic(&SORT_CONFIG_32, 4096, 4096, 8);
        // Histogram, scan, scatter, and the copy back after an odd pass count.
        let read = keys + table + (pairs + table) + pairs;
        let written = table + (table + 4) + pairs + pairs;
        assert_eq!(one_pass, Traffic::new(read, written));
        let two_passes = RadixSort::traffic(&SORT_CONFIG_32, 4096, 4096, 16);
        let pass = Traffic::new(keys + table + pairs + table, table + table + 4 + pairs);
        assert_eq!(two_passes, pass.times(2));
        // The digit tables follow the capacity, not the count.
        let roomy = RadixSort::traffic(&SORT_CONFIG_32, 4096, 8 * 4096, 16);
        assert!(roomy.total() > two_passes.total());
        assert_eq!(
            RadixSort::traffic(&SORT_CONFIG_32, 0, 4096, 16),
            Traffic::default()
        );
    }
}
