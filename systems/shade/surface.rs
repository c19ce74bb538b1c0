//! The shading point of a hit, shared by the systems that shade, sample lights or add
//! emission: position with its error bound, normals, the shading frame and wo.

use super::lanes::{DiffuseLanes, F, LANES, M, V3, draw2, lanes_of, offset_origin, same_side};
use crate::bsdf::{Material, MaterialKind, TransportMode, sample_direction};
use crate::components::path_tracing::DIM_BSDF;
use crate::components::path_tracing::bounce_dim;
use crate::components::{
    Hits, PathFlags, Paths, PathsChunk, Rays, RaysChunk, Surfaces, SurfacesView,
};
use crate::geometry::{SurfacePoint, offset_ray_origin};
use crate::math::Frame;
use crate::pipeline::Flow;
use crate::sampling::{SampleKey, Sampler};
use crate::scene::SceneData;
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::{FRAC_1_PI, PI};
use std::ops::Range;

pub struct Surface {
    pub p: Vec3,
    pub p_error: Vec3,
    /// Geometric normal (flipped to wo's side for two-sided materials).
    pub ng: Vec3,
    /// Shading frame; its normal is in the hemisphere of `ng`.
    pub frame: Frame,
    /// Direction towards the ray's origin, world and local.
    pub wo: Vec3,
    pub wo_local: Vec3,
    pub material: Material,
}

impl Surface {
    /// The shading point of item `i` of a chunk's view of the surfaces (its hit's triangle
    /// given), seen along `dir`.
    #[inline(always)]
    pub fn at(
        data: &SceneData,
        surfaces: &SurfacesView,
        triangle: u32,
        i: usize,
        dir: Vec3,
    ) -> Surface {
        let point = SurfacePoint {
            p: surfaces.p[i],
            p_error: surfaces.p_error[i],
            ng: surfaces.ng[i],
            ns: surfaces.ns[i],
        };
        Surface::new(data, triangle, &point, dir)
    }

    /// The shading point at `point` on `triangle` (its shading normal in the hemisphere of
    /// its geometric one, as `sort_by_material::shading_point` makes it), seen along
    /// `dir`.
    #[inline(always)]
    pub fn new(data: &SceneData, triangle: u32, point: &SurfacePoint, dir: Vec3) -> Surface {
        let tris = &data.scene.triangles;
        let material = data.scene.materials[tris.material[triangle as usize] as usize];
        let mut ng = point.ng;
        let mut ns = point.ns;
        let wo = -dir;
        // Lambertian surfaces reflect on both sides: shade from the side the ray came from.
        if matches!(material, Material::Diffuse { .. }) && wo.dot(ng) < 0.0 {
            ng = -ng;
            ns = -ns;
        }
        let frame = Frame::from_normal(ns);
        Surface {
            p: point.p,
            p_error: point.p_error,
            ng,
            frame,
            wo,
            wo_local: frame.to_local(wo),
            material,
        }
    }

    /// Origin of a ray leaving towards `w` that cannot re-hit this surface.
    #[inline]
    pub fn spawn(&self, w: Vec3) -> Vec3 {
        offset_ray_origin(self.p, self.p_error, self.ng, w)
    }
}

/// The scattering step every shading system shares, compiled once per material kind `KIND`
/// (a `MaterialKind as u8`) so that each loop holds only its kind's BSDF code (about 1% of a
/// PT render's instructions): at each path of `range` (all on materials of that kind) the
/// surface's BSDF draws wi; the path's throughput, next ray and MIS state follow, or the path
/// ends when the sample carries nothing or leaks through the surface. Returns the flow (paths
/// taken, paths that scatter on).
#[inline]
pub fn scatter_paths<const KIND: u8>(
    data: &SceneData,
    sampler: &Sampler,
    hits: &Hits,
    surfaces: &Surfaces,
    rays: &mut Rays,
    paths: &mut Paths,
    range: Range<usize>,
) -> Flow {
    let taken = range.len();
    let rays = rays.chunks_mut(range.clone());
    let paths = paths.chunks_mut(range);
    let scattered: usize = rays
        .into_par_iter()
        .zip(paths)
        .map(|(r, p)| {
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::has_avx512() {
                // SAFETY: the CPU has AVX-512 (F, DQ, VL, BW), AVX2 and FMA (checked just above).
                return unsafe {
                    scatter_chunk_avx512::<KIND>(data, sampler, hits, surfaces, r, p)
                };
            }
            if crate::cpu::has_avx2_fma() {
                // SAFETY: the CPU has AVX2 and FMA (checked just above).
                return unsafe { scatter_chunk_avx2::<KIND>(data, sampler, hits, surfaces, r, p) };
            }
            scatter_chunk::<KIND>(data, sampler, hits, surfaces, r, p)
        })
        .sum();
    Flow::new(taken, scattered)
}

/// `scatter_chunk` compiled for AVX2 and FMA (see `crate::cpu`): about 15% fewer instructions.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn scatter_chunk_avx2<const KIND: u8>(
    data: &SceneData,
    sampler: &Sampler,
    hits: &Hits,
    surfaces: &Surfaces,
    r: RaysChunk,
    p: PathsChunk,
) -> usize {
    scatter_chunk::<KIND>(data, sampler, hits, surfaces, r, p)
}

/// `scatter_chunk` compiled for AVX-512 (see `crate::cpu::has_avx512`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
fn scatter_chunk_avx512<const KIND: u8>(
    data: &SceneData,
    sampler: &Sampler,
    hits: &Hits,
    surfaces: &Surfaces,
    r: RaysChunk,
    p: PathsChunk,
) -> usize {
    scatter_chunk::<KIND>(data, sampler, hits, surfaces, r, p)
}

/// The scattering step at the paths of one chunk; returns the number that scatter on.
#[inline(always)]
fn scatter_chunk<const KIND: u8>(
    data: &SceneData,
    sampler: &Sampler,
    hits: &Hits,
    surfaces: &Surfaces,
    r: RaysChunk,
    p: PathsChunk,
) -> usize {
    let mut scattered = 0;
    let range = p.start..p.start + p.len();
    let (hits, surfaces) = (hits.view(range.clone()), surfaces.view(range));
    // Lambertian paths LANES at a time (the rest one by one, below).
    let mut first = 0;
    if KIND == MaterialKind::Diffuse as u8 {
        while first + LANES <= p.len() {
            let i = first;
            let Some(surf) = DiffuseLanes::at(data, &surfaces, hits.triangle, r.dir, i) else {
                break;
            };
            let keys: &[SampleKey; LANES] = p.key[i..i + LANES].try_into().unwrap();
            let depths: &[u32; LANES] = p.depth[i..i + LANES].try_into().unwrap();
            let next = scatter_lanes(sampler, &surf, keys, depths);
            let throughput = V3::load(&p.throughput[i..]) * next.weight;
            for l in 0..LANES {
                let j = i + l;
                if next.scattered.0[l] {
                    p.throughput[j] = throughput.lane(l);
                    p.bsdf_pdf[j] = next.pdf.0[l];
                    p.flags[j].set(PathFlags::SPECULAR, false);
                    p.depth[j] += 1;
                    r.origin[j] = next.origin.lane(l);
                    r.dir[j] = next.dir.lane(l);
                    scattered += 1;
                } else {
                    p.flags[j].set(PathFlags::DEAD, true);
                }
            }
            first += LANES;
        }
    }
    for i in first..p.len() {
        let surf = Surface::at(data, &surfaces, hits.triangle[i], i, r.dir[i]);
        // The material queue holds only this kind; saying so lets the compiler drop the
        // other kinds' arms of the inlined BSDF sample.
        if surf.material.kind() as u8 != KIND {
            debug_assert!(
                false,
                "a path of another material kind in this kind's queue"
            );
            p.flags[i].set(PathFlags::DEAD, true);
            continue;
        }
        match scatter(sampler, &surf, p.key[i], p.depth[i]) {
            Some(next) => {
                p.throughput[i] *= next.weight;
                p.bsdf_pdf[i] = next.pdf;
                p.flags[i].set(PathFlags::SPECULAR, next.delta);
                p.depth[i] += 1;
                r.origin[i] = next.origin;
                r.dir[i] = next.dir;
                scattered += 1;
            }
            None => p.flags[i].set(PathFlags::DEAD, true),
        }
    }
    scattered
}

/// Where a path goes on from a surface: what its throughput is multiplied by, the density
/// and kind of the BSDF sample (for MIS at the emitter it may find next), and its next ray.
#[derive(Clone, Copy, Debug)]
pub struct Scattered {
    pub weight: Vec3,
    pub pdf: f32,
    pub delta: bool,
    pub origin: Vec3,
    pub dir: Vec3,
}

/// The BSDF sample of a path at bounce `depth` (its random numbers from `key`), or None when
/// the sample carries nothing or leaks through the surface and the path ends: the one
/// per-path step of the shading systems, shared with the megakernel
/// (`systems/trace/paths.rs`).
#[inline(always)]
pub fn scatter(sampler: &Sampler, surf: &Surface, key: SampleKey, depth: u32) -> Option<Scattered> {
    let u = sampler.get2(key, bounce_dim(depth) + DIM_BSDF);
    let (bs, wi) = sample_direction(
        &surf.material,
        &surf.frame,
        surf.ng,
        surf.wo,
        surf.wo_local,
        u,
        TransportMode::Radiance,
    )?;
    let weight = bs.value * bs.wi.z.abs() / bs.pdf;
    (weight.max_element() > 0.0).then(|| Scattered {
        weight,
        pdf: bs.pdf,
        delta: bs.delta,
        origin: surf.spawn(wi),
        dir: wi,
    })
}

/// `scatter` of `LANES` paths on Lambertian surfaces: where `scattered` is set, the path's
/// throughput factor, BSDF density and next ray.
pub struct ScatterLanes {
    pub scattered: M,
    pub weight: V3,
    pub pdf: F,
    pub origin: V3,
    pub dir: V3,
}

/// `scatter` in lanes for paths on Lambertian surfaces (`diffuse::sample` and
/// `sample_direction`): lane by lane the same operations, so the same bits.
#[inline(always)]
pub fn scatter_lanes(
    sampler: &Sampler,
    surf: &DiffuseLanes,
    keys: &[SampleKey; LANES],
    depths: &[u32; LANES],
) -> ScatterLanes {
    let (ux, uy) = draw2(
        sampler,
        keys,
        &lanes_of(|l| bounce_dim(depths[l]) + DIM_BSDF),
    );
    let zero = F::splat(0.0);
    let wo_z = surf.wo_local.z;
    // cosine_hemisphere: Shirley and Chiu's concentric map, then lifted to the hemisphere.
    let (ox, oy) = (2.0 * ux - 1.0, 2.0 * uy - 1.0);
    let centre = ox.eq(zero) & oy.eq(zero);
    let wide = ox.abs().gt(oy.abs());
    let r = wide.select(ox, oy);
    let theta = wide.select((0.25 * PI) * (oy / ox), 0.5 * PI - (0.25 * PI) * (ox / oy));
    let mut dx = F::splat(0.0);
    let mut dy = F::splat(0.0);
    for l in 0..LANES {
        if !centre.0[l] {
            dx.0[l] = r.0[l] * theta.0[l].cos();
            dy.0[l] = r.0[l] * theta.0[l].sin();
        }
    }
    let z = (1.0 - dx * dx - dy * dy).max(zero).sqrt();
    // Mirror the lobe onto wo's side: the surface reflects on both sides.
    let wi = V3 {
        x: dx,
        y: dy,
        z: wo_z.lt(zero).select(-z, z),
    };
    let same = same_side(wo_z, wi.z);
    let pdf = same.select(wi.z.abs() * FRAC_1_PI, zero);
    let value = surf.reflectance * F::splat(FRAC_1_PI);
    // sample_direction: reflection must leave on wo's side of the geometric surface.
    let dir = surf.frame.to_world(wi).normalize();
    let reflected = (wi.z * wo_z).gt(zero);
    let leaves_right = (dir.dot(surf.ng) * surf.wo.dot(surf.ng)).gt(zero);
    let kept = !wo_z.eq(zero) & !pdf.le(zero) & !(leaves_right ^ reflected);
    let weight = value * wi.z.abs() / pdf;
    ScatterLanes {
        scattered: kept & weight.max_element().gt(zero),
        weight,
        pdf,
        origin: offset_origin(surf.p, surf.p_error, surf.ng, dir),
        dir,
    }
}
