//! The two drivers every integrator runs under. An integrator is a state type with a graph;
//! what a step means is the driver's business:
//!
//! - `render_waves` drives sample-based integrators (PT, BDPT): global sample ids in waves of
//!   up to the state's wavefront, whole passes per wave where they fit. Samples are a pure
//!   function of (seed, pixel, sample index, dimension) and the film sums them exactly, so
//!   a render can resume from the film of its finished passes, and shards of disjoint pass
//!   ranges add up to one render's film, bit for bit.
//! - `render_passes` drives pass-based integrators (the photon mappers, MLT): one graph run
//!   per pass, the image made from the state at the end.

use super::{Budget, Control, RenderOutcome, Resume};
use crate::film::{Film, Image};
use crate::pipeline::{Graph, Stats};
use crate::scene::SceneData;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The state of an integrator and the graph that runs over it.
pub trait IntegratorState: Sized + Send + 'static {
    /// The integrator's own settings.
    type Settings: Copy + Send + Sync;
    /// Columns the driver sets before the graph runs (for `Graph::check`).
    const INPUTS: &'static [&'static str];
    /// The graph for a scene: only the systems the scene needs.
    fn graph(data: &SceneData, settings: &Self::Settings) -> Graph<Self>;
}

/// A sample-based integrator: renders the samples of a wave, adding them to its film.
pub trait WaveState: IntegratorState {
    /// Samples in flight at most.
    const WAVEFRONT: usize;
    fn new(data: Arc<SceneData>, settings: Self::Settings, capacity: usize) -> Self;
    /// Sets the wave the next graph run renders.
    fn begin_wave(&mut self, wave: Wave);
    fn film_mut(&mut self) -> &mut Film;
    /// The film and any further images (`new_passes` rendered by this run), and the bytes of
    /// wavefront state per sample.
    fn finish(self, new_passes: u64) -> (Film, Vec<(String, Image)>, usize);
    /// Closest-hit and shadow rays traced, for a state whose graph has no trace systems to
    /// count them (the megakernel); None: the trace systems' stats count them.
    fn counted_rays(&self) -> Option<(u64, u64)> {
        None
    }
    /// Lines the integrator adds to the render report (label, value).
    fn notes(&self) -> Vec<(&'static str, String)> {
        Vec::new()
    }
    /// Whether a state per thread may render waves of `wavefront` over the thread count side
    /// by side, folded together at the end (`absorb`), with the image of one state rendering
    /// waves of `wavefront`: true where the image does not depend on the waves' size and all
    /// a state sums is exact (the film) or counted.
    fn waves_side_by_side(_settings: &Self::Settings) -> bool {
        true
    }
    /// Adds what `other` rendered (other waves of the same render) to this state: its film,
    /// and whatever else a state counts or sums that the report or the image reads.
    fn absorb(&mut self, mut other: Self) -> Result<(), String> {
        self.film_mut().add_film(other.film_mut())
    }
}

/// A pass-based integrator: the graph runs once per pass.
pub trait PassState: IntegratorState {
    fn new(data: Arc<SceneData>, settings: Self::Settings) -> Self;
    /// Prepares pass `pass` (0, 1, ...).
    fn begin_pass(&mut self, pass: u64);
    /// Lines the integrator adds to the render report (label, value).
    fn report(&self) -> Vec<(&'static str, String)> {
        Vec::new()
    }
    /// The image of `passes` finished passes, the bytes of state per pixel and the slots in
    /// flight.
    fn finish(self, passes: u64) -> (Film, usize, usize);
    /// Further images of the render (named), taken before `finish`: mmlt's strategy images.
    fn layers(&self) -> Vec<(String, Image)> {
        Vec::new()
    }
    /// What a later run needs to continue after the passes done (`restore`), as bytes; None
    /// for an integrator that does not resume.
    fn save(&self) -> Option<Vec<u8>> {
        None
    }
    /// Continues from `save`'s bytes, taken after `passes` passes with the same scene, seed
    /// and settings (the checkpoint's header vouches for them), so that the next passes give
    /// what an uninterrupted run's would, bit for bit.
    fn restore(&mut self, _bytes: &[u8], _passes: u64) {
        unreachable!("only integrators that save their state are resumed")
    }
}

pub use crate::components::Wave;

/// A default wave: `per_thread` samples for each thread of the current pool (each renders
/// whole waves on a state of its own, `render_waves_of`), at most `most` in all.
pub fn waves_for_threads(per_thread: usize, most: usize) -> usize {
    per_thread
        .saturating_mul(rayon::current_num_threads())
        .min(most)
}

/// Renders with a sample-based integrator until the budget is spent or a stop is asked for,
/// continuing from `from` when given: a sample budget counts the passes already done
/// (`SamplesPerPixel(n)` ends at pass n), a time budget counts from now. The outcome's film,
/// passes and samples are totals, resumed passes included. Waves of up to the state's
/// `WAVEFRONT` samples.
pub fn render_waves<S: WaveState>(
    data: Arc<SceneData>,
    settings: S::Settings,
    budget: Budget,
    control: &Control,
    from: Option<Resume>,
) -> RenderOutcome {
    render_waves_of::<S>(data, settings, budget, control, from, S::WAVEFRONT)
}

/// `render_waves` in waves of up to `wavefront` samples (at least 1; `--wavefront N`): the
/// paths in flight. Samples are pure functions of their ids and the film's sums exact, so the
/// image is the same for every `wavefront`.
///
/// Each thread of the pool renders whole waves on a state of its own (waves of `wavefront`
/// over the thread count), taking the next wave of the plan when its last is done, and the
/// states are folded together at the end. A wave's systems still split their queues over the
/// pool, so a thread that reaches the barrier at the end of a system takes work of the other
/// waves in flight instead of waiting: one wave's barriers no longer idle the machine.
pub fn render_waves_of<S: WaveState>(
    data: Arc<SceneData>,
    settings: S::Settings,
    budget: Budget,
    control: &Control,
    from: Option<Resume>,
    wavefront: usize,
) -> RenderOutcome {
    assert!(wavefront > 0, "a wave holds at least one sample");
    let cam = data.scene.camera;
    let pixels = cam.width as u64 * cam.height as u64;
    let graph = S::graph(&data, &settings);
    let first_pass = from.as_ref().map_or(0, |r| r.passes);
    // Never more paths in flight than `wavefront`, however many threads.
    let workers = if S::waves_side_by_side(&settings) {
        rayon::current_num_threads().clamp(1, wavefront)
    } else {
        1
    };
    let plan = WavePlan::starting_at(pixels, budget, wavefront / workers, first_pass);
    let capacity = plan.capacity();
    let mut first_state = S::new(data.clone(), settings, capacity);
    if let Some(from) = from {
        assert!(
            from.film.width == cam.width as usize
                && from.film.height == cam.height as usize
                && from.first_pass <= from.passes
                && from.film.total_samples() == (from.passes - from.first_pass) * pixels,
            "a resumed film must hold whole passes of this camera's image"
        );
        *first_state.film_mut() = from.film;
    }
    // Paths in flight at most: a state per thread, or per wave where there are fewer waves.
    let waves = plan.total.map_or(workers as u64, |t| {
        t.saturating_sub(plan.next).div_ceil(capacity.max(1) as u64)
    });
    let in_flight = capacity * workers.min(waves.max(1) as usize);
    let mut workers: Vec<Option<(S, Stats)>> = (0..workers).map(|_| None).collect();
    workers[0] = Some((first_state, Stats::default()));
    let plan = Mutex::new(plan);
    let rendered = AtomicU64::new(first_pass * pixels);
    workers.par_iter_mut().for_each(|worker| {
        loop {
            let Some((first, len)) = plan.lock().unwrap().next_wave(control) else {
                break;
            };
            let (state, stats) = worker.get_or_insert_with(|| {
                (S::new(data.clone(), settings, capacity), Stats::default())
            });
            state.begin_wave(Wave { first, len });
            graph.run(state, stats);
            let done = rendered.fetch_add(len as u64, Ordering::Relaxed) + len as u64;
            let total_passes = plan.lock().unwrap().total_passes();
            (control.progress)(done / pixels, total_passes);
        }
    });
    let plan = plan.into_inner().unwrap();
    let mut worked = workers.into_iter().flatten();
    let (mut state, mut stats) = worked
        .next()
        .expect("the first worker's state is made first");
    let mut notes = Vec::new();
    for (other, other_stats) in worked {
        stats.absorb(&other_stats);
        if let Err(e) = state.absorb(other) {
            // Sums within 2^63 film units of the brightest light each: not seen in practice.
            notes.push(("lost waves", format!("a thread's waves were dropped: {e}")));
        }
    }
    // A stop that arrives after the last wave interrupts nothing.
    let interrupted = control.stopped() && !plan.budget_spent();
    let new_passes = plan.passes_done() - first_pass;
    let counted_rays = state.counted_rays();
    notes.extend(state.notes());
    let (film, layers, bytes_per_path) = state.finish(new_passes);
    RenderOutcome {
        samples: plan.next,
        passes: plan.passes_done(),
        wall: plan.elapsed(),
        film,
        stats,
        interrupted,
        systems: graph.system_names(),
        bytes_per_path,
        wavefront: in_flight,
        layers,
        notes,
        counted_rays,
        state: None,
    }
}

/// Runs `graph` over the waves of `spp` passes of a fresh state (waves of up to `wavefront`
/// samples, as `render_waves_of` plans them) and returns the state, for callers that read
/// what the graph left in it (`stagelight rays`: the rays it recorded).
pub fn run_waves_of<S: WaveState>(
    data: Arc<SceneData>,
    settings: S::Settings,
    graph: &Graph<S>,
    spp: u64,
    wavefront: usize,
) -> S {
    assert!(wavefront > 0, "a wave holds at least one sample");
    let cam = data.scene.camera;
    let pixels = cam.width as u64 * cam.height as u64;
    let mut plan = WavePlan::starting_at(pixels, Budget::SamplesPerPixel(spp), wavefront, 0);
    let mut state = S::new(data, settings, plan.capacity());
    let mut stats = Stats::default();
    let never = std::sync::atomic::AtomicBool::new(false);
    let control = Control {
        stop: &never,
        progress: &|_, _| {},
    };
    while let Some((first, len)) = plan.next_wave(&control) {
        state.begin_wave(Wave { first, len });
        graph.run(&mut state, &mut stats);
    }
    state
}

/// Renders with a pass-based integrator: a sample budget is a number of passes, a time budget
/// ends at the first pass boundary past it (at least one pass). A stop request ends the render
/// at a pass boundary, or inside a pass at a stop point of its graph (the photon mappers:
/// between chunks of photons), keeping every finished pass and dropping the unfinished one.
pub fn render_passes<S: PassState>(
    data: Arc<SceneData>,
    settings: S::Settings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    resume_passes::<S>(data, settings, budget, control, None)
}

/// `render_passes`, continuing from `from` when given (its `state`, saved after `from.passes`
/// passes): a sample budget counts the passes already done, a time budget counts from now.
/// The outcome's passes are totals, and its `state` what a later run continues from.
pub fn resume_passes<S: PassState>(
    data: Arc<SceneData>,
    settings: S::Settings,
    budget: Budget,
    control: &Control,
    from: Option<Resume>,
) -> RenderOutcome {
    let start = Instant::now();
    let graph = S::graph(&data, &settings);
    let mut state = S::new(data, settings);
    let mut stats = Stats::default();
    let total = match budget {
        Budget::SamplesPerPixel(n) => Some(n),
        Budget::Seconds(_) => None,
    };
    let mut passes = 0;
    if let Some(from) = from {
        let bytes = from
            .state
            .expect("a pass-based integrator resumes from its saved state");
        state.restore(&bytes, from.passes);
        passes = from.passes;
    }
    let first_pass = passes;
    loop {
        let over = match budget {
            Budget::SamplesPerPixel(n) => passes >= n,
            Budget::Seconds(s) => passes > first_pass && start.elapsed().as_secs_f64() >= s,
        };
        if over || control.stopped() {
            break;
        }
        state.begin_pass(passes);
        // A stop inside the pass (at a stop point of its graph) drops it: the state holds
        // the finished passes alone.
        if !graph.run_until(&mut state, &mut stats, control.stop) {
            break;
        }
        passes += 1;
        (control.progress)(passes, total);
    }
    let interrupted = control.stopped() && total.is_some_and(|t| passes < t);
    let notes = state.report();
    let saved = state.save();
    let layers = state.layers();
    let (film, bytes_per_path, wavefront) = state.finish(passes);
    let pixels = film.width as u64 * film.height as u64;
    RenderOutcome {
        film,
        stats,
        passes,
        samples: passes * pixels,
        wall: start.elapsed(),
        interrupted,
        systems: graph.system_names(),
        bytes_per_path,
        wavefront,
        layers,
        notes,
        counted_rays: None,
        state: saved,
    }
}

/// Runs `passes` passes of a pass-based integrator and returns its state (for tests of the
/// statistics).
pub fn run_passes<S: PassState>(data: Arc<SceneData>, settings: S::Settings, passes: u64) -> S {
    let graph = S::graph(&data, &settings);
    let mut state = S::new(data, settings);
    let mut stats = Stats::default();
    for pass in 0..passes {
        state.begin_pass(pass);
        graph.run(&mut state, &mut stats);
    }
    state
}

/// Paths per wave under a time budget (rounded up to whole passes, at most the wavefront):
/// enough to keep the cores busy, small enough that the time is checked often.
pub const TIMED_WAVE_PATHS: u64 = 1 << 16;

/// Plans waves over the global sample ids: whole passes per wave when a pass fits in the
/// wavefront, else a pass split into wavefront-sized waves. Stops only at pass boundaries.
struct WavePlan {
    pixels: u64,
    wave_len: u64,
    total: Option<u64>,
    next: u64,
    /// The first sample id of this render (pass 0, or where a resumed render starts).
    first: u64,
    start: Instant,
    budget: Budget,
}

impl WavePlan {
    /// A plan whose first wave starts at pass `first_pass` (a resumed render); a sample
    /// budget still counts from pass 0.
    fn starting_at(pixels: u64, budget: Budget, wavefront: usize, first_pass: u64) -> WavePlan {
        let next = first_pass * pixels;
        let wave_len = if pixels <= wavefront as u64 {
            (wavefront as u64 / pixels) * pixels
        } else {
            wavefront as u64
        };
        let total = match budget {
            Budget::SamplesPerPixel(spp) => Some(spp * pixels),
            Budget::Seconds(_) => None,
        };
        let wave_len = match total {
            Some(t) => wave_len.min(t.saturating_sub(next)),
            // The clock is read between waves: a time budget takes waves of about
            // TIMED_WAVE_PATHS paths (whole passes), so it overshoots by a fraction of the
            // full wavefront's time at most.
            None => wave_len.min(TIMED_WAVE_PATHS.div_ceil(pixels) * pixels),
        };
        WavePlan {
            pixels,
            wave_len,
            total,
            next,
            first: next,
            start: Instant::now(),
            budget,
        }
    }

    /// Slots the state needs.
    fn capacity(&self) -> usize {
        self.wave_len as usize
    }

    /// The next wave (first sample id, length), or None when the budget is spent or a stop
    /// was asked for at a pass boundary.
    fn next_wave(&mut self, control: &Control) -> Option<(u64, usize)> {
        let at_pass_boundary = self.next.is_multiple_of(self.pixels);
        if at_pass_boundary {
            if control.stopped() {
                return None;
            }
            // A time budget renders at least one wave, however long the setup took.
            if let Budget::Seconds(s) = self.budget
                && self.next > self.first
                && self.start.elapsed().as_secs_f64() >= s
            {
                return None;
            }
        }
        let mut len = self.wave_len;
        if let Some(total) = self.total {
            if self.next >= total {
                return None;
            }
            len = len.min(total - self.next);
        }
        // A wave never crosses a pass boundary in the middle of a split pass.
        if self.wave_len < self.pixels {
            len = len.min(self.pixels - self.next % self.pixels);
        }
        let first = self.next;
        self.next += len;
        Some((first, len as usize))
    }

    /// True when a sample budget has been rendered in full (a time budget never is: it ends
    /// when the time is up).
    fn budget_spent(&self) -> bool {
        self.total.is_some_and(|t| self.next >= t)
    }

    fn passes_done(&self) -> u64 {
        self.next / self.pixels
    }

    fn total_passes(&self) -> Option<u64> {
        self.total.map(|t| t / self.pixels)
    }

    fn elapsed(&self) -> Duration {
        self.start.elapsed()
    }
}
