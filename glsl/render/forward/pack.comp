#version 460
#extension GL_GOOGLE_include_directive : require
// Pack: the frame's colour as 8-bit RGBA (alpha 255) for consumers that show it (the
// viewer), so a quarter of the colour plane's bytes leaves the device. Quantised exactly as
// output::to_u8 on the host: clamp(v * 255 + 0.5, 0, 255) truncated, NaN to 0, with the
// multiply and the add rounded separately (`precise` forbids fusing them), so a packed
// frame equals the PNG that `verisplat render` writes from the float frame, bit for bit.

// PIXEL_WG_X x PIXEL_WG_Y (16 x 8) pixels: 128 invocations, within every device's limit.
layout(local_size_x = PIXEL_WG_X, local_size_y = PIXEL_WG_Y) in;

layout(binding = PACK_COLOR, rgba32f) uniform readonly image2D color;  // rgb + T * background
layout(std430, binding = PACK_PACKED) writeonly buffer PackedBuf { uint packed[]; };

#include "interface.glsl"

layout(push_constant) uniform PackBlock { PackPush size; };

uint to_u8(float v) {
    precise float x = v * 255.0;
    precise float y = x + 0.5;
    // `!(y >= 0)` catches NaN and negatives (Rust's saturating cast gives 0 for both).
    if (!(y >= 0.0)) return 0u;
    return uint(min(y, 255.0));
}

void main() {
    uvec2 p = gl_GlobalInvocationID.xy;
    if (p.x >= size.width || p.y >= size.height) return;
    vec4 c = imageLoad(color, ivec2(p));
    packed[p.y * size.width + p.x] = to_u8(c.r) | (to_u8(c.g) << 8) | (to_u8(c.b) << 16) | (255u << 24);
}
