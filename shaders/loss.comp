// Loss and adjoint image on the GPU (ALGORITHMS.md §7.1): per value, the loss term and
// A = ∂loss/∂I, with the loss summed by a subgroup reduction and one float atomic per subgroup.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_EXT_shader_atomic_float : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require
#include <generated/contract.glsl>

layout(local_size_x = WORKGROUP_SIZE) in;
layout(set = 0, binding = BINDING_PROBE_IN, scalar) readonly buffer Images { float values[]; };  // image, then target
layout(set = 0, binding = BINDING_PROBE_OUT, scalar) buffer Outputs { float outputs[]; };       // loss sum, then adjoint
PUSH_LossPush;


void main() {
    uint i = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * WORKGROUP_SIZE + gl_GlobalInvocationID.x;
    float term = 0.0;
    if (i < count) {
        float d = values[i] - values[count + i];
        float grad;
        if (kind == LOSS_L1) {
            term = abs(d);
            grad = d > 0.0 ? 1.0 : (d < 0.0 ? -1.0 : 0.0);
        } else if (kind == LOSS_L2) {
            term = d * d;
            grad = 2.0 * d;
        } else {
            float target = values[count + i];
            float denom = kind == LOSS_REL_MSE ? target + REL_MSE_EPSILON : max(abs(target), REL_MSE_EPSILON);
            term = d * d / (denom * denom);
            grad = 2.0 * d / (denom * denom);
        }
        outputs[1u + i] = grad / float(count);
    }
    float total = subgroupAdd(term);
    if (subgroupElect()) atomicAdd(outputs[0], total / float(count));
}
