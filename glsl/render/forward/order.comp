#version 460
// Depth order, second half: after the stable depth sort of the depth-bit keys (values: the
// Gaussian indices), gather the tiles-touched counts into depth order for the scan. Keys are then emitted in
// depth order, so the pair sort only needs the tile bits: for equal tiles the stable sort
// keeps depth order, and for equal depths the depth sort kept index order, which is exactly
// the order of a stable sort of the full tile << 32 | depth keys emitted in index order.
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"

layout(local_size_x = LINEAR_WG) in;

layout(std430, binding = ORDER_PARAMS) readonly buffer ParamsBuf { FrameParams params; };
layout(std430, binding = ORDER_DEPTH_ORDER) readonly buffer OrderBuf { uint depth_order[]; };
layout(std430, binding = ORDER_TOUCHED) readonly buffer TouchedBuf { uint touched_by_index[]; };
layout(std430, binding = ORDER_TOUCHED_IN_ORDER) writeonly buffer TouchedInOrderBuf { uint touched_in_order[]; };

void main() {
    uint k = linear_group_id() * LINEAR_WG + gl_LocalInvocationIndex;
    if (k < params.counts.x) touched_in_order[k] = touched_by_index[depth_order[k]];
}
