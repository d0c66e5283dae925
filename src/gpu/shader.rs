//! GLSL compute shaders compiled with shaderc at start-up, and the RAII
//! [`ComputePipeline`] that binds them through push descriptors.

use std::sync::Arc;

use ash::vk;

use super::context::Shared;
use super::{BufferSlice, GpuContext, GpuError, GpuResult, VkContext};

/// Shader sources embedded in the binary, by file name under `glsl/`.
pub const SOURCES: &[(&str, &str)] = &[
    ("common.glsl", include_str!("../../glsl/common.glsl")),
    (
        "sort_common.glsl",
        include_str!("../../glsl/sort_common.glsl"),
    ),
    (
        "scan_reduce.comp",
        include_str!("../../glsl/scan_reduce.comp"),
    ),
    (
        "scan_block.comp",
        include_str!("../../glsl/scan_block.comp"),
    ),
    ("scan_add.comp", include_str!("../../glsl/scan_add.comp")),
    (
        "sort_setup.comp",
        include_str!("../../glsl/sort_setup.comp"),
    ),
    (
        "sort_histogram.comp",
        include_str!("../../glsl/sort_histogram.comp"),
    ),
    (
        "sort_scatter.comp",
        include_str!("../../glsl/sort_scatter.comp"),
    ),
    ("sort_copy.comp", include_str!("../../glsl/sort_copy.comp")),
    (
        "splat_common.glsl",
        include_str!("../../glsl/splat_common.glsl"),
    ),
    (
        "preprocess.comp",
        include_str!("../../glsl/preprocess.comp"),
    ),
    ("keys.comp", include_str!("../../glsl/keys.comp")),
    ("ranges.comp", include_str!("../../glsl/ranges.comp")),
    ("blend.comp", include_str!("../../glsl/blend.comp")),
];

/// Shader compilation failures.
#[derive(Debug, thiserror::Error)]
pub enum ShaderError {
    /// shaderc could not be initialised.
    #[error("shaderc initialisation failed: {0}")]
    Init(String),
    /// No embedded shader has this name.
    #[error("no embedded shader named glsl/{0}")]
    Unknown(String),
    /// The GLSL did not compile; the message carries `glsl/<file>:<line>:`.
    #[error("compiling {file} failed:\n{message}")]
    Compile {
        /// `glsl/<name>.comp`
        file: String,
        /// shaderc's diagnostics.
        message: String,
    },
}

fn embedded(name: &str) -> Option<&'static str> {
    SOURCES.iter().find(|(n, _)| *n == name).map(|(_, s)| *s)
}

/// Compiles GLSL compute source to SPIR-V for Vulkan 1.3 with optimisation.
/// `name` is the stage name without extension; diagnostics refer to
/// `glsl/<name>.comp:<line>`. `#include "x.glsl"` resolves from [`SOURCES`];
/// `defines` become `#define NAME VALUE` lines.
pub fn compile_glsl(
    name: &str,
    source: &str,
    defines: &[(&str, String)],
) -> Result<Vec<u32>, ShaderError> {
    let file = format!("glsl/{name}.comp");
    let compiler = shaderc::Compiler::new().map_err(|e| ShaderError::Init(e.to_string()))?;
    let mut options =
        shaderc::CompileOptions::new().map_err(|e| ShaderError::Init(e.to_string()))?;
    options.set_target_env(
        shaderc::TargetEnv::Vulkan,
        shaderc::EnvVersion::Vulkan1_3 as u32,
    );
    options.set_optimization_level(shaderc::OptimizationLevel::Performance);
    for (key, value) in defines {
        if key.contains('\0') || value.contains('\0') {
            return Err(ShaderError::Compile {
                file,
                message: format!("define {key:?} contains a NUL byte"),
            });
        }
        options.add_macro_definition(key, Some(value));
    }
    options.set_include_callback(|requested, _kind, _from, _depth| {
        embedded(requested)
            .map(|content| shaderc::ResolvedInclude {
                resolved_name: format!("glsl/{requested}"),
                content: content.to_string(),
            })
            .ok_or_else(|| format!("no embedded include named glsl/{requested}"))
    });
    compiler
        .compile_into_spirv(
            source,
            shaderc::ShaderKind::Compute,
            &file,
            "main",
            Some(&options),
        )
        .map(|artifact| artifact.as_binary().to_vec())
        .map_err(|e| ShaderError::Compile {
            file: file.clone(),
            message: e.to_string(),
        })
}

/// Compiles the embedded shader `glsl/<name>.comp`.
pub fn compile_embedded(name: &str, defines: &[(&str, String)]) -> Result<Vec<u32>, ShaderError> {
    let file = format!("{name}.comp");
    let source = embedded(&file).ok_or(ShaderError::Unknown(file))?;
    compile_glsl(name, source, defines)
}

/// What a binding slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingKind {
    /// `buffer` block (std430).
    StorageBuffer,
    /// `image2D` with a format qualifier.
    StorageImage,
    /// `samplerBuffer` / `usamplerBuffer` read with `texelFetch`.
    UniformTexelBuffer,
}

/// What is bound to one binding slot at dispatch time.
#[derive(Clone, Copy)]
pub enum Resource<'a> {
    /// A storage buffer range.
    Buffer(BufferSlice<'a>),
    /// A storage image view in `layout` (normally `GENERAL`).
    Image {
        /// The view.
        view: vk::ImageView,
        /// Its layout while the dispatch runs.
        layout: vk::ImageLayout,
    },
    /// A uniform texel buffer view.
    TexelBuffer(vk::BufferView),
}

/// A compute pipeline with a push-descriptor set layout and push constants.
pub struct ComputePipeline {
    shared: Arc<Shared>,
    name: String,
    module: vk::ShaderModule,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    bindings: Vec<BindingKind>,
    push_size: u32,
}

impl ComputePipeline {
    /// Builds a pipeline from SPIR-V; binding `i` of set 0 is `bindings[i]`.
    /// `workgroup_size` (local_size_x) decides whether full subgroups can be required.
    pub fn new(
        ctx: &GpuContext,
        name: &str,
        spirv: &[u32],
        bindings: &[BindingKind],
        push_size: u32,
        workgroup_size: u32,
    ) -> GpuResult<Self> {
        let device = &ctx.shared.device;
        let mut this = Self {
            shared: ctx.shared.clone(),
            name: name.to_string(),
            module: vk::ShaderModule::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            bindings: bindings.to_vec(),
            push_size,
        };
        let module_info = vk::ShaderModuleCreateInfo::default().code(spirv);
        // SAFETY: SPIR-V from shaderc; every handle below is destroyed by Drop (null ones
        // are ignored by the destroy calls).
        this.module = unsafe { device.create_shader_module(&module_info, None) }
            .vk("vkCreateShaderModule")?;
        ctx.set_name(this.module, name);
        let layout_bindings: Vec<vk::DescriptorSetLayoutBinding> = bindings
            .iter()
            .enumerate()
            .map(|(i, kind)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(i as u32)
                    .descriptor_type(match kind {
                        BindingKind::StorageBuffer => vk::DescriptorType::STORAGE_BUFFER,
                        BindingKind::StorageImage => vk::DescriptorType::STORAGE_IMAGE,
                        BindingKind::UniformTexelBuffer => vk::DescriptorType::UNIFORM_TEXEL_BUFFER,
                    })
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let set_info = vk::DescriptorSetLayoutCreateInfo::default()
            .flags(vk::DescriptorSetLayoutCreateFlags::PUSH_DESCRIPTOR_KHR)
            .bindings(&layout_bindings);
        // SAFETY: valid create info.
        this.set_layout = unsafe { device.create_descriptor_set_layout(&set_info, None) }
            .vk("vkCreateDescriptorSetLayout")?;
        ctx.set_name(this.set_layout, name);
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .size(push_size)];
        let set_layouts = [this.set_layout];
        let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if push_size > 0 {
            layout_info = layout_info.push_constant_ranges(&ranges);
        }
        // SAFETY: valid create info.
        this.layout = unsafe { device.create_pipeline_layout(&layout_info, None) }
            .vk("vkCreatePipelineLayout")?;
        ctx.set_name(this.layout, name);
        // Workgroup scans index subgroups by gl_SubgroupID and assume they are full.
        let stage_flags =
            if ctx.full_subgroups && workgroup_size % ctx.info().subgroup_size.max(1) == 0 {
                vk::PipelineShaderStageCreateFlags::REQUIRE_FULL_SUBGROUPS
            } else {
                vk::PipelineShaderStageCreateFlags::empty()
            };
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .flags(stage_flags)
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(this.module)
            .name(c"main");
        let info = [vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(this.layout)];
        // SAFETY: valid create info.
        let pipelines =
            unsafe { device.create_compute_pipelines(vk::PipelineCache::null(), &info, None) }
                .map_err(|(_, result)| GpuError::Vk {
                    call: "vkCreateComputePipelines",
                    result,
                })?;
        this.pipeline = pipelines[0];
        ctx.set_name(this.pipeline, name);
        Ok(this)
    }

    /// Compiles the embedded `glsl/<shader>.comp` with `defines` and builds the pipeline.
    pub fn from_embedded(
        ctx: &GpuContext,
        shader: &str,
        defines: &[(&str, String)],
        bindings: &[BindingKind],
        push_size: u32,
        workgroup_size: u32,
    ) -> GpuResult<Self> {
        let spirv = compile_embedded(shader, defines)?;
        Self::new(ctx, shader, &spirv, bindings, push_size, workgroup_size)
    }

    /// Binds the pipeline, pushes the buffer descriptors (binding i = `buffers[i]`) and
    /// the push constants.
    pub fn bind(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        buffers: &[BufferSlice],
        push: &[u8],
    ) -> GpuResult<()> {
        let resources: Vec<Resource> = buffers.iter().map(|&b| Resource::Buffer(b)).collect();
        self.bind_resources(ctx, cmd, &resources, push)
    }

    /// Like [`ComputePipeline::bind`] for pipelines that also use storage images.
    pub fn bind_resources(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        resources: &[Resource],
        push: &[u8],
    ) -> GpuResult<()> {
        let matches = resources.len() == self.bindings.len()
            && resources.iter().zip(&self.bindings).all(|(r, b)| {
                matches!(
                    (r, b),
                    (Resource::Buffer(_), BindingKind::StorageBuffer)
                        | (Resource::Image { .. }, BindingKind::StorageImage)
                        | (Resource::TexelBuffer(_), BindingKind::UniformTexelBuffer)
                )
            });
        if !matches {
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{}' expects bindings {:?}, got {} resources of other kinds",
                self.name,
                self.bindings,
                resources.len()
            )));
        }
        if push.len() != self.push_size as usize {
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{}' expects {} push-constant bytes, got {}",
                self.name,
                self.push_size,
                push.len()
            )));
        }
        let buffer_infos: Vec<[vk::DescriptorBufferInfo; 1]> = resources
            .iter()
            .map(|r| match r {
                Resource::Buffer(b) => [vk::DescriptorBufferInfo::default()
                    .buffer(b.buffer.handle())
                    .offset(b.offset)
                    // An empty range is not allowed; bind the rest of the buffer.
                    .range(if b.size == 0 { vk::WHOLE_SIZE } else { b.size })],
                Resource::Image { .. } | Resource::TexelBuffer(_) => {
                    [vk::DescriptorBufferInfo::default()]
                }
            })
            .collect();
        let image_infos: Vec<[vk::DescriptorImageInfo; 1]> = resources
            .iter()
            .map(|r| match r {
                Resource::Image { view, layout } => [vk::DescriptorImageInfo::default()
                    .image_view(*view)
                    .image_layout(*layout)],
                Resource::Buffer(_) | Resource::TexelBuffer(_) => {
                    [vk::DescriptorImageInfo::default()]
                }
            })
            .collect();
        let texel_views: Vec<[vk::BufferView; 1]> = resources
            .iter()
            .map(|r| match r {
                Resource::TexelBuffer(view) => [*view],
                _ => [vk::BufferView::null()],
            })
            .collect();
        let writes: Vec<vk::WriteDescriptorSet> = resources
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let write = vk::WriteDescriptorSet::default().dst_binding(i as u32);
                match r {
                    Resource::Buffer(_) => write
                        .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                        .buffer_info(&buffer_infos[i]),
                    Resource::Image { .. } => write
                        .descriptor_type(vk::DescriptorType::STORAGE_IMAGE)
                        .image_info(&image_infos[i]),
                    Resource::TexelBuffer(_) => write
                        .descriptor_type(vk::DescriptorType::UNIFORM_TEXEL_BUFFER)
                        .texel_buffer_view(&texel_views[i]),
                }
            })
            .collect();
        let device = ctx.device();
        // SAFETY: cmd is recording; the resources are alive; the layout matches.
        unsafe {
            device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            ctx.shared.push_descriptor.cmd_push_descriptor_set(
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                self.layout,
                0,
                &writes,
            );
            if !push.is_empty() {
                device.cmd_push_constants(cmd, self.layout, vk::ShaderStageFlags::COMPUTE, 0, push);
            }
        }
        Ok(())
    }

    /// Binds buffers and images and dispatches `groups` workgroups.
    pub fn dispatch_resources(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        resources: &[Resource],
        push: &[u8],
        groups: [u32; 3],
    ) -> GpuResult<()> {
        self.bind_resources(ctx, cmd, resources, push)?;
        // SAFETY: pipeline and descriptors bound above.
        unsafe {
            ctx.device()
                .cmd_dispatch(cmd, groups[0], groups[1], groups[2])
        };
        Ok(())
    }

    /// Binds and dispatches `groups` workgroups.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        buffers: &[BufferSlice],
        push: &[u8],
        groups: [u32; 3],
    ) -> GpuResult<()> {
        self.bind(ctx, cmd, buffers, push)?;
        // SAFETY: pipeline and descriptors bound above.
        unsafe {
            ctx.device()
                .cmd_dispatch(cmd, groups[0], groups[1], groups[2])
        };
        Ok(())
    }

    /// Binds and dispatches with a VkDispatchIndirectCommand at `args` (offset % 4 == 0).
    pub fn dispatch_indirect(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        buffers: &[BufferSlice],
        push: &[u8],
        args: BufferSlice,
    ) -> GpuResult<()> {
        self.bind(ctx, cmd, buffers, push)?;
        // SAFETY: pipeline and descriptors bound above; args holds 12 bytes.
        unsafe {
            ctx.device()
                .cmd_dispatch_indirect(cmd, args.buffer.handle(), args.offset)
        };
        Ok(())
    }

    /// The pipeline's name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

impl Drop for ComputePipeline {
    fn drop(&mut self) {
        let device = &self.shared.device;
        // SAFETY: the owner guarantees no submitted work still uses the pipeline;
        // destroying null handles is a no-op.
        unsafe {
            device.destroy_pipeline(self.pipeline, None);
            device.destroy_pipeline_layout(self.layout, None);
            device.destroy_descriptor_set_layout(self.set_layout, None);
            device.destroy_shader_module(self.module, None);
        }
    }
}
