//! `compare --preset thesis`: the experiment of the study stagelight grew from, on this
//! machine, with measured error beside the times.
//!
//! The study: A. Kouhzadi, "A Comprehensive Study of the Seminal Monte Carlo-based Image
//! Synthesis Algorithms", master's thesis, UCLA, 2016. It rendered three scenes at 256x256
//! with Mitsuba 0.5 on an Intel Core i7 at 2.6 GHz (eight logical cores) and reported wall
//! seconds only. The figures below are its tables as quoted in the project's notes on the
//! study (THESIS.md), copied here so the preset needs nothing outside the repository; they keep
//! the thesis' own inconsistencies (PM on the Cornell box at 500k photons in 4 s).

use super::format::{sci, secs};
use super::run::{ComparePlan, SceneRun, compare_scene};
use super::{BudgetUnit, CompareJob, Comparison, RunResult, page, report};
use crate::commands::{exit_code, load_scene, print_out, stop_on_ctrl_c, thread_pool};
use crate::film::Image;
use crate::integrators::{IntegratorKind, MltOptions, PhotonSettings, RenderSettings};
use anyhow::Result;
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// The scenes: (file stem in scenes/, the thesis' name for it).
pub const SCENES: [(&str, &str); 3] = [
    ("cornell_box", "Cornell box"),
    ("torus_glass", "torus"),
    ("door_ajar", "room"),
];

/// Samples per pixel of the unbiased algorithms' runs.
pub const UNBIASED_SPP: [u64; 3] = [25, 400, 841];
/// The unbiased algorithms, by integrator name.
pub const UNBIASED: [&str; 3] = ["pt", "bdpt", "mlt"];
/// Algorithms the study did not have, run at the same samples per pixel beside it: vertex
/// connection and merging and its merges alone (consistent, not unbiased).
pub const SINCE: [&str; 2] = ["vcm", "bpm"];

/// Photons per pass of the biased algorithms' runs.
pub const PHOTONS_PER_PASS: [u64; 2] = [250_000, 500_000];

/// Camera passes (samples per pixel) of PM's runs: each pass shoots one final-gather ray per
/// pixel, so this is also the number of gather rays per pixel.
pub const PM_PASSES: u64 = 16;

/// A biased algorithm of the study: integrator name, passes, row label. PM traces its
/// photons once; PPM traces the given number per pass.
pub const BIASED: [(&str, u64, &str); 3] = [
    ("pm", PM_PASSES, "PM"),
    ("ppm", 3, "PPM, 3 passes"),
    ("ppm", 75, "PPM, 75 passes"),
];

/// The thesis' wall seconds of the unbiased algorithms at 25, 400 and 841 spp.
pub const THESIS_UNBIASED_SECONDS: [(&str, &str, [f64; 3]); 9] = [
    ("cornell_box", "pt", [1.0, 17.0, 37.0]),
    ("cornell_box", "bdpt", [6.0, 92.0, 200.0]),
    ("cornell_box", "mlt", [3.0, 14.0, 27.0]),
    ("torus_glass", "pt", [2.0, 22.0, 47.0]),
    ("torus_glass", "bdpt", [3.0, 49.0, 109.0]),
    ("torus_glass", "mlt", [3.0, 33.0, 69.0]),
    ("door_ajar", "pt", [2.0, 31.0, 67.0]),
    ("door_ajar", "bdpt", [8.0, 138.0, 294.0]),
    ("door_ajar", "mlt", [4.0, 20.0, 38.0]),
];

/// The thesis' wall seconds of the biased algorithms at 250k and 500k photons per pass,
/// keyed by the `BIASED` row label.
pub const THESIS_BIASED_SECONDS: [(&str, &str, [f64; 2]); 9] = [
    ("cornell_box", "PM", [53.0, 4.0]),
    ("cornell_box", "PPM, 3 passes", [2.0, 56.0]),
    ("cornell_box", "PPM, 75 passes", [29.0, 52.0]),
    ("torus_glass", "PM", [54.0, 61.0]),
    ("torus_glass", "PPM, 3 passes", [22.0, 58.0]),
    ("torus_glass", "PPM, 75 passes", [222.0, 438.0]),
    ("door_ajar", "PM", [38.0, 76.0]),
    ("door_ajar", "PPM, 3 passes", [2.0, 4.0]),
    ("door_ajar", "PPM, 75 passes", [35.0, 71.0]),
];

/// The thesis' seconds for an unbiased row.
pub fn thesis_unbiased(scene: &str, integrator: &str) -> Option<[f64; 3]> {
    THESIS_UNBIASED_SECONDS
        .iter()
        .find(|(s, i, _)| *s == scene && *i == integrator)
        .map(|r| r.2)
}

/// The thesis' seconds for a biased row.
pub fn thesis_biased(scene: &str, label: &str) -> Option<[f64; 2]> {
    THESIS_BIASED_SECONDS
        .iter()
        .find(|(s, l, _)| *s == scene && *l == label)
        .map(|r| r.2)
}

/// The integrators run by samples per pixel (the study's unbiased ones, then `SINCE`) this
/// binary has.
pub fn by_spp_built() -> Vec<IntegratorKind> {
    UNBIASED
        .iter()
        .chain(&SINCE)
        .filter_map(|n| IntegratorKind::from_name(n).ok())
        .collect()
}

fn display_name(integrator: &str) -> String {
    integrator.to_ascii_uppercase()
}

fn thousands(photons: u64) -> String {
    format!("{}k", photons / 1000)
}

/// How the report page names a scene's runs: the unbiased ones by integrator and spp, the
/// biased ones by their row of `BIASED` and their photons per pass (the k-th biased run is
/// the k-th of `biased_runs_of`).
pub fn page_labels(c: &Comparison, photon_budgets: &[u64]) -> Vec<page::RunLabel> {
    let mut biased = 0;
    c.results
        .iter()
        .map(|r| {
            if UNBIASED.contains(&r.integrator.as_str()) || SINCE.contains(&r.integrator.as_str()) {
                return page::RunLabel {
                    method: display_name(r.integrator.as_str()),
                    group: format!("{} spp", r.budget),
                };
            }
            let row = BIASED[biased % BIASED.len()].2;
            let photons = photon_budgets
                .get(biased / BIASED.len())
                .map_or("? photons".to_string(), |p| {
                    format!("{} photons", thousands(*p))
                });
            biased += 1;
            page::RunLabel {
                method: row.to_string(),
                group: photons,
            }
        })
        .collect()
}

/// Writes the report of one scene of the preset, its page linking back to the index.
pub(crate) fn write_scene_report(
    c: &Comparison,
    dir: &Path,
    photon_budgets: &[u64],
) -> Result<(), super::ReportError> {
    report::write_report_labelled(
        c,
        dir,
        &page_labels(c, photon_budgets),
        vec![(
            "all scenes".into(),
            format!("../{}", super::files::INDEX_HTML),
        )],
    )
}

/// The preset's index.html: each scene's plot and grid, linking to its page.
pub(crate) fn write_index(out_dir: &Path, scenes: &[SceneResult]) -> Result<()> {
    use crate::viewer::escape_html;
    let mut body = String::new();
    for scene in scenes {
        let label = escape_html(scene_label(scene.key));
        let key = escape_html(scene.key);
        let _ = match scene.comparison {
            Some(c) => writeln!(
                body,
                "<section><h2><a href=\"{key}/{index}\">{label} ({key})</a></h2>\n\
                 <p>{} runs at {}x{}; <a href=\"{key}/{index}\">open its viewer</a>, \
                 <a href=\"{key}/{summary}\">summary.md</a>.</p>\n\
                 <a href=\"{key}/{index}\"><img src=\"{key}/{plot}\" alt=\"relMSE against \
                 time, {label}\"> <img src=\"{key}/{grid}\" alt=\"images and error maps, \
                 {label}\"></a></section>",
                c.results.len(),
                c.width,
                c.height,
                index = super::files::INDEX_HTML,
                summary = super::files::SUMMARY_MD,
                plot = super::files::PLOT_SVG,
                grid = super::files::GRID_PNG,
            ),
            None => writeln!(
                body,
                "<section><h2>{label} ({key})</h2><p>Not run.</p></section>"
            ),
        };
    }
    let html = format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <title>Thesis preset</title>\n<style>\nbody {{ font: 14px/1.4 system-ui, sans-serif; \
         margin: 1rem 2rem; background: #16181c; color: #e4e6ea; }}\na {{ color: #f0a640; }}\n\
         img {{ max-height: 360px; max-width: 48%; vertical-align: top; background: #fff; }}\n\
         </style>\n</head>\n<body>\n<h1>Thesis preset: three scenes</h1>\n<p>Each scene's \
         page has the viewer over all its runs and its reference (flip, error maps, zoom, \
         exposure, pixel readout), its sortable results and its plot. \
         <a href=\"{summary}\">summary.md</a>, <a href=\"{csv}\">results.csv</a>.</p>\n\
         {body}</body>\n</html>\n",
        summary = super::files::SUMMARY_MD,
        csv = super::files::RESULTS_CSV,
    );
    let path = out_dir.join(super::files::INDEX_HTML);
    crate::film::output::write_bytes(&path, html.as_bytes())?;
    Ok(())
}

/// One scene of the preset: its file stem and its comparison (None when it could not run).
pub struct SceneResult<'a> {
    pub key: &'static str,
    pub comparison: Option<&'a Comparison>,
}

/// The preset's summary.md: the study's two tables with our seconds and relMSE beside its
/// seconds.
///
/// `sharded`: a paragraph saying how a sharded run's figures were made (None for one machine).
pub fn summary_markdown(
    scenes: &[SceneResult],
    threads: usize,
    photon_budgets: &[u64],
    sharded: Option<&str>,
) -> String {
    let mut s = String::new();
    let mut sizes: Vec<String> = scenes
        .iter()
        .filter_map(|sc| sc.comparison.map(|c| format!("{}x{}", c.width, c.height)))
        .collect();
    sizes.dedup();
    let size = if sizes.is_empty() {
        "256x256 (the thesis' size)".to_string()
    } else {
        sizes.join(", ")
    };
    let _ = writeln!(s, "# The thesis experiment on this machine\n");
    let _ = writeln!(
        s,
        "The experiment of A. Kouhzadi, \"A Comprehensive Study of the Seminal Monte Carlo-based \
         Image Synthesis Algorithms\" (master's thesis, UCLA, 2016), rerun on stagelight's own \
         scenes at {size} with {threads} threads. The thesis rendered 256x256 images with \
         Mitsuba 0.5 on an Intel Core i7 at 2.6 GHz with eight logical cores and gave wall \
         seconds only; here each run also has its relMSE against a reference of the same scene \
         (see each scene's summary for it). The thesis' figures are printed as it printed them, \
         inconsistencies included.\n"
    );
    if let Some(note) = sharded {
        let _ = writeln!(s, "{note}\n");
    }
    let max_spp = UNBIASED_SPP[UNBIASED_SPP.len() - 1];
    let thin: Vec<String> = scenes
        .iter()
        .filter_map(|sc| {
            let c = sc.comparison?;
            let spp = c.reference_spp?;
            (spp < 10 * max_spp).then(|| format!("{} ({spp} spp)", scene_label(sc.key)))
        })
        .collect();
    if !thin.is_empty() {
        let _ = writeln!(
            s,
            "Note: the references of {} have fewer than ten times the {max_spp} spp of the \
             longest runs, so the smallest errors are partly the references' own noise (a \
             larger --reference-spp refines them; the checkpoints let that resume).\n",
            thin.join(", ")
        );
    }
    let noisy: Vec<String> = scenes
        .iter()
        .filter_map(|sc| {
            let noise = sc.comparison?.reference_noise?;
            Some(format!("{} {}", scene_label(sc.key), sci(noise)))
        })
        .collect();
    if !noisy.is_empty() {
        let _ = writeln!(
            s,
            "The references' own noise (estimated from each reference's two halves) adds to \
             every relMSE of its scene: {}. A relMSE minus that estimates the run's own error; \
             relMSEs within a few times of it are mostly the reference's.\n",
            noisy.join(", ")
        );
    }
    let mut missing: Vec<String> = Vec::new();

    let _ = writeln!(s, "## Unbiased algorithms, by samples per pixel\n");
    spp_table(&mut s, scenes, &UNBIASED, &mut missing);
    let _ = writeln!(s, "## Since the study: VCM and BPM, by samples per pixel\n");
    let _ = writeln!(
        s,
        "Vertex connection and merging (Georgiev et al. 2012) and its merges alone, which the \
         thesis did not have, at the same samples per pixel (each sample one camera and one \
         light subpath; a pass of as many samples as pixels shrinks the merge radius once).\n"
    );
    spp_table(&mut s, scenes, &SINCE, &mut missing);

    let _ = writeln!(s, "## Biased algorithms, by photons per pass\n");
    let _ = writeln!(
        s,
        "PM traces its photons once and renders {PM_PASSES} camera passes (one final-gather ray \
         per pixel each); PPM traces the photons per pass given, for 3 or 75 passes. The \
         thesis' seconds stand beside ours only at its own 250k and 500k photons.\n"
    );
    let mut head = String::from("| scene | algorithm |");
    let mut rule = String::from("|---|---|");
    for &photons in photon_budgets {
        let _ = write!(
            head,
            " {} photons/pass: s | thesis s | relMSE |",
            thousands(photons)
        );
        rule += "---|---|---|";
    }
    let _ = writeln!(s, "{head}\n{rule}");
    for scene in scenes {
        let label = scene_label(scene.key);
        for (integrator, passes, row) in BIASED {
            let thesis = thesis_biased(scene.key, row);
            let _ = write!(s, "| {label} | {row} |");
            let built = IntegratorKind::from_name(integrator).ok();
            if built.is_none() && !missing.contains(&integrator.to_string()) {
                missing.push(integrator.to_string());
            }
            for &photons in photon_budgets {
                let thesis_s = PHOTONS_PER_PASS
                    .iter()
                    .position(|&p| p == photons)
                    .and_then(|j| thesis.map(|t| format!("{}", t[j])))
                    .unwrap_or_default();
                // PM traces `photons` in all, PPM that many per pass.
                let traced = if integrator == "pm" {
                    photons
                } else {
                    photons * passes
                };
                let run = built.and_then(|kind| {
                    scene.comparison.and_then(|c| {
                        c.results.iter().find(|r| {
                            r.integrator == kind && r.passes == passes && r.photons == traced
                        })
                    })
                });
                s += &cells(built.is_some(), run, &thesis_s);
            }
            s.push('\n');
        }
    }
    s.push('\n');

    let _ = writeln!(s, "## Missing\n");
    if missing.is_empty() {
        let _ = writeln!(s, "Every algorithm of the study is built.\n");
    } else {
        let _ = writeln!(
            s,
            "Not built yet in this binary, so listed as missing above: {}.\n",
            missing
                .iter()
                .map(|m| display_name(m))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }

    let _ = writeln!(s, "## Per scene\n");
    for scene in scenes {
        match scene.comparison {
            Some(c) => {
                let _ = writeln!(
                    s,
                    "- {}: [summary]({key}/summary.md), [plot]({key}/error_vs_time.png), \
                     [images]({key}/grid.png); reference `{}` ({}).",
                    scene_label(scene.key),
                    c.reference_path.display(),
                    c.reference_note,
                    key = scene.key
                );
            }
            None => {
                let _ = writeln!(s, "- {}: not run.", scene_label(scene.key));
            }
        }
    }
    s
}

/// One row per scene and integrator of `integrators`: seconds, the thesis' seconds and relMSE
/// at each of `UNBIASED_SPP`; integrators this binary lacks go into `missing`.
fn spp_table(
    s: &mut String,
    scenes: &[SceneResult],
    integrators: &[&str],
    missing: &mut Vec<String>,
) {
    let mut head = String::from("| scene | algorithm |");
    let mut rule = String::from("|---|---|");
    for spp in UNBIASED_SPP {
        let _ = write!(head, " {spp} spp: s | thesis s | relMSE |");
        rule += "---|---|---|";
    }
    let _ = writeln!(s, "{head}\n{rule}");
    for scene in scenes {
        let label = scene_label(scene.key);
        for &integrator in integrators {
            let thesis = thesis_unbiased(scene.key, integrator);
            let _ = write!(s, "| {label} | {} |", display_name(integrator));
            let built = IntegratorKind::from_name(integrator).ok();
            if built.is_none() && !missing.contains(&integrator.to_string()) {
                missing.push(integrator.to_string());
            }
            for (j, spp) in UNBIASED_SPP.iter().enumerate() {
                let thesis_s = thesis.map_or("".to_string(), |t| format!("{}", t[j]));
                let run: Option<&RunResult> = built.and_then(|kind| {
                    scene.comparison.and_then(|c| {
                        c.results
                            .iter()
                            .find(|r| r.integrator == kind && r.budget == *spp as f64)
                    })
                });
                *s += &cells(built.is_some(), run, &thesis_s);
            }
            s.push('\n');
        }
    }
    s.push('\n');
}

/// One budget's three cells (our seconds, the thesis' seconds, our relMSE) of a row.
fn cells(built: bool, run: Option<&RunResult>, thesis_s: &str) -> String {
    match (built, run) {
        (false, _) => format!(" missing | {thesis_s} | missing |"),
        (true, None) => format!(" not run | {thesis_s} | |"),
        (true, Some(r)) => format!(
            " {} | {thesis_s} | {} |",
            secs(r.wall),
            sci(r.metrics.relmse)
        ),
    }
}

fn scene_label(key: &str) -> &'static str {
    SCENES
        .iter()
        .find(|(k, _)| *k == key)
        .map_or("?", |(_, label)| label)
}

/// What the preset was asked for.
pub struct ThesisOptions {
    /// Where the preset finds `SCENES` (as STEM.ron).
    pub scenes_dir: PathBuf,
    /// Report folder: summary.md and results.csv of every scene, one folder per scene.
    pub output: PathBuf,
    /// Seed of the compared renders (the references have their own).
    pub seed: u64,
    pub max_depth: u32,
    /// Settings of the photon mappers; their photon counts are each of `photon_budgets`.
    pub photons: PhotonSettings,
    /// Photons per pass of the biased runs (PM traces this many in all).
    pub photon_budgets: Vec<u64>,
    /// Samples per pixel of the references the preset makes.
    pub reference_spp: u64,
    /// A folder of given references, one SCENE.exr per scene (e.g. an independent renderer's,
    /// with its halves SCENE.a.exr and SCENE.b.exr beside it for its noise); None: the preset
    /// makes its own with pt.
    pub references: Option<PathBuf>,
    /// Worker threads (None: all cores).
    pub threads: Option<usize>,
    /// No progress bar.
    pub quiet: bool,
}

/// `compare --preset thesis`: the three scenes of the study, its budgets, its tables. Returns
/// the exit code: 0, or `EXIT_INTERRUPTED` when Ctrl-C stopped it.
pub fn run(o: &ThesisOptions) -> Result<i32> {
    let out_dir = &o.output;
    let plan = by_spp_plan(o);
    let given = given_references(o)?;
    let stop = stop_on_ctrl_c()?;
    let pool = thread_pool(o.threads)?;
    let mut comparisons: Vec<(&'static str, Comparison)> = Vec::new();
    let mut interrupted = false;
    for ((key, _label), given) in SCENES.into_iter().zip(&given) {
        let scene = o.scenes_dir.join(format!("{key}.ron"));
        let data = load_scene(&scene)?;
        let scene_dir = out_dir.join(key);
        if !o.quiet {
            eprintln!("{key}: {}", scene.display());
        }
        match compare_scene(
            &scene,
            data,
            given.as_deref(),
            &scene_dir,
            &plan,
            o.reference_spp,
            &stop,
            &pool,
            o.quiet,
        )? {
            SceneRun::Done(mut c) => {
                if !c.interrupted {
                    let (runs, stopped) =
                        biased_runs(&scene, &c.reference, &plan, o, &stop, &pool)?;
                    c.results.extend(runs);
                    c.interrupted |= stopped;
                }
                write_scene_report(&c, &scene_dir, &o.photon_budgets)?;
                interrupted |= c.interrupted;
                comparisons.push((key, *c));
            }
            SceneRun::ReferenceInterrupted(note) => {
                eprintln!("{note}");
                interrupted = true;
            }
        }
        if interrupted {
            break;
        }
    }
    let scenes: Vec<SceneResult> = SCENES
        .iter()
        .map(|(key, _)| SceneResult {
            key,
            comparison: comparisons.iter().find(|(k, _)| k == key).map(|(_, c)| c),
        })
        .collect();
    let summary = out_dir.join(super::files::SUMMARY_MD);
    crate::film::output::write_bytes(
        &summary,
        summary_markdown(&scenes, pool.current_num_threads(), &o.photon_budgets, None).as_bytes(),
    )?;
    let csv = out_dir.join(super::files::RESULTS_CSV);
    let all: Vec<(&str, &Comparison)> = comparisons.iter().map(|(k, c)| (*k, c)).collect();
    write_csv(&all, &csv)?;
    write_index(out_dir, &scenes)?;
    let mut text = format!(
        "thesis preset: {} of 3 scenes; wrote {}, {} and {}\n",
        comparisons.len(),
        summary.display(),
        csv.display(),
        out_dir.join(super::files::INDEX_HTML).display()
    );
    if interrupted {
        text += "interrupted: the report holds the runs finished before the stop\n";
    }
    print_out(&text);
    Ok(exit_code(interrupted))
}

/// The preset's runs by samples per pixel: PT, BDPT, MLT, VCM and BPM at `UNBIASED_SPP`.
pub(crate) fn by_spp_plan(o: &ThesisOptions) -> ComparePlan {
    ComparePlan {
        integrators: by_spp_built(),
        unit: BudgetUnit::Spp,
        budgets: UNBIASED_SPP.iter().map(|&s| s as f64).collect(),
        settings: RenderSettings {
            seed: o.seed,
            max_depth: o.max_depth,
            // VCM's and BPM's merges take the given radius and alpha, as the photon mappers do.
            photons: PhotonSettings {
                radius: o.photons.radius,
                alpha: o.photons.alpha,
                ..PhotonSettings::default()
            },
            // The study's MLT is Mitsuba's: direct light apart at its fixed samples per pixel.
            mlt: MltOptions {
                direct_spp: Some(crate::integrators::path_mlt::MITSUBA_DIRECT_SPP),
                ..MltOptions::default()
            },
            ..RenderSettings::default()
        },
    }
}

/// The given reference of each scene of `SCENES` (None: the preset makes it), each checked
/// to exist before the first run of hours.
pub(crate) fn given_references(o: &ThesisOptions) -> Result<Vec<Option<PathBuf>>> {
    let given: Vec<Option<PathBuf>> = SCENES
        .iter()
        .map(|(key, _)| o.references.as_ref().map(|d| d.join(format!("{key}.exr"))))
        .collect();
    for path in given.iter().flatten() {
        if !path.is_file() {
            anyhow::bail!(
                "{}: no such reference (--references needs one SCENE.exr per scene of the \
                 study: {})",
                path.display(),
                SCENES.map(|(k, _)| format!("{k}.exr")).join(", ")
            );
        }
    }
    Ok(given)
}

/// The biased runs of a scene in run order: (integrator, passes, photons per pass, settings),
/// each row of `BIASED` at each of the photon budgets.
pub(crate) fn biased_runs_of(
    plan: &ComparePlan,
    o: &ThesisOptions,
) -> Result<Vec<(IntegratorKind, u64, u64, RenderSettings)>> {
    let mut runs = Vec::new();
    for &photons in &o.photon_budgets {
        for (name, passes, _row) in BIASED {
            let kind = IntegratorKind::from_name(name).map_err(|e| anyhow::anyhow!("{e}"))?;
            let settings = RenderSettings {
                photons: PhotonSettings {
                    photons_per_pass: photons,
                    photons,
                    ..o.photons
                },
                ..plan.settings
            };
            runs.push((kind, passes, photons, settings));
        }
    }
    Ok(runs)
}

/// The biased runs of one scene: each row of `BIASED` at each of the photon budgets, against
/// the scene's reference. Returns the runs and whether a stop cut them short.
fn biased_runs(
    scene: &Path,
    reference: &Image,
    plan: &ComparePlan,
    o: &ThesisOptions,
    stop: &AtomicBool,
    pool: &rayon::ThreadPool,
) -> Result<(Vec<RunResult>, bool)> {
    let data = load_scene(scene)?;
    let mut runs = Vec::new();
    for (kind, passes, photons, settings) in biased_runs_of(plan, o)? {
        if !o.quiet {
            eprintln!("  {kind} at {passes} passes, {photons} photons");
        }
        let job = CompareJob {
            data: data.clone(),
            reference,
            integrators: &[kind],
            unit: BudgetUnit::Spp,
            budgets: &[passes as f64],
            settings,
        };
        let (results, stopped) = pool
            .install(|| super::run_comparison(&job, stop, &|_, _| {}))
            .map_err(|e| anyhow::anyhow!("{}: {e}", scene.display()))?;
        runs.extend(results);
        if stopped {
            return Ok((runs, true));
        }
    }
    Ok((runs, false))
}

/// One CSV of every scene's runs, with a scene column first.
pub(crate) fn write_csv(all: &[(&str, &Comparison)], path: &Path) -> Result<()> {
    let mut rows = Vec::new();
    let mut scenes = Vec::new();
    for (key, c) in all {
        for r in &c.results {
            rows.push(r.clone());
            scenes.push(*key);
        }
    }
    report::write_csv_with_scenes(&rows, BudgetUnit::Spp, path, &scenes)?;
    Ok(())
}
