//! Next-event estimation: at every path on a non-delta surface, picks an emitter by power and a
//! point on it uniformly by area, and casts a shadow ray carrying the MIS-weighted (power
//! heuristic against BSDF sampling) contribution it brings if unoccluded.

use crate::components::{Hits, Paths, Rays, ShadowRaysChunk, Surfaces};
use crate::integrators::SceneData;
use crate::integrators::pt::{DIM_LIGHT_PICK, DIM_LIGHT_POINT, PtState, bounce_dim};
use crate::pipeline::Flow;
use crate::sampling::{SampleKey, Sampler, power_heuristic};
use crate::systems::shade::Surface;
use glam::Vec3;
use rayon::prelude::*;

pub struct SampleLights;

crate::system! {
    SampleLights = "sample_lights";
    on PtState {
        read data, sampler, hits, rays, paths, surfaces, ranges;
        write shadow, shadow_len;
    }
    run {
        let data: &SceneData = data;
        let range = ranges.non_delta();
        let taken = range.len();
        *shadow_len = range.end;
        let cast: usize = shadow
            .chunks_mut(range)
            .into_par_iter()
            .map(|c| {
                #[cfg(target_arch = "x86_64")]
                if crate::cpu::has_avx2_fma() {
                    // SAFETY: the CPU has AVX2 and FMA (checked just above).
                    return unsafe { sample_chunk_avx2(data, sampler, hits, rays, paths, surfaces, c) };
                }
                sample_chunk(data, sampler, hits, rays, paths, surfaces, c)
            })
            .sum();
        Flow::new(taken, cast)
    }
}

/// `sample_chunk` compiled for AVX2 and FMA (see `crate::cpu`): about 15% fewer instructions.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn sample_chunk_avx2(
    data: &SceneData,
    sampler: &Sampler,
    hits: &Hits,
    rays: &Rays,
    paths: &Paths,
    surfaces: &Surfaces,
    c: ShadowRaysChunk,
) -> usize {
    sample_chunk(data, sampler, hits, rays, paths, surfaces, c)
}

/// Light sampling at the paths of one chunk; returns the number of shadow rays cast.
#[inline(always)]
fn sample_chunk(
    data: &SceneData,
    sampler: &Sampler,
    hits: &Hits,
    rays: &Rays,
    paths: &Paths,
    surfaces: &Surfaces,
    c: ShadowRaysChunk,
) -> usize {
    let mut cast = 0;
    let range = c.start..c.start + c.len();
    let hits = hits.view(range.clone());
    let rays = rays.view(range.clone());
    let paths = paths.view(range.clone());
    let surfaces = surfaces.view(range);
    for i in 0..c.len() {
        c.t_max[i] = 0.0;
        let surf = Surface::at(data, &surfaces, hits.triangle[i], i, rays.dir[i]);
        if let Some(light) = light_sample(
            data,
            sampler,
            &surf,
            paths.key[i],
            paths.depth[i],
            paths.throughput[i],
        ) {
            c.origin[i] = light.origin;
            c.dir[i] = light.dir;
            c.t_max[i] = light.t_max;
            c.contribution[i] = light.contribution;
            cast += 1;
        }
    }
    cast
}

/// A shadow ray toward a light sample and what it brings if unoccluded.
#[derive(Clone, Copy, Debug)]
pub struct LightConnection {
    pub origin: Vec3,
    pub dir: Vec3,
    pub t_max: f32,
    /// Radiance the path receives if the ray is unoccluded (MIS weight included).
    pub contribution: Vec3,
}

/// Next-event estimation at a path's surface (bounce `depth`, random numbers from `key`,
/// `throughput` so far): an emitter point and the shadow ray to it, or None when the sample
/// brings nothing. The one per-path step of this system, shared with the megakernel
/// (`systems/trace/paths.rs`). The scene must have an emitter.
#[inline(always)]
pub fn light_sample(
    data: &SceneData,
    sampler: &Sampler,
    surf: &Surface,
    key: SampleKey,
    depth: u32,
    throughput: Vec3,
) -> Option<LightConnection> {
    let dim = bounce_dim(depth);
    let light = data.scene.sample_light_from(
        surf.p,
        surf.p_error,
        surf.ng,
        surf.wo,
        sampler.get(key, dim + DIM_LIGHT_PICK),
        sampler.get2(key, dim + DIM_LIGHT_POINT),
    )?;
    let wi_local = surf.frame.to_local(light.wi);
    let f = surf.material.eval(surf.wo_local, wi_local);
    if f == Vec3::ZERO {
        return None;
    }
    let weight = power_heuristic(light.pdf, surf.material.pdf(surf.wo_local, wi_local));
    Some(LightConnection {
        origin: light.origin,
        dir: light.dir,
        t_max: light.t_max,
        contribution: throughput * f * (wi_local.z.abs() * weight / light.pdf) * light.radiance,
    })
}
