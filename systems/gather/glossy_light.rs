//! Adds to each pixel the light sampled at the glossy surfaces its camera chains followed
//! (shadow slots `points..points + glossy_points`), when unoccluded: PM's pass radiance, or
//! PPM's and SPPM's per-pixel sum over passes. NaN or Inf values are counted and dropped.

use crate::integrators::{pm::PmState, sppm::ProgressiveState};
use crate::pipeline::Flow;

pub struct AddGlossyLight;

crate::system! {
    AddGlossyLight = "add_glossy_light";
    on PmState {
        read glossy = camera_walk.glossy, glossy_points = camera_walk.glossy_points, points = camera_walk.points, shadow;
        write sums = pass_radiance, nonfinite;
    }
    on ProgressiveState {
        read glossy = camera_walk.glossy, glossy_points = camera_walk.glossy_points, points = camera_walk.points, shadow;
        write sums = glossy_direct, nonfinite;
    }
    run {
        // Serial: several glossy points may add to one pixel, in their order.
        let mut lit = 0;
        for k in 0..*glossy_points {
            let slot = *points + k;
            if !(shadow.t_max[slot] > 0.0 && shadow.unoccluded[slot]) {
                continue;
            }
            let value = shadow.contribution[slot];
            if value.is_finite() {
                sums[glossy.pixel[k] as usize] += value.as_dvec3();
                lit += 1;
            } else {
                *nonfinite += 1;
            }
        }
        Flow::new(*glossy_points, lit)
    }
}
