//! BVH traversal throughput: closest-hit and any-hit queries of incoherent rays (origins
//! uniform in the scene's bounds, directions uniform on the sphere, fixed seed), on the Cornell
//! box and door_ajar scenes.
//!
//! Throughput is in rays: criterion's "elem/s" is rays per second on one thread.
//! `BVH_COMPARE=1 cargo bench --bench bvh_traversal` prints best-of-many Mrays/s instead, with
//! obvhs' own (not watertight) CWBVH traversal as a reference.

use criterion::{Criterion, Throughput, criterion_group};
use glam::{Vec2, Vec3};
use stagelight::accel::Accel;
use stagelight::sampling::{SampleKey, uniform_sphere};
use stagelight::scene::TriangleColumns;
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

const RAYS: usize = 16_384;
const SEED: u64 = 0x5eed;

struct Ray {
    origin: Vec3,
    dir: Vec3,
    /// For any-hit: a segment of random length up to half the scene's diagonal.
    t_max: f32,
}

fn incoherent_rays(lo: Vec3, hi: Vec3) -> Vec<Ray> {
    let diag = (hi - lo).length();
    (0..RAYS as u64)
        .map(|i| {
            let k = SampleKey::new(SEED, i, 0);
            Ray {
                origin: lo + (hi - lo) * Vec3::new(k.get(0), k.get(1), k.get(2)),
                dir: uniform_sphere(Vec2::new(k.get(3), k.get(4))),
                t_max: 0.5 * diag * k.get(5),
            }
        })
        .collect()
}

fn bench_scene(c: &mut Criterion, name: &str, tris: &TriangleColumns, lo: Vec3, hi: Vec3) {
    let rays = incoherent_rays(lo, hi);
    let mut group = c.benchmark_group(format!("{name} ({} triangles)", tris.len()));
    group.throughput(Throughput::Elements(RAYS as u64));
    let accel = Accel::build(tris);
    group.bench_function("closest_hit", |b| {
        b.iter(|| {
            for r in &rays {
                black_box(accel.closest_hit(r.origin, r.dir, f32::INFINITY));
            }
        })
    });
    group.bench_function("any_hit", |b| {
        b.iter(|| {
            for r in &rays {
                black_box(accel.any_hit(r.origin, r.dir, r.t_max));
            }
        })
    });
    group.finish();
}

fn load(file: &str) -> TriangleColumns {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(file);
    match stagelight::scene::load(&path) {
        Ok(scene) => scene.triangles,
        Err(e) => panic!("{e}"),
    }
}

fn bounds(t: &TriangleColumns) -> (Vec3, Vec3) {
    let all = t.p0.iter().chain(&t.p1).chain(&t.p2);
    let lo = all.clone().fold(Vec3::INFINITY, |a, &p| a.min(p));
    let hi = all.fold(Vec3::NEG_INFINITY, |a, &p| a.max(p));
    (lo, hi)
}

const SCENES: [&str; 2] = ["cornell_box.ron", "door_ajar.ron"];

fn traversal(c: &mut Criterion) {
    for file in SCENES {
        let tris = load(file);
        let (lo, hi) = bounds(&tris);
        bench_scene(c, file, &tris, lo, hi);
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    targets = traversal
}

/// `BVH_COMPARE=1 cargo bench --bench bvh_traversal`: the variants interleaved, each timed as
/// the best of many passes, which shared, noisy machines disturb far less than criterion's
/// means. The reference is obvhs' own CWBVH traversal with its Moeller-Trumbore triangle test
/// (not watertight, non-conservative boxes), closest hit, on the same tree and leaf order.
fn compare() {
    for name in SCENES {
        let tris = &load(name);
        let (lo, hi) = bounds(tris);
        let rays = incoherent_rays(lo, hi);
        let accel = Accel::build(tris);
        let soup: Vec<obvhs::triangle::Triangle> = (0..tris.len())
            .map(|i| obvhs::triangle::Triangle {
                v0: tris.p0[i].into(),
                v1: tris.p1[i].into(),
                v2: tris.p2[i].into(),
            })
            .collect();
        let cw = obvhs::cwbvh::builder::build_cwbvh_from_tris(
            &soup,
            obvhs::BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let leaf: Vec<_> = cw
            .primitive_indices
            .iter()
            .map(|&i| soup[i as usize])
            .collect();
        let time = |best: &mut f64, f: &dyn Fn(&Ray)| {
            let start = std::time::Instant::now();
            rays.iter().for_each(f);
            *best = best.min(start.elapsed().as_secs_f64());
        };
        let mut best = [f64::INFINITY; 3];
        for _ in 0..40 {
            time(&mut best[0], &|r| {
                black_box(accel.closest_hit(r.origin, r.dir, f32::INFINITY));
            });
            time(&mut best[1], &|r| {
                black_box(accel.any_hit(r.origin, r.dir, r.t_max));
            });
            time(&mut best[2], &|r| {
                let ray = obvhs::ray::Ray::new_inf(r.origin.into(), r.dir.into());
                let mut hit = obvhs::ray::RayHit::none();
                black_box(cw.ray_traverse(ray, &mut hit, |ray, i| leaf[i].intersect(ray)));
            });
        }
        let mrays = |t: f64| RAYS as f64 / t * 1e-6;
        println!(
            "{name:22} closest {:5.2} Mrays/s, any {:5.2} Mrays/s; obvhs' own closest {:5.2} Mrays/s",
            mrays(best[0]),
            mrays(best[1]),
            mrays(best[2])
        );
    }
}

fn main() {
    if std::env::var_os("BVH_COMPARE").is_some() {
        compare();
    } else {
        benches();
        Criterion::default().configure_from_args().final_summary();
    }
}
