//! Rough plastic as Mitsuba 3 defines it (src/bsdfs/roughplastic.cpp): a rough dielectric
//! coat (GGX or Beckmann, isotropic roughness, relative index eta = int_ior / ext_ior) over a
//! Lambertian base. Light either reflects off the coat's microfacets (a glossy lobe scaled by
//! the dielectric Fresnel term and `specular`) or enters through it, scatters in the base and
//! between base and coat, and leaves again:
//!
//! f = specular F(wo.h) D(h) G1(wo) G1(wi) / (4 wo.z wi.z)
//!   + diffuse / (1 - R_i) / (pi eta^2) T(wo.z) T(wi.z),
//!
//! with T(cos) the coat's transmittance from outside (all the light a rough dielectric
//! refracts, by quadrature over its visible normals) and R_i its reflectance from inside
//! averaged over the cosine-weighted hemisphere (`nonlinear`: diffuse R_i instead, Mitsuba's
//! colour shift of repeated bounces). Both are tabulated once per (distribution, alpha, eta)
//! as Mitsuba tabulates them: T at 64 cosines, linearly interpolated. Sampling picks the glossy
//! lobe with probability (1 - T(wo.z)) w_s against T(wo.z) (1 - w_s), w_s the specular share of
//! the two reflectances' means, then visible normals or the cosine. One-sided: black from
//! behind the shading normal.

use super::conductor::Microfacet;
use super::dielectric::fresnel;
use super::microfacet::Alphas;
use super::{Bsdf, BsdfSample, TransportMode};
use glam::{Vec2, Vec3};
use std::collections::HashMap;
use std::f32::consts::FRAC_1_PI;
use std::sync::{Mutex, OnceLock};

/// Cosines at which the coat's transmittance is tabulated (Mitsuba's
/// MI_ROUGH_TRANSMITTANCE_RES): i / (N - 1) for i in 0..N.
pub const TRANSMITTANCE_POINTS: usize = 64;

/// What a coat of given roughness and index scatters, tabulated once (see `coat_tables`).
#[derive(Debug, PartialEq)]
pub struct Coat {
    /// The transmittance from outside at `TRANSMITTANCE_POINTS` cosines.
    pub transmittance: [f32; TRANSMITTANCE_POINTS],
    /// R_i: the reflectance from inside over the cosine-weighted hemisphere.
    pub internal_reflectance: f32,
}

/// Mitsuba's `roughplastic`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughPlastic {
    pub distribution: Microfacet,
    /// Mitsuba's `nonlinear`: the base's own colour in the internal reflections' sum.
    pub nonlinear: bool,
    pub alpha: f32,
    /// Relative index of the coat (inside over outside).
    pub eta: f32,
    /// The base's reflectance (Mitsuba's `diffuse_reflectance`).
    pub diffuse: Vec3,
    /// A factor on the glossy lobe (Mitsuba's `specular_reflectance`, 1 by default).
    pub specular: Vec3,
    /// The specular share of the sampling: mean(specular) / (mean(diffuse) + mean(specular)),
    /// the means over the channels (and over a texture's texels where textured).
    pub specular_weight: f32,
    pub coat: &'static Coat,
    /// Reflects on both sides (Mitsuba's `twosided`; see `Conductor::two_sided`).
    pub two_sided: bool,
}

impl RoughPlastic {
    /// A rough plastic; `diffuse_mean` is the mean of the base's reflectance (a texture's
    /// where it is textured, `diffuse` the value the texture stands in for).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        distribution: Microfacet,
        alpha: f32,
        eta: f32,
        diffuse: Vec3,
        diffuse_mean: f32,
        specular: Vec3,
        nonlinear: bool,
    ) -> RoughPlastic {
        let specular_mean = (specular.x + specular.y + specular.z) / 3.0;
        RoughPlastic {
            distribution,
            nonlinear,
            alpha,
            eta,
            diffuse,
            specular,
            specular_weight: specular_mean / (diffuse_mean + specular_mean),
            coat: coat_tables(distribution, alpha, eta),
            two_sided: false,
        }
    }

    /// T(cos), linearly interpolated as Mitsuba's `lerp_gather`.
    #[inline]
    fn transmittance_at(&self, cos: f32) -> f32 {
        let x = cos * (TRANSMITTANCE_POINTS - 1) as f32;
        let i = (x as usize).min(TRANSMITTANCE_POINTS - 2);
        let (t0, t1) = (self.coat.transmittance[i], self.coat.transmittance[i + 1]);
        t0 + (t1 - t0) * (x - i as f32)
    }

    /// The probability of sampling the glossy lobe from `wo` (wo.z > 0).
    #[inline]
    fn specular_probability(&self, wo_z: f32) -> f32 {
        let t = self.transmittance_at(wo_z);
        let specular = (1.0 - t) * self.specular_weight;
        let diffuse = t * (1.0 - self.specular_weight);
        specular / (specular + diffuse)
    }

    #[inline]
    fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Vec3::ZERO, 0.0);
        }
        let h = wo + wi;
        let h = h / h.length();
        let a = Alphas::new(self.alpha, self.alpha);
        let m = self.distribution;
        let (d, go, gi) = (a.ndf(m, h), a.g1_over_cos(m, wo), a.g1_over_cos(m, wi));
        let glossy_pdf = 0.25 * go * d;
        let glossy = self.specular * (fresnel(wo.dot(h), self.eta) * glossy_pdf * gi);
        let (t_o, t_i) = (self.transmittance_at(wo.z), self.transmittance_at(wi.z));
        let inside = if self.nonlinear {
            self.diffuse * self.coat.internal_reflectance
        } else {
            Vec3::splat(self.coat.internal_reflectance)
        };
        let base =
            self.diffuse / (Vec3::ONE - inside) * (FRAC_1_PI / (self.eta * self.eta) * t_o * t_i);
        let p = self.specular_probability(wo.z);
        (glossy + base, p * glossy_pdf + (1.0 - p) * wi.z * FRAC_1_PI)
    }
}

impl Bsdf for RoughPlastic {
    const IS_DELTA: bool = false;
    const HAS_DELTA_LOBE: bool = false;
    const TRANSMITS: bool = false;
    const SHADING_SYSTEM: &'static str = "shade_rough_plastic";

    fn two_sided(&self) -> bool {
        self.two_sided
    }

    /// f(wo, wi) without the cosine; zero unless both lie strictly above the surface.
    fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Vec3 {
        self.eval_pdf(wo, wi).0
    }

    /// The solid-angle density with which `sample` returns `wi`.
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(wo, wi).1
    }

    /// Samples the glossy lobe or the base (one number chooses, then is stretched back to
    /// [0, 1) for the direction); `None` when wo is not above the surface or the reflection
    /// goes below it.
    fn sample(&self, wo: Vec3, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let p = self.specular_probability(wo.z);
        let wi = if u.x < p {
            let u = Vec2::new(u.x / p, u.y);
            let a = Alphas::new(self.alpha, self.alpha);
            let h = a.visible_normal(self.distribution, wo, u);
            (2.0 * wo.dot(h) * h - wo).normalize()
        } else {
            let u = Vec2::new(((u.x - p) / (1.0 - p)).min(1.0 - f32::EPSILON), u.y);
            crate::sampling::cosine_hemisphere(u)
        };
        if wi.z <= 0.0 {
            return None;
        }
        let (value, pdf) = self.eval_pdf(wo, wi);
        BsdfSample::of_lobe(wi, value, pdf)
    }
}

type TableKey = (Microfacet, u32, u32);

/// The coat's tables for (distribution, alpha, eta), computed once per process and shared by
/// every material (and every scene) with those parameters: a few hundred bytes each, kept
/// for the process's life so that materials stay `Copy`.
fn coat_tables(distribution: Microfacet, alpha: f32, eta: f32) -> &'static Coat {
    static TABLES: OnceLock<Mutex<HashMap<TableKey, &'static Coat>>> = OnceLock::new();
    let tables = TABLES.get_or_init(Default::default);
    let key = (distribution, alpha.to_bits(), eta.to_bits());
    let lock = || tables.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(coat) = lock().get(&key) {
        return coat;
    }
    // Computed without the lock held (the quadratures run on rayon's threads); a thread that
    // raced to the same key keeps the first table stored, equal to its own.
    let coat = compute_coat(distribution, alpha, eta);
    lock()
        .entry(key)
        .or_insert_with(|| Box::leak(Box::new(coat)))
}

/// `coat_tables`' work: each cosine's two quadratures on rayon's threads (tens of thousands of
/// visible-normal samples each), summed in index order, so the tables do not depend on the
/// thread count.
fn compute_coat(distribution: Microfacet, alpha: f32, eta: f32) -> Coat {
    use rayon::prelude::*;
    let per_cosine: Vec<(f32, f64)> = (0..TRANSMITTANCE_POINTS)
        .into_par_iter()
        .map(|i| {
            let mu = (i as f32 / (TRANSMITTANCE_POINTS - 1) as f32).max(1e-6);
            let w = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            (
                coat_scattering(distribution, alpha, w, eta, false) as f32,
                coat_scattering(distribution, alpha, w, 1.0 / eta, true) * f64::from(mu),
            )
        })
        .collect();
    let mut transmittance = [0.0f32; TRANSMITTANCE_POINTS];
    let mut inside = 0.0f64;
    for (t, (transmitted, reflected)) in transmittance.iter_mut().zip(per_cosine) {
        *t = transmitted;
        inside += reflected;
    }
    Coat {
        transmittance,
        // Twice the mean of R(mu) mu over the same cosines: the cosine-weighted average.
        internal_reflectance: (2.0 * inside / TRANSMITTANCE_POINTS as f64) as f32,
    }
}

/// What a rough dielectric interface of relative index `eta` reflects (`reflect`) or refracts
/// of light arriving from `w` (w.z > 0): the mean over its visible normals m of the Fresnel
/// factor (F or 1 - F) times the masking G1 of the outgoing direction, by Gauss-Legendre
/// quadrature over the visible-normal sampler's unit square (32 x 32 nodes where eta > 1, 128 x
/// 128 where the other side is the dense one and total internal reflection makes the
/// integrand steep, as Mitsuba's eval_reflectance / eval_transmittance choose).
fn coat_scattering(distribution: Microfacet, alpha: f32, w: Vec3, eta: f32, reflect: bool) -> f64 {
    let (nodes, weights) = gauss_legendre(if eta > 1.0 { 32 } else { 128 });
    let a = Alphas::new(alpha, alpha);
    let g1 = |v: Vec3| {
        // Smith's G1 is even in v.z (a refracted direction lies below the surface).
        let up = Vec3::new(v.x, v.y, v.z.abs());
        f64::from(a.g1_over_cos(distribution, up) * up.z)
    };
    let mut sum = 0.0f64;
    for (x, wx) in nodes.iter().zip(&weights) {
        for (y, wy) in nodes.iter().zip(&weights) {
            let u = Vec2::new((0.5 * x + 0.5) as f32, (0.5 * y + 0.5) as f32);
            let m = a.visible_normal(distribution, w, u);
            let cos_i = w.dot(m);
            let f = f64::from(fresnel(cos_i, eta));
            let value = if reflect {
                let out = 2.0 * cos_i * m - w;
                if out.z <= 0.0 { 0.0 } else { f * g1(out) }
            } else {
                let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
                if sin2_t >= 1.0 {
                    0.0
                } else {
                    let cos_t = (1.0 - sin2_t).sqrt();
                    let out = m * (cos_i / eta - cos_t) - w / eta;
                    if out.z >= 0.0 {
                        0.0
                    } else {
                        (1.0 - f) * g1(out)
                    }
                }
            };
            sum += value * wx * wy;
        }
    }
    // The weights on [-1, 1] sum to 2 per axis: a mean over the unit square.
    0.25 * sum
}

/// The `n` nodes and weights of Gauss-Legendre quadrature on [-1, 1] (Newton's method on the
/// Legendre polynomial from the usual cosine guesses).
fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut nodes = vec![0.0; n];
    let mut weights = vec![0.0; n];
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut derivative = 1.0;
        for _ in 0..100 {
            // P_n(x) and P_n'(x) by the three-term recurrence.
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            derivative = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let step = p1 / derivative;
            x -= step;
            if step.abs() < 1e-15 {
                break;
            }
        }
        nodes[i] = x;
        weights[i] = 2.0 / ((1.0 - x * x) * derivative * derivative);
    }
    (nodes, weights)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let (x, w) = gauss_legendre(8);
        assert!((w.iter().sum::<f64>() - 2.0).abs() < 1e-13);
        // Exact up to degree 15: x^14 integrates to 2/15 over [-1, 1].
        let got: f64 = x.iter().zip(&w).map(|(x, w)| x.powi(14) * w).sum();
        assert!((got - 2.0 / 15.0).abs() < 1e-13, "{got}");
    }

    #[test]
    fn a_smooth_coat_transmits_one_minus_fresnel() {
        // alpha -> 0: every visible normal is the geometric one and G1 is 1.
        for mu in [1.0f32, 0.7, 0.3] {
            let w = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
                let t = coat_scattering(distribution, 1e-4, w, 1.5, false);
                let r = coat_scattering(distribution, 1e-4, w, 1.5, true);
                let f = f64::from(fresnel(mu, 1.5));
                assert!((t - (1.0 - f)).abs() < 1e-4, "{distribution:?} {mu}: T {t}");
                assert!((r - f).abs() < 1e-4, "{distribution:?} {mu}: R {r}");
            }
        }
    }

    #[test]
    fn a_rough_coat_reflects_and_transmits_at_most_everything() {
        for alpha in [0.05f32, 0.3, 1.0] {
            for mu in [1.0f32, 0.5, 0.1, 0.01] {
                let w = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let t = coat_scattering(Microfacet::Beckmann, alpha, w, 1.49, false);
                let r = coat_scattering(Microfacet::Beckmann, alpha, w, 1.49, true);
                assert!(
                    t >= 0.0 && r >= 0.0 && t + r <= 1.0 + 1e-6,
                    "{alpha} {mu}: {t} {r}"
                );
            }
        }
    }
}
