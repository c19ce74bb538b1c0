//! Multiplies each unoccluded connection's contribution by its MIS weight (and a multiplexed
//! sample's strategy count). `connect_strategies` leaves the weight of connections with a
//! shadow ray to this system, run after the rays are traced, so the weight's ratio walk (four
//! BSDF densities at the joint, then one step per path vertex) is paid only by connections
//! that reach the film: on door_ajar 4% of them. The arithmetic is the one the connection
//! would have done at once, so the image is the same bit for bit.

use crate::integrators::bdpt::{BdptState, CONNECT_CHUNK};
use crate::path::{PathContext, Vertex};
use crate::pipeline::Flow;
use crate::sampling::Stream;
use crate::systems::connect::strategies::{connection_weight, sampled_light_vertex};
use rayon::prelude::*;

pub struct WeighConnections;

crate::system! {
    WeighConnections = "weigh_connections";
    on BdptState {
        read wave, capacity, settings, numbers = sampler, subpath_len, data, vertices, pixels, multiplex, connection_start, connections_len, connections;
        write shadow;
    }
    run {
        let n = wave.len;
        let cap = *capacity;
        let settings = *settings;
        let sampler = numbers.sampler();
        let sampler = &sampler;
        let (wave, pixels) = (*wave, *pixels);
        let starts = connection_start;
        let total = *connections_len;
        let ctx = PathContext::new(&data.scene);
        let scene = &data.scene;
        let vertices: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
        let lens = subpath_len;
        let chunk_starts: Vec<usize> = (0..n).step_by(CONNECT_CHUNK).map(|k| starts[k]).collect();
        let weighed: usize = shadow
            .split_mut(&chunk_starts, total)
            .into_par_iter()
            .enumerate()
            .map(|(c, sh)| {
                let mut camera: Vec<Vertex> = Vec::new();
                let mut light: Vec<Vertex> = Vec::new();
                let mut weighed = 0;
                let first_sample = c * CONNECT_CHUNK;
                for k in first_sample..(first_sample + CONNECT_CHUNK).min(n) {
                    // The vertices the sample's weights read: camera z_0..z_{t-1} and light
                    // y_0..y_{s-1} of each unoccluded connection (s = 1 with t >= 2 joins a
                    // fresh light sample instead).
                    let slots = starts[k]..starts[k + 1];
                    let (mut nc, mut nl) = (0, 0);
                    for slot in slots.clone() {
                        let this = slot - sh.start;
                        if sh.t_max[this] > 0.0 && sh.unoccluded[this] {
                            let (s, t) = (connections.s[slot] as usize, connections.t[slot] as usize);
                            nc = nc.max(t);
                            if s >= 2 || t == 1 {
                                nl = nl.max(s);
                            }
                        }
                    }
                    if nc == 0 {
                        continue;
                    }
                    camera.clear();
                    light.clear();
                    for (d, store) in vertices.iter().enumerate().take(nc) {
                        camera.push(Vertex::from_store(store, k, d));
                    }
                    for (d, store) in vertices.iter().enumerate().take(nl) {
                        light.push(Vertex::from_store(store, cap + k, d));
                    }
                    for slot in slots {
                        let this = slot - sh.start;
                        if sh.t_max[this] <= 0.0 || !sh.unoccluded[this] {
                            continue;
                        }
                        let (s, t) = (connections.s[slot] as usize, connections.t[slot] as usize);
                        let sampled;
                        let light_side: &[Vertex] = if s == 1 && t >= 2 {
                            let key = numbers.key(sampler, Stream::Connection, wave, pixels, k);
                            sampled = [sampled_light_vertex(scene, sampler, key, t)];
                            &sampled
                        } else {
                            &light
                        };
                        let strategy_count =
                            if multiplex.is_empty() { 1.0 } else { multiplex[k] as f32 + 2.0 };
                        let weight = connection_weight(
                            &ctx,
                            &settings,
                            &camera,
                            light_side,
                            (s, t),
                            strategy_count,
                        );
                        sh.contribution[this] *= weight;
                        weighed += 1;
                    }
                }
                weighed
            })
            .sum();
        Flow::new(total, weighed)
    }
}
