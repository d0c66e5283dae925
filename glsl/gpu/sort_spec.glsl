// The radix sort's tunables (the host's SortConfig) as specialization constants,
// so one compiled module serves every configuration the device allows. The ids are
// SORT_SPEC_* (host constants). Shaders whose workgroup is the
// sort's define WG_SIZE_SPEC_ID before including common.glsl, then include this.
#ifndef VERISPLAT_SORT_SPEC_GLSL
#define VERISPLAT_SORT_SPEC_GLSL

#ifdef WG_SIZE_SPEC_ID
#define SORT_WG WG_SIZE
#else
layout(constant_id = SORT_SPEC_WG) const uint SORT_WG = 128u;
#endif
layout(constant_id = SORT_SPEC_ITEMS) const uint SORT_ITEMS = 32u;
layout(constant_id = SORT_SPEC_RADIX) const uint SORT_RADIX = 256u;
layout(constant_id = SORT_SPEC_MAX_SUBGROUPS) const uint SORT_MAX_SUBGROUPS = 16u;
// Elements per sort block.
const uint SORT_BLOCK = SORT_WG * SORT_ITEMS;

#endif
