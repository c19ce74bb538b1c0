//! Loading the shipped scenes and the shapes, through the public API. Expected values come from
//! SCENES.md by hand, not from the code.

use crate::common::scene_path;
use glam::Vec3;
use stagelight::bsdf::conductor::Conductor;
use stagelight::bsdf::dielectric::Dielectric;
use stagelight::bsdf::diffuse::Diffuse;
use stagelight::bsdf::{Material, MaterialKind};
use stagelight::scene::{self, FLAT, NO_EMITTER, PreparedScene};
use std::collections::BTreeSet;
use std::f32::consts::PI;
use std::path::{Path, PathBuf};

fn load_shipped(name: &str) -> PreparedScene {
    let path = scene_path(name);
    scene::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Writes `text` as `name` in a fresh directory of its own under the temp dir.
fn temp_scene(test: &str, name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "stagelight_scene_loading_{test}_{}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn kinds(s: &PreparedScene) -> BTreeSet<MaterialKind> {
    s.materials.iter().map(Material::kind).collect()
}

fn assert_vec_near(a: Vec3, b: Vec3, tol: f32) {
    assert!((a - b).abs().max_element() <= tol, "{a} != {b}");
}

fn normal(s: &PreparedScene, t: usize) -> Vec3 {
    let tr = &s.triangles;
    (tr.p1[t] - tr.p0[t]).cross(tr.p2[t] - tr.p0[t]).normalize()
}

/// Checks the invariants every prepared scene keeps.
fn check_columns(s: &PreparedScene) {
    let t = &s.triangles;
    let n = t.len();
    for column in [
        t.p1.len(),
        t.p2.len(),
        t.material.len(),
        t.emitter.len(),
        t.smooth.len(),
    ] {
        assert_eq!(column, n);
    }
    for i in 0..n {
        assert!((t.material[i] as usize) < s.materials.len());
        if t.emitter[i] != NO_EMITTER {
            assert_eq!(s.emitters.triangle[t.emitter[i] as usize] as usize, i);
        }
        if t.smooth[i] != FLAT {
            for v in t.vertex_normals[t.smooth[i] as usize] {
                assert!((v.length() - 1.0).abs() < 1e-5);
            }
        }
        assert!(t.p0[i].is_finite() && t.p1[i].is_finite() && t.p2[i].is_finite());
    }
    let e = &s.emitters;
    assert_eq!(e.pmf.len(), e.triangle.len());
    assert_eq!(e.cdf.len(), e.triangle.len());
    if !e.pmf.is_empty() {
        let sum: f32 = e.pmf.iter().sum();
        assert!((sum - 1.0).abs() < 1e-5, "pmf sums to {sum}");
        assert_eq!(*e.cdf.last().unwrap(), 1.0);
        assert!(e.cdf.windows(2).all(|w| w[0] <= w[1]));
    }
}

#[test]
fn cornell_box() {
    let s = load_shipped("cornell_box.ron");
    check_columns(&s);
    assert_eq!(s.triangles.len(), 32);
    assert_eq!(s.emitters.triangle.len(), 2);
    assert_vec_near(s.bounds_min, Vec3::ZERO, 0.0);
    assert_vec_near(s.bounds_max, Vec3::new(556.0, 548.8, 559.2), 1e-4);
    assert_eq!(kinds(&s), BTreeSet::from([MaterialKind::Diffuse]));
    // white, red, green and the light's black.
    assert_eq!(s.materials.len(), 4);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);

    // The light: 130 x 105 mm, radiance (17, 12, 4), facing down.
    let area = (343.0 - 213.0) * (332.0 - 227.0);
    let total_area: f32 = s.emitters.area.iter().sum();
    assert!((total_area - area).abs() < 1e-2, "{total_area}");
    assert_vec_near(
        s.emitters.total_power,
        PI * area * Vec3::new(17.0, 12.0, 4.0),
        1.0,
    );
    for (&t, &l) in s.emitters.triangle.iter().zip(&s.emitters.radiance) {
        assert_vec_near(normal(&s, t as usize), -Vec3::Y, 1e-6);
        assert_eq!(l, Vec3::new(17.0, 12.0, 4.0));
        assert_eq!(
            s.materials[s.triangles.material[t as usize] as usize],
            Material::Diffuse(Diffuse {
                reflectance: Vec3::ZERO
            })
        );
    }
    // Two equal halves: equal probabilities.
    assert!((s.emitters.pmf[0] - 0.5).abs() < 1e-6);

    // Camera: forward +z, right is forward x up = -x (the red wall, at x = 556, on the left).
    let c = s.camera;
    assert_eq!(c.position, Vec3::new(278.0, 273.0, -800.0));
    assert_vec_near(c.forward, Vec3::Z, 1e-6);
    assert_vec_near(c.right, -Vec3::X, 1e-6);
    assert_vec_near(c.up, Vec3::Y, 1e-6);
    assert_eq!((c.width, c.height), (256, 256));
    assert!((c.fov_y_degrees - 39.3077).abs() < 1e-5);
}

#[test]
fn torus_glass() {
    let s = load_shipped("torus_glass.ron");
    check_columns(&s);
    // floor 2 + glass box 12 + torus 2 * 64 * 32 + light 2.
    assert_eq!(s.triangles.len(), 2 + 12 + 4096 + 2);
    assert_eq!(s.emitters.triangle.len(), 2);
    assert_vec_near(s.bounds_min, Vec3::new(-6.0, 0.0, -6.0), 1e-6);
    assert_vec_near(s.bounds_max, Vec3::new(6.0, 6.0, 6.0), 1e-6);
    assert_eq!(
        kinds(&s),
        BTreeSet::from([MaterialKind::Diffuse, MaterialKind::Dielectric])
    );
    assert!(
        s.materials
            .contains(&Material::Dielectric(Dielectric { ior: 1.5 }))
    );
    for &t in &s.emitters.triangle {
        assert_vec_near(normal(&s, t as usize), -Vec3::Y, 1e-6);
    }
    assert_vec_near(s.emitters.total_power, PI * 0.25 * Vec3::splat(200.0), 1e-3);
    // Everything is flat-shaded.
    assert!(s.triangles.vertex_normals.is_empty());

    // The torus: every vertex at distance r = 0.25 from its centre circle (radius 0.6 in the
    // plane tilted 30 degrees about x, centred at (0, 1.01, 0)).
    let torus = s.materials.iter().position(|m| {
        *m == Material::Diffuse(Diffuse {
            reflectance: Vec3::new(0.8, 0.5, 0.2),
        })
    });
    let torus = torus.unwrap() as u32;
    let (sin, cos) = 30f32.to_radians().sin_cos();
    let axis = Vec3::new(0.0, cos, sin); // the rotated y axis
    let centre = Vec3::new(0.0, 1.01, 0.0);
    let mut count = 0;
    for i in 0..s.triangles.len() {
        if s.triangles.material[i] != torus {
            continue;
        }
        count += 1;
        let p = s.triangles.p0[i] - centre;
        let in_plane = p - axis * p.dot(axis);
        let tube = (p - in_plane.normalize() * 0.6).length();
        assert!((tube - 0.25).abs() < 1e-5, "{tube}");
    }
    assert_eq!(count, 4096);
}

#[test]
fn door_ajar() {
    let s = load_shipped("door_ajar.ron");
    check_columns(&s);
    // 13 wall/floor/ceiling quads, door, light, 5 boxes, two level-4 icospheres.
    let spheres = 2 * 5120;
    assert_eq!(s.triangles.len(), 2 * 13 + 2 + 2 + 5 * 12 + spheres);
    assert_eq!(s.emitters.triangle.len(), 2);
    assert_vec_near(s.bounds_min, Vec3::ZERO, 1e-6);
    assert_vec_near(s.bounds_max, Vec3::new(4.0, 2.6, 7.0), 1e-6);
    assert_eq!(
        kinds(&s),
        BTreeSet::from([
            MaterialKind::Diffuse,
            MaterialKind::Dielectric,
            MaterialKind::Conductor
        ])
    );
    assert!(s.materials.contains(&Material::Conductor(Conductor::ggx(
        0.1,
        Vec3::new(1.0, 0.78, 0.34)
    ))));
    for &t in &s.emitters.triangle {
        assert_vec_near(normal(&s, t as usize), -Vec3::Y, 1e-6);
    }
    assert_vec_near(
        s.emitters.total_power,
        PI * 1.0 * Vec3::new(400.0, 360.0, 300.0),
        1e-2,
    );
    // Only the spheres are smooth; their normals are (p - centre) / 0.15.
    assert_eq!(s.triangles.vertex_normals.len(), spheres);
    for i in 0..s.triangles.len() {
        let Some(&n) = s
            .triangles
            .vertex_normals
            .get(s.triangles.smooth[i] as usize)
        else {
            continue;
        };
        let p = s.triangles.p0[i];
        let centre = if p.x < 2.0 {
            Vec3::new(1.7, 0.9, 2.3)
        } else {
            Vec3::new(2.3, 0.9, 2.3)
        };
        assert!(((p - centre).length() - 0.15).abs() < 1e-6);
        assert_vec_near(n[0], (p - centre) / 0.15, 1e-4);
        // The geometric normal agrees with the shading normal's side (outward).
        assert!(normal(&s, i).dot(n[0]) > 0.9);
    }
    // The door's free edge, opened 15 degrees into room A (z < 4).
    let (sin, cos) = 15f32.to_radians().sin_cos();
    let free_edge = Vec3::new(1.5 + 0.9 * cos, 2.1, 4.0 - 0.9 * sin);
    let found = (0..s.triangles.len()).any(|i| {
        [s.triangles.p0[i], s.triangles.p1[i], s.triangles.p2[i]]
            .iter()
            .any(|p| (*p - free_edge).length() < 1e-5)
    });
    assert!(found, "no vertex at the door's free edge {free_edge}");
}

#[test]
fn furnace() {
    let s = load_shipped("furnace.ron");
    check_columns(&s);
    assert_eq!(s.triangles.len(), 20 * 4usize.pow(3));
    assert_eq!(s.emitters.triangle.len(), 1280);
    // A level >= 1 icosphere has vertices at (+-1, 0, 0), (0, +-1, 0), (0, 0, +-1).
    assert_vec_near(s.bounds_min, Vec3::splat(-1.0), 1e-6);
    assert_vec_near(s.bounds_max, Vec3::splat(1.0), 1e-6);
    assert_eq!(
        s.materials,
        vec![Material::Diffuse(Diffuse {
            reflectance: Vec3::splat(0.5)
        })]
    );
    assert!(s.triangles.vertex_normals.is_empty());
    // Every triangle faces inward (toward the camera at the centre) and emits (1, 1, 1).
    for i in 0..s.triangles.len() {
        let centroid = (s.triangles.p0[i] + s.triangles.p1[i] + s.triangles.p2[i]) / 3.0;
        assert!(normal(&s, i).dot(centroid) < 0.0);
        assert_ne!(s.triangles.emitter[i], NO_EMITTER);
    }
    assert!(s.emitters.radiance.iter().all(|&l| l == Vec3::ONE));
    // Total area is a little under the sphere's 4 pi.
    let area: f32 = s.emitters.area.iter().sum();
    assert!(area < 4.0 * PI && area > 0.98 * 4.0 * PI, "{area}");
    assert_vec_near(s.emitters.total_power, Vec3::splat(PI * area), 1e-3);
    let c = s.camera;
    assert_eq!(c.position, Vec3::ZERO);
    assert_vec_near(c.forward, Vec3::Z, 0.0);
    assert_eq!(c.fov_y_degrees, 90.0);
}

const CAMERA: &str = "camera: (position: (0, 0, -5), look_at: (0, 0, 0), fov: 40),";

#[test]
fn icosphere_and_torus_counts() {
    for (shape, count) in [
        ("Icosphere(level: 0)", 20),
        ("Icosphere(level: 1, smooth: true)", 80),
        ("Icosphere(level: 2)", 320),
        ("Icosphere(level: 4, smooth: true)", 5120),
        (
            "Torus(major_radius: 1, minor_radius: 0.5, nu: 3, nv: 3)",
            18,
        ),
        (
            "Torus(major_radius: 0.6, minor_radius: 0.25, nu: 64, nv: 32)",
            4096,
        ),
        (
            "Torus(major_radius: 2, minor_radius: 0.1, nu: 10, nv: 7)",
            140,
        ),
        ("Box(min: (0, 0, 0), max: (1, 2, 3))", 12),
        ("Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0))", 1),
    ] {
        let text = format!(
            "Scene({CAMERA} materials: {{\"m\": Diffuse(reflectance: (0.5, 0.5, 0.5))}},
             objects: [(shape: {shape}, material: \"m\")])"
        );
        let s = scene::load_from_str(Path::new("counts.ron"), &text)
            .unwrap_or_else(|e| panic!("{shape}: {e}"));
        assert_eq!(s.triangles.len(), count, "{shape}");
        check_columns(&s);
        // Closed shapes, outward normals: signed volume is positive.
        if !shape.starts_with("Triangle") {
            let volume: f32 = (0..s.triangles.len())
                .map(|i| s.triangles.p0[i].dot(s.triangles.p1[i].cross(s.triangles.p2[i])))
                .sum();
            assert!(volume > 0.0, "{shape}: volume {volume}");
        }
    }
}

#[test]
fn level_zero_icosphere_is_the_icosahedron_on_the_unit_sphere() {
    let text = format!(
        "Scene({CAMERA} materials: {{\"m\": Diffuse(reflectance: (0.5, 0.5, 0.5))}},
         objects: [(shape: Icosphere(level: 0, smooth: true), material: \"m\")])"
    );
    let s = scene::load_from_str(Path::new("ico.ron"), &text).unwrap();
    assert_eq!(s.triangles.len(), 20);
    let phi = (1.0 + 5f32.sqrt()) / 2.0;
    let norm = (1.0 + phi * phi).sqrt();
    let mut expected = Vec::new();
    for a in [-1.0, 1.0] {
        for b in [-phi, phi] {
            expected.push(Vec3::new(0.0, a, b) / norm);
            expected.push(Vec3::new(a, b, 0.0) / norm);
            expected.push(Vec3::new(b, 0.0, a) / norm);
        }
    }
    let t = &s.triangles;
    for (i, p) in t.p0.iter().chain(&t.p1).chain(&t.p2).enumerate() {
        assert!((p.length() - 1.0).abs() < 1e-6);
        assert!(expected.iter().any(|e| (*e - *p).length() < 1e-6), "{p}");
        // Smooth normals equal the positions on the unit sphere.
        let n = t.vertex_normals[t.smooth[i % 20] as usize][i / 20];
        assert_vec_near(n, *p, 1e-6);
    }
    // Every icosahedron edge has length 2 / norm.
    for i in 0..20 {
        for (a, b) in [(t.p0[i], t.p1[i]), (t.p1[i], t.p2[i]), (t.p2[i], t.p0[i])] {
            assert!(((a - b).length() - 2.0 / norm).abs() < 1e-6);
        }
    }
}

#[test]
fn transformed_box_bounds_and_mirroring() {
    let text = format!(
        "Scene({CAMERA} materials: {{\"m\": Diffuse(reflectance: (0.5, 0.5, 0.5))}},
         objects: [
           (shape: Box(min: (-1, -1, -1), max: (1, 1, 1)), material: \"m\",
            transform: [Scale((1, 2, 3)), Rotate(axis: (0, 0, 1), degrees: 90),
                        Translate((10, 0, 0))]),
           (shape: Box(min: (0, 0, 0), max: (1, 1, 1)), material: \"m\",
            transform: [Scale((-1, 1, 1)), Translate((0, 20, 0))]),
         ])"
    );
    let s = scene::load_from_str(Path::new("box.ron"), &text).unwrap();
    assert_eq!(s.triangles.len(), 24);
    // The first box, [-1,1] x [-2,2] x [-3,3] turned 90 degrees about z: x in [8, 12],
    // y in [-1, 1]; the second box is [-1, 0] x [20, 21] x [0, 1].
    assert_vec_near(s.bounds_min, Vec3::new(-1.0, -1.0, -3.0), 1e-5);
    assert_vec_near(s.bounds_max, Vec3::new(12.0, 21.0, 3.0), 1e-5);
    // Normals stay outward through the rotation and the mirror.
    for i in 0..24 {
        let centre = if i < 12 {
            Vec3::new(10.0, 0.0, 0.0)
        } else {
            Vec3::new(-0.5, 20.5, 0.5)
        };
        let centroid = (s.triangles.p0[i] + s.triangles.p1[i] + s.triangles.p2[i]) / 3.0;
        assert!(normal(&s, i).dot(centroid - centre) > 0.0, "triangle {i}");
    }
}

#[test]
fn obj_mesh_with_a_degenerate_face() {
    // A unit square in z = 0 (two triangles, normals +z) and one face whose vertices are
    // collinear; vertex normals given for every vertex.
    let obj = "\
# test mesh
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
vn 0 0 1
f 1//1 2//1 3//1
f 1//1 3//1 4//1
f 1//1 2//1 5//1
";
    let scene_text = format!(
        "Scene({CAMERA} materials: {{\"m\": Diffuse(reflectance: (0.5, 0.5, 0.5))}},
         objects: [(name: Some(\"thing\"), shape: Obj(\"meshes/square.obj\"), material: \"m\",
                    emission: Some((1, 2, 3)))])"
    );
    let path = temp_scene("obj", "scene.ron", &scene_text);
    let meshes = path.parent().unwrap().join("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    std::fs::write(meshes.join("square.obj"), obj).unwrap();

    let s = scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    check_columns(&s);
    assert_eq!(s.triangles.len(), 2);
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("zero-area"), "{}", s.warnings[0]);
    assert!(s.warnings[0].contains("thing"), "{}", s.warnings[0]);
    for i in 0..2 {
        assert_vec_near(normal(&s, i), Vec3::Z, 1e-6);
        let n = s.triangles.vertex_normals[s.triangles.smooth[i] as usize];
        assert_eq!(n, [Vec3::Z; 3]);
    }
    assert_eq!(s.emitters.triangle.len(), 2);
    assert!((s.emitters.area.iter().sum::<f32>() - 1.0).abs() < 1e-6);
    assert!(s.emitters.area.iter().all(|a| a.is_finite()));
    assert_vec_near(s.emitters.total_power, PI * Vec3::new(1.0, 2.0, 3.0), 1e-5);
    assert_vec_near(s.bounds_min, Vec3::ZERO, 0.0);
    assert_vec_near(s.bounds_max, Vec3::new(1.0, 1.0, 0.0), 0.0);
}

#[test]
fn obj_without_normals_is_flat() {
    let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";
    let scene_text = format!(
        "Scene({CAMERA} materials: {{\"m\": Diffuse(reflectance: (0.5, 0.5, 0.5))}},
         objects: [(shape: Obj(\"quad.obj\"), material: \"m\", flip_normals: true)])"
    );
    let path = temp_scene("obj_flat", "scene.ron", &scene_text);
    std::fs::write(path.parent().unwrap().join("quad.obj"), obj).unwrap();
    let s = scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    // The quad is triangulated; flip_normals turns it to face -z.
    assert_eq!(s.triangles.len(), 2);
    assert!(s.triangles.smooth.iter().all(|&i| i == FLAT));
    for i in 0..2 {
        assert_vec_near(normal(&s, i), -Vec3::Z, 1e-6);
    }
}

#[test]
fn camera_defaults_and_frame() {
    let text = "Scene(camera: (position: (1, 2, 3), look_at: (1, 2, 4), up: (0, 2, 0.5),
                       fov: 30, width: 640, height: 480),
                materials: {\"m\": Diffuse(reflectance: (1, 1, 1))},
                objects: [(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"m\")])";
    let s = scene::load_from_str(Path::new("camera.ron"), text).unwrap();
    let c = s.camera;
    assert_eq!((c.width, c.height), (640, 480));
    assert_vec_near(c.forward, Vec3::Z, 1e-6);
    // up is re-orthogonalised against forward.
    assert_vec_near(c.up, Vec3::Y, 1e-6);
    assert_vec_near(c.right, -Vec3::X, 1e-6);
    // No light: a warning, not an error.
    assert!(s.warnings.iter().any(|w| w.contains("emits")));
}

#[test]
fn file_extensions_apply_to_objects() {
    // With implicit_some, `emission: (1, 1, 1)` needs no `Some`, inside the objects too.
    let text = format!(
        "#![enable(implicit_some)]
         Scene({CAMERA} materials: {{\"m\": Diffuse(reflectance: (0.5, 0.5, 0.5))}},
         objects: [(name: \"lamp\", shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)),
                    material: \"m\", emission: (1, 1, 1))])"
    );
    let s = scene::load_from_str(Path::new("ext.ron"), &text).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.emitters.triangle.len(), 1);
    assert!((s.emitters.area[0] - 0.5).abs() < 1e-7);
}

/// A PLY file's shape equals the same shape written inline, through the same transforms: a
/// box as a binary big-endian PLY of 6 quads, and as `Box`, scaled, turned and mirrored.
#[test]
fn ply_mesh_transforms_as_inline_shapes_do() {
    // The 8 corners of [0,1]^3 and the 6 faces wound outward, as quads.
    let corners: Vec<[f32; 3]> = (0..8)
        .map(|k| [(k & 1) as f32, ((k >> 1) & 1) as f32, ((k >> 2) & 1) as f32])
        .collect();
    let faces: [[u32; 4]; 6] = [
        [0, 2, 3, 1], // z = 0, normal -z
        [4, 5, 7, 6], // z = 1
        [0, 1, 5, 4], // y = 0
        [2, 6, 7, 3], // y = 1
        [0, 4, 6, 2], // x = 0
        [1, 3, 7, 5], // x = 1
    ];
    let mut ply = String::from(
        "ply\nformat binary_big_endian 1.0\nelement vertex 8\nproperty float x\n\
         property float y\nproperty float z\nelement face 6\n\
         property list uchar int vertex_indices\nend_header\n",
    )
    .into_bytes();
    for c in &corners {
        for v in c {
            ply.extend(v.to_be_bytes());
        }
    }
    for f in &faces {
        ply.push(4);
        for i in f {
            ply.extend((*i as i32).to_be_bytes());
        }
    }
    let transform = "transform: [Scale((-1, 2, 3)), Rotate(axis: (1, 1, 0), degrees: 40), \
                     Translate((5, 0, 1))]";
    let scene_text = |shape: &str| {
        format!(
            "Scene({CAMERA} materials: {{\"m\": Diffuse(reflectance: (0.5, 0.5, 0.5))}},
             objects: [(shape: {shape}, material: \"m\", {transform})])"
        )
    };
    let path = temp_scene("ply", "scene.ron", &scene_text("Ply(\"meshes/box.ply\")"));
    let meshes = path.parent().unwrap().join("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    std::fs::write(meshes.join("box.ply"), &ply).unwrap();
    let from_ply = scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    let inline = scene::load_from_str(
        Path::new("inline.ron"),
        &scene_text("Box(min: (0, 0, 0), max: (1, 1, 1))"),
    )
    .unwrap();
    check_columns(&from_ply);
    assert_eq!(from_ply.triangles.len(), 12);
    assert_vec_near(from_ply.bounds_min, inline.bounds_min, 1e-6);
    assert_vec_near(from_ply.bounds_max, inline.bounds_max, 1e-6);
    // Every PLY triangle lies on a face of the inline box with the same outward normal.
    let centre = (inline.bounds_min + inline.bounds_max) / 2.0;
    for i in 0..12 {
        let centroid =
            (from_ply.triangles.p0[i] + from_ply.triangles.p1[i] + from_ply.triangles.p2[i]) / 3.0;
        assert!(
            normal(&from_ply, i).dot(centroid - centre) > 0.0,
            "triangle {i} faces inward"
        );
        let same_plane = (0..12).any(|j| {
            (normal(&inline, j) - normal(&from_ply, i)).length() < 1e-5
                && normal(&inline, j)
                    .dot(centroid - inline.triangles.p0[j])
                    .abs()
                    < 1e-5
        });
        assert!(same_plane, "triangle {i} is on no face of the inline box");
    }
    let area = |s: &PreparedScene| -> f32 {
        (0..s.triangles.len())
            .map(|i| {
                let t = &s.triangles;
                (t.p1[i] - t.p0[i]).cross(t.p2[i] - t.p0[i]).length() / 2.0
            })
            .sum()
    };
    assert!((area(&from_ply) - area(&inline)).abs() < 1e-4 * area(&inline));
}

/// The scenes `bench --big` writes load with the triangles they promise, in both renderers'
/// files (the Mitsuba scene names the same PLY files).
#[test]
fn generated_big_scenes_load() {
    use stagelight::commands::big_scenes::{BIG_SCENES, write_big_scene};
    let dir = crate::common::temp_dir("big-scenes");
    for size in &BIG_SCENES[..2] {
        let path = write_big_scene(&dir, size).unwrap();
        let s = scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
        check_columns(&s);
        assert_eq!(s.triangles.len() as u64, size.triangles(), "{}", size.name);
        assert!(s.warnings.is_empty(), "{:?}", s.warnings);
        // The box's light: 2 triangles of 130 x 105 mm emitting (17, 12, 4).
        assert_eq!(s.emitters.triangle.len(), 2);
        assert_vec_near(
            s.emitters.total_power,
            PI * 130.0 * 105.0 * Vec3::new(17.0, 12.0, 4.0),
            1.0,
        );
        // Everything inside the box (the torus dips 5 mm before its open front, z < 0).
        assert_vec_near(s.bounds_min, Vec3::new(0.0, 0.0, 0.0), 10.0);
        assert!(s.bounds_max.cmple(Vec3::new(556.0, 548.8, 559.2)).all());
        let xml = std::fs::read_to_string(path.with_extension("xml")).unwrap();
        let plys: Vec<&str> = xml.matches(".ply\"").collect();
        assert_eq!(
            plys.len(),
            std::fs::read_to_string(&path)
                .unwrap()
                .matches("Ply(")
                .count()
        );
        if size.sphere_level.is_some() {
            // The sphere is smooth-shaded (its PLY has normals), the torus flat.
            assert!(s.triangles.smooth.iter().any(|&i| i != FLAT));
            assert!(xml.contains("sphere.ply\"/><boolean name=\"face_normals\" value=\"false\""));
            assert!(xml.contains("torus.ply\"/><boolean name=\"face_normals\" value=\"true\""));
        }
    }
}
