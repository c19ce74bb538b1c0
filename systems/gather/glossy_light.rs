//! Adds to each pixel the light sampled at the glossy surfaces its camera chains followed
//! (shadow slots `points..points + glossy_points`), when unoccluded: PM's pass radiance, or
//! PPM's and SPPM's per-pixel sum over passes. NaN or Inf values are counted and dropped.

use crate::components::ShadowRays;
use crate::components::VisiblePoints;
use crate::pipeline::Flow;
use glam::DVec3;

pub struct AddGlossyLight;

crate::system! {
    AddGlossyLight = "add_glossy_light";
    read glossy: VisiblePoints, glossy_points: usize, points: usize, shadow: ShadowRays;
    write sums: Vec<DVec3>, nonfinite: u64;
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
