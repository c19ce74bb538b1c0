//! GGX (Trowbridge-Reitz) rough conductor with a constant Fresnel term.
use super::BsdfSample;
use glam::{Vec2, Vec3};

pub fn eval(_alpha: f32, _reflectance: Vec3, _wo: Vec3, _wi: Vec3) -> Vec3 {
    todo!("bsdf helper")
}
pub fn pdf(_alpha: f32, _wo: Vec3, _wi: Vec3) -> f32 {
    todo!("bsdf helper")
}
pub fn sample(_alpha: f32, _reflectance: Vec3, _wo: Vec3, _u: Vec2) -> Option<BsdfSample> {
    todo!("bsdf helper")
}
