//! Lambertian reflection on both sides of the surface.
use super::BsdfSample;
use crate::sampling::cosine_hemisphere;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// True when both directions lie strictly on the same side of the surface (a zero cosine is on
/// neither side: such directions carry no projected energy).
#[inline]
fn same_side(wo: Vec3, wi: Vec3) -> bool {
    (wo.z > 0.0 && wi.z > 0.0) || (wo.z < 0.0 && wi.z < 0.0)
}

pub fn eval(reflectance: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
    if same_side(wo, wi) {
        reflectance * FRAC_1_PI
    } else {
        Vec3::ZERO
    }
}

pub fn pdf(wo: Vec3, wi: Vec3) -> f32 {
    if same_side(wo, wi) {
        wi.z.abs() * FRAC_1_PI
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
