//! Mitsuba's `serialized` meshes, format versions 3 and 4 (src/shapes/serialized.cpp):
//! little-endian, several meshes per file. Each mesh is a plain header (u16 magic 0x041C,
//! u16 version) followed by its own zlib stream holding
//!
//! - u32 flags: 0x0001 vertex normals, 0x0002 texture coordinates, 0x0008 vertex colours,
//!   0x0010 face normals, 0x1000 single precision, 0x2000 double precision;
//! - version 4 only: the shape's name, UTF-8, ending with a zero byte;
//! - u64 vertex count V, u64 triangle count F;
//! - V x 3 positions, then (as flagged) V x 3 normals, V x 2 texture coordinates and V x 3
//!   colours, all f32 or f64;
//! - F x 3 u32 vertex indices.
//!
//! The file ends with a dictionary: the byte offset of every mesh (u64 in version 4, u32 in
//! version 3; the first is 0), then the u32 number of meshes. As in Mitsuba, mesh 0 is read
//! from the start of the file and any other through the dictionary, whose layout the first
//! header's version decides; colours are read past, and the face-normals flag is ignored
//! (Mitsuba 3 reads it only from its `face_normals` parameter for these versions). Texture
//! coordinates are kept as stored (Mitsuba does not flip them for this format).
//!
//! Malformed files are errors naming the file, never panics: nothing is allocated for the
//! counts a header claims until the decompressed data is there to fill it.

use crate::scene::shapes::{Mesh, MeshFile};
use glam::{DVec2, DVec3};
use miniz_oxide::inflate::{TINFLStatus, decompress_to_vec_zlib_with_limit};
use std::path::Path;

/// The first two bytes of every mesh's header.
const MAGIC: u16 = 0x041C;

const HAS_NORMALS: u32 = 0x0001;
const HAS_TEXCOORDS: u32 = 0x0002;
const HAS_COLORS: u32 = 0x0008;
const DOUBLE_PRECISION: u32 = 0x2000;

/// Most bytes of a version 4 shape name read before giving up on its terminating zero.
const MAX_NAME: usize = 4096;

/// Reads mesh `shape_index` (0 for the first) of a `.serialized` file; errors and warnings
/// name the file.
pub fn load_serialized(path: &Path, shape_index: u32) -> Result<MeshFile, String> {
    use std::io::Read;
    let name = crate::scene::echo_path(path);
    let mut bytes = Vec::new();
    crate::scene::shapes::open_mesh_file(path, &name)?
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read mesh file {name}: {e}"))?;
    parse_serialized(&name, &bytes, shape_index)
}

/// Parses the bytes of a `.serialized` file; `name` is the file as messages name it.
pub fn parse_serialized(name: &str, bytes: &[u8], shape_index: u32) -> Result<MeshFile, String> {
    let fail = |what: String| format!("mesh file {name}: {what}");
    let version = header_version(bytes, 0).map_err(fail)?;
    let start = if shape_index == 0 {
        0
    } else {
        let offset = dictionary_offset(bytes, version, shape_index).map_err(fail)?;
        let at = header_version(bytes, offset).map_err(|what| {
            fail(format!(
                "the dictionary places shape {shape_index} at byte {offset}, but {what}"
            ))
        })?;
        if at != version {
            return Err(fail(format!(
                "shape {shape_index} has format version {at}, the file's first shape {version}"
            )));
        }
        offset
    };
    // `start + 4` is within the file: header_version read 4 bytes there.
    let stream = &bytes[start + 4..];
    let (mesh, warnings) = read_mesh(stream, version).map_err(|what| {
        if shape_index == 0 {
            fail(what)
        } else {
            fail(format!("shape {shape_index}: {what}"))
        }
    })?;
    let warnings = warnings
        .into_iter()
        .map(|w| format!("mesh file {name}: {w}"))
        .collect();
    Ok(MeshFile { mesh, warnings })
}

/// The format version of the mesh header at `offset`: the magic number must be there and the
/// version 3 or 4.
fn header_version(bytes: &[u8], offset: usize) -> Result<u16, String> {
    let header = offset
        .checked_add(4)
        .and_then(|end| bytes.get(offset..end))
        .ok_or_else(|| {
            format!(
                "the file ends before a mesh header (it has {} bytes)",
                bytes.len()
            )
        })?;
    let magic = u16::from_le_bytes([header[0], header[1]]);
    let version = u16::from_le_bytes([header[2], header[3]]);
    if magic != MAGIC {
        return Err(format!(
            "not a Mitsuba serialized mesh (the header starts with 0x{magic:04X}, not 0x{MAGIC:04X})"
        ));
    }
    match version {
        3 | 4 => Ok(version),
        _ => Err(format!(
            "serialized format version {version} is not supported (versions 3 and 4 are)"
        )),
    }
}

/// The byte offset of mesh `shape_index` from the dictionary at the end of the file.
fn dictionary_offset(bytes: &[u8], version: u16, shape_index: u32) -> Result<usize, String> {
    let short = || "the file is too short for its dictionary of shapes".to_string();
    let count_at = bytes.len().checked_sub(4).ok_or_else(short)?;
    let count = u32::from_le_bytes(le_array(&bytes[count_at..]).ok_or_else(short)?);
    if shape_index >= count {
        return Err(format!(
            "shape_index {shape_index} is out of range: the file holds {count} shape{}",
            if count == 1 { "" } else { "s" }
        ));
    }
    let entry = if version == 4 { 8 } else { 4 };
    let table = (count as usize)
        .checked_mul(entry)
        .and_then(|size| count_at.checked_sub(size))
        .ok_or_else(|| {
            format!(
                "the file's dictionary lists {count} shapes, more than its {} bytes can hold",
                bytes.len()
            )
        })?;
    let at = table + shape_index as usize * entry;
    let offset = if version == 4 {
        u64::from_le_bytes(le_array(&bytes[at..]).ok_or_else(short)?)
    } else {
        u32::from_le_bytes(le_array(&bytes[at..]).ok_or_else(short)?).into()
    };
    usize::try_from(offset)
        .ok()
        .filter(|&o| o < table)
        .ok_or_else(|| {
            format!(
                "the dictionary places shape {shape_index} at byte {offset}, past the meshes \
                 (they end at byte {table})"
            )
        })
}

/// The first N bytes of `bytes` as an array, if there are that many.
fn le_array<const N: usize>(bytes: &[u8]) -> Option<[u8; N]> {
    bytes.get(..N)?.try_into().ok()
}

/// Inflates the start of a zlib stream, at most `limit` bytes: all of it, or just `limit`
/// bytes when it holds more (those are complete).
fn inflate(stream: &[u8], limit: usize) -> Result<Vec<u8>, String> {
    match decompress_to_vec_zlib_with_limit(stream, limit) {
        Ok(data) => Ok(data),
        Err(e) if e.status == TINFLStatus::HasMoreOutput => {
            let mut data = e.output;
            data.truncate(limit);
            Ok(data)
        }
        Err(e) => Err(match e.status {
            TINFLStatus::FailedCannotMakeProgress | TINFLStatus::NeedsMoreInput => {
                "the compressed mesh data is truncated".to_string()
            }
            _ => format!("the compressed mesh data is corrupt ({e})"),
        }),
    }
}

/// A little-endian cursor over the inflated mesh data (bounds are checked by the caller).
struct Cursor<'a> {
    data: &'a [u8],
    at: usize,
}

impl Cursor<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        if let Some(bytes) = self.data.get(self.at..self.at + N) {
            out.copy_from_slice(bytes);
        }
        self.at += N;
        out
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }

    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
    }

    fn float(&mut self, double: bool) -> f64 {
        if double {
            f64::from_le_bytes(self.take())
        } else {
            f32::from_le_bytes(self.take()).into()
        }
    }
}

/// The mesh in one zlib stream (after its plain header), with warnings.
fn read_mesh(stream: &[u8], version: u16) -> Result<(Mesh, Vec<String>), String> {
    // Flags, the name and the counts first: then the size of the rest is known.
    let head_limit = 4 + if version == 4 { MAX_NAME + 1 } else { 0 } + 16;
    let head = inflate(stream, head_limit)?;
    let too_short = |what: &str| format!("the compressed mesh data ends inside {what}");
    if head.len() < 4 {
        return Err(too_short("the flags"));
    }
    let flags = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
    let mut header_len = 4;
    if version == 4 {
        let end = head[4..].iter().position(|&b| b == 0).ok_or_else(|| {
            if head.len() < head_limit {
                too_short("the shape name")
            } else {
                format!("the shape name is longer than {MAX_NAME} bytes")
            }
        })?;
        header_len += end + 1;
    }
    if head.len() < header_len + 16 {
        return Err(too_short("the vertex and triangle counts"));
    }
    let mut cursor = Cursor {
        data: &head,
        at: header_len,
    };
    let (vertices, triangles) = (cursor.u64(), cursor.u64());
    header_len += 16;
    if vertices > u32::MAX as u64 || triangles > u32::MAX as u64 {
        return Err(format!(
            "the header claims {vertices} vertices and {triangles} triangles, more than \
             32-bit indices allow"
        ));
    }
    if triangles == 0 {
        return Err("the mesh has no triangles".into());
    }

    let double = flags & DOUBLE_PRECISION != 0;
    let has_normals = flags & HAS_NORMALS != 0;
    let has_uvs = flags & HAS_TEXCOORDS != 0;
    let lanes = 3
        + if has_normals { 3 } else { 0 }
        + if has_uvs { 2 } else { 0 }
        + if flags & HAS_COLORS != 0 { 3 } else { 0 };
    let float_size = if double { 8 } else { 4 };
    let size = vertices
        .checked_mul(lanes * float_size)
        .and_then(|v| v.checked_add(triangles.checked_mul(12)?))
        .and_then(|s| s.checked_add(header_len as u64))
        .and_then(|s| usize::try_from(s).ok())
        .ok_or_else(|| "the mesh is too large for this machine".to_string())?;
    // The whole stream, bounded by what the header announces: allocation follows the data
    // actually inflated, not the counts.
    let data = if head.len() >= size {
        head
    } else {
        inflate(stream, size)?
    };
    if data.len() < size {
        return Err(format!(
            "the compressed mesh data is truncated: it holds {} bytes, the header announces \
             {size} for {vertices} vertices and {triangles} triangles",
            data.len()
        ));
    }
    let (v, f) = (vertices as usize, triangles as usize);
    let mut cursor = Cursor {
        data: &data,
        at: header_len,
    };
    let mut mesh = Mesh::default();
    let mut warnings = Vec::new();
    mesh.positions = (0..v)
        .map(|_| {
            DVec3::new(
                cursor.float(double),
                cursor.float(double),
                cursor.float(double),
            )
        })
        .collect();
    if let Some(k) = mesh.positions.iter().position(|p| !p.is_finite()) {
        return Err(format!(
            "vertex {k} {:?} is not finite",
            mesh.positions[k].to_array()
        ));
    }
    if has_normals {
        let (normals, bad) = crate::scene::shapes::usable_normals((0..v).map(|_| {
            DVec3::new(
                cursor.float(double),
                cursor.float(double),
                cursor.float(double),
            )
        }));
        mesh.normals = Some(normals);
        if bad > 0 {
            warnings.push(format!(
                "{bad} vertex normal{} infinite, NaN or zero: the faces that use {} are shaded \
                 flat",
                if bad == 1 { " is" } else { "s are" },
                if bad == 1 { "it" } else { "them" },
            ));
        }
    }
    if has_uvs {
        let uvs: Vec<DVec2> = (0..v)
            .map(|_| DVec2::new(cursor.float(double), cursor.float(double)))
            .collect();
        if uvs.iter().all(|uv| uv.is_finite()) {
            mesh.uvs = Some(uvs);
        } else {
            warnings.push(
                "texture coordinates that are not finite: the mesh's texture coordinates are \
                 dropped"
                    .into(),
            );
        }
    }
    if flags & HAS_COLORS != 0 {
        cursor.at += v * 3 * float_size as usize;
    }
    mesh.triangles = (0..f)
        .map(|_| [cursor.u32(), cursor.u32(), cursor.u32()])
        .collect();
    if let Some((k, i)) = mesh
        .triangles
        .iter()
        .enumerate()
        .find_map(|(k, t)| t.iter().find(|&&i| i as usize >= v).map(|&i| (k, i)))
    {
        return Err(format!(
            "triangle {k} refers to vertex {i} but the mesh has {v}"
        ));
    }
    Ok((mesh, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meshes_dir() -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/mitsuba/meshes")
    }

    /// One mesh of a file we write: f32 or f64, with or without normals, uvs and colours.
    struct Spec<'a> {
        mesh: &'a Mesh,
        double: bool,
        colors: bool,
    }

    /// A `.serialized` file of `meshes` in `version` 3 or 4, written independently of the
    /// reader from the format description.
    fn write(version: u16, meshes: &[Spec]) -> Vec<u8> {
        let mut file = Vec::new();
        let mut offsets = Vec::new();
        for (k, spec) in meshes.iter().enumerate() {
            offsets.push(file.len() as u64);
            file.extend(MAGIC.to_le_bytes());
            file.extend(version.to_le_bytes());
            let m = spec.mesh;
            let mut flags = if spec.double { 0x2000 } else { 0x1000 };
            flags |= if m.normals.is_some() { 1 } else { 0 };
            flags |= if m.uvs.is_some() { 2 } else { 0 };
            flags |= if spec.colors { 8 } else { 0 };
            let mut raw = Vec::new();
            raw.extend(u32::to_le_bytes(flags));
            if version == 4 {
                raw.extend(format!("shape {k}").bytes());
                raw.push(0);
            }
            raw.extend((m.positions.len() as u64).to_le_bytes());
            raw.extend((m.triangles.len() as u64).to_le_bytes());
            let mut floats = |values: &mut dyn Iterator<Item = f64>| {
                for x in values {
                    if spec.double {
                        raw.extend(x.to_le_bytes());
                    } else {
                        raw.extend((x as f32).to_le_bytes());
                    }
                }
            };
            floats(&mut m.positions.iter().flat_map(|p| p.to_array()));
            if let Some(n) = &m.normals {
                floats(&mut n.iter().flat_map(|n| n.to_array()));
            }
            if let Some(uv) = &m.uvs {
                floats(&mut uv.iter().flat_map(|uv| uv.to_array()));
            }
            if spec.colors {
                floats(&mut m.positions.iter().flat_map(|_| [0.25, 0.5, 0.75]));
            }
            for t in &m.triangles {
                for i in t {
                    raw.extend(i.to_le_bytes());
                }
            }
            file.extend(miniz_oxide::deflate::compress_to_vec_zlib(&raw, 6));
        }
        for o in &offsets {
            if version == 4 {
                file.extend(o.to_le_bytes());
            } else {
                file.extend((*o as u32).to_le_bytes());
            }
        }
        file.extend((meshes.len() as u32).to_le_bytes());
        file
    }

    /// Two small meshes: a quad with normals and uvs, a triangle without either.
    fn quad() -> Mesh {
        Mesh {
            positions: vec![
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(1.5, 0.0, 0.0),
                DVec3::new(1.5, 2.0, 0.0),
                DVec3::new(0.0, 2.0, 0.125),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            normals: Some(vec![DVec3::Z; 4]),
            uvs: Some(vec![
                DVec2::new(0.0, 0.0),
                DVec2::new(1.0, 0.0),
                DVec2::new(1.0, 1.0),
                DVec2::new(0.0, 0.75),
            ]),
        }
    }

    fn triangle() -> Mesh {
        crate::scene::shapes::triangle(
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(-1.0, 2.5, 3.0),
            DVec3::new(0.125, 7.0, -3.0),
        )
    }

    fn parse(bytes: &[u8], index: u32) -> Result<MeshFile, String> {
        parse_serialized("m.serialized", bytes, index)
    }

    #[test]
    fn serialized_written_files_read_back() {
        let (quad, triangle) = (quad(), triangle());
        for version in [3, 4] {
            for double in [false, true] {
                let file = write(
                    version,
                    &[
                        Spec {
                            mesh: &triangle,
                            double,
                            colors: true,
                        },
                        Spec {
                            mesh: &quad,
                            double,
                            colors: false,
                        },
                        Spec {
                            mesh: &triangle,
                            double: !double,
                            colors: false,
                        },
                    ],
                );
                let what = format!("version {version}, double {double}");
                // The values above are exact in f32.
                assert_eq!(parse(&file, 0).unwrap().mesh, triangle, "{what}");
                let read = parse(&file, 1).unwrap();
                assert_eq!(read.mesh, quad, "{what}");
                assert!(read.warnings.is_empty(), "{what}");
                assert_eq!(parse(&file, 2).unwrap().mesh, triangle, "{what}");
                let e = parse(&file, 7).unwrap_err();
                assert_eq!(
                    e,
                    "mesh file m.serialized: shape_index 7 is out of range: the file holds 3 \
                     shapes"
                );
            }
        }
    }

    #[test]
    fn serialized_double_precision_is_kept() {
        let mut mesh = triangle();
        mesh.positions[0].x = 0.1;
        let file = write(
            4,
            &[Spec {
                mesh: &mesh,
                double: true,
                colors: false,
            }],
        );
        assert_eq!(parse(&file, 0).unwrap().mesh.positions[0].x, 0.1);
    }

    /// Mitsuba 3.9.1's figures for the committed files: `mi.load_dict({'type': 'serialized',
    /// 'filename': ..., 'shape_index': i})`, then vertex_count(), face_count(), bbox(),
    /// surface_area() and the first entries of `mi.traverse`'s vertex arrays.
    struct Expected {
        file: &'static str,
        index: u32,
        vertices: usize,
        triangles: usize,
        min: [f32; 3],
        max: [f32; 3],
        area: f64,
        first_position: [f32; 3],
        first_normal: Option<[f32; 3]>,
        first_uvs: Option<[f32; 4]>,
    }

    const RECTANGLE_MIN: [f32; 3] = [-2.85, 0.0, -7.6];
    const RECTANGLE_MAX: [f32; 3] = [2.85, 0.0, 0.599999];
    const RECTANGLE_UVS: [f32; 4] = [0.950589, 0.011583984, 0.025105, 0.011583984];

    const EXPECTED: [Expected; 5] = [
        Expected {
            file: "rectangle_normals.serialized",
            index: 0,
            vertices: 4,
            triangles: 2,
            min: RECTANGLE_MIN,
            max: RECTANGLE_MAX,
            area: 46.73999,
            first_position: [-2.85, 0.0, -7.6],
            first_normal: Some([0.0, 1.0, 0.0]),
            first_uvs: None,
        },
        Expected {
            file: "rectangle_normals_uv.serialized",
            index: 0,
            vertices: 4,
            triangles: 2,
            min: RECTANGLE_MIN,
            max: RECTANGLE_MAX,
            area: 46.73999,
            first_position: [-2.85, 0.0, -7.6],
            first_normal: Some([0.0, 1.0, 0.0]),
            first_uvs: Some(RECTANGLE_UVS),
        },
        Expected {
            // Mitsuba computes vertex normals for it; the file has none.
            file: "rectangle_uv.serialized",
            index: 0,
            vertices: 4,
            triangles: 2,
            min: RECTANGLE_MIN,
            max: RECTANGLE_MAX,
            area: 46.73999,
            first_position: [-2.85, 0.0, -7.6],
            first_normal: None,
            first_uvs: Some(RECTANGLE_UVS),
        },
        Expected {
            file: "matpreview_2.serialized",
            index: 0,
            vertices: 289,
            triangles: 512,
            min: [-1.002427, -1.0, 0.0],
            max: [1.131355, 0.6228086, 1.29644],
            area: 4.9608188,
            first_position: [-0.50486624, 0.57472086, 0.784379],
            first_normal: Some([-0.0005493488, -0.9891029, 0.14722551]),
            first_uvs: Some([0.644658, 0.80923563, 0.6926974, 0.9002641]),
        },
        Expected {
            file: "matpreview_2.serialized",
            index: 1,
            vertices: 2078,
            triangles: 3936,
            min: [-0.9272718, -0.9272718, -0.0311116],
            max: [0.9272718, 0.9272718, 1.686867],
            area: 8.681538,
            first_position: [0.66702855, 0.27629226, 0.06282294],
            first_normal: Some([0.07086497, 0.029359221, 0.9970538]),
            first_uvs: Some([0.15914541, 0.31697714, 0.13776654, 0.352614]),
        },
    ];

    fn area(mesh: &Mesh) -> f64 {
        mesh.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
                (b - a).cross(c - a).length() / 2.0
            })
            .sum()
    }

    fn check(mesh: &Mesh, e: &Expected) {
        let what = format!("{} shape {}", e.file, e.index);
        assert_eq!(mesh.positions.len(), e.vertices, "{what}");
        assert_eq!(mesh.triangles.len(), e.triangles, "{what}");
        let min = mesh
            .positions
            .iter()
            .fold(DVec3::INFINITY, |m, p| m.min(*p));
        let max = mesh
            .positions
            .iter()
            .fold(DVec3::NEG_INFINITY, |m, p| m.max(*p));
        let near = |a: f64, b: f32| (a - f64::from(b)).abs() <= 2e-6 * (1.0 + a.abs());
        for k in 0..3 {
            assert!(
                near(min[k], e.min[k]) && near(max[k], e.max[k]),
                "{what}: {min} {max}"
            );
            assert!(near(mesh.positions[0][k], e.first_position[k]), "{what}");
        }
        assert!(
            (area(mesh) / e.area - 1.0).abs() < 1e-5,
            "{what}: {}",
            area(mesh)
        );
        match (&mesh.normals, e.first_normal) {
            (Some(n), Some(want)) => assert!((0..3).all(|k| near(n[0][k], want[k])), "{what}"),
            (None, None) => {}
            (got, want) => panic!(
                "{what}: normals {:?} vs {want:?}",
                got.as_ref().map(|n| n[0])
            ),
        }
        match (&mesh.uvs, e.first_uvs) {
            (Some(uv), Some(want)) => {
                let got = [uv[0].x, uv[0].y, uv[1].x, uv[1].y];
                assert!((0..4).all(|k| near(got[k], want[k])), "{what}: {got:?}");
            }
            (None, None) => {}
            (got, want) => panic!("{what}: uvs {:?} vs {want:?}", got.as_ref().map(|u| u[0])),
        }
    }

    #[test]
    fn serialized_files_match_mitsuba() {
        for e in &EXPECTED {
            let read = load_serialized(&meshes_dir().join(e.file), e.index).unwrap();
            assert!(read.warnings.is_empty(), "{:?}", read.warnings);
            check(&read.mesh, e);
        }
        let e = load_serialized(&meshes_dir().join("matpreview_2.serialized"), 2).unwrap_err();
        assert!(
            e.ends_with("shape_index 2 is out of range: the file holds 2 shapes"),
            "{e}"
        );
    }

    /// The whole matpreview.serialized of mitsuba-data (857 kB, not committed), where
    /// MITSUBA_DATA names a checkout of it.
    #[test]
    fn serialized_full_matpreview_matches_mitsuba() {
        let Some(data) = std::env::var_os("MITSUBA_DATA") else {
            eprintln!(
                "serialized_full_matpreview_matches_mitsuba: skipped, MITSUBA_DATA (a \
                 mitsuba-data checkout) is not set"
            );
            return;
        };
        let path = std::path::Path::new(&data).join("common/meshes/matpreview.serialized");
        for e in &EXPECTED[3..] {
            check(&load_serialized(&path, e.index).unwrap().mesh, e);
        }
        let third = Expected {
            file: "matpreview.serialized",
            index: 2,
            vertices: 29439,
            triangles: 57152,
            min: [-1.219943, -1.219943, -1.176495],
            max: [1.003021, 1.219943, 1.013164],
            area: 32.166462,
            first_position: [0.047490597, -0.44950318, -0.90268445],
            first_normal: Some([0.046815902, -0.38725355, -0.92078394]),
            first_uvs: Some([0.903927, 0.86437035, 0.91823924, 0.850504]),
        };
        check(&load_serialized(&path, 2).unwrap().mesh, &third);
        let e = load_serialized(&path, 7).unwrap_err();
        assert!(
            e.ends_with("shape_index 7 is out of range: the file holds 3 shapes"),
            "{e}"
        );
    }

    #[test]
    fn serialized_bad_files_are_clear_errors() {
        let quad = quad();
        let one = |version| {
            write(
                version,
                &[Spec {
                    mesh: &quad,
                    double: false,
                    colors: false,
                }],
            )
        };
        let good = one(4);
        assert!(parse(&good, 0).is_ok());
        let with = |f: &dyn Fn(&mut Vec<u8>)| {
            let mut b = good.clone();
            f(&mut b);
            b
        };
        // A mesh whose raw stream we build by hand: flags, name, counts, data.
        let raw_file = |raw: &[u8]| {
            let mut b = vec![0x1C, 0x04, 4, 0];
            b.extend(miniz_oxide::deflate::compress_to_vec_zlib(raw, 6));
            b.extend(0u64.to_le_bytes());
            b.extend(1u32.to_le_bytes());
            b
        };
        let header = |vertices: u64, triangles: u64| {
            let mut raw = 0x1000u32.to_le_bytes().to_vec();
            raw.extend(b"x\0");
            raw.extend(vertices.to_le_bytes());
            raw.extend(triangles.to_le_bytes());
            raw
        };
        let one_triangle = |index: u32, x: f32| {
            let mut raw = header(3, 1);
            for v in [x, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
                raw.extend(v.to_le_bytes());
            }
            for i in [0, 1, index] {
                raw.extend(u32::to_le_bytes(i));
            }
            raw_file(&raw)
        };
        assert!(parse(&one_triangle(2, 0.0), 0).is_ok());
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (vec![], "ends before a mesh header"),
            (vec![0x1C, 0x04, 4], "ends before a mesh header"),
            (with(&|b| b[0] = 0x1D), "not a Mitsuba serialized mesh"),
            (b"PLY\nformat".to_vec(), "not a Mitsuba serialized mesh"),
            (with(&|b| b[2] = 5), "version 5 is not supported"),
            (with(&|b| b[2] = 2), "version 2 is not supported"),
            (with(&|b| b[10] ^= 0xFF), "corrupt"),
            (good[..good.len() / 2].to_vec(), "truncated"),
            (good[..7].to_vec(), "truncated"),
            (
                one_triangle(3, 0.0),
                "triangle 0 refers to vertex 3 but the mesh has 3",
            ),
            (
                one_triangle(2, f32::NAN),
                "vertex 0 [NaN, 0.0, 0.0] is not finite",
            ),
            (one_triangle(2, f32::INFINITY), "not finite"),
            (raw_file(&header(3, 0)), "no triangles"),
            (raw_file(&header(1 << 40, 1)), "32-bit indices"),
            (raw_file(&header(3, 1)), "truncated: it holds 22 bytes"),
            (
                raw_file(&header(u32::MAX.into(), u32::MAX.into())),
                "truncated",
            ),
            (
                raw_file(&[0, 0x10, 0, 0, b'a']),
                "ends inside the shape name",
            ),
            (raw_file(&[0, 0x10]), "ends inside the flags"),
            (
                raw_file(&[0, 0x10, 0, 0, 0, 1, 2]),
                "ends inside the vertex and triangle",
            ),
            (raw_file(&vec![b'a'; 5000]), "longer than 4096 bytes"),
        ];
        for (bytes, phrase) in cases {
            let e = parse(&bytes, 0).expect_err(phrase);
            assert!(e.starts_with("mesh file m.serialized: "), "{e}");
            assert!(e.contains(phrase), "{phrase:?} missing from {e}");
            assert!(!e.contains('\n') && e.len() < 300, "{e}");
        }
        // Dictionary troubles, for a shape other than the first.
        let two = write(
            3,
            &[
                Spec {
                    mesh: &quad,
                    double: false,
                    colors: false,
                },
                Spec {
                    mesh: &quad,
                    double: false,
                    colors: false,
                },
            ],
        );
        assert!(parse(&two, 1).is_ok());
        let n = two.len();
        let dictionary_cases: Vec<(Vec<u8>, &str)> = vec![
            (
                one(4),
                "shape_index 1 is out of range: the file holds 1 shape",
            ),
            (
                [&two[..n - 4], &1000u32.to_le_bytes()[..]].concat(),
                "lists 1000 shapes, more than",
            ),
            (
                [
                    &two[..n - 8],
                    &9999u32.to_le_bytes()[..],
                    &2u32.to_le_bytes()[..],
                ]
                .concat(),
                "at byte 9999, past the meshes",
            ),
            (
                [
                    &two[..n - 8],
                    &5u32.to_le_bytes()[..],
                    &2u32.to_le_bytes()[..],
                ]
                .concat(),
                "places shape 1 at byte 5, but not a Mitsuba serialized mesh",
            ),
        ];
        for (bytes, phrase) in dictionary_cases {
            let e = parse(&bytes, 1).expect_err(phrase);
            assert!(e.contains(phrase), "{phrase:?} missing from {e}");
        }
        // A version 3 file whose second mesh says version 4.
        let first = one(3);
        let first = &first[..first.len() - 8];
        let second = one(4);
        let second = &second[..second.len() - 12];
        let mut mixed = [first, second].concat();
        for word in [0, first.len() as u32, 2] {
            mixed.extend(word.to_le_bytes());
        }
        assert!(parse(&mixed, 0).is_ok());
        let e = parse(&mixed, 1).unwrap_err();
        assert!(
            e.contains("shape 1 has format version 4, the file's first shape 3"),
            "{e}"
        );
    }

    #[test]
    fn serialized_truncated_and_corrupted_files_never_panic() {
        let bytes = std::fs::read(meshes_dir().join("matpreview_2.serialized")).unwrap();
        // Shape 0's data ends where shape 1 starts (its dictionary entry).
        let second = 5167;
        assert!(parse(&bytes, 0).is_ok() && parse(&bytes, 1).is_ok());
        // Every cut inside shape 0 loses some of it; every cut loses the dictionary that
        // shape 1 is found by.
        let cuts = (0..second + 64).chain((second + 64..bytes.len()).step_by(97));
        for cut in cuts {
            let part = &bytes[..cut];
            if cut < second {
                assert!(parse(part, 0).is_err(), "shape 0, cut at {cut}");
            }
            assert!(parse(part, 1).is_err(), "shape 1, cut at {cut}");
        }
        // Corrupted bytes: a clear error, or a mesh that passed every check.
        let mut errors = 0;
        let spots = (0..600).chain((600..bytes.len()).step_by(53));
        for spot in spots {
            for flip in [0x01u8, 0x80, 0xFF] {
                let mut bad = bytes.clone();
                bad[spot] ^= flip;
                for index in [0, 1] {
                    match parse(&bad, index) {
                        Ok(m) => {
                            let count = m.mesh.positions.len() as u32;
                            assert!(m.mesh.triangles.iter().flatten().all(|&i| i < count));
                            assert!(m.mesh.positions.iter().all(|p| p.is_finite()));
                        }
                        Err(e) => {
                            assert!(e.starts_with("mesh file m.serialized: "), "{e}");
                            errors += 1;
                        }
                    }
                }
            }
        }
        assert!(errors > 1000, "{errors}");
    }
}
