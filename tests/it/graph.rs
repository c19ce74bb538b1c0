//! Each scene's path-tracing graph holds the systems the scene needs and no others, and every
//! column a system reads is written by an earlier system or is an input of the wave.

use crate::common::*;
use stagelight::integrators::{SceneData, pt};

fn graph_systems(scene: &str) -> Vec<&'static str> {
    let data = SceneData::new(load_small(scene, 8));
    let graph = pt::graph(&data);
    let missing = graph.unsatisfied_reads(&["wave", "camera", "emitters"]);
    assert!(
        missing.is_empty(),
        "{scene}: reads nobody writes: {missing:?}"
    );
    graph.system_names()
}

#[test]
fn graphs_follow_the_materials_in_use() {
    let shading = |scene: &str| -> Vec<&'static str> {
        graph_systems(scene)
            .into_iter()
            .filter(|s| s.starts_with("shade_"))
            .collect()
    };
    assert_eq!(shading("cornell_box.ron"), ["shade_diffuse"]);
    assert_eq!(shading("furnace.ron"), ["shade_diffuse"]);
    assert_eq!(
        shading("torus_glass.ron"),
        ["shade_diffuse", "shade_dielectric"]
    );
    assert_eq!(
        shading("door_ajar.ron"),
        ["shade_diffuse", "shade_dielectric", "shade_conductor"]
    );
}

#[test]
fn every_scene_samples_lights_and_traces_shadows() {
    for scene in [
        "cornell_box.ron",
        "torus_glass.ron",
        "door_ajar.ron",
        "furnace.ron",
    ] {
        let systems = graph_systems(scene);
        for s in [
            "generate_camera_rays",
            "trace_closest",
            "sample_lights",
            "trace_shadow",
        ] {
            assert!(systems.contains(&s), "{scene} lacks {s}");
        }
    }
}
