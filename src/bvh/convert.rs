//! The binary tree → CWBVH conversion: obvhs 0.4.0's `cwbvh::bvh2_to_cwbvh` (Ylitie et al. 2017,
//! after jan-van-bergen/GPU-Raytracer's `BVH8Converter.cpp`; obvhs is MIT / Apache-2.0), step for
//! step and float operation for float operation, so it gives the same nodes and leaf order —
//! with a decision table of one byte per (binary node, slot) instead of obvhs's eight (`Decision`:
//! an f32 cost, a kind and two slot numbers). A decision's cost is read only by its parent, so
//! here each subtree returns its seven costs up the recursion instead of storing them (issue 38:
//! at 2 M triangles the table is 27 MiB instead of 214 MiB, which was the BVH build's summit).
//! `tests::converts_as_obvhs_does` compares both on several trees.

use glam::{Vec3A, vec3a};
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::node::CwBvhNode;

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

/// Converts `bvh2` (leaves of one primitive) into compressed 8-wide nodes with leaves of up to
/// `max_prims_per_leaf` (at most 3) primitives, children ordered by ray octant: the nodes and the
/// primitive indices in leaf order, equal to `bvh2_to_cwbvh(bvh2, max_prims_per_leaf, true,
/// false)`'s.
pub(super) fn bvh2_to_cwbvh(bvh2: &Bvh2, max_prims_per_leaf: u32) -> (Vec<CwBvhNode>, Vec<u32>) {
    if bvh2.nodes.is_empty() {
        return (Vec::new(), Vec::new());
    }
    // obvhs's capacities: one node per primitive is more than a tree of 8-wide nodes needs, and
    // what is never written is never touched, so growing never copies the nodes.
    let mut nodes = Vec::with_capacity(bvh2.primitive_indices.len());
    nodes.push(CwBvhNode::default());
    let mut c = Converter {
        bvh2,
        nodes,
        primitive_indices: Vec::with_capacity(bvh2.primitive_indices.len()),
        decisions: vec![DEFAULT; bvh2.nodes.len() * 7],
    };
    c.calculate_cost(0, max_prims_per_leaf);
    c.convert(0, 0);
    (c.nodes, c.primitive_indices)
}

struct Converter<'a> {
    bvh2: &'a Bvh2,
    nodes: Vec<CwBvhNode>,
    primitive_indices: Vec<u32>,
    decisions: Vec<Decision>,
}

impl Converter<'_> {
    /// Fills node `node_index`'s seven decisions and returns its primitive count and the seven
    /// decisions' costs (obvhs's `calculate_cost_impl`).
    fn calculate_cost(&mut self, node_index: usize, max_prims_per_leaf: u32) -> (u32, [f32; 7]) {
        let node = &self.bvh2.nodes[node_index];
        let half_area = node.aabb().half_area();
        let (first_index, prim_count) = (node.first_index as usize, node.prim_count);
        let at = node_index * 7;
        let mut costs = [0.0f32; 7];
        if prim_count != 0 {
            assert_eq!(prim_count, 1, "the conversion expects leaves of one primitive");
            let cost_leaf = half_area * (prim_count as f32) * PRIM_COST;
            costs = [cost_leaf; 7];
            self.decisions[at..at + 7].fill(Decision::new(LEAF, 0, 0));
            return (prim_count, costs);
        }
        let (left_count, left) = self.calculate_cost(first_index, max_prims_per_leaf);
        let (right_count, right) = self.calculate_cost(first_index + 1, max_prims_per_leaf);
        let num_primitives = left_count + right_count;
        // Slot budget 1 (i = 0; i = 1 in the paper).
        {
            let cost_leaf = if num_primitives <= max_prims_per_leaf {
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
            self.decisions[at] = Decision::new(kind, distribute_left, distribute_right);
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
            self.decisions[at + i] = if distribute_left != u8::MAX {
                Decision::new(DISTRIBUTE, distribute_left, distribute_right)
            } else {
                self.decisions[at + i - 1]
            };
        }
        (num_primitives, costs)
    }

    /// Writes compressed node `index8` for binary node `index2` and recurses on its inner
    /// children (obvhs's `convert_to_cwbvh_impl`).
    fn convert(&mut self, index8: usize, index2: usize) {
        let mut node = self.nodes[index8];
        let aabb = self.bvh2.nodes[index2].aabb();
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
        node.primitive_base_idx = self.primitive_indices.len() as u32;
        node.child_base_idx = self.nodes.len() as u32;
        let (mut num_internal_nodes, mut num_primitives) = (0, 0u32);
        for (i, &child) in children.iter().enumerate() {
            if child == EMPTY {
                continue;
            }
            let child_aabb = self.bvh2.nodes[child as usize].aabb();
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
            if self.decisions[child as usize * 7].kind() == LEAF {
                let count = self.count_primitives(child as usize);
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
                num_internal_nodes += 1;
            }
        }
        self.nodes.resize(self.nodes.len() + num_internal_nodes, CwBvhNode::default());
        self.nodes[index8] = node;
        let mut offset = 0;
        for (i, &child) in children.iter().enumerate() {
            if child != EMPTY && node.imask & (1 << i) != 0 {
                self.convert((node.child_base_idx + offset) as usize, child as usize);
                offset += 1;
            }
        }
    }

    /// Appends the primitives under binary node `index` in leaf order; their count.
    fn count_primitives(&mut self, index: usize) -> u32 {
        let node = self.bvh2.nodes[index];
        if node.is_leaf() {
            self.primitive_indices.push(self.bvh2.primitive_indices[node.first_index as usize]);
            return node.prim_count;
        }
        self.count_primitives(node.first_index as usize) + self.count_primitives(node.first_index as usize + 1)
    }

    /// The binary nodes that become the children of compressed node `index` with slot budget `i`.
    fn get_children(&self, index: usize, children: &mut [u32; 8], child_count: &mut usize, i: usize) {
        let node = &self.bvh2.nodes[index];
        if node.is_leaf() {
            children[*child_count] = index as u32;
            *child_count += 1;
            return;
        }
        let decision = self.decisions[index * 7 + i];
        let first = node.first_index as usize;
        for (child, budget) in [(first, decision.left()), (first + 1, decision.right())] {
            if self.decisions[child * 7 + budget].kind() == DISTRIBUTE {
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
        let p = self.bvh2.nodes[index].aabb().center();
        let mut cost = [[f32::MAX; DIRECTIONS]; 8];
        for (row, &child) in cost.iter_mut().zip(children.iter()).take(child_count) {
            let v = self.bvh2.nodes[child as usize].aabb().center() - p;
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
        let mut state = 0x9e37_79b9u32;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        };
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
            let ours = bvh2_to_cwbvh(&bvh2, crate::contract::BVH_LEAF_MAX);
            let theirs = obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh(&bvh2, crate::contract::BVH_LEAF_MAX, true, false);
            assert!(ours.0 == theirs.nodes, "nodes differ at {} triangles", tris.len());
            assert_eq!(ours.1, theirs.primitive_indices, "leaf order at {} triangles", tris.len());
        }
    }
}
