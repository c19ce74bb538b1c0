//! Microfacet distributions as Mitsuba 3 defines them (include/mitsuba/render/microfacet.h):
//! GGX and Beckmann normal distributions, anisotropic (alpha_u along the first tangent of the
//! frame they are evaluated in, alpha_v along the second), Smith's separable shadowing and
//! sampling by the distribution of visible normals. The conductor and the plastic coat use them.
//!
//! Beckmann's G1 is Smith's exact one (through erf). Mitsuba evaluates it with a rational
//! approximation (within 0.35%) but samples the exact visible normals, so its sampled density
//! and its pdf differ by up to that much; with the exact G1 here they agree.
use crate::lanes::{Mask, Real, V3};
use glam::{DVec3, Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Smallest roughness used (Mitsuba clamps alpha to the same 1e-4). Directions in f32 carry
/// errors of ~1e-7, and the lobe's width in half-vector space is ~alpha, so D evaluated at a
/// half-vector rebuilt from (wo, wi) is accurate to ~1e-7/alpha: below 1e-4 `eval` and `pdf`
/// would no longer match what `sample` drew. The peak values also stay modest:
/// D <= 1/(pi alpha^2) ~ 3e7 and f <= R/(pi alpha^4) ~ 3e15.
pub const ALPHA_MIN: f32 = 1e-4;

/// A microfacet normal distribution (Mitsuba's `distribution`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Microfacet {
    /// Trowbridge-Reitz.
    Ggx,
    /// Gaussian slopes: Mitsuba's default for `roughconductor` and `roughplastic`.
    Beckmann,
}

/// `alpha` clamped to [ALPHA_MIN, 1e4], written as a comparison so that a NaN alpha also
/// becomes ALPHA_MIN (clamp would keep NaN); the upper bound only keeps alpha^2 and D's
/// denominator far from overflow.
#[inline(always)]
fn clamp_alpha<T: Real>(alpha: T) -> T {
    T::select(
        alpha.less(T::splat(ALPHA_MIN)) | !alpha.equal(alpha),
        T::splat(ALPHA_MIN),
        alpha.min(T::splat(1.0e4)),
    )
}

/// The direction of a lobe's first roughness in the shading frame's tangent plane, (cos, sin)
/// of its angle from the frame's first tangent, per path or per lane: exactly (1, 0) for an
/// isotropic lobe, whose directions are then left as they are.
#[derive(Clone, Copy)]
pub(crate) struct Axis<T: Real> {
    cos: T,
    sin: T,
    /// Where the axis is the first tangent (the identity, bit for bit).
    identity: T::Mask,
}

impl<T: Real> Axis<T> {
    #[inline(always)]
    pub(crate) fn new(cos: T, sin: T) -> Axis<T> {
        let identity = cos.equal(T::splat(1.0)) & sin.equal(T::splat(0.0));
        Axis { cos, sin, identity }
    }

    /// `w` in the frame whose first tangent is the axis.
    #[inline(always)]
    pub(crate) fn onto(&self, w: V3<T>) -> V3<T> {
        let (c, s) = (self.cos, self.sin);
        V3::select_with(
            self.identity,
            || w,
            || V3::new(c * w.x + s * w.y, c * w.y - s * w.x, w.z),
        )
    }

    /// The inverse of `onto`.
    #[inline(always)]
    pub(crate) fn off(&self, w: V3<T>) -> V3<T> {
        let (c, s) = (self.cos, self.sin);
        V3::select_with(
            self.identity,
            || w,
            || V3::new(c * w.x - s * w.y, s * w.x + c * w.y, w.z),
        )
    }
}

/// `w` in the frame whose first tangent is `axis` ((cos, sin) of its angle from the current
/// frame's first tangent): the identity for `Vec2::X`, the axis of every isotropic lobe.
#[inline]
pub(crate) fn onto_axis(axis: Vec2, w: Vec3) -> Vec3 {
    Axis::new(axis.x, axis.y).onto(w.into()).into()
}

/// The inverse of `onto_axis`.
#[inline]
pub(crate) fn off_axis(axis: Vec2, w: Vec3) -> Vec3 {
    Axis::new(axis.x, axis.y).off(w.into()).into()
}

/// A lobe's distribution and its two roughnesses, clamped (see `clamp_alpha`), in the frame of
/// its axis, for one path (`f32`) or lanes (`F<N>`): the maths below is written once over
/// `Real`, so the megakernel and the wavefront's lanes compute the same bits. With alpha_u =
/// alpha_v every formula performs the isotropic lobe's operations exactly, so isotropic
/// materials render as they did before anisotropy existed.
#[derive(Clone, Copy)]
pub(crate) struct Distribution<T: Real> {
    /// Where the lobe is Beckmann's (else GGX).
    beckmann: T::Mask,
    u: T,
    v: T,
    isotropic: T::Mask,
}

/// 1 / sqrt(pi).
const FRAC_1_SQRT_PI: f32 = 0.564_189_6;

impl Distribution<f32> {
    /// One path's lobe.
    #[inline(always)]
    pub(crate) fn of(distribution: Microfacet, alpha_u: f32, alpha_v: f32) -> Distribution<f32> {
        Distribution::new(distribution == Microfacet::Beckmann, alpha_u, alpha_v)
    }
}

impl<T: Real> Distribution<T> {
    #[inline(always)]
    pub(crate) fn new(beckmann: T::Mask, alpha_u: T, alpha_v: T) -> Distribution<T> {
        let (u, v) = (clamp_alpha(alpha_u), clamp_alpha(alpha_v));
        Distribution {
            beckmann,
            u,
            v,
            isotropic: u.equal(v),
        }
    }

    /// D(m) (see `ggx_ndf`, `beckmann_ndf`).
    #[inline(always)]
    pub(crate) fn ndf(&self, m: V3<T>) -> T {
        // A group with no Beckmann lane runs GGX's side right here, inlined with the caller's
        // vector features: `select_with`'s closures are compiled apart, without them (here and
        // below; docs/measurements/2026-11-29-microfacet-sides-inlined.md).
        if !self.beckmann.any() {
            return self.ggx_ndf(m);
        }
        T::select_with(self.beckmann, || self.beckmann_ndf(m), || self.ggx_ndf(m))
    }

    /// Smith's G1(w) / w.z, w.z > 0.
    #[inline(always)]
    pub(crate) fn g1_over_cos(&self, w: V3<T>) -> T {
        if !self.beckmann.any() {
            return self.ggx_g1_over_cos(w);
        }
        T::select_with(
            self.beckmann,
            || self.beckmann_g1_over_cos(w),
            || self.ggx_g1_over_cos(w),
        )
    }

    /// A normal visible from `wo` (wo.z > 0), for the numbers `ux`, `uy`, in the lanes
    /// `needed` (the others may get +z). Beckmann's slope inversion has no vector form: it
    /// runs lane by lane (in double precision), and only in the needed Beckmann lanes.
    #[inline(always)]
    pub(crate) fn visible_normal(&self, wo: V3<T>, ux: T, uy: T, needed: T::Mask) -> V3<T> {
        if !self.beckmann.any() {
            return self.ggx_visible_normal(wo, ux, uy);
        }
        V3::select_with(
            self.beckmann,
            || {
                V3::lanes(|l| {
                    if !(needed.lane(l) && self.beckmann.lane(l)) {
                        return Vec3::Z;
                    }
                    beckmann_visible_normal(
                        self.u.lane(l),
                        self.v.lane(l),
                        wo.lane_of(l),
                        Vec2::new(ux.lane(l), uy.lane(l)),
                    )
                })
            },
            || self.ggx_visible_normal(wo, ux, uy),
        )
    }

    /// `projected` squared: alpha^2 sin^2 for an isotropic lobe, alpha_u^2 w.x^2 + alpha_v^2
    /// w.y^2 in general.
    #[inline(always)]
    fn projected2(&self, w: V3<T>) -> T {
        let (u, v) = (self.u, self.v);
        T::select(
            self.isotropic,
            u * u * (w.x * w.x + w.y * w.y),
            u * u * w.x * w.x + v * v * w.y * w.y,
        )
    }

    /// The roughness in `w`'s azimuth times sin(theta).
    #[inline(always)]
    fn projected(&self, w: V3<T>) -> T {
        T::select(
            self.isotropic,
            self.u * (w.x * w.x + w.y * w.y).sqrt(),
            self.projected2(w).sqrt(),
        )
    }

    /// GGX normal distribution 1 / (pi au av (x^2/au^2 + y^2/av^2 + z^2)^2) for a unit
    /// half-vector `m` with m.z > 0, written as au av / (pi d^2) with d = au av z^2 +
    /// (av/au) x^2 + (au/av) y^2: x^2 + y^2 stands for sin^2 rather than 1 - m.z^2, which
    /// cancels to 0 for tiny alpha.
    #[inline(always)]
    fn ggx_ndf(&self, m: V3<T>) -> T {
        let a2 = self.u * self.v;
        let d = a2 * m.z * m.z + (self.v / self.u) * m.x * m.x + (self.u / self.v) * m.y * m.y;
        a2 * FRAC_1_PI / (d * d)
    }

    /// Smith G1(w) / w.z for the GGX distribution, w.z > 0:
    /// G1 = 2 / (1 + sqrt(1 + alpha^2 tan^2)), so G1 / cos = 2 / (cos + sqrt(cos^2 + alpha^2
    /// sin^2)) with alpha the roughness in w's azimuth: bounded by 2/alpha even at cos = 0.
    #[inline(always)]
    fn ggx_g1_over_cos(&self, w: V3<T>) -> T {
        let c2 = w.z * w.z;
        T::splat(2.0) / (w.z + (c2 + self.projected2(w)).sqrt())
    }

    /// Beckmann normal distribution exp(-(x^2/au^2 + y^2/av^2) / z^2) / (pi au av z^4) for a
    /// unit half-vector `m` with m.z > 0 (x^2 + y^2 for sin^2, see `ggx_ndf`).
    #[inline(always)]
    fn beckmann_ndf(&self, m: V3<T>) -> T {
        let a2 = self.u * self.v;
        let c2 = m.z * m.z;
        let exponent = ((self.v / self.u) * m.x * m.x + (self.u / self.v) * m.y * m.y) / (a2 * c2);
        // exp(-87) ~ 1e-38: beyond, D is 0 (and a c2 underflowing to 0 would give 0 / 0).
        T::select(
            exponent.less(T::splat(87.0)),
            (-exponent).exp() * FRAC_1_PI / (a2 * c2 * c2),
            T::splat(0.0),
        )
    }

    /// Smith G1(w) / w.z for the Beckmann distribution, w.z > 0. With r = alpha sin (alpha in
    /// w's azimuth) and a = cos / r, Lambda = (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi))
    /// and G1 = 1 / (1 + Lambda), so G1 / cos = 2 / (cos (1 + erf(a)) + r exp(-a^2) /
    /// sqrt(pi)): bounded by 2 sqrt(pi) / alpha at cos = 0, and 1 / cos at normal incidence
    /// (a infinite).
    #[inline(always)]
    fn beckmann_g1_over_cos(&self, w: V3<T>) -> T {
        let r = self.projected(w);
        let a = w.z / r;
        T::splat(2.0) / (w.z * (a.erf() + 1.0) + r * (-a * a).exp() * FRAC_1_SQRT_PI)
    }

    /// A half-vector from the GGX distribution of normals visible from `wo` (wo.z > 0),
    /// following Heitz 2018: stretch to the alpha = 1 configuration, sample the projected
    /// hemisphere, unstretch.
    #[inline(always)]
    fn ggx_visible_normal(&self, wo: V3<T>, ux: T, uy: T) -> V3<T> {
        let (zero, one) = (T::splat(0.0), T::splat(1.0));
        let v = V3::new(self.u * wo.x, self.v * wo.y, wo.z).normalize();
        // Basis around v; at normal incidence any tangent will do.
        let len2 = v.x * v.x + v.y * v.y;
        let t1 = V3::select(
            len2.greater(zero),
            V3::new(-v.y, v.x, zero) / len2.sqrt(),
            V3::new(one, zero, zero),
        );
        let t2 = v.cross(t1);
        // Uniform disk point, its second coordinate squeezed onto the visible part of the
        // hemisphere's projection.
        let r = ux.sqrt();
        let (sin, cos) = uy.sin_cos_turn();
        let p1 = r * cos;
        let p2 = r * sin;
        let s = (v.z + 1.0) * 0.5;
        let p2 = (one - s) * (one - p1 * p1).max(zero).sqrt() + s * p2;
        let nz = (one - p1 * p1 - p2 * p2).max(zero).sqrt();
        let n = t1 * p1 + t2 * p2 + v * nz;
        V3::new(self.u * n.x, self.v * n.y, n.z.max(zero)).normalize_or(V3::new(zero, zero, one))
    }
}

/// A half-vector from the Beckmann distribution of roughnesses `alpha_u`, `alpha_v` (clamped)
/// of normals visible from `wo` (wo.z > 0), as Heitz and d'Eon 2014 (and Mitsuba's
/// `MicrofacetDistribution::sample`): stretch wo to the alpha = 1 configuration, draw the
/// slopes visible from there, rotate them to wo's azimuth and unstretch. In double precision,
/// so the slopes' CDF is inverted to far below f32's resolution and the sampled density is the
/// pdf's.
fn beckmann_visible_normal(alpha_u: f32, alpha_v: f32, wo: Vec3, u: Vec2) -> Vec3 {
    let v = DVec3::new(
        alpha_u as f64 * wo.x as f64,
        alpha_v as f64 * wo.y as f64,
        wo.z as f64,
    )
    .normalize();
    let sin_theta = (v.x * v.x + v.y * v.y).sqrt();
    let (cos_phi, sin_phi) = if sin_theta > 0.0 {
        (v.x / sin_theta, v.y / sin_theta)
    } else {
        (1.0, 0.0)
    };
    let tan_theta = sin_theta / v.z;
    let slope_x = invert_visible_slope_cdf(tan_theta, u.x as f64);
    let slope_y = gaussian_slope(u.y as f64);
    let x = (cos_phi * slope_x - sin_phi * slope_y) * alpha_u as f64;
    let y = (sin_phi * slope_x + cos_phi * slope_y) * alpha_v as f64;
    DVec3::new(-x, -y, 1.0).normalize().as_vec3()
}

/// sqrt(pi).
const SQRT_PI: f64 = 1.772_453_850_905_516;

/// A slope of a Beckmann microsurface of roughness 1 seen from a direction at polar tangent
/// `tan_theta` and azimuth 0: the s in (-inf, 1/tan_theta] where u of the way through the
/// density exp(-s^2) (1 - s tan_theta) lies (the microfacet normal (-s, ., 1) faces the
/// viewer for s < 1/tan_theta, with projected area in proportion to 1 - s tan_theta). Its CDF
/// is C(s) = sqrt(pi)/2 erfc(-s) + tan_theta/2 exp(-s^2). Halley's method on C from
/// `first_slope`'s guess, kept inside a bracket that bisection shrinks whenever a step would
/// leave it: C' and C'' cost no more transcendentals than C, and a cubic step needs one
/// evaluation fewer than Newton's (about 2 evaluations a search where Newton's took 4.4).
/// Within 1e-11 of u in C (`tests`).
fn invert_visible_slope_cdf(tan_theta: f64, u: f64) -> f64 {
    let mut lo = -SLOPE_LIMIT;
    let mut hi = if tan_theta > 0.0 {
        (1.0 / tan_theta).min(SLOPE_LIMIT)
    } else {
        SLOPE_LIMIT
    };
    let u = u.clamp(0.0, 1.0);
    // C(hi) through erf(hi), which the guess reads too: erfc(-hi) = 1 + erf(hi) for hi > 0,
    // and erf(8) is 1 in double precision.
    let erf_hi = if hi < SLOPE_LIMIT { libm::erf(hi) } else { 1.0 };
    let target = u * (0.5 * SQRT_PI * (1.0 + erf_hi) + 0.5 * tan_theta * (-hi * hi).exp());
    let guess = first_slope(tan_theta, erf_hi, u);
    let mut s = if guess.is_finite() {
        guess.clamp(lo, hi)
    } else {
        0.0f64.min(hi)
    };
    for _ in 0..100 {
        let gauss = (-s * s).exp();
        let excess = 0.5 * SQRT_PI * libm::erfc(-s) + 0.5 * tan_theta * gauss - target;
        if excess == 0.0 {
            return s;
        }
        if excess < 0.0 {
            lo = s;
        } else {
            hi = s;
        }
        let slope = gauss * (1.0 - s * tan_theta);
        let curve = gauss * (-2.0 * s * (1.0 - s * tan_theta) - tan_theta);
        let halley = s - 2.0 * excess * slope / (2.0 * slope * slope - excess * curve);
        // Halley's error after a step is about the step's cube (times C's derivatives'
        // ratios): a step under 1e-5 leaves some 1e-15.
        if slope > 0.0 && (halley - s).abs() <= 1e-5 * (1.0 + s.abs()) {
            return halley.clamp(lo, hi);
        }
        s = if slope > 0.0 && halley > lo && halley < hi {
            halley
        } else {
            0.5 * (lo + hi)
        };
    }
    s
}

/// The slopes' search stays within |s| <= 8: beyond lies a probability under 1e-28.
const SLOPE_LIMIT: f64 = 8.0;

/// The Beckmann microsurface's other slope, Gaussian and independent of the view: erfinv(2u -
/// 1), from `erfinv_guess` and one Newton step on erf (the guess is within 1e-7, so the step
/// leaves about 1e-14; 2.5x faster than searching C with tan_theta 0).
fn gaussian_slope(u: f64) -> f64 {
    let x = 2.0 * u.clamp(0.0, 1.0) - 1.0;
    if x.abs() >= 1.0 || x.is_nan() {
        return SLOPE_LIMIT.copysign(x);
    }
    let s = erfinv_guess(x);
    (s - (libm::erf(s) - x) * (0.5 * SQRT_PI) * (s * s).exp()).clamp(-SLOPE_LIMIT, SLOPE_LIMIT)
}

/// Where Halley's method starts for `invert_visible_slope_cdf` (`erf_hi` is erf of the
/// bracket's top): Mitsuba 3's fit in erf's domain (`sample_visible_11`), exact at normal
/// incidence (erf(s) = 2u - 1) and near the root elsewhere. NaN where the guess leaves erf's
/// range (the caller then starts at 0).
fn first_slope(tan_theta: f64, erf_hi: f64, u: f64) -> f64 {
    let theta = tan_theta.atan();
    let fit = 1.0 + theta * (-0.876 + theta * (0.4265 - 0.0594 * theta));
    let x = erf_hi - (erf_hi + 1.0) * (1.0 - u).powf(fit);
    if x.abs() < 1.0 {
        erfinv_guess(x)
    } else {
        f64::NAN
    }
}

/// erfinv(x) for |x| < 1 to about 1e-7 (Giles 2010's single-precision polynomials, evaluated
/// in double): a starting point, not an answer.
fn erfinv_guess(x: f64) -> f64 {
    let w = -((1.0 - x) * (1.0 + x)).ln();
    let (w, coefficients): (f64, [f64; 9]) = if w < 5.0 {
        (
            w - 2.5,
            [
                2.810_226_36e-8,
                3.432_739_39e-7,
                -3.523_387_7e-6,
                -4.391_506_54e-6,
                2.185_808_7e-4,
                -1.253_725_03e-3,
                -4.177_681_64e-3,
                2.466_407_27e-1,
                1.501_409_41,
            ],
        )
    } else {
        (
            w.sqrt() - 3.0,
            [
                -2.002_142_57e-4,
                1.009_505_58e-4,
                1.349_343_22e-3,
                -3.673_428_44e-3,
                5.739_507_73e-3,
                -7.622_461_3e-3,
                9.438_870_47e-3,
                1.001_674_06,
                2.832_976_82,
            ],
        )
    };
    coefficients.iter().fold(0.0, |p, &c| c + p * w) * x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mitsuba's rational approximation of Beckmann's G1 (microfacet.h), for comparison.
    fn mitsuba_beckmann_g1(alpha: f32, w: Vec3) -> f32 {
        let tan_alpha2 = alpha * alpha * (w.x * w.x + w.y * w.y) / (w.z * w.z);
        let a = 1.0 / tan_alpha2.sqrt();
        if a >= 1.6 {
            1.0
        } else {
            (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
        }
    }

    #[test]
    fn beckmann_g1_is_within_mitsuba_approximation() {
        for alpha in [0.05f32, 0.2, 0.5, 1.0] {
            for i in 0..90 {
                let t = (i as f32).to_radians();
                let w = Vec3::new(t.sin(), 0.0, t.cos());
                let ours = Distribution::of(Microfacet::Beckmann, alpha, alpha)
                    .g1_over_cos(w.into())
                    * w.z;
                let theirs = mitsuba_beckmann_g1(alpha, w);
                assert!(
                    (ours - theirs).abs() <= 0.0036 * ours + 1e-6,
                    "alpha {alpha} theta {i}: {ours} vs Mitsuba's {theirs}"
                );
            }
        }
    }

    #[test]
    pub(crate) fn beckmann_ndf_integrates_to_one_over_projected_area() {
        // Midpoint rule over theta in (0, pi/2): int D cos sin dtheta dphi = 1.
        for alpha in [0.05f64, 0.3, 1.0] {
            let n = 200_000;
            let mut sum = 0.0;
            for i in 0..n {
                let t = (i as f64 + 0.5) / n as f64 * std::f64::consts::FRAC_PI_2;
                let m = Vec3::new(t.sin() as f32, 0.0, t.cos() as f32);
                let a = alpha as f32;
                sum += Distribution::of(Microfacet::Beckmann, a, a).ndf(m.into()) as f64
                    * t.cos()
                    * t.sin();
            }
            let integral =
                sum * std::f64::consts::FRAC_PI_2 / n as f64 * 2.0 * std::f64::consts::PI;
            assert!((integral - 1.0).abs() < 1e-3, "alpha {alpha}: {integral}");
        }
    }

    #[test]
    fn erfinv_guess_is_near_erfinv() {
        for i in -999..=999 {
            let x = i as f64 / 1000.0;
            let y = erfinv_guess(x);
            assert!(
                (libm::erf(y) - x).abs() < 1e-6,
                "x {x}: erf({y}) = {}",
                libm::erf(y)
            );
        }
    }

    #[test]
    fn visible_slope_cdf_inverts() {
        for tan_theta in [0.0f64, 1e-3, 0.1, 0.3, 1.0, 3.0, 10.0, 100.0, 1e4] {
            let cdf = |s: f64| 0.5 * SQRT_PI * libm::erfc(-s) + 0.5 * tan_theta * (-s * s).exp();
            let top = if tan_theta > 0.0 {
                (1.0 / tan_theta).min(8.0)
            } else {
                8.0
            };
            let inner = (1..1000).map(|i| i as f64 / 1000.0);
            for u in [0.0, 1e-9, 1.0 - 1e-9, 1.0].into_iter().chain(inner) {
                let s = invert_visible_slope_cdf(tan_theta, u);
                assert!(s <= top + 1e-12, "tan {tan_theta} u {u}: {s} beyond {top}");
                let got = cdf(s) / cdf(top);
                assert!(
                    (got - u).abs() < 1e-11,
                    "tan {tan_theta} u {u}: C(s) = {got}"
                );
            }
        }
    }

    #[test]
    fn gaussian_slope_inverts_its_cdf() {
        // Every f32 number in [0, 1) at a step of 2^-20, and the ends.
        for i in 0..=(1u32 << 20) {
            let u = f64::from(i) / f64::from(1u32 << 20);
            let s = gaussian_slope(u);
            let got = 0.5 * libm::erfc(-s);
            assert!((got - u).abs() < 1e-13, "u {u}: C(s) = {got}");
        }
        // Its quartiles: erfinv(+-1/2) = +-0.476936.
        assert!((gaussian_slope(0.75) - 0.476_936_3).abs() < 1e-6);
        assert!((gaussian_slope(0.25) + 0.476_936_3).abs() < 1e-6);
    }
}
