//! Scenes: the RON description, OBJ loading, procedural shapes, the hecs world of scene
//! entities, and "prepare", which flattens that world once into render data.

mod camera;
pub use camera::Frustum;
pub mod format;
pub mod parse;
pub mod prepare;
pub mod shapes;
pub mod world;

pub use parse::{Located, ParsedScene, parse};
pub use prepare::prepare;
pub use world::SceneWorld;

use crate::bsdf::Material;
use glam::Vec3;
use std::path::{Path, PathBuf};

pub use crate::geometry::{FLAT, NO_EMITTER, TriangleColumns};

/// A pinhole camera. The image's right is forward x up; row 0 is the top row.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    /// Unit vectors: `right = forward x up` (normalised), `up` re-orthogonalised.
    pub forward: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    /// Full vertical field of view in degrees, in (0, 180).
    pub fov_y_degrees: f32,
    pub width: u32,
    pub height: u32,
}

/// The emitting triangles and the distribution that picks one by power.
#[derive(Clone, Debug, Default)]
pub struct Emitters {
    /// Triangle id of each emitter.
    pub triangle: Vec<u32>,
    /// Constant radiance, emitted on the geometric normal's side only.
    pub radiance: Vec<Vec3>,
    pub area: Vec<f32>,
    /// Probability of picking each emitter (proportional to pi * area * luminance(radiance)).
    pub pmf: Vec<f32>,
    /// Running sum of `pmf`, ending at exactly 1.
    pub cdf: Vec<f32>,
    /// Total emitted power, sum of pi * area * radiance (RGB).
    pub total_power: Vec3,
}

/// The render data of a scene: what systems read while rendering. No hecs queries happen
/// after this is built.
#[derive(Clone, Debug)]
pub struct PreparedScene {
    pub source: PathBuf,
    pub camera: Camera,
    pub triangles: TriangleColumns,
    pub materials: Vec<Material>,
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
}

impl PreparedScene {
    /// Next-event estimation's light sample from the surface point (p, its error bound,
    /// geometric normal ng) seen along wo: an emitter point by `sample_emitter`, or None when
    /// the point faces away from it or it lies on the other side of the surface than wo.
    #[inline(always)]
    pub fn sample_light_from(
        &self,
        p: Vec3,
        p_error: Vec3,
        ng: Vec3,
        wo: Vec3,
        u_pick: f32,
        u_point: glam::Vec2,
    ) -> Option<LightSample> {
        let sampled = self.sample_emitter(u_pick, u_point);
        let light = sampled.point;
        let to_light = light.p - p;
        let dist2 = to_light.length_squared();
        let wi = to_light / dist2.sqrt();
        let cos_light = -wi.dot(light.ng);
        if cos_light <= 0.0 || wi.dot(ng) * wo.dot(ng) <= 0.0 {
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
        })
    }

    /// The emitter point for `u_pick` (which emitter) and `u_point` (where on it). The scene
    /// must have an emitter.
    #[inline]
    pub fn sample_emitter(&self, u_pick: f32, u_point: glam::Vec2) -> EmitterPoint {
        let emitters = &self.emitters;
        let e = crate::sampling::sample_cdf(&emitters.cdf, u_pick);
        let b = crate::sampling::uniform_triangle(u_point);
        let triangle = emitters.triangle[e];
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

/// Reads a RON scene and prepares it for rendering.
pub fn load(path: &Path) -> Result<PreparedScene, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError {
        file: path.to_path_buf(),
        line: None,
        column: None,
        message: format!("cannot read the scene file: {e}"),
    })?;
    load_from_str(path, &text)
}

/// Prepares scene text as if read from `source` (named by errors; mesh paths are relative to
/// its directory).
pub fn load_from_str(source: &Path, text: &str) -> Result<PreparedScene, SceneError> {
    let parsed = parse(source, text)?;
    let world = world::build(&parsed)?;
    prepare(&world)
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
}
