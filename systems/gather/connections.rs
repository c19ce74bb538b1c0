//! Adds the wave's connections to the film: each sample's strategies with t >= 2 to its own
//! pixel; light-tracing splats (t = 1) to the pixels they project to. The film's sums are
//! exact, so the image never depends on how work was split between threads. With strategy
//! images on, each strategy's share is also summed on its own.

use crate::components::CHUNK;
use crate::components::Connections;
use crate::components::ShadowRays;
use crate::components::Wave;
use crate::film::Film;
use crate::film::Splats;
use crate::pipeline::Flow;
use glam::{DVec3, Vec2, Vec3};
use rayon::prelude::*;
use std::collections::BTreeMap;

pub struct AccumulateConnections;

crate::system! {
    AccumulateConnections = "accumulate_connections";
    read wave: Wave, shadow: ShadowRays, connections: Connections, connection_start: Vec<usize>,
        connections_len: usize, pixels: u64, sample_raster: Vec<Vec2>, strategy_images: bool;
    write sample_radiance: Vec<Vec3>, film: Film, strategy_sums: BTreeMap<(u16, u16), Vec<DVec3>>;
    run {
        let n = wave.len;
        let (conns, starts) = (connections, connection_start);
        // One pass over the slots, in parallel chunks of samples: strategies with t >= 2 to
        // the sample's own value (in slot order, as always), light-tracing splats (t = 1)
        // gathered for the film, which adds them block by block in parallel.
        let batches: Vec<Splats> = sample_radiance[..n]
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, out)| {
                let mut splats = Splats::default();
                for (i, value) in out.iter_mut().enumerate() {
                    let k = c * CHUNK + i;
                    for slot in starts[k]..starts[k + 1] {
                        if !shadow.unoccluded[slot] {
                            continue;
                        }
                        if conns.t[slot] >= 2 {
                            *value += shadow.contribution[slot];
                        } else {
                            splats.push_at(
                                conns.pixel[slot] as usize,
                                conns.raster[slot],
                                shadow.contribution[slot],
                            );
                        }
                    }
                }
                splats
            })
            .collect();
        debug_assert_eq!(*pixels as usize, film.width * film.height);
        // Each sample where its camera ray left the film (the film's filter weighs it there).
        // The film takes positions on the whole film (a crop's offset added).
        let first = wave.first;
        let origin = Vec2::new(film.origin().0 as f32, film.origin().1 as f32);
        let raster = |g: u64| sample_raster[(g - first) as usize] + origin;
        film.add_wave_at(wave.first, &sample_radiance[..n], &raster);
        film.add_splats(&batches);
        let splats: usize = batches.iter().map(Splats::len).sum();
        let total = *connections_len;
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
