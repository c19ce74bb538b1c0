//! Adds each pixel's radiance of this pass to PM's film as one sample (NaN or Inf counted,
//! never added) and clears it for the next pass.

use crate::integrators::pm::PmState;
use crate::pipeline::{Flow, System};
use glam::DVec3;

pub struct AddPassToFilm;

impl System<PmState> for AddPassToFilm {
    fn name(&self) -> &'static str {
        "add_pass_to_film"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["pass_radiance"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["film", "pass_radiance"]
    }
    fn run(&self, s: &mut PmState) -> Flow {
        for (pixel, value) in s.pass_radiance.iter_mut().enumerate() {
            s.film.add_sample(pixel, value.as_vec3());
            *value = DVec3::ZERO;
        }
        Flow::new(s.pixels, s.pixels)
    }
}
