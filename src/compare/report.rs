//! The report folder of a comparison: results.csv, the pictures, and summary.md.

use super::format::{points, sci, secs, slope_of};
use super::{BudgetUnit, Comparison, Reach, ReportError, RunResult, error_at_time};
use super::{quality_targets, report_error, time_to_reach};
use std::fmt::Write;
use std::path::Path;

use super::files::{GRID_PNG, INDEX_HTML, PLOT_PNG, PLOT_SVG, RESULTS_CSV, SUMMARY_MD};

/// The CSV's columns, in order.
pub const CSV_HEADER: [&str; 17] = [
    "integrator",
    "budget",
    "budget_unit",
    "wall_s",
    "cpu_s",
    "samples",
    "passes",
    "closest_hit_rays",
    "shadow_rays",
    "photons",
    "relmse",
    "rmse",
    "mae",
    "efficiency",
    "mean_r",
    "mean_g",
    "mean_b",
];

/// Writes every file of the report into `dir` (created if missing), the page's runs named by
/// integrator and budget.
pub fn write_report(c: &Comparison, dir: &Path) -> Result<(), ReportError> {
    write_report_labelled(c, dir, &super::page::budget_labels(c), Vec::new())
}

/// `write_report` with the page's own names for the runs, and links at its top.
pub fn write_report_labelled(
    c: &Comparison,
    dir: &Path,
    labels: &[super::page::RunLabel],
    links: Vec<(String, String)>,
) -> Result<(), ReportError> {
    std::fs::create_dir_all(dir).map_err(|e| report_error(dir, e))?;
    write_csv(&c.results, c.unit, &dir.join(RESULTS_CSV))?;
    super::plot::write_error_plot(c, &dir.join(PLOT_PNG), &dir.join(PLOT_SVG))?;
    super::plot::write_grid(c, &dir.join(GRID_PNG))?;
    let summary = dir.join(SUMMARY_MD);
    crate::film::output::write_bytes(&summary, summary_markdown(c).as_bytes())
        .map_err(|e| report_error(&summary, e.message))?;
    super::page::write_page(c, dir, labels, links)
}

/// The files of a report folder, to check before the runs that fill them.
pub fn report_files(dir: &Path) -> Vec<std::path::PathBuf> {
    [
        RESULTS_CSV,
        PLOT_PNG,
        PLOT_SVG,
        GRID_PNG,
        SUMMARY_MD,
        INDEX_HTML,
    ]
    .iter()
    .map(|f| dir.join(f))
    .collect()
}

/// Writes runs as CSV with `CSV_HEADER`.
pub fn write_csv(results: &[RunResult], unit: BudgetUnit, path: &Path) -> Result<(), ReportError> {
    write_csv_rows(results, unit, path, None)
}

/// Writes runs of several scenes as CSV: a `scene` column (one name per run), then
/// `CSV_HEADER`.
pub fn write_csv_with_scenes(
    results: &[RunResult],
    unit: BudgetUnit,
    path: &Path,
    scenes: &[&str],
) -> Result<(), ReportError> {
    write_csv_rows(results, unit, path, Some(scenes))
}

fn write_csv_rows(
    results: &[RunResult],
    unit: BudgetUnit,
    path: &Path,
    scenes: Option<&[&str]>,
) -> Result<(), ReportError> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let mut header: Vec<&str> = scenes.map(|_| "scene").into_iter().collect();
    header.extend(CSV_HEADER);
    w.write_record(&header).map_err(|e| report_error(path, e))?;
    for (i, r) in results.iter().enumerate() {
        let mut row: Vec<String> = scenes
            .map(|s| s.get(i).copied().unwrap_or("").to_string())
            .into_iter()
            .collect();
        let m = &r.metrics;
        row.extend([
            r.integrator.as_str().to_string(),
            r.budget.to_string(),
            unit.as_str().to_string(),
            format!("{:.6}", r.wall),
            format!("{:.3}", r.cpu),
            r.samples.to_string(),
            r.passes.to_string(),
            r.closest_rays.to_string(),
            r.shadow_rays.to_string(),
            r.photons.to_string(),
            format!("{:e}", m.relmse),
            format!("{:e}", m.rmse),
            format!("{:e}", m.mae),
            format!("{:e}", r.efficiency()),
            format!("{:e}", m.mean.x),
            format!("{:e}", m.mean.y),
            format!("{:e}", m.mean.z),
        ]);
        w.write_record(&row).map_err(|e| report_error(path, e))?;
    }
    let bytes = w.into_inner().map_err(|e| report_error(path, e))?;
    crate::film::output::write_bytes(path, &bytes).map_err(|e| report_error(path, e.message))
}

/// summary.md: what was compared, the pictures, equal-time and equal-quality tables, slopes
/// and the bias check.
pub fn summary_markdown(c: &Comparison) -> String {
    let mut s = String::new();
    let unit = c.unit.suffix();
    let budgets: Vec<String> = c.budgets.iter().map(|b| format!("{b}")).collect();
    let _ = writeln!(s, "# Speed against error: {}\n", c.scene_name);
    let _ = writeln!(
        s,
        "Scene `{}` at {}x{}, {} threads. Integrators: {}. Budgets: {} {} each.\n",
        c.scene_path.display(),
        c.width,
        c.height,
        c.threads,
        c.integrators
            .iter()
            .map(|k| k.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        budgets.join(", "),
        unit
    );
    let _ = writeln!(
        s,
        "Reference: `{}` ({}).\n",
        c.reference_path.display(),
        c.reference_note
    );
    if let Some(note) = &c.sharded {
        let _ = writeln!(s, "{note}\n");
    }
    if let Some(noise) = c.reference_noise {
        let _ = writeln!(
            s,
            "The reference's own noise, estimated from its two halves (REF.a.exr, REF.b.exr), \
             adds {} to every relMSE below: errors near it are mostly the reference's.\n",
            crate::compare::format::sci(noise)
        );
    }
    if c.interrupted {
        let _ = writeln!(
            s,
            "**Interrupted:** only the runs finished before the stop are reported.\n"
        );
    }
    let _ = writeln!(
        s,
        "relMSE is the mean over pixels and channels of (x - r)^2 / (r^2 + 0.01) against the \
         reference; efficiency is 1 / (relMSE x wall seconds), higher is better. Every run is \
         in [results.csv]({RESULTS_CSV}).\n"
    );
    let _ = writeln!(s, "![relMSE against wall time]({PLOT_PNG})\n");
    let _ = writeln!(
        s,
        "[error_vs_time.svg]({PLOT_SVG}): the same plot as SVG. \
         [grid.png]({GRID_PNG}): the images (columns: budgets) with their relative-error maps \
         beneath.\n"
    );
    let _ = writeln!(s, "![images and relative-error maps]({GRID_PNG})\n");

    equal_time_table(c, &mut s);
    equal_quality_table(c, &mut s);
    slope_table(c, &mut s);
    bias_table(c, &mut s);
    s
}

fn equal_time_table(c: &Comparison, s: &mut String) {
    let _ = writeln!(s, "## Equal time\n");
    let kinds = &c.integrators;
    match c.unit {
        BudgetUnit::Seconds => {
            let _ = writeln!(
                s,
                "Each integrator rendered whole passes for the same wall time; relMSE, \
                 efficiency and the wall seconds actually taken.\n"
            );
            let mut head = String::from("| budget |");
            let mut rule = String::from("|---|");
            for k in kinds {
                let _ = write!(head, " {k} relMSE | {k} efficiency | {k} wall s |");
                rule += "---|---|---|";
            }
            let _ = writeln!(s, "{head}\n{rule}");
            for &b in &c.budgets {
                let _ = write!(s, "| {b} s |");
                for &k in kinds {
                    match c
                        .results
                        .iter()
                        .find(|r| r.integrator == k && r.budget == b)
                    {
                        Some(r) => {
                            let _ = write!(
                                s,
                                " {} | {} | {} |",
                                sci(r.metrics.relmse),
                                sci(r.efficiency()),
                                secs(r.wall)
                            );
                        }
                        None => s.push_str(" not run | | |"),
                    }
                }
                s.push('\n');
            }
            let _ = writeln!(s, "\n{}\n", best_line(c));
        }
        BudgetUnit::Spp => {
            // Sample budgets take different times per integrator: compare at common times,
            // the median wall time of each budget, interpolating each integrator in log-log.
            let _ = writeln!(
                s,
                "Sample budgets take each integrator a different time, so each row is a wall \
                 time (the median over integrators of one budget's runs) and each cell the \
                 relMSE interpolated in log-log between the integrator's runs that bracket it \
                 (\"outside\" where its runs do not).\n"
            );
            let mut head = String::from("| wall s |");
            let mut rule = String::from("|---|");
            for k in kinds {
                let _ = write!(head, " {k} relMSE |");
                rule += "---|";
            }
            let _ = writeln!(s, "{head}\n{rule}");
            for &b in &c.budgets {
                let mut walls: Vec<f64> = c
                    .results
                    .iter()
                    .filter(|r| r.budget == b)
                    .map(|r| r.wall)
                    .collect();
                if walls.is_empty() {
                    continue;
                }
                walls.sort_by(f64::total_cmp);
                let t = walls[walls.len() / 2];
                let _ = write!(s, "| {} (at {b} spp) |", secs(t));
                for &k in kinds {
                    let cell =
                        error_at_time(&points(&c.runs_of(k)), t).map_or("outside".to_string(), sci);
                    let _ = write!(s, " {cell} |");
                }
                s.push('\n');
            }
            s.push('\n');
            let _ = writeln!(s, "{}\n", best_line(c));
        }
    }
}

/// Which integrator was most efficient at the largest budget.
fn best_line(c: &Comparison) -> String {
    let Some(&last) = c.budgets.last() else {
        return String::new();
    };
    let best = c
        .results
        .iter()
        .filter(|r| r.budget == last)
        .max_by(|a, b| a.efficiency().total_cmp(&b.efficiency()));
    match best {
        Some(r) => format!(
            "Most efficient at the largest budget ({last} {}): **{}** (efficiency {}).",
            c.unit.suffix(),
            r.integrator,
            sci(r.efficiency())
        ),
        None => String::new(),
    }
}

fn equal_quality_table(c: &Comparison, s: &mut String) {
    let _ = writeln!(s, "## Equal quality\n");
    let errors: Vec<f64> = c.results.iter().map(|r| r.metrics.relmse).collect();
    let targets = quality_targets(&errors);
    let _ = writeln!(
        s,
        "Wall seconds each integrator needs to reach a relMSE, interpolated in log-log between \
         the two runs that bracket it; \"<= t\" when its shortest run (t seconds) was already \
         there, \"not reached\" when its longest was not.\n"
    );
    if targets.is_empty() {
        let _ = writeln!(s, "No run to compare.\n");
        return;
    }
    let mut head = String::from("| relMSE |");
    let mut rule = String::from("|---|");
    for k in &c.integrators {
        let _ = write!(head, " {k} |");
        rule += "---|";
    }
    let _ = writeln!(s, "{head}\n{rule}");
    for target in targets {
        let _ = write!(s, "| {} |", sci(target));
        for &k in &c.integrators {
            let cell = match time_to_reach(&points(&c.runs_of(k)), target) {
                Reach::AtFirstRun(t) => format!("<= {} s", secs(t)),
                Reach::At(t) => format!("{} s", secs(t)),
                Reach::NotReached => "not reached".into(),
            };
            let _ = write!(s, " {cell} |");
        }
        s.push('\n');
    }
    s.push('\n');
}

fn slope_table(c: &Comparison, s: &mut String) {
    let _ = writeln!(s, "## Convergence\n");
    let _ = writeln!(
        s,
        "Least-squares slope of log relMSE against log wall time over each integrator's runs. \
         An unbiased integrator falls with slope -1 (MSE ~ 1/N) until the reference's own \
         noise is reached; a flatter slope means bias, or a reference not converged enough.\n"
    );
    let _ = writeln!(s, "| integrator | slope | runs | relMSE first -> last |");
    let _ = writeln!(s, "|---|---|---|---|");
    for &k in &c.integrators {
        let runs = c.runs_of(k);
        let slope = slope_of(c, k).map_or("n/a".to_string(), |v| format!("{v:.2}"));
        let span = match (runs.first(), runs.last()) {
            (Some(a), Some(b)) => format!("{} -> {}", sci(a.metrics.relmse), sci(b.metrics.relmse)),
            _ => "no run".into(),
        };
        let _ = writeln!(s, "| {k} | {slope} | {} | {span} |", runs.len());
    }
    s.push('\n');
    if let (Some(ref_spp), Some(max_spp)) =
        (c.reference_spp, c.results.iter().map(|r| r.passes).max())
        && ref_spp < 10 * max_spp
    {
        let _ = writeln!(
            s,
            "Note: the reference has {ref_spp} spp, less than ten times the {max_spp} spp of \
             the longest run, so its own noise is a visible part of the smallest errors.\n"
        );
    }
}

fn bias_table(c: &Comparison, s: &mut String) {
    let _ = writeln!(s, "## Bias check\n");
    let r = c.reference.channel_means();
    let _ = writeln!(
        s,
        "Image means per channel at the largest budget against the reference's ({:.5}, {:.5}, \
         {:.5}): unbiased integrators agree within their noise.\n",
        r.x, r.y, r.z
    );
    let _ = writeln!(s, "| integrator | budget | mean R | mean G | mean B |");
    let _ = writeln!(s, "|---|---|---|---|---|");
    for &k in &c.integrators {
        if let Some(run) = c.runs_of(k).last() {
            let m = run.metrics.mean;
            let _ = writeln!(
                s,
                "| {k} | {} {} | {:.5} | {:.5} | {:.5} |",
                run.budget,
                c.unit.suffix(),
                m.x,
                m.y,
                m.z
            );
        }
    }
    s.push('\n');
}
