//! Starts the photon mappers' camera chains, at most one per pixel at a time: one camera ray
//! per pixel, uniform inside it (a one-pixel box filter), keyed by (seed, pixel, pass) so every
//! pass jitters anew; or, for PPM's trees, chain c is tree t = c / pixels of pixel c % pixels,
//! jittered to point t of the pixel's stratified net (`CameraWalk::jitter`) and weighing
//! 1 / trees.
//!
//! Under the gaussian filter the jitter is drawn by the filter's shape about the pixel's
//! centre instead (`GaussianSampler`: the same numbers through its inverse distribution), and
//! the chain weighs the filter over that density: each pixel's estimate is then the filtered
//! pixel, however the photon mapper averages its passes. An orthographic camera's rays leave
//! points of its near plane (`Frustum::ray`).

use crate::components::CameraChains;
use crate::components::Rays;
use crate::pipeline::Flow;
use crate::sampling::Sampler;
use crate::sampling::Stream;
use crate::scene::Camera;
use crate::scene::filter::{GaussianSampler, PixelFilter};
use crate::systems::shade::extend_camera_chains::DIM_PIXEL;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

pub struct GenerateCameraChains;

crate::system! {
    GenerateCameraChains = "generate_camera_chains";
    read camera: Camera, sampler: Sampler<'static>, jitter: Sampler<'static>, sample_index: u64,
        starts: usize, tree: bool, trees: u32;
    write chains: CameraChains, rays: Rays, active: usize, points: usize, started: usize,
        glossy_points: usize, glossy_rank: Vec<u32>;
    run {
        let cam = camera.frustum();
        let (w, pixels) = (cam.width as u64, cam.width as u64 * cam.height as u64);
        let filter = match camera.filter {
            PixelFilter::Box => None,
            PixelFilter::Gaussian(g) => Some(GaussianSampler::new(g)),
        };
        let filter = filter.as_ref();
        let first = *started as u64;
        let n = (*starts - *started).min(pixels as usize);
        let (tree, trees, sample_index) = (*tree, *trees, *sample_index);
        let weight = Vec3::splat(1.0 / trees as f32);
        let rays = rays.chunks_mut(0..n);
        chains
            .chunks_mut(0..n)
            .into_par_iter()
            .zip(rays)
            .for_each(|(c, r)| {
                for i in 0..c.len() {
                    let chain = first + (c.start + i) as u64;
                    let pixel = chain % pixels;
                    let (key, offset, beta) = if tree {
                        let t = chain / pixels;
                        let key = sampler.key(Stream::Camera, pixel, t);
                        let at = jitter.get2(jitter.key(Stream::Camera, pixel, t), DIM_PIXEL);
                        (key, at, weight)
                    } else {
                        let key = sampler.key(Stream::Camera, pixel, sample_index);
                        (key, sampler.get2(key, DIM_PIXEL), Vec3::ONE)
                    };
                    let (px, py) = ((pixel % w) as usize, (pixel / w) as usize);
                    let (raster, beta) = match filter {
                        None => (Vec2::new(px as f32, py as f32) + offset, beta),
                        Some(f) => {
                            let (x, wx) = f.sample(offset.x, px, cam.width as usize);
                            let (y, wy) = f.sample(offset.y, py, cam.height as usize);
                            (Vec2::new(x, y), beta * (wx * wy))
                        }
                    };
                    let (origin, dir) = cam.ray(raster);
                    r.origin[i] = origin;
                    r.dir[i] = dir;
                    c.pixel[i] = pixel as u32;
                    c.key[i] = key;
                    c.beta[i] = beta;
                    c.emitted[i] = Vec3::ZERO;
                    c.bsdf_pdf[i] = 0.0;
                    c.depth[i] = 0;
                    c.alive[i] = true;
                }
            });
        *active = n;
        if first == 0 && n > 0 {
            // A new walk: its glossy points (and a new forest's hit points) are appended.
            *glossy_points = 0;
            glossy_rank.fill(0);
            if tree {
                *points = 0;
            }
        }
        *started += n;
        Flow::new(n, n)
    }
}
