//! Starts the photon mappers' camera chains: one camera ray per pixel, uniform inside it
//! (a one-pixel box filter), keyed by (seed, pixel, pass) so every pass jitters anew.

use crate::pipeline::{Flow, System};
use crate::sampling::SampleKey;
use crate::systems::shade::extend_camera_chains::{CameraChainQueue, DIM_PIXEL};
use glam::{Vec2, Vec3};
use rayon::prelude::*;

pub struct GenerateCameraChains;

impl<S: CameraChainQueue + Send> System<S> for GenerateCameraChains {
    fn name(&self) -> &'static str {
        "generate_camera_chains"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["camera", "pass"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["camera_chains", "rays"]
    }
    fn run(&self, state: &mut S) -> Flow {
        let (seed, sample_index, n) = state.new_chains();
        let q = state.camera_chain_queue();
        let cam = q.data.scene.camera.frustum();
        let w = cam.width as u64;
        let rays = q.wave.rays.chunks_mut(0..n);
        q.wave
            .chains
            .chunks_mut(0..n)
            .into_par_iter()
            .zip(rays)
            .for_each(|(c, r)| {
                for i in 0..c.len() {
                    let pixel = (c.start + i) as u64;
                    let key = SampleKey::new(seed, pixel, sample_index);
                    let raster =
                        Vec2::new((pixel % w) as f32, (pixel / w) as f32) + key.get2(DIM_PIXEL);
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
        q.wave.active = n;
        Flow::new(n, n)
    }
}
