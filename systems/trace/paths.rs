//! The megakernel (`--kernel megakernel`): each thread carries one path at a time from the
//! camera to its end, calling the same per-path steps as the wavefront PT's systems (camera
//! ray, closest hit, emission, surface point, light sample and its shadow ray, BSDF sample,
//! Russian roulette) in the same order, so every sample's radiance is the same f32 value as
//! the wavefront's, and the film the same bits. Nothing is stored between the steps: a path's
//! state lives in registers and on the stack, and only its final radiance is written.

use crate::accel::{Accel, Hit};
use crate::components::Wave;
use crate::components::path_tracing::PtSettings;
use crate::components::{CHUNK, PathFlags};
use crate::pipeline::Flow;
use crate::sampling::Sampler;
use crate::scene::Frustum;
use crate::scene::SceneData;
use crate::systems::connect::sample_lights::light_sample;
use crate::systems::generate::camera_rays::camera_ray;
use crate::systems::shade::emitted_light::{emitted_light, escaped_light};
use crate::systems::shade::russian_roulette::roulette;
use crate::systems::shade::sort_by_material::shading_point;
use crate::systems::shade::{Surface, scatter};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

pub struct TracePaths;

crate::system! {
    TracePaths = "trace_paths";
    read data: Arc<SceneData>, settings: PtSettings, sampler: Sampler<'static>, wave: Wave,
        pixels: u64;
    write sample_radiance: Vec<Vec3>, traced: RayCounts;
    run {
        let n = wave.len;
        let walk = Walk {
            data,
            sampler,
            camera: data.scene.camera.frustum(),
            pixels: *pixels,
            max_depth: settings.max_depth,
            has_emitters: !data.scene.emitters.triangle.is_empty(),
        };
        let first = wave.first;
        let counts = sample_radiance[..n]
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, radiance)| {
                let first = first + (c * CHUNK) as u64;
                #[cfg(target_arch = "x86_64")]
                if crate::cpu::has_avx2_fma() {
                    // SAFETY: the CPU has AVX2 and FMA (checked just above).
                    return unsafe { walk_chunk_avx2(&walk, first, radiance) };
                }
                walk_chunk(&walk, first, radiance, |o, d, t_max, any| {
                    if any {
                        walk.data.accel.any_hit(o, d, t_max).then_some(HIT_SOMETHING)
                    } else {
                        walk.data.accel.closest_hit(o, d, t_max)
                    }
                })
            })
            .reduce(RayCounts::default, RayCounts::add);
        traced.closest += counts.closest;
        traced.shadow += counts.shadow;
        Flow::new(n, n)
    }
}

/// Rays the megakernel traced (the wavefront counts them as its trace systems' items).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    pub closest: u64,
    pub shadow: u64,
}

impl RayCounts {
    fn add(self, o: RayCounts) -> RayCounts {
        RayCounts {
            closest: self.closest + o.closest,
            shadow: self.shadow + o.shadow,
        }
    }
}

/// What every path of a wave shares.
struct Walk<'a> {
    data: &'a SceneData,
    sampler: &'a Sampler<'static>,
    camera: Frustum,
    pixels: u64,
    max_depth: u32,
    /// The scene has an emitter: the wavefront's graph adds emission and samples lights only then.
    has_emitters: bool,
}

/// Stands for "something is in the way" where only occlusion was asked.
const HIT_SOMETHING: Hit = Hit {
    t: 0.0,
    triangle: 0,
    b1: 0.0,
    b2: 0.0,
};

/// `walk_chunk` compiled for AVX2 and FMA with the traversal inlined, as the wavefront's
/// hot systems are (see `crate::cpu`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn walk_chunk_avx2(walk: &Walk, first: u64, radiance: &mut [Vec3]) -> RayCounts {
    let accel: &Accel = &walk.data.accel;
    walk_chunk(walk, first, radiance, |o, d, t_max, any| {
        // SAFETY: this function is compiled for AVX2 and FMA and only called where the CPU
        // has them.
        unsafe {
            if any {
                accel.trace_in_avx2::<true>(o, d, t_max)
            } else {
                accel.trace_in_avx2::<false>(o, d, t_max)
            }
        }
    })
}

/// The paths of global samples `first..first + radiance.len()`, each to its end; writes each
/// one's radiance. `trace(origin, dir, t_max, any)` is the closest hit, or with `any` any hit.
#[inline(always)]
fn walk_chunk(
    walk: &Walk,
    first: u64,
    radiance: &mut [Vec3],
    trace: impl Fn(Vec3, Vec3, f32, bool) -> Option<Hit>,
) -> RayCounts {
    let mut counts = RayCounts::default();
    for (i, out) in radiance.iter_mut().enumerate() {
        *out = walk_path(walk, first + i as u64, &trace, &mut counts);
    }
    counts
}

/// One path, camera to end: the wavefront's bounce loop for a single path, step for step.
#[inline(always)]
fn walk_path(
    walk: &Walk,
    g: u64,
    trace: &impl Fn(Vec3, Vec3, f32, bool) -> Option<Hit>,
    counts: &mut RayCounts,
) -> Vec3 {
    let data = walk.data;
    let ray = camera_ray(walk.sampler, &walk.camera, walk.pixels, g);
    let key = ray.key;
    let (mut origin, mut dir) = (ray.origin, ray.dir);
    let mut throughput = Vec3::ONE;
    let mut radiance = Vec3::ZERO;
    let mut depth = 0;
    let mut bsdf_pdf = 0.0;
    let mut flags = PathFlags(PathFlags::SPECULAR);
    loop {
        // trace_closest
        counts.closest += 1;
        let Some(hit) = trace(origin, dir, f32::INFINITY, false) else {
            if walk.has_emitters
                && let Some(light) = escaped_light(data, dir, throughput, flags, bsdf_pdf)
            {
                radiance += light;
            }
            break;
        };
        // add_emitted_light
        if walk.has_emitters
            && let Some(light) = emitted_light(data, &hit, dir, throughput, flags, bsdf_pdf)
        {
            radiance += light;
        }
        // sort_by_material retires paths at the depth cap
        if depth >= walk.max_depth {
            break;
        }
        // sort_by_material interpolates the surface point
        let point = shading_point(&data.scene.triangles, hit.triangle, hit.b1, hit.b2);
        let surf = Surface::new(data, hit.triangle, &point, dir);
        // sample_lights, only at non-delta kinds
        let connection = if walk.has_emitters && !surf.material.kind().is_delta() {
            light_sample(data, walk.sampler, &surf, key, depth, throughput)
        } else {
            None
        };
        // shade_KIND
        let next = scatter(walk.sampler, &surf, key, depth);
        // trace_shadow, apply_shadow_contributions
        if let Some(c) = connection {
            counts.shadow += 1;
            if trace(c.origin, c.dir, c.t_max, true).is_none() {
                radiance += c.contribution;
            }
        }
        let Some(next) = next else {
            break;
        };
        throughput *= next.weight;
        bsdf_pdf = next.pdf;
        flags.set(PathFlags::SPECULAR, next.delta);
        depth += 1;
        origin = next.origin;
        dir = next.dir;
        // russian_roulette
        if !roulette(walk.sampler, key, depth, &mut throughput) {
            break;
        }
    }
    radiance
}
