//! `stagelight rays` and `bench --rays`: the files hold the rays the render traced, read back
//! by a parser of NumPy's format written here (not the crate's), and `bench --rays` finds the
//! same hits as the render did on them.

use crate::common::{shrunk_scene, stagelight, stderr, temp_dir};
use stagelight::accel::Accel;
use stagelight::components::MISS;
use stagelight::integrators::SceneData;
use std::path::Path;
use std::sync::Arc;

/// A .npy file as read here: the header's dict text and the data bytes.
struct Npy {
    header: String,
    data: Vec<u8>,
}

/// Reads a version 1.0 .npy file, checking its magic and that the data starts at a multiple
/// of 16 bytes (NumPy's rule for readers that map the data).
fn read_npy(path: &Path) -> Npy {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..6], b"\x93NUMPY", "{}", path.display());
    assert_eq!(bytes[6..8], [1, 0], "version 1.0");
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    assert_eq!((10 + len) % 16, 0, "data aligned");
    let header = String::from_utf8(bytes[10..10 + len].to_vec()).unwrap();
    assert!(header.ends_with('\n'));
    Npy {
        header,
        data: bytes[10 + len..].to_vec(),
    }
}

fn f32_at(bytes: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

/// The rows of an (N, 8) float32 ray file.
fn read_rays(path: &Path) -> Vec<[f32; 8]> {
    let npy = read_npy(path);
    assert!(npy.header.contains("'descr': '<f4'"), "{}", npy.header);
    assert!(npy.header.contains("'fortran_order': False"));
    let shape = npy.header.split("'shape': (").nth(1).unwrap();
    let shape: Vec<usize> = shape[..shape.find(')').unwrap()]
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().unwrap())
        .collect();
    assert_eq!(shape.len(), 2);
    assert_eq!(shape[1], 8);
    assert_eq!(npy.data.len(), shape[0] * 32);
    (0..shape[0])
        .map(|r| std::array::from_fn(|k| f32_at(&npy.data, 32 * r + 4 * k)))
        .collect()
}

/// The (t, primitive) rows of hits.npy.
fn read_hits(path: &Path) -> Vec<(f32, u32)> {
    let npy = read_npy(path);
    assert!(
        npy.header
            .contains("'descr': [('t', '<f4'), ('primitive', '<u4')]"),
        "{}",
        npy.header
    );
    let n = npy.data.len() / 8;
    assert!(npy.header.contains(&format!("'shape': ({n},)")));
    (0..n)
        .map(|r| (f32_at(&npy.data, 8 * r), u32_at(&npy.data, 8 * r + 4)))
        .collect()
}

#[test]
fn written_rays_are_the_renders_and_bench_finds_its_hits() {
    let dir = temp_dir("rays");
    let scene = shrunk_scene("cornell_box", 24, &dir.join("cornell_box.ron"));
    let out = dir.join("rays");
    let o = stagelight(&[
        "rays",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--spp",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));

    // The same render in this process, with what its trace systems found.
    let data = Arc::new(SceneData::new(stagelight::scene::load(&scene).unwrap()));
    use stagelight::integrators::driver::IntegratorState;
    use stagelight::integrators::pt::{PtState, recording_graph};
    assert_eq!(
        recording_graph(&data).check(PtState::INPUTS),
        Vec::<String>::new()
    );
    let record = stagelight::commands::rays::record(data.clone(), 2, None);
    let closest = read_rays(&out.join("closest.npy"));
    let shadow = read_rays(&out.join("shadow.npy"));
    let rendered_closest: Vec<[f32; 8]> =
        record.closest.iter().flat_map(|b| b.rays.clone()).collect();
    let rendered_shadow: Vec<[f32; 8]> =
        record.shadow.iter().flat_map(|b| b.rays.clone()).collect();
    let bits =
        |rows: &[[f32; 8]]| -> Vec<[u32; 8]> { rows.iter().map(|r| r.map(f32::to_bits)).collect() };
    assert_eq!(bits(&closest), bits(&rendered_closest));
    assert_eq!(bits(&shadow), bits(&rendered_shadow));
    // 24 x 24 pixels, 2 samples: the camera's rays are bounce 0; paths go on bouncing.
    assert_eq!(record.closest[0].rays.len(), 24 * 24 * 2);
    assert!(record.closest.len() > 3 && !shadow.is_empty());

    // rays.json splits the files by bounce.
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("rays.json")).unwrap()).unwrap();
    let spans = index["closest"].as_array().unwrap();
    assert_eq!(spans.len(), record.closest.len());
    for (b, span) in spans.iter().enumerate() {
        assert_eq!(span["bounce"], b);
        assert_eq!(span["count"], record.closest[b].rays.len());
    }

    // mesh.ply: face i is triangle id i, at the scene's coordinates.
    let mesh = stagelight::scene::ply::load_ply(&out.join("mesh.ply"))
        .unwrap()
        .mesh;
    let t = &data.scene.triangles;
    assert_eq!(mesh.triangles.len(), t.len());
    for (i, f) in mesh.triangles.iter().enumerate() {
        let corners = f.map(|v| mesh.positions[v as usize].as_vec3());
        assert_eq!(corners, [t.p0[i], t.p1[i], t.p2[i]]);
    }

    let o = stagelight(&[
        "bench",
        "--rays",
        out.to_str().unwrap(),
        "--threads",
        "1",
        "--runs",
        "1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let hits = read_hits(&out.join("hits.npy"));
    assert_eq!(hits.len(), closest.len() + shadow.len());
    // Writing rays again into the folder drops the hits of the old ones.
    let o = stagelight(&[
        "rays",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--spp",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("hits.npy").exists());
    // Closest rays: the render's hits, bit for bit.
    let rendered_hits = record.closest.iter().flat_map(|b| b.hits.clone());
    let mut found = 0;
    for (i, (hit, rendered)) in hits.iter().zip(rendered_hits).enumerate() {
        assert_eq!(hit.1, rendered.triangle, "closest ray {i}");
        assert_eq!(hit.0.to_bits(), rendered.t.to_bits(), "closest ray {i}");
        found += (hit.1 != MISS) as usize;
    }
    assert!(found > 0 && found < closest.len(), "hits and misses both");
    // Shadow rays: occluded exactly where the render found them occluded, by a triangle the
    // ray really hits within its segment.
    let accel = Accel::build(t);
    let rendered_occluded = record.shadow.iter().flat_map(|b| b.occluded.clone());
    let mut occluded = 0;
    for (i, (hit, was)) in hits[closest.len()..]
        .iter()
        .zip(rendered_occluded)
        .enumerate()
    {
        assert_eq!(hit.1 != MISS, was, "shadow ray {i}");
        if was {
            occluded += 1;
            let r = shadow[i];
            let tri = [
                t.p0[hit.1 as usize],
                t.p1[hit.1 as usize],
                t.p2[hit.1 as usize],
            ];
            let o = glam::Vec3::new(r[0], r[1], r[2]);
            let d = glam::Vec3::new(r[4], r[5], r[6]);
            let single = stagelight::accel::intersect_triangle(o, d, &tri, r[7]);
            let single_t = single.expect("the occluder is hit").0;
            assert!((single_t - hit.0).abs() <= 1e-5 * hit.0, "shadow ray {i}");
            assert!(accel.any_hit(o, d, r[7]));
        }
    }
    assert!(occluded > 0 && occluded < shadow.len());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bounces_limit_and_bad_folders_are_clear_errors() {
    let dir = temp_dir("rays-errors");
    let scene = shrunk_scene("cornell_box", 8, &dir.join("cornell_box.ron"));
    let out = dir.join("rays");
    let o = stagelight(&[
        "rays",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--bounces",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("rays.json")).unwrap()).unwrap();
    assert_eq!(index["closest"].as_array().unwrap().len(), 2);
    let rows = read_rays(&out.join("closest.npy"));
    let count = |b: usize| index["closest"][b]["count"].as_u64().unwrap() as usize;
    assert_eq!(count(0), 8 * 8);
    assert_eq!(rows.len(), count(0) + count(1));

    let bench = |d: &Path| stagelight(&["bench", "--rays", d.to_str().unwrap(), "--runs", "1"]);
    let fails_with = |o: std::process::Output, words: &[&str]| {
        let e = stderr(&o);
        assert!(!o.status.success(), "should fail: {e}");
        assert!(!e.contains("panicked"), "{e}");
        for w in words {
            assert!(e.contains(w), "{w:?} not in {e}");
        }
    };
    fails_with(
        bench(&dir.join("missing")),
        &["missing", "not a folder of rays"],
    );

    // A closest.npy cut short, one with another row width, and one that is not .npy at all.
    let file = out.join("closest.npy");
    let good = std::fs::read(&file).unwrap();
    std::fs::write(&file, &good[..good.len() - 4]).unwrap();
    fails_with(bench(&out), &["closest.npy", "bytes of data"]);
    let mut narrow = good.clone();
    let at = narrow.windows(6).position(|w| w == b", 8), ").unwrap();
    narrow[at + 2] = b'7';
    std::fs::write(&file, &narrow).unwrap();
    fails_with(bench(&out), &["closest.npy", "expected (N, 8)"]);
    std::fs::write(&file, b"origin,dir\n").unwrap();
    fails_with(bench(&out), &["closest.npy", "not a NumPy .npy file"]);
    std::fs::write(&file, &good).unwrap();
    std::fs::remove_file(out.join("mesh.ply")).unwrap();
    fails_with(bench(&out), &["mesh.ply"]);
    let _ = std::fs::remove_dir_all(&dir);
}
