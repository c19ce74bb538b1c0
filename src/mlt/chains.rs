//! Chain state as structure of arrays: one `Vec` (or dimension-major store) per field, indexed
//! by chain (= wavefront slot), sized once and reused every step.

use crate::components::CHUNK;
use crate::math::luminance;
use crate::sampling::{PrimarySamples, SampleKey};
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Chains per task of the loops over primary-sample vectors (`propose_mutations`,
/// `commit_accepted`): a block's loops run to its longest vector, so small blocks skip most
/// of the dimensions that only a block's one deep chain uses, and many tasks balance the two
/// cores. Any size gives the same numbers: each chain's are its own.
pub const VECTOR_BLOCK: usize = 128;

/// What one evaluation of a primary-sample vector produced, per chain: the target value `c`
/// (the luminance the chain samples in proportion to) and up to `stride` image contributions
/// (pixel, RGB). MMLT evaluates one strategy, so one contribution; PSSMLT over full BDPT may
/// land in several pixels (light tracing), so `stride` is the most connections one sample makes.
/// Contributions of chain `i` live in `i * stride .. i * stride + count[i]`.
#[derive(Clone, Debug, Default)]
pub struct Contributions {
    stride: usize,
    /// The target function `c` per chain: what acceptance compares and splats divide by.
    /// Normally the luminance of the sum of the chain's contributions.
    pub target: Vec<f32>,
    /// Contributions in use per chain.
    pub count: Vec<u32>,
    pub pixel: Vec<u32>,
    /// Where in its pixel each contribution landed (raster position of the rendered image),
    /// for a filter wider than a pixel; NaN where none was given (box filter only).
    pub raster: Vec<Vec2>,
    pub value: Vec<Vec3>,
    /// The strategy of each chain's evaluation, (depth, s), in mmlt (one strategy per
    /// evaluation); (0, 0) in pssmlt. Only the strategy images read it.
    pub strategy: Vec<(u32, u16)>,
}

/// A mutable view of the contributions of one chunk of chains, for an evaluation system that
/// writes its chunks in parallel. Indices are local to the chunk.
pub struct ContributionsChunk<'a> {
    /// Chain of the chunk's first item.
    pub first_chain: usize,
    stride: usize,
    pub target: &'a mut [f32],
    pub count: &'a mut [u32],
    pub pixel: &'a mut [u32],
    pub raster: &'a mut [Vec2],
    pub value: &'a mut [Vec3],
    pub strategy: &'a mut [(u32, u16)],
}

impl Contributions {
    /// Room for `chains` chains of at most `stride` contributions each, all empty (target 0).
    pub fn new(chains: usize, stride: usize) -> Contributions {
        assert!(stride > 0, "Contributions: stride must be at least 1");
        Contributions {
            stride,
            target: vec![0.0; chains],
            count: vec![0; chains],
            pixel: vec![0; chains * stride],
            raster: vec![Vec2::NAN; chains * stride],
            value: vec![Vec3::ZERO; chains * stride],
            strategy: vec![(0, 0); chains],
        }
    }

    pub fn chains(&self) -> usize {
        self.target.len()
    }

    /// Keeps the first `chains` chains (an evaluation wave may hold more than the chains).
    pub fn truncate(&mut self, chains: usize) {
        self.target.truncate(chains);
        self.count.truncate(chains);
        self.pixel.truncate(chains * self.stride);
        self.raster.truncate(chains * self.stride);
        self.value.truncate(chains * self.stride);
        self.strategy.truncate(chains);
    }

    pub fn stride(&self) -> usize {
        self.stride
    }

    /// Makes room for at least `stride` contributions per chain, keeping every chain's
    /// entries (a full BDPT sample lands in one pixel per light vertex, and subpaths have no
    /// length cap: the rare deep sample widens the columns once).
    pub fn ensure_stride(&mut self, stride: usize) {
        if stride <= self.stride {
            return;
        }
        let chains = self.chains();
        let mut pixel = vec![0; chains * stride];
        let mut raster = vec![Vec2::NAN; chains * stride];
        let mut value = vec![Vec3::ZERO; chains * stride];
        for i in 0..chains {
            let n = self.count[i] as usize;
            let (from, to) = (i * self.stride, i * stride);
            pixel[to..to + n].copy_from_slice(&self.pixel[from..from + n]);
            raster[to..to + n].copy_from_slice(&self.raster[from..from + n]);
            value[to..to + n].copy_from_slice(&self.value[from..from + n]);
        }
        self.stride = stride;
        self.pixel = pixel;
        self.raster = raster;
        self.value = value;
    }

    /// Chain `chain` contributed nothing (target 0).
    pub fn clear(&mut self, chain: usize) {
        self.target[chain] = 0.0;
        self.count[chain] = 0;
    }

    /// Appends one contribution to `chain` (its target is left to the caller). Panics past
    /// `stride` contributions.
    pub fn push(&mut self, chain: usize, pixel: u32, value: Vec3) {
        let range = chain * self.stride..(chain + 1) * self.stride;
        push_entry(
            self.stride,
            &mut self.count[chain],
            (
                &mut self.pixel[range.clone()],
                &mut self.raster[range.clone()],
            ),
            &mut self.value[range],
            (pixel, Vec2::NAN),
            value,
        );
    }

    /// One contribution, and the target set to its luminance (the MMLT case).
    pub fn set_single(&mut self, chain: usize, pixel: u32, value: Vec3) {
        self.count[chain] = 0;
        self.push(chain, pixel, value);
        self.target[chain] = luminance(value);
    }

    /// The contributions of `chain`, in the order they were pushed.
    pub fn entries(&self, chain: usize) -> impl Iterator<Item = (u32, Vec3)> + '_ {
        self.entries_at(chain).map(|(p, _, v)| (p, v))
    }

    /// `entries` with where each landed (NaN where not given).
    pub fn entries_at(&self, chain: usize) -> impl Iterator<Item = (u32, Vec2, Vec3)> + '_ {
        let start = chain * self.stride;
        let end = start + self.count[chain] as usize;
        (start..end).map(|i| (self.pixel[i], self.raster[i], self.value[i]))
    }

    /// Views of the chains in `CHUNK`-sized pieces, in parallel.
    pub fn par_chunks_mut(
        &mut self,
    ) -> impl IndexedParallelIterator<Item = ContributionsChunk<'_>> + '_ {
        let stride = self.stride;
        self.target
            .par_chunks_mut(CHUNK)
            .zip(self.count.par_chunks_mut(CHUNK))
            .zip(self.pixel.par_chunks_mut(CHUNK * stride))
            .zip(self.raster.par_chunks_mut(CHUNK * stride))
            .zip(self.value.par_chunks_mut(CHUNK * stride))
            .zip(self.strategy.par_chunks_mut(CHUNK))
            .enumerate()
            .map(
                move |(c, (((((target, count), pixel), raster), value), strategy))| {
                    ContributionsChunk {
                        first_chain: c * CHUNK,
                        stride,
                        target,
                        count,
                        pixel,
                        raster,
                        value,
                        strategy,
                    }
                },
            )
    }
}

impl ContributionsChunk<'_> {
    pub fn len(&self) -> usize {
        self.target.len()
    }

    pub fn is_empty(&self) -> bool {
        self.target.is_empty()
    }

    pub fn clear(&mut self, local: usize) {
        self.target[local] = 0.0;
        self.count[local] = 0;
    }

    pub fn push(&mut self, local: usize, pixel: u32, value: Vec3) {
        self.push_at(local, pixel, Vec2::NAN, value);
    }

    /// `push` of a contribution that landed at raster position `at` in `pixel`.
    pub fn push_at(&mut self, local: usize, pixel: u32, at: Vec2, value: Vec3) {
        let range = local * self.stride..(local + 1) * self.stride;
        push_entry(
            self.stride,
            &mut self.count[local],
            (
                &mut self.pixel[range.clone()],
                &mut self.raster[range.clone()],
            ),
            &mut self.value[range],
            (pixel, at),
            value,
        );
    }

    pub fn set_single(&mut self, local: usize, pixel: u32, value: Vec3) {
        self.count[local] = 0;
        self.push(local, pixel, value);
        self.target[local] = luminance(value);
    }
}

#[inline]
fn push_entry(
    stride: usize,
    count: &mut u32,
    (pixels, rasters): (&mut [u32], &mut [Vec2]),
    values: &mut [Vec3],
    (pixel, raster): (u32, Vec2),
    value: Vec3,
) {
    let at = *count as usize;
    assert!(at < stride, "Contributions: more than {stride} per chain");
    pixels[at] = pixel;
    rasters[at] = raster;
    values[at] = value;
    *count += 1;
}

/// Every chain's state, one chain per wavefront slot.
///
/// The step's systems touch these columns in order: `propose_mutations` writes `step_key`,
/// `large_step` and `proposal`; the evaluation writes `proposal_contributions`;
/// `accept_or_reject` writes `acceptance` and `accepted`; `splat_expected_values` reads both
/// states; `commit_accepted` copies accepted proposals into the current state.
#[derive(Clone, Debug)]
pub struct ChainStates {
    /// Current primary-sample vectors (dimension-major).
    pub current: PrimarySamples,
    /// Proposed vectors of the step under way: every number a chain uses is rewritten each
    /// step, so a rejection needs no restore.
    pub proposal: PrimarySamples,
    pub current_contributions: Contributions,
    pub proposal_contributions: Contributions,
    /// The seed group of each chain: the path depth k in MMLT, 0 in PSSMLT. The evaluation
    /// reads it (MMLT evaluates paths of exactly this depth); set by `SeedSelection::apply`.
    pub group: Vec<u32>,
    /// Factor on every splat of the chain: b_k / (chains of group k), so that the film's splat
    /// sums, times the pixel count, divided by the steps per chain, are the image, whatever
    /// the rounding of chains per group. Set by `SeedSelection::apply` (1 until then).
    pub splat_scale: Vec<f32>,
    /// The (seed, chain, step) key of the step under way; `accept_or_reject` draws from it.
    pub step_key: Vec<SampleKey>,
    /// Whether the step under way is a large step (fresh uniforms).
    pub large_step: Vec<bool>,
    /// Acceptance probability a of the step under way.
    pub acceptance: Vec<f32>,
    pub accepted: Vec<bool>,
}

impl ChainStates {
    /// `chains` chains of `dims`-dimensional primary-sample vectors, each evaluation making
    /// at most `contributions_per_chain` contributions, evaluated in waves of up to
    /// `wave` (at least `chains`) evaluations (the bootstrap's).
    pub fn new(
        chains: usize,
        dims: u32,
        contributions_per_chain: usize,
        wave: usize,
    ) -> ChainStates {
        ChainStates {
            current: PrimarySamples::new(chains, dims),
            proposal: PrimarySamples::new(chains, dims),
            current_contributions: Contributions::new(chains, contributions_per_chain),
            proposal_contributions: Contributions::new(wave.max(chains), contributions_per_chain),
            group: vec![0; chains],
            splat_scale: vec![1.0; chains],
            step_key: vec![SampleKey::default(); chains],
            large_step: vec![false; chains],
            acceptance: vec![0.0; chains],
            accepted: vec![false; chains],
        }
    }

    pub fn chains(&self) -> usize {
        self.group.len()
    }

    pub fn dims(&self) -> u32 {
        self.current.dims()
    }
}

/// Counts of what the steps did. Sums of per-chunk integer counts, so thread-independent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MltCounters {
    /// Chain steps taken (chains x steps).
    pub steps: u64,
    pub accepted: u64,
    pub large_proposed: u64,
    pub large_accepted: u64,
    pub small_proposed: u64,
    pub small_accepted: u64,
    /// Proposals with target exactly 0 (a path that found no light): common, harmless.
    pub rejected_zero: u64,
    /// Proposals with a negative, NaN or infinite target: a bug upstream, never accepted.
    pub rejected_invalid: u64,
}

impl MltCounters {
    pub fn acceptance_rate(&self) -> f64 {
        self.accepted as f64 / self.steps.max(1) as f64
    }
}

impl std::ops::AddAssign for MltCounters {
    fn add_assign(&mut self, o: MltCounters) {
        self.steps += o.steps;
        self.accepted += o.accepted;
        self.large_proposed += o.large_proposed;
        self.large_accepted += o.large_accepted;
        self.small_proposed += o.small_proposed;
        self.small_accepted += o.small_accepted;
        self.rejected_zero += o.rejected_zero;
        self.rejected_invalid += o.rejected_invalid;
    }
}

impl std::ops::Add for MltCounters {
    type Output = MltCounters;
    fn add(mut self, o: MltCounters) -> MltCounters {
        self += o;
        self
    }
}
