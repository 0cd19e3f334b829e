// Fields over space (FieldDesc): a constant or a voxel grid under its world-to-unit-cube map,
// looked up trilinearly as Mitsuba's `gridvolume`, and the derivative of a lookup; read by media
// (medium.glsl) and by the `volume` texture on surfaces (surface.glsl). Twin: rgb and field_grad
// of src/cpu/medium.rs.
#ifndef PATHGRAD_FIELD_GLSL
#define PATHGRAD_FIELD_GLSL

// Included by surface.glsl after its wrap_texel, which grid_footprint uses.
#include "bvh.glsl"
#include "params.glsl"

// a + (b − a)·w, as the Rust twin writes its lerp (GLSL's mix may round otherwise).
float lerp_exact(float a, float b, float w) {
    return a + (b - a) * w;
}

// A field's description (FieldDesc, 18 words at a stride of 72 bytes) read as nine 64-bit words,
// as surface_at reads a triangle's shading data: on lavapipe each word read is one gather whatever
// its width, and the field index differs from lane to lane.
struct FieldWords { uint64_t w0; uint64_t w1; uint64_t w2; uint64_t w3; uint64_t w4; uint64_t w5; uint64_t w6; uint64_t w7; uint64_t w8; };
layout(buffer_reference, scalar, buffer_reference_align = 8) readonly buffer FieldWordArray { FieldWords v[]; };

FieldDesc load_field(uint f) {
    FieldWordArray a = FieldWordArray(globals.addr_fields);
    uvec2 w0 = unpackUint2x32(a.v[f].w0);          // kind, channels
    uvec2 w1 = unpackUint2x32(a.v[f].w1);          // offset, res_x
    uvec2 w2 = unpackUint2x32(a.v[f].w2);          // res_y, res_z
    vec2 w3 = word_floats(a.v[f].w3);              // row0.xy
    vec2 w4 = word_floats(a.v[f].w4);              // row0.z, row1.x
    vec2 w5 = word_floats(a.v[f].w5);              // row1.yz
    vec2 w6 = word_floats(a.v[f].w6);              // row2.xy
    vec2 w7 = word_floats(a.v[f].w7);              // row2.z, shift.x
    vec2 w8 = word_floats(a.v[f].w8);              // shift.yz
    return FieldDesc(w0.x, w0.y, w1.x, w1.y, w2.x, w2.y, vec3(w3, w4.x), vec3(w4.y, w5), vec3(w6, w7.x), vec3(w7.y, w8));
}

// The voxels a trilinear lookup of grid field d at local point `local` reads: the lower and upper
// index per axis and the fraction t towards the upper one. The voxel coordinate is local·res − 0.5,
// clamped to [0, res − 1] for FIELD_GRID (Mitsuba's default clamp), otherwise its two indices per
// axis wrapped (repeat, mirror) as a bitmap's texels are. Twin of footprint in src/scene/volume.rs.
void grid_footprint(FieldDesc d, vec3 local, out uvec3 lo, out uvec3 hi, out vec3 t) {
    uvec3 res = uvec3(d.res_x, d.res_y, d.res_z);
    vec3 r = vec3(res);
    vec3 u = local * r - 0.5;
    if (d.kind == FIELD_GRID) u = clamp(u, vec3(0.0), r - 1.0);
    vec3 f = floor(u);
    ivec3 i = ivec3(f);
    ivec3 n = ivec3(res);
    uint mode = d.kind == FIELD_GRID ? TEX_WRAP_CLAMP : d.kind == FIELD_GRID_MIRROR ? TEX_WRAP_MIRROR : 0u;
    lo = uvec3(wrap_texel(i.x, n.x, mode), wrap_texel(i.y, n.y, mode), wrap_texel(i.z, n.z, mode));
    hi = uvec3(wrap_texel(i.x + 1, n.x, mode), wrap_texel(i.y + 1, n.y, mode), wrap_texel(i.z + 1, n.z, mode));
    t = u - f;
}

// Field `f` at world point p per channel (trilinear, grid_footprint's voxels, as Mitsuba); a
// grey field's one channel in all three. One lookup body, looped over the channels, so each call
// site inlines eight voxel loads rather than twenty-four; the twin is rgb in src/cpu/medium.rs.
vec3 field_rgb(uint f, vec3 p) {
    FieldDesc d = load_field(f);
    if (d.kind == FIELD_CONSTANT) {
        return vec3(params[d.offset], params[d.offset + min(1u, d.channels - 1u)], params[d.offset + min(2u, d.channels - 1u)]);
    }
    vec3 local = vec3(dot(d.row0, p), dot(d.row1, p), dot(d.row2, p)) + d.shift;
    uvec3 res = uvec3(d.res_x, d.res_y, d.res_z);
    uvec3 lo, hi;
    vec3 t;
    grid_footprint(d, local, lo, hi, t);
    float v[3];
    [[dont_unroll]] for (uint c = 0u; c < d.channels; c++) {
#define VOXEL(VX, VY, VZ) params[d.offset + (((VZ) * res.y + (VY)) * res.x + (VX)) * d.channels + c]
        float x00 = lerp_exact(VOXEL(lo.x, lo.y, lo.z), VOXEL(hi.x, lo.y, lo.z), t.x);
        float x10 = lerp_exact(VOXEL(lo.x, hi.y, lo.z), VOXEL(hi.x, hi.y, lo.z), t.x);
        float x01 = lerp_exact(VOXEL(lo.x, lo.y, hi.z), VOXEL(hi.x, lo.y, hi.z), t.x);
        float x11 = lerp_exact(VOXEL(lo.x, hi.y, hi.z), VOXEL(hi.x, hi.y, hi.z), t.x);
#undef VOXEL
        v[c] = lerp_exact(lerp_exact(x00, x10, t.y), lerp_exact(x01, x11, t.y), t.z);
    }
    return d.channels == 1u ? vec3(v[0]) : vec3(v[0], v[1], v[2]);
}

// GRAD of field `f` at world point x with weight w per image channel: each value the lookup
// reads, weighted as it weighs it (channel c of an RGB field reaches image channel c only; a grey
// field reaches all three). One param_grad site for every voxel (twin: field_grad of
// src/cpu/medium.rs).
void field_grad(uint f, vec3 x, vec3 w) {
    FieldDesc d = load_field(f);
    uvec3 res = uvec3(d.res_x, d.res_y, d.res_z);
    uvec3 lo, hi;
    vec3 t;
    if (d.kind != FIELD_CONSTANT) grid_footprint(d, vec3(dot(d.row0, x), dot(d.row1, x), dot(d.row2, x)) + d.shift, lo, hi, t);
    uint corners = d.kind == FIELD_CONSTANT ? 1u : 8u;
    [[dont_unroll]] for (uint corner = 0u; corner < corners; corner++) {
        uint base = d.offset;
        float weight = 1.0;
        if (d.kind != FIELD_CONSTANT) {
            bvec3 up = bvec3((corner & 1u) != 0u, (corner & 2u) != 0u, (corner & 4u) != 0u);
            uvec3 v = uvec3(up.x ? hi.x : lo.x, up.y ? hi.y : lo.y, up.z ? hi.z : lo.z);
            weight = (up.x ? t.x : 1.0 - t.x) * (up.y ? t.y : 1.0 - t.y) * (up.z ? t.z : 1.0 - t.z);
            base += ((v.z * res.y + v.y) * res.x + v.x) * d.channels;
        }
        if (weight == 0.0) continue;
        [[dont_unroll]] for (uint c = 0u; c < d.channels; c++) {
            vec3 by = d.channels == 1u ? w * weight : vec3(c == 0u ? w.x : 0.0, c == 1u ? w.y : 0.0, c == 2u ? w.z : 0.0) * weight;
            param_grad(base + c, by);
        }
    }
}

#endif
