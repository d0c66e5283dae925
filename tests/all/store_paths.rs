//! Microbenchmark (ignored): how lavapipe's per-lane memory operations cost by path.
//! `cargo test --release --test all store_paths:: -- --ignored --nocapture`

use ash::vk;
use vksplat::gpu::buffer::{BufferView, GpuBuffer, MemoryKind};
use vksplat::gpu::shader::{compile_glsl, BindingKind, Resource};
use vksplat::gpu::{ComputePipeline, ContextOptions, GpuContext, GpuTimer};

const HEAD: &str = "#version 460\nlayout(local_size_x = 256) in;\n";

#[test]
#[ignore]
fn store_and_load_paths() {
    let ctx = GpuContext::new(&ContextOptions::default()).expect("context");
    let n: u32 = 1 << 22;
    let perm: Vec<u32> = (0..n).map(|i| (i.wrapping_mul(2654435761)) % n).collect();
    let src: Vec<u32> = (0..n).collect();
    let perm_buf = GpuBuffer::from_slice(&ctx, "perm", &perm).unwrap();
    let src_buf = GpuBuffer::from_slice(&ctx, "src", &src).unwrap();
    let dst_buf = GpuBuffer::new(&ctx, "dst", 16 * u64::from(n), MemoryKind::Device).unwrap();
    let u32_view =
        |b: &GpuBuffer, bytes| BufferView::new(&ctx, b, vk::Format::R32_UINT, 0, bytes).unwrap();
    let v4_view = |b: &GpuBuffer| {
        BufferView::new(&ctx, b, vk::Format::R32G32B32A32_SFLOAT, 0, b.size()).unwrap()
    };
    let src_view = u32_view(&src_buf, src_buf.size());
    let perm_view = u32_view(&perm_buf, perm_buf.size());
    let dst_view = u32_view(&dst_buf, 4 * u64::from(n));
    let dst_v4 = v4_view(&dst_buf);
    // The blend's output path: imageStore of a vec4 into a 2D image vs a texel buffer.
    let (w, h) = (2048u32, n / 2048);
    let image =
        vksplat::gpu::GpuImage::new(&ctx, "image", w, h, vk::Format::R32G32B32A32_SFLOAT).unwrap();
    let ssbo = [
        Resource::Buffer(src_buf.whole()),
        Resource::Buffer(perm_buf.whole()),
        Resource::Buffer(dst_buf.whole()),
    ];
    let texel = |dst: &BufferView| {
        [
            Resource::TexelBuffer(src_view.handle()),
            Resource::TexelBuffer(perm_view.handle()),
            Resource::TexelBuffer(dst.handle()),
        ]
    };
    use BindingKind::*;
    let cases: Vec<(&str, &str, Vec<BindingKind>, Vec<Resource>)> = vec![
        ("ssbo load/ssbo scatter u32", "layout(std430, binding=0) readonly buffer A { uint a[]; }; layout(std430, binding=1) readonly buffer P { uint p[]; }; layout(std430, binding=2) writeonly buffer D { uint d[]; };\nvoid main() { uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u; d[p[i]] = a[i]; }", vec![StorageBuffer, StorageBuffer, StorageBuffer], ssbo.to_vec()),
        ("texel load/imageStore scatter u32", "layout(binding=0) uniform usamplerBuffer a; layout(binding=1) uniform usamplerBuffer p; layout(binding=2, r32ui) uniform writeonly uimageBuffer d;\nvoid main() { int i = int(gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u); imageStore(d, int(texelFetch(p, i).x), texelFetch(a, i)); }", vec![UniformTexelBuffer, UniformTexelBuffer, StorageTexelBuffer], texel(&dst_view).to_vec()),
        ("ssbo load/ssbo store vec4 (contiguous)", "layout(std430, binding=0) readonly buffer A { uint a[]; }; layout(std430, binding=1) readonly buffer P { uint p[]; }; layout(std430, binding=2) writeonly buffer D { vec4 d[]; };\nvoid main() { uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u; d[i] = vec4(float(a[i]), 1.0, 2.0, float(p[i])); }", vec![StorageBuffer, StorageBuffer, StorageBuffer], ssbo.to_vec()),
        ("texel load/imageStore vec4 (contiguous)", "layout(binding=0) uniform usamplerBuffer a; layout(binding=1) uniform usamplerBuffer p; layout(binding=2, rgba32f) uniform writeonly imageBuffer d;\nvoid main() { int i = int(gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u); imageStore(d, i, vec4(float(texelFetch(a, i).x), 1.0, 2.0, float(texelFetch(p, i).x))); }", vec![UniformTexelBuffer, UniformTexelBuffer, StorageTexelBuffer], texel(&dst_v4).to_vec()),
        ("imageStore vec4 into image2D", "layout(binding=0, rgba32f) uniform writeonly image2D d;\nvoid main() { uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u; imageStore(d, ivec2(i % 2048u, i / 2048u), vec4(float(i), 1.0, 2.0, 3.0)); }", vec![StorageImage], vec![Resource::Image { view: image.view(), layout: vk::ImageLayout::GENERAL }]),
        ("imageStore vec4 into imageBuffer", "layout(binding=0, rgba32f) uniform writeonly imageBuffer d;\nvoid main() { uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u; imageStore(d, int(i), vec4(float(i), 1.0, 2.0, 3.0)); }", vec![StorageTexelBuffer], vec![Resource::TexelBuffer(dst_v4.handle())]),
    ];
    let mut timer = GpuTimer::new(&ctx, "t", 8).unwrap();
    for (name, body, kinds, res) in cases {
        let spirv = compile_glsl(name, &format!("{HEAD}{body}"), &[]).unwrap();
        let p = ComputePipeline::new(&ctx, "case", &spirv, &kinds, 0, 256).unwrap();
        let mut ms = Vec::new();
        for _ in 0..4 {
            ctx.submit_and_wait("mb", |cmd| {
                image.transition_to_general(&ctx, cmd);
                timer.reset(&ctx, cmd);
                timer.stage(&ctx, cmd, "x", |cmd| {
                    p.dispatch_resources(&ctx, cmd, &res, &[], [256, n / 65536, 1])
                })
            })
            .unwrap();
            ms.push(timer.span_ms(&ctx).unwrap());
        }
        ms.sort_by(f64::total_cmp);
        eprintln!(
            "{name:45} {:.2} ms for {n} elements ({:.1} ns each)",
            ms[1],
            ms[1] * 1e6 / f64::from(n)
        );
    }
}
