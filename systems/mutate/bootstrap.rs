//! The bootstrap and the chains' seeds.
//!
//! - `begin_bootstrap_wave`: the next wave of bootstrap evaluations, each a fresh
//!   primary-sample vector (a pure function of seed and evaluation index), evaluated by the
//!   BDPT systems as a full BDPT sample (in mmlt too: issue 42, see `collect_bootstrap_weights`).
//! - `collect_bootstrap_weights`: each evaluation's weight in every group (pssmlt: its target;
//!   mmlt: the luminance of its connections of the group's depth, MIS-weighted); ends the
//!   bootstrap by the size rule: at least `BOOTSTRAP_PER_CHAIN` evaluations per chain,
//!   `MIN_BOOTSTRAP_SAMPLES` and one per `MUTATIONS_PER_BOOTSTRAP_EVALUATION`
//!   mutations, then until b's relative error is below half the
//!   image's expected noise at M mutations per pixel (`crate::mlt::needs_more_bootstrap`; M =
//!   --spp, or `TIMED_MUTATIONS_PER_PIXEL` under --time), but never more evaluations than
//!   the M x pixels mutations asked for nor `MAX_BOOTSTRAP_EVALUATIONS`; under a time budget
//!   it also ends once it has taken `BOOTSTRAP_TIME_SHARE` of the budget and found some
//!   light; `--bootstrap N` sets N evaluations instead. Why full samples in mmlt: light
//!   that one strategy alone carries (the floor seen through glass, lit by next-event
//!   estimation: s = 1 only) is found by every full sample that reaches it but by one
//!   multiplexed evaluation in (depths x strategies); on tests/scenes/glass_tube.ron the
//!   one-strategy bootstrap's b_k of that depth ranged 0.45-1.46 of its value over 40 seeds,
//!   and the sphere rendered 0.916 +- 0.035 of Mitsuba's (0.983 +- 0.010 with full samples:
//!   docs/measurements/2026-11-27-mmlt-glass-sphere.md).
//! - `select_seeds`: b_k, chains per group by largest remainder, seeds by stratified
//!   resampling (`crate::mlt::select_seeds`).
//! - `replay_seeds`: each chain's seed vector rebuilt from its evaluation index, evaluated
//!   again (the same numbers give the same contribution); in mmlt `pick_seed_strategies`
//!   then gives each chain one connection of its group from that sample, by luminance, as the
//!   multiplexed sample that makes it, evaluated again; `adopt_seeds` makes that the chains'
//!   current state.

use crate::components::CHUNK;
use crate::components::Wave;
use crate::components::metropolis::BOOTSTRAP_PER_CHAIN;
use crate::components::metropolis::BOOTSTRAP_TIME_SHARE;
use crate::components::metropolis::Bootstrap;
use crate::components::metropolis::ChainRule;
use crate::components::metropolis::MAX_BOOTSTRAP_EVALUATIONS;
use crate::components::metropolis::MIN_CHAINS;
use crate::components::metropolis::MUTATIONS_PER_BOOTSTRAP_EVALUATION;
use crate::components::metropolis::MltSettings;
use crate::components::metropolis::NONZERO_SEEDS_PER_CHAIN;
use crate::components::metropolis::STEPS_PER_CHAIN;
use crate::components::metropolis::TIMED_MUTATIONS_PER_PIXEL;
use crate::components::subpaths::Numbers;
use crate::components::subpaths::{
    CONNECTION_DIM_STRATEGY, CONNECTION_DIM_TAIL_DEPTH, MULTIPLEX_TAIL_CONTINUE,
    MULTIPLEX_TAIL_DEPTH, multiplexed_depth,
};
use crate::components::{Connections, ShadowRays};
use crate::math::luminance;
use crate::mlt::Contributions;
use crate::mlt::Normalisation;
use crate::mlt::SeedSelection;
use crate::mlt::{ChainStates, MIN_BOOTSTRAP_SAMPLES, bootstrap_error, needs_more_bootstrap};
use crate::pipeline::Flow;
use crate::sampling::{PRIMARY_STREAMS, PrimarySamples, SampleKey, Stream, mix64};
use rayon::prelude::*;

/// Fills slots `0..items.len()` of `store` with the vectors of bootstrap evaluations `items`.
/// Slot k of `store` gets bootstrap item `items[k]`'s vector: its length every stored number
/// (a full BDPT sample: pssmlt's, and mmlt's bootstrap, see `BeginBootstrapWave`), its numbers
/// a pure function of (seed, item, dimension).
fn fill_vectors(store: &mut PrimarySamples, settings: &MltSettings, items: &[u64]) {
    for (slot, &item) in items.iter().enumerate() {
        store.set_used(slot, settings.dims());
        store.tails_mut()[slot] = Bootstrap::tail(settings.seed, item);
    }
    store
        .blocks_mut(CHUNK)
        .into_par_iter()
        .take(items.len().div_ceil(CHUNK))
        // One block per task: a block's cost is its longest vector, which varies, and
        // rayon's default split (a few pieces per thread) left a core idle at the end.
        .with_max_len(1)
        .for_each(|block| {
            let items = &items[block.first..items.len().min(block.first + CHUNK)];
            for (dim, column) in block.columns.into_iter().enumerate() {
                let dim = dim as u32;
                for ((x, &item), &used) in column.iter_mut().zip(items).zip(block.used) {
                    if dim < used {
                        *x = Bootstrap::number(settings.seed, item, dim);
                    }
                }
            }
        });
}

pub struct BeginBootstrapWave;

crate::system! {
    BeginBootstrapWave = "begin_bootstrap_wave";
    read settings: MltSettings, pixels: u64;
    write bootstrap: Bootstrap, numbers: Numbers, wave: Wave, multiplex: Vec<u32>;
    run {
        bootstrap.started.get_or_insert_with(std::time::Instant::now);
        let Numbers::Primary { store, .. } = numbers else {
            unreachable!("MLT evaluates primary samples")
        };
        let mut len = store.slots() as u64;
        if let Some(n) = settings.bootstrap {
            // N evaluations, each a candidate in every group.
            len = len.min(n.saturating_sub(bootstrap.evaluated));
        } else if let Some(budget) = settings.time_budget {
            let pace = BootstrapPace::of(bootstrap);
            let chains = timed_chains(pace, settings, *pixels, budget) as u64;
            len = len.min(timed_wave_len(pace, budget, chains));
        }
        let first = bootstrap.evaluated;
        let items: Vec<u64> = (first..first + len).collect();
        fill_vectors(store, settings, &items);
        // Full BDPT samples, in mmlt too: each gives every depth's candidate paths at once,
        // by every strategy (see `CollectBootstrapWeights`).
        multiplex.clear();
        *wave = Wave { first: 0, len: len as usize };
        Flow::new(len as usize, len as usize)
    }
}

/// Under a time budget, the first wave's size: it times the evaluations.
const FIRST_TIMED_WAVE: u64 = 4096;

/// The waves are planned to fill this fraction of the bootstrap's share: the pace varies
/// from wave to wave (measured: up to 2% of the budget over when planned to the full share).
const TIMED_PLAN: f64 = 0.85;

/// How far the bootstrap has got: seconds since it began and evaluations made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BootstrapPace {
    pub spent: f64,
    pub evaluated: u64,
}

impl BootstrapPace {
    pub fn of(bootstrap: &Bootstrap) -> BootstrapPace {
        BootstrapPace {
            spent: bootstrap.started.map_or(0.0, |s| s.elapsed().as_secs_f64()),
            evaluated: bootstrap.evaluated,
        }
    }

    /// Evaluations per second so far.
    fn rate(self) -> f64 {
        self.evaluated as f64 / self.spent.max(1e-9)
    }
}

/// Under a time budget, a mutation costs about this many bootstrap evaluations (the same
/// BDPT evaluation, plus the proposal and the splats: measured 1.5-2 on door_ajar and
/// torus_glass).
const EVALUATIONS_PER_MUTATION: f64 = 2.0;

/// The chains for a time budget of `budget` seconds (pssmlt, mmlt, unless `--chains` is
/// given): as many as can each take `STEPS_PER_CHAIN` steps in the chains' share of the budget
/// at the bootstrap's pace (the rule for `--spp` assumes `TIMED_MUTATIONS_PER_PIXEL`, which
/// a short budget does not reach: at 5 s on door_ajar pssmlt took 14 steps per chain with
/// the 32768 chains it gave). Before the pace is known (no wave yet), that rule's count.
pub fn timed_chains(
    pace: BootstrapPace,
    settings: &MltSettings,
    pixels: u64,
    budget: f64,
) -> usize {
    let rule = settings.chain_count(pixels);
    if settings.chains.is_some()
        || !matches!(settings.chain_rule, ChainRule::StepsPerChain(_))
        || pace.evaluated == 0
    {
        return rule;
    }
    let mutations = pace.rate() / EVALUATIONS_PER_MUTATION * (1.0 - BOOTSTRAP_TIME_SHARE) * budget;
    ((mutations / STEPS_PER_CHAIN as f64) as usize).clamp(MIN_CHAINS, rule)
}

/// Under a time budget of `budget` seconds, the next wave: as many evaluations as fit in the
/// bootstrap's share of the budget at the pace so far, less the seeds' replay (`chains`
/// evaluations); the first wave is small, to time them.
pub fn timed_wave_len(pace: BootstrapPace, budget: f64, chains: u64) -> u64 {
    if pace.evaluated == 0 {
        return FIRST_TIMED_WAVE;
    }
    let left =
        pace.rate() * (TIMED_PLAN * BOOTSTRAP_TIME_SHARE * budget - pace.spent) - chains as f64;
    (left.max(0.0) as u64).max(CHUNK as u64)
}

/// Under a time budget, whether the share is spent: not even a wave of `CHUNK` evaluations
/// and the seeds' replay fit in it at the pace so far.
pub fn timed_waves_done(pace: BootstrapPace, budget: f64, chains: u64) -> bool {
    pace.spent + (CHUNK as u64 + chains) as f64 / pace.rate()
        > TIMED_PLAN * BOOTSTRAP_TIME_SHARE * budget
}

pub struct CollectBootstrapWeights;

crate::system! {
    CollectBootstrapWeights = "collect_bootstrap_weights";
    read settings: MltSettings, pixels: u64, wave: Wave, contributions: Contributions,
        connections: Connections, shadow: ShadowRays, starts: Vec<usize>;
    write bootstrap: Bootstrap;
    run {
        let n = wave.len;
        let pixels = *pixels;
        let groups = settings.groups();

        // Each evaluation's weight in every group, sample-major (`groups` per sample): pssmlt's
        // one group is its target; mmlt's group k is the luminance of its connections of depth
        // k (the tail group: of every depth from `MULTIPLEX_TAIL_DEPTH` on), MIS-weighted: the
        // mean over samples is b_k, as the mean of a multiplexed evaluation's target is.
        let mut per_sample = vec![0.0f32; n * groups];
        per_sample
            .par_chunks_mut(groups * CHUNK)
            .enumerate()
            .for_each(|(c, out)| {
                for (local, w) in out.chunks_mut(groups).enumerate() {
                    let k = c * CHUNK + local;
                    if !settings.multiplexed {
                        w[0] = contributions.target[k];
                        continue;
                    }
                    for slot in starts[k]..starts[k + 1] {
                        if let Some((g, value)) = seed_connection(connections, shadow, slot)
                            && g as u32 >= settings.min_depth()
                        {
                            w[g] += luminance(value);
                        }
                    }
                }
            });
        // Per group in parallel, each taking the wave's samples in order.
        bootstrap
            .weights
            .par_iter_mut()
            .enumerate()
            .with_max_len(1)
            .for_each(|(g, weights)| {
                weights.extend((0..n).map(|k| per_sample[k * groups + g]));
            });
        // The bootstrap's own image (tests): each group's part of every evaluation.
        if !bootstrap.images.is_empty() {
            for k in 0..n {
                if settings.multiplexed {
                    for slot in starts[k]..starts[k + 1] {
                        if let Some((g, value)) = seed_connection(connections, shadow, slot) {
                            bootstrap.images[g][connections.pixel[slot] as usize] +=
                                value.as_dvec3();
                        }
                    }
                } else {
                    for (pixel, value) in contributions.entries(k) {
                        bootstrap.images[0][pixel as usize] += value.as_dvec3();
                    }
                }
            }
        }
        let found = contributions.target[..n].iter().filter(|&&t| t > 0.0).count();
        bootstrap.evaluated += n as u64;
        let chains = match settings.time_budget {
            Some(budget) => timed_chains(BootstrapPace::of(bootstrap), settings, pixels, budget),
            None => settings.chain_count(pixels),
        } as u64;
        let weights: Vec<&[f32]> = bootstrap.weights.iter().map(Vec::as_slice).collect();
        bootstrap.done = match settings.bootstrap {
            Some(evaluations) => bootstrap.evaluated >= evaluations,
            None => {
                let m = settings.mutations_per_pixel.unwrap_or(TIMED_MUTATIONS_PER_PIXEL);
                automatic_bootstrap_done(&weights, chains, m, pixels)
                    || settings.time_budget.is_some_and(|budget| {
                        timed_waves_done(BootstrapPace::of(bootstrap), budget, chains)
                            && weights.iter().any(|w| w.iter().any(|&x| x > 0.0))
                    })
            }
        };
        Flow::new(n, found)
    }
}

/// Connection `slot` of a full BDPT sample as mmlt's seeds use it: its group (its depth
/// s + t - 2, or the tail group past `MULTIPLEX_TAIL_DEPTH`) and its MIS-weighted
/// contribution, when it reached the film (s = 0 has no shadow ray; the others an unoccluded
/// one) with some light.
#[inline]
fn seed_connection(
    connections: &Connections,
    shadow: &ShadowRays,
    slot: usize,
) -> Option<(usize, glam::Vec3)> {
    let (s, t) = (connections.s[slot] as u32, connections.t[slot] as u32);
    if !(s == 0 || shadow.unoccluded[slot]) {
        return None;
    }
    let value = shadow.contribution[slot];
    if value == glam::Vec3::ZERO || !value.is_finite() {
        return None;
    }
    let depth = s + t - 2;
    Some((depth.min(MULTIPLEX_TAIL_DEPTH) as usize, value))
}

/// The automatic bootstrap rule, given the weights so far (per group): at least
/// `BOOTSTRAP_PER_CHAIN` evaluations per chain, `MIN_BOOTSTRAP_SAMPLES` per group and one per
/// `MUTATIONS_PER_BOOTSTRAP_EVALUATION` mutations (within `MAX_BOOTSTRAP_EVALUATIONS`), then more until b's relative error is below `BOOTSTRAP_NOISE_FRACTION` of the
/// image noise at `mutations_per_pixel` and the non-zero evaluations number
/// `NONZERO_SEEDS_PER_CHAIN` per chain; never more than `MAX_BOOTSTRAP_EVALUATIONS`, nor more
/// than the mutations asked for (beyond that the bootstrap would take most of the render). A
/// black scene stops at the floor.
pub fn automatic_bootstrap_done(
    weights: &[&[f32]],
    chains: u64,
    mutations_per_pixel: u64,
    pixels: u64,
) -> bool {
    // Every evaluation has a weight in every group (a full BDPT sample in mmlt too).
    let evaluated = weights.first().map_or(0, |w| w.len() as u64);
    let nonzero: usize = weights
        .par_iter()
        .map(|w| w.par_iter().filter(|&&x| x > 0.0).count())
        .sum();
    // The weights kept are evaluations x groups: mmlt's 17 groups take 4x pssmlt's memory at
    // most (64 MB of f32).
    let most =
        MAX_BOOTSTRAP_EVALUATIONS.min(4 * MAX_BOOTSTRAP_EVALUATIONS / weights.len().max(1) as u64);
    let floor = (BOOTSTRAP_PER_CHAIN * chains)
        .max(MIN_BOOTSTRAP_SAMPLES as u64)
        .max((mutations_per_pixel * pixels / MUTATIONS_PER_BOOTSTRAP_EVALUATION).min(most));
    let cap = most.min(floor.max(mutations_per_pixel * pixels));
    let black = bootstrap_error(weights).normalisation <= 0.0;
    let seeds_enough = nonzero as f64 >= NONZERO_SEEDS_PER_CHAIN * chains as f64;
    evaluated >= cap
        || (evaluated >= floor
            && (black
                || (seeds_enough && !needs_more_bootstrap(weights, mutations_per_pixel as f64))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_timed_bootstrap_stays_within_its_share() {
        let budget = 10.0;
        // 100k evaluations a second: the share (1 s, planned to 0.85 s) holds about 85k
        // evaluations with the replay of the chains.
        let pace = |spent: f64| BootstrapPace {
            spent,
            evaluated: (spent * 1e5) as u64,
        };
        assert_eq!(timed_wave_len(pace(0.0), budget, 1000), FIRST_TIMED_WAVE);
        let first = pace(0.04096);
        let next = timed_wave_len(first, budget, 1000);
        assert!((79_000..81_000).contains(&next), "{next}");
        // After that wave the share is spent (the replay no longer fits with another wave).
        let after = pace(0.04096 + next as f64 / 1e5);
        assert!(after.spent + 1000.0 / 1e5 <= 0.1 * budget);
        assert!(timed_waves_done(after, budget, 1000));
        assert!(!timed_waves_done(first, budget, 1000));
        // Chains that cannot all be replayed in the share: one more wave of the least size.
        assert_eq!(timed_wave_len(first, budget, 200_000), CHUNK as u64);
        assert!(timed_waves_done(first, budget, 200_000));
    }

    #[test]
    fn timed_chains_take_their_steps_in_the_budget() {
        let s = MltSettings::new(0, false);
        let pixels = 256 * 256;
        let pace = BootstrapPace {
            spent: 0.1,
            evaluated: 40_000,
        };
        // 400k evaluations/s, 200k mutations/s, 0.9 x 5 s: 900k mutations, 64 steps each.
        assert_eq!(timed_chains(pace, &s, pixels, 5.0), 900_000 / 64);
        // Never more than the rule's, never fewer than MIN_CHAINS, and the rule's until timed.
        assert_eq!(timed_chains(pace, &s, pixels, 1e6), s.chain_count(pixels));
        assert_eq!(timed_chains(pace, &s, pixels, 0.01), MIN_CHAINS);
        let untimed = BootstrapPace {
            spent: 0.0,
            evaluated: 0,
        };
        assert_eq!(
            timed_chains(untimed, &s, pixels, 5.0),
            s.chain_count(pixels)
        );
    }

    /// `n` weights per group, one in `every` of them 1, the rest 0.
    fn weights(groups: usize, n: usize, every: usize) -> Vec<Vec<f32>> {
        let w: Vec<f32> = (0..n).map(|i| (i % every == 0) as u8 as f32).collect();
        vec![w; groups]
    }

    fn done(w: &[Vec<f32>], chains: u64, m: u64, pixels: u64) -> bool {
        let views: Vec<&[f32]> = w.iter().map(Vec::as_slice).collect();
        automatic_bootstrap_done(&views, chains, m, pixels)
    }

    #[test]
    fn bootstrap_goes_on_while_seeds_are_scarce() {
        // Every group holds one weight per evaluation (mmlt's are full BDPT samples too).
        // 1024 chains: the floor is 16k evaluations. One mutation per pixel of 256k pixels: b's
        // error may be up to half the (large) image noise, one evaluation per 16 mutations is
        // 16k too, and the cap is 256k evaluations.
        let (chains, m, pixels) = (1024, 1, 1 << 18);
        // Light in one evaluation of 4: past the floor, plenty of seeds, b known: done.
        assert!(done(&weights(2, 1 << 14, 4), chains, m, pixels));
        // Light in one of 256: b is known well enough, but 128 non-zero weights for 1024
        // chains are too few seeds, so it goes on ...
        assert!(!done(&weights(2, 1 << 14, 256), chains, m, pixels));
        // ... until there are a quarter as many as chains (512 of 2 x 64k, below the cap),
        assert!(done(&weights(2, 1 << 16, 256), chains, m, pixels));
        // or the cap: no more evaluations than the mutations asked for (here 32k).
        assert!(!done(&weights(2, 1 << 14, 1024), chains, m, 1 << 15));
        assert!(done(&weights(2, 1 << 15, 1024), chains, m, 1 << 15));
        // A black scene stops at the floor.
        let black = |n: usize| vec![vec![0.0f32; n]; 2];
        assert!(done(&black(1 << 14), chains, m, pixels));
        assert!(!done(&black(1 << 13), chains, m, pixels));
    }

    #[test]
    fn bootstrap_draws_one_evaluation_per_sixteen_mutations() {
        // 4M mutations: at least 256k evaluations, however well the weights look before.
        let (chains, m, pixels) = (1024, 4, 1 << 20);
        assert!(!done(&weights(2, 1 << 17, 4), chains, m, pixels));
        assert!(done(&weights(2, 1 << 18, 4), chains, m, pixels));
        // Within `MAX_BOOTSTRAP_EVALUATIONS` (4M) when the mutations are many more,
        assert!(done(&weights(2, 1 << 22, 4), chains, 1024, pixels));
        // and within 4 x that many weights in all: mmlt's 17 groups stop at 986k evaluations.
        assert!(!done(&weights(17, 986_000, 4), chains, 1024, pixels));
        assert!(done(&weights(17, 987_000, 4), chains, 1024, pixels));
    }

    #[test]
    fn seed_numbers_take_their_strategy_and_depth() {
        use crate::components::subpaths::MULTIPLEX_TAIL_DEPTH as TAIL;
        for max_depth in [u32::MAX, TAIL + 7] {
            for depth in (0..TAIL + 7).chain([TAIL + 40]) {
                if depth > max_depth {
                    continue;
                }
                for s in 0..depth + 2 {
                    for (v0, v1) in [(0.0, 0.0), (0.999_999, 0.999_999), (0.3, 0.7)] {
                        let (u_s, u_d) = multiplexed_numbers(depth, s, max_depth, v0, v1);
                        // As `start_subpaths` reads them.
                        let group = depth.min(TAIL);
                        let d = multiplexed_depth(group, u_d, max_depth);
                        let strategies = d + 2;
                        let picked = ((u_s * strategies as f32) as u32).min(strategies - 1);
                        assert_eq!((d, picked), (depth, s), "{depth} {s} {v0} {v1}");
                        assert!((0.0..1.0).contains(&u_s) && (0.0..1.0).contains(&u_d));
                    }
                }
            }
        }
    }
}

pub struct SelectSeeds;

crate::system! {
    SelectSeeds = "select_seeds";
    read settings: MltSettings, bootstrap: Bootstrap, pixels: u64;
    write selection: Option<SeedSelection>, chains: ChainStates, normalisation: Normalisation,
        steps_per_pass: u64;
    run {
        if let Some(budget) = settings.time_budget {
            // Fewer chains where the budget cannot give each its steps.
            let n = timed_chains(BootstrapPace::of(bootstrap), settings, *pixels, budget);
            if n < chains.chains() {
                *chains = ChainStates::new(
                    n,
                    chains.dims(),
                    chains.current_contributions.stride(),
                    chains.proposal_contributions.chains(),
                );
                *steps_per_pass = pixels.div_ceil(n as u64).max(1);
            }
        }
        let weights: Vec<&[f32]> = bootstrap.weights.iter().map(Vec::as_slice).collect();
        *normalisation = crate::mlt::Normalisation::from_bootstrap(&weights);
        *selection = crate::mlt::select_seeds(&weights, chains.chains(), settings.seed);
        if let Some(s) = selection.as_ref() {
            s.apply(chains);
        }
        Flow::new(bootstrap.evaluated as usize, selection.as_ref().map_or(0, |s| s.group.len()))
    }
}

pub struct ReplaySeeds;

crate::system! {
    ReplaySeeds = "replay_seeds";
    read settings: MltSettings, selection: Option<SeedSelection>;
    write chains: ChainStates, numbers: Numbers, wave: Wave, multiplex: Vec<u32>;
    run {
        let Some(selection) = selection.as_ref() else {
            *wave = Wave { first: 0, len: 0 };
            return Flow::new(0, 0);
        };
        // Candidate j of any group is bootstrap evaluation j, replayed as the full BDPT
        // sample it was (mmlt then picks each chain's strategy from its connections).
        let items: Vec<u64> = selection.candidate.iter().map(|&j| j as u64).collect();
        fill_vectors(&mut chains.current, settings, &items);
        chains.proposal.copy_from(&chains.current);
        let Numbers::Primary { store, .. } = numbers else {
            unreachable!("MLT evaluates primary samples")
        };
        store.copy_from(&chains.current);
        multiplex.clear();
        *wave = Wave { first: 0, len: items.len() };
        Flow::new(items.len(), items.len())
    }
}

/// Separates the seeds' strategy picks from every other use of the seed.
const STRATEGY_DOMAIN: u64 = 0x6d6d_6c74_7374_7261;

pub struct PickSeedStrategies;

crate::system! {
    PickSeedStrategies = "pick_seed_strategies";
    read settings: MltSettings, selection: Option<SeedSelection>, connections: Connections,
        shadow: ShadowRays, starts: Vec<usize>;
    write chains: ChainStates, numbers: Numbers, wave: Wave, multiplex: Vec<u32>;
    run {
        // mmlt: chain i of group k takes one connection of depth k (any depth from the tail
        // on, for the tail group) of its replayed full sample, with probability its luminance
        // over the sample's weight in the group: with the resampling by that weight, the
        // candidate paths in proportion to their luminance (as Mitsuba seeds its MLT). Its
        // vector is the sample's, with the connection numbers that make a multiplexed
        // evaluation take that depth and strategy; the evaluation that follows gives the
        // chain's current state.
        let n = chains.chains();
        if selection.is_none() {
            *wave = Wave { first: 0, len: 0 };
            return Flow::new(0, 0);
        }
        let key_seed = mix64(settings.seed ^ STRATEGY_DOMAIN);
        let mut picked = 0;
        for i in 0..n {
            let group = chains.group[i] as usize;
            let slots = starts[i]..starts[i + 1];
            let in_group = |slot: &usize| {
                seed_connection(connections, shadow, *slot)
                    .filter(|&(g, _)| g == group)
                    .map(|(_, v)| luminance(v) as f64)
            };
            let total: f64 = slots.clone().filter_map(|slot| in_group(&slot)).sum();
            let key = SampleKey::new(key_seed, i as u64, 0);
            let goal = key.get(0) as f64 * total;
            let (mut running, mut choice) = (0.0, None);
            for slot in slots {
                let Some(w) = in_group(&slot).filter(|&w| w > 0.0) else {
                    continue;
                };
                choice = Some(slot);
                running += w;
                if running > goal {
                    break;
                }
            }
            chains.current.set_used(i, settings.dims_of_group(group as u32));
            // No connection in the group (a replay that lost its light: counted by
            // `adopt_seeds`): the chain starts at strategy 0 with no target and takes its
            // first valid proposal.
            let (depth, s) = choice.map_or((group as u32, 0), |slot| {
                let (s, t) = (connections.s[slot] as u32, connections.t[slot] as u32);
                (s + t - 2, s)
            });
            picked += choice.is_some() as usize;
            let (u_strategy, u_depth) =
                multiplexed_numbers(depth, s, settings.max_depth, key.get(1), key.get(2));
            chains.current.set(i, connection_dim(CONNECTION_DIM_STRATEGY), u_strategy);
            if group as u32 >= MULTIPLEX_TAIL_DEPTH {
                chains.current.set(i, connection_dim(CONNECTION_DIM_TAIL_DEPTH), u_depth);
            }
        }
        chains.proposal.copy_from(&chains.current);
        let Numbers::Primary { store, .. } = numbers else {
            unreachable!("MLT evaluates primary samples")
        };
        store.copy_from(&chains.current);
        multiplex.clear();
        multiplex.extend_from_slice(&chains.group);
        *wave = Wave { first: 0, len: n };
        Flow::new(n, picked)
    }
}

/// The store dimension of connection-stream number `dim` (the streams are interleaved:
/// `sampling::primary_get`).
#[inline]
fn connection_dim(dim: u32) -> u32 {
    dim * PRIMARY_STREAMS + Stream::Connection.ordinal() as u32
}

/// The connection numbers (strategy, tail depth) with which a multiplexed evaluation takes
/// strategy s at depth `depth` (`bdpt::multiplexed_depth`, `start_subpaths`): each drawn
/// uniformly (from `v_strategy`, `v_depth`) within the interval that gives it, so the chain's
/// state has the density its target asks for in those numbers too; the interval's midpoint
/// where rounding puts the drawn one outside it.
pub fn multiplexed_numbers(
    depth: u32,
    s: u32,
    max_depth: u32,
    v_strategy: f32,
    v_depth: f32,
) -> (f32, f32) {
    let strategies = depth + 2;
    let takes = |u: f32| ((u * strategies as f32) as u32).min(strategies - 1) == s;
    let within = |v: f32| ((s as f64 + v as f64) / strategies as f64) as f32;
    // A primary sample lies in [0, 1): (s + v) / strategies may round up to 1.
    let u_strategy = [within(v_strategy), within(0.5)]
        .into_iter()
        .find(|&u| u < 1.0 && takes(u))
        .unwrap_or(within(0.5));
    if depth < MULTIPLEX_TAIL_DEPTH {
        return (u_strategy, 0.0);
    }
    // Depth MULTIPLEX_TAIL_DEPTH + j takes u in [(1 - q^j) / mass, (1 - q^(j + 1)) / mass).
    let q = MULTIPLEX_TAIL_CONTINUE;
    let j = (depth - MULTIPLEX_TAIL_DEPTH) as f64;
    let mass = 1.0 - q.powf(max_depth.saturating_sub(MULTIPLEX_TAIL_DEPTH) as f64 + 1.0);
    let (lo, hi) = (
        (1.0 - q.powf(j)) / mass,
        ((1.0 - q.powf(j + 1.0)) / mass).min(1.0),
    );
    let at = |v: f32| (lo + (hi - lo) * v as f64) as f32;
    let u_depth = [at(v_depth), at(0.5)]
        .into_iter()
        .find(|&u| u < 1.0 && multiplexed_depth(MULTIPLEX_TAIL_DEPTH, u, max_depth) == depth)
        .unwrap_or(at(0.5));
    (u_strategy, u_depth)
}

pub struct AdoptSeeds;

crate::system! {
    AdoptSeeds = "adopt_seeds";
    read settings: MltSettings, selection: Option<SeedSelection>;
    write chains: ChainStates, bootstrap: Bootstrap;
    run {
        chains.current_contributions.clone_from(&chains.proposal_contributions);
        chains.current_contributions.truncate(chains.chains());
        // The same numbers give the same contribution: pssmlt's seed's target is its weight.
        // An mmlt seed evaluates one strategy of its sample without Russian roulette (its
        // target is that connection's luminance, unless roulette scaled it, times the
        // strategy count), so there a mismatch is a seed with a weight that found no light.
        if let Some(sel) = selection.as_ref() {
            bootstrap.replay_mismatches = sel
                .group
                .iter()
                .zip(&sel.candidate)
                .enumerate()
                .filter(|&(i, (&g, &j))| {
                    let target = chains.current_contributions.target[i];
                    let weight = bootstrap.weights[g as usize][j as usize];
                    if settings.multiplexed {
                        (weight > 0.0) && !(target.is_finite() && target > 0.0)
                    } else {
                        target != weight
                    }
                })
                .count();
        }
        bootstrap.time = bootstrap.started.map_or_else(Default::default, |s| s.elapsed());
        let n = chains.chains();
        let live = chains.current_contributions.target.iter().filter(|&&t| t > 0.0).count();
        Flow::new(n, live)
    }
}
