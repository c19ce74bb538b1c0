//! `weigh_connections` through a light-vertex cache: a connection to a picked light vertex
//! reads that vertex's own subpath, and every weight counts the connection strategies
//! (s >= 2, t >= 2) `LightVertexCache::connection_count` times.

use crate::integrators::bdpt::BdptState;
use crate::systems::connect::weights::{WeighInputs, weigh_wave};

pub struct WeighCachedConnections;

crate::system! {
    WeighCachedConnections = "weigh_cached_connections";
    on BdptState {
        read wave, capacity, settings, numbers = sampler, subpath_len, data, vertices, pixels, multiplex, connection_start, connections_len, connections, light_cache, cache_pick;
        write shadow;
    }
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
