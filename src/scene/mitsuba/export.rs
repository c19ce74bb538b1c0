//! A scene world written as a Mitsuba 3 scene file: the XML and one PLY mesh per object, so a
//! RON scene can be rendered by Mitsuba and read back by stagelight as the same triangles.
//!
//! Meshes are written in world space, in double precision, exactly as `prepare` places them
//! (transformed, mirrored or flipped windings resolved, normals transformed and normalised), so
//! reading the file back gives the RON scene's triangles bit for bit. Materials map as
//! SCENES.md's Mitsuba renders do: Diffuse is `twosided(diffuse)`, Dielectric a `dielectric`
//! with ext_ior 1 (ThinDielectric a `thindielectric`), Conductor a `roughconductor` (material "none" for a Fresnel factor of 1, rgb
//! eta and k otherwise); lights are one-sided `area` emitters; the film has the box filter.

use crate::bsdf::Material;
use crate::bsdf::conductor::{ComplexIor, Microfacet};
use crate::bsdf::dielectric::{Dielectric, ThinDielectric};
use crate::bsdf::diffuse::Diffuse;
use crate::scene::Camera;
use crate::scene::world::{
    Emission, FlipNormals, MaterialInfo, MaterialRef, ObjectInfo, SceneWorld, Shape, Transform,
};
use glam::{DVec3, Vec3};
use hecs::Entity;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

/// Writes a RON scene (`parsed`, built into `world`) as `xml_path`, its meshes in
/// `meshes/NAME_K.ply` beside it. The camera is written from the file's own numbers, so the
/// frame stagelight rebuilds from the XML is the RON camera's, bit for bit.
pub fn export(
    parsed: &crate::scene::ParsedScene,
    world: &SceneWorld,
    xml_path: &Path,
) -> Result<(), String> {
    let dir = xml_path.parent().unwrap_or(Path::new(""));
    let stem = xml_path
        .file_stem()
        .and_then(|s| s.to_str())
        .ok_or("the output file needs a name")?;
    let mesh_dir = dir.join("meshes");
    std::fs::create_dir_all(&mesh_dir)
        .map_err(|e| format!("cannot create {}: {e}", mesh_dir.display()))?;
    let w = &world.world;
    let camera = {
        let mut q = w.query::<&Camera>();
        *q.iter().next().ok_or("the scene has no camera")?
    };
    let mut xml = String::new();
    let _ = writeln!(xml, "<scene version=\"3.0.0\">");
    let _ = writeln!(xml, "    <default name=\"spp\" value=\"64\"/>");
    // Mitsuba's roulette starts after `rr_depth` scatterings, as stagelight's after
    // ROULETTE_DEPTH (its default, 5, would give Mitsuba longer paths: more work a sample).
    let _ = writeln!(
        xml,
        "    <integrator type=\"path\">\n        <integer name=\"max_depth\" value=\"-1\"/>\n        \
         <integer name=\"rr_depth\" value=\"{}\"/>\n    </integrator>",
        crate::sampling::roulette::ROULETTE_DEPTH
    );
    let desc = &parsed.camera.desc;
    let point = |v: DVec3| format!("{}, {}, {}", v.x, v.y, v.z);
    let f64s = |v: Vec3| format!("{}, {}, {}", float(v.x), float(v.y), float(v.z));
    let _ = writeln!(
        xml,
        "    <sensor type=\"perspective\">\n        <string name=\"fov_axis\" value=\"y\"/>\n        \
         <float name=\"fov\" value=\"{}\"/>\n        <transform name=\"to_world\">\n            \
         <lookat origin=\"{}\" target=\"{}\" up=\"{}\"/>\n        </transform>\n        \
         <sampler type=\"independent\">\n            <integer name=\"sample_count\" value=\"$spp\"/>\n        \
         </sampler>\n        <film type=\"hdrfilm\">\n            <integer name=\"width\" value=\"{}\"/>\n            \
         <integer name=\"height\" value=\"{}\"/>\n            <rfilter type=\"box\"/>\n            \
         <string name=\"pixel_format\" value=\"rgb\"/>\n        </film>\n    </sensor>",
        desc.fov.0,
        point(desc.position.0),
        point(desc.look_at.0),
        point(desc.up.0),
        camera.width,
        camera.height
    );

    let mut materials: Vec<(Entity, &MaterialInfo, &Material)> = Vec::new();
    let mut mq = w.query::<(Entity, &MaterialInfo, &Material)>();
    materials.extend(mq.iter());
    materials.sort_by_key(|m| m.1.order);
    let mut ids: HashMap<Entity, String> = HashMap::new();
    for (k, (entity, _, material)) in materials.iter().enumerate() {
        let id = format!("material_{k}");
        let _ = writeln!(xml, "{}", bsdf_xml(material, &id));
        ids.insert(*entity, id);
    }

    let mut oq = w.query::<(
        &ObjectInfo,
        &Shape,
        &Transform,
        &MaterialRef,
        Option<&Emission>,
        Option<&FlipNormals>,
    )>();
    let mut objects: Vec<_> = oq.iter().collect();
    objects.sort_by_key(|o| o.0.order);
    for (k, (_, shape, transform, material, emission, flip)) in objects.into_iter().enumerate() {
        let file = format!("{stem}_{k}.ply");
        let placed = world_space(&shape.0, transform, flip.is_some());
        let path = mesh_dir.join(&file);
        let mut out = std::io::BufWriter::new(
            std::fs::File::create(&path)
                .map_err(|e| format!("cannot write {}: {e}", path.display()))?,
        );
        write_ply_f64(&mut out, &placed)
            .and_then(|()| out.flush())
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        let _ = writeln!(
            xml,
            "    <shape type=\"ply\">\n        <string name=\"filename\" value=\"meshes/{file}\"/>"
        );
        if placed.normals.is_none() {
            let _ = writeln!(
                xml,
                "        <boolean name=\"face_normals\" value=\"true\"/>"
            );
        }
        let _ = writeln!(xml, "        <ref id=\"{}\"/>", ids[&material.0]);
        if let Some(Emission(radiance)) = emission {
            let _ = writeln!(
                xml,
                "        <emitter type=\"area\">\n            <rgb name=\"radiance\" value=\"{}\"/>\n        </emitter>",
                f64s(*radiance)
            );
        }
        let _ = writeln!(xml, "    </shape>");
    }
    let _ = writeln!(xml, "</scene>");
    std::fs::write(xml_path, xml).map_err(|e| format!("cannot write {}: {e}", xml_path.display()))
}

/// An f32 as the shortest decimal that reads back (through f64, as the XML reader reads it) as
/// the same f32.
fn float(x: f32) -> String {
    let short = format!("{x}");
    match short.parse::<f64>() {
        Ok(v) if v as f32 == x => short,
        _ => format!("{}", x as f64),
    }
}

fn distribution_name(distribution: Microfacet) -> &'static str {
    match distribution {
        Microfacet::Ggx => "ggx",
        Microfacet::Beckmann => "beckmann",
    }
}

/// A microfacet lobe's roughness: `alpha`, or `alpha_u` and `alpha_v` where they differ.
fn alphas_xml(alpha_u: f32, alpha_v: f32) -> String {
    if alpha_u == alpha_v {
        format!("<float name=\"alpha\" value=\"{}\"/>", float(alpha_u))
    } else {
        format!(
            "<float name=\"alpha_u\" value=\"{}\"/>\n        <float name=\"alpha_v\" value=\"{}\"/>",
            float(alpha_u),
            float(alpha_v)
        )
    }
}

fn bsdf_xml(material: &Material, id: &str) -> String {
    let rgb = |v: Vec3| format!("{}, {}, {}", float(v.x), float(v.y), float(v.z));
    match *material {
        Material::Diffuse(Diffuse { reflectance }) => format!(
            "    <bsdf type=\"twosided\" id=\"{id}\">\n        <bsdf type=\"diffuse\">\n            \
             <rgb name=\"reflectance\" value=\"{}\"/>\n        </bsdf>\n    </bsdf>",
            rgb(reflectance)
        ),
        Material::RoughPlastic(p) => format!(
            "    <bsdf type=\"roughplastic\" id=\"{id}\">\n        \
             <string name=\"distribution\" value=\"{}\"/>\n        \
             <float name=\"alpha\" value=\"{}\"/>\n        \
             <float name=\"int_ior\" value=\"{}\"/>\n        <float name=\"ext_ior\" value=\"1\"/>\n        \
             <rgb name=\"diffuse_reflectance\" value=\"{}\"/>\n        \
             <rgb name=\"specular_reflectance\" value=\"{}\"/>\n        \
             <boolean name=\"nonlinear\" value=\"{}\"/>\n    </bsdf>",
            distribution_name(p.distribution),
            float(p.alpha),
            float(p.eta),
            rgb(p.diffuse),
            rgb(p.specular),
            p.nonlinear
        ),
        Material::RoughDielectric(d) => format!(
            "    <bsdf type=\"roughdielectric\" id=\"{id}\">\n        \
             <string name=\"distribution\" value=\"{}\"/>\n        {}\n        \
             <float name=\"int_ior\" value=\"{}\"/>\n        <float name=\"ext_ior\" value=\"1\"/>\n        \
             <rgb name=\"specular_reflectance\" value=\"{}\"/>\n        \
             <rgb name=\"specular_transmittance\" value=\"{}\"/>\n    </bsdf>",
            distribution_name(d.distribution),
            alphas_xml(d.alpha_u, d.alpha_v),
            float(d.eta),
            rgb(d.reflectance),
            rgb(d.transmittance)
        ),
        Material::Plastic(p) => format!(
            "    <bsdf type=\"plastic\" id=\"{id}\">\n        \
             <float name=\"int_ior\" value=\"{}\"/>\n        <float name=\"ext_ior\" value=\"1\"/>\n        \
             <rgb name=\"diffuse_reflectance\" value=\"{}\"/>\n        \
             <rgb name=\"specular_reflectance\" value=\"{}\"/>\n        \
             <boolean name=\"nonlinear\" value=\"{}\"/>\n    </bsdf>",
            float(p.eta),
            rgb(p.diffuse),
            rgb(p.specular),
            p.nonlinear
        ),
        Material::Dielectric(Dielectric { ior }) => format!(
            "    <bsdf type=\"dielectric\" id=\"{id}\">\n        <float name=\"int_ior\" value=\"{}\"/>\n        \
             <float name=\"ext_ior\" value=\"1\"/>\n    </bsdf>",
            float(ior)
        ),
        Material::ThinDielectric(ThinDielectric { ior }) => format!(
            "    <bsdf type=\"thindielectric\" id=\"{id}\">\n        <float name=\"int_ior\" value=\"{}\"/>\n        \
             <float name=\"ext_ior\" value=\"1\"/>\n    </bsdf>",
            float(ior)
        ),
        Material::Conductor(c) => {
            // The Fresnel factor 1 as Mitsuba's material "none"; any other index as rgb, which
            // Mitsuba's RGB variants take as it is (an unbounded texture).
            let ior = if c.ior == ComplexIor::PERFECT_MIRROR {
                "<string name=\"material\" value=\"none\"/>".to_string()
            } else {
                format!(
                    "<rgb name=\"eta\" value=\"{}\"/>\n        <rgb name=\"k\" value=\"{}\"/>",
                    rgb(c.ior.eta),
                    rgb(c.ior.k)
                )
            };
            let distribution = distribution_name(c.distribution);
            let alpha = alphas_xml(c.alpha_u, c.alpha_v);
            format!(
                "    <bsdf type=\"roughconductor\" id=\"{id}\">\n        {ior}\n        \
                 <string name=\"distribution\" value=\"{distribution}\"/>\n        {alpha}\n        \
                 <rgb name=\"specular_reflectance\" value=\"{}\"/>\n    </bsdf>",
                rgb(c.reflectance)
            )
        }
    }
}

/// The mesh as `prepare` places it: positions transformed, windings reversed where the
/// transform mirrors or the object flips its normals, normals transformed and normalised.
fn world_space(
    mesh: &crate::scene::shapes::Mesh,
    transform: &Transform,
    flip: bool,
) -> crate::scene::shapes::Mesh {
    let affine = transform.0;
    let normal_matrix = affine.matrix3.inverse().transpose();
    let reverse = (affine.matrix3.determinant() < 0.0) != flip;
    crate::scene::shapes::Mesh {
        positions: mesh
            .positions
            .iter()
            .map(|&p| affine.transform_point3(p))
            .collect(),
        triangles: mesh
            .triangles
            .iter()
            .map(|&[a, b, c]| if reverse { [a, c, b] } else { [a, b, c] })
            .collect(),
        normals: mesh.normals.as_ref().map(|normals| {
            normals
                .iter()
                .map(|&n| {
                    let n = (normal_matrix * n).try_normalize().unwrap_or(DVec3::ZERO);
                    if flip { -n } else { n }
                })
                .collect()
        }),
        // Texture coordinates are not written: the RON scenes have no textures.
        uvs: None,
    }
}

/// Binary little-endian PLY with double positions (and normals), so nothing is rounded.
fn write_ply_f64(out: &mut impl Write, mesh: &crate::scene::shapes::Mesh) -> std::io::Result<()> {
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by stagelight export\n\
         element vertex {}\nproperty double x\nproperty double y\nproperty double z\n",
        mesh.positions.len()
    );
    if mesh.normals.is_some() {
        header += "property double nx\nproperty double ny\nproperty double nz\n";
    }
    header += &format!(
        "element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.triangles.len()
    );
    out.write_all(header.as_bytes())?;
    for (k, p) in mesh.positions.iter().enumerate() {
        for c in p.to_array() {
            out.write_all(&c.to_le_bytes())?;
        }
        if let Some(normals) = &mesh.normals {
            for c in normals[k].to_array() {
                out.write_all(&c.to_le_bytes())?;
            }
        }
    }
    for t in &mesh.triangles {
        out.write_all(&[3])?;
        for i in t {
            out.write_all(&i.to_le_bytes())?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::conductor::Conductor;

    /// A conductor written by `bsdf_xml` reads back as itself, bit for bit: the Fresnel factor
    /// 1 as material "none", any other index as rgb eta and k, both distributions.
    #[test]
    fn conductors_export_and_read_back_exactly() {
        let gold = ComplexIor {
            eta: Vec3::new(0.143_035_98, 0.375_307_08, 1.442_045_3),
            k: Vec3::new(3.982_997, 2.385_556_5, 1.603_359_2),
        };
        for conductor in [
            Conductor::ggx(0.1, Vec3::new(1.0, 0.78, 0.34)),
            Conductor::isotropic(Microfacet::Beckmann, 0.3, Vec3::new(0.9, 0.8, 0.7), gold),
        ] {
            let material = Material::Conductor(conductor);
            let text = format!(
                "<scene version=\"3.0.0\">\n<sensor type=\"perspective\"><film type=\"hdrfilm\"><rfilter type=\"box\"/></film></sensor>\n{}\n\
                 <shape type=\"rectangle\"><ref id=\"m\"/></shape>\n\
                 <shape type=\"rectangle\"><transform name=\"to_world\"><translate z=\"2\"/></transform>\
                 <emitter type=\"area\"><rgb name=\"radiance\" value=\"1\"/></emitter></shape>\n</scene>\n",
                bsdf_xml(&material, "m")
            );
            let (scene, _) = crate::scene::load_mitsuba_from_str(
                Path::new("export-test.xml"),
                &text,
                &[],
                &crate::scene::Limits::of_this_machine(),
            )
            .unwrap_or_else(|e| panic!("{text}\n{e}"));
            assert!(scene.materials.contains(&material), "{text}");
        }
    }
}
