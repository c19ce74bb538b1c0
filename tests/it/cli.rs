//! The command line: exit codes, clear errors for bad input, and Ctrl-C keeping finished work.

use crate::common::{
    interrupt, spawn, stagelight, stagelight_command, stderr, stdout, temp_dir, wait_for_progress,
};

#[test]
fn zero_samples_is_a_clear_error() {
    let o = stagelight(&["render", "scenes/cornell_box.ron", "--spp", "0"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--spp"), "{}", stderr(&o));
}

#[test]
fn non_positive_time_is_a_clear_error() {
    let o = stagelight(&["render", "scenes/cornell_box.ron", "--time=-3"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("positive"), "{}", stderr(&o));
}

#[test]
fn missing_scene_names_the_file() {
    let o = stagelight(&["render", "scenes/no_such_scene.ron"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("no_such_scene.ron"), "{}", stderr(&o));
}

#[test]
fn malformed_scene_names_file_and_line() {
    let dir = temp_dir("cli-malformed");
    let scene = dir.join("broken.ron");
    std::fs::write(&scene, "Scene(\n  camera: (\n    position: (0, 0, 0),,\n").unwrap();
    let o = stagelight(&["render", scene.to_str().unwrap(), "--spp", "1"]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.contains("broken.ron:3"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn diff_of_different_sizes_is_an_error_and_of_itself_is_zero() {
    let dir = temp_dir("cli-diff");
    let (a, b) = (dir.join("a.exr"), dir.join("b.exr"));
    stagelight::film::Image::new(4, 4).write_exr(&a).unwrap();
    stagelight::film::Image::new(4, 5).write_exr(&b).unwrap();
    let o = stagelight(&["diff", a.to_str().unwrap(), b.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("size"), "{}", stderr(&o));
    let o = stagelight(&["diff", a.to_str().unwrap(), a.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0));
    assert!(stdout(&o).contains("relMSE  0.000000e0"));
}

#[test]
fn render_writes_exr_and_png_and_reports() {
    let dir = temp_dir("cli-render");
    let out = dir.join("cb.exr");
    let o = stagelight(&[
        "render",
        "scenes/cornell_box.ron",
        "--spp",
        "2",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let report = stdout(&o);
    for line in [
        "samples/s",
        "closest-hit rays",
        "shadow rays",
        "NaN/Inf samples",
        "bytes/path",
    ] {
        assert!(report.contains(line), "report lacks {line}: {report}");
    }
    // The Cornell box is all diffuse: the report's systems say so.
    assert!(report.contains("shade_diffuse") && !report.contains("shade_dielectric"));
    let image = stagelight::film::Image::read_exr(&out).unwrap();
    assert_eq!((image.width, image.height), (256, 256));
    assert!(out.with_extension("png").exists());
}

#[test]
fn ctrl_c_saves_the_finished_passes_and_exits_130() {
    ctrl_c_case("pt");
}

#[test]
fn ctrl_c_saves_the_finished_photon_passes_and_exits_130() {
    ctrl_c_case("sppm");
}

fn ctrl_c_case(integrator: &str) {
    let dir = temp_dir(&format!("cli-sigint-{integrator}"));
    let out = dir.join("long.exr");
    let mut child = spawn(
        stagelight_command()
            .args([
                "render",
                "scenes/cornell_box.ron",
                "--integrator",
                integrator,
                "--spp",
                "1000000",
                "--threads",
                "2",
                "--quiet",
                "-o",
            ])
            .arg(&out),
    );
    // The stop drops the pass in flight (sppm: between chunks of photons), so the image has
    // some once the first has finished: loading and setting up take a fraction of a CPU
    // second (a whole 4-spp render of this scene about 0.5 s). Two threads keep idle workers
    // from adding CPU time without progress.
    wait_for_progress(&mut child, 3.0);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    let report = stdout(&o);
    assert!(report.contains("interrupted: saved the"), "{report}");
    let image = stagelight::film::Image::read_exr(&out).expect("the finished passes were written");
    let mean = image.channel_means();
    assert!(mean.x > 0.0 && mean.x.is_finite());
}

/// Path-space MLT stopped mid-run writes the steps its chains finished, normalised by them:
/// with direct light kept in the chains, the image's mean luminance is the bootstrap's b
/// whatever the number of steps, so an image scaled by the steps asked for (or by a step
/// count other than the one splatted) fails.
#[test]
fn ctrl_c_saves_the_finished_metropolis_steps_normalised_by_them() {
    let dir = temp_dir("cli-sigint-mlt");
    let scene = crate::common::shrunk_scene("cornell_box", 32, &dir.join("cb.ron"));
    let out = dir.join("long.exr");
    let mut child = spawn(
        stagelight_command()
            .arg("render")
            .arg(&scene)
            .args([
                "--integrator",
                "mlt",
                "--direct-spp",
                "0",
                "--spp",
                "100000000",
                "--threads",
                "2",
                "--quiet",
                "-o",
            ])
            .arg(&out),
    );
    // The bootstrap of a 32x32 image takes a fraction of a CPU second.
    wait_for_progress(&mut child, 2.0);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    let report = stdout(&o);
    assert!(report.contains("interrupted: saved the"), "{report}");
    let b: f64 = report
        .split("b = ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|v| v.trim_end_matches(',').parse().ok())
        .unwrap_or_else(|| panic!("no b in the report: {report}"));
    let image = stagelight::film::Image::read_exr(&out).expect("the finished steps were written");
    let m = image.channel_means();
    let mean = 0.2126 * m.x + 0.7152 * m.y + 0.0722 * m.z;
    assert!(
        b > 0.0 && (mean / b - 1.0).abs() < 1e-3,
        "mean {mean}, b {b}"
    );
}

#[test]
fn bdpt_writes_the_image_and_one_image_per_strategy() {
    let dir = temp_dir("cli-bdpt");
    let out = dir.join("cb.exr");
    let strategies = dir.join("strategies");
    let o = stagelight(&[
        "render",
        "scenes/cornell_box.ron",
        "--integrator",
        "bdpt",
        "--spp",
        "1",
        "--max-depth",
        "2",
        "--mis",
        "balance",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
        "--strategy-images",
        strategies.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let report = stdout(&o);
    assert!(report.contains("with bdpt") && report.contains("connect_strategies"));
    assert!(out.exists() && out.with_extension("png").exists());
    // Depth 2: paths of 2 to 4 vertices; every strategy that can carry light has its image.
    for name in [
        "s0_t2", "s1_t1", "s0_t3", "s1_t2", "s2_t1", "s1_t3", "s2_t2", "s3_t1",
    ] {
        let path = strategies.join(format!("{name}.exr"));
        assert!(path.exists(), "{} missing", path.display());
    }
    assert!(!strategies.join("s0_t5.exr").exists());
}

#[test]
fn strategy_images_need_bdpt() {
    let o = stagelight(&[
        "render",
        "scenes/cornell_box.ron",
        "--spp",
        "1",
        "--strategy-images",
        "/tmp/never-written",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--strategy-images needs --integrator bdpt"));
}

#[test]
fn metropolis_and_photon_options_are_refused_by_integrators_that_do_not_read_them() {
    for (command, integrator, flag, value, takers) in [
        ("render", "pt", "--direct-spp", "4", "pssmlt, mmlt, mlt"),
        ("render", "bdpt", "--chains", "300", "pssmlt, mmlt, mlt"),
        ("render", "mlt", "--sigma", "0.01", "pssmlt, mmlt"),
        ("render", "mmlt", "--lens-min", "0.2", "mlt"),
        ("render", "pt", "--photons-per-pass", "1000", "ppm, sppm"),
        ("render", "bdpt", "--radius", "0.1", "vcm, bpm, ppm, sppm"),
        ("render", "sppm", "--k", "8", "pm"),
        ("render", "pm", "--eye-rays", "4", "ppm"),
        ("render", "vcm", "--photons", "1000", "pm"),
        ("reference", "pt", "--alpha", "0.5", "vcm, bpm, ppm, sppm"),
        ("reference", "ppm", "--max-radius", "1", "pm"),
    ] {
        let o = stagelight(&[
            command,
            "scenes/cornell_box.ron",
            "--integrator",
            integrator,
            "--spp",
            "1",
            flag,
            value,
            "-o",
            "/tmp/never-written.exr",
        ]);
        assert_eq!(o.status.code(), Some(1), "{command} {integrator} {flag}");
        let want = format!("{flag} is not an option of {integrator}: it is {takers}'s");
        assert!(stderr(&o).contains(&want), "{}", stderr(&o));
    }
}

#[test]
fn photon_mappers_render_and_report_their_photons() {
    let dir = temp_dir("cli-photon-mappers");
    for (integrator, extra) in [
        ("sppm", ["--photons-per-pass", "20000"]),
        ("ppm", ["--photons-per-pass", "20000"]),
        ("pm", ["--photons", "20000"]),
    ] {
        let out = dir.join(format!("{integrator}.exr"));
        let mut args = vec![
            "render",
            "scenes/torus_glass.ron",
            "--integrator",
            integrator,
        ];
        args.extend(["--passes", "2", "--quiet", "-o", out.to_str().unwrap()]);
        args.extend(extra);
        let o = stagelight(&args);
        assert_eq!(o.status.code(), Some(0), "{integrator}: {}", stderr(&o));
        let report = stdout(&o);
        assert!(
            report.contains("photons/s") && report.contains("passes/s"),
            "{report}"
        );
        assert!(report.contains("emit_photons"), "{report}");
        assert!(out.exists() && out.with_extension("png").exists());
    }
}

#[test]
fn photon_mapper_options_are_checked() {
    for (args, message) in [
        (
            vec!["--integrator", "sppm", "--alpha", "1.5"],
            "alpha must be a number in (0, 1)",
        ),
        (
            vec!["--integrator", "ppm", "--radius", "0"],
            "the radius must be a positive number",
        ),
        (vec!["--integrator", "pm", "--k", "0"], "--k"),
        (vec!["--integrator", "pm", "--k", "1"], "--k"),
        (vec!["--integrator", "pm", "--photons", "0"], "--photons"),
    ] {
        let mut all = vec!["render", "scenes/cornell_box.ron"];
        all.extend(args);
        let o = stagelight(&all);
        assert_eq!(o.status.code(), Some(1), "{all:?}");
        assert!(stderr(&o).contains(message), "{all:?}: {}", stderr(&o));
    }
    let o = stagelight(&[
        "reference",
        "scenes/cornell_box.ron",
        "--integrator",
        "pssmlt",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("needs an integrator that resumes"),
        "{}",
        stderr(&o)
    );
}

/// A second Ctrl-C ends the process at once, with 130, where the first waits for the pass in
/// flight: pssmlt stops between passes, and its bootstrap (sized here to take minutes) is part
/// of its first. The message is the second signal's own, so the test fails if the first signal
/// ended the process or the second was ignored. Any output left is whole.
#[test]
fn a_second_ctrl_c_ends_the_process_at_once() {
    let dir = temp_dir("cli-second-sigint");
    let scene = crate::common::shrunk_scene("cornell_box", 16, &dir.join("cb.ron"));
    let out = dir.join("long.exr");
    let mut child = spawn(
        stagelight_command()
            .args(["render"])
            .arg(&scene)
            .args([
                "--integrator",
                "pssmlt",
                "--spp",
                "4",
                "--bootstrap",
                "100000000",
                "--threads",
                "2",
                "--quiet",
                "-o",
            ])
            .arg(&out),
    );
    wait_for_progress(&mut child, 1.0);
    let signal = |child: &std::process::Child| {
        let sent = std::process::Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(sent.success());
    };
    signal(&child);
    std::thread::sleep(std::time::Duration::from_millis(300));
    signal(&child);
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("second stop signal: ending now"),
        "{}",
        stderr(&o)
    );
    if out.exists() {
        stagelight::film::Image::read_exr(&out).expect("a whole EXR or none");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A stop inside a photon pass drops that pass: PPM's first pass made slow on purpose (a
/// radius that takes in every photon: its gather, in chunks of 8,192 points, takes tens of
/// seconds) is stopped between chunks of its gather, nothing is written and the exit is 130.
/// Were the stop to wait for the pass, its image would be written ("saved the 1 finished
/// passes").
#[test]
fn ctrl_c_inside_a_long_photon_pass_drops_it() {
    let dir = temp_dir("cli-sigint-in-pass");
    let scene = crate::common::shrunk_scene("door_ajar", 48, &dir.join("door.ron"));
    let out = dir.join("long.exr");
    let mut child = spawn(
        stagelight_command()
            .args(["render"])
            .arg(&scene)
            .args([
                "--integrator",
                "ppm",
                "--radius",
                "50",
                "--photons-per-pass",
                "50000",
                "--spp",
                "2",
                "--threads",
                "2",
                "--quiet",
                "-o",
            ])
            .arg(&out),
    );
    // Past the eye rays and the photons (a fraction of a CPU second at 48 x 48), into the
    // gather.
    wait_for_progress(&mut child, 3.0);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    let report = stdout(&o);
    assert!(
        report.contains("before the first pass finished"),
        "{report}"
    );
    assert!(!out.exists(), "nothing is written for no finished pass");
    let _ = std::fs::remove_dir_all(&dir);
}

/// SPPM stopped inside a pass keeps exactly its finished passes: the image is byte for byte
/// the uninterrupted render of that many passes (a pass's photons or direct light left in the
/// estimates would change it).
#[test]
fn sppm_stopped_inside_a_pass_equals_the_render_of_its_finished_passes() {
    let dir = temp_dir("cli-sigint-sppm-exact");
    let scene = crate::common::shrunk_scene("cornell_box", 32, &dir.join("cb.ron"));
    let run = |spp: &str, out: &std::path::Path| {
        let mut command = stagelight_command();
        command
            .arg("render")
            .arg(&scene)
            // Most of a pass is its photons and its gather, both with stop points: a stop
            // mostly lands inside a pass.
            .args([
                "--integrator",
                "sppm",
                "--photons-per-pass",
                "300000",
                "--radius",
                "2",
            ])
            .args(["--spp", spp, "--threads", "2", "--quiet", "-o"])
            .arg(out);
        command
    };
    let stopped = dir.join("stopped.exr");
    let mut child = spawn(&mut run("1000000", &stopped));
    wait_for_progress(&mut child, 4.0);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    let report = stdout(&o);
    let passes: u64 = report
        .split("saved the ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no finished passes in {report}"));
    assert!(passes >= 1);
    let whole = dir.join("whole.exr");
    let o = run(&passes.to_string(), &whole)
        .output()
        .expect("stagelight runs");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::read(&stopped).unwrap() == std::fs::read(&whole).unwrap(),
        "{passes} passes: the stopped render differs from the uninterrupted one"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
