#version 460
// Duplicate-per-tile keys: the k-th Gaussian in depth order writes one (key, value) pair per
// tile it reaches at its scanned offset, so pairs come out in (depth, index) order and the
// stable pair sort only has to order the tile bits. Pairs past the key capacity are dropped
// (the host sees the exact total and grows the buffers). Thread 0 also publishes the
// number of keys to sort and the ranges stage's indirect dispatch.
// A frame whose pairs do not fit the key buffers is keyed in chunks of consecutive
// depth-ordered Gaussians [first, end), each writing its pairs from slot `base` (the
// scanned offset of `first`) on; a frame in one piece is the chunk (0, n, 0).
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"

layout(local_size_x = LINEAR_WG) in;

layout(std430, binding = KEYS_PARAMS) readonly buffer ParamsBuf { FrameParams params; };
// The splats as 3 rgba32f texels each: texel buffers address more than one storage
// binding on some devices (lavapipe: 128 M texels against 128 MiB).
layout(binding = KEYS_SPLAT_TEXELS) uniform samplerBuffer splat_texels;
// Keys are the bin ids: pairs are written in depth order, so the key needs no depth bits.
#ifndef KEYS_TEXEL_IO
#define KEYS_TEXEL_IO 0
#endif
#if KEYS_TEXEL_IO
// CPU devices: the per-Gaussian arrays through texel views, the pairs written with
// imageStore (straight per-lane code on llvmpipe, where storage-buffer accesses are a
// guarded loop per component; the tuning bench measures both).
layout(binding = KEYS_RECTS) uniform usamplerBuffer rects_tex;
layout(binding = KEYS_OFFSETS) uniform usamplerBuffer offsets_tex;
layout(binding = KEYS_KEYS, r32ui) uniform writeonly uimageBuffer keys_img;
layout(binding = KEYS_VALUES, r32ui) uniform writeonly uimageBuffer values_img;
layout(binding = KEYS_DEPTH_ORDER) uniform usamplerBuffer order_tex;
layout(binding = KEYS_BIN_MASKS) uniform usamplerBuffer masks_tex;
#define RECT(i) texelFetch(rects_tex, int(i)).xy
#define OFFSET(k) texelFetch(offsets_tex, int(k)).x
#define ORDER(k) texelFetch(order_tex, int(k)).x
#define MASK(i) texelFetch(masks_tex, int(i)).x
#define STORE_PAIR(off, key, value) \
    imageStore(keys_img, int(off), uvec4(key)); \
    imageStore(values_img, int(off), uvec4(value))
#else
layout(std430, binding = KEYS_RECTS) readonly buffer RectBuf { uvec2 rects[]; };
layout(std430, binding = KEYS_OFFSETS) readonly buffer OffsetBuf { uint offsets[]; };
layout(std430, binding = KEYS_KEYS) writeonly buffer KeyBuf { uint keys[]; };
layout(std430, binding = KEYS_VALUES) writeonly buffer ValueBuf { uint values[]; };
layout(std430, binding = KEYS_DEPTH_ORDER) readonly buffer OrderBuf { uint depth_order[]; };
layout(std430, binding = KEYS_BIN_MASKS) readonly buffer BinMaskBuf { uint bin_masks[]; };
#define RECT(i) rects[i]
#define OFFSET(k) offsets[k]
#define ORDER(k) depth_order[k]
#define MASK(i) bin_masks[i]
#define STORE_PAIR(off, key, value) \
    keys[off] = key; \
    values[off] = value
#endif
layout(std430, binding = KEYS_COUNTERS) buffer CounterBuf { Counters counters; };
layout(push_constant) uniform KeysBlock { KeysPush chunk; };

#define RANGES_WORKGROUP LINEAR_WG

void main() {
    uint k = chunk.first + linear_group_id() * LINEAR_WG + gl_LocalInvocationIndex;
    uint n = params.counts.x;
    uint capacity = params.counts.w;
    if (k == chunk.first) {
        // The exact total says whether the scan total of a whole frame wrapped past 2^32;
        // a chunk's pairs (offsets mod 2^32 apart) always fit the capacity.
        bool whole = chunk.first == 0u && chunk.end >= n;
        uint next = chunk.end < n ? OFFSET(chunk.end) : counters.scan_total;
        uint total = whole && counters.touched_hi != 0u ? capacity : min(next - chunk.base, capacity);
        counters.sort_count = total;
        // A 2D grid beyond 65535 groups (the minimum maxComputeWorkGroupCount[0]).
        uint groups = (total + RANGES_WORKGROUP - 1u) / RANGES_WORKGROUP;
        counters.ranges_groups[0] = min(groups, 65535u);
        counters.ranges_groups[1] = (groups + 65534u) / 65535u;
        counters.ranges_groups[2] = 1u;
    }
    if (k >= chunk.end) return;
    uint i = ORDER(k);
    uvec2 rect = RECT(i);
    uvec2 rmin = unpack_tile(rect.x);
    uvec2 rmax = unpack_tile(rect.y);
    if (rmax.x <= rmin.x || rmax.y <= rmin.y) return;
    // Only larger rectangles (below) test bins with the splat's conic, but fetching it
    // here, outside the divergent branch, measured about 1 ms faster on lavapipe.
    vec4 mean_opacity_bound = texelFetch(splat_texels, int(i * 3u));
    vec4 conic_depth = texelFetch(splat_texels, int(i * 3u + 1u));
    float bound = mean_opacity_bound.w;
    uint bins_x = params.bins.y;
    // An image that wraps: the bins of a turn of whole tiles (wrapped_bin_receives).
    uint turn_bins = params.image.z * params.bins.w;
    // An image that wraps around (wrapped_mean): the rectangle is in the bins of three
    // turns side by side, the image the middle one; each bin is taken back to the image.
    bool wraps = params.modes.z != 0u;
    uvec2 bmin = rmin * params.bins.w;
    uvec2 bmax = min(rmax * params.bins.w, uvec2(wraps ? 3u * turn_bins : bins_x, params.bins.z));
    uint off = OFFSET(k) - chunk.base;
    // This Gaussian's slots end where the next one's begin (or at the scan total).
    uint end = (k + 1u < n ? OFFSET(k + 1u) : counters.scan_total) - chunk.base;
    uint limit = min(end, capacity);
    uint w = bmax.x - bmin.x;
    if (w * (bmax.y - bmin.y) <= BIN_MASK_BINS) {
        // The bins preprocess found, in the same row-major order.
        uint mask = MASK(i);
        while (mask != 0u) {
            uint j = uint(findLSB(mask));
            mask &= mask - 1u;
            uint y = bmin.y + j / w, x = bmin.x + j % w;
            if (off < limit) {
                STORE_PAIR(off, y * bins_x + x % turn_bins, i);
            }
            off++;
        }
    } else {
        uint y = bmin.y;
        uint x = bmax.x;
        for (; y < bmax.y; y++) {
            for (x = bmin.x; x < bmax.x; x++) {
                // The same test preprocess counted with (tile_receives in splat_common.glsl).
                bool receives = wraps
                    ? wrapped_bin_receives(mean_opacity_bound.xy, conic_depth.xyz, bound, uvec2(x, y), params.bins.x, bins_x, turn_bins, params.image.x)
                    : tile_receives(mean_opacity_bound.xy, conic_depth.xyz, bound, uvec2(x, y), params.bins.x);
                if (!receives) continue;
                if (off < limit) {
                    STORE_PAIR(off, y * bins_x + x % turn_bins, i);
                }
                off++;
            }
        }
        // Cut off (see LOOP_REPORT): both loops must have run to their ends.
        if (y < bmax.y || x < bmax.x) {
            REPORT_LOOP(counters.max_bins_loop, (bmax.x - bmin.x + 1u) * (bmax.y - bmin.y) + 16u);
        }
    }
    for (; off < min(end, capacity); off++) {
        STORE_PAIR(off, SENTINEL_TILE, i);
    }
}
