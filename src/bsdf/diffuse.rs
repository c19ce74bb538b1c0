//! Lambertian reflection on both sides of the surface.
use super::BsdfSample;
use crate::sampling::cosine_hemisphere;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// True when both directions lie strictly on the same side of the surface (a zero cosine is on
/// neither side: such directions carry no projected energy).
#[inline]
fn same_side(cos_o: f32, cos_i: f32) -> bool {
    (cos_o > 0.0 && cos_i > 0.0) || (cos_o < 0.0 && cos_i < 0.0)
}

pub fn eval(reflectance: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
    eval_cos(reflectance, wo.z, wi.z)
}

pub fn pdf(wo: Vec3, wi: Vec3) -> f32 {
    pdf_cos(wo.z, wi.z)
}

/// `eval` from the two cosines with the shading normal (all the lobe depends on).
#[inline]
pub fn eval_cos(reflectance: Vec3, cos_o: f32, cos_i: f32) -> Vec3 {
    if same_side(cos_o, cos_i) {
        reflectance * FRAC_1_PI
    } else {
        Vec3::ZERO
    }
}

/// `pdf` from the two cosines with the shading normal.
#[inline]
pub fn pdf_cos(cos_o: f32, cos_i: f32) -> f32 {
    if same_side(cos_o, cos_i) {
        cos_i.abs() * FRAC_1_PI
    } else {
        0.0
    }
}

pub fn sample(reflectance: Vec3, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
    if wo.z == 0.0 {
        return None;
    }
    let mut wi = cosine_hemisphere(u);
    // Mirror the lobe onto wo's side: the surface reflects on both sides.
    if wo.z < 0.0 {
        wi.z = -wi.z;
    }
    let pdf = pdf(wo, wi);
    // The rim of the disk maps to the tangent plane, where the density vanishes.
    if pdf <= 0.0 {
        return None;
    }
    Some(BsdfSample {
        wi,
        value: reflectance * FRAC_1_PI,
        pdf,
        delta: false,
    })
}
