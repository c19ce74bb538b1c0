//! Adds the wave's finished samples to the film. The film's sums are exact, so the image never
//! depends on how the work was split between threads.

use crate::integrators::pt::PtState;
use crate::integrators::pt_megakernel::MegakernelState;
use crate::pipeline::Flow;

pub struct AccumulateFilm;

crate::system! {
    AccumulateFilm = "accumulate_film";
    on PtState {
        read sample_radiance, wave, pixels;
        write film;
    }
    on MegakernelState {
        read sample_radiance, wave, pixels;
        write film;
    }
    run {
        let len = wave.len;
        debug_assert_eq!(*pixels as usize, film.width * film.height);
        film.add_wave(wave.first, &sample_radiance[..len]);
        Flow::new(len, len)
    }
}
