//! Generates one camera ray per sample of the wave: a pinhole camera, each sample uniform
//! inside its pixel (a one-pixel box filter).

use crate::components::PathFlags;
use crate::integrators::pt::{DIM_PIXEL, PtState};
use crate::pipeline::{Flow, System};
use crate::sampling::SampleKey;
use glam::Vec3;
use rayon::prelude::*;

pub struct GenerateCameraRays;

impl System<PtState> for GenerateCameraRays {
    fn name(&self) -> &'static str {
        "generate_camera_rays"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["wave", "camera"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["rays", "paths", "sample_radiance"]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let n = s.wave.len;
        let cam = s.data.scene.camera;
        let (w, h) = (cam.width as u64, cam.height as u64);
        let tan_half = (cam.fov_y_degrees.to_radians() * 0.5).tan();
        let aspect = w as f32 / h as f32;
        let (first, pixels, seed) = (s.wave.first, s.pixels, s.settings.seed);
        s.sample_radiance[..n].fill(Vec3::ZERO);
        let rays = s.rays.chunks_mut(0..n);
        let paths = s.paths.chunks_mut(0..n);
        rays.into_par_iter().zip(paths).for_each(|(r, p)| {
            for i in 0..r.len() {
                let slot = r.start + i;
                let g = first + slot as u64;
                let pixel = g % pixels;
                let key = SampleKey::new(seed, pixel, g / pixels);
                let jitter = key.get2(DIM_PIXEL);
                let (x, y) = ((pixel % w) as f32, (pixel / w) as f32);
                let sx = (2.0 * (x + jitter.x) / w as f32 - 1.0) * tan_half * aspect;
                let sy = (1.0 - 2.0 * (y + jitter.y) / h as f32) * tan_half;
                r.origin[i] = cam.position;
                r.dir[i] = (cam.forward + cam.right * sx + cam.up * sy).normalize();
                p.sample[i] = slot as u32;
                p.key[i] = key;
                p.throughput[i] = Vec3::ONE;
                p.radiance[i] = Vec3::ZERO;
                p.depth[i] = 0;
                p.bsdf_pdf[i] = 0.0;
                p.flags[i] = PathFlags(PathFlags::SPECULAR);
            }
        });
        s.active = n;
        Flow::new(n, n)
    }
}
