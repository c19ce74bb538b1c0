//! Smooth dielectric interface, and the thin dielectric sheet.
use super::{Bsdf, BsdfSample, TransportMode};
use crate::lanes::Real;
use glam::{Vec2, Vec3};

/// Smooth dielectric: exact unpolarised Fresnel, refraction, total internal reflection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dielectric {
    /// The index inside (the side opposite the geometric normal) over outside.
    pub ior: f32,
}

impl Bsdf for Dielectric {
    const IS_DELTA: bool = true;
    const HAS_DELTA_LOBE: bool = true;
    const TRANSMITS: bool = false;
    const SHADING_SYSTEM: &'static str = "shade_dielectric";

    fn two_sided(&self) -> bool {
        false
    }

    fn eval(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> Vec3 {
        Vec3::ZERO
    }

    fn pdf(&self, _wo: Vec3, _wi: Vec3) -> f32 {
        0.0
    }

    #[inline]
    fn sample(&self, wo: Vec3, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        Some(sample(self.ior, wo, u.x, mode))
    }
}

/// Thin dielectric sheet (Mitsuba's `thindielectric`): reflects R' (the Fresnel term of both
/// faces and the light bouncing between them) and lets 1 - R' straight through.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinDielectric {
    /// The sheet's index over its surroundings'; alike from both sides.
    pub ior: f32,
}

impl Bsdf for ThinDielectric {
    const IS_DELTA: bool = true;
    const HAS_DELTA_LOBE: bool = true;
    const TRANSMITS: bool = false;
    const SHADING_SYSTEM: &'static str = "shade_thin_dielectric";

    fn two_sided(&self) -> bool {
        false
    }

    fn eval(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> Vec3 {
        Vec3::ZERO
    }

    fn pdf(&self, _wo: Vec3, _wi: Vec3) -> f32 {
        0.0
    }

    #[inline]
    fn sample(&self, wo: Vec3, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        Some(sample_thin(self.ior, wo, u.x))
    }
}

/// Smallest |cos| a delta lobe divides by. A direction exactly in the tangent plane would make
/// `F / |cos|` infinite; with the floor the value stays finite (at most ~1e20 times eta^2) and
/// the weight `value * |cos| / pdf` is exact for every |cos| >= 1e-20 (and 0 below, where the
/// ray is tangent and carries no projected energy anyway).
const COS_FLOOR: f32 = 1e-20;

/// Unpolarised Fresnel reflectance for a ray arriving with cosine `cos_i` (positive: from the
/// outside) at an interface with relative index `eta` (inside over outside).
pub fn fresnel(cos_i: f32, eta: f32) -> f32 {
    fresnel_of(cos_i, eta)
}

/// `fresnel` for one path or lanes.
#[inline(always)]
pub fn fresnel_of<T: Real>(cos_i: T, eta: T) -> T {
    // f32::clamp(-1, 1), NaN kept.
    let c = T::select(
        cos_i.less(T::splat(-1.0)),
        T::splat(-1.0),
        T::select(cos_i.greater(T::splat(1.0)), T::splat(1.0), cos_i),
    );
    fresnel_cs(c, (T::splat(1.0) - c * c).max(T::splat(0.0)), eta)
}

/// `fresnel` given also sin^2 of the incident angle: near normal incidence 1 - cos^2 cancels,
/// so `sample` passes wo.x^2 + wo.y^2 instead, which keeps grazing transmission accurate.
#[inline(always)]
fn fresnel_cs<T: Real>(cos_i: T, sin2_i: T, eta: T) -> T {
    let one = T::splat(1.0);
    // Arriving from the inside: the side left is the dense one.
    let inside = cos_i.less(T::splat(0.0));
    let eta = T::select(inside, one / eta, eta);
    let cos_i = T::select(inside, -cos_i, cos_i);
    let sin2_t = sin2_i / (eta * eta);
    let cos_t = (one - sin2_t).max(T::splat(0.0)).sqrt();
    let r_s = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let r_p = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    // Both denominators are > 0 where sin2_t < 1: cos_t > 0, and eta > 0; at or beyond 1, total
    // internal reflection.
    T::select(
        sin2_t.less(one),
        ((r_s * r_s + r_p * r_p) * 0.5).min(one),
        one,
    )
}

/// Fresnel reflectance of a refraction pair from both its cosines: `cos_outside` and
/// `cos_inside` (both positive) on the two sides of an interface of relative index `eta`
/// (inside over outside). The same value as `fresnel` from either side, but without forming
/// the transmitted cosine as sqrt(1 - sin^2), which loses all its digits near the critical
/// angle.
pub fn fresnel_of_pair(cos_outside: f32, cos_inside: f32, eta: f32) -> f32 {
    let r_s = (cos_outside - eta * cos_inside) / (cos_outside + eta * cos_inside);
    let r_p = (eta * cos_outside - cos_inside) / (eta * cos_outside + cos_inside);
    if !(r_s.is_finite() && r_p.is_finite()) {
        return 1.0; // both cosines zero: grazing on both sides
    }
    (0.5 * (r_s * r_s + r_p * r_p)).min(1.0)
}

/// Samples reflection with probability F and refraction with probability 1 - F, choosing with
/// `u`. The reflected sample has weight 1; the refracted one has weight 1 in importance mode and
/// (eta_o / eta_t)^2 in radiance mode, where eta_o is the index of wo's side and eta_t that of
/// wi's side (radiance is compressed into the narrower cone of the denser medium).
pub fn sample(ior: f32, wo: Vec3, u: f32, mode: TransportMode) -> BsdfSample {
    let cos_o = wo.z.clamp(-1.0, 1.0);
    let sin2_o = (wo.x * wo.x + wo.y * wo.y).min(1.0);
    let f = fresnel_cs(cos_o, sin2_o, ior);
    if u < f {
        let wi = Vec3::new(-wo.x, -wo.y, wo.z);
        return BsdfSample {
            wi,
            value: Vec3::splat(f / wi.z.abs().max(COS_FLOOR)),
            pdf: f,
            delta: true,
        };
    }
    // Refraction; here F < 1, so the transmitted cosine is nonzero.
    let outside = wo.z >= 0.0;
    // eta = index of the side entered over that of the side left.
    let eta = if outside { ior } else { 1.0 / ior };
    let sin2_t = sin2_o / (eta * eta);
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    // Snell: tangential part scaled by 1/eta and reversed, normal part on the other side.
    let wi = Vec3::new(
        -wo.x / eta,
        -wo.y / eta,
        if outside { -cos_t } else { cos_t },
    )
    .normalize_or(Vec3::new(0.0, 0.0, if outside { -1.0 } else { 1.0 }));
    let t = 1.0 - f;
    let scale = match mode {
        TransportMode::Radiance => 1.0 / (eta * eta),
        TransportMode::Importance => 1.0,
    };
    BsdfSample {
        wi,
        value: Vec3::splat(t * scale / wi.z.abs().max(COS_FLOOR)),
        pdf: t,
        delta: true,
    }
}

/// Reflectance of a thin dielectric sheet (Mitsuba 3's `thindielectric`): light that enters
/// one face leaves by either after any number of internal reflections, so with R the Fresnel
/// reflectance of one face and T = 1 - R, R' = R + T^2 R / (1 - R^2) = 2R / (1 + R) (the rest,
/// 1 - R', goes straight through: the two refractions cancel). The sheet is alike from both
/// sides: `cos` is taken as |cos|, `ior` is the sheet's index over its surroundings'.
pub fn thin_reflectance(cos: f32, ior: f32) -> f32 {
    let c = cos.abs().min(1.0);
    let r = fresnel(c, ior);
    (2.0 * r / (1.0 + r)).min(1.0)
}

/// Samples a thin dielectric sheet: reflection with probability R' (`thin_reflectance`, chosen
/// with `u`), or straight through (wi = -wo) with probability 1 - R'. Both weigh 1: the sheet
/// has no radiance scaling, its two refractions undo each other, so the transport mode does
/// not matter.
pub fn sample_thin(ior: f32, wo: Vec3, u: f32) -> BsdfSample {
    let r = thin_reflectance(wo.z, ior);
    let (wi, pdf) = if u < r {
        (Vec3::new(-wo.x, -wo.y, wo.z), r)
    } else {
        (-wo, 1.0 - r)
    };
    BsdfSample {
        wi,
        value: Vec3::splat(pdf / wi.z.abs().max(COS_FLOOR)),
        pdf,
        delta: true,
    }
}
