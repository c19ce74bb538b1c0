//! Fills the wave's light-vertex cache (LVC-BDPT): every light vertex past the emitter
//! (depth >= 1, strategy s >= 2) that a connection may join and that carries light, prepared
//! for joining, in light-subpath order then depth order (the order the picks index, the same
//! for any thread count).

use crate::integrators::bdpt::{BdptState, CONNECT_CHUNK, LightVertexCache};
use crate::path::{Joint, PathContext, Vertex};
use crate::pipeline::Flow;
use rayon::prelude::*;

pub struct CacheLightVertices;

/// The cached vertices of one chunk of light subpaths.
#[derive(Default)]
struct Piece {
    subpath: Vec<u32>,
    depth: Vec<u32>,
    vertex: Vec<Vertex>,
    joint: Vec<Joint>,
}

crate::system! {
    CacheLightVertices = "cache_light_vertices";
    on BdptState {
        read wave, capacity, subpath_len, data, vertices;
        write light_cache;
    }
    run {
        let n = wave.len;
        let cap = *capacity;
        let ctx = PathContext::new(&data.scene);
        let stores: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
        let pieces: Vec<Piece> = (0..n.div_ceil(CONNECT_CHUNK))
            .into_par_iter()
            .map(|c| {
                let mut piece = Piece::default();
                let mut subpath: Vec<Vertex> = Vec::new();
                for k in c * CONNECT_CHUNK..((c + 1) * CONNECT_CHUNK).min(n) {
                    let sub = cap + k;
                    subpath.clear();
                    for (d, store) in stores.iter().enumerate().take(subpath_len[sub] as usize) {
                        subpath.push(Vertex::from_store(store, sub, d));
                    }
                    for d in 1..subpath.len() {
                        if let Some(joint) = LightVertexCache::joint(&ctx, &subpath, d) {
                            piece.subpath.push(sub as u32);
                            piece.depth.push(d as u32);
                            piece.vertex.push(subpath[d]);
                            piece.joint.push(joint);
                        }
                    }
                }
                piece
            })
            .collect();
        let cache = &mut *light_cache;
        cache.light_subpaths = n;
        cache.subpath.clear();
        cache.depth.clear();
        cache.vertex.clear();
        cache.joint.clear();
        for piece in &pieces {
            cache.subpath.extend_from_slice(&piece.subpath);
            cache.depth.extend_from_slice(&piece.depth);
            cache.vertex.extend_from_slice(&piece.vertex);
            cache.joint.extend_from_slice(&piece.joint);
        }
        Flow::new(n, cache.len())
    }
}
