//! Gathers the wave's light vertices that camera vertices may merge with (VCM, BPM) and
//! builds the photon mappers' hash grid over them: every light vertex past the emitter that
//! is not on glass and carries light, with what a merge's weight reads of its subpath (its
//! `MergedLight`), in light-subpath then depth order (the order the
//! merges visit, so no image depends on the thread count). Cells are twice the radius of the
//! wave's first pass, the largest of its passes (radii only shrink), for octant queries.

use crate::components::PathVertices;
use crate::components::Wave;
use crate::components::subpaths::{BdptSettings, LightVertexGrid, MergeableVertex};
use crate::path::{PathContext, Vertex, towards};
use crate::photons::HashGrid;
use crate::pipeline::Flow;
use crate::scene::SceneData;
use crate::weight_tails::{MergedLight, Side, weight_tails};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

pub struct BuildLightVertexGrid;

/// Light subpaths per parallel piece of the gathering.
const SUBPATHS_PER_PIECE: usize = 1024;

crate::system! {
    BuildLightVertexGrid = "build_light_vertex_grid";
    read wave: Wave, capacity: usize, settings: BdptSettings, pixels: u64,
        subpath_len: Vec<u32>, data: Arc<SceneData>, vertices: Vec<PathVertices>;
    write light_grid: LightVertexGrid;
    run {
        let n = wave.len;
        let cap = *capacity;
        light_grid.clear();
        let Some(merging) = settings.merging.filter(|m| m.merge) else {
            return Flow::new(n, 0);
        };
        let ctx = PathContext::new(&data.scene);
        let stores: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
        let pieces: Vec<(Vec<Vec3>, Vec<MergeableVertex>)> = (0..n.div_ceil(SUBPATHS_PER_PIECE))
            .into_par_iter()
            .map(|piece| {
                let mut out = (Vec::new(), Vec::new());
                let (mut light, mut tails) = (Vec::new(), Vec::new());
                let first = piece * SUBPATHS_PER_PIECE;
                for k in first..(first + SUBPATHS_PER_PIECE).min(n) {
                    let sub = cap + k;
                    light.clear();
                    for (d, store) in stores.iter().enumerate().take(subpath_len[sub] as usize) {
                        light.push(Vertex::from_store(store, sub, d));
                    }
                    weight_tails(&light, Side::Light, settings.mis, &mut tails);
                    for (d, v) in light.iter().enumerate().skip(1) {
                        if v.beta == Vec3::ZERO || !ctx.is_connectible(v) {
                            continue;
                        }
                        out.0.push(v.p);
                        out.1.push(MergeableVertex {
                            ng: v.ng,
                            w_light: towards(v, &light[d - 1]),
                            beta: v.beta,
                            weight: MergedLight::new(&light[..=d], &tails),
                        });
                    }
                }
                out
            })
            .collect();
        for (p, vertex) in pieces {
            light_grid.p.extend(p);
            light_grid.vertex.extend(vertex);
        }
        let radius = merging.radius_at(wave.first / *pixels);
        if !light_grid.p.is_empty() && radius > 0.0 {
            light_grid.grid = Some(HashGrid::build_for_octants(&light_grid.p, radius));
        }
        Flow::new(n, light_grid.p.len())
    }
}
