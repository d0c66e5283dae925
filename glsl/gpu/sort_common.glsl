// Radix sort helpers shared by sort_histogram and sort_scatter. Include after the
// push constants (`pc.shift`, `pc.bits`) and the meta buffer. SORT_KEY (a define from the
// host) is the key's type: `uvec2` (lo, hi) for 64-bit keys, `uint` for 32-bit ones;
// SORT_TEXEL_IO = 1 reads and writes 32-bit keys and values through texel views.
//
// Element layout inside a block of SORT_BLOCK = SORT_WG * SORT_ITEMS elements:
// subgroup s owns the contiguous chunk of SUBGROUP_SIZE * SORT_ITEMS elements
// starting at s * SUBGROUP_SIZE * SORT_ITEMS, processed as SORT_ITEMS rows of
// SUBGROUP_SIZE consecutive elements (row k, lane l -> chunk + k * size + l). So
// (subgroup, row, lane) order is input order, and loads are contiguous per row.
// Everything is generic over SUBGROUP_SIZE (needs full subgroups, <= 128 lanes).
#ifndef VERISPLAT_SORT_COMMON_GLSL
#define VERISPLAT_SORT_COMMON_GLSL

// Per-subgroup digit counters: subgroup_counts[subgroup * SORT_RADIX + digit].
shared uint subgroup_counts[SORT_MAX_SUBGROUPS * SORT_RADIX];

// Index of element (row) of this invocation's subgroup chunk in block `block`.
uint sort_element_index(uint block, uint row) {
    return block * SORT_BLOCK + (gl_SubgroupID * SORT_ITEMS + row) * SUBGROUP_SIZE
        + gl_SubgroupInvocationID;
}

// Ballot of the lanes whose valid digit equals ours ("multi-split" match), built from
// one ballot per digit bit, so no dynamic indexing and no shared-memory atomics.
uvec4 match_digit(uint digit, bool valid) {
    uvec4 match = subgroupBallot(valid);
    for (uint b = 0; b < pc.bits; ++b) {
        bool bit = ((digit >> b) & 1u) != 0u;
        uvec4 ballot = subgroupBallot(bit);
        match &= bit ? ballot : ~ballot;
    }
    return match;
}

void clear_subgroup_counts() {
    for (uint d = gl_SubgroupInvocationID; d < SORT_RADIX; d += SUBGROUP_SIZE) {
        subgroup_counts[gl_SubgroupID * SORT_RADIX + d] = 0u;
    }
    subgroupMemoryBarrierShared();
    subgroupBarrier();
}

// Counts one row's digits into this subgroup's counters; returns, for a valid lane,
// its rank among equal digits of the subgroup's chunk so far (input order).
uint count_row(uint digit, bool valid) {
    uvec4 match = match_digit(digit, valid);
    uint before_in_row = subgroupBallotExclusiveBitCount(match);
    uint slot = gl_SubgroupID * SORT_RADIX + digit;
    uint prior = valid ? subgroup_counts[slot] : 0u;
    // Every lane has read its counter before the row's last lane of each digit
    // advances it.
    subgroupMemoryBarrierShared();
    subgroupBarrier();
    if (valid && subgroupBallotFindMSB(match) == gl_SubgroupInvocationID) {
        subgroup_counts[slot] = prior + before_in_row + 1u;
    }
    subgroupMemoryBarrierShared();
    subgroupBarrier();
    return prior + before_in_row;
}

#endif
