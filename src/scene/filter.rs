//! Pixel reconstruction filters, as Mitsuba 3 defines them (src/rfilters/*.cpp,
//! src/render/imageblock.cpp): `Box` puts each sample in the pixel it falls in; `Gaussian`
//! splats each sample into every pixel whose centre lies within the filter's radius, weighted
//! by the separable product of the 1D filter at the two offsets, and a pixel is the weighted sum
//! of its samples over the sum of their weights.
//!
//! Mitsuba's gaussian is exp(-x^2 / (2 stddev^2)) with its value at the radius (4 stddev)
//! subtracted so that it reaches zero there, clamped at zero beyond. Its CPU variants (scalar
//! and LLVM) evaluate a degree-9 Remez fit of exp(-t/2) in t = x^2 / stddev^2, with the fit's
//! own value at the radius subtracted; that fit is up to 5e-4 off the exponential (0.99925 at
//! 0), and this is that fit, coefficient for coefficient, so the weights are Mitsuba's
//! (checked against Mitsuba 3.9.1's `eval` in the tests).

/// A film's reconstruction filter.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum PixelFilter {
    /// Each sample counts in its own pixel only (Mitsuba's `box` of radius 0.5).
    #[default]
    Box,
    Gaussian(Gaussian),
}

/// Mitsuba's `gaussian` rfilter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gaussian {
    pub stddev: f32,
    /// 4 standard deviations: the filter is zero from there on.
    pub radius: f32,
    /// The polynomial in x^2 that Mitsuba evaluates, its value at the radius subtracted from
    /// the constant term so that the filter ends at zero.
    coefficients: [f32; 10],
}

/// Mitsuba's Remez fit of exp(-t/2) on t in [0, 16] (src/rfilters/gaussian.cpp).
const REMEZ_EXP_HALF: [f64; 10] = [
    9.992604880e-1,
    -4.977025247e-1,
    1.222248550e-1,
    -1.932406282e-2,
    2.136713061e-3,
    -1.679873860e-4,
    9.202145248e-6,
    -3.329417433e-7,
    7.128382794e-9,
    -6.821193280e-11,
];

/// A polynomial's value at `t` (Horner's rule, f32 as Mitsuba).
#[inline]
fn polynomial(coefficients: &[f32; 10], t: f32) -> f32 {
    coefficients.iter().rev().fold(0.0, |acc, &c| acc * t + c)
}

/// Mitsuba's default standard deviation.
pub const DEFAULT_STDDEV: f32 = 0.5;

impl Gaussian {
    /// The filter of this standard deviation; None unless it is finite and positive.
    pub fn new(stddev: f32) -> Option<Gaussian> {
        (stddev.is_finite() && stddev > 0.0).then(|| {
            let radius = 4.0 * stddev;
            // Coefficient i scaled by stddev^-2i: the fit in x^2 rather than x^2 / stddev^2.
            let mut coefficients = [0.0f32; 10];
            let mut scale = 1.0f64;
            for (c, &fit) in coefficients.iter_mut().zip(&REMEZ_EXP_HALF) {
                *c = (fit * scale) as f32;
                scale /= (stddev as f64) * (stddev as f64);
            }
            coefficients[0] -= polynomial(&coefficients, radius * radius);
            Gaussian {
                stddev,
                radius,
                coefficients,
            }
        })
    }

    /// The 1D filter at offset `x` (pixels) from a pixel centre.
    #[inline]
    pub fn eval(&self, x: f32) -> f32 {
        polynomial(&self.coefficients, x * x).max(0.0)
    }

    /// The pixels along one axis (0..size) whose centres lie within the radius of film
    /// coordinate `pos`, as Mitsuba's image block finds them: from ceil(pos - 0.5 - radius) to
    /// floor(pos - 0.5 + radius), clipped to the film.
    #[inline]
    pub fn footprint(&self, pos: f32, size: usize) -> std::ops::Range<usize> {
        let centre = pos - 0.5;
        let first = (centre - self.radius).ceil().max(0.0) as usize;
        let last = (centre + self.radius).floor();
        if last < 0.0 {
            return 0..0;
        }
        first..((last as usize) + 1).min(size)
    }

    /// `footprint` of film coordinate `pos` on a whole film, as indices of its pixels from
    /// `offset` on, of which there are `size` (a crop window's): the same pixels the whole
    /// film's footprint has there.
    #[inline]
    pub fn footprint_in(&self, pos: f32, offset: usize, size: usize) -> std::ops::Range<usize> {
        let centre = pos - 0.5;
        let (first, last) = (
            (centre - self.radius).ceil(),
            (centre + self.radius).floor(),
        );
        if last < offset as f32 {
            return 0..0;
        }
        let first = (first.max(0.0) as usize).max(offset) - offset;
        first..((last as usize + 1).min(offset + size) - offset).max(first)
    }

    /// Half the footprint's widest extent in whole pixels: a sample's weights reach at most
    /// this many pixels away from its own pixel.
    pub fn reach(&self) -> usize {
        (self.radius + 0.5).ceil() as usize
    }

    /// The integral of the filter over film coordinates 0..size, centred on pixel `pixel`'s
    /// centre: what the weights of one uniform sample per pixel sum to on average there (the
    /// normalisation of a light-tracing splat, so that splats and camera samples estimate the
    /// same filtered pixel). Simpson's rule on 64 intervals per pixel: exact to 1e-7 here.
    pub fn integral_over_film(&self, pixel: usize, size: usize) -> f64 {
        let centre = pixel as f64 + 0.5;
        let r = self.radius as f64;
        let (a, b) = ((centre - r).max(0.0), (centre + r).min(size as f64));
        if b <= a {
            return 0.0;
        }
        let n = (((b - a) * 64.0).ceil() as usize).max(2) & !1usize;
        let h = (b - a) / n as f64;
        let f = |x: f64| self.eval((x - centre) as f32) as f64;
        let mut s = f(a) + f(b);
        for i in 1..n {
            s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0
    }
}

/// Draws film positions by the gaussian's own shape (filter importance sampling), for
/// estimators that keep one estimate per pixel (the photon mappers' camera passes): a pixel's
/// camera ray leaves the film at its centre plus an offset drawn per axis with density
/// proportional to the filter, clipped to the film, and weighs `w(x) / pdf(x)` over the
/// integral of the filter over the film there. Its expected value is then the filter-weighted
/// mean of the image around the pixel, the normalised filter that the camera's weighted
/// samples of pt and the splats estimate too. The density is piecewise constant over
/// `BINS` bins across the footprint, so the weight is the filter over its bin's value, within
/// 1e-3 of 1.
#[derive(Clone, Debug)]
pub struct GaussianSampler {
    gaussian: Gaussian,
    /// The filter at each bin's middle.
    value: Vec<f32>,
    /// The integral of the binned density from -radius to each bin's start (BINS + 1 entries).
    cdf: Vec<f64>,
    bin: f64,
}

impl GaussianSampler {
    const BINS: usize = 1024;

    pub fn new(gaussian: Gaussian) -> GaussianSampler {
        let r = gaussian.radius as f64;
        let bin = 2.0 * r / Self::BINS as f64;
        let value: Vec<f32> = (0..Self::BINS)
            .map(|k| gaussian.eval((-r + (k as f64 + 0.5) * bin) as f32))
            .collect();
        let mut cdf = Vec::with_capacity(Self::BINS + 1);
        let mut sum = 0.0f64;
        cdf.push(0.0);
        for &v in &value {
            sum += v as f64 * bin;
            cdf.push(sum);
        }
        GaussianSampler {
            gaussian,
            value,
            cdf,
            bin,
        }
    }

    /// The binned density's integral from -radius to offset `x` (clamped to the footprint).
    fn integral_to(&self, x: f64) -> f64 {
        let r = self.gaussian.radius as f64;
        let t = ((x + r) / self.bin).clamp(0.0, Self::BINS as f64);
        let k = (t as usize).min(Self::BINS - 1);
        self.cdf[k] + (t - k as f64) * self.bin * self.value[k] as f64
    }

    /// The binned density's integral over the film (0..size) about pixel `pixel`'s centre:
    /// `Gaussian::integral_over_film` to within the bins' error.
    pub fn integral_over_film(&self, pixel: usize, size: usize) -> f64 {
        let centre = pixel as f64 + 0.5;
        self.integral_to(size as f64 - centre) - self.integral_to(-centre)
    }

    /// One axis: for `u` in [0, 1) the film coordinate drawn about pixel `pixel`'s centre on
    /// an axis of `size` pixels, and its weight along this axis (the filter over the density,
    /// over the film-clipped integral: 1 up to the bins' error).
    pub fn sample(&self, u: f32, pixel: usize, size: usize) -> (f32, f32) {
        let centre = pixel as f64 + 0.5;
        let (lo, hi) = (
            self.integral_to(-centre),
            self.integral_to(size as f64 - centre),
        );
        let target = lo + u as f64 * (hi - lo);
        // The bin whose cumulative range holds the target.
        let k = match self.cdf.binary_search_by(|c| c.total_cmp(&target)) {
            Ok(k) => k,
            Err(k) => k - 1,
        }
        .min(Self::BINS - 1);
        let mut k = k;
        while self.value[k] == 0.0 && k + 1 < Self::BINS {
            k += 1;
        }
        let within = ((target - self.cdf[k]) / (self.bin * self.value[k] as f64)).clamp(0.0, 1.0);
        let r = self.gaussian.radius as f64;
        let offset = -r + (k as f64 + within) * self.bin;
        let x = (centre + offset).clamp(0.0, size as f64 - 1e-4) as f32;
        let weight = self.gaussian.eval(x - centre as f32) / self.value[k];
        (x, weight)
    }
}

impl PixelFilter {
    /// The filter's name in Mitsuba's XML (for messages).
    pub fn name(&self) -> &'static str {
        match self {
            PixelFilter::Box => "box",
            PixelFilter::Gaussian(_) => "gaussian",
        }
    }

    /// The default filter of a Mitsuba film without an rfilter.
    pub fn mitsuba_default() -> PixelFilter {
        PixelFilter::Gaussian(Gaussian::new(DEFAULT_STDDEV).expect("a positive stddev"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn footprints_are_the_pixels_within_the_radius() {
        let g = Gaussian::new(0.5).unwrap();
        assert_eq!(g.radius, 2.0);
        // A sample at 10.3: pixel centres 8.5 .. 11.5 lie within 2 of it.
        assert_eq!(g.footprint(10.3, 100), 8..12);
        assert_eq!(g.footprint(0.2, 100), 0..2);
        assert_eq!(g.footprint(99.9, 100), 98..100);
        assert_eq!(g.reach(), 3);
    }

    /// The sampler's positions follow the filter: a histogram of weighted draws about an
    /// interior and an edge pixel against the filter's integral over each sub-pixel cell,
    /// normalised by the film-clipped integral; and the mean weight is 1.
    #[test]
    fn sampler_draws_positions_by_the_filter() {
        let g = Gaussian::new(0.5).unwrap();
        let sampler = GaussianSampler::new(g);
        for (pixel, size) in [(10usize, 20usize), (0, 20), (19, 20), (1, 3)] {
            let norm = g.integral_over_film(pixel, size);
            assert!((sampler.integral_over_film(pixel, size) - norm).abs() < 1e-5 * norm);
            let n = 200_000;
            let cells = 8; // per pixel
            let mut hist = vec![0.0f64; size * cells];
            let mut weights = 0.0;
            for i in 0..n {
                let u = (i as f32 + 0.5) / n as f32;
                let (x, w) = sampler.sample(u, pixel, size);
                assert!((0.0..size as f32).contains(&x), "{x}");
                hist[(x * cells as f32) as usize] += w as f64 / n as f64;
                weights += w as f64 / n as f64;
            }
            assert!((weights - 1.0).abs() < 1e-3, "mean weight {weights}");
            let centre = pixel as f64 + 0.5;
            for (c, &h) in hist.iter().enumerate() {
                let (a, b) = (c as f64 / cells as f64, (c + 1) as f64 / cells as f64);
                // Simpson on the cell.
                let f = |x: f64| g.eval((x - centre) as f32) as f64;
                let expected = (b - a) / 6.0 * (f(a) + 4.0 * f(0.5 * (a + b)) + f(b)) / norm;
                assert!(
                    (h - expected).abs() < 2e-3,
                    "pixel {pixel} cell {c}: {h} against {expected}"
                );
            }
        }
    }

    #[test]
    fn integral_over_the_whole_line_is_the_gaussians() {
        let g = Gaussian::new(0.5).unwrap();
        // sqrt(2 pi) stddev erf(2 sqrt 2) - 2 radius exp(-8): the gaussian less its tail,
        // which Mitsuba's fit follows to 5e-4.
        let erf = 0.999_936_657_516_334_2; // erf(2 sqrt(2))
        let exact = (2.0 * std::f64::consts::PI).sqrt() * 0.5 * erf - 2.0 * 2.0 * (-8.0f64).exp();
        let integral = g.integral_over_film(50, 100);
        assert!(
            (integral - exact).abs() < 1e-3,
            "{integral} against {exact}"
        );
        // At the film's edge only the inner half (and a bit) counts.
        let edge = g.integral_over_film(0, 100);
        assert!(edge < exact * 0.85 && edge > exact * 0.6, "{edge}");
    }
}
