//! `stagelight bench`: a scene (or the big scenes of `--big`) rendered several times at a
//! fixed budget, its throughput as a table (`report::bench_table`), with the scene's load and
//! tree-build times and memory; the machine it ran on; the results saved as JSON (`--save`)
//! and compared with a saved baseline (`--baseline`), as ratios.

use super::big_scenes::{BIG_SCENES, scene_path, write_big_scene};
use super::{
    check_kernel, check_outputs, check_render_memory, check_samples, check_threads, print_out,
};
use crate::integrators::pt::Kernel;
use crate::integrators::{Budget, Control, IntegratorKind, RenderSettings, SceneData};
use crate::lanes::LaneWidth;
use crate::report::{BenchRuns, bench_table, sweep_table};
use crate::sysinfo::cpu_seconds;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// What a bench was asked for.
pub struct BenchOptions {
    /// Scene file (RON); None with `big`.
    pub scene: Option<PathBuf>,
    /// Write the big scenes into this folder (those missing) and bench each.
    pub big: Option<PathBuf>,
    pub integrator: IntegratorKind,
    /// Samples per pixel of each timed run.
    pub spp: u64,
    /// Timed runs, after one warm-up run; also the number of tree builds timed.
    pub runs: u32,
    /// Worker threads (None: all cores).
    pub threads: Option<usize>,
    /// Write the results here as JSON.
    pub save: Option<PathBuf>,
    /// Compare with the results saved here.
    pub baseline: Option<PathBuf>,
    /// The kernel and wavefront of the renders (`--kernel`, `--wavefront`).
    pub settings: RenderSettings,
    /// Bench every wavefront size of `sweep_settings` (and PT's megakernel) instead.
    pub sweep: bool,
}

/// A saved bench: the machine and each scene's measures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BenchFile {
    pub machine: Machine,
    pub results: Vec<BenchResult>,
}

/// What the figures depend on besides the code.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Machine {
    pub stagelight: String,
    pub cpu: String,
    /// Worker threads of the bench.
    pub threads: usize,
    /// Target features the build was compiled for (`-C target-cpu`, `-C target-feature`).
    pub target_features: Vec<String>,
    /// Whether the traversal's AVX2 copy ran (chosen at run time).
    pub avx2_fma_at_run_time: bool,
    /// Paths PT's wavefront shaded at a time in vector lanes (`--lanes`); None where no render
    /// ran (`stagelight rays`) and in files saved before the width was a choice (8 then).
    #[serde(default)]
    pub lanes: Option<usize>,
}

impl Machine {
    /// This machine, with `threads` workers and PT's lanes `lanes` wide.
    pub fn this(threads: usize, lanes: Option<LaneWidth>) -> Machine {
        Machine {
            stagelight: env!("CARGO_PKG_VERSION").to_string(),
            cpu: cpu_model(),
            threads,
            target_features: target_features(),
            avx2_fma_at_run_time: crate::cpu::has_avx2_fma(),
            lanes: lanes.map(LaneWidth::count),
        }
    }

    /// What differs from `other`, one phrase per field ("threads 2, not 1").
    pub fn differences(&self, other: &Machine) -> Vec<String> {
        let mut out = Vec::new();
        let mut check = |what: &str, a: String, b: String| {
            if a != b {
                out.push(format!("{what} {a}, not {b}"));
            }
        };
        check(
            "stagelight",
            self.stagelight.clone(),
            other.stagelight.clone(),
        );
        check("CPU", self.cpu.clone(), other.cpu.clone());
        check(
            "threads",
            self.threads.to_string(),
            other.threads.to_string(),
        );
        check(
            "target features",
            self.target_features.join(","),
            other.target_features.join(","),
        );
        check(
            "AVX2+FMA at run time",
            self.avx2_fma_at_run_time.to_string(),
            other.avx2_fma_at_run_time.to_string(),
        );
        if let (Some(a), Some(b)) = (self.lanes, other.lanes) {
            check("lanes", a.to_string(), b.to_string());
        }
        out
    }

    /// One line for the report.
    pub fn describe(&self) -> String {
        let mut line = format!(
            "machine: {}, {} threads; build target features: {}; AVX2+FMA code at run time: {}",
            self.cpu,
            self.threads,
            self.target_features.join(","),
            if self.avx2_fma_at_run_time {
                "yes"
            } else {
                "no"
            }
        );
        if let Some(n) = self.lanes {
            let _ = write!(line, "; pt wavefront lanes: {n}");
        }
        line
    }
}

/// The CPU's model name (Linux: /proc/cpuinfo), or "unknown CPU".
fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".to_string())
}

/// The x86 features this build may use everywhere (a build for `-C target-cpu=native` lists
/// more than the default SSE2).
fn target_features() -> Vec<String> {
    let mut features = Vec::new();
    macro_rules! check {
        ($($f:tt),*) => {$(
            if cfg!(target_feature = $f) {
                features.push($f.to_string());
            }
        )*};
    }
    check!(
        "sse2", "sse3", "ssse3", "sse4.1", "sse4.2", "popcnt", "avx", "avx2", "fma", "bmi2",
        "avx512f", "neon"
    );
    if features.is_empty() {
        features.push(std::env::consts::ARCH.to_string());
    }
    features
}

/// One scene's figures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BenchResult {
    /// The scene's file name (without its folder: results from another checkout compare).
    pub scene: String,
    pub integrator: String,
    /// PT's kernel (files saved before kernels existed were all `wavefront`).
    #[serde(default = "wavefront_kernel")]
    pub kernel: String,
    /// Samples in flight asked for (`--wavefront`); None: the integrator's default.
    #[serde(default)]
    pub wavefront: Option<u64>,
    pub spp: u64,
    pub triangles: u64,
    pub measures: Vec<Measure>,
}

fn wavefront_kernel() -> String {
    Kernel::Wavefront.as_str().to_string()
}

impl BenchResult {
    /// Whether the two are the same bench (scene, integrator, kernel, wavefront and spp), so
    /// that their figures compare.
    fn same_bench(&self, other: &BenchResult) -> bool {
        self.scene == other.scene
            && self.integrator == other.integrator
            && self.kernel == other.kernel
            && self.wavefront == other.wavefront
            && self.spp == other.spp
    }

    /// The integrator with its kernel and wavefront where they are not the defaults.
    fn label(&self) -> String {
        let mut label = self.integrator.clone();
        if self.kernel != Kernel::Wavefront.as_str() {
            let _ = write!(label, " {}", self.kernel);
        }
        if let Some(n) = self.wavefront {
            let _ = write!(label, " --wavefront {n}");
        }
        label
    }
}

/// A measure over the runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measure {
    pub name: String,
    /// Whether more is better (rates) or less (seconds, bytes).
    pub higher_is_better: bool,
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

impl Measure {
    fn of(name: &str, higher_is_better: bool, values: &[f64]) -> Measure {
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        Measure {
            name: name.to_string(),
            higher_is_better,
            median: v[v.len() / 2],
            min: v[0],
            max: v[v.len() - 1],
        }
    }
}

/// A measure against its baseline.
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    pub scene: String,
    /// The integrator, with its kernel and wavefront where not the defaults.
    pub bench: String,
    pub measure: String,
    pub baseline: f64,
    pub current: f64,
    /// current / baseline (of the medians).
    pub ratio: f64,
    pub verdict: Verdict,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    Better,
    Worse,
    /// Within the runs' spread: the ranges of the two overlap, or the medians differ by less
    /// than `NOISE`.
    Same,
}

/// Medians closer than this share are the same whatever the ranges say.
pub const NOISE: f64 = 0.03;

/// Each measure of `current` against the same measure of the same scene, integrator, kernel,
/// wavefront and spp in `baseline`; measures or scenes the baseline lacks are left out. Worse
/// (or better) only when the two runs' ranges do not overlap and the medians differ by more
/// than `NOISE`.
pub fn compare_with_baseline(current: &BenchFile, baseline: &BenchFile) -> Vec<Comparison> {
    let mut out = Vec::new();
    for r in &current.results {
        let Some(b) = baseline.results.iter().find(|b| b.same_bench(r)) else {
            continue;
        };
        for m in &r.measures {
            let Some(bm) = b.measures.iter().find(|bm| bm.name == m.name) else {
                continue;
            };
            let ratio = m.median / bm.median;
            let apart = m.min > bm.max || m.max < bm.min;
            let verdict = if !ratio.is_finite() || !apart || (ratio - 1.0).abs() <= NOISE {
                Verdict::Same
            } else if (ratio > 1.0) == m.higher_is_better {
                Verdict::Better
            } else {
                Verdict::Worse
            };
            out.push(Comparison {
                scene: r.scene.clone(),
                bench: r.label(),
                measure: m.name.clone(),
                baseline: bm.median,
                current: m.median,
                ratio,
                verdict,
            });
        }
    }
    out
}

/// The comparison as a Markdown table, with a line when the machines differ.
pub fn comparison_table(current: &BenchFile, baseline: &BenchFile, baseline_file: &Path) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "against the baseline {}", baseline_file.display());
    let differences = baseline.machine.differences(&current.machine);
    if !differences.is_empty() {
        let _ = writeln!(
            t,
            "note: the baseline ran on another machine, build or thread count ({}): {}",
            differences.join("; "),
            baseline.machine.describe()
        );
    }
    let rows = compare_with_baseline(current, baseline);
    if rows.is_empty() {
        let _ = writeln!(
            t,
            "no measure to compare: the baseline has no result for these scenes, integrator, \
             kernel, wavefront and spp"
        );
        return t;
    }
    let _ = writeln!(
        t,
        "| scene | bench | measure | baseline | now | now / baseline | |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|---|");
    for c in rows {
        let flag = match c.verdict {
            Verdict::Better => "better",
            Verdict::Worse => "WORSE",
            Verdict::Same => "",
        };
        let _ = writeln!(
            t,
            "| {} | {} | {} | {} | {} | {:.3}x | {flag} |",
            c.scene,
            c.bench,
            c.measure,
            short(c.baseline),
            short(c.current),
            c.ratio
        );
    }
    t
}

/// A figure in 4 significant digits (k, M and G for large ones).
fn short(v: f64) -> String {
    let (v, unit) = match v.abs() {
        a if a >= 1e9 => (v / 1e9, " G"),
        a if a >= 1e6 => (v / 1e6, " M"),
        a if a >= 1e4 => (v / 1e3, " k"),
        _ => (v, ""),
    };
    let digits = if v == 0.0 || !v.is_finite() {
        0
    } else {
        (3 - v.abs().log10().floor() as i32).max(0) as usize
    };
    format!("{v:.digits$}{unit}")
}

/// Reads a saved bench (`--baseline`); errors name the file.
pub fn read_bench_file(path: &Path) -> Result<BenchFile> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read the baseline", path.display()))?;
    serde_json::from_str(&text).map_err(|e| {
        anyhow::anyhow!(
            "{}:{}:{}: not a saved bench: {}",
            path.display(),
            e.line(),
            e.column(),
            crate::scene::echo(&e.to_string())
        )
    })
}

/// The file as `--save` writes it.
pub fn bench_file_json(file: &BenchFile) -> String {
    serde_json::to_string_pretty(file).unwrap_or_default() + "\n"
}

/// Benches the scene or the big scenes, prints the tables, saves and compares.
pub fn bench(o: &BenchOptions) -> Result<()> {
    check_threads(o.threads)?;
    if o.sweep {
        if o.big.is_some() {
            bail!("--sweep benches one scene, not --big");
        }
        sweep_settings(o.integrator, &o.settings)?;
    } else {
        check_kernel(o.integrator, &o.settings)?;
    }
    let pool = super::thread_pool(o.threads)?;
    let baseline = o.baseline.as_deref().map(read_bench_file).transpose()?;
    if let Some(save) = &o.save {
        let inputs: Vec<&Path> = o.baseline.iter().map(|p| p.as_path()).collect();
        check_outputs(&[save], &inputs)?;
    }
    let scenes: Vec<PathBuf> = match (&o.scene, &o.big) {
        (Some(scene), None) => vec![scene.clone()],
        (None, Some(dir)) => BIG_SCENES
            .iter()
            .map(|size| {
                let path = scene_path(dir, size);
                if path.is_file() {
                    return Ok(path);
                }
                eprintln!(
                    "writing {} ({} triangles)",
                    path.display(),
                    size.triangles()
                );
                write_big_scene(dir, size)
            })
            .collect::<Result<_>>()?,
        _ => bail!("bench takes a scene file or --big DIR"),
    };
    let lanes = o.settings.lanes.unwrap_or_else(LaneWidth::widest);
    let machine = Machine::this(pool.current_num_threads(), Some(lanes));
    print_out(&format!("{}\n\n", machine.describe()));
    let mut file = BenchFile {
        machine,
        results: Vec::new(),
    };
    for scene in &scenes {
        file.results.extend(bench_scene(o, &pool, scene)?);
    }
    if o.big.is_some() {
        print_out(&big_table(&file));
    }
    if let (Some(baseline), Some(path)) = (&baseline, &o.baseline) {
        print_out(&comparison_table(&file, baseline, path));
    }
    if let Some(save) = &o.save {
        crate::film::output::write_bytes(save, bench_file_json(&file).as_bytes())?;
        eprintln!("saved {}", save.display());
    }
    Ok(())
}

/// Paths in flight that `--sweep` benches: every power of two from 2^10 to 2^20 for pt (and
/// its megakernel last), to 2^16 for bdpt (a BDPT sample keeps about 4 kB in flight).
pub fn sweep_settings(
    integrator: IntegratorKind,
    settings: &RenderSettings,
) -> Result<Vec<RenderSettings>> {
    let largest = match integrator.as_str() {
        "pt" => 20,
        "bdpt" => 16,
        other => bail!("--sweep: only pt and bdpt render in waves of samples, not {other}"),
    };
    if settings.wavefront.is_some() || settings.kernel != Kernel::Wavefront {
        bail!(
            "--sweep chooses the kernels and wavefronts itself: leave out --kernel and --wavefront"
        );
    }
    let mut out: Vec<RenderSettings> = (10..=largest)
        .map(|k| RenderSettings {
            wavefront: Some(1 << k),
            ..*settings
        })
        .collect();
    if integrator.as_str() == "pt" {
        out.push(RenderSettings {
            kernel: Kernel::Megakernel,
            ..*settings
        });
    }
    Ok(out)
}

/// The big scenes' figures side by side.
fn big_table(file: &BenchFile) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "| scene | triangles | load s | tree build s | tree + triangles MB | samples/s | closest-hit rays/s |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|---|");
    for r in &file.results {
        let get = |name: &str| {
            r.measures
                .iter()
                .find(|m| m.name == name)
                .map_or(f64::NAN, |m| m.median)
        };
        let _ = writeln!(
            t,
            "| {} | {} | {:.2} | {:.2} | {:.0} | {} | {} |",
            r.scene,
            r.triangles,
            get("scene load s"),
            get("tree build s"),
            get("tree + triangles bytes") / 1e6,
            short(get("samples/s")),
            short(get("closest-hit rays/s")),
        );
    }
    t
}

/// Loads, builds and renders one scene (once per kernel and wavefront with `--sweep`): its
/// tables printed, its figures returned (the scene's load and build figures with the first).
fn bench_scene(
    o: &BenchOptions,
    pool: &rayon::ThreadPool,
    path: &Path,
) -> Result<Vec<BenchResult>> {
    let t = Instant::now();
    let scene = crate::scene::load_with_defines(
        path,
        crate::commands::scene_defines(),
        &crate::scene::Limits::of_this_machine(),
    )?;
    let load_s = t.elapsed().as_secs_f64();
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    // The tree is built `runs` times: the first is kept for the renders.
    let mut build_s = Vec::new();
    let mut accel = None;
    for _ in 0..o.runs {
        let t = Instant::now();
        let built = pool.install(|| crate::accel::Accel::build(&scene.triangles));
        build_s.push(t.elapsed().as_secs_f64());
        accel.get_or_insert(built);
    }
    let accel = accel.context("at least one run")?;
    let (nodes, leaf_triangles) = accel.memory_bytes();
    let columns = scene.triangles.memory_bytes();
    let triangles = scene.triangles.len() as u64;
    let data = Arc::new(SceneData { scene, accel });
    check_samples("--spp", o.spp, &data)?;
    let configs = if o.sweep {
        sweep_settings(o.integrator, &o.settings)?
    } else {
        vec![o.settings]
    };
    for settings in &configs {
        check_render_memory(o.integrator, settings, &data, pool.current_num_threads())?;
    }
    let scene_name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    );
    let mut results = Vec::new();
    let mut sweep_rows = Vec::new();
    for settings in &configs {
        let runs = time_renders(o, pool, &data, settings);
        let mut measures: Vec<Measure> = runs
            .rates()
            .into_iter()
            .map(|(name, values)| Measure::of(name, true, values))
            .collect();
        let bytes = (nodes + leaf_triangles + columns) as f64;
        if results.is_empty() {
            measures.push(Measure::of("scene load s", false, &[load_s]));
            measures.push(Measure::of("tree build s", false, &build_s));
            measures.push(Measure::of("tree + triangles bytes", false, &[bytes]));
        }
        results.push(BenchResult {
            scene: scene_name.clone(),
            integrator: o.integrator.as_str().to_string(),
            kernel: settings.kernel.as_str().to_string(),
            wavefront: settings.wavefront.map(|n| n as u64),
            spp: o.spp,
            triangles,
            measures,
        });
        if o.sweep {
            sweep_rows.push((settings.kernel, runs));
            continue;
        }
        let label = results.last().map(BenchResult::label).unwrap_or_default();
        let mut table = bench_table(path, &label, o.spp, pool.current_num_threads(), runs);
        let _ = writeln!(
            table,
            "| scene | {triangles} triangles, loaded in {load_s:.2} s (file read and prepared) |\n\
             | tree build | {} s median of {} (min {:.3}, max {:.3}) |\n\
             | memory | tree nodes {:.1} MB, triangles in leaf order {:.1} MB, scene's triangle \
             columns {:.1} MB: {:.1} MB, {:.0} bytes a triangle |\n",
            short(Measure::of("", false, &build_s).median),
            build_s.len(),
            build_s.iter().copied().fold(f64::INFINITY, f64::min),
            build_s.iter().copied().fold(0.0, f64::max),
            nodes as f64 / 1e6,
            leaf_triangles as f64 / 1e6,
            columns as f64 / 1e6,
            bytes / 1e6,
            bytes / triangles.max(1) as f64,
        );
        print_out(&table);
    }
    if o.sweep {
        print_out(&sweep_table(
            path,
            o.integrator,
            o.spp,
            pool.current_num_threads(),
            sweep_rows,
        ));
    }
    Ok(results)
}

/// One warm-up render and `o.runs` timed ones of the scene with `settings` (seeds 0, 1, ...).
fn time_renders(
    o: &BenchOptions,
    pool: &rayon::ThreadPool,
    data: &Arc<SceneData>,
    settings: &RenderSettings,
) -> BenchRuns {
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    let run_once = |seed: u64| {
        let cpu0 = cpu_seconds();
        let t = Instant::now();
        let settings = RenderSettings { seed, ..*settings };
        let outcome = pool.install(|| {
            crate::integrators::render(
                o.integrator,
                data.clone(),
                &settings,
                Budget::SamplesPerPixel(o.spp),
                &control,
            )
        });
        let wall = t.elapsed().as_secs_f64();
        (outcome, wall, cpu_seconds() - cpu0)
    };
    run_once(1_000_000); // warm-up
    let mut runs = BenchRuns::default();
    for r in 0..o.runs {
        let (outcome, wall, cpu) = run_once(r as u64);
        runs.add(outcome, wall, cpu);
    }
    runs
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(samples: [f64; 3], build: [f64; 3]) -> BenchFile {
        let m = |name: &str, higher: bool, [min, median, max]: [f64; 3]| Measure {
            name: name.into(),
            higher_is_better: higher,
            median,
            min,
            max,
        };
        BenchFile {
            machine: Machine::this(2, Some(LaneWidth::Eight)),
            results: vec![BenchResult {
                scene: "cornell_box.ron".into(),
                integrator: "pt".into(),
                kernel: "wavefront".into(),
                wavefront: None,
                spp: 32,
                triangles: 32,
                measures: vec![
                    m("samples/s", true, samples),
                    m("tree build s", false, build),
                ],
            }],
        }
    }

    #[test]
    fn baseline_ratios_and_verdicts() {
        let base = file([0.9e6, 1.0e6, 1.1e6], [0.10, 0.11, 0.12]);
        // Slower rate, apart from the baseline's range: worse; faster build: better.
        let now = file([0.6e6, 0.7e6, 0.8e6], [0.05, 0.055, 0.06]);
        let c = compare_with_baseline(&now, &base);
        assert_eq!(c.len(), 2);
        assert_eq!(c[0].measure, "samples/s");
        assert!((c[0].ratio - 0.7).abs() < 1e-12);
        assert_eq!(c[0].verdict, Verdict::Worse);
        assert!((c[1].ratio - 0.5).abs() < 1e-12);
        assert_eq!(c[1].verdict, Verdict::Better);
        // Overlapping ranges are the same, however far the medians.
        let now = file([1.05e6, 1.3e6, 1.4e6], [0.115, 0.2, 0.3]);
        let c = compare_with_baseline(&now, &base);
        assert!(c.iter().all(|c| c.verdict == Verdict::Same), "{c:?}");
        // Apart, but within NOISE: the same.
        let now = file([1.11e6, 1.12e6, 1.13e6], [0.10, 0.11, 0.12]);
        assert_eq!(
            compare_with_baseline(&now, &base)[0].verdict,
            Verdict::Better
        );
        let now = file([0.975e6, 0.98e6, 0.985e6], [0.10, 0.11, 0.12]);
        let base_tight = file([0.999e6, 1.0e6, 1.001e6], [0.10, 0.11, 0.12]);
        assert_eq!(
            compare_with_baseline(&now, &base_tight)[0].verdict,
            Verdict::Same
        );
        // Another spp or scene is not compared.
        let mut other = now.clone();
        other.results[0].spp = 64;
        assert!(compare_with_baseline(&other, &base).is_empty());
        other.results[0].spp = 32;
        other.results[0].scene = "door_ajar.ron".into();
        assert!(compare_with_baseline(&other, &base).is_empty());
        // Nor another kernel or wavefront.
        let mut other = now.clone();
        other.results[0].kernel = "megakernel".into();
        assert!(compare_with_baseline(&other, &base).is_empty());
        other.results[0].kernel = "wavefront".into();
        other.results[0].wavefront = Some(1024);
        assert!(compare_with_baseline(&other, &base).is_empty());
    }

    #[test]
    fn the_table_flags_a_regression_and_another_machine() {
        let base = file([0.9e6, 1.0e6, 1.1e6], [0.10, 0.11, 0.12]);
        let now = file([0.6e6, 0.7e6, 0.8e6], [0.10, 0.11, 0.12]);
        let t = comparison_table(&now, &base, Path::new("b.json"));
        assert!(
            t.contains("| cornell_box.ron | pt | samples/s | 1.000 M | 700.0 k | 0.700x | WORSE |"),
            "{t}"
        );
        assert!(!t.contains("another machine"), "{t}");
        let mut elsewhere = base.clone();
        elsewhere.machine.cpu = "a slower CPU".into();
        elsewhere.machine.threads = 1;
        let t = comparison_table(&now, &elsewhere, Path::new("b.json"));
        assert!(
            t.contains("another machine")
                && t.contains("CPU a slower CPU, not ")
                && t.contains("threads 1, not 2"),
            "{t}"
        );
    }

    #[test]
    fn saved_files_read_back() {
        let f = file([0.9e6, 1.0e6, 1.1e6], [0.10, 0.11, 0.12]);
        let dir =
            std::env::temp_dir().join(format!("stagelight_bench_json_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bench.json");
        std::fs::write(&path, bench_file_json(&f)).unwrap();
        assert_eq!(read_bench_file(&path).unwrap(), f);
        // A file saved before kernels existed reads as the wavefront's.
        let old = bench_file_json(&f)
            .replace("\"kernel\": \"wavefront\",", "")
            .replace("\"wavefront\": null,", "");
        assert!(!old.contains("kernel"), "{old}");
        std::fs::write(&path, old).unwrap();
        assert_eq!(read_bench_file(&path).unwrap(), f);
        std::fs::write(&path, "{\"machine\": 3}").unwrap();
        let e = read_bench_file(&path).unwrap_err().to_string();
        assert!(
            e.contains("bench.json:1:") && e.contains("not a saved bench"),
            "{e}"
        );
    }
}
