//! Comparisons rendered on many machines. `stagelight slurm --shards N -- compare ...` writes a
//! plan (`plan.ron`): the compare command, and every render of the study (each run of each
//! scene, and the reference a comparison makes) with the tasks 1..N that render it. A task
//! (`compare --plan plan.ron --shard I/N`, a Slurm array task or run by hand anywhere that
//! sees the folders) renders its share: shards of the runs of the unbiased integrators (PT,
//! BDPT) and of the reference, whose merged films are, bit for bit, those of one machine
//! rendering every pass; and the runs of the other integrators whole (their shards would be
//! independent runs averaged, another estimator than the one compared). Each finished shard
//! leaves its film (or image) and its statistics in the plan's parts folder, so a task stopped
//! by its time limit resumes where it stopped. `compare --plan plan.ron` then merges every
//! run's shards, measures each merged image against the reference and writes the report one
//! machine would write: the same relMSE and image means; the seconds of a run are its shards'
//! summed.
//!
//! Equal-time runs (`--budget-unit seconds`) are refused: a run of S seconds renders as many
//! passes as one machine manages in S seconds, which sharding cannot reproduce.

use super::run::{CompareOptions, ComparePlan};
use super::thesis::{self, ThesisOptions};
use super::{BudgetUnit, Comparison, RunResult, report};
use crate::commands::{
    check_outputs, check_render_memory, load_scene, print_out, scene_stem, stop_on_ctrl_c,
    thread_pool,
};
use crate::film::Image;
use crate::integrators::{Budget, Control, IntegratorKind, RenderSettings, Resume, SceneData};
use crate::reference::{
    Checkpoint, CheckpointHeader, DEFAULT_REFERENCE_SEED, PassRange, ReferenceBudget, ReferenceJob,
    checkpoint_path, load_reference, scene_fingerprint,
};
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The plan file's format version.
pub const PLAN_VERSION: u32 = 1;

/// The fewest passes a shard of a run renders: each shard pays its own setup (about 9 ms for
/// PT and BDPT at 256x256, measured), which a run's summed seconds include; 16 passes keep
/// that near 3% of PT's time (19 ms a pass there) and below 1% of BDPT's. A run of fewer
/// passes is one shard.
pub const MIN_PASSES_PER_SHARD: u64 = 16;

/// The name of a planned reference among a scene's renders.
const REFERENCE: &str = "reference";

/// What a `compare` command line asks for.
pub enum CompareRequest {
    Plain(CompareOptions),
    Thesis(ThesisOptions),
}

impl CompareRequest {
    fn threads(&self) -> Option<usize> {
        match self {
            CompareRequest::Plain(o) => o.threads,
            CompareRequest::Thesis(o) => o.threads,
        }
    }
}

/// The plan of a sharded comparison, as `plan.ron` holds it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanFile {
    pub version: u32,
    /// The compare command line (`compare ...`) as given to `stagelight slurm`.
    pub command: Vec<String>,
    /// The folder it was given in: tasks and the report run there (its relative paths are
    /// relative to it).
    pub workdir: PathBuf,
    /// Tasks (the job array's size).
    pub tasks: u64,
    /// Folder of the shards' films, the whole runs' images and their statistics.
    pub parts: PathBuf,
    pub scenes: Vec<PlannedScene>,
}

/// One scene of a plan and its renders.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannedScene {
    /// Its name in the parts folder (and the thesis' tables).
    pub key: String,
    pub scene: PathBuf,
    /// `scene_fingerprint` of the prepared scene when the plan was made: every task must
    /// render that scene.
    pub fingerprint: String,
    pub renders: Vec<PlannedRender>,
}

/// One render of a plan: a run of the comparison, or the reference it makes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannedRender {
    /// `reference`, or the run's integrator and budget (`pt-400spp`,
    /// `ppm-75passes-500000photons`).
    pub name: String,
    pub integrator: String,
    pub passes: u64,
    /// Rendered whole by one task (a biased integrator), not as shards to merge.
    pub whole: bool,
    /// The task of each shard, in pass order (one task for a whole run).
    pub tasks: Vec<u64>,
}

impl PlanFile {
    /// Writes the plan (RON, one field a line) under a temporary name and renames it.
    pub fn write(&self, path: &Path) -> Result<()> {
        let text = ron::ser::to_string_pretty(
            self,
            ron::ser::PrettyConfig::default().compact_arrays(true),
        )
        .context("cannot write the plan")?;
        crate::film::output::write_bytes(path, format!("{text}\n").as_bytes())?;
        Ok(())
    }

    /// Reads and checks a plan.
    pub fn read(path: &Path) -> Result<PlanFile> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the plan", path.display()))?;
        let plan: PlanFile = ron::from_str(&text).map_err(|e| {
            anyhow::anyhow!(
                "{}: not a plan of stagelight slurm: {}",
                path.display(),
                crate::scene::clip(&e.to_string(), 200)
            )
        })?;
        plan.check()
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Ok(plan)
    }

    fn check(&self) -> std::result::Result<(), String> {
        if self.version != PLAN_VERSION {
            return Err(format!(
                "plan version {}, but this stagelight reads version {PLAN_VERSION}: write the \
                 plan again with this stagelight slurm",
                self.version
            ));
        }
        if self.tasks == 0 {
            return Err("a plan of 0 tasks".into());
        }
        for scene in &self.scenes {
            for r in &scene.renders {
                let bad = r.tasks.is_empty()
                    || r.tasks.len() as u64 > r.passes
                    || (r.whole && r.tasks.len() != 1)
                    || r.tasks.iter().any(|&t| t == 0 || t > self.tasks);
                if bad {
                    return Err(format!(
                        "{} {}: tasks {:?} do not split {} passes among tasks 1 to {}",
                        scene.key, r.name, r.tasks, r.passes, self.tasks
                    ));
                }
            }
        }
        Ok(())
    }

    /// "3 scenes, 45 runs (27 whole, 612 shards) and 3 references (192 shards)".
    pub fn describe(&self) -> String {
        let renders = self.scenes.iter().flat_map(|s| &s.renders);
        let (mut runs, mut whole, mut shards, mut references, mut reference_shards) =
            (0, 0, 0, 0, 0);
        for r in renders {
            if r.name == REFERENCE {
                references += 1;
                reference_shards += r.tasks.len();
            } else {
                runs += 1;
                if r.whole {
                    whole += 1;
                } else {
                    shards += r.tasks.len();
                }
            }
        }
        let mut text = format!(
            "{} scene{}, {runs} runs ({whole} whole, {shards} shards)",
            self.scenes.len(),
            if self.scenes.len() == 1 { "" } else { "s" }
        );
        if references > 0 {
            text += &format!(
                " and {references} reference{} ({reference_shards} shards)",
                if references == 1 { "" } else { "s" }
            );
        }
        text
    }
}

/// A run of the study.
struct RunStudy {
    kind: IntegratorKind,
    /// The budget in the comparison's unit (samples per pixel, or passes).
    budget: f64,
    passes: u64,
    settings: RenderSettings,
    name: String,
}

impl RunStudy {
    /// A biased integrator's run is rendered whole by one task.
    fn whole(&self) -> bool {
        !self.kind.is_unbiased()
    }
}

/// A scene of the study: what one machine's `compare` (or the preset's scene) would do.
struct SceneStudy {
    key: String,
    path: PathBuf,
    report_dir: PathBuf,
    given_reference: Option<PathBuf>,
    reference_spp: u64,
    /// The comparison's integrators, unit and budgets (for the report).
    plan: ComparePlan,
    runs: Vec<RunStudy>,
}

impl SceneStudy {
    /// The reference `compare` makes for this scene when none is given.
    fn made_reference(&self) -> PathBuf {
        self.report_dir.join("reference.exr")
    }

    fn reference_settings(&self) -> RenderSettings {
        RenderSettings {
            seed: DEFAULT_REFERENCE_SEED,
            max_depth: self.plan.settings.max_depth,
            ..RenderSettings::default()
        }
    }
}

/// Every scene and run of the comparison, in the order one machine renders them.
/// One run per integrator and budget of a samples-per-pixel comparison.
fn spp_runs(plan: &ComparePlan) -> Vec<RunStudy> {
    plan.integrators
        .iter()
        .flat_map(|&kind| {
            plan.budgets.iter().map(move |&budget| RunStudy {
                kind,
                budget,
                passes: budget as u64,
                settings: plan.settings,
                name: format!("{kind}-{budget}spp"),
            })
        })
        .collect()
}

fn study_of(request: &CompareRequest) -> Result<Vec<SceneStudy>> {
    match request {
        CompareRequest::Plain(o) => {
            let plan = ComparePlan::new(o)?;
            if plan.unit == BudgetUnit::Seconds {
                bail!(
                    "--budget-unit seconds: a timed (equal-time) comparison cannot be sharded: a \
                     run of S seconds renders as many passes as one machine manages in S \
                     seconds, which shards on other machines cannot reproduce; shard it with \
                     --budget-unit spp (its equal-time table is then read from the runs' \
                     measured seconds), or run it on one machine"
                );
            }
            let runs = spp_runs(&plan);
            Ok(vec![SceneStudy {
                key: scene_stem(&o.scene),
                path: o.scene.clone(),
                report_dir: o.output.clone(),
                given_reference: o.reference.clone(),
                reference_spp: o.reference_spp,
                plan,
                runs,
            }])
        }
        CompareRequest::Thesis(o) => {
            let plan = thesis::by_spp_plan(o);
            let given = thesis::given_references(o)?;
            let biased = thesis::biased_runs_of(&plan, o)?;
            let mut scenes = Vec::new();
            for ((key, _), given) in thesis::SCENES.into_iter().zip(given) {
                let mut runs = spp_runs(&plan);
                runs.extend(
                    biased
                        .iter()
                        .map(|&(kind, passes, photons, settings)| RunStudy {
                            kind,
                            budget: passes as f64,
                            passes,
                            settings,
                            name: format!("{kind}-{passes}passes-{photons}photons"),
                        }),
                );
                scenes.push(SceneStudy {
                    key: key.to_string(),
                    path: o.scenes_dir.join(format!("{key}.ron")),
                    report_dir: o.output.join(key),
                    given_reference: given,
                    reference_spp: o.reference_spp,
                    plan: ComparePlan {
                        integrators: plan.integrators.clone(),
                        unit: plan.unit,
                        budgets: plan.budgets.clone(),
                        settings: plan.settings,
                    },
                    runs,
                });
            }
            Ok(scenes)
        }
    }
}

/// Whether the reference `compare` would make at `path` is there, finished: true when it is
/// (the plan uses it), false when there is none (the plan renders it as shards); an error when
/// one is there unfinished or made otherwise (one machine would resume or refuse it).
fn finished_reference(study: &SceneStudy, data: &SceneData) -> Result<bool> {
    let path = study.made_reference();
    let film = checkpoint_path(&path);
    if !film.exists() {
        if path.exists() {
            bail!(
                "{}: a reference without its checkpoint is in the way of the one this \
                 comparison makes: give it with --reference, or remove it",
                path.display()
            );
        }
        return Ok(false);
    }
    let found = Checkpoint::read(&film)?.header;
    let wanted = CheckpointHeader::start(
        &study.path,
        data,
        IntegratorKind::named("pt"),
        &study.reference_settings(),
        None,
    );
    let same = found.made_by == REFERENCE
        && found.shard.is_none()
        && found.first_pass == 0
        && found.integrator == wanted.integrator
        && found.seed == wanted.seed
        && found.sampler == wanted.sampler
        && found.max_depth == wanted.max_depth
        && found.settings == wanted.settings
        && (found.width, found.height) == (wanted.width, wanted.height)
        && found.scene_fingerprint == wanted.scene_fingerprint;
    if same && found.passes >= study.reference_spp {
        return Ok(true);
    }
    bail!(
        "{}: a reference is there, {}: finish it (`stagelight reference`) or remove it before \
         sharding the comparison, or give a reference with --reference",
        path.display(),
        if same {
            format!(
                "unfinished ({} of {} spp)",
                found.passes, study.reference_spp
            )
        } else {
            "made with other settings or of another scene".to_string()
        }
    )
}

/// Plans a sharded comparison of `tasks` tasks: checks the command (no timed runs), the
/// scenes (loaded now: their errors come before any job) and every output, decides for each
/// scene whether its reference is given, already made or to be rendered as shards, and gives
/// every shard and whole run a task: a render is split into as many shards as there are tasks,
/// but none of fewer than `MIN_PASSES_PER_SHARD` passes. Whole runs go first, one per task,
/// then the shards, round the tasks in turn.
pub fn make_plan(
    command: &[String],
    request: &CompareRequest,
    tasks: u64,
    parts: &Path,
    workdir: &Path,
) -> Result<PlanFile> {
    if tasks == 0 {
        bail!("--shards must be at least 1");
    }
    let studies = study_of(request)?;
    let mut scenes = Vec::new();
    for study in &studies {
        let data = load_scene(&study.path)?;
        let mut outputs = report::report_files(&study.report_dir);
        let mut inputs = vec![study.path.clone()];
        match &study.given_reference {
            Some(given) => inputs.push(given.clone()),
            None => outputs.push(study.made_reference()),
        }
        let outputs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
        let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
        check_outputs(&outputs, &inputs)?;
        if study.given_reference.is_none() {
            crate::commands::check_samples("--reference-spp", study.reference_spp, &data)?;
        }
        for run in &study.runs {
            crate::commands::check_samples("--budgets", run.passes, &data)?;
        }
        let mut renders = Vec::new();
        if study.given_reference.is_none() && !finished_reference(study, &data)? {
            renders.push(PlannedRender {
                name: REFERENCE.into(),
                integrator: "pt".into(),
                passes: study.reference_spp,
                whole: false,
                tasks: Vec::new(),
            });
        }
        renders.extend(study.runs.iter().map(|run| PlannedRender {
            name: run.name.clone(),
            integrator: run.kind.as_str().into(),
            passes: run.passes,
            whole: run.whole(),
            tasks: Vec::new(),
        }));
        scenes.push(PlannedScene {
            key: study.key.clone(),
            scene: study.path.clone(),
            fingerprint: format!("{:016x}", scene_fingerprint(&data)),
            renders,
        });
    }
    let parts_probe = parts.join("probe");
    check_outputs(&[&parts_probe], &[])?;
    // Whole runs first, one to a task, then every shard, round the tasks in turn.
    let mut next = 0u64;
    for whole in [true, false] {
        for scene in &mut scenes {
            for render in scene.renders.iter_mut().filter(|r| r.whole == whole) {
                let shards = if whole {
                    1
                } else {
                    tasks.min(render.passes / MIN_PASSES_PER_SHARD).max(1)
                };
                for _ in 0..shards {
                    render.tasks.push(next % tasks + 1);
                    next += 1;
                }
            }
        }
    }
    let plan = PlanFile {
        version: PLAN_VERSION,
        command: command.to_vec(),
        workdir: workdir.to_path_buf(),
        tasks,
        parts: parts.to_path_buf(),
        scenes,
    };
    plan.check().map_err(anyhow::Error::msg)?;
    Ok(plan)
}

/// What a finished shard or whole run records beside its film or image (written last: its
/// presence says the shard is done).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ShardStats {
    /// Wall and CPU seconds of the render call (as one machine's `compare` measures a run).
    wall_s: f64,
    cpu_s: f64,
    samples: u64,
    passes: u64,
    closest_hit_rays: u64,
    shadow_rays: u64,
    photons: u64,
    threads: usize,
}

impl ShardStats {
    fn read(path: &Path) -> Result<ShardStats> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read it", path.display()))?;
        ron::from_str(&text).map_err(|e| {
            anyhow::anyhow!(
                "{}: damaged shard statistics ({}); delete it to render the shard again",
                path.display(),
                crate::scene::clip(&e.to_string(), 200)
            )
        })
    }

    fn write(&self, path: &Path) -> Result<()> {
        let text = ron::to_string(self).context("cannot write shard statistics")?;
        crate::film::output::write_bytes(path, format!("{text}\n").as_bytes())?;
        Ok(())
    }
}

/// Where a render's shards lie: `PARTS/SCENE/NAME/`.
fn render_dir(plan: &PlanFile, scene: &PlannedScene, render: &PlannedRender) -> PathBuf {
    plan.parts.join(&scene.key).join(&render.name)
}

/// The image (or shard image, for its film beside it) of shard `j` (1-based) of a render; a
/// whole run's image is `run.exr`.
fn shard_image(dir: &Path, render: &PlannedRender, j: usize) -> PathBuf {
    if render.whole {
        dir.join("run.exr")
    } else {
        dir.join(format!("part-{j}.exr"))
    }
}

fn stats_path(image: &Path) -> PathBuf {
    image.with_extension("ron")
}

/// `compare --plan PLAN [--shard I/N]`: a task of the plan, or (without `--shard`) the report
/// from every task's shards. `threads` overrides the compare command's `--threads`;
/// `parse_command` reads the plan's compare command as the command line does (the CLI's
/// parser, handed down so this layer needs none). Returns the exit code.
pub fn run_plan(
    parse_command: fn(&[String]) -> Result<CompareRequest>,
    plan_path: &Path,
    shard: Option<(u64, u64)>,
    threads: Option<usize>,
    quiet: bool,
) -> Result<i32> {
    let plan_path = std::path::absolute(plan_path)
        .with_context(|| format!("{}: cannot find the plan", plan_path.display()))?;
    let plan = PlanFile::read(&plan_path)?;
    std::env::set_current_dir(&plan.workdir).with_context(|| {
        format!(
            "{}: cannot run in the plan's folder {}",
            plan_path.display(),
            plan.workdir.display()
        )
    })?;
    let request = parse_command(&plan.command)
        .map_err(|e| anyhow::anyhow!("{}: {e}", plan_path.display()))?;
    let studies = study_of(&request)?;
    check_plan_matches(&plan, &studies)
        .map_err(|e| anyhow::anyhow!("{}: {e}", plan_path.display()))?;
    let threads = threads.or(request.threads());
    match shard {
        Some((task, count)) => {
            if count != plan.tasks {
                bail!(
                    "--shard {task}/{count}: the plan {} has {} tasks",
                    plan_path.display(),
                    plan.tasks
                );
            }
            run_task(&plan, &studies, task, threads, quiet)
        }
        None => write_sharded_report(&plan, &plan_path, &request, &studies),
    }
}

/// The plan's runs must be those its command gives now: a plan written by another version of
/// stagelight, or edited, could make shards that do not belong together.
fn check_plan_matches(plan: &PlanFile, studies: &[SceneStudy]) -> Result<(), String> {
    let differs = |what: String| {
        Err(format!(
            "{what}: the plan's renders are not those its command makes with this stagelight \
             (written by another version, or edited); write the plan again with stagelight slurm"
        ))
    };
    if plan.scenes.len() != studies.len() {
        return differs(format!(
            "{} scenes planned, {} in the command",
            plan.scenes.len(),
            studies.len()
        ));
    }
    for (planned, study) in plan.scenes.iter().zip(studies) {
        if planned.key != study.key || planned.scene != study.path {
            return differs(format!("scene {} planned, {} now", planned.key, study.key));
        }
        let runs: Vec<&PlannedRender> = planned
            .renders
            .iter()
            .filter(|r| r.name != REFERENCE)
            .collect();
        let has_reference = runs.len() != planned.renders.len();
        if has_reference && study.given_reference.is_some() {
            return differs(format!("{}: a reference planned and given", study.key));
        }
        if runs.len() != study.runs.len() {
            return differs(format!("{}: {} runs planned", study.key, runs.len()));
        }
        for (r, s) in runs.iter().zip(&study.runs) {
            if r.name != s.name
                || r.integrator != s.kind.as_str()
                || r.passes != s.passes
                || r.whole != s.whole()
            {
                return differs(format!("{} {}", study.key, r.name));
            }
        }
    }
    Ok(())
}

/// Renders task `task`'s shards and whole runs, skipping those finished by an earlier run of
/// the task. Ctrl-C (Slurm's signal before the time limit) stops it after the passes in
/// flight: a reference shard keeps them in its checkpoint, a run's shard in flight is
/// dropped (it is rendered again, whole, by the next run), and the exit status is 130.
fn run_task(
    plan: &PlanFile,
    studies: &[SceneStudy],
    task: u64,
    threads: Option<usize>,
    quiet: bool,
) -> Result<i32> {
    let stop = stop_on_ctrl_c()?;
    let pool = thread_pool(threads)?;
    let started = Instant::now();
    let (mut rendered, mut earlier) = (0, 0);
    let stopped = |rendered: u64, earlier: u64| {
        print_out(&format!(
            "task {task}/{}: stopped; {rendered} shards rendered by this run and {earlier} \
             earlier are kept: run the task again to go on\n",
            plan.tasks
        ));
        Ok(crate::commands::EXIT_INTERRUPTED)
    };
    for (planned, study) in plan.scenes.iter().zip(studies) {
        let mine = |r: &PlannedRender| r.tasks.contains(&task);
        if !planned.renders.iter().any(mine) {
            continue;
        }
        let data = load_scene(&study.path)?;
        let fingerprint = format!("{:016x}", scene_fingerprint(&data));
        if fingerprint != planned.fingerprint {
            bail!(
                "{}: the scene is not the one planned (fingerprint {fingerprint}, planned {}): \
                 every task must render the same scene; restore it, or write the plan again",
                study.path.display(),
                planned.fingerprint
            );
        }
        let mut warmed: Vec<IntegratorKind> = Vec::new();
        for render in planned.renders.iter().filter(|r| mine(r)) {
            let dir = render_dir(plan, planned, render);
            let count = render.tasks.len() as u64;
            for (j, _) in render.tasks.iter().enumerate().filter(|(_, t)| **t == task) {
                let index = j as u64 + 1;
                let range =
                    PassRange::shard(index, count, render.passes).map_err(anyhow::Error::msg)?;
                let image = shard_image(&dir, render, j + 1);
                if render.name == REFERENCE {
                    let job = ReferenceJob {
                        scene_path: &study.path,
                        data: data.clone(),
                        integrator: IntegratorKind::named("pt"),
                        settings: study.reference_settings(),
                        budget: ReferenceBudget::SamplesPerPixel(render.passes),
                        output: &image,
                        checkpoint_every: Duration::from_secs(30),
                        shard: Some(range),
                    };
                    let outcome =
                        crate::commands::reference::make_reference(&job, &stop, &pool, quiet)?;
                    if outcome.interrupted {
                        return stopped(rendered, earlier);
                    }
                    if outcome.already_complete {
                        earlier += 1;
                    } else {
                        rendered += 1;
                    }
                    continue;
                }
                let stats = stats_path(&image);
                if stats.exists() {
                    earlier += 1;
                    continue;
                }
                let run = study
                    .runs
                    .iter()
                    .find(|r| r.name == render.name)
                    .expect("check_plan_matches found every run");
                check_render_memory(run.kind, &run.settings, &data, pool.current_num_threads())?;
                if !warmed.contains(&run.kind) {
                    pool.install(|| {
                        super::warm_up_integrator(run.kind, data.clone(), &run.settings)
                    });
                    warmed.push(run.kind);
                }
                if !quiet {
                    eprintln!(
                        "{} {}: {}",
                        planned.key,
                        render.name,
                        if render.whole {
                            "whole".to_string()
                        } else {
                            format!(
                                "shard {index}/{count}, passes {}..{}",
                                range.first, range.end
                            )
                        }
                    );
                }
                match render_shard(&data, &study.path, run, render.whole, range, &stop, &pool)? {
                    Some((film, result)) => {
                        std::fs::create_dir_all(&dir)
                            .with_context(|| format!("{}: cannot create it", dir.display()))?;
                        match film {
                            ShardFilm::Whole(image_of_run) => image_of_run.write_exr(&image)?,
                            ShardFilm::Part(checkpoint) => {
                                checkpoint.write(&checkpoint_path(&image))?
                            }
                        }
                        result.write(&stats)?;
                        rendered += 1;
                    }
                    None => return stopped(rendered, earlier),
                }
            }
        }
    }
    print_out(&format!(
        "task {task}/{}: {rendered} shards rendered in {:.1} s, {earlier} finished earlier\n",
        plan.tasks,
        started.elapsed().as_secs_f64()
    ));
    Ok(0)
}

/// What a shard leaves: a run's shard film, or a whole run's image.
enum ShardFilm {
    Part(Box<Checkpoint>),
    Whole(Image),
}

/// Renders one shard of an unbiased run (passes `range`, as `render --shard` does) or a whole
/// run, timed as `compare` times a run. None when a stop cut it short.
fn render_shard(
    data: &Arc<SceneData>,
    scene_path: &Path,
    run: &RunStudy,
    whole: bool,
    range: PassRange,
    stop: &std::sync::atomic::AtomicBool,
    pool: &rayon::ThreadPool,
) -> Result<Option<(ShardFilm, ShardStats)>> {
    let control = Control {
        stop,
        progress: &|_, _| {},
    };
    let cam = data.scene.camera;
    let pixels = cam.width as u64 * cam.height as u64;
    let cpu_start = crate::sysinfo::cpu_seconds();
    let wall_start = Instant::now();
    let mut outcome = pool.install(|| {
        if whole {
            crate::integrators::render(
                run.kind,
                data.clone(),
                &run.settings,
                Budget::SamplesPerPixel(run.passes),
                &control,
            )
        } else {
            let start = Resume::shard_start(data, range.first);
            crate::integrators::resume(
                run.kind,
                data.clone(),
                &run.settings,
                Budget::SamplesPerPixel(range.end),
                &control,
                start,
            )
        }
    });
    let wall = wall_start.elapsed().as_secs_f64();
    let cpu = crate::sysinfo::cpu_seconds() - cpu_start;
    if outcome.interrupted || outcome.passes == 0 {
        return Ok(None);
    }
    let film = if whole {
        ShardFilm::Whole(outcome.film.image())
    } else {
        // The shard's own passes and samples (a resumed render counts from pass 0).
        outcome.passes -= range.first;
        outcome.samples -= range.first * pixels;
        let film = outcome.film.clone();
        let header = CheckpointHeader {
            passes: range.end,
            seconds: outcome.wall.as_secs_f64(),
            nonfinite: film.nonfinite,
            nonfinite_splats: film.nonfinite_splats,
            out_of_range: film.out_of_range,
            made_by: "render".into(),
            ..CheckpointHeader::start(scene_path, data, run.kind, &run.settings, Some(range))
        };
        ShardFilm::Part(Box::new(Checkpoint { header, film }))
    };
    let stats = ShardStats {
        wall_s: wall,
        cpu_s: cpu,
        samples: outcome.samples,
        passes: outcome.passes,
        closest_hit_rays: outcome.closest_rays(),
        shadow_rays: outcome.shadow_rays(),
        photons: outcome.stats.get("emit_photons").map_or(0, |s| s.emitted),
        threads: pool.current_num_threads(),
    };
    Ok(Some((film, stats)))
}

/// Every shard of the plan not finished yet, as "SCENE NAME shard J/N (task T)".
fn unfinished(plan: &PlanFile) -> Vec<String> {
    let mut missing = Vec::new();
    for scene in &plan.scenes {
        for render in &scene.renders {
            let dir = render_dir(plan, scene, render);
            for (j, &task) in render.tasks.iter().enumerate() {
                let image = shard_image(&dir, render, j + 1);
                let done = if render.name == REFERENCE {
                    let range =
                        PassRange::shard(j as u64 + 1, render.tasks.len() as u64, render.passes);
                    Checkpoint::read(&checkpoint_path(&image))
                        .ok()
                        .zip(range.ok())
                        .is_some_and(|(c, r)| c.header.passes >= r.end)
                } else {
                    stats_path(&image).exists()
                };
                if !done {
                    let what = if render.whole {
                        "whole run".to_string()
                    } else {
                        format!("shard {}/{}", j + 1, render.tasks.len())
                    };
                    missing.push(format!(
                        "{} {} {what} (task {task})",
                        scene.key, render.name
                    ));
                }
            }
        }
    }
    missing
}

/// Merges every run's shards, measures the images against the references (merged first,
/// where the plan renders them) and writes the report one machine's `compare` writes.
fn write_sharded_report(
    plan: &PlanFile,
    plan_path: &Path,
    request: &CompareRequest,
    studies: &[SceneStudy],
) -> Result<i32> {
    let missing = unfinished(plan);
    if !missing.is_empty() {
        let shown: Vec<&str> = missing.iter().take(6).map(String::as_str).collect();
        let more = missing.len() - shown.len();
        bail!(
            "{}: {} shard{} not finished: {}{}; run their tasks again (stagelight compare --plan \
             {} --shard I/{}) before the report",
            plan_path.display(),
            missing.len(),
            if missing.len() == 1 { "" } else { "s" },
            shown.join(", "),
            if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            },
            plan_path.display(),
            plan.tasks
        );
    }
    let mut comparisons: Vec<(String, Comparison)> = Vec::new();
    let mut most_threads = 0;
    for (planned, study) in plan.scenes.iter().zip(studies) {
        let data = load_scene(&study.path)?;
        let cam = data.scene.camera;
        let (width, height) = (cam.width as usize, cam.height as usize);
        let planned_reference = planned.renders.iter().find(|r| r.name == REFERENCE);
        let (reference_path, note) = match (&study.given_reference, planned_reference) {
            (Some(given), _) => (given.clone(), "given with --reference".to_string()),
            (None, Some(render)) => {
                let dir = render_dir(plan, planned, render);
                let parts: Vec<PathBuf> = (1..=render.tasks.len())
                    .map(|j| shard_image(&dir, render, j))
                    .collect();
                let output = study.made_reference();
                crate::commands::merge::merge(&parts, &output)?;
                (
                    output,
                    "made by this compare run's shards, with pt".to_string(),
                )
            }
            (None, None) => (
                study.made_reference(),
                "made by an earlier compare run, with pt".to_string(),
            ),
        };
        let loaded = load_reference(&reference_path, width, height)?;
        let mut results = Vec::new();
        let runs = planned.renders.iter().filter(|r| r.name != REFERENCE);
        for (render, run) in runs.zip(&study.runs) {
            let dir = render_dir(plan, planned, render);
            let images: Vec<PathBuf> = (1..=render.tasks.len())
                .map(|j| shard_image(&dir, render, j))
                .collect();
            let stats = images
                .iter()
                .map(|i| ShardStats::read(&stats_path(i)))
                .collect::<Result<Vec<_>>>()?;
            let image = if render.whole {
                Image::read_exr(&images[0])?
            } else {
                crate::commands::merge::merged_film(&images)
                    .with_context(|| format!("{} {}", planned.key, render.name))?
                    .1
                    .image()
            };
            let metrics = crate::metrics::compare(&image, &loaded.image).map_err(|e| {
                anyhow::anyhow!(
                    "{}: {} {}: {e}",
                    reference_path.display(),
                    planned.key,
                    render.name
                )
            })?;
            most_threads = stats
                .iter()
                .map(|s| s.threads)
                .fold(most_threads, usize::max);
            results.push(RunResult {
                integrator: run.kind,
                budget: run.budget,
                wall: stats.iter().map(|s| s.wall_s).sum(),
                cpu: stats.iter().map(|s| s.cpu_s).sum(),
                samples: stats.iter().map(|s| s.samples).sum(),
                passes: stats.iter().map(|s| s.passes).sum(),
                closest_rays: stats.iter().map(|s| s.closest_hit_rays).sum(),
                shadow_rays: stats.iter().map(|s| s.shadow_rays).sum(),
                photons: stats.iter().map(|s| s.photons).sum(),
                metrics,
                image,
            });
        }
        let note = match loaded.spp {
            Some(spp) => format!("{note}, {spp} spp"),
            None => note,
        };
        comparisons.push((
            study.key.clone(),
            Comparison {
                scene_name: scene_stem(&study.path),
                scene_path: study.path.clone(),
                width,
                height,
                threads: 0,
                reference: loaded.image,
                reference_path,
                reference_note: note,
                reference_spp: loaded.spp,
                reference_noise: loaded.noise_relmse,
                integrators: study.plan.integrators.clone(),
                unit: study.plan.unit,
                budgets: study.plan.budgets.clone(),
                results,
                interrupted: false,
                sharded: None,
            },
        ));
    }
    let note = sharded_note(plan, plan_path, most_threads);
    for ((_, c), study) in comparisons.iter_mut().zip(studies) {
        c.threads = most_threads;
        c.sharded = Some(note.clone());
        match &request {
            CompareRequest::Thesis(o) => {
                thesis::write_scene_report(c, &study.report_dir, &o.photon_budgets)?
            }
            CompareRequest::Plain(_) => report::write_report(c, &study.report_dir)?,
        }
    }
    let mut text = String::new();
    for ((key, c), study) in comparisons.iter().zip(studies) {
        text += &format!(
            "{key}: {} runs merged from the shards of {} tasks; wrote {}/{{{}, {}, {}, {}, {}}}\n",
            c.results.len(),
            plan.tasks,
            study.report_dir.display(),
            super::files::RESULTS_CSV,
            super::files::PLOT_PNG,
            super::files::PLOT_SVG,
            super::files::GRID_PNG,
            super::files::SUMMARY_MD
        );
    }
    if let CompareRequest::Thesis(o) = request {
        let scenes: Vec<thesis::SceneResult> = thesis::SCENES
            .iter()
            .map(|(key, _)| thesis::SceneResult {
                key,
                comparison: comparisons.iter().find(|(k, _)| k == key).map(|(_, c)| c),
            })
            .collect();
        let summary = o.output.join(super::files::SUMMARY_MD);
        crate::film::output::write_bytes(
            &summary,
            thesis::summary_markdown(&scenes, most_threads, &o.photon_budgets, Some(&note))
                .as_bytes(),
        )?;
        let csv = o.output.join(super::files::RESULTS_CSV);
        let all: Vec<(&str, &Comparison)> =
            comparisons.iter().map(|(k, c)| (k.as_str(), c)).collect();
        thesis::write_csv(&all, &csv)?;
        thesis::write_index(&o.output, &scenes)?;
        text += &format!(
            "thesis preset: wrote {} and {}\n",
            summary.display(),
            csv.display()
        );
    }
    print_out(&text);
    Ok(0)
}

/// The summary's paragraph on how a sharded comparison's figures were made.
fn sharded_note(plan: &PlanFile, plan_path: &Path, threads: usize) -> String {
    let unbiased: Vec<&str> = IntegratorKind::all()
        .into_iter()
        .filter(|k| k.is_unbiased())
        .map(|k| k.as_str())
        .collect();
    format!(
        "Rendered as shards by the {} tasks of the plan `{}` (`stagelight slurm`), up to \
         {threads} threads each. A run's wall and CPU seconds are the sums of its shards' (each \
         shard pays its own setup), so they compare integrators only where the tasks ran on \
         alike machines; its relMSE is that of its merged image, which for {} is bit for bit \
         the image one machine renders. The other integrators' runs were each rendered whole \
         by one task.",
        plan.tasks,
        plan_path.display(),
        unbiased.join(" and ")
    )
}
