//! `connect_strategies` through a light-vertex cache (LVC-BDPT, `--light-vertex-cache M`):
//! strategies s = 0, s = 1 and t = 1 as BDPT makes them, and at each camera vertex (t >= 2)
//! M connections to light vertices picked uniformly from the wave's cache in place of one
//! per vertex of the sample's own light subpath, each scaled by V / (N M) (see
//! `LightVertexCache::scale`). Each pick's cache index goes to `cache_pick`, for the weights.

use crate::integrators::bdpt::BdptState;
use crate::systems::connect::strategies::{WaveInputs, WaveOutputs, connect_wave};

pub struct ConnectThroughCache;

crate::system! {
    ConnectThroughCache = "connect_through_cache";
    on BdptState {
        read wave, capacity, settings, numbers = sampler, subpath_len, data, vertices, pixels, multiplex, chosen_s, sample_pixel, light_cache;
        write connection_start, connections_len, shadow, connections, sample_radiance, cache_pick;
    }
    run {
        let input = WaveInputs {
            wave: *wave,
            capacity: *capacity,
            settings: *settings,
            numbers,
            subpath_len,
            data,
            vertices,
            pixels: *pixels,
            multiplex,
            chosen_s,
            sample_pixel,
        };
        let out = WaveOutputs { connection_start, connections_len, shadow, connections, sample_radiance };
        connect_wave(input, out, Some((light_cache, cache_pick)))
    }
}
