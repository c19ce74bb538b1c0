//! Adds to each pixel's sum what its camera chain saw without photons: the emission it met
//! and its light sample, when unoccluded. NaN or Inf values are counted and dropped.

use crate::pipeline::{Flow, System};
use crate::systems::connect::sample_direct_light::VisiblePointLights;
use glam::Vec3;
use rayon::prelude::*;

pub struct AddDirectLight;

impl<S: VisiblePointLights + Send> System<S> for AddDirectLight {
    fn name(&self) -> &'static str {
        "add_direct_light"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["visible_points.emitted", "shadow_rays"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["direct"]
    }
    fn run(&self, state: &mut S) -> Flow {
        let q = state.direct_light_queue();
        let (visible, shadow) = (q.visible, &*q.shadow);
        let pixels = visible.capacity();
        let (lit, nonfinite) = q
            .direct
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
        *q.nonfinite += nonfinite;
        Flow::new(pixels, lit)
    }
}
