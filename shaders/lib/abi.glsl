// Scene bindings of the render kernels: the generated struct twins and one storage buffer each.
#ifndef PATHGRAD_ABI_GLSL
#define PATHGRAD_ABI_GLSL

#extension GL_EXT_scalar_block_layout : require
#extension GL_EXT_control_flow_attributes : require
#include <generated/abi_structs.glsl>

// Per-render constants: a uniform buffer (every lane reads the same values).
layout(set = 0, binding = BINDING_GLOBALS, scalar) uniform GlobalsBuf { Globals globals; };
layout(set = 0, binding = BINDING_NODES, scalar) readonly buffer NodeBuf { BvhNode nodes[]; };
layout(set = 0, binding = BINDING_TRIS, scalar) readonly buffer TriBuf { TriPositions tris[]; };
layout(set = 0, binding = BINDING_PRIM_IDS, scalar) readonly buffer PrimIdBuf { uint prim_ids[]; };
layout(set = 0, binding = BINDING_SHADING, scalar) readonly buffer ShadingBuf { TriShading shading[]; };
layout(set = 0, binding = BINDING_MATERIALS, scalar) readonly buffer MaterialBuf { Material materials[]; };
layout(set = 0, binding = BINDING_EMITTERS, scalar) readonly buffer EmitterBuf { EmitterTri emitters[]; };
layout(set = 0, binding = BINDING_PARAMS, scalar) readonly buffer ParamBuf { float params[]; };
layout(set = 0, binding = BINDING_STATUS, scalar) coherent buffer StatusBuf { uint status_flags; };

// Raises a status bit that the host checks after the dispatch.
void raise_status(uint bit) {
    atomicOr(status_flags, bit);
}

vec3 param_rgb(uint offset) {
    return vec3(params[offset], params[offset + 1u], params[offset + 2u]);
}

#endif
