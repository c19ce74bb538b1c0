//! Adds the wave's finished samples to the film, each where its camera ray went through. The film's sums are exact, so the image never
//! depends on how the work was split between threads.

use crate::components::Wave;
use crate::film::Film;
use crate::pipeline::Flow;
use crate::sampling::Sampler;
use crate::scene::Camera;
use crate::systems::generate::camera_rays::sample_raster;
use glam::Vec3;

pub struct AccumulateFilm;

crate::system! {
    AccumulateFilm = "accumulate_film";
    read sample_radiance: Vec<Vec3>, wave: Wave, pixels: u64, camera: Camera,
        sampler: Sampler<'static>;
    write film: Film;
    run {
        let len = wave.len;
        debug_assert_eq!(*pixels as usize, film.width * film.height);
        // Where each sample fell, for a filter wider than its pixel: the camera ray's own
        // jitter, drawn again from its key.
        let cam = camera.frustum();
        let raster = |g: u64| sample_raster(sampler, &cam, *pixels, g).1;
        film.add_wave_at(wave.first, &sample_radiance[..len], &raster);
        Flow::new(len, len)
    }
}
