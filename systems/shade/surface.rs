//! The shading point of a hit, shared by the systems that shade, sample lights or add
//! emission: position with its error bound, normals, the shading frame and wo.

use super::lanes::{SurfaceLanes, draw2, material_seen, offset_origin};
use crate::bsdf::{Bsdf, BsdfSample, KindVisitor, Material, TransportMode, leaving_direction};
use crate::components::path_tracing::DIM_BSDF;
use crate::components::path_tracing::bounce_dim;
use crate::components::{PathFlags, Paths, PathsChunk, Rays, RaysChunk, Surfaces, SurfacesView};
use crate::geometry::{SurfacePoint, offset_ray_origin};
use crate::lanes::{F, LaneKernel, LaneWidth, M, Mask, Real, V3, lanes_of, run_lanes};
use crate::math::Frame;
use crate::pipeline::Flow;
use crate::sampling::{SampleKey, Sampler};
use crate::scene::SceneData;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::marker::PhantomData;
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
    /// given), seen along `dir`; its material is `looked_up[i]` where the scene has textures
    /// (`look_up_textures` wrote the chunk's column), else the scene's (`looked_up` empty).
    #[inline(always)]
    pub fn at(
        data: &SceneData,
        surfaces: &SurfacesView,
        looked_up: &[Material],
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
        let material = material_seen(data, looked_up, surfaces, i);
        Surface::with_material(data, triangle, &point, dir, material)
    }

    /// The shading point at `point` on `triangle` (its shading normal in the hemisphere of
    /// its geometric one, as `sort_by_material::shading_point` makes it), seen along
    /// `dir`, its textures looked up here (the megakernel's way).
    #[inline(always)]
    pub fn new(data: &SceneData, triangle: u32, point: &SurfacePoint, dir: Vec3) -> Surface {
        let material = material_looked_up(data, triangle, point, dir);
        Surface::with_material(data, triangle, point, dir, material)
    }

    #[inline(always)]
    fn with_material(
        data: &SceneData,
        triangle: u32,
        point: &SurfacePoint,
        dir: Vec3,
        material: Material,
    ) -> Surface {
        let wo = -dir;
        let (ng, ns) = facing_normals(data, triangle, point, wo);
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

/// The geometric and shading normals a shading point uses, seen from `wo`: Lambertian
/// surfaces (and two-sided others) reflect on both sides, so they shade from the side the
/// ray came from, the material read in that frame.
#[inline(always)]
fn facing_normals(data: &SceneData, triangle: u32, point: &SurfacePoint, wo: Vec3) -> (Vec3, Vec3) {
    if wo.dot(point.ng) < 0.0 && data.scene.reflects_on_both_sides(triangle) {
        (-point.ng, -point.ns)
    } else {
        (point.ng, point.ns)
    }
}

/// The material a ray along `dir` sees at `point` on `triangle`, its textures looked up there
/// (in the shading frame `Surface` builds).
#[inline(always)]
pub fn material_looked_up(
    data: &SceneData,
    triangle: u32,
    point: &SurfacePoint,
    dir: Vec3,
) -> Material {
    let wo = -dir;
    let (_, ns) = facing_normals(data, triangle, point, wo);
    data.scene
        .material_seen(triangle, point.p, wo, point.ng, ns)
}

/// The scattering step every shading system shares, over the paths of `range` (all on
/// materials of one kind): at each path the surface's BSDF draws wi; the path's throughput,
/// next ray and MIS state follow, or the path ends when the sample carries nothing or leaks
/// through the surface. Kinds with a lane form (`Bsdf::IN_LANES`) go `lanes` paths at a time. A `KindVisitor`: compiled once
/// per material type so that each loop holds only its kind's BSDF code (about 1% of a PT
/// render's instructions); visiting returns the flow (paths taken, paths that scatter on).
pub struct ScatterPaths<'a> {
    pub data: &'a SceneData,
    pub sampler: &'a Sampler<'a>,
    pub lanes: LaneWidth,
    pub triangles: &'a [u32],
    pub surfaces: &'a Surfaces,
    pub looked_up: &'a [Material],
    pub rays: &'a mut Rays,
    pub paths: &'a mut Paths,
    pub range: Range<usize>,
}

impl KindVisitor for ScatterPaths<'_> {
    type Output = Flow;
    #[inline]
    fn visit<B: Bsdf>(self) -> Flow {
        let ScatterPaths {
            data,
            sampler,
            lanes,
            triangles,
            surfaces,
            looked_up,
            rays,
            paths,
            range,
        } = self;
        let taken = range.len();
        let rays = rays.chunks_mut(range.clone());
        let paths = paths.chunks_mut(range);
        let scattered: usize = rays
            .into_par_iter()
            .zip(paths)
            .map(|(r, p)| {
                let chunk = ScatterChunk::<B> {
                    data,
                    sampler,
                    triangles,
                    surfaces,
                    looked_up,
                    r,
                    p,
                    bsdf: PhantomData,
                };
                run_lanes(lanes, chunk)
            })
            .sum();
        Flow::new(taken, scattered)
    }
}

/// The scattering step's work over one chunk, for `run_lanes`.
struct ScatterChunk<'a, B> {
    data: &'a SceneData,
    sampler: &'a Sampler<'a>,
    triangles: &'a [u32],
    surfaces: &'a Surfaces,
    looked_up: &'a [Material],
    r: RaysChunk<'a>,
    p: PathsChunk<'a>,
    bsdf: PhantomData<fn() -> B>,
}

impl<B: Bsdf> LaneKernel for ScatterChunk<'_, B> {
    type Output = usize;
    #[inline(always)]
    fn run<const N: usize>(self) -> usize {
        let ScatterChunk {
            data,
            sampler,
            triangles,
            surfaces,
            looked_up,
            r,
            p,
            bsdf: _,
        } = self;
        scatter_chunk::<B, N>(data, sampler, triangles, surfaces, looked_up, r, p)
    }
}

/// The scattering step at the paths of one chunk; returns the number that scatter on.
#[inline(always)]
fn scatter_chunk<B: Bsdf, const N: usize>(
    data: &SceneData,
    sampler: &Sampler,
    triangles: &[u32],
    surfaces: &Surfaces,
    looked_up: &[Material],
    r: RaysChunk,
    p: PathsChunk,
) -> usize {
    let mut scattered = 0;
    let range = p.start..p.start + p.len();
    let looked_up = looked_up.get(range.clone()).unwrap_or_default();
    let (triangles, surfaces) = (&triangles[range.clone()], surfaces.view(range));
    // Kinds with a lane form N paths at a time (the rest one by one, below).
    let mut first = 0;
    if B::IN_LANES {
        while first + N <= p.len() {
            let i = first;
            let Some((surf, materials)) =
                SurfaceLanes::<N>::at::<B>(data, &surfaces, looked_up, r.dir, i)
            else {
                break;
            };
            let keys: &[SampleKey; N] = p.key[i..i + N].try_into().unwrap();
            let depths: &[u32; N] = p.depth[i..i + N].try_into().unwrap();
            let next = scatter_lanes(sampler, &surf, &materials, keys, depths);
            // Every lane is written, without a branch per lane: a path that ends here is
            // only ever read again for its radiance (Russian roulette empties its ray and
            // `sort_by_material` retires it), so what lands in its other columns is unused.
            let throughput = V3::load(&p.throughput[i..]) * next.weight;
            throughput.store(&mut p.throughput[i..]);
            p.bsdf_pdf[i..i + N].copy_from_slice(&next.pdf.0);
            next.origin.store(&mut r.origin[i..]);
            next.dir.store(&mut r.dir[i..]);
            for l in 0..N {
                let j = i + l;
                let on = next.scattered.lane(l);
                p.depth[j] += 1;
                // Also clears SPECULAR on an ended path, which is harmless (see above).
                p.flags[j].set(PathFlags::SPECULAR, false);
                p.flags[j].set(PathFlags::DEAD, !on);
                scattered += usize::from(on);
            }
            first += N;
        }
    }
    for (i, &triangle) in triangles.iter().enumerate().skip(first) {
        let surf = Surface::at(data, &surfaces, looked_up, triangle, i, r.dir[i]);
        // The material queue holds only this kind: its own type's sample runs, no dispatch.
        let Some(bsdf) = B::of(&surf.material) else {
            debug_assert!(
                false,
                "a path of another material kind in this kind's queue"
            );
            p.flags[i].set(PathFlags::DEAD, true);
            continue;
        };
        let sample = |wo, u| bsdf.sample(wo, u, TransportMode::Radiance);
        match scatter_by(sampler, &surf, p.key[i], p.depth[i], sample) {
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
    let sample = |wo, u| surf.material.sample(wo, u, TransportMode::Radiance);
    scatter_by(sampler, surf, key, depth, sample)
}

/// `scatter` with the BSDF sample drawn by `sample` (from wo in the shading frame and the
/// path's two numbers): the material's, or where the caller knows the material's type, that
/// type's own.
#[inline(always)]
fn scatter_by(
    sampler: &Sampler,
    surf: &Surface,
    key: SampleKey,
    depth: u32,
    sample: impl FnOnce(Vec3, Vec2) -> Option<BsdfSample>,
) -> Option<Scattered> {
    let u = sampler.get2(key, bounce_dim(depth) + DIM_BSDF);
    let bs = sample(surf.wo_local, u)?;
    let (bs, wi) = leaving_direction(bs, &surf.frame, surf.ng, surf.wo, surf.wo_local)?;
    let weight = bs.value * bs.wi.z.abs() / bs.pdf;
    (weight.max_element() > 0.0).then(|| Scattered {
        weight,
        pdf: bs.pdf,
        delta: bs.delta,
        origin: surf.spawn(wi),
        dir: wi,
    })
}

/// `scatter` of `N` paths on materials of one kind with a lane form: where `scattered` is
/// set, the path's throughput factor, BSDF density and next ray.
pub struct ScatterLanes<const N: usize> {
    pub scattered: M<N>,
    pub weight: V3<F<N>>,
    pub pdf: F<N>,
    pub origin: V3<F<N>>,
    pub dir: V3<F<N>>,
}

/// `scatter` in lanes for paths on materials of one kind with a lane form (`sample_lanes`, the
/// very maths of the single path, then `sample_direction`'s test): lane by lane the same
/// operations, so the same bits. Such lobes never refract and are never delta.
#[inline(always)]
pub fn scatter_lanes<B: Bsdf, const N: usize>(
    sampler: &Sampler,
    surf: &SurfaceLanes<N>,
    materials: &[B; N],
    keys: &[SampleKey; N],
    depths: &[u32; N],
) -> ScatterLanes<N> {
    let (ux, uy) = draw2(
        sampler,
        keys,
        &lanes_of(|l| bounce_dim(depths[l]) + DIM_BSDF),
    );
    let zero = F::splat(0.0);
    let bs = B::sample_lanes(materials, surf.wo_local, ux, uy);
    // sample_direction: reflection must leave on wo's side of the geometric surface.
    let dir = surf.frame.to_world(bs.wi).normalize();
    let reflected = (bs.wi.z * surf.wo_local.z).greater(zero);
    let leaves_right = (dir.dot(surf.ng) * surf.wo.dot(surf.ng)).greater(zero);
    let kept = bs.valid & !(leaves_right ^ reflected);
    let weight = bs.value * bs.wi.z.abs() / bs.pdf;
    ScatterLanes {
        scattered: kept & weight.max_element().greater(zero),
        weight,
        pdf: bs.pdf,
        origin: offset_origin(surf.p, surf.p_error, surf.ng, dir),
        dir,
    }
}
