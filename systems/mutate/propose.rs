//! `propose_mutations`: every chain's proposal vector for the next step (`mlt::propose_mutations`:
//! a large step with probability p, else a small step on every number; keyed by chain and
//! step), then hands it to the BDPT state as its primary-sample store (a swap, no copy), with
//! each chain's group as its sample's multiplexed depth group (mmlt).

use crate::integrators::Wave;
use crate::integrators::bdpt::Numbers;
use crate::integrators::mlt::MltState;
use crate::pipeline::Flow;

pub struct ProposeMutations;

crate::system! {
    ProposeMutations = "propose_mutations";
    on MltState {
        read settings, step;
        write chains, numbers = bdpt.sampler, wave = bdpt.wave, multiplex = bdpt.multiplex;
    }
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
