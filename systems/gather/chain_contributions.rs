//! Gathers each evaluated sample's connections into its chain's proposal contributions: the
//! strategies with t >= 2 (and s = 0) summed at the sample's own pixel, and each unoccluded
//! light-tracing splat (t = 1) at the pixel it projects to. The target is the luminance of
//! them all (pssmlt: the whole BDPT sample; mmlt: its one strategy, MIS weight included).
//! The same selection of connections as `accumulate_connections`, into the chains instead
//! of the film; each with where it landed, for a filter wider than a pixel.

use crate::components::Connections;
use crate::components::ShadowRays;
use crate::components::Wave;
use crate::math::luminance;
use crate::mlt::Contributions;
use crate::pipeline::Flow;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

pub struct GatherChainContributions;

crate::system! {
    GatherChainContributions = "gather_chain_contributions";
    read wave: Wave, shadow: ShadowRays, connections: Connections, starts: Vec<usize>,
        radiance: Vec<Vec3>, sample_pixel: Vec<u32>, sample_raster: Vec<Vec2>, multiplex: Vec<u32>,
        chosen_s: Vec<u16>;
    write out: Contributions;
    run {
        let n = wave.len;
        // The sample's own pixel and one per light-tracing splat: widen the columns for the
        // rare deep sample that has more than they hold (a multiplexed sample has one).
        let most = if !multiplex.is_empty() { 1 } else { (0..n)
            .into_par_iter()
            .with_min_len(crate::components::CHUNK)
            .map(|k| {
                1 + (starts[k]..starts[k + 1])
                    .filter(|&slot| connections.t[slot] == 1 && shadow.unoccluded[slot])
                    .count()
            })
            .max()
            .unwrap_or(0) };
        out.ensure_stride(most);
        let made: usize = out
            .par_chunks_mut()
            .map(|mut chunk| {
                let mut made = 0;
                for local in 0..chunk.len() {
                    let k = chunk.first_chain + local;
                    chunk.clear(local);
                    if k >= n {
                        continue;
                    }
                    // A multiplexed sample's depth (drawn, in the tail group) and strategy.
                    chunk.strategy[local] = match multiplex.get(k) {
                        Some(&depth) => (depth, chosen_s[k]),
                        None => (0, 0),
                    };
                    let mut own = radiance[k];
                    let mut total = Vec3::ZERO;
                    for slot in starts[k]..starts[k + 1] {
                        if connections.t[slot] >= 2 && shadow.unoccluded[slot] {
                            own += shadow.contribution[slot];
                        }
                    }
                    if own != Vec3::ZERO {
                        chunk.push_at(local, sample_pixel[k], sample_raster[k], own);
                        total += own;
                    }
                    for slot in starts[k]..starts[k + 1] {
                        if connections.t[slot] == 1 && shadow.unoccluded[slot] {
                            let v = shadow.contribution[slot];
                            chunk.push_at(local, connections.pixel[slot], connections.raster[slot], v);
                            total += v;
                        }
                    }
                    chunk.target[local] = luminance(total);
                    made += (chunk.target[local] != 0.0) as usize;
                }
                made
            })
            .sum();
        Flow::new(n, made)
    }
}
