//! The graphs of a camera walk (`crate::components::camera_walk`): from the camera, in waves
//! of trees, or from chains already started (final gathering).

pub use crate::components::camera_walk::*;
use crate::pipeline::{Graph, Node};
use crate::systems::{generate, shade, trace};

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

/// PPM's walk: `loop camera_waves` of one chain per pixel (a tree each) until `starts` have
/// started, each wave followed by `loop NAME` until its chains and branches have ended.
pub fn from_camera_in_waves(loop_name: &'static str) -> Graph<CameraWalk> {
    Graph::new(
        "camera_walk",
        vec![Node::Loop {
            name: "camera_waves",
            queue_len: CameraWalk::next_wave,
            body: vec![
                // PPM's first pass may stop between waves of its eye rays (the pass, the
                // only one with hit points to find, is then dropped whole).
                Node::StopPoint,
                Node::system(generate::camera_chains::GenerateCameraChains),
                bounces(loop_name),
            ],
        }],
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

/// The systems of its graphs bound to the columns of `CameraWalk`.
mod bindings {
    use super::CameraWalk;
    use crate::systems::*;

    crate::bind! {
        CameraWalk:
        generate::camera_chains::GenerateCameraChains {
            read camera = data.scene.camera, sampler, jitter, sample_index, starts, tree, trees;
            write chains, rays, active, points, started, glossy_points, glossy_rank;
        }
        shade::compact_camera_chains::CompactCameraChains {
            read tree;
            write chains, rays, hits, active, visible, points, spawned, order, scratch_chains,
                scratch_rays, glossy, glossy_points, glossy_rank, met_glossy;
        }
        shade::extend_camera_chains::ExtendCameraChains {
            read scene = data.scene, sampler, max_depth, tree, direct_light, hits, live = active;
            write chains, rays, spawned, met_glossy;
        }
        trace::closest::TraceClosest {
            read accel = data.accel, rays, live = active;
            write hits;
        }
    }
}
