//! The photon mappers. PPM and SPPM: the progressive update on unit cases, convergence on the
//! analytic furnace, error against a path-traced reference that falls with passes. PM: its
//! bias in the furnace, its caustic map only where needed. All: thread-count determinism.

use crate::common::*;
use glam::DVec3;
use stagelight::film::Image;
use stagelight::integrators::pm;
use stagelight::integrators::sppm::{self, ProgressiveSettings};
use stagelight::integrators::{Budget, Control, RenderOutcome, SceneData};
use stagelight::systems::gather::progressive_update::progressive_update;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

fn render(data: Arc<SceneData>, settings: ProgressiveSettings, passes: u64) -> Image {
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    let o = sppm::render(data, settings, Budget::SamplesPerPixel(passes), &control);
    assert_eq!(o.passes, passes);
    assert_eq!(o.film.nonfinite, 0);
    o.film.image()
}

fn settings(seed: u64, stochastic: bool, photons: u64) -> ProgressiveSettings {
    ProgressiveSettings {
        photons_per_pass: photons,
        ..ProgressiveSettings::new(seed, stochastic)
    }
}

/// PPM with one eye-ray tree per pixel (for tests of a tree's structure).
fn one_tree(settings: ProgressiveSettings) -> ProgressiveSettings {
    ProgressiveSettings {
        eye_rays: 1,
        ..settings
    }
}

fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(f)
}

#[test]
fn progressive_update_follows_the_ppm_formulas() {
    let tau = DVec3::new(1.0, 2.0, 3.0);
    let tau_m = DVec3::new(0.5, 0.25, 0.0);
    // N = 10, M = 5, alpha = 0.7: N' = 13.5, R' = R sqrt(13.5 / 15), tau' = (tau + tau_M) 0.9.
    let (n, r, t) = progressive_update(10.0, 2.0, tau, 5, tau_m, 0.7);
    assert!((n - 13.5).abs() < 1e-12);
    assert!((r as f64 - 2.0 * (0.9f64).sqrt()).abs() < 1e-6);
    assert!((t - (tau + tau_m) * 0.9).length() < 1e-12);
    // The first pass: N = 0 keeps alpha M photons and shrinks the radius by sqrt(alpha).
    let (n, r, t) = progressive_update(0.0, 1.0, DVec3::ZERO, 4, tau_m, 0.5);
    assert!((n - 2.0).abs() < 1e-12);
    assert!((r as f64 - 0.5f64.sqrt()).abs() < 1e-6);
    assert!((t - tau_m * 0.5).length() < 1e-12);
    // No photons found: nothing changes.
    assert_eq!(
        progressive_update(3.0, 0.25, tau, 0, DVec3::ZERO, 0.7),
        (3.0, 0.25, tau)
    );
    // alpha = 1 keeps everything: the radius stays and the flux just adds.
    let (n, r, t) = progressive_update(7.0, 0.3, tau, 3, tau_m, 1.0);
    assert_eq!((n, r), (10.0, 0.3));
    assert!((t - (tau + tau_m)).length() < 1e-12);
}

/// Mean |L - 2| over the furnace's pixels and the image mean.
fn furnace_error(image: &Image) -> (f64, f64) {
    let n = image.pixels.len() as f64;
    let dev = image
        .pixels
        .iter()
        .map(|p| (p[1] as f64 - 2.0).abs())
        .sum::<f64>()
        / n;
    let mean = image.pixels.iter().map(|p| p[1] as f64).sum::<f64>() / n;
    (dev, mean)
}

#[test]
fn ppm_and_sppm_converge_to_two_in_the_furnace() {
    let data = Arc::new(SceneData::new(load_small("furnace.ron", 32)));
    for stochastic in [false, true] {
        let few = furnace_error(&render(data.clone(), settings(3, stochastic, 20_000), 2));
        let many = furnace_error(&render(data.clone(), settings(3, stochastic, 20_000), 32));
        let name = if stochastic { "sppm" } else { "ppm" };
        // The per-pixel error shrinks with passes (noise and bias both fall) ...
        assert!(
            many.0 < 0.6 * few.0,
            "{name}: mean |L - 2| {} after 32 passes, {} after 2",
            many.0,
            few.0
        );
        // ... and the image mean is 2: the estimate's bias in a uniform radiance field is
        // zero (every disc sees the same density), so only noise remains.
        assert!((many.1 - 2.0).abs() < 0.01, "{name}: mean {}", many.1);
    }
}

#[test]
fn sppm_error_against_path_tracing_falls_with_passes_on_the_cornell_box() {
    let data = Arc::new(SceneData::new(load_small("cornell_box.ron", 48)));
    let reference = render_pt(load_small("cornell_box.ron", 48), 1024, 99, u32::MAX)
        .film
        .image();
    let relmse = |passes| {
        let image = render(data.clone(), settings(5, true, 40_000), passes);
        stagelight::metrics::compare(&image, &reference)
            .expect("same size, finite")
            .relmse
    };
    let (e2, e8, e32) = (relmse(2), relmse(8), relmse(32));
    assert!(
        e8 < 0.8 * e2 && e32 < 0.8 * e8,
        "relMSE after 2, 8, 32 passes: {e2}, {e8}, {e32}"
    );
}

#[test]
fn ppm_and_sppm_are_bit_identical_for_one_and_three_threads() {
    let data = Arc::new(SceneData::new(load_small("torus_glass.ron", 32)));
    for stochastic in [false, true] {
        let image = |threads| {
            on_threads(threads, || {
                render(data.clone(), settings(8, stochastic, 30_000), 3)
            })
        };
        let (a, b) = (image(1), image(3));
        assert!(
            a.pixels == b.pixels,
            "stochastic {stochastic}: 1 and 3 threads differ"
        );
    }
}

#[test]
fn ppm_keeps_its_visible_points_and_sppm_renews_them() {
    let data = Arc::new(SceneData::new(load_small("cornell_box.ron", 16)));
    for stochastic in [false, true] {
        let one = sppm::run_passes(data.clone(), one_tree(settings(1, stochastic, 5_000)), 1);
        let two = sppm::run_passes(data.clone(), one_tree(settings(1, stochastic, 5_000)), 2);
        let same = one.camera_walk.visible.p == two.camera_walk.visible.p;
        assert_eq!(same, !stochastic, "stochastic = {stochastic}");
        // Memory does not grow with passes: one visible point and estimate per pixel (the
        // Cornell box has no glass, so PPM's ray tree has at most one hit point per pixel,
        // in pixel order: none where the eye ray leaves the box).
        let walk = &two.camera_walk;
        let points = walk.points;
        assert_eq!(points, one.camera_walk.points);
        assert_eq!(
            two.estimates.capacity(),
            if stochastic { 16 * 16 } else { points }
        );
        if stochastic {
            assert_eq!(points, 16 * 16);
            assert!((0..points).all(|i| walk.visible.pixel[i] as usize == i));
        } else {
            assert!(points > 200 && points <= 16 * 16, "{points} hit points");
            assert!((1..points).all(|i| walk.visible.pixel[i] > walk.visible.pixel[i - 1]));
        }
        assert!((0..points).all(|i| walk.visible.branch[i] == 0));
    }
}

/// A glass slab 0.2 thick across the view, a wall behind it and one behind the camera.
const GLASS_SLAB: &str = r#"Scene(
    camera: (position: (0, 0, 0), look_at: (0, 0, -1), fov: 20, width: 9, height: 9),
    materials: {
        "front": Diffuse(reflectance: (0.5, 0.5, 0.5)),
        "back": Diffuse(reflectance: (0.5, 0.5, 0.5)),
        "glass": Dielectric(ior: 1.5),
        "black": Diffuse(reflectance: (0, 0, 0)),
    },
    objects: [
        (shape: Box(min: (-5, -5, -3.2), max: (5, 5, -3)), material: "glass"),
        (shape: Quad((-20, -20, -6), (20, -20, -6), (20, 20, -6), (-20, 20, -6)), material: "back"),
        (shape: Quad((-20, -20, 1), (-20, 20, 1), (20, 20, 1), (20, -20, 1)), material: "front"),
        (name: Some("light"), material: "black", emission: Some((1, 1, 1)),
         shape: Quad((-1, 4, -4), (1, 4, -4), (1, 4, -5), (-1, 4, -5))),
    ],
)"#;

/// PPM's eye pass is a ray tree (Hachisuka et al. 2008): the pixel looking straight at a
/// glass slab owns a hit point on the wall behind the camera (reflected at the slab, weight
/// F = 0.04 at normal incidence) and one on the wall behind the slab (refracted twice, weight
/// (1 - F)^2 = 0.9216; the 1/eta^2 going in and eta^2 coming out cancel), and one reflected
/// inside the slab once; branches reflected more often fall below the weight floor. SPPM
/// samples one branch per pass.
#[test]
fn a_ppm_pixel_looking_at_glass_owns_hit_points_of_both_branches() {
    let scene = stagelight::scene::load_from_str(std::path::Path::new("slab.ron"), GLASS_SLAB)
        .expect("the slab loads");
    let data = Arc::new(SceneData::new(scene));
    let materials = |s: &sppm::ProgressiveState, pixel: u32| {
        let walk = &s.camera_walk;
        (0..walk.points)
            .filter(|&i| walk.visible.pixel[i] == pixel)
            .map(|i| {
                let tri = walk.visible.triangle[i] as usize;
                let material = s.data.scene.triangles.material[tri];
                (material, walk.visible.beta[i].y)
            })
            .collect::<Vec<_>>()
    };
    let ppm = sppm::run_passes(data.clone(), one_tree(settings(1, false, 1_000)), 1);
    let centre = 4 * 9 + 4;
    let points = materials(&ppm, centre);
    let front = ppm.data.scene.triangles.material[data
        .accel
        .closest_hit(glam::Vec3::ZERO, glam::Vec3::Z, f32::INFINITY)
        .expect("the wall behind the camera")
        .triangle as usize];
    let heaviest = |on_front: bool| {
        points
            .iter()
            .filter(|(m, _)| (*m == front) == on_front)
            .map(|p| p.1)
            .fold(0.0f32, f32::max)
    };
    // The centre pixel's rays meet the slab within 1 degree of its normal: F within 1e-4 of
    // 0.04.
    let (reflected, refracted) = (heaviest(true), heaviest(false));
    assert!(
        (reflected - 0.04).abs() < 2e-4,
        "reflected branch weighs {reflected}: {points:?}"
    );
    assert!(
        (refracted - 0.9216).abs() < 5e-4,
        "refracted branch weighs {refracted}: {points:?}"
    );
    // Reflected at the slab's far face and out through its near one: (1 - F)^2 F.
    assert!(
        points
            .iter()
            .any(|&(m, w)| m == front && (w - 0.9216 * 0.04).abs() < 5e-4),
        "{points:?}"
    );
    // Weights sum to what Fresnel leaves: light that bounces within the slab comes out on
    // one side or the other, up to the branches cut below the weight floor.
    let total: f32 = points.iter().map(|p| p.1).sum();
    assert!(
        (total - 1.0).abs() < 2e-3,
        "total weight {total}: {points:?}"
    );
    // SPPM: one hit point per pixel per pass.
    let sppm = sppm::run_passes(data, settings(1, true, 1_000), 1);
    assert_eq!(materials(&sppm, centre).len(), 1);
}

/// Mean over pixels and channels of (x - a)(x - b) / (w^2 + 0.01): with a and b independent
/// unbiased estimates of the truth t, and weights w independent of them, its expectation is
/// the mean of (x - t)^2 / (w^2 + 0.01), x's relative error against the truth itself, the
/// references' own noise taken out. (Weights made from a and b would not do: where their noise
/// is large, (a + b)^2 / 4 in the denominator correlates with the numerator.)
fn error_against_truth(x: &Image, a: &Image, b: &Image, w: &Image) -> f64 {
    let mut sum = 0.0;
    for (((x, a), b), w) in x.pixels.iter().zip(&a.pixels).zip(&b.pixels).zip(&w.pixels) {
        for c in 0..3 {
            let (x, a, b, w) = (x[c] as f64, a[c] as f64, b[c] as f64, w[c] as f64);
            sum += (x - a) * (x - b) / (w * w + 0.01);
        }
    }
    sum / (3 * x.pixels.len()) as f64
}

/// PPM's error on torus_glass keeps falling with passes (a 32 x 32 copy, 1000 photons a
/// pass, 16 eye rays a pixel), measured against path tracing's two independent halves (whose
/// noise the measure takes out), weighted by the 1000-pass image: 5.9e-3 after 75 passes,
/// 2.5e-3 after 1000 when measured. With one eye ray per pixel its fixed hit points never
/// average the pixel's area: 5.2e-2 and 4.5e-2, which fails the test.
#[test]
fn ppm_error_on_the_torus_keeps_falling_from_75_to_1000_passes() {
    let scene = || load_small("torus_glass.ron", 32);
    let data = Arc::new(SceneData::new(scene()));
    let a = render_pt(scene(), 4096, 21, u32::MAX).film.image();
    let b = render_pt(scene(), 4096, 22, u32::MAX).film.image();
    let ppm = |passes| render(data.clone(), settings(9, false, 1_000), passes);
    let (i75, i1000) = (ppm(75), ppm(1000));
    let (e75, e1000) = (
        error_against_truth(&i75, &a, &b, &i1000),
        error_against_truth(&i1000, &a, &b, &i1000),
    );
    assert!(
        e1000 < 0.75 * e75,
        "error against the truth after 75 passes {e75:e}, after 1000 {e1000:e}"
    );
}

/// PPM shoots `eye_rays` trees per pixel (Hachisuka et al. average the pixel with several
/// eye rays: its hit points are fixed, so only they can): on the diffuse Cornell box each tree
/// has one hit point, weighing 1 / trees, and a pixel's 16 eye rays are a stratified net, one
/// in each cell of a 4 x 4 grid over the pixel.
#[test]
fn ppm_pixels_own_eye_ray_trees_stratified_over_them() {
    let size = 12;
    let data = Arc::new(SceneData::new(load_small("cornell_box.ron", size)));
    let ppm = sppm::run_passes(data.clone(), settings(1, false, 1_000), 1);
    let walk = &ppm.camera_walk;
    let cam = data.scene.camera.frustum();
    let mut cells = vec![Vec::new(); (size * size) as usize];
    for i in 0..walk.points {
        assert!((walk.visible.beta[i] - glam::Vec3::splat(1.0 / 16.0)).length() < 1e-7);
        let raster = cam
            .raster_of(walk.visible.p[i] - cam.position)
            .expect("a hit point in view");
        let pixel = walk.visible.pixel[i] as usize;
        let at = raster
            - glam::Vec2::new(
                (pixel % size as usize) as f32,
                (pixel / size as usize) as f32,
            );
        // A hair outside the pixel for points rebuilt from their hit (rounding).
        let cell = |v: f32| (v.clamp(0.0, 0.9999) * 4.0) as usize;
        cells[pixel].push(cell(at.y) * 4 + cell(at.x));
    }
    let full = cells.iter().filter(|c| c.len() == 16).count();
    assert!(full >= 80, "{full} pixels with 16 hit points");
    for c in cells.iter_mut().filter(|c| c.len() == 16) {
        c.sort();
        assert_eq!(*c, (0..16).collect::<Vec<_>>());
    }
    assert!(cells.iter().all(|c| c.len() <= 16));
}

fn render_pm(data: Arc<SceneData>, settings: pm::PmSettings, passes: u64) -> RenderOutcome {
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    let o = pm::render(data, settings, Budget::SamplesPerPixel(passes), &control);
    assert_eq!(o.film.nonfinite, 0);
    o
}

/// PM in the furnace: the k-nearest estimate leaves out the k-th photon, which makes it exact
/// in expectation in a uniform photon density, so the only bias left is that of the facets'
/// curvature within a radius: stated here as 0.25% of the mean, with or without final
/// gathering. (Counting the k-th photon too would put the mean 0.5 / (k - 1) = 1% high.)
#[test]
fn pm_in_the_furnace_is_within_its_stated_bias() {
    let data = Arc::new(SceneData::new(load_small("furnace.ron", 32)));
    for final_gather in [true, false] {
        let settings = pm::PmSettings {
            photons: 100_000,
            final_gather,
            ..pm::PmSettings::new(4)
        };
        let image = render_pm(data.clone(), settings, 16).film.image();
        let (_, mean) = furnace_error(&image);
        assert!(
            (mean - 2.0).abs() < 0.005,
            "final gather {final_gather}: mean {mean}"
        );
    }
}

#[test]
fn pm_has_a_caustic_map_only_where_there_are_specular_surfaces() {
    for (scene, caustics) in [("cornell_box.ron", false), ("torus_glass.ron", true)] {
        let data = Arc::new(SceneData::new(load_small(scene, 8)));
        let settings = pm::PmSettings {
            photons: 10_000,
            ..pm::PmSettings::new(1)
        };
        let o = render_pm(data, settings, 1);
        assert_eq!(o.systems.contains(&"gather_caustics"), caustics, "{scene}");
    }
}

#[test]
fn pm_is_bit_identical_for_one_and_three_threads() {
    let data = Arc::new(SceneData::new(load_small("torus_glass.ron", 32)));
    let image = |threads| {
        let settings = pm::PmSettings {
            photons: 30_000,
            ..pm::PmSettings::new(2)
        };
        on_threads(threads, || {
            render_pm(data.clone(), settings, 2).film.image()
        })
    };
    assert!(image(1).pixels == image(3).pixels, "1 and 3 threads differ");
}

/// A closed box split in two by a zero-thickness two-sided wall, the light in one half and the
/// camera in the other (see the scene's comment for its black strips).
const SPLIT_BOX: &str = r#"// A closed box (0, 0, 0)-(2, 1, 1) split at x = 1 by a zero-thickness two-sided wall: the camera
// in the dark half, a light in the other facing away from the wall. On the lit side a black
// strip 0.1 wide runs along the wall on the floor, ceiling and side walls: photons landing
// there end, so none starts a ray a rounding error away from the wall (where the
// accelerator's self-intersection margin lets it slip through), yet they are stored within a
// gather radius of the dark half's surfaces across the wall.
Scene(
    camera: (position: (0.1, 0.5, 0.5), look_at: (1.0, 0.5, 0.5), fov: 90, width: 24, height: 24),
    materials: {
        "white": Diffuse(reflectance: (0.8, 0.8, 0.8)),
        "black": Diffuse(reflectance: (0, 0, 0)),
    },
    objects: [
        // The wall.
        (shape: Quad((1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)), material: "white"),
        // The dark half: x in [0, 1].
        (shape: Quad((0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)), material: "white"),
        (shape: Quad((0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)), material: "white"),
        (shape: Quad((0, 1, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1)), material: "white"),
        (shape: Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), material: "white"),
        (shape: Quad((0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)), material: "white"),
        // The lit half: x in [1, 2], black strips x in [1, 1.1].
        (shape: Quad((1, 0, 0), (1.1, 0, 0), (1.1, 0, 1), (1, 0, 1)), material: "black"),
        (shape: Quad((1, 1, 0), (1.1, 1, 0), (1.1, 1, 1), (1, 1, 1)), material: "black"),
        (shape: Quad((1, 0, 0), (1.1, 0, 0), (1.1, 1, 0), (1, 1, 0)), material: "black"),
        (shape: Quad((1, 0, 1), (1.1, 0, 1), (1.1, 1, 1), (1, 1, 1)), material: "black"),
        (shape: Quad((1.1, 0, 0), (2, 0, 0), (2, 0, 1), (1.1, 0, 1)), material: "white"),
        (shape: Quad((1.1, 1, 0), (2, 1, 0), (2, 1, 1), (1.1, 1, 1)), material: "white"),
        (shape: Quad((1.1, 0, 0), (2, 0, 0), (2, 1, 0), (1.1, 1, 0)), material: "white"),
        (shape: Quad((1.1, 0, 1), (2, 0, 1), (2, 1, 1), (1.1, 1, 1)), material: "white"),
        (shape: Quad((2, 0, 0), (2, 1, 0), (2, 1, 1), (2, 0, 1)), material: "white"),
        // The light, facing +x (away from the wall).
        (name: Some("light"), material: "black", emission: Some((10, 10, 10)),
         shape: Quad((1.9, 0.3, 0.3), (1.9, 0.7, 0.3), (1.9, 0.7, 0.7), (1.9, 0.3, 0.7))),
    ],
)
"#;

fn split_box(camera_in_the_lit_half: bool) -> Arc<SceneData> {
    let text = if camera_in_the_lit_half {
        SPLIT_BOX.replace(
            "position: (0.1, 0.5, 0.5), look_at: (1.0, 0.5, 0.5)",
            "position: (1.2, 0.5, 0.5), look_at: (2.0, 0.5, 0.5)",
        )
    } else {
        SPLIT_BOX.to_string()
    };
    let scene = stagelight::scene::load_from_str(std::path::Path::new("split_box.ron"), &text)
        .expect("the split box loads");
    Arc::new(SceneData::new(scene))
}

fn image_mean(image: &Image) -> f64 {
    image.pixels.iter().map(|p| p[1] as f64).sum::<f64>() / image.pixels.len() as f64
}

/// No light through walls: the photon mappers' image of the dark half is no brighter than
/// path tracing's (an independent estimate of what rounding lets through), where gathering
/// across the wall lit a band as wide as the radius along it (PM's mean 1.1e-3, PPM's 4.1e-4,
/// SPPM's 2.1e-4 at 256 passes, against PT's 0). The same integrators do see the lit half.
#[test]
fn photon_mappers_gather_no_light_through_a_thin_wall() {
    let dark = split_box(false);
    let pt = image_mean(
        &render_pt(
            stagelight::scene::load_from_str(std::path::Path::new("split_box.ron"), SPLIT_BOX)
                .unwrap(),
            4096,
            3,
            u32::MAX,
        )
        .film
        .image(),
    );
    for lit in [false, true] {
        let data = if lit { split_box(true) } else { dark.clone() };
        let mut means = Vec::new();
        for stochastic in [false, true] {
            // One eye ray per pixel: walls, not antialiasing, are tested here.
            let image = render(data.clone(), one_tree(settings(2, stochastic, 50_000)), 16);
            means.push((if stochastic { "sppm" } else { "ppm" }, image_mean(&image)));
        }
        let pm_settings = pm::PmSettings {
            photons: 100_000,
            ..pm::PmSettings::new(2)
        };
        let image = render_pm(data.clone(), pm_settings, 8).film.image();
        means.push(("pm", image_mean(&image)));
        for (name, mean) in means {
            if lit {
                assert!(mean > 0.02, "{name}: the lit half's mean is {mean}");
            } else {
                assert!(
                    mean <= pt,
                    "{name}: the dark half's mean is {mean:e}, PT's {pt:e}"
                );
            }
        }
    }
}

/// docs/mlt/mirror_box.ron at 32 x 24: a Cornell box seen from a high corner, its back wall a
/// GGX near-mirror (alpha 0.02), its short block a rough GGX conductor (alpha 0.3), its tall
/// block glass.
fn mirror_box() -> stagelight::scene::PreparedScene {
    let text = include_str!("../../docs/mlt/mirror_box.ron")
        .replace("width: 160, height: 120,", "width: 32, height: 24,");
    assert!(text.contains("width: 32, height: 24,"));
    stagelight::scene::load_from_str(std::path::Path::new("mirror_box.ron"), &text)
        .expect("the mirror box loads")
}

/// The conductor of GGX `alpha` on triangle `tri`.
fn is_conductor(data: &SceneData, tri: u32, alpha: f32) -> bool {
    let scene = &data.scene;
    let material = scene.materials[scene.triangles.material[tri as usize] as usize];
    matches!(material, stagelight::bsdf::Material::Conductor(c) if c.alpha_u == alpha)
}

/// The pixels whose centre's camera ray meets the conductor of GGX `alpha` first.
fn pixels_on(data: &SceneData, alpha: f32) -> Vec<usize> {
    let scene = &data.scene;
    let cam = scene.camera.frustum();
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    (0..w * h)
        .filter(|&p| {
            let raster = glam::Vec2::new((p % w) as f32 + 0.5, (p / w) as f32 + 0.5);
            data.accel
                .closest_hit(cam.position, cam.direction(raster), f32::INFINITY)
                .is_some_and(|hit| is_conductor(data, hit.triangle, alpha))
        })
        .collect()
}

/// relMSE over some pixels.
fn relmse_on(image: &Image, reference: &Image, pixels: &[usize]) -> f64 {
    let mut sum = 0.0;
    for &p in pixels {
        for c in 0..3 {
            let (x, r) = (image.pixels[p][c] as f64, reference.pixels[p][c] as f64);
            sum += (x - r) * (x - r) / (r * r + 0.01);
        }
    }
    sum / (3 * pixels.len()) as f64
}

/// The photon mappers' camera chains follow a near-mirror (GGX alpha 0.02) as a path tracer
/// does, sampling light there under MIS, and gather on a rough conductor (alpha 0.3): on the
/// mirror box's mirror SPPM's error is then within 2x of a path tracer's at equal samples.
/// Negative control (FOLLOW_ALPHA = 0, a visible point on every conductor): the structural
/// assertions fail (224 visible points on the mirror); the error comparison alone still
/// passed at this size and 16 samples, so it guards against a broken glossy estimate, not
/// against the old rule. The old rule's error was measured at full size and equal time
/// (docs/photons/README.md: SPPM 9.0e-2 on the mirror against PT's 6.7e-3; 2.4e-3 after).
#[test]
fn photon_mappers_follow_a_near_mirror_and_gather_on_a_rough_conductor() {
    let data = Arc::new(SceneData::new(mirror_box()));
    let (mirror, rough) = (pixels_on(&data, 0.02), pixels_on(&data, 0.3));
    assert!(
        mirror.len() > 150 && rough.len() > 30,
        "{} {}",
        mirror.len(),
        rough.len()
    );
    let on = |walk: &stagelight::integrators::camera_walk::CameraWalk, alpha: f32| {
        (0..walk.points)
            .filter(|&i| {
                let tri = walk.visible.triangle[i];
                tri != stagelight::components::NO_VISIBLE_POINT && is_conductor(&data, tri, alpha)
            })
            .count()
    };
    for stochastic in [true, false] {
        let pass = sppm::run_passes(data.clone(), one_tree(settings(4, stochastic, 10_000)), 1);
        let walk = &pass.camera_walk;
        assert_eq!(on(walk, 0.02), 0, "a visible point on the mirror");
        assert!(walk.glossy_points >= mirror.len(), "{}", walk.glossy_points);
        assert!(on(walk, 0.3) * 10 >= rough.len() * 9, "{}", on(walk, 0.3));
    }

    let reference = render_pt(mirror_box(), 4096, 77, u32::MAX).film.image();
    let passes = 16;
    let pt = render_pt(mirror_box(), passes, 5, u32::MAX).film.image();
    let sppm = render(data.clone(), settings(5, true, 20_000), passes);
    let (pt_err, sppm_err) = (
        relmse_on(&pt, &reference, &mirror),
        relmse_on(&sppm, &reference, &mirror),
    );
    assert!(
        sppm_err < 2.0 * pt_err,
        "relMSE on the mirror at {passes} samples: sppm {sppm_err:e}, pt {pt_err:e}"
    );
}

/// The furnace (a closed sphere, diffuse 0.5, emitting 1 inward) with a glass ball (radius
/// 0.35, ior 1.5, flat facets) in front of the camera: the chains that see the wall through
/// the ball reach it two bounces deep, and photons cross the ball too.
const GLASS_BALL_FURNACE: &str = r#"Scene(
    camera: (position: (0, 0, 0), look_at: (0, 0, 1), up: (0, 1, 0), fov: 90, width: 16, height: 16),
    materials: {
        "grey": Diffuse(reflectance: (0.5, 0.5, 0.5)),
        "glass": Dielectric(ior: 1.5),
    },
    objects: [
        (name: Some("sphere"), material: "grey", emission: Some((1, 1, 1)),
         shape: Icosphere(level: 3, smooth: false), flip_normals: true),
        (name: Some("ball"), material: "glass", shape: Icosphere(level: 3, smooth: false),
         transform: [Scale(0.35), Translate((0, 0, 0.55))]),
    ],
)"#;

/// The image mean of each photon mapper (PM with and without final gathering, PPM, SPPM)
/// at `max_depth`.
fn photon_mapper_means(
    data: &Arc<SceneData>,
    max_depth: u32,
    seed: u64,
) -> Vec<(&'static str, f64)> {
    use stagelight::integrators::{IntegratorKind, RenderSettings};
    let mut means = Vec::new();
    for (name, kind, final_gather) in [
        ("pm", "pm", true),
        ("pm without final gathering", "pm", false),
        ("ppm", "ppm", true),
        ("sppm", "sppm", true),
    ] {
        let mut settings = RenderSettings {
            seed,
            max_depth,
            ..RenderSettings::default()
        };
        settings.photons.photons = 100_000;
        settings.photons.photons_per_pass = 10_000;
        settings.photons.eye_rays = 4;
        settings.photons.final_gather = final_gather;
        let image = render_with(IntegratorKind::named(kind), data.clone(), &settings, 16);
        means.push((name, image_mean(&image)));
    }
    means
}

/// `--max-depth` bounds the whole path, as PT's does: a visible point d bounces from the camera
/// gathers only photons stored after at most max_depth - d - 1 bounces (the photon's landing
/// is the path's bounce at the point), a final-gather point counts on from its visible
/// point's depth, and a chain at the cap keeps no gather point (no light is sampled there).
///
/// In the furnace (every pixel Le sum of rho^b over b <= max_depth bounces) max_depth 0 is
/// exactly 1, the emission seen. Max_depth 2 is 1.75; counted per path, each mapper is within
/// 0.12% of it but SPPM, 0.45% under (its shrinking radius at 16 passes), each spread over
/// seeds 1 to 3 by at most 0.11% (standard deviation): the tolerance, 1.5%, is past that bias
/// by 10 deviations.
///
/// Through the glass ball (the wall behind it two bounces deep, so at max_depth 3 it gathers
/// only photons stored at their first surface, which PPM and SPPM do not store), against PT
/// at 256 samples (spread over seeds 0.05%): over seeds 1 to 3 every mean is within 0.8% of
/// PT's, with a spread of at most 0.76%; the tolerance, 4%, is 5 such deviations.
///
/// Counting depth per subpath, as before, each mapper took in a bounce or two more: at
/// max_depth 0 PM gave 1.750 and the others 1.500 (direct light); at 2 PM 1.939 (+10.8%), PM
/// without final gathering 1.880, PPM 1.871, SPPM 1.863 (+6.5%); through the ball at 3, 21%
/// (PPM) to 28% (PM) over PT.
#[test]
fn photon_mappers_keep_the_whole_path_within_the_maximum_depth() {
    let furnace = Arc::new(SceneData::new(load_small("furnace.ron", 16)));
    for (max_depth, expected, tolerance) in [(0, 1.0, 1e-6), (2, 1.75, 0.015)] {
        for (name, mean) in photon_mapper_means(&furnace, max_depth, 1) {
            assert!(
                (mean / expected - 1.0).abs() < tolerance,
                "{name}: the furnace's mean at max_depth {max_depth} is {mean}, not {expected}"
            );
        }
    }
    let ball = || {
        stagelight::scene::load_from_str(std::path::Path::new("ball.ron"), GLASS_BALL_FURNACE)
            .expect("the glass ball furnace loads")
    };
    let pt = image_mean(&render_pt(ball(), 256, 1, 3).film.image());
    for (name, mean) in photon_mapper_means(&Arc::new(SceneData::new(ball())), 3, 1) {
        assert!(
            (mean / pt - 1.0).abs() < 0.04,
            "{name}: the glass ball's mean at max_depth 3 is {mean}, PT's {pt}"
        );
    }
}
