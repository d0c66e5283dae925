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
    ("order.comp", include_str!("../../glsl/order.comp")),
    ("ranges.comp", include_str!("../../glsl/ranges.comp")),
    ("blend.comp", include_str!("../../glsl/blend.comp")),
    (
        "blend_features.comp",
        include_str!("../../glsl/blend_features.comp"),
    ),
    ("pack.comp", include_str!("../../glsl/pack.comp")),
    ("shade.comp", include_str!("../../glsl/shade.comp")),
    (
        "count64_test.comp",
        include_str!("../../glsl/count64_test.comp"),
    ),
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

/// The source of `glsl/<name>`: read from `$VKSPLAT_GLSL_DIR/<name>` when that variable is
/// set (shader development: edit and re-run without rebuilding; such compiles skip the
/// SPIR-V cache), else the copy embedded in the binary.
fn embedded(name: &str) -> Option<String> {
    if let Some(dir) = glsl_dir() {
        if let Ok(text) = std::fs::read_to_string(dir.join(name)) {
            return Some(text);
        }
    }
    SOURCES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, s)| (*s).to_string())
}

fn glsl_dir() -> Option<std::path::PathBuf> {
    std::env::var_os("VKSPLAT_GLSL_DIR").map(std::path::PathBuf::from)
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
                content,
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
///
/// Compiled SPIR-V is cached on disk (see [`shader_cache_dir`]): compiling every shader
/// with glslang takes over a second, most of a short render's start-up. The cache key
/// covers every embedded source, the shader name and its defines, so any change to any
/// shader misses. A damaged entry is ignored and rewritten.
pub fn compile_embedded(name: &str, defines: &[(&str, String)]) -> Result<Vec<u32>, ShaderError> {
    compile_embedded_cached(name, defines, shader_cache_dir().as_deref())
}

/// [`compile_embedded`] with an explicit cache directory (`None`: no cache).
pub fn compile_embedded_cached(
    name: &str,
    defines: &[(&str, String)],
    cache_dir: Option<&std::path::Path>,
) -> Result<Vec<u32>, ShaderError> {
    let file = format!("{name}.comp");
    let source = embedded(&file).ok_or(ShaderError::Unknown(file))?;
    let cache_dir = cache_dir.filter(|_| glsl_dir().is_none());
    let cached =
        cache_dir.map(|dir| dir.join(format!("{name}-{:016x}.spv", cache_key(name, defines))));
    if let Some(words) = cached.as_deref().and_then(read_spirv) {
        return Ok(words);
    }
    let words = compile_glsl(name, &source, defines)?;
    if let Some(path) = cached {
        write_spirv(&path, &words);
    }
    Ok(words)
}

/// Where compiled shaders are cached: `$VKSPLAT_SHADER_CACHE`, else
/// `$XDG_CACHE_HOME/vksplat/spirv`, else `~/.cache/vksplat/spirv`. `None` (no caching)
/// when `VKSPLAT_NO_SHADER_CACHE` is set or no location is known.
pub fn shader_cache_dir() -> Option<std::path::PathBuf> {
    use std::path::PathBuf;
    if std::env::var_os("VKSPLAT_NO_SHADER_CACHE").is_some() {
        return None;
    }
    if let Some(dir) = std::env::var_os("VKSPLAT_SHADER_CACHE") {
        return Some(PathBuf::from(dir));
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    Some(base.join("vksplat").join("spirv"))
}

/// FNV-1a over every embedded source, the crate version, the shader name and its defines.
fn cache_key(name: &str, defines: &[(&str, String)]) -> u64 {
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    let mut feed = |bytes: &[u8]| {
        for &b in bytes {
            hash ^= u64::from(b);
            hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        }
        // A separator so that concatenations cannot collide.
        hash ^= 0xff;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    };
    feed(env!("CARGO_PKG_VERSION").as_bytes());
    for (file, text) in SOURCES {
        feed(file.as_bytes());
        feed(text.as_bytes());
    }
    feed(name.as_bytes());
    for (k, v) in defines {
        feed(k.as_bytes());
        feed(v.as_bytes());
    }
    hash
}

fn read_spirv(path: &std::path::Path) -> Option<Vec<u32>> {
    let bytes = std::fs::read(path).ok()?;
    if bytes.len() < 20 || bytes.len() % 4 != 0 {
        return None;
    }
    let words: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    (words[0] == 0x0723_0203).then_some(words)
}

/// Best effort: a cache that cannot be written only costs the next start-up time.
fn write_spirv(path: &std::path::Path, words: &[u32]) {
    let Some(dir) = path.parent() else { return };
    if std::fs::create_dir_all(dir).is_err() {
        return;
    }
    // Unique per process and call, so concurrent writers never share a temporary file.
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.{n}.tmp", std::process::id()));
    let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
    if std::fs::write(&tmp, bytes).is_ok() && std::fs::rename(&tmp, path).is_ok() {
        return;
    }
    let _ = std::fs::remove_file(&tmp);
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
    /// `imageBuffer` / `uimageBuffer` with a format qualifier, written with `imageStore`.
    StorageTexelBuffer,
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
                        | (
                            Resource::TexelBuffer(_),
                            BindingKind::UniformTexelBuffer | BindingKind::StorageTexelBuffer
                        )
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

#[cfg(test)]
mod cache_tests {
    use super::*;

    #[test]
    fn cache_hits_misses_and_ignores_damaged_entries() {
        let dir = std::env::temp_dir().join(format!("vksplat-cache-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let defines = [("STRIP", "2".to_string()), ("TEXEL_FETCH", "1".to_string())];
        let fresh = compile_embedded_cached("blend", &defines, Some(&dir)).unwrap();
        let entries: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        assert_eq!(
            entries.len(),
            1,
            "one entry, no temporary files left: {entries:?}"
        );
        assert_eq!(read_spirv(&entries[0]).unwrap(), fresh);
        // A hit returns what the cache holds (here another valid module, to prove it is read).
        let other = compile_embedded_cached("ranges", &[], None).unwrap();
        write_spirv(&entries[0], &other);
        assert_eq!(
            compile_embedded_cached("blend", &defines, Some(&dir)).unwrap(),
            other
        );
        // Other defines are another entry.
        let strip4 = [("STRIP", "4".to_string()), ("TEXEL_FETCH", "1".to_string())];
        assert_ne!(
            compile_embedded_cached("blend", &strip4, Some(&dir)).unwrap(),
            other
        );
        // A damaged entry is ignored and replaced by a fresh compile.
        std::fs::write(&entries[0], b"not spir-v at all").unwrap();
        assert_eq!(
            compile_embedded_cached("blend", &defines, Some(&dir)).unwrap(),
            fresh
        );
        assert_eq!(read_spirv(&entries[0]).unwrap(), fresh);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
