//! The chains of Veach's MLT: each chain's current path and the step's proposal, stored as
//! path-vertex columns (`PathVertices`, `INLINE_VERTICES` slots per chain) and, for a path
//! longer than that, the rest in the chain's own overflow list; with per chain the path's f,
//! pixel and target, the mutation chosen, and the proposal's Hastings ratio T(y -> x) / T(x -> y).
//!
//! Paths have no length bound but the user's `--max-depth`: most are short and live in the
//! columns alone (no allocation per step), and the rare long one (a box of mirrors, light
//! trapped in glass) spills its vertices past `INLINE_VERTICES` into `current_overflow` /
//! `proposal_overflow`, which are chain-indexed like every other column, so the chunks of
//! chains the systems work on in parallel own their overflow too.

use super::path_space::{Landing, Path, PathSpace};
use crate::components::{PathVertex, PathVertices, PathVerticesChunk, PathVerticesView};
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
    /// apart: paths of depth >= 2); `usize::MAX` most: no bound (the default; `--max-depth D`
    /// makes it D + 2).
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
            max_vertices: usize::MAX,
        }
    }

    pub fn has(&self, k: MutationKind) -> bool {
        self.enabled & (1 << k as u8) != 0
    }

    /// The most vertices for a depth cap (`u32::MAX`: none).
    pub fn max_vertices_for_depth(max_depth: u32) -> usize {
        if max_depth == u32::MAX {
            usize::MAX
        } else {
            max_depth as usize + 2
        }
    }
}

/// Vertices of a chain's path kept in the path-vertex columns (slots per chain); a longer
/// path keeps its vertices from this one on in the chain's overflow list.
pub const INLINE_VERTICES: usize = 16;

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
    /// Vertices 0..`INLINE_VERTICES` of each chain's path (slots `chain x INLINE_VERTICES..`).
    pub current: PathVertices,
    /// Per chain its path's vertices from `INLINE_VERTICES` on (empty for a shorter path).
    pub current_overflow: Vec<Vec<PathVertex>>,
    /// Vertices per path (any number).
    pub current_len: Vec<u32>,
    pub current_f: Vec<DVec3>,
    /// Where the current path lands on the film.
    pub current_landing: Vec<Landing>,
    pub current_target: Vec<f64>,
    pub proposal: PathVertices,
    pub proposal_overflow: Vec<Vec<PathVertex>>,
    pub proposal_len: Vec<u32>,
    pub proposal_f: Vec<DVec3>,
    pub proposal_landing: Vec<Landing>,
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
            current: PathVertices::new(chains * INLINE_VERTICES),
            current_overflow: vec![Vec::new(); chains],
            current_len: vec![0; chains],
            current_f: vec![DVec3::ZERO; chains],
            current_landing: vec![Landing::default(); chains],
            current_target: vec![0.0; chains],
            proposal: PathVertices::new(chains * INLINE_VERTICES),
            proposal_overflow: vec![Vec::new(); chains],
            proposal_len: vec![0; chains],
            proposal_f: vec![DVec3::ZERO; chains],
            proposal_landing: vec![Landing::default(); chains],
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

    /// Bytes per chain (the overflow lists' vertices not counted: most chains have none).
    pub fn bytes_per_chain() -> usize {
        2 * INLINE_VERTICES * PathVertices::bytes_per_item()
            + 2 * (std::mem::size_of::<Vec<PathVertex>>() + 4 + 24 + 12 + 8)
            + 8
            + 1
            + 1
            + 8
    }

    /// Chain `chain`'s current path.
    pub fn current_path(&self, chain: usize) -> Path {
        let store = self.current.view(0..self.chains() * INLINE_VERTICES);
        load_path(
            &store,
            &self.current_overflow[chain],
            chain,
            self.current_len[chain] as usize,
        )
    }

    /// Makes `path` chain `chain`'s current path (its f, pixel and target left as they are).
    pub fn set_current_path(&mut self, chain: usize, path: &[Vertex]) {
        let mut stores = self
            .current
            .split_mut(&[chain * INLINE_VERTICES], (chain + 1) * INLINE_VERTICES);
        store_path(&mut stores[0], &mut self.current_overflow[chain], 0, path);
        self.current_len[chain] = path_len(path.len());
    }
}

/// A path's vertex count as the length columns hold it.
#[inline]
pub fn path_len(n: usize) -> u32 {
    u32::try_from(n).expect("a path of fewer than 2^32 vertices")
}

/// Chain `local`'s path (of `len` vertices) from a view of whole chains' columns and the
/// chain's overflow list.
pub fn load_path(
    store: &PathVerticesView,
    overflow: &[PathVertex],
    local: usize,
    len: usize,
) -> Path {
    let inline = len.min(INLINE_VERTICES);
    let mut path: Path = Vec::with_capacity(len);
    path.extend((0..inline).map(|i| Vertex::from_store(store, local * INLINE_VERTICES + i, 1)));
    if len > INLINE_VERTICES {
        let rest = PathVerticesView {
            items: &overflow[..len - INLINE_VERTICES],
        };
        path.extend((0..len - INLINE_VERTICES).map(|i| Vertex::from_store(&rest, i, 1)));
    }
    PathSpace::fix_kinds(&mut path);
    path
}

/// Writes `path` as chain `local` of a column chunk, its vertices past `INLINE_VERTICES` into
/// the chain's overflow list (emptied first, its allocation kept).
pub fn store_path(
    store: &mut PathVerticesChunk,
    overflow: &mut Vec<PathVertex>,
    local: usize,
    path: &[Vertex],
) {
    let (inline, rest) = path.split_at(path.len().min(INLINE_VERTICES));
    for (i, v) in inline.iter().enumerate() {
        store.set(local * INLINE_VERTICES + i, v.stored());
    }
    overflow.clear();
    overflow.extend(rest.iter().map(Vertex::stored));
}

/// Copies chain `local`'s path of `len` vertices from one store (columns and overflow) to
/// another.
pub fn copy_path(
    from: &PathVerticesChunk,
    from_overflow: &[PathVertex],
    to: &mut PathVerticesChunk,
    to_overflow: &mut Vec<PathVertex>,
    local: usize,
    len: usize,
) {
    let first = local * INLINE_VERTICES;
    for v in first..first + len.min(INLINE_VERTICES) {
        to.set(v, from.get(v));
    }
    to_overflow.clear();
    if len > INLINE_VERTICES {
        to_overflow.extend_from_slice(&from_overflow[..len - INLINE_VERTICES]);
    }
}

/// Chunk starts of a `PathVertices` column holding `chains` chains, `CHUNK` chains per chunk.
pub fn chunk_starts(chains: usize) -> Vec<usize> {
    (0..chains)
        .step_by(crate::components::CHUNK)
        .map(|c| c * INLINE_VERTICES)
        .collect()
}
