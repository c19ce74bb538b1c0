//! The report's interactive page: index.html with the viewer over every run and the
//! reference, the sortable results table and the error-against-time plot; each run's image is
//! also written as an EXR in runs/.

use super::format::{sci, secs};
use super::{Comparison, ReportError, report_error};
use crate::viewer::{Page, PageImage, ResultsTable, TableCell, TableRow};
use std::path::Path;

/// The runs' images as EXR files.
pub const RUNS_DIR: &str = "runs";

/// How the viewer names a run: the method it picks, and the group shown side by side.
#[derive(Clone, Debug, PartialEq)]
pub struct RunLabel {
    pub method: String,
    pub group: String,
}

/// The default labels: the integrator, and its budget ("2 s", "16 spp").
pub fn budget_labels(c: &Comparison) -> Vec<RunLabel> {
    c.results
        .iter()
        .map(|r| RunLabel {
            method: r.integrator.as_str().to_string(),
            group: format!("{} {}", r.budget, c.unit.suffix()),
        })
        .collect()
}

/// A file name from a label: lower-case letters, digits and single underscores.
fn file_stem(label: &RunLabel) -> String {
    let mut stem = String::new();
    for c in format!("{} {}", label.method, label.group).chars() {
        if c.is_ascii_alphanumeric() || c == '.' {
            stem.push(c.to_ascii_lowercase());
        } else if !stem.ends_with('_') {
            stem.push('_');
        }
    }
    stem.trim_matches('_').to_string()
}

/// The EXR file of each run under runs/ (names made unique with the run's number).
pub fn run_files(labels: &[RunLabel]) -> Vec<String> {
    let stems: Vec<String> = labels.iter().map(file_stem).collect();
    stems
        .iter()
        .enumerate()
        .map(|(i, stem)| {
            if stems.iter().filter(|s| *s == stem).count() > 1 {
                format!("{RUNS_DIR}/{stem}_{i}.exr")
            } else {
                format!("{RUNS_DIR}/{stem}.exr")
            }
        })
        .collect()
}

/// Writes runs/*.exr and index.html (with index_data/) into `dir`. `links` go at the top
/// (e.g. to the index over a preset's scenes).
pub fn write_page(
    c: &Comparison,
    dir: &Path,
    labels: &[RunLabel],
    links: Vec<(String, String)>,
) -> Result<(), ReportError> {
    let files = run_files(labels);
    for (run, file) in c.results.iter().zip(&files) {
        let path = dir.join(file);
        std::fs::create_dir_all(dir.join(RUNS_DIR)).map_err(|e| report_error(&path, e))?;
        run.image
            .write_exr(&path)
            .map_err(|e| report_error(&path, e.message))?;
    }
    let plot_path = dir.join(super::files::PLOT_SVG);
    let plot_svg = std::fs::read_to_string(&plot_path).map_err(|e| report_error(&plot_path, e))?;
    let images = c
        .results
        .iter()
        .zip(labels)
        .zip(&files)
        .map(|((run, label), file)| PageImage {
            method: label.method.clone(),
            group: label.group.clone(),
            source: Some(file.clone()),
            image: &run.image,
        })
        .collect();
    let mut notes = vec![format!(
        "Scene {} at {}x{}, {} threads; reference {} ({}). Each run's image is in {RUNS_DIR}/ \
         as EXR; the viewer shows their float32 values, decoded in the page.",
        c.scene_path.display(),
        c.width,
        c.height,
        c.threads,
        c.reference_path.display(),
        c.reference_note
    )];
    if let Some(noise) = c.reference_noise {
        notes.push(format!(
            "The reference's own noise adds {} to every relMSE (estimated from its halves).",
            sci(noise)
        ));
    }
    if c.interrupted {
        notes.push("Interrupted: only the runs finished before the stop are here.".into());
    }
    let mut links = links;
    links.extend([
        (
            "summary.md".to_string(),
            super::files::SUMMARY_MD.to_string(),
        ),
        (
            "results.csv".to_string(),
            super::files::RESULTS_CSV.to_string(),
        ),
        ("grid.png".to_string(), super::files::GRID_PNG.to_string()),
    ]);
    let page = Page {
        title: format!("Speed against error: {}", c.scene_name),
        notes,
        reference: PageImage {
            method: "reference".into(),
            group: String::new(),
            source: Some(c.reference_path.display().to_string()),
            image: &c.reference,
        },
        images,
        plot_svg: Some(plot_svg),
        table: Some(results_table(c, labels)),
        links,
    };
    let html = dir.join(super::files::INDEX_HTML);
    crate::viewer::write_page(&page, &html).map_err(|e| report_error(&e.path, e.message))?;
    Ok(())
}

/// The runs as a table: relMSE, time, spp, speed and efficiency.
pub fn results_table(c: &Comparison, labels: &[RunLabel]) -> ResultsTable {
    let columns = [
        "method",
        "budget",
        "relMSE",
        "wall s",
        "spp",
        "speed (spp/s)",
        "Mrays/s",
        "efficiency",
    ];
    let rows = c
        .results
        .iter()
        .zip(labels)
        .enumerate()
        .map(|(i, (r, label))| {
            let rays = (r.closest_rays + r.shadow_rays) as f64 / r.wall.max(1e-9) / 1e6;
            let speed = r.passes as f64 / r.wall.max(1e-9);
            TableRow {
                image: Some(i),
                cells: vec![
                    TableCell::text(label.method.clone()),
                    // Sorted by the budget's number where the group is the budget (a preset's
                    // photon groups sort as text).
                    if label.group == format!("{} {}", r.budget, c.unit.suffix()) {
                        TableCell::number(label.group.clone(), r.budget)
                    } else {
                        TableCell::text(label.group.clone())
                    },
                    TableCell::number(sci(r.metrics.relmse), r.metrics.relmse),
                    TableCell::number(secs(r.wall), r.wall),
                    TableCell::number(r.passes.to_string(), r.passes as f64),
                    TableCell::number(format!("{speed:.3}"), speed),
                    TableCell::number(format!("{rays:.2}"), rays),
                    TableCell::number(sci(r.efficiency()), r.efficiency()),
                ],
            }
        })
        .collect();
    ResultsTable {
        columns: columns.iter().map(|s| s.to_string()).collect(),
        rows,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn label(method: &str, group: &str) -> RunLabel {
        RunLabel {
            method: method.into(),
            group: group.into(),
        }
    }

    #[test]
    fn run_files_are_plain_names_made_unique() {
        let labels = [
            label("pt", "2 s"),
            label("PPM, 3 passes", "250k photons"),
            label("pt", "0.5 s"),
            label("a/b", "x"),
            label("a b", "x"),
        ];
        assert_eq!(
            run_files(&labels),
            [
                "runs/pt_2_s.exr",
                "runs/ppm_3_passes_250k_photons.exr",
                "runs/pt_0.5_s.exr",
                "runs/a_b_x_3.exr",
                "runs/a_b_x_4.exr"
            ]
        );
    }
}
