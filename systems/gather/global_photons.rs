//! Indirect light of PM from the global map. With final gathering (`gather_global_photons`),
//! a density estimate of all photons where each pixel's gather ray landed; without
//! (`gather_indirect_photons`), an estimate at the visible point of the photons that are
//! neither direct nor caustic (light sampling and the caustic map cover those).

use crate::components::photon_mapping::PmSettings;
use crate::components::{PhotonFlags, VisiblePoints};
use crate::photons::{MapQuery, PhotonMaps};
use crate::pipeline::Flow;
use crate::scene::SceneData;
use glam::DVec3;
use std::sync::Arc;

pub struct GatherGlobalPhotons;

crate::system! {
    GatherGlobalPhotons = "gather_global_photons";
    read data: Arc<SceneData>, settings: PmSettings, maps: Option<PhotonMaps>,
        points: VisiblePoints;
    write pass_radiance: Vec<DVec3>, nonfinite: u64;
    run {
        gather(data, settings, maps, points, |_| true, pass_radiance, nonfinite)
    }
}

pub struct GatherIndirectPhotons;

crate::system! {
    GatherIndirectPhotons = "gather_indirect_photons";
    read data: Arc<SceneData>, settings: PmSettings, maps: Option<PhotonMaps>,
        points: VisiblePoints;
    write pass_radiance: Vec<DVec3>, nonfinite: u64;
    run {
        let indirect =
            |f: PhotonFlags| !(f.has(PhotonFlags::DIRECT) || f.has(PhotonFlags::CAUSTIC));
        gather(data, settings, maps, points, indirect, pass_radiance, nonfinite)
    }
}

/// Adds the global map's estimate of the photons `keep` accepts at each point to its pixel.
fn gather(
    data: &SceneData,
    settings: &PmSettings,
    maps: &Option<PhotonMaps>,
    points: &VisiblePoints,
    keep: impl Fn(PhotonFlags) -> bool + Sync,
    pass_radiance: &mut [DVec3],
    nonfinite: &mut u64,
) -> Flow {
    let Some(maps) = maps else {
        return Flow::default();
    };
    let query = MapQuery {
        tree: &maps.global,
        index: None,
        photons: &maps.photons,
        k: settings.k,
        max_radius: settings.max_radius_in(data),
        scale: 1.0 / maps.emitted.max(1) as f32,
        max_depth: settings.max_depth,
    };
    let (made, dropped) = query.add_estimates(data, points, keep, pass_radiance);
    *nonfinite += dropped;
    Flow::new(points.capacity(), made)
}
