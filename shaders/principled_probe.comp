// Test probe: principled_sample / principled_eval_grad / principled_pdf on host-given inputs,
// compared with src/bsdf/principled.rs.
#version 460
#extension GL_EXT_scalar_block_layout : require
#include <generated/contract.glsl>
#include "lib/bsdf.glsl"
#include "lib/principled.glsl"

layout(local_size_x = WORKGROUP_SIZE) in;
layout(set = 0, binding = BINDING_PROBE_IN, scalar) readonly buffer ProbeIn { PrincipledProbeCase cases[]; };
layout(set = 0, binding = BINDING_PROBE_OUT, scalar) writeonly buffer ProbeOut { PrincipledProbeResult results[]; };
PUSH_CasePush;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= case_count) return;
    PrincipledProbeCase c = cases[i];
    Principled p = Principled(c.base_color, c.roughness, c.anisotropic, c.metallic, c.spec_trans, c.eta, c.spec_tint,
                              c.sheen, c.sheen_tint, c.clearcoat, c.clearcoat_gloss, c.flatness, c.rates);
    vec3 wo;
    bool valid = principled_sample(p, c.wi, c.u_lobe, c.u, wo);
    PrincipledGrad g;
    vec3 value = principled_eval_grad(p, c.wi, c.wo_eval, g);
    results[i] = PrincipledProbeResult(wo, valid ? 1u : 0u, value, principled_pdf(p, c.wi, c.wo_eval), g.base[0],
                                       g.base[1], g.base[2], g.roughness, g.anisotropic, g.metallic, g.spec_trans,
                                       g.spec_tint, g.sheen, g.sheen_tint, g.clearcoat, g.clearcoat_gloss,
                                       g.flatness);
}
