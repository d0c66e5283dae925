//! RAII 2D storage images (the blend stage's outputs) and their layout transition and
//! copy-out helpers.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::device::Shared;
use super::{memory, GpuBuffer, GpuContext, GpuError, GpuResult, MemoryKind, VkContext};

/// A device-local 2D image with a view, usable as a storage image and copy source.
pub struct GpuImage {
    shared: Arc<Shared>,
    image: vk::Image,
    view: vk::ImageView,
    allocation: Option<Allocation>,
    width: u32,
    height: u32,
    texel_bytes: u64,
    name: String,
}

impl GpuImage {
    /// Creates a `width` x `height` image of `format` (R32G32B32A32_SFLOAT or R32_SFLOAT).
    pub fn new(
        ctx: &GpuContext,
        name: &str,
        width: u32,
        height: u32,
        format: vk::Format,
    ) -> GpuResult<Self> {
        let texel_bytes = match format {
            vk::Format::R32G32B32A32_SFLOAT => 16,
            vk::Format::R32_SFLOAT => 4,
            other => {
                return Err(GpuError::InvalidArgument(format!(
                    "image '{name}': unsupported format {other:?}"
                )))
            }
        };
        let device = &ctx.shared.device;
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D {
                width,
                height,
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::TRANSFER_SRC)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid create info; destroyed in Drop (or below on error).
        let image = unsafe { device.create_image(&info, None) }.vk("vkCreateImage")?;
        let mut this = GpuImage {
            shared: ctx.shared.clone(),
            image,
            view: vk::ImageView::null(),
            allocation: None,
            width,
            height,
            texel_bytes,
            name: name.to_string(),
        };
        // SAFETY: the image was just created from this device.
        let requirements = unsafe { device.get_image_memory_requirements(image) };
        // Device memory as for device buffers (never mapped).
        let plan = memory::plan(
            ctx.info(),
            MemoryKind::Device,
            requirements.memory_type_bits,
            name,
        )?;
        let requirements = plan.requirements(requirements);
        let bytes = requirements.size;
        GpuContext::check_budget(&ctx.shared, name, bytes)?;
        let allocation = ctx
            .shared
            .allocator
            .lock()
            .map_err(|_| GpuError::Internal("allocator mutex poisoned".into()))?
            .allocate(&AllocationCreateDesc {
                name,
                requirements,
                location: MemoryLocation::Unknown,
                linear: false,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
            .map_err(|source| GpuError::from_alloc(&ctx.shared, name, bytes, source))?;
        // SAFETY: memory from an allocation made for this image's requirements.
        unsafe { device.bind_image_memory(image, allocation.memory(), allocation.offset()) }
            .vk("vkBindImageMemory")?;
        this.allocation = Some(allocation);
        let view_info = vk::ImageViewCreateInfo::default()
            .image(image)
            .view_type(vk::ImageViewType::TYPE_2D)
            .format(format)
            .subresource_range(Self::range());
        // SAFETY: the image has memory bound; the view is destroyed in Drop.
        this.view =
            unsafe { device.create_image_view(&view_info, None) }.vk("vkCreateImageView")?;
        ctx.set_name(image, name);
        ctx.set_name(this.view, name);
        Ok(this)
    }

    fn range() -> vk::ImageSubresourceRange {
        vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: 1,
        }
    }

    /// The image view bound as a storage image.
    pub fn view(&self) -> vk::ImageView {
        self.view
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Bytes of texel data (what a copy to a buffer writes).
    pub fn bytes(&self) -> u64 {
        u64::from(self.width) * u64::from(self.height) * self.texel_bytes
    }

    /// The image's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Records a layout transition with the given sync2 scopes.
    fn transition(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        src: (vk::PipelineStageFlags2, vk::AccessFlags2),
        dst: (vk::PipelineStageFlags2, vk::AccessFlags2),
        layouts: (vk::ImageLayout, vk::ImageLayout),
    ) {
        let barrier = [vk::ImageMemoryBarrier2::default()
            .src_stage_mask(src.0)
            .src_access_mask(src.1)
            .dst_stage_mask(dst.0)
            .dst_access_mask(dst.1)
            .old_layout(layouts.0)
            .new_layout(layouts.1)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(self.image)
            .subresource_range(Self::range())];
        let dep = vk::DependencyInfo::default().image_memory_barriers(&barrier);
        // SAFETY: cmd is recording; the image is alive.
        unsafe { ctx.device().cmd_pipeline_barrier2(cmd, &dep) };
    }

    /// Records a transition from "whatever the last frame left" (UNDEFINED: its contents
    /// are overwritten) to GENERAL for storage writes, ordered after the previous frame's
    /// copy out of it.
    pub fn transition_to_general(&self, ctx: &GpuContext, cmd: vk::CommandBuffer) {
        self.transition(
            ctx,
            cmd,
            (
                vk::PipelineStageFlags2::ALL_TRANSFER,
                vk::AccessFlags2::NONE,
            ),
            (
                vk::PipelineStageFlags2::COMPUTE_SHADER,
                vk::AccessFlags2::SHADER_STORAGE_WRITE,
            ),
            (vk::ImageLayout::UNDEFINED, vk::ImageLayout::GENERAL),
        );
    }

    /// Records the transition from storage writes (GENERAL) to a copy source
    /// (TRANSFER_SRC_OPTIMAL), making the compute writes visible to the copy.
    pub fn transition_for_copy(&self, ctx: &GpuContext, cmd: vk::CommandBuffer) {
        self.transition(
            ctx,
            cmd,
            (
                vk::PipelineStageFlags2::COMPUTE_SHADER,
                vk::AccessFlags2::SHADER_STORAGE_WRITE,
            ),
            (
                vk::PipelineStageFlags2::ALL_TRANSFER,
                vk::AccessFlags2::TRANSFER_READ,
            ),
            (
                vk::ImageLayout::GENERAL,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            ),
        );
    }

    /// Records a copy of the whole image (in TRANSFER_SRC_OPTIMAL layout, see
    /// [`GpuImage::transition_for_copy`]) to `buffer` at `offset` (a multiple of the texel
    /// size), tightly packed row-major.
    pub fn copy_to_buffer(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        buffer: &GpuBuffer,
        offset: u64,
    ) {
        let region = [vk::BufferImageCopy::default()
            .buffer_offset(offset)
            .buffer_row_length(0)
            .buffer_image_height(0)
            .image_subresource(vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: 1,
            })
            .image_extent(vk::Extent3D {
                width: self.width,
                height: self.height,
                depth: 1,
            })];
        // SAFETY: cmd is recording; the image is in TRANSFER_SRC_OPTIMAL layout and the buffer holds
        // `offset + bytes()` bytes (checked by the caller's sizing).
        unsafe {
            ctx.device().cmd_copy_image_to_buffer(
                cmd,
                self.image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                buffer.handle(),
                &region,
            )
        };
    }
}

impl Drop for GpuImage {
    fn drop(&mut self) {
        let device = &self.shared.device;
        // SAFETY: the owner guarantees no submitted work still uses the image; null
        // handles are ignored by the destroy calls.
        unsafe {
            device.destroy_image_view(self.view, None);
            device.destroy_image(self.image, None);
        }
        if let Some(allocation) = self.allocation.take() {
            if let Ok(mut alloc) = self.shared.allocator.lock() {
                let _ = alloc.free(allocation);
            }
        }
    }
}
