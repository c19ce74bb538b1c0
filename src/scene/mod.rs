//! Scenes: the RON description, OBJ and PLY loading, procedural shapes, the hecs world of scene
//! entities, and "prepare", which flattens that world once into render data.

mod camera;
pub use camera::Frustum;
pub mod environment;
pub mod filter;
pub mod format;
pub mod lights;
pub mod mitsuba;
pub mod obj;
pub mod parse;
pub mod ply;
pub mod prepare;
pub mod shapes;
pub mod textures;
pub mod world;

pub use parse::{Located, ParsedScene, parse};
pub use prepare::prepare;
pub use world::SceneWorld;

use crate::bsdf::Material;
use crate::bsdf::diffuse::Diffuse;
use glam::Vec3;
use std::path::{Path, PathBuf};

pub use crate::geometry::{FLAT, MAX_COORDINATE, NO_EMITTER, TriangleColumns};

/// A camera: a pinhole by default, or orthographic. The image's right is forward x up; row 0
/// is the top row.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    /// Unit vectors: `right = forward x up` (normalised), `up` re-orthogonalised.
    pub forward: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    /// Full vertical field of view of the whole film in degrees, in (0, 180) (a pinhole's).
    pub fov_y_degrees: f32,
    /// The rendered image's size: the crop window's (the whole film without one).
    pub width: u32,
    pub height: u32,
    /// Where the rendered image lies on the film the projection is defined on.
    pub crop: Crop,
    pub projection: Projection,
    /// How samples are reconstructed into pixels.
    pub filter: crate::scene::filter::PixelFilter,
}

/// A crop window (Mitsuba's hdrfilm crop_offset_x/y, crop_width/height): the rendered image
/// is the camera's `width` x `height` pixels from (x, y) of a `film_width` x `film_height`
/// film, whose rays are those of the whole film.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    pub film_width: u32,
    pub film_height: u32,
    pub x: u32,
    pub y: u32,
}

impl Crop {
    /// No crop: the whole `width` x `height` film.
    pub fn whole(width: u32, height: u32) -> Crop {
        Crop {
            film_width: width,
            film_height: height,
            x: 0,
            y: 0,
        }
    }
}

/// How film positions become camera rays.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Projection {
    /// A pinhole at `position` with `fov_y_degrees`.
    #[default]
    Perspective,
    /// Parallel rays along `forward`, from a rectangle `2 half_width` by `2 half_height`
    /// (world units) centred `near` along `forward` from `position` (Mitsuba's near_clip:
    /// rays start on the near plane).
    Orthographic {
        half_width: f32,
        half_height: f32,
        near: f32,
    },
}

/// The emitters (emitting triangles, then point lights) and the distribution that picks one by
/// power.
#[derive(Clone, Debug, Default)]
pub struct Emitters {
    /// Triangle id of each emitter; `POINT_LIGHT | e` for point light `e`, which no triangle
    /// has (a light vertex's `triangle` names its emitter either way).
    pub triangle: Vec<u32>,
    /// Constant radiance, emitted on the geometric normal's side only; a point light's
    /// intensity (radiant power per steradian), the same in every direction.
    pub radiance: Vec<Vec3>,
    /// A triangle's area; 1 for a point light, so that `pmf / area` is its discrete
    /// probability wherever an area density is asked for.
    pub area: Vec<f32>,
    /// A point light's position; a directional light's unit direction of travel (zero for a
    /// triangle).
    pub position: Vec<Vec3>,
    /// A point light's spot cone, if it has one (None for a triangle).
    pub profile: Vec<lights::PointProfile>,
    /// Probability of picking each emitter (proportional to pi * area * luminance(radiance)).
    pub pmf: Vec<f32>,
    /// Running sum of `pmf`, ending at exactly 1.
    pub cdf: Vec<f32>,
    /// Total emitted power, sum of pi * area * radiance (RGB).
    pub total_power: Vec3,
    /// The textures spots and projectors project (their `texture` fields index them).
    pub projected_textures: Vec<textures::Texture>,
    /// Where light paths from lights at infinity start (set where the scene has one).
    pub disk: environment::SceneDisk,
    /// The light at infinity, if the scene has one: the last emitter, its `triangle`
    /// `ENVIRONMENT`.
    pub environment: Option<environment::Environment>,
}

impl Emitters {
    /// Whether any emitter is a point light (they come after the triangles).
    #[inline]
    pub fn has_point_lights(&self) -> bool {
        self.triangle.last().is_some_and(|&t| t & POINT_LIGHT != 0)
    }

    /// Whether emitter `e` is a point light.
    #[inline]
    pub fn is_point(&self, e: usize) -> bool {
        self.triangle[e] & POINT_LIGHT != 0
    }

    /// Whether emitter `e` is a directional light (its `position` is its direction of travel,
    /// its `radiance` its irradiance).
    #[inline]
    pub fn is_directional(&self, e: usize) -> bool {
        self.triangle[e] & (POINT_LIGHT | AT_INFINITY) == POINT_LIGHT | AT_INFINITY
    }

    /// Whether every emitter is a triangle (no point light, no light at infinity).
    #[inline]
    pub fn only_triangles(&self) -> bool {
        !self.has_point_lights() && self.environment.is_none()
    }

    /// The light at infinity with its emitter index.
    #[inline]
    pub fn environment(&self) -> Option<(usize, &environment::Environment)> {
        self.environment
            .as_ref()
            .map(|env| (self.triangle.len() - 1, env))
    }

    /// Point light `e`'s intensity towards unit direction `w`.
    #[inline]
    pub fn intensity_towards(&self, e: usize, w: Vec3) -> Vec3 {
        self.radiance[e] * self.profile_towards(e, w)
    }

    /// The fraction of point light `e`'s intensity it sends towards unit direction `w`, per
    /// channel: its profile's (a spot's falloff, a projector's 1 / cos^3) times the texture it
    /// projects there.
    #[inline]
    pub fn profile_towards(&self, e: usize, w: Vec3) -> Vec3 {
        match self.profile[e].towards(w) {
            (fraction, Some((texture, uv))) if fraction > 0.0 => {
                self.projected_textures[texture as usize].eval(uv) * fraction
            }
            (fraction, _) => Vec3::splat(fraction),
        }
    }
}

/// What a material reads at each shading point (see `PreparedScene::material_at`): indices
/// into `PreparedScene::textures`, and whether its lobe turns with the uv tangent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Varying {
    pub reflectance: Option<u32>,
    pub alpha_u: Option<u32>,
    pub alpha_v: Option<u32>,
    pub anisotropic: bool,
}

/// The render data of a scene: what systems read while rendering. No hecs queries happen
/// after this is built.
#[derive(Clone, Debug)]
pub struct PreparedScene {
    pub source: PathBuf,
    pub camera: Camera,
    pub triangles: TriangleColumns,
    pub materials: Vec<Material>,
    /// Per material: black when seen from behind its geometric normal (see `material_seen`).
    pub black_behind: Vec<bool>,
    /// Per material: the material seen from behind its geometric normal where it is a twosided
    /// of two BSDFs (its back's index), else `None` (see `material_seen`).
    pub back: Vec<Option<u32>>,
    /// Per material: what it reads at each shading point (textures, the uv tangent), or
    /// `None` for a material that is the same everywhere (see `material_at`).
    pub varying: Vec<Option<Varying>>,
    /// `has_textures`.
    textured: bool,
    pub textures: Vec<textures::Texture>,
    /// Per triangle, the uvs of its corners (Mitsuba's (0, 0), (1, 0), (0, 1) where the mesh has
    /// none); empty when no material varies over its surface.
    pub triangle_uvs: Vec<[glam::Vec2; 3]>,
    pub emitters: Emitters,
    pub bounds_min: Vec3,
    pub bounds_max: Vec3,
    /// Messages for the user (the CLI prints them): zero-area triangles dropped while
    /// preparing (one message per object), unused materials, a scene without light.
    pub warnings: Vec<String>,
}

/// A point on an emitter, picked by power and then uniformly by area (light sampling, light
/// subpaths and photons all start this way).
#[derive(Clone, Copy, Debug)]
pub struct EmitterPoint {
    /// Index into `PreparedScene::emitters`.
    pub emitter: usize,
    pub triangle: u32,
    pub point: crate::geometry::SurfacePoint,
    /// Area density of the point: the emitter's pick probability over its area.
    pub pdf_area: f32,
}

/// A light sample seen from a surface point: the direction to it, its solid-angle density,
/// the shadow ray that tests it and the radiance it sends.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    pub wi: Vec3,
    pub pdf: f32,
    pub origin: Vec3,
    pub dir: Vec3,
    pub t_max: f32,
    pub radiance: Vec3,
    /// A point light's sample: no BSDF sample can find it, so its MIS weight is 1.
    pub delta: bool,
}

/// Marks a light vertex's `triangle` (and `Emitters::triangle`) as point light `e` in the low
/// bits: scenes hold fewer than 2^31 triangles.
pub const POINT_LIGHT: u32 = 1 << 31;

/// Marks a light at infinity in `Emitters::triangle` (no triangle has this bit: scenes hold
/// fewer than 2^30 triangles): alone, the environment; with `POINT_LIGHT`, a directional
/// light (a delta direction, as a point light is a delta position): `POINT_LIGHT | AT_INFINITY
/// | e`.
pub const AT_INFINITY: u32 = 1 << 30;

/// `Emitters::triangle` of the environment (constant or envmap).
pub const ENVIRONMENT: u32 = AT_INFINITY;

/// The emitter index a point or directional light's triangle tag names.
#[inline]
pub fn light_index(triangle: u32) -> usize {
    (triangle & !(POINT_LIGHT | AT_INFINITY)) as usize
}

/// Whether a vertex's triangle tag is a light at infinity (the camera's and a miss's tag,
/// all bits set, is not).
#[inline]
pub fn is_at_infinity(triangle: u32) -> bool {
    triangle != u32::MAX && triangle & AT_INFINITY != 0
}

/// The index `uniform_material_index_seen` gives for `BLACK` (no material has it).
pub const SEEN_BLACK: u32 = u32::MAX;

/// What a one-sided surface is from behind: it reflects nothing.
pub const BLACK: Material = Material::Diffuse(Diffuse {
    reflectance: Vec3::ZERO,
});

impl PreparedScene {
    /// The material of triangle `tri` as a ray arriving from `wo` (unit, pointing away from the
    /// surface) sees it: a one-sided material seen from behind its geometric normal `ng` (not
    /// flipped to any side) is `BLACK`, as Mitsuba's `diffuse` outside a `twosided`. `ns` as
    /// in `material_at`.
    #[inline(always)]
    pub fn material_seen(&self, tri: u32, p: Vec3, wo: Vec3, ng: Vec3, ns: Vec3) -> Material {
        if self.seen_from_behind(tri, wo, ng) {
            BLACK
        } else {
            self.material_facing(tri, p, wo, ns)
        }
    }

    /// `material_seen` of a material that does not vary over its surface (`varying` is
    /// `None`: no texture to look up, so neither the point nor the shading normal matters),
    /// as its index in `materials` (`SEEN_BLACK` for `BLACK`; `seen_material` reads it).
    /// The wavefront finds it once per hit, in `sort_by_material`, and its shading systems
    /// read it from the hit's surface point; scenes with textures look theirs up once per hit
    /// instead (`systems/shade/look_up_textures.rs`).
    #[inline(always)]
    pub fn uniform_material_index_seen(&self, tri: u32, wo: Vec3, ng: Vec3) -> u32 {
        if self.seen_from_behind(tri, wo, ng) {
            return SEEN_BLACK;
        }
        let m = self.triangles.material[tri as usize];
        debug_assert!(
            self.varying[m as usize].is_none(),
            "a textured material read as uniform"
        );
        match self.back[m as usize] {
            Some(back) if wo.dot(self.triangles.normal[tri as usize]) < 0.0 => back,
            _ => m,
        }
    }

    /// The material of an index `uniform_material_index_seen` gave.
    #[inline(always)]
    pub fn seen_material(&self, index: u32) -> Material {
        match self.materials.get(index as usize) {
            Some(&material) => material,
            None => BLACK,
        }
    }

    /// Whether a material some triangle uses (or its back) varies over its surface: the
    /// wavefront then holds `look_up_textures`. Found once, when the scene is prepared
    /// (`sort_by_material` asks it every bounce).
    #[inline]
    pub fn has_textures(&self) -> bool {
        self.textured
    }

    /// `has_textures`, from the materials the triangles use.
    fn uses_textures(&self) -> bool {
        let varies = |m: usize| self.varying[m].is_some();
        let mut used = vec![false; self.materials.len()];
        for &m in &self.triangles.material {
            used[m as usize] = true;
        }
        used.iter()
            .enumerate()
            .any(|(m, &u)| u && (varies(m) || self.back[m].is_some_and(|b| varies(b as usize))))
    }

    /// `material_at` on the side `wo` (pointing away from the surface) lies: behind the
    /// triangle's normal, a twosided of two BSDFs' back material; else the triangle's own.
    /// (Not black from behind: callers that need that ask `seen_from_behind`.)
    #[inline(always)]
    pub fn material_facing(&self, tri: u32, p: Vec3, wo: Vec3, ns: Vec3) -> Material {
        let m = self.triangles.material[tri as usize] as usize;
        match self.back[m] {
            Some(back) if wo.dot(self.triangles.normal[tri as usize]) < 0.0 => {
                self.material_of(back as usize, tri, p, ns)
            }
            _ => self.material_of(m, tri, p, ns),
        }
    }

    /// The kind of the material a ray travelling along `dir` sees on triangle `tri`
    /// (`material_seen`'s, without its textures; a black back is the front's kind).
    #[inline(always)]
    pub fn kind_seen(&self, tri: u32, dir: Vec3) -> crate::bsdf::MaterialKind {
        let m = self.triangles.material[tri as usize] as usize;
        match self.back[m] {
            Some(back) if dir.dot(self.triangles.normal[tri as usize]) > 0.0 => {
                self.materials[back as usize].kind()
            }
            _ => self.materials[m].kind(),
        }
    }

    /// Whether triangle `tri`'s material reflects alike on both sides (`Material::is_two_sided`).
    #[inline]
    pub fn reflects_on_both_sides(&self, tri: u32) -> bool {
        self.materials[self.triangles.material[tri as usize] as usize].is_two_sided()
    }

    /// For each material, whether it is Lambertian wherever it is seen: untextured `Diffuse` on
    /// both faces (or black behind, which is `Diffuse` too), so that its density is the cosine
    /// one about the shading normal whichever side a direction comes from.
    pub fn lambertian_materials(&self) -> Vec<bool> {
        let uniform_diffuse = |m: usize| {
            matches!(self.materials[m], Material::Diffuse(_)) && self.varying[m].is_none()
        };
        (0..self.materials.len())
            .map(|m| uniform_diffuse(m) && self.back[m].is_none_or(|b| uniform_diffuse(b as usize)))
            .collect()
    }

    /// The material of triangle `tri` at point `p` on it, its textures looked up there (the
    /// front's, for a twosided of two BSDFs: `material_facing` takes the side). `ns` is
    /// the normal of the shading frame the caller evaluates the material in
    /// (`Frame::from_normal(ns)`): an anisotropic lobe's axis is given in that frame.
    #[inline(always)]
    pub fn material_at(&self, tri: u32, p: Vec3, ns: Vec3) -> Material {
        self.material_of(self.triangles.material[tri as usize] as usize, tri, p, ns)
    }

    /// Material `m` at point `p` of triangle `tri`, its textures looked up there.
    #[inline(always)]
    fn material_of(&self, m: usize, tri: u32, p: Vec3, ns: Vec3) -> Material {
        match &self.varying[m] {
            None => self.materials[m],
            Some(varying) => self.vary(self.materials[m], varying, tri, p, ns),
        }
    }

    /// `material` with what it reads at point `p` of triangle `tri` read there.
    #[inline]
    fn vary(&self, mut material: Material, v: &Varying, tri: u32, p: Vec3, ns: Vec3) -> Material {
        let uv = self.uv_at(tri, p);
        let texture = |t: u32| &self.textures[t as usize];
        match &mut material {
            Material::Diffuse(Diffuse { reflectance }) => {
                if let Some(t) = v.reflectance {
                    *reflectance = texture(t).eval(uv);
                }
            }
            Material::Conductor(c) => {
                if let Some(t) = v.reflectance {
                    c.reflectance = texture(t).eval(uv);
                }
                if let Some(t) = v.alpha_u {
                    c.alpha_u = texture(t).eval_1(uv);
                }
                if let Some(t) = v.alpha_v {
                    c.alpha_v = texture(t).eval_1(uv);
                }
                if v.anisotropic && c.alpha_u != c.alpha_v {
                    c.axis = self.uv_axis(tri, ns);
                }
            }
            Material::RoughPlastic(plastic) => {
                if let Some(t) = v.reflectance {
                    plastic.diffuse = texture(t).eval(uv);
                }
            }
            Material::RoughDielectric(d) => {
                if let Some(t) = v.alpha_u {
                    d.alpha_u = texture(t).eval_1(uv);
                }
                if let Some(t) = v.alpha_v {
                    d.alpha_v = texture(t).eval_1(uv);
                }
                if v.anisotropic && d.alpha_u != d.alpha_v {
                    d.axis = self.uv_axis(tri, ns);
                }
            }
            Material::Plastic(plastic) => {
                if let Some(t) = v.reflectance {
                    plastic.diffuse = texture(t).eval(uv);
                }
            }
            Material::Dielectric(_) | Material::ThinDielectric(_) => {}
        }
        material
    }

    /// The direction in which u grows on triangle `tri` (Mitsuba's dp/du, the first tangent of
    /// its shading frames) as (cos, sin) of its angle in `Frame::from_normal(ns)`'s tangent
    /// plane. Where the uvs are degenerate Mitsuba takes the first tangent of its
    /// `coordinate_system` of the geometric normal, which is `Frame::from_normal`'s.
    fn uv_axis(&self, tri: u32, ns: Vec3) -> glam::Vec2 {
        let t = &self.triangles;
        let i = tri as usize;
        let (dp0, dp1) = (t.p1[i] - t.p0[i], t.p2[i] - t.p0[i]);
        let [uv0, uv1, uv2] = self.triangle_uvs[i];
        let (duv0, duv1) = (uv1 - uv0, uv2 - uv0);
        let det = duv0.x * duv1.y - duv0.y * duv1.x;
        let dp_du = if det != 0.0 {
            (duv1.y * dp0 - duv0.y * dp1) / det
        } else {
            crate::math::Frame::from_normal(t.normal[i]).s
        };
        let frame = crate::math::Frame::from_normal(ns);
        glam::Vec2::new(dp_du.dot(frame.s), dp_du.dot(frame.t))
            .try_normalize()
            .unwrap_or(glam::Vec2::X)
    }

    /// The surface uv at point `p` of triangle `tri` (from its barycentric coordinates).
    #[inline]
    pub fn uv_at(&self, tri: u32, p: Vec3) -> glam::Vec2 {
        let t = &self.triangles;
        let i = tri as usize;
        let (p0, e1, e2) = (t.p0[i], t.p1[i] - t.p0[i], t.p2[i] - t.p0[i]);
        let v = p - p0;
        let (d00, d01, d11) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let (d20, d21) = (v.dot(e1), v.dot(e2));
        let den = d00 * d11 - d01 * d01;
        let (b1, b2) = if den > 0.0 {
            ((d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den)
        } else {
            (0.0, 0.0)
        };
        let [uv0, uv1, uv2] = self.triangle_uvs[i];
        uv0 * (1.0 - b1 - b2) + uv1 * b1 + uv2 * b2
    }

    /// Whether `material_seen` makes triangle `tri` black: a ray from `wo` sees the back of a
    /// one-sided material, which absorbs all light arriving there.
    #[inline(always)]
    pub fn seen_from_behind(&self, tri: u32, wo: Vec3, ng: Vec3) -> bool {
        self.black_behind[self.triangles.material[tri as usize] as usize] && wo.dot(ng) < 0.0
    }

    /// Next-event estimation's light sample from the surface point (p, its error bound,
    /// geometric normal ng) seen along wo: an emitter point by `sample_emitter`, or None when
    /// the point faces away from it or it lies on the other side of the surface than wo and
    /// the surface does not transmit (`transmits`, see `MaterialKind::transmits`).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub fn sample_light_from(
        &self,
        p: Vec3,
        p_error: Vec3,
        ng: Vec3,
        wo: Vec3,
        transmits: bool,
        u_pick: f32,
        u_point: glam::Vec2,
    ) -> Option<LightSample> {
        let wo_ng = wo.dot(ng);
        let reaches = |wi: Vec3| {
            let side = wi.dot(ng) * wo_ng;
            side > 0.0 || (transmits && side < 0.0)
        };
        if let Some((env_index, env)) = self.emitters.environment()
            && crate::sampling::sample_cdf(&self.emitters.cdf, u_pick) == env_index
        {
            let (wi, pdf_dir) = env.sample(u_point);
            if pdf_dir <= 0.0 || pdf_dir.is_nan() || !reaches(wi) {
                return None;
            }
            return Some(self.environment_sample(p, p_error, ng, env_index, env, wi, pdf_dir));
        }
        let sampled = self.sample_emitter(u_pick, u_point);
        if self.emitters.is_directional(sampled.emitter) {
            // A delta direction: the irradiance it brings, no falloff, a shadow ray that must
            // leave the scene.
            let wi = -self.emitters.position[sampled.emitter];
            if !reaches(wi) {
                return None;
            }
            return Some(LightSample {
                wi,
                pdf: sampled.pdf_area,
                origin: crate::geometry::offset_ray_origin(p, p_error, ng, wi),
                dir: wi,
                t_max: f32::INFINITY,
                radiance: self.emitters.radiance[sampled.emitter],
                delta: true,
            });
        }
        let light = sampled.point;
        let to_light = light.p - p;
        let dist2 = to_light.length_squared();
        let wi = to_light / dist2.sqrt();
        if sampled.triangle & POINT_LIGHT != 0 {
            // A delta position: no other technique finds it, and the intensity falls off
            // with the squared distance.
            if !wi.is_finite() || !reaches(wi) {
                return None;
            }
            let origin = crate::geometry::offset_ray_origin(p, p_error, ng, wi);
            return Some(LightSample {
                wi,
                pdf: sampled.pdf_area,
                origin,
                dir: light.p - origin,
                t_max: 1.0 - crate::geometry::SHADOW_EPSILON,
                radiance: self.emitters.intensity_towards(sampled.emitter, -wi) / dist2,
                delta: true,
            });
        }
        let cos_light = -wi.dot(light.ng);
        if cos_light <= 0.0 || !reaches(wi) {
            return None;
        }
        let (origin, dir, t_max) =
            crate::geometry::spawn_ray_to(p, p_error, ng, light.p, light.p_error, light.ng);
        Some(LightSample {
            wi,
            pdf: sampled.pdf_area * dist2 / cos_light,
            origin,
            dir,
            t_max,
            radiance: self.emitters.radiance[sampled.emitter],
            delta: false,
        })
    }

    /// `sample_light_from`'s sample of the light at infinity (emitter `e`): direction `wi`
    /// drawn by the environment's own distribution with density `pdf_dir`, and a shadow ray
    /// that must leave the scene.
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn environment_sample(
        &self,
        p: Vec3,
        p_error: Vec3,
        ng: Vec3,
        e: usize,
        env: &environment::Environment,
        wi: Vec3,
        pdf_dir: f32,
    ) -> LightSample {
        let origin = crate::geometry::offset_ray_origin(p, p_error, ng, wi);
        LightSample {
            wi,
            pdf: self.emitters.pmf[e] * pdf_dir,
            origin,
            dir: wi,
            t_max: f32::INFINITY,
            radiance: env.eval(wi),
            delta: false,
        }
    }

    /// The density with which light sampling picks the light at infinity in direction `dir`
    /// (the emitter's probability times the environment's solid-angle density), for MIS of
    /// paths that leave the scene.
    #[inline]
    pub fn environment_light_pdf(&self, dir: Vec3) -> f32 {
        match self.emitters.environment() {
            Some((e, env)) => self.emitters.pmf[e] * env.pdf(dir),
            None => 0.0,
        }
    }

    /// The emitter point for `u_pick` (which emitter) and `u_point` (where on it). The scene
    /// must have an emitter.
    #[inline]
    pub fn sample_emitter(&self, u_pick: f32, u_point: glam::Vec2) -> EmitterPoint {
        let emitters = &self.emitters;
        let e = crate::sampling::sample_cdf(&emitters.cdf, u_pick);
        let triangle = emitters.triangle[e];
        if triangle & POINT_LIGHT != 0 {
            return EmitterPoint {
                emitter: e,
                triangle,
                point: crate::geometry::SurfacePoint {
                    p: emitters.position[e],
                    p_error: Vec3::ZERO,
                    ng: Vec3::Z,
                    ns: Vec3::Z,
                },
                pdf_area: emitters.pmf[e],
            };
        }
        let b = crate::sampling::uniform_triangle(u_point);
        EmitterPoint {
            emitter: e,
            triangle,
            point: crate::geometry::surface_point(&self.triangles, triangle, b.x, b.y),
            pdf_area: emitters.pmf[e] / emitters.area[e],
        }
    }
}

/// A scene error that names the file, the line and column where known, and what is wrong.
#[derive(Debug, thiserror::Error)]
#[error("{}{}: {message}", .file.display(), location(*.line, *.column))]
pub struct SceneError {
    pub file: PathBuf,
    pub line: Option<usize>,
    pub column: Option<usize>,
    pub message: String,
}

fn location(line: Option<usize>, column: Option<usize>) -> String {
    match (line, column) {
        (Some(l), Some(c)) => format!(":{l}:{c}"),
        (Some(l), None) => format!(":{l}"),
        _ => String::new(),
    }
}

/// The emitted power of a scene, pi x area x radiance summed over its emitters, must stay
/// below this in every channel: light subpaths and photons carry it in f32, times geometry
/// and BSDF factors (emission of 1e34 overflowed to a black image).
pub const MAX_POWER: f64 = 1e30;

/// Bytes a triangle costs while a scene is built, prepared and put in the tree, at most
/// (mesh in f64, prepared columns, vertex normals, the BVH build and its leaves): what the
/// memory estimate before meshing multiplies triangle counts by.
pub const BYTES_PER_TRIANGLE: u64 = 400;

/// What a scene may cost to load.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Memory the scene's triangles may take (estimated before meshing); None: no limit.
    pub memory: Option<crate::sysinfo::MemoryLimit>,
}

impl Limits {
    /// The memory this process may use (`sysinfo::memory_limit`).
    pub fn of_this_machine() -> Limits {
        Limits {
            memory: crate::sysinfo::memory_limit(),
        }
    }
}

/// Most characters of a user's string (a name, a number) a message repeats.
pub const ECHO_CHARS: usize = 60;

/// A user's string as a message repeats it: control characters escaped, and at most
/// `ECHO_CHARS` characters of it (then "... (N bytes)"), so a 1 MB name gives a short line.
pub fn echo(s: &str) -> String {
    clip(s, ECHO_CHARS)
}

/// A path as a message repeats it: at most 200 characters (a scene may name a mesh file with
/// a path as long as itself).
pub fn echo_path(path: &Path) -> String {
    clip(&path.display().to_string(), 200)
}

/// `s` with control characters escaped, cut after `max_chars` characters (then
/// "... (N bytes)").
pub fn clip(s: &str, max_chars: usize) -> String {
    let mut out = String::new();
    for (count, c) in s.chars().enumerate() {
        if count == max_chars {
            out.push_str(&format!("... ({} bytes)", s.len()));
            break;
        }
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

fn file_error(path: &Path, message: String) -> SceneError {
    SceneError {
        file: path.to_path_buf(),
        line: None,
        column: None,
        message,
    }
}

/// Reads a RON scene and prepares it for rendering.
pub fn load(path: &Path) -> Result<PreparedScene, SceneError> {
    load_with(path, &Limits::of_this_machine())
}

/// `load` within `limits`.
pub fn load_with(path: &Path, limits: &Limits) -> Result<PreparedScene, SceneError> {
    load_with_defines(path, &[], limits)
}

/// Whether `path` names a Mitsuba scene file (by its extension, `.xml`); others are RON.
pub fn is_mitsuba(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("xml"))
}

/// Reads a RON or Mitsuba XML scene and prepares it; `defines` set a Mitsuba file's `$name`
/// parameters (a RON scene has none: giving one is an error).
pub fn load_with_defines(
    path: &Path,
    defines: &mitsuba::Defines,
    limits: &Limits,
) -> Result<PreparedScene, SceneError> {
    if is_mitsuba(path) {
        let (world, _) = mitsuba::build::load(path, defines, limits)?;
        return prepare(&world);
    }
    if let Some((name, _)) = defines.first() {
        return Err(file_error(
            path,
            format!(
                "-D {}: parameters are for Mitsuba scene files (.xml); this is a RON scene",
                echo(name)
            ),
        ));
    }
    if std::fs::metadata(path).is_ok_and(|m| m.is_dir()) {
        return Err(file_error(path, "is a folder, not a scene file".into()));
    }
    let bytes = std::fs::read(path)
        .map_err(|e| file_error(path, format!("cannot read the scene file: {e}")))?;
    let text = text_of(path, &bytes)?;
    load_from_str_with(path, text, limits)
}

/// The scene file's bytes as text: UTF-8, or an error at the line and column of the first
/// byte that is not (with its byte offset).
pub fn text_of<'a>(path: &Path, bytes: &'a [u8]) -> Result<&'a str, SceneError> {
    std::str::from_utf8(bytes).map_err(|e| {
        let offset = e.valid_up_to();
        // The prefix up to the bad byte is valid UTF-8.
        let before = std::str::from_utf8(&bytes[..offset]).unwrap_or("");
        let spot = parse::Positions::new(before).at(offset);
        SceneError {
            file: path.to_path_buf(),
            line: Some(spot.line),
            column: Some(spot.column),
            message: format!(
                "the scene file is not UTF-8 text: byte 0x{:02x} at byte offset {offset}",
                bytes[offset]
            ),
        }
    })
}

/// Prepares scene text as if read from `source` (named by errors; mesh paths are relative to
/// its directory).
pub fn load_from_str(source: &Path, text: &str) -> Result<PreparedScene, SceneError> {
    load_from_str_with(source, text, &Limits::of_this_machine())
}

/// `load_from_str` within `limits`.
pub fn load_from_str_with(
    source: &Path,
    text: &str,
    limits: &Limits,
) -> Result<PreparedScene, SceneError> {
    let parsed = parse(source, text)?;
    let world = world::build_with(&parsed, limits)?;
    prepare(&world)
}

/// A Mitsuba scene's text prepared as if read from `source` (includes and meshes resolve
/// against its folder), with the file's settings.
pub fn load_mitsuba_from_str(
    source: &Path,
    text: &str,
    defines: &mitsuba::Defines,
    limits: &Limits,
) -> Result<(PreparedScene, mitsuba::FileSettings), SceneError> {
    let doc =
        mitsuba::document::read_str(source, text, defines).map_err(mitsuba::build::scene_error)?;
    let (world, settings) = mitsuba::build::build(&doc, limits)?;
    Ok((prepare(&world)?, settings))
}

/// A prepared scene with its acceleration structure: everything systems read while rendering.
pub struct SceneData {
    pub scene: PreparedScene,
    pub accel: crate::accel::Accel,
}

impl SceneData {
    pub fn new(scene: PreparedScene) -> SceneData {
        let accel = crate::accel::Accel::build(&scene.triangles);
        SceneData { scene, accel }
    }

    /// Bytes of the tree (nodes and triangles in leaf order) and the triangle columns: what
    /// tracing and shading read at random.
    pub fn geometry_bytes(&self) -> usize {
        let (nodes, leaves) = self.accel.memory_bytes();
        nodes + leaves + self.scene.triangles.memory_bytes()
    }
}
