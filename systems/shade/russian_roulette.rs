//! Russian roulette by path throughput, then compaction: ended paths give their radiance to
//! their sample and the live ones move to the front.

use crate::components::PathFlags;
use crate::integrators::pt::{DIM_ROULETTE, PtState, ROULETTE_DEPTH, bounce_dim};
use crate::pipeline::{Flow, System};
use rayon::prelude::*;

pub struct RussianRouletteAndCompaction;

impl System<PtState> for RussianRouletteAndCompaction {
    fn name(&self) -> &'static str {
        "russian_roulette_and_compaction"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["paths"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["paths", "rays", "sample_radiance"]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let taken = s.active;
        s.paths.chunks_mut(0..taken).into_par_iter().for_each(|p| {
            for i in 0..p.len() {
                if p.flags[i].has(PathFlags::DEAD) || p.depth[i] < ROULETTE_DEPTH {
                    continue;
                }
                let survive = p.throughput[i].max_element().min(1.0);
                let u = p.key[i].get(bounce_dim(p.depth[i] - 1) + DIM_ROULETTE);
                if u >= survive {
                    p.flags[i].set(PathFlags::DEAD, true);
                } else {
                    p.throughput[i] /= survive;
                }
            }
        });
        let mut order = std::mem::take(&mut s.scratch.order);
        order.clear();
        for slot in 0..taken {
            if s.paths.flags[slot].has(PathFlags::DEAD) {
                s.finish_path(slot);
            } else {
                order.push(slot as u32);
            }
        }
        s.scratch.order = order;
        s.reorder(false);
        Flow::new(taken, s.active)
    }
}
