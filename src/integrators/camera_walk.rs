//! Camera chains of the photon mappers as a state of their own: one chain per pixel follows
//! specular bounces from the camera (or from a final-gather direction) to the first surface
//! that is not specular, which becomes its pixel's gather point in `visible`. PM runs two
//! walks (to the visible points, then to the final-gather points), PPM and SPPM one; each is a
//! nested graph over its walk.

use crate::components::{CameraChains, Hits, Rays, VisiblePoints};
use crate::pipeline::{Graph, Node};
use crate::sampling::Sampler;
use crate::scene::SceneData;
use crate::systems::{generate, shade, trace};
use std::sync::Arc;

/// Chains in flight (slots `0..active`) with their rays and hits, the scratch stores that
/// compaction swaps them with, and the gather points the ended chains write: one slot per
/// pixel, allocated once.
pub struct CameraWalk {
    pub data: Arc<SceneData>,
    pub sampler: Sampler<'static>,
    /// Maximum number of specular bounces; `u32::MAX` for unlimited.
    pub max_depth: u32,
    /// Sample index of the chains `generate_camera_chains` starts (the pass).
    pub sample_index: u64,
    /// Chains `generate_camera_chains` starts: one per pixel, or none (PPM after its first
    /// pass keeps its gather points).
    pub starts: usize,
    pub chains: CameraChains,
    pub rays: Rays,
    pub hits: Hits,
    pub active: usize,
    pub scratch_chains: CameraChains,
    pub scratch_rays: Rays,
    pub order: Vec<u32>,
    /// Where ended chains go, at their pixel's slot.
    pub visible: VisiblePoints,
}

/// Columns set before a walk's graph runs (for `Graph::check`); `visible` persists across
/// passes.
pub const INPUTS: &[&str] = &[
    "data",
    "sampler",
    "max_depth",
    "sample_index",
    "starts",
    "scratch_chains",
    "scratch_rays",
    "order",
    "visible",
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
            chains: CameraChains::new(slots),
            rays: Rays::new(slots),
            hits: Hits::new(slots),
            active: 0,
            scratch_chains: CameraChains::new(slots),
            scratch_rays: Rays::new(slots),
            order: Vec::with_capacity(slots),
            visible: VisiblePoints::new(slots),
        }
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

/// The walk from the camera: one chain per pixel (`starts` of them), then `loop NAME` until
/// every chain has ended.
pub fn from_camera(loop_name: &'static str) -> Graph<CameraWalk> {
    Graph::new(
        "camera_walk",
        vec![
            Node::system(generate::camera_chains::GenerateCameraChains),
            bounces(loop_name),
        ],
    )
}

/// The walk of chains started by another system (PM's final gathering): the chains it left
/// dead end at once, then `loop NAME`.
pub fn from_started(loop_name: &'static str) -> Graph<CameraWalk> {
    Graph::new(
        "gather_walk",
        vec![
            Node::system(shade::compact_camera_chains::CompactCameraChains),
            bounces(loop_name),
        ],
    )
}

fn bounces(name: &'static str) -> Node<CameraWalk> {
    Node::Loop {
        name,
        queue_len: |w: &CameraWalk| w.active,
        body: vec![
            Node::system(trace::closest::TraceClosest),
            Node::system(shade::extend_camera_chains::ExtendCameraChains),
            Node::system(shade::compact_camera_chains::CompactCameraChains),
        ],
    }
}
