//! Adds the wave's connections to the film: each sample's strategies with t >= 2 to its own
//! pixel; light-tracing splats (t = 1) to the pixels they project to. The film's sums are
//! exact, so the image never depends on how work was split between threads. With strategy images on, each strategy's share is also
//! summed on its own.

use crate::components::CHUNK;
use crate::integrators::bdpt::BdptState;
use crate::pipeline::Flow;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

pub struct AccumulateConnections;

crate::system! {
    AccumulateConnections = "accumulate_connections";
    on BdptState {
        read wave, shadow, connections, connection_start, connections_len, pixels, strategy_images = settings.strategy_images;
        write sample_radiance, film, strategy_sums;
    }
    run {
        let n = wave.len;
        let (conns, starts) = (connections, connection_start);
        sample_radiance[..n]
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
        debug_assert_eq!(*pixels as usize, film.width * film.height);
        film.add_wave(wave.first, &sample_radiance[..n]);
        let total = *connections_len;
        let mut splats = 0;
        for slot in 0..total {
            if conns.t[slot] == 1 && shadow.unoccluded[slot] {
                film
                    .add_splat(conns.pixel[slot] as usize, shadow.contribution[slot]);
                splats += 1;
            }
        }
        if *strategy_images {
            let size = film.width * film.height;
            for slot in 0..total {
                let value: Vec3 = shadow.contribution[slot];
                let visible = conns.s[slot] == 0 || shadow.unoccluded[slot];
                if !visible || value == Vec3::ZERO || !value.is_finite() {
                    continue;
                }
                let sums = strategy_sums
                    .entry((conns.s[slot], conns.t[slot]))
                    .or_insert_with(|| vec![DVec3::ZERO; size]);
                sums[conns.pixel[slot] as usize] += value.as_dvec3();
            }
        }
        Flow::new(n + splats, n + splats)
    }
}
