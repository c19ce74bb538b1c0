//! Photon references (`reference --integrator pm|ppm|sppm`): a run interrupted and resumed
//! from its checkpoint equals an uninterrupted one, bit for bit, at 1 and 2 threads, after a
//! checkpoint between passes, Ctrl-C or SIGTERM; a checkpoint of another scene, seed or
//! settings, or one without the integrator's state, is refused.

use crate::common::{
    load_small, shrunk_scene, spawn, stagelight, stagelight_command, stderr, stdout, temp_dir,
    wait_until,
};
use stagelight::film::Image;
use stagelight::integrators::{
    Budget, Control, IntegratorKind, PhotonSettings, RenderSettings, SceneData,
};
use stagelight::reference::{
    Checkpoint, ReferenceBudget, ReferenceError, ReferenceJob, ReferenceOutcome, checkpoint_path,
    render_reference,
};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

fn settings(seed: u64) -> RenderSettings {
    RenderSettings {
        seed,
        photons: PhotonSettings {
            photons_per_pass: 3_000,
            photons: 3_000,
            k: 20,
            eye_rays: 4,
            ..PhotonSettings::default()
        },
        ..RenderSettings::default()
    }
}

fn reference(
    integrator: &str,
    data: &Arc<SceneData>,
    settings: RenderSettings,
    spp: u64,
    output: &Path,
    checkpoint_every: Duration,
) -> Result<ReferenceOutcome, ReferenceError> {
    let job = ReferenceJob {
        scene_path: Path::new("scenes/torus_glass.ron"),
        data: data.clone(),
        integrator: IntegratorKind::named(integrator),
        settings,
        budget: ReferenceBudget::SamplesPerPixel(spp),
        output,
        checkpoint_every,
        shard: None,
    };
    render_reference(&job, &AtomicBool::new(false), &|_, _| {})
}

fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// The checkpoint's film sums, counts and saved state (its header's seconds differ by run).
fn contents(output: &Path) -> (Vec<glam::DVec3>, Vec<u64>, Vec<u8>) {
    let (c, state) = Checkpoint::read_with_state(&checkpoint_path(output)).unwrap();
    (c.film.sums(), c.film.sample_counts().to_vec(), state)
}

#[test]
fn photon_references_resume_bit_for_bit_at_one_and_two_threads() {
    let dir = temp_dir("photon-reference-resume");
    // Glass: PPM's trees split, PM has a caustic map.
    let data = Arc::new(SceneData::new(load_small("torus_glass.ron", 12)));
    for integrator in ["sppm", "ppm", "pm"] {
        let mut per_threads = Vec::new();
        for threads in [1, 2] {
            let name = |what: &str| dir.join(format!("{integrator}-{threads}-{what}.exr"));
            let (resumed, whole) = (name("resumed"), name("whole"));
            on_threads(threads, || {
                // "Interrupted" after 2 passes (a checkpoint after every pass), resumed to 5.
                let first =
                    reference(integrator, &data, settings(7), 2, &resumed, Duration::ZERO).unwrap();
                assert_eq!((first.passes_before, first.passes), (0, 2));
                let second =
                    reference(integrator, &data, settings(7), 5, &resumed, Duration::ZERO).unwrap();
                assert_eq!((second.passes_before, second.passes), (2, 5));
                let once = reference(
                    integrator,
                    &data,
                    settings(7),
                    5,
                    &whole,
                    Duration::from_secs(3600),
                )
                .unwrap();
                assert_eq!((once.passes_before, once.passes), (0, 5));
            });
            let (a, b) = (contents(&resumed), contents(&whole));
            assert!(!a.2.is_empty(), "{integrator}: no state saved");
            assert!(
                a == b,
                "{integrator} at {threads} threads: resumed != whole"
            );
            assert!(
                std::fs::read(&resumed).unwrap() == std::fs::read(&whole).unwrap(),
                "{integrator} at {threads} threads: the EXRs differ"
            );
            per_threads.push(b);
        }
        assert!(
            per_threads[0] == per_threads[1],
            "{integrator}: 1 and 2 threads differ"
        );
        // And the image is the plain render's of 5 passes.
        let stop = AtomicBool::new(false);
        let control = Control {
            stop: &stop,
            progress: &|_, _| {},
        };
        let plain = stagelight::integrators::render(
            IntegratorKind::named(integrator),
            data.clone(),
            &settings(7),
            Budget::SamplesPerPixel(5),
            &control,
        );
        let whole = dir.join(format!("{integrator}-1-whole.exr"));
        assert!(
            plain.film.image() == Image::read_exr(&whole).unwrap(),
            "{integrator}: the reference is not the plain render"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_photon_checkpoint_continues_only_its_own_render() {
    let dir = temp_dir("photon-reference-mismatch");
    let data = Arc::new(SceneData::new(load_small("torus_glass.ron", 8)));
    let out = dir.join("ref.exr");
    reference("sppm", &data, settings(3), 2, &out, Duration::ZERO).unwrap();

    let refused = |integrator: &str, data: &Arc<SceneData>, settings: RenderSettings| {
        reference(integrator, data, settings, 4, &out, Duration::ZERO)
            .unwrap_err()
            .to_string()
    };
    let e = refused("sppm", &data, settings(4));
    assert!(e.contains("seed 3, not 4"), "{e}");
    assert!(e.contains("ref.exr.checkpoint"), "{e}");
    let e = refused("ppm", &data, settings(3));
    assert!(e.contains("integrator sppm, not ppm"), "{e}");
    let other = Arc::new(SceneData::new(load_small("cornell_box.ron", 8)));
    let e = refused("sppm", &other, settings(3));
    assert!(e.contains("a different scene"), "{e}");
    let mut alpha = settings(3);
    alpha.photons.alpha = Some(0.5);
    let e = refused("sppm", &data, alpha);
    assert!(
        e.contains("settings") && e.contains("alpha: Some(0.5)"),
        "{e}"
    );

    // The image without the state (as `merge` writes one) cannot be continued.
    let (c, state) = Checkpoint::read_with_state(&checkpoint_path(&out)).unwrap();
    assert!(!state.is_empty());
    c.write(&checkpoint_path(&out)).unwrap();
    let e = refused("sppm", &data, settings(3));
    assert!(e.contains("but not its state"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `reference --integrator sppm` stopped by SIGINT (Ctrl-C) or SIGTERM keeps its finished
/// passes, and the same command continues them to what an uninterrupted run makes.
#[test]
fn a_stopped_sppm_reference_resumes_exactly() {
    let dir = temp_dir("photon-reference-signal");
    let scene = shrunk_scene("torus_glass", 16, &dir.join("torus16.ron"));
    let scene = scene.to_str().unwrap();
    let common = [
        "--integrator",
        "sppm",
        "--photons-per-pass",
        "2000",
        "--seed",
        "5",
        "--threads",
        "2",
        "--quiet",
    ];
    for signal in ["INT", "TERM"] {
        let out = dir.join(format!("{signal}.exr"));
        let cp = checkpoint_path(&out);
        let mut child = spawn(
            stagelight_command()
                .args([
                    "reference",
                    scene,
                    "--spp",
                    "1000000",
                    "--checkpoint-every",
                    "0.2",
                ])
                .args(common)
                .arg("-o")
                .arg(&out),
        );
        wait_until(&mut child, "a first checkpoint", || cp.exists());
        let killed = std::process::Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(130), "{signal}: {}", stderr(&o));
        assert!(
            stdout(&o).contains("run the same command again"),
            "{}",
            stdout(&o)
        );
        let stopped = Checkpoint::read(&cp).unwrap().header.passes;
        assert!(stopped >= 1);

        let target = (stopped + 2).to_string();
        let run = |output: &Path| {
            let mut args = vec!["reference", scene, "--spp", &target];
            args.extend(common);
            args.extend(["-o", output.to_str().unwrap()]);
            stagelight(&args)
        };
        let o = run(&out);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        assert!(
            stdout(&o).contains(&format!("resumed from {stopped} spp")),
            "{}",
            stdout(&o)
        );
        let whole = dir.join(format!("{signal}-whole.exr"));
        assert_eq!(run(&whole).status.code(), Some(0));
        assert!(
            contents(&out) == contents(&whole),
            "{signal}: resumed != whole"
        );
        assert!(std::fs::read(&out).unwrap() == std::fs::read(&whole).unwrap());
    }
    let _ = std::fs::remove_dir_all(&dir);
}
