// Test probe: bsdf_sample / bsdf_eval / bsdf_pdf on host-given inputs, compared with src/bsdf/.
#version 460
#extension GL_EXT_scalar_block_layout : require
#include <generated/contract.glsl>
#include "lib/bsdf.glsl"

layout(local_size_x = WORKGROUP_SIZE) in;
layout(set = 0, binding = BINDING_PROBE_IN, scalar) readonly buffer ProbeIn { BsdfProbeCase cases[]; };
layout(set = 0, binding = BINDING_PROBE_OUT, scalar) writeonly buffer ProbeOut { BsdfProbeResult results[]; };
PUSH_CasePush;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= case_count) return;
    BsdfProbeCase c = cases[i];
    Bsdf b;
    b.leaf0 = Leaf(c.kind0, c.dist0, c.alpha0, c.color0, c.eta0, c.k0, 0u, c.alpha_v0, vec4(0.0), vec4(0.0));
    b.leaf1 = Leaf(c.kind1, c.dist1, c.alpha1, c.color1, c.eta1, c.k1, 0u, c.alpha_v1, vec4(0.0), vec4(0.0));
    b.weight = c.weight;
    b.blend = c.blend != 0u;
    b.mapped = false;
    b.base_n = vec3(0.0, 0.0, 1.0);
    b.nmap_alpha2 = 0.0;
    BsdfSample s = bsdf_sample(b, c.wi, c.u_lobe, c.u);
    results[i] = BsdfProbeResult(s.wo, s.pdf, s.value, s.valid ? 1u : 0u, bsdf_eval(b, c.wi, c.wo_eval), bsdf_pdf(b, c.wi, c.wo_eval));
}
