//! Generates one camera ray per sample of the wave: a pinhole camera, each sample uniform
//! inside its pixel (a one-pixel box filter).

use crate::components::PathFlags;
use crate::integrators::pt::{DIM_PIXEL, PtState};
use crate::pipeline::Flow;
use crate::sampling::Stream;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

pub struct GenerateCameraRays;

crate::system! {
    GenerateCameraRays = "generate_camera_rays";
    on PtState {
        read wave, camera = data.scene.camera, pixels, sampler;
        write rays, paths, sample_radiance, active;
    }
    run {
        let n = wave.len;
        let cam = camera.frustum();
        let w = cam.width as u64;
        let (first, pixels) = (wave.first, *pixels);
        sample_radiance[..n].fill(Vec3::ZERO);
        let rays = rays.chunks_mut(0..n);
        let paths = paths.chunks_mut(0..n);
        rays.into_par_iter().zip(paths).for_each(|(r, p)| {
            for i in 0..r.len() {
                let slot = r.start + i;
                let g = first + slot as u64;
                let pixel = g % pixels;
                let key = sampler.key(Stream::Camera, pixel, g / pixels);
                let jitter = sampler.get2(key, DIM_PIXEL);
                let raster = Vec2::new((pixel % w) as f32, (pixel / w) as f32) + jitter;
                r.origin[i] = cam.position;
                r.dir[i] = cam.direction(raster);
                p.sample[i] = slot as u32;
                p.key[i] = key;
                p.throughput[i] = Vec3::ONE;
                p.radiance[i] = Vec3::ZERO;
                p.depth[i] = 0;
                p.bsdf_pdf[i] = 0.0;
                p.flags[i] = PathFlags(PathFlags::SPECULAR);
            }
        });
        *active = n;
        Flow::new(n, n)
    }
}
