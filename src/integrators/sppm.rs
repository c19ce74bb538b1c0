//! Progressive photon mapping (`--integrator ppm`, Hachisuka, Ogaki and Jensen 2008) and
//! stochastic progressive photon mapping (`--integrator sppm`, Hachisuka and Jensen 2009): one
//! graph, the two differing only in when visible points are found.
//!
//! Every pixel has a visible point: where its camera ray, having followed specular bounces,
//! meets a surface that is not specular. Each pass traces `photons_per_pass` photons, gathers
//! those within each pixel's radius R, and updates the pixel's statistics (alpha = 0.7 by
//! default):
//!
//! ```text
//! N' = N + alpha M,   R' = R sqrt(N' / (N + M)),   tau' = (tau + tau_M) N' / (N + M)
//! L  = D / passes + tau / (pi R^2 N_emitted)
//! ```
//!
//! where M photons carrying tau_M = sum beta f(wo, wi) power were found this pass, and D sums
//! over passes what needs no photons: emission seen directly or through specular surfaces,
//! and direct light at the visible point by light sampling (so photons stored at their first
//! surface are not kept: every gathered photon has bounced at least once).
//!
//! PPM finds the visible points once (pass 0's camera rays) and keeps them; SPPM traces new
//! camera rays, with new jitter, every pass, so its estimate also averages over the pixel
//! area, over the choices at glass, and over everything else a camera ray samples. PPM's
//! pixels converge to the value at one fixed point each: aliased edges and whatever one
//! choice at the glass showed stay in its image, whatever the number of passes.
//!
//! Its graph, built from the scene: `stagelight graph SCENE --integrator sppm` prints it with
//! each system's columns, and docs/architecture.md shows it for `door_ajar`.
//!
//! Memory is bounded: per pixel a visible point and its statistics, per pass its photons;
//! nothing grows with the number of passes.

use crate::components::{PixelEstimates, ShadowRays, VisiblePoints};
use crate::film::Film;
use crate::integrators::camera_walk::{self, CameraWalk};
use crate::integrators::driver::render_passes;
use crate::integrators::{
    Budget, Control, IntegratorState, PassState, RenderOutcome, RenderSettings, SceneData,
};
use crate::photons::state::{self, StateReader, StateWriter};
use crate::photons::{HashGrid, PhotonPass};
use crate::pipeline::{Graph, Node};
use crate::sampling::Sampler;
use crate::systems::{connect, gather, shade, trace};
use glam::DVec3;
use std::sync::Arc;

pub use crate::components::photon_mapping::{
    DEFAULT_ALPHA, DEFAULT_EYE_RAYS, DEFAULT_PHOTONS_PER_PASS, PPM_RADIUS_FRACTION,
    ProgressiveSettings, SPPM_RADIUS_FRACTION,
};

impl ProgressiveSettings {
    /// The settings of PPM (`stochastic` false) or SPPM from a render's settings.
    pub fn from_render(s: &RenderSettings, stochastic: bool) -> ProgressiveSettings {
        let p = s.photons;
        ProgressiveSettings {
            max_depth: s.max_depth,
            photons_per_pass: p.photons_per_pass,
            alpha: p.alpha.unwrap_or(DEFAULT_ALPHA),
            initial_radius: p.radius,
            eye_rays: p.eye_rays,
            sampler: s.sampler,
            ..ProgressiveSettings::new(s.seed, stochastic)
        }
    }

    /// Bytes of state a render of `pixels` pixels is expected to need (photons apart): PPM's
    /// grow with its eye rays, about two hit points each where a scene has glass (the torus:
    /// 0.93 per eye ray; `ProgressiveState::bytes` counts what a render holds).
    pub fn expected_bytes(&self, pixels: u64) -> u64 {
        let points = if self.stochastic {
            pixels
        } else {
            pixels.saturating_mul(2 * self.eye_rays as u64)
        };
        let walk = CameraWalk::bytes_per_slot() - VisiblePoints::bytes_per_item();
        pixels
            .saturating_mul(walk as u64)
            .saturating_add(points.saturating_mul(ProgressiveState::bytes_per_point() as u64))
    }
}

/// The state of PPM and SPPM: one slot per pixel in every per-pixel store.
pub struct ProgressiveState {
    pub data: Arc<SceneData>,
    pub settings: ProgressiveSettings,
    pub pixels: usize,
    /// The pass being rendered.
    pub pass: u64,
    /// Chains from the camera to the visible points (found every pass by SPPM, in the first
    /// pass only by PPM).
    pub camera_walk: CameraWalk,
    pub shadow: ShadowRays,
    /// Shadow rays in use: the visible points', then the followed glossy surfaces'.
    pub shadow_len: usize,
    pub estimates: PixelEstimates,
    /// Per pixel, the sum over passes of the light sampled at the glossy surfaces its chains
    /// followed.
    pub glossy_direct: Vec<DVec3>,
    pub photon_pass: PhotonPass,
    /// Grid over this pass's photons (built by `build_photon_grid`).
    pub grid: Option<HashGrid>,
    /// Visible points gathered this pass (`gather_photons` runs in chunks).
    pub gathered: usize,
    /// Photons emitted over all passes.
    pub photons_emitted: u64,
    /// NaN or Inf contributions dropped.
    pub nonfinite: u64,
}

impl ProgressiveState {
    pub fn new(data: Arc<SceneData>, settings: ProgressiveSettings) -> ProgressiveState {
        let cam = data.scene.camera;
        let pixels = cam.width as usize * cam.height as usize;
        let mut estimates = PixelEstimates::new(pixels);
        estimates.radius.fill(settings.radius_in(&data));
        let sampler = Sampler::new(settings.sampler, settings.seed, cam.width, cam.height);
        let mut photon_pass = PhotonPass::new(
            data.clone(),
            sampler,
            crate::photons::deepest_stored_photon(settings.max_depth),
        );
        // Direct light comes from light sampling at the visible points.
        photon_pass.tracing.store_direct = false;
        let mut camera_walk = CameraWalk::new(data.clone(), sampler, settings.max_depth);
        if !settings.stochastic {
            // PPM: the ray trees, whose hit points the first pass appends.
            camera_walk.trace_trees(settings.eye_rays, settings.seed);
        }
        ProgressiveState {
            camera_walk,
            data,
            settings,
            pixels,
            pass: 0,
            shadow: ShadowRays::new(pixels),
            shadow_len: 0,
            estimates,
            glossy_direct: vec![DVec3::ZERO; pixels],
            photon_pass,
            grid: None,
            gathered: 0,
            photons_emitted: 0,
            nonfinite: 0,
        }
    }

    /// Prepares pass `pass`: whether it finds visible points, and its photons.
    pub fn begin_pass(&mut self, pass: u64) {
        self.pass = pass;
        self.gathered = 0;
        let find_visible_points = self.settings.stochastic || pass == 0;
        self.camera_walk.sample_index = pass;
        let chains = if self.settings.stochastic {
            self.pixels
        } else {
            self.pixels * self.camera_walk.trees as usize
        };
        self.camera_walk.starts = if find_visible_points { chains } else { 0 };
        self.camera_walk.started = 0;
        self.photon_pass
            .tracing
            .begin_pass(pass, self.settings.photons_per_pass);
    }

    /// The image so far: per pixel, over its hit points (one, but for PPM's ray trees),
    /// D / passes + tau / (pi R^2 N_emitted), plus the light sampled at the glossy surfaces
    /// its chains followed over passes.
    pub fn film(&self, passes: u64) -> Film {
        let cam = self.data.scene.camera;
        let e = &self.estimates;
        let n_emitted = self.photons_emitted.max(1) as f64;
        let mut nonfinite = self.nonfinite;
        let mut sum = self.glossy_direct.clone();
        let points = self.camera_walk.points.min(e.capacity());
        for i in 0..points {
            let r = e.radius[i] as f64;
            let photons = e.flux[i] / (std::f64::consts::PI * r * r * n_emitted);
            let value = e.direct[i] + photons * passes as f64;
            if value.is_finite() {
                sum[self.camera_walk.visible.pixel[i] as usize] += value;
            } else {
                nonfinite += 1;
            }
        }
        Film::from_parts(
            cam.width as usize,
            cam.height as usize,
            sum,
            vec![passes; self.pixels],
            Vec::new(),
            nonfinite,
        )
        .expect("one sum and count per pixel")
    }

    /// PPM's hit points' and glossy points' hash (`photons::state::points_hash`); 0 for SPPM,
    /// whose visible points are found anew every pass.
    fn hit_points_hash(&self) -> u64 {
        let walk = &self.camera_walk;
        if self.settings.stochastic {
            0
        } else {
            state::points_hash(&walk.visible, walk.points)
                ^ state::points_hash(&walk.glossy, walk.glossy_points).rotate_left(1)
        }
    }

    /// Bytes of state per pixel: the walk's chains and rays (double buffered) and hits, and
    /// per visible point (PPM: per hit point) the point, its shadow ray and its statistics.
    pub fn bytes_per_pixel(&self) -> usize {
        self.bytes().div_ceil(self.pixels.max(1))
    }

    /// Bytes of state: the walk's per-pixel stores, and the visible or hit points with their
    /// shadow rays and statistics (the photons of a pass apart).
    pub fn bytes(&self) -> usize {
        let points = self.camera_walk.visible.capacity().max(self.pixels);
        let glossy = self.camera_walk.glossy.capacity();
        let walk = CameraWalk::bytes_per_slot() - VisiblePoints::bytes_per_item();
        self.pixels * (walk + std::mem::size_of::<DVec3>() + 4)
            + points * Self::bytes_per_point()
            + glossy * (VisiblePoints::bytes_per_item() + ShadowRays::bytes_per_item())
    }

    /// Bytes per visible (or hit) point: the point, its shadow ray and its statistics.
    pub fn bytes_per_point() -> usize {
        ShadowRays::bytes_per_item()
            + PixelEstimates::bytes_per_item()
            + VisiblePoints::bytes_per_item()
    }
}

/// PPM's eye pass alone: pass 0's trees and their hit points ordered (a resumed run's).
fn eye_pass() -> Graph<ProgressiveState> {
    Graph::new(
        "ppm_eye_pass",
        vec![
            Node::nested(
                camera_walk::from_camera_in_waves("camera_bounces"),
                "camera_walk",
                |s: &mut ProgressiveState| &mut s.camera_walk,
                camera_walk::INPUTS,
            ),
            Node::system(shade::order_hit_points::OrderHitPoints),
        ],
    )
}

/// The graph of one pass (PPM's walk starts its trees in waves; see the module's
/// documentation).
pub fn graph(stochastic: bool, glossy: bool) -> Graph<ProgressiveState> {
    let walk = if stochastic {
        camera_walk::from_camera("camera_bounces")
    } else {
        camera_walk::from_camera_in_waves("camera_bounces")
    };
    let mut nodes = vec![
        Node::nested(
            walk,
            "camera_walk",
            |s: &mut ProgressiveState| &mut s.camera_walk,
            camera_walk::INPUTS,
        ),
        Node::system(shade::order_hit_points::OrderHitPoints),
        // The photons before anything the pass adds to the estimates: a stop between chunks
        // of photons drops the pass with the estimates as the last finished pass left them.
        Node::nested(
            crate::photons::graph(),
            "photon_pass",
            |s: &mut ProgressiveState| &mut s.photon_pass,
            crate::photons::INPUTS,
        ),
        Node::system(connect::sample_direct_light::SampleDirectLight),
        Node::system(trace::shadow::TraceShadow),
        Node::system(gather::photon_grid::BuildPhotonGrid),
        Node::Loop {
            name: "gather_chunks",
            queue_len: |s: &ProgressiveState| s.camera_walk.points - s.gathered,
            body: vec![
                Node::StopPoint,
                Node::system(gather::visible_point_photons::GatherPhotons),
            ],
        },
        // What persists across passes is added last, after the stop points: a pass dropped
        // at one leaves the estimates as the last finished pass left them.
        Node::system(gather::direct_light::AddDirectLight),
    ];
    if glossy {
        nodes.push(Node::system(gather::glossy_light::AddGlossyLight));
    }
    nodes.push(Node::system(
        gather::progressive_update::UpdatePixelEstimates,
    ));
    Graph::new(if stochastic { "sppm" } else { "ppm" }, nodes)
}

impl IntegratorState for ProgressiveState {
    type Settings = ProgressiveSettings;
    /// The walk, the estimates and the photon pass persist across passes.
    const INPUTS: &'static [&'static str] = &[
        "data",
        "settings",
        "pixels",
        "pass",
        "camera_walk",
        "estimates",
        "glossy_direct",
        "photon_pass",
        "photons_emitted",
        "nonfinite",
    ];
    fn graph(data: &SceneData, settings: &ProgressiveSettings) -> Graph<ProgressiveState> {
        graph(
            settings.stochastic,
            crate::photons::scene_has_followed_glossy(data),
        )
    }
}

impl PassState for ProgressiveState {
    fn new(data: Arc<SceneData>, settings: ProgressiveSettings) -> ProgressiveState {
        ProgressiveState::new(data, settings)
    }
    fn begin_pass(&mut self, pass: u64) {
        ProgressiveState::begin_pass(self, pass)
    }
    fn save(&self) -> Option<Vec<u8>> {
        let points = self.camera_walk.points;
        let mut w = StateWriter::new(state::PROGRESSIVE_TAG);
        w.u64(self.photons_emitted);
        w.u64(self.nonfinite);
        w.u64(points as u64);
        w.u64(self.hit_points_hash());
        state::write_estimates(&mut w, &self.estimates, points);
        for &g in &self.glossy_direct {
            w.dvec3(g);
        }
        Some(w.0)
    }
    fn restore(&mut self, bytes: &[u8], _passes: u64) {
        if !self.settings.stochastic {
            // PPM's hit points: pass 0's eye rays, traced again from the seed.
            self.begin_pass(0);
            eye_pass().run(self, &mut crate::pipeline::Stats::default());
        }
        let mut r = StateReader::new(bytes, state::PROGRESSIVE_TAG);
        self.photons_emitted = r.u64();
        self.nonfinite = r.u64();
        let (points, hash) = (r.u64() as usize, r.u64());
        assert_eq!(
            (points, hash),
            (self.camera_walk.points, self.hit_points_hash()),
            "the saved statistics belong to other visible points"
        );
        state::read_estimates(&mut r, &mut self.estimates, points);
        for g in &mut self.glossy_direct {
            *g = r.dvec3();
        }
        r.finish();
    }
    fn report(&self) -> Vec<(&'static str, String)> {
        let mib = self.bytes() as f64 / (1 << 20) as f64;
        let line = if self.settings.stochastic {
            format!(
                "{} visible points, one per pixel, {mib:.1} MiB with the walk",
                self.pixels
            )
        } else {
            let points = self.camera_walk.points;
            format!(
                "{points} hit points ({:.2} per pixel, of {} eye-ray trees each), {mib:.1} MiB \
                 with the walk",
                points as f64 / self.pixels.max(1) as f64,
                self.camera_walk.trees
            )
        };
        let s = &self.data.scene;
        let diagonal = (s.bounds_max - s.bounds_min).length();
        let radius = self.settings.radius_in(&self.data);
        let footprint = crate::components::photon_mapping::pixel_footprint(&self.data)
            .map_or(String::new(), |f| {
                format!(", {:.2} pixel footprints of {f:.4e}", radius / f)
            });
        let radius = format!(
            "initial {radius:.4e} ({:.3}% of the scene's diagonal {diagonal:.4e}{footprint})",
            100.0 * radius / diagonal
        );
        vec![("state", line), ("radius", radius)]
    }
    fn finish(self, passes: u64) -> (Film, usize, usize) {
        (self.film(passes), self.bytes_per_pixel(), self.pixels)
    }
}

/// Renders with PPM or SPPM: a sample budget is a number of passes, a time budget ends at
/// the first pass boundary past it (at least one pass).
pub fn render(
    data: Arc<SceneData>,
    settings: ProgressiveSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    render_passes::<ProgressiveState>(data, settings, budget, control)
}

/// Runs `passes` passes and returns the state (for tests of the statistics).
pub fn run_passes(
    data: Arc<SceneData>,
    settings: ProgressiveSettings,
    passes: u64,
) -> ProgressiveState {
    crate::integrators::driver::run_passes(data, settings, passes)
}

/// The systems of its graphs bound to the columns of `ProgressiveState`.
mod bindings {
    use super::ProgressiveState;
    use crate::systems::*;

    crate::bind! {
        ProgressiveState:
        connect::sample_direct_light::SampleDirectLight {
            read data, visible = camera_walk.visible, points = camera_walk.points,
                glossy = camera_walk.glossy, glossy_points = camera_walk.glossy_points,
                sampler = camera_walk.sampler, index = pass;
            write shadow, shadow_len;
        }
        gather::direct_light::AddDirectLight {
            read visible = camera_walk.visible, points = camera_walk.points, shadow;
            write direct = estimates.direct, nonfinite;
        }
        gather::glossy_light::AddGlossyLight {
            read glossy = camera_walk.glossy, glossy_points = camera_walk.glossy_points,
                points = camera_walk.points, shadow;
            write sums = glossy_direct, nonfinite;
        }
        gather::photon_grid::BuildPhotonGrid {
            read radius = estimates.radius, triangle = camera_walk.visible.triangle,
                points = camera_walk.points, tracing = photon_pass.tracing;
            write grid;
        }
        gather::progressive_update::UpdatePixelEstimates {
            read alpha = settings.alpha, points = camera_walk.points,
                emitted = photon_pass.tracing.emitted;
            write estimates, nonfinite, photons_emitted;
        }
        gather::visible_point_photons::GatherPhotons {
            read data, visible = camera_walk.visible, tracing = photon_pass.tracing, grid,
                hit_points = camera_walk.points, max_depth = settings.max_depth;
            write estimates, gathered;
        }
        shade::order_hit_points::OrderHitPoints {
            read data, settings, tree = camera_walk.tree, starts = camera_walk.starts,
                points = camera_walk.points;
            write visible = camera_walk.visible, estimates, shadow;
        }
        trace::shadow::TraceShadow {
            read accel = data.accel, len = shadow_len;
            write shadow;
        }
    }
}
