//! Vertex merging (VCM, BPM): each camera vertex past the camera that is not on glass merges
//! with every light vertex of the wave within the radius of its sample's pass, as a photon
//! mapper's density estimate over the wave's N light subpaths, f(z) beta(y) / (pi r^2 N),
//! each merge weighted by VCM's MIS against the connections and the merges at the path's
//! other vertices. Adds to each sample's own value, in grid order. As the photon mappers'
//! gathers, a merge takes only light vertices on the camera vertex's plane and side (either
//! side where the surface transmits) that see it (`crate::photons::NORMAL_COSINE`, `VISIBILITY_LIFT`): without that, the light vertices
//! round a corner within the radius made every edge of door_ajar's room a bright line (BPM at
//! radius 0.05: +38% over the image, +100% to +300% on the side walls seen edge-on).

use crate::bsdf::TransportMode;
use crate::components::CHUNK;
use crate::components::PathVertices;
use crate::components::Wave;
use crate::components::subpaths::{BdptSettings, LightVertexGrid, StrategyFilter};
use crate::geometry::offset_ray_origin;
use crate::path::{PathContext, Vertex, towards};
use crate::photons::{NORMAL_COSINE, VISIBILITY_LIFT, VISIBILITY_MARGIN};
use crate::pipeline::Flow;
use crate::scene::SceneData;
use crate::weight_tails::{Side, weight_tails};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

pub struct MergeLightVertices;

crate::system! {
    MergeLightVertices = "merge_light_vertices";
    read wave: Wave, settings: BdptSettings, pixels: u64,
        subpath_len: Vec<u32>, data: Arc<SceneData>, vertices: Vec<PathVertices>,
        light_grid: LightVertexGrid;
    write sample_radiance: Vec<Vec3>;
    run {
        let n = wave.len;
        let (Some(merging), Some(grid)) = (settings.merging.filter(|m| m.merge), &light_grid.grid)
        else {
            return Flow::new(n, 0);
        };
        let ctx = PathContext::new(&data.scene);
        let stores: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
        let weighted = settings.strategies == StrategyFilter::All;
        let (min_depth, max_depth) = (settings.min_depth as usize, settings.max_depth as usize);
        let bounds = data.scene.bounds_max - data.scene.bounds_min;
        let margin = VISIBILITY_MARGIN * bounds.length();
        let merged: usize = sample_radiance[..n]
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, out)| {
                let mut camera: Vec<Vertex> = Vec::new();
                let mut camera_tails = Vec::new();
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
                    if weighted {
                        weight_tails(&camera, Side::Camera, settings.mis, &mut camera_tails);
                    }
                    let mut sum = Vec3::ZERO;
                    for t in 2..=camera.len() {
                        let z = &camera[t - 1];
                        if z.beta == Vec3::ZERO || !ctx.is_connectible(z) || z.is_at_infinity() {
                            continue;
                        }
                        let wo = towards(z, &camera[t - 2]);
                        let transmits = ctx.material(z).kind().transmits();
                        let gather_point = GatherPoint::at(z, wo, margin, &data.accel);
                        grid.for_each_within_octants(&light_grid.p, z.p, radius, |i| {
                            let y = &light_grid.vertex[i as usize];
                            let s = y.weight.depth as usize;
                            // The merged path y_0..y_{s-1} z_{t-1}..z_0: s + t vertices.
                            let depth = s + t - 2;
                            if depth < min_depth || depth > max_depth {
                                return;
                            }
                            // Unweighted study of one technique: the merges of its (s, t).
                            if !weighted && !settings.strategies.keeps(s, t) {
                                return;
                            }
                            let y_p = light_grid.p[i as usize];
                            if !same_surface(&gather_point, y_p, y.ng, y.w_light, transmits) {
                                return;
                            }
                            let f = ctx.f(z, wo, y.w_light, TransportMode::Radiance);
                            if f == Vec3::ZERO {
                                return;
                            }
                            let weight = if weighted {
                                ctx.merge_weight_from_tails(
                                    (&camera[..t], &camera_tails),
                                    t,
                                    &y.weight,
                                    y.w_light,
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

/// A camera vertex as a merge sees it: its normal on the camera's side, and what the
/// visibility test needs (the photon mappers' `GatherPoint::sees`, for a path vertex).
struct GatherPoint<'a> {
    p: Vec3,
    ng: Vec3,
    clearance: f32,
    margin: f32,
    accel: &'a crate::accel::Accel,
}

impl<'a> GatherPoint<'a> {
    #[inline]
    fn at(z: &Vertex, wo: Vec3, margin: f32, accel: &'a crate::accel::Accel) -> GatherPoint<'a> {
        let ng = if wo.dot(z.ng) >= 0.0 { z.ng } else { -z.ng };
        let lifted = offset_ray_origin(z.p, z.p_error, ng, ng);
        GatherPoint {
            p: z.p,
            ng,
            clearance: 2.0 * (lifted - z.p).length(),
            margin,
            accel,
        }
    }
}

/// Whether a light vertex at `p` with normal `ng`, reached from direction `w_light` (unit,
/// towards its previous vertex), lies on the gather point's plane and side and sees it. On a
/// surface that `transmits`, light arriving from the other side counts too: then the light
/// vertex is seen from the gather point's side of the plane.
#[inline]
fn same_surface(point: &GatherPoint, p: Vec3, ng: Vec3, w_light: Vec3, transmits: bool) -> bool {
    let mut side = if w_light.dot(ng) >= 0.0 { ng } else { -ng };
    if transmits && side.dot(point.ng) <= -NORMAL_COSINE && w_light.dot(point.ng) < 0.0 {
        side = -side;
    } else if side.dot(point.ng) < NORMAL_COSINE || w_light.dot(point.ng) <= 0.0 {
        return false;
    }
    let lift = VISIBILITY_LIFT * (p - point.p).length() + point.clearance;
    let start = point.p + lift * point.ng;
    let to = p + lift * side;
    let Some(dir) = (to - start).try_normalize() else {
        return true;
    };
    let from = start - point.margin * dir;
    !point.accel.any_hit(from, dir, (to - from).dot(dir))
}
