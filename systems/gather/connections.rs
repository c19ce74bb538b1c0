//! Adds the wave's connections to the film: each sample's strategies with t >= 2 to its own
//! pixel, in sample order; light-tracing splats (t = 1) to the pixels they project to, in
//! connection order. Both orders are fixed by the wave, so the image never depends on how
//! work was split between threads. With strategy images on, each strategy's share is also
//! summed on its own.

use crate::components::CHUNK;
use crate::integrators::bdpt::BdptState;
use crate::pipeline::{Flow, System};
use glam::{DVec3, Vec3};
use rayon::prelude::*;

pub struct AccumulateConnections;

impl System<BdptState> for AccumulateConnections {
    fn name(&self) -> &'static str {
        "accumulate_connections"
    }
    fn reads(&self) -> &'static [&'static str] {
        &[
            "shadow_rays",
            "connections",
            "connection_start",
            "sample_radiance",
        ]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["film", "strategy_sums"]
    }
    fn run(&self, s: &mut BdptState) -> Flow {
        let n = s.wave.len;
        let (shadow, conns, starts) = (&s.shadow, &s.connections, &s.connection_start);
        s.sample_radiance[..n]
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, out)| {
                for (i, value) in out.iter_mut().enumerate() {
                    let k = c * CHUNK + i;
                    for slot in starts[k]..starts[k + 1] {
                        if conns.t[slot] >= 2 && shadow.unoccluded[slot] {
                            *value += shadow.contribution[slot];
                        }
                    }
                }
            });
        let (first, pixels) = (s.wave.first, s.pixels);
        for (k, &value) in s.sample_radiance[..n].iter().enumerate() {
            s.film
                .add_sample(((first + k as u64) % pixels) as usize, value);
        }
        let total = s.connections_len;
        let mut splats = 0;
        for slot in 0..total {
            if conns.t[slot] == 1 && shadow.unoccluded[slot] {
                s.film
                    .add_splat(conns.pixel[slot] as usize, shadow.contribution[slot]);
                splats += 1;
            }
        }
        if s.settings.strategy_images {
            let size = s.film.width * s.film.height;
            for slot in 0..total {
                let value: Vec3 = shadow.contribution[slot];
                let visible = conns.s[slot] == 0 || shadow.unoccluded[slot];
                if !visible || value == Vec3::ZERO || !value.is_finite() {
                    continue;
                }
                let sums = s
                    .strategy_sums
                    .entry((conns.s[slot], conns.t[slot]))
                    .or_insert_with(|| vec![DVec3::ZERO; size]);
                sums[conns.pixel[slot] as usize] += value.as_dvec3();
            }
        }
        Flow::new(n + splats, n + splats)
    }
}
