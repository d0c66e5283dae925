// Shared helpers of the splatting stages: the rules' constants, the alpha falloff, the tile
// and key layout. The records (FrameParams, Gaussian, Splat, Counters) and the flags
// (RULES_*, SPLAT_KERNEL_*) are declared once on the host and written into interface.glsl.
#ifndef SPLAT_COMMON_GLSL
#define SPLAT_COMMON_GLSL

#include "interface.glsl"
#include "portable_math.glsl"

// Reference rules (shared/docs/reference-semantics.md): TILE_SIZE, TILE_PIXELS,
// COV2D_DILATION, ALPHA_MIN, GSPLAT_EXTEND and T_MIN are #defines from the host, which
// defines each once. What differs between the original rules and gsplat's (the near
// plane, the guard band, the alpha clamp, the stop, the antialiased ratio's floor and the
// screen extent) comes per frame in FrameParams.rules, .limits and .modes.
#ifndef T_MIN
#error "the reference's constants come from the host: compile the shaders through the crate's build"
#endif

// The reproducible mode (RenderOptions::reproducible, docs/reproducibility.md): the blends
// take exp from portable_exp, the CPU reference's own, and keep their arithmetic unfused
// (`precise`), so that every device computes the reference's bits. A specialization
// constant: a pipeline holds one of the two only.
layout(constant_id = REPRODUCIBLE_SPEC) const bool REPRODUCIBLE = false;

// Alpha falloff with the squared Mahalanobis distance d2 = -2 power (the splat kernel):
// Gaussian opacity * exp(-d2 / 2), the reference; power opacity * max(0, 1 - d2 / 9).
// Alpha before the clamp (0.99, gsplat's 0.999) where the reference's exponent is `power` (<= 0). The blend
// passes its compile-time SPLAT_KERNEL, so each blend pipeline holds one formula only.
float kernel_falloff(uint kernel, float opacity, float power) {
    if (kernel == SPLAT_KERNEL_POWER) {
        if (REPRODUCIBLE) {
            // A division by a constant is otherwise a product with its reciprocal.
            precise float d2 = -2.0 * power;
            precise float a = opacity * max(0.0, 1.0 - d2 / 9.0);
            return a;
        }
        float d2 = -2.0 * power;
        return opacity * max(0.0, 1.0 - d2 / 9.0);
    }
    if (REPRODUCIBLE) {
        precise float a = opacity * portable_exp(power);
        return a;
    }
    return opacity * exp(power);
}

// The exponent of a splat at offset d from its 2D centre, with its conic (A, B, C):
// -(A dx^2 + C dy^2) / 2 - B dx dy, in the CPU reference's order (cpu::pixel_alpha).
#define SPLAT_POWER(conic, d) \
    (-0.5 * ((conic).x * (d).x * (d).x + (conic).z * (d).y * (d).y) - (conic).y * (d).x * (d).y)
float splat_power(vec3 conic, vec2 d) {
    if (REPRODUCIBLE) {
        precise float p = SPLAT_POWER(conic, d);
        return p;
    }
    return SPLAT_POWER(conic, d);
}

// Pairs are keyed by bins: the reference's 16x16 tiles, or 8x8 quarters of them (for CPU
// devices, where a shorter list per pixel block is worth more pairs). Either way only bins
// inside the Gaussian's reference tile rectangle are candidates, so the reference's
// clipping at that rectangle is kept exactly.

// CPU implementations may end every loop of an invocation after a fixed total number of
// iterations (llvmpipe: 65,535, shared by all loops), silently. A long loop that stopped
// before its end for no reason of its own was cut off: it is reported in
// Counters.max_*_loop (with the iterations it needed) so the host can choose larger bins
// or refuse the frame instead of returning an incomplete image. Only long loops can be cut
// off, which keeps these atomics rare.
#define LOOP_REPORT 4096u
#define REPORT_LOOP(FIELD, ITERATIONS) \
    if ((ITERATIONS) > LOOP_REPORT) atomicMax(FIELD, (ITERATIONS))

// Tile rectangles are packed as two uints: x | y << 16 for min (inclusive) and max
// (exclusive); 16 bits suffice for 16384 / 16 = 1024 tiles per side.
uint pack_tile(uint x, uint y) { return x | (y << 16u); }
uvec2 unpack_tile(uint v) { return uvec2(v & 0xFFFFu, v >> 16u); }

// Sort key of a (bin, Gaussian) pair: the bin id y * bins_x + x (32 bits). Pairs are
// emitted in depth order (the order stage sorted the float bits of the view depths, which
// order like the floats since depth > 0.2), and the pair sort is stable.

// Exact tile culling. A splat adds to pixel d (offset from its centre) only when its alpha
// is >= 1/255; with q(d) = A dx^2 + 2 B dx dy + C dy^2 (the squared Mahalanobis distance)
// that is, for the Gaussian kernel, opacity * exp(-q/2) >= 1/255, i.e. q <= 2 ln(255 opacity),
// and for the power kernel opacity * (1 - q/9) >= 1/255, i.e. q <= 9 (1 - 1/(255 opacity)).
// A tile of its reference rectangle where the minimum of q over the tile's pixel square
// exceeds the kernel's bound receives nothing from it, so dropping the pair changes no
// pixel; it only saves sorting and blending work. The small margin keeps the test
// conservative against rounding in the per-pixel evaluation. Mirrors
// cpu::SplatKernel::alpha_bound.
float alpha_bound(float opacity, uint kernel) {
    precise float exact = kernel == SPLAT_KERNEL_POWER
        ? 9.0 * (1.0 - 1.0 / (255.0 * opacity))
        : 2.0 * log(255.0 * opacity);
    precise float b = exact * 1.001 + 0.01;
    return b;
}

// Key of a padding pair (never produced when the count and the emission agree): its tile id
// is past every real tile, so it sorts last and the ranges stage ignores it.
#define SENTINEL_TILE 0xFFFFFFFFu

// Minimum over dy in [lo, hi] of A a^2 + 2 B a dy + C dy^2 (an edge at dx = a).
// `precise` forbids contraction, so preprocess (which counts) and keys (which emits)
// evaluate the test bit-identically.
float edge_min(float a, float lo, float hi, float A, float B, float C) {
    precise float dy = clamp(-B * a / C, lo, hi);
    precise float q = A * a * a + 2.0 * B * a * dy + C * dy * dy;
    return q;
}

// A splat's centre in an image that wraps around (FrameParams::modes.z, a full turn of
// an equirectangular lens: camera::Lens::wraps): moved by whole turns (the image's width)
// to the copy nearest the 16-pixel tile starting at column x0, as cpu::wrapped_for_tile.
vec2 wrapped_mean(vec2 mean, uint x0, uint wraps, uint width) {
    if (wraps == 0u) return mean;
    float w = float(width);
    float turns = floor((float(x0 + TILE_SIZE / 2u) - mean.x) / w + 0.5);
    return vec2(mean.x + turns * w, mean.y);
}

bool tile_receives(vec2 mean2d, vec3 conic, float bound, uvec2 bin, uint size) {
    // Pixel positions of the bin are bin * size + {0..size-1}; use the continuous square.
    precise vec2 lo = vec2(bin * size) - mean2d;
    precise vec2 hi = lo + vec2(float(size - 1u));
    if (lo.x <= 0.0 && hi.x >= 0.0 && lo.y <= 0.0 && hi.y >= 0.0) return bound >= 0.0;
    float A = conic.x, B = conic.y, C = conic.z;
    float m = min(min(edge_min(lo.x, lo.y, hi.y, A, B, C), edge_min(hi.x, lo.y, hi.y, A, B, C)),
                  min(edge_min(lo.y, lo.x, hi.x, C, B, A), edge_min(hi.y, lo.x, hi.x, C, B, A)));
    return m <= bound;
}

// tile_receives of bin `bin` of the bins of three turns side by side (the image the
// middle one) of an image that wraps around: the bin taken back to the image, and the copy
// of the splat the blend draws there (wrapped_mean). Each turn is whole tiles,
// `turn_bins` bins (FrameParams: image.z * bins.w); `bins_x` of them are the image's,
// the others (past a width that is not whole bins' tiles) receive nothing.
bool wrapped_bin_receives(vec2 mean2d, vec3 conic, float bound, uvec2 bin, uint size, uint bins_x, uint turn_bins, uint width) {
    uvec2 real = uvec2(bin.x % turn_bins, bin.y);
    if (real.x >= bins_x) return false;
    vec2 mean = wrapped_mean(mean2d, real.x * size / TILE_SIZE * TILE_SIZE, 1u, width);
    return tile_receives(mean, conic, bound, real, size);
}

// Preprocess records, for a tile rectangle of at most BIN_MASK_BINS bins, which of them
// receive the splat: bit j for the j-th bin in row-major order. The keys stage then emits
// those bins without testing them again; larger rectangles are tested again there.
#define BIN_MASK_BINS 32u

// The tile or bin of a workgroup of a 2D grid over the image, for the CPU-device kernels.
// lavapipe hands each of its T threads one contiguous T-th of a dispatch's workgroups
// (Mesa's lp_cs_tpool: iter_per_thread = groups / threads), so tiles taken in row-major
// order leave one thread the image's busy half while the other idles (measured: blend_bwd
// no faster on two threads than on one). Here the workgroups' row-major index runs through
// a transpose of 32 bands of the tiles, so any contiguous run of workgroups takes tiles
// from all over the image. A bijection on the grid: every tile is still one workgroup, and
// what each computes is unchanged.
uvec2 spread_workgroup() {
    const uint K = 32u;
    uint gx = gl_NumWorkGroups.x, n = gx * gl_NumWorkGroups.y;
    uint l = gl_WorkGroupID.y * gx + gl_WorkGroupID.x;
    uint m = (n + K - 1u) / K;      // tiles of the longest bands
    uint full = K - (m * K - n);    // bands of m tiles; the rest have m - 1
    // l = q K + r: the q-th tile of band r (in the last row q = m - 1, r < full).
    uint q = l / K, r = l % K;
    uint b = r * m - (r > full ? r - full : 0u) + q;
    return uvec2(b % gx, b / gx);
}

// Linear workgroup id of a (possibly 2D) dispatch grid, see gpu::dispatch_grid.
uint linear_group_id() {
    return gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
}

#ifdef WORKGROUP_COUNT64
#extension GL_KHR_shader_subgroup_arithmetic : require
// Exact 64-bit counting across workgroups, without 64-bit atomics: each workgroup sums its
// terms in shared memory, then one invocation adds the sum to a (lo, hi) pair of u32 with
// an atomic add and carries into hi when lo wrapped. The adder that crosses 2^32 sees it
// (old + sum < old), so the carry is exact under any interleaving.
shared uint s_count64[1];

// Sum of `value` over the workgroup (at most 256 invocations), valid in invocation 0. Every
// invocation must call it (barriers); the caller keeps 256 * max(value) below 2^32.
// One subgroup sum and one shared atomic per subgroup, for any subgroup size: two barriers
// instead of the nine of a shared-memory tree (measured: preprocess about 15 % less CPU time
// on lavapipe, where every barrier switches all of the workgroup's coroutines).
uint workgroup_sum_u32(uint value) {
    if (gl_LocalInvocationIndex == 0u) s_count64[0] = 0u;
    barrier();
    uint sum = subgroupAdd(value);
    if (subgroupElect() && sum != 0u) atomicAdd(s_count64[0], sum);
    barrier();
    return s_count64[0];
}

#define ATOMIC_ADD_U64(lo, hi, sum)                 \
    {                                               \
        uint add64_old_ = atomicAdd(lo, (sum));     \
        if (add64_old_ + (sum) < add64_old_) {      \
            atomicAdd(hi, 1u);                      \
        }                                           \
    }
#endif

#endif
