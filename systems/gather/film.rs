//! Adds the wave's finished samples to the film, in global sample order, so the image never
//! depends on how work was split between threads.

use crate::integrators::pt::PtState;
use crate::pipeline::{Flow, System};

pub struct AccumulateFilm;

impl System<PtState> for AccumulateFilm {
    fn name(&self) -> &'static str {
        "accumulate_film"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["sample_radiance", "wave"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["film"]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let (first, len, pixels) = (s.wave.first, s.wave.len, s.pixels);
        for (i, &value) in s.sample_radiance[..len].iter().enumerate() {
            s.film
                .add_sample(((first + i as u64) % pixels) as usize, value);
        }
        Flow::new(len, len)
    }
}
