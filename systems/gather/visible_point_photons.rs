//! Finds, for every visible point, this pass's photons within its pixel's radius: their
//! count M and the flux tau_M = beta sum f(wo, wi) power they bring. A photon counts only on
//! the visible point's side and plane and in its sight (see `photons::GatherPoint::reflected`),
//! so light does not bleed round corners, through a wall from the photons on its far side,
//! or under a wall from the next room's floor; and only if the path it makes with the camera
//! chain stays within the maximum depth.

use crate::components::PixelEstimates;
use crate::components::VisiblePoints;
use crate::photons::GatherPoint;
use crate::photons::HashGrid;
use crate::photons::PhotonTracing;
use crate::pipeline::Flow;
use crate::scene::SceneData;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

/// Visible points gathered per run of `gather_photons`: a loop of runs, `gathered` counting the
/// points done, with a stop point before each (a radius that takes in every photon makes a
/// gather minutes long, and a stop must not wait for it). Eight tasks of `CHUNK` points per
/// run, so both cores stay busy however unevenly the points' costs fall.
pub const GATHER_CHUNK: usize = 8 * crate::components::CHUNK;

pub struct GatherPhotons;

crate::system! {
    GatherPhotons = "gather_photons";
    read data: Arc<SceneData>, visible: VisiblePoints, tracing: PhotonTracing,
        grid: Option<HashGrid>, hit_points: usize, max_depth: u32;
    write estimates: PixelEstimates, gathered: usize;
    run {
        let photons = &tracing.photons;
        let points = &photons.p[..tracing.stored];
        let grid = grid.as_ref();
        let range = *gathered..(*gathered + GATHER_CHUNK).min(*hit_points);
        *gathered = range.end;
        let taken = range.len();
        let found: usize = estimates
            .chunks_mut(range)
            .into_par_iter()
            // One chunk per task: a pixel's cost is its photons in reach, which varies over
            // the image, and rayon's default split (a few pieces per thread) left a core
            // idle for a third of this loop.
            .with_max_len(1)
            .map(|e| {
                let mut found = 0;
                for i in 0..e.len() {
                    e.pass_photons[i] = 0;
                    e.pass_flux[i] = Vec3::ZERO;
                    let pixel = e.start + i;
                    let at = GatherPoint::of(data, visible, pixel, *max_depth);
                    let (Some(grid), Some(at)) = (grid, at) else {
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
        Flow::new(taken, found)
    }
}
