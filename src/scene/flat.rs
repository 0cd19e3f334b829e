//! `FlatScene`: the scene flattened into the arrays that the kernels read — and that the CPU
//! reference reads too, so both back ends see the same data by construction.

use glam::Vec3;

use crate::bvh::{self, Bvh};
use crate::contract::{
    EmitterTri, MAT_BLEND, MAT_DIFFUSE, MAT_ROUGH_CONDUCTOR, Material as GpuMaterial, NO_EMITTER, TriShading,
};
use crate::error::Result;
use crate::scene::shapes::triangle_area;
use crate::scene::{Albedo, Material, Scene};

/// The GPU-layout arrays of one scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FlatScene {
    /// BVH nodes and leaf-ordered triangles.
    pub bvh: Bvh,
    /// Shading data by original triangle id.
    pub shading: Vec<TriShading>,
    /// Materials.
    pub materials: Vec<GpuMaterial>,
    /// Emissive triangles with their cumulative area distribution.
    pub emitters: Vec<EmitterTri>,
    /// Total emissive area.
    pub emitter_total_area: f32,
    /// Parameter values.
    pub params: Vec<f32>,
}

/// Gives `scene` and its flattened twin `flat` the values of `params`, which must have the scene
/// table's layout (what both backends' `set_params` do before the GPU uploads).
///
/// # Errors
/// [`crate::Error::InvalidArgument`] if the layout differs.
pub(crate) fn replace_params(
    scene: &mut Scene,
    flat: &mut FlatScene,
    params: &crate::params::ParamTable,
) -> Result<()> {
    if params.entries() != scene.params.entries() {
        return Err(crate::Error::InvalidArgument {
            parameter: "params".into(),
            message: "the table's layout differs from the scene's".into(),
        });
    }
    scene.params = params.clone();
    flat.params = params.values().to_vec();
    Ok(())
}

impl FlatScene {
    /// Flattens and validates `scene` and builds its BVH.
    ///
    /// # Errors
    /// [`crate::Error::Scene`] from validation or the BVH build.
    pub fn new(scene: &Scene) -> Result<FlatScene> {
        scene.validate()?;
        refuse_media(scene)?;
        let mut triangles = Vec::with_capacity(scene.triangle_count());
        let mut shading = Vec::with_capacity(scene.triangle_count());
        let mut emitters = Vec::new();
        for mesh in &scene.meshes {
            for t in &mesh.indices {
                let p = t.map(|i| mesh.positions[i as usize]);
                let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
                let n = match &mesh.normals {
                    Some(normals) => t.map(|i| normals[i as usize]),
                    None => [face; 3],
                };
                let uv = match &mesh.uvs {
                    Some(uvs) => t.map(|i| uvs[i as usize]),
                    None => [glam::Vec2::ZERO; 3],
                };
                let id = triangles.len() as u32;
                let area = triangle_area(p[0], p[1], p[2]);
                let emitter = match mesh.emitter {
                    Some(radiance) if area > 0.0 => {
                        emitters.push(EmitterTri {
                            tri: id,
                            p_radiance: scene.params.entry(radiance).offset,
                            cdf: 0.0,
                            area,
                            v0: p[0],
                            v1: p[1],
                            v2: p[2],
                        });
                        emitters.len() as u32 - 1
                    }
                    _ => NO_EMITTER,
                };
                triangles.push(p);
                shading.push(TriShading {
                    n0: n[0],
                    n1: n[1],
                    n2: n[2],
                    uv0: uv[0],
                    uv1: uv[1],
                    uv2: uv[2],
                    material: mesh.material.0,
                    emitter,
                });
            }
        }
        let total: f64 = emitters.iter().map(|e| f64::from(e.area)).sum();
        let mut running = 0.0f64;
        for e in &mut emitters {
            running += f64::from(e.area);
            e.cdf = (running / total) as f32;
        }
        if let Some(last) = emitters.last_mut() {
            last.cdf = 1.0;
        }
        let materials = scene.materials.iter().map(|m| flatten_material(scene, m)).collect();
        let bvh = bvh::build(&triangles)?;
        Ok(FlatScene {
            bvh,
            shading,
            materials,
            emitters,
            emitter_total_area: total as f32,
            params: scene.params.values().to_vec(),
        })
    }

    /// The geometric (winding) normal of the triangle in leaf slot `slot`, unit length.
    pub fn face_normal(&self, slot: u32) -> Vec3 {
        let t = &self.bvh.tris[slot as usize];
        (t.v1 - t.v0).cross(t.v2 - t.v0).normalize()
    }
}

fn flatten_material(scene: &Scene, m: &Material) -> GpuMaterial {
    let offset = |id| scene.params.entry(id).offset;
    match *m {
        Material::Diffuse { albedo: Albedo::Rgb(albedo) } => {
            GpuMaterial { tag: MAT_DIFFUSE, p_color: offset(albedo), ..Default::default() }
        }
        Material::Diffuse { albedo: Albedo::Bitmap(t) } => {
            let t = &scene.textures[t.0 as usize];
            GpuMaterial {
                tag: MAT_DIFFUSE,
                p_color: offset(t.texels),
                tex_width: t.width,
                tex_height: t.height,
                ..Default::default()
            }
        }
        Material::TwoSided(child) => {
            GpuMaterial { two_sided: 1, ..flatten_material(scene, &scene.materials[child.0 as usize]) }
        }
        Material::RoughConductor { distribution, alpha, specular, eta, k } => GpuMaterial {
            tag: MAT_ROUGH_CONDUCTOR,
            distribution: distribution as u32,
            p_color: offset(specular),
            p_alpha: offset(alpha),
            eta,
            k,
            ..Default::default()
        },
        Material::Blend { weight, children } => GpuMaterial {
            tag: MAT_BLEND,
            child0: children[0].0,
            child1: children[1].0,
            p_weight: offset(weight),
            ..Default::default()
        },
        // Refused by `refuse_media` before anything is flattened.
        Material::Null => GpuMaterial::default(),
    }
}

/// The renderers do not trace participating media yet: a scene with a medium or a `null`
/// boundary loads (its parameters are listed) but is refused here, naming what it holds.
fn refuse_media(scene: &Scene) -> Result<()> {
    let what = match (
        scene.media.first(),
        scene.meshes.iter().find(|m| matches!(scene.materials[m.material.0 as usize], Material::Null)),
    ) {
        (Some(medium), _) => format!("the medium '{}'", medium.name),
        (None, Some(mesh)) => format!("the null-BSDF shape '{}'", mesh.name),
        (None, None) => return Ok(()),
    };
    Err(crate::Error::Scene {
        location: scene.source.clone(),
        message: format!("{what}: participating media are loaded (`pathgrad params` lists them) but not rendered yet"),
    })
}
