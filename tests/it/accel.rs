//! The accelerator against brute force, watertightness on closed meshes, robust ray spawning,
//! surface point error bounds and degenerate input.

use glam::{DVec3, Vec3};
use stagelight::accel::{Accel, Hit, intersect_triangle};
use stagelight::geometry::{offset_ray_origin, spawn_ray_to, surface_point};
use stagelight::sampling::{SampleKey, uniform_sphere};
use stagelight::scene::{FLAT, NO_EMITTER, TriangleColumns};

/// A counter-based random stream over `SampleKey`.
struct Rng {
    seed: u64,
    n: u64,
}

impl Rng {
    fn new(seed: u64) -> Rng {
        Rng { seed, n: 0 }
    }
    fn f(&mut self) -> f32 {
        self.n += 1;
        SampleKey::new(self.seed, self.n, 0).get(0)
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
    fn vec_in(&mut self, lo: Vec3, hi: Vec3) -> Vec3 {
        Vec3::new(
            self.range(lo.x, hi.x),
            self.range(lo.y, hi.y),
            self.range(lo.z, hi.z),
        )
    }
    fn dir(&mut self) -> Vec3 {
        let u = glam::Vec2::new(self.f(), self.f());
        uniform_sphere(u)
    }
    fn index(&mut self, n: usize) -> usize {
        ((self.f() * n as f32) as usize).min(n - 1)
    }
}

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

fn random_soup(rng: &mut Rng, n: usize, lo: Vec3, hi: Vec3, size: f32) -> Vec<[Vec3; 3]> {
    (0..n)
        .map(|_| {
            let c = rng.vec_in(lo, hi);
            let s = size * rng.range(0.05, 1.0);
            [c + s * rng.dir(), c + s * rng.dir(), c + s * rng.dir()]
        })
        .collect()
}

/// An icosphere (closed, outward winding) of the given level, from the scene module's shapes.
fn icosphere(level: u32, centre: Vec3, radius: f32) -> Vec<[Vec3; 3]> {
    let mesh = stagelight::scene::shapes::icosphere(level, false);
    mesh.triangles
        .iter()
        .map(|t| t.map(|i| centre + radius * mesh.positions[i as usize].as_vec3()))
        .collect()
}

/// A closed axis-aligned box, each face an n x n grid of quads (two triangles each); all
/// vertices are exact (dyadic) and shared exactly between faces.
fn grid_box(lo: Vec3, hi: Vec3, n: u32) -> Vec<[Vec3; 3]> {
    let at = |axis: usize, i: u32| lo[axis] + (hi[axis] - lo[axis]) * (i as f32 / n as f32);
    let mut tris = Vec::new();
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [0, n] {
            for i in 0..n {
                for j in 0..n {
                    let p = |di: u32, dj: u32| {
                        let mut q = [0.0f32; 3];
                        q[axis] = at(axis, side);
                        q[u] = at(u, i + di);
                        q[v] = at(v, j + dj);
                        Vec3::from(q)
                    };
                    let (a, b, c, d) = (p(0, 0), p(1, 0), p(1, 1), p(0, 1));
                    if side == 0 {
                        tris.extend([[a, c, b], [a, d, c]]);
                    } else {
                        tris.extend([[a, b, c], [a, c, d]]);
                    }
                }
            }
        }
    }
    tris
}

fn brute_force(tris: &[[Vec3; 3]], o: Vec3, d: Vec3, t_max: f32) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    let mut t_max = t_max;
    for (i, tri) in tris.iter().enumerate() {
        if let Some((t, b1, b2)) = intersect_triangle(o, d, tri, t_max) {
            t_max = t;
            best = Some(Hit {
                t,
                triangle: i as u32,
                b1,
                b2,
            });
        }
    }
    best
}

/// Checks one ray's closest and any hit against brute force; returns whether it hits.
fn check_ray(accel: &Accel, tris: &[[Vec3; 3]], o: Vec3, d: Vec3, t_max: f32) -> bool {
    let expected = brute_force(tris, o, d, t_max);
    let got = accel.closest_hit(o, d, t_max);
    match (expected, got) {
        (None, None) => {}
        (Some(e), Some(g)) => {
            assert_eq!(e.t, g.t, "t differs for o={o} d={d}");
            if e.triangle != g.triangle {
                // Only a tie at exactly the same t may pick another triangle.
                let other = intersect_triangle(o, d, &tris[g.triangle as usize], t_max);
                assert_eq!(other.map(|h| h.0), Some(e.t), "o={o} d={d}");
            } else {
                assert_eq!((e.b1, e.b2), (g.b1, g.b2));
            }
            assert!(g.t > 0.0 && g.t < t_max);
        }
        _ => panic!("brute force {expected:?}, accel {got:?}, o={o} d={d} t_max={t_max}"),
    }
    assert_eq!(accel.any_hit(o, d, t_max), got.is_some(), "any_hit");
    got.is_some()
}

/// Returns the number of hits seen.
fn check_against_brute_force(
    tris: &[[Vec3; 3]],
    rng: &mut Rng,
    rays: usize,
    origin_box: (Vec3, Vec3),
) -> usize {
    let accel = Accel::build(&columns(tris));
    let mut hits = 0;
    for _ in 0..rays {
        let o = rng.vec_in(origin_box.0, origin_box.1);
        let d = rng.dir() * rng.range(0.01, 100.0);
        let t_max = if rng.f() < 0.5 {
            f32::INFINITY
        } else {
            rng.range(0.0, 2.0)
        };
        hits += usize::from(check_ray(&accel, tris, o, d, t_max));
    }
    hits
}

#[test]
fn closest_hit_matches_brute_force_on_random_soups() {
    let mut rng = Rng::new(1);
    let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
    let mut hits = 0;
    for (n, size) in [(1, 2.0), (2, 1.5), (7, 1.0), (100, 0.5), (3000, 0.15)] {
        let tris = random_soup(&mut rng, n, lo, hi, size);
        hits += check_against_brute_force(&tris, &mut rng, 10_000, (lo * 1.2, hi * 1.2));
    }
    assert!(hits > 5_000, "too few hits ({hits}) for a meaningful test");
    // Far from the origin, with large coordinates.
    let offset = Vec3::splat(1e5);
    let tris = random_soup(&mut rng, 500, lo * 10.0 + offset, hi * 10.0 + offset, 2.0);
    let hits = check_against_brute_force(
        &tris,
        &mut rng,
        5000,
        (lo * 12.0 + offset, hi * 12.0 + offset),
    );
    assert!(hits > 500, "too few hits ({hits}) for a meaningful test");
}

/// Against brute force where the box test's rounding is hardest (written for the quantized
/// node boxes tried on branch exp-quantized-nodes, kept for any box format): a tiny scene
/// (1e-20 across), scenes far from the origin for their size, triangles of sizes over six
/// orders of magnitude in one soup, flat axis-aligned triangles (boxes of zero extent along an
/// axis), and rays along the axes (zero direction components: infinite reciprocals in the box
/// test), from inside the scene and from the planes of the flat triangles.
#[test]
fn closest_hit_matches_brute_force_at_extreme_scales_and_along_the_axes() {
    let mut rng = Rng::new(13);
    let mut hits = 0;
    for (scale, offset) in [(1e-20, 0.0), (1.0, 0.0), (1.0, 3e5), (1e7, 1e11)] {
        let centre = Vec3::new(offset, -0.5 * offset, 0.25 * offset);
        let (lo, hi) = (centre - Vec3::splat(scale), centre + Vec3::splat(scale));
        let mut tris: Vec<[Vec3; 3]> = (0..1500)
            .map(|_| {
                let c = rng.vec_in(lo, hi);
                let s = scale * 10f32.powf(rng.range(-5.0, 0.5));
                [c + s * rng.dir(), c + s * rng.dir(), c + s * rng.dir()]
            })
            .collect();
        // Flat axis-aligned triangles, some sharing a plane with an axis ray below.
        let flat: Vec<[Vec3; 3]> = (0..300)
            .map(|k| {
                let axis = k % 3;
                let mut c = rng.vec_in(lo, hi);
                c[axis] = centre[axis] + scale * ((k / 3) % 5) as f32 * 0.25;
                let s = scale * rng.range(0.01, 0.3);
                let mut corner = || {
                    let mut v = c + s * rng.dir();
                    v[axis] = c[axis];
                    v
                };
                [corner(), corner(), corner()]
            })
            .collect();
        tris.extend(flat);
        tris.retain(|t| (t[1] - t[0]).cross(t[2] - t[0]) != Vec3::ZERO);
        let accel = Accel::build(&columns(&tris));
        for k in 0..6000 {
            let mut o = rng.vec_in(lo, hi);
            let d = if k % 2 == 0 {
                // Along an axis, sometimes from a flat triangle's plane.
                let axis = k / 2 % 3;
                if k % 8 == 0 {
                    o[(axis + 1) % 3] = centre[(axis + 1) % 3] + scale * (k / 8 % 5) as f32 * 0.25;
                }
                let mut d = Vec3::ZERO;
                d[axis] = if k % 4 == 0 { 1.0 } else { -1.0 };
                d
            } else {
                rng.dir()
            };
            let t_max = if k % 3 == 0 {
                f32::INFINITY
            } else {
                3.0 * scale * rng.f()
            };
            hits += usize::from(check_ray(&accel, &tris, o, d, t_max));
        }
    }
    assert!(hits > 4000, "too few hits ({hits}) for a meaningful test");
}

/// One outsized triangle (a floor 2e10 wide) under a small scene: the tree is built from boxes
/// clipped to the scene and pads each box by its own magnitudes (a padding scaled to the
/// largest vertex made every ray enter every box, 250x slower: see
/// docs/measurements/outsized-triangles.md); hits stay exact against brute force.
#[test]
fn closest_hit_matches_brute_force_beside_an_outsized_floor() {
    let mut rng = Rng::new(7);
    let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
    let mut tris = random_soup(&mut rng, 3000, lo, hi, 0.15);
    let (y, w) = (-0.75, 1e10);
    tris.push([
        Vec3::new(-w, y, -w),
        Vec3::new(-w, y, w),
        Vec3::new(w, y, w),
    ]);
    tris.push([
        Vec3::new(-w, y, -w),
        Vec3::new(w, y, w),
        Vec3::new(w, y, -w),
    ]);
    let hits = check_against_brute_force(&tris, &mut rng, 10_000, (lo * 1.2, hi * 1.2));
    assert!(hits > 4_000, "too few hits ({hits}) for a meaningful test");
}

#[test]
fn closest_hit_matches_brute_force_on_closed_meshes() {
    let mut rng = Rng::new(2);
    let mut tris = icosphere(3, Vec3::new(0.2, -0.1, 0.3), 0.6);
    tris.extend(grid_box(Vec3::splat(-1.0), Vec3::splat(1.0), 6));
    let hits =
        check_against_brute_force(&tris, &mut rng, 4000, (Vec3::splat(-1.2), Vec3::splat(1.2)));
    assert!(hits > 2000, "too few hits ({hits})");
}

/// Rays from inside a closed mesh, aimed exactly at its vertices and at points of its edges
/// and along the axes through grid lines: none may escape.
/// Past 20,000 triangles the eight-wide tree is collapsed by several tasks, whose parts are
/// then joined (references moved, the top nodes' boxes widened to their deferred children):
/// against brute force on a mesh and a soup of that size, with exact copies (the same corners,
/// any starting corner) among them, which are left out of the tree; reversed copies are kept.
/// (The reversed copies stay out of the rays' test: a reversed triangle's t may differ from
/// its original's by a rounding, and which of two hits an ulp apart is kept depends on the
/// order they are tested in, in the tree as in brute force.)
#[test]
fn closest_hit_matches_brute_force_on_a_tree_collapsed_in_parallel() {
    let mut rng = Rng::new(5);
    let mut tris = icosphere(5, Vec3::new(0.1, 0.2, -0.1), 0.7);
    tris.extend(random_soup(
        &mut rng,
        9000,
        Vec3::splat(-1.0),
        Vec3::splat(1.0),
        0.08,
    ));
    let originals = tris.len();
    // Copies of distinct originals (7919 is prime to their number).
    let original = |k: usize| tris[k * 7919 % originals];
    let exact: Vec<[Vec3; 3]> = (0..1000)
        .map(|k| {
            let [a, b, c] = original(k);
            if k % 2 == 0 { [a, b, c] } else { [b, c, a] }
        })
        .collect();
    let reversed: Vec<[Vec3; 3]> = (1000..1500)
        .map(|k| {
            let [a, b, c] = original(k);
            [a, c, b]
        })
        .collect();
    tris.extend(exact);
    assert!(tris.len() > 30_000);
    assert_eq!(Accel::build(&columns(&tris)).len(), originals);
    let mut with_reversed = tris.clone();
    with_reversed.extend(reversed);
    assert_eq!(
        Accel::build(&columns(&with_reversed)).len(),
        originals + 500
    );
    let hits =
        check_against_brute_force(&tris, &mut rng, 1500, (Vec3::splat(-1.2), Vec3::splat(1.2)));
    assert!(hits > 500, "too few hits ({hits})");
}

fn assert_watertight(tris: &[[Vec3; 3]], inside: impl Fn(&mut Rng) -> Vec3, rays: usize) {
    let cols = columns(tris);
    let mut rng = Rng::new(3);
    {
        let accel = Accel::build(&cols);
        for r in 0..rays {
            let tri = tris[rng.index(tris.len())];
            let k = rng.index(3);
            let target = match r % 3 {
                0 => tri[k],
                1 => {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    a + (b - a) * 0.5
                }
                _ => {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    a + (b - a) * rng.f()
                }
            };
            let o = inside(&mut rng);
            let d = target - o;
            if d == Vec3::ZERO {
                continue;
            }
            let hit = accel.closest_hit(o, d, f32::INFINITY);
            assert!(hit.is_some(), "escaped through o={o} target={target}");
            let t = hit.unwrap().t;
            // The target is on the (convex) mesh, up to the rounding of d far from the origin.
            assert!(t > 0.9 && t < 1.1, "t={t}");
            assert!(accel.any_hit(o, d, f32::INFINITY));
            assert!(accel.closest_hit(o, d, 0.5 * t).is_none());
        }
    }
}

#[test]
fn rays_at_shared_edges_and_vertices_of_a_grid_box_never_miss() {
    for offset in [Vec3::ZERO, Vec3::new(1e5, -1e5, 1e5)] {
        let (lo, hi) = (
            Vec3::new(-1.5, -0.5, -2.0) + offset,
            Vec3::new(2.5, 1.5, 2.0) + offset,
        );
        let tris = grid_box(lo, hi, 8);
        assert_watertight(&tris, |rng| rng.vec_in(lo + 0.01, hi - 0.01), 20_000);

        // Axis-aligned rays through the grid lines hit vertices and edges exactly; zero
        // direction components exercise the infinite slab distances.
        let cols = columns(&tris);
        {
            let accel = Accel::build(&cols);
            let step = (hi - lo) / 8.0;
            for i in 1..8 {
                for j in 1..8 {
                    for axis in 0..3 {
                        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                        let mut o = (lo + hi) * 0.5;
                        o[u] = lo[u] + step[u] * i as f32;
                        o[v] = lo[v] + step[v] * j as f32;
                        for sign in [1.0, -1.0] {
                            let mut d = Vec3::ZERO;
                            d[axis] = sign;
                            let hit = accel.closest_hit(o, d, f32::INFINITY);
                            let expected = if sign > 0.0 { hi[axis] } else { lo[axis] } - o[axis];
                            assert_eq!(hit.map(|h| h.t), Some(expected.abs()), "o={o} d={d}");
                        }
                        // And diagonally within a face's plane of grid lines.
                        let mut d = Vec3::ZERO;
                        d[axis] = 1.0;
                        d[u] = 1.0;
                        assert!(
                            accel.closest_hit(o, d, f32::INFINITY).is_some(),
                            "o={o} d={d}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn rays_at_shared_edges_and_vertices_of_a_sphere_never_miss() {
    for (centre, radius) in [(Vec3::ZERO, 1.0), (Vec3::new(1e5, 2e5, -1e5), 3.0)] {
        let tris = icosphere(4, centre, radius);
        assert_watertight(
            &tris,
            |rng| centre + rng.dir() * radius * 0.9 * rng.f(),
            20_000,
        );
    }
}

#[test]
fn offset_rays_never_rehit_their_own_triangle() {
    let mut rng = Rng::new(4);
    for offset in [
        Vec3::ZERO,
        Vec3::new(1e5, 0.0, 0.0),
        Vec3::new(0.0, 1e5, 0.0),
        Vec3::new(0.0, 0.0, 1e5),
        Vec3::splat(-1e5),
    ] {
        // A closed sphere and a soup: leaving from a surface, towards either side.
        let mut tris = icosphere(3, offset, 1.0);
        tris.extend(random_soup(&mut rng, 200, offset - 2.0, offset + 2.0, 0.5));
        let cols = columns(&tris);
        {
            let accel = Accel::build(&cols);
            for _ in 0..20_000 {
                let id = rng.index(tris.len()) as u32;
                let (b1, b2) = (rng.f(), rng.f());
                let (b1, b2) = if b1 + b2 > 1.0 {
                    (1.0 - b1, 1.0 - b2)
                } else {
                    (b1, b2)
                };
                let sp = surface_point(&cols, id, b1, b2);
                let mut w = rng.dir();
                if rng.f() < 0.3 {
                    // Grazing: almost in the plane.
                    w = (w - w.dot(sp.ng) * sp.ng + 1e-4 * sp.ng * (rng.f() - 0.5)).normalize();
                }
                if w.dot(sp.ng) == 0.0 {
                    continue;
                }
                let o = offset_ray_origin(sp.p, sp.p_error, sp.ng, w);
                if let Some(hit) = accel.closest_hit(o, w, f32::INFINITY) {
                    assert_ne!(hit.triangle, id, "re-hit own triangle, t={}", hit.t);
                }
            }
        }
    }
}

#[test]
fn shadow_rays_between_surfaces() {
    // Two facing quads, and a blocker between them that can be switched on.
    let quad = |y: f32, up: bool| -> Vec<[Vec3; 3]> {
        let (a, b, c, d) = (
            Vec3::new(-1.0, y, -1.0),
            Vec3::new(1.0, y, -1.0),
            Vec3::new(1.0, y, 1.0),
            Vec3::new(-1.0, y, 1.0),
        );
        if up {
            vec![[a, d, c], [a, c, b]]
        } else {
            vec![[a, b, c], [a, c, d]]
        }
    };
    let mut rng = Rng::new(5);
    for offset in [Vec3::ZERO, Vec3::splat(1e5)] {
        let mut tris: Vec<[Vec3; 3]> = quad(0.0, true);
        tris.extend(quad(1.0, false));
        let tris: Vec<[Vec3; 3]> = tris.iter().map(|t| t.map(|p| p + offset)).collect();
        let mut blocked = tris.clone();
        blocked.extend(
            quad(0.5, true)
                .iter()
                .map(|t| t.map(|p| p * Vec3::new(10.0, 1.0, 10.0) + offset)),
        );
        let (cols, cols_blocked) = (columns(&tris), columns(&blocked));
        {
            let open = Accel::build(&cols);
            let closed = Accel::build(&cols_blocked);
            for _ in 0..5_000 {
                let (i, j) = (rng.index(2) as u32, 2 + rng.index(2) as u32);
                let a = surface_point(&cols, i, rng.f() * 0.5, rng.f() * 0.5);
                let b = surface_point(&cols, j, rng.f() * 0.5, rng.f() * 0.5);
                let (o, d, t_max) = spawn_ray_to(a.p, a.p_error, a.ng, b.p, b.p_error, b.ng);
                assert!(!open.any_hit(o, d, t_max), "self-occluded shadow ray");
                assert!(open.closest_hit(o, d, t_max).is_none());
                assert!(closed.any_hit(o, d, t_max), "blocker missed");
            }
        }
    }
}

#[test]
fn surface_point_error_bound_contains_the_exact_point() {
    let mut rng = Rng::new(6);
    for offset in [
        Vec3::ZERO,
        Vec3::new(1e5, -1e5, 1e5),
        Vec3::new(1e5, 1.0, -3e3),
    ] {
        let tris = random_soup(&mut rng, 1000, offset - 10.0, offset + 10.0, 5.0);
        let cols = columns(&tris);
        for _ in 0..20_000 {
            let id = rng.index(tris.len());
            let (b1, b2) = (rng.f(), rng.f());
            let (b1, b2) = if b1 + b2 > 1.0 {
                (1.0 - b1, 1.0 - b2)
            } else {
                (b1, b2)
            };
            let sp = surface_point(&cols, id as u32, b1, b2);
            let [p0, p1, p2] = tris[id].map(|p| p.as_dvec3());
            let (b1d, b2d) = (f64::from(b1), f64::from(b2));
            let exact: DVec3 = (1.0 - b1d - b2d) * p0 + b1d * p1 + b2d * p2;
            let err = (sp.p.as_dvec3() - exact).abs();
            assert!(
                err.cmple(sp.p_error.as_dvec3()).all(),
                "error {err} beyond bound {} at {exact}",
                sp.p_error
            );
            assert!((sp.ng.length() - 1.0).abs() < 1e-5);
            assert_eq!(sp.ns, sp.ng);
        }
    }
}

#[test]
fn surface_point_interpolates_smooth_normals() {
    let mut cols = columns(&[[Vec3::ZERO, Vec3::X, Vec3::Y]]);
    cols.smooth[0] = 0;
    cols.vertex_normals = vec![[Vec3::Z, Vec3::X, Vec3::Y]];
    let sp = surface_point(&cols, 0, 0.25, 0.25);
    assert_eq!(sp.ng, Vec3::Z);
    let expected = Vec3::new(0.25, 0.25, 0.5).normalize();
    assert!((sp.ns - expected).length() < 1e-6);
    assert!((sp.p - Vec3::new(0.25, 0.25, 0.0)).length() < 1e-7);
}

#[test]
fn t_max_is_respected() {
    let mut rng = Rng::new(7);
    let tris = icosphere(2, Vec3::ZERO, 1.0);
    let cols = columns(&tris);
    {
        let accel = Accel::build(&cols);
        for _ in 0..5_000 {
            let o = rng.vec_in(Vec3::splat(-0.5), Vec3::splat(0.5));
            let d = rng.dir() * rng.range(0.1, 10.0);
            let hit = accel
                .closest_hit(o, d, f32::INFINITY)
                .expect("inside a closed sphere");
            // Exactly at t_max: excluded; just past it: included.
            assert!(accel.closest_hit(o, d, hit.t).is_none());
            assert!(!accel.any_hit(o, d, hit.t));
            let beyond = hit.t * (1.0 + 1e-6);
            assert_eq!(accel.closest_hit(o, d, beyond), Some(hit));
            assert!(accel.any_hit(o, d, beyond));
            assert!(accel.closest_hit(o, d, 0.0).is_none());
            assert!(!accel.any_hit(o, d, -1.0));
            // Scaling the direction scales t.
            let scaled = accel.closest_hit(o, d * 4.0, f32::INFINITY).unwrap();
            assert!((scaled.t * 4.0 - hit.t).abs() <= 1e-5 * hit.t);
        }
    }
}

#[test]
fn degenerate_triangles_are_never_hit() {
    let mut rng = Rng::new(8);
    let p = Vec3::new(0.3, 0.2, 0.1);
    let mut tris = vec![
        [p, p, p],
        [Vec3::ZERO, Vec3::ONE, Vec3::splat(2.0)],
        [Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
        [Vec3::ZERO, Vec3::ZERO, Vec3::Y],
        [Vec3::Y, Vec3::Z, Vec3::Z],
        [
            Vec3::new(-1.0, 0.5, 0.5),
            Vec3::new(1.0, 0.5, 0.5),
            Vec3::new(0.0, 0.5, 0.5),
        ],
    ];
    let degenerate = tris.len() as u32;
    tris.extend(random_soup(
        &mut rng,
        50,
        Vec3::splat(-1.0),
        Vec3::splat(1.0),
        0.3,
    ));
    let cols = columns(&tris);
    let only_degenerate = columns(&tris[..degenerate as usize]);
    {
        let accel = Accel::build(&cols);
        let empty = Accel::build(&only_degenerate);
        assert!(empty.is_empty());
        assert_eq!(accel.len(), tris.len() - degenerate as usize);
        for _ in 0..20_000 {
            let o = rng.vec_in(Vec3::splat(-1.5), Vec3::splat(1.5));
            // Aim at a point of a degenerate triangle half of the time.
            let d = if rng.f() < 0.5 {
                let t = tris[rng.index(degenerate as usize)];
                t[0] + (t[2] - t[0]) * rng.f() - o
            } else {
                rng.dir()
            };
            if let Some(hit) = accel.closest_hit(o, d, f32::INFINITY) {
                assert!(hit.triangle >= degenerate, "hit degenerate {hit:?}");
                assert!(hit.t.is_finite() && hit.b1.is_finite() && hit.b2.is_finite());
            }
            assert!(empty.closest_hit(o, d, f32::INFINITY).is_none());
            assert!(!empty.any_hit(o, d, f32::INFINITY));
        }
    }
    // Nothing at all, and invalid rays.
    let accel = Accel::build(&TriangleColumns::default());
    assert!(
        accel
            .closest_hit(Vec3::ZERO, Vec3::X, f32::INFINITY)
            .is_none()
    );
    let accel = Accel::build(&cols);
    assert!(
        accel
            .closest_hit(Vec3::ZERO, Vec3::ZERO, f32::INFINITY)
            .is_none()
    );
    assert!(
        accel
            .closest_hit(Vec3::NAN, Vec3::X, f32::INFINITY)
            .is_none()
    );
    assert!(accel.closest_hit(Vec3::ZERO, Vec3::X, f32::NAN).is_none());
}

#[test]
fn accel_is_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<Accel>();
}
