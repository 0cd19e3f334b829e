//! The binary tree → CWBVH conversion: obvhs 0.4.0's `cwbvh::bvh2_to_cwbvh` (Ylitie et al. 2017,
//! after jan-van-bergen/GPU-Raytracer's `BVH8Converter.cpp`; obvhs is MIT / Apache-2.0), step for
//! step and float operation for float operation, so it gives the same nodes and leaf order —
//! with a decision table of one byte per (inner binary node, slot) instead of obvhs's eight per
//! (binary node, slot) (`Decision`: an f32 cost, a kind and two slot numbers; a leaf's are
//! constant, so the table holds inner nodes only, about 7 bytes a triangle). A decision's cost is read only by its parent, so
//! here each subtree returns its seven costs up the recursion instead of storing them (issue 38:
//! at 2 M triangles the table is 13 MiB instead of 214 MiB, which was the BVH build's summit).
//! Subtrees are costed and converted in parallel, then renumbered into obvhs's order.
//! `tests::converts_as_obvhs_does` compares both on several trees.

use std::sync::atomic::{AtomicU8, Ordering};

use glam::{Vec3A, vec3a};
use obvhs::cwbvh::node::CwBvhNode;
use rayon::prelude::*;

use super::node2::Node2;

/// A slot of a compressed node per ray octant, as obvhs: `order_children` assigns children to them.
const DIRECTIONS: usize = 8;
/// obvhs's `DENOM`: one over the largest quantised coordinate (255).
const DENOM: f32 = 1.0 / 255.0;
/// obvhs's `PRIM_COST`: a triangle's SAH cost relative to a node's.
const PRIM_COST: f32 = 0.3;
/// No child in a slot of `children`.
const EMPTY: u32 = u32::MAX;

/// What the node does in a slot budget, as obvhs's `DecisionKind`.
const LEAF: u8 = 0;
const INTERNAL: u8 = 1;
const DISTRIBUTE: u8 = 2;

/// One byte of the decision table: the kind in bits 0–1, the slots given to the left child in
/// bits 2–4 and to the right child in bits 5–7 (7 where obvhs has its `INVALID`, 255, which a
/// valid tree never reads).
#[derive(Clone, Copy, Default)]
struct Decision(u8);

impl Decision {
    fn new(kind: u8, left: u8, right: u8) -> Decision {
        Decision(kind | left.min(7) << 2 | right.min(7) << 5)
    }
    fn kind(self) -> u8 {
        self.0 & 3
    }
    fn left(self) -> usize {
        usize::from(self.0 >> 2 & 7)
    }
    fn right(self) -> usize {
        usize::from(self.0 >> 5)
    }
}

/// obvhs's `Decision::default()`: a distribution into slots 0 and 0.
const DEFAULT: Decision = Decision(DISTRIBUTE);

/// Binary depth above which `Converter::calculate_cost` costs a node's two subtrees in
/// parallel (up to 2¹⁰ tasks). Each task writes only its own nodes' decisions, so the result does
/// not depend on the thread count or on scheduling.
const PARALLEL_COST_DEPTH: u32 = 10;
/// Compressed depth above which `Converter::convert_subtree` converts a node's inner children in
/// parallel (up to 8³ subtrees), each numbered on its own and then renumbered into place.
const PARALLEL_CONVERT_DEPTH: u32 = 3;

/// Converts the binary tree `bvh2` (leaves of one primitive, `node2`'s: a leaf's `first_index` is
/// its primitive) into compressed 8-wide nodes with leaves of up to `max_prims_per_leaf` (at most
/// 3) primitives, children ordered by ray octant: the nodes and the primitive indices in leaf
/// order, equal to `bvh2_to_cwbvh(bvh2, max_prims_per_leaf, true, false)`'s on obvhs's
/// `Bvh2` of the same nodes and the identity primitive mapping. Subtrees are costed and
/// converted on rayon's threads (issue 38).
pub(super) fn bvh2_to_cwbvh(bvh2: &[Node2], max_prims_per_leaf: u32) -> (Vec<CwBvhNode>, Vec<u32>) {
    bvh2_to_cwbvh_split(bvh2, max_prims_per_leaf, PARALLEL_COST_DEPTH, PARALLEL_CONVERT_DEPTH)
}

/// [`bvh2_to_cwbvh`] with the depths down to which work is split (the tests vary them).
fn bvh2_to_cwbvh_split(
    bvh2: &[Node2],
    max_prims_per_leaf: u32,
    cost_depth: u32,
    convert_depth: u32,
) -> (Vec<CwBvhNode>, Vec<u32>) {
    if bvh2.is_empty() {
        return (Vec::new(), Vec::new());
    }
    let c = Converter {
        bvh2,
        decisions: (0..(bvh2.len() / 2 + 1) * 7).map(|_| AtomicU8::new(DEFAULT.0)).collect(),
        max_prims_per_leaf,
        cost_depth,
        convert_depth,
    };
    c.calculate_cost(0, 0);
    let root = match c.convert_parts(0, 0) {
        Parts::Whole(root) => root,
        Parts::Split(root, subtrees) => {
            // The decision table (7 bytes a binary node) is not needed to join.
            drop(c);
            join(root, subtrees)
        }
    };
    (root.nodes, root.primitive_indices)
}

struct Converter<'a> {
    bvh2: &'a [Node2],
    /// Seven [`Decision`]s per inner binary node (`Converter::slot`); each is written once, by
    /// the task costing its node.
    decisions: Vec<AtomicU8>,
    max_prims_per_leaf: u32,
    cost_depth: u32,
    convert_depth: u32,
}

/// A converted subtree numbered on its own: its root compressed node at 0, then its
/// descendants in obvhs's depth-first order, and its primitives in leaf order from 0.
struct Subtree {
    nodes: Vec<CwBvhNode>,
    primitive_indices: Vec<u32>,
}

impl Subtree {
    /// A subtree whose root's fields are set and whose descendants are still to be written.
    fn new() -> Subtree {
        Subtree { nodes: vec![CwBvhNode::default()], primitive_indices: Vec::new() }
    }

    /// Writes compressed node `index8` for binary node `index2` and recurses on its inner
    /// children (obvhs's `convert_to_cwbvh_impl`).
    fn convert(&mut self, c: &Converter, index8: usize, index2: usize) {
        let (node, children) = c.node(index2, self.nodes.len() as u32, &mut self.primitive_indices);
        self.nodes.resize(self.nodes.len() + node.imask.count_ones() as usize, CwBvhNode::default());
        self.nodes[index8] = node;
        let mut offset = 0;
        for (i, &child) in children.iter().enumerate() {
            if child != EMPTY && node.imask & (1 << i) != 0 {
                self.convert(c, (node.child_base_idx + offset) as usize, child as usize);
                offset += 1;
            }
        }
    }
}

/// A subtree converted in parts: whole, or its root (with its own leaves' primitives) and its
/// inner children's subtrees, still to be joined.
enum Parts {
    Whole(Subtree),
    Split(Subtree, Vec<Subtree>),
}

/// Joins root `out` and its inner children's `subtrees` into one subtree in obvhs's order: the
/// children's own nodes, then each one's descendants in turn. Each child's subtree is freed as
/// soon as it is copied, so the copy and the parts are never both whole (issue 38: at 20 M
/// triangles the compressed nodes and leaf order are about 230 MiB).
fn join(mut out: Subtree, subtrees: Vec<Subtree>) -> Subtree {
    let mut base = 1 + subtrees.len() as u32;
    let mut prims = out.primitive_indices.len() as u32;
    let mut shifts = Vec::with_capacity(subtrees.len());
    for sub in &subtrees {
        shifts.push((base - 1, prims));
        base += sub.nodes.len() as u32 - 1;
        prims += sub.primitive_indices.len() as u32;
    }
    out.nodes.reserve(base as usize - 1);
    out.primitive_indices.reserve(prims as usize - out.primitive_indices.len());
    let moved = |n: &CwBvhNode, (nodes, prims): (u32, u32)| CwBvhNode {
        child_base_idx: n.child_base_idx + nodes,
        primitive_base_idx: n.primitive_base_idx + prims,
        ..*n
    };
    for (sub, &shift) in subtrees.iter().zip(&shifts) {
        out.nodes.push(moved(&sub.nodes[0], shift));
    }
    for (sub, shift) in subtrees.into_iter().zip(shifts) {
        out.nodes.extend(sub.nodes[1..].iter().map(|n| moved(n, shift)));
        out.primitive_indices.extend_from_slice(&sub.primitive_indices);
    }
    out
}

impl Converter<'_> {
    /// Where inner binary node `node`'s seven decisions start: its children's pair, whose first
    /// index halved numbers the inner nodes (sibling pairs never overlap), so the table holds
    /// inner nodes only. A leaf's decisions are all `LEAF` and are not stored.
    fn slot(&self, node: usize) -> Option<usize> {
        let n = &self.bvh2[node];
        (!n.is_leaf()).then(|| n.first_index as usize / 2 * 7)
    }

    /// Node `node`'s decision for slot budget `k + 1`.
    fn decision(&self, node: usize, k: usize) -> Decision {
        match self.slot(node) {
            Some(at) => Decision(self.decisions[at + k].load(Ordering::Relaxed)),
            None => Decision::new(LEAF, 0, 0),
        }
    }

    /// Sets inner node `node`'s decision for slot budget `k + 1`.
    fn set_decision(&self, node: usize, k: usize, d: Decision) {
        let at = self.slot(node).expect("only inner nodes' decisions are stored");
        self.decisions[at + k].store(d.0, Ordering::Relaxed);
    }

    /// Fills node `node_index`'s seven decisions and returns its primitive count and the seven
    /// decisions' costs (obvhs's `calculate_cost_impl`); `depth` is the node's (the root's 0).
    fn calculate_cost(&self, node_index: usize, depth: u32) -> (u32, [f32; 7]) {
        let node = &self.bvh2[node_index];
        let half_area = node.aabb().half_area();
        let (first_index, prim_count) = (node.first_index as usize, node.prim_count);
        let mut costs = [0.0f32; 7];
        if prim_count != 0 {
            assert_eq!(prim_count, 1, "the conversion expects leaves of one primitive");
            let cost_leaf = half_area * (prim_count as f32) * PRIM_COST;
            costs = [cost_leaf; 7];
            return (prim_count, costs);
        }
        let ((left_count, left), (right_count, right)) = if depth < self.cost_depth {
            rayon::join(
                || self.calculate_cost(first_index, depth + 1),
                || self.calculate_cost(first_index + 1, depth + 1),
            )
        } else {
            (self.calculate_cost(first_index, depth + 1), self.calculate_cost(first_index + 1, depth + 1))
        };
        let num_primitives = left_count + right_count;
        // Slot budget 1 (i = 0; i = 1 in the paper).
        {
            let cost_leaf = if num_primitives <= self.max_prims_per_leaf {
                (num_primitives as f32) * half_area * PRIM_COST
            } else {
                f32::INFINITY
            };
            let (mut cost_distribute, mut distribute_left, mut distribute_right) = (f32::INFINITY, u8::MAX, u8::MAX);
            for k in 0..7 {
                let c = left[k] + right[6 - k];
                if c < cost_distribute {
                    cost_distribute = c;
                    distribute_left = k as u8;
                    distribute_right = 6 - k as u8;
                }
            }
            let cost_internal = cost_distribute + half_area;
            let (kind, cost) = if cost_leaf < cost_internal { (LEAF, cost_leaf) } else { (INTERNAL, cost_internal) };
            self.set_decision(node_index, 0, Decision::new(kind, distribute_left, distribute_right));
            costs[0] = cost;
        }
        // Slot budgets 2–7 (the paper's i = 2..7).
        for i in 1..7 {
            let mut cost_distribute = costs[i - 1];
            let (mut distribute_left, mut distribute_right) = (u8::MAX, u8::MAX);
            for k in 0..i {
                let c = left[k] + right[i - k - 1];
                if c < cost_distribute {
                    cost_distribute = c;
                    distribute_left = k as u8;
                    distribute_right = (i - k - 1) as u8;
                }
            }
            costs[i] = cost_distribute;
            let d = if distribute_left != u8::MAX {
                Decision::new(DISTRIBUTE, distribute_left, distribute_right)
            } else {
                self.decision(node_index, i - 1)
            };
            self.set_decision(node_index, i, d);
        }
        (num_primitives, costs)
    }

    /// The subtree under binary node `index2`, at compressed depth `depth` (the root's 0): above
    /// `convert_depth` its inner children's subtrees are converted in parallel, each numbered on
    /// its own, then renumbered into place — the numbers obvhs's single depth-first pass gives,
    /// as in it a compressed node's descendants and primitives are each one contiguous run.
    fn convert_subtree(&self, index2: usize, depth: u32) -> Subtree {
        match self.convert_parts(index2, depth) {
            Parts::Whole(out) => out,
            Parts::Split(out, subtrees) => join(out, subtrees),
        }
    }

    /// [`Converter::convert_subtree`] with its last step, the join of the parallel parts, left to
    /// the caller (the root's is made after the decision table is freed).
    fn convert_parts(&self, index2: usize, depth: u32) -> Parts {
        let mut out = Subtree::new();
        if depth >= self.convert_depth {
            out.convert(self, 0, index2);
            return Parts::Whole(out);
        }
        let (node, children) = self.node(index2, 1, &mut out.primitive_indices);
        let inner: Vec<usize> = (0..8)
            .filter(|&i| children[i] != EMPTY && node.imask & (1 << i) != 0)
            .map(|i| children[i] as usize)
            .collect();
        let subtrees: Vec<Subtree> = inner.par_iter().map(|&child| self.convert_subtree(child, depth + 1)).collect();
        out.nodes[0] = node;
        Parts::Split(out, subtrees)
    }

    /// Compressed node for binary node `index2`, its children's first index `child_base` and
    /// its leaves' primitives appended to `primitive_indices`; its binary children by slot.
    fn node(&self, index2: usize, child_base: u32, primitive_indices: &mut Vec<u32>) -> (CwBvhNode, [u32; 8]) {
        let mut node = CwBvhNode::default();
        let aabb = self.bvh2[index2].aabb();
        let node_p = aabb.min;
        node.p = node_p.into();
        let e = ((aabb.max - aabb.min).max(Vec3A::splat(1e-20)) * DENOM).log2().ceil().exp2();
        let rcp_e = 1.0 / e;
        // Only the exponent bits of `e` are set.
        node.e = [(e.x.to_bits() >> 23) as u8, (e.y.to_bits() >> 23) as u8, (e.z.to_bits() >> 23) as u8];
        let mut children = [EMPTY; 8];
        let mut child_count = 0;
        self.get_children(index2, &mut children, &mut child_count, 0);
        self.order_children(index2, &mut children, child_count);
        node.imask = 0;
        node.primitive_base_idx = primitive_indices.len() as u32;
        node.child_base_idx = child_base;
        let mut num_primitives = 0u32;
        for (i, &child) in children.iter().enumerate() {
            if child == EMPTY {
                continue;
            }
            let child_aabb = self.bvh2[child as usize].aabb();
            // obvhs's PAD of 0, kept so the float operations are the same.
            const PAD: f32 = 0.0;
            let child_min = ((child_aabb.min - node_p - PAD) * rcp_e).floor().clamp(Vec3A::ZERO, Vec3A::splat(255.0));
            let child_max = ((child_aabb.max - node_p + PAD) * rcp_e).ceil().clamp(Vec3A::ZERO, Vec3A::splat(255.0));
            node.child_min_x[i] = child_min.x as u8;
            node.child_min_y[i] = child_min.y as u8;
            node.child_min_z[i] = child_min.z as u8;
            node.child_max_x[i] = child_max.x as u8;
            node.child_max_y[i] = child_max.y as u8;
            node.child_max_z[i] = child_max.z as u8;
            if self.decision(child as usize, 0).kind() == LEAF {
                let count = self.count_primitives(child as usize, primitive_indices);
                node.child_meta[i] = num_primitives as u8
                    | match count {
                        1 => 0b0010_0000,
                        2 => 0b0110_0000,
                        3 => 0b1110_0000,
                        _ => unreachable!("a leaf holds 1 to 3 primitives, not {count}"),
                    };
                num_primitives += count;
            } else {
                // INTERNAL: a child's slot-budget-1 decision is never a distribution.
                node.imask |= 1 << i;
                node.child_meta[i] = (24 + i as u8) | 0b0010_0000;
            }
        }
        (node, children)
    }

    /// Appends the primitives under binary node `index` in leaf order; their count.
    fn count_primitives(&self, index: usize, primitive_indices: &mut Vec<u32>) -> u32 {
        let node = self.bvh2[index];
        if node.is_leaf() {
            primitive_indices.push(node.first_index);
            return node.prim_count;
        }
        self.count_primitives(node.first_index as usize, primitive_indices)
            + self.count_primitives(node.first_index as usize + 1, primitive_indices)
    }

    /// The binary nodes that become the children of compressed node `index` with slot budget `i`.
    fn get_children(&self, index: usize, children: &mut [u32; 8], child_count: &mut usize, i: usize) {
        let node = &self.bvh2[index];
        if node.is_leaf() {
            children[*child_count] = index as u32;
            *child_count += 1;
            return;
        }
        let decision = self.decision(index, i);
        let first = node.first_index as usize;
        for (child, budget) in [(first, decision.left()), (first + 1, decision.right())] {
            if self.decision(child, budget).kind() == DISTRIBUTE {
                self.get_children(child, children, child_count, budget);
            } else {
                children[*child_count] = child as u32;
                *child_count += 1;
            }
        }
    }

    /// Assigns the children to the slots of the ray octants, greedily by the dot product of the
    /// octant's direction with the child's offset from the parent's centre (obvhs's
    /// `order_children`).
    fn order_children(&self, index: usize, children: &mut [u32; 8], child_count: usize) {
        let p = self.bvh2[index].aabb().center();
        let mut cost = [[f32::MAX; DIRECTIONS]; 8];
        for (row, &child) in cost.iter_mut().zip(children.iter()).take(child_count) {
            let v = self.bvh2[child as usize].aabb().center() - p;
            for (s, slot) in row.iter_mut().enumerate() {
                let d = vec3a(
                    if s & 0b100 != 0 { -1.0 } else { 1.0 },
                    if s & 0b010 != 0 { -1.0 } else { 1.0 },
                    if s & 0b001 != 0 { -1.0 } else { 1.0 },
                );
                *slot = d.dot(v);
            }
        }
        let mut assignment = [usize::MAX; 8];
        let mut slot_filled = [false; DIRECTIONS];
        loop {
            let (mut min_cost, mut min_slot, mut min_index) = (f32::MAX, usize::MAX, usize::MAX);
            for c in 0..child_count {
                if assignment[c] == usize::MAX {
                    for (s, &filled) in slot_filled.iter().enumerate() {
                        if !filled && cost[c][s] < min_cost {
                            (min_cost, min_slot, min_index) = (cost[c][s], s, c);
                        }
                    }
                }
            }
            if min_slot == usize::MAX {
                break;
            }
            slot_filled[min_slot] = true;
            assignment[min_index] = min_slot;
        }
        let original = std::mem::replace(children, [EMPTY; 8]);
        for c in 0..child_count {
            children[assignment[c]] = original[c];
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    /// Deterministic pseudo-random triangles: a soup of `n` small triangles in a unit cube,
    /// some of them degenerate.
    fn soup(n: u32) -> Vec<[Vec3; 3]> {
        let mut next = super::super::node2::xorshift(0x9e37_79b9);
        (0..n)
            .map(|k| {
                let c = Vec3::new(next(), next(), next());
                let s = if k % 17 == 0 { 0.0 } else { 0.05 };
                [c, c + Vec3::new(next(), next(), 0.0) * s, c + Vec3::new(0.0, next(), next()) * s]
            })
            .collect()
    }

    #[test]
    fn converts_as_obvhs_does() {
        let grid: Vec<[Vec3; 3]> = (0..60 * 60)
            .map(|k| {
                let (x, y) = ((k % 60) as f32, (k / 60) as f32);
                [Vec3::new(x, y, 0.0), Vec3::new(x + 1.0, y, 0.0), Vec3::new(x, y + 1.0, 0.1 * x)]
            })
            .collect();
        for tris in [soup(1), soup(2), soup(9), soup(1000), soup(20_000), grid] {
            let bvh2 = super::super::binary_tree(tris.len(), &|id| tris[id as usize], false).0;
            let wide = super::super::node2::widen(&bvh2);
            let theirs = obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh(&wide, crate::contract::BVH_LEAF_MAX, true, false);
            // Serial, the default split, and splits so deep that most subtrees are renumbered.
            for (cost_depth, convert_depth) in [(0, 0), (PARALLEL_COST_DEPTH, PARALLEL_CONVERT_DEPTH), (40, 12)] {
                let ours = bvh2_to_cwbvh_split(&bvh2, crate::contract::BVH_LEAF_MAX, cost_depth, convert_depth);
                let n = tris.len();
                assert!(ours.0 == theirs.nodes, "nodes differ at {n} triangles, split {cost_depth}/{convert_depth}");
                assert_eq!(ours.1, theirs.primitive_indices, "leaf order at {n} triangles, split {convert_depth}");
            }
        }
    }
}
