//! Shards and `stagelight merge`: a render split into pass ranges, each rendered by its own
//! process, merges into the very bytes one process rendering every pass writes (EXR and PNG,
//! as `cmp` would compare them); parts that do not belong together are refused, naming
//! what is missing, overlapping or different.

use crate::common::{TempDir, shrunk_scene, stagelight, stderr, stdout, temp_dir};
use std::path::Path;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs `stagelight` and fails the test, with its stderr, unless it exits 0.
fn ok(args: &[&str]) -> String {
    let o = stagelight(args);
    assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
    stdout(&o)
}

/// Runs `stagelight`, which must fail with exit 1 and one error line; returns that line.
fn refused(args: &[&str]) -> String {
    let o = stagelight(args);
    assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stdout(&o));
    let err = stderr(&o);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("error: "), "{err}");
    err
}

/// The two files hold the same bytes (what `cmp` checks).
fn assert_same_bytes(a: &Path, b: &Path) {
    let (x, y) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    assert!(
        x == y,
        "{} and {} differ ({} and {} bytes)",
        a.display(),
        b.display(),
        x.len(),
        y.len()
    );
}

/// Renders `command` (render or reference) whole, and as shards given by `shard_args` (each
/// a list of extra arguments), merges the shards and compares the bytes.
fn whole_against_merged(
    name: &str,
    command: &str,
    common: &[&str],
    shard_args: &[&[&str]],
) -> TempDir {
    let dir = temp_dir(name);
    let scene = shrunk_scene("cornell_box", 12, &dir.join("scene.ron"));
    let whole = dir.join("whole.exr");
    let mut args = vec![command, s(&scene), "-o", s(&whole), "--quiet"];
    args.extend_from_slice(common);
    ok(&args);
    let mut parts = Vec::new();
    for (i, extra) in shard_args.iter().enumerate() {
        let part = dir.join(format!("part{i}.exr"));
        let mut args = vec![command, s(&scene), "-o", s(&part), "--quiet"];
        args.extend_from_slice(common);
        args.extend_from_slice(extra);
        // Each shard with another thread count: the film must not care.
        let threads = (i % 3 + 1).to_string();
        args.extend_from_slice(&["--threads", &threads]);
        ok(&args);
        assert!(
            dir.join(format!("part{i}.exr.checkpoint")).exists(),
            "the shard's film lies beside its image"
        );
        parts.push(part);
    }
    // Given in any order.
    parts.reverse();
    let merged = dir.join("merged.exr");
    let mut args = vec!["merge"];
    args.extend(parts.iter().map(|p| s(p)));
    args.extend_from_slice(&["-o", s(&merged)]);
    let out = ok(&args);
    assert!(out.contains("merged"), "{out}");
    assert_same_bytes(&whole, &merged);
    assert_same_bytes(&whole.with_extension("png"), &merged.with_extension("png"));
    dir
}

#[test]
fn pt_shards_merge_into_the_single_render_byte_for_byte() {
    whole_against_merged(
        "shards-pt",
        "render",
        &["--spp", "10", "--seed", "3"],
        &[
            &["--shard", "1/3"],
            &["--shard", "2/3"],
            &["--shard", "3/3"],
        ],
    );
}

#[test]
fn pt_sobol_shards_with_a_depth_cap_merge_byte_for_byte() {
    whole_against_merged(
        "shards-pt-sobol",
        "render",
        &["--spp", "7", "--sampler", "sobol", "--max-depth", "3"],
        &[&["--pass-range", "0..1"], &["--pass-range", "1..7"]],
    );
}

#[test]
fn bdpt_shards_merge_into_the_single_render_byte_for_byte() {
    // BDPT splats light tracing into other pixels: the splat sums merge exactly too.
    whole_against_merged(
        "shards-bdpt",
        "render",
        &["--integrator", "bdpt", "--spp", "6", "--seed", "5"],
        &[
            &["--pass-range", "0..2"],
            &["--pass-range", "2..3"],
            &["--pass-range", "3..6"],
        ],
    );
}

#[test]
fn reference_shards_merge_into_the_single_reference_and_it_extends() {
    let dir = whole_against_merged(
        "shards-reference",
        "reference",
        &["--integrator", "bdpt", "--spp", "4", "--seed", "9"],
        &[&["--shard", "1/2"], &["--shard", "2/2"]],
    );
    // The merged reference has the single reference's checkpoint: `reference` extends it
    // to 6 spp exactly as it extends the single one.
    let scene = dir.join("scene.ron");
    for name in ["whole.exr", "merged.exr"] {
        let out = ok(&[
            "reference",
            s(&scene),
            "--integrator",
            "bdpt",
            "--spp",
            "6",
            "--seed",
            "9",
            "-o",
            s(&dir.join(name)),
            "--quiet",
        ]);
        assert!(out.contains("resumed from 4 spp"), "{out}");
    }
    assert_same_bytes(&dir.join("whole.exr"), &dir.join("merged.exr"));
}

#[test]
fn merge_names_missing_overlapping_and_foreign_parts() {
    let dir = temp_dir("shards-refused");
    let scene = shrunk_scene("cornell_box", 6, &dir.join("scene.ron"));
    let shard = |name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let mut args = vec!["render", s(&scene), "--spp", "8", "-o", s(&out), "--quiet"];
        args.extend_from_slice(extra);
        ok(&args);
        out
    };
    let a = shard("a.exr", &["--shard", "1/4"]);
    let b = shard("b.exr", &["--shard", "2/4"]);
    let d = shard("d.exr", &["--shard", "4/4"]);
    let merged = dir.join("merged.exr");
    let merge = |parts: &[&Path]| {
        let mut args = vec!["merge"];
        args.extend(parts.iter().map(|p| s(p)));
        args.extend_from_slice(&["-o", s(&merged)]);
        refused(&args)
    };

    let err = merge(&[&a, &b, &d]);
    assert!(err.contains("passes 4..6 missing"), "{err}");
    let err = merge(&[&a, &b]);
    assert!(err.contains("passes 4..8 missing"), "{err}");

    let wide = shard("wide.exr", &["--pass-range", "1..5"]);
    let err = merge(&[&a, &wide, &d]);
    assert!(err.contains("overlap in passes 1..2"), "{err}");
    assert!(err.contains("wide.exr") && err.contains("a.exr"), "{err}");

    let seeded = shard("seeded.exr", &["--shard", "3/4", "--seed", "1"]);
    let err = merge(&[&a, &b, &seeded, &d]);
    assert!(err.contains("seed 1") && err.contains("seed 0"), "{err}");

    let bdpt = shard("bdpt.exr", &["--shard", "3/4", "--integrator", "bdpt"]);
    let err = merge(&[&a, &b, &bdpt, &d]);
    assert!(err.contains("integrator bdpt"), "{err}");

    // A different scene (another image size here) is named too.
    let other = shrunk_scene("cornell_box", 5, &dir.join("other.ron"));
    let c5 = dir.join("c5.exr");
    ok(&[
        "render",
        s(&other),
        "--spp",
        "8",
        "--shard",
        "3/4",
        "-o",
        s(&c5),
        "--quiet",
    ]);
    let err = merge(&[&a, &b, &c5, &d]);
    assert!(err.contains("image size 5x5"), "{err}");

    // A part without a film, and a damaged film.
    let plain = dir.join("plain.exr");
    ok(&[
        "render",
        s(&scene),
        "--spp",
        "2",
        "-o",
        s(&plain),
        "--quiet",
    ]);
    let err = merge(&[&a, &plain]);
    assert!(
        err.contains("plain.exr.checkpoint: no partial film"),
        "{err}"
    );
    let film = dir.join("b.exr.checkpoint");
    let mut bytes = std::fs::read(&film).unwrap();
    let last = bytes.len() - 20;
    bytes[last] ^= 1;
    std::fs::write(&film, bytes).unwrap();
    let err = merge(&[&a, &b, &d]);
    assert!(
        err.contains("b.exr.checkpoint") && err.contains("damaged"),
        "{err}"
    );
    assert!(
        !merged.exists(),
        "nothing is written when parts are refused"
    );

    // Shards need a sample budget, and an unbiased integrator.
    let o = stagelight(&[
        "render",
        s(&scene),
        "--time",
        "1",
        "--shard",
        "1/2",
        "-o",
        s(&merged),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--time"), "{}", stderr(&o));
    let err = refused(&[
        "render",
        s(&scene),
        "--spp",
        "2",
        "--shard",
        "1/3",
        "-o",
        s(&merged),
    ]);
    assert!(err.contains("3 shards of 2 passes"), "{err}");
}

/// Mean over pixels of |L - 2| and the mean L (the green channel), in the furnace, where every
/// pixel is exactly 2.
fn furnace_error(image: &stagelight::film::Image) -> (f64, f64) {
    let n = image.pixels.len() as f64;
    let dev = image
        .pixels
        .iter()
        .map(|p| (p.y as f64 - 2.0).abs())
        .sum::<f64>()
        / n;
    let mean = image.pixels.iter().map(|p| p.y as f64).sum::<f64>() / n;
    (dev, mean)
}

/// Shards of the biased integrators are independent runs: shard 1 (from pass 0) is the
/// plain render of its passes with the render's seed, the other has its own seed, and merge
/// averages their images weighted by mutations (the Metropolis integrators) or passes x
/// pixels (SPPM). Checked in
/// the furnace (every pixel exactly 2): the weighted average recomputed here from the shards'
/// EXRs, the merged mean against 2, and less per-pixel error than the worse shard's.
#[test]
fn biased_shards_are_independent_runs_averaged_by_their_weights() {
    use stagelight::film::Image;
    use stagelight::reference::Checkpoint;
    let dir = temp_dir("shards-biased");
    let scene = shrunk_scene("furnace", 8, &dir.join("scene.ron"));
    let pixels = 64u64;
    for (integrator, spp, extra, tolerance) in [
        ("pssmlt", 256u64, &[][..], 0.03),
        ("mmlt", 256, &[][..], 0.03),
        ("mlt", 256, &["--direct-spp", "4"][..], 0.03),
        // The radius given: the default, a few pixel footprints, is most of the sphere at
        // 8 x 8 pixels, and its bias (1.81 against 2 at 6 passes) is not what this tests.
        (
            "sppm",
            6,
            &["--photons-per-pass", "20000", "--radius", "0.035"][..],
            0.03,
        ),
    ] {
        let render = |name: &str, spp: u64, more: &[&str]| {
            let spp_text = spp.to_string();
            let out = dir.join(format!("{integrator}-{name}.exr"));
            let mut args = vec![
                "render",
                s(&scene),
                "--integrator",
                integrator,
                "--spp",
                &spp_text,
                "--seed",
                "4",
                "-o",
                s(&out),
                "--quiet",
            ];
            args.extend_from_slice(extra);
            args.extend_from_slice(more);
            ok(&args);
            out
        };
        let a = render("a", spp, &["--shard", "1/2"]);
        let b = render("b", spp, &["--shard", "2/2"]);
        // Shard 1 is the plain render of its half of the passes, seed 4.
        let plain = render("plain", spp / 2, &[]);
        assert_same_bytes(&plain, &a);
        let merged = dir.join(format!("{integrator}-merged.exr"));
        let out = ok(&["merge", s(&b), s(&a), "-o", s(&merged)]);
        assert!(out.contains("independent runs"), "{out}");

        let read = |p: &Path| Image::read_exr(p).unwrap();
        let (ia, ib, im) = (read(&a), read(&b), read(&merged));
        assert!(
            ia.pixels != ib.pixels,
            "{integrator}: shard 2 has its own seed"
        );
        let weight = |p: &Path| {
            let film = Checkpoint::read(&p.with_extension("exr.checkpoint"))
                .unwrap()
                .film;
            film.sample_counts()[0]
        };
        let (wa, wb) = (weight(&a), weight(&b));
        for (w, passes) in [(wa, spp / 2), (wb, spp - spp / 2)] {
            if integrator == "sppm" {
                assert_eq!(w, passes * pixels, "{integrator}: passes x pixels");
            } else {
                // Mutations: whole MLT passes of about one mutation per pixel each.
                assert!(
                    (passes * pixels..passes * pixels + 2 * pixels).contains(&w),
                    "{integrator}: {w} mutations for {passes} per pixel"
                );
            }
        }
        for ((pa, pb), pm) in ia.pixels.iter().zip(&ib.pixels).zip(&im.pixels) {
            let expected =
                (pa.as_dvec3() * wa as f64 + pb.as_dvec3() * wb as f64) / (wa + wb) as f64;
            let off = (pm.as_dvec3() - expected).abs().max_element();
            assert!(
                off <= 1e-6 * expected.abs().max_element().max(1e-30),
                "{integrator}: merged {pm} against the weighted average {expected}"
            );
        }
        let (ea, eb, em) = (furnace_error(&ia), furnace_error(&ib), furnace_error(&im));
        assert!(
            (em.1 / 2.0 - 1.0).abs() < tolerance,
            "{integrator}: merged mean {} against 2",
            em.1
        );
        assert!(
            em.0 < ea.0.max(eb.0),
            "{integrator}: merged mean |L - 2| {} not below the shards' {} and {}",
            em.0,
            ea.0,
            eb.0
        );
    }
    // Parts of differently set runs are not averaged.
    let c = dir.join("pssmlt-c.exr");
    ok(&[
        "render",
        s(&scene),
        "--integrator",
        "pssmlt",
        "--spp",
        "256",
        "--seed",
        "4",
        "--sigma",
        "0.05",
        "--shard",
        "2/2",
        "-o",
        s(&c),
        "--quiet",
    ]);
    let err = refused(&[
        "merge",
        s(&dir.join("pssmlt-a.exr")),
        s(&c),
        "-o",
        s(&dir.join("refused.exr")),
    ]);
    assert!(err.contains("settings") && err.contains("0.05"), "{err}");
}

/// Runs a generated batch script with bash, as a Slurm node would (`SLURM_ARRAY_TASK_ID` set
/// for array tasks), and fails the test unless it exits 0.
#[cfg(unix)]
fn run_script(script: &Path, task: Option<u64>) {
    let mut command = std::process::Command::new("bash");
    command.arg(script);
    if let Some(task) = task {
        command.env("SLURM_ARRAY_TASK_ID", task.to_string());
    }
    let o = command.output().expect("bash runs");
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}: {}{}",
        script.display(),
        stdout(&o),
        stderr(&o)
    );
}

#[cfg(unix)]
#[test]
fn slurm_scripts_run_by_hand_merge_into_the_single_render() {
    let dir = temp_dir("shards-slurm");
    let scene = shrunk_scene("cornell_box", 8, &dir.join("scene.ron"));
    let whole = dir.join("whole.exr");
    ok(&[
        "reference",
        s(&scene),
        "--spp",
        "5",
        "-o",
        s(&whole),
        "--quiet",
    ]);
    let job = dir.join("job");
    let merged = dir.join("merged.exr");
    let out = ok(&[
        "slurm",
        "--shards",
        "3",
        "--cpus-per-task",
        "1",
        "-o",
        s(&job),
        "--",
        "reference",
        s(&scene),
        "--spp",
        "5",
        "-o",
        s(&merged),
    ]);
    assert!(out.contains("submit.sh"), "{out}");
    // The array's tasks, then the merge job, without Slurm.
    for task in 1..=3 {
        run_script(&job.join("shards.sbatch"), Some(task));
    }
    run_script(&job.join("merge.sbatch"), None);
    assert_same_bytes(&whole, &merged);

    // More shards than passes, or a command that is not render or reference, are refused
    // before anything is written.
    let err = refused(&[
        "slurm",
        "--shards",
        "6",
        "-o",
        s(&job),
        "--",
        "reference",
        s(&scene),
        "--spp",
        "5",
        "-o",
        s(&merged),
    ]);
    assert!(
        err.contains("more shards than the command's 5 passes"),
        "{err}"
    );
    let err = refused(&[
        "slurm",
        "--shards",
        "2",
        "-o",
        s(&job),
        "--",
        "reference",
        s(&scene),
        "--spp",
        "5",
        "--sampler",
        "halton",
        "-o",
        s(&merged),
    ]);
    assert!(err.contains("the command to shard"), "{err}");
}

/// The generated shard script passes Slurm's signal to the render and, when the signal is the
/// one before the time limit (SIGINT), submits the shard's next job (`--dependency=singleton`,
/// after this one), which resumes from the checkpoint; a cancelled shard (SIGTERM) hands
/// nothing on. `sbatch` is a stand-in that records its arguments.
#[cfg(target_os = "linux")]
#[test]
fn a_shard_script_passes_the_signal_on_and_goes_on_in_a_next_job_only_before_its_limit() {
    use std::os::unix::fs::PermissionsExt;
    let dir = temp_dir("shards-slurm-signal");
    let scene = shrunk_scene("cornell_box", 8, &dir.join("scene.ron"));
    let fake = dir.join("bin");
    std::fs::create_dir_all(&fake).unwrap();
    let sbatch = fake.join("sbatch");
    let recorded = dir.join("sbatch.args");
    std::fs::write(
        &sbatch,
        format!(
            "#!/bin/sh\necho \"$@\" >> '{}'\necho '4242;cluster'\n",
            recorded.display()
        ),
    )
    .unwrap();
    std::fs::set_permissions(&sbatch, std::fs::Permissions::from_mode(0o755)).unwrap();
    let path = format!("{}:{}", fake.display(), std::env::var("PATH").unwrap());
    for (signal, goes_on) in [("INT", true), ("TERM", false)] {
        let job = dir.join(format!("job-{signal}"));
        ok(&[
            "slurm",
            "--shards",
            "2",
            "-o",
            s(&job),
            "--",
            "reference",
            s(&scene),
            // Minutes of work: only the signal ends it in time.
            "--spp",
            "4000000",
            "--threads",
            "1",
            "-o",
            s(&dir.join(format!("ref-{signal}.exr"))),
        ]);
        let script = std::fs::read_to_string(job.join("shards.sbatch")).unwrap();
        let name = script
            .lines()
            .find_map(|l| l.strip_prefix("#SBATCH --job-name="))
            .and_then(|n| n.strip_suffix("-shards"))
            .unwrap()
            .to_string();
        let checkpoint = job.join("parts/part-1.exr.checkpoint");
        let mut child = std::process::Command::new("bash")
            .arg(job.join("shards.sbatch"))
            .env("SLURM_ARRAY_TASK_ID", "1")
            .env("SLURM_JOB_ID", "77")
            .env("PATH", &path)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        crate::common::wait_until(&mut child, "the shard's first checkpoint", || {
            checkpoint.exists()
        });
        let sent = std::process::Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap();
        assert!(sent.success());
        let o = child.wait_with_output().unwrap();
        let out = stdout(&o);
        assert!(out.contains("shard 1/2: exit 130"), "{out}");
        let args = std::fs::read_to_string(&recorded).unwrap_or_default();
        if goes_on {
            assert_eq!(o.status.code(), Some(0), "SIGINT: {}", stderr(&o));
            assert!(out.contains("continues in job 4242"), "{out}");
            let expected = format!(
                "--parsable --array=1 --job-name={name}-shard-1 \
                 --dependency=singleton,afterany:77 {}",
                job.join("shards.sbatch").display()
            );
            assert_eq!(args.trim(), expected, "SIGINT");
        } else {
            assert_eq!(o.status.code(), Some(130), "SIGTERM: {}", stderr(&o));
            assert_eq!(args, "", "SIGTERM: nothing handed on");
        }
        let _ = std::fs::remove_file(&recorded);
    }
    // The merge job waits while a shard's next job is queued: `squeue` (a stand-in) lists
    // one, and the merge submits itself again after it instead of merging.
    let job = dir.join("job-INT");
    let script = std::fs::read_to_string(job.join("shards.sbatch")).unwrap();
    let name = script
        .lines()
        .find_map(|l| l.strip_prefix("#SBATCH --job-name="))
        .and_then(|n| n.strip_suffix("-shards"))
        .unwrap()
        .to_string();
    let squeue = fake.join("squeue");
    std::fs::write(
        &squeue,
        format!("#!/bin/sh\necho '4242 {name}-shard-1'\necho '99 other-shard-1'\n"),
    )
    .unwrap();
    std::fs::set_permissions(&squeue, std::fs::Permissions::from_mode(0o755)).unwrap();
    let o = std::process::Command::new("bash")
        .arg(job.join("merge.sbatch"))
        .env("PATH", &path)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("shards go on in job(s) 4242; the merge follows in job 4242"),
        "{}",
        stdout(&o)
    );
    let args = std::fs::read_to_string(&recorded).unwrap();
    assert_eq!(
        args.trim(),
        format!(
            "--parsable --dependency=afterany:4242 {}",
            job.join("merge.sbatch").display()
        )
    );
    assert!(!dir.join("ref-INT.exr").exists(), "not merged yet");
}
