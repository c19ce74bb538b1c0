//! Rough dielectric as Mitsuba 3 defines it (src/bsdfs/roughdielectric.cpp, after Walter et
//! al. 2007): an interface of relative index eta whose microfacets (GGX or Beckmann, possibly
//! anisotropic) reflect with the dielectric Fresnel term F and refract with 1 - F. With m the
//! generalised half-vector (wo + wi for reflection, wo + eta wi for refraction, turned to +z),
//!
//! f_r = F(wo.m) D(m) G1(wo) G1(wi) / (4 |wo.z| |wi.z|),
//! f_t = s (1 - F) D(m) G1(wo) G1(wi) eta^2 |wo.m| |wi.m| / (|wo.z| |wi.z| (wo.m + eta wi.m)^2),
//!
//! eta the index of wi's side over wo's, s = 1 / eta^2 for radiance and 1 for importance (the
//! adjoint BSDF: radiance is compressed into the denser medium's narrower cone, importance is
//! not), times Mitsuba's `specular_reflectance` and `specular_transmittance`. G1 is zero
//! where a direction would see the back of its microfacet.
//!
//! Sampling draws a normal from the distribution visible from wo (Heitz and d'Eon) and then
//! reflects or refracts about it. Mitsuba chooses the lobe with a third random number against
//! F(wo.m); stagelight's BSDFs take two numbers per bounce, so the lobe is chosen first, with
//! the first number against `reflect_probability(wo)` (the macro-surface's Fresnel term kept
//! within [0.05, 0.95], which depends on wo only), and that number, rescaled, then draws the
//! normal. The estimator stays unbiased with weight F / P_r (or (1 - F) / (1 - P_r)) times
//! G1(wi), bounded by 20 G1(wi); the pdf is the same mixture, so eval / pdf is the weight.
use super::dielectric::{fresnel, fresnel_of_pair};
use super::microfacet::{Distribution, Microfacet, off_axis, onto_axis};
use super::{Bsdf, BsdfSample, TransportMode};
use glam::{Vec2, Vec3};

/// The least probability of either lobe: refraction past the macro-surface's critical angle
/// is still possible on tilted microfacets, and reflection at ior 1.0001 still happens.
const MIN_LOBE_PROBABILITY: f32 = 0.05;

/// Mitsuba's `roughdielectric`: microfacets that reflect and refract.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughDielectric {
    pub distribution: Microfacet,
    /// Roughness along `axis` (see `Conductor::alpha_u`).
    pub alpha_u: f32,
    /// Roughness across `axis`.
    pub alpha_v: f32,
    /// The direction of `alpha_u` in the shading frame (see `Conductor::axis`).
    pub axis: Vec2,
    /// The index inside (the side opposite the geometric normal) over outside.
    pub eta: f32,
    /// Factors on the reflected and the refracted light (Mitsuba's `specular_reflectance`
    /// and `specular_transmittance`, 1 by default).
    pub reflectance: Vec3,
    pub transmittance: Vec3,
}

/// `w` turned to the upper hemisphere as a whole (Mitsuba's `mulsign(w, cos_theta(w))`).
#[inline]
fn upper(w: Vec3) -> Vec3 {
    if w.z < 0.0 { -w } else { w }
}

impl RoughDielectric {
    /// An isotropic interface of roughness `alpha` and relative index `eta`, reflectance and
    /// transmittance 1.
    pub fn isotropic(distribution: Microfacet, alpha: f32, eta: f32) -> RoughDielectric {
        RoughDielectric {
            distribution,
            alpha_u: alpha,
            alpha_v: alpha,
            axis: Vec2::X,
            eta,
            reflectance: Vec3::ONE,
            transmittance: Vec3::ONE,
        }
    }

    /// The larger of the two roughnesses.
    pub fn max_alpha(&self) -> f32 {
        self.alpha_u.max(self.alpha_v)
    }

    /// The probability of choosing reflection when sampling from `wo` (wo.z != 0).
    #[inline]
    pub fn reflect_probability(&self, wo: Vec3) -> f32 {
        fresnel(wo.z, self.eta).clamp(MIN_LOBE_PROBABILITY, 1.0 - MIN_LOBE_PROBABILITY)
    }

    /// (f, pdf) of the pair, in the frame of the lobe's axis.
    #[inline]
    fn value_and_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Vec3, f32) {
        let none = (Vec3::ZERO, 0.0);
        let (wo, wi) = (onto_axis(self.axis, wo), onto_axis(self.axis, wi));
        if wo.z == 0.0 || wi.z == 0.0 {
            return none;
        }
        let reflect = wo.z * wi.z > 0.0;
        // The index of wi's side over wo's.
        let eta = if wo.z > 0.0 { self.eta } else { 1.0 / self.eta };
        let h = if reflect { wo + wi } else { wo + eta * wi };
        let length = h.length();
        if length <= 0.0 || length.is_nan() {
            return none; // refraction straight through an interface of index 1
        }
        let m = upper(h / length);
        let (wo_m, wi_m) = (wo.dot(m), wi.dot(m));
        // Neither direction may see the back of the microfacet (Smith's G1 is zero there).
        if wo_m * wo.z <= 0.0 || wi_m * wi.z <= 0.0 {
            return none;
        }
        let a = Distribution::of(self.distribution, self.alpha_u, self.alpha_v);
        let d = a.ndf(m.into());
        let g_o = a.g1_over_cos(upper(wo).into());
        let g_i = a.g1_over_cos(upper(wi).into());
        let p_r = self.reflect_probability(wo);
        if reflect {
            let f = fresnel(wo_m, self.eta);
            // The visible normals' density G1(wo) |wo.m| D / |wo.z| times the reflection's
            // Jacobian 1 / (4 |wi.m|), with wo.m = wi.m.
            let lobe = 0.25 * g_o * d;
            let pdf = p_r * lobe;
            (self.reflectance * (f * lobe * g_i), pdf)
        } else {
            // wi is wo refracted about m: F from both cosines (see `fresnel_of_pair`).
            let (outside, inside) = if wo.z > 0.0 {
                (wo_m, wi_m)
            } else {
                (wi_m, wo_m)
            };
            let f = fresnel_of_pair(outside.abs(), inside.abs(), self.eta);
            // (wo + eta wi) . m = |h|: the Jacobian's denominator without cancellation.
            let lobe = g_o * wo_m.abs() * d * eta * eta * wi_m.abs() / (length * length);
            let pdf = (1.0 - p_r) * lobe;
            let scale = match mode {
                TransportMode::Radiance => 1.0 / (eta * eta),
                TransportMode::Importance => 1.0,
            };
            (self.transmittance * (scale * (1.0 - f) * lobe * g_i), pdf)
        }
    }
}

impl Bsdf for RoughDielectric {
    const IS_DELTA: bool = false;
    const HAS_DELTA_LOBE: bool = false;
    const TRANSMITS: bool = true;
    const SHADING_SYSTEM: &'static str = "shade_rough_dielectric";

    fn two_sided(&self) -> bool {
        false
    }

    /// f(wo, wi) without the cosine, for light carried as `mode` says.
    fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Vec3 {
        self.value_and_pdf(wo, wi, mode).0
    }

    /// The solid-angle density with which `sample` returns `wi`.
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.value_and_pdf(wo, wi, TransportMode::Radiance).1
    }

    #[inline]
    fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Vec3, f32) {
        self.value_and_pdf(wo, wi, mode)
    }

    /// Samples wi given wo (see the module's comment); `None` where the sample carries nothing.
    fn sample(&self, wo: Vec3, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 || !wo.is_finite() {
            return None;
        }
        let p_r = self.reflect_probability(wo);
        let reflect = u.x < p_r;
        // The first number, rescaled to [0, 1) within the chosen lobe, draws the normal.
        let u_normal = if reflect {
            u.x / p_r
        } else {
            (u.x - p_r) / (1.0 - p_r)
        };
        let u_normal = Vec2::new(u_normal.min(1.0 - f32::EPSILON / 2.0), u.y);
        let on_axis = onto_axis(self.axis, wo);
        let a = Distribution::of(self.distribution, self.alpha_u, self.alpha_v);
        let up = upper(on_axis);
        let m: Vec3 = a
            .visible_normal(up.into(), u_normal.x, u_normal.y, true)
            .into();
        // Turned to wo's side of the surface, m faces wo: wo.m > 0.
        let m = if on_axis.z < 0.0 { -m } else { m };
        let cos_o = on_axis.dot(m);
        let wi = if reflect {
            2.0 * cos_o * m - on_axis
        } else {
            // Snell about m; eta the index of the side entered over the one left.
            let eta = if on_axis.z > 0.0 {
                self.eta
            } else {
                1.0 / self.eta
            };
            let sin2_t = (1.0 - cos_o * cos_o).max(0.0) / (eta * eta);
            if sin2_t >= 1.0 {
                return None; // total internal reflection: F = 1, the refraction carries nothing
            }
            let cos_t = (1.0 - sin2_t).sqrt();
            (-on_axis / eta + (cos_o / eta - cos_t) * m).normalize()
        };
        // A reflection below the surface or a refraction back above it is masked (Mitsuba's
        // G1(wi) is zero there); rejecting them keeps each side's density a single lobe's.
        if !wi.is_finite() || (wi.z * on_axis.z > 0.0) != reflect || wi.z == 0.0 {
            return None;
        }
        let wi = off_axis(self.axis, wi);
        // Value and pdf from the same code as eval/pdf so that MIS sees identical densities.
        let (value, pdf) = self.value_and_pdf(wo, wi, mode);
        BsdfSample::of_lobe(wi, value, pdf)
    }
}
