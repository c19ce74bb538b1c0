//! Metropolis light transport (pssmlt, mmlt): normalisation (image mean luminance = b, the
//! bootstrap's b = its image's mean, b refined by the large steps), the furnace, block means
//! against BDPT on the three scenes (direct illumination apart, and in the chains), no depth
//! cap (a closed mirror box against PT), thread-count independence, seeds replayed exactly,
//! the direct image, and no zero or invalid proposal ever accepted.

use crate::common::{
    assert_blocks_agree, block_luminance_stats, block_means, load_small, load_test_scene,
    render_bdpt, render_pt,
};
use stagelight::film::Image;
use stagelight::integrators::bdpt::BdptSettings;
use stagelight::integrators::driver::run_passes;
use stagelight::integrators::mlt::{DirectIllumination, MltSettings, MltState};
use stagelight::integrators::{RenderSettings, SceneData};
use stagelight::math::luminance;
use std::sync::Arc;

fn settings(multiplexed: bool, seed: u64, max_depth: u32, mutations: u64) -> MltSettings {
    let mut s = MltSettings::from_render(
        &RenderSettings {
            seed,
            max_depth,
            ..RenderSettings::default()
        },
        multiplexed,
    );
    s.mutations_per_pixel = Some(mutations);
    s
}

/// `settings` with every depth left to the chains (`--direct-spp 0`): the normalisation's
/// invariants are the chains'.
fn in_chains(s: MltSettings) -> MltSettings {
    let max_depth = s.max_depth;
    s.with_direct(max_depth, Some(0))
}

/// Runs `mutations` mutations per pixel (whole passes) and returns the state.
fn run(scene: &str, size: u32, s: MltSettings) -> MltState {
    let data = Arc::new(SceneData::new(load_small(scene, size)));
    let pixels = (size * size) as u64;
    let passes = s.passes_for(pixels, s.mutations_per_pixel.unwrap());
    run_passes::<MltState>(data, s, passes)
}

fn image(state: &MltState) -> Image {
    state.image_film().image()
}

fn mean_luminance(pixels: impl Iterator<Item = glam::DVec3>) -> f64 {
    let (mut sum, mut n) = (0.0, 0.0);
    for p in pixels {
        sum += 0.2126 * p.x + 0.7152 * p.y + 0.0722 * p.z;
        n += 1.0;
    }
    sum / n
}

const BOTH: [(bool, &str); 2] = [(false, "pssmlt"), (true, "mmlt")];

#[test]
fn mlt_image_mean_luminance_is_b_and_b_is_the_bootstrap_image_mean() {
    for (multiplexed, name) in BOTH {
        let mut s = in_chains(settings(multiplexed, 3, 6, 8));
        s.bootstrap_image = true;
        let state = run("cornell_box.ron", 16, s);
        let b = state.normalisation();
        assert!(b > 0.0, "{name}");
        let img = image(&state);
        let mean = mean_luminance(img.pixels.iter().map(|p| p.as_dvec3()));
        assert!(
            (mean / b - 1.0).abs() < 1e-4,
            "{name}: image mean {mean}, b {b}"
        );
        let boot = mean_luminance(state.bootstrap_image().into_iter());
        let b_boot = state.bootstrap_normalisation();
        assert!(
            (boot / b_boot - 1.0).abs() < 1e-6,
            "{name}: bootstrap image {boot}, its b {b_boot}"
        );
        // b is the mean target over the bootstrap and every large step since; every
        // bootstrap evaluation has a weight in every group (mmlt's are full BDPT samples).
        let n = &state.normalisation;
        assert_eq!(n.large_steps, state.counters.large_proposed, "{name}");
        let evaluated: u64 = n.counts.iter().sum();
        assert_eq!(
            evaluated,
            state.bootstrap.evaluated * n.counts.len() as u64 + n.large_steps,
            "{name}"
        );
        assert!(
            state.counters.steps >= 8 * 256,
            "{name}: {:?}",
            state.counters
        );
    }
}

#[test]
fn mlt_seeds_replay_their_bootstrap_weight_and_invalid_proposals_are_never_accepted() {
    for (multiplexed, name) in BOTH {
        let state = run("torus_glass.ron", 16, settings(multiplexed, 5, 8, 8));
        let sel = state.selection.as_ref().expect("seeds");
        // Every chain's current state has a positive, finite target: proposals with a zero
        // or invalid target are never accepted.
        let targets = &state.chains.current_contributions.target;
        assert!(targets.iter().all(|t| t.is_finite() && *t > 0.0), "{name}");
        let c = state.counters;
        assert_eq!(c.rejected_invalid, 0, "{name}: {c:?}");
        assert!(c.rejected_zero > 0 && c.accepted > 0, "{name}: {c:?}");
        assert!(c.accepted <= c.steps - c.rejected_zero, "{name}: {c:?}");
        assert_eq!(c.large_proposed + c.small_proposed, c.steps);
        assert_eq!(sel.group.len(), state.chains.chains());
        // Every seed had a positive bootstrap weight, and its replay gave that weight again.
        for (&g, &j) in sel.group.iter().zip(&sel.candidate) {
            assert!(
                state.bootstrap.weights[g as usize][j as usize] > 0.0,
                "{name}"
            );
        }
        assert_eq!(state.bootstrap.replay_mismatches, 0, "{name}");
    }
}

#[test]
fn mlt_furnace_is_two_and_depth_caps_give_the_partial_sums() {
    for (multiplexed, name) in BOTH {
        for (depth, expected) in [(u32::MAX, 2.0), (0, 1.0), (1, 1.5), (3, 1.875)] {
            let s = settings(multiplexed, 1, depth, 512);
            // Depths 0 and 1 (1 + 0.5) are path traced apart where the chains have deeper
            // paths: b is then the rest.
            let apart = s.direct != DirectIllumination::InChains;
            assert_eq!(apart, depth >= 2, "{name} depth {depth}");
            let chains_part = if apart { expected - 1.5 } else { expected };
            let state = run("furnace.ron", 8, s);
            let img = image(&state);
            let b = state.normalisation();
            assert!(
                (b / chains_part - 1.0).abs() < 0.03,
                "{name} depth {depth}: b {b} against {chains_part}"
            );
            // Every pixel the same light, within the noise of 512 correlated mutations.
            let worst = img
                .pixels
                .iter()
                .map(|p| (luminance(*p) as f64 / expected - 1.0).abs())
                .fold(0.0, f64::max);
            assert!(
                worst < 0.5,
                "{name} depth {depth}: a pixel {worst} off {expected}"
            );
            // 4x4 blocks (16 pixels, 8192 mutations each) within 10%.
            for m in block_means(&img, 4) {
                let l = 0.2126 * m[0] + 0.7152 * m[1] + 0.0722 * m[2];
                assert!(
                    (l / expected - 1.0).abs() < 0.1,
                    "{name} depth {depth}: a block {l} against {expected}"
                );
            }
            if multiplexed && depth == 3 {
                let sel = state.selection.as_ref().unwrap();
                for (k, &bk) in sel.normalisation.iter().enumerate() {
                    if k < 2 {
                        assert_eq!(bk, 0.0, "b_{k}: depth {k} is path traced apart");
                        continue;
                    }
                    let want = 0.5f64.powi(k as i32);
                    assert!((bk / want - 1.0).abs() < 0.05, "b_{k} = {bk}, want {want}");
                }
            }
        }
    }
}

#[test]
fn mlt_block_means_agree_with_bdpt() {
    const SIZE: u32 = 32;
    const DEPTH: u32 = 8;
    const SEEDS: u64 = 4;
    for scene in ["cornell_box.ron", "door_ajar.ron", "torus_glass.ron"] {
        let reference: Vec<Image> = (0..SEEDS)
            .map(|seed| {
                render_bdpt(
                    load_small(scene, SIZE),
                    48,
                    BdptSettings::new(1000 + seed, DEPTH),
                )
                .0
                .film
                .image()
            })
            .collect();
        let reference = block_luminance_stats(&reference);
        for (multiplexed, name) in BOTH {
            let images: Vec<Image> = (0..SEEDS)
                .map(|seed| image(&run(scene, SIZE, settings(multiplexed, seed, DEPTH, 32))))
                .collect();
            assert_blocks_agree(&format!("{scene} {name}"), &images, &reference, 0.35, 5.0);
            // Every depth in the chains (`--direct-spp 0`) where glass makes depth 1 matter.
            if scene == "torus_glass.ron" {
                let images: Vec<Image> = (0..SEEDS)
                    .map(|seed| {
                        let s = in_chains(settings(multiplexed, seed, DEPTH, 32));
                        image(&run(scene, SIZE, s))
                    })
                    .collect();
                let what = format!("{scene} {name} --direct-spp 0");
                assert_blocks_agree(&what, &images, &reference, 0.35, 5.0);
            }
        }
    }
}

#[test]
fn mlt_same_image_for_any_thread_count() {
    for (multiplexed, name) in BOTH {
        let images: Vec<Vec<glam::Vec3>> = [1, 2, 3]
            .into_iter()
            .map(|threads| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| {
                    image(&run("door_ajar.ron", 16, settings(multiplexed, 7, 6, 4))).pixels
                })
            })
            .collect();
        assert!(images[0] == images[1] && images[1] == images[2], "{name}");
    }
}

/// The bootstrap may evaluate in waves wider than the chains (path-space MLT's seeding does):
/// with its size fixed, the wave width changes neither the seeds nor the image.
#[test]
fn mlt_bootstrap_wave_width_changes_nothing() {
    for (multiplexed, name) in BOTH {
        let render = |wave: usize| {
            let mut s = settings(multiplexed, 11, 6, 4);
            s.bootstrap = Some(3000);
            s.bootstrap_wave = wave;
            let state = run("door_ajar.ron", 16, s);
            (image(&state).pixels, state.normalisation())
        };
        let narrow = render(0);
        let wide = render(8192);
        assert!(narrow.1 > 0.0, "{name}: no light found");
        assert_eq!(narrow.1, wide.1, "{name}: b");
        assert!(narrow.0 == wide.0, "{name}: images differ");
    }
}

/// pssmlt's and mmlt's direct image grows by a sample per pixel as the chains take a mutation
/// per pixel, each time going on from its film: after the render it is, bit for bit, one path
/// tracing render of that many samples (its numbers are pure functions of the sample ids).
#[test]
fn mlt_direct_image_grows_with_the_mutations_and_equals_one_render_of_its_samples() {
    use stagelight::integrators::direct_illumination::{held, path_tracing_settings};
    for (multiplexed, name) in BOTH {
        let state = run("cornell_box.ron", 16, settings(multiplexed, 4, 6, 12));
        let direct = state
            .direct
            .as_ref()
            .expect("direct illumination apart by default");
        let spp = held(Some(direct));
        let mutations = state.counters.steps as f64 / 256.0;
        // One sample at the start, one more per mutation per pixel taken before the last pass.
        assert!(
            spp >= 8 && (spp as f64) <= mutations + 1.0,
            "{name}: {spp} samples per pixel after {mutations} mutations per pixel"
        );
        let data = Arc::new(SceneData::new(load_small("cornell_box.ron", 16)));
        let once =
            stagelight::integrators::driver::render_waves::<stagelight::integrators::pt::PtState>(
                data,
                path_tracing_settings(4),
                stagelight::integrators::Budget::SamplesPerPixel(spp),
                &stagelight::integrators::Control {
                    stop: &std::sync::atomic::AtomicBool::new(false),
                    progress: &|_, _| {},
                },
                None,
            );
        assert!(
            once.film.image().pixels == direct.image().pixels,
            "{name}: the direct image differs from one render of {spp} samples per pixel"
        );
    }
}

/// Mean and standard error of a few values.
fn mean_and_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// tests/scenes/mirror_glass_box.ron: a closed box of rough mirrors with a glass sphere, where
/// light bounces about 20 times; a depth cap of 16 loses 44% of PT's image (measured: PT at
/// 1024 spp, image mean 0.1930 capped against 0.3466). With no cap, each Metropolis
/// integrator's image mean (its b) agrees with PT's within the spread of its seeds.
/// Negative control: with `max_depth` 16 (the cap the integrators had) pssmlt's mean was
/// 0.198 against PT's 0.348, 34 standard errors off.
#[test]
fn mlt_has_no_depth_cap_in_a_closed_mirror_box() {
    let pt: Vec<f64> = (0..2)
        .map(|seed| {
            let film = render_pt(
                load_test_scene("mirror_glass_box.ron"),
                512,
                50 + seed,
                u32::MAX,
            )
            .film;
            mean_luminance(film.image().pixels.iter().map(|p| p.as_dvec3()))
        })
        .collect();
    let (pt_mean, pt_error) = mean_and_error(&pt);
    for (multiplexed, name) in BOTH {
        let means: Vec<f64> = (0..4)
            .map(|seed| {
                let data = Arc::new(SceneData::new(load_test_scene("mirror_glass_box.ron")));
                let mut s = settings(multiplexed, 60 + seed, u32::MAX, 16);
                s.bootstrap = Some(if multiplexed { 2048 } else { 8192 });
                let passes = s.passes_for(24 * 16, 16);
                let state = run_passes::<MltState>(data, s, passes);
                mean_luminance(image(&state).pixels.iter().map(|p| p.as_dvec3()))
            })
            .collect();
        let (mean, error) = mean_and_error(&means);
        let se = (error * error + pt_error * pt_error).sqrt();
        assert!(
            se < 0.05 * pt_mean,
            "{name}: standard error {se} of {pt_mean}"
        );
        assert!(
            (mean - pt_mean).abs() < 4.0 * se,
            "{name}: image mean {mean} (seeds {means:?}) against PT's {pt_mean}: {:.1} standard errors",
            (mean - pt_mean).abs() / se
        );
    }
}

/// b is refined by the chains' large steps: from a bootstrap of 64 evaluations per group, b
/// after 256 mutations per pixel agrees with BDPT's image mean within 3% on the Cornell box,
/// about 0.3 of the steps are large steps counted into it, and the image mean is b.
#[test]
fn mlt_b_converges_from_a_tiny_bootstrap() {
    let bdpt: Vec<f64> = (0..2)
        .map(|seed| {
            let image = render_bdpt(
                load_small("cornell_box.ron", 16),
                512,
                BdptSettings::new(70 + seed, 6),
            )
            .0
            .film
            .image();
            mean_luminance(image.pixels.iter().map(|p| p.as_dvec3()))
        })
        .collect();
    let reference = (bdpt[0] + bdpt[1]) / 2.0;
    for (multiplexed, name) in BOTH {
        let mut s = in_chains(settings(multiplexed, 8, 6, 256));
        s.bootstrap = Some(64);
        let state = run("cornell_box.ron", 16, s);
        let b = state.normalisation();
        assert!(
            (b / reference - 1.0).abs() < 0.03,
            "{name}: b {b} (the bootstrap's {}) against BDPT's {reference}",
            state.bootstrap_normalisation()
        );
        let large = state.normalisation.large_steps as f64 / state.counters.steps as f64;
        assert!((large - 0.3).abs() < 0.01, "{name}: large steps {large}");
        let mean = mean_luminance(image(&state).pixels.iter().map(|p| p.as_dvec3()));
        assert!((mean / b - 1.0).abs() < 1e-4, "{name}: image {mean}, b {b}");
    }
}

/// Issue 42: tests/scenes/glass_tube.ron, a small light at the top of a square tube whose spot
/// falls on a glass sphere seen from a slant. The 16x16 block at (24, 24) over the sphere, the
/// mean over 16 seeds of mmlt at 16 mutations per pixel, agrees with Mitsuba 3's render of the
/// same scene (tests/scenes/references/glass_tube.exr, docs/measurements/mitsuba/glass_tube.xml)
/// within 3 standard errors and 5%, and 3 standard errors are under 5%. Negative control: with
/// mmlt's former bootstrap (one strategy of one depth per evaluation, main at 34ae553) this
/// test fails: the seeds scatter from 0.64 to 1.24 of the reference (mean 0.961, standard error
/// 0.048), as heavy-tailed per-depth normalisations b_k make them.
#[test]
fn mmlt_glass_sphere_block_agrees_with_mitsuba() {
    const SEEDS: u64 = 16;
    const BLOCK: std::ops::Range<usize> = 24..40;
    let block = |image: &Image| {
        mean_luminance(
            BLOCK.flat_map(|y| BLOCK.map(move |x| image.pixels[y * image.width + x].as_dvec3())),
        )
    };
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/scenes/references/glass_tube.exr");
    let reference = block(&Image::read_exr(&path).expect("the committed reference"));
    let values: Vec<f64> = (0..SEEDS)
        .map(|seed| {
            let data = Arc::new(SceneData::new(load_test_scene("glass_tube.ron")));
            let s = settings(true, seed, u32::MAX, 16);
            let passes = s.passes_for(64 * 64, 16);
            block(&image(&run_passes::<MltState>(data, s, passes)))
        })
        .collect();
    let (mean, error) = mean_and_error(&values);
    let ratios: Vec<String> = values
        .iter()
        .map(|v| format!("{:.3}", v / reference))
        .collect();
    assert!(
        3.0 * error < 0.05 * reference,
        "standard error {:.4} of the reference: 3 of them are not under 5% (seeds: {})",
        error / reference,
        ratios.join(" ")
    );
    assert!(
        (mean - reference).abs() < 3.0 * error && (mean / reference - 1.0).abs() < 0.05,
        "mean {:.4} of the reference, standard error {:.4} (seeds: {})",
        mean / reference,
        error / reference,
        ratios.join(" ")
    );
}
