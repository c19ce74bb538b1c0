//! Wavefront OBJ meshes: vertices (`v`), vertex normals (`vn`), texture coordinates (`vt`)
//! and polygonal faces (`f`, with `v`, `v/vt`, `v//vn` or `v/vt/vn` references, negative ones
//! relative to the end), every group merged into one mesh; other statements (groups,
//! materials, lines, points) are ignored. Errors name the mesh file and its line.
//!
//! Texture coordinates become `Mesh::uvs` as written in the file (v is not flipped; Mitsuba's
//! reader flips it by default, see `Mesh::flip_tex_coords`); a corner without a `vt`
//! reference gets (0, 0), as in Mitsuba. They are only kept, not rendered, so a file whose
//! texture coordinates are unusable (a `vt` that is not numbers or not finite, a face that
//! refers to a `vt` the file lacks) still loads as before: its uvs are dropped with a warning.
//!
//! Polygons of up to `FAN_LIMIT` vertices are triangulated as a fan from their first vertex
//! (as tobj and most tools do); larger ones by halving (the triangles (0, 1, 2), (2, 3, 4),
//! ..., then the same over the vertices 0, 2, 4, ..., and so on). Both give n - 2 triangles
//! covering a convex polygon, but a fan of 100,000 slivers that all span the polygon made the
//! BVH build quadratic, while halving gives small triangles along the rim and a few large
//! ones inside.

use super::shapes::{Mesh, MeshFile};
use glam::{DVec2, DVec3};
use std::collections::HashMap;
use std::path::Path;

/// Polygons with more vertices than this are triangulated by halving instead of as a fan.
pub const FAN_LIMIT: usize = 32;

/// A face's corner: its position, texture coordinate and normal indices (0-based), `NONE`
/// where it has none (plain indices keep a big file's corners at 24 bytes).
type Corner = (usize, usize, usize);

/// The index of a missing texture coordinate or normal in a `Corner`.
const NONE: usize = usize::MAX;

/// A `Corner` index as an option.
fn some(index: usize) -> Option<usize> {
    (index != NONE).then_some(index)
}

/// A face's corner as parsed: the texture index is `Err` with the reason when the reference
/// cannot be used.
type ParsedCorner = (usize, Option<Result<usize, String>>, Option<usize>);

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
    let mut texcoords: Vec<DVec2> = Vec::new();
    // The first reason the texture coordinates cannot be used, and its line.
    let mut uv_problem: Option<(usize, String)> = None;
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
            b"vt" => {
                // u, then v (0 when missing, as the OBJ format has it), then an ignored w.
                let mut uv = [0.0f64; 2];
                let mut problem = None;
                for (k, c) in uv.iter_mut().enumerate() {
                    match tokens.next() {
                        Some(token) => match number(token) {
                            Some(x) if x.is_finite() => *c = x,
                            _ => {
                                problem = Some(format!(
                                    "texture coordinate \"{}\" is not a finite number",
                                    echo_token(token)
                                ))
                            }
                        },
                        None if k == 0 => problem = Some("`vt` needs a number".into()),
                        None => {}
                    }
                }
                if let Some(problem) = problem
                    && uv_problem.is_none()
                {
                    uv_problem = Some((line, problem));
                }
                texcoords.push(DVec2::from_array(uv));
            }
            b"f" => {
                let mut corners = Vec::new();
                for token in tokens {
                    let (p, t, n) =
                        corner(token, positions.len(), texcoords.len(), file_normals.len())
                            .map_err(|what| {
                                at(
                                    line,
                                    format!("face vertex \"{}\": {what}", echo_token(token)),
                                )
                            })?;
                    let t = t.map_or(NONE, |t| {
                        t.unwrap_or_else(|problem| {
                            uv_problem.get_or_insert((line, problem));
                            NONE
                        })
                    });
                    corners.push((p, t, n.unwrap_or(NONE)));
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

    // Texture references are checked against the whole file, as positions are (a face may use
    // a `vt` defined after it); the first unusable one drops the uvs.
    if uv_problem.is_none()
        && let Some((line, t)) = faces.iter().find_map(|(line, corners)| {
            corners.iter().find_map(|&(_, t, _)| {
                some(t)
                    .filter(|&t| t >= texcoords.len())
                    .map(|t| (*line, t))
            })
        })
    {
        uv_problem = Some((
            line,
            format!(
                "a face refers to texture coordinate {} but the file has {}",
                t + 1,
                texcoords.len()
            ),
        ));
    }
    let with_uvs = uv_problem.is_none()
        && faces
            .iter()
            .any(|(_, corners)| corners.iter().any(|&(_, t, _)| t != NONE));

    // One vertex per distinct (position, texture, normal) triple, as tobj's `single_index`
    // makes them (the texture index only counts when the uvs are kept).
    let mut mesh = Mesh::default();
    let mut normals: Vec<DVec3> = Vec::new();
    let mut uvs: Vec<DVec2> = Vec::new();
    let mut any_normals = false;
    let mut vertex_of: HashMap<Corner, u32> = HashMap::new();
    let mut polygon: Vec<u32> = Vec::new();
    for (line, corners) in &faces {
        polygon.clear();
        for &(p, t, n) in corners {
            // The texture index only tells vertices apart when the uvs are kept.
            let t = if with_uvs { t } else { NONE };
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
            if let Some(n) = some(n)
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
            let v = *vertex_of.entry((p, t, n)).or_insert_with(|| {
                mesh.positions.push(positions[p]);
                let normal = some(n).and_then(|n| file_normals[n]);
                any_normals |= normal.is_some();
                normals.push(normal.unwrap_or(DVec3::ZERO));
                if with_uvs {
                    uvs.push(some(t).map_or(DVec2::ZERO, |t| texcoords[t]));
                }
                next
            });
            polygon.push(v);
        }
        triangulate(&polygon, &mut mesh.triangles);
    }
    mesh.uvs = with_uvs.then_some(uvs);
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
    if let Some((line, problem)) = uv_problem {
        warnings.push(format!(
            "mesh file {name} line {line}: {problem}: the mesh's texture coordinates are dropped"
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
fn corner(
    token: &[u8],
    positions: usize,
    texcoords: usize,
    normals: usize,
) -> Result<ParsedCorner, String> {
    let mut parts = token.split(|&b| b == b'/');
    let p = parts.next().unwrap_or_default();
    let t = parts.next().filter(|t| !t.is_empty());
    let n = parts.next().filter(|n| !n.is_empty());
    if parts.next().is_some() {
        return Err("more than three indices".into());
    }
    let p = resolve(p, positions)?;
    // A bad texture reference only costs the mesh its uvs (see the module comment).
    let t = t.map(|t| {
        resolve(t, texcoords).map_err(|what| {
            format!(
                "face vertex \"{}\": texture coordinate {what}",
                echo_token(token)
            )
        })
    });
    let n = n.map(|n| resolve(n, normals)).transpose()?;
    Ok((p, t, n))
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

    const TRIANGLE: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

    fn uvs(m: &MeshFile) -> Vec<[f64; 2]> {
        m.mesh
            .uvs
            .as_ref()
            .unwrap()
            .iter()
            .map(|uv| uv.to_array())
            .collect()
    }

    #[test]
    fn texture_coordinates_are_read_unflipped() {
        let text = format!("{TRIANGLE}vt 0.25 0.75\nvt 1 0 0.5\nvt 0.5\nf 1/1 2/2 3/3\n");
        let m = parse_obj("m.obj", text.as_bytes()).unwrap();
        assert!(m.warnings.is_empty(), "{:?}", m.warnings);
        assert_eq!(uvs(&m), vec![[0.25, 0.75], [1.0, 0.0], [0.5, 0.0]]);
        // Relative references, and Mitsuba's flip.
        let text = format!("{TRIANGLE}vt 0.25 0.75\nvt 1 0\nvt 0.5 1\nf 1/-3 2/-2 3/-1/\n");
        let mut m = parse_obj("m.obj", text.as_bytes()).unwrap();
        assert_eq!(uvs(&m), vec![[0.25, 0.75], [1.0, 0.0], [0.5, 1.0]]);
        m.mesh.flip_tex_coords();
        assert_eq!(uvs(&m), vec![[0.25, 0.25], [1.0, 1.0], [0.5, 0.0]]);
        // No `vt` references: no uvs.
        let m = parse_obj("m.obj", format!("{TRIANGLE}vt 1 1\nf 1 2 3\n").as_bytes()).unwrap();
        assert_eq!(m.mesh.uvs, None);
    }

    #[test]
    fn texture_coordinates_split_vertices() {
        // Vertex 1 with two different uvs becomes two vertices; a corner without one gets
        // (0, 0), as in Mitsuba.
        let text = format!("{TRIANGLE}v 1 1 0\nvt 0 0\nvt 1 1\nf 1/1 2/1 3/1\nf 1/2 4 2/1\n");
        let m = parse_obj("m.obj", text.as_bytes()).unwrap();
        assert_eq!(m.mesh.positions.len(), 5);
        assert_eq!(m.mesh.triangles, vec![[0, 1, 2], [3, 4, 1]]);
        assert_eq!(m.mesh.positions[3], m.mesh.positions[0]);
        assert_eq!(
            uvs(&m),
            vec![[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [1.0, 1.0], [0.0, 0.0]]
        );
    }

    #[test]
    fn unusable_texture_coordinates_are_dropped_with_a_warning() {
        let cases = [
            (
                "vt 0 0\nf 1/1 2/5 3/1\n",
                "line 5: a face refers to texture coordinate 5 but the file has 1",
            ),
            (
                "vt 0 0\nf 1/1 2/-3 3/1\n",
                "line 5: face vertex \"2/-3\": texture coordinate relative index -3",
            ),
            ("vt 0 0\nf 1/x 2/1 3/1\n", "texture coordinate not an index"),
            (
                "vt a 0\nf 1/1 2/1 3/1\n",
                "line 4: texture coordinate \"a\" is not a finite number",
            ),
            ("vt 0 nan\nf 1/1 2/1 3/1\n", "\"nan\" is not a finite"),
            ("vt\nf 1/1 2/1 3/1\n", "line 4: `vt` needs a number"),
            ("f 1/1 2/1 3/1\n", "texture coordinate 1 but the file has 0"),
        ];
        for (tail, phrase) in cases {
            let text = format!("{TRIANGLE}{tail}");
            let m = parse_obj("m.obj", text.as_bytes()).unwrap_or_else(|e| panic!("{tail}: {e}"));
            assert_eq!(m.mesh.uvs, None, "{tail}");
            assert_eq!(m.mesh.triangles, vec![[0, 1, 2]], "{tail}");
            assert_eq!(m.warnings.len(), 1, "{tail}");
            let w = &m.warnings[0];
            assert!(
                w.contains(phrase) && w.ends_with("texture coordinates are dropped"),
                "{w}"
            );
        }
    }

    /// Each triangle's corners as the renderer reads them: position and normal.
    fn corners(m: &MeshFile) -> Vec<[(DVec3, Option<DVec3>); 3]> {
        let normal = |i: u32| m.mesh.normals.as_ref().map(|n| n[i as usize]);
        m.mesh
            .triangles
            .iter()
            .map(|t| t.map(|i| (m.mesh.positions[i as usize], normal(i))))
            .collect()
    }

    #[test]
    fn texture_coordinates_leave_the_rendered_geometry_alone() {
        // The corpus files with `vt`, against the same files with the texture references
        // taken out: the triangles' positions and normals are the same.
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz/corpus/obj");
        for file in ["polygons.obj", "tetrahedron.obj"] {
            let text = std::fs::read_to_string(dir.join(file)).unwrap();
            let stripped: String = text
                .lines()
                .map(|line| match line.strip_prefix("f ") {
                    Some(face) => {
                        let corners: Vec<String> = face
                            .split_whitespace()
                            .map(|c| {
                                let parts: Vec<&str> = c.split('/').collect();
                                match parts.as_slice() {
                                    [p, _, n] => format!("{p}//{n}"),
                                    [p, ..] => p.to_string(),
                                    [] => String::new(),
                                }
                            })
                            .collect();
                        format!("f {}\n", corners.join(" "))
                    }
                    None => format!("{line}\n"),
                })
                .collect();
            let with = parse_obj(file, text.as_bytes()).unwrap();
            let without = parse_obj(file, stripped.as_bytes()).unwrap();
            assert!(
                with.mesh.uvs.is_some() && without.mesh.uvs.is_none(),
                "{file}"
            );
            assert_eq!(corners(&with), corners(&without), "{file}");
        }
    }
}
