//! The BVH: built by obvhs on the host, flattened into `BvhNode`s, and traversed here on the CPU in
//! exactly the order `shaders/lib/bvh.glsl` traverses it on the GPU (its twin).

use std::time::Duration;

use glam::Vec3;
use obvhs::BvhBuildParams;
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::triangle::Triangle;

use crate::contract::{
    BVH_LEAF_BIT, BVH_LEAF_COUNT_SHIFT, BVH_LEAF_FIRST_MASK, BVH_LEAF_MAX, BVH_NO_CHILD, BVH_STACK_SIZE, BvhNode,
    TriPositions,
};
use crate::error::{Error, Result};

pub use crate::contract::MIN_DIR_COMPONENT;

/// A built BVH: nodes plus the triangles in leaf order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh {
    /// Nodes, each with both children's boxes; the root is node 0.
    pub nodes: Vec<BvhNode>,
    /// Triangle positions in leaf order.
    pub tris: Vec<TriPositions>,
    /// The original triangle id of each leaf slot.
    pub prim_ids: Vec<u32>,
    /// Inner nodes on the longest path from the root to a leaf (the root counts).
    pub depth: u32,
}

impl Bvh {
    /// The leaf-slot range of every leaf, in node order.
    pub fn leaves(&self) -> impl Iterator<Item = std::ops::Range<u32>> + '_ {
        self.nodes
            .iter()
            .flat_map(|n| [n.child0, n.child1])
            .filter(|&r| r != BVH_NO_CHILD && r & BVH_LEAF_BIT != 0)
            .map(|r| {
                let first = r & BVH_LEAF_FIRST_MASK;
                first..first + ((r & !BVH_LEAF_BIT) >> BVH_LEAF_COUNT_SHIFT) + 1
            })
    }
}

/// Deepest tree the traversal stack holds: a step pops one entry and pushes at most two, so a
/// path through `d` inner nodes keeps at most `d + 1` entries.
const MAX_DEPTH: u32 = BVH_STACK_SIZE - 2;
/// A subtree still too deep at this depth is rebuilt by median splits, whose height is at most
/// ⌈log₂(n / BVH_LEAF_MAX)⌉ + 1 ≤ 28 for any n < 2²⁸: so every tree fits the stack.
const REBUILD_DEPTH: u32 = MAX_DEPTH - 30;

/// A node of the tree while it is being shaped: an inner node with two children, or a leaf of
/// original triangle ids.
#[derive(Clone, Debug)]
enum Shape {
    Inner([usize; 2]),
    Leaf(Vec<u32>),
}

#[derive(Clone, Debug)]
struct TmpNode {
    lo: Vec3,
    hi: Vec3,
    shape: Shape,
}

/// Builds a BVH over `triangles`: obvhs's PLOC build (`medium_build`, leaves of at most
/// [`BVH_LEAF_MAX`] triangles), flattened into nodes that hold both children's boxes. Any valid
/// mesh builds: subtrees deeper than the traversal stack allows (a fan-triangulated 1000-gon
/// gives PLOC depth ~270) are rebuilt below depth `REBUILD_DEPTH` by median splits.
///
/// # Errors
/// [`Error::Scene`] for more triangles than a leaf reference can address (2²⁸).
pub fn build(triangles: &[[Vec3; 3]]) -> Result<Bvh> {
    if triangles.len() >= BVH_LEAF_FIRST_MASK as usize {
        return Err(Error::Scene {
            location: "BVH".into(),
            message: format!("{} triangles exceed the {} a BVH can address", triangles.len(), BVH_LEAF_FIRST_MASK),
        });
    }
    if triangles.is_empty() {
        let empty = BvhNode { child0: BVH_NO_CHILD, child1: BVH_NO_CHILD, ..BvhNode::default() };
        return Ok(Bvh { nodes: vec![empty], tris: Vec::new(), prim_ids: Vec::new(), depth: 1 });
    }
    let tris: Vec<Triangle> =
        triangles.iter().map(|t| Triangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() }).collect();
    let mut build_time = Duration::ZERO;
    let params = BvhBuildParams { max_prims_per_leaf: BVH_LEAF_MAX, ..BvhBuildParams::medium_build() };
    let bvh2 = build_bvh2_from_tris(&tris, params, &mut build_time);
    let arena: Vec<TmpNode> = bvh2
        .nodes
        .iter()
        .map(|n| {
            let shape = if n.prim_count > 0 {
                let first = n.first_index as usize;
                Shape::Leaf(bvh2.primitive_indices[first..first + n.prim_count as usize].to_vec())
            } else {
                Shape::Inner([n.first_index as usize, n.first_index as usize + 1])
            };
            TmpNode { lo: n.aabb.min.into(), hi: n.aabb.max.into(), shape }
        })
        .collect();
    let mut out = Flattener { triangles, arena, heights: Vec::new(), bvh: Bvh::default() };
    out.heights = heights(&out.arena);
    let root_depth = out.heights[0];
    out.flatten_root();
    let bvh = out.bvh;
    tracing::debug!(
        triangles = triangles.len(),
        nodes = bvh.nodes.len(),
        depth = bvh.depth,
        ploc_depth = root_depth,
        ?build_time,
        "BVH built"
    );
    Ok(bvh)
}

/// Inner nodes on the longest path down from each node (0 for a leaf), without recursion.
fn heights(arena: &[TmpNode]) -> Vec<u32> {
    let mut h = vec![0u32; arena.len()];
    // Post-order by an explicit stack: a degenerate tree may be far deeper than the call stack.
    let mut stack = vec![(0usize, false)];
    while let Some((i, expanded)) = stack.pop() {
        match &arena[i].shape {
            Shape::Leaf(_) => h[i] = 0,
            Shape::Inner([a, b]) => {
                if expanded {
                    h[i] = 1 + h[*a].max(h[*b]);
                } else {
                    stack.push((i, true));
                    stack.push((*a, false));
                    stack.push((*b, false));
                }
            }
        }
    }
    h
}

struct Flattener<'a> {
    triangles: &'a [[Vec3; 3]],
    arena: Vec<TmpNode>,
    heights: Vec<u32>,
    bvh: Bvh,
}

impl Flattener<'_> {
    fn flatten_root(&mut self) {
        self.bvh.nodes.push(BvhNode::default());
        match self.arena[0].shape.clone() {
            Shape::Leaf(ids) => {
                let child0 = self.leaf(&ids);
                let (lo0, hi0) = (self.arena[0].lo, self.arena[0].hi);
                self.bvh.nodes[0] = BvhNode { lo0, child0, hi0, child1: BVH_NO_CHILD, ..BvhNode::default() };
                self.bvh.depth = 1;
            }
            Shape::Inner(_) => {
                self.bvh.depth = 0;
                self.inner(0, 0, 1);
            }
        }
    }

    /// Writes arena node `i` (inner) as flat node `slot` at depth `depth` (the root is 1).
    fn inner(&mut self, i: usize, slot: usize, depth: u32) {
        self.bvh.depth = self.bvh.depth.max(depth);
        let Shape::Inner([a, b]) = self.arena[i].shape else { unreachable!("inner() is given inner nodes") };
        let child0 = self.child(a, depth + 1);
        let child1 = self.child(b, depth + 1);
        let (na, nb) = (&self.arena[a], &self.arena[b]);
        self.bvh.nodes[slot] =
            BvhNode { lo0: na.lo, child0, hi0: na.hi, child1, lo1: nb.lo, hi1: nb.hi, ..BvhNode::default() };
    }

    /// The reference of arena node `i` placed at `depth`, rebuilding it first if its subtree
    /// would not fit the stack.
    fn child(&mut self, i: usize, depth: u32) -> u32 {
        if matches!(self.arena[i].shape, Shape::Inner(_))
            && depth + self.heights[i] > MAX_DEPTH + 1
            && depth >= REBUILD_DEPTH
        {
            let mut ids = Vec::new();
            collect_leaves(&self.arena, i, &mut ids);
            let rebuilt = self.median(&mut ids);
            return self.child(rebuilt, depth);
        }
        if let Shape::Leaf(ids) = &self.arena[i].shape {
            if ids.len() > BVH_LEAF_MAX as usize {
                let mut ids = ids.clone();
                let rebuilt = self.median(&mut ids);
                return self.child(rebuilt, depth);
            }
            let ids = ids.clone();
            return self.leaf(&ids);
        }
        let slot = self.bvh.nodes.len();
        self.bvh.nodes.push(BvhNode::default());
        self.inner(i, slot, depth);
        slot as u32
    }

    /// Appends a leaf's triangles to the leaf-ordered arrays; its reference.
    fn leaf(&mut self, ids: &[u32]) -> u32 {
        let first = self.bvh.tris.len() as u32;
        for &id in ids {
            let t = &self.triangles[id as usize];
            self.bvh.tris.push(TriPositions { v0: t[0], v1: t[1], v2: t[2], ..TriPositions::default() });
            self.bvh.prim_ids.push(id);
        }
        BVH_LEAF_BIT | ((ids.len() as u32 - 1) << BVH_LEAF_COUNT_SHIFT) | first
    }

    /// Builds a subtree over `ids` by splitting at the median centroid along the widest axis
    /// (halving every time, whatever the geometry); returns its arena index.
    fn median(&mut self, ids: &mut [u32]) -> usize {
        let (lo, hi) = bounds(self.triangles, ids);
        if ids.len() <= BVH_LEAF_MAX as usize {
            self.arena.push(TmpNode { lo, hi, shape: Shape::Leaf(ids.to_vec()) });
            self.heights.push(0);
            return self.arena.len() - 1;
        }
        let centroid = |id: u32| {
            let t = &self.triangles[id as usize];
            t[0] + t[1] + t[2]
        };
        let (clo, chi) =
            ids.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(l, h), &id| {
                (l.min(centroid(id)), h.max(centroid(id)))
            });
        let extent = chi - clo;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let mid = ids.len() / 2;
        ids.select_nth_unstable_by(mid, |&a, &b| centroid(a)[axis].total_cmp(&centroid(b)[axis]).then(a.cmp(&b)));
        let (left, right) = ids.split_at_mut(mid);
        let a = self.median(left);
        let b = self.median(right);
        self.arena.push(TmpNode { lo, hi, shape: Shape::Inner([a, b]) });
        self.heights.push(1 + self.heights[a].max(self.heights[b]));
        self.arena.len() - 1
    }
}

/// The original triangle ids under arena node `i`, without recursion.
fn collect_leaves(arena: &[TmpNode], i: usize, ids: &mut Vec<u32>) {
    let mut stack = vec![i];
    while let Some(j) = stack.pop() {
        match &arena[j].shape {
            Shape::Leaf(l) => ids.extend_from_slice(l),
            Shape::Inner([a, b]) => {
                stack.push(*b);
                stack.push(*a);
            }
        }
    }
}

fn bounds(triangles: &[[Vec3; 3]], ids: &[u32]) -> (Vec3, Vec3) {
    ids.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(l, h), &id| {
        let t = &triangles[id as usize];
        (l.min(t[0]).min(t[1]).min(t[2]), h.max(t[0]).max(t[1]).max(t[2]))
    })
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

/// Entry distance of the ray into the box `lo..hi` if it enters before `tmax` (and ends after `tmin`).
fn slab(ray: &Ray, lo: Vec3, hi: Vec3, tmin: f32, tmax: f32) -> Option<f32> {
    let t0 = (lo - ray.origin) * ray.inv_dir;
    let t1 = (hi - ray.origin) * ray.inv_dir;
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

/// One stack entry per step: a leaf's triangles are tested, an inner node's two boxes are
/// tested and the children hit are pushed — the farther first for closest hits, in node order
/// for shadow rays (any hit will do, so no ordering is paid for). The GLSL twin keeps the entry
/// it would pop next in a register instead of pushing it; the visiting order is the same.
fn traverse(bvh: &Bvh, ray: &Ray, tmin: f32, mut tmax: f32, any_hit: bool) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    let mut stack = [0u32; BVH_STACK_SIZE as usize];
    let mut sp = 1usize;
    while sp > 0 {
        sp -= 1;
        let r = stack[sp];
        if r & BVH_LEAF_BIT != 0 {
            let first = r & BVH_LEAF_FIRST_MASK;
            let count = ((r & !BVH_LEAF_BIT) >> BVH_LEAF_COUNT_SHIFT) + 1;
            for slot in first..first + count {
                if let Some((t, b1, b2)) = intersect_triangle(ray, &bvh.tris[slot as usize], tmin, tmax) {
                    tmax = t;
                    best = Some(Hit { t, slot, b1, b2 });
                    if any_hit {
                        return best;
                    }
                }
            }
        } else {
            let n = &bvh.nodes[r as usize];
            let ta = if n.child0 != BVH_NO_CHILD { slab(ray, n.lo0, n.hi0, tmin, tmax) } else { None };
            let tb = if n.child1 != BVH_NO_CHILD { slab(ray, n.lo1, n.hi1, tmin, tmax) } else { None };
            let (a, b) = (n.child0, n.child1);
            // Pushed first, visited last.
            let (first, second) = match (ta, tb) {
                (Some(_), Some(_)) if any_hit => (Some(b), Some(a)),
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
