//! Photon tracing: emitted power equals the emitters' power, scattering follows the albedo in
//! expectation, caustic photons exist only where a specular surface does, and the stored
//! photons do not depend on the thread count.

use crate::common::load_small;
use glam::{DVec3, Vec3};
use stagelight::components::PhotonFlags;
use stagelight::integrators::SceneData;
use stagelight::photons::{self, PhotonPass};
use stagelight::pipeline::{Graph, Node, Stats};
use std::sync::Arc;

fn pass(name: &str, max_depth: u32) -> PhotonPass {
    let scene = load_small(name, 8);
    PhotonPass::new(
        Arc::new(SceneData::new(scene)),
        stagelight::sampling::Sampler::Independent { seed: 7 },
        max_depth,
    )
}

/// Mean and standard error of a per-item quantity.
fn mean_se(values: impl Iterator<Item = DVec3>, n: f64) -> (DVec3, DVec3) {
    let (mut sum, mut sum2) = (DVec3::ZERO, DVec3::ZERO);
    for v in values {
        sum += v;
        sum2 += v * v;
    }
    let mean = sum / n;
    let var = (sum2 / n - mean * mean).max(DVec3::ZERO) * (n / (n - 1.0));
    (mean, (var / n).max(DVec3::ZERO).powf(0.5))
}

fn assert_close(what: &str, got: (DVec3, DVec3), expected: DVec3) {
    let (mean, se) = got;
    for c in 0..3 {
        let tol = 5.0 * se[c] + 1e-5 * expected[c].abs();
        assert!(
            (mean[c] - expected[c]).abs() <= tol,
            "{what}: channel {c}: {} vs {} (se {})",
            mean[c],
            expected[c],
            se[c]
        );
    }
}

#[test]
fn emitted_photons_carry_the_emitters_power() {
    let emit_only = Graph::new(
        "emit",
        vec![Node::system(
            stagelight::systems::generate::photons::EmitPhotons,
        )],
    );
    for name in [
        "cornell_box.ron",
        "torus_glass.ron",
        "door_ajar.ron",
        "furnace.ron",
    ] {
        let mut p = pass(name, u32::MAX);
        let n = 50_000;
        p.tracing.begin_pass(0, n as u64);
        emit_only.run(&mut p, &mut Stats::default());
        let got = mean_se(
            p.tracing.walkers.power[..n].iter().map(|v| v.as_dvec3()),
            n as f64,
        );
        let total = p.data.scene.emitters.total_power.as_dvec3();
        assert_close(name, got, total);
    }
}

#[test]
fn scattered_power_follows_the_albedo() {
    // The furnace is closed and grey (albedo 0.5): every photon lands, and the power landing
    // after d bounces is 0.5^d of the emitted power in expectation.
    let mut p = pass("furnace.ron", u32::MAX);
    let n = 200_000u64;
    p.trace(&photons::graph(), 0, n, &mut Stats::default());
    let t = &p.tracing;
    assert_eq!(t.emitted, n);
    let total = p.data.scene.emitters.total_power.as_dvec3();
    for depth in 0..4u32 {
        let landed = (0..t.stored).map(|i| {
            if t.photons.depth[i] == depth {
                t.photons.power[i].as_dvec3()
            } else {
                DVec3::ZERO
            }
        });
        // Per emitted photon: the photons of one path land at distinct depths.
        let got = mean_se(landed, n as f64);
        assert_close(
            &format!("depth {depth}"),
            got,
            total * 0.5f64.powi(depth as i32),
        );
    }
    assert!((0..t.stored).all(|i| !t.photons.flags[i].has(PhotonFlags::CAUSTIC)));
    assert!(
        (0..t.stored)
            .all(|i| t.photons.flags[i].has(PhotonFlags::DIRECT) == (t.photons.depth[i] == 0))
    );
}

#[test]
fn caustic_photons_come_through_glass() {
    let mut p = pass("torus_glass.ron", u32::MAX);
    p.trace(&photons::graph(), 0, 100_000, &mut Stats::default());
    let t = &p.tracing;
    let caustic = (0..t.stored)
        .filter(|&i| t.photons.flags[i].has(PhotonFlags::CAUSTIC))
        .count();
    assert!(caustic > 100, "only {caustic} caustic photons");
}

/// A point d bounces from the camera may gather photons of up to max_depth - d - 1 bounces:
/// the photon lands on the point, one bounce more. Photons deeper than a point the camera sees
/// directly could take could never count, so they are not stored.
#[test]
fn the_photon_depth_limit_counts_the_whole_path() {
    assert_eq!(photons::photon_depth_limit(3, 0), Some(2));
    assert_eq!(photons::photon_depth_limit(3, 2), Some(0));
    assert_eq!(photons::photon_depth_limit(3, 3), None);
    assert_eq!(photons::photon_depth_limit(0, 0), None);
    assert_eq!(photons::photon_depth_limit(u32::MAX, u32::MAX), None);
    assert_eq!(photons::deepest_stored_photon(3), 2);
    assert_eq!(photons::deepest_stored_photon(0), 0);
    assert_eq!(photons::deepest_stored_photon(u32::MAX), u32::MAX - 1);
}

#[test]
fn stored_photons_do_not_depend_on_threads() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut p = pass("torus_glass.ron", u32::MAX);
            // More photons than one wave, to cross a wave boundary.
            p.trace(&photons::graph(), 3, 70_000, &mut Stats::default());
            let t = &p.tracing;
            (0..t.stored)
                .map(|i| (t.photons.p[i], t.photons.power[i], t.photons.depth[i]))
                .collect::<Vec<(Vec3, Vec3, u32)>>()
        })
    };
    let one = run(1);
    assert!(!one.is_empty());
    assert_eq!(one, run(2));
    assert_eq!(one, run(3));
}

fn random_points(n: usize, seed: u64) -> Vec<Vec3> {
    let key = |i: usize| stagelight::sampling::SampleKey::new(seed, i as u64, 0);
    (0..n)
        .map(|i| {
            let k = key(i);
            // Clustered on a few planes, like photons on walls, plus some spread.
            let plane = (k.get(3) * 4.0) as u32;
            let v = Vec3::new(k.get(0), k.get(1), k.get(2)) * 10.0;
            match plane {
                0 => Vec3::new(v.x, 0.0, v.z),
                1 => Vec3::new(0.0, v.y, v.z),
                _ => v,
            }
        })
        .collect()
}

#[test]
fn hash_grid_finds_exactly_the_points_within_the_radius() {
    let points = random_points(20_000, 1);
    let radius = 0.3;
    let grid = stagelight::photons::HashGrid::build(&points, radius);
    for (j, q) in random_points(300, 2).iter().enumerate() {
        let r = if j % 2 == 0 { radius } else { radius * 0.5 };
        let mut found = Vec::new();
        grid.for_each_within(&points, *q, r, |i| found.push(i));
        found.sort_unstable();
        let expected: Vec<u32> = (0..points.len() as u32)
            .filter(|&i| points[i as usize].distance_squared(*q) <= r * r)
            .collect();
        assert_eq!(found, expected, "query {j}");
    }
    // The octant query of a grid with cells twice the radius finds the same points.
    let wide = stagelight::photons::HashGrid::build_for_octants(&points, radius);
    let mut nonempty = 0;
    for (j, q) in random_points(300, 5).iter().enumerate() {
        let r = if j % 2 == 0 { radius } else { radius * 0.5 };
        let mut found = Vec::new();
        wide.for_each_within_octants(&points, *q, r, |i| found.push(i));
        found.sort_unstable();
        let expected: Vec<u32> = (0..points.len() as u32)
            .filter(|&i| points[i as usize].distance_squared(*q) <= r * r)
            .collect();
        nonempty += !expected.is_empty() as u32;
        assert_eq!(found, expected, "octant query {j}");
    }
    assert!(
        nonempty > 100,
        "only {nonempty} octant queries found points"
    );
}

#[test]
fn kd_tree_finds_the_k_nearest() {
    let points = random_points(20_000, 3);
    let tree = stagelight::photons::KdTree::build(&points);
    let mut near = stagelight::photons::Nearest::new(1, 1.0);
    for (j, q) in random_points(300, 4).iter().enumerate() {
        let (k, max_r) = if j % 3 == 0 {
            (50, 0.2)
        } else {
            (50, f32::INFINITY)
        };
        tree.nearest(*q, k, max_r, &mut near);
        let mut got: Vec<f32> = near.found.iter().map(|f| f.0).collect();
        got.sort_by(f32::total_cmp);
        let mut all: Vec<f32> = points
            .iter()
            .map(|p| p.distance_squared(*q))
            .filter(|&d2| d2 <= max_r * max_r)
            .collect();
        all.sort_by(f32::total_cmp);
        all.truncate(k);
        assert_eq!(got, all, "query {j}");
        for &(d2, i) in &near.found {
            assert_eq!(points[i as usize].distance_squared(*q), d2);
        }
    }
}

#[test]
fn grid_and_kd_tree_answer_both_queries_alike() {
    let points = random_points(20_000, 5);
    let tree = stagelight::photons::KdTree::build(&points);
    let grid = stagelight::photons::HashGrid::build(&points, 1.0);
    let mut near = stagelight::photons::Nearest::new(1, 1.0);
    for q in random_points(200, 6) {
        let (mut a, mut b) = (Vec::new(), Vec::new());
        tree.for_each_within(q, 0.7, |i| a.push(i));
        grid.for_each_within(&points, q, 0.7, |i| b.push(i));
        a.sort_unstable();
        b.sort_unstable();
        assert!(!a.is_empty() || q.length() > 0.0);
        assert_eq!(a, b);
        grid.nearest(&points, q, 30, 1.0, &mut near);
        let mut from_grid = near.found.clone();
        tree.nearest(q, 30, 1.0, &mut near);
        let mut from_tree = near.found.clone();
        from_grid.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        from_tree.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        assert_eq!(from_grid, from_tree);
    }
}
