#version 460
// Training appearance (`--appearance affine`): a photo's colour transform applied to the
// rendered image, c' = A c + b per pixel (background included), into the buffer the loss
// reads; the rendered image stays as it is for the transform's gradient (appearance_grad).
#extension GL_GOOGLE_include_directive : require
#include "loss_common.glsl"

layout(push_constant) uniform AffineBlock { ImageRowsPush p; };

layout(std430, binding = APPEARANCE_APPLY_IMAGE) readonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = APPEARANCE_APPLY_CORRECTED) writeonly buffer CorrectedBuf { vec4 corrected[]; };

void main() {
    uint i = pixel_index();
    if (i >= p.size.x * p.size.y) return;
    vec4 c = image[i];
    precise vec3 out_ = vec3(
        dot(p.rows[0].xyz, c.rgb) + p.rows[0].w,
        dot(p.rows[1].xyz, c.rgb) + p.rows[1].w,
        dot(p.rows[2].xyz, c.rgb) + p.rows[2].w);
    corrected[i] = vec4(out_, c.w);
}
