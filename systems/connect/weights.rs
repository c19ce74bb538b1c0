//! Multiplies each unoccluded connection's contribution by its MIS weight (and a multiplexed
//! sample's strategy count). `connect_strategies` leaves the weight of connections with a
//! shadow ray to this system, run after the rays are traced, so the weight's ratio walk (four
//! BSDF densities at the joint, then one step per path vertex) is paid only by connections
//! that reach the film: on door_ajar 4% of them. The arithmetic is the one the connection
//! would have done at once, so the image is the same bit for bit.

use crate::components::Wave;
use crate::components::subpaths::BdptSettings;
use crate::components::subpaths::CONNECT_CHUNK;
use crate::components::subpaths::LightVertexCache;
use crate::components::subpaths::Numbers;
use crate::components::{Connections, PathVertices, ShadowRays};
use crate::path::{PathContext, Vertex};
use crate::pipeline::Flow;
use crate::sampling::Stream;
use crate::scene::SceneData;
use crate::systems::connect::strategies::{connection_weight, sampled_light_vertex};
use crate::weight_tails::{Side, weight_tails};
use rayon::prelude::*;
use std::sync::Arc;

pub struct WeighConnections;

crate::system! {
    WeighConnections = "weigh_connections";
    read wave: Wave, capacity: usize, settings: BdptSettings, numbers: Numbers,
        subpath_len: Vec<u32>, data: Arc<SceneData>, vertices: Vec<PathVertices>, pixels: u64,
        multiplex: Vec<u32>, connection_start: Vec<usize>, connections_len: usize,
        connections: Connections;
    write shadow: ShadowRays;
    run {
        let input = WeighInputs {
            wave: *wave,
            capacity: *capacity,
            settings: *settings,
            numbers,
            data,
            vertices,
            pixels: *pixels,
            multiplex,
            connection_start,
            connections_len: *connections_len,
            connections,
        };
        weigh_wave(input, shadow, None)
    }
}

/// What `weigh_wave` reads of a BDPT state.
pub struct WeighInputs<'a> {
    pub wave: Wave,
    pub capacity: usize,
    pub settings: BdptSettings,
    pub numbers: &'a Numbers,
    pub data: &'a SceneData,
    pub vertices: &'a [PathVertices],
    pub pixels: u64,
    pub multiplex: &'a [u32],
    pub connection_start: &'a [usize],
    pub connections_len: usize,
    pub connections: &'a Connections,
}

/// Weighs the wave's unoccluded connections; through a light-vertex cache (`cache`: the cache
/// and each slot's pick), the connection strategies (s >= 2, t >= 2) read their picked light
/// vertex's own subpath, and every weight counts the connection strategies as the cache samples
/// them.
pub fn weigh_wave(
    input: WeighInputs,
    shadow: &mut ShadowRays,
    cache: Option<(&LightVertexCache, &[u32])>,
) -> Flow {
    let WeighInputs {
        wave,
        capacity: cap,
        settings,
        numbers,
        data,
        vertices,
        pixels,
        multiplex,
        connection_start: starts,
        connections_len: total,
        connections,
    } = input;
    let n = wave.len;
    let sampler = numbers.sampler();
    let sampler = &sampler;
    let ctx = PathContext::new(&data.scene);
    let scene = &data.scene;
    let vertices: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
    let connection_count = cache.map_or(1.0, |(c, _)| c.connection_count);
    let through_cache = |s: usize, t: usize| cache.is_some() && s >= 2 && t >= 2;
    let chunk_starts: Vec<usize> = (0..n).step_by(CONNECT_CHUNK).map(|k| starts[k]).collect();
    let weighed: usize = shadow
        .split_mut(&chunk_starts, total)
        .into_par_iter()
        .enumerate()
        .map(|(c, sh)| {
            let mut camera: Vec<Vertex> = Vec::new();
            let mut light: Vec<Vertex> = Vec::new();
            let mut picked: Vec<Vertex> = Vec::new();
            let (mut camera_tails, mut light_tails) = (Vec::new(), Vec::new());
            let mut weighed = 0;
            let first_sample = c * CONNECT_CHUNK;
            for k in first_sample..(first_sample + CONNECT_CHUNK).min(n) {
                // The vertices the sample's weights read: camera z_0..z_{t-1} and light
                // y_0..y_{s-1} of each unoccluded connection (s = 1 with t >= 2 joins a
                // fresh light sample instead, a connection through the cache its pick's
                // subpath).
                let slots = starts[k]..starts[k + 1];
                let (mut nc, mut nl) = (0, 0);
                for slot in slots.clone() {
                    let this = slot - sh.start;
                    if sh.t_max[this] > 0.0 && sh.unoccluded[this] {
                        let (s, t) = (connections.s[slot] as usize, connections.t[slot] as usize);
                        nc = nc.max(t);
                        if (s >= 2 || t == 1) && !through_cache(s, t) {
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
                // VCM's merge factor follows the sample's pass radius (a power): once a sample.
                let techniques = settings.techniques(wave, k, pixels);
                // Each connection's weight in constant time from these (not through a cache,
                // whose picks are other subpaths).
                if cache.is_none() {
                    weight_tails(&camera, Side::Camera, settings.mis, &mut camera_tails);
                    weight_tails(&light, Side::Light, settings.mis, &mut light_tails);
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
                        sampled = [sampled_light_vertex(scene, sampler, key, t, &camera[t - 1])];
                        &sampled
                    } else if let Some((cache, picks)) = cache.filter(|_| through_cache(s, t)) {
                        let sub = cache.group(k).subpath[picks[slot] as usize] as usize;
                        picked.clear();
                        for (d, store) in vertices.iter().enumerate().take(s) {
                            picked.push(Vertex::from_store(store, sub, d));
                        }
                        &picked
                    } else {
                        &light
                    };
                    let strategy_count = if multiplex.is_empty() {
                        1.0
                    } else {
                        crate::components::subpaths::multiplexed_factor(
                            multiplex[k],
                            settings.max_depth,
                        )
                    };
                    let weight = connection_weight(
                        &ctx,
                        &settings,
                        (&camera, light_side),
                        (s, t),
                        (strategy_count, connection_count),
                        techniques,
                        cache
                            .is_none()
                            .then_some((&camera_tails[..], &light_tails[..])),
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
