//! Next-event estimation: at every path on a non-delta surface, picks an emitter by power and a
//! point on it uniformly by area, and casts a shadow ray carrying the MIS-weighted (power
//! heuristic against BSDF sampling) contribution it brings if unoccluded.

use crate::bsdf::{Bsdf, KindVisitor, Material, MaterialKind, TransportMode, scatters_between};
use crate::components::ShadowRays;
use crate::components::path_tracing::DIM_LIGHT_PICK;
use crate::components::path_tracing::DIM_LIGHT_POINT;
use crate::components::path_tracing::MaterialRanges;
use crate::components::path_tracing::bounce_dim;
use crate::components::{Paths, PathsView, ShadowRaysChunk, Surfaces, SurfacesView};
use crate::lanes::{F, LaneKernel, LaneWidth, M, Mask, Real, V3, lanes_of, run_lanes};
use crate::math::gamma;
use crate::pipeline::Flow;
use crate::sampling::{SampleKey, Sampler, power_heuristic, sample_cdf};
use crate::scene::SceneData;
use crate::systems::shade::Surface;
use crate::systems::shade::lanes::{
    SurfaceLanes, draw, draw2, offset_origin, power_heuristic as power_heuristic_lanes,
};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

pub struct SampleLights;

crate::system! {
    SampleLights = "sample_lights";
    read data: Arc<SceneData>, sampler: Sampler<'static>, lanes: LaneWidth,
        triangles: Vec<u32>, dirs: Vec<Vec3>, paths: Paths, surfaces: Surfaces,
        materials: Vec<Material>, ranges: MaterialRanges;
    write shadow: ShadowRays, shadow_len: usize;
    run {
        let data: &SceneData = data;
        let range = ranges.non_delta();
        let taken = range.len();
        *shadow_len = range.end;
        let cast: usize = shadow
            .chunks_mut(range)
            .into_par_iter()
            .map(|c| {
                let chunk = SampleChunk {
                    data, sampler, triangles, dirs, paths, surfaces, materials, ranges, c,
                };
                run_lanes(*lanes, chunk)
            })
            .sum();
        Flow::new(taken, cast)
    }
}

/// Light sampling's work over one chunk, for `run_lanes`.
struct SampleChunk<'a> {
    data: &'a SceneData,
    sampler: &'a Sampler<'a>,
    triangles: &'a [u32],
    dirs: &'a [Vec3],
    paths: &'a Paths,
    surfaces: &'a Surfaces,
    materials: &'a [Material],
    ranges: &'a MaterialRanges,
    c: ShadowRaysChunk<'a>,
}

impl LaneKernel for SampleChunk<'_> {
    type Output = usize;
    #[inline(always)]
    fn run<const N: usize>(self) -> usize {
        sample_chunk::<N>(self)
    }
}

/// Light sampling at the paths of one chunk; returns the number of shadow rays cast.
#[inline(always)]
fn sample_chunk<const N: usize>(chunk: SampleChunk) -> usize {
    let SampleChunk {
        data,
        sampler,
        triangles,
        dirs,
        paths,
        surfaces,
        materials: looked_up,
        ranges,
        mut c,
    } = chunk;
    let mut cast = 0;
    let range = c.start..c.start + c.len();
    let looked_up = looked_up.get(range.clone()).unwrap_or_default();
    let (triangles, dirs) = (&triangles[range.clone()], &dirs[range.clone()]);
    let paths = paths.view(range.clone());
    let surfaces = surfaces.view(range);
    let one = |c: &mut ShadowRaysChunk, i: usize| {
        c.t_max[i] = 0.0;
        let surf = Surface::at(data, &surfaces, looked_up, triangles[i], i, dirs[i]);
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
            1
        } else {
            0
        }
    };
    // Groups of N paths on one kind with a lane form at a time; the rest (other kinds, groups
    // that mix kinds, the chunk's tail) one by one. The lanes sample triangles only: scenes
    // with point lights or a light at infinity go one by one.
    let lanes = data.scene.emitters.only_triangles();
    let mut i = 0;
    // The queues hold one kind each, in `MaterialKind::ALL`'s order (`sort_by_material`): a
    // group within one queue is of that kind, which `SurfaceLanes::at` checks path by path.
    let mut queue = 0;
    while lanes && i + N <= c.len() {
        let (first, end) = (c.start + i, c.start + i + N);
        while queue + 1 < MaterialKind::COUNT && ranges.of(MaterialKind::ALL[queue]).end <= first {
            queue += 1;
        }
        let kind = MaterialKind::ALL[queue];
        if end > ranges.of(kind).end {
            for j in i..i + N {
                cast += one(&mut c, j);
            }
            i += N;
            continue;
        }
        let group = LightLanesOf::<N> {
            data,
            sampler,
            surfaces: &surfaces,
            looked_up,
            dirs,
            paths: &paths,
            i,
            c: &mut c,
        };
        match kind.visit(group) {
            Some(n) => cast += n,
            None => {
                for j in i..i + N {
                    cast += one(&mut c, j);
                }
            }
        }
        i += N;
    }
    for j in i..c.len() {
        cast += one(&mut c, j);
    }
    cast
}

/// The length of every light sample's shadow ray (`spawn_ray_to`'s).
const LIGHT_T_MAX: f32 = 1.0 - crate::geometry::SHADOW_EPSILON;

/// Light sampling for the `N` paths from slot `i` of a chunk, if they are all on materials of
/// the visited kind and it has a lane form (`Bsdf::IN_LANES`): writes their shadow rays and
/// returns how many are cast (None: the paths are left to be sampled one by one).
struct LightLanesOf<'a, 'c, const N: usize> {
    data: &'a SceneData,
    sampler: &'a Sampler<'a>,
    surfaces: &'a SurfacesView<'a>,
    looked_up: &'a [Material],
    dirs: &'a [Vec3],
    paths: &'a PathsView<'a>,
    i: usize,
    c: &'a mut ShadowRaysChunk<'c>,
}

impl<const N: usize> KindVisitor for LightLanesOf<'_, '_, N> {
    type Output = Option<usize>;
    #[inline(always)]
    fn visit<B: Bsdf>(self) -> Option<usize> {
        if !B::IN_LANES {
            return None;
        }
        let LightLanesOf {
            data,
            sampler,
            surfaces,
            looked_up,
            dirs,
            paths,
            i,
            c,
        } = self;
        let (surf, materials) = SurfaceLanes::<N>::at::<B>(data, surfaces, looked_up, dirs, i)?;
        let keys: &[SampleKey; N] = paths.key[i..i + N].try_into().unwrap();
        let depths: &[u32; N] = paths.depth[i..i + N].try_into().unwrap();
        let throughput = V3::load(&paths.throughput[i..]);
        let light = light_sample_lanes(data, sampler, &surf, &materials, keys, depths, throughput);
        let t_max = F::select(light.cast, F::splat(LIGHT_T_MAX), F::splat(0.0));
        light.origin.store(&mut c.origin[i..]);
        light.dir.store(&mut c.dir[i..]);
        light.contribution.store(&mut c.contribution[i..]);
        c.t_max[i..i + N].copy_from_slice(&t_max.0);
        Some((0..N).filter(|&l| light.cast.lane(l)).count())
    }
}

/// `light_sample` of `N` paths: the shadow rays and their contributions, which count only
/// where `cast` is set.
pub struct LightLanes<const N: usize> {
    pub cast: M<N>,
    pub origin: V3<F<N>>,
    pub dir: V3<F<N>>,
    pub contribution: V3<F<N>>,
}

/// `light_sample` in lanes, for paths on materials of one kind with a lane form (the BSDF by
/// `Bsdf::eval_pdf_lanes`, the very maths of the single path): lane by lane the same
/// operations, so the same bits. Such lobes never refract.
#[inline(always)]
pub fn light_sample_lanes<B: Bsdf, const N: usize>(
    data: &SceneData,
    sampler: &Sampler,
    surf: &SurfaceLanes<N>,
    materials: &[B; N],
    keys: &[SampleKey; N],
    depths: &[u32; N],
    throughput: V3<F<N>>,
) -> LightLanes<N> {
    let scene = &data.scene;
    let emitters = &scene.emitters;
    let u_pick = draw(
        sampler,
        keys,
        &lanes_of(|l| bounce_dim(depths[l]) + DIM_LIGHT_PICK),
    );
    let (ux, uy) = draw2(
        sampler,
        keys,
        &lanes_of(|l| bounce_dim(depths[l]) + DIM_LIGHT_POINT),
    );
    // sample_emitter: an emitter by the cdf, a point uniform on it.
    let e: [usize; N] = lanes_of(|l| sample_cdf(&emitters.cdf, u_pick.0[l]));
    let su = ux.sqrt();
    let (b1, b2) = (1.0 - su, uy * su);
    let tri: [usize; N] = lanes_of(|l| emitters.triangle[e[l]] as usize);
    let tris = &scene.triangles;
    let (p0, p1, p2) = (
        V3::from_fn(|l| tris.p0[tri[l]]),
        V3::from_fn(|l| tris.p1[tri[l]]),
        V3::from_fn(|l| tris.p2[tri[l]]),
    );
    // surface_point: b0 from f64, so that its only error is the final rounding.
    let b0 = F::from_fn(|l| (1.0 - f64::from(b1.0[l]) - f64::from(b2.0[l])) as f32);
    let (w0, w1, w2) = (b0 * p0, b1 * p1, b2 * p2);
    let light_p = w0 + w1 + w2;
    let light_p_error = F::splat(gamma(7)) * (w0.abs() + w1.abs() + w2.abs());
    let light_ng = V3::from_fn(|l| tris.normal[tri[l]]);
    let pdf_area = F::from_fn(|l| emitters.pmf[e[l]] / emitters.area[e[l]]);
    let radiance = V3::from_fn(|l| emitters.radiance[e[l]]);
    // sample_light_from
    let to_light = light_p - surf.p;
    let dist2 = to_light.dot(to_light);
    let wi = to_light / dist2.sqrt();
    let cos_light = -wi.dot(light_ng);
    let zero = F::splat(0.0);
    let facing =
        !(cos_light.less_eq(zero) | (wi.dot(surf.ng) * surf.wo.dot(surf.ng)).less_eq(zero));
    // spawn_ray_to: both ends moved off their surfaces, towards each other.
    let origin = offset_origin(surf.p, surf.p_error, surf.ng, light_p - surf.p);
    let target = offset_origin(light_p, light_p_error, light_ng, origin - light_p);
    let light_pdf = pdf_area * dist2 / cos_light;
    // The BSDF toward the light, and MIS against sampling it.
    let wi_local = surf.frame.to_local(wi);
    let (f, bsdf_pdf) = B::eval_pdf_lanes(materials, surf.wo_local, wi_local);
    let black = f.is_zero();
    let weight = power_heuristic_lanes(light_pdf, bsdf_pdf);
    LightLanes {
        cast: facing & !black,
        origin,
        dir: target - origin,
        contribution: throughput * f * (wi_local.z.abs() * weight / light_pdf) * radiance,
    }
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
    let kind = surf.material.kind();
    let light = data.scene.sample_light_from(
        surf.p,
        surf.p_error,
        surf.ng,
        surf.wo,
        kind.transmits(),
        sampler.get(key, dim + DIM_LIGHT_PICK),
        sampler.get2(key, dim + DIM_LIGHT_POINT),
    )?;
    let wi_local = surf.frame.to_local(light.wi);
    if kind.transmits()
        && !scatters_between(
            kind,
            surf.wo.dot(surf.ng),
            light.wi.dot(surf.ng),
            surf.wo_local.z,
            wi_local.z,
        )
    {
        return None;
    }
    let (f, pdf) = surf
        .material
        .eval_pdf(surf.wo_local, wi_local, TransportMode::Radiance);
    if f == Vec3::ZERO {
        return None;
    }
    let weight = if light.delta {
        1.0
    } else {
        power_heuristic(light.pdf, pdf)
    };
    Some(LightConnection {
        origin: light.origin,
        dir: light.dir,
        t_max: light.t_max,
        contribution: throughput * f * (wi_local.z.abs() * weight / light.pdf) * light.radiance,
    })
}
