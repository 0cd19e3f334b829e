//! The BVH: built by obvhs on the host, flattened into `BvhNode`s, and traversed here on the CPU in
//! exactly the order `shaders/lib/bvh.glsl` traverses it on the GPU (its twin).

use std::time::Duration;

use glam::Vec3;
use obvhs::BvhBuildParams;
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::triangle::Triangle;

use crate::error::{Error, Result};
use crate::gpu::abi::{BVH_STACK_SIZE, BvhNode, TriPositions};

/// Direction components smaller than this are replaced by it (keeping the sign), so the slab test's
/// reciprocal is finite and `0 · ∞` never produces NaN — identically in Rust and GLSL.
pub const MIN_DIR_COMPONENT: f32 = 1e-20;

/// A built BVH: nodes plus the triangles in leaf order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh {
    /// Nodes; the root is node 0.
    pub nodes: Vec<BvhNode>,
    /// Triangle positions in leaf order.
    pub tris: Vec<TriPositions>,
    /// The original triangle id of each leaf slot.
    pub prim_ids: Vec<u32>,
    /// Depth of the deepest leaf (root = 1).
    pub depth: u32,
}

/// Builds a BVH over `triangles` (obvhs `medium_build`: no spatial splits).
///
/// # Errors
/// [`Error::Scene`] if the tree is deeper than the GPU traversal stack allows.
pub fn build(triangles: &[[Vec3; 3]]) -> Result<Bvh> {
    let tris: Vec<Triangle> =
        triangles.iter().map(|t| Triangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() }).collect();
    let mut build_time = Duration::ZERO;
    let bvh2 = build_bvh2_from_tris(&tris, BvhBuildParams::medium_build(), &mut build_time);
    let nodes: Vec<BvhNode> = bvh2
        .nodes
        .iter()
        .map(|n| BvhNode {
            bmin: n.aabb.min.into(),
            count: n.prim_count,
            bmax: n.aabb.max.into(),
            first: n.first_index,
        })
        .collect();
    let prim_ids = bvh2.primitive_indices.clone();
    let tris = prim_ids
        .iter()
        .map(|&i| {
            let t = &triangles[i as usize];
            TriPositions { v0: t[0], v1: t[1], v2: t[2] }
        })
        .collect();
    let depth = tree_depth(&nodes);
    // Traversal pushes at most one entry per level plus the root's children.
    if depth + 1 >= BVH_STACK_SIZE {
        return Err(Error::Scene {
            location: "BVH".into(),
            message: format!("depth {depth} exceeds the traversal stack ({BVH_STACK_SIZE})"),
        });
    }
    tracing::debug!(triangles = triangles.len(), nodes = nodes.len(), depth, ?build_time, "BVH built");
    Ok(Bvh { nodes, tris, prim_ids, depth })
}

fn tree_depth(nodes: &[BvhNode]) -> u32 {
    let mut deepest = 0;
    let mut stack = vec![(0usize, 1u32)];
    while let Some((i, d)) = stack.pop() {
        let n = &nodes[i];
        deepest = deepest.max(d);
        if n.count == 0 && nodes.len() > 1 {
            stack.push((n.first as usize, d + 1));
            stack.push((n.first as usize + 1, d + 1));
        }
    }
    deepest
}

/// A ray with precomputed reciprocal direction.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (need not be unit; `t` is in units of it).
    pub dir: Vec3,
    inv_dir: Vec3,
}

fn safe_component(x: f32) -> f32 {
    if x.abs() < MIN_DIR_COMPONENT { MIN_DIR_COMPONENT.copysign(x) } else { x }
}

impl Ray {
    /// A ray from `origin` along `dir`.
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        let safe = Vec3::new(safe_component(dir.x), safe_component(dir.y), safe_component(dir.z));
        Ray { origin, dir, inv_dir: Vec3::ONE / safe }
    }
}

/// A closest hit: distance, leaf slot and barycentrics of vertices 1 and 2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Leaf slot of the triangle (index into `Bvh::tris` / `Bvh::prim_ids`).
    pub slot: u32,
    /// Barycentric coordinate of vertex 1.
    pub b1: f32,
    /// Barycentric coordinate of vertex 2.
    pub b2: f32,
}

/// Möller–Trumbore: `(t, b1, b2)` if the ray hits the triangle with `tmin < t < tmax`.
pub fn intersect_triangle(ray: &Ray, tri: &TriPositions, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let e1 = tri.v1 - tri.v0;
    let e2 = tri.v2 - tri.v0;
    let p = ray.dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let inv_det = 1.0 / det;
    let s = ray.origin - tri.v0;
    let b1 = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&b1) {
        return None;
    }
    let q = s.cross(e1);
    let b2 = ray.dir.dot(q) * inv_det;
    if b2 < 0.0 || b1 + b2 > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv_det;
    (t > tmin && t < tmax).then_some((t, b1, b2))
}

/// Entry distance of the ray into the node's box if it enters before `tmax` (and ends after `tmin`).
fn slab(ray: &Ray, node: &BvhNode, tmin: f32, tmax: f32) -> Option<f32> {
    let t0 = (node.bmin - ray.origin) * ray.inv_dir;
    let t1 = (node.bmax - ray.origin) * ray.inv_dir;
    let near = t0.min(t1).max_element().max(tmin);
    let far = t0.max(t1).min_element().min(tmax);
    (near <= far).then_some(near)
}

/// The closest hit with `tmin < t < tmax`, or `None`. Same visiting order as `bvh_closest_hit`.
pub fn closest_hit(bvh: &Bvh, ray: &Ray, tmin: f32, tmax: f32) -> Option<Hit> {
    traverse(bvh, ray, tmin, tmax, false)
}

/// Whether anything lies on the ray with `tmin < t < tmax` (shadow rays).
pub fn occluded(bvh: &Bvh, ray: &Ray, tmin: f32, tmax: f32) -> bool {
    traverse(bvh, ray, tmin, tmax, true).is_some()
}

fn traverse(bvh: &Bvh, ray: &Ray, tmin: f32, mut tmax: f32, any_hit: bool) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    if bvh.nodes.is_empty() || slab(ray, &bvh.nodes[0], tmin, tmax).is_none() {
        return None;
    }
    let mut stack = [0u32; BVH_STACK_SIZE as usize];
    let mut sp = 1usize;
    while sp > 0 {
        sp -= 1;
        let node = &bvh.nodes[stack[sp] as usize];
        if node.count > 0 {
            for slot in node.first..node.first + node.count {
                if let Some((t, b1, b2)) = intersect_triangle(ray, &bvh.tris[slot as usize], tmin, tmax) {
                    tmax = t;
                    best = Some(Hit { t, slot, b1, b2 });
                    if any_hit {
                        return best;
                    }
                }
            }
        } else {
            let (a, b) = (node.first, node.first + 1);
            let ta = slab(ray, &bvh.nodes[a as usize], tmin, tmax);
            let tb = slab(ray, &bvh.nodes[b as usize], tmin, tmax);
            // Push the farther child first so the nearer one is visited next.
            let (first, second) = match (ta, tb) {
                (Some(x), Some(y)) if y < x => (Some(a), Some(b)),
                (Some(_), Some(_)) => (Some(b), Some(a)),
                (Some(_), None) => (None, Some(a)),
                (None, Some(_)) => (None, Some(b)),
                (None, None) => (None, None),
            };
            for child in [first, second].into_iter().flatten() {
                stack[sp] = child;
                sp += 1;
            }
        }
    }
    best
}
