//! Acceptance with Veach's expected values: the systems `accept_or_reject`,
//! `splat_expected_values` and `commit_accepted`.

use super::chains::{ChainStates, Contributions, MltCounters, VECTOR_BLOCK};
use super::mutate::LANE_ACCEPT;
use crate::components::CHUNK;
use glam::{DVec3, Vec2, Vec3};
use rayon::prelude::*;

/// a = min(1, c_prop / c_cur) for a symmetric proposal. A proposal whose target is zero,
/// negative, NaN or infinite has a = 0 (never accepted); a current state with no positive
/// target (an unseeded chain) accepts any valid proposal.
#[inline]
pub fn acceptance_probability(current: f32, proposal: f32) -> f32 {
    if !(proposal.is_finite() && proposal > 0.0) {
        0.0
    } else if !(current.is_finite() && current > 0.0) {
        1.0
    } else {
        (proposal / current).min(1.0)
    }
}

/// System `accept_or_reject`: per chain a and the decision u < a, u drawn from the step's key
/// (keyed by chain). Writes `acceptance` and `accepted`; the current state is left as it is
/// until `splat_expected_values` has used it. Returns the step's counters.
pub fn accept_or_reject(chains: &mut ChainStates) -> MltCounters {
    let keys = &chains.step_key;
    let large = &chains.large_step;
    let current = &chains.current_contributions.target;
    let proposal = &chains.proposal_contributions.target;
    chains
        .acceptance
        .par_chunks_mut(CHUNK)
        .zip(chains.accepted.par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(c, (acceptance, accepted))| {
            let mut counts = MltCounters::default();
            for (local, (a_out, accepted_out)) in acceptance.iter_mut().zip(accepted).enumerate() {
                let i = c * CHUNK + local;
                let c_prop = proposal[i];
                let a = acceptance_probability(current[i], c_prop);
                let accept = keys[i].get(LANE_ACCEPT) < a;
                *a_out = a;
                *accepted_out = accept;
                counts.steps += 1;
                counts.accepted += accept as u64;
                if large[i] {
                    counts.large_proposed += 1;
                    counts.large_accepted += accept as u64;
                } else {
                    counts.small_proposed += 1;
                    counts.small_accepted += accept as u64;
                }
                if c_prop == 0.0 {
                    counts.rejected_zero += 1;
                } else if !(c_prop.is_finite() && c_prop > 0.0) {
                    counts.rejected_invalid += 1;
                }
            }
            counts
        })
        .reduce(MltCounters::default, |a, b| a + b)
}

/// System `estimate_normalisation`'s sums: per group, the usable targets of this step's large
/// steps and their count (fresh uniform vectors: independent samples of b_k), summed per
/// `CHUNK` of chains in parallel and the chunks in order, so the same bits for any thread
/// count.
pub fn large_step_targets(chains: &ChainStates, groups: usize) -> Vec<(f64, u64)> {
    let target = &chains.proposal_contributions.target;
    let per_chunk: Vec<Vec<(f64, u64)>> = chains
        .large_step
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, large)| {
            let mut sums = vec![(0.0, 0); groups];
            for (local, &l) in large.iter().enumerate() {
                let i = c * CHUNK + local;
                if l {
                    let s = &mut sums[chains.group[i] as usize];
                    s.0 += super::seeds::usable_weight(target[i]);
                    s.1 += 1;
                }
            }
            sums
        })
        .collect();
    let mut total = vec![(0.0, 0); groups];
    for chunk in per_chunk {
        for (t, (sum, count)) in total.iter_mut().zip(chunk) {
            t.0 += sum;
            t.1 += count;
        }
    }
    total
}

/// One weighted contribution for the film's splat sums.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat {
    pub pixel: u32,
    pub value: Vec3,
    /// Where in its pixel it landed (raster position of the rendered image; NaN if not
    /// given): `add_splats_filtered` spreads it from there.
    pub at: Vec2,
}

/// The splats of one step, one list per `CHUNK` of chains; each list in chain order, so
/// reading the lists in chunk order is chain order, and an f64 film sum over them does not
/// depend on the thread count. The lists keep their capacity from step to step.
#[derive(Clone, Debug, Default)]
pub struct ChainSplats {
    chunks: Vec<Vec<Splat>>,
}

impl ChainSplats {
    pub fn new() -> ChainSplats {
        ChainSplats::default()
    }

    /// Adds every finite splat to its pixel's sum (`add_splats`); returns (added, non-finite).
    pub fn add_to(&self, sums: &mut [DVec3]) -> (u64, u64) {
        add_splats(&self.chunks, sums)
    }

    /// `add_to` under the film's filter (`add_splats_filtered`).
    pub fn add_to_filtered(
        &self,
        sums: &mut [DVec3],
        filter: crate::film::PixelFilter,
        size: (usize, usize),
    ) -> (u64, u64) {
        match filter {
            crate::film::PixelFilter::Box => add_splats(&self.chunks, sums),
            crate::film::PixelFilter::Gaussian(g) => {
                add_splats_filtered(&self.chunks, sums, g, size)
            }
        }
    }

    /// Every splat of the step, in chain order.
    pub fn iter(&self) -> impl Iterator<Item = &Splat> + '_ {
        self.chunks.iter().flatten()
    }

    pub fn len(&self) -> usize {
        self.chunks.iter().map(Vec::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.chunks.iter().all(Vec::is_empty)
    }
}

/// Pixels per block when splats are added to the sums in parallel.
const SPLAT_BLOCK: usize = 4096;

/// Adds every finite splat of `chunks` to its pixel's sum in `sums`; returns (added,
/// non-finite). In parallel over blocks of pixels: each chunk's splats are first grouped by
/// block (stably), then each block adds its splats chunk after chunk, so every pixel's f64
/// sum adds the same values in the same order as one loop over the chunks in order would:
/// the same bits for any thread count. (That serial loop was a serial stretch of every MLT
/// step.)
pub fn add_splats(chunks: &[Vec<Splat>], sums: &mut [DVec3]) -> (u64, u64) {
    let blocks = sums.len().div_ceil(SPLAT_BLOCK);
    let grouped: Vec<(Vec<Splat>, Vec<usize>)> = chunks
        .par_iter()
        .with_max_len(1)
        .map(|splats| {
            let mut starts = vec![0; blocks + 1];
            for s in splats {
                starts[s.pixel as usize / SPLAT_BLOCK + 1] += 1;
            }
            for b in 0..blocks {
                starts[b + 1] += starts[b];
            }
            let mut at = starts.clone();
            let mut grouped = vec![
                Splat {
                    pixel: 0,
                    value: Vec3::ZERO,
                    at: Vec2::NAN,
                };
                splats.len()
            ];
            for s in splats {
                let b = s.pixel as usize / SPLAT_BLOCK;
                grouped[at[b]] = *s;
                at[b] += 1;
            }
            (grouped, starts)
        })
        .collect();
    sums.par_chunks_mut(SPLAT_BLOCK)
        .with_max_len(1)
        .enumerate()
        .map(|(b, sums)| {
            let (mut added, mut nonfinite) = (0, 0);
            for (splats, starts) in &grouped {
                for s in &splats[starts[b]..starts[b + 1]] {
                    if s.value.is_finite() {
                        sums[s.pixel as usize - b * SPLAT_BLOCK] += s.value.as_dvec3();
                        added += 1;
                    } else {
                        nonfinite += 1;
                    }
                }
            }
            (added, nonfinite)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// `add_splats` under the gaussian: each splat reaches every pixel of its image (a group's
/// `width x height` slots, the image its slot lies in) whose centre lies within the radius of
/// where it landed, weighted by the filter there (the image is divided by the filter's
/// film-clipped integral about each pixel afterwards: `PixelFilter::splat_normalisation`).
/// In parallel over blocks of pixels; a block takes, chunk after chunk, the splats of every
/// block whose footprints reach it, in the order one loop over the chunks would add them,
/// so each pixel's f64 sum has the same bits for any thread count. A non-finite splat (or one
/// without a position) is counted once, in its own pixel's block, and added nowhere.
pub fn add_splats_filtered(
    chunks: &[Vec<Splat>],
    sums: &mut [DVec3],
    gaussian: crate::film::Gaussian,
    (width, height): (usize, usize),
) -> (u64, u64) {
    let pixels = width * height;
    if pixels == 0 {
        return (0, 0);
    }
    let blocks = sums.len().div_ceil(SPLAT_BLOCK);
    let span = gaussian.reach() * (width + 1);
    let grouped: Vec<(Vec<Splat>, Vec<usize>)> = chunks
        .par_iter()
        .with_max_len(1)
        .map(|splats| {
            let mut grouped = splats.clone();
            // Stable: each block's splats stay in chain order.
            grouped.sort_by_key(|s| s.pixel as usize / SPLAT_BLOCK);
            let mut starts = vec![0; blocks + 1];
            for s in splats {
                starts[s.pixel as usize / SPLAT_BLOCK + 1] += 1;
            }
            for b in 0..blocks {
                starts[b + 1] += starts[b];
            }
            (grouped, starts)
        })
        .collect();
    sums.par_chunks_mut(SPLAT_BLOCK)
        .with_max_len(1)
        .enumerate()
        .map(|(b, sums)| {
            let (mut added, mut nonfinite) = (0, 0);
            let (first, end) = (b * SPLAT_BLOCK, b * SPLAT_BLOCK + sums.len());
            let from = first.saturating_sub(span) / SPLAT_BLOCK;
            let to = ((end + span) / SPLAT_BLOCK + 1).min(blocks);
            for (splats, starts) in &grouped {
                for s in &splats[starts[from]..starts[to]] {
                    let own = (first..end).contains(&(s.pixel as usize));
                    if !s.value.is_finite() || !s.at.is_finite() {
                        nonfinite += own as u64;
                        continue;
                    }
                    added += own as u64;
                    let base = s.pixel as usize / pixels * pixels;
                    let value = s.value.as_dvec3();
                    let xs = gaussian.footprint(s.at.x, width);
                    for y in gaussian.footprint(s.at.y, height) {
                        let row = base + y * width;
                        if row + xs.end <= first || row + xs.start >= end {
                            continue;
                        }
                        let wy = gaussian.eval(y as f32 + 0.5 - s.at.y);
                        for x in xs.clone() {
                            let q = row + x;
                            if (first..end).contains(&q) {
                                let w = gaussian.eval(x as f32 + 0.5 - s.at.x) * wy;
                                sums[q - first] += value * w as f64;
                            }
                        }
                    }
                }
            }
            (added, nonfinite)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// System `splat_expected_values`: per chain, the proposal's contributions with weight
/// a / c_prop and the current state's with (1 - a) / c_cur, both times the chain's
/// `splat_scale` (Veach's expected values: every step deposits `splat_scale` units of target
/// whatever it decides, and rejected proposals still count). Zero weights emit nothing.
/// A splat of a chain of group g goes to film slot `g x group_stride + pixel` (one film per
/// group, so each can be scaled by its own b_k at the end; `group_stride` 0: one film).
/// Replaces `splats`' lists; per chain the proposal's splats come first.
pub fn splat_expected_values(chains: &ChainStates, splats: &mut ChainSplats, group_stride: u32) {
    let n_chunks = chains.chains().div_ceil(CHUNK);
    splats.chunks.resize_with(n_chunks, Vec::new);
    let (current, proposal) = (
        &chains.current_contributions,
        &chains.proposal_contributions,
    );
    let (acceptance, scale) = (&chains.acceptance, &chains.splat_scale);
    splats
        .chunks
        .par_iter_mut()
        .enumerate()
        .for_each(|(c, out)| {
            out.clear();
            let end = ((c + 1) * CHUNK).min(chains.chains());
            for i in c * CHUNK..end {
                let offset = chains.group[i] * group_stride;
                let a = acceptance[i];
                if a > 0.0 {
                    emit(out, proposal, i, offset, scale[i] * a / proposal.target[i]);
                }
                let c_cur = current.target[i];
                if a < 1.0 && c_cur.is_finite() && c_cur > 0.0 {
                    emit(out, current, i, offset, scale[i] * (1.0 - a) / c_cur);
                }
            }
        });
}

/// The strategy images' sums of one step (mmlt, `--strategy-images`): the same expected-value
/// weights as `splat_expected_values`, each state's splats added to the sums of its strategy,
/// keyed (group, depth, s), in units of the group's b_k (`splat_scale` included). Serial, in
/// chain order, so the sums do not depend on the thread count; a diagnostic, not the hot path.
pub fn splat_strategies(
    chains: &ChainStates,
    sums: &mut std::collections::BTreeMap<(u32, u32, u16), Vec<DVec3>>,
    pixels: usize,
) {
    let (current, proposal) = (
        &chains.current_contributions,
        &chains.proposal_contributions,
    );
    let mut add = |state: &Contributions, i: usize, weight: f32| {
        let (depth, s) = state.strategy[i];
        let image = sums
            .entry((chains.group[i], depth, s))
            .or_insert_with(|| vec![DVec3::ZERO; pixels]);
        for (pixel, value) in state.entries(i) {
            let v = value * weight;
            if v.is_finite() && (pixel as usize) < pixels {
                image[pixel as usize] += v.as_dvec3();
            }
        }
    };
    for i in 0..chains.chains() {
        let (a, scale) = (chains.acceptance[i], chains.splat_scale[i]);
        if a > 0.0 {
            add(proposal, i, scale * a / proposal.target[i]);
        }
        let c_cur = current.target[i];
        if a < 1.0 && c_cur.is_finite() && c_cur > 0.0 {
            add(current, i, scale * (1.0 - a) / c_cur);
        }
    }
}

#[inline]
fn emit(out: &mut Vec<Splat>, state: &Contributions, chain: usize, offset: u32, weight: f32) {
    for (pixel, at, value) in state.entries_at(chain) {
        if value != Vec3::ZERO {
            out.push(Splat {
                pixel: offset + pixel,
                value: value * weight,
                at,
            });
        }
    }
}

/// System `commit_accepted`: accepted chains take their proposal (vector and contributions)
/// as their current state: the numbers each uses, in parallel over fixed chunks of chains.
pub fn commit_accepted(chains: &mut ChainStates) {
    let accepted = &chains.accepted;
    let proposal = &chains.proposal;
    chains
        .current
        .blocks_mut(VECTOR_BLOCK)
        .into_par_iter()
        // One block per task: a block's cost is its longest vector, which varies, and
        // rayon's default split (a few pieces per thread) left a core idle at the end.
        .with_max_len(1)
        .for_each(|block| {
            let first = block.first;
            for (dim, current) in block.columns.into_iter().enumerate() {
                let dim = dim as u32;
                let proposed = &proposal.column(dim)[first..first + current.len()];
                for (local, (x, &p)) in current.iter_mut().zip(proposed).enumerate() {
                    if accepted[first + local] && dim < block.used[local] {
                        *x = p;
                    }
                }
            }
        });
    for ((tail, &proposed), &accepted) in chains
        .current
        .tails_mut()
        .iter_mut()
        .zip(chains.proposal.tails())
        .zip(accepted)
    {
        if accepted {
            *tail = proposed;
        }
    }
    let proposal = &chains.proposal_contributions;
    chains
        .current_contributions
        .ensure_stride(proposal.stride());
    let stride = proposal.stride();
    chains
        .current_contributions
        .par_chunks_mut()
        .with_max_len(1)
        .for_each(|chunk| {
            for local in 0..chunk.len() {
                let i = chunk.first_chain + local;
                if !accepted[i] {
                    continue;
                }
                let n = proposal.count[i] as usize;
                let (from, to) = (i * stride, local * stride);
                chunk.pixel[to..to + n].copy_from_slice(&proposal.pixel[from..from + n]);
                chunk.raster[to..to + n].copy_from_slice(&proposal.raster[from..from + n]);
                chunk.value[to..to + n].copy_from_slice(&proposal.value[from..from + n]);
                chunk.count[local] = n as u32;
                chunk.target[local] = proposal.target[i];
                chunk.strategy[local] = proposal.strategy[i];
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlt::mutate::{MutationSettings, propose_mutations};

    #[test]
    fn zero_and_non_finite_proposals_are_never_accepted_and_are_counted() {
        let bad = [0.0, -1.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
        let chains = 4000;
        let mut s = ChainStates::new(chains, 2, 1, 0);
        for i in 0..chains {
            s.current_contributions.set_single(i, 7, Vec3::splat(2.0));
            let t = bad[i % bad.len()];
            s.proposal_contributions.set_single(i, 9, Vec3::splat(t));
            s.proposal_contributions.target[i] = t;
        }
        propose_mutations(&mut s, &MutationSettings::PSSMLT, 1, 0);
        let counts = accept_or_reject(&mut s);
        assert_eq!(counts.steps, chains as u64);
        assert_eq!(counts.accepted, 0);
        assert_eq!(counts.rejected_zero, (chains / bad.len()) as u64);
        assert_eq!(
            counts.rejected_invalid,
            (chains - chains / bad.len()) as u64
        );
        assert!(s.acceptance.iter().all(|&a| a == 0.0));
        // Only the current states are splatted, each with its whole unit of target.
        let mut splats = ChainSplats::new();
        splat_expected_values(&s, &mut splats, 0);
        assert_eq!(splats.len(), chains);
        assert!(splats.iter().all(|s| s.pixel == 7));
        let before = s.current_contributions.target.clone();
        commit_accepted(&mut s);
        assert_eq!(s.current_contributions.target, before);
    }

    /// The splats added by pixel blocks in parallel give every pixel the bits one serial
    /// loop over the chunks in order gives (f64 sums depend on the order of their terms).
    #[test]
    fn splats_add_as_one_serial_loop_would_bit_for_bit() {
        let pixels = 3 * SPLAT_BLOCK + 77;
        let chunks: Vec<Vec<Splat>> = (0..9u64)
            .map(|c| {
                (0..1500u64)
                    .map(|j| {
                        let h = crate::sampling::mix64(c * 7919 + j);
                        // Few pixels, so each gets many terms of very different sizes.
                        let pixel = (h % 61) as u32 * 211 % pixels as u32;
                        let size = 10f32.powi((h >> 20) as i32 % 13 - 6);
                        let value = if h.is_multiple_of(97) {
                            Vec3::splat(f32::NAN)
                        } else {
                            Vec3::new(size, size * 0.3, (h >> 40) as f32 * 1e-9)
                        };
                        Splat {
                            pixel,
                            value,
                            at: Vec2::NAN,
                        }
                    })
                    .collect()
            })
            .collect();
        let mut serial = vec![DVec3::ZERO; pixels];
        let (mut added, mut nonfinite) = (0, 0);
        for s in chunks.iter().flatten() {
            if s.value.is_finite() {
                serial[s.pixel as usize] += s.value.as_dvec3();
                added += 1;
            } else {
                nonfinite += 1;
            }
        }
        let mut parallel = vec![DVec3::ZERO; pixels];
        assert_eq!(add_splats(&chunks, &mut parallel), (added, nonfinite));
        assert!(nonfinite > 0);
        for (p, s) in parallel.iter().zip(&serial) {
            assert_eq!(
                p.to_array().map(f64::to_bits),
                s.to_array().map(f64::to_bits)
            );
        }
    }

    #[test]
    fn acceptance_follows_the_ratio_and_an_empty_current_state_accepts() {
        assert_eq!(acceptance_probability(2.0, 1.0), 0.5);
        assert_eq!(acceptance_probability(1.0, 3.0), 1.0);
        assert_eq!(acceptance_probability(0.0, 3.0), 1.0);
        assert_eq!(acceptance_probability(0.0, 0.0), 0.0);
        assert_eq!(acceptance_probability(f32::NAN, 1.0), 1.0);
        assert_eq!(acceptance_probability(1e-30, f32::MAX), 1.0);
    }
}
