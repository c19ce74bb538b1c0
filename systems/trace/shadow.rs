//! Tests every shadow ray for occlusion (any hit before its end).

use crate::accel::Accel;
use crate::components::ShadowRays;
use crate::pipeline::{Flow, System};
use rayon::prelude::*;
use std::ops::Range;

/// A state with a queue of shadow rays; a ray with `t_max == 0` is absent.
pub trait ShadowQueue {
    fn shadow_queue(&mut self) -> (&Accel, &mut ShadowRays, Range<usize>);
}

pub struct TraceShadow;

impl<S: ShadowQueue + Send> System<S> for TraceShadow {
    fn name(&self) -> &'static str {
        "trace_shadow"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["shadow_rays"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["shadow_rays.unoccluded"]
    }
    fn run(&self, state: &mut S) -> Flow {
        let (accel, shadow, range) = state.shadow_queue();
        let (taken, unoccluded) = shadow
            .chunks_mut(range)
            .into_par_iter()
            .map(|c| {
                let (mut taken, mut clear) = (0, 0);
                for i in 0..c.len() {
                    if c.t_max[i] <= 0.0 {
                        c.unoccluded[i] = false;
                        continue;
                    }
                    taken += 1;
                    let open = !accel.any_hit(c.origin[i], c.dir[i], c.t_max[i]);
                    c.unoccluded[i] = open;
                    clear += open as usize;
                }
                (taken, clear)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        Flow::new(taken, unoccluded)
    }
}
