//! `propose_mutations`: every chain's proposal vector for the next step (`mlt::propose_mutations`:
//! a large step with probability p, else a small step on every number; keyed by chain and
//! step), then hands it to the BDPT state as its primary-sample store (a swap, no copy), with
//! each chain's group as its sample's multiplexed depth group (mmlt).

use crate::components::Wave;
use crate::components::metropolis::MltSettings;
use crate::components::subpaths::Numbers;
use crate::mlt::ChainStates;
use crate::pipeline::Flow;

pub struct ProposeMutations;

crate::system! {
    ProposeMutations = "propose_mutations";
    read settings: MltSettings, step: u64;
    write chains: ChainStates, numbers: Numbers, wave: Wave, multiplex: Vec<u32>;
    run {
        crate::mlt::propose_mutations(chains, &settings.mutation, settings.seed, *step);
        // Each sample starts from its chain's group (`start_subpaths` makes it a depth).
        if settings.multiplexed {
            multiplex.clear();
            multiplex.extend_from_slice(&chains.group);
        }
        let Numbers::Primary { store, .. } = numbers else {
            unreachable!("MLT evaluates primary samples")
        };
        std::mem::swap(store, &mut chains.proposal);
        *wave = Wave { first: 0, len: chains.chains() };
        Flow::new(chains.chains(), chains.chains())
    }
}
