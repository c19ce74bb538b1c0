//! Metropolis light transport in primary sample space: the engine-independent kernel of
//! `pssmlt` (Kelemen over full BDPT) and `mmlt` (multiplexed MLT, as pbrt-v4).
//!
//! Many chains run in lock step, one chain per wavefront slot, their state in
//! structure-of-arrays columns (`ChainStates`, sized once and reused every step). Every random
//! number is a pure function of (seed, chain, step, lane) and all parallel work is split into
//! fixed `CHUNK`s of chains, so results are bit-identical for any thread count.
//!
//! # How the renderer's graphs use these pieces
//!
//! Graph `bootstrap` (once, or at each reseeding):
//! 1. the BDPT graph with its own sample keys (full BDPT samples); per bootstrap sample and
//!    group (MMLT: depth k, PSSMLT: one group) the weight = luminance of its contribution (MMLT:
//!    of its MIS-weighted connections of depth k), zeros kept;
//! 2. `needs_more_bootstrap(groups, mutations_per_pixel)`: draw more bootstrap samples until
//!    false (b's relative error under half the image's; formula in `seeds`);
//! 3. `select_seeds(groups, chains, seed)` -> `SeedSelection` (b_k, chains per group by largest
//!    remainder, each chain's candidate by stratified resampling), then
//!    `SeedSelection::apply(&mut chains)` (group = depth and splat scale per chain);
//! 4. the renderer replays each chain's candidate into `chains.current` (the numbers its sample
//!    key gave) and evaluates it into `chains.current_contributions` (MMLT: after picking one
//!    connection of the chain's depth by luminance and setting the numbers that make a
//!    multiplexed evaluation take it).
//!
//! Graph `mutations`, per step `step` (one step = one mutation of every chain):
//! 1. `propose_mutations(&mut chains, &settings, seed, step)`: `chains.proposal`, every
//!    number each chain uses (`PrimarySamples::used`; large step: fresh uniforms; small step:
//!    `SmallStep` on each);
//! 2. the evaluation systems (BDPT at the chain's `group` depth for MMLT) read their numbers
//!    from `chains.proposal` instead of the hash, and write per chain the target c (luminance)
//!    and the (pixel, RGB) contributions into `chains.proposal_contributions`
//!    (`Contributions::par_chunks_mut` for parallel writers);
//! 3. `accept_or_reject(&mut chains)` -> the step's `MltCounters`: a = min(1, c_prop / c_cur)
//!    and the decision u < a, per chain;
//! 4. `large_step_targets(&chains, groups)`: the targets of the step's large steps, per group,
//!    into the running `Normalisation` (b_k from the bootstrap and every large step since);
//! 5. `splat_expected_values(&chains, &mut splats, pixels)`: proposal x a / c_prop and current
//!    x (1 - a) / c_cur, times the chain's splat scale; the renderer adds `splats.iter()`
//!    (chain order) to the f64 splat film of the chain's group;
//! 6. `commit_accepted(&mut chains)`: accepted chains take their proposal.
//!
//! The image is the sum over groups of b_k x the group's splat sums x (pixel count) / (steps
//! per chain): each step deposits 1 / chains_k units of luminance per chain of group k, and
//! b_k is the running estimate at the end, so the image's mean luminance is b.

mod accept;
mod chains;
mod mutate;
pub mod path_chains;
pub mod path_space;
mod seeds;

pub use accept::{
    ChainSplats, Splat, accept_or_reject, acceptance_probability, add_splats, add_splats_filtered,
    commit_accepted, large_step_targets, splat_expected_values, splat_strategies,
};
pub use chains::{ChainStates, Contributions, ContributionsChunk, MltCounters};
pub use mutate::{MutationSettings, SmallStep, propose_mutations, step_key, wrap_unit};
pub use seeds::{
    BOOTSTRAP_NOISE_FRACTION, BootstrapError, MIN_BOOTSTRAP_SAMPLES, Normalisation, SeedSelection,
    allocate_largest_remainder, bootstrap_error, bootstrap_samples_needed, group_normalisation,
    needs_more_bootstrap, resample_stratified, select_seeds, usable_weight,
};

#[cfg(test)]
mod tests;
