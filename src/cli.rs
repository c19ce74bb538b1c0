//! The `stagelight` command line: render, diff and bench.

use crate::film::Image;
use crate::integrators::{Budget, Control, RenderOutcome, SceneData, bdpt, pt};
use crate::path::MisHeuristic;
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
    /// Prints the error of an image against a reference: relMSE, RMSE, MAE, channel means.
    Diff { image: PathBuf, reference: PathBuf },
    /// Renders a scene several times at a fixed budget and prints throughput as a table.
    Bench {
        scene: PathBuf,
        #[arg(long, value_enum, default_value_t = IntegratorName::Pt)]
        integrator: IntegratorName,
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

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum IntegratorName {
    /// Path tracing with next-event estimation and MIS.
    Pt,
    /// Bidirectional path tracing: every strategy (s, t), MIS-weighted.
    Bdpt,
}

impl IntegratorName {
    pub fn as_str(self) -> &'static str {
        match self {
            IntegratorName::Pt => "pt",
            IntegratorName::Bdpt => "bdpt",
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Scene file (RON).
    pub scene: PathBuf,
    #[arg(long, value_enum, default_value_t = IntegratorName::Pt)]
    pub integrator: IntegratorName,
    /// Samples per pixel (default 64 unless --time is given).
    #[arg(long, conflicts_with = "time", value_parser = clap::value_parser!(u64).range(1..))]
    pub spp: Option<u64>,
    /// Render for this many wall-clock seconds (whole passes).
    #[arg(long, value_parser = parse_seconds)]
    pub time: Option<f64>,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub threads: Option<u64>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
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

/// What an integrator is asked for, whichever it is.
#[derive(Clone, Copy, Debug)]
pub struct RenderRequest {
    pub integrator: IntegratorName,
    pub seed: u64,
    pub max_depth: u32,
    pub mis: MisHeuristic,
    pub strategy_images: bool,
}

/// Runs the requested integrator; returns its outcome and any auxiliary images it made.
pub fn run_integrator(
    request: RenderRequest,
    data: Arc<SceneData>,
    budget: Budget,
    control: &Control,
) -> (RenderOutcome, Vec<(String, Image)>) {
    match request.integrator {
        IntegratorName::Pt => {
            let settings = pt::PtSettings {
                seed: request.seed,
                max_depth: request.max_depth,
            };
            (pt::render(data, settings, budget, control), Vec::new())
        }
        IntegratorName::Bdpt => {
            let settings = bdpt::BdptSettings {
                mis: request.mis,
                strategy_images: request.strategy_images,
                ..bdpt::BdptSettings::new(request.seed, request.max_depth)
            };
            bdpt::render_with_images(data, settings, budget, control)
        }
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
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second Ctrl-C while the image is being written has no further effect.
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("cannot install the Ctrl-C handler")?;
    }
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
    if args.strategy_images.is_some() && args.integrator != IntegratorName::Bdpt {
        bail!("--strategy-images needs --integrator bdpt");
    }
    let request = RenderRequest {
        integrator: args.integrator,
        seed: args.seed,
        max_depth: args.max_depth.unwrap_or(u32::MAX),
        mis: args.mis.heuristic(),
        strategy_images: args.strategy_images.is_some(),
    };
    let cpu_start = cpu_seconds();
    let (outcome, layers) =
        pool.install(|| run_integrator(request, data.clone(), budget, &control));
    let cpu = cpu_seconds() - cpu_start;
    bar.finish_and_clear();

    let image = outcome.film.image();
    image.write_exr(&output)?;
    let png = output.with_extension("png");
    image.write_png(&png)?;
    if let Some(dir) = &args.strategy_images {
        for (name, layer) in &layers {
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

/// CPU seconds (user + system) this process has used, from /proc (Linux; 0 elsewhere).
pub fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let Some(rest) = stat.rsplit_once(')').map(|(_, r)| r) else {
        return 0.0;
    };
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // Linux reports these in USER_HZ, which is 100 on every mainstream architecture.
    (ticks(11) + ticks(12)) / 100.0
}

/// Peak resident memory in bytes (VmHWM), from /proc (Linux; 0 elsewhere).
pub fn peak_memory_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

fn mega(x: f64) -> String {
    if x >= 1e6 {
        format!("{:.3} M", x / 1e6)
    } else if x >= 1e3 {
        format!("{:.3} k", x / 1e3)
    } else {
        format!("{x:.0}")
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
    integrator: IntegratorName,
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
    integrator: IntegratorName,
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
        let request = RenderRequest {
            integrator,
            seed,
            max_depth: u32::MAX,
            mis: MisHeuristic::Power,
            strategy_images: false,
        };
        let o = pool.install(|| {
            run_integrator(
                request,
                data.clone(),
                Budget::SamplesPerPixel(spp),
                &control,
            )
            .0
        });
        let wall = t.elapsed().as_secs_f64();
        (o, wall, cpu_seconds() - cpu0)
    };
    run_once(1_000_000); // warm-up
    let mut samples_per_s = Vec::new();
    let mut closest_per_s = Vec::new();
    let mut shadow_per_s = Vec::new();
    let mut last = None;
    for r in 0..runs {
        let (o, wall, cpu) = run_once(r as u64);
        samples_per_s.push(o.samples as f64 / wall);
        closest_per_s.push(o.closest_rays() as f64 / wall);
        shadow_per_s.push(o.shadow_rays() as f64 / wall);
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
    ] {
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
