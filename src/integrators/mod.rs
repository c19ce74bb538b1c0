//! Integrators: one file each, with its graph of systems and its parameters.

pub mod bdpt;
pub mod mlt;
pub mod path_mlt;
pub mod pm;
pub mod pt;
pub mod pt_megakernel;
pub mod sppm;

pub mod camera_walk;
pub mod direct_illumination;
pub mod driver;

pub use crate::scene::SceneData;
pub use driver::{IntegratorState, PassState, Wave, WaveState};

use crate::film::Film;
use crate::pipeline::Stats;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// One integrator as the CLI, `compare`, `reference` and the thesis preset see it. Adding an
/// integrator takes its file (state, settings and graph), its systems, and one entry in
/// `REGISTRY`.
pub struct IntegratorInfo {
    pub name: &'static str,
    pub description: &'static str,
    /// Unbiased integrators' films add up over shards and runs; the photon mappers and MLT
    /// are consistent but biased.
    pub unbiased: bool,
    /// Whether a render continues from a checkpoint (`reference`): the unbiased ones from
    /// their film, the photon mappers from their saved state (`PassState::save`).
    pub resumes: bool,
    /// The `render` options that concern it, besides the common ones.
    pub options: &'static [&'static str],
    /// Renders (from `Resume` when given: only integrators that `resumes` are asked to).
    pub render:
        fn(Arc<SceneData>, &RenderSettings, Budget, &Control, Option<Resume>) -> RenderOutcome,
    /// Its graph for a scene, described (`stagelight graph`), and the graph's data-flow check.
    pub graph: fn(&SceneData, &RenderSettings) -> GraphReport,
}

/// An integrator's graph for a scene: its description and its check's problems.
pub struct GraphReport {
    pub description: String,
    pub problems: Vec<String>,
}

fn graph_report<S: IntegratorState>(data: &SceneData, settings: &S::Settings) -> GraphReport {
    let graph = S::graph(data, settings);
    GraphReport {
        description: graph.describe(),
        problems: graph.check(S::INPUTS),
    }
}

/// The `render` options of PPM and SPPM.
const PROGRESSIVE_OPTIONS: &[&str] = &["--photons-per-pass", "--alpha", "--radius"];
/// The `render` options of PPM.
const PPM_OPTIONS: &[&str] = &["--photons-per-pass", "--alpha", "--radius", "--eye-rays"];
/// The `render` options of the Metropolis integrators.
const MLT_OPTIONS: &[&str] = &[
    "--large-step",
    "--sigma",
    "--bootstrap",
    "--chains",
    "--mis",
    "--direct-spp",
];

/// The `render` options of mmlt: the Metropolis ones and the strategy images (each chain
/// state is one strategy (s, t), so its splats split by strategy as BDPT's connections do).
const MMLT_OPTIONS: &[&str] = &[
    "--large-step",
    "--sigma",
    "--bootstrap",
    "--chains",
    "--mis",
    "--direct-spp",
    "--strategy-images",
];

/// Every integrator built into this binary, in the order reports list them.
pub static REGISTRY: [IntegratorInfo; 10] = [
    IntegratorInfo {
        name: "pt",
        description: "path tracing with next-event estimation and MIS",
        unbiased: true,
        resumes: true,
        options: &[],
        render: |data, s, budget, control, from| pt::render_with(data, s, budget, control, from),
        graph: |data, s| match s.kernel {
            pt::Kernel::Wavefront => graph_report::<pt::PtState>(data, &pt::PtSettings::from(s)),
            pt::Kernel::Megakernel => {
                graph_report::<pt_megakernel::MegakernelState>(data, &pt::PtSettings::from(s))
            }
        },
    },
    IntegratorInfo {
        name: "bdpt",
        description: "bidirectional path tracing, every strategy MIS-weighted",
        unbiased: true,
        resumes: true,
        options: &["--mis", "--strategy-images", "--light-vertex-cache"],
        render: |data, s, budget, control, from| {
            let settings = bdpt::BdptSettings::from(s);
            let wavefront = s
                .wavefront
                .unwrap_or_else(|| bdpt::default_wavefront(&settings));
            driver::render_waves_of::<bdpt::BdptState>(
                data, settings, budget, control, from, wavefront,
            )
        },
        graph: |data, s| graph_report::<bdpt::BdptState>(data, &bdpt::BdptSettings::from(s)),
    },
    IntegratorInfo {
        name: "vcm",
        description: "vertex connection and merging: BDPT's connections and photon merges, MIS-weighted",
        unbiased: false,
        resumes: false,
        options: &["--mis", "--radius", "--alpha"],
        render: |data, s, budget, control, _| {
            let settings = bdpt::vcm_settings(&data, s, true, true);
            let wavefront = s.wavefront.unwrap_or(bdpt::WAVEFRONT);
            driver::render_waves_of::<bdpt::BdptState>(
                data, settings, budget, control, None, wavefront,
            )
        },
        graph: |data, s| {
            graph_report::<bdpt::BdptState>(data, &bdpt::vcm_settings(data, s, true, true))
        },
    },
    IntegratorInfo {
        name: "bpm",
        description: "bidirectional photon mapping: VCM's merges alone (and emitters hit)",
        unbiased: false,
        resumes: false,
        options: &["--mis", "--radius", "--alpha"],
        render: |data, s, budget, control, _| {
            let settings = bdpt::vcm_settings(&data, s, false, true);
            let wavefront = s.wavefront.unwrap_or(bdpt::WAVEFRONT);
            driver::render_waves_of::<bdpt::BdptState>(
                data, settings, budget, control, None, wavefront,
            )
        },
        graph: |data, s| {
            graph_report::<bdpt::BdptState>(data, &bdpt::vcm_settings(data, s, false, true))
        },
    },
    IntegratorInfo {
        name: "pm",
        description: "photon mapping: global and caustic maps, final gathering",
        unbiased: false,
        resumes: true,
        options: &["--photons", "--k", "--max-radius", "--no-final-gather"],
        render: |data, s, budget, control, from| {
            let settings = pm::PmSettings::from(s);
            driver::resume_passes::<pm::PmState>(data, settings, budget, control, from)
        },
        graph: |data, s| graph_report::<pm::PmState>(data, &pm::PmSettings::from(s)),
    },
    IntegratorInfo {
        name: "ppm",
        description: "progressive photon mapping (visible points found once)",
        unbiased: false,
        resumes: true,
        options: PPM_OPTIONS,
        render: |data, s, budget, control, from| {
            let settings = sppm::ProgressiveSettings::from_render(s, false);
            driver::resume_passes::<sppm::ProgressiveState>(data, settings, budget, control, from)
        },
        graph: |data, s| {
            let settings = sppm::ProgressiveSettings::from_render(s, false);
            graph_report::<sppm::ProgressiveState>(data, &settings)
        },
    },
    IntegratorInfo {
        name: "sppm",
        description: "stochastic progressive photon mapping",
        unbiased: false,
        resumes: true,
        options: PROGRESSIVE_OPTIONS,
        render: |data, s, budget, control, from| {
            let settings = sppm::ProgressiveSettings::from_render(s, true);
            driver::resume_passes::<sppm::ProgressiveState>(data, settings, budget, control, from)
        },
        graph: |data, s| {
            let settings = sppm::ProgressiveSettings::from_render(s, true);
            graph_report::<sppm::ProgressiveState>(data, &settings)
        },
    },
    IntegratorInfo {
        name: "pssmlt",
        description: "Kelemen primary-sample-space MLT over full BDPT",
        // Consistent: b is estimated by the bootstrap, and a render does not resume.
        unbiased: false,
        resumes: false,
        options: MLT_OPTIONS,
        render: |data, s, budget, control, _| {
            mlt::render(
                data,
                mlt::MltSettings::from_render(s, false),
                budget,
                control,
            )
        },
        graph: |data, s| {
            graph_report::<mlt::MltState>(data, &mlt::MltSettings::from_render(s, false))
        },
    },
    IntegratorInfo {
        name: "mmlt",
        description: "multiplexed MLT: one BDPT strategy per evaluation (pbrt-v4's mlt)",
        unbiased: false,
        resumes: false,
        options: MMLT_OPTIONS,
        render: |data, s, budget, control, _| {
            mlt::render(
                data,
                mlt::MltSettings::from_render(s, true),
                budget,
                control,
            )
        },
        graph: |data, s| {
            graph_report::<mlt::MltState>(data, &mlt::MltSettings::from_render(s, true))
        },
    },
    IntegratorInfo {
        name: "mlt",
        description: "Veach's path-space MLT: bidirectional mutation, lens, caustic and multi-chain perturbations",
        unbiased: false,
        resumes: false,
        options: &[
            "--bootstrap",
            "--chains",
            "--direct-spp",
            "--mutations",
            "--lens-min",
        ],
        render: |data, s, budget, control, _| {
            let settings = path_mlt::PathMltSettings::from_render(&data, s);
            path_mlt::render(data, settings, budget, control)
        },
        graph: |data, s| {
            let settings = path_mlt::PathMltSettings::from_render(data, s);
            graph_report::<path_mlt::PathMltState>(data, &settings)
        },
    },
];

/// Every integrator name, in the order reports list them.
pub fn known_integrators() -> Vec<&'static str> {
    REGISTRY.iter().map(|i| i.name).collect()
}

/// An integrator of `REGISTRY`: a copyable handle that compares by registry position.
#[derive(Clone, Copy)]
pub struct IntegratorKind(&'static IntegratorInfo);

impl PartialEq for IntegratorKind {
    fn eq(&self, other: &Self) -> bool {
        std::ptr::eq(self.0, other.0)
    }
}
impl Eq for IntegratorKind {}
impl std::hash::Hash for IntegratorKind {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.index().hash(state)
    }
}
impl PartialOrd for IntegratorKind {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for IntegratorKind {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.index().cmp(&other.index())
    }
}
impl std::fmt::Debug for IntegratorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.0.name)
    }
}

/// A name that is not an integrator of this binary.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum IntegratorNameError {
    #[error(
        "unknown integrator \"{0}\" (known: {known})",
        known = known_integrators().join(", ")
    )]
    Unknown(String),
}

impl IntegratorKind {
    /// Every integrator this binary can run, in registry order.
    pub fn all() -> Vec<IntegratorKind> {
        REGISTRY.iter().map(IntegratorKind).collect()
    }

    /// The integrator of a name the code itself uses (panics on a name not in the registry).
    pub fn named(name: &str) -> IntegratorKind {
        Self::from_name(name).unwrap_or_else(|e| panic!("{e}"))
    }

    pub fn info(self) -> &'static IntegratorInfo {
        self.0
    }

    fn index(self) -> usize {
        REGISTRY
            .iter()
            .position(|i| std::ptr::eq(i, self.0))
            .expect("a kind points into the registry")
    }

    pub fn as_str(self) -> &'static str {
        self.0.name
    }

    pub fn description(self) -> &'static str {
        self.0.description
    }

    /// Whether the integrator is unbiased (its films add up over shards and runs); the
    /// photon mappers and MLT are consistent but biased.
    pub fn is_unbiased(self) -> bool {
        self.0.unbiased
    }

    /// Whether its renders continue from a checkpoint (`reference`): all but MLT's.
    pub fn resumes(self) -> bool {
        self.0.resumes
    }

    /// Parses an integrator name (case-insensitive).
    pub fn from_name(name: &str) -> Result<IntegratorKind, IntegratorNameError> {
        let lower = name.trim().to_ascii_lowercase();
        if let Some(info) = REGISTRY.iter().find(|i| i.name == lower) {
            Ok(IntegratorKind(info))
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
    /// Fraction of a pass's photons each pixel keeps (ppm, sppm), or the radius reduction of
    /// vcm and bpm (None: each one's default).
    pub alpha: Option<f32>,
    /// Initial gather radius in scene units (default: a fraction of the scene diagonal).
    pub radius: Option<f32>,
    /// Eye-ray trees per pixel (ppm).
    pub eye_rays: u32,
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
            alpha: None,
            radius: None,
            eye_rays: sppm::DEFAULT_EYE_RAYS,
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
    /// Where the random numbers come from (`--sampler`).
    pub sampler: crate::sampling::SamplerKind,
    /// Maximum number of scattering events; `u32::MAX` for unlimited.
    pub max_depth: u32,
    /// How bidirectional strategies are weighted (bdpt).
    pub mis: crate::path::MisHeuristic,
    /// Keep each strategy's weighted contribution as its own image (bdpt).
    pub strategy_images: bool,
    /// Light-vertex cache: light vertices each camera vertex joins (bdpt; 0: plain BDPT).
    pub light_vertex_cache: u32,
    pub photons: PhotonSettings,
    pub mlt: MltOptions,
    /// How PT's work is laid out: wavefront systems or one path per thread (`--kernel`).
    /// The image is the same.
    pub kernel: pt::Kernel,
    /// Samples in flight of the sample-based integrators (pt, bdpt; `--wavefront N`); None:
    /// the integrator's default. The image is the same.
    pub wavefront: Option<usize>,
    /// Paths PT's wavefront shades at a time in vector lanes (`--lanes`); None: as many as the
    /// CPU's vector registers hold. The image is the same.
    pub lanes: Option<crate::lanes::LaneWidth>,
    /// Also sum each pixel's sample squares, for the variance image (`--variance`; pt).
    pub moments: bool,
}

/// Options of the Metropolis integrators (pssmlt, mmlt); None: the integrator's default.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MltOptions {
    /// Probability of a large step (0.3).
    pub large_step: Option<f32>,
    /// Small steps as a wrapped normal of this sigma (default: Kelemen's for pssmlt,
    /// sigma 0.01 for mmlt).
    pub sigma: Option<f32>,
    /// Bootstrap evaluations per group (per depth in mmlt).
    pub bootstrap: Option<u64>,
    /// Chains (default: from the budget).
    pub chains: Option<u64>,
    /// Samples per pixel of the direct illumination rendered apart (0: in the chains; None:
    /// one per `DIRECT_MUTATIONS_PER_SAMPLE` mutations per pixel).
    pub direct_spp: Option<u32>,
    /// Path-space MLT: the mutations enabled, bit k = `MutationKind` k (all).
    pub mutations: Option<u8>,
    /// Path-space MLT: the lens perturbation's smallest offset in pixels (0.1).
    pub lens_min: Option<f32>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            seed: 0,
            sampler: crate::sampling::SamplerKind::Independent,
            max_depth: u32::MAX,
            mis: crate::path::MisHeuristic::Power,
            strategy_images: false,
            light_vertex_cache: 0,
            photons: PhotonSettings::default(),
            mlt: MltOptions::default(),
            kernel: pt::Kernel::Wavefront,
            wavefront: None,
            lanes: None,
            moments: false,
        }
    }
}

/// A render to continue: the film of the passes already done (`first_pass..passes`; a shard
/// starts at its first pass with an empty film). Samples are a pure function of (seed, pixel,
/// sample index, dimension) and the film sums them exactly, so continuing gives, bit for bit,
/// the film of one uninterrupted render of those passes.
pub struct Resume {
    pub film: Film,
    /// The first pass in `film` (0 unless the render is a shard).
    pub first_pass: u64,
    pub passes: u64,
    /// A pass-based integrator's saved state (`RenderOutcome::state`); the film is then
    /// only its image and not read.
    pub state: Option<Vec<u8>>,
}

impl Resume {
    /// A shard's start: an empty film of the scene, the render beginning at pass
    /// `first_pass`.
    pub fn shard_start(data: &SceneData, first_pass: u64) -> Resume {
        Resume {
            film: Film::for_scene(data),
            first_pass,
            passes: first_pass,
            state: None,
        }
    }
}

/// The settings of an integrator that change its image besides the seed, sampler and depth
/// cap, as text; shards must agree on it to be merged. For the unbiased ones: empty when they
/// are the defaults (so checkpoints made before this was recorded still match), else e.g.
/// `mis=balance`; for the others, all their options (`--photons`, `--alpha`, `--sigma`, ...).
pub fn film_settings(kind: IntegratorKind, settings: &RenderSettings) -> String {
    let options = kind.info().options;
    if options.contains(&"--large-step") {
        format!("{:?}", settings.mlt)
    } else if options.contains(&"--photons") || options.contains(&"--photons-per-pass") {
        format!("{:?}", settings.photons)
    } else if options.contains(&"--mis") {
        let mut parts = Vec::new();
        if settings.mis != crate::path::MisHeuristic::Power {
            parts.push(format!("mis={:?}", settings.mis).to_ascii_lowercase());
        }
        if settings.light_vertex_cache > 0 {
            parts.push(format!(
                "light_vertex_cache={}",
                settings.light_vertex_cache
            ));
        }
        parts.join(",")
    } else {
        String::new()
    }
}

/// The integrators that render an orthographic camera: its rays leave points of a plane in
/// one direction, a delta that no light vertex can be joined to, so the bidirectional ones
/// give their light-tracing strategies (t = 1) no weight, as for any delta vertex, and the
/// photon mappers' camera passes shoot its rays.
pub const TAKE_ORTHOGRAPHIC: [&str; 9] = [
    "pt", "bdpt", "vcm", "bpm", "pm", "ppm", "sppm", "pssmlt", "mmlt",
];

/// Refuses a camera the integrator cannot render as the scene asks: an orthographic camera
/// where `TAKE_ORTHOGRAPHIC` does not list the integrator. (Every integrator takes the
/// gaussian filter: camera-side samples land where their rays left the film, splats spread
/// over the filter's footprint from where they land, normalised as the camera's samples
/// are.) The message names the integrator, the camera, the reason and what works.
pub fn check_camera(kind: IntegratorKind, camera: &crate::scene::Camera) -> Result<(), String> {
    let name = kind.as_str();
    if !camera.is_pinhole() && !TAKE_ORTHOGRAPHIC.contains(&name) {
        return Err(format!(
            "{kind} cannot render an orthographic sensor: {}; {} render it",
            orthographic_reason(name),
            TAKE_ORTHOGRAPHIC.join(", ")
        ));
    }
    Ok(())
}

/// Why an integrator that `TAKE_ORTHOGRAPHIC` leaves out cannot take the camera.
fn orthographic_reason(name: &str) -> &'static str {
    match name {
        "mlt" => {
            "its mutations move the camera end of a path by projecting vertices through a \
             pinhole (the lens and multi-chain perturbations, the bidirectional mutation's \
             camera joins), and an orthographic camera's rays share one direction, a delta no \
             vertex can be projected through"
        }
        _ => "its rays all have one direction, a delta it does not model",
    }
}

/// Renders a scene with an integrator from nothing.
pub fn render(
    kind: IntegratorKind,
    data: Arc<SceneData>,
    settings: &RenderSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    (kind.0.render)(data, settings, budget, control, None)
}

/// Continues a render from its finished passes (see `driver::render_waves` and
/// `driver::resume_passes`). Callers check `resumes` first (`reference` refuses MLT).
pub fn resume(
    kind: IntegratorKind,
    data: Arc<SceneData>,
    settings: &RenderSettings,
    budget: Budget,
    control: &Control,
    from: Resume,
) -> RenderOutcome {
    assert!(
        kind.resumes(),
        "{kind} does not resume (callers check resumes)"
    );
    (kind.0.render)(data, settings, budget, control, Some(from))
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
    /// Lines the integrator adds to the report and the bench table (label, value).
    pub notes: Vec<(&'static str, String)>,
    /// What a later run continues from (the photon mappers' saved state; `PassState::save`).
    pub state: Option<Vec<u8>>,
    /// Closest-hit and shadow rays, where no trace system counted them (the megakernel).
    pub counted_rays: Option<(u64, u64)>,
}

impl RenderOutcome {
    pub fn closest_rays(&self) -> u64 {
        match self.counted_rays {
            Some((closest, _)) => closest,
            None => self.taken_by(&["trace_closest", "trace_coherent_closest"]),
        }
    }
    pub fn shadow_rays(&self) -> u64 {
        match self.counted_rays {
            Some((_, shadow)) => shadow,
            None => self.taken_by(&["trace_shadow", "trace_coherent_shadow"]),
        }
    }
    /// Items the systems of these names took, together.
    fn taken_by(&self, systems: &[&str]) -> u64 {
        systems
            .iter()
            .filter_map(|name| self.stats.get(name))
            .map(|s| s.taken)
            .sum()
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
