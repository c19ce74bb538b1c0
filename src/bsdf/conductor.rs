//! GGX (Trowbridge-Reitz) rough conductor with a constant Fresnel term.
//!
//! f = R D(h) G1(wo) G1(wi) / (4 wo.z wi.z), sampled with the distribution of visible normals
//! (Heitz 2018), pdf = G1(wo) D(h) / (4 wo.z). Both are written with the bounded ratio
//! G1(w) / w.z, which tends to 2/alpha in the tangent plane instead of forming 0/0.
use super::BsdfSample;
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// Smallest roughness used. Directions in f32 carry errors of ~1e-7, and the lobe's width in
/// half-vector space is ~alpha, so D evaluated at a half-vector rebuilt from (wo, wi) is accurate
/// to ~1e-7/alpha: below 1e-4 `eval` and `pdf` would no longer match what `sample` drew. The
/// peak values also stay modest: D <= 1/(pi alpha^2) ~ 3e7 and f <= R/(pi alpha^4) ~ 3e15.
pub const ALPHA_MIN: f32 = 1e-4;

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

/// GGX normal distribution for a unit half-vector `m` with m.z > 0. The denominator uses
/// m.x^2 + m.y^2 for sin^2 rather than 1 - m.z^2, which cancels to 0 for tiny alpha.
#[inline]
fn ndf(a2: f32, m: Vec3) -> f32 {
    let d = a2 * m.z * m.z + m.x * m.x + m.y * m.y;
    a2 * FRAC_1_PI / (d * d)
}

/// Smith G1(w) / w.z for the GGX distribution, w.z > 0:
/// G1 = 2 / (1 + sqrt(1 + alpha^2 tan^2)), so G1 / cos = 2 / (cos + sqrt(cos^2 + alpha^2 sin^2)),
/// which is bounded by 2/alpha even at cos = 0.
#[inline]
fn g1_over_cos(a2: f32, w: Vec3) -> f32 {
    let c2 = w.z * w.z;
    let s2 = w.x * w.x + w.y * w.y;
    2.0 / (w.z + (c2 + a2 * s2).sqrt())
}

/// (f, pdf) for a reflection pair; zero unless both lie strictly above the surface.
#[inline]
fn eval_pdf(alpha: f32, reflectance: Vec3, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return (Vec3::ZERO, 0.0);
    }
    let h = wo + wi;
    // Both above the surface: h.z > 0 and |h| >= h.z, so normalising is safe.
    let h = h / h.length();
    let a2 = {
        let a = clamp_alpha(alpha);
        a * a
    };
    let d = ndf(a2, h);
    let go = g1_over_cos(a2, wo);
    let gi = g1_over_cos(a2, wi);
    // The pdf's (wo.h) factors cancel: D_wo(h) / (4 wo.h) = G1(wo) D(h) / (4 wo.z).
    let pdf = 0.25 * go * d;
    (reflectance * (pdf * gi), pdf)
}

pub fn eval(alpha: f32, reflectance: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
    eval_pdf(alpha, reflectance, wo, wi).0
}

pub fn pdf(alpha: f32, wo: Vec3, wi: Vec3) -> f32 {
    eval_pdf(alpha, Vec3::ONE, wo, wi).1
}

/// A half-vector from the distribution of normals visible from `wo` (wo.z > 0), following
/// Heitz 2018: stretch to the alpha = 1 configuration, sample the projected hemisphere, unstretch.
fn sample_visible_normal(alpha: f32, wo: Vec3, u: Vec2) -> Vec3 {
    let v = Vec3::new(alpha * wo.x, alpha * wo.y, wo.z).normalize();
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
    Vec3::new(alpha * n.x, alpha * n.y, n.z.max(0.0)).normalize_or(Vec3::Z)
}

pub fn sample(alpha: f32, reflectance: Vec3, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let alpha = clamp_alpha(alpha);
    let h = sample_visible_normal(alpha, wo, u);
    let wi = 2.0 * wo.dot(h) * h - wo;
    if wi.z <= 0.0 {
        return None; // reflected below the surface: masked
    }
    let wi = wi.normalize();
    // Value and pdf from the same code as eval/pdf so that MIS sees identical densities.
    let (value, pdf) = eval_pdf(alpha, reflectance, wo, wi);
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
