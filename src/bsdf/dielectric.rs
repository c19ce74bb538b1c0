//! Smooth dielectric interface.
use super::{BsdfSample, TransportMode};
use glam::Vec3;

/// Unpolarised Fresnel reflectance for a ray arriving with cosine `cos_i` (positive: from the
/// outside) at an interface with relative index `eta` (inside over outside).
pub fn fresnel(_cos_i: f32, _eta: f32) -> f32 {
    todo!("bsdf helper")
}
pub fn sample(_ior: f32, _wo: Vec3, _u: f32, _mode: TransportMode) -> BsdfSample {
    todo!("bsdf helper")
}
