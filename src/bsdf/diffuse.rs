//! Lambertian reflection on both sides of the surface.
use super::BsdfSample;
use glam::{Vec2, Vec3};

pub fn eval(_reflectance: Vec3, _wo: Vec3, _wi: Vec3) -> Vec3 {
    todo!("bsdf helper")
}
pub fn pdf(_wo: Vec3, _wi: Vec3) -> f32 {
    todo!("bsdf helper")
}
pub fn sample(_reflectance: Vec3, _wo: Vec3, _u: Vec2) -> Option<BsdfSample> {
    todo!("bsdf helper")
}
