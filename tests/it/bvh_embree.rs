//! The BVH three ways: `src/bvh.rs` on the CPU, its GLSL twin `shaders/lib/bvh.glsl` on the device
//! (through `shaders/bvh_probe.comp`), and Embree 3 in robust mode as the independent reference.
//!
//! Scene: a displaced UV sphere and a heightfield (closed and open indexed meshes whose triangles
//! share edges exactly) plus a soup of random triangles, a tenth of them slivers — 15 600 triangles
//! from a fixed seed. Rays: 130 000 from outside aimed at the sphere, from inside it, incoherent
//! ones through the whole box, and finite shadow segments.
//!
//! What must agree, and how closely (PLATFORM.md §7):
//! - CPU and GPU are twins: the same hit/miss, slot and occlusion answer for every ray, and the same
//!   `t` to a few ulps (on lavapipe, whose arithmetic is IEEE, the slots must match exactly; other
//!   drivers may round division differently (GLSL allows 2.5 ulp), so there they get the edge budget).
//! - Against Embree, `t` within 1e-3 relative when both hit the same triangle, and the primitive id
//!   equal except at ties (two triangles at the same `t` to float precision, as at a shared edge).
//! - Hit/miss may differ only on rays through an edge. Embree's robust test is watertight; ours is
//!   Möller–Trumbore in f32, which decides each edge per triangle with a rounding error of a few
//!   units of 2⁻²⁴ scaled by the ray's conditioning, so a ray close enough to a shared edge can slip
//!   between its two triangles (and reach a farther surface) or hit an unshared edge Embree misses.
//!   Each such ray is verified in f64 to pass within its own rounding band (`rounding_band`) of the
//!   reported triangle's edge, and their number is bounded by the chance of a crossing landing in
//!   that band, summed over the rays (λ ≈ 30 here; budget λ + 4√λ + 1 = 52, 4e-4 of the rays;
//!   measured: 1). The occlusion query must agree with Embree's wherever the closest hits agree.

use std::time::Instant;

use ash::vk;
use glam::{DVec3, Vec3};
use pathgrad::bvh::{self, Bvh, Hit};

use crate::support::TestGpu;
use crate::support::bvh_probe::{self, BvhProbe, ProbeHit, ProbeRay};
use crate::support::embree::EmbreeScene;

/// Seed of the scene and the rays.
const SEED: u64 = 0x5EED_B1A5_0001;
/// `t` tolerance against Embree, relative (PLATFORM.md §7: one sliver in 1 M rays reached ~1e-3).
const T_REL_TOL: f64 = 1e-3;
/// Roundings that reach a barycentric coordinate in f32 Möller–Trumbore, to first order: `s` (1),
/// `p = d × e2` or `q = s × e1` (2), the dot product (3), the product with `1 / det` (2, the
/// reciprocal included). See `rounding_band`.
const BARY_ROUNDINGS: f64 = 8.0;
/// Two hits are a tie when their exact (f64) distances differ by less than this, relative: both
/// triangles are then equally right to within float precision.
const TIE_REL: f64 = 1e-5;
/// The CPU and GPU `t` may differ by this many ulps (both compute the same `precise` expression;
/// the allowance covers division rounded to 2.5 ulp, which GLSL permits).
const TWIN_T_ULPS: u32 = 4;

/// SplitMix64 (Steele, Lea & Flood 2014): a deterministic stream for the scene and the rays.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// Uniform in [lo, hi).
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform in the box [lo, hi]³.
    fn in_box(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }

    /// Uniform on the unit sphere.
    fn direction(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f32::consts::TAU);
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// Uniform in the ball of radius `radius` about the origin.
    fn in_ball(&mut self, radius: f32) -> Vec3 {
        self.direction() * radius * self.unit().cbrt()
    }
}

/// An indexed triangle mesh; triangle ids are positions in `triangles`.
#[derive(Default)]
struct Mesh {
    vertices: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
}

impl Mesh {
    fn vertex(&mut self, p: Vec3) -> u32 {
        self.vertices.push(p.to_array());
        self.vertices.len() as u32 - 1
    }

    fn corners(&self, id: u32) -> [Vec3; 3] {
        self.triangles[id as usize].map(|v| Vec3::from(self.vertices[v as usize]))
    }

    fn soup(&self) -> Vec<[Vec3; 3]> {
        (0..self.triangles.len() as u32).map(|i| self.corners(i)).collect()
    }
}

/// Longitude segments and latitude rings of the sphere: 2·100 + 2·100·58 = 11 800 triangles.
const SPHERE_LON: u32 = 100;
const SPHERE_LAT: u32 = 60;
/// Heightfield cells per side: 2·40² = 3 200 triangles.
const FIELD_CELLS: u32 = 40;
/// Random triangles, every tenth a sliver.
const SOUP: u32 = 600;

/// The test scene: a displaced closed sphere of radius 1 ± 0.08 at the origin, a heightfield below
/// it, and random triangles in [-2, 2]³ (some crossing the sphere).
fn scene(rng: &mut Rng) -> Mesh {
    let mut mesh = Mesh::default();
    // Sphere: radius 1 + 0.05 sin(5θ) cos(7φ) + 0.03 noise, noise per vertex so shared edges stay shared.
    let radius = |rng: &mut Rng, theta: f32, phi: f32| {
        1.0 + 0.05 * (5.0 * theta).sin() * (7.0 * phi).cos() + 0.03 * rng.range(-1.0, 1.0)
    };
    let north = mesh.vertex(Vec3::Y * radius(rng, 0.0, 0.0));
    let south = mesh.vertex(-Vec3::Y * radius(rng, std::f32::consts::PI, 0.0));
    let ring0 = mesh.vertices.len() as u32;
    for j in 1..SPHERE_LAT {
        let theta = std::f32::consts::PI * j as f32 / SPHERE_LAT as f32;
        for i in 0..SPHERE_LON {
            let phi = std::f32::consts::TAU * i as f32 / SPHERE_LON as f32;
            let r = radius(rng, theta, phi);
            mesh.vertex(r * Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin()));
        }
    }
    let at = |j: u32, i: u32| ring0 + (j - 1) * SPHERE_LON + i % SPHERE_LON;
    for i in 0..SPHERE_LON {
        mesh.triangles.push([north, at(1, i + 1), at(1, i)]);
        mesh.triangles.push([south, at(SPHERE_LAT - 1, i), at(SPHERE_LAT - 1, i + 1)]);
        for j in 1..SPHERE_LAT - 1 {
            mesh.triangles.push([at(j, i), at(j, i + 1), at(j + 1, i)]);
            mesh.triangles.push([at(j + 1, i), at(j, i + 1), at(j + 1, i + 1)]);
        }
    }
    // Heightfield over x, z ∈ [-2.5, 2.5] at y ≈ -1.5.
    let field0 = mesh.vertices.len() as u32;
    for j in 0..=FIELD_CELLS {
        for i in 0..=FIELD_CELLS {
            let (x, z) = (-2.5 + 5.0 * i as f32 / FIELD_CELLS as f32, -2.5 + 5.0 * j as f32 / FIELD_CELLS as f32);
            let y = -1.5 + 0.1 * (1.3 * x).sin() * (0.7 * z).cos() + 0.02 * rng.range(-1.0, 1.0);
            mesh.vertex(Vec3::new(x, y, z));
        }
    }
    let grid = |j: u32, i: u32| field0 + j * (FIELD_CELLS + 1) + i;
    for j in 0..FIELD_CELLS {
        for i in 0..FIELD_CELLS {
            mesh.triangles.push([grid(j, i), grid(j + 1, i), grid(j, i + 1)]);
            mesh.triangles.push([grid(j, i + 1), grid(j + 1, i), grid(j + 1, i + 1)]);
        }
    }
    // Soup: edges up to 0.3; a sliver has its third corner within 1e-3 of its first edge's midpoint.
    for k in 0..SOUP {
        let a = rng.in_box(-2.0, 2.0);
        let b = a + rng.direction() * rng.range(0.02, 0.3);
        let c = if k % 10 == 0 {
            0.5 * (a + b) + rng.direction() * 1e-3
        } else {
            a + rng.direction() * rng.range(0.02, 0.3)
        };
        let first = mesh.vertex(a);
        mesh.vertex(b);
        mesh.vertex(c);
        mesh.triangles.push([first, first + 1, first + 2]);
    }
    mesh
}

/// Where a ray comes from; the agreement table is printed per kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// From the sphere of radius 4 towards a point in the ball of radius 1.2.
    Outside,
    /// From inside the closed sphere, any direction: must hit it.
    Inside,
    /// From anywhere in [-3, 3]³, any direction.
    Incoherent,
    /// A finite segment between two points of [-2.5, 2.5]³ (`t` ∈ (0, 1)).
    Shadow,
}

const KINDS: [(Kind, usize); 4] =
    [(Kind::Outside, 50_000), (Kind::Inside, 25_000), (Kind::Incoherent, 30_000), (Kind::Shadow, 25_000)];

/// The rays, with their kinds. Directions are unit for every other ray and of random length
/// otherwise (`t` is in units of the direction's length in all three implementations).
fn rays(rng: &mut Rng) -> Vec<(Kind, ProbeRay)> {
    let mut rays = Vec::new();
    for (kind, count) in KINDS {
        for n in 0..count {
            let (origin, dir, tmax) = match kind {
                Kind::Outside => {
                    let origin = rng.direction() * 4.0;
                    (origin, rng.in_ball(1.2) - origin, f32::INFINITY)
                }
                Kind::Inside => (rng.in_ball(0.8), rng.direction(), f32::INFINITY),
                Kind::Incoherent => (rng.in_box(-3.0, 3.0), rng.direction(), f32::INFINITY),
                Kind::Shadow => {
                    let origin = rng.in_box(-2.5, 2.5);
                    (origin, rng.in_box(-2.5, 2.5) - origin, 1.0)
                }
            };
            let dir = match (kind, n % 2) {
                (Kind::Shadow, _) => dir,
                (_, 0) => dir.normalize(),
                _ => dir.normalize() * rng.range(0.25, 4.0),
            };
            rays.push((kind, ProbeRay { origin: origin.to_array(), tmin: 0.0, dir: dir.to_array(), tmax }));
        }
    }
    rays
}

/// How far from an edge, in barycentric units, f32 Möller–Trumbore can misplace the crossing of
/// `ray` with `tri`: each coordinate is a dot product of magnitude up to |s|·|d|·|e| divided by
/// det, so its absolute error is at most `BARY_ROUNDINGS`·u·|s|·|d|·(|e1| + |e2|) / |det| (u = 2⁻²⁴,
/// first order; `1 − b1 − b2` adds the two errors, hence the sum of the edges). Grazing rays
/// (small det) and far origins (large |s|) widen the band.
fn rounding_band(ray: &ProbeRay, tri: [Vec3; 3]) -> f64 {
    let [v0, v1, v2] = tri.map(|v| v.as_dvec3());
    let (o, d) = (DVec3::from(ray.origin.map(f64::from)), DVec3::from(ray.dir.map(f64::from)));
    let (e1, e2) = (v1 - v0, v2 - v0);
    let det = e1.dot(d.cross(e2)).abs();
    BARY_ROUNDINGS * f64::from(f32::EPSILON / 2.0) * (o - v0).length() * d.length() * (e1.length() + e2.length()) / det
}

/// Möller–Trumbore in f64 without bounds: (t, distance of the crossing point from the triangle's
/// nearest edge in barycentric units — negative outside).
fn exact_crossing(ray: &ProbeRay, tri: [Vec3; 3]) -> (f64, f64) {
    let [v0, v1, v2] = tri.map(|v| v.as_dvec3());
    let (o, d) = (DVec3::from(ray.origin.map(f64::from)), DVec3::from(ray.dir.map(f64::from)));
    let (e1, e2) = (v1 - v0, v2 - v0);
    let p = d.cross(e2);
    let inv_det = 1.0 / e1.dot(p);
    let s = o - v0;
    let b1 = s.dot(p) * inv_det;
    let q = s.cross(e1);
    let b2 = d.dot(q) * inv_det;
    (e2.dot(q) * inv_det, b1.min(b2).min(1.0 - b1 - b2))
}

/// How one implementation's closest hit compares with Embree's on one ray.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Verdict {
    /// Both miss, or both hit the same triangle at a `t` within `T_REL_TOL` (the relative difference).
    Same(f64),
    /// Different triangles at the same `t` to float precision.
    Tie,
    /// One hits and the other misses, or one reaches a farther triangle: an edge case, verified
    /// (the crossing's distance from the edge and the rounding band, in barycentric units).
    Edge(f64, f64),
    /// Embree's hit is within `T_REL_TOL` of `tmax` and the other answer is a miss: undecidable.
    AtTmax,
}

/// Compares a hit `(t, triangle id)` with Embree's unbounded closest hit `embree_any_t` (which is
/// the answer within `tmax` if it lies before `tmax`); panics on anything that is not an agreement,
/// a tie or a verified edge case.
fn judge(
    mesh: &Mesh,
    ray: &ProbeRay,
    ours: Option<(f32, u32)>,
    embree_any_t: Option<(f32, u32)>,
    who: &str,
) -> Verdict {
    let rel = |a: f64, b: f64| (a - b).abs() / a.abs().max(b.abs()).max(f64::MIN_POSITIVE);
    let embree = embree_any_t.filter(|&(t, _)| t < ray.tmax);
    // Whatever either side reports is really crossed, up to rounding.
    for (side, hit) in [("ours", ours), ("Embree's", embree)] {
        if let Some((_, id)) = hit {
            let (edge, band) = (exact_crossing(ray, mesh.corners(id)).1, rounding_band(ray, mesh.corners(id)));
            assert!(
                edge >= -band,
                "{who}: {side} triangle {id} lies {edge:.2e} outside its edges (rounding band {band:.2e}); ray {ray:?}"
            );
        }
    }
    match (ours, embree) {
        (None, None) => Verdict::Same(0.0),
        (Some((t, id)), Some((te, ide))) if id == ide => {
            let err = rel(f64::from(t), f64::from(te));
            assert!(
                err <= T_REL_TOL,
                "{who}: t = {t} vs Embree {te} on triangle {id} (relative {err:.2e}); ray {ray:?}"
            );
            Verdict::Same(err)
        }
        (Some((_, id)), Some((_, ide))) => {
            let (t, edge) = exact_crossing(ray, mesh.corners(id));
            let (te, edge_e) = exact_crossing(ray, mesh.corners(ide));
            if rel(t, te) <= TIE_REL {
                return Verdict::Tie;
            }
            // Whoever stopped farther went through the nearer triangle: that must be an edge graze.
            let (nearer, nearer_edge) = if t < te { (id, edge) } else { (ide, edge_e) };
            let band = rounding_band(ray, mesh.corners(nearer));
            assert!(
                nearer_edge.abs() <= band,
                "{who}: triangle {id} at t = {t} vs Embree's {ide} at {te}, nearer one {nearer_edge:.2e} from its edge (rounding band {band:.2e}); ray {ray:?}"
            );
            Verdict::Edge(nearer_edge.abs(), band)
        }
        (Some((_, id)), None) | (None, Some((_, id))) => {
            if let Some((te, _)) = embree_any_t
                && ray.tmax.is_finite()
                && rel(f64::from(te), f64::from(ray.tmax)) <= T_REL_TOL
            {
                return Verdict::AtTmax;
            }
            let (_, edge) = exact_crossing(ray, mesh.corners(id));
            let band = rounding_band(ray, mesh.corners(id));
            assert!(
                edge.abs() <= band,
                "{who}: {ours:?} vs Embree {embree:?}: triangle {id} is hit {edge:.2e} from its edge (rounding band {band:.2e}); ray {ray:?}"
            );
            Verdict::Edge(edge.abs(), band)
        }
    }
}

/// Distance in ulps between two finite floats of the same sign.
fn ulps(a: f32, b: f32) -> u32 {
    if a == b {
        0
    } else if a.is_sign_negative() != b.is_sign_negative() {
        u32::MAX
    } else {
        a.to_bits().abs_diff(b.to_bits())
    }
}

/// Counts of one comparison per ray kind.
#[derive(Clone, Copy, Debug, Default)]
struct Tally {
    rays: usize,
    hits: usize,
    ties: usize,
    edges: usize,
    at_tmax: usize,
    occlusion_diffs: usize,
    max_t_rel: f64,
    max_edge_dist: f64,
}

#[test]
fn bvh_agrees_with_its_twin_and_embree() {
    let started = Instant::now();
    let mut rng = Rng(SEED);
    let mesh = scene(&mut rng);
    let rays = rays(&mut rng);
    let probe_rays: Vec<ProbeRay> = rays.iter().map(|r| r.1).collect();
    assert!(mesh.triangles.len() >= 10_000 && rays.len() >= 100_000);

    let clock = Instant::now();
    let bvh: Bvh = bvh::build(&mesh.soup()).unwrap();
    let build_ms = clock.elapsed().as_secs_f64() * 1e3;
    println!(
        "{} triangles, {} rays; BVH {} nodes, depth {}, built in {build_ms:.0} ms",
        mesh.triangles.len(),
        rays.len(),
        bvh.nodes.len(),
        bvh.depth
    );

    // ---- CPU ----
    let clock = Instant::now();
    let cpu: Vec<(Option<Hit>, bool)> = probe_rays
        .iter()
        .map(|r| {
            let ray = bvh::Ray::new(Vec3::from(r.origin), Vec3::from(r.dir));
            (bvh::closest_hit(&bvh, &ray, r.tmin, r.tmax), bvh::occluded(&bvh, &ray, r.tmin, r.tmax))
        })
        .collect();
    let cpu_ms = clock.elapsed().as_secs_f64() * 1e3;

    // ---- GPU ----
    let gpu = TestGpu::new();
    let lavapipe = gpu.ctx.info().driver_id == vk::DriverId::MESA_LLVMPIPE;
    let probe = BvhProbe::new(&gpu, &bvh);
    // lavapipe compiles the kernel at its first dispatch (PLATFORM.md §6.3): warm up before timing.
    probe.trace(&probe_rays[..64], bvh_probe::CLOSEST | bvh_probe::OCCLUDED, 0);
    let clock = Instant::now();
    let (gpu_hits, status): (Vec<ProbeHit>, u32) =
        probe.trace(&probe_rays, bvh_probe::CLOSEST | bvh_probe::OCCLUDED, 0);
    let gpu_ms = clock.elapsed().as_secs_f64() * 1e3;
    assert_eq!(status, 0, "the traversal raised status {status:#x} (1: loop budget, 2: stack overflow)");

    // ---- Embree ----
    let clock = Instant::now();
    let embree = EmbreeScene::new(&mesh.vertices, &mesh.triangles);
    let segments: Vec<([f32; 3], [f32; 3])> = probe_rays.iter().map(|r| (r.origin, r.dir)).collect();
    let embree_hits = embree.closest_hits(&segments, 0.0);
    let (open, shadow): (Vec<usize>, Vec<usize>) = (0..rays.len()).partition(|&i| probe_rays[i].tmax.is_infinite());
    assert!(shadow.iter().all(|&i| probe_rays[i].tmax == 1.0));
    let mut embree_occluded = vec![false; rays.len()];
    for (subset, tmax) in [(&open, f32::INFINITY), (&shadow, 1.0)] {
        let subset_rays: Vec<_> = subset.iter().map(|&i| segments[i]).collect();
        for (&i, o) in subset.iter().zip(embree.occluded(&subset_rays, 0.0, tmax)) {
            embree_occluded[i] = o;
        }
    }
    let embree_ms = clock.elapsed().as_secs_f64() * 1e3;
    println!(
        "CPU (closest + occluded) {cpu_ms:.0} ms, GPU {gpu_ms:.0} ms ({}), Embree {embree_ms:.0} ms",
        gpu.ctx.info().driver
    );

    // ---- the edge budget ----
    // A crossing lies within δ of one of its triangle's three edges with probability ≤ 6δ (the band
    // b_i < δ covers 1 − (1 − δ)² ≈ 2δ of the triangle), so with δ the ray's rounding band the
    // expected number of edge cases is at most λ = Σ 6·δ over the rays Embree sees hit something.
    // Budget: λ plus four standard deviations of a Poisson count, plus one.
    let lambda: f64 = rays
        .iter()
        .zip(&embree_hits)
        .filter_map(|((_, ray), hit)| {
            hit.filter(|&(t, _)| t < ray.tmax).map(|(_, id)| 6.0 * rounding_band(ray, mesh.corners(id)).min(1.0 / 6.0))
        })
        .sum();
    let budget = (lambda + 4.0 * lambda.sqrt() + 1.0).floor() as usize;
    println!("expected edge cases at most {lambda:.2}: budget {budget}");

    // ---- CPU vs GPU: twins ----
    let (mut twin_diffs, mut t_bitwise, mut bary_bitwise, mut max_ulps, mut cpu_gpu_hits) =
        (0usize, 0usize, 0usize, 0u32, 0usize);
    for (i, ((cpu_hit, cpu_occ), g)) in cpu.iter().zip(&gpu_hits).enumerate() {
        assert_eq!(g.occluded == 1, g.hit == 1, "ray {i}: the GPU's occlusion and closest-hit answers disagree");
        assert_eq!(*cpu_occ, cpu_hit.is_some(), "ray {i}: the CPU's occlusion and closest-hit answers disagree");
        match cpu_hit {
            Some(h) if g.hit == 1 && h.slot == g.slot => {
                cpu_gpu_hits += 1;
                max_ulps = max_ulps.max(ulps(h.t, g.t));
                t_bitwise += usize::from(h.t.to_bits() == g.t.to_bits());
                bary_bitwise += usize::from(h.b1.to_bits() == g.b1.to_bits() && h.b2.to_bits() == g.b2.to_bits());
            }
            None if g.hit == 0 => {}
            _ => {
                twin_diffs += 1;
                assert!(!lavapipe, "ray {i}: CPU {cpu_hit:?} vs GPU {g:?}; the twins must agree exactly on lavapipe");
            }
        }
    }
    println!(
        "CPU vs GPU: {} rays, {cpu_gpu_hits} common hits, {twin_diffs} hit/slot differences; t bitwise equal {t_bitwise}/{cpu_gpu_hits} (max {max_ulps} ulp), barycentrics bitwise equal {bary_bitwise}/{cpu_gpu_hits}",
        rays.len()
    );
    assert!(max_ulps <= TWIN_T_ULPS, "CPU and GPU t differ by {max_ulps} ulps");
    assert!(twin_diffs <= budget, "{twin_diffs} hit/slot differences between the twins, budget {budget}");

    // ---- both vs Embree ----
    for who in ["CPU", "GPU"] {
        let mut tally: Vec<(Kind, Tally)> = KINDS.iter().map(|&(k, _)| (k, Tally::default())).collect();
        for (i, (kind, ray)) in rays.iter().enumerate() {
            let (ours, occluded) = match who {
                "CPU" => (cpu[i].0.map(|h| (h.t, bvh.prim_ids[h.slot as usize])), cpu[i].1),
                _ => (
                    (gpu_hits[i].hit == 1).then(|| (gpu_hits[i].t, bvh.prim_ids[gpu_hits[i].slot as usize])),
                    gpu_hits[i].occluded == 1,
                ),
            };
            let verdict = judge(&mesh, ray, ours, embree_hits[i], who);
            let reference = embree_hits[i].filter(|&(t, _)| t < ray.tmax);
            let entry = &mut tally.iter_mut().find(|(k, _)| k == kind).unwrap().1;
            entry.rays += 1;
            entry.hits += usize::from(reference.is_some());
            match verdict {
                Verdict::Same(err) => entry.max_t_rel = entry.max_t_rel.max(err),
                Verdict::Tie => entry.ties += 1,
                Verdict::Edge(dist, band) => {
                    entry.edges += 1;
                    entry.max_edge_dist = entry.max_edge_dist.max(dist);
                    println!(
                        "{who} edge case, ray {i} ({kind:?}): ours {ours:?}, Embree {:?}, {dist:.1e} from the edge (band {band:.1e})",
                        embree_hits[i]
                    );
                }
                Verdict::AtTmax => entry.at_tmax += 1,
            }
            if occluded != embree_occluded[i] {
                entry.occlusion_diffs += 1;
                // Occlusion is "a hit in (tmin, tmax)", so it can differ only where the closest hits do.
                assert!(
                    matches!(verdict, Verdict::Edge(..) | Verdict::AtTmax),
                    "{who} ray {i}: occluded {occluded} vs Embree, closest hits {verdict:?}"
                );
            }
        }
        for (kind, t) in &tally {
            println!(
                "{who} vs Embree, {kind:?}: {} rays, {} hits, max t error {:.1e}; {} ties, {} edge cases (max {:.1e} from the edge), {} at tmax, {} occlusion differences",
                t.rays, t.hits, t.max_t_rel, t.ties, t.edges, t.max_edge_dist, t.at_tmax, t.occlusion_diffs
            );
        }
        let edges: usize = tally.iter().map(|(_, t)| t.edges).sum();
        assert!(edges <= budget, "{who}: {edges} edge cases against Embree, budget {budget}");
    }
    println!("whole test {:.1} s", started.elapsed().as_secs_f64());
}
