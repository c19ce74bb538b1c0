//! Wavefront OBJ meshes: vertices (`v`), vertex normals (`vn`) and polygonal faces (`f`, with
//! `v`, `v/vt`, `v//vn` or `v/vt/vn` references, negative ones relative to the end), every
//! group merged into one mesh; other statements (texture coordinates, groups, materials,
//! lines, points) are ignored. Errors name the mesh file and its line.
//!
//! Polygons of up to `FAN_LIMIT` vertices are triangulated as a fan from their first vertex
//! (as tobj and most tools do); larger ones by halving (the triangles (0, 1, 2), (2, 3, 4),
//! ..., then the same over the vertices 0, 2, 4, ..., and so on). Both give n - 2 triangles
//! covering a convex polygon, but a fan of 100,000 slivers that all span the polygon made the
//! BVH build quadratic, while halving gives small triangles along the rim and a few large
//! ones inside.

use super::shapes::{Mesh, MeshFile};
use glam::DVec3;
use std::collections::HashMap;
use std::path::Path;

/// Polygons with more vertices than this are triangulated by halving instead of as a fan.
pub const FAN_LIMIT: usize = 32;

/// A face's corner: its position index and normal index (0-based).
type Corner = (usize, Option<usize>);

/// Reads an OBJ file; errors and warnings name it (and the line).
pub fn load_obj(path: &Path) -> Result<MeshFile, String> {
    use std::io::Read;
    let name = super::echo_path(path);
    let mut bytes = Vec::new();
    super::shapes::open_mesh_file(path, &name)?
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read mesh file {name}: {e}"))?;
    parse_obj(&name, &bytes)
}

/// Parses OBJ text; `name` is the file as messages name it.
pub fn parse_obj(name: &str, bytes: &[u8]) -> Result<MeshFile, String> {
    let at = |line: usize, what: String| format!("mesh file {name} line {line}: {what}");
    let mut positions: Vec<DVec3> = Vec::new();
    let mut file_normals: Vec<Option<DVec3>> = Vec::new();
    let mut bad_normals = 0usize;
    let mut first_bad_normal = 0usize;
    // Faces as (line, [(position, normal)]) with indices resolved to 0-based, checked against
    // the counts at the end (a face may refer to vertices defined after it).
    let mut faces: Vec<(usize, Vec<Corner>)> = Vec::new();
    for (index, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = index + 1;
        let raw = match raw.iter().position(|&b| b == b'#') {
            Some(hash) => &raw[..hash],
            None => raw,
        };
        let mut tokens = raw
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty());
        let Some(keyword) = tokens.next() else {
            continue;
        };
        match keyword {
            b"v" | b"vn" => {
                let mut xyz = [0.0f64; 3];
                for (k, c) in xyz.iter_mut().enumerate() {
                    let token = tokens.next().ok_or_else(|| {
                        at(
                            line,
                            format!(
                                "`{}` needs 3 numbers, this one has {k}",
                                String::from_utf8_lossy(keyword)
                            ),
                        )
                    })?;
                    *c = number(token).ok_or_else(|| {
                        at(
                            line,
                            format!(
                                "malformed line: \"{}\" is not a number",
                                super::echo(&lossy(token))
                            ),
                        )
                    })?;
                }
                let v = DVec3::from_array(xyz);
                if keyword == b"v" {
                    if !v.is_finite() {
                        return Err(at(line, format!("vertex {:?} is not finite", v.to_array())));
                    }
                    positions.push(v);
                } else {
                    let n = v.is_finite().then(|| v.try_normalize()).flatten();
                    if n.is_none() {
                        bad_normals += 1;
                        if first_bad_normal == 0 {
                            first_bad_normal = line;
                        }
                    }
                    file_normals.push(n);
                }
            }
            b"f" => {
                let mut corners = Vec::new();
                for token in tokens {
                    corners.push(corner(token, positions.len(), file_normals.len()).map_err(
                        |what| {
                            at(
                                line,
                                format!("face vertex \"{}\": {what}", echo_token(token)),
                            )
                        },
                    )?);
                }
                if corners.len() < 3 {
                    return Err(at(
                        line,
                        format!(
                            "malformed face: a face needs at least 3 vertices, this one has {}",
                            corners.len()
                        ),
                    ));
                }
                faces.push((line, corners));
            }
            _ => {}
        }
    }
    if faces.is_empty() {
        return Err(format!("mesh file {name} has no faces"));
    }

    // One vertex per distinct (position, normal) pair, as tobj's `single_index` makes them.
    let mut mesh = Mesh::default();
    let mut normals: Vec<DVec3> = Vec::new();
    let mut any_normals = false;
    let mut vertex_of: HashMap<(usize, Option<usize>), u32> = HashMap::new();
    let mut polygon: Vec<u32> = Vec::new();
    for (line, corners) in &faces {
        polygon.clear();
        for &(p, n) in corners {
            if p >= positions.len() {
                return Err(at(
                    *line,
                    format!(
                        "a face refers to vertex {} but the file has {}",
                        p + 1,
                        positions.len()
                    ),
                ));
            }
            if let Some(n) = n
                && n >= file_normals.len()
            {
                return Err(at(
                    *line,
                    format!(
                        "a face refers to normal {} but the file has {}",
                        n + 1,
                        file_normals.len()
                    ),
                ));
            }
            if mesh.positions.len() >= u32::MAX as usize {
                return Err(format!("mesh file {name} has too many vertices"));
            }
            let next = mesh.positions.len() as u32;
            let v = *vertex_of.entry((p, n)).or_insert_with(|| {
                mesh.positions.push(positions[p]);
                let normal = n.and_then(|n| file_normals[n]);
                any_normals |= normal.is_some();
                normals.push(normal.unwrap_or(DVec3::ZERO));
                next
            });
            polygon.push(v);
        }
        triangulate(&polygon, &mut mesh.triangles);
    }
    mesh.normals = any_normals.then_some(normals);
    let mut warnings = Vec::new();
    if bad_normals > 0 {
        warnings.push(format!(
            "mesh file {name} line {first_bad_normal}: {bad_normals} vertex normal{} \
             infinite, NaN or zero: the faces that use {} are shaded flat",
            if bad_normals == 1 { " is" } else { "s are" },
            if bad_normals == 1 { "it" } else { "them" },
        ));
    }
    Ok(MeshFile { mesh, warnings })
}

/// Appends the triangles of a polygon (vertex indices in order): a fan up to `FAN_LIMIT`
/// vertices, halving beyond.
pub fn triangulate(polygon: &[u32], out: &mut Vec<[u32; 3]>) {
    if polygon.len() < 3 {
        return;
    }
    if polygon.len() <= FAN_LIMIT {
        for k in 1..polygon.len() - 1 {
            out.push([polygon[0], polygon[k], polygon[k + 1]]);
        }
        return;
    }
    let mut ring = polygon.to_vec();
    while ring.len() > 3 {
        let mut next = Vec::with_capacity(ring.len() / 2 + 2);
        let mut i = 0;
        while i + 2 < ring.len() {
            out.push([ring[i], ring[i + 1], ring[i + 2]]);
            next.push(ring[i]);
            i += 2;
        }
        next.extend_from_slice(&ring[i..]);
        ring = next;
    }
    out.push([ring[0], ring[1], ring[2]]);
}

/// An OBJ number as f32 (as tobj reads them), widened.
fn number(token: &[u8]) -> Option<f64> {
    std::str::from_utf8(token)
        .ok()?
        .parse::<f32>()
        .ok()
        .map(f64::from)
}

fn lossy(token: &[u8]) -> String {
    String::from_utf8_lossy(token).into_owned()
}

fn echo_token(token: &[u8]) -> String {
    super::echo(&lossy(token))
}

/// A face's vertex reference `v`, `v/vt`, `v//vn` or `v/vt/vn`: the 0-based position and
/// normal indices (negative references count back from the vertices defined so far).
fn corner(token: &[u8], positions: usize, normals: usize) -> Result<Corner, String> {
    let mut parts = token.split(|&b| b == b'/');
    let p = parts.next().unwrap_or_default();
    let _texture = parts.next();
    let n = parts.next().filter(|n| !n.is_empty());
    if parts.next().is_some() {
        return Err("more than three indices".into());
    }
    let p = resolve(p, positions)?;
    let n = n.map(|n| resolve(n, normals)).transpose()?;
    Ok((p, n))
}

/// A 1-based index, or a negative one counting back from `count`, as a 0-based index.
fn resolve(index: &[u8], count: usize) -> Result<usize, String> {
    let text = std::str::from_utf8(index).map_err(|_| "not an index".to_string())?;
    let i: i64 = text.parse().map_err(|_| "not an index".to_string())?;
    match i {
        0 => Err("index 0 (OBJ indices start at 1)".into()),
        i if i > 0 => Ok((i - 1) as usize),
        i => count
            .checked_sub(i.unsigned_abs() as usize)
            .ok_or_else(|| format!("relative index {i} reaches before the first vertex")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halving_covers_the_polygon_once() {
        for n in [3usize, 4, 5, 6, 7, 33, 34, 100, 1001] {
            let polygon: Vec<u32> = (0..n as u32).collect();
            let mut triangles = Vec::new();
            triangulate(&polygon, &mut triangles);
            assert_eq!(triangles.len(), n - 2, "{n}");
            // A regular polygon: the triangles' areas add up to the polygon's, all positive.
            let p = |i: u32| {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                DVec3::new(a.cos(), a.sin(), 0.0)
            };
            let area: f64 = triangles
                .iter()
                .map(|t| {
                    let z = (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).z;
                    assert!(z > 0.0, "{n}: {t:?} winds backwards");
                    z / 2.0
                })
                .sum();
            let exact = n as f64 / 2.0 * (std::f64::consts::TAU / n as f64).sin();
            assert!((area - exact).abs() < 1e-9, "{n}: {area} vs {exact}");
        }
    }

    #[test]
    fn short_faces_name_their_line() {
        let e = parse_obj("m.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n").unwrap_err();
        assert!(
            e.contains("m.obj line 5") && e.contains("3 vertices"),
            "{e}"
        );
        let e = parse_obj("m.obj", b"v 0 0 0\nf 1\n").unwrap_err();
        assert!(e.contains("line 2"), "{e}");
    }

    #[test]
    fn bad_normals_warn() {
        let m = parse_obj(
            "m.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn nan 0 1\nf 1//1 2//1 3//1\n",
        )
        .unwrap();
        assert_eq!(m.warnings.len(), 1);
        assert!(m.warnings[0].contains("line 4"), "{:?}", m.warnings);
        assert_eq!(m.mesh.normals, None);
    }
}
