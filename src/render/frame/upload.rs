//! Scene upload: the Gaussians' records, their SH coefficients and feature channels on
//! the device ([`GpuScene`], [`GpuFeatures`]).

use crate::core::model::surface::{surface_axes, surface_axis, SURFACE_CHANNELS};
use crate::core::model::ActivatedScene;
use crate::gpu::{BufferView, GpuBuffer, GpuContext, GpuError, GpuResult, MemoryKind};
use crate::render::forward::types::{GpuGaussian, GpuGaussianCompact};
use ash::vk;

use crate::render::check_binding;
use crate::render::forward::{features, shade};

/// A scene uploaded to the device.
pub struct GpuScene {
    // The views go before the buffers they view.
    pub(crate) sh_texels: BufferView,
    /// RGBA32UI view of the records, for the texel-I/O preprocess (CPU devices).
    pub(crate) gaussian_texels: Option<BufferView>,
    pub(crate) gaussians: GpuBuffer,
    pub(crate) sh: GpuBuffer,
    /// Gaussians drawn: all uploaded, or the first of them ([`GpuScene::draw_first`]).
    pub(crate) count: u32,
    /// Gaussians uploaded.
    pub(crate) uploaded: u32,
    pub(crate) sh_degree: u32,
    pub(crate) sh_coeffs: u32,
    pub(crate) compact: bool,
}

impl GpuScene {
    /// Frames draw only the first `n` Gaussians uploaded (all of them when `n` is
    /// larger); the viewer's previews draw a prefix of a scene uploaded most important
    /// first. Every stage reads the drawn count, so nothing past it is touched.
    pub fn draw_first(&mut self, n: u32) {
        self.count = n.min(self.uploaded);
    }
    /// Gaussians uploaded (of which [`Self::len`] are drawn).
    pub fn uploaded_len(&self) -> u32 {
        self.uploaded
    }
    /// Whether the scene was uploaded compact ([`GpuRenderer::set_compact`](crate::render::GpuRenderer::set_compact): fp16 SH, scales and rotations).
    pub fn is_compact(&self) -> bool {
        self.compact
    }
    /// Number of Gaussians drawn (all uploaded unless [`Self::draw_first`] says fewer).
    pub fn len(&self) -> u32 {
        self.count
    }
    /// True when the scene is empty.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
    /// Device bytes held by the scene.
    pub fn device_bytes(&self) -> u64 {
        self.gaussians.size() + self.sh.size()
    }
    /// The records (`GpuGaussian`, 48 bytes each) and the SH coefficients (RGBA32F texels,
    /// [`sh_texel_stride`] per Gaussian) as storage buffers, for a device pass that writes
    /// them ([`GpuRenderer::scene_for_device_writes`](crate::render::GpuRenderer::scene_for_device_writes)).
    pub fn device_buffers(&self) -> (crate::gpu::BufferSlice<'_>, crate::gpu::BufferSlice<'_>) {
        (self.gaussians.whole(), self.sh.whole())
    }
}

/// A scene's feature channels uploaded to the device: one buffer per group of four
/// channels, a vec4 per Gaussian (zero past the last channel).
pub struct GpuFeatures {
    // The views go before the buffers they view.
    pub(crate) views: Vec<BufferView>,
    pub(crate) groups: Vec<GpuBuffer>,
    pub(crate) channels: usize,
    pub(crate) count: u32,
    /// The surface pass's axes ([`GpuRenderer::upload_surface`](crate::render::GpuRenderer::upload_surface)), blended by the feature
    /// blend's surface variant.
    pub(crate) surface: bool,
}

impl GpuFeatures {
    /// Channels per Gaussian (K).
    pub fn channels(&self) -> usize {
        self.channels
    }
    /// Whether these are the surface pass's axes ([`GpuRenderer::upload_surface`](crate::render::GpuRenderer::upload_surface)): frames
    /// blended with them hold facing normals and the median depth.
    pub fn is_surface(&self) -> bool {
        self.surface
    }
    /// Device bytes of the channels.
    pub fn device_bytes(&self) -> u64 {
        self.groups.iter().map(|b| b.size()).sum()
    }
    /// The groups' buffers (a vec4 per Gaussian each), for a device pass that writes them
    /// ([`GpuRenderer::features_for_device_writes`](crate::render::GpuRenderer::features_for_device_writes)).
    pub fn device_buffers(&self) -> Vec<crate::gpu::BufferSlice<'_>> {
        self.groups.iter().map(|b| b.whole()).collect()
    }
}

/// What a frame blends besides colour: the scene's features, and the neural shader
/// applied to them.
pub(crate) type FeatureJob<'a> = (&'a GpuFeatures, Option<&'a shade::GpuShader>);

/// RGBA32F texels of SH per Gaussian: the `3 (d + 1)^2` floats rounded up to whole texels
/// (`glsl/render/forward/preprocess.comp` computes the same stride).
pub fn sh_texel_stride(sh_degree: u32) -> u32 {
    (3 * (sh_degree + 1) * (sh_degree + 1)).div_ceil(4)
}

/// What an upload needs of the renderer: the device, whether scenes go up compact
/// ([`GpuRenderer::set_compact`](crate::render::GpuRenderer::set_compact)) and whether preprocess reads the records through texel
/// views (CPU devices).
pub(crate) struct Uploader<'a> {
    pub(crate) ctx: &'a GpuContext,
    pub(crate) compact: bool,
    pub(crate) texel_io: bool,
}

impl Uploader<'_> {
    /// [`GpuRenderer::upload`](crate::render::GpuRenderer::upload).
    pub(crate) fn upload(&self, scene: &ActivatedScene) -> GpuResult<GpuScene> {
        let count = u32::try_from(scene.len()).map_err(|_| {
            GpuError::Input(format!(
                "{} Gaussians exceed the 2^32 limit of one upload",
                scene.len()
            ))
        })?;
        // Preprocess binds windows of the records, so one binding need not hold them all.
        let gaussians = if self.compact {
            let records: Vec<GpuGaussianCompact> = (0..scene.len())
                .map(|i| {
                    GpuGaussianCompact::new(
                        scene.positions[i],
                        scene.opacities[i],
                        scene.scales[i],
                        scene.rotations[i],
                    )
                })
                .collect();
            self.upload_records("gaussians (compact)", &records)?
        } else {
            let records: Vec<GpuGaussian> = (0..scene.len())
                .map(|i| {
                    let p = scene.positions[i];
                    let s = scene.scales[i];
                    GpuGaussian {
                        pos_opacity: [p[0], p[1], p[2], scene.opacities[i]],
                        scale: [s[0], s[1], s[2], 0.0],
                        rotation: scene.rotations[i],
                    }
                })
                .collect();
            self.upload_records("gaussians", &records)?
        };
        // SH is read through an RGBA32F texel buffer (texel buffers address up to
        // maxTexelBufferElements texels, far beyond one storage binding on lavapipe), each
        // Gaussian's floats padded to whole texels.
        let stride = scene.sh_stride();
        let padded = sh_texel_stride(scene.sh_degree) as usize * 4;
        self.check_sh_texels(count, scene.sh_degree)?;
        // SH degrees 1 and 3 fill whole texels already and upload as they are.
        let sh_padded: std::borrow::Cow<[f32]> = if stride == padded {
            std::borrow::Cow::Borrowed(&scene.sh)
        } else {
            let mut v = vec![0f32; scene.len() * padded];
            for (dst, src) in v
                .chunks_exact_mut(padded)
                .zip(scene.sh.chunks_exact(stride))
            {
                dst[..stride].copy_from_slice(src);
            }
            std::borrow::Cow::Owned(v)
        };
        let (sh, format, sh_bytes) = if self.compact {
            // Round to nearest fp16; beyond fp16's range (|x| > 65504) becomes infinite.
            let halves: Vec<u16> = sh_padded
                .iter()
                .map(|&x| half::f16::from_f32(x).to_bits())
                .collect();
            let bytes = (halves.len() * 2).max(8) as u64;
            let sh = GpuBuffer::new(
                self.ctx,
                "sh coefficients (fp16)",
                bytes,
                MemoryKind::Device,
            )?;
            sh.upload(self.ctx, &halves)?;
            (sh, vk::Format::R16G16B16A16_SFLOAT, bytes)
        } else {
            let bytes = (sh_padded.len() * 4).max(16) as u64;
            let sh = GpuBuffer::new(self.ctx, "sh coefficients", bytes, MemoryKind::Device)?;
            sh.upload(self.ctx, &sh_padded)?;
            (sh, vk::Format::R32G32B32A32_SFLOAT, bytes)
        };
        self.scene_of(gaussians, (sh, format, sh_bytes), count, scene.sh_degree)
    }

    /// Refuses SH coefficients of `count` Gaussians (degree `sh_degree`) that one texel
    /// buffer of the device cannot address.
    fn check_sh_texels(&self, count: u32, sh_degree: u32) -> GpuResult<()> {
        let texels = u64::from(count) * u64::from(sh_texel_stride(sh_degree));
        let max_texels = u64::from(self.ctx.info().max_texel_buffer_elements);
        if texels > max_texels {
            return Err(GpuError::DeviceLimit {
                limit: "maxTexelBufferElements",
                needed: texels,
                max: max_texels,
                message: format!(
                    "the SH coefficients of {count} Gaussians need {texels} texels ({} bytes) in one texel buffer, but this device addresses at most {max_texels} (maxTexelBufferElements); use fewer Gaussians, a lower --sh-degree or a device with a larger limit",
                    texels * 16
                ),
            });
        }
        Ok(())
    }

    /// The scene of `count` Gaussians in `gaussians` (records) and `sh` (the SH buffer,
    /// its texel format and bytes), with the texel views its stages read.
    fn scene_of(
        &self,
        gaussians: GpuBuffer,
        (sh, format, sh_bytes): (GpuBuffer, vk::Format, u64),
        count: u32,
        sh_degree: u32,
    ) -> GpuResult<GpuScene> {
        let sh_texels = BufferView::new(self.ctx, &sh, format, 0, sh_bytes)?;
        let gaussian_texels = if self.texel_io {
            let bytes = gaussians.size() / 16 * 16;
            Some(BufferView::new(
                self.ctx,
                &gaussians,
                vk::Format::R32G32B32A32_UINT,
                0,
                bytes,
            )?)
        } else {
            None
        };
        Ok(GpuScene {
            sh_texels,
            gaussian_texels,
            gaussians,
            sh,
            count,
            uploaded: count,
            sh_degree,
            sh_coeffs: (sh_degree + 1) * (sh_degree + 1),
            compact: self.compact,
        })
    }

    /// [`GpuRenderer::scene_for_device_writes`](crate::render::GpuRenderer::scene_for_device_writes).
    pub(crate) fn scene_for_device_writes(
        &self,
        count: u32,
        sh_degree: u32,
    ) -> GpuResult<GpuScene> {
        if self.compact {
            return Err(GpuError::InvalidArgument(
                "a scene written on the device is full precision; turn the compact upload off"
                    .into(),
            ));
        }
        let record_bytes = (u64::from(count) * std::mem::size_of::<GpuGaussian>() as u64).max(16);
        let gaussians = GpuBuffer::new(self.ctx, "gaussians", record_bytes, MemoryKind::Device)?;
        self.check_sh_texels(count, sh_degree)?;
        let sh_bytes = (u64::from(count) * u64::from(sh_texel_stride(sh_degree)) * 16).max(16);
        check_binding(self.ctx, "sh coefficients", sh_bytes)?;
        let sh = GpuBuffer::new(self.ctx, "sh coefficients", sh_bytes, MemoryKind::Device)?;
        let format = vk::Format::R32G32B32A32_SFLOAT;
        self.scene_of(gaussians, (sh, format, sh_bytes), count, sh_degree)
    }

    /// [`GpuRenderer::features_for_device_writes`](crate::render::GpuRenderer::features_for_device_writes).
    pub(crate) fn features_for_device_writes(
        &self,
        count: u32,
        k: usize,
    ) -> GpuResult<GpuFeatures> {
        if k == 0 {
            return Err(GpuError::InvalidArgument("no feature channels".into()));
        }
        let (mut groups, mut views) = (Vec::new(), Vec::new());
        for g in 0..features::groups(k) {
            let name = format!("features {}..{}", g * 4, (g * 4 + 4).min(k));
            let bytes = (u64::from(count) * 16).max(16);
            check_binding(self.ctx, &name, bytes)?;
            let buf = GpuBuffer::new(self.ctx, &name, bytes, MemoryKind::Device)?;
            if self.texel_io {
                views.push(BufferView::new(
                    self.ctx,
                    &buf,
                    vk::Format::R32G32B32A32_SFLOAT,
                    0,
                    bytes,
                )?);
            }
            groups.push(buf);
        }
        Ok(GpuFeatures {
            views,
            groups,
            channels: k,
            count,
            surface: false,
        })
    }

    /// A device buffer holding `records`.
    pub(crate) fn upload_records<T: bytemuck::Pod>(
        &self,
        name: &str,
        records: &[T],
    ) -> GpuResult<GpuBuffer> {
        // At least one texel, so the preprocess's texel view is valid for an empty scene.
        let bytes = (std::mem::size_of_val(records) as u64).max(16);
        let buffer = GpuBuffer::new(self.ctx, name, bytes, MemoryKind::Device)?;
        buffer.upload(self.ctx, records)?;
        Ok(buffer)
    }

    /// [`GpuRenderer::upload_features`](crate::render::GpuRenderer::upload_features).
    pub(crate) fn upload_features(&self, scene: &ActivatedScene) -> GpuResult<GpuFeatures> {
        let k = scene.feature_count;
        let n = scene.len();
        if k == 0 || scene.features.len() != n * k {
            return Err(GpuError::Input(format!(
                "the scene has no feature channels to upload ({} values for {n} Gaussians and {k} channels)",
                scene.features.len()
            )));
        }
        let count = u32::try_from(n).map_err(|_| {
            GpuError::Input(format!("{n} Gaussians exceed the 2^32 limit of one upload"))
        })?;
        let uploaded = self.features_for_device_writes(count, k)?;
        for (g, buf) in uploaded.groups.iter().enumerate() {
            let mut v = vec![[0f32; 4]; n.max(1)];
            for (i, dst) in v.iter_mut().enumerate().take(n) {
                for (c, d) in dst.iter_mut().enumerate() {
                    let ch = g * features::CHANNELS_PER_GROUP + c;
                    if ch < k {
                        *d = scene.features[i * k + ch];
                    }
                }
            }
            buf.upload(self.ctx, &v)?;
        }
        Ok(uploaded)
    }

    /// [`GpuRenderer::upload_surface`](crate::render::GpuRenderer::upload_surface).
    pub(crate) fn upload_surface(&self, scene: &ActivatedScene) -> GpuResult<GpuFeatures> {
        let n = scene.len();
        let count = u32::try_from(n).map_err(|_| {
            GpuError::Input(format!("{n} Gaussians exceed the 2^32 limit of one upload"))
        })?;
        let mut uploaded = self.features_for_device_writes(count, SURFACE_CHANNELS)?;
        // A compact upload draws the fp16-rounded shapes
        // (`ActivatedScene::compact_rounded`), so its axes are theirs.
        let mut axes = if self.compact {
            let round = |x: f32| half::f16::from_f32(x).to_f32();
            (0..n)
                .map(|i| {
                    surface_axis(
                        scene.positions[i],
                        scene.scales[i].map(round),
                        scene.rotations[i].map(round),
                    )
                })
                .collect()
        } else {
            surface_axes(scene)
        };
        if axes.is_empty() {
            axes.push([0.0; 4]);
        }
        uploaded.groups[0].upload(self.ctx, &axes)?;
        uploaded.surface = true;
        Ok(uploaded)
    }
}
