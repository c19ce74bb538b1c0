//! Vertex merging (VCM, BPM): each camera vertex past the camera that is not on glass merges
//! with every light vertex of the wave within the radius of its sample's pass, as a photon
//! mapper's density estimate over the wave's N light subpaths, f(z) beta(y) / (pi r^2 N),
//! each merge weighted by VCM's MIS against the connections and the merges at the path's
//! other vertices. Adds to each sample's own value, in grid order.

use crate::bsdf::TransportMode;
use crate::components::CHUNK;
use crate::components::PathVertices;
use crate::components::Wave;
use crate::components::subpaths::{BdptSettings, LightVertexGrid, StrategyFilter};
use crate::path::{PathContext, Vertex, towards};
use crate::pipeline::Flow;
use crate::scene::SceneData;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

pub struct MergeLightVertices;

crate::system! {
    MergeLightVertices = "merge_light_vertices";
    read wave: Wave, capacity: usize, settings: BdptSettings, pixels: u64,
        subpath_len: Vec<u32>, data: Arc<SceneData>, vertices: Vec<PathVertices>,
        light_grid: LightVertexGrid;
    write sample_radiance: Vec<Vec3>;
    run {
        let n = wave.len;
        let (Some(merging), Some(grid)) = (settings.merging.filter(|m| m.merge), &light_grid.grid)
        else {
            return Flow::new(n, 0);
        };
        let cap = *capacity;
        let ctx = PathContext::new(&data.scene);
        let stores: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
        let weighted = settings.strategies == StrategyFilter::All;
        let (min_depth, max_depth) = (settings.min_depth as usize, settings.max_depth as usize);
        let merged: usize = sample_radiance[..n]
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, out)| {
                let mut camera: Vec<Vertex> = Vec::new();
                let mut light: Vec<Vertex> = Vec::new();
                let mut merged = 0;
                for (local, value) in out.iter_mut().enumerate() {
                    let k = c * CHUNK + local;
                    let radius = merging.radius_at((wave.first + k as u64) / *pixels);
                    let techniques = settings.techniques(*wave, k, *pixels);
                    // The density estimate's kernel: uniform over the disc, over N subpaths.
                    let kernel = 1.0 / (std::f32::consts::PI * radius * radius * n as f32);
                    camera.clear();
                    for (d, store) in stores.iter().enumerate().take(subpath_len[k] as usize) {
                        camera.push(Vertex::from_store(store, k, d));
                    }
                    let mut sum = Vec3::ZERO;
                    for t in 2..=camera.len() {
                        let z = &camera[t - 1];
                        if z.beta == Vec3::ZERO || !ctx.is_connectible(z) {
                            continue;
                        }
                        let wo = towards(z, &camera[t - 2]);
                        grid.for_each_within_octants(&light_grid.p, z.p, radius, |i| {
                            let i = i as usize;
                            let (sub, s) = (light_grid.subpath[i] as usize, light_grid.depth[i] as usize);
                            // The merged path y_0..y_{s-1} z_{t-1}..z_0: s + t vertices.
                            let depth = s + t - 2;
                            if depth < min_depth || depth > max_depth {
                                return;
                            }
                            light.clear();
                            for (d, store) in stores.iter().enumerate().take(s + 1) {
                                light.push(Vertex::from_store(store, sub, d));
                            }
                            let y = &light[s];
                            let w_light = towards(y, &light[s - 1]);
                            let f = ctx.f(z, wo, w_light, TransportMode::Radiance);
                            if f == Vec3::ZERO {
                                return;
                            }
                            let weight = if weighted {
                                ctx.vcm_weight(
                                    &camera[..t],
                                    &light[..s],
                                    (s, t),
                                    Some(y),
                                    settings.mis,
                                    techniques,
                                )
                            } else {
                                1.0
                            };
                            sum += z.beta * f * y.beta * (kernel * weight);
                            merged += 1;
                        });
                    }
                    *value += sum;
                }
                merged
            })
            .sum();
        Flow::new(n, merged)
    }
}
