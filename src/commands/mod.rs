//! The commands' bodies, each taking plain options (`cli` turns the command line into them),
//! and what they share at the terminal: worker pools, Ctrl-C, scene loading with its warnings,
//! progress bars, and stdout that tolerates a closed pipe. The compare command lives in
//! `compare::run` and `compare::thesis`.

pub mod bench;
pub mod reference;
pub mod render;

use crate::film::Image;
use crate::integrators::{Budget, IntegratorKind, RenderSettings, SceneData};
use anyhow::{Context, Result};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Exit code of an interrupted command that saved its finished work.
pub const EXIT_INTERRUPTED: i32 = 130;

/// The exit code of a command that ended, interrupted or not.
pub fn exit_code(interrupted: bool) -> i32 {
    if interrupted { EXIT_INTERRUPTED } else { 0 }
}

/// A pool of `threads` workers (default: all cores).
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
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

/// The file stem of a scene, for default output names and titles.
pub fn scene_stem(scene: &Path) -> String {
    scene
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy().into_owned())
}

/// A flag Ctrl-C sets: renders stop after the passes in flight. A second Ctrl-C while files
/// are being written has no further effect.
pub fn stop_on_ctrl_c() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
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
