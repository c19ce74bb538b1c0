//! Finds, for every visible point, this pass's photons within its pixel's radius: their
//! count M and the flux tau_M = beta sum f(wo, wi) power they bring. A photon counts only on
//! the visible point's side and plane (see `photons::GatherPoint::reflected`), so light does
//! not bleed round corners or through a wall from the photons on its far side.

use crate::integrators::sppm::ProgressiveState;
use crate::photons::GatherPoint;
use crate::pipeline::{Flow, System};
use glam::Vec3;
use rayon::prelude::*;

pub struct GatherPhotons;

impl System<ProgressiveState> for GatherPhotons {
    fn name(&self) -> &'static str {
        "gather_photons"
    }
    fn reads(&self) -> &'static [&'static str] {
        &[
            "photon_grid",
            "photons",
            "visible_points",
            "pixel_estimates.radius",
        ]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["pixel_estimates.pass_photons", "pixel_estimates.pass_flux"]
    }
    fn run(&self, s: &mut ProgressiveState) -> Flow {
        let scene = &s.data.scene;
        let visible = &s.visible;
        let photons = &s.photon_pass.tracing.photons;
        let points = &photons.p[..s.photon_pass.tracing.stored];
        let grid = s.grid.as_ref();
        let pixels = s.pixels;
        let found: usize = s
            .estimates
            .chunks_mut(0..pixels)
            .into_par_iter()
            .map(|e| {
                let mut found = 0;
                for i in 0..e.len() {
                    e.pass_photons[i] = 0;
                    e.pass_flux[i] = Vec3::ZERO;
                    let pixel = e.start + i;
                    let (Some(grid), Some(at)) = (grid, GatherPoint::of(scene, visible, pixel))
                    else {
                        continue;
                    };
                    let (mut m, mut flux) = (0u32, Vec3::ZERO);
                    grid.for_each_within(points, at.p, e.radius[i], |k| {
                        if let Some(v) = at.reflected(photons, k as usize) {
                            m += 1;
                            flux += v;
                        }
                    });
                    e.pass_photons[i] = m;
                    e.pass_flux[i] = visible.beta[pixel] * flux;
                    found += m as usize;
                }
                found
            })
            .sum();
        Flow::new(pixels, found)
    }
}
