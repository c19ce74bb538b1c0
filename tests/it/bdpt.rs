//! Bidirectional path tracing: agreement with the path tracer and the furnace, MIS weights
//! that sum to one, each strategy alone converging to the same light, light tracing alone
//! matching PT, and determinism across thread counts.

use crate::common::{load_small, mean_over_seeds, render_bdpt, render_pt};
use stagelight::film::Image;
use stagelight::integrators::SceneData;
use stagelight::integrators::bdpt::{self, BdptSettings, StrategyFilter};
use stagelight::path::{MisHeuristic, PathContext, Vertex, VertexKind};
use std::sync::Arc;

fn settings(seed: u64, max_depth: u32) -> BdptSettings {
    BdptSettings::new(seed, max_depth)
}

/// |a - b| within `z` combined standard errors, per channel, and the errors small enough
/// for the check to mean something.
pub(crate) fn assert_agree(name: &str, a: ([f64; 3], [f64; 3]), b: ([f64; 3], [f64; 3]), z: f64) {
    for c in 0..3 {
        let (ma, sa) = (a.0[c], a.1[c]);
        let (mb, sb) = (b.0[c], b.1[c]);
        let se = (sa * sa + sb * sb).sqrt();
        assert!(
            se < 0.15 * mb.abs().max(1e-3),
            "{name} channel {c}: standard error {se} too large for a meaningful check ({ma} vs {mb})"
        );
        assert!(
            (ma - mb).abs() <= z * se,
            "{name} channel {c}: {ma} vs {mb}, {:.2} standard errors apart",
            (ma - mb).abs() / se
        );
    }
}

#[test]
fn the_furnace_gives_two() {
    let scene = load_small("furnace.ron", 16);
    let (mean, se) = mean_over_seeds(
        |seed| {
            render_bdpt(scene.clone(), 4, settings(seed, u32::MAX))
                .0
                .film
                .image()
        },
        8,
    );
    for c in 0..3 {
        assert!(
            (mean[c] - 2.0).abs() <= 5.0 * se[c].max(1e-4),
            "{mean:?} +- {se:?}"
        );
    }
    // Depth caps count the same paths as PT's: 1, 1.5, 1.875 for 0, 1 and 3 bounces.
    for (depth, expected) in [(0, 1.0), (1, 1.5), (3, 1.875)] {
        let (m, s) = mean_over_seeds(
            |seed| {
                render_bdpt(scene.clone(), 2, settings(seed, depth))
                    .0
                    .film
                    .image()
            },
            6,
        );
        assert!(
            (m[0] - expected).abs() <= 5.0 * s[0].max(1e-4),
            "max depth {depth}: {} +- {} against {expected}",
            m[0],
            s[0]
        );
    }
}

#[test]
fn bdpt_agrees_with_pt_on_the_cornell_box() {
    let scene = load_small("cornell_box.ron", 24);
    let pt = mean_over_seeds(
        |seed| {
            render_pt(scene.clone(), 16, 100 + seed, u32::MAX)
                .film
                .image()
        },
        8,
    );
    let bd = mean_over_seeds(
        |seed| {
            render_bdpt(scene.clone(), 4, settings(seed, u32::MAX))
                .0
                .film
                .image()
        },
        8,
    );
    assert_agree("cornell bdpt vs pt", bd, pt, 4.5);
    let balance = mean_over_seeds(
        |seed| {
            let s = BdptSettings {
                mis: MisHeuristic::Balance,
                ..settings(50 + seed, u32::MAX)
            };
            render_bdpt(scene.clone(), 4, s).0.film.image()
        },
        8,
    );
    assert_agree("cornell bdpt (balance) vs pt", balance, pt, 4.5);
}

/// Turns a camera subpath that ends on an emitter into the camera and light subpaths of the
/// split (s, t), with the densities each walk would have stored.
pub(crate) fn split(ctx: &PathContext, full: &[Vertex], t: usize) -> (Vec<Vertex>, Vec<Vertex>) {
    let camera = full[..t].to_vec();
    let mut light: Vec<Vertex> = full[t..].iter().rev().copied().collect();
    let s = light.len();
    for j in 0..s {
        let mut v = light[j];
        v.delta = v.kind == VertexKind::Surface && !ctx.is_connectible(&v);
        if j == 0 {
            v.kind = VertexKind::Light;
            v.ns = v.ng;
            v.pdf_fwd = ctx.pdf_light_origin(&v);
        } else if j == 1 {
            v.pdf_fwd = ctx.pdf_light_dir(&light[0], &v);
        } else {
            v.pdf_fwd = ctx.pdf_area(&light[j - 1], Some(&light[j - 2]), &v);
        }
        v.pdf_rev = if j + 2 < s {
            ctx.pdf_area(&light[j + 1], Some(&light[j + 2]), &v)
        } else {
            0.0
        };
        light[j] = v;
    }
    (camera, light)
}

fn check_weights_sum_to_one(scene_name: &str) {
    let scene = load_small(scene_name, 32);
    let data = Arc::new(SceneData::new(scene));
    let ctx = PathContext::new(&data.scene);
    // Small lights are rarely hit by camera subpaths: more samples there.
    let samples = if scene_name == "cornell_box.ron" || scene_name == "furnace.ron" {
        1 << 15
    } else {
        1 << 17
    };
    let subpaths = bdpt::trace_subpaths(data.clone(), settings(3, u32::MAX), 0, samples);
    let mut checked = 0;
    let mut through_glass = 0;
    let mut grazing = 0;
    for (camera, _) in &subpaths {
        // Every prefix that ends on the front of an emitter is a full path.
        for k in 1..camera.len() {
            let z = &camera[k];
            let wo = (camera[k - 1].p - z.p).normalize();
            if ctx.emitted(z, wo) == glam::Vec3::ZERO {
                continue;
            }
            let full = &camera[..=k];
            // With a light-vertex cache the connection strategies are counted differently:
            // the weights must still sum to one.
            let sum = |heuristic, connection_count| {
                let mut sum = 0.0f64;
                for t in 1..=full.len() {
                    let s = full.len() - t;
                    let (cam, light) = split(&ctx, full, t);
                    let joint_ok = (s == 0 || ctx.is_connectible(&light[s - 1]))
                        && (t == 1 || s == 0 || ctx.is_connectible(&cam[t - 1]));
                    if joint_ok {
                        sum +=
                            ctx.mis_weight_counted(&cam, &light, s, t, heuristic, connection_count)
                                as f64;
                    }
                }
                sum
            };
            // The walk's densities come from the sampled directions, the recomputed ones from
            // the rounded hit positions. Where a segment is short or grazing, rounding moves its
            // cosines by more than the tolerance (relative error ~ position error / (length x
            // cosine)), so such paths are counted but not checked.
            let ill_conditioned = full.windows(2).skip(1).any(|w| {
                let d = w[1].p - w[0].p;
                let dir = d.normalize();
                let cos = w[0].ng.dot(dir).abs().min(w[1].ng.dot(dir).abs());
                (w[0].p_error + w[1].p_error).length() > 1e-4 * d.length() * cos
            });
            if ill_conditioned {
                grazing += 1;
                continue;
            }
            for heuristic in [MisHeuristic::Power, MisHeuristic::Balance] {
                for count in [1.0, 0.26, 3.0] {
                    let sum = sum(heuristic, count);
                    assert!(
                        (sum - 1.0).abs() < 1e-3,
                        "{scene_name}, {heuristic:?}, connections counted {count}: weights of a \
                         {}-vertex path sum to {sum}",
                        full.len()
                    );
                }
            }
            checked += 1;
            if full
                .iter()
                .any(|v| v.kind == VertexKind::Surface && !ctx.is_connectible(v))
            {
                through_glass += 1;
            }
        }
    }
    assert!(
        grazing * 4 < checked,
        "{scene_name}: {grazing} grazing paths of {checked}"
    );
    assert!(
        checked > 30,
        "{scene_name}: only {checked} paths reached a light"
    );
    if scene_name == "torus_glass.ron" {
        assert!(
            through_glass > 5,
            "only {through_glass} paths through glass"
        );
    }
}

#[test]
fn mis_weights_sum_to_one_in_every_scene() {
    for scene in [
        "cornell_box.ron",
        "torus_glass.ron",
        "door_ajar.ron",
        "furnace.ron",
    ] {
        check_weights_sum_to_one(scene);
    }
}

/// The top or bottom half of an image (region-wise checks: not only the mean must agree).
pub(crate) fn half(image: Image, top: bool) -> Image {
    let h = image.height / 2;
    let rows = if top { 0..h } else { h..image.height };
    Image {
        width: image.width,
        height: h,
        pixels: rows
            .flat_map(|y| image.pixels[y * image.width..(y + 1) * image.width].to_vec())
            .collect(),
    }
}

pub(crate) type MeanSe = ([f64; 3], [f64; 3]);

/// `mean_over_seeds` of the upper and the lower half, from one render per seed.
pub(crate) fn halves_over_seeds(render: impl Fn(u64) -> Image, seeds: u64) -> [MeanSe; 2] {
    let images: Vec<Image> = (0..seeds).map(&render).collect();
    [true, false].map(|top| mean_over_seeds(|seed| half(images[seed as usize].clone(), top), seeds))
}

#[test]
fn each_strategy_alone_converges_to_the_same_light() {
    // Paths of exactly `depth` bounces, made by each strategy alone, unweighted; PT's share
    // of the same paths is the difference of two depth caps.
    let scene = load_small("cornell_box.ron", 16);
    for depth in 0..=2u32 {
        let pt_at = |cap: u32, seed: u64| render_pt(scene.clone(), 64, seed, cap).film.image();
        let pt_share_of = |seed: u64| {
            let hi = pt_at(depth, 10 + seed);
            if depth == 0 {
                return hi;
            }
            let lo = pt_at(depth - 1, 10 + seed);
            let mut d = hi.clone();
            for (p, q) in d.pixels.iter_mut().zip(&lo.pixels) {
                *p -= *q;
            }
            d
        };
        // The upper half (ceiling, light, walls) and the lower half (floor, boxes) apart.
        let pt_halves =
            [true, false].map(|top| mean_over_seeds(|seed| half(pt_share_of(seed), top), 8));
        let k = depth as usize + 2; // vertices
        for t in 1..=k {
            let s = k - t;
            let only = BdptSettings {
                strategies: StrategyFilter::Only {
                    s: Some(s as u16),
                    t: Some(t as u16),
                },
                ..settings(0, u32::MAX)
            };
            let spp = if t == 1 || s == 0 { 64 } else { 16 };
            let alone = |seed: u64| {
                let st = BdptSettings {
                    seed: 200 + seed,
                    ..only
                };
                render_bdpt(scene.clone(), spp, st).0.film.image()
            };
            let alone_halves = halves_over_seeds(alone, 8);
            for (i, top) in [true, false].into_iter().enumerate() {
                assert_agree(
                    &format!(
                        "strategy ({s},{t}) alone vs PT depth {depth}, {} half",
                        if top { "upper" } else { "lower" }
                    ),
                    alone_halves[i],
                    pt_halves[i],
                    4.5,
                );
            }
        }
    }
}

#[test]
fn light_tracing_alone_matches_pt() {
    let scene = load_small("cornell_box.ron", 16);
    let lt = BdptSettings {
        strategies: StrategyFilter::Only {
            s: None,
            t: Some(1),
        },
        ..settings(0, u32::MAX)
    };
    let light_traced = mean_over_seeds(
        |seed| {
            render_bdpt(scene.clone(), 32, BdptSettings { seed, ..lt })
                .0
                .film
                .image()
        },
        8,
    );
    let pt = mean_over_seeds(
        |seed| {
            render_pt(scene.clone(), 32, 300 + seed, u32::MAX)
                .film
                .image()
        },
        8,
    );
    assert_agree("light tracing vs pt", light_traced, pt, 4.5);
}

#[test]
fn strategy_images_add_up_to_the_image() {
    let scene = load_small("cornell_box.ron", 16);
    let s = BdptSettings {
        strategy_images: true,
        ..settings(1, 4)
    };
    let (outcome, layers) = render_bdpt(scene, 4, s);
    let image = outcome.film.image();
    assert!(layers.iter().any(|(n, _)| n == "s0_t2") && layers.iter().any(|(n, _)| n == "s1_t1"));
    for (i, p) in image.pixels.iter().enumerate() {
        let sum: glam::Vec3 = layers.iter().map(|(_, l)| l.pixels[i]).sum();
        assert!(
            (sum - *p).abs().max_element() <= 1e-4 * (1.0 + p.max_element()),
            "pixel {i}: {sum} vs {p}"
        );
    }
}

/// Plain BDPT, and BDPT through a light-vertex cache (whose caches are built per group of
/// samples in parallel).
#[test]
fn same_image_for_any_thread_count() {
    let scene = load_small("torus_glass.ron", 24);
    for light_vertex_cache in [0, 2] {
        let s = BdptSettings {
            light_vertex_cache,
            ..settings(5, u32::MAX)
        };
        let render = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| render_bdpt(scene.clone(), 2, s).0.film.image())
        };
        let one = render(1);
        assert_eq!(one, render(2), "light_vertex_cache {light_vertex_cache}");
        assert_eq!(one, render(3), "light_vertex_cache {light_vertex_cache}");
    }
}

/// The connection layout counts strategies from `light_vertices`: it must hold exactly the s
/// that `uses` keeps (before the filter), for every depth bound and subpath length.
#[test]
fn light_vertices_are_the_strategies_within_the_depth_bounds() {
    for max_depth in [0, 1, 2, 3, 5, 9, u32::MAX] {
        for min_depth in [0, 1, 2, 4] {
            let s = BdptSettings {
                min_depth,
                ..settings(0, max_depth)
            };
            for t in 0..14 {
                for nl in 0..14 {
                    let expected: Vec<usize> = (0..=nl).filter(|&l| s.uses(l, t)).collect();
                    let got: Vec<usize> = s.light_vertices(t, nl).collect();
                    assert_eq!(
                        got, expected,
                        "max {max_depth} min {min_depth} t {t} nl {nl}"
                    );
                }
            }
        }
    }
}
