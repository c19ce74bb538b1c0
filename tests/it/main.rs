//! The integration tests, one binary so the suite links once. Each module is one subject;
//! `common` holds the helpers they share (small renders, running the `stagelight` binary,
//! temporary folders, interrupting a run once it has made progress).

mod common;

mod accel;
mod assembled_integrator;
mod bdpt;
mod bsdf;
mod cli;
mod compare;
mod determinism;
mod docs;
mod film_filter;
mod film_precision;
mod fuzz;
#[path = "../fuzz/targets.rs"]
mod fuzz_targets;
mod graph;
mod hostile;
mod kernels;
mod layering;
mod light_vertex_cache;
mod mitsuba_scenes;
mod mlt;
mod path_mlt;
mod path_mlt_split;
mod photon_checkpoint;
mod photon_mapping;
mod photons;
mod properties;
mod pt_furnace;
mod rays;
mod reference;
mod report_page;
mod scene_crosscheck;
mod scene_errors;
mod scene_loading;
mod shards;
mod stability;
mod vcm;
mod window_room;
