#version 460
// What a subgroup really is on this device, measured rather than taken from the driver
// (the host's subgroup probe): one workgroup of 128 invocations records, per invocation, the
// gl_SubgroupSize it is told and the lanes that actually run together (a ballot of
// every active lane, and a subgroup sum of ones). On a conformant device they agree;
// llvmpipe configured wider than 512 bits reports 32 or 64 lanes but runs 16.
#define WG_SIZE 128
#include "common.glsl"

layout(std430, binding = SUBGROUP_PROBE_OUT) buffer Out { uint o[]; };

void main() {
    uint ballot_lanes = subgroupBallotBitCount(subgroupBallot(true));
    uint summed_lanes = subgroupAdd(1u);
    atomicMax(o[0], gl_SubgroupSize);
    atomicMin(o[1], gl_SubgroupSize);
    atomicMax(o[2], ballot_lanes);
    atomicMin(o[3], ballot_lanes);
    atomicMax(o[4], summed_lanes);
    atomicMin(o[5], summed_lanes);
    atomicMax(o[6], gl_SubgroupInvocationID + 1u);
    atomicMax(o[7], gl_NumSubgroups);
    atomicMax(o[8], gl_SubgroupID + 1u);
}
