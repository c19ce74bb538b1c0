//! Camera chains of the photon mappers as a state of their own: one chain per pixel follows
//! specular bounces from the camera (or from a final-gather direction) to the first surface
//! that is not specular, which becomes its pixel's gather point in `visible`. PM runs two
//! walks (to the visible points, then to the final-gather points), PPM and SPPM one; each is a
//! nested graph over its walk.
//!
//! PPM's walk is a ray tree (Hachisuka, Ogaki and Jensen 2008): at a smooth dielectric a
//! chain follows both the reflection and the refraction, each weighted by its Fresnel term,
//! so a pixel owns a hit point at every non-specular surface its tree reaches. Branches
//! lighter than `MIN_BRANCH_WEIGHT` or deeper than `TREE_DEPTH` end (nothing is chosen at
//! random, so the hit points, kept for the whole render, carry no frozen choice). A pixel
//! traces `trees` such trees, their eye rays jittered over the pixel as the points of a
//! stratified net (Hachisuka et al. shoot several eye rays per pixel: PPM's hit points stay
//! where the first pass put them, so only they can average the pixel's area). The trees start
//! in waves of one chain per pixel, so the walk's stores never hold more than a pixel's worth
//! of chains and branches at a time.

use crate::components::{CameraChains, Hits, Rays, VisiblePoint, VisiblePoints};
use crate::sampling::SampleKey;
use crate::sampling::{Sampler, SamplerKind};
use crate::scene::SceneData;
use glam::Vec3;
use std::sync::Arc;

/// Chains in flight (slots `0..active`) with their rays and hits, the scratch stores that
/// compaction swaps them with, and the gather points the ended chains write: one slot per
/// pixel, allocated once.
pub struct CameraWalk {
    pub data: Arc<SceneData>,
    pub sampler: Sampler<'static>,
    /// Maximum number of bounces of a path (a path tracer's count: the camera ray's first
    /// hit is depth 0); `u32::MAX` for unlimited. Chains follow surfaces below it and keep
    /// gather points only below it.
    pub max_depth: u32,
    /// Sample index of the chains `generate_camera_chains` starts (the pass).
    pub sample_index: u64,
    /// Chains the walk starts: one per pixel, `trees` per pixel (PPM's first pass), or none
    /// (PPM after its first pass keeps its gather points).
    pub starts: usize,
    /// Chains started so far: `generate_camera_chains` starts at most one per pixel at a time.
    pub started: usize,
    /// Eye-ray trees per pixel (PPM); chain c of a walk is tree c / pixels of pixel
    /// c % pixels.
    pub trees: u32,
    /// Where the trees' eye rays go in their pixel: ZSobol with `trees` samples per pixel, so
    /// a pixel's jitters are a stratified net whatever the render's sampler.
    pub jitter: Sampler<'static>,
    pub chains: CameraChains,
    pub rays: Rays,
    pub hits: Hits,
    pub active: usize,
    pub scratch_chains: CameraChains,
    pub scratch_rays: Rays,
    pub order: Vec<u32>,
    /// Where ended chains go: at their pixel's slot, or (`tree`) appended.
    pub visible: VisiblePoints,
    /// Entries of `visible` in use: every pixel's slot, or the hit points of the tree.
    pub points: usize,
    /// Follow both branches at dielectrics (PPM's ray tree) instead of sampling one.
    pub tree: bool,
    /// Per chunk of chains, the branches it split off this bounce (started in chunk order).
    pub spawned: Vec<Vec<Branch>>,
    /// Sample light at the followed glossy surfaces (camera walks; not PM's gather walk,
    /// whose emission the caustic map covers).
    pub direct_light: bool,
    /// The followed glossy surfaces the chains met (`glossy_points` of them), each with the
    /// chain's weight there: the integrator samples light at them, with MIS against the
    /// chain's own bounce, and adds it to their pixel.
    pub glossy: VisiblePoints,
    pub glossy_points: usize,
    /// Glossy points so far per pixel (their `branch`).
    pub glossy_rank: Vec<u32>,
    /// Per chunk of chains, the glossy points it met this bounce (kept in chunk order).
    pub met_glossy: Vec<Vec<VisiblePoint>>,
}

/// A branch of the ray tree split off at a dielectric, to start as a chain of its own.
#[derive(Clone, Copy, Debug)]
pub struct Branch {
    pub pixel: u32,
    pub key: SampleKey,
    pub beta: Vec3,
    pub depth: u32,
    pub origin: Vec3,
    pub dir: Vec3,
}

/// Ray-tree branches whose weight (largest channel of the product of Fresnel terms) falls
/// below this end: a pixel then owns at most a few hundred hit points, and what is lost is
/// at most this fraction of the pixel per branch cut.
pub const MIN_BRANCH_WEIGHT: f32 = 1e-3;
/// Deepest bounce of a ray-tree branch (total internal reflection keeps a branch's weight).
pub const TREE_DEPTH: u32 = 32;

/// Columns set before a walk's graph runs (for `Graph::check`); `visible` persists across
/// passes.
pub const INPUTS: &[&str] = &[
    "data",
    "sampler",
    "max_depth",
    "sample_index",
    "starts",
    "started",
    "trees",
    "jitter",
    "scratch_chains",
    "scratch_rays",
    "order",
    "visible",
    "points",
    "tree",
    "spawned",
    "direct_light",
    "glossy",
    "glossy_points",
    "glossy_rank",
    "met_glossy",
];

impl CameraWalk {
    pub fn new(data: Arc<SceneData>, sampler: Sampler<'static>, max_depth: u32) -> CameraWalk {
        let cam = data.scene.camera;
        let slots = cam.width as usize * cam.height as usize;
        CameraWalk {
            data,
            sampler,
            max_depth,
            sample_index: 0,
            starts: 0,
            started: 0,
            trees: 1,
            jitter: sampler,
            chains: CameraChains::new(slots),
            rays: Rays::new(slots),
            hits: Hits::new(slots),
            active: 0,
            scratch_chains: CameraChains::new(slots),
            scratch_rays: Rays::new(slots),
            order: Vec::with_capacity(slots),
            visible: VisiblePoints::new(slots),
            points: slots,
            tree: false,
            spawned: Vec::new(),
            direct_light: true,
            glossy: VisiblePoints::new(0),
            glossy_points: 0,
            glossy_rank: vec![0; slots],
            met_glossy: Vec::new(),
        }
    }

    /// Makes the walk PPM's: `trees` ray trees per pixel, their hit points appended.
    pub fn trace_trees(&mut self, trees: u32, seed: u64) {
        let cam = self.data.scene.camera;
        self.tree = true;
        self.points = 0;
        self.trees = trees.max(1);
        self.jitter = Sampler::new(SamplerKind::Sobol, seed, cam.width, cam.height)
            .with_samples_per_pixel(self.trees as u64);
    }

    /// Chains of the next wave: at most one per pixel.
    pub fn next_wave(&self) -> usize {
        let cam = self.data.scene.camera;
        let pixels = cam.width as usize * cam.height as usize;
        (self.starts - self.started).min(pixels)
    }

    /// Bytes per slot: chains and rays (double buffered), hits, compaction order and the
    /// gather point.
    pub fn bytes_per_slot() -> usize {
        2 * (CameraChains::bytes_per_item() + Rays::bytes_per_item())
            + Hits::bytes_per_item()
            + std::mem::size_of::<u32>()
            + VisiblePoints::bytes_per_item()
    }
}
