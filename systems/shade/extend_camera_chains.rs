//! Camera chains of the photon mappers: at each hit, adds the emission seen, then either
//! follows a specular surface or a conductor smoother than `photons::FOLLOW_ALPHA` by
//! sampling it (keeping the glossy ones in `met_glossy`, where the integrator samples light),
//! or ends on any other surface, which becomes the chain's gather point unless the chain is
//! at the depth cap. Chains that leave the scene, reach the depth cap or lose the roulette
//! (after `ROULETTE_DEPTH` bounces, by throughput) end with no gather point. In a ray tree
//! (PPM) a chain at a dielectric (thick or thin) follows both branches instead, the second as a new chain,
//! and at a followed conductor one sampled direction, with no roulette (see `camera_walk`).
//! At a smooth plastic a chain follows the delta reflection or gathers on the diffuse lobe, by
//! the choice its BSDF sampling makes (a tree: both); see the rule where it is applied.

use crate::bsdf::{Material, TransportMode, sample_direction};
use crate::components::CameraChains;
use crate::components::Hits;
use crate::components::Rays;
use crate::components::camera_walk::Branch;
use crate::components::camera_walk::MIN_BRANCH_WEIGHT;
use crate::components::camera_walk::TREE_DEPTH;
use crate::components::{CHUNK, MISS, NO_VISIBLE_POINT, VisiblePoint};
use crate::geometry::{offset_ray_origin, surface_point};
use crate::math::Frame;
use crate::photons::chains_follow;
use crate::pipeline::Flow;
use crate::sampling::Sampler;
use crate::sampling::power_heuristic;
use crate::sampling::roulette::{ROULETTE_DEPTH, survival, survives};
use crate::scene::NO_EMITTER;
use crate::scene::PreparedScene;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Random-number dimensions of a camera chain: the pixel jitter (2), then per bounce a BSDF
/// sample (2) and roulette (1).
pub const DIM_PIXEL: u32 = 0;
pub const DIMS_PER_BOUNCE: u32 = 3;

#[inline]
pub fn bounce_dim(depth: u32) -> u32 {
    2 + depth * DIMS_PER_BOUNCE
}

pub struct ExtendCameraChains;

crate::system! {
    ExtendCameraChains = "extend_camera_chains";
    read scene: PreparedScene, sampler: Sampler<'static>, max_depth: u32, tree: bool,
        direct_light: bool, hits: Hits, live: usize;
    write chains: CameraChains, rays: Rays, spawned: Vec<Vec<Branch>>,
        met_glossy: Vec<Vec<VisiblePoint>>;
    run {
        let (n, max_depth, tree, direct_light) = (*live, *max_depth, *tree, *direct_light);
        let rays = rays.chunks_mut(0..n);
        let chunks = n.div_ceil(CHUNK);
        spawned.resize_with(chunks, Vec::new);
        met_glossy.resize_with(chunks, Vec::new);
        let live: usize = chains
            .chunks_mut(0..n)
            .into_par_iter()
            .zip(rays)
            .zip(spawned[..chunks].par_iter_mut().zip(&mut met_glossy[..chunks]))
            .map(|((c, r), (out, glossy))| {
                out.clear();
                glossy.clear();
                let mut live = 0;
                let hits = hits.view(c.start..c.start + c.len());
                for i in 0..c.len() {
                    c.alive[i] = false;
                    c.triangle[i] = NO_VISIBLE_POINT;
                    let tri = hits.triangle[i];
                    if tri == MISS {
                        // Leaving the scene: the light at infinity, if any, weighed as an
                        // emitter the chain hits.
                        let dir = r.dir[i];
                        if let Some((_, env)) = scene.emitters.environment()
                            && dir != Vec3::ZERO
                        {
                            let weight = if c.bsdf_pdf[i] > 0.0 {
                                power_heuristic(c.bsdf_pdf[i], scene.environment_light_pdf(dir))
                            } else {
                                1.0
                            };
                            c.emitted[i] += c.beta[i] * env.eval(dir) * weight;
                        }
                        continue;
                    }
                    let sp = surface_point(&scene.triangles, tri, hits.b1[i], hits.b2[i]);
                    let wo = -r.dir[i];
                    let e = scene.triangles.emitter[tri as usize] as usize;
                    let cos_light = wo.dot(sp.ng);
                    if e != NO_EMITTER as usize && cos_light > 0.0 {
                        // After a glossy bounce the light sample there could have found this
                        // emitter too: weigh both by the power heuristic, as a path tracer.
                        let em = &scene.emitters;
                        let weight = if c.bsdf_pdf[i] > 0.0 {
                            let t = hits.t[i];
                            let light_pdf = em.pmf[e] / em.area[e] * t * t / cos_light;
                            power_heuristic(c.bsdf_pdf[i], light_pdf)
                        } else {
                            1.0
                        };
                        c.emitted[i] += c.beta[i] * em.radiance[e] * weight;
                    }
                    if scene.seen_from_behind(tri, wo, sp.ng) {
                        // Nothing reflects here (a one-sided surface seen from behind): no
                        // visible point, the chain ends.
                        continue;
                    }
                    let (mut ng, mut ns) = (sp.ng, sp.ns);
                    if wo.dot(ng) < 0.0 && scene.reflects_on_both_sides(tri) {
                        // Lambertian surfaces reflect on both sides: gather on wo's side.
                        ng = -ng;
                        ns = -ns;
                    }
                    if ns.dot(ng) < 0.0 {
                        ns = -ns;
                    }
                    // Read after the normals settle: an anisotropic lobe's axis is given in
                    // the frame of `ns`.
                    let material = scene.material_facing(tri, sp.p, wo, ns);
                    let depth = c.depth[i];
                    if let Material::Plastic(plastic) = material
                        && depth < max_depth
                    {
                        // The smooth plastic's rule: chains follow its delta reflection and
                        // gather on its diffuse lobe (a visible point's `eval` is that lobe
                        // alone). A tree takes both: the visible point here and the reflection
                        // as a new chain, weighing specular F. A chain takes one, chosen as
                        // `sample` chooses (the reflection with probability p): the reflection,
                        // weighing specular F / p, or the visible point here, its throughput
                        // over 1 - p. Both unbiased; photons are stored at plastics.
                        let frame = Frame::from_normal(ns);
                        let wo_local = frame.to_local(wo);
                        let p = if wo_local.z > 0.0 {
                            plastic.specular_probability(wo_local.z)
                        } else {
                            0.0
                        };
                        let reflect = |u: f32| {
                            sample_direction(
                                &material,
                                &frame,
                                ng,
                                wo,
                                wo_local,
                                Vec2::new(u, 0.5),
                                TransportMode::Radiance,
                            )
                            .filter(|(bs, _)| bs.delta)
                        };
                        if tree {
                            if depth < TREE_DEPTH
                                && p > 0.0
                                && let Some((bs, wi)) = reflect(0.0)
                            {
                                let beta = c.beta[i] * bs.value * bs.wi.z.abs();
                                let weight = beta.max_element();
                                if !weight.is_nan() && weight >= MIN_BRANCH_WEIGHT {
                                    out.push(Branch {
                                        pixel: c.pixel[i],
                                        key: c.key[i],
                                        beta,
                                        depth: depth + 1,
                                        origin: offset_ray_origin(sp.p, sp.p_error, sp.ng, wi),
                                        dir: wi,
                                    });
                                }
                            }
                        } else {
                            let dim = bounce_dim(depth);
                            let u = sampler.get(c.key[i], dim);
                            if u < p {
                                let Some((bs, wi)) = reflect(u) else {
                                    continue;
                                };
                                let mut beta = c.beta[i] * bs.value * (bs.wi.z.abs() / bs.pdf);
                                if depth + 1 >= ROULETTE_DEPTH {
                                    let q = survival(beta, 1.0);
                                    if !survives(q, sampler.get(c.key[i], dim + 2)) {
                                        continue;
                                    }
                                    beta /= q;
                                }
                                c.beta[i] = beta;
                                c.bsdf_pdf[i] = 0.0;
                                c.depth[i] = depth + 1;
                                c.alive[i] = true;
                                r.origin[i] = offset_ray_origin(sp.p, sp.p_error, sp.ng, wi);
                                r.dir[i] = wi;
                                live += 1;
                                continue;
                            }
                            c.beta[i] /= 1.0 - p;
                        }
                    }
                    if !chains_follow(&material) {
                        // At the depth cap every path through the point (light sampled there,
                        // photons gathered, a final gather) is a bounce too long: no gather
                        // point, as a path tracer ends there.
                        if depth < max_depth {
                            c.p[i] = sp.p;
                            c.p_error[i] = sp.p_error;
                            c.ng[i] = ng;
                            c.ns[i] = ns;
                            c.wo[i] = wo;
                            c.triangle[i] = tri;
                        }
                        continue;
                    }
                    if depth >= max_depth || (tree && depth >= TREE_DEPTH) {
                        continue;
                    }
                    let frame = Frame::from_normal(ns);
                    let wo_local = frame.to_local(wo);
                    if tree && material.kind().is_delta() {
                        // Refraction (u = 1 is never below F), then reflection (u = 0 is
                        // below F unless F = 0); each weighs its Fresnel term: f cos, not
                        // divided by the probability of choosing it.
                        let mut next = None;
                        for u in [1.0, 0.0] {
                            let Some((bs, wi)) = sample_direction(
                                &material,
                                &frame,
                                ng,
                                wo,
                                wo_local,
                                Vec2::new(u, 0.0),
                                TransportMode::Radiance,
                            ) else {
                                continue;
                            };
                            if (bs.wi.z * wo_local.z > 0.0) != (u == 0.0) {
                                continue;
                            }
                            let beta = c.beta[i] * bs.value * bs.wi.z.abs();
                            let weight = beta.max_element();
                            if weight.is_nan() || weight < MIN_BRANCH_WEIGHT {
                                continue;
                            }
                            let origin = offset_ray_origin(sp.p, sp.p_error, sp.ng, wi);
                            if next.is_none() {
                                next = Some((beta, origin, wi));
                            } else {
                                out.push(Branch {
                                    pixel: c.pixel[i],
                                    key: c.key[i],
                                    beta,
                                    depth: depth + 1,
                                    origin,
                                    dir: wi,
                                });
                            }
                        }
                        let Some((beta, origin, wi)) = next else {
                            continue;
                        };
                        c.beta[i] = beta;
                        c.bsdf_pdf[i] = 0.0;
                        c.depth[i] = depth + 1;
                        c.alive[i] = true;
                        r.origin[i] = origin;
                        r.dir[i] = wi;
                        live += 1;
                        continue;
                    }
                    if direct_light {
                        // A followed glossy surface: the integrator samples light here.
                        glossy.push(VisiblePoint {
                            pixel: c.pixel[i],
                            branch: 0,
                            p: sp.p,
                            p_error: sp.p_error,
                            ng,
                            ns,
                            wo,
                            triangle: tri,
                            beta: c.beta[i],
                            emitted: Vec3::ZERO,
                            depth,
                        });
                    }
                    let dim = bounce_dim(depth);
                    let Some((bs, wi)) = sample_direction(
                        &material,
                        &frame,
                        ng,
                        wo,
                        wo_local,
                        sampler.get2(c.key[i], dim),
                        TransportMode::Radiance,
                    ) else {
                        continue;
                    };
                    let mut beta = c.beta[i] * bs.value * (bs.wi.z.abs() / bs.pdf);
                    if tree {
                        // A tree's glossy bounce is one sampled direction, kept with its
                        // hit points; a branch too light to matter ends, as at glass.
                        let weight = beta.max_element();
                        if weight.is_nan() || weight < MIN_BRANCH_WEIGHT {
                            continue;
                        }
                    } else if depth + 1 >= ROULETTE_DEPTH {
                        let q = survival(beta, 1.0);
                        if !survives(q, sampler.get(c.key[i], dim + 2)) {
                            continue;
                        }
                        beta /= q;
                    }
                    c.beta[i] = beta;
                    c.bsdf_pdf[i] = if bs.delta { 0.0 } else { bs.pdf };
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
