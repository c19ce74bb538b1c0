//! The film's reconstruction filters, crop windows, variance image and the orthographic
//! sensor, against Mitsuba 3.9.1 where it defines them: the gaussian filter's weights, renders
//! of small XML scenes against committed Mitsuba renders (tests/scenes/mitsuba/*_mitsuba.exr,
//! 2 x 16384 spp by ../shared/mitsuba/render_xml.py), the film's independence of the thread
//! count, a crop against the same pixels of the whole film, and the variance image against the
//! spread of independent renders.

use stagelight::film::{Gaussian, Image, PixelFilter};
use stagelight::integrators::pt;
use stagelight::integrators::{Budget, Control, RenderOutcome};
use stagelight::scene::{self, Limits, PreparedScene, SceneData};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

fn mitsuba_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/mitsuba")
}

/// A scene of tests/scenes/mitsuba, its text edited by `edit`.
fn load_xml(name: &str, edit: impl Fn(String) -> String) -> PreparedScene {
    let path = mitsuba_dir().join(name);
    let text = edit(std::fs::read_to_string(&path).unwrap());
    scene::load_mitsuba_from_str(&path, &text, &[], &Limits::of_this_machine())
        .unwrap_or_else(|e| panic!("{e}"))
        .0
}

/// The film of one PT render with moments, on `threads` threads.
fn render(scene: &PreparedScene, spp: u64, seed: u64, threads: usize) -> RenderOutcome {
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    let settings = pt::PtSettings {
        moments: true,
        ..pt::PtSettings::new(seed, 2)
    };
    let data = Arc::new(SceneData::new(scene.clone()));
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(|| pt::render(data, settings, Budget::SamplesPerPixel(spp), &control))
}

#[test]
fn gaussian_weights_are_mitsubas() {
    // Mitsuba 3.9.1, scalar_rgb: mi.load_dict({'type': 'gaussian', 'stddev': s}).eval(x).
    let mitsuba: [(f32, &[(f32, f32)]); 2] = [
        (
            0.5,
            &[
                (0.0, 0.999_247_13),
                (0.25, 0.882_166_74),
                (0.5, 0.606_423),
                (0.75, 0.324_242_56),
                (1.0, 0.134_960_49),
                (1.5, 0.010_758_21),
                (1.9, 0.000_387_881_85),
                (1.99, 2.973_749_5e-5),
                (2.0, 1.907_348_6e-6),
                (2.5, 0.0),
            ],
        ),
        (
            0.25,
            &[
                (0.0, 0.999_247_13),
                (0.25, 0.606_423),
                (0.5, 0.134_960_49),
                (0.75, 0.010_758_21),
                (1.0, 1.907_348_6e-6),
                (1.5, 0.0),
            ],
        ),
    ];
    for (stddev, values) in mitsuba {
        let g = Gaussian::new(stddev).unwrap();
        assert_eq!(g.radius, 4.0 * stddev);
        for &(x, expected) in values {
            for x in [x, -x] {
                let w = g.eval(x);
                assert!(
                    (w - expected).abs() <= 2e-6,
                    "stddev {stddev}, x {x}: {w} against Mitsuba's {expected}"
                );
            }
        }
    }
    assert!(Gaussian::new(-0.5).is_none() && Gaussian::new(0.0).is_none());
    // The default of a film without an rfilter.
    assert_eq!(
        PixelFilter::mitsuba_default(),
        PixelFilter::Gaussian(Gaussian::new(0.5).unwrap())
    );
}

/// Mitsuba's render test on one image (z per pixel channel with our own per-sample variance
/// scaled to the mean's, Sidak-corrected 0.01 over the pixels, at least 99.75% passing); the
/// fraction that passes. The gaussian's weighted mean has the variance of about spp / 1.3
/// independent samples (sum w^2 / (sum w)^2 for stddev 0.5): taken as spp / 1.3 throughout.
fn pass_fraction(ours: &Image, variance: &Image, spp: u64, reference: &Image) -> f64 {
    assert_eq!(
        (ours.width, ours.height),
        (reference.width, reference.height)
    );
    let pixels = ours.pixels.len();
    let alpha = 1.0 - (1.0f64 - 0.01).powf(1.0 / pixels as f64);
    let mut passed = 0;
    for ((o, v), r) in ours
        .pixels
        .iter()
        .zip(&variance.pixels)
        .zip(&reference.pixels)
    {
        for c in 0..3 {
            // The reference's own noise: 2 x 16384 samples, 1/128 of ours at 256.
            let var = (v[c] as f64).max(1e-6) * 1.3 / spp as f64 * (1.0 + spp as f64 / 32768.0);
            let z = (o[c] as f64 - r[c] as f64).abs() / var.sqrt();
            if libm_erfc(z / std::f64::consts::SQRT_2) > alpha {
                passed += 1;
            }
        }
    }
    passed as f64 / (3 * pixels) as f64
}

/// erfc for the test's p-values (Abramowitz and Stegun 7.1.26, to 1.5e-7).
fn libm_erfc(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    poly * (-x * x).exp()
}

/// `gaussian_filter.xml` has no rfilter: Mitsuba's default gaussian. Rendered at 256 spp, it
/// passes Mitsuba's own render test against Mitsuba's image; the same file with a box filter
/// fails it (the light's edges are one-pixel steps the gaussian blurs), so the test sees the
/// filter.
#[test]
fn default_gaussian_agrees_with_mitsuba() {
    let reference = Image::read_exr(&mitsuba_dir().join("gaussian_filter_mitsuba.exr")).unwrap();
    let spp = 256;
    let gaussian = load_xml("gaussian_filter.xml", |t| t);
    assert!(matches!(gaussian.camera.filter, PixelFilter::Gaussian(_)));
    let outcome = render(&gaussian, spp, 1, 2);
    let variance = outcome.film.variance_image().unwrap();
    let frac = pass_fraction(&outcome.film.image(), &variance, spp, &reference);
    eprintln!("gaussian_filter.xml, gaussian: {frac:.4} of the pixel channels pass");
    assert!(
        frac >= 0.9975,
        "gaussian: {frac} of the pixel channels pass"
    );

    let boxed = load_xml("gaussian_filter.xml", |t| {
        t.replace(
            "<film type=\"hdrfilm\">",
            "<film type=\"hdrfilm\"><rfilter type=\"box\"/>",
        )
    });
    assert_eq!(boxed.camera.filter, PixelFilter::Box);
    let outcome = render(&boxed, spp, 1, 2);
    let variance = outcome.film.variance_image().unwrap();
    let frac = pass_fraction(&outcome.film.image(), &variance, spp, &reference);
    eprintln!("gaussian_filter.xml, box: {frac:.4} pass");
    assert!(
        frac < 0.98,
        "box: {frac} of the pixel channels pass the gaussian's test"
    );
}

/// An orthographic sensor (to_world scaled, near_clip 1) with the default gaussian, against
/// Mitsuba's render of the same file.
#[test]
fn orthographic_agrees_with_mitsuba() {
    let reference = Image::read_exr(&mitsuba_dir().join("orthographic_mitsuba.exr")).unwrap();
    let spp = 256;
    let scene = load_xml("orthographic.xml", |t| t);
    assert!(!scene.camera.is_pinhole());
    let outcome = render(&scene, spp, 3, 2);
    let variance = outcome.film.variance_image().unwrap();
    let frac = pass_fraction(&outcome.film.image(), &variance, spp, &reference);
    eprintln!("orthographic.xml: {frac:.4} of the pixel channels pass");
    assert!(frac >= 0.9975, "{frac} of the pixel channels pass");
    // The same view through a pinhole is another image: the test can fail.
    let pinhole = load_xml("orthographic.xml", |t| {
        t.replace("type=\"orthographic\"", "type=\"perspective\"")
            .replace(
                "<float name=\"near_clip\" value=\"1\"/>",
                "<float name=\"fov\" value=\"30\"/>",
            )
            .replace("<scale x=\"1.5\" y=\"1.5\"/>", "")
    });
    let outcome = render(&pinhole, spp, 3, 2);
    let variance = outcome.film.variance_image().unwrap();
    let frac = pass_fraction(&outcome.film.image(), &variance, spp, &reference);
    eprintln!("orthographic.xml as a pinhole: {frac:.4} pass");
    assert!(frac < 0.9, "a pinhole: {frac} pass");
}

/// The gaussian film's sums are exact and every sample reaches the same pixels, so the image
/// and the variance are the same bits on 1 and 3 threads (the bands of rows each thread takes
/// differ).
#[test]
fn gaussian_film_does_not_depend_on_the_thread_count() {
    let scene = load_xml("gaussian_filter.xml", |t| t);
    let one = render(&scene, 8, 7, 1);
    let three = render(&scene, 8, 7, 3);
    assert_eq!(one.film.image(), three.film.image());
    assert_eq!(one.film.variance_image(), three.film.variance_image());
    assert!(one.film.image().channel_means().x > 0.1);
}

/// A crop window renders the film's own samples in its pixels: under the box filter its image
/// is the whole film's there, bit for bit; under the gaussian so is every pixel at least 2
/// pixels (the filter's radius) from the crop's inner edges, while the edge pixels lose the
/// samples beyond the crop (as in Mitsuba) and only stay close.
#[test]
fn a_crop_is_the_crop_of_the_whole_film() {
    let crop = "<integer name=\"crop_offset_x\" value=\"5\"/><integer name=\"crop_offset_y\" \
                value=\"3\"/><integer name=\"crop_width\" value=\"20\"/><integer \
                name=\"crop_height\" value=\"13\"/>";
    for filter in ["<rfilter type=\"box\"/>", ""] {
        let edit = |cropped: bool| {
            move |t: String| {
                let extra = format!("{filter}{}", if cropped { crop } else { "" });
                t.replace(
                    "<film type=\"hdrfilm\">",
                    &format!("<film type=\"hdrfilm\">{extra}"),
                )
            }
        };
        let whole = load_xml("gaussian_filter.xml", edit(false));
        let part = load_xml("gaussian_filter.xml", edit(true));
        assert_eq!((part.camera.width, part.camera.height), (20, 13));
        let whole = render(&whole, 16, 5, 2).film.image();
        let part = render(&part, 16, 5, 2).film.image();
        let margin = if filter.is_empty() { 2 } else { 0 };
        let (mut compared, mut edges_differ) = (0, 0);
        for y in 0..13 {
            for x in 0..20 {
                let (a, b) = (part.pixels[y * 20 + x], whole.pixels[(y + 3) * 32 + x + 5]);
                let inner =
                    (margin..20 - margin).contains(&x) && (margin..13 - margin).contains(&y);
                if inner {
                    assert_eq!(a, b, "pixel ({x}, {y}) filter {filter:?}");
                    compared += 1;
                } else if a != b {
                    edges_differ += 1;
                }
            }
        }
        assert!(compared >= 16 * 9);
        // The gaussian's edge pixels miss the samples beyond the crop, as Mitsuba's do.
        assert_eq!(edges_differ > 0, margin > 0, "{filter:?}");
    }
}

/// The variance image is the variance of one sample's estimate (E[x^2] - E[x]^2 over the
/// pixel's n samples, as Mitsuba's moment integrator: n/(n - 1) of it is unbiased): its mean
/// over 32 seeds times 1/spp is the variance of the pixel means across the seeds. Box filter
/// (each pixel the plain mean of its spp samples); summed over the image, within 15% (a few
/// dozen bright edge pixels dominate both sums: their 31-degree-of-freedom spread is about
/// 5% of the total; a variance off by a factor of spp, or of 2, fails).
#[test]
fn variance_image_matches_the_spread_of_seeds() {
    let scene = load_xml("gaussian_filter.xml", |t| {
        t.replace(
            "<film type=\"hdrfilm\">",
            "<film type=\"hdrfilm\"><rfilter type=\"box\"/>",
        )
    });
    let (spp, seeds) = (16u64, 32usize);
    let runs: Vec<(Image, Image)> = (0..seeds)
        .map(|seed| {
            let film = render(&scene, spp, 100 + seed as u64, 2).film;
            (film.image(), film.variance_image().unwrap())
        })
        .collect();
    let pixels = runs[0].0.pixels.len();
    let bessel = spp as f64 / (spp - 1) as f64;
    let (mut predicted, mut observed) = (0.0f64, 0.0f64);
    for p in 0..pixels {
        for c in 0..3 {
            let means: Vec<f64> = runs.iter().map(|r| r.0.pixels[p][c] as f64).collect();
            let m = means.iter().sum::<f64>() / seeds as f64;
            observed += means.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (seeds - 1) as f64;
            predicted += runs.iter().map(|r| r.1.pixels[p][c] as f64).sum::<f64>() / seeds as f64
                * bessel
                / spp as f64;
        }
    }
    let ratio = observed / predicted;
    eprintln!("variance: observed / predicted {ratio:.4}");
    assert!(
        predicted > 0.0 && (ratio - 1.0).abs() < 0.15,
        "observed / predicted {ratio}"
    );
}

/// Only pt renders an orthographic sensor or the gaussian filter; the others refuse them by
/// name, with what works.
#[test]
fn other_integrators_refuse_orthographic_and_gaussian_by_name() {
    use stagelight::integrators::{IntegratorKind, check_camera};
    let ortho = load_xml("orthographic.xml", |t| t).camera;
    let gaussian = load_xml("gaussian_filter.xml", |t| t).camera;
    let boxed = load_xml("gaussian_filter.xml", |t| {
        t.replace(
            "<film type=\"hdrfilm\">",
            "<film type=\"hdrfilm\"><rfilter type=\"box\"/>",
        )
    })
    .camera;
    for kind in IntegratorKind::all() {
        assert!(check_camera(kind, &boxed).is_ok());
        if kind.as_str() == "pt" {
            assert!(check_camera(kind, &ortho).is_ok() && check_camera(kind, &gaussian).is_ok());
            continue;
        }
        let e = check_camera(kind, &ortho).unwrap_err();
        assert!(
            e.contains(kind.as_str()) && e.contains("orthographic"),
            "{e}"
        );
        let e = check_camera(kind, &gaussian).unwrap_err();
        assert!(e.contains(kind.as_str()) && e.contains("gaussian"), "{e}");
    }
}
