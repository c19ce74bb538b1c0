//! Builds the hash grid over this pass's photons that `gather_photons` queries, with cells
//! of the largest gather radius of any pixel (radii only shrink, so cells do too).

use crate::components::NO_VISIBLE_POINT;
use crate::integrators::sppm::ProgressiveState;
use crate::photons::HashGrid;
use crate::pipeline::{Flow, System};

pub struct BuildPhotonGrid;

impl System<ProgressiveState> for BuildPhotonGrid {
    fn name(&self) -> &'static str {
        "build_photon_grid"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["photons.p", "pixel_estimates.radius"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["photon_grid"]
    }
    fn run(&self, s: &mut ProgressiveState) -> Flow {
        let radius = s
            .estimates
            .radius
            .iter()
            .zip(&s.visible.triangle)
            .filter(|(_, t)| **t != NO_VISIBLE_POINT)
            .fold(0.0f32, |m, (r, _)| m.max(*r));
        let t = &s.photon_pass.tracing;
        s.grid = (radius > 0.0 && t.stored > 0)
            .then(|| HashGrid::build(&t.photons.p[..t.stored], radius));
        Flow::new(t.stored, t.stored)
    }
}
