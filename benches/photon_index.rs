//! The photon index: a hash grid (fixed radius) against a kd-tree (k nearest), on real
//! photons and visible points of the Cornell box (one photon pass with direct photons kept,
//! as PM stores them; the visible points of one SPPM pass). Both structures answer both
//! kinds of query, so each is measured at each:
//!
//! - build, at 250k and 500k photons emitted;
//! - the PPM/SPPM gather: every photon within the initial radius of every visible point;
//! - the PM estimate: the 50 nearest within the default maximum radius.
//!
//! `cargo bench --bench photon_index`; criterion's elem/s is photons (build) or queries.

use criterion::{Criterion, Throughput, criterion_group};
use glam::Vec3;
use stagelight::components::NO_VISIBLE_POINT;
use stagelight::integrators::SceneData;
use stagelight::integrators::pm::{DEFAULT_K, PmSettings};
use stagelight::integrators::sppm::{self, ProgressiveSettings};
use stagelight::photons::{HashGrid, KdTree, Nearest, PhotonPass};
use stagelight::pipeline::Stats;
use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

fn scene() -> Arc<SceneData> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.ron");
    Arc::new(SceneData::new(
        stagelight::scene::load(&path).expect("scene loads"),
    ))
}

fn photons(data: &Arc<SceneData>, emitted: u64) -> Vec<Vec3> {
    let mut pass = PhotonPass::new(
        data.clone(),
        stagelight::sampling::Sampler::Independent { seed: 1 },
        u32::MAX,
    );
    pass.trace(
        &stagelight::photons::graph(),
        0,
        emitted,
        &mut Stats::default(),
    );
    pass.tracing.photons.p[..pass.tracing.stored].to_vec()
}

fn visible_points(data: &Arc<SceneData>) -> Vec<Vec3> {
    let settings = ProgressiveSettings {
        photons_per_pass: 1,
        ..ProgressiveSettings::new(1, true)
    };
    let state = sppm::run_passes(data.clone(), settings, 1);
    (0..state.pixels)
        .filter(|&i| state.camera_walk.visible.triangle[i] != NO_VISIBLE_POINT)
        .map(|i| state.camera_walk.visible.p[i])
        .collect()
}

fn bench(c: &mut Criterion) {
    let data = scene();
    let queries = visible_points(&data);
    let radius = ProgressiveSettings::new(0, true).radius_in(&data);
    let max_radius = PmSettings::new(0).max_radius_in(&data);
    for emitted in [250_000u64, 500_000] {
        let points = photons(&data, emitted);
        let label = format!("{}k", emitted / 1000);

        let mut g = c.benchmark_group(format!("build_{label}"));
        g.sample_size(10).measurement_time(Duration::from_secs(3));
        g.throughput(Throughput::Elements(points.len() as u64));
        g.bench_function("hash_grid", |b| {
            b.iter(|| HashGrid::build(black_box(&points), radius))
        });
        g.bench_function("kd_tree", |b| b.iter(|| KdTree::build(black_box(&points))));
        g.finish();

        let grid = HashGrid::build(&points, max_radius);
        let tree = KdTree::build(&points);
        let mut g = c.benchmark_group(format!("radius_gather_{label}"));
        g.sample_size(10).measurement_time(Duration::from_secs(3));
        g.throughput(Throughput::Elements(queries.len() as u64));
        let fine_grid = HashGrid::build(&points, radius);
        g.bench_function("hash_grid", |b| {
            b.iter(|| {
                let mut n = 0usize;
                for q in &queries {
                    fine_grid.for_each_within(&points, *q, radius, |_| n += 1);
                }
                n
            })
        });
        g.bench_function("kd_tree", |b| {
            b.iter(|| {
                let mut n = 0usize;
                for q in &queries {
                    tree.for_each_within(*q, radius, |_| n += 1);
                }
                n
            })
        });
        g.finish();

        let mut g = c.benchmark_group(format!("k_nearest_{label}"));
        g.sample_size(10).measurement_time(Duration::from_secs(3));
        g.throughput(Throughput::Elements(queries.len() as u64));
        let mut near = Nearest::new(DEFAULT_K, max_radius);
        g.bench_function("hash_grid", |b| {
            b.iter(|| {
                let mut n = 0usize;
                for q in &queries {
                    grid.nearest(&points, *q, DEFAULT_K, max_radius, &mut near);
                    n += near.found.len();
                }
                n
            })
        });
        g.bench_function("kd_tree", |b| {
            b.iter(|| {
                let mut n = 0usize;
                for q in &queries {
                    tree.nearest(*q, DEFAULT_K, max_radius, &mut near);
                    n += near.found.len();
                }
                n
            })
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
}
