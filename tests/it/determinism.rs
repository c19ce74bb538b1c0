//! The same scene, seed and sample count give a bit-identical EXR whatever the thread count.

use crate::common::{stagelight_command, stderr, temp_dir};
use std::path::Path;

fn render(threads: u32, seed: u64, out: &Path) {
    let o = stagelight_command()
        .args(["render", "scenes/cornell_box.ron", "--spp", "3", "--quiet"])
        .args(["--seed", &seed.to_string()])
        .args(["--threads", &threads.to_string(), "-o"])
        .arg(out)
        .output()
        .expect("stagelight runs");
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn exr_is_bit_identical_for_one_two_and_three_threads() {
    let dir = temp_dir("determinism");
    let files: Vec<_> = [1, 2, 3]
        .iter()
        .map(|&t| {
            let out = dir.join(format!("t{t}.exr"));
            render(t, 11, &out);
            std::fs::read(&out).expect("EXR written")
        })
        .collect();
    let image = stagelight::film::Image::read_exr(&dir.join("t1.exr")).expect("EXR reads");
    assert_eq!((image.width, image.height), (256, 256));
    assert!(files[0] == files[1], "1 and 2 threads differ");
    assert!(files[0] == files[2], "1 and 3 threads differ");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_different_seed_gives_a_different_image() {
    let dir = temp_dir("seed");
    let (a, b) = (dir.join("a.exr"), dir.join("b.exr"));
    render(2, 11, &a);
    render(2, 12, &b);
    assert!(std::fs::read(&a).unwrap() != std::fs::read(&b).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Each thread renders whole waves on a state of its own and the states are folded at the end
/// (`driver::render_waves_of`): the film's sums, the samples and every system's item counts
/// are those of one state rendering every wave, for both kernels and for BDPT, on waves small
/// enough that each thread takes several.
#[test]
fn states_folded_across_threads_keep_every_sample_and_count() {
    use stagelight::integrators::{IntegratorKind, RenderSettings, pt::Kernel};
    use std::sync::Arc;
    let data = Arc::new(stagelight::scene::SceneData::new(
        crate::common::load_small("cornell_box.ron", 24),
    ));
    let cases = [
        ("pt", Kernel::Wavefront),
        ("pt", Kernel::Megakernel),
        ("bdpt", Kernel::Wavefront),
    ];
    for (name, kernel) in cases {
        let settings = RenderSettings {
            seed: 4,
            kernel,
            wavefront: Some(700),
            ..RenderSettings::default()
        };
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let kind = IntegratorKind::from_name(name).unwrap();
                    crate::common::render_outcome_with(kind, data.clone(), &settings, 9)
                })
        };
        let (one, three) = (on(1), on(3));
        let what = format!("{name} {kernel}");
        let sums = |o: &stagelight::integrators::RenderOutcome| {
            (o.film.fixed_sums().to_vec(), o.film.fixed_splats().to_vec())
        };
        assert!(sums(&one) == sums(&three), "{what}: the films' sums");
        assert_eq!(
            one.film.sample_counts(),
            three.film.sample_counts(),
            "{what}"
        );
        assert_eq!(one.film.total_samples(), 9 * 24 * 24, "{what}");
        assert_eq!(
            (one.samples, one.passes),
            (three.samples, three.passes),
            "{what}"
        );
        assert!(one.closest_rays() > 9 * 24 * 24, "{what}: rays counted");
        assert_eq!(
            one.closest_rays(),
            three.closest_rays(),
            "{what}: closest rays"
        );
        assert_eq!(
            one.shadow_rays(),
            three.shadow_rays(),
            "{what}: shadow rays"
        );
        let taken = |o: &stagelight::integrators::RenderOutcome| -> Vec<(&str, u64, u64)> {
            o.stats
                .systems
                .iter()
                .map(|s| (s.name, s.taken, s.emitted))
                .collect()
        };
        assert_eq!(taken(&one), taken(&three), "{what}: systems' counts");
        assert!(
            three.wavefront <= 3 * 700,
            "{what}: {} paths in flight",
            three.wavefront
        );
    }
}
