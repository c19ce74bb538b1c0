//! Drops the subpaths that ended, keeping the live ones in slot order (so walkers stay in
//! increasing subpath order, which lets later bounces split the vertex stores by chunk), and
//! moves on to the next depth.

use crate::components::{gather_column, live_slots};
use crate::integrators::bdpt::BdptState;
use crate::pipeline::{Flow, System};

pub struct CompactSubpaths;

impl System<BdptState> for CompactSubpaths {
    fn name(&self) -> &'static str {
        "compact_subpaths"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["walkers.alive"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["walkers", "rays"]
    }
    fn run(&self, s: &mut BdptState) -> Flow {
        use std::mem::swap;
        let n = s.active;
        let mut order = std::mem::take(&mut s.scratch.order);
        live_slots(&s.walkers.alive[..n], &mut order);
        let scratch = &mut s.scratch;
        scratch.walkers.gather_from(&s.walkers, &order);
        gather_column(&mut scratch.rays.origin, &s.rays.origin, &order);
        gather_column(&mut scratch.rays.dir, &s.rays.dir, &order);
        swap(&mut s.walkers, &mut scratch.walkers);
        swap(&mut s.rays, &mut scratch.rays);
        s.active = order.len();
        s.scratch.order = order;
        s.depth += 1;
        Flow::new(n, s.active)
    }
}
