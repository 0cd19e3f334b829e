//! The binary tree between PLOC and the CWBVH conversion, in 32-byte nodes (obvhs's `Bvh2Node`
//! is 48: issue 38, at 20 M triangles its 2N − 1 nodes were 1.8 GiB of the build's summit).

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec3A};
use obvhs::aabb::Aabb;

/// A node of the binary tree: an inner node (`prim_count` 0) whose children are nodes
/// `first_index` and `first_index + 1`, or a leaf of one triangle whose id is `first_index` (the
/// identity primitive mapping of obvhs's one-triangle leaves, so the tree needs no
/// `primitive_indices`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub(super) struct Node2 {
    /// The box's lower corner.
    pub min: Vec3,
    /// 0 for an inner node, 1 for a leaf.
    pub prim_count: u32,
    /// The box's upper corner.
    pub max: Vec3,
    /// The first child (inner node) or the triangle id (leaf).
    pub first_index: u32,
}

impl Node2 {
    /// A node with box `aabb` (its coordinates are kept exactly).
    pub fn new(aabb: Aabb, prim_count: u32, first_index: u32) -> Node2 {
        Node2 { min: aabb.min.into(), prim_count, max: aabb.max.into(), first_index }
    }

    /// The node's box as obvhs's `Aabb` (the same floats), so that the conversion's float
    /// operations are obvhs's.
    pub fn aabb(&self) -> Aabb {
        Aabb::new(Vec3A::from(self.min), Vec3A::from(self.max))
    }

    /// Whether the node is a leaf.
    pub fn is_leaf(&self) -> bool {
        self.prim_count != 0
    }
}

/// obvhs's binary tree for `nodes` (identity primitive mapping), for the tests that compare with
/// obvhs's code.
/// The BVH tests' deterministic uniforms in [0, 1]: Marsaglia's 32-bit xorshift from `seed`.
#[cfg(test)]
pub(super) fn xorshift(seed: u32) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    }
}

#[cfg(test)]
pub(super) fn widen(nodes: &[Node2]) -> obvhs::bvh2::Bvh2 {
    use obvhs::bvh2::{Bvh2, node::Bvh2Node};
    let mut bvh = Bvh2::zeroed(0);
    bvh.nodes = nodes.iter().map(|n| Bvh2Node::new(n.aabb(), n.prim_count, n.first_index)).collect();
    let leaves = nodes.iter().filter(|n| n.is_leaf()).count() as u32;
    bvh.primitive_indices = (0..leaves).collect();
    bvh
}
