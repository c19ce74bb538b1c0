//! Smooth plastic as Mitsuba 3 defines it (src/bsdfs/plastic.cpp): a smooth dielectric coat
//! (relative index eta = int_ior / ext_ior) over a Lambertian base. Light either reflects off
//! the coat, a delta lobe of weight `specular` F(wo.z), or enters through it, scatters in the
//! base and between base and coat, and leaves again:
//!
//! f_diffuse = diffuse / (1 - F_dr) / (pi eta^2) (1 - F(wo.z)) (1 - F(wi.z)),
//!
//! with F the coat's Fresnel term and F_dr Mitsuba's fit of the coat's diffuse reflectance
//! from inside (`fresnel_diffuse_reflectance(1 / eta)`, up to eta 3, where the fit fails, the
//! integral itself beyond: `internal_reflectance`; `nonlinear`: diffuse F_dr instead, the
//! colour shift of repeated bounces). Sampling picks the specular lobe with probability
//! F(wo.z) w_s against (1 - F(wo.z)) (1 - w_s), w_s the specular share of the two
//! reflectances' means, then the cosine for the diffuse lobe. One-sided: black from behind
//! the shading normal.
//!
//! The first material with a delta lobe and a non-delta one: its kind is not delta (light
//! sampling and connections reach it, and `eval`/`pdf` are the diffuse lobe's alone, the
//! pdf times the probability of choosing that lobe), while `sample` says `delta: true` when
//! it picks the reflection. Each integrator keys its delta rules on that per-sample flag.

use super::dielectric::fresnel;
use super::{Bsdf, BsdfSample, TransportMode};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Smallest cosine the delta lobe's value divides by (as the smooth dielectric's).
const COS_FLOOR: f32 = 1e-20;

/// Mitsuba's `plastic`: a delta reflection off a smooth coat over a Lambertian base, a
/// delta lobe and a non-delta one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmoothPlastic {
    /// Relative index of the coat (inside over outside).
    pub eta: f32,
    /// The base's reflectance (Mitsuba's `diffuse_reflectance`).
    pub diffuse: Vec3,
    /// A factor on the specular lobe (Mitsuba's `specular_reflectance`, 1 by default).
    pub specular: Vec3,
    /// The specular share of the sampling: mean(specular) / (mean(diffuse) + mean(specular)).
    pub specular_weight: f32,
    /// The coat's diffuse reflectance from inside, Mitsuba's fit at 1 / eta.
    pub internal_reflectance: f32,
    /// Mitsuba's `nonlinear`.
    pub nonlinear: bool,
    /// Reflects on both sides (Mitsuba's `twosided`; see `Conductor::two_sided`).
    pub two_sided: bool,
}

/// Mitsuba's `fresnel_diffuse_reflectance(eta)`: the Fresnel reflectance over the
/// cosine-weighted hemisphere of an interface of relative index `eta`, by Egan and Hilgeman's
/// fit where eta < 1 and d'Eon and Irving's elsewhere (fresnel.h), coefficients as Mitsuba's.
pub fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    let inv = 1.0 / eta;
    if eta < 1.0 {
        0.0636 * inv + eta * (eta * -1.4399 + 0.7099) + 0.6681
    } else {
        let c = [
            0.919_317f32,
            -3.4793,
            6.753_35,
            -7.809_89,
            4.985_54,
            -1.368_81,
        ];
        c.iter().rev().fold(0.0, |acc, &k| acc * inv + k)
    }
}

/// Relative indices above this take the coat's internal reflectance from the integral itself
/// rather than Mitsuba's fit: the fit's error grows past 2 (9.5% up to 5, fresnel.h says) and
/// it reaches 1 at about 3.85, where 1 / (1 - F_dr) makes Mitsuba's diffuse lobe infinite, then
/// negative. Below, Mitsuba's values exactly.
pub const FIT_MAX_ETA: f32 = 3.0;

/// The coat's diffuse reflectance from inside, F_dr = 2 int_0^1 F(mu) mu dmu with F the
/// Fresnel term from inside: Mitsuba's fit up to `FIT_MAX_ETA`, then the integral (midpoints,
/// 4096 cosines; total internal reflection makes the integrand's kink at the critical angle
/// the only error, well under 1e-4).
pub fn internal_reflectance(eta: f32) -> f32 {
    if eta <= FIT_MAX_ETA {
        return fresnel_diffuse_reflectance(1.0 / eta);
    }
    const N: usize = 4096;
    let sum: f64 = (0..N)
        .map(|i| {
            let mu = (i as f64 + 0.5) / N as f64;
            2.0 * mu * f64::from(fresnel(-(mu as f32), eta))
        })
        .sum();
    (sum / N as f64) as f32
}

impl SmoothPlastic {
    /// A smooth plastic; `diffuse_mean` is the mean of the base's reflectance (a texture's
    /// where it is textured, `diffuse` the value the texture stands in for).
    pub fn new(
        eta: f32,
        diffuse: Vec3,
        diffuse_mean: f32,
        specular: Vec3,
        nonlinear: bool,
    ) -> SmoothPlastic {
        let specular_mean = (specular.x + specular.y + specular.z) / 3.0;
        SmoothPlastic {
            eta,
            diffuse,
            specular,
            specular_weight: specular_mean / (diffuse_mean + specular_mean),
            internal_reflectance: internal_reflectance(eta),
            nonlinear,
            two_sided: false,
        }
    }

    /// The probability with which `sample` picks the specular lobe from `wo` (wo.z > 0).
    #[inline]
    pub fn specular_probability(&self, wo_z: f32) -> f32 {
        let f = fresnel(wo_z, self.eta);
        let specular = f * self.specular_weight;
        let diffuse = (1.0 - f) * (1.0 - self.specular_weight);
        let sum = specular + diffuse;
        if sum > 0.0 { specular / sum } else { 0.0 }
    }
}

impl Bsdf for SmoothPlastic {
    const IS_DELTA: bool = false;
    const HAS_DELTA_LOBE: bool = true;
    const TRANSMITS: bool = false;
    const SHADING_SYSTEM: &'static str = "shade_plastic";

    fn two_sided(&self) -> bool {
        self.two_sided
    }

    /// The diffuse lobe's f(wo, wi) without the cosine; zero unless both lie strictly above
    /// the surface. (The specular lobe is a delta: `sample` alone returns it.)
    fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Vec3 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Vec3::ZERO;
        }
        let inside = if self.nonlinear {
            self.diffuse * self.internal_reflectance
        } else {
            Vec3::splat(self.internal_reflectance)
        };
        let coat = (1.0 - fresnel(wo.z, self.eta)) * (1.0 - fresnel(wi.z, self.eta));
        self.diffuse / (Vec3::ONE - inside) * (FRAC_1_PI / (self.eta * self.eta) * coat)
    }

    /// The solid-angle density with which `sample` returns `wi` by the diffuse lobe.
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        (1.0 - self.specular_probability(wo.z)) * wi.z * FRAC_1_PI
    }

    /// Picks the specular lobe (the mirror direction, `delta: true`, weight specular F / its
    /// probability) or the diffuse one (the cosine); one number chooses, then is stretched back
    /// to [0, 1) for the direction. `None` when wo is not above the surface.
    fn sample(&self, wo: Vec3, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let p = self.specular_probability(wo.z);
        if u.x < p {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            let f = fresnel(wo.z, self.eta);
            return Some(BsdfSample {
                wi,
                value: self.specular * (f / wo.z.max(COS_FLOOR)),
                pdf: p,
                delta: true,
            });
        }
        let u = Vec2::new(((u.x - p) / (1.0 - p)).min(1.0 - f32::EPSILON), u.y);
        let wi = crate::sampling::cosine_hemisphere(u);
        if wi.z <= 0.0 {
            return None;
        }
        let pdf = (1.0 - p) * wi.z * FRAC_1_PI;
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        Some(BsdfSample {
            wi,
            value: self.eval(wo, wi, mode),
            pdf,
            delta: false,
        })
    }
}
