//! Compares the shipped scenes with meshes written by an independent generator (one OBJ per
//! object plus an `objects.json` listing each object's material), triangle by triangle with
//! winding, material, emission and vertex normals.
//!
//! Skipped unless STAGELIGHT_REFERENCE_MESHES names the generator's output directory (with one
//! sub-directory per scene), e.g.
//!   python3 gen_meshes.py /tmp/meshes && STAGELIGHT_REFERENCE_MESHES=/tmp/meshes cargo test --test scene_crosscheck

use glam::Vec3;
use stagelight::bsdf::Material;
use stagelight::bsdf::conductor::Conductor;
use stagelight::bsdf::dielectric::Dielectric;
use stagelight::bsdf::diffuse::Diffuse;
use stagelight::scene::{self, FLAT, NO_EMITTER, PreparedScene};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// What a reference material name means: the material and the radiance, if it emits.
fn expected_material(scene: &str, name: &str) -> (Material, Option<Vec3>) {
    let diffuse = |r, g, b| {
        Material::Diffuse(Diffuse {
            reflectance: Vec3::new(r, g, b),
        })
    };
    let black = diffuse(0.0, 0.0, 0.0);
    match (scene, name) {
        ("cornell_box", "white") => (diffuse(0.725, 0.71, 0.68), None),
        ("cornell_box", "red") => (diffuse(0.63, 0.065, 0.05), None),
        ("cornell_box", "green") => (diffuse(0.14, 0.45, 0.091), None),
        ("cornell_box", "light") => (black, Some(Vec3::new(17.0, 12.0, 4.0))),
        ("torus_glass", "floor") => (diffuse(0.5, 0.5, 0.5), None),
        ("torus_glass", "glass") => (Material::Dielectric(Dielectric { ior: 1.5 }), None),
        ("torus_glass", "torus") => (diffuse(0.8, 0.5, 0.2), None),
        ("torus_glass", "light") => (black, Some(Vec3::splat(200.0))),
        ("door_ajar", "wall") => (diffuse(0.75, 0.75, 0.75), None),
        ("door_ajar", "floor") => (diffuse(0.45, 0.40, 0.35), None),
        ("door_ajar", "door") => (diffuse(0.6, 0.5, 0.4), None),
        ("door_ajar", "table") => (diffuse(0.4, 0.25, 0.15), None),
        ("door_ajar", "glass") => (Material::Dielectric(Dielectric { ior: 1.5 }), None),
        ("door_ajar", "metal") => (
            Material::Conductor(Conductor::ggx(0.1, Vec3::new(1.0, 0.78, 0.34))),
            None,
        ),
        ("door_ajar", "light") => (black, Some(Vec3::new(400.0, 360.0, 300.0))),
        ("furnace", "furnace") => (diffuse(0.5, 0.5, 0.5), Some(Vec3::ONE)),
        _ => panic!("{scene}: no expectation for material {name}"),
    }
}

struct RefTriangle {
    p: [Vec3; 3],
    n: Option<[Vec3; 3]>,
    material: Material,
    emission: Option<Vec3>,
    object: String,
}

fn reference_triangles(dir: &Path, scene: &str) -> Vec<RefTriangle> {
    let listing = std::fs::read_to_string(dir.join("objects.json")).unwrap();
    // JSON objects of strings, numbers and booleans are valid RON.
    let objects: BTreeMap<String, BTreeMap<String, ron::Value>> = ron::from_str(&listing).unwrap();
    let mut out = Vec::new();
    for (name, fields) in objects {
        let field = |k: &str| match fields.get(k) {
            Some(ron::Value::String(s)) => s.clone(),
            other => panic!("{name}: field {k} is {other:?}"),
        };
        let (material, emission) = expected_material(scene, &field("material"));
        let options = tobj::LoadOptions {
            single_index: true,
            ..Default::default()
        };
        let (models, _) = tobj::load_obj(dir.join(field("obj")), &options).unwrap();
        for model in models {
            let m = &model.mesh;
            let vertex = |v: &[f32], i: u32| {
                Vec3::new(
                    v[3 * i as usize],
                    v[3 * i as usize + 1],
                    v[3 * i as usize + 2],
                )
            };
            for f in m.indices.chunks_exact(3) {
                out.push(RefTriangle {
                    p: [0, 1, 2].map(|k| vertex(&m.positions, f[k])),
                    n: (!m.normals.is_empty()).then(|| [0, 1, 2].map(|k| vertex(&m.normals, f[k]))),
                    material,
                    emission,
                    object: name.clone(),
                });
            }
        }
    }
    out
}

/// Matches every reference triangle to one prepared triangle with the same vertices in the
/// same cyclic order (so the same winding); returns a list of differences.
fn compare(scene_name: &str, s: &PreparedScene, reference: &[RefTriangle]) -> Vec<String> {
    let t = &s.triangles;
    let extent = (s.bounds_max - s.bounds_min).max_element();
    let tol = 2e-6 * extent;
    let cell = 1e-3 * extent;
    let key = |c: Vec3| (c / cell).floor().as_ivec3();
    let mut grid: HashMap<glam::IVec3, Vec<usize>> = HashMap::new();
    for i in 0..t.len() {
        grid.entry(key((t.p0[i] + t.p1[i] + t.p2[i]) / 3.0))
            .or_default()
            .push(i);
    }
    let mut used = vec![false; t.len()];
    let mut problems = Vec::new();
    for r in reference {
        let k = key((r.p[0] + r.p[1] + r.p[2]) / 3.0);
        let mut found = None;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(ids) = grid.get(&(k + glam::IVec3::new(dx, dy, dz))) else {
                        continue;
                    };
                    for &i in ids.iter().filter(|&&i| !used[i]) {
                        let mine = [t.p0[i], t.p1[i], t.p2[i]];
                        for rot in 0..3 {
                            if (0..3).all(|v| (mine[(v + rot) % 3] - r.p[v]).length() <= tol) {
                                found = Some((i, rot));
                                break 'search;
                            }
                        }
                    }
                }
            }
        }
        let Some((i, rot)) = found else {
            let reversed = [t.p0.clone(), t.p1.clone(), t.p2.clone()];
            let flipped = (0..t.len()).any(|i| {
                let mine = [reversed[0][i], reversed[2][i], reversed[1][i]];
                (0..3).any(|rot| (0..3).all(|v| (mine[(v + rot) % 3] - r.p[v]).length() <= tol))
            });
            problems.push(format!(
                "{scene_name}/{}: triangle {:?} {}",
                r.object,
                r.p,
                if flipped {
                    "has the opposite winding"
                } else {
                    "is missing"
                }
            ));
            continue;
        };
        used[i] = true;
        if s.materials[t.material[i] as usize] != r.material {
            problems.push(format!("{scene_name}/{}: material differs", r.object));
        }
        let emission =
            (t.emitter[i] != NO_EMITTER).then(|| s.emitters.radiance[t.emitter[i] as usize]);
        if emission != r.emission {
            problems.push(format!(
                "{scene_name}/{}: emission {emission:?} != {:?}",
                r.object, r.emission
            ));
        }
        match (r.n, t.smooth[i]) {
            (None, FLAT) => {}
            (Some(rn), smooth) if smooth != FLAT => {
                let n = t.vertex_normals[smooth as usize];
                if !(0..3).all(|v| (n[(v + rot) % 3] - rn[v].normalize()).length() <= 1e-4) {
                    problems.push(format!("{scene_name}/{}: vertex normals differ", r.object));
                }
            }
            _ => problems.push(format!("{scene_name}/{}: smooth/flat differs", r.object)),
        }
    }
    let extra = used.iter().filter(|u| !**u).count();
    if extra > 0 {
        problems.push(format!(
            "{scene_name}: {extra} triangles not in the reference"
        ));
    }
    problems
}

#[test]
fn shipped_scenes_match_the_reference_meshes() {
    let Some(root) = std::env::var_os("STAGELIGHT_REFERENCE_MESHES") else {
        eprintln!("skipped: STAGELIGHT_REFERENCE_MESHES is not set");
        return;
    };
    let root = Path::new(&root);
    let mut problems = Vec::new();
    for name in ["cornell_box", "torus_glass", "door_ajar", "furnace"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("scenes/{name}.ron"));
        let s = scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let reference = reference_triangles(&root.join(name), name);
        assert_eq!(s.triangles.len(), reference.len(), "{name}: triangle count");
        let found = compare(name, &s, &reference);
        eprintln!(
            "{name}: {} triangles, {} differences",
            reference.len(),
            found.len()
        );
        problems.extend(found);
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
