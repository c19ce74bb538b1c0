//! Stanford PLY meshes, read with `ply-rs-bw` (ASCII, binary little-endian and binary
//! big-endian): the `vertex` element's `x`, `y`, `z` (any scalar type) and, when all three are
//! there, its `nx`, `ny`, `nz` as vertex normals, and texture coordinates as Mitsuba's PLY
//! reader finds them (`texture_u`/`texture_v`, else `s`/`t`, else `u`/`v`, stored unflipped as
//! Mitsuba does by default; uvs that are not finite are dropped with a warning); the `face`
//! element's `vertex_indices` (or `vertex_index`) list of any integer type. Other elements and
//! properties (colours, edges, materials) are read past and ignored. Polygons are triangulated as OBJ
//! polygons are (`obj::triangulate`: fans up to 32 vertices, halving beyond); a face of fewer
//! than 3 vertices, an index outside the file or a negative one is an error, as is a vertex
//! that is not finite. Normals that are not finite or zero are a warning, and the faces that
//! use them are shaded flat.
//!
//! Errors name the mesh file and, where the crate knows it, the line (ASCII) or the element
//! being read; the crate's multi-line messages are flattened to one short line.

use super::shapes::{Mesh, MeshFile};
use glam::{DVec2, DVec3};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{ElementDef, Header, Property, PropertyAccess, PropertyAccessResult};
use std::io::{BufRead, Write};
use std::path::Path;

/// Reads a PLY file; errors and warnings name it.
pub fn load_ply(path: &Path) -> Result<MeshFile, String> {
    let name = super::echo_path(path);
    let file = super::shapes::open_mesh_file(path, &name)?;
    parse_ply(&name, std::io::BufReader::with_capacity(1 << 16, file))
}

/// Which pair of vertex properties holds the texture coordinates (a const parameter of
/// `Vertex`, since the crate builds each record without context).
const NO_UV: u8 = 0;
const UV_U_V: u8 = 1;
const UV_S_T: u8 = 2;
const UV_TEXTURE_U_V: u8 = 3;

/// The texture coordinate properties of a vertex element, as Mitsuba looks for them:
/// `texture_u`/`texture_v`, else `s`/`t`, else `u`/`v`.
fn uv_names(def: &ElementDef) -> u8 {
    let has = |name: &str| def.properties.contains_key(name);
    if has("texture_u") && has("texture_v") {
        UV_TEXTURE_U_V
    } else if has("s") && has("t") {
        UV_S_T
    } else if has("u") && has("v") {
        UV_U_V
    } else {
        NO_UV
    }
}

/// A vertex as read: position, normal and texture coordinates in double precision; `UV`
/// names the properties the texture coordinates come from.
#[derive(Default)]
struct Vertex<const UV: u8> {
    p: [f64; 3],
    n: [f64; 3],
    uv: [f64; 2],
}

impl<const UV: u8> PropertyAccess for Vertex<UV> {
    fn new() -> Self {
        Vertex::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let slot = match (name, UV) {
            ("x", _) => &mut self.p[0],
            ("y", _) => &mut self.p[1],
            ("z", _) => &mut self.p[2],
            ("nx", _) => &mut self.n[0],
            ("ny", _) => &mut self.n[1],
            ("nz", _) => &mut self.n[2],
            ("u", UV_U_V) | ("s", UV_S_T) | ("texture_u", UV_TEXTURE_U_V) => &mut self.uv[0],
            ("v", UV_U_V) | ("t", UV_S_T) | ("texture_v", UV_TEXTURE_U_V) => &mut self.uv[1],
            _ => return PropertyAccessResult::Ignored,
        };
        match scalar(&property) {
            Some(v) => {
                *slot = v;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::UnsupportedType,
        }
    }
}

/// A scalar property as f64; None for a list.
fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v.into(),
        Property::UChar(v) => v.into(),
        Property::Short(v) => v.into(),
        Property::UShort(v) => v.into(),
        Property::Int(v) => v.into(),
        Property::UInt(v) => v.into(),
        Property::Float(v) => v.into(),
        Property::Double(v) => v,
        _ => return None,
    })
}

/// A face as read: its vertex indices, or the first negative one.
#[derive(Default)]
struct Face {
    indices: Vec<u32>,
    negative: Option<i32>,
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Face::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        if !is_index_list(name) {
            return PropertyAccessResult::Ignored;
        }
        let signed = |face: &mut Face, values: &mut dyn Iterator<Item = i32>| {
            for v in values {
                match u32::try_from(v) {
                    Ok(i) => face.indices.push(i),
                    Err(_) => {
                        face.negative.get_or_insert(v);
                    }
                }
            }
        };
        match property {
            Property::ListUInt(v) => self.indices = v,
            Property::ListUShort(v) => self.indices = v.into_iter().map(u32::from).collect(),
            Property::ListUChar(v) => self.indices = v.into_iter().map(u32::from).collect(),
            Property::ListInt(v) => signed(self, &mut v.into_iter()),
            Property::ListShort(v) => signed(self, &mut v.into_iter().map(i32::from)),
            Property::ListChar(v) => signed(self, &mut v.into_iter().map(i32::from)),
            _ => return PropertyAccessResult::UnsupportedType,
        }
        PropertyAccessResult::Set
    }
}

fn is_index_list(name: &str) -> bool {
    name == "vertex_indices" || name == "vertex_index"
}

/// An element the mesh does not use: read past.
struct Skipped;

impl PropertyAccess for Skipped {
    fn new() -> Self {
        Skipped
    }
}

/// The crate's message as one short line: its line breaks and tabs become spaces, and it is
/// cut after 200 characters (it quotes the offending line, which may be a megabyte of binary).
fn one_line(message: &str) -> String {
    let flat: String = message.split_whitespace().collect::<Vec<_>>().join(" ");
    super::clip(&flat, 200)
}

/// Parses a PLY file from `source`; `name` is the file as messages name it.
pub fn parse_ply<R: BufRead>(name: &str, source: R) -> Result<MeshFile, String> {
    let fail = |what: String| format!("mesh file {name}: {what}");
    let mut reader = Reader::new(source);
    let header = Parser::<Skipped>::new()
        .read_header(&mut reader)
        .map_err(|e| {
            fail(format!(
                "not a valid PLY header: {}",
                one_line(&e.to_string())
            ))
        })?;
    let vertex_def = header
        .elements
        .get("vertex")
        .ok_or_else(|| fail("the PLY file has no vertex element".into()))?;
    let face_def = header.elements.get("face").ok_or_else(|| {
        fail("the PLY file has no face element (triangle strips are not read)".into())
    })?;
    let has = |def: &ElementDef, property: &str| def.properties.contains_key(property);
    for axis in ["x", "y", "z"] {
        if !has(vertex_def, axis) {
            return Err(fail(format!(
                "the PLY vertex element has no `{axis}` property"
            )));
        }
    }
    let with_normals = ["nx", "ny", "nz"].iter().all(|n| has(vertex_def, n));
    if !face_def.properties.keys().any(|k| is_index_list(k)) {
        return Err(fail(
            "the PLY face element has no vertex_indices (or vertex_index) list".into(),
        ));
    }

    let uv = uv_names(vertex_def);
    match uv {
        UV_U_V => read_mesh::<UV_U_V, R>(name, reader, &header, with_normals),
        UV_S_T => read_mesh::<UV_S_T, R>(name, reader, &header, with_normals),
        UV_TEXTURE_U_V => read_mesh::<UV_TEXTURE_U_V, R>(name, reader, &header, with_normals),
        _ => read_mesh::<NO_UV, R>(name, reader, &header, with_normals),
    }
}

/// The elements after the header, and the mesh they make; `UV` names the texture coordinate
/// properties (`NO_UV`: none).
fn read_mesh<const UV: u8, R: BufRead>(
    name: &str,
    mut reader: Reader<R>,
    header: &Header,
    with_normals: bool,
) -> Result<MeshFile, String> {
    let fail = |what: String| format!("mesh file {name}: {what}");
    let mut vertices: Vec<Vertex<UV>> = Vec::new();
    let mut faces: Vec<Face> = Vec::new();
    for (element, def) in &header.elements {
        let read = |e: ply_rs_bw::parser::ParseError| {
            fail(format!(
                "PLY element \"{}\": {}",
                super::echo(element),
                one_line(&e.to_string())
            ))
        };
        match element.as_str() {
            "vertex" => vertices = read_element(&mut reader, def, header).map_err(read)?,
            "face" => faces = read_element(&mut reader, def, header).map_err(read)?,
            _ => {
                read_element::<Skipped, R>(&mut reader, def, header).map_err(read)?;
            }
        }
    }
    if faces.is_empty() {
        return Err(fail("the PLY file has no faces".into()));
    }

    let mut mesh = Mesh::default();
    mesh.positions.reserve(vertices.len());
    for (k, v) in vertices.iter().enumerate() {
        let p = DVec3::from_array(v.p);
        if !p.is_finite() {
            return Err(fail(format!("vertex {k} {:?} is not finite", v.p)));
        }
        mesh.positions.push(p);
    }
    let mut warnings = Vec::new();
    if with_normals {
        let (normals, bad) =
            super::shapes::usable_normals(vertices.iter().map(|v| DVec3::from_array(v.n)));
        mesh.normals = Some(normals);
        if bad > 0 {
            warnings.push(format!(
                "mesh file {name}: {bad} vertex normal{} infinite, NaN or zero: the faces \
                 that use {} are shaded flat",
                if bad == 1 { " is" } else { "s are" },
                if bad == 1 { "it" } else { "them" },
            ));
        }
    }
    if UV != NO_UV {
        if vertices.iter().all(|v| v.uv.iter().all(|c| c.is_finite())) {
            mesh.uvs = Some(vertices.iter().map(|v| DVec2::from_array(v.uv)).collect());
        } else {
            warnings.push(format!(
                "mesh file {name}: texture coordinates that are not finite: the mesh's \
                 texture coordinates are dropped"
            ));
        }
    }
    drop(vertices);
    let count = mesh.positions.len();
    mesh.triangles.reserve(faces.len());
    for (k, face) in faces.iter().enumerate() {
        if let Some(i) = face.negative {
            return Err(fail(format!("face {k} refers to vertex {i}")));
        }
        if face.indices.len() < 3 {
            return Err(fail(format!(
                "malformed face {k}: a face needs at least 3 vertices, this one has {}",
                face.indices.len()
            )));
        }
        if let Some(&i) = face.indices.iter().find(|&&i| i as usize >= count) {
            return Err(fail(format!(
                "face {k} refers to vertex {i} but the file has {count}"
            )));
        }
        super::obj::triangulate(&face.indices, &mut mesh.triangles);
    }
    Ok(MeshFile { mesh, warnings })
}

fn read_element<E: PropertyAccess, R: BufRead>(
    reader: &mut Reader<R>,
    def: &ElementDef,
    header: &Header,
) -> Result<Vec<E>, ply_rs_bw::parser::ParseError> {
    Parser::<E>::new().read_payload_for_element(reader, def, header)
}

/// Writes a mesh as binary little-endian PLY: float positions, float normals when the mesh has
/// them, and each triangle as a list of three (uchar count, uint indices), the layout
/// Mitsuba's and pbrt's loaders read.
pub fn write_ply(out: &mut impl Write, mesh: &Mesh) -> std::io::Result<()> {
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by stagelight\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        mesh.positions.len()
    );
    if mesh.normals.is_some() {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    header += &format!(
        "element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.triangles.len()
    );
    out.write_all(header.as_bytes())?;
    let mut bytes = Vec::with_capacity(1 << 16);
    let flush = |bytes: &mut Vec<u8>, out: &mut dyn Write| -> std::io::Result<()> {
        out.write_all(bytes)?;
        bytes.clear();
        Ok(())
    };
    for (k, p) in mesh.positions.iter().enumerate() {
        for c in p.as_vec3().to_array() {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
        if let Some(normals) = &mesh.normals {
            for c in normals[k].as_vec3().to_array() {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        if bytes.len() >= 1 << 16 {
            flush(&mut bytes, out)?;
        }
    }
    for t in &mesh.triangles {
        bytes.push(3);
        for i in t {
            bytes.extend_from_slice(&i.to_le_bytes());
        }
        if bytes.len() >= 1 << 16 {
            flush(&mut bytes, out)?;
        }
    }
    flush(&mut bytes, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(bytes: &[u8]) -> Result<MeshFile, String> {
        parse_ply("m.ply", bytes)
    }

    const SQUARE_ASCII: &str = "ply\nformat ascii 1.0\ncomment a unit square as one quad\n\
        element vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
        element face 1\nproperty list uchar int vertex_indices\nend_header\n\
        0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";

    #[test]
    fn ascii_quad_is_two_triangles() {
        let m = parse(SQUARE_ASCII.as_bytes()).unwrap();
        assert_eq!(m.mesh.positions.len(), 4);
        assert_eq!(m.mesh.positions[2], DVec3::new(1.0, 1.0, 0.0));
        assert_eq!(m.mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.mesh.normals, None);
    }

    /// The same triangle with a normal per vertex, written by hand in both byte orders,
    /// with double positions, a ushort-indexed list and an extra element to read past.
    fn binary(big_endian: bool) -> Vec<u8> {
        let mut b = format!(
            "ply\nformat binary_{}_endian 1.0\nelement vertex 3\nproperty double x\n\
             property double y\nproperty double z\nproperty uchar red\nproperty float nx\n\
             property float ny\nproperty float nz\nelement face 1\n\
             property list uchar ushort vertex_index\nelement edge 1\nproperty int a\n\
             end_header\n",
            if big_endian { "big" } else { "little" }
        )
        .into_bytes();
        let f64s = |b: &mut Vec<u8>, v: f64| {
            b.extend(if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            })
        };
        let f32s = |b: &mut Vec<u8>, v: f32| {
            b.extend(if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            })
        };
        for (p, n) in [
            ([0.5, 0.0, 0.1], [0.0, 0.0, 2.0]),
            ([1.0, 0.0, 0.1], [0.0, 0.0, 1.0]),
            ([0.0, 1.0, 0.1], [0.0, 0.0, 0.0]),
        ] {
            for c in p {
                f64s(&mut b, c);
            }
            b.push(200);
            for c in n {
                f32s(&mut b, c);
            }
        }
        b.push(3);
        for i in [0u16, 1, 2] {
            b.extend(if big_endian {
                i.to_be_bytes()
            } else {
                i.to_le_bytes()
            });
        }
        b.extend(7i32.to_le_bytes());
        b
    }

    #[test]
    fn binary_both_byte_orders_with_normals() {
        for big_endian in [false, true] {
            let m = parse(&binary(big_endian)).unwrap();
            assert_eq!(m.mesh.positions[0], DVec3::new(0.5, 0.0, 0.1));
            assert_eq!(m.mesh.positions[2], DVec3::new(0.0, 1.0, 0.1));
            assert_eq!(m.mesh.triangles, vec![[0, 1, 2]]);
            // Normalised; the zero one is kept as "no normal" with a warning.
            assert_eq!(m.mesh.normals, Some(vec![DVec3::Z, DVec3::Z, DVec3::ZERO]));
            assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
            assert!(m.warnings[0].contains("m.ply") && m.warnings[0].contains("flat"));
        }
    }

    #[test]
    fn polygons_triangulate_as_obj_polygons_do() {
        let text = SQUARE_ASCII
            .replace("element vertex 4", "element vertex 5")
            .replace("0 1 0\n4 0 1 2 3", "0 1 0\n0.5 1.5 0\n5 0 1 2 4 3");
        let m = parse(text.as_bytes()).unwrap();
        assert_eq!(m.mesh.triangles, vec![[0, 1, 2], [0, 2, 4], [0, 4, 3]]);
    }

    #[test]
    fn written_files_read_back() {
        let mut mesh = super::super::shapes::icosphere(1, true);
        let mut bytes = Vec::new();
        write_ply(&mut bytes, &mesh).unwrap();
        let read = parse(&bytes).unwrap();
        // Positions and normals go through f32.
        for v in mesh.positions.iter_mut() {
            *v = v.as_vec3().as_dvec3();
        }
        let normals = mesh.normals.as_mut().unwrap();
        for n in normals.iter_mut() {
            *n = n.as_vec3().as_dvec3().normalize();
        }
        assert_eq!(read.mesh.positions, mesh.positions);
        assert_eq!(read.mesh.triangles, mesh.triangles);
        for (a, b) in read.mesh.normals.unwrap().iter().zip(mesh.normals.unwrap()) {
            assert!((*a - b).length() < 1e-15, "{a} {b}");
        }
    }

    #[test]
    fn bad_files_are_one_line_errors_naming_the_file() {
        let cases: Vec<(String, &str)> = vec![
            ("solid x\n".into(), "header"),
            (SQUARE_ASCII.replace("ascii", "utf8"), "header"),
            (SQUARE_ASCII.replace("end_header\n", ""), "header"),
            (SQUARE_ASCII.replace("4 0 1 2 3", "4 0 1 2 9"), "vertex 9"),
            (SQUARE_ASCII.replace("4 0 1 2 3", "4 0 1 -2 3"), "vertex -2"),
            (SQUARE_ASCII.replace("4 0 1 2 3", "2 0 1"), "3 vertices"),
            (SQUARE_ASCII.replace("4 0 1 2 3", "4 0 1 2"), "face"),
            (SQUARE_ASCII.replace("1 1 0\n", "1 1e39 0\n"), "not finite"),
            (SQUARE_ASCII.replace("1 1 0\n", "1 nan 0\n"), "vertex"),
            (SQUARE_ASCII.replace("1 1 0\n", "1 one 0\n"), "vertex"),
            (SQUARE_ASCII.replace("0 1 0\n4", "4"), "face"),
            (SQUARE_ASCII.replace("property float y\n", ""), "`y`"),
            (
                SQUARE_ASCII.replace("vertex_indices", "corners"),
                "vertex_indices",
            ),
            (
                SQUARE_ASCII.replace("element face 1", "element face 0"),
                "no faces",
            ),
            (
                SQUARE_ASCII.replace("list uchar int", "list uchar float"),
                "vertex_indices",
            ),
            (
                SQUARE_ASCII.replace("element vertex 4", "element vertex 4000000000000"),
                "vertex",
            ),
        ];
        for (text, phrase) in cases {
            let e = parse(text.as_bytes()).expect_err(&text);
            assert!(!e.contains('\n') && e.len() < 400, "{e:?}");
            assert!(e.starts_with("mesh file m.ply: "), "{e}");
            assert!(e.contains(phrase), "{phrase:?} missing from {e}");
        }
    }

    #[test]
    fn every_truncation_of_a_binary_file_is_an_error() {
        let whole = binary(false);
        assert!(parse(&whole).is_ok());
        // Every proper prefix lacks data (the last byte ends the edge element).
        for cut in 0..whole.len() {
            let e = parse(&whole[..cut]).expect_err(&format!("cut at {cut}"));
            assert!(!e.contains('\n') && e.contains("m.ply"), "{e:?}");
        }
    }

    #[test]
    fn texture_coordinates_as_mitsuba_finds_them() {
        let with = |properties: &str, extra: &str| {
            SQUARE_ASCII
                .replace(
                    "property float z\n",
                    &format!("property float z\n{properties}"),
                )
                .replace("0 0 0\n1 0 0\n1 1 0\n0 1 0\n", extra)
        };
        let values = "0 0 0 0.1 0.2\n1 0 0 0.3 0.4\n1 1 0 0.5 0.6\n0 1 0 0.7 0.8\n";
        let want = [[0.1, 0.2], [0.3, 0.4], [0.5, 0.6], [0.7, 0.8]];
        for pair in [("u", "v"), ("s", "t"), ("texture_u", "texture_v")] {
            let text = with(
                &format!("property float {}\nproperty double {}\n", pair.0, pair.1),
                values,
            );
            let m = parse(text.as_bytes()).unwrap();
            let uvs: Vec<[f64; 2]> = m.mesh.uvs.unwrap().iter().map(|uv| uv.to_array()).collect();
            let uvs: Vec<[f64; 2]> = uvs.iter().map(|uv| uv.map(|c| (c as f32) as f64)).collect();
            let want: Vec<[f64; 2]> = want
                .iter()
                .map(|uv| uv.map(|c| (c as f32) as f64))
                .collect();
            assert_eq!(uvs, want, "{pair:?}");
        }
        // s/t wins over u/v, texture_u/texture_v over both (Mitsuba renames them to u/v).
        let text = with(
            "property float u\nproperty float v\nproperty float s\nproperty float t\n",
            "0 0 0 9 9 0.5 0.25\n1 0 0 9 9 0 0\n1 1 0 9 9 0 0\n0 1 0 9 9 0 0\n",
        );
        let m = parse(text.as_bytes()).unwrap();
        assert_eq!(m.mesh.uvs.unwrap()[0], DVec2::new(0.5, 0.25));
        // Half a pair is not texture coordinates.
        let text = with("property float u\n", "0 0 0 1\n1 0 0 1\n1 1 0 1\n0 1 0 1\n");
        assert_eq!(parse(text.as_bytes()).unwrap().mesh.uvs, None);
        // Not finite: dropped with a warning.
        let text = with(
            "property float u\nproperty float v\n",
            "0 0 0 0 0\n1 0 0 1e39 0\n1 1 0 0 0\n0 1 0 0 0\n",
        );
        let m = parse(text.as_bytes()).unwrap();
        assert_eq!(m.mesh.uvs, None);
        assert!(
            m.warnings[0].contains("texture coordinates are dropped"),
            "{:?}",
            m.warnings
        );
    }
}
