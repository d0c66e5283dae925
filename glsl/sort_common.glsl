// Radix sort helpers shared by sort_histogram and sort_scatter. Include after the
// push constants (`pc.shift`) and after defining SORT_KEYS as the key array's name.
#ifndef VKSPLAT_SORT_COMMON_GLSL
#define VKSPLAT_SORT_COMMON_GLSL

#if SORT_RADIX != 16
#error "the register-packed digit counters assume 4-bit digits"
#endif

// SORT_RADIX 8-bit counters packed four to a word (so SORT_ITEMS must stay below 256).
#define SORT_PACKED_WORDS (SORT_RADIX / 4)

// Counts the digits of this invocation's SORT_ITEMS consecutive keys in registers,
// using selects rather than dynamically indexed (shared or private) memory.
void count_digits(uint begin, uint n, uint mask, out uint packed[SORT_PACKED_WORDS]) {
    for (uint w = 0; w < SORT_PACKED_WORDS; ++w) {
        packed[w] = 0u;
    }
    for (uint k = 0; k < SORT_ITEMS; ++k) {
        uint i = begin + k;
        if (i < n) {
            uint digit = key_digit(SORT_KEYS[i], pc.shift, mask);
            uint increment = 1u << ((digit & 3u) * 8u);
            for (uint w = 0; w < SORT_PACKED_WORDS; ++w) {
                packed[w] += (digit >> 2) == w ? increment : 0u;
            }
        }
    }
}

// The count of `digit` (a compile-time constant in unrolled loops).
uint unpack_count(uint packed[SORT_PACKED_WORDS], uint digit) {
    return (packed[digit >> 2] >> ((digit & 3u) * 8u)) & 0xFFu;
}

#endif
