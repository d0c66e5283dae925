// The training loss's per-pixel stages: one invocation per pixel,
// workgroups of 64 laid out in two dimensions so that any image fits the dispatch limits.

#include "interface.glsl"

layout(local_size_x = 64) in;

uint pixel_index() {
    return (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * 64u + gl_LocalInvocationID.x;
}
