// Shared header for all verisplat compute shaders.
//
// Constants shared with the host are defined once, on the host, and passed in as
// #defines; the records, push blocks and flags come from interface.glsl, which the build
// writes from their one declaration on the host; the sort's tunables are specialization constants
// (sort_spec.glsl). This header provides the helpers every stage uses.
#ifndef VERISPLAT_COMMON_GLSL
#define VERISPLAT_COMMON_GLSL

#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_ballot : require
#include "subgroup.glsl"
#include "interface.glsl"

#ifdef WG_SIZE_SPEC_ID
// The workgroup size is a specialization constant (the sort's).
layout(local_size_x_id = WG_SIZE_SPEC_ID, local_size_y = 1, local_size_z = 1) in;
#define WG_SIZE gl_WorkGroupSize.x
#else
#ifndef WG_SIZE
#error "define WG_SIZE (the workgroup size) or WG_SIZE_SPEC_ID before including common.glsl"
#endif
layout(local_size_x = WG_SIZE, local_size_y = 1, local_size_z = 1) in;
#endif

// Linear workgroup id for 1D work spread over a 2D grid (maxComputeWorkGroupCount[0]
// is only 65535 on many devices). Ids past the end must be ignored by the caller.
uint linear_group_id() {
    return gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
}

// One slot per subgroup; sized for the worst case of 1-wide subgroups.
shared uint wg_partials[WG_SIZE];

// Exclusive prefix sum of `value` over the workgroup, in invocation order.
// Generic over SUBGROUP_SIZE (8 on lavapipe, 32 NVIDIA, 64 AMD); needs full
// subgroups (WG_SIZE a multiple of the subgroup size). Contains two barriers, so it
// must be reached by every invocation; call at most once between other barriers.
uint workgroup_exclusive_scan(uint value) {
    uint inclusive = subgroupInclusiveAdd(value);
    uint subgroup_total = subgroupAdd(value);
    if (subgroupElect()) {
        wg_partials[gl_SubgroupID] = subgroup_total;
    }
    barrier();
    if (gl_SubgroupID == 0) {
        uint carry = 0;
        for (uint base = 0; base < gl_NumSubgroups; base += SUBGROUP_SIZE) {
            uint idx = base + gl_SubgroupInvocationID;
            uint x = idx < gl_NumSubgroups ? wg_partials[idx] : 0u;
            uint x_inclusive = subgroupInclusiveAdd(x);
            if (idx < gl_NumSubgroups) {
                wg_partials[idx] = carry + x_inclusive - x;
            }
            carry += subgroupAdd(x);
        }
    }
    barrier();
    return wg_partials[gl_SubgroupID] + inclusive - value;
}

// Sum of `value` over the workgroup; the result is valid in invocation 0 only.
uint workgroup_sum(uint value) {
    uint subgroup_total = subgroupAdd(value);
    if (subgroupElect()) {
        wg_partials[gl_SubgroupID] = subgroup_total;
    }
    barrier();
    uint total = 0;
    if (gl_LocalInvocationID.x == 0) {
        for (uint i = 0; i < gl_NumSubgroups; ++i) {
            total += wg_partials[i];
        }
    }
    return total;
}

// Bits [shift, shift + popcount(mask)) of a 64-bit key stored as (lo, hi).
uint key_digit(uvec2 key, uint shift, uint mask) {
    uint bits;
    if (shift >= 32u) {
        bits = key.y >> (shift - 32u);
    } else if (shift == 0u) {
        bits = key.x;
    } else {
        bits = (key.x >> shift) | (key.y << (32u - shift));
    }
    return bits & mask;
}

// Bits [shift, shift + popcount(mask)) of a 32-bit key (shift < 32).
uint key_digit(uint key, uint shift, uint mask) {
    return (key >> shift) & mask;
}

#endif
