//! `stagelight bench`: a scene rendered several times at a fixed budget, its throughput as a
//! table (`report::bench_table`).

use super::{
    check_render_memory, check_samples, check_threads, load_scene, print_out, thread_pool,
};
use crate::integrators::{Budget, Control, IntegratorKind, RenderSettings};
use crate::report::{BenchRuns, bench_table};
use crate::sysinfo::cpu_seconds;
use anyhow::Result;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// What a bench was asked for.
pub struct BenchOptions {
    /// Scene file (RON).
    pub scene: PathBuf,
    pub integrator: IntegratorKind,
    /// Samples per pixel of each timed run.
    pub spp: u64,
    /// Timed runs, after one warm-up run.
    pub runs: u32,
    /// Worker threads (None: all cores).
    pub threads: Option<usize>,
}

/// Renders one warm-up run and `runs` timed ones, and prints the table.
pub fn bench(o: &BenchOptions) -> Result<()> {
    check_threads(o.threads)?;
    let data = load_scene(&o.scene)?;
    check_samples("--spp", o.spp, &data)?;
    let pool = thread_pool(o.threads)?;
    check_render_memory(
        o.integrator,
        &RenderSettings::default(),
        &data,
        pool.current_num_threads(),
    )?;
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
    print_out(&bench_table(
        &o.scene,
        o.integrator,
        o.spp,
        pool.current_num_threads(),
        runs,
    ));
    Ok(())
}
