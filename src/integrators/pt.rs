//! Path tracing (`--integrator pt`): next-event estimation and BSDF sampling combined by
//! multiple importance sampling (power heuristic), Russian roulette, unlimited depth unless
//! capped.
//!
//! Its graph, built from the scene: `stagelight graph SCENE --integrator pt` prints it with
//! each system's columns, and docs/architecture.md shows it for `door_ajar`.

use crate::bsdf::{Material, MaterialKind};
use crate::components::ray_record::RayRecord;
use crate::components::{Hits, Paths, Rays, ShadowRays, Surfaces};
use crate::film::{Film, Image};
use crate::integrators::driver::render_waves_of;
use crate::integrators::{
    Budget, Control, IntegratorState, RenderOutcome, RenderSettings, Resume, SceneData, Wave,
    WaveState,
};
use crate::pipeline::{Graph, Node};
use crate::sampling::Sampler;
use crate::systems::{connect, gather, generate, shade, trace};
use glam::Vec3;
use std::sync::Arc;

pub use crate::components::path_tracing::*;

impl From<&RenderSettings> for PtSettings {
    fn from(s: &RenderSettings) -> PtSettings {
        PtSettings {
            seed: s.seed,
            sampler: s.sampler,
            max_depth: s.max_depth,
            lanes: s.lanes.unwrap_or_else(crate::lanes::LaneWidth::widest),
            moments: s.moments,
        }
    }
}

/// The path tracer's wavefront state.
pub struct PtState {
    pub data: Arc<SceneData>,
    pub settings: PtSettings,
    pub sampler: Sampler<'static>,
    pub pixels: u64,
    pub wave: Wave,
    pub rays: Rays,
    pub hits: Hits,
    pub paths: Paths,
    pub shadow: ShadowRays,
    pub surfaces: Surfaces,
    /// The material at each live path's hit with its textures looked up
    /// (`look_up_textures`); empty in scenes without textures.
    pub materials: Vec<Material>,
    /// Live paths occupy slots `0..active`.
    pub active: usize,
    pub ranges: MaterialRanges,
    /// Shadow rays cast this bounce occupy slots `0..shadow_len`.
    pub shadow_len: usize,
    /// Radiance of each sample of the wave, written when its path ends.
    pub sample_radiance: Vec<Vec3>,
    pub film: Film,
    /// Double buffers for compaction and sorting.
    pub scratch: Scratch,
    /// The rays traced, for `stagelight rays` (`recording_graph`); empty otherwise.
    pub record: RayRecord,
}

impl PtState {
    pub fn new(data: Arc<SceneData>, settings: PtSettings, capacity: usize) -> PtState {
        let cam = data.scene.camera;
        let pixels = cam.width as u64 * cam.height as u64;
        let film = Film::for_scene(&data);
        let film = if settings.moments {
            film.with_moments()
        } else {
            film
        };
        PtState {
            sampler: Sampler::new(
                settings.sampler,
                settings.seed,
                cam.crop.film_width,
                cam.crop.film_height,
            ),
            data,
            settings,
            pixels,
            wave: Wave::default(),
            rays: Rays::new(capacity),
            hits: Hits::new(capacity),
            paths: Paths::new(capacity),
            shadow: ShadowRays::new(capacity),
            surfaces: Surfaces::new(capacity),
            materials: Vec::new(),
            active: 0,
            ranges: MaterialRanges::default(),
            shadow_len: 0,
            sample_radiance: vec![Vec3::ZERO; capacity],
            film,
            scratch: Scratch {
                rays: Rays::new(capacity),
                hits: Hits::new(capacity),
                paths: Paths::new(capacity),
                order: Vec::with_capacity(capacity),
                queue: vec![0; capacity],
                chunk_counts: Vec::with_capacity(capacity.div_ceil(crate::components::CHUNK)),
            },
            record: RayRecord::default(),
        }
    }

    /// Bytes of wavefront state per path slot (double buffers included).
    pub fn bytes_per_path() -> usize {
        2 * (Rays::bytes_per_item() + Hits::bytes_per_item() + Paths::bytes_per_item())
            + ShadowRays::bytes_per_item()
            + Surfaces::bytes_per_item()
            + std::mem::size_of::<Vec3>()
            + std::mem::size_of::<u32>()
            + std::mem::size_of::<u8>()
    }
}

/// Which material kinds the scene's surfaces use (a twosided's back material's too).
pub fn used_kinds(data: &SceneData) -> Vec<MaterialKind> {
    let scene = &data.scene;
    let mut used: Vec<MaterialKind> = scene
        .triangles
        .material
        .iter()
        .flat_map(|&m| {
            let back = scene.back[m as usize].map(|b| scene.materials[b as usize].kind());
            std::iter::once(scene.materials[m as usize].kind()).chain(back)
        })
        .collect();
    used.sort();
    used.dedup();
    used
}

/// The path tracer's graph for a scene: one shading system per material kind in use, light
/// sampling only where a non-delta surface and an emitter exist.
pub fn graph(data: &SceneData) -> Graph<PtState> {
    graph_of(data, false)
}

/// `graph` with each trace system followed by one that records the rays it traced and what
/// it found into `PtState::record` (`stagelight rays`); the render is unchanged.
pub fn recording_graph(data: &SceneData) -> Graph<PtState> {
    graph_of(data, true)
}

fn graph_of(data: &SceneData, record: bool) -> Graph<PtState> {
    let kinds = used_kinds(data);
    let has_emitters = !data.scene.emitters.triangle.is_empty();
    let light_sampling = has_emitters && kinds.iter().any(|k| !k.is_delta());

    // The systems of one bounce. The first bounce's rays are coherent (camera rays of
    // neighbouring pixels, and shadow rays from their hits), so it is laid out ahead of the
    // loop with the trace systems that make use of that.
    let bounce = |first: bool| {
        let mut nodes: Vec<Node<PtState>> = vec![if first {
            Node::system(trace::closest::TraceCoherentClosest)
        } else {
            Node::system(trace::closest::TraceClosest)
        }];
        if record {
            nodes.push(Node::system(trace::record_rays::RecordClosestRays));
        }
        if has_emitters {
            nodes.push(Node::system(shade::emitted_light::AddEmittedLight));
        }
        nodes.push(Node::system(shade::sort_by_material::SortByMaterial));
        if data.scene.has_textures() {
            nodes.push(Node::system(shade::look_up_textures::LookUpTextures));
        }
        if light_sampling {
            nodes.push(Node::system(connect::sample_lights::SampleLights));
        }
        for &kind in &kinds {
            nodes.push(Node::system(shade::material::ShadeMaterial(kind)));
        }
        if light_sampling {
            nodes.push(if first {
                Node::system(trace::shadow::TraceCoherentShadow)
            } else {
                Node::system(trace::shadow::TraceShadow)
            });
            if record {
                nodes.push(Node::system(trace::record_rays::RecordShadowRays));
            }
            nodes.push(Node::system(
                connect::apply_shadow::ApplyShadowContributions,
            ));
        }
        nodes.push(Node::system(shade::russian_roulette::RussianRoulette));
        nodes
    };

    let mut nodes = vec![Node::system(generate::camera_rays::GenerateCameraRays)];
    nodes.extend(bounce(true));
    nodes.push(Node::Loop {
        name: "bounces",
        queue_len: |s: &PtState| s.active,
        body: bounce(false),
    });
    nodes.push(Node::system(gather::film::AccumulateFilm));
    Graph::new("pt", nodes)
}

impl IntegratorState for PtState {
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
    fn graph(data: &SceneData, _: &PtSettings) -> Graph<PtState> {
        graph(data)
    }
}

impl WaveState for PtState {
    const WAVEFRONT: usize = WAVEFRONT;
    fn new(data: Arc<SceneData>, settings: PtSettings, capacity: usize) -> PtState {
        PtState::new(data, settings, capacity)
    }
    fn begin_wave(&mut self, wave: Wave) {
        self.wave = wave;
    }
    fn film_mut(&mut self) -> &mut Film {
        &mut self.film
    }
    fn finish(self, _: u64) -> (Film, Vec<(String, Image)>, usize) {
        (self.film, Vec::new(), PtState::bytes_per_path())
    }
}

/// How the path tracer lays out its work (`--kernel`); both render the same image, bit for
/// bit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Kernel {
    /// Waves of paths through the graph's systems, a queue per stage (`graph` above).
    #[default]
    Wavefront,
    /// One path per thread from the camera to its end (`pt_megakernel`).
    Megakernel,
}

impl Kernel {
    pub fn as_str(self) -> &'static str {
        match self {
            Kernel::Wavefront => "wavefront",
            Kernel::Megakernel => "megakernel",
        }
    }
}

impl std::fmt::Display for Kernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// PT as a render asks for it: its kernel and paths in flight (`--kernel`, `--wavefront`).
pub fn render_with(
    data: Arc<SceneData>,
    s: &RenderSettings,
    budget: Budget,
    control: &Control,
    from: Option<Resume>,
) -> RenderOutcome {
    let settings = PtSettings::from(s);
    match s.kernel {
        Kernel::Wavefront => {
            let wavefront = s
                .wavefront
                .unwrap_or_else(|| default_wavefront(data.geometry_bytes()));
            render_waves_of::<PtState>(data, settings, budget, control, from, wavefront)
        }
        Kernel::Megakernel => {
            let wavefront = s.wavefront.unwrap_or_else(default_megakernel_wave);
            render_waves_of::<crate::integrators::pt_megakernel::MegakernelState>(
                data, settings, budget, control, from, wavefront,
            )
        }
    }
}

/// Renders with the path tracer until the budget is spent or a stop is asked for.
pub fn render(
    data: Arc<SceneData>,
    settings: PtSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    let wavefront = default_wavefront(data.geometry_bytes());
    render_waves_of::<PtState>(data, settings, budget, control, None, wavefront)
}

/// The systems of its graphs bound to the columns of `PtState`.
mod bindings {
    use super::PtState;
    use crate::systems::*;

    crate::bind! {
        PtState:
        connect::apply_shadow::ApplyShadowContributions {
            read shadow, len = shadow_len;
            write radiance = paths.radiance;
        }
        connect::sample_lights::SampleLights {
            read data, sampler, lanes = settings.lanes, triangles = hits.triangle, dirs = rays.dir,
                paths, surfaces, materials, ranges;
            write shadow, shadow_len;
        }
        gather::film::AccumulateFilm {
            read sample_radiance, wave, pixels, camera = data.scene.camera, sampler;
            write film;
        }
        generate::camera_rays::GenerateCameraRays {
            read wave, camera = data.scene.camera, pixels, sampler, lanes = settings.lanes;
            write rays, paths, sample_radiance, active;
        }
        shade::emitted_light::AddEmittedLight {
            read data, hits, rays, live = active;
            write paths;
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
        shade::russian_roulette::RussianRoulette {
            read live = active, sampler;
            write paths, rays;
        }
        shade::sort_by_material::SortByMaterial {
            read scene = data.scene, max_depth = settings.max_depth;
            write hits, paths, rays, sample_radiance, ranges, active, scratch, surfaces;
        }
        trace::closest::TraceClosest {
            read accel = data.accel, rays, live = active;
            write hits;
        }
        trace::closest::TraceCoherentClosest {
            read accel = data.accel, rays, live = active;
            write hits;
        }
        trace::record_rays::RecordClosestRays {
            read rays, hits, live = active, wave;
            write record;
        }
        trace::record_rays::RecordShadowRays {
            read shadow, len = shadow_len;
            write record;
        }
        trace::shadow::TraceShadow {
            read accel = data.accel, len = shadow_len;
            write shadow;
        }
        trace::shadow::TraceCoherentShadow {
            read accel = data.accel, len = shadow_len;
            write shadow;
        }
    }
}
