//! Bounding the binary tree's depth in place: the subtrees too deep for the traversal stack are
//! rebuilt by median splits in the very slots they take, into the tree `bvh::Shaper` makes by
//! rewriting the whole tree (issue 38: at 20 M triangles PLOC's tree is deeper than the stack
//! allows, and the rewrite's arena of the whole tree took about 4.6 GiB and most of two minutes).

use glam::{Vec3, Vec3A};
use obvhs::aabb::Aabb;

use super::node2::Node2;

/// Rebuilds every subtree of the binary tree `nodes` rooted at depth `rebuild_depth`
/// (the root's is 1) whose height would take it past `max_depth` + 1, as `Shaper::place` does:
/// by median splits over its triangles (`triangle` by id). A binary tree of k leaves
/// has k − 1 sibling pairs whatever its shape, so the rebuilt subtree takes the old one's pairs.
pub(super) fn bound_in_place(
    nodes: &mut [Node2],
    triangle: &impl Fn(u32) -> [Vec3; 3],
    max_depth: u32,
    rebuild_depth: u32,
) {
    let mut roots = Vec::new();
    let mut stack = vec![(0u32, 1u32)];
    while let Some((i, d)) = stack.pop() {
        let n = &nodes[i as usize];
        if n.prim_count > 0 {
            continue;
        }
        debug_assert!(d <= rebuild_depth);
        if d == rebuild_depth {
            roots.push(i);
        } else {
            stack.push((n.first_index, d + 1));
            stack.push((n.first_index + 1, d + 1));
        }
    }
    for root in roots {
        if rebuild_depth + height(nodes, root) > max_depth + 1 {
            rebuild(nodes, triangle, root);
        }
    }
}

/// Inner nodes on the longest path down from node `i` (0 for a leaf), without recursion.
fn height(nodes: &[Node2], i: u32) -> u32 {
    let mut deepest = 0;
    let mut stack = vec![(i, 0u32)];
    while let Some((j, d)) = stack.pop() {
        let n = &nodes[j as usize];
        if n.prim_count == 0 {
            deepest = deepest.max(d + 1);
            stack.push((n.first_index, d + 1));
            stack.push((n.first_index + 1, d + 1));
        }
    }
    deepest
}

/// Rebuilds the subtree at node `root` by median splits in its own slots.
fn rebuild(nodes: &mut [Node2], triangle: &impl Fn(u32) -> [Vec3; 3], root: u32) {
    // Its leaves' triangle ids, left to right (`collect_leaves`' order), and the first slots of
    // its sibling pairs.
    let mut leaves = Vec::new();
    let mut pairs = Vec::new();
    let mut stack = vec![root];
    while let Some(j) = stack.pop() {
        let n = nodes[j as usize];
        if n.prim_count > 0 {
            leaves.push(n.first_index);
        } else {
            pairs.push(n.first_index);
            stack.push(n.first_index + 1);
            stack.push(n.first_index);
        }
    }
    median(nodes, triangle, &mut leaves, root as usize, &mut pairs);
    debug_assert!(pairs.is_empty());
}

/// Writes the subtree of median splits over the triangles `leaves` at slot `slot`, its inner nodes' children in the sibling pairs taken from `pairs`:
/// `Shaper::median`'s tree (widest axis of the centroids, the lower half by centroid then id on
/// the left), with its boxes.
fn median(
    nodes: &mut [Node2],
    triangle: &impl Fn(u32) -> [Vec3; 3],
    leaves: &mut [u32],
    slot: usize,
    pairs: &mut Vec<u32>,
) {
    let (lo, hi) = leaves.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(l, h), &id| {
        let t = triangle(id);
        (l.min(t[0]).min(t[1]).min(t[2]), h.max(t[0]).max(t[1]).max(t[2]))
    });
    let aabb = Aabb::new(Vec3A::from(lo), Vec3A::from(hi));
    if let [id] = leaves {
        nodes[slot] = Node2::new(aabb, 1, *id);
        return;
    }
    let centroid = |id: u32| {
        let t = triangle(id);
        t[0] + t[1] + t[2]
    };
    let (clo, chi) = leaves.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(l, h), &id| {
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
    let mid = leaves.len() / 2;
    leaves.select_nth_unstable_by(mid, |&a, &b| centroid(a)[axis].total_cmp(&centroid(b)[axis]).then(a.cmp(&b)));
    let pair = pairs.pop().expect("a subtree of k leaves has k - 1 sibling pairs");
    nodes[slot] = Node2::new(aabb, 0, pair);
    let (left, right) = leaves.split_at_mut(mid);
    median(nodes, triangle, left, pair as usize, pairs);
    median(nodes, triangle, right, pair as usize + 1, pairs);
}
