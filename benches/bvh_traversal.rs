//! BVH traversal throughput: closest-hit and any-hit queries of incoherent rays (origins
//! uniform in the scene's bounds, directions uniform on the sphere, fixed seed), on the shipped
//! scenes and on built-in stand-ins of them (so that the numbers exist even where the scenes
//! cannot be loaded).
//!
//! Throughput is in rays: criterion's "elem/s" is rays per second on one thread.
//! `BVH_COMPARE=1 cargo bench --bench bvh_traversal` prints best-of-many Mrays/s instead, with
//! obvhs' own (not watertight) CWBVH traversal as a reference.

use criterion::{Criterion, Throughput, criterion_group};
use glam::{Vec2, Vec3};
use stagelight::accel::Accel;
use stagelight::sampling::{SampleKey, uniform_sphere};
use stagelight::scene::{FLAT, NO_EMITTER, TriangleColumns};
use std::collections::HashMap;
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

fn bench_loaded(c: &mut Criterion, file: &str) {
    // The loader may be missing or fail: then only the stand-ins are measured.
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(file);
    match std::panic::catch_unwind(|| stagelight::scene::load(&path)) {
        Ok(Ok(scene)) => bench_scene(
            c,
            file,
            &scene.triangles,
            scene.bounds_min,
            scene.bounds_max,
        ),
        Ok(Err(e)) => eprintln!("skipping {file}: {e}"),
        Err(_) => eprintln!("skipping {file}: the loader panicked"),
    }
}

fn traversal(c: &mut Criterion) {
    bench_loaded(c, "cornell_box.ron");
    bench_loaded(c, "door_ajar.ron");

    let cornell = standin::cornell_box();
    let (lo, hi) = standin::bounds(&cornell);
    bench_scene(c, "stand-in cornell_box", &cornell, lo, hi);
    let door = standin::door_ajar();
    let (lo, hi) = standin::bounds(&door);
    bench_scene(c, "stand-in door_ajar", &door, lo, hi);
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
    let scenes = [
        ("cornell_box stand-in", standin::cornell_box()),
        ("door_ajar stand-in", standin::door_ajar()),
    ];
    for (name, tris) in &scenes {
        let (lo, hi) = standin::bounds(tris);
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

/// Triangle soups shaped like the shipped scenes (geometry from shared/SCENES.md).
mod standin {
    use super::*;

    fn columns(tris: &[[Vec3; 3]]) -> TriangleColumns {
        TriangleColumns {
            p0: tris.iter().map(|t| t[0]).collect(),
            p1: tris.iter().map(|t| t[1]).collect(),
            p2: tris.iter().map(|t| t[2]).collect(),
            normal: tris
                .iter()
                .map(|t| (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero())
                .collect(),
            material: vec![0; tris.len()],
            emitter: vec![NO_EMITTER; tris.len()],
            smooth: vec![FLAT; tris.len()],
            vertex_normals: Vec::new(),
        }
    }

    pub fn bounds(t: &TriangleColumns) -> (Vec3, Vec3) {
        let all = t.p0.iter().chain(&t.p1).chain(&t.p2);
        let lo = all.clone().fold(Vec3::INFINITY, |a, &p| a.min(p));
        let hi = all.fold(Vec3::NEG_INFINITY, |a, &p| a.max(p));
        (lo, hi)
    }

    /// (a, b, c, d) as the triangles (a, b, c) and (a, c, d).
    fn quad(tris: &mut Vec<[Vec3; 3]>, q: [[f32; 3]; 4]) {
        let [a, b, c, d] = q.map(Vec3::from);
        tris.extend([[a, b, c], [a, c, d]]);
    }

    /// The Cornell box: 32 triangles.
    pub fn cornell_box() -> TriangleColumns {
        let quads: [[[f32; 3]; 4]; 16] = [
            [
                [552.8, 0.0, 0.0],
                [0.0, 0.0, 0.0],
                [0.0, 0.0, 559.2],
                [549.6, 0.0, 559.2],
            ],
            [
                [556.0, 548.8, 0.0],
                [556.0, 548.8, 559.2],
                [0.0, 548.8, 559.2],
                [0.0, 548.8, 0.0],
            ],
            [
                [549.6, 0.0, 559.2],
                [0.0, 0.0, 559.2],
                [0.0, 548.8, 559.2],
                [556.0, 548.8, 559.2],
            ],
            [
                [0.0, 0.0, 559.2],
                [0.0, 0.0, 0.0],
                [0.0, 548.8, 0.0],
                [0.0, 548.8, 559.2],
            ],
            [
                [552.8, 0.0, 0.0],
                [549.6, 0.0, 559.2],
                [556.0, 548.8, 559.2],
                [556.0, 548.8, 0.0],
            ],
            [
                [343.0, 548.7, 227.0],
                [343.0, 548.7, 332.0],
                [213.0, 548.7, 332.0],
                [213.0, 548.7, 227.0],
            ],
            [
                [130.0, 165.0, 65.0],
                [82.0, 165.0, 225.0],
                [240.0, 165.0, 272.0],
                [290.0, 165.0, 114.0],
            ],
            [
                [290.0, 0.0, 114.0],
                [290.0, 165.0, 114.0],
                [240.0, 165.0, 272.0],
                [240.0, 0.0, 272.0],
            ],
            [
                [130.0, 0.0, 65.0],
                [130.0, 165.0, 65.0],
                [290.0, 165.0, 114.0],
                [290.0, 0.0, 114.0],
            ],
            [
                [82.0, 0.0, 225.0],
                [82.0, 165.0, 225.0],
                [130.0, 165.0, 65.0],
                [130.0, 0.0, 65.0],
            ],
            [
                [240.0, 0.0, 272.0],
                [240.0, 165.0, 272.0],
                [82.0, 165.0, 225.0],
                [82.0, 0.0, 225.0],
            ],
            [
                [423.0, 330.0, 247.0],
                [265.0, 330.0, 296.0],
                [314.0, 330.0, 456.0],
                [472.0, 330.0, 406.0],
            ],
            [
                [423.0, 0.0, 247.0],
                [423.0, 330.0, 247.0],
                [472.0, 330.0, 406.0],
                [472.0, 0.0, 406.0],
            ],
            [
                [472.0, 0.0, 406.0],
                [472.0, 330.0, 406.0],
                [314.0, 330.0, 456.0],
                [314.0, 0.0, 456.0],
            ],
            [
                [314.0, 0.0, 456.0],
                [314.0, 330.0, 456.0],
                [265.0, 330.0, 296.0],
                [265.0, 0.0, 296.0],
            ],
            [
                [265.0, 0.0, 296.0],
                [265.0, 330.0, 296.0],
                [423.0, 330.0, 247.0],
                [423.0, 0.0, 247.0],
            ],
        ];
        let mut tris = Vec::new();
        for q in quads {
            quad(&mut tris, q);
        }
        columns(&tris)
    }

    fn aabb_box(tris: &mut Vec<[Vec3; 3]>, lo: Vec3, hi: Vec3) {
        let p = |x: bool, y: bool, z: bool| {
            Vec3::new(
                if x { hi.x } else { lo.x },
                if y { hi.y } else { lo.y },
                if z { hi.z } else { lo.z },
            )
        };
        let faces = [
            [
                p(false, false, false),
                p(false, false, true),
                p(false, true, true),
                p(false, true, false),
            ],
            [
                p(true, false, false),
                p(true, true, false),
                p(true, true, true),
                p(true, false, true),
            ],
            [
                p(false, false, false),
                p(true, false, false),
                p(true, false, true),
                p(false, false, true),
            ],
            [
                p(false, true, false),
                p(false, true, true),
                p(true, true, true),
                p(true, true, false),
            ],
            [
                p(false, false, false),
                p(false, true, false),
                p(true, true, false),
                p(true, false, false),
            ],
            [
                p(false, false, true),
                p(true, false, true),
                p(true, true, true),
                p(false, true, true),
            ],
        ];
        for [a, b, c, d] in faces {
            tris.extend([[a, b, c], [a, c, d]]);
        }
    }

    fn icosphere(tris: &mut Vec<[Vec3; 3]>, level: u32, centre: Vec3, radius: f32) {
        let phi = (1.0 + 5.0f32.sqrt()) / 2.0;
        let mut verts: Vec<Vec3> = [
            (-1.0, phi, 0.0),
            (1.0, phi, 0.0),
            (-1.0, -phi, 0.0),
            (1.0, -phi, 0.0),
            (0.0, -1.0, phi),
            (0.0, 1.0, phi),
            (0.0, -1.0, -phi),
            (0.0, 1.0, -phi),
            (phi, 0.0, -1.0),
            (phi, 0.0, 1.0),
            (-phi, 0.0, -1.0),
            (-phi, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
        .collect();
        let mut faces: Vec<[usize; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..level {
            let mut mids: HashMap<(usize, usize), usize> = HashMap::new();
            let mut next = Vec::with_capacity(faces.len() * 4);
            for [a, b, c] in faces {
                let mut mid = |a: usize, b: usize| {
                    *mids.entry((a.min(b), a.max(b))).or_insert_with(|| {
                        verts.push(((verts[a] + verts[b]) * 0.5).normalize());
                        verts.len() - 1
                    })
                };
                let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            faces = next;
        }
        tris.extend(faces.iter().map(|f| f.map(|i| centre + radius * verts[i])));
    }

    /// Two rooms, a door ajar, a table and two level-4 icospheres: 10,340 triangles.
    pub fn door_ajar() -> TriangleColumns {
        let mut t = Vec::new();
        let rect_y = |t: &mut Vec<[Vec3; 3]>, y: f32, x0: f32, x1: f32, z0: f32, z1: f32| {
            quad(t, [[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]]);
        };
        let rect_x = |t: &mut Vec<[Vec3; 3]>, x: f32, y0: f32, y1: f32, z0: f32, z1: f32| {
            quad(t, [[x, y0, z0], [x, y1, z0], [x, y1, z1], [x, y0, z1]]);
        };
        let rect_z = |t: &mut Vec<[Vec3; 3]>, z: f32, x0: f32, x1: f32, y0: f32, y1: f32| {
            quad(t, [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]);
        };
        for (z0, z1) in [(0.0, 4.0), (4.0, 7.0)] {
            rect_y(&mut t, 0.0, 0.0, 4.0, z0, z1);
            rect_y(&mut t, 2.6, 0.0, 4.0, z0, z1);
            rect_x(&mut t, 0.0, 0.0, 2.6, z0, z1);
            rect_x(&mut t, 4.0, 0.0, 2.6, z0, z1);
        }
        rect_z(&mut t, 0.0, 0.0, 4.0, 0.0, 2.6);
        rect_z(&mut t, 7.0, 0.0, 4.0, 0.0, 2.6);
        rect_z(&mut t, 4.0, 0.0, 1.5, 0.0, 2.6);
        rect_z(&mut t, 4.0, 2.4, 4.0, 0.0, 2.6);
        rect_z(&mut t, 4.0, 1.5, 2.4, 2.1, 2.6);
        let (c, s) = (15f32.to_radians().cos(), 15f32.to_radians().sin());
        let (fx, fz) = (1.5 + 0.9 * c, 4.0 - 0.9 * s);
        quad(
            &mut t,
            [
                [1.5, 0.0, 4.0],
                [fx, 0.0, fz],
                [fx, 2.1, fz],
                [1.5, 2.1, 4.0],
            ],
        );
        rect_y(&mut t, 2.59, 2.8, 3.8, 5.5, 6.5);
        aabb_box(&mut t, Vec3::new(1.2, 0.70, 1.8), Vec3::new(2.8, 0.75, 2.8));
        for x in [1.2, 2.75] {
            for z in [1.8, 2.75] {
                aabb_box(
                    &mut t,
                    Vec3::new(x, 0.0, z),
                    Vec3::new(x + 0.05, 0.70, z + 0.05),
                );
            }
        }
        icosphere(&mut t, 4, Vec3::new(1.7, 0.90, 2.3), 0.15);
        icosphere(&mut t, 4, Vec3::new(2.3, 0.90, 2.3), 0.15);
        columns(&t)
    }
}
