//! Acceptance for the path-space chains: `accept_path_proposals` (a = min(1, f(y) T(y -> x) /
//! (f(x) T(x -> y))) with f the luminance; zero, negative or non-finite gives 0),
//! `splat_path_expected_values` (Veach's expected values, in chain order) and
//! `commit_path_proposals` (accepted chains take their proposal).

use super::path_mutation::LANE_ACCEPT;
use crate::components::CHUNK;
use crate::components::metropolis::MutationCounts;
use crate::mlt::Splat;
use crate::mlt::path_chains::PathChains;
use crate::mlt::path_chains::{INLINE_VERTICES, chunk_starts, copy_path};
use crate::mlt::path_space::Landing;
use crate::pipeline::Flow;
use crate::scene::Camera;
use glam::DVec3;
use rayon::prelude::*;

/// a(x -> y) given the targets and T(y -> x) / T(x -> y).
#[inline]
pub fn acceptance(current: f64, proposal: f64, ratio: f64) -> f64 {
    let r = proposal * ratio;
    if !(r.is_finite() && r > 0.0) {
        0.0
    } else if !(current.is_finite() && current > 0.0) {
        1.0
    } else {
        (r / current).min(1.0)
    }
}

pub struct AcceptPathProposals;

crate::system! {
    AcceptPathProposals = "accept_path_proposals";
    write chains: PathChains, counts: MutationCounts;
    run {
        let n = chains.chains();
        let (cur, prop, ratio, keys, kinds) = (&chains.current_target, &chains.proposal_target, &chains.ratio, &chains.step_key, &chains.kind);
        let step: MutationCounts = chains
            .acceptance
            .par_chunks_mut(CHUNK)
            .zip(chains.accepted.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (a_out, acc_out))| {
                let mut counts = MutationCounts {
                    steps: a_out.len() as u64,
                    ..MutationCounts::default()
                };
                for local in 0..a_out.len() {
                    let i = c * CHUNK + local;
                    let a = acceptance(cur[i], prop[i], ratio[i]);
                    let accept = f64::from(keys[i].get(LANE_ACCEPT)) < a;
                    a_out[local] = a;
                    acc_out[local] = accept;
                    let k = kinds[i] as usize;
                    counts.proposed[k] += 1;
                    counts.accepted[k] += accept as u64;
                    counts.zero[k] += (prop[i] == 0.0) as u64;
                }
                counts
            })
            .reduce(MutationCounts::default, |a, b| a + b);
        *counts = *counts + step;
        Flow::new(n, step.accepted.iter().sum::<u64>() as usize)
    }
}

pub struct SplatPathExpectedValues;

crate::system! {
    SplatPathExpectedValues = "splat_path_expected_values";
    read chains: PathChains, splat_scale: f32, camera: Camera;
    write splats: Vec<Vec<Splat>>, splat_sums: Vec<DVec3>, nonfinite: u64;
    run {
        let n = chains.chains();
        let scale = *splat_scale;
        splats.resize_with(n.div_ceil(CHUNK), Vec::new);
        splats.par_iter_mut().enumerate().for_each(|(c, out)| {
            out.clear();
            for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                // f / its luminance is a colour of luminance 1: in f32 range whatever f's.
                let a = chains.acceptance[i];
                if a > 0.0 {
                    let w = f64::from(scale) * a / chains.proposal_target[i];
                    let Landing { pixel, at } = chains.proposal_landing[i];
                    out.push(Splat { pixel, value: (chains.proposal_f[i] * w).as_vec3(), at });
                }
                let t = chains.current_target[i];
                if a < 1.0 && t.is_finite() && t > 0.0 {
                    let w = f64::from(scale) * (1.0 - a) / t;
                    let Landing { pixel, at } = chains.current_landing[i];
                    out.push(Splat { pixel, value: (chains.current_f[i] * w).as_vec3(), at });
                }
            }
        });
        // Under the gaussian each splat spreads over its footprint from where it landed.
        let (made, dropped) = match camera.filter {
            crate::film::PixelFilter::Box => crate::mlt::add_splats(splats, splat_sums),
            crate::film::PixelFilter::Gaussian(g) => {
                let size = (camera.width as usize, camera.height as usize);
                crate::mlt::add_splats_filtered(splats, splat_sums, g, size)
            }
        };
        let made = made as usize;
        *nonfinite += dropped;
        Flow::new(n, made)
    }
}

pub struct CommitPathProposals;

crate::system! {
    CommitPathProposals = "commit_path_proposals";
    write chains: PathChains, step: u64, steps_left: u64;
    run {
        *step += 1;
        *steps_left -= 1;
        let n = chains.chains();
        let starts = chunk_starts(n);
        let end = n * INLINE_VERTICES;
        let current = chains.current.split_mut(&starts, end);
        let proposal = chains.proposal.split_mut(&starts, end);
        let accepted = &chains.accepted;
        let (plen, pf, ppix, ptarget, poverflow) = (&chains.proposal_len, &chains.proposal_f, &chains.proposal_landing, &chains.proposal_target, &chains.proposal_overflow);
        let taken: usize = current
            .into_par_iter()
            .zip(proposal)
            .zip(chains.current_overflow.par_chunks_mut(CHUNK))
            .zip(chains.current_len.par_chunks_mut(CHUNK))
            .zip(chains.current_f.par_chunks_mut(CHUNK))
            .zip(chains.current_landing.par_chunks_mut(CHUNK))
            .zip(chains.current_target.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, ((((((mut cur, prop), overflow), len), f), pix), target))| {
                let mut taken = 0;
                for local in 0..len.len() {
                    let i = c * CHUNK + local;
                    if !accepted[i] {
                        continue;
                    }
                    copy_path(&prop, &poverflow[i], &mut cur, &mut overflow[local], local, plen[i] as usize);
                    len[local] = plen[i];
                    f[local] = pf[i];
                    pix[local] = ppix[i];
                    target[local] = ptarget[i];
                    taken += 1;
                }
                taken
            })
            .sum();
        Flow::new(n, taken)
    }
}
