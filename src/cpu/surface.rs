//! Surface interactions and material resolution (twin of `shaders/lib/surface.glsl`).

use glam::Vec3;

use crate::bsdf::plastic::SmoothPlasticLeaf;
use crate::bsdf::principled::PrincipledLeaf;
use crate::bsdf::principled_thin::PrincipledThinLeaf;
use crate::bsdf::rough_dielectric::RoughDielectricLeaf;
use crate::bsdf::rough_plastic::PlasticLeaf;
use crate::bsdf::specular::{SmoothKind, SmoothLeaf};
use crate::bsdf::{Bsdf, Distribution, Leaf, LeafGrad, bsdf_sample_grad};
use crate::bvh::Hit;
use crate::contract::ALPHA_TEXTURE_FLOOR;
use crate::contract::{
    COATING_TABLE_LEN, MAT_BLEND, MAT_CONDUCTOR, MAT_DIELECTRIC, MAT_PLASTIC, MAT_PRINCIPLED, MAT_PRINCIPLED_THIN,
    MAT_ROUGH_CONDUCTOR, MAT_ROUGH_DIELECTRIC, MAT_ROUGH_PLASTIC, MAT_THIN_DIELECTRIC, Material, NMAP_BUMP, NO_ARRAY,
    NO_EMITTER, NO_PARAM, SCALAR_TEXTURE, TEX_ATTR_FACE, TEX_ATTR_VERTEX, TEX_CHECKER, TEX_NEAREST, TEX_VOLUME,
    TEX_WRAP_CLAMP, TEX_WRAP_MIRROR, TEXTURE_DESC_LEN,
};
use crate::cpu::path::GradSink;
use crate::gpu::variant::{colour_textured, colour_volume};
use crate::scene::flat::FlatScene;

pub use crate::contract::{RAY_OFFSET, SHADOW_EPSILON};

/// A hit resolved to position, normals, material and emitter.
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    /// Position (from barycentrics).
    pub p: Vec3,
    /// Geometric (winding) normal.
    pub ng: Vec3,
    /// Interpolated shading normal.
    pub ns: Vec3,
    /// Interpolated texture coordinates.
    pub uv: glam::Vec2,
    /// Material index.
    pub material: u32,
    /// Emitter index or `NO_EMITTER`.
    pub emitter: u32,
    /// ∂p/∂u of the triangle from its texture coordinates (0 where they are degenerate).
    pub dpdu: Vec3,
    /// ∂p/∂v of the triangle from its texture coordinates (0 where they are degenerate).
    pub dpdv: Vec3,
    /// The hit's barycentric coordinates (b1, b2).
    pub bary: glam::Vec2,
    /// The hit triangle's index in [`FlatScene::tri_vertices`].
    pub tri: u32,
}

/// Where a material's textures are read: the hit's texture coordinates, for a mesh attribute its
/// triangle (index in [`FlatScene::tri_vertices`]) and barycentric coordinates (b1, b2), and for
/// a `volume` texture the world-space point (twin: `TexAt` of shaders/lib/surface.glsl).
#[derive(Clone, Copy, Debug)]
pub struct TexAt {
    /// Texture coordinates.
    pub uv: glam::Vec2,
    /// Barycentric coordinates (b1, b2) in the triangle.
    pub bary: glam::Vec2,
    /// The triangle.
    pub tri: u32,
    /// The world-space point.
    pub p: Vec3,
}

impl Surface {
    /// Where this hit's material reads its textures.
    pub fn tex_at(&self) -> TexAt {
        TexAt { uv: self.uv, bary: self.bary, tri: self.tri, p: self.p }
    }
}

/// Resolves `hit`: the mesh's vertex normals (its face normal where it has none) and texture
/// coordinates (0 where it has none) interpolated, its material, its triangle's emitter.
pub fn surface_at(flat: &FlatScene, hit: &Hit) -> Surface {
    let tri = &flat.bvh.tris[hit.slot as usize];
    let id = flat.bvh.prim_ids[hit.slot as usize];
    let tv = &flat.tri_vertices[id as usize];
    let m = &flat.meshes[tv.mesh as usize];
    let vertices = [tv.i0, tv.i1, tv.i2];
    let [n0, n1, n2] = if m.normal_base == NO_ARRAY {
        [(tri.v1 - tri.v0).cross(tri.v2 - tri.v0).normalize_or_zero(); 3]
    } else {
        vertices.map(|i| flat.normals[(m.normal_base + i) as usize])
    };
    let [uv0, uv1, uv2] = if m.uv_base == NO_ARRAY {
        [glam::Vec2::ZERO; 3]
    } else {
        vertices.map(|i| flat.uvs[(m.uv_base + i) as usize])
    };
    let emitter = if m.emitter_base == NO_ARRAY {
        NO_EMITTER
    } else {
        flat.emitter_ids[(m.emitter_base + id - m.first_tri) as usize]
    };
    let b0 = 1.0 - hit.b1 - hit.b2;
    let p = b0 * tri.v0 + hit.b1 * tri.v1 + hit.b2 * tri.v2;
    let ng = (tri.v1 - tri.v0).cross(tri.v2 - tri.v0).normalize();
    let n = b0 * n0 + hit.b1 * n1 + hit.b2 * n2;
    let ns = if n.dot(n) > 0.0 { n.normalize() } else { ng };
    let uv = b0 * uv0 + hit.b1 * uv1 + hit.b2 * uv2;
    let (d0, d1) = (uv1 - uv0, uv2 - uv0);
    let det = d0.x * d1.y - d0.y * d1.x;
    let (e0, e1) = (tri.v1 - tri.v0, tri.v2 - tri.v0);
    let dpdu = if det != 0.0 { (d1.y * e0 - d0.y * e1) / det } else { Vec3::ZERO };
    let dpdv = if det != 0.0 { (d0.x * e1 - d1.x * e0) / det } else { Vec3::ZERO };
    Surface { p, ng, ns, uv, material: m.material, emitter, dpdu, dpdv, bary: glam::Vec2::new(hit.b1, hit.b2), tri: id }
}

/// ∂n/∂x of the unflipped shading normal of [`surface_at`] along the hit's triangle: zero for a
/// flat-shaded mesh (attached derivatives, [`crate::attached::normal_derivative`]).
pub fn shading_normal_gradient(flat: &FlatScene, hit: &Hit) -> glam::Mat3 {
    let tri = &flat.bvh.tris[hit.slot as usize];
    let id = flat.bvh.prim_ids[hit.slot as usize];
    let tv = &flat.tri_vertices[id as usize];
    let m = &flat.meshes[tv.mesh as usize];
    if m.normal_base == NO_ARRAY {
        return glam::Mat3::ZERO;
    }
    let normals = [tv.i0, tv.i1, tv.i2].map(|i| flat.normals[(m.normal_base + i) as usize]);
    let b0 = 1.0 - hit.b1 - hit.b2;
    let raw = b0 * normals[0] + hit.b1 * normals[1] + hit.b2 * normals[2];
    crate::attached::normal_derivative([tri.v0, tri.v1, tri.v2], normals, raw)
}

/// Whether material `id` is (or blends) an anisotropic rough conductor or dielectric, or is
/// principled, thin or not (whose `anisotropic` is a parameter), whose shading frame must follow
/// the surface ([`tangent_frame`]).
pub fn material_anisotropic(flat: &FlatScene, id: u32) -> bool {
    let anisotropic = |m: &Material| {
        (matches!(m.tag, MAT_ROUGH_CONDUCTOR | MAT_ROUGH_DIELECTRIC) && m.p_alpha_v != m.p_alpha)
            || m.tag == MAT_PRINCIPLED
            || m.tag == MAT_PRINCIPLED_THIN
    };
    let m = &flat.materials[id as usize];
    if m.tag == MAT_BLEND {
        anisotropic(&flat.materials[m.child0 as usize]) || anisotropic(&flat.materials[m.child1 as usize])
    } else {
        anisotropic(m)
    }
}

/// Mitsuba's shading frame for anisotropic BSDFs: x along ∂p/∂u made orthogonal to the shading
/// normal `ns` (where the texture coordinates are degenerate, the first axis of the geometric
/// normal's coordinate system, as Mitsuba's meshes without them), y = ns × x.
pub fn tangent_frame(ns: Vec3, ng: Vec3, dpdu: Vec3) -> crate::sampling::Frame {
    let u = if dpdu == Vec3::ZERO { crate::sampling::Frame::from_normal(ng).t } else { dpdu };
    let s = (u - ns * ns.dot(u)).normalize_or_zero();
    if s == Vec3::ZERO {
        return crate::sampling::Frame::from_normal(ns);
    }
    crate::sampling::Frame { t: s, b: ns.cross(s), n: ns }
}

/// Whether material `id` carries a normal map (its frame is [`normal_map_frame`]'s).
pub fn material_normal_mapped(flat: &FlatScene, id: u32) -> bool {
    flat.materials[id as usize].nmap_width > 0
}

/// The height's gradient (∂h/∂u, ∂h/∂v) of bump map `m` at `uv`, times its `scale` (Mitsuba's
/// bitmap `eval_1_grad`: the bilinear interpolant's derivative; 0 for a nearest lookup). The
/// heights are one value a texel at `m.nmap`.
fn bump_gradient(flat: &FlatScene, m: &Material, uv: glam::Vec2) -> glam::Vec2 {
    if m.nmap_mode & TEX_NEAREST != 0 {
        return glam::Vec2::ZERO;
    }
    let (texel, _) = texture_footprint(m.nmap, m.nmap_width, m.nmap_height, m.nmap_mode, uv);
    // The footprint's RGB offsets (3 per texel) as offsets of one height per texel.
    let h = texel.map(|t| flat.tables[(m.nmap + (t - m.nmap) / 3) as usize]);
    let x = uv.x * m.nmap_width as f32 - 0.5;
    let y = uv.y * m.nmap_height as f32 - 0.5;
    let (fx, fy) = (x - x.floor(), y - y.floor());
    let dx = (1.0 - fy) * (h[1] - h[0]) + fy * (h[3] - h[2]);
    let dy = (1.0 - fx) * (h[2] - h[0]) + fx * (h[3] - h[1]);
    glam::Vec2::new(dx * m.nmap_width as f32, dy * m.nmap_height as f32) * m.nmap_scale
}

/// The perturbed normal of a normal or bump map in the front-side frame of ∂p/∂u (Mitsuba's
/// coordinates, before `flip_invalid_normals`), unnormalised for a normal map: its RGB mapped to
/// [−1, 1]; for a bump map (Mitsuba's `bumpmap.cpp`) ∂p/∂u and ∂p/∂v moved along the front normal
/// `ns` to the height's gradient, their cross product turned to the side of `ng`. `front` is the
/// unperturbed frame seen from the front.
fn mapped_normal(flat: &FlatScene, m: &Material, s: &Surface, front: crate::sampling::Frame) -> Vec3 {
    if m.nmap_mode & NMAP_BUMP == 0 {
        let (texel, weight) = texture_footprint(m.nmap, m.nmap_width, m.nmap_height, m.nmap_mode, s.uv);
        let mut rgb = Vec3::ZERO;
        for (t, w) in texel.into_iter().zip(weight) {
            rgb += param_rgb(&flat.tables, t) * w;
        }
        return rgb * 2.0 - Vec3::ONE;
    }
    let g = bump_gradient(flat, m, s.uv);
    // Mitsuba falls back to ng's coordinate system where the texture coordinates are degenerate.
    let (dpdu, dpdv) = if s.dpdu == Vec3::ZERO {
        let f = crate::sampling::Frame::from_normal(s.ng);
        (f.t, f.b)
    } else {
        (s.dpdu, s.dpdv)
    };
    let ns = front.n;
    let du = dpdu + ns * (g.x - ns.dot(dpdu));
    let dv = dpdv + ns * (g.y - ns.dot(dpdv));
    let c = du.cross(dv);
    let n = if c.dot(c) > 0.0 { c.normalize() } else { Vec3::ZERO };
    let n = if s.ng.dot(n) < 0.0 { -n } else { n };
    front.to_local(n)
}

/// Mitsuba's `normalmap` and `bumpmap` frame (their `frame()`, 3.9.1) for material `m` at the
/// surface `s` (its `ns` seen from the front), from the unperturbed frame `base` (∂p/∂u's,
/// [`tangent_frame`] of the normal that faces wi; `mirrored` when a two-sided material is seen
/// from the back, whose frame is then (s, t, −n), as Mitsuba's `twosided` flips only the z
/// coordinate and leaves the map's normal in the front's coordinates) and the direction
/// `wi_world`: the map's normal n in that frame (`mapped_normal`), its x and y negated where it
/// faces away from wi (`flip_invalid_normals`), normalised; s = (1, 0, 0) made orthogonal to n,
/// t = n × s. Returns the perturbed frame in world space and the BSDF's wrapper.
///
/// Mitsuba's bump map takes s from the world-space ∂p/∂u made orthogonal to the local n (mixing
/// two frames): it differs from this s by a rotation about n, which only anisotropic BSDFs see, so
/// the loader refuses them inside a bump map. A map normal of 0 (not a direction) shades with the
/// unperturbed normal, and a horizontal n = (±1, 0, 0) takes s = z, where Mitsuba's
/// normalisations would give NaN.
pub fn normal_map_frame(
    flat: &FlatScene,
    m: &Material,
    s: &Surface,
    base: crate::sampling::Frame,
    mirrored: bool,
    wi_world: Vec3,
) -> (crate::sampling::Frame, crate::bsdf::Perturbed) {
    let base = if mirrored { crate::sampling::Frame { b: -base.b, ..base } } else { base };
    let front = if mirrored { crate::sampling::Frame { n: -base.n, ..base } } else { base };
    let mut n = mapped_normal(flat, m, s, front);
    let wi = base.to_local(wi_world);
    if wi.z * wi.dot(n) <= 0.0 {
        n = Vec3::new(-n.x, -n.y, n.z);
    }
    let n = if n == Vec3::ZERO { Vec3::Z } else { n.normalize() };
    let t_axis = Vec3::X - n * n.x;
    let t_axis = if t_axis == Vec3::ZERO { Vec3::Z } else { t_axis.normalize() };
    let b_axis = n.cross(t_axis);
    let frame = crate::sampling::Frame { t: base.to_world(t_axis), b: base.to_world(b_axis), n: base.to_world(n) };
    let nz2 = n.z * n.z;
    let alpha2 = (0.125 * ((1.0 - nz2).max(0.0) / nz2)).min(1.0);
    (frame, crate::bsdf::Perturbed { base_n: Vec3::new(t_axis.z, b_axis.z, n.z), alpha2 })
}

/// `p` moved off the surface to the side `dir` leaves to.
pub fn offset_origin(p: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
    let a = p.abs();
    let scale = RAY_OFFSET * 1f32.max(a.x.max(a.y).max(a.z));
    p + ng * if ng.dot(dir) > 0.0 { scale } else { -scale }
}

fn param_rgb(params: &[f32], offset: u32) -> Vec3 {
    let o = offset as usize;
    Vec3::new(params[o], params[o + 1], params[o + 2])
}

/// Texel index `i` of a row or column of `n` texels under wrap mode `mode` (Mitsuba's `repeat`,
/// `mirror`, `clamp`).
fn wrap_texel(i: i32, n: i32, mode: u32) -> i32 {
    use crate::scene::Wrap;
    let wrap = if mode & TEX_WRAP_CLAMP != 0 {
        Wrap::Clamp
    } else if mode & TEX_WRAP_MIRROR != 0 {
        Wrap::Mirror
    } else {
        Wrap::Repeat
    };
    wrap.index(i, n)
}

/// The four texels a lookup at `uv` reads (row 0 is v = 0): their parameter offsets (RGB at
/// `offset..offset + 2`) and weights — bilinear, or the nearest texel with weight 1
/// (`TEX_NEAREST`), indices wrapped by `mode`; or the checkerboard's texel with weight 1
/// (`TEX_CHECKER`). Shared by the lookup and its gradient.
pub fn texture_footprint(offset: u32, width: u32, height: u32, mode: u32, uv: glam::Vec2) -> ([u32; 4], [f32; 4]) {
    if mode & TEX_CHECKER != 0 {
        let upper = (uv - uv.floor()).cmpgt(glam::Vec2::splat(0.5));
        let t = offset + if upper.x == upper.y { 0 } else { 3 };
        return ([t; 4], [1.0, 0.0, 0.0, 0.0]);
    }
    let x = uv.x * width as f32 - 0.5;
    let y = uv.y * height as f32 - 0.5;
    let nearest = mode & TEX_NEAREST != 0;
    let (x0, y0) = if nearest { ((x + 0.5).floor(), (y + 0.5).floor()) } else { (x.floor(), y.floor()) };
    let (fx, fy) = if nearest { (0.0, 0.0) } else { (x - x0, y - y0) };
    let (w, h) = (width as i32, height as i32);
    let ix0 = wrap_texel(x0 as i32, w, mode);
    let iy0 = wrap_texel(y0 as i32, h, mode);
    let (ix1, iy1) = (wrap_texel(x0 as i32 + 1, w, mode), wrap_texel(y0 as i32 + 1, h, mode));
    let texel = |ix: i32, iy: i32| offset + 3 * (iy * w + ix) as u32;
    (
        [texel(ix0, iy0), texel(ix1, iy0), texel(ix0, iy1), texel(ix1, iy1)],
        [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy],
    )
}

/// The rows a mesh attribute (`TEX_ATTR_FACE` or `TEX_ATTR_VERTEX` in `mode`) reads at `at`: the
/// hit triangle's row with weight 1, or its three vertices' rows weighted by the barycentric
/// coordinates (Mitsuba's `interpolate_attribute`); rows of `dim` values from `offset`. Shared by
/// the lookup and its gradient (twin of the GLSL's).
pub fn attribute_footprint(flat: &FlatScene, offset: u32, dim: u32, mode: u32, at: TexAt) -> ([u32; 4], [f32; 4]) {
    let tv = &flat.tri_vertices[at.tri as usize];
    if mode & TEX_ATTR_FACE != 0 {
        let t = offset + dim * (at.tri - flat.meshes[tv.mesh as usize].first_tri);
        return ([t; 4], [1.0, 0.0, 0.0, 0.0]);
    }
    (
        [offset + dim * tv.i0, offset + dim * tv.i1, offset + dim * tv.i2, offset],
        [1.0 - at.bary.x - at.bary.y, at.bary.x, at.bary.y, 0.0],
    )
}

/// Whether a texture mode is a mesh attribute's.
fn attribute_mode(mode: u32) -> bool {
    mode & (TEX_ATTR_FACE | TEX_ATTR_VERTEX) != 0
}

/// The texels (or mesh attribute rows) a textured material's colour reads at `at`.
pub fn material_footprint(flat: &FlatScene, m: &Material, at: TexAt) -> ([u32; 4], [f32; 4]) {
    if attribute_mode(m.tex_mode) {
        attribute_footprint(flat, m.p_color, 3, m.tex_mode, at)
    } else {
        texture_footprint(m.p_color, m.tex_width, m.tex_height, m.tex_mode, texture_uv(m, at.uv))
    }
}

/// A textured material's texture coordinates: the hit's `uv` through its `to_uv` rows.
pub fn texture_uv(m: &Material, uv: glam::Vec2) -> glam::Vec2 {
    let p = Vec3::new(uv.x, uv.y, 1.0);
    glam::Vec2::new(m.uv_row0.dot(p), m.uv_row1.dot(p))
}

/// Whether a textured material's colour is Mitsuba's `volume` texture: a field (`p_color` is its
/// index in [`FlatScene::fields`]) looked up at the world-space point.
fn volume_textured(m: &Material) -> bool {
    m.tex_mode & TEX_VOLUME != 0
}

/// A textured material's colour at `at`.
pub fn texture_lookup(flat: &FlatScene, m: &Material, at: TexAt) -> Vec3 {
    if volume_textured(m) {
        return crate::cpu::medium::field_rgb(flat, &flat.fields[m.p_color as usize], at.p);
    }
    let params = &flat.params[..];
    let (texel, weight) = material_footprint(flat, m, at);
    param_rgb(params, texel[0]) * weight[0]
        + param_rgb(params, texel[1]) * weight[1]
        + param_rgb(params, texel[2]) * weight[2]
        + param_rgb(params, texel[3]) * weight[3]
}

/// The texels (RGB at each offset) and weights of the lookup of colour texture `slot` (a smooth
/// BSDF's or rough dielectric's colour with `SCALAR_TEXTURE` set: its descriptor in the tables)
/// at `at`: its texture coordinates through its `to_uv`, or its mesh attribute's rows (twin:
/// `colour_footprint` of shaders/lib/surface.glsl).
pub fn colour_footprint(flat: &FlatScene, slot: u32, at: TexAt) -> ([u32; 4], [f32; 4]) {
    let d = (slot & !SCALAR_TEXTURE) as usize;
    let desc = &flat.tables[d..d + TEXTURE_DESC_LEN as usize];
    let mode = desc[3].to_bits();
    if attribute_mode(mode) {
        return attribute_footprint(flat, desc[0].to_bits(), 3, mode, at);
    }
    let p = Vec3::new(at.uv.x, at.uv.y, 1.0);
    let t = glam::Vec2::new(Vec3::new(desc[4], desc[5], desc[6]).dot(p), Vec3::new(desc[7], desc[8], desc[9]).dot(p));
    texture_footprint(desc[0].to_bits(), desc[1].to_bits(), desc[2].to_bits(), mode, t)
}

/// A smooth BSDF's or rough dielectric's colour slot at `at`: its RGB parameter, its texture's
/// lookup, or (`NO_PARAM`) `constant`.
fn colour_value(flat: &FlatScene, slot: u32, at: TexAt, constant: Vec3) -> Vec3 {
    if slot == NO_PARAM {
        return constant;
    }
    if !colour_textured(slot) {
        return param_rgb(&flat.params, slot);
    }
    if let Some(f) = colour_volume(flat, slot) {
        return crate::cpu::medium::field_rgb(flat, &flat.fields[f as usize], at.p);
    }
    let (texel, weight) = colour_footprint(flat, slot, at);
    texel.into_iter().zip(weight).map(|(t, w)| param_rgb(&flat.params, t) * w).sum()
}

/// Adds `g` (per image channel) times the derivative of colour slot `slot` at `at` to `sink`: its
/// RGB parameter's, its texels' weighted as the lookup weighs them, nothing for a constant (twin:
/// `push_colour` of shaders/lib/surface.glsl).
fn colour_backward(flat: &FlatScene, slot: u32, at: TexAt, g: Vec3, sink: &mut GradSink<'_>) {
    if slot == NO_PARAM {
        return;
    }
    if !colour_textured(slot) {
        sink.add_rgb(slot, g);
        return;
    }
    if let Some(f) = colour_volume(flat, slot) {
        crate::cpu::medium::field_grad(&flat.fields[f as usize], at.p, g, sink);
        return;
    }
    let (texel, weight) = colour_footprint(flat, slot, at);
    for (t, w) in texel.into_iter().zip(weight) {
        if w != 0.0 {
            sink.add_rgb(t, g * w);
        }
    }
}

/// Whether a scalar slot (roughness, blend weight) holds a texture (`SCALAR_TEXTURE`).
fn scalar_textured(slot: u32) -> bool {
    slot != NO_PARAM && slot & SCALAR_TEXTURE != 0
}

/// The texels' parameter offsets and weights of the lookup of scalar texture `slot` at `at`: at
/// its texture coordinates (its `to_uv` applied; one value a texel), or its mesh attribute's rows
/// (twin of the GLSL's).
pub fn scalar_footprint(flat: &FlatScene, slot: u32, at: TexAt) -> ([u32; 4], [f32; 4]) {
    let d = (slot & !SCALAR_TEXTURE) as usize;
    let desc = &flat.tables[d..d + TEXTURE_DESC_LEN as usize];
    let mode = desc[3].to_bits();
    if attribute_mode(mode) {
        return attribute_footprint(flat, desc[0].to_bits(), 1, mode, at);
    }
    let p = Vec3::new(at.uv.x, at.uv.y, 1.0);
    let t = glam::Vec2::new(Vec3::new(desc[4], desc[5], desc[6]).dot(p), Vec3::new(desc[7], desc[8], desc[9]).dot(p));
    let (texel, weight) = texture_footprint(0, desc[1].to_bits(), desc[2].to_bits(), mode, t);
    // texture_footprint's offsets step 3 a texel (RGB); these texels hold one value.
    (texel.map(|k| desc[0].to_bits() + k / 3), weight)
}

/// The value of scalar texture `slot` at `at`.
fn scalar_lookup(flat: &FlatScene, slot: u32, at: TexAt) -> f32 {
    let (texel, weight) = scalar_footprint(flat, slot, at);
    flat.params[texel[0] as usize] * weight[0]
        + flat.params[texel[1] as usize] * weight[1]
        + flat.params[texel[2] as usize] * weight[2]
        + flat.params[texel[3] as usize] * weight[3]
}

/// A blend weight: its parameter, or its texture at `at`.
fn scalar_value(flat: &FlatScene, slot: u32, at: TexAt) -> f32 {
    if scalar_textured(slot) { scalar_lookup(flat, slot, at) } else { flat.params[slot as usize] }
}

/// A roughness: its parameter, or its texture at `at` clamped to [`ALPHA_TEXTURE_FLOOR`] as
/// Mitsuba's microfacet distribution clamps it.
fn alpha_value(flat: &FlatScene, slot: u32, at: TexAt) -> f32 {
    if scalar_textured(slot) {
        scalar_lookup(flat, slot, at).max(ALPHA_TEXTURE_FLOOR)
    } else {
        flat.params[slot as usize]
    }
}

/// A scalar slot's derivative `g` (per image channel): its parameter's, or for a texture the
/// footprint's texels weighted as the lookup weighs them; a roughness clamped to
/// [`ALPHA_TEXTURE_FLOOR`] has none (twin: `push_scalar` of `shaders/lib/surface.glsl`).
fn scalar_backward(flat: &FlatScene, slot: u32, at: TexAt, g: Vec3, roughness: bool, sink: &mut GradSink<'_>) {
    if !scalar_textured(slot) {
        sink.add(slot, g);
        return;
    }
    let (texel, weight) = scalar_footprint(flat, slot, at);
    if roughness && scalar_lookup(flat, slot, at) < ALPHA_TEXTURE_FLOOR {
        return;
    }
    for (t, w) in texel.into_iter().zip(weight) {
        if w != 0.0 {
            sink.add(t, g * w);
        }
    }
}

/// A mask's opacity at `at`: its parameter or texture, clipped to [0, 1] as Mitsuba clips it
/// (twin: `mask_opacity_at` of shaders/lib/surface.glsl).
pub fn mask_opacity_at(flat: &FlatScene, slot: u32, at: TexAt) -> f32 {
    scalar_value(flat, slot, at).clamp(0.0, 1.0)
}

/// Adds `g` (per image channel) times the derivative of a mask's opacity at `at` to `sink`.
pub fn opacity_backward(flat: &FlatScene, slot: u32, at: TexAt, g: Vec3, sink: &mut GradSink<'_>) {
    scalar_backward(flat, slot, at, g, false, sink);
}

fn leaf_from_material(flat: &FlatScene, m: &Material, at: TexAt) -> Leaf {
    let params = &flat.params[..];
    let color = if m.tex_width > 0 {
        texture_lookup(flat, m, at)
    } else if m.p_color == NO_PARAM || colour_textured(m.p_color) {
        Vec3::ZERO // a smooth leaf's or rough dielectric's colour: read below
    } else {
        param_rgb(params, m.p_color)
    };
    let distribution =
        if m.distribution == Distribution::Ggx as u32 { Distribution::Ggx } else { Distribution::Beckmann };
    match m.tag {
        MAT_ROUGH_CONDUCTOR => Leaf::RoughConductor {
            distribution,
            alpha: alpha_value(flat, m.p_alpha, at),
            alpha_v: alpha_value(flat, m.p_alpha_v, at),
            specular: color,
            eta: conductor_ior(flat, m).0,
            k: conductor_ior(flat, m).1,
        },
        MAT_ROUGH_PLASTIC => {
            let t = m.table as usize;
            let mut table = [0.0; COATING_TABLE_LEN as usize];
            table.copy_from_slice(&flat.tables[t..t + COATING_TABLE_LEN as usize]);
            Leaf::RoughPlastic(PlasticLeaf {
                distribution,
                alpha: params[m.p_alpha as usize],
                diffuse: color,
                specular: colour_value(flat, m.p_weight, at, m.k),
                eta: m.eta.x,
                specular_weight: m.eta.y,
                nonlinear: m.eta.z != 0.0,
                table,
            })
        }
        MAT_ROUGH_DIELECTRIC => Leaf::RoughDielectric(RoughDielectricLeaf {
            distribution,
            alpha: alpha_value(flat, m.p_alpha, at),
            alpha_v: alpha_value(flat, m.p_alpha_v, at),
            reflectance: colour_value(flat, m.p_color, at, m.uv_row0),
            transmittance: colour_value(flat, m.p_weight, at, m.k),
            // η: its parameter (`table`) or the constant.
            eta: if m.table != NO_PARAM { params[m.table as usize] } else { m.eta.x },
        }),
        MAT_PRINCIPLED => {
            let s = |i: u32| scalar_value(flat, principled_slot(flat, m, i), at);
            Leaf::Principled(PrincipledLeaf {
                base_color: color,
                // Mitsuba floors α = roughness², not the texture's roughness.
                roughness: scalar_value(flat, m.p_alpha, at),
                anisotropic: scalar_value(flat, m.p_alpha_v, at),
                metallic: s(0),
                spec_tint: s(1),
                spec_trans: s(2),
                sheen: s(3),
                sheen_tint: s(4),
                clearcoat: s(5),
                clearcoat_gloss: s(6),
                flatness: s(7),
                eta: m.eta.x,
                rates: m.k,
            })
        }
        MAT_PRINCIPLED_THIN => {
            // The record's words as MAT_PRINCIPLED_THIN lays them out (word 6 repeats eta's).
            let s = |i: u32| scalar_value(flat, principled_slot(flat, m, i), at);
            Leaf::PrincipledThin(PrincipledThinLeaf {
                base_color: color,
                roughness: scalar_value(flat, m.p_alpha, at),
                anisotropic: scalar_value(flat, m.p_alpha_v, at),
                diff_trans: s(0),
                spec_tint: s(1),
                spec_trans: s(2),
                sheen: s(3),
                sheen_tint: s(4),
                eta: s(5),
                flatness: s(7),
                rates: [m.k.x, m.k.y, m.k.z, m.eta.x],
            })
        }
        MAT_PLASTIC => Leaf::SmoothPlastic(SmoothPlasticLeaf {
            diffuse: color,
            specular: colour_value(flat, m.p_weight, at, m.k),
            eta: m.eta.x,
            specular_weight: m.eta.y,
            nonlinear: m.eta.z != 0.0,
        }),
        MAT_CONDUCTOR | MAT_DIELECTRIC | MAT_THIN_DIELECTRIC => Leaf::Smooth(SmoothLeaf {
            kind: match m.tag {
                MAT_CONDUCTOR => SmoothKind::Conductor,
                MAT_DIELECTRIC => SmoothKind::Dielectric,
                _ => SmoothKind::ThinDielectric,
            },
            reflectance: colour_value(flat, m.p_color, at, m.uv_row0),
            transmittance: match m.tag {
                MAT_CONDUCTOR => Vec3::ZERO,
                _ => colour_value(flat, m.p_alpha, at, m.k),
            },
            // A dielectric's η: its parameter (p_weight) or the constant; a conductor's eta and k.
            eta: if m.tag != MAT_CONDUCTOR && m.p_weight != NO_PARAM {
                Vec3::new(params[m.p_weight as usize], 0.0, 0.0)
            } else {
                conductor_ior(flat, m).0
            },
            k: conductor_ior(flat, m).1,
        }),
        _ => Leaf::Diffuse { albedo: color },
    }
}

/// A conductor's (eta, k): its parameters (eta's at `p_weight`, k's the three values after it) or
/// the constants (twin: `leaf_from_material` of `shaders/lib/surface.glsl`); the constants for
/// another material.
fn conductor_ior(flat: &FlatScene, m: &Material) -> (Vec3, Vec3) {
    if matches!(m.tag, MAT_CONDUCTOR | MAT_ROUGH_CONDUCTOR) && m.p_weight != NO_PARAM {
        (param_rgb(&flat.params, m.p_weight), param_rgb(&flat.params, m.p_weight + 3))
    } else {
        (m.eta, m.k)
    }
}

/// The BSDF of material `id` with the current parameter values at `at`.
pub fn resolve_bsdf(flat: &FlatScene, id: u32, at: TexAt) -> Bsdf {
    let m = &flat.materials[id as usize];
    if m.tag == MAT_BLEND {
        let a = leaf_from_material(flat, &flat.materials[m.child0 as usize], at);
        let b = leaf_from_material(flat, &flat.materials[m.child1 as usize], at);
        Bsdf { leaves: [a, b], weight: scalar_value(flat, m.p_weight, at), blend: true, perturbed: None }
    } else {
        let a = leaf_from_material(flat, m, at);
        Bsdf { leaves: [a, a], weight: 0.0, blend: false, perturbed: None }
    }
}

/// Scatters ∂/∂(texels) of a lookup: per-channel gradient `g` split by the footprint's weights
/// (a nearest or checkerboard lookup reads one texel: nothing is added for the rest).
pub fn texture_backward(flat: &FlatScene, m: &Material, at: TexAt, g: Vec3, sink: &mut GradSink<'_>) {
    if volume_textured(m) {
        crate::cpu::medium::field_grad(&flat.fields[m.p_color as usize], at.p, g, sink);
        return;
    }
    let (texel, weight) = material_footprint(flat, m, at);
    for (t, w) in texel.into_iter().zip(weight) {
        if w != 0.0 {
            sink.add_rgb(t, g * w);
        }
    }
}

fn leaf_backward(flat: &FlatScene, m: &Material, at: TexAt, g: &LeafGrad, sink: &mut GradSink<'_>) {
    if m.tag == MAT_PRINCIPLED || m.tag == MAT_PRINCIPLED_THIN {
        // A thin leaf's derivatives sit in the fields of its record's words (by_record_slot).
        principled_backward(flat, m, at, &g.principled, sink);
        return;
    }
    if is_smooth_tag(m.tag) || m.tag == MAT_ROUGH_DIELECTRIC {
        // A dielectric's reflectance and transmittance (a smooth leaf's transmittance parameter
        // sits in p_alpha, a rough one's in p_weight); a constant has no parameter.
        let p_trans = if m.tag == MAT_ROUGH_DIELECTRIC { m.p_weight } else { m.p_alpha };
        colour_backward(flat, m.p_color, at, g.color, sink);
        if m.tag != MAT_CONDUCTOR {
            colour_backward(flat, p_trans, at, g.trans, sink);
        }
        conductor_ior_backward(m, g, sink);
        if m.tag == MAT_ROUGH_DIELECTRIC && m.p_alpha_v != m.p_alpha {
            scalar_backward(flat, m.p_alpha, at, g.alpha, true, sink);
            scalar_backward(flat, m.p_alpha_v, at, g.alpha_v, true, sink);
        } else if m.tag == MAT_ROUGH_DIELECTRIC {
            // Isotropic: α_u and α_v are one parameter.
            scalar_backward(flat, m.p_alpha, at, g.alpha + g.alpha_v, true, sink);
        }
        return;
    }
    if m.tex_width > 0 {
        texture_backward(flat, m, at, g.color, sink);
    } else {
        sink.add_rgb(m.p_color, g.color);
    }
    if m.tag == MAT_ROUGH_PLASTIC || m.tag == MAT_PLASTIC {
        // The coating's specular colour (a parameter, a texture or a constant in p_weight).
        colour_backward(flat, m.p_weight, at, g.trans, sink);
    }
    conductor_ior_backward(m, g, sink);
    if m.tag == MAT_ROUGH_CONDUCTOR && m.p_alpha_v != m.p_alpha {
        scalar_backward(flat, m.p_alpha, at, g.alpha, true, sink);
        scalar_backward(flat, m.p_alpha_v, at, g.alpha_v, true, sink);
    } else if m.tag == MAT_ROUGH_CONDUCTOR || m.tag == MAT_ROUGH_PLASTIC {
        // Isotropic: α_u and α_v are one parameter.
        scalar_backward(flat, m.p_alpha, at, g.alpha + g.alpha_v, true, sink);
    }
}

/// A conductor's eta and k derivatives (`LeafGrad::eta`, `LeafGrad::k`) to their parameters, where
/// they are parameters (twin: `push_leaf` of `shaders/lib/surface.glsl`).
fn conductor_ior_backward(m: &Material, g: &LeafGrad, sink: &mut GradSink<'_>) {
    if matches!(m.tag, MAT_CONDUCTOR | MAT_ROUGH_CONDUCTOR) && m.p_weight != NO_PARAM {
        sink.add_rgb(m.p_weight, g.eta);
        sink.add_rgb(m.p_weight + 3, g.k);
    }
}

/// A principled leaf's derivatives `g` (adj-weighted, per image channel) to its parameters: base
/// colour channel k (a texel's, weighted by the lookup) reaches every image channel, the roughness
/// and every scalar may be a texture, the eight scalars' slots are `Material::table`'s record (twin: `push_principled` of
/// `shaders/lib/surface.glsl`).
fn principled_backward(
    flat: &FlatScene,
    m: &Material,
    at: TexAt,
    g: &crate::bsdf::principled::PrincipledGrad,
    sink: &mut GradSink<'_>,
) {
    if m.tex_width > 0 {
        let (texel, weight) = material_footprint(flat, m, at);
        for (t, w) in texel.into_iter().zip(weight) {
            if w != 0.0 {
                for (k, gk) in g.base_color.iter().enumerate() {
                    sink.add(t + k as u32, *gk * w);
                }
            }
        }
    } else {
        for (k, gk) in g.base_color.iter().enumerate() {
            sink.add(m.p_color + k as u32, *gk);
        }
    }
    scalar_backward(flat, m.p_alpha, at, g.roughness, false, sink);
    scalar_backward(flat, m.p_alpha_v, at, g.anisotropic, false, sink);
    for (i, gi) in g.scalars().into_iter().enumerate() {
        scalar_backward(flat, principled_slot(flat, m, i as u32), at, gi, false, sink);
    }
}

/// Scalar slot `i` (`PRINCIPLED_SCALARS`) of principled material `m`: word `i` of its record.
fn principled_slot(flat: &FlatScene, m: &Material, i: u32) -> u32 {
    flat.tables[(m.table + i) as usize].to_bits()
}

/// Whether material tag `tag` is a smooth (delta) BSDF's.
fn is_smooth_tag(tag: u32) -> bool {
    matches!(tag, MAT_CONDUCTOR | MAT_DIELECTRIC | MAT_THIN_DIELECTRIC)
}

/// GRAD(f̂(wi, wo), adj), or of a delta sample's value where `delta`
/// ([`crate::bsdf::bsdf_sample_grad`]): the BSDF's parameters at this surface point.
#[allow(clippy::too_many_arguments, reason = "the twin of the GLSL function, argument for argument")]
pub fn bsdf_backward(
    flat: &FlatScene,
    material: u32,
    at: TexAt,
    bsdf: &Bsdf,
    wi: Vec3,
    wo: Vec3,
    delta: bool,
    adj: Vec3,
    sink: &mut GradSink<'_>,
) {
    let g = bsdf_sample_grad(bsdf, wi, wo, delta, adj);
    let m = &flat.materials[material as usize];
    if m.tag == MAT_BLEND {
        leaf_backward(flat, &flat.materials[m.child0 as usize], at, &g.leaves[0], sink);
        leaf_backward(flat, &flat.materials[m.child1 as usize], at, &g.leaves[1], sink);
        scalar_backward(flat, m.p_weight, at, g.weight, false, sink);
    } else {
        leaf_backward(flat, m, at, &g.leaves[0], sink);
    }
}

/// [`bsdf_backward`] of a sampled (non-delta) direction without the roughness's derivatives: a
/// rough conductor under attached sampling, whose lobe differentiates its roughness itself
/// (`crate::attached::RoughLobe`).
#[allow(clippy::too_many_arguments)]
pub fn bsdf_backward_but_alpha(
    flat: &FlatScene,
    material: u32,
    at: TexAt,
    bsdf: &Bsdf,
    wi: Vec3,
    wo: Vec3,
    adj: Vec3,
    sink: &mut GradSink<'_>,
) {
    let mut g = bsdf_sample_grad(bsdf, wi, wo, false, adj);
    g.leaves[0].alpha = Vec3::ZERO;
    g.leaves[0].alpha_v = Vec3::ZERO;
    leaf_backward(flat, &flat.materials[material as usize], at, &g.leaves[0], sink);
}

/// Per-channel a / b with 0 where b is 0 (ALGORITHMS.md §3.3: 1/f̂ replaced by 0 when f̂ = 0).
pub fn safe_div(a: Vec3, b: Vec3) -> Vec3 {
    let d = |x: f32, y: f32| if y != 0.0 { x / y } else { 0.0 };
    Vec3::new(d(a.x, b.x), d(a.y, b.y), d(a.z, b.z))
}

/// Power heuristic a²/(a² + b²), safe for huge densities.
pub fn mis_power(a: f32, b: f32) -> f32 {
    if a <= 0.0 {
        return 0.0;
    }
    let r = b / a;
    1.0 / (1.0 + r * r)
}

/// RGB parameter at `offset`.
pub fn param_color(flat: &FlatScene, offset: u32) -> Vec3 {
    param_rgb(&flat.params, offset)
}
