//! An integrator the crate does not have, assembled here, outside it, from its public systems
//! and components without touching a system's file: a path tracer by BSDF sampling alone (no
//! light sampling). Its state holds the columns the systems declare, `bind!` maps each
//! system's columns to the state's fields, and one system of its own (`system!` works out
//! here too) tells emission that no light sampling shares its paths. It must converge to the
//! image of PT, which also samples lights.

use crate::common::{assert_blocks_agree, block_luminance_stats, load_small, render_pt};
use glam::Vec3;
use stagelight::bsdf::Material;
use stagelight::components::path_tracing::{MaterialRanges, PtSettings, Scratch};
use stagelight::components::{CHUNK, Hits, PathFlags, Paths, Rays, Surfaces, Wave};
use stagelight::film::{Film, Image};
use stagelight::integrators::driver::{IntegratorState, WaveState, render_waves};
use stagelight::integrators::{Budget, Control, pt};
use stagelight::pipeline::{Flow, Graph, Node};
use stagelight::sampling::Sampler;
use stagelight::scene::SceneData;
use stagelight::systems::{gather, generate, shade, trace};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// The columns of a BSDF-sampling path tracer: a path wave (rays, hits, paths, surfaces) and
/// its film target, no shadow rays.
struct BsdfOnlyState {
    data: Arc<SceneData>,
    settings: PtSettings,
    sampler: Sampler<'static>,
    pixels: u64,
    wave: Wave,
    rays: Rays,
    hits: Hits,
    paths: Paths,
    surfaces: Surfaces,
    /// The materials `look_up_textures` looks up, in scenes with textures.
    materials: Vec<Material>,
    active: usize,
    ranges: MaterialRanges,
    sample_radiance: Vec<Vec3>,
    film: Film,
    scratch: Scratch,
}

/// Marks every live path's last bounce as one light sampling could not have taken, so
/// `add_emitted_light` counts the light the next bounce finds whole instead of weighting it
/// against light sampling (which this integrator never does).
struct CountEmissionWhole;

stagelight::system! {
    CountEmissionWhole = "count_emission_whole";
    read live: usize;
    write paths: Paths;
    run {
        for flags in &mut paths.flags[..*live] {
            flags.set(PathFlags::SPECULAR, true);
        }
        Flow::new(*live, *live)
    }
}

stagelight::bind! {
    BsdfOnlyState:
    generate::camera_rays::GenerateCameraRays {
        read wave, camera = data.scene.camera, pixels, sampler, lanes = settings.lanes;
        write rays, paths, sample_radiance, active;
    }
    trace::closest::TraceClosest {
        read accel = data.accel, rays, live = active;
        write hits;
    }
    shade::emitted_light::AddEmittedLight {
        read data, hits, rays, live = active;
        write paths;
    }
    shade::sort_by_material::SortByMaterial {
        read scene = data.scene, max_depth = settings.max_depth;
        write hits, paths, rays, sample_radiance, ranges, active, scratch, surfaces;
    }
    shade::look_up_textures::LookUpTextures {
        read data, triangles = hits.triangle, dirs = rays.dir, surfaces, live = active;
        write materials;
    }
    shade::material::ShadeMaterial {
        read data, sampler, lanes = settings.lanes, triangles = hits.triangle, surfaces,
            materials, ranges;
        write rays, paths;
    }
    CountEmissionWhole {
        read live = active;
        write paths;
    }
    shade::russian_roulette::RussianRoulette {
        read live = active, sampler;
        write paths, rays;
    }
    gather::film::AccumulateFilm {
        read sample_radiance, wave, pixels, camera = data.scene.camera, sampler;
        write film;
    }
}

impl IntegratorState for BsdfOnlyState {
    type Settings = PtSettings;
    const INPUTS: &'static [&'static str] = &[
        "data",
        "settings",
        "sampler",
        "pixels",
        "wave",
        "film",
        "scratch",
        "materials",
    ];
    fn graph(data: &SceneData, _: &PtSettings) -> Graph<BsdfOnlyState> {
        let mut bounce = vec![
            Node::system(trace::closest::TraceClosest),
            Node::system(shade::emitted_light::AddEmittedLight),
            Node::system(shade::sort_by_material::SortByMaterial),
        ];
        if data.scene.has_textures() {
            bounce.push(Node::system(shade::look_up_textures::LookUpTextures));
        }
        for kind in pt::used_kinds(data) {
            bounce.push(Node::system(shade::material::ShadeMaterial(kind)));
        }
        bounce.push(Node::system(CountEmissionWhole));
        bounce.push(Node::system(shade::russian_roulette::RussianRoulette));
        Graph::new(
            "bsdf_only",
            vec![
                Node::system(generate::camera_rays::GenerateCameraRays),
                Node::Loop {
                    name: "bounces",
                    queue_len: |s: &BsdfOnlyState| s.active,
                    body: bounce,
                },
                Node::system(gather::film::AccumulateFilm),
            ],
        )
    }
}

impl WaveState for BsdfOnlyState {
    const WAVEFRONT: usize = 1 << 14;
    fn new(data: Arc<SceneData>, settings: PtSettings, capacity: usize) -> BsdfOnlyState {
        let cam = data.scene.camera;
        BsdfOnlyState {
            sampler: Sampler::new(settings.sampler, settings.seed, cam.width, cam.height),
            pixels: cam.width as u64 * cam.height as u64,
            film: Film::for_scene(&data),
            data,
            settings,
            wave: Wave::default(),
            rays: Rays::new(capacity),
            hits: Hits::new(capacity),
            paths: Paths::new(capacity),
            surfaces: Surfaces::new(capacity),
            materials: Vec::new(),
            active: 0,
            ranges: MaterialRanges::default(),
            sample_radiance: vec![Vec3::ZERO; capacity],
            scratch: Scratch {
                rays: Rays::new(capacity),
                hits: Hits::new(capacity),
                paths: Paths::new(capacity),
                order: Vec::with_capacity(capacity),
                queue: vec![0; capacity],
                chunk_counts: Vec::with_capacity(capacity.div_ceil(CHUNK)),
            },
        }
    }
    fn begin_wave(&mut self, wave: Wave) {
        self.wave = wave;
    }
    fn film_mut(&mut self) -> &mut Film {
        &mut self.film
    }
    fn finish(self, _: u64) -> (Film, Vec<(String, Image)>, usize) {
        (self.film, Vec::new(), 0)
    }
}

const SIZE: u32 = 64;
const SPP: u64 = 64;
const SEEDS: u64 = 8;

fn render_bsdf_only(seed: u64) -> Image {
    let data = Arc::new(SceneData::new(load_small("cornell_box.ron", SIZE)));
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    let outcome = render_waves::<BsdfOnlyState>(
        data,
        PtSettings::new(seed, u32::MAX),
        Budget::SamplesPerPixel(SPP),
        &control,
        None,
    );
    assert!(outcome.systems.contains(&"count_emission_whole"));
    assert!(!outcome.systems.contains(&"sample_lights"));
    outcome.film.image()
}

#[test]
fn graph_reads_only_what_was_written_before() {
    let data = SceneData::new(load_small("cornell_box.ron", SIZE));
    let graph = BsdfOnlyState::graph(&data, &PtSettings::new(0, u32::MAX));
    assert_eq!(graph.check(BsdfOnlyState::INPUTS), Vec::<String>::new());
    assert!(graph.describe().contains("count_emission_whole"));
}

#[test]
fn bsdf_sampling_alone_converges_to_path_tracing_on_cornell_box() {
    let pt_images: Vec<Image> = (0..SEEDS)
        .map(|seed| {
            render_pt(
                load_small("cornell_box.ron", SIZE),
                SPP,
                100 + seed,
                u32::MAX,
            )
            .film
            .image()
        })
        .collect();
    let bsdf_images: Vec<Image> = (0..SEEDS)
        .map(|seed| render_bsdf_only(200 + seed))
        .collect();
    // Per 16x16 block, the means over seeds agree within 4.5 combined standard errors, each
    // below 10% of the block's value; and the images are not the same (a different estimator).
    assert_blocks_agree(
        "bsdf-only PT against PT",
        &bsdf_images,
        &block_luminance_stats(&pt_images),
        0.1,
        4.5,
    );
    assert_ne!(pt_images[0].pixels, bsdf_images[0].pixels);
}
