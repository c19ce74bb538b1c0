//! Adds the contribution of every unoccluded shadow ray to the path that cast it.

use crate::integrators::pt::PtState;
use crate::pipeline::{Flow, System};
use rayon::prelude::*;

pub struct ApplyShadowContributions;

impl System<PtState> for ApplyShadowContributions {
    fn name(&self) -> &'static str {
        "apply_shadow_contributions"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["shadow_rays.unoccluded", "shadow_rays.contribution"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["paths.radiance"]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let shadow = &s.shadow;
        let range = s.ranges.non_delta();
        let taken = range.len();
        let applied: usize = s
            .paths
            .chunks_mut(range)
            .into_par_iter()
            .map(|p| {
                let mut applied = 0;
                let shadow = shadow.view(p.start..p.start + p.len());
                for i in 0..p.len() {
                    if shadow.unoccluded[i] {
                        p.radiance[i] += shadow.contribution[i];
                        applied += 1;
                    }
                }
                applied
            })
            .sum();
        Flow::new(taken, applied)
    }
}
