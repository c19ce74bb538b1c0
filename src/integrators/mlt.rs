//! Metropolis light transport in primary sample space over BDPT: `pssmlt` (Kelemen et al.
//! 2002: every evaluation is a full BDPT sample, the target the luminance of all its
//! contributions, light-tracing splats included) and `mmlt` (Hachisuka et al. 2014, pbrt-v4's
//! `mlt`: every evaluation one strategy (s, t) at the chain's depth, its MIS weight in the
//! target). The kernel (mutations, acceptance, expected-value splats, seeds) is `crate::mlt`;
//! the evaluation is the BDPT graph's own systems, run as a nested graph on a `BdptState`
//! whose numbers come from the chains' primary-sample vectors (`bdpt::Numbers::Primary`).
//!
//! The graph (one run per pass; a pass is `steps_per_pass` steps of every chain):
//!
//! ```text
//! once bootstrap:
//!     loop bootstrap_waves:  begin_bootstrap_wave -> [bdpt evaluation] -> gather_chain_contributions
//!                            -> collect_bootstrap_weights
//!     select_seeds -> replay_seeds -> [bdpt evaluation] -> gather_chain_contributions -> adopt_seeds
//! loop mutation_steps:
//!     propose_mutations -> [bdpt evaluation] -> gather_chain_contributions -> accept_or_reject
//!     -> splat_expected_values -> commit_accepted
//! ```
//!
//! Chains are the BDPT state's wavefront slots (chain i = sample slot i), all in lock step.
//!
//! Bounded dimensions: a primary-sample vector must have a fixed length, so MLT caps the path
//! depth at `MLT_MAX_DEPTH` (16; `--max-depth` below that is used as given) and sizes the
//! vectors to every number a path of that depth can draw (`bdpt::stream_dims`, three streams
//! interleaved). Paths deeper than the cap are not rendered (on the furnace, 2^-17 of the
//! light).

use crate::film::Film;
use crate::integrators::bdpt::{self, BdptSettings, BdptState, Numbers};
use crate::integrators::driver::{IntegratorState, PassState, render_passes};
use crate::integrators::{Budget, Control, RenderOutcome, RenderSettings, SceneData};
use crate::mlt::{
    ChainSplats, ChainStates, MltCounters, MutationSettings, SeedSelection, SmallStep,
};
use crate::path::MisHeuristic;
use crate::pipeline::{Graph, Node};
use crate::sampling::{PrimarySamples, SampleKey, mix64};
use crate::systems::{gather, mutate};
use glam::DVec3;
use std::sync::Arc;
use std::time::Duration;

/// Deepest path MLT renders (see the module docs).
pub const MLT_MAX_DEPTH: u32 = 16;
/// Most chains (the BDPT wavefront).
pub const MAX_CHAINS: usize = bdpt::WAVEFRONT;
/// Fewest chains.
pub const MIN_CHAINS: usize = 256;
/// Chains of pssmlt and mmlt are about (mutations) / this, so each takes at least this many
/// steps.
pub const STEPS_PER_CHAIN: u64 = 64;
/// Chains of path-space MLT are about sqrt(this x mutations): its perturbations move a path a
/// few pixels per step, so a short chain stays where its seed put it (torus_glass wants long
/// chains), while more chains start from more seeds (door_ajar wants many). relMSE against
/// Mitsuba's references at 64 mutations per pixel (256x256, 4.2M mutations, one bootstrap):
/// torus_glass 0.028 / 0.027 / 0.035 / 0.108 with 256 / 1024 / 4096 / 32768 chains,
/// door_ajar 0.113 / 0.075 / 0.062 / 0.055; this rule gives 4096 there. Mitsuba runs one chain
/// per ~200k mutations.
pub const PATH_CHAINS_PER_SQRT_MUTATION: u64 = 4;
/// The automatic bootstrap draws at least one evaluation per this many mutations asked for
/// (Mitsuba's 100000 luminance samples are one per 16 mutations at 256x256 and 25 per pixel):
/// b's error is a heavy-tailed scale error (paths that only a rare strategy finds, such as
/// light reaching a diffuse surface through glass), and the sample variance cannot warn of
/// tails it has not yet seen.
pub const MUTATIONS_PER_BOOTSTRAP_EVALUATION: u64 = 16;
/// The mutations per pixel a time budget is planned for (chains and bootstrap size).
pub const TIMED_MUTATIONS_PER_PIXEL: u64 = 256;
/// Bootstrap evaluations per wave at least in path-space MLT: with fewer (a few hundred chains), per-wave
/// overheads dominate (1.8M evaluations took 44 s in waves of 256, 2.8 s for 1M in 4096).
pub const BOOTSTRAP_WAVE: usize = 8192;
/// Most bootstrap evaluations (all groups together) the automatic rule draws.
pub const MAX_BOOTSTRAP_EVALUATIONS: u64 = 1 << 22;
/// Bootstrap evaluations per chain at least (so chains rarely share a seed).
pub const BOOTSTRAP_PER_CHAIN: u64 = 16;
/// The automatic bootstrap also runs until it has found this many non-zero evaluations per
/// chain (within `MAX_BOOTSTRAP_EVALUATIONS`): where light is hard to find (door_ajar finds it
/// in 0.4% of evaluations), 16 evaluations per chain leave about 13 chains on each seed, and
/// those start in the same spot and stay correlated for hundreds of steps (measured on
/// door_ajar at 20 s: relMSE 0.39 with the floor alone, 0.15 with 1.7 M evaluations).
pub const NONZERO_SEEDS_PER_CHAIN: f64 = 0.25;

/// Separates the bootstrap's numbers from every other use of the seed.
const BOOTSTRAP_DOMAIN: u64 = 0x6d6c_745f_626f_6f74;

/// How the number of chains follows the mutations asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChainRule {
    /// Mutations / this (pssmlt, mmlt: `STEPS_PER_CHAIN`).
    StepsPerChain(u64),
    /// sqrt(this x mutations) (path-space mlt: `PATH_CHAINS_PER_SQRT_MUTATION`).
    SqrtOfMutations(u64),
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MltSettings {
    pub seed: u64,
    /// Multiplexed (mmlt) or full BDPT per evaluation (pssmlt).
    pub multiplexed: bool,
    /// The path depth cap (at most `MLT_MAX_DEPTH`).
    pub max_depth: u32,
    pub mis: MisHeuristic,
    pub mutation: MutationSettings,
    /// Bootstrap evaluations per group (depth in mmlt); None: the automatic rule.
    pub bootstrap: Option<u64>,
    /// Chains; None: from the budget.
    pub chains: Option<usize>,
    /// The mutations per pixel asked for (None for a time budget).
    pub mutations_per_pixel: Option<u64>,
    /// Keep the bootstrap's own image (tests).
    pub bootstrap_image: bool,
    /// Depths below this get no weight (path-space MLT renders them apart).
    pub min_depth: u32,
    /// How many chains, unless given.
    pub chain_rule: ChainRule,
    /// Bootstrap evaluations per wave at least (path-space MLT: `BOOTSTRAP_WAVE`; else the
    /// chains, which evaluate in the same columns).
    pub bootstrap_wave: usize,
}

impl MltSettings {
    pub fn from_render(s: &RenderSettings, multiplexed: bool) -> MltSettings {
        let mut mutation = if multiplexed {
            MutationSettings::MMLT
        } else {
            MutationSettings::PSSMLT
        };
        if let Some(p) = s.mlt.large_step {
            mutation.large_step_probability = p;
        }
        if let Some(sigma) = s.mlt.sigma {
            mutation.small_step = SmallStep::WrappedNormal { sigma };
        }
        MltSettings {
            seed: s.seed,
            multiplexed,
            max_depth: s.max_depth.min(MLT_MAX_DEPTH),
            mis: s.mis,
            mutation,
            bootstrap: s.mlt.bootstrap,
            chains: s.mlt.chains.map(|c| c as usize),
            mutations_per_pixel: None,
            bootstrap_image: false,
            min_depth: 0,
            chain_rule: ChainRule::StepsPerChain(STEPS_PER_CHAIN),
            bootstrap_wave: 0,
        }
    }

    /// Seed groups: one per depth 0..=max_depth (mmlt), or one.
    pub fn groups(&self) -> usize {
        if self.multiplexed {
            self.max_depth as usize + 1
        } else {
            1
        }
    }

    /// Numbers per primary-sample vector.
    pub fn dims(&self) -> u32 {
        3 * bdpt::stream_dims(self.max_depth)
    }

    /// Numbers the evaluations of seed group `group` can read: in mmlt, those of a path of
    /// depth `group` (the BDPT streams read no further for that depth); all in pssmlt.
    pub fn dims_of_group(&self, group: u32) -> u32 {
        if self.multiplexed {
            3 * bdpt::stream_dims(group.min(self.max_depth))
        } else {
            self.dims()
        }
    }

    /// Chains for a `pixels`-pixel image by `chain_rule`, within [`MIN_CHAINS`,
    /// `MAX_CHAINS`], unless given.
    pub fn chain_count(&self, pixels: u64) -> usize {
        self.chains.unwrap_or_else(|| {
            let m = self
                .mutations_per_pixel
                .unwrap_or(TIMED_MUTATIONS_PER_PIXEL);
            let chains = match self.chain_rule {
                ChainRule::StepsPerChain(steps) => m * pixels / steps,
                ChainRule::SqrtOfMutations(k) => ((k * m * pixels) as f64).sqrt() as u64,
            };
            (chains as usize).clamp(MIN_CHAINS, MAX_CHAINS)
        })
    }

    /// Steps of every chain per pass: about one mutation per pixel.
    pub fn steps_per_pass(&self, pixels: u64) -> u64 {
        pixels.div_ceil(self.chain_count(pixels) as u64).max(1)
    }

    /// Passes for `m` mutations per pixel (rounded up).
    pub fn passes_for(&self, pixels: u64, m: u64) -> u64 {
        let per_pass = self.steps_per_pass(pixels) * self.chain_count(pixels) as u64;
        (m * pixels).div_ceil(per_pass).max(1)
    }
}

/// The bootstrap: BDPT evaluations with fresh numbers, their weights per group.
#[derive(Default)]
pub struct Bootstrap {
    /// Per group, one weight per evaluation (the target: luminance, MIS-weighted in mmlt).
    pub weights: Vec<Vec<f32>>,
    pub evaluated: u64,
    pub done: bool,
    /// Per group, the evaluations' contributions summed per pixel (with `bootstrap_image`).
    pub images: Vec<Vec<DVec3>>,
    pub time: Duration,
    pub started: Option<std::time::Instant>,
    /// Seeds whose replay did not give their bootstrap weight (0: the numbers replay exactly).
    pub replay_mismatches: usize,
}

/// The state of a Metropolis render: the chains and the BDPT state that evaluates them.
pub struct MltState {
    pub data: Arc<SceneData>,
    pub settings: MltSettings,
    pub pixels: u64,
    pub steps_per_pass: u64,
    pub bdpt: BdptState,
    pub chains: ChainStates,
    pub bootstrap: Bootstrap,
    pub selection: Option<SeedSelection>,
    /// Steps taken by every chain so far.
    pub step: u64,
    /// Steps left in the pass under way.
    pub steps_left: u64,
    pub counters: MltCounters,
    pub splats: ChainSplats,
    /// Splat sums per pixel, in chain order (f64).
    pub splat_sums: Vec<DVec3>,
    pub nonfinite: u64,
}

impl MltState {
    /// The vector of bootstrap evaluation `item` (a pure function of seed and item).
    #[inline]
    pub fn bootstrap_number(seed: u64, item: u64, dim: u32) -> f32 {
        SampleKey::new(mix64(seed ^ BOOTSTRAP_DOMAIN), item, 0).get(dim)
    }

    /// b = sum of b_k (0 before the bootstrap, or for a black scene).
    pub fn normalisation(&self) -> f64 {
        self.selection
            .as_ref()
            .map_or(0.0, SeedSelection::total_normalisation)
    }

    /// The bootstrap's own image (its BDPT estimate), with `bootstrap_image` set.
    pub fn bootstrap_image(&self) -> Vec<DVec3> {
        let mut image = vec![DVec3::ZERO; self.pixels as usize];
        for (g, sums) in self.bootstrap.images.iter().enumerate() {
            let n = self.bootstrap.weights[g].len().max(1) as f64;
            for (out, v) in image.iter_mut().zip(sums) {
                *out += *v * (self.pixels as f64 / n);
            }
        }
        image
    }

    /// The image of the steps taken: splat sums x pixels / steps per chain.
    pub fn image_film(&self) -> Film {
        let (w, h) = (self.bdpt.film.width, self.bdpt.film.height);
        let scale = if self.step == 0 {
            0.0
        } else {
            self.pixels as f64 / self.step as f64
        };
        let sums = self.splat_sums.iter().map(|v| *v * scale).collect();
        let mut film = Film::from_parts(w, h, sums, vec![1; w * h], Vec::new(), self.nonfinite)
            .expect("the image's size");
        film.nonfinite = self.nonfinite;
        film
    }

    /// Lines for the render report.
    pub fn report_lines(&self) -> Vec<(&'static str, String)> {
        let c = &self.counters;
        let rate = |a: u64, n: u64| format!("{:.1}%", 100.0 * a as f64 / n.max(1) as f64);
        let mut lines = vec![
            (
                "mutations",
                format!(
                    "{} ({} chains x {} steps)",
                    c.steps,
                    self.chains.chains(),
                    self.step
                ),
            ),
            (
                "acceptance",
                format!(
                    "{} overall, {} large steps, {} small steps",
                    rate(c.accepted, c.steps),
                    rate(c.large_accepted, c.large_proposed),
                    rate(c.small_accepted, c.small_proposed)
                ),
            ),
            (
                "rejected",
                format!(
                    "{} zero, {} invalid (never accepted)",
                    c.rejected_zero, c.rejected_invalid
                ),
            ),
            (
                "bootstrap",
                format!(
                    "{} evaluations in {:.3} s, b = {:.6}",
                    self.bootstrap.evaluated,
                    self.bootstrap.time.as_secs_f64(),
                    self.normalisation()
                ),
            ),
        ];
        if let Some(sel) = &self.selection {
            let seeds = sel.distinct_seeds();
            lines.push((
                "seeds",
                format!(
                    "{} distinct for {} chains",
                    seeds.iter().sum::<usize>(),
                    self.chains.chains()
                ),
            ));
            if self.settings.multiplexed {
                let per_depth: Vec<String> = sel
                    .normalisation
                    .iter()
                    .zip(&sel.chains_per_group)
                    .zip(&seeds)
                    .enumerate()
                    .filter(|(_, ((b, _), _))| **b > 0.0)
                    .map(|(k, ((b, n), s))| format!("{k}: {b:.4}/{n}/{s}"))
                    .collect();
                lines.push(("b_k/chains/seeds by depth", per_depth.join(", ")));
            }
        }
        lines
    }
}

fn evaluation() -> Node<MltState> {
    Node::nested(
        bdpt::evaluation_graph(),
        "bdpt",
        |s: &mut MltState| &mut s.bdpt,
        <BdptState as IntegratorState>::INPUTS,
    )
}

/// The bootstrap's nodes: waves of BDPT evaluations with fresh numbers and their weights,
/// then the seeds chosen by weight, replayed and adopted. Path-space MLT runs them too.
pub fn bootstrap_nodes() -> Vec<Node<MltState>> {
    use mutate::bootstrap;
    vec![
        Node::Loop {
            name: "bootstrap_waves",
            queue_len: |s: &MltState| !s.bootstrap.done as usize,
            body: vec![
                Node::system(bootstrap::BeginBootstrapWave),
                evaluation(),
                Node::system(gather::chain_contributions::GatherChainContributions),
                Node::system(bootstrap::CollectBootstrapWeights),
            ],
        },
        Node::system(bootstrap::SelectSeeds),
        Node::system(bootstrap::ReplaySeeds),
        evaluation(),
        Node::system(gather::chain_contributions::GatherChainContributions),
        Node::system(bootstrap::AdoptSeeds),
    ]
}

/// The MLT graph (the same for pssmlt and mmlt; the settings choose).
pub fn graph() -> Graph<MltState> {
    use mutate::{accept, propose};
    Graph::new(
        "mlt",
        vec![
            Node::Once {
                name: "bootstrap",
                needed: |s: &MltState| !s.bootstrap.done,
                body: bootstrap_nodes(),
            },
            Node::Loop {
                name: "mutation_steps",
                queue_len: |s: &MltState| {
                    if s.selection.is_some() {
                        s.steps_left as usize
                    } else {
                        0
                    }
                },
                body: vec![
                    Node::system(propose::ProposeMutations),
                    evaluation(),
                    Node::system(gather::chain_contributions::GatherChainContributions),
                    Node::system(accept::AcceptOrReject),
                    Node::system(accept::SplatExpectedValues),
                    Node::system(accept::CommitAccepted),
                ],
            },
        ],
    )
}

impl IntegratorState for MltState {
    type Settings = MltSettings;
    const INPUTS: &'static [&'static str] = &[
        "data",
        "settings",
        "pixels",
        "steps_per_pass",
        "bdpt",
        "chains",
        "bootstrap",
        "selection",
        "step",
        "steps_left",
        "counters",
        "splats",
        "splat_sums",
        "nonfinite",
    ];
    fn graph(_: &SceneData, _: &MltSettings) -> Graph<MltState> {
        graph()
    }
}

impl PassState for MltState {
    fn new(data: Arc<SceneData>, settings: MltSettings) -> MltState {
        let cam = data.scene.camera;
        let pixels = cam.width as u64 * cam.height as u64;
        let chains = settings.chain_count(pixels);
        let dims = settings.dims();
        let bdpt_settings = BdptSettings {
            mis: settings.mis,
            min_depth: settings.min_depth,
            ..BdptSettings::new(settings.seed, settings.max_depth)
        };
        let wave = chains.max(settings.bootstrap_wave);
        let mut bdpt = BdptState::new(data.clone(), bdpt_settings, wave);
        bdpt.sampler = Numbers::Primary {
            store: PrimarySamples::new(wave, dims),
            fallback_seed: mix64(settings.seed ^ BOOTSTRAP_DOMAIN),
        };
        // The most contributions one evaluation makes: its own pixel and a light-tracing
        // splat per light vertex (pssmlt); one strategy (mmlt).
        let stride = if settings.multiplexed {
            1
        } else {
            settings.max_depth as usize + 3
        };
        let groups = settings.groups();
        MltState {
            steps_per_pass: settings.steps_per_pass(pixels),
            bootstrap: Bootstrap {
                weights: vec![Vec::new(); groups],
                images: if settings.bootstrap_image {
                    vec![vec![DVec3::ZERO; pixels as usize]; groups]
                } else {
                    Vec::new()
                },
                ..Bootstrap::default()
            },
            data,
            settings,
            pixels,
            bdpt,
            chains: ChainStates::new(chains, dims, stride, wave),
            selection: None,
            step: 0,
            steps_left: 0,
            counters: MltCounters::default(),
            splats: ChainSplats::new(),
            splat_sums: vec![DVec3::ZERO; pixels as usize],
            nonfinite: 0,
        }
    }

    fn begin_pass(&mut self, _pass: u64) {
        self.steps_left = self.steps_per_pass;
    }

    fn report(&self) -> Vec<(&'static str, String)> {
        self.report_lines()
    }

    fn finish(self, _passes: u64) -> (Film, usize, usize) {
        let film = self.image_film();
        let chains = self.chains.chains();
        let bytes = 2 * self.chains.dims() as usize * 4
            + self.chains.current_contributions.stride() * 2 * 16
            + self.bdpt.bytes_per_sample();
        (film, bytes, chains)
    }
}

/// Renders with pssmlt (`multiplexed` false) or mmlt: `--spp M` is M mutations per pixel
/// (rounded up to whole passes), a time budget ends at a pass boundary.
pub fn render(
    data: Arc<SceneData>,
    settings: MltSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    render_chains::<MltState>(data, settings, |s| s, budget, control)
}

/// Renders a Metropolis integrator whose chains `chains` describes (pssmlt, mmlt, or the
/// bootstrap settings of path-space mlt): `--spp M` is M mutations per pixel (rounded up to
/// whole passes), and the outcome counts mutations as its samples.
pub fn render_chains<S: PassState>(
    data: Arc<SceneData>,
    mut settings: S::Settings,
    chains: fn(&mut S::Settings) -> &mut MltSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    let cam = data.scene.camera;
    let pixels = cam.width as u64 * cam.height as u64;
    let mlt = chains(&mut settings);
    let budget = match budget {
        Budget::SamplesPerPixel(m) => {
            mlt.mutations_per_pixel = Some(m);
            Budget::SamplesPerPixel(mlt.passes_for(pixels, m))
        }
        b => b,
    };
    let mutations_per_pass = mlt.steps_per_pass(pixels) * mlt.chain_count(pixels) as u64;
    let mut outcome = render_passes::<S>(data, settings, budget, control);
    outcome.samples = outcome.passes * mutations_per_pass;
    let wall = outcome.wall.as_secs_f64().max(1e-9);
    outcome.notes.insert(
        0,
        (
            "mutations/s",
            crate::report::mega(outcome.samples as f64 / wall),
        ),
    );
    outcome
}
