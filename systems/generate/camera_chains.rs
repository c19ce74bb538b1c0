//! Starts the photon mappers' camera chains: one camera ray per pixel, uniform inside it
//! (a one-pixel box filter), keyed by (seed, pixel, pass) so every pass jitters anew.

use crate::integrators::camera_walk::CameraWalk;
use crate::pipeline::Flow;
use crate::sampling::Stream;
use crate::systems::shade::extend_camera_chains::DIM_PIXEL;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

pub struct GenerateCameraChains;

crate::system! {
    GenerateCameraChains = "generate_camera_chains";
    on CameraWalk {
        read camera = data.scene.camera, sampler, sample_index, starts, tree;
        write chains, rays, active, points;
    }
    run {
        let (sample_index, n) = (*sample_index, *starts);
        let cam = camera.frustum();
        let w = cam.width as u64;
        let rays = rays.chunks_mut(0..n);
        chains
            .chunks_mut(0..n)
            .into_par_iter()
            .zip(rays)
            .for_each(|(c, r)| {
                for i in 0..c.len() {
                    let pixel = (c.start + i) as u64;
                    let key = sampler.key(Stream::Camera, pixel, sample_index);
                    let raster =
                        Vec2::new((pixel % w) as f32, (pixel / w) as f32) + sampler.get2(key, DIM_PIXEL);
                    r.origin[i] = cam.position;
                    r.dir[i] = cam.direction(raster);
                    c.pixel[i] = pixel as u32;
                    c.key[i] = key;
                    c.beta[i] = Vec3::ONE;
                    c.emitted[i] = Vec3::ZERO;
                    c.depth[i] = 0;
                    c.alive[i] = true;
                }
            });
        *active = n;
        if *tree && n > 0 {
            // A new tree: its hit points are appended as its chains end.
            *points = 0;
        }
        Flow::new(n, n)
    }
}
