//! The `stagelight` command line: render, reference, compare, diff and bench.

use crate::compare::{BudgetUnit, CompareJob, Comparison, report, thesis};
use crate::film::Image;
use crate::integrators::{
    Budget, Control, IntegratorKind, RenderOutcome, RenderSettings, SceneData,
};
use crate::path::MisHeuristic;
use crate::sysinfo::{cpu_seconds, peak_memory_bytes};
use crate::reference::{
    DEFAULT_REFERENCE_SEED, ReferenceBudget, ReferenceJob, checkpoint_path, load_reference,
    render_reference,
};
use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

#[derive(Parser, Debug)]
#[command(
    name = "stagelight",
    version,
    about = "A data-oriented wavefront CPU renderer"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Renders a scene to an EXR (float32 linear RGB) with a PNG preview beside it.
    Render(RenderArgs),
    /// Renders a long reference, checkpointed: run it again to resume or extend it.
    Reference(ReferenceArgs),
    /// Renders each integrator at each budget and writes a report folder of speed against
    /// error: results.csv, error_vs_time.png/.svg, grid.png, summary.md.
    Compare(CompareArgs),
    /// Prints the error of an image against a reference: relMSE, RMSE, MAE, channel means.
    Diff { image: PathBuf, reference: PathBuf },
    /// Renders a scene several times at a fixed budget and prints throughput as a table.
    Bench {
        scene: PathBuf,
        #[arg(long, default_value = "pt", value_parser = parse_integrator)]
        integrator: IntegratorKind,
        /// Samples per pixel of each timed run.
        #[arg(long, default_value_t = 32, value_parser = clap::value_parser!(u64).range(1..))]
        spp: u64,
        /// Timed runs (after one warm-up run); the table gives their median and spread.
        #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..))]
        runs: u32,
        /// Worker threads (default: all cores).
        #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
        threads: Option<u64>,
    },
}

/// Parses an integrator name: unknown names and planned-but-unbuilt ones are clear errors.
fn parse_integrator(s: &str) -> std::result::Result<IntegratorKind, String> {
    IntegratorKind::from_name(s).map_err(|e| e.to_string())
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Scene file (RON).
    pub scene: PathBuf,
    #[arg(long, default_value = "pt", value_parser = parse_integrator)]
    pub integrator: IntegratorKind,
    /// Samples per pixel (default 64 unless --time is given). A pass is one sample per
    /// pixel, so this is also the number of passes (ppm, sppm).
    #[arg(long, visible_alias = "passes", conflicts_with = "time", value_parser = clap::value_parser!(u64).range(1..))]
    pub spp: Option<u64>,
    /// Render for this many wall-clock seconds (whole passes).
    #[arg(long, value_parser = parse_seconds)]
    pub time: Option<f64>,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub threads: Option<u64>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub photons: PhotonArgs,
    /// Maximum number of bounces (default: unlimited; Russian roulette ends paths).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// MIS heuristic of bidirectional strategies (bdpt).
    #[arg(long, value_enum, default_value_t = MisName::Power)]
    pub mis: MisName,
    /// Also write each strategy's weighted contribution as DIR/s{S}_t{T}.exr (bdpt).
    #[arg(long, value_name = "DIR")]
    pub strategy_images: Option<PathBuf>,
    /// Output EXR (default render/SCENE_INTEGRATOR.exr); a PNG preview is written beside it.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Options of the photon mappers.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct PhotonArgs {
    /// Photons traced per pass (ppm, sppm).
    #[arg(long, default_value_t = crate::integrators::sppm::DEFAULT_PHOTONS_PER_PASS, value_parser = clap::value_parser!(u64).range(1..))]
    pub photons_per_pass: u64,
    /// Fraction of each pass's photons a pixel keeps, in (0, 1) (ppm, sppm).
    #[arg(long, default_value_t = crate::integrators::sppm::DEFAULT_ALPHA, value_parser = parse_alpha)]
    pub alpha: f32,
    /// Initial gather radius in scene units (ppm, sppm; default: 0.5% of the scene's
    /// bounding-box diagonal).
    #[arg(long, value_parser = parse_radius)]
    pub radius: Option<f32>,
    /// Photons traced for the photon maps (pm).
    #[arg(long, default_value_t = crate::integrators::pm::DEFAULT_PHOTONS, value_parser = clap::value_parser!(u64).range(1..))]
    pub photons: u64,
    /// Photons per density estimate (pm; at least 2: the estimate sums the k - 1 nearest over
    /// the disc through the k-th).
    #[arg(long, default_value_t = crate::integrators::pm::DEFAULT_K as u32, value_parser = clap::value_parser!(u32).range(2..))]
    pub k: u32,
    /// Largest density-estimate radius in scene units (pm; default: 2% of the scene's
    /// bounding-box diagonal).
    #[arg(long, value_parser = parse_radius)]
    pub max_radius: Option<f32>,
    /// Take indirect light straight from the global photon map instead of final gathering
    /// (pm).
    #[arg(long)]
    pub no_final_gather: bool,
}

impl PhotonArgs {
    pub fn settings(&self) -> crate::integrators::PhotonSettings {
        crate::integrators::PhotonSettings {
            photons_per_pass: self.photons_per_pass,
            alpha: self.alpha,
            radius: self.radius,
            photons: self.photons,
            k: self.k as usize,
            max_radius: self.max_radius,
            final_gather: !self.no_final_gather,
        }
    }
}

fn parse_alpha(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v > 0.0 && v < 1.0 => Ok(v),
        _ => Err(format!("alpha must be a number in (0, 1), not {s}")),
    }
}

fn parse_radius(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("the radius must be a positive number, not {s}")),
    }
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum MisName {
    /// Veach's power heuristic (exponent 2).
    Power,
    /// The balance heuristic.
    Balance,
}

impl MisName {
    pub fn heuristic(self) -> MisHeuristic {
        match self {
            MisName::Power => MisHeuristic::Power,
            MisName::Balance => MisHeuristic::Balance,
        }
    }
}

/// Samples per pixel of a reference when neither --spp nor --time is given.
pub const DEFAULT_REFERENCE_SPP: u64 = 4096;

#[derive(clap::Args, Debug)]
pub struct ReferenceArgs {
    /// Scene file (RON).
    pub scene: PathBuf,
    /// An unbiased integrator: pt or bdpt.
    #[arg(long, default_value = "pt", value_parser = parse_integrator)]
    pub integrator: IntegratorKind,
    /// Total samples per pixel, over all runs (default 4096 unless --time is given).
    #[arg(long, conflicts_with = "time", value_parser = clap::value_parser!(u64).range(1..))]
    pub spp: Option<u64>,
    /// Total render seconds, over all runs (whole passes).
    #[arg(long, value_parser = parse_seconds)]
    pub time: Option<f64>,
    /// Seed (default: a reference seed that ordinary renders do not use).
    #[arg(long, default_value_t = DEFAULT_REFERENCE_SEED)]
    pub seed: u64,
    /// Maximum number of bounces (default: unlimited).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub threads: Option<u64>,
    /// Output EXR (default reference/SCENE_INTEGRATOR.exr); REF.exr.checkpoint and a PNG
    /// preview go beside it.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Seconds between checkpoints.
    #[arg(long, default_value = "30", value_parser = parse_seconds)]
    pub checkpoint_every: f64,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Samples per pixel of the reference that compare makes when none is given.
pub const DEFAULT_COMPARE_REFERENCE_SPP: u64 = 4096;

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum BudgetUnitArg {
    Seconds,
    Spp,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum Preset {
    /// The 2016 study stagelight grew from (Kouhzadi, UCLA): three scenes, PT/BDPT/MLT at 25, 400 and 841 spp, PM/PPM at
    /// 250k and 500k photons per pass, its times beside ours.
    Thesis,
}

#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// Scene file (RON); not with --preset.
    #[arg(required_unless_present = "preset", conflicts_with = "preset")]
    pub scene: Option<PathBuf>,
    /// Reference EXR of the scene (default: made with `reference` in the output folder, or
    /// resumed from there, at --reference-spp).
    #[arg(long, conflicts_with = "preset")]
    pub reference: Option<PathBuf>,
    /// Integrators to compare, comma-separated (default: every integrator built; built: pt;
    /// planned: bdpt, pm, ppm, sppm, mlt).
    #[arg(long, value_delimiter = ',', value_parser = parse_integrator, conflicts_with = "preset")]
    pub integrators: Vec<IntegratorKind>,
    /// Budgets, comma-separated and strictly increasing, in --budget-unit.
    #[arg(long, value_delimiter = ',', value_parser = parse_budget, default_value = "1,2,4,8",
          conflicts_with = "preset")]
    pub budgets: Vec<f64>,
    #[arg(long, value_enum, default_value_t = BudgetUnitArg::Seconds, conflicts_with = "preset")]
    pub budget_unit: BudgetUnitArg,
    /// Report folder (default compare/SCENE, or compare/thesis with --preset thesis).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Seed of the compared renders (the reference has its own).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Maximum number of bounces (default: unlimited).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub threads: Option<u64>,
    /// Samples per pixel of a reference this command makes.
    #[arg(long, default_value_t = DEFAULT_COMPARE_REFERENCE_SPP,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub reference_spp: u64,
    /// Runs a fixed experiment instead of SCENE and --budgets.
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
    /// Where --preset finds its scenes.
    #[arg(long, default_value = "scenes")]
    pub scenes_dir: PathBuf,
    /// Photons per pass of the thesis preset's biased runs (PM traces this many in all).
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u64).range(1..),
          default_values_t = crate::compare::thesis::PHOTONS_PER_PASS)]
    pub thesis_photons: Vec<u64>,
    #[command(flatten)]
    pub photons: PhotonArgs,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// One budget of --budgets (the list as a whole is checked after parsing).
fn parse_budget(s: &str) -> std::result::Result<f64, String> {
    if s.trim().is_empty() {
        return Err("the budget list is empty (or has an empty entry)".into());
    }
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("budget {s} is not a positive number"))
    }
}

fn parse_seconds(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("'{s}' is not a number of seconds"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!(
            "the time must be a positive number of seconds, not {s}"
        ))
    }
}

/// Exit code of an interrupted render that saved its finished passes.
pub const EXIT_INTERRUPTED: i32 = 130;

/// Runs the command line; returns the process exit code (0 success, 1 error, 130 interrupted).
pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { 1 } else { 0 };
            let _ = e.print();
            return code;
        }
    };
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            1
        }
    }
}

fn run(cli: Cli) -> Result<i32> {
    match cli.command {
        Command::Render(args) => render_command(&args),
        Command::Reference(args) => reference_command(&args),
        Command::Compare(args) => compare_command(&args),
        Command::Diff { image, reference } => {
            diff_command(&image, &reference)?;
            Ok(0)
        }
        Command::Bench {
            scene,
            integrator,
            spp,
            runs,
            threads,
        } => {
            bench_command(&scene, integrator, spp, runs, threads.map(|t| t as usize))?;
            Ok(0)
        }
    }
}

fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        builder = builder.num_threads(n);
    }
    builder.build().context("cannot start the worker threads")
}

/// Loads and prepares a scene, printing its warnings.
pub fn load_scene(path: &Path) -> Result<Arc<SceneData>> {
    let scene = crate::scene::load(path)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    Ok(Arc::new(SceneData::new(scene)))
}

fn render_command(args: &RenderArgs) -> Result<i32> {
    let data = load_scene(&args.scene)?;
    let budget = match (args.spp, args.time) {
        (_, Some(t)) => Budget::Seconds(t),
        (Some(spp), None) => Budget::SamplesPerPixel(spp),
        (None, None) => Budget::SamplesPerPixel(64),
    };
    let output = args.output.clone().unwrap_or_else(|| {
        let stem = args
            .scene
            .file_stem()
            .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
        PathBuf::from("render").join(format!("{stem}_{}.exr", args.integrator.as_str()))
    });
    if output
        .extension()
        .is_none_or(|e| !e.eq_ignore_ascii_case("exr"))
    {
        bail!("{}: the output must be an .exr file", output.display());
    }
    let stop = stop_on_ctrl_c()?;
    let pool = thread_pool(args.threads.map(|t| t as usize))?;
    let threads = pool.current_num_threads();
    let bar = progress_bar(budget, args.quiet);
    let progress = |done: u64, _total: Option<u64>| match budget {
        Budget::SamplesPerPixel(_) => bar.set_position(done),
        Budget::Seconds(_) => {
            bar.set_position(bar.elapsed().as_secs().min(bar.length().unwrap_or(0)))
        }
    };
    let control = Control {
        stop: &stop,
        progress: &progress,
    };
    if args.strategy_images.is_some() && args.integrator != IntegratorKind::Bdpt {
        bail!("--strategy-images needs --integrator bdpt");
    }
    let settings = RenderSettings {
        seed: args.seed,
        max_depth: args.max_depth.unwrap_or(u32::MAX),
        mis: args.mis.heuristic(),
        strategy_images: args.strategy_images.is_some(),
        photons: args.photons.settings(),
    };
    let cpu_start = cpu_seconds();
    let outcome = pool.install(|| {
        crate::integrators::render(args.integrator, data.clone(), &settings, budget, &control)
    });
    let cpu = cpu_seconds() - cpu_start;
    bar.finish_and_clear();

    let image = outcome.film.image();
    image.write_exr(&output)?;
    let png = output.with_extension("png");
    image.write_png(&png)?;
    if let Some(dir) = &args.strategy_images {
        for (name, layer) in &outcome.layers {
            layer.write_exr(&dir.join(format!("{name}.exr")))?;
        }
    }
    let mut report = render_report(&args.scene, args.integrator, threads, &outcome, cpu, &data);
    report += &format!("wrote {} and {}\n", output.display(), png.display());
    if outcome.interrupted {
        report += &format!(
            "interrupted: saved the {} finished passes ({} samples)\n",
            outcome.passes, outcome.samples
        );
    }
    print_out(&report);
    if outcome.interrupted {
        return Ok(EXIT_INTERRUPTED);
    }
    Ok(0)
}

/// A flag Ctrl-C sets: renders stop after the passes in flight. A second Ctrl-C while files
/// are being written has no further effect.
fn stop_on_ctrl_c() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("cannot install the Ctrl-C handler")?;
    Ok(stop)
}

fn progress_bar(budget: Budget, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let (len, unit) = match budget {
        Budget::SamplesPerPixel(spp) => (spp, "passes"),
        Budget::Seconds(s) => (s.ceil() as u64, "s"),
    };
    let bar = indicatif::ProgressBar::new(len);
    let style = indicatif::ProgressStyle::with_template(&format!(
        "{{elapsed_precise}} [{{bar:40}}] {{pos}}/{{len}} {unit} (eta {{eta}})"
    ))
    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
    bar.set_style(style);
    bar
}

fn mega(x: f64) -> String {
    if x >= 1e6 {
        format!("{:.3} M", x / 1e6)
    } else if x >= 1e3 {
        format!("{:.3} k", x / 1e3)
    } else {
        // Small rates (passes/s) keep two decimals.
        format!("{x:.2}")
    }
}

/// Writes to stdout, ignoring a closed pipe (`stagelight render ... | head` is fine).
fn print_out(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = out.write_all(text.as_bytes()).and_then(|_| out.flush());
}

/// The end-of-render report.
pub fn render_report(
    scene: &Path,
    integrator: IntegratorKind,
    threads: usize,
    o: &RenderOutcome,
    cpu: f64,
    data: &SceneData,
) -> String {
    use std::fmt::Write;
    let mut r = String::new();
    let wall = o.wall.as_secs_f64();
    let cam = data.scene.camera;
    let _ = writeln!(
        r,
        "{} with {} at {}x{}, {} threads",
        scene.display(),
        integrator.as_str(),
        cam.width,
        cam.height,
        threads
    );
    let _ = writeln!(
        r,
        "  passes            {} ({} samples)",
        o.passes, o.samples
    );
    let _ = writeln!(
        r,
        "  time              {wall:.3} s wall, {cpu:.2} s CPU ({:.2} cores busy)",
        cpu / wall.max(1e-9)
    );
    let _ = writeln!(r, "  samples/s         {}", mega(o.samples as f64 / wall));
    let _ = writeln!(
        r,
        "  closest-hit rays  {} ({}rays/s)",
        o.closest_rays(),
        mega(o.closest_rays() as f64 / wall)
    );
    let _ = writeln!(
        r,
        "  shadow rays       {} ({}rays/s)",
        o.shadow_rays(),
        mega(o.shadow_rays() as f64 / wall)
    );
    if let Some(emit) = o.stats.get("emit_photons") {
        let _ = writeln!(
            r,
            "  photons           {} emitted ({}photons/s), {} passes/s",
            emit.emitted,
            mega(emit.emitted as f64 / wall),
            format_args!("{:.2}", o.passes as f64 / wall)
        );
    }
    let _ = writeln!(
        r,
        "  NaN/Inf samples   {} (counted, never added)",
        o.film.nonfinite
    );
    let _ = writeln!(
        r,
        "  memory            peak {:.1} MiB; {} paths in flight x {} bytes/path = {:.1} MiB",
        peak_memory_bytes() as f64 / (1 << 20) as f64,
        o.wavefront,
        o.bytes_per_path,
        (o.wavefront * o.bytes_per_path) as f64 / (1 << 20) as f64
    );
    let _ = writeln!(
        r,
        "  systems           time share   runs   items taken -> emitted"
    );
    for (s, share) in o.stats.time_shares() {
        let (name, runs, taken, emitted) = (s.name, s.runs, s.taken, s.emitted);
        let _ = writeln!(
            r,
            "    {name:<32} {share:>6.1}% {runs:>6} {taken:>14} -> {emitted}"
        );
    }
    r
}

fn diff_command(image: &Path, reference: &Path) -> Result<()> {
    let a = Image::read_exr(image)?;
    let b = Image::read_exr(reference)?;
    let m = crate::metrics::compare(&a, &b)
        .with_context(|| format!("{} against {}", image.display(), reference.display()))?;
    use std::fmt::Write;
    let mut t = String::new();
    let _ = writeln!(t, "{} against {}", image.display(), reference.display());
    let _ = writeln!(t, "  relMSE  {:.6e}", m.relmse);
    let _ = writeln!(t, "  RMSE    {:.6e}", m.rmse);
    let _ = writeln!(t, "  MAE     {:.6e}", m.mae);
    let _ = writeln!(
        t,
        "  mean    ({:.6}, {:.6}, {:.6}) against ({:.6}, {:.6}, {:.6})",
        m.mean.x, m.mean.y, m.mean.z, m.reference_mean.x, m.reference_mean.y, m.reference_mean.z
    );
    print_out(&t);
    Ok(())
}

fn bench_command(
    scene: &Path,
    integrator: IntegratorKind,
    spp: u64,
    runs: u32,
    threads: Option<usize>,
) -> Result<()> {
    let data = load_scene(scene)?;
    let pool = thread_pool(threads)?;
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    let run_once = |seed: u64| {
        let cpu0 = cpu_seconds();
        let t = Instant::now();
        let settings = RenderSettings {
            seed,
            ..RenderSettings::default()
        };
        let o = pool.install(|| {
            crate::integrators::render(
                integrator,
                data.clone(),
                &settings,
                Budget::SamplesPerPixel(spp),
                &control,
            )
        });
        let wall = t.elapsed().as_secs_f64();
        (o, wall, cpu_seconds() - cpu0)
    };
    run_once(1_000_000); // warm-up
    let mut samples_per_s = Vec::new();
    let mut closest_per_s = Vec::new();
    let mut shadow_per_s = Vec::new();
    let mut photons_per_s = Vec::new();
    let mut passes_per_s = Vec::new();
    let mut last = None;
    for r in 0..runs {
        let (o, wall, cpu) = run_once(r as u64);
        samples_per_s.push(o.samples as f64 / wall);
        closest_per_s.push(o.closest_rays() as f64 / wall);
        shadow_per_s.push(o.shadow_rays() as f64 / wall);
        if let Some(emit) = o.stats.get("emit_photons") {
            photons_per_s.push(emit.emitted as f64 / wall);
            passes_per_s.push(o.passes as f64 / wall);
        }
        last = Some((o, cpu));
    }
    use std::fmt::Write;
    let (o, cpu) = last.expect("at least one run");
    let mut t = String::new();
    let _ = writeln!(
        t,
        "bench {} ({}, {} spp, {} runs after a warm-up, {} threads)",
        scene.display(),
        integrator.as_str(),
        spp,
        runs,
        pool.current_num_threads()
    );
    let _ = writeln!(t, "| measure | median | min | max |");
    let _ = writeln!(t, "|---|---|---|---|");
    for (name, v) in [
        ("samples/s", &mut samples_per_s),
        ("closest-hit rays/s", &mut closest_per_s),
        ("shadow rays/s", &mut shadow_per_s),
        ("photons/s", &mut photons_per_s),
        ("passes/s", &mut passes_per_s),
    ] {
        if v.is_empty() {
            continue; // no photons
        }
        v.sort_by(f64::total_cmp);
        let _ = writeln!(
            t,
            "| {name} | {} | {} | {} |",
            mega(v[v.len() / 2]),
            mega(v[0]),
            mega(v[v.len() - 1])
        );
    }
    let _ = writeln!(t, "| bytes per path in flight | {} | | |", o.bytes_per_path);
    let _ = writeln!(t, "| paths in flight | {} | | |", o.wavefront);
    let _ = writeln!(
        t,
        "| peak memory | {:.1} MiB | | |",
        peak_memory_bytes() as f64 / (1 << 20) as f64
    );
    let _ = writeln!(
        t,
        "| CPU s / wall s (last run) | {:.2} | | |",
        cpu / o.wall.as_secs_f64()
    );
    let _ = writeln!(
        t,
        "| NaN/Inf samples (last run) | {} | | |",
        o.film.nonfinite
    );
    let _ = writeln!(t);
    let _ = writeln!(
        t,
        "| system (last run) | time share | runs | taken | emitted |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|");
    for (s, share) in o.stats.time_shares() {
        let (name, runs, taken, emitted) = (s.name, s.runs, s.taken, s.emitted);
        let _ = writeln!(t, "| {name} | {share:.1}% | {runs} | {taken} | {emitted} |");
    }
    print_out(&t);
    Ok(())
}

fn scene_stem(scene: &Path) -> String {
    scene
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy().into_owned())
}

/// A bar over `len` units whose position the caller sets; hidden when quiet.
fn unit_bar(len: u64, template: &str, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len.max(1));
    let style = indicatif::ProgressStyle::with_template(template)
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
    bar.set_style(style);
    bar
}

/// Makes or continues a reference, with a progress bar in its budget's unit; prints what it
/// did. Returns the outcome (interrupted or not).
fn make_reference(
    job: &ReferenceJob,
    stop: &AtomicBool,
    pool: &rayon::ThreadPool,
    quiet: bool,
) -> Result<crate::reference::ReferenceOutcome> {
    let (len, unit) = match job.budget {
        ReferenceBudget::SamplesPerPixel(spp) => (spp, "spp"),
        ReferenceBudget::Seconds(s) => (s.ceil() as u64, "s"),
    };
    let bar = unit_bar(
        len,
        &format!("reference {{elapsed_precise}} [{{bar:40}}] {{pos}}/{{len}} {unit} (eta {{eta}})"),
        quiet,
    );
    let progress = |done: f64, _target: f64| bar.set_position(done as u64);
    let outcome = pool.install(|| render_reference(job, stop, &progress))?;
    bar.finish_and_clear();
    Ok(outcome)
}

fn describe_reference(job: &ReferenceJob, o: &crate::reference::ReferenceOutcome) -> String {
    let file = job.output.display();
    let what = format!(
        "{} at {} spp ({:.1} s of rendering), seed {}, {}",
        job.integrator,
        o.passes,
        o.seconds,
        job.settings.seed,
        job.scene_path.display()
    );
    if o.already_complete {
        format!("{file}: already complete with {what}; nothing rendered")
    } else if o.passes_before > 0 {
        format!("{file}: resumed from {} spp to {what}", o.passes_before)
    } else {
        format!("{file}: made with {what}")
    }
}

fn reference_command(args: &ReferenceArgs) -> Result<i32> {
    if !args.integrator.is_unbiased() {
        bail!(
            "--integrator {}: a reference needs an unbiased integrator (pt or bdpt)",
            args.integrator
        );
    }
    let data = load_scene(&args.scene)?;
    let output = args.output.clone().unwrap_or_else(|| {
        PathBuf::from("reference").join(format!(
            "{}_{}.exr",
            scene_stem(&args.scene),
            args.integrator
        ))
    });
    if output
        .extension()
        .is_none_or(|e| !e.eq_ignore_ascii_case("exr"))
    {
        bail!("{}: the output must be an .exr file", output.display());
    }
    let budget = match (args.spp, args.time) {
        (_, Some(t)) => ReferenceBudget::Seconds(t),
        (Some(spp), None) => ReferenceBudget::SamplesPerPixel(spp),
        (None, None) => ReferenceBudget::SamplesPerPixel(DEFAULT_REFERENCE_SPP),
    };
    let stop = stop_on_ctrl_c()?;
    let pool = thread_pool(args.threads.map(|t| t as usize))?;
    let job = ReferenceJob {
        scene_path: &args.scene,
        data,
        integrator: args.integrator,
        settings: RenderSettings {
            seed: args.seed,
            max_depth: args.max_depth.unwrap_or(u32::MAX),
            ..RenderSettings::default()
        },
        budget,
        output: &output,
        checkpoint_every: std::time::Duration::from_secs_f64(args.checkpoint_every),
    };
    let outcome = make_reference(&job, &stop, &pool, args.quiet)?;
    let mut report = describe_reference(&job, &outcome) + "\n";
    report += &format!(
        "  {} threads, {:.1} s this run, {} NaN/Inf samples; checkpoint {}\n",
        pool.current_num_threads(),
        outcome.seconds_this_run,
        outcome.nonfinite,
        checkpoint_path(&output).display()
    );
    if outcome.interrupted {
        report += &format!(
            "interrupted: {} holds the {} finished passes; run the same command again to \
             continue\n",
            output.display(),
            outcome.passes
        );
    }
    print_out(&report);
    Ok(if outcome.interrupted {
        EXIT_INTERRUPTED
    } else {
        0
    })
}

/// The checked settings of a comparison.
struct ComparePlan {
    integrators: Vec<IntegratorKind>,
    unit: BudgetUnit,
    budgets: Vec<f64>,
    settings: RenderSettings,
}

fn compare_plan(args: &CompareArgs) -> Result<ComparePlan> {
    let unit = match args.budget_unit {
        BudgetUnitArg::Seconds => BudgetUnit::Seconds,
        BudgetUnitArg::Spp => BudgetUnit::Spp,
    };
    crate::compare::validate_budgets(&args.budgets, unit)
        .map_err(|e| anyhow::anyhow!("--budgets: {e}"))?;
    let mut integrators: Vec<IntegratorKind> = Vec::new();
    for &k in &args.integrators {
        if integrators.contains(&k) {
            bail!("--integrators: {k} is listed twice");
        }
        integrators.push(k);
    }
    if integrators.is_empty() {
        integrators = IntegratorKind::BUILT.to_vec();
    }
    Ok(ComparePlan {
        integrators,
        unit,
        budgets: args.budgets.clone(),
        settings: RenderSettings {
            seed: args.seed,
            max_depth: args.max_depth.unwrap_or(u32::MAX),
            photons: args.photons.settings(),
            ..RenderSettings::default()
        },
    })
}

fn compare_command(args: &CompareArgs) -> Result<i32> {
    if args.preset == Some(Preset::Thesis) {
        return thesis_command(args);
    }
    let plan = compare_plan(args)?;
    let scene = args
        .scene
        .clone()
        .context("a scene file is needed (or --preset thesis)")?;
    let out_dir = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from("compare").join(scene_stem(&scene)));
    let stop = stop_on_ctrl_c()?;
    let pool = thread_pool(args.threads.map(|t| t as usize))?;
    let data = load_scene(&scene)?;
    let (comparison, interrupted) = match compare_scene(
        &scene,
        data,
        args.reference.as_deref(),
        &out_dir,
        &plan,
        args.reference_spp,
        &stop,
        &pool,
        args.quiet,
    )? {
        SceneRun::Done(c) => {
            let interrupted = c.interrupted;
            (*c, interrupted)
        }
        SceneRun::ReferenceInterrupted(note) => {
            print_out(&format!("{note}\n"));
            return Ok(EXIT_INTERRUPTED);
        }
    };
    report::write_report(&comparison, &out_dir)?;
    let mut text = format!(
        "{} runs of {} on {}; reference {} ({})\nwrote {}/{{{}, {}, {}, {}, {}}}\n",
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
        report::RESULTS_CSV,
        report::PLOT_PNG,
        report::PLOT_SVG,
        report::GRID_PNG,
        report::SUMMARY_MD
    );
    if interrupted {
        text += "interrupted: the report holds the runs finished before the stop\n";
    }
    print_out(&text);
    Ok(if interrupted { EXIT_INTERRUPTED } else { 0 })
}

enum SceneRun {
    Done(Box<Comparison>),
    /// The reference was being made when a stop came: its checkpoint holds the passes done.
    ReferenceInterrupted(String),
}

/// The reference of a scene (given, or made or resumed in `out_dir`), then every run.
#[allow(clippy::too_many_arguments)]
fn compare_scene(
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
                integrator: IntegratorKind::Pt,
                settings: RenderSettings {
                    seed: DEFAULT_REFERENCE_SEED,
                    max_depth: plan.settings.max_depth,
                    ..RenderSettings::default()
                },
                budget: ReferenceBudget::SamplesPerPixel(reference_spp),
                output: &path,
                checkpoint_every: std::time::Duration::from_secs(30),
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
        .install(|| crate::compare::run_comparison(&job, stop, &progress))
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
        integrators: plan.integrators.clone(),
        unit: plan.unit,
        budgets: plan.budgets.clone(),
        results,
        interrupted,
    })))
}

/// `compare --preset thesis`: the three scenes of the study, its budgets, its tables.
fn thesis_command(args: &CompareArgs) -> Result<i32> {
    let out_dir = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from("compare").join("thesis"));
    let integrators = thesis::unbiased_built();
    let plan = ComparePlan {
        integrators,
        unit: BudgetUnit::Spp,
        budgets: thesis::UNBIASED_SPP.iter().map(|&s| s as f64).collect(),
        settings: RenderSettings {
            seed: args.seed,
            max_depth: args.max_depth.unwrap_or(u32::MAX),
            ..RenderSettings::default()
        },
    };
    let stop = stop_on_ctrl_c()?;
    let pool = thread_pool(args.threads.map(|t| t as usize))?;
    let mut comparisons: Vec<(&'static str, Comparison)> = Vec::new();
    let mut interrupted = false;
    for (key, _label) in thesis::SCENES {
        let scene = args.scenes_dir.join(format!("{key}.ron"));
        let data = load_scene(&scene)?;
        let scene_dir = out_dir.join(key);
        if !args.quiet {
            eprintln!("{key}: {}", scene.display());
        }
        match compare_scene(
            &scene,
            data,
            None,
            &scene_dir,
            &plan,
            args.reference_spp,
            &stop,
            &pool,
            args.quiet,
        )? {
            SceneRun::Done(mut c) => {
                if !c.interrupted {
                    let (runs, stopped) =
                        thesis_biased_runs(&scene, &c.reference, &plan, args, &stop, &pool)?;
                    c.results.extend(runs);
                    c.interrupted |= stopped;
                }
                report::write_report(&c, &scene_dir)?;
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
    let scenes: Vec<thesis::SceneResult> = thesis::SCENES
        .iter()
        .map(|(key, _)| thesis::SceneResult {
            key,
            comparison: comparisons.iter().find(|(k, _)| k == key).map(|(_, c)| c),
        })
        .collect();
    std::fs::create_dir_all(&out_dir).with_context(|| out_dir.display().to_string())?;
    let summary = out_dir.join(report::SUMMARY_MD);
    std::fs::write(
        &summary,
        thesis::summary_markdown(&scenes, pool.current_num_threads(), &args.thesis_photons),
    )
    .with_context(|| summary.display().to_string())?;
    let csv = out_dir.join(report::RESULTS_CSV);
    let all: Vec<(&str, &Comparison)> = comparisons.iter().map(|(k, c)| (*k, c)).collect();
    write_thesis_csv(&all, &csv)?;
    let mut text = format!(
        "thesis preset: {} of 3 scenes; wrote {} and {}\n",
        comparisons.len(),
        summary.display(),
        csv.display()
    );
    if interrupted {
        text += "interrupted: the report holds the runs finished before the stop\n";
    }
    print_out(&text);
    Ok(if interrupted { EXIT_INTERRUPTED } else { 0 })
}

/// The thesis preset's biased runs of one scene: each row of `thesis::BIASED` at each of
/// `--thesis-photons`, against the scene's reference. Returns the runs and whether a stop cut
/// them short.
fn thesis_biased_runs(
    scene: &Path,
    reference: &Image,
    plan: &ComparePlan,
    args: &CompareArgs,
    stop: &AtomicBool,
    pool: &rayon::ThreadPool,
) -> Result<(Vec<crate::compare::RunResult>, bool)> {
    let data = load_scene(scene)?;
    let mut runs = Vec::new();
    for &photons in &args.thesis_photons {
        for (name, passes, row) in thesis::BIASED {
            let kind = IntegratorKind::from_name(name).map_err(|e| anyhow::anyhow!("{e}"))?;
            if !args.quiet {
                eprintln!("  {row} at {photons} photons");
            }
            let settings = RenderSettings {
                photons: crate::integrators::PhotonSettings {
                    photons_per_pass: photons,
                    photons,
                    ..args.photons.settings()
                },
                ..plan.settings
            };
            let job = CompareJob {
                data: data.clone(),
                reference,
                integrators: &[kind],
                unit: BudgetUnit::Spp,
                budgets: &[passes as f64],
                settings,
            };
            let (results, stopped) = pool
                .install(|| crate::compare::run_comparison(&job, stop, &|_, _| {}))
                .map_err(|e| anyhow::anyhow!("{}: {e}", scene.display()))?;
            runs.extend(results);
            if stopped {
                return Ok((runs, true));
            }
        }
    }
    Ok((runs, false))
}

/// One CSV of every scene's runs, with a scene column first.
fn write_thesis_csv(all: &[(&str, &Comparison)], path: &Path) -> Result<()> {
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
