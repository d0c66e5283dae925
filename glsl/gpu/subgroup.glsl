// The subgroup size every shader computes with: gl_SubgroupSize, unless the host measured
// that the driver reports another size than the one its subgroups run at (llvmpipe wider
// than 512 bits: it says 32 or 64 lanes and runs 16) and passes the real one as this
// specialization constant (the host's probe). gl_SubgroupID, gl_NumSubgroups,
// gl_SubgroupInvocationID and ballots follow the lanes that run, so only the size needs it.
#ifndef VERISPLAT_SUBGROUP_GLSL
#define VERISPLAT_SUBGROUP_GLSL
#extension GL_KHR_shader_subgroup_basic : require
layout(constant_id = SUBGROUP_SIZE_SPEC) const uint SUBGROUP_SIZE_MEASURED = 0u;
#define SUBGROUP_SIZE (SUBGROUP_SIZE_MEASURED != 0u ? SUBGROUP_SIZE_MEASURED : gl_SubgroupSize)
#endif
