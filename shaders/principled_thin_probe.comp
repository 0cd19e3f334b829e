// Test probe: principled_thin_sample / principled_thin_eval_grad / principled_thin_pdf on
// host-given inputs, compared with src/bsdf/principled_thin.rs.
#version 460
#extension GL_EXT_scalar_block_layout : require
#include <generated/contract.glsl>
#include "lib/bsdf.glsl"
#include "lib/principled.glsl"
#include "lib/principled_thin.glsl"

layout(local_size_x = WORKGROUP_SIZE) in;
layout(set = 0, binding = BINDING_PROBE_IN, scalar) readonly buffer ProbeIn { PrincipledThinProbeCase cases[]; };
layout(set = 0, binding = BINDING_PROBE_OUT, scalar) writeonly buffer ProbeOut { PrincipledThinProbeResult results[]; };
PUSH_CasePush;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= case_count) return;
    PrincipledThinProbeCase c = cases[i];
    PrincipledThin p = PrincipledThin(c.base_color, c.roughness, c.anisotropic, c.spec_trans, c.eta, c.spec_tint,
                                      c.sheen, c.sheen_tint, c.flatness, c.diff_trans,
                                      vec4(c.rates_specular, c.rates_diffuse));
    vec3 wo;
    bool valid = principled_thin_sample(p, c.wi, c.u_lobe, c.u, wo);
    PrincipledThinGrad g;
    vec3 value = principled_thin_eval_grad(p, c.wi, c.wo_eval, g);
    results[i] = PrincipledThinProbeResult(wo, valid ? 1u : 0u, value, principled_thin_pdf(p, c.wi, c.wo_eval),
                                           g.base[0], g.base[1], g.base[2], g.roughness, g.anisotropic,
                                           g.spec_trans, g.eta, g.spec_tint, g.sheen, g.sheen_tint, g.flatness,
                                           g.diff_trans);
}
