//! The furnace: a closed diffuse sphere (reflectance 0.5) emitting radiance 1 inward. Every
//! pixel's exact value is Le / (1 - rho) = 2; with the depth capped at D bounces it is the
//! partial sum 2 - 0.5^D. These are analytic checks of the path tracer, MIS weights included.

mod common;
use common::*;

/// Renders the furnace and checks every channel's image mean against `expected` within five
/// standard errors (estimated from the pixel spread: pixels are independent), and every pixel
/// within six pixel standard deviations.
fn check_furnace(max_depth: u32, expected: f64) {
    let size = 48;
    let spp = 32;
    let o = render_pt(load_small("furnace.ron", size), spp, 7, max_depth);
    assert_eq!(o.film.nonfinite, 0);
    let image = o.film.image();
    for c in 0..3 {
        let (mean, sd) = pixel_stats(&image, c);
        let stderr = sd / (image.pixels.len() as f64).sqrt();
        // A floor on the spread keeps the bound meaningful when the estimator is exact.
        let tol = 5.0 * stderr.max(1e-6);
        assert!(
            (mean - expected).abs() < tol,
            "channel {c}: mean {mean} vs {expected} (tolerance {tol}, max depth {max_depth})"
        );
        let worst = image
            .pixels
            .iter()
            .map(|p| (p[c] as f64 - expected).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 6.0 * sd.max(1e-6) + 1e-6,
            "channel {c}: a pixel is {worst} from {expected} (pixel sd {sd})"
        );
    }
}

#[test]
fn furnace_is_two_everywhere() {
    check_furnace(u32::MAX, 2.0);
}

#[test]
fn furnace_with_depth_cap_matches_partial_sums() {
    check_furnace(0, 1.0);
    check_furnace(1, 1.5);
    check_furnace(3, 2.0 - 0.125);
}

#[test]
fn furnace_graph_has_no_dielectric_or_conductor_system() {
    let o = render_pt(load_small("furnace.ron", 8), 1, 0, u32::MAX);
    assert!(o.systems.contains(&"shade_diffuse"));
    assert!(!o.systems.contains(&"shade_dielectric"));
    assert!(!o.systems.contains(&"shade_conductor"));
}
