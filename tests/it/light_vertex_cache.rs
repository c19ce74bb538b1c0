//! BDPT through a light-vertex cache (`--light-vertex-cache M`): unbiased like BDPT. Each
//! connection strategy alone (unweighted, so MIS hides no scale error) agrees with plain
//! BDPT's; the MIS-weighted image agrees with PT on the Cornell box and gives 2 in the
//! furnace; the option is refused elsewhere. (That the image does not depend on the thread
//! count is checked for plain and cached BDPT in bdpt.rs.)

use crate::common::{load_small, mean_over_seeds, render_bdpt, render_pt, stagelight, stderr};
use stagelight::film::Image;
use stagelight::integrators::bdpt::{BdptSettings, StrategyFilter};

fn cached(seed: u64, max_depth: u32, m: u32) -> BdptSettings {
    BdptSettings {
        light_vertex_cache: m,
        ..BdptSettings::new(seed, max_depth)
    }
}

type MeanSe = ([f64; 3], [f64; 3]);

/// |a - b| within `z` combined standard errors, per channel, with errors small enough for
/// the check to mean something.
fn assert_agree(name: &str, a: MeanSe, b: MeanSe, z: f64) {
    for c in 0..3 {
        let (ma, sa) = (a.0[c], a.1[c]);
        let (mb, sb) = (b.0[c], b.1[c]);
        let se = (sa * sa + sb * sb).sqrt();
        assert!(
            se < 0.25 * mb.abs().max(1e-3),
            "{name} channel {c}: standard error {se} too large for a meaningful check ({ma} vs {mb})"
        );
        assert!(
            (ma - mb).abs() <= z * se,
            "{name} channel {c}: {ma} vs {mb}, {:.2} standard errors apart",
            (ma - mb).abs() / se
        );
    }
}

/// The top or bottom half of an image.
fn half(image: &Image, top: bool) -> Image {
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

/// Mean and standard error over seeds of each half of the images `render` makes.
fn halves(render: impl Fn(u64) -> Image, seeds: u64) -> [MeanSe; 2] {
    let images: Vec<Image> = (0..seeds).map(render).collect();
    [true, false].map(|top| mean_over_seeds(|seed| half(&images[seed as usize], top), seeds))
}

#[test]
fn each_connection_strategy_alone_matches_bdpt() {
    // Unweighted, a strategy through the cache is V / (N M) times its picks' contributions:
    // without that factor it would be 1 / (mean cached vertices per light subpath) of BDPT's.
    let scene = load_small("cornell_box.ron", 16);
    for (s, t) in [(2u16, 2u16), (3, 2), (2, 3)] {
        let only = StrategyFilter::Only {
            s: Some(s),
            t: Some(t),
        };
        let plain = halves(
            |seed| {
                let st = BdptSettings {
                    strategies: only,
                    ..BdptSettings::new(100 + seed, u32::MAX)
                };
                render_bdpt(scene.clone(), 32, st).0.film.image()
            },
            8,
        );
        for m in [1, 3] {
            let through_cache = halves(
                |seed| {
                    let st = BdptSettings {
                        strategies: only,
                        ..cached(200 + seed, u32::MAX, m)
                    };
                    // A pick lands on the strategy's s about 1 / 3 of the time.
                    render_bdpt(scene.clone(), 64, st).0.film.image()
                },
                8,
            );
            for (i, name) in ["upper", "lower"].into_iter().enumerate() {
                assert_agree(
                    &format!("strategy ({s},{t}) through a cache of M = {m}, {name} half"),
                    through_cache[i],
                    plain[i],
                    4.5,
                );
            }
        }
    }
}

#[test]
fn cached_bdpt_agrees_with_pt_on_the_cornell_box() {
    let scene = load_small("cornell_box.ron", 24);
    let pt = halves(
        |seed| {
            render_pt(scene.clone(), 16, 100 + seed, u32::MAX)
                .film
                .image()
        },
        8,
    );
    for m in [1, 4] {
        let lvc = halves(
            |seed| {
                render_bdpt(scene.clone(), 4, cached(seed, u32::MAX, m))
                    .0
                    .film
                    .image()
            },
            8,
        );
        for (i, name) in ["upper", "lower"].into_iter().enumerate() {
            assert_agree(
                &format!("cornell lvc M = {m} vs pt, {name} half"),
                lvc[i],
                pt[i],
                4.5,
            );
        }
    }
}

#[test]
fn cached_bdpt_gives_two_in_the_furnace() {
    let scene = load_small("furnace.ron", 16);
    // Unlimited, then depth caps that count the same paths as PT's: 1.5 and 1.875 for 1
    // and 3 bounces.
    for (depth, expected) in [(u32::MAX, 2.0), (1, 1.5), (3, 1.875)] {
        let (mean, se) = mean_over_seeds(
            |seed| {
                render_bdpt(scene.clone(), 4, cached(seed, depth, 2))
                    .0
                    .film
                    .image()
            },
            8,
        );
        for c in 0..3 {
            assert!(
                (mean[c] - expected).abs() <= 5.0 * se[c].max(1e-4),
                "max depth {depth}: {mean:?} +- {se:?} against {expected}"
            );
        }
    }
}

#[test]
fn the_option_is_refused_outside_bdpt() {
    let out = stagelight(&[
        "render",
        "scenes/cornell_box.ron",
        "--integrator",
        "pt",
        "--light-vertex-cache",
        "2",
        "--spp",
        "1",
        "--quiet",
        "-o",
        "/tmp/stagelight_lvc_refused.exr",
    ]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("--light-vertex-cache needs --integrator bdpt"),
        "{}",
        stderr(&out)
    );
    let out = stagelight(&[
        "render",
        "scenes/cornell_box.ron",
        "--integrator",
        "bdpt",
        "--light-vertex-cache",
        "0",
    ]);
    assert!(!out.status.success(), "M = 0 is refused");
}
