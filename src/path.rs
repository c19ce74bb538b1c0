//! Path-space building blocks of bidirectional methods (BDPT now; MLT over BDPT later): a
//! subpath vertex as a connection sees it, the densities of sampling one vertex from another
//! in area measure, the unweighted contribution of each connection strategy (s, t), and its
//! multiple-importance weight by Veach's ratio walk.
//!
//! Conventions follow Veach's thesis (ch. 10) and pbrt: a camera subpath z_0 .. z_{t-1}
//! (z_0 on the camera), a light subpath y_0 .. y_{s-1} (y_0 on an emitter), and strategy
//! (s, t) joins y_{s-1} to z_{t-1}. Each vertex stores `pdf_fwd`, the area density with which
//! its own subpath sampled it, and `pdf_rev`, the area density with which the other direction
//! would have; a strategy's weight needs only ratios of the two along the path, so the weight
//! of every strategy is found in one walk instead of by evaluating each from scratch.

use crate::bsdf::diffuse::Diffuse;
use crate::bsdf::{Material, TransportMode, scatters_between};
use crate::components::{CAMERA_VERTEX, PathVertex, PathVerticesView};
use crate::math::Frame;
use crate::scene::lights;
use crate::scene::{Frustum, NO_EMITTER, PreparedScene};
use glam::Vec3;
use std::f32::consts::FRAC_1_PI;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VertexKind {
    Camera,
    /// The first vertex of a light subpath (or a point sampled on an emitter): it emits.
    Light,
    Surface,
}

/// One vertex of a subpath, gathered from the `PathVertices` columns for a connection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vertex {
    pub kind: VertexKind,
    pub p: Vec3,
    pub p_error: Vec3,
    pub ng: Vec3,
    pub ns: Vec3,
    pub triangle: u32,
    pub beta: Vec3,
    pub pdf_fwd: f32,
    pub pdf_rev: f32,
    pub delta: bool,
}

impl Vertex {
    /// Vertex `i` of a view of the store of depth `depth` (a light subpath's vertex 0 is its
    /// light vertex; a camera subpath's is marked `CAMERA_VERTEX`).
    #[inline]
    pub fn from_store(store: &PathVerticesView, i: usize, depth: usize) -> Vertex {
        let v = store.get(i);
        let kind = match (depth, v.triangle) {
            (_, CAMERA_VERTEX) => VertexKind::Camera,
            (0, _) | (_, crate::scene::ENVIRONMENT) => VertexKind::Light,
            _ => VertexKind::Surface,
        };
        Vertex {
            kind,
            p: v.p,
            p_error: v.p_error,
            ng: v.ng,
            ns: v.ns,
            triangle: v.triangle,
            beta: v.beta,
            pdf_fwd: v.pdf_fwd,
            pdf_rev: v.pdf_rev,
            delta: v.delta,
        }
    }

    /// The vertex as its depth's store keeps it (the kind follows from depth and triangle).
    pub fn stored(&self) -> PathVertex {
        PathVertex {
            p: self.p,
            p_error: self.p_error,
            ng: self.ng,
            ns: self.ns,
            triangle: self.triangle,
            beta: self.beta,
            pdf_fwd: self.pdf_fwd,
            pdf_rev: self.pdf_rev,
            delta: self.delta,
        }
    }

    pub fn is_on_surface(&self) -> bool {
        self.kind != VertexKind::Camera && !self.is_point_light() && !self.is_at_infinity()
    }

    /// Whether this vertex lies on a light at infinity (the environment, or a directional
    /// light, which is also a point light: a delta direction): a light subpath's origin there,
    /// or where a camera subpath left the scene. Its `ng` is the direction light
    /// travels from it into the scene; its position a point beyond the scene along that line.
    /// Densities there are in solid angle, and the area density of the next vertex along a
    /// light path is the disk density times the cosine there (`to_area`).
    #[inline]
    pub fn is_at_infinity(&self) -> bool {
        crate::scene::is_at_infinity(self.triangle)
    }

    /// Whether this is a light subpath's vertex on a point light (a delta position: no other
    /// strategy can reach it, and it emits alike in every direction).
    #[inline]
    pub fn is_point_light(&self) -> bool {
        self.kind == VertexKind::Light && self.triangle & crate::scene::POINT_LIGHT != 0
    }
}

/// Which MIS heuristic weighs the strategies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MisHeuristic {
    /// Veach's power heuristic with exponent 2.
    #[default]
    Power,
    Balance,
}

/// The scene as path-space functions see it.
#[derive(Clone, Copy)]
pub struct PathContext<'a> {
    pub scene: &'a PreparedScene,
    pub camera: Frustum,
}

/// `0 -> 1`: a zero density (a subpath's end, where no walk went on) stands for "no choice
/// here" in the ratio walk, and the delta checks drop the strategies that would need it.
#[inline]
pub fn remap0(x: f32) -> f32 {
    if x != 0.0 { x } else { 1.0 }
}

/// The area density at `to` of a direction density `pdf_dir` at `from`. A vertex at infinity
/// keeps densities in solid angle (`to` there: no conversion); from one, `pdf_dir` is its disk
/// density and only the cosine at `to` converts it (rays from it are parallel).
#[inline]
pub fn to_area(pdf_dir: f32, from: &Vertex, to: &Vertex) -> f32 {
    if to.is_at_infinity() {
        return pdf_dir;
    }
    if from.is_at_infinity() {
        return if to.is_on_surface() {
            pdf_dir * to.ng.dot(from.ng).abs()
        } else {
            pdf_dir
        };
    }
    let d = to.p - from.p;
    let dist2 = d.length_squared();
    if dist2 == 0.0 {
        return 0.0;
    }
    let mut pdf = pdf_dir / dist2;
    if to.is_on_surface() {
        pdf *= to.ng.dot(d).abs() / dist2.sqrt();
    }
    pdf
}

/// The material of surface vertex `v` seen from `wo`, its shading frame and its geometric
/// normal: a material that reflects on both sides (`Material::is_two_sided`) is evaluated
/// about normals turned to `wo`'s side (and read in that frame: an anisotropic lobe's axis).
#[inline]
pub fn local_frame(scene: &PreparedScene, v: &Vertex, wo: Vec3) -> (Material, Frame, Vec3) {
    let (ng, ns) = turned_normals(scene, v, wo);
    let material = scene.material_seen(v.triangle, v.p, wo, v.ng, ns);
    (material, Frame::from_normal(ns), ng)
}

/// `v`'s geometric and shading normals, turned to `wo`'s side where its material reflects on
/// both sides.
#[inline]
fn turned_normals(scene: &PreparedScene, v: &Vertex, wo: Vec3) -> (Vec3, Vec3) {
    if wo.dot(v.ng) < 0.0 && scene.reflects_on_both_sides(v.triangle) {
        (-v.ng, -v.ns)
    } else {
        (v.ng, v.ns)
    }
}

impl<'a> PathContext<'a> {
    pub fn new(scene: &'a PreparedScene) -> PathContext<'a> {
        PathContext {
            scene,
            camera: scene.camera.frustum(),
        }
    }
}

impl PathContext<'_> {
    #[inline]
    pub fn material(&self, v: &Vertex) -> Material {
        let tris = &self.scene.triangles;
        self.scene.materials[tris.material[v.triangle as usize] as usize]
    }

    /// The material at surface vertex `v` as seen from direction `wo` (see
    /// `PreparedScene::material_seen`) and the shading normal it is evaluated about (turned to
    /// `wo`'s side where it reflects on both sides).
    #[inline]
    pub fn material_seen(&self, v: &Vertex, wo: Vec3) -> (Material, Vec3) {
        let (_, ns) = turned_normals(self.scene, v, wo);
        (self.scene.material_seen(v.triangle, v.p, wo, v.ng, ns), ns)
    }

    /// `material_seen` where the surface may scatter `wo` into `wi` (`scatters_between`: the
    /// geometric surface and the shading frame agree on reflection or refraction), else None.
    #[inline]
    fn scattering(&self, v: &Vertex, wo: Vec3, wi: Vec3) -> Option<(Material, Vec3)> {
        let (material, ns) = self.material_seen(v, wo);
        let (wo_ng, wi_ng, wo_ns, wi_ns) = (wo.dot(v.ng), wi.dot(v.ng), wo.dot(ns), wi.dot(ns));
        scatters_between(material.kind(), wo_ng, wi_ng, wo_ns, wi_ns).then_some((material, ns))
    }

    /// Whether a strategy may join a subpath at this vertex: not at a delta surface.
    #[inline]
    pub fn is_connectible(&self, v: &Vertex) -> bool {
        match v.kind {
            VertexKind::Camera | VertexKind::Light => true,
            VertexKind::Surface => !self.material(v).kind().is_delta(),
        }
    }

    /// The scene's light at infinity (asked only of vertices on it).
    #[inline]
    fn environment(&self) -> &crate::scene::environment::Environment {
        self.scene
            .emitters
            .environment
            .as_ref()
            .expect("a vertex at infinity in a scene with no light at infinity")
    }

    /// The emission profile of a point light's vertex (None for any other vertex).
    #[inline]
    pub fn point_profile(&self, v: &Vertex) -> Option<&lights::PointProfile> {
        v.is_point_light()
            .then(|| &self.scene.emitters.profile[crate::scene::light_index(v.triangle)])
    }

    /// The emitter index of the triangle under `v`, if it emits.
    #[inline]
    pub fn emitter(&self, v: &Vertex) -> Option<usize> {
        if v.kind == VertexKind::Camera {
            return None;
        }
        if v.is_point_light() {
            return Some(crate::scene::light_index(v.triangle));
        }
        if v.is_at_infinity() {
            return self.scene.emitters.environment().map(|(e, _)| e);
        }
        let e = self.scene.triangles.emitter[v.triangle as usize];
        (e != NO_EMITTER).then_some(e as usize)
    }

    /// Radiance `v` emits towards `w` (unit): one-sided, on the geometric normal's side.
    #[inline]
    pub fn emitted(&self, v: &Vertex, w: Vec3) -> Vec3 {
        match self.emitter(v) {
            Some(e) if v.is_point_light() => self.scene.emitters.intensity_towards(e, w),
            Some(_) if v.is_at_infinity() && !v.is_point_light() => self.environment().eval(-v.ng),
            Some(e) if w.dot(v.ng) > 0.0 => self.scene.emitters.radiance[e],
            _ => Vec3::ZERO,
        }
    }

    /// Area density of choosing `v` as a light subpath's first vertex: the emitter by power,
    /// the point uniformly on it.
    #[inline]
    pub fn pdf_light_origin(&self, v: &Vertex) -> f32 {
        if v.is_at_infinity() && !v.is_point_light() {
            // In solid angle: the direction it comes from.
            return self.scene.environment_light_pdf(-v.ng);
        }
        match self.emitter(v) {
            Some(e) => self.scene.emitters.pmf[e] / self.scene.emitters.area[e],
            None => 0.0,
        }
    }

    /// Area density at `to` of the direction a light subpath leaves `light` by (cosine
    /// distributed about the emitting side).
    #[inline]
    pub fn pdf_light_dir(&self, light: &Vertex, to: &Vertex) -> f32 {
        if light.is_at_infinity() {
            return to_area(self.scene.emitters.disk.pdf(), light, to);
        }
        if let Some(profile) = self.point_profile(light) {
            return to_area(
                lights::pdf_direction(profile, towards(light, to)),
                light,
                to,
            );
        }
        let w = (to.p - light.p).normalize_or_zero();
        let cos = w.dot(light.ng);
        if cos <= 0.0 {
            return 0.0;
        }
        to_area(cos * FRAC_1_PI, light, to)
    }

    /// f(wo, wi) at a surface vertex (no cosine), with `wo` towards the vertex the subpath
    /// came from and `wi` towards the one it goes to. Scattering the geometric surface and the
    /// shading frame disagree on is refused (`scatters_between`: shading normals must not leak
    /// light). A subpath from a
    /// light carries importance, and there shading normals break the symmetry of the BSDF:
    /// the factor |wo.ns| |wi.ng| / (|wo.ng| |wi.ns|) restores it (Veach, sec. 5.3).
    /// At a light vertex (y_0), 1 on the emitting side (its radiance is in `beta`).
    pub fn f(&self, v: &Vertex, wo: Vec3, wi: Vec3, mode: TransportMode) -> Vec3 {
        match v.kind {
            VertexKind::Camera => Vec3::ZERO,
            VertexKind::Light => {
                if v.is_point_light() {
                    let e = crate::scene::light_index(v.triangle);
                    self.scene.emitters.profile_towards(e, wi)
                } else if wi.dot(v.ng) > 0.0 {
                    Vec3::ONE
                } else {
                    Vec3::ZERO
                }
            }
            VertexKind::Surface => {
                let Some((material, ns)) = self.scattering(v, wo, wi) else {
                    return Vec3::ZERO;
                };
                let f = material.eval_world(ns, wo, wi, mode);
                match mode {
                    TransportMode::Radiance => f,
                    TransportMode::Importance => f * shading_correction(v, wo, wi),
                }
            }
        }
    }

    /// Solid-angle density with which the subpath at `v`, arrived from direction `wo`,
    /// samples `wi`. At a camera vertex: the camera's ray density; at a light vertex: the
    /// emission's cosine density. At a smooth dielectric, 1: the direction is fixed, and the
    /// choice of reflection or refraction is as likely from either side (Fresnel's
    /// reciprocity), so it cancels in every ratio of two techniques' densities; what does not
    /// cancel, and what a 0 read as "no choice" used to drop, is the area conversion (cosine
    /// over squared distance) on both sides of the specular vertex. Without it, a glass face
    /// 0.01 above a floor made the floor's merges 10^4 times too unlikely in VCM's weights.
    pub fn pdf_dir(&self, v: &Vertex, wo: Vec3, wi: Vec3) -> f32 {
        match v.kind {
            VertexKind::Camera => self.camera.pdf_dir(wi),
            // Before the point lights: a directional light is one too.
            VertexKind::Light if v.is_at_infinity() => {
                if wi.dot(v.ng) > 0.0 {
                    self.scene.emitters.disk.pdf()
                } else {
                    0.0
                }
            }
            VertexKind::Light if v.is_point_light() => lights::pdf_direction(
                self.point_profile(v)
                    .unwrap_or(&lights::PointProfile::Uniform),
                wi,
            ),
            VertexKind::Light => wi.dot(v.ng).max(0.0) * FRAC_1_PI,
            VertexKind::Surface if !self.is_connectible(v) => 1.0,
            VertexKind::Surface => {
                let Some((material, ns)) = self.scattering(v, wo, wi) else {
                    return 0.0;
                };
                material.pdf_world(ns, wo, wi)
            }
        }
    }

    /// Area density at `next` of `v` sampling it, `v` having been reached from `prev` (none
    /// at a subpath's first vertex).
    pub fn pdf_area(&self, v: &Vertex, prev: Option<&Vertex>, next: &Vertex) -> f32 {
        let wi = (next.p - v.p).normalize_or_zero();
        let wo = prev.map_or(Vec3::ZERO, |p| (p.p - v.p).normalize_or_zero());
        to_area(self.pdf_dir(v, wo, wi), v, next)
    }
}

/// What many connections need of a connectible vertex besides the vertex itself: the cosines
/// of the direction to its subpath's previous vertex and its BSDF, found once per vertex
/// instead of once per connection. `Joint::f` is `PathContext::f`, bit for bit.
#[derive(Clone, Copy, Debug)]
pub struct Joint {
    /// wo . ng and wo . ns, wo the unit direction to the previous vertex (zero at a light).
    wo: Vec3,
    wo_ng: f32,
    wo_ns: f32,
    /// The shading normal is not the geometric one (importance needs a correction).
    shading_normal: bool,
    lobe: Lobe,
}

#[derive(Clone, Copy, Debug)]
enum Lobe {
    /// A point on an emitter (its radiance is in `beta`): 1 on the emitting side.
    Light,
    /// Point light `e` (its intensity is in `beta`; `Emitters::profile_towards` shapes it).
    PointLight(usize),
    /// Lambertian: reflectance / pi.
    Diffuse(Vec3),
    /// Any other connectible BSDF, and the shading normal it is evaluated about.
    Other(Material, Vec3),
}

impl Joint {
    /// f(wo, wi) at the vertex the joint was prepared for, for unit `wi`, given wi . ng and
    /// wi . ns.
    #[inline]
    fn f(
        &self,
        emitters: &crate::scene::Emitters,
        wi: Vec3,
        wi_ng: f32,
        wi_ns: f32,
        mode: TransportMode,
    ) -> Vec3 {
        let f = match self.lobe {
            Lobe::Light => {
                return if wi_ng > 0.0 { Vec3::ONE } else { Vec3::ZERO };
            }
            Lobe::PointLight(e) => return emitters.profile_towards(e, wi),
            Lobe::Other(material, ns) => {
                if !scatters_between(material.kind(), self.wo_ng, wi_ng, self.wo_ns, wi_ns) {
                    return Vec3::ZERO;
                }
                material.eval_world(ns, self.wo, wi, mode)
            }
            _ if wi_ng * self.wo_ng <= 0.0 => return Vec3::ZERO,
            Lobe::Diffuse(value) => {
                if (self.wo_ns > 0.0 && wi_ns > 0.0) || (self.wo_ns < 0.0 && wi_ns < 0.0) {
                    value
                } else {
                    return Vec3::ZERO;
                }
            }
        };
        match mode {
            TransportMode::Importance if self.shading_normal => {
                // `shading_correction` from the cosines.
                let den = self.wo_ng.abs() * wi_ns.abs();
                if den == 0.0 {
                    return f * 0.0;
                }
                f * (self.wo_ns.abs() * wi_ng.abs() / den)
            }
            _ => f,
        }
    }
}

/// The unit direction from `v` to `to` (zero where they coincide).
#[inline]
pub fn towards(v: &Vertex, to: &Vertex) -> Vec3 {
    (to.p - v.p).normalize_or_zero()
}

/// The shading-normal factor of an importance-carrying scattering at `v` (1 where the shading
/// normal is the geometric one).
#[inline]
pub fn shading_correction(v: &Vertex, wo: Vec3, wi: Vec3) -> f32 {
    if v.ns == v.ng {
        return 1.0;
    }
    let den = wo.dot(v.ng).abs() * wi.dot(v.ns).abs();
    if den == 0.0 {
        return 0.0;
    }
    wo.dot(v.ns).abs() * wi.dot(v.ng).abs() / den
}

/// A strategy's connection: its unweighted contribution and the segment whose visibility it
/// needs (none for s = 0, where the camera subpath itself reached the light).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Connection {
    pub contribution: Vec3,
    /// The two vertices joined, light side first, when a shadow ray must test them.
    pub segment: Option<(Vertex, Vertex)>,
    /// For t = 1, the pixel the light vertex projects to and where in it.
    pub pixel: Option<(usize, glam::Vec2)>,
}

impl PathContext<'_> {
    /// The unweighted contribution of strategy (s, t), given the camera subpath `camera`
    /// (at least t vertices) and the light subpath `light` (at least s vertices; for s = 1
    /// pass the freshly sampled light vertex as `light[0]`). `None` when the strategy cannot
    /// contribute (a delta vertex at the joint, a back-facing emitter, outside the image...).
    pub fn connect(
        &self,
        camera: &[Vertex],
        light: &[Vertex],
        s: usize,
        t: usize,
    ) -> Option<Connection> {
        if s == 0 {
            // The camera subpath found the light by itself.
            let contribution = self.reached_emission(&camera[t - 1], &camera[t - 2]);
            return (contribution != Vec3::ZERO).then_some(Connection {
                contribution,
                segment: None,
                pixel: None,
            });
        }
        let y = &light[s - 1];
        if !self.is_connectible(y) {
            return None;
        }
        let y_wo = if s >= 2 {
            towards(y, &light[s - 2])
        } else {
            Vec3::ZERO
        };
        if t == 1 {
            let (contribution, pixel, raster) = self.connect_to_camera(y, y_wo)?;
            return Some(Connection {
                contribution,
                segment: Some((*y, camera[0])),
                pixel: Some((pixel, raster)),
            });
        }
        let z = &camera[t - 1];
        if !self.is_connectible(z) {
            return None;
        }
        let contribution = self.join(y, y_wo, z, towards(z, &camera[t - 2]))?;
        Some(Connection {
            contribution,
            segment: Some((*y, *z)),
            pixel: None,
        })
    }

    /// Strategy s = 0: what the camera subpath carries from the emitter it reached at `z`,
    /// arriving from `prev`.
    #[inline]
    pub fn reached_emission(&self, z: &Vertex, prev: &Vertex) -> Vec3 {
        z.beta * self.emitted(z, towards(z, prev))
    }

    /// Strategy t = 1 (light tracing): the light vertex `y` (connectible, reached along
    /// `-y_wo`, zero at a light vertex) seen by the camera: its unweighted contribution and
    /// the pixel it lands in and its raster position there, or `None` outside the image, for
    /// no contribution, or for a camera no direction reaches (orthographic).
    #[inline]
    pub fn connect_to_camera(&self, y: &Vertex, y_wo: Vec3) -> Option<(Vec3, usize, glam::Vec2)> {
        if y.is_point_light() || y.is_at_infinity() {
            // A point light is not seen directly, as in Mitsuba and pbrt: no camera ray hits
            // it, and (s, t) = (1, 1), the only other strategy, is not counted either. The
            // light at infinity is seen directly by camera rays that leave the scene (0, 2);
            // from its disk, (1, 1) would need the one parallel ray that meets the pinhole.
            return None;
        }
        let cam = &self.camera;
        let to_y = y.p - cam.position;
        let dist2 = to_y.length_squared();
        let dir = to_y / dist2.sqrt();
        let (pixel, raster, importance) = cam.project(dir)?;
        let wi = -dir;
        let f = self.f(y, y_wo, wi, TransportMode::Importance);
        let cos_y = if y.is_point_light() {
            1.0
        } else if y.kind == VertexKind::Light {
            wi.dot(y.ng).abs()
        } else {
            wi.dot(y.ns).abs()
        };
        let contribution = y.beta * f * (cos_y * importance / dist2);
        (contribution != Vec3::ZERO).then_some((contribution, pixel, raster))
    }

    /// Strategies s >= 1, t >= 2: the unweighted contribution of joining light vertex `y` to
    /// camera vertex `z` (both connectible; `y_wo`, `z_wo` the unit directions to their
    /// subpaths' previous vertices, zero at a light vertex), or `None` when it is zero.
    #[inline]
    pub fn join(&self, y: &Vertex, y_wo: Vec3, z: &Vertex, z_wo: Vec3) -> Option<Vec3> {
        self.join_prepared((y, &self.joint(y, y_wo)?), (z, &self.joint(z, z_wo)?))
    }

    /// Vertex `v`, reached from direction `wo`, prepared for joining, or `None` if no
    /// strategy may join there.
    #[inline]
    pub fn joint(&self, v: &Vertex, wo: Vec3) -> Option<Joint> {
        let lobe = match v.kind {
            VertexKind::Camera => return None,
            // Where a camera subpath left the scene (reached from `wo`) it ends: only s = 0
            // counts there. As a light subpath's origin it joins as any light vertex.
            VertexKind::Light if v.is_at_infinity() && wo != Vec3::ZERO => return None,
            VertexKind::Light if v.is_point_light() => {
                Lobe::PointLight(crate::scene::light_index(v.triangle))
            }
            VertexKind::Light => Lobe::Light,
            VertexKind::Surface => match self.material_seen(v, wo) {
                (m, _) if m.kind().is_delta() => return None,
                (Material::Diffuse(Diffuse { reflectance }), _) => {
                    Lobe::Diffuse(reflectance * FRAC_1_PI)
                }
                (material, ns) => Lobe::Other(material, ns),
            },
        };
        Some(Joint {
            wo,
            wo_ng: wo.dot(v.ng),
            wo_ns: wo.dot(v.ns),
            shading_normal: v.ns != v.ng,
            lobe,
        })
    }

    /// `join` of prepared vertices, bit for bit: the BSDF at `z` is tested first, so a
    /// back-facing joint costs a few dot products.
    #[inline]
    pub fn join_prepared(
        &self,
        (y, yj): (&Vertex, &Joint),
        (z, zj): (&Vertex, &Joint),
    ) -> Option<Vec3> {
        let d = y.p - z.p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let w = d / dist2.sqrt(); // from z towards y
        let emitters = &self.scene.emitters;
        let fz = zj.f(
            emitters,
            w,
            w.dot(z.ng),
            w.dot(z.ns),
            TransportMode::Radiance,
        );
        if fz == Vec3::ZERO {
            return None;
        }
        // Towards z from y: -w, whose dot products are those of w negated, exactly.
        let (w_ng_y, w_ns_y) = (w.dot(y.ng), w.dot(y.ns));
        let fy = yj.f(emitters, -w, -w_ng_y, -w_ns_y, TransportMode::Importance);
        let cos_y = if y.is_point_light() {
            1.0
        } else if y.kind == VertexKind::Light {
            w_ng_y.abs()
        } else {
            w_ns_y.abs()
        };
        // From infinity, radiance arrives without falloff (its density is in solid angle).
        let g = if y.is_at_infinity() {
            w.dot(z.ns).abs()
        } else {
            w.dot(z.ns).abs() * cos_y / dist2
        };
        let contribution = z.beta * fz * y.beta * fy * g;
        (contribution != Vec3::ZERO).then_some(contribution)
    }

    /// The MIS weight of strategy (s, t) for the path its connection makes, by Veach's ratio
    /// walk over the stored forward and reverse densities; the densities the connection itself
    /// changes (at the two joined vertices and their predecessors) are recomputed here.
    #[inline]
    pub fn mis_weight(
        &self,
        camera: &[Vertex],
        light: &[Vertex],
        s: usize,
        t: usize,
        heuristic: MisHeuristic,
    ) -> f32 {
        self.mis_weight_counted(camera, light, s, t, heuristic, 1.0)
    }

    /// `mis_weight` where each connection strategy (s >= 2, t >= 2) is sampled
    /// `connection_count` times as often as the others (a light-vertex cache: Davidovic et al.
    /// 2014): strategy j weighs `n_j p_j` against the others' instead of `p_j`. Any positive
    /// count keeps the weights of a path summing to one; with 1 it is `mis_weight` bit for bit.
    pub fn mis_weight_counted(
        &self,
        camera: &[Vertex],
        light: &[Vertex],
        s: usize,
        t: usize,
        heuristic: MisHeuristic,
        connection_count: f32,
    ) -> f32 {
        let techniques = Techniques {
            connection_count,
            ..Techniques::CONNECTIONS
        };
        self.vcm_weight(camera, light, (s, t), None, heuristic, techniques)
    }
}

/// The techniques a vertex connection and merging estimator (VCM, Georgiev et al. 2012)
/// combines, as its MIS weights count them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Techniques {
    /// Whether the strategies with s >= 1 (light sampling, joins, light tracing) take part;
    /// s = 0 (the camera subpath reaches a light) always does.
    pub connect: bool,
    /// pi r^2 N (merge radius r, N light subpaths merged with): a merge at vertex x is
    /// sampled with the density of the connection that ends its light subpath just before x,
    /// times x's light-side area density, times this. 0: no merging.
    pub merge_count: f32,
    /// How many times as often each join (s >= 2, t >= 2) is sampled as the other
    /// connections (a light-vertex cache: Davidovic et al. 2014): strategy j weighs n_j p_j.
    pub connection_count: f32,
}

impl Techniques {
    /// BDPT's strategies alone.
    pub const CONNECTIONS: Techniques = Techniques {
        connect: true,
        merge_count: 0.0,
        connection_count: 1.0,
    };
}

impl PathContext<'_> {
    /// The MIS weight of one technique of a VCM estimator for the path it makes: the
    /// connection (s, t) of `camera` (z_0..z_{t-1}) and `light` (y_0..y_{s-1}) when `merged`
    /// is `None`, or the merge of camera vertex z_{t-1} with light vertex y_s (`merged`, the
    /// light subpath's next vertex after `light[s - 1]`, found within the radius of z_{t-1}),
    /// the path being y_0..y_{s-1} z_{t-1}..z_0.
    ///
    /// Veach's ratio walk over every connection (s', t') of the path (BDPT's `mis_weight` is
    /// this with no merges), with a merge term at each vertex where merging is allowed (not
    /// delta, neither the emitter's nor the camera's vertex): p_VM(x_i) = p_VC(light reaching x_{i-1}) p_light(x_i)
    /// merge_count, read off the walk before it steps past x_i. For a merge, the densities at
    /// the joint come from the light subpath's own direction into y_s and the camera's BSDF
    /// at z_{t-1} (its neighbours' densities as the merged path makes them).
    pub fn vcm_weight(
        &self,
        camera: &[Vertex],
        light: &[Vertex],
        (s, t): (usize, usize),
        merged: Option<&Vertex>,
        heuristic: MisHeuristic,
        techniques: Techniques,
    ) -> f32 {
        if merged.is_none() && s == 1 && t == 1 && light[0].is_at_infinity() {
            // No technique: the light at infinity seen through the pinhole from its disk.
            return 0.0;
        }
        let eta = techniques.merge_count;
        let connect = techniques.connect;
        let mut z_rev = [0.0f32; 2]; // for z_{t-1}, z_{t-2}
        let mut y_rev = [0.0f32; 2]; // for y_{s-1}, y_{s-2}
        let z = &camera[t - 1];
        match merged {
            None => {
                let y_last = light.get(s.wrapping_sub(1)).filter(|_| s >= 1);
                z_rev[0] = match y_last {
                    Some(y) => self.pdf_area(y, if s >= 2 { Some(&light[s - 2]) } else { None }, z),
                    None => self.pdf_light_origin(z),
                };
                if t >= 2 {
                    z_rev[1] = match y_last {
                        Some(y) => self.pdf_area(z, Some(y), &camera[t - 2]),
                        None => self.pdf_light_dir(z, &camera[t - 2]),
                    };
                }
                if let Some(y) = y_last {
                    let z_prev = if t >= 2 { Some(&camera[t - 2]) } else { None };
                    y_rev[0] = self.pdf_area(z, z_prev, y);
                    if s >= 2 {
                        y_rev[1] = self.pdf_area(y, Some(z), &light[s - 2]);
                    }
                }
            }
            Some(y_s) => {
                debug_assert!(s >= 1 && t >= 2);
                let y = &light[s - 1];
                // The light arrives at the merge along y_{s-1} -> y_s; the camera left
                // z_{t-1} towards z_{t-2}.
                let w_light = towards(y_s, y);
                let w_camera = towards(z, &camera[t - 2]);
                z_rev[0] = y_s.pdf_fwd;
                z_rev[1] = to_area(self.pdf_dir(z, w_light, w_camera), z, &camera[t - 2]);
                y_rev[0] = to_area(self.pdf_dir(z, w_camera, w_light), y_s, y);
                if s >= 2 {
                    // y_{s-1} sampling y_{s-2}, reached from y_s: stored by the light walk.
                    y_rev[1] = light[s - 2].pdf_rev;
                }
            }
        }
        let h = |r: f32| match heuristic {
            MisHeuristic::Power => r * r,
            MisHeuristic::Balance => r,
        };
        let camera_rev = |i: usize| {
            if i + 1 == t {
                z_rev[0]
            } else if i + 2 == t {
                z_rev[1]
            } else {
                camera[i].pdf_rev
            }
        };
        // A connection's joined vertices and a merge's camera vertex are never delta; a
        // merge's y_{s-1} may be (a caustic).
        let camera_delta = |i: usize| i + 1 != t && camera[i].delta;
        let light_rev = |i: usize| {
            if i + 1 == s {
                y_rev[0]
            } else if i + 2 == s {
                y_rev[1]
            } else {
                light[i].pdf_rev
            }
        };
        let light_delta = |i: usize| (merged.is_some() || i + 1 != s) && light[i].delta;
        let merging = eta > 0.0;
        // n_j / n_own for connection (sj, tj): joins count `connection_count`, all else 1.
        let count = |sj: usize, tj: usize| {
            if sj >= 2 && tj >= 2 {
                techniques.connection_count
            } else {
                1.0
            }
        };
        let own_count = if merged.is_none() { count(s, t) } else { 1.0 };
        let relative = |sj: usize, tj: usize| count(sj, tj) / own_count;

        // The technique's own density over p_VC(s, t).
        let own = match merged {
            None => 1.0,
            Some(_) => h(remap0(z_rev[0]) * eta),
        };
        // Connection (s, t) itself: for a merge, only when its joint is not delta.
        let mut sum = match merged {
            None => 1.0,
            Some(_) if connect && !light_delta(s - 1) => h(relative(s, t)),
            Some(_) => 0.0,
        };
        // Fewer camera vertices: (s + 1, t - 1), ... down to t = 1; the merge at camera
        // vertex i before the step past it (not at the emitter: s = 0, i = t - 1).
        let mut ratio = 1.0f32;
        // A camera ray that sees the light at infinity directly has no (1, 1) alternative.
        let seen_at_infinity = s == 0 && t == 2 && z.is_at_infinity();
        for i in (1..t).rev() {
            if merging && !camera_delta(i) && !(s == 0 && i + 1 == t) {
                sum += h(ratio * remap0(camera_rev(i)) * eta);
            }
            ratio *= remap0(camera_rev(i)) / remap0(camera[i].pdf_fwd);
            if connect && !camera_delta(i) && !camera_delta(i - 1) && !seen_at_infinity {
                sum += h(ratio * relative(s + t - i, i));
            }
        }
        // Fewer light vertices, down to s = 0; merges at light vertices past the emitter.
        ratio = 1.0;
        for i in (0..s).rev() {
            if merging && i >= 1 && !light_delta(i) {
                sum += h(ratio * remap0(light_rev(i)) * eta);
            }
            ratio *= remap0(light_rev(i)) / remap0(light[i].pdf_fwd);
            let delta_before = i > 0 && light_delta(i - 1);
            // No camera path hits a point light: (0, s + t) is no strategy there.
            let unreachable = i == 0 && light[0].is_point_light();
            if (connect || i == 0) && !light_delta(i) && !delta_before && !unreachable {
                sum += h(ratio * relative(i, s + t - i));
            }
        }
        own / sum
    }
}
