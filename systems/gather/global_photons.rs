//! Indirect light of PM from the global map: with final gathering, a density estimate of all
//! photons where each pixel's gather ray landed; without, an estimate at the visible point
//! of the photons that are neither direct nor caustic (light sampling and the caustic map
//! cover those).

use crate::components::PhotonFlags;
use crate::integrators::pm::PmState;
use crate::photons::MapQuery;
use crate::pipeline::{Flow, System};

pub struct GatherGlobalPhotons;

impl System<PmState> for GatherGlobalPhotons {
    fn name(&self) -> &'static str {
        "gather_global_photons"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["photon_maps", "visible_points", "gather_points"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["pass_radiance"]
    }
    fn run(&self, s: &mut PmState) -> Flow {
        let Some(maps) = &s.maps else {
            return Flow::default();
        };
        let final_gather = s.settings.final_gather;
        let points = if final_gather {
            &s.gather_points
        } else {
            &s.visible
        };
        let query = MapQuery {
            tree: &maps.global,
            index: None,
            photons: &maps.photons,
            k: s.settings.k,
            max_radius: s.settings.max_radius_in(&s.data),
            scale: 1.0 / maps.emitted.max(1) as f32,
        };
        let keep = |f: PhotonFlags| {
            final_gather || !(f.has(PhotonFlags::DIRECT) || f.has(PhotonFlags::CAUSTIC))
        };
        let (made, nonfinite) =
            query.add_estimates(&s.data.scene, points, keep, &mut s.pass_radiance);
        s.nonfinite += nonfinite;
        Flow::new(s.pixels, made)
    }
}
