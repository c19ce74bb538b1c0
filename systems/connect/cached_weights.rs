//! `weigh_connections` through a light-vertex cache: a connection to a picked light vertex
//! reads that vertex's own subpath, and every weight counts the connection strategies
//! (s >= 2, t >= 2) `LightVertexCache::connection_count` times.

use crate::components::Connections;
use crate::components::PathVertices;
use crate::components::ShadowRays;
use crate::components::Wave;
use crate::components::subpaths::BdptSettings;
use crate::components::subpaths::LightVertexCache;
use crate::components::subpaths::Numbers;
use crate::scene::SceneData;
use crate::systems::connect::weights::{WeighInputs, weigh_wave};
use std::sync::Arc;

pub struct WeighCachedConnections;

crate::system! {
    WeighCachedConnections = "weigh_cached_connections";
    read wave: Wave, capacity: usize, settings: BdptSettings, numbers: Numbers,
        subpath_len: Vec<u32>, data: Arc<SceneData>, vertices: Vec<PathVertices>, pixels: u64,
        multiplex: Vec<u32>, connection_start: Vec<usize>, connections_len: usize,
        connections: Connections, light_cache: LightVertexCache, cache_pick: Vec<u32>;
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
        weigh_wave(input, shadow, Some((light_cache, cache_pick)))
    }
}
