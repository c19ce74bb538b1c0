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
