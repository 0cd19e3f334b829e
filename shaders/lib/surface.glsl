// Surface interactions and material resolution: hit → position, normals, BSDF (twin of src/cpu/surface.rs).
#ifndef PATHGRAD_SURFACE_GLSL
#define PATHGRAD_SURFACE_GLSL

#include "abi.glsl"
#include "bvh.glsl"
#include "bsdf.glsl"
#include "params.glsl"
#include "emitter.glsl"

// RAY_OFFSET and SHADOW_EPSILON come from src/contract/floats.rs.

// dpdu: ∂p/∂u of the triangle from its texture coordinates (kernels with anisotropic BSDFs or
// normal maps; 0 where the coordinates are degenerate).
// dpdv: ∂p/∂v likewise (kernels with normal or bump maps).
struct Surface { vec3 p; vec3 ng; vec3 ns; vec2 uv; uint material; uint emitter; uint interior; vec3 dpdu; vec3 dpdv; vec2 bary; uint tri; };

// Where a material's textures are read: the hit's texture coordinates, for a mesh attribute
// its triangle (index in the tri_vertices array) and barycentric coordinates (b1, b2), and for a
// volume texture the world-space point (twin: TexAt of src/cpu/surface.rs).
struct TexAt { vec2 uv; vec2 bary; uint tri; vec3 p; };

TexAt tex_at(Surface s) { return TexAt(s.uv, s.bary, s.tri, s.p); }

// A triangle's vertex indices and mesh (TriVertices, 16 bytes) read as two 64-bit words, like
// the traversal's nodes and triangles (bvh.glsl): on lavapipe each word read is one gather
// whatever its width. The meshes' records, vertex normals, uvs and emitter indices beside them.
struct TriVertexWords { uint64_t w0; uint64_t w1; };
layout(buffer_reference, scalar, buffer_reference_align = 8) readonly buffer TriVertexWordArray { TriVertexWords v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer MeshShadingArray { MeshShading v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer Vec3Array { vec3 v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer Vec2Array { vec2 v[]; };

// The winding normal of a triangle without vertex normals as the host's glam computes it
// ((v1 − v0) × (v2 − v0) times the reciprocal of its length, or 0 where that is not finite and
// positive): the same floats as the per-triangle normals this replaced (twin: surface_at of
// src/cpu/surface.rs).
vec3 face_normal(TriPositions tri) {
    precise vec3 a = tri.v1 - tri.v0;
    precise vec3 b = tri.v2 - tri.v0;
    precise vec3 c = vec3(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
    precise float len = sqrt(c.x * c.x + c.y * c.y + c.z * c.z);
    precise float rcp = 1.0 / len;
    return (!isinf(rcp) && !isnan(rcp) && rcp > 0.0) ? c * rcp : vec3(0.0);
}

Surface surface_at(Hit hit) {
    TriPositions tri = load_tri(hit.slot);
    TriVertexWordArray a = TriVertexWordArray(globals.addr_tri_vertices);
    uint id = prim_ids[hit.slot];
    uvec2 w0 = unpackUint2x32(a.v[id].w0);        // i0, i1
    uvec2 w1 = unpackUint2x32(a.v[id].w1);        // i2, mesh
    MeshShading m = MeshShadingArray(globals.addr_meshes).v[w1.y];
    vec3 n0, n1, n2;
    if (m.normal_base == NO_ARRAY) {
        n0 = face_normal(tri);
        n1 = n0;
        n2 = n0;
    } else {
        Vec3Array normals = Vec3Array(globals.addr_normals);
        n0 = normals.v[m.normal_base + w0.x];
        n1 = normals.v[m.normal_base + w0.y];
        n2 = normals.v[m.normal_base + w1.x];
    }
    vec2 uv0 = vec2(0.0), uv1 = vec2(0.0), uv2 = vec2(0.0);
    if (m.uv_base != NO_ARRAY) {
        Vec2Array uvs = Vec2Array(globals.addr_uvs);
        uv0 = uvs.v[m.uv_base + w0.x];
        uv1 = uvs.v[m.uv_base + w0.y];
        uv2 = uvs.v[m.uv_base + w1.x];
    }
    float b0 = 1.0 - hit.b1 - hit.b2;
    Surface s;
    s.p = b0 * tri.v0 + hit.b1 * tri.v1 + hit.b2 * tri.v2;
    s.ng = normalize(cross(tri.v1 - tri.v0, tri.v2 - tri.v0));
    vec3 n = b0 * n0 + hit.b1 * n1 + hit.b2 * n2;
    s.ns = dot(n, n) > 0.0 ? normalize(n) : s.ng;
    s.uv = b0 * uv0 + hit.b1 * uv1 + hit.b2 * uv2;
    s.material = m.material;
    s.emitter = m.emitter_base == NO_ARRAY ? NO_EMITTER : UintArray(globals.addr_emitter_ids).v[m.emitter_base + id - m.first_tri];
    s.interior = m.interior;
    s.dpdu = vec3(0.0);
    s.dpdv = vec3(0.0);
    s.bary = vec2(hit.b1, hit.b2);
    s.tri = id;
    if (HAS(F_ANISOTROPIC) || HAS(F_NORMAL_MAP)) {
        vec2 d0 = uv1 - uv0;
        vec2 d1 = uv2 - uv0;
        float det = d0.x * d1.y - d0.y * d1.x;
        vec3 e0 = tri.v1 - tri.v0;
        vec3 e1 = tri.v2 - tri.v0;
        if (det != 0.0) s.dpdu = (d1.y * e0 - d0.y * e1) / det;
        if (HAS(F_NORMAL_MAP) && det != 0.0) s.dpdv = (d0.x * e1 - d1.x * e0) / det;
    }
    return s;
}

// Whether material `id` is (or blends) an anisotropic rough conductor, is an anisotropic rough
// dielectric (never blended), or is principled (its
// `anisotropic` a parameter; never blended), whose shading frame must follow the surface (twin: material_anisotropic of src/cpu/surface.rs).
bool material_anisotropic(uint id) {
    Material m = materials[id];
    if (HAS(F_BLEND) && m.tag == MAT_BLEND) {
        Material a = materials[m.child0];
        Material b = materials[m.child1];
        return (a.tag == MAT_ROUGH_CONDUCTOR && a.p_alpha_v != a.p_alpha)
            || (b.tag == MAT_ROUGH_CONDUCTOR && b.p_alpha_v != b.p_alpha);
    }
    return ((m.tag == MAT_ROUGH_CONDUCTOR || m.tag == MAT_ROUGH_DIELECTRIC) && m.p_alpha_v != m.p_alpha)
        || is_principled(m.tag) || is_principled_thin(m.tag);
}

// Mitsuba's shading frame for anisotropic BSDFs: x along ∂p/∂u made orthogonal to ns (where the
// texture coordinates are degenerate, the first axis of ng's coordinate system), y = ns × x
// (twin: tangent_frame of src/cpu/surface.rs).
ShadingFrame tangent_frame(vec3 ns, vec3 ng, vec3 dpdu) {
    vec3 u = dpdu == vec3(0.0) ? shading_frame(ng).t : dpdu;
    vec3 x = u - ns * dot(ns, u);
    if (dot(x, x) == 0.0) return shading_frame(ns);
    x = normalize(x);
    return ShadingFrame(x, cross(ns, x), ns);
}

vec3 offset_origin(vec3 p, vec3 ng, vec3 dir) {
    vec3 a = abs(p);
    float scale = RAY_OFFSET * max(1.0, max(max(a.x, a.y), a.z));
    return p + ng * (dot(ng, dir) > 0.0 ? scale : -scale);
}

// i mod n in [0, n) for any sign of i (GLSL leaves % of a negative operand undefined).
int euclid_mod(int i, int n) {
    int q = i / n;   // rounds toward zero for either sign
    int r = i - q * n;
    return r < 0 ? r + n : r;
}

// Texel index i of a row or column of n texels under wrap mode `mode` (Mitsuba's `repeat`,
// `mirror`, `clamp`).
int wrap_texel(int i, int n, uint mode) {
    if ((mode & TEX_WRAP_CLAMP) != 0u) return clamp(i, 0, n - 1);
    if ((mode & TEX_WRAP_MIRROR) != 0u) {
        int m = euclid_mod(i, 2 * n);
        return m < n ? m : 2 * n - 1 - m;
    }
    return euclid_mod(i, n);
}

#include "field.glsl"

// The four texels a lookup at uv reads (row 0 is v = 0): their parameter offsets (RGB at
// offset..offset+2) and weights — bilinear, or the nearest texel with weight 1 (`TEX_NEAREST`),
// indices wrapped by `mode`; or the checkerboard's texel with weight 1 (`TEX_CHECKER`). Shared by
// the lookup and its gradient.
void texture_footprint(uint offset, uint width, uint height, uint mode, vec2 uv, out uint texel[4],
                       out float weight[4]) {
    if ((mode & TEX_CHECKER) != 0u) {
        bvec2 upper = greaterThan(uv - floor(uv), vec2(0.5));
        uint t = offset + (upper.x == upper.y ? 0u : 3u);
        texel = uint[4](t, t, t, t);
        weight = float[4](1.0, 0.0, 0.0, 0.0);
        return;
    }
    float x = uv.x * float(width) - 0.5;
    float y = uv.y * float(height) - 0.5;
    bool nearest = (mode & TEX_NEAREST) != 0u;
    float x0 = nearest ? floor(x + 0.5) : floor(x);
    float y0 = nearest ? floor(y + 0.5) : floor(y);
    float fx = nearest ? 0.0 : x - x0;
    float fy = nearest ? 0.0 : y - y0;
    int w = int(width);
    int h = int(height);
    int ix0 = wrap_texel(int(x0), w, mode);
    int iy0 = wrap_texel(int(y0), h, mode);
    int ix1 = wrap_texel(int(x0) + 1, w, mode);
    int iy1 = wrap_texel(int(y0) + 1, h, mode);
    texel[0] = offset + 3u * uint(iy0 * w + ix0);
    texel[1] = offset + 3u * uint(iy0 * w + ix1);
    texel[2] = offset + 3u * uint(iy1 * w + ix0);
    texel[3] = offset + 3u * uint(iy1 * w + ix1);
    weight[0] = (1.0 - fx) * (1.0 - fy);
    weight[1] = fx * (1.0 - fy);
    weight[2] = (1.0 - fx) * fy;
    weight[3] = fx * fy;
}

// The rows a mesh attribute (`TEX_ATTR_FACE` or `TEX_ATTR_VERTEX` in `mode`) reads at `at`: the
// hit triangle's row with weight 1, or its three vertices' rows weighted by the barycentric
// coordinates (Mitsuba's `interpolate_attribute`); rows of `dim` values from `offset`. Shared by
// the lookup and its gradient (twin: attribute_footprint of src/cpu/surface.rs).
void attribute_footprint(uint offset, uint dim, uint mode, TexAt at, out uint texel[4], out float weight[4]) {
    TriVertexWordArray a = TriVertexWordArray(globals.addr_tri_vertices);
    uvec2 w0 = unpackUint2x32(a.v[at.tri].w0);        // i0, i1
    uvec2 w1 = unpackUint2x32(a.v[at.tri].w1);        // i2, mesh
    if ((mode & TEX_ATTR_FACE) != 0u) {
        uint t = offset + dim * (at.tri - MeshShadingArray(globals.addr_meshes).v[w1.y].first_tri);
        texel = uint[4](t, t, t, t);
        weight = float[4](1.0, 0.0, 0.0, 0.0);
        return;
    }
    texel = uint[4](offset + dim * w0.x, offset + dim * w0.y, offset + dim * w1.x, offset);
    weight = float[4](1.0 - at.bary.x - at.bary.y, at.bary.x, at.bary.y, 0.0);
}

bool attribute_mode(uint mode) { return (mode & (TEX_ATTR_FACE | TEX_ATTR_VERTEX)) != 0u; }

// ---- textured area emitters (an EmitterTri's p_radiance with SCALAR_TEXTURE set: the offset of
// its RGB texture's descriptor in the tables array; twin: area_footprint and friends of
// src/cpu/emitter.rs) ----
// Only kernels of scenes with a textured area emitter (F2_AREA_TEXTURE) carry the lookup below.
bool area_textured(uint p) { return HAS2(F2_AREA_TEXTURE) && p != NO_PARAM && (p & SCALAR_TEXTURE) != 0u; }

// The texels (RGB at offset..offset+2) and weights of textured area radiance `p` at uv (its
// `to_uv` applied).
void area_footprint(uint p, vec2 uv, out uint texel[4], out float weight[4]) {
    uint d = p & ~SCALAR_TEXTURE;
    vec3 q = vec3(uv, 1.0);
    vec3 row0 = vec3(coating_table(d + 4u), coating_table(d + 5u), coating_table(d + 6u));
    vec3 row1 = vec3(coating_table(d + 7u), coating_table(d + 8u), coating_table(d + 9u));
    uint word[4] = uint[4](floatBitsToUint(coating_table(d)), floatBitsToUint(coating_table(d + 1u)),
                           floatBitsToUint(coating_table(d + 2u)), floatBitsToUint(coating_table(d + 3u)));
    texture_footprint(word[0], word[1], word[2], word[3], vec2(dot(row0, q), dot(row1, q)), texel, weight);
}

// An area emitter's radiance at the texture coordinates uv of its point: its RGB parameter, or
// its texture there.
vec3 area_radiance(uint p, vec2 uv) {
    if (!area_textured(p)) return param_rgb(p);
    uint texel[4];
    float weight[4];
    area_footprint(p, uv, texel, weight);
    return param_rgb(texel[0]) * weight[0] + param_rgb(texel[1]) * weight[1] + param_rgb(texel[2]) * weight[2]
        + param_rgb(texel[3]) * weight[3];
}

// The texture coordinates at barycentrics b = (b1, b2) of triangle `tri` (0 on a mesh without).
vec2 triangle_uv(uint tri, vec2 b) {
    TriVertexWordArray a = TriVertexWordArray(globals.addr_tri_vertices);
    uvec2 w0 = unpackUint2x32(a.v[tri].w0);        // i0, i1
    uvec2 w1 = unpackUint2x32(a.v[tri].w1);        // i2, mesh
    MeshShading m = MeshShadingArray(globals.addr_meshes).v[w1.y];
    if (m.uv_base == NO_ARRAY) return vec2(0.0);
    Vec2Array uvs = Vec2Array(globals.addr_uvs);
    return (1.0 - b.x - b.y) * uvs.v[m.uv_base + w0.x] + b.x * uvs.v[m.uv_base + w0.y] + b.y * uvs.v[m.uv_base + w1.x];
}

// A textured light's or projector's intensity (or 1) × texture at uv (or 1) × scale (or 1)
// (declared in emitter.glsl; twin: light_tint in src/cpu/emitter.rs).
vec3 light_texture(DeltaLight l, vec2 uv) {
    uint texel[4];
    float weight[4];
    texture_footprint(l.tex, l.tex_width, l.tex_height, l.tex_mode, uv, texel, weight);
    return param_rgb(texel[0]) * weight[0] + param_rgb(texel[1]) * weight[1] + param_rgb(texel[2]) * weight[2]
        + param_rgb(texel[3]) * weight[3];
}

vec3 light_tint(DeltaLight l, vec2 uv) {
    vec3 tint = l.p_intensity != NO_PARAM ? param_rgb(l.p_intensity) : vec3(1.0);
    if (l.tex != NO_PARAM) tint *= light_texture(l, uv);
    if (l.p_scale != NO_PARAM) tint *= params[l.p_scale];
    return tint;
}

// RGB at offset i of the tables array: a normal map's texel (twin: param_rgb over FlatScene::tables).
vec3 table_rgb(uint i) { return vec3(coating_table(i), coating_table(i + 1u), coating_table(i + 2u)); }

// The height's gradient of bump map m at uv times its scale (twin: bump_gradient of
// src/cpu/surface.rs); one height a texel at m.nmap.
vec2 bump_gradient(Material m, vec2 uv) {
    if ((m.nmap_mode & TEX_NEAREST) != 0u) return vec2(0.0);
    uint texel[4];
    float weight[4];
    texture_footprint(m.nmap, m.nmap_width, m.nmap_height, m.nmap_mode, uv, texel, weight);
    float h[4];
    for (uint k = 0u; k < 4u; k++) h[k] = coating_table(m.nmap + (texel[k] - m.nmap) / 3u);
    float x = uv.x * float(m.nmap_width) - 0.5;
    float y = uv.y * float(m.nmap_height) - 0.5;
    float fx = x - floor(x);
    float fy = y - floor(y);
    float dx = (1.0 - fy) * (h[1] - h[0]) + fy * (h[3] - h[2]);
    float dy = (1.0 - fx) * (h[2] - h[0]) + fx * (h[3] - h[1]);
    return vec2(dx * float(m.nmap_width), dy * float(m.nmap_height)) * m.nmap_scale;
}

// The perturbed normal of a normal or bump map in the front-side frame `front` (twin:
// mapped_normal of src/cpu/surface.rs, which states the conventions).
vec3 mapped_normal(Material m, Surface s, ShadingFrame front) {
    if ((m.nmap_mode & NMAP_BUMP) == 0u) {
        uint texel[4];
        float weight[4];
        texture_footprint(m.nmap, m.nmap_width, m.nmap_height, m.nmap_mode, s.uv, texel, weight);
        vec3 rgb = vec3(0.0);
        for (uint k = 0u; k < 4u; k++) rgb += table_rgb(texel[k]) * weight[k];
        return rgb * 2.0 - vec3(1.0);
    }
    vec2 g = bump_gradient(m, s.uv);
    vec3 dpdu = s.dpdu;
    vec3 dpdv = s.dpdv;
    if (dpdu == vec3(0.0)) {
        ShadingFrame f = shading_frame(s.ng);
        dpdu = f.t;
        dpdv = f.b;
    }
    vec3 ns = front.n;
    vec3 du = dpdu + ns * (g.x - dot(ns, dpdu));
    vec3 dv = dpdv + ns * (g.y - dot(ns, dpdv));
    vec3 c = cross(du, dv);
    vec3 n = dot(c, c) > 0.0 ? normalize(c) : vec3(0.0);
    if (dot(s.ng, n) < 0.0) n = -n;
    return to_local(front, n);
}

// Mitsuba's `normalmap` and `bumpmap` frame for material m at surface s (its ns seen from the
// front) from the unperturbed frame `base` (mirrored: a two-sided material seen from the back)
// and wi_world; sets the BSDF's wrapper (twin: normal_map_frame of src/cpu/surface.rs, which
// states the conventions).
ShadingFrame normal_map_frame(Material m, Surface s, ShadingFrame base, bool mirrored, vec3 wi_world, inout Bsdf b) {
    if (mirrored) base.b = -base.b;
    ShadingFrame front = base;
    if (mirrored) front.n = -base.n;
    vec3 n = mapped_normal(m, s, front);
    vec3 wi = to_local(base, wi_world);
    if (wi.z * dot(wi, n) <= 0.0) n = vec3(-n.x, -n.y, n.z);
    n = n == vec3(0.0) ? vec3(0.0, 0.0, 1.0) : normalize(n);
    vec3 t_axis = vec3(1.0, 0.0, 0.0) - n * n.x;
    t_axis = t_axis == vec3(0.0) ? vec3(0.0, 0.0, 1.0) : normalize(t_axis);
    vec3 b_axis = cross(n, t_axis);
    float nz2 = n.z * n.z;
    b.mapped = true;
    b.base_n = vec3(t_axis.z, b_axis.z, n.z);
    b.nmap_alpha2 = min(0.125 * (max(1.0 - nz2, 0.0) / nz2), 1.0);
    return ShadingFrame(to_world(base, t_axis), to_world(base, b_axis), to_world(base, n));
}

// A textured material's texture coordinates: the hit's through its `to_uv` rows.
vec2 texture_uv(Material m, vec2 uv) {
    vec3 p = vec3(uv, 1.0);
    return vec2(dot(m.uv_row0, p), dot(m.uv_row1, p));
}

// The texels (or mesh attribute rows) a textured material's colour reads at `at`.
void material_footprint(Material m, TexAt at, out uint texel[4], out float weight[4]) {
    if (attribute_mode(m.tex_mode)) {
        attribute_footprint(m.p_color, 3u, m.tex_mode, at, texel, weight);
    } else {
        texture_footprint(m.p_color, m.tex_width, m.tex_height, m.tex_mode, texture_uv(m, at.uv), texel, weight);
    }
}

// Whether a textured material's colour is Mitsuba's `volume` texture: a field (p_color is its
// index in the fields array) looked up at the world-space point.
bool volume_textured(Material m) { return HAS2(F2_VOLUME_TEXTURE) && (m.tex_mode & TEX_VOLUME) != 0u; }

// A textured material's colour at `at`.
vec3 texture_lookup(Material m, TexAt at) {
    if (volume_textured(m)) return field_rgb(m.p_color, at.p);
    uint texel[4];
    float weight[4];
    material_footprint(m, at, texel, weight);
    return param_rgb(texel[0]) * weight[0] + param_rgb(texel[1]) * weight[1] + param_rgb(texel[2]) * weight[2]
        + param_rgb(texel[3]) * weight[3];
}

// ---- scalar textures (a roughness or blend weight with SCALAR_TEXTURE set; twin:
// scalar_footprint and friends of src/cpu/surface.rs) ----
bool scalar_textured(uint slot) { return HAS(F_PARAM_TEXTURE) && slot != NO_PARAM && (slot & SCALAR_TEXTURE) != 0u; }

// Word i of the scalar texture descriptor at offset d of the tables array.
uint texture_desc_word(uint d, uint i) { return floatBitsToUint(coating_table(d + i)); }

// The texels' parameter offsets and weights of the lookup of scalar texture `slot` at the hit's
// texture coordinates (its `to_uv` applied; one value a texel), or its mesh attribute's rows.
void scalar_footprint(uint slot, TexAt at, out uint texel[4], out float weight[4]) {
    uint d = slot & ~SCALAR_TEXTURE;
    uint mode = texture_desc_word(d, 3u);
    if (attribute_mode(mode)) {
        attribute_footprint(texture_desc_word(d, 0u), 1u, mode, at, texel, weight);
        return;
    }
    vec3 p = vec3(at.uv, 1.0);
    vec3 row0 = vec3(coating_table(d + 4u), coating_table(d + 5u), coating_table(d + 6u));
    vec3 row1 = vec3(coating_table(d + 7u), coating_table(d + 8u), coating_table(d + 9u));
    vec2 t = vec2(dot(row0, p), dot(row1, p));
    texture_footprint(0u, texture_desc_word(d, 1u), texture_desc_word(d, 2u), mode, t, texel, weight);
    uint offset = texture_desc_word(d, 0u);
    // texture_footprint's offsets step 3 a texel (RGB); these texels hold one value.
    for (uint k = 0u; k < 4u; k++) texel[k] = offset + texel[k] / 3u;
}

// The value of scalar texture `slot` at `at`.
float scalar_lookup(uint slot, TexAt at) {
    uint texel[4];
    float weight[4];
    scalar_footprint(slot, at, texel, weight);
    return params[texel[0]] * weight[0] + params[texel[1]] * weight[1] + params[texel[2]] * weight[2]
        + params[texel[3]] * weight[3];
}

// A blend weight: its parameter, or its texture at `at`.
float scalar_value(uint slot, TexAt at) { return scalar_textured(slot) ? scalar_lookup(slot, at) : params[slot]; }

// A mask's opacity at `at`: its parameter or texture, clipped to [0, 1] as Mitsuba clips it (twin:
// mask_opacity_at of src/cpu/surface.rs).
float mask_opacity_at(uint slot, TexAt at) { return clamp(scalar_value(slot, at), 0.0, 1.0); }

// A roughness: its parameter, or its texture at `at` clamped to ALPHA_TEXTURE_FLOOR as Mitsuba's
// microfacet distribution clamps it.
float alpha_value(uint slot, TexAt at) {
    return scalar_textured(slot) ? max(scalar_lookup(slot, at), ALPHA_TEXTURE_FLOOR) : params[slot];
}

// ---- colour textures (a smooth BSDF's or rough dielectric's reflectance or transmittance with
// SCALAR_TEXTURE set: the offset of its RGB texture's descriptor in the tables array; twin:
// colour_footprint and friends of src/cpu/surface.rs) ----
bool colour_textured(uint slot) { return HAS(F_TEXTURE) && slot != NO_PARAM && (slot & SCALAR_TEXTURE) != 0u; }

// The texels (RGB at each offset) and weights of the lookup of colour texture `slot` at `at`: at
// its texture coordinates through its `to_uv`, or its mesh attribute's rows.
void colour_footprint(uint slot, TexAt at, out uint texel[4], out float weight[4]) {
    uint d = slot & ~SCALAR_TEXTURE;
    uint mode = texture_desc_word(d, 3u);
    if (attribute_mode(mode)) {
        attribute_footprint(texture_desc_word(d, 0u), 3u, mode, at, texel, weight);
        return;
    }
    vec3 p = vec3(at.uv, 1.0);
    vec3 row0 = vec3(coating_table(d + 4u), coating_table(d + 5u), coating_table(d + 6u));
    vec3 row1 = vec3(coating_table(d + 7u), coating_table(d + 8u), coating_table(d + 9u));
    texture_footprint(texture_desc_word(d, 0u), texture_desc_word(d, 1u), texture_desc_word(d, 2u), mode,
                      vec2(dot(row0, p), dot(row1, p)), texel, weight);
}

// Whether colour texture `slot` is Mitsuba's `volume` texture: its descriptor's word 0 the
// field's index, looked up at the world-space point.
bool colour_volume(uint slot) {
    return HAS2(F2_VOLUME_TEXTURE) && (texture_desc_word(slot & ~SCALAR_TEXTURE, 3u) & TEX_VOLUME) != 0u;
}

// A smooth BSDF's or rough dielectric's colour slot at `at`: its RGB parameter, its texture's
// lookup, or (NO_PARAM) `constant`.
vec3 colour_value(uint slot, TexAt at, vec3 constant) {
    if (slot == NO_PARAM) return constant;
    if (!colour_textured(slot)) return param_rgb(slot);
    if (colour_volume(slot)) return field_rgb(texture_desc_word(slot & ~SCALAR_TEXTURE, 0u), at.p);
    uint texel[4];
    float weight[4];
    colour_footprint(slot, at, texel, weight);
    return param_rgb(texel[0]) * weight[0] + param_rgb(texel[1]) * weight[1] + param_rgb(texel[2]) * weight[2]
        + param_rgb(texel[3]) * weight[3];
}

// Scalar slot i (PRINCIPLED_SCALARS) of principled material m: word i of its record in the tables
// array (twin: principled_slot of src/cpu/surface.rs), and its value at uv.
uint principled_slot(Material m, uint i) { return floatBitsToUint(coating_table(m.table + i)); }
float principled_scalar(Material m, uint i, TexAt at) { return scalar_value(principled_slot(m, i), at); }

// Whether conductor m's eta and k are parameters (p_weight: eta's offset, k's three after it).
bool conductor_ior_param(Material m) {
    return (m.tag == MAT_CONDUCTOR || m.tag == MAT_ROUGH_CONDUCTOR) && m.p_weight != NO_PARAM;
}

Leaf leaf_from_material(Material m, TexAt at) {
    Leaf l;
    bool plastic = is_plastic(m.tag);
    bool conductor = is_conductor(m.tag);
    bool delta = is_delta(m.tag);
    bool rough_glass = is_rough_dielectric(m.tag);
    // A thin principled material has principled's layout (MAT_PRINCIPLED_THIN).
    bool principled = is_principled(m.tag) || is_principled_thin(m.tag);
    l.kind = (delta || is_smooth_plastic(m.tag) || rough_glass || principled) ? m.tag
        : (plastic ? LEAF_ROUGH_PLASTIC : (conductor ? LEAF_ROUGH_CONDUCTOR : LEAF_DIFFUSE));
    l.distribution = m.distribution;
    l.alpha = (conductor || plastic || rough_glass) ? alpha_value(m.p_alpha, at) : 0.0;
    // Kernels without anisotropic BSDFs read no second roughness (α_v = α).
    l.alpha_v = (HAS(F_ANISOTROPIC) && (conductor || rough_glass)) ? alpha_value(m.p_alpha_v, at) : l.alpha;
    l.pr0 = vec4(0.0);
    l.pr1 = vec4(0.0);
    if (principled) {
        // Mitsuba floors α = roughness², not a textured roughness; the eight scalars' slots are
        // the record at m.table.
        l.alpha = scalar_value(m.p_alpha, at);
        l.alpha_v = scalar_value(m.p_alpha_v, at);
        l.pr0 = vec4(principled_scalar(m, 0u, at), principled_scalar(m, 1u, at), principled_scalar(m, 2u, at),
                     principled_scalar(m, 3u, at));
        l.pr1 = vec4(principled_scalar(m, 4u, at), principled_scalar(m, 5u, at), principled_scalar(m, 6u, at),
                     principled_scalar(m, 7u, at));
    }
    l.table = m.table;
    if (delta || rough_glass) {
        // Each colour a parameter, a texture or (NO_PARAM) a constant: the reflectance in uv_row0,
        // a dielectric's transmittance in k.
        l.color = colour_value(m.p_color, at, m.uv_row0);
    } else {
        l.color = (HAS(F_TEXTURE) && m.tex_width > 0u) ? texture_lookup(m, at) : param_rgb(m.p_color);
    }
    l.eta = m.eta;
    // A smooth dielectric's η: its parameter (p_weight) or the constant.
    if (delta && m.tag != MAT_CONDUCTOR && m.p_weight != NO_PARAM) l.eta.x = params[m.p_weight];
    // A rough dielectric's η: its parameter (table) or the constant.
    if (rough_glass && m.table != NO_PARAM) l.eta.x = params[m.table];
    // A dielectric's transmittance parameter: p_alpha (smooth) or p_weight (rough); a plastic's
    // specular colour: p_weight.
    bool coated = plastic || is_smooth_plastic(m.tag);
    uint p_trans = (rough_glass || coated) ? m.p_weight : (delta && m.tag != MAT_CONDUCTOR ? m.p_alpha : NO_PARAM);
    l.k = colour_value(p_trans, at, m.k);
    // A conductor's eta and k: its parameters (eta's at p_weight, k's the three values after it) or
    // the constants (twin: conductor_ior of src/cpu/surface.rs).
    if (conductor_ior_param(m)) {
        l.eta = param_rgb(m.p_weight);
        l.k = param_rgb(m.p_weight + 3u);
    }
    return l;
}

// The BSDF of a material with its current parameter values at `at`.
Bsdf resolve_bsdf(uint material_id, TexAt at) {
    Material m = materials[material_id];
    Bsdf b;
    if (HAS(F_BLEND) && m.tag == MAT_BLEND) {
        b.leaf0 = leaf_from_material(materials[m.child0], at);
        b.leaf1 = leaf_from_material(materials[m.child1], at);
        b.weight = scalar_value(m.p_weight, at);
        b.blend = true;
    } else {
        b.leaf0 = leaf_from_material(m, at);
        b.leaf1 = b.leaf0;
        b.weight = 0.0;
        b.blend = false;
    }
    b.mapped = false;
    b.base_n = vec3(0.0, 0.0, 1.0);
    b.nmap_alpha2 = 0.0;
    return b;
}

// ---- the gradient terms of one vertex (ARCHITECTURE decision 5, issue "Fast kernels" item 3) ----
// A replay step gathers every derivative it produces into `GradTerms`, and `scatter_terms` sends
// them through the one param_grad site in a loop, instead of one inlined reduction per term: the
// BSDF's derivative (NEE and the sampled direction summed, they share the material and uv), the
// radiance of the emitter the step hit (or the environment) and of the emitter NEE reached.
struct GradTerms {
    uint material;    // NO_PARAM: no BSDF term
    TexAt at;
    BsdfGrad bsdf;
    uint hit_param;   // RGB parameter of the emitter or environment hit, or NO_PARAM
    vec3 hit;
    uint nee_param;   // RGB parameter of the emitter NEE reached, or NO_PARAM
    vec3 nee;
    vec2 hit_uv;      // the texture coordinates of a textured area emitter's terms (hit, NEE)
    vec2 nee_uv;
    vec3 env_dir;     // the direction of the environment's term (hit or NEE: a step has at most one)
    uint mask;        // a mask's opacity slot (read at `at`), or NO_PARAM
    vec3 opacity;     // its derivative term
};

GradTerms no_grad_terms() {
    LeafGrad none = LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    return GradTerms(NO_PARAM, TexAt(vec2(0.0), vec2(0.0), 0u, vec3(0.0)), BsdfGrad(none, none, vec3(0.0)), NO_PARAM, vec3(0.0), NO_PARAM, vec3(0.0),
                     vec2(0.0), vec2(0.0), vec3(0.0, 0.0, 1.0), NO_PARAM, vec3(0.0));
}

// Most (offset, per-channel value) entries one vertex can produce: an RGB emitter, four RGB texels
// of an environment map (NEE), two leaves of four RGB texels and a roughness each, a blend weight,
// a mask's opacity (a step that hits the environment ends there: it has no other term). A
// principled leaf (never blended) produces at most 22: 12 for its texels' channels, anisotropic
// and eight scalars, and its roughness (a texture's texels go at once).
#define GRAD_ENTRIES 43

// The entries of the vertex being scattered. Globals, not parameters: GLSL passes arrays by
// copy, and copying 33 entries in and out of every helper made the kernel several times larger.
uint grad_offset[GRAD_ENTRIES];
vec3 grad_value[GRAD_ENTRIES];
uint grad_count = 0u;

void push_entry(uint offset, vec3 by_channel) {
    grad_offset[grad_count] = offset;
    grad_value[grad_count] = by_channel;
    grad_count++;
}

// An RGB parameter: image channel c depends only on value c.
void push_rgb(uint offset, vec3 g) {
    push_entry(offset, vec3(g.x, 0.0, 0.0));
    push_entry(offset + 1u, vec3(0.0, g.y, 0.0));
    push_entry(offset + 2u, vec3(0.0, 0.0, g.z));
}

// A scalar slot's derivative g (per image channel): its parameter's entry, or for a texture the
// footprint's texels, added at once (not entries: up to 12 of them a vertex would outgrow
// GRAD_ENTRIES); a roughness clamped to ALPHA_TEXTURE_FLOOR has none.
void push_scalar(uint slot, TexAt at, vec3 g, bool roughness) {
    if (!scalar_textured(slot)) {
        push_entry(slot, g);
        return;
    }
    uint texel[4];
    float weight[4];
    scalar_footprint(slot, at, texel, weight);
    if (roughness && scalar_lookup(slot, at) < ALPHA_TEXTURE_FLOOR) return;
    for (uint k = 0u; k < 4u; k++) {
        if (weight[k] != 0.0) param_grad(texel[k], g * weight[k]);
    }
}

// A smooth BSDF's or rough dielectric's colour slot's derivative g (per image channel): its RGB
// parameter's entries (G_COLOR), or its texture's texels weighted as the lookup weighs them,
// added at once as push_scalar's (G_TEXTURE); a constant has none.
void push_colour(uint slot, TexAt at, vec3 g) {
    if (slot == NO_PARAM) return;
    if (!colour_textured(slot)) {
        if (HAS(G_COLOR)) push_rgb(slot, g);
        return;
    }
    if (!HAS(G_TEXTURE)) return;
    if (colour_volume(slot)) {
        field_grad(texture_desc_word(slot & ~SCALAR_TEXTURE, 0u), at.p, g);
        return;
    }
    uint texel[4];
    float weight[4];
    colour_footprint(slot, at, texel, weight);
    for (uint k = 0u; k < 4u; k++) {
        if (weight[k] != 0.0) param_grad_rgb(texel[k], g * weight[k]);
    }
}

// A principled leaf's derivatives (pr_terms of bsdf.glsl): base colour channel k (a texel's,
// weighted by the lookup) reaches every image channel; every scalar may be a texture; the eight
// scalars' slots are the record at m.table (twin: principled_backward of src/cpu/surface.rs).
void push_principled(Material m, TexAt at) {
    if (HAS(F_TEXTURE) && m.tex_width > 0u) {
        if (HAS(G_TEXTURE)) {
            uint texel[4];
            float weight[4];
            material_footprint(m, at, texel, weight);
            for (uint k = 0u; k < 4u; k++) {
                if (weight[k] == 0.0) continue;
                push_entry(texel[k], pr_terms.base[0] * weight[k]);
                push_entry(texel[k] + 1u, pr_terms.base[1] * weight[k]);
                push_entry(texel[k] + 2u, pr_terms.base[2] * weight[k]);
            }
        }
    } else if (HAS(G_COLOR)) {
        push_entry(m.p_color, pr_terms.base[0]);
        push_entry(m.p_color + 1u, pr_terms.base[1]);
        push_entry(m.p_color + 2u, pr_terms.base[2]);
    }
    if (HAS(G_ALPHA)) push_scalar(m.p_alpha, at, pr_terms.roughness, false);
    if (HAS(G_WEIGHT)) {
        push_scalar(m.p_alpha_v, at, pr_terms.anisotropic, false);
        push_scalar(principled_slot(m, 0u), at, pr_terms.metallic, false);
        push_scalar(principled_slot(m, 1u), at, pr_terms.spec_tint, false);
        push_scalar(principled_slot(m, 2u), at, pr_terms.spec_trans, false);
        push_scalar(principled_slot(m, 3u), at, pr_terms.sheen, false);
        push_scalar(principled_slot(m, 4u), at, pr_terms.sheen_tint, false);
        push_scalar(principled_slot(m, 5u), at, pr_terms.clearcoat, false);
        push_scalar(principled_slot(m, 6u), at, pr_terms.clearcoat_gloss, false);
        push_scalar(principled_slot(m, 7u), at, pr_terms.flatness, false);
    }
}

void push_leaf(Material m, TexAt at, LeafGrad g) {
    if (is_principled(m.tag) || is_principled_thin(m.tag)) {
        push_principled(m, at);
        return;
    }
    // A conductor's eta and k, added at once (as push_scalar's texels: six entries a leaf would
    // outgrow GRAD_ENTRIES); twin: conductor_ior_backward.
    if (HAS(G_COLOR) && conductor_ior_param(m)) {
        param_grad_rgb(m.p_weight, g.eta);
        param_grad_rgb(m.p_weight + 3u, g.k);
    }
    bool rough_glass = is_rough_dielectric(m.tag);
    if (is_delta(m.tag) || rough_glass) {
        // The reflectance and the transmittance (p_alpha of a smooth leaf, p_weight of a rough
        // one); a constant has no parameter.
        uint p_trans = rough_glass ? m.p_weight : m.p_alpha;
        push_colour(m.p_color, at, g.color);
        if (m.tag != MAT_CONDUCTOR) push_colour(p_trans, at, g.trans);
        if (HAS(G_ALPHA) && rough_glass && m.p_alpha_v != m.p_alpha) {
            push_scalar(m.p_alpha, at, g.alpha, true);
            push_scalar(m.p_alpha_v, at, g.alpha_v, true);
        } else if (HAS(G_ALPHA) && rough_glass) {
            // Isotropic: α_u and α_v are one parameter.
            push_scalar(m.p_alpha, at, g.alpha + g.alpha_v, true);
        }
        return;
    }
    if (HAS(F_TEXTURE) && m.tex_width > 0u) {
        if (HAS(G_TEXTURE) && volume_textured(m)) {
            field_grad(m.p_color, at.p, g.color);
        } else if (HAS(G_TEXTURE)) {
            uint texel[4];
            float weight[4];
            material_footprint(m, at, texel, weight);
            // A nearest, checkerboard or per-face lookup reads one texel: no pushes of zero for the rest.
            for (uint k = 0u; k < 4u; k++) {
                if (weight[k] != 0.0) push_rgb(texel[k], g.color * weight[k]);
            }
        }
    } else if (HAS(G_COLOR)) {
        push_rgb(m.p_color, g.color);
    }
    // A plastic's specular colour (p_weight: a parameter, a texture or a constant).
    if (is_plastic(m.tag) || is_smooth_plastic(m.tag)) push_colour(m.p_weight, at, g.trans);
    if (HAS(G_ALPHA) && is_conductor(m.tag) && m.p_alpha_v != m.p_alpha) {
        push_scalar(m.p_alpha, at, g.alpha, true);
        push_scalar(m.p_alpha_v, at, g.alpha_v, true);
    } else if (HAS(G_ALPHA) && (is_conductor(m.tag) || is_plastic(m.tag))) {
        // Isotropic: α_u and α_v are one parameter.
        push_scalar(m.p_alpha, at, g.alpha + g.alpha_v, true);
    }
}

// A textured light's or projector's term `g` (its factor included) toward shading point `x`: its
// intensity and scale as entries, its four texels added at once (as push_scalar's).
void push_light(DeltaLight l, vec3 g, vec3 x) {
    float factor;
    vec2 uv = light_lookup(l, x, factor);
    vec3 intensity = l.p_intensity != NO_PARAM ? param_rgb(l.p_intensity) : vec3(1.0);
    vec3 texture = l.tex != NO_PARAM ? light_texture(l, uv) : vec3(1.0);
    float scale = l.p_scale != NO_PARAM ? params[l.p_scale] : 1.0;
    if (l.p_intensity != NO_PARAM) push_rgb(l.p_intensity, g * texture * scale);
    if (l.p_scale != NO_PARAM) push_entry(l.p_scale, g * intensity * texture);
    if (l.tex != NO_PARAM) {
        uint texel[4];
        float weight[4];
        texture_footprint(l.tex, l.tex_width, l.tex_height, l.tex_mode, uv, texel, weight);
        vec3 t = g * intensity * scale;
        for (uint k = 0u; k < 4u; k++) {
            if (weight[k] != 0.0) param_grad_rgb(texel[k], t * weight[k]);
        }
    }
}

// An emitter's radiance term: one RGB value, or the four texels of the environment map around
// `env_dir` weighted as its lookup weighs them, or a textured light's or projector's values
// (`LIGHT_SLOT` | its index, `env_dir` the shading point), or a textured area emitter's texels at
// `uv`, added at once (as push_light's).
void push_emitter(uint offset, vec3 g, vec3 env_dir, vec2 uv) {
    if (HAS(F_EMITTERS) && area_textured(offset)) {
        uint texel[4];
        float weight[4];
        area_footprint(offset, uv, texel, weight);
        for (uint k = 0u; k < 4u; k++) {
            if (weight[k] != 0.0) param_grad_rgb(texel[k], g * weight[k]);
        }
    } else if (HAS(F_LIGHT_TEXTURE) && offset != NO_PARAM && (offset & LIGHT_SLOT) != 0u) {
        push_light(lights[offset & ~LIGHT_SLOT], g, env_dir);
    } else if (HAS(F_ENV_MAP) && offset == globals.env_param) {
        uint texel[4];
        float weight[4];
        env_footprint(env_dir, texel, weight);
        for (uint k = 0u; k < 4u; k++) {
            if (weight[k] != 0.0) push_rgb(texel[k], g * (globals.env_scale * weight[k]));
        }
    } else {
        push_rgb(offset, g);
    }
}

// Scatters every term of `t` through one param_grad site.
void scatter_terms(GradTerms t) {
    grad_count = 0u;
    if ((HAS(G_EMISSION) || HAS(G_ENV)) && t.hit_param != NO_PARAM) push_emitter(t.hit_param, t.hit, t.env_dir, t.hit_uv);
    if ((HAS(G_EMISSION) || HAS(G_ENV)) && t.nee_param != NO_PARAM) push_emitter(t.nee_param, t.nee, t.env_dir, t.nee_uv);
    if ((HAS(G_COLOR) || HAS(G_TEXTURE) || HAS(G_ALPHA) || HAS(G_WEIGHT)) && t.material != NO_PARAM) {
        Material m = materials[t.material];
        if (HAS(F_BLEND) && m.tag == MAT_BLEND) {
            push_leaf(materials[m.child0], t.at, t.bsdf.leaf0);
            push_leaf(materials[m.child1], t.at, t.bsdf.leaf1);
            if (HAS(G_WEIGHT)) push_scalar(m.p_weight, t.at, t.bsdf.weight, false);
        } else {
            push_leaf(m, t.at, t.bsdf.leaf0);
        }
    }
    if (HAS(F_MASK) && HAS(G_WEIGHT) && t.mask != NO_PARAM) push_scalar(t.mask, t.at, t.opacity, false);
    [[dont_unroll]] for (uint i = 0u; i < grad_count; i++) param_grad(grad_offset[i], grad_value[i]);
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
