//! What the systems of Metropolis light transport share: the settings of pssmlt and mmlt,
//! the rules that size their chains and bootstrap, and the bootstrap's numbers.
//! `crate::integrators::mlt` assembles them into its state; path-space MLT seeds from it.

use super::subpaths as bdpt;
use crate::mlt::{MutationSettings, path_chains::MutationSet};
use crate::path::MisHeuristic;
use crate::sampling::{SampleKey, mix64};
use glam::DVec3;
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

/// Separates the bootstrap's numbers from every other use of the seed.
pub const BOOTSTRAP_DOMAIN: u64 = 0x6d6c_745f_626f_6f74;

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
    /// Bootstrap evaluations (full BDPT samples, each with a weight in every group); None: the
    /// automatic rule.
    pub bootstrap: Option<u64>,
    /// Chains; None: from the budget.
    pub chains: Option<usize>,
    /// The mutations per pixel asked for (None for a time budget).
    pub mutations_per_pixel: Option<u64>,
    /// Keep the bootstrap's own image (tests).
    pub bootstrap_image: bool,
    /// Keep each strategy's share of the image (mmlt: `--strategy-images`), split by the
    /// strategy (s, t) of the chain state that made each splat.
    pub strategy_images: bool,
    /// Where direct illumination comes from (`integrators::direct_illumination`); where it
    /// is apart, depths 0 and 1 get no weight (`min_depth`).
    pub direct: DirectIllumination,
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
    /// pssmlt (`multiplexed` false) or mmlt with `seed` and every other setting its default:
    /// no depth cap, power-heuristic MIS, the automatic bootstrap and chains.
    pub fn new(seed: u64, multiplexed: bool) -> MltSettings {
        MltSettings {
            seed,
            multiplexed,
            max_depth: u32::MAX,
            mis: MisHeuristic::Power,
            mutation: if multiplexed {
                MutationSettings::MMLT
            } else {
                MutationSettings::PSSMLT
            },
            bootstrap: None,
            chains: None,
            mutations_per_pixel: None,
            bootstrap_image: false,
            strategy_images: false,
            direct: DirectIllumination::InChains,
            chain_rule: ChainRule::StepsPerChain(STEPS_PER_CHAIN),
            bootstrap_wave: 0,
            time_budget: None,
        }
    }

    /// Depths below this get no weight: 2 where direct illumination is rendered apart.
    pub fn min_depth(&self) -> u32 {
        if self.direct.apart() { 2 } else { 0 }
    }

    /// Direct illumination as `--direct-spp` asks (None: one sample per pixel per
    /// `DIRECT_MUTATIONS_PER_SAMPLE` mutations per pixel) where the chains have deeper paths to
    /// render (`max_depth` 2 or more); else in the chains.
    pub fn with_direct(mut self, max_depth: u32, direct_spp: Option<u32>) -> MltSettings {
        self.direct = if max_depth >= 2 {
            DirectIllumination::from_option(direct_spp)
        } else {
            DirectIllumination::InChains
        };
        self
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

impl Bootstrap {
    /// The vector of bootstrap evaluation `item` (a pure function of seed and item).
    #[inline]
    pub fn number(seed: u64, item: u64, dim: u32) -> f32 {
        SampleKey::new(mix64(seed ^ BOOTSTRAP_DOMAIN), item, 0).get(dim)
    }

    /// The tail seed of bootstrap evaluation `item` (its numbers past the stored ones).
    #[inline]
    pub fn tail(seed: u64, item: u64) -> u64 {
        SampleKey::new(mix64(seed ^ BOOTSTRAP_DOMAIN), item, 1).bits()
    }
}

/// Mitsuba's samples per pixel for the direct illumination rendered apart by its `mlt` (the
/// study's preset asks for it).
pub const MITSUBA_DIRECT_SPP: u32 = 16;

/// The Metropolis integrators' default: one sample per pixel of direct illumination every this many mutations per
/// pixel, so that it converges with the chains whatever the budget. A depth-0/1 path tracing
/// sample costs a fraction of a mutation (a BDPT evaluation of a whole path): one per mutation
/// took about 12% of mmlt's time on tests/scenes/glass_tube.ron, whose direct light includes
/// a small light's reflection in glass that a quarter of that sampled too rarely (issue 42).
pub const DIRECT_MUTATIONS_PER_SAMPLE: u32 = 1;

/// Where a Metropolis render's direct illumination (paths of depth 0 and 1) comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirectIllumination {
    /// The chains render every depth (`--direct-spp 0`).
    InChains,
    /// Path tracing at this many samples per pixel, before the chains (`--direct-spp N`).
    Samples(u32),
    /// Path tracing, one sample per pixel from the start and one more every this many
    /// mutations per pixel (the default, `DIRECT_MUTATIONS_PER_SAMPLE`).
    OnePerMutations(u32),
}

impl DirectIllumination {
    /// From `--direct-spp` (None: the default).
    pub fn from_option(spp: Option<u32>) -> DirectIllumination {
        match spp {
            None => DirectIllumination::OnePerMutations(DIRECT_MUTATIONS_PER_SAMPLE),
            Some(0) => DirectIllumination::InChains,
            Some(n) => DirectIllumination::Samples(n),
        }
    }

    /// Whether the chains leave depths 0 and 1 to path tracing.
    pub fn apart(self) -> bool {
        self != DirectIllumination::InChains
    }

    /// Samples per pixel the direct image should hold once the chains have taken
    /// `mutations` steps in all over `pixels` pixels.
    pub fn samples_after(self, mutations: u64, pixels: u64) -> u64 {
        match self {
            DirectIllumination::InChains => 0,
            DirectIllumination::Samples(n) => n as u64,
            DirectIllumination::OnePerMutations(k) => {
                mutations / (pixels.max(1) * k.max(1) as u64) + 1
            }
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathMltSettings {
    pub seed: u64,
    /// The user's depth cap (`u32::MAX`: none).
    pub max_depth: u32,
    pub mutations: MutationSet,
    /// The bootstrap's settings (full BDPT, balance heuristic, depth >= 2 with direct
    /// illumination apart), and the direct illumination's samples per pixel.
    pub bootstrap: MltSettings,
}

/// Proposals and acceptances per mutation kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MutationCounts {
    pub proposed: [u64; 4],
    pub accepted: [u64; 4],
    /// Proposals with f = 0 (impossible or black paths).
    pub zero: [u64; 4],
    /// Chain steps taken (chains x steps).
    pub steps: u64,
}

impl std::ops::Add for MutationCounts {
    type Output = MutationCounts;
    fn add(mut self, o: MutationCounts) -> MutationCounts {
        for k in 0..4 {
            self.proposed[k] += o.proposed[k];
            self.accepted[k] += o.accepted[k];
            self.zero[k] += o.zero[k];
        }
        self.steps += o.steps;
        self
    }
}
