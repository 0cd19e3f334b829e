//! PLOC (Meister & Bittner 2018, "Parallel Locally-Ordered Clustering for Bounding Volume
//! Hierarchy Construction"): obvhs 0.4.0's `PlocBuilder::build_ploc_from_leaves` for search
//! distance 14 and a search-depth threshold (obvhs is MIT / Apache-2.0), float operation for
//! float operation and tie for tie, so it gives obvhs's binary tree — in less memory (issue 38):
//! the clusters are 32-byte boxes instead of obvhs's 48-byte `Bvh2Node`s, in one array instead of
//! two (each pass writes the next one's over its own), the Morton
//! codes are freed after the sort instead of becoming the merge buffer, and the output tree is
//! allocated only after the sort (with `convert`'s parallel conversion, the BVH phase's peak RSS
//! at 2 M triangles went from 464 to 365 MiB). The output tree is allocated zeroed, so its pages
//! become resident only as merges fill them (from its end), and the cluster array is shrunk to
//! what each pass leaves: the two are never both whole (at 20 M triangles, 1.2 GiB and 0.6 GiB).
//! The output tree is in `node2`'s 32-byte nodes (obvhs's are 48: at 20 M triangles 1.2 GiB
//! instead of 1.8), the same boxes and indices. obvhs's serial merge runs on rayon's threads
//! (`merge_pass`: window by window, each chunk placed by a count of its clusters and merges), the
//! same tree on any thread count. `tests::builds_obvhs_tree` compares both.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use obvhs::ploc::morton::morton_encode_u64_unorm;
use rayon::prelude::*;

use super::node2::Node2;

/// Clusters searched on either side for the best partner (obvhs's `PlocSearchDistance::Medium`).
pub(super) const SEARCH_DISTANCE: usize = 14;

/// The clusters of a pass the merge keeps copies of: more than `SEARCH_DISTANCE`.
const RECENT: usize = 16;
const _: () = assert!(RECENT > SEARCH_DISTANCE);

/// Clusters the parallel merge makes at a time into its buffer (8 MiB of 32-byte clusters).
const MERGE_WINDOW: usize = 1 << 18;
/// The least clusters a rayon job of the merge takes.
const MIN_MERGE_CHUNK: usize = 4096;

/// A cluster: its box and where it is (a triangle id for a leaf, its first child's index in the
/// output tree for an inner node).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Cluster {
    min: Vec3,
    leaf: u32,
    max: Vec3,
    index: u32,
}

impl Cluster {
    fn union(&self, other: &Cluster) -> (Vec3, Vec3) {
        (self.min.min(other.min), self.max.max(other.max))
    }

    /// Half the surface area of the union of two clusters' boxes, as obvhs's `Aabb::half_area`.
    fn merged_half_area(&self, other: &Cluster) -> f32 {
        let (lo, hi) = self.union(other);
        let d = hi - lo;
        (d.x + d.y) * d.z + d.x * d.y
    }

    fn node(&self) -> Node2 {
        Node2 { min: self.min, prim_count: self.leaf, max: self.max, first_index: self.index }
    }
}

/// obvhs's 64-bit Morton key: the same layout, so that rayon's unstable sort orders ties as it
/// does in obvhs.
#[derive(Clone, Copy, Pod, Zeroable)]
#[repr(C)]
struct Morton64 {
    code: u64,
    index: u64,
}

/// Builds obvhs's PLOC tree over `count` (> 0) triangles that `triangle` gives by id, its nodes
/// as obvhs's (root at 0), leaves of one triangle whose `first_index` is the triangle id. Below
/// `search_depth_threshold` passes the search distance is 1, as obvhs's.
pub(super) fn build(
    count: usize,
    triangle: &(impl Fn(u32) -> [Vec3; 3] + Sync),
    search_depth_threshold: usize,
) -> Vec<Node2> {
    build_with(count, triangle, search_depth_threshold, MERGE_WINDOW)
}

/// [`build`], merging `window` clusters at a time (the tests try small windows).
fn build_with(
    count: usize,
    triangle: &(impl Fn(u32) -> [Vec3; 3] + Sync),
    search_depth_threshold: usize,
    window: usize,
) -> Vec<Node2> {
    assert!(count > 0 && count < u32::MAX as usize / 2);
    let leaves: Vec<Cluster> = (0..count as u32)
        .into_par_iter()
        .map(|id| {
            let [v0, v1, v2] = triangle(id);
            Cluster { min: v0.min(v1).min(v2), leaf: 1, max: v0.max(v1).max(v2), index: id }
        })
        .collect();
    let (lo, hi) = leaves
        .par_iter()
        .fold(|| (Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), c| (lo.min(c.min), hi.max(c.max)))
        .reduce(|| (Vec3::INFINITY, Vec3::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    let mut clusters = sort_by_morton(leaves, lo, hi);
    let mut merge = vec![0i8; count];

    // Zeroed (`calloc`, fresh pages from the kernel): a page costs memory only once a merge
    // writes to it, while the clusters shrink.
    let mut nodes: Vec<Node2> = bytemuck::zeroed_vec(2 * count - 1);
    let mut insert_index = nodes.len();
    let mut depth = 0usize;
    let mut n = count;
    let mut window_buffer = Vec::new();
    while n > 1 {
        find_partners(&clusters[..n], &mut merge[..n], depth < search_depth_threshold);
        n = merge_pass(&mut clusters, &merge[..n], &mut nodes, &mut insert_index, window, &mut window_buffer);
        depth += 1;
        // The clusters merged away are freed (a large array is its own mapping, which `realloc`
        // shrinks in place).
        clusters.truncate(n);
        clusters.shrink_to_fit();
    }
    debug_assert_eq!(insert_index, 1);
    nodes[0] = clusters[0].node();
    drop((clusters, merge, window_buffer));
    nodes
}

/// What one step of obvhs's sequential merge does with cluster `index` (of partners `merge`).
#[derive(Clone, Copy, PartialEq)]
enum Step {
    /// It is kept for the next pass.
    Keep,
    /// It merges with the earlier cluster `best`; their parent is kept.
    Merge(usize),
    /// It merges with a later cluster, which makes the parent.
    Skip,
}

fn step(merge: &[i8], index: usize) -> Step {
    let best = (index as i64 + merge[index] as i64) as usize;
    if best as i64 + merge[best] as i64 != index as i64 {
        Step::Keep
    } else if best > index {
        Step::Skip
    } else {
        Step::Merge(best)
    }
}

/// One pass of obvhs's sequential merge over `clusters[..merge.len()]`, on rayon's threads with
/// the same result: a pair merges where both chose each other, the parent taking the later one's
/// place among the next pass's clusters; the output tree is filled from its end (below
/// `insert_index`, which is moved down). The next pass's clusters (their count is returned) are
/// written over this pass's: window by window of `window` clusters, each window's kept clusters
/// made in parallel into `buffer` (a window's chunks know where their clusters and nodes go from a
/// count of each chunk's), then copied down to where the kept ones so far end, which is never
/// past the window's end. A partner (at most `SEARCH_DISTANCE` earlier) in the window before is
/// read from a copy of that window's last clusters, made before the copy down.
fn merge_pass(
    clusters: &mut [Cluster],
    merge: &[i8],
    nodes: &mut [Node2],
    insert_index: &mut usize,
    window: usize,
    buffer: &mut Vec<Cluster>,
) -> usize {
    let n = merge.len();
    let chunk = window.div_ceil(rayon::current_num_threads() * 4).clamp(MIN_MERGE_CHUNK.min(window), window);
    let mut previous = [Cluster::default(); RECENT];
    let mut kept = 0;
    for start in (0..n).step_by(window) {
        let end = (start + window).min(n);
        let current = &clusters[start..end];
        let earlier = |i: usize| if i >= start { current[i - start] } else { previous[i + RECENT - start] };
        // Per chunk: clusters kept and merges.
        let counts: Vec<(usize, usize)> = (0..(end - start).div_ceil(chunk))
            .into_par_iter()
            .map(|c| {
                let from = start + c * chunk;
                (from..(from + chunk).min(end)).fold((0, 0), |(k, m), i| match step(merge, i) {
                    Step::Keep => (k + 1, m),
                    Step::Merge(_) => (k + 1, m + 1),
                    Step::Skip => (k, m),
                })
            })
            .collect();
        let window_kept: usize = counts.iter().map(|c| c.0).sum();
        let window_merges: usize = counts.iter().map(|c| c.1).sum();
        buffer.clear();
        buffer.resize(window_kept, Cluster::default());
        // Each chunk's place in the buffer and in the output tree (chunks in order fill the tree
        // downwards).
        let mut jobs = Vec::with_capacity(counts.len());
        let (mut out_rest, mut node_rest) =
            (&mut buffer[..], &mut nodes[*insert_index - 2 * window_merges..*insert_index]);
        let node_base = *insert_index - 2 * window_merges;
        for (c, &(k, m)) in counts.iter().enumerate() {
            let (out, rest) = std::mem::take(&mut out_rest).split_at_mut(k);
            out_rest = rest;
            let split = node_rest.len() - 2 * m;
            let (rest, node_out) = std::mem::take(&mut node_rest).split_at_mut(split);
            node_rest = rest;
            let from = start + c * chunk;
            jobs.push((from..(from + chunk).min(end), out, node_out, node_base + split));
        }
        jobs.into_par_iter().for_each(|(range, out, node_out, node_first)| {
            let (mut k, mut top) = (0, node_out.len());
            for index in range {
                match step(merge, index) {
                    Step::Keep => {
                        out[k] = current[index - start];
                        k += 1;
                    }
                    Step::Skip => {}
                    Step::Merge(best) => {
                        let (left, right) = (current[index - start], earlier(best));
                        top -= 2;
                        node_out[top] = left.node();
                        node_out[top + 1] = right.node();
                        let (min, max) = left.union(&right);
                        out[k] = Cluster { min, leaf: 0, max, index: (node_first + top) as u32 };
                        k += 1;
                    }
                }
            }
        });
        *insert_index -= 2 * window_merges;
        // The last `RECENT` clusters before the next window (some in earlier windows if this
        // one is shorter), read before the copy down overwrites them.
        let mut last = [Cluster::default(); RECENT];
        for (j, p) in last.iter_mut().enumerate() {
            if end + j >= RECENT {
                let i = end + j - RECENT;
                *p = if i >= start { clusters[i] } else { previous[i + RECENT - start] };
            }
        }
        previous = last;
        clusters[kept..kept + window_kept].copy_from_slice(buffer);
        kept += window_kept;
    }
    kept
}

/// The leaves in the order of their centres' 63-bit Morton codes in the box `lo`–`hi` (obvhs's
/// `sort_nodes_by_morton` with `SortPrecision::U64`: f64 centres, rayon's unstable sort).
fn sort_by_morton(leaves: Vec<Cluster>, lo: Vec3, hi: Vec3) -> Vec<Cluster> {
    let scale = 1.0 / (hi - lo).as_dvec3();
    let offset = -lo.as_dvec3() * scale;
    let mut mortons: Vec<Morton64> = leaves
        .par_iter()
        .enumerate()
        .map(|(index, c)| {
            let center = ((c.max + c.min) * 0.5).as_dvec3() * scale + offset;
            Morton64 { code: morton_encode_u64_unorm(center), index: index as u64 }
        })
        .collect();
    mortons.par_sort_unstable_by_key(|m| m.code);
    mortons.par_iter().map(|m| leaves[m.index as usize]).collect()
}

/// For each cluster, the offset (−14 to 14) of the partner it would merge with: the neighbour
/// within the search distance whose union with it has the least half area, the last one on ties
/// (obvhs's `find_best_node`); with `nearest_only`, the cheaper of its two neighbours' unions,
/// the left one on ties (obvhs's search distance 1).
fn find_partners(clusters: &[Cluster], merge: &mut [i8], nearest_only: bool) {
    let n = clusters.len();
    let chunk = n.div_ceil(rayon::current_num_threads() * 4).max(4096);
    if nearest_only {
        let cost = |i: usize| clusters[i].merged_half_area(&clusters[i + 1]);
        merge[..n - 1].par_chunks_mut(chunk).enumerate().for_each(|(c, out)| {
            let start = c * chunk;
            let mut last = if start == 0 { f32::INFINITY } else { cost(start - 1) };
            for (k, m) in out.iter_mut().enumerate() {
                let c = cost(start + k);
                *m = if last < c { -1 } else { 1 };
                last = c;
            }
        });
        merge[n - 1] = -1;
        return;
    }
    merge.par_chunks_mut(chunk).enumerate().for_each(|(c, out)| {
        let start = c * chunk;
        // cache[i % D][j % D]: the union cost of clusters i < j, computed when i was searched.
        let mut cache = [[0.0f32; SEARCH_DISTANCE]; SEARCH_DISTANCE];
        for (k, m) in out.iter_mut().enumerate() {
            let index = start + k;
            let (mut best, mut best_cost) = (index, f32::INFINITY);
            for other in index.saturating_sub(SEARCH_DISTANCE)..index {
                let cost = if other >= start {
                    cache[other % SEARCH_DISTANCE][index % SEARCH_DISTANCE]
                } else {
                    clusters[index].merged_half_area(&clusters[other])
                };
                if cost <= best_cost {
                    (best, best_cost) = (other, cost);
                }
            }
            for other in index + 1..(index + SEARCH_DISTANCE + 1).min(n) {
                let cost = clusters[index].merged_half_area(&clusters[other]);
                cache[index % SEARCH_DISTANCE][other % SEARCH_DISTANCE] = cost;
                if cost <= best_cost {
                    (best, best_cost) = (other, cost);
                }
            }
            *m = (best as i64 - index as i64) as i8;
        }
    });
}

#[cfg(test)]
mod tests {
    use obvhs::aabb::Aabb;
    use obvhs::bvh2::{Bvh2, node::Bvh2Node};
    use obvhs::ploc::PlocBuilder;

    use super::super::node2::widen;
    use super::*;

    /// obvhs's PLOC over the same leaves, as `bvh::binary_tree` ran it before this module.
    fn obvhs_tree(tris: &[[Vec3; 3]], threshold: usize) -> Bvh2 {
        let mut bvh = Bvh2::zeroed(tris.len());
        bvh.reset_for_reuse(tris.len(), Some((0..tris.len() as u32).collect()));
        let mut builder = PlocBuilder::new();
        builder.current_nodes = tris
            .iter()
            .enumerate()
            .map(|(id, t)| Bvh2Node::new(Aabb::from_points(&[t[0].into(), t[1].into(), t[2].into()]), 1, id as u32))
            .collect();
        let total = builder.current_nodes.iter().fold(Aabb::empty(), |mut total, n| {
            total.extend(n.aabb().min);
            total.extend(n.aabb().max);
            total
        });
        let precision = obvhs::ploc::SortPrecision::U64;
        builder.build_ploc_from_leaves::<SEARCH_DISTANCE, false>(&mut bvh, total, precision, threshold);
        bvh
    }

    #[test]
    fn builds_obvhs_tree() {
        // A soup with duplicate centres (equal Morton codes) and degenerate triangles, a grid
        // (ties in cost), and a large soup split into many parallel chunks.
        let soup = |n: u32, scale: f32| -> Vec<[Vec3; 3]> {
            let mut next = super::super::node2::xorshift(0x2545_f491);
            (0..n)
                .map(|k| {
                    let c = Vec3::new(next(), next(), next()) * scale;
                    let s = if k % 13 == 0 { 0.0 } else { 0.05 };
                    let c = if k % 7 == 0 { Vec3::splat(0.5) } else { c };
                    [c, c + Vec3::new(next(), next(), 0.0) * s, c + Vec3::new(0.0, next(), next()) * s]
                })
                .collect()
        };
        let grid: Vec<[Vec3; 3]> = (0..80 * 80)
            .map(|k| {
                let (x, y) = ((k % 80) as f32, (k / 80) as f32);
                [Vec3::new(x, y, 0.0), Vec3::new(x + 1.0, y, 0.0), Vec3::new(x, y + 1.0, 0.0)]
            })
            .collect();
        // The merge's windows: the default (one window and many chunks at 60 000 triangles), a
        // window of one chunk and a part (many windows), and windows shorter than the partner
        // search's reach.
        for tris in [soup(1, 1.0), soup(2, 1.0), soup(29, 1.0), soup(3000, 1.0), grid, soup(60_000, 100.0)] {
            for threshold in [0, 3] {
                let theirs = obvhs_tree(&tris, threshold);
                let n = tris.len();
                for window in [MERGE_WINDOW, MIN_MERGE_CHUNK + 900, 7] {
                    if window < 100 && n > 10_000 {
                        continue;
                    }
                    let ours = widen(&build_with(n, &|id| tris[id as usize], threshold, window));
                    let bytes = |b: &Bvh2| bytemuck::cast_slice::<Bvh2Node, u8>(&b.nodes).to_vec();
                    let at = format!("{n} triangles, threshold {threshold}, window {window}");
                    assert!(bytes(&ours) == bytes(&theirs), "nodes differ at {at}");
                    assert_eq!(ours.primitive_indices, theirs.primitive_indices, "{at}");
                }
            }
        }
    }
}
