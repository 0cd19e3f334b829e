//! `FlatScene`: the scene flattened into the arrays that the kernels read — and that the CPU
//! reference reads too, so both back ends see the same data by construction.

use std::time::Instant;

use glam::{Vec2, Vec3};

use crate::bsdf::Distribution;
use crate::bsdf::rough_plastic::CoatingTable;
use crate::bsdf::specular::SmoothKind;
use crate::bvh::{self, Bvh};
use crate::contract::{
    COATING_TABLE_LEN, DIST_GGX, DeltaLight, EmitterTri, EnvCell, FIELD_CONSTANT, FIELD_GRID, FIELD_GRID_MIRROR,
    FIELD_GRID_REPEAT, FieldDesc, LIGHT_DIRECTIONAL, LIGHT_POINT, LIGHT_PROJECTOR, LIGHT_SPOT, MAT_BLEND,
    MAT_CONDUCTOR, MAT_DIELECTRIC, MAT_DIFFUSE, MAT_NULL, MAT_PLASTIC, MAT_PRINCIPLED, MAT_PRINCIPLED_THIN,
    MAT_ROUGH_CONDUCTOR, MAT_ROUGH_DIELECTRIC, MAT_ROUGH_PLASTIC, MAT_THIN_DIELECTRIC, Material as GpuMaterial,
    MediumDesc, MeshShading, NMAP_BUMP, NO_ARRAY, NO_EMITTER, NO_MEDIUM, NO_PARAM, PHASE_HG, PHASE_ISOTROPIC,
    SCALAR_TEXTURE, TEX_ATTR_FACE, TEX_ATTR_VERTEX, TEX_CHECKER, TEX_NEAREST, TEX_VOLUME, TEX_WRAP_CLAMP,
    TEX_WRAP_MIRROR, TEXTURE_DESC_LEN, TriVertices,
};
use crate::error::Result;
use crate::params::ParamId;
use crate::phases::PhaseReport;
use crate::scene::medium::{Field, Phase};
use crate::scene::shapes::triangle_area;
use crate::scene::{Albedo, Light, LightShape, Material, Scene, SmoothColour, Wrap};

/// The GPU-layout arrays of one scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FlatScene {
    /// BVH nodes and leaf-ordered triangles (the triangles empty from
    /// [`FlatScene::for_device_reporting`]).
    pub bvh: Bvh,
    /// Each triangle's vertex indices and mesh, by original triangle id (16 bytes a triangle;
    /// empty from [`FlatScene::for_device_reporting`], whose upload makes them from the scene).
    pub tri_vertices: Vec<TriVertices>,
    /// The meshes' shading records (material, medium, where their per-vertex data starts), one
    /// a mesh of the scene.
    pub meshes: Vec<MeshShading>,
    /// The vertex normals of the meshes that have them, mesh after mesh (12 bytes a vertex;
    /// empty from [`FlatScene::for_device_reporting`]).
    pub normals: Vec<Vec3>,
    /// The texture coordinates of the meshes that have them, mesh after mesh (8 bytes a vertex;
    /// empty from [`FlatScene::for_device_reporting`]).
    pub uvs: Vec<Vec2>,
    /// The emitter index (or `NO_EMITTER`) of every triangle of the emissive meshes
    /// (`MeshShading::emitter_base`).
    pub emitter_ids: Vec<u32>,
    /// Materials.
    pub materials: Vec<GpuMaterial>,
    /// Emissive triangles with their cumulative area distribution.
    pub emitters: Vec<EmitterTri>,
    /// Total emissive area.
    pub emitter_total_area: f32,
    /// Parameter values.
    pub params: Vec<f32>,
    /// Participating media, in the scene's order.
    pub media: Vec<MediumDesc>,
    /// Their extinction and albedo fields.
    pub fields: Vec<FieldDesc>,
    /// The media's majorant grids (`MediumDesc::grid`), one after another; they follow the
    /// densities.
    pub majorants: Vec<f32>,
    /// The environment map's sampling cells (`crate::scene::envmap`); empty without a map.
    pub env_cells: Vec<EnvCell>,
    /// Lights without area, in the scene's order.
    pub lights: Vec<DeltaLight>,
    /// The rough plastics' coating tables (`Material::table`), which follow the roughness, then
    /// the normal maps' texels (`Material::nmap`).
    pub tables: Vec<f32>,
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
    // A rough plastic's coating table follows its roughness: rebuilt only when some α moved.
    let alpha_moved = flat
        .materials
        .iter()
        .any(|m| m.tag == MAT_ROUGH_PLASTIC && flat.params[m.p_alpha as usize] != params.values()[m.p_alpha as usize]);
    scene.params = params.clone();
    flat.params = params.values().to_vec();
    // The majorants follow the densities (ALGORITHMS.md §8: recomputed when parameters change),
    // and an environment map's sampling cells follow its texels.
    for (desc, medium) in flat.media.iter_mut().zip(&scene.media) {
        desc.majorant = medium.majorant(&scene.params);
        if let Some(grid) = medium.majorant_grid(&scene.params) {
            flat.majorants[desc.grid as usize..][..grid.values.len()].copy_from_slice(&grid.values);
        }
    }
    flat.env_cells = env_cells(scene)?;
    if alpha_moved {
        // The coating tables lead the array and keep their layout; the normal maps after them
        // are constants.
        let coating = coating_tables(&mut flat.materials, &flat.params);
        flat.tables[..coating.len()].copy_from_slice(&coating);
    }
    Ok(())
}

impl FlatScene {
    /// Flattens and validates `scene` and builds its BVH.
    ///
    /// # Errors
    /// [`crate::Error::Scene`] from validation or the BVH build.
    pub fn new(scene: &Scene) -> Result<FlatScene> {
        FlatScene::new_reporting(scene, &mut PhaseReport::new())
    }

    /// [`FlatScene::new`], recording three phases in `report`: `flatten` (validation and every
    /// array but the BVH's and the per-triangle and per-vertex shading data), `bvh` (the build)
    /// and `shading` (those: [`FlatScene::tri_vertices`], [`FlatScene::normals`],
    /// [`FlatScene::uvs`]).
    ///
    /// # Errors
    /// As [`FlatScene::new`]; what was recorded before the failure stays.
    pub fn new_reporting(scene: &Scene, report: &mut PhaseReport) -> Result<FlatScene> {
        FlatScene::build(scene, report, true)
    }

    /// [`FlatScene::new_reporting`] without the per-triangle and per-vertex shading data
    /// (`tri_vertices`, `normals` and `uvs` are empty) and its phase, and without the BVH's
    /// leaf-order positions (`bvh.tris` is empty; `bvh.prim_ids` says whose they are): what a
    /// renderer needs, since [`crate::gpu::Renderer::from_flat`] uploads them from the scene
    /// chunk by chunk, so that no host copy of them exists (issue 38). The CPU reference needs
    /// [`FlatScene::new_reporting`]'s.
    ///
    /// # Errors
    /// As [`FlatScene::new`]; what was recorded before the failure stays.
    pub fn for_device_reporting(scene: &Scene, report: &mut PhaseReport) -> Result<FlatScene> {
        FlatScene::build(scene, report, false)
    }

    fn build(scene: &Scene, report: &mut PhaseReport, with_shading: bool) -> Result<FlatScene> {
        let start = Instant::now();
        scene.validate()?;
        let mut emitters = Vec::new();
        let firsts = first_ids(scene);
        let mut id = 0u32;
        for mesh in &scene.meshes {
            for t in &mesh.indices {
                let p = t.map(|i| mesh.positions[i as usize]);
                let area = triangle_area(p[0], p[1], p[2]);
                if let Some(radiance) = mesh.emitter
                    && area > 0.0
                {
                    emitters.push(EmitterTri {
                        tri: id,
                        p_radiance: scene.params.entry(radiance).offset,
                        cdf: 0.0,
                        area,
                        v0: p[0],
                        v1: p[1],
                        v2: p[2],
                    });
                }
                id += 1;
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
        let mut materials: Vec<GpuMaterial> = scene
            .materials
            .iter()
            .map(|m| GpuMaterial { p_opacity: mask_slot(scene, m), ..flatten_material(scene, m) })
            .collect();
        let mut tables = coating_tables(&mut materials, scene.params.values());
        normal_map_tables(scene, &mut materials, &mut tables);
        scalar_texture_tables(scene, &mut materials, &mut tables);
        colour_texture_tables(scene, &mut materials, &mut tables);
        area_texture_tables(scene, &mut emitters, &mut tables);
        let (media, fields, majorants) = flatten_media(scene);
        let env_cells = env_cells(scene)?;
        let lights = scene.lights.iter().map(|l| flatten_light(scene, l)).collect();
        report.record("flatten", start);
        let start = Instant::now();
        // Triangle `id`'s positions, read from its mesh: the BVH build needs no flattened copy.
        let triangle = |id: u32| triangle_positions(scene, &firsts, id);
        // Without shading data (a renderer's) the leaf-order positions are made by the upload
        // too, from the scene and `prim_ids` (`GpuScene::new`): never whole on the host.
        let bvh = if with_shading {
            bvh::build_from(id as usize, triangle)?
        } else {
            bvh::build_tree_from(id as usize, triangle)?
        };
        report.record("bvh", start);
        let (meshes, emitter_ids) = mesh_shading(scene, &emitters);
        // After the build, so that the BVH's intermediate forms and the shading data are never
        // alive together (issue 38).
        let (tri_vertices, normals, uvs) = if with_shading {
            let start = Instant::now();
            // Sized first: collecting a `flat_map` would grow the arrays by doubling.
            let mut tri_vertices = Vec::with_capacity(scene.triangle_count());
            tri_vertices.extend(tri_vertices_iter(scene));
            let mut normals = Vec::with_capacity(normal_count(scene));
            normals.extend(normals_iter(scene));
            let mut uvs = Vec::with_capacity(uv_count(scene));
            uvs.extend(uvs_iter(scene));
            report.record("shading", start);
            (tri_vertices, normals, uvs)
        } else {
            (Vec::new(), Vec::new(), Vec::new())
        };
        Ok(FlatScene {
            bvh,
            tri_vertices,
            meshes,
            normals,
            uvs,
            emitter_ids,
            materials,
            emitters,
            emitter_total_area: total as f32,
            params: scene.params.values().to_vec(),
            media,
            fields,
            majorants,
            env_cells,
            lights,
            tables,
        })
    }

    /// How many leading values of [`FlatScene::tables`] are coating tables (they follow the
    /// roughness); the normal maps' texels after them never change.
    pub fn coating_tables_len(&self) -> usize {
        self.materials.iter().filter(|m| m.tag == MAT_ROUGH_PLASTIC).count() * COATING_TABLE_LEN as usize
    }

    /// The shading record of the mesh of the triangle in leaf slot `slot`.
    pub fn mesh_of(&self, slot: u32) -> &MeshShading {
        let id = self.bvh.prim_ids[slot as usize];
        &self.meshes[self.tri_vertices[id as usize].mesh as usize]
    }

    /// The geometric (winding) normal of the triangle in leaf slot `slot`, unit length.
    pub fn face_normal(&self, slot: u32) -> Vec3 {
        let t = &self.bvh.tris[slot as usize];
        (t.v1 - t.v0).cross(t.v2 - t.v0).normalize()
    }
}

/// The meshes' shading records and the emissive meshes' per-triangle emitter indices
/// (`emitters` lists the emissive triangles in id order; a triangle of no area is not one of
/// them and gets `NO_EMITTER`). The per-vertex offsets count the vertices of the earlier meshes
/// that have normals (uvs): [`normals_iter`] and [`uvs_iter`] lay them out so.
pub(crate) fn mesh_shading(scene: &Scene, emitters: &[EmitterTri]) -> (Vec<MeshShading>, Vec<u32>) {
    let mut next_emitter = emitters.iter().map(|e| e.tri).enumerate().peekable();
    let (mut first_tri, mut normals, mut uvs) = (0u32, 0u32, 0u32);
    let mut emitter_ids = Vec::new();
    let meshes = scene
        .meshes
        .iter()
        .map(|mesh| {
            let record = MeshShading {
                material: mesh.material.0,
                interior: mesh.interior.map_or(NO_MEDIUM, |m| m.0),
                first_tri,
                normal_base: mesh.normals.as_ref().map_or(NO_ARRAY, |_| normals),
                uv_base: mesh.uvs.as_ref().map_or(NO_ARRAY, |_| uvs),
                emitter_base: mesh.emitter.map_or(NO_ARRAY, |_| emitter_ids.len() as u32),
            };
            if mesh.emitter.is_some() {
                for id in first_tri..first_tri + mesh.indices.len() as u32 {
                    emitter_ids.push(match next_emitter.next_if(|&(_, tri)| tri == id) {
                        Some((k, _)) => k as u32,
                        None => NO_EMITTER,
                    });
                }
            }
            first_tri += mesh.indices.len() as u32;
            normals += mesh.normals.as_ref().map_or(0, Vec::len) as u32;
            uvs += mesh.uvs.as_ref().map_or(0, Vec::len) as u32;
            record
        })
        .collect();
    (meshes, emitter_ids)
}

/// Every triangle's vertex indices (into its mesh's vertices) and mesh index, by original
/// triangle id. Both back ends' come from here: collected by the CPU reference, written chunk by
/// chunk into the upload by a renderer.
pub(crate) fn tri_vertices_iter(scene: &Scene) -> impl Iterator<Item = TriVertices> + '_ {
    scene
        .meshes
        .iter()
        .zip(0u32..)
        .flat_map(|(mesh, m)| mesh.indices.iter().map(move |t| TriVertices { i0: t[0], i1: t[1], i2: t[2], mesh: m }))
}

/// The first triangle id of every mesh: ids run through the meshes in order.
pub(crate) fn first_ids(scene: &Scene) -> Vec<u32> {
    let mut id = 0u32;
    scene
        .meshes
        .iter()
        .map(|mesh| {
            let first = id;
            id += mesh.indices.len() as u32;
            first
        })
        .collect()
}

/// Triangle `id`'s positions, read from its mesh (`firsts`: [`first_ids`]).
pub(crate) fn triangle_positions(scene: &Scene, firsts: &[u32], id: u32) -> [Vec3; 3] {
    // The last mesh starting at or before `id`: an empty mesh shares its start with the next, so
    // it is never the one found.
    let m = firsts.partition_point(|&first| first <= id) - 1;
    let mesh = &scene.meshes[m];
    mesh.indices[(id - firsts[m]) as usize].map(|i| mesh.positions[i as usize])
}

/// The vertex normals of the meshes that have them, mesh after mesh (`MeshShading::normal_base`).
pub(crate) fn normals_iter(scene: &Scene) -> impl Iterator<Item = Vec3> + '_ {
    scene.meshes.iter().filter_map(|m| m.normals.as_deref()).flatten().copied()
}

/// How many normals [`normals_iter`] gives.
pub(crate) fn normal_count(scene: &Scene) -> usize {
    scene.meshes.iter().filter_map(|m| m.normals.as_ref()).map(Vec::len).sum()
}

/// The texture coordinates of the meshes that have them, mesh after mesh (`MeshShading::uv_base`).
pub(crate) fn uvs_iter(scene: &Scene) -> impl Iterator<Item = Vec2> + '_ {
    scene.meshes.iter().filter_map(|m| m.uvs.as_deref()).flatten().copied()
}

/// How many coordinate pairs [`uvs_iter`] gives.
pub(crate) fn uv_count(scene: &Scene) -> usize {
    scene.meshes.iter().filter_map(|m| m.uvs.as_ref()).map(Vec::len).sum()
}

/// The kernels' form of a light without area.
fn flatten_light(scene: &Scene, light: &Light) -> DeltaLight {
    let p_intensity = light.intensity.map_or(NO_PARAM, |p| scene.params.entry(p).offset);
    let mut d = DeltaLight {
        kind: LIGHT_POINT,
        p_intensity,
        position: Vec3::ZERO,
        axis: Vec3::Z,
        cos_cutoff: -1.0,
        cos_beam: -1.0,
        cutoff: std::f32::consts::PI,
        inv_transition: 0.0,
        tex: NO_PARAM,
        tex_width: 0,
        tex_height: 0,
        tex_mode: 0,
        p_scale: NO_PARAM,
        uv_scale: Vec2::ZERO,
        row0: Vec3::X,
        row1: Vec3::Y,
        row2: Vec3::Z,
    };
    if let Some(t) = light.texture {
        let t = &scene.textures[t.0 as usize];
        d.tex = scene.params.entry(t.texels).offset;
        (d.tex_width, d.tex_height, d.tex_mode) = (t.width, t.height, texture_mode(t.nearest, t.wrap));
    }
    let rows = |m: glam::Mat3| {
        let t = m.transpose();
        (t.x_axis, t.y_axis, t.z_axis)
    };
    match light.shape {
        LightShape::Point { position } => d.position = position,
        LightShape::Spot { position, axis, cutoff, beam_width, to_local } => {
            // Mitsuba's spot: its radians, cosines and slope from the angles in degrees.
            let (cutoff, beam) = (cutoff.to_radians(), beam_width.to_radians());
            let (row0, row1, row2) = rows(to_local);
            d = DeltaLight {
                kind: LIGHT_SPOT,
                position,
                axis,
                cos_cutoff: cutoff.cos(),
                cos_beam: beam.cos(),
                cutoff,
                // Unused when the beam fills the cone (every lit direction is within the beam).
                inv_transition: if cutoff > beam { 1.0 / (cutoff - beam) } else { 0.0 },
                uv_scale: Vec2::splat(0.5 / cutoff.tan()),
                row0,
                row1,
                row2,
                ..d
            };
        }
        LightShape::Directional { direction } => d = DeltaLight { kind: LIGHT_DIRECTIONAL, axis: direction, ..d },
        LightShape::Projector { position, to_local, normal, uv_scale, scale } => {
            let (row0, row1, row2) = rows(to_local);
            d = DeltaLight {
                kind: LIGHT_PROJECTOR,
                position,
                axis: normal,
                p_scale: scene.params.entry(scale).offset,
                uv_scale,
                row0,
                row1,
                row2,
                ..d
            };
        }
    }
    d
}

/// Whether `light` needs the kernels' `F_LIGHT_TEXTURE` part: a texture or a projector.
pub fn light_textured(light: &DeltaLight) -> bool {
    light.tex != NO_PARAM || light.kind == LIGHT_PROJECTOR
}

/// The sampling cells of `scene`'s environment map, if it has one.
fn env_cells(scene: &Scene) -> Result<Vec<EnvCell>> {
    match (scene.env_map, scene.environment) {
        (Some(map), Some(texels)) => map.cells(scene.params.get(texels)),
        _ => Ok(Vec::new()),
    }
}

/// The colour fields of a material whose colour is `albedo`: a constant, a checkerboard or a bitmap.
fn albedo_fields(scene: &Scene, albedo: Albedo) -> GpuMaterial {
    let offset = |id| scene.params.entry(id).offset;
    match albedo {
        Albedo::Rgb(albedo) => GpuMaterial { p_color: offset(albedo), ..Default::default() },
        Albedo::Checker { colors, to_uv } => GpuMaterial {
            p_color: offset(colors),
            tex_width: 2,
            tex_height: 1,
            tex_mode: TEX_CHECKER,
            uv_row0: to_uv[0],
            uv_row1: to_uv[1],
            ..Default::default()
        },
        // tex_width × tex_height is the number of rows (the kernels read neither).
        Albedo::Attribute { values, source } => GpuMaterial {
            p_color: offset(values),
            tex_width: scene.params.entry(values).len / 3,
            tex_height: 1,
            tex_mode: attribute_mode(source),
            ..Default::default()
        },
        // p_color is the field's index: after the media's two each (flatten_media).
        Albedo::Volume(v) => GpuMaterial {
            p_color: 2 * scene.media.len() as u32 + v,
            tex_width: 1,
            tex_height: 1,
            tex_mode: TEX_VOLUME,
            ..Default::default()
        },
        Albedo::Bitmap(t) => {
            let t = &scene.textures[t.0 as usize];
            GpuMaterial {
                p_color: offset(t.texels),
                tex_width: t.width,
                tex_height: t.height,
                tex_mode: texture_mode(t.nearest, t.wrap),
                uv_row0: t.to_uv[0],
                uv_row1: t.to_uv[1],
                ..Default::default()
            }
        }
    }
}

/// The mean of a colour over its channels and (textured) texels: Mitsuba's `Texture::mean`.
fn albedo_mean(scene: &Scene, albedo: Albedo) -> f32 {
    let values = match albedo {
        Albedo::Rgb(id) | Albedo::Checker { colors: id, .. } | Albedo::Attribute { values: id, .. } => {
            scene.params.get(id)
        }
        Albedo::Bitmap(t) => scene.params.get(scene.textures[t.0 as usize].texels),
        Albedo::Volume(v) => match scene.volume_textures[v as usize] {
            Field::Constant { value, .. } | Field::Grid { values: value, .. } => scene.params.get(value),
        },
    };
    (values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len().max(1) as f64) as f32
}

/// The mean of a specular colour over its channels (and texels): Mitsuba's `Texture::mean`.
fn colour_mean(scene: &Scene, c: SmoothColour) -> f32 {
    match c {
        SmoothColour::Param(id) => albedo_mean(scene, Albedo::Rgb(id)),
        SmoothColour::Constant(v) => v.element_sum() / 3.0,
        SmoothColour::Texture(a) => albedo_mean(scene, a),
    }
}

/// A dielectric's or conductor's colour as (parameter offset, 0), (`NO_PARAM`, the constant), or
/// for a texture (`SCALAR_TEXTURE`, 0) until [`colour_texture_tables`] places its descriptor.
fn split_colour(scene: &Scene, c: SmoothColour) -> (u32, Vec3) {
    match c {
        SmoothColour::Param(id) => (scene.params.entry(id).offset, Vec3::ZERO),
        SmoothColour::Constant(v) => (NO_PARAM, v),
        SmoothColour::Texture(_) => (SCALAR_TEXTURE, Vec3::ZERO),
    }
}

/// The descriptor (`TEXTURE_DESC_LEN` words as `SCALAR_TEXTURE` states, RGB texels) of colour
/// texture `albedo`: a bitmap's, a checkerboard's (2 × 1 texels, `TEX_CHECKER`) or a mesh
/// attribute's (its rows × 1, an attribute mode).
fn colour_descriptor(scene: &Scene, albedo: Albedo) -> [f32; TEXTURE_DESC_LEN as usize] {
    let m = albedo_fields(scene, albedo);
    let words = [m.p_color, m.tex_width, m.tex_height, m.tex_mode].map(f32::from_bits);
    let mut d = [0.0; TEXTURE_DESC_LEN as usize];
    d[..4].copy_from_slice(&words);
    d[4..7].copy_from_slice(&m.uv_row0.to_array());
    d[7..].copy_from_slice(&m.uv_row1.to_array());
    d
}

/// Appends the descriptor of every textured specular colour ([`SmoothColour::Texture`] of a
/// smooth BSDF or rough dielectric) to `tables` (once per texture) and points its slot at it,
/// `SCALAR_TEXTURE` or-ed with its offset there: the reflectance's `p_color`, the
/// transmittance's `p_alpha` (smooth) or `p_weight` (rough), a plastic's specular colour's
/// `p_weight`. `materials` are `scene`'s, flattened.
fn colour_texture_tables(scene: &Scene, materials: &mut [GpuMaterial], tables: &mut Vec<f32>) {
    let mut placed: Vec<(Albedo, u32)> = Vec::new();
    let mut place = |albedo: Albedo, tables: &mut Vec<f32>| match placed.iter().find(|(a, _)| *a == albedo) {
        Some(&(_, at)) => SCALAR_TEXTURE | at,
        None => {
            let at = tables.len() as u32;
            tables.extend(colour_descriptor(scene, albedo));
            placed.push((albedo, at));
            SCALAR_TEXTURE | at
        }
    };
    for (m, flat) in scene.materials.iter().zip(materials.iter_mut()) {
        // The leaf a wrapper flattens into (as `flatten_material`).
        let mut leaf = m;
        while let Material::TwoSided(c)
        | Material::Mask { nested: c, .. }
        | Material::NormalMap { nested: c, .. }
        | Material::BumpMap { nested: c, .. } = *leaf
        {
            leaf = &scene.materials[c.0 as usize];
        }
        let (reflectance, transmittance, rough) = match *leaf {
            Material::Smooth { reflectance, transmittance, .. } => (reflectance, transmittance, false),
            Material::RoughDielectric { reflectance, transmittance, .. } => (reflectance, transmittance, true),
            // A plastic's specular colour sits where a rough dielectric's transmittance does.
            Material::RoughPlastic { specular, .. } | Material::SmoothPlastic { specular, .. } => {
                (SmoothColour::Constant(Vec3::ZERO), specular, true)
            }
            _ => continue,
        };
        if let SmoothColour::Texture(a) = reflectance {
            flat.p_color = place(a, tables);
        }
        if let SmoothColour::Texture(a) = transmittance {
            *(if rough { &mut flat.p_weight } else { &mut flat.p_alpha }) = place(a, tables);
        }
    }
}

fn flatten_material(scene: &Scene, m: &Material) -> GpuMaterial {
    let offset = |id| scene.params.entry(id).offset;
    match *m {
        Material::Diffuse { albedo } => GpuMaterial { tag: MAT_DIFFUSE, ..albedo_fields(scene, albedo) },
        Material::TwoSided(child) => {
            GpuMaterial { two_sided: 1, ..flatten_material(scene, &scene.materials[child.0 as usize]) }
        }
        Material::RoughConductor { distribution, alpha, alpha_v, specular, eta, k, eta_param } => GpuMaterial {
            tag: MAT_ROUGH_CONDUCTOR,
            distribution: distribution as u32,
            p_alpha: scalar_slot(scene, alpha),
            p_alpha_v: scalar_slot(scene, alpha_v),
            // eta's parameter, k's the three values after it (their values override eta and k).
            p_weight: eta_param.map_or(NO_PARAM, offset),
            eta,
            k,
            ..albedo_fields(scene, specular)
        },
        Material::RoughPlastic { distribution, alpha, diffuse, specular, eta, nonlinear } => {
            // Mitsuba's sampling weight of the coating from the mean reflectances; the specular
            // colour a parameter or texture (p_weight) or a constant (k).
            let (d_mean, s_mean) = (albedo_mean(scene, diffuse), colour_mean(scene, specular));
            let (p_weight, k) = split_colour(scene, specular);
            GpuMaterial {
                tag: MAT_ROUGH_PLASTIC,
                distribution: distribution as u32,
                p_alpha: offset(alpha),
                p_weight,
                eta: Vec3::new(eta, s_mean / (d_mean + s_mean), f32::from(u8::from(nonlinear))),
                k,
                ..albedo_fields(scene, diffuse)
            }
        }
        Material::SmoothPlastic { diffuse, specular, eta, nonlinear } => {
            let (d_mean, s_mean) = (albedo_mean(scene, diffuse), colour_mean(scene, specular));
            let (p_weight, k) = split_colour(scene, specular);
            GpuMaterial {
                tag: MAT_PLASTIC,
                p_weight,
                eta: Vec3::new(eta, s_mean / (d_mean + s_mean), f32::from(u8::from(nonlinear))),
                k,
                ..albedo_fields(scene, diffuse)
            }
        }
        Material::Smooth { kind, reflectance, transmittance, eta, k, eta_param } => {
            // Each colour a parameter (p_color, p_alpha) or a constant (uv_row0; k for a
            // dielectric's transmittance, whose k is free).
            let ((p_color, r), (p_alpha, t)) = (split_colour(scene, reflectance), split_colour(scene, transmittance));
            GpuMaterial {
                tag: match kind {
                    SmoothKind::Conductor => MAT_CONDUCTOR,
                    SmoothKind::Dielectric => MAT_DIELECTRIC,
                    SmoothKind::ThinDielectric => MAT_THIN_DIELECTRIC,
                },
                p_color,
                p_alpha,
                // A dielectric's η parameter (its value overrides eta.x); a conductor's eta, k's
                // the three values after it (overriding eta and k).
                p_weight: eta_param.map_or(NO_PARAM, offset),
                uv_row0: r,
                eta,
                k: if kind == SmoothKind::Conductor { k } else { t },
                ..Default::default()
            }
        }
        Material::RoughDielectric { distribution, alpha, alpha_v, reflectance, transmittance, eta, eta_param } => {
            // The reflectance a parameter (p_color) or a constant (uv_row0), the transmittance a
            // parameter (p_weight, free in a leaf) or a constant (k); η's parameter in `table`
            // (free in a rough dielectric; its value overrides eta.x).
            let ((p_color, r), (p_weight, t)) = (split_colour(scene, reflectance), split_colour(scene, transmittance));
            GpuMaterial {
                tag: MAT_ROUGH_DIELECTRIC,
                distribution: distribution as u32,
                p_color,
                p_alpha: scalar_slot(scene, alpha),
                p_alpha_v: scalar_slot(scene, alpha_v),
                p_weight,
                uv_row0: r,
                eta: Vec3::new(eta, 0.0, 0.0),
                k: t,
                table: eta_param.map_or(NO_PARAM, offset),
                ..Default::default()
            }
        }
        Material::Principled { base_color, roughness, anisotropic, eta, rates, .. } => GpuMaterial {
            tag: MAT_PRINCIPLED,
            distribution: DIST_GGX,
            p_alpha: scalar_slot(scene, roughness),
            p_alpha_v: scalar_slot(scene, anisotropic),
            // The material's index until `scalar_texture_tables` places its record.
            table: scene.materials.iter().position(|x| std::ptr::eq(x, m)).expect("a material of the scene") as u32,
            eta: Vec3::new(eta, 0.0, 0.0),
            k: rates,
            ..albedo_fields(scene, base_color)
        },
        Material::PrincipledThin { base_color, roughness, anisotropic, rates, .. } => GpuMaterial {
            tag: MAT_PRINCIPLED_THIN,
            distribution: DIST_GGX,
            p_alpha: scalar_slot(scene, roughness),
            p_alpha_v: scalar_slot(scene, anisotropic),
            // The material's index until `scalar_texture_tables` places its record.
            table: scene.materials.iter().position(|x| std::ptr::eq(x, m)).expect("a material of the scene") as u32,
            eta: Vec3::new(rates[3], 0.0, 0.0),
            k: Vec3::new(rates[0], rates[1], rates[2]),
            ..albedo_fields(scene, base_color)
        },
        Material::Blend { weight, children } => GpuMaterial {
            tag: MAT_BLEND,
            child0: children[0].0,
            child1: children[1].0,
            p_weight: scalar_slot(scene, weight),
            ..Default::default()
        },
        Material::Null => GpuMaterial { tag: MAT_NULL, ..Default::default() },
        // The opacity is `mask_slot`'s, set on every flattened material.
        Material::Mask { nested, .. } => flatten_material(scene, &scene.materials[nested.0 as usize]),
        Material::NormalMap { nested, map } | Material::BumpMap { nested, map, .. } => {
            // `nmap` holds the map's index until `normal_map_tables` places its texels.
            let t = &scene.normal_maps[map as usize];
            let (bump, scale) = match *m {
                Material::BumpMap { scale, .. } => (NMAP_BUMP, scale),
                _ => (0, 0.0),
            };
            GpuMaterial {
                nmap: map,
                nmap_width: t.width,
                nmap_height: t.height,
                nmap_mode: texture_mode(t.nearest, t.wrap) | bump,
                nmap_scale: scale,
                ..flatten_material(scene, &scene.materials[nested.0 as usize])
            }
        }
    }
}

/// `Material::p_opacity` of `m`: its mask's opacity slot ([`scalar_slot`]), looking through the
/// wrappers that flatten into one material (two-sided, normal and bump maps), or `NO_PARAM`.
fn mask_slot(scene: &Scene, m: &Material) -> u32 {
    match *m {
        Material::Mask { opacity, .. } => scalar_slot(scene, opacity),
        Material::TwoSided(c) | Material::NormalMap { nested: c, .. } | Material::BumpMap { nested: c, .. } => {
            mask_slot(scene, &scene.materials[c.0 as usize])
        }
        _ => NO_PARAM,
    }
}

/// A scalar slot's value in `Material`: the parameter's offset, or for a textured one
/// `SCALAR_TEXTURE` with the texture's index in [`Scene::scalar_textures`] until
/// `scalar_texture_tables` places its descriptor.
fn scalar_slot(scene: &Scene, id: ParamId) -> u32 {
    match scene.scalar_textures.iter().position(|t| t.texels == id) {
        Some(i) => SCALAR_TEXTURE | i as u32,
        None => scene.params.entry(id).offset,
    }
}

/// Appends the descriptor of every scalar texture that `materials` use to `tables` (once per
/// texture; `TEXTURE_DESC_LEN` words as `SCALAR_TEXTURE` states) and points their slots at them;
/// appends each principled material's record of scalar slots (`PRINCIPLED_SCALARS`).
fn scalar_texture_tables(scene: &Scene, materials: &mut [GpuMaterial], tables: &mut Vec<f32>) {
    let mut placed: Vec<(u32, u32)> = Vec::new();
    let mut place = |slot: &mut u32, tables: &mut Vec<f32>| {
        if *slot == NO_PARAM || *slot & SCALAR_TEXTURE == 0 {
            return;
        }
        let index = *slot & !SCALAR_TEXTURE;
        let at = match placed.iter().find(|(i, _)| *i == index) {
            Some(&(_, at)) => at,
            None => {
                let t = &scene.scalar_textures[index as usize];
                let at = tables.len() as u32;
                let mode = match t.attribute {
                    Some(source) => attribute_mode(source),
                    None if t.checker => TEX_CHECKER,
                    None => texture_mode(t.nearest, t.wrap),
                };
                let words = [scene.params.entry(t.texels).offset, t.width, t.height, mode];
                tables.extend(words.map(f32::from_bits));
                tables.extend(t.to_uv[0].to_array());
                tables.extend(t.to_uv[1].to_array());
                placed.push((index, at));
                at
            }
        };
        *slot = SCALAR_TEXTURE | at;
    };
    for m in materials.iter_mut() {
        match m.tag {
            MAT_ROUGH_CONDUCTOR | MAT_ROUGH_DIELECTRIC => {
                place(&mut m.p_alpha, tables);
                place(&mut m.p_alpha_v, tables);
            }
            MAT_PRINCIPLED | MAT_PRINCIPLED_THIN => {
                place(&mut m.p_alpha, tables);
                place(&mut m.p_alpha_v, tables);
                // The record of its eight scalar slots (`PRINCIPLED_SCALARS`); a thin one's in
                // the words of principled's that play their part (MAT_PRINCIPLED_THIN's layout).
                let scalars = match &scene.materials[m.table as usize] {
                    Material::Principled { scalars, .. } => *scalars,
                    Material::PrincipledThin { scalars, .. } => {
                        let [spec_trans, spec_tint, sheen, sheen_tint, flatness, diff_trans, eta] = *scalars;
                        [diff_trans, spec_tint, spec_trans, sheen, sheen_tint, eta, eta, flatness]
                    }
                    _ => unreachable!("a principled material's table holds its index until here"),
                };
                let mut words = scalars.map(|id| scalar_slot(scene, id));
                for w in &mut words {
                    place(w, tables);
                }
                m.table = tables.len() as u32;
                tables.extend(words.map(f32::from_bits));
            }
            MAT_BLEND => place(&mut m.p_weight, tables),
            _ => {}
        }
        place(&mut m.p_opacity, tables);
    }
}

/// Appends the descriptor of every textured area emitter's radiance (`TEXTURE_DESC_LEN` words as
/// `SCALAR_TEXTURE` states, the texels RGB: a bitmap's, or a checkerboard's two colours with
/// `TEX_CHECKER`) to `tables` and points its triangles' `p_radiance` at it, `SCALAR_TEXTURE`
/// or-ed with its offset there.
fn area_texture_tables(scene: &Scene, emitters: &mut [EmitterTri], tables: &mut Vec<f32>) {
    // (radiance offset, descriptor offset) of each textured emitter's radiance, placed once.
    let mut placed: Vec<(u32, u32)> = Vec::new();
    for m in &scene.meshes {
        let (Some(radiance), Some(albedo)) = (m.emitter, m.emitter_texture) else {
            continue;
        };
        let offset = scene.params.entry(radiance).offset;
        if placed.iter().all(|(o, _)| *o != offset) {
            placed.push((offset, tables.len() as u32));
            tables.extend(colour_descriptor(scene, albedo));
        }
    }
    for e in emitters.iter_mut() {
        if let Some(&(_, at)) = placed.iter().find(|(o, _)| *o == e.p_radiance) {
            e.p_radiance = SCALAR_TEXTURE | at;
        }
    }
}

/// `Material::tex_mode` of a mesh attribute: per vertex or per triangle.
fn attribute_mode(source: crate::scene::AttributeSource) -> u32 {
    if source.per_vertex { TEX_ATTR_VERTEX } else { TEX_ATTR_FACE }
}

/// `Material::tex_mode`'s filter and wrap bits.
fn texture_mode(nearest: bool, wrap: Wrap) -> u32 {
    (if nearest { TEX_NEAREST } else { 0 })
        | match wrap {
            Wrap::Repeat => 0,
            Wrap::Mirror => TEX_WRAP_MIRROR,
            Wrap::Clamp => TEX_WRAP_CLAMP,
        }
}

/// Appends the texels of every normal map that `materials` use to `tables` (once per map) and
/// points each material's `nmap` at them.
fn normal_map_tables(scene: &Scene, materials: &mut [GpuMaterial], tables: &mut Vec<f32>) {
    let mut placed: Vec<(u32, u32)> = Vec::new();
    for m in materials.iter_mut().filter(|m| m.nmap_width > 0) {
        let map = m.nmap;
        m.nmap = match placed.iter().find(|(i, _)| *i == map) {
            Some(&(_, at)) => at,
            None => {
                let at = tables.len() as u32;
                tables.extend_from_slice(&scene.normal_maps[map as usize].texels);
                placed.push((map, at));
                at
            }
        };
    }
}

/// Gives every rough plastic of `materials` its coating table ([`CoatingTable`]) at the current
/// roughness `params` and returns the tables: one slot per rough plastic in material order, so
/// the layout never changes when the roughness does; equal (distribution, α, η) are computed once.
fn coating_tables(materials: &mut [GpuMaterial], params: &[f32]) -> Vec<f32> {
    let mut tables: Vec<f32> = Vec::new();
    let mut made: Vec<((u32, u32, u32), usize)> = Vec::new();
    for m in materials.iter_mut().filter(|m| m.tag == MAT_ROUGH_PLASTIC) {
        let alpha = params[m.p_alpha as usize];
        let key = (m.distribution, alpha.to_bits(), m.eta.x.to_bits());
        let at = tables.len();
        m.table = at as u32;
        match made.iter().find(|(k, _)| *k == key) {
            Some(&(_, from)) => tables.extend_from_within(from..from + COATING_TABLE_LEN as usize),
            None => {
                let distribution = if m.distribution == DIST_GGX { Distribution::Ggx } else { Distribution::Beckmann };
                tables.extend(CoatingTable::new(distribution, alpha, m.eta.x).flatten());
                made.push((key, at));
            }
        }
    }
    tables
}

/// The media, their fields (two per medium, extinction then albedo, then the surfaces' `volume`
/// textures, [`Scene::volume_textures`]) and their majorant grids.
fn flatten_media(scene: &Scene) -> (Vec<MediumDesc>, Vec<FieldDesc>, Vec<f32>) {
    let offset = |id| scene.params.entry(id).offset;
    let field = |f: &Field| match f {
        Field::Constant { value, channels } => {
            FieldDesc { kind: FIELD_CONSTANT, channels: *channels, offset: offset(*value), ..Default::default() }
        }
        Field::Grid { resolution, channels, values, to_local, wrap } => {
            let rows = to_local.transpose();
            FieldDesc {
                kind: match wrap {
                    Wrap::Clamp => FIELD_GRID,
                    Wrap::Repeat => FIELD_GRID_REPEAT,
                    Wrap::Mirror => FIELD_GRID_MIRROR,
                },
                channels: *channels,
                offset: offset(*values),
                res_x: resolution.x,
                res_y: resolution.y,
                res_z: resolution.z,
                row0: rows.x_axis.truncate(),
                row1: rows.y_axis.truncate(),
                row2: rows.z_axis.truncate(),
                shift: to_local.w_axis.truncate(),
            }
        }
    };
    let mut fields = Vec::new();
    let mut majorants = Vec::new();
    let media = scene
        .media
        .iter()
        .map(|m| {
            let first = fields.len() as u32;
            fields.push(field(&m.sigma_t));
            fields.push(field(&m.albedo));
            let (phase, p_g) = match m.phase {
                Phase::Isotropic => (PHASE_ISOTROPIC, NO_PARAM),
                Phase::HenyeyGreenstein { g } => (PHASE_HG, offset(g)),
            };
            let (grid, cells) = match m.majorant_grid(&scene.params) {
                Some(g) => {
                    let at = majorants.len() as u32;
                    majorants.extend_from_slice(&g.values);
                    (at, g.cells)
                }
                None => (NO_PARAM, glam::UVec3::ZERO),
            };
            MediumDesc {
                sigma_t: first,
                albedo: first + 1,
                p_scale: offset(m.scale),
                phase,
                p_g,
                majorant: m.majorant(&scene.params),
                bounded: u32::from(m.extent.is_some()),
                lo: m.extent.map_or(Vec3::ZERO, |e| e.0),
                hi: m.extent.map_or(Vec3::ZERO, |e| e.1),
                grid,
                grid_x: cells.x,
                grid_y: cells.y,
                grid_z: cells.z,
            }
        })
        .collect();
    fields.extend(scene.volume_textures.iter().map(field));
    (media, fields, majorants)
}
