//! Fills the wave's light-vertex caches (LVC-BDPT), one per `CACHE_GROUP` samples, in
//! parallel: every light vertex past the emitter (depth >= 1, strategy s >= 2) of the group's
//! light subpaths that a connection may join and that carries light, prepared for joining, in
//! light-subpath order then depth order (the order the picks index, the same for any thread
//! count).

use crate::components::PathVertices;
use crate::components::Wave;
use crate::components::subpaths::CACHE_GROUP;
use crate::components::subpaths::LightVertexCache;
use crate::path::{PathContext, Vertex};
use crate::pipeline::Flow;
use crate::scene::SceneData;
use rayon::prelude::*;
use std::sync::Arc;

pub struct CacheLightVertices;

crate::system! {
    CacheLightVertices = "cache_light_vertices";
    read wave: Wave, capacity: usize, subpath_len: Vec<u32>, data: Arc<SceneData>,
        vertices: Vec<PathVertices>;
    write light_cache: LightVertexCache;
    run {
        let n = wave.len;
        let cap = *capacity;
        let ctx = PathContext::new(&data.scene);
        let stores: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
        // The groups keep their allocations from wave to wave.
        let groups = &mut light_cache.groups;
        groups.resize_with(n.div_ceil(CACHE_GROUP), Default::default);
        let cached: usize = groups
            .par_iter_mut()
            .enumerate()
            .map(|(g, group)| {
                group.clear();
                let samples = g * CACHE_GROUP..((g + 1) * CACHE_GROUP).min(n);
                group.light_subpaths = samples.len();
                let mut subpath: Vec<Vertex> = Vec::new();
                for k in samples {
                    let sub = cap + k;
                    subpath.clear();
                    for (d, store) in stores.iter().enumerate().take(subpath_len[sub] as usize) {
                        subpath.push(Vertex::from_store(store, sub, d));
                    }
                    for d in 1..subpath.len() {
                        if let Some(joint) = LightVertexCache::joint(&ctx, &subpath, d) {
                            group.subpath.push(sub as u32);
                            group.depth.push(d as u32);
                            group.vertex.push(subpath[d]);
                            group.joint.push(joint);
                        }
                    }
                }
                group.len()
            })
            .sum();
        Flow::new(n, cached)
    }
}
