//! Caustics at PM's visible points: a density estimate of the k nearest caustic photons.

use crate::integrators::pm::PmState;
use crate::photons::MapQuery;
use crate::pipeline::{Flow, System};

pub struct GatherCaustics;

impl System<PmState> for GatherCaustics {
    fn name(&self) -> &'static str {
        "gather_caustics"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["photon_maps", "visible_points"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["pass_radiance"]
    }
    fn run(&self, s: &mut PmState) -> Flow {
        let Some(maps) = &s.maps else {
            return Flow::default();
        };
        let Some((tree, index)) = &maps.caustic else {
            return Flow::default();
        };
        let query = MapQuery {
            tree,
            index: Some(index),
            photons: &maps.photons,
            k: s.settings.k,
            max_radius: s.settings.max_radius_in(&s.data),
            scale: 1.0 / maps.emitted.max(1) as f32,
        };
        let (made, nonfinite) =
            query.add_estimates(&s.data.scene, &s.visible, |_| true, &mut s.pass_radiance);
        s.nonfinite += nonfinite;
        Flow::new(s.pixels, made)
    }
}
