//! How a texture read varies along the surface it is read on: the derivatives by the hit point of
//! a diffuse albedo, of an area emitter's radiance and of what a textured spot sends there, for
//! attached sampling (twin: the `*_slope` functions of `shaders/lib/attached.glsl`).
//!
//! A hit point moves only along its triangle's plane (`crate::attached`), so each derivative is a
//! vector in that plane: through the barycentric coordinates for a mesh attribute, through the
//! texture coordinates and the bilinear weights for a bitmap. Reads that are piecewise constant
//! (nearest texels, the checkerboard, a face attribute) have slope 0 between their jumps and a
//! jump where they change; attached sampling refuses them
//! ([`crate::attached::refuse_unsupported`]) rather than miss the jumps.

use glam::{Vec2, Vec3};

use crate::attached::barycentric_gradients;
use crate::bvh::Hit;
use crate::contract::{
    DeltaLight, Material, NO_ARRAY, SCALAR_TEXTURE, TEX_ATTR_VERTEX, TEX_CHECKER, TEX_NEAREST, TEXTURE_DESC_LEN,
};
use crate::cpu::surface::{TexAt, material_footprint, param_color, texture_footprint};
use crate::scene::flat::FlatScene;

/// The gradients along a hit triangle's plane of its barycentric coordinates b1, b2 and of its
/// texture coordinates u, v.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfaceGradients {
    /// ∇b1.
    pub b1: Vec3,
    /// ∇b2.
    pub b2: Vec3,
    /// ∇u (zero on a mesh without texture coordinates).
    pub u: Vec3,
    /// ∇v.
    pub v: Vec3,
}

/// [`SurfaceGradients`] of the triangle `hit` lies on.
pub fn surface_gradients(flat: &FlatScene, hit: &Hit) -> SurfaceGradients {
    let tri = &flat.bvh.tris[hit.slot as usize];
    let id = flat.bvh.prim_ids[hit.slot as usize];
    let tv = &flat.tri_vertices[id as usize];
    let m = &flat.meshes[tv.mesh as usize];
    let (b1, b2) = barycentric_gradients([tri.v0, tri.v1, tri.v2]);
    if m.uv_base == NO_ARRAY {
        return SurfaceGradients { b1, b2, ..Default::default() };
    }
    let [uv0, uv1, uv2] = [tv.i0, tv.i1, tv.i2].map(|i| flat.uvs[(m.uv_base + i) as usize]);
    let (d0, d1) = (uv1 - uv0, uv2 - uv0);
    SurfaceGradients { b1, b2, u: d0.x * b1 + d1.x * b2, v: d0.y * b1 + d1.y * b2 }
}

/// ∂w_k/∂t of the four weights [`crate::cpu::surface::texture_footprint`] gives at texture
/// coordinates `t` of a `width` × `height` texture: the bilinear weights' slopes, zero for
/// nearest texels and the checkerboard.
pub fn footprint_slopes(width: u32, height: u32, mode: u32, t: Vec2) -> [Vec2; 4] {
    if mode & (TEX_CHECKER | TEX_NEAREST) != 0 {
        return [Vec2::ZERO; 4];
    }
    let (w, h) = (width as f32, height as f32);
    let (x, y) = (t.x * w - 0.5, t.y * h - 0.5);
    let (fx, fy) = (x - x.floor(), y - y.floor());
    [
        Vec2::new(-(1.0 - fy) * w, -(1.0 - fx) * h),
        Vec2::new((1.0 - fy) * w, -fx * h),
        Vec2::new(-fy * w, (1.0 - fx) * h),
        Vec2::new(fy * w, fx * h),
    ]
}

/// Σ_k texel_k ⊗ ∇w_k: the rows ∂value_c/∂x, one per channel, of an RGB read with weight
/// gradients `dw`.
fn rows(flat: &FlatScene, texel: [u32; 4], dw: [Vec3; 4]) -> [Vec3; 3] {
    let mut out = [Vec3::ZERO; 3];
    for (t, g) in texel.into_iter().zip(dw) {
        if g != Vec3::ZERO {
            let c = param_color(flat, t);
            for (ch, row) in out.iter_mut().enumerate() {
                *row += c[ch] * g;
            }
        }
    }
    out
}

/// The weights' gradients along the surface of a bitmap read at texture coordinates `t =
/// (row0·(u, v, 1), row1·(u, v, 1))`.
fn bitmap_weight_gradients(
    width: u32,
    height: u32,
    mode: u32,
    rows_uv: [Vec3; 2],
    at_uv: Vec2,
    g: &SurfaceGradients,
) -> [Vec3; 4] {
    let p = Vec3::new(at_uv.x, at_uv.y, 1.0);
    let t = Vec2::new(rows_uv[0].dot(p), rows_uv[1].dot(p));
    let dt = [rows_uv[0].x * g.u + rows_uv[0].y * g.v, rows_uv[1].x * g.u + rows_uv[1].y * g.v];
    footprint_slopes(width, height, mode, t).map(|s| s.x * dt[0] + s.y * dt[1])
}

/// ∂albedo_c/∂x along the surface of a textured diffuse material `m` read at `at` (a bitmap
/// through its `to_uv`, or a per-vertex attribute through the barycentric coordinates).
pub fn albedo_slope(flat: &FlatScene, m: &Material, at: TexAt, g: &SurfaceGradients) -> [Vec3; 3] {
    let (texel, _) = material_footprint(flat, m, at);
    let dw = if m.tex_mode & TEX_ATTR_VERTEX != 0 {
        [-g.b1 - g.b2, g.b1, g.b2, Vec3::ZERO]
    } else {
        bitmap_weight_gradients(m.tex_width, m.tex_height, m.tex_mode, [m.uv_row0, m.uv_row1], at.uv, g)
    };
    rows(flat, texel, dw)
}

/// ∂L_c/∂x along the surface of textured area radiance `p` (`SCALAR_TEXTURE` set: its
/// descriptor in the tables) read at texture coordinates `uv`.
pub fn area_radiance_slope(flat: &FlatScene, p: u32, uv: Vec2, g: &SurfaceGradients) -> [Vec3; 3] {
    let d = (p & !SCALAR_TEXTURE) as usize;
    let desc = &flat.tables[d..d + TEXTURE_DESC_LEN as usize];
    let (texel, _) = crate::cpu::emitter::area_footprint(flat, p, uv);
    let rows_uv = [Vec3::new(desc[4], desc[5], desc[6]), Vec3::new(desc[7], desc[8], desc[9])];
    let dw = bitmap_weight_gradients(desc[1].to_bits(), desc[2].to_bits(), desc[3].to_bits(), rows_uv, uv, g);
    rows(flat, texel, dw)
}

/// ∂texture_c/∂x (one row per channel) and the texture's value, of a textured spot `l` read
/// toward the shading point `x`. The lookup is uv = 0.5 + uv_scale ⊙ (lx, ly)/lz of the light's
/// local point (lx, ly, lz) = rows · (x − position), so ∂u/∂x = uv_scale.x·(row0 − (lx/lz)·row2)/lz
/// (and v through row1), then the bilinear weights' slopes.
pub fn light_texture_slope(flat: &FlatScene, l: &DeltaLight, x: Vec3) -> ([Vec3; 3], Vec3) {
    let (uv, _) = crate::cpu::emitter::light_lookup(l, x);
    let d = x - l.position;
    let local = Vec3::new(l.row0.dot(d), l.row1.dot(d), l.row2.dot(d));
    let du = l.uv_scale.x * (l.row0 - (local.x / local.z) * l.row2) / local.z;
    let dv = l.uv_scale.y * (l.row1 - (local.y / local.z) * l.row2) / local.z;
    let (texel, _) = texture_footprint(l.tex, l.tex_width, l.tex_height, l.tex_mode, uv);
    let dw = footprint_slopes(l.tex_width, l.tex_height, l.tex_mode, uv).map(|s| s.x * du + s.y * dv);
    (rows(flat, texel, dw), crate::cpu::emitter::texture_value(flat, l, uv))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::{Ray, closest_hit};
    use crate::cpu::emitter::area_radiance;
    use crate::cpu::surface::{surface_at, texture_lookup};

    /// The slopes against central differences of the lookups themselves, at the floor points
    /// hit by rays moved by δ in world space: a bilinear bitmap albedo and a bilinear bitmap
    /// radiance, each with its `to_uv`, on the textured floor of `attached_slab_table.xml`.
    #[test]
    fn slopes_match_the_lookups() {
        let path = format!("{}/tests/data/scenes/attached_slab_table.xml", env!("CARGO_MANIFEST_DIR"));
        let scene = crate::scene::load(&path, &[]).unwrap();
        let flat = FlatScene::new(&scene).unwrap();
        let mut checked = 0;
        // The floor's hit of a ray straight down from (x, 5, z), through the slab (its hits skipped).
        let floor_hit = |x: f32, z: f32| {
            let mut ray = Ray::new(Vec3::new(x, 5.0, z), Vec3::NEG_Y);
            loop {
                let hit = closest_hit(&flat.bvh, &ray, 0.0, f32::MAX).unwrap();
                if surface_at(&flat, &hit).emitter != crate::contract::NO_EMITTER {
                    break hit;
                }
                ray = Ray::new(ray.origin + (hit.t + 1e-3) * ray.dir, ray.dir);
            }
        };
        for (x, z) in [(0.03f32, 0.07f32), (-0.21, 0.13), (0.17, -0.26), (0.4, 0.31)] {
            let hit = floor_hit(x, z);
            let s = surface_at(&flat, &hit);
            let m = &flat.materials[s.material as usize];
            let p_radiance = flat.emitters[s.emitter as usize].p_radiance;
            let g = surface_gradients(&flat, &hit);
            let albedo = albedo_slope(&flat, m, s.tex_at(), &g);
            let radiance = area_radiance_slope(&flat, p_radiance, s.uv, &g);
            // The lookups at the floor point moved by δ in world space (a vertical ray moved by δ).
            let moved = |delta: Vec3| {
                let s = surface_at(&flat, &floor_hit(x + delta.x, z + delta.z));
                (texture_lookup(&flat, m, s.tex_at()), area_radiance(&flat, p_radiance, s.uv))
            };
            let h = 1e-3;
            for delta in [Vec3::X, Vec3::Z] {
                let (a_plus, l_plus) = moved(h * delta);
                let (a_minus, l_minus) = moved(-h * delta);
                for c in 0..3 {
                    let (fa, fl) = ((a_plus[c] - a_minus[c]) / (2.0 * h), (l_plus[c] - l_minus[c]) / (2.0 * h));
                    assert!(
                        (fa - albedo[c].dot(delta)).abs() < 2e-2 * (1.0 + fa.abs()),
                        "albedo {c}: {fa} vs {}",
                        albedo[c]
                    );
                    assert!(
                        (fl - radiance[c].dot(delta)).abs() < 2e-2 * (1.0 + fl.abs()),
                        "radiance {c}: {fl} vs {}",
                        radiance[c]
                    );
                }
            }
            assert!(albedo[0].length() > 0.1 && radiance[0].length() > 0.1, "the floor's ramps have slopes");
            checked += 1;
        }
        assert_eq!(checked, 4);
    }
}
