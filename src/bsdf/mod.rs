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

use glam::{Vec2, Vec3};

/// A material as SCENES.md defines them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Lambertian, reflecting on both sides.
    Diffuse { reflectance: Vec3 },
    /// Smooth dielectric: exact unpolarised Fresnel, refraction, total internal reflection.
    /// `ior` is the index inside (the side opposite the geometric normal) over outside.
    Dielectric { ior: f32 },
    /// Rough conductor (GGX or Beckmann microfacets, possibly anisotropic): a conductor's Fresnel term
    /// times a reflectance, or the reflectance alone (see `conductor`).
    Conductor(conductor::Conductor),
    /// Rough plastic: a rough dielectric coat over a Lambertian base (see `plastic`).
    RoughPlastic(plastic::RoughPlastic),
    /// Rough dielectric: microfacets that reflect and refract (see `rough_dielectric`).
    RoughDielectric(rough_dielectric::RoughDielectric),
    /// Smooth plastic: a delta reflection off a smooth coat over a Lambertian base (see
    /// `smooth_plastic`): a delta lobe and a non-delta one.
    Plastic(smooth_plastic::SmoothPlastic),
    /// Thin dielectric sheet (Mitsuba's `thindielectric`): reflects R' (the Fresnel term of
    /// both faces and the light bouncing between them) and lets 1 - R' straight through.
    /// `ior` is the sheet's index over its surroundings'; alike from both sides.
    ThinDielectric { ior: f32 },
}

// Materials are copied by value into every shading point and visible point: keep them small
// (the anisotropic conductor, with its Fresnel indices, two roughnesses and axis, is the largest).
const _: () = assert!(std::mem::size_of::<Material>() <= 56);

/// The kind of a material: the graph holds one shading system per kind a scene uses, and
/// `sort_by_material` one queue per kind, in this order: the kinds with a non-delta lobe
/// first, so light sampling runs over one contiguous range of slots. What each kind is (delta
/// or not, reflecting on both sides or not, its system's name) is said here once.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MaterialKind {
    Diffuse = 0,
    Conductor = 1,
    RoughPlastic = 2,
    RoughDielectric = 3,
    Plastic = 4,
    Dielectric = 5,
    ThinDielectric = 6,
}

impl MaterialKind {
    /// Every kind, in queue order.
    pub const ALL: [MaterialKind; 7] = [
        MaterialKind::Diffuse,
        MaterialKind::Conductor,
        MaterialKind::RoughPlastic,
        MaterialKind::RoughDielectric,
        MaterialKind::Plastic,
        MaterialKind::Dielectric,
        MaterialKind::ThinDielectric,
    ];
    pub const COUNT: usize = MaterialKind::ALL.len();

    /// Whether every lobe is a Dirac delta: light sampling and connections cannot reach it.
    /// (The smooth plastic is not: its diffuse lobe is reached; see `has_delta_lobe`.)
    pub const fn is_delta(self) -> bool {
        match self {
            MaterialKind::Diffuse
            | MaterialKind::Conductor
            | MaterialKind::RoughPlastic
            | MaterialKind::RoughDielectric
            | MaterialKind::Plastic => false,
            MaterialKind::Dielectric | MaterialKind::ThinDielectric => true,
        }
    }

    /// Whether `sample` may return a delta lobe (`BsdfSample::delta`): the delta kinds, and
    /// the smooth plastic, whose specular reflection is a delta beside its diffuse lobe.
    pub const fn has_delta_lobe(self) -> bool {
        match self {
            MaterialKind::Diffuse
            | MaterialKind::Conductor
            | MaterialKind::RoughPlastic
            | MaterialKind::RoughDielectric => false,
            MaterialKind::Plastic | MaterialKind::Dielectric | MaterialKind::ThinDielectric => true,
        }
    }

    /// Whether a non-delta lobe transmits: connections, light samples and merges may then join
    /// the surface's two sides (where the shading frame agrees, see `scatters_between`).
    pub const fn transmits(self) -> bool {
        match self {
            MaterialKind::RoughDielectric => true,
            MaterialKind::Diffuse
            | MaterialKind::Conductor
            | MaterialKind::RoughPlastic
            | MaterialKind::Plastic
            | MaterialKind::Dielectric
            | MaterialKind::ThinDielectric => false,
        }
    }

    /// The name of the shading system of this kind.
    pub const fn shading_system(self) -> &'static str {
        match self {
            MaterialKind::Diffuse => "shade_diffuse",
            MaterialKind::Conductor => "shade_conductor",
            MaterialKind::RoughPlastic => "shade_rough_plastic",
            MaterialKind::RoughDielectric => "shade_rough_dielectric",
            MaterialKind::Plastic => "shade_plastic",
            MaterialKind::Dielectric => "shade_dielectric",
            MaterialKind::ThinDielectric => "shade_thin_dielectric",
        }
    }
}

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
    /// Whether it reflects alike on both sides of a surface: the engine turns the shading
    /// frame to the side a ray arrives from (Lambertian surfaces always; a conductor or a
    /// plastic inside Mitsuba's `twosided`). The others are black from behind, or transmit.
    pub const fn is_two_sided(&self) -> bool {
        match self {
            Material::Diffuse { .. } => true,
            Material::Conductor(c) => c.two_sided,
            Material::RoughPlastic(p) => p.two_sided,
            Material::Plastic(p) => p.two_sided,
            Material::RoughDielectric(_)
            | Material::Dielectric { .. }
            | Material::ThinDielectric { .. } => false,
        }
    }

    pub fn kind(&self) -> MaterialKind {
        match self {
            Material::Diffuse { .. } => MaterialKind::Diffuse,
            Material::Dielectric { .. } => MaterialKind::Dielectric,
            Material::Conductor(_) => MaterialKind::Conductor,
            Material::RoughPlastic(_) => MaterialKind::RoughPlastic,
            Material::RoughDielectric(_) => MaterialKind::RoughDielectric,
            Material::Plastic(_) => MaterialKind::Plastic,
            Material::ThinDielectric { .. } => MaterialKind::ThinDielectric,
        }
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
    let bs = material.sample(wo_local, u, mode)?;
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

impl Material {
    /// f(wo, wi) without the cosine, for radiance; zero for delta materials (the smooth
    /// plastic's diffuse lobe alone: its delta reflection only `sample` returns).
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.eval_mode(wo, wi, TransportMode::Radiance)
    }

    /// f(wo, wi) for what the path carries: only refraction tells the two apart.
    pub fn eval_mode(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Vec3 {
        match *self {
            Material::Diffuse { reflectance } => diffuse::eval(reflectance, wo, wi),
            Material::Dielectric { .. } | Material::ThinDielectric { .. } => Vec3::ZERO,
            Material::Conductor(c) => c.eval(wo, wi),
            Material::RoughPlastic(p) => p.eval(wo, wi),
            Material::RoughDielectric(d) => d.eval(wo, wi, mode),
            Material::Plastic(p) => p.eval(wo, wi),
        }
    }

    /// Solid-angle density with which `sample` returns `wi`; zero for delta materials (the
    /// smooth plastic's diffuse lobe's, times the probability of choosing that lobe).
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match *self {
            Material::Diffuse { .. } => diffuse::pdf(wo, wi),
            Material::Dielectric { .. } | Material::ThinDielectric { .. } => 0.0,
            Material::Conductor(c) => c.pdf(wo, wi),
            Material::RoughPlastic(p) => p.pdf(wo, wi),
            Material::RoughDielectric(d) => d.pdf(wo, wi),
            Material::Plastic(p) => p.pdf(wo, wi),
        }
    }

    /// `eval_mode` for world-space directions about the shading normal `ns`. The Lambertian
    /// lobe depends only on the two cosines, so it needs no frame (the common case in
    /// bidirectional connections, which evaluate many direction pairs per vertex).
    #[inline]
    pub fn eval_world(&self, ns: Vec3, wo: Vec3, wi: Vec3, mode: TransportMode) -> Vec3 {
        match *self {
            Material::Diffuse { reflectance } => {
                diffuse::eval_cos(reflectance.into(), wo.dot(ns), wi.dot(ns)).into()
            }
            Material::Dielectric { .. } | Material::ThinDielectric { .. } => Vec3::ZERO,
            Material::Conductor(_)
            | Material::RoughPlastic(_)
            | Material::RoughDielectric(_)
            | Material::Plastic(_) => {
                let frame = crate::math::Frame::from_normal(ns);
                self.eval_mode(frame.to_local(wo), frame.to_local(wi), mode)
            }
        }
    }

    /// `pdf` for world-space directions about the shading normal `ns`.
    #[inline]
    pub fn pdf_world(&self, ns: Vec3, wo: Vec3, wi: Vec3) -> f32 {
        match *self {
            Material::Diffuse { .. } => diffuse::pdf_cos(wo.dot(ns), wi.dot(ns)),
            Material::Dielectric { .. } | Material::ThinDielectric { .. } => 0.0,
            Material::Conductor(_)
            | Material::RoughPlastic(_)
            | Material::RoughDielectric(_)
            | Material::Plastic(_) => {
                let frame = crate::math::Frame::from_normal(ns);
                self.pdf(frame.to_local(wo), frame.to_local(wi))
            }
        }
    }

    /// Samples wi given wo; `None` when the sample carries no energy. Inlined so that each
    /// shading system's loop, which sees one material kind, keeps only that kind's arm hot.
    #[inline(always)]
    pub fn sample(&self, wo: Vec3, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        match *self {
            Material::Diffuse { reflectance } => diffuse::sample(reflectance, wo, u),
            Material::Dielectric { ior } => Some(dielectric::sample(ior, wo, u.x, mode)),
            Material::Conductor(c) => c.sample(wo, u),
            Material::RoughPlastic(p) => p.sample(wo, u),
            Material::RoughDielectric(d) => d.sample(wo, u, mode),
            Material::Plastic(p) => p.sample(wo, u),
            Material::ThinDielectric { ior } => Some(dielectric::sample_thin(ior, wo, u.x)),
        }
    }
}
