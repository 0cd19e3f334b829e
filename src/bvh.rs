//! The BVH: obvhs's compressed 8-wide BVH (CWBVH, Ylitie et al. 2017) over the scene's triangles,
//! traversed here on the CPU in exactly the order `shaders/lib/bvh.glsl` traverses it on the GPU
//! (its twin).

use std::time::Instant;

use glam::{UVec2, Vec3};
use obvhs::BvhBuildParams;
use obvhs::ploc::{PlocSearchDistance, SortPrecision};
use rayon::prelude::*;

use crate::contract::{BVH_FAR_SCALE, BVH_LEAF_MAX, BVH_STACK_SIZE, BvhNode, TriPositions};
use crate::error::{Error, Result};

pub use crate::contract::MIN_DIR_COMPONENT;

mod convert;
mod depth;
mod node2;
mod ploc;
mod reinsert;

use node2::Node2;

/// A built BVH: nodes plus the triangles in leaf order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh {
    /// Compressed 8-wide nodes; the root is node 0.
    pub nodes: Vec<BvhNode>,
    /// Triangle positions in leaf order (empty where the tree was built without them, for a renderer: its upload writes them from the meshes).
    pub tris: Vec<TriPositions>,
    /// The original triangle id of each leaf slot.
    pub prim_ids: Vec<u32>,
    /// Nodes on the longest path from the root down (the root counts).
    pub depth: u32,
}

/// Byte `k` (0–7) of a per-child word pair.
fn child_byte(w: UVec2, k: u32) -> u32 {
    let word = if k < 4 { w.x } else { w.y };
    (word >> (8 * (k % 4))) & 0xff
}

impl Bvh {
    /// The leaf-slot range of every leaf child, in node and slot order.
    pub fn leaves(&self) -> impl Iterator<Item = std::ops::Range<u32>> + '_ {
        self.nodes.iter().flat_map(|n| {
            (0..8).filter_map(move |k| {
                let meta = child_byte(n.meta, k);
                let inner = (n.exp_imask >> 24) & (1 << k) != 0;
                (meta != 0 && !inner).then(|| {
                    let first = n.tri_base + (meta & 0x1f);
                    first..first + (meta >> 5).count_ones()
                })
            })
        })
    }
}

/// A leaf slot's record of a triangle's positions (what [`Bvh::tris`] holds).
pub(crate) fn leaf_positions([v0, v1, v2]: [Vec3; 3]) -> TriPositions {
    TriPositions { v0, v1, v2, ..TriPositions::default() }
}

/// Deepest binary tree the conversion is given: a compressed node consumes at least one of its
/// levels, and a traversal step pops one entry and pushes at most one, so the stack holds fewer
/// entries than this.
const MAX_DEPTH: u32 = BVH_STACK_SIZE - 2;
/// A subtree still too deep at this depth is rebuilt by median splits, whose height is at most
/// ⌈log₂ n⌉ + 1 ≤ 29 for any n < 2²⁸: so every tree fits the stack.
const REBUILD_DEPTH: u32 = MAX_DEPTH - 30;
/// Triangles a BVH can address (leaf slots are 32-bit; the median rebuild's bound assumes this).
const MAX_TRIANGLES: usize = 1 << 28;

/// A node of the binary tree while it is being shaped: an inner node with two children, or a
/// leaf of original triangle ids.
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

/// Builds a BVH over `triangles`: obvhs's PLOC build and reinsertion (`medium_build`'s, in less
/// memory: `ploc`, `reinsert`; the second reinsertion pass only up to `SECOND_REINSERTION_MAX`
/// triangles, the first up to `FIRST_REINSERTION_MAX`) into a binary tree of one-triangle
/// leaves, its depth bounded, converted (obvhs's conversion with a smaller decision table,
/// `convert`) into compressed 8-wide nodes with leaves of up to
/// [`BVH_LEAF_MAX`] triangles and children ordered for the ray octant. Any valid
/// mesh builds: subtrees deeper than the traversal stack allows (a fan-triangulated 1000-gon
/// gives PLOC depth ~270) are rebuilt below depth `REBUILD_DEPTH` by median splits.
///
/// # Errors
/// [`Error::Scene`] for more triangles than a BVH can address (2²⁸).
pub fn build(triangles: &[[Vec3; 3]]) -> Result<Bvh> {
    build_from(triangles.len(), |id| triangles[id as usize])
}

/// [`build`] over `count` triangles that `triangle` gives by id (`0..count`), without a
/// flattened copy of them: the scene's indexed meshes stay the only one (issue 38: at 2 M
/// triangles a `[[Vec3; 3]]` array is 69 MiB of the build's peak).
///
/// # Errors
/// As [`build`].
pub fn build_from(count: usize, triangle: impl Fn(u32) -> [Vec3; 3] + Sync) -> Result<Bvh> {
    build_impl(count, &triangle, false, true)
}

/// [`build_from`] without the leaf-order positions: [`Bvh::tris`] is left empty, for a caller
/// that makes them from `prim_ids` where they are consumed (a renderer's upload writes them
/// chunk by chunk: issue 38, at 2 M triangles the array is 76 MiB held beside its device copy).
/// The nodes and `prim_ids` are [`build_from`]'s.
///
/// # Errors
/// As [`build`].
pub(crate) fn build_tree_from(count: usize, triangle: impl Fn(u32) -> [Vec3; 3] + Sync) -> Result<Bvh> {
    build_impl(count, &triangle, false, false)
}

/// [`build_from`]; `always_shape` sends the PLOC tree through the depth-bounding rewrite even
/// when it needs none (the tests compare both paths); without `positions` the leaf-order
/// positions are not made ([`build_tree_from`]).
fn build_impl(
    count: usize,
    triangle: &(impl Fn(u32) -> [Vec3; 3] + Sync),
    always_shape: bool,
    positions: bool,
) -> Result<Bvh> {
    if count >= MAX_TRIANGLES {
        return Err(Error::Scene {
            location: "BVH".into(),
            message: format!("{count} triangles exceed the {MAX_TRIANGLES} a BVH can address"),
        });
    }
    if count == 0 {
        // A root with eight empty slots: nothing is ever hit.
        let empty = BvhNode { exp_imask: 127 | 127 << 8 | 127 << 16, ..BvhNode::default() };
        return Ok(Bvh { nodes: vec![empty], tris: Vec::new(), prim_ids: Vec::new(), depth: 1 });
    }
    let (bvh2, ploc_depth, mut steps) = binary_tree(count, triangle, always_shape);
    // obvhs's `bvh2_to_cwbvh` with a decision table of 1 byte per (node, slot) instead of 8.
    let (cw_nodes, prim_ids) = convert::bvh2_to_cwbvh(&bvh2, BVH_LEAF_MAX);
    drop(bvh2);
    let nodes: Vec<BvhNode> = cw_nodes.iter().map(|n| bytemuck::cast(*n)).collect();
    drop(cw_nodes);
    steps.lap("convert");
    let tris =
        if positions { prim_ids.par_iter().map(|&id| leaf_positions(triangle(id))).collect() } else { Vec::new() };
    let depth = cw_depth(&nodes);
    steps.lap("positions");
    let bvh = Bvh { nodes, tris, prim_ids, depth };
    tracing::debug!(
        triangles = count,
        nodes = bvh.nodes.len(),
        depth = bvh.depth,
        ploc_depth,
        steps = %steps,
        "BVH built"
    );
    Ok(bvh)
}

/// The seconds of each step of a BVH build, for the debug log (`pathgrad -vv`).
struct Steps {
    last: Instant,
    laps: Vec<(&'static str, f64)>,
}

impl Steps {
    fn new() -> Steps {
        Steps { last: Instant::now(), laps: Vec::new() }
    }

    /// Ends step `name` now.
    fn lap(&mut self, name: &'static str) {
        let now = Instant::now();
        self.laps.push((name, (now - self.last).as_secs_f64()));
        self.last = now;
    }
}

impl std::fmt::Display for Steps {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, (name, seconds)) in self.laps.iter().enumerate() {
            write!(f, "{}{name} {seconds:.3} s", if i == 0 { "" } else { ", " })?;
        }
        Ok(())
    }
}

/// Triangles up to which the build runs obvhs's second reinsertion pass (at twice the first's
/// batch ratio). Above, the first pass alone: the second lowers the binary tree's summed half
/// area by under 1 % (6.86 → 6.79 at 200 k triangles, 7.60 → 7.54 at 2 M) and takes about twice
/// the first's time, which grows faster than the triangles (its searches miss the caches of a
/// large tree): at 2 M triangles it took a quarter of the BVH build, at 20 M 35–40 % (BENCHMARKS.md,
/// issue 38, eighth step).
const SECOND_REINSERTION_MAX: usize = 1 << 20;

/// Triangles up to which the build runs the first reinsertion pass; above, none. At 20 M
/// triangles the pass took 3.9–4.2 s of a 12 s BVH build (its searches miss the caches), while
/// the render that followed (256², 16 spp, depth 6) took 2.10–2.35 s with it and 2.20–2.41 s
/// without: the whole process went from 18.9–19.8 s to 13.9–14.4 s, its CPU time to that of
/// Mitsuba 3.9.1 (BENCHMARKS.md, issue 38: "the first reinsertion pass above 8 M triangles").
const FIRST_REINSERTION_MAX: usize = 1 << 23;

/// How many of obvhs's two reinsertion passes a build over `count` triangles runs.
fn reinsertion_passes(count: usize) -> u32 {
    const _: () = assert!(SECOND_REINSERTION_MAX < FIRST_REINSERTION_MAX);
    match count {
        c if c <= SECOND_REINSERTION_MAX => 2,
        c if c <= FIRST_REINSERTION_MAX => 1,
        _ => 0,
    }
}

/// The binary tree of one-triangle leaves that [`build_impl`] converts, with PLOC's depth and
/// the seconds of the steps so far (`count` > 0).
fn binary_tree(
    count: usize,
    triangle: &(impl Fn(u32) -> [Vec3; 3] + Sync),
    always_shape: bool,
) -> (Vec<Node2>, u32, Steps) {
    // The steps of obvhs's `build_bvh2_from_tris` for one-triangle leaves (the tree is the same),
    // without its debug-build validation, which panics on trees the reinsertion made deeper than
    // its own stack estimate (a fan-triangulated 1000-gon: depth 273 against 252). PLOC and
    // reinsertion are ours (`ploc`, `reinsert`: obvhs's, on 32-byte nodes and in smaller working
    // arrays), so neither a slice of obvhs `Triangle`s (48 bytes a triangle) nor obvhs's 48-byte
    // nodes are ever made (issue 38).
    let mut steps = Steps::new();
    let params = BvhBuildParams::medium_build();
    debug_assert!(matches!(params.ploc_search_distance, PlocSearchDistance::Medium));
    debug_assert!(matches!(params.sort_precision, SortPrecision::U64));
    // obvhs's PLOC (`PlocSearchDistance::Medium` is its search distance 14), in less memory.
    let mut nodes = ploc::build(count, triangle, params.search_depth_threshold);
    steps.lap("ploc");
    let passes = reinsertion_passes(count);
    if passes >= 1 {
        // The parent links (4 bytes a node) only where a pass runs.
        let mut parents = reinsert::parents(&nodes);
        reinsert::run(&mut nodes, &mut parents, params.reinsertion_batch_ratio);
        steps.lap("reinsertion");
        // obvhs's leaf collapse comes between the two passes; with leaves of one triangle it leaves
        // the tree as it is.
        if passes >= 2 {
            let ratio = params.reinsertion_batch_ratio * params.post_collapse_reinsertion_batch_ratio_multiplier;
            reinsert::run(&mut nodes, &mut parents, ratio);
            steps.lap("reinsertion 2");
        }
    }
    let ploc_depth = bvh2_height(&nodes);
    // A tree with one-triangle leaves is converted as PLOC left it, its subtrees too deep for the
    // stack rebuilt in place (`depth`): the rewrite below would give the same tree (same nodes,
    // numbered in depth-first order), and the conversion depends on the tree, not on the
    // numbering. The rewrite, whose arena holds the whole tree again (56 bytes a node and a heap
    // `Vec` a leaf: about 4.6 GiB at 20 M triangles, issue 38), is left for the tests.
    let bvh2 = if !always_shape {
        if ploc_depth > MAX_DEPTH {
            depth::bound_in_place(&mut nodes, triangle, MAX_DEPTH, REBUILD_DEPTH);
        }
        nodes
    } else {
        let arena: Vec<TmpNode> = nodes
            .iter()
            .map(|n| {
                let shape = if n.is_leaf() {
                    Shape::Leaf(vec![n.first_index])
                } else {
                    Shape::Inner([n.first_index as usize, n.first_index as usize + 1])
                };
                TmpNode { lo: n.min, hi: n.max, shape }
            })
            .collect();
        drop(nodes);
        let mut shaper = Shaper { triangle, arena, heights: Vec::new(), nodes: vec![Node2::default()] };
        shaper.heights = heights(&shaper.arena);
        shaper.place(0, 0, 1);
        shaper.nodes
    };
    steps.lap("depth");
    (bvh2, ploc_depth, steps)
}

/// Inner nodes on the longest path down from the root of the binary tree `nodes` (0 for a lone
/// leaf), as [`heights`] counts them: the subtrees below binary depth 10 on rayon's threads.
fn bvh2_height(nodes: &[Node2]) -> u32 {
    fn from(nodes: &[Node2], index: u32, depth: u32) -> u32 {
        let n = &nodes[index as usize];
        if n.prim_count != 0 {
            0
        } else if depth < 10 {
            let (a, b) =
                rayon::join(|| from(nodes, n.first_index, depth + 1), || from(nodes, n.first_index + 1, depth + 1));
            1 + a.max(b)
        } else {
            subtree_height(nodes, index)
        }
    }
    from(nodes, 0, 0)
}

/// [`bvh2_height`] of the subtree at node `root`, without recursion.
fn subtree_height(nodes: &[Node2], root: u32) -> u32 {
    let mut deepest = 0;
    let mut stack = vec![(root, 0u32)];
    while let Some((i, d)) = stack.pop() {
        let n = &nodes[i as usize];
        if n.prim_count == 0 {
            deepest = deepest.max(d + 1);
            stack.push((n.first_index, d + 1));
            stack.push((n.first_index + 1, d + 1));
        }
    }
    deepest
}

/// Nodes on the longest path from the root down, without recursion.
fn cw_depth(nodes: &[BvhNode]) -> u32 {
    let mut deepest = 0;
    let mut stack = vec![(0u32, 1u32)];
    while let Some((i, d)) = stack.pop() {
        deepest = deepest.max(d);
        let n = &nodes[i as usize];
        let inner = n.exp_imask >> 24;
        for k in 0..inner.count_ones() {
            stack.push((n.child_base + k, d + 1));
        }
    }
    deepest
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

/// Writes the arena's tree as a binary tree of one-triangle leaves (siblings adjacent, as
/// obvhs's), rebuilding subtrees that would be too deep.
struct Shaper<'a, F> {
    triangle: &'a F,
    arena: Vec<TmpNode>,
    heights: Vec<u32>,
    nodes: Vec<Node2>,
}

impl<F: Fn(u32) -> [Vec3; 3]> Shaper<'_, F> {
    /// Writes arena node `i` as binary node `slot` at depth `depth` (the root is 1), rebuilding
    /// it first if its subtree would not fit the stack or it is a leaf of several triangles.
    fn place(&mut self, mut i: usize, slot: usize, depth: u32) {
        let too_deep = matches!(self.arena[i].shape, Shape::Inner(_))
            && depth + self.heights[i] > MAX_DEPTH + 1
            && depth >= REBUILD_DEPTH;
        let wide_leaf = matches!(&self.arena[i].shape, Shape::Leaf(ids) if ids.len() > 1);
        if too_deep || wide_leaf {
            let mut ids = Vec::new();
            collect_leaves(&self.arena, i, &mut ids);
            i = self.median(&mut ids);
        }
        let (min, max) = (self.arena[i].lo, self.arena[i].hi);
        match self.arena[i].shape.clone() {
            Shape::Leaf(ids) => {
                self.nodes[slot] = Node2 { min, prim_count: 1, max, first_index: ids[0] };
            }
            Shape::Inner([a, b]) => {
                let first = self.nodes.len();
                self.nodes.push(Node2::default());
                self.nodes.push(Node2::default());
                self.nodes[slot] = Node2 { min, prim_count: 0, max, first_index: first as u32 };
                self.place(a, first, depth + 1);
                self.place(b, first + 1, depth + 1);
            }
        }
    }

    /// Builds a subtree over `ids` by splitting at the median centroid along the widest axis
    /// (halving every time, whatever the geometry) down to single triangles; its arena index.
    fn median(&mut self, ids: &mut [u32]) -> usize {
        let (lo, hi) = bounds(self.triangle, ids);
        if ids.len() == 1 {
            self.arena.push(TmpNode { lo, hi, shape: Shape::Leaf(ids.to_vec()) });
            self.heights.push(0);
            return self.arena.len() - 1;
        }
        let centroid = |id: u32| {
            let t = (self.triangle)(id);
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

fn bounds(triangle: &impl Fn(u32) -> [Vec3; 3], ids: &[u32]) -> (Vec3, Vec3) {
    ids.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(l, h), &id| {
        let t = triangle(id);
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
    // Not `(0.0..=1.0).contains`, which debug builds call out of line (see `rng::philox4x32_10`);
    // NaN fails both forms.
    #[allow(clippy::manual_range_contains)]
    if !(b1 >= 0.0 && b1 <= 1.0) {
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

/// The ray's octant as the children's traversal order wants it: byte-replicated bits 2, 1, 0 set
/// for non-negative x, y, z.
fn octant_inv4(dir: Vec3) -> u32 {
    (if dir.x < 0.0 { 0 } else { 0x0404_0404 })
        | (if dir.y < 0.0 { 0 } else { 0x0202_0202 })
        | (if dir.z < 0.0 { 0 } else { 0x0101_0101 })
}

/// Tests the ray against a node's eight child boxes; the hit mask: for an inner child hit, bit
/// 24 + (slot ^ octant), so that the highest bit is the child to visit first; for a leaf child
/// hit, its triangles' bits (offsets from `tri_base`) in the low 24 bits.
fn intersect_node(node: &BvhNode, ray: &Ray, octant: u32, tmin: f32, tmax: f32) -> u32 {
    let e = node.exp_imask;
    let cell = Vec3::new(
        f32::from_bits((e & 0xff) << 23),
        f32::from_bits(((e >> 8) & 0xff) << 23),
        f32::from_bits(((e >> 16) & 0xff) << 23),
    );
    // The ray in the node's grid: a plane at cell q is crossed at q·scale + offset.
    let scale = cell * ray.inv_dir;
    let offset = (node.origin - ray.origin) * ray.inv_dir;
    let mut mask = 0;
    // `while` loops: debug builds call `Range::next` out of line (see `rng::philox4x32_10`).
    let mut half = 0;
    while half < 2 {
        let m = if half == 0 { node.meta.x } else { node.meta.y };
        // Inner children's metas are 24 + slot with bits 3 and 4 both set, which no leaf has.
        let inner4 = (m & (m << 1)) & 0x1010_1010;
        let bit_index4 = (m ^ (octant & ((inner4 >> 4) * 0xff))) & 0x1f1f_1f1f;
        let child_bits4 = (m >> 5) & 0x0707_0707;
        let mut k = 0;
        while k < 4 {
            let slot = 4 * half + k;
            let q = |w: UVec2| child_byte(w, slot) as f32;
            let lo = Vec3::new(q(node.lo_x), q(node.lo_y), q(node.lo_z));
            let hi = Vec3::new(q(node.hi_x), q(node.hi_y), q(node.hi_z));
            let t0 = lo * scale + offset;
            let t1 = hi * scale + offset;
            let near = t0.min(t1).max_element().max(tmin);
            let far = (t0.max(t1).min_element() * BVH_FAR_SCALE).min(tmax);
            if near <= far {
                mask |= ((child_bits4 >> (8 * k)) & 0xff) << ((bit_index4 >> (8 * k)) & 0xff);
            }
            k += 1;
        }
        half += 1;
    }
    mask
}

/// The closest hit with `tmin < t < tmax`, or `None`. Same visiting order as `bvh_closest_hit`.
pub fn closest_hit(bvh: &Bvh, ray: &Ray, tmin: f32, tmax: f32) -> Option<Hit> {
    traverse(bvh, ray, tmin, tmax, false)
}

/// Whether anything lies on the ray with `tmin < t < tmax` (shadow rays).
pub fn occluded(bvh: &Bvh, ray: &Ray, tmin: f32, tmax: f32) -> bool {
    traverse(bvh, ray, tmin, tmax, true).is_some()
}

/// Ylitie et al.'s traversal, one step at a time: a step tests one pending triangle if there is
/// one, else visits the next inner child hit (highest bit first: the nearest for the ray's
/// octant) of the current node group, pushing the rest of the group. A group is a node's
/// `(child_base, inner hits << 24 | inner mask)`; the triangles pending are `(tri_base, bits)`.
/// When both are empty the next group is popped. Shadow rays use the same order and stop at the
/// first hit.
fn traverse(bvh: &Bvh, ray: &Ray, tmin: f32, mut tmax: f32, any_hit: bool) -> Option<Hit> {
    let octant = octant_inv4(ray.dir);
    let mut best: Option<Hit> = None;
    let mut stack = [UVec2::ZERO; BVH_STACK_SIZE as usize];
    let mut sp = 0usize;
    // The root, as the only inner child of a virtual group.
    let mut group = UVec2::new(0, 0x8000_0000);
    let mut tris = UVec2::ZERO;
    loop {
        if tris.y != 0 {
            let k = 31 - tris.y.leading_zeros();
            tris.y &= !(1 << k);
            let slot = tris.x + k;
            if let Some((t, b1, b2)) = intersect_triangle(ray, &bvh.tris[slot as usize], tmin, tmax) {
                tmax = t;
                best = Some(Hit { t, slot, b1, b2 });
                if any_hit {
                    return best;
                }
            }
        } else if group.y & 0xff00_0000 != 0 {
            let bit = 31 - group.y.leading_zeros();
            let slot = (bit - 24) ^ (octant & 0xff);
            let index = group.x + (group.y & !(u32::MAX << slot)).count_ones();
            group.y &= !(1 << bit);
            if group.y & 0xff00_0000 != 0 {
                stack[sp] = group;
                sp += 1;
            }
            let node = &bvh.nodes[index as usize];
            let hits = intersect_node(node, ray, octant, tmin, tmax);
            group = UVec2::new(node.child_base, (hits & 0xff00_0000) | (node.exp_imask >> 24));
            tris = UVec2::new(node.tri_base, hits & 0x00ff_ffff);
        }
        if tris.y == 0 && group.y & 0xff00_0000 == 0 {
            if sp == 0 {
                break;
            }
            sp -= 1;
            group = stack[sp];
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both reinsertion passes up to 1 M triangles, the first alone up to 8 M, none above.
    #[test]
    fn reinsertion_passes_drop_with_the_size() {
        assert_eq!(reinsertion_passes(1000), 2);
        assert_eq!(reinsertion_passes(SECOND_REINSERTION_MAX), 2);
        assert_eq!(reinsertion_passes(SECOND_REINSERTION_MAX + 1), 1);
        assert_eq!(reinsertion_passes(FIRST_REINSERTION_MAX), 1);
        assert_eq!(reinsertion_passes(FIRST_REINSERTION_MAX + 1), 0);
        assert_eq!(reinsertion_passes(20_000_000), 0);
    }

    fn tri(x: f32) -> [Vec3; 3] {
        [Vec3::new(x, -1.0, -1.0), Vec3::new(x, 1.0, -1.0), Vec3::new(x, -1.0, 1.0)]
    }

    /// Every leaf slot is in exactly one leaf, and the slots map back to every triangle once.
    fn assert_leaves_cover(bvh: &Bvh, n: usize) {
        let mut seen = vec![0u32; bvh.tris.len()];
        for leaf in bvh.leaves() {
            assert!(!leaf.is_empty() && leaf.len() <= BVH_LEAF_MAX as usize, "leaf {leaf:?}");
            for slot in leaf {
                seen[slot as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1), "slots covered {seen:?}");
        let mut ids = bvh.prim_ids.clone();
        ids.sort_unstable();
        assert_eq!(ids, (0..n as u32).collect::<Vec<_>>());
    }

    #[test]
    fn an_empty_bvh_is_never_hit() {
        let bvh = build(&[]).unwrap();
        let ray = Ray::new(Vec3::ZERO, Vec3::X);
        assert_eq!(closest_hit(&bvh, &ray, 0.0, f32::MAX), None);
        assert!(!occluded(&bvh, &ray, 0.0, f32::MAX));
    }

    #[test]
    fn a_single_triangle_is_hit_and_missed() {
        let bvh = build(&[tri(2.0)]).unwrap();
        assert_leaves_cover(&bvh, 1);
        let hit = closest_hit(&bvh, &Ray::new(Vec3::new(0.0, -0.5, -0.5), Vec3::X), 0.0, f32::MAX).unwrap();
        assert_eq!((hit.t, hit.slot), (2.0, 0));
        assert!(closest_hit(&bvh, &Ray::new(Vec3::new(0.0, 0.5, 0.5), Vec3::X), 0.0, f32::MAX).is_none());
        assert!(!occluded(&bvh, &Ray::new(Vec3::new(0.0, -0.5, -0.5), Vec3::X), 0.0, 1.5));
        assert!(occluded(&bvh, &Ray::new(Vec3::new(0.0, -0.5, -0.5), Vec3::X), 0.0, 2.5));
    }

    /// Stacked triangles along a ray: the closest is found from either side, whatever the octant.
    #[test]
    fn the_closest_of_many_is_found_from_both_sides() {
        let tris: Vec<[Vec3; 3]> = (0..100).map(|i| tri(i as f32 * 0.1)).collect();
        let bvh = build(&tris).unwrap();
        assert_leaves_cover(&bvh, tris.len());
        let forward = closest_hit(&bvh, &Ray::new(Vec3::new(-1.0, -0.5, -0.5), Vec3::X), 0.0, f32::MAX).unwrap();
        assert_eq!(bvh.prim_ids[forward.slot as usize], 0);
        let back = closest_hit(&bvh, &Ray::new(Vec3::new(20.0, -0.5, -0.5), -Vec3::X), 0.0, f32::MAX).unwrap();
        assert_eq!(bvh.prim_ids[back.slot as usize], 99);
    }

    /// A fan-triangulated 1000-gon, whose PLOC tree is ~270 deep, is bounded to fit the stack.
    #[test]
    fn a_deep_fan_fits_the_stack() {
        let ring = |k: u32| {
            let a = k as f32 / 1000.0 * std::f32::consts::TAU;
            Vec3::new(a.cos(), a.sin(), 0.0)
        };
        let tris: Vec<[Vec3; 3]> = (1..999).map(|k| [ring(0), ring(k), ring(k + 1)]).collect();
        let bvh = build(&tris).unwrap();
        assert!(bvh.depth < BVH_STACK_SIZE, "depth {}", bvh.depth);
        assert_leaves_cover(&bvh, tris.len());
        let hit = closest_hit(&bvh, &Ray::new(Vec3::new(0.3, 0.2, 1.0), -Vec3::Z), 0.0, f32::MAX).unwrap();
        assert!((hit.t - 1.0).abs() < 1e-6);
    }

    /// A tree that fits the stack is converted as PLOC left it, and a deeper one after its deep
    /// subtrees are rebuilt in place (issue 38); the rewrite into depth-first order that leaves of
    /// several triangles take gives the very same BVH.
    #[test]
    fn ploc_trees_convert_as_their_rewrite_does() {
        // A bumpy 60 x 40 grid (4 800 triangles, several PLOC passes) and 100 stacked triangles.
        let height = |x: u32, y: u32| ((x * 7 + y * 13) % 11) as f32 * 0.05;
        let p = |x: u32, y: u32| Vec3::new(x as f32 * 0.1, height(x, y), y as f32 * 0.1);
        let grid: Vec<[Vec3; 3]> = (0..60 * 40)
            .flat_map(|k| {
                let (x, y) = (k % 60, k / 60);
                [[p(x, y), p(x + 1, y), p(x + 1, y + 1)], [p(x, y), p(x + 1, y + 1), p(x, y + 1)]]
            })
            .collect();
        let stack: Vec<[Vec3; 3]> = (0..100).map(|i| tri(i as f32 * 0.1)).collect();
        // A fan whose PLOC tree is far too deep: rebuilt in place, it is the rewrite's tree.
        let ring = |k: u32| {
            let a = k as f32 / 1000.0 * std::f32::consts::TAU;
            Vec3::new(a.cos(), a.sin(), 0.0)
        };
        let fan: Vec<[Vec3; 3]> = (1..999).map(|k| [ring(0), ring(k), ring(k + 1)]).collect();
        for tris in [grid, stack, fan] {
            let get = |id: u32| tris[id as usize];
            let direct = build_impl(tris.len(), &get, false, true).unwrap();
            let rewritten = build_impl(tris.len(), &get, true, true).unwrap();
            assert_eq!(direct, rewritten);
            assert_leaves_cover(&direct, tris.len());
        }
    }

    #[test]
    fn the_tree_is_the_same_on_any_number_of_threads() {
        // A bumpy 250 x 200 grid (100 000 triangles: PLOC's chunks and the conversion's splits
        // depend on the thread count; many equal half areas) and a soup of 30 000.
        let height = |x: u32, y: u32| ((x * 7 + y * 13) % 11) as f32 * 0.05;
        let p = |x: u32, y: u32| Vec3::new(x as f32 * 0.1, height(x, y), y as f32 * 0.1);
        let grid: Vec<[Vec3; 3]> = (0..250 * 200)
            .flat_map(|k| {
                let (x, y) = (k % 250, k / 250);
                [[p(x, y), p(x + 1, y), p(x + 1, y + 1)], [p(x, y), p(x + 1, y + 1), p(x, y + 1)]]
            })
            .collect();
        let mut next = node2::xorshift(0x1357_9bdf);
        let soup: Vec<[Vec3; 3]> = (0..30_000)
            .map(|_| {
                let c = Vec3::new(next(), next(), next()) * 10.0;
                [c, c + Vec3::new(next(), 0.1, next()) * 0.2, c + Vec3::new(0.1, next(), next()) * 0.2]
            })
            .collect();
        for tris in [grid, soup] {
            let on = |threads: usize| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                pool.install(|| build(&tris).unwrap())
            };
            let one = on(1);
            assert_leaves_cover(&one, tris.len());
            for threads in [2, 3, 8] {
                assert!(on(threads) == one, "{} triangles: {threads} threads build another tree", tris.len());
            }
        }
    }
}
