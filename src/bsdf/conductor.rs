//! Rough conductors as Mitsuba 3 defines them (src/bsdfs/roughconductor.cpp and conductor.cpp):
//! a microfacet reflector, GGX or Beckmann, whose Fresnel term is that of a conductor of
//! complex index of refraction eta + i k per RGB channel, times `reflectance` (Mitsuba's
//! `specular_reflectance`).
//!
//! f = R F(wo.h) D(h) G1(wo) G1(wi) / (4 wo.z wi.z), sampled with the distribution of visible
//! normals, pdf = G1(wo) D(h) / (4 wo.z). Both are written with the bounded ratio G1(w) / w.z,
//! which tends to a finite limit in the tangent plane instead of forming 0/0.
//!
//! Beckmann's G1 is Smith's exact one (through erf). Mitsuba evaluates it with a rational
//! approximation (within 0.35%, include/mitsuba/render/microfacet.h) but samples the exact
//! visible normals, so its sampled density and its pdf differ by up to that much; with the
//! exact G1 here they agree, and images differ from Mitsuba's by far less than noise.
use super::BsdfSample;
use glam::{DVec3, Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// Smallest roughness used (Mitsuba clamps alpha to the same 1e-4). Directions in f32 carry
/// errors of ~1e-7, and the lobe's width in half-vector space is ~alpha, so D evaluated at a
/// half-vector rebuilt from (wo, wi) is accurate to ~1e-7/alpha: below 1e-4 `eval` and `pdf`
/// would no longer match what `sample` drew. The peak values also stay modest:
/// D <= 1/(pi alpha^2) ~ 3e7 and f <= R/(pi alpha^4) ~ 3e15.
pub const ALPHA_MIN: f32 = 1e-4;

/// The microfacet normal distribution of a rough conductor (Mitsuba's `distribution`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Microfacet {
    /// Trowbridge-Reitz.
    Ggx,
    /// Gaussian slopes: Mitsuba's default for `roughconductor`.
    Beckmann,
}

/// A conductor's complex index of refraction eta + i k, per RGB channel, relative to the
/// medium outside (Mitsuba's `eta` and `k`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ComplexIor {
    pub eta: Vec3,
    pub k: Vec3,
}

impl ComplexIor {
    /// Mitsuba's material "none" (eta 0, k 1), for which `fresnel` is exactly 1 at every
    /// angle: a Fresnel factor of 1, the RON format's conductor.
    pub const PERFECT_MIRROR: ComplexIor = ComplexIor {
        eta: Vec3::ZERO,
        k: Vec3::ONE,
    };
}

/// A rough conductor: what `Material::Conductor` holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conductor {
    pub distribution: Microfacet,
    /// Roughness (the slopes' scale) along `axis`; below ALPHA_MIN it is taken as ALPHA_MIN.
    pub alpha_u: f32,
    /// Roughness across `axis`: equal to `alpha_u` for an isotropic lobe.
    pub alpha_v: f32,
    /// The direction of `alpha_u` in the shading frame's tangent plane, (cos, sin) of its
    /// angle from the frame's first tangent: Mitsuba's uv tangent (dp/du) as the frame in
    /// which eval and sample run sees it. Exactly (1, 0) unless the lobe is anisotropic, and
    /// then the directions are turned by it (see `PreparedScene::material_at`).
    pub axis: Vec2,
    /// A factor on the Fresnel term (Mitsuba's `specular_reflectance`).
    pub reflectance: Vec3,
    pub ior: ComplexIor,
}

impl Conductor {
    /// An isotropic lobe of roughness `alpha`.
    pub fn isotropic(
        distribution: Microfacet,
        alpha: f32,
        reflectance: Vec3,
        ior: ComplexIor,
    ) -> Conductor {
        Conductor {
            distribution,
            alpha_u: alpha,
            alpha_v: alpha,
            axis: Vec2::X,
            reflectance,
            ior,
        }
    }

    /// A GGX lobe whose Fresnel factor is 1, scaled by `reflectance`: the RON format's
    /// `Conductor`, and Mitsuba's `roughconductor` of material "none" with distribution ggx.
    pub fn ggx(alpha: f32, reflectance: Vec3) -> Conductor {
        Conductor::isotropic(
            Microfacet::Ggx,
            alpha,
            reflectance,
            ComplexIor::PERFECT_MIRROR,
        )
    }

    /// The larger of the two roughnesses (what decides whether the lobe is nearly a mirror).
    pub fn max_alpha(&self) -> f32 {
        self.alpha_u.max(self.alpha_v)
    }

    /// `w` in the frame whose first tangent is `axis` (identity for isotropic lobes).
    #[inline]
    fn onto_axis(&self, w: Vec3) -> Vec3 {
        if self.axis == Vec2::X {
            return w;
        }
        let (c, s) = (self.axis.x, self.axis.y);
        Vec3::new(c * w.x + s * w.y, c * w.y - s * w.x, w.z)
    }

    /// The inverse of `onto_axis`.
    #[inline]
    fn off_axis(&self, w: Vec3) -> Vec3 {
        if self.axis == Vec2::X {
            return w;
        }
        let (c, s) = (self.axis.x, self.axis.y);
        Vec3::new(c * w.x - s * w.y, s * w.x + c * w.y, w.z)
    }

    /// f(wo, wi) without the cosine; zero unless both lie strictly above the surface.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.eval_pdf(wo, wi).0
    }

    /// The solid-angle density with which `sample` returns `wi`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(wo, wi).1
    }

    /// (f, pdf) for a reflection pair; zero unless both lie strictly above the surface.
    #[inline]
    fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
        let (wo, wi) = (self.onto_axis(wo), self.onto_axis(wi));
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Vec3::ZERO, 0.0);
        }
        let h = wo + wi;
        // Both above the surface: h.z > 0 and |h| >= h.z, so normalising is safe.
        let h = h / h.length();
        let a = Alphas::of(self);
        let (d, go, gi) = match self.distribution {
            Microfacet::Ggx => (a.ggx_ndf(h), a.ggx_g1_over_cos(wo), a.ggx_g1_over_cos(wi)),
            Microfacet::Beckmann => (
                a.beckmann_ndf(h),
                a.beckmann_g1_over_cos(wo),
                a.beckmann_g1_over_cos(wi),
            ),
        };
        // The pdf's (wo.h) factors cancel: D_wo(h) / (4 wo.h) = G1(wo) D(h) / (4 wo.z).
        let pdf = 0.25 * go * d;
        let reflectance = if self.ior == ComplexIor::PERFECT_MIRROR {
            // Skips a Fresnel factor of exactly 1, so the RON conductor is what it always was.
            self.reflectance
        } else {
            self.reflectance * fresnel(wo.dot(h), self.ior)
        };
        (reflectance * (pdf * gi), pdf)
    }

    /// Samples wi given wo by the distribution of visible normals; `None` when wo is not
    /// above the surface or the reflected direction is not (the microsurface masks it).
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let on_axis = self.onto_axis(wo);
        let a = Alphas::of(self);
        let h = match self.distribution {
            Microfacet::Ggx => a.ggx_visible_normal(on_axis, u),
            Microfacet::Beckmann => a.beckmann_visible_normal(on_axis, u),
        };
        let wi = 2.0 * on_axis.dot(h) * h - on_axis;
        if wi.z <= 0.0 {
            return None; // reflected below the surface: masked
        }
        let wi = self.off_axis(wi.normalize());
        // Value and pdf from the same code as eval/pdf so that MIS sees identical densities.
        let (value, pdf) = self.eval_pdf(wo, wi);
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        Some(BsdfSample {
            wi,
            value,
            pdf,
            delta: false,
        })
    }
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

/// Unpolarised Fresnel reflectance of a conductor, per channel, for light meeting the
/// (micro)surface at cosine `cos_i`: Mitsuba's `fresnel_conductor`
/// (include/mitsuba/render/fresnel.h, after Moeller's "Optics"), which its RGB variants
/// evaluate on the three channels' eta and k. At normal incidence it is
/// ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2); at grazing incidence 1.
pub fn fresnel(cos_i: f32, ior: ComplexIor) -> Vec3 {
    let c = cos_i.clamp(0.0, 1.0);
    Vec3::new(
        fresnel_channel(c, ior.eta.x, ior.k.x),
        fresnel_channel(c, ior.eta.y, ior.k.y),
        fresnel_channel(c, ior.eta.z, ior.k.z),
    )
}

/// `fresnel` of one channel, for `cos_i` in [0, 1].
#[inline]
fn fresnel_channel(cos_i: f32, eta: f32, k: f32) -> f32 {
    let cos2 = cos_i * cos_i;
    let sin2 = 1.0 - cos2;
    let sin4 = sin2 * sin2;
    let t = eta * eta - k * k - sin2;
    // a^2 + b^2 and a, where a + i b is the complex cosine of the transmitted angle times eta.
    let a2_plus_b2 = (t * t + 4.0 * k * k * eta * eta).max(0.0).sqrt();
    let a = (0.5 * (a2_plus_b2 + t)).max(0.0).sqrt();
    let term1 = a2_plus_b2 + cos2;
    let term2 = 2.0 * cos_i * a;
    // term1 + term2 vanishes only at grazing incidence with eta 1 and k 0 (no interface at
    // all), term3 + term4 only at normal incidence with eta = k = 0: the limits there are 1
    // and r_s, which avoids 0/0.
    let r_s = if term1 + term2 > 0.0 {
        (term1 - term2) / (term1 + term2)
    } else {
        1.0
    };
    let term3 = a2_plus_b2 * cos2 + sin4;
    let term4 = term2 * sin2;
    let r_p = if term3 + term4 > 0.0 {
        r_s * (term3 - term4) / (term3 + term4)
    } else {
        r_s
    };
    0.5 * (r_s + r_p)
}

/// A lobe's two roughnesses, clamped (see `clamp_alpha`), in the frame of its axis. With
/// alpha_u = alpha_v every formula below performs the isotropic lobe's operations exactly,
/// so isotropic materials render as they did before anisotropy existed.
#[derive(Clone, Copy, Debug)]
struct Alphas {
    u: f32,
    v: f32,
}

/// 1 / sqrt(pi).
const FRAC_1_SQRT_PI: f32 = 0.564_189_6;

impl Alphas {
    #[inline]
    fn of(c: &Conductor) -> Alphas {
        Alphas {
            u: clamp_alpha(c.alpha_u),
            v: clamp_alpha(c.alpha_v),
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
    fn ggx_ndf(&self, m: Vec3) -> f32 {
        let a2 = self.u * self.v;
        let d = a2 * m.z * m.z + (self.v / self.u) * m.x * m.x + (self.u / self.v) * m.y * m.y;
        a2 * FRAC_1_PI / (d * d)
    }

    /// Smith G1(w) / w.z for the GGX distribution, w.z > 0:
    /// G1 = 2 / (1 + sqrt(1 + alpha^2 tan^2)), so G1 / cos = 2 / (cos + sqrt(cos^2 + alpha^2
    /// sin^2)) with alpha the roughness in w's azimuth: bounded by 2/alpha even at cos = 0.
    #[inline]
    fn ggx_g1_over_cos(&self, w: Vec3) -> f32 {
        let c2 = w.z * w.z;
        2.0 / (w.z + (c2 + self.projected2(w)).sqrt())
    }

    /// Beckmann normal distribution exp(-(x^2/au^2 + y^2/av^2) / z^2) / (pi au av z^4) for a
    /// unit half-vector `m` with m.z > 0 (x^2 + y^2 for sin^2, see `ggx_ndf`).
    #[inline]
    fn beckmann_ndf(&self, m: Vec3) -> f32 {
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
    fn beckmann_g1_over_cos(&self, w: Vec3) -> f32 {
        let r = self.projected(w);
        let a = w.z / r;
        2.0 / (w.z * (1.0 + libm::erff(a)) + r * (-a * a).exp() * FRAC_1_SQRT_PI)
    }

    /// A half-vector from the GGX distribution of normals visible from `wo` (wo.z > 0),
    /// following Heitz 2018: stretch to the alpha = 1 configuration, sample the projected
    /// hemisphere, unstretch.
    fn ggx_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
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
    fn beckmann_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
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

    /// ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2), the normal-incidence reflectance.
    fn normal_incidence(eta: f64, k: f64) -> f64 {
        ((eta - 1.0).powi(2) + k * k) / ((eta + 1.0).powi(2) + k * k)
    }

    /// The Fresnel equations with complex arithmetic, independent of Moeller's real form:
    /// r_s = (cos - n cos_t) / (cos + n cos_t), r_p = (n cos - cos_t) / (n cos + cos_t),
    /// n cos_t = sqrt(n^2 - sin^2) for complex n = eta + i k.
    fn fresnel_complex(cos: f64, eta: f64, k: f64) -> f64 {
        type C = (f64, f64);
        let mul = |a: C, b: C| (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
        let div = |a: C, b: C| {
            let d = b.0 * b.0 + b.1 * b.1;
            ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
        };
        let sqrt = |a: C| {
            let r = (a.0 * a.0 + a.1 * a.1).sqrt();
            let re = (0.5 * (r + a.0)).max(0.0).sqrt();
            let im = (0.5 * (r - a.0)).max(0.0).sqrt().copysign(a.1);
            (re, im)
        };
        let n = (eta, k);
        let n2 = mul(n, n);
        let sin2 = 1.0 - cos * cos;
        let n_cos_t = sqrt((n2.0 - sin2, n2.1));
        let r_s = div((cos - n_cos_t.0, -n_cos_t.1), (cos + n_cos_t.0, n_cos_t.1));
        // n cos_t over n (cos_t) needs cos_t = n_cos_t / n.
        let cos_t = div(n_cos_t, n);
        let n_cos = (eta * cos, k * cos);
        let r_p = div(
            (n_cos.0 - cos_t.0, n_cos.1 - cos_t.1),
            (n_cos.0 + cos_t.0, n_cos.1 + cos_t.1),
        );
        let norm2 = |a: C| a.0 * a.0 + a.1 * a.1;
        0.5 * (norm2(r_s) + norm2(r_p))
    }

    #[test]
    fn fresnel_at_normal_incidence_is_the_textbook_value() {
        // Mitsuba's Au and Cu (RGB) and a few others.
        for (eta, k) in [
            (0.143_036, 3.983),
            (1.442_045, 1.603_359),
            (0.201_005, 3.913_262),
            (1.5, 0.0),
            (2.0, 1.0),
            (0.2, 1.5),
        ] {
            let got = fresnel_channel(1.0, eta as f32, k as f32) as f64;
            let want = normal_incidence(eta, k);
            assert!(
                (got - want).abs() < 2e-6,
                "eta {eta} k {k}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn fresnel_matches_the_complex_fresnel_equations_at_every_angle() {
        for (eta, k) in [
            (0.143, 3.983),
            (1.44, 1.6),
            (0.27, 2.78),
            (1.5, 0.0),
            (3.0, 0.5),
        ] {
            for i in 0..=90 {
                let cos = (i as f64).to_radians().cos();
                let got = fresnel_channel(cos as f32, eta as f32, k as f32) as f64;
                let want = fresnel_complex(cos, eta, k);
                assert!(
                    (got - want).abs() < 1e-5,
                    "eta {eta} k {k} theta {i}: {got} vs {want}"
                );
            }
            // Grazing incidence reflects everything.
            assert!((fresnel_channel(0.0, eta as f32, k as f32) - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn fresnel_of_the_perfect_mirror_is_exactly_one() {
        // What `eval` skips: Mitsuba's material "none" gives 1 through the formula too.
        for i in 0..=10_000 {
            let c = i as f32 / 10_000.0;
            assert_eq!(fresnel_channel(c, 0.0, 1.0), 1.0, "cos {c}");
        }
        assert_eq!(fresnel(0.3, ComplexIor::PERFECT_MIRROR), Vec3::ONE);
    }

    #[test]
    fn fresnel_degenerate_indices_stay_finite() {
        for (eta, k) in [(0.0, 0.0), (1.0, 0.0), (1e4, 1e4), (0.0, 1e4), (1e4, 0.0)] {
            for c in [0.0f32, 1e-20, 1e-7, 0.5, 1.0] {
                let f = fresnel_channel(c, eta, k);
                assert!((0.0..=1.0).contains(&f), "eta {eta} k {k} cos {c}: {f}");
            }
        }
        assert_eq!(fresnel_channel(1.0, 0.0, 0.0), 1.0);
        assert_eq!(fresnel_channel(0.0, 1.0, 0.0), 1.0);
    }

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
    fn beckmann_ndf_integrates_to_one_over_projected_area() {
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
