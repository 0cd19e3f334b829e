// Surface interactions and material resolution: hit → position, normals, BSDF (twin of src/cpu/surface.rs).
#ifndef PATHGRAD_SURFACE_GLSL
#define PATHGRAD_SURFACE_GLSL

#include "abi.glsl"
#include "bvh.glsl"
#include "bsdf.glsl"
#include "params.glsl"

// Spawned rays start this far (relative to the largest coordinate, at least 1) off the surface on
// the side they leave to, so they do not re-hit the triangle they start on.
#define RAY_OFFSET 1e-4
// Shadow rays stop this fraction short of the emitter point so the emitter itself never occludes.
#define SHADOW_EPSILON 1e-4

struct Surface { vec3 p; vec3 ng; vec3 ns; vec2 uv; uint material; uint emitter; };

Surface surface_at(Hit hit) {
    TriPositions tri = tris[hit.slot];
    TriShading sh = shading[prim_ids[hit.slot]];
    float b0 = 1.0 - hit.b1 - hit.b2;
    Surface s;
    s.p = b0 * tri.v0 + hit.b1 * tri.v1 + hit.b2 * tri.v2;
    s.ng = normalize(cross(tri.v1 - tri.v0, tri.v2 - tri.v0));
    vec3 n = b0 * sh.n0 + hit.b1 * sh.n1 + hit.b2 * sh.n2;
    s.ns = dot(n, n) > 0.0 ? normalize(n) : s.ng;
    s.uv = b0 * sh.uv0 + hit.b1 * sh.uv1 + hit.b2 * sh.uv2;
    s.material = sh.material;
    s.emitter = sh.emitter;
    return s;
}

vec3 offset_origin(vec3 p, vec3 ng, vec3 dir) {
    vec3 a = abs(p);
    float scale = RAY_OFFSET * max(1.0, max(max(a.x, a.y), a.z));
    return p + ng * (dot(ng, dir) > 0.0 ? scale : -scale);
}

// The four texels a bilinear lookup at uv reads (with repeat wrapping; row 0 is v = 0): their
// parameter offsets (RGB at offset..offset+2) and weights. Shared by the lookup and its gradient.
void texture_footprint(uint offset, uint width, uint height, vec2 uv, out uint texel[4], out float weight[4]) {
    float x = uv.x * float(width) - 0.5;
    float y = uv.y * float(height) - 0.5;
    float x0 = floor(x);
    float y0 = floor(y);
    float fx = x - x0;
    float fy = y - y0;
    int w = int(width);
    int h = int(height);
    int ix0 = ((int(x0) % w) + w) % w;
    int iy0 = ((int(y0) % h) + h) % h;
    int ix1 = (ix0 + 1) % w;
    int iy1 = (iy0 + 1) % h;
    texel[0] = offset + 3u * uint(iy0 * w + ix0);
    texel[1] = offset + 3u * uint(iy0 * w + ix1);
    texel[2] = offset + 3u * uint(iy1 * w + ix0);
    texel[3] = offset + 3u * uint(iy1 * w + ix1);
    weight[0] = (1.0 - fx) * (1.0 - fy);
    weight[1] = fx * (1.0 - fy);
    weight[2] = (1.0 - fx) * fy;
    weight[3] = fx * fy;
}

vec3 texture_bilinear(uint offset, uint width, uint height, vec2 uv) {
    uint texel[4];
    float weight[4];
    texture_footprint(offset, width, height, uv, texel, weight);
    return param_rgb(texel[0]) * weight[0] + param_rgb(texel[1]) * weight[1] + param_rgb(texel[2]) * weight[2]
        + param_rgb(texel[3]) * weight[3];
}

Leaf leaf_from_material(Material m, vec2 uv) {
    Leaf l;
    l.kind = m.tag == MAT_ROUGH_CONDUCTOR ? LEAF_ROUGH_CONDUCTOR : LEAF_DIFFUSE;
    l.distribution = m.distribution;
    l.alpha = m.tag == MAT_ROUGH_CONDUCTOR ? params[m.p_alpha] : 0.0;
    l.color = m.tex_width > 0u ? texture_bilinear(m.p_color, m.tex_width, m.tex_height, uv) : param_rgb(m.p_color);
    l.eta = m.eta;
    l.k = m.k;
    return l;
}

// The BSDF of a material with its current parameter values at texture coordinates uv.
Bsdf resolve_bsdf(uint material_id, vec2 uv) {
    Material m = materials[material_id];
    Bsdf b;
    if (m.tag == MAT_BLEND) {
        b.leaf0 = leaf_from_material(materials[m.child0], uv);
        b.leaf1 = leaf_from_material(materials[m.child1], uv);
        b.weight = params[m.p_weight];
        b.blend = true;
    } else {
        b.leaf0 = leaf_from_material(m, uv);
        b.leaf1 = b.leaf0;
        b.weight = 0.0;
        b.blend = false;
    }
    return b;
}

// Scatters ∂/∂(texels) of a bilinear lookup: per-channel gradient `g` split by the four weights.
void texture_backward(uint offset, uint width, uint height, vec2 uv, vec3 g) {
    uint texel[4];
    float weight[4];
    texture_footprint(offset, width, height, uv, texel, weight);
    param_grad_rgb(texel[0], g * weight[0]);
    param_grad_rgb(texel[1], g * weight[1]);
    param_grad_rgb(texel[2], g * weight[2]);
    param_grad_rgb(texel[3], g * weight[3]);
}

void leaf_backward(Material m, vec2 uv, LeafGrad g) {
    if (m.tex_width > 0u) texture_backward(m.p_color, m.tex_width, m.tex_height, uv, g.color);
    else param_grad_rgb(m.p_color, g.color);
    if (m.tag == MAT_ROUGH_CONDUCTOR) param_grad(m.p_alpha, g.alpha);
}

// GRAD(f̂(wi, wo), adj): the BSDF's parameters at this surface point.
void bsdf_backward(uint material_id, vec2 uv, Bsdf b, vec3 wi, vec3 wo, vec3 adj) {
    BsdfGrad g = bsdf_eval_grad(b, wi, wo, adj);
    Material m = materials[material_id];
    if (m.tag == MAT_BLEND) {
        leaf_backward(materials[m.child0], uv, g.leaf0);
        leaf_backward(materials[m.child1], uv, g.leaf1);
        param_grad(m.p_weight, g.weight);
    } else {
        leaf_backward(m, uv, g.leaf0);
    }
}

// Per-channel a / b with 0 where b is 0 (ALGORITHMS.md §3.3: 1/f̂ replaced by 0 when f̂ = 0).
vec3 safe_div(vec3 a, vec3 b) {
    return vec3(b.x != 0.0 ? a.x / b.x : 0.0, b.y != 0.0 ? a.y / b.y : 0.0, b.z != 0.0 ? a.z / b.z : 0.0);
}

// Power heuristic a² / (a² + b²), written so that huge densities neither overflow nor give NaN.
float mis_power(float a, float b) {
    if (a <= 0.0) return 0.0;
    float r = b / a;
    return 1.0 / (1.0 + r * r);
}

float max_component(vec3 v) { return max(max(v.x, v.y), v.z); }

#endif
