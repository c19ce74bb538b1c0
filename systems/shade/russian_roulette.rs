//! Russian roulette by path throughput. A path that ends here (or ended in shading) gets an
//! empty ray: tracing finds nothing for it, and `sort_by_material` retires it with the paths
//! that left the scene. So the wavefront is compacted once per bounce, not twice.

use crate::components::PathFlags;
use crate::components::Paths;
use crate::components::Rays;
use crate::components::path_tracing::DIM_ROULETTE;
use crate::components::path_tracing::bounce_dim;
use crate::pipeline::Flow;
use crate::sampling::roulette::{ROULETTE_DEPTH, survival, survives};
use crate::sampling::{SampleKey, Sampler};
use glam::Vec3;
use rayon::prelude::*;

pub struct RussianRoulette;

crate::system! {
    RussianRoulette = "russian_roulette";
    read live: usize, sampler: Sampler<'static>;
    write paths: Paths, rays: Rays;
    run {
        let taken = *live;
        let rays = rays.chunks_mut(0..taken);
        let survivors: usize = paths
            .chunks_mut(0..taken)
            .into_par_iter()
            .zip(rays)
            .map(|(p, r)| {
                let mut survivors = 0;
                for i in 0..p.len() {
                    if !p.flags[i].has(PathFlags::DEAD)
                        && !roulette(sampler, p.key[i], p.depth[i], &mut p.throughput[i])
                    {
                        p.flags[i].set(PathFlags::DEAD, true);
                    }
                    if p.flags[i].has(PathFlags::DEAD) {
                        r.dir[i] = Vec3::ZERO;
                    } else {
                        survivors += 1;
                    }
                }
                survivors
            })
            .sum();
        Flow::new(taken, survivors)
    }
}

/// Russian roulette for a path that has scattered `depth` times (random numbers from `key`):
/// whether it goes on, its throughput divided by its survival probability if so. Paths play
/// from `ROULETTE_DEPTH` bounces on. The one per-path step of this system, shared with the
/// megakernel (`systems/trace/paths.rs`).
#[inline(always)]
pub fn roulette(sampler: &Sampler, key: SampleKey, depth: u32, throughput: &mut Vec3) -> bool {
    if depth < ROULETTE_DEPTH {
        return true;
    }
    let q = survival(*throughput, 1.0);
    let u = sampler.get(key, bounce_dim(depth - 1) + DIM_ROULETTE);
    if survives(q, u) {
        *throughput /= q;
        true
    } else {
        false
    }
}
