//! Builds the hash grid over this pass's photons that `gather_photons` queries, with cells
//! of the largest gather radius of any pixel (radii only shrink, so cells do too).

use crate::components::NO_VISIBLE_POINT;
use crate::photons::HashGrid;
use crate::photons::PhotonTracing;
use crate::pipeline::Flow;

pub struct BuildPhotonGrid;

crate::system! {
    BuildPhotonGrid = "build_photon_grid";
    read radius: Vec<f32>, triangle: Vec<u32>, points: usize, tracing: PhotonTracing;
    write grid: Option<HashGrid>;
    run {
        let radius = radius[..*points]
            .iter()
            .zip(&triangle[..*points])
            .filter(|(_, t)| **t != NO_VISIBLE_POINT)
            .fold(0.0f32, |m, (r, _)| m.max(*r));
        let t = tracing;
        *grid = (radius > 0.0 && t.stored > 0)
            .then(|| HashGrid::build(&t.photons.p[..t.stored], radius));
        Flow::new(t.stored, t.stored)
    }
}
