//! Rough conductors as Mitsuba 3 defines them (src/bsdfs/roughconductor.cpp and conductor.cpp):
//! a microfacet reflector, GGX or Beckmann, whose Fresnel term is that of a conductor of
//! complex index of refraction eta + i k per RGB channel, times `reflectance` (Mitsuba's
//! `specular_reflectance`).
//!
//! f = R F(wo.h) D(h) G1(wo) G1(wi) / (4 wo.z wi.z), sampled with the distribution of visible
//! normals, pdf = G1(wo) D(h) / (4 wo.z). Both are written with the bounded ratio G1(w) / w.z,
//! which tends to a finite limit in the tangent plane instead of forming 0/0.
//! The microfacet maths (src/bsdf/microfacet.rs) is Mitsuba's up to Beckmann's exact G1, which
//! moves images by far less than noise.
pub use super::microfacet::{ALPHA_MIN, Microfacet};
use super::microfacet::{Axis, Distribution};
use super::{Bsdf, BsdfSample, LobeSample, TransportMode};
use crate::lanes::{F, Mask, Real, V3};
use glam::{Vec2, Vec3};

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

/// Rough conductor (GGX or Beckmann microfacets, possibly anisotropic): a conductor's Fresnel
/// term times a reflectance, or the reflectance alone.
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
    /// Reflects on both sides (Mitsuba's `twosided`): the engine turns the shading frame to
    /// the side a ray arrives from, as for Lambertian surfaces.
    pub two_sided: bool,
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
            two_sided: false,
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

    /// The lobe for one path.
    #[inline(always)]
    fn lobe(&self) -> ConductorLobe<f32> {
        ConductorLobe::gather(&[*self])
    }
}

impl Bsdf for Conductor {
    const IS_DELTA: bool = false;
    const HAS_DELTA_LOBE: bool = false;
    const TRANSMITS: bool = false;
    const SHADING_SYSTEM: &'static str = "shade_conductor";

    fn two_sided(&self) -> bool {
        self.two_sided
    }

    /// f(wo, wi) without the cosine; zero unless both lie strictly above the surface.
    fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Vec3 {
        self.lobe().eval_pdf(wo.into(), wi.into()).0.into()
    }

    /// The solid-angle density with which `sample` returns `wi`.
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.lobe().eval_pdf(wo.into(), wi.into()).1
    }

    #[inline]
    fn eval_pdf(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> (Vec3, f32) {
        let (f, pdf) = self.lobe().eval_pdf(wo.into(), wi.into());
        (f.into(), pdf)
    }

    /// Samples wi given wo by the distribution of visible normals; `None` when wo is not
    /// above the surface or the reflected direction is not (the microsurface masks it).
    fn sample(&self, wo: Vec3, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        self.lobe().sample(wo.into(), u.x, u.y).one()
    }

    const IN_LANES: bool = true;

    #[inline(always)]
    fn sample_lanes<const N: usize>(
        materials: &[Self; N],
        wo: V3<F<N>>,
        ux: F<N>,
        uy: F<N>,
    ) -> LobeSample<F<N>> {
        ConductorLobe::gather(materials).sample(wo, ux, uy)
    }

    #[inline(always)]
    fn eval_pdf_lanes<const N: usize>(
        materials: &[Self; N],
        wo: V3<F<N>>,
        wi: V3<F<N>>,
    ) -> (V3<F<N>>, F<N>) {
        ConductorLobe::gather(materials).eval_pdf(wo, wi)
    }
}

/// A conductor's lobe for one path (`f32`) or lanes (`F<N>`): the maths of `eval`, `pdf` and
/// `sample`, written once over `Real` (docs/architecture.md, "Writing a material once for one
/// path and for lanes").
#[derive(Clone, Copy)]
pub struct ConductorLobe<T: Real> {
    distribution: Distribution<T>,
    axis: Axis<T>,
    reflectance: V3<T>,
    eta: V3<T>,
    k: V3<T>,
    /// Where the Fresnel factor is exactly 1 (`ComplexIor::PERFECT_MIRROR`): skipped, so the
    /// RON conductor is what it always was.
    mirror: T::Mask,
}

impl<T: Real> ConductorLobe<T> {
    /// Lane `l`'s lobe is `conductors[l]`'s.
    #[inline(always)]
    pub fn gather(conductors: &[Conductor]) -> ConductorLobe<T> {
        let c = |l: usize| &conductors[l];
        ConductorLobe {
            distribution: Distribution::new(
                T::Mask::lanes(|l| c(l).distribution == Microfacet::Beckmann),
                T::lanes(|l| c(l).alpha_u),
                T::lanes(|l| c(l).alpha_v),
            ),
            axis: Axis::new(T::lanes(|l| c(l).axis.x), T::lanes(|l| c(l).axis.y)),
            reflectance: V3::lanes(|l| c(l).reflectance),
            eta: V3::lanes(|l| c(l).ior.eta),
            k: V3::lanes(|l| c(l).ior.k),
            mirror: T::Mask::lanes(|l| c(l).ior == ComplexIor::PERFECT_MIRROR),
        }
    }

    /// (f, pdf) for a reflection pair; zero unless both lie strictly above the surface.
    #[inline(always)]
    pub fn eval_pdf(&self, wo: V3<T>, wi: V3<T>) -> (V3<T>, T) {
        let zero = T::splat(0.0);
        let none = (V3::splat(Vec3::ZERO), zero);
        let (wo, wi) = (self.axis.onto(wo), self.axis.onto(wi));
        let above = wo.z.greater(zero) & wi.z.greater(zero);
        if !above.any() {
            return none;
        }
        let h = wo + wi;
        // Both above the surface: h.z > 0 and |h| >= h.z, so normalising is safe.
        let h = h / h.length();
        let m = &self.distribution;
        let (d, go, gi) = (m.ndf(h), m.g1_over_cos(wo), m.g1_over_cos(wi));
        // The pdf's (wo.h) factors cancel: D_wo(h) / (4 wo.h) = G1(wo) D(h) / (4 wo.z).
        let pdf = T::splat(0.25) * go * d;
        let reflectance = V3::select_with(
            self.mirror,
            || self.reflectance,
            || self.reflectance * fresnel_of(wo.dot(h), self.eta, self.k),
        );
        (
            V3::select(above, reflectance * (pdf * gi), none.0),
            T::select(above, pdf, zero),
        )
    }

    /// A direction by the distribution of visible normals, valid where wo and the reflected
    /// direction are above the surface (below, the microsurface masks it).
    #[inline(always)]
    pub fn sample(&self, wo: V3<T>, ux: T, uy: T) -> LobeSample<T> {
        let zero = T::splat(0.0);
        let facing = wo.z.greater(zero);
        if !facing.any() {
            return LobeSample::none();
        }
        let on_axis = self.axis.onto(wo);
        let h = self.distribution.visible_normal(on_axis, ux, uy, facing);
        let wi = h * (T::splat(2.0) * on_axis.dot(h)) - on_axis;
        let kept = facing & wi.z.greater(zero);
        let wi = self.axis.off(wi.normalize());
        // Value and pdf from the same code as eval/pdf so that MIS sees identical densities.
        let (value, pdf) = self.eval_pdf(wo, wi);
        LobeSample::of_lobe(kept, wi, value, pdf)
    }
}

/// Unpolarised Fresnel reflectance of a conductor, per channel, for light meeting the
/// (micro)surface at cosine `cos_i`: Mitsuba's `fresnel_conductor`
/// (include/mitsuba/render/fresnel.h, after Moeller's "Optics"), which its RGB variants
/// evaluate on the three channels' eta and k. At normal incidence it is
/// ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2); at grazing incidence 1.
pub fn fresnel(cos_i: f32, ior: ComplexIor) -> Vec3 {
    fresnel_of(cos_i, ior.eta.into(), ior.k.into()).into()
}

/// `fresnel` for one path or lanes.
#[inline(always)]
fn fresnel_of<T: Real>(cos_i: T, eta: V3<T>, k: V3<T>) -> V3<T> {
    // f32::clamp(0, 1), NaN kept.
    let c = T::select(
        cos_i.less(T::splat(0.0)),
        T::splat(0.0),
        T::select(cos_i.greater(T::splat(1.0)), T::splat(1.0), cos_i),
    );
    V3::new(
        fresnel_channel(c, eta.x, k.x),
        fresnel_channel(c, eta.y, k.y),
        fresnel_channel(c, eta.z, k.z),
    )
}

/// `fresnel` of one channel, for `cos_i` in [0, 1].
#[inline(always)]
fn fresnel_channel<T: Real>(cos_i: T, eta: T, k: T) -> T {
    let (zero, one) = (T::splat(0.0), T::splat(1.0));
    let cos2 = cos_i * cos_i;
    let sin2 = one - cos2;
    let sin4 = sin2 * sin2;
    let t = eta * eta - k * k - sin2;
    // a^2 + b^2 and a, where a + i b is the complex cosine of the transmitted angle times eta.
    let a2_plus_b2 = (t * t + T::splat(4.0) * k * k * eta * eta).max(zero).sqrt();
    let a = ((a2_plus_b2 + t) * 0.5).max(zero).sqrt();
    let term1 = a2_plus_b2 + cos2;
    let term2 = T::splat(2.0) * cos_i * a;
    // term1 + term2 vanishes only at grazing incidence with eta 1 and k 0 (no interface at
    // all), term3 + term4 only at normal incidence with eta = k = 0: the limits there are 1
    // and r_s, which avoids 0/0.
    let r_s = T::select(
        (term1 + term2).greater(zero),
        (term1 - term2) / (term1 + term2),
        one,
    );
    let term3 = a2_plus_b2 * cos2 + sin4;
    let term4 = term2 * sin2;
    let r_p = T::select(
        (term3 + term4).greater(zero),
        r_s * (term3 - term4) / (term3 + term4),
        r_s,
    );
    (r_s + r_p) * 0.5
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
}
