//! The film accumulates in f64: a million samples of a constant give that constant exactly.

use glam::Vec3;
use stagelight::film::Film;

#[test]
fn a_million_samples_of_a_constant_give_the_constant() {
    let mut film = Film::new(1, 1);
    let value = Vec3::new(0.1, 1.0 / 3.0, 17.3);
    for _ in 0..1_000_000 {
        film.add_sample(0, value);
    }
    assert_eq!(film.image().pixels[0], value);
    assert_eq!(film.total_samples(), 1_000_000);
}
