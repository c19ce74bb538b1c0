//! Caustics at PM's visible points: a density estimate of the k nearest caustic photons.

use crate::components::VisiblePoints;
use crate::components::photon_mapping::PmSettings;
use crate::photons::MapQuery;
use crate::photons::PhotonMaps;
use crate::pipeline::Flow;
use crate::scene::SceneData;
use glam::DVec3;
use std::sync::Arc;

pub struct GatherCaustics;

crate::system! {
    GatherCaustics = "gather_caustics";
    read data: Arc<SceneData>, settings: PmSettings, maps: Option<PhotonMaps>,
        visible: VisiblePoints, pixels: usize;
    write pass_radiance: Vec<DVec3>, nonfinite: u64;
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
            max_depth: settings.max_depth,
        };
        let (made, dropped) =
            query.add_estimates(data, visible, |_| true, pass_radiance);
        *nonfinite += dropped;
        Flow::new(*pixels, made)
    }
}
