//! RAII storage buffers backed by gpu-allocator, plus upload/read-back helpers. The
//! memory each buffer gets, and the flushes and invalidates its mapping needs, come from
//! [`super::memory`].

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::device::Shared;
use super::memory::{self, MemoryPlan};
use super::sync::{barrier, Access};
use super::{GpuContext, GpuError, GpuResult, VkContext};

/// Where a buffer's memory lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemoryKind {
    /// Device-local; used by shaders. Never mapped where device memory is not
    /// host-visible: the host reaches it through staging ([`GpuBuffer::upload`],
    /// [`GpuBuffer::read`]).
    Device,
    /// Host-visible, written by the CPU and read by the GPU.
    Upload,
    /// Host-visible, written by the GPU and read by the CPU.
    Readback,
}

/// A named Vulkan buffer with its memory; freed on drop.
pub struct GpuBuffer {
    shared: Arc<Shared>,
    buffer: vk::Buffer,
    allocation: Option<Allocation>,
    size: u64,
    kind: MemoryKind,
    plan: MemoryPlan,
    name: String,
    /// Flushes and invalidates issued (see [`GpuBuffer::host_syncs`]).
    flushes: AtomicU32,
    invalidates: AtomicU32,
}

/// A byte range of a buffer, as bound to a shader.
#[derive(Clone, Copy)]
pub struct BufferSlice<'a> {
    /// The buffer.
    pub buffer: &'a GpuBuffer,
    /// Start in bytes (must respect minStorageBufferOffsetAlignment when bound).
    pub offset: u64,
    /// Length in bytes.
    pub size: u64,
}

impl<'a> From<&'a GpuBuffer> for BufferSlice<'a> {
    fn from(buffer: &'a GpuBuffer) -> Self {
        buffer.whole()
    }
}

impl GpuBuffer {
    /// Creates a buffer of `size` bytes (rounded up to at least 4) usable as storage,
    /// transfer source/destination and indirect-dispatch arguments.
    pub fn new(ctx: &GpuContext, name: &str, size: u64, kind: MemoryKind) -> GpuResult<Self> {
        let size = size.max(4);
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_SRC
            | vk::BufferUsageFlags::TRANSFER_DST
            | vk::BufferUsageFlags::INDIRECT_BUFFER
            | vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER
            | vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER;
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        let device = &ctx.shared.device;
        // SAFETY: valid create info; the buffer is destroyed in Drop or on error below.
        let buffer = unsafe { device.create_buffer(&info, None) }.vk("vkCreateBuffer")?;
        // SAFETY: the buffer was just created from this device.
        let requirements = unsafe { device.get_buffer_memory_requirements(buffer) };
        let plan = match memory::plan(ctx.info(), kind, requirements.memory_type_bits, name) {
            Ok(p) => p,
            Err(e) => {
                // SAFETY: unused buffer with no memory bound.
                unsafe { device.destroy_buffer(buffer, None) };
                return Err(e);
            }
        };
        // The chosen type only (gpu-allocator's own choice insists on coherent memory
        // for host access), in whole atoms where the host syncs by hand.
        let requirements = plan.requirements(requirements);
        let allocation = GpuContext::check_budget(&ctx.shared, name, requirements.size)
            .and_then(|()| {
                ctx.shared
                    .allocator
                    .lock()
                    .map_err(|_| GpuError::Internal("allocator mutex poisoned".into()))
            })
            .and_then(|mut alloc| {
                alloc
                    .allocate(&AllocationCreateDesc {
                        name,
                        requirements,
                        location: MemoryLocation::Unknown,
                        linear: true,
                        allocation_scheme: AllocationScheme::GpuAllocatorManaged,
                    })
                    .map_err(|source| GpuError::from_alloc(&ctx.shared, name, size, source))
            });
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: unused buffer with no memory bound.
                unsafe { device.destroy_buffer(buffer, None) };
                return Err(e);
            }
        };
        let this = Self {
            shared: ctx.shared.clone(),
            buffer,
            allocation: Some(allocation),
            size,
            kind,
            plan,
            name: name.to_string(),
            flushes: AtomicU32::new(0),
            invalidates: AtomicU32::new(0),
        };
        let alloc = this
            .allocation
            .as_ref()
            .ok_or_else(|| GpuError::Internal("allocation missing".into()))?;
        // SAFETY: memory and offset come from an allocation made for these requirements;
        // on error `this` drops and frees both.
        unsafe { device.bind_buffer_memory(buffer, alloc.memory(), alloc.offset()) }
            .vk("vkBindBufferMemory")?;
        ctx.set_name(buffer, name);
        Ok(this)
    }

    /// Creates a device-local buffer holding `data` (uploaded through a staging buffer).
    pub fn from_slice<T: bytemuck::Pod>(
        ctx: &GpuContext,
        name: &str,
        data: &[T],
    ) -> GpuResult<Self> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let buffer = Self::new(ctx, name, bytes.len() as u64, MemoryKind::Device)?;
        buffer.upload(ctx, data)?;
        Ok(buffer)
    }

    /// Copies `data` into the start of this buffer through a staging buffer and waits.
    pub fn upload<T: bytemuck::Pod>(&self, ctx: &GpuContext, data: &[T]) -> GpuResult<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.is_empty() {
            return Ok(());
        }
        if bytes.len() as u64 > self.size {
            return Err(GpuError::InvalidArgument(format!(
                "uploading {} bytes into buffer '{}' of {} bytes",
                bytes.len(),
                self.name,
                self.size
            )));
        }
        let mut staging = Self::new(
            ctx,
            &format!("{} (upload staging)", self.name),
            bytes.len() as u64,
            MemoryKind::Upload,
        )?;
        staging.write_mapped(bytes)?;
        ctx.submit_and_wait("upload", |cmd| {
            // Earlier GPU work on this buffer must finish before it is overwritten.
            barrier(ctx, cmd, Access::Any, Access::TransferWrite);
            let region = [vk::BufferCopy::default().size(bytes.len() as u64)];
            // SAFETY: both buffers are alive and large enough.
            unsafe {
                ctx.device()
                    .cmd_copy_buffer(cmd, staging.buffer, self.buffer, &region)
            };
            // Make the copy visible to whatever the next submission does with it.
            barrier(ctx, cmd, Access::TransferWrite, Access::Any);
            Ok(())
        })
    }

    /// Reads the first `count` elements back through a staging buffer (waits for the GPU).
    pub fn read<T: bytemuck::Pod>(&self, ctx: &GpuContext, count: usize) -> GpuResult<Vec<T>> {
        let bytes = (count * std::mem::size_of::<T>()) as u64;
        if bytes > self.size {
            return Err(GpuError::InvalidArgument(format!(
                "reading {bytes} bytes from buffer '{}' of {} bytes",
                self.name, self.size
            )));
        }
        if bytes == 0 {
            return Ok(Vec::new());
        }
        let staging = Self::new(
            ctx,
            &format!("{} (read-back staging)", self.name),
            bytes,
            MemoryKind::Readback,
        )?;
        ctx.submit_and_wait("read back", |cmd| {
            barrier(ctx, cmd, Access::Any, Access::TransferRead);
            let region = [vk::BufferCopy::default().size(bytes)];
            // SAFETY: both buffers are alive and large enough.
            unsafe {
                ctx.device()
                    .cmd_copy_buffer(cmd, self.buffer, staging.buffer, &region)
            };
            barrier(ctx, cmd, Access::TransferWrite, Access::HostRead);
            Ok(())
        })?;
        let mapped = staging.mapped_range(0, bytes)?;
        let mut out = vec![T::zeroed(); count];
        bytemuck::cast_slice_mut::<T, u8>(&mut out).copy_from_slice(&mapped[..bytes as usize]);
        Ok(out)
    }

    /// Reads all elements that fit in the buffer.
    pub fn read_all<T: bytemuck::Pod>(&self, ctx: &GpuContext) -> GpuResult<Vec<T>> {
        self.read(ctx, (self.size / std::mem::size_of::<T>() as u64) as usize)
    }

    /// Writes bytes at the start of a host-visible buffer's mapping, flushed when the
    /// memory is not coherent. The caller submits the GPU work that reads them afterwards.
    pub fn write_mapped(&mut self, bytes: &[u8]) -> GpuResult<()> {
        self.write_mapped_with(bytes.len() as u64, |dst| dst.copy_from_slice(bytes))
    }

    /// Lets `fill` write the first `len` bytes of a host-visible buffer's mapping in place
    /// (no intermediate copy), then flushes them when the memory is not coherent. The
    /// caller submits the GPU work that reads them afterwards.
    pub fn write_mapped_with(&mut self, len: u64, fill: impl FnOnce(&mut [u8])) -> GpuResult<()> {
        self.check_mappable()?;
        let name = self.name.clone();
        if len > self.size {
            return Err(GpuError::InvalidArgument(format!(
                "writing {len} bytes into mapped buffer '{name}' of {}",
                self.size
            )));
        }
        let slice = self
            .allocation
            .as_mut()
            .and_then(|a| a.mapped_slice_mut())
            .ok_or_else(|| GpuError::InvalidArgument(format!("buffer '{name}' is not mapped")))?;
        fill(&mut slice[..len as usize]);
        self.sync_host(0, len, HostSync::Flush)
    }

    /// The whole mapping of a host-visible buffer, invalidated first when the memory is
    /// not coherent: call it after the GPU writes it shows were waited for (a fence), as
    /// each call reads them again.
    pub fn mapped(&self) -> GpuResult<&[u8]> {
        self.mapped_range(0, self.size)
    }

    /// Bytes `offset..offset + len` of a host-visible buffer's mapping, invalidated first
    /// (rounded out to whole `nonCoherentAtomSize`s) when the memory is not coherent; as
    /// [`Self::mapped`], after the GPU's writes were waited for.
    pub fn mapped_range(&self, offset: u64, len: u64) -> GpuResult<&[u8]> {
        self.check_mappable()?;
        let end = offset
            .checked_add(len)
            .filter(|&e| e <= self.size)
            .ok_or_else(|| {
                GpuError::InvalidArgument(format!(
                    "reading bytes {offset}..+{len} of mapped buffer '{}' of {}",
                    self.name, self.size
                ))
            })?;
        self.sync_host(offset, len, HostSync::Invalidate)?;
        let slice = self
            .allocation
            .as_ref()
            .and_then(|a| a.mapped_slice())
            .ok_or_else(|| {
                GpuError::InvalidArgument(format!("buffer '{}' is not mapped", self.name))
            })?;
        Ok(&slice[offset as usize..end as usize])
    }

    /// The one check before any mapping is touched: a device buffer on a device whose
    /// device-local memory is not host-visible (real or emulated) is never mapped.
    fn check_mappable(&self) -> GpuResult<()> {
        if self.plan.mappable {
            return Ok(());
        }
        Err(GpuError::Internal(format!(
            "buffer '{}' ({:?}) is not host-visible on this device; the host reaches it through a staging buffer (GpuBuffer::upload / read)",
            self.name, self.kind
        )))
    }

    /// Flushes (after host writes) or invalidates (before host reads) bytes
    /// `offset..offset + len` of the mapping when the memory needs it, rounded out to
    /// whole atoms of the memory object ([`memory::atom_range`]).
    fn sync_host(&self, offset: u64, len: u64, what: HostSync) -> GpuResult<()> {
        if !self.plan.explicit_sync || len == 0 {
            return Ok(());
        }
        let alloc = self
            .allocation
            .as_ref()
            .ok_or_else(|| GpuError::Internal("allocation missing".into()))?;
        let (start, size) =
            memory::atom_range(alloc.offset(), alloc.size(), offset, len, self.plan.atom);
        // SAFETY: the handle is only named in the range below, while the allocation lives.
        let memory = unsafe { alloc.memory() };
        let range = [vk::MappedMemoryRange::default()
            .memory(memory)
            .offset(start)
            .size(size)];
        let device = &self.shared.device;
        match what {
            HostSync::Flush => {
                self.flushes.fetch_add(1, Ordering::Relaxed);
                // SAFETY: the memory is mapped (gpu-allocator maps host-visible blocks
                // whole) and the range lies inside this buffer's allocation, in atoms.
                unsafe { device.flush_mapped_memory_ranges(&range) }.vk("vkFlushMappedMemoryRanges")
            }
            HostSync::Invalidate => {
                self.invalidates.fetch_add(1, Ordering::Relaxed);
                // SAFETY: as for the flush.
                unsafe { device.invalidate_mapped_memory_ranges(&range) }
                    .vk("vkInvalidateMappedMemoryRanges")
            }
        }
    }

    /// The memory this buffer got and what its mapping needs ([`super::memory`]).
    pub fn memory_plan(&self) -> MemoryPlan {
        self.plan
    }

    /// Flushes and invalidates issued on this buffer's mapping so far.
    pub fn host_syncs(&self) -> (u32, u32) {
        (
            self.flushes.load(Ordering::Relaxed),
            self.invalidates.load(Ordering::Relaxed),
        )
    }

    /// Records vkCmdFillBuffer of `value` over `size` bytes from `offset` (multiples of 4,
    /// or `vk::WHOLE_SIZE`). The caller places barriers (TransferWrite).
    pub fn fill(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        offset: u64,
        size: u64,
        value: u32,
    ) {
        // SAFETY: the buffer is alive and has TRANSFER_DST usage.
        unsafe {
            ctx.device()
                .cmd_fill_buffer(cmd, self.buffer, offset, size, value)
        };
    }

    /// Size in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// The raw handle.
    pub fn handle(&self) -> vk::Buffer {
        self.buffer
    }

    /// The debug name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Memory kind.
    pub fn kind(&self) -> MemoryKind {
        self.kind
    }

    /// The whole buffer as a slice.
    pub fn whole(&self) -> BufferSlice<'_> {
        BufferSlice {
            buffer: self,
            offset: 0,
            size: self.size,
        }
    }

    /// A byte range of the buffer.
    pub fn slice(&self, offset: u64, size: u64) -> BufferSlice<'_> {
        BufferSlice {
            buffer: self,
            offset,
            size,
        }
    }
}

impl Drop for GpuBuffer {
    fn drop(&mut self) {
        // SAFETY: the owner guarantees the GPU no longer uses this buffer (the usual
        // Vulkan rule); memory is freed after the buffer is destroyed.
        unsafe { self.shared.device.destroy_buffer(self.buffer, None) };
        if let Some(allocation) = self.allocation.take() {
            if let Ok(mut alloc) = self.shared.allocator.lock() {
                if let Err(e) = alloc.free(allocation) {
                    crate::core::console::note!(
                        "verisplat: freeing buffer '{}' failed: {e}",
                        self.name
                    );
                }
            }
        }
    }
}

/// What the host does to a mapping that is not coherent.
#[derive(Clone, Copy)]
enum HostSync {
    /// After host writes, before the GPU reads.
    Flush,
    /// After the GPU's writes were waited for, before the host reads.
    Invalidate,
}

/// A typed view of a buffer range for `texelFetch` (uniform texel buffer); destroyed on drop.
pub struct BufferView {
    shared: Arc<Shared>,
    view: vk::BufferView,
}

impl BufferView {
    /// Views `size` bytes of `buffer` from `offset` as texels of `format`.
    pub fn new(
        ctx: &GpuContext,
        buffer: &GpuBuffer,
        format: vk::Format,
        offset: u64,
        size: u64,
    ) -> GpuResult<Self> {
        let info = vk::BufferViewCreateInfo::default()
            .buffer(buffer.handle())
            .format(format)
            .offset(offset)
            .range(size);
        // SAFETY: the buffer was created with texel buffer usages; the view is
        // destroyed in Drop, and its owner keeps the buffer alive as long as the view.
        let view = unsafe { ctx.shared.device.create_buffer_view(&info, None) }
            .vk("vkCreateBufferView")?;
        ctx.set_name(view, buffer.name());
        Ok(BufferView {
            shared: ctx.shared.clone(),
            view,
        })
    }

    /// The Vulkan handle.
    pub fn handle(&self) -> vk::BufferView {
        self.view
    }
}

impl Drop for BufferView {
    fn drop(&mut self) {
        // SAFETY: the owner guarantees no submitted work still uses the view.
        unsafe { self.shared.device.destroy_buffer_view(self.view, None) };
    }
}
