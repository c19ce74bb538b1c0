//! The RON scene format: the structs `ron` deserialises, with every value checked as it is read
//! so that ron's error carries the position of the offending value.
//!
//! The scene's `camera` and each entry of `objects` are first read as raw RON text and parsed
//! on their own (see `super::parse`): that gives every object a source position, which errors
//! found later (an unknown material name, a missing mesh file, a light of zero area) can name.

use glam::{DVec3, Vec3};
use ron::value::RawValue;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, de::Error as _};
use std::fmt;

/// The whole file. Camera and objects stay raw here: they are parsed one by one afterwards.
#[derive(Deserialize)]
#[serde(rename = "Scene", deny_unknown_fields)]
pub struct SceneFile<'a> {
    #[serde(borrow)]
    pub camera: &'a RawValue,
    #[serde(default)]
    pub materials: MaterialTable,
    #[serde(borrow)]
    pub objects: Vec<&'a RawValue>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(rename = "Camera", deny_unknown_fields)]
pub struct CameraDesc {
    pub position: Point,
    pub look_at: Point,
    #[serde(default = "Point::y_up")]
    pub up: Point,
    /// Full vertical field of view, degrees.
    pub fov: Fov,
    #[serde(default)]
    pub width: ImageSize,
    #[serde(default)]
    pub height: ImageSize,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(rename = "Material", deny_unknown_fields)]
pub enum MaterialDesc {
    Diffuse {
        reflectance: Reflectance,
    },
    Dielectric {
        ior: Ior,
    },
    /// Mitsuba's `thindielectric`: a thin sheet of index `ior` (relative to its surroundings).
    ThinDielectric {
        ior: Ior,
    },
    Conductor {
        alpha: Alpha,
        reflectance: Reflectance,
    },
    /// Mitsuba's `roughplastic` on its defaults but `diffuse` and `alpha` (Beckmann,
    /// polypropylene's index 1.49 unless `ior` says otherwise, specular 1, linear).
    RoughPlastic {
        diffuse: Reflectance,
        alpha: Alpha,
        #[serde(default)]
        ior: Option<Ior>,
    },
    /// Mitsuba's `roughdielectric` on its defaults but `alpha` and `ior` (Beckmann, the index
    /// inside over outside; reflectance and transmittance 1).
    RoughDielectric {
        alpha: Alpha,
        ior: Ior,
    },
    /// Mitsuba's smooth `plastic` on its defaults but `diffuse` (polypropylene's index 1.49
    /// unless `ior` says otherwise, specular 1, linear).
    Plastic {
        diffuse: Reflectance,
        #[serde(default)]
        ior: Option<Ior>,
    },
}

#[derive(Clone, Debug, Deserialize)]
#[serde(rename = "Object", deny_unknown_fields)]
pub struct ObjectDesc {
    /// Optional, only used in messages.
    #[serde(default)]
    pub name: Option<String>,
    pub shape: ShapeDesc,
    pub material: String,
    /// Radiance emitted on the geometric normal's side of every triangle.
    #[serde(default)]
    pub emission: Option<Radiance>,
    /// Applied in order, first to last.
    #[serde(default)]
    pub transform: Vec<TransformDesc>,
    /// Reverses every triangle (and negates vertex normals).
    #[serde(default)]
    pub flip_normals: bool,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(rename = "Shape", deny_unknown_fields)]
pub enum ShapeDesc {
    /// (a, b, c, d): the triangles (a, b, c) and (a, c, d).
    Quad(Point, Point, Point, Point),
    Triangle(Point, Point, Point),
    /// A closed axis-aligned box; `min < max` on every axis (checked when meshing).
    Box {
        min: Point,
        max: Point,
    },
    Icosphere {
        level: IcoLevel,
        #[serde(default)]
        smooth: bool,
    },
    Torus {
        major_radius: Length,
        minor_radius: Length,
        nu: Segments,
        nv: Segments,
    },
    /// A Wavefront OBJ file, relative to the scene file.
    Obj(String),
    /// A Stanford PLY file (ASCII or binary), relative to the scene file.
    Ply(String),
}

#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(rename = "Transform", deny_unknown_fields)]
pub enum TransformDesc {
    Translate(Point),
    Rotate {
        axis: Direction,
        degrees: Finite,
    },
    /// A factor, or per-axis factors `(x, y, z)`; negative factors mirror.
    Scale(ScaleDesc),
}

// ------------------------------------------------------------------------ checked values

/// A finite 3-vector written `(x, y, z)`.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "[f64; 3]")]
pub struct Point(pub DVec3);

impl Point {
    fn y_up() -> Point {
        Point(DVec3::Y)
    }
}

impl TryFrom<[f64; 3]> for Point {
    type Error = String;
    fn try_from(v: [f64; 3]) -> Result<Self, String> {
        if v.iter().all(|c| c.is_finite()) {
            Ok(Point(DVec3::from_array(v)))
        } else {
            Err(format!("{v:?} is not a finite vector"))
        }
    }
}

/// A non-zero finite direction (not necessarily unit).
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "[f64; 3]")]
pub struct Direction(pub DVec3);

impl TryFrom<[f64; 3]> for Direction {
    type Error = String;
    fn try_from(v: [f64; 3]) -> Result<Self, String> {
        let d = Point::try_from(v)?.0;
        if d.length_squared() > 0.0 {
            Ok(Direction(d))
        } else {
            Err("rotation axis must not be zero".to_string())
        }
    }
}

#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "f64")]
pub struct Finite(pub f64);

impl TryFrom<f64> for Finite {
    type Error = String;
    fn try_from(v: f64) -> Result<Self, String> {
        if v.is_finite() {
            Ok(Finite(v))
        } else {
            Err(format!("{v} is not a finite number"))
        }
    }
}

/// Reflectance: every channel in [0, 1] (energy conservation).
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "[f32; 3]")]
pub struct Reflectance(pub Vec3);

impl TryFrom<[f32; 3]> for Reflectance {
    type Error = String;
    fn try_from(v: [f32; 3]) -> Result<Self, String> {
        if v.iter().all(|c| (0.0..=1.0).contains(c)) {
            Ok(Reflectance(Vec3::from_array(v)))
        } else {
            Err(format!(
                "reflectance {v:?} must lie in [0, 1] in every channel"
            ))
        }
    }
}

/// Emitted radiance: finite, non-negative, not all zero, each channel at most
/// `MAX_RADIANCE`.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "[f32; 3]")]
pub struct Radiance(pub Vec3);

/// The largest radiance a channel may have: radiance times throughput (and, for light
/// subpaths, times area) is carried in f32, and overflowed to a black image from about 1e34.
pub const MAX_RADIANCE: f32 = 1e30;

impl TryFrom<[f32; 3]> for Radiance {
    type Error = String;
    fn try_from(v: [f32; 3]) -> Result<Self, String> {
        if !v.iter().all(|c| c.is_finite() && *c >= 0.0) {
            Err(format!(
                "emission radiance {v:?} must be finite and non-negative"
            ))
        } else if v.iter().any(|c| *c > MAX_RADIANCE) {
            Err(format!(
                "emission radiance {v:?} is too large: each channel must stay below \
                 {MAX_RADIANCE:e} (f32 light transport overflows)"
            ))
        } else if v.iter().all(|c| *c == 0.0) {
            Err("emission radiance is zero: leave `emission` out instead".to_string())
        } else {
            Ok(Radiance(Vec3::from_array(v)))
        }
    }
}

#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "f64")]
pub struct Fov(pub f64);

impl TryFrom<f64> for Fov {
    type Error = String;
    fn try_from(v: f64) -> Result<Self, String> {
        if v > 0.0 && v < 180.0 {
            Ok(Fov(v))
        } else {
            Err(format!("fov {v} must lie in (0, 180) degrees"))
        }
    }
}

/// Image width or height in pixels.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "i64")]
pub struct ImageSize(pub u32);

pub const MAX_IMAGE_SIZE: u32 = 16384;

impl Default for ImageSize {
    fn default() -> Self {
        ImageSize(256)
    }
}

impl TryFrom<i64> for ImageSize {
    type Error = String;
    fn try_from(v: i64) -> Result<Self, String> {
        match u32::try_from(v) {
            Ok(v) if (1..=MAX_IMAGE_SIZE).contains(&v) => Ok(ImageSize(v)),
            _ => Err(format!(
                "image size {v} must lie in 1..={MAX_IMAGE_SIZE} pixels"
            )),
        }
    }
}

/// Index of refraction: finite, positive and not 1 (as Mitsuba requires: index 1 is no
/// interface, and a rough one would refract straight through, a delta it cannot sample).
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "f32")]
pub struct Ior(pub f32);

impl TryFrom<f32> for Ior {
    type Error = String;
    fn try_from(v: f32) -> Result<Self, String> {
        if v.is_finite() && v > 0.0 && v != 1.0 {
            Ok(Ior(v))
        } else {
            Err(format!("ior {v} must be finite, positive and not 1"))
        }
    }
}

/// GGX roughness in (0, 1].
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "f32")]
pub struct Alpha(pub f32);

impl TryFrom<f32> for Alpha {
    type Error = String;
    fn try_from(v: f32) -> Result<Self, String> {
        if v > 0.0 && v <= 1.0 {
            Ok(Alpha(v))
        } else {
            Err(format!("GGX alpha {v} must lie in (0, 1]"))
        }
    }
}

/// Icosphere subdivision level: level 8 is already 1.3 million triangles.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "i64")]
pub struct IcoLevel(pub u32);

pub const MAX_ICO_LEVEL: u32 = 8;

impl TryFrom<i64> for IcoLevel {
    type Error = String;
    fn try_from(v: i64) -> Result<Self, String> {
        match u32::try_from(v) {
            Ok(v) if v <= MAX_ICO_LEVEL => Ok(IcoLevel(v)),
            _ => Err(format!(
                "icosphere level {v} must lie in 0..={MAX_ICO_LEVEL}"
            )),
        }
    }
}

/// Torus segment count.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "i64")]
pub struct Segments(pub u32);

pub const MAX_SEGMENTS: u32 = 4096;

impl TryFrom<i64> for Segments {
    type Error = String;
    fn try_from(v: i64) -> Result<Self, String> {
        match u32::try_from(v) {
            Ok(v) if (3..=MAX_SEGMENTS).contains(&v) => Ok(Segments(v)),
            _ => Err(format!(
                "torus segment count {v} must lie in 3..={MAX_SEGMENTS}"
            )),
        }
    }
}

/// A finite positive length.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(try_from = "f64")]
pub struct Length(pub f64);

impl TryFrom<f64> for Length {
    type Error = String;
    fn try_from(v: f64) -> Result<Self, String> {
        if v.is_finite() && v > 0.0 {
            Ok(Length(v))
        } else {
            Err(format!("torus radius {v} must be finite and positive"))
        }
    }
}

/// Scale factors: `Scale(2)` or `Scale((1, 2, 1))`; each finite and non-zero.
#[derive(Clone, Copy, Debug)]
pub struct ScaleDesc(pub DVec3);

impl<'de> Deserialize<'de> for ScaleDesc {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct ScaleVisitor;

        fn checked<E: de::Error>(v: DVec3) -> Result<ScaleDesc, E> {
            if v.is_finite() && v.cmpne(DVec3::ZERO).all() {
                Ok(ScaleDesc(v))
            } else {
                Err(E::custom(format!(
                    "scale {:?} must be finite and non-zero on every axis",
                    v.to_array()
                )))
            }
        }

        impl<'de> Visitor<'de> for ScaleVisitor {
            type Value = ScaleDesc;

            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a scale factor or per-axis factors (x, y, z)")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<ScaleDesc, E> {
                checked(DVec3::splat(v))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<ScaleDesc, E> {
                checked(DVec3::splat(v as f64))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<ScaleDesc, E> {
                checked(DVec3::splat(v as f64))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<ScaleDesc, A::Error> {
                let mut v = [0.0; 3];
                for (i, c) in v.iter_mut().enumerate() {
                    *c = seq
                        .next_element()?
                        .ok_or_else(|| A::Error::invalid_length(i, &self))?;
                }
                if seq.next_element::<f64>()?.is_some() {
                    return Err(A::Error::invalid_length(4, &self));
                }
                checked(DVec3::from_array(v))
            }
        }

        deserializer.deserialize_any(ScaleVisitor)
    }
}

/// The `materials` map, in file order, refusing a name defined twice (a plain map would keep
/// the last silently).
#[derive(Clone, Debug, Default)]
pub struct MaterialTable(pub Vec<(String, MaterialDesc)>);

impl<'de> Deserialize<'de> for MaterialTable {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct TableVisitor;

        impl<'de> Visitor<'de> for TableVisitor {
            type Value = MaterialTable;

            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a map from material names to materials")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<MaterialTable, A::Error> {
                let mut table: Vec<(String, MaterialDesc)> = Vec::new();
                let mut names = std::collections::HashSet::new();
                while let Some(name) = map.next_key::<String>()? {
                    if !names.insert(name.clone()) {
                        return Err(A::Error::custom(format!(
                            "material \"{}\" is defined twice",
                            super::echo(&name)
                        )));
                    }
                    let material = map.next_value()?;
                    table.push((name, material));
                }
                Ok(MaterialTable(table))
            }
        }

        deserializer.deserialize_map(TableVisitor)
    }
}
