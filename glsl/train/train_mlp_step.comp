#version 460
// Training step of the neural shader's weights and biases on the device (feature splats,
// the training step): one invocation per value, flattened as Mlp::gpu_words lays them
// out after its header (per layer the weights, row-major, then the biases). MLP_STATE
// holds the values, MLP_M and MLP_V Adam's moments, MLP_GRADS the shader backward's
// gradients; the new values go into the shader's words (WORDS, after the header) that the
// next frame's shade pass reads. STEP_NORM writes each value's squared gradient after the
// Gaussians' (NORMS, at pc.sizes.w) for the clipping norm; STEP_CLIP scales the
// gradients as train_step.comp does. The arithmetic is Model::step's.
#extension GL_GOOGLE_include_directive : require
#define WG_SIZE LINEAR_WG
#include "common.glsl"

layout(local_size_x = LINEAR_WG) in;

layout(std430, binding = TRAIN_MLP_STEP_STATE) buffer StateBuf { float state[]; };
layout(std430, binding = TRAIN_MLP_STEP_M) buffer MBuf { float moment_m[]; };
layout(std430, binding = TRAIN_MLP_STEP_V) buffer VBuf { float moment_v[]; };
layout(std430, binding = TRAIN_MLP_STEP_GRADS) readonly buffer GradBuf { float grads[]; };
layout(std430, binding = TRAIN_MLP_STEP_WORDS) writeonly buffer WordBuf { uint words[]; };
layout(std430, binding = TRAIN_MLP_STEP_NORMS) writeonly buffer NormBuf { vec4 norms[]; };
layout(std430, binding = TRAIN_MLP_STEP_NORM_TOTAL) readonly buffer NormTotalBuf { vec4 norm_total[]; };

layout(push_constant) uniform MlpBlock { MlpPush pc; };

void main() {
    uint j = linear_group_id() * LINEAR_WG + gl_LocalInvocationIndex;
    if (j >= pc.sizes.x) return;
    uint flags = pc.sizes.z;
    float g = grads[j];
    if ((flags & STEP_NORM) != 0u) {
        precise float sq = g * g;
        norms[pc.sizes.w + j] = vec4(sq, 0.0, 0.0, 0.0);
        return;
    }
    if ((flags & STEP_ADAM) != 0u) {
        if ((flags & STEP_CLIP) != 0u) {
            float norm = sqrt(norm_total[0].x);
            if (norm > pc.lr_c.w && !isinf(norm) && !isnan(norm)) g *= pc.lr_c.w / norm;
        }
        precise float m = 0.9 * moment_m[j] + (1.0 - 0.9) * g;
        precise float v = 0.999 * moment_v[j] + (1.0 - 0.999) * g * g;
        moment_m[j] = m;
        moment_v[j] = v;
        precise float p = state[j] - pc.lr_c.x / pc.lr_c.y * m / (sqrt(v) / pc.lr_c.z + 1e-15);
        state[j] = p;
    }
    words[pc.sizes.y + j] = floatBitsToUint(state[j]);
}
