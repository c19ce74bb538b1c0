//! Records the vertex each subpath's ray found and scatters the subpath on: a BSDF sample
//! (radiance transport for camera subpaths, importance for light subpaths), the densities the
//! ratio walk needs (this vertex's forward density, the previous vertex's reverse one), and
//! Russian roulette (not for multiplexed samples, whose lengths are fixed in advance). A
//! subpath ends when its ray leaves the scene, at the depth cap, when its sample carries
//! nothing, or by roulette.

use crate::bsdf::{TransportMode, sample_direction};
use crate::components::Hits;
use crate::components::Rays;
use crate::components::Walkers;
use crate::components::subpaths::BdptSettings;
use crate::components::subpaths::DIM_BSDF;
use crate::components::subpaths::DIM_ROULETTE;
use crate::components::subpaths::Numbers;
use crate::components::subpaths::camera_vertex_dim;
use crate::components::subpaths::light_vertex_dim;
use crate::components::{MISS, PathVertex, PathVertices, split_ranges};
use crate::geometry::{offset_ray_origin, surface_point};
use crate::path::{Vertex, VertexKind, local_frame, shading_correction, to_area};
use crate::pipeline::Flow;
use crate::sampling::roulette::{ROULETTE_DEPTH, survival, survives};
use crate::sampling::{SampleKey, Sampler};
use crate::scene::PreparedScene;
use glam::Vec3;
use rayon::prelude::*;

pub struct ExtendSubpaths;

crate::system! {
    ExtendSubpaths = "extend_subpaths";
    read scene: PreparedScene, settings: BdptSettings, numbers: Numbers, capacity: usize,
        hits: Hits, active: usize, depth: usize, multiplex: Vec<u32>, chosen_s: Vec<u16>;
    write vertices: Vec<PathVertices>, subpath_len: Vec<u32>, walkers: Walkers, rays: Rays;
    run {
        let sampler = numbers.sampler();
        let sampler = &sampler;
        // The last vertex index subpath `sub` may reach: the depth cap, or for a multiplexed
        // sample its strategy's t - 1 (camera) or s - 1 (light).
        let last_vertex = |sub: usize, light: bool| {
            if multiplex.is_empty() {
                settings.last_vertex(light)
            } else {
                let k = if light { sub - *capacity } else { sub };
                let s = chosen_s[k] as usize;
                let t = multiplex[k] as usize + 2 - s;
                if light { s.saturating_sub(1) } else { t - 1 }
            }
        };
        let d = *depth;
        while vertices.len() <= d {
            vertices.push(PathVertices::new(2 * *capacity));
        }
        let n = *active;
        let cap = *capacity;
        let end = 2 * cap;
        let settings = *settings;
        let scene = &scene;
        let tris = &scene.triangles;
        // Each chunk of walkers owns the subpath slots from its first walker's subpath on
        // (walkers stay in increasing subpath order), so the vertex stores split along them.
        // The deep bounces of a wave hold few walkers: there the chunks are smaller, so that
        // the last bounces do not run on one core (each walker's work is its own, so the
        // split never changes the result).
        let chunk = walker_chunk(n);
        let first_walker: Vec<usize> = (0..n).step_by(chunk).collect();
        let first_subpath: Vec<usize> = first_walker
            .iter()
            .map(|&slot| walkers.subpath[slot] as usize)
            .collect();
        let (before, from_d) = vertices.split_at_mut(d);
        let prev_views = before[d - 1].split_mut(&first_subpath, end);
        let views = from_d[0].split_mut(&first_subpath, end);
        let lens = split_ranges(subpath_len, &first_subpath, end);
        let hits = &hits;
        let walkers = walkers.split_mut(&first_walker, n);
        let rays = rays.split_mut(&first_walker, n);
        let alive: usize = walkers
            .into_par_iter()
            .zip(rays)
            .zip(views)
            .zip(prev_views)
            .zip(lens)
            .map(|((((wk, r), mut v), pv), lens)| {
                let mut alive = 0;
                let base = v.start;
                let hits = hits.view(wk.start..wk.start + wk.len());
                for i in 0..wk.len() {
                    if !wk.alive[i] {
                        continue;
                    }
                    let sub = wk.subpath[i] as usize;
                    let j = sub - base;
                    let light = sub >= cap;
                    if hits.triangle[i] == MISS {
                        wk.alive[i] = false;
                        // A camera subpath that leaves the scene ends on the light at
                        // infinity, if there is one (strategy s = 0 reads it there).
                        if let Some(env) = scene.emitters.environment.as_ref().filter(|_| !light) {
                            let prev = Vertex::from_store(&pv.view(), j, d - 1);
                            let dir = r.dir[i];
                            let mut here = Vertex {
                                kind: VertexKind::Light,
                                p: scene.emitters.disk.far_point(r.origin[i], dir),
                                p_error: Vec3::ZERO,
                                ng: -dir,
                                ns: -dir,
                                triangle: crate::scene::ENVIRONMENT,
                                beta: wk.beta[i],
                                pdf_fwd: 0.0,
                                pdf_rev: 0.0,
                                delta: false,
                            };
                            here.pdf_fwd = to_area(wk.pdf_dir[i], &prev, &here);
                            v.set(j, here.stored());
                            lens[j] = d as u32 + 1;
                        }
                        continue;
                    }
                    let tri = hits.triangle[i];
                    let sp = surface_point(tris, tri, hits.b1[i], hits.b2[i]);
                    let ns = if sp.ns.dot(sp.ng) < 0.0 {
                        -sp.ns
                    } else {
                        sp.ns
                    };
                    let prev = Vertex::from_store(&pv.view(), j, d - 1);
                    let mut here = Vertex {
                        kind: VertexKind::Surface,
                        p: sp.p,
                        p_error: sp.p_error,
                        ng: sp.ng,
                        ns,
                        triangle: tri,
                        beta: wk.beta[i],
                        pdf_fwd: 0.0,
                        pdf_rev: 0.0,
                        delta: false,
                    };
                    here.pdf_fwd = to_area(wk.pdf_dir[i], &prev, &here);
                    lens[j] = d as u32 + 1;
                    wk.alive[i] = false;
                    let next = (d < last_vertex(sub, light))
                        .then(|| scatter(scene, sampler, &mut here, &prev, wk.key[i], d, light))
                        .flatten();
                    // The reverse density is written by the next bounce (or stays 0).
                    v.set(
                        j,
                        PathVertex {
                            pdf_rev: 0.0,
                            ..here.stored()
                        },
                    );
                    let Some(next) = next else { continue };
                    pv.items[j].pdf_rev = next.pdf_rev_prev;
                    let mut beta = wk.beta[i] * next.weight;
                    // A multiplexed sample's lengths are drawn in advance (its depth's
                    // probability is in its weight): no roulette, which would end most deep
                    // ones with nothing.
                    if d >= ROULETTE_DEPTH as usize && multiplex.is_empty() {
                        let q = survival(beta, wk.roulette_scale[i]);
                        let u = sampler.get(
                            wk.key[i],
                            if light {
                                light_vertex_dim(d)
                            } else {
                                camera_vertex_dim(d)
                            } + DIM_ROULETTE,
                        );
                        if !survives(q, u) {
                            continue;
                        }
                        beta /= q;
                    }
                    wk.beta[i] = beta;
                    wk.pdf_dir[i] = next.pdf_dir;
                    wk.alive[i] = true;
                    r.origin[i] = offset_ray_origin(here.p, here.p_error, here.ng, next.wi);
                    r.dir[i] = next.wi;
                    alive += 1;
                }
                alive
            })
            .sum();
        Flow::new(n, alive)
    }
}

/// Walkers per chunk of a bounce with `n` walkers: `CHUNK`, or for a small bounce enough
/// smaller chunks (of at least `MIN_WALKER_CHUNK`) to keep every core of a small machine busy.
fn walker_chunk(n: usize) -> usize {
    const CHUNKS_AT_LEAST: usize = 16;
    const MIN_WALKER_CHUNK: usize = 64;
    n.div_ceil(CHUNKS_AT_LEAST)
        .clamp(MIN_WALKER_CHUNK, crate::components::CHUNK)
}

/// A subpath's next step.
struct Scattered {
    wi: Vec3,
    /// BSDF value times cosine over density (with the shading-normal correction for
    /// importance).
    weight: Vec3,
    /// Solid-angle density of `wi` (0 for a delta lobe).
    pdf_dir: f32,
    /// Area density at the previous vertex of sampling it from here in the other direction.
    pdf_rev_prev: f32,
}

/// Samples the BSDF at `here` (reached from `prev`); marks `here` delta for a delta lobe.
#[inline]
fn scatter(
    scene: &crate::scene::PreparedScene,
    sampler: &Sampler,
    here: &mut Vertex,
    prev: &Vertex,
    key: SampleKey,
    d: usize,
    light: bool,
) -> Option<Scattered> {
    let wo = (prev.p - here.p).normalize_or_zero();
    let (material, frame, ng) = local_frame(scene, here, wo);
    let wo_local = frame.to_local(wo);
    let (dim, mode) = if light {
        (light_vertex_dim(d), TransportMode::Importance)
    } else {
        (camera_vertex_dim(d), TransportMode::Radiance)
    };
    let (bs, wi) = sample_direction(
        &material,
        &frame,
        ng,
        wo,
        wo_local,
        sampler.get2(key, dim + DIM_BSDF),
        mode,
    )?;
    let mut weight = bs.value * (bs.wi.z.abs() / bs.pdf);
    if light {
        weight *= shading_correction(here, wo, wi);
    }
    if !weight.is_finite() || weight.max_element() <= 0.0 {
        return None;
    }
    let (pdf_dir, pdf_rev_dir) = if bs.delta {
        here.delta = true;
        // A delta lobe's direction counts 1 both ways (`PathContext::pdf_dir`): the area
        // conversion it then gets is the Jacobian MIS needs across the specular vertex.
        (1.0, 1.0)
    } else {
        (bs.pdf, material.pdf(bs.wi, wo_local))
    };
    Some(Scattered {
        wi,
        weight,
        pdf_dir,
        pdf_rev_prev: to_area(pdf_rev_dir, here, prev),
    })
}
