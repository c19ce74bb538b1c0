//! The commands' bodies, each taking plain options (`cli` turns the command line into them),
//! and what they share at the terminal: worker pools, Ctrl-C, scene loading with its warnings,
//! progress bars, and stdout that tolerates a closed pipe. The compare command lives in
//! `compare::run` and `compare::thesis`.

pub mod bench;
pub mod big_scenes;
pub mod merge;
pub mod rays;
pub mod reference;
pub mod render;
pub mod slurm;

use crate::film::Image;
use crate::integrators::pt::{self, Kernel};
use crate::integrators::{Budget, IntegratorKind, RenderSettings, SceneData, bdpt};
use anyhow::{Context, Result, bail};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Exit code of an interrupted command that saved its finished work.
pub const EXIT_INTERRUPTED: i32 = 130;

/// The exit code of a command that ended, interrupted or not.
pub fn exit_code(interrupted: bool) -> i32 {
    if interrupted { EXIT_INTERRUPTED } else { 0 }
}

/// The most worker threads a command starts: 8 per core, and at least 256 (more only
/// thrash; a mistyped count would exhaust the machine's process table).
pub fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (8 * cores).max(256)
}

/// Checks a `--threads` count (1..=`max_threads()`).
pub fn check_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads
        && n > max_threads()
    {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        bail!(
            "--threads {n}: at most {} threads (this machine has {cores} cores)",
            max_threads()
        );
    }
    Ok(())
}

/// A pool of `threads` workers (default: all cores); a count above `max_threads()` is
/// refused.
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    check_threads(threads)?;
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        builder = builder.num_threads(n);
    }
    builder.build().context("cannot start the worker threads")
}

/// The command line's `-D NAME=VALUE` scene parameters, set once when it is parsed.
static SCENE_DEFINES: std::sync::OnceLock<Vec<(String, String)>> = std::sync::OnceLock::new();

/// Records the command line's scene parameters (the first call wins).
pub fn set_scene_defines(defines: Vec<(String, String)>) {
    let _ = SCENE_DEFINES.set(defines);
}

/// The command line's scene parameters (none before `set_scene_defines`).
pub fn scene_defines() -> &'static [(String, String)] {
    SCENE_DEFINES.get().map_or(&[], |d| d.as_slice())
}

/// `stagelight export`: a RON scene written as a Mitsuba scene file.
pub fn export(scene: &Path, output: &Path) -> Result<()> {
    if crate::scene::is_mitsuba(scene) {
        anyhow::bail!("{}: is already a Mitsuba scene file", scene.display());
    }
    if !crate::scene::is_mitsuba(output) {
        anyhow::bail!(
            "{}: the output is a Mitsuba scene file, SCENE.xml",
            output.display()
        );
    }
    let bytes = std::fs::read(scene)
        .with_context(|| format!("{}: cannot read the scene file", scene.display()))?;
    let text = crate::scene::text_of(scene, &bytes)?;
    let parsed = crate::scene::parse(scene, text)?;
    let world = crate::scene::world::build(&parsed)?;
    crate::scene::mitsuba::export::export(&parsed, &world, output).map_err(anyhow::Error::msg)?;
    println!("wrote {}", output.display());
    Ok(())
}

/// Loads and prepares a scene (RON or Mitsuba XML, with the command line's `-D` parameters),
/// printing its warnings.
pub fn load_scene(path: &Path) -> Result<Arc<SceneData>> {
    let scene = crate::scene::load_with_defines(
        path,
        scene_defines(),
        &crate::scene::Limits::of_this_machine(),
    )?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    Ok(Arc::new(SceneData::new(scene)))
}

/// Which passes a shard renders, as the command line said it (`--shard I/N` or
/// `--pass-range FIRST..END`), before the render's pass count is known.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShardChoice {
    Shard { index: u64, count: u64 },
    Range { first: u64, end: u64 },
}

impl ShardChoice {
    /// The passes of a render of `total` passes this shard makes.
    pub fn range(self, total: u64) -> Result<crate::reference::PassRange> {
        use crate::reference::PassRange;
        match self {
            ShardChoice::Shard { index, count } => PassRange::shard(index, count, total),
            ShardChoice::Range { first, end } => PassRange::explicit(first, end, total),
        }
        .map_err(anyhow::Error::msg)
    }
}

/// Checks, before any rendering, that every output can be written (`film::output::
/// check_writable`: its folder is created) and that none is an input file (the scene, a
/// reference).
pub fn check_outputs(outputs: &[&Path], inputs: &[&Path]) -> Result<()> {
    for output in outputs {
        for input in inputs {
            if crate::film::output::same_file(output, input) {
                bail!(
                    "{}: the output is the input file {}: choose another output",
                    output.display(),
                    input.display()
                );
            }
        }
    }
    for output in outputs {
        crate::film::output::check_writable(output)?;
    }
    Ok(())
}

/// Checks that `spp` passes of the scene's image can be counted: spp x pixels samples fit in
/// a u64 (they wrapped to 0 passes and a black image).
pub fn check_samples(option: &str, spp: u64, data: &SceneData) -> Result<()> {
    let cam = data.scene.camera;
    let pixels = cam.width as u64 * cam.height as u64;
    if spp.checked_mul(pixels).is_none() {
        bail!(
            "{option} {spp}: {spp} passes of {}x{} pixels are more samples than can be \
             counted (at most {} passes at this size)",
            cam.width,
            cam.height,
            u64::MAX / pixels
        );
    }
    Ok(())
}

/// Bytes per pixel of the film and the images written from it (the fixed-point sums, 3 x 16
/// bytes, the count, the image and its encoding).
const FILM_BYTES_PER_PIXEL: u64 = 88;
/// Bytes per emitted photon of the photon mappers (the photons stored at each bounce and
/// their index).
const PHOTON_BYTES: u64 = 200;

/// An estimate of the memory a render takes beyond its scene (loaded already): the film,
/// the integrator's state and its photons.
pub fn render_memory(
    kind: IntegratorKind,
    settings: &RenderSettings,
    data: &SceneData,
    threads: usize,
) -> u64 {
    let cam = data.scene.camera;
    let pixels = cam.width as u64 * cam.height as u64;
    let film = pixels.saturating_mul(FILM_BYTES_PER_PIXEL);
    let p = &settings.photons;
    let wavefront = |default: usize| settings.wavefront.unwrap_or(default) as u64;
    let state = match kind.as_str() {
        // Wavefronts of at most 2^18 (pt) and 2^15 (bdpt) paths unless --wavefront says
        // otherwise; the megakernel keeps 12 bytes per sample of a wave; bdpt's film has
        // splats.
        "pt" => match settings.kernel {
            Kernel::Wavefront => wavefront(pt::WAVEFRONT).saturating_mul(300),
            Kernel::Megakernel => wavefront(pt::WAVEFRONT).saturating_mul(12),
        },
        "bdpt" => wavefront(bdpt::WAVEFRONT)
            .saturating_mul(4200)
            .saturating_add(pixels.saturating_mul(48)),
        // The photon mappers keep state per pixel, and photons.
        "pm" => pixels
            .saturating_mul(800)
            .saturating_add(p.photons.saturating_mul(PHOTON_BYTES))
            .saturating_add((p.k as u64).saturating_mul(16 * threads as u64)),
        "ppm" | "sppm" => crate::integrators::sppm::ProgressiveSettings::from_render(
            settings,
            kind.as_str() == "sppm",
        )
        .expected_bytes(pixels)
        .saturating_add(p.photons_per_pass.saturating_mul(PHOTON_BYTES)),
        _ => pixels
            .saturating_mul(500)
            .saturating_add(p.photons_per_pass.saturating_mul(PHOTON_BYTES)),
    };
    // pt and bdpt keep a state, film included, per thread (`driver::render_waves_of`).
    let films = if matches!(kind.as_str(), "pt" | "bdpt") {
        threads.max(1) as u64
    } else {
        1
    };
    film.saturating_mul(films).saturating_add(state)
}

/// Refuses each of `flags` (options the command line gives) that `integrator` does not read,
/// naming the integrators that do: an option that would change nothing is a mistake to say.
pub fn refuse_options_of_others<'a>(
    integrator: IntegratorKind,
    flags: impl IntoIterator<Item = &'a str>,
) -> Result<()> {
    for flag in flags {
        if !integrator.info().options.contains(&flag) {
            let takers: Vec<&str> = crate::integrators::REGISTRY
                .iter()
                .filter(|i| i.options.contains(&flag))
                .map(|i| i.name)
                .collect();
            bail!(
                "{flag} is not an option of {integrator}: it is {}'s",
                takers.join(", ")
            );
        }
    }
    Ok(())
}

/// Refuses `--kernel megakernel` for an integrator that has none (only pt has one) and
/// `--wavefront` for one that does not render in waves of samples (pt, bdpt, vcm, bpm do), and
/// `--lanes` for one with nothing in vector lanes.
pub fn check_kernel(kind: IntegratorKind, settings: &RenderSettings) -> Result<()> {
    if settings.kernel == Kernel::Megakernel && kind.as_str() != "pt" {
        bail!("--kernel megakernel: only pt has a megakernel, not {kind}");
    }
    if settings.wavefront.is_some() && !matches!(kind.as_str(), "pt" | "bdpt" | "vcm" | "bpm") {
        bail!("--wavefront: only pt, bdpt, vcm and bpm render in waves of samples, not {kind}");
    }
    let in_lanes = match kind.as_str() {
        "pt" => settings.kernel == Kernel::Wavefront,
        // Their connections' weights.
        "bdpt" | "vcm" => true,
        _ => false,
    };
    if settings.lanes.is_some() && !in_lanes {
        bail!("--lanes: only pt's wavefront, bdpt and vcm work in vector lanes, not {kind}");
    }
    Ok(())
}

/// Refuses a render whose estimated memory exceeds what this process may use.
pub fn check_render_memory(
    kind: IntegratorKind,
    settings: &RenderSettings,
    data: &SceneData,
    threads: usize,
) -> Result<()> {
    // Every render is checked here before it starts: the camera's needs too.
    crate::integrators::check_camera(kind, &data.scene.camera)
        .map_err(|e| anyhow::anyhow!("{}: {e}", data.scene.source.display()))?;
    // PM's estimate takes the k nearest of the stored photons.
    if kind.as_str() == "pm" && settings.photons.k as u64 > settings.photons.photons {
        bail!(
            "--k {}: a density estimate cannot take more photons than --photons {} traces",
            settings.photons.k,
            settings.photons.photons
        );
    }
    let cam = data.scene.camera;
    let what = match kind.as_str() {
        "pm" => format!(
            "{} at {}x{} with {} photons",
            kind, cam.width, cam.height, settings.photons.photons
        ),
        "ppm" | "sppm" => format!(
            "{} at {}x{} with {} photons per pass",
            kind, cam.width, cam.height, settings.photons.photons_per_pass
        ),
        _ => format!("{} at {}x{}", kind, cam.width, cam.height),
    };
    crate::sysinfo::check_memory(
        &format!("rendering {what}"),
        render_memory(kind, settings, data, threads),
        crate::sysinfo::memory_limit(),
    )
    .map_err(|e| anyhow::anyhow!("{}: {e}", data.scene.source.display()))?;
    Ok(())
}

/// The file stem of a scene, for default output names and titles.
pub fn scene_stem(scene: &Path) -> String {
    scene
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy().into_owned())
}

/// A flag Ctrl-C (SIGINT), SIGTERM and SIGHUP set: renders stop after the passes in flight,
/// write what they finished and exit 130. A second signal ends the process at once with 130,
/// nothing more written: a pass can take long (issue 29: a scene whose one huge triangle made
/// a photon pass take minutes), and outputs are written to temporary files and renamed, so
/// any output left is a whole file.
pub fn stop_on_ctrl_c() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            eprintln!("second stop signal: ending now, without writing");
            std::process::exit(130);
        }
    })
    .context("cannot install the Ctrl-C handler")?;
    Ok(stop)
}

/// A bar over a render's budget (passes, or whole seconds); hidden when quiet.
pub fn budget_bar(budget: Budget, quiet: bool) -> indicatif::ProgressBar {
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

/// A bar over `len` units whose position the caller sets; hidden when quiet.
pub fn unit_bar(len: u64, template: &str, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len.max(1));
    let style = indicatif::ProgressStyle::with_template(template)
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
    bar.set_style(style);
    bar
}

/// Writes to stdout, ignoring a closed pipe (`stagelight render ... | head` is fine).
pub fn print_out(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = out.write_all(text.as_bytes()).and_then(|_| out.flush());
}

/// `stagelight diff`: prints the error of an image against a reference.
pub fn diff(image: &Path, reference: &Path) -> Result<()> {
    let a = Image::read_exr(image)?;
    let b = Image::read_exr(reference)?;
    let m = crate::metrics::compare(&a, &b)
        .with_context(|| format!("{} against {}", image.display(), reference.display()))?;
    print_out(&crate::report::diff_report(image, reference, &m));
    Ok(())
}

/// Prints `integrator`'s graph for the scene at `path` (`stagelight graph`).
pub fn graph(path: &Path, integrator: IntegratorKind, final_gather: bool) -> Result<()> {
    let data = load_scene(path)?;
    let mut settings = RenderSettings::default();
    settings.photons.final_gather = final_gather;
    let report = (integrator.info().graph)(&data, &settings);
    print!("{}", report.description);
    Ok(())
}
