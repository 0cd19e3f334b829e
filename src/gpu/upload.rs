//! The scene on the device: its flattened arrays uploaded once, and their device addresses.

use std::sync::Arc;

use rayon::prelude::*;

use crate::bvh;
use crate::contract::{Globals, TriPositions};
use crate::error::Result;
use crate::gpu::buffer::Buffer;
use crate::gpu::context::Context;
use crate::scene::Scene;
use crate::scene::flat::{
    FlatScene, first_ids, normal_count, normals_iter, tri_vertices_iter, triangle_positions, uv_count, uvs_iter,
};

/// The scene's arrays on the device.
pub(crate) struct GpuScene {
    /// How many BVH nodes `nodes` holds (the kernels' traversal bound): the host's copy of them
    /// is emptied by the upload.
    pub node_count: u32,
    pub nodes: Buffer,
    pub tris: Buffer,
    pub prim_ids: Buffer,
    /// Each triangle's vertex indices and mesh (`TriVertices`, by original id).
    pub tri_vertices: Buffer,
    /// The meshes' shading records.
    pub meshes: Buffer,
    /// The vertex normals of the meshes that have them.
    pub normals: Buffer,
    /// The texture coordinates of the meshes that have them.
    pub uvs: Buffer,
    /// The emissive meshes' per-triangle emitter indices.
    pub emitter_ids: Buffer,
    pub materials: Buffer,
    pub emitters: Buffer,
    /// One f32 per parameter value (`ParamTable` offsets): what `Renderer::set_params` rewrites.
    pub params: Buffer,
    /// The media (their majorants follow the parameters: rewritten with them).
    pub media: Buffer,
    /// The media's fields.
    pub fields: Buffer,
    /// The media's majorant grids (they follow the densities: rewritten with the parameters).
    pub majorants: Buffer,
    /// The environment map's sampling cells (they follow its texels: rewritten with the parameters).
    pub env_cells: Buffer,
    /// The lights without area.
    pub lights: Buffer,
    /// The rough plastics' coating tables (they follow the roughness: rewritten with the
    /// parameters), then the normal and bump maps' texels (constants).
    pub tables: Buffer,
}

impl GpuScene {
    /// Uploads `flat`, the flattened form of `scene`, emptying its per-triangle and per-vertex
    /// arrays — the BVH's nodes, triangles and triangle ids, and the shading data (vertex
    /// indices, normals, texture coordinates) if it has any — each as soon as it is on the
    /// device: from then on they live there only (issue 38: on a CPU device the device copy is
    /// host memory too). Without shading data and leaf-order positions
    /// (`FlatScene::for_device_reporting`) they are copied from `scene`'s meshes chunk by chunk
    /// straight into the staging buffer, so no host copy of them exists.
    pub(crate) fn new(ctx: &Arc<Context>, scene: &Scene, flat: &mut FlatScene) -> Result<GpuScene> {
        let _span = tracing::info_span!("upload").entered();
        // One statement each: a host array taken into a temporary of the struct expression below
        // would live until the whole expression ends, so all of them would outlive their uploads
        // (at 2 M triangles, 85 MB more at the upload's peak).
        let node_count = flat.bvh.nodes.len() as u32;
        let nodes = Buffer::storage_with(ctx, "BVH nodes", &std::mem::take(&mut flat.bvh.nodes))?;
        let tris = if flat.bvh.tris.is_empty() {
            leaf_positions(ctx, scene, &flat.bvh.prim_ids)?
        } else {
            Buffer::storage_with(ctx, "triangles (leaf order)", &std::mem::take(&mut flat.bvh.tris))?
        };
        let prim_ids = Buffer::storage_with(ctx, "triangle ids", &std::mem::take(&mut flat.bvh.prim_ids))?;
        let tri_vertices = if flat.tri_vertices.is_empty() {
            streamed(ctx, "triangle vertices", scene.triangle_count(), tri_vertices_iter(scene))?
        } else {
            Buffer::storage_with(ctx, "triangle vertices", &std::mem::take(&mut flat.tri_vertices))?
        };
        let normals = if flat.normals.is_empty() {
            streamed(ctx, "vertex normals", normal_count(scene), normals_iter(scene))?
        } else {
            Buffer::storage_with(ctx, "vertex normals", &std::mem::take(&mut flat.normals))?
        };
        let uvs = if flat.uvs.is_empty() {
            streamed(ctx, "texture coordinates", uv_count(scene), uvs_iter(scene))?
        } else {
            Buffer::storage_with(ctx, "texture coordinates", &std::mem::take(&mut flat.uvs))?
        };
        Ok(GpuScene {
            node_count,
            nodes,
            tris,
            prim_ids,
            tri_vertices,
            meshes: Buffer::storage_with(ctx, "mesh shading", &flat.meshes)?,
            normals,
            uvs,
            emitter_ids: Buffer::storage_with(ctx, "emitter ids", &flat.emitter_ids)?,
            materials: Buffer::storage_with(ctx, "materials", &flat.materials)?,
            emitters: Buffer::storage_with(ctx, "emitters", &flat.emitters)?,
            params: Buffer::storage_with(ctx, "param buffer", &flat.params)?,
            media: Buffer::storage_with(ctx, "media", &flat.media)?,
            fields: Buffer::storage_with(ctx, "media fields", &flat.fields)?,
            majorants: Buffer::storage_with(ctx, "majorant grids", &flat.majorants)?,
            env_cells: Buffer::storage_with(ctx, "environment map cells", &flat.env_cells)?,
            lights: Buffer::storage_with(ctx, "lights", &flat.lights)?,
            tables: Buffer::storage_with(ctx, "coating tables and normal maps", &flat.tables)?,
        })
    }

    /// Bytes of all the scene's buffers.
    pub(crate) fn bytes(&self) -> u64 {
        [
            &self.nodes,
            &self.tris,
            &self.prim_ids,
            &self.tri_vertices,
            &self.meshes,
            &self.normals,
            &self.uvs,
            &self.emitter_ids,
            &self.materials,
            &self.emitters,
            &self.params,
            &self.media,
            &self.fields,
            &self.majorants,
            &self.env_cells,
            &self.lights,
            &self.tables,
        ]
        .iter()
        .map(|b| b.size())
        .sum()
    }

    /// `globals` with the device addresses of the scene's arrays filled in.
    pub(crate) fn with_addresses(&self, globals: &Globals) -> Globals {
        Globals {
            addr_nodes: self.nodes.device_address(),
            addr_tris: self.tris.device_address(),
            addr_prim_ids: self.prim_ids.device_address(),
            addr_tri_vertices: self.tri_vertices.device_address(),
            addr_meshes: self.meshes.device_address(),
            addr_normals: self.normals.device_address(),
            addr_uvs: self.uvs.device_address(),
            addr_emitter_ids: self.emitter_ids.device_address(),
            addr_materials: self.materials.device_address(),
            addr_emitters: self.emitters.device_address(),
            addr_params: self.params.device_address(),
            addr_media: self.media.device_address(),
            addr_fields: self.fields.device_address(),
            addr_env_cells: self.env_cells.device_address(),
            addr_lights: self.lights.device_address(),
            addr_tables: self.tables.device_address(),
            addr_majorants: self.majorants.device_address(),
            node_count: self.node_count,
            ..*globals
        }
    }
}

/// The BVH's triangle positions in leaf order (`prim_ids`: the triangle id of each leaf slot),
/// read from `scene`'s meshes into the reused staging buffer chunk by chunk on rayon's threads:
/// the array never exists on the host (at 2 M triangles it is 76 MiB).
fn leaf_positions(ctx: &Arc<Context>, scene: &Scene, prim_ids: &[u32]) -> Result<Buffer> {
    let count = prim_ids.len();
    let buffer = Buffer::storage(ctx, "triangles (leaf order)", (count * size_of::<TriPositions>()) as u64)?;
    let firsts = first_ids(scene);
    let mut done = 0;
    buffer.upload_with(count, |chunk: &mut [TriPositions]| {
        let ids = &prim_ids[done..done + chunk.len()];
        chunk
            .par_iter_mut()
            .zip(ids)
            .for_each(|(slot, &id)| *slot = bvh::leaf_positions(triangle_positions(scene, &firsts, id)));
        done += chunk.len();
    })?;
    Ok(buffer)
}

/// A storage buffer of the `count` elements of `items`, written chunk by chunk into the reused
/// staging buffer (`Buffer::upload_with`): the whole array never exists on the host.
fn streamed<T: bytemuck::Pod>(
    ctx: &Arc<Context>,
    name: &str,
    count: usize,
    mut items: impl Iterator<Item = T>,
) -> Result<Buffer> {
    let buffer = Buffer::storage(ctx, name, (count * size_of::<T>()) as u64)?;
    buffer.upload_with(count, |chunk: &mut [T]| {
        for (slot, item) in chunk.iter_mut().zip(&mut items) {
            *slot = item;
        }
    })?;
    Ok(buffer)
}
