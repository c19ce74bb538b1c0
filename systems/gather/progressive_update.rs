//! The progressive radius and flux update of every pixel (Hachisuka, Ogaki and Jensen 2008):
//! of the M photons found this pass, a fraction alpha is kept, the radius shrinks so that
//! the density stays, and the flux is scaled to the smaller disc:
//!
//! N' = N + alpha M,  R' = R sqrt(N' / (N + M)),  tau' = (tau + tau_M) N' / (N + M)

use crate::components::PixelEstimates;
use crate::pipeline::Flow;
use glam::DVec3;
use rayon::prelude::*;

/// One pixel's update; returns the new (N, R, tau). A pass that found no photons changes
/// nothing.
#[inline]
pub fn progressive_update(
    n: f64,
    radius: f32,
    tau: DVec3,
    m: u32,
    tau_m: DVec3,
    alpha: f64,
) -> (f64, f32, DVec3) {
    if m == 0 {
        return (n, radius, tau);
    }
    let m = m as f64;
    let n_new = n + alpha * m;
    let ratio = n_new / (n + m);
    (
        n_new,
        (radius as f64 * ratio.sqrt()) as f32,
        (tau + tau_m) * ratio,
    )
}

pub struct UpdatePixelEstimates;

crate::system! {
    UpdatePixelEstimates = "update_pixel_estimates";
    read alpha: f32, points: usize, emitted: u64;
    write estimates: PixelEstimates, nonfinite: u64, photons_emitted: u64;
    run {
        let alpha = *alpha as f64;
        let pixels = *points;
        let (updated, dropped) = estimates
            .chunks_mut(0..pixels)
            .into_par_iter()
            .map(|e| {
                let (mut updated, mut nonfinite) = (0, 0);
                for i in 0..e.len() {
                    let tau_m = e.pass_flux[i].as_dvec3();
                    if !tau_m.is_finite() {
                        nonfinite += 1;
                        continue;
                    }
                    let (n, r, tau) = progressive_update(
                        e.photons[i],
                        e.radius[i],
                        e.flux[i],
                        e.pass_photons[i],
                        tau_m,
                        alpha,
                    );
                    updated += (e.pass_photons[i] > 0) as usize;
                    (e.photons[i], e.radius[i], e.flux[i]) = (n, r, tau);
                }
                (updated, nonfinite)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        *nonfinite += dropped;
        // The estimate divides by every photon emitted so far.
        *photons_emitted += emitted;
        Flow::new(pixels, updated)
    }
}
