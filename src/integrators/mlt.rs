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
//!     -> estimate_normalisation -> splat_expected_values -> commit_accepted
//! ```
//!
//! Chains are the BDPT state's wavefront slots (chain i = sample slot i), all in lock step.
//!
//! No depth cap but the user's `--max-depth` (default unlimited, Russian roulette ends paths,
//! as PT and BDPT): a primary-sample vector stores every number a path of depth
//! `STORED_DEPTH` can draw (`bdpt::stream_dims`, three streams interleaved), and a deeper path
//! draws its further numbers from the vector's tail seed, fresh in every proposal (an
//! independent uniform proposal for those numbers: symmetric, see `PrimarySamples`). mmlt's
//! groups are the depths below `bdpt::MULTIPLEX_TAIL_DEPTH` and one tail group for every
//! deeper path, each sample's depth drawn geometrically and divided by its probability.
//!
//! The normalisation b (and mmlt's b_k) is the bootstrap's mean target, refined as the chains
//! run by every large step's target (fresh uniform vectors: more independent samples of b),
//! and the image is scaled by it when developed (`estimate_normalisation`).

use crate::film::Film;
use crate::integrators::bdpt::{self, BdptSettings, BdptState, Numbers};
use crate::integrators::driver::{IntegratorState, PassState, render_passes};
use crate::integrators::{Budget, Control, RenderOutcome, RenderSettings, SceneData};
use crate::mlt::{
    ChainSplats, ChainStates, MltCounters, MutationSettings, Normalisation, SeedSelection,
    SmallStep,
};
use crate::path::MisHeuristic;
use crate::pipeline::{Graph, Node};
use crate::sampling::{PrimarySamples, SampleKey, mix64};
use crate::systems::{gather, mutate};
use glam::DVec3;
use std::sync::Arc;
use std::time::Duration;

/// Depth whose numbers a primary-sample vector stores (see the module docs): deeper paths
/// draw their further numbers from the vector's tail seed.
pub const STORED_DEPTH: u32 = 16;
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

/// Under a time budget, the bootstrap stops drawing waves once it has taken this share of the
/// budget (the chains get the rest): measured as it runs, so a wave that starts below it may
/// end a little above it. b is refined by the chains' large steps as they run, so a short
/// bootstrap costs the seeds' spread rather than a frozen scale error (pssmlt, mmlt).
pub const BOOTSTRAP_TIME_SHARE: f64 = 0.1;

/// The report warns when the bootstrap took more than this share of the wall time.
pub const BOOTSTRAP_SHARE_WARNING: f64 = 0.25;

/// The report's warning for a bootstrap that took `share` of the wall time.
pub fn bootstrap_warning(share: f64) -> String {
    format!(
        "the bootstrap took {:.0}% of the wall time: the chains had the rest (--bootstrap N \
         or a longer budget)",
        100.0 * share
    )
}

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
    /// The path depth cap (`u32::MAX`: none).
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
    /// The render's time budget in seconds, if it has one: the bootstrap then ends once it
    /// has taken `BOOTSTRAP_TIME_SHARE` of it (and found some light), whatever its size rule.
    pub time_budget: Option<f64>,
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
            max_depth: s.max_depth,
            mis: s.mis,
            mutation,
            bootstrap: s.mlt.bootstrap,
            chains: s.mlt.chains.map(|c| c as usize),
            mutations_per_pixel: None,
            bootstrap_image: false,
            min_depth: 0,
            chain_rule: ChainRule::StepsPerChain(STEPS_PER_CHAIN),
            bootstrap_wave: 0,
            time_budget: None,
        }
    }

    /// Seed groups: in mmlt one per depth below `MULTIPLEX_TAIL_DEPTH` (up to max_depth), and
    /// the tail group of every deeper path if max_depth reaches it; in pssmlt one.
    pub fn groups(&self) -> usize {
        if self.multiplexed {
            let tail = bdpt::MULTIPLEX_TAIL_DEPTH;
            self.max_depth.min(tail - 1) as usize + 1 + (self.max_depth >= tail) as usize
        } else {
            1
        }
    }

    /// Numbers stored per primary-sample vector.
    pub fn dims(&self) -> u32 {
        3 * bdpt::stream_dims(self.max_depth.min(STORED_DEPTH))
    }

    /// Stored numbers the evaluations of seed group `group` can read: in mmlt, those of a
    /// path of depth `group` (the BDPT streams read no further for that depth), all for the
    /// tail group; all in pssmlt.
    pub fn dims_of_group(&self, group: u32) -> u32 {
        if self.multiplexed && group < bdpt::MULTIPLEX_TAIL_DEPTH {
            3 * bdpt::stream_dims(group.min(self.max_depth).min(STORED_DEPTH))
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
    /// Splat sums per group and pixel (slot `group x pixels + pixel`), in chain order (f64),
    /// in units of the group's b_k.
    pub splat_sums: Vec<DVec3>,
    /// The running b_k: the bootstrap's, then every large step's target too.
    pub normalisation: Normalisation,
    pub nonfinite: u64,
    /// When the render began (the report gives the bootstrap's share of the wall time).
    pub started: std::time::Instant,
}

impl MltState {
    /// The vector of bootstrap evaluation `item` (a pure function of seed and item).
    #[inline]
    pub fn bootstrap_number(seed: u64, item: u64, dim: u32) -> f32 {
        SampleKey::new(mix64(seed ^ BOOTSTRAP_DOMAIN), item, 0).get(dim)
    }

    /// The tail seed of bootstrap evaluation `item` (its numbers past the stored ones).
    #[inline]
    pub fn bootstrap_tail(seed: u64, item: u64) -> u64 {
        SampleKey::new(mix64(seed ^ BOOTSTRAP_DOMAIN), item, 1).bits()
    }

    /// b = sum of b_k as the render stands: the bootstrap's, refined by every large step
    /// since (0 before the bootstrap, or for a black scene).
    pub fn normalisation(&self) -> f64 {
        if self.selection.is_none() {
            return 0.0;
        }
        self.normalisation.total()
    }

    /// b as the bootstrap alone estimated it.
    pub fn bootstrap_normalisation(&self) -> f64 {
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

    /// The image of the steps taken: per group, b_k x its splat sums x pixels / steps per
    /// chain, summed over the groups.
    pub fn image_film(&self) -> Film {
        let (w, h) = (self.bdpt.film.width, self.bdpt.film.height);
        let n = self.pixels as usize;
        let mut sums = vec![DVec3::ZERO; n];
        if self.step > 0 && self.selection.is_some() {
            let per_step = self.pixels as f64 / self.step as f64;
            for (g, group) in self.splat_sums.chunks(n).enumerate() {
                let scale = self.normalisation.group(g) * per_step;
                if scale > 0.0 {
                    for (out, v) in sums.iter_mut().zip(group) {
                        *out += *v * scale;
                    }
                }
            }
        }
        let mut film = Film::from_parts(w, h, sums, vec![1; w * h], Vec::new(), self.nonfinite)
            .expect("the image's size");
        film.nonfinite = self.nonfinite;
        film
    }

    /// The bootstrap's share of the time since the render began.
    pub fn bootstrap_share(&self) -> f64 {
        self.bootstrap.time.as_secs_f64() / self.started.elapsed().as_secs_f64().max(1e-9)
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
                    "{} evaluations in {:.3} s ({:.1}% of the wall time), b = {:.6}",
                    self.bootstrap.evaluated,
                    self.bootstrap.time.as_secs_f64(),
                    100.0 * self.bootstrap_share(),
                    self.bootstrap_normalisation()
                ),
            ),
            (
                "normalisation",
                format!(
                    "b = {:.6} from the bootstrap and {} large steps",
                    self.normalisation(),
                    self.normalisation.large_steps
                ),
            ),
        ];
        if self.bootstrap_share() > BOOTSTRAP_SHARE_WARNING {
            lines.push(("warning", bootstrap_warning(self.bootstrap_share())));
        }
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
                    .map(|(k, ((b, n), s))| {
                        let tail = k as u32 >= bdpt::MULTIPLEX_TAIL_DEPTH;
                        format!("{k}{}: {b:.4}/{n}/{s}", if tail { "+" } else { "" })
                    })
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
                    Node::system(accept::EstimateNormalisation),
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
        "normalisation",
        "nonfinite",
        "started",
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
            settings.max_depth.min(STORED_DEPTH) as usize + 3
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
            splat_sums: vec![DVec3::ZERO; groups * pixels as usize],
            normalisation: Normalisation::default(),
            nonfinite: 0,
            started: std::time::Instant::now(),
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
        Budget::Seconds(t) => {
            mlt.time_budget = Some(t);
            Budget::Seconds(t)
        }
    };
    let mut outcome = render_passes::<S>(data, settings, budget, control);
    // The chains the render ran (a time budget may have fitted them to its pace), each
    // taking steps_per_pass steps a pass.
    let chains = outcome.wavefront as u64;
    outcome.samples = outcome.passes * pixels.div_ceil(chains.max(1)).max(1) * chains;
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
