//! Speed against error (../METRICS.md): render each integrator at each budget, measure its
//! error against a reference, and write a report folder: results.csv, error_vs_time.png and
//! .svg, grid.png, summary.md, and index.html (the interactive page, with runs/*.exr).

pub mod files;
pub mod format;
pub mod page;
pub mod plot;
pub mod report;
pub mod run;
pub mod shards;
pub mod thesis;

use crate::film::Image;
use crate::integrators::{Budget, Control, IntegratorKind, RenderSettings, SceneData};
use crate::metrics::{ErrorMetrics, compare};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// What the numbers of `--budgets` count.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum BudgetUnit {
    /// Wall seconds (each run renders whole passes until its time is spent).
    Seconds,
    /// Samples per pixel (passes).
    Spp,
}

impl BudgetUnit {
    pub fn as_str(self) -> &'static str {
        match self {
            BudgetUnit::Seconds => "seconds",
            BudgetUnit::Spp => "spp",
        }
    }

    /// The short unit after a number: "4 s", "16 spp".
    pub fn suffix(self) -> &'static str {
        match self {
            BudgetUnit::Seconds => "s",
            BudgetUnit::Spp => "spp",
        }
    }

    pub fn budget(self, value: f64) -> Budget {
        match self {
            BudgetUnit::Seconds => Budget::Seconds(value),
            BudgetUnit::Spp => Budget::SamplesPerPixel(value as u64),
        }
    }
}

/// Checks a budget list: not empty, every value positive and finite (whole numbers for spp),
/// strictly increasing. The message names the first problem.
pub fn validate_budgets(budgets: &[f64], unit: BudgetUnit) -> Result<(), String> {
    if budgets.is_empty() {
        return Err("the budget list is empty".into());
    }
    for &b in budgets {
        if !(b.is_finite() && b > 0.0) {
            return Err(format!("budget {} is not a positive number", short(b)));
        }
        if unit == BudgetUnit::Spp && b > u32::MAX as f64 {
            return Err(format!(
                "budget {b:e} is too large: at most {} samples per pixel",
                u32::MAX
            ));
        }
        if unit == BudgetUnit::Spp && b.fract() != 0.0 {
            return Err(format!(
                "budget {} is not a whole number of samples per pixel",
                short(b)
            ));
        }
    }
    if let Some(w) = budgets.windows(2).find(|w| w[1] <= w[0]) {
        return Err(format!(
            "budgets must be strictly increasing, but {} follows {}",
            short(w[1]),
            short(w[0])
        ));
    }
    Ok(())
}

/// A number as a message repeats it: plain, or in scientific notation when plain would be
/// long (1e300 is not 301 digits).
fn short(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-6..1e15).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// A report file could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", .path.display())]
pub struct ReportError {
    pub path: PathBuf,
    pub message: String,
}

pub(crate) fn report_error(path: &Path, message: impl std::fmt::Display) -> ReportError {
    ReportError {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// One integrator rendered at one budget, and its error.
#[derive(Clone, Debug)]
pub struct RunResult {
    pub integrator: IntegratorKind,
    /// The budget as given, in the comparison's unit.
    pub budget: f64,
    /// Wall and CPU seconds of the whole call, setup included.
    pub wall: f64,
    pub cpu: f64,
    pub samples: u64,
    pub passes: u64,
    pub closest_rays: u64,
    pub shadow_rays: u64,
    /// Photons traced (0 for integrators without photons).
    pub photons: u64,
    pub metrics: ErrorMetrics,
    pub image: Image,
}

impl RunResult {
    /// 1 / (relMSE x wall seconds): higher is better; infinite for an exact image.
    pub fn efficiency(&self) -> f64 {
        1.0 / (self.metrics.relmse * self.wall)
    }
}

/// A finished (or interrupted) comparison: everything the report shows.
pub struct Comparison {
    /// Short name (the scene file's stem), for titles.
    pub scene_name: String,
    pub scene_path: PathBuf,
    pub width: usize,
    pub height: usize,
    pub threads: usize,
    pub reference: Image,
    pub reference_path: PathBuf,
    /// Where the reference came from, one sentence: "given", "made by this run: ...".
    pub reference_note: String,
    pub reference_spp: Option<u64>,
    /// What the reference's own noise adds to every relMSE against it (estimated from its
    /// halves, when they lie beside it); None when unknown.
    pub reference_noise: Option<f64>,
    pub integrators: Vec<IntegratorKind>,
    pub unit: BudgetUnit,
    pub budgets: Vec<f64>,
    /// In run order: integrator by integrator, budgets increasing.
    pub results: Vec<RunResult>,
    /// True when a stop cut the comparison short: some runs are missing.
    pub interrupted: bool,
    /// How the runs were made when they were rendered as shards (a paragraph for the
    /// summary); None when one machine rendered them.
    pub sharded: Option<String>,
}

impl Comparison {
    /// The runs of one integrator, budgets increasing.
    pub fn runs_of(&self, kind: IntegratorKind) -> Vec<&RunResult> {
        self.results
            .iter()
            .filter(|r| r.integrator == kind)
            .collect()
    }
}

/// The renders of a comparison.
pub struct CompareJob<'a> {
    pub data: Arc<SceneData>,
    pub reference: &'a Image,
    pub integrators: &'a [IntegratorKind],
    pub unit: BudgetUnit,
    pub budgets: &'a [f64],
    pub settings: RenderSettings,
}

impl CompareJob<'_> {
    /// Total budget units of every run (the length of a progress bar).
    pub fn total_units(&self) -> f64 {
        self.budgets.iter().sum::<f64>() * self.integrators.len() as f64
    }
}

/// Renders every integrator at every budget, in the current rayon pool, and measures each
/// image against the reference. `progress(units_done, label)` follows the runs in budget
/// units; a stop keeps the finished runs and drops the one it cut short. Errors (a size or
/// NaN problem) are returned as a message.
pub fn run_comparison(
    job: &CompareJob,
    stop: &AtomicBool,
    progress: &(dyn Fn(f64, &str) + Sync),
) -> Result<(Vec<RunResult>, bool), String> {
    let mut results = Vec::new();
    let mut units_before = 0.0;
    for &kind in job.integrators {
        warm_up(kind, job);
        for &budget in job.budgets {
            let label = format!("{kind} at {budget} {}", job.unit.suffix());
            let run_start = Instant::now();
            let unit = job.unit;
            let on_wave = |passes: u64, _total: Option<u64>| {
                let done = match unit {
                    BudgetUnit::Spp => passes as f64,
                    BudgetUnit::Seconds => run_start.elapsed().as_secs_f64().min(budget),
                };
                progress(units_before + done, &label);
            };
            let control = Control {
                stop,
                progress: &on_wave,
            };
            progress(units_before, &label);
            let cpu_start = crate::sysinfo::cpu_seconds();
            let wall_start = Instant::now();
            let outcome = crate::integrators::render(
                kind,
                job.data.clone(),
                &job.settings,
                job.unit.budget(budget),
                &control,
            );
            let wall = wall_start.elapsed().as_secs_f64();
            let cpu = crate::sysinfo::cpu_seconds() - cpu_start;
            if outcome.interrupted || outcome.passes == 0 {
                return Ok((results, true));
            }
            let image = outcome.film.image();
            let metrics = compare(&image, job.reference)
                .map_err(|e| format!("{kind} at {budget} {}: {e}", job.unit.suffix()))?;
            results.push(RunResult {
                integrator: kind,
                budget,
                wall,
                cpu,
                samples: outcome.samples,
                passes: outcome.passes,
                closest_rays: outcome.closest_rays(),
                shadow_rays: outcome.shadow_rays(),
                photons: outcome.stats.get("emit_photons").map_or(0, |s| s.emitted),
                metrics,
                image,
            });
            units_before += budget;
            progress(units_before, &label);
        }
    }
    Ok((results, false))
}

/// One pass before the timed runs, so the first timed run does not pay for page faults and
/// cold caches the later ones do not.
fn warm_up(kind: IntegratorKind, job: &CompareJob) {
    warm_up_integrator(kind, job.data.clone(), &job.settings);
}

/// One untimed pass of `kind` with a seed of its own (see `warm_up`).
pub(crate) fn warm_up_integrator(
    kind: IntegratorKind,
    data: Arc<SceneData>,
    settings: &RenderSettings,
) {
    let never = AtomicBool::new(false);
    let control = Control {
        stop: &never,
        progress: &|_, _| {},
    };
    let _ = crate::integrators::render(
        kind,
        data,
        &RenderSettings {
            seed: settings.seed ^ 0x77a2_3e11,
            ..*settings
        },
        Budget::SamplesPerPixel(1),
        &control,
    );
}

/// Least-squares slope of log(error) against log(time): -1 for an unbiased estimator whose
/// MSE falls as 1/N. None with fewer than two usable points (positive, distinct times).
pub fn fit_log_slope(points: &[(f64, f64)]) -> Option<f64> {
    let logs: Vec<(f64, f64)> = points
        .iter()
        .filter(|(t, e)| *t > 0.0 && *e > 0.0 && t.is_finite() && e.is_finite())
        .map(|(t, e)| (t.ln(), e.ln()))
        .collect();
    if logs.len() < 2 {
        return None;
    }
    let n = logs.len() as f64;
    let mx = logs.iter().map(|p| p.0).sum::<f64>() / n;
    let my = logs.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = logs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = logs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 1e-12).then(|| sxy / sxx)
}

/// When an integrator's error first reaches a target.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reach {
    /// Already at its first (shortest) run, which took this long: the time needed is at most
    /// this.
    AtFirstRun(f64),
    /// Between two runs: the time interpolated in log-log.
    At(f64),
    NotReached,
}

/// The time an integrator needs to reach relMSE `target`, from its runs as (wall seconds,
/// relMSE) sorted by time: the first pair of consecutive runs that brackets the target,
/// interpolated linearly in log time against log error.
pub fn time_to_reach(points: &[(f64, f64)], target: f64) -> Reach {
    let Some(&(t0, e0)) = points.first() else {
        return Reach::NotReached;
    };
    if e0 <= target {
        return Reach::AtFirstRun(t0);
    }
    for w in points.windows(2) {
        let ((ta, ea), (tb, eb)) = (w[0], w[1]);
        if ea > target && eb <= target {
            if eb <= 0.0 || ta <= 0.0 || tb <= 0.0 {
                return Reach::At(tb);
            }
            let f = (target.ln() - ea.ln()) / (eb.ln() - ea.ln());
            return Reach::At((ta.ln() + f * (tb.ln() - ta.ln())).exp());
        }
    }
    Reach::NotReached
}

/// An integrator's relMSE at wall time `t`, interpolated in log-log between the runs that
/// bracket it (points sorted by time); None outside the measured times.
pub fn error_at_time(points: &[(f64, f64)], t: f64) -> Option<f64> {
    for w in points.windows(2) {
        let ((ta, ea), (tb, eb)) = (w[0], w[1]);
        if ta <= t && t <= tb {
            if tb <= ta || ea <= 0.0 || eb <= 0.0 {
                return Some(eb);
            }
            let f = (t.ln() - ta.ln()) / (tb.ln() - ta.ln());
            return Some((ea.ln() + f * (eb.ln() - ea.ln())).exp());
        }
    }
    match points {
        [(ta, ea)] if (*ta - t).abs() <= 1e-9 * t.abs() => Some(*ea),
        _ => None,
    }
}

/// relMSE levels for the equal-quality table: the 1-2-5 steps (1, 2, 5, 10, 20, ... times a
/// power of ten) between the best and worst errors measured, thinned to the powers of ten when
/// they would be more than seven, or the median error when none fits.
pub fn quality_targets(errors: &[f64]) -> Vec<f64> {
    let mut finite: Vec<f64> = errors
        .iter()
        .copied()
        .filter(|e| e.is_finite() && *e > 0.0)
        .collect();
    if finite.is_empty() {
        return Vec::new();
    }
    finite.sort_by(f64::total_cmp);
    let (lo, hi) = (finite[0], finite[finite.len() - 1]);
    let inside = |steps: &[f64]| -> Vec<f64> {
        let mut v = Vec::new();
        for k in lo.log10().floor() as i32..=hi.log10().ceil() as i32 {
            for &m in steps {
                // Rounded to the step's own digits, so 0.1 * 2 prints as 0.2.
                let t: f64 = format!("{m}e{k}").parse().unwrap_or(m * 10f64.powi(k));
                if lo <= t && t <= hi {
                    v.push(t);
                }
            }
        }
        v
    };
    let mut targets = inside(&[1.0, 2.0, 5.0]);
    if targets.len() > 7 {
        targets = inside(&[1.0]);
    }
    if targets.is_empty() {
        let median = finite[finite.len() / 2];
        let scale = 10f64.powi(median.log10().floor() as i32 - 1);
        targets.push((median / scale).round() * scale);
    }
    targets.reverse();
    targets
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slope_of_an_exact_power_law() {
        let pts: Vec<(f64, f64)> = [1.0, 2.0, 4.0, 8.0].iter().map(|&t| (t, 0.3 / t)).collect();
        assert!((fit_log_slope(&pts).unwrap() + 1.0).abs() < 1e-12);
        assert_eq!(fit_log_slope(&pts[..1]), None);
    }

    #[test]
    fn reach_interpolates_in_log_log() {
        let pts = [(1.0, 1.0), (4.0, 0.25), (16.0, 0.0625)];
        match time_to_reach(&pts, 0.5) {
            Reach::At(t) => assert!((t - 2.0).abs() < 1e-9, "{t}"),
            r => panic!("{r:?}"),
        }
        assert_eq!(time_to_reach(&pts, 2.0), Reach::AtFirstRun(1.0));
        assert_eq!(time_to_reach(&pts, 0.01), Reach::NotReached);
        assert!((error_at_time(&pts, 2.0).unwrap() - 0.5).abs() < 1e-9);
        assert_eq!(error_at_time(&pts, 32.0), None);
    }

    #[test]
    fn budget_lists_are_checked() {
        assert!(validate_budgets(&[1.0, 2.0, 4.0], BudgetUnit::Seconds).is_ok());
        assert!(
            validate_budgets(&[], BudgetUnit::Seconds)
                .unwrap_err()
                .contains("empty")
        );
        let e = validate_budgets(&[1.0, 4.0, 2.0], BudgetUnit::Seconds).unwrap_err();
        assert!(e.contains("increasing"), "{e}");
        assert!(validate_budgets(&[2.0, 2.0], BudgetUnit::Spp).is_err());
        assert!(validate_budgets(&[1.5], BudgetUnit::Spp).is_err());
        assert!(validate_budgets(&[0.0, 1.0], BudgetUnit::Seconds).is_err());
    }

    #[test]
    fn quality_targets_are_round_levels_inside_the_range() {
        assert_eq!(
            quality_targets(&[0.5, 0.003]),
            vec![0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005]
        );
        // Eight 1-2-5 steps are too many: the decades remain.
        assert_eq!(quality_targets(&[0.5, 0.002]), vec![0.1, 0.01]);
        assert_eq!(quality_targets(&[0.028, 0.0049]), vec![0.02, 0.01, 0.005]);
        assert_eq!(
            quality_targets(&[3.0, 1e-6]),
            vec![1.0, 0.1, 0.01, 1e-3, 1e-4, 1e-5, 1e-6]
        );
        assert_eq!(quality_targets(&[0.031, 0.032, 0.033]), vec![0.032]);
        assert!(quality_targets(&[]).is_empty());
    }
}
