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
use super::{Comparison, RunResult};
use crate::integrators::IntegratorKind;
use std::fmt::Write;

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

/// The unbiased integrators of the study this binary has.
pub fn unbiased_built() -> Vec<IntegratorKind> {
    UNBIASED
        .iter()
        .filter_map(|n| IntegratorKind::from_name(n).ok())
        .collect()
}

fn display_name(integrator: &str) -> String {
    integrator.to_ascii_uppercase()
}

fn thousands(photons: u64) -> String {
    format!("{}k", photons / 1000)
}

/// One scene of the preset: its file stem and its comparison (None when it could not run).
pub struct SceneResult<'a> {
    pub key: &'static str,
    pub comparison: Option<&'a Comparison>,
}

/// The preset's summary.md: the study's two tables with our seconds and relMSE beside its
/// seconds, algorithms not built yet listed as missing.
pub fn summary_markdown(scenes: &[SceneResult], threads: usize, photon_budgets: &[u64]) -> String {
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
    let mut missing: Vec<String> = Vec::new();

    let _ = writeln!(s, "## Unbiased algorithms, by samples per pixel\n");
    let mut head = String::from("| scene | algorithm |");
    let mut rule = String::from("|---|---|");
    for spp in UNBIASED_SPP {
        let _ = write!(head, " {spp} spp: s | thesis s | relMSE |");
        rule += "---|---|---|";
    }
    let _ = writeln!(s, "{head}\n{rule}");
    for scene in scenes {
        let label = scene_label(scene.key);
        for integrator in UNBIASED {
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
                s += &cells(built.is_some(), run, &thesis_s);
            }
            s.push('\n');
        }
    }
    s.push('\n');

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
