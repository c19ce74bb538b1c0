//! `stagelight reference`: a long render, checkpointed, that a second run resumes or extends;
//! and the reference a comparison makes for itself.

use super::{
    check_outputs, check_samples, check_threads, exit_code, load_scene, print_out, stop_on_ctrl_c,
    thread_pool, unit_bar,
};
use crate::integrators::{IntegratorKind, RenderSettings};
use crate::reference::{
    ReferenceBudget, ReferenceJob, ReferenceOutcome, checkpoint_path, render_reference,
};
use anyhow::{Result, bail};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

/// What a reference was asked for.
pub struct ReferenceOptions {
    /// Scene file (RON).
    pub scene: PathBuf,
    /// An integrator that resumes (pt, bdpt, pm, ppm, sppm); MLT's are refused.
    pub integrator: IntegratorKind,
    /// Total budget over all runs.
    pub budget: ReferenceBudget,
    pub settings: RenderSettings,
    /// Output EXR; its checkpoint and PNG preview go beside it.
    pub output: PathBuf,
    /// The integrators' own options the command line gives (the photon mappers'), refused
    /// where the integrator does not read them.
    pub integrator_flags: Vec<&'static str>,
    pub checkpoint_every: Duration,
    /// Only a shard of the passes (`--shard I/N` or `--pass-range`), for `stagelight merge`.
    pub shard: Option<super::ShardChoice>,
    /// Worker threads (None: all cores).
    pub threads: Option<usize>,
    /// No progress bar.
    pub quiet: bool,
}

/// Makes, resumes or extends a reference and prints what it did. Returns the exit code: 0,
/// or `EXIT_INTERRUPTED` when Ctrl-C stopped it (the checkpoint holds the passes done).
pub fn reference(o: &ReferenceOptions) -> Result<i32> {
    check_reference_options(o)?;
    let data = load_scene(&o.scene)?;
    let stop = stop_on_ctrl_c()?;
    let (outcome, report) = reference_of(o, data, &stop)?;
    print_out(&report);
    Ok(exit_code(outcome.interrupted))
}

/// The checks of a reference's options before its scene is read (the command line and the
/// Python module make the same ones).
pub fn check_reference_options(o: &ReferenceOptions) -> Result<()> {
    if !o.integrator.resumes() {
        bail!(
            "--integrator {}: a reference needs an integrator that resumes from a checkpoint \
             (pt, bdpt, pm, ppm or sppm)",
            o.integrator
        );
    }
    if o.output
        .extension()
        .is_none_or(|e| !e.eq_ignore_ascii_case("exr"))
    {
        bail!("{}: the output must be an .exr file", o.output.display());
    }
    super::refuse_options_of_others(o.integrator, o.integrator_flags.iter().copied())?;
    check_threads(o.threads)?;
    super::check_kernel(o.integrator, &o.settings)
}

/// Makes, resumes or extends the reference of a loaded scene until its budget is met or
/// `stop` is set; returns what it did and the report the command prints.
pub fn reference_of(
    o: &ReferenceOptions,
    data: std::sync::Arc<crate::integrators::SceneData>,
    stop: &AtomicBool,
) -> Result<(ReferenceOutcome, String)> {
    let output = &o.output;
    if let ReferenceBudget::SamplesPerPixel(spp) = o.budget {
        check_samples("--spp", spp, &data)?;
    }
    let shard = match (o.shard, o.budget) {
        (None, _) => None,
        (Some(choice), ReferenceBudget::SamplesPerPixel(spp)) => Some(choice.range(spp)?),
        (Some(_), ReferenceBudget::Seconds(_)) => {
            bail!("--shard and --pass-range split --spp passes, not a --time budget")
        }
    };
    check_reference_outputs(output, &[&o.scene])?;
    let pool = thread_pool(o.threads)?;
    super::check_render_memory(o.integrator, &o.settings, &data, pool.current_num_threads())?;
    let job = ReferenceJob {
        scene_path: &o.scene,
        data,
        integrator: o.integrator,
        settings: o.settings,
        budget: o.budget,
        output,
        checkpoint_every: o.checkpoint_every,
        shard,
    };
    let outcome = make_reference(&job, stop, &pool, o.quiet)?;
    let mut report = describe_reference(&job, &outcome) + "\n";
    report += &format!(
        "  {} threads, {:.1} s this run, {} NaN/Inf samples; checkpoint {}\n",
        pool.current_num_threads(),
        outcome.seconds_this_run,
        outcome.nonfinite,
        checkpoint_path(output).display()
    );
    if outcome.interrupted {
        report += &format!(
            "interrupted: {} holds the {} finished passes; run the same command again to \
             continue\n",
            output.display(),
            outcome.passes
        );
    }
    Ok((outcome, report))
}

/// Checks the files a reference writes (the EXR, its PNG preview and its checkpoint) before
/// rendering: writable, and none of them an input.
pub fn check_reference_outputs(
    output: &std::path::Path,
    inputs: &[&std::path::Path],
) -> Result<()> {
    let png = output.with_extension("png");
    let checkpoint = checkpoint_path(output);
    check_outputs(&[output, &png, &checkpoint], inputs)
}

/// Makes or continues a reference in `pool`, with a progress bar in its budget's unit.
/// Returns the outcome (interrupted or not).
pub fn make_reference(
    job: &ReferenceJob,
    stop: &AtomicBool,
    pool: &rayon::ThreadPool,
    quiet: bool,
) -> Result<ReferenceOutcome> {
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

/// One line on what a reference run did: made, resumed or already complete, and with what.
pub fn describe_reference(job: &ReferenceJob, o: &ReferenceOutcome) -> String {
    let file = job.output.display();
    let passes = match job.shard {
        Some(r) => format!(
            "passes {}..{} of {} (shard {}..{})",
            r.first, o.passes, r.total, r.first, r.end
        ),
        None => format!("{} spp", o.passes),
    };
    let what = format!(
        "{} at {passes} ({:.1} s of rendering), seed {}, {}",
        job.integrator,
        o.seconds,
        job.settings.seed,
        job.scene_path.display()
    );
    if o.already_complete {
        format!("{file}: already complete with {what}; nothing rendered")
    } else if o.passes_before > job.shard.map_or(0, |r| r.first) {
        let from = match job.shard {
            Some(_) => format!("pass {}", o.passes_before),
            None => format!("{} spp", o.passes_before),
        };
        format!("{file}: resumed from {from} to {what}")
    } else {
        format!("{file}: made with {what}")
    }
}
