// Test probe: bsdf_sample_diff / bsdf_pdf_diff / Lambert W / the inversions on host-given inputs,
// compared with src/bsdf/differential.rs. Reuses the BSDF probe's ABI: `u_lobe` also serves as
// `u_sign` (a conductor reads only u_sign, a blend only u_lobe); `eval` carries
// (W0(−u_lobe/e), W−1((u_lobe − 1)/e), diff_sample_x(dist0, u.x < 0.5, u.y)), `eval_pdf` is
// bsdf_pdf_diff at `wo_eval`. Bit 1 of `blend` is target_v (an anisotropic leaf's target is α_v).
#version 460
#extension GL_EXT_scalar_block_layout : require
#include <generated/contract.glsl>
#include "lib/differential.glsl"

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
    b.blend = (c.blend & 1u) != 0u;
    bool target_v = (c.blend & 2u) != 0u;
    b.mapped = false;
    b.base_n = vec3(0.0, 0.0, 1.0);
    b.nmap_alpha2 = 0.0;
    BsdfSample s = bsdf_sample_diff(b, target_v, c.wi, c.u_lobe, c.u_lobe, c.u);
    vec3 extra = vec3(lambert_w0(-c.u_lobe / EULER_E), lambert_wm1((c.u_lobe - 1.0) / EULER_E),
                      diff_sample_x(c.dist0, c.u.x < 0.5, c.u.y));
    results[i] = BsdfProbeResult(s.wo, s.pdf, s.value, s.valid ? 1u : 0u, extra, bsdf_pdf_diff(b, target_v, c.wi, c.wo_eval));
}
