//! The furnace: a closed diffuse sphere (reflectance 0.5) emitting radiance 1 inward. Every
//! pixel's exact value is Le / (1 - rho) = 2; with the depth capped at D bounces it is the
//! partial sum 2 - 0.5^D. These are analytic checks of the path tracer, MIS weights included.

use crate::common::*;

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

/// The furnace with an object inside it: the radiance field is uniform (2 everywhere), so a
/// lossless dielectric is invisible (entering scales radiance by 1/eta^2, leaving by eta^2),
/// and a white near-mirror conductor shows 2 times its albedo, which is just under 1. (A
/// coloured conductor would absorb, and the field would no longer be uniform.)
fn furnace_with(object: &str) -> stagelight::scene::PreparedScene {
    let text = format!(
        r#"Scene(
    camera: (position: (0, 0, 0), look_at: (0, 0, 1), up: (0, 1, 0), fov: 60, width: 32, height: 32),
    materials: {{
        "grey": Diffuse(reflectance: (0.5, 0.5, 0.5)),
        "glass": Dielectric(ior: 1.5),
        "mirror": Conductor(alpha: 0.01, reflectance: (1, 1, 1)),
    }},
    objects: [
        (material: "grey", emission: Some((1, 1, 1)), shape: Icosphere(level: 3), flip_normals: true),
        {object}
    ],
)"#
    );
    stagelight::scene::load_from_str(std::path::Path::new("furnace_with_object.ron"), &text)
        .expect("scene loads")
}

#[test]
fn glass_in_the_furnace_is_invisible() {
    let scene = furnace_with(
        r#"(material: "glass", shape: Icosphere(level: 3, smooth: true), transform: [Scale(0.3), Translate((0, 0, 0.5))]),"#,
    );
    let o = render_pt(scene, 64, 3, u32::MAX);
    assert!(o.systems.contains(&"shade_dielectric"));
    assert_eq!(o.film.nonfinite, 0);
    let image = o.film.image();
    let (mean, sd) = pixel_stats(&image, 0);
    let stderr = sd / (image.pixels.len() as f64).sqrt();
    assert!(
        (mean - 2.0).abs() < 5.0 * stderr,
        "mean {mean}, stderr {stderr}"
    );
    // The pixels that see the sphere through its centre: still 2.
    let centre = block_means(&image, 8)[4 + 1 + 4];
    assert!((centre[0] - 2.0).abs() < 0.1, "centre block {centre:?}");
}

#[test]
fn near_mirror_conductor_in_the_furnace_shows_its_albedo() {
    let scene = furnace_with(
        r#"(material: "mirror", shape: Box(min: (-0.5, -0.5, 0.6), max: (0.5, 0.5, 0.8))),"#,
    );
    let o = render_pt(scene, 32, 5, u32::MAX);
    assert!(o.systems.contains(&"shade_conductor"));
    assert_eq!(o.film.nonfinite, 0);
    // The central pixels see the box's front face head-on: 2 x the albedo of GGX at alpha
    // 0.01 (a near-mirror loses well under 1% to single-scattering Smith masking).
    let image = o.film.image();
    // The 8 x 8 pixels at the centre of the image.
    let c = block_means(&image, 8)[4 + 1 + 4];
    for (ch, value) in c.iter().enumerate() {
        let v = value / 2.0;
        assert!((0.97..=1.01).contains(&v), "channel {ch}: {value} for 2");
    }
}

/// A closed white furnace (reflectance 1) has no finite answer, but every render of it must
/// still end: Russian roulette never lets a path survive with probability 1.
#[test]
fn a_closed_white_scene_still_terminates() {
    let text = r#"Scene(
    camera: (position: (0, 0, 0), look_at: (0, 0, 1), fov: 90, width: 8, height: 8),
    materials: { "white": Diffuse(reflectance: (1, 1, 1)) },
    objects: [(material: "white", emission: Some((1, 1, 1)), shape: Icosphere(level: 2), flip_normals: true)],
)"#;
    let scene = stagelight::scene::load_from_str(std::path::Path::new("white.ron"), text)
        .expect("scene loads");
    let o = render_pt(scene, 2, 1, u32::MAX);
    assert_eq!(o.samples, 128);
    assert_eq!(o.film.nonfinite, 0);
}
