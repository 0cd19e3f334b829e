//! Reinsertion (Meister & Bittner 2022, "Parallel Reinsertion for Bounding Volume Hierarchy
//! Optimization"): obvhs 0.4.0's `ReinsertionOptimizer` (obvhs is MIT / Apache-2.0; after
//! madmann91/bvh's `reinsertion_optimizer.h`) on `node2`'s 32-byte nodes instead of obvhs's
//! 48-byte `Bvh2Node`s (issue 38: at 20 M triangles obvhs's tree and reinsertion arrays set the
//! build's memory summit), float operation for float operation. Candidates of equal cost are
//! taken in node order where obvhs's radix sort leaves them in an order of its own, so the
//! trees are the same where no two candidates' half areas are equal;
//! `tests::reinserts_as_obvhs_does` compares both.

use glam::Vec3;
use rayon::prelude::*;

use super::node2::Node2;

/// A reinsertion: node `from` moved next to node `to`, lowering the tree's summed half area by
/// `area_diff` (obvhs's `Reinsertion`).
#[derive(Clone, Copy, Default)]
struct Reinsertion {
    from: u32,
    to: u32,
    area_diff: f32,
}

/// The node on the other side of `node`'s sibling pair (children `2k + 1`, `2k + 2`).
fn sibling(node: usize) -> usize {
    if node % 2 == 1 { node + 1 } else { node - 1 }
}

/// The first (left) node of `node`'s sibling pair.
fn left_sibling(node: usize) -> usize {
    if node % 2 == 1 { node } else { node - 1 }
}

fn half_area(min: Vec3, max: Vec3) -> f32 {
    let d = max - min;
    (d.x + d.y) * d.z + d.x * d.y
}

/// obvhs's `ReinsertionOptimizer::run(bvh, batch_size_ratio, None)` on a tree of `node2` nodes
/// whose parents are `parents` (made by [`parents`]; kept up to date here).
pub(super) fn run(nodes: &mut [Node2], parents: &mut [u32], batch_size_ratio: f32) {
    if nodes.is_empty() || nodes[0].is_leaf() || batch_size_ratio <= 0.0 {
        return;
    }
    let cap = (nodes.len() as f32 * batch_size_ratio.min(1.0)).ceil() as usize;
    let mut candidates: Vec<(u32, f32)> = Vec::with_capacity(cap);
    let mut reinsertions: Vec<Reinsertion> = Vec::with_capacity(cap);
    let mut touched = vec![false; nodes.len()];
    let mut marked: Vec<usize> = Vec::new();
    for n in (1..32).step_by(2) {
        let ratio = 1.0 / n as f32;
        let batch_size = (((nodes.len() as f32 * batch_size_ratio) * ratio) as usize).max(1);
        let node_count = nodes.len().min(batch_size + 1);
        let count = node_count - 1;
        largest_first(nodes, node_count, &mut candidates);
        reinsertions.resize(count, Reinsertion::default());
        let tree: &[Node2] = nodes;
        let up: &[u32] = parents;
        // Each rayon job keeps one search stack for all its candidates.
        reinsertions.par_iter_mut().enumerate().for_each_init(
            || Vec::with_capacity(64),
            |stack, (i, r)| *r = find_reinsertion(tree, up, candidates[i].0 as usize, stack),
        );
        reinsertions.par_sort_unstable_by(|a, b| b.area_diff.partial_cmp(&a.area_diff).unwrap());
        for r in &reinsertions {
            if r.area_diff <= 0.0 {
                continue;
            }
            let (from, to) = (r.from as usize, r.to as usize);
            let conflicts = [to, from, sibling(from), parents[to] as usize, parents[from] as usize];
            if conflicts.iter().any(|&c| touched[c]) {
                continue;
            }
            for c in conflicts {
                touched[c] = true;
            }
            marked.extend(conflicts);
            reinsert_node(nodes, parents, from, to);
        }
        // Unmarked for the next batch (cheaper than clearing every node's flag).
        for c in marked.drain(..) {
            touched[c] = false;
        }
    }
}

/// Into `candidates`, the `node_count - 1` of the first `2 node_count` nodes (the root left
/// out) with the largest half areas, largest first, ties in node order — the head of a stable
/// sort of all `2 node_count - 1` by half area, which is what the search reads. Node order
/// breaks the ties, so the order is total, and a selection followed by an unstable sort of the
/// selected gives the same sequence in half the sorting.
fn largest_first(nodes: &[Node2], node_count: usize, candidates: &mut Vec<(u32, f32)>) {
    let take = nodes.len().min(node_count * 2);
    candidates.clear();
    candidates
        .par_extend(nodes[..take].par_iter().enumerate().skip(1).map(|(i, n)| (i as u32, half_area(n.min, n.max))));
    let count = node_count - 1;
    let order = |a: &(u32, f32), b: &(u32, f32)| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0));
    if count < candidates.len() {
        candidates.select_nth_unstable_by(count, order);
    }
    candidates[..count].par_sort_unstable_by(order);
    candidates.truncate(count);
}

/// Each node's parent (the root's is 0), as obvhs's `Bvh2::compute_parents`.
pub(super) fn parents(nodes: &[Node2]) -> Vec<u32> {
    let mut parents = vec![0u32; nodes.len()];
    for (i, n) in nodes.iter().enumerate() {
        if !n.is_leaf() {
            parents[n.first_index as usize] = i as u32;
            parents[n.first_index as usize + 1] = i as u32;
        }
    }
    parents
}

/// The best place to move node `node_id` to, as obvhs's `find_reinsertion` (see its comment for
/// how the area decrease is summed along the path to the root); `stack` is scratch space (empty
/// on return).
fn find_reinsertion(nodes: &[Node2], parents: &[u32], node_id: usize, stack: &mut Vec<(f32, u32)>) -> Reinsertion {
    debug_assert_ne!(node_id, 0);
    let mut best = Reinsertion { from: node_id as u32, to: 0, area_diff: 0.0 };
    let node = nodes[node_id];
    let node_area = half_area(node.min, node.max);
    let parent_id = parents[node_id] as usize;
    let mut area_diff = half_area(nodes[parent_id].min, nodes[parent_id].max);
    let mut sibling_id = sibling(node_id);
    let (mut pivot_min, mut pivot_max) = (nodes[sibling_id].min, nodes[sibling_id].max);
    let mut pivot_id = parent_id;
    stack.clear();
    loop {
        stack.push((area_diff, sibling_id as u32));
        while let Some((top_area_diff, top_sibling_id)) = stack.pop() {
            if top_area_diff - node_area <= best.area_diff {
                continue;
            }
            let dst = &nodes[top_sibling_id as usize];
            let merged_area = half_area(dst.min.min(node.min), dst.max.max(node.max));
            let reinsert_area = top_area_diff - merged_area;
            if reinsert_area > best.area_diff {
                best.to = top_sibling_id;
                best.area_diff = reinsert_area;
            }
            if !dst.is_leaf() {
                let child_area = reinsert_area + half_area(dst.min, dst.max);
                stack.push((child_area, dst.first_index));
                stack.push((child_area, dst.first_index + 1));
            }
        }
        if pivot_id != parent_id {
            let s = &nodes[sibling_id];
            (pivot_min, pivot_max) = (pivot_min.min(s.min), pivot_max.max(s.max));
            let p = &nodes[pivot_id];
            area_diff += half_area(p.min, p.max) - half_area(pivot_min, pivot_max);
        }
        if pivot_id == 0 {
            break;
        }
        sibling_id = sibling(pivot_id);
        pivot_id = parents[pivot_id] as usize;
    }
    if best.to as usize == sibling(best.from as usize) || best.to == parents[best.from as usize] {
        best = Reinsertion::default();
    }
    best
}

/// Moves node `from` next to node `to` (obvhs's `reinsert_node`): `from`'s sibling takes their
/// parent's place, and `to`'s slot becomes the parent of `to` and `from`.
fn reinsert_node(nodes: &mut [Node2], parents: &mut [u32], from: usize, to: usize) {
    let sibling_id = sibling(from);
    let parent_id = parents[from] as usize;
    let sibling_node = nodes[sibling_id];
    let dst_node = nodes[to];
    nodes[to].prim_count = 0;
    nodes[to].first_index = left_sibling(from) as u32;
    nodes[sibling_id] = dst_node;
    nodes[parent_id] = sibling_node;
    // The children of the two moved nodes learn where their parent went.
    for (moved, at) in [(dst_node, sibling_id), (sibling_node, parent_id)] {
        if !moved.is_leaf() {
            parents[moved.first_index as usize] = at as u32;
            parents[moved.first_index as usize + 1] = at as u32;
        }
    }
    parents[sibling_id] = to as u32;
    parents[from] = to as u32;
    refit_from(nodes, parents, to);
    refit_from(nodes, parents, parent_id);
}

/// Refits the boxes from node `index` up to the root, stopping after the second node whose box
/// did not change (obvhs's `refit_from_fast` in a release build).
fn refit_from(nodes: &mut [Node2], parents: &[u32], mut index: usize) {
    let mut same_count = 0;
    loop {
        let node = nodes[index];
        if !node.is_leaf() {
            let (a, b) = (nodes[node.first_index as usize], nodes[node.first_index as usize + 1]);
            let (min, max) = (a.min.min(b.min), a.max.max(b.max));
            if node.min == min && node.max == max {
                same_count += 1;
                if same_count == 2 {
                    return;
                }
            }
            nodes[index].min = min;
            nodes[index].max = max;
        }
        if index == 0 {
            break;
        }
        index = parents[index] as usize;
    }
}

#[cfg(test)]
mod tests {
    use obvhs::bvh2::leaf_collapser::collapse;
    use obvhs::bvh2::reinsertion::ReinsertionOptimizer;

    use super::super::node2::widen;
    use super::*;

    /// Triangles of `n` random sizes and places: candidates of equal half area, which this module
    /// orders differently from obvhs's radix sort, are unlikely.
    fn soup(n: u32) -> Vec<[Vec3; 3]> {
        let mut next = super::super::node2::xorshift(0x1234_5679);
        (0..n)
            .map(|_| {
                let c = Vec3::new(next(), next(), next()) * 10.0;
                let s = 0.05 + next() * 0.3;
                [c, c + Vec3::new(next(), next(), 0.1) * s, c + Vec3::new(0.2, next(), next()) * s]
            })
            .collect()
    }

    #[test]
    fn candidates_are_the_head_of_a_stable_sort() {
        // Half areas of few distinct values (many ties, as on a regular grid) and of many.
        let mut next = super::super::node2::xorshift(0x2468_ace1);
        for (len, levels) in [(3, 2.0), (41, 3.0), (1000, 4.0), (5000, 1e6)] {
            let nodes: Vec<Node2> = (0..len)
                .map(|_| {
                    let size = (next() * levels).floor() + 1.0;
                    Node2 { min: Vec3::ZERO, max: Vec3::new(size, 1.0, 1.0), ..Node2::default() }
                })
                .collect();
            for node_count in [2, 3, len / 7 + 2, len / 2, len] {
                let mut stable: Vec<(u32, f32)> = nodes
                    .iter()
                    .take(node_count * 2)
                    .enumerate()
                    .skip(1)
                    .map(|(i, n)| (i as u32, half_area(n.min, n.max)))
                    .collect();
                stable.sort_by(|a, b| b.1.total_cmp(&a.1));
                stable.truncate(node_count - 1);
                let mut ours = Vec::new();
                largest_first(&nodes, node_count, &mut ours);
                assert_eq!(ours, stable, "{len} nodes, {node_count}");
            }
        }
    }

    #[test]
    fn reinserts_as_obvhs_does() {
        for n in [2, 3, 40, 1000, 30_000] {
            let tris = soup(n);
            let mut ours = super::super::ploc::build(tris.len(), &|id| tris[id as usize], 3);
            let mut theirs = widen(&ours);
            // `bvh::binary_tree`'s steps before this module: two passes, the second at twice the
            // ratio after a collapse that one-triangle leaves leave as it is.
            let mut optimizer = ReinsertionOptimizer::default();
            optimizer.run(&mut theirs, 0.05, None);
            collapse(&mut theirs, 1, 3.0);
            optimizer.run(&mut theirs, 0.1, None);
            let mut up = parents(&ours);
            run(&mut ours, &mut up, 0.05);
            run(&mut ours, &mut up, 0.1);
            let before = super::super::ploc::build(tris.len(), &|id| tris[id as usize], 3);
            assert!(n < 1000 || ours != before, "reinsertion changed nothing at {n} triangles");
            let bytes = |b: &obvhs::bvh2::Bvh2| bytemuck::cast_slice::<_, u8>(&b.nodes).to_vec();
            assert!(bytes(&widen(&ours)) == bytes(&theirs), "trees differ at {n} triangles");
            assert_eq!(up, parents(&ours), "parents kept up to date at {n} triangles");
        }
    }
}
