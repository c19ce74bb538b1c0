//! Mitsuba 3 plugin objects interpreted as stagelight's scene world: the sensor as the camera,
//! the film's size, the BSDFs as materials, the shapes as meshes with their area emitters, the
//! sampler's sample count and the integrator's depth as the file's defaults for `--spp` and
//! `--max-depth`.
//!
//! Every parameter of a plugin is read by name; what is left unread at the end is an error
//! naming it (`Params::finish`), so nothing a file asks for is silently dropped. The parameters
//! that change only noise or nothing (`IGNORED_*` below) are read and ignored on purpose.

use super::document::{
    Child, Class, Defines, Document, Object, ObjectId, Property, Spectrum, Spot, Value, XmlError,
};
use crate::bsdf::Material;
use crate::bsdf::conductor::{ComplexIor, Conductor, Microfacet};
use crate::bsdf::dielectric::{Dielectric, ThinDielectric};
use crate::bsdf::diffuse::Diffuse;
use crate::bsdf::plastic::RoughPlastic;
use crate::bsdf::rough_dielectric::RoughDielectric;
use crate::bsdf::smooth_plastic::SmoothPlastic;
use crate::scene::filter::{Gaussian, PixelFilter};
use crate::scene::lights::{NO_TEXTURE, PointProfile, Projector, SpotProjection};
use crate::scene::shapes::Mesh;
use crate::scene::textures::{Bitmap, Filter, Pattern, Texture, UvTransform, Wrap, read_image};
use crate::scene::world::{
    BackMaterial, DeclaredIn, DirectionalLight, Emission, EnvironmentLight, FlipNormals,
    MaterialInfo, MaterialRef, ObjectInfo, OneSided, PointLight, ProjectedTexture, SceneWorld,
    Shape, SourceSpot, SurfaceVarying, Transform,
};
use crate::scene::{Camera, Crop, Limits, Projection, SceneError};

/// Whether a material reflects on both sides of a surface or only where its normal points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sides {
    One,
    Two,
}
use glam::{DAffine3, DMat4, DVec3, Vec3};
use hecs::{Entity, EntityBuilder, World};
use std::collections::HashMap;
use std::path::Path;

/// What the file says about rendering that the command line may override: the sampler's
/// `sample_count` (the default `--spp`) and the integrator's `max_depth` (the default
/// `--max-depth`, in stagelight's bounces).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FileSettings {
    pub spp: Option<u64>,
    pub max_depth: Option<u32>,
}

/// Integrators read: `path` is stagelight's `pt` (any integrator may be picked on the command
/// line; the file gives only the depth), `direct` is a path of at most two segments (emitters
/// seen directly and direct light), `moment` is read through to the integrator it wraps.
pub const INTEGRATORS: &str = "path, direct, moment";
pub const SHAPES: &str =
    "obj, ply, serialized, rectangle, disk, cube, sphere, cylinder, shapegroup, instance";
pub const BSDFS: &str = "diffuse, twosided, dielectric, thindielectric, roughdielectric, \
     conductor, roughconductor, plastic, roughplastic";
pub const EMITTERS: &str = "area, point, spot, projector, directional, constant, envmap";
pub const TEXTURES: &str = "bitmap, checkerboard";
pub const SENSORS: &str = "perspective, orthographic";
pub const FILMS: &str = "hdrfilm";
pub const RFILTERS: &str = "box, gaussian";

/// Parameters that change only noise or nothing (see docs/scene-format.md): read and ignored.
const IGNORED_INTEGRATOR: &[&str] = &[
    "rr_depth",
    "hide_emitters_false",
    "emitter_samples",
    "bsdf_samples",
];
const IGNORED_SENSOR: &[&str] = &["focus_distance", "shutter_open", "shutter_close"];
const IGNORED_FILM: &[&str] = &[
    "pixel_format",
    "component_format",
    "file_format",
    "banner",
    "high_quality_edges",
    "sample_border",
];
const IGNORED_SAMPLER: &[&str] = &["seed", "jitter", "scramble"];
const IGNORED_BSDF: &[&str] = &["sample_visible"];

/// Mitsuba's near and far clipping distances when the sensor gives none.
const DEFAULT_NEAR_CLIP: f64 = 1e-2;
const DEFAULT_FAR_CLIP: f64 = 1e4;

/// What a sensor's film says: the rendered image (its crop window) and its filter.
#[derive(Clone, Copy, Debug)]
struct FilmSpec {
    width: u32,
    height: u32,
    crop: Crop,
    filter: PixelFilter,
}

/// Mitsuba's film size when the file gives none.
const DEFAULT_WIDTH: i64 = 768;
const DEFAULT_HEIGHT: i64 = 576;

/// Reads a Mitsuba scene file into a scene world, with its file settings.
pub fn load(
    path: &Path,
    defines: &Defines,
    limits: &Limits,
) -> Result<(SceneWorld, FileSettings), SceneError> {
    let doc = super::document::read(path, defines).map_err(scene_error)?;
    build(&doc, limits)
}

/// The file settings alone (no mesh is read): the command line needs them before it renders.
pub fn file_settings(path: &Path, defines: &Defines) -> Result<FileSettings, SceneError> {
    let doc = super::document::read(path, defines).map_err(scene_error)?;
    let mut builder = Builder::new(&doc);
    builder.settings_only = true;
    builder.run().map_err(scene_error)?;
    Ok(builder.settings)
}

/// Builds the world of a read document.
pub fn build(doc: &Document, limits: &Limits) -> Result<(SceneWorld, FileSettings), SceneError> {
    let mut builder = Builder::new(doc);
    builder.limits = Some(*limits);
    builder.run().map_err(scene_error)?;
    check_clip_planes(&builder.world).map_err(scene_error)?;
    let Builder {
        world,
        settings,
        warnings,
        ..
    } = builder;
    Ok((
        SceneWorld {
            world,
            source: doc.source.clone(),
            warnings,
        },
        settings,
    ))
}

pub fn scene_error(e: XmlError) -> SceneError {
    SceneError {
        file: e.file,
        line: e.line.map(|l| l as usize),
        column: e.column.map(|c| c as usize),
        message: e.message,
    }
}

/// An object's parameters, each marked when read.
struct Params<'a> {
    object: &'a Object,
    read: Vec<bool>,
}

/// How a spectrum becomes RGB: reflectances are D65-weighted and clipped to [0, 1], emitted
/// radiance is unweighted and clipped at 0 (as Mitsuba's RGB variants do).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    Reflectance,
    Emission,
    /// Not emitted, but not bounded by 1 either (a conductor's eta and k): D65-weighted like
    /// a reflectance, clipped at 0 only (Mitsuba's `get_unbounded_texture`).
    Unbounded,
}

impl<'a> Params<'a> {
    fn new(object: &'a Object) -> Params<'a> {
        Params {
            object,
            read: vec![false; object.properties.len()],
        }
    }

    fn plugin(&self) -> String {
        format!(
            "{} \"{}\"",
            self.object.class.tag(),
            super::super::echo(&self.object.kind)
        )
    }

    fn take(&mut self, name: &str) -> Option<&'a Property> {
        let i = self.object.properties.iter().position(|p| p.name == name)?;
        self.read[i] = true;
        Some(&self.object.properties[i])
    }

    fn wrong_type(&self, p: &Property, wanted: &str) -> XmlError {
        XmlError::at(
            &p.spot,
            format!(
                "{}: parameter \"{}\" is a {}, not a {wanted}",
                self.plugin(),
                super::super::echo(&p.name),
                p.value.tag()
            ),
        )
    }

    fn float(&mut self, name: &str) -> Result<Option<(f64, Spot)>, XmlError> {
        let Some(p) = self.take(name) else {
            return Ok(None);
        };
        match p.value {
            Value::Float(v) => Ok(Some((v, p.spot.clone()))),
            Value::Integer(v) => Ok(Some((v as f64, p.spot.clone()))),
            _ => Err(self.wrong_type(p, "float")),
        }
    }

    fn integer(&mut self, name: &str) -> Result<Option<(i64, Spot)>, XmlError> {
        let Some(p) = self.take(name) else {
            return Ok(None);
        };
        match p.value {
            Value::Integer(v) => Ok(Some((v, p.spot.clone()))),
            _ => Err(self.wrong_type(p, "integer")),
        }
    }

    fn boolean(&mut self, name: &str) -> Result<Option<bool>, XmlError> {
        let Some(p) = self.take(name) else {
            return Ok(None);
        };
        match p.value {
            Value::Boolean(v) => Ok(Some(v)),
            _ => Err(self.wrong_type(p, "boolean")),
        }
    }

    fn string(&mut self, name: &str) -> Result<Option<(&'a str, Spot)>, XmlError> {
        let Some(p) = self.take(name) else {
            return Ok(None);
        };
        match &p.value {
            Value::String(v) => Ok(Some((v.as_str(), p.spot.clone()))),
            _ => Err(self.wrong_type(p, "string")),
        }
    }

    fn point(&mut self, name: &str) -> Result<Option<DVec3>, XmlError> {
        let Some(p) = self.take(name) else {
            return Ok(None);
        };
        match p.value {
            Value::Point(v) => Ok(Some(v)),
            _ => Err(self.wrong_type(p, "point")),
        }
    }

    fn vector(&mut self, name: &str) -> Result<Option<(DVec3, Spot)>, XmlError> {
        let Some(p) = self.take(name) else {
            return Ok(None);
        };
        match p.value {
            Value::Vector(v) => Ok(Some((v, p.spot.clone()))),
            _ => Err(self.wrong_type(p, "vector")),
        }
    }

    fn transform(&mut self, name: &str) -> Result<Option<(DMat4, Spot)>, XmlError> {
        let Some(p) = self.take(name) else {
            return Ok(None);
        };
        match p.value {
            Value::Transform(m) => Ok(Some((m, p.spot.clone()))),
            _ => Err(self.wrong_type(p, "transform")),
        }
    }

    /// An rgb, spectrum or float (a grey) as linear RGB.
    fn color(&mut self, name: &str, role: Role) -> Result<Option<(Vec3, Spot)>, XmlError> {
        let Some(p) = self.take(name) else {
            return Ok(None);
        };
        let rgb = match &p.value {
            Value::Rgb(v) => v.as_vec3(),
            Value::Float(v) => Vec3::splat(*v as f32),
            Value::Integer(v) => Vec3::splat(*v as f32),
            Value::Spectrum(Spectrum::Constant(v)) => match role {
                Role::Reflectance | Role::Unbounded => Vec3::splat(*v as f32),
                Role::Emission => super::spectrum::uniform_emission_rgb(*v),
            },
            Value::Spectrum(Spectrum::Pairs(pairs)) => match role {
                Role::Reflectance => super::spectrum::reflectance_rgb(pairs),
                Role::Emission => super::spectrum::emission_rgb(pairs),
                Role::Unbounded => super::spectrum::unbounded_rgb(pairs),
            },
            _ => return Err(self.wrong_type(p, "color (rgb, spectrum or float)")),
        };
        Ok(Some((rgb, p.spot.clone())))
    }

    /// `color` of a light (a radiance, intensity or irradiance): finite and not negative.
    fn light_color(&mut self, name: &str, role: Role) -> Result<Option<(Vec3, Spot)>, XmlError> {
        match self.color(name, role)? {
            Some((c, spot)) if !c.is_finite() || c.min_element() < 0.0 => Err(XmlError::at(
                &spot,
                format!("{name} {:?} must be finite and not negative", c.to_array()),
            )),
            found => Ok(found),
        }
    }

    /// A light's `scale` (1 by default): finite and not negative.
    fn light_scale(&mut self) -> Result<f64, XmlError> {
        match self.float("scale")? {
            Some((v, spot)) if !(v.is_finite() && v >= 0.0) => Err(XmlError::at(
                &spot,
                format!("scale {v} must be finite and not negative"),
            )),
            found => Ok(found.map_or(1.0, |(v, _)| v)),
        }
    }

    /// A string parameter that names one of `choices` (`default` when absent); any other value
    /// is an error listing them.
    fn keyword<T: Copy>(
        &mut self,
        name: &str,
        choices: &[(&str, T)],
        default: T,
    ) -> Result<T, XmlError> {
        let Some((value, spot)) = self.string(name)? else {
            return Ok(default);
        };
        match choices.iter().find(|(k, _)| *k == value) {
            Some(&(_, t)) => Ok(t),
            None => {
                let names: Vec<&str> = choices.iter().map(|(k, _)| *k).collect();
                Err(XmlError::at(
                    &spot,
                    format!(
                        "{} {name} \"{}\" is not supported (supported: {})",
                        self.plugin(),
                        super::super::echo(value),
                        names.join(", ")
                    ),
                ))
            }
        }
    }

    /// Marks these parameters read: they change only noise or nothing.
    fn ignore(&mut self, names: &[&str]) {
        for name in names {
            self.take(name);
        }
    }

    /// Fails on the first parameter nobody read.
    fn finish(self) -> Result<(), XmlError> {
        if let Some(i) = self.read.iter().position(|r| !r) {
            let p = &self.object.properties[i];
            return Err(XmlError::at(
                &p.spot,
                format!(
                    "{}: parameter \"{}\" is not supported (stagelight does not model it)",
                    self.plugin(),
                    super::super::echo(&p.name)
                ),
            ));
        }
        Ok(())
    }
}

struct Builder<'a> {
    doc: &'a Document,
    world: World,
    settings: FileSettings,
    warnings: Vec<String>,
    limits: Option<Limits>,
    /// Only the integrator and the sampler: no meshes are read.
    settings_only: bool,
    /// Material entities of BSDF objects already made (a BSDF referenced twice is one material).
    materials: HashMap<usize, Entity>,
    /// The default BSDF of emitting shapes (Mitsuba's: a black diffuse), made when first needed.
    default_material: Option<Entity>,
    default_diffuse: Option<Entity>,
    point_lights: u32,
    directional_lights: u32,
    /// Textures read so far, by object (shared by every ref, as the image data is).
    textures: HashMap<usize, Texture>,
    objects: u32,
    triangles_so_far: u64,
    film: Option<FilmSpec>,
}

/// A shape's mesh with its placement, ready to spawn.
struct Placed {
    mesh: Mesh,
    to_world: DAffine3,
    flip_normals: bool,
    material: usize,
    emission: Option<Vec3>,
    spot: Spot,
}

impl<'a> Builder<'a> {
    fn new(doc: &'a Document) -> Builder<'a> {
        Builder {
            doc,
            world: World::new(),
            settings: FileSettings::default(),
            warnings: Vec::new(),
            limits: None,
            settings_only: false,
            materials: HashMap::new(),
            default_material: None,
            default_diffuse: None,
            point_lights: 0,
            directional_lights: 0,
            textures: HashMap::new(),
            objects: 0,
            triangles_so_far: 0,
            film: None,
        }
    }

    fn object(&self, id: usize) -> &'a Object {
        &self.doc.objects[id]
    }

    fn run(&mut self) -> Result<(), XmlError> {
        let scene = self.doc.scene();
        Params::new(scene).finish()?;
        let mut integrators = 0;
        let mut sensors = 0;
        for child in &scene.children {
            let object = self.object(child.object);
            match object.class {
                Class::Integrator => {
                    integrators += 1;
                    if integrators > 1 {
                        return Err(XmlError::at(
                            &child.spot,
                            "a second <integrator>: a scene has one",
                        ));
                    }
                    self.integrator(child.object)?;
                }
                Class::Sensor => {
                    sensors += 1;
                    if sensors > 1 {
                        return Err(XmlError::at(
                            &child.spot,
                            "a second <sensor>: stagelight renders one camera per scene",
                        ));
                    }
                    self.sensor(child.object)?;
                }
                _ if self.settings_only => {}
                Class::Shape => {
                    let mut placed = Vec::new();
                    self.shape(child.object, DAffine3::IDENTITY, &mut placed)?;
                    for p in placed {
                        self.spawn(p)?;
                    }
                }
                // Declared for a later ref: made when a shape uses them.
                Class::Bsdf | Class::Texture => {
                    if object.id.is_none() {
                        return Err(XmlError::at(
                            &object.spot,
                            format!(
                                "a top-level <{}> without an id is never used",
                                object.class.tag()
                            ),
                        ));
                    }
                    if object.class == Class::Texture {
                        // Checked now (a diffuse refers to it by id); read where it is used.
                        self.texture(child.object)?;
                        continue;
                    }
                    // Checked now, so an unused BSDF's errors are not hidden.
                    self.material(child.object)?;
                }
                Class::Emitter => {
                    if object.kind == "area" {
                        if object.id.is_none() {
                            return Err(XmlError::at(
                                &object.spot,
                                "an area emitter outside a shape needs an id for a shape to ref",
                            ));
                        }
                        self.area_emitter(child.object)?;
                    } else if matches!(object.kind.as_str(), "point" | "spot" | "projector") {
                        let (light, texture) = self.point_emitter(child.object)?;
                        let spot = object.spot.clone();
                        let entity = self.world.spawn((
                            light,
                            source_spot(&spot),
                            DeclaredIn(spot.file.to_path_buf()),
                        ));
                        if let Some(texture) = texture {
                            self.world
                                .insert_one(entity, texture)
                                .expect("just spawned");
                        }
                    } else if object.kind == "directional" {
                        let light = self.directional_emitter(child.object)?;
                        let spot = object.spot.clone();
                        self.world.spawn((
                            light,
                            source_spot(&spot),
                            DeclaredIn(spot.file.to_path_buf()),
                        ));
                    } else if object.kind == "constant" || object.kind == "envmap" {
                        let light = self.environment_emitter(child.object)?;
                        let spot = object.spot.clone();
                        self.world.spawn((
                            light,
                            source_spot(&spot),
                            DeclaredIn(spot.file.to_path_buf()),
                        ));
                    } else {
                        return Err(unsupported(object, EMITTERS));
                    }
                }
                Class::Film | Class::Rfilter | Class::Sampler | Class::Scene => {
                    return Err(XmlError::at(
                        &object.spot,
                        format!("<{}> belongs inside a <sensor>", object.class.tag()),
                    ));
                }
            }
        }
        if self.settings_only {
            return Ok(());
        }
        if sensors == 0 {
            return Err(XmlError::at(
                &scene.spot,
                "the scene has no <sensor>: stagelight needs a camera (a perspective sensor)",
            ));
        }
        Ok(())
    }

    fn integrator(&mut self, id: usize) -> Result<(), XmlError> {
        let object = self.object(id);
        let mut params = Params::new(object);
        match object.kind.as_str() {
            "moment" => {
                params.finish()?;
                let inner: Vec<&Child> = object
                    .children
                    .iter()
                    .filter(|c| self.object(c.object).class == Class::Integrator)
                    .collect();
                match inner[..] {
                    [one] if inner.len() == object.children.len() => self.integrator(one.object),
                    _ => Err(XmlError::at(
                        &object.spot,
                        "moment wraps exactly one integrator",
                    )),
                }
            }
            "path" | "direct" => {
                let max_depth = if object.kind == "direct" {
                    // Direct light only: emitters seen directly and one bounce to a light.
                    params.ignore(&["shading_samples", "hide_emitters"]);
                    Some(2)
                } else {
                    params.integer("max_depth")?.map(|(v, _)| v)
                };
                params.ignore(IGNORED_INTEGRATOR);
                let hide = params.boolean("hide_emitters")?;
                if hide == Some(true) {
                    return Err(XmlError::at(
                        &object.spot,
                        "integrator: hide_emitters true is not supported",
                    ));
                }
                params.finish()?;
                if let Some(children) = object.children.first() {
                    return Err(XmlError::at(
                        &children.spot,
                        "this integrator takes no nested objects",
                    ));
                }
                self.settings.max_depth = match max_depth {
                    None | Some(-1) => None,
                    Some(d) => Some(
                        mitsuba_depth_to_bounces(d).map_err(|m| XmlError::at(&object.spot, m))?,
                    ),
                };
                Ok(())
            }
            _ => Err(unsupported(object, INTEGRATORS)),
        }
    }

    fn sensor(&mut self, id: usize) -> Result<(), XmlError> {
        let object = self.object(id);
        let orthographic = match object.kind.as_str() {
            "perspective" => false,
            "orthographic" => true,
            _ => return Err(unsupported(object, SENSORS)),
        };
        let mut params = Params::new(object);
        let mut film = None;
        for child in &object.children {
            let inner = self.object(child.object);
            match inner.class {
                Class::Film => film = Some(self.film(child.object)?),
                Class::Sampler => self.sampler(child.object)?,
                _ => {
                    return Err(XmlError::at(
                        &child.spot,
                        format!(
                            "a sensor holds a film and a sampler, not a <{}>",
                            inner.class.tag()
                        ),
                    ));
                }
            }
        }
        let film = match film {
            Some(film) => film,
            None => FilmSpec {
                width: DEFAULT_WIDTH as u32,
                height: DEFAULT_HEIGHT as u32,
                crop: Crop::whole(DEFAULT_WIDTH as u32, DEFAULT_HEIGHT as u32),
                filter: PixelFilter::mitsuba_default(),
            },
        };
        self.film = Some(film);
        let (film_width, film_height) = (film.crop.film_width, film.crop.film_height);
        let aspect = film_width as f64 / film_height as f64;
        let fov_y = if orthographic {
            None
        } else {
            Some(perspective_fov_y(object, &mut params, aspect)?)
        };
        let near_clip = params.float("near_clip")?;
        let far_clip = params.float("far_clip")?;
        for (clip, spot) in near_clip.iter().chain(&far_clip) {
            if !(clip.is_finite() && *clip > 0.0) {
                return Err(XmlError::at(
                    spot,
                    format!("a clipping distance must be finite and positive, not {clip}"),
                ));
            }
        }
        let near = near_clip.as_ref().map_or(DEFAULT_NEAR_CLIP, |c| c.0);
        let far = far_clip.as_ref().map_or(DEFAULT_FAR_CLIP, |c| c.0);
        if near >= far {
            let spot = far_clip.as_ref().or(near_clip.as_ref()).map(|c| &c.1);
            return Err(XmlError::at(
                spot.unwrap_or(&object.spot),
                format!("near_clip {near} must be less than far_clip {far}"),
            ));
        }
        params.ignore(IGNORED_SENSOR);
        let to_world = params.transform("to_world")?;
        params.finish()?;
        let (matrix, spot) = to_world.unwrap_or((DMat4::IDENTITY, object.spot.clone()));
        let lens = match fov_y {
            Some(fov_y) => Lens::Pinhole { fov_y },
            None => Lens::Orthographic { near },
        };
        let mut camera = camera_of(&matrix, lens, film_width, film_height)
            .map_err(|m| XmlError::at(&spot, m))?;
        camera.width = film.width;
        camera.height = film.height;
        camera.crop = film.crop;
        camera.filter = film.filter;
        if !self.settings_only {
            // An orthographic camera's rays start on the near plane (as Mitsuba's): only its
            // far plane can hide what a ray would otherwise reach.
            let near_clip = if orthographic { None } else { near_clip };
            let far_clip = match (orthographic, far_clip) {
                (true, None) => Some((DEFAULT_FAR_CLIP, object.spot.clone())),
                (_, far) => far,
            };
            self.world.spawn((
                camera,
                source_spot(&object.spot),
                DeclaredIn(object.spot.file.to_path_buf()),
                ClipPlanes {
                    near: near_clip,
                    far: far_clip,
                },
            ));
        }
        Ok(())
    }

    fn film(&mut self, id: usize) -> Result<FilmSpec, XmlError> {
        let object = self.object(id);
        if object.kind != "hdrfilm" {
            return Err(unsupported(object, FILMS));
        }
        let mut params = Params::new(object);
        let size = |v: Option<(i64, Spot)>, default: i64| -> Result<u32, XmlError> {
            match v {
                None => Ok(default as u32),
                Some((v, spot)) => {
                    if v < 1 || v > crate::scene::format::MAX_IMAGE_SIZE as i64 {
                        Err(XmlError::at(
                            &spot,
                            format!(
                                "film size {v} must lie in 1..={}",
                                crate::scene::format::MAX_IMAGE_SIZE
                            ),
                        ))
                    } else {
                        Ok(v as u32)
                    }
                }
            }
        };
        let width = size(params.integer("width")?, DEFAULT_WIDTH)?;
        let height = size(params.integer("height")?, DEFAULT_HEIGHT)?;
        // The crop window, as Mitsuba's hdrfilm checks it: inside the film, at least a pixel.
        let mut window = |axis: &str, film: u32| -> Result<(u32, u32), XmlError> {
            let offset = params.integer(&format!("crop_offset_{axis}"))?;
            let extent_name = if axis == "x" {
                "crop_width"
            } else {
                "crop_height"
            };
            let extent = params.integer(extent_name)?;
            let o = offset.as_ref().map_or(0, |v| v.0);
            if !(0..film as i64).contains(&o) {
                let spot = offset.map(|v| v.1).unwrap_or_else(|| object.spot.clone());
                return Err(XmlError::at(
                    &spot,
                    format!(
                        "hdrfilm: crop_offset_{axis} {o} must lie in 0..{film} (the film's pixels)"
                    ),
                ));
            }
            let e = extent.as_ref().map_or(film as i64 - o, |v| v.0);
            if e < 1 || o + e > film as i64 {
                let spot = extent.map(|v| v.1).unwrap_or_else(|| object.spot.clone());
                return Err(XmlError::at(
                    &spot,
                    format!(
                        "hdrfilm: {extent_name} {e} from crop_offset_{axis} {o} must lie in 1..={} \
                         (the crop window must lie inside the {film}-pixel film)",
                        film as i64 - o
                    ),
                ));
            }
            Ok((o as u32, e as u32))
        };
        let (x, crop_width) = window("x", width)?;
        let (y, crop_height) = window("y", height)?;
        params.ignore(IGNORED_FILM);
        params.finish()?;
        let mut filter = None;
        for child in &object.children {
            let inner = self.object(child.object);
            if inner.class != Class::Rfilter {
                return Err(XmlError::at(
                    &child.spot,
                    format!("a film holds an rfilter, not a <{}>", inner.class.tag()),
                ));
            }
            filter = Some(inner);
        }
        let filter = match filter {
            Some(f) if f.kind == "box" => {
                let mut p = Params::new(f);
                if let Some((radius, spot)) = p.float("radius")?
                    && radius != 0.5
                {
                    return Err(XmlError::at(
                        &spot,
                        format!(
                            "rfilter box: radius {radius} is not supported (only 0.5: each sample in its own pixel)"
                        ),
                    ));
                }
                p.finish()?;
                PixelFilter::Box
            }
            Some(f) if f.kind == "gaussian" => {
                let mut p = Params::new(f);
                let stddev = match p.float("stddev")? {
                    None => crate::scene::filter::DEFAULT_STDDEV,
                    Some((v, spot)) => {
                        // Wider than 64 pixels would splat each sample into 65536 pixels.
                        if !(v.is_finite() && v > 0.0 && v <= 16.0) {
                            return Err(XmlError::at(
                                &spot,
                                format!("rfilter gaussian: stddev {v} must lie in (0, 16] pixels"),
                            ));
                        }
                        v as f32
                    }
                };
                p.finish()?;
                PixelFilter::Gaussian(Gaussian::new(stddev).expect("checked positive"))
            }
            Some(f) => return Err(unsupported(f, RFILTERS)),
            // Mitsuba's default (texture_interp and most of mitsuba-data rely on it).
            None => PixelFilter::mitsuba_default(),
        };
        Ok(FilmSpec {
            width: crop_width,
            height: crop_height,
            crop: Crop {
                film_width: width,
                film_height: height,
                x,
                y,
            },
            filter,
        })
    }

    fn sampler(&mut self, id: usize) -> Result<(), XmlError> {
        let object = self.object(id);
        // Every sampler type changes only noise: stagelight uses its own (--sampler).
        let mut params = Params::new(object);
        if let Some((count, spot)) = params.integer("sample_count")? {
            if count < 1 {
                return Err(XmlError::at(
                    &spot,
                    format!("sample_count {count} must be at least 1"),
                ));
            }
            self.settings.spp = Some(count as u64);
        }
        params.ignore(IGNORED_SAMPLER);
        params.finish()
    }

    /// The material entity of a BSDF object (made once per object).
    fn material(&mut self, id: usize) -> Result<Entity, XmlError> {
        if let Some(&e) = self.materials.get(&id) {
            return Ok(e);
        }
        let object = self.object(id).clone();
        let name = match &object.id {
            Some(id) => id.clone(),
            None => format!("{} at line {}", object.kind, object.spot.line),
        };
        // Orders leave room for a twosided's back material right after its front.
        let order = 2 * (self.materials.len() as u32 + 1);
        if object.kind == "twosided" && object.children.len() == 2 {
            // Mitsuba's twosided of two BSDFs: the first where the surface is seen from the
            // side its normal points to, the second from the other; each reflects on the side
            // it is seen from.
            Params::new(&object).finish()?;
            let (front, back) = (&object.children[0], &object.children[1]);
            for side in [front, back] {
                let inner = self.object(side.object);
                if inner.class == Class::Bsdf && inner.kind == "plastic" {
                    // Each side's kind decides delta tests that know the triangle, not the
                    // side: a delta lobe on one side only is not modelled.
                    return Err(XmlError::at(
                        &side.spot,
                        "twosided of two BSDFs: \"plastic\" (smooth, a delta lobe) is not \
                         supported on one side only (supported: diffuse, conductor, \
                         roughconductor, roughplastic; or one plastic for both sides)",
                    ));
                }
            }
            let back_material = self.twosided_side(back)?;
            let back_varying = self.varying_of(&self.object(back.object).clone())?;
            let back_info = MaterialInfo {
                name: format!("{name} (back)"),
                order: order + 1,
            };
            let back_entity = self.world.spawn((back_info, back_material));
            if let Some(varying) = back_varying {
                self.world
                    .insert_one(back_entity, varying)
                    .expect("just spawned");
            }
            let front_material = self.twosided_side(front)?;
            let front_varying = self.varying_of(&self.object(front.object).clone())?;
            let info = MaterialInfo { name, order };
            let entity = self
                .world
                .spawn((info, front_material, BackMaterial(back_entity)));
            if let Some(varying) = front_varying {
                self.world
                    .insert_one(entity, varying)
                    .expect("just spawned");
            }
            self.materials.insert(id, entity);
            return Ok(entity);
        }
        let object = &object;
        let (material, sides) = self.material_of(object)?;
        let varying = self.varying_of(object)?;
        let info = MaterialInfo { name, order };
        let entity = self.world.spawn((info, material));
        if sides == Sides::One {
            self.world
                .insert_one(entity, OneSided)
                .expect("just spawned");
        }
        if let Some(varying) = varying {
            self.world
                .insert_one(entity, varying)
                .expect("just spawned");
        }
        self.materials.insert(id, entity);
        Ok(entity)
    }

    /// The material of a BSDF inside `twosided`, made to reflect on whichever side it is seen
    /// from (only non-transmissive BSDFs, as Mitsuba's twosided takes).
    fn twosided_side(&self, child: &Child) -> Result<Material, XmlError> {
        let inner = self.object(child.object);
        const REFLECTORS: [&str; 5] = [
            "diffuse",
            "conductor",
            "roughconductor",
            "plastic",
            "roughplastic",
        ];
        if inner.class != Class::Bsdf || !REFLECTORS.contains(&inner.kind.as_str()) {
            return Err(XmlError::at(
                &child.spot,
                format!(
                    "twosided of \"{}\" is not supported (supported: twosided of {})",
                    super::super::echo(&inner.kind),
                    REFLECTORS.join(", ")
                ),
            ));
        }
        let (mut material, _) = self.material_of(inner)?;
        match &mut material {
            Material::Conductor(c) => c.two_sided = true,
            Material::RoughPlastic(p) => p.two_sided = true,
            Material::Plastic(p) => p.two_sided = true,
            // Lambertian reflection is two-sided in the engine already.
            Material::Diffuse(_)
            | Material::Dielectric(_)
            | Material::RoughDielectric(_)
            | Material::ThinDielectric(_) => {}
        }
        Ok(material)
    }

    /// The material of a BSDF object and whether it reflects on one side or both.
    fn material_of(&self, object: &Object) -> Result<(Material, Sides), XmlError> {
        let mut params = Params::new(object);
        params.ignore(IGNORED_BSDF);
        let no_children = |object: &Object| -> Result<(), XmlError> {
            match object.children.first() {
                Some(c) => Err(XmlError::at(
                    &c.spot,
                    format!(
                        "bsdf \"{}\": a nested <{}> is not supported here (textures are read for a diffuse's reflectance only)",
                        super::super::echo(&object.kind),
                        self.object(c.object).class.tag()
                    ),
                )),
                None => Ok(()),
            }
        };
        let material = match object.kind.as_str() {
            "twosided" => {
                params.finish()?;
                let inner: Vec<&Child> = object.children.iter().collect();
                let [one] = inner[..] else {
                    return Err(XmlError::at(
                        &object.spot,
                        "twosided takes one BSDF (both sides) or two (front, back)",
                    ));
                };
                return Ok((self.twosided_side(one)?, Sides::Two));
            }
            "diffuse" => {
                drop(params);
                return Ok((self.diffuse(object)?, Sides::One));
            }
            "dielectric" | "thindielectric" => {
                let kind = object.kind.as_str();
                no_children(object)?;
                let int_ior = ior(&mut params, "int_ior", 1.5046)?;
                let ext_ior = ior(&mut params, "ext_ior", 1.000277)?;
                for name in ["specular_reflectance", "specular_transmittance"] {
                    if let Some((c, spot)) = params.color(name, Role::Reflectance)?
                        && c != Vec3::ONE
                    {
                        return Err(XmlError::at(
                            &spot,
                            format!("{kind}: {name} other than 1 is not supported yet"),
                        ));
                    }
                }
                params.finish()?;
                let ratio = (int_ior / ext_ior) as f32;
                if kind == "thindielectric" {
                    // Index-matched (ratio 1) is a valid, invisible, sheet.
                    if !(ratio.is_finite() && ratio > 0.0) {
                        return Err(XmlError::at(
                            &object.spot,
                            format!("thindielectric: int_ior / ext_ior = {ratio} must be positive"),
                        ));
                    }
                    Material::ThinDielectric(ThinDielectric { ior: ratio })
                } else {
                    if !(ratio.is_finite() && ratio > 0.0) || ratio == 1.0 {
                        return Err(XmlError::at(
                            &object.spot,
                            format!(
                                "dielectric: int_ior / ext_ior = {ratio} must be positive and not 1"
                            ),
                        ));
                    }
                    Material::Dielectric(Dielectric { ior: ratio })
                }
            }
            "conductor" | "roughconductor" => {
                let textured = self.microfacet_textures(object)?;
                let ior = conductor_ior(&mut params, object)?;
                let reflectance = params
                    .color("specular_reflectance", Role::Reflectance)?
                    .map(|(c, _)| c)
                    .unwrap_or(Vec3::ONE);
                let mut conductor = if object.kind == "roughconductor" {
                    // Visible normals or not changes only noise (Mitsuba's default: visible).
                    params.boolean("sample_visible")?;
                    let distribution = microfacet(&mut params, &object.kind)?;
                    let (alpha_u, alpha_v) = roughness(&mut params, object, &textured)?;
                    let mut c = Conductor::isotropic(distribution, alpha_u, reflectance, ior);
                    c.alpha_v = alpha_v;
                    c
                } else {
                    // A smooth mirror, as the narrowest lobe the conductor evaluates accurately
                    // (see bsdf::conductor::ALPHA_MIN).
                    Conductor::isotropic(
                        Microfacet::Ggx,
                        crate::bsdf::conductor::ALPHA_MIN,
                        reflectance,
                        ior,
                    )
                };
                if textured.iter().any(|t| t.0 == "specular_reflectance") {
                    // The texture stands in for it at every shading point.
                    conductor.reflectance = Vec3::ONE;
                }
                params.finish()?;
                Material::Conductor(conductor)
            }
            "roughdielectric" => {
                let textured = self.microfacet_textures(object)?;
                let int_ior = ior(&mut params, "int_ior", 1.5046)?;
                let ext_ior = ior(&mut params, "ext_ior", 1.000277)?;
                // Visible normals or not changes only noise (Mitsuba's default: visible).
                params.boolean("sample_visible")?;
                let distribution = microfacet(&mut params, &object.kind)?;
                let (alpha_u, alpha_v) = roughness(&mut params, object, &textured)?;
                let mut factor = |name: &str| -> Result<Vec3, XmlError> {
                    Ok(params
                        .color(name, Role::Reflectance)?
                        .map_or(Vec3::ONE, |(c, _)| c))
                };
                let reflectance = factor("specular_reflectance")?;
                let transmittance = factor("specular_transmittance")?;
                params.finish()?;
                let eta = (int_ior / ext_ior) as f32;
                if !(eta.is_finite() && eta > 0.0) || eta == 1.0 {
                    return Err(XmlError::at(
                        &object.spot,
                        format!(
                            "roughdielectric: int_ior / ext_ior = {eta} must be positive and not 1"
                        ),
                    ));
                }
                Material::RoughDielectric(RoughDielectric {
                    distribution,
                    alpha_u,
                    alpha_v,
                    axis: glam::Vec2::X,
                    eta,
                    reflectance,
                    transmittance,
                })
            }
            "plastic" | "roughplastic" => {
                let kind = object.kind.as_str();
                let diffuse_texture = match object.children.first() {
                    Some(c)
                        if c.name.as_deref() == Some("diffuse_reflectance")
                            && self.object(c.object).class == Class::Texture
                            && object.children.len() == 1 =>
                    {
                        Some(self.read_texture(c.object)?)
                    }
                    Some(c) => {
                        return Err(XmlError::at(
                            &c.spot,
                            format!(
                                "{kind}: only a texture named \"diffuse_reflectance\" may be nested"
                            ),
                        ));
                    }
                    None => None,
                };
                let int_ior = ior(&mut params, "int_ior", 1.49)?;
                let ext_ior = ior(&mut params, "ext_ior", 1.000277)?;
                // The coat's microfacets (a smooth plastic has none: Mitsuba's `plastic`
                // reads no roughness, and neither is taken here, so a stray one is an error).
                let rough = if kind == "roughplastic" {
                    // Visible normals or not changes only noise (Mitsuba's default: visible).
                    params.boolean("sample_visible")?;
                    let distribution = microfacet(&mut params, &object.kind)?;
                    for name in ["alpha_u", "alpha_v"] {
                        if let Some((_, spot)) = params.float(name)? {
                            return Err(XmlError::at(
                                &spot,
                                "roughplastic: anisotropic roughness is not supported (Mitsuba's \
                                 roughplastic refuses it too): give alpha",
                            ));
                        }
                    }
                    let (alpha, _) = roughness(&mut params, object, &[])?;
                    Some((distribution, alpha))
                } else {
                    None
                };
                let nonlinear = params.boolean("nonlinear")?.unwrap_or(false);
                let diffuse = params
                    .color("diffuse_reflectance", Role::Reflectance)?
                    .map_or(Vec3::splat(0.5), |(c, _)| c);
                let specular = params
                    .color("specular_reflectance", Role::Reflectance)?
                    .map_or(Vec3::ONE, |(c, _)| c);
                params.finish()?;
                let eta = (int_ior / ext_ior) as f32;
                if !(eta.is_finite() && eta > 0.0) || eta == 1.0 {
                    return Err(XmlError::at(
                        &object.spot,
                        format!("{kind}: int_ior / ext_ior = {eta} must be positive and not 1"),
                    ));
                }
                let diffuse_mean = match &diffuse_texture {
                    Some(t) => t.mean(),
                    None => diffuse.element_sum() / 3.0,
                };
                match rough {
                    Some((distribution, alpha)) => Material::RoughPlastic(RoughPlastic::new(
                        distribution,
                        alpha,
                        eta,
                        diffuse,
                        diffuse_mean,
                        specular,
                        nonlinear,
                    )),
                    None => Material::Plastic(SmoothPlastic::new(
                        eta,
                        diffuse,
                        diffuse_mean,
                        specular,
                        nonlinear,
                    )),
                }
            }
            _ => return Err(unsupported(object, BSDFS)),
        };
        // Dielectrics (thick or thin) scatter on both sides; conductors and plastics reflect only
        // on the front.
        Ok((material, Sides::One))
    }

    /// A conductor's nested textures, by parameter name: specular_reflectance, and for a
    /// roughconductor alpha, alpha_u and alpha_v; anything else nested is an error.
    fn microfacet_textures(
        &self,
        object: &Object,
    ) -> Result<Vec<(&'static str, ObjectId)>, XmlError> {
        let names: &[&'static str] = match object.kind.as_str() {
            "roughconductor" => &["specular_reflectance", "alpha", "alpha_u", "alpha_v"],
            "roughdielectric" => &["alpha", "alpha_u", "alpha_v"],
            _ => &["specular_reflectance"],
        };
        let mut textured = Vec::new();
        for c in &object.children {
            let child = self.object(c.object);
            match c.name.as_deref() {
                Some(name) if child.class == Class::Texture && names.contains(&name) => {
                    if textured.iter().any(|(n, _)| *n == name) {
                        return Err(XmlError::at(
                            &c.spot,
                            format!("{}: {name} is given twice", object.kind),
                        ));
                    }
                    let name = names.iter().find(|n| **n == name).expect("contained");
                    textured.push((*name, c.object));
                }
                _ => {
                    return Err(XmlError::at(
                        &c.spot,
                        format!(
                            "{}: a nested <{}>{} is not supported here (textures are read for {})",
                            object.kind,
                            child.class.tag(),
                            c.name
                                .as_deref()
                                .map(|n| format!(" named \"{}\"", super::super::echo(n)))
                                .unwrap_or_default(),
                            names.join(", ")
                        ),
                    ));
                }
            }
        }
        Ok(textured)
    }

    /// What a material reads at each shading point: a (twosided) diffuse's reflectance
    /// texture (a plastic's diffuse_reflectance), a conductor's textured parameters and whether its lobe is anisotropic; `None`
    /// for a material that is the same everywhere.
    fn varying_of(&mut self, object: &Object) -> Result<Option<SurfaceVarying>, XmlError> {
        let inner = match object.kind.as_str() {
            "twosided" => match object.children.first() {
                Some(c) => self.object(c.object),
                None => return Ok(None),
            },
            _ => object,
        };
        let mut varying = SurfaceVarying::default();
        match inner.kind.as_str() {
            "diffuse" | "plastic" | "roughplastic" => {
                if let Some(c) = inner.children.first() {
                    varying.reflectance = Some(self.texture(c.object)?);
                }
            }
            "conductor" | "roughconductor" | "roughdielectric" => {
                let inner = inner.clone();
                for (name, id) in self.microfacet_textures(&inner)? {
                    let texture = Some(self.texture(id)?);
                    match name {
                        "specular_reflectance" => varying.reflectance = texture,
                        "alpha" => {
                            varying.alpha_u = texture.clone();
                            varying.alpha_v = texture;
                        }
                        "alpha_u" => varying.alpha_u = texture,
                        _ => varying.alpha_v = texture,
                    }
                }
                // alpha_u and alpha_v given apart (as values or textures) may differ: the
                // lobe may turn with the uv tangent (`prepare` keeps the mark only where they
                // can differ).
                varying.anisotropic = inner
                    .children
                    .iter()
                    .any(|c| c.name.as_deref() == Some("alpha_u"))
                    || inner.properties.iter().any(|p| p.name == "alpha_u");
            }
            _ => {}
        }
        let varies = varying.reflectance.is_some()
            || varying.alpha_u.is_some()
            || varying.alpha_v.is_some()
            || varying.anisotropic;
        Ok(varies.then_some(varying))
    }

    /// A `bitmap` or `checkerboard` texture.
    fn texture(&mut self, id: usize) -> Result<Texture, XmlError> {
        if let Some(t) = self.textures.get(&id) {
            return Ok(t.clone());
        }
        let texture = self.read_texture(id)?;
        self.textures.insert(id, texture.clone());
        Ok(texture)
    }

    /// `texture`'s work, once per texture object (its image read once however many refs).
    fn read_texture(&self, id: usize) -> Result<Texture, XmlError> {
        let object = self.object(id);
        let mut params = Params::new(object);
        if let Some(c) = object.children.first() {
            return Err(XmlError::at(
                &c.spot,
                "a texture inside a texture is not supported",
            ));
        }
        let to_uv = match params.transform("to_uv")? {
            Some((m, _)) => UvTransform::from_mat4(&m),
            None => UvTransform::IDENTITY,
        };
        let pattern = match object.kind.as_str() {
            "bitmap" => {
                let (name, spot) = params
                    .string("filename")?
                    .ok_or_else(|| XmlError::at(&object.spot, "bitmap needs a filename"))?;
                let path = self.doc.resolve(name);
                let raw = params.boolean("raw")?.unwrap_or(false);
                let filter = params.keyword(
                    "filter_type",
                    &[("bilinear", Filter::Bilinear), ("nearest", Filter::Nearest)],
                    Filter::Bilinear,
                )?;
                let wrap = params.keyword(
                    "wrap_mode",
                    &[
                        ("repeat", Wrap::Repeat),
                        ("mirror", Wrap::Mirror),
                        ("clamp", Wrap::Clamp),
                    ],
                    Wrap::Repeat,
                )?;
                params.finish()?;
                let (width, height, texels) =
                    read_image(&path, raw).map_err(|m| XmlError::at(&spot, m))?;
                if width == 0 || height == 0 || texels.iter().any(|t| !t.is_finite()) {
                    return Err(XmlError::at(
                        &spot,
                        format!(
                            "{}: an empty image or one with NaN or infinite texels",
                            path.display()
                        ),
                    ));
                }
                Pattern::Bitmap(Bitmap {
                    width,
                    height,
                    texels: std::sync::Arc::new(texels),
                    filter,
                    wrap,
                })
            }
            "checkerboard" => {
                let color0 = params
                    .color("color0", Role::Reflectance)?
                    .map_or(Vec3::splat(0.4), |(c, _)| c);
                let color1 = params
                    .color("color1", Role::Reflectance)?
                    .map_or(Vec3::splat(0.2), |(c, _)| c);
                params.finish()?;
                Pattern::Checkerboard { color0, color1 }
            }
            _ => return Err(unsupported(object, TEXTURES)),
        };
        Ok(Texture { pattern, to_uv })
    }

    fn diffuse(&self, object: &Object) -> Result<Material, XmlError> {
        let mut params = Params::new(object);
        if let Some(c) = object.children.first() {
            let child = self.object(c.object);
            if child.class != Class::Texture || c.name.as_deref() != Some("reflectance") {
                return Err(XmlError::at(
                    &c.spot,
                    "diffuse: only a texture named \"reflectance\" may be nested",
                ));
            }
            // Read by `reflectance_texture_of`; the constant stands for it in the material.
            params.finish()?;
            return Ok(Material::Diffuse(Diffuse {
                reflectance: Vec3::splat(0.5),
            }));
        }
        let reflectance = params
            .color("reflectance", Role::Reflectance)?
            .map(|(c, _)| c)
            .unwrap_or(Vec3::splat(0.5));
        params.finish()?;
        Ok(Material::Diffuse(Diffuse { reflectance }))
    }

    fn area_emitter(&self, id: usize) -> Result<Vec3, XmlError> {
        let object = self.object(id);
        let mut params = Params::new(object);
        if let Some(c) = object.children.first() {
            return Err(XmlError::at(
                &c.spot,
                "area: a textured radiance is not supported yet",
            ));
        }
        let (radiance, _) = params
            .light_color("radiance", Role::Emission)?
            .ok_or_else(|| XmlError::at(&object.spot, "area emitter needs a radiance"))?;
        params.finish()?;
        Ok(radiance)
    }

    /// A `point` emitter: `intensity` (W/sr, default 1) from `position` or from the origin
    /// placed by `to_world` (one of the two); or a `spot`: the same from to_world's origin
    /// along its +z, within `cutoff_angle` (default 20 degrees), full within `beam_width`
    /// (default 3/4 of the cutoff); or a `projector` (`projector_emitter`).
    fn point_emitter(
        &mut self,
        id: usize,
    ) -> Result<(PointLight, Option<ProjectedTexture>), XmlError> {
        let object = self.object(id);
        let kind = object.kind.as_str();
        if kind == "projector" {
            return self.projector_emitter(id);
        }
        let mut params = Params::new(object);
        let mut projected = None;
        for c in &object.children {
            let child = self.object(c.object);
            if kind != "spot"
                || child.class != Class::Texture
                || c.name.as_deref() != Some("texture")
                || projected.is_some()
            {
                return Err(XmlError::at(
                    &c.spot,
                    format!(
                        "{kind}: only a spot's projected texture (named \"texture\") may be \
                         nested (a textured intensity is not supported)"
                    ),
                ));
            }
            projected = Some(self.texture(c.object)?);
        }
        let object = self.object(id);
        let position = if kind == "point" {
            params.point("position")?
        } else {
            None
        };
        let to_world = params.transform("to_world")?;
        let linear = to_world
            .as_ref()
            .map_or(glam::DMat3::IDENTITY, |(m, _)| glam::DMat3::from_mat4(*m));
        let (position, axis) = match (position, to_world) {
            (Some(_), Some((_, spot))) => {
                return Err(XmlError::at(
                    &spot,
                    "point: give either position or to_world, not both (as Mitsuba)",
                ));
            }
            (Some(p), None) => (p, DVec3::Z),
            (None, Some((m, _))) => (m.w_axis.truncate(), m.z_axis.truncate()),
            (None, None) => (DVec3::ZERO, DVec3::Z),
        };
        let spot = if kind == "spot" {
            let cutoff = params.float("cutoff_angle")?.map_or(20.0, |(v, _)| v);
            let beam = params
                .float("beam_width")?
                .map_or(cutoff * 0.75, |(v, _)| v);
            if !(axis.length() > 0.0 && axis.is_finite()) {
                return Err(XmlError::at(
                    &object.spot,
                    "spot: to_world flattens its axis",
                ));
            }
            let mut spot = crate::scene::lights::Spot::new(axis.as_vec3(), cutoff, beam)
                .map_err(|m| XmlError::at(&object.spot, m))?;
            if projected.is_some() {
                // The texture is looked up in the light's own frame (to_world's inverse).
                spot.projection = Some(SpotProjection {
                    to_local: linear.inverse().as_mat3(),
                    uv_factor: cutoff.to_radians().tan() as f32,
                    texture: u32::MAX,
                });
            }
            Some(spot)
        } else {
            None
        };
        let intensity = params
            .light_color("intensity", Role::Emission)?
            .map_or(Vec3::ONE, |(c, _)| c);
        params.finish()?;
        self.point_lights += 1;
        Ok((
            PointLight {
                position,
                intensity,
                profile: spot.map_or(PointProfile::Uniform, PointProfile::Spot),
                order: self.point_lights,
            },
            projected.map(ProjectedTexture),
        ))
    }

    /// A `projector`: a pinhole at to_world's origin looking along its +z that casts its
    /// `irradiance` (a texture, or a colour: a one-texel image) onto the plane z = 1 through
    /// the frustum a perspective camera of the image's aspect would see (`fov`, `fov_axis`,
    /// `focal_length` as the sensor reads them), times `scale`. to_world must be rigid: Mitsuba
    /// scales the light with a scaled to_world in a way no other light follows.
    fn projector_emitter(
        &mut self,
        id: usize,
    ) -> Result<(PointLight, Option<ProjectedTexture>), XmlError> {
        let object = self.object(id);
        let mut params = Params::new(object);
        let mut image = None;
        for c in &object.children {
            let child = self.object(c.object);
            if child.class != Class::Texture
                || c.name.as_deref() != Some("irradiance")
                || image.is_some()
            {
                return Err(XmlError::at(
                    &c.spot,
                    "projector: only its irradiance texture (named \"irradiance\") may be nested",
                ));
            }
            image = Some(self.texture(c.object)?);
        }
        let object = self.object(id);
        let constant = params.light_color("irradiance", Role::Unbounded)?;
        let (texture, colour) = match (image, constant) {
            (Some(_), Some((_, spot))) => {
                return Err(XmlError::at(
                    &spot,
                    "projector: irradiance given twice (a texture and a value)",
                ));
            }
            (Some(t), None) => (Some(t), Vec3::ONE),
            (None, Some((c, _))) => {
                // One colour: Mitsuba's constant texture, of resolution 1 x 1, in the
                // intensity (and so in the power that light selection counts).
                (None, c)
            }
            (None, None) => {
                return Err(XmlError::at(
                    &object.spot,
                    "projector needs an irradiance (a texture or a colour)",
                ));
            }
        };
        let scale = params.light_scale()?;
        let (width, height) = texture.as_ref().map_or((1, 1), Texture::resolution);
        let aspect = width as f64 / height as f64;
        let fov_y = perspective_fov_y(object, &mut params, aspect)?;
        let (matrix, spot) = params
            .transform("to_world")?
            .unwrap_or((DMat4::IDENTITY, object.spot.clone()));
        let linear = glam::DMat3::from_mat4(matrix);
        let rigid = (linear.transpose() * linear - glam::DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .all(|d| d.abs() < 1e-6)
            && linear.determinant() > 0.0;
        if !rigid {
            return Err(XmlError::at(
                &spot,
                "projector: to_world must be a rotation and translation (no scale, shear or \
                 mirror)",
            ));
        }
        params.finish()?;
        let tan_y = (0.5 * fov_y.to_radians()).tan();
        let projector = Projector {
            to_local: linear.transpose().as_mat3(),
            to_world: linear.as_mat3(),
            tan_x: (tan_y * aspect) as f32,
            tan_y: tan_y as f32,
            texture: NO_TEXTURE,
        };
        self.point_lights += 1;
        Ok((
            PointLight {
                position: matrix.w_axis.truncate(),
                intensity: colour * (std::f64::consts::PI * scale) as f32,
                profile: PointProfile::Projector(projector),
                order: self.point_lights,
            },
            texture.map(ProjectedTexture),
        ))
    }

    /// A `directional` light: `irradiance` (1 by default) travelling along `direction` or
    /// `to_world`'s +z (one or the other, as Mitsuba).
    fn directional_emitter(&mut self, id: usize) -> Result<DirectionalLight, XmlError> {
        let object = self.object(id);
        let mut params = Params::new(object);
        if let Some(c) = object.children.first() {
            return Err(XmlError::at(
                &c.spot,
                "directional: a nested texture is not supported (give its irradiance as rgb or spectrum)",
            ));
        }
        let direction = params.vector("direction")?;
        let to_world = params.transform("to_world")?;
        let (direction, spot) = match (direction, to_world) {
            (Some(_), Some((_, spot))) => {
                return Err(XmlError::at(
                    &spot,
                    "directional: give either direction or to_world, not both (as Mitsuba)",
                ));
            }
            (Some((d, spot)), None) => (d, spot),
            (None, Some((m, spot))) => (m.z_axis.truncate(), spot),
            (None, None) => (DVec3::Z, object.spot.clone()),
        };
        if !(direction.length() > 0.0 && direction.is_finite()) {
            return Err(XmlError::at(
                &spot,
                "directional: the direction is zero or not finite",
            ));
        }
        let irradiance = params
            .light_color("irradiance", Role::Emission)?
            .map_or(Vec3::ONE, |(c, _)| c);
        params.finish()?;
        self.directional_lights += 1;
        Ok(DirectionalLight {
            direction: direction.normalize(),
            irradiance,
            order: self.directional_lights,
        })
    }

    /// A light at infinity: `constant` (radiance, 1 by default) or `envmap` (an
    /// equirectangular image file, times `scale`, turned by `to_world`).
    fn environment_emitter(&mut self, id: usize) -> Result<EnvironmentLight, XmlError> {
        use crate::scene::environment::{Environment, EnvironmentMap, EnvironmentRadiance};
        let object = self.object(id);
        let kind = object.kind.as_str();
        let mut params = Params::new(object);
        if let Some(c) = object.children.first() {
            return Err(XmlError::at(
                &c.spot,
                format!(
                    "{kind}: a nested texture is not supported (give its radiance as rgb or spectrum)"
                ),
            ));
        }
        let to_world = match params.transform("to_world")? {
            None => glam::DMat3::IDENTITY,
            Some((m, spot)) => {
                let linear = glam::DMat3::from_mat4(m);
                let gram = linear.transpose() * linear;
                let off = (gram - glam::DMat3::IDENTITY)
                    .to_cols_array()
                    .iter()
                    .fold(0.0f64, |a, v| a.max(v.abs()));
                if off.is_nan() || off >= 1e-4 {
                    return Err(XmlError::at(
                        &spot,
                        format!(
                            "{kind}: to_world must only rotate or mirror the map (no scale or \
                             shear): its directions would not stay unit"
                        ),
                    ));
                }
                linear
            }
        };
        let radiance = if kind == "constant" {
            let radiance = params
                .light_color("radiance", Role::Emission)?
                .map_or(Vec3::ONE, |(c, _)| c);
            EnvironmentRadiance::Constant(radiance)
        } else {
            params.ignore(&["mis_compensation"]);
            let (name, spot) = params
                .string("filename")?
                .ok_or_else(|| XmlError::at(&object.spot, "envmap needs a filename"))?;
            let path = self.doc.resolve(name);
            let scale = params.light_scale()? as f32;
            let (width, height, texels) =
                read_image(&path, false).map_err(|m| XmlError::at(&spot, m))?;
            let texels = texels.into_iter().map(|t| t * scale).collect();
            let map = EnvironmentMap::new(width, height, texels)
                .map_err(|m| XmlError::at(&spot, format!("{}: {m}", path.display())))?;
            EnvironmentRadiance::Map(std::sync::Arc::new(map))
        };
        params.finish()?;
        let to_world = to_world.as_mat3();
        Ok(EnvironmentLight(Environment {
            radiance,
            to_world,
            to_local: to_world.transpose(),
        }))
    }

    /// Meshes a shape (a shapegroup's members through an instance) into `out`.
    fn shape(&mut self, id: usize, outer: DAffine3, out: &mut Vec<Placed>) -> Result<(), XmlError> {
        let object = self.object(id);
        let mut params = Params::new(object);
        let to_world = match params.transform("to_world")? {
            None => DAffine3::IDENTITY,
            Some((m, spot)) => super::document::affine(&m).ok_or_else(|| {
                XmlError::at(
                    &spot,
                    "a shape's to_world must be affine (last row 0 0 0 1)",
                )
            })?,
        };
        let to_world = outer * to_world;
        match object.kind.as_str() {
            "shapegroup" => {
                if object.id.is_none() {
                    return Err(XmlError::at(
                        &object.spot,
                        "a shapegroup needs an id for instances to ref",
                    ));
                }
                // Declared only: instances place its members.
                params.finish()?;
                return Ok(());
            }
            "instance" => {
                params.finish()?;
                let groups: Vec<&Child> = object.children.iter().collect();
                let [group] = groups[..] else {
                    return Err(XmlError::at(
                        &object.spot,
                        "an instance refs exactly one shapegroup",
                    ));
                };
                let inner = self.object(group.object);
                if inner.class != Class::Shape || inner.kind != "shapegroup" {
                    return Err(XmlError::at(&group.spot, "an instance refs a shapegroup"));
                }
                let mut members = Vec::new();
                for child in &inner.children {
                    let member = self.object(child.object);
                    if member.class != Class::Shape
                        || matches!(member.kind.as_str(), "shapegroup" | "instance")
                    {
                        return Err(XmlError::at(
                            &child.spot,
                            "a shapegroup holds shapes (not groups or instances)",
                        ));
                    }
                    self.shape(child.object, to_world, &mut members)?;
                }
                out.extend(members);
                return Ok(());
            }
            _ => {}
        }
        let flip_normals = params.boolean("flip_normals")?.unwrap_or(false);
        let mesh = match object.kind.as_str() {
            "obj" | "ply" | "serialized" => self.mesh_file(object, &mut params)?,
            "rectangle" => super::analytic::rectangle(),
            "disk" => super::analytic::disk(),
            "cube" => super::analytic::cube(),
            "sphere" | "cylinder" => {
                let radius = params.float("radius")?.map_or(1.0, |(r, _)| r);
                let point = |params: &mut Params, name: &str, default: DVec3| {
                    params.point(name).map(|p| p.unwrap_or(default))
                };
                let round = |check: Result<(), String>| {
                    check.map_err(|m| XmlError::at(&object.spot, format!("{}: {m}", object.kind)))
                };
                if object.kind == "sphere" {
                    round(check_similarity(&to_world))?;
                    let center = point(&mut params, "center", DVec3::ZERO)?;
                    super::analytic::sphere(center, radius)
                } else {
                    let p0 = point(&mut params, "p0", DVec3::ZERO)?;
                    let p1 = point(&mut params, "p1", DVec3::Z)?;
                    round(check_round_cylinder(&to_world, p1 - p0))?;
                    super::analytic::cylinder(p0, p1, radius)
                }
                .map_err(|m| XmlError::at(&object.spot, m))?
            }
            _ => return Err(unsupported(object, SHAPES)),
        };
        self.check_memory(Some(mesh.triangles.len() as u64), &object.spot)?;
        let mut material = None;
        let mut emission = None;
        for child in &object.children {
            let inner = self.object(child.object);
            match inner.class {
                Class::Bsdf => {
                    if material.replace(child.object).is_some() {
                        return Err(XmlError::at(&child.spot, "a shape has one bsdf"));
                    }
                }
                Class::Emitter => {
                    if inner.kind != "area" {
                        return Err(XmlError::at(
                            &child.spot,
                            format!(
                                "a shape's emitter is an area emitter, not \"{}\"",
                                super::super::echo(&inner.kind)
                            ),
                        ));
                    }
                    if emission.replace(self.area_emitter(child.object)?).is_some() {
                        return Err(XmlError::at(&child.spot, "a shape has one emitter"));
                    }
                }
                other => {
                    return Err(XmlError::at(
                        &child.spot,
                        format!(
                            "a shape holds a bsdf and an emitter, not a <{}>",
                            other.tag()
                        ),
                    ));
                }
            }
        }
        params.finish()?;
        let material = match material {
            Some(m) => m,
            None => usize::MAX,
        };
        out.push(Placed {
            mesh,
            to_world,
            flip_normals,
            material,
            emission,
            spot: object.spot.clone(),
        });
        Ok(())
    }

    /// A mesh read from a file (obj, ply, serialized), with its vertex normals as Mitsuba
    /// makes them: the file's, none with `face_normals`, angle-weighted ones where the file has
    /// none.
    fn mesh_file(&mut self, object: &Object, params: &mut Params) -> Result<Mesh, XmlError> {
        let (name, spot) = params.string("filename")?.ok_or_else(|| {
            XmlError::at(
                &object.spot,
                format!("shape {} needs a filename", object.kind),
            )
        })?;
        let face_normals = params.boolean("face_normals")?.unwrap_or(false);
        let path = self.doc.resolve(name);
        let file = match object.kind.as_str() {
            "obj" => crate::scene::obj::load_obj(&path),
            "ply" => crate::scene::ply::load_ply(&path),
            _ => {
                let index = match params.integer("shape_index")? {
                    None => 0,
                    Some((i, s)) => u32::try_from(i).map_err(|_| {
                        XmlError::at(&s, format!("shape_index {i} must be 0 or more"))
                    })?,
                };
                super::serialized::load_serialized(&path, index)
            }
        }
        .map_err(|m| XmlError::at(&spot, m))?;
        self.warnings.extend(file.warnings);
        let mut mesh = file.mesh;
        // Mitsuba flips an OBJ's v by default (OBJ's v points up an image, Mitsuba's down).
        if object.kind == "obj" && params.boolean("flip_tex_coords")?.unwrap_or(true) {
            mesh.flip_tex_coords();
        }
        if face_normals {
            mesh.normals = None;
        } else if mesh.normals.is_none() {
            mesh.normals = Some(smooth_vertex_normals(&mesh));
        }
        Ok(mesh)
    }

    fn check_memory(&mut self, triangles: Option<u64>, spot: &Spot) -> Result<(), XmlError> {
        let Some(count) = triangles else {
            return Ok(());
        };
        let total = self.triangles_so_far.saturating_add(count);
        if let Some(limits) = &self.limits {
            crate::sysinfo::check_memory(
                &format!("the scene's {total} triangles"),
                total.saturating_mul(crate::scene::BYTES_PER_TRIANGLE),
                limits.memory,
            )
            .map_err(|m| XmlError::at(spot, m))?;
        }
        self.triangles_so_far = total;
        Ok(())
    }

    fn spawn(&mut self, placed: Placed) -> Result<(), XmlError> {
        let material = if placed.material != usize::MAX {
            self.material(placed.material)?
        } else if placed.emission.is_some() {
            // Mitsuba's default BSDF of an emitting shape: a black diffuse (the light
            // reflects nothing; black is black from both sides).
            match self.default_material {
                Some(e) => e,
                None => {
                    let e = self.world.spawn((
                        MaterialInfo {
                            name: "the default BSDF of emitters (black)".into(),
                            order: 0,
                        },
                        Material::Diffuse(Diffuse {
                            reflectance: Vec3::ZERO,
                        }),
                    ));
                    self.default_material = Some(e);
                    e
                }
            }
        } else {
            // Mitsuba's default BSDF: a one-sided diffuse of reflectance 0.5.
            match self.default_diffuse {
                Some(e) => e,
                None => {
                    let e = self.world.spawn((
                        MaterialInfo {
                            name: "the default BSDF (one-sided diffuse 0.5)".into(),
                            order: 0,
                        },
                        Material::Diffuse(Diffuse {
                            reflectance: Vec3::splat(0.5),
                        }),
                        OneSided,
                    ));
                    self.default_diffuse = Some(e);
                    e
                }
            }
        };
        let mut entity = EntityBuilder::new();
        entity.add_bundle((
            ObjectInfo {
                order: self.objects,
                name: None,
            },
            source_spot(&placed.spot),
            DeclaredIn(placed.spot.file.to_path_buf()),
            Shape(placed.mesh),
            Transform(placed.to_world),
            MaterialRef(material),
        ));
        if let Some(radiance) = placed.emission {
            entity.add(Emission(radiance));
        }
        if placed.flip_normals {
            entity.add(FlipNormals);
        }
        self.world.spawn(entity.build());
        self.objects += 1;
        Ok(())
    }
}

/// Fails unless `m` is a rotation (or mirror) with one scale and a translation: Mitsuba's sphere
/// and cylinder keep their round cross-section under any to_world, a mesh would not.
fn check_similarity(m: &DAffine3) -> Result<(), String> {
    let c = [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis];
    let lengths = c.map(|v| v.length());
    let scale = lengths[0];
    let tolerance = 1e-6 * scale;
    let uniform = lengths.iter().all(|l| (l - scale).abs() <= tolerance);
    let orthogonal = (c[0].dot(c[1]).abs() + c[1].dot(c[2]).abs() + c[0].dot(c[2]).abs())
        <= 1e-6 * scale * scale;
    if uniform && orthogonal {
        Ok(())
    } else {
        Err(
            "a to_world with non-uniform scale or shear is not supported (Mitsuba keeps the \
             shape round; a mesh would not be)"
                .into(),
        )
    }
}

/// Fails unless `m` keeps a cylinder along `axis` round: across the axis a rotation (or
/// mirror) with one scale, along it any scale (its length), no shear between the two; Mitsuba
/// reads a cylinder's radius and length from such a to_world (a scale of (r, r, l)).
fn check_round_cylinder(m: &DAffine3, axis: DVec3) -> Result<(), String> {
    let refused = || {
        "a to_world that scales or shears across the axis unevenly is not supported (Mitsuba \
         keeps the cylinder round; a mesh would not be)"
            .to_string()
    };
    let axis = axis.try_normalize().ok_or_else(refused)?;
    let across = crate::math::Frame::from_normal(axis.as_vec3());
    let (a, b) = (across.s.as_dvec3(), across.t.as_dvec3());
    let (ma, mb, md) = (m.matrix3 * a, m.matrix3 * b, m.matrix3 * axis);
    let scale = ma.length();
    let tolerance = 1e-6 * scale * scale.max(md.length());
    let round = (mb.length() - scale).abs() <= 1e-6 * scale
        && ma.dot(mb).abs() <= tolerance
        && ma.dot(md).abs() <= tolerance
        && mb.dot(md).abs() <= tolerance;
    if round { Ok(()) } else { Err(refused()) }
}

/// A perspective sensor's vertical field of view (degrees) on a film of this aspect: from
/// `fov` along `fov_axis`, or from `focal_length` (50 mm by default) across the diagonal;
/// principal point offsets other than 0 are refused.
fn perspective_fov_y(object: &Object, params: &mut Params, aspect: f64) -> Result<f64, XmlError> {
    let fov = params.float("fov")?;
    let focal = params.string("focal_length")?;
    let axis = params.string("fov_axis")?;
    let fov_y = match (fov, focal) {
        (Some(_), Some((_, spot))) => {
            return Err(XmlError::at(
                &spot,
                "perspective: give fov or focal_length, not both",
            ));
        }
        (Some((fov, spot)), None) => {
            if !(fov > 0.0 && fov < 180.0) {
                return Err(XmlError::at(
                    &spot,
                    format!("fov {fov} must lie in (0, 180) degrees"),
                ));
            }
            let (axis, axis_spot) = axis.unwrap_or(("x", spot));
            fov_y_degrees(fov, axis, aspect).map_err(|m| XmlError::at(&axis_spot, m))?
        }
        (None, focal) => {
            if let Some((_, spot)) = axis {
                return Err(XmlError::at(
                    &spot,
                    "fov_axis applies to fov, not to focal_length",
                ));
            }
            let (text, spot) = focal.unwrap_or(("50mm", object.spot.clone()));
            let mm = text
                .strip_suffix("mm")
                .unwrap_or(text)
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v > 0.0)
                .ok_or_else(|| {
                    XmlError::at(
                        &spot,
                        format!(
                            "focal_length \"{}\" is not of the form <x>mm",
                            super::super::echo(text)
                        ),
                    )
                })?;
            // A 35 mm film's diagonal over twice the focal length.
            let diagonal_fov = 2.0
                * ((36.0f64 * 36.0 + 24.0 * 24.0).sqrt() / (2.0 * mm))
                    .atan()
                    .to_degrees();
            fov_y_degrees(diagonal_fov, "diagonal", aspect).map_err(|m| XmlError::at(&spot, m))?
        }
    };
    for name in ["principal_point_offset_x", "principal_point_offset_y"] {
        if let Some((v, spot)) = params.float(name)?
            && v != 0.0
        {
            return Err(XmlError::at(
                &spot,
                format!(
                    "perspective: {name} {v} is not supported (only 0: the image centred on the view)"
                ),
            ));
        }
    }
    Ok(fov_y)
}

/// Near and far clipping distances a perspective sensor gives (checked against the scene once
/// its triangles are placed: see `check_clip_planes`).
#[derive(Clone, Debug)]
pub struct ClipPlanes {
    pub near: Option<(f64, Spot)>,
    pub far: Option<(f64, Spot)>,
}

/// Fails where the sensor's near or far clipping plane would hide part of a triangle in view:
/// stagelight's camera rays are not clipped, so such a file would render a different image.
/// Each triangle is clipped (in camera space) to the part of the view frustum before the near
/// plane, then to the part beyond the far plane; any area left is an error.
fn check_clip_planes(world: &World) -> Result<(), XmlError> {
    let mut cameras = world.query::<(&Camera, &ClipPlanes)>();
    let Some((camera, clip)) = cameras.iter().next() else {
        return Ok(());
    };
    if clip.near.is_none() && clip.far.is_none() {
        return Ok(());
    }
    let tan_y = (0.5 * (camera.fov_y_degrees as f64).to_radians()).tan();
    let tan_x = tan_y * camera.crop.film_width as f64 / camera.crop.film_height as f64;
    let (o, r, u, f) = (
        camera.position.as_dvec3(),
        camera.right.as_dvec3(),
        camera.up.as_dvec3(),
        camera.forward.as_dvec3(),
    );
    let mut objects = world.query::<(&Shape, &Transform)>();
    for (shape, transform) in objects.iter() {
        let local: Vec<DVec3> = shape
            .0
            .positions
            .iter()
            .map(|&p| {
                let d = transform.0.transform_point3(p) - o;
                DVec3::new(d.dot(r), d.dot(u), d.dot(f))
            })
            .collect();
        for tri in &shape.0.triangles {
            let corners = tri.map(|i| local[i as usize]);
            // Frustum sides: x <= z tan_x, -x <= z tan_x, y <= z tan_y, -y <= z tan_y, z >= 0,
            // each as a plane a.p <= b; an orthographic camera's box: |x| <= half width,
            // |y| <= half height, z >= near.
            let sides = match camera.projection {
                Projection::Perspective => [
                    (DVec3::new(1.0, 0.0, -tan_x), 0.0),
                    (DVec3::new(-1.0, 0.0, -tan_x), 0.0),
                    (DVec3::new(0.0, 1.0, -tan_y), 0.0),
                    (DVec3::new(0.0, -1.0, -tan_y), 0.0),
                    (DVec3::new(0.0, 0.0, -1.0), 0.0),
                ],
                Projection::Orthographic {
                    half_width,
                    half_height,
                    near,
                } => [
                    (DVec3::X, half_width as f64),
                    (-DVec3::X, half_width as f64),
                    (DVec3::Y, half_height as f64),
                    (-DVec3::Y, half_height as f64),
                    (-DVec3::Z, -near as f64),
                ],
            };
            if let Some((near, spot)) = &clip.near {
                let mut planes = sides.to_vec();
                planes.push((DVec3::Z, *near));
                if clipped_area(&corners, &planes) > 0.0 {
                    return Err(XmlError::at(
                        spot,
                        format!(
                            "near_clip {near} hides part of the scene in view: camera rays are not clipped in stagelight (lower near_clip below the nearest visible surface)"
                        ),
                    ));
                }
            }
            if let Some((far, spot)) = &clip.far {
                let mut planes = sides.to_vec();
                planes.push((-DVec3::Z, -*far));
                if clipped_area(&corners, &planes) > 0.0 {
                    return Err(XmlError::at(
                        spot,
                        format!(
                            "far_clip {far} hides part of the scene in view: camera rays are not clipped in stagelight (raise far_clip beyond the farthest surface)"
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The area of a triangle's part inside every half-space a.p <= b (Sutherland-Hodgman).
fn clipped_area(triangle: &[DVec3; 3], planes: &[(DVec3, f64)]) -> f64 {
    let mut polygon: Vec<DVec3> = triangle.to_vec();
    for &(a, b) in planes {
        let mut next = Vec::with_capacity(polygon.len() + 1);
        for i in 0..polygon.len() {
            let (p, q) = (polygon[i], polygon[(i + 1) % polygon.len()]);
            let (dp, dq) = (a.dot(p) - b, a.dot(q) - b);
            if dp <= 0.0 {
                next.push(p);
            }
            if (dp < 0.0 && dq > 0.0) || (dp > 0.0 && dq < 0.0) {
                next.push(p + (q - p) * (dp / (dp - dq)));
            }
        }
        polygon = next;
        if polygon.len() < 3 {
            return 0.0;
        }
    }
    let mut doubled = DVec3::ZERO;
    for i in 1..polygon.len() - 1 {
        doubled += (polygon[i] - polygon[0]).cross(polygon[i + 1] - polygon[0]);
    }
    0.5 * doubled.length()
}

fn unsupported(object: &Object, supported: &str) -> XmlError {
    XmlError::at(
        &object.spot,
        format!(
            "{} type \"{}\" is not supported (supported: {supported})",
            object.class.tag(),
            super::super::echo(&object.kind)
        ),
    )
}

fn source_spot(spot: &Spot) -> SourceSpot {
    SourceSpot {
        line: spot.line as usize,
        column: spot.column as usize,
    }
}

/// A conductor's complex index of refraction as Mitsuba 3 reads it (conductor.cpp,
/// roughconductor.cpp): `material` names one of its measured presets (resources/data/ior), or
/// is "none" (the default: eta 0 and k 1, a Fresnel factor of exactly 1), in which case `eta`
/// and `k` may be given (floats, rgb or spectra, unbounded); a preset with `eta` or `k` is an
/// error, as in Mitsuba.
fn conductor_ior(params: &mut Params, object: &Object) -> Result<ComplexIor, XmlError> {
    let material = params.string("material")?;
    let eta = params.color("eta", Role::Unbounded)?;
    let k = params.color("k", Role::Unbounded)?;
    let plugin = super::super::echo(&object.kind);
    if let Some((name, spot)) = material.filter(|(name, _)| *name != "none") {
        if let Some((_, given)) = eta.as_ref().or(k.as_ref()) {
            return Err(XmlError::at(
                given,
                format!(
                    "{plugin}: give either eta and k or material \"{}\", not both",
                    super::super::echo(name)
                ),
            ));
        }
        let (eta, k) = super::spectrum::conductor_eta_k(name).ok_or_else(|| {
            XmlError::at(
                &spot,
                format!(
                    "{plugin} material \"{}\" is not one of Mitsuba's (known: none, {})",
                    super::super::echo(name),
                    super::spectrum::CONDUCTOR_NAMES.join(", ")
                ),
            )
        })?;
        return Ok(ComplexIor { eta, k });
    }
    let mut ior = ComplexIor::PERFECT_MIRROR;
    for (given, value, name) in [(eta, &mut ior.eta, "eta"), (k, &mut ior.k, "k")] {
        let Some((v, spot)) = given else { continue };
        // A generous bound (measured metals lie below 100) that keeps the Fresnel formula's
        // fourth powers far inside f32's range.
        if !(v.cmpge(Vec3::ZERO).all() && v.cmple(Vec3::splat(1e4)).all()) {
            return Err(XmlError::at(
                &spot,
                format!(
                    "{plugin}: {name} ({}, {}, {}) must lie in [0, 1e4] in every channel",
                    v.x, v.y, v.z
                ),
            ));
        }
        *value = v;
    }
    Ok(ior)
}

/// A roughconductor's `distribution`: beckmann (Mitsuba's default) or ggx, in any case, as
/// Mitsuba lowercases the name.
fn microfacet(params: &mut Params, bsdf: &str) -> Result<Microfacet, XmlError> {
    let Some((name, spot)) = params.string("distribution")? else {
        return Ok(Microfacet::Beckmann);
    };
    match name.to_lowercase().as_str() {
        "beckmann" => Ok(Microfacet::Beckmann),
        "ggx" => Ok(Microfacet::Ggx),
        _ => Err(XmlError::at(
            &spot,
            format!(
                "{bsdf} distribution \"{}\" is not supported (supported: beckmann, ggx)",
                super::super::echo(name)
            ),
        )),
    }
}

/// A roughconductor's or roughdielectric's roughness (alpha_u, alpha_v): `alpha` (default 0.1, as Mitsuba's) for
/// both, or `alpha_u` and `alpha_v` apart (anisotropic: alpha_u along the uv tangent), each a
/// value or a texture (`textured` names those given as textures; their values here are
/// placeholders that the textures replace at every shading point).
fn roughness(
    params: &mut Params,
    object: &Object,
    textured: &[(&str, ObjectId)],
) -> Result<(f32, f32), XmlError> {
    let mut read = |name: &str| -> Result<Option<(f64, Spot)>, XmlError> {
        let value = params.float(name)?;
        match textured.iter().find(|t| t.0 == name) {
            Some(&(_, id)) => {
                let spot = object
                    .children
                    .iter()
                    .find(|c| c.object == id)
                    .map_or_else(|| object.spot.clone(), |c| c.spot.clone());
                if value.is_some() {
                    return Err(XmlError::at(
                        &spot,
                        format!("{}: {name} is given twice", object.kind),
                    ));
                }
                Ok(Some((0.1, spot)))
            }
            None => Ok(value),
        }
    };
    let alpha = read("alpha")?;
    let alpha_u = read("alpha_u")?;
    let alpha_v = read("alpha_v")?;
    let (u, v) = match (alpha, alpha_u, alpha_v) {
        (alpha, None, None) => {
            let a = alpha.unwrap_or((0.1, object.spot.clone()));
            (a.clone(), a)
        }
        (Some(_), Some((_, spot)), _) | (Some(_), None, Some((_, spot))) => {
            return Err(XmlError::at(
                &spot,
                format!(
                    "{}: give either alpha or alpha_u and alpha_v, not both",
                    object.kind
                ),
            ));
        }
        (None, Some((_, spot)), None) | (None, None, Some((_, spot))) => {
            return Err(XmlError::at(
                &spot,
                format!(
                    "{}: alpha_u and alpha_v must be given together",
                    object.kind
                ),
            ));
        }
        (None, Some(u), Some(v)) => (u, v),
    };
    for (alpha, spot) in [&u, &v] {
        if !(*alpha > 0.0 && *alpha <= 1e4) {
            return Err(XmlError::at(
                spot,
                format!("alpha {alpha} must lie in (0, 1e4]"),
            ));
        }
    }
    Ok((u.0 as f32, v.0 as f32))
}

/// An index of refraction: a number or one of Mitsuba's named materials.
fn ior(params: &mut Params, name: &str, default: f64) -> Result<f64, XmlError> {
    let Some(p) = params.take(name) else {
        return Ok(default);
    };
    let value = match &p.value {
        Value::Float(v) => *v,
        Value::Integer(v) => *v as f64,
        Value::String(s) => super::spectrum::named_ior(s).ok_or_else(|| {
            XmlError::at(
                &p.spot,
                format!(
                    "{name} \"{}\" is not a known material (known: {})",
                    super::super::echo(s),
                    super::spectrum::IOR_NAMES.join(", ")
                ),
            )
        })?,
        _ => return Err(params.wrong_type(p, "float or material name")),
    };
    if !(value.is_finite() && value >= 1.0) {
        return Err(XmlError::at(
            &p.spot,
            format!("{name} {value} must be a finite number of at least 1"),
        ));
    }
    Ok(value)
}

/// Mitsuba's max_depth counts a path's segments (1: emitters seen directly, 2: direct light);
/// stagelight's `--max-depth` counts bounces, so it is one less.
pub fn mitsuba_depth_to_bounces(depth: i64) -> Result<u32, String> {
    match depth {
        d if d >= 1 && d <= u32::MAX as i64 => Ok((d - 1) as u32),
        0 => Err("max_depth 0 renders a black image: not supported (use -1 for unlimited, 1 for emitters seen directly)".into()),
        d => Err(format!("max_depth {d} must be -1 (unlimited) or at least 1")),
    }
}

/// The vertical field of view of Mitsuba's `fov` along `axis` on a film of this aspect (width
/// over height). Along y it is `fov` itself, unrounded.
pub fn fov_y_degrees(fov: f64, axis: &str, aspect: f64) -> Result<f64, String> {
    let full = |tan_half: f64| 2.0 * tan_half.atan().to_degrees();
    let tan = (0.5 * fov.to_radians()).tan();
    let axis = match axis {
        "smaller" if aspect > 1.0 => "y",
        "smaller" => "x",
        "larger" if aspect > 1.0 => "x",
        "larger" => "y",
        other => other,
    };
    Ok(match axis {
        "x" => full(tan / aspect),
        "y" => fov,
        // The diagonal is sqrt(1 + aspect^2) heights long.
        "diagonal" => full(tan / (1.0 + aspect * aspect).sqrt()),
        other => {
            return Err(format!(
                "fov_axis \"{}\" is not one of x, y, diagonal, smaller, larger",
                super::super::echo(other)
            ));
        }
    })
}

/// What a sensor projects through.
#[derive(Clone, Copy, Debug)]
enum Lens {
    Pinhole {
        fov_y: f64,
    },
    /// Mitsuba's orthographic sensor, its rays starting `near` (camera units) along its +z.
    Orthographic {
        near: f64,
    },
}

/// The camera of a sensor's to_world on a `film_width` x `film_height` film (the whole film,
/// no filter: the caller sets those): Mitsuba's camera looks along its +z with +y up; the
/// image's right is its -x. An orthographic sensor's view is camera x in [-1, 1] and y in
/// [-1/aspect, 1/aspect], so to_world's scale along x sets the view's width.
fn camera_of(m: &DMat4, lens: Lens, film_width: u32, film_height: u32) -> Result<Camera, String> {
    let affine = super::document::affine(m).ok_or("a sensor's to_world must be affine")?;
    let position = affine.transform_point3(DVec3::ZERO);
    let z = affine.transform_vector3(DVec3::Z);
    let forward = z
        .try_normalize()
        .ok_or("the sensor's to_world flattens its view direction")?;
    let (up, right) = (
        affine.transform_vector3(DVec3::Y),
        -affine.transform_vector3(DVec3::X),
    );
    let (half_width, half_height) = (right.length(), up.length());
    // The frame must stay orthogonal: a sensor's to_world is a rotation, translation and
    // possibly a mirror (and, orthographic, a scale); shear would skew the image.
    let (up, right) = (
        up.try_normalize()
            .ok_or("the sensor's to_world flattens its up direction")?,
        right
            .try_normalize()
            .ok_or("the sensor's to_world flattens its side direction")?,
    );
    if forward.dot(up).abs() > 1e-6 || forward.dot(right).abs() > 1e-6 || up.dot(right).abs() > 1e-6
    {
        return Err("the sensor's to_world is not orthogonal (shear or non-uniform scale)".into());
    }
    if position.abs().max_element() >= crate::scene::MAX_COORDINATE {
        return Err("the sensor's position is too far out".into());
    }
    let aspect = film_width as f64 / film_height as f64;
    let (fov_y, projection) = match lens {
        Lens::Pinhole { fov_y } => {
            if !(fov_y > 0.0 && fov_y < 180.0) {
                return Err(format!(
                    "the vertical field of view {fov_y} degrees is out of (0, 180)"
                ));
            }
            (fov_y, Projection::Perspective)
        }
        Lens::Orthographic { near } => {
            let extent = half_width.max(half_height / aspect).max(near * z.length());
            if !(extent.is_finite() && extent < crate::scene::MAX_COORDINATE) {
                return Err("the orthographic sensor's view is too large".into());
            }
            // The field of view of a pinhole is meaningless here; kept at a valid value.
            (
                90.0,
                Projection::Orthographic {
                    half_width: half_width as f32,
                    half_height: (half_height / aspect) as f32,
                    near: (near * z.length()) as f32,
                },
            )
        }
    };
    Ok(Camera {
        position: position.as_vec3(),
        forward: forward.as_vec3(),
        right: right.as_vec3(),
        up: up.as_vec3(),
        fov_y_degrees: fov_y as f32,
        width: film_width,
        height: film_height,
        crop: Crop::whole(film_width, film_height),
        projection,
        filter: PixelFilter::Box,
    })
}

/// Per-vertex normals of a mesh without them, as Mitsuba makes them: each face's unit normal
/// added to its corners weighted by the corner's angle (Thürmer and Wüthrich 1998).
pub fn smooth_vertex_normals(mesh: &Mesh) -> Vec<DVec3> {
    let mut normals = vec![DVec3::ZERO; mesh.positions.len()];
    for tri in &mesh.triangles {
        let p = tri.map(|i| mesh.positions[i as usize]);
        let Some(n) = (p[1] - p[0]).cross(p[2] - p[0]).try_normalize() else {
            continue;
        };
        for k in 0..3 {
            let a = (p[(k + 1) % 3] - p[k]).try_normalize();
            let b = (p[(k + 2) % 3] - p[k]).try_normalize();
            if let (Some(a), Some(b)) = (a, b) {
                normals[tri[k] as usize] += n * a.dot(b).clamp(-1.0, 1.0).acos();
            }
        }
    }
    // A vertex no face reaches keeps a zero normal: its triangles are shaded flat.
    normals
        .iter()
        .map(|n| n.try_normalize().unwrap_or(DVec3::ZERO))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_depth_counts_segments() {
        assert_eq!(mitsuba_depth_to_bounces(1), Ok(0));
        assert_eq!(mitsuba_depth_to_bounces(2), Ok(1));
        assert_eq!(mitsuba_depth_to_bounces(8), Ok(7));
        assert!(mitsuba_depth_to_bounces(0).is_err());
        assert!(mitsuba_depth_to_bounces(-2).is_err());
    }

    #[test]
    fn fov_axes() {
        // Square film: every axis but the diagonal is the same.
        for axis in ["x", "y", "smaller", "larger"] {
            assert!((fov_y_degrees(40.0, axis, 1.0).unwrap() - 40.0).abs() < 1e-12);
        }
        // 2:1 film, fov 90 along x: tan(y/2) = tan(45) / 2; "larger" is x there.
        let y = 2.0 * 0.5f64.atan().to_degrees();
        for axis in ["x", "larger"] {
            assert!((fov_y_degrees(90.0, axis, 2.0).unwrap() - y).abs() < 1e-12);
        }
        assert_eq!(fov_y_degrees(90.0, "smaller", 2.0).unwrap(), 90.0);
        // Diagonal of a square: tan(y/2) = tan(d/2) / sqrt(2).
        let y = fov_y_degrees(90.0, "diagonal", 1.0).unwrap();
        assert!((y - 2.0 * (1.0 / 2.0f64.sqrt()).atan().to_degrees()).abs() < 1e-12);
        // Mitsuba's default lens, 50 mm on 35 mm film: 46.8 degrees across the diagonal.
        let diagonal = 2.0
            * ((36.0f64 * 36.0 + 24.0 * 24.0).sqrt() / 100.0)
                .atan()
                .to_degrees();
        assert!((diagonal - 46.8).abs() < 0.01, "{diagonal}");
        assert!(fov_y_degrees(40.0, "z", 1.0).is_err());
    }
}
