//! What the path-space mutation systems share: `choose_mutations` (per chain, one mutation
//! uniformly among the enabled ones suitable for its path) and the loop each mutation system
//! runs over the chains that chose it (propose, then evaluate f of the proposal).

use crate::components::CHUNK;
use crate::components::metropolis::PathMltSettings;
use crate::mlt::path_chains::{
    INLINE_VERTICES, MutationKind, MutationSet, PathChains, Proposal, chunk_starts, load_path,
    path_len, store_path,
};
use crate::mlt::path_space::{PathSpace, StepNumbers};
use crate::path::Vertex;
use crate::pipeline::Flow;
use crate::scene::SceneData;
use crate::systems::mutate::{
    bidirectional, caustic_perturbation, lens_perturbation, multichain_perturbation,
};
use glam::DVec3;
use rayon::prelude::*;
use std::sync::Arc;

/// Random-number lanes of a chain's step: the mutation's choice, the acceptance, then the
/// mutation's own numbers.
pub const LANE_CHOICE: u32 = 0;
pub const LANE_ACCEPT: u32 = 1;
pub const LANE_MUTATION: u32 = 2;

/// The enabled mutations suitable for `x`, in `MutationKind` order.
pub fn suitable(ps: &PathSpace, set: &MutationSet, x: &[Vertex]) -> Vec<MutationKind> {
    MutationKind::ALL
        .into_iter()
        .filter(|&k| set.has(k))
        .filter(|&k| match k {
            MutationKind::Bidirectional => true,
            MutationKind::Lens => lens_perturbation::suitable(ps, x).is_some(),
            MutationKind::Caustic => caustic_perturbation::suitable(ps, x).is_some(),
            MutationKind::MultiChain => multichain_perturbation::suitable(ps, x).is_some(),
        })
        .collect()
}

/// Proposes by mutation `kind`.
pub fn propose(
    ps: &PathSpace,
    set: &MutationSet,
    kind: MutationKind,
    x: &[Vertex],
    u: &mut StepNumbers,
) -> Option<Proposal> {
    match kind {
        MutationKind::Bidirectional => bidirectional::propose(ps, set, x, u),
        MutationKind::Lens => lens_perturbation::propose(ps, set, x, u),
        MutationKind::Caustic => caustic_perturbation::propose(ps, set, x, u),
        MutationKind::MultiChain => multichain_perturbation::propose(ps, set, x, u),
    }
}

pub struct ChooseMutations;

crate::system! {
    ChooseMutations = "choose_mutations";
    read data: Arc<SceneData>, settings: PathMltSettings, step: u64;
    write chains: PathChains;
    run {
        choose(data, settings, *step, chains)
    }
}

fn choose(
    data: &SceneData,
    settings: &PathMltSettings,
    step: u64,
    chains: &mut PathChains,
) -> Flow {
    let ps = PathSpace::new(data);
    let n = chains.chains();
    let starts = chunk_starts(n);
    let stores = chains.current.split_mut(&starts, n * INLINE_VERTICES);
    let set = &settings.mutations;
    stores
        .into_par_iter()
        .zip(chains.current_overflow.par_chunks(CHUNK))
        .zip(chains.kind.par_chunks_mut(CHUNK))
        .zip(chains.suitable.par_chunks_mut(CHUNK))
        .zip(chains.step_key.par_chunks_mut(CHUNK))
        .zip(chains.current_len.par_chunks(CHUNK))
        .enumerate()
        .for_each(|(c, (((((store, overflow), kind), count), key), len))| {
            for local in 0..kind.len() {
                let chain = c * CHUNK + local;
                key[local] = crate::mlt::step_key(settings.seed, chain, step);
                let x = load_path(&store.view(), &overflow[local], local, len[local] as usize);
                let options = if x.len() >= 2 {
                    suitable(&ps, set, &x)
                } else {
                    vec![MutationKind::Bidirectional]
                };
                let u = key[local].get(LANE_CHOICE);
                kind[local] = options[((u * options.len() as f32) as usize).min(options.len() - 1)];
                count[local] = options.len() as u8;
            }
        });
    Flow::new(n, n)
}

/// Runs mutation `kind` on the chains that chose it: their proposals, f and target, and the
/// Hastings ratio (the choice's probability included).
pub fn run(
    data: &SceneData,
    set: &MutationSet,
    chains: &mut PathChains,
    kind: MutationKind,
    propose_by: fn(&PathSpace, &MutationSet, &[Vertex], &mut StepNumbers) -> Option<Proposal>,
) -> Flow {
    let ps = PathSpace::new(data);
    let n = chains.chains();
    let starts = chunk_starts(n);
    let end = n * INLINE_VERTICES;
    let current = chains.current.split_mut(&starts, end);
    let proposal = chains.proposal.split_mut(&starts, end);
    let (kinds, suitable_counts, keys, lens, current_overflow) = (
        &chains.kind,
        &chains.suitable,
        &chains.step_key,
        &chains.current_len,
        &chains.current_overflow,
    );
    let made: usize = current
        .into_par_iter()
        .zip(proposal)
        .zip(chains.proposal_overflow.par_chunks_mut(CHUNK))
        .zip(chains.proposal_len.par_chunks_mut(CHUNK))
        .zip(chains.proposal_f.par_chunks_mut(CHUNK))
        .zip(chains.proposal_landing.par_chunks_mut(CHUNK))
        .zip(chains.proposal_target.par_chunks_mut(CHUNK))
        .zip(chains.ratio.par_chunks_mut(CHUNK))
        .enumerate()
        .map(
            |(c, (((((((cur, mut prop), poverflow), plen), pf), ppix), ptarget), ratio))| {
                let mut made = 0;
                for local in 0..plen.len() {
                    let chain = c * CHUNK + local;
                    if kinds[chain] != kind {
                        continue;
                    }
                    plen[local] = 0;
                    pf[local] = DVec3::ZERO;
                    ptarget[local] = 0.0;
                    ratio[local] = 0.0;
                    let x = load_path(
                        &cur.view(),
                        &current_overflow[chain],
                        local,
                        lens[chain] as usize,
                    );
                    if x.len() < 2 {
                        continue;
                    }
                    let mut u = StepNumbers::new(keys[chain], LANE_MUTATION);
                    let Some(p) = propose_by(&ps, set, &x, &mut u) else {
                        continue;
                    };
                    let Some((f, landing)) = ps.contribution(&p.path) else {
                        continue;
                    };
                    let back = suitable(&ps, set, &p.path).len();
                    if back == 0 {
                        continue;
                    }
                    store_path(&mut prop, &mut poverflow[local], local, &p.path);
                    plen[local] = path_len(p.path.len());
                    pf[local] = f;
                    ppix[local] = landing;
                    ptarget[local] = PathSpace::target(f);
                    // P(choose kind | x) / P(choose kind | y) = |suitable(y)| / |suitable(x)|,
                    // inverted: T carries 1 / |suitable|.
                    ratio[local] = p.ratio * suitable_counts[chain] as f64 / back as f64;
                    made += 1;
                }
                made
            },
        )
        .sum();
    let chosen = kinds.iter().filter(|&&k| k == kind).count();
    Flow::new(chosen, made)
}
