//! Lambertian reflection on both sides of the surface.
//!
//! The lobe's maths is written once over [`Real`] (`eval_cos`, `pdf_cos`, `sample_of`): the
//! megakernel and the other integrators run it for one path (`f32`, through `Diffuse`'s
//! `Bsdf`), the wavefront's lane systems for `N` paths at a time (`F<N>`), bit for bit alike
//! (see docs/architecture.md, "Writing a material once for one path and for lanes").
use super::{Bsdf, BsdfSample, LobeSample, TransportMode};
use crate::lanes::{F, Real, V3};
use crate::sampling::cosine_hemisphere_of;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// True when both directions lie strictly on the same side of the surface (a zero cosine is on
/// neither side: such directions carry no projected energy).
#[inline(always)]
fn same_side<T: Real>(cos_o: T, cos_i: T) -> T::Mask {
    let zero = T::splat(0.0);
    (cos_o.greater(zero) & cos_i.greater(zero)) | (cos_o.less(zero) & cos_i.less(zero))
}

/// Lambertian reflection, alike on both sides.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Diffuse {
    pub reflectance: Vec3,
}

impl Bsdf for Diffuse {
    const IS_DELTA: bool = false;
    const HAS_DELTA_LOBE: bool = false;
    const TRANSMITS: bool = false;
    const SHADING_SYSTEM: &'static str = "shade_diffuse";

    fn two_sided(&self) -> bool {
        true
    }

    fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Vec3 {
        eval_cos(self.reflectance.into(), wo.z, wi.z).into()
    }

    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        pdf_cos(wo.z, wi.z)
    }

    fn sample(&self, wo: Vec3, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        sample_of(self.reflectance.into(), wo.into(), u.x, u.y).one()
    }

    const IN_LANES: bool = true;

    #[inline(always)]
    fn sample_lanes<const N: usize>(
        materials: &[Self; N],
        wo: V3<F<N>>,
        ux: F<N>,
        uy: F<N>,
    ) -> LobeSample<F<N>> {
        sample_of(V3::lanes(|l| materials[l].reflectance), wo, ux, uy)
    }

    #[inline(always)]
    fn eval_pdf_lanes<const N: usize>(
        materials: &[Self; N],
        wo: V3<F<N>>,
        wi: V3<F<N>>,
    ) -> (V3<F<N>>, F<N>) {
        (
            eval_cos(V3::lanes(|l| materials[l].reflectance), wo.z, wi.z),
            pdf_cos(wo.z, wi.z),
        )
    }

    /// The lobe depends only on the two cosines, so it needs no frame (the common case in
    /// bidirectional connections, which evaluate many direction pairs per vertex).
    #[inline]
    fn eval_world(&self, ns: Vec3, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Vec3 {
        eval_cos(self.reflectance.into(), wo.dot(ns), wi.dot(ns)).into()
    }

    #[inline]
    fn pdf_world(&self, ns: Vec3, wo: Vec3, wi: Vec3) -> f32 {
        pdf_cos(wo.dot(ns), wi.dot(ns))
    }
}

/// `eval` from the two cosines with the shading normal (all the lobe depends on).
#[inline(always)]
pub fn eval_cos<T: Real>(reflectance: V3<T>, cos_o: T, cos_i: T) -> V3<T> {
    V3::select(
        same_side(cos_o, cos_i),
        reflectance * T::splat(FRAC_1_PI),
        V3::splat(Vec3::ZERO),
    )
}

/// `pdf` from the two cosines with the shading normal.
#[inline(always)]
pub fn pdf_cos<T: Real>(cos_o: T, cos_i: T) -> T {
    T::select(
        same_side(cos_o, cos_i),
        cos_i.abs() * FRAC_1_PI,
        T::splat(0.0),
    )
}

/// `sample` for one path or lanes: the one body of both.
#[inline(always)]
pub fn sample_of<T: Real>(reflectance: V3<T>, wo: V3<T>, ux: T, uy: T) -> LobeSample<T> {
    let zero = T::splat(0.0);
    let wi = cosine_hemisphere_of(ux, uy);
    // Mirror the lobe onto wo's side: the surface reflects on both sides.
    let wi = V3::new(wi.x, wi.y, T::select(wo.z.less(zero), -wi.z, wi.z));
    let pdf = pdf_cos(wo.z, wi.z);
    LobeSample {
        // A grazing wo has no side; the rim of the disk maps to the tangent plane, where the
        // density vanishes.
        valid: !wo.z.equal(zero) & !pdf.less_eq(zero),
        wi,
        value: reflectance * T::splat(FRAC_1_PI),
        pdf,
    }
}
