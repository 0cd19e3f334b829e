// In-shader BVH2 traversal over nodes that hold both children's boxes: closest hit and shadow
// any-hit (twin of src/bvh.rs).
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

// The node and triangle arrays are read as 64-bit words: on lavapipe a load is one gather per
// 32-bit component, while a 64-bit gather fetches two for about the price of one (a node is 7
// gathers instead of 14, a triangle 5 instead of 9; BENCHMARKS.md). The layouts
// (src/contract/structs.rs) put the used words first and keep them 8-byte aligned; the values are
// the same floats, so results are bit-identical.
// One struct per node or triangle, so a word's address is the element's plus a constant.
struct NodeWords { uint64_t w0; uint64_t w1; uint64_t w2; uint64_t w3; uint64_t w4; uint64_t w5; uint64_t w6; uint64_t pad; };
struct TriWords { uint64_t w0; uint64_t w1; uint64_t w2; uint64_t w3; uint64_t w4; };
layout(buffer_reference, scalar, buffer_reference_align = 8) readonly buffer NodeWordArray { NodeWords v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 8) readonly buffer TriWordArray { TriWords v[]; };

vec2 word_floats(uint64_t w) { return uintBitsToFloat(unpackUint2x32(w)); }

BvhNode load_node(uint i) {
    NodeWordArray a = NodeWordArray(globals.addr_nodes);
    vec2 w0 = word_floats(a.v[i].w0);
    vec2 w1 = word_floats(a.v[i].w1);
    vec2 w2 = word_floats(a.v[i].w2);
    vec2 w3 = word_floats(a.v[i].w3);
    vec2 w4 = word_floats(a.v[i].w4);
    vec2 w5 = word_floats(a.v[i].w5);
    uvec2 children = unpackUint2x32(a.v[i].w6);
    return BvhNode(vec3(w0, w1.x), vec3(w1.y, w2), vec3(w3, w4.x), vec3(w4.y, w5), children.x, children.y, 0u, 0u);
}

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

// Entry distance into the box lo..hi, or -1 when the ray misses it within [tmin, tmax] (tmin >= 0).
float slab(Ray ray, vec3 lo, vec3 hi, float tmin, float tmax) {
    precise vec3 t0 = (lo - ray.origin) * ray.inv_dir;
    precise vec3 t1 = (hi - ray.origin) * ray.inv_dir;
    vec3 near3 = min(t0, t1);
    vec3 far3 = max(t0, t1);
    float near = max(max(max(near3.x, near3.y), near3.z), tmin);
    float far = min(min(min(far3.x, far3.y), far3.z), tmax);
    return near <= far ? near : -1.0;
}

// The first REG_STACK entries of the traversal stack live in eight registers, read and written
// with selects; only deeper entries go to the private array. On lavapipe a private array indexed
// per lane costs a scalar load or store per lane, while eight selects are a few vector
// instructions, and a traversal rarely has more than eight entries pending (BENCHMARKS.md: about
// 5 % on primal renders and gradient steps, images bit-identical). The order of visits is
// src/bvh.rs's either way.
#define REG_STACK 8u
// One node or leaf per step, visited in the order of src/bvh.rs (`traverse`): a leaf's triangles
// are tested; an inner node's two boxes are fetched together and tested, and the step goes on to
// the nearer child hit (the first in node order for shadow rays: any hit will do, so no ordering
// is paid for) with the other one pushed. Keeping the next entry in a register instead of pushing
// and popping it saves two stack accesses a step — on lavapipe a private array indexed per lane
// costs a scalar sequence per lane (hence also the register part of the stack below). The builder
// bounds the depth to fit the stack; the overflow check stays as a guard.
Hit bvh_traverse(Ray ray, float tmin, float tmax, bool any_hit) {
    Hit best = Hit(0.0, 0u, 0.0, 0.0, false);
    uint stack[BVH_STACK_SIZE - REG_STACK];
    uint r0 = 0u, r1 = 0u, r2 = 0u, r3 = 0u, r4 = 0u, r5 = 0u, r6 = 0u, r7 = 0u;
    uint sp = 0u;
    uint current = 0u;   // the root
    bool have_current = true;
    // Every entry is visited at most once, so the step bound is never reached; but the compiler
    // cannot know that, so `finished` is not provably true after the loop and the check survives.
    uint max_steps = 2u * globals.node_count + 1u;
    bool finished = false;
    for (uint step = 0u; step <= max_steps; step++) {
        if (!have_current) {
            if (sp == 0u) { finished = true; break; }
            sp -= 1u;
            if (sp >= REG_STACK) {
                current = stack[sp - REG_STACK];
            } else {
                current = sp == 0u ? r0 : sp == 1u ? r1 : sp == 2u ? r2 : sp == 3u ? r3 : sp == 4u ? r4 : sp == 5u ? r5 : sp == 6u ? r6 : r7;
            }
        }
        have_current = false;
        if ((current & BVH_LEAF_BIT) != 0u) {
            uint first = current & BVH_LEAF_FIRST_MASK;
            uint count = ((current & ~BVH_LEAF_BIT) >> BVH_LEAF_COUNT_SHIFT) + 1u;
            // Unrolled over the few slots a leaf can have: no inner loop to mask and join.
            [[unroll]] for (uint k = 0u; k < BVH_LEAF_MAX; k++) {
                if (k < count && !(any_hit && best.valid)) {
                    vec4 h = intersect_triangle(ray, load_tri(first + k), tmin, tmax);
                    if (h.w != 0.0) {
                        tmax = h.x;
                        best = Hit(h.x, first + k, h.y, h.z, true);
                    }
                }
            }
            // Any hit answers a shadow query, even one found just before a loop budget ran out.
            if (any_hit && best.valid) { finished = true; break; }
        } else {
            // The whole node is loaded and both boxes tested before the references are looked at:
            // a test behind `child != BVH_NO_CHILD` became a branch whose box loads waited for the
            // reference's, so the node's words are now requested together (alone, no measurable gain).
            BvhNode node = load_node(current);
            float sa = slab(ray, node.lo0, node.hi0, tmin, tmax);
            float sb = slab(ray, node.lo1, node.hi1, tmin, tmax);
            float ta = node.child0 != BVH_NO_CHILD ? sa : -1.0;
            float tb = node.child1 != BVH_NO_CHILD ? sb : -1.0;
            bool ha = ta >= 0.0;
            bool hb = tb >= 0.0;
            if (ha && hb) {
                if (sp + 1u > BVH_STACK_SIZE) { raise_status(STATUS_STACK_OVERFLOW); finished = true; break; }
                bool b_nearer = !any_hit && tb < ta;
                uint pushed = b_nearer ? node.child0 : node.child1;
                if (sp >= REG_STACK) {
                    stack[sp - REG_STACK] = pushed;
                } else {
                    r0 = sp == 0u ? pushed : r0; r1 = sp == 1u ? pushed : r1; r2 = sp == 2u ? pushed : r2; r3 = sp == 3u ? pushed : r3;
                    r4 = sp == 4u ? pushed : r4; r5 = sp == 5u ? pushed : r5; r6 = sp == 6u ? pushed : r6; r7 = sp == 7u ? pushed : r7;
                }
                sp += 1u;
                current = b_nearer ? node.child1 : node.child0;
                have_current = true;
            } else if (ha || hb) {
                current = ha ? node.child0 : node.child1;
                have_current = true;
            }
        }
    }
    if (!finished) raise_status(STATUS_LOOP_BUDGET);
    return best;
}

Hit bvh_closest_hit(Ray ray, float tmin, float tmax) { return bvh_traverse(ray, tmin, tmax, false); }
bool bvh_occluded(Ray ray, float tmin, float tmax) { return bvh_traverse(ray, tmin, tmax, true).valid; }

#endif
