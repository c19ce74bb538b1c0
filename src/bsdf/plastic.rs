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
use super::dielectric::{fresnel, fresnel_of};
use super::microfacet::Distribution;
use super::{Bsdf, BsdfSample, LobeSample, TransportMode};
use crate::lanes::{F, Mask, Real, V3};
use crate::sampling::cosine_hemisphere_of;
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

    /// The lobe for one path.
    #[inline(always)]
    fn lobe(&self) -> RoughPlasticLobe<f32> {
        RoughPlasticLobe::gather(&[*self])
    }
}

impl Coat {
    /// T(cos), linearly interpolated as Mitsuba's `lerp_gather`.
    #[inline]
    fn transmittance_at(&self, cos: f32) -> f32 {
        let x = cos * (TRANSMITTANCE_POINTS - 1) as f32;
        let i = (x as usize).min(TRANSMITTANCE_POINTS - 2);
        let (t0, t1) = (self.transmittance[i], self.transmittance[i + 1]);
        t0 + (t1 - t0) * (x - i as f32)
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

    /// Samples the glossy lobe or the base (one number chooses, then is stretched back to
    /// [0, 1) for the direction); `None` when wo is not above the surface or the reflection
    /// goes below it.
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
        RoughPlasticLobe::gather(materials).sample(wo, ux, uy)
    }

    #[inline(always)]
    fn eval_pdf_lanes<const N: usize>(
        materials: &[Self; N],
        wo: V3<F<N>>,
        wi: V3<F<N>>,
    ) -> (V3<F<N>>, F<N>) {
        RoughPlasticLobe::gather(materials).eval_pdf(wo, wi)
    }
}

/// A rough plastic's lobes for one path (`f32`) or lanes (`F<N>`): the maths of `eval`, `pdf`
/// and `sample`, written once over `Real`; the coat's tables are read lane by lane.
#[derive(Clone, Copy)]
pub struct RoughPlasticLobe<T: Real> {
    distribution: Distribution<T>,
    eta: T,
    specular: V3<T>,
    specular_weight: T,
    /// diffuse / (1 - the internal reflections' factor): the base lobe's colour.
    base: V3<T>,
    coats: T::Each<&'static Coat>,
}

impl<T: Real> RoughPlasticLobe<T> {
    /// Lane `l`'s lobes are `plastics[l]`'s.
    #[inline(always)]
    pub fn gather(plastics: &[RoughPlastic]) -> RoughPlasticLobe<T> {
        let p = |l: usize| &plastics[l];
        let alpha = T::lanes(|l| p(l).alpha);
        RoughPlasticLobe {
            distribution: Distribution::new(
                T::Mask::lanes(|l| p(l).distribution == Microfacet::Beckmann),
                alpha,
                alpha,
            ),
            eta: T::lanes(|l| p(l).eta),
            specular: V3::lanes(|l| p(l).specular),
            specular_weight: T::lanes(|l| p(l).specular_weight),
            base: V3::lanes(|l| {
                let p = p(l);
                let inside = if p.nonlinear {
                    p.diffuse * p.coat.internal_reflectance
                } else {
                    Vec3::splat(p.coat.internal_reflectance)
                };
                p.diffuse / (Vec3::ONE - inside)
            }),
            coats: T::each(|l| p(l).coat),
        }
    }

    /// T(cos) of each lane's coat.
    #[inline(always)]
    fn transmittance_at(&self, cos: T) -> T {
        T::lanes(|l| self.coats[l].transmittance_at(cos.lane(l)))
    }

    /// The probability of sampling the glossy lobe from wo, given T(wo.z).
    #[inline(always)]
    fn specular_probability(&self, t_o: T) -> T {
        let specular = (T::splat(1.0) - t_o) * self.specular_weight;
        let diffuse = t_o * (T::splat(1.0) - self.specular_weight);
        specular / (specular + diffuse)
    }

    /// (f, pdf) of a pair; zero unless both lie strictly above the surface.
    #[inline(always)]
    pub fn eval_pdf(&self, wo: V3<T>, wi: V3<T>) -> (V3<T>, T) {
        let zero = T::splat(0.0);
        let none = (V3::splat(Vec3::ZERO), zero);
        let above = wo.z.greater(zero) & wi.z.greater(zero);
        if !above.any() {
            return none;
        }
        let h = wo + wi;
        let h = h / h.length();
        let m = &self.distribution;
        let (d, go, gi) = (m.ndf(h), m.g1_over_cos(wo), m.g1_over_cos(wi));
        let glossy_pdf = T::splat(0.25) * go * d;
        let glossy = self.specular * (fresnel_of(wo.dot(h), self.eta) * glossy_pdf * gi);
        let (t_o, t_i) = (self.transmittance_at(wo.z), self.transmittance_at(wi.z));
        let base = self.base * (T::splat(FRAC_1_PI) / (self.eta * self.eta) * t_o * t_i);
        let p = self.specular_probability(t_o);
        let pdf = p * glossy_pdf + (T::splat(1.0) - p) * wi.z * FRAC_1_PI;
        (
            V3::select(above, glossy + base, none.0),
            T::select(above, pdf, zero),
        )
    }

    /// A direction of the glossy lobe (visible normals) or the base (the cosine), one number
    /// choosing and then stretched back to [0, 1); valid where wo and wi are above the surface.
    #[inline(always)]
    pub fn sample(&self, wo: V3<T>, ux: T, uy: T) -> LobeSample<T> {
        let zero = T::splat(0.0);
        let facing = wo.z.greater(zero);
        if !facing.any() {
            return LobeSample::none();
        }
        let p = self.specular_probability(self.transmittance_at(wo.z));
        let glossy = ux.less(p);
        let wi = V3::select_with(
            glossy,
            || {
                let h = self
                    .distribution
                    .visible_normal(wo, ux / p, uy, facing & glossy);
                (h * (T::splat(2.0) * wo.dot(h)) - wo).normalize()
            },
            || {
                let ux = ((ux - p) / (T::splat(1.0) - p)).min(T::splat(1.0 - f32::EPSILON));
                cosine_hemisphere_of(ux, uy)
            },
        );
        let kept = facing & wi.z.greater(zero);
        let (value, pdf) = self.eval_pdf(wo, wi);
        LobeSample::of_lobe(kept, wi, value, pdf)
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
    let a = Distribution::of(distribution, alpha, alpha);
    let g1 = |v: Vec3| {
        // Smith's G1 is even in v.z (a refracted direction lies below the surface).
        let up = Vec3::new(v.x, v.y, v.z.abs());
        f64::from(a.g1_over_cos(up.into()) * up.z)
    };
    let mut sum = 0.0f64;
    for (x, wx) in nodes.iter().zip(&weights) {
        for (y, wy) in nodes.iter().zip(&weights) {
            let u = Vec2::new((0.5 * x + 0.5) as f32, (0.5 * y + 0.5) as f32);
            let m: Vec3 = a.visible_normal(w.into(), u.x, u.y, true).into();
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
