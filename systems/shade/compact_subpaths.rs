//! Drops the subpaths that ended, keeping the live ones in slot order (so walkers stay in
//! increasing subpath order, which lets later bounces split the vertex stores by chunk), and
//! moves on to the next depth.

use crate::components::Rays;
use crate::components::Walkers;
use crate::components::subpaths::Scratch;
use crate::components::{gather_column, live_slots};
use crate::pipeline::Flow;

pub struct CompactSubpaths;

crate::system! {
    CompactSubpaths = "compact_subpaths";
    write walkers: Walkers, rays: Rays, active: usize, depth: usize, scratch: Scratch;
    run {
        use std::mem::swap;
        let n = *active;
        let mut order = std::mem::take(&mut scratch.order);
        live_slots(&walkers.alive[..n], &mut order);
        scratch.walkers.gather_from(walkers, &order);
        gather_column(&mut scratch.rays.origin, &rays.origin, &order);
        gather_column(&mut scratch.rays.dir, &rays.dir, &order);
        swap(walkers, &mut scratch.walkers);
        swap(rays, &mut scratch.rays);
        *active = order.len();
        scratch.order = order;
        *depth += 1;
        Flow::new(n, *active)
    }
}
