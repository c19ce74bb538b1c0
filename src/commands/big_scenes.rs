//! The big scenes of `stagelight bench --big DIR`: the Cornell box of `scenes/cornell_box.ron`
//! holding a smooth icosphere and a dense flat torus, at about 100 thousand, 1 million and 5
//! million triangles (and the bare box, 32 triangles, for scale). They are written, not
//! committed: every object as a binary PLY file, a stagelight scene (`SIZE.ron`, whose objects
//! are those `Ply` files) and a Mitsuba 3 scene (`SIZE.xml`, the same PLY files and the
//! mapping of ../shared/mitsuba/README.md: two-sided diffuse, one-sided area light, `path`
//! with unlimited depth, box filter), so that both renderers trace the same f32 geometry.

use crate::scene::format::{MaterialDesc, ShapeDesc};
use crate::scene::shapes::{self, Mesh};
use anyhow::{Context, Result, bail};
use glam::{DAffine3, DQuat, DVec3};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// One size: its name and the meshes added to the box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BigScene {
    pub name: &'static str,
    /// Icosphere level (20 * 4^level triangles), or None for the bare box.
    pub sphere_level: Option<u32>,
    /// Torus segments (nu, nv): 2 * nu * nv triangles.
    pub torus: Option<(u32, u32)>,
}

impl BigScene {
    pub fn triangles(&self) -> u64 {
        let sphere = self.sphere_level.map_or(0, |l| 20u64 << (2 * l));
        let torus = self.torus.map_or(0, |(nu, nv)| 2 * nu as u64 * nv as u64);
        BOX_TRIANGLES + sphere + torus
    }
}

/// The Cornell box's own triangles.
const BOX_TRIANGLES: u64 = 32;

/// The sizes the bench runs, smallest first.
pub const BIG_SCENES: [BigScene; 4] = [
    BigScene {
        name: "box_32",
        sphere_level: None,
        torus: None,
    },
    // 81,920 + 20,480 + 32 = 102,432 triangles.
    BigScene {
        name: "big_100k",
        sphere_level: Some(6),
        torus: Some((160, 64)),
    },
    // 327,680 + 655,360 + 32 = 983,072.
    BigScene {
        name: "big_1m",
        sphere_level: Some(7),
        torus: Some((1024, 320)),
    },
    // 1,310,720 + 3,686,400 + 32 = 4,997,152.
    BigScene {
        name: "big_5m",
        sphere_level: Some(8),
        torus: Some((2048, 900)),
    },
];

const CORNELL_BOX: &str = include_str!("../../scenes/cornell_box.ron");

/// An object of a big scene, in world space.
struct Object {
    file: String,
    material: String,
    emission: Option<[f32; 3]>,
    mesh: Mesh,
}

/// The objects: the box's (from `scenes/cornell_box.ron`, all quads without transforms),
/// then the sphere on the short block and the torus tilted over the floor's right side.
fn objects(size: &BigScene) -> Result<(crate::scene::ParsedScene, Vec<Object>)> {
    let parsed = crate::scene::parse(Path::new("scenes/cornell_box.ron"), CORNELL_BOX)?;
    let mut objects = Vec::new();
    for (k, object) in parsed.objects.iter().enumerate() {
        let desc = &object.desc;
        let ShapeDesc::Quad(a, b, c, d) = desc.shape else {
            bail!("scenes/cornell_box.ron: the big scenes take only quads from the box");
        };
        if !desc.transform.is_empty() || desc.flip_normals {
            bail!("scenes/cornell_box.ron: the big scenes take quads without transforms");
        }
        objects.push(Object {
            file: format!("box_{k:02}.ply"),
            material: desc.material.clone(),
            emission: desc.emission.map(|e| e.0.to_array()),
            mesh: shapes::quad(a.0, b.0, c.0, d.0),
        });
    }
    if let Some(level) = size.sphere_level {
        let mut mesh = shapes::icosphere(level, true);
        // Radius 90 mm, resting on the short block's top (y = 165).
        let place = DAffine3::from_translation(DVec3::new(186.0, 255.0, 169.0))
            * DAffine3::from_scale(DVec3::splat(90.0));
        for p in &mut mesh.positions {
            *p = place.transform_point3(*p);
        }
        objects.push(Object {
            file: "sphere.ply".into(),
            material: "white".into(),
            emission: None,
            mesh,
        });
    }
    if let Some((nu, nv)) = size.torus {
        let mut mesh = shapes::torus(90.0, 35.0, nu, nv);
        let place = DAffine3::from_translation(DVec3::new(400.0, 90.0, 130.0))
            * DAffine3::from_quat(DQuat::from_rotation_x(30f64.to_radians()));
        for p in &mut mesh.positions {
            *p = place.transform_point3(*p);
        }
        objects.push(Object {
            file: "torus.ply".into(),
            material: "white".into(),
            emission: None,
            mesh,
        });
    }
    Ok((parsed, objects))
}

/// The scene file of a size in `dir`: `dir/NAME/NAME.ron`.
pub fn scene_path(dir: &Path, size: &BigScene) -> PathBuf {
    dir.join(size.name).join(format!("{}.ron", size.name))
}

/// Writes a size's PLY files, its stagelight scene and its Mitsuba scene into
/// `dir/NAME/`, and returns the stagelight scene's path.
pub fn write_big_scene(dir: &Path, size: &BigScene) -> Result<PathBuf> {
    let folder = dir.join(size.name);
    std::fs::create_dir_all(&folder)
        .with_context(|| format!("{}: cannot create the folder", folder.display()))?;
    let (parsed, objects) = objects(size)?;
    let count: u64 = objects.iter().map(|o| o.mesh.triangles.len() as u64).sum();
    debug_assert_eq!(count, size.triangles());
    for object in &objects {
        let path = folder.join(&object.file);
        crate::film::output::write_atomically(&path, |out| {
            crate::scene::ply::write_ply(out, &object.mesh)
                .map_err(|e| format!("cannot write: {e}"))
        })?;
    }
    let camera = &parsed.camera.desc;
    let v = |p: DVec3| format!("({}, {}, {})", p.x, p.y, p.z);
    let c = |p: [f32; 3]| format!("({}, {}, {})", p[0], p[1], p[2]);

    let mut ron = format!(
        "// Written by `stagelight bench --big`: the Cornell box of scenes/cornell_box.ron\n\
         // holding a smooth icosphere and a flat torus, {count} triangles, every object a PLY file.\n\
         Scene(\n    camera: (position: {}, look_at: {}, up: {}, fov: {}, width: {}, height: {}),\n    materials: {{\n",
        v(camera.position.0),
        v(camera.look_at.0),
        v(camera.up.0),
        camera.fov.0,
        camera.width.0,
        camera.height.0
    );
    // rr_depth: Mitsuba's roulette after as many scatterings as stagelight's, so that a sample
    // costs both renderers the same rays.
    let mut xml = format!(
        "<!-- Written by stagelight bench (its big scenes): the same geometry as {name}.ron, for Mitsuba 3 -->\n\
         <scene version=\"3.0.0\">\n\
         \x20   <default name=\"spp\" value=\"32\"/>\n\
         \x20   <integrator type=\"path\"><integer name=\"max_depth\" value=\"-1\"/>\
         <integer name=\"rr_depth\" value=\"{rr_depth}\"/></integrator>\n\
         \x20   <sensor type=\"perspective\">\n\
         \x20       <float name=\"fov\" value=\"{fov}\"/><string name=\"fov_axis\" value=\"y\"/>\n\
         \x20       <transform name=\"to_world\"><lookat origin=\"{o}\" target=\"{t}\" up=\"{u}\"/></transform>\n\
         \x20       <sampler type=\"independent\"><integer name=\"sample_count\" value=\"$spp\"/></sampler>\n\
         \x20       <film type=\"hdrfilm\"><integer name=\"width\" value=\"{w}\"/><integer name=\"height\" value=\"{h}\"/>\n\
         \x20           <string name=\"pixel_format\" value=\"rgb\"/><string name=\"component_format\" value=\"float32\"/>\n\
         \x20           <rfilter type=\"box\"/></film>\n\
         \x20   </sensor>\n",
        name = size.name,
        rr_depth = crate::sampling::roulette::ROULETTE_DEPTH,
        fov = camera.fov.0,
        o = xml_vector(camera.position.0),
        t = xml_vector(camera.look_at.0),
        u = xml_vector(camera.up.0),
        w = camera.width.0,
        h = camera.height.0,
    );
    for (name, material) in &parsed.materials {
        if !objects.iter().any(|o| &o.material == name) {
            continue;
        }
        let (stagelight, mitsuba) = match material {
            MaterialDesc::Diffuse { reflectance } => {
                let r = reflectance.0.to_array();
                (
                    format!("Diffuse(reflectance: {})", c(r)),
                    format!(
                        "<bsdf type=\"twosided\" id=\"{name}\"><bsdf type=\"diffuse\">\
                         <rgb name=\"reflectance\" value=\"{}, {}, {}\"/></bsdf></bsdf>",
                        r[0], r[1], r[2]
                    ),
                )
            }
            _ => bail!("scenes/cornell_box.ron: the big scenes take only diffuse materials"),
        };
        let _ = writeln!(ron, "        \"{name}\": {stagelight},");
        let _ = writeln!(xml, "    {mitsuba}");
    }
    ron += "    },\n    objects: [\n";
    for o in &objects {
        let emission = o
            .emission
            .map_or(String::new(), |e| format!(", emission: Some({})", c(e)));
        let _ = writeln!(
            ron,
            "        (shape: Ply(\"{}\"), material: \"{}\"{emission}),",
            o.file, o.material
        );
        // Mitsuba computes smooth normals for a PLY without them unless told not to.
        let mut shape = format!(
            "    <shape type=\"ply\"><string name=\"filename\" value=\"{}\"/>\
             <boolean name=\"face_normals\" value=\"{}\"/><ref id=\"{}\"/>",
            o.file,
            o.mesh.normals.is_none(),
            o.material
        );
        if let Some(e) = o.emission {
            let _ = write!(
                shape,
                "<emitter type=\"area\"><rgb name=\"radiance\" value=\"{}, {}, {}\"/></emitter>",
                e[0], e[1], e[2]
            );
        }
        shape += "</shape>\n";
        xml += &shape;
    }
    ron += "    ],\n)\n";
    xml += "</scene>\n";
    let scene = scene_path(dir, size);
    crate::film::output::write_bytes(&scene, ron.as_bytes())?;
    crate::film::output::write_bytes(&scene.with_extension("xml"), xml.as_bytes())?;
    Ok(scene)
}

fn xml_vector(p: DVec3) -> String {
    format!("{}, {}, {}", p.x, p.y, p.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_count_their_triangles() {
        let counts: Vec<u64> = BIG_SCENES.iter().map(|s| s.triangles()).collect();
        assert_eq!(counts, vec![32, 102_432, 983_072, 4_997_152]);
    }
}
