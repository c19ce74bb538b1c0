//! Caustics at PM's visible points: a density estimate of the k nearest caustic photons.

use crate::integrators::pm::PmState;
use crate::photons::{GatherPoint, Nearest, density_estimate};
use crate::pipeline::{Flow, System};
use rayon::prelude::*;

pub struct GatherCaustics;

impl System<PmState> for GatherCaustics {
    fn name(&self) -> &'static str {
        "gather_caustics"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["photon_maps", "visible_points"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["pass_radiance"]
    }
    fn run(&self, s: &mut PmState) -> Flow {
        let Some(maps) = &s.maps else {
            return Flow::default();
        };
        let Some((tree, index)) = &maps.caustic else {
            return Flow::default();
        };
        let (scene, visible) = (&s.data.scene, &s.visible);
        let k = s.settings.k;
        let max_radius = s.settings.max_radius_in(&s.data);
        let scale = 1.0 / maps.emitted.max(1) as f32;
        let chunk = crate::components::CHUNK;
        let (gathered, nonfinite) = s
            .pass_radiance
            .par_chunks_mut(chunk)
            .enumerate()
            .map(|(c, out)| {
                let mut nearest = Nearest::new(k, max_radius);
                let (mut gathered, mut nonfinite) = (0, 0);
                for (j, sum) in out.iter_mut().enumerate() {
                    let pixel = c * chunk + j;
                    let Some(at) = GatherPoint::of(scene, visible, pixel) else {
                        continue;
                    };
                    let l = density_estimate(
                        tree,
                        Some(index),
                        &maps.photons,
                        &at,
                        |_| true,
                        &mut nearest,
                    );
                    let value = visible.beta[pixel] * l * scale;
                    if value.is_finite() {
                        *sum += value.as_dvec3();
                    } else {
                        nonfinite += 1;
                    }
                    gathered += 1;
                }
                (gathered, nonfinite)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        s.nonfinite += nonfinite;
        Flow::new(s.pixels, gathered)
    }
}
