//! Veach's path-space Metropolis light transport (`--integrator mlt`, Veach and Guibas 1997, as
//! Mitsuba 0.5's `mlt`, the study's): each chain's state is a path of vertices in path-vertex
//! columns (`crate::mlt::path_chains`), and mutations change part of it: the bidirectional
//! mutation, the lens, caustic and multi-chain perturbations (systems/mutate/, one file each;
//! the path-space functions in `crate::mlt::path_space`). Per chain and step one mutation is
//! chosen uniformly among the enabled ones suitable for its path, and accepted with
//! a = min(1, f(y) T(y -> x) / (f(x) T(x -> y))).
//!
//! Direct illumination (paths of depth 0 and 1) is rendered apart by path tracing and added,
//! so the chains spend their mutations on indirect light: by default one sample per pixel per
//! mutation per pixel, as pssmlt and mmlt (Mitsuba's fixed 16 spp left a noise floor, worst
//! where a mirror lobe reflects a small light: the smooth plastic); `--direct-spp N` renders
//! N before the chains (the study's preset asks Mitsuba's 16), `--direct-spp 0` leaves every
//! depth to the chains.
//!
//! The graph (one run per pass; a pass is `steps_per_pass` steps of every chain):
//!
//! ```text
//! once direct_illumination: render_direct_illumination
//! once bootstrap: [pssmlt bootstrap: full BDPT, balance heuristic] -> adopt_seed_paths
//! loop mutation_steps:
//!     choose_mutations -> bidirectional_mutation -> lens_perturbation -> caustic_perturbation
//!     -> multichain_perturbation -> accept_path_proposals -> splat_path_expected_values
//!     -> commit_path_proposals
//! ```
//!
//! The caustic and multi-chain perturbations are in the graph only for scenes with a specular
//! material (they apply to nothing else).
//!
//! No depth cap but the user's (`--max-depth`, unlimited by default, as for PT): the seeds are
//! the bootstrap's BDPT paths, which Russian roulette ends, the bidirectional mutation's length
//! distributions are Mitsuba's unbounded two-tailed geometric ones, and a chain stores a path
//! of any length (`crate::mlt::path_chains`: fixed slots per chain, the rest of a long path in
//! the chain's overflow list).

use crate::film::Film;
use crate::integrators::direct_illumination;
use crate::integrators::driver::{IntegratorState, PassState};
use crate::integrators::mlt::{self, MltSettings, MltState};
use crate::integrators::{Budget, Control, RenderOutcome, RenderSettings, SceneData};
use crate::mlt::Splat;
use crate::mlt::path_chains::{MutationKind, MutationSet, PathChains};
use crate::path::MisHeuristic;
use crate::pipeline::{Graph, Node};
use crate::systems::mutate::{
    bidirectional, caustic_perturbation, lens_perturbation, multichain_perturbation, path_accept,
    path_mutation, path_seeds,
};
use glam::DVec3;
use std::sync::Arc;

pub use crate::components::metropolis::{
    DirectIllumination, MITSUBA_DIRECT_SPP, MutationCounts, PathMltSettings,
};

impl PathMltSettings {
    pub fn from_render(data: &SceneData, s: &RenderSettings) -> PathMltSettings {
        let cam = data.scene.camera;
        let mut mutations = MutationSet::new(cam.width, cam.height, s.mlt.lens_min.unwrap_or(0.1));
        if let Some(m) = s.mlt.mutations {
            mutations.enabled = m;
        }
        let mut bootstrap =
            MltSettings::from_render(s, false).with_direct(s.max_depth, s.mlt.direct_spp);
        bootstrap.mis = MisHeuristic::Balance;
        bootstrap.bootstrap_wave = mlt::BOOTSTRAP_WAVE;
        bootstrap.chain_rule = mlt::ChainRule::SqrtOfMutations(mlt::PATH_CHAINS_PER_SQRT_MUTATION);
        if !bootstrap.direct.apart() {
            mutations.min_vertices = 2;
        }
        mutations.max_vertices = MutationSet::max_vertices_for_depth(s.max_depth);
        PathMltSettings {
            seed: s.seed,
            max_depth: s.max_depth,
            mutations,
            bootstrap,
        }
    }
}

/// The state of a path-space MLT render.
pub struct PathMltState {
    pub data: Arc<SceneData>,
    pub settings: PathMltSettings,
    pub pixels: u64,
    pub steps_per_pass: u64,
    /// The BDPT bootstrap that seeds the chains.
    pub seeding: MltState,
    pub seeded: bool,
    pub seed_mismatches: usize,
    pub chains: PathChains,
    /// What every splat of a step is worth: b / chains.
    pub splat_scale: f32,
    pub step: u64,
    pub steps_left: u64,
    pub counts: MutationCounts,
    pub splats: Vec<Vec<Splat>>,
    /// Splat sums per pixel, in chain order (f64).
    pub splat_sums: Vec<DVec3>,
    pub nonfinite: u64,
    /// The direct illumination's film, once rendered.
    pub direct: Option<Film>,
}

/// The graph for a scene: the perturbations that can apply to its paths.
pub fn graph(data: &SceneData, settings: &PathMltSettings) -> Graph<PathMltState> {
    let specular = data
        .scene
        .materials
        .iter()
        .any(|m| m.kind().has_delta_lobe());
    let set = &settings.mutations;
    let mut step: Vec<Node<PathMltState>> = vec![Node::system(path_mutation::ChooseMutations)];
    if set.has(MutationKind::Bidirectional) {
        step.push(Node::system(bidirectional::BidirectionalMutation));
    }
    if set.has(MutationKind::Lens) {
        step.push(Node::system(lens_perturbation::LensPerturbation));
    }
    if specular && set.has(MutationKind::Caustic) {
        step.push(Node::system(caustic_perturbation::CausticPerturbation));
    }
    if specular && set.has(MutationKind::MultiChain) {
        step.push(Node::system(
            multichain_perturbation::MultiChainPerturbation,
        ));
    }
    step.extend([
        Node::system(path_accept::AcceptPathProposals),
        Node::system(path_accept::SplatPathExpectedValues),
        Node::system(path_accept::CommitPathProposals),
    ]);
    let mut nodes = Vec::new();
    if settings.bootstrap.direct.apart() {
        nodes.push(Node::Once {
            name: "direct_illumination",
            needed: |s: &PathMltState| {
                direct_illumination::due(
                    s.settings.bootstrap.direct,
                    s.counts.steps,
                    s.pixels,
                    s.direct.as_ref(),
                )
            },
            body: vec![Node::system(direct_illumination::RenderDirectIllumination)],
        });
    }
    nodes.push(Node::Once {
        name: "bootstrap",
        needed: |s: &PathMltState| !s.seeded,
        body: vec![
            Node::nested(
                Graph::new("mmlt_bootstrap", mlt::bootstrap_nodes()),
                "seeding",
                |s: &mut PathMltState| &mut s.seeding,
                <MltState as IntegratorState>::INPUTS,
            ),
            Node::system(path_seeds::AdoptSeedPaths),
        ],
    });
    nodes.push(Node::Loop {
        name: "mutation_steps",
        queue_len: |s: &PathMltState| s.steps_left as usize,
        body: step,
    });
    Graph::new("mlt", nodes)
}

impl IntegratorState for PathMltState {
    type Settings = PathMltSettings;
    const INPUTS: &'static [&'static str] = &[
        "data",
        "settings",
        "pixels",
        "steps_per_pass",
        "seeding",
        "seeded",
        "seed_mismatches",
        "chains",
        "splat_scale",
        "step",
        "steps_left",
        "counts",
        "splats",
        "splat_sums",
        "nonfinite",
        "direct",
    ];
    fn graph(data: &SceneData, settings: &PathMltSettings) -> Graph<PathMltState> {
        graph(data, settings)
    }
}

impl PassState for PathMltState {
    fn new(data: Arc<SceneData>, settings: PathMltSettings) -> PathMltState {
        let cam = data.scene.camera;
        let pixels = cam.width as u64 * cam.height as u64;
        let seeding = <MltState as PassState>::new(data.clone(), settings.bootstrap);
        let chains = seeding.chains.chains();
        PathMltState {
            steps_per_pass: settings.bootstrap.steps_per_pass(pixels),
            seeding,
            seeded: false,
            seed_mismatches: 0,
            chains: PathChains::new(chains),
            splat_scale: 0.0,
            step: 0,
            steps_left: 0,
            counts: MutationCounts::default(),
            splats: Vec::new(),
            splat_sums: vec![DVec3::ZERO; pixels as usize],
            nonfinite: 0,
            direct: None,
            data,
            settings,
            pixels,
        }
    }

    fn begin_pass(&mut self, _pass: u64) {
        self.steps_left = self.steps_per_pass;
    }

    fn report(&self) -> Vec<(&'static str, String)> {
        let c = &self.counts;
        let total: u64 = c.proposed.iter().sum();
        let accepted: u64 = c.accepted.iter().sum();
        let per_kind: Vec<String> = MutationKind::ALL
            .iter()
            .filter(|&&k| c.proposed[k as usize] > 0)
            .map(|&k| {
                let i = k as usize;
                format!(
                    "{} {:.1}% of {} ({:.1}% zero)",
                    k.name(),
                    100.0 * c.accepted[i] as f64 / c.proposed[i] as f64,
                    c.proposed[i],
                    100.0 * c.zero[i] as f64 / c.proposed[i] as f64
                )
            })
            .collect();
        let mut lines = vec![
            (
                "mutations",
                format!(
                    "{} ({} chains x {} steps), {:.1}% accepted",
                    total,
                    self.chains.chains(),
                    self.step,
                    100.0 * accepted as f64 / total.max(1) as f64
                ),
            ),
            ("acceptance by mutation", per_kind.join(", ")),
        ];
        let mut inner = self.seeding.report_lines();
        inner.retain(|(k, _)| matches!(*k, "bootstrap" | "seeds" | "warning"));
        lines.extend(inner);
        lines.push((
            "seed paths",
            format!("{} not rebuilt", self.seed_mismatches),
        ));
        lines.push((
            "direct illumination",
            direct_illumination::report_line(self.settings.bootstrap.direct, self.direct.as_ref()),
        ));
        lines
    }

    fn finish(self, _passes: u64) -> (Film, usize, usize) {
        let (w, h) = (
            self.data.scene.camera.width as usize,
            self.data.scene.camera.height as usize,
        );
        let scale = if self.step == 0 {
            0.0
        } else {
            self.pixels as f64 / self.step as f64
        };
        // Under the gaussian each pixel is divided by the filter's integral about it: the
        // splats were spread over their footprints (`Film::splat_normalisations`).
        let norm = Film::splat_normalisations(self.data.scene.camera.filter, w, h);
        let mut sums: Vec<DVec3> = self
            .splat_sums
            .iter()
            .zip(&norm)
            .map(|(v, d)| *v * (scale / d))
            .collect();
        let nonfinite =
            self.nonfinite + direct_illumination::add_direct_image(&mut sums, self.direct.as_ref());
        let mut film = Film::from_parts(w, h, sums, vec![1; w * h], Vec::new(), nonfinite)
            .expect("the image's size");
        film.nonfinite = nonfinite;
        let chains = self.chains.chains();
        (film, PathChains::bytes_per_chain(), chains)
    }
}

/// Renders with path-space MLT: `--spp M` is M mutations per pixel (rounded up to whole
/// passes), a time budget ends at a pass boundary.
pub fn render(
    data: Arc<SceneData>,
    settings: PathMltSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    mlt::render_chains::<PathMltState>(data, settings, |s| &mut s.bootstrap, budget, control)
}

/// The systems of its graphs bound to the columns of `PathMltState`.
mod bindings {
    use super::PathMltState;
    use crate::systems::*;

    crate::bind! {
        PathMltState:
        crate::integrators::direct_illumination::RenderDirectIllumination {
            read data, seed = settings.seed, schedule = settings.bootstrap.direct,
                mutations = counts.steps, pixels;
            write direct;
        }
        mutate::bidirectional::BidirectionalMutation {
            read data, settings;
            write chains;
        }
        mutate::caustic_perturbation::CausticPerturbation {
            read data, settings;
            write chains;
        }
        mutate::lens_perturbation::LensPerturbation {
            read data, settings;
            write chains;
        }
        mutate::multichain_perturbation::MultiChainPerturbation {
            read data, settings;
            write chains;
        }
        mutate::path_accept::AcceptPathProposals {
            write chains, counts;
        }
        mutate::path_accept::SplatPathExpectedValues {
            read chains, splat_scale, camera = data.scene.camera;
            write splats, splat_sums, nonfinite;
        }
        mutate::path_accept::CommitPathProposals {
            write chains, step, steps_left;
        }
        mutate::path_mutation::ChooseMutations {
            read data, settings, step;
            write chains;
        }
        mutate::path_seeds::AdoptSeedPaths {
            read data, pixels, selection = seeding.selection, seed = seeding.settings.seed,
                targets = seeding.chains.current_contributions.target,
                capacity = seeding.bdpt.capacity, numbers = seeding.bdpt.sampler,
                wave = seeding.bdpt.wave, subpath_len = seeding.bdpt.subpath_len,
                vertices = seeding.bdpt.vertices, connection_start = seeding.bdpt.connection_start,
                shadow = seeding.bdpt.shadow, connections = seeding.bdpt.connections;
            write chains, splat_scale, seeded, seed_mismatches;
        }
    }
}
