//! Photon mapping (`--integrator pm`, Jensen 1996): photons are traced once, into a global
//! map (every photon stored on a surface that is not specular) and, where the scene has
//! specular surfaces, a caustic map (photons whose path from the light is L S+ D). Then every
//! pass shoots one camera ray per pixel, follows its specular bounces to the first surface
//! that is not specular (the visible point), and adds there:
//!
//! - direct light, by light sampling;
//! - caustics, by a density estimate in the caustic map (its k nearest photons);
//! - indirect light, by final gathering: one BSDF sample from the visible point, followed
//!   through specular bounces, and a global-map density estimate where it lands. Without
//!   final gathering (`final_gather: false`), a global-map estimate at the visible point
//!   itself, of the photons that are neither direct nor caustic.
//!
//! A density estimate of k photons is sum f(wo, wi) power / (pi r^2 N_emitted), r the distance
//! to the k-th nearest (at most `max_radius`). The result is biased (blurred by r) and the bias
//! does not fall with passes: only more photons shrink it.
//!
//! The graph (the caustic system only when the scene has specular surfaces):
//!
//! ```text
//! loop photon_maps (pass 0 only):
//!     photons                       (nested: emit, then trace -> scatter -> compact)
//!     build_photon_maps             kd-trees over the global and caustic photons
//! generate_camera_chains
//! loop camera_bounces: trace_closest -> extend_camera_chains -> compact_camera_chains
//! sample_direct_light -> trace_shadow -> add_direct_light
//! gather_caustics
//! generate_final_gather_rays        (final gathering)
//! loop gather_bounces: trace_closest -> extend_camera_chains -> compact_camera_chains
//! gather_global_photons
//! add_pass_to_film
//! ```

use crate::bsdf::MaterialKind;
use crate::components::{Hits, Rays, ShadowRays, VisiblePoints};
use crate::film::Film;
use crate::integrators::{Budget, Control, RenderOutcome, SceneData, pass_by_pass};
use crate::photons::{PhotonMaps, PhotonPass};
use crate::pipeline::{Graph, Node, Stats};
use crate::systems::shade::extend_camera_chains::ChainWavefront;
use crate::systems::{connect, gather, generate, shade, trace};
use glam::DVec3;
use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

/// Default photons traced.
pub const DEFAULT_PHOTONS: u64 = 250_000;
/// Default photons per density estimate.
pub const DEFAULT_K: usize = 50;
/// Default largest search radius, as a fraction of the scene's bounding-box diagonal.
pub const DEFAULT_MAX_RADIUS_FRACTION: f32 = 0.02;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PmSettings {
    pub seed: u64,
    pub max_depth: u32,
    pub photons: u64,
    /// Photons per density estimate, at least 2 (the k - 1 nearest over the k-th's disc).
    pub k: usize,
    /// Largest search radius in scene units (`None`: `DEFAULT_MAX_RADIUS_FRACTION` of the
    /// scene diagonal).
    pub max_radius: Option<f32>,
    pub final_gather: bool,
}

impl PmSettings {
    pub fn new(seed: u64) -> PmSettings {
        PmSettings {
            seed,
            max_depth: u32::MAX,
            photons: DEFAULT_PHOTONS,
            k: DEFAULT_K,
            max_radius: None,
            final_gather: true,
        }
    }

    pub fn max_radius_in(&self, data: &SceneData) -> f32 {
        self.max_radius.unwrap_or_else(|| {
            let s = &data.scene;
            DEFAULT_MAX_RADIUS_FRACTION * (s.bounds_max - s.bounds_min).length()
        })
    }
}

/// Which surfaces the camera chains are looking for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChainPhase {
    /// From the camera to the visible points.
    Camera,
    /// From the visible points to the final-gather points.
    FinalGather,
}

pub struct PmState {
    pub data: Arc<SceneData>,
    pub settings: PmSettings,
    pub pixels: usize,
    pub pass: u64,
    pub phase: ChainPhase,
    pub wave: ChainWavefront,
    pub visible: VisiblePoints,
    /// Where each pixel's final-gather ray landed (slot = pixel).
    pub gather_points: VisiblePoints,
    pub shadow: ShadowRays,
    /// This pass's radiance per pixel.
    pub pass_radiance: Vec<DVec3>,
    pub photon_pass: PhotonPass,
    pub maps: Option<PhotonMaps>,
    /// Whether the scene has specular surfaces (and so a caustic map).
    pub caustics: bool,
    pub film: Film,
    pub nonfinite: u64,
}

impl PmState {
    pub fn new(data: Arc<SceneData>, settings: PmSettings) -> PmState {
        let cam = data.scene.camera;
        let pixels = cam.width as usize * cam.height as usize;
        let mut photon_pass = PhotonPass::new(data.clone(), settings.seed, settings.max_depth);
        photon_pass.tracing.begin_pass(0, settings.photons);
        let caustics =
            crate::integrators::pt::used_kinds(&data).contains(&MaterialKind::Dielectric);
        PmState {
            settings,
            pixels,
            pass: 0,
            phase: ChainPhase::Camera,
            wave: ChainWavefront::new(pixels),
            visible: VisiblePoints::new(pixels),
            gather_points: VisiblePoints::new(pixels),
            shadow: ShadowRays::new(pixels),
            pass_radiance: vec![DVec3::ZERO; pixels],
            photon_pass,
            maps: None,
            caustics,
            film: Film::new(cam.width as usize, cam.height as usize),
            nonfinite: 0,
            data,
        }
    }

    /// Bytes of state per pixel: chains and rays (double buffered), hits, visible and gather
    /// points, shadow ray and the pass's radiance.
    pub fn bytes_per_pixel(&self) -> usize {
        ChainWavefront::bytes_per_slot()
            + 2 * VisiblePoints::bytes_per_item()
            + ShadowRays::bytes_per_item()
            + std::mem::size_of::<DVec3>()
    }
}

impl crate::systems::trace::closest::ClosestHitQueue for PmState {
    fn closest_hit_queue(&mut self) -> (&crate::accel::Accel, &Rays, &mut Hits, usize) {
        (
            &self.data.accel,
            &self.wave.rays,
            &mut self.wave.hits,
            self.wave.active,
        )
    }
}

impl crate::systems::trace::shadow::ShadowQueue for PmState {
    fn shadow_queue(&mut self) -> (&crate::accel::Accel, &mut ShadowRays, Range<usize>) {
        (&self.data.accel, &mut self.shadow, 0..self.pixels)
    }
}

impl shade::extend_camera_chains::CameraChainQueue for PmState {
    fn new_chains(&self) -> (u64, u64, usize) {
        (self.settings.seed, self.pass, self.pixels)
    }

    fn camera_chain_queue(&mut self) -> shade::extend_camera_chains::ChainQueue<'_> {
        let visible = match self.phase {
            ChainPhase::Camera => &mut self.visible,
            ChainPhase::FinalGather => &mut self.gather_points,
        };
        self.wave
            .queue(&self.data, self.settings.max_depth, visible)
    }
}

impl connect::sample_direct_light::VisiblePointLights for PmState {
    fn direct_light_queue(&mut self) -> connect::sample_direct_light::DirectLightQueue<'_> {
        connect::sample_direct_light::DirectLightQueue {
            data: &self.data,
            visible: &self.visible,
            shadow: &mut self.shadow,
            direct: &mut self.pass_radiance,
            seed: self.settings.seed,
            sample_index: self.pass,
            nonfinite: &mut self.nonfinite,
        }
    }
}

fn camera_bounces(name: &'static str) -> Node<PmState> {
    Node::Loop {
        name,
        queue_len: |s: &PmState| s.wave.active,
        body: vec![
            Node::system(trace::closest::TraceClosest),
            Node::system(shade::extend_camera_chains::ExtendCameraChains),
            Node::system(shade::compact_camera_chains::CompactCameraChains),
        ],
    }
}

/// The graph of one pass, for a scene with (`caustics`) or without specular surfaces.
pub fn graph(settings: &PmSettings, caustics: bool) -> Graph<PmState> {
    let mut nodes = vec![
        Node::Loop {
            name: "photon_maps",
            queue_len: |s: &PmState| s.maps.is_none() as usize,
            body: vec![
                Node::nested(crate::photons::graph(), |s: &mut PmState| {
                    &mut s.photon_pass
                }),
                Node::system(gather::photon_maps::BuildPhotonMaps),
            ],
        },
        Node::system(generate::camera_chains::GenerateCameraChains),
        camera_bounces("camera_bounces"),
        Node::system(connect::sample_direct_light::SampleDirectLight),
        Node::system(trace::shadow::TraceShadow),
        Node::system(gather::direct_light::AddDirectLight),
    ];
    if caustics {
        nodes.push(Node::system(gather::caustic_photons::GatherCaustics));
    }
    if settings.final_gather {
        nodes.push(Node::system(
            generate::final_gather_rays::GenerateFinalGatherRays,
        ));
        nodes.push(Node::system(
            shade::compact_camera_chains::CompactCameraChains,
        ));
        nodes.push(camera_bounces("gather_bounces"));
    }
    nodes.push(Node::system(gather::global_photons::GatherGlobalPhotons));
    nodes.push(Node::system(gather::pass_film::AddPassToFilm));
    Graph::new("pm", nodes)
}

/// Renders with PM: the photon maps once, then passes of one camera sample per pixel until
/// the budget (passes, or seconds at a pass boundary) is spent or a stop is asked for.
pub fn render(
    data: Arc<SceneData>,
    settings: PmSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    assert!(settings.k >= 2, "PM needs k >= 2 (the CLI refuses less)");
    let start = Instant::now();
    let mut state = PmState::new(data, settings);
    let graph = graph(&settings, state.caustics);
    let mut stats = Stats::default();
    let (passes, interrupted) = pass_by_pass(budget, control, |pass| {
        state.pass = pass;
        state.phase = ChainPhase::Camera;
        graph.run(&mut state, &mut stats);
    });
    state.film.nonfinite += state.nonfinite;
    RenderOutcome {
        bytes_per_path: state.bytes_per_pixel(),
        wavefront: state.pixels,
        film: state.film,
        stats,
        passes,
        samples: passes * state.pixels as u64,
        wall: start.elapsed(),
        interrupted,
        systems: graph.system_names(),
        layers: Vec::new(),
    }
}
