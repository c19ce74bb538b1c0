//! Joins the camera and light subpaths of every sample by each strategy (s, t): computes the
//! strategy's contribution and MIS weight, and for every strategy but s = 0 a shadow ray for
//! the segment it adds. The connections of a sample take consecutive slots (counted from the
//! subpath lengths first), so the whole wave's shadow rays form one batch in sample order.
//!
//! Strategy s = 1 samples a fresh point on a light for each camera vertex (next-event
//! estimation); t = 1 projects a light vertex onto the image (light tracing: it lands in
//! whichever pixel it projects to).

use crate::components::{Connections, ShadowRays, split_ranges};
use crate::geometry::spawn_ray_to;
use crate::integrators::bdpt::{
    BdptSettings, BdptState, CONNECT_CHUNK, DIM_LIGHT_PICK, DIM_LIGHT_POINT, StrategyFilter,
    camera_vertex_dim,
};
use crate::path::{PathContext, Vertex, VertexKind};
use crate::pipeline::Flow;
use crate::sampling::Stream;
use glam::Vec3;
use rayon::prelude::*;

pub struct ConnectStrategies;

/// Strategies (s, t) a sample with `nc` camera and `nl` light vertices may use, in the order
/// their connections are laid out: t outer, s inner.
#[inline]
fn strategies(
    settings: &BdptSettings,
    nc: usize,
    nl: usize,
) -> impl Iterator<Item = (usize, usize)> + '_ {
    (1..=nc)
        .flat_map(move |t| (0..=nl).map(move |s| (s, t)))
        .filter(|&(s, t)| settings.uses(s, t))
}

crate::system! {
    ConnectStrategies = "connect_strategies";
    on BdptState {
        read wave, capacity, settings, numbers = sampler, subpath_len, data, vertices, pixels, multiplex, chosen_s, sample_pixel;
        write connection_start, connections_len, shadow, connections, sample_radiance;
    }
    run {
        let n = wave.len;
        let cap = *capacity;
        let settings = *settings;
        let sampler = numbers.sampler();
        let sampler = &sampler;
        // A multiplexed sample keeps its one strategy, its weight times the strategy count.
        let multiplexed = !multiplex.is_empty();
        let keeps = |k: usize, (s, t): (usize, usize)| {
            !multiplexed || (s == chosen_s[k] as usize && s + t == multiplex[k] as usize + 2)
        };
        // Slots per sample, then where each sample's begin.
        let lens = subpath_len;
        let counts: Vec<usize> = (0..n)
            .into_par_iter()
            .with_min_len(CONNECT_CHUNK)
            .map(|k| {
                strategies(&settings, lens[k] as usize, lens[cap + k] as usize)
                    .filter(|&st| keeps(k, st))
                    .count()
            })
            .collect();
        let starts = &mut *connection_start;
        starts[0] = 0;
        for k in 0..n {
            starts[k + 1] = starts[k] + counts[k];
        }
        let total = starts[n];
        *connections_len = total;
        if shadow.capacity() < total {
            // Grows to the largest wave seen, then is reused.
            *shadow = ShadowRays::new(total);
            *connections = Connections::new(total);
        }

        let ctx = PathContext::new(&data.scene);
        let vertices: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
        let starts = &*connection_start;
        let chunk_starts: Vec<usize> = (0..n).step_by(CONNECT_CHUNK).map(|k| starts[k]).collect();
        let shadow = shadow.split_mut(&chunk_starts, total);
        let conns = connections.split_mut(&chunk_starts, total);
        let radiance = split_ranges(
            sample_radiance,
            &(0..n).step_by(CONNECT_CHUNK).collect::<Vec<_>>(),
            n,
        );
        let (wave, pixels) = (*wave, *pixels);
        let weighted = settings.strategies == StrategyFilter::All;
        let emitters = &data.scene.emitters;
        let scene = &data.scene;
        let has_light = !emitters.triangle.is_empty();
        let made: usize = shadow
            .into_par_iter()
            .zip(conns)
            .zip(radiance)
            .enumerate()
            .map(|(c, ((sh, cn), radiance))| {
                let mut camera: Vec<Vertex> = Vec::new();
                let mut light: Vec<Vertex> = Vec::new();
                let mut made = 0;
                let first_sample = c * CONNECT_CHUNK;
                for (local, out) in radiance.iter_mut().enumerate() {
                    *out = Vec3::ZERO;
                    let k = first_sample + local;
                    let pixel = sample_pixel[k];
                    let key = numbers.key(sampler, Stream::Connection, wave, pixels, k);
                    let strategy_count = if multiplexed { multiplex[k] as f32 + 2.0 } else { 1.0 };
                    let (nc, nl) = (lens[k] as usize, lens[cap + k] as usize);
                    camera.clear();
                    light.clear();
                    for (d, store) in vertices.iter().enumerate().take(nc) {
                        camera.push(Vertex::from_store(store, k, d));
                    }
                    for (d, store) in vertices.iter().enumerate().take(nl) {
                        light.push(Vertex::from_store(store, cap + k, d));
                    }
                    let slots = starts[k] - sh.start..;
                    let kept = strategies(&settings, nc, nl).filter(|&st| keeps(k, st));
                    for (this, (si, ti)) in slots.zip(kept) {
                        sh.t_max[this] = 0.0;
                        sh.contribution[this] = Vec3::ZERO;
                        cn.sample[this] = k as u32;
                        cn.pixel[this] = pixel;
                        cn.s[this] = si as u16;
                        cn.t[this] = ti as u16;
                        // s = 1 with t >= 2: a fresh light sample at z_{t-1}.
                        let sampled;
                        let light_side: &[Vertex] = if si == 1 && ti >= 2 {
                            if !has_light {
                                continue;
                            }
                            let dim = camera_vertex_dim(ti - 1);
                            let light = scene.sample_emitter(
                                sampler.get(key, dim + DIM_LIGHT_PICK),
                                sampler.get2(key, dim + DIM_LIGHT_POINT),
                            );
                            let (e, tri, sp) = (light.emitter, light.triangle, light.point);
                            let pdf_origin = light.pdf_area;
                            sampled = [Vertex {
                                kind: VertexKind::Light,
                                p: sp.p,
                                p_error: sp.p_error,
                                ng: sp.ng,
                                ns: sp.ng,
                                triangle: tri,
                                beta: emitters.radiance[e] / pdf_origin,
                                pdf_fwd: pdf_origin,
                                pdf_rev: 0.0,
                                delta: false,
                            }];
                            &sampled
                        } else {
                            &light
                        };
                        let Some(conn) = ctx.connect(&camera, light_side, si, ti) else {
                            continue;
                        };
                        let weight = if weighted {
                            ctx.mis_weight(&camera, light_side, si, ti, settings.mis)
                                * strategy_count
                        } else {
                            strategy_count
                        };
                        let contribution = conn.contribution * weight;
                        if contribution == Vec3::ZERO {
                            continue;
                        }
                        sh.contribution[this] = contribution;
                        if let Some(p) = conn.pixel {
                            cn.pixel[this] = p as u32;
                        }
                        match conn.segment {
                            Some((y, z)) => {
                                let (origin, dir, t_max) =
                                    spawn_ray_to(y.p, y.p_error, y.ng, z.p, z.p_error, z.ng);
                                sh.origin[this] = origin;
                                sh.dir[this] = dir;
                                sh.t_max[this] = t_max;
                                made += 1;
                            }
                            // s = 0: nothing to test; it reaches the sample's own pixel.
                            None => *out += contribution,
                        }
                    }
                }
                made
            })
            .sum();
        Flow::new(n, made)
    }
}
