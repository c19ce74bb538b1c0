//! Generates one camera ray per sample of the wave: a pinhole camera, each sample uniform
//! inside its pixel (a one-pixel box filter).

use crate::components::Paths;
use crate::components::Rays;
use crate::components::Wave;
use crate::components::path_tracing::DIM_PIXEL;
use crate::components::{Path, PathFlags};
use crate::pipeline::Flow;
use crate::sampling::{SampleKey, Sampler, Stream};
use crate::scene::Camera;
use crate::scene::Frustum;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

pub struct GenerateCameraRays;

crate::system! {
    GenerateCameraRays = "generate_camera_rays";
    read wave: Wave, camera: Camera, pixels: u64, sampler: Sampler<'static>;
    write rays: Rays, paths: Paths, sample_radiance: Vec<Vec3>, active: usize;
    run {
        let n = wave.len;
        let cam = camera.frustum();
        let (first, pixels) = (wave.first, *pixels);
        sample_radiance[..n].fill(Vec3::ZERO);
        let rays = rays.chunks_mut(0..n);
        let paths = paths.chunks_mut(0..n);
        rays.into_par_iter().zip(paths).for_each(|(r, mut p)| {
            for i in 0..r.len() {
                let slot = r.start + i;
                let ray = camera_ray(sampler, &cam, pixels, first + slot as u64);
                r.origin[i] = ray.origin;
                r.dir[i] = ray.dir;
                p.set(
                    i,
                    Path {
                        sample: slot as u32,
                        key: ray.key,
                        throughput: Vec3::ONE,
                        radiance: Vec3::ZERO,
                        depth: 0,
                        bsdf_pdf: 0.0,
                        flags: PathFlags(PathFlags::SPECULAR),
                    },
                );
            }
        });
        *active = n;
        Flow::new(n, n)
    }
}

/// The camera ray of one sample and the key of its random numbers.
#[derive(Clone, Copy, Debug)]
pub struct CameraRay {
    pub key: SampleKey,
    pub origin: Vec3,
    pub dir: Vec3,
}

/// The camera ray of global sample `g` (pixel `g % pixels`, sample index `g / pixels`): the
/// one per-sample step of this system, shared with the megakernel (`systems/trace/paths.rs`).
#[inline(always)]
pub fn camera_ray(sampler: &Sampler, cam: &Frustum, pixels: u64, g: u64) -> CameraRay {
    let w = cam.width as u64;
    let pixel = g % pixels;
    let key = sampler.key(Stream::Camera, pixel, g / pixels);
    let jitter = sampler.get2(key, DIM_PIXEL);
    let raster = Vec2::new((pixel % w) as f32, (pixel / w) as f32) + jitter;
    CameraRay {
        key,
        origin: cam.position,
        dir: cam.direction(raster),
    }
}
