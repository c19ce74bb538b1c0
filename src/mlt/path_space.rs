//! Path space for Veach's MLT (`--integrator mlt`): a path as a list of vertices from the light
//! (x_0, on an emitter) to the camera (x_{n-1}), its measurement contribution f(x), the area
//! densities with which a subpath sampler would make each vertex, and the scalar sampling and
//! tracing the mutations (systems/mutate/) regrow paths with.
//!
//! Delta lobes (the smooth dielectric) follow one convention everywhere, as in Veach's thesis
//! and pbrt's BDPT: the Dirac factor is left out of both the BSDF and the density. At a
//! specular vertex f(x) holds the lobe's weight (F, or (1 - F) / eta^2 for radiance through a
//! refraction) and a sampler's "density" is the lobe's discrete probability; f(y) / T(x -> y)
//! is then finite and right, because a mutation samples every specular vertex it regrows
//! through the same lobe (the connecting edge never touches one).
//!
//! f(x) = Le(x_0 -> x_1) * prod_i [fs(x_i) |wi . ns_i|] * prod_edges [|cos at the edge's light
//! end (geometric)| / d^2] * W(x_{n-2}), with W the camera's importance times its cosine
//! (`Frustum::project`): the estimator of the whole film's mean, as a path tracer's sample is,
//! so an image is splats x pixels / mutations.

use crate::accel::Accel;
use crate::bsdf::dielectric::{Dielectric, ThinDielectric};
use crate::bsdf::dielectric::{fresnel, thin_reflectance};
use crate::bsdf::{Material, TransportMode, sample_direction};
use crate::components::CAMERA_VERTEX;
use crate::geometry::{offset_ray_origin, spawn_ray_to, surface_point};
use crate::math::Frame;
use crate::path::{PathContext, Vertex, VertexKind, local_frame, to_area};
use crate::sampling::{SampleKey, cosine_hemisphere};
use crate::scene::SceneData;
use crate::systems::shade::sort_by_material::shading_point;
use glam::{DVec3, Vec2, Vec3};
use std::f32::consts::PI;

/// A path, light first.
pub type Path = Vec<Vertex>;

/// Random numbers of one chain's step: dimension after dimension of its key.
/// Where a path lands on the film: its pixel and its raster position there (the gaussian
/// filter spreads its splats from that point).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Landing {
    pub pixel: u32,
    pub at: glam::Vec2,
}

pub struct StepNumbers {
    key: SampleKey,
    next: u32,
}

impl StepNumbers {
    pub fn new(key: SampleKey, first: u32) -> StepNumbers {
        StepNumbers { key, next: first }
    }
    #[inline]
    pub fn get(&mut self) -> f32 {
        let u = self.key.get(self.next);
        self.next += 1;
        u
    }
    #[inline]
    pub fn get2(&mut self) -> Vec2 {
        Vec2::new(self.get(), self.get())
    }
}

/// What the path-space functions need of the scene.
#[derive(Clone, Copy)]
pub struct PathSpace<'a> {
    pub ctx: PathContext<'a>,
    pub accel: &'a Accel,
    pub data: &'a SceneData,
}

/// The unit direction from `a` to `b`; a vertex at infinity is a direction (its `ng`, the way
/// its light travels), whatever its far point.
#[inline]
pub fn dir(a: &Vertex, b: &Vertex) -> Vec3 {
    if a.is_at_infinity() {
        return a.ng;
    }
    if b.is_at_infinity() {
        return -b.ng;
    }
    (b.p - a.p).normalize_or_zero()
}

impl<'a> PathSpace<'a> {
    pub fn new(data: &'a SceneData) -> PathSpace<'a> {
        PathSpace {
            ctx: PathContext::new(&data.scene),
            accel: &data.accel,
            data,
        }
    }

    /// The camera vertex.
    pub fn camera_vertex(&self) -> Vertex {
        let cam = &self.ctx.camera;
        Vertex {
            kind: VertexKind::Camera,
            p: cam.position,
            p_error: Vec3::ZERO,
            ng: cam.forward,
            ns: cam.forward,
            triangle: CAMERA_VERTEX,
            beta: Vec3::ZERO,
            pdf_fwd: 0.0,
            pdf_rev: 0.0,
            delta: false,
        }
    }

    /// Whether `v` scatters by a delta lobe in this path: at a delta material always; at a
    /// material with a delta lobe beside a non-delta one (the smooth plastic) when the
    /// vertex's `delta` says so. That flag is the vertex's role in the path: set where a
    /// subpath sampled the delta lobe there, cleared at a joint (a connection evaluates the
    /// non-delta lobe), kept by a perturbation's new vertex from the one it replaces
    /// (`in_role_of`). The contribution, the densities and the specular chains all read it.
    #[inline]
    pub fn is_specular(&self, v: &Vertex) -> bool {
        if !v.is_on_surface() {
            return false;
        }
        let kind = self.ctx.material(v).kind();
        kind.is_delta() || (v.delta && kind.has_delta_lobe())
    }

    /// `hit`, a perturbation's new vertex in place of `old`, in `old`'s role (its lobe, delta
    /// or not, where its material has both).
    #[inline]
    pub fn in_role_of(&self, mut hit: Vertex, old: &Vertex) -> Vertex {
        hit.delta =
            old.delta && hit.is_on_surface() && self.ctx.material(&hit).kind().has_delta_lobe();
        hit
    }

    /// The surface vertex of a point on triangle `triangle` given its position (the light
    /// vertices BDPT stores carry the geometric normal as shading normal; a path vertex
    /// carries the surface's own, whatever role it plays).
    pub fn reshade(&self, v: &Vertex) -> Vertex {
        if v.kind == VertexKind::Camera || v.is_point_light() || v.is_at_infinity() {
            return *v;
        }
        let tris = &self.data.scene.triangles;
        let i = v.triangle as usize;
        let (p0, p1, p2) = (tris.p0[i], tris.p1[i], tris.p2[i]);
        let n = (p1 - p0).cross(p2 - p0);
        let area2 = n.length_squared();
        if area2 == 0.0 {
            return *v;
        }
        let b1 = (v.p - p0).cross(p2 - p0).dot(n) / area2;
        let b2 = (p1 - p0).cross(v.p - p0).dot(n) / area2;
        let sp = surface_point(tris, v.triangle, b1, b2);
        let ns = if sp.ns.dot(sp.ng) < 0.0 {
            -sp.ns
        } else {
            sp.ns
        };
        Vertex { ns, ..*v }
    }

    /// Sets every vertex's kind from its place: light, surfaces, camera.
    pub fn fix_kinds(path: &mut [Vertex]) {
        let n = path.len();
        for (i, v) in path.iter_mut().enumerate() {
            v.kind = if i + 1 == n {
                VertexKind::Camera
            } else if i == 0 {
                VertexKind::Light
            } else {
                VertexKind::Surface
            };
        }
    }

    /// f(x) and where on the film the path lands; `None` when it carries nothing (or leaves
    /// the image). Visibility is not tested here: every edge of a path a mutation makes was traced
    /// or tested when made.
    /// f is kept in f64: a product of many 1 / d^2 (scenes in millimetres) leaves f32's range.
    pub fn contribution(&self, path: &[Vertex]) -> Option<(DVec3, Landing)> {
        let n = path.len();
        if n < 2 || path[n - 1].kind != VertexKind::Camera || path[0].kind != VertexKind::Light {
            return None;
        }
        if n == 2 && path[0].is_point_light() {
            // Point lights are not seen directly (`PathContext::connect_to_camera`).
            return None;
        }
        let cam = &path[n - 1];
        let (pixel, at, importance) = self.ctx.camera.project(dir(cam, &path[n - 2]))?;
        let le = self.ctx.emitted(&path[0], dir(&path[0], &path[1]));
        let mut f = le.as_dvec3() * f64::from(importance);
        if f == DVec3::ZERO {
            return None;
        }
        for i in 0..n - 1 {
            let (a, b) = (&path[i], &path[i + 1]);
            if a.is_at_infinity() {
                // Light from a direction: its density is in solid angle there, and the cosine
                // at b is b's own (`scatter_weight`): no factor on this edge.
                continue;
            }
            if b.is_at_infinity() {
                return None; // only the light end of a path lies at infinity
            }
            let d = b.p - a.p;
            let dist2 = d.length_squared();
            if dist2 == 0.0 {
                return None;
            }
            // The cosine at a; a point light has none (its intensity is per solid angle).
            let cos_a = if a.is_point_light() {
                dist2.sqrt()
            } else {
                a.ng.dot(d).abs()
            };
            f *= f64::from(cos_a) / (f64::from(dist2) * f64::from(dist2).sqrt());
        }
        for i in 1..n - 1 {
            let v = &path[i];
            let wo = dir(v, &path[i + 1]);
            let wi = dir(v, &path[i - 1]);
            f *= self
                .scatter_weight(v, wo, wi, TransportMode::Radiance)
                .as_dvec3();
            if f == DVec3::ZERO {
                return None;
            }
        }
        (f.is_finite() && f.max_element() > 0.0).then_some((
            f,
            Landing {
                pixel: pixel as u32,
                at,
            },
        ))
    }

    /// fs(wo, wi) |wi . ns| at a surface vertex (`wo` towards the camera side for radiance),
    /// the delta factor left out at a specular vertex.
    pub fn scatter_weight(&self, v: &Vertex, wo: Vec3, wi: Vec3, mode: TransportMode) -> Vec3 {
        match self.ctx.material(v) {
            Material::Dielectric(Dielectric { ior }) => match specular_lobe(v, wo, wi) {
                Some(reflect) => {
                    let f = fresnel(wo.dot(v.ns), ior);
                    if reflect {
                        Vec3::splat(f)
                    } else {
                        let eta = if wo.dot(v.ns) >= 0.0 { ior } else { 1.0 / ior };
                        let scale = match mode {
                            TransportMode::Radiance => 1.0 / (eta * eta),
                            TransportMode::Importance => 1.0,
                        };
                        Vec3::splat((1.0 - f) * scale)
                    }
                }
                None => Vec3::ZERO,
            },
            // The smooth plastic's reflection, in the delta role (`is_specular`).
            Material::Plastic(p) if v.delta => {
                // The cosine on the side the coat faces (either, inside `twosided`).
                let cos = if p.two_sided {
                    wo.dot(v.ns).abs()
                } else {
                    wo.dot(v.ns)
                };
                match specular_lobe(v, wo, wi) {
                    Some(true) if cos > 0.0 => p.specular * fresnel(cos, p.eta),
                    _ => Vec3::ZERO,
                }
            }
            // Thin glass: R' back, 1 - R' straight on, in either mode (no index change).
            Material::ThinDielectric(ThinDielectric { ior }) => match specular_lobe(v, wo, wi) {
                Some(true) => Vec3::splat(thin_reflectance(wo.dot(v.ns), ior)),
                Some(false) => Vec3::splat(1.0 - thin_reflectance(wo.dot(v.ns), ior)),
                None => Vec3::ZERO,
            },
            _ => self.ctx.f(v, wo, wi, mode) * wi.dot(v.ns).abs(),
        }
    }

    /// Solid-angle density with which a subpath at `v`, arrived from direction `wo` (towards
    /// its previous vertex), samples `wi`; at a specular vertex the lobe's probability.
    pub fn pdf_dir(&self, v: &Vertex, wo: Vec3, wi: Vec3) -> f32 {
        if v.kind == VertexKind::Surface {
            if let Material::Plastic(p) = self.ctx.material(v)
                && v.delta
            {
                let cos = if p.two_sided {
                    wo.dot(v.ns).abs()
                } else {
                    wo.dot(v.ns)
                };
                return match specular_lobe(v, wo, wi) {
                    Some(true) if cos > 0.0 => p.specular_probability(cos),
                    _ => 0.0,
                };
            }
            let reflectance = match self.ctx.material(v) {
                Material::Dielectric(Dielectric { ior }) => Some(fresnel(wo.dot(v.ns), ior)),
                Material::ThinDielectric(ThinDielectric { ior }) => {
                    Some(thin_reflectance(wo.dot(v.ns), ior))
                }
                _ => None,
            };
            if let Some(r) = reflectance {
                return match specular_lobe(v, wo, wi) {
                    Some(true) => r,
                    Some(false) => 1.0 - r,
                    None => 0.0,
                };
            }
        }
        self.ctx.pdf_dir(v, wo, wi)
    }

    /// Area density at `path[to]` of sampling it from `path[from]` (adjacent), the sampler
    /// having reached `path[from]` from its other neighbour: light-side samplers move up the
    /// indices, camera-side ones down. `path[0]` as a light-side origin is sampled on the
    /// emitters.
    pub fn density(&self, path: &[Vertex], from: Option<usize>, to: usize) -> f32 {
        let Some(from) = from else {
            return self.ctx.pdf_light_origin(&path[to]);
        };
        if to < from && path[to].is_point_light() {
            // No sampled direction from the camera side hits a point.
            return 0.0;
        }
        let v = &path[from];
        let wi = dir(v, &path[to]);
        let pdf = if to > from {
            // Light side.
            match v.kind {
                VertexKind::Light => return self.ctx.pdf_light_dir(v, &path[to]),
                _ => self.pdf_dir(v, dir(v, &path[from - 1]), wi),
            }
        } else {
            match v.kind {
                VertexKind::Camera => self.ctx.camera.pdf_dir(wi),
                _ => self.pdf_dir(v, dir(v, &path[from + 1]), wi),
            }
        };
        to_area(pdf, v, &path[to])
    }

    /// Density of the vertices `path[lo..lo + count]` (the rest kept) had a light subpath made
    /// the first `s` of them from `path[lo - 1]` (or from an emitter when lo = 0) and a camera
    /// subpath the others from `path[lo + count]`, joined by one edge; 0 where that split
    /// cannot make the path (a joint at a specular vertex).
    pub fn split_density(&self, path: &[Vertex], lo: usize, count: usize, s: usize) -> f64 {
        let joint_light = (lo + s).checked_sub(1);
        let joint_camera = lo + s;
        let joins = |v: &Vertex| self.ctx.is_connectible(v) && !self.is_specular(v);
        if let Some(a) = joint_light
            && (!joins(&path[a]) || !joins(&path[joint_camera]))
        {
            return 0.0;
        }
        let mut d = 1.0f64;
        for i in lo..lo + s {
            d *= f64::from(self.density(path, i.checked_sub(1), i));
        }
        for i in (lo + s..lo + count).rev() {
            d *= f64::from(self.density(path, Some(i + 1), i));
        }
        d
    }

    /// The first surface along `dir` from `from`, as a vertex.
    pub fn trace(&self, from: &Vertex, dir: Vec3) -> Option<Vertex> {
        let origin = match from.kind {
            VertexKind::Camera => from.p,
            _ => offset_ray_origin(from.p, from.p_error, from.ng, dir),
        };
        self.first_surface(origin, dir)
    }

    /// The surface vertex where the ray (origin, dir) first hits, its shading normal turned to
    /// the geometric one's side.
    fn first_surface(&self, origin: Vec3, dir: Vec3) -> Option<Vertex> {
        let hit = self.accel.closest_hit(origin, dir, f32::INFINITY)?;
        let sp = shading_point(&self.data.scene.triangles, hit.triangle, hit.b1, hit.b2);
        Some(Vertex {
            kind: VertexKind::Surface,
            p: sp.p,
            p_error: sp.p_error,
            ng: sp.ng,
            ns: sp.ns,
            triangle: hit.triangle,
            beta: Vec3::ZERO,
            pdf_fwd: 0.0,
            pdf_rev: 0.0,
            delta: false,
        })
    }

    /// The first surface along `dir` from `from`, or where the ray leaves the scene, the
    /// environment's vertex that way (a path's light end; `None` without an environment).
    pub fn trace_or_sky(&self, from: &Vertex, dir: Vec3) -> Option<Vertex> {
        if let Some(hit) = self.trace(from, dir) {
            return Some(hit);
        }
        self.data.scene.emitters.environment()?;
        Some(self.at_infinity(-dir, crate::scene::ENVIRONMENT, from.p))
    }

    /// A light vertex at infinity whose light travels along `travel` (unit), tagged
    /// `triangle`, its far point beyond the scene from `seen_from`.
    fn at_infinity(&self, travel: Vec3, triangle: u32, seen_from: Vec3) -> Vertex {
        Vertex {
            kind: VertexKind::Light,
            p: self.data.scene.emitters.disk.far_point(seen_from, -travel),
            p_error: Vec3::ZERO,
            ng: travel,
            ns: travel,
            triangle,
            beta: Vec3::ZERO,
            pdf_fwd: 0.0,
            pdf_rev: 0.0,
            delta: false,
        }
    }

    /// The first surface a light path from `v` (at infinity) meets, leaving the disk across
    /// the scene at the point for `u`; the solid-angle-like density of that choice is the
    /// disk's (`PathContext::pdf_light_dir`).
    pub fn trace_from_infinity(&self, v: &Vertex, u: Vec2) -> Option<Vertex> {
        self.first_surface(self.data.scene.emitters.disk.origin(-v.ng, u), v.ng)
    }

    /// Whether nothing lies between `a` and `b` (to the end of the scene where one of them
    /// lies at infinity).
    pub fn visible(&self, a: &Vertex, b: &Vertex) -> bool {
        let (near, far) = match (a.is_at_infinity(), b.is_at_infinity()) {
            (true, _) => (b, a),
            (_, true) => (a, b),
            _ => {
                let (origin, d, t_max) = spawn_ray_to(a.p, a.p_error, a.ng, b.p, b.p_error, b.ng);
                return !self.accel.any_hit(origin, d, t_max);
            }
        };
        let d = -far.ng;
        let origin = match near.kind {
            VertexKind::Camera => near.p,
            _ => offset_ray_origin(near.p, near.p_error, near.ng, d),
        };
        !self.accel.any_hit(origin, d, f32::INFINITY)
    }

    /// A light vertex by power: a point uniform on an emitter, a point light, or a direction
    /// at infinity (the environment's by its distribution, a directional light's own), as
    /// BDPT's s = 1 strategy draws it from the same numbers.
    pub fn sample_light_origin(&self, u_pick: f32, u_point: Vec2) -> Option<Vertex> {
        let scene = &self.data.scene;
        if scene.emitters.triangle.is_empty() {
            return None;
        }
        if let Some((e, env)) = scene.emitters.environment()
            && crate::sampling::sample_cdf(&scene.emitters.cdf, u_pick) == e
        {
            let (towards_light, pdf) = env.sample(u_point);
            return (pdf > 0.0).then(|| {
                self.at_infinity(
                    -towards_light,
                    crate::scene::ENVIRONMENT,
                    scene.emitters.disk.center,
                )
            });
        }
        let e = self.data.scene.sample_emitter(u_pick, u_point);
        if scene.emitters.is_directional(e.emitter) {
            let travel = scene.emitters.position[e.emitter];
            return Some(self.at_infinity(travel, e.triangle, scene.emitters.disk.center));
        }
        let sp = e.point;
        let ns = if sp.ns.dot(sp.ng) < 0.0 {
            -sp.ns
        } else {
            sp.ns
        };
        Some(Vertex {
            kind: VertexKind::Light,
            p: sp.p,
            p_error: sp.p_error,
            ng: sp.ng,
            ns,
            triangle: e.triangle,
            beta: Vec3::ZERO,
            pdf_fwd: 0.0,
            pdf_rev: 0.0,
            delta: false,
        })
    }

    /// A direction out of `v` as a subpath would sample it (the camera's ray with the raster
    /// position uniform, the light's cosine lobe, or the BSDF, arrived from `wo`), the
    /// solid-angle density the sampler reports for it (a delta lobe's probability) and
    /// whether a delta lobe made it (`v`'s role then: `is_specular`).
    pub fn sample_direction(
        &self,
        v: &Vertex,
        wo: Vec3,
        u: Vec2,
        mode: TransportMode,
    ) -> Option<(Vec3, f32, bool)> {
        match v.kind {
            VertexKind::Camera => {
                let cam = &self.ctx.camera;
                let raster = Vec2::new(u.x * cam.width as f32, u.y * cam.height as f32);
                let w = cam.direction(raster);
                Some((w, cam.pdf_dir(w), false))
            }
            // Its paths leave a disk, not a point: `trace_from_infinity`.
            VertexKind::Light if v.is_at_infinity() => None,
            VertexKind::Light if v.is_point_light() => {
                let profile = self
                    .ctx
                    .point_profile(v)
                    .unwrap_or(&crate::scene::lights::PointProfile::Uniform);
                let (w, pdf) = crate::scene::lights::sample_direction(profile, u);
                (pdf > 0.0).then_some((w, pdf, false))
            }
            VertexKind::Light => {
                let local = cosine_hemisphere(u);
                (local.z > 0.0).then(|| {
                    (
                        Frame::from_normal(v.ng).to_world(local).normalize(),
                        local.z * std::f32::consts::FRAC_1_PI,
                        false,
                    )
                })
            }
            VertexKind::Surface => {
                let (material, frame, ng) = local_frame(self.ctx.scene, v, wo);
                let (bs, wi) =
                    sample_direction(&material, &frame, ng, wo, frame.to_local(wo), u, mode)?;
                (bs.value.max_element() > 0.0).then_some((wi, bs.pdf, bs.delta))
            }
        }
    }

    /// The direction a specular vertex sends `wo` to by reflection (`reflect`) or refraction
    /// (thin glass: straight through, `-wo`); `None` under total internal reflection (or where
    /// thin glass reflects everything) or where the shading normal would send it through the
    /// wrong geometric side.
    pub fn follow_specular(&self, v: &Vertex, wo: Vec3, reflect: bool) -> Option<Vec3> {
        let ior = match self.ctx.material(v) {
            Material::Dielectric(Dielectric { ior }) => ior,
            // The plastic's delta lobe only reflects (its `eta` is not used below then).
            Material::Plastic(p) if v.delta && reflect => p.eta,
            Material::ThinDielectric(ThinDielectric { ior }) if !reflect => {
                // Straight on: -wo is on the other geometric side whatever the normals.
                return (thin_reflectance(wo.dot(v.ns), ior) < 1.0 && wo.dot(v.ng) != 0.0)
                    .then_some(-wo);
            }
            Material::ThinDielectric(ThinDielectric { ior }) => ior,
            _ => return None,
        };
        let frame = Frame::from_normal(v.ns);
        let w = frame.to_local(wo);
        let local = if reflect {
            Vec3::new(-w.x, -w.y, w.z)
        } else {
            let outside = w.z >= 0.0;
            let eta = if outside { ior } else { 1.0 / ior };
            let sin2_t = (w.x * w.x + w.y * w.y) / (eta * eta);
            if sin2_t >= 1.0 {
                return None;
            }
            let cos_t = (1.0 - sin2_t).sqrt();
            Vec3::new(-w.x / eta, -w.y / eta, if outside { -cos_t } else { cos_t })
        };
        let wi = frame.to_world(local).normalize();
        ((wi.dot(v.ng) * wo.dot(v.ng) > 0.0) == reflect).then_some(wi)
    }

    /// Luminance of f (Rec. 709, as `math::luminance`), the chains' target.
    #[inline]
    pub fn target(f: DVec3) -> f64 {
        0.2126 * f.x + 0.7152 * f.y + 0.0722 * f.z
    }
}

/// Whether `wi` leaves a specular vertex by reflection (`Some(true)`) or refraction, judged by
/// the geometric sides of `wo` and `wi`.
#[inline]
pub fn specular_lobe(v: &Vertex, wo: Vec3, wi: Vec3) -> Option<bool> {
    let (a, b) = (wo.dot(v.ng), wi.dot(v.ng));
    if a == 0.0 || b == 0.0 {
        return None;
    }
    Some(a * b > 0.0)
}

/// A 2D offset of length log-uniform in [r_min, r_max] (density ~ 1/r^2 on the plane, as
/// Veach's perturbations), any direction: symmetric, so its density cancels in acceptance.
pub fn perturb_offset(u: Vec2, r_min: f32, r_max: f32) -> Vec2 {
    let r = r_max * (r_min / r_max).powf(u.x);
    let phi = 2.0 * PI * u.y;
    Vec2::new(r * phi.cos(), r * phi.sin())
}

/// `w` (unit) turned by an angle log-uniform in [theta_min, theta_max] about a uniformly
/// chosen axis: the density depends only on the angle, so it is symmetric.
pub fn perturb_direction(w: Vec3, u: Vec2, theta_min: f32, theta_max: f32) -> Vec3 {
    let theta = theta_max * (theta_min / theta_max).powf(u.x);
    let phi = 2.0 * PI * u.y;
    let frame = Frame::from_normal(w);
    let (s, c) = theta.sin_cos();
    frame
        .to_world(Vec3::new(s * phi.cos(), s * phi.sin(), c))
        .normalize()
}
