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
//!     select_seeds -> replay_seeds -> [bdpt evaluation] -> gather_chain_contributions
//!     -> (mmlt: pick_seed_strategies -> [bdpt evaluation] -> gather_chain_contributions)
//!     -> adopt_seeds
//! loop mutation_steps:
//!     propose_mutations -> [bdpt evaluation] -> gather_chain_contributions -> accept_or_reject
//!     -> estimate_normalisation -> splat_expected_values -> splat_strategy_images
//!     -> commit_accepted
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

use crate::film::{Film, Image};
use crate::integrators::bdpt::{self, BdptSettings, BdptState, Numbers};
use crate::integrators::direct_illumination;
use crate::integrators::driver::{IntegratorState, PassState, render_passes};
use crate::integrators::{Budget, Control, RenderOutcome, RenderSettings, SceneData};
use crate::mlt::{ChainSplats, ChainStates, MltCounters, Normalisation, SeedSelection, SmallStep};
use crate::pipeline::{Graph, Node};
use crate::sampling::{PrimarySamples, mix64};
use crate::systems::{gather, mutate};
use glam::DVec3;
use std::collections::BTreeMap;
use std::sync::Arc;

pub use crate::components::metropolis::*;

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

impl MltSettings {
    pub fn from_render(s: &RenderSettings, multiplexed: bool) -> MltSettings {
        let mut mutation = MltSettings::new(s.seed, multiplexed).mutation;
        if let Some(p) = s.mlt.large_step {
            mutation.large_step_probability = p;
        }
        if let Some(sigma) = s.mlt.sigma {
            mutation.small_step = SmallStep::WrappedNormal { sigma };
        }
        MltSettings {
            max_depth: s.max_depth,
            mis: s.mis,
            mutation,
            bootstrap: s.mlt.bootstrap,
            chains: s.mlt.chains.map(|c| c as usize),
            // Each chain state is one strategy only in mmlt; a pssmlt state is all of them.
            strategy_images: multiplexed && s.strategy_images,
            ..MltSettings::new(s.seed, multiplexed)
        }
        // By default one sample per pixel of direct light per mutation per pixel.
        .with_direct(s.max_depth, s.mlt.direct_spp)
    }
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
    /// With `strategy_images` (mmlt): the splat sums again, per (group, depth, s), in units
    /// of the group's b_k.
    pub strategy_sums: BTreeMap<(u32, u32, u16), Vec<DVec3>>,
    /// The running b_k: the bootstrap's, then every large step's target too.
    pub normalisation: Normalisation,
    pub nonfinite: u64,
    /// When the render began (the report gives the bootstrap's share of the wall time).
    pub started: std::time::Instant,
    /// The direct illumination's film, once rendered (where `settings.direct` is apart).
    pub direct: Option<Film>,
}

impl MltState {
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
    /// chain, summed over the groups, plus the direct illumination rendered apart; under the
    /// gaussian each pixel divided by the filter's integral about it
    /// (`Film::splat_normalisations`: the splats were spread over their footprints).
    pub fn image_film(&self) -> Film {
        let (w, h) = (self.bdpt.film.width, self.bdpt.film.height);
        let n = self.pixels as usize;
        let mut sums = vec![DVec3::ZERO; n];
        let norm = Film::splat_normalisations(self.bdpt.data.scene.camera.filter, w, h);
        if self.step > 0 && self.selection.is_some() {
            let per_step = self.pixels as f64 / self.step as f64;
            for (g, group) in self.splat_sums.chunks(n).enumerate() {
                let scale = self.normalisation.group(g) * per_step;
                if scale > 0.0 {
                    for ((out, v), d) in sums.iter_mut().zip(group).zip(&norm) {
                        *out += *v * (scale / d);
                    }
                }
            }
        }
        let nonfinite =
            self.nonfinite + direct_illumination::add_direct_image(&mut sums, self.direct.as_ref());
        let mut film = Film::from_parts(w, h, sums, vec![1; w * h], Vec::new(), nonfinite)
            .expect("the image's size");
        film.nonfinite = nonfinite;
        film
    }

    /// Each strategy's image (`s{s}_t{t}`, with `strategy_images`): its splats scaled as the
    /// image's are (b_k of its group x pixels / steps per chain), so the images of a depth
    /// sum to that depth's part of the image; with the direct illumination's image
    /// (`direct`, depths 0 and 1) where it was rendered apart, all of them sum to the image.
    pub fn strategy_images(&self) -> Vec<(String, Image)> {
        let (w, h) = (self.bdpt.film.width, self.bdpt.film.height);
        let mut layers: BTreeMap<(u32, u16), Vec<DVec3>> = BTreeMap::new();
        if self.step > 0 && self.selection.is_some() {
            let per_step = self.pixels as f64 / self.step as f64;
            for (&(g, depth, s), sums) in &self.strategy_sums {
                let scale = self.normalisation.group(g as usize) * per_step;
                let image = layers
                    .entry((depth, s))
                    .or_insert_with(|| vec![DVec3::ZERO; sums.len()]);
                for (out, v) in image.iter_mut().zip(sums) {
                    *out += *v * scale;
                }
            }
        }
        layers
            .into_iter()
            .map(|((depth, s), sums)| {
                let t = depth as u64 + 2 - s as u64;
                let image = Image {
                    width: w,
                    height: h,
                    pixels: sums.iter().map(|v| v.as_vec3()).collect(),
                };
                (format!("s{s}_t{t}"), image)
            })
            .chain(
                self.direct
                    .as_ref()
                    .filter(|_| self.settings.strategy_images)
                    .map(|direct| ("direct".to_string(), direct.image())),
            )
            .collect()
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
        lines.push((
            "direct illumination",
            direct_illumination::report_line(self.settings.direct, self.direct.as_ref()),
        ));
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
        // mmlt: each chain's strategy from its replayed full sample, and its state there.
        Node::Once {
            name: "multiplexed_seeds",
            needed: |s: &MltState| s.settings.multiplexed,
            body: vec![
                Node::system(bootstrap::PickSeedStrategies),
                evaluation(),
                Node::system(gather::chain_contributions::GatherChainContributions),
            ],
        },
        Node::system(bootstrap::AdoptSeeds),
    ]
}

/// The MLT graph (the same for pssmlt and mmlt; the settings choose), with direct
/// illumination rendered first where it is apart.
pub fn graph(settings: &MltSettings) -> Graph<MltState> {
    use mutate::{accept, propose};
    let mut nodes = Vec::new();
    if settings.direct.apart() {
        nodes.push(Node::Once {
            name: "direct_illumination",
            needed: |s: &MltState| {
                direct_illumination::due(
                    s.settings.direct,
                    s.counters.steps,
                    s.pixels,
                    s.direct.as_ref(),
                )
            },
            body: vec![Node::system(direct_illumination::RenderDirectIllumination)],
        });
    }
    nodes.extend([
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
                Node::system(accept::SplatStrategyImages),
                Node::system(accept::CommitAccepted),
            ],
        },
    ]);
    Graph::new("mlt", nodes)
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
        "strategy_sums",
        "normalisation",
        "nonfinite",
        "started",
        "direct",
    ];
    fn graph(_: &SceneData, settings: &MltSettings) -> Graph<MltState> {
        graph(settings)
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
            min_depth: settings.min_depth(),
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
            strategy_sums: BTreeMap::new(),
            normalisation: Normalisation::default(),
            nonfinite: 0,
            started: std::time::Instant::now(),
            direct: None,
        }
    }

    fn begin_pass(&mut self, _pass: u64) {
        self.steps_left = self.steps_per_pass;
    }

    fn report(&self) -> Vec<(&'static str, String)> {
        self.report_lines()
    }

    fn layers(&self) -> Vec<(String, Image)> {
        self.strategy_images()
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
            crate::units::mega(outcome.samples as f64 / wall),
        ),
    );
    outcome
}

/// The systems of its graphs bound to the columns of `MltState`.
mod bindings {
    use super::MltState;
    use crate::systems::*;

    crate::bind! {
        MltState:
        crate::integrators::direct_illumination::RenderDirectIllumination {
            read data, seed = settings.seed, schedule = settings.direct,
                mutations = counters.steps, pixels;
            write direct;
        }
        gather::chain_contributions::GatherChainContributions {
            read wave = bdpt.wave, shadow = bdpt.shadow, connections = bdpt.connections,
                starts = bdpt.connection_start, radiance = bdpt.sample_radiance,
                sample_pixel = bdpt.sample_pixel, sample_raster = bdpt.sample_raster,
                multiplex = bdpt.multiplex,
                chosen_s = bdpt.chosen_s;
            write out = chains.proposal_contributions;
        }
        mutate::accept::AcceptOrReject {
            write chains, numbers = bdpt.sampler, counters;
        }
        mutate::accept::EstimateNormalisation {
            read chains;
            write normalisation;
        }
        mutate::accept::SplatExpectedValues {
            read chains, pixels, camera = bdpt.data.scene.camera;
            write splats, splat_sums, nonfinite;
        }
        mutate::accept::SplatStrategyImages {
            read settings, chains, pixels;
            write strategy_sums;
        }
        mutate::accept::CommitAccepted {
            write chains, step, steps_left;
        }
        mutate::bootstrap::BeginBootstrapWave {
            read settings, pixels;
            write bootstrap, numbers = bdpt.sampler, wave = bdpt.wave, multiplex = bdpt.multiplex;
        }
        mutate::bootstrap::CollectBootstrapWeights {
            read settings, pixels, wave = bdpt.wave, contributions = chains.proposal_contributions,
                connections = bdpt.connections, shadow = bdpt.shadow,
                starts = bdpt.connection_start;
            write bootstrap;
        }
        mutate::bootstrap::PickSeedStrategies {
            read settings, selection, connections = bdpt.connections, shadow = bdpt.shadow,
                starts = bdpt.connection_start;
            write chains, numbers = bdpt.sampler, wave = bdpt.wave, multiplex = bdpt.multiplex;
        }
        mutate::bootstrap::SelectSeeds {
            read settings, bootstrap, pixels;
            write selection, chains, normalisation, steps_per_pass;
        }
        mutate::bootstrap::ReplaySeeds {
            read settings, selection;
            write chains, numbers = bdpt.sampler, wave = bdpt.wave, multiplex = bdpt.multiplex;
        }
        mutate::bootstrap::AdoptSeeds {
            read settings, selection;
            write chains, bootstrap;
        }
        mutate::propose::ProposeMutations {
            read settings, step;
            write chains, numbers = bdpt.sampler, wave = bdpt.wave, multiplex = bdpt.multiplex;
        }
    }
}
