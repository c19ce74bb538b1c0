//! Materials and their BSDFs, evaluated in the local shading frame (normal = +z).
//!
//! Conventions: `wo` and `wi` are unit vectors pointing away from the surface; `eval` returns
//! f(wo, wi) without the cosine; `sample` returns a direction with its value and solid-angle pdf
//! so that the path weight is `value * |wi.z| / pdf`. Delta lobes (the smooth dielectric and
//! the thin one) return
//! `delta: true`, and for them `value * |wi.z| / pdf` is still the weight.

pub mod conductor;
pub mod dielectric;
pub mod diffuse;
pub mod microfacet;
pub mod plastic;
pub mod rough_dielectric;
pub mod smooth_plastic;

use crate::lanes::{F, Mask, Real, V3};
use glam::{Vec2, Vec3};

/// A material's BSDF, one type per material in that material's own file (`diffuse::Diffuse`,
/// `conductor::Conductor`, ...), listed once in `materials!` below, which derives `Material`,
/// `MaterialKind` and their dispatch from the list. A new material provides what its kind is
/// (the consts: the engine reads them per kind, before any material is seen), whether it
/// reflects alike on both sides, and `eval`, `pdf` and `sample` in the local shading frame
/// (normal = +z); `eval_world` and `pdf_world` build that frame unless the material has a
/// cheaper form.
pub trait Bsdf: ListedMaterial + Copy {
    /// Whether every lobe is a Dirac delta: light sampling and connections cannot reach it.
    /// (The smooth plastic is not: its diffuse lobe is reached; see `HAS_DELTA_LOBE`.)
    const IS_DELTA: bool;
    /// Whether `sample` may return a delta lobe (`BsdfSample::delta`): the delta kinds, and
    /// the smooth plastic, whose specular reflection is a delta beside its diffuse lobe.
    const HAS_DELTA_LOBE: bool;
    /// Whether a non-delta lobe transmits: connections, light samples and merges may then join
    /// the surface's two sides (where the shading frame agrees, see `scatters_between`).
    const TRANSMITS: bool;
    /// The name of the kind's shading system.
    const SHADING_SYSTEM: &'static str;

    /// Whether it reflects alike on both sides of a surface: the engine turns the shading
    /// frame to the side a ray arrives from (Lambertian surfaces always; a conductor or a
    /// plastic inside Mitsuba's `twosided`). The others are black from behind, or transmit.
    fn two_sided(&self) -> bool;

    /// f(wo, wi) without the cosine, for what the path carries (only refraction tells the
    /// two apart); zero for delta materials (the smooth plastic: its diffuse lobe's alone).
    fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Vec3;

    /// Solid-angle density with which `sample` returns `wi`; zero for delta materials (the
    /// smooth plastic's diffuse lobe's, times the probability of choosing that lobe).
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32;

    /// Samples wi given wo; `None` when the sample carries no energy.
    fn sample(&self, wo: Vec3, u: Vec2, mode: TransportMode) -> Option<BsdfSample>;

    /// `eval` and `pdf` of one pair at once (the microfacet materials compute them together).
    #[inline]
    fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Vec3, f32) {
        (self.eval(wo, wi, mode), self.pdf(wo, wi))
    }

    /// Whether the kind has a lane form: `sample_lanes` and `eval_pdf_lanes` compute, for `N`
    /// paths on materials of the kind at once, the bits `sample` and `eval_pdf` compute for
    /// each (the material's maths written once over `Real`), so the wavefront shades and
    /// samples lights `N` paths at a time. Non-delta materials whose lobes never refract
    /// (radiance and importance alike), one direction per sample.
    const IN_LANES: bool = false;

    /// `sample` (radiance) of `N` paths on `materials` at once; only called where `IN_LANES`.
    #[inline(always)]
    fn sample_lanes<const N: usize>(
        _materials: &[Self; N],
        _wo: V3<F<N>>,
        _ux: F<N>,
        _uy: F<N>,
    ) -> LobeSample<F<N>> {
        LobeSample::none()
    }

    /// `eval_pdf` of `N` pairs at once; only called where `IN_LANES`.
    #[inline(always)]
    fn eval_pdf_lanes<const N: usize>(
        _materials: &[Self; N],
        _wo: V3<F<N>>,
        _wi: V3<F<N>>,
    ) -> (V3<F<N>>, F<N>) {
        (V3::splat(Vec3::ZERO), F::splat(0.0))
    }

    /// `eval` for world-space directions about the shading normal `ns`.
    #[inline]
    fn eval_world(&self, ns: Vec3, wo: Vec3, wi: Vec3, mode: TransportMode) -> Vec3 {
        if Self::IS_DELTA {
            return Vec3::ZERO;
        }
        let frame = crate::math::Frame::from_normal(ns);
        self.eval(frame.to_local(wo), frame.to_local(wi), mode)
    }

    /// `pdf` for world-space directions about the shading normal `ns`.
    #[inline]
    fn pdf_world(&self, ns: Vec3, wo: Vec3, wi: Vec3) -> f32 {
        if Self::IS_DELTA {
            return 0.0;
        }
        let frame = crate::math::Frame::from_normal(ns);
        self.pdf(frame.to_local(wo), frame.to_local(wi))
    }
}

/// What `materials!` gives each material type it lists: its kind and the way back to it from
/// a `Material`, so that code generic over a `Bsdf` (a kind's shading system) reads its own
/// type. A `Bsdf` not in the list does not compile.
pub trait ListedMaterial: Sized {
    const KIND: MaterialKind;
    /// The material's value if `material` is of this type.
    fn of(material: &Material) -> Option<&Self>;
}

/// Code generic over the material type, run for a kind known only at run time
/// (`MaterialKind::visit`): each kind's shading system is one such instance.
pub trait KindVisitor {
    type Output;
    fn visit<B: Bsdf>(self) -> Self::Output;
}

/// The one list of materials: each entry names a kind and the `Bsdf` type behind it, and
/// from the list come `Material` (a variant per entry), `MaterialKind` (the kinds in the
/// list's order), the kinds' facts, `MaterialKind::visit` and `Material`'s dispatch of
/// `eval_mode`, `pdf`, `sample`, `eval_world` and `pdf_world`. The order is the queue order
/// of `sort_by_material`: the kinds with a non-delta lobe first, so light sampling runs over
/// one contiguous range of slots (checked below).
macro_rules! materials {
    ($($kind:ident($bsdf:ty)),+ $(,)?) => {
        /// A material as SCENES.md defines them: the value of one of the listed `Bsdf` types.
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub enum Material {
            $(
                #[doc = concat!("See [`", stringify!($bsdf), "`].")]
                $kind($bsdf),
            )+
        }

        /// The kind of a material: the graph holds one shading system per kind a scene uses,
        /// and `sort_by_material` one queue per kind, in this order. What each kind is comes
        /// from its `Bsdf` type's consts.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum MaterialKind {
            $($kind,)+
        }

        $(
            impl ListedMaterial for $bsdf {
                const KIND: MaterialKind = MaterialKind::$kind;
                #[inline(always)]
                fn of(material: &Material) -> Option<&Self> {
                    match material {
                        Material::$kind(m) => Some(m),
                        _ => None,
                    }
                }
            }
        )+

        impl MaterialKind {
            /// Every kind, in queue order.
            pub const ALL: [MaterialKind; [$(MaterialKind::$kind),+].len()] =
                [$(MaterialKind::$kind),+];
            pub const COUNT: usize = MaterialKind::ALL.len();

            /// `Bsdf::IS_DELTA` of the kind.
            pub const fn is_delta(self) -> bool {
                match self {
                    $(MaterialKind::$kind => <$bsdf as Bsdf>::IS_DELTA,)+
                }
            }

            /// `Bsdf::HAS_DELTA_LOBE` of the kind.
            pub const fn has_delta_lobe(self) -> bool {
                match self {
                    $(MaterialKind::$kind => <$bsdf as Bsdf>::HAS_DELTA_LOBE,)+
                }
            }

            /// `Bsdf::TRANSMITS` of the kind.
            pub const fn transmits(self) -> bool {
                match self {
                    $(MaterialKind::$kind => <$bsdf as Bsdf>::TRANSMITS,)+
                }
            }

            /// The name of the shading system of this kind.
            pub const fn shading_system(self) -> &'static str {
                match self {
                    $(MaterialKind::$kind => <$bsdf as Bsdf>::SHADING_SYSTEM,)+
                }
            }

            /// Runs `visitor` for this kind's `Bsdf` type. Always inlined: a visitor called
            /// from a lane kernel must be compiled into that kernel's copy for the CPU's
            /// vector instructions (`run_lanes`); out of line it ran on the baseline's.
            #[inline(always)]
            pub fn visit<V: KindVisitor>(self, visitor: V) -> V::Output {
                match self {
                    $(MaterialKind::$kind => visitor.visit::<$bsdf>(),)+
                }
            }
        }

        impl Material {
            pub fn kind(&self) -> MaterialKind {
                match self {
                    $(Material::$kind(_) => MaterialKind::$kind,)+
                }
            }

            /// `Bsdf::two_sided` of the material.
            pub fn is_two_sided(&self) -> bool {
                match self {
                    $(Material::$kind(m) => m.two_sided(),)+
                }
            }

            /// f(wo, wi) for what the path carries: only refraction tells the two apart.
            pub fn eval_mode(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Vec3 {
                match self {
                    $(Material::$kind(m) => m.eval(wo, wi, mode),)+
                }
            }

            /// Solid-angle density with which `sample` returns `wi`; zero for delta materials
            /// (the smooth plastic's diffuse lobe's, times the probability of choosing that
            /// lobe).
            pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
                match self {
                    $(Material::$kind(m) => m.pdf(wo, wi),)+
                }
            }

            /// `eval_mode` and `pdf` at once.
            #[inline]
            pub fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Vec3, f32) {
                match self {
                    $(Material::$kind(m) => m.eval_pdf(wo, wi, mode),)+
                }
            }

            /// `eval_mode` for world-space directions about the shading normal `ns`.
            #[inline]
            pub fn eval_world(&self, ns: Vec3, wo: Vec3, wi: Vec3, mode: TransportMode) -> Vec3 {
                match self {
                    $(Material::$kind(m) => m.eval_world(ns, wo, wi, mode),)+
                }
            }

            /// `pdf` for world-space directions about the shading normal `ns`.
            #[inline]
            pub fn pdf_world(&self, ns: Vec3, wo: Vec3, wi: Vec3) -> f32 {
                match self {
                    $(Material::$kind(m) => m.pdf_world(ns, wo, wi),)+
                }
            }

            /// Samples wi given wo; `None` when the sample carries no energy. Inlined so that
            /// a loop that sees one material kind keeps only that kind's arm hot.
            #[inline(always)]
            pub fn sample(&self, wo: Vec3, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
                match self {
                    $(Material::$kind(m) => m.sample(wo, u, mode),)+
                }
            }
        }
    };
}

materials! {
    Diffuse(diffuse::Diffuse),
    Conductor(conductor::Conductor),
    RoughPlastic(plastic::RoughPlastic),
    RoughDielectric(rough_dielectric::RoughDielectric),
    Plastic(smooth_plastic::SmoothPlastic),
    Dielectric(dielectric::Dielectric),
    ThinDielectric(dielectric::ThinDielectric),
}

// Materials are copied by value into every shading point and visible point: keep them small
// (the anisotropic conductor, with its Fresnel indices, two roughnesses and axis, is the largest).
const _: () = assert!(std::mem::size_of::<Material>() <= 56);

// `ALL` lists the kinds in their queue order, the non-delta ones first.
const _: () = {
    let mut i = 0;
    while i < MaterialKind::COUNT {
        assert!(MaterialKind::ALL[i] as usize == i);
        assert!(i == 0 || MaterialKind::ALL[i].is_delta() || !MaterialKind::ALL[i - 1].is_delta());
        i += 1;
    }
};

impl Material {
    /// f(wo, wi) without the cosine, for radiance; zero for delta materials (the smooth
    /// plastic's diffuse lobe alone: its delta reflection only `sample` returns).
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.eval_mode(wo, wi, TransportMode::Radiance)
    }
}

/// Whether a path carries radiance (from the camera) or importance (from a light): refraction
/// scales radiance by 1/eta^2 but not importance, which makes the BSDF non-symmetric.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransportMode {
    Radiance,
    Importance,
}

/// A sampled direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    pub wi: Vec3,
    /// f(wo, wi), without the cosine.
    pub value: Vec3,
    /// Solid-angle density of `wi` (for delta lobes, the discrete probability of the lobe).
    pub pdf: f32,
    pub delta: bool,
}

impl BsdfSample {
    /// A sample of a non-delta lobe whose value and pdf `eval` and `pdf` give at `wi` (so
    /// that MIS sees the same densities); None where the pdf is not positive and finite or
    /// the value is zero.
    #[inline]
    pub fn of_lobe(wi: Vec3, value: Vec3, pdf: f32) -> Option<BsdfSample> {
        (pdf > 0.0 && pdf.is_finite() && value != Vec3::ZERO).then_some(BsdfSample {
            wi,
            value,
            pdf,
            delta: false,
        })
    }
}

/// A sample of a non-delta lobe for one path or lanes (`BsdfSample` where `valid` is set;
/// elsewhere the sample carries nothing): what the materials' lane forms return.
#[derive(Clone, Copy, Debug)]
pub struct LobeSample<T: Real> {
    pub valid: T::Mask,
    pub wi: V3<T>,
    pub value: V3<T>,
    pub pdf: T,
}

impl<T: Real> LobeSample<T> {
    /// No sample in any lane.
    #[inline(always)]
    pub fn none() -> LobeSample<T> {
        LobeSample {
            valid: T::Mask::splat(false),
            wi: V3::splat(Vec3::Z),
            value: V3::splat(Vec3::ZERO),
            pdf: T::splat(0.0),
        }
    }

    /// `BsdfSample::of_lobe` where `kept`: valid where the pdf is positive and finite and the
    /// value not zero.
    #[inline(always)]
    pub fn of_lobe(kept: T::Mask, wi: V3<T>, value: V3<T>, pdf: T) -> LobeSample<T> {
        let finite_pdf = pdf.greater(T::splat(0.0)) & pdf.less(T::splat(f32::INFINITY));
        LobeSample {
            valid: kept & finite_pdf & !value.is_zero(),
            wi,
            value,
            pdf,
        }
    }
}

impl LobeSample<f32> {
    /// The one path's sample, if any.
    #[inline(always)]
    pub fn one(self) -> Option<BsdfSample> {
        self.valid.then(|| BsdfSample {
            wi: self.wi.into(),
            value: self.value.into(),
            pdf: self.pdf,
            delta: false,
        })
    }
}

/// Samples `material` at a surface and turns the sample into a world direction `wi`: `frame`
/// is the shading frame, `ng` the geometric normal (both on the side the caller shades), `wo`
/// the direction back along the incoming ray and `wo_local` the same in `frame`. `None` when
/// the sample carries nothing (no sample, `pdf <= 0`) or leaves through the wrong geometric
/// side: reflection must leave on wo's side of the geometric surface and refraction on the
/// other, which shading normals alone would not ensure (light would leak through surfaces).
#[inline(always)]
pub fn sample_direction(
    material: &Material,
    frame: &crate::math::Frame,
    ng: Vec3,
    wo: Vec3,
    wo_local: Vec3,
    u: Vec2,
    mode: TransportMode,
) -> Option<(BsdfSample, Vec3)> {
    leaving_direction(material.sample(wo_local, u, mode)?, frame, ng, wo, wo_local)
}

/// `sample_direction` for a sample `bs` already drawn (by one material type's own `sample`,
/// where the caller knows the type).
#[inline(always)]
pub fn leaving_direction(
    bs: BsdfSample,
    frame: &crate::math::Frame,
    ng: Vec3,
    wo: Vec3,
    wo_local: Vec3,
) -> Option<(BsdfSample, Vec3)> {
    if bs.pdf <= 0.0 {
        return None;
    }
    let wi = frame.to_world(bs.wi).normalize();
    let reflected = bs.wi.z * wo_local.z > 0.0;
    if (wi.dot(ng) * wo.dot(ng) > 0.0) != reflected {
        return None;
    }
    Some((bs, wi))
}

/// Whether a material of `kind` may scatter between two directions at a surface, from their
/// cosines with the geometric normal (`wo_ng`, `wi_ng`) and the shading normal (`wo_ns`,
/// `wi_ns`): reflection on the geometric surface, and where the kind transmits (see
/// `MaterialKind::transmits`) refraction too, when the shading frame sees the same (shading
/// normals alone would let light leak through surfaces). What the BSDF then makes of the pair
/// is its `eval`.
#[inline]
pub fn scatters_between(
    kind: MaterialKind,
    wo_ng: f32,
    wi_ng: f32,
    wo_ns: f32,
    wi_ns: f32,
) -> bool {
    let reflected = wo_ng * wi_ng > 0.0;
    if kind.transmits() {
        let refracted = wo_ng * wi_ng < 0.0;
        (reflected && wo_ns * wi_ns > 0.0) || (refracted && wo_ns * wi_ns < 0.0)
    } else {
        reflected
    }
}
