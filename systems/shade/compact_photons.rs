//! Drops the photons that ended, keeping the rest in slot order.

use crate::components::{gather_column, live_slots};
use crate::photons::PhotonTracing;
use crate::pipeline::Flow;

pub struct CompactPhotons;

crate::system! {
    CompactPhotons = "compact_photons";
    write tracing: PhotonTracing;
    run {
        use std::mem::swap;
        let t = tracing;
        let n = t.active;
        let mut order = std::mem::take(&mut t.order);
        live_slots(&t.walkers.alive[..n], &mut order);
        t.scratch_walkers.gather_from(&t.walkers, &order);
        gather_column(&mut t.scratch_rays.origin, &t.rays.origin, &order);
        gather_column(&mut t.scratch_rays.dir, &t.rays.dir, &order);
        swap(&mut t.walkers, &mut t.scratch_walkers);
        swap(&mut t.rays, &mut t.scratch_rays);
        t.active = order.len();
        t.order = order;
        Flow::new(n, t.active)
    }
}
