// The training loss's per-pixel stages: one invocation per pixel,
// workgroups of LOSS_WG (64) laid out in two dimensions so that any image fits the dispatch limits.

#include "interface.glsl"

layout(local_size_x = LOSS_WG) in;

uint pixel_index() {
    return (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * LOSS_WG + gl_LocalInvocationID.x;
}
