//! The interface between the host and the shaders, declared once: every record a shader
//! reads or writes through a buffer, every push-constant block and every flag. Each record
//! here is a `#[repr(C)]` Rust struct, and `build.rs` writes its GLSL declaration (std430)
//! into `interface.glsl`, which the shaders include; the flags become GLSL constants. So no
//! struct, field, offset or flag is typed in both languages.
//!
//! Field types are spelt with GLSL's names ([`glsl`]: `uint`, `vec4`, `[vec4; 3]`, or
//! another record), which are plain Rust aliases (`vec4` is `[f32; 4]`). The declaration
//! is checked against std430 when it is written: a Rust offset that std430 would place
//! elsewhere fails the build, naming the field. At run time every pipeline checks that its
//! push-constant block is the record the host pushes, member by member
//! ([`crate::gpu::reflect`]).
//!
//! A push block is declared in a shader as one member of the record's type:
//! `layout(push_constant) uniform WindowBlock { WindowPush window; };` (`window.first`).
//!
//! This file uses std and bytemuck only: `build.rs` includes it.

/// GLSL's type names, as Rust types of the same std430 size.
#[allow(non_camel_case_types)]
pub mod glsl {
    /// `uint`.
    pub type uint = u32;
    /// `int`.
    pub type int = i32;
    /// `float`.
    pub type float = f32;
    /// `uvec2`.
    pub type uvec2 = [u32; 2];
    /// `vec2`.
    pub type vec2 = [f32; 2];
    /// `uvec4`.
    pub type uvec4 = [u32; 4];
    /// `ivec4`.
    pub type ivec4 = [i32; 4];
    /// `vec4`.
    pub type vec4 = [f32; 4];
}

use glsl::{uint, uvec4, vec4};

/// One field of a record: its name, its GLSL type as written (`vec4`, `[uint; 3]`, a
/// record's name) and its byte offset in the Rust struct.
#[derive(Clone, Copy, Debug)]
pub struct FieldLayout {
    /// The field's name, the same in both languages.
    pub name: &'static str,
    /// The type as written in the declaration.
    pub ty: &'static str,
    /// Byte offset (`offset_of!`).
    pub offset: usize,
}

/// A record's layout as Rust lays it out.
#[derive(Clone, Copy, Debug)]
pub struct RecordLayout {
    /// The Rust name.
    pub rust: &'static str,
    /// The GLSL name.
    pub glsl: &'static str,
    /// `size_of`.
    pub size: usize,
    /// The fields, in order.
    pub fields: &'static [FieldLayout],
}

/// The push constants of a shader that has none.
pub const NO_PUSH_CONSTANTS: RecordLayout = RecordLayout {
    rust: "no push constants",
    glsl: "(none)",
    size: 0,
    fields: &[],
};

/// A record shared with the shaders.
pub trait ShaderRecord: Copy {
    /// Its layout.
    const LAYOUT: RecordLayout;
}

macro_rules! glsl_name {
    ($rust:ident) => {
        stringify!($rust)
    };
    ($rust:ident $glsl:ident) => {
        stringify!($glsl)
    };
}

/// Declares records: each a `#[repr(C)]` struct deriving Pod (and what is listed), with its
/// [`ShaderRecord`] layout; `struct A as B` is called `B` in GLSL.
macro_rules! records {
    ($(
        $(#[$attr:meta])*
        pub struct $name:ident $(as $glsl:ident)? {
            $( $(#[$fattr:meta])* pub $field:ident : $ty:ty ),* $(,)?
        }
    )*) => {
        $(
            $(#[$attr])*
            #[repr(C)]
            #[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
            pub struct $name {
                $( $(#[$fattr])* pub $field: $ty, )*
            }
            impl $name {
                /// Its layout (also [`ShaderRecord::LAYOUT`]).
                pub const LAYOUT: RecordLayout = RecordLayout {
                    rust: stringify!($name),
                    glsl: glsl_name!($name $($glsl)?),
                    size: std::mem::size_of::<$name>(),
                    fields: &[$(FieldLayout {
                        name: stringify!($field),
                        ty: stringify!($ty),
                        offset: std::mem::offset_of!($name, $field),
                    }),*],
                };
            }
            impl ShaderRecord for $name {
                const LAYOUT: RecordLayout = $name::LAYOUT;
            }
        )*
        /// Every record, in declaration order (a record is declared after those it holds).
        pub const RECORDS: &[RecordLayout] = &[$(<$name as ShaderRecord>::LAYOUT),*];
    };
}

/// Declares `u32` constants shared with the shaders (GLSL `const uint`).
macro_rules! constants {
    ($( $(#[$attr:meta])* pub const $name:ident: u32 = $value:expr; )*) => {
        $( $(#[$attr])* pub const $name: u32 = $value; )*
        /// Every constant, in declaration order.
        pub const CONSTANTS: &[(&str, u32)] = &[$((stringify!($name), $name)),*];
    };
}

constants! {
    /// `FrameParams::filters.w`, the alpha falloff: opacity * exp(-d2 / 2) (the reference).
    pub const SPLAT_KERNEL_GAUSSIAN: u32 = 0;
    /// The power falloff: opacity * max(0, 1 - d2 / 9).
    pub const SPLAT_KERNEL_POWER: u32 = 1;
    /// `FrameParams::modes.x`: the original rasterizer's screen extent and rules.
    pub const RULES_ORIGINAL: u32 = 0;
    /// gsplat's.
    pub const RULES_GSPLAT: u32 = 1;
    /// `FrameParams::modes.y`, the camera's lens (`camera::Lens`): the pinhole, projected
    /// by the EWA rule; every other lens by the unscented transform.
    pub const LENS_PINHOLE: u32 = 0;
    /// Brown-Conrady radial-tangential distortion (`lens_a` = k1..k4, `lens_b` = k5, k6,
    /// p1, p2).
    pub const LENS_RADIAL_TANGENTIAL: u32 = 1;
    /// The equidistant fisheye (`lens_a` = k1..k4, `lens_b.x` = the largest angle from
    /// the axis imaged).
    pub const LENS_FISHEYE: u32 = 2;
    /// Orthographic.
    pub const LENS_ORTHOGRAPHIC: u32 = 3;
    /// Equirectangular (`lens_a` = the window's left and right longitudes, top and
    /// bottom latitudes).
    pub const LENS_EQUIRECTANGULAR: u32 = 4;
    /// `StepPush::flags_size.x`: add the frame's densification statistics.
    pub const STEP_STATS: u32 = 1;
    /// Take an Adam step.
    pub const STEP_ADAM: u32 = 2;
    /// Leave the opacities alone (just reset).
    pub const STEP_SKIP_OPACITY: u32 = 4;
    /// The colour is feature channels, not SH.
    pub const STEP_FEATURES: u32 = 8;
    /// Write the gradients' squared norms (for clipping).
    pub const STEP_NORM: u32 = 16;
    /// Clip the gradients by their total norm.
    pub const STEP_CLIP: u32 = 32;
    /// The MCMC strategy's regularisers and noise.
    pub const STEP_NOISE: u32 = 64;
    /// Mip-Splatting's 3D filter: the record's unused float holds each Gaussian's
    /// (`train::model::mip`).
    pub const STEP_MIP: u32 = 128;
    /// Where the colour starts in a trained Gaussian's record of floats (a multiple of 4):
    /// centre 3, log scale 3, quaternion 4, opacity logit 1, the 3D filter (STEP_MIP).
    pub const COLOUR_OFFSET: u32 = 12;
    /// The neural shader's widest layer (inputs or outputs).
    pub const MAX_WIDTH: u32 = 128;
    /// The neural shader's most layers.
    pub const MAX_LAYERS: u32 = 8;
}

records! {
    /// Per-frame parameters (one record, written with vkCmdUpdateBuffer).
    pub struct FrameParams {
        /// World-to-camera rotation row 0, `w` = translation x.
        pub w2c_row0: vec4,
        /// Row 1, `w` = translation y.
        pub w2c_row1: vec4,
        /// Row 2, `w` = translation z.
        pub w2c_row2: vec4,
        /// Camera centre (xyz); `w` is 1 with the antialiasing opacity compensation, else 0.
        pub cam_pos: vec4,
        /// fx, fy, cx, cy.
        pub focal: vec4,
        /// The guard band of the 2D covariance (`model::Rules::clamp_limits`): `x/z` is
        /// clamped to `[-x, y]`, `y/z` to `[-z, w]`.
        pub limits: vec4,
        /// Background rgb.
        pub background: vec4,
        /// width, height, tiles_x, tiles_y.
        pub image: uvec4,
        /// Gaussians, active SH degree, stored SH coefficients per channel, key capacity.
        pub counts: uvec4,
        /// Bin size in pixels (16 or 8), bins_x, bins_y, 16 / bin size.
        pub bins: uvec4,
        /// Scale modifier, max scale (< 0: no limit), min opacity (< 0: no limit), and the
        /// alpha falloff (`SPLAT_KERNEL_*` as a float): the per-frame options of
        /// `RenderOptions`, applied by preprocess (the falloff also picks the blend
        /// pipeline).
        pub filters: vec4,
        /// The rules' numbers (`model::Rules`): a centre is kept when its depth is above
        /// `x` (the near plane, or the float below gsplat's), alpha clamp, a pixel ends
        /// before its transmittance would drop below `z`, the antialiased compensation's
        /// lowest ratio.
        pub rules: vec4,
        /// `RULES_*` (the screen extent's rule), `LENS_*` (the camera's lens), 1 where
        /// the image wraps around (`camera::Lens::wraps`: a splat across the seam is drawn
        /// on both sides) and a zero.
        pub modes: uvec4,
        /// The lens's first four coefficients (see the `LENS_*` constants).
        pub lens_a: vec4,
        /// Its next four.
        pub lens_b: vec4,
        /// The unscented transform (`model::unscented`): the sigma points' spread, the
        /// centre's mean weight, every other point's weight, the centre's covariance
        /// weight.
        pub unscented: vec4,
        /// How far outside the image a sigma point still counts as in view, as a
        /// fraction of its width and height; a distorted lens's fold, the squared radius
        /// of `(x / z, y / z)` from which it images nothing (`camera::lens::radial_fold`);
        /// two zeros.
        pub lens_c: vec4,
    }

    /// One uploaded Gaussian, activated.
    pub struct GpuGaussian as Gaussian {
        /// xyz centre, w = opacity (sigmoid applied).
        pub pos_opacity: vec4,
        /// xyz axis scales (exp applied), w unused.
        pub scale: vec4,
        /// Normalised quaternion (w, x, y, z).
        pub rotation: vec4,
    }

    /// One uploaded Gaussian, compact (`--compact`): centre and opacity in f32, the axis
    /// scales and the rotation as fp16 pairs; unpacking is exact.
    pub struct GpuGaussianCompact as GaussianCompact {
        /// xyz centre, w = opacity.
        pub pos_opacity: vec4,
        /// (scale x, y), (scale z, rotation w), (rotation x, y), (rotation z, 0) as fp16
        /// pairs.
        pub shape: uvec4,
    }

    /// A projected Gaussian, written by preprocess, read by keys and blend. The first two
    /// vec4s hold everything needed to tell whether it reaches a pixel (`alpha_bound`).
    pub struct Splat {
        /// mean2d.xy, opacity, alpha_bound(opacity).
        pub mean_opacity_bound: vec4,
        /// conic A, B, C, view depth.
        pub conic_depth: vec4,
        /// rgb from SH, radius (pixels; 0 when culled).
        pub color_radius: vec4,
    }

    /// Frame counters (one record, cleared at the start of each frame).
    pub struct Counters {
        /// Sum of tiles touched modulo 2^32 (the scan's total).
        pub scan_total: uint,
        /// Number of keys sorted: min(total, capacity).
        pub sort_count: uint,
        /// Exact sum of tiles touched, low word ...
        pub touched_lo: uint,
        /// ... and high word, so overflow past 2^32 is detected.
        pub touched_hi: uint,
        /// VkDispatchIndirectCommand of the ranges stage.
        pub ranges_groups: [uint; 3],
        /// Gaussians touching at least one tile.
        pub visible: uint,
        /// Largest bin loop of one Gaussian (preprocess, keys), recorded past LOOP_REPORT.
        pub max_bins_loop: uint,
        /// Largest list loop of one bin (blend), recorded past LOOP_REPORT.
        pub max_list_loop: uint,
        /// Padding.
        pub pad: [uint; 2],
    }

    /// One Gaussian's gradients from the backward pass: (dmean xyz, dopacity), dquat
    /// (w, x, y, z), (dscale xyz, 0), (dmean2d xy, absgrad xy).
    pub struct GaussianGrad {
        /// dL/d centre xyz, dL/d opacity (activated).
        pub mean_opacity: vec4,
        /// dL/d quaternion (w, x, y, z).
        pub quat: vec4,
        /// dL/d scale xyz (activated), 0.
        pub scale: vec4,
        /// dL/d 2D mean xy, and its absolute-value sums xy (densification).
        pub mean2d_abs: vec4,
    }

    /// A window of Gaussians (preprocess).
    pub struct WindowPush {
        /// First Gaussian of the window.
        pub first: uint,
        /// Gaussians in the window.
        pub count: uint,
    }

    /// A chunk of the keys stage.
    pub struct KeysPush {
        /// First depth-order position of the chunk.
        pub first: uint,
        /// One past its last.
        pub end: uint,
        /// Key slot of the chunk's first pair.
        pub base: uint,
    }

    /// A chunk of the blend: whether it resumes the pixels' state and is the last; and
    /// the band of tile rows it runs (a frame whose last contributors exceed one binding
    /// saves them in bands).
    pub struct BlendPush {
        /// Non-zero: read the state the previous chunk left.
        pub resume: uint,
        /// Non-zero: the frame's last chunk (write the final colour).
        pub last: uint,
        /// The first tile row dispatched (workgroup row 0), whose first pixel row is where
        /// the last-contributor binding starts.
        pub first_tile_row: uint,
        /// Padding.
        pub pad: uint,
    }

    /// A chunk of the feature blend.
    pub struct FeatureBlendPush {
        /// Non-zero: read the state the previous chunk left.
        pub resume: uint,
        /// Padding.
        pub pad: uint,
    }

    /// The 8-bit pack: the frame's size.
    pub struct PackPush {
        /// Width in pixels.
        pub width: uint,
        /// Height in pixels.
        pub height: uint,
    }

    /// The accumulation and the preprocess backward: the items dispatched over (pairs;
    /// Gaussians), and log2 of the most pairs one Gaussian can have.
    pub struct GradPush {
        /// Sorted pairs (accumulation) or Gaussians (preprocess backward).
        pub count: uint,
        /// `ceil(log2(bins))`.
        pub bits: uint,
        /// vec4s of fields per pair: 3, plus one per group of four feature channels.
        pub vecs: uint,
    }

    /// The neural shader's constants (`shade`, and the first part of `shade_bwd`'s).
    pub struct ShadePush {
        /// Width, height, K channels, groups of four channels.
        pub size: uvec4,
        /// Input code (`Mlp::input_code`), layers, plane stride (vec4s), and for the
        /// backward pass the first chunk.
        pub code: uvec4,
        /// fx, fy, cx, cy.
        pub intrinsics: vec4,
        /// Rows of the world-to-camera rotation.
        pub rot: [vec4; 3],
        /// Background rgb.
        pub background: vec4,
    }

    /// The neural shader's backward pass: the forward's constants, then the pass's shape.
    pub struct ShadeBwdPush {
        /// The forward's.
        pub shade: ShadePush,
        /// Scratch vec4s per workgroup, 0, parameters, 0.
        pub shape: uvec4,
    }

    /// The field renders' parameter block.
    pub struct FieldParams {
        /// Width, height, Gaussians, channel groups.
        pub size: uvec4,
        /// Samples along the ray (maximum).
        pub mode: uvec4,
        /// World-to-camera rotation rows, translation in `w`.
        pub w2c: [vec4; 3],
        /// Camera centre; `w` the kernel's cutoff `d2`.
        pub origin: vec4,
        /// fx, fy, cx, cy.
        pub focal: vec4,
        /// The slice plane's point.
        pub plane_point: vec4,
        /// The slice plane's unit normal.
        pub plane_normal: vec4,
        /// The field's box, lower corner.
        pub bounds_min: vec4,
        /// Upper corner.
        pub bounds_max: vec4,
    }

    /// One Gaussian as the field renders read it: centre and support radius, inverse
    /// covariance.
    pub struct FieldGaussian {
        /// Centre, and the radius of the support's bounding sphere.
        pub mean_radius: vec4,
        /// A: xx, xy, xz, yy.
        pub a0: vec4,
        /// A: yz, zz, 0, 0.
        pub a1: vec4,
    }

    /// One pass of a field render: channel group, the Gaussians `[first, first + count)`,
    /// and whether to add to the output rather than write it.
    pub struct FieldPush {
        /// Channel group.
        pub group: uint,
        /// First Gaussian.
        pub first: uint,
        /// Gaussians in the pass.
        pub count: uint,
        /// Non-zero: add to the output.
        pub accumulate: uint,
    }

    /// The training step (`train_step`).
    pub struct StepPush {
        /// Gaussians, floats per stored record, colour floats C (3 (d + 1)^2 SH
        /// coefficients, or K feature channels), SH floats per Gaussian in the texels.
        pub counts: uvec4,
        /// `STEP_*` bits; half the frame's width and height (floats); feature groups.
        pub flags_size: uvec4,
        /// Learning rates: centre, log scale, quaternion, opacity logit.
        pub lr: vec4,
        /// Colour learning rates (SH DC or features, SH rest) and the colour group's bias
        /// corrections (1 - b1^t, sqrt(1 - b2^t)).
        pub lr_sh: vec4,
        /// Bias corrections 1 - b1^t of centre, log scale, quaternion, opacity.
        pub c1: vec4,
        /// Bias corrections sqrt(1 - b2^t) of the same groups.
        pub c2: vec4,
        /// The largest gradient norm (`STEP_CLIP`); MCMC: the noise scale, the opacity and
        /// scale regularisers' weights over n and 3 n.
        pub clip: vec4,
        /// MCMC: the noise key of the iteration (`model::noise_key`).
        pub noise: uvec4,
    }

    /// The neural shader's optimiser step (`train_mlp_step`).
    pub struct MlpPush {
        /// Values, words of the header before them, `STEP_*` bits, first NORMS entry.
        pub sizes: uvec4,
        /// Learning rate, bias corrections (1 - b1^t, sqrt(1 - b2^t)), the largest norm.
        pub lr_c: vec4,
    }

    /// A frame's size (`ssim_prepare`, `ssim_map`): width, height.
    pub struct SizePush {
        /// Width, height, 0, 0.
        pub size: uvec4,
    }

    /// A reduction's counts (`loss_reduce`: values; `mlp_grad_reduce`: parameters, slots),
    /// or the blend backward's band (`blend_bwd`: its pairs, first bin row and first pixel
    /// row).
    pub struct CountsPush {
        /// The counts.
        pub counts: uvec4,
    }

    /// An image's size and three vec4 rows: the SSIM filter's (`ssim_filter`) and a
    /// training photo's affine colour transform (`appearance_apply`, `appearance_grad`).
    /// One record for both: glslang 2023.2 (Debian's glslc) takes gigabytes and minutes on
    /// `train_step` once `interface.glsl` declares a 27th record, so a push block of the
    /// same layout shares this one.
    pub struct ImageRowsPush {
        /// `ssim_filter`: width, height, vec4s per pixel, axis (0: x, 1: y); the
        /// appearance: width, height, 0, 0.
        pub size: uvec4,
        /// `ssim_filter`: the 11 normalised taps (`metrics::ssim`'s, in f32); the
        /// appearance: row r of `[A | b]`, that is (A[r][0], A[r][1], A[r][2], b[r]).
        pub rows: [vec4; 3],
    }

    /// The loss gradient (`ssim_grad`).
    pub struct LossGradPush {
        /// Width, height.
        pub size: uvec4,
        /// (1 - lambda) / n, lambda / n.
        pub scale: vec4,
    }

    /// `sort_setup`.
    pub struct SortSetupPush {
        /// Element count when given by the host.
        pub host_n: uint,
        /// u32 index of the count in the count buffer, or `u32::MAX` for `host_n`.
        pub count_index: uint,
        /// Capacity: the count is clamped to this.
        pub max_n: uint,
        /// `maxComputeWorkGroupCount[0]`.
        pub max_groups_x: uint,
    }

    /// `sort_histogram` and `sort_scatter`.
    pub struct SortPassPush {
        /// First key bit of this pass's digit.
        pub shift: uint,
        /// Digit width of this pass (the last pass may be narrower).
        pub bits: uint,
        /// Row length of the digit-major histogram table (blocks at capacity).
        pub hist_stride: uint,
        /// Padding to 16 bytes.
        pub pad: uint,
    }

    /// `scan_reduce`, `scan_block` and `scan_add`.
    pub struct ScanPush {
        /// Number of elements.
        pub n: uint,
        /// Non-zero: write the grand total to `totals[total_index]` (scan_block only).
        pub write_total: uint,
        /// u32 index of the total in the total buffer.
        pub total_index: uint,
        /// Padding to 16 bytes.
        pub pad: uint,
    }
}

/// (alignment, size) of a GLSL type as std430 lays it out; `None` for a name that is
/// neither a GLSL type [`glsl`] spells nor a record declared before.
fn std430(ty: &str, records: &[RecordLayout]) -> Option<(usize, usize)> {
    let ty = ty.trim();
    if let Some(inner) = ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
        let (elem, len) = inner.rsplit_once(';')?;
        let (align, size) = std430(elem, records)?;
        let len: usize = len.trim().parse().ok()?;
        return Some((align, size.next_multiple_of(align) * len));
    }
    Some(match ty {
        "uint" | "int" | "float" => (4, 4),
        "uvec2" | "vec2" => (8, 8),
        "uvec4" | "ivec4" | "vec4" => (16, 16),
        _ => {
            let record = records.iter().find(|r| r.rust == ty || r.glsl == ty)?;
            record_std430(record, records).ok()?
        }
    })
}

/// (alignment, size) of `record` in std430, or which field Rust places elsewhere.
fn record_std430(
    record: &RecordLayout,
    records: &[RecordLayout],
) -> Result<(usize, usize), String> {
    let mut offset: usize = 0;
    let mut align: usize = 4;
    for f in record.fields {
        let (a, size) = std430(f.ty, records)
            .ok_or_else(|| format!("{}.{}: unknown type {}", record.rust, f.name, f.ty))?;
        offset = offset.next_multiple_of(a);
        if offset != f.offset {
            return Err(format!(
                "{}.{}: Rust places it at byte {}, std430 at {offset}",
                record.rust, f.name, f.offset
            ));
        }
        offset += size;
        align = align.max(a);
    }
    let size = offset.next_multiple_of(align);
    if size != record.size {
        return Err(format!(
            "{}: Rust's size is {} bytes, std430's {size}",
            record.rust, record.size
        ));
    }
    Ok((align, size))
}

/// The GLSL spelling of a field: `vec4 name` or `vec4 name[3]`; a record by its GLSL name.
fn glsl_field(ty: &str, name: &str, records: &[RecordLayout]) -> String {
    let ty = ty.trim();
    if let Some((elem, len)) = ty
        .strip_prefix('[')
        .and_then(|t| t.strip_suffix(']'))
        .and_then(|t| t.rsplit_once(';'))
    {
        return format!("{}[{}]", glsl_field(elem, name, records), len.trim());
    }
    let ty = records.iter().find(|r| r.rust == ty).map_or(ty, |r| r.glsl);
    format!("{ty} {name}")
}

/// `interface.glsl`: the constants and the record declarations, each checked against
/// std430 (`Err` names the field Rust lays out differently).
pub fn glsl_declarations() -> Result<String, String> {
    let mut out = String::from(
        "// Written by build.rs from src/core/shader_interface.rs: the records, push blocks and\n\
         // flags the host shares with the shaders. Do not edit; change the Rust.\n\
         #ifndef VERISPLAT_INTERFACE_GLSL\n#define VERISPLAT_INTERFACE_GLSL\n\n",
    );
    for (name, value) in CONSTANTS {
        out.push_str(&format!("const uint {name} = {value}u;\n"));
    }
    for (i, record) in RECORDS.iter().enumerate() {
        // A record may only hold those declared before it (GLSL's order).
        record_std430(record, &RECORDS[..i])?;
        out.push_str(&format!("\nstruct {} {{\n", record.glsl));
        for f in record.fields {
            out.push_str(&format!("    {};\n", glsl_field(f.ty, f.name, RECORDS)));
        }
        out.push_str("};\n");
    }
    out.push_str("\n#endif\n");
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_record_is_laid_out_as_std430() {
        let text = glsl_declarations().expect("std430");
        assert!(text.contains("struct Gaussian {\n    vec4 pos_opacity;"));
        assert!(text.contains("    uint ranges_groups[3];\n"));
        assert!(text.contains("    ShadePush shade;\n"));
        assert!(text.contains("const uint STEP_NOISE = 64u;\n"));
    }

    /// The shaders declare none of the records or constants themselves, each push block
    /// is one record, no workgroup size is a literal, and no shader comment names a Rust
    /// file.
    #[test]
    fn the_shaders_take_every_record_and_flag_from_the_interface() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("glsl");
        let mut files = 0;
        let mut blocks = 0;
        // Every file of the wings' folders.
        let (mut paths, mut folders) = (Vec::new(), vec![dir]);
        while let Some(folder) = folders.pop() {
            for entry in std::fs::read_dir(&folder).unwrap() {
                let path = entry.unwrap().path();
                match path.is_dir() {
                    true => folders.push(path),
                    false => paths.push(path),
                }
            }
        }
        for path in paths {
            let name = path.file_name().unwrap().to_string_lossy().to_string();
            if !(name.ends_with(".comp") || name.ends_with(".glsl")) {
                continue;
            }
            files += 1;
            let text = std::fs::read_to_string(&path).unwrap();
            for r in RECORDS {
                let decl = format!("struct {} {{", r.glsl);
                assert!(
                    !text.contains(&decl),
                    "{name} declares {decl}: use interface.glsl"
                );
            }
            for (constant, _) in CONSTANTS {
                for decl in [
                    format!("#define {constant} "),
                    format!("const uint {constant} "),
                ] {
                    assert!(!text.contains(&decl), "{name} declares {constant} itself");
                }
            }
            for (i, line) in text.lines().enumerate() {
                let at = format!("{name}:{}", i + 1);
                assert!(
                    !(line.contains("src/") || line.contains(".rs)") || line.contains(".rs ")),
                    "{at} names a Rust file: {line}"
                );
                // Workgroup sizes are host constants (gpu::shader_set), never literals (but
                // the 1 of a dimension a workgroup does not use).
                for (i, _) in line.match_indices("local_size_") {
                    let value = line[i..].split_once('=').map(|(_, v)| v.trim_start());
                    let literal = value.map(|v| {
                        v.chars()
                            .take_while(char::is_ascii_digit)
                            .collect::<String>()
                    });
                    assert!(
                        literal.as_deref().is_none_or(|n| n.is_empty() || n == "1"),
                        "{at} types a workgroup size: {line}"
                    );
                }
                let Some(rest) = line.trim().strip_prefix("layout(push_constant) uniform ") else {
                    continue;
                };
                blocks += 1;
                // `XBlock { Record name; };`
                let body = rest
                    .split_once('{')
                    .and_then(|(_, b)| b.split_once('}'))
                    .map(|(b, _)| b.trim())
                    .unwrap_or_else(|| panic!("{at}: a push block on one line"));
                let ty = body.split_whitespace().next().unwrap_or("");
                assert!(
                    body.matches(';').count() == 1 && RECORDS.iter().any(|r| r.glsl == ty),
                    "{at}: the push block is not one record of the interface: {line}"
                );
            }
        }
        assert!(
            files > 30 && blocks > 20,
            "{files} files, {blocks} push blocks"
        );
    }

    #[test]
    fn a_misplaced_field_is_named() {
        // A vec4 after one uint: std430 aligns it to 16, a packed struct would not.
        const BAD: RecordLayout = RecordLayout {
            rust: "Bad",
            glsl: "Bad",
            size: 20,
            fields: &[
                FieldLayout {
                    name: "a",
                    ty: "uint",
                    offset: 0,
                },
                FieldLayout {
                    name: "b",
                    ty: "vec4",
                    offset: 4,
                },
            ],
        };
        let e = record_std430(&BAD, RECORDS).unwrap_err();
        assert_eq!(e, "Bad.b: Rust places it at byte 4, std430 at 16");
    }

    #[test]
    fn fixed_offsets_the_host_uses() {
        // The counters' fields the host copies or dispatches from by offset.
        let c = Counters::LAYOUT;
        let at = |n: &str| c.fields.iter().find(|f| f.name == n).unwrap().offset;
        assert_eq!(
            (at("scan_total"), at("sort_count"), at("ranges_groups")),
            (0, 4, 16)
        );
        assert_eq!(c.size, 48);
        assert_eq!(FrameParams::LAYOUT.size, 272);
        assert_eq!(GaussianGrad::LAYOUT.size, 64);
    }
}
