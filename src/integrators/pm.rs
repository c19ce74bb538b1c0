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
//! each system's columns, and docs/architecture.md shows it for `door_ajar`.

use crate::components::ShadowRays;
use crate::film::Film;
use crate::integrators::camera_walk::{self, CameraWalk};
use crate::integrators::driver::render_passes;
use crate::integrators::{
    Budget, Control, IntegratorState, PassState, RenderOutcome, RenderSettings, SceneData,
};
use crate::photons::state::{self, StateReader, StateWriter};
use crate::photons::{PhotonMaps, PhotonPass};
use crate::pipeline::{Graph, Node};
use crate::sampling::Sampler;
use crate::systems::{connect, gather, generate, trace};
use glam::DVec3;
use std::sync::Arc;

pub use crate::components::photon_mapping::{
    DEFAULT_K, DEFAULT_MAX_RADIUS_FRACTION, DEFAULT_PHOTONS, PmSettings,
};

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
    /// Shadow rays in use: the visible points', then the followed glossy surfaces'.
    pub shadow_len: usize,
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
        let mut photon_pass = PhotonPass::new(
            data.clone(),
            sampler,
            crate::photons::deepest_stored_photon(settings.max_depth),
        );
        photon_pass.tracing.begin_pass(0, settings.photons);
        let caustics = has_caustics(&data);
        PmState {
            settings,
            pixels,
            pass: 0,
            camera_walk: CameraWalk::new(data.clone(), sampler, settings.max_depth),
            gather_walk: CameraWalk {
                // Light reached through the gather walk is the caustic map's.
                direct_light: false,
                ..CameraWalk::new(data.clone(), sampler, settings.max_depth)
            },
            shadow: ShadowRays::new(pixels),
            shadow_len: 0,
            pass_radiance: vec![DVec3::ZERO; pixels],
            photon_pass,
            maps: None,
            caustics,
            // One sample per pixel per pass, the filter already in its camera chain's weight
            // (`generate_camera_chains`): the film's own is the box.
            film: Film::for_scene(&data).with_filter(crate::film::PixelFilter::Box),
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

/// The graph of one pass, for a scene with (`caustics`) or without surfaces camera chains
/// follow, and with (`glossy`) or without glossy ones among them.
pub fn graph(settings: &PmSettings, caustics: bool, glossy: bool) -> Graph<PmState> {
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
    if glossy {
        nodes.push(Node::system(gather::glossy_light::AddGlossyLight));
    }
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
        graph(
            settings,
            has_caustics(data),
            crate::photons::scene_has_followed_glossy(data),
        )
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
        self.camera_walk.started = 0;
    }
    fn save(&self) -> Option<Vec<u8>> {
        let mut w = StateWriter::new(state::PM_TAG);
        w.u64(self.nonfinite);
        state::write_film(&mut w, &self.film);
        Some(w.0)
    }
    fn restore(&mut self, bytes: &[u8], _passes: u64) {
        // The maps are traced again (from the seed) by the first pass run.
        let mut r = StateReader::new(bytes, state::PM_TAG);
        self.nonfinite = r.u64();
        self.film = state::read_film(&mut r, self.film.width, self.film.height);
        r.finish();
    }
    fn finish(mut self, _: u64) -> (Film, usize, usize) {
        self.film.nonfinite += self.nonfinite;
        let bytes = self.bytes_per_pixel();
        (self.film, bytes, self.pixels)
    }
}

/// Whether the scene has surfaces camera chains follow (specular, or nearly: see
/// `photons::chains_follow`), and so a caustic map.
fn has_caustics(data: &SceneData) -> bool {
    crate::photons::scene_has_followed(data)
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

/// The systems of its graphs bound to the columns of `PmState`.
mod bindings {
    use super::PmState;
    use crate::systems::*;

    crate::bind! {
        PmState:
        connect::sample_direct_light::SampleDirectLight {
            read data, visible = camera_walk.visible, points = camera_walk.points,
                glossy = camera_walk.glossy, glossy_points = camera_walk.glossy_points,
                sampler = camera_walk.sampler, index = pass;
            write shadow, shadow_len;
        }
        gather::caustic_photons::GatherCaustics {
            read data, settings, maps, visible = camera_walk.visible, pixels;
            write pass_radiance, nonfinite;
        }
        gather::direct_light::AddDirectLight {
            read visible = camera_walk.visible, points = camera_walk.points, shadow;
            write direct = pass_radiance, nonfinite;
        }
        gather::global_photons::GatherGlobalPhotons {
            read data, settings, maps, points = gather_walk.visible;
            write pass_radiance, nonfinite;
        }
        gather::global_photons::GatherIndirectPhotons {
            read data, settings, maps, points = camera_walk.visible;
            write pass_radiance, nonfinite;
        }
        gather::glossy_light::AddGlossyLight {
            read glossy = camera_walk.glossy, glossy_points = camera_walk.glossy_points,
                points = camera_walk.points, shadow;
            write sums = pass_radiance, nonfinite;
        }
        gather::pass_film::AddPassToFilm {
            read pixels;
            write pass_radiance, film;
        }
        gather::photon_maps::BuildPhotonMaps {
            read caustics;
            write tracing = photon_pass.tracing, maps;
        }
        generate::final_gather_rays::GenerateFinalGatherRays {
            read scene = data.scene, visible = camera_walk.visible, sampler = gather_walk.sampler,
                pass, pixels;
            write chains = gather_walk.chains, rays = gather_walk.rays, active = gather_walk.active;
        }
        trace::shadow::TraceShadow {
            read accel = data.accel, len = shadow_len;
            write shadow;
        }
    }
}
