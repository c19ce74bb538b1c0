//! Finds, for every visible point, this pass's photons within its pixel's radius: their
//! count M and the flux tau_M = beta sum f(wo, wi) power they bring. A photon counts only on
//! the visible point's side and plane (its surface's normal within 60 degrees of the visible
//! point's, and arriving on the side the camera sees), so light does not bleed through thin
//! walls or round corners.

use crate::components::NO_VISIBLE_POINT;
use crate::integrators::sppm::ProgressiveState;
use crate::math::Frame;
use crate::pipeline::{Flow, System};
use glam::Vec3;
use rayon::prelude::*;

/// Least |cos| between a photon's surface normal and the visible point's.
pub const NORMAL_COSINE: f32 = 0.5;

pub struct GatherPhotons;

impl System<ProgressiveState> for GatherPhotons {
    fn name(&self) -> &'static str {
        "gather_photons"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["photon_grid", "photons", "visible_points", "pixel_estimates.radius"]
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
                    let tri = visible.triangle[pixel];
                    let Some(grid) = grid else { continue };
                    if tri == NO_VISIBLE_POINT {
                        continue;
                    }
                    let material = scene.materials[scene.triangles.material[tri as usize] as usize];
                    let (p, ng, wo) = (visible.p[pixel], visible.ng[pixel], visible.wo[pixel]);
                    let frame = Frame::from_normal(visible.ns[pixel]);
                    let wo_local = frame.to_local(wo);
                    let (mut m, mut flux) = (0u32, Vec3::ZERO);
                    grid.for_each_within(points, p, e.radius[i], |k| {
                        let k = k as usize;
                        let wi = photons.wi[k];
                        if photons.ng[k].dot(ng).abs() < NORMAL_COSINE || wi.dot(ng) <= 0.0 {
                            return;
                        }
                        m += 1;
                        flux += material.eval(wo_local, frame.to_local(wi)) * photons.power[k];
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
