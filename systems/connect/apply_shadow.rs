//! Adds the contribution of every unoccluded shadow ray to the path that cast it.

use crate::components::CHUNK;
use crate::components::ShadowRays;
use crate::pipeline::Flow;
use glam::Vec3;
use rayon::prelude::*;

pub struct ApplyShadowContributions;

crate::system! {
    ApplyShadowContributions = "apply_shadow_contributions";
    read shadow: ShadowRays, len: usize;
    write radiance: Vec<Vec3>;
    run {
        let taken = *len;
        let applied: usize = radiance[..taken]
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, radiance)| {
                let mut applied = 0;
                let start = c * CHUNK;
                let shadow = shadow.view(start..start + radiance.len());
                for (i, radiance) in radiance.iter_mut().enumerate() {
                    if shadow.unoccluded[i] {
                        *radiance += shadow.contribution[i];
                        applied += 1;
                    }
                }
                applied
            })
            .sum();
        Flow::new(taken, applied)
    }
}
