//! Speed against error: the error measures, the compare command's report folder, and its
//! clear errors for bad input. Tiny images and sample budgets keep it fast and independent of
//! the machine's speed.

use crate::common::{
    interrupt, shrunk_scene, spawn, stagelight, stagelight_command, stderr, temp_dir,
    wait_for_progress,
};
use glam::Vec3;
use stagelight::compare::report::CSV_HEADER;
use stagelight::film::Image;
use stagelight::metrics::{MetricsError, compare};
use std::path::{Path, PathBuf};

/// The Cornell box at `size` x `size`, written into `dir`.
fn tiny_cornell(dir: &Path, size: u32) -> PathBuf {
    shrunk_scene("cornell_box", size, &dir.join("tiny_cornell.ron"))
}

/// A smooth test image with values from dark to bright.
fn ramp(w: usize, h: usize) -> Image {
    let mut img = Image::new(w, h);
    for (i, p) in img.pixels.iter_mut().enumerate() {
        let t = i as f32 / (w * h) as f32;
        *p = Vec3::new(0.02 + 2.0 * t, 0.5 * t, 1.0 - 0.9 * t);
    }
    img
}

#[test]
fn relmse_of_an_image_against_itself_is_zero() {
    let r = ramp(7, 5);
    let m = compare(&r, &r).unwrap();
    assert_eq!((m.relmse, m.rmse, m.mae), (0.0, 0.0, 0.0));
}

#[test]
fn relmse_of_a_known_perturbation_is_the_analytic_value() {
    // x = r (1 + e) with e varying per pixel and channel: relMSE = mean e^2 r^2 / (r^2 + 0.01).
    let r = ramp(16, 9);
    let mut x = r.clone();
    let mut expected = 0.0f64;
    let mut n = 0.0;
    for (i, (xp, rp)) in x.pixels.iter_mut().zip(&r.pixels).enumerate() {
        for c in 0..3 {
            let e = 0.3 * ((i * 3 + c) as f64 * 0.7).sin();
            let rv = rp[c] as f64;
            xp[c] = (rv * (1.0 + e)) as f32;
            // The image holds f32: the expected value uses the stored difference exactly.
            let d = xp[c] as f64 - rv;
            expected += d * d / (rv * rv + 0.01);
            let analytic = e * e * rv * rv / (rv * rv + 0.01);
            assert!((d * d / (rv * rv + 0.01) - analytic).abs() < 1e-6);
            n += 1.0;
        }
    }
    let m = compare(&x, &r).unwrap();
    assert!(
        (m.relmse - expected / n).abs() <= 1e-12 * (expected / n),
        "{} against {}",
        m.relmse,
        expected / n
    );
}

#[test]
fn nan_or_inf_in_either_image_is_an_error() {
    let r = ramp(4, 4);
    let mut bad = r.clone();
    bad.pixels[5].z = f32::NAN;
    assert_eq!(
        compare(&bad, &r),
        Err(MetricsError::NonFinite {
            which: "image",
            x: 1,
            y: 1
        })
    );
    assert!(matches!(
        compare(&r, &bad),
        Err(MetricsError::NonFinite {
            which: "reference",
            ..
        })
    ));
    let mut inf = r.clone();
    inf.pixels[0].x = f32::INFINITY;
    assert!(compare(&r, &inf).is_err());
}

#[test]
fn integrator_names_are_parsed_with_clear_errors() {
    use stagelight::integrators::{IntegratorKind, IntegratorNameError};
    assert_eq!(
        IntegratorKind::from_name("pt"),
        Ok(IntegratorKind::named("pt"))
    );
    assert_eq!(
        IntegratorKind::from_name("PT"),
        Ok(IntegratorKind::named("pt"))
    );
    assert_eq!(
        IntegratorKind::from_name("bdpt"),
        Ok(IntegratorKind::named("bdpt"))
    );
    assert_eq!(
        IntegratorKind::from_name("mlt"),
        Ok(IntegratorKind::named("mlt"))
    );
    let unknown = IntegratorKind::from_name("foo").unwrap_err();
    assert!(matches!(unknown, IntegratorNameError::Unknown(_)));
    assert!(unknown.to_string().contains("foo"), "{unknown}");
    assert!(unknown.to_string().contains("bdpt"), "{unknown}");
    for kind in IntegratorKind::all() {
        assert_eq!(IntegratorKind::from_name(kind.as_str()), Ok(kind));
    }
}

#[test]
fn compare_writes_every_report_file_and_pt_error_falls_with_samples() {
    let dir = temp_dir("compare-report");
    let scene = tiny_cornell(&dir, 32);
    let out = dir.join("report");
    let o = stagelight(&[
        "compare",
        scene.to_str().unwrap(),
        "--integrators",
        "pt",
        "--budgets",
        "2,8,32,128",
        "--budget-unit",
        "spp",
        "--reference-spp",
        "2048",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for file in [
        "results.csv",
        "error_vs_time.png",
        "error_vs_time.svg",
        "grid.png",
        "summary.md",
        "reference.exr",
        "reference.exr.checkpoint",
    ] {
        let path = out.join(file);
        let len = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        assert!(len > 0, "{} is missing or empty", path.display());
    }
    // The reference made on the way says what it is.
    let attributes =
        stagelight::reference::reference_attributes(&out.join("reference.exr")).unwrap();
    assert_eq!(attributes.get("spp").map(String::as_str), Some("2048"));

    let mut reader = csv::Reader::from_path(out.join("results.csv")).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(header, CSV_HEADER);
    let column = |name: &str| header.iter().position(|h| h == name).unwrap();
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    assert_eq!(rows.len(), 4);
    let points: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| {
            assert_eq!(&r[column("integrator")], "pt");
            let passes: f64 = r[column("passes")].parse().unwrap();
            let relmse: f64 = r[column("relmse")].parse().unwrap();
            let eff: f64 = r[column("efficiency")].parse().unwrap();
            assert!(relmse > 0.0 && eff > 0.0);
            (passes, relmse)
        })
        .collect();
    assert_eq!(
        points.iter().map(|p| p.0).collect::<Vec<_>>(),
        [2.0, 8.0, 32.0, 128.0]
    );
    // Four times the samples each step: the error of an unbiased estimator falls about
    // fourfold (measured ratios 0.18 to 0.37 over seeds); allow a wide margin for the noise
    // of the error estimate itself. (One spp is left out: its error is heavy-tailed.)
    for w in points.windows(2) {
        assert!(w[1].1 < 0.6 * w[0].1, "relMSE did not fall: {points:?}");
    }
    let slope = stagelight::compare::fit_log_slope(&points).unwrap();
    assert!((-1.4..=-0.6).contains(&slope), "slope {slope}: {points:?}");

    let summary = std::fs::read_to_string(out.join("summary.md")).unwrap();
    for part in [
        "## Equal time",
        "## Equal quality",
        "## Convergence",
        "error_vs_time.png",
        "grid.png",
        "reference.exr",
    ] {
        assert!(summary.contains(part), "summary lacks {part}:\n{summary}");
    }
    let svg = std::fs::read_to_string(out.join("error_vs_time.svg")).unwrap();
    assert!(
        svg.contains("pt (slope"),
        "the legend names pt and its slope"
    );

    // A second run reuses the finished reference instead of rendering it again.
    let o = stagelight(&[
        "compare",
        scene.to_str().unwrap(),
        "--budgets",
        "1,2",
        "--budget-unit",
        "spp",
        "--reference-spp",
        "2048",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("already complete"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_seconds_budget_comparison_reports_its_runs() {
    // Only what does not depend on the machine's speed is checked.
    let dir = temp_dir("compare-seconds");
    let scene = tiny_cornell(&dir, 8);
    let reference = dir.join("ref.exr");
    let o = stagelight(&[
        "reference",
        scene.to_str().unwrap(),
        "--spp",
        "64",
        "--quiet",
        "-o",
        reference.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = dir.join("report");
    let o = stagelight(&[
        "compare",
        scene.to_str().unwrap(),
        "--reference",
        reference.to_str().unwrap(),
        "--budgets",
        "0.05,0.1",
        "--integrators",
        "pt",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let mut reader = csv::Reader::from_path(out.join("results.csv")).unwrap();
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    assert_eq!(rows.len(), 2);
    assert_eq!(&rows[0][2], "seconds");
    let summary = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(summary.contains("given with --reference"), "{summary}");
    let _ = std::fs::remove_dir_all(&dir);
}

fn expect_clear_error(args: &[&str], needles: &[&str]) {
    let o = stagelight(args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    for needle in needles {
        assert!(
            err.contains(needle),
            "{args:?}: message lacks {needle:?}: {err}"
        );
    }
}

#[test]
fn bad_input_gives_one_clear_message_and_exit_1() {
    let dir = temp_dir("compare-bad");
    let scene = tiny_cornell(&dir, 8);
    let scene = scene.to_str().unwrap();

    // A reference of another size, named in the message with both sizes.
    let small = dir.join("small_ref.exr");
    Image::new(4, 4).write_exr(&small).unwrap();
    let small = small.to_str().unwrap();
    expect_clear_error(
        &[
            "compare",
            scene,
            "--reference",
            small,
            "--budgets",
            "1",
            "--budget-unit",
            "spp",
        ],
        &["small_ref.exr", "4x4", "8x8"],
    );

    // A reference with NaN.
    let nan = dir.join("nan_ref.exr");
    let mut image = Image::new(8, 8);
    image.pixels[10] = Vec3::new(0.5, f32::NAN, 0.5);
    image.write_exr(&nan).unwrap();
    let nan = nan.to_str().unwrap();
    expect_clear_error(
        &[
            "compare",
            scene,
            "--reference",
            nan,
            "--budgets",
            "1",
            "--budget-unit",
            "spp",
        ],
        &["nan_ref.exr", "NaN", "(2, 1)"],
    );

    // Integrator names: unknown.
    expect_clear_error(
        &["compare", scene, "--integrators", "pt,foo"],
        &["unknown integrator \"foo\""],
    );
    expect_clear_error(
        &["reference", scene, "--integrator", "warp"],
        &["unknown integrator"],
    );

    // Budget lists: empty, not increasing, repeated, not whole samples.
    expect_clear_error(&["compare", scene, "--budgets", ""], &["empty"]);
    expect_clear_error(
        &["compare", scene, "--budgets", "4,2"],
        &["strictly increasing"],
    );
    expect_clear_error(
        &["compare", scene, "--budgets", "1,1"],
        &["strictly increasing"],
    );
    expect_clear_error(
        &["compare", scene, "--budgets", "1.5", "--budget-unit", "spp"],
        &["whole number"],
    );
    expect_clear_error(&["compare", scene, "--budgets", "1,-2"], &["positive"]);

    // diff of images with NaN names the problem.
    let clean = dir.join("clean.exr");
    Image::new(8, 8).write_exr(&clean).unwrap();
    expect_clear_error(&["diff", clean.to_str().unwrap(), nan], &["NaN"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_thesis_tables_hold_the_studys_seconds_beside_ours() {
    use stagelight::compare::thesis::{SCENES, SceneResult, summary_markdown};
    let scenes: Vec<SceneResult> = SCENES
        .iter()
        .map(|(key, _)| SceneResult {
            key,
            comparison: None,
        })
        .collect();
    let md = summary_markdown(
        &scenes,
        2,
        &stagelight::compare::thesis::PHOTONS_PER_PASS,
        None,
    );
    assert!(md.contains("## Unbiased algorithms, by samples per pixel"));
    assert!(md.contains("## Biased algorithms, by photons per pass"));
    assert!(md.contains("| 25 spp: s | thesis s | relMSE |"), "{md}");
    // The thesis' own figures sit beside ours: MLT on the room took 38 s at 841 spp.
    assert!(
        md.contains("| room | MLT | not run | 4 | | not run | 20 | | not run | 38 | |"),
        "{md}"
    );
    assert!(md.contains("| Cornell box | PPM, 75 passes |"), "{md}");
    assert!(!md.contains("Not built yet"), "{md}");
}

#[test]
fn the_thesis_preset_runs_on_shrunken_scenes_and_fills_its_tables() {
    // The preset's real scenes at 256x256 take minutes; the same files at 8x8 take a second
    // and exercise every step: references, runs, per-scene folders, the study's tables.
    let dir = temp_dir("compare-thesis");
    let scenes = dir.join("scenes");
    std::fs::create_dir_all(&scenes).unwrap();
    for name in ["cornell_box", "torus_glass", "door_ajar"] {
        shrunk_scene(name, 8, &scenes.join(format!("{name}.ron")));
    }
    let out = dir.join("thesis");
    let o = stagelight(&[
        "compare",
        "--preset",
        "thesis",
        "--scenes-dir",
        scenes.to_str().unwrap(),
        "--reference-spp",
        "256",
        "--thesis-photons",
        "2000,4000",
        // At 8x8 the default radius, 1.5 pixel footprints, spans the scenes: VCM and BPM
        // then merge every camera vertex with every light vertex (minutes). About twice a
        // 256-px render's radius on torus_glass and door_ajar keeps the merges local.
        "--radius",
        "0.05",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for name in ["cornell_box", "torus_glass", "door_ajar"] {
        for file in [
            "summary.md",
            "results.csv",
            "grid.png",
            "error_vs_time.png",
            "reference.exr",
        ] {
            assert!(out.join(name).join(file).exists(), "{name}/{file} missing");
        }
    }
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    // PT has our seconds and relMSE beside the thesis' 1, 17 and 37 s; MLT is path-space mlt.
    let pt_row = md
        .lines()
        .find(|l| l.starts_with("| Cornell box | PT |"))
        .expect("a PT row");
    let cells: Vec<&str> = pt_row.split('|').map(str::trim).collect();
    assert_eq!(
        (cells[4], cells[7], cells[10]),
        ("1", "17", "37"),
        "{pt_row}"
    );
    assert!(
        !pt_row.contains("missing") && !pt_row.contains("not run"),
        "{pt_row}"
    );
    assert!(cells[5].parse::<f64>().is_ok(), "relMSE cell: {pt_row}");
    let mlt_row = md
        .lines()
        .find(|l| l.starts_with("| room | MLT |"))
        .expect("an MLT row");
    assert!(!mlt_row.contains("missing"), "{mlt_row}");
    let bdpt_row = md
        .lines()
        .find(|l| l.starts_with("| room | BDPT |"))
        .expect("a BDPT row");
    assert!(!bdpt_row.contains("missing"), "{bdpt_row}");
    // VCM and BPM, which the study did not have, run at its samples per pixel beside it.
    for row in ["| torus | VCM |", "| room | BPM |"] {
        let line = md.lines().find(|l| l.starts_with(row)).expect(row);
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        assert!(cells[3].parse::<f64>().is_ok(), "seconds cell: {line}");
        assert_eq!(cells[4], "", "no thesis seconds: {line}");
        assert!(cells[5].parse::<f64>().is_ok(), "relMSE cell: {line}");
    }
    // The biased rows have our seconds and relMSE at the photon budgets asked for, and no
    // thesis seconds (it measured 250k and 500k only).
    assert!(
        md.contains("| 2k photons/pass: s | thesis s | relMSE |"),
        "{md}"
    );
    for row in [
        "| torus | PM |",
        "| torus | PPM, 3 passes |",
        "| room | PPM, 75 passes |",
    ] {
        let line = md.lines().find(|l| l.starts_with(row)).expect(row);
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        assert!(cells[3].parse::<f64>().is_ok(), "seconds cell: {line}");
        assert_eq!(cells[4], "", "no thesis seconds at 2k: {line}");
        assert!(cells[5].parse::<f64>().is_ok(), "relMSE cell: {line}");
    }
    // The report pages: one over the scenes, and one per scene with every run (named by the
    // study's rows) and the reference, their floats beside it and their EXRs in runs/.
    let index = std::fs::read_to_string(out.join("index.html")).unwrap();
    for name in ["cornell_box", "torus_glass", "door_ajar"] {
        assert!(
            index.contains(&format!("href=\"{name}/index.html\"")),
            "{index}"
        );
        let page = std::fs::read_to_string(out.join(name).join("index.html")).unwrap();
        assert!(page.contains("href=\"../index.html\""), "no link back");
        for entry in [
            r#""method":"PT","group":"25 spp""#,
            r#""method":"PPM, 75 passes","group":"4k photons""#,
            r#""method":"PM","group":"2k photons""#,
        ] {
            assert!(page.contains(entry), "{name}: no {entry}");
        }
        let count = |folder: &str| {
            std::fs::read_dir(out.join(name).join(folder))
                .unwrap()
                .count()
        };
        assert_eq!((count("index_data"), count("runs")), (22, 21), "{name}");
    }
    let mut reader = csv::Reader::from_path(out.join("results.csv")).unwrap();
    assert_eq!(&reader.headers().unwrap()[0], "scene");
    assert_eq!(
        reader.records().count(),
        63,
        "3 scenes x (PT, BDPT, MLT, VCM and BPM at 3 budgets + PM, PPM 3 and PPM 75 at 2 photon \
         budgets)"
    );

    // Given references: a folder without them is refused before any run, naming the file;
    // with them (the made ones copied, the Cornell box's with two halves) the preset uses
    // them and reports the halves' noise.
    let given = dir.join("given");
    std::fs::create_dir_all(&given).unwrap();
    let preset_with = |references: &Path, out: &Path| {
        stagelight(&[
            "compare",
            "--preset",
            "thesis",
            "--scenes-dir",
            scenes.to_str().unwrap(),
            "--references",
            references.to_str().unwrap(),
            "--thesis-photons",
            "2000",
            // As above: local merges for VCM and BPM at 8x8.
            "--radius",
            "0.05",
            "--quiet",
            "-o",
            out.to_str().unwrap(),
        ])
    };
    let o = preset_with(&given, &dir.join("refused"));
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("cornell_box.exr: no such reference"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("refused").exists());
    for name in ["cornell_box", "torus_glass", "door_ajar"] {
        let made = out.join(name).join("reference.exr");
        std::fs::copy(&made, given.join(format!("{name}.exr"))).unwrap();
    }
    let cornell = Image::read_exr(&given.join("cornell_box.exr")).unwrap();
    let mut brighter = cornell.clone();
    for p in &mut brighter.pixels {
        *p *= 1.5;
    }
    cornell.write_exr(&given.join("cornell_box.a.exr")).unwrap();
    brighter
        .write_exr(&given.join("cornell_box.b.exr"))
        .unwrap();
    let out_given = dir.join("thesis-given");
    let o = preset_with(&given, &out_given);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!out_given.join("cornell_box").join("reference.exr").exists());
    let md = std::fs::read_to_string(out_given.join("summary.md")).unwrap();
    let noise_line = md
        .lines()
        .find(|l| l.contains("two halves"))
        .unwrap_or_else(|| panic!("no noise line: {md}"));
    // Halves r and 1.5 r: the noise is the mean of (r / 4)^2 / (r^2 + 0.01), above zero.
    assert!(
        noise_line.contains("Cornell box") && !noise_line.contains("torus"),
        "{noise_line}"
    );

    // The same preset as 5 tasks of a plan (each with its own thread count) reports the
    // figures of one machine: every run's relMSE and image means in each scene's results.csv
    // and the study's, and every cell of the study's tables but our seconds.
    let job = dir.join("job");
    let sharded = dir.join("thesis-sharded");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let o = stagelight(&[
        "slurm",
        "--shards",
        "5",
        "-o",
        &s(&job),
        "--",
        "compare",
        "--preset",
        "thesis",
        "--scenes-dir",
        &s(&scenes),
        "--references",
        &s(&given),
        "--thesis-photons",
        "2000",
        "--radius",
        "0.05",
        "-o",
        &s(&sharded),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let plan = s(&job.join("plan.ron"));
    for task in 1..=5 {
        let shard = format!("{task}/5");
        let threads = (task % 3 + 1).to_string();
        let o = stagelight(&[
            "compare",
            "--plan",
            &plan,
            "--shard",
            &shard,
            "--threads",
            &threads,
            "--quiet",
        ]);
        assert_eq!(o.status.code(), Some(0), "task {task}: {}", stderr(&o));
    }
    let o = stagelight(&["compare", "--plan", &plan]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for name in ["cornell_box", "torus_glass", "door_ajar"] {
        assert_eq!(
            untimed_figures(&out_given.join(name).join("results.csv")),
            untimed_figures(&sharded.join(name).join("results.csv")),
            "{name}"
        );
    }
    let all = untimed_figures(&out_given.join("results.csv"));
    assert_eq!(all.len(), 3 * (15 + 3));
    assert_eq!(all, untimed_figures(&sharded.join("results.csv")));
    let (a, b) = (
        std::fs::read_to_string(out_given.join("summary.md")).unwrap(),
        std::fs::read_to_string(sharded.join("summary.md")).unwrap(),
    );
    let rows = |md: &str| -> Vec<Vec<String>> {
        md.lines()
            .filter(|l| l.starts_with("| ") && !l.starts_with("| scene"))
            .map(|l| {
                l.split('|')
                    .enumerate()
                    .filter(|(i, _)| ![3, 6, 9].contains(i))
                    .map(|(_, c)| c.trim().to_string())
                    .collect()
            })
            .collect()
    };
    assert_eq!(rows(&a).len(), 24);
    assert_eq!(rows(&a), rows(&b));
    assert!(b.contains("Rendered as shards by the 5 tasks"), "{b}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ctrl_c_during_a_comparison_writes_the_finished_runs_and_exits_130() {
    let dir = temp_dir("compare-sigint");
    let scene = tiny_cornell(&dir, 8);
    let reference = dir.join("ref.exr");
    Image::new(8, 8).write_exr(&reference).unwrap();
    let out = dir.join("report");
    let mut child = spawn(
        stagelight_command()
            .args(["compare", scene.to_str().unwrap(), "--reference"])
            .arg(&reference)
            .args([
                "--budgets",
                "1,100000000",
                "--budget-unit",
                "spp",
                "--threads",
                "2",
                "--quiet",
                "-o",
            ])
            .arg(&out),
    );
    // The 1-spp run of an 8x8 image takes milliseconds: the stop comes during the long one.
    wait_for_progress(&mut child, 0.5);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    let summary = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(summary.contains("**Interrupted:**"), "{summary}");
    // The run cut short is not reported; the one before it (if it had finished) is.
    let rows = csv::Reader::from_path(out.join("results.csv"))
        .unwrap()
        .records()
        .count();
    assert!(rows <= 1, "{rows} rows");
    assert!(out.join("grid.png").exists() && out.join("error_vs_time.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// results.csv's rows as "column=value" cells, without the columns that time the runs
/// (wall_s, cpu_s, efficiency): what a sharded comparison must reproduce.
fn untimed_figures(csv_path: &Path) -> Vec<Vec<String>> {
    let mut reader = csv::Reader::from_path(csv_path).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    let timed = ["wall_s", "cpu_s", "efficiency"];
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            header
                .iter()
                .zip(r.iter())
                .filter(|(h, _)| !timed.contains(&h.as_str()))
                .map(|(h, v)| format!("{h}={v}"))
                .collect()
        })
        .collect()
}

/// Runs `stagelight`; it must exit 0. Returns its stdout.
#[track_caller]
fn succeeds(args: &[&str]) -> String {
    let o = stagelight(args);
    assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs a generated batch script with bash as a Slurm node would (no Slurm here).
#[cfg(unix)]
fn run_batch_script(script: &Path, task: Option<u64>) -> std::process::Output {
    let mut command = std::process::Command::new("bash");
    command.arg(script);
    if let Some(task) = task {
        command.env("SLURM_ARRAY_TASK_ID", task.to_string());
    }
    command.output().expect("bash runs")
}

#[track_caller]
fn assert_same_bytes(a: &Path, b: &Path) {
    let (x, y) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    assert!(x == y, "{} and {} differ", a.display(), b.display());
}

/// A comparison split by `stagelight slurm` into a plan of 4 tasks, whose tasks run (in any
/// order, as an array would) by the generated script, reports what one machine reports: the
/// reference its shards make is the same file, and every run's relMSE, image means, samples
/// and rays are the same (PT and BDPT from merged shards, PM rendered whole by one task).
#[cfg(unix)]
#[test]
fn a_sharded_comparison_reports_the_figures_of_one_machine() {
    let dir = temp_dir("compare-shards");
    let scene = tiny_cornell(&dir, 12);
    let path = |p: &Path| p.to_str().unwrap().to_string();
    let scene_arg = path(&scene);
    let compare_args = |out: &Path| -> Vec<String> {
        [
            "compare",
            &scene_arg,
            "--integrators",
            "pt,bdpt,pm",
            // 1 shard (fewer than 16 passes each), 3 and 4 shards; the reference 4.
            "--budgets",
            "8,48,80",
            "--budget-unit",
            "spp",
            "--reference-spp",
            "64",
            "--photons",
            "3000",
            "--quiet",
            "-o",
            &path(out),
        ]
        .map(String::from)
        .to_vec()
    };
    let one = dir.join("one");
    let args = compare_args(&one);
    succeeds(&args.iter().map(String::as_str).collect::<Vec<_>>());

    let job = dir.join("job");
    let sharded = dir.join("sharded");
    let mut args = vec!["slurm", "--shards", "4", "-o"]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
    args.push(path(&job));
    args.push("--".into());
    args.extend(compare_args(&sharded));
    let slurm_args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = succeeds(&slurm_args);
    assert!(
        out.contains("plan.ron (1 scene, 9 runs (3 whole, 16 shards) and 1 reference (4 shards))"),
        "{out}"
    );
    // The report before every task has run names what is missing, and its task.
    let o = run_batch_script(&job.join("shards.sbatch"), Some(3));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = run_batch_script(&job.join("merge.sbatch"), None);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("not finished") && stderr(&o).contains("(task 1)"),
        "{}",
        stderr(&o)
    );
    for task in [4, 1, 2] {
        let o = run_batch_script(&job.join("shards.sbatch"), Some(task));
        assert_eq!(o.status.code(), Some(0), "task {task}: {}", stderr(&o));
    }
    // A task run again (Slurm's next job after a stop) finds its shards done.
    let o = run_batch_script(&job.join("shards.sbatch"), Some(2));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("task 2/4: 0 shards rendered"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let o = run_batch_script(&job.join("merge.sbatch"), None);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));

    assert_same_bytes(&one.join("reference.exr"), &sharded.join("reference.exr"));
    let (a, b) = (
        untimed_figures(&one.join("results.csv")),
        untimed_figures(&sharded.join("results.csv")),
    );
    assert_eq!(a.len(), 9);
    assert_eq!(a, b);
    let summary = std::fs::read_to_string(sharded.join("summary.md")).unwrap();
    assert!(
        summary.contains("Rendered as shards by the 4 tasks"),
        "{summary}"
    );

    // A timed comparison is refused: sharding cannot reproduce a run of S seconds.
    let o = stagelight(&[
        "slurm",
        "--shards",
        "2",
        "-o",
        &path(&dir.join("timed")),
        "--",
        "compare",
        &scene_arg,
        "--budgets",
        "1,2",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("a timed (equal-time) comparison cannot be sharded"),
        "{}",
        stderr(&o)
    );
    // A plan that no longer matches its command, or a scene changed since the plan, is
    // refused rather than rendered into shards that do not belong together.
    let plan = job.join("plan.ron");
    let text = std::fs::read_to_string(&plan).unwrap();
    std::fs::write(&plan, text.replacen("passes: 48,", "passes: 47,", 1)).unwrap();
    let o = stagelight(&["compare", "--plan", &path(&plan)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("write the plan again"),
        "{}",
        stderr(&o)
    );
    std::fs::write(&plan, &text).unwrap();
    shrunk_scene("cornell_box", 13, &scene);
    let o = stagelight(&["compare", "--plan", &path(&plan), "--shard", "1/4"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("is not the one planned"),
        "{}",
        stderr(&o)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
