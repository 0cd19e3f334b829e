// Alias-table draws for adaptive pixel sampling (ALGORITHMS.md §6): twin of AliasTable::draw in
// src/alias.rs and of select_pixel in src/adaptive.rs. Include after the generated shared structs.
#ifndef PATHGRAD_ALIAS_GLSL
#define PATHGRAD_ALIAS_GLSL

#include "rng.glsl"

layout(set = 0, binding = BINDING_ALIAS, scalar) readonly buffer AliasBuf { AliasEntry alias_table[]; };

// One entry of the `count`-entry table from two uniforms:
// i = min(floor(u0·P), P−1); (u1 < prob[i]) ? i : alias[i].
uint alias_draw(uint count, float u0, float u1) {
    precise float scaled = u0 * float(count);
    uint i = min(uint(floor(scaled)), count - 1u);
    AliasEntry e = alias_table[i];
    return u1 < e.prob ? i : e.alias;
}

// The pixel of global sample k: two uniforms of stream PIXEL, counter (0, k), vertex 0, block 0,
// under the pixel-selection key (the gradient key with pass tag PASS_PIXEL_SELECT).
uint select_pixel(uvec2 gradient_key, uint pixels, uint k) {
    uvec2 key = uvec2(gradient_key.x, (gradient_key.y & ~0xFFu) | PASS_PIXEL_SELECT);
    vec4 u = uniform4(key, 0u, k, 0u, STREAM_PIXEL, 0u, 0u);
    return alias_draw(pixels, u.x, u.y);
}

#endif
