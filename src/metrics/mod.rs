//! Error of an image against a reference (../METRICS.md): relMSE, RMSE, MAE and channel means.

use crate::film::Image;
use glam::DVec3;

/// The error measures of one image against a reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorMetrics {
    /// Mean over pixels and channels of (x - r)^2 / (r^2 + 0.01).
    pub relmse: f64,
    pub rmse: f64,
    pub mae: f64,
    pub mean: DVec3,
    pub reference_mean: DVec3,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MetricsError {
    #[error("images differ in size: {0}x{1} against a reference of {2}x{3}")]
    SizeMismatch(usize, usize, usize, usize),
    #[error("the {which} has a NaN or infinite value at pixel ({x}, {y})")]
    NonFinite {
        which: &'static str,
        x: usize,
        y: usize,
    },
}

/// Compares `image` against `reference`; images of different sizes or with non-finite values
/// are an error.
pub fn compare(image: &Image, reference: &Image) -> Result<ErrorMetrics, MetricsError> {
    if image.width != reference.width || image.height != reference.height {
        return Err(MetricsError::SizeMismatch(
            image.width,
            image.height,
            reference.width,
            reference.height,
        ));
    }
    for (which, img) in [("image", image), ("reference", reference)] {
        if let Some(i) = img.pixels.iter().position(|p| !p.is_finite()) {
            return Err(MetricsError::NonFinite {
                which,
                x: i % img.width,
                y: i / img.width,
            });
        }
    }
    let (mut rel, mut sq, mut abs) = (0.0f64, 0.0f64, 0.0f64);
    for (x, r) in image.pixels.iter().zip(&reference.pixels) {
        for c in 0..3 {
            let (x, r) = (x[c] as f64, r[c] as f64);
            let d = x - r;
            rel += d * d / (r * r + 0.01);
            sq += d * d;
            abs += d.abs();
        }
    }
    let n = (image.pixels.len() * 3).max(1) as f64;
    Ok(ErrorMetrics {
        relmse: rel / n,
        rmse: (sq / n).sqrt(),
        mae: abs / n,
        mean: image.channel_means(),
        reference_mean: reference.channel_means(),
    })
}

/// The relMSE of a reference against the truth it estimates, from two independent halves
/// `a` and `b` of it (the reference being their average): per pixel and channel the
/// reference's variance is estimated by ((a - b) / 2)^2, so the mean of that over
/// (r^2 + 0.01) is what the reference's own noise adds to an image's expected relMSE against
/// it. Returns None when the halves do not match the reference in size or are not finite.
pub fn reference_noise(reference: &Image, a: &Image, b: &Image) -> Option<f64> {
    let same = |i: &Image| i.width == reference.width && i.height == reference.height;
    if !same(a) || !same(b) {
        return None;
    }
    let mut sum = 0.0f64;
    for ((r, a), b) in reference.pixels.iter().zip(&a.pixels).zip(&b.pixels) {
        for c in 0..3 {
            let (r, half_gap) = (r[c] as f64, (a[c] as f64 - b[c] as f64) / 2.0);
            sum += half_gap * half_gap / (r * r + 0.01);
        }
    }
    let n = (reference.pixels.len() * 3).max(1) as f64;
    (sum.is_finite()).then_some(sum / n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn constant(w: usize, h: usize, v: f32) -> Image {
        Image {
            width: w,
            height: h,
            pixels: vec![Vec3::splat(v); w * h],
        }
    }

    #[test]
    fn reference_noise_is_what_independent_halves_add_to_the_error() {
        // Truth 0.5 everywhere; halves with independent noise of variance s^2 each, so the
        // reference (their mean) has variance s^2 / 2 per value.
        let (w, h) = (64, 64);
        let mut rng = 12345u64;
        let mut gauss = || {
            let mut u = || {
                rng = rng
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((rng >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (u1, u2) = (u(), u());
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        };
        let s = 0.05f64;
        let mut noisy = || {
            let mut img = constant(w, h, 0.5);
            for p in &mut img.pixels {
                for c in 0..3 {
                    p[c] += (s * gauss()) as f32;
                }
            }
            img
        };
        let (a, b) = (noisy(), noisy());
        let mut r = constant(w, h, 0.0);
        for ((p, a), b) in r.pixels.iter_mut().zip(&a.pixels).zip(&b.pixels) {
            *p = (*a + *b) * 0.5;
        }
        let noise = reference_noise(&r, &a, &b).unwrap();
        // Expected s^2 / 2 / (0.25 + 0.01), to a few percent with 12288 values.
        let expected = s * s / 2.0 / 0.26;
        assert!(
            (noise / expected - 1.0).abs() < 0.05,
            "{noise} vs {expected}"
        );
        // The exact reference has no noise; a mismatched half gives None.
        assert_eq!(reference_noise(&r, &r, &r), Some(0.0));
        assert_eq!(reference_noise(&r, &constant(2, 2, 0.5), &b), None);
    }

    #[test]
    fn self_comparison_is_zero() {
        let a = constant(4, 3, 0.7);
        let m = compare(&a, &a).unwrap();
        assert_eq!((m.relmse, m.rmse, m.mae), (0.0, 0.0, 0.0));
    }

    #[test]
    fn known_perturbation_gives_the_analytic_value() {
        let r = constant(4, 4, 1.0);
        let x = constant(4, 4, 1.5);
        let m = compare(&x, &r).unwrap();
        assert!((m.relmse - 0.25 / 1.01).abs() < 1e-12);
        assert!((m.rmse - 0.5).abs() < 1e-12);
        assert!((m.mae - 0.5).abs() < 1e-12);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let a = constant(2, 2, 1.0);
        assert!(matches!(
            compare(&a, &constant(3, 2, 1.0)),
            Err(MetricsError::SizeMismatch(..))
        ));
        let mut n = a.clone();
        n.pixels[3].y = f32::NAN;
        assert_eq!(
            compare(&a, &n),
            Err(MetricsError::NonFinite {
                which: "reference",
                x: 1,
                y: 1
            })
        );
    }
}
