//! Integrators: one file each, with its graph of systems and its parameters.

pub mod bdpt;
pub mod pm;
pub mod pt;
pub mod sppm;

pub mod camera_walk;

pub use crate::scene::SceneData;

use crate::film::Film;
use crate::pipeline::Stats;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The integrators built into this binary. Adding one takes a variant, its name in `as_str`
/// and `description`, its entry in `BUILT`, and a match arm in `run`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum IntegratorKind {
    /// Path tracing with next-event estimation and MIS.
    Pt,
    /// Bidirectional path tracing: every strategy (s, t), MIS-weighted.
    Bdpt,
    /// Photon mapping: photon maps traced once, final gathering.
    Pm,
    /// Progressive photon mapping: visible points found once, passes of photons.
    Ppm,
    /// Stochastic progressive photon mapping: new visible points every pass.
    Sppm,
}

/// Every integrator name the project knows, built or planned, in the order reports list them.
pub const KNOWN_INTEGRATORS: [&str; 6] = ["pt", "bdpt", "pm", "ppm", "sppm", "mlt"];

/// A name that is not an integrator of this binary.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum IntegratorNameError {
    #[error("integrator \"{0}\" is not built yet (built: {built})", built = built_names())]
    NotBuilt(String),
    #[error(
        "unknown integrator \"{0}\" (known: {known}; built: {built})",
        known = KNOWN_INTEGRATORS.join(", "),
        built = built_names()
    )]
    Unknown(String),
}

fn built_names() -> String {
    IntegratorKind::BUILT
        .iter()
        .map(|k| k.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

impl IntegratorKind {
    /// The integrators this binary can run, in the order of `KNOWN_INTEGRATORS`.
    pub const BUILT: &'static [IntegratorKind] = &[
        IntegratorKind::Pt,
        IntegratorKind::Bdpt,
        IntegratorKind::Pm,
        IntegratorKind::Ppm,
        IntegratorKind::Sppm,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            IntegratorKind::Pt => "pt",
            IntegratorKind::Bdpt => "bdpt",
            IntegratorKind::Pm => "pm",
            IntegratorKind::Ppm => "ppm",
            IntegratorKind::Sppm => "sppm",
        }
    }

    pub fn description(self) -> &'static str {
        match self {
            IntegratorKind::Pt => "path tracing with next-event estimation and MIS",
            IntegratorKind::Bdpt => "bidirectional path tracing, every strategy MIS-weighted",
            IntegratorKind::Pm => "photon mapping: global and caustic maps, final gathering",
            IntegratorKind::Ppm => "progressive photon mapping (visible points found once)",
            IntegratorKind::Sppm => "stochastic progressive photon mapping",
        }
    }

    /// Whether the integrator is unbiased (its renders can serve as references and resume
    /// from a checkpoint); the photon mappers are consistent but biased.
    pub fn is_unbiased(self) -> bool {
        matches!(self, IntegratorKind::Pt | IntegratorKind::Bdpt)
    }

    /// Parses an integrator name (case-insensitive). A planned but unbuilt name is
    /// `NotBuilt`, anything else unknown is `Unknown`.
    pub fn from_name(name: &str) -> Result<IntegratorKind, IntegratorNameError> {
        let lower = name.trim().to_ascii_lowercase();
        if let Some(&kind) = Self::BUILT.iter().find(|k| k.as_str() == lower) {
            Ok(kind)
        } else if KNOWN_INTEGRATORS.contains(&lower.as_str()) {
            Err(IntegratorNameError::NotBuilt(lower))
        } else {
            Err(IntegratorNameError::Unknown(name.to_string()))
        }
    }
}

impl std::str::FromStr for IntegratorKind {
    type Err = IntegratorNameError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        IntegratorKind::from_name(s)
    }
}

impl std::fmt::Display for IntegratorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Settings of the photon mappers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotonSettings {
    /// Photons traced per pass (ppm, sppm).
    pub photons_per_pass: u64,
    /// Fraction of a pass's photons each pixel keeps (ppm, sppm).
    pub alpha: f32,
    /// Initial gather radius in scene units (default: a fraction of the scene diagonal).
    pub radius: Option<f32>,
    /// Photons traced for the photon maps (pm).
    pub photons: u64,
    /// Photons per density estimate (pm).
    pub k: usize,
    /// Largest density-estimate radius in scene units (pm; default: a fraction of the scene
    /// diagonal).
    pub max_radius: Option<f32>,
    /// Indirect light by final gathering (pm); else straight from the global map.
    pub final_gather: bool,
}

impl Default for PhotonSettings {
    fn default() -> Self {
        PhotonSettings {
            photons_per_pass: sppm::DEFAULT_PHOTONS_PER_PASS,
            alpha: sppm::DEFAULT_ALPHA,
            radius: None,
            photons: pm::DEFAULT_PHOTONS,
            k: pm::DEFAULT_K,
            max_radius: None,
            final_gather: true,
        }
    }
}

/// Settings of a render; each integrator reads those that concern it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    pub seed: u64,
    /// Maximum number of scattering events; `u32::MAX` for unlimited.
    pub max_depth: u32,
    /// How bidirectional strategies are weighted (bdpt).
    pub mis: crate::path::MisHeuristic,
    /// Keep each strategy's weighted contribution as its own image (bdpt).
    pub strategy_images: bool,
    pub photons: PhotonSettings,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            seed: 0,
            max_depth: u32::MAX,
            mis: crate::path::MisHeuristic::Power,
            strategy_images: false,
            photons: PhotonSettings::default(),
        }
    }
}

/// A render to continue: the film of the passes already done (0..passes). Samples are a
/// pure function of (seed, pixel, sample index, dimension) and the film adds them in global
/// sample order, so continuing gives, bit for bit, the film of one uninterrupted render.
pub struct Resume {
    pub film: Film,
    pub passes: u64,
}

/// Renders a scene with an integrator from nothing.
pub fn render(
    kind: IntegratorKind,
    data: Arc<SceneData>,
    settings: &RenderSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    run(kind, data, settings, budget, control, None)
}

/// Continues a render from its finished passes: a sample budget counts the passes already
/// done (`SamplesPerPixel(n)` ends at pass n), a time budget counts from now. The outcome's
/// film, passes and samples are totals, resumed passes included.
pub fn resume(
    kind: IntegratorKind,
    data: Arc<SceneData>,
    settings: &RenderSettings,
    budget: Budget,
    control: &Control,
    from: Resume,
) -> RenderOutcome {
    run(kind, data, settings, budget, control, Some(from))
}

/// The one dispatch: each integrator's arm renders from `from` when given (the passes it
/// holds, then on), as `reference` needs to resume; see `pt::render_from`.
fn run(
    kind: IntegratorKind,
    data: Arc<SceneData>,
    settings: &RenderSettings,
    budget: Budget,
    control: &Control,
    from: Option<Resume>,
) -> RenderOutcome {
    match kind {
        IntegratorKind::Pt => {
            let pt_settings = pt::PtSettings {
                seed: settings.seed,
                max_depth: settings.max_depth,
            };
            pt::render_from(data, pt_settings, budget, control, from)
        }
        IntegratorKind::Bdpt => {
            let bdpt_settings = bdpt::BdptSettings {
                mis: settings.mis,
                strategy_images: settings.strategy_images,
                ..bdpt::BdptSettings::new(settings.seed, settings.max_depth)
            };
            bdpt::render_from(data, bdpt_settings, budget, control, from)
        }
        IntegratorKind::Pm => {
            refuse_resume(kind, from);
            let p = settings.photons;
            let pm_settings = pm::PmSettings {
                max_depth: settings.max_depth,
                photons: p.photons,
                k: p.k,
                max_radius: p.max_radius,
                final_gather: p.final_gather,
                ..pm::PmSettings::new(settings.seed)
            };
            pm::render(data, pm_settings, budget, control)
        }
        IntegratorKind::Ppm | IntegratorKind::Sppm => {
            refuse_resume(kind, from);
            let p = settings.photons;
            let progressive = sppm::ProgressiveSettings {
                max_depth: settings.max_depth,
                photons_per_pass: p.photons_per_pass,
                alpha: p.alpha,
                initial_radius: p.radius,
                ..sppm::ProgressiveSettings::new(settings.seed, kind == IntegratorKind::Sppm)
            };
            sppm::render(data, progressive, budget, control)
        }
    }
}

/// Passes of an integrator that renders pass by pass (the photon mappers): calls `pass(i)`
/// for i = 0, 1, ... until the budget is spent (a sample budget counts passes; a time budget
/// ends at the first pass boundary past it, after at least one pass) or a stop is asked for,
/// reporting progress after each. Returns (passes done, whether a stop cut a sample budget
/// short).
pub(crate) fn pass_by_pass(
    budget: Budget,
    control: &Control,
    mut pass: impl FnMut(u64),
) -> (u64, bool) {
    let start = Instant::now();
    let total = match budget {
        Budget::SamplesPerPixel(n) => Some(n),
        Budget::Seconds(_) => None,
    };
    let mut passes = 0;
    loop {
        let over = match budget {
            Budget::SamplesPerPixel(n) => passes >= n,
            Budget::Seconds(s) => passes > 0 && start.elapsed().as_secs_f64() >= s,
        };
        if over || control.stopped() {
            break;
        }
        pass(passes);
        passes += 1;
        (control.progress)(passes, total);
    }
    (
        passes,
        control.stopped() && total.is_some_and(|t| passes < t),
    )
}

/// The biased integrators keep per-pixel statistics a film checkpoint does not hold, so they
/// cannot resume; callers check `is_unbiased` first (`reference` refuses them).
fn refuse_resume(kind: IntegratorKind, from: Option<Resume>) {
    assert!(
        from.is_none(),
        "{kind} is biased and does not resume (callers check is_unbiased)"
    );
}

/// How long a render runs: samples per pixel, or wall seconds (whole passes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    SamplesPerPixel(u64),
    Seconds(f64),
}

/// What a render produced.
pub struct RenderOutcome {
    pub film: Film,
    pub stats: Stats,
    /// Completed passes (one sample in every pixel each).
    pub passes: u64,
    pub samples: u64,
    pub wall: Duration,
    pub interrupted: bool,
    /// Systems of the graph, in order.
    pub systems: Vec<&'static str>,
    pub bytes_per_path: usize,
    pub wavefront: usize,
    /// Further images the integrator made, by name (BDPT's per-strategy images).
    pub layers: Vec<(String, crate::film::Image)>,
}

impl RenderOutcome {
    pub fn closest_rays(&self) -> u64 {
        self.stats.get("trace_closest").map_or(0, |s| s.taken)
    }
    pub fn shadow_rays(&self) -> u64 {
        self.stats.get("trace_shadow").map_or(0, |s| s.taken)
    }
}

/// Progress callbacks and the stop flag of a render.
pub struct Control<'a> {
    /// Set (e.g. by Ctrl-C) to stop after the passes in flight.
    pub stop: &'a AtomicBool,
    /// Called after each wave with (passes done, total passes if known).
    pub progress: &'a (dyn Fn(u64, Option<u64>) + Sync),
}

impl Control<'_> {
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// Paths per wave under a time budget (rounded up to whole passes, at most the wavefront):
/// enough to keep the cores busy, small enough that the time is checked often.
pub const TIMED_WAVE_PATHS: u64 = 1 << 16;

/// Plans waves over the global sample ids: whole passes per wave when a pass fits in the
/// wavefront, else a pass split into wavefront-sized waves. Stops only at pass boundaries.
pub(crate) struct WavePlan {
    pub pixels: u64,
    pub wave_len: u64,
    pub total: Option<u64>,
    pub next: u64,
    /// The first sample id of this render (pass 0, or where a resumed render starts).
    first: u64,
    start: Instant,
    budget: Budget,
}

impl WavePlan {
    /// A plan from pass 0 (every integrator that does not resume).
    #[allow(dead_code)]
    pub fn new(pixels: u64, budget: Budget, wavefront: usize) -> WavePlan {
        WavePlan::starting_at(pixels, budget, wavefront, 0)
    }

    /// A plan whose first wave starts at pass `first_pass` (a resumed render); a sample
    /// budget still counts from pass 0.
    pub fn starting_at(pixels: u64, budget: Budget, wavefront: usize, first_pass: u64) -> WavePlan {
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
    pub fn capacity(&self) -> usize {
        self.wave_len as usize
    }

    /// The next wave (first sample id, length), or None when the budget is spent or a stop
    /// was asked for at a pass boundary.
    pub fn next_wave(&mut self, control: &Control) -> Option<(u64, usize)> {
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
    pub fn budget_spent(&self) -> bool {
        self.total.is_some_and(|t| self.next >= t)
    }

    pub fn passes_done(&self) -> u64 {
        self.next / self.pixels
    }

    pub fn total_passes(&self) -> Option<u64> {
        self.total.map(|t| t / self.pixels)
    }

    pub fn elapsed(&self) -> Duration {
        self.start.elapsed()
    }
}
