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
//! Its graph, built from the scene: `stagelight graph SCENE --integrator pm` prints it with
//! each system's columns, and the README shows it for `door_ajar`.

use crate::bsdf::MaterialKind;
use crate::components::ShadowRays;
use crate::film::Film;
use crate::integrators::camera_walk::{self, CameraWalk};
use crate::integrators::driver::render_passes;
use crate::integrators::{
    Budget, Control, IntegratorState, PassState, RenderOutcome, RenderSettings, SceneData,
};
use crate::photons::{PhotonMaps, PhotonPass};
use crate::pipeline::{Graph, Node};
use crate::sampling::{Sampler, SamplerKind};
use crate::systems::{connect, gather, generate, trace};
use glam::DVec3;
use std::sync::Arc;

/// Default photons traced.
pub const DEFAULT_PHOTONS: u64 = 250_000;
/// Default photons per density estimate.
pub const DEFAULT_K: usize = 50;
/// Default largest search radius, as a fraction of the scene's bounding-box diagonal.
pub const DEFAULT_MAX_RADIUS_FRACTION: f32 = 0.02;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PmSettings {
    pub seed: u64,
    pub sampler: SamplerKind,
    pub max_depth: u32,
    pub photons: u64,
    /// Photons per density estimate, at least 2 (the k - 1 nearest over the k-th's disc).
    pub k: usize,
    /// Largest search radius in scene units (`None`: `DEFAULT_MAX_RADIUS_FRACTION` of the
    /// scene diagonal).
    pub max_radius: Option<f32>,
    pub final_gather: bool,
}

impl From<&RenderSettings> for PmSettings {
    fn from(s: &RenderSettings) -> PmSettings {
        let p = s.photons;
        PmSettings {
            max_depth: s.max_depth,
            photons: p.photons,
            k: p.k,
            max_radius: p.max_radius,
            final_gather: p.final_gather,
            sampler: s.sampler,
            ..PmSettings::new(s.seed)
        }
    }
}

impl PmSettings {
    pub fn new(seed: u64) -> PmSettings {
        PmSettings {
            seed,
            sampler: SamplerKind::Independent,
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

/// The state of PM: one slot per pixel in every per-pixel store.
pub struct PmState {
    pub data: Arc<SceneData>,
    pub settings: PmSettings,
    pub pixels: usize,
    pub pass: u64,
    /// Chains from the camera to the visible points.
    pub camera_walk: CameraWalk,
    /// Chains from the visible points to where their final-gather rays land.
    pub gather_walk: CameraWalk,
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
        let sampler = Sampler::new(settings.sampler, settings.seed, cam.width, cam.height);
        let mut photon_pass = PhotonPass::new(data.clone(), sampler, settings.max_depth);
        photon_pass.tracing.begin_pass(0, settings.photons);
        let caustics = has_caustics(&data);
        PmState {
            settings,
            pixels,
            pass: 0,
            camera_walk: CameraWalk::new(data.clone(), sampler, settings.max_depth),
            gather_walk: CameraWalk::new(data.clone(), sampler, settings.max_depth),
            shadow: ShadowRays::new(pixels),
            pass_radiance: vec![DVec3::ZERO; pixels],
            photon_pass,
            maps: None,
            caustics,
            film: Film::for_scene(&data),
            nonfinite: 0,
            data,
        }
    }

    /// Bytes of state per pixel: chains and rays (double buffered), hits, visible and gather
    /// points, shadow ray and the pass's radiance.
    pub fn bytes_per_pixel(&self) -> usize {
        2 * CameraWalk::bytes_per_slot()
            + ShadowRays::bytes_per_item()
            + std::mem::size_of::<DVec3>()
    }
}

/// The graph of one pass, for a scene with (`caustics`) or without specular surfaces.
pub fn graph(settings: &PmSettings, caustics: bool) -> Graph<PmState> {
    let mut nodes = vec![
        Node::Once {
            name: "photon_maps",
            needed: |s: &PmState| s.maps.is_none(),
            body: vec![
                Node::nested(
                    crate::photons::graph(),
                    "photon_pass",
                    |s: &mut PmState| &mut s.photon_pass,
                    crate::photons::INPUTS,
                ),
                Node::system(gather::photon_maps::BuildPhotonMaps),
            ],
        },
        Node::nested(
            camera_walk::from_camera("camera_bounces"),
            "camera_walk",
            |s: &mut PmState| &mut s.camera_walk,
            camera_walk::INPUTS,
        ),
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
        nodes.push(Node::nested(
            camera_walk::from_started("gather_bounces"),
            "gather_walk",
            |s: &mut PmState| &mut s.gather_walk,
            camera_walk::INPUTS,
        ));
        nodes.push(Node::system(gather::global_photons::GatherGlobalPhotons));
    } else {
        nodes.push(Node::system(gather::global_photons::GatherIndirectPhotons));
    }
    nodes.push(Node::system(gather::pass_film::AddPassToFilm));
    Graph::new("pm", nodes)
}

impl IntegratorState for PmState {
    type Settings = PmSettings;
    /// The walks, the maps and the photon pass persist across passes.
    const INPUTS: &'static [&'static str] = &[
        "data",
        "settings",
        "pixels",
        "pass",
        "caustics",
        "film",
        "maps",
        "photon_pass",
        "camera_walk",
        "gather_walk",
    ];
    fn graph(data: &SceneData, settings: &PmSettings) -> Graph<PmState> {
        graph(settings, has_caustics(data))
    }
}

impl PassState for PmState {
    fn new(data: Arc<SceneData>, settings: PmSettings) -> PmState {
        assert!(settings.k >= 2, "PM needs k >= 2 (the CLI refuses less)");
        PmState::new(data, settings)
    }
    fn begin_pass(&mut self, pass: u64) {
        self.pass = pass;
        self.camera_walk.sample_index = pass;
        self.camera_walk.starts = self.pixels;
    }
    fn finish(mut self, _: u64) -> (Film, usize, usize) {
        self.film.nonfinite += self.nonfinite;
        let bytes = self.bytes_per_pixel();
        (self.film, bytes, self.pixels)
    }
}

/// Whether the scene has specular surfaces, and so a caustic map.
fn has_caustics(data: &SceneData) -> bool {
    crate::integrators::pt::used_kinds(data).contains(&MaterialKind::Dielectric)
}

/// Renders with PM: the photon maps once, then passes of one camera sample per pixel until
/// the budget (passes, or seconds at a pass boundary) is spent or a stop is asked for.
pub fn render(
    data: Arc<SceneData>,
    settings: PmSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    render_passes::<PmState>(data, settings, budget, control)
}
