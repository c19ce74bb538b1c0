//! The megakernel against the wavefront, and the wavefront's size and lane width: PT's two
//! kernels call the same per-path steps in the same order (the wavefront's lanes are their
//! lane-by-lane twins) and the film sums exactly, so they must give the same film bit for bit;
//! and every wavefront size and lane width must give the same film too.

use crate::common::{load_small, shrunk_scene, stagelight, stderr, stdout, temp_dir};
use stagelight::film::Film;
use stagelight::integrators::pt::Kernel;
use stagelight::integrators::{
    Budget, Control, IntegratorKind, RenderOutcome, RenderSettings, SceneData,
};
use stagelight::lanes::LaneWidth;
use stagelight::sampling::SamplerKind;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

const SCENES: [&str; 4] = [
    "cornell_box.ron",
    "torus_glass.ron",
    "door_ajar.ron",
    "furnace.ron",
];

fn render(
    data: &Arc<SceneData>,
    integrator: &str,
    settings: RenderSettings,
    spp: u64,
) -> RenderOutcome {
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    stagelight::integrators::render(
        IntegratorKind::named(integrator),
        data.clone(),
        &settings,
        Budget::SamplesPerPixel(spp),
        &control,
    )
}

/// Asserts the films hold the same sums and counts, bit for bit, and that they are not empty
/// (an all-black film would make the comparison vacuous).
fn assert_same_film(a: &Film, b: &Film, what: &str) {
    assert_eq!(a.fixed_sums(), b.fixed_sums(), "{what}: pixel sums differ");
    assert_eq!(a.fixed_splats(), b.fixed_splats(), "{what}: splats differ");
    assert_eq!(a.total_samples(), b.total_samples(), "{what}");
    assert_eq!((a.nonfinite, b.nonfinite), (0, 0), "{what}");
    let mean = a.image().channel_means();
    assert!(mean.max_element() > 0.0, "{what}: a black image");
}

#[test]
fn the_megakernel_renders_the_wavefront_image_bit_for_bit() {
    for name in SCENES {
        let data = Arc::new(SceneData::new(load_small(name, 24)));
        let cases = [
            (SamplerKind::Independent, u32::MAX, None),
            (SamplerKind::Sobol, u32::MAX, Some(1000)),
            (SamplerKind::Independent, 2, Some(333)),
        ];
        for (sampler, max_depth, wavefront) in cases {
            let settings = RenderSettings {
                seed: 5,
                sampler,
                max_depth,
                wavefront,
                ..RenderSettings::default()
            };
            let mega = render(
                &data,
                "pt",
                RenderSettings {
                    kernel: Kernel::Megakernel,
                    ..settings
                },
                8,
            );
            // Each lane width runs in the copy compiled for this CPU (AVX-512, AVX2 or the
            // baseline): each must give the megakernel's film.
            for lanes in [LaneWidth::Eight, LaneWidth::Sixteen] {
                let wave = render(
                    &data,
                    "pt",
                    RenderSettings {
                        lanes: Some(lanes),
                        ..settings
                    },
                    8,
                );
                let what = format!(
                    "{name} {sampler:?} max depth {max_depth} wavefront {wavefront:?} {lanes:?} lanes"
                );
                assert_same_film(&wave.film, &mega.film, &what);
                // The same paths: the same rays, counted by the trace systems in one and by
                // the megakernel in the other.
                assert!(mega.counted_rays.is_some() && wave.counted_rays.is_none());
                assert_eq!(wave.closest_rays(), mega.closest_rays(), "{what}");
                assert_eq!(wave.shadow_rays(), mega.shadow_rays(), "{what}");
            }
            let what = format!("{name} {sampler:?} max depth {max_depth} wavefront {wavefront:?}");
            assert!(mega.closest_rays() > 0);
            assert_eq!(
                mega.systems,
                vec!["trace_paths", "accumulate_film"],
                "{what}"
            );
        }
    }
}

/// Textures are looked up by a system of their own, once per hit, and only in the graphs of
/// scenes that have them: its column gives the shading and light-sampling systems the very
/// material the megakernel looks up inline, so the images stay the same bit for bit.
#[test]
fn textures_are_looked_up_by_their_own_system_only_where_a_scene_has_them() {
    let graph_of = |data: &SceneData| stagelight::integrators::pt::graph(data).system_names();
    let plain = SceneData::new(load_small("cornell_box.ron", 8));
    assert!(!plain.scene.has_textures());
    assert!(!graph_of(&plain).contains(&"look_up_textures"));
    // Textured diffuse, plastics' textured bases, textured anisotropic roughness (its axis
    // follows the uvs), a textured twosided back.
    for name in [
        "textured.xml",
        "plastics.xml",
        "anisotropic.xml",
        "twosided_two.xml",
    ] {
        let mut scene = crate::common::load_test_scene(&format!("mitsuba/{name}"));
        scene.camera.resize(24, 24);
        let data = Arc::new(SceneData::new(scene));
        assert!(data.scene.has_textures(), "{name}");
        assert!(
            graph_of(&data).contains(&"look_up_textures"),
            "{name}: {:?}",
            graph_of(&data)
        );
        let settings = RenderSettings {
            seed: 3,
            ..RenderSettings::default()
        };
        let film = |kernel| render(&data, "pt", RenderSettings { kernel, ..settings }, 4).film;
        assert_same_film(&film(Kernel::Wavefront), &film(Kernel::Megakernel), name);
    }
}

/// The microfacet materials shade in lanes (`Bsdf::IN_LANES`): scenes of GGX and Beckmann
/// conductors and rough plastics (isotropic, anisotropic, textured, mixed in one queue, lit by
/// area lights only, where light sampling runs in lanes too, and with every other kind of
/// light, where it goes one path at a time beside shading in lanes) give the megakernel's film
/// at both lane widths.
#[test]
fn microfacet_materials_shade_in_lanes_as_one_path() {
    // The conductors' room under an area, a point, a spot and a directional light and a
    // constant sky at once.
    let every_light = temp_dir("every-light");
    let all_lights = every_light.join("every_light.xml");
    let conductors = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/scenes/mitsuba/conductors.xml"),
    )
    .unwrap();
    let lights = r#"
    <emitter type="point"><point name="position" x="0.5" y="1.5" z="1"/><rgb name="intensity" value="2, 3, 4"/></emitter>
    <emitter type="spot">
        <transform name="to_world"><lookat origin="-1, 1.8, 1.5" target="0, 0.4, 0" up="0, 1, 0"/></transform>
        <rgb name="intensity" value="6, 4, 2"/><float name="cutoff_angle" value="30"/>
    </emitter>
    <emitter type="directional"><vector name="direction" x="0.2" y="-1" z="-0.3"/><rgb name="irradiance" value="1, 1, 2"/></emitter>
    <emitter type="constant"><rgb name="radiance" value="0.2, 0.3, 0.4"/></emitter>
</scene>"#;
    std::fs::write(&all_lights, conductors.replace("</scene>", lights)).unwrap();
    let scenes = [
        "conductors.xml",
        "plastics.xml",
        "anisotropic.xml",
        "materials_room.xml",
        "point_light.xml",
        "spot_light.xml",
        "envmap.xml",
    ];
    let mut paths: Vec<std::path::PathBuf> = scenes
        .iter()
        .map(|name| {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/scenes/mitsuba")
                .join(name)
        })
        .collect();
    paths.push(all_lights);
    for path in paths {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let mut scene = stagelight::scene::load(&path).expect("scene loads");
        scene.camera.resize(24, 24);
        let data = Arc::new(SceneData::new(scene));
        let settings = RenderSettings {
            seed: 9,
            ..RenderSettings::default()
        };
        let mega = render(
            &data,
            "pt",
            RenderSettings {
                kernel: Kernel::Megakernel,
                ..settings
            },
            4,
        );
        for lanes in [LaneWidth::Eight, LaneWidth::Sixteen] {
            let wave = render(
                &data,
                "pt",
                RenderSettings {
                    lanes: Some(lanes),
                    ..settings
                },
                4,
            );
            assert_same_film(&wave.film, &mega.film, &format!("{name} {lanes:?} lanes"));
        }
    }
}

#[test]
fn images_do_not_depend_on_the_wavefront() {
    // 20 x 20 = 400 pixels: waves of 3, 400 and 1000 paths split passes, hold one pass, and
    // hold passes and a half.
    for name in ["door_ajar.ron", "torus_glass.ron"] {
        let data = Arc::new(SceneData::new(load_small(name, 20)));
        let of = |integrator: &str, wavefront: Option<usize>, spp: u64| {
            let settings = RenderSettings {
                seed: 11,
                wavefront,
                ..RenderSettings::default()
            };
            let o = render(&data, integrator, settings, spp);
            if let Some(n) = wavefront {
                assert!(
                    o.wavefront <= n,
                    "{integrator}: {} paths in a wave of {n}",
                    o.wavefront
                );
            }
            o.film
        };
        let pt = of("pt", None, 6);
        for n in [3, 400, 1000, 4096] {
            assert_same_film(
                &pt,
                &of("pt", Some(n), 6),
                &format!("{name} pt --wavefront {n}"),
            );
        }
        let bdpt = of("bdpt", None, 2);
        for n in [7, 1000] {
            assert_same_film(
                &bdpt,
                &of("bdpt", Some(n), 2),
                &format!("{name} bdpt --wavefront {n}"),
            );
        }
    }
}

#[test]
fn the_kernel_and_wavefront_options_run_and_refuse_what_does_not_apply() {
    let dir = temp_dir("kernels-cli");
    let scene = shrunk_scene("cornell_box", 16, &dir.join("cb.ron"));
    let scene = scene.to_str().unwrap();
    let out = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let (a, b) = (out("wave.exr"), out("mega.exr"));
    let o = stagelight(&[
        "render",
        scene,
        "--spp",
        "4",
        "--quiet",
        "--wavefront",
        "100",
        "-o",
        &a,
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("100 paths in flight"), "{}", stdout(&o));
    let o = stagelight(&[
        "render",
        scene,
        "--spp",
        "4",
        "--quiet",
        "--kernel",
        "megakernel",
        "-o",
        &b,
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let report = stdout(&o);
    assert!(
        report.contains("trace_paths") && report.contains("megakernel"),
        "{report}"
    );
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        "the EXRs differ"
    );
    // Both lane widths, whatever the CPU: the same image again.
    for lanes in ["8", "16"] {
        let c = out(&format!("lanes{lanes}.exr"));
        let o = stagelight(&[
            "render", scene, "--spp", "4", "--quiet", "--lanes", lanes, "-o", &c,
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        assert_eq!(
            std::fs::read(&a).unwrap(),
            std::fs::read(&c).unwrap(),
            "--lanes {lanes}: the EXRs differ"
        );
    }
    // BDPT's weights in lanes of either width: the same image as at the widest.
    let bdpt = |lanes: &[&str], name: &str| {
        let c = out(name);
        let mut line = vec![
            "render",
            scene,
            "--spp",
            "2",
            "--quiet",
            "--integrator",
            "bdpt",
        ];
        line.extend(lanes.iter().copied().chain(["-o", c.as_str()]));
        let o = stagelight(&line);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        std::fs::read(&c).unwrap()
    };
    let widest = bdpt(&[], "bdpt.exr");
    for lanes in ["8", "16"] {
        let image = bdpt(&["--lanes", lanes], &format!("bdpt_lanes{lanes}.exr"));
        assert!(image == widest, "bdpt --lanes {lanes}: the EXRs differ");
    }
    // Bad input: one clear message, exit 1.
    for (args, expect) in [
        (
            vec!["--integrator", "bdpt", "--kernel", "megakernel"],
            "only pt has a megakernel",
        ),
        (
            vec!["--integrator", "sppm", "--wavefront", "64"],
            "only pt, bdpt, vcm and bpm",
        ),
        (vec!["--wavefront", "0"], "--wavefront"),
        (vec!["--lanes", "4"], "expected 8 or 16"),
        (
            vec!["--kernel", "megakernel", "--lanes", "8"],
            "only pt's wavefront",
        ),
        (
            vec!["--integrator", "sppm", "--lanes", "16"],
            "only pt's wavefront, bdpt and vcm",
        ),
        (vec!["--kernel", "simd"], "--kernel"),
    ] {
        let mut line = vec!["render", scene, "--spp", "1", "--quiet", "-o", &a];
        line.extend(args.iter().copied());
        let o = stagelight(&line);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    }
    let o = stagelight(&[
        "bench",
        scene,
        "--sweep",
        "--integrator",
        "pm",
        "--runs",
        "1",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("--sweep"), "{}", stderr(&o));
}

#[test]
fn bench_sweeps_the_wavefront_and_compares_with_a_baseline_per_kernel() {
    let dir = temp_dir("kernels-bench");
    let scene = shrunk_scene("cornell_box", 16, &dir.join("cb.ron"));
    let scene = scene.to_str().unwrap();
    let saved = dir.join("sweep.json");
    let o = stagelight(&[
        "bench",
        scene,
        "--sweep",
        "--spp",
        "4",
        "--runs",
        "1",
        "--threads",
        "2",
        "--save",
        saved.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let table = stdout(&o);
    assert!(
        table.contains("machine: ") && table.contains("2 threads"),
        "{table}"
    );
    // The lane width that ran: the widest this CPU has, as no --lanes was given.
    let widest = LaneWidth::widest().count();
    assert!(
        table.contains(&format!("pt wavefront lanes: {widest}")),
        "{table}"
    );
    // Eleven wavefront sizes (a wave holds at most the render's 1024 samples) and the
    // megakernel, in both tables.
    let rows = |start: &str| table.lines().filter(|l| l.starts_with(start)).count();
    assert_eq!(rows("| wavefront | 1024 |"), 2 * 11, "{table}");
    assert_eq!(rows("| megakernel | 2 (one per thread) |"), 2, "{table}");
    assert!(table.contains("wall ns per sample by system"), "{table}");
    // The saved file holds one result per kernel and wavefront; a plain bench of the
    // megakernel finds its own row in it, not a wavefront's.
    let file = stagelight::commands::bench::read_bench_file(&saved).unwrap();
    assert_eq!(file.results.len(), 12);
    let o = stagelight(&[
        "bench",
        scene,
        "--kernel",
        "megakernel",
        "--spp",
        "4",
        "--runs",
        "1",
        "--threads",
        "1",
        "--baseline",
        saved.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let table = stdout(&o);
    assert!(table.contains("against the baseline"), "{table}");
    assert!(
        table.contains("| cb.ron | pt megakernel | samples/s |"),
        "{table}"
    );
    assert!(!table.contains("--wavefront"), "{table}");
    assert!(table.contains("threads 2, not 1"), "{table}");
}
