//! Acceptance and Veach's expected values: `accept_or_reject` (takes the proposal vectors back
//! from the BDPT state, a = min(1, c_prop / c_cur), u < a), `estimate_normalisation` (the
//! large steps' targets into the running b_k), `splat_expected_values` (both states weighted,
//! added to the f64 splat sums of the chain's group in chain order: the image does not depend
//! on the thread count), `splat_strategy_images` (with `--strategy-images`, the same splats by
//! strategy), `commit_accepted` (accepted chains take their proposal; the step ends).

use crate::components::metropolis::MltSettings;
use crate::components::subpaths::Numbers;
use crate::mlt::ChainSplats;
use crate::mlt::ChainStates;
use crate::mlt::MltCounters;
use crate::mlt::Normalisation;
use crate::pipeline::Flow;
use crate::scene::Camera;
use glam::DVec3;
use std::collections::BTreeMap;

pub struct AcceptOrReject;

crate::system! {
    AcceptOrReject = "accept_or_reject";
    write chains: ChainStates, numbers: Numbers, counters: MltCounters;
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
    read chains: ChainStates;
    write normalisation: Normalisation;
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
    read chains: ChainStates, pixels: u64, camera: Camera;
    write splats: ChainSplats, splat_sums: Vec<DVec3>, nonfinite: u64;
    run {
        crate::mlt::splat_expected_values(chains, splats, *pixels as u32);
        // Under the gaussian each splat spreads over its footprint from where it landed.
        let size = (camera.width as usize, camera.height as usize);
        let (added, dropped) = splats.add_to_filtered(splat_sums, camera.filter, size);
        *nonfinite += dropped;
        Flow::new(chains.chains(), (added + dropped) as usize)
    }
}

pub struct SplatStrategyImages;

crate::system! {
    SplatStrategyImages = "splat_strategy_images";
    read settings: MltSettings, chains: ChainStates, pixels: u64;
    write strategy_sums: BTreeMap<(u32, u32, u16), Vec<DVec3>>;
    run {
        // Only with `--strategy-images` (mmlt): each splat again, into its strategy's image.
        if !settings.strategy_images {
            return Flow::new(0, 0);
        }
        crate::mlt::splat_strategies(chains, strategy_sums, *pixels as usize);
        Flow::new(chains.chains(), chains.chains())
    }
}

pub struct CommitAccepted;

crate::system! {
    CommitAccepted = "commit_accepted";
    write chains: ChainStates, step: u64, steps_left: u64;
    run {
        crate::mlt::commit_accepted(chains);
        *step += 1;
        *steps_left -= 1;
        let accepted = chains.accepted.iter().filter(|&&a| a).count();
        Flow::new(chains.chains(), accepted)
    }
}
