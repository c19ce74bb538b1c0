//! Adds the wave's finished samples to the film. The film's sums are exact, so the image never
//! depends on how the work was split between threads.

use crate::components::Wave;
use crate::film::Film;
use crate::pipeline::Flow;
use glam::Vec3;

pub struct AccumulateFilm;

crate::system! {
    AccumulateFilm = "accumulate_film";
    read sample_radiance: Vec<Vec3>, wave: Wave, pixels: u64;
    write film: Film;
    run {
        let len = wave.len;
        debug_assert_eq!(*pixels as usize, film.width * film.height);
        film.add_wave(wave.first, &sample_radiance[..len]);
        Flow::new(len, len)
    }
}
