//! Primary-sample mutations: the system `propose_mutations` writes every chain's proposal
//! vector from its current one, the numbers the chain uses and no more.
//!
//! Every number is a pure function of (seed, chain, step, lane) through `SampleKey`, keyed by
//! the CHAIN: chains resampled from one heavy seed start equal but draw different proposals at
//! once (pbrt-v4 keys its generator by the seed's index, so such chains move in lock step and
//! their splats pile up as duplicates).

use super::chains::{ChainStates, VECTOR_BLOCK};
use crate::sampling::{SampleKey, mix64};
use rayon::prelude::*;
use std::f32::consts::TAU;

/// Lane of the large/small choice in a step's key.
pub(crate) const LANE_LARGE_STEP: u32 = 0;
/// Lane of the acceptance number.
pub(crate) const LANE_ACCEPT: u32 = 1;

/// First of the two lanes that mutate dimension `dim`.
#[inline]
fn dimension_lane(dim: u32) -> u32 {
    2 + 2 * dim
}

/// Separates the mutation numbers from every other use of the render's seed (the bootstrap
/// keys its samples with `SampleKey::new(seed, pixel, sample)`).
const MUTATION_DOMAIN: u64 = 0x6d6c_745f_6d75_7461;

/// The key of chain `chain`'s step `step`.
#[inline]
pub fn step_key(seed: u64, chain: usize, step: u64) -> SampleKey {
    SampleKey::new(mix64(seed ^ MUTATION_DOMAIN), chain as u64, step)
}

/// Separates the proposals' tail seeds from every other use of the seed.
const TAIL_DOMAIN: u64 = 0x6d6c_745f_7461_696c;

/// The tail seed of chain `chain`'s proposal at step `step`.
#[inline]
pub fn tail_seed(seed: u64, chain: usize, step: u64) -> u64 {
    SampleKey::new(mix64(seed ^ TAIL_DOMAIN), chain as u64, step).bits()
}

/// How a small step perturbs one number; both are symmetric (T(x -> y) = T(y -> x) on the
/// wrapped unit interval), so acceptance needs no Hastings correction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SmallStep {
    /// Kelemen et al. 2002: |dv| = s2 exp(-ln(s2 / s1) u), log-uniform between s1 and s2, sign
    /// from a second number, wrapped into [0, 1).
    Kelemen { s1: f32, s2: f32 },
    /// pbrt-v4: dv ~ N(0, sigma^2), wrapped into [0, 1).
    WrappedNormal { sigma: f32 },
}

impl SmallStep {
    /// Kelemen's and Mitsuba's bounds: steps between 1/1024 and 1/64.
    pub const KELEMEN: SmallStep = SmallStep::Kelemen {
        s1: 1.0 / 1024.0,
        s2: 1.0 / 64.0,
    };
    /// pbrt-v4's default sigma.
    pub const PBRT_NORMAL: SmallStep = SmallStep::WrappedNormal { sigma: 0.01 };

    /// `x` moved by this step, drawn from the two uniforms `u0`, `u1`.
    #[inline]
    pub fn perturb(self, x: f32, u0: f32, u1: f32) -> f32 {
        PreparedSmallStep::new(self).perturb(x, u0, u1)
    }
}

/// Constants of a small step computed once per column rather than once per number.
#[derive(Clone, Copy)]
enum PreparedSmallStep {
    Kelemen { s2: f32, log_ratio: f32 },
    WrappedNormal { sigma: f32 },
}

impl PreparedSmallStep {
    fn new(step: SmallStep) -> PreparedSmallStep {
        match step {
            SmallStep::Kelemen { s1, s2 } => PreparedSmallStep::Kelemen {
                s2,
                log_ratio: (s2 / s1).ln(),
            },
            SmallStep::WrappedNormal { sigma } => PreparedSmallStep::WrappedNormal { sigma },
        }
    }

    #[inline]
    fn perturb(self, x: f32, u0: f32, u1: f32) -> f32 {
        let moved = match self {
            PreparedSmallStep::Kelemen { s2, log_ratio } => {
                let dv = s2 * (-log_ratio * u0).exp();
                if u1 < 0.5 { x + dv } else { x - dv }
            }
            PreparedSmallStep::WrappedNormal { sigma } => {
                // Box-Muller; 1 - u0 is in (0, 1], so the logarithm is finite.
                let normal = (-2.0 * (1.0 - u0).ln()).sqrt() * (TAU * u1).cos();
                x + sigma * normal
            }
        };
        wrap_unit(moved)
    }
}

/// `x` modulo 1, in [0, 1): a tiny negative x rounds to 1 after adding 1, and goes to 0.
#[inline]
pub fn wrap_unit(x: f32) -> f32 {
    let r = x - x.floor();
    if r < 1.0 { r } else { 0.0 }
}

/// The mutation kernel: with probability `large_step_probability` a large step (every number
/// fresh and uniform: an independence proposal, which keeps the chains ergodic and reaches
/// regions the small steps cannot), else a small step on every dimension.
///
/// Defaults (`PSSMLT`, `MMLT`): each integrator keeps the small step of its reference
/// implementation, so equal-time comparisons with Mitsuba's `pssmlt` and pbrt-v4's `mlt`
/// measure this engine, not a different Markov chain. PSSMLT over full BDPT uses Kelemen's
/// exponential: its step sizes are spread log-uniformly over 1.2 decades (median 1/256), which
/// suits a long vector whose dimensions have very different sensitivities (a pixel coordinate
/// and the fourth bounce's direction) without tuning one scale. MMLT uses pbrt-v4's wrapped
/// normal with sigma = 0.01 (mean |dv| 0.008 against Kelemen's 0.0053): its vectors are short
/// (one strategy at one depth) and pbrt-v4 tuned its sigma and p_large = 0.3 together. Both
/// use p_large = 0.3, as pbrt-v4 and Mitsuba do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MutationSettings {
    pub large_step_probability: f32,
    pub small_step: SmallStep,
}

impl MutationSettings {
    /// Kelemen PSSMLT over full BDPT (Mitsuba's `pssmlt`).
    pub const PSSMLT: MutationSettings = MutationSettings {
        large_step_probability: 0.3,
        small_step: SmallStep::KELEMEN,
    };
    /// Multiplexed MLT (pbrt-v4's `mlt`).
    pub const MMLT: MutationSettings = MutationSettings {
        large_step_probability: 0.3,
        small_step: SmallStep::PBRT_NORMAL,
    };
}

/// System `propose_mutations`: for step `step`, every chain's key, large/small choice and
/// proposal vector (the numbers its evaluation can read: `PrimarySamples::used`). One
/// parallel loop over fixed blocks of `VECTOR_BLOCK` chains, each writing its chains' columns, so
/// bit-identical for any thread count.
pub fn propose_mutations(
    chains: &mut ChainStates,
    settings: &MutationSettings,
    seed: u64,
    step: u64,
) {
    let p_large = settings.large_step_probability;
    let small = PreparedSmallStep::new(settings.small_step);
    // Every proposal's numbers past the stored ones are fresh (see `PrimarySamples`).
    chains
        .proposal
        .tails_mut()
        .par_chunks_mut(VECTOR_BLOCK)
        .enumerate()
        .for_each(|(b, tails)| {
            for (local, tail) in tails.iter_mut().enumerate() {
                *tail = tail_seed(seed, b * VECTOR_BLOCK + local, step);
            }
        });
    let current = &chains.current;
    chains
        .proposal
        .blocks_mut(VECTOR_BLOCK)
        .into_par_iter()
        .zip(chains.step_key.par_chunks_mut(VECTOR_BLOCK))
        .zip(chains.large_step.par_chunks_mut(VECTOR_BLOCK))
        // One block per task: a block's cost is its longest vector, which varies, and
        // rayon's default split (a few pieces per thread) left a core idle at the end.
        .with_max_len(1)
        .for_each(|((block, keys), large)| {
            let first = block.first;
            for (local, (key, large)) in keys.iter_mut().zip(large.iter_mut()).enumerate() {
                *key = step_key(seed, first + local, step);
                *large = key.get(LANE_LARGE_STEP) < p_large;
            }
            for (dim, proposal) in block.columns.into_iter().enumerate() {
                let dim = dim as u32;
                let lane = dimension_lane(dim);
                let current = &current.column(dim)[first..first + proposal.len()];
                for ((((p, &x), key), &large), &used) in proposal
                    .iter_mut()
                    .zip(current)
                    .zip(keys.iter())
                    .zip(large.iter())
                    .zip(block.used)
                {
                    if dim >= used {
                        continue;
                    }
                    let u0 = key.get(lane);
                    *p = if large {
                        u0
                    } else {
                        small.perturb(x, u0, key.get(lane + 1))
                    };
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signed wrapped difference y - x in [-0.5, 0.5).
    fn wrapped_difference(y: f32, x: f32) -> f32 {
        let d = y - x;
        d - (d + 0.5).floor()
    }

    fn proposals(settings: &MutationSettings, chains: usize, dims: u32, step: u64) -> ChainStates {
        let mut states = ChainStates::new(chains, dims, 1, 0);
        for d in 0..dims {
            for i in 0..chains {
                states
                    .current
                    .set(i, d, ((i * 7 + d as usize * 13) % 101) as f32 / 101.0);
            }
        }
        propose_mutations(&mut states, settings, 42, step);
        states
    }

    #[test]
    fn kelemen_steps_lie_between_s1_and_s2_and_are_symmetric() {
        let settings = MutationSettings {
            large_step_probability: 0.0,
            small_step: SmallStep::KELEMEN,
        };
        let s = proposals(&settings, 20_000, 3, 5);
        let (mut sum, mut log_sum, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for d in 0..3 {
            for i in 0..s.chains() {
                let p = s.proposal.get(i, d);
                assert!((0.0..1.0).contains(&p));
                let dv = wrapped_difference(p, s.current.get(i, d));
                let m = dv.abs();
                assert!(
                    (1.0 / 1024.0 * 0.999..=1.0 / 64.0 * 1.001).contains(&m),
                    "{m}"
                );
                sum += dv as f64;
                log_sum += (m as f64).ln();
                n += 1.0;
            }
        }
        // Mean signed step about 0 (symmetric), mean log-magnitude halfway between the bounds.
        assert!((sum / n).abs() < 2e-4, "mean step {}", sum / n);
        let mid = 0.5 * ((1.0f64 / 1024.0).ln() + (1.0f64 / 64.0).ln());
        assert!((log_sum / n - mid).abs() < 0.02, "{} vs {mid}", log_sum / n);
    }

    #[test]
    fn wrapped_normal_steps_have_sigma() {
        let settings = MutationSettings {
            large_step_probability: 0.0,
            small_step: SmallStep::WrappedNormal { sigma: 0.01 },
        };
        let s = proposals(&settings, 50_000, 2, 1);
        let (mut sum, mut sq, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for d in 0..2 {
            for i in 0..s.chains() {
                let p = s.proposal.get(i, d);
                assert!((0.0..1.0).contains(&p));
                let dv = wrapped_difference(p, s.current.get(i, d)) as f64;
                sum += dv;
                sq += dv * dv;
                n += 1.0;
            }
        }
        let sigma = (sq / n - (sum / n).powi(2)).sqrt();
        assert!((sum / n).abs() < 2e-4);
        assert!((sigma - 0.01).abs() < 2e-4, "sigma {sigma}");
    }

    #[test]
    fn large_steps_are_fresh_and_take_their_probability() {
        let settings = MutationSettings::PSSMLT;
        let s = proposals(&settings, 100_000, 1, 3);
        let large = s.large_step.iter().filter(|&&l| l).count() as f64 / 1e5;
        assert!((large - 0.3).abs() < 0.006, "{large}");
        // Large-step proposals are uniform: chi-square over 10 bins (27.9 = 0.1% critical).
        let mut bins = [0u32; 10];
        let mut n = 0;
        for i in 0..s.chains() {
            if s.large_step[i] {
                bins[(s.proposal.get(i, 0) * 10.0) as usize] += 1;
                n += 1;
            }
        }
        let e = n as f64 / 10.0;
        let chi2: f64 = bins.iter().map(|&b| (b as f64 - e).powi(2) / e).sum();
        assert!(chi2 < 27.9, "{chi2}");
    }

    #[test]
    fn proposals_are_keyed_by_chain_and_step() {
        // Two chains at the same state (resampled from one seed) must not propose the same.
        let mut s = ChainStates::new(2, 4, 1, 0);
        for d in 0..4 {
            s.current.set(0, d, 0.25);
            s.current.set(1, d, 0.25);
        }
        let settings = MutationSettings::MMLT;
        propose_mutations(&mut s, &settings, 9, 17);
        let first: Vec<f32> = (0..4).map(|d| s.proposal.get(0, d)).collect();
        let second: Vec<f32> = (0..4).map(|d| s.proposal.get(1, d)).collect();
        assert_ne!(first, second);
        // Pure: the same (seed, chain, step) again gives the same numbers; another step does not.
        propose_mutations(&mut s, &settings, 9, 17);
        assert_eq!(
            first,
            (0..4).map(|d| s.proposal.get(0, d)).collect::<Vec<_>>()
        );
        propose_mutations(&mut s, &settings, 9, 18);
        assert_ne!(
            first,
            (0..4).map(|d| s.proposal.get(0, d)).collect::<Vec<_>>()
        );
    }

    #[test]
    fn wrap_stays_below_one() {
        assert_eq!(wrap_unit(-1e-9), 0.0);
        assert_eq!(wrap_unit(1.0), 0.0);
        assert_eq!(wrap_unit(1.25), 0.25);
        assert_eq!(wrap_unit(-0.25), 0.75);
    }
}
