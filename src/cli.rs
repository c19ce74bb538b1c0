//! The `stagelight` command line: render, reference, merge, compare, view, diff and bench.
//! This file holds what clap parses and the dispatch; `values` the value parsers, `options`
//! the parsed arguments turned into each command's options.

use crate::commands::bench::BenchOptions;
use crate::commands::reference::ReferenceOptions;
use crate::commands::render::RenderOptions;
use crate::commands::scene_stem;
use crate::compare::BudgetUnit;
use crate::compare::run::CompareOptions;
use crate::compare::thesis::ThesisOptions;
use crate::integrators::pt::Kernel;
use crate::integrators::{Budget, IntegratorKind, RenderSettings};
use crate::path::MisHeuristic;
use crate::reference::{DEFAULT_REFERENCE_SEED, ReferenceBudget};
use crate::sampling::SamplerKind;
use anyhow::{Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

mod options;
mod values;
use values::*;
pub use values::{MAX_CHECKPOINT_SECONDS, one_line};

#[derive(Parser, Debug)]
#[command(
    name = "stagelight",
    version,
    about = "A data-oriented wavefront CPU renderer"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// Sets a Mitsuba scene's parameter `$NAME` (overrides its `<default>`; repeatable), as
    /// Mitsuba's `-D spp=64`. `--spp` beats `-D spp`, which beats the file's sample_count.
    #[arg(short = 'D', global = true, value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Renders a scene to an EXR (float32 linear RGB) with a PNG preview beside it.
    Render(RenderArgs),
    /// Renders a long reference, checkpointed: run it again to resume or extend it.
    Reference(ReferenceArgs),
    /// Renders each integrator at each budget and writes a report folder of speed against
    /// error: results.csv, error_vs_time.png/.svg, grid.png, summary.md, and index.html (an
    /// interactive page over every run; open it from the disk in a browser).
    Compare(CompareArgs),
    /// Adds the partial films of shards (`render` or `reference` with --shard) into the
    /// image one machine would have made; each PART.exr's film is PART.exr.checkpoint.
    Merge(MergeArgs),
    /// Writes Slurm batch scripts that run a render, reference or comparison as a job array of
    /// shards and a merge job after them, e.g. `stagelight slurm --shards 16 -o job --
    /// reference scenes/door_ajar.ron --spp 4096 -o ref.exr`, then `sh job/submit.sh`.
    Slurm(SlurmArgs),
    /// Prints the error of an image against a reference: relMSE, RMSE, MAE, channel means.
    Diff { image: PathBuf, reference: PathBuf },
    /// Writes the report's interactive viewer for any EXRs of one size: flip to the reference,
    /// error maps, synchronised zoom, exposure, pixel readout. PAGE.html opens from the disk;
    /// the images' floats go into PAGE_data/ beside it.
    View {
        /// The images; the first is the reference unless --reference names one.
        #[arg(required = true, value_name = "IMAGE.exr")]
        images: Vec<PathBuf>,
        /// The image flips go to and error maps are measured against.
        #[arg(long, value_name = "REF.exr")]
        reference: Option<PathBuf>,
        #[arg(short, long, value_name = "PAGE.html")]
        output: PathBuf,
    },
    /// Renders a scene several times at a fixed budget and prints throughput as a table; with
    /// --rays, traces the rays of a folder `stagelight rays` wrote instead.
    Bench {
        #[arg(required_unless_present_any = ["big", "rays"], conflicts_with_all = ["big", "rays"])]
        scene: Option<PathBuf>,
        /// Trace the rays in DIR (written by `stagelight rays`) with the renderer's trace
        /// systems, closest-hit and shadow rays by bounce group (after one warm-up run),
        /// print rays/s and write DIR/hits.npy (t and primitive per ray). Takes --threads,
        /// --runs and --save.
        #[arg(long, value_name = "DIR", conflicts_with_all = ["big", "baseline", "sweep"])]
        rays: Option<PathBuf>,
        /// Bench the big scenes (the Cornell box with 32 to 5 million triangles), written as
        /// PLY files, stagelight and Mitsuba 3 scenes into DIR where missing.
        #[arg(long, value_name = "DIR")]
        big: Option<PathBuf>,
        /// Write the results as JSON.
        #[arg(long, value_name = "FILE.json")]
        save: Option<PathBuf>,
        /// Compare with results saved by --save: ratios, and which measures got worse.
        #[arg(long, value_name = "FILE.json")]
        baseline: Option<PathBuf>,
        #[arg(long, default_value = "pt", value_parser = IntegratorParser)]
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
        #[command(flatten)]
        kernel: KernelArgs,
        /// Bench every wavefront size from 2^10 to 2^20 paths in flight (2^16 for bdpt) and
        /// PT's megakernel, and print them side by side.
        #[arg(long, conflicts_with_all = ["big", "kernel", "wavefront"])]
        sweep: bool,
    },
    /// Writes the rays PT traces on a scene, as data: DIR/mesh.ply (every triangle in world
    /// space; face i is triangle id i), DIR/closest.npy and DIR/shadow.npy (float32, N x 8:
    /// origin xyz, t_min, direction xyz, t_max) and DIR/rays.json (their rows by bounce).
    /// `stagelight bench --rays DIR` traces them.
    Rays(RaysArgs),
    /// Writes a RON scene as a Mitsuba 3 scene file (SCENE.xml, its meshes as double-precision
    /// PLY files in meshes/ beside it), which Mitsuba renders and stagelight reads back as the
    /// same triangles.
    Export {
        scene: PathBuf,
        #[arg(short, long, value_name = "SCENE.xml")]
        output: PathBuf,
    },
    /// Prints an integrator's graph for a scene: its systems in run order, with the columns
    /// each reads and writes.
    Graph {
        scene: PathBuf,
        #[arg(long, default_value = "pt", value_parser = IntegratorParser)]
        integrator: IntegratorKind,
        /// The graph without final gathering (pm).
        #[arg(long)]
        no_final_gather: bool,
    },
}

/// `stagelight rays`.
#[derive(clap::Args, Debug)]
pub struct RaysArgs {
    /// Scene file: RON, or Mitsuba 3 XML (.xml).
    pub scene: PathBuf,
    /// The folder to write (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Samples per pixel of the render whose rays are written (PT with the defaults of
    /// `render`).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub spp: u64,
    /// Write the rays of bounces 0..K only (0: camera rays and the shadow rays from the
    /// points they find); default: all.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub bounces: Option<u64>,
    /// Worker threads of the render (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub threads: Option<u64>,
}

/// Which passes of a render this run makes (a shard); see `commands::ShardChoice`.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct ShardArgs {
    /// Render shard I of N (1 <= I <= N) of the --spp passes and write its partial film,
    /// OUT.exr.checkpoint, beside the image, for `stagelight merge`.
    #[arg(long, value_name = "I/N", value_parser = parse_shard, conflicts_with_all = ["time", "pass_range"])]
    pub shard: Option<(u64, u64)>,
    /// Render passes FIRST..END (END excluded) of the --spp passes, as a shard.
    #[arg(long, value_name = "FIRST..END", value_parser = parse_pass_range, conflicts_with = "time")]
    pub pass_range: Option<(u64, u64)>,
}

/// `stagelight merge`.
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// The shards' images (the paths given to them with -o); each one's film is read from
    /// PART.exr.checkpoint beside it.
    #[arg(required = true, value_name = "PART.exr")]
    pub parts: Vec<PathBuf>,
    /// The merged EXR; a PNG preview goes beside it (and, for a reference, its checkpoint).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// `stagelight slurm`.
#[derive(clap::Args, Debug)]
pub struct SlurmArgs {
    /// Shards: the tasks of the job array.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub shards: u64,
    /// Folder of the scripts (shards.sbatch, merge.sbatch, submit.sh), the shards' parts and
    /// the logs.
    #[arg(short, long, default_value = "slurm-job")]
    pub output: PathBuf,
    /// Slurm partition of the jobs.
    #[arg(long)]
    pub partition: Option<String>,
    /// Time limit of each shard, as sbatch --time takes it (MINUTES, HH:MM:SS, D-HH:MM).
    #[arg(long)]
    pub time_limit: Option<String>,
    /// CPUs of each shard (sbatch --cpus-per-task; the render's threads unless --threads).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub cpus_per_task: Option<u32>,
    /// Seconds before a shard's time limit that Slurm stops it (it keeps its finished
    /// passes; a reference's shard requeues and resumes).
    #[arg(long, default_value_t = 300)]
    pub signal_seconds: u32,
    /// The stagelight binary the jobs run (default: this one).
    #[arg(long)]
    pub stagelight: Option<PathBuf>,
    /// The command to shard, after `--`: `render ...` or `reference ...` with `--spp N` and
    /// `-o OUT.exr` (where the merge job writes the merged image), or `compare ...` with
    /// `--budget-unit spp` or `--preset thesis` (a plan, plan.ron, that the tasks read).
    #[arg(last = true, required = true, value_name = "COMMAND")]
    pub command: Vec<String>,
}

/// How a sample-based render lays out its work (the image is the same either way).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct KernelArgs {
    /// PT's kernel: `wavefront` (paths in waves through one system per stage) or
    /// `megakernel` (each thread carries one path from the camera to its end).
    #[arg(long, value_enum, default_value_t = KernelName::Wavefront)]
    pub kernel: KernelName,
    /// Samples in flight per wave (pt, bdpt, vcm, bpm; default for pt 16384 a thread, 4096 on
    /// scenes whose tree and triangles pass 64 MiB, at most 262144; for bdpt 1024 a thread, at
    /// most 32768, and 32768 with a light-vertex cache; 32768 for vcm and bpm). vcm and bpm
    /// merge with the light subpaths of the same wave.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..=1 << 30))]
    pub wavefront: Option<u64>,
    /// Paths pt's wavefront shades at a time in vector lanes (and connections whose MIS weights
    /// bdpt and vcm find at a time): 8 (AVX2's registers) or 16 (AVX-512's); default:
    /// the widest this CPU has. The image is the same.
    #[arg(long, value_name = "8|16", value_parser = parse_lanes)]
    pub lanes: Option<crate::lanes::LaneWidth>,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum KernelName {
    Wavefront,
    Megakernel,
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Scene file: RON, or Mitsuba 3 XML (.xml).
    pub scene: PathBuf,
    #[arg(long, default_value = "pt", value_parser = IntegratorParser)]
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
    /// Where random numbers come from: `independent` (hashed) or `sobol` (Owen-scrambled
    /// Sobol' with Morton-ordered pixels).
    #[arg(long, default_value = "independent", value_parser = parse_sampler)]
    pub sampler: SamplerKind,
    #[command(flatten)]
    pub photons: PhotonArgs,
    #[command(flatten)]
    pub mlt: MltArgs,
    /// Maximum number of bounces (default: unlimited; Russian roulette ends paths).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// MIS heuristic of bidirectional strategies (bdpt).
    #[arg(long, value_enum, default_value_t = MisName::Power)]
    pub mis: MisName,
    /// Also write each strategy's weighted contribution as DIR/s{S}_t{T}.exr (bdpt; mmlt: the
    /// splats of the chain states at each strategy, scaled as the image is).
    #[arg(long, value_name = "DIR")]
    pub strategy_images: Option<PathBuf>,
    /// Light-vertex cache (bdpt; Davidovic et al. 2014): each camera vertex joins M light
    /// vertices picked from all of the wave's light subpaths instead of every vertex of its
    /// own. Unbiased; fewer connections per sample.
    #[arg(long, value_name = "M", value_parser = clap::value_parser!(u32).range(1..=64))]
    pub light_vertex_cache: Option<u32>,
    /// Output EXR (default render/SCENE_INTEGRATOR.exr); a PNG preview is written beside it.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Also write each pixel's sample variance as an EXR (pt): the per-channel variance of a
    /// single sample's estimate, E[x^2] - E[x]^2 over the pixel's (filter-weighted) samples,
    /// as Mitsuba's `moment` integrator gives it.
    #[arg(long, value_name = "PATH")]
    pub variance: Option<PathBuf>,
    #[command(flatten)]
    pub kernel: KernelArgs,
    #[command(flatten)]
    pub shard: ShardArgs,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Options of the Metropolis integrators (pssmlt, mmlt, mlt).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct MltArgs {
    /// Probability of a large step, in [0, 1] (pssmlt, mmlt; default 0.3).
    #[arg(long, value_parser = parse_probability)]
    pub large_step: Option<f32>,
    /// Small steps as a wrapped normal of this sigma (default: Kelemen's exponential for
    /// pssmlt, sigma 0.01 for mmlt).
    #[arg(long, value_parser = parse_sigma)]
    pub sigma: Option<f32>,
    /// Bootstrap evaluations, full BDPT samples (in mmlt each is a candidate at every depth)
    /// (default: grows with --spp).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub bootstrap: Option<u64>,
    /// Markov chains (default: the mutations / 64, between 256 and 32768).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1 << 15))]
    pub chains: Option<u64>,
    /// Direct illumination (depths 0 and 1) rendered apart by path tracing at this many
    /// samples per pixel (mlt, pssmlt, mmlt; 0: the chains render it too; default: one per
    /// mutation per pixel, so it keeps pace with any budget; Mitsuba's mlt renders 16).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=1 << 16))]
    pub direct_spp: Option<u32>,
    /// The path-space mutations to use, comma-separated from bidir, lens, caustic,
    /// multichain (mlt; default all). bidir alone can reach every path; the perturbations
    /// cannot, so a list without bidir is refused.
    #[arg(long, value_parser = parse_mutations)]
    pub mutations: Option<u8>,
    /// The lens perturbation's smallest raster offset in pixels (mlt; default 0.1).
    #[arg(long, value_parser = parse_lens_min)]
    pub lens_min: Option<f32>,
}

/// Options of the photon mappers.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct PhotonArgs {
    /// Photons traced per pass (ppm, sppm; default 250,000).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub photons_per_pass: Option<u64>,
    /// Fraction of each pass's photons a pixel keeps, in (0, 1) (ppm, sppm; default 0.7), or
    /// the merge radius reduction: pass i's radius is r (i + 1)^((alpha - 1) / 2) (vcm, bpm;
    /// default 0.75).
    #[arg(long, value_parser = parse_alpha)]
    pub alpha: Option<f32>,
    /// Initial gather radius in scene units (default: a multiple of the width of a pixel where
    /// the camera's rays first hit, their median: 5.6 for sppm, 2.8 for ppm, 1.5 for vcm and
    /// bpm).
    #[arg(long, value_parser = parse_radius)]
    pub radius: Option<f32>,
    /// Eye-ray trees per pixel, jittered over it as a stratified net (ppm: its hit points are
    /// fixed, so only they average the pixel's area; memory grows with them; default 16).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub eye_rays: Option<u32>,
    /// Photons traced for the photon maps (pm; default 250,000).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub photons: Option<u64>,
    /// Photons per density estimate (pm; at least 2: the estimate sums the k - 1 nearest over
    /// the disc through the k-th; default 50).
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..))]
    pub k: Option<u32>,
    /// Largest density-estimate radius in scene units (pm; default: 2% of the scene's
    /// bounding-box diagonal).
    #[arg(long, value_parser = parse_radius)]
    pub max_radius: Option<f32>,
    /// Take indirect light straight from the global photon map instead of final gathering
    /// (pm).
    #[arg(long)]
    pub no_final_gather: bool,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum MisName {
    /// Veach's power heuristic (exponent 2).
    Power,
    /// The balance heuristic.
    Balance,
}

/// Samples per pixel of a reference when neither --spp nor --time is given.
pub const DEFAULT_REFERENCE_SPP: u64 = 4096;

#[derive(clap::Args, Debug)]
pub struct ReferenceArgs {
    /// Scene file: RON, or Mitsuba 3 XML (.xml).
    pub scene: PathBuf,
    /// An integrator that resumes from a checkpoint: pt, bdpt, or the photon mappers (pm,
    /// ppm, sppm: --spp counts passes).
    #[arg(long, default_value = "pt", value_parser = IntegratorParser)]
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
    /// Where random numbers come from: `independent` (hashed) or `sobol` (Owen-scrambled
    /// Sobol' with Morton-ordered pixels).
    #[arg(long, default_value = "independent", value_parser = parse_sampler)]
    pub sampler: SamplerKind,
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
    /// Seconds between checkpoints (at most 1e9).
    #[arg(long, default_value = "30", value_parser = parse_checkpoint_seconds)]
    pub checkpoint_every: f64,
    #[command(flatten)]
    pub photons: PhotonArgs,
    #[command(flatten)]
    pub kernel: KernelArgs,
    #[command(flatten)]
    pub shard: ShardArgs,
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
    #[arg(required_unless_present_any = ["preset", "plan"], conflicts_with = "preset")]
    pub scene: Option<PathBuf>,
    /// Reference EXR of the scene (default: made with `reference` in the output folder, or
    /// resumed from there, at --reference-spp).
    #[arg(long, conflicts_with = "preset")]
    pub reference: Option<PathBuf>,
    /// Integrators to compare, comma-separated (default: every integrator listed below).
    #[arg(long, value_delimiter = ',', value_parser = IntegratorParser, conflicts_with = "preset")]
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
    /// Where random numbers come from: `independent` (hashed) or `sobol` (Owen-scrambled
    /// Sobol' with Morton-ordered pixels).
    #[arg(long, default_value = "independent", value_parser = parse_sampler)]
    pub sampler: SamplerKind,
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
    /// With --preset: a folder of given references, one SCENE.exr per scene (halves
    /// SCENE.a.exr and SCENE.b.exr beside them give the references' own noise); default: the
    /// preset makes its own with pt at --reference-spp.
    #[arg(long, requires = "preset")]
    pub references: Option<PathBuf>,
    /// Photons per pass of the thesis preset's biased runs (PM traces this many in all).
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u64).range(1..),
          default_values_t = crate::compare::thesis::PHOTONS_PER_PASS)]
    pub thesis_photons: Vec<u64>,
    #[command(flatten)]
    pub photons: PhotonArgs,
    /// A plan written by `stagelight slurm ... -- compare ...`: with --shard I/N, render task
    /// I's shards of it; alone, merge every task's shards and write the report.
    #[arg(long, value_name = "PLAN.ron",
          conflicts_with_all = ["scene", "preset", "reference", "integrators", "references",
                                "budgets", "budget_unit", "seed", "sampler", "max_depth",
                                "reference_spp", "scenes_dir", "thesis_photons", "output",
                                "kernel", "wavefront"])]
    pub plan: Option<PathBuf>,
    /// With --plan: the task to render, I of N.
    #[arg(long, value_name = "I/N", value_parser = parse_shard, requires = "plan")]
    pub shard: Option<(u64, u64)>,
    /// The kernel and wavefront of the pt (and bdpt) runs.
    #[command(flatten)]
    pub kernel: KernelArgs,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// What a `compare ...` command line (a plan's, or the one `stagelight slurm` shards) asks
/// for, parsed as `stagelight` parses it.
pub fn compare_request(command: &[String]) -> Result<crate::compare::shards::CompareRequest> {
    use crate::compare::shards::CompareRequest;
    let line = ["stagelight"]
        .into_iter()
        .chain(command.iter().map(String::as_str));
    let parsed = Cli::try_parse_from(line).map_err(|e| {
        let text = e.render().to_string();
        anyhow::anyhow!(
            "the compare command: {}",
            text.lines()
                .next()
                .unwrap_or_default()
                .trim_start_matches("error: ")
        )
    })?;
    match parsed.command {
        Command::Compare(a) if a.plan.is_some() => {
            anyhow::bail!("the compare command to shard cannot have a --plan of its own")
        }
        Command::Compare(a) if a.preset == Some(Preset::Thesis) => {
            Ok(CompareRequest::Thesis(a.thesis_options()))
        }
        Command::Compare(a) => Ok(CompareRequest::Plain(a.options()?)),
        _ => anyhow::bail!("not a compare command"),
    }
}

/// Runs the command line; returns the process exit code (0 success, 1 error, 130 interrupted).
pub fn main() -> i32 {
    // Allocations of 4 MiB or more get fresh pages of their own (glibc raises its threshold
    // for that to the largest block freed so far, up to 32 MiB, so a scene's columns were
    // carved out of memory its loading had already touched): only fresh pages can be huge
    // pages, and on big_1m `sort_by_material`, which reads the triangle columns at every hit,
    // takes 10-25% less time with them there (`TriangleColumns::move_to_huge_pages`).
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes how glibc serves later allocations; no memory changes hands.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 4 << 20);
    }
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { 1 } else { 0 };
            let text = e.render().to_string();
            if e.use_stderr()
                && text
                    .split_whitespace()
                    .any(|w| w.chars().count() > MAX_WORD)
            {
                // clap repeats the value it refused: a huge one is cut.
                let mut lines = text.lines();
                let first = lines.next().unwrap_or_default();
                eprintln!("{}", one_line(first));
                for line in lines {
                    eprintln!("{line}");
                }
            } else {
                let _ = e.print();
            }
            return code;
        }
    };
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", one_line(&format!("{e:#}")));
            1
        }
    }
}

/// What a Mitsuba scene file gives as defaults for `--spp` and `--max-depth` (nothing for a
/// RON scene, or a file that cannot be read: loading it reports that).
fn file_settings(scene: &std::path::Path) -> Result<crate::scene::mitsuba::FileSettings> {
    if !crate::scene::is_mitsuba(scene) || !scene.is_file() {
        return Ok(Default::default());
    }
    Ok(crate::scene::mitsuba::build::file_settings(
        scene,
        crate::commands::scene_defines(),
    )?)
}

/// Turns the parsed command line into a command's options and runs it.
fn run(cli: Cli) -> Result<i32> {
    crate::commands::set_scene_defines(cli.define);
    match cli.command {
        Command::Render(mut args) => {
            let file = file_settings(&args.scene)?;
            if args.time.is_none() {
                args.spp = args.spp.or(file.spp);
            }
            args.max_depth = args.max_depth.or(file.max_depth);
            crate::commands::render::render(&args.options())
        }
        Command::Reference(mut args) => {
            args.max_depth = args.max_depth.or(file_settings(&args.scene)?.max_depth);
            crate::commands::reference::reference(&args.options())
        }
        Command::Merge(args) => crate::commands::merge::merge(&args.parts, &args.output),
        Command::Slurm(args) => crate::commands::slurm::write(&args.options()?),
        Command::Compare(args) if args.plan.is_some() => crate::compare::shards::run_plan(
            compare_request,
            args.plan.as_deref().unwrap_or(std::path::Path::new("")),
            args.shard,
            args.threads.map(|t| t as usize),
            args.quiet,
        ),
        Command::Compare(args) if args.preset == Some(Preset::Thesis) => {
            crate::compare::thesis::run(&args.thesis_options())
        }
        Command::Compare(mut args) => {
            if let Some(scene) = &args.scene {
                args.max_depth = args.max_depth.or(file_settings(scene)?.max_depth);
            }
            crate::compare::run::compare(&args.options()?)
        }
        Command::Export { scene, output } => {
            crate::commands::export(&scene, &output)?;
            Ok(0)
        }
        Command::Graph {
            scene,
            integrator,
            no_final_gather,
        } => {
            crate::commands::graph(&scene, integrator, !no_final_gather)?;
            Ok(0)
        }
        Command::View {
            images,
            reference,
            output,
        } => {
            crate::viewer::view::view(&crate::viewer::view::ViewOptions {
                images,
                reference,
                output,
            })?;
            Ok(0)
        }
        Command::Diff { image, reference } => {
            crate::commands::diff(&image, &reference)?;
            Ok(0)
        }
        Command::Bench {
            rays: Some(dir),
            runs,
            threads,
            save,
            ..
        } => {
            crate::commands::rays::bench_rays(&crate::commands::rays::RayBenchOptions {
                dir,
                threads: threads.map(|t| t as usize),
                runs,
                save,
            })?;
            Ok(0)
        }
        Command::Rays(a) => {
            crate::commands::rays::rays(&crate::commands::rays::RaysOptions {
                scene: a.scene,
                out: a.out,
                spp: a.spp,
                bounces: a.bounces.map(|b| b as usize),
                threads: a.threads.map(|t| t as usize),
            })?;
            Ok(0)
        }
        Command::Bench {
            rays: None,
            scene,
            big,
            save,
            baseline,
            integrator,
            spp,
            runs,
            threads,
            kernel,
            sweep,
        } => {
            let max_depth = match &scene {
                Some(scene) => file_settings(scene)?.max_depth,
                None => None,
            };
            crate::commands::bench::bench(&BenchOptions {
                scene,
                big,
                save,
                baseline,
                integrator,
                spp,
                runs,
                threads: threads.map(|t| t as usize),
                settings: kernel.apply(RenderSettings {
                    max_depth: max_depth.unwrap_or(u32::MAX),
                    ..RenderSettings::default()
                }),
                sweep,
            })?;
            Ok(0)
        }
    }
}
