//! `stagelight render`: one image, its PNG preview, and the end-of-render report.

use super::{
    EXIT_INTERRUPTED, budget_bar, check_kernel, check_outputs, check_render_memory, check_samples,
    check_threads, exit_code, load_scene, print_out, stop_on_ctrl_c, thread_pool,
};
use crate::integrators::{Budget, Control, IntegratorKind, RenderSettings, Resume};
use crate::reference::{Checkpoint, CheckpointHeader, checkpoint_path};
use crate::sysinfo::cpu_seconds;
use anyhow::{Result, bail};
use std::path::PathBuf;

/// What a render was asked for.
pub struct RenderOptions {
    /// Scene file (RON).
    pub scene: PathBuf,
    pub integrator: IntegratorKind,
    pub budget: Budget,
    pub settings: RenderSettings,
    /// Folder of each strategy's weighted contribution (bdpt; `settings.strategy_images`
    /// says the same).
    pub strategy_images: Option<PathBuf>,
    /// Output EXR; the PNG preview goes beside it.
    pub output: PathBuf,
    /// Where each pixel's sample variance goes (`--variance`; pt; `settings.moments` says
    /// the same).
    pub variance: Option<PathBuf>,
    /// The Metropolis and photon mappers' options the command line gives (`--sigma`,
    /// `--radius`, ...), refused where the integrator does not read them.
    pub integrator_flags: Vec<&'static str>,
    /// Only a shard of the passes (`--shard I/N` or `--pass-range`): its image and its
    /// partial film (`OUT.exr.checkpoint`) for `stagelight merge`.
    pub shard: Option<super::ShardChoice>,
    /// Worker threads (None: all cores).
    pub threads: Option<usize>,
    /// No progress bar.
    pub quiet: bool,
}

/// The checks of a render's options against its integrator, before the scene is read (the
/// command line and the Python module make the same ones, with the same messages).
pub fn check_integrator_options(o: &RenderOptions) -> Result<()> {
    if o.strategy_images.is_some() && !o.integrator.info().options.contains(&"--strategy-images") {
        bail!("--strategy-images needs --integrator bdpt or mmlt");
    }
    super::refuse_options_of_others(o.integrator, o.integrator_flags.iter().copied())?;
    if o.settings.light_vertex_cache > 0
        && !o
            .integrator
            .info()
            .options
            .contains(&"--light-vertex-cache")
    {
        bail!(
            "--light-vertex-cache needs --integrator bdpt, not {}",
            o.integrator
        );
    }
    if o.variance.is_some() && o.integrator.as_str() != "pt" {
        bail!(
            "--variance: a pixel's sample variance is that of pt's per-sample estimates; {} \
             has no such samples (its pixels mix light-path splats or density estimates)",
            o.integrator
        );
    }
    check_threads(o.threads)?;
    check_kernel(o.integrator, &o.settings)
}

/// Renders, writes the EXR, its preview and any strategy images, prints the report. Returns
/// the exit code: 0, or `EXIT_INTERRUPTED` when Ctrl-C stopped it (the finished passes are
/// written).
pub fn render(o: &RenderOptions) -> Result<i32> {
    let output = &o.output;
    if output
        .extension()
        .is_none_or(|e| !e.eq_ignore_ascii_case("exr"))
    {
        bail!("{}: the output must be an .exr file", output.display());
    }
    check_integrator_options(o)?;
    if let Some(path) = &o.variance {
        if path
            .extension()
            .is_none_or(|e| !e.eq_ignore_ascii_case("exr"))
        {
            bail!("{}: --variance must be an .exr file", path.display());
        }
        if o.shard.is_some() {
            bail!(
                "--variance is not made by shards (their checkpoints hold no squares): render it without --shard"
            );
        }
    }
    let data = load_scene(&o.scene)?;
    if let Budget::SamplesPerPixel(spp) = o.budget {
        check_samples("--spp", spp, &data)?;
    }
    let shard = match (o.shard, o.budget) {
        (None, _) => None,
        (Some(_), _) if o.strategy_images.is_some() => {
            bail!("--strategy-images are not made by shards: render them without --shard")
        }
        (Some(_), _) if data.scene.camera.filter != crate::film::PixelFilter::Box => {
            bail!(
                "{}: --shard writes a checkpoint of box-filtered sums, not the gaussian \
                 rfilter's weights: add <rfilter type=\"box\"/> to the film, or render without \
                 --shard",
                o.scene.display()
            )
        }
        (Some(choice), Budget::SamplesPerPixel(spp)) => Some(choice.range(spp)?),
        (Some(_), Budget::Seconds(_)) => {
            bail!("--shard and --pass-range split --spp passes, not a --time budget")
        }
    };
    let png = output.with_extension("png");
    let film_file = checkpoint_path(output);
    // Every output is checked before the render, not found unwritable after it.
    let mut outputs = vec![output.as_path(), png.as_path()];
    if shard.is_some() {
        outputs.push(&film_file);
    }
    let strategy_probe = o.strategy_images.as_ref().map(|dir| dir.join("s1_t1.exr"));
    outputs.extend(strategy_probe.as_deref());
    outputs.extend(o.variance.as_deref());
    check_outputs(&outputs, &[&o.scene])?;
    let stop = stop_on_ctrl_c()?;
    let pool = thread_pool(o.threads)?;
    let threads = pool.current_num_threads();
    check_render_memory(o.integrator, &o.settings, &data, threads)?;
    let budget = o.budget;
    let bar = budget_bar(budget, o.quiet);
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
    let cpu_start = cpu_seconds();
    let unbiased = o.integrator.is_unbiased();
    let mut outcome = pool.install(|| match shard {
        None => {
            crate::integrators::render(o.integrator, data.clone(), &o.settings, budget, &control)
        }
        Some(range) if !unbiased => {
            // An independent run of the shard's share, with its own seed.
            let settings = RenderSettings {
                seed: range.independent_seed(o.settings.seed),
                ..o.settings
            };
            let budget = Budget::SamplesPerPixel(range.end - range.first);
            crate::integrators::render(o.integrator, data.clone(), &settings, budget, &control)
        }
        Some(range) => {
            let start = Resume::shard_start(&data, range.first);
            let budget = Budget::SamplesPerPixel(range.end);
            let settings = &o.settings;
            crate::integrators::resume(
                o.integrator,
                data.clone(),
                settings,
                budget,
                &control,
                start,
            )
        }
    });
    let cpu = cpu_seconds() - cpu_start;
    bar.finish_and_clear();
    let mut shard_end = 0;
    if let Some(range) = shard {
        // The report counts this shard's passes; its film lies beside the image.
        let pixels = data.scene.camera.width as u64 * data.scene.camera.height as u64;
        let (film, passes) = if unbiased {
            outcome.passes -= range.first;
            outcome.samples -= range.first * pixels;
            (outcome.film.clone(), range.first + outcome.passes)
        } else {
            // Its image weighted by its mutations (MLT) or passes x pixels (the photon
            // mappers), the weight as each pixel's count: adding such films averages
            // the images by weight. Passes here are the --spp unit (mutations per pixel
            // for MLT), of which an interrupted run has done fewer.
            let done = if outcome.interrupted {
                (outcome.samples / pixels).min(range.end - range.first)
            } else {
                range.end - range.first
            };
            let film = crate::reference::weighted_film(
                &outcome.film.image(),
                outcome.samples,
                &outcome.film,
            );
            (film, range.first + done)
        };
        shard_end = passes;
        let header = CheckpointHeader {
            passes,
            seconds: outcome.wall.as_secs_f64(),
            nonfinite: film.nonfinite,
            nonfinite_splats: film.nonfinite_splats,
            out_of_range: film.out_of_range,
            made_by: "render".into(),
            ..CheckpointHeader::start(&o.scene, &data, o.integrator, &o.settings, Some(range))
        };
        if outcome.passes > 0 {
            Checkpoint { header, film }.write(&film_file)?;
        }
    }

    if outcome.passes == 0 {
        // Nothing finished: an existing output is better than a black image.
        print_out(&format!(
            "interrupted before the first pass finished: nothing written ({} is as it was)\n",
            output.display()
        ));
        return Ok(EXIT_INTERRUPTED);
    }
    let image = outcome.film.image();
    image.write_exr(output)?;
    image.write_png(&png)?;
    let variance = o
        .variance
        .as_ref()
        .zip(outcome.film.variance_image())
        .map(|(path, v)| v.write_exr(path).map(|()| path));
    let variance = variance.transpose()?;
    if let Some(dir) = &o.strategy_images {
        for (name, layer) in &outcome.layers {
            layer.write_exr(&dir.join(format!("{name}.exr")))?;
        }
    }
    let mut report =
        crate::report::render_report(&o.scene, o.integrator, threads, &outcome, cpu, &data);
    report += &format!("wrote {} and {}\n", output.display(), png.display());
    if let Some(path) = variance {
        report += &format!("wrote {} (each pixel's sample variance)\n", path.display());
    }
    if let Some(range) = shard {
        report += &format!(
            "shard: passes {}..{shard_end} of {}; its film is {} (stagelight merge adds the \
             shards)\n",
            range.first,
            range.total,
            film_file.display()
        );
        if !unbiased {
            report += &format!(
                "shard: an independent run with seed {} (merge averages the shards' images)\n",
                range.independent_seed(o.settings.seed)
            );
        }
    }
    if outcome.interrupted {
        report += &format!(
            "interrupted: saved the {} finished passes ({} samples)\n",
            outcome.passes, outcome.samples
        );
    }
    print_out(&report);
    if let Some(warning) = crate::report::nonfinite_warning(&outcome.film) {
        eprintln!("warning: {warning}");
    }
    Ok(exit_code(outcome.interrupted))
}
