//! The scene as a hecs world: the camera, each material and each object is an entity.
//! `build` fills it from the parsed file (meshing every shape, reading OBJ and PLY files);
//! `super::prepare` reads it once into render data.

use super::format::{CameraDesc, MaterialDesc, ShapeDesc, TransformDesc};
use super::shapes::{self, Mesh};
use super::{Camera, ParsedScene, SceneError};
use crate::bsdf::Material;
use crate::bsdf::conductor::Conductor;
use crate::bsdf::dielectric::{Dielectric, ThinDielectric};
use crate::bsdf::diffuse::Diffuse;
use glam::{DAffine3, DQuat, Vec3};
use hecs::{Entity, EntityBuilder, World};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A scene's entities, before preparation.
pub struct SceneWorld {
    pub world: World,
    /// The scene file, named by errors.
    pub source: PathBuf,
    /// Messages found while building (e.g. a mesh file's unusable normals).
    pub warnings: Vec<String>,
}

/// Where an entity was declared in the scene file (1-based), for messages.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SourceSpot {
    pub line: usize,
    pub column: usize,
}

/// A point light (Mitsuba's `point` emitter): `intensity` (W/sr, RGB) in every direction from
/// `position`; `order` among the file's point lights.
#[derive(Clone, Copy, Debug)]
pub struct PointLight {
    pub position: glam::DVec3,
    pub intensity: Vec3,
    /// How it sends its intensity out: alike everywhere, a spot's cone (Mitsuba's `spot`) or a
    /// projector's frustum (`projector`).
    pub profile: super::lights::PointProfile,
    pub order: u32,
}

/// A directional light (Mitsuba's `directional` emitter): `irradiance` (W/m^2, RGB) arriving
/// from every point of the scene's far side along `direction` (unit, the way light travels);
/// `order` among the file's directional lights.
#[derive(Clone, Copy, Debug)]
pub struct DirectionalLight {
    pub direction: glam::DVec3,
    pub irradiance: Vec3,
    pub order: u32,
}

/// The texture a spot light or a projector projects (its profile says how).
#[derive(Clone, Debug)]
pub struct ProjectedTexture(pub super::textures::Texture);

/// The light at infinity (Mitsuba's `constant` or `envmap` emitter).
#[derive(Clone, Debug)]
pub struct EnvironmentLight(pub super::environment::Environment);

/// What a material entity reads at each shading point rather than holds: its textured
/// parameters (a Mitsuba `diffuse` or `roughconductor` with nested textures) and whether its
/// lobe is anisotropic, and so turns with the surface's uv tangent.
#[derive(Clone, Debug, Default)]
pub struct SurfaceVarying {
    /// A diffuse's reflectance, a conductor's specular_reflectance.
    pub reflectance: Option<super::textures::Texture>,
    /// A conductor's alpha_u (its alpha when isotropic) and alpha_v, read as Mitsuba's
    /// `eval_1` reads a texture.
    pub alpha_u: Option<super::textures::Texture>,
    pub alpha_v: Option<super::textures::Texture>,
    /// The lobe follows the uv tangent (Mitsuba's dp/du): an anisotropic conductor.
    pub anisotropic: bool,
}

/// Marks a material entity that reflects only on the side its geometric normal faces (a
/// Mitsuba `diffuse` not wrapped in `twosided`): seen from behind it is black.
#[derive(Clone, Copy, Debug)]
pub struct OneSided;

/// On a twosided material of two BSDFs (the front's entity): the material seen from behind
/// the surface's normal.
#[derive(Clone, Copy, Debug)]
pub struct BackMaterial(pub hecs::Entity);

/// A material entity's name and declaration order.
#[derive(Clone, Debug)]
pub struct MaterialInfo {
    pub name: String,
    pub order: u32,
}

/// A scene object's declaration order (triangle ids follow it) and optional name.
#[derive(Clone, Debug)]
pub struct ObjectInfo {
    pub order: u32,
    pub name: Option<String>,
}

/// The object's mesh in object space.
pub struct Shape(pub Mesh);

/// Object space to world space.
#[derive(Clone, Copy, Debug)]
pub struct Transform(pub DAffine3);

/// The material entity an object uses.
#[derive(Clone, Copy, Debug)]
pub struct MaterialRef(pub Entity);

/// Constant radiance emitted on the geometric normal's side of every triangle of the object.
#[derive(Clone, Copy, Debug)]
pub struct Emission(pub Vec3);

/// The file an entity was declared in, where it is not the scene file itself (a Mitsuba
/// scene's `include`s): errors name it with the entity's `SourceSpot`.
#[derive(Clone, Debug)]
pub struct DeclaredIn(pub PathBuf);

/// Marks an object whose triangles are reversed (and vertex normals negated).
#[derive(Clone, Copy, Debug)]
pub struct FlipNormals;

/// Spawns the camera, the materials and the objects of a parsed scene.
pub fn build(parsed: &ParsedScene) -> Result<SceneWorld, SceneError> {
    build_with(parsed, &super::Limits::of_this_machine())
}

/// `build` within `limits`: the triangles' memory is estimated before each shape is meshed.
pub fn build_with(parsed: &ParsedScene, limits: &super::Limits) -> Result<SceneWorld, SceneError> {
    let source = parsed.source.clone();
    let mut world = World::new();
    let mut warnings = Vec::new();

    let camera = make_camera(&parsed.camera.desc).map_err(|message| SceneError {
        file: source.clone(),
        line: Some(parsed.camera.spot.line),
        column: Some(parsed.camera.spot.column),
        message,
    })?;
    world.spawn((camera, parsed.camera.spot.clone()));

    let materials: HashMap<&str, Entity> = parsed
        .materials
        .iter()
        .enumerate()
        .map(|(order, (name, desc))| {
            let info = MaterialInfo {
                name: name.clone(),
                order: order as u32,
            };
            (name.as_str(), world.spawn((info, make_material(desc))))
        })
        .collect();
    let mut triangles_so_far: u64 = 0;

    let base_dir = source.parent().unwrap_or(Path::new("")).to_path_buf();
    for (order, object) in parsed.objects.iter().enumerate() {
        let error = |message: String| SceneError {
            file: source.clone(),
            line: Some(object.spot.line),
            column: Some(object.spot.column),
            message,
        };
        let desc = &object.desc;
        let material = materials
            .get(desc.material.as_str())
            .copied()
            .ok_or_else(|| {
                error(format!(
                    "unknown material \"{}\" (defined: {})",
                    super::echo(&desc.material),
                    defined_names(&parsed.materials)
                ))
            })?;
        // Procedural shapes are counted before they are meshed, mesh files once read.
        let memory_check = |triangles: u64| {
            crate::sysinfo::check_memory(
                &format!("the scene's {triangles} triangles"),
                triangles.saturating_mul(super::BYTES_PER_TRIANGLE),
                limits.memory,
            )
        };
        if let Some(count) = triangle_count(&desc.shape) {
            memory_check(triangles_so_far.saturating_add(count)).map_err(error)?;
        }
        let mesh = make_mesh(&desc.shape, &base_dir, &mut warnings).map_err(error)?;
        triangles_so_far = triangles_so_far.saturating_add(mesh.triangles.len() as u64);
        memory_check(triangles_so_far).map_err(error)?;
        let mut entity = EntityBuilder::new();
        entity.add_bundle((
            ObjectInfo {
                order: order as u32,
                name: desc.name.clone(),
            },
            object.spot.clone(),
            Shape(mesh),
            Transform(make_transform(&desc.transform)),
            MaterialRef(material),
        ));
        // Optional components: their absence is the common case.
        if let Some(radiance) = desc.emission {
            entity.add(Emission(radiance.0));
        }
        if desc.flip_normals {
            entity.add(FlipNormals);
        }
        world.spawn(entity.build());
    }
    Ok(SceneWorld {
        world,
        source,
        warnings,
    })
}

/// The defined material names for a message: the first few, and how many more.
fn defined_names(materials: &[(String, MaterialDesc)]) -> String {
    const SHOWN: usize = 8;
    if materials.is_empty() {
        return "none".to_string();
    }
    let mut names: Vec<String> = materials
        .iter()
        .take(SHOWN)
        .map(|(n, _)| super::echo(n))
        .collect();
    if materials.len() > SHOWN {
        names.push(format!("and {} more", materials.len() - SHOWN));
    }
    names.join(", ")
}

/// The number of triangles a procedural shape will have (None for a mesh file: counted when
/// read).
fn triangle_count(shape: &ShapeDesc) -> Option<u64> {
    Some(match shape {
        ShapeDesc::Quad(..) => 2,
        ShapeDesc::Triangle(..) => 1,
        ShapeDesc::Box { .. } => 12,
        ShapeDesc::Icosphere { level, .. } => 20u64 << (2 * level.0),
        ShapeDesc::Torus { nu, nv, .. } => 2 * nu.0 as u64 * nv.0 as u64,
        ShapeDesc::Obj(_) | ShapeDesc::Ply(_) => return None,
    })
}

/// The camera frame: forward = normalize(look_at - position), right = normalize(forward x up),
/// up = right x forward.
fn make_camera(desc: &CameraDesc) -> Result<Camera, String> {
    let position = desc.position.0;
    if position.abs().max_element() >= super::MAX_COORDINATE {
        return Err(format!(
            "camera position {:?} is too far out: coordinates must stay below {:e} in magnitude",
            position.to_array(),
            super::MAX_COORDINATE
        ));
    }
    let forward = (desc.look_at.0 - position)
        .try_normalize()
        .ok_or("camera position and look_at are the same point")?;
    let up = desc
        .up
        .0
        .try_normalize()
        .ok_or("camera up vector is zero")?;
    let side = forward.cross(up);
    // sin of the angle between forward and up: below ~1e-6 the frame is undefined.
    if side.length() < 1e-6 {
        return Err("camera looks along its up vector: forward and up are parallel".to_string());
    }
    let right = side.normalize();
    let up = right.cross(forward);
    Ok(Camera {
        position: position.as_vec3(),
        forward: forward.as_vec3(),
        right: right.as_vec3(),
        up: up.as_vec3(),
        fov_y_degrees: desc.fov.0 as f32,
        width: desc.width.0,
        height: desc.height.0,
        crop: super::Crop::whole(desc.width.0, desc.height.0),
        projection: super::Projection::Perspective,
        filter: crate::scene::filter::PixelFilter::Box,
    })
}

fn make_material(desc: &MaterialDesc) -> Material {
    match *desc {
        MaterialDesc::Diffuse { reflectance } => Material::Diffuse(Diffuse {
            reflectance: reflectance.0,
        }),
        MaterialDesc::Dielectric { ior } => Material::Dielectric(Dielectric { ior: ior.0 }),
        MaterialDesc::ThinDielectric { ior } => {
            Material::ThinDielectric(ThinDielectric { ior: ior.0 })
        }
        MaterialDesc::RoughPlastic {
            diffuse,
            alpha,
            ior,
        } => Material::RoughPlastic(crate::bsdf::plastic::RoughPlastic::new(
            crate::bsdf::conductor::Microfacet::Beckmann,
            alpha.0,
            ior.map_or(1.49, |i| i.0),
            diffuse.0,
            diffuse.0.element_sum() / 3.0,
            Vec3::ONE,
            false,
        )),
        MaterialDesc::RoughDielectric { alpha, ior } => {
            Material::RoughDielectric(crate::bsdf::rough_dielectric::RoughDielectric::isotropic(
                crate::bsdf::conductor::Microfacet::Beckmann,
                alpha.0,
                ior.0,
            ))
        }
        MaterialDesc::Plastic { diffuse, ior } => {
            Material::Plastic(crate::bsdf::smooth_plastic::SmoothPlastic::new(
                ior.map_or(1.49, |i| i.0),
                diffuse.0,
                diffuse.0.element_sum() / 3.0,
                Vec3::ONE,
                false,
            ))
        }
        MaterialDesc::Conductor { alpha, reflectance } => {
            Material::Conductor(Conductor::ggx(alpha.0, reflectance.0))
        }
    }
}

/// The mesh of a shape; a mesh file's warnings go to `warnings`.
fn make_mesh(
    shape: &ShapeDesc,
    base_dir: &Path,
    warnings: &mut Vec<String>,
) -> Result<Mesh, String> {
    Ok(match shape {
        ShapeDesc::Quad(a, b, c, d) => shapes::quad(a.0, b.0, c.0, d.0),
        ShapeDesc::Triangle(a, b, c) => shapes::triangle(a.0, b.0, c.0),
        ShapeDesc::Box { min, max } => {
            if !min.0.cmplt(max.0).all() {
                return Err(format!(
                    "box min {:?} must be below max {:?} on every axis",
                    min.0.to_array(),
                    max.0.to_array()
                ));
            }
            shapes::cuboid(min.0, max.0)
        }
        ShapeDesc::Icosphere { level, smooth } => shapes::icosphere(level.0, *smooth),
        ShapeDesc::Torus {
            major_radius,
            minor_radius,
            nu,
            nv,
        } => shapes::torus(major_radius.0, minor_radius.0, nu.0, nv.0),
        ShapeDesc::Obj(file) => {
            let obj = super::obj::load_obj(&base_dir.join(file))?;
            warnings.extend(obj.warnings);
            obj.mesh
        }
        ShapeDesc::Ply(file) => {
            let ply = super::ply::load_ply(&base_dir.join(file))?;
            warnings.extend(ply.warnings);
            ply.mesh
        }
    })
}

/// Composes the list, first entry applied first.
fn make_transform(list: &[TransformDesc]) -> DAffine3 {
    list.iter().fold(DAffine3::IDENTITY, |acc, t| {
        let step = match *t {
            TransformDesc::Translate(offset) => DAffine3::from_translation(offset.0),
            TransformDesc::Rotate { axis, degrees } => DAffine3::from_quat(DQuat::from_axis_angle(
                axis.0.normalize(),
                degrees.0.to_radians(),
            )),
            TransformDesc::Scale(factors) => DAffine3::from_scale(factors.0),
        };
        step * acc
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::format::{Direction, Finite, Point, ScaleDesc};
    use glam::DVec3;

    #[test]
    fn transforms_apply_in_order() {
        let t = make_transform(&[
            TransformDesc::Scale(ScaleDesc(DVec3::splat(2.0))),
            TransformDesc::Rotate {
                axis: Direction(DVec3::Y),
                degrees: Finite(90.0),
            },
            TransformDesc::Translate(Point(DVec3::new(1.0, 0.0, 0.0))),
        ]);
        // (1,0,0) -> scale (2,0,0) -> rotate about y by 90 degrees (0,0,-2) -> (1,0,-2).
        let p = t.transform_point3(DVec3::X);
        assert!((p - DVec3::new(1.0, 0.0, -2.0)).length() < 1e-12, "{p}");
    }
}
