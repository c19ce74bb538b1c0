//! Indirect light of PM from the global map: with final gathering, a density estimate of all
//! photons where each pixel's gather ray landed; without, an estimate at the visible point
//! of the photons that are neither direct nor caustic (light sampling and the caustic map
//! cover those).

use crate::components::PhotonFlags;
use crate::integrators::pm::PmState;
use crate::photons::{GatherPoint, Nearest, density_estimate};
use crate::pipeline::{Flow, System};
use rayon::prelude::*;

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
        let scene = &s.data.scene;
        let k = s.settings.k;
        let max_radius = s.settings.max_radius_in(&s.data);
        let scale = 1.0 / maps.emitted.max(1) as f32;
        let keep = move |f: PhotonFlags| {
            final_gather || !(f.has(PhotonFlags::DIRECT) || f.has(PhotonFlags::CAUSTIC))
        };
        let chunk = crate::components::CHUNK;
        let (gathered, nonfinite) = s
            .pass_radiance
            .par_chunks_mut(chunk)
            .enumerate()
            .map(|(c, out)| {
                let mut nearest = Nearest::new(k, max_radius);
                let (mut gathered, mut nonfinite) = (0, 0);
                for (j, sum) in out.iter_mut().enumerate() {
                    let pixel = c * chunk + j;
                    let Some(at) = GatherPoint::of(scene, points, pixel) else {
                        continue;
                    };
                    let l = density_estimate(
                        &maps.global,
                        None,
                        &maps.photons,
                        &at,
                        keep,
                        &mut nearest,
                    );
                    let value = points.beta[pixel] * l * scale;
                    if value.is_finite() {
                        *sum += value.as_dvec3();
                    } else {
                        nonfinite += 1;
                    }
                    gathered += 1;
                }
                (gathered, nonfinite)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        s.nonfinite += nonfinite;
        Flow::new(s.pixels, gathered)
    }
}
