//! Adds to each pixel's sum what its camera chain saw without photons: the emission it met
//! and its light sample, when unoccluded. NaN or Inf values are counted and dropped.

use crate::components::ShadowRays;
use crate::components::VisiblePoints;
use crate::pipeline::Flow;
use glam::DVec3;
use glam::Vec3;
use rayon::prelude::*;

pub struct AddDirectLight;

crate::system! {
    AddDirectLight = "add_direct_light";
    read visible: VisiblePoints, points: usize, shadow: ShadowRays;
    write direct: Vec<DVec3>, nonfinite: u64;
    run {
        let pixels = *points;
        let (lit, dropped) = direct[..pixels]
            .par_chunks_mut(crate::components::CHUNK)
            .enumerate()
            .map(|(k, sums)| {
                let (mut lit, mut nonfinite) = (0, 0);
                for (j, sum) in sums.iter_mut().enumerate() {
                    let i = k * crate::components::CHUNK + j;
                    let mut value = visible.emitted[i];
                    if shadow.t_max[i] > 0.0 && shadow.unoccluded[i] {
                        value += shadow.contribution[i];
                        lit += 1;
                    }
                    if value.is_finite() {
                        if value != Vec3::ZERO {
                            *sum += value.as_dvec3();
                        }
                    } else {
                        nonfinite += 1;
                    }
                }
                (lit, nonfinite)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        *nonfinite += dropped;
        Flow::new(pixels, lit)
    }
}
