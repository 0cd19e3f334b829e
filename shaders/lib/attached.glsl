// Attached derivatives (issue 34, ALGORITHMS.md §9): ray-state Jacobians of smooth vertices, their
// completion, and the row vectors the attached estimator carries. Twin: src/attached.rs (the
// derivation is there). A ray's state is (o, d); a Jac6 maps a perturbation of the ray reaching a
// vertex to one of the ray leaving it, δo′ = oo·δo + od·δd, δd′ = dob·δo + dd·δd; a Row6 is a
// derivative by a ray state.
#ifndef PATHGRAD_ATTACHED_GLSL
#define PATHGRAD_ATTACHED_GLSL

struct Row6 { vec3 o; vec3 d; };
struct Jac6 { mat3 oo; mat3 od; mat3 dob; mat3 dd; };

const Row6 ROW6_ZERO = Row6(vec3(0.0), vec3(0.0));

Jac6 jac_identity() {
    return Jac6(mat3(1.0), mat3(0.0), mat3(0.0), mat3(1.0));
}

// The row `r` times `j`: the same derivative by the ray before the map `j`.
Row6 row_through(Row6 r, Jac6 j) {
    return Row6(transpose(j.oo) * r.o + transpose(j.dob) * r.d, transpose(j.od) * r.o + transpose(j.dd) * r.d);
}

Row6 row_add_scaled(Row6 a, Row6 b, float s) {
    return Row6(a.o + s * b.o, a.d + s * b.d);
}

// `outer ∘ inner`.
Jac6 jac_compose(Jac6 outer_map, Jac6 inner) {
    return Jac6(outer_map.oo * inner.oo + outer_map.od * inner.dob, outer_map.oo * inner.od + outer_map.od * inner.dd,
                outer_map.dob * inner.oo + outer_map.dd * inner.dob, outer_map.dob * inner.od + outer_map.dd * inner.dd);
}

// The completion (ng, 0)⊗(prev_normal, 0) + (0, d_out)⊗(0, d): zero on the manifold of rays the
// vertex maps, invertible off it (Jac6::completed).
Jac6 jac_completed(Jac6 a, vec3 prev_normal, vec3 d, vec3 ng, vec3 d_out) {
    return Jac6(a.oo + outerProduct(ng, prev_normal), a.od, a.dob, a.dd + outerProduct(d_out, d));
}

Jac6 jac_plus_identity(Jac6 a, float y) {
    return Jac6(a.oo + mat3(y), a.od, a.dob, a.dd + mat3(y));
}

// a + y·R in the direction block, R = t_out⊗t_in + b_out⊗b_in (the frames of d and d_out): the
// regularisation of a vertex whose outgoing direction ignores the incoming one
// (Jac6::plus_direction_noise).
Jac6 jac_plus_direction_noise(Jac6 a, float y, vec3 d, vec3 d_out) {
    ShadingFrame fi = shading_frame(d);
    ShadingFrame fo = shading_frame(d_out);
    return Jac6(a.oo, a.od, a.dob, a.dd + y * (outerProduct(fo.t, fi.t) + outerProduct(fo.b, fi.b)));
}

// The row x with x·a = b (block elimination on the transposed system); false where a block is
// singular or the result is not finite.
bool jac_solve_row(Jac6 a, Row6 b, out Row6 x) {
    mat3 ta = transpose(a.oo);
    mat3 tb = transpose(a.dob);
    mat3 tc = transpose(a.od);
    mat3 td = transpose(a.dd);
    x = ROW6_ZERO;
    if (determinant(ta) == 0.0) return false;
    mat3 a_inv = inverse(ta);
    mat3 s = td - tc * a_inv * tb;
    if (determinant(s) == 0.0) return false;
    vec3 xd = inverse(s) * (b.d - tc * (a_inv * b.o));
    vec3 xo = a_inv * (b.o - tb * xd);
    bool finite = !any(isnan(xo)) && !any(isinf(xo)) && !any(isnan(xd)) && !any(isinf(xd));
    if (finite) x = Row6(xo, xd);
    return finite;
}

// The regularisation scalar Y: magnitude uniform in [a/2, a], sign from u_sign.
float jac_regularisation(float amplitude, float u_sign, float u_size) {
    float size = amplitude * (0.5 + 0.5 * u_size);
    return u_sign < 0.5 ? -size : size;
}

// Where a ray meets a triangle: distance t, incoming direction d, the plane's normal ng, the
// shading normal n the BSDF used and ∂n/∂x along the plane.
struct HitGeometry { float t; vec3 d; vec3 ng; vec3 n; mat3 dn_dx; };

mat3 hit_projection(HitGeometry g) {
    return mat3(1.0) - outerProduct(g.d, g.ng / dot(g.d, g.ng));
}

// ∂cos θi/∂r with cos θi = −d·n.
Row6 hit_cos_row(HitGeometry g) {
    vec3 w = transpose(hit_projection(g)) * (transpose(g.dn_dx) * g.d);
    return Row6(-w, -(g.n + g.t * w));
}

// The vertex's Jacobian for an outgoing direction T(d, n) with ∂T/∂d = t_d, ∂T/∂n = t_n.
Jac6 hit_jacobian(HitGeometry g, mat3 t_d, mat3 t_n) {
    mat3 p = hit_projection(g);
    mat3 np = t_n * g.dn_dx * p;
    return Jac6(p, g.t * p, np, t_d + g.t * np);
}

// ∇b1 and ∇b2 along the triangle v0 v1 v2 (barycentric_gradients).
void barycentric_gradients(vec3 v0, vec3 v1, vec3 v2, out vec3 grad_b1, out vec3 grad_b2) {
    vec3 e0 = v1 - v0;
    vec3 e1 = v2 - v0;
    float g00 = dot(e0, e0);
    float g01 = dot(e0, e1);
    float g11 = dot(e1, e1);
    float det = g00 * g11 - g01 * g01;
    grad_b1 = vec3(0.0);
    grad_b2 = vec3(0.0);
    if (det == 0.0) return;
    grad_b1 = (g11 * e0 - g01 * e1) / det;
    grad_b2 = (g00 * e1 - g01 * e0) / det;
}

// ∂n/∂x of the normalised interpolation of vertex normals over the triangle v0 v1 v2.
mat3 normal_derivative(vec3 v0, vec3 v1, vec3 v2, vec3 n0, vec3 n1, vec3 n2, vec3 n_raw) {
    vec3 grad_b1;
    vec3 grad_b2;
    barycentric_gradients(v0, v1, v2, grad_b1, grad_b2);
    float len = length(n_raw);
    if ((grad_b1 == vec3(0.0) && grad_b2 == vec3(0.0)) || len == 0.0) return mat3(0.0);
    mat3 raw = outerProduct(n1 - n0, grad_b1) + outerProduct(n2 - n0, grad_b2);
    vec3 n = n_raw / len;
    return (mat3(1.0) - outerProduct(n, n)) * raw / len;
}

// The triangle `hit` lies on: its positions, its vertex indices and its mesh.
struct HitTriangle { TriPositions tri; uvec3 index; MeshShading mesh; };

HitTriangle hit_triangle(Hit hit) {
    TriVertexWordArray a = TriVertexWordArray(globals.addr_tri_vertices);
    uint id = prim_ids[hit.slot];
    uvec2 w0 = unpackUint2x32(a.v[id].w0);        // i0, i1
    uvec2 w1 = unpackUint2x32(a.v[id].w1);        // i2, mesh
    return HitTriangle(load_tri(hit.slot), uvec3(w0, w1.x), MeshShadingArray(globals.addr_meshes).v[w1.y]);
}

// ∂n/∂x of the unflipped shading normal of surface_at(hit): zero for a mesh without normals.
mat3 shading_normal_gradient(Hit hit) {
    HitTriangle h = hit_triangle(hit);
    if (h.mesh.normal_base == NO_ARRAY) return mat3(0.0);
    Vec3Array normals = Vec3Array(globals.addr_normals);
    vec3 n0 = normals.v[h.mesh.normal_base + h.index.x];
    vec3 n1 = normals.v[h.mesh.normal_base + h.index.y];
    vec3 n2 = normals.v[h.mesh.normal_base + h.index.z];
    float b0 = 1.0 - hit.b1 - hit.b2;
    return normal_derivative(h.tri.v0, h.tri.v1, h.tri.v2, n0, n1, n2, b0 * n0 + hit.b1 * n1 + hit.b2 * n2);
}

// The environment's radiance toward `dir` differentiated by the direction: row c of the result
// (GLSL: the transpose's column c) is ∂L_c/∂d; zero for a constant (EnvMap::footprint_gradient).
mat3 env_radiance_gradient(vec3 dir) {
    if (!HAS(F_ENV_MAP)) return mat3(0.0);
    vec3 l = vec3(dot(globals.env_rot0, dir), dot(globals.env_rot1, dir), dot(globals.env_rot2, dir));
    float rho2 = l.x * l.x + l.z * l.z;
    if (!(rho2 > 0.0)) return mat3(0.0);
    float rho = sqrt(rho2);
    vec3 grad_u = vec3(-l.z, 0.0, l.x) / (rho2 * 2.0 * PI);
    vec3 grad_v = vec3(l.y * l.x / rho, -rho, l.y * l.z / rho) / ((rho2 + l.y * l.y) * PI);
    vec2 f;
    env_cell_at(dir, f);
    mat3 to_world = mat3(globals.env_rot0, globals.env_rot1, globals.env_rot2);
    vec3 gx = to_world * grad_u * float(globals.env_width);
    vec3 gy = to_world * grad_v * float(globals.env_height - 1u);
    vec3 grads[4] = vec3[4](-(1.0 - f.y) * gx - (1.0 - f.x) * gy, (1.0 - f.y) * gx - f.x * gy,
                            -f.y * gx + (1.0 - f.x) * gy, f.y * gx + f.x * gy);
    uint texel[4];
    float weight[4];
    env_footprint(dir, texel, weight);
    mat3 sum = mat3(0.0);
    for (uint k = 0u; k < 4u; k++) sum += outerProduct(param_rgb(texel[k]), grads[k]);
    return globals.env_scale * sum;
}

// The dielectric Fresnel reflectance and its derivatives by cos θi and η: (F, ∂F/∂cos, ∂F/∂η).
vec3 fresnel_dielectric_grad(float cos_i, float eta) {
    float r = fresnel_dielectric(cos_i, eta);
    bool outside = cos_i >= 0.0;
    float e = outside ? eta : 1.0 / eta;
    float de_deta = outside ? 1.0 : -1.0 / (eta * eta);
    float c = abs(cos_i);
    float ct2 = 1.0 - (1.0 - c * c) / (e * e);
    if (eta == 1.0 || c == 0.0 || !(ct2 > 0.0)) return vec3(r, 0.0, 0.0);
    float ct = sqrt(ct2);
    float dct_dc = c / (e * e * ct);
    float dct_de = (1.0 - c * c) / (e * e * e * ct);
    float ns = c - e * ct, ds = c + e * ct;
    float a_s = ns / ds;
    float das_dc = ((1.0 - e * dct_dc) * ds - ns * (1.0 + e * dct_dc)) / (ds * ds);
    float das_de = ((-ct - e * dct_de) * ds - ns * (ct + e * dct_de)) / (ds * ds);
    float np = ct - e * c, dp = ct + e * c;
    float a_p = np / dp;
    float dap_dc = ((dct_dc - e) * dp - np * (dct_dc + e)) / (dp * dp);
    float dap_de = ((dct_de - c) * dp - np * (dct_de + c)) / (dp * dp);
    float dr_dc = a_s * das_dc + a_p * dap_dc;
    float dr_de = a_s * das_de + a_p * dap_de;
    return vec3(r, (outside ? 1.0 : -1.0) * dr_dc, dr_de * de_deta);
}

// What a smooth lobe contributes (attached::SmoothLobe): ∂d′/∂d, ∂d′/∂n, ∂d′/∂η and the
// derivatives of its log-weight by cos θi and by η (grey for dielectrics).
struct SmoothLobe { mat3 t_d; mat3 t_n; vec3 t_eta; vec3 dlnw_dcos; float dlnw_deta; };

void reflect_jacobians(vec3 d, vec3 n, out mat3 t_d, out mat3 t_n) {
    t_d = mat3(1.0) - 2.0 * outerProduct(n, n);
    t_n = -2.0 * (outerProduct(n, d) + mat3(dot(d, n)));
}

// The smooth `dielectric` (thin false) or `thindielectric` lobe's derivatives; false where the
// lobe cannot have been sampled.
bool smooth_lobe(bool thin, vec3 d, vec3 n, float eta, bool transmitted, out SmoothLobe lobe) {
    float cos_i = -dot(d, n);
    lobe = SmoothLobe(mat3(1.0), mat3(0.0), vec3(0.0), vec3(0.0), 0.0);
    if (thin) {
        float sign_c = cos_i >= 0.0 ? 1.0 : -1.0;
        vec3 fr = fresnel_dielectric_grad(abs(cos_i), eta);
        float r2 = 2.0 * fr.x / (1.0 + fr.x);
        float g = 2.0 / ((1.0 + fr.x) * (1.0 + fr.x));
        float p = transmitted ? 1.0 - r2 : r2;
        float sgn = transmitted ? -1.0 : 1.0;
        if (!(p > 0.0)) return false;
        if (!transmitted) reflect_jacobians(d, n, lobe.t_d, lobe.t_n);
        lobe.dlnw_dcos = vec3(sgn * g * fr.y * sign_c / p);
        lobe.dlnw_deta = sgn * g * fr.z / p;
        return true;
    }
    vec3 fr = fresnel_dielectric_grad(cos_i, eta);
    float f = fr.x;
    if (!transmitted) {
        if (!(f > 0.0)) return false;
        reflect_jacobians(d, n, lobe.t_d, lobe.t_n);
        lobe.dlnw_dcos = vec3(fr.y / f);
        lobe.dlnw_deta = fr.z / f;
        return true;
    }
    if (!(f < 1.0)) return false;
    bool outside = cos_i >= 0.0;
    float eta_ti = outside ? 1.0 / eta : eta;
    float deta_ti = outside ? -1.0 / (eta * eta) : 1.0;
    // d′ = η_ti·d + (cos θt + η_ti·cos θi)·n.
    float c = cos_i;
    float root2 = 1.0 - eta_ti * eta_ti * (1.0 - c * c);
    if (!(root2 > 0.0)) return false;
    float root = sqrt(root2);
    float sign_c = c >= 0.0 ? 1.0 : -1.0;
    float cos_t = -sign_c * root;
    float dct_dc = -sign_c * eta_ti * eta_ti * c / root;
    float dct_deta = sign_c * eta_ti * (1.0 - c * c) / root;
    float k = dct_dc + eta_ti;
    lobe.t_d = eta_ti * mat3(1.0) - k * outerProduct(n, n);
    lobe.t_n = (cos_t + eta_ti * c) * mat3(1.0) - k * outerProduct(n, d);
    lobe.t_eta = (d + (dct_deta + c) * n) * deta_ti;
    lobe.dlnw_dcos = vec3(-fr.y / (1.0 - f));
    lobe.dlnw_deta = -fr.z / (1.0 - f) + 2.0 * deta_ti / eta_ti;
    return true;
}

// The conductor Fresnel reflectance's derivative by cos θi, per channel (fresnel_conductor_grad).
vec3 fresnel_conductor_dcos(float c, vec3 eta, vec3 k) {
    vec3 df;
    for (uint ch = 0u; ch < 3u; ch++) {
        float e = eta[ch];
        float kk = k[ch];
        float c2 = c * c;
        float s2 = 1.0 - c2;
        float s4 = s2 * s2;
        float ds2 = -2.0 * c;
        float ds4 = -4.0 * c * s2;
        float t1 = e * e - kk * kk - s2;
        float dt1 = -ds2;
        float q = sqrt(t1 * t1 + 4.0 * e * e * kk * kk);
        float dq = q > 0.0 ? t1 * dt1 / q : 0.0;
        float a = sqrt(max((q + t1) * 0.5, 0.0));
        float da = a > 0.0 ? (dq + dt1) / (4.0 * a) : 0.0;
        float n = q + c2 - 2.0 * c * a;
        float d = q + c2 + 2.0 * c * a;
        float dn = dq + 2.0 * c - 2.0 * a - 2.0 * c * da;
        float dd = dq + 2.0 * c + 2.0 * a + 2.0 * c * da;
        float rs = n / d;
        float drs = (dn * d - n * dd) / (d * d);
        float cross_term = a * s2 + c * da * s2 + c * a * ds2;
        float m = q * c2 + s4 - 2.0 * c * a * s2;
        float e2 = q * c2 + s4 + 2.0 * c * a * s2;
        float dm = dq * c2 + 2.0 * q * c + ds4 - 2.0 * cross_term;
        float de2 = dq * c2 + 2.0 * q * c + ds4 + 2.0 * cross_term;
        float r = m / e2;
        float dr = (dm * e2 - m * de2) / (e2 * e2);
        df[ch] = 0.5 * (drs + drs * r + rs * dr);
    }
    return df;
}

// A smooth conductor's mirror lobe (conductor_lobe): false below the surface or where F is 0.
bool conductor_lobe(vec3 d, vec3 n, vec3 eta, vec3 k, out SmoothLobe lobe) {
    float cos_i = -dot(d, n);
    lobe = SmoothLobe(mat3(1.0), mat3(0.0), vec3(0.0), vec3(0.0), 0.0);
    vec3 f = fresnel_conductor(cos_i, eta, k);
    if (!(cos_i > 0.0) || !(min(f.x, min(f.y, f.z)) > 0.0)) return false;
    reflect_jacobians(d, n, lobe.t_d, lobe.t_n);
    lobe.dlnw_dcos = fresnel_conductor_dcos(cos_i, eta, k) / f;
    return true;
}

// Duff et al.'s basis (t, b) around n and ∂t/∂n, ∂b/∂n (basis_jacobians).
void basis_jacobians(vec3 n, out vec3 t, out vec3 b, out mat3 t_n, out mat3 b_n) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float bb = n.x * n.y * a;
    t = vec3(1.0 + s * n.x * n.x * a, s * bb, -s * n.x);
    b = vec3(bb, s + n.y * n.y * a, -n.y);
    vec3 db = vec3(n.y * a, n.x * a, n.x * n.y * a * a);
    t_n = transpose(mat3(vec3(2.0 * s * n.x * a, 0.0, s * n.x * n.x * a * a), s * db, vec3(-s, 0.0, 0.0)));
    b_n = transpose(mat3(db, vec3(0.0, 2.0 * n.y * a, n.y * n.y * a * a), vec3(0.0, -1.0, 0.0)));
}

// ∂d′/∂n of a diffuse vertex's cosine sample `local` in the frame of basis_jacobians around n
// (diffuse_direction_jacobian).
mat3 diffuse_direction_jacobian(vec3 n, vec3 local) {
    vec3 t;
    vec3 b;
    mat3 t_n;
    mat3 b_n;
    basis_jacobians(n, t, b, t_n, b_n);
    return local.x * t_n + local.y * b_n + mat3(local.z);
}

// ln G1 and its derivative by s² = α² tan² θ (ln_g1).
vec2 attached_ln_g1(bool beckmann, float s2) {
    if (!(s2 > 0.0)) return vec2(0.0);
    if (beckmann) {
        float a = 1.0 / sqrt(s2);
        float lambda = 0.5 * (erf_approx(a) - 1.0) + exp(-a * a) / (2.0 * a * sqrt(PI));
        float g1 = 1.0 / (1.0 + lambda);
        return vec2(log(g1), -g1 * exp(-a * a) / (4.0 * a * s2 * sqrt(PI)));
    }
    float root = sqrt(1.0 + s2);
    return vec2(log(2.0 / (1.0 + root)), -1.0 / (2.0 * root * (1.0 + root)));
}

// A rough conductor's attached lobe (RoughLobe of src/attached.rs).
struct RoughLobe {
    vec3 wo; vec3 weight; float pdf; mat3 t_d; mat3 t_n; vec3 t_alpha;
    vec3 dlnw_dd; vec3 dlnw_dn; float dlnw_dalpha; vec3 dc_dd; vec3 dc_dn; float dc_dalpha; vec3 dlnf_dc;
};

float attached_tan2(float c) { return max(1.0 - c * c, 0.0) / (c * c); }

// ln(G1(cos θi)·G1(cos θo)) at roughness α and its derivatives by cos θi, cos θo and α (ln_masking
// of src/attached.rs): ∂ ln G1/∂cos = ∂ ln G1/∂s² · α²·(−2/cos³); ∂ ln G1/∂α = ∂ ln G1/∂s² · 2α tan².
vec4 attached_ln_masking(bool beckmann, float alpha, float ci, float co) {
    vec2 gi = attached_ln_g1(beckmann, alpha * alpha * attached_tan2(ci));
    vec2 go = attached_ln_g1(beckmann, alpha * alpha * attached_tan2(co));
    float gi_c = gi.y * alpha * alpha * -2.0 / (ci * ci * ci);
    float go_c = go.y * alpha * alpha * -2.0 / (co * co * co);
    float g_alpha = gi.y * 2.0 * alpha * attached_tan2(ci) + go.y * 2.0 * alpha * attached_tan2(co);
    return vec4(gi.x + go.x, gi_c, go_c, g_alpha);
}

// micro_normal of src/attached.rs: a microfacet normal h drawn from D(h)·cos θh (GGX, or Beckmann)
// about the unit normal n, in the frame basis_jacobians builds from n; with ∂h/∂n (hn), ∂h/∂α, h's
// local coordinates hl and ∂hl.z/∂α. The rough conductor's and the rough dielectric's lobes share it.
void attached_micro_normal(vec3 n, float alpha, bool beckmann, vec2 u, out vec3 h, out mat3 hn, out vec3 h_alpha,
                           out vec3 hl, out float dhl_z) {
    vec3 t, b;
    mat3 t_n, b_n;
    basis_jacobians(n, t, b, t_n, b_n);
    float uu = min(u.x, 1.0 - 1e-7);
    float g = beckmann ? sqrt(max(-log(1.0 - uu), 0.0)) : sqrt(uu / (1.0 - uu));
    float phi = 2.0 * PI * u.y;
    float sin_p = sin(phi);
    float cos_p = cos(phi);
    vec3 m = vec3(alpha * g * cos_p, alpha * g * sin_p, 1.0);
    float len = length(m);
    hl = m / len;
    vec3 dm = vec3(g * cos_p, g * sin_p, 0.0);
    vec3 dhl = (dm - hl * dot(hl, dm)) / len;
    h = hl.x * t + hl.y * b + hl.z * n;
    hn = hl.x * t_n + hl.y * b_n + mat3(hl.z);
    h_alpha = dhl.x * t + dhl.y * b + dhl.z * n;
    dhl_z = dhl.z;
}

// rough_conductor_lobe: false where the sample leaves below the surface or weighs nothing.
bool rough_conductor_lobe(vec3 d, vec3 n, float alpha, bool beckmann, vec2 u, vec3 eta, vec3 k, out RoughLobe l) {
    l = RoughLobe(vec3(0.0), vec3(0.0), 0.0, mat3(1.0), mat3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), 0.0,
                  vec3(0.0), vec3(0.0), 0.0, vec3(0.0));
    float ci = -dot(d, n);
    if (!(ci > 0.0) || !(alpha > 0.0)) return false;
    vec3 h, h_alpha, hl;
    mat3 hn;
    float dhl_z;
    attached_micro_normal(n, alpha, beckmann, u, h, hn, h_alpha, hl, dhl_z);
    float c = -dot(d, h);
    vec3 wo = d + 2.0 * c * h;
    float co = dot(wo, n);
    if (!(c > 0.0) || !(co > 0.0)) return false;
    vec3 f = fresnel_conductor(c, eta, k);
    if (!(min(f.x, min(f.y, f.z)) > 0.0)) return false;
    vec4 masking = attached_ln_masking(beckmann, alpha, ci, co);
    float gi_c = masking.y;
    float go_c = masking.z;
    float g_alpha = masking.w;
    float hz = hl.z;
    l.wo = wo;
    l.weight = f * (exp(masking.x) * c / (ci * hz));
    l.dc_dd = -h;
    l.dc_dn = -(transpose(hn) * d);
    l.dc_dalpha = -dot(d, h_alpha);
    l.t_d = mat3(1.0) - 2.0 * outerProduct(h, h);
    l.t_n = 2.0 * outerProduct(h, l.dc_dn) + 2.0 * c * hn;
    l.t_alpha = 2.0 * l.dc_dalpha * h + 2.0 * c * h_alpha;
    vec3 co_d = transpose(l.t_d) * n;
    vec3 co_n = transpose(l.t_n) * n + wo;
    float co_alpha = dot(n, l.t_alpha);
    l.dlnw_dd = l.dc_dd / c + gi_c * -n + go_c * co_d + n / ci;
    l.dlnw_dn = l.dc_dn / c + gi_c * -d + go_c * co_n + d / ci;
    l.dlnw_dalpha = l.dc_dalpha / c + go_c * co_alpha + g_alpha - dhl_z / hz;
    l.pdf = microfacet_d(beckmann ? DIST_BECKMANN : DIST_GGX, alpha, hl) * hz / (4.0 * c);
    l.dlnf_dc = fresnel_conductor_dcos(c, eta, k) / f;
    return true;
}

// A rough dielectric's attached lobe (RoughDielectricLobe of src/attached/rough_dielectric.rs, where
// it is derived): a microfacet normal drawn from D(h)·cos θh about the normal turned to the side the
// ray arrives on, then reflection (u_lobe ≤ F) or refraction through it. Rows are of ln(w·P), P the
// lobe's choice probability; `weight` leaves out the specular reflectance or transmittance.
struct RoughGlassLobe {
    vec3 wo; bool transmitted; float weight; float pdf; mat3 t_d; mat3 t_n; vec3 t_alpha; vec3 t_eta;
    vec3 dlnw_dd; vec3 dlnw_dn; float dlnw_dalpha; float dlnw_deta;
};

// rough_dielectric_lobe (eta: inside over outside; n: the outward shading normal): false where the
// sample leaves on the side its lobe does not serve, meets total internal reflection on the
// refracted branch, or weighs nothing.
bool rough_dielectric_lobe(vec3 d, vec3 n, float alpha, bool beckmann, vec2 u, float u_lobe, float eta,
                           out RoughGlassLobe l) {
    l = RoughGlassLobe(vec3(0.0), false, 0.0, 0.0, mat3(1.0), mat3(0.0), vec3(0.0), vec3(0.0), vec3(0.0),
                       vec3(0.0), 0.0, 0.0);
    // The normal turned to the incoming side: n′ = s·n.
    float s = dot(d, n) <= 0.0 ? 1.0 : -1.0;
    vec3 ns = s * n;
    float ci = -dot(d, ns);
    if (!(ci > 0.0) || !(alpha > 0.0) || !(eta > 0.0)) return false;
    // The microfacet normal about n′ (micro_normal).
    vec3 h, h_alpha, hl;
    mat3 hn;
    float dhl_z;
    attached_micro_normal(ns, alpha, beckmann, u, h, hn, h_alpha, hl, dhl_z);
    // ∂h/∂n = s·∂h/∂n′.
    hn = s * hn;
    float c = -dot(d, h);
    if (!(c > 0.0)) return false;
    vec3 dc_dd = -h;
    vec3 dc_dn = -(transpose(hn) * d);
    float dc_dalpha = -dot(d, h_alpha);
    // F at the microfacet with the side's sign, by c and by η.
    vec3 fr = fresnel_dielectric_grad(s * c, eta);
    float f = fr.x;
    float df_dc = s * fr.y;
    bool transmitted = u_lobe > f;
    bool outside = s > 0.0;
    float eta_ti = outside ? 1.0 / eta : eta;
    float deta_ti = outside ? -1.0 / (eta * eta) : 1.0;
    vec3 wo;
    mat3 t_d;
    mat3 t_nn;
    vec3 t_alpha;
    vec3 t_eta = vec3(0.0);
    float choice;
    float dlnp_df;
    if (transmitted) {
        // Refraction through h (refract_jacobians with cos θi = c > 0).
        float root2 = 1.0 - eta_ti * eta_ti * (1.0 - c * c);
        if (!(root2 > 0.0)) return false;
        float root = sqrt(root2);
        float cos_t = -root;
        float dct_dc = -eta_ti * eta_ti * c / root;
        float dct_deta = eta_ti * (1.0 - c * c) / root;
        wo = eta_ti * d + (cos_t + eta_ti * c) * h;
        float k = dct_dc + eta_ti;
        t_d = eta_ti * mat3(1.0) - k * outerProduct(h, h);
        mat3 r_h = (cos_t + eta_ti * c) * mat3(1.0) - k * outerProduct(h, d);
        t_nn = r_h * hn;
        t_alpha = r_h * h_alpha;
        t_eta = (d + (dct_deta + c) * h) * deta_ti;
        choice = 1.0 - f;
        dlnp_df = -1.0 / (1.0 - f);
    } else {
        wo = d + 2.0 * c * h;
        t_d = mat3(1.0) - 2.0 * outerProduct(h, h);
        t_nn = 2.0 * outerProduct(h, dc_dn) + 2.0 * c * hn;
        t_alpha = 2.0 * dc_dalpha * h + 2.0 * c * h_alpha;
        choice = f;
        dlnp_df = 1.0 / f;
    }
    float co = dot(wo, ns);
    if (!(choice > 0.0) || !(co != 0.0) || (co < 0.0) != transmitted) return false;
    vec4 masking = attached_ln_masking(beckmann, alpha, ci, co);
    float gi_c = masking.y;
    float go_c = masking.z;
    float g_alpha = masking.w;
    float hz = hl.z;
    float radiance = transmitted ? eta_ti * eta_ti : 1.0;
    l.wo = wo;
    l.transmitted = transmitted;
    l.weight = exp(masking.x) * c / (ci * hz) * radiance;
    l.t_d = t_d;
    l.t_n = t_nn;
    l.t_alpha = t_alpha;
    l.t_eta = t_eta;
    // cos θi = −d·n′; cos θo = wo·n′ (∂n′/∂n = s).
    vec3 ci_d = -ns;
    vec3 ci_n = -s * d;
    vec3 co_d = transpose(t_d) * ns;
    vec3 co_n = transpose(t_nn) * ns + s * wo;
    float co_alpha = dot(ns, t_alpha);
    float co_eta = dot(ns, t_eta);
    l.dlnw_dd = dc_dd / c + gi_c * ci_d + go_c * co_d - ci_d / ci + dlnp_df * df_dc * dc_dd;
    l.dlnw_dn = dc_dn / c + gi_c * ci_n + go_c * co_n - ci_n / ci + dlnp_df * df_dc * dc_dn;
    l.dlnw_dalpha = dc_dalpha / c + go_c * co_alpha + g_alpha - dhl_z / hz + dlnp_df * df_dc * dc_dalpha;
    float dradiance = transmitted ? 2.0 * deta_ti / eta_ti : 0.0;
    l.dlnw_deta = go_c * co_eta + dlnp_df * fr.z + dradiance;
    // |∂h/∂wo|: 1/(4c) reflected; η_rel²·|wo·h|/(c + η_rel·wo·h)² refracted (η_rel = 1/η_ti).
    float jacobian = 1.0 / (4.0 * c);
    if (transmitted) {
        float eta_rel = 1.0 / eta_ti;
        float om = dot(wo, h);
        float den = c + eta_rel * om;
        jacobian = eta_rel * eta_rel * abs(om) / (den * den);
    }
    l.pdf = microfacet_d(beckmann ? DIST_BECKMANN : DIST_GGX, alpha, hl) * hz * choice * jacobian;
    return true;
}

// The row over the incoming ray of a quantity with derivatives by_d (direction) and by_n (normal).
Row6 hit_row(HitGeometry g, vec3 by_d, vec3 by_n) {
    vec3 w = transpose(hit_projection(g)) * (transpose(g.dn_dx) * by_n);
    return Row6(w, by_d + g.t * w);
}

// The row over the ray reaching the hit of a quantity whose gradient along the surface is g
// (HitGeometry::position_row).
Row6 hit_position_row(HitGeometry geometry, vec3 g) {
    vec3 w = transpose(hit_projection(geometry)) * g;
    return Row6(w, geometry.t * w);
}

// At an emitter's hit: the row of ln p_e, NEE's solid-angle density of the hit point
// (HitGeometry::emitter_density_row).
Row6 hit_emitter_density_row(HitGeometry g) {
    float dn = dot(g.d, g.ng);
    return Row6(g.ng * (-2.0 / (g.t * dn)), g.ng * (-3.0 / dn));
}

// At an emitter's hit after a diffuse vertex that estimated next events: the row of ln w_b, its
// MIS weight, p_f fixed (HitGeometry::emitter_mis_row).
Row6 hit_emitter_mis_row(HitGeometry g, float w_b) {
    Row6 r = hit_emitter_density_row(g);
    return Row6(r.o * (-2.0 * (1.0 - w_b)), r.d * (-2.0 * (1.0 - w_b)));
}

// NEE at a diffuse vertex toward an area emitter's fixed point: the gradient by the hit point of
// ln(cos θo/p_e)·(2w − 1) (HitGeometry::nee_gradient).
// ∂ln cos θo/∂x toward a fixed point at distance 1/inv_dist (0: a fixed direction).
vec3 hit_ln_cos_gradient(HitGeometry g, vec3 wl, float inv_dist) {
    float cos_o = dot(g.n, wl);
    return (-(g.n - cos_o * wl) * inv_dist + transpose(g.dn_dx) * wl) / cos_o;
}

vec3 hit_nee_gradient(HitGeometry g, vec3 wl, float dist, vec3 light_normal, float w) {
    float cos_y = -dot(light_normal, wl);
    vec3 dln_p_e = -2.0 * wl / dist - (light_normal + cos_y * wl) / (dist * cos_y);
    return (2.0 * w - 1.0) * (hit_ln_cos_gradient(g, wl, 1.0 / dist) - dln_p_e);
}

// NEE toward a point light (inv_dist = 1/dist) or a directional one (0): the gradient of
// ln(cos θo/dist²) (HitGeometry::delta_light_gradient).
vec3 hit_delta_light_gradient(HitGeometry g, vec3 wl, float inv_dist) {
    return hit_ln_cos_gradient(g, wl, inv_dist) + 2.0 * inv_dist * wl;
}

// ---- texture slopes along the surface (twin: src/cpu/slope.rs) ----
struct SurfaceGradients { vec3 b1; vec3 b2; vec3 u; vec3 v; };

// ∇b1, ∇b2, ∇u, ∇v along the triangle `hit` lies on (surface_gradients).
SurfaceGradients surface_gradients(Hit hit) {
    HitTriangle h = hit_triangle(hit);
    SurfaceGradients g;
    barycentric_gradients(h.tri.v0, h.tri.v1, h.tri.v2, g.b1, g.b2);
    g.u = vec3(0.0);
    g.v = vec3(0.0);
    if (h.mesh.uv_base != NO_ARRAY) {
        Vec2Array uvs = Vec2Array(globals.addr_uvs);
        vec2 uv0 = uvs.v[h.mesh.uv_base + h.index.x];
        vec2 d0 = uvs.v[h.mesh.uv_base + h.index.y] - uv0;
        vec2 d1 = uvs.v[h.mesh.uv_base + h.index.z] - uv0;
        g.u = d0.x * g.b1 + d1.x * g.b2;
        g.v = d0.y * g.b1 + d1.y * g.b2;
    }
    return g;
}

// ∂w_k/∂t of texture_footprint's weights (footprint_slopes): bilinear, zero for nearest texels and
// the checkerboard.
void footprint_slopes(uint width, uint height, uint mode, vec2 t, out vec2 slope[4]) {
    slope = vec2[4](vec2(0.0), vec2(0.0), vec2(0.0), vec2(0.0));
    if ((mode & (TEX_CHECKER | TEX_NEAREST)) != 0u) return;
    float w = float(width);
    float h = float(height);
    float x = t.x * w - 0.5;
    float y = t.y * h - 0.5;
    float fx = x - floor(x);
    float fy = y - floor(y);
    slope[0] = vec2(-(1.0 - fy) * w, -(1.0 - fx) * h);
    slope[1] = vec2((1.0 - fy) * w, -fx * h);
    slope[2] = vec2(-fy * w, (1.0 - fx) * h);
    slope[3] = vec2(fy * w, fx * h);
}

// The weights' gradients along the surface of a bitmap read through to_uv rows row0, row1.
void bitmap_weight_gradients(uint width, uint height, uint mode, vec3 row0, vec3 row1, vec2 at_uv,
                             SurfaceGradients g, out vec3 dw[4]) {
    vec3 p = vec3(at_uv, 1.0);
    vec2 t = vec2(dot(row0, p), dot(row1, p));
    vec3 dt0 = row0.x * g.u + row0.y * g.v;
    vec3 dt1 = row1.x * g.u + row1.y * g.v;
    vec2 slope[4];
    footprint_slopes(width, height, mode, t, slope);
    for (int k = 0; k < 4; k++) dw[k] = slope[k].x * dt0 + slope[k].y * dt1;
}

// Σ_k texel_k ⊗ ∇w_k: column c is ∂value_c/∂x.
mat3 slope_rows(uint texel[4], vec3 dw[4]) {
    mat3 r = mat3(0.0);
    for (int k = 0; k < 4; k++) {
        if (dw[k] == vec3(0.0)) continue;
        vec3 c = param_rgb(texel[k]);
        r[0] += c.x * dw[k];
        r[1] += c.y * dw[k];
        r[2] += c.z * dw[k];
    }
    return r;
}

// ∂albedo_c/∂x (column c) of a textured diffuse material read at `at` (albedo_slope).
mat3 albedo_slope(Material m, TexAt at, SurfaceGradients g) {
    uint texel[4];
    float weight[4];
    material_footprint(m, at, texel, weight);
    vec3 dw[4];
    if ((m.tex_mode & TEX_ATTR_VERTEX) != 0u) {
        dw = vec3[4](-g.b1 - g.b2, g.b1, g.b2, vec3(0.0));
    } else {
        bitmap_weight_gradients(m.tex_width, m.tex_height, m.tex_mode, m.uv_row0, m.uv_row1, at.uv, g, dw);
    }
    return slope_rows(texel, dw);
}

// ∂L_c/∂x (column c) of textured area radiance p read at uv (area_radiance_slope).
mat3 area_radiance_slope(uint p, vec2 uv, SurfaceGradients g) {
    uint d = p & ~SCALAR_TEXTURE;
    uint texel[4];
    float weight[4];
    area_footprint(p, uv, texel, weight);
    vec3 row0 = vec3(coating_table(d + 4u), coating_table(d + 5u), coating_table(d + 6u));
    vec3 row1 = vec3(coating_table(d + 7u), coating_table(d + 8u), coating_table(d + 9u));
    vec3 dw[4];
    bitmap_weight_gradients(texture_desc_word(d, 1u), texture_desc_word(d, 2u), texture_desc_word(d, 3u), row0, row1,
                            uv, g, dw);
    return slope_rows(texel, dw);
}

// ∂texture_c/∂x (column c) of a textured spot l read toward the shading point x, and in `value`
// the texture there: through the lookup uv = 0.5 + uv_scale ⊙ (lx, ly)/lz of the light's local
// point, then the bilinear weights (light_texture_slope in src/cpu/slope.rs).
mat3 light_texture_slope(DeltaLight l, vec3 x, out vec3 value) {
    float factor;
    vec2 uv = light_lookup(l, x, factor);
    vec3 d = x - l.position;
    vec3 local = vec3(dot(l.row0, d), dot(l.row1, d), dot(l.row2, d));
    vec3 du = l.uv_scale.x * (l.row0 - (local.x / local.z) * l.row2) / local.z;
    vec3 dv = l.uv_scale.y * (l.row1 - (local.y / local.z) * l.row2) / local.z;
    uint texel[4];
    float weight[4];
    texture_footprint(l.tex, l.tex_width, l.tex_height, l.tex_mode, uv, texel, weight);
    vec2 slope[4];
    footprint_slopes(l.tex_width, l.tex_height, l.tex_mode, uv, slope);
    vec3 dw[4];
    for (int k = 0; k < 4; k++) dw[k] = slope[k].x * du + slope[k].y * dv;
    value = light_texture(l, uv);
    return slope_rows(texel, dw);
}

#endif
