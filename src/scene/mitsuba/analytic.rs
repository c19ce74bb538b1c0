//! Mitsuba's analytic shapes as triangle meshes in object space (before `to_world`), with
//! Mitsuba's uv parametrisations at the vertices: `rectangle`, `disk`, `cube`, `sphere` and
//! `cylinder` (src/shapes/*.cpp). Flat shapes are flat shaded (no vertex normals); the
//! sphere and the cylinder carry their exact analytic normals at the vertices. Windings are
//! counter-clockwise seen from the side the normal points to.
//!
//! Curved shapes are polygons of a slightly larger radius, scaled so that the mesh's area
//! equals the exact shape's: emitters then send the exact power, and the silhouette errors
//! (which a radius correction cannot cancel in every direction at once) stay small on both
//! sides. With the counts below, measured by the tests:
//!
//! | shape    | triangles | area error      | silhouette error (front-facing projected area) |
//! |----------|-----------|-----------------|------------------------------------------------|
//! | disk     | 96        | 0 (to rounding) | 0 (a flat polygon projects as its area)        |
//! | cylinder | 192       | 0 (to rounding) | -3.6e-4 to +1.8e-4 over 507 directions         |
//! | sphere   | 9024      | 0 (to rounding) | -3.1e-4 to +1.8e-4 over 507 directions         |
//!
//! Without the correction the same meshes are 1.8e-4 (cylinder) and 8.9e-4 (sphere) short in
//! area, and their silhouettes up to 5.3e-4 (cylinder) and 1.2e-3 (sphere, seen along the
//! poles) short.
//!
//! Seams and poles repeat vertices for the uvs, with positions computed from the same angle so
//! that neighbouring triangles share their edges exactly (no cracks for rays to slip through).

use crate::scene::shapes::Mesh;
use glam::{DVec2, DVec3};
use std::f64::consts::{PI, TAU};

/// Segments around the disk's rim and the cylinder.
pub const CIRCLE_SEGMENTS: u32 = 96;

/// Bands from pole to pole of the sphere (its latitude steps).
pub const SPHERE_BANDS: u32 = 48;

/// Segments around the sphere (its longitude steps).
pub const SPHERE_SEGMENTS: u32 = 96;

/// Mitsuba's `rectangle`: [-1, 1]^2 at z = 0, normal +z, uv = ((x + 1) / 2, (y + 1) / 2).
pub fn rectangle() -> Mesh {
    let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
    Mesh {
        positions: corners.map(|(x, y)| DVec3::new(x, y, 0.0)).to_vec(),
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        normals: None,
        uvs: Some(
            corners
                .map(|(x, y)| DVec2::new((x + 1.0) / 2.0, (y + 1.0) / 2.0))
                .to_vec(),
        ),
    }
}

/// Mitsuba's `disk`: the unit disk at z = 0, normal +z, as a fan of `CIRCLE_SEGMENTS`
/// triangles whose rim radius makes the area exactly pi. uv = (r, phi / 2 pi) as Mitsuba's
/// (phi from +x towards +y in [0, 2 pi)); the centre is repeated per triangle with the
/// triangle's middle angle (so v is exact along each triangle's middle and off by up to half
/// a segment, 1/192, along its edges), and the rim's first vertex is repeated with v = 1.
pub fn disk() -> Mesh {
    let n = CIRCLE_SEGMENTS;
    let step = TAU / f64::from(n);
    // A regular n-gon of circumradius k has area n k^2 sin(2 pi / n) / 2.
    let k = (TAU / (f64::from(n) * step.sin())).sqrt();
    let mut mesh = Mesh::default();
    let mut uvs = Vec::new();
    for j in 0..=n {
        let phi = step * f64::from(j % n);
        mesh.positions
            .push(DVec3::new(k * phi.cos(), k * phi.sin(), 0.0));
        uvs.push(DVec2::new(1.0, f64::from(j) / f64::from(n)));
    }
    for j in 0..n {
        let centre = mesh.positions.len() as u32;
        mesh.positions.push(DVec3::ZERO);
        uvs.push(DVec2::new(0.0, (f64::from(j) + 0.5) / f64::from(n)));
        mesh.triangles.push([centre, j, j + 1]);
    }
    mesh.uvs = Some(uvs);
    mesh
}

/// Mitsuba's `cube`: [-1, 1]^3, 24 vertices (four per face, for the face's uvs) and 12
/// triangles in Mitsuba's order, each face's uv square ((0, 1), (1, 1), (1, 0), (0, 0)) at its
/// four vertices; flat, normals outward.
pub fn cube() -> Mesh {
    // Each face's four corners: corner c is (+-1, +-1, +-1), bit k of c giving axis k's sign.
    // Faces -y, +y, +x, +z, -x, -z.
    const CORNERS: [u32; 24] = [
        1, 5, 4, 0, 3, 2, 6, 7, 1, 3, 7, 5, 5, 7, 6, 4, 4, 6, 2, 0, 3, 1, 0, 2,
    ];
    const FACE_UV: [(f64, f64); 4] = [(0.0, 1.0), (1.0, 1.0), (1.0, 0.0), (0.0, 0.0)];
    let sign = |c: u32, bit: u32| if c & bit != 0 { 1.0 } else { -1.0 };
    let positions = CORNERS
        .iter()
        .map(|&c| DVec3::new(sign(c, 1), sign(c, 2), sign(c, 4)))
        .collect();
    let uvs = (0..24).map(|v| DVec2::from(FACE_UV[v % 4])).collect();
    let triangles = (0..6u32)
        .flat_map(|s| {
            let v = 4 * s;
            [[v, v + 1, v + 2], [v + 3, v, v + 2]]
        })
        .collect();
    Mesh {
        positions,
        triangles,
        normals: None,
        uvs: Some(uvs),
    }
}

/// Mitsuba's `sphere` of `center` and `radius` (Mitsuba applies them before `to_world`): a
/// latitude-longitude mesh about the z axis, `SPHERE_BANDS` x `SPHERE_SEGMENTS` (9024
/// triangles), with the analytic normals and Mitsuba's uv = (phi / 2 pi, theta / pi), theta
/// from +z, phi from +x towards +y. The vertices sit on a sphere a little larger than
/// `radius` (by 4.5e-4) so that the mesh's area is exactly 4 pi radius^2.
pub fn sphere(center: DVec3, radius: f64) -> Result<Mesh, String> {
    if !center.is_finite() {
        return Err(format!("the sphere's center {center} is not finite"));
    }
    positive("sphere", radius)?;
    let (bands, segments) = (SPHERE_BANDS, SPHERE_SEGMENTS);
    // Unit directions and uvs, rows from the north pole: the poles have one vertex per
    // segment (uv at the segment's middle), the rings one per segment plus the seam's repeat.
    let mut directions = Vec::new();
    let mut uvs = Vec::new();
    let ring_start = |i: u32| segments + (i - 1) * (segments + 1);
    for j in 0..segments {
        directions.push(DVec3::Z);
        uvs.push(DVec2::new((f64::from(j) + 0.5) / f64::from(segments), 0.0));
    }
    for i in 1..bands {
        let theta = PI * f64::from(i) / f64::from(bands);
        for j in 0..=segments {
            let phi = TAU * f64::from(j % segments) / f64::from(segments);
            directions.push(DVec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ));
            uvs.push(DVec2::new(
                f64::from(j) / f64::from(segments),
                f64::from(i) / f64::from(bands),
            ));
        }
    }
    let south = ring_start(bands);
    for j in 0..segments {
        directions.push(DVec3::NEG_Z);
        uvs.push(DVec2::new((f64::from(j) + 0.5) / f64::from(segments), 1.0));
    }
    let mut triangles = Vec::with_capacity((2 * segments * (bands - 1)) as usize);
    for j in 0..segments {
        let below = ring_start(1) + j;
        triangles.push([j, below, below + 1]);
    }
    for i in 1..bands - 1 {
        for j in 0..segments {
            let (a, b) = (ring_start(i) + j, ring_start(i + 1) + j);
            triangles.push([a, b, b + 1]);
            triangles.push([a, b + 1, a + 1]);
        }
    }
    for j in 0..segments {
        let above = ring_start(bands - 1) + j;
        triangles.push([above, south + j, above + 1]);
    }
    let unit_area = area(&directions, &triangles);
    let scale = radius * (4.0 * PI / unit_area).sqrt();
    Ok(Mesh {
        positions: directions.iter().map(|&d| center + scale * d).collect(),
        triangles,
        normals: Some(directions),
        uvs: Some(uvs),
    })
}

/// Mitsuba's `cylinder` from `p0` to `p1` of `radius`: the open tube (no caps), one band of
/// 2 x `CIRCLE_SEGMENTS` triangles, with the analytic (radial) normals and Mitsuba's uv =
/// (phi / 2 pi, distance along the axis / length), phi measured in Mitsuba's frame of the
/// axis (`coordinate_system`). The rims' radius is a little larger than `radius` (by 1.8e-4)
/// so that the mesh's area is exactly 2 pi radius |p1 - p0|.
pub fn cylinder(p0: DVec3, p1: DVec3, radius: f64) -> Result<Mesh, String> {
    if !p0.is_finite() || !p1.is_finite() {
        return Err(format!("the cylinder's p0 {p0} or p1 {p1} is not finite"));
    }
    positive("cylinder", radius)?;
    let axis = p1 - p0;
    let Some(n) = axis.try_normalize() else {
        return Err(format!(
            "the cylinder's p0 and p1 are both {p0}: it has no length"
        ));
    };
    let (s, t) = coordinate_system(n);
    let segments = CIRCLE_SEGMENTS;
    let half = PI / f64::from(segments);
    // Each side of a regular n-gon of circumradius k is 2 k sin(pi / n) long.
    let rim = radius * half / half.sin();
    let mut mesh = Mesh::default();
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    for (end, base) in [(0.0, p0), (1.0, p1)] {
        for j in 0..=segments {
            let phi = TAU * f64::from(j % segments) / f64::from(segments);
            let radial = s * phi.cos() + t * phi.sin();
            mesh.positions.push(base + rim * radial);
            normals.push(radial);
            uvs.push(DVec2::new(f64::from(j) / f64::from(segments), end));
        }
    }
    let top = segments + 1;
    for j in 0..segments {
        mesh.triangles.push([j, j + 1, top + j + 1]);
        mesh.triangles.push([j, top + j + 1, top + j]);
    }
    mesh.normals = Some(normals);
    mesh.uvs = Some(uvs);
    Ok(mesh)
}

fn positive(shape: &str, radius: f64) -> Result<(), String> {
    if radius.is_finite() && radius > 0.0 {
        Ok(())
    } else {
        Err(format!(
            "the {shape}'s radius {radius} is not a positive number"
        ))
    }
}

/// Mitsuba's `coordinate_system` (Duff et al. 2017, "Building an Orthonormal Basis,
/// Revisited"): two unit vectors s, t with (s, t, n) right-handed, the frame that its
/// cylinder measures phi in.
fn coordinate_system(n: DVec3) -> (DVec3, DVec3) {
    // -0 counts as positive, as in Mitsuba's sign().
    let z = n.z + 0.0;
    let sign = if z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + z);
    let b = n.x * n.y * a;
    (
        DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        DVec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// The total area of the triangles.
fn area(positions: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            (b - a).cross(c - a).length() / 2.0
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// Directions to project along: the axes, diagonals and a spread of others (a golden
    /// spiral over the sphere).
    fn directions() -> Vec<DVec3> {
        let mut out: Vec<DVec3> = [
            (1.0, 0.0, 0.0),
            (0.0, 1.0, 0.0),
            (0.0, 0.0, 1.0),
            (1.0, 1.0, 0.0),
            (1.0, 0.0, 1.0),
            (1.0, 1.0, 1.0),
            (0.3, -0.2, 0.9),
        ]
        .iter()
        .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
        .collect();
        let n = 500;
        let golden = PI * (3.0 - 5f64.sqrt());
        for i in 0..n {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            out.push(DVec3::new(r * phi.cos(), r * phi.sin(), z));
        }
        out
    }

    /// Triangle area vectors (normal times area).
    fn area_vectors(mesh: &Mesh) -> Vec<DVec3> {
        mesh.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
                (b - a).cross(c - a) / 2.0
            })
            .collect()
    }

    fn mesh_area(mesh: &Mesh) -> f64 {
        area_vectors(mesh).iter().map(|v| v.length()).sum()
    }

    /// The projected area of the triangles facing `d`: for a closed convex mesh its
    /// silhouette's area, for an open tube that of its front half, for a flat shape its
    /// projection (when it faces d).
    fn front_projected(mesh: &Mesh, d: DVec3) -> f64 {
        area_vectors(mesh).iter().map(|v| v.dot(d).max(0.0)).sum()
    }

    /// The range of relative errors of the front projected area over `directions()`,
    /// against `exact(d)` (directions where it vanishes are skipped).
    fn silhouette_errors(mesh: &Mesh, exact: impl Fn(DVec3) -> f64) -> (f64, f64) {
        directions()
            .into_iter()
            .filter(|&d| exact(d) > 1e-6)
            .map(|d| front_projected(mesh, d) / exact(d) - 1.0)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), e| {
                (lo.min(e), hi.max(e))
            })
    }

    /// Every edge is shared by exactly two triangles, in opposite directions, when vertices
    /// are identified by their exact position: the mesh is closed and has no cracks.
    fn assert_closed(mesh: &Mesh) {
        let key = |i: u32| mesh.positions[i as usize].to_array().map(f64::to_bits);
        let mut edges: HashMap<_, i32> = HashMap::new();
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (key(t[k]), key(t[(k + 1) % 3]));
                if a != b {
                    *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
                }
            }
        }
        assert!(edges.values().all(|&count| count == 0), "open or cracked");
    }

    /// Where the ray o + s d (s > 0) first meets the mesh: the triangle and the barycentric
    /// coordinates of the second and third vertex (Moller-Trumbore).
    fn hit(mesh: &Mesh, o: DVec3, d: DVec3) -> Option<(usize, f64, f64)> {
        let mut best: Option<(f64, usize, f64, f64)> = None;
        for (k, t) in mesh.triangles.iter().enumerate() {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            let (e1, e2) = (b - a, c - a);
            let p = d.cross(e2);
            let det = e1.dot(p);
            if det.abs() < 1e-15 {
                continue;
            }
            let s = o - a;
            let u = s.dot(p) / det;
            let q = s.cross(e1);
            let v = d.dot(q) / det;
            let dist = e2.dot(q) / det;
            if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && dist > 0.0 && best.is_none_or(|b| dist < b.0)
            {
                best = Some((dist, k, u, v));
            }
        }
        best.map(|(_, k, u, v)| (k, u, v))
    }

    /// The mesh's interpolated uv where the ray meets it.
    fn uv_at(mesh: &Mesh, o: DVec3, d: DVec3) -> DVec2 {
        let (k, u, v) = hit(mesh, o, d).expect("the ray meets the mesh");
        let uvs = mesh.uvs.as_ref().unwrap();
        let [a, b, c] = mesh.triangles[k].map(|i| uvs[i as usize]);
        a * (1.0 - u - v) + b * u + c * v
    }

    #[test]
    fn analytic_rectangle_is_mitsubas() {
        let m = rectangle();
        assert_eq!(mesh_area(&m), 4.0);
        assert!(
            area_vectors(&m)
                .iter()
                .all(|v| v.z > 0.0 && v.x == 0.0 && v.y == 0.0)
        );
        // Mitsuba: uv (0.25, 0.75) is the point (-0.5, 0.5, 0).
        let uv = uv_at(&m, DVec3::new(-0.5, 0.5, 1.0), DVec3::NEG_Z);
        assert!((uv - DVec2::new(0.25, 0.75)).length() < 1e-12, "{uv}");
        let uv = uv_at(&m, DVec3::new(0.9, -0.2, 1.0), DVec3::NEG_Z);
        assert!((uv - DVec2::new(0.95, 0.4)).length() < 1e-12, "{uv}");
    }

    #[test]
    fn analytic_disk_area_and_silhouette() {
        let m = disk();
        assert_eq!(m.triangles.len(), CIRCLE_SEGMENTS as usize);
        assert!(
            ((mesh_area(&m)) / PI - 1.0).abs() < 1e-14,
            "{}",
            mesh_area(&m)
        );
        assert!(area_vectors(&m).iter().all(|v| v.z > 0.0));
        let (lo, hi) = silhouette_errors(&m, |d| PI * d.z.max(0.0));
        assert!(lo.abs() < 1e-14 && hi.abs() < 1e-14, "{lo} {hi}");
        // The rim stays within 0.1% of the unit circle, on both sides.
        for t in &m.triangles {
            let (a, b) = (m.positions[t[1] as usize], m.positions[t[2] as usize]);
            assert!(a.length() < 1.001 && ((a + b) / 2.0).length() > 0.999);
        }
        // Mitsuba's uv is (r, phi / 2 pi): exact along the middle of each fan triangle, where
        // the centre's v is taken; along the fan's edges v is off by up to half a segment.
        for (r, phi) in [(0.5, 24.5), (0.9, 60.5), (0.2, 95.5)] {
            let phi = phi * TAU / f64::from(CIRCLE_SEGMENTS);
            let p = DVec3::new(r * phi.cos(), r * phi.sin(), 1.0);
            let uv = uv_at(&m, p, DVec3::NEG_Z);
            assert!((uv - DVec2::new(r, phi / TAU)).length() < 1e-3, "{uv}");
        }
        let uv = uv_at(&m, DVec3::new(0.0, 0.5, 1.0), DVec3::NEG_Z);
        assert!((uv - DVec2::new(0.5, 0.25)).length() < 0.5 / f64::from(CIRCLE_SEGMENTS));
    }

    /// Mitsuba 3.9.1's cube (`mi.traverse`): vertex positions and faces.
    #[test]
    fn analytic_cube_is_mitsubas() {
        let m = cube();
        let mitsuba: [[f64; 3]; 24] = [
            [1., -1., -1.],
            [1., -1., 1.],
            [-1., -1., 1.],
            [-1., -1., -1.],
            [1., 1., -1.],
            [-1., 1., -1.],
            [-1., 1., 1.],
            [1., 1., 1.],
            [1., -1., -1.],
            [1., 1., -1.],
            [1., 1., 1.],
            [1., -1., 1.],
            [1., -1., 1.],
            [1., 1., 1.],
            [-1., 1., 1.],
            [-1., -1., 1.],
            [-1., -1., 1.],
            [-1., 1., 1.],
            [-1., 1., -1.],
            [-1., -1., -1.],
            [1., 1., -1.],
            [1., -1., -1.],
            [-1., -1., -1.],
            [-1., 1., -1.],
        ];
        let positions: Vec<[f64; 3]> = m.positions.iter().map(|p| p.to_array()).collect();
        assert_eq!(positions, mitsuba);
        assert_eq!(m.triangles[0], [0, 1, 2]);
        assert_eq!(m.triangles[1], [3, 0, 2]);
        assert_eq!(m.triangles[11], [23, 20, 22]);
        assert_eq!(m.uvs.as_ref().unwrap()[5], DVec2::new(1.0, 1.0));
        assert_eq!(mesh_area(&m), 24.0);
        assert_closed(&m);
        for (t, v) in m.triangles.iter().zip(area_vectors(&m)) {
            let centre = t.iter().map(|&i| m.positions[i as usize]).sum::<DVec3>();
            assert!(v.dot(centre) > 0.0, "outward");
        }
        let (lo, hi) = silhouette_errors(&m, |d| 4.0 * (d.x.abs() + d.y.abs() + d.z.abs()));
        assert!(lo.abs() < 1e-14 && hi.abs() < 1e-14, "{lo} {hi}");
    }

    #[test]
    fn analytic_sphere_area_silhouette_and_uv() {
        let (center, radius) = (DVec3::new(1.0, 2.0, 3.0), 0.5);
        let m = sphere(center, radius).unwrap();
        assert_eq!(m.triangles.len(), 9024);
        let exact = 4.0 * PI * radius * radius;
        let area_error = mesh_area(&m) / exact - 1.0;
        let (lo, hi) = silhouette_errors(&m, |_| PI * radius * radius);
        eprintln!("sphere: area error {area_error:.1e}, silhouette errors {lo:.2e} to {hi:.2e}");
        assert!(lo > -1e-3 && hi < 1e-3, "{lo} {hi}");
        assert!(area_error.abs() < 1e-12, "{area_error}");
        // The radius correction, as the doc comment states it.
        let k = (m.positions[SPHERE_SEGMENTS as usize] - center).length() / radius;
        eprintln!("sphere: vertices at {k} times the radius");
        assert!((k - 1.0 - 4.5e-4).abs() < 0.05e-4, "{k}");
        assert_closed(&m);
        let normals = m.normals.as_ref().unwrap();
        for (p, n) in m.positions.iter().zip(normals) {
            assert!((n.length() - 1.0).abs() < 1e-12);
            assert!(((*p - center).normalize() - *n).length() < 1e-12);
        }
        for (t, v) in m.triangles.iter().zip(area_vectors(&m)) {
            let centre = t.iter().map(|&i| m.positions[i as usize]).sum::<DVec3>() / 3.0;
            assert!(v.dot(centre - center) > 0.0, "outward");
        }
        // Mitsuba's uv where its rays meet the sphere at (theta, phi) (ray_intersect).
        for (theta, phi, want) in [
            (
                0.7,
                0.2,
                DVec2::new(0.03183092549443245, 0.2228168547153473),
            ),
            (2.5, 4.0, DVec2::new(0.6366196870803833, 0.7957746982574463)),
            (PI / 2.0, PI / 2.0, DVec2::new(0.25, 0.5)),
        ] {
            let dir = DVec3::new(
                theta.sin() * f64::cos(phi),
                theta.sin() * f64::sin(phi),
                theta.cos(),
            );
            let uv = uv_at(&m, center + 3.0 * dir, -dir);
            assert!((uv - want).length() < 1e-3, "{uv} vs {want}");
        }
    }

    #[test]
    fn analytic_cylinder_area_silhouette_and_uv() {
        let (p0, p1, radius) = (DVec3::new(1.0, 2.0, 3.0), DVec3::new(2.0, 0.0, 5.0), 0.5);
        let m = cylinder(p0, p1, radius).unwrap();
        assert_eq!(m.triangles.len(), 2 * CIRCLE_SEGMENTS as usize);
        let length = (p1 - p0).length();
        let axis = (p1 - p0) / length;
        let area_error = mesh_area(&m) / (TAU * radius * length) - 1.0;
        assert!(area_error.abs() < 1e-12, "{area_error}");
        // The front half of the tube projects to 2 r L sin(angle to the axis).
        let (lo, hi) = silhouette_errors(&m, |d| {
            2.0 * radius * length * (1.0 - d.dot(axis).powi(2)).max(0.0).sqrt()
        });
        eprintln!("cylinder: area error {area_error:.1e}, silhouette errors {lo:.2e} to {hi:.2e}");
        assert!(lo > -1e-3 && hi < 1e-3, "{lo} {hi}");
        // The outline of the solid cylinder (the tube with one end's rim polygon):
        // 2 r L sin(angle) + pi r^2 |cos(angle)|.
        let segments = CIRCLE_SEGMENTS as usize;
        let rim_area: f64 = (0..segments)
            .map(|j| {
                (m.positions[j] - p0)
                    .cross(m.positions[j + 1] - p0)
                    .length()
                    / 2.0
            })
            .sum();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for d in directions() {
            let cos = d.dot(axis).abs();
            let sin = (1.0 - cos * cos).max(0.0).sqrt();
            let mesh = front_projected(&m, d) + rim_area * cos;
            let error = mesh / (2.0 * radius * length * sin + PI * radius * radius * cos) - 1.0;
            (lo, hi) = (lo.min(error), hi.max(error));
        }
        eprintln!("cylinder: solid outline errors {lo:.2e} to {hi:.2e}");
        assert!(lo > -1e-3 && hi < 1e-3, "{lo} {hi}");
        let normals = m.normals.as_ref().unwrap();
        for (p, n) in m.positions.iter().zip(normals) {
            let radial = (*p - p0) - (*p - p0).dot(axis) * axis;
            assert!((radial.normalize() - *n).length() < 1e-12);
            assert!((radial.length() / radius - 1.0 - 1.8e-4).abs() < 0.05e-4);
        }
        for (t, v) in m.triangles.iter().zip(area_vectors(&m)) {
            let centre = t.iter().map(|&i| m.positions[i as usize]).sum::<DVec3>() / 3.0;
            let radial = (centre - p0) - (centre - p0).dot(axis) * axis;
            assert!(v.dot(radial) > 0.0, "outward");
        }
        // Mitsuba's uv where its rays meet this cylinder (ray_intersect, from outside
        // towards the axis), at the frame angle phi and height z.
        let (s, t) = (
            DVec3::new(0.93333334, 0.13333334, -0.33333334),
            DVec3::new(0.13333334, 0.73333335, 0.6666667),
        );
        for (phi, z, want) in [
            (
                PI / 2.0,
                0.5,
                DVec2::new(0.24999994039535522, 0.49999985098838806),
            ),
            (
                0.3,
                0.25,
                DVec2::new(0.04774642735719681, 0.2499999850988388),
            ),
            (5.0, 0.9, DVec2::new(0.7957747578620911, 0.8999999165534973)),
        ] {
            let radial = s * f64::cos(phi) + t * f64::sin(phi);
            let on_axis = p0 + (p1 - p0) * z;
            let uv = uv_at(&m, on_axis + 2.0 * radial, -radial);
            assert!((uv - want).length() < 1e-3, "{uv} vs {want}");
        }
    }

    /// Mitsuba's `Frame3f(n)` for these normals (its s and t).
    #[test]
    fn analytic_frames_are_mitsubas() {
        let cases = [
            ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
            ((0.0, 0.0, -1.0), (1.0, 0.0, 0.0), (0.0, -1.0, 0.0)),
            ((0.6, 0.0, 0.8), (0.79999995, 0.0, -0.6), (0.0, 1.0, 0.0)),
            (
                (0.36, -0.48, -0.8),
                (0.928, 0.09600001, 0.36),
                (-0.09600001, -0.872, 0.48),
            ),
            ((1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
        ];
        for (n, s, t) in cases {
            let n = DVec3::from(n);
            let (got_s, got_t) = coordinate_system(n);
            assert!((got_s - DVec3::from(s)).length() < 1e-6, "{n}: s {got_s}");
            assert!((got_t - DVec3::from(t)).length() < 1e-6, "{n}: t {got_t}");
            assert!((got_s.cross(got_t) - n).length() < 1e-12);
        }
    }

    #[test]
    fn analytic_bad_parameters_are_errors() {
        for r in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = sphere(DVec3::ZERO, r).unwrap_err();
            assert!(e.contains("radius"), "{e}");
            let e = cylinder(DVec3::ZERO, DVec3::Z, r).unwrap_err();
            assert!(e.contains("radius"), "{e}");
        }
        let e = sphere(DVec3::new(f64::INFINITY, 0.0, 0.0), 1.0).unwrap_err();
        assert!(e.contains("center"), "{e}");
        let e = cylinder(DVec3::ONE, DVec3::ONE, 1.0).unwrap_err();
        assert!(e.contains("no length"), "{e}");
        let e = cylinder(DVec3::ONE, DVec3::NAN, 1.0).unwrap_err();
        assert!(e.contains("not finite"), "{e}");
    }
}
