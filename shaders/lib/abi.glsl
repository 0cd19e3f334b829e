// Scene data of the render kernels: the generated struct twins, the per-render constants and the
// scene arrays behind their device addresses.
#ifndef PATHGRAD_ABI_GLSL
#define PATHGRAD_ABI_GLSL

#extension GL_EXT_scalar_block_layout : require
#extension GL_EXT_control_flow_attributes : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
#include <generated/contract.glsl>

// Per-render constants: a uniform buffer (every lane reads the same values).
layout(set = 0, binding = BINDING_GLOBALS, scalar) uniform GlobalsBuf { Globals globals; };
// The scene's arrays are read through buffer device addresses (GL_EXT_buffer_reference), not
// storage-buffer bindings: on lavapipe (Mesa 25.0) a storage-buffer load whose index differs per
// lane is a branchy per-lane scalar sequence with a bounds check per component, while a
// buffer-reference load is one masked gather per component. The addresses sit in `globals`. The
// triangles, their shading data and the media's fields are read as 64-bit words (lib/bvh.glsl,
// lib/surface.glsl, lib/medium.glsl).
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer UintArray { uint v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer MaterialArray { Material v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer EmitterArray { EmitterTri v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer FloatArray { float v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer ViewArray { ViewCamera v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer MediumArray { MediumDesc v[]; };
#define prim_ids (UintArray(globals.addr_prim_ids).v)
#define materials (MaterialArray(globals.addr_materials).v)
#define emitters (EmitterArray(globals.addr_emitters).v)
#define params (FloatArray(globals.addr_params).v)
#define views (ViewArray(globals.addr_views).v)
#define media (MediumArray(globals.addr_media).v)
layout(set = 0, binding = BINDING_STATUS, scalar) coherent buffer StatusBuf { uint status_flags; };

// Raises a status bit that the host checks after the dispatch.
void raise_status(uint bit) {
    atomicOr(status_flags, bit);
}

vec3 param_rgb(uint offset) {
    return vec3(params[offset], params[offset + 1u], params[offset + 2u]);
}

#endif
