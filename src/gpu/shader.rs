//! Compute shaders (SPIR-V compiled at build time, see `build.rs`), and the RAII
//! [`ComputePipeline`] that binds them through push descriptors.

use std::sync::Arc;

use ash::vk;

use super::device::Shared;
use super::shader_set;
use super::{BufferSlice, GpuContext, GpuError, GpuResult, VkContext};
use crate::core::shader_interface::RecordLayout;

/// SPIR-V compiled at build time (build.rs), by [`shader_set::ShaderVariant::key`]; the
/// defines and binding names of every wing it was compiled with.
mod prebuilt {
    include!(concat!(env!("OUT_DIR"), "/prebuilt_shaders.rs"));
}

/// Every wing's binding names by shader, in binding order (`bindings::ALL` of
/// `gpu::shader_set`, `render::shaders` and `train::shaders`, gathered by build.rs).
pub fn all_bindings() -> &'static [(&'static str, &'static [&'static str])] {
    prebuilt::BINDINGS
}

/// The GLSL headers, for compiling other sources at run time ([`compile_glsl`]).
const HEADERS: &[(&str, &str)] = &[
    ("common.glsl", include_str!("../../glsl/gpu/common.glsl")),
    // Written by build.rs from crate::core::shader_interface.
    (
        "interface.glsl",
        include_str!(concat!(env!("OUT_DIR"), "/glsl/interface.glsl")),
    ),
    (
        "sort_common.glsl",
        include_str!("../../glsl/gpu/sort_common.glsl"),
    ),
    (
        "sort_spec.glsl",
        include_str!("../../glsl/gpu/sort_spec.glsl"),
    ),
    (
        "subgroup.glsl",
        include_str!("../../glsl/gpu/subgroup.glsl"),
    ),
    (
        "splat_common.glsl",
        include_str!("../../glsl/render/forward/splat_common.glsl"),
    ),
];

/// Shader failures.
#[derive(Debug, thiserror::Error)]
pub enum ShaderError {
    /// No variant with these defines was compiled at build time.
    #[error(
        "no shader variant '{0}' was compiled at build time (the variants are listed in \
         each wing's shader table: src/gpu/shader_set.rs, src/render/shaders.rs, \
         src/train/shaders.rs)"
    )]
    Unknown(String),
    /// The GLSL did not compile; the message carries `glsl/<file>:<line>:`.
    #[error("compiling {file} failed:\n{message}")]
    Compile {
        /// `glsl/<name>.comp`
        file: String,
        /// glslc's diagnostics.
        message: String,
    },
}

/// `VERISPLAT_GLSL_DIR`, made absolute (glslc runs in a scratch directory).
fn glsl_dir() -> Option<std::path::PathBuf> {
    let dir = crate::core::former_name::env_var_os("VERISPLAT_GLSL_DIR")?;
    let dir = std::path::PathBuf::from(dir);
    Some(std::path::absolute(&dir).unwrap_or(dir))
}

/// A scratch directory for one run-time compile, removed on drop.
struct ScratchDir(std::path::PathBuf);

impl ScratchDir {
    fn new() -> Result<Self, String> {
        static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("verisplat-glsl-{}-{n}", std::process::id()));
        std::fs::create_dir_all(dir.join("glsl")).map_err(|e| format!("{}: {e}", dir.display()))?;
        Ok(ScratchDir(dir))
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Compiles GLSL compute source to SPIR-V for Vulkan 1.3 with optimisation, at run time
/// (with `glslc`, which must be installed: shader development and tests only; the
/// shipped shaders are compiled at build time). `name` is the stage name without
/// extension; diagnostics refer to `glsl/<name>.comp:<line>`. `#include "x.glsl"` resolves
/// the shipped headers; `defines` become `#define NAME VALUE` lines, after the constants
/// every shader gets ([`shader_set::shared_defines`]).
pub fn compile_glsl(
    name: &str,
    source: &str,
    defines: &[(&str, String)],
) -> Result<Vec<u32>, ShaderError> {
    // Diagnostics name `glsl/<name>.comp`, the file glslc reads; a name that is no plain
    // file name (a benchmark's case label) is written with `_` for the other characters.
    let stem: String = name
        .chars()
        .map(|c| match c {
            'a'..='z' | 'A'..='Z' | '0'..='9' | '_' | '-' | '.' | ' ' => c,
            _ => '_',
        })
        .collect();
    let file = format!("glsl/{stem}.comp");
    let compile_error = |message: String| ShaderError::Compile {
        file: file.clone(),
        message,
    };
    let scratch = ScratchDir::new().map_err(compile_error)?;
    let glsl = scratch.0.join("glsl");
    for (header, text) in HEADERS {
        std::fs::write(glsl.join(header), text).map_err(|e| compile_error(e.to_string()))?;
    }
    std::fs::write(glsl.join(format!("{stem}.comp")), source)
        .map_err(|e| compile_error(e.to_string()))?;
    run_glslc(
        &scratch.0,
        &file,
        &[&glsl],
        defines,
        &scratch.0.join("out.spv"),
    )
}

fn run_glslc(
    cwd: &std::path::Path,
    file: &str,
    include: &[&std::path::Path],
    defines: &[(&str, String)],
    output: &std::path::Path,
) -> Result<Vec<u32>, ShaderError> {
    let all: Vec<(&str, &str)> = prebuilt::SHARED_DEFINES
        .iter()
        .copied()
        .chain(defines.iter().map(|(k, v)| (*k, v.as_str())))
        .collect();
    shader_set::compile_glsl_file(cwd, file, include, &all, output).map_err(|message| {
        ShaderError::Compile {
            file: file.to_string(),
            message,
        }
    })
}

/// The SPIR-V of `glsl/<wing>/<name>.comp` with `defines`: the module compiled at build
/// time, or, when `VERISPLAT_GLSL_DIR` is set (shader development: edit and re-run without
/// rebuilding), `<name>.comp` of that folder's tree (a copy of `glsl/`) compiled now with
/// `glslc`, every folder of it searched by `#include`.
pub fn shader_spirv(name: &str, defines: &[(&str, String)]) -> Result<Vec<u32>, ShaderError> {
    if let Some(dir) = glsl_dir() {
        let compile_error = |message: String| ShaderError::Compile {
            file: format!("{name}.comp"),
            message,
        };
        let scratch = ScratchDir::new().map_err(compile_error)?;
        let (shaders, folders) = shader_set::glsl_tree(&dir).map_err(compile_error)?;
        let file = shaders
            .get(name)
            .cloned()
            .ok_or_else(|| compile_error(format!("no {name}.comp under {}", dir.display())))?;
        // The records' declarations, as build.rs writes them, beside the edited headers.
        let interface = HEADERS
            .iter()
            .find(|(header, _)| *header == "interface.glsl")
            .map(|(_, text)| *text)
            .expect("interface.glsl is a header");
        std::fs::write(scratch.0.join("interface.glsl"), interface).map_err(|e| {
            ShaderError::Compile {
                file: format!("{name}.comp"),
                message: e.to_string(),
            }
        })?;
        let mut include: Vec<&std::path::Path> = folders.iter().map(|f| f.as_path()).collect();
        include.push(&scratch.0);
        return run_glslc(
            &scratch.0,
            &file.display().to_string(),
            &include,
            defines,
            &scratch.0.join("out.spv"),
        );
    }
    let key = shader_set::variant_key(name, defines.iter().map(|(k, v)| (*k, v.as_str())));
    let bytes = prebuilt::PREBUILT
        .iter()
        .find(|(k, _)| *k == key)
        .map(|(_, bytes)| *bytes)
        .ok_or(ShaderError::Unknown(key))?;
    Ok(shader_set::spirv_words(bytes).expect("build.rs checked every module's SPIR-V"))
}

/// Keys of every variant compiled at build time.
pub fn prebuilt_variants() -> impl Iterator<Item = &'static str> {
    prebuilt::PREBUILT.iter().map(|(k, _)| *k)
}

pub use super::reflect::BindingKind;

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
    /// Builds a pipeline from SPIR-V; binding `i` of set 0 is `bindings[i]`. The module's
    /// own workgroup size decides whether full subgroups can be required.
    pub fn new(
        ctx: &GpuContext,
        name: &str,
        spirv: &[u32],
        bindings: &[BindingKind],
        push: &RecordLayout,
    ) -> GpuResult<Self> {
        Self::new_specialized(ctx, name, spirv, bindings, push, &[])
    }

    /// [`Self::new`] with specialization constants: `(constant_id, u32 value)` pairs.
    pub fn new_specialized(
        ctx: &GpuContext,
        name: &str,
        spirv: &[u32],
        bindings: &[BindingKind],
        push: &RecordLayout,
        specialization: &[(u32, u32)],
    ) -> GpuResult<Self> {
        // A driver that misreports its subgroup size: every shader computes with the
        // measured one (`glsl/gpu/subgroup.glsl`).
        let measured = ctx.info().subgroup_size_override;
        let specialization: Vec<(u32, u32)> = specialization
            .iter()
            .copied()
            .chain((measured != 0).then_some((super::shader_set::SUBGROUP_SIZE_SPEC, measured)))
            .collect();
        let specialization = specialization.as_slice();
        // One reading of the module: its interface and its workgroup's demand.
        let (interface, demand) = read_module(spirv, specialization);
        // The module must bind what the host binds (the two sides cannot drift).
        super::reflect::check_interface(name, interface, bindings, push)
            .map_err(GpuError::Internal)?;
        let device = &ctx.shared.device;
        let mut this = Self {
            shared: ctx.shared.clone(),
            name: name.to_string(),
            module: vk::ShaderModule::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            bindings: bindings.to_vec(),
            push_size: push.size as u32,
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
                        BindingKind::StorageTexelBuffer => vk::DescriptorType::STORAGE_TEXEL_BUFFER,
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
            .size(this.push_size)];
        let set_layouts = [this.set_layout];
        let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if this.push_size > 0 {
            layout_info = layout_info.push_constant_ranges(&ranges);
        }
        // SAFETY: valid create info.
        this.layout = unsafe { device.create_pipeline_layout(&layout_info, None) }
            .vk("vkCreatePipelineLayout")?;
        ctx.set_name(this.layout, name);

        // The workgroup must fit the device's (or the emulated) limits.
        let demand = super::workgroup::check_demand(name, demand, ctx.info())?;
        // Workgroup scans index subgroups by gl_SubgroupID and assume they are full: asked
        // for where the module's x size allows it (the module's own size, which the driver
        // checks).
        let stage_flags = full_subgroups_flag(ctx, demand.size[0]);
        let entries: Vec<vk::SpecializationMapEntry> = specialization
            .iter()
            .enumerate()
            .map(|(i, &(id, _))| vk::SpecializationMapEntry {
                constant_id: id,
                offset: 4 * i as u32,
                size: 4,
            })
            .collect();
        let values: Vec<u32> = specialization.iter().map(|&(_, v)| v).collect();
        let spec_info = vk::SpecializationInfo::default()
            .map_entries(&entries)
            .data(bytemuck::cast_slice(&values));
        let mut stage = vk::PipelineShaderStageCreateInfo::default()
            .flags(stage_flags)
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(this.module)
            .name(c"main");
        if !specialization.is_empty() {
            stage = stage.specialization_info(&spec_info);
        }
        let info = [vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(this.layout)];
        // SAFETY: valid create info.
        let pipelines =
            unsafe { device.create_compute_pipelines(ctx.pipeline_cache(), &info, None) }.map_err(
                |(_, result)| GpuError::Vk {
                    call: "vkCreateComputePipelines",
                    result,
                },
            )?;
        this.pipeline = pipelines[0];
        ctx.set_name(this.pipeline, name);
        Ok(this)
    }

    /// Builds the pipeline of `glsl/<shader>.comp` with `defines` (a variant compiled at
    /// build time, see [`shader_spirv`]).
    pub fn from_embedded(
        ctx: &GpuContext,
        shader: &str,
        defines: &[(&str, String)],
        bindings: &[BindingKind],
        push: &RecordLayout,
    ) -> GpuResult<Self> {
        Self::from_embedded_specialized(ctx, shader, defines, bindings, push, &[])
    }

    /// [`Self::from_embedded`] with specialization constants (`(constant_id, value)`).
    #[allow(clippy::too_many_arguments)]
    pub fn from_embedded_specialized(
        ctx: &GpuContext,
        shader: &str,
        defines: &[(&str, String)],
        bindings: &[BindingKind],
        push: &RecordLayout,
        specialization: &[(u32, u32)],
    ) -> GpuResult<Self> {
        let spirv = shader_spirv(shader, defines)?;
        Self::new_specialized(ctx, shader, &spirv, bindings, push, specialization)
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
                        | (
                            Resource::TexelBuffer(_),
                            BindingKind::UniformTexelBuffer | BindingKind::StorageTexelBuffer
                        )
                )
            });
        if !matches {
            return Err(GpuError::Internal(format!(
                "pipeline '{}' expects bindings {:?}, got {} resources of other kinds",
                self.name,
                self.bindings,
                resources.len()
            )));
        }
        if push.len() != self.push_size as usize {
            return Err(GpuError::Internal(format!(
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
                        .descriptor_type(match self.bindings[i] {
                            BindingKind::StorageTexelBuffer => {
                                vk::DescriptorType::STORAGE_TEXEL_BUFFER
                            }
                            _ => vk::DescriptorType::UNIFORM_TEXEL_BUFFER,
                        })
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
        let resources: Vec<Resource> = buffers.iter().map(|&b| Resource::Buffer(b)).collect();
        self.dispatch_indirect_resources(ctx, cmd, &resources, push, args)
    }

    /// [`Self::dispatch_indirect`] with buffers, images and texel views.
    pub fn dispatch_indirect_resources(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        resources: &[Resource],
        push: &[u8],
        args: BufferSlice,
    ) -> GpuResult<()> {
        self.bind_resources(ctx, cmd, resources, push)?;
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

/// What a stage binds, `(binding, value)` by the shader's named bindings
/// ([`shader_set::bindings`]), in binding order: each slot exactly once.
pub fn by_binding<T: Copy, const N: usize>(items: [(u32, T); N]) -> GpuResult<[T; N]> {
    shader_set::by_binding(items).map_err(GpuError::Internal)
}

/// Reads `words` once, for both of what a pipeline checks: the module's interface
/// ([`super::reflect`]) and its workgroup's demand with `specialization` applied
/// ([`super::workgroup`]). Each `Err` names what is malformed or cannot be evaluated.
fn read_module(
    words: &[u32],
    specialization: &[(u32, u32)],
) -> (
    Result<super::reflect::Interface, String>,
    Result<super::workgroup::WorkgroupDemand, String>,
) {
    if words.len() < 5 || words[0] != super::shader_set::SPIRV_MAGIC {
        let e = "not a SPIR-V module".to_string();
        return (Err(e.clone()), Err(e));
    }
    let overrides: std::collections::HashMap<u32, u32> = specialization.iter().copied().collect();
    let mut interface = super::reflect::Declarations::default();
    let mut workgroup = super::workgroup::Declarations::default();
    for instruction in super::reflect::instructions(words) {
        match instruction {
            Ok((op, w)) => {
                interface.visit(op, w);
                workgroup.visit(op, w, &overrides);
            }
            Err(e) => return (Err(e.clone()), Err(e)),
        }
    }
    (interface.interface(), workgroup.demand())
}

/// Whether a pipeline stage whose workgroup is `local_size_x` wide along x may ask for
/// full subgroups on `ctx`: x a multiple of the subgroup size that runs and of the one the
/// driver reports (the rule the validation layer checks; they differ where the driver
/// misreports).
fn full_subgroups_flag(ctx: &GpuContext, local_size_x: u32) -> vk::PipelineShaderStageCreateFlags {
    let info = ctx.info();
    if ctx.full_subgroups
        && local_size_x % info.subgroup_size.max(1) == 0
        && local_size_x % info.reported_subgroup_size.max(1) == 0
    {
        vk::PipelineShaderStageCreateFlags::REQUIRE_FULL_SUBGROUPS
    } else {
        vk::PipelineShaderStageCreateFlags::empty()
    }
}
