//! Camera chains of the photon mappers: at each hit, adds the emission seen, then either
//! follows a specular (delta) surface by sampling it, or ends on a surface that is not
//! specular, which becomes the chain's gather point. Chains that leave the scene, reach the
//! depth cap or lose the roulette (after `ROULETTE_DEPTH` bounces, by throughput) end with no
//! gather point.

use crate::accel::{offset_ray_origin, surface_point};
use crate::bsdf::{Material, TransportMode};
use crate::components::{CameraChains, Hits, MISS, NO_VISIBLE_POINT, Rays, VisiblePoints};
use crate::integrators::SceneData;
use crate::integrators::pt::{ROULETTE_DEPTH, ROULETTE_MAX_SURVIVAL};
use crate::math::Frame;
use crate::pipeline::{Flow, System};
use crate::scene::NO_EMITTER;
use rayon::prelude::*;

/// Random-number dimensions of a camera chain: the pixel jitter (2), then per bounce a BSDF
/// sample (2) and roulette (1).
pub const DIM_PIXEL: u32 = 0;
pub const DIMS_PER_BOUNCE: u32 = 3;

#[inline]
pub fn bounce_dim(depth: u32) -> u32 {
    2 + depth * DIMS_PER_BOUNCE
}

/// Camera chains in flight (slots `0..active`) with their rays and hits, and the scratch
/// stores compaction swaps them with: one slot per pixel, allocated once.
pub struct ChainWavefront {
    pub chains: CameraChains,
    pub rays: Rays,
    pub hits: Hits,
    pub active: usize,
    pub scratch_chains: CameraChains,
    pub scratch_rays: Rays,
    pub order: Vec<u32>,
}

impl ChainWavefront {
    pub fn new(slots: usize) -> ChainWavefront {
        ChainWavefront {
            chains: CameraChains::new(slots),
            rays: Rays::new(slots),
            hits: Hits::new(slots),
            active: 0,
            scratch_chains: CameraChains::new(slots),
            scratch_rays: Rays::new(slots),
            order: Vec::with_capacity(slots),
        }
    }

    /// Bytes per slot: chains and rays (double buffered), hits, compaction order.
    pub fn bytes_per_slot() -> usize {
        2 * (CameraChains::bytes_per_item() + Rays::bytes_per_item())
            + Hits::bytes_per_item()
            + std::mem::size_of::<u32>()
    }

    /// The queue of the chain systems, ending chains into `visible`.
    pub fn queue<'a>(
        &'a mut self,
        data: &'a SceneData,
        max_depth: u32,
        visible: &'a mut VisiblePoints,
    ) -> ChainQueue<'a> {
        ChainQueue {
            data,
            max_depth,
            wave: self,
            visible,
        }
    }
}

/// What the chain systems work on.
pub struct ChainQueue<'a> {
    pub data: &'a SceneData,
    pub max_depth: u32,
    pub wave: &'a mut ChainWavefront,
    /// Where ended chains go, at their pixel's slot.
    pub visible: &'a mut VisiblePoints,
}

/// A state with camera chains.
pub trait CameraChainQueue {
    fn camera_chain_queue(&mut self) -> ChainQueue<'_>;
    /// (seed, sample index, chains to start) for `generate_camera_chains`: pixel k starts
    /// chain k; a count of zero starts none.
    fn new_chains(&self) -> (u64, u64, usize);
}

pub struct ExtendCameraChains;

impl<S: CameraChainQueue + Send> System<S> for ExtendCameraChains {
    fn name(&self) -> &'static str {
        "extend_camera_chains"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["hits", "rays.dir", "camera_chains"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["camera_chains", "rays"]
    }
    fn run(&self, state: &mut S) -> Flow {
        let q = state.camera_chain_queue();
        let w = q.wave;
        let n = w.active;
        let (data, hits, max_depth) = (q.data, &w.hits, q.max_depth);
        let scene = &data.scene;
        let rays = w.rays.chunks_mut(0..n);
        let live: usize = w
            .chains
            .chunks_mut(0..n)
            .into_par_iter()
            .zip(rays)
            .map(|(c, r)| {
                let mut live = 0;
                let hits = hits.view(c.start..c.start + c.len());
                for i in 0..c.len() {
                    c.alive[i] = false;
                    c.triangle[i] = NO_VISIBLE_POINT;
                    let tri = hits.triangle[i];
                    if tri == MISS {
                        continue;
                    }
                    let sp = surface_point(&scene.triangles, tri, hits.b1[i], hits.b2[i]);
                    let wo = -r.dir[i];
                    let e = scene.triangles.emitter[tri as usize];
                    if e != NO_EMITTER && wo.dot(sp.ng) > 0.0 {
                        c.emitted[i] += c.beta[i] * scene.emitters.radiance[e as usize];
                    }
                    let material = scene.materials[scene.triangles.material[tri as usize] as usize];
                    let (mut ng, mut ns) = (sp.ng, sp.ns);
                    if wo.dot(ng) < 0.0 && matches!(material, Material::Diffuse { .. }) {
                        // Lambertian surfaces reflect on both sides: gather on wo's side.
                        ng = -ng;
                        ns = -ns;
                    }
                    if ns.dot(ng) < 0.0 {
                        ns = -ns;
                    }
                    if !matches!(material, Material::Dielectric { .. }) {
                        c.p[i] = sp.p;
                        c.p_error[i] = sp.p_error;
                        c.ng[i] = ng;
                        c.ns[i] = ns;
                        c.wo[i] = wo;
                        c.triangle[i] = tri;
                        continue;
                    }
                    let depth = c.depth[i];
                    if depth >= max_depth {
                        continue;
                    }
                    let frame = Frame::from_normal(ns);
                    let wo_local = frame.to_local(wo);
                    let dim = bounce_dim(depth);
                    let Some(bs) =
                        material.sample(wo_local, c.key[i].get2(dim), TransportMode::Radiance)
                    else {
                        continue;
                    };
                    let wi = frame.to_world(bs.wi).normalize();
                    let reflected = bs.wi.z * wo_local.z > 0.0;
                    if bs.pdf <= 0.0 || (wi.dot(ng) * wo.dot(ng) > 0.0) != reflected {
                        continue;
                    }
                    let mut beta = c.beta[i] * bs.value * (bs.wi.z.abs() / bs.pdf);
                    if depth + 1 >= ROULETTE_DEPTH {
                        let q = beta.max_element().min(ROULETTE_MAX_SURVIVAL);
                        if q.is_nan() || q <= 0.0 || c.key[i].get(dim + 2) >= q {
                            continue;
                        }
                        beta /= q;
                    }
                    c.beta[i] = beta;
                    c.depth[i] = depth + 1;
                    c.alive[i] = true;
                    r.origin[i] = offset_ray_origin(sp.p, sp.p_error, sp.ng, wi);
                    r.dir[i] = wi;
                    live += 1;
                }
                live
            })
            .sum();
        Flow::new(n, live)
    }
}
