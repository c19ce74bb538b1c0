//! Every integrator's graph on every scene holds the systems the scene needs and no others,
//! and reads every column only after a system (or the driver) has written it.

use crate::common::*;
use stagelight::integrators::{IntegratorKind, IntegratorState, RenderSettings, SceneData, pt};

const SCENES: [&str; 4] = [
    "cornell_box.ron",
    "torus_glass.ron",
    "door_ajar.ron",
    "furnace.ron",
];

fn pt_systems(scene: &str) -> Vec<&'static str> {
    let data = SceneData::new(load_small(scene, 8));
    pt::graph(&data).system_names()
}

#[test]
fn every_graph_of_every_integrator_reads_only_what_was_written_before() {
    for scene in SCENES {
        let data = SceneData::new(load_small(scene, 8));
        for kind in IntegratorKind::all() {
            for final_gather in [true, false] {
                let mut settings = RenderSettings::default();
                settings.photons.final_gather = final_gather;
                let report = (kind.info().graph)(&data, &settings);
                assert!(
                    report.problems.is_empty(),
                    "{scene}, {kind}:\n{}{:#?}",
                    report.description,
                    report.problems
                );
            }
        }
    }
}

#[test]
fn the_check_finds_a_read_before_its_write() {
    let data = SceneData::new(load_small("cornell_box.ron", 8));
    let graph = pt::graph(&data);
    // Without the wave set by the driver, the camera rays read what nobody wrote.
    let inputs: Vec<&str> = <pt::PtState as IntegratorState>::INPUTS
        .iter()
        .copied()
        .filter(|c| *c != "wave")
        .collect();
    let problems = graph.check(&inputs);
    assert!(
        problems
            .iter()
            .any(|p| p.starts_with("generate_camera_rays reads wave")),
        "{problems:?}"
    );
}

#[test]
fn graphs_follow_the_materials_in_use() {
    let shading = |scene: &str| -> Vec<&'static str> {
        pt_systems(scene)
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
        ["shade_diffuse", "shade_conductor", "shade_dielectric"]
    );
}

#[test]
fn every_scene_samples_lights_and_traces_shadows() {
    for scene in SCENES {
        let systems = pt_systems(scene);
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

/// The graph blocks of docs/architecture.md (`<!-- graph: INTEGRATOR SCENE -->` then a text block) are what
/// `stagelight graph` prints, so the docs never drift from the graphs.
#[test]
fn readme_graph_blocks_are_the_graphs_printed() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/architecture.md"))
            .expect("docs/architecture.md");
    let mut checked = 0;
    for (i, _) in readme.match_indices("<!-- graph: ") {
        let rest = &readme[i + "<!-- graph: ".len()..];
        let tag = &rest[..rest.find(" -->").expect("tag ends")];
        let (name, scene) = tag.split_once(' ').expect("integrator and scene");
        let body = rest
            .split_once("```text\n")
            .and_then(|(_, b)| b.split_once("```"))
            .expect("a text block follows the tag")
            .0;
        let data = SceneData::new(load_small(&format!("{scene}.ron"), 8));
        let kind = IntegratorKind::named(name);
        let printed = (kind.info().graph)(&data, &RenderSettings::default()).description;
        assert_eq!(body, printed, "docs/architecture.md graph block of {tag}");
        checked += 1;
    }
    assert!(checked >= 4, "found {checked} graph blocks");
}
