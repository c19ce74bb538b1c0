//! Russian roulette by path throughput. A path that ends here (or ended in shading) gets an
//! empty ray: tracing finds nothing for it, and `sort_by_material` retires it with the paths
//! that left the scene. So the wavefront is compacted once per bounce, not twice.

use crate::components::PathFlags;
use crate::integrators::pt::{DIM_ROULETTE, PtState, bounce_dim};
use crate::pipeline::Flow;
use crate::sampling::roulette::{ROULETTE_DEPTH, survival, survives};
use glam::Vec3;
use rayon::prelude::*;

pub struct RussianRoulette;

crate::system! {
    RussianRoulette = "russian_roulette";
    on PtState {
        read live = active, sampler;
        write paths, rays;
    }
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
                    if !p.flags[i].has(PathFlags::DEAD) && p.depth[i] >= ROULETTE_DEPTH {
                        let q = survival(p.throughput[i], 1.0);
                        let u = sampler.get(p.key[i], bounce_dim(p.depth[i] - 1) + DIM_ROULETTE);
                        if survives(q, u) {
                            p.throughput[i] /= q;
                        } else {
                            p.flags[i].set(PathFlags::DEAD, true);
                        }
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
