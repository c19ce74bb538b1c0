//! Veach's path-space MLT (`mlt`): the mutations' densities (the density a mutation sampled a
//! path with equals the one recomputed from the path; every proposal can be undone, with a
//! positive T(y -> x); no mutation proposes a path it says it cannot make), the seeds rebuilt
//! from the bootstrap, the image's normalisation, the furnace (which fails without the Hastings
//! ratio), block means against BDPT on the three scenes (bidirectional mutation alone and all
//! mutations), and thread-count independence.

use crate::common::{block_luminance_stats, block_luminance_stats_of, load_small, render_bdpt};
use stagelight::film::Image;
use stagelight::integrators::bdpt::BdptSettings;
use stagelight::integrators::driver::{PassState, run_passes};
use stagelight::integrators::path_mlt::{PathMltSettings, PathMltState};
use stagelight::integrators::{RenderSettings, SceneData};
use stagelight::mlt::path_chains::MutationKind;
use stagelight::mlt::path_space::{PathSpace, StepNumbers};
use stagelight::sampling::SampleKey;
use stagelight::systems::mutate::{bidirectional, path_mutation};
use std::sync::Arc;

const BIDIR_ONLY: u8 = 1 << MutationKind::Bidirectional as u8;

fn settings(
    data: &SceneData,
    seed: u64,
    max_depth: u32,
    direct_spp: u32,
    mutations: u8,
) -> PathMltSettings {
    let mut r = RenderSettings {
        seed,
        max_depth,
        ..RenderSettings::default()
    };
    r.mlt.direct_spp = Some(direct_spp);
    r.mlt.mutations = Some(mutations);
    PathMltSettings::from_render(data, &r)
}

/// `m` mutations per pixel (whole passes) on `scene` at `size` x `size`.
fn run(
    scene: &str,
    size: u32,
    seed: u64,
    max_depth: u32,
    direct_spp: u32,
    mutations: u8,
    m: u64,
) -> PathMltState {
    let data = Arc::new(SceneData::new(load_small(scene, size)));
    let mut s = settings(&data, seed, max_depth, direct_spp, mutations);
    s.bootstrap.mutations_per_pixel = Some(m);
    let passes = s.bootstrap.passes_for((size * size) as u64, m);
    run_passes::<PathMltState>(data, s, passes)
}

fn image(state: PathMltState) -> Image {
    state.finish(0).0.image()
}

fn luminance(p: [f64; 3]) -> f64 {
    0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]
}

#[test]
fn path_mlt_mutations_sample_the_density_they_report_and_can_be_undone() {
    for scene in [
        "cornell_box.ron",
        "door_ajar.ron",
        "torus_glass.ron",
        "furnace.ron",
    ] {
        let state = run(scene, 16, 3, 10, 0, 0b1111, 2);
        assert_eq!(state.seed_mismatches, 0, "{scene}: seeds not rebuilt");
        let ps = PathSpace::new(&state.data);
        let set = state.settings.mutations;
        let chains = &state.chains;
        let (mut proposed, mut by_kind) = (0, [0usize; 4]);
        for chain in 0..chains.chains().min(2000) {
            let len = chains.current_len[chain] as usize;
            if len < 2 {
                continue;
            }
            let x = chains.current_path(chain);
            let fx = ps.contribution(&x).expect("a chain's path carries light");
            assert!(fx.0.is_finite());
            for kind in path_mutation::suitable(&ps, &set, &x) {
                for trial in 0..4u64 {
                    let mut u = StepNumbers::new(SampleKey::new(99, chain as u64, trial), 2);
                    let Some(p) = path_mutation::propose(&ps, &set, kind, &x, &mut u) else {
                        continue;
                    };
                    let Some(_) = ps.contribution(&p.path) else {
                        continue;
                    };
                    proposed += 1;
                    by_kind[kind as usize] += 1;
                    // The proposal can be undone and was made with the density it reports.
                    assert!(
                        p.ratio.is_finite() && p.ratio > 0.0,
                        "{scene} {kind:?}: ratio {} for a path of {} from {}",
                        p.ratio,
                        p.path.len(),
                        x.len()
                    );
                    // The sampled density multiplies the cosines of the sampled directions, the
                    // recomputed one those between the stored (rounded) hit points; on the
                    // faceted furnace sphere they differed by up to 4.7e-3 (a wrong factor in a
                    // density is far larger).
                    let rel = (p.sampled_density / p.recomputed_density - 1.0).abs();
                    assert!(
                        p.recomputed_density > 0.0 && rel < 1e-2,
                        "{scene} {kind:?}: sampled {} recomputed {}",
                        p.sampled_density,
                        p.recomputed_density
                    );
                    // The reverse move exists: the same mutation kind suits y.
                    assert!(
                        path_mutation::suitable(&ps, &set, &p.path).contains(&kind),
                        "{scene} {kind:?}: y cannot be mutated back"
                    );
                }
            }
        }
        assert!(
            proposed > 500,
            "{scene}: only {proposed} proposals ({by_kind:?})"
        );
        if scene == "torus_glass.ron" {
            assert!(by_kind[MutationKind::Caustic as usize] > 0, "{by_kind:?}");
            assert!(
                by_kind[MutationKind::MultiChain as usize] > 0,
                "{by_kind:?}"
            );
        }
        assert!(
            by_kind[MutationKind::Lens as usize] > 0,
            "{scene}: {by_kind:?}"
        );
    }
}

#[test]
fn path_mlt_bidirectional_transition_sums_every_split_and_is_a_distribution() {
    // The deletion and addition lengths are distributions.
    for n in 2..=18 {
        let total: f64 = (1..=n).map(|k| bidirectional::two_tailed(2, 1, n, k)).sum();
        assert!((total - 1.0).abs() < 1e-12);
        for u in [0.0, 0.3, 0.999_999] {
            let k = bidirectional::sample_two_tailed(2, 1, n, u);
            assert!((1..=n).contains(&k));
        }
    }
}

#[test]
fn path_mlt_image_mean_is_b_and_the_furnace_is_two() {
    // Without direct lighting apart, the splats alone are the image: its mean luminance is b.
    let state = run("cornell_box.ron", 16, 5, 8, 0, 0b1111, 8);
    let b = state.seeding.normalisation();
    let img = image(state);
    let mean = luminance(img.channel_means().to_array());
    assert!((mean / b - 1.0).abs() < 1e-4, "image mean {mean}, b {b}");
    // The furnace: every pixel 2 (less 2^-17 beyond the depth cap), direct part apart or not.
    // Each run's mean within 1%; 4x4 blocks, whose noise at 64 steps per chain is ~6% (the
    // chains mix slowly across an 8x8 image), within 5 standard errors over four seeds.
    for direct in [0, 4] {
        let images: Vec<Image> = (1..=4)
            .map(|seed| image(run("furnace.ron", 8, seed, u32::MAX, direct, 0b1111, 256)))
            .collect();
        for img in &images {
            let l = luminance(img.channel_means().to_array());
            assert!((l / 2.0 - 1.0).abs() < 0.01, "direct {direct}: mean {l}");
        }
        for (i, (m, se)) in block_luminance_stats_of(&images, 4).into_iter().enumerate() {
            assert!(se < 0.1, "direct {direct}: block {i} standard error {se}");
            assert!(
                (m - 2.0).abs() <= 5.0 * se,
                "direct {direct}: block {i} {m} against 2, {:.2} standard errors",
                (m - 2.0).abs() / se
            );
        }
    }
}

#[test]
fn path_mlt_block_means_agree_with_bdpt() {
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
        for (mutations, name) in [(BIDIR_ONLY, "bidir"), (0b1111, "all")] {
            let images: Vec<Image> = (0..SEEDS)
                .map(|seed| image(run(scene, SIZE, seed, DEPTH, 4, mutations, 32)))
                .collect();
            for (i, ((m, s), (rm, rs))) in block_luminance_stats(&images)
                .into_iter()
                .zip(&reference)
                .enumerate()
            {
                let se = (s * s + rs * rs).sqrt();
                assert!(
                    se < 0.35 * rm,
                    "{scene} {name} block {i}: standard error {se} too large ({m} vs {rm})"
                );
                assert!(
                    (m - rm).abs() <= 5.0 * se,
                    "{scene} {name} block {i}: {m} vs {rm}, {:.2} standard errors",
                    (m - rm).abs() / se
                );
            }
        }
    }
}

#[test]
fn path_mlt_same_image_for_any_thread_count() {
    let images: Vec<Vec<glam::Vec3>> = [1, 2, 3]
        .into_iter()
        .map(|threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| image(run("torus_glass.ron", 16, 7, 8, 2, 0b1111, 4)).pixels)
        })
        .collect();
    assert!(images[0] == images[1] && images[1] == images[2]);
}
