//! Acceptance and Veach's expected values: `accept_or_reject` (takes the proposal vectors back
//! from the BDPT state, a = min(1, c_prop / c_cur), u < a), `estimate_normalisation` (the
//! large steps' targets into the running b_k), `splat_expected_values` (both states weighted,
//! added to the f64 splat sums of the chain's group in chain order: the image does not depend
//! on the thread count), `commit_accepted` (accepted chains take their proposal; the step
//! ends).

use crate::integrators::bdpt::Numbers;
use crate::integrators::mlt::MltState;
use crate::pipeline::Flow;

pub struct AcceptOrReject;

crate::system! {
    AcceptOrReject = "accept_or_reject";
    on MltState {
        write chains, numbers = bdpt.sampler, counters;
    }
    run {
        let Numbers::Primary { store, .. } = numbers else {
            unreachable!("MLT evaluates primary samples")
        };
        std::mem::swap(store, &mut chains.proposal);
        let step = crate::mlt::accept_or_reject(chains);
        *counters += step;
        Flow::new(step.steps as usize, step.accepted as usize)
    }
}

pub struct EstimateNormalisation;

crate::system! {
    EstimateNormalisation = "estimate_normalisation";
    on MltState {
        read chains;
        write normalisation;
    }
    run {
        let per_group = crate::mlt::large_step_targets(chains, normalisation.sums.len());
        normalisation.add_large_steps(&per_group);
        let large = per_group.iter().map(|&(_, n)| n as usize).sum();
        Flow::new(chains.chains(), large)
    }
}

pub struct SplatExpectedValues;

crate::system! {
    SplatExpectedValues = "splat_expected_values";
    on MltState {
        read chains, pixels;
        write splats, splat_sums, nonfinite;
    }
    run {
        crate::mlt::splat_expected_values(chains, splats, *pixels as u32);
        let (added, dropped) = splats.add_to(splat_sums);
        *nonfinite += dropped;
        Flow::new(chains.chains(), (added + dropped) as usize)
    }
}

pub struct CommitAccepted;

crate::system! {
    CommitAccepted = "commit_accepted";
    on MltState {
        write chains, step, steps_left;
    }
    run {
        crate::mlt::commit_accepted(chains);
        *step += 1;
        *steps_left -= 1;
        let accepted = chains.accepted.iter().filter(|&&a| a).count();
        Flow::new(chains.chains(), accepted)
    }
}
