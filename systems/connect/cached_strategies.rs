//! `connect_strategies` through a light-vertex cache (LVC-BDPT, `--light-vertex-cache M`):
//! strategies s = 0, s = 1 and t = 1 as BDPT makes them, and at each camera vertex (t >= 2)
//! M connections to light vertices picked uniformly from the wave's cache in place of one
//! per vertex of the sample's own light subpath, each scaled by V / (N M) (see
//! `LightVertexCache::scale`). Each pick's cache index goes to `cache_pick`, for the weights.

use crate::components::Connections;
use crate::components::PathVertices;
use crate::components::ShadowRays;
use crate::components::Wave;
use crate::components::subpaths::BdptSettings;
use crate::components::subpaths::LightVertexCache;
use crate::components::subpaths::Numbers;
use crate::scene::SceneData;
use crate::systems::connect::strategies::{WaveInputs, WaveOutputs, connect_wave};
use glam::Vec3;
use std::sync::Arc;

pub struct ConnectThroughCache;

crate::system! {
    ConnectThroughCache = "connect_through_cache";
    read wave: Wave, capacity: usize, settings: BdptSettings, numbers: Numbers,
        subpath_len: Vec<u32>, data: Arc<SceneData>, vertices: Vec<PathVertices>, pixels: u64,
        multiplex: Vec<u32>, chosen_s: Vec<u16>, sample_pixel: Vec<u32>,
        light_cache: LightVertexCache;
    write connection_start: Vec<usize>, connections_len: usize, shadow: ShadowRays,
        connections: Connections, sample_radiance: Vec<Vec3>, cache_pick: Vec<u32>;
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
