//! Next-event estimation: at every path on a non-delta surface, picks an emitter by power and a
//! point on it uniformly by area, and casts a shadow ray carrying the MIS-weighted (power
//! heuristic against BSDF sampling) contribution it brings if unoccluded.

use crate::accel::spawn_ray_to;
use crate::components::{Hits, Paths, Rays, ShadowRaysChunk, Surfaces};
use crate::integrators::SceneData;
use crate::integrators::pt::{DIM_LIGHT_PICK, DIM_LIGHT_POINT, PtState, bounce_dim};
use crate::pipeline::{Flow, System};
use crate::sampling::power_heuristic;
use crate::systems::shade::Surface;
use glam::Vec3;
use rayon::prelude::*;

pub struct SampleLights;

impl System<PtState> for SampleLights {
    fn name(&self) -> &'static str {
        "sample_lights"
    }
    fn reads(&self) -> &'static [&'static str] {
        &[
            "hits",
            "surfaces",
            "rays.dir",
            "paths",
            "material_ranges",
            "emitters",
        ]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["shadow_rays"]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let data = &*s.data;
        let (hits, rays, paths, surfaces) = (&s.hits, &s.rays, &s.paths, &s.surfaces);
        let range = s.ranges.non_delta();
        let taken = range.len();
        let cast: usize = s
            .shadow
            .chunks_mut(range)
            .into_par_iter()
            .map(|c| {
                #[cfg(target_arch = "x86_64")]
                if crate::cpu::has_avx2_fma() {
                    // SAFETY: the CPU has AVX2 and FMA (checked just above).
                    return unsafe { sample_chunk_avx2(data, hits, rays, paths, surfaces, c) };
                }
                sample_chunk(data, hits, rays, paths, surfaces, c)
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
    hits: &Hits,
    rays: &Rays,
    paths: &Paths,
    surfaces: &Surfaces,
    c: ShadowRaysChunk,
) -> usize {
    sample_chunk(data, hits, rays, paths, surfaces, c)
}

/// Light sampling at the paths of one chunk; returns the number of shadow rays cast.
#[inline(always)]
fn sample_chunk(
    data: &SceneData,
    hits: &Hits,
    rays: &Rays,
    paths: &Paths,
    surfaces: &Surfaces,
    c: ShadowRaysChunk,
) -> usize {
    let emitters = &data.scene.emitters;

    let mut cast = 0;
    let range = c.start..c.start + c.len();
    let hits = hits.view(range.clone());
    let rays = rays.view(range.clone());
    let paths = paths.view(range.clone());
    let surfaces = surfaces.view(range);
    for i in 0..c.len() {
        c.t_max[i] = 0.0;
        let surf = Surface::at(data, &surfaces, hits.triangle[i], i, rays.dir[i]);
        let key = paths.key[i];
        let dim = bounce_dim(paths.depth[i]);
        let sampled = data.scene.sample_emitter(
            key.get(dim + DIM_LIGHT_PICK),
            key.get2(dim + DIM_LIGHT_POINT),
        );
        let (e, light) = (sampled.emitter, sampled.point);
        let to_light = light.p - surf.p;
        let dist2 = to_light.length_squared();
        let wi = to_light / dist2.sqrt();
        let cos_light = -wi.dot(light.ng);
        if cos_light <= 0.0 || !surf.reflects_geometrically(wi) {
            continue;
        }
        let wi_local = surf.frame.to_local(wi);
        let f = surf.material.eval(surf.wo_local, wi_local);
        if f == Vec3::ZERO {
            continue;
        }
        let light_pdf = sampled.pdf_area * dist2 / cos_light;
        let weight = power_heuristic(light_pdf, surf.material.pdf(surf.wo_local, wi_local));
        let (origin, dir, t_max) = spawn_ray_to(
            surf.p,
            surf.p_error,
            surf.ng,
            light.p,
            light.p_error,
            light.ng,
        );
        c.origin[i] = origin;
        c.dir[i] = dir;
        c.t_max[i] = t_max;
        c.contribution[i] = paths.throughput[i]
            * f
            * (wi_local.z.abs() * weight / light_pdf)
            * emitters.radiance[e];
        cast += 1;
    }
    cast
}
