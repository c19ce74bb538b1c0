//! Microfacet distributions as Mitsuba 3 defines them (include/mitsuba/render/microfacet.h):
//! GGX and Beckmann normal distributions, anisotropic (alpha_u along the first tangent of the
//! frame they are evaluated in, alpha_v along the second), Smith's separable shadowing and
//! sampling by the distribution of visible normals. The conductor and the plastic coat use them.
//!
//! Beckmann's G1 is Smith's exact one (through erf). Mitsuba evaluates it with a rational
//! approximation (within 0.35%) but samples the exact visible normals, so its sampled density
//! and its pdf differ by up to that much; with the exact G1 here they agree.
use glam::{DVec3, Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

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

#[inline]
fn clamp_alpha(alpha: f32) -> f32 {
    // Written as a comparison so that a NaN alpha also becomes ALPHA_MIN (clamp would keep
    // NaN); the upper bound only keeps alpha^2 and D's denominator far from overflow.
    if alpha >= ALPHA_MIN {
        alpha.min(1.0e4)
    } else {
        ALPHA_MIN
    }
}

/// `w` in the frame whose first tangent is `axis` ((cos, sin) of its angle from the current
/// frame's first tangent): the identity for `Vec2::X`, the axis of every isotropic lobe.
#[inline]
pub(crate) fn onto_axis(axis: Vec2, w: Vec3) -> Vec3 {
    if axis == Vec2::X {
        return w;
    }
    let (c, s) = (axis.x, axis.y);
    Vec3::new(c * w.x + s * w.y, c * w.y - s * w.x, w.z)
}

/// The inverse of `onto_axis`.
#[inline]
pub(crate) fn off_axis(axis: Vec2, w: Vec3) -> Vec3 {
    if axis == Vec2::X {
        return w;
    }
    let (c, s) = (axis.x, axis.y);
    Vec3::new(c * w.x - s * w.y, s * w.x + c * w.y, w.z)
}

/// A lobe's two roughnesses, clamped (see `clamp_alpha`), in the frame of its axis. With
/// alpha_u = alpha_v every formula below performs the isotropic lobe's operations exactly,
/// so isotropic materials render as they did before anisotropy existed.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Alphas {
    u: f32,
    v: f32,
}

/// 1 / sqrt(pi).
const FRAC_1_SQRT_PI: f32 = 0.564_189_6;

impl Alphas {
    #[inline]
    pub(crate) fn new(alpha_u: f32, alpha_v: f32) -> Alphas {
        Alphas {
            u: clamp_alpha(alpha_u),
            v: clamp_alpha(alpha_v),
        }
    }

    /// D(m) of `distribution` (see `ggx_ndf`, `beckmann_ndf`).
    #[inline]
    pub(crate) fn ndf(&self, distribution: Microfacet, m: Vec3) -> f32 {
        match distribution {
            Microfacet::Ggx => self.ggx_ndf(m),
            Microfacet::Beckmann => self.beckmann_ndf(m),
        }
    }

    /// Smith's G1(w) / w.z of `distribution`, w.z > 0.
    #[inline]
    pub(crate) fn g1_over_cos(&self, distribution: Microfacet, w: Vec3) -> f32 {
        match distribution {
            Microfacet::Ggx => self.ggx_g1_over_cos(w),
            Microfacet::Beckmann => self.beckmann_g1_over_cos(w),
        }
    }

    /// A normal of `distribution` visible from `wo` (wo.z > 0), for the numbers `u`.
    #[inline]
    pub(crate) fn visible_normal(&self, distribution: Microfacet, wo: Vec3, u: Vec2) -> Vec3 {
        match distribution {
            Microfacet::Ggx => self.ggx_visible_normal(wo, u),
            Microfacet::Beckmann => self.beckmann_visible_normal(wo, u),
        }
    }

    /// The roughness in `w`'s azimuth times sin(theta): alpha sin for an isotropic lobe,
    /// sqrt(alpha_u^2 w.x^2 + alpha_v^2 w.y^2) in general.
    #[inline]
    fn projected(&self, w: Vec3) -> f32 {
        if self.u == self.v {
            self.u * (w.x * w.x + w.y * w.y).sqrt()
        } else {
            self.projected2(w).sqrt()
        }
    }

    /// `projected` squared.
    #[inline]
    fn projected2(&self, w: Vec3) -> f32 {
        if self.u == self.v {
            self.u * self.u * (w.x * w.x + w.y * w.y)
        } else {
            self.u * self.u * w.x * w.x + self.v * self.v * w.y * w.y
        }
    }

    /// GGX normal distribution 1 / (pi au av (x^2/au^2 + y^2/av^2 + z^2)^2) for a unit
    /// half-vector `m` with m.z > 0, written as au av / (pi d^2) with d = au av z^2 +
    /// (av/au) x^2 + (au/av) y^2: x^2 + y^2 stands for sin^2 rather than 1 - m.z^2, which
    /// cancels to 0 for tiny alpha.
    #[inline]
    pub(crate) fn ggx_ndf(&self, m: Vec3) -> f32 {
        let a2 = self.u * self.v;
        let d = a2 * m.z * m.z + (self.v / self.u) * m.x * m.x + (self.u / self.v) * m.y * m.y;
        a2 * FRAC_1_PI / (d * d)
    }

    /// Smith G1(w) / w.z for the GGX distribution, w.z > 0:
    /// G1 = 2 / (1 + sqrt(1 + alpha^2 tan^2)), so G1 / cos = 2 / (cos + sqrt(cos^2 + alpha^2
    /// sin^2)) with alpha the roughness in w's azimuth: bounded by 2/alpha even at cos = 0.
    #[inline]
    pub(crate) fn ggx_g1_over_cos(&self, w: Vec3) -> f32 {
        let c2 = w.z * w.z;
        2.0 / (w.z + (c2 + self.projected2(w)).sqrt())
    }

    /// Beckmann normal distribution exp(-(x^2/au^2 + y^2/av^2) / z^2) / (pi au av z^4) for a
    /// unit half-vector `m` with m.z > 0 (x^2 + y^2 for sin^2, see `ggx_ndf`).
    #[inline]
    pub(crate) fn beckmann_ndf(&self, m: Vec3) -> f32 {
        let a2 = self.u * self.v;
        let c2 = m.z * m.z;
        let exponent = ((self.v / self.u) * m.x * m.x + (self.u / self.v) * m.y * m.y) / (a2 * c2);
        // exp(-87) ~ 1e-38: beyond, D is 0 (and a c2 underflowing to 0 would give 0 / 0).
        if exponent >= 87.0 {
            return 0.0;
        }
        (-exponent).exp() * FRAC_1_PI / (a2 * c2 * c2)
    }

    /// Smith G1(w) / w.z for the Beckmann distribution, w.z > 0. With r = alpha sin (alpha in
    /// w's azimuth) and a = cos / r, Lambda = (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi))
    /// and G1 = 1 / (1 + Lambda), so G1 / cos = 2 / (cos (1 + erf(a)) + r exp(-a^2) /
    /// sqrt(pi)): bounded by 2 sqrt(pi) / alpha at cos = 0, and 1 / cos at normal incidence
    /// (a infinite).
    #[inline]
    pub(crate) fn beckmann_g1_over_cos(&self, w: Vec3) -> f32 {
        let r = self.projected(w);
        let a = w.z / r;
        2.0 / (w.z * (1.0 + libm::erff(a)) + r * (-a * a).exp() * FRAC_1_SQRT_PI)
    }

    /// A half-vector from the GGX distribution of normals visible from `wo` (wo.z > 0),
    /// following Heitz 2018: stretch to the alpha = 1 configuration, sample the projected
    /// hemisphere, unstretch.
    pub(crate) fn ggx_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
        let v = Vec3::new(self.u * wo.x, self.v * wo.y, wo.z).normalize();
        // Basis around v; at normal incidence any tangent will do.
        let len2 = v.x * v.x + v.y * v.y;
        let t1 = if len2 > 0.0 {
            Vec3::new(-v.y, v.x, 0.0) / len2.sqrt()
        } else {
            Vec3::X
        };
        let t2 = v.cross(t1);
        // Uniform disk point, its second coordinate squeezed onto the visible part of the
        // hemisphere's projection.
        let r = u.x.sqrt();
        let phi = 2.0 * PI * u.y;
        let p1 = r * phi.cos();
        let mut p2 = r * phi.sin();
        let s = 0.5 * (1.0 + v.z);
        p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
        let nz = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        let n = p1 * t1 + p2 * t2 + nz * v;
        Vec3::new(self.u * n.x, self.v * n.y, n.z.max(0.0)).normalize_or(Vec3::Z)
    }

    /// A half-vector from the Beckmann distribution of normals visible from `wo` (wo.z > 0),
    /// as Heitz and d'Eon 2014 (and Mitsuba's `MicrofacetDistribution::sample`): stretch wo to
    /// the alpha = 1 configuration, draw the slopes visible from there, rotate them to wo's
    /// azimuth and unstretch. In double precision, so the slopes' CDF is inverted to far below
    /// f32's resolution and the sampled density is the pdf's.
    pub(crate) fn beckmann_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
        let v = DVec3::new(
            self.u as f64 * wo.x as f64,
            self.v as f64 * wo.y as f64,
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
        let slope_y = invert_visible_slope_cdf(0.0, u.y as f64);
        let x = (cos_phi * slope_x - sin_phi * slope_y) * self.u as f64;
        let y = (sin_phi * slope_x + cos_phi * slope_y) * self.v as f64;
        DVec3::new(-x, -y, 1.0).normalize().as_vec3()
    }
}

/// sqrt(pi).
const SQRT_PI: f64 = 1.772_453_850_905_516;

/// A slope of a Beckmann microsurface of roughness 1 seen from a direction at polar tangent
/// `tan_theta` and azimuth 0: the s in (-inf, 1/tan_theta] where u of the way through the
/// density exp(-s^2) (1 - s tan_theta) lies (the microfacet normal (-s, ., 1) faces the
/// viewer for s < 1/tan_theta, with projected area in proportion to 1 - s tan_theta). Its CDF
/// is C(s) = sqrt(pi)/2 erfc(-s) + tan_theta/2 exp(-s^2); with `tan_theta` 0 this is the
/// other slope, Gaussian and independent. Newton's method on C, kept inside a bracket that
/// bisection shrinks whenever a step would leave it.
fn invert_visible_slope_cdf(tan_theta: f64, u: f64) -> f64 {
    // Beyond |s| = 8 lies a probability under 1e-28: the search stays inside.
    const LIMIT: f64 = 8.0;
    let cdf = |s: f64| 0.5 * SQRT_PI * libm::erfc(-s) + 0.5 * tan_theta * (-s * s).exp();
    let density = |s: f64| (-s * s).exp() * (1.0 - s * tan_theta);
    let mut lo = -LIMIT;
    let mut hi = if tan_theta > 0.0 {
        (1.0 / tan_theta).min(LIMIT)
    } else {
        LIMIT
    };
    let target = u.clamp(0.0, 1.0) * cdf(hi);
    let mut s = 0.0f64.min(hi);
    for _ in 0..100 {
        let excess = cdf(s) - target;
        if excess < 0.0 {
            lo = s;
        } else {
            hi = s;
        }
        let slope = density(s);
        let newton = s - excess / slope;
        let next = if slope > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - s).abs() <= 1e-12 * (1.0 + s.abs()) {
            return next;
        }
        s = next;
    }
    s
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
                let ours = Alphas { u: alpha, v: alpha }.beckmann_g1_over_cos(w) * w.z;
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
                sum += Alphas { u: a, v: a }.beckmann_ndf(m) as f64 * t.cos() * t.sin();
            }
            let integral =
                sum * std::f64::consts::FRAC_PI_2 / n as f64 * 2.0 * std::f64::consts::PI;
            assert!((integral - 1.0).abs() < 1e-3, "alpha {alpha}: {integral}");
        }
    }

    #[test]
    fn visible_slope_cdf_inverts() {
        for tan_theta in [0.0f64, 0.1, 1.0, 10.0, 1e4] {
            let cdf = |s: f64| 0.5 * SQRT_PI * libm::erfc(-s) + 0.5 * tan_theta * (-s * s).exp();
            let top = if tan_theta > 0.0 {
                (1.0 / tan_theta).min(8.0)
            } else {
                8.0
            };
            for u in [1e-9, 0.01, 0.25, 0.5, 0.75, 0.99, 1.0 - 1e-9] {
                let s = invert_visible_slope_cdf(tan_theta, u);
                assert!(s <= top + 1e-12, "tan {tan_theta} u {u}: {s} beyond {top}");
                let got = cdf(s) / cdf(top);
                assert!(
                    (got - u).abs() < 1e-9,
                    "tan {tan_theta} u {u}: C(s) = {got}"
                );
            }
        }
        // The Gaussian slope's quartiles: erfinv(+-1/2) = +-0.476936.
        assert!((invert_visible_slope_cdf(0.0, 0.75) - 0.476_936_3).abs() < 1e-6);
        assert!((invert_visible_slope_cdf(0.0, 0.25) + 0.476_936_3).abs() < 1e-6);
    }
}
