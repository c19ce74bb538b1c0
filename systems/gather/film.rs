//! Adds the wave's finished samples to the film, in global sample order, so the image never
//! depends on how work was split between threads.

use crate::integrators::pt::PtState;
use crate::pipeline::Flow;

pub struct AccumulateFilm;

crate::system! {
    AccumulateFilm = "accumulate_film";
    on PtState {
        read sample_radiance, wave, pixels;
        write film;
    }
    run {
        let (first, len) = (wave.first, wave.len);
        for (i, &value) in sample_radiance[..len].iter().enumerate() {
            film.add_sample(((first + i as u64) % pixels) as usize, value);
        }
        Flow::new(len, len)
    }
}
