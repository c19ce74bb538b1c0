//! The compare command: a plan checked from its options, the reference of a scene (given, or
//! made or resumed in the report folder), every run, and the report folder.

use super::{BudgetUnit, CompareJob, Comparison, report};
use crate::commands::reference::{describe_reference, make_reference};
use crate::commands::{
    exit_code, load_scene, print_out, scene_stem, stop_on_ctrl_c, thread_pool, unit_bar,
};
use crate::integrators::{IntegratorKind, RenderSettings, SceneData};
use crate::reference::{DEFAULT_REFERENCE_SEED, ReferenceBudget, ReferenceJob, load_reference};
use anyhow::{Result, bail};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// What a comparison was asked for.
pub struct CompareOptions {
    /// Scene file (RON).
    pub scene: PathBuf,
    /// Reference EXR of the scene (None: made or resumed as `output`/reference.exr).
    pub reference: Option<PathBuf>,
    /// Integrators in run order (empty: every integrator built); each at most once.
    pub integrators: Vec<IntegratorKind>,
    pub unit: BudgetUnit,
    /// Strictly increasing, in `unit`.
    pub budgets: Vec<f64>,
    /// Settings of the compared renders (the reference has its own seed).
    pub settings: RenderSettings,
    /// Samples per pixel of a reference the comparison makes.
    pub reference_spp: u64,
    /// Report folder.
    pub output: PathBuf,
    /// Worker threads (None: all cores).
    pub threads: Option<usize>,
    /// No progress bar.
    pub quiet: bool,
}

/// The checked settings of a comparison.
pub struct ComparePlan {
    pub integrators: Vec<IntegratorKind>,
    pub unit: BudgetUnit,
    pub budgets: Vec<f64>,
    pub settings: RenderSettings,
}

impl ComparePlan {
    /// Checks the budgets and the integrator list (the messages name the option).
    pub fn new(o: &CompareOptions) -> Result<ComparePlan> {
        super::validate_budgets(&o.budgets, o.unit)
            .map_err(|e| anyhow::anyhow!("--budgets: {e}"))?;
        let mut integrators: Vec<IntegratorKind> = Vec::new();
        for &k in &o.integrators {
            if integrators.contains(&k) {
                bail!("--integrators: {k} is listed twice");
            }
            integrators.push(k);
        }
        if integrators.is_empty() {
            integrators = IntegratorKind::all();
        }
        Ok(ComparePlan {
            integrators,
            unit: o.unit,
            budgets: o.budgets.clone(),
            settings: o.settings,
        })
    }
}

/// Runs a comparison and writes its report folder. Returns the exit code: 0, or
/// `EXIT_INTERRUPTED` when Ctrl-C stopped it (the report holds the runs finished before).
pub fn compare(o: &CompareOptions) -> Result<i32> {
    let plan = ComparePlan::new(o)?;
    let scene = &o.scene;
    let out_dir = &o.output;
    crate::commands::check_threads(o.threads)?;
    let data = load_scene(scene)?;
    // The report's files, and the reference made here, are checked before any run.
    let report_files = report::report_files(out_dir);
    let mut outputs: Vec<&Path> = report_files.iter().map(|p| p.as_path()).collect();
    let made_reference = out_dir.join("reference.exr");
    let mut inputs: Vec<&Path> = vec![scene];
    match o.reference.as_deref() {
        Some(given) => inputs.push(given),
        None => outputs.push(&made_reference),
    }
    crate::commands::check_outputs(&outputs, &inputs)?;
    if o.reference.is_none() {
        crate::commands::reference::check_reference_outputs(&made_reference, &inputs)?;
        crate::commands::check_samples("--reference-spp", o.reference_spp, &data)?;
    }
    let stop = stop_on_ctrl_c()?;
    let pool = thread_pool(o.threads)?;
    for &k in &plan.integrators {
        crate::commands::check_render_memory(k, &plan.settings, &data, pool.current_num_threads())?;
    }
    let comparison = match compare_scene(
        scene,
        data,
        o.reference.as_deref(),
        out_dir,
        &plan,
        o.reference_spp,
        &stop,
        &pool,
        o.quiet,
    )? {
        SceneRun::Done(c) => *c,
        SceneRun::ReferenceInterrupted(note) => {
            print_out(&format!("{note}\n"));
            return Ok(exit_code(true));
        }
    };
    if comparison.interrupted && comparison.results.is_empty() {
        print_out(&format!(
            "interrupted before the first run finished: no report written ({} is as it was)\n",
            out_dir.display()
        ));
        return Ok(exit_code(true));
    }
    report::write_report(&comparison, out_dir)?;
    let mut text = format!(
        "{} runs of {} on {}; reference {} ({})\nwrote {}/{{{}, {}, {}, {}, {}, {}}}\n",
        comparison.results.len(),
        comparison
            .integrators
            .iter()
            .map(|k| k.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        scene.display(),
        comparison.reference_path.display(),
        comparison.reference_note,
        out_dir.display(),
        super::files::RESULTS_CSV,
        super::files::PLOT_PNG,
        super::files::PLOT_SVG,
        super::files::GRID_PNG,
        super::files::SUMMARY_MD,
        super::files::INDEX_HTML
    );
    if comparison.interrupted {
        text += "interrupted: the report holds the runs finished before the stop\n";
    }
    print_out(&text);
    Ok(exit_code(comparison.interrupted))
}

/// How the comparison of one scene ended.
pub(crate) enum SceneRun {
    Done(Box<Comparison>),
    /// The reference was being made when a stop came: its checkpoint holds the passes done.
    ReferenceInterrupted(String),
}

/// The reference of a scene (given, or made or resumed in `out_dir`), then every run.
#[allow(clippy::too_many_arguments)]
pub(crate) fn compare_scene(
    scene: &Path,
    data: Arc<SceneData>,
    given_reference: Option<&Path>,
    out_dir: &Path,
    plan: &ComparePlan,
    reference_spp: u64,
    stop: &AtomicBool,
    pool: &rayon::ThreadPool,
    quiet: bool,
) -> Result<SceneRun> {
    let cam = data.scene.camera;
    let (width, height) = (cam.width as usize, cam.height as usize);
    let (reference_path, reference_note) = match given_reference {
        Some(path) => (path.to_path_buf(), "given with --reference".to_string()),
        None => {
            let path = out_dir.join("reference.exr");
            let job = ReferenceJob {
                scene_path: scene,
                data: data.clone(),
                integrator: IntegratorKind::named("pt"),
                settings: RenderSettings {
                    seed: DEFAULT_REFERENCE_SEED,
                    max_depth: plan.settings.max_depth,
                    ..RenderSettings::default()
                },
                budget: ReferenceBudget::SamplesPerPixel(reference_spp),
                output: &path,
                checkpoint_every: std::time::Duration::from_secs(30),
                shard: None,
            };
            if !quiet {
                eprintln!(
                    "no --reference given: using {} (pt, {reference_spp} spp; made or resumed \
                     now)",
                    path.display()
                );
            }
            let outcome = make_reference(&job, stop, pool, quiet)?;
            let note = describe_reference(&job, &outcome);
            if outcome.interrupted {
                return Ok(SceneRun::ReferenceInterrupted(format!(
                    "interrupted while making the reference: {note}; run the same command \
                     again to continue"
                )));
            }
            if !quiet {
                eprintln!("{note}");
            }
            let how = if outcome.already_complete {
                "made by an earlier compare run, with pt"
            } else {
                "made by this compare run, with pt"
            };
            (path, how.to_string())
        }
    };
    let loaded = load_reference(&reference_path, width, height)?;
    if let (Some(seed), Some(integrator)) = (loaded.seed, loaded.integrator.as_deref())
        && seed == plan.settings.seed
        && plan.integrators.iter().any(|k| k.as_str() == integrator)
    {
        eprintln!(
            "warning: {} was made by {integrator} with seed {seed}, the seed of the compared \
             renders: their errors are correlated with it; use another --seed",
            reference_path.display()
        );
    }
    let note = match loaded.spp {
        Some(spp) => format!("{reference_note}, {spp} spp"),
        None => reference_note,
    };
    let job = CompareJob {
        data,
        reference: &loaded.image,
        integrators: &plan.integrators,
        unit: plan.unit,
        budgets: &plan.budgets,
        settings: plan.settings,
    };
    // The bar counts milliseconds of time budgets, or passes of sample budgets.
    let scale = match plan.unit {
        BudgetUnit::Seconds => 1000.0,
        BudgetUnit::Spp => 1.0,
    };
    let bar = unit_bar(
        (job.total_units() * scale).ceil() as u64,
        "compare {elapsed_precise} [{bar:40}] {percent:>3}% {msg} (eta {eta})",
        quiet,
    );
    let progress = |done: f64, label: &str| {
        bar.set_position((done * scale) as u64);
        bar.set_message(label.to_string());
    };
    let (results, interrupted) = pool
        .install(|| super::run_comparison(&job, stop, &progress))
        .map_err(|e| anyhow::anyhow!("{}: {e}", reference_path.display()))?;
    bar.finish_and_clear();
    Ok(SceneRun::Done(Box::new(Comparison {
        scene_name: scene_stem(scene),
        scene_path: scene.to_path_buf(),
        width,
        height,
        threads: pool.current_num_threads(),
        reference: loaded.image,
        reference_path,
        reference_note: note,
        reference_spp: loaded.spp,
        reference_noise: loaded.noise_relmse,
        integrators: plan.integrators.clone(),
        unit: plan.unit,
        budgets: plan.budgets.clone(),
        results,
        interrupted,
        sharded: None,
    })))
}
