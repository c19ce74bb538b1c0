//! The chains of Veach's MLT: each chain's current path and the step's proposal, stored as
//! path-vertex columns (`PathVertices`, `MAX_VERTICES` slots per chain), with per chain the
//! path's f, pixel and target, the mutation chosen, and the proposal's Hastings ratio
//! T(y -> x) / T(x -> y).

use super::path_space::{MAX_VERTICES, Path, PathSpace};
use crate::components::{PathVertices, PathVerticesChunk, PathVerticesView};
use crate::path::Vertex;
use crate::sampling::SampleKey;
use glam::DVec3;

/// The path-space mutations (Veach and Guibas 1997).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MutationKind {
    Bidirectional = 0,
    Lens = 1,
    Caustic = 2,
    MultiChain = 3,
}

impl MutationKind {
    pub const ALL: [MutationKind; 4] = [
        MutationKind::Bidirectional,
        MutationKind::Lens,
        MutationKind::Caustic,
        MutationKind::MultiChain,
    ];

    pub fn name(self) -> &'static str {
        match self {
            MutationKind::Bidirectional => "bidir",
            MutationKind::Lens => "lens",
            MutationKind::Caustic => "caustic",
            MutationKind::MultiChain => "multichain",
        }
    }

    pub fn parse(s: &str) -> Option<MutationKind> {
        MutationKind::ALL.into_iter().find(|k| k.name() == s)
    }
}

/// Which mutations run and their sizes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MutationSet {
    /// Bit k: `MutationKind` k enabled.
    pub enabled: u8,
    /// Lens perturbation radius in pixels, log-uniform in [lens_min, lens_max].
    pub lens_min: f32,
    pub lens_max: f32,
    /// Caustic and multi-chain perturbation angle in radians, log-uniform in this range.
    pub angle_min: f32,
    pub angle_max: f32,
    /// Fewest and most vertices of a path the chains visit (4 with direct lighting rendered
    /// apart: paths of depth >= 2).
    pub min_vertices: usize,
    pub max_vertices: usize,
}

impl MutationSet {
    /// Veach's sizes: the lens offset between 0.1 px and sqrt(0.05 W H / pi) px, the angle
    /// between 1e-4 and 0.1 radians.
    pub fn new(width: u32, height: u32, lens_min: f32) -> MutationSet {
        MutationSet {
            enabled: 0b1111,
            lens_min,
            lens_max: (0.05 * width as f32 * height as f32 / std::f32::consts::PI)
                .sqrt()
                .max(lens_min),
            angle_min: 1e-4,
            angle_max: 0.1,
            min_vertices: 4,
            max_vertices: MAX_VERTICES,
        }
    }

    pub fn has(&self, k: MutationKind) -> bool {
        self.enabled & (1 << k as u8) != 0
    }
}

/// A proposed path and its Hastings ratio T(y -> x) / T(x -> y).
#[derive(Clone, Debug)]
pub struct Proposal {
    pub path: Path,
    pub ratio: f64,
    /// Density (area measure, discrete choices included) with which the sampler made the new
    /// vertices by the split it drew; tests compare it with the recomputed one.
    pub sampled_density: f64,
    /// The recomputed density of that same split.
    pub recomputed_density: f64,
}

/// The chains' columns.
pub struct PathChains {
    pub current: PathVertices,
    pub current_len: Vec<u8>,
    pub current_f: Vec<DVec3>,
    pub current_pixel: Vec<u32>,
    pub current_target: Vec<f64>,
    pub proposal: PathVertices,
    pub proposal_len: Vec<u8>,
    pub proposal_f: Vec<DVec3>,
    pub proposal_pixel: Vec<u32>,
    pub proposal_target: Vec<f64>,
    /// T(y -> x) / T(x -> y) of the proposal (0 for no proposal).
    pub ratio: Vec<f64>,
    pub kind: Vec<MutationKind>,
    /// Mutations suitable for the current path (the choice's probability is 1 / this).
    pub suitable: Vec<u8>,
    pub step_key: Vec<SampleKey>,
    pub acceptance: Vec<f64>,
    pub accepted: Vec<bool>,
}

impl PathChains {
    pub fn new(chains: usize) -> PathChains {
        PathChains {
            current: PathVertices::new(chains * MAX_VERTICES),
            current_len: vec![0; chains],
            current_f: vec![DVec3::ZERO; chains],
            current_pixel: vec![0; chains],
            current_target: vec![0.0; chains],
            proposal: PathVertices::new(chains * MAX_VERTICES),
            proposal_len: vec![0; chains],
            proposal_f: vec![DVec3::ZERO; chains],
            proposal_pixel: vec![0; chains],
            proposal_target: vec![0.0; chains],
            ratio: vec![0.0; chains],
            kind: vec![MutationKind::Bidirectional; chains],
            suitable: vec![1; chains],
            step_key: vec![SampleKey::default(); chains],
            acceptance: vec![0.0; chains],
            accepted: vec![false; chains],
        }
    }

    pub fn chains(&self) -> usize {
        self.current_len.len()
    }

    /// Bytes per chain.
    pub fn bytes_per_chain() -> usize {
        2 * MAX_VERTICES * PathVertices::bytes_per_item() + 2 * (1 + 24 + 4 + 8) + 8 + 1 + 1 + 8
    }
}

/// Chain `local`'s path (of `len` vertices) from a view of whole chains' columns.
pub fn load_path(store: &PathVerticesView, local: usize, len: usize) -> Path {
    let mut path: Path = (0..len)
        .map(|i| Vertex::from_store(store, local * MAX_VERTICES + i, 1))
        .collect();
    PathSpace::fix_kinds(&mut path);
    path
}

/// Writes `path` as chain `local` of a column chunk.
pub fn store_path(store: &mut PathVerticesChunk, local: usize, path: &[Vertex]) {
    for (i, v) in path.iter().enumerate() {
        store.set(local * MAX_VERTICES + i, v.stored());
    }
}

/// Chunk starts of a `PathVertices` column holding `chains` chains, `CHUNK` chains per chunk.
pub fn chunk_starts(chains: usize) -> Vec<usize> {
    (0..chains)
        .step_by(crate::components::CHUNK)
        .map(|c| c * MAX_VERTICES)
        .collect()
}
