//! Finds the closest hit of every live ray.

use crate::accel::Accel;
use crate::components::{Hits, MISS, Rays};
use crate::pipeline::{Flow, System};
use rayon::prelude::*;

/// A state with a queue of rays to trace for closest hits (slots `0..len`).
pub trait ClosestHitQueue {
    fn closest_hit_queue(&mut self) -> (&Accel, &Rays, &mut Hits, usize);
}

pub struct TraceClosest;

impl<S: ClosestHitQueue + Send> System<S> for TraceClosest {
    fn name(&self) -> &'static str {
        "trace_closest"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["rays"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["hits"]
    }
    fn run(&self, state: &mut S) -> Flow {
        let (accel, rays, hits, len) = state.closest_hit_queue();
        let found: usize = hits
            .chunks_mut(0..len)
            .into_par_iter()
            .map(|h| {
                let mut found = 0;
                for i in 0..h.len() {
                    let slot = h.start + i;
                    match accel.closest_hit(rays.origin[slot], rays.dir[slot], f32::INFINITY) {
                        Some(hit) => {
                            h.t[i] = hit.t;
                            h.triangle[i] = hit.triangle;
                            h.b1[i] = hit.b1;
                            h.b2[i] = hit.b2;
                            found += 1;
                        }
                        None => h.triangle[i] = MISS,
                    }
                }
                found
            })
            .sum();
        Flow::new(len, found)
    }
}
