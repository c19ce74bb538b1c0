//! Caustics at PM's visible points: a density estimate of the k nearest caustic photons.

use crate::integrators::pm::PmState;
use crate::photons::MapQuery;
use crate::pipeline::Flow;

pub struct GatherCaustics;

crate::system! {
    GatherCaustics = "gather_caustics";
    on PmState {
        read data, settings, maps, visible = camera_walk.visible, pixels;
        write pass_radiance, nonfinite;
    }
    run {
        let Some(maps) = maps else {
            return Flow::default();
        };
        let Some((tree, index)) = &maps.caustic else {
            return Flow::default();
        };
        let query = MapQuery {
            tree,
            index: Some(index),
            photons: &maps.photons,
            k: settings.k,
            max_radius: settings.max_radius_in(data),
            scale: 1.0 / maps.emitted.max(1) as f32,
        };
        let (made, dropped) =
            query.add_estimates(data, visible, |_| true, pass_radiance);
        *nonfinite += dropped;
        Flow::new(*pixels, made)
    }
}
