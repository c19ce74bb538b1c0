//! The shading point of a hit, shared by the systems that shade, sample lights or add
//! emission: position with its error bound, normals, the shading frame and wo.

use crate::bsdf::{Material, TransportMode, sample_direction};
use crate::components::{
    Hits, PathFlags, Paths, PathsChunk, Rays, RaysChunk, Surfaces, SurfacesView,
};
use crate::geometry::{SurfacePoint, offset_ray_origin};
use crate::integrators::SceneData;
use crate::integrators::pt::{DIM_BSDF, bounce_dim};
use crate::math::Frame;
use crate::pipeline::Flow;
use crate::sampling::{SampleKey, Sampler};
use glam::Vec3;
use rayon::prelude::*;
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
    /// its geometric one, as `interpolate_surfaces::shading_point` makes it), seen along
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
    for i in 0..p.len() {
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
