// The neural shader's evaluation, shared by its forward (shade.comp) and backward
// (shade_bwd.comp) so both run the same f32 operations in the same order as the CPU
// reference. The including shader declares `words_view` (the network's
// words: 4 * MAX_LAYERS header words, then weights and biases as float bits).

// MAX_WIDTH and MAX_LAYERS come from interface.glsl.

float weight(uint i) {
    return uintBitsToFloat(texelFetch(words_view, int(4u * MAX_LAYERS + i)).x);
}

// Layer l's inputs, outputs, activation and float offset of its weights.
uvec4 layer_header(uint l) {
    return uvec4(texelFetch(words_view, int(4u * l)).x, texelFetch(words_view, int(4u * l + 1u)).x,
                 texelFetch(words_view, int(4u * l + 2u)).x, texelFetch(words_view, int(4u * l + 3u)).x);
}

float activate(uint kind, float x) {
    if (kind == 1u) return max(x, 0.0);
    if (kind == 2u) return 1.0 / (1.0 + exp(-x));
    if (kind == 3u) return tanh(x);
    return x;
}

// The activation's derivative from its output y (relu: y > 0 exactly when x > 0).
float activate_grad(uint kind, float y) {
    if (kind == 1u) return y > 0.0 ? 1.0 : 0.0;
    if (kind == 2u) return y * (1.0 - y);
    if (kind == 3u) return 1.0 - y * y;
    return 1.0;
}

// The unit world-space direction through pixel `pix`'s centre (crate::mlp::view_dir).
vec3 mlp_view_dir(uvec2 pix, vec4 intrinsics, vec4 rot0, vec4 rot1, vec4 rot2) {
    vec3 d = vec3((float(pix.x) + 0.5 - intrinsics.z) / intrinsics.x,
                  (float(pix.y) + 0.5 - intrinsics.w) / intrinsics.y, 1.0);
    vec3 w = d.x * rot0.xyz + d.y * rot1.xyz + d.z * rot2.xyz;
    return w / length(w);
}
