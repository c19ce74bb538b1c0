//! The fuzz targets, shared by the stable driver (`tests/it/fuzz.rs`, run by `cargo nextest
//! run`) and the cargo-fuzz entry points (`tests/fuzz/fuzz_targets/`, libFuzzer, nightly).
//!
//! Each takes arbitrary bytes and panics only when a property is broken: a panic inside
//! stagelight, an error message that is not one line naming the file, or a result that
//! breaks an invariant (a prepared scene whose light distribution does not match its lights,
//! an image whose size does not match its pixels, a checkpoint that does not read back as
//! written). Each returns a short signature of the outcome (the kind of error, or the kind of
//! success), which the stable driver uses to keep inputs that reach something new.

#![allow(dead_code)]

use stagelight::film::Image;
use stagelight::integrators::{Budget, Control, IntegratorKind, RenderSettings, SceneData};
use stagelight::reference::Checkpoint;
use stagelight::scene::{self, Limits, PreparedScene};
use stagelight::sysinfo::MemoryLimit;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Memory a fuzzed input may ask for: larger requests must be refused with a message.
const FUZZ_MEMORY: MemoryLimit = MemoryLimit {
    bytes: 64 << 20,
    source: "the fuzz target allows",
};

/// Checks an error message: one line, short, naming `file`. Returns its signature: the
/// message without the file, digits or quoted text.
fn check_message(message: &str, file: &str) -> String {
    assert!(
        !message.contains('\n'),
        "message on several lines: {message:?}"
    );
    assert!(
        message.len() <= 2500,
        "message of {} bytes: {}...",
        message.len(),
        &message[..200]
    );
    assert!(
        message.contains(file),
        "message does not name {file}: {message}"
    );
    signature(message)
}

/// A message's shape: digits, quoted parts and backquoted parts removed, at most 80
/// characters.
fn signature(message: &str) -> String {
    let mut out = String::new();
    let mut quoted = None;
    for c in message.chars() {
        match quoted {
            Some(q) if c == q => quoted = None,
            Some(_) => {}
            None if c == '"' || c == '`' || c == '\'' => quoted = Some(c),
            None if c.is_ascii_digit() => {}
            None => out.push(c),
        }
    }
    out.chars().take(80).collect()
}

/// A scene file: parsed, checked, prepared, its tree built and one pass of a tiny image
/// rendered with PT or BDPT (chosen by the input's length).
pub fn scene(data: &[u8]) -> String {
    // A folder that does not exist: relative mesh paths find nothing.
    let path = Path::new("/nonexistent-stagelight-fuzz/fuzz.ron");
    let limits = Limits {
        memory: Some(FUZZ_MEMORY),
    };
    let text = match scene::text_of(path, data) {
        Ok(text) => text,
        Err(e) => return check_message(&e.to_string(), "fuzz.ron"),
    };
    let mut prepared = match scene::load_from_str_with(path, text, &limits) {
        Ok(s) => s,
        Err(e) => return check_message(&e.to_string(), "fuzz.ron"),
    };
    check_prepared(&prepared);
    let (w, h) = (prepared.camera.width.min(8), prepared.camera.height.min(8));
    prepared.camera.resize(w, h);
    let lights = prepared.emitters.triangle.len();
    let data_arc = Arc::new(SceneData::new(prepared));
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    let kind = IntegratorKind::named(if data.len().is_multiple_of(2) {
        "pt"
    } else {
        "bdpt"
    });
    let settings = RenderSettings {
        max_depth: 8,
        ..RenderSettings::default()
    };
    let outcome = stagelight::integrators::render(
        kind,
        data_arc,
        &settings,
        Budget::SamplesPerPixel(1),
        &control,
    );
    let image = outcome.film.image();
    assert_eq!(image.pixels.len(), image.width * image.height);
    assert!(
        image.pixels.iter().all(|p| p.is_finite()),
        "the film holds a non-finite value"
    );
    format!("ok {kind} lights:{}", lights.min(3))
}

/// A Mitsuba scene file: read, interpreted, prepared, its tree built and one pass of a tiny
/// image rendered with PT.
pub fn mitsuba(data: &[u8]) -> String {
    let path = Path::new("/nonexistent-stagelight-fuzz/fuzz.xml");
    let limits = Limits {
        memory: Some(FUZZ_MEMORY),
    };
    let text = match scene::text_of(path, data) {
        Ok(text) => text,
        Err(e) => return check_message(&e.to_string(), "fuzz.xml"),
    };
    let mut prepared = match scene::load_mitsuba_from_str(path, text, &[], &limits) {
        Ok((s, _)) => s,
        Err(e) => return check_message(&e.to_string(), "fuzz.xml"),
    };
    check_prepared(&prepared);
    let (w, h) = (prepared.camera.width.min(8), prepared.camera.height.min(8));
    prepared.camera.resize(w, h);
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    let settings = RenderSettings {
        max_depth: 8,
        ..RenderSettings::default()
    };
    let outcome = stagelight::integrators::render(
        IntegratorKind::named("pt"),
        Arc::new(SceneData::new(prepared)),
        &settings,
        Budget::SamplesPerPixel(1),
        &control,
    );
    let image = outcome.film.image();
    assert!(
        image.pixels.iter().all(|p| p.is_finite()),
        "the film holds a non-finite value"
    );
    "ok".to_string()
}

/// The invariants of a prepared scene.
pub fn check_prepared(s: &PreparedScene) {
    let t = &s.triangles;
    let n = t.len();
    assert!(n > 0);
    for column in [t.p1.len(), t.p2.len(), t.normal.len()] {
        assert_eq!(column, n);
    }
    assert_eq!(t.material.len(), n);
    assert_eq!(t.emitter.len(), n);
    assert_eq!(t.smooth.len(), n);
    for i in 0..n {
        for p in [t.p0[i], t.p1[i], t.p2[i]] {
            assert!(
                p.is_finite() && (p.abs().max_element() as f64) < scene::MAX_COORDINATE,
                "vertex {p}"
            );
        }
        assert!(
            (t.normal[i].length() - 1.0).abs() < 1e-3,
            "normal {}",
            t.normal[i]
        );
        assert!((t.material[i] as usize) < s.materials.len());
        let e = t.emitter[i];
        assert!(e == scene::NO_EMITTER || (e as usize) < s.emitters.triangle.len());
        let k = t.smooth[i];
        assert!(k == scene::FLAT || (k as usize) < t.vertex_normals.len());
    }
    let e = &s.emitters;
    let lights = e.triangle.len();
    assert_eq!(e.radiance.len(), lights);
    assert_eq!(e.area.len(), lights);
    assert_eq!(e.pmf.len(), lights, "pmf of {lights} lights");
    assert_eq!(e.cdf.len(), lights, "cdf of {lights} lights");
    if lights > 0 {
        assert_eq!(*e.cdf.last().unwrap(), 1.0);
        assert!(e.cdf.windows(2).all(|w| w[0] <= w[1]));
        assert!(e.total_power.is_finite());
    }
    for k in 0..lights {
        assert!(
            e.area[k].is_normal() && e.area[k] > 0.0,
            "area {}",
            e.area[k]
        );
        assert!(e.pmf[k].is_finite() && e.pmf[k] >= 0.0);
        assert!(e.radiance[k].is_finite());
        assert_eq!(t.emitter[e.triangle[k] as usize] as usize, k);
    }
    assert!(s.bounds_min.is_finite() && s.bounds_max.is_finite());
}

/// An OBJ file: parsed, its mesh checked, and a tree built over its triangles.
pub fn obj(data: &[u8]) -> String {
    match scene::obj::parse_obj("fuzz.obj", data) {
        Ok(m) => check_mesh(&m, "fuzz.obj"),
        Err(e) => check_message(&e, "fuzz.obj"),
    }
}

/// A PLY file (ASCII or binary): parsed, its mesh checked, and a tree built over its
/// triangles.
pub fn ply(data: &[u8]) -> String {
    match scene::ply::parse_ply("fuzz.ply", data) {
        Ok(m) => check_mesh(&m, "fuzz.ply"),
        Err(e) => check_message(&e, "fuzz.ply"),
    }
}

/// A mesh read from `file`: triangles, finite positions, unit (or zero) normals, indices
/// inside, a tree built over it, warnings that are one line naming the file.
fn check_mesh(parsed: &scene::shapes::MeshFile, file: &str) -> String {
    let m = &parsed.mesh;
    assert!(!m.triangles.is_empty());
    assert!(m.positions.iter().all(|p| p.is_finite()));
    if let Some(normals) = &m.normals {
        assert_eq!(normals.len(), m.positions.len());
        for n in normals {
            assert!(
                *n == glam::DVec3::ZERO || (n.length() - 1.0).abs() < 1e-9,
                "{n}"
            );
        }
    }
    let mut columns = scene::TriangleColumns::default();
    for t in &m.triangles {
        for &i in t {
            assert!((i as usize) < m.positions.len(), "index {i}");
        }
        let [a, b, c] = t.map(|i| m.positions[i as usize].as_vec3());
        columns.p0.push(a);
        columns.p1.push(b);
        columns.p2.push(c);
        columns.normal.push(
            (b - a)
                .cross(c - a)
                .try_normalize()
                .unwrap_or(glam::Vec3::Z),
        );
        columns.material.push(0);
        columns.emitter.push(scene::NO_EMITTER);
        columns.smooth.push(scene::FLAT);
    }
    let accel = stagelight::accel::Accel::build(&columns);
    assert!(accel.len() <= columns.len());
    for w in &parsed.warnings {
        check_message(w, file);
    }
    format!(
        "ok normals:{} warnings:{}",
        m.normals.is_some(),
        parsed.warnings.len()
    )
}

/// An EXR file, read as `diff` reads it (with 256 MB of memory).
pub fn exr(data: &[u8]) -> String {
    let memory = MemoryLimit {
        bytes: 256 << 20,
        source: "the fuzz target allows",
    };
    match Image::read_exr_bytes(data, Some(memory)) {
        Ok(image) => {
            assert_eq!(image.pixels.len(), image.width * image.height);
            format!("ok {}", (image.width * image.height).min(2))
        }
        Err(e) => {
            assert!(!e.contains('\n'), "{e:?}");
            assert!(e.len() <= 1000, "{} bytes", e.len());
            signature(&e)
        }
    }
}

/// A checkpoint file: read, and if valid, written and read back unchanged.
pub fn checkpoint(data: &[u8]) -> String {
    match Checkpoint::from_bytes(data) {
        Ok(c) => {
            let f = &c.film;
            assert_eq!(f.sums().len(), f.width * f.height);
            let in_film = c.header.passes - c.header.first_pass;
            assert!(f.sample_counts().iter().all(|&n| n == in_film));
            let bytes = c.to_bytes().expect("a checkpoint read is written");
            let again = Checkpoint::from_bytes(&bytes).expect("a checkpoint written reads back");
            assert_eq!(again.header, c.header);
            assert_eq!(again.film.fixed_sums(), c.film.fixed_sums());
            assert_eq!(again.film.fixed_splats(), c.film.fixed_splats());
            assert_eq!(again.film.image(), c.film.image());
            "ok".to_string()
        }
        Err(e) => {
            assert!(!e.contains('\n'), "{e:?}");
            assert!(e.len() <= 1000, "{} bytes", e.len());
            signature(&e)
        }
    }
}
