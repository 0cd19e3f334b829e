//! lavapipe's loop budget (PLATFORM.md §6.1) is a known limit of Mesa before 25 (Debian 12's
//! 22.3.6 has it, bookworm-backports' 25.0.7 does not, §14), kept as an expected failure (STYLE.md
//! §9): where `DeviceInfo::loop_budget` says the driver has it, a loop longer than the budget must
//! be cut short *and* the "did the loop end for its own reason" check of the kernels must notice;
//! on every other driver loops run to the end and the guard stays quiet. Either branch failing
//! means the detection in `gpu::context` (and §6.1) must be revisited.
//!
//! The check is a flag set where a loop ends for its own reason, in a loop that also has a bound the
//! compiler can see. Re-testing a loop's condition after the loop (`for (; k < n; k++) …; if (k < n)`)
//! does not work: the test is provably false, the compiler folds it, and on lavapipe a truncated
//! 70 000-iteration loop went unreported (measured with `shaders/loop_budget_probe.comp`).

use pathgrad::bvh;
use pathgrad::contract::{BINDING_PROBE_OUT, BINDING_STATUS, STATUS_LOOP_BUDGET, WORKGROUP_SIZE};
use pathgrad::gpu::pipeline::groups_for;
use pathgrad::gpu::{Buffer, Kernel};

use crate::support::TestGpu;
use crate::support::bvh_probe::{self, BvhProbe, ProbeRay};

/// Comfortably under the measured budget (65 534 iterations): must run to the end everywhere.
const UNDER_BUDGET: u32 = 60_000;
/// Comfortably over it: truncated where the driver has a loop budget, complete elsewhere.
const OVER_BUDGET: u32 = 70_000;
/// One workgroup: 8 subgroups of 8 lanes on lavapipe, each with its own budget.
const INVOCATIONS: u32 = WORKGROUP_SIZE;

/// The probe's recurrence (xorshift32) from the same seed, run `iterations` times on the host.
fn xorshift32(seed: u32, iterations: u32) -> u32 {
    let mut x = seed;
    for _ in 0..iterations {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
    }
    x
}

/// Runs `shaders/loop_budget_probe.comp` with `iterations` per invocation: (status word, per
/// invocation (iterations run, final state)).
fn run_probe(gpu: &TestGpu, iterations: u32) -> (u32, Vec<[u32; 2]>) {
    let status = Buffer::storage_with(&gpu.ctx, "loop probe status", &[0u32]).unwrap();
    let output = Buffer::storage(&gpu.ctx, "loop probe output", u64::from(INVOCATIONS) * 8).unwrap();
    let kernel = Kernel::new(&gpu.ctx, "loop_budget_probe", &[BINDING_STATUS, BINDING_PROBE_OUT], 8).unwrap();
    let group = kernel.bind(&[(BINDING_STATUS, &status), (BINDING_PROBE_OUT, &output)]).unwrap();
    let push = pathgrad::contract::LoopBudgetPush { invocation_count: INVOCATIONS, iterations };
    gpu.ctx
        .submit_and_wait("loop budget probe", |cmd| {
            kernel.record(cmd, &group, bytemuck::bytes_of(&push), groups_for(INVOCATIONS))
        })
        .unwrap();
    let out: Vec<[u32; 2]> = output.download(INVOCATIONS as usize).unwrap();
    (status.download::<u32>(1).unwrap()[0], out)
}

/// Every invocation reports its own iteration count, and its state is the host recurrence at that
/// count: the loop really ran that many times and was neither folded nor shortened by the compiler.
fn check_states(out: &[[u32; 2]]) {
    for (i, &[count, state]) in out.iter().enumerate() {
        assert_eq!(state, xorshift32(i as u32 + 1, count), "invocation {i}: state after {count} iterations");
    }
}

#[test]
fn loop_budget_guard_fires_where_the_driver_has_a_budget() {
    let gpu = TestGpu::new();
    let limited = gpu.ctx.info().loop_budget;

    let (status, out) = run_probe(&gpu, UNDER_BUDGET);
    check_states(&out);
    assert!(out.iter().all(|o| o[0] == UNDER_BUDGET), "{UNDER_BUDGET} iterations must complete: {:?}", &out[..4]);
    assert_eq!(status, 0, "the guard fired on a loop that completed");

    let (status, out) = run_probe(&gpu, OVER_BUDGET);
    let counts: Vec<u32> = out.iter().map(|o| o[0]).collect();
    println!(
        "driver {:?}: {OVER_BUDGET}-iteration loop ran {}..={} iterations, status {status:#x}",
        gpu.ctx.info().driver_id,
        counts.iter().min().unwrap(),
        counts.iter().max().unwrap()
    );
    if limited {
        // Expected driver limit: every lane is cut short (the budget is per subgroup, and all lanes
        // run the same trip count) and the guard notices.
        // The state is not checked: after a truncation the loop's live-out values need not even be
        // consistent with each other (measured: the counter reads 65 535 while the state has
        // advanced 65 534 times), which is why results are discarded once the guard fires.
        assert!(
            counts.iter().all(|&c| c < OVER_BUDGET),
            "the driver reports a loop budget but no longer truncates a {OVER_BUDGET}-iteration loop: revisit PLATFORM.md §6.1 and this expectation"
        );
        assert_eq!(
            status & STATUS_LOOP_BUDGET,
            STATUS_LOOP_BUDGET,
            "the loop was truncated but the guard did not fire"
        );
    } else {
        check_states(&out);
        assert!(
            counts.iter().all(|&c| c == OVER_BUDGET),
            "{OVER_BUDGET} iterations must complete without a loop budget: {counts:?}"
        );
        assert_eq!(status, 0, "the guard fired on a driver without a loop budget");
    }
}

/// Triangles the deep ray must test one by one: with the inner nodes above their leaves this is
/// well past the budget (each leaf holds at most 2, so ≥ 50 000 leaves and ≥ 100 000 node visits on
/// top of 100 000 triangle tests).
const STACKED_TRIANGLES: usize = 100_000;

/// A scene that defeats the BVH for one ray: `STACKED_TRIANGLES` triangles in the planes x = i·0.01
/// whose bounding boxes all contain the x axis but which do not (each lies on the far side of the
/// line y + z = 0.1 in its plane), then one triangle at x = 1 001 covering the axis.
fn stacked_triangles() -> Vec<[glam::Vec3; 3]> {
    let mut tris: Vec<[glam::Vec3; 3]> = (0..STACKED_TRIANGLES)
        .map(|i| {
            let x = i as f32 * 0.01;
            [glam::Vec3::new(x, -0.9, 1.0), glam::Vec3::new(x, 1.0, 1.0), glam::Vec3::new(x, 1.0, -0.9)]
        })
        .collect();
    let x = 1_001.0;
    tris.push([glam::Vec3::new(x, -1.0, -1.0), glam::Vec3::new(x, 2.0, -1.0), glam::Vec3::new(x, -1.0, 2.0)]);
    tris
}

/// The traversal's own guard in `shaders/lib/bvh.glsl` (not just the probe's copy of it) fires when
/// one ray needs more loop iterations than a loop-budget driver allows, for the closest-hit and the shadow query
/// alike; elsewhere both queries finish and find the far triangle.
#[test]
fn bvh_traversal_guard_fires_where_the_driver_has_a_budget() {
    let gpu = TestGpu::new();
    let limited = gpu.ctx.info().loop_budget;
    let tris = stacked_triangles();
    let bvh = bvh::build(&tris).unwrap();
    let ray = ProbeRay { origin: [-1.0, 0.0, 0.0], tmin: 0.0, dir: [1.0, 0.0, 0.0], tmax: f32::INFINITY };

    // The host twin has no budget: it visits every node and finds the far triangle.
    let host = bvh::closest_hit(
        &bvh,
        &bvh::Ray::new(glam::Vec3::from(ray.origin), glam::Vec3::from(ray.dir)),
        ray.tmin,
        ray.tmax,
    )
    .expect("the far triangle");
    assert_eq!(bvh.prim_ids[host.slot as usize] as usize, STACKED_TRIANGLES);
    println!("deep ray: {} nodes, depth {}, host hit at t = {}", bvh.nodes.len(), bvh.depth, host.t);

    let probe = BvhProbe::new(&gpu, &bvh);
    for (queries, name) in [(bvh_probe::CLOSEST, "closest hit"), (bvh_probe::OCCLUDED, "occlusion")] {
        let (hits, status) = probe.trace(&[ray], queries, 0);
        println!("{name}: status {status:#x}, {:?}", hits[0]);
        if limited {
            assert_eq!(
                status & STATUS_LOOP_BUDGET,
                STATUS_LOOP_BUDGET,
                "{name}: the driver cut the traversal short and the guard did not fire (or it lost its loop budget: revisit PLATFORM.md §6.1)"
            );
        } else {
            assert_eq!(status, 0, "{name}: the guard fired on a driver without a loop budget");
            let found = if queries == bvh_probe::CLOSEST {
                hits[0].hit == 1 && hits[0].slot == host.slot && hits[0].t == host.t
            } else {
                hits[0].occluded == 1
            };
            assert!(found, "{name}: {:?}, host {host:?}", hits[0]);
        }
    }
}

/// The start value of lavapipe's (Mesa < 25) per-subgroup loop counter (PLATFORM.md §6.1).
const LAVAPIPE_BUDGET: u32 = 65_535;

/// A short traversal whose last step matters: 64 stacked misses along the x axis, then a last leaf
/// of 1 miss and the only triangle the ray hits, all with the same bounding box, so the hit sits
/// in a full leaf that is popped with the stack empty. Returns the triangles and the hit's id.
fn last_leaf_scene() -> (Vec<[glam::Vec3; 3]>, usize) {
    let miss = |x: f32| [glam::Vec3::new(x, -0.9, 1.0), glam::Vec3::new(x, 1.0, 1.0), glam::Vec3::new(x, 1.0, -0.9)];
    let mut tris: Vec<[glam::Vec3; 3]> = (0..64).map(|i| miss(i as f32 * 0.01)).collect();
    tris.extend((1..2).map(|j| miss(10.0 - 0.001 * j as f32)));
    tris.push([glam::Vec3::new(10.0, -0.9, -0.9), glam::Vec3::new(10.0, 1.0, -0.9), glam::Vec3::new(10.0, -0.9, 1.0)]);
    let hit = tris.len() - 1;
    (tris, hit)
}

/// Whatever step of a traversal the budget runs out at, the answer is either complete or flagged.
/// The probe spends `burn` iterations before tracing, and `burn` sweeps from "the traversal fits"
/// to "nothing is left", one iteration at a time, for both queries. The scene puts the deciding
/// triangle last in the last leaf: the case that a post-loop re-test of the loop conditions missed
/// (7 silent wrong closest hits in this sweep before `bvh.glsl` switched to a `finished` flag).
#[test]
fn bvh_guard_catches_truncation_at_every_step() {
    let gpu = TestGpu::new();
    let limited = gpu.ctx.info().loop_budget;
    let (tris, hit_id) = last_leaf_scene();
    let bvh = bvh::build(&tris).unwrap();
    let slot = bvh.prim_ids.iter().position(|&p| p as usize == hit_id).unwrap() as u32;
    let leaf = bvh.leaves().find(|l| l.contains(&slot)).unwrap();
    assert!(
        leaf.len() > 1 && slot == leaf.end - 1,
        "the scene no longer puts the hit last in a shared leaf: {leaf:?}, slot {slot}"
    );

    let probe = BvhProbe::new(&gpu, &bvh);
    let ray = ProbeRay { origin: [-1.0, 0.0, 0.0], tmin: 0.0, dir: [1.0, 0.0, 0.0], tmax: f32::INFINITY };
    let (want, status) = probe.trace(&[ray], bvh_probe::CLOSEST | bvh_probe::OCCLUDED, 0);
    assert_eq!((status, want[0].hit, want[0].slot, want[0].occluded), (0, 1, slot, 1));
    // 300 iterations cover this traversal (about 90 node and triangle steps) with room to spare.
    let burns = LAVAPIPE_BUDGET - 300..=LAVAPIPE_BUDGET + 1;
    for (queries, name) in [(bvh_probe::CLOSEST, "closest hit"), (bvh_probe::OCCLUDED, "occlusion")] {
        let runs = probe.trace_burning(ray, queries, burns.clone());
        // '.' complete and quiet, 'f' flagged but complete, 'F' flagged and wrong, 'S' silently wrong.
        let marks: String = runs
            .iter()
            .map(|(h, status)| {
                let right = if queries == bvh_probe::CLOSEST {
                    h.hit == 1 && h.slot == want[0].slot && h.t == want[0].t
                } else {
                    h.occluded == 1
                };
                match (right, status & STATUS_LOOP_BUDGET != 0) {
                    (true, false) => '.',
                    (true, true) => 'f',
                    (false, true) => 'F',
                    (false, false) => 'S',
                }
            })
            .collect();
        println!("{name}, burn {}..={}: {}", burns.start(), burns.end(), marks.trim_start_matches('.'));
        assert!(!marks.contains('S'), "{name}: a truncated traversal went unflagged: {marks}");
        if limited {
            assert!(
                marks.starts_with('.') && marks.ends_with('F'),
                "{name}: the sweep must run from complete to truncated (did the budget change? PLATFORM.md §6.1): {marks}"
            );
        } else {
            assert!(marks.chars().all(|c| c == '.'), "{name}: without a loop budget nothing may be truncated: {marks}");
        }
    }
}
