//! References: an interrupted reference and its resumption equal, sample for sample, an
//! uninterrupted one; a checkpoint continues only the render that made it.

use crate::common::{
    interrupt, load_small, render_bdpt, render_pt, spawn, stagelight, stagelight_command, stderr,
    stdout, temp_dir, wait_until,
};
use stagelight::film::Image;
use stagelight::integrators::{IntegratorKind, RenderSettings, SceneData};
use stagelight::reference::{
    Checkpoint, ReferenceBudget, ReferenceJob, checkpoint_path, reference_attributes,
    render_reference,
};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

fn small(name: &str, size: u32) -> Arc<SceneData> {
    Arc::new(SceneData::new(load_small(name, size)))
}

fn reference(
    data: &Arc<SceneData>,
    seed: u64,
    spp: u64,
    output: &Path,
    checkpoint_every: Duration,
) -> Result<stagelight::reference::ReferenceOutcome, stagelight::reference::ReferenceError> {
    reference_with(
        IntegratorKind::named("pt"),
        data,
        seed,
        spp,
        output,
        checkpoint_every,
    )
}

fn reference_with(
    integrator: IntegratorKind,
    data: &Arc<SceneData>,
    seed: u64,
    spp: u64,
    output: &Path,
    checkpoint_every: Duration,
) -> Result<stagelight::reference::ReferenceOutcome, stagelight::reference::ReferenceError> {
    let job = ReferenceJob {
        scene_path: Path::new("scenes/cornell_box.ron"),
        data: data.clone(),
        integrator,
        settings: RenderSettings {
            seed,
            ..RenderSettings::default()
        },
        budget: ReferenceBudget::SamplesPerPixel(spp),
        output,
        checkpoint_every,
        shard: None,
    };
    render_reference(&job, &AtomicBool::new(false), &|_, _| {})
}

#[test]
fn interrupted_and_resumed_equals_uninterrupted_bit_for_bit() {
    let dir = temp_dir("reference-resume");
    let data = small("cornell_box.ron", 16);
    // "Interrupted" after 5 passes, checkpointing after every pass; then resumed to 12.
    let resumed = dir.join("resumed.exr");
    let first = reference(&data, 7, 5, &resumed, Duration::ZERO).unwrap();
    assert_eq!((first.passes_before, first.passes), (0, 5));
    let second = reference(&data, 7, 12, &resumed, Duration::ZERO).unwrap();
    assert_eq!((second.passes_before, second.passes), (5, 12));
    assert!(!second.interrupted && !second.already_complete);

    let whole = dir.join("whole.exr");
    let once = reference(&data, 7, 12, &whole, Duration::from_secs(3600)).unwrap();
    assert_eq!((once.passes_before, once.passes), (0, 12));

    // The f64 sums, the float32 EXR and its header are the same, bit for bit.
    let a = Checkpoint::read(&checkpoint_path(&resumed)).unwrap();
    let b = Checkpoint::read(&checkpoint_path(&whole)).unwrap();
    let bits = |c: &Checkpoint| -> Vec<u64> {
        c.film
            .sums()
            .iter()
            .flat_map(|s| [s.x.to_bits(), s.y.to_bits(), s.z.to_bits()])
            .collect()
    };
    assert!(bits(&a) == bits(&b), "the film sums differ");
    assert_eq!(a.film.sample_counts(), b.film.sample_counts());
    assert_eq!(a.header.passes, 12);
    assert!(std::fs::read(&resumed).unwrap() == std::fs::read(&whole).unwrap());

    // And both equal a plain 12-spp render with the same seed.
    let plain = render_pt(load_small("cornell_box.ron", 16), 12, 7, u32::MAX);
    assert!(plain.film.image() == Image::read_exr(&whole).unwrap());

    let attributes = reference_attributes(&resumed).unwrap();
    assert_eq!(attributes.get("spp").map(String::as_str), Some("12"));
    assert_eq!(attributes.get("seed").map(String::as_str), Some("7"));
    assert_eq!(attributes.get("integrator").map(String::as_str), Some("pt"));
    assert_eq!(
        attributes.get("scene").map(String::as_str),
        Some("scenes/cornell_box.ron")
    );

    // Asking for fewer passes than the reference holds renders nothing.
    let again = reference(&data, 7, 8, &resumed, Duration::ZERO).unwrap();
    assert!(again.already_complete && again.passes == 12);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bdpt_reference_resumes_with_its_splats() {
    // Light tracing splats into any pixel: the checkpoint must keep them to resume exactly.
    let dir = temp_dir("reference-bdpt");
    let data = small("cornell_box.ron", 12);
    let resumed = dir.join("resumed.exr");
    reference_with(
        IntegratorKind::named("bdpt"),
        &data,
        5,
        2,
        &resumed,
        Duration::ZERO,
    )
    .unwrap();
    reference_with(
        IntegratorKind::named("bdpt"),
        &data,
        5,
        5,
        &resumed,
        Duration::ZERO,
    )
    .unwrap();
    let whole = dir.join("whole.exr");
    reference_with(
        IntegratorKind::named("bdpt"),
        &data,
        5,
        5,
        &whole,
        Duration::from_secs(3600),
    )
    .unwrap();
    assert!(std::fs::read(&resumed).unwrap() == std::fs::read(&whole).unwrap());
    let settings = stagelight::integrators::bdpt::BdptSettings::new(5, u32::MAX);
    let plain = render_bdpt(load_small("cornell_box.ron", 12), 5, settings);
    assert!(plain.0.film.image() == Image::read_exr(&whole).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_checkpoint_continues_only_its_own_render() {
    let dir = temp_dir("reference-mismatch");
    let data = small("cornell_box.ron", 8);
    let out = dir.join("ref.exr");
    reference(&data, 3, 2, &out, Duration::ZERO).unwrap();

    let e = reference(&data, 4, 4, &out, Duration::ZERO).unwrap_err();
    assert!(e.to_string().contains("seed 3, not 4"), "{e}");
    assert!(e.to_string().contains("ref.exr.checkpoint"), "{e}");

    let e = reference(&small("cornell_box.ron", 9), 3, 4, &out, Duration::ZERO).unwrap_err();
    assert!(e.to_string().contains("8x8, not 9x9"), "{e}");

    let e = reference(&small("torus_glass.ron", 8), 3, 4, &out, Duration::ZERO).unwrap_err();
    assert!(e.to_string().contains("a different scene"), "{e}");

    // An EXR without its checkpoint cannot be resumed.
    let lone = dir.join("lone.exr");
    Image::new(8, 8).write_exr(&lone).unwrap();
    let e = reference(&data, 3, 4, &lone, Duration::ZERO).unwrap_err();
    assert!(e.to_string().contains("without its checkpoint"), "{e}");

    // A damaged checkpoint is named as such.
    let cp = checkpoint_path(&out);
    let bytes = std::fs::read(&cp).unwrap();
    std::fs::write(&cp, &bytes[..bytes.len() - 100]).unwrap();
    let e = reference(&data, 3, 4, &out, Duration::ZERO).unwrap_err();
    assert!(e.to_string().contains("damaged checkpoint"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ctrl_c_keeps_the_checkpoint_and_a_second_run_resumes_it_exactly() {
    let dir = temp_dir("reference-sigint");
    let out = dir.join("cb.exr");
    let cp = checkpoint_path(&out);
    let mut child = spawn(
        stagelight_command()
            .args([
                "reference",
                "scenes/cornell_box.ron",
                "--spp",
                "100000",
                "--quiet",
            ])
            .args(["--seed", "5", "--checkpoint-every", "0.2", "-o"])
            .arg(&out),
    );
    wait_until(&mut child, "a first checkpoint", || cp.exists());
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(stdout(&o).contains("run the same command again"));
    let stopped = Checkpoint::read(&cp).unwrap().header.passes;
    assert!(stopped >= 1);
    let attributes = reference_attributes(&out).unwrap();
    assert_eq!(attributes.get("spp"), Some(&stopped.to_string()));

    // Resume to one pass more than was done, then compare with an uninterrupted render.
    let target = (stopped + 1).to_string();
    let run = |output: &Path| {
        stagelight(&[
            "reference",
            "scenes/cornell_box.ron",
            "--spp",
            &target,
            "--quiet",
            "--seed",
            "5",
            "-o",
            output.to_str().unwrap(),
        ])
    };
    let o = run(&out);
    assert_eq!(o.status.code(), Some(0));
    assert!(stdout(&o).contains(&format!("resumed from {stopped} spp")));
    let whole = dir.join("whole.exr");
    assert_eq!(run(&whole).status.code(), Some(0));
    // Same film sums, same EXR bytes (pixels and header).
    let sums = |p: &Path| {
        Checkpoint::read(&checkpoint_path(p))
            .unwrap()
            .film
            .sums()
            .to_vec()
    };
    assert!(sums(&out) == sums(&whole));
    assert!(std::fs::read(&out).unwrap() == std::fs::read(&whole).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}
