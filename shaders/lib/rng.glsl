// Counter-based random numbers: Philox4x32-10 keyed and laid out as ALGORITHMS.md §2 (twin of src/rng.rs).
#ifndef PATHGRAD_RNG_GLSL
#define PATHGRAD_RNG_GLSL

// One Philox round with its key; the ten rounds are spelled out so that no loop spends lavapipe's
// per-invocation loop budget (PLATFORM.md §6.1).
uvec4 philox_round(uvec4 c, uvec2 k) {
    uint hi0, lo0, hi1, lo1;
    umulExtended(0xD2511F53u, c.x, hi0, lo0);
    umulExtended(0xCD9E8D57u, c.z, hi1, lo1);
    return uvec4(hi1 ^ c.y ^ k.x, lo1, hi0 ^ c.w ^ k.y, lo0);
}

// Philox4x32 with 10 rounds: encrypts the 128-bit counter under the 64-bit key.
uvec4 philox4x32_10(uvec4 c, uvec2 k) {
    const uvec2 weyl = uvec2(0x9E3779B9u, 0xBB67AE85u);
    c = philox_round(c, k); k += weyl;
    c = philox_round(c, k); k += weyl;
    c = philox_round(c, k); k += weyl;
    c = philox_round(c, k); k += weyl;
    c = philox_round(c, k); k += weyl;
    c = philox_round(c, k); k += weyl;
    c = philox_round(c, k); k += weyl;
    c = philox_round(c, k); k += weyl;
    c = philox_round(c, k); k += weyl;
    c = philox_round(c, k);
    return c;
}

// The top 24 bits with the lowest forced to 1, times 2^-24: a float in the open interval (0, 1).
float u32_to_unit_f32(uint x) {
    return float((x >> 8) | 1u) * (1.0 / 16777216.0);
}

// Four uniforms of one block: dimensions 4*block .. 4*block+3 of (pixel, sample, vertex, stream, step).
vec4 uniform4(uvec2 key, uint pixel, uint sample_index, uint vertex, uint stream, uint block, uint step) {
    uint c2 = (vertex & 0xFFFFu) | (stream << 16) | (block << 24);
    uvec4 bits = philox4x32_10(uvec4(pixel, sample_index, c2, step), key);
    return vec4(u32_to_unit_f32(bits.x), u32_to_unit_f32(bits.y), u32_to_unit_f32(bits.z),
                u32_to_unit_f32(bits.w));
}

#endif
