// In-shader traversal of the compressed 8-wide BVH: closest hit and shadow any-hit (twin of
// src/bvh.rs).
//
// lavapipe truncates loops silently once an invocation batch has spent ~65 535 iterations
// (PLATFORM.md §6.1), and then every loop exits. The traversal records in `finished` whether it ended
// for its own reason; if not, the budget ran out and STATUS_LOOP_BUDGET is raised, so a truncated
// result is never used. Only a flag set where the loop ends can say so: re-testing a loop's
// condition after the loop is provably false to the compiler, which folds the test away (a
// truncation in the last leaf, with the stack empty, then went unnoticed; tests/it/loop_budget.rs).
#ifndef PATHGRAD_BVH_GLSL
#define PATHGRAD_BVH_GLSL

#include "abi.glsl"
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

// The node and triangle arrays are read as 64-bit words: lavapipe loads every component of a
// divergent address lane by lane (or one gather per 32-bit component where the host has fast
// gathers), and a 64-bit word costs about what a 32-bit one does (BENCHMARKS.md). A compressed node
// (src/contract/structs.rs) is ten words for eight child boxes; a triangle is five.
struct NodeWords { uint64_t w0; uint64_t w1; uint64_t w2; uint64_t w3; uint64_t w4; uint64_t w5; uint64_t w6; uint64_t w7; uint64_t w8; uint64_t w9; };
struct TriWords { uint64_t w0; uint64_t w1; uint64_t w2; uint64_t w3; uint64_t w4; };
layout(buffer_reference, scalar, buffer_reference_align = 8) readonly buffer NodeWordArray { NodeWords v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 8) readonly buffer TriWordArray { TriWords v[]; };

vec2 word_floats(uint64_t w) { return uintBitsToFloat(unpackUint2x32(w)); }

TriPositions load_tri(uint i) {
    TriWordArray a = TriWordArray(globals.addr_tris);
    vec2 w0 = word_floats(a.v[i].w0);
    vec2 w1 = word_floats(a.v[i].w1);
    vec2 w2 = word_floats(a.v[i].w2);
    vec2 w3 = word_floats(a.v[i].w3);
    vec2 w4 = word_floats(a.v[i].w4);   // its second half is padding
    return TriPositions(vec3(w0, w1.x), vec3(w1.y, w2), vec3(w3, w4.x), 0u);
}

struct Ray { vec3 origin; vec3 dir; vec3 inv_dir; };
struct Hit { float t; uint slot; float b1; float b2; bool valid; };

float safe_component(float x) {
    return abs(x) < MIN_DIR_COMPONENT ? (x < 0.0 ? -MIN_DIR_COMPONENT : MIN_DIR_COMPONENT) : x;
}

Ray make_ray(vec3 origin, vec3 dir) {
    vec3 safe = vec3(safe_component(dir.x), safe_component(dir.y), safe_component(dir.z));
    return Ray(origin, dir, vec3(1.0) / safe);
}

// Möller–Trumbore; returns (t, b1, b2) in xyz and w = 1 on a hit with tmin < t < tmax. Written
// without early returns: under SIMD masking every exit is a mask update, and a miss costs the
// whole test anyway once one lane of the batch goes on. A zero determinant makes the values
// infinite or NaN, and every comparison then fails, as the early return did.
vec4 intersect_triangle(Ray ray, TriPositions tri, float tmin, float tmax) {
    precise vec3 e1 = tri.v1 - tri.v0;
    precise vec3 e2 = tri.v2 - tri.v0;
    precise vec3 p = cross(ray.dir, e2);
    precise float det = dot(e1, p);
    precise float inv_det = 1.0 / det;
    precise vec3 s = ray.origin - tri.v0;
    precise float b1 = dot(s, p) * inv_det;
    precise vec3 q = cross(s, e1);
    precise float b2 = dot(ray.dir, q) * inv_det;
    precise float t = dot(e2, q) * inv_det;
    bool hit = det != 0.0 && b1 >= 0.0 && b1 <= 1.0 && b2 >= 0.0 && b1 + b2 <= 1.0 && t > tmin && t < tmax;
    return hit ? vec4(t, b1, b2, 1.0) : vec4(0.0);
}

// The ray's octant as the children's order wants it: byte-replicated bits 2, 1, 0 set for
// non-negative x, y, z.
uint octant_inv4(vec3 dir) {
    return (dir.x < 0.0 ? 0u : 0x04040404u) | (dir.y < 0.0 ? 0u : 0x02020202u) | (dir.z < 0.0 ? 0u : 0x01010101u);
}

// Visits node i: tests the ray against its eight child boxes. Returns the node group of its inner
// children hit, (child_base, hits << 24 | inner mask), in `group` and its leaf children's
// triangles hit, (tri_base, bits), in `pending`. An inner child hit sets bit 24 + (slot ^ octant), so
// the highest bit is the child to visit first; a leaf child sets its triangles' offsets.
void visit_node(uint i, Ray ray, uint octant, float tmin, float tmax, out uvec2 group, out uvec2 pending) {
    NodeWordArray a = NodeWordArray(globals.addr_nodes);
    vec2 w0 = word_floats(a.v[i].w0);
    uvec2 w1 = unpackUint2x32(a.v[i].w1);
    uvec2 bases = unpackUint2x32(a.v[i].w2);
    uvec2 meta = unpackUint2x32(a.v[i].w3);
    uvec2 lo_x = unpackUint2x32(a.v[i].w4);
    uvec2 hi_x = unpackUint2x32(a.v[i].w5);
    uvec2 lo_y = unpackUint2x32(a.v[i].w6);
    uvec2 hi_y = unpackUint2x32(a.v[i].w7);
    uvec2 lo_z = unpackUint2x32(a.v[i].w8);
    uvec2 hi_z = unpackUint2x32(a.v[i].w9);
    vec3 origin = vec3(w0, uintBitsToFloat(w1.x));
    uint e = w1.y;
    vec3 cell = uintBitsToFloat(uvec3(e & 0xffu, (e >> 8) & 0xffu, (e >> 16) & 0xffu) << 23);
    // The ray in the node's grid: a plane at cell q is crossed at q·scale + offset.
    precise vec3 scale = cell * ray.inv_dir;
    precise vec3 offset = (origin - ray.origin) * ray.inv_dir;
    uint hits = 0u;
    [[unroll]] for (uint half_ = 0u; half_ < 2u; half_++) {
        uint m = meta[half_];
        // Inner children's metas are 24 + slot, with bits 3 and 4 both set, which no leaf has.
        uint inner4 = (m & (m << 1)) & 0x10101010u;
        uint bit_index4 = (m ^ (octant & ((inner4 >> 4) * 0xffu))) & 0x1f1f1f1fu;
        uint child_bits4 = (m >> 5) & 0x07070707u;
        [[unroll]] for (uint k = 0u; k < 4u; k++) {
            int sh = int(8u * k);
            vec3 lo = vec3(bitfieldExtract(lo_x[half_], sh, 8), bitfieldExtract(lo_y[half_], sh, 8), bitfieldExtract(lo_z[half_], sh, 8));
            vec3 hi = vec3(bitfieldExtract(hi_x[half_], sh, 8), bitfieldExtract(hi_y[half_], sh, 8), bitfieldExtract(hi_z[half_], sh, 8));
            precise vec3 t0 = lo * scale + offset;
            precise vec3 t1 = hi * scale + offset;
            vec3 near3 = min(t0, t1);
            vec3 far3 = max(t0, t1);
            float near = max(max(max(near3.x, near3.y), near3.z), tmin);
            precise float far_scaled = min(min(far3.x, far3.y), far3.z) * BVH_FAR_SCALE;
            float far = min(far_scaled, tmax);
            if (near <= far) hits |= bitfieldExtract(child_bits4, sh, 8) << bitfieldExtract(bit_index4, sh, 8);
        }
    }
    group = uvec2(bases.x, (hits & 0xff000000u) | (e >> 24));
    pending = uvec2(bases.y, hits & 0x00ffffffu);
}

// The first REG_STACK entries of the traversal stack live in registers, read and written with
// selects; only deeper entries go to the private array. On lavapipe a private array indexed per
// lane costs a scalar load or store per lane, while a few selects are vector instructions, and a
// compressed BVH's traversal rarely has more than four groups pending. The order of visits is
// src/bvh.rs's either way.
#define REG_STACK 4u
// The traversal's step bound, set by bvh_init() at the top of every kernel that traverses, where
// every lane is active: lavapipe in Mesa 25.2 (Ubuntu 24.04) can run a uniform-buffer load with no
// lane active and then dereference a null descriptor (a segfault in the JIT code), and the
// traversal runs inside the path loop's divergent control flow. A kernel that forgets bvh_init()
// has a bound of 0 and raises STATUS_LOOP_BUDGET on its first traversal, so the mistake shows.
uint bvh_max_steps = 0u;
void bvh_init() {
    bvh_max_steps = 26u * globals.node_count + 1u;
}
// Ylitie et al.'s traversal, one step per iteration, in the order of src/bvh.rs (`traverse`): a
// step tests one pending triangle if there is one, else visits the next inner child hit of the
// current node group (the highest bit: the nearest for the ray's octant) and pushes the rest of
// the group; when neither is left the next group is popped. Shadow rays take the same order and
// stop at the first hit. The builder bounds the depth to fit the stack; the overflow check stays
// as a guard.
Hit bvh_traverse(Ray ray, float tmin, float tmax, bool any_hit) {
    // The reciprocal direction is taken here, from `dir`, the same values make_ray gives: the
    // kernel's one traversal site is then its one place that computes it, and the callers' copies
    // are dead code.
    ray = make_ray(ray.origin, ray.dir);
    Hit best = Hit(0.0, 0u, 0.0, 0.0, false);
    uint octant = octant_inv4(ray.dir);
    uvec2 stack[BVH_STACK_SIZE - REG_STACK];
    uvec2 r0 = uvec2(0u), r1 = uvec2(0u), r2 = uvec2(0u), r3 = uvec2(0u);
    uint sp = 0u;
    uvec2 group = uvec2(0u, 0x80000000u);   // the root, as the only inner child of a virtual group
    uvec2 pending = uvec2(0u);
    // Every node is visited and every triangle slot tested at most once, and a node's leaves hold
    // at most 24 triangles, so the step bound is never reached; but the compiler cannot know that,
    // so `finished` is not provably true after the loop and the check survives.
    uint max_steps = bvh_max_steps;
    bool finished = false;
    for (uint step = 0u; step <= max_steps; step++) {
        if (pending.y != 0u) {
            uint k = uint(findMSB(pending.y));
            pending.y &= ~(1u << k);
            uint slot = pending.x + k;
            vec4 h = intersect_triangle(ray, load_tri(slot), tmin, tmax);
            if (h.w != 0.0) {
                tmax = h.x;
                best = Hit(h.x, slot, h.y, h.z, true);
                // Any hit answers a shadow query, even one found just before a loop budget ran out.
                if (any_hit) { finished = true; break; }
            }
        } else if ((group.y & 0xff000000u) != 0u) {
            uint bit = uint(findMSB(group.y));
            uint slot = (bit - 24u) ^ (octant & 0xffu);
            uint index = group.x + uint(bitCount(group.y & ~(0xffffffffu << slot)));
            group.y &= ~(1u << bit);
            if ((group.y & 0xff000000u) != 0u) {
                if (sp + 1u > BVH_STACK_SIZE) { raise_status(STATUS_STACK_OVERFLOW); finished = true; break; }
                if (sp >= REG_STACK) {
                    stack[sp - REG_STACK] = group;
                } else {
                    r0 = sp == 0u ? group : r0; r1 = sp == 1u ? group : r1; r2 = sp == 2u ? group : r2; r3 = sp == 3u ? group : r3;
                }
                sp += 1u;
            }
            visit_node(index, ray, octant, tmin, tmax, group, pending);
        }
        if (pending.y == 0u && (group.y & 0xff000000u) == 0u) {
            if (sp == 0u) { finished = true; break; }
            sp -= 1u;
            if (sp >= REG_STACK) {
                group = stack[sp - REG_STACK];
            } else {
                group = sp == 0u ? r0 : sp == 1u ? r1 : sp == 2u ? r2 : r3;
            }
        }
    }
    if (!finished) raise_status(STATUS_LOOP_BUDGET);
    return best;
}

Hit bvh_closest_hit(Ray ray, float tmin, float tmax) { return bvh_traverse(ray, tmin, tmax, false); }
bool bvh_occluded(Ray ray, float tmin, float tmax) { return bvh_traverse(ray, tmin, tmax, true).valid; }

#endif
