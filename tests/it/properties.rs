//! Properties over many generated cases (proptest): checkpoints read back as written and
//! refuse any damaged byte; a render resumed from the sums of its first passes equals the
//! render made in one go; films add samples in a fixed order, so a film rebuilt from its
//! parts and continued equals one never interrupted; a prepared scene has the triangles its
//! shapes make.

use glam::{DVec3, Vec3};
use proptest::prelude::*;
use stagelight::film::Film;
use stagelight::integrators::{Budget, Control, IntegratorKind, RenderSettings, Resume, SceneData};
use stagelight::reference::{Checkpoint, CheckpointHeader};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

/// A sample value: mostly ordinary, sometimes zero, huge or not finite.
fn sample() -> impl Strategy<Value = Vec3> {
    prop_oneof![
        8 => (0.0f32..10.0, 0.0f32..10.0, 0.0f32..10.0).prop_map(|(x, y, z)| Vec3::new(x, y, z)),
        1 => Just(Vec3::ZERO),
        1 => Just(Vec3::splat(3e38)),
        1 => prop_oneof![Just(f32::NAN), Just(f32::INFINITY)].prop_map(|v| Vec3::new(v, 0.0, 1.0)),
    ]
}

fn header(width: usize, height: usize, passes: u64) -> impl Strategy<Value = CheckpointHeader> {
    (
        prop_oneof![Just("pt"), Just("bdpt")],
        any::<u64>(),
        prop_oneof![Just(u32::MAX), 0u32..100],
        "[ -~]{0,40}",
        any::<u64>(),
        0.0f64..1e7,
        0u64..1000,
        -20i32..20,
    )
        .prop_map(
            move |(integrator, seed, max_depth, scene, fingerprint, seconds, splats, unit)| {
                CheckpointHeader {
                    integrator: integrator.into(),
                    seed,
                    sampler: "independent".into(),
                    max_depth,
                    scene,
                    scene_fingerprint: format!("{fingerprint:016x}"),
                    width,
                    height,
                    passes,
                    seconds,
                    nonfinite: 0,
                    nonfinite_splats: splats,
                    out_of_range: 0,
                    first_pass: 0,
                    shard: None,
                    made_by: "reference".into(),
                    settings: String::new(),
                    unit_exponent: unit,
                }
            },
        )
}

/// A film of whole passes with its checkpoint header.
fn checkpoint() -> impl Strategy<Value = Checkpoint> {
    (1usize..6, 1usize..6, 0u64..4)
        .prop_flat_map(|(w, h, passes)| {
            let n = w * h;
            (
                header(w, h, passes),
                proptest::collection::vec(sample(), n * passes as usize),
                proptest::collection::vec(sample(), 0..3 * n),
            )
        })
        .prop_map(|(mut header, samples, splats)| {
            let mut film = Film::with_unit(header.width, header.height, header.unit_exponent);
            let n = header.width * header.height;
            for (i, s) in samples.iter().enumerate() {
                film.add_sample(i % n, *s);
            }
            for (i, s) in splats.iter().enumerate() {
                film.add_splat(i % n, *s);
            }
            header.nonfinite = film.nonfinite;
            header.nonfinite_splats = film.nonfinite_splats;
            header.out_of_range = film.out_of_range;
            Checkpoint { header, film }
        })
}

proptest! {
    #![proptest_config(config(200))]

    #[test]
    fn checkpoints_read_back_as_written(c in checkpoint()) {
        let bytes = c.to_bytes().unwrap();
        let back = Checkpoint::from_bytes(&bytes).unwrap();
        prop_assert_eq!(&back.header, &c.header);
        prop_assert_eq!(back.film.sums(), c.film.sums());
        prop_assert_eq!(back.film.sample_counts(), c.film.sample_counts());
        prop_assert_eq!(back.film.nonfinite_splats, c.film.nonfinite_splats);
        prop_assert_eq!(back.film.out_of_range, c.film.out_of_range);
        prop_assert_eq!(back.film.image(), c.film.image());
    }

    #[test]
    fn any_changed_byte_of_a_checkpoint_is_refused(
        c in checkpoint(),
        at in any::<prop::sample::Index>(),
        flip in 1u8..=255,
    ) {
        let mut bytes = c.to_bytes().unwrap();
        let i = at.index(bytes.len());
        bytes[i] ^= flip;
        prop_assert!(Checkpoint::from_bytes(&bytes).is_err(), "byte {} changed", i);
    }

    #[test]
    fn a_film_rebuilt_from_its_parts_continues_bit_for_bit(
        (w, h, samples, cut) in (1usize..5, 1usize..5).prop_flat_map(|(w, h)| {
            (Just(w), Just(h), proptest::collection::vec(sample(), 0..60), any::<prop::sample::Index>())
        })
    ) {
        let n = w * h;
        let mut whole = Film::new(w, h);
        for (i, s) in samples.iter().enumerate() {
            whole.add_sample(i % n, *s);
        }
        // Stop anywhere, keep the sums, counts and splats, and go on in the same order.
        let cut = cut.index(samples.len() + 1);
        let mut first = Film::new(w, h);
        for (i, s) in samples[..cut].iter().enumerate() {
            first.add_sample(i % n, *s);
        }
        let mut resumed = Film::from_fixed_parts(
            w,
            h,
            first.unit_exponent(),
            first.fixed_sums().to_vec(),
            first.sample_counts().to_vec(),
            first.fixed_splats().to_vec(),
            first.nonfinite,
        )
        .unwrap();
        for (i, s) in samples.iter().enumerate().skip(cut) {
            resumed.add_sample(i % n, *s);
        }
        prop_assert_eq!(resumed.sums(), whole.sums());
        prop_assert_eq!(resumed.nonfinite, whole.nonfinite);
        prop_assert_eq!(resumed.image(), whole.image());
        // A rejected sample (NaN, infinite, or 3e38: beyond the film's range) counts as
        // black: the mean is over every sample.
        let in_range = |s: &Vec3| s.is_finite() && s.abs().max_element() < 2f32.powi(63);
        prop_assert_eq!(
            whole.nonfinite + whole.out_of_range,
            samples.iter().filter(|s| !in_range(s)).count() as u64
        );
        for p in 0..n {
            let finite: Vec<Vec3> = samples.iter().skip(p).step_by(n).copied().filter(in_range).collect();
            let count = samples.iter().skip(p).step_by(n).count();
            if count > 0 {
                let mean = finite.iter().map(|s| s.as_dvec3()).sum::<DVec3>() / count as f64;
                prop_assert_eq!(whole.image().pixels[p], mean.as_vec3());
            }
        }
    }
}

/// A 4 x 3 image of a box lit from above.
fn tiny_scene() -> Arc<SceneData> {
    let text =
        "Scene(camera: (position: (0, 1, -3), look_at: (0, 1, 0), fov: 60, width: 4, height: 3),
        materials: {\"w\": Diffuse(reflectance: (0.6, 0.6, 0.6))},
        objects: [
            (shape: Box(min: (-2, 0, -2), max: (2, 3, 2)), material: \"w\", flip_normals: true),
            (shape: Quad((-0.5, 2.9, -0.5), (0.5, 2.9, -0.5), (0.5, 2.9, 0.5), (-0.5, 2.9, 0.5)),
             material: \"w\", emission: Some((3, 3, 3))),
        ])";
    let scene = stagelight::scene::load_from_str(std::path::Path::new("tiny.ron"), text).unwrap();
    Arc::new(SceneData::new(scene))
}

proptest! {
    #![proptest_config(config(24))]

    #[test]
    fn a_render_resumed_from_its_chunk_sums_equals_one_render(
        integrator in prop_oneof![Just("pt"), Just("bdpt")],
        seed in 0u64..1000,
        first in 1u64..5,
        more in 1u64..5,
    ) {
        let data = tiny_scene();
        let kind = IntegratorKind::named(integrator);
        let settings = RenderSettings { seed, ..RenderSettings::default() };
        let stop = AtomicBool::new(false);
        let control = Control { stop: &stop, progress: &|_, _| {} };
        let whole = stagelight::integrators::render(kind, data.clone(), &settings, Budget::SamplesPerPixel(first + more), &control);
        let part = stagelight::integrators::render(kind, data.clone(), &settings, Budget::SamplesPerPixel(first), &control);
        // Through a checkpoint's bytes, as `reference` resumes.
        let c = Checkpoint {
            header: CheckpointHeader {
                integrator: integrator.into(),
                seed,
                sampler: "independent".into(),
                max_depth: u32::MAX,
                scene: "tiny.ron".into(),
                scene_fingerprint: "0000000000000000".into(),
                width: 4,
                height: 3,
                passes: first,
                seconds: 0.0,
                nonfinite: part.film.nonfinite,
                nonfinite_splats: part.film.nonfinite_splats,
                out_of_range: part.film.out_of_range,
                first_pass: 0,
                shard: None,
                made_by: "reference".into(),
                settings: String::new(),
                unit_exponent: part.film.unit_exponent(),
            },
            film: part.film,
        };
        let film = Checkpoint::from_bytes(&c.to_bytes().unwrap()).unwrap().film;
        let resumed = stagelight::integrators::resume(
            kind,
            data,
            &settings,
            Budget::SamplesPerPixel(first + more),
            &control,
            Resume { film, first_pass: 0, passes: first },
        );
        prop_assert_eq!(resumed.film.sums(), whole.film.sums());
        prop_assert_eq!(resumed.film.image(), whole.film.image());
    }
}

/// A shape of the scene format and the triangles it makes.
fn shape() -> impl Strategy<Value = (String, usize)> {
    let p = || (-5.0f64..5.0, -5.0f64..5.0, -5.0f64..5.0);
    prop_oneof![
        Just((
            "Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0))".to_string(),
            2
        )),
        Just(("Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0))".to_string(), 1)),
        (p(), 0.1f64..3.0).prop_map(|((x, y, z), d)| {
            (
                format!(
                    "Box(min: ({x}, {y}, {z}), max: ({}, {}, {}))",
                    x + d,
                    y + d,
                    z + d
                ),
                12,
            )
        }),
        (0u32..3, any::<bool>()).prop_map(|(level, smooth)| {
            (
                format!("Icosphere(level: {level}, smooth: {smooth})"),
                20 << (2 * level),
            )
        }),
        (3u32..12, 3u32..12).prop_map(|(nu, nv)| {
            (
                format!("Torus(major_radius: 1, minor_radius: 0.3, nu: {nu}, nv: {nv})"),
                2 * (nu * nv) as usize,
            )
        }),
    ]
}

fn transform() -> impl Strategy<Value = String> {
    prop_oneof![
        (-9.0f64..9.0).prop_map(|x| format!("Translate(({x}, 1, -2))")),
        (-360.0f64..360.0).prop_map(|d| format!("Rotate(axis: (1, 2, 3), degrees: {d})")),
        (0.2f64..5.0, any::<bool>())
            .prop_map(|(s, mirror)| format!("Scale(({}, {s}, 1))", if mirror { -s } else { s })),
    ]
}

proptest! {
    #![proptest_config(config(64))]

    #[test]
    fn a_prepared_scene_has_the_triangles_of_its_shapes(
        objects in proptest::collection::vec(
            (shape(), proptest::collection::vec(transform(), 0..3), any::<bool>(), any::<bool>()),
            1..6,
        )
    ) {
        let mut text = String::from(
            "Scene(camera: (position: (0, 0, -10), look_at: (0, 0, 0), fov: 40),
             materials: {\"m\": Diffuse(reflectance: (0.5, 0.5, 0.5))}, objects: [",
        );
        let mut expected = 0;
        let mut emitting = 0;
        // The tree leaves out exact copies: objects with the same shape and transforms.
        let mut distinct = std::collections::HashMap::new();
        for ((shape, count), transforms, flip, emits) in &objects {
            expected += count;
            let key = (shape.replace(", smooth: true", "").replace(", smooth: false", ""), transforms.clone(), *flip);
            distinct.insert(key, *count);
            if *emits {
                emitting += count;
            }
            text += &format!(
                "(shape: {shape}, material: \"m\", transform: [{}], flip_normals: {flip}{}),",
                transforms.join(", "),
                if *emits { ", emission: Some((1, 2, 3))" } else { "" }
            );
        }
        text += "])";
        let scene = stagelight::scene::load_from_str(std::path::Path::new("p.ron"), &text)
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(scene.triangles.len(), expected);
        prop_assert_eq!(scene.emitters.triangle.len(), emitting);
        prop_assert_eq!(scene.emitters.cdf.len(), emitting);
        let data = SceneData::new(scene);
        prop_assert_eq!(data.accel.len(), distinct.values().sum::<usize>());
    }
}
