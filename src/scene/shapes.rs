//! Triangle meshes of the scene's shapes, in object space and double precision (the transforms
//! are applied in double too, and only the final positions are rounded to f32).
//!
//! Windings follow SCENES.md: counter-clockwise seen from the side the normal points to.

use glam::{DVec2, DVec3};
use std::collections::HashMap;
use std::f64::consts::TAU;
use std::path::Path;

/// An indexed triangle mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
    /// Per-vertex shading normals (same indexing as `positions`), or `None` for flat shading.
    /// A zero normal marks a vertex without one: its triangles are shaded flat.
    pub normals: Option<Vec<DVec3>>,
    /// Per-vertex texture coordinates (same indexing as `positions`), or `None` when the
    /// source has none. Kept for the Mitsuba reader's textures; the renderer does not read
    /// them yet. They are the values as the source holds them: an OBJ file's `vt` are NOT
    /// flipped here, while Mitsuba's `obj` plugin flips v by default (`flip_tex_coords`), so
    /// a caller that wants Mitsuba's uvs calls `flip_tex_coords` on an OBJ mesh.
    pub uvs: Option<Vec<DVec2>>,
}

impl Mesh {
    /// Replaces every texture coordinate (u, v) by (u, 1 - v): Mitsuba's `flip_tex_coords`,
    /// on by default for its OBJ reader (OBJ's v axis points up an image, Mitsuba's down).
    pub fn flip_tex_coords(&mut self) {
        for uv in self.uvs.iter_mut().flatten() {
            uv.y = 1.0 - uv.y;
        }
    }

    /// Appends the quad (a, b, c, d) as the triangles (a, b, c) and (a, c, d).
    fn push_quad(&mut self, corners: [DVec3; 4]) {
        let o = self.positions.len() as u32;
        self.positions.extend(corners);
        self.triangles.push([o, o + 1, o + 2]);
        self.triangles.push([o, o + 2, o + 3]);
    }
}

/// File normals made unit, each unusable one (infinite, NaN or zero) replaced by zero (its
/// faces are then shaded flat); with the count of unusable ones, for the reader's warning.
pub fn usable_normals(normals: impl Iterator<Item = DVec3>) -> (Vec<DVec3>, usize) {
    let mut bad = 0usize;
    let normals = normals
        .map(|n| {
            n.is_finite()
                .then(|| n.try_normalize())
                .flatten()
                .unwrap_or_else(|| {
                    bad += 1;
                    DVec3::ZERO
                })
        })
        .collect();
    (normals, bad)
}

pub fn quad(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> Mesh {
    let mut mesh = Mesh::default();
    mesh.push_quad([a, b, c, d]);
    mesh
}

pub fn triangle(a: DVec3, b: DVec3, c: DVec3) -> Mesh {
    Mesh {
        positions: vec![a, b, c],
        triangles: vec![[0, 1, 2]],
        normals: None,
        uvs: None,
    }
}

/// A closed axis-aligned box: 6 quads, 12 triangles, normals outward.
pub fn cuboid(min: DVec3, max: DVec3) -> Mesh {
    let (x0, y0, z0) = (min.x, min.y, min.z);
    let (x1, y1, z1) = (max.x, max.y, max.z);
    let v = DVec3::new;
    let mut mesh = Mesh::default();
    mesh.push_quad([v(x0, y0, z0), v(x1, y0, z0), v(x1, y0, z1), v(x0, y0, z1)]); // -y
    mesh.push_quad([v(x0, y1, z0), v(x0, y1, z1), v(x1, y1, z1), v(x1, y1, z0)]); // +y
    mesh.push_quad([v(x0, y0, z0), v(x0, y0, z1), v(x0, y1, z1), v(x0, y1, z0)]); // -x
    mesh.push_quad([v(x1, y0, z0), v(x1, y1, z0), v(x1, y1, z1), v(x1, y0, z1)]); // +x
    mesh.push_quad([v(x0, y0, z0), v(x0, y1, z0), v(x1, y1, z0), v(x1, y0, z0)]); // -z
    mesh.push_quad([v(x0, y0, z1), v(x1, y0, z1), v(x1, y1, z1), v(x0, y1, z1)]); // +z
    mesh
}

/// The unit icosphere of SCENES.md: the icosahedron with vertices (0, +-1, +-phi),
/// (+-1, +-phi, 0), (+-phi, 0, +-1) projected onto the sphere, each level splitting every
/// triangle into four through its edge midpoints, projected at once. `20 * 4^level` triangles,
/// normals outward; `smooth` adds vertex normals equal to the positions.
pub fn icosphere(level: u32, smooth: bool) -> Mesh {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let mut positions: Vec<DVec3> = [
        (-1.0, phi, 0.0),
        (1.0, phi, 0.0),
        (-1.0, -phi, 0.0),
        (1.0, -phi, 0.0),
        (0.0, -1.0, phi),
        (0.0, 1.0, phi),
        (0.0, -1.0, -phi),
        (0.0, 1.0, -phi),
        (phi, 0.0, -1.0),
        (phi, 0.0, 1.0),
        (-phi, 0.0, -1.0),
        (-phi, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        // Each edge is shared by two triangles: the cache gives both the same midpoint vertex.
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32| -> u32 {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let m = ((positions[a as usize] + positions[b as usize]) * 0.5).normalize();
                positions.push(m);
                positions.len() as u32 - 1
            })
        };
        triangles = triangles
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = (midpoint(a, b), midpoint(b, c), midpoint(c, a));
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    let normals = smooth.then(|| positions.clone());
    Mesh {
        positions,
        triangles,
        normals,
        uvs: None,
    }
}

/// The torus of SCENES.md around the y axis: vertex k(i, j) = i * nv + j at
/// ((R + r cos w) cos u, r sin w, (R + r cos w) sin u), u = 2 pi i / nu, w = 2 pi j / nv;
/// triangles (k(i,j), k(i,j1), k(i1,j1)) and (k(i,j), k(i1,j1), k(i1,j)). Flat.
pub fn torus(major_radius: f64, minor_radius: f64, nu: u32, nv: u32) -> Mesh {
    let mut positions = Vec::with_capacity((nu * nv) as usize);
    for i in 0..nu {
        let u = TAU * i as f64 / nu as f64;
        for j in 0..nv {
            let w = TAU * j as f64 / nv as f64;
            let ring = major_radius + minor_radius * w.cos();
            positions.push(DVec3::new(
                ring * u.cos(),
                minor_radius * w.sin(),
                ring * u.sin(),
            ));
        }
    }
    let k = |i: u32, j: u32| i * nv + j;
    let mut triangles = Vec::with_capacity((2 * nu * nv) as usize);
    for i in 0..nu {
        for j in 0..nv {
            let (i1, j1) = ((i + 1) % nu, (j + 1) % nv);
            triangles.push([k(i, j), k(i, j1), k(i1, j1)]);
            triangles.push([k(i, j), k(i1, j1), k(i1, j)]);
        }
    }
    Mesh {
        positions,
        triangles,
        normals: None,
        uvs: None,
    }
}

/// A mesh read from a file (OBJ, PLY), with warnings for the user.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshFile {
    pub mesh: Mesh,
    pub warnings: Vec<String>,
}

/// Opens a mesh file (`name` is the path as messages show it): a missing file, a folder, a
/// device or a pipe (/dev/zero, a FIFO: read forever) is an error naming it.
pub fn open_mesh_file(path: &Path, name: &str) -> Result<std::fs::File, String> {
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot read mesh file {name}: {e}"))?;
    if !meta.is_file() {
        return Err(format!("cannot read mesh file {name}: not a regular file"));
    }
    std::fs::File::open(path).map_err(|e| format!("cannot read mesh file {name}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_counts_and_closure() {
        for level in 0..4 {
            let m = icosphere(level, false);
            assert_eq!(m.triangles.len(), 20 * 4usize.pow(level));
            // Euler: V - E + F = 2 with E = 3F/2 for a closed triangle mesh.
            assert_eq!(m.positions.len(), 2 + m.triangles.len() / 2);
            for t in &m.triangles {
                let [a, b, c] = t.map(|i| m.positions[i as usize]);
                let n = (b - a).cross(c - a);
                assert!(n.dot(a + b + c) > 0.0, "outward winding");
            }
        }
    }

    #[test]
    fn box_normals_point_outward() {
        let m = cuboid(DVec3::new(-1.0, 0.0, -2.0), DVec3::new(1.0, 3.0, 2.0));
        let centre = DVec3::new(0.0, 1.5, 0.0);
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            assert!((b - a).cross(c - a).dot((a + b + c) / 3.0 - centre) > 0.0);
        }
    }

    #[test]
    fn torus_normals_point_outward() {
        let m = torus(0.6, 0.25, 16, 8);
        assert_eq!(m.triangles.len(), 2 * 16 * 8);
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let centroid = (a + b + c) / 3.0;
            // Nearest point of the tube's centre circle.
            let ring = DVec3::new(centroid.x, 0.0, centroid.z).normalize() * 0.6;
            assert!((b - a).cross(c - a).dot(centroid - ring) > 0.0);
        }
    }
}
