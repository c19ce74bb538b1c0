//! Where each photon landed: stores it unless camera chains follow the surface (specular or
//! nearly, `photons::chains_follow`), then scatters it on by
//! sampling the BSDF (importance transport), with Russian roulette by the sampled weight so
//! that its power stays constant in expectation. Stored photons join the pass in photon order.

use crate::bsdf::{TransportMode, sample_direction};
use crate::components::{CHUNK, MISS, PhotonFlags};
use crate::geometry::{offset_ray_origin, surface_point};
use crate::path::{Vertex, VertexKind, local_frame, shading_correction};
use crate::photons::PhotonTracing;
use crate::photons::{DIM_BSDF, DIM_ROULETTE, StoredPhoton, bounce_dim, chains_follow};
use crate::pipeline::Flow;
use crate::sampling::roulette::{survival, survives};
use crate::scene::SceneData;
use rayon::prelude::*;
use std::sync::Arc;

pub struct ScatterPhotons;

crate::system! {
    ScatterPhotons = "scatter_photons";
    read data: Arc<SceneData>;
    write tracing: PhotonTracing;
    run {
        let (data, t): (&SceneData, _) = (data, tracing);
        let n = t.active;
        let scene = &data.scene;
        let (max_depth, store_direct, sampler) = (t.max_depth, t.store_direct, t.sampler);
        let chunks = n.div_ceil(CHUNK);
        t.chunk_photons.resize_with(chunks, Vec::new);
        let hits = &t.hits;
        let rays = t.rays.chunks_mut(0..n);
        let alive: usize = t
            .walkers
            .chunks_mut(0..n)
            .into_par_iter()
            .zip(rays)
            .zip(&mut t.chunk_photons[..chunks])
            // One chunk per task: photons' costs vary (misses, roulette), and rayon's
            // default split (a few pieces per thread) left a core idle at the loop's end.
            .with_max_len(1)
            .map(|((w, r), out)| {
                out.clear();
                let mut alive = 0;
                let hits = hits.view(w.start..w.start + w.len());
                for i in 0..w.len() {
                    if !w.alive[i] || hits.triangle[i] == MISS {
                        w.alive[i] = false;
                        continue;
                    }
                    w.alive[i] = false;
                    let tri = hits.triangle[i];
                    let sp = surface_point(&scene.triangles, tri, hits.b1[i], hits.b2[i]);
                    let ns = if sp.ns.dot(sp.ng) < 0.0 {
                        -sp.ns
                    } else {
                        sp.ns
                    };
                    let wo = -r.dir[i].normalize();
                    if scene.seen_from_behind(tri, wo, sp.ng) {
                        // Absorbed (a one-sided surface seen from behind): nothing gathers
                        // a photon here and none leaves.
                        continue;
                    }
                    let material = scene.material_facing(tri, sp.p, wo, ns);
                    let depth = w.depth[i];
                    // Nothing gathers on surfaces camera chains follow.
                    let followed = chains_follow(&material);
                    if !followed && (depth > 0 || store_direct) {
                        let mut flags = 0;
                        if depth == 0 {
                            flags |= PhotonFlags::DIRECT;
                        } else if w.specular_chain[i] {
                            flags |= PhotonFlags::CAUSTIC;
                        }
                        // The side it arrived on: a two-sided wall's photons belong to
                        // one room each.
                        let side = if wo.dot(sp.ng) < 0.0 { -sp.ng } else { sp.ng };
                        out.push(StoredPhoton {
                            p: sp.p,
                            wi: wo,
                            power: w.power[i],
                            ng: side,
                            depth,
                            flags: PhotonFlags(flags),
                        });
                    }
                    if depth >= max_depth {
                        continue;
                    }
                    let here = Vertex {
                        kind: VertexKind::Surface,
                        p: sp.p,
                        p_error: sp.p_error,
                        ng: sp.ng,
                        ns,
                        triangle: tri,
                        beta: w.power[i],
                        pdf_fwd: 0.0,
                        pdf_rev: 0.0,
                        delta: false,
                    };
                    let (material, frame, ng) = local_frame(scene, &here, wo);
                    let wo_local = frame.to_local(wo);
                    let key = w.key[i];
                    let dim = bounce_dim(depth);
                    let Some((bs, wi)) = sample_direction(
                        &material,
                        &frame,
                        ng,
                        wo,
                        wo_local,
                        sampler.get2(key, dim + DIM_BSDF),
                        TransportMode::Importance,
                    ) else {
                        continue;
                    };
                    let weight =
                        bs.value * (bs.wi.z.abs() / bs.pdf) * shading_correction(&here, wo, wi);
                    if !weight.is_finite() {
                        continue;
                    }
                    // Roulette by the weight: survivors carry power / q x weight, which keeps
                    // a Lambertian photon's power unchanged (weight = albedo = q per channel
                    // when grey).
                    let q = survival(weight, 1.0);
                    if !survives(q, sampler.get(key, dim + DIM_ROULETTE)) {
                        continue;
                    }
                    w.power[i] *= weight / q;
                    w.depth[i] = depth + 1;
                    // A delta lobe of a surface chains do not follow (the smooth plastic's
                    // reflection, which camera chains take by a choice of their own) keeps
                    // the photon a caustic one too: PM's final gathering never reads the
                    // light it carries to a visible point.
                    w.specular_chain[i] &= followed || bs.delta;
                    w.alive[i] = true;
                    r.origin[i] = offset_ray_origin(sp.p, sp.p_error, sp.ng, wi);
                    r.dir[i] = wi;
                    alive += 1;
                }
                alive
            })
            .sum();
        let stored_before = t.stored;
        let mut chunk_photons = std::mem::take(&mut t.chunk_photons);
        t.append_chunks(&chunk_photons[..chunks]);
        for out in &mut chunk_photons {
            out.clear();
        }
        t.chunk_photons = chunk_photons;
        Flow::new(n, alive + (t.stored - stored_before))
    }
}
