//! What the commands print: the end-of-render report, the bench table and the diff lines.

use crate::integrators::pt::Kernel;
use crate::integrators::{IntegratorKind, RenderOutcome, SceneData};
use crate::metrics::ErrorMetrics;
use crate::sysinfo::peak_memory_bytes;
use std::fmt::Write;
use std::path::Path;

pub use crate::units::mega;

/// The end-of-render report: passes, time, throughput, memory, and each system's share.
pub fn render_report(
    scene: &Path,
    integrator: IntegratorKind,
    threads: usize,
    o: &RenderOutcome,
    cpu: f64,
    data: &SceneData,
) -> String {
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
        "  NaN/Inf samples   {} (counted as black, never added){}{}",
        o.film.nonfinite,
        if o.film.nonfinite_splats > 0 {
            format!("; {} NaN/Inf splats dropped", o.film.nonfinite_splats)
        } else {
            String::new()
        },
        if o.film.out_of_range > 0 {
            format!(
                "; {} samples or splats beyond the film's range (+-2^63) rejected",
                o.film.out_of_range
            )
        } else {
            String::new()
        }
    );
    let _ = writeln!(
        r,
        "  memory            peak {:.1} MiB; {} paths in flight x {} bytes/path = {:.1} MiB",
        peak_memory_bytes() as f64 / (1 << 20) as f64,
        o.wavefront,
        o.bytes_per_path,
        (o.wavefront * o.bytes_per_path) as f64 / (1 << 20) as f64
    );
    for (label, value) in &o.notes {
        let _ = writeln!(r, "  {label:<17} {value}");
    }
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

/// Share of rejected (NaN or infinite) samples above which a render warns: they count as
/// black, so the image is darker by about that share.
pub const NONFINITE_WARNING_SHARE: f64 = 0.001;

/// A warning when many samples (or splats) were NaN or infinite: the image is then darker
/// than it should be (or lacks light tracing's part), which a user must not miss.
pub fn nonfinite_warning(film: &crate::film::Film) -> Option<String> {
    let samples = film.total_samples().max(1);
    let share = film.nonfinite as f64 / samples as f64;
    if share > NONFINITE_WARNING_SHARE {
        return Some(format!(
            "{:.2}% of the samples ({} of {samples}) were NaN or infinite and count as black: \
             the image is too dark (very bright lights or extreme geometry overflow f32)",
            100.0 * share,
            film.nonfinite
        ));
    }
    if film.out_of_range > 0 {
        return Some(format!(
            "{} samples or splats were beyond the film's range (a pixel sum beyond 2^63 = \
             9.2e18) and were rejected: the image is too dark where they fell",
            film.out_of_range
        ));
    }
    if film.nonfinite_splats as f64 > NONFINITE_WARNING_SHARE * samples as f64 {
        return Some(format!(
            "{} light-tracing splats were NaN or infinite and were dropped: the image lacks \
             part of its light",
            film.nonfinite_splats
        ));
    }
    None
}

/// The timed runs of a bench: each run's rates, and the last run itself.
#[derive(Default)]
pub struct BenchRuns {
    samples_per_s: Vec<f64>,
    closest_per_s: Vec<f64>,
    shadow_per_s: Vec<f64>,
    /// Empty for integrators without photons.
    photons_per_s: Vec<f64>,
    passes_per_s: Vec<f64>,
    /// The last run and its CPU seconds.
    last: Option<(RenderOutcome, f64)>,
}

impl BenchRuns {
    /// Adds a timed run that took `wall` and `cpu` seconds.
    pub fn add(&mut self, o: RenderOutcome, wall: f64, cpu: f64) {
        self.samples_per_s.push(o.samples as f64 / wall);
        self.closest_per_s.push(o.closest_rays() as f64 / wall);
        self.shadow_per_s.push(o.shadow_rays() as f64 / wall);
        if let Some(emit) = o.stats.get("emit_photons") {
            self.photons_per_s.push(emit.emitted as f64 / wall);
            self.passes_per_s.push(o.passes as f64 / wall);
        }
        self.last = Some((o, cpu));
    }

    /// Each rate's name and its value in every run (photons/s and passes/s only for the
    /// photon mappers).
    pub fn rates(&self) -> Vec<(&'static str, &[f64])> {
        [
            ("samples/s", &self.samples_per_s),
            ("closest-hit rays/s", &self.closest_per_s),
            ("shadow rays/s", &self.shadow_per_s),
            ("photons/s", &self.photons_per_s),
            ("passes/s", &self.passes_per_s),
        ]
        .into_iter()
        .filter(|(_, v)| !v.is_empty())
        .map(|(name, v)| (name, v.as_slice()))
        .collect()
    }
}

/// The bench table (Markdown): median, min and max of each rate over the runs, then the
/// last run's memory, CPU use and systems. `bench` names the integrator (with its kernel and
/// wavefront where not the defaults).
pub fn bench_table(
    scene: &Path,
    bench: &str,
    spp: u64,
    threads: usize,
    mut runs: BenchRuns,
) -> String {
    let count = runs.samples_per_s.len();
    let (o, cpu) = runs.last.take().expect("at least one run");
    let mut t = String::new();
    let _ = writeln!(
        t,
        "bench {} ({}, {} spp, {} runs after a warm-up, {} threads)",
        scene.display(),
        bench,
        spp,
        count,
        threads
    );
    let _ = writeln!(t, "| measure | median | min | max |");
    let _ = writeln!(t, "|---|---|---|---|");
    for (name, v) in [
        ("samples/s", &mut runs.samples_per_s),
        ("closest-hit rays/s", &mut runs.closest_per_s),
        ("shadow rays/s", &mut runs.shadow_per_s),
        ("photons/s", &mut runs.photons_per_s),
        ("passes/s", &mut runs.passes_per_s),
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
    for (label, value) in &o.notes {
        let _ = writeln!(t, "| {label} (last run) | {value} | | |");
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
    t
}

/// The lines of `stagelight diff`: the error measures and both images' channel means.
pub fn diff_report(image: &Path, reference: &Path, m: &ErrorMetrics) -> String {
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
    t
}

/// `bench --sweep`'s tables (Markdown): for each kernel and wavefront, samples/s over the runs
/// and the state in flight; then each system's wall nanoseconds per sample (last run), where
/// the time goes as the wavefront grows.
pub fn sweep_table(
    scene: &Path,
    integrator: IntegratorKind,
    spp: u64,
    threads: usize,
    rows: Vec<(Kernel, BenchRuns)>,
) -> String {
    let mut t = String::new();
    let count = rows.first().map_or(0, |(_, r)| r.samples_per_s.len());
    let _ = writeln!(
        t,
        "sweep {} ({}, {} spp, {} runs after a warm-up each, {} threads)",
        scene.display(),
        integrator.as_str(),
        spp,
        count,
        threads
    );
    let _ = writeln!(
        t,
        "| kernel | paths in flight | samples/s median (min-max) | bytes per path | state MiB | CPU s / wall s |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|");
    let mut systems: Vec<&'static str> = Vec::new();
    for (_, runs) in &rows {
        if let Some((o, _)) = &runs.last {
            for s in &o.stats.systems {
                if !systems.contains(&s.name) {
                    systems.push(s.name);
                }
            }
        }
    }
    let mut per_system = String::new();
    let _ = writeln!(
        per_system,
        "\nwall ns per sample by system (last run)\n| kernel | paths in flight | {} | total |",
        systems.join(" | ")
    );
    let _ = writeln!(per_system, "|---|---|{}---|", "---|".repeat(systems.len()));
    for (kernel, runs) in rows {
        let mut rates = runs.samples_per_s.clone();
        rates.sort_by(f64::total_cmp);
        let Some((o, cpu)) = &runs.last else {
            continue;
        };
        let (in_flight, bytes) = match kernel {
            Kernel::Wavefront => (o.wavefront.to_string(), o.bytes_per_path.to_string()),
            Kernel::Megakernel => (
                format!("{threads} (one per thread)"),
                format!(
                    "{} per sample of a wave of {}",
                    o.bytes_per_path, o.wavefront
                ),
            ),
        };
        let _ = writeln!(
            t,
            "| {kernel} | {in_flight} | {} ({}-{}) | {bytes} | {:.1} | {:.2} |",
            mega(rates[rates.len() / 2]),
            mega(rates[0]),
            mega(rates[rates.len() - 1]),
            (o.wavefront * o.bytes_per_path) as f64 / (1 << 20) as f64,
            cpu / o.wall.as_secs_f64(),
        );
        let samples = o.samples.max(1) as f64;
        let ns = |name: &str| {
            o.stats.get(name).map_or("".to_string(), |s| {
                format!("{:.1}", s.time.as_secs_f64() * 1e9 / samples)
            })
        };
        let cells: Vec<String> = systems.iter().map(|n| ns(n)).collect();
        let _ = writeln!(
            per_system,
            "| {kernel} | {in_flight} | {} | {:.1} |",
            cells.join(" | "),
            o.stats.total_time().as_secs_f64() * 1e9 / samples
        );
    }
    t + &per_system
}
