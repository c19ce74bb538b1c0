//! Adds each pixel's radiance of this pass to PM's film as one sample (NaN or Inf counted,
//! never added) and clears it for the next pass.

use crate::film::Film;
use crate::pipeline::Flow;
use glam::DVec3;

pub struct AddPassToFilm;

crate::system! {
    AddPassToFilm = "add_pass_to_film";
    read pixels: usize;
    write pass_radiance: Vec<DVec3>, film: Film;
    run {
        for (pixel, value) in pass_radiance.iter_mut().enumerate() {
            film.add_sample(pixel, value.as_vec3());
            *value = DVec3::ZERO;
        }
        Flow::new(*pixels, *pixels)
    }
}
